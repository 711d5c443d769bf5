// SPDX-License-Identifier: Apache-2.0
#include "servoarm/kinematics/orientation.hpp"

#include <cmath>

namespace servoarm::kin {

double wrap_pi(double a) {
  if (!std::isfinite(a)) return a;
  a = std::remainder(a, 2.0 * M_PI);  // [-pi, pi]
  if (a <= -M_PI) a += 2.0 * M_PI;
  return a;
}

Eigen::Matrix3d rotation_from_zyz(const EulerZyz& e) {
  const double ca = std::cos(e.alpha), sa = std::sin(e.alpha);
  const double cb = std::cos(e.beta), sb = std::sin(e.beta);
  const double cg = std::cos(e.gamma), sg = std::sin(e.gamma);
  Eigen::Matrix3d R;
  // Custódio et al. (IST 2019), eq. (4)
  R << ca * cb * cg - sa * sg, -ca * cb * sg - sa * cg, ca * sb,
       sa * cb * cg + ca * sg, -sa * cb * sg + ca * cg, sa * sb,
       -sb * cg, sb * sg, cb;
  return R;
}

ZyzSolutions zyz_from_rotation(const Eigen::Matrix3d& R, double alpha_if_singular, double tol) {
  ZyzSolutions out;
  const double r13 = R(0, 2), r23 = R(1, 2), r33 = R(2, 2);
  const double r31 = R(2, 0), r32 = R(2, 1);
  const double sb = std::sqrt(r13 * r13 + r23 * r23);
  if (sb > tol) {
    // Custódio et al. (IST 2019), §2: s_beta > 0 and s_beta < 0 branches
    EulerZyz p{std::atan2(r23, r13), std::atan2(sb, r33), std::atan2(r32, -r31)};
    EulerZyz n{std::atan2(-r23, -r13), std::atan2(-sb, r33), std::atan2(-r32, r31)};
    out.branch[0] = p;
    out.branch[1] = n;
    out.count = 2;
    out.singular = false;
    return out;
  }
  // s_beta = 0: only alpha +- gamma is defined. Keep alpha, solve gamma.
  EulerZyz e;
  e.alpha = alpha_if_singular;
  if (r33 > 0) {
    // c_beta = 1: R = Rz(alpha + gamma); alpha + gamma = atan2(r21, r11)
    e.beta = 0.0;
    e.gamma = wrap_pi(std::atan2(R(1, 0), R(0, 0)) - e.alpha);
  } else {
    // c_beta = -1: alpha - gamma = atan2(-r21, -r11)
    e.beta = M_PI;
    e.gamma = wrap_pi(e.alpha - std::atan2(-R(1, 0), -R(0, 0)));
  }
  out.branch[0] = e;
  out.branch[1] = e;
  out.count = 1;
  out.singular = true;
  return out;
}

Eigen::Matrix3d rotation_from_rpy(double roll, double pitch, double yaw) {
  const double cr = std::cos(roll), sr = std::sin(roll);
  const double cp = std::cos(pitch), sp = std::sin(pitch);
  const double cy = std::cos(yaw), sy = std::sin(yaw);
  Eigen::Matrix3d R;
  R << cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr,
       sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr,
       -sp, cp * sr, cp * cr;
  return R;
}

Eigen::Vector3d rpy_from_rotation(const Eigen::Matrix3d& R) {
  const double cp = std::hypot(R(0, 0), R(1, 0));
  const double pitch = std::atan2(-R(2, 0), cp);
  double roll, yaw;
  if (cp > 1e-12) {
    roll = std::atan2(R(2, 1), R(2, 2));
    yaw = std::atan2(R(1, 0), R(0, 0));
  } else {
    // gimbal lock: only yaw -+ roll is defined; take roll = 0.
    roll = 0.0;
    yaw = std::atan2(-R(0, 1), R(1, 1));
  }
  return {roll, pitch, yaw};
}

Eigen::Quaterniond quaternion_from_rotation(const Eigen::Matrix3d& R) {
  Eigen::Quaterniond q(R);
  q.normalize();
  if (q.w() < 0) q.coeffs() = -q.coeffs();  // canonical: w >= 0
  return q;
}

Status rotation_from_quaternion(double w, double x, double y, double z, Eigen::Matrix3d& R) {
  const double n = std::sqrt(w * w + x * x + y * y + z * z);
  if (!std::isfinite(n) || n < 1e-12) return Status::bad_input;
  R = Eigen::Quaterniond(w / n, x / n, y / n, z / n).toRotationMatrix();
  return Status::ok;
}

AxisAngle axis_angle_from_rotation(const Eigen::Matrix3d& R) {
  Eigen::AngleAxisd aa(R);
  AxisAngle out;
  out.axis = aa.axis();
  out.angle = aa.angle();
  if (out.angle < 1e-15) {
    out.axis = Eigen::Vector3d::UnitZ();
    out.angle = 0;
  }
  return out;
}

Status rotation_from_axis_angle(const Eigen::Vector3d& axis, double angle, Eigen::Matrix3d& R) {
  const double n = axis.norm();
  if (!std::isfinite(n) || !std::isfinite(angle) || n < 1e-12) return Status::bad_input;
  R = Eigen::AngleAxisd(angle, axis / n).toRotationMatrix();
  return Status::ok;
}

bool is_rotation(const Eigen::Matrix3d& R, double tol) {
  if (!R.allFinite()) return false;
  if ((R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > tol) return false;
  return std::abs(R.determinant() - 1.0) <= tol;
}

Eigen::Vector3d rotation_error(const Eigen::Matrix3d& R_current, const Eigen::Matrix3d& R_target) {
  const Eigen::Matrix3d Re = R_target * R_current.transpose();
  // log map, robust near 0 and pi
  const double c = std::clamp((Re.trace() - 1.0) * 0.5, -1.0, 1.0);
  const double angle = std::acos(c);
  const Eigen::Vector3d v(Re(2, 1) - Re(1, 2), Re(0, 2) - Re(2, 0), Re(1, 0) - Re(0, 1));
  if (angle < 1e-6) return 0.5 * v;  // sin(angle) ~ angle
  if (M_PI - angle > 1e-6) return v * (angle / (2.0 * std::sin(angle)));
  // near pi: axis from the diagonal of (Re + I)/2 = a a^T
  Eigen::Matrix3d B = 0.5 * (Re + Eigen::Matrix3d::Identity());
  int k = 0;
  B.diagonal().maxCoeff(&k);
  Eigen::Vector3d axis = B.col(k) / std::sqrt(std::max(B(k, k), 1e-300));
  if (axis.dot(v) < 0) axis = -axis;
  return axis.normalized() * angle;
}

}  // namespace servoarm::kin
