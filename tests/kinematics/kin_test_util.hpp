// SPDX-License-Identifier: Apache-2.0
#pragma once
// Helpers shared by the kinematics suites: loading built-ins, random joints.
#include <cmath>
#include <random>
#include <string>

#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/kinematics/orientation.hpp"
#include <sstream>
#include <vector>
#include <algorithm>
#include <limits>

// CppUTest last: its leak detector redefines `new` for what follows.
#include <CppUTest/TestHarness.h>

namespace servoarm::test {

inline kin::Chain model(const char* name) {
  const kin::LoadResult r = kin::load_robot(name);
  if (!r.ok) FAIL(r.error.c_str());
  return r.chain;
}

/// Uniform random joints within limits (+-pi where a joint is unlimited).
inline kin::JointVector random_q(const kin::Chain& c, std::mt19937_64& rng) {
  kin::JointVector q(c.n_joints);
  for (int j = 0; j < c.n_joints; ++j) {
    const auto& r = c.joint(j);
    const double lo = std::isfinite(r.lower) ? r.lower : -M_PI;
    const double hi = std::isfinite(r.upper) ? r.upper : M_PI;
    q[j] = std::uniform_real_distribution<double>(lo, hi)(rng);
  }
  return q;
}

inline kin::Pose fk(const kin::Chain& c, const kin::JointVector& q) {
  kin::Pose T;
  const kin::Status s = kin::forward(c, q, T);
  if (s != kin::Status::ok) FAIL(kin::to_string(s));
  return T;
}

inline double deg(double d) { return d * M_PI / 180.0; }

inline std::string describe(const kin::JointVector& q) {
  std::string s = "q = [";
  for (int i = 0; i < q.size(); ++i) s += (i ? ", " : "") + std::to_string(q[i]);
  return s + "]";
}

}  // namespace servoarm::test
