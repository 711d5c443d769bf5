#pragma once
// Test IK "nearest to q_near": Newton iterations on the full pose error from
// the seed (heap-free, fixed 6x6 solve). Converges to the solution on the seed's
// branch when the seed is close, which is how movel calls it. Used by the
// motion suites so they test movel independently of kinematics/ik.
#include <Eigen/LU>
#include <cmath>

#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/orientation.hpp"

namespace servoarm::test {

inline kin::Status newton_ik(const kin::Chain& chain, const kin::Pose& target, const kin::JointVector& q_near,
                             kin::JointVector& q_out, void* /*ctx*/) {
  if (chain.n_joints != 6) return kin::Status::unsupported;
  kin::JointVector q = q_near;
  kin::Jacobian J(6, 6);
  kin::Pose x;
  for (int it = 0; it < 40; ++it) {
    kin::jacobian(chain, q, J, &x);
    Eigen::Matrix<double, 6, 1> e;
    e.head<3>() = target.translation() - x.translation();
    e.tail<3>() = kin::rotation_error(x.linear(), target.linear());
    if (e.norm() < 1e-13) break;
    const Eigen::Matrix<double, 6, 6> Jf = J;
    Eigen::Matrix<double, 6, 1> dq = Jf.partialPivLu().solve(e);
    if (!dq.allFinite()) return kin::Status::singular;
    const double nrm = dq.norm();
    if (nrm > 0.3) dq *= 0.3 / nrm;
    q += dq;
  }
  kin::forward(chain, q, x);
  const double err = (target.translation() - x.translation()).norm() +
                     kin::rotation_error(x.linear(), target.linear()).norm();
  if (!(err < 1e-10)) return kin::Status::unreachable;
  q_out = q;
  return kin::Status::ok;
}

}  // namespace servoarm::test
