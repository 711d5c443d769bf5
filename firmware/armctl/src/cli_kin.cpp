// SPDX-License-Identifier: Apache-2.0
// armctl kin fk | jacobian | models
#include "servoarm/armctl/cli_kin.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "servoarm/armctl/cli_common.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/kinematics/orientation.hpp"

namespace servoarm::fw {
namespace {

struct KinArgs {
  std::string robot;
  bool json = false;
  bool strict = false;
  std::vector<double> values;
};

const char* kFkUsage =
    "usage: armctl kin fk --robot NAME|FILE [--json] [--strict] q1 ... qn\n"
    "  Forward kinematics: tool pose for the given joint values, in the units of the\n"
    "  description (built-in models: mm and degrees). A value outside its joint's\n"
    "  limits is a warning, or an error with --strict. Joint values for which the pose\n"
    "  is not finite (1e308) are an error (exit 2): nothing is printed, --json included.\n";
const char* kJacUsage =
    "usage: armctl kin jacobian --robot NAME|FILE [--json] [--strict] q1 ... qn\n"
    "  Geometric Jacobian at the tool point in the base frame: rows vx vy vz wx wy wz,\n"
    "  one column per joint. Linear rows in <length unit> per rad (revolute) or per\n"
    "  <length unit> (prismatic); angular rows in rad per rad (0 for prismatic joints).\n"
    "  Also prints the manipulability and the condition number (--json: null when singular).\n"
    "  A Jacobian that is not finite (joint values like 1e308) is an error (exit 2).\n";

// Returns -1 to continue, otherwise an exit code.
int parse(int argc, char** argv, const char* usage, KinArgs& a) {
  for (int i = 1; i < argc; ++i) {
    const std::string s = argv[i];
    if (s == "--help" || s == "-h") {
      std::fputs(usage, stdout);
      return kExitOk;
    } else if (s == "--robot") {
      if (++i >= argc) return usage_error("--robot needs a model name or a file path");
      a.robot = argv[i];
    } else if (s == "--json") {
      a.json = true;
    } else if (s == "--strict") {
      a.strict = true;
    } else {
      double v;
      if (!parse_number(argv[i], v)) {
        if (s.size() > 1 && s[0] == '-' && !(s[1] >= '0' && s[1] <= '9') && s[1] != '.')
          return usage_error("unknown option '" + s + "' (see armctl kin " + argv[0] + " --help)");
        return usage_error("joint value '" + s + "' is not a finite number");
      }
      a.values.push_back(v);
    }
  }
  if (a.robot.empty()) return usage_error("--robot is required (see armctl kin models)");
  return -1;
}

// Load the robot and the joints; -1 to continue.
int prepare(const KinArgs& a, kin::Chain& chain, kin::JointVector& q) {
  const kin::LoadResult r = load_robot_checked(a.robot);
  if (!r.ok) return usage_error(r.error);
  chain = r.chain;
  std::string err;
  if (!joints_from_user(chain, a.values, q, err)) return usage_error(err);
  std::string report;
  if (limit_violations(chain, q, report) > 0) {
    if (a.strict) {
      report.pop_back();
      return usage_error("outside the joint limits (--strict): " + report.substr(0, report.find('\n')));
    }
    std::string line;
    for (char c : report) {
      if (c == '\n') {
        std::fprintf(stderr, "armctl: warning: %s\n", line.c_str());
        line.clear();
      } else {
        line += c;
      }
    }
  }
  return -1;
}

// One line naming what is not finite, and the joint values furthest outside their limits.
int not_finite_error(const char* what, const kin::Chain& chain, const kin::JointVector& q) {
  std::string worst;
  double far = 0;
  for (int j = 0; j < chain.n_joints; ++j) {
    const kin::DhRow& r = chain.joint(j);
    const double out = std::max(r.lower - q[j], q[j] - r.upper);
    if (out > far) {
      far = out;
      worst = ", joint " + std::to_string(j + 1) + " = " + num(q[j] * chain.joint_user_scale(j)) + " " +
              joint_unit_name(chain, j) + " is far outside its limits";
    }
  }
  std::fprintf(stderr, "armctl: %s is not finite for these joint values%s\n", what, worst.c_str());
  return kExitUsage;
}

// A matrix entry for people: fixed point while it fits the column, otherwise %g.
std::string cell(double v) {
  char b[40];
  if (std::abs(v) < 5e-13) v = 0;
  std::snprintf(b, sizeof b, std::abs(v) < 1e7 ? "%12.6f" : "%12.5g", v);
  return b;
}

}  // namespace

int cli_kin_fk(int argc, char** argv) {
  KinArgs a;
  int rc = parse(argc, argv, kFkUsage, a);
  if (rc >= 0) return rc;
  kin::Chain chain;
  kin::JointVector q;
  if ((rc = prepare(a, chain, q)) >= 0) return rc;
  kin::Pose T;
  if (kin::forward(chain, q, T) != kin::Status::ok) return usage_error("forward kinematics failed");
  const double L = 1.0 / chain.length_unit, A = 1.0 / chain.angle_unit;
  const Eigen::Vector3d p = T.translation() * L;
  const Eigen::Matrix3d R = T.linear();
  const kin::ZyzSolutions z = kin::zyz_from_rotation(R);
  const Eigen::Vector3d rpy = kin::rpy_from_rotation(R) * A;
  const Eigen::Quaterniond quat = kin::quaternion_from_rotation(R);
  const double zyz0[3] = {z.branch[0].alpha * A, z.branch[0].beta * A, z.branch[0].gamma * A};
  const double zyz1[3] = {z.branch[1].alpha * A, z.branch[1].beta * A, z.branch[1].gamma * A};
  const double qq[4] = {quat.w(), quat.x(), quat.y(), quat.z()};
  const std::vector<double> ju = joints_to_user(chain, q);
  // A pose that is not finite (joint values like 1e308) is an error, never printed.
  if (!all_finite(p.data(), 3) || !all_finite(R.data(), 9)) return not_finite_error("the tool pose", chain, q);
  if (!all_finite(zyz0, 3) || !all_finite(zyz1, 3) || !all_finite(rpy.data(), 3) || !all_finite(qq, 4))
    return not_finite_error("the tool orientation", chain, q);
  if (a.json) {
    std::string s = "{\"robot\": \"" + std::string(chain.name.data()) + "\", \"length_unit\": \"" +
                    length_unit_name(chain) + "\", \"angle_unit\": \"" + angle_unit_name(chain) + "\", ";
    s += "\"joints\": " + json_array(ju.data(), static_cast<int>(ju.size())) + ", ";
    s += "\"position\": " + json_array(p.data(), 3) + ", \"rotation\": [";
    for (int r = 0; r < 3; ++r) {
      const double row[3] = {R(r, 0), R(r, 1), R(r, 2)};
      s += (r ? ", " : "") + json_array(row, 3);
    }
    s += "], \"zyz\": " + json_array(zyz0, 3);
    s += ", \"zyz_other\": " + json_array(zyz1, 3);
    s += std::string(", \"zyz_singular\": ") + (z.singular ? "true" : "false");
    s += ", \"rpy\": " + json_array(rpy.data(), 3) + ", \"quaternion\": " + json_array(qq, 4) + "}";
    std::printf("%s\n", s.c_str());
    return kExitOk;
  }
  const char* lu = length_unit_name(chain);
  const char* au = angle_unit_name(chain);
  std::printf("robot %s: %s DH, %d joints\n", chain.name.data(), kin::to_string(chain.convention), chain.n_joints);
  std::printf("position [%s]:   x %s   y %s   z %s\n", lu, num(p.x()).c_str(), num(p.y()).c_str(), num(p.z()).c_str());
  std::printf("rotation matrix:\n");
  auto clean = [](double v) { return std::abs(v) < 5e-13 ? 0.0 : v; };
  for (int r = 0; r < 3; ++r) std::printf("  %12.9f %12.9f %12.9f\n", clean(R(r, 0)), clean(R(r, 1)), clean(R(r, 2)));
  if (z.singular)
    std::printf("ZYZ [%s]:        alpha %s  beta %s  gamma %s   (sin beta = 0: only alpha%sgamma is defined; alpha set to 0)\n", au,
                num(zyz0[0]).c_str(), num(zyz0[1]).c_str(), num(zyz0[2]).c_str(), std::cos(z.branch[0].beta) > 0 ? "+" : "-");
  else {
    std::printf("ZYZ [%s]:        alpha %s  beta %s  gamma %s   (sin beta > 0)\n", au, num(zyz0[0]).c_str(), num(zyz0[1]).c_str(), num(zyz0[2]).c_str());
    std::printf("                 alpha %s  beta %s  gamma %s   (sin beta < 0)\n", num(zyz1[0]).c_str(), num(zyz1[1]).c_str(), num(zyz1[2]).c_str());
  }
  std::printf("RPY [%s]:        roll %s  pitch %s  yaw %s   (R = Rz(yaw) Ry(pitch) Rx(roll))\n", au, num(rpy[0]).c_str(),
              num(rpy[1]).c_str(), num(rpy[2]).c_str());
  std::printf("quaternion:      w %s  x %s  y %s  z %s\n", num(qq[0]).c_str(), num(qq[1]).c_str(), num(qq[2]).c_str(), num(qq[3]).c_str());
  return kExitOk;
}

int cli_kin_jacobian(int argc, char** argv) {
  KinArgs a;
  int rc = parse(argc, argv, kJacUsage, a);
  if (rc >= 0) return rc;
  kin::Chain chain;
  kin::JointVector q;
  if ((rc = prepare(a, chain, q)) >= 0) return rc;
  kin::Jacobian J;
  if (kin::jacobian(chain, q, J) != kin::Status::ok) return usage_error("Jacobian failed");
  if (!all_finite(J.data(), static_cast<int>(J.size()))) return not_finite_error("the Jacobian", chain, q);
  const double m = kin::manipulability(J), cond = kin::condition_number(J);
  if (!std::isfinite(m)) return not_finite_error("the manipulability", chain, q);
  kin::Jacobian Ju = J;
  for (int j = 0; j < chain.n_joints; ++j)
    if (chain.joint(j).type == kin::JointType::revolute) Ju.block<3, 1>(0, j) /= chain.length_unit;
  if (a.json) {
    std::string s = "{\"robot\": \"" + std::string(chain.name.data()) + "\", \"length_unit\": \"" +
                    length_unit_name(chain) + "\", \"jacobian\": [";
    for (int r = 0; r < 6; ++r) {
      std::vector<double> row(static_cast<std::size_t>(chain.n_joints));
      for (int j = 0; j < chain.n_joints; ++j) row[static_cast<std::size_t>(j)] = Ju(r, j);
      s += (r ? ", " : "") + json_array(row.data(), chain.n_joints);
    }
    s += "], \"manipulability\": " + num(m) + ", \"condition_number\": " +
         (std::isfinite(cond) ? num(cond) : std::string("null")) + "}";
    std::printf("%s\n", s.c_str());
    return kExitOk;
  }
  std::printf("robot %s: Jacobian at the tool point, base frame (linear rows in %s/rad or %s/%s)\n", chain.name.data(),
              length_unit_name(chain), length_unit_name(chain), length_unit_name(chain));
  const char* names[6] = {"vx", "vy", "vz", "wx", "wy", "wz"};
  for (int r = 0; r < 6; ++r) {
    std::printf("  %s", names[r]);
    for (int j = 0; j < chain.n_joints; ++j) std::printf(" %s", cell(Ju(r, j)).c_str());
    std::printf("\n");
  }
  std::printf("manipulability %s   condition number %s%s\n", num(m).c_str(), std::isfinite(cond) ? num(cond).c_str() : "inf",
              std::isfinite(cond) && cond < 1e6 ? "" : "   (singular)");
  return kExitOk;
}

int cli_kin_models(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--help") == 0 || std::strcmp(argv[i], "-h") == 0) {
      std::printf("usage: armctl kin models\n  Lists the built-in robot models (use the name with --robot).\n");
      return kExitOk;
    }
    return usage_error(std::string("kin models takes no arguments, got '") + argv[i] + "'");
  }
  for (const auto& m : kin::builtin_models()) {
    const kin::LoadResult r = kin::load_robot(m.name);
    std::printf("%-22s %d joints  %s\n", m.name, r.ok ? r.chain.n_joints : 0, m.summary);
  }
  return kExitOk;
}

}  // namespace servoarm::fw
