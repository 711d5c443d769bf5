// SPDX-License-Identifier: Apache-2.0
#include "servoarm/armctl/cli_common.hpp"

#include "servoarm/lang/number.hpp"
#include "servoarm/lang/text.hpp"
#include "servoarm/lang/units.hpp"

#include <sys/stat.h>

#include <cerrno>
#include <cmath>
#include <cstdlib>

namespace servoarm::fw {

bool parse_number(const char* s, double& out) {
  // The console's decimal reader (servoarm/lang/number.hpp): one grammar for every
  // number typed at armctl, armfw or the console.
  return s && parse_decimal(s, out) == Num::ok;
}

int usage_error(const std::string& message) {
  std::fprintf(stderr, "armctl: %s\n", message.c_str());
  return kExitUsage;
}

std::string num(double v) {
  if (!std::isfinite(v)) return "null";
  if (std::abs(v) < 5e-13) v = 0;  // round-off dust and "-0" print as 0
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.10g", v);
  return buf;
}

std::string seconds_text(double s) { return fixed(s, kTimeDecimals); }
std::string length_text(const kin::Chain& chain, double user) { return fixed(user, units_of(chain).length_decimals()); }
std::string angle_text(const kin::Chain& chain, double user) { return fixed(user, units_of(chain).angle_decimals()); }

bool all_finite(const double* v, int n) {
  for (int i = 0; i < n; ++i)
    if (!std::isfinite(v[i])) return false;
  return true;
}

kin::LoadResult load_robot_checked(const std::string& name_or_path) {
  bool builtin = false;
  for (const auto& m : kin::builtin_models()) builtin = builtin || name_or_path == m.name;
  struct stat st {};
  if (!builtin && ::stat(name_or_path.c_str(), &st) == 0) {
    kin::LoadResult r;
    if (!S_ISREG(st.st_mode)) {
      r.error = name_or_path + ": not a regular file (" +
                (S_ISDIR(st.st_mode) ? "a directory" : S_ISFIFO(st.st_mode) ? "a FIFO" : S_ISCHR(st.st_mode) ? "a device" : "not a file") +
                "): --robot takes a built-in model name or a .toml description file";
      return r;
    }
  }
  return kin::load_robot(name_or_path);
}

std::string check_position(const char* option, const std::vector<double>& values, const kin::Chain& chain) {
  for (double x : values)
    if (!(std::abs(x * chain.length_unit) <= kMaxPositionM))
      return std::string(option) + ": " + num(x) + " " + length_unit_name(chain) + " is not a plausible position (at most " +
             num(kMaxPositionM / chain.length_unit) + " " + length_unit_name(chain) + ")";
  return "";
}

std::string check_angles(const char* option, const std::vector<double>& values, const kin::Chain& chain) {
  const double max_rad = kMaxOrientationDeg * M_PI / 180;
  for (double r : values)
    if (!(std::abs(r * chain.angle_unit) <= max_rad))
      return std::string(option) + ": " + num(r) + " " + angle_unit_name(chain) + " is not a plausible angle (at most " +
             num(max_rad / chain.angle_unit) + " " + angle_unit_name(chain) + ")";
  return "";
}

std::string json_array(const double* v, int n) {
  std::string s = "[";
  for (int i = 0; i < n; ++i) s += (i ? ", " : "") + num(v[i]);
  return s + "]";
}

bool joints_from_user(const kin::Chain& chain, const std::vector<double>& values, kin::JointVector& q,
                      std::string& error) {
  if (static_cast<int>(values.size()) != chain.n_joints) {
    error = std::string(chain.name.data()) + " has " + std::to_string(chain.n_joints) + " joints, got " +
            std::to_string(values.size()) + " joint values";
    return false;
  }
  q.resize(chain.n_joints);
  for (int j = 0; j < chain.n_joints; ++j) q[j] = values[static_cast<std::size_t>(j)] / chain.joint_user_scale(j);
  return true;
}

std::vector<double> joints_to_user(const kin::Chain& chain, const kin::JointVector& q) {
  std::vector<double> v(static_cast<std::size_t>(q.size()));
  for (int j = 0; j < q.size(); ++j) v[static_cast<std::size_t>(j)] = q[j] * chain.joint_user_scale(j);
  return v;
}

const char* length_unit_name(const kin::Chain& c) { return c.length_unit == 1.0 ? "m" : "mm"; }
const char* angle_unit_name(const kin::Chain& c) { return c.angle_unit == 1.0 ? "rad" : "deg"; }
const char* joint_unit_name(const kin::Chain& c, int j) {
  return c.joint(j).type == kin::JointType::prismatic ? length_unit_name(c) : angle_unit_name(c);
}

int limit_violations(const kin::Chain& chain, const kin::JointVector& q, std::string& report) {
  int n = 0;
  for (int j = 0; j < chain.n_joints; ++j) {
    const kin::DhRow& r = chain.joint(j);
    if (q[j] >= r.lower - 1e-12 && q[j] <= r.upper + 1e-12) continue;
    const double s = chain.joint_user_scale(j);
    report += "joint " + std::to_string(j + 1) + ": value " + num(q[j] * s) + " is outside [" + num(r.lower * s) +
              ", " + num(r.upper * s) + "] " + joint_unit_name(chain, j) + "\n";
    ++n;
  }
  return n;
}

}  // namespace servoarm::fw
