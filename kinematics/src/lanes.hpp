// SPDX-License-Identifier: Apache-2.0
#pragma once
// Two-lane doubles for code written once for a lane type T (internal header).
//
// T = double computes one case; T = v2d computes two at once in one register
// (SSE2 on x86-64, NEON on aarch64; GCC/Clang vector extensions, pairs of
// scalars on targets without double vectors). The same operations in the same
// order, so each lane of a v2d result equals the double result bit for bit
// where the compiler does not contract a*b+c differently (x86-64 has no FMA
// in the baseline ISA).
//
// Masks: comparisons give bool for double and v2m (all ones / zero per lane)
// for v2d. Generic code combines them with & and |, picks with select(), and
// never uses ! or ~ on them. Values selected away are computed anyway, so the
// generic code keeps every operation valid in every lane (no 0/0, no sqrt of
// a negative): the unit tests fail on any floating-point exception.
#include <cmath>
#if defined(__SSE2__)
#include <emmintrin.h>
#elif defined(__aarch64__)
#include <arm_neon.h>
#endif

namespace servoarm::kin::detail {

typedef double v2d __attribute__((vector_size(16)));
using v2m = decltype(v2d{} > v2d{});

template <class T>
inline T bc(double x);  ///< x in every lane
template <>
inline double bc<double>(double x) { return x; }
template <>
inline v2d bc<v2d>(double x) { return v2d{x, x}; }

[[gnu::always_inline]] inline double select(bool m, double a, double b) { return m ? a : b; }
[[gnu::always_inline]] inline v2d select(v2m m, v2d a, v2d b) { return (v2d)((m & (v2m)a) | (~m & (v2m)b)); }

/// min and max of non-NaN values (one instruction each on SSE2 and NEON; for equal
/// operands, which may differ only in the sign of a zero, either may be returned).
[[gnu::always_inline]] inline double lmin(double a, double b) { return b < a ? b : a; }
[[gnu::always_inline]] inline double lmax(double a, double b) { return a < b ? b : a; }
[[gnu::always_inline]] inline v2d lmin(v2d a, v2d b) {
#if defined(__SSE2__)
  return (v2d)_mm_min_pd((__m128d)a, (__m128d)b);
#elif defined(__aarch64__)
  return vminq_f64(a, b);
#else
  return v2d{lmin(a[0], b[0]), lmin(a[1], b[1])};
#endif
}
[[gnu::always_inline]] inline v2d lmax(v2d a, v2d b) {
#if defined(__SSE2__)
  return (v2d)_mm_max_pd((__m128d)a, (__m128d)b);
#elif defined(__aarch64__)
  return vmaxq_f64(a, b);
#else
  return v2d{lmax(a[0], b[0]), lmax(a[1], b[1])};
#endif
}

[[gnu::always_inline]] inline double lsqrt(double a) { return std::sqrt(a); }
[[gnu::always_inline]] inline v2d lsqrt(v2d a) {
#if defined(__SSE2__)
  return (v2d)_mm_sqrt_pd((__m128d)a);
#elif defined(__aarch64__)
  return vsqrtq_f64(a);
#else
  return v2d{std::sqrt(a[0]), std::sqrt(a[1])};
#endif
}

[[gnu::always_inline]] inline double lane(double a, int) { return a; }
[[gnu::always_inline]] inline double lane(v2d a, int i) { return a[i]; }
[[gnu::always_inline]] inline bool lane(bool m, int) { return m; }
[[gnu::always_inline]] inline bool lane(v2m m, int i) { return m[i] != 0; }
[[gnu::always_inline]] inline bool any(bool m) { return m; }
[[gnu::always_inline]] inline bool any(v2m m) { return (m[0] | m[1]) != 0; }
[[gnu::always_inline]] inline bool both(v2m m) { return (m[0] & m[1]) != 0; }  ///< both lanes set

}  // namespace servoarm::kin::detail
