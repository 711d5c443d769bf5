// SPDX-License-Identifier: Apache-2.0
// The motion IK adapter (see motion_ik.hpp) and the damped Newton "IK
// nearest to a seed", its IkFallback::newton:
//   e = [p_target - p(q); log(R_target R(q)^T)]      (6-D pose error, base frame)
//   dq = J^T (J J^T + lambda^2 I)^-1 e                (damped least squares)
// The damping is tiny (1e-9) so that near the solution it is plain Newton
// (quadratic convergence); steps are capped at 0.3 rad so a far seed cannot
// jump to another branch in one step.
#include "servoarm/kinematics/motion_ik.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>

#include "ik/ik_detail.hpp"
#include "servoarm/kinematics/ik.hpp"
#include "servoarm/kinematics/orientation.hpp"

namespace servoarm::kin {

const char* to_string(IkFallback f) {
  switch (f) {
    case IkFallback::numeric: return "numeric";
    case IkFallback::newton: return "newton";
    case IkFallback::none: return "none";
  }
  return "unknown";
}

namespace {

// The adapter: one function, the options fixed per instantiation (IkSolver
// carries only fn and ctx = the model).
template <bool kOutOfLimits, bool kClosedForm, IkFallback kFallback>
Status motion_ik(const Chain& chain, const Pose& target, const JointVector& q_near, JointVector& q_out, void* ctx) {
  const auto* model = static_cast<const IkModel*>(ctx);
  if (!model) return Status::bad_input;
  const bool closed = kClosedForm && model->method != IkMethod::none;
  if (closed || kFallback == IkFallback::numeric) {
    if (model->chain.n_joints != chain.n_joints) return Status::bad_input;
    if (closed || model->method == IkMethod::none) {
      IkChoice choice;
      choice.allow_out_of_limits = kOutOfLimits;
      return ik_solve_nearest(*model, target, q_near, q_out, choice);  // closed form, else numeric
    }
    if (q_near.size() != model->chain.n_joints) return Status::wrong_size;
    return detail::ik_nearest_numeric(model->chain, target, q_near, q_out);
  }
  if (kFallback == IkFallback::newton) return ik_nearest_newton(chain, target, q_near, q_out, nullptr);
  return Status::unsupported;
}

template <bool kOutOfLimits, bool kClosedForm>
IkNearestFn pick(IkFallback f) {
  switch (f) {
    case IkFallback::numeric: return &motion_ik<kOutOfLimits, kClosedForm, IkFallback::numeric>;
    case IkFallback::newton: return &motion_ik<kOutOfLimits, kClosedForm, IkFallback::newton>;
    case IkFallback::none: return &motion_ik<kOutOfLimits, kClosedForm, IkFallback::none>;
  }
  return &motion_ik<kOutOfLimits, kClosedForm, IkFallback::none>;
}

}  // namespace

IkSolver make_ik_solver(const IkModel& model, const IkSolverOptions& o) {
  IkSolver s;
  s.ctx = const_cast<IkModel*>(&model);  // IkSolver's ctx is void*; the adapter only reads it
  if (o.allow_out_of_limits) s.fn = o.closed_form ? pick<true, true>(o.fallback) : pick<true, false>(o.fallback);
  else s.fn = o.closed_form ? pick<false, true>(o.fallback) : pick<false, false>(o.fallback);
  return s;
}

// Kept for the firmware until it switches to make_ik_solver (motion_ik.hpp).
Status ik_nearest_fn(const Chain& chain, const Pose& target, const JointVector& q_near, JointVector& q_out,
                     void* ctx) {
  return motion_ik<false, true, IkFallback::numeric>(chain, target, q_near, q_out, ctx);
}

Status ik_nearest_for_motion(const Chain& chain, const Pose& target, const JointVector& q_near, JointVector& q_out,
                             void* ctx) {
  return motion_ik<true, true, IkFallback::numeric>(chain, target, q_near, q_out, ctx);
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
