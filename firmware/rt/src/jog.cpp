// SPDX-License-Identifier: Apache-2.0
#include "servoarm/rt/jog.hpp"

#include <cmath>

#include <Eigen/Geometry>

namespace servoarm::fw {

const char* to_string(JogEnd e) {
  switch (e) {
    case JogEnd::running: return "running";
    case JogEnd::done: return "done";
    case JogEnd::deadman: return "deadman";
    case JogEnd::limit: return "limit";
    case JogEnd::singular: return "singular";
    case JogEnd::unreachable: return "unreachable";
  }
  return "?";
}

namespace {
constexpr int kAxes = 6;                // x y z rx ry rz
constexpr double kFar = 100.0;          // m / rad: the target of a continuous tool jog along its axis
constexpr double kScaleStep = 0.01;     // per cycle: how fast a tool jog may slow down or speed up again
constexpr double kFloor = 1e-3;         // per-axis limits never below this fraction (the planner needs > 0)
bool finite(const kin::JointVector& v, int n) {
  for (int i = 0; i < n; ++i)
    if (!std::isfinite(v[i])) return false;
  return true;
}
}  // namespace

void Jogger::configure(const kin::Chain& chain, const kin::JointLimits& limits, double period_s) {
  chain_ = &chain;
  limits_ = limits;
  dt_ = period_s;
  n_ = limits.n;
  vlimits_.n = kAxes;
  for (int a = 0; a < kAxes; ++a) {
    vlimits_.lower[static_cast<std::size_t>(a)] = -1e6;
    vlimits_.upper[static_cast<std::size_t>(a)] = 1e6;
  }
  c_ = kin::JointState::rest(kin::JointVector::Zero(kAxes));
  q_prev_ = kin::JointVector::Zero(n_);
}

JogEnd Jogger::end(JogEnd e, int joint, bool ramp) {
  active_ = false;
  deadman_ = false;
  stopping_ = false;
  needs_ramp_ = ramp;
  joint_ = joint;
  return e;
}

bool Jogger::plan_joint(const kin::JointState& cmd) {
  // The jog's speed is a fraction of each joint's velocity limit; accelerations and jerks
  // stay the joint's own (a speed override would scale them too, and a slow jog would
  // then start and stop sluggishly).
  // The safety envelope's caps lower the velocity limits further (a plan from a state above
  // them starts with the planner's recovery to within them).
  kin::JointLimits L = limits_;
  for (int j = 0; j < n_; ++j) L.dyn[static_cast<std::size_t>(j)].max_velocity *= spec_.override;
  if (spec_.stream) {
    // A stream's target held still: the catch-up's TCP cap along its own straight line to the
    // target (a target at rest, SpeedCap::apply_moving), not spread over every joint's limit
    // at once, so the catch-up runs near the TCP limit (the run-time scale holds the rest).
    cap_.apply_joints(L);
    kin::JointVector v = kin::JointVector::Zero(n_), rel = cmd.pos - spec_.q_goal;
    cap_.apply_moving(L, v, rel, kMovingShare);
  } else {
    cap_.apply(L, cmd, spec_.q_goal, kin::JointVector());
  }
  if (kin::plan_movej(L, cmd, spec_.q_goal, kin::MovejOptions{}, plan_) != kin::MotionStatus::ok) return false;
  t_ = 0;
  safe_.reset();  // planned from the real-time state within the caps
  return true;
}

bool Jogger::plan_moving(const kin::JointState& cmd) {
  if (spec_.qd_goal.size() != n_ || !finite(spec_.qd_goal, n_) || !(spec_.horizon_s > 0) ||
      !std::isfinite(spec_.horizon_s) || spec_.qd_goal.cwiseAbs().maxCoeff() == 0)
    return false;
  const double h = spec_.horizon_s;
  // The relative limits: |v_rel| <= vmax - |v_target| keeps |v| <= vmax; the target's speed is
  // held to kMovingShare of the limit so the arm keeps room to catch up.
  kin::JointLimits L = limits_;
  for (int j = 0; j < n_; ++j) L.dyn[static_cast<std::size_t>(j)].max_velocity *= spec_.override;
  cap_.apply_joints(L);  // the safety envelope's joint caps (its TCP cap below)
  kin::JointVector v = spec_.qd_goal;
  kin::JointState rel = cmd;
  for (int j = 0; j < n_; ++j) {
    const auto u = static_cast<std::size_t>(j);
    const double vmax = L.dyn[u].max_velocity;
    v[j] = std::fmax(-kMovingShare * vmax, std::fmin(kMovingShare * vmax, v[j]));
    L.dyn[u].max_velocity = vmax - std::fabs(v[j]);
    L.lower[u] = -1e9;
    L.upper[u] = 1e9;
  }
  for (int j = 0; j < n_; ++j) rel.pos[j] = cmd.pos[j] - spec_.q_goal[j];
  cap_.apply_moving(L, v, rel.pos, kMovingShare);  // the target's TCP speed, then the catch-up's, within the TCP cap
  for (int j = 0; j < n_; ++j) rel.vel[j] = cmd.vel[j] - v[j];
  kin::JointTrajectory plan;
  if (kin::plan_movej(L, rel, kin::JointVector::Zero(n_), kin::MovejOptions{}, plan) != kin::MotionStatus::ok) return false;
  // Where the arm can get to: the relative path's extremes, the target's travel over the horizon,
  // and the braking from its speed, all within the joint's limits.
  for (int j = 0; j < n_; ++j) {
    const auto u = static_cast<std::size_t>(j);
    const kin::JointPeaks pk = kin::peaks(plan, j);
    const double travel = v[j] * h;
    const double a = limits_.dyn[u].max_acceleration, jk = limits_.dyn[u].max_jerk;
    const double reach = v[j] * v[j] / (2 * a) + std::fabs(v[j]) * (a / jk + dt_);
    const double lo = spec_.q_goal[j] + pk.min_position + std::fmin(0.0, travel) - (v[j] < 0 ? reach : 0.0);
    const double hi = spec_.q_goal[j] + pk.max_position + std::fmax(0.0, travel) + (v[j] > 0 ? reach : 0.0);
    if (lo < limits_.lower[u] || hi > limits_.upper[u]) return false;
  }
  plan_ = plan;
  q_ref_ = spec_.q_goal;
  v_ref_ = v;
  horizon_ = h;
  moving_ = true;
  t_ = 0;
  safe_.reset();  // planned from the real-time state within the caps
  return true;
}

// Per-axis limits proportional to the axis's share of the move, so that a move from rest
// is a straight line at the asked speed (the planner synchronises the axes).
bool Jogger::plan_tool(const kin::JointVector& c_goal) {
  const kin::JointVector d = c_goal - c_.pos;
  const double lin = d.head<3>().norm(), ang = d.tail<3>().norm();
  const kin::CartesianLimits& L = spec_.limits;
  for (int a = 0; a < kAxes; ++a) {
    const bool linear = a < 3;
    const double share = linear ? (lin > 0 ? std::fabs(d[a]) / lin : 0.0) : (ang > 0 ? std::fabs(d[a]) / ang : 0.0);
    const double f = std::fmax(share, kFloor);
    kin::JointDynamics& dy = vlimits_.dyn[static_cast<std::size_t>(a)];
    dy.max_velocity = f * (linear ? std::fmin(spec_.linear_speed, cap_.tcp) : spec_.angular_speed);  // (the TCP's cap)
    dy.max_acceleration = f * (linear ? L.linear_acceleration : L.angular_acceleration);
    dy.max_jerk = f * (linear ? L.linear_jerk : L.angular_jerk);
  }
  // The state of the virtual axes in real time (the clock may have been slowed, near a
  // singularity and by the speed scale).
  const double k = scale_ * safe_.s;
  kin::JointState s = c_;
  s.vel *= k;
  s.acc *= k * k;
  if (kin::plan_movej(vlimits_, s, c_goal, kin::MovejOptions{}, plan_) != kin::MotionStatus::ok) return false;
  c_ = s;
  t_ = 0;
  scale_ = 1.0;
  safe_.reset();
  return true;
}

void Jogger::tool_pose(const kin::JointState& c, kin::Pose& out) const {
  const Eigen::Vector3d p = frame_ * Eigen::Vector3d(c.pos[0], c.pos[1], c.pos[2]);
  const Eigen::Vector3d r = frame_ * Eigen::Vector3d(c.pos[3], c.pos[4], c.pos[5]);
  const double angle = r.norm();
  const Eigen::Matrix3d R = angle > 0 ? Eigen::AngleAxisd(angle, r / angle).toRotationMatrix() : Eigen::Matrix3d::Identity();
  out.linear() = R * origin_.linear();
  out.translation() = origin_.translation() + p;
}

bool Jogger::set(const JogSpec& spec, const kin::JointState& cmd, hal::TimePoint now, const char*& why) {
  if (chain_ == nullptr) {
    why = "jog not configured";
    return false;
  }
  if (active_ && spec.space != spec_.space) {
    why = spec.space == JogSpace::tool ? "a joint jog is running: jog stop first" : "a tool jog is running: jog stop first";
    return false;
  }
  if (spec.space == JogSpace::joint) {
    if (spec.q_goal.size() != n_ || !finite(spec.q_goal, n_) || !(spec.override >= 0.01 && spec.override <= 1.0)) {
      why = "bad joint jog";
      return false;
    }
    const JogSpec old = spec_;
    spec_ = spec;
    const bool was_moving = moving_;
    moving_ = false;
    if (spec.stream && plan_moving(cmd)) {
      // tracking the moving target
    } else if (!plan_joint(cmd)) {
      moving_ = was_moving;
      spec_ = old;
      why = "jog cannot be planned from here (it would overshoot a joint limit)";
      return false;
    }
  } else {
    if (spec.ik.fn == nullptr || !(spec.linear_speed > 0) || !(spec.angular_speed > 0) ||
        !std::isfinite(spec.linear_speed) || !std::isfinite(spec.angular_speed)) {
      why = "bad tool jog";
      return false;
    }
    if (active_ && !spec_.frame.isApprox(spec.frame, 1e-12)) {
      why = "a jog in another frame is running: jog stop first";
      return false;
    }
    if (active_ && spec_.chain != spec.chain) {
      why = "a jog with another tool is running: jog stop first";
      return false;
    }
    const JogSpec old = spec_;
    const bool fresh = !active_;
    spec_ = spec;
    if (fresh) {
      kin::forward(spec.chain != nullptr ? *spec.chain : *chain_, cmd.pos, origin_);
      frame_ = spec.frame;
      c_ = kin::JointState::rest(kin::JointVector::Zero(kAxes));
      scale_ = 1.0;
    }
    kin::JointVector goal = c_.pos;
    if (spec.continuous) {
      goal[spec.axis] = c_.pos[spec.axis] + spec.direction * kFar;
    } else {
      const Eigen::Vector3d dp = frame_.transpose() * (spec.target.translation() - origin_.translation());
      const Eigen::AngleAxisd aa(spec.target.linear() * origin_.linear().transpose());
      const Eigen::Vector3d dr = frame_.transpose() * (aa.axis() * aa.angle());
      goal << dp.x(), dp.y(), dp.z(), dr.x(), dr.y(), dr.z();
    }
    if (!finite(goal, kAxes) || !plan_tool(goal)) {
      spec_ = old;
      why = "tool jog cannot be planned";
      return false;
    }
  }
  stopping_ = false;
  deadman_ = false;
  needs_ramp_ = false;
  joint_ = -1;
  active_ = true;
  last_refresh_ = now;
  q_prev_ = cmd.pos;
  return true;
}

void Jogger::stop(const kin::JointState& cmd) {
  if (!active_ || stopping_) return;
  kin::MovejOptions o;
  moving_ = false;  // cmd is where the arm is: the stop is planned in joint space from there
  if (spec_.space == JogSpace::joint) {
    if (kin::plan_stop(limits_, cmd, o, plan_) != kin::MotionStatus::ok) {
      end(JogEnd::done, -1, true);
      return;
    }
  } else {
    const double k = scale_ * safe_.s;
    kin::JointState s = c_;
    s.vel *= k;
    s.acc *= k * k;
    if (kin::plan_stop(vlimits_, s, o, plan_) != kin::MotionStatus::ok) {
      end(JogEnd::done, -1, true);
      return;
    }
    c_ = s;
    scale_ = 1.0;
  }
  t_ = 0;
  stopping_ = true;
  safe_.reset();  // the stop brakes on the limits in real time
}

double Jogger::scale_step(const kin::JointState& cmd) {
  if (safe_.idle()) return dt_;
  double down = 0, up = 0;
  safe_.rate_bounds(limits_, n_, cmd, down, up);
  safe_.step(dt_, down, up);
  return dt_ * safe_.s;
}

JogEnd Jogger::step(kin::JointState& cmd, hal::TimePoint now) {
  if (!active_) return JogEnd::done;
  const bool expired = (spec_.continuous || spec_.stream) && !stopping_ &&
                       static_cast<double>(now - last_refresh_) * 1e-9 > spec_.deadman_s;
  if (expired) {
    stop(cmd);
    deadman_ = true;
  }
  if (!active_) return JogEnd::done;  // (no stop could be planned)
  const JogEnd at_end = deadman_ ? JogEnd::deadman : JogEnd::done;

  if (spec_.space == JogSpace::joint) {
    if (moving_ && t_ + dt_ >= horizon_) {
      // No newer target within the horizon: to rest where the target has got to (or, should
      // that overshoot a limit, to rest as soon as the limits allow).
      moving_ = false;
      spec_.q_goal = q_ref_ + v_ref_ * horizon_;
      if (!plan_joint(cmd)) {
        if (kin::plan_stop(limits_, cmd, kin::MovejOptions{}, plan_) != kin::MotionStatus::ok) return end(JogEnd::done, -1, true);
        t_ = 0;
        safe_.reset();
      }
    }
    t_ += stopping_ ? dt_ : scale_step(cmd);  // the jog's clock: on the speed scale
    if (moving_) {
      plan_.sample(t_, cmd);
      cmd.pos += q_ref_ + v_ref_ * t_;
      cmd.vel += v_ref_;
      scaled(cmd);
      return JogEnd::running;
    }
    plan_.sample(t_, cmd);
    scaled(cmd);
    if (t_ < plan_.duration) return JogEnd::running;
    if (spec_.stream && !stopping_) {  // at the target: held there until the next one (or the deadman)
      t_ = plan_.duration;
      return JogEnd::running;
    }
    // A continuous joint jog that ran to its target has reached the joint's limit.
    if (spec_.continuous && !stopping_) return end(JogEnd::limit, spec_.axis, false);
    return end(at_end, -1, false);
  }

  // Tool jog: try the next pose at the current time scale (near a singularity, scale_) times
  // the speed scale (ks); slow down when a joint would need more than kSlowRatio of its
  // velocity limit.
  const double ks = stopping_ ? 1.0 : scale_step(cmd) / dt_;
  auto solve = [&](double t, kin::JointState& c, kin::JointVector& q, double& ratio, int& worst) {
    plan_.sample(t, c);
    kin::Pose x;
    tool_pose(c, x);
    if (spec_.ik.fn(spec_.chain != nullptr ? *spec_.chain : *chain_, x, cmd.pos, q, spec_.ik.ctx) < kin::Status::ok) return false;
    ratio = 0;
    worst = -1;
    for (int j = 0; j < n_; ++j) {
      const double r = std::fabs(q[j] - cmd.pos[j]) / (limits_.dyn[static_cast<std::size_t>(j)].max_velocity * dt_);
      if (r > ratio) ratio = r, worst = j;
    }
    return true;
  };
  kin::JointState c;
  kin::JointVector q;
  double ratio = 0;
  int worst = -1;
  double scale = scale_;
  if (!solve(t_ + dt_ * scale * ks, c, q, ratio, worst)) return end(JogEnd::unreachable, -1, true);
  // A joint's step scales with the clock: at both scales 1 it would need about ratio / (scale ks).
  const double at_full = scale * ks > 0 ? ratio / (scale * ks) : ratio;
  const double want = at_full > 0 ? std::fmin(1.0, kSlowRatio / (at_full * ks)) : 1.0;
  const double next = std::fmin(1.0, std::fmin(std::fmax(want, scale_ - kScaleStep), scale_ + kScaleStep));
  if (next != scale) {
    scale = next;
    if (!solve(t_ + dt_ * scale * ks, c, q, ratio, worst)) return end(JogEnd::unreachable, -1, true);
  }
  // Above kStopRatio of a limit (slowing could not keep up) the jog gives up its line; the
  // caller's joint ramp then starts below the limit.
  if (ratio > kStopRatio || (scale < kMinScale && want < scale)) return end(JogEnd::singular, worst, true);
  // Joint limits: stop before a joint's stopping distance reaches its limit.
  for (int j = 0; j < n_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    const double v = (q[j] - cmd.pos[j]) / dt_;
    const double a = limits_.dyn[ju].max_acceleration, jk = limits_.dyn[ju].max_jerk;
    const double reach = v * v / (2 * a) + std::fabs(v) * (a / jk + dt_);
    if ((v > 0 && q[j] + reach > limits_.upper[ju]) || (v < 0 && q[j] - reach < limits_.lower[ju]) ||
        q[j] > limits_.upper[ju] || q[j] < limits_.lower[ju])
      return end(JogEnd::limit, j, true);
  }
  const kin::JointVector vel = (q - cmd.pos) / dt_;
  cmd.acc = (vel - cmd.vel) / dt_;
  cmd.vel = vel;
  cmd.pos = q;
  scale_ = scale;
  t_ += dt_ * scale * ks;
  c_ = c;
  if (t_ < plan_.duration) return JogEnd::running;
  cmd.vel.setZero();
  cmd.acc.setZero();
  return end(at_end, -1, false);
}

}  // namespace servoarm::fw
