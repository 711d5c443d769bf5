// SPDX-License-Identifier: Apache-2.0
// URDF import and export against Orocos KDL: the KDL chain is built here from urdfdom's
// model (as ROS's kdl_parser does: joint axes rotated into the parent, inertia rotated
// from the inertial frame), independent of the converter; the converted description
// (through its TOML text) must give the same FK to 1e-12 m on 10 000 seeded joint
// vectors per arm, the same RNEA torques to 1e-9 relative, and IK round trips. Every
// built-in model exported and imported again gives the same FK and dynamics.
#include <kdl/chainfksolverpos_recursive.hpp>
#include <kdl/chainidsolver_recursive_newton_euler.hpp>
#include <kdl/tree.hpp>
#include <urdf_parser/urdf_parser.h>

#include <chrono>
#include <fstream>
#include <sstream>

#include "../support/kdl_reference.hpp"
#include "../support/sweep.hpp"
#include "servoarm/kinematics/dynamics.hpp"
#include "servoarm/kinematics/ik.hpp"
#include "servoarm/kinematics/urdf.hpp"
#include "../kinematics/kin_test_util.hpp"

using namespace servoarm;
using namespace servoarm::test;

namespace {

std::string data(const std::string& name) { return std::string(URDF_DATA_DIR) + "/" + name; }

std::string slurp(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

KDL::Frame kdl_pose(const urdf::Pose& p) {
  return KDL::Frame(KDL::Rotation::Quaternion(p.rotation.x, p.rotation.y, p.rotation.z, p.rotation.w),
                    KDL::Vector(p.position.x, p.position.y, p.position.z));
}

KDL::RigidBodyInertia kdl_inertia(const urdf::Link& link) {
  if (!link.inertial) return KDL::RigidBodyInertia::Zero();
  const urdf::Inertial& i = *link.inertial;
  const KDL::Frame o = kdl_pose(i.origin);
  const KDL::RotationalInertia Ic(i.ixx, i.iyy, i.izz, i.ixy, i.ixz, i.iyz);
  const KDL::RotationalInertia Ir = (o.M * KDL::RigidBodyInertia(0, KDL::Vector::Zero(), Ic)).getRotationalInertia();
  return KDL::RigidBodyInertia(i.mass, o.p, Ir);
}

void add_children(KDL::Tree& tree, const urdf::Link& link) {
  for (const auto& child : link.child_links) {
    const urdf::Joint& j = *child->parent_joint;
    const KDL::Frame F = kdl_pose(j.parent_to_joint_origin_transform);
    KDL::Vector axis(j.axis.x, j.axis.y, j.axis.z);
    axis.Normalize();
    KDL::Joint kj(j.name, KDL::Joint::None);
    if (j.type == urdf::Joint::REVOLUTE || j.type == urdf::Joint::CONTINUOUS) kj = KDL::Joint(j.name, F.p, F.M * axis, KDL::Joint::RotAxis);
    if (j.type == urdf::Joint::PRISMATIC) kj = KDL::Joint(j.name, F.p, F.M * axis, KDL::Joint::TransAxis);
    tree.addSegment(KDL::Segment(child->name, kj, F, kdl_inertia(*child)), link.name);
    add_children(tree, *child);
  }
}

/// The URDF as a KDL chain base -> tip, straight from urdfdom's model.
KDL::Chain kdl_chain(const std::string& file, const std::string& base, const std::string& tip) {
  const urdf::ModelInterfaceSharedPtr m = urdf::parseURDF(slurp(file));
  CHECK(m != nullptr);
  KDL::Tree tree(m->getRoot()->name);
  add_children(tree, *m->getRoot());
  KDL::Chain chain;
  CHECK(tree.getChain(base, tip, chain));
  return chain;
}

kin::UrdfConversion convert(const std::string& file, const std::string& tip = "",
                            kin::Convention conv = kin::Convention::standard) {
  kin::UrdfParseOptions po;
  po.tip = tip;
  const kin::UrdfParseResult p = kin::urdf_parse_file(file, po);
  if (!p.ok) FAIL(p.error.c_str());
  kin::UrdfConversion c = kin::urdf_convert(p.chain, {conv, ""});
  if (!c.ok) FAIL(c.error.c_str());
  return c;
}

double pose_diff(const kin::Pose& a, const kin::Pose& b) {
  return std::max((a.translation() - b.translation()).norm(), (a.linear() - b.linear()).norm());
}

/// Largest FK difference (m; rotation matrix difference, dimensionless) over n seeded vectors.
double fk_vs_kdl(const kin::Chain& c, const KDL::Chain& kc, int n, unsigned seed) {
  KDL::ChainFkSolverPos_recursive fk_kdl(kc);
  LONGS_EQUAL(kc.getNrOfJoints(), static_cast<unsigned>(c.n_joints));
  std::mt19937_64 rng(seed);
  double worst = 0;
  for (int s = 0; s < n; ++s) {
    const kin::JointVector q = random_q(c, rng);
    KDL::Frame F;
    CHECK(fk_kdl.JntToCart(to_kdl(q), F) >= 0);
    worst = std::max(worst, pose_diff(fk(c, q), from_kdl(F)));
  }
  return worst;
}

double rnea_vs_kdl(const kin::Chain& c, const KDL::Chain& kc, int n, unsigned seed) {
  KDL::ChainIdSolver_RNE rne(kc, KDL::Vector(c.gravity[0], c.gravity[1], c.gravity[2]));
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-2, 2);
  double worst = 0;
  const unsigned nj = kc.getNrOfJoints();
  for (int s = 0; s < n; ++s) {
    const kin::JointVector q = random_q(c, rng);
    kin::JointVector qd(c.n_joints), qdd(c.n_joints), tau(c.n_joints);
    for (int j = 0; j < c.n_joints; ++j) qd[j] = u(rng), qdd[j] = u(rng);
    CHECK(kin::inverse_dynamics(c, q, qd, qdd, tau) == kin::Status::ok);
    KDL::JntArray kq = to_kdl(q), kqd = to_kdl(qd), kqdd = to_kdl(qdd), kt(nj);
    KDL::Wrenches f(kc.getNrOfSegments(), KDL::Wrench::Zero());
    CHECK(rne.CartToJnt(kq, kqd, kqdd, f, kt) >= 0);
    double num = 0, den = 0;
    for (unsigned j = 0; j < nj; ++j) num = std::max(num, std::abs(tau[j] - kt(j))), den = std::max(den, std::abs(kt(j)));
    worst = std::max(worst, num / std::max(den, 1e-300));
  }
  return worst;
}

struct Arm {
  const char* file;
  const char* tip;  // "" = default
  kin::IkMethod method;
};
const Arm kArms[] = {
    {"ur_like.urdf", "", kin::IkMethod::ur},
    {"opw_like.urdf", "", kin::IkMethod::opw},
    {"seven_dof.urdf", "", kin::IkMethod::none},
    {"desktop5.urdf", "", kin::IkMethod::none},
    {"prismatic.urdf", "", kin::IkMethod::none},
    {"rotated.urdf", "", kin::IkMethod::opw},
    {"continuous.urdf", "", kin::IkMethod::ur},
    {"tool_beyond_flange.urdf", "tool0", kin::IkMethod::opw},
};

}  // namespace

TEST_GROUP(Urdf){};

TEST(Urdf, FkOfEveryTestArmMatchesKdlBuiltFromUrdfdom) {
  for (const Arm& arm : kArms) {
    for (kin::Convention conv : {kin::Convention::standard, kin::Convention::modified}) {
      const kin::UrdfConversion c = convert(data(arm.file), arm.tip, conv);
      const kin::UrdfParseResult p = kin::urdf_parse_file(data(arm.file), {"", arm.tip});
      const KDL::Chain kc = kdl_chain(data(arm.file), p.chain.base, p.chain.tip);
      const int n = conv == kin::Convention::standard ? sweep(10000) : sweep(2000);
      const double worst = fk_vs_kdl(c.chain, kc, n, 42);
      std::printf("\n  %-24s %-8s %d joints, FK vs KDL worst %.2e over %d", arm.file, kin::to_string(conv), c.chain.n_joints, worst, n);
      if (!(worst <= 1e-12)) FAIL((std::string(arm.file) + ": FK differs from KDL's").c_str());
    }
  }
}

TEST(Urdf, RneaOfEveryTestArmMatchesKdl) {
  for (const Arm& arm : kArms) {
    for (kin::Convention conv : {kin::Convention::standard, kin::Convention::modified}) {
      const kin::UrdfConversion c = convert(data(arm.file), arm.tip, conv);
      CHECK(c.chain.has_inertial);
      const kin::UrdfParseResult p = kin::urdf_parse_file(data(arm.file), {"", arm.tip});
      const double worst = rnea_vs_kdl(c.chain, kdl_chain(data(arm.file), p.chain.base, p.chain.tip), sweep(1000), 7);
      std::printf("\n  %-24s %-8s RNEA vs KDL worst relative %.2e", arm.file, kin::to_string(conv), worst);
      if (!(worst <= 1e-9)) FAIL((std::string(arm.file) + ": RNEA differs from KDL's").c_str());
    }
  }
}

TEST(Urdf, EveryTestArmGetsItsIkClassAndRoundTrips) {
  for (const Arm& arm : kArms) {
    const kin::UrdfConversion c = convert(data(arm.file), arm.tip);
    kin::IkModel m;
    kin::ik_prepare(c.chain, m);
    std::printf("\n  %-24s IK: %s", arm.file, kin::to_string(m.method));
    STRCMP_EQUAL(kin::to_string(arm.method), kin::to_string(m.method));
    std::mt19937_64 rng(3);
    for (int s = 0; s < sweep(200); ++s) {
      const kin::JointVector q = random_q(c.chain, rng);
      const kin::Pose target = fk(c.chain, q);
      if (m.method != kin::IkMethod::none) {
        kin::IkResult r;
        kin::ik_solve_all(m, target, &q, r);
        CHECK(r.count > 0);
        double best = 1e9;  // the configuration that made the target is among the solutions
        for (int k = 0; k < r.count; ++k) {
          const kin::JointVector& qs = r.solutions[static_cast<std::size_t>(k)].q;
          CHECK(pose_diff(fk(c.chain, qs), target) < 1e-9);
          double d = 0;
          for (int j = 0; j < q.size(); ++j) d = std::max(d, std::abs(std::remainder(qs[j] - q[j], 2 * M_PI)));
          best = std::min(best, d);
        }
        CHECK(best < 1e-6);
      } else {
        kin::JointVector start = q;
        for (int j = 0; j < q.size(); ++j) start[j] += 0.05;
        kin::IkNumericResult r;
        kin::ik_numeric(c.chain, target, start, {}, r);
        CHECK(r.status == kin::Status::ok);
        CHECK(pose_diff(fk(c.chain, r.q), target) < 1e-8);
      }
    }
  }
}

TEST(Urdf, ConvertedFileNamesTheUrdfJointOfEveryRowAndKeepsLimits) {
  const kin::UrdfConversion c = convert(data("tool_beyond_flange.urdf"), "tool0");
  for (const char* j : {"j1", "j2", "j3", "j4", "j5", "j6"})
    CHECK(c.toml.find(std::string("# URDF joint '") + j + "' (revolute)") != std::string::npos);
  CHECK(c.toml.find("Skipped (off the chain): camera_joint finger_left_joint finger_right_joint") != std::string::npos);
  // j2's limits in the URDF: -90..150 deg; velocity and effort carried over.
  DOUBLES_EQUAL(-M_PI / 2, c.chain.joint(1).lower, 1e-12);
  DOUBLES_EQUAL(150 * M_PI / 180, c.chain.joint(1).upper, 1e-12);
  CHECK(c.chain.joint(1).dynamics.max_velocity > 1 && c.chain.joint(1).max_effort > 10);
  const kin::UrdfConversion u = convert(data("continuous.urdf"));
  for (int j = 0; j < 6; ++j) CHECK(!std::isfinite(u.chain.joint(j).lower) && u.chain.joint(j).direction == 1);
}

TEST(Urdf, ExportThenImportOfEveryBuiltinModelGivesTheSameFk) {
  for (const auto& bm : kin::builtin_models()) {
    const kin::Chain orig = model(bm.name);
    const std::string text = kin::urdf_export(orig);
    const kin::UrdfParseResult p = kin::urdf_parse(text, bm.name);
    if (!p.ok) FAIL(p.error.c_str());
    const kin::UrdfConversion c = kin::urdf_convert(p.chain);
    if (!c.ok) FAIL(c.error.c_str());
    LONGS_EQUAL(orig.n_joints, c.chain.n_joints);
    std::mt19937_64 rng(11);
    double worst = 0;
    for (int s = 0; s < sweep(2000); ++s) {
      const kin::JointVector q = random_q(orig, rng);
      worst = std::max(worst, pose_diff(fk(orig, q), fk(c.chain, q)));
    }
    std::printf("\n  %-20s export -> import FK worst %.2e", bm.name, worst);
    if (!(worst <= 1e-12)) FAIL((std::string(bm.name) + ": FK after export/import differs").c_str());
    for (int j = 0; j < orig.n_joints; ++j) {
      DOUBLES_EQUAL(orig.joint(j).lower, c.chain.joint(j).lower, 1e-12);
      DOUBLES_EQUAL(orig.joint(j).dynamics.max_velocity, c.chain.joint(j).dynamics.max_velocity, 1e-12);
    }
    if (orig.has_inertial) {  // same rigid-body torques (URDF holds no rotor inertia, gear, friction)
      kin::Chain rigid = orig;
      for (int i = 0; i < rigid.n_rows; ++i) {
        kin::LinkInertial L = rigid.inertial[static_cast<std::size_t>(i)];
        L.rotor_inertia = 0, L.gear_ratio = 1, L.viscous = 0, L.coulomb = 0;
        CHECK(kin::set_inertial(rigid, i, L) == kin::Status::ok);
      }
      const kin::JointVector q = random_q(orig, rng);
      kin::JointVector qd = q * 0.3, qdd = q * 0.7, t1(q.size()), t2(q.size());
      CHECK(kin::inverse_dynamics(rigid, q, qd, qdd, t1) == kin::Status::ok);
      CHECK(kin::inverse_dynamics(c.chain, q, qd, qdd, t2) == kin::Status::ok);
      CHECK((t1 - t2).cwiseAbs().maxCoeff() <= 1e-9 * t1.cwiseAbs().maxCoeff());
    }
  }
}

// The exporter draws each link as a cylinder from the link's origin to the next joint's:
// read back by urdfdom, its visual origin sits halfway along that vector and its rotation
// takes the cylinder's z axis onto it, for every link of every built-in model (links along
// +z, along -z and across).
TEST(Urdf, ExportedLinkCylindersRunFromTheLinkOriginToTheNextJoint) {
  int cylinders = 0, along_minus_z = 0;
  std::vector<std::pair<std::string, kin::Chain>> arms;
  for (const auto& bm : kin::builtin_models()) arms.emplace_back(bm.name, model(bm.name));
  // No built-in link runs along -z: a modified-DH arm whose second row is a pure offset d < 0
  // has one (the next joint straight below the first link's origin).
  for (const auto& [name, c] : arms) {
    if (c.convention != kin::Convention::modified || c.n_rows < 3) continue;
    kin::Chain down = c;
    down.rows[1].a = 0, down.rows[1].alpha = 0, down.rows[1].theta = 0, down.rows[1].d = -0.25;
    arms.emplace_back(name + "_down", down);
    break;
  }
  for (const auto& [arm, c] : arms) {
    const urdf::ModelInterfaceSharedPtr m = urdf::parseURDF(kin::urdf_export(c));
    CHECK_TEXT(m != nullptr, arm.c_str());
    for (const auto& [name, link] : m->links_) {
      if (!link->visual || !link->visual->geometry || link->visual->geometry->type != urdf::Geometry::CYLINDER) continue;
      const auto& cyl = static_cast<const urdf::Cylinder&>(*link->visual->geometry);
      const urdf::Pose& o = link->visual->origin;
      const KDL::Vector half(o.position.x, o.position.y, o.position.z);
      const KDL::Vector axis = kdl_pose(o).M * KDL::Vector(0, 0, 1);
      const std::string where = arm + " link " + name;
      DOUBLES_EQUAL_TEXT(cyl.length, 2 * half.Norm(), 1e-12, where.c_str());
      CHECK_TEXT((axis - half / half.Norm()).Norm() < 1e-12, where.c_str());
      ++cylinders;
      if (half.z() < 0 && std::hypot(half.x(), half.y()) < 1e-12) ++along_minus_z;
    }
  }
  std::printf("\n  %d link cylinders, %d along -z", cylinders, along_minus_z);
  CHECK(cylinders >= 40);
  CHECK(along_minus_z >= 1);
}

TEST(Urdf, ConversionTimeOfTheSevenJointArm) {
  const std::string text = slurp(data("seven_dof.urdf"));
  std::vector<double> us;
  for (int i = 0; i < sweep(200); ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    const kin::UrdfParseResult p = kin::urdf_parse(text, "seven_dof");
    const kin::UrdfConversion c = kin::urdf_convert(p.chain);
    us.push_back(std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count());
    CHECK(c.ok);
  }
  std::sort(us.begin(), us.end());
  std::printf("\n  seven_dof.urdf: parse + convert + check, median %.1f us of %zu", us[us.size() / 2], us.size());
}
