#pragma once
// Helpers shared by armctl's subcommands (non-real-time: may allocate).
//
// Exit codes of every armctl command:
//   0  success
//   1  the request was valid but failed (unreachable target, refused move, ...)
//   2  bad usage or bad input (unknown option, malformed number, unknown robot, ...)
#include <cstdio>
#include <string>
#include <vector>

#include "servoarm/kinematics/chain.hpp"

namespace servoarm::fw {

inline constexpr int kExitOk = 0;
inline constexpr int kExitFailed = 1;
inline constexpr int kExitUsage = 2;

/// Parse a whole string as a finite double; false on trailing junk, NaN or Inf.
bool parse_number(const char* s, double& out);

/// One-line error on stderr, prefixed "armctl: ", returns kExitUsage.
int usage_error(const std::string& message);

/// Format a double compactly for people and JSON (no trailing zeros, %.10g-like).
std::string num(double v);
/// JSON array of numbers.
std::string json_array(const double* v, int n);

/// Joint values typed by a user (description units) -> SI; checks the count.
/// On error fills `error` (one line) and returns false.
bool joints_from_user(const kin::Chain& chain, const std::vector<double>& values, kin::JointVector& q,
                      std::string& error);
/// SI -> description units.
std::vector<double> joints_to_user(const kin::Chain& chain, const kin::JointVector& q);

/// Names of the description units, e.g. "mm" / "deg".
const char* length_unit_name(const kin::Chain& chain);
const char* angle_unit_name(const kin::Chain& chain);
/// Unit of joint j ("deg", "rad", "mm" or "m").
const char* joint_unit_name(const kin::Chain& chain, int j);

/// Checks q against the joint limits. Returns the number of joints outside;
/// writes one "joint N: value V is outside [lo, hi] unit" line per joint to `report`.
int limit_violations(const kin::Chain& chain, const kin::JointVector& q, std::string& report);

}  // namespace servoarm::fw
