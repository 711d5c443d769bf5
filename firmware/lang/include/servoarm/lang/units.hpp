// SPDX-License-Identifier: Apache-2.0
#pragma once
// The console's units: one conversion table for every front end. Inside
// everything is SI (m, rad); the command language reads and writes the robot
// description's units (length_unit = "mm" | "m", angle_unit = "deg" | "rad"),
// G-code its own: lengths in G21 mm / G20 inches, A B C in degrees (the
// machine-tool convention, whatever the description says). Joint values:
// the angle unit for revolute joints, the length unit for prismatic ones.
#include <cstdint>
#include <string>

#include "servoarm/kinematics/chain.hpp"

namespace servoarm::fw {

enum class LengthUnit : std::uint8_t { mm, m };
enum class AngleUnit : std::uint8_t { deg, rad };
const char* to_string(LengthUnit u);
const char* to_string(AngleUnit u);

struct ConsoleUnits {
  LengthUnit length = LengthUnit::mm;
  AngleUnit angle = AngleUnit::deg;

  /// User value -> SI (m, rad) and back.
  double length_in(double user) const;
  double length_out(double si) const;
  double angle_in(double user) const;
  double angle_out(double si) const;
  /// Joint j of `chain` (revolute: angle unit, prismatic: length unit).
  double joint_in(const kin::Chain& chain, int j, double user) const;
  double joint_out(const kin::Chain& chain, int j, double si) const;
  const char* joint_name(const kin::Chain& chain, int j) const;
  const char* length_name() const { return to_string(length); }
  const char* angle_name() const { return to_string(angle); }
  /// Decimals that print a position (0.001 mm, 1e-6 m) and an angle (0.001 deg, 1e-6 rad):
  /// each unit's resolution in every answer (fixed(), text.hpp).
  int length_decimals() const { return length == LengthUnit::mm ? 3 : 6; }
  int angle_decimals() const { return angle == AngleUnit::deg ? 3 : 6; }
  int joint_decimals(const kin::Chain& chain, int j) const;
  /// A length (m), an angle (rad), joint j's value (SI) in these units at their resolution.
  std::string length_text(double si) const;
  std::string angle_text(double si) const;
  std::string joint_text(const kin::Chain& chain, int j, double si) const;
  /// The rx ry rz (rad) of R as every answer prints them: fixed-axis roll-pitch-yaw
  /// (kin::rpy_from_rotation). Within kGimbalLockBand of the gimbal lock (pitch +-90 deg,
  /// where rx and rz are not unique and swing by tens of degrees for a hundredth of a degree
  /// of the arm) ry is +-90 exactly, rx 0 and rz the whole turn about z: the orientation
  /// with ry = +-90 closest to R, within the band of it. One conversion for status, fk,
  /// wait's answer, M114, points, tools and frames: one pose prints one way, from the
  /// measured joints (a following error off the goal) or from a move's goal alike.
  Eigen::Vector3d rpy_of(const Eigen::Matrix3d& R) const;
  /// "x=.. y=.. z=.. rx=.. ry=.. rz=..": a pose in these units at their resolution.
  std::string pose_text(const kin::Pose& p) const;
  /// The `help` line naming them.
  const char* help_line() const;
};

/// armfw.toml's lengths and angles are in mm and degrees (the keys say so: _mm, _deg; a joint's
/// value in mm when it is prismatic, in degrees when revolute), whatever units the robot
/// description uses: they reach SI through the units table.
inline constexpr ConsoleUnits kConfigUnits{LengthUnit::mm, AngleUnit::deg};

/// The gimbal-lock band of ConsoleUnits::rpy_of: |pitch -+ 90 deg| below 1e-3 rad (0.057
/// deg), well above a settled arm's following error, prints as the lock.
inline constexpr double kGimbalLockBand = 1e-3;

/// Times print to the millisecond (durations, dwells: "duration=1.322s").
inline constexpr int kTimeDecimals = 3;

/// The units of a loaded robot description (kin::Chain::length_unit / angle_unit: SI per
/// user unit; 1 = m / rad, anything else mm / deg, the only other units descriptions allow).
ConsoleUnits units_of(const kin::Chain& chain);

/// What G-code's X Y Z A B C and F are in once parse_line has read them (it converts
/// G20 inches to mm): mm and degrees.
inline constexpr ConsoleUnits kGcodeUnits{LengthUnit::mm, AngleUnit::deg};

}  // namespace servoarm::fw
