// SPDX-License-Identifier: Apache-2.0
// Closed-form IK of the OPW class (ortho-parallel base + spherical wrist:
// abb_irb2400, kuka_kr6_r700, ist6, random arms with every OPW offset) and of
// the UR class (ur5e, ur10e, random UR-type arms), recognised from the DH rows
// in either convention: round trips FK(IK(FK(q))) on 10 000 random
// configurations per model with every solution checked by the chain's FK, the
// original configuration among the solutions, distinct branch tags; the OPW
// models' FK against the published OPW forward kinematics; near-miss models
// (0.001 mm offset, 0.01 deg twist) that must not take the closed form.
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "ik_class_util.hpp"
#include "sweep.hpp"

using namespace servoarm;
using namespace servoarm::test;

namespace {

struct ClassCase {
  const char* name;
  const char* method;
};
const ClassCase kClassModels[] = {
    {"abb_irb2400", "opw"}, {"kuka_kr6_r700", "opw"}, {"ist6", "opw"},
    {"ur5e", "ur"},         {"ur10e", "ur"},          {"puma560", "spherical_wrist"},
};

int samples() {
  const char* s = std::getenv("SERVOARM_IK_SAMPLES");
  return s ? std::atoi(s) : servoarm::test::sweep(10000);  // 1/20 under qemu and the sanitizers
}

// The OPW forward kinematics of Brandstoetter et al. 2014 (wrist centre and
// R = Rz(q1) Ry(q2 + q3) Rz(q4) Ry(q5) Rz(q6)), written from the paper's
// equations, in the OPW joint variables q' = sign * q - offset.
struct Opw {
  double a1, a2, b, c1, c2, c3, c4;
  double offset[6];
  double sign[6];
};
kin::Pose opw_forward(const Opw& p, const kin::JointVector& qs) {
  double q[6];
  for (int j = 0; j < 6; ++j) q[j] = qs[j] * p.sign[j] - p.offset[j];
  auto Ry = [](double a) { return Eigen::AngleAxisd(a, Eigen::Vector3d::UnitY()).toRotationMatrix(); };
  auto Rz = [](double a) { return Eigen::AngleAxisd(a, Eigen::Vector3d::UnitZ()).toRotationMatrix(); };
  const double k = std::hypot(p.a2, p.c3), psi3 = std::atan2(p.a2, p.c3);
  const Eigen::Vector3d c1(p.c2 * std::sin(q[1]) + k * std::sin(q[1] + q[2] + psi3) + p.a1, p.b,
                           p.c2 * std::cos(q[1]) + k * std::cos(q[1] + q[2] + psi3));
  const Eigen::Vector3d c0 = Rz(q[0]) * c1 + Eigen::Vector3d(0, 0, p.c1);
  const Eigen::Matrix3d R = Rz(q[0]) * Ry(q[1] + q[2]) * Rz(q[3]) * Ry(q[4]) * Rz(q[5]);
  kin::Pose T = kin::Pose::Identity();
  T.linear() = R;
  T.translation() = c0 + p.c4 * R.col(2);
  return T;
}

}  // namespace

TEST_GROUP(IkClasses){};

TEST(IkClasses, EveryModelIsRecognisedFromItsDhRows) {
  for (const auto& k : kClassModels) {
    const kin::IkModel m = prepared(k.name);
    STRCMP_EQUAL_TEXT(k.method, kin::to_string(m.method), k.name);
  }
}

TEST(IkClasses, OpwModelsMatchThePublishedOpwForwardKinematics) {
  // opw_kinematics' parameter sets (see the model files' headers), in metres.
  const Opw abb{0.100, -0.135, 0.0, 0.615, 0.705, 0.755, 0.085, {0, 0, -M_PI / 2, 0, 0, 0}, {1, 1, 1, 1, 1, 1}};
  const Opw kuka{0.025, -0.035, 0.0, 0.400, 0.315, 0.365, 0.080, {0, -M_PI / 2, 0, 0, 0, 0}, {-1, 1, 1, -1, 1, -1}};
  const std::pair<const char*, Opw> cases[] = {{"abb_irb2400", abb}, {"kuka_kr6_r700", kuka}};
  for (const auto& [name, p] : cases) {
    const kin::Chain c = model(name);
    std::mt19937_64 rng(7);
    double worst = 0;
    for (int k = 0; k < 1000; ++k) {
      const kin::JointVector q = random_q(c, rng);
      const kin::Pose A = fk(c, q), B = opw_forward(p, q);
      worst = std::max(worst, (A.matrix() - B.matrix()).cwiseAbs().maxCoeff());
    }
    if (worst > 1e-12) FAIL((std::string(name) + ": FK differs from OPW by " + std::to_string(worst)).c_str());
  }
}

TEST(IkClasses, RoundTripEverySolutionOriginalAmongThemBranchesDistinct) {
  const int n = samples();
  for (const auto& k : kClassModels) {
    const kin::IkModel m = prepared(k.name);
    const RoundTripStats st = round_trip(m, n, 4321, k.name);
    std::printf("\n  %-14s %-16s %d poses: %.3f solutions/pose, %d with 8, singular %d, refined %d", k.name, k.method,
                n, st.mean_count(), st.with8, st.singular, st.refined);
    // OPW arms with a shoulder offset: the flipped shoulder may not reach.
    CHECK_TEXT(st.with8 > n / 2, k.name);
  }
}

TEST(IkClasses, RandomOpwArmsWithEveryOffsetInBothConventions) {
  std::mt19937_64 rng(99);
  std::uniform_real_distribution<double> U(-1, 1);
  for (int arm = 0; arm < 40; ++arm) {
    OpwParams p;
    p.a1 = 0.2 * U(rng);
    p.a2 = 0.2 * U(rng);
    p.b = arm % 3 == 0 ? 0.0 : 0.1 * U(rng);
    p.c1 = 0.3 + 0.3 * U(rng);
    p.c2 = 0.5 + 0.2 * U(rng);
    p.c3 = 0.5 + 0.2 * U(rng);
    p.c4 = 0.1 + 0.05 * U(rng);
    const bool modified = arm % 2 == 1;
    const kin::Chain c = opw_chain(p, modified, arm % 4 == 3);
    kin::IkModel m;
    LONGS_EQUAL(0, static_cast<int>(kin::ik_prepare(c, m)));
    const std::string what = "OPW arm " + std::to_string(arm) + (modified ? " (modified DH)" : " (standard DH)");
    // a1 = 0 and b = 0 is the PUMA-like decoupled case; every other is opw.
    STRCMP_EQUAL_TEXT("opw", kin::to_string(m.method), what.c_str());
    round_trip(m, 500, 1000 + arm, what.c_str());
  }
}

TEST(IkClasses, RandomUrArmsInBothConventions) {
  std::mt19937_64 rng(98);
  std::uniform_real_distribution<double> U(-1, 1);
  for (int arm = 0; arm < 40; ++arm) {
    UrParams p;
    p.d1 = 0.15 + 0.05 * U(rng);
    p.a2 = -0.4 + 0.2 * U(rng);
    p.a3 = -0.4 + 0.2 * U(rng);
    p.d4 = 0.13 + 0.08 * U(rng);
    p.d5 = 0.1 + 0.05 * U(rng);
    p.d6 = 0.1 + 0.05 * U(rng);
    const bool modified = arm % 2 == 1;
    const kin::Chain c = ur_chain(p, modified, arm % 4 == 3);
    kin::IkModel m;
    LONGS_EQUAL(0, static_cast<int>(kin::ik_prepare(c, m)));
    const std::string what = "UR arm " + std::to_string(arm) + (modified ? " (modified DH)" : " (standard DH)");
    STRCMP_EQUAL_TEXT("ur", kin::to_string(m.method), what.c_str());
    round_trip(m, 500, 2000 + arm, what.c_str());
  }
}

TEST(IkClasses, NearMissModelsDoNotTakeTheClosedForm) {
  // Each perturbation breaks the structure the closed form relies on; the
  // model then takes the general (degree-8) path or the numerical solver,
  // and what it returns still reproduces the pose.
  struct Miss {
    const char* name;
    int row;
    char key;      // 'a', 'd' (length +1e-6 m) or 't' (alpha +0.01 deg)
    const char* expect;
  };
  const Miss cases[] = {
      {"abb_irb2400", 1, 't', "spherical_general"},  // axes 2, 3 no longer parallel
      {"abb_irb2400", 3, 'a', "numeric"},            // wrist axes 4, 5 no longer meet
      {"abb_irb2400", 4, 'd', "numeric"},            // wrist axes 5, 6 no longer meet
      {"kuka_kr6_r700", 1, 't', "spherical_general"},
      {"kuka_kr6_r700", 4, 'a', "numeric"},
      {"ur5e", 1, 't', "numeric"},  // axes 2, 3 no longer parallel
      {"ur5e", 2, 't', "numeric"},  // axes 3, 4 no longer parallel
      {"ur5e", 3, 't', "numeric"},  // axis 5 no longer normal to axis 4
      {"ur5e", 4, 'a', "numeric"},  // axes 5, 6 no longer meet
      {"ur10e", 2, 't', "numeric"},
      {"ur10e", 4, 'a', "numeric"},
  };
  for (const Miss& x : cases) {
    kin::Chain c = model(x.name);
    c = perturbed(c, x.row, x.key);
    kin::IkModel m;
    LONGS_EQUAL(0, static_cast<int>(kin::ik_prepare(c, m)));
    const std::string what = std::string(x.name) + " row " + std::to_string(x.row + 1) + " " + x.key;
    STRCMP_EQUAL_TEXT(x.expect, kin::to_string(m.method), what.c_str());
    std::mt19937_64 rng(5);
    for (int k = 0; k < 50; ++k) {
      const kin::JointVector q = random_q(c, rng);
      const kin::Pose T = fk(c, q);
      if (m.method == kin::IkMethod::none) {
        // The numerical solver from a start near q finds q's pose.
        kin::JointVector start = q;
        for (int j = 0; j < 6; ++j) start[j] += 0.05;
        kin::JointVector out;
        const kin::Status s = kin::ik_solve_nearest(m, T, start, out);
        LONGS_EQUAL_TEXT(0, static_cast<int>(s), what.c_str());
        check_pose(c, out, T, what);
      } else {
        kin::IkResult r;
        kin::ik_solve_all(m, T, nullptr, r);
        CHECK_TEXT(r.count > 0, what.c_str());
        for (int i = 0; i < r.count; ++i) check_pose(c, r.solutions[static_cast<std::size_t>(i)].q, T, what);
        CHECK_TEXT(original_found(c, r, q), what.c_str());
      }
    }
  }
}
