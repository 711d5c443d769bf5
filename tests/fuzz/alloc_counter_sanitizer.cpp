// SPDX-License-Identifier: Apache-2.0
// tests/support/alloc_counter.hpp for sanitizer builds (the `asan` and `tsan` presets).
//
// The ordinary counter (tests/support/alloc_counter.cpp) interposes malloc and calls
// glibc's __libc_malloc; under ASan or TSan that hands the sanitizer's free() memory
// its allocator never gave out (ASan stops at once: "CHECK failed: asan_posix.cpp:124").
// Here the sanitizer's own allocator reports every allocation through
// __sanitizer_install_malloc_and_free_hooks, so the same API counts the same events
// (malloc, calloc, realloc, aligned allocations, operator new) without interposing;
// the count itself and the API are alloc_counter_count.hpp's, as in the ordinary counter.
// tests/fuzz/CMakeLists.txt puts this file in place of alloc_counter.cpp when
// SERVOARM_SANITIZE is set.
#include <sanitizer/allocator_interface.h>

#include "alloc_counter_count.hpp"

namespace {
void on_malloc(const volatile void*, std::size_t) { servoarm::test::count_allocation(); }
void on_free(const volatile void*) {}
[[maybe_unused]] const int g_installed = __sanitizer_install_malloc_and_free_hooks(on_malloc, on_free);
}  // namespace
