// SPDX-License-Identifier: Apache-2.0
// lanes.hpp: code written once for a lane type gives, in each lane of the
// two-lane version, what the one-lane (double) version gives -- the contract
// the spherical-wrist IK relies on when it computes two arm configurations at
// once. Checked on x86-64 (SSE2), aarch64 (NEON, under qemu in CI) and wherever
// else the suite is built (scalar pairs).
#include <cmath>
#include <cstring>
#include <random>

#include "../../kinematics/src/lanes.hpp"

#include <CppUTest/TestHarness.h>

namespace {
using namespace servoarm::kin::detail;

// A kernel in the style of the IK's: safe normalisation of (x, y) with a
// select instead of a branch, a clamp, and a root of a difference that can
// be negative in the lanes it is selected away from.
template <class T>
void kernel(T x, T y, T& c, T& s, T& r) {
  const T n2 = x * x + y * y;
  const auto pos = n2 > 0.0;
  const T inv = 1.0 / lsqrt(select(pos, n2, bc<T>(1.0)));
  c = select(pos, x * inv, bc<T>(1.0));
  s = select(pos, y * inv, bc<T>(0.0));
  const T d = x - y;
  const T dc = select(d < 0.0, bc<T>(0.0), d);
  r = select((d > 1.0) | (d < -1.0), bc<T>(-1.0), lsqrt(dc));
}

bool same_bits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

}  // namespace

TEST_GROUP(Lanes){};

TEST(Lanes, BroadcastSelectLaneAndAny) {
  const v2d a = bc<v2d>(2.5);
  CHECK(lane(a, 0) == 2.5 && lane(a, 1) == 2.5);
  CHECK(bc<double>(-1.0) == -1.0);
  const v2d x{1.0, -3.0}, y{7.0, 8.0};
  const v2m m = x > 0.0;
  CHECK(lane(m, 0));
  CHECK_FALSE(lane(m, 1));
  const v2d p = select(m, x, y);
  CHECK(lane(p, 0) == 1.0 && lane(p, 1) == 8.0);
  CHECK(any(m));
  CHECK_FALSE(any(x > 5.0));
  CHECK(any(x < -2.0));
  CHECK(select(true, 1.0, 2.0) == 1.0 && select(false, 1.0, 2.0) == 2.0);
  const v2d r = lsqrt(v2d{4.0, 0.0});
  CHECK(lane(r, 0) == 2.0 && lane(r, 1) == 0.0);
}

TEST(Lanes, TwoLaneKernelEqualsOneLaneBitForBit) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  // First every combination of special values (no product of two of them
  // under- or overflows: the suite fails on any floating-point exception).
  const double special[] = {0.0, -0.0, 1.0, -1.0, 1e-100, 2.0, 1e150};
  const int pow7[4] = {1, 7, 49, 343};
  int checked = 0;
  for (int n = 0; n < 200000; ++n) {
    double in[4];
    for (int k = 0; k < 4; ++k) in[k] = n < 2401 ? special[(n / pow7[k]) % 7] : u(rng);
    double c0, s0, r0, c1, s1, r1;
    kernel(in[0], in[1], c0, s0, r0);
    kernel(in[2], in[3], c1, s1, r1);
    v2d c, s, r;
    kernel(v2d{in[0], in[2]}, v2d{in[1], in[3]}, c, s, r);
    CHECK(same_bits(lane(c, 0), c0) && same_bits(lane(s, 0), s0) && same_bits(lane(r, 0), r0));
    CHECK(same_bits(lane(c, 1), c1) && same_bits(lane(s, 1), s1) && same_bits(lane(r, 1), r1));
    CHECK(std::isfinite(c0) && std::isfinite(s0) && std::isfinite(r0));
    ++checked;
  }
  CHECK(checked == 200000);
}
