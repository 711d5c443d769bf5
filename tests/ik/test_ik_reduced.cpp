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
