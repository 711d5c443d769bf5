#include "servoarm/armctl/cli_common.hpp"

#include <cerrno>
#include <cmath>
#include <cstdlib>

namespace servoarm::fw {

bool parse_number(const char* s, double& out) {
  if (!s || !*s) return false;
  errno = 0;
  char* end = nullptr;
  const double v = std::strtod(s, &end);
  if (end == s || *end != '\0' || errno == ERANGE || !std::isfinite(v)) return false;
  out = v;
  return true;
}

int usage_error(const std::string& message) {
  std::fprintf(stderr, "armctl: %s\n", message.c_str());
  return kExitUsage;
}

std::string num(double v) {
  if (std::abs(v) < 5e-13) v = 0;  // round-off dust and "-0" print as 0
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.10g", v);
  return buf;
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
