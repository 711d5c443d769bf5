// SPDX-License-Identifier: Apache-2.0
#include "servoarm/service/stream.hpp"

#include <cmath>
#include <cstdio>
#include <utility>

namespace servoarm::fw {

StreamResult StreamService::joint_target(const kin::JointVector& q_in, bool start, const kin::JointVector& qd_in,
                                         std::optional<double> t_in, bool clamp_step) {
  StreamResult r;
  const kin::JointLimits& lim = svc_.limits();
  const int n = lim.n;
  if (q_in.size() != n) {
    r.error = CmdError::arg_count;
    r.reason = "expected " + std::to_string(n) + " joint values, got " + std::to_string(q_in.size());
    return r;
  }
  for (int j = 0; j < n; ++j) {
    const auto u = static_cast<std::size_t>(j);
    if (!std::isfinite(q_in[j])) {
      r.error = CmdError::not_finite;
      r.reason = "joint " + std::to_string(j) + ": not finite";
      return r;
    }
    if (q_in[j] < lim.lower[u] || q_in[j] > lim.upper[u]) {
      char b[160];
      std::snprintf(b, sizeof b, "joint %d = %.6g outside [%.6g, %.6g]", j, q_in[j], lim.lower[u], lim.upper[u]);
      r.error = CmdError::limits;
      r.reason = b;
      return r;
    }
  }
  if (qd_in.size() != 0 && qd_in.size() != n) {
    r.error = CmdError::arg_count;
    r.reason = "qd: expected " + std::to_string(n) + " joint velocities, got " + std::to_string(qd_in.size());
    return r;
  }
  for (int j = 0; j < qd_in.size(); ++j)
    if (!std::isfinite(qd_in[j])) {
      r.error = CmdError::not_finite;
      r.reason = "qd: joint " + std::to_string(j) + ": not finite";
      return r;
    }
  if (t_in && !std::isfinite(*t_in)) {
    r.error = CmdError::not_finite;
    r.reason = "t: not finite";
    return r;
  }
  if (t_in && *t_in < 0) {
    char b[160];
    std::snprintf(b, sizeof b, "t: %.6g s is negative (the target's time on the client's monotonic clock)", *t_in);
    r.error = CmdError::out_of_range;
    r.reason = b;
    return r;
  }
  const Telemetry t = ctl_.telemetry();
  // The stream runs while the control thread says so, or the target before this one was taken
  // in the cycle the telemetry shows (its own publication may not have come yet).
  const bool running = this->running(t);
  if (!start && !running) {
    r.error = CmdError::bad_state;
    r.reason = sent_ ? std::string("the stream ended (the arm is ") + to_string(t.state) + "): start a new one"
                     : "no stream runs: the first target starts it (start)";
    return r;
  }
  // The client's clock: `start` begins it anew. A timed target not newer than the newest is
  // dropped (counted, answered ok: a reordering transport is not an error of the client's).
  const double now = static_cast<double>(t.cycles) * ctl_.period_s();
  const bool clock = !start && clock_;
  if (t_in && clock && *t_in <= t_newest_) {
    ++stats_.stale;
    r.stale = true;
    r.stats = stats_;
    return r;
  }
  double offset_min = offset_min_, late = 0;
  if (t_in) {
    const double off = now - *t_in;  // arrival on the control thread's clock less the client's time
    if (clock && offset_min_ - off > kStreamClockAheadS) {
      char b[200];
      std::snprintf(b, sizeof b, "t: %.6g s is %.3f s ahead of the control thread's clock since the stream's fastest delivery (at most %g s)",
                    *t_in, offset_min_ - off, kStreamClockAheadS);
      r.error = CmdError::out_of_range;
      r.reason = b;
      return r;
    }
    offset_min = clock ? std::fmin(offset_min_, off) : off;
    late = off - offset_min;
  }
  kin::JointVector q = q_in;
  kin::JointVector from(n);
  for (int j = 0; j < n; ++j) from[j] = running ? last_[j] : t.q_cmd[static_cast<std::size_t>(j)];
  for (int j = 0; j < n && static_cast<std::size_t>(j) < cfg_.max_step.size(); ++j) {
    const double step = cfg_.max_step[static_cast<std::size_t>(j)];
    const double d = q[j] - from[j];
    if (!(step > 0) || std::fabs(d) <= step) continue;
    if (!clamp_step) {
      char b[160];
      std::snprintf(b, sizeof b, "joint %d: a step of %.6g from the last target, more than %.6g", j, d, step);
      r.error = CmdError::out_of_range;
      r.reason = b;
      return r;
    }
    q[j] = from[j] + std::copysign(step, d);
    r.clamped = true;
  }
  // The safety envelope (docs/safety.md): the target's tool (and elbow) sphere, planes, boxes
  // and orientation, with the active tool. Speed is the control thread's: it tracks within the
  // limits, and its monitor scales or stops.
  if (std::string why = svc_.check_target(from, q, 0.0, &svc_.tool_chain(svc_.active_tool())); !why.empty()) {
    r.error = CmdError::limits;
    r.reason = std::move(why);
    return r;
  }
  // The target's velocity: the client's, or estimated from the target before and the time
  // between them (the client's times when both have one, else the control thread's clock at
  // their arrival). The target moves on at it for `horizon` (twice the time between targets, at
  // most the deadman time); a velocity that would carry it through the safety envelope within
  // that time is dropped (the arm comes to rest at the target).
  const double arrival_gap = now - sent_t_;
  const bool arrival_spaced = running && arrival_gap > 0 && arrival_gap <= cfg_.deadman_s;
  const bool client_gap = t_in && clock && last_timed_ && running;
  const double gap = client_gap ? *t_in - t_newest_ : arrival_gap;
  const bool spaced = client_gap ? gap > 0 && gap <= cfg_.deadman_s : arrival_spaced;
  kin::JointVector qd = kin::JointVector::Zero(n);
  if (qd_in.size() == n)
    qd = qd_in;
  else if (spaced && client_gap)
    qd = (q - from) / std::fmax(gap, ctl_.period_s());
  else if (spaced)  // two targets that arrive close together (delayed on the way) are not a burst of speed
    qd = (q - from) / std::fmax(gap, 0.5 * gap_avg_);
  const double horizon = spaced ? std::fmin(cfg_.deadman_s, 2 * gap) : cfg_.deadman_s;
  // Element by element over the n joints: GCC 12 for armhf reads Eigen's reduction over the
  // inline storage as possibly uninitialised (-Wmaybe-uninitialized).
  const auto moving = [n](const kin::JointVector& v) {
    for (int j = 0; j < n; ++j)
      if (v[j] != 0) return true;
    return false;
  };
  if (moving(qd)) {
    const kin::JointVector ahead = q + qd * horizon;
    bool inside = true;
    for (int j = 0; j < n; ++j)
      inside = inside && ahead[j] >= lim.lower[static_cast<std::size_t>(j)] && ahead[j] <= lim.upper[static_cast<std::size_t>(j)];
    if (!inside || !svc_.check_target(q, ahead, 0.0, &svc_.tool_chain(svc_.active_tool())).empty()) qd.setZero();
  }
  // A timed target that came `late` after the fastest delivery has moved on at its velocity
  // since it was sampled: it starts that far along its checked path, for the rest of its
  // horizon (past the horizon: at the path's end, at rest).
  kin::JointVector goal = q;
  double goal_horizon = horizon;
  if (late > 0 && moving(qd)) {
    if (late + ctl_.period_s() < horizon) {
      goal = q + qd * late;
      goal_horizon = horizon - late;
    } else {
      goal = q + qd * horizon;
      qd.setZero();
    }
  }
  Request rq;
  rq.op = RequestOp::jog;
  rq.jog.space = JogSpace::joint;
  rq.jog.stream = true;
  rq.jog.deadman_s = cfg_.deadman_s;
  rq.jog.q_goal = goal;
  rq.jog.override = std::fmin(1.0, std::fmax(0.01, cfg_.speed_pct / 100.0));
  rq.jog.axis = -1;
  rq.jog.qd_goal = qd;
  rq.jog.horizon_s = goal_horizon;
  Reply rep;
  if (!svc_.request(rq, rep)) {
    r.error = CmdError::timeout;
    r.reason = "control thread did not answer the stream target";
    return r;
  }
  switch (rep.result) {
    case RtResult::ok:
      last_ = q;
      sent_ = true;
      sent_cycle_ = ctl_.telemetry().cycles;
      sent_t_ = now;
      gap_avg_ = arrival_spaced ? (gap_avg_ > 0 ? 0.8 * gap_avg_ + 0.2 * arrival_gap : arrival_gap) : 0.0;
      svc_.jog_forget();  // the next jog starts from the commanded position, not a jog's tail
      if (start) {
        stats_ = StreamStats();
        clock_ = false;
        late_mean_ = late_m2_ = 0;
      }
      ++stats_.targets;
      last_timed_ = t_in.has_value();
      if (t_in) {
        clock_ = true;
        t_newest_ = *t_in;
        offset_min_ = offset_min;
        const double k = static_cast<double>(++stats_.timed), d = late - late_mean_;
        late_mean_ += d / k;
        late_m2_ += d * (late - late_mean_);
        stats_.late_s = late;
        stats_.late_max_s = std::fmax(stats_.late_max_s, late);
        stats_.jitter_s = std::sqrt(late_m2_ / k);
      }
      r.stats = stats_;
      return r;
    case RtResult::busy: r.error = CmdError::busy; break;
    case RtResult::fault: r.error = CmdError::fault; break;
    case RtResult::not_homed: r.error = CmdError::not_homed; break;
    case RtResult::bad_state:
    case RtResult::start_moved:
    case RtResult::plan_failed: r.error = CmdError::bad_state; break;
  }
  r.reason = rep.message;
  return r;
}

StreamResult StreamService::target_pose(const kin::Pose& pose_in, bool in_frame, bool start, std::optional<double> t_in) {
  StreamResult r;
  if (!pose_in.matrix().allFinite()) {
    r.error = CmdError::not_finite;
    r.reason = "pose: not finite";
    return r;
  }
  const std::size_t tool = svc_.active_tool();
  const kin::Pose pose = in_frame ? svc_.frame(svc_.active_frame()).pose * pose_in : pose_in;
  const Telemetry t = ctl_.telemetry();
  const int n = svc_.limits().n;
  kin::JointVector seed(n);
  const bool run = running(t) && last_.size() == n;
  for (int j = 0; j < n; ++j) seed[j] = run ? last_[j] : t.q_cmd[static_cast<std::size_t>(j)];
  const kin::IkSolver ik = svc_.tool_ik(tool);
  kin::JointVector q(n);
  if (ik.fn == nullptr || ik.fn(svc_.tool_chain(tool), pose, seed, q, ik.ctx) < kin::Status::ok) {
    const Eigen::Vector3d p = pose.translation();
    char b[160];
    std::snprintf(b, sizeof b, "pose [%.4g, %.4g, %.4g] m (base frame) of tool %s: no IK solution within the joint limits",
                  p.x(), p.y(), p.z(), svc_.tool(tool).name.c_str());
    r.error = CmdError::unreachable;
    r.reason = b;
    return r;
  }
  return joint_target(q, start, kin::JointVector(), t_in, false);
}

}  // namespace servoarm::fw
