// tests/support/alloc_counter.hpp for sanitizer builds (the `asan` and `tsan` presets).
//
// The ordinary counter (tests/support/alloc_counter.cpp) interposes malloc and calls
// glibc's __libc_malloc; under ASan or TSan that hands the sanitizer's free() memory
// its allocator never gave out (ASan stops at once: "CHECK failed: asan_posix.cpp:124").
// Here the sanitizer's own allocator reports every allocation through
// __sanitizer_install_malloc_and_free_hooks, so the same API counts the same events
// (malloc, calloc, realloc, aligned allocations, operator new) without interposing.
// tests/fuzz/CMakeLists.txt puts this file in place of alloc_counter.cpp when
// SERVOARM_SANITIZE is set.
#include <sanitizer/allocator_interface.h>

#include <cstdlib>

#include "alloc_counter.hpp"

namespace {
thread_local bool t_counting = false;
thread_local std::size_t t_count = 0;
void on_malloc(const volatile void*, std::size_t) {
  if (t_counting) ++t_count;
}
void on_free(const volatile void*) {}
const int g_installed = __sanitizer_install_malloc_and_free_hooks(on_malloc, on_free);
}  // namespace

namespace servoarm::test {
void alloc_count_begin() {
  (void)g_installed;
  t_count = 0;
  t_counting = true;
}
std::size_t alloc_count_end() {
  t_counting = false;
  return t_count;
}
std::size_t alloc_count_now() { return t_count; }
void probe_malloc_free() {
  void* volatile p = std::malloc(16);
  std::free(p);
}
}  // namespace servoarm::test
