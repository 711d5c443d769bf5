// SPDX-License-Identifier: Apache-2.0
#pragma once
// The per-thread count behind alloc_counter.hpp, shared by the implementations that
// count: the ordinary one (alloc_counter.cpp, which interposes malloc) and the sanitizer
// builds' one (tests/fuzz/alloc_counter_sanitizer.cpp, the sanitizer's allocation hooks).
// Each calls count_allocation() from its hook. Include it in exactly one .cpp of a binary:
// it defines alloc_counter.hpp's functions.
#include <cstddef>
#include <cstdlib>

#include "alloc_counter.hpp"

namespace servoarm::test {
namespace {
thread_local bool t_counting = false;
thread_local std::size_t t_count = 0;
inline void count_allocation() {
  if (t_counting) ++t_count;
}
}  // namespace

void alloc_count_begin() {
  t_count = 0;
  t_counting = true;
}
std::size_t alloc_count_end() {
  t_counting = false;
  return t_count;
}
std::size_t alloc_count_now() { return t_count; }
bool alloc_counter_counts() { return true; }
void probe_malloc_free() {
  void* volatile p = std::malloc(16);
  std::free(p);
}
}  // namespace servoarm::test
