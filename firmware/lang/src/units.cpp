// SPDX-License-Identifier: Apache-2.0
#include "servoarm/lang/units.hpp"

#include <cmath>

#include "servoarm/lang/text.hpp"
#include "servoarm/kinematics/orientation.hpp"

namespace servoarm::fw {

namespace {
constexpr double kDeg = M_PI / 180.0;
}

const char* to_string(LengthUnit u) {
  switch (u) {
    case LengthUnit::mm: return "mm";
    case LengthUnit::m: return "m";
  }
  return "?";
}

const char* to_string(AngleUnit u) {
  switch (u) {
    case AngleUnit::deg: return "deg";
    case AngleUnit::rad: return "rad";
  }
  return "?";
}

// Written as the console always computed them (x * 1e-3, x * 1e3, x * kDeg, x / kDeg),
// so mm / deg answers are bit for bit what they were.
double ConsoleUnits::length_in(double user) const { return length == LengthUnit::mm ? user * 1e-3 : user; }
double ConsoleUnits::length_out(double si) const { return length == LengthUnit::mm ? si * 1e3 : si; }
double ConsoleUnits::angle_in(double user) const { return angle == AngleUnit::deg ? user * kDeg : user; }
double ConsoleUnits::angle_out(double si) const { return angle == AngleUnit::deg ? si / kDeg : si; }

double ConsoleUnits::joint_in(const kin::Chain& chain, int j, double user) const {
  return chain.joint(j).type == kin::JointType::prismatic ? length_in(user) : angle_in(user);
}
double ConsoleUnits::joint_out(const kin::Chain& chain, int j, double si) const {
  return chain.joint(j).type == kin::JointType::prismatic ? length_out(si) : angle_out(si);
}
const char* ConsoleUnits::joint_name(const kin::Chain& chain, int j) const {
  return chain.joint(j).type == kin::JointType::prismatic ? length_name() : angle_name();
}

int ConsoleUnits::joint_decimals(const kin::Chain& chain, int j) const {
  return chain.joint(j).type == kin::JointType::prismatic ? length_decimals() : angle_decimals();
}
std::string ConsoleUnits::length_text(double si) const { return fixed(length_out(si), length_decimals()); }
std::string ConsoleUnits::angle_text(double si) const { return fixed(angle_out(si), angle_decimals()); }
std::string ConsoleUnits::joint_text(const kin::Chain& chain, int j, double si) const {
  return fixed(joint_out(chain, j, si), joint_decimals(chain, j));
}

Eigen::Vector3d ConsoleUnits::rpy_of(const Eigen::Matrix3d& R) const {
  Eigen::Vector3d rpy = kin::rpy_from_rotation(R);
  // cos(pitch) is the pitch's distance to +-90 deg (rad, to first order). Within the band R
  // is Rz(rz - rx) Ry(+-90) (or Rz(rz + rx) Ry(-90)) turned by at most that distance, so the
  // triple printed is within it of the arm's orientation.
  if (std::hypot(R(0, 0), R(1, 0)) < kGimbalLockBand) {
    rpy[1] = std::copysign(M_PI / 2, -R(2, 0));
    rpy[0] = 0.0;
    rpy[2] = std::atan2(-R(0, 1), R(1, 1));  // yaw -+ roll, roll taken as 0
  }
  return rpy;
}

std::string ConsoleUnits::pose_text(const kin::Pose& p) const {
  const Eigen::Vector3d t = p.translation(), r = rpy_of(p.linear());
  return "x=" + length_text(t.x()) + " y=" + length_text(t.y()) + " z=" + length_text(t.z()) + " rx=" + angle_text(r[0]) +
         " ry=" + angle_text(r[1]) + " rz=" + angle_text(r[2]);
}

const char* ConsoleUnits::help_line() const {
  if (length == LengthUnit::mm)
    return angle == AngleUnit::deg ? "units: lengths mm, angles deg (revolute joints deg, prismatic mm), speeds mm/s"
                                   : "units: lengths mm, angles rad (revolute joints rad, prismatic mm), speeds mm/s";
  return angle == AngleUnit::deg ? "units: lengths m, angles deg (revolute joints deg, prismatic m), speeds m/s"
                                 : "units: lengths m, angles rad (revolute joints rad, prismatic m), speeds m/s";
}

ConsoleUnits units_of(const kin::Chain& chain) {
  ConsoleUnits u;
  u.length = chain.length_unit == 1.0 ? LengthUnit::m : LengthUnit::mm;
  u.angle = chain.angle_unit == 1.0 ? AngleUnit::rad : AngleUnit::deg;
  return u;
}

}  // namespace servoarm::fw
