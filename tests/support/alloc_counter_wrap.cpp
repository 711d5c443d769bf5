// SPDX-License-Identifier: Apache-2.0
// The allocation counter of a statically linked test (SERVOARM_STATIC): a static
// glibc keeps malloc and __libc_malloc in one object, so defining malloc beside it
// (alloc_counter.cpp's interposition) clashes. The link wraps the allocation
// functions instead (-Wl,--wrap=malloc ..., tests/CMakeLists.txt): every call in
// the program, libstdc++'s operator new and CppUTest's included, comes here.
#include "alloc_counter_count.hpp"

#include <cstddef>

extern "C" {
void* __real_malloc(size_t);
void* __real_calloc(size_t, size_t);
void* __real_realloc(void*, size_t);
void* __real_memalign(size_t, size_t);
void* __real_aligned_alloc(size_t, size_t);
int __real_posix_memalign(void**, size_t, size_t);

void* __wrap_malloc(size_t n) {
  servoarm::test::count_allocation();
  return __real_malloc(n);
}
void* __wrap_calloc(size_t n, size_t m) {
  servoarm::test::count_allocation();
  return __real_calloc(n, m);
}
void* __wrap_realloc(void* p, size_t n) {
  servoarm::test::count_allocation();
  return __real_realloc(p, n);
}
void* __wrap_memalign(size_t a, size_t n) {
  servoarm::test::count_allocation();
  return __real_memalign(a, n);
}
void* __wrap_aligned_alloc(size_t a, size_t n) {
  servoarm::test::count_allocation();
  return __real_aligned_alloc(a, n);
}
int __wrap_posix_memalign(void** out, size_t a, size_t n) {
  servoarm::test::count_allocation();
  return __real_posix_memalign(out, a, n);
}
}
