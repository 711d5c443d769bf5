// SPDX-License-Identifier: Apache-2.0
#pragma once
// Orientation conversions. Heap-free, no exceptions.
//
//   ZYZ Euler (alpha, beta, gamma): R = Rz(alpha) Ry(beta) Rz(gamma)   (Custódio et al. (IST 2019), eq. 4)
//   RPY (roll, pitch, yaw), ZYX:    R = Rz(yaw) Ry(pitch) Rx(roll)
//   quaternion (w, x, y, z), unit
//   axis-angle (unit axis, angle in [0, pi])
#include "servoarm/kinematics/status.hpp"
#include "servoarm/kinematics/types.hpp"

namespace servoarm::kin {

struct EulerZyz {
  double alpha = 0, beta = 0, gamma = 0;
};

/// Both ZYZ branches of a rotation (Custódio et al. (IST 2019), §2).
/// Regular case: count = 2, branch[0] has sin(beta) > 0, branch[1] sin(beta) < 0.
/// sin(beta) = 0 (|sin beta| < tol): count = 1, singular = true; only alpha+gamma
/// (cos beta = 1) or alpha-gamma (cos beta = -1) is defined, and alpha is set
/// to `alpha_if_singular` (e.g. the current value) with gamma solved from it.
struct ZyzSolutions {
  EulerZyz branch[2];
  int count = 0;
  bool singular = false;
};

Eigen::Matrix3d rotation_from_zyz(const EulerZyz& e);
ZyzSolutions zyz_from_rotation(const Eigen::Matrix3d& R, double alpha_if_singular = 0.0,
                               double tol = 1e-12);

/// RPY: returns (roll, pitch, yaw). At pitch = +-90 deg (gimbal lock) roll is 0.
Eigen::Matrix3d rotation_from_rpy(double roll, double pitch, double yaw);
Eigen::Vector3d rpy_from_rotation(const Eigen::Matrix3d& R);

/// Quaternion <-> rotation. rotation_from_quaternion normalises; a zero or
/// non-finite quaternion gives bad_input and leaves R untouched.
Eigen::Quaterniond quaternion_from_rotation(const Eigen::Matrix3d& R);
Status rotation_from_quaternion(double w, double x, double y, double z, Eigen::Matrix3d& R);

struct AxisAngle {
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();
  double angle = 0;
};
AxisAngle axis_angle_from_rotation(const Eigen::Matrix3d& R);
/// A zero or non-finite axis gives bad_input.
Status rotation_from_axis_angle(const Eigen::Vector3d& axis, double angle, Eigen::Matrix3d& R);

/// True if R is finite, orthonormal (|R^T R - I| < tol) and det(R) = +1.
bool is_rotation(const Eigen::Matrix3d& R, double tol = 1e-6);

/// Orientation error between two rotations as a rotation vector (axis*angle),
/// expressed in the base frame: log(R_target * R_current^T).
Eigen::Vector3d rotation_error(const Eigen::Matrix3d& R_current, const Eigen::Matrix3d& R_target);

/// Wrap an angle into (-pi, pi].
double wrap_pi(double a);

}  // namespace servoarm::kin
