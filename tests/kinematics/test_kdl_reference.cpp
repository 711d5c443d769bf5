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
  for (const auto& m : kin::builtin_models()) {
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
  CHECK(models >= 12);
}
