// SPDX-License-Identifier: Apache-2.0
// Differential test against Orocos KDL: FK and Jacobian of every built-in
// model, standard and modified DH, on 10 000 random configurations each.
#include <kdl/chainfksolverpos_recursive.hpp>
#include <kdl/chainjnttojacsolver.hpp>

#include "../support/kdl_reference.hpp"
#include "kin_test_util.hpp"

using namespace servoarm;
using namespace servoarm::test;

TEST_GROUP(KdlReference){};

TEST(KdlReference, ForwardKinematicsAndJacobianOfEveryBuiltinModel) {
  constexpr int kConfigs = 10000;
  int models = 0;
  // The OPW and UR models must be among them (OPW and UR classes).
  int issue19 = 0;
  for (const auto& m : kin::builtin_models()) {
    for (const char* want : {"abb_irb2400", "kuka_kr6_r700", "ur5e", "ur10e"})
      if (std::string(m.name) == want) ++issue19;
    const kin::Chain c = model(m.name);
    const KDL::Chain kc = to_kdl(c);
    LONGS_EQUAL(c.n_joints, static_cast<long>(kc.getNrOfJoints()));
    KDL::ChainFkSolverPos_recursive kfk(kc);
    KDL::ChainJntToJacSolver kjac(kc);
    KDL::Jacobian kJ(kc.getNrOfJoints());
    std::mt19937_64 rng(100 + static_cast<unsigned>(models));
    double worst_p = 0, worst_r = 0, worst_j = 0;
    for (int n = 0; n < kConfigs; ++n) {
      const kin::JointVector q = random_q(c, rng);
      const KDL::JntArray kq = to_kdl(q);
      KDL::Frame F;
      CHECK(kfk.JntToCart(kq, F) >= 0);
      const kin::Pose ref = from_kdl(F);
      kin::Jacobian J;
      kin::Pose T;
      CHECK(kin::jacobian(c, q, J, &T) == kin::Status::ok);
      const kin::Pose T2 = fk(c, q);
      CHECK(T.isApprox(T2, 1e-14) || (T.matrix() - T2.matrix()).cwiseAbs().maxCoeff() < 1e-14);
      worst_p = std::max(worst_p, (T.translation() - ref.translation()).cwiseAbs().maxCoeff());
      worst_r = std::max(worst_r, (T.linear() - ref.linear()).cwiseAbs().maxCoeff());
      CHECK(kjac.JntToJac(kq, kJ) >= 0);
      worst_j = std::max(worst_j, (J - kJ.data).cwiseAbs().maxCoeff());
      if (worst_p > 1e-9 || worst_r > 1e-9 || worst_j > 1e-9) {
        std::ostringstream os;
        os << m.name << " " << describe(q) << ": position error " << worst_p << " m, rotation error "
           << worst_r << ", Jacobian error " << worst_j;
        FAIL(os.str().c_str());
      }
    }
    ++models;
  }
  CHECK(models >= 16);
  LONGS_EQUAL(4, issue19);
}

// Random chains: both conventions, every row type, general and special alphas
// (0, +-90, 180 and arbitrary), negative directions, base and tool transforms.
TEST(KdlReference, RandomChainsOfEveryShape) {
  std::mt19937_64 rng(777);
  std::uniform_real_distribution<double> len(-0.5, 0.5), ang(-M_PI, M_PI);
  std::uniform_int_distribution<int> pick(0, 9);
  int checked = 0;
  for (int c = 0; c < 300; ++c) {
    kin::Chain chain;
    chain.convention = (c % 2) ? kin::Convention::modified : kin::Convention::standard;
    const int rows = 1 + static_cast<int>(rng() % kin::kMaxRows);
    for (int i = 0; i < rows; ++i) {
      kin::DhRow r;
      const int t = pick(rng);
      r.type = t < 6 ? kin::JointType::revolute : t < 8 ? kin::JointType::prismatic : kin::JointType::fixed;
      if (r.type != kin::JointType::fixed && chain.n_joints == kin::kMaxJoints) r.type = kin::JointType::fixed;
      const double alphas[] = {0, M_PI / 2, -M_PI / 2, M_PI, ang(rng)};
      r.alpha = alphas[rng() % 5];
      r.theta = pick(rng) < 3 ? 0 : ang(rng);
      r.a = pick(rng) < 3 ? 0 : len(rng);
      r.d = pick(rng) < 3 ? 0 : len(rng);
      r.direction = pick(rng) < 3 ? -1 : 1;
      CHECK(kin::add_row(chain, r) == kin::Status::ok);
    }
    if (chain.n_joints == 0) continue;
    if (c % 3 == 0) {
      kin::Pose B = kin::Pose::Identity();
      B.linear() = Eigen::AngleAxisd(ang(rng), Eigen::Vector3d(len(rng), len(rng), 1).normalized()).toRotationMatrix();
      B.translation() << len(rng), len(rng), len(rng);
      chain.base = B;
      kin::set_tool(chain, B.inverse());
    }
    const KDL::Chain kc = to_kdl(chain);
    KDL::ChainFkSolverPos_recursive kfk(kc);
    KDL::ChainJntToJacSolver kjac(kc);
    KDL::Jacobian kJ(kc.getNrOfJoints());
    for (int n = 0; n < 50; ++n) {
      kin::JointVector q(chain.n_joints);
      for (int j = 0; j < chain.n_joints; ++j) q[j] = ang(rng);
      KDL::Frame F;
      kfk.JntToCart(to_kdl(q), F);
      kjac.JntToJac(to_kdl(q), kJ);
      kin::Jacobian J;
      kin::Pose T;
      CHECK(kin::jacobian(chain, q, J, &T) == kin::Status::ok);
      const kin::Pose ref = from_kdl(F);
      const double e = std::max({(T.translation() - ref.translation()).cwiseAbs().maxCoeff(),
                                 (T.linear() - ref.linear()).cwiseAbs().maxCoeff(), (J - kJ.data).cwiseAbs().maxCoeff(),
                                 (fk(chain, q).matrix() - T.matrix()).cwiseAbs().maxCoeff()});
      if (e > 1e-9) {
        std::ostringstream os;
        os << "chain " << c << " (" << kin::to_string(chain.convention) << ", " << chain.n_rows << " rows) "
           << describe(q) << " error " << e;
        FAIL(os.str().c_str());
      }
      ++checked;
    }
  }
  CHECK(checked > 10000);
}
