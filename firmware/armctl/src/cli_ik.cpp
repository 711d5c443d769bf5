// SPDX-License-Identifier: Apache-2.0
// armctl kin ik | precision
#include "servoarm/armctl/cli_ik.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "servoarm/armctl/cli_common.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/kinematics/ik.hpp"
#include "servoarm/kinematics/orientation.hpp"

namespace servoarm::fw {
namespace {

const char* kIkUsage =
    "usage: armctl kin ik --robot NAME|FILE --xyz X Y Z (--zyz A B G | --rpy R P Y | --quat W X Y Z)\n"
    "                     [--all] [--near q1..qn] [--keep-branch] [--json]\n"
    "  Inverse kinematics of the tool pose, in the units of the description (built-in\n"
    "  models: mm and degrees). ZYZ: R = Rz(A) Ry(B) Rz(G); RPY: R = Rz(Y) Ry(P) Rx(R).\n"
    "  Closed form (every solution) where the arm has one, numerical otherwise; the\n"
    "  output names the method and the path (closed form, general, numeric).\n"
    "  Without --all: the solution nearest to --near (default: all joints 0) within the\n"
    "  limits (--keep-branch: on the same shoulder/elbow/wrist branch as --near).\n"
    "  Arms that control fewer than 6 coordinates read what they control: the tool\n"
    "  position (RR, TRR: the rotation may be omitted), plus the heading about the base\n"
    "  z axis (RRR, RLR) or the pitch (TRL:R, VVL:R) from the rotation.\n"
    "  Exit status: 0 solved (also at a singularity), 1 unreachable or no solution within\n"
    "  the limits, 2 bad usage or input.\n";
const char* kPrecisionUsage =
    "usage: armctl kin precision --robot NAME|FILE --resolution d1..dn q1..qn [--json]\n"
    "  Worst-case tool position error from per-joint resolutions (Carrara, Apostila de Robótica, 3.14):\n"
    "  dw = sum_i |dw/dq_i| dq_i at the configuration q, in the description's length\n"
    "  unit. Resolutions and joints in the joint units (built-ins: deg / mm).\n";

bool is_option(const char* s) { return s[0] == '-' && s[1] == '-'; }

// Reads exactly n numbers after argv[i]; false with an error message otherwise.
bool take_numbers(int argc, char** argv, int& i, int n, double* out, const std::string& opt, std::string& err) {
  for (int k = 0; k < n; ++k) {
    if (i + 1 >= argc || !parse_number(argv[i + 1], out[k])) {
      err = opt + " needs " + std::to_string(n) + " finite numbers";
      return false;
    }
    ++i;
  }
  return true;
}

// Every number following argv[i] up to the next option.
void take_list(int argc, char** argv, int& i, std::vector<double>& out, std::string& bad) {
  while (i + 1 < argc && !is_option(argv[i + 1])) {
    double v;
    if (!parse_number(argv[i + 1], v)) {
      bad = argv[i + 1];
      return;
    }
    out.push_back(v);
    ++i;
  }
}

std::string branch_json(const kin::Branch& b) {
  return "{\"shoulder\": " + std::to_string(b.shoulder) + ", \"elbow\": " + std::to_string(b.elbow) +
         ", \"wrist\": " + std::to_string(b.wrist) + "}";
}

// Which IK path solved it, said in the output (a model that is
// almost but not exactly of a closed-form class must say it did not take it).
const char* ik_path(kin::IkMethod m) {
  switch (m) {
    case kin::IkMethod::none: return "numeric";
    case kin::IkMethod::spherical_general: return "general";
    case kin::IkMethod::spherical_wrist:
    case kin::IkMethod::opw:
    case kin::IkMethod::ur:
    case kin::IkMethod::planar_2r:
    case kin::IkMethod::planar_3:
    case kin::IkMethod::spatial_3:
    case kin::IkMethod::pitch_4: return "closed_form";
  }
  return "numeric";
}
const char* ik_path_text(kin::IkMethod m) {
  switch (m) {
    case kin::IkMethod::none: return "numerical solver (no closed form fits these DH rows)";
    case kin::IkMethod::spherical_general: return "general path (spherical wrist, degree-8 resultant)";
    case kin::IkMethod::spherical_wrist:
    case kin::IkMethod::opw:
    case kin::IkMethod::ur:
    case kin::IkMethod::planar_2r:
    case kin::IkMethod::planar_3:
    case kin::IkMethod::spatial_3:
    case kin::IkMethod::pitch_4: return "closed form";
  }
  return "";
}

std::string kinds(std::uint8_t k) {
  char buf[40];
  return kin::singular_kinds_to_string(k, buf, sizeof buf);
}

}  // namespace

int cli_kin_ik(int argc, char** argv) {
  std::string robot;
  bool json = false, all = false, keep = false, have_xyz = false, have_near = false;
  int n_rot = 0;
  double xyz[3] = {0, 0, 0}, ang[4] = {0, 0, 0, 0};
  enum { kNone, kZyz, kRpy, kQuat } rot = kNone;
  std::vector<double> near;
  std::string err;
  for (int i = 1; i < argc; ++i) {
    const std::string s = argv[i];
    if (s == "--help" || s == "-h") {
      std::fputs(kIkUsage, stdout);
      return kExitOk;
    } else if (s == "--robot") {
      if (++i >= argc) return usage_error("--robot needs a model name or a file path");
      robot = argv[i];
    } else if (s == "--xyz") {
      if (!take_numbers(argc, argv, i, 3, xyz, s, err)) return usage_error(err);
      have_xyz = true;
    } else if (s == "--zyz" || s == "--rpy" || s == "--quat") {
      if (rot != kNone) return usage_error("give one orientation: --zyz, --rpy or --quat");
      rot = s == "--zyz" ? kZyz : s == "--rpy" ? kRpy : kQuat;
      n_rot = rot == kQuat ? 4 : 3;
      if (!take_numbers(argc, argv, i, n_rot, ang, s, err)) return usage_error(err);
    } else if (s == "--all") {
      all = true;
    } else if (s == "--keep-branch") {
      keep = true;
    } else if (s == "--json") {
      json = true;
    } else if (s == "--near") {
      std::string bad;
      take_list(argc, argv, i, near, bad);
      if (!bad.empty()) return usage_error("--near: '" + bad + "' is not a finite number");
      have_near = true;
    } else {
      return usage_error("unknown argument '" + s + "' (see armctl kin ik --help)");
    }
  }
  if (robot.empty()) return usage_error("--robot is required (see armctl kin models)");
  if (!have_xyz) return usage_error("--xyz X Y Z is required");
  if (keep && !have_near) return usage_error("--keep-branch needs --near q1..qn (the current joints)");
  const kin::LoadResult lr = load_robot_checked(robot);
  if (!lr.ok) return usage_error(lr.error);
  const kin::Chain& chain = lr.chain;
  // Plausible targets only (cli_common: at most 1 km, 3600 deg), naming the option: an
  // absurd value (1e300) would otherwise reach the solver as an overflowed pose.
  if (const std::string e = check_position("--xyz", {xyz[0], xyz[1], xyz[2]}, chain); !e.empty())
    return usage_error(e);
  if (rot == kZyz || rot == kRpy) {
    if (const std::string e = check_angles(rot == kZyz ? "--zyz" : "--rpy", {ang[0], ang[1], ang[2]}, chain);
        !e.empty())
      return usage_error(e);
  } else if (rot == kQuat) {
    // Only the direction of the quaternion counts; scale by the largest component so that
    // w*w + ... cannot overflow (1e300 1 0 0 is the identity's neighbour, not an error).
    double big = 0;
    for (int k = 0; k < 4; ++k) big = std::max(big, std::abs(ang[k]));
    if (big > 0)
      for (int k = 0; k < 4; ++k) ang[k] /= big;
  }
  kin::IkModel model;
  if (kin::ik_prepare(chain, model) != kin::Status::ok) return usage_error("cannot analyse this chain");
  const bool position_only = model.method == kin::IkMethod::planar_2r || model.method == kin::IkMethod::spatial_3;
  if (rot == kNone && !position_only)
    return usage_error("an orientation is required for this arm: --zyz A B G, --rpy R P Y or --quat W X Y Z");
  kin::Pose T = kin::Pose::Identity();
  T.translation() = Eigen::Vector3d(xyz[0], xyz[1], xyz[2]) * chain.length_unit;
  const double A = chain.angle_unit;
  if (rot == kZyz) {
    T.linear() = kin::rotation_from_zyz({ang[0] * A, ang[1] * A, ang[2] * A});
  } else if (rot == kRpy) {
    T.linear() = kin::rotation_from_rpy(ang[0] * A, ang[1] * A, ang[2] * A);
  } else if (rot == kQuat) {
    Eigen::Matrix3d R;
    if (kin::rotation_from_quaternion(ang[0], ang[1], ang[2], ang[3], R) != kin::Status::ok)
      return usage_error("--quat: the quaternion is zero (or not finite)");
    T.linear() = R;
  }
  kin::JointVector q_near = kin::JointVector::Zero(chain.n_joints);
  if (have_near) {
    if (!joints_from_user(chain, near, q_near, err)) return usage_error("--near: " + err);
  }
  // Solve.
  struct Out {
    kin::JointVector q;
    kin::Branch branch;
    bool within = false;
    std::uint8_t singular = 0;
  };
  std::vector<Out> outs;
  kin::Status status;
  std::string status_text;  // overrides to_string(status) where the code says too little
  const char* method = kin::to_string(model.method);
  double residual_p = 0, residual_r = 0;
  int iterations = -1;
  if (model.method == kin::IkMethod::none) {
    kin::IkNumericOptions o;
    kin::IkNumericResult nr;
    kin::ik_numeric(chain, T, q_near, o, nr);
    status = nr.status == kin::Status::not_converged ? kin::Status::unreachable : nr.status;
    residual_p = nr.position_error;
    residual_r = nr.rotation_error;
    iterations = nr.iterations;
    if (nr.status == kin::Status::ok) outs.push_back({nr.q, {}, kin::within_limits(chain, nr.q, 1e-9), 0});
  } else {
    kin::IkResult r;
    kin::ik_solve_all(model, T, have_near ? &q_near : nullptr, r);
    status = r.status;
    if (r.status == kin::Status::bad_input) return usage_error("the target is not a valid pose (NaN/Inf or not a rotation)");
    if (all) {
      for (int i = 0; i < r.count; ++i) {
        const auto& s = r.solutions[static_cast<std::size_t>(i)];
        outs.push_back({s.q, s.branch, s.within_limits, s.singular});
      }
    } else if (r.count > 0) {
      kin::IkChoice choice;
      choice.keep_branch = keep;
      const int i = kin::ik_choose(model, r, q_near, choice);
      if (i >= 0) {
        const auto& s = r.solutions[static_cast<std::size_t>(i)];
        outs.push_back({s.q, s.branch, s.within_limits, s.singular});
        status = s.singular ? kin::Status::singular : kin::Status::ok;
      } else {
        status = kin::Status::out_of_limits;
        if (keep && r.status != kin::Status::out_of_limits) status_text = "no_solution_on_branch";
        err = keep ? "no solution on the current branch within the limits" : "no solution within the joint limits";
      }
    }
  }
  const bool failed = !(status == kin::Status::ok || status == kin::Status::singular);
  if (status_text.empty()) status_text = kin::to_string(status);
  if (json) {
    std::string s = "{\"robot\": \"" + std::string(chain.name.data()) + "\", \"method\": \"" + method +
                    "\", \"path\": \"" + ik_path(model.method) + "\", \"status\": \"" + status_text + "\", \"length_unit\": \"" +
                    length_unit_name(chain) + "\", \"angle_unit\": \"" + angle_unit_name(chain) + "\"";
    if (iterations >= 0)
      s += ", \"iterations\": " + std::to_string(iterations) + ", \"position_residual\": " +
           num(residual_p / chain.length_unit) + ", \"rotation_residual\": " + num(residual_r / A);
    s += ", \"solutions\": [";
    for (std::size_t i = 0; i < outs.size(); ++i) {
      const std::vector<double> ju = joints_to_user(chain, outs[i].q);
      s += (i ? ", " : "") + std::string("{\"joints\": ") + json_array(ju.data(), static_cast<int>(ju.size())) +
           ", \"branch\": " + branch_json(outs[i].branch) + ", \"within_limits\": " +
           (outs[i].within ? "true" : "false") + ", \"singular\": " + (outs[i].singular ? "true" : "false") +
           ", \"singular_kinds\": \"" + kinds(outs[i].singular) + "\"}";
    }
    s += "]}";
    std::printf("%s\n", s.c_str());
  } else {
    std::printf("robot %s: method %s (%s), status %s\n", chain.name.data(), method, ik_path_text(model.method),
                status_text.c_str());
    if (iterations >= 0)
      std::printf("numerical: %d iterations, residual %s %s, %s %s\n", iterations,
                  num(residual_p / chain.length_unit).c_str(), length_unit_name(chain), num(residual_r / A).c_str(),
                  angle_unit_name(chain));
    for (std::size_t i = 0; i < outs.size(); ++i) {
      const std::vector<double> ju = joints_to_user(chain, outs[i].q);
      std::string line = "solution " + std::to_string(i + 1) + ":";
      for (int j = 0; j < chain.n_joints; ++j) line += " " + num(ju[static_cast<std::size_t>(j)]);
      line += "  [";
      for (int j = 0; j < chain.n_joints; ++j) line += std::string(j ? " " : "") + joint_unit_name(chain, j);
      line += "]  shoulder " + std::to_string(outs[i].branch.shoulder) + " elbow " +
              std::to_string(outs[i].branch.elbow) + " wrist " + std::to_string(outs[i].branch.wrist);
      line += outs[i].within ? "  within limits" : "  OUTSIDE limits";
      if (outs[i].singular) line += "  singular: " + kinds(outs[i].singular);
      std::printf("%s\n", line.c_str());
    }
  }
  if (failed) {
    if (err.empty()) err = status == kin::Status::unreachable ? "target unreachable" : kin::to_string(status);
    std::fprintf(stderr, "armctl: %s\n", err.c_str());
    return kExitFailed;
  }
  return kExitOk;
}

int cli_kin_precision(int argc, char** argv) {
  std::string robot;
  bool json = false, have_res = false;
  std::vector<double> res, q;
  for (int i = 1; i < argc; ++i) {
    const std::string s = argv[i];
    if (s == "--help" || s == "-h") {
      std::fputs(kPrecisionUsage, stdout);
      return kExitOk;
    } else if (s == "--robot") {
      if (++i >= argc) return usage_error("--robot needs a model name or a file path");
      robot = argv[i];
    } else if (s == "--json") {
      json = true;
    } else if (s == "--resolution") {
      std::string bad;
      take_list(argc, argv, i, res, bad);
      if (!bad.empty()) return usage_error("--resolution: '" + bad + "' is not a finite number");
      have_res = true;
    } else {
      double v;
      if (!parse_number(argv[i], v)) return usage_error("unknown argument '" + s + "' (see armctl kin precision --help)");
      q.push_back(v);
    }
  }
  if (robot.empty()) return usage_error("--robot is required (see armctl kin models)");
  if (!have_res) return usage_error("--resolution d1..dn is required");
  const kin::LoadResult lr = load_robot_checked(robot);
  if (!lr.ok) return usage_error(lr.error);
  const kin::Chain& chain = lr.chain;
  const auto n = static_cast<std::size_t>(chain.n_joints);
  // "--resolution d1..dn q1..qn": the list after --resolution holds both.
  if (q.empty() && res.size() == 2 * n) {
    q.assign(res.begin() + static_cast<long>(n), res.end());
    res.resize(n);
  }
  if (res.size() != n)
    return usage_error(std::string(chain.name.data()) + " has " + std::to_string(n) + " joints, got " +
                       std::to_string(res.size()) + " resolutions");
  for (double d : res)
    if (d < 0) return usage_error("--resolution: resolutions must be >= 0");
  kin::JointVector qs, dq;
  std::string err;
  if (!joints_from_user(chain, q, qs, err)) return usage_error(err);
  if (!joints_from_user(chain, res, dq, err)) return usage_error(err);
  Eigen::Vector3d dw;
  const kin::Status st = kin::cartesian_precision(chain, qs, dq, dw);
  if (st != kin::Status::ok) return usage_error(std::string("precision: ") + kin::to_string(st));
  dw /= chain.length_unit;
  // Huge resolutions or joint values (1e308) overflow the sum: an error, never printed.
  if (!all_finite(dw.data(), 3))
    return usage_error("precision: the tool position error is not finite for these resolutions and joint values");
  if (json) {
    std::printf("{\"robot\": \"%s\", \"length_unit\": \"%s\", \"dx\": %s, \"dy\": %s, \"dz\": %s}\n", chain.name.data(),
                length_unit_name(chain), num(dw.x()).c_str(), num(dw.y()).c_str(), num(dw.z()).c_str());
  } else {
    std::printf("worst-case tool position error [%s]:  dx %s  dy %s  dz %s\n", length_unit_name(chain),
                num(dw.x()).c_str(), num(dw.y()).c_str(), num(dw.z()).c_str());
  }
  return kExitOk;
}

}  // namespace servoarm::fw
