// SPDX-License-Identifier: Apache-2.0
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
#include "servoarm/kinematics/description.hpp"

namespace servoarm::fw {

inline constexpr int kExitOk = 0;
inline constexpr int kExitFailed = 1;
inline constexpr int kExitUsage = 2;

/// Parse a whole string as a finite double; false on trailing junk, NaN or Inf.
bool parse_number(const char* s, double& out);

/// One-line error on stderr, prefixed "armctl: ", returns kExitUsage.
int usage_error(const std::string& message);

/// Format a double compactly for people and JSON (no trailing zeros, %.10g-like).
/// A value that is not finite prints as `null`: armctl's JSON never holds nan or inf
/// (and the commands refuse non-finite results before printing them, see all_finite).
std::string num(double v);
/// What armctl's text (not its JSON, which keeps num()) prints at each unit's resolution,
/// as the console does (fw::fixed, ConsoleUnits): a time in seconds to 1 ms ("1.322"), a
/// length and an angle in the description's units (0.001 mm or 1e-6 m, 0.001 deg or 1e-6 rad).
std::string seconds_text(double s);
std::string length_text(const kin::Chain& chain, double user);
std::string angle_text(const kin::Chain& chain, double user);
/// True when every one of the n values is finite.
bool all_finite(const double* v, int n);
/// JSON array of numbers.
std::string json_array(const double* v, int n);

/// kin::load_robot, but a path that is not a regular file (a directory, a FIFO,
/// /dev/zero) is refused first, naming the path and what it is (the loader itself caps
/// the size: kin::kMaxInputFileBytes, file_input.hpp).
kin::LoadResult load_robot_checked(const std::string& name_or_path);

/// Plausible targets typed by a user (description units): a position coordinate at most
/// kMaxPositionM, an orientation angle (rpy, zyz) at most kMaxOrientationDeg. Each returns
/// "" or one line naming the option and the value, e.g. "--rpy: 1e+300 deg is not a
/// plausible angle (at most 3600 deg)".
inline constexpr double kMaxPositionM = 1000;       // 1 km
inline constexpr double kMaxOrientationDeg = 3600;  // 10 turns
std::string check_position(const char* option, const std::vector<double>& values, const kin::Chain& chain);
std::string check_angles(const char* option, const std::vector<double>& values, const kin::Chain& chain);

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
