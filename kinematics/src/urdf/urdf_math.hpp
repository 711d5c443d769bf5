// SPDX-License-Identifier: Apache-2.0
#pragma once
// Shared by the URDF converter and exporter (internal).
#include <cmath>

#include "servoarm/kinematics/types.hpp"

namespace servoarm::kin::urdf_detail {

/// Rz(yaw) Ry(pitch) Rx(roll) = R as (roll, pitch, yaw), stable at pitch = +-90 deg: yaw
/// first, the rest from Rz(yaw)^T R, whose middle row is [0, cos roll, -sin roll] for any
/// yaw there, so the three angles always rebuild R to rounding.
inline Eigen::Vector3d rpy_of(const Eigen::Matrix3d& R) {
  const double yaw = (std::fabs(R(1, 0)) + std::fabs(R(0, 0)) == 0) ? 0.0 : std::atan2(R(1, 0), R(0, 0));
  const Eigen::Matrix3d Q = Eigen::AngleAxisd(-yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix() * R;
  return {std::atan2(-Q(1, 2), Q(1, 1)), std::atan2(-Q(2, 0), Q(0, 0)), yaw};
}

}  // namespace servoarm::kin::urdf_detail
