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
#include <cmath>

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
  const double k = (x * two_over_pi + magic) - magic;
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
  const long q = static_cast<long>(k) & 3;
  const bool swap = (q & 1) != 0;
  const double sin_base = swap ? cr : sr;
  const double cos_base = swap ? sr : cr;
  s = (q & 2) ? -sin_base : sin_base;
  c = ((q + 1) & 2) ? -cos_base : cos_base;
}

}  // namespace servoarm::kin::detail
