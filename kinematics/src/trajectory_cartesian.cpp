// SPDX-License-Identifier: Apache-2.0
// Cartesian straight-line moves: path check, singularity slowdown, sampling.
// See trajectory_cartesian.hpp for the model.
#include "servoarm/kinematics/trajectory_cartesian.hpp"

#include <algorithm>
#include <cmath>

#include "servoarm/kinematics/orientation.hpp"

namespace servoarm::kin {

namespace {

constexpr double kStep = 1.0 / kMovelKnots;

bool positive_finite(double x) { return std::isfinite(x) && x > 0; }

// The path parameter as a one-joint system with position limits [0, 1].
JointLimits s_axis(const Limits1& l) {
  JointLimits sl;
  sl.n = 1;
  sl.dyn[0] = JointDynamics{l.v, l.a, l.j};
  sl.lower[0] = 0.0;
  sl.upper[0] = 1.0;
  return sl;
}

// Hermite interpolation of the knot table at s: q, dq/ds, d2q/ds2 of joint i.
void hermite(const CartesianTrajectory& tr, double s, int i, double& q, double& dq, double& ddq) {
  s = std::clamp(s, 0.0, 1.0);
  int k = static_cast<int>(s * kMovelKnots);
  k = std::clamp(k, 0, kMovelKnots - 1);
  const double u = (s - k * kStep) * kMovelKnots;
  const auto a = static_cast<std::size_t>(k), b = a + 1, j = static_cast<std::size_t>(i);
  const double q0 = tr.q_knot[a][j], q1 = tr.q_knot[b][j];
  const double m0 = tr.dq_knot[a][j] * kStep, m1 = tr.dq_knot[b][j] * kStep;
  const double u2 = u * u, u3 = u2 * u;
  q = (2 * u3 - 3 * u2 + 1) * q0 + (u3 - 2 * u2 + u) * m0 + (-2 * u3 + 3 * u2) * q1 + (u3 - u2) * m1;
  dq = ((6 * u2 - 6 * u) * q0 + (3 * u2 - 4 * u + 1) * m0 + (-6 * u2 + 6 * u) * q1 + (3 * u2 - 2 * u) * m1) *
       kMovelKnots;
  ddq = ((12 * u - 6) * q0 + (6 * u - 4) * m0 + (-12 * u + 6) * q1 + (6 * u - 2) * m1) *
        (static_cast<double>(kMovelKnots) * kMovelKnots);
}

void fill_report(PathReport* r, MotionStatus st, double s, const Eigen::Vector3d& p, int joint) {
  if (!r) return;
  r->status = st;
  r->s = s;
  r->position = p;
  r->joint = joint;
}

}  // namespace

Pose CartesianTrajectory::pose_at(double s) const {
  s = std::clamp(s, 0.0, 1.0);
  Pose x = Pose::Identity();
  x.linear() = r0.slerp(s, r1).toRotationMatrix();
  x.translation() = p0 + s * (p1 - p0);
  return x;
}

void CartesianTrajectory::path_state(double t, double& s, double& sd, double& sdd) const {
  if (t >= timing.duration) {
    s = timing.goal[0];
    sd = sdd = 0;
  } else {
    eval_profile(timing.joint[0], t, s, sd, sdd);
  }
  s = std::clamp(s, 0.0, 1.0);
}

void CartesianTrajectory::sample_precomputed(double t, JointVector& q, JointVector& qd, JointVector& qdd) const {
  double s, sd, sdd;
  path_state(t, s, sd, sdd);
  q.resize(n);
  qd.resize(n);
  qdd.resize(n);
  for (int i = 0; i < n; ++i) {
    double p, dp, ddp;
    hermite(*this, s, i, p, dp, ddp);
    q[i] = p;
    qd[i] = dp * sd;
    qdd[i] = ddp * sd * sd + dp * sdd;
  }
}

Status CartesianTrajectory::sample_ik(double t, JointVector& q, JointVector& qd, JointVector& qdd) const {
  sample_precomputed(t, q, qd, qdd);
  if (!chain || !ik.fn) return Status::bad_input;
  double s, sd, sdd;
  path_state(t, s, sd, sdd);
  JointVector seed = q, sol(n);
  const Status st = ik.fn(*chain, pose_at(s), seed, sol, ik.ctx);
  if (is_ok(st)) q = sol;
  return st;
}

MotionStatus plan_movel(const Chain& chain, const JointVector& q_start, const Pose& target,
                        const CartesianLimits& limits, const MovelOptions& options, IkSolver ik,
                        CartesianTrajectory& out, PathReport* report) {
  if (report) *report = PathReport{};
  const int n = chain.n_joints;
  if (n < 1 || n > kMaxJoints || q_start.size() != n) return MotionStatus::wrong_size;
  if (!q_start.allFinite() || !target.matrix().allFinite() || !is_rotation(target.linear()) || !ik.fn)
    return MotionStatus::bad_input;
  if (!(options.override >= 0.01 && options.override <= 1.0) || !(options.max_slowdown >= 1) ||
      !(options.max_condition > 1) || !positive_finite(options.max_joint_step) ||
      !(options.joint_margin > 0 && options.joint_margin <= 1))
    return MotionStatus::bad_input;
  if (!positive_finite(limits.linear_velocity) || !positive_finite(limits.linear_acceleration) ||
      !positive_finite(limits.linear_jerk) || !positive_finite(limits.angular_velocity) ||
      !positive_finite(limits.angular_acceleration) || !positive_finite(limits.angular_jerk))
    return MotionStatus::bad_limits;
  const JointLimits jl = limits_from(chain);
  for (int i = 0; i < n; ++i) {
    const JointDynamics& d = jl.dyn[static_cast<std::size_t>(i)];
    if (!positive_finite(d.max_velocity) || !positive_finite(d.max_acceleration) || !positive_finite(d.max_jerk))
      return MotionStatus::bad_limits;
  }
  Pose start;
  if (forward(chain, q_start, start) != Status::ok) return MotionStatus::bad_input;

  CartesianTrajectory tr;
  tr.chain = &chain;
  tr.ik = ik;
  tr.n = n;
  tr.limits = jl;
  tr.p0 = start.translation();
  tr.p1 = target.translation();
  tr.r0 = Eigen::Quaterniond(start.linear()).normalized();
  tr.r1 = Eigen::Quaterniond(target.linear()).normalized();
  if (tr.r0.dot(tr.r1) < 0) tr.r1.coeffs() = -tr.r1.coeffs();  // shortest rotation
  tr.length = (tr.p1 - tr.p0).norm();
  tr.angle = tr.r0.angularDistance(tr.r1);

  // Path-parameter limits from the Cartesian limits.
  Limits1 sl{1e300, 1e300, 1e300};
  const bool moves = tr.length > 1e-12 || tr.angle > 1e-12;
  if (tr.length > 1e-12) {
    sl.v = std::min(sl.v, limits.linear_velocity / tr.length);
    sl.a = std::min(sl.a, limits.linear_acceleration / tr.length);
    sl.j = std::min(sl.j, limits.linear_jerk / tr.length);
  }
  if (tr.angle > 1e-12) {
    sl.v = std::min(sl.v, limits.angular_velocity / tr.angle);
    sl.a = std::min(sl.a, limits.angular_acceleration / tr.angle);
    sl.j = std::min(sl.j, limits.angular_jerk / tr.angle);
  }
  if (!moves) sl = Limits1{1, 1, 1};

  // Knots: IK nearest to the previous solution, limits, jumps, conditioning.
  JointVector prev = q_start, q(n);
  Jacobian J(6, n);
  double worst_cond = 0;
  for (int k = 0; k <= kMovelKnots; ++k) {
    const double s = k * kStep;
    const Pose x = tr.pose_at(s);
    if (k == 0) {
      q = q_start;
    } else if (!moves) {
      q = q_start;
    } else {
      const Status st = ik.fn(chain, x, prev, q, ik.ctx);
      Pose check;
      if (!is_ok(st) || q.size() != n || !q.allFinite() || forward(chain, q, check) != Status::ok ||
          (check.translation() - x.translation()).norm() > 1e-6 ||
          rotation_error(check.linear(), x.linear()).norm() > 1e-6) {
        fill_report(report, MotionStatus::no_ik_solution, s, x.translation(), -1);
        return MotionStatus::no_ik_solution;
      }
    }
    for (int i = 0; i < n; ++i) {
      const auto j = static_cast<std::size_t>(i);
      if (k > 0 && (q[i] < jl.lower[j] - 1e-9 || q[i] > jl.upper[j] + 1e-9)) {
        fill_report(report, MotionStatus::path_out_of_limits, s, x.translation(), i);
        return MotionStatus::path_out_of_limits;
      }
    }
    if (moves) {
      jacobian(chain, q, J);
      const double c = condition_number(J);
      worst_cond = std::max(worst_cond, std::isfinite(c) ? c : 1e300);
      if (!(c <= options.max_condition)) {
        fill_report(report, MotionStatus::singularity, s, x.translation(), -1);
        if (report) report->max_condition = worst_cond;
        return MotionStatus::singularity;
      }
    }
    if (k > 0) {
      for (int i = 0; i < n; ++i) {
        if (std::fabs(q[i] - prev[i]) > options.max_joint_step) {
          // A jump: either the line passes close to a singularity (joint rates
          // explode between the knots) or the solution switched branch. Look at
          // the conditioning at both knots and halfway.
          double c = condition_number(J);
          jacobian(chain, prev, J);
          c = std::max(c, condition_number(J));
          JointVector qm(n);
          if (is_ok(ik.fn(chain, tr.pose_at(s - 0.5 * kStep), prev, qm, ik.ctx)) && qm.allFinite()) {
            jacobian(chain, qm, J);
            c = std::max(c, condition_number(J));
          }
          const bool singular = !(c <= std::sqrt(options.max_condition));
          const MotionStatus why = singular ? MotionStatus::singularity : MotionStatus::branch_change;
          fill_report(report, why, s, x.translation(), i);
          if (report) report->max_condition = std::max(worst_cond, std::isfinite(c) ? c : 1e300);
          return why;
        }
      }
    }
    for (int i = 0; i < n; ++i) tr.q_knot[static_cast<std::size_t>(k)][static_cast<std::size_t>(i)] = q[i];
    prev = q;
  }
  if (report) report->max_condition = worst_cond;

  // dq/ds (second-order differences) and the slowdown the joint limits need.
  double slow = 1.0;
  int slow_joint = -1, slow_knot = 0;
  for (int k = 0; k <= kMovelKnots; ++k) {
    const auto a = static_cast<std::size_t>(k);
    for (int i = 0; i < n; ++i) {
      const auto j = static_cast<std::size_t>(i);
      double d1, d2;
      const auto& Q = tr.q_knot;
      if (k == 0) {
        d1 = (-3 * Q[0][j] + 4 * Q[1][j] - Q[2][j]) / (2 * kStep);
        d2 = (Q[0][j] - 2 * Q[1][j] + Q[2][j]) / (kStep * kStep);
      } else if (k == kMovelKnots) {
        d1 = (3 * Q[a][j] - 4 * Q[a - 1][j] + Q[a - 2][j]) / (2 * kStep);
        d2 = (Q[a][j] - 2 * Q[a - 1][j] + Q[a - 2][j]) / (kStep * kStep);
      } else {
        d1 = (Q[a + 1][j] - Q[a - 1][j]) / (2 * kStep);
        d2 = (Q[a + 1][j] - 2 * Q[a][j] + Q[a - 1][j]) / (kStep * kStep);
      }
      tr.dq_knot[a][j] = d1;
      // Chord speed between knots too: catches a peak between two knots.
      double chord = 0;
      if (k > 0) chord = std::fabs(Q[a][j] - Q[a - 1][j]) / kStep;
      const JointDynamics& dyn = jl.dyn[j];
      const double m = options.joint_margin;
      const double kv = std::max(std::fabs(d1), chord) * sl.v / (m * dyn.max_velocity);
      const double ka = std::sqrt((std::fabs(d2) * sl.v * sl.v + std::fabs(d1) * sl.a) / (m * dyn.max_acceleration));
      const double kk = std::max(kv, ka);
      if (kk > slow) {
        slow = kk;
        slow_joint = i;
        slow_knot = k;
      }
    }
  }
  MotionStatus result = MotionStatus::ok;
  if (slow > 1.0 && moves) {
    const double s = slow_knot * kStep;
    const Eigen::Vector3d where = tr.pose_at(s).translation();
    if (!options.allow_slowdown) {
      fill_report(report, MotionStatus::joint_velocity, s, where, slow_joint);
      if (report) report->slowdown = slow;
      return MotionStatus::joint_velocity;
    }
    if (slow > options.max_slowdown) {
      fill_report(report, MotionStatus::singularity, s, where, slow_joint);
      if (report) report->slowdown = slow;
      return MotionStatus::singularity;
    }
    sl.v /= slow;
    sl.a /= slow * slow;
    sl.j /= slow * slow * slow;
    result = MotionStatus::slowed_near_singularity;
    fill_report(report, result, s, where, slow_joint);
  } else {
    slow = 1.0;
  }
  if (report) report->slowdown = slow;
  tr.slowdown = slow;
  tr.s_limits = sl;
  tr.status = result;
  tr.goal.resize(n);
  for (int i = 0; i < n; ++i) tr.goal[i] = tr.q_knot[kMovelKnots][static_cast<std::size_t>(i)];

  JointVector s0 = JointVector::Zero(1), s1 = JointVector::Constant(1, moves ? 1.0 : 0.0);
  const MotionStatus ts = plan_movej(s_axis(sl), JointState::rest(s0), s1, MovejOptions{options.override}, tr.timing);
  if (ts != MotionStatus::ok) return ts;
  tr.duration = tr.timing.duration;
  out = tr;
  return result;
}

MotionStatus stop_movel(CartesianTrajectory& traj, double t) {
  JointState st;
  traj.timing.sample(t, st);
  JointTrajectory stop;
  const MotionStatus r = plan_stop(s_axis(traj.s_limits), st, MovejOptions{traj.timing.override}, stop);
  if (r != MotionStatus::ok) return r;
  traj.timing = stop;
  traj.duration = stop.duration;
  return MotionStatus::ok;
}

MotionStatus resume_movel(CartesianTrajectory& traj, double t, double override) {
  JointState st;
  traj.timing.sample(t, st);
  JointTrajectory next;
  const MotionStatus r =
      plan_movej(s_axis(traj.s_limits), st, JointVector::Constant(1, 1.0), MovejOptions{override}, next);
  if (r != MotionStatus::ok) return r;
  traj.timing = next;
  traj.duration = next.duration;
  return MotionStatus::ok;
}

}  // namespace servoarm::kin
