// SPDX-License-Identifier: Apache-2.0
#include "servoarm/rt/controller.hpp"

#include <cmath>
#include <cstdio>
#include <cstring>

namespace servoarm::fw {

const char* to_string(FaultCause c) {
  switch (c) {
    case FaultCause::none: return "none";
    case FaultCause::heartbeat_lost: return "heartbeat_lost";
    case FaultCause::drive_fault: return "drive_fault";
    case FaultCause::drive_refused: return "drive_refused";
    case FaultCause::left_enabled: return "left_enabled";
    case FaultCause::emcy: return "emcy";
    case FaultCause::bus_off: return "bus_off";
    case FaultCause::bus_error: return "bus_error";
    case FaultCause::following_error: return "following_error";
    case FaultCause::setpoint_nan: return "setpoint_nan";
    case FaultCause::setpoint_position: return "setpoint_position";
    case FaultCause::setpoint_velocity: return "setpoint_velocity";
    case FaultCause::feedback_invalid: return "feedback_invalid";
    case FaultCause::homing_failed: return "homing_failed";
    case FaultCause::collision: return "collision";
    case FaultCause::over_temperature: return "over_temperature";
    case FaultCause::joint_limit: return "joint_limit";
  }
  return "?";
}

const char* to_string(RtResult r) {
  switch (r) {
    case RtResult::ok: return "ok";
    case RtResult::bad_state: return "bad_state";
    case RtResult::fault: return "fault";
    case RtResult::busy: return "busy";
    case RtResult::start_moved: return "start_moved";
    case RtResult::plan_failed: return "plan_failed";
    case RtResult::not_homed: return "not_homed";
  }
  return "?";
}

const char* to_string(MotionKind k) {
  switch (k) {
    case MotionKind::joint: return "joint";
    case MotionKind::cartesian: return "cartesian";
    case MotionKind::dwell: return "dwell";
    case MotionKind::path: return "path";
  }
  return "?";
}

const char* to_string(EventKind k) {
  switch (k) {
    case EventKind::fault: return "fault";
    case EventKind::estop: return "estop";
    case EventKind::motion_done: return "motion_done";
    case EventKind::motion_refused: return "motion_refused";
    case EventKind::state: return "state";
    case EventKind::jog_stopped: return "jog_stopped";
    case EventKind::homing: return "homing";
    case EventKind::freedrive: return "freedrive";
    case EventKind::warning: return "warning";
  }
  return "?";
}

namespace {
/// "<what>" or "<what>; N queued move(s) dropped".
void dropped_text(char* dst, std::size_t cap, const char* what, std::size_t dropped) {
  if (dropped == 0) std::snprintf(dst, cap, "%s", what);
  else std::snprintf(dst, cap, "%s; %zu queued move%s dropped", what, dropped, dropped == 1 ? "" : "s");
}

void copy_text(char* dst, std::size_t cap, const char* src) {
  std::size_t i = 0;
  for (; src != nullptr && src[i] != '\0' && i + 1 < cap; ++i) dst[i] = src[i];
  dst[i] = '\0';
}
}  // namespace

Controller::Controller(hal::ServoBus& bus, const kin::Chain& chain, const ControllerConfig& cfg)
    : bus_(bus), chain_(chain), cfg_(cfg), limits_(kin::limits_from(chain)), n_(chain.n_joints) {
  period_s_ = 1.0 / cfg_.rate_hz;
  cmd_ = kin::JointState::rest(kin::JointVector::Zero(n_));
  q_act_ = kin::JointVector::Zero(n_);
  q_prev_ = kin::JointVector::Zero(n_);
  jog_.configure(chain_, limits_, period_s_);
  exec_.configure(limits_, n_, period_s_, *this);
  safety_.configure(chain_, cfg_.safety, period_s_);
}

hal::Status Controller::boot(TimePoint now, TimePoint deadline) {
  const hal::Status st = bus_.start(deadline);
  if (st != hal::Status::ok) return st;
  now_ = now;
  zeroed_ = 0;  // the bus's start() unhomed every joint: no zero is assumed from before
  hrunning_ = 0;
  bus_.read(now);
  hold_measured();
  for (int j = 0; j < n_; ++j) emcy_seen_[static_cast<std::size_t>(j)] = bus_.feedback(static_cast<std::size_t>(j)).emcy_count;
  set_mode(Mode::disabled);
  publish();
  flush_replies();
  return st;
}

void Controller::hold_measured() {
  for (int j = 0; j < n_; ++j) {
    const auto& fb = bus_.feedback(static_cast<std::size_t>(j));
    q_act_[j] = fb.valid ? fb.position : q_act_[j];
  }
  cmd_ = kin::JointState::rest(q_act_);
  have_prev_ = false;
  ++generation_;
}

std::size_t Controller::flush_motions() {
  const std::size_t n = exec_.flush();
  ++generation_;
  return n;
}

void Controller::reply(std::uint32_t seq, RtResult res, const char* msg) {
  if (seq == 0) return;  // the controller's own request (the e-stop input): no one waits for it
  if (n_pending_ >= static_cast<int>(pending_replies_.size())) return;  // cannot happen: <= 4 requests per cycle
  Reply& r = pending_replies_[static_cast<std::size_t>(n_pending_++)];
  r.seq = seq;
  r.result = res;
  copy_text(r.message, sizeof r.message, msg);
}

void Controller::flush_replies() {
  for (int i = 0; i < n_pending_; ++i)
    if (!replies_.push(pending_replies_[static_cast<std::size_t>(i)])) break;  // console stopped reading: it times out
  n_pending_ = 0;
}

void Controller::emit(EventKind k, FaultCause c, int joint, std::uint32_t id, const char* msg) {
  Event* e = events_.back();
  if (e == nullptr) {
    events_dropped_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  e->kind = k;
  e->state = arm_state(mode_);
  e->cause = c;
  e->joint = static_cast<std::int8_t>(joint);
  e->motion_id = id;
  copy_text(e->message, sizeof e->message, msg);
  events_.commit();
}

void Controller::set_mode(Mode m) {
  if (m == mode_) return;
  if (mode_ == Mode::jogging) {
    jog_.reset();  // whatever ends the jogging mode ends the jog
    ++generation_;  // and the arm is not where the console's last queued move left it
  }
  if (mode_ == Mode::freedrive && model_ != nullptr) {
    // Whatever ends free-drive (off, stop, a fault, e-stop, disable) takes every drive back to
    // CSP holding where it stands, from this cycle's write (the bus does it by itself on faults,
    // disable and quick stop too); the arm was moved by hand.
    model_->freedrive_leave();
    ++generation_;
  }
  mode_ = m;
  mode_since_ = now_;
}

void Controller::record_timing(std::int64_t latency_ns, std::int64_t compute_ns, std::uint32_t missed_deadlines) {
  latency_.add(latency_ns);
  compute_.add(compute_ns);
  overruns_ += missed_deadlines;
}

// ---------------------------------------------------------------------------
// Stops: the controller's ramp, the drives' quick stop, powering down
// ---------------------------------------------------------------------------

void Controller::power_down(Mode m) {
  bus_.disable();
  set_mode(m);
}

// A ramp has brought the arm to rest (or none could be planned): where each ramping mode goes.
void Controller::end_of_ramp(Mode ramp) {
  cmd_ = kin::JointState::rest(cmd_.pos);
  switch (ramp) {
    case Mode::hold_ramp: set_mode(Mode::held); return;  // at rest, the motion kept
    case Mode::hold_ramp_resume: resume_held(); return;
    case Mode::stopping_to_idle: set_mode(Mode::idle); return;
    case Mode::stopping_to_disabled: power_down(Mode::disabled); return;
    case Mode::fault_ramp:
    case Mode::estop_ramp:
      if (bus_.quick_stop_holds()) {  // drives without brakes (MIT motors) hold where the ramp ended
        bus_.quick_stop();
        stop_t_ = 0;
        set_mode(ramp == Mode::estop_ramp ? Mode::estop_quick_stop : Mode::fault_quick_stop);
        return;
      }
      power_down(ramp == Mode::estop_ramp ? Mode::estop : Mode::fault);
      return;
    case Mode::boot:
    case Mode::disabled:
    case Mode::enabling:
    case Mode::idle:
    case Mode::moving:
    case Mode::hold_line:
    case Mode::held:
    case Mode::fault_quick_stop:
    case Mode::fault:
    case Mode::estop_quick_stop:
    case Mode::estop:
    case Mode::jogging:
    case Mode::homing:
    case Mode::homing_abort:
    case Mode::freedrive:
    case Mode::freedrive_end: return;  // not a ramp
  }
}

void Controller::begin_ramp(Mode ramp) {
  // A stop always wins: the ramp starts from the commanded (blended) state; the queue was
  // flushed before (stop, disable, fault, e-stop) or the hold kept the segment (hold_rule).
  // Ramp every joint to rest from the commanded state with the full limits.
  kin::MovejOptions o;
  if (kin::plan_stop(limits_, cmd_, o, stop_traj_) == kin::MotionStatus::ok) {
    stop_t_ = 0;
    set_mode(ramp);
  } else {
    end_of_ramp(ramp);  // cannot plan (never seen): at rest where the command is
  }
}

void Controller::begin_emergency_stop(Mode ramp, Mode quick_stop) {
  if (!cfg_.drive_quick_stop) {
    begin_ramp(ramp);
    return;
  }
  // CiA 402 Quick Stop to every drive in this cycle's RPDOs; they ramp down themselves.
  bus_.quick_stop();
  stop_t_ = 0;
  set_mode(quick_stop);
}

void Controller::step_ramp() {
  stop_t_ += period_s_;
  stop_traj_.sample(stop_t_, cmd_);
  if (stop_t_ >= stop_traj_.duration) end_of_ramp(mode_);
}

// The drives stop on their own ramps: follow their measured positions (so the
// setpoints never pull against the ramp and enabling later never jumps); power
// down once none is powered any more (`stopping`: operation enabled on its way down,
// or quick stop active with speed; `enabled`), or at the timeout.
void Controller::step_drive_stop() {
  stop_t_ += period_s_;
  bool moving = false, held = false;
  for (int j = 0; j < n_; ++j) {
    const auto& fb = bus_.feedback(static_cast<std::size_t>(j));
    if (fb.valid) cmd_.pos[j] = fb.position;
    const bool holds = bus_.holding(static_cast<std::size_t>(j));  // at rest, held powered (no brakes)
    held = held || holds;
    if ((fb.state == hal::JointState::stopping || fb.state == hal::JointState::enabled) && !holds) moving = true;
  }
  cmd_.vel.setZero();
  cmd_.acc.setZero();
  brake_holding_drives();
  if (moving && stop_t_ < cfg_.drive_stop_timeout) return;
  const Mode latched = mode_ == Mode::estop_quick_stop ? Mode::estop : Mode::fault;
  if (held) {  // the drives hold the arm where it came to rest (watch_hold)
    if (moving) power_down_moving_holds();  // at the timeout: the joints still moving, alone
    stop_t_ = 0;
    set_mode(latched);
  } else {
    power_down(latched);
  }
}

// Drives that hold after a quick stop (no brakes): a joint that does not come to rest, or is
// driven out of its hold, is powered down alone; the others keep holding the arm, which would
// fall if they were powered down too.
void Controller::power_down_moving_holds() {
  for (int j = 0; j < n_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    const auto st = bus_.feedback(ju).state;
    if ((st == hal::JointState::stopping || st == hal::JointState::enabled) && !bus_.holding(ju)) bus_.disable_joint(ju);
  }
}

// Drives that hold the arm after a quick stop (ServoBus::quick_stop_holds: MIT motors) brake on
// the damping of their hold frame alone, which takes a heavy joint seconds (its inertia over the
// frame's largest kd). The torque feed-forward of this cycle's setpoint (the model, when it runs:
// dynamics.feed_forward = "torque") then carries the torque that brakes each joint on its
// acceleration limit: the setpoint is the measured state with qdd = -qd / kBrakeTime, at most
// the limit, so the torque is M(q) qdd + c(q, qd) + g(q); near rest it is a velocity loop of
// time constant kBrakeTime on the model's inertia, and once the joint is held it damps the hold.
// A joint powered down brakes on nothing: 0 there.
// Drives in a CiA 402 quick stop follow their own ramp and ignore the offsets.
void Controller::brake_holding_drives() {
  if (!bus_.quick_stop_holds()) return;
  bool any = false;  // no joint powered (disabled after a disable): the setpoint stays at rest
  for (int j = 0; j < n_ && !any; ++j) {
    const auto st = bus_.feedback(static_cast<std::size_t>(j)).state;
    any = st == hal::JointState::stopping || st == hal::JointState::enabled;
  }
  if (!any) return;
  constexpr double kBrakeTime = 0.05;  // s
  for (int j = 0; j < n_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    const auto& fb = bus_.feedback(ju);
    const double v = fb.valid && std::isfinite(fb.velocity) ? fb.velocity : 0.0;
    const bool powered = fb.state == hal::JointState::stopping || fb.state == hal::JointState::enabled;
    cmd_.vel[j] = v;
    cmd_.acc[j] = powered ? -std::copysign(std::min(limits_.dyn[ju].max_acceleration, std::fabs(v) / kBrakeTime), v) : 0.0;
  }
}

// Latched fault / e-stop whose drives hold the arm (ServoBus::quick_stop_holds): a joint driven
// out of its hold (pushed beyond the motor's torque) for safety.drive_stop_timeout_s is powered
// down (that joint alone), as a stop that does not come to rest is.
void Controller::watch_hold() {
  if (!bus_.quick_stop_holds()) return;
  brake_holding_drives();
  bool moving = false;
  for (int j = 0; j < n_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    if (bus_.feedback(ju).state == hal::JointState::stopping && !bus_.holding(ju)) moving = true;
  }
  stop_t_ = moving ? stop_t_ + period_s_ : 0;
  if (stop_t_ < cfg_.drive_stop_timeout) return;
  power_down_moving_holds();
  stop_t_ = 0;
}

void Controller::raise_fault(FaultCause c, int joint, const char* detail) {
  enum class Reaction { latched, emergency_stop, at_rest };
  Reaction how = Reaction::at_rest;
  switch (mode_) {
    case Mode::fault_ramp:
    case Mode::fault_quick_stop:
    case Mode::fault: how = Reaction::latched; break;  // first cause wins
    case Mode::enabling:
    case Mode::idle:
    case Mode::moving:
    case Mode::hold_ramp:
    case Mode::hold_ramp_resume:
    case Mode::hold_line:
    case Mode::held:
    case Mode::stopping_to_idle:
    case Mode::stopping_to_disabled:
    case Mode::jogging:
    case Mode::freedrive:      // every drive back to CSP where it stands (set_mode), then the reaction
    case Mode::freedrive_end: how = Reaction::emergency_stop; break;
    case Mode::boot:
    case Mode::disabled:
    case Mode::estop_ramp:        // a fault during an e-stop powers down at once
    case Mode::estop_quick_stop:
    case Mode::estop: how = Reaction::at_rest; break;
    case Mode::homing:        // the drives move the homed joints: homing is aborted, the drives powered down
    case Mode::homing_abort: how = Reaction::at_rest; break;
  }
  if (how == Reaction::latched) return;
  if (hrunning_ != 0) {
    abort_running_homing();
    hrunning_ = 0;
  }
  cause_ = c;
  fault_joint_ = joint;
  if (joint >= 0)
    std::snprintf(fault_text_, sizeof fault_text_, "joint %d %s%s%s", joint + 1, to_string(c), detail[0] ? ": " : "",
                  detail);
  else
    std::snprintf(fault_text_, sizeof fault_text_, "%s%s%s", to_string(c), detail[0] ? ": " : "", detail);
  const std::size_t dropped = flush_motions();
  if (how == Reaction::emergency_stop) begin_emergency_stop(Mode::fault_ramp, Mode::fault_quick_stop);
  else power_down(Mode::fault);
  emit(EventKind::fault, c, joint, 0, fault_text_);
  if (dropped > 0) {
    char d[sizeof(Event::message)];
    std::snprintf(d, sizeof d, "%zu queued move%s dropped: arm is fault", dropped, dropped == 1 ? "" : "s");
    emit(EventKind::motion_refused, FaultCause::none, -1, 0, d);
  }
}

// ---------------------------------------------------------------------------
// Supervisor
// ---------------------------------------------------------------------------

void Controller::supervise(TimePoint now) {
  (void)now;
  // What is watched: everything while the drives are powered for normal work; live
  // feedback while enabling; nothing that latches in boot / disabled (a drive fault or
  // lost heartbeat is shown in `status` and cleared by the next enable, which faults
  // again if the cause persists) nor during / after a fault or e-stop reaction.
  enum class Watch { nothing, enabling, all };
  Watch w = Watch::nothing;
  switch (mode_) {
    case Mode::boot:
    case Mode::disabled:
    case Mode::fault_ramp:
    case Mode::fault_quick_stop:
    case Mode::fault:
    case Mode::estop_ramp:
    case Mode::estop_quick_stop:
    case Mode::estop: w = Watch::nothing; break;
    case Mode::enabling: w = Watch::enabling; break;
    case Mode::idle:
    case Mode::moving:
    case Mode::hold_ramp:
    case Mode::hold_ramp_resume:
    case Mode::hold_line:
    case Mode::held:
    case Mode::stopping_to_idle:
    case Mode::stopping_to_disabled:
    case Mode::jogging:
    case Mode::homing:
    case Mode::homing_abort:
    case Mode::freedrive:
    case Mode::freedrive_end: w = Watch::all; break;
  }
  const bool all_checks = w == Watch::all;
  for (int j = 0; j < n_; ++j) {
    const auto& fb = bus_.feedback(static_cast<std::size_t>(j));
    char d[64];
    if (fb.emcy_count != emcy_seen_[static_cast<std::size_t>(j)]) {
      emcy_seen_[static_cast<std::size_t>(j)] = fb.emcy_count;
      // While enabling, the fault reset itself produces EMCY "error reset" frames;
      // a real error there also puts the drive in fault, which is caught below.
      if (all_checks && fb.error_code != 0) {
        std::snprintf(d, sizeof d, "EMCY 0x%04X", unsigned(fb.error_code));
        raise_fault(FaultCause::emcy, j, d);
        return;
      }
    }
    if (w == Watch::nothing) continue;
    if (fb.state == hal::JointState::fault) {
      FaultCause c = FaultCause::drive_fault;
      switch (fb.fault) {
        case hal::Status::heartbeat_lost: c = FaultCause::heartbeat_lost; break;
        case hal::Status::drive_refused: c = FaultCause::drive_refused; break;
        case hal::Status::drive_fault: c = FaultCause::drive_fault; break;
        case hal::Status::bus_off: c = FaultCause::bus_off; break;
        case hal::Status::ok:
        case hal::Status::timeout:
        case hal::Status::would_block:
        case hal::Status::error_passive:
        case hal::Status::invalid_argument:
        case hal::Status::io_error:
        case hal::Status::interface_down:
        case hal::Status::not_open:
        case hal::Status::sdo_abort:
        case hal::Status::protocol_error:
        case hal::Status::not_configured:
        case hal::Status::capacity:
        case hal::Status::not_supported:
        case hal::Status::aborted:
        case hal::Status::homing_error:
        case hal::Status::bad_state: c = FaultCause::bus_error; break;
      }
      if (fb.fault == hal::Status::drive_fault && fb.has_temperature && fb.temperature >= fb.temperature_limit) {
        char t[96];
        std::snprintf(t, sizeof t, "%.0f deg C, at or above its limit %.0f deg C (the motor's own cut-off %.0f deg C)",
                      fb.temperature, fb.temperature_limit, fb.temperature_cutoff);
        raise_fault(FaultCause::over_temperature, j, t);
        return;
      }
      std::snprintf(d, sizeof d, "%s, error code 0x%04X", hal::to_string(fb.fault), unsigned(fb.error_code));
      raise_fault(c, j, d);
      return;
    }
    if (all_checks && fb.state != hal::JointState::enabled) {
      std::snprintf(d, sizeof d, "drive now %s", hal::to_string(fb.state));
      raise_fault(FaultCause::left_enabled, j, d);
      return;
    }
    // Enabling needs live drives too: a drive that has been talking and went quiet faults
    // the enable (one that has not sent feedback yet since start is waited for, above).
    const bool watched = all_checks || (w == Watch::enabling && fb.valid);
    if (all_checks && !fb.valid) {
      raise_fault(FaultCause::feedback_invalid, j, "no position feedback");
      return;
    }
    if (watched && static_cast<double>(fb.age) * 1e-9 > cfg_.feedback_timeout) {
      std::snprintf(d, sizeof d, "no position feedback for %.1f ms", static_cast<double>(fb.age) * 1e-6);
      raise_fault(FaultCause::feedback_invalid, j, d);
      return;
    }
    const bool master_moves = (hrunning_ >> j) & 1u;  // homing: no setpoint of ours to follow
    if (all_checks && cfg_.check_following_error && have_prev_ && !master_moves) {
      const double e = std::fabs(q_prev_[j] - fb.position);
      if (e > max_follow_) max_follow_ = e;
      if (e > cfg_.following_error) {
        // In the joint's SI unit, with as many digits as it takes for the excess to show
        // (0.0009123 rad > limit 0.0009 rad, never "0.0009 > limit 0.0009").
        const char* u = chain_.joint(j).type == kin::JointType::prismatic ? "m" : "rad";
        int digits = 4;
        char a[24], b[24];
        for (;; ++digits) {
          std::snprintf(a, sizeof a, "%.*g", digits, e);
          std::snprintf(b, sizeof b, "%.*g", digits, cfg_.following_error);
          if (std::strcmp(a, b) != 0 || digits >= 12) break;
        }
        std::snprintf(d, sizeof d, "%s %s > limit %s %s", a, u, b, u);
        raise_fault(FaultCause::following_error, j, d);
        return;
      }
    }
  }
  if (model_ != nullptr) {
    // Collision detection: the momentum observer on this cycle's feedback, watched
    // while the drives follow our setpoints (not homing; ModelControl leaves out free-drive and
    // joints not enabled, and starts again afresh after any of them). On a verdict the arm stops
    // where it is (not along the ramp of the commanded motion, which would push on into what it
    // hit): the setpoint becomes the measured pose, then the fault reaction.
    const bool watch = all_checks && hrunning_ == 0 && mode_ != Mode::homing && mode_ != Mode::homing_abort;
    kin::CollisionVerdict v;
    if (model_->observe(watch, period_s_, v)) {
      char d[96];
      model_->describe_collision(v, d, sizeof d);
      cmd_ = kin::JointState::rest(q_act_);
      have_prev_ = false;
      raise_fault(FaultCause::collision, v.joint, d);
      return;
    }
  }
  if (w == Watch::enabling) {
    // Enabled = every drive operation enabled (the bus reports that only with a heartbeat
    // within its consumer time) and every drive's position feedback valid and fresh.
    bool all = true;
    for (int j = 0; j < n_; ++j) all = all && bus_.feedback(static_cast<std::size_t>(j)).state == hal::JointState::enabled;
    bool fresh = true;
    for (int j = 0; j < n_; ++j) fresh = fresh && bus_.feedback(static_cast<std::size_t>(j)).valid;
    if (all && fresh) {
      hold_measured();
      set_mode(Mode::idle);
      emit(EventKind::state, FaultCause::none, -1, 0, "enabled");
    } else if (static_cast<double>(now_ - mode_since_) * 1e-9 > cfg_.enable_timeout) {
      for (int j = 0; j < n_; ++j)
        if (bus_.feedback(static_cast<std::size_t>(j)).state != hal::JointState::enabled) {
          raise_fault(FaultCause::drive_refused, j, "not operation enabled within enable_timeout");
          return;
        }
      for (int j = 0; j < n_; ++j)
        if (!bus_.feedback(static_cast<std::size_t>(j)).valid) {
          raise_fault(FaultCause::feedback_invalid, j, "no position feedback within enable_timeout");
          return;
        }
    }
  }
}

void Controller::watch_temperatures() {
  for (int j = 0; j < n_; ++j) {
    const auto& fb = bus_.feedback(static_cast<std::size_t>(j));
    const auto bit = static_cast<std::uint16_t>(1u << j);
    const bool hot = fb.has_temperature && fb.temperature >= fb.temperature_warning;
    if (hot && (hot_ & bit) == 0) {
      char m[sizeof(Event::message)];
      std::snprintf(m, sizeof m, "joint %d at %.0f deg C: over-temperature warning (from %.0f deg C; the arm stops at %.0f)",
                    j + 1, fb.temperature, fb.temperature_warning, fb.temperature_limit);
      emit(EventKind::warning, FaultCause::none, j, 0, m);
    }
    hot_ = static_cast<std::uint16_t>(hot ? hot_ | bit : hot_ & ~bit);
  }
}

// ---------------------------------------------------------------------------
// Requests: one (mode x request) table (mode_table.hpp), one small action each
// ---------------------------------------------------------------------------

void Controller::handle_request(const Request& r, TimePoint now) { run(action_for(mode_, r.op), r, now); }

void Controller::run(Action a, const Request& r, TimePoint now) {
  char m[sizeof(Reply::message)];
  switch (a) {
    // enable
    case Action::power_up: power_up(r); return;
    case Action::already_enabled: reply(r.seq, RtResult::ok, "already enabled"); return;
    case Action::refuse_stopping: reply(r.seq, RtResult::bad_state, "stopping; retry"); return;
    case Action::refuse_not_started: reply(r.seq, RtResult::bad_state, "drives not started"); return;
    case Action::refuse_send_reset:
      std::snprintf(m, sizeof m, "in %s: send reset first", to_string(arm_state(mode_)));
      reply(r.seq, RtResult::fault, m);
      return;
    // disable
    case Action::disable_now: disable_now(r); return;
    case Action::disable_drives:  // boot / fault / estop: the mode (and a running reaction) stays
      flush_motions();
      bus_.disable();
      reply(r.seq, RtResult::ok, "drives disabled");
      return;
    case Action::ramp_then_disable:
      flush_motions();
      begin_ramp(Mode::stopping_to_disabled);
      reply(r.seq, RtResult::ok, "stopping, then disabling");
      return;
    case Action::keep_ramp_then_disable:
      flush_motions();
      set_mode(Mode::stopping_to_disabled);
      reply(r.seq, RtResult::ok, "stopping, then disabling");
      return;
    // stop
    case Action::ramp_to_idle:
      flush_motions();
      begin_ramp(Mode::stopping_to_idle);
      reply(r.seq, RtResult::ok, "stopping");
      return;
    case Action::keep_ramp_to_idle:
      flush_motions();
      set_mode(Mode::stopping_to_idle);
      reply(r.seq, RtResult::ok, "stopping");
      return;
    case Action::drop_queue:
      // Not moving yet, but a move queued in this same cycle would start at the next one.
      dropped_text(m, sizeof m, arm_state(mode_) == ArmState::stopping ? "stopping" : "not moving", flush_motions());
      reply(r.seq, RtResult::ok, m);
      return;
    // estop: acts in this cycle
    case Action::estop_stop: {
      const std::size_t dropped = begin_estop(now);
      begin_emergency_stop(Mode::estop_ramp, Mode::estop_quick_stop);
      estop_done(r, dropped);
      return;
    }
    case Action::estop_keep_ramp: {  // the running ramp goes on; in drive mode the drives take over
      const std::size_t dropped = begin_estop(now);
      if (cfg_.drive_quick_stop) begin_emergency_stop(Mode::estop_ramp, Mode::estop_quick_stop);
      else set_mode(Mode::estop_ramp);
      estop_done(r, dropped);
      return;
    }
    case Action::estop_keep_quick_stop: {
      const std::size_t dropped = begin_estop(now);
      set_mode(Mode::estop_quick_stop);
      estop_done(r, dropped);
      return;
    }
    case Action::estop_at_rest: {
      const std::size_t dropped = begin_estop(now);
      power_down(Mode::estop);
      estop_done(r, dropped);
      return;
    }
    case Action::estop_again: reply(r.seq, RtResult::ok, "estop"); return;
    // reset
    case Action::reset_latched: reset_latched(r); return;
    case Action::refuse_still_stopping:
      reply(r.seq, RtResult::bad_state, "still stopping; retry when the arm is at rest");
      return;
    case Action::nothing_to_reset: reply(r.seq, RtResult::ok, "nothing to reset"); return;
    // hold
    case Action::hold_motion: hold_motion(r); return;
    case Action::hold_queue:
      // Moves queued but not started (GRBL Hold with a planned queue): hold the queue;
      // `resume` / '~' starts it, `stop` drops it.
      if (exec_.queue().empty()) {
        reply(r.seq, RtResult::ok, "not moving");
        return;
      }
      set_mode(Mode::held);
      reply(r.seq, RtResult::ok, "feed hold (queue held)");
      return;
    case Action::already_holding: reply(r.seq, RtResult::ok, "already holding"); return;
    case Action::hold_drops_resume:
      set_mode(Mode::hold_ramp);
      reply(r.seq, RtResult::ok, "feed hold");
      return;
    case Action::not_moving: reply(r.seq, RtResult::ok, "not moving"); return;
    // resume
    case Action::resume_motion: resume_motion(r); return;
    case Action::resume_after_ramp:
      set_mode(Mode::hold_ramp_resume);  // the ramp goes on (the same stop trajectory)
      reply(r.seq, RtResult::ok, "resumes when the hold's ramp ends");
      return;
    case Action::not_holding: reply(r.seq, RtResult::ok, "not holding"); return;
    // set_zero
    case Action::set_zero: set_zero(r); return;
    case Action::refuse_set_zero:
      std::snprintf(m, sizeof m, "home zero needs the arm disabled (it is %s)", to_string(arm_state(mode_)));
      reply(r.seq, RtResult::bad_state, m);
      return;
    // jog
    case Action::start_jog:
      if (!exec_.queue().empty()) {  // queued in this same cycle: the move goes first, the jog is refused
        reply(r.seq, RtResult::busy, "moves are queued: jog refused");
        return;
      }
      [[fallthrough]];
    case Action::update_jog: {
      const char* why = "";
      const std::uint16_t unhomed = static_cast<std::uint16_t>(all_joints() & ~homed_mask());
      if (unhomed != 0 && r.jog.space == JogSpace::tool) {
        char j[48];
        joints_text(j, sizeof j, unhomed);
        std::snprintf(m, sizeof m, "tool jog refused: %s not homed (home first; joint jogs run at %.0f %%)", j,
                      100.0 * cfg_.unhomed_jog_scale);
        reply(r.seq, RtResult::not_homed, m);
        return;
      }
      Request slow = r;  // an unhomed arm jogs its joints at the reduced speed only
      if (unhomed != 0) slow.jog.override = std::fmax(0.01, r.jog.override * cfg_.unhomed_jog_scale);
      update_jog_cap();  // the plan within the safety envelope's speed limits
      if (!jog_.set(slow.jog, cmd_, now, why)) {
        std::snprintf(m, sizeof m, "jog refused: %s", why);
        reply(r.seq, RtResult::bad_state, m);
        return;
      }
      if (a == Action::start_jog) ++generation_;  // the setpoint leaves the queue's end: the console re-reads it
      set_mode(Mode::jogging);
      reply(r.seq, RtResult::ok, a == Action::start_jog ? "jogging" : "jog retargeted");
      return;
    }
    case Action::refuse_jog_moving:
      reply(r.seq, RtResult::busy, "a move is running (or held): jog refused");
      return;
    case Action::refuse_jog_not_enabled:
      std::snprintf(m, sizeof m, "jog needs the arm enabled (it is %s)", to_string(arm_state(mode_)));
      reply(r.seq, RtResult::bad_state, m);
      return;
    case Action::cancel_jog:
      jog_.stop(cmd_);
      reply(r.seq, RtResult::ok, "jog cancelled");
      return;
    case Action::not_jogging: reply(r.seq, RtResult::ok, "not jogging"); return;
    case Action::refresh_jog:
      jog_.refresh(now);
      reply(r.seq, RtResult::ok, "jog refreshed");
      return;
    // home
    case Action::start_homing: start_homing(r); return;
    case Action::refuse_home_not_enabled:
      std::snprintf(m, sizeof m, "home needs the arm enabled (it is %s)", to_string(arm_state(mode_)));
      reply(r.seq, RtResult::bad_state, m);
      return;
    case Action::refuse_home_moving:
      reply(r.seq, RtResult::busy, "a move or jog is running (or held): home refused");
      return;
    case Action::refuse_homing:
      reply(r.seq, RtResult::busy, "homing runs: stop it first (stop, !, Ctrl-X)");
      return;
    // stop / hold / disable / estop while homing
    case Action::abort_homing: {
      char j[48];
      joints_text(j, sizeof j, hrunning_);
      flush_motions();
      abort_running_homing();
      set_mode(Mode::homing_abort);
      std::snprintf(m, sizeof m, "homing aborted: %s left unhomed", hrunning_ ? j : "no joint");
      emit(EventKind::homing, FaultCause::none, -1, 0, m);
      reply(r.seq, RtResult::ok, m);
      return;
    }
    case Action::abort_homing_disable:
      flush_motions();
      abort_running_homing();
      hrunning_ = 0;
      power_down(Mode::disabled);
      hold_measured();
      emit(EventKind::homing, FaultCause::none, -1, 0, "homing aborted: disabled");
      reply(r.seq, RtResult::ok, "homing aborted; disabled");
      return;
    // free-drive
    case Action::start_freedrive: start_freedrive(r); return;
    case Action::already_freedrive: reply(r.seq, RtResult::ok, "free-drive on"); return;
    case Action::refuse_freedrive_not_enabled:
      std::snprintf(m, sizeof m, "freedrive needs the arm enabled (it is %s)", to_string(arm_state(mode_)));
      reply(r.seq, RtResult::bad_state, m);
      return;
    case Action::refuse_freedrive_busy:
      reply(r.seq, RtResult::busy, "a move, jog or homing is running (or held): freedrive refused");
      return;
    case Action::end_freedrive:
      set_mode(Mode::freedrive_end);  // (set_mode: every drive back to CSP where it stands)
      reply(r.seq, RtResult::ok, "free-drive off: holding where it stands");
      return;
    case Action::not_in_freedrive:
      reply(r.seq, RtResult::ok, mode_ == Mode::freedrive_end ? "free-drive ending" : "free-drive off");
      return;
    case Action::estop_abort_homing: {
      const std::size_t dropped = begin_estop(now);
      abort_running_homing();
      hrunning_ = 0;
      power_down(Mode::estop);
      emit(EventKind::homing, FaultCause::none, -1, 0, "homing aborted: emergency stop");
      estop_done(r, dropped);
      return;
    }
  }
}

void Controller::power_up(const Request& r) {
  // Never power up on a drive's last known state: every drive must be talking now
  // (position feedback younger than feedback_timeout; heartbeats are checked by the
  // bus, which reports a joint enabled only with a heartbeat within its consumer time).
  char m[sizeof(Reply::message)];
  for (int j = 0; j < n_; ++j) {
    const auto& fb = bus_.feedback(static_cast<std::size_t>(j));
    // (no feedback at all yet, just after start: the enabling mode waits for it)
    if (!fb.valid || static_cast<double>(fb.age) * 1e-9 <= cfg_.feedback_timeout) continue;
    char d[64];
    std::snprintf(d, sizeof d, "no position feedback for %.1f ms", static_cast<double>(fb.age) * 1e-6);
    raise_fault(FaultCause::feedback_invalid, j, d);
    std::snprintf(m, sizeof m, "enable failed: %s", fault_text_);
    reply(r.seq, RtResult::fault, m);
    return;
  }
  flush_motions();  // a move queued before the arm was disabled never starts
  for (int j = 0; j < n_; ++j) emcy_seen_[static_cast<std::size_t>(j)] = bus_.feedback(static_cast<std::size_t>(j)).emcy_count;
  bus_.enable();
  hold_measured();
  set_mode(Mode::enabling);
  reply(r.seq, RtResult::ok, "enabling");
}

void Controller::disable_now(const Request& r) {
  // Moves queued but not started yet (same cycle as this request) are dropped too.
  char m[sizeof(Reply::message)];
  const std::size_t dropped = flush_motions();
  power_down(Mode::disabled);
  hold_measured();
  dropped_text(m, sizeof m, "disabled", dropped);
  reply(r.seq, RtResult::ok, m);
}

std::size_t Controller::begin_estop(TimePoint now) {
  estop_seen_ = now;
  return flush_motions();
}

void Controller::estop_done(const Request& r, std::size_t dropped) {
  char m[sizeof(Reply::message)];
  emit(EventKind::estop, FaultCause::none, -1, 0, estop_why_ != nullptr ? estop_why_ : "emergency stop");
  dropped_text(m, sizeof m, "estop", dropped);
  reply(r.seq, RtResult::ok, m);
}

void Controller::reset_latched(const Request& r) {
  // Drives that hold the arm after a quick stop (no brakes: MIT motors) go on holding it until
  // the next enable (back to the setpoints) or disable: powered down here, a heavy arm would fall
  // between reset and enable. A joint not held at rest is powered down (as at the timeout).
  bool holds = false;
  if (bus_.quick_stop_holds()) {
    for (int j = 0; j < n_; ++j) holds = holds || bus_.holding(static_cast<std::size_t>(j));
  }
  if (holds) power_down_moving_holds();
  else bus_.disable();
  cause_ = FaultCause::none;
  fault_joint_ = -1;
  fault_text_[0] = '\0';
  max_follow_ = 0;
  hold_measured();
  set_mode(Mode::disabled);
  reply(r.seq, RtResult::ok,
        holds ? "reset; the motors hold the arm until enable (disable powers them down)" : "reset; drives disabled, send enable");
}

void Controller::set_zero(const Request& r) {
  char m[sizeof(Reply::message)];
  // Check every joint before touching any, so the request applies to all or none.
  for (int j = 0; j < n_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    const hal::JointFeedback& fb = bus_.feedback(ju);
    if (fb.state != hal::JointState::disabled || !fb.valid) {
      std::snprintf(m, sizeof m, "joint %d: drive is %s%s, not disabled", j + 1, hal::to_string(fb.state),
                    fb.valid ? "" : " (no position feedback)");
      reply(r.seq, RtResult::bad_state, m);
      return;
    }
    if (!(limits_.lower[ju] <= 0.0 && 0.0 <= limits_.upper[ju])) {
      std::snprintf(m, sizeof m, "joint %d: zero lies outside its limits", j + 1);
      reply(r.seq, RtResult::bad_state, m);
      return;
    }
  }
  int len = std::snprintf(m, sizeof m, "zero_offset = [");
  for (int j = 0; j < n_; ++j) {
    const hal::Status st = bus_.set_position_zero(static_cast<std::size_t>(j));
    if (st != hal::Status::ok) {  // not_supported: nothing was changed (first joint), else a bug
      std::snprintf(m, sizeof m, "joint %d: %s", j + 1, hal::describe(st));
      reply(r.seq, RtResult::bad_state, m);
      return;
    }
    if (len > 0 && static_cast<std::size_t>(len) < sizeof m)
      len += std::snprintf(m + len, sizeof m - static_cast<std::size_t>(len), "%s%lld%s", j ? ", " : "",
                           static_cast<long long>(bus_.zero_offset(static_cast<std::size_t>(j))), j + 1 == n_ ? "]" : "");
  }
  zeroed_ = all_joints();  // a zero declared this power cycle: the joints count as homed
  hold_measured();
  reply(r.seq, RtResult::ok, m);
}

// ---------------------------------------------------------------------------
// Homing
// ---------------------------------------------------------------------------

void Controller::joints_text(char* buf, std::size_t cap, std::uint16_t mask) {
  int len = 0, count = 0;
  for (int j = 0; j < 16; ++j)
    if ((mask >> j) & 1u) ++count;
  len = std::snprintf(buf, cap, "%s", count == 1 ? "joint" : "joints");
  int k = 0;
  for (int j = 0; j < 16 && len > 0 && static_cast<std::size_t>(len) < cap; ++j)
    if ((mask >> j) & 1u)
      len += std::snprintf(buf + len, cap - static_cast<std::size_t>(len), "%s%d", k++ ? ", " : " ", j + 1);
}

std::uint16_t Controller::homed_mask() const {
  std::uint16_t m = zeroed_;
  for (int j = 0; j < n_; ++j)
    if (bus_.homing(static_cast<std::size_t>(j)).phase == hal::HomingPhase::attained) m = static_cast<std::uint16_t>(m | (1u << j));
  return static_cast<std::uint16_t>(m & ~hrunning_);
}

void Controller::abort_running_homing() {
  for (int j = 0; j < n_; ++j)
    if ((hrunning_ >> j) & 1u) bus_.abort_homing(static_cast<std::size_t>(j));
}

void Controller::homing_failed(int j, const char* why) {
  hrunning_ = static_cast<std::uint16_t>(hrunning_ & ~(1u << j));
  abort_running_homing();  // the rest of the group stops too
  hrunning_ = 0;
  cause_ = FaultCause::homing_failed;
  fault_joint_ = j;
  if (why != nullptr && why[0] != '\0') {
    copy_text(fault_text_, sizeof fault_text_, why);
  } else {
    // The bus's line names the joint its own way ("joint 1 (node 2): ..." with 0-based joints
    // in the CANopen master): the firmware's joints are 1-based everywhere, so the line is
    // re-headed "joint <j+1> (node N): <cause>".
    char d[sizeof fault_text_];
    bus_.describe_homing(static_cast<std::size_t>(j), d, sizeof d);
    const char* node = std::strstr(d, "(node ");
    const char* rest = node != nullptr ? std::strstr(node, "): ") : nullptr;
    std::size_t len = 0;
    auto append = [&](const char* src, std::size_t count) {
      for (std::size_t i = 0; i < count && src[i] != '\0' && len + 1 < sizeof fault_text_; ++i) fault_text_[len++] = src[i];
      fault_text_[len] = '\0';
    };
    char head[24];
    std::snprintf(head, sizeof head, "joint %d", j + 1);
    append(head, sizeof head);
    if (d[0] == '\0') {
      append(": homing failed", 64);
    } else if (std::strncmp(d, "joint ", 6) == 0 && rest != nullptr) {
      append(" ", 1);
      append(node, static_cast<std::size_t>(rest + 1 - node));  // "(node 2)"
      append(": ", 2);
      append(rest + 3, sizeof d);
    } else {
      append(": ", 2);
      append(d, sizeof d);
    }
  }
  flush_motions();
  power_down(Mode::fault);  // the master left the drive enabled in CSP: the arm is disabled, never moving
  hold_measured();
  emit(EventKind::fault, FaultCause::homing_failed, j, 0, fault_text_);
}

void Controller::start_homing(const Request& r) {
  char m[sizeof(Reply::message)];
  if (!exec_.queue().empty()) {
    reply(r.seq, RtResult::busy, "moves are queued: home refused");
    return;
  }
  hgroup_n_ = 0;
  if (r.joints != 0) {
    hgroups_[0] = static_cast<std::uint16_t>(r.joints & all_joints());
    hgroup_n_ = hgroups_[0] != 0 ? 1 : 0;
  } else if (cfg_.homing_groups <= 0) {
    hgroups_[0] = all_joints();
    hgroup_n_ = 1;
  } else {
    for (int g = 0; g < cfg_.homing_groups && g < static_cast<int>(hgroups_.size()); ++g) {
      const auto mask = static_cast<std::uint16_t>(cfg_.homing_group_mask[static_cast<std::size_t>(g)] & all_joints());
      if (mask != 0) hgroups_[static_cast<std::size_t>(hgroup_n_++)] = mask;
    }
  }
  if (hgroup_n_ == 0) {
    reply(r.seq, RtResult::bad_state, "home: no such joint");
    return;
  }
  hgroup_i_ = 0;
  cmd_ = kin::JointState::rest(cmd_.pos);
  ++generation_;  // the positions jump: the console re-reads them
  if (!start_homing_group()) {
    std::snprintf(m, sizeof m, "homing failed: %s", fault_text_);
    reply(r.seq, RtResult::fault, m);
    return;
  }
  set_mode(Mode::homing);
  char j[48];
  joints_text(j, sizeof j, hgroups_[0]);
  std::snprintf(m, sizeof m, "homing: group 1 of %d (%s)", hgroup_n_, j);
  reply(r.seq, RtResult::ok, m);
}

bool Controller::start_homing_group() {
  const std::uint16_t g = hgroups_[static_cast<std::size_t>(hgroup_i_)];
  for (int j = 0; j < n_; ++j) {
    if (!((g >> j) & 1u)) continue;
    const hal::Status st = bus_.start_homing(static_cast<std::size_t>(j), now_);
    if (st != hal::Status::ok) {
      char d[sizeof fault_text_];
      std::snprintf(d, sizeof d, "joint %d: homing not started: %s", j + 1, hal::describe(st));
      homing_failed(j, d);
      return false;
    }
    zeroed_ = static_cast<std::uint16_t>(zeroed_ & ~(1u << j));
    hrunning_ = static_cast<std::uint16_t>(hrunning_ | (1u << j));
    char e[sizeof(Event::message)];
    std::snprintf(e, sizeof e, "joint %d homing (group %d of %d, %s)", j + 1, hgroup_i_ + 1, hgroup_n_,
                  hal::to_string(bus_.homing_kind(static_cast<std::size_t>(j))));
    emit(EventKind::homing, FaultCause::none, j, 0, e);
  }
  return true;
}

// The joints the master homes follow their measured positions (so the setpoint is the measured,
// jumped, position when the homing ends: never the old one); the others hold.
void Controller::step_homing() {
  for (int j = 0; j < n_; ++j) {
    if (!((hrunning_ >> j) & 1u)) continue;
    const auto ju = static_cast<std::size_t>(j);
    const hal::JointFeedback& fb = bus_.feedback(ju);
    if (fb.valid) cmd_.pos[j] = fb.position;
    cmd_.vel[j] = 0;
    cmd_.acc[j] = 0;
    const hal::HomingProgress p = bus_.homing(ju);
    if (p.phase == hal::HomingPhase::running) continue;
    hrunning_ = static_cast<std::uint16_t>(hrunning_ & ~(1u << j));
    q_prev_[j] = cmd_.pos[j];  // the jump to the homed coordinates is no setpoint step
    char e[sizeof(Event::message)];
    if (mode_ == Mode::homing_abort) {
      std::snprintf(e, sizeof e, "joint %d homing aborted: not homed", j + 1);
      emit(EventKind::homing, FaultCause::none, j, 0, e);
      continue;
    }
    if (p.phase != hal::HomingPhase::attained) {
      homing_failed(j, nullptr);
      return;
    }
    if (!(cmd_.pos[j] >= limits_.lower[ju] - cfg_.position_tolerance && cmd_.pos[j] <= limits_.upper[ju] + cfg_.position_tolerance)) {
      char d[sizeof fault_text_];
      std::snprintf(d, sizeof d, "joint %d homed at %.5f, outside its limits [%.5f, %.5f]: check drive.homing.offset", j + 1,
                    cmd_.pos[j], limits_.lower[ju], limits_.upper[ju]);
      homing_failed(j, d);
      return;
    }
    std::snprintf(e, sizeof e, "joint %d homed", j + 1);
    emit(EventKind::homing, FaultCause::none, j, 0, e);
  }
  if (hrunning_ != 0) return;
  if (mode_ == Mode::homing && ++hgroup_i_ < hgroup_n_) {
    if (start_homing_group()) return;
    return;  // failed: the arm is disabled
  }
  const bool done = mode_ == Mode::homing;
  hold_measured();
  set_mode(Mode::idle);
  const std::uint16_t unhomed = static_cast<std::uint16_t>(all_joints() & ~homed_mask());
  char e[sizeof(Event::message)];
  if (unhomed == 0) {
    std::snprintf(e, sizeof e, "%s: every joint homed", done ? "homing done" : "homing stopped");
  } else {
    char j[48];
    joints_text(j, sizeof j, unhomed);
    std::snprintf(e, sizeof e, "%s: %s not homed", done ? "homing done" : "homing stopped", j);
  }
  emit(EventKind::homing, FaultCause::none, -1, 0, e);
}

// ---------------------------------------------------------------------------
// Following the drives, free-drive, jog
// ---------------------------------------------------------------------------

// Not powered (or the reaction is over): follow the measured position so enabling never jumps.
void Controller::follow_measured() {
  if (!exec_.queue().empty()) {
    // A move the console committed on a state it read before a fault / e-stop / disable:
    // it never starts, and the console hears about it.
    char d[sizeof(Event::message)];
    const std::size_t n = flush_motions();
    std::snprintf(d, sizeof d, "%zu queued move%s dropped: arm is %s", n, n == 1 ? "" : "s",
                  to_string(arm_state(mode_)));
    emit(EventKind::motion_refused, FaultCause::none, -1, 0, d);
  }
  for (int j = 0; j < n_; ++j) {
    const auto& fb = bus_.feedback(static_cast<std::size_t>(j));
    if (fb.valid) cmd_.pos[j] = fb.position;
  }
  cmd_.vel.setZero();
  cmd_.acc.setZero();
  have_prev_ = false;
}

void Controller::start_freedrive(const Request& r) {
  char m[sizeof(Reply::message)];
  if (!exec_.queue().empty()) {  // queued in this same cycle: the move goes first
    reply(r.seq, RtResult::busy, "moves are queued: freedrive refused");
    return;
  }
  if (!all_homed()) {  // the model's gravity at an unknown pose would push the arm
    char j[48];
    joints_text(j, sizeof j, static_cast<std::uint16_t>(all_joints() & ~homed_mask()));
    std::snprintf(m, sizeof m, "freedrive refused: %s not homed (home first)", j);
    reply(r.seq, RtResult::not_homed, m);
    return;
  }
  if (model_ == nullptr) {
    reply(r.seq, RtResult::bad_state, "freedrive refused: no dynamic model in this firmware");
    return;
  }
  if (model_->freedrive_enter() != hal::Status::ok) {
    std::snprintf(m, sizeof m, "freedrive refused: %.140s", model_->last_error());
    reply(r.seq, RtResult::bad_state, m);
    return;
  }
  set_mode(Mode::freedrive);
  ++generation_;  // the arm will be moved by hand: the console re-reads the setpoint
  emit(EventKind::freedrive, FaultCause::none, -1, 0, "free-drive on");
  reply(r.seq, RtResult::ok, "free-drive on: gravity compensated; push the arm, `freedrive off` holds it");
}

void Controller::step_freedrive() {
  // The drives in torque mode move the arm, not the setpoints: the setpoint follows the
  // measured pose (write() ignores it in CST; CSP resumes where the drive stands). A move queued
  // meanwhile is dropped with an event (the arm is not where the console planned it from).
  follow_measured();
  if (mode_ == Mode::freedrive) {
    // the hand may carry a joint anywhere: past a position limit the arm stops in fault
    for (int j = 0; j < n_; ++j) {
      const auto ju = static_cast<std::size_t>(j);
      const double q = q_act_[j], lo = limits_.lower[ju], hi = limits_.upper[ju];
      if (q >= lo - cfg_.position_tolerance && q <= hi + cfg_.position_tolerance) continue;
      const char* u = chain_.joint(j).type == kin::JointType::prismatic ? "m" : "rad";
      char d[96];
      std::snprintf(d, sizeof d, "free-drive carried it to %.4f %s, beyond its %s limit %.4f %s", q, u,
                    q > hi ? "upper" : "lower", q > hi ? hi : lo, u);
      raise_fault(FaultCause::joint_limit, j, d);
      return;
    }
  }
  const FreedrivePhase ph = model_ != nullptr ? model_->freedrive_step() : FreedrivePhase::off;
  if (mode_ == Mode::freedrive && ph != FreedrivePhase::entering && ph != FreedrivePhase::active) {
    // a joint left torque mode by itself (refused, fault, heartbeat): every drive back to CSP
    emit(EventKind::freedrive, FaultCause::none, -1, 0, model_ != nullptr ? model_->last_error() : "free-drive ended");
    set_mode(Mode::freedrive_end);
  }
  if (mode_ == Mode::freedrive_end && ph == FreedrivePhase::off) {
    hold_measured();  // the setpoint restarts from the measured pose
    set_mode(Mode::idle);
    emit(EventKind::freedrive, FaultCause::none, -1, 0, "free-drive off");
  }
}

void Controller::step_jog() {
  const JogEnd e = jog_.step(cmd_, now_);
  if (e == JogEnd::running) return;
  if (e != JogEnd::done) {
    char d[sizeof(Event::message)];
    const int j = jog_.joint();
    switch (e) {
      case JogEnd::deadman:
        if (jog_.stream_jog())
          std::snprintf(d, sizeof d, "stream stopped: no target within its deadman time (%.0f ms)", 1e3 * jog_.deadman_s());
        else
          std::snprintf(d, sizeof d, "jog stopped: not refreshed within its deadman time (%.0f ms)", 1e3 * jog_.deadman_s());
        break;
      case JogEnd::limit: std::snprintf(d, sizeof d, "jog stopped: joint %d at its limit", j + 1); break;
      case JogEnd::singular:
        std::snprintf(d, sizeof d, "jog stopped near a singularity: joint %d would exceed its velocity limit", j + 1);
        break;
      case JogEnd::unreachable: std::snprintf(d, sizeof d, "jog stopped: the next pose has no IK solution"); break;
      case JogEnd::running:
      case JogEnd::done: d[0] = '\0'; break;
    }
    emit(EventKind::jog_stopped, FaultCause::none, j, 0, d);
  }
  if (jog_.needs_joint_ramp()) {
    // The tool jog gave up its line: ramp down in joint space from its last velocities.
    // Its accelerations are finite differences of IK solutions (large near a singularity):
    // the ramp starts from zero acceleration, so no joint overshoots its velocity.
    cmd_.acc.setZero();
    begin_ramp(Mode::stopping_to_idle);
    return;
  }
  cmd_ = kin::JointState::rest(cmd_.pos);
  set_mode(Mode::idle);
}

// ---------------------------------------------------------------------------
// Setpoints out, telemetry, the cycle
// ---------------------------------------------------------------------------

void Controller::validate_and_write(TimePoint now) {
  const bool is_powered = powered(mode_);
  if (is_powered) {
    const bool stopping_ramp = ramping(mode_);  // a stop may cross a limit it was already about to
    for (int j = 0; j < n_; ++j) {
      if ((hrunning_ >> j) & 1u) continue;  // the master moves it (homing): write() ignores its setpoint
      const double q = cmd_.pos[j];
      char d[64];
      if (!std::isfinite(q)) {
        cmd_ = kin::JointState::rest(q_prev_);
        raise_fault(FaultCause::setpoint_nan, j, "non-finite setpoint; holding");
        break;
      }
      const auto ju = static_cast<std::size_t>(j);
      if (!stopping_ramp && (q < limits_.lower[ju] - cfg_.position_tolerance || q > limits_.upper[ju] + cfg_.position_tolerance)) {
        std::snprintf(d, sizeof d, "%.5f outside [%.5f, %.5f]", q, limits_.lower[ju], limits_.upper[ju]);
        cmd_.pos[j] = std::fmin(std::fmax(q, limits_.lower[ju]), limits_.upper[ju]);
        raise_fault(FaultCause::setpoint_position, j, d);
        break;
      }
      if (have_prev_) {
        const double v = std::fabs(q - q_prev_[j]) / period_s_;
        const double vmax = limits_.dyn[ju].max_velocity * cfg_.velocity_margin + 1e-9;
        if (v > vmax) {
          std::snprintf(d, sizeof d, "%.4f/s > %.4f/s", v, vmax);
          cmd_ = kin::JointState::rest(q_prev_);
          raise_fault(FaultCause::setpoint_velocity, j, d);
          break;
        }
      }
    }
  }
  const auto sp = std::span<const double>(cmd_.pos.data(), static_cast<std::size_t>(n_));
  const hal::Status ws = bus_.write(sp, now);
  if (estop_seen_ >= 0) {
    estop_latency_ = now - estop_seen_;
    estop_seen_ = -1;
  }
  q_prev_ = cmd_.pos;
  have_prev_ = is_powered;
  const bool faulted = arm_state(mode_) == ArmState::fault;
  if (ws == hal::Status::bus_off && !faulted) raise_fault(FaultCause::bus_off, -1, "CAN controller bus-off");
  else if (static_cast<int>(ws) < 0 && ws != hal::Status::invalid_argument && !faulted && is_powered) {
    char d[64];
    std::snprintf(d, sizeof d, "write: %s", hal::to_string(ws));
    raise_fault(FaultCause::bus_error, -1, d);
  }
}

void Controller::publish() {
  if (cycles_ % 64 == 0) {
    latency_sum_ = latency_.summary();
    compute_sum_ = compute_.summary();
  }
  Telemetry t;
  t.state = arm_state(mode_);
  t.holding = holding(mode_);
  t.mode = mode_;
  t.n = n_;
  for (int j = 0; j < n_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    t.q_cmd[ju] = cmd_.pos[j];
    t.qd_cmd[ju] = cmd_.vel[j];
    const auto& fb = bus_.feedback(ju);
    t.q_act[ju] = fb.position;
    t.qd_act[ju] = fb.velocity;
    t.tau_act[ju] = fb.has_torque ? fb.torque : 0.0;
    if (fb.has_torque) t.torque_valid = static_cast<std::uint16_t>(t.torque_valid | (1u << j));
    if (fb.has_temperature) {
      t.temperature[ju] = fb.temperature;
      t.temperature_valid = static_cast<std::uint16_t>(t.temperature_valid | (1u << j));
    }
    t.joint_state[ju] = static_cast<std::uint8_t>(fb.state);
  }
  t.queued = static_cast<std::uint32_t>(exec_.queue().size());
  t.streaming = mode_ == Mode::jogging && jog_.streaming();
  t.running_id = exec_.running_id();
  t.done_id = done_id_;
  t.temperature_warning = hot_;
  t.cause = cause_;
  t.fault_joint = static_cast<std::int8_t>(fault_joint_);
  std::memcpy(t.fault_text, fault_text_, sizeof t.fault_text);
  t.cycles = cycles_;
  t.overruns = overruns_;
  t.generation = generation_;
  for (int j = 0; j < n_; ++j) t.outputs[static_cast<std::size_t>(j)] = bus_.digital_outputs(static_cast<std::size_t>(j));
  t.latency = latency_sum_;
  t.compute = compute_sum_;
  t.max_following_error = max_follow_;
  t.estop_latency_ns = estop_latency_;
  t.ik_fallbacks = exec_.ik_fallbacks();
  t.joint_replans = exec_.joint_replans();
  t.blended_corners = exec_.blended_corners();
  t.path_time = exec_.path_time();
  t.path_id = exec_.path_id();
  t.homing_now = hrunning_;
  t.safety_mode = reduced_in_.asserted() ? static_cast<std::uint8_t>(kin::SafetyMode::reduced)
                                         : safety_mode_.load(std::memory_order_relaxed);
  t.safety_inputs = static_cast<std::uint8_t>((estop_in_.asserted() ? 1u : 0u) | (estop_in_.lost() ? 2u : 0u) |
                                              (reduced_in_.asserted() ? 4u : 0u) | (reduced_in_.lost() ? 8u : 0u));
  t.safety_stops = safety_stops_;
  t.safety_zone = static_cast<std::int8_t>(safety_.zone());
  t.speed_scale = mode_ == Mode::jogging ? jog_.speed_scale() : exec_.speed_scale();
  t.homing_failed = 0;
  std::uint16_t attained = 0;  // homed_mask() from the progress read here: one homing() a joint
  for (int j = 0; j < n_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    const hal::HomingProgress hp = bus_.homing(ju);
    if (hp.phase == hal::HomingPhase::attained) attained = static_cast<std::uint16_t>(attained | (1u << j));
    t.homing_phase[ju] = static_cast<std::uint8_t>(hp.phase);
    if (hp.phase == hal::HomingPhase::failed && hp.status != hal::Status::aborted)
      t.homing_failed = static_cast<std::uint16_t>(t.homing_failed | (1u << j));
    t.homing_kind[ju] = static_cast<std::uint8_t>(bus_.homing_kind(ju));
  }
  t.homed = static_cast<std::uint16_t>((zeroed_ | attained) & ~hrunning_);

  const bool homing_mode = mode_ == Mode::homing || mode_ == Mode::homing_abort;
  t.homing_group = static_cast<std::uint8_t>(homing_mode ? hgroup_i_ + 1 : 0);
  t.homing_groups = static_cast<std::uint8_t>(homing_mode ? hgroup_n_ : 0);
  if (model_ != nullptr) {
    const ModelControlStats& ms = model_->stats();
    t.feed_forward = static_cast<std::uint8_t>(model_->feed_forward_on() ? model_->feed_forward_kind() : FeedForwardKind::off);
    t.collision_on = model_->collision_on();
    t.freedrive = static_cast<std::uint8_t>(model_->freedrive_phase());
    t.collision_peak = ms.peak_ratio;
    t.collision_peak_joint = static_cast<std::int8_t>(ms.peak_joint);
    t.collision_ratio = ms.last_ratio;
    t.collisions = ms.collisions;
    t.feed_forward_cycles = ms.ff_cycles;
  }
  telemetry_.write(t);
  if (sampling_.load(std::memory_order_acquire)) take_sample(t);
}

void Controller::take_sample(const Telemetry& t) {
  if (t.cycles % sample_every_.load(std::memory_order_relaxed) != 0) return;
  CycleSample* s = samples_->back();
  if (s == nullptr) {  // the recorder is behind by a whole ring: counted, the cycle never waits
    samples_dropped_.store(samples_dropped_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
    return;
  }
  s->cycles = t.cycles;
  s->state = t.state;
  s->mode = t.mode;
  s->holding = t.holding;
  s->n = static_cast<std::uint8_t>(t.n);
  s->torque_valid = t.torque_valid;
  s->homed = t.homed;
  s->running_id = t.running_id;
  s->queued = t.queued;
  s->q_cmd = t.q_cmd;
  s->qd_cmd = t.qd_cmd;
  s->q_act = t.q_act;
  s->qd_act = t.qd_act;
  s->tau_act = t.tau_act;
  samples_->commit();
}

void Controller::start_samples(std::uint64_t every) {
  sampling_.store(false, std::memory_order_release);
  if (samples_ == nullptr) samples_ = std::make_unique<SpscQueue<CycleSample, kSampleRing>>();
  samples_->clear();
  sample_every_.store(every > 0 ? every : 1, std::memory_order_relaxed);
  sampling_.store(true, std::memory_order_release);
}

namespace {
// dst = a + b, cut to size (an event's fixed line).
void join_text(char* dst, std::size_t size, const char* a, const char* b) {
  std::size_t n = 0;
  for (; *a != '\0' && n + 1 < size; ++a) dst[n++] = *a;
  for (; *b != '\0' && n + 1 < size; ++b) dst[n++] = *b;
  dst[n] = '\0';
}
}  // namespace

void Controller::step_safety() {
  // A confirmed run-time change of the envelope (ArmService::confirm_safety): the console thread
  // sends the active tool again right after it.
  if (safety_configs_.pop(safety_next_)) safety_.configure(chain_, safety_next_, period_s_);
  if (!safety_.enabled()) return;
  SafetyToolChange tc;
  while (safety_tools_.pop(tc)) {
    kin::Pose tool;
    for (int i = 0; i < 16; ++i) tool.matrix().data()[i] = tc.m[static_cast<std::size_t>(i)];
    safety_.set_tool(tool, tc.radius);
  }
  bool watch = false;  // the modes a protective stop acts in (the planner's moves, jogs, a hold on a line)
  switch (mode_) {
    case Mode::moving:
    case Mode::hold_line:
    case Mode::jogging: watch = true; break;
    case Mode::idle:
    case Mode::held:
    case Mode::hold_ramp:
    case Mode::hold_ramp_resume:
    case Mode::stopping_to_idle:
    case Mode::stopping_to_disabled:
    case Mode::fault_ramp:
    case Mode::estop_ramp: break;  // at rest or braking already: monitored for the speeds' continuity
    case Mode::boot:
    case Mode::disabled:
    case Mode::enabling:
    case Mode::fault_quick_stop:
    case Mode::fault:
    case Mode::estop_quick_stop:
    case Mode::estop:
    case Mode::homing:
    case Mode::homing_abort:
    case Mode::freedrive:
    case Mode::freedrive_end: safety_.reset(); return;  // not powered on the setpoints
  }
  const kin::SafetyMode op = reduced_in_.asserted() ? kin::SafetyMode::reduced : safety_mode();
  if (op != last_op_) {  // the limits the running motion was planned with came down (or went up)
    if (op == kin::SafetyMode::reduced) reduced_since_ = static_cast<std::int64_t>(cycles_);
    last_op_ = op;
  }
  const bool jogging = mode_ == Mode::jogging;
  // the motion runs on the speed scale: the executor's segments, a jog (not while it brakes)
  const bool scaled = watch && !(jogging && jog_.stopping());
  if (!scaled) speed_over_cycles_ = 0, target_hold_ = 1.0;
  kin::SafetyViolation v;
  bool on_actual = false;
  const int zone_before = safety_.zone();
  bool hit = safety_.update(cmd_.pos, q_act_, op, jogging, v, on_actual, scaled);
  const kin::SafetyMode sm = safety_.effective(op);  // Reduced in a trigger plane's zone
  if (const int zone = safety_.zone(); zone != zone_before) {
    char z[sizeof(Event::message)];
    if (zone >= 0)
      std::snprintf(z, sizeof z, "safety mode reduced: the tool entered reduced plane %d", zone);
    else
      std::snprintf(z, sizeof z, "safety mode %s: the tool left reduced plane %d", kin::to_string(op), zone_before);
    emit(EventKind::warning, FaultCause::none, -1, 0, z);
  }
  if (!watch) return;
  if (jogging) update_jog_cap();  // for its re-plans (a new target, a target's horizon)
  // stop time and distance (a stop now); momentum and power on the scale as the speeds
  if (!hit && safety_.check_state(limits_, cmd_, sm, v, scaled)) hit = true, on_actual = false;
  if (!hit && scaled && scale_speed(v)) hit = true, on_actual = false;  // a speed the scale cannot keep
  char line[sizeof(Event::message)];
  char what[sizeof(Event::message)];
  if (jogging && !hit && safety_.predict_stop(limits_, cmd_, sm, v)) {
    // the ramp from here ends beyond a plane or box: brake now, to rest at it
    const int j = jog_.joint();
    kin::describe(v, what, sizeof what);
    join_text(line, sizeof line, "jog stopped at the ", what + 7);  // (what: "safety ...")
    cmd_.acc.setZero();
    begin_ramp(Mode::stopping_to_idle);
    ++safety_stops_;
    emit(EventKind::jog_stopped, FaultCause::none, j, 0, line);
    return;
  }
  if (!hit) return;
  kin::describe(v, what, sizeof what);
  join_text(line, sizeof line, on_actual ? "protective stop (measured): " : "protective stop (commanded): ", what + 7);
  const std::uint32_t id = exec_.running_id();
  const bool was_jog = jogging;
  flush_motions();
  if (was_jog) cmd_.acc.setZero();
  begin_ramp(Mode::stopping_to_idle);
  ++safety_stops_;
  emit(was_jog ? EventKind::jog_stopped : EventKind::motion_refused, FaultCause::none, -1, id, line);
}

// Speed scaling (docs/safety.md#speed-scaling). The speeds go with the scale s, so the ratio
// per unit scale is speed_ratio / s and the scale that holds every speed function is kScaleAim over
// it. Outside a trigger zone, the Reduced mode's scale is taken as soon as the tool, moving on at
// its unscaled velocity, would reach a trigger plane within the time the scale takes to ramp
// from 1 down to it (with margin): so it is below the Reduced limits when it crosses. A speed
// beyond its limit and tolerance is left to the scale only in the kScaleGrace after Reduced
// mode was switched on (the limits came down onto a running motion); anywhere else the
// scale should have kept it, and it is a protective stop as without scaling.
bool Controller::scale_speed(kin::SafetyViolation& v) {
  constexpr double kScaleGrace = 0.5;  // s: how long a speed may stay beyond its limit and tolerance while the scale ramps
  const bool jogging = mode_ == Mode::jogging;
  const double s = jogging ? jog_.speed_scale() : exec_.speed_scale();
  const double per_scale = s > 0 ? safety_.speed_ratio() / s : 0.0;
  double want = per_scale > kScaleAim ? kScaleAim / per_scale : 1.0;
  double reduced = 0;
  const double t = safety_.time_to_trigger(s > 0 ? 1.0 / s : 1.0, reduced);
  if (reduced > 0 && s > 0) {
    const double want_reduced = kScaleAim * s / reduced;
    if (want_reduced < want && t <= 1.2 * TimeScale::ramp_time(1.0, want_reduced) + 3 * period_s_) want = want_reduced;
  }
  // The executor's target is held at its lowest: the speed a plan slows to at a blend's corner
  // (or a trigger plane's look-ahead reached in such a dip) comes back after it, and a scale
  // that had risen meanwhile would lag behind it. Under the Reduced limits (the mode, or a
  // trigger zone) the hold lasts while the motion runs; under Normal, kTargetHoldS from its
  // last new low (the look-ahead's target, should the tool not reach the plane after all). A
  // jog's re-plans are capped instead (update_jog_cap): not held.
  constexpr double kTargetHoldS = 0.4;
  const auto now = static_cast<std::int64_t>(cycles_);
  const bool release = jogging || (safety_.effective(safety_mode()) == kin::SafetyMode::normal &&
                                   static_cast<double>(now - target_hold_since_) * period_s_ > kTargetHoldS);
  if (want <= target_hold_ || release) {
    target_hold_ = want;
    target_hold_since_ = now;
  }
  want = target_hold_;
  if (jogging)
    jog_.set_speed_target(want);
  else
    exec_.set_speed_target(want);
  kin::SafetyViolation over;
  if (!safety_.speed_over(over)) {
    speed_over_cycles_ = 0;
    return false;
  }
  // Left to the scale for at most kScaleGrace after Reduced was switched on, while the scale it
  // needs is within its range: the limits came down onto a running motion, and the scale ramps
  // down from there (a plan still speeding up, or joints at their acceleration limits, only
  // delay it: a speed still beyond after the grace is a protective stop).
  ++speed_over_cycles_;
  over_last_ = over;
  const bool after_switch = static_cast<double>(static_cast<std::int64_t>(cycles_) - reduced_since_) * period_s_ <= kScaleGrace;
  if (after_switch && want >= TimeScale::kMin) return false;
  v = over;
  return true;
}

// A jog's or stream's plans are made within the envelope's speed limits (SafetyMonitor::speed_cap):
// near a trigger plane, slow enough that the scale's look-ahead (the longest ramp, 1 down to
// TimeScale::kMin, with its margin) can bring them to the Reduced limits before the plane.
void Controller::update_jog_cap() {
  SpeedCap cap;
  const double horizon = 1.2 * TimeScale::ramp_time(1.0, TimeScale::kMin) + 3 * period_s_;
  safety_.speed_cap(safety_mode(), kScaleAim, horizon, cap);
  jog_.set_speed_cap(cap);
}

void Controller::apply_output(const OutputChange& c) {
  if (c.joint < 0 || c.joint >= n_) return;
  const auto j = static_cast<std::size_t>(c.joint);
  out_words_[j] = (out_words_[j] & ~c.mask) | (c.value & c.mask);
  bus_.set_digital_outputs(j, out_words_[j]);  // not_supported: the console checked the mapping
}

void Controller::watch_safety_inputs(TimePoint now) {
  char m[256];  // (emit() cuts it to the event's length)
  if (reduced_in_.configured()) {
    const bool was = reduced_in_.asserted(), was_lost = reduced_in_.lost();
    const bool on = reduced_in_.update(now);
    reduced_by_input_.store(on, std::memory_order_relaxed);
    if (reduced_in_.lost() && !was_lost) {
      std::snprintf(m, sizeof m, "safety mode reduced: Reduced input cannot be read: %s", reduced_in_.input()->why_lost());
      emit(EventKind::warning, FaultCause::none, -1, 0, m);
    } else if (on != was) {
      if (on) std::snprintf(m, sizeof m, "safety mode reduced: Reduced input %s asserted", reduced_in_.input()->source());
      else std::snprintf(m, sizeof m, "safety mode %s: Reduced input %s released", kin::to_string(safety_mode()),
                         reduced_in_.input()->source());
      emit(EventKind::warning, FaultCause::none, -1, 0, m);
    }
  }
  if (!estop_in_.configured()) return;
  const bool was_lost = estop_in_.lost(), was = estop_in_.asserted();
  const bool on = estop_in_.update(now);
  const bool newly_lost = estop_in_.lost() && !was_lost;
  // Not powered and nothing stopping (boot, disabled, a latched fault or e-stop): nothing to
  // stop; `enable` and `reset` are refused while it is asserted (cycle()).
  const bool at_rest_off = mode_ == Mode::boot || mode_ == Mode::disabled || mode_ == Mode::fault;
  if (on && !at_rest_off && arm_state(mode_) != ArmState::estop) {
    if (estop_in_.lost()) std::snprintf(m, sizeof m, "emergency stop: e-stop input cannot be read: %s", estop_in_.input()->why_lost());
    else std::snprintf(m, sizeof m, "emergency stop: e-stop input %s asserted", estop_in_.input()->source());
    estop_why_ = m;
    run(action_for(mode_, RequestOp::estop), Request(RequestOp::estop, 0), now);
    estop_why_ = nullptr;
    return;
  }
  if (newly_lost) {  // (already in e-stop, or not powered)
    std::snprintf(m, sizeof m, "e-stop input cannot be read: %s", estop_in_.input()->why_lost());
    emit(EventKind::warning, FaultCause::none, -1, 0, m);
  } else if (on && !was) {  // (already in e-stop, or not powered)
    std::snprintf(m, sizeof m, "e-stop input %s asserted", estop_in_.input()->source());
    emit(EventKind::warning, FaultCause::none, -1, 0, m);
  } else if (was && !on) {
    std::snprintf(m, sizeof m, "e-stop input %s released%s", estop_in_.input()->source(),
                  arm_state(mode_) == ArmState::estop ? ": `reset` clears the emergency stop" : "");
    emit(EventKind::warning, FaultCause::none, -1, 0, m);
  }
}

void Controller::cycle(TimePoint now) {
  now_ = now;
  ++cycles_;
  // 1 feedback
  bus_.read(now);
  for (int j = 0; j < n_; ++j) q_act_[j] = bus_.feedback(static_cast<std::size_t>(j)).position;
  watch_safety_inputs(now);  // the e-stop input acts before any request of this cycle
  // free-drive: the hand moves the arm; whatever a request starts, it starts from where it is now
  if (mode_ == Mode::freedrive || mode_ == Mode::freedrive_end) cmd_ = kin::JointState::rest(q_act_);
  // console requests (bounded per cycle)
  Request r;
  for (int i = 0; i < 4 && requests_.pop(r); ++i) {
    if ((r.op == RequestOp::reset || r.op == RequestOp::enable) && estop_in_.asserted()) {
      char m[256];  // (reply() cuts it to the reply's length)
      std::snprintf(m, sizeof m, "the e-stop input %s is asserted%s: release it first", estop_in_.input()->source(),
                    estop_in_.lost() ? " (cannot be read)" : "");
      reply(r.seq, RtResult::fault, m);
      continue;
    }
    handle_request(r, now);
  }
  // digital outputs set at once (M64 / M65, `out`), bounded per cycle
  OutputChange oc;
  for (int i = 0; i < 8 && outputs_.pop(oc); ++i) apply_output(oc);
  // 2 supervisor
  supervise(now);
  watch_temperatures();
  // 3 motion, and the model's feed-forward of the setpoint (60B1h / 60B2h with this write)
  step_motion();
  step_safety();
  if (model_ != nullptr) model_->feed_forward(cmd_);
  // 4 + 5 validate, write setpoints + SYNC
  validate_and_write(now);
  // 6 telemetry (statistics are added by the loop through record_timing), then the replies
  publish();
  flush_replies();
}

}  // namespace servoarm::fw
