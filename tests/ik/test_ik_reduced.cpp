// Closed forms of seed 002 chapter 4 (RR, RRR, RLR, TRR, TRL:R, VVL:R),
// recognised from the DH rows: round trip on random configurations, the
// original among the solutions, the seed's formulas, unreachable targets.
#include <cstdlib>

#include "servoarm/kinematics/ik.hpp"
#include "kin_test_util.hpp"

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
  return s ? std::atoi(s) : 100000;
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
  // RR (seed 002 4.1): theta2 = +-acos((x^2 + y^2 - a1^2 - a2^2) / (2 a1 a2)).
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
  // TRR (seed 002 4.4): theta3 = +-acos((x^2+y^2+(z-a1)^2-a2^2-a3^2)/(2 a2 a3)), 4 solutions.
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
  // VVL:R (seed 002 4.6): a3 = sqrt((z - a1 - a4 s_phi)^2 + (sqrt(x^2+y^2-a2^2) - a4 c_phi)^2).
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
        LONGS_EQUAL_TEXT(slow.count, fast.count, what.c_str());
        for (int i = 0; i < fast.count; ++i) {
          const auto& a = fast.solutions[static_cast<std::size_t>(i)];
          const auto& b = slow.solutions[static_cast<std::size_t>(i)];
          // near-singular (flagged): a root clamped ~1e-8 rad off, polished by the chain path
          const double tol = a.singular ? 1e-6 : 1e-9;
          CHECK_TEXT(gap(m.chain, a.q, b.q) < tol, (what + " solution " + describe(a.q) + " vs " + describe(b.q)).c_str());
          LONGS_EQUAL_TEXT(b.branch.shoulder, a.branch.shoulder, what.c_str());
          LONGS_EQUAL_TEXT(b.branch.elbow, a.branch.elbow, what.c_str());
          CHECK_TEXT(a.within_limits == b.within_limits, what.c_str());
          LONGS_EQUAL_TEXT(b.singular, a.singular, what.c_str());
          // and it is what it says: the chain's FK reaches the (reachable part of the) target
          const kin::Pose X = fk(m.chain, a.q);
          CHECK_TEXT((X.translation() - T.translation()).norm() <= 1e-9, what.c_str());
          CHECK_TEXT(a.position_error <= 1e-9 && a.rotation_error <= 1e-9, what.c_str());
        }
      }
    }
    std::printf("\n  %-12s %d poses: cheap path = chain path, %d results flagged singular", k.name, n, flagged);
  }
}
