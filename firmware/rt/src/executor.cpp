// SPDX-License-Identifier: Apache-2.0
// The motion executor (executor.hpp): one queue of segments, one start, one sample, one hold,
// one resume and one re-plan rule; and the controller's side of it (step_motion, feed hold,
// resume, the SegmentHost callbacks).
#include "servoarm/rt/executor.hpp"

#include <cmath>
#include <cstdio>

#include "servoarm/rt/controller.hpp"

namespace servoarm::fw {

namespace {
kin::PathSegment& seg_of(MotionItem& m) { return std::get_if<PathMove>(&m.payload)->seg; }

/// The arm is at rest exactly where `plan` starts (so it runs as it is).
bool starts_here(const kin::JointTrajectory& plan, const kin::JointState& cmd, int n) {
  if (plan.n != n) return false;
  kin::JointState s0;
  plan.sample(-1.0, s0);  // t < 0: exactly the start state
  for (int j = 0; j < n; ++j)
    if (s0.pos[j] != cmd.pos[j] || s0.vel[j] != 0.0 || cmd.vel[j] != 0.0) return false;
  return true;
}
}  // namespace

void MotionExecutor::configure(const kin::JointLimits& limits, int n_joints, double period_s, SegmentHost& host) {
  limits_ = &limits;
  n_ = n_joints;
  period_s_ = period_s;
  host_ = &host;
  path_ahead_ = kin::JointVector::Zero(n_);
}

// ---------------------------------------------------------------------------
// Start, finish, flush
// ---------------------------------------------------------------------------

bool MotionExecutor::replan(const kin::JointVector& from, const kin::JointVector& target, double override,
                            kin::JointTrajectory& out) const {
  kin::MovejOptions o;
  o.override = override;
  return kin::plan_movej(*limits_, kin::JointState::rest(from), target, o, out) == kin::MotionStatus::ok;
}

RtResult MotionExecutor::open(MotionItem& m, kin::JointState& cmd) {
  if (m.kind() != MotionKind::dwell && !host_->may_move()) return RtResult::not_homed;  // (the console refuses these first)
  switch (m.kind()) {
    case MotionKind::joint: {
      JointMove& jm = *std::get_if<JointMove>(&m.payload);
      if (jm.blend > 0.0 && begin_blend(jm, cmd)) return RtResult::ok;  // the run's first segment (replaces the plan)
      phase_ = SegPhase::plan;
      plan_ = &jm.plan;
      if (starts_here(jm.plan, cmd, n_)) return RtResult::ok;  // the console's plan, as it is
      ++joint_replans_;
      return replan(cmd.pos, jm.goal, jm.override, jm.plan) ? RtResult::ok : RtResult::plan_failed;
    }
    case MotionKind::cartesian: {
      kin::CartesianTrajectory& path = std::get_if<CartesianMove>(&m.payload)->path;
      double dev = 0;
      for (int j = 0; j < n_; ++j) dev = std::fmax(dev, std::fabs(path.q_knot[0][static_cast<std::size_t>(j)] - cmd.pos[j]));
      phase_ = SegPhase::line;
      line_ = &path;
      return dev > 1e-6 ? RtResult::start_moved : RtResult::ok;
    }
    case MotionKind::dwell: phase_ = SegPhase::dwell; return RtResult::ok;
    case MotionKind::path:  // a run starts from rest where its first segment does
      return begin_path(m, cmd) ? RtResult::ok : RtResult::start_moved;
  }
  return RtResult::plan_failed;
}

bool MotionExecutor::start(kin::JointState& cmd) {
  while (MotionItem* m = queue_.front()) {
    t_ = 0;
    running_ = m;
    const RtResult r = open(*m, cmd);
    if (r != RtResult::ok) {
      retire(true, r);
      continue;
    }
    host_->segment_started(*m);
    return true;
  }
  return false;
}

void MotionExecutor::retire(bool refused, RtResult why) {
  if (running_ == nullptr) return;
  const std::uint32_t id = running_->id;
  running_ = nullptr;
  phase_ = SegPhase::none;
  queue_.pop();
  host_->segment_ended(id, refused, why);
}

MotionExecutor::Step MotionExecutor::finish(kin::JointState& cmd, bool at_goal) {
  if (at_goal) cmd = kin::JointState::rest(running_->goal());
  retire(false, RtResult::ok);
  return start(cmd) ? Step::running : Step::idle;
}

MotionExecutor::Step MotionExecutor::refuse(RtResult why, kin::JointState& cmd) {
  retire(true, why);
  return start(cmd) ? Step::running : Step::idle;
}

std::size_t MotionExecutor::flush() {
  const std::size_t n = queue_.clear();
  running_ = nullptr;
  phase_ = SegPhase::none;
  scale_.reset();  // (a stop ramps from the commanded state, in real time)
  return n;
}

double MotionExecutor::scale_step(const kin::JointState& cmd) {
  double down = 0, up = 0;
  scale_.rate_bounds(*limits_, n_, cmd, down, up);
  scale_.step(period_s_, down, up);
  return period_s_ * scale_.s;
}

// ---------------------------------------------------------------------------
// The samplers (MotionExecutor::step in executor.hpp dispatches on the phase)
// ---------------------------------------------------------------------------

MotionExecutor::Step MotionExecutor::step_dwell(kin::JointState& cmd) {
  return t_ >= std::get_if<DwellMove>(&running_->payload)->seconds ? finish(cmd, false) : Step::running;
}

// The end of a joint plan (plan_): the move's own, or after a hold of a path move the joint
// move to the segment's end (then done) or to its start (then it runs from rest as planned).
MotionExecutor::Step MotionExecutor::end_of_plan(kin::JointState& cmd) {
  if (phase_ != SegPhase::path_to_start) return finish(cmd, true);
  cmd = kin::JointState::rest(resume_plan_.goal);
  if (begin_path(*running_, cmd)) return Step::running;  // at its start: the segment runs from rest
  return refuse(RtResult::start_moved, cmd);
}

// The end of a line (line_: a line, or a path move's line after a hold). In hold_line it has
// slowed to rest on its line: held.
MotionExecutor::Step MotionExecutor::end_of_line(Mode mode, kin::JointState& cmd) {
  if (mode == Mode::hold_line) {  // at rest on the line
    t_ = line_->duration;
    return Step::held;
  }
  return finish(cmd, true);
}

// ---------------------------------------------------------------------------
// Blended joint runs (docs/motion.md#blending)
// ---------------------------------------------------------------------------
// Consecutive queued joint moves whose target carries a blend tolerance run as one
// kin::JointBlendQueue: each move one straight joint-space segment, the next one
// superposed on its end as far as the tolerance and every joint's velocity, acceleration
// and jerk limits (scaled by the moves' override) allow, checked exactly by the queue; a
// corner that cannot blend is an exact stop. The next move is appended while the arm
// moves, at most one append per cycle (bounded, heap-free, never earlier than the next
// sample: nothing already commanded changes). A move is done (motion_done) when its
// segment has come to rest; the next one is then running_ (it has been moving since its
// blend began). A run is only entered from rest and ends at rest; a hold leaves it (phase
// plan: the ramp starts from the blended state, resume plans the rest of the move).

bool MotionExecutor::begin_blend(const JointMove& jm, const kin::JointState& cmd) {
  kin::JointLimits l = *limits_;
  const double o = jm.override;
  if (!(o >= 0.01 && o <= 1.0)) return false;
  for (int j = 0; j < n_; ++j)
    if (cmd.vel[j] != 0.0) return false;  // a run starts from rest only
  for (int j = 0; j < n_; ++j) {
    kin::JointDynamics& d = l.dyn[static_cast<std::size_t>(j)];
    d.max_velocity *= o;
    d.max_acceleration *= o * o;
    d.max_jerk *= o * o * o;
  }
  blend_.reset(l, cmd.pos);
  const kin::BlendStatus st = blend_.append(jm.goal, jm.blend, 0.0);
  if (!kin::is_ok(st) || st == kin::BlendStatus::zero_length) return false;
  phase_ = SegPhase::blend_open;
  blend_items_ = 1;
  blend_t_ = 0;
  blend_override_ = o;
  return true;
}

void MotionExecutor::blend_more() {
  if (phase_ != SegPhase::blend_open || blend_items_ >= kBlendSegments) return;
  const MotionItem* last = queue_.peek(static_cast<std::size_t>(blend_items_ - 1));
  const MotionItem* next = queue_.peek(static_cast<std::size_t>(blend_items_));
  if (last == nullptr || next == nullptr) return;  // nothing queued after it yet: try again next cycle
  const auto* lj = std::get_if<JointMove>(&last->payload);
  const auto* nj = std::get_if<JointMove>(&next->payload);
  if (lj == nullptr || !(lj->blend > 0.0) || nj == nullptr || nj->override != blend_override_ || next->n_outputs != 0) {
    phase_ = SegPhase::blend_closed;  // the run ends at rest at `last`; `next` starts from rest as an unblended move
    return;
  }
  kin::BlendReport rep;
  const kin::BlendStatus st = blend_.append(nj->goal, nj->blend, blend_t_ + period_s_, &rep);
  if (!kin::is_ok(st) || st == kin::BlendStatus::zero_length) {
    phase_ = SegPhase::blend_closed;
    return;
  }
  if (rep.blend > 0.0) ++blends_;
  ++blend_items_;
}

MotionExecutor::Step MotionExecutor::step_blend(kin::JointState& cmd, double h) {
  blend_more();
  blend_t_ += h;
  blend_.sample(blend_t_, cmd.pos, cmd.vel, cmd.acc);
  scaled(cmd);
  const int before = blend_.size();
  blend_.retire(blend_t_);
  for (int ended = before - blend_.size(); ended > 0 && running_ != nullptr; --ended) {
    if (--blend_items_ == 0) return finish(cmd, true);  // the run's end: at rest there
    const SegPhase run = phase_;
    retire(false, RtResult::ok);
    running_ = queue_.front();  // appended to the run: moving since its blend began
    phase_ = run;
    t_ = 0;
  }
  return Step::running;
}

// ---------------------------------------------------------------------------
// Path runs (PathMove; docs/motion.md#blending)
// ---------------------------------------------------------------------------
// The console plans each segment (a joint move or a line) alone from rest at the previous
// target and chooses its overlap with the one before it (kin::PathBlendQueue: checks of every
// joint's limits, the tool speed and the corner tolerance, sampled at this rate on the run's
// time base). Here the segments run in place in the queue: running_ and, from its start time
// on, the next one (the second in the queue: phase path_overlap) when it blends out of
// running_; the sample is their superposition (kin::path_sample_pair: one IK in a line-line
// overlap, as a movel sample). The command's velocity and acceleration are the samples'
// differences (what a stop ramps down from). A segment is done (motion_done) when it has
// ended; the next is then running_. A segment that comes too late to start at its time (the
// console queued it after the run passed it) starts from rest where the one before ends: an
// exact stop (phase path_closed). A stop, fault or e-stop ramps down from the blended state.

bool MotionExecutor::begin_path(MotionItem& m, const kin::JointState& cmd) {
  const kin::PathSegment& g = seg_of(m);
  kin::JointVector q0(n_);
  kin::path_segment_start(g, n_, q0);
  for (int j = 0; j < n_; ++j)
    if (std::fabs(q0[j] - cmd.pos[j]) > 1e-6 || cmd.vel[j] != 0.0) return false;
  phase_ = SegPhase::path_open;
  path_t0_ = g.start;  // on the console's time base: the overlaps it checked line up
  path_k_ = 0;
  path_lag_ = path_next_lag_ = 0;
  path_have_ahead_ = false;
  t_ = 0;
  return true;
}

void MotionExecutor::path_look_ahead(const kin::PathSegment& g, double t, double tn) {
  MotionItem* nx = queue_.peek(1);
  const PathMove* np = nx != nullptr ? std::get_if<PathMove>(&nx->payload) : nullptr;
  if (np != nullptr && np->after == running_->id && nx->n_outputs == 0 && np->seg.start < g.end() - 1e-12) {
    if (!(np->seg.start > t)) phase_ = SegPhase::path_closed;  // queued after its start time went by
    else if (np->seg.start <= tn) {
      phase_ = SegPhase::path_overlap;
      next_ = nx;
      ++blends_;
    }
  } else if (nx != nullptr) {
    phase_ = SegPhase::path_closed;  // what follows does not blend out of this segment: rest at its target
  }
}

// One sample ahead: the setpoint is the sample at t (taken last cycle), its velocity and
// acceleration central differences with the one at t + h (what a stop ramps down from,
// accurate to O(dt^2): the ramp starts without an acceleration step). h is the period on the
// run's time base (period_s_ times the speed scale): the differences are over real time
// already, so the setpoints need no conversion.
MotionExecutor::Step MotionExecutor::step_path(kin::JointState& cmd, double h) {
  const kin::PathSegment& g = seg_of(*running_);
  ++path_k_;
  path_lag_ += path_next_lag_;
  path_next_lag_ = h - period_s_;  // 0 at full speed: the run stays on whole periods
  const double t = run_time(), tn = t + h;
  if (!path_have_ahead_) {  // the run's first cycle
    const bool both = phase_ == SegPhase::path_overlap;
    if (kin::path_sample_pair(both ? &g : nullptr, both ? seg_of(*next_) : g, t, cmd.pos, path_ahead_) <
        kin::Status::ok)
      ++ik_fallbacks_;
    path_have_ahead_ = true;
  }
  if (phase_ == SegPhase::path_open) path_look_ahead(g, t, tn);  // computed so far: up to t
  const bool both = phase_ == SegPhase::path_overlap;
  kin::JointVector qn(n_);
  if (kin::path_sample_pair(both ? &g : nullptr, both ? seg_of(*next_) : g, tn, path_ahead_, qn) < kin::Status::ok)
    ++ik_fallbacks_;
  for (int j = 0; j < n_; ++j) {
    const double q0 = cmd.pos[j], q1 = path_ahead_[j], q2 = qn[j];
    cmd.pos[j] = q1;
    cmd.vel[j] = (q2 - q0) / (2 * period_s_);
    cmd.acc[j] = (q2 - 2 * q1 + q0) / (period_s_ * period_s_);
  }
  path_ahead_ = qn;
  if (t < g.end()) return Step::running;
  if (!both) return finish(cmd, true);  // the run ends at rest at its target
  retire(false, RtResult::ok);  // its segment is over; the next one has been moving since its start
  running_ = queue_.front();
  phase_ = SegPhase::path_open;
  t_ = 0;
  return Step::running;
}

// ---------------------------------------------------------------------------
// Hold and resume (the rules per phase: hold_rule, resume_rule in mode_table.hpp)
// ---------------------------------------------------------------------------

HoldRule MotionExecutor::hold() {
  bool line_alone = false;
  if (phase_ == SegPhase::path_open || phase_ == SegPhase::path_closed) {
    const kin::PathSegment& g = seg_of(*running_);
    const double u = run_time() - g.start;
    line_alone = g.kind == kin::PathKind::line && u >= 0 && u < g.duration;
    if (line_alone) t_ = u;  // on its line: stops there as a line does
  }
  const HoldRule h = hold_rule(phase_, line_alone);
  if (phase_ == SegPhase::path_overlap) {  // running_'s target was passed (within its tolerance)
    retire(false, RtResult::ok);
    running_ = queue_.front();
  }
  if (h.after == SegPhase::path_line) line_ = &seg_of(*running_).line;
  if (h.mode == Mode::hold_line) kin::stop_movel(*line_, t_);
  if (h.after != SegPhase::dwell) t_ = 0;  // (a dwell's clock stops, and goes on at resume)
  phase_ = h.after;
  return h;
}

bool MotionExecutor::resume(const kin::JointState& cmd) {
  switch (resume_rule(phase_)) {
    case ResumeRule::nothing: return true;
    case ResumeRule::on_line: kin::resume_movel(*line_, t_, 1.0); break;
    case ResumeRule::replan_goal: {
      JointMove& jm = *std::get_if<JointMove>(&running_->payload);
      if (!replan(cmd.pos, jm.goal, jm.override, jm.plan)) {
        retire(true, RtResult::plan_failed);
        return false;
      }
      plan_ = &jm.plan;
      break;
    }
    case ResumeRule::replan_end:
    case ResumeRule::replan_start: {
      // Ramped down off the run: a joint move to the segment's target (or, held in an
      // overlap, back to its start: the corner the blend rounded, within the tolerance).
      const PathMove& pm = *std::get_if<PathMove>(&running_->payload);
      kin::JointVector target = pm.seg.q_end;
      if (phase_ == SegPhase::path_to_start) kin::path_segment_start(pm.seg, n_, target);
      if (!replan(cmd.pos, target, pm.override, resume_plan_)) {
        retire(true, RtResult::plan_failed);
        return false;
      }
      plan_ = &resume_plan_;
      break;
    }
  }
  t_ = 0;
  return true;
}

// ---------------------------------------------------------------------------
// The controller's side: when the executor runs (by mode), feed hold, resume, the events
// ---------------------------------------------------------------------------

void Controller::step_motion() {
  switch (mode_) {
    case Mode::fault_quick_stop:
    case Mode::estop_quick_stop: step_drive_stop(); return;
    case Mode::hold_ramp:
    case Mode::hold_ramp_resume:
    case Mode::stopping_to_idle:
    case Mode::stopping_to_disabled:
    case Mode::fault_ramp:
    case Mode::estop_ramp: step_ramp(); return;  // a stop has priority over everything
    case Mode::boot:
    case Mode::enabling: follow_measured(); return;
    case Mode::disabled:  // after reset, drives without brakes may still hold the arm
      follow_measured();
      watch_hold();
      return;
    case Mode::fault:
    case Mode::estop:
      follow_measured();
      watch_hold();
      return;
    case Mode::jogging: step_jog(); return;
    case Mode::homing:
    case Mode::homing_abort: step_homing(); return;
    case Mode::freedrive:
    case Mode::freedrive_end: step_freedrive(); return;
    case Mode::held:
      // At rest, the segment kept (its phase says how it resumes). A held queue that has
      // not started goes idle once nothing is left of it.
      if (exec_.running() == nullptr && exec_.queue().empty()) set_mode(Mode::idle);
      return;
    case Mode::idle:
      exec_.reset_speed_scale();  // at rest: a new run starts as planned
      if (!exec_.start(cmd_)) return;
      set_mode(Mode::moving);
      break;
    case Mode::moving:
      if (exec_.running() == nullptr && !exec_.start(cmd_)) {
        set_mode(Mode::idle);
        return;
      }
      break;
    case Mode::hold_line:
      if (exec_.running() == nullptr) {  // (cannot happen: entered with a line running)
        set_mode(Mode::held);
        return;
      }
      break;
  }
  // moving or hold_line, a segment running
  switch (exec_.step(mode_, cmd_)) {
    case MotionExecutor::Step::running: return;
    case MotionExecutor::Step::idle: set_mode(Mode::idle); return;
    case MotionExecutor::Step::held: set_mode(Mode::held); return;
  }
}

void Controller::hold_motion(const Request& r) {
  const HoldRule h = exec_.hold();
  if (h.mode == Mode::hold_ramp) begin_ramp(Mode::hold_ramp);  // from the commanded (blended) state, in joint space
  else set_mode(h.mode);
  reply(r.seq, RtResult::ok, "feed hold");
}

void Controller::resume_motion(const Request& r) {
  set_mode(Mode::moving);
  if (!exec_.resume(cmd_)) {
    reply(r.seq, RtResult::plan_failed, "cannot re-plan the interrupted move");
    return;
  }
  reply(r.seq, RtResult::ok, "resumed");
}

void Controller::resume_held() {
  // The resume was answered when it came, during the ramp: what happens at rest is an event.
  set_mode(Mode::moving);
  if (!exec_.resume(cmd_)) {
    emit(EventKind::motion_refused, FaultCause::none, -1, 0, "resume at the end of the hold's ramp: cannot re-plan the interrupted move");
    return;
  }
  emit(EventKind::state, FaultCause::none, -1, 0, "resumed at the end of the hold's ramp");
}

bool Controller::may_move() const { return all_homed(); }

void Controller::segment_started(const MotionItem& m) {
  for (std::uint8_t k = 0; k < m.n_outputs && k < kMotionOutputs; ++k) apply_output(m.outputs[k]);  // M62 / M63
}

void Controller::segment_ended(std::uint32_t id, bool refused, RtResult why) {
  if (refused) {
    char m[96];
    std::snprintf(m, sizeof m, "motion %u refused: %s", unsigned(id), to_string(why));
    emit(EventKind::motion_refused, FaultCause::none, -1, id, m);
  } else {
    done_id_ = id;
    emit(EventKind::motion_done, FaultCause::none, -1, id, "done");
  }
}

}  // namespace servoarm::fw
