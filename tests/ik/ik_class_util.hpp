// SPDX-License-Identifier: Apache-2.0
#pragma once
// Helpers of the IK class suites (test_ik_classes.cpp, test_ik_singular.cpp):
// chains built from OPW / UR parameters in either DH convention, a row
// perturbed (near-miss models), the round-trip check of every solution.
#include <set>
#include <string>
#include <vector>

#include "servoarm/kinematics/ik.hpp"
#include "kin_test_util.hpp"

namespace servoarm::test {

inline kin::IkModel prepared(const char* name) {
  const kin::Chain c = model(name);
  kin::IkModel m;
  LONGS_EQUAL(static_cast<int>(kin::Status::ok), static_cast<int>(kin::ik_prepare(c, m)));
  return m;
}

inline double joint_gap(const kin::Chain& c, const kin::JointVector& a, const kin::JointVector& b) {
  double g = 0;
  for (int j = 0; j < c.n_joints; ++j) {
    const double d = a[j] - b[j];
    g = std::max(g, c.joint(j).type == kin::JointType::revolute ? std::abs(kin::wrap_pi(d)) : std::abs(d));
  }
  return g;
}

inline kin::Pose make_pose(const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  kin::Pose T = kin::Pose::Identity();
  T.linear() = R;
  T.translation() = t;
  return T;
}

/// A chain from rows (SI), in the standard convention or converted to the
/// modified one with the same FK: standard T = prod Rz Tz Tx(a_i) Rx(alpha_i);
/// since Tx(a) Rx(alpha) = Rx(alpha) Tx(a), modified row i takes (alpha, a)
/// of standard row i-1, and the last row's Tx(a6) Rx(alpha6) goes into the tool.
inline kin::Chain chain_of(const std::vector<kin::DhRow>& rows, bool modified, const char* name) {
  kin::Chain c;
  kin::set_name(c, name);
  c.convention = modified ? kin::Convention::modified : kin::Convention::standard;
  c.length_unit = 0.001;
  c.angle_unit = M_PI / 180;
  double prev_a = 0, prev_alpha = 0;
  for (const kin::DhRow& r0 : rows) {
    kin::DhRow r = r0;
    if (modified) {
      r.a = prev_a;
      r.alpha = prev_alpha;
      prev_a = r0.a;
      prev_alpha = r0.alpha;
    }
    if (kin::add_row(c, r) != kin::Status::ok) FAIL("add_row");
  }
  if (modified) {
    kin::Pose T = kin::Pose::Identity();
    T.translation().x() = prev_a;
    T.linear() = Eigen::AngleAxisd(prev_alpha, Eigen::Vector3d::UnitX()).toRotationMatrix();
    kin::set_tool(c, T);
  }
  return c;
}

inline kin::DhRow rev(double theta, double d, double a, double alpha, double dir = 1) {
  kin::DhRow r;
  r.type = kin::JointType::revolute;
  r.theta = theta;
  r.d = d;
  r.a = a;
  r.alpha = alpha;
  r.direction = dir;
  r.lower = -M_PI;
  r.upper = M_PI;
  return r;
}

/// OPW parameters (Brandstoetter et al. 2014), metres.
struct OpwParams {
  double a1 = 0, a2 = 0, b = 0, c1 = 0, c2 = 0, c3 = 0, c4 = 0;
};
/// The OPW arm as DH rows (the mapping of kinematics/models/abb_irb2400.toml);
/// `odd`: joints 2 and 4 reversed and joint offsets on 1, 3, 6.
inline kin::Chain opw_chain(const OpwParams& p, bool modified, bool odd) {
  const double h = M_PI / 2, s = odd ? -1 : 1, o = odd ? 0.3 : 0.0;
  return chain_of({rev(o, p.c1, p.a1, -h), rev(-h, p.b, p.c2, 0, s), rev(h + o, 0, p.a2, h),
                   rev(0, p.c3, 0, -h, s), rev(0, 0, 0, h), rev(-o, p.c4, 0, 0)},
                  modified, "opw_test");
}

/// UR parameters (standard DH: d1, a2, a3, d4, d5, d6), metres.
struct UrParams {
  double d1 = 0, a2 = 0, a3 = 0, d4 = 0, d5 = 0, d6 = 0;
};
inline kin::Chain ur_chain(const UrParams& p, bool modified, bool odd) {
  const double h = M_PI / 2, s = odd ? -1 : 1, o = odd ? 0.4 : 0.0;
  return chain_of({rev(o, p.d1, 0, h, s), rev(-o, 0, p.a2, 0), rev(0, 0, p.a3, 0, s), rev(o, p.d4, 0, h),
                   rev(0, p.d5, 0, -h, s), rev(o, p.d6, 0, 0)},
                  modified, "ur_test");
}

/// c with DH row `row` changed: 'a' or 'd' + 1e-6 m (0.001 mm), 't' alpha + 0.01 deg.
inline kin::Chain perturbed(const kin::Chain& c, int row, char key) {
  kin::Chain out = c;
  out.n_rows = 0;
  out.n_joints = 0;
  for (int i = 0; i < c.n_rows; ++i) {
    kin::DhRow r = c.rows[static_cast<std::size_t>(i)];
    if (i == row) {
      if (key == 'a') r.a += 1e-6;
      if (key == 'd') r.d += 1e-6;
      if (key == 't') r.alpha += 0.01 * M_PI / 180;
    }
    if (kin::add_row(out, r) != kin::Status::ok) FAIL("add_row");
  }
  return out;
}

inline void check_pose(const kin::Chain& c, const kin::JointVector& q, const kin::Pose& T, const std::string& what) {
  kin::Pose X;
  LONGS_EQUAL(0, static_cast<int>(kin::forward(c, q, X)));
  const double ep = (X.translation() - T.translation()).norm();
  const double er = kin::rotation_error(X.linear(), T.linear()).norm();
  if (!(ep <= 1e-9 && er <= 1e-9))
    FAIL((what + ": " + describe(q) + " ep=" + std::to_string(ep) + " er=" + std::to_string(er)).c_str());
}

inline bool original_found(const kin::Chain& c, const kin::IkResult& r, const kin::JointVector& q, double tol = 1e-6) {
  for (int i = 0; i < r.count; ++i)
    if (joint_gap(c, r.solutions[static_cast<std::size_t>(i)].q, q) < tol) return true;
  return false;
}

struct RoundTripStats {
  int n = 0, with8 = 0, singular = 0, refined = 0;
  long total = 0;
  double mean_count() const { return n ? static_cast<double>(total) / n : 0.0; }
};

/// FK(IK(FK(q))) on n random configurations within the limits: every
/// solution reproduces the pose (chain FK, 1e-9 m / 1e-9 rad), its
/// within_limits flag is right, the branch tags are distinct, the original
/// configuration is among the solutions (also at singular poses: random
/// configurations are never exactly singular).
inline RoundTripStats round_trip(const kin::IkModel& m, int n, unsigned seed, const char* name) {
  RoundTripStats st;
  st.n = n;
  std::mt19937_64 rng(seed);
  for (int k = 0; k < n; ++k) {
    const kin::JointVector q = random_q(m.chain, rng);
    const kin::Pose T = fk(m.chain, q);
    kin::IkResult r;
    kin::ik_solve_all(m, T, nullptr, r);
    const std::string what = std::string(name) + " " + describe(q);
    if (r.count == 0) FAIL((what + ": no solution, status " + kin::to_string(r.status)).c_str());
    std::set<std::tuple<int, int, int>> tags;
    for (int i = 0; i < r.count; ++i) {
      const auto& s = r.solutions[static_cast<std::size_t>(i)];
      check_pose(m.chain, s.q, T, what + " solution " + std::to_string(i));
      CHECK_EQUAL_TEXT(kin::within_limits(m.chain, s.q, 1e-9), s.within_limits, what.c_str());
      if (!tags.insert({s.branch.shoulder, s.branch.elbow, s.branch.wrist}).second)
        FAIL((what + ": two solutions with the same branch tags").c_str());
      if (s.position_error > 1e-12 * 10 || s.rotation_error > 1e-11) ++st.refined;
    }
    if (!original_found(m.chain, r, q)) {
      std::string all;
      for (int i = 0; i < r.count; ++i) all += "\n    " + describe(r.solutions[static_cast<std::size_t>(i)].q);
      FAIL((what + ": the original configuration is not among the " + std::to_string(r.count) + " solutions" + all)
               .c_str());
    }
    st.total += r.count;
    if (r.count == 8) ++st.with8;
    if (r.singular_kinds) ++st.singular;
  }
  return st;
}

}  // namespace servoarm::test
