// SPDX-License-Identifier: Apache-2.0
// Closed forms of Carrara, Apostila de Robótica, chapter 4 (RR, RRR, RLR, TRR, TRL:R, VVL:R),
// recognised from the DH rows: round trip on random configurations, the
// original among the solutions, the seed's formulas, unreachable targets.
#include <cstdlib>
#include <vector>

#include "servoarm/kinematics/ik.hpp"
#include "kin_test_util.hpp"
#include "sweep.hpp"

using namespace servoarm;
using namespace servoarm::test;

namespace {

struct Case {
  const char* name;
  const char* method;
  bool full_pose;  ///< the arm controls the target's rotation (the reachable part)
  int max_count;
};
const Case kCases[] = {
    {"rr_planar", "planar_2r", false, 2},  {"rrr_planar", "planar_3", true, 2}, {"rlr_planar", "planar_3", true, 2},
    {"trr", "spatial_3", false, 4},        {"trl_r", "pitch_4", true, 2},       {"vvl_r", "pitch_4", true, 2},
};

int samples() {
  const char* s = std::getenv("SERVOARM_IK_SAMPLES");
  return s ? std::atoi(s) : servoarm::test::sweep(100000);  // 1/20 under qemu and the sanitizers
}

double gap(const kin::Chain& c, const kin::JointVector& a, const kin::JointVector& b) {
  double g = 0;
  for (int j = 0; j < c.n_joints; ++j) {
    const double d = a[j] - b[j];
    g = std::max(g, c.joint(j).type == kin::JointType::revolute ? std::abs(kin::wrap_pi(d)) : std::abs(d));
  }
  return g;
}

}  // namespace

TEST_GROUP(IkReduced){};

TEST(IkReduced, RecognisedFromTheDhRows) {
  for (const Case& k : kCases) {
    kin::IkModel m;
    kin::ik_prepare(model(k.name), m);
    STRCMP_EQUAL_TEXT(k.method, kin::to_string(m.method), k.name);
  }
  kin::IkModel m;
  kin::ik_prepare(model("vvr_vr"), m);  // five joints, no closed form: numeric
  STRCMP_EQUAL("numeric", kin::to_string(m.method));
}

TEST(IkReduced, RoundTripAndOriginalAmongSolutions) {
  const int n = samples();
  for (const Case& k : kCases) {
    kin::IkModel m;
    kin::ik_prepare(model(k.name), m);
    std::mt19937_64 rng(77);
    long total = 0;
    int found = 0, singular = 0;
    for (int s = 0; s < n; ++s) {
      const kin::JointVector q = random_q(m.chain, rng);
      const kin::Pose T = fk(m.chain, q);
      kin::IkResult r;
      kin::ik_solve_all(m, T, nullptr, r);
      const std::string what = std::string(k.name) + " " + describe(q);
      if (r.count == 0 || r.count > k.max_count) FAIL((what + " count " + std::to_string(r.count)).c_str());
      total += r.count;
      bool in = false;
      for (int i = 0; i < r.count; ++i) {
        const kin::JointVector& x = r.solutions[static_cast<std::size_t>(i)].q;
        const kin::Pose X = fk(m.chain, x);
        const double ep = (X.translation() - T.translation()).norm();
        const double er = k.full_pose ? kin::rotation_error(X.linear(), T.linear()).norm() : 0.0;
        if (!(ep <= 1e-9 && er <= 1e-9))
          FAIL((what + " solution " + describe(x) + " ep " + std::to_string(ep) + " er " + std::to_string(er)).c_str());
        in = in || gap(m.chain, x, q) < 1e-6;
      }
      if (r.singular_kinds) ++singular;
      if (in) ++found;
      else if (!r.singular_kinds) FAIL((what + ": original not among the solutions").c_str());
    }
    std::printf("\n  %-12s %d poses: %.3f solutions/pose, original found %d, singular %d", k.name, n,
                static_cast<double>(total) / n, found, singular);
  }
}

TEST(IkReduced, MatchesTheSeedFormulas) {
  // RR (Carrara, Apostila de Robótica, 4.1): theta2 = +-acos((x^2 + y^2 - a1^2 - a2^2) / (2 a1 a2)).
  {
    kin::IkModel m;
    kin::ik_prepare(model("rr_planar"), m);
    const double a1 = 0.3, a2 = 0.25, x = 0.35, y = 0.2;
    kin::Pose T = kin::Pose::Identity();
    T.translation() << x, y, 0;
    kin::IkResult r;
    kin::ik_solve_all(m, T, nullptr, r);
    LONGS_EQUAL(2, r.count);
    const double t2 = std::acos((x * x + y * y - a1 * a1 - a2 * a2) / (2 * a1 * a2));
    for (int i = 0; i < 2; ++i) {
      const auto& q = r.solutions[static_cast<std::size_t>(i)].q;
      DOUBLES_EQUAL(t2, std::abs(q[1]), 1e-12);
      const double t1 = std::atan2(y * (a1 + a2 * std::cos(q[1])) - x * a2 * std::sin(q[1]),
                                   x * (a1 + a2 * std::cos(q[1])) + y * a2 * std::sin(q[1]));
      DOUBLES_EQUAL(t1, q[0], 1e-12);
    }
    CHECK(r.solutions[0].branch.elbow != r.solutions[1].branch.elbow);
  }
  // TRR (Carrara, Apostila de Robótica, 4.4): theta3 = +-acos((x^2+y^2+(z-a1)^2-a2^2-a3^2)/(2 a2 a3)), 4 solutions.
  {
    kin::IkModel m;
    kin::ik_prepare(model("trr"), m);
    const double a1 = 0.3, a2 = 0.25, a3 = 0.2, x = 0.2, y = 0.15, z = 0.45;
    kin::Pose T = kin::Pose::Identity();
    T.translation() << x, y, z;
    kin::IkResult r;
    kin::ik_solve_all(m, T, nullptr, r);
    LONGS_EQUAL(4, r.count);
    const double t3 = std::acos((x * x + y * y + (z - a1) * (z - a1) - a2 * a2 - a3 * a3) / (2 * a2 * a3));
    int front = 0;
    for (int i = 0; i < 4; ++i) {
      const auto& s = r.solutions[static_cast<std::size_t>(i)];
      DOUBLES_EQUAL(t3, std::abs(s.q[2]), 1e-12);
      if (std::abs(kin::wrap_pi(s.q[0] - std::atan2(y, x))) < 1e-12) ++front;
      if (std::abs(std::abs(kin::wrap_pi(s.q[0] - std::atan2(y, x))) - M_PI) < 1e-12) --front;
    }
    LONGS_EQUAL(0, front);  // two shoulder front, two back
  }
  // VVL:R (Carrara, Apostila de Robótica, 4.6): a3 = sqrt((z - a1 - a4 s_phi)^2 + (sqrt(x^2+y^2-a2^2) - a4 c_phi)^2).
  {
    kin::IkModel m;
    kin::ik_prepare(model("vvl_r"), m);
    kin::JointVector q(4);
    q << 0.4, 0.3, 0.35, -0.2;
    const kin::Pose T = fk(m.chain, q);
    kin::IkResult r;
    kin::ik_solve_all(m, T, nullptr, r);
    CHECK(r.count >= 1);
    const double a1 = 0.3, a2 = 0.1, a4 = 0.1;
    const Eigen::Vector3d p = T.translation();
    const Eigen::Vector3d xt = T.linear().col(0);
    const double phi = std::atan2(xt.z(), std::hypot(xt.x(), xt.y()));
    const double a3 = std::hypot(p.z() - a1 - a4 * std::sin(phi),
                                 std::sqrt(p.x() * p.x() + p.y() * p.y() - a2 * a2) - a4 * std::cos(phi));
    bool match = false;
    for (int i = 0; i < r.count; ++i) match = match || std::abs(r.solutions[static_cast<std::size_t>(i)].q[2] - a3) < 1e-9;
    CHECK(match);
  }
}

TEST(IkReduced, UnreachableAndOffPlane) {
  for (const Case& k : kCases) {
    kin::IkModel m;
    kin::ik_prepare(model(k.name), m);
    kin::Pose T = kin::Pose::Identity();
    T.translation() << 3.0, 2.0, 0.0;
    kin::IkResult r;
    kin::ik_solve_all(m, T, nullptr, r);
    // the telescopic arms reach any distance mathematically: then out_of_limits
    if (r.count == 0) STRCMP_EQUAL_TEXT("unreachable", kin::to_string(r.status), k.name);
    else STRCMP_EQUAL_TEXT("out_of_limits", kin::to_string(r.status), k.name);
  }
  kin::IkModel m;
  kin::ik_prepare(model("rr_planar"), m);
  kin::Pose T = kin::Pose::Identity();
  T.translation() << 0.3, 0.2, 0.05;  // off the arm's plane
  kin::IkResult r;
  kin::ik_solve_all(m, T, nullptr, r);
  LONGS_EQUAL(0, r.count);
}

TEST(IkReduced, StretchedElbowIsOneSingularSolution) {
  kin::IkModel m;
  kin::ik_prepare(model("rr_planar"), m);
  kin::Pose T = kin::Pose::Identity();
  T.translation() << 0.55 * std::cos(0.3), 0.55 * std::sin(0.3), 0;
  kin::IkResult r;
  kin::ik_solve_all(m, T, nullptr, r);
  LONGS_EQUAL(1, r.count);
  CHECK(r.singular_kinds & kin::kSingularElbow);
  STRCMP_EQUAL("singular", kin::to_string(r.status));
}

#include "../../kinematics/src/ik/ik_detail.hpp"

namespace {
// The reference: every candidate through the chain's FK, Gauss-Newton and Jacobian
// (detail::solve_reduced_slow, what solve_reduced did before its cheap paths), with
// ik_solve_all's status rule.
void solve_slow(const kin::IkModel& m, const kin::Pose& T, const kin::JointVector* ref, kin::IkResult& r) {
  r.count = 0;
  r.singular_kinds = 0;
  kin::detail::solve_reduced_slow(m, T, ref, r);
  bool any_in = false;
  for (int i = 0; i < r.count; ++i) {
    r.singular_kinds |= r.solutions[static_cast<std::size_t>(i)].singular;
    any_in = any_in || r.solutions[static_cast<std::size_t>(i)].within_limits;
  }
  r.status = r.count == 0 ? kin::Status::unreachable
             : !any_in    ? kin::Status::out_of_limits
             : r.singular_kinds ? kin::Status::singular
                                : kin::Status::ok;
}

// fast (ik_solve_all) against the chain path's slow, solution by solution: the same
// configurations (1e-9; 1e-6 where flagged singular: a root clamped ~1e-8 rad off, polished
// by the chain path), order, branches, limit and singular flags, and what each says it is:
// the chain's FK reaches the (reachable part of the) target, its errors within 1e-9.
void same_as_chain(const kin::IkModel& m, const kin::Pose& T, const kin::IkResult& fast, const kin::IkResult& slow,
                   const std::string& what) {
  LONGS_EQUAL_TEXT(slow.count, fast.count, what.c_str());
  for (int i = 0; i < fast.count; ++i) {
    const auto& a = fast.solutions[static_cast<std::size_t>(i)];
    const auto& b = slow.solutions[static_cast<std::size_t>(i)];
    const double tol = a.singular ? 1e-6 : 1e-9;
    CHECK_TEXT(gap(m.chain, a.q, b.q) < tol, (what + " solution " + describe(a.q) + " vs " + describe(b.q)).c_str());
    LONGS_EQUAL_TEXT(b.branch.shoulder, a.branch.shoulder, what.c_str());
    LONGS_EQUAL_TEXT(b.branch.elbow, a.branch.elbow, what.c_str());
    CHECK_TEXT(a.within_limits == b.within_limits, what.c_str());
    LONGS_EQUAL_TEXT(b.singular, a.singular, what.c_str());
    const kin::Pose X = fk(m.chain, a.q);
    CHECK_TEXT((X.translation() - T.translation()).norm() <= 1e-9, what.c_str());
    CHECK_TEXT(a.position_error <= 1e-9 && a.rotation_error <= 1e-9, what.c_str());
  }
}
}  // namespace

TEST(IkReduced, CheapPathGivesWhatTheChainPathGives) {
  // Issue 19 (reduced arms <= 100 ns): planar_3, spatial_3 and pitch_4 verify through the
  // decomposition, not the chain's FK. Same solutions (1e-9), order, branches, limits and
  // singular flags as the chain path, on random poses, with and without a reference, on
  // poses with the elbow stretched or folded (joint 2 / 3 at 0 or pi, the prismatic joint
  // at a limit), and out of reach.
  const int n = std::max(2000, samples() / 10);
  for (const Case& k : kCases) {
    if (std::string(k.method) == "planar_2r") continue;
    kin::IkModel m;
    kin::ik_prepare(model(k.name), m);
    CHECK_TEXT(kin::detail::solver_data(m).red_fast, k.name);
    std::mt19937_64 rng(1919);
    int flagged = 0;
    for (int s = 0; s < n; ++s) {
      kin::JointVector q = random_q(m.chain, rng);
      const int cls = s % 5;
      const int e = std::string(k.method) == "planar_3" ? 1 : 2;  // the joint that stretches the arm
      if (cls == 1 || cls == 2) {
        const kin::DhRow& row = m.chain.joint(e);
        if (row.type == kin::JointType::revolute) q[e] = cls == 1 ? 0.0 : M_PI - 1e-9;
        else q[e] = cls == 1 ? row.lower : row.upper;
      }
      kin::Pose T = fk(m.chain, q);
      if (cls == 3) T.translation() *= 4.0;
      const kin::JointVector ref = random_q(m.chain, rng);
      for (const kin::JointVector* r : {static_cast<const kin::JointVector*>(nullptr), &ref}) {
        kin::IkResult fast, slow;
        kin::ik_solve_all(m, T, r, fast);
        solve_slow(m, T, r, slow);
        const std::string what = std::string(k.name) + " " + describe(q) + (r ? " ref " + describe(*r) : "");
        STRCMP_EQUAL_TEXT(kin::to_string(slow.status), kin::to_string(fast.status), what.c_str());
        LONGS_EQUAL_TEXT(slow.singular_kinds, fast.singular_kinds, what.c_str());
        if (fast.singular_kinds) ++flagged;
        if (cls == 1 || cls == 2) {
          // Stretched / folded: the two roots lie ~1e-8 rad apart. The cheap path keeps
          // them where they verify (one solution after de-duplication, as planar_2r); the
          // chain path's Gauss-Newton may move them apart: the same configurations to 1e-6.
          CHECK_TEXT(fast.count >= 1 && fast.count <= slow.count,
                     (what + " counts " + std::to_string(fast.count) + " / " + std::to_string(slow.count)).c_str());
          auto covered = [&](const kin::IkResult& x, const kin::IkResult& y) {
            for (int i = 0; i < x.count; ++i) {
              bool near = false;
              for (int j = 0; j < y.count && !near; ++j)
                near = gap(m.chain, x.solutions[static_cast<std::size_t>(i)].q, y.solutions[static_cast<std::size_t>(j)].q) < 1e-6;
              if (!near) return false;
            }
            return true;
          };
          CHECK_TEXT(covered(fast, slow) && covered(slow, fast), what.c_str());
          for (int i = 0; i < fast.count; ++i) {
            const kin::Pose X = fk(m.chain, fast.solutions[static_cast<std::size_t>(i)].q);
            CHECK_TEXT((X.translation() - T.translation()).norm() <= 1e-9, what.c_str());
          }
          continue;
        }
        same_as_chain(m, T, fast, slow, what);
      }
    }
    std::printf("\n  %-12s %d poses: cheap path = chain path, %d results flagged singular", k.name, n, flagged);
  }
}

TEST(IkReduced, MergeBandIsOneRuleOnBothPaths) {
  // The planar arms' elbow near stretched / folded: the two roots (2 q_e apart) are one
  // configuration when |sin 2 q_e| < 2e-6 (merge_close_roots), on the cheap path and on the
  // chain path alike. Before the chain path took that rule it kept two solutions at
  // q_e = 9.1e-7 (the pose 10^6 random samples found), the cheap path one. The count expected
  // is the rule's, computed here from q_e; the values keep 1e-9 from its edge.
  for (const char* name : {"rr_planar", "rrr_planar"}) {
    kin::IkModel m;
    kin::ik_prepare(model(name), m);
    for (const double t : {5e-7, 9.1066506602288655e-7, 9.99e-7, 1.001e-6, 1.5e-6, 3e-6})
      for (const double base : {0.0, M_PI})
        for (const double sgn : {1.0, -1.0}) {
          kin::JointVector q = kin::JointVector::Zero(m.chain.n_joints);
          q[0] = 0.985520;
          q[1] = base + sgn * t;
          if (m.chain.n_joints > 2) q[2] = -3.111702;
          const kin::Pose T = fk(m.chain, q);
          kin::IkResult fast, slow;
          kin::ik_solve_all(m, T, nullptr, fast);
          solve_slow(m, T, nullptr, slow);
          const int expected = std::abs(std::sin(2 * t)) < 2e-6 ? 1 : 2;
          const std::string what = std::string(name) + " " + describe(q);
          LONGS_EQUAL_TEXT(expected, fast.count, ("cheap path " + what).c_str());
          LONGS_EQUAL_TEXT(expected, slow.count, ("chain path " + what).c_str());
        }
  }
}

TEST(IkReduced, SpatialLanesGiveWhatTheChainPathGives) {
  // Issue 19: spatial_3's lanes (case A of the position subproblem: the four configurations
  // two at a time, detail::solve_spatial_3_lanes) on the seed's TRR and on variants built
  // here: offsets along the parallel axes, twist -90 with joint offsets, a reversed joint
  // with narrow limits (values outside the limits take emit's wrap), and a shoulder offset
  // a1 (not case A: the lanes stay off, the other paths answer). Each: what ik_solve_all
  // gives equals the chain path's solutions (1e-9), order, branches, limit and singular
  // flags; where the lanes answered, ik_solve_all gave their solutions bit for bit; and
  // they answered all but a few random poses (the rest: handed over, the chain path's
  // answer all the same).
  struct Variant {
    const char* what;
    double d2, d3, a1, alpha1, th2, th3, dir3, lim;
    bool lanes;
  };
  const Variant kV[] = {
      {"seed TRR rows", 0, 0, 0, 90, 0, 0, 1, 180, true},
      {"d2 = 50 mm", 0.05, 0, 0, 90, 0, 0, 1, 180, true},
      {"d3 = -30 mm", 0, -0.03, 0, 90, 0, 0, 1, 180, true},
      {"alpha1 = -90, theta2 = 30, theta3 = -45", 0, 0, 0, -90, 30, -45, 1, 180, true},
      {"joint 3 reversed, limits +-100, d2 = 20 mm", 0.02, 0, 0, 90, 0, 0, -1, 100, true},
      {"a1 = 40 mm (not case A)", 0, 0, 0.04, 90, 0, 0, 1, 180, false},
  };
  const int n = std::max(2000, samples() / 20);
  for (const Variant& v : kV) {
    kin::Chain c;
    auto row = [&](double theta, double d, double a, double alpha, double dir) {
      kin::DhRow r;
      r.theta = deg(theta);
      r.d = d;
      r.a = a;
      r.alpha = deg(alpha);
      r.direction = dir;
      r.lower = deg(-v.lim);
      r.upper = deg(v.lim);
      CHECK_TEXT(kin::add_row(c, r) == kin::Status::ok, v.what);
    };
    row(0, 0.3, v.a1, v.alpha1, 1);
    row(v.th2, v.d2, 0.25, 0, 1);
    row(v.th3, v.d3, 0.2, 0, v.dir3);
    kin::IkModel m;
    CHECK_TEXT(kin::ik_prepare(c, m) == kin::Status::ok, v.what);
    STRCMP_EQUAL_TEXT("spatial_3", kin::to_string(m.method), v.what);
    CHECK_TEXT(kin::detail::solver_data(m).s3.on == v.lanes, v.what);
    std::mt19937_64 rng(1903);
    int answered = 0, outside = 0;
    for (int s = 0; s < n; ++s) {
      const kin::JointVector q = random_q(m.chain, rng);
      const kin::Pose T = fk(m.chain, q);
      const kin::JointVector ref = random_q(m.chain, rng);
      for (const kin::JointVector* r : {static_cast<const kin::JointVector*>(nullptr), &ref}) {
        kin::IkResult fast, slow, lanes;
        kin::ik_solve_all(m, T, r, fast);
        solve_slow(m, T, r, slow);
        lanes.count = 0;
        const bool yes = kin::detail::solve_spatial_3_lanes(m, T, r, lanes);
        const std::string what = std::string(v.what) + " " + describe(q) + (r ? " ref " + describe(*r) : "");
        STRCMP_EQUAL_TEXT(kin::to_string(slow.status), kin::to_string(fast.status), what.c_str());
        LONGS_EQUAL_TEXT(slow.singular_kinds, fast.singular_kinds, what.c_str());
        same_as_chain(m, T, fast, slow, what);
        if (yes) {
          ++answered;
          LONGS_EQUAL_TEXT(4, lanes.count, what.c_str());
        }
        for (int i = 0; i < fast.count; ++i) {
          const auto& a = fast.solutions[static_cast<std::size_t>(i)];
          if (!a.within_limits) ++outside;
          if (yes) {
            const auto& l = lanes.solutions[static_cast<std::size_t>(i)];
            CHECK_TEXT(gap(m.chain, a.q, l.q) == 0.0 && a.branch == l.branch && a.singular == l.singular &&
                           a.within_limits == l.within_limits && a.position_error == l.position_error,
                       what.c_str());
          }
        }
      }
    }
    std::printf("\n  %-42s %d poses x 2: the lanes answered %d, %d solutions outside the limits", v.what, n,
                answered, outside);
    if (v.lanes) CHECK_TEXT(answered >= 2 * n * 99 / 100, v.what);
    else LONGS_EQUAL_TEXT(0, answered, v.what);
  }
}

TEST(IkReduced, TwoDimensionalFormsAnswerRandomPoses) {
  // Issue 19: the 2-D closed forms (detail::solve_reduced_2d: the forward map in the
  // reduced coordinates as the check) answer every random pose themselves, not by
  // handing it to the 3-D paths, and what they answer reproduces the target through
  // the chain's FK; they are set up for every seed arm (IkSolverData::Planar).
  const int n = std::max(2000, samples() / 10);
  for (const Case& k : kCases) {
    kin::IkModel m;
    kin::ik_prepare(model(k.name), m);
    if (std::string(k.method) != "spatial_3") CHECK_TEXT(kin::detail::solver_data(m).pl.on, k.name);
    const bool is_2r = std::string(k.method) == "planar_2r";
    std::mt19937_64 rng(2020);
    int answered = 0;
    for (int s = 0; s < n; ++s) {
      const kin::JointVector q = random_q(m.chain, rng);
      const kin::Pose T = fk(m.chain, q);
      const kin::JointVector ref = random_q(m.chain, rng);
      kin::IkResult r2, all;
      r2.count = 0;
      const bool yes = kin::detail::solve_reduced_2d(m, T, s % 2 ? &ref : nullptr, r2);
      kin::ik_solve_all(m, T, s % 2 ? &ref : nullptr, all);
      if (!yes) continue;
      ++answered;
      const std::string what = std::string(k.name) + " " + describe(q);
      LONGS_EQUAL_TEXT(all.count, r2.count, what.c_str());
      bool in = false;
      for (int i = 0; i < r2.count; ++i) {
        const auto& a = r2.solutions[static_cast<std::size_t>(i)];
        // the same code, the same bits; rr_planar: ik_solve_all takes planar_2r's own closed
        // form (c291865), another sequence of operations: to rounding (aarch64 contracts FMAs)
        CHECK_TEXT(gap(m.chain, a.q, all.solutions[static_cast<std::size_t>(i)].q) <= (is_2r ? 1e-12 : 0.0), what.c_str());
        const kin::Pose X = fk(m.chain, a.q);
        CHECK_TEXT((X.translation() - T.translation()).norm() <= 1e-9, what.c_str());
        if (k.full_pose) CHECK_TEXT(kin::rotation_error(X.linear(), T.linear()).norm() <= 1e-9, what.c_str());
        // the error the 2-D check reports is the chain's, to rounding
        CHECK_TEXT(std::abs(a.position_error - (X.translation() - T.translation()).norm()) <= 1e-12, what.c_str());
        in = in || gap(m.chain, a.q, q) < 1e-6;
      }
      CHECK_TEXT(in, (what + ": original not among the 2-D solutions").c_str());
    }
    std::printf("\n  %-12s %d poses: the 2-D form answered %d", k.name, n, answered);
    CHECK_TEXT(answered == n, k.name);
  }
}

TEST(IkReduced, PlanarCaseTablesFromTheSeedFormulas) {
  // RRR (Carrara, Apostila de Robótica, 4.2): the wrist point w = p - a3 (cos phi, sin phi), theta2 =
  // +-acos((|w|^2 - a1^2 - a2^2) / (2 a1 a2)), theta1 = atan2(w) - atan2(a2 s2, a1 + a2 c2),
  // theta3 = phi - theta1 - theta2. RLR (4.3): d2 = |w|, theta1 = atan2(w), theta3 = phi -
  // theta1, and d2 = -|w| (out of the telescope's limits). Both solutions, each one.
  struct Row {
    double x, y, phi;
  };
  const Row rows[] = {{0.40, 0.20, 0.5},  {-0.30, 0.35, 2.8}, {0.05, -0.45, -1.9}, {0.62, 0.01, 0.02},
                      {0.10, 0.12, -3.0}, {-0.5, -0.2, 1.2},  {0.0, 0.3, 0.0},     {0.2, -0.2, 3.1}};
  kin::IkModel rrr, rlr;
  kin::ik_prepare(model("rrr_planar"), rrr);
  kin::ik_prepare(model("rlr_planar"), rlr);
  const double a1 = 0.3, a2 = 0.25, a3 = 0.1;
  for (const Row& w : rows) {
    kin::Pose T = kin::Pose::Identity();
    T.linear() = Eigen::AngleAxisd(w.phi, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    T.translation() << w.x, w.y, 0;
    const double wx = w.x - a3 * std::cos(w.phi), wy = w.y - a3 * std::sin(w.phi);
    const std::string what = std::to_string(w.x) + " " + std::to_string(w.y) + " " + std::to_string(w.phi);
    {
      const double k = (wx * wx + wy * wy - a1 * a1 - a2 * a2) / (2 * a1 * a2);
      kin::IkResult r;
      kin::ik_solve_all(rrr, T, nullptr, r);
      if (std::abs(k) > 1) {
        LONGS_EQUAL_TEXT(0, r.count, what.c_str());
      } else {
        LONGS_EQUAL_TEXT(2, r.count, what.c_str());
        for (const double t2 : {std::acos(k), -std::acos(k)}) {
          const double t1 = std::atan2(wy, wx) - std::atan2(a2 * std::sin(t2), a1 + a2 * std::cos(t2));
          kin::JointVector e(3);
          e << kin::wrap_pi(t1), t2, kin::wrap_pi(w.phi - t1 - t2);
          int hits = 0;
          for (int i = 0; i < r.count; ++i) hits += gap(rrr.chain, r.solutions[static_cast<std::size_t>(i)].q, e) < 1e-12;
          LONGS_EQUAL_TEXT(1, hits, ("rrr " + what + " expected " + describe(e)).c_str());
        }
        CHECK_TEXT(r.solutions[0].branch.elbow != r.solutions[1].branch.elbow, what.c_str());
      }
    }
    {
      kin::IkResult r;
      kin::ik_solve_all(rlr, T, nullptr, r);
      LONGS_EQUAL_TEXT(2, r.count, what.c_str());
      const double d = std::hypot(wx, wy), t1 = std::atan2(wy, wx);
      for (const double s : {1.0, -1.0}) {
        kin::JointVector e(3);
        e << kin::wrap_pi(s > 0 ? t1 : t1 + M_PI), s * d, kin::wrap_pi(w.phi - (s > 0 ? t1 : t1 + M_PI));
        int hits = 0;
        for (int i = 0; i < r.count; ++i) {
          const auto& x = r.solutions[static_cast<std::size_t>(i)];
          if (gap(rlr.chain, x.q, e) < 1e-12) {
            ++hits;
            CHECK_TEXT(x.within_limits == (s > 0 && d >= 0.1 && d <= 0.5), what.c_str());
          }
        }
        LONGS_EQUAL_TEXT(1, hits, ("rlr " + what + " expected " + describe(e)).c_str());
      }
    }
  }
}

TEST(IkReduced, NothingTheNumericSearchFindsIsMissing) {
  // A slow reference independent of the closed forms: ik_numeric from 40 random starts
  // per pose collects the distinct solutions within the limits; each of them is among
  // ik_solve_all's solutions (within 1e-6), and every solution of ours within the limits
  // is found by the search, on 60 random poses per arm and 20 with the elbow stretched.
  for (const Case& k : kCases) {
    kin::IkModel m;
    kin::ik_prepare(model(k.name), m);
    std::mt19937_64 rng(404);
    kin::IkNumericOptions opt;
    opt.position_only = !k.full_pose;
    opt.max_restarts = 0;
    opt.max_iterations = 100;
    opt.stall_iterations = 0;
    int found_total = 0;
    for (int s = 0; s < 80; ++s) {
      kin::JointVector q = random_q(m.chain, rng);
      if (s >= 60) {
        const int e = std::string(k.method) == "planar_3" || std::string(k.method) == "planar_2r" ? 1 : 2;
        if (m.chain.joint(e).type == kin::JointType::revolute) q[e] = 0.0;
      }
      const kin::Pose T = fk(m.chain, q);
      kin::IkResult r;
      kin::ik_solve_all(m, T, nullptr, r);
      std::vector<kin::JointVector> num;
      for (int t = 0; t < 40; ++t) {
        kin::IkNumericResult nr;
        kin::ik_numeric(m.chain, T, random_q(m.chain, rng), opt, nr);
        if (nr.status != kin::Status::ok) continue;
        bool dup = false;
        for (const auto& x : num) dup = dup || gap(m.chain, x, nr.q) < 1e-5;
        if (!dup) num.push_back(nr.q);
      }
      const std::string what = std::string(k.name) + " " + describe(q);
      // stretched: a double root, the search stops ~sqrt(1e-9 / L) rad from it
      const double tol = s >= 60 ? 1e-3 : 1e-5;
      for (const auto& x : num) {
        bool ours = false;
        for (int i = 0; i < r.count; ++i) ours = ours || gap(m.chain, r.solutions[static_cast<std::size_t>(i)].q, x) < tol;
        CHECK_TEXT(ours, (what + ": numeric solution " + describe(x) + " missing").c_str());
      }
      for (int i = 0; i < r.count; ++i) {
        const auto& a = r.solutions[static_cast<std::size_t>(i)];
        if (!a.within_limits) continue;
        bool there = false;
        for (const auto& x : num) there = there || gap(m.chain, a.q, x) < tol;
        CHECK_TEXT(there, (what + ": ours " + describe(a.q) + " not found by the search").c_str());
      }
      found_total += static_cast<int>(num.size());
    }
    std::printf("\n  %-12s 80 poses: %d numeric solutions, all among ours", k.name, found_total);
  }
}
