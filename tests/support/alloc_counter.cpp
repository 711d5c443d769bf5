#include "alloc_counter.hpp"

#include <cstdlib>
#include <cstring>
#include <malloc.h>

extern "C" {
void* __libc_malloc(size_t);
void* __libc_calloc(size_t, size_t);
void* __libc_realloc(void*, size_t);
void* __libc_memalign(size_t, size_t);
}

namespace {
thread_local bool t_counting = false;
thread_local std::size_t t_count = 0;
inline void note() {
  if (t_counting) ++t_count;
}
}  // namespace

namespace servoarm::test {
void alloc_count_begin() {
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

extern "C" {
void* malloc(size_t n) {
  note();
  return __libc_malloc(n);
}
void* calloc(size_t n, size_t m) {
  note();
  return __libc_calloc(n, m);
}
void* realloc(void* p, size_t n) {
  note();
  return __libc_realloc(p, n);
}
void* memalign(size_t a, size_t n) {
  note();
  return __libc_memalign(a, n);
}
void* aligned_alloc(size_t a, size_t n) {
  note();
  return __libc_memalign(a, n);
}
int posix_memalign(void** out, size_t a, size_t n) {
  note();
  void* p = __libc_memalign(a, n);
  if (!p) return 12;  // ENOMEM
  *out = p;
  return 0;
}
}
