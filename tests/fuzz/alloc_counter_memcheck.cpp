// SPDX-License-Identifier: Apache-2.0
// tests/support/alloc_counter.hpp for the memcheck build: counts nothing.
// The ordinary counter interposes malloc and calls glibc's __libc_malloc, so valgrind
// never sees those blocks and reports their free() as invalid. Under valgrind the heap
// belongs to valgrind; alloc_counter_counts() says so, and the tests' self-checks of the
// counter (probe_malloc_free) are left out in this build.
#include <cstdlib>

#include "alloc_counter.hpp"

namespace servoarm::test {
void alloc_count_begin() {}
std::size_t alloc_count_end() { return 0; }
std::size_t alloc_count_now() { return 0; }
bool alloc_counter_counts() { return false; }
void probe_malloc_free() {
  void* volatile p = std::malloc(16);
  std::free(p);
}
}  // namespace servoarm::test
