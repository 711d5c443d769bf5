// SPDX-License-Identifier: Apache-2.0
#pragma once
// Counts heap allocations made by the calling thread.
//
// malloc, calloc, realloc, aligned_alloc, posix_memalign and memalign are
// interposed (glibc lets an executable define them) and forwarded to glibc's
// implementation; operator new ends in malloc, so C++ allocations are counted
// too. Counting is per thread, so a test can watch exactly one thread (the
// control thread) while others allocate freely.
#include <cstddef>

namespace servoarm::test {

/// Start counting allocations on this thread (resets the count).
void alloc_count_begin();
/// Stop counting on this thread; returns the allocations seen since begin().
std::size_t alloc_count_end();
/// Allocations counted so far on this thread (counting may still be on).
std::size_t alloc_count_now();

/// Whether this build's counter counts at all: false in the memcheck build (valgrind owns
/// the heap there and tests/fuzz/alloc_counter_memcheck.cpp counts nothing), so a test's
/// self-check of the counter is left out there and its zero counts prove nothing.
bool alloc_counter_counts();

/// Calls malloc and free once (from a file that CppUTest's malloc macros do not
/// reach), so a test can prove the counter sees plain mallocs.
void probe_malloc_free();

/// RAII scope: counts allocations on this thread while alive.
class AllocScope {
 public:
  AllocScope() { alloc_count_begin(); }
  ~AllocScope() { if (!ended_) alloc_count_end(); }
  std::size_t end() { ended_ = true; return alloc_count_end(); }
  AllocScope(const AllocScope&) = delete;
  AllocScope& operator=(const AllocScope&) = delete;
 private:
  bool ended_ = false;
};

}  // namespace servoarm::test
