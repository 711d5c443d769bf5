// SPDX-License-Identifier: Apache-2.0
#pragma once
// Batched sine/cosine for the FK hot path (internal header).
//
// Why hand-written: FK of a 6-joint arm is ~40 flops per row plus one sincos
// per revolute joint, so libm's sincos (an out-of-line call each) is most of
// the cost. This version is inlined and branch-free, so the compiler
// vectorises it across the joints of a chain. SLEEF (Debian libsleef-dev) has
// vector sincos too, but only as out-of-line calls per ISA, which loses the
// inlining that makes this fast.
//
// Accuracy: Cody-Waite reduction by pi/2 with a three-part constant (exact for
// |x| < 1e5 rad, far beyond any joint), then Taylor polynomials on |r| <= pi/4:
// sin to r^15 (first omitted term < 5e-17), cos to r^16 (< 3e-18). Measured
// against std::sin/std::cos over 1e6 arguments in [-50, 50]: max error 2.3e-16
// (see tests/kinematics/test_fast_trig.cpp).
#include <bit>
#include <cstdint>
#include <cmath>

#include "lanes.hpp"

namespace servoarm::kin::detail {

inline void sincos_poly(double x, double& s, double& c) {
  constexpr double two_over_pi = 0.63661977236758134308;
  // pi/2 split into three parts (each exactly representable; products with
  // small integers are exact).
  constexpr double p1 = 1.5707963267341256e+00;
  constexpr double p2 = 6.07710050630396597660e-11;
  constexpr double p3 = 2.02226624879595063154e-21;
  // Round to nearest with the 1.5*2^52 trick: std::nearbyint is a libm call
  // on baseline x86-64 (no SSE4.1 roundsd). Exact for |x * 2/pi| < 2^51.
  constexpr double magic = 6755399441055744.0;
  const double km = x * two_over_pi + magic;  // k in the low mantissa bits (2^51 + k: k mod 4 exact)
  const double k = km - magic;
  const double r = ((x - k * p1) - k * p2) - k * p3;
  const double r2 = r * r;
  // sin r = r (1 - r2/3! + r2^2/5! - ... - r2^7/15!)
  const double ps =
      1.0 + r2 * (-1.0 / 6 + r2 * (1.0 / 120 + r2 * (-1.0 / 5040 + r2 * (1.0 / 362880 +
      r2 * (-1.0 / 39916800 + r2 * (1.0 / 6227020800 + r2 * (-1.0 / 1307674368000.0)))))));
  // cos r = 1 - r2/2! + ... + r2^8/16!
  const double pc =
      1.0 + r2 * (-0.5 + r2 * (1.0 / 24 + r2 * (-1.0 / 720 + r2 * (1.0 / 40320 + r2 * (-1.0 / 3628800 +
      r2 * (1.0 / 479001600 + r2 * (-1.0 / 87178291200.0 + r2 * (1.0 / 20922789888000.0))))))));
  const double sr = r * ps;
  const double cr = pc;
  // The quadrant from km's bits, not static_cast<long>(k): that is undefined behaviour for
  // |x| beyond the range of long (UBSan: `armctl kin fk --json 1e308 ...`); the bits are the
  // same integer wherever the reduction is exact and merely meaningless beyond it.
  const long q = static_cast<long>(std::bit_cast<std::uint64_t>(km) & 3u);
  const bool swap = (q & 1) != 0;
  const double sin_base = swap ? cr : sr;
  const double cos_base = swap ? sr : cr;
  s = (q & 2) ? -sin_base : sin_base;
  c = ((q + 1) & 2) ? -cos_base : cos_base;
}

/// Constants of atan2_poly and atan2_poly_x2 (Cephes atan).
namespace atan2_coef {
inline constexpr double P0 = -8.750608600031904122785e-1, P1 = -1.615753718733365076637e1,
                        P2 = -7.500855792314704667340e1, P3 = -1.228866684490136173410e2,
                        P4 = -6.485021904942025371773e1;
inline constexpr double Q0 = 2.485846490142306297962e1, Q1 = 1.650270098316988542046e2,
                        Q2 = 4.328810604912902668951e2, Q3 = 4.853903996359136964868e2,
                        Q4 = 1.945506571482613964425e2;
inline constexpr double pio4 = 7.85398163397448309616e-1;         // pi/4 rounded to double
inline constexpr double morebits = 6.123233995736765886130e-17;  // pi/2 - 2 pio4 (Cephes' MOREBITS)
/// pi/4 = hi + lo: hi = pio4 to 26 bits (k hi exact for k <= 4), lo = (pio4 - hi, exact) + morebits/2
namespace pio4_k {
inline constexpr double hi = 0x1.921fb5p-1;
inline constexpr double lo = (pio4 - hi) + 0.5 * morebits;
inline constexpr double tiny = 4.9406564584124654e-324;  // the least subnormal: td > 0 when num = den = 0
}  // namespace pio4_k
}  // namespace atan2_coef

/// atan2(y, x) for finite arguments, inlined and branch-light (the closed-form
/// IK calls it ~30 times per pose; glibc's atan2 is an out-of-line call of
/// ~15-20 ns each here). Cephes atan: the ratio min/max in [0, 1] is reduced
/// to |t| <= 0.66 by t = (a - 1)/(a + 1) above 0.66, then the degree 4/5
/// rational minimax approximation x + x^3 P(x^2)/Q(x^2) (peak relative error
/// 2.6e-18). The octant is restored in one step: the angle is s r + k pi/4
/// with s = +-1 and k in 0..4 from the three choices (ratio swapped, reduced,
/// x negative), k pi/4 added as k hi (hi: pi/4 to 26 bits, so k hi is exact) after
/// k lo (lo = pi/4 - hi: pio4's remainder and Cephes' MOREBITS): two roundings
/// where Cephes' three nested steps take six. Measured against std::atan2 over
/// 2e6 random and special arguments: max error 4.5e-16 rad
/// (tests/ik/test_ik_closed_form.cpp). atan2(0, 0) = 0; the signs of zeros
/// follow std::atan2 (atan2(-0, -1) = -pi). No FP exceptions for finite
/// normal arguments.
[[gnu::always_inline]] inline double atan2_poly(double y, double x) {
  using namespace atan2_coef;
  // Written as selects between values computed unconditionally (no branches,
  // no floating-point operation under a condition), the same operations in
  // the same order as atan2_poly_v2 (bit for bit, tested).
  const double ax = std::abs(x), ay = std::abs(y);
  const bool swap = ay > ax;
  const double num = lmin(ax, ay), den = lmax(ax, ay);
  // t = a or (a - 1)/(a + 1) with a = num/den, in one division; when den = 0,
  // num = 0 and t = 0/denorm_min = 0 (no 0/0)
  const bool big = num > 0.66 * den;
  const double tn = num - (big ? den : 0.0);
  const double td = (big ? num : 0.0) + lmax(den, pio4_k::tiny);
  const double t = tn / td;
  const double z = t * t;
  const double p = (((P0 * z + P1) * z + P2) * z + P3) * z + P4;
  const double q = ((((z + Q0) * z + Q1) * z + Q2) * z + Q3) * z + Q4;
  const double r = t + t * (z * p / q);
  // k = 4 [x < 0] +- (2 [swap] -+ [big]) and the sign of r: the signs flip with swap and
  // with x's sign bit (so -0 too: atan2(+-0, -0) = +-pi); 4 [x < 0] = 2 - copysign(2, x)
  const double sx = std::copysign(1.0, x);
  const double kb = big ? 1.0 : 0.0, ks = swap ? 2.0 : 0.0;
  const double k = (2.0 - 2.0 * sx) + sx * (ks + (swap ? -kb : kb));
  const double sr = sx * (swap ? -r : r);
  const double a = (sr + k * pio4_k::lo) + k * pio4_k::hi;
  return std::copysign(a, y);
}

/// atan2_poly on two argument pairs at once (lane i: atan2(vy[i], vx[i])): the same operations on a
/// two-lane vector (GCC/Clang vector extensions; one SSE2 register on
/// x86-64, NEON on aarch64, pairs of scalars elsewhere), so the same result
/// bit for bit, at about half the instructions. The scalar version does not
/// vectorise by itself (-ftrapping-math keeps its comparisons as branches).
[[gnu::always_inline]] inline v2d atan2_poly_v2(v2d vy, v2d vx) {
  using namespace atan2_coef;
  auto splat = [](double c) { return bc<v2d>(c); };
  const v2m sign = (v2m)splat(-0.0);
  auto when = [](v2m m, v2d a) { return (v2d)(m & (v2m)a); };  // m ? a : 0
  auto flip = [](v2d a, v2m s) { return (v2d)((v2m)a ^ s); };   // a with its sign bit xor s
  const v2d ax = (v2d)((v2m)vx & ~sign), ay = (v2d)((v2m)vy & ~sign);
  const v2m swap = ay > ax;
  const v2d num = lmin(ax, ay), den = lmax(ax, ay);
  const v2m big = num > splat(0.66) * den;
  const v2d tn = num - when(big, den);
  const v2d td = when(big, num) + lmax(den, splat(pio4_k::tiny));
  const v2d t = tn / td;
  const v2d z = t * t;
  const v2d p = (((splat(P0) * z + splat(P1)) * z + splat(P2)) * z + splat(P3)) * z + splat(P4);
  const v2d q = ((((z + splat(Q0)) * z + splat(Q1)) * z + splat(Q2)) * z + splat(Q3)) * z + splat(Q4);
  const v2d r = t + t * (z * p / q);
  // as atan2_poly, its multiplications by sx = copysign(1, x) and by -1 as sign-bit xors
  const v2m xs = (v2m)vx & sign, ss = swap & sign;
  const v2d k = (splat(2.0) - (v2d)((v2m)splat(2.0) | xs)) + flip(when(swap, splat(2.0)) + flip(when(big, splat(1.0)), ss), xs);
  const v2d sr = flip(r, ss ^ xs);
  const v2d a = (sr + k * splat(pio4_k::lo)) + k * splat(pio4_k::hi);
  return (v2d)((v2m)a | ((v2m)vy & sign));  // copysign(a, y): a >= 0
}
/// The same on two pairs held in arrays.
[[gnu::always_inline]] inline void atan2_poly_x2(const double* y, const double* x, double* out) {
  const v2d r = atan2_poly_v2(v2d{y[0], y[1]}, v2d{x[0], x[1]});
  out[0] = r[0];
  out[1] = r[1];
}

}  // namespace servoarm::kin::detail
