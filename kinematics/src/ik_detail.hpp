#pragma once
// Internal helpers shared by the IK sources (not installed).
#include <cmath>

#include "servoarm/kinematics/ik.hpp"

namespace servoarm::kin::detail {

/// True if every coefficient is finite. Unlike Eigen's allFinite() (x - x
/// == 0) it raises no floating-point exception on Inf.
template <typename D>
inline bool all_finite(const Eigen::DenseBase<D>& m) {
  for (Eigen::Index c = 0; c < m.cols(); ++c)
    for (Eigen::Index r = 0; r < m.rows(); ++r)
      if (!std::isfinite(m(r, c))) return false;
  return true;
}

/// Motion of joint j by m: Rz(m) (revolute) or Tz(m) (prismatic).
inline Pose joint_motion(bool prismatic, double m) {
  Pose T = Pose::Identity();
  if (prismatic) {
    T.translation().z() = m;
  } else {
    const double c = std::cos(m), s = std::sin(m);
    T.linear() << c, -s, 0, s, c, 0, 0, 0, 1;
  }
  return T;
}

inline Eigen::Matrix3d rot_z(double m) {
  const double c = std::cos(m), s = std::sin(m);
  Eigen::Matrix3d R;
  R << c, -s, 0, s, c, 0, 0, 0, 1;
  return R;
}

/// Position and rotation error of q against target; false on FK failure.
bool pose_error(const Chain& chain, const JointVector& q, const Pose& target, double& ep, double& er);

/// A few Gauss-Newton/DLS steps on the full pose (position-only if asked):
/// polishes a closed-form solution that lost digits near a singularity.
void refine(const Chain& chain, const Pose& target, JointVector& q, int iterations, bool position_only);


}  // namespace servoarm::kin::detail
