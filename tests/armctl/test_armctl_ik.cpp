// SPDX-License-Identifier: Apache-2.0
// armctl kin ik / kin precision end to end: the JSON output is parsed and
// every returned solution is checked with the library's forward kinematics
// against the requested pose (targets are built here with Eigen, not with
// armctl's code path); --near against a nearest-solution search done here;
// precision against an independent central-difference computation of
// sum_i |dw/dq_i| dq_i; bad input gives one line on stderr and exit status 2.
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "run_command.hpp"
#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/kinematics/orientation.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using servoarm::test::json_numbers;
using servoarm::test::run_command;

namespace {
const std::string kArmctl = ARMCTL_PATH;
double deg(double r) { return r * 180 / M_PI; }

std::string fmt(double v) {
  char b[40];
  std::snprintf(b, sizeof b, "%.17g", v);
  return b;
}

kin::Chain load(const char* name) {
  const kin::LoadResult r = kin::load_robot(name);
  CHECK_TEXT(r.ok, name);
  return r.chain;
}

// Joints in the description's units (built-ins: degrees, mm) to SI.
kin::JointVector to_si(const kin::Chain& c, const std::vector<double>& user) {
  kin::JointVector q(c.n_joints);
  for (int j = 0; j < c.n_joints; ++j) q[j] = user[static_cast<std::size_t>(j)] / c.joint_user_scale(j);
  return q;
}

// "--xyz X Y Z --quat W X Y Z" of a pose (mm), the quaternion from Eigen.
std::string pose_args(const kin::Pose& T) {
  const Eigen::Vector3d p = T.translation() * 1000.0;
  const Eigen::Quaterniond qu(T.linear());
  return " --xyz " + fmt(p.x()) + " " + fmt(p.y()) + " " + fmt(p.z()) + " --quat " + fmt(qu.w()) + " " +
         fmt(qu.x()) + " " + fmt(qu.y()) + " " + fmt(qu.z());
}

std::string json_string(const std::string& json, const std::string& key) {
  const std::size_t k = json.find("\"" + key + "\": \"");
  if (k == std::string::npos) return "";
  const std::size_t b = k + key.size() + 5;
  return json.substr(b, json.find('"', b) - b);
}

int json_int(const std::string& json, const std::string& key) {
  const std::size_t k = json.find("\"" + key + "\": ");
  if (k == std::string::npos) return -99;
  return std::atoi(json.c_str() + k + key.size() + 4);
}

bool json_bool(const std::string& json, const std::string& key) {
  return json.find("\"" + key + "\": true") != std::string::npos;
}

struct Sol {
  std::vector<double> joints;
  int shoulder = 0, elbow = 0, wrist = 0;
  bool within = false, singular = true;
};

// The objects of the "solutions" array.
std::vector<Sol> solutions(const std::string& json) {
  std::vector<Sol> v;
  std::size_t at = json.find("\"solutions\": [");
  if (at == std::string::npos) return v;
  while ((at = json.find("{\"joints\":", at)) != std::string::npos) {
    const std::size_t end = json.find('}', json.find("\"branch\":", at) + 10);  // after the branch object
    const std::string obj = json.substr(at, json.find('}', end + 1) - at + 1);
    Sol s;
    s.joints = json_numbers(obj, "joints");
    s.shoulder = json_int(obj, "shoulder");
    s.elbow = json_int(obj, "elbow");
    s.wrist = json_int(obj, "wrist");
    s.within = json_bool(obj, "within_limits");
    s.singular = json_bool(obj, "singular");
    v.push_back(s);
    at += obj.size();
  }
  return v;
}

bool empty_solution_list(const std::string& json) { return json.find("\"solutions\": []") != std::string::npos; }

// Library FK of the printed joints against the requested pose.
void check_reaches(const kin::Chain& c, const Sol& s, const kin::Pose& T, const std::string& what) {
  LONGS_EQUAL_TEXT(c.n_joints, static_cast<long>(s.joints.size()), what.c_str());
  const kin::JointVector q = to_si(c, s.joints);
  kin::Pose X;
  LONGS_EQUAL_TEXT(0, static_cast<int>(kin::forward(c, q, X)), what.c_str());
  const double ep = (X.translation() - T.translation()).norm();
  const double er = kin::rotation_error(X.linear(), T.linear()).norm();
  // joints are printed with 10 significant digits (1e-7 deg): ~1e-9 m, 1e-8 rad
  if (!(ep < 1e-7 && er < 1e-7))
    FAIL((what + ": FK misses the target by " + fmt(ep) + " m, " + fmt(er) + " rad").c_str());
  CHECK_EQUAL_TEXT(kin::within_limits(c, q, 1e-7), s.within, what.c_str());
}

void check_one_line_error(const test::CommandResult& r, const std::string& label, int status = 2) {
  LONGS_EQUAL_TEXT(status, r.status, label.c_str());
  CHECK_TEXT(r.err.rfind("armctl: ", 0) == 0, label.c_str());
  CHECK_TEXT(!r.err.empty() && r.err.find('\n') == r.err.size() - 1, label.c_str());
}
}  // namespace

TEST_GROUP(ArmctlIk){};

TEST(ArmctlIk, AllEightPumaSolutionsReachTheRequestedPose) {
  const kin::Chain c = load("puma560");
  std::mt19937_64 rng(31);
  for (int k = 0; k < 12; ++k) {
    // A generic in-limit configuration away from the singularities.
    kin::JointVector q0(6);
    for (int j = 0; j < 6; ++j) {
      const auto& r = c.joint(j);
      q0[j] = std::uniform_real_distribution<double>(r.lower + 0.2, r.upper - 0.2)(rng);
    }
    if (std::abs(std::sin(q0[4])) < 0.2) q0[4] = 0.8;
    kin::Pose T;
    kin::forward(c, q0, T);
    const std::string label = "pose " + std::to_string(k);
    const auto r = run_command(kArmctl + " kin ik --robot puma560 --all --json" + pose_args(T));
    const std::string what = label + ": " + r.out + r.err;
    const std::string status = json_string(r.out, "status");
    CHECK_TEXT(status == "ok" || status == "singular", what.c_str());
    LONGS_EQUAL_TEXT(0, r.status, what.c_str());
    const std::vector<Sol> sols = solutions(r.out);
    if (status == "singular") continue;  // (near a singularity by chance: fewer may be returned)
    LONGS_EQUAL_TEXT(8, static_cast<long>(sols.size()), what.c_str());
    bool original = false;
    for (std::size_t i = 0; i < sols.size(); ++i) {
      check_reaches(c, sols[i], T, label + " solution " + std::to_string(i));
      CHECK_TEXT(!sols[i].singular, what.c_str());
      CHECK_TEXT(std::abs(sols[i].shoulder) == 1 && std::abs(sols[i].elbow) == 1 && std::abs(sols[i].wrist) == 1,
                 what.c_str());
      for (std::size_t t = 0; t < i; ++t)
        CHECK_TEXT(!(sols[i].shoulder == sols[t].shoulder && sols[i].elbow == sols[t].elbow &&
                     sols[i].wrist == sols[t].wrist),
                   (what + " (two solutions on one branch)").c_str());
      double gap = 0;
      for (int j = 0; j < 6; ++j)
        gap = std::max(gap, std::abs(std::remainder(sols[i].joints[static_cast<std::size_t>(j)] - deg(q0[j]), 360.0)));
      original = original || gap < 1e-6;
    }
    CHECK_TEXT(original, (what + " (the configuration the pose came from is missing)").c_str());
  }
}

TEST(ArmctlIk, OtherArmsAndOrientationFormsReachThePose) {
  // Stanford (prismatic joint 3, mm) with --rpy, ist6 with --zyz: every
  // solution checked by FK. The angles for the command line are computed here.
  {
    const kin::Chain c = load("stanford");
    kin::JointVector q0(6);
    q0 << 0.5, 1.1, 0.0, -0.4, 0.9, 0.3;
    q0[2] = 0.5 * (c.joint(2).lower + c.joint(2).upper);
    kin::Pose T;
    kin::forward(c, q0, T);
    // RPY of T's rotation computed here: R = Rz(Y) Ry(P) Rx(R)
    const Eigen::Matrix3d Rm = T.linear();
    const double P = deg(std::asin(-Rm(2, 0))), R = deg(std::atan2(Rm(2, 1), Rm(2, 2))),
                 Y = deg(std::atan2(Rm(1, 0), Rm(0, 0)));
    const Eigen::Vector3d p = T.translation() * 1000;
    const auto r = run_command(kArmctl + " kin ik --robot stanford --all --json --xyz " + fmt(p.x()) + " " +
                               fmt(p.y()) + " " + fmt(p.z()) + " --rpy " + fmt(R) + " " + fmt(P) + " " + fmt(Y));
    LONGS_EQUAL_TEXT(0, r.status, (r.out + r.err).c_str());
    const std::vector<Sol> sols = solutions(r.out);
    CHECK_TEXT(!sols.empty(), r.out.c_str());
    for (std::size_t i = 0; i < sols.size(); ++i) check_reaches(c, sols[i], T, "stanford " + std::to_string(i));
  }
  {
    const kin::Chain c = load("ist6");
    kin::JointVector q0(6);
    q0 << 0.4, 0.3, -0.6, 0.2, 0.7, -0.5;
    kin::Pose T;
    kin::forward(c, q0, T);
    // ZYZ angles of T's rotation computed here: R = Rz(a) Ry(b) Rz(g)
    const Eigen::Matrix3d Rm = T.linear();
    const double b = std::atan2(std::hypot(Rm(0, 2), Rm(1, 2)), Rm(2, 2));
    const double a = std::atan2(Rm(1, 2), Rm(0, 2)), g = std::atan2(Rm(2, 1), -Rm(2, 0));
    const Eigen::Vector3d p = T.translation() * 1000;
    const auto r = run_command(kArmctl + " kin ik --robot ist6 --all --json --xyz " + fmt(p.x()) + " " + fmt(p.y()) +
                               " " + fmt(p.z()) + " --zyz " + fmt(deg(a)) + " " + fmt(deg(b)) + " " + fmt(deg(g)));
    LONGS_EQUAL_TEXT(0, r.status, (r.out + r.err).c_str());
    const std::vector<Sol> sols = solutions(r.out);
    CHECK_TEXT(sols.size() >= 4, r.out.c_str());
    for (std::size_t i = 0; i < sols.size(); ++i) check_reaches(c, sols[i], T, "ist6 " + std::to_string(i));
  }
}

TEST(ArmctlIk, NearPicksTheSolutionNearestToTheGivenJoints) {
  const kin::Chain c = load("puma560");
  kin::JointVector q0(6);
  q0 << 0.3, -0.9, 0.6, 0.4, 0.9, -0.2;
  kin::Pose T;
  kin::forward(c, q0, T);
  const auto all = run_command(kArmctl + " kin ik --robot puma560 --all --json" + pose_args(T));
  LONGS_EQUAL(0, all.status);
  const std::vector<Sol> sols = solutions(all.out);
  LONGS_EQUAL(8, static_cast<long>(sols.size()));
  std::mt19937_64 rng(5);
  int checked = 0;
  for (int k = 0; k < 16; ++k) {
    // --near: one solution plus up to 20 degrees per joint, or random joints
    std::vector<double> near(6);
    for (int j = 0; j < 6; ++j)
      near[static_cast<std::size_t>(j)] =
          k < 8 ? sols[static_cast<std::size_t>(k)].joints[static_cast<std::size_t>(j)] +
                      std::uniform_real_distribution<double>(-20, 20)(rng)
                : std::uniform_real_distribution<double>(-150, 150)(rng);
    // Expected: the within-limits solution with the least squared joint
    // distance, each angle taken as its 360-degree equivalent within the
    // limits nearest to --near (what armctl reports with --near).
    int best = -1;
    double bd = 0;
    std::vector<double> best_q;
    for (std::size_t i = 0; i < sols.size(); ++i) {
      if (!sols[i].within) continue;
      std::vector<double> qq = sols[i].joints;
      double d = 0;
      for (int j = 0; j < 6; ++j) {
        const double lo = deg(c.joint(j).lower), hi = deg(c.joint(j).upper);
        double& v = qq[static_cast<std::size_t>(j)];
        double pick = v, pd = 1e300;
        for (int t = -2; t <= 2; ++t) {
          const double w = v + 360.0 * t;
          if (w < lo - 1e-9 || w > hi + 1e-9) continue;
          if (std::abs(w - near[static_cast<std::size_t>(j)]) < pd) pick = w, pd = std::abs(w - near[static_cast<std::size_t>(j)]);
        }
        v = pick;
        const double e = v - near[static_cast<std::size_t>(j)];
        d += e * e;
      }
      if (best < 0 || d < bd) best = static_cast<int>(i), bd = d, best_q = qq;
    }
    std::string args;
    for (double v : near) args += " " + fmt(v);
    const auto r = run_command(kArmctl + " kin ik --robot puma560 --json" + pose_args(T) + " --near" + args);
    const std::string what = "near" + args + ": " + r.out + r.err;
    if (best < 0) continue;
    LONGS_EQUAL_TEXT(0, r.status, what.c_str());
    const std::vector<Sol> one = solutions(r.out);
    LONGS_EQUAL_TEXT(1, static_cast<long>(one.size()), what.c_str());
    for (int j = 0; j < 6; ++j)
      DOUBLES_EQUAL_TEXT(best_q[static_cast<std::size_t>(j)], one[0].joints[static_cast<std::size_t>(j)], 1e-6,
                         what.c_str());
    check_reaches(c, one[0], T, what);
    ++checked;
  }
  CHECK(checked >= 12);
}

TEST(ArmctlIk, UnreachableSaysSoWithAnEmptyListAndExitStatus1) {
  for (const char* args : {"--robot puma560 --xyz 3000 0 0 --zyz 0 0 0", "--robot puma560 --xyz 0 5000 100 --rpy 0 90 0",
                           "--robot ist6 --xyz 4000 1000 2000 --quat 1 0 0 0", "--robot trr --xyz 5000 0 0"}) {
    for (const char* json : {" --json", " --all --json"}) {
      const auto r = run_command(kArmctl + " kin ik " + args + json);
      const std::string what = std::string(args) + json + ": " + r.out + r.err;
      check_one_line_error(r, what, 1);
      CHECK_TEXT(json_string(r.out, "status") == "unreachable", what.c_str());
      CHECK_TEXT(empty_solution_list(r.out), what.c_str());
      CHECK_TEXT(r.err.find("unreachable") != std::string::npos, what.c_str());
    }
  }
}

TEST(ArmctlIk, BadInputIsOneLineAndExitStatus2) {
  struct Case {
    const char* args;
    const char* expect;
  } cases[] = {
      {"kin ik --robot puma560 --xyz nan 0 0 --zyz 0 0 0", "--xyz needs 3 finite numbers"},
      {"kin ik --robot puma560 --xyz 400 inf 0 --zyz 0 0 0", "--xyz needs 3 finite numbers"},
      {"kin ik --robot puma560 --xyz 400 100 --zyz 0 0 0", "--xyz needs 3 finite numbers"},
      {"kin ik --robot puma560 --xyz 400 100 300 --quat 0 0 0 0", "quaternion is zero"},
      {"kin ik --robot puma560 --xyz 400 100 300 --quat 1 nan 0 0", "--quat needs 4 finite numbers"},
      {"kin ik --robot puma560 --xyz 400 100 300 --rpy 0 nan 0", "--rpy needs 3 finite numbers"},
      {"kin ik --robot puma560 --xyz 400 100 300", "an orientation is required"},
      {"kin ik --robot puma560 --zyz 0 0 0", "--xyz X Y Z is required"},
      {"kin ik --xyz 400 100 300 --zyz 0 0 0", "--robot is required"},
      {"kin ik --robot puma560 --xyz 400 100 300 --zyz 0 0 0 --rpy 0 0 0", "give one orientation"},
      {"kin ik --robot puma560 --xyz 400 100 300 --zyz 0 0 0 --near 1 2 3", "--near: "},
      {"kin ik --robot puma560 --xyz 400 100 300 --zyz 0 0 0 --near 0 0 nan 0 0 0", "--near: 'nan' is not a finite number"},
      {"kin ik --robot puma560 --xyz 400 100 300 --zyz 0 0 0 --keep-branch", "--keep-branch needs --near"},
      {"kin ik --robot puma561 --xyz 400 100 300 --zyz 0 0 0", "unknown robot 'puma561'"},
      {"kin ik --robot puma560 --xyz 400 100 300 --zyz 0 0 0 --bogus", "unknown argument '--bogus'"},
      {"kin precision --robot puma560 --resolution 0.01 0.01 0.01 0.01 0.01 0 0 0 0 0 0", "has 6 joints, got"},
      {"kin precision --robot puma560 --resolution 0.01 0.01 -0.01 0.01 0.01 0.01 0 0 0 0 0 0", "must be >= 0"},
      {"kin precision --robot puma560 --resolution 0.01 0.01 0.01 0.01 0.01 nan 0 0 0 0 0 0", "'nan' is not a finite number"},
      {"kin precision --robot puma560 0 0 0 0 0 0", "--resolution d1..dn is required"},
      {"kin precision --resolution 1 1", "--robot is required"},
      // absurd targets name the option (cli_common's check_position / check_angles)
      {"kin ik --robot puma560 --xyz 400 100 300 --rpy 1e300 0 0", "--rpy: 1e+300 deg is not a plausible angle"},
      {"kin ik --robot puma560 --xyz 400 100 300 --rpy 0 0 -3601", "--rpy: -3601 deg is not a plausible angle"},
      {"kin ik --robot puma560 --xyz 400 100 300 --zyz 0 1e300 0", "--zyz: 1e+300 deg is not a plausible angle"},
      {"kin ik --robot puma560 --xyz 1e300 100 300 --zyz 0 0 0", "--xyz: 1e+300 mm is not a plausible position"},
      {"kin ik --robot puma560 --xyz 400 -2e6 300 --rpy 0 0 0", "--xyz: -2000000 mm is not a plausible position"},
      {"kin ik --robot trr --xyz 0 0 -1e308", "--xyz: -1e+308 mm is not a plausible position"},
      {"kin ik --robot ist6 --xyz 1e300 0 0 --quat 1 0 0 0", "--xyz: 1e+300 mm"},
      // --robot through the same checked loader as kin fk / plan
      {"kin ik --robot /tmp --xyz 400 100 300 --zyz 0 0 0", "/tmp: not a regular file (a directory)"},
      {"kin ik --robot /dev/zero --xyz 400 100 300 --zyz 0 0 0", "/dev/zero: not a regular file"},
      {"kin precision --robot /tmp --resolution 0.1 0.1 10 20", "/tmp: not a regular file (a directory)"},
      // a sum that overflows is refused, not printed as null
      {"kin precision --robot rr_planar --resolution 1e308 1e308 10 20", "precision: the tool position error is not finite"},
      {"kin precision --robot rr_planar --resolution 1e308 1e308 10 20 --json", "is not finite"},
  };
  for (const Case& k : cases) {
    const auto r = run_command(kArmctl + " " + k.args);
    const std::string label = std::string(k.args) + " -> " + r.err;
    check_one_line_error(r, label, 2);
    CHECK_TEXT(r.err.find(k.expect) != std::string::npos, label.c_str());
    CHECK_TEXT(r.out.empty(), label.c_str());
  }
}

TEST(ArmctlIk, HugeQuaternionComponentsGiveTheRotationOfTheirDirection) {
  // Only the direction of --quat counts: 1e300 1e300 0 0 is Rx(90 deg) (w*w would overflow
  // if summed unscaled), and the answer is that of 1 1 0 0.
  const auto a = run_command(kArmctl + " kin ik --robot puma560 --xyz 400 150 300 --quat 1e300 1e300 0 0 --all --json");
  const auto b = run_command(kArmctl + " kin ik --robot puma560 --xyz 400 150 300 --quat 1 1 0 0 --all --json");
  LONGS_EQUAL_TEXT(0, a.status, (a.out + a.err).c_str());
  LONGS_EQUAL_TEXT(0, b.status, (b.out + b.err).c_str());
  CHECK(!solutions(a.out).empty());
  STRCMP_EQUAL(b.out.c_str(), a.out.c_str());
  // at the 3600 deg bound the angle is still accepted
  const auto c = run_command(kArmctl + " kin ik --robot puma560 --xyz 400 150 300 --rpy 3600 0 0 --json");
  LONGS_EQUAL_TEXT(0, c.status, (c.out + c.err).c_str());
}

TEST(ArmctlIk, PrecisionMatchesCentralDifferences) {
  // dw_k = sum_i |dw_k/dq_i| dq_i, the partial derivatives by central
  // differences of the library FK (independent of the Jacobian armctl uses).
  struct Case {
    const char* robot;
    std::vector<double> res, q;  // description units
  } cases[] = {
      {"puma560", {0.01, 0.01, 0.02, 0.05, 0.05, 0.1}, {10, -40, 60, 30, 45, -20}},
      {"puma560", {0.001, 0.002, 0.003, 0.004, 0.005, 0.006}, {-120, -150, 170, -90, 80, 200}},
      {"stanford", {0.01, 0.01, 0.1, 0.02, 0.02, 0.02}, {30, 60, 400, 10, -30, 5}},
      {"rr_planar", {0.01, 0.01}, {30, 45}},
      {"ist6", {0.005, 0.005, 0.005, 0.01, 0.01, 0.01}, {20, 10, -30, 40, 60, -10}},
  };
  for (const Case& k : cases) {
    const kin::Chain c = load(k.robot);
    std::string args = std::string(" kin precision --json --robot ") + k.robot + " --resolution";
    for (double d : k.res) args += " " + fmt(d);
    for (double v : k.q) args += " " + fmt(v);
    const auto r = run_command(kArmctl + args);
    const std::string what = args + ": " + r.out + r.err;
    LONGS_EQUAL_TEXT(0, r.status, what.c_str());
    const kin::JointVector q = to_si(c, k.q);
    Eigen::Vector3d dw = Eigen::Vector3d::Zero();
    for (int i = 0; i < c.n_joints; ++i) {
      const double h = 1e-6;
      kin::JointVector a = q, b = q;
      a[i] += h;
      b[i] -= h;
      kin::Pose Ta, Tb;
      kin::forward(c, a, Ta);
      kin::forward(c, b, Tb);
      const Eigen::Vector3d dpdq = (Ta.translation() - Tb.translation()) / (2 * h);
      dw += dpdq.cwiseAbs() * (k.res[static_cast<std::size_t>(i)] / c.joint_user_scale(i));
    }
    dw *= 1000.0;  // mm
    const double dx = std::strtod(r.out.c_str() + r.out.find("\"dx\": ") + 6, nullptr);
    const double dy = std::strtod(r.out.c_str() + r.out.find("\"dy\": ") + 6, nullptr);
    const double dz = std::strtod(r.out.c_str() + r.out.find("\"dz\": ") + 6, nullptr);
    DOUBLES_EQUAL_TEXT(dw.x(), dx, 1e-6 * (1 + dw.norm()), what.c_str());
    DOUBLES_EQUAL_TEXT(dw.y(), dy, 1e-6 * (1 + dw.norm()), what.c_str());
    DOUBLES_EQUAL_TEXT(dw.z(), dz, 1e-6 * (1 + dw.norm()), what.c_str());
    CHECK_TEXT(dw.norm() > 0, what.c_str());
  }
  // Text form names the unit.
  const auto r = run_command(kArmctl + " kin precision --robot rr_planar --resolution 0.01 0.01 30 45");
  LONGS_EQUAL(0, r.status);
  CHECK(r.out.find("[mm]") != std::string::npos);
}
