// SPDX-License-Identifier: Apache-2.0
// The safety envelope's run-time monitor (servoarm/rt/safety_monitor.hpp).
#include "servoarm/rt/safety_monitor.hpp"

#include <algorithm>
#include <cmath>

namespace servoarm::fw {

void SafetyMonitor::configure(const kin::Chain& chain, const kin::SafetyConfig& cfg, double period_s) {
  own_ = chain;
  flange_ = chain.tool;
  chain_ = &own_;
  cfg_ = cfg;
  period_s_ = period_s;
  have_prev_ = false;
}

void SafetyMonitor::set_tool(const kin::Pose& tool, double radius) {
  kin::set_tool(own_, flange_ * tool);
  cfg_.tool_radius = radius;
  have_prev_ = false;
}

bool SafetyMonitor::update(const kin::JointVector& q_cmd, const kin::JointVector& q_act, kin::SafetyMode mode,
                           bool only_growing, kin::SafetyViolation& out, bool& on_actual, bool speeds_scaled) {
  ratio_ = 0;
  reduced_state_ratio_ = 0;
  had_stop_ = has_stop_ && have_prev_;
  has_stop_ = false;
  speed_over_ = false;
  if (!cfg_.enabled || chain_ == nullptr) return false;
  const bool ok_cmd = kin::safety_sample(*chain_, cfg_, q_cmd, -1.0, cmd_);
  const bool ok_act = kin::safety_sample(*chain_, cfg_, q_act, -1.0, act_);
  cmd_.has_velocity = act_.has_velocity = false;
  if (ok_cmd) zone_ = kin::trigger_plane(cfg_, cmd_);
  mode = effective(mode);
  const bool had_prev = have_prev_;
  if (had_prev) kin::set_velocity(cmd_, prev_cmd_, prev_q_cmd_, q_cmd, period_s_);
  // The measured state's speed would be the drives' position quantisation differenced every
  // cycle: only its positions and orientation are checked.
  const double pm = cfg_.position_tolerance, am = cfg_.angle_tolerance, sm = cfg_.speed_tolerance;
  bool hit = false;
  if (ok_cmd) ratio_ = kin::speed_ratio(cfg_, mode, cmd_);
  if (ok_cmd && kin::check_sample(cfg_, mode, cmd_, pm, am, sm, out, 1.0)) {
    if (speeds_scaled && kin::is_speed(out.function)) {  // (the places come first: they are inside)
      speed_over_ = true;
      speed_v_ = out;
    } else {
      hit = !only_growing || !had_prev || out.excess() > kin::safety_excess(cfg_, mode, prev_cmd_, out);
      on_actual = false;
    }
  }
  if (!hit && ok_act && kin::check_sample(cfg_, mode, act_, pm, am, sm, out)) {
    hit = !only_growing || !had_prev || out.excess() > kin::safety_excess(cfg_, mode, prev_act_, out);
    on_actual = true;
  }
  have_prev_ = ok_cmd && ok_act;
  prev_cmd_ = cmd_;
  prev_act_ = act_;
  prev_q_cmd_ = q_cmd;
  return hit;
}

bool SafetyMonitor::check_state(const kin::JointLimits& limits, const kin::JointState& cmd, kin::SafetyMode mode,
                                kin::SafetyViolation& out, bool speeds_scaled) {
  if (!cfg_.enabled || chain_ == nullptr) return false;
  const kin::SafetyLimits& lim = cfg_.limits(mode);
  // The trigger look-ahead (time_to_trigger) takes the Reduced stop and dynamics limits too.
  const kin::SafetyLimits& red = cfg_.reduced;
  const bool ahead = speeds_scaled && mode == kin::SafetyMode::normal && cfg_.trigger_count > 0 && zone_ < 0;
  const bool stops = lim.has_stop_limit() || (ahead && red.has_stop_limit());
  const bool dynamics = lim.has_dynamics_limit() || (ahead && red.has_dynamics_limit());
  if (!stops && !dynamics) return false;
  // cmd_ is the TCP at cmd.pos (update() of this cycle)
  if (stops) (void)kin::stop_prediction(*chain_, limits, cmd, stop_, cmd_);
  if (dynamics) (void)kin::dynamics_prediction(*chain_, cmd, cmd_);
  if (ahead) reduced_state_ratio_ = kin::speed_ratio(cfg_, kin::SafetyMode::reduced, cmd_, kStopAim);
  if (!speeds_scaled) {
    const bool hit = kin::check_stop(cfg_, mode, cmd_, cfg_.position_tolerance, 1.0, out);
    cmd_.has_stop = cmd_.has_dynamics = false;
    return hit;
  }
  // On the speed scale: each of these goes down with the speed, so their ratios (kin::speed_ratio)
  // drive the scale's target as the speeds' do, and the predicted stop is kept within its limits
  // before they are reached. A stop time or distance beyond limit + tolerance is a protective
  // stop in this very cycle all the same: the stop that starts now is the ramp predicted, and one
  // a cycle later would end beyond it. Momentum and power beyond theirs are left to the caller
  // as the speeds are (speed_over()).
  ratio_ = std::fmax(ratio_, kin::speed_ratio(cfg_, mode, cmd_, kStopAim));
  const bool dyn = cmd_.has_dynamics;
  cmd_.has_dynamics = false;
  // The stop is checked as predicted one cycle on (its growth over the last cycle added): a
  // prediction growing by a millimetre a cycle would otherwise pass limit + tolerance by up to
  // that much in the cycle it is caught. The event shows the value predicted now.
  const double d = cmd_.stop_distance, t = cmd_.stop_time;
  if (cmd_.has_stop && had_stop_) {
    cmd_.stop_distance += std::fmax(0.0, d - prev_stop_distance_);
    cmd_.stop_time += std::fmax(0.0, t - prev_stop_time_);
  }
  const bool hit = kin::check_stop(cfg_, mode, cmd_, cfg_.position_tolerance, 1.0, out);
  if (hit) out.value = out.function == kin::SafetyFunction::stop_time ? t : d;
  has_stop_ = cmd_.has_stop;
  prev_stop_distance_ = d;
  prev_stop_time_ = t;
  cmd_.stop_distance = d;
  cmd_.stop_time = t;
  cmd_.has_dynamics = dyn;
  cmd_.has_stop = false;
  kin::SafetyViolation v;
  if (!hit && kin::check_stop(cfg_, mode, cmd_, cfg_.position_tolerance, 1.0, v)) {
    if (!speed_over_) speed_v_ = v;
    speed_over_ = true;
  }
  cmd_.has_dynamics = false;
  return hit;
}

double SafetyMonitor::time_to_trigger(double per_scale, double& reduced_ratio) const {
  reduced_ratio = 0;
  if (!cfg_.enabled || zone_ >= 0 || cfg_.trigger_count == 0 || !cmd_.has_velocity) return INFINITY;
  double t = INFINITY;
  const Eigen::Vector3d c = cmd_.tcp.translation();
  const Eigen::Vector3d v = cmd_.tcp_velocity * per_scale;
  for (int i = 0; i < cfg_.trigger_count && i < kin::kMaxSafetyPlanes; ++i) {
    const kin::SafetyPlane& p = cfg_.trigger_planes[static_cast<std::size_t>(i)];
    const double gap = p.normal.dot(c) - cfg_.tool_radius - p.offset;  // > 0: outside its zone
    const double towards = -p.normal.dot(v);
    if (towards > 0) t = std::fmin(t, std::fmax(0.0, gap) / towards);
  }
  if (t < INFINITY)
    reduced_ratio = std::fmax(kin::speed_ratio(cfg_, kin::SafetyMode::reduced, cmd_), reduced_state_ratio_);
  return t;
}

void SafetyMonitor::speed_cap(kin::SafetyMode mode, double aim, double horizon_s, SpeedCap& out) const {
  out = SpeedCap{};
  if (!cfg_.enabled || chain_ == nullptr || !have_prev_) return;
  const kin::SafetyMode m = effective(mode);
  const kin::SafetyLimits& lim = cfg_.limits(m);
  const int n = static_cast<int>(prev_q_cmd_.size());
  if (lim.tcp_speed > 0) out.tcp = aim * lim.tcp_speed;
  for (int j = 0; j < n && j < kin::kMaxJoints; ++j) {
    const auto u = static_cast<std::size_t>(j);
    if (lim.joint_speed[u] > 0) out.joint[u] = aim * lim.joint_speed[u];
  }
  if (m == kin::SafetyMode::normal && cfg_.trigger_count > 0) {
    const kin::SafetyLimits& red = cfg_.reduced;
    double gap = INFINITY;
    const Eigen::Vector3d c = cmd_.tcp.translation();
    for (int i = 0; i < cfg_.trigger_count && i < kin::kMaxSafetyPlanes; ++i) {
      const kin::SafetyPlane& p = cfg_.trigger_planes[static_cast<std::size_t>(i)];
      gap = std::fmin(gap, std::fmax(0.0, p.normal.dot(c) - cfg_.tool_radius - p.offset));
    }
    const double v = red.tcp_speed > 0 ? red.tcp_speed : kCapSpeed;
    const double f = std::fmax(1.0, gap / (horizon_s * v));
    if (red.tcp_speed > 0) out.tcp = std::fmin(out.tcp, aim * red.tcp_speed * f);
    for (int j = 0; j < n && j < kin::kMaxJoints; ++j) {
      const auto u = static_cast<std::size_t>(j);
      if (red.joint_speed[u] > 0) out.joint[u] = std::fmin(out.joint[u], aim * red.joint_speed[u] * f);
    }
  }
  if (!(out.tcp < INFINITY)) return;
  kin::Jacobian J;
  if (kin::jacobian(*chain_, prev_q_cmd_, J) < kin::Status::ok) return;
  for (int j = 0; j < n && j < kin::kMaxJoints; ++j) {
    const auto u = static_cast<std::size_t>(j);
    out.tcp_gain[u] = J.block<3, 1>(0, j).norm();
    for (int k = 0; k < 3; ++k) out.tcp_col[u][static_cast<std::size_t>(k)] = J(k, j);
  }
}

bool SafetyMonitor::predict_stop(const kin::JointLimits& limits, const kin::JointState& cmd, kin::SafetyMode mode,
                                 kin::SafetyViolation& out) {
  if (!cfg_.enabled || chain_ == nullptr) return false;
  kin::MovejOptions o;
  if (kin::plan_stop(limits, cmd, o, stop_) != kin::MotionStatus::ok) return false;
  kin::JointState end;
  end.pos = cmd.pos;
  end.vel = cmd.vel;
  end.acc = cmd.acc;
  stop_.sample(stop_.duration, end);
  kin::SafetySample here, there;
  if (!kin::safety_sample(*chain_, cfg_, cmd.pos, 0.0, here) || !kin::safety_sample(*chain_, cfg_, end.pos, -1.0, there))
    return false;
  // positions only: the cone and the speeds are the per-cycle check's
  kin::SafetyConfig positions_only = cfg_;
  positions_only.cone = false;
  kin::SafetyViolation v;
  if (!kin::check_sample(positions_only, mode, there, 0.0, 0.0, 0.0, v)) return false;
  if (kin::safety_excess(cfg_, mode, there, v) <= kin::safety_excess(cfg_, mode, here, v)) return false;  // moving back in
  out = v;
  return true;
}

}  // namespace servoarm::fw
