// Damped Newton "IK nearest to a seed" (see motion_ik.hpp).
//   e = [p_target - p(q); log(R_target R(q)^T)]      (6-D pose error, base frame)
//   dq = J^T (J J^T + lambda^2 I)^-1 e                (damped least squares)
// The damping is tiny (1e-9) so that near the solution it is plain Newton
// (quadratic convergence); steps are capped at 0.3 rad so a far seed cannot
// jump to another branch in one step.
#include "servoarm/kinematics/motion_ik.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>

#include "servoarm/kinematics/ik.hpp"
#include "servoarm/kinematics/orientation.hpp"

namespace servoarm::kin {

Status ik_nearest_for_motion(const Chain& /*chain*/, const Pose& target, const JointVector& q_near, JointVector& q_out,
                             void* ctx) {
  if (!ctx) return Status::bad_input;
  const IkModel& model = *static_cast<const IkModel*>(ctx);
  IkChoice choice;
  choice.allow_out_of_limits = true;
  return ik_solve_nearest(model, target, q_near, q_out, choice);
}

Status ik_nearest_newton(const Chain& chain, const Pose& target, const JointVector& q_near, JointVector& q_out,
                         void* /*ctx*/) {
  const int n = chain.n_joints;
  if (q_near.size() != n) return Status::wrong_size;
  if (!q_near.allFinite() || !target.matrix().allFinite()) return Status::bad_input;
  JointVector q = q_near;
  Jacobian J(6, n);
  Pose x;
  double err = 1e300;
  for (int it = 0; it < 40; ++it) {
    if (jacobian(chain, q, J, &x) != Status::ok) return Status::bad_input;
    Eigen::Matrix<double, 6, 1> e;
    e.head<3>() = target.translation() - x.translation();
    e.tail<3>() = rotation_error(x.linear(), target.linear());
    err = e.norm();
    if (err < 1e-13) break;
    Eigen::Matrix<double, 6, 6> JJt = J * J.transpose();
    JJt.diagonal().array() += 1e-18;
    const Eigen::Matrix<double, 6, 1> y = JJt.ldlt().solve(e);
    // dq = J^T y, written as a loop (GCC 12 -O3 warns falsely on the Eigen expression).
    double dq[kMaxJoints];
    double m = 0;
    for (int j = 0; j < n; ++j) {
      dq[j] = J.col(j).dot(y);
      if (!std::isfinite(dq[j])) return Status::unreachable;
      m = std::max(m, std::fabs(dq[j]));
    }
    const double scale = m > 0.3 ? 0.3 / m : 1.0;
    for (int j = 0; j < n; ++j) q[j] += scale * dq[j];
  }
  forward(chain, q, x);
  err = (target.translation() - x.translation()).norm() + rotation_error(x.linear(), target.linear()).norm();
  if (!(err < 1e-10)) return Status::unreachable;
  q_out = q;
  return Status::ok;
}

}  // namespace servoarm::kin
