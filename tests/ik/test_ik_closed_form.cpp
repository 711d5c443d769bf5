// SPDX-License-Identifier: Apache-2.0
// Closed-form IK of the six-joint spherical-wrist arms, solved from the DH
// description alone: round trip FK(IK(FK(q))) = FK(q) on random
// configurations (every solution checked), the original q among the
// solutions, solution counts (generic, reach limit, unreachable), each
// singularity kind, solution choice, bad input.
#include <cstdlib>
#include <cstring>
#include <limits>
#include <vector>

#include "servoarm/kinematics/ik.hpp"
#include "kin_test_util.hpp"
#include "sweep.hpp"

using namespace servoarm;
using namespace servoarm::test;

namespace {

const char* const kWristArms[] = {"puma560", "puma560_craig", "stanford", "cylindrical_rpp_rrr", "ist6"};
// Solutions at a generic pose: 4 arm configurations x 2 wrists; the
// cylindrical RPP arm has 2 arm configurations ((q1, d3) and (q1 + pi, -d3)).
int generic_count(const char* name) { return std::string(name) == "cylindrical_rpp_rrr" ? 4 : 8; }

int samples_per_arm() {
  const char* s = std::getenv("SERVOARM_IK_SAMPLES");
  return s ? std::atoi(s) : servoarm::test::sweep(100000);  // 1/20 under qemu and the sanitizers
}

kin::IkModel prepared(const char* name) {
  const kin::Chain c = model(name);
  kin::IkModel m;
  LONGS_EQUAL(static_cast<int>(kin::Status::ok), static_cast<int>(kin::ik_prepare(c, m)));
  return m;
}

double joint_gap(const kin::Chain& c, const kin::JointVector& a, const kin::JointVector& b) {
  double g = 0;
  for (int j = 0; j < c.n_joints; ++j) {
    const double d = a[j] - b[j];
    g = std::max(g, c.joint(j).type == kin::JointType::revolute ? std::abs(kin::wrap_pi(d)) : std::abs(d));
  }
  return g;
}

void check_solutions(const kin::IkModel& m, const kin::Pose& T, const kin::IkResult& r, const std::string& what) {
  for (int i = 0; i < r.count; ++i) {
    const auto& s = r.solutions[static_cast<std::size_t>(i)];
    CHECK_TEXT(s.q.allFinite(), what.c_str());
    kin::Pose X;
    LONGS_EQUAL(0, static_cast<int>(kin::forward(m.chain, s.q, X)));
    const double ep = (X.translation() - T.translation()).norm();
    const double er = kin::rotation_error(X.linear(), T.linear()).norm();
    if (!(ep <= 1e-9 && er <= 1e-9))
      FAIL((what + " solution " + std::to_string(i) + " " + describe(s.q) + " ep=" + std::to_string(ep) +
            " er=" + std::to_string(er)).c_str());
    CHECK_EQUAL(kin::within_limits(m.chain, s.q, 1e-9), s.within_limits);
  }
}

}  // namespace

TEST_GROUP(IkSphericalWrist){};

TEST(IkSphericalWrist, EveryArmIsRecognisedFromItsDhRows) {
  for (const char* name : kWristArms) {
    const kin::IkModel m = prepared(name);
    // ist6: axes 2 and 3 parallel, axes 1 and 2 40 mm apart: the OPW class
    // (joint 1 first); the others decouple one of E1, E2.
    STRCMP_EQUAL_TEXT(std::string(name) == "ist6" ? "opw" : "spherical_wrist", kin::to_string(m.method), name);
  }
  // A six-joint arm whose wrist axes do not meet is not (offset on joint 5).
  kin::Chain c = model("puma560");
  c.rows[4].a = 0.01;
  kin::IkModel m;
  kin::ik_prepare(c, m);
  STRCMP_EQUAL("numeric", kin::to_string(m.method));
}

TEST(IkSphericalWrist, RoundTripEverySolutionAndOriginalAmongThem) {
  const int n = samples_per_arm();
  for (const char* name : kWristArms) {
    const kin::IkModel m = prepared(name);
    std::mt19937_64 rng(1234);
    int eight = 0, found = 0, singular = 0;
    long total = 0;
    for (int k = 0; k < n; ++k) {
      const kin::JointVector q = random_q(m.chain, rng);
      const kin::Pose T = fk(m.chain, q);
      kin::IkResult r;
      kin::ik_solve_all(m, T, nullptr, r);
      const std::string what = std::string(name) + " " + describe(q);
      if (r.count == 0) FAIL((what + " no solution, status " + kin::to_string(r.status)).c_str());
      check_solutions(m, T, r, what);
      total += r.count;
      if (r.count == generic_count(name)) ++eight;
      else if (!r.singular_kinds && std::string(name) == "ist6" && r.count != 4)
        FAIL((what + " ist6: " + std::to_string(r.count) + " solutions").c_str());
      if (r.singular_kinds) ++singular;
      bool in = false;
      for (int i = 0; i < r.count && !in; ++i) in = joint_gap(m.chain, r.solutions[static_cast<std::size_t>(i)].q, q) < 1e-6;
      if (in) {
        ++found;
      } else if (!r.singular_kinds) {
        FAIL((what + ": the original configuration is not among the " + std::to_string(r.count) + " solutions").c_str());
      }
    }
    std::printf("\n  %-20s %d poses: %.3f solutions/pose, %d with %d, original found %d, singular %d", name, n,
                static_cast<double>(total) / n, eight, generic_count(name), found, singular);
    // Generic poses of these arms have 8 solutions (ist6, puma: all 8 real
    // for most random poses; the prismatic arms have 8 counting the
    // negative-stroke branches, which the limits then reject).
    // ist6: axes 1 and 2 do not meet (a = 40 mm), so the flipped shoulder
    // sees the wrist centre at another distance from axis 2 and may not
    // reach it: 8 or 4 solutions.
    if (std::string(name) == "ist6") CHECK(eight > n * 7 / 10);
    else CHECK(eight > n * 99 / 100);
  }
}

TEST(IkSphericalWrist, GenericPoseHasEightSolutionsWithDistinctBranches) {
  for (const char* name : kWristArms) {
    const kin::IkModel m = prepared(name);
    kin::JointVector q(6);
    q << 0.3, -0.7, 0.5, 0.4, 0.9, -0.2;
    for (int j = 0; j < 6; ++j)
      if (m.chain.joint(j).type == kin::JointType::prismatic) q[j] = 0.5 * (m.chain.joint(j).lower + m.chain.joint(j).upper);
    const kin::Pose T = fk(m.chain, q);
    kin::IkResult r;
    kin::ik_solve_all(m, T, nullptr, r);
    LONGS_EQUAL_TEXT(generic_count(name), r.count, name);
    check_solutions(m, T, r, name);
    for (int i = 0; i < r.count; ++i)
      for (int k = i + 1; k < r.count; ++k)
        CHECK_TEXT(!(r.solutions[static_cast<std::size_t>(i)].branch == r.solutions[static_cast<std::size_t>(k)].branch), name);
  }
}

TEST(IkSphericalWrist, PumaCraigMatchesSeed004ClosedForm) {
  // Seed 004: theta3 from a3 C3 - d4 S3 = K. Check every solution satisfies it.
  const kin::IkModel m = prepared("puma560_craig");
  const double a2 = 0.4318, a3 = 0.02032, d3 = 0.14909, d4 = 0.43307;
  std::mt19937_64 rng(7);
  for (int k = 0; k < 200; ++k) {
    const kin::JointVector q = random_q(m.chain, rng);
    const kin::Pose T = fk(m.chain, q);
    const Eigen::Vector3d p = T.translation();
    const double K = (p.squaredNorm() - a2 * a2 - a3 * a3 - d3 * d3 - d4 * d4) / (2 * a2);
    kin::IkResult r;
    kin::ik_solve_all(m, T, nullptr, r);
    CHECK(r.count >= 1);
    for (int i = 0; i < r.count; ++i) {
      const double t3 = r.solutions[static_cast<std::size_t>(i)].q[2];
      DOUBLES_EQUAL(K, a3 * std::cos(t3) - d4 * std::sin(t3), 1e-9);
      const double t1 = r.solutions[static_cast<std::size_t>(i)].q[0];
      DOUBLES_EQUAL(d3, -std::sin(t1) * p.x() + std::cos(t1) * p.y(), 1e-9);
    }
  }
}

TEST(IkSphericalWrist, UnreachableGivesNoSolution) {
  for (const char* name : {"puma560", "puma560_craig", "ist6"}) {
    const kin::IkModel m = prepared(name);
    kin::Pose T = kin::Pose::Identity();
    T.translation() << 5.0, 1.0, 2.0;  // metres: outside the arm's reach
    kin::IkResult r;
    kin::ik_solve_all(m, T, nullptr, r);
    LONGS_EQUAL_TEXT(0, r.count, name);
    STRCMP_EQUAL_TEXT("unreachable", kin::to_string(r.status), name);
  }
  {
    // Stanford: the telescope reaches any distance, but not a wrist centre
    // closer to the shoulder than the offset d2 = 154 mm.
    const kin::IkModel m = prepared("stanford");
    kin::Pose T = kin::Pose::Identity();
    T.translation() = Eigen::Vector3d(0.05, 0.0, 0.412) - m.w_tool;
    kin::IkResult r;
    kin::ik_solve_all(m, T, nullptr, r);
    LONGS_EQUAL(0, r.count);
    STRCMP_EQUAL("unreachable", kin::to_string(r.status));
  }
  {
    // Cylindrical RPP: every point is solvable without limits; 5 m away the
    // strokes are exceeded: out_of_limits, solutions still reported.
    const kin::IkModel m = prepared("cylindrical_rpp_rrr");
    kin::Pose T = kin::Pose::Identity();
    T.translation() << 5.0, 1.0, 2.0;
    kin::IkResult r;
    kin::ik_solve_all(m, T, nullptr, r);
    CHECK(r.count > 0);
    STRCMP_EQUAL("out_of_limits", kin::to_string(r.status));
  }
}

TEST(IkSphericalWrist, ReachLimitHasFewerSolutions) {
  // PUMA stretched: elbow branches merge (wrist centre at the largest distance
  // from the shoulder): 4 solutions, flagged elbow-singular.
  const kin::IkModel m = prepared("puma560");
  kin::JointVector q(6);
  // theta3 with a3 C3 - d4 S3 extreme: the arm straight (standard DH: theta3 = 90 - atan(a3/d4) ... )
  // find it numerically: maximise |W - shoulder| over q3.
  double best = 0, best_q3 = 0;
  for (int i = 0; i < 200000; ++i) {
    const double q3 = -M_PI + 2 * M_PI * i / 200000.0;
    q << 0.2, -0.4, q3, 0.3, 0.8, 0.1;
    const kin::Pose T = fk(m.chain, q);
    const double d = (T * m.w_tool).norm();
    if (d > best) { best = d; best_q3 = q3; }
  }
  // refine by golden section
  double lo = best_q3 - 1e-4, hi = best_q3 + 1e-4;
  for (int it = 0; it < 100; ++it) {
    const double a = lo + (hi - lo) * 0.382, b = lo + (hi - lo) * 0.618;
    q[2] = a;
    const double fa = (fk(m.chain, q) * m.w_tool).norm();
    q[2] = b;
    const double fb = (fk(m.chain, q) * m.w_tool).norm();
    if (fa > fb) hi = b; else lo = a;
  }
  q[2] = 0.5 * (lo + hi);
  const kin::Pose T = fk(m.chain, q);
  kin::IkResult r;
  kin::ik_solve_all(m, T, nullptr, r);
  LONGS_EQUAL(4, r.count);
  check_solutions(m, T, r, "reach limit");
  CHECK(r.singular_kinds & kin::kSingularElbow);
  STRCMP_EQUAL("singular", kin::to_string(r.status));
  // Just outside the reach: none.
  kin::Pose T2 = T;
  const Eigen::Vector3d W = T * m.w_tool;
  T2.translation() += 1e-4 * W.normalized();
  kin::ik_solve_all(m, T2, nullptr, r);
  LONGS_EQUAL(0, r.count);
}

TEST(IkSphericalWrist, Ist6TargetOfSeed001HasFourSolutions) {
  // Custódio et al. (IST 2019), §5: a target with only 4 solutions -- here the same situation,
  // the wrist centre at the elbow's reach limit; q3 so the arm is stretched.
  const kin::IkModel m = prepared("ist6");
  kin::JointVector q(6);
  double best = 0, bq = 0;
  for (int i = 0; i < 100000; ++i) {
    const double q3 = -M_PI + 2 * M_PI * i / 100000.0;
    q << 0.4, 0.3, q3, 0.2, 0.7, -0.5;
    const Eigen::Vector3d W = fk(m.chain, q) * m.w_tool;
    // distance from axis 2 (the elbow triangle's base): measure via |W - J2 origin| on the arm plane
    kin::FrameSet F;
    kin::Pose X;
    kin::forward_frames(m.chain, q, F, X);
    const double d = (W - F.frame[2].translation()).norm();
    if (d > best) { best = d; bq = q3; }
  }
  double lo = bq - 1e-4, hi = bq + 1e-4;
  auto dist = [&](double q3) {
    q[2] = q3;
    kin::FrameSet F;
    kin::Pose X;
    kin::forward_frames(m.chain, q, F, X);
    return ((X * m.w_tool) - F.frame[2].translation()).norm();
  };
  for (int it = 0; it < 100; ++it) {
    const double a = lo + (hi - lo) * 0.382, b = lo + (hi - lo) * 0.618;
    if (dist(a) > dist(b)) hi = b; else lo = a;
  }
  q[2] = 0.5 * (lo + hi);
  const kin::Pose T = fk(m.chain, q);
  kin::IkResult r;
  kin::ik_solve_all(m, T, nullptr, r);
  check_solutions(m, T, r, "ist6 limit");
  // The stretched shoulder branch keeps one elbow (2 wrists); the other
  // shoulder branch, at a different distance from axis 2, keeps 2 or 0.
  if (!(r.count == 6 || r.count == 2)) {
    std::string all;
    for (int i = 0; i < r.count; ++i) all += "\n  " + describe(r.solutions[static_cast<std::size_t>(i)].q);
    FAIL(("ist6 at the reach limit: " + std::to_string(r.count) + " solutions" + all).c_str());
  }
  CHECK(r.singular_kinds & kin::kSingularElbow);
}

TEST(IkSphericalWrist, WristSingularityKeepsTheCurrentJoint4) {
  for (const char* name : kWristArms) {
    const kin::IkModel m = prepared(name);
    kin::JointVector q(6);
    q << 0.3, -0.7, 0.5, 0.4, 0.0, -0.2;
    for (int j = 0; j < 3; ++j)
      if (m.chain.joint(j).type == kin::JointType::prismatic) q[j] = 0.5 * (m.chain.joint(j).lower + m.chain.joint(j).upper);
    // Joint 5's value that aligns axes 4 and 6 (theta5 = 0 for these arms).
    const kin::Pose T = fk(m.chain, q);
    kin::JointVector ref = q;
    ref[3] = 0.9;  // current joint 4
    kin::IkResult r;
    kin::ik_solve_all(m, T, &ref, r);
    check_solutions(m, T, r, name);
    CHECK_TEXT(r.singular_kinds & kin::kSingularWrist, name);
    STRCMP_EQUAL_TEXT("singular", kin::to_string(r.status), name);
    // The arm configuration with theta5 = 0 gives one representative (its two
    // wrist branches merge); the other arm configurations keep two each.
    int flagged = 0;
    bool kept = false;
    for (int i = 0; i < r.count; ++i) {
      const auto& s = r.solutions[static_cast<std::size_t>(i)];
      if (s.singular & kin::kSingularWrist) {
        ++flagged;
        kept = std::abs(kin::wrap_pi(s.q[3] - 0.9)) < 1e-9;
        // axis 6 along axis 4 (q5 = 0) or against it (q5 = 180 deg: the
        // reversed-telescope branch of Stanford and the cylindrical arm)
        DOUBLES_EQUAL(0.0, std::sin(s.q[4] - q[4]), 1e-9);
      }
    }
    // (Stanford and the cylindrical arm: the branch with the reversed
    // telescope is wrist-singular too.)
    CHECK_TEXT(flagged >= 1, name);
    LONGS_EQUAL_TEXT(generic_count(name) - flagged, r.count, name);
    CHECK_TEXT(kept, name);
  }
}

TEST(IkSphericalWrist, NearWristSingularityKeepsBothWristRootsExact) {
  // theta5 a hair off 0: the two wrist roots do not merge, q4 alone is
  // ill-conditioned (q4 + q6 is not). The second root of each arm
  // configuration is the wrist flip of the first; both must still verify by
  // the chain's FK and carry the wrist flag, and the original must be among
  // them up to the family (q4 and q6 individually).
  const double theta5[] = {1e-9, -3e-8, 1e-7, -5e-7};
  for (const char* name : kWristArms) {
    const kin::IkModel m = prepared(name);
    std::mt19937_64 rng(77);
    for (int k = 0; k < 200; ++k) {
      kin::JointVector q = random_q(m.chain, rng);
      q[4] = theta5[k % 4];
      const kin::Pose T = fk(m.chain, q);
      kin::IkResult r;
      kin::ik_solve_all(m, T, nullptr, r);
      const std::string what = std::string(name) + " " + describe(q);
      check_solutions(m, T, r, what);
      CHECK_TEXT(r.singular_kinds & kin::kSingularWrist, what.c_str());
      int near = 0;
      bool in = false;
      for (int i = 0; i < r.count; ++i) {
        const auto& s = r.solutions[static_cast<std::size_t>(i)];
        if (std::abs(std::sin(s.q[4])) < 1e-6) {
          ++near;
          CHECK_TEXT(s.singular & kin::kSingularWrist, what.c_str());
        }
        // the original, up to the singular family (q4 and q6 individually)
        kin::JointVector a = s.q, b = q;
        a[3] = b[3] = a[5] = b[5] = 0;
        in = in || joint_gap(m.chain, a, b) < 1e-6;
      }
      CHECK_TEXT(near >= 2, what.c_str());  // +t and -t, not merged
      CHECK_TEXT(in, (what + ": original (q1, q2, q3, q5) not among the solutions").c_str());
      if (std::string(name) != "ist6") LONGS_EQUAL_TEXT(generic_count(name), r.count, what.c_str());
    }
  }
}

TEST(IkSphericalWrist, ShoulderSingularityWristCentreOnAxis1) {
  // Stanford and the cylindrical arm can put the wrist centre on axis 1
  // (PUMA cannot: its shoulder offset d2; its shoulder singularity is the
  // wrist centre in the plane of axes 1 and 2).
  {
    const kin::IkModel m = prepared("cylindrical_rpp_rrr");
    kin::JointVector q(6);
    q << 0.3, 0.2, 0.0, 0.4, 0.6, -0.2;  // d3 = 0: wrist centre on axis 1
    const kin::Pose T = fk(m.chain, q);
    kin::JointVector ref = q;
    ref[0] = -1.1;
    kin::IkResult r;
    kin::ik_solve_all(m, T, &ref, r);
    check_solutions(m, T, r, "cylindrical shoulder");
    CHECK(r.count >= 1);

    CHECK(r.singular_kinds & kin::kSingularShoulder);
    bool kept = false;
    for (int i = 0; i < r.count; ++i)
      if (std::abs(r.solutions[static_cast<std::size_t>(i)].q[0] + 1.1) < 1e-9) kept = true;
    CHECK(kept);
  }
  {
    const kin::IkModel m = prepared("puma560");
    // Wrist centre in the plane of axes 1 and 2: a2 c2 + d4 s23 + a3 c23 = 0.
    kin::JointVector q(6);
    q << 0.2, 0.0, 0.0, 0.3, 0.7, 0.1;
    auto h = [&](double q2) {
      q[1] = q2;
      const Eigen::Vector3d W = fk(m.chain, q) * m.w_tool;
      return W.dot(Eigen::Vector3d(std::cos(q[0]), std::sin(q[0]), 0));
    };
    double lo = -M_PI, hi = lo;
    for (int i = 1; i <= 64; ++i) {
      hi = -M_PI + 2 * M_PI * i / 64;
      if ((h(lo) > 0) != (h(hi) > 0)) break;
      lo = hi;
    }
    for (int it = 0; it < 200; ++it) {
      const double mid = 0.5 * (lo + hi);
      if ((h(lo) > 0) == (h(mid) > 0)) lo = mid; else hi = mid;
    }
    q[1] = 0.5 * (lo + hi);
    DOUBLES_EQUAL(0.0, h(q[1]), 1e-12);
    const kin::Pose T = fk(m.chain, q);
    kin::IkResult r;
    kin::ik_solve_all(m, T, &q, r);
    check_solutions(m, T, r, "puma shoulder");
    CHECK(r.singular_kinds & kin::kSingularShoulder);
  }
}

TEST(IkSphericalWrist, AnglesAreWrappedIntoTheLimits) {
  const kin::IkModel m = prepared("puma560");
  std::mt19937_64 rng(5);
  for (int k = 0; k < 2000; ++k) {
    const kin::JointVector q = random_q(m.chain, rng);
    kin::IkResult r;
    kin::ik_solve_all(m, fk(m.chain, q), nullptr, r);
    for (int i = 0; i < r.count; ++i) {
      const auto& s = r.solutions[static_cast<std::size_t>(i)];
      for (int j = 0; j < 6; ++j) {
        const auto& row = m.chain.joint(j);
        // if some 2 pi equivalent fits the limits, the returned value does
        bool fits = false;
        for (int t = -2; t <= 2; ++t) {
          const double v = s.q[j] + 2 * M_PI * t;
          fits = fits || (v >= row.lower - 1e-12 && v <= row.upper + 1e-12);
        }
        if (fits) CHECK(s.q[j] >= row.lower - 1e-9 && s.q[j] <= row.upper + 1e-9);
      }
    }
  }
}

TEST(IkSphericalWrist, ChooseNearestWithinLimitsAndKeepBranch) {
  const kin::IkModel m = prepared("puma560");
  std::mt19937_64 rng(9);
  for (int k = 0; k < 500; ++k) {
    const kin::JointVector q = random_q(m.chain, rng);
    kin::JointVector q_near = q;
    for (int j = 0; j < 6; ++j) q_near[j] += 0.01 * std::sin(j + k);
    const kin::Pose T = fk(m.chain, q);
    kin::IkResult r;
    kin::ik_solve_all(m, T, &q_near, r);
    const int i = kin::ik_choose(m, r, q_near);
    CHECK(i >= 0);
    // nearest: the original q (in limits) is at most 0.01*sqrt(6) away
    // nearest: no solution within limits is closer to q_near than the chosen one,
    // and the original q (within limits) is at least as far
    auto dist = [&](const kin::JointVector& a) { return (a - q_near).squaredNorm(); };
    const double dc = dist(r.solutions[static_cast<std::size_t>(i)].q);
    CHECK(r.solutions[static_cast<std::size_t>(i)].within_limits);
    for (int t = 0; t < r.count; ++t)
      if (r.solutions[static_cast<std::size_t>(t)].within_limits) CHECK(dc <= dist(r.solutions[static_cast<std::size_t>(t)].q) + 1e-15);
    CHECK(dc <= dist(q) + 1e-12);
    kin::IkChoice keep;
    keep.keep_branch = true;
    const int kb = kin::ik_choose(m, r, q_near, keep);
    if (kb >= 0) CHECK(r.solutions[static_cast<std::size_t>(kb)].branch == kin::ik_branch_of(m, q_near));
    kin::JointVector out;
    CHECK(kin::is_ok(kin::ik_solve_nearest(m, T, q_near, out)));
  }
}

TEST(IkSphericalWrist, BadInputGivesAClearStatusAndNoNaN) {
  const kin::IkModel m = prepared("puma560");
  kin::IkResult r;
  kin::Pose T = fk(m.chain, kin::JointVector::Zero(6));
  kin::Pose bad = T;
  bad.translation().x() = std::numeric_limits<double>::quiet_NaN();
  kin::ik_solve_all(m, bad, nullptr, r);
  STRCMP_EQUAL("bad_input", kin::to_string(r.status));
  LONGS_EQUAL(0, r.count);
  bad = T;
  bad.translation().y() = std::numeric_limits<double>::infinity();
  kin::ik_solve_all(m, bad, nullptr, r);
  STRCMP_EQUAL("bad_input", kin::to_string(r.status));
  bad = T;
  bad.linear()(0, 0) *= 1.1;  // not orthonormal
  kin::ik_solve_all(m, bad, nullptr, r);
  STRCMP_EQUAL("bad_input", kin::to_string(r.status));
  bad = T;
  bad.linear().col(2) *= -1;  // reflection
  kin::ik_solve_all(m, bad, nullptr, r);
  STRCMP_EQUAL("bad_input", kin::to_string(r.status));
  kin::JointVector wrong(5);
  wrong.setZero();
  kin::ik_solve_all(m, T, &wrong, r);
  STRCMP_EQUAL("wrong_size", kin::to_string(r.status));
  Eigen::Matrix3d R;
  CHECK(kin::rotation_from_quaternion(0, 0, 0, 0, R) == kin::Status::bad_input);
}

// The target's rotation check (a rotation to 1e-6: every entry of R^T R - I and det R - 1
// within it) against that rule computed here with Eigen, on random rotations with random
// perturbations of 0.1x to 10x the tolerance, on a PUMA and on a reduced arm (the check comes
// before the solver). Cases within 1e-12 of the boundary are left out (rounding order).
TEST(IkSphericalWrist, RotationCheckIsTheDocumentedRule) {
  for (const char* name : {"puma560", "trr"}) {
    const kin::IkModel m = prepared(name);
    std::mt19937_64 rng(1906);
    std::normal_distribution<double> g(0, 1);
    std::uniform_real_distribution<double> lg(-7, -5);
    int rejected = 0, accepted = 0;
    kin::IkResult r;
    for (int k = 0; k < 20000; ++k) {
      const Eigen::Quaterniond qu = Eigen::Quaterniond(g(rng), g(rng), g(rng), g(rng)).normalized();
      kin::Pose T = fk(m.chain, kin::JointVector::Zero(m.chain.n_joints));
      Eigen::Matrix3d E;
      for (int i = 0; i < 9; ++i) E.data()[i] = g(rng);
      T.linear() = qu.toRotationMatrix() + std::pow(10.0, lg(rng)) * E / E.cwiseAbs().maxCoeff();
      if (k % 4 == 0) T.linear().col(k % 3) *= -1;  // reflections among them
      const Eigen::Matrix3d R = T.linear();
      const double e = std::max((R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff(),
                                std::abs(R.determinant() - 1.0));
      if (std::abs(e - 1e-6) < 1e-12) continue;
      kin::ik_solve_all(m, T, nullptr, r);
      const bool bad = r.status == kin::Status::bad_input;
      if (bad != (e > 1e-6)) FAIL((std::string(name) + ": rule error " + std::to_string(e) + ", status " + kin::to_string(r.status)).c_str());
      (bad ? rejected : accepted)++;
    }
    CHECK(rejected > 5000 && accepted > 5000);  // both sides of the boundary were reached
  }
}

TEST(IkSphericalWrist, NearestFnAdapterForMovelAndNumericFallback) {
  // kin::IkSolver{ik_nearest_fn, &model}: what plan_movel calls at every knot.
  const kin::IkModel m = prepared("ist6");
  std::mt19937_64 rng(12);
  for (int k = 0; k < 200; ++k) {
    const kin::JointVector q = random_q(m.chain, rng);
    kin::JointVector q_near = q;
    for (int j = 0; j < 6; ++j) q_near[j] += 1e-3;
    kin::JointVector out;
    const kin::Status s = kin::ik_nearest_fn(m.chain, fk(m.chain, q), q_near, out, const_cast<kin::IkModel*>(&m));
    CHECK(kin::is_ok(s));
    if (s == kin::Status::ok) CHECK(joint_gap(m.chain, out, q) < 1e-6);
  }
  // A chain with no closed form (vvr_vr, five joints): the numerical solver from the current joints.
  kin::IkModel v;
  kin::ik_prepare(model("vvr_vr"), v);
  std::mt19937_64 rng2(13);
  int ok = 0;
  for (int k = 0; k < 200; ++k) {
    const kin::JointVector q = random_q(v.chain, rng2);
    kin::JointVector q_near = q;
    for (int j = 0; j < 5; ++j) q_near[j] += 0.02;
    kin::JointVector out;
    if (kin::ik_solve_nearest(v, fk(v.chain, q), q_near, out) == kin::Status::ok) {
      ++ok;
      const kin::Pose X = fk(v.chain, out), T = fk(v.chain, q);
      CHECK((X.translation() - T.translation()).norm() < 1e-9);
      CHECK(kin::within_limits(v.chain, out, 1e-12));
    }
  }
  CHECK(ok >= 195);
  kin::JointVector out;
  kin::Pose far = kin::Pose::Identity();
  far.translation() << 5, 0, 0;
  STRCMP_EQUAL("unreachable", kin::to_string(kin::ik_solve_nearest(m, far, kin::JointVector::Zero(6), out)));
}

// ---------------------------------------------------------------------------
// The fast path's pieces: atan2_poly (fast_trig.hpp) against std::atan2, and
// the errors the solver reports (computed from its own decomposition) against
// the chain's FK.
// ---------------------------------------------------------------------------
#include "../../kinematics/src/fast_trig.hpp"

TEST_GROUP(IkFastPath){};

TEST(IkFastPath, Atan2PolyMatchesStdAtan2) {
  std::mt19937_64 rng(77);
  std::uniform_real_distribution<double> u(-3, 3);
  double worst = 0;
  for (int i = 0; i < 2000000; ++i) {
    double y = u(rng), x = u(rng);
    if (i % 5 == 1) y *= 1e-9;    // near the axes
    if (i % 7 == 2) x *= 1e-12;
    if (i % 11 == 3) x = y * (1 + 1e-15 * u(rng));  // near the diagonal (reduction switch)
    if (i % 13 == 4) x = y * 0.66;                   // at the rational's switch point
    worst = std::max(worst, std::abs(servoarm::kin::detail::atan2_poly(y, x) - std::atan2(y, x)));
  }
  CHECK(worst < 1e-15);
  // Signs and zeros as std::atan2.
  const double z[] = {0.0, -0.0, 1.0, -1.0, 1e-30, -1e-30, 1e30, -1e30};  // (no underflow: the FP plugin traps it)
  for (double y : z)
    for (double x : z) {
      const double a = servoarm::kin::detail::atan2_poly(y, x), b = std::atan2(y, x);
      if (!(std::abs(a - b) <= 1e-15)) FAIL(("atan2_poly(" + std::to_string(y) + ", " + std::to_string(x) + ")").c_str());
      CHECK(std::signbit(a) == std::signbit(b));
    }
}

TEST(IkFastPath, ReportedErrorsAgreeWithTheChainFk) {
  for (const char* name : kWristArms) {
    const kin::IkModel m = prepared(name);
    std::mt19937_64 rng(21);
    for (int k = 0; k < 2000; ++k) {
      const kin::JointVector q = random_q(m.chain, rng);
      const kin::Pose T = fk(m.chain, q);
      kin::IkResult r;
      kin::ik_solve_all(m, T, nullptr, r);
      for (int i = 0; i < r.count; ++i) {
        const auto& s = r.solutions[static_cast<std::size_t>(i)];
        const kin::Pose X = fk(m.chain, s.q);
        const double ep = (X.translation() - T.translation()).norm();
        const double er = kin::rotation_error(X.linear(), T.linear()).norm();
        // both are rounding-level: they agree to rounding
        if (!(std::abs(ep - s.position_error) < 1e-12 && std::abs(er - s.rotation_error) < 1e-12))
          FAIL((std::string(name) + " " + describe(s.q) + ": reported " + std::to_string(s.position_error) + " / " +
                std::to_string(s.rotation_error) + ", FK " + std::to_string(ep) + " / " + std::to_string(er))
                   .c_str());
      }
    }
  }
}

TEST(IkFastPath, Atan2PolyX2IsTheScalarVersionBitForBit) {
  std::mt19937_64 rng(78);
  std::uniform_real_distribution<double> u(-3, 3);
  const double z[] = {0.0, -0.0, 1.0, -1.0, 0.66, -0.66, 1e-30, -1e-30, 1e30, -1e30};
  std::vector<double> ys, xs;
  for (double y : z)
    for (double x : z) {
      ys.push_back(y);
      xs.push_back(x);
    }
  for (int i = 0; i < 200000; ++i) {
    double y = u(rng), x = u(rng);
    if (i % 5 == 1) y *= 1e-9;
    if (i % 7 == 2) x *= 1e-12;
    if (i % 11 == 3) x = y;
    if (i % 13 == 4) x = y * 0.66;
    ys.push_back(y);
    xs.push_back(x);
  }
  if (ys.size() % 2) {
    ys.push_back(0.0);
    xs.push_back(1.0);
  }
  for (std::size_t i = 0; i < ys.size(); i += 2) {
    double out[2];
    servoarm::kin::detail::atan2_poly_x2(&ys[i], &xs[i], out);
    for (std::size_t k = 0; k < 2; ++k) {
      const double s = servoarm::kin::detail::atan2_poly(ys[i + k], xs[i + k]);
      if (std::memcmp(&s, &out[k], sizeof s) != 0)
        FAIL(("atan2_poly_x2(" + std::to_string(ys[i + k]) + ", " + std::to_string(xs[i + k]) + ")").c_str());
    }
  }
}

// The per-joint wrap table of ik_prepare (IkJointWrap, ik_detail.hpp): the
// branch-free form for joints whose limits span less than a turn gives what
// the rule (wrap_into_limits) gives, on a case table and random angles,
// references and limits.
#include "../../kinematics/src/ik/ik_detail.hpp"

namespace {
// A revolute DH row with only its limits set (the wrap tests below).
kin::DhRow revolute_row(double lo, double hi) {
  kin::DhRow r;
  r.type = kin::JointType::revolute;
  r.lower = lo;
  r.upper = hi;
  return r;
}
}  // namespace

TEST(IkFastPath, NarrowWrapMatchesTheRule) {
  using servoarm::kin::detail::kTwoPi;
  auto check = [&](const kin::DhRow& r, double w, double ref) {
    const kin::IkJointWrap j = servoarm::kin::detail::make_joint_wrap(r);
    const double rule = servoarm::kin::detail::wrap_into_limits(w, j.lo, j.hi, ref);
    if (!servoarm::kin::detail::narrow_applies(j, ref)) return false;
    const double fast = servoarm::kin::detail::wrap_narrow(j, w);
    // the same equivalent (ulp-level differences: w + 2 pi k vs. turns added one by one)
    if (!(std::abs(fast - rule) <= 1e-14))
      FAIL(("limits [" + std::to_string(r.lower) + ", " + std::to_string(r.upper) + "] w=" + std::to_string(w) +
            " ref=" + std::to_string(ref) + ": " + std::to_string(fast) + " vs rule " + std::to_string(rule)).c_str());
    return true;
  };
  const double d = M_PI / 180;
  // Case table: PUMA-like limits, limits off zero, beyond +-pi, a span just
  // under a turn; angles inside, outside, at the limits, at +-pi.
  const double lims[][2] = {{-160 * d, 160 * d}, {-225 * d, 45 * d}, {-45 * d, 225 * d}, {-110 * d, 170 * d},
                            {-100 * d, 100 * d}, {100 * d, 350 * d}, {-350 * d, -100 * d}, {0, kTwoPi - 1e-6},
                            {-M_PI, M_PI - 1e-9}, {400 * d, 500 * d}, {-500 * d, -400 * d}};
  const double ws[] = {0.0, 0.5, -0.5, 1.0, -1.0, 2.5, -2.5, M_PI, -M_PI + 1e-15, 45 * d, -45 * d, 160 * d, -160 * d,
                       170 * d, 100 * d, -100 * d, 135 * d, -135 * d};
  const double refs[] = {0.0, 1.0, -1.0, 3.0, -3.0, 6.0, -6.0, 7.5};
  int used = 0;
  for (const auto& l : lims)
    for (double w : ws)
      for (double ref : refs) used += check(revolute_row(l[0], l[1]), w, ref) ? 1 : 0;
  CHECK(used > 1000);
  // Explicit expectations.
  const kin::IkJointWrap j2 = servoarm::kin::detail::make_joint_wrap(revolute_row(-225 * d, 45 * d));
  LONGS_EQUAL(1, j2.kind);
  DOUBLES_EQUAL(135 * d - kTwoPi, servoarm::kin::detail::wrap_narrow(j2, 135 * d), 1e-15);  // -225 deg
  DOUBLES_EQUAL(90 * d, servoarm::kin::detail::wrap_narrow(j2, 90 * d), 0);                // nothing fits: unchanged
  LONGS_EQUAL(2, servoarm::kin::detail::make_joint_wrap(revolute_row(-266 * d, 266 * d)).kind);     // wide: the rule
  kin::DhRow p = revolute_row(-1, 1);
  p.type = kin::JointType::prismatic;
  LONGS_EQUAL(0, servoarm::kin::detail::make_joint_wrap(p).kind);
  kin::DhRow inf = revolute_row(-std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity());
  LONGS_EQUAL(2, servoarm::kin::detail::make_joint_wrap(inf).kind);
  // Random limits (span < a turn), angles, references within a turn of the limits.
  std::mt19937_64 rng(31);
  std::uniform_real_distribution<double> u(0, 1);
  int n = 0;
  for (int i = 0; i < 200000; ++i) {
    const double lo = -2.9 * M_PI + 5.0 * M_PI * u(rng);
    const double hi = std::min(lo + kTwoPi * u(rng), 2.95 * M_PI);
    const double w = -M_PI + kTwoPi * u(rng);
    const double ref = lo - kTwoPi + (hi - lo + 2 * kTwoPi) * u(rng);
    n += check(revolute_row(lo, hi), w, ref) ? 1 : 0;
  }
  CHECK(n > 150000);
}

// The quick exit of the reduced arms' wrap (IkJointWrap::in_abs): an
// angle w in (-pi, pi] with |w| < in_abs is what the rule (wrap_into_limits)
// and the narrow form give for any reference, and within the limits widened
// by 1e-9; it exists for the usual limits around zero and is off where two
// equivalents fit everywhere or the limits miss zero.
TEST(IkFastPath, QuickWrapExitKeepsWhatTheRuleGives) {
  using servoarm::kin::detail::kTwoPi;
  int quick = 0;
  auto check = [&](const kin::DhRow& r, double w, double ref) {
    const kin::IkJointWrap j = servoarm::kin::detail::make_joint_wrap(r);
    // below pi: the reduced paths test |v| < in_abs before wrapping v at all
    if (!(j.in_abs < M_PI)) FAIL(("in_abs " + std::to_string(j.in_abs) + " not below pi").c_str());
    if (!(std::abs(w) < j.in_abs)) return;
    ++quick;
    const double rule = servoarm::kin::detail::wrap_into_limits(w, j.lo, j.hi, ref);
    const bool narrow_ok =
        !servoarm::kin::detail::narrow_applies(j, ref) || servoarm::kin::detail::wrap_narrow(j, w) == w;
    if (!(rule == w && narrow_ok && w >= j.lo9 && w <= j.hi9))
      FAIL(("limits [" + std::to_string(r.lower) + ", " + std::to_string(r.upper) + "] w=" + std::to_string(w) +
            " ref=" + std::to_string(ref) + ": rule " + std::to_string(rule))
               .c_str());
  };
  const double d = M_PI / 180;
  const double lims[][2] = {{-M_PI, M_PI},         {-180 * d, 180 * d}, {-160 * d, 160 * d}, {-225 * d, 45 * d},
                            {-45 * d, 225 * d},    {-110 * d, 170 * d}, {-266 * d, 266 * d}, {-350 * d, 350 * d},
                            {100 * d, 350 * d},    {-M_PI, M_PI - 1e-9}, {-2 * M_PI, 2 * M_PI}, {0, kTwoPi - 1e-6}};
  const double refs[] = {0.0, 1.0, -1.0, 3.0, -3.0, M_PI, -M_PI, 6.0, -6.0, 7.5, -20.0, 1e6};
  for (const auto& l : lims) {
    const kin::IkJointWrap j = servoarm::kin::detail::make_joint_wrap(revolute_row(l[0], l[1]));
    // the boundary itself and just either side of it, then a grid
    const double b = j.in_abs;
    // (no nextafter from 0: a subnormal raises FE_UNDERFLOW, which the test plugin rejects)
    const double ws[] = {b, -b, b - 1e-15, -(b - 1e-15), b + 1e-15, 0.0,
                         M_PI, -M_PI + 1e-15, M_PI - 1e-9, -M_PI + 1e-9, M_PI - 1e-7, -M_PI + 1e-7};
    for (double w : ws)
      for (double ref : refs) check(revolute_row(l[0], l[1]), w, ref);
    for (int k = -1000; k <= 1000; ++k)
      for (double ref : refs) check(revolute_row(l[0], l[1]), M_PI * k / 1000.0, ref);
  }
  // where it exists: +-180 degrees up to 1e-7 rad from +-pi (a float rounded down), not
  // for limits that miss zero, nor where every angle has two equivalents inside
  CHECK(servoarm::kin::detail::make_joint_wrap(revolute_row(-M_PI, M_PI)).in_abs > M_PI - 1e-6);
  CHECK(servoarm::kin::detail::make_joint_wrap(revolute_row(-160 * d, 160 * d)).in_abs > 160 * d - 1e-6);
  DOUBLES_EQUAL(0.0, servoarm::kin::detail::make_joint_wrap(revolute_row(100 * d, 350 * d)).in_abs, 0);
  DOUBLES_EQUAL(0.0, servoarm::kin::detail::make_joint_wrap(revolute_row(-2 * M_PI, 2 * M_PI)).in_abs, 0);
  kin::DhRow inf = revolute_row(-std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity());
  DOUBLES_EQUAL(0.0, servoarm::kin::detail::make_joint_wrap(inf).in_abs, 0);
  kin::DhRow p = revolute_row(-1, 1);
  p.type = kin::JointType::prismatic;
  DOUBLES_EQUAL(0.0, servoarm::kin::detail::make_joint_wrap(p).in_abs, 0);
  // random limits, angles and references
  std::mt19937_64 rng(37);
  std::uniform_real_distribution<double> u(0, 1);
  for (int i = 0; i < 200000; ++i) {
    const double lo = -2.9 * M_PI + 4.0 * M_PI * u(rng);
    const double hi = lo + 2.5 * kTwoPi * u(rng);
    check(revolute_row(lo, hi), -M_PI + kTwoPi * u(rng), -10.0 + 20.0 * u(rng));
  }
  CHECK(quick > 100000);
}
