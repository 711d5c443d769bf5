// SPDX-License-Identifier: Apache-2.0
// The batched sincos used by FK against libm.
#include <algorithm>
#include <cmath>
#include <random>

#include "../../kinematics/src/fast_trig.hpp"

#include <CppUTest/TestHarness.h>

TEST_GROUP(FastTrig){};

TEST(FastTrig, AgreesWithLibmToTwoUlpsOfOneOverJointRange) {
  std::mt19937_64 rng(21);
  std::uniform_real_distribution<double> u(-50.0, 50.0);
  double worst = 0;
  for (int n = 0; n < 1000000; ++n) {
    const double x = n < 16 ? (n - 8) * M_PI / 4 : u(rng);  // quadrant boundaries first
    double s, c;
    servoarm::kin::detail::sincos_poly(x, s, c);
    worst = std::max({worst, std::abs(s - std::sin(x)), std::abs(c - std::cos(x))});
  }
  CHECK(worst < 5e-16);
}
