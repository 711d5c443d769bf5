// SPDX-License-Identifier: Apache-2.0
// The motion queue on the control thread: starting, sampling, holding and resuming the
// queued motions (joint plans, blended joint runs, lines, path moves, dwells).
#include <cmath>
#include <cstdio>

#include "servoarm/rt/controller.hpp"

namespace servoarm::fw {

// ---------------------------------------------------------------------------
// Motion
// ---------------------------------------------------------------------------

void Controller::finish_motion(bool refused, RtResult why) {
  if (running_ == nullptr) return;
  const std::uint32_t id = running_->id;
  running_ = nullptr;
  motions_.pop();
  if (refused) {
    char m[96];
    std::snprintf(m, sizeof m, "motion %u refused: %s", unsigned(id), to_string(why));
    emit(EventKind::motion_refused, FaultCause::none, -1, id, m);
  } else {
    done_id_ = id;
    emit(EventKind::motion_done, FaultCause::none, -1, id, "done");
  }
}

bool Controller::starts_here(const kin::JointTrajectory& plan) const {
  if (plan.n != n_) return false;
  kin::JointState s0;
  plan.sample(-1.0, s0);  // t < 0: exactly the start state
  for (int j = 0; j < n_; ++j)
    if (s0.pos[j] != cmd_.pos[j] || s0.vel[j] != 0.0 || cmd_.vel[j] != 0.0) return false;
  return true;
}

bool Controller::start_next_motion() {
  while (MotionItem* m = motions_.front()) {
    motion_t_ = 0;
    if (m->kind() != MotionKind::dwell && !all_homed()) {  // (the console refuses these first)
      running_ = m;
      finish_motion(true, RtResult::not_homed);
      continue;
    }
    switch (m->kind()) {
      case MotionKind::joint: {
        JointMove& jm = *std::get_if<JointMove>(&m->payload);
        if (jm.blend > 0.0 && begin_blend(jm)) break;  // the run's first segment (replaces the plan)
        if (starts_here(jm.plan)) break;  // the console's plan, as it is
        kin::MovejOptions o;
        o.override = jm.override;
        ++joint_replans_;
        if (kin::plan_movej(limits_, kin::JointState::rest(cmd_.pos), jm.goal, o, jm.plan) != kin::MotionStatus::ok) {
          running_ = m;
          finish_motion(true, RtResult::plan_failed);
          continue;
        }
        break;
      }
      case MotionKind::cartesian: {
        const kin::CartesianTrajectory& path = std::get_if<CartesianMove>(&m->payload)->path;
        double dev = 0;
        for (int j = 0; j < n_; ++j)
          dev = std::fmax(dev, std::fabs(path.q_knot[0][static_cast<std::size_t>(j)] - cmd_.pos[j]));
        if (dev > 1e-6) {
          running_ = m;
          finish_motion(true, RtResult::start_moved);
          continue;
        }
        break;
      }
      case MotionKind::dwell: break;
      case MotionKind::path:
        if (!begin_path(*m)) {  // a run starts from rest where its first segment does
          running_ = m;
          finish_motion(true, RtResult::start_moved);
          continue;
        }
        break;
    }
    running_ = m;
    for (std::uint8_t k = 0; k < m->n_outputs && k < kMotionOutputs; ++k) apply_output(m->outputs[k]);  // M62 / M63
    return true;
  }
  return false;
}

void Controller::step_motion() {
  switch (mode_) {
    case Mode::fault_quick_stop:
    case Mode::estop_quick_stop: step_drive_stop(); return;
    case Mode::hold_ramp:
    case Mode::stopping_to_idle:
    case Mode::stopping_to_disabled:
    case Mode::fault_ramp:
    case Mode::estop_ramp: step_ramp(); return;  // a stop has priority over everything
    case Mode::boot:
    case Mode::disabled:
    case Mode::enabling:
    case Mode::fault:
    case Mode::estop: follow_measured(); return;
    case Mode::jogging: step_jog(); return;
    case Mode::homing:
    case Mode::homing_abort: step_homing(); return;
    case Mode::freedrive:
    case Mode::freedrive_end: step_freedrive(); return;
    case Mode::held:
      // At rest, the motion kept (joint / dwell / Cartesian stopped on its line). A held
      // queue that has not started goes idle once nothing is left of it.
      if (running_ == nullptr && motions_.empty()) set_mode(Mode::idle);
      return;
    case Mode::idle:
      if (!start_next_motion()) return;
      set_mode(Mode::moving);
      break;
    case Mode::moving:
      if (running_ == nullptr && !start_next_motion()) {
        set_mode(Mode::idle);
        return;
      }
      break;
    case Mode::hold_line:
      if (running_ == nullptr) {  // (cannot happen: entered with a Cartesian move running)
        set_mode(Mode::held);
        return;
      }
      break;
  }
  // moving or hold_line, running_ set
  motion_t_ += period_s_;
  bool done = false;
  switch (running_->kind()) {
    case MotionKind::path: step_path(); return;
    case MotionKind::joint: {
      if (blending_) {
        step_blend();
        return;
      }
      const kin::JointTrajectory& plan = std::get_if<JointMove>(&running_->payload)->plan;
      plan.sample(motion_t_, cmd_);
      done = motion_t_ >= plan.duration;
      break;
    }
    case MotionKind::cartesian: {
      kin::CartesianTrajectory& path = std::get_if<CartesianMove>(&running_->payload)->path;
      // IK at the exact pose; when it fails the precomputed joint value of the path is
      // kept (the console checked the whole path with IK, and validate_and_write checks
      // the setpoint as every other one), and the sample is counted (Telemetry::ik_fallbacks).
      if (path.sample_ik(motion_t_, cmd_.pos, cmd_.vel, cmd_.acc) < kin::Status::ok) ++ik_fallbacks_;
      if (mode_ == Mode::hold_line) {
        if (motion_t_ >= path.duration) {  // at rest on the line
          motion_t_ = path.duration;
          set_mode(Mode::held);
        }
        return;
      }
      done = motion_t_ >= path.duration;
      break;
    }
    case MotionKind::dwell:
      done = motion_t_ >= std::get_if<DwellMove>(&running_->payload)->seconds;
      break;
  }
  if (done) {
    if (running_->kind() != MotionKind::dwell) {
      cmd_.pos = running_->goal();
      cmd_.vel.setZero();
      cmd_.acc.setZero();
    }
    finish_motion(false, RtResult::ok);
    if (start_next_motion()) return;
    set_mode(Mode::idle);
  }
}

// ---------------------------------------------------------------------------
// Blended joint moves (docs/motion.md#blending)
// ---------------------------------------------------------------------------
// Consecutive queued joint moves whose target carries a blend tolerance run as one
// kin::JointBlendQueue: each move one straight joint-space segment, the next one
// superposed on its end as far as the tolerance and every joint's velocity, acceleration
// and jerk limits (scaled by the moves' override) allow, checked exactly by the queue; a
// corner that cannot blend is an exact stop. The next move is appended while the arm
// moves, at most one append per cycle (bounded, heap-free, never earlier than the next
// sample: nothing already commanded changes). A move is done (motion_done) when its
// segment has come to rest; the next one is then running_ (it has been moving since its
// blend began). A run is only entered from rest and ends at rest; a stop, hold, fault,
// e-stop or flush leaves it (end_blend) and the ramp starts from the blended state.

bool Controller::begin_blend(const JointMove& jm) {
  kin::JointLimits l = limits_;
  const double o = jm.override;
  if (!(o >= 0.01 && o <= 1.0)) return false;
  for (int j = 0; j < n_; ++j)
    if (cmd_.vel[j] != 0.0) return false;  // a run starts from rest only
  for (int j = 0; j < n_; ++j) {
    kin::JointDynamics& d = l.dyn[static_cast<std::size_t>(j)];
    d.max_velocity *= o;
    d.max_acceleration *= o * o;
    d.max_jerk *= o * o * o;
  }
  blend_.reset(l, cmd_.pos);
  const kin::BlendStatus st = blend_.append(jm.goal, jm.blend, 0.0);
  if (!kin::is_ok(st) || st == kin::BlendStatus::zero_length) return false;
  blending_ = true;
  blend_closed_ = false;
  blend_items_ = 1;
  blend_t_ = 0;
  blend_override_ = o;
  return true;
}

void Controller::blend_more() {
  if (!blending_ || blend_closed_ || blend_items_ >= kBlendSegments) return;
  const MotionItem* last = motions_.peek(static_cast<std::size_t>(blend_items_ - 1));
  const MotionItem* next = motions_.peek(static_cast<std::size_t>(blend_items_));
  if (last == nullptr || next == nullptr) return;  // nothing queued after it yet: try again next cycle
  const auto* lj = std::get_if<JointMove>(&last->payload);
  const auto* nj = std::get_if<JointMove>(&next->payload);
  if (lj == nullptr || !(lj->blend > 0.0) || nj == nullptr || nj->override != blend_override_ || next->n_outputs != 0) {
    blend_closed_ = true;  // the run ends at rest at `last`; `next` starts from rest as an unblended move
    return;
  }
  kin::BlendReport rep;
  const kin::BlendStatus st = blend_.append(nj->goal, nj->blend, blend_t_ + period_s_, &rep);
  if (!kin::is_ok(st) || st == kin::BlendStatus::zero_length) {
    blend_closed_ = true;
    return;
  }
  if (rep.blend > 0.0) ++blends_;
  ++blend_items_;
}

void Controller::step_blend() {
  blend_more();
  blend_t_ += period_s_;
  blend_.sample(blend_t_, cmd_.pos, cmd_.vel, cmd_.acc);
  const int before = blend_.size();
  blend_.retire(blend_t_);
  for (int ended = before - blend_.size(); ended > 0 && running_ != nullptr; --ended) {
    const bool last = --blend_items_ == 0;
    if (last) {
      cmd_ = kin::JointState::rest(running_->goal());  // the run's end: at rest there
      blending_ = false;
    }
    finish_motion(false, RtResult::ok);
    if (last) {
      if (!start_next_motion()) set_mode(Mode::idle);
      return;
    }
    running_ = motions_.front();  // appended to the run: moving since its blend began
    motion_t_ = 0;
  }
}

void Controller::end_blend() {
  blending_ = false;
  blend_closed_ = false;
  blend_items_ = 0;
}

// ---------------------------------------------------------------------------
// Blended runs (PathMove; docs/motion.md#blending)
// ---------------------------------------------------------------------------
// The console plans each segment (a joint move or a line) alone from rest at the previous
// target and chooses its overlap with the one before it (kin::PathBlendQueue: checks of every
// joint's limits, the tool speed and the corner tolerance, sampled at this rate on the run's
// time base). Here the segments run in place in the motion queue: running_ and, from its
// start time on, the next one (path_next_) when it blends out of running_; the sample is
// their superposition (kin::path_sample_pair: one IK in a line-line overlap, as a movel
// sample). The command's velocity and acceleration are the samples' differences (what a
// stop ramps down from). A segment is done (motion_done) when it has ended; the next is then
// running_. A segment that comes too late to start at its time (the console queued it after
// the run passed it) starts from rest where the one before ends: an exact stop. A stop,
// fault or e-stop ramps down from the blended state; a feed hold: hold_path.

namespace {
const kin::PathSegment& seg_of(const MotionItem& m) { return std::get_if<PathMove>(&m.payload)->seg; }
}  // namespace

bool Controller::begin_path(MotionItem& m) {
  const kin::PathSegment& g = seg_of(m);
  kin::JointVector q0(n_);
  kin::path_segment_start(g, n_, q0);
  for (int j = 0; j < n_; ++j)
    if (std::fabs(q0[j] - cmd_.pos[j]) > 1e-6 || cmd_.vel[j] != 0.0) return false;
  path_phase_ = PathPhase::run;
  path_t0_ = g.start;  // on the console's time base: the overlaps it checked line up
  path_k_ = 0;
  path_next_ = nullptr;
  path_late_ = false;
  path_have_ahead_ = false;
  motion_t_ = 0;
  return true;
}

void Controller::step_path() {
  kin::PathSegment& g = std::get_if<PathMove>(&running_->payload)->seg;
  switch (path_phase_) {
    case PathPhase::line:  // held on its line, resumed: a movel (motion_t_ from the hold)
      if (g.line.sample_ik(motion_t_, cmd_.pos, cmd_.vel, cmd_.acc) < kin::Status::ok) ++ik_fallbacks_;
      if (motion_t_ < g.line.duration) return;
      if (mode_ == Mode::hold_line) {
        motion_t_ = g.line.duration;
        set_mode(Mode::held);
        return;
      }
      break;  // done at rest at its target
    case PathPhase::to_end:
    case PathPhase::to_start:
      resume_plan_.sample(motion_t_, cmd_);
      if (motion_t_ < resume_plan_.duration) return;
      cmd_ = kin::JointState::rest(resume_plan_.goal);
      if (path_phase_ == PathPhase::to_start) {  // at its start: the segment runs from rest as planned
        if (!begin_path(*running_)) {
          end_path();
          finish_motion(true, RtResult::start_moved);
          if (!start_next_motion()) set_mode(Mode::idle);
        }
        return;
      }
      break;  // at its target
    case PathPhase::none:  // (not entered without begin_path)
    case PathPhase::run: {
      // One sample ahead: the setpoint is the sample at t (taken last cycle), its velocity
      // and acceleration central differences with the one at t + dt (what a stop ramps
      // down from, accurate to O(dt^2): the ramp starts without an acceleration step).
      ++path_k_;
      const double t = path_time(), tn = t + period_s_;
      if (!path_have_ahead_) {  // the run's first cycle
        const kin::PathSegment* a0 = path_next_ != nullptr ? &g : nullptr;
        const kin::PathSegment& b0 = path_next_ != nullptr ? seg_of(*path_next_) : g;
        if (kin::path_sample_pair(a0, b0, t, cmd_.pos, path_ahead_) < kin::Status::ok) ++ik_fallbacks_;
        path_have_ahead_ = true;
      }
      if (path_next_ == nullptr && !path_late_) {  // computed so far: up to t
        MotionItem* nx = motions_.peek(1);
        const PathMove* np = nx != nullptr ? std::get_if<PathMove>(&nx->payload) : nullptr;
        if (np != nullptr && np->after == running_->id && nx->n_outputs == 0 && np->seg.start < g.end() - 1e-12) {
          if (!(np->seg.start > t)) path_late_ = true;  // queued after its start time went by
          else if (np->seg.start <= tn) {
            path_next_ = nx;
            ++blends_;
          }
        } else if (nx != nullptr) {
          path_late_ = true;  // what follows does not blend out of this segment: rest at its target
        }
      }
      kin::JointVector qn(n_);
      const kin::PathSegment* a = path_next_ != nullptr ? &g : nullptr;
      const kin::PathSegment& b = path_next_ != nullptr ? seg_of(*path_next_) : g;
      if (kin::path_sample_pair(a, b, tn, path_ahead_, qn) < kin::Status::ok) ++ik_fallbacks_;
      for (int j = 0; j < n_; ++j) {
        const double q0 = cmd_.pos[j], q1 = path_ahead_[j], q2 = qn[j];
        cmd_.pos[j] = q1;
        cmd_.vel[j] = (q2 - q0) / (2 * period_s_);
        cmd_.acc[j] = (q2 - 2 * q1 + q0) / (period_s_ * period_s_);
      }
      path_ahead_ = qn;
      if (t < g.end()) return;
      if (path_next_ != nullptr) {  // its segment is over; the next one has been moving since its start
        finish_motion(false, RtResult::ok);
        running_ = motions_.front();
        path_next_ = nullptr;
        path_late_ = false;
        motion_t_ = 0;
        return;
      }
      break;  // the run ends at rest at its target
    }
  }
  cmd_ = kin::JointState::rest(g.q_end);
  end_path();
  finish_motion(false, RtResult::ok);
  if (!start_next_motion()) set_mode(Mode::idle);
}

void Controller::hold_path() {
  kin::PathSegment& g = std::get_if<PathMove>(&running_->payload)->seg;
  PathPhase after = PathPhase::to_end;
  switch (path_phase_) {
    case PathPhase::line:
      kin::stop_movel(g.line, motion_t_);
      motion_t_ = 0;
      set_mode(Mode::hold_line);
      return;
    case PathPhase::run: {
      if (path_next_ != nullptr) {  // in an overlap: running_'s target was passed (within its tolerance)
        finish_motion(false, RtResult::ok);
        running_ = motions_.front();
        after = PathPhase::to_start;
        break;
      }
      const double u = path_time() - g.start;
      if (g.kind == kin::PathKind::line && u >= 0 && u < g.duration) {  // a line alone: it stops on its line
        kin::stop_movel(g.line, u);
        path_phase_ = PathPhase::line;
        path_next_ = nullptr;
        motion_t_ = 0;
        set_mode(Mode::hold_line);
        return;
      }
      break;
    }
    case PathPhase::to_start: after = PathPhase::to_start; break;
    case PathPhase::to_end:
    case PathPhase::none: break;
  }
  begin_ramp(Mode::hold_ramp);  // (ends the run) from the blended state, in joint space
  path_phase_ = after;          // resume_motion plans the joint move of this phase
  motion_t_ = 0;
}

void Controller::end_path() {
  end_blend();
  path_phase_ = PathPhase::none;
  path_next_ = nullptr;
  path_late_ = false;
}

// ---------------------------------------------------------------------------
// Feed hold and resume of the running motion
// ---------------------------------------------------------------------------

void Controller::hold_motion(const Request& r) {
  if (running_ == nullptr) {
    set_mode(Mode::held);  // between two moves: the rest of the queue is held
  } else {
    switch (running_->kind()) {
      case MotionKind::cartesian:
        kin::stop_movel(std::get_if<CartesianMove>(&running_->payload)->path, motion_t_);  // stops on the line
        motion_t_ = 0;
        set_mode(Mode::hold_line);
        break;
      case MotionKind::joint: begin_ramp(Mode::hold_ramp); break;
      case MotionKind::dwell: set_mode(Mode::held); break;  // the dwell's clock stops
      case MotionKind::path: hold_path(); break;
    }
  }
  reply(r.seq, RtResult::ok, "feed hold");
}

void Controller::resume_motion(const Request& r) {
  set_mode(Mode::moving);
  if (auto* c = running_ ? std::get_if<CartesianMove>(&running_->payload) : nullptr) {
    kin::resume_movel(c->path, motion_t_, 1.0);
    motion_t_ = 0;
  } else if (auto* jm = running_ ? std::get_if<JointMove>(&running_->payload) : nullptr) {
    // The interrupted move ramped down off its plan: plan the rest from where it stopped.
    kin::MovejOptions o;
    o.override = jm->override;
    if (kin::plan_movej(limits_, cmd_, jm->goal, o, jm->plan) != kin::MotionStatus::ok) {
      finish_motion(true, RtResult::plan_failed);
      reply(r.seq, RtResult::plan_failed, "cannot re-plan the interrupted move");
      return;
    }
    motion_t_ = 0;
  } else if (auto* pm = running_ ? std::get_if<PathMove>(&running_->payload) : nullptr) {
    if (path_phase_ == PathPhase::line) {
      kin::resume_movel(pm->seg.line, motion_t_, 1.0);  // on along its line
    } else if (path_phase_ == PathPhase::to_end || path_phase_ == PathPhase::to_start) {
      // Ramped down off the run: a joint move to the segment's target (or, held in an
      // overlap, back to its start: the corner the blend rounded, within the tolerance).
      kin::MovejOptions o;
      o.override = pm->override;
      kin::JointVector target = pm->seg.q_end;
      if (path_phase_ == PathPhase::to_start) kin::path_segment_start(pm->seg, n_, target);
      if (kin::plan_movej(limits_, cmd_, target, o, resume_plan_) != kin::MotionStatus::ok) {
        end_path();
        finish_motion(true, RtResult::plan_failed);
        reply(r.seq, RtResult::plan_failed, "cannot re-plan the interrupted move");
        return;
      }
    }
    motion_t_ = 0;
  }
  reply(r.seq, RtResult::ok, "resumed");
}

}  // namespace servoarm::fw
