// SPDX-License-Identifier: Apache-2.0
// The arm service's program runner (arm_service.hpp): feeds a loaded program's steps to the
// motion queue one motion ahead of the running one, through the front end's StepExecutor,
// and ends it when a step is refused or the arm stops taking moves. Console thread.
#include <algorithm>

#include "servoarm/lang/text.hpp"
#include "servoarm/service/arm_service.hpp"

namespace servoarm::fw {

const char* to_string(RunState r) {
  switch (r) {
    case RunState::idle: return "idle";
    case RunState::running: return "running";
    case RunState::pausing: return "pausing";
    case RunState::paused: return "paused";
    case RunState::stepping: return "stepping";
  }
  return "?";
}

const char* to_string(ProgramPhase p) {
  switch (p) {
    case ProgramPhase::started: return "started";
    case ProgramPhase::step: return "step";
    case ProgramPhase::ended: return "ended";
  }
  return "?";
}

const char* to_string(ProgramEnd e) {
  switch (e) {
    case ProgramEnd::none: return "none";
    case ProgramEnd::done: return "done";
    case ProgramEnd::stop: return "stop";
    case ProgramEnd::estop: return "estop";
    case ProgramEnd::soft_reset: return "soft_reset";
    case ProgramEnd::disable: return "disable";
    case ProgramEnd::abort: return "abort";
    case ProgramEnd::fault: return "fault";
    case ProgramEnd::arm_state: return "arm_state";
    case ProgramEnd::queue_dropped: return "queue_dropped";
    case ProgramEnd::step_refused: return "step_refused";
  }
  return "?";
}

const char* to_string(ProgramRefusal r) {
  switch (r) {
    case ProgramRefusal::none: return "none";
    case ProgramRefusal::no_program: return "no_program";
    case ProgramRefusal::running: return "running";
    case ProgramRefusal::program_state: return "program_state";
    case ProgramRefusal::arm_not_ready: return "arm_not_ready";
  }
  return "?";
}

// ---------------------------------------------------------------------------
// Hold and resume
// ---------------------------------------------------------------------------

ControlResult ArmService::hold() {
  if (run_) run_->state = RunState::paused;  // the program pauses with the hold
  return control(RequestOp::hold);
}

ControlResult ArmService::resume(bool end_pause) {
  if (run_ && (run_->state == RunState::paused || (end_pause && run_->state == RunState::pausing)))
    run_->state = RunState::running;
  return control(RequestOp::resume);
}

// ---------------------------------------------------------------------------
// Status and events
// ---------------------------------------------------------------------------

RunState ArmService::run_state() const { return run_ ? run_->state : RunState::idle; }

// The step a program's place names: the running motion's, else the next to feed.
std::size_t ArmService::where_step() const {
  const ProgramRun& r = *run_;
  if (r.spec.steps.empty()) return 0;
  const std::size_t i = r.fed.empty() ? std::min(r.next, r.spec.steps.size() - 1) : r.current;
  return std::min(i, r.spec.steps.size() - 1);
}

ProgramStatus ArmService::program_status() const {
  ProgramStatus p;
  if (!run_) return p;
  const ProgramRun& r = *run_;
  p.state = r.state;
  p.name = r.spec.name;
  p.steps = r.spec.steps.size();
  p.step = where_step();
  p.running = r.current;
  p.started_cycle = r.started_cycle;
  if (p.step < p.steps) {
    const ProgramSpec::Step& st = r.spec.steps[p.step];
    p.line = st.line;
    if (st.file >= 0 && static_cast<std::size_t>(st.file) < r.spec.files.size()) p.file = r.spec.files[static_cast<std::size_t>(st.file)];
    else p.file = "?";
  }
  if (p.running < p.steps) p.running_line = r.spec.steps[p.running].line;
  return p;
}

void ArmService::post_program(ProgramPhase phase, std::size_t step, ProgramEnd end) {
  const ProgramRun& r = *run_;
  EventSlot& s = push_event();
  s.ev.kind = ArmEventKind::program;
  s.ev.program = phase;
  s.ev.end = end;
  s.ev.steps = static_cast<std::uint32_t>(r.spec.steps.size());
  s.ev.step = static_cast<std::uint32_t>(step);
  if (ctl_ != nullptr) s.ev.state = ctl_->telemetry().state;
  s.program = r.spec.name;
  if (step < r.spec.steps.size()) {
    const ProgramSpec::Step& st = r.spec.steps[step];
    s.ev.line = st.line;
    s.file = st.file >= 0 && static_cast<std::size_t>(st.file) < r.spec.files.size() ? r.spec.files[static_cast<std::size_t>(st.file)]
                                                                                      : std::string("?");
  }
}

void ArmService::end_program(ProgramEnd how, std::size_t step, bool realtime, CmdError error, std::string_view detail) {
  if (!run_) return;
  post_program(ProgramPhase::ended, step, how);
  EventSlot& s = (*ring_)[(next_seq_ - 1) % kEventRing];
  s.ev.realtime = realtime;
  s.ev.error = error;
  if (how == ProgramEnd::done && ctl_ != nullptr)
    s.ev.seconds = static_cast<double>(ctl_->telemetry().cycles - run_->started_cycle) / ctl_->config().rate_hz;
  const std::size_t n = std::min(detail.size(), sizeof s.detail - 1);
  detail.copy(s.detail, n);
  s.detail[n] = '\0';
  run_.reset();
}

// ---------------------------------------------------------------------------
// Requests
// ---------------------------------------------------------------------------

ProgramResult ArmService::run_program(ProgramSpec spec, StepExecutor exec) {
  ProgramResult res;
  if (run_) {
    res.error = CmdError::bad_state;
    res.refusal = ProgramRefusal::running;
    res.status = program_status();
    return res;
  }
  const Telemetry t = ctl_ != nullptr ? ctl_->telemetry() : Telemetry{};
  if (ctl_ == nullptr || t.state != ArmState::idle || !ctl_->motions().empty() || !t.all_homed()) {
    res.error = ctl_ != nullptr && t.state == ArmState::idle && ctl_->motions().empty() ? CmdError::not_homed : CmdError::bad_state;
    res.refusal = ProgramRefusal::arm_not_ready;
    res.arm = t.state;
    res.queued = ctl_ != nullptr ? static_cast<std::uint32_t>(ctl_->motions().size()) : 0;
    return res;
  }
  run_ = std::make_unique<ProgramRun>();
  run_->spec = std::move(spec);
  run_->exec = std::move(exec);
  run_->generation = t.generation;
  run_->started_cycle = t.cycles;
  post_program(ProgramPhase::started, 0);
  res.status = program_status();
  program_tick();
  return res;
}

ProgramResult ArmService::program_pause() {
  ProgramResult res;
  if (!run_) {
    res.error = CmdError::bad_state;
    res.refusal = ProgramRefusal::no_program;
    return res;
  }
  if (run_->state == RunState::running || run_->state == RunState::stepping) run_->state = RunState::pausing;
  program_tick();
  res.status = program_status();
  return res;
}

ProgramResult ArmService::program_step() {
  ProgramResult res;
  if (!run_ || run_->state != RunState::paused) {
    res.error = CmdError::bad_state;
    res.refusal = run_ ? ProgramRefusal::program_state : ProgramRefusal::no_program;
    res.status = program_status();
    return res;
  }
  run_->state = RunState::stepping;
  run_->step_fed = false;
  const Telemetry t = ctl_->telemetry();
  Reply r;
  if (t.holding || t.mode == Mode::held) request(RequestOp::resume, r);  // a move held by `!` is finished first
  program_tick();
  res.status = program_status();
  return res;
}

ProgramResult ArmService::program_abort(ProgramEnd why, bool realtime) {
  ProgramResult res;
  if (!run_) {
    res.error = CmdError::bad_state;
    res.refusal = ProgramRefusal::no_program;
    return res;
  }
  res.status = program_status();
  end_program(why, where_step(), realtime);
  if (why == ProgramEnd::abort) {  // the other ends: the front end asks its own stop, e-stop or disable
    Reply r;
    if (!request(RequestOp::stop, r)) res.error = CmdError::timeout;
  }
  res.status.state = RunState::idle;
  return res;
}

// ---------------------------------------------------------------------------
// The runner
// ---------------------------------------------------------------------------

// The arm stopped taking moves: the program ends, saying why. True when it ended.
bool ArmService::program_ended_by_arm(const Telemetry& t) {
  switch (t.state) {
    case ArmState::fault: end_program(ProgramEnd::fault, where_step(), false, CmdError::fault, bounded_text(t.fault_text)); return true;
    case ArmState::estop: end_program(ProgramEnd::estop, where_step()); return true;
    case ArmState::boot:
    case ArmState::disabled:
    case ArmState::jogging:
    case ArmState::homing:
    case ArmState::freedrive: end_program(ProgramEnd::arm_state, where_step()); return true;
    case ArmState::enabling:
    case ArmState::idle:
    case ArmState::moving:
    case ArmState::stopping: break;
  }
  if (t.generation != run_->generation) {  // the queue was dropped (a stop from elsewhere) or a move refused
    end_program(ProgramEnd::queue_dropped, where_step());
    return true;
  }
  return false;
}

// Feed the steps that may go now; false when the program ended (a step refused).
bool ArmService::feed_program() {
  ProgramRun& r = *run_;
  for (int guard = 0; guard < 64 && r.next < r.spec.steps.size(); ++guard) {
    if (r.state != RunState::running && r.state != RunState::stepping) break;
    const StepClass k = r.spec.steps[r.next].kind;
    const Telemetry now = ctl_->telemetry();
    const bool at_rest = now.state == ArmState::idle && ctl_->motions().empty();
    if (k == StepClass::motion) {
      if (r.state == RunState::stepping && r.step_fed) break;
      if (ctl_->motions().size() >= 2) break;  // one queued behind the running move
      if (now.state != ArmState::idle && now.state != ArmState::moving) break;
      if (now.mode == Mode::held || now.holding) break;
    } else if (k == StepClass::needs_idle && !at_rest) {
      break;
    }
    const std::size_t i = r.next++;
    if (k == StepClass::wait) {  // done at once when nothing is queued, else the next ticks wait
      r.waiting = !at_rest;
      if (r.waiting) break;
      continue;
    }
    const StepOutcome o = r.exec(i);
    if (!run_) return false;
    if (!o.ok()) {
      Reply rp;
      request(RequestOp::stop, rp);  // the rest is dropped
      end_program(ProgramEnd::step_refused, i, false, o.error, o.reason);
      return false;
    }
    if (k == StepClass::motion) {
      r.fed.emplace_back(last_motion_id(), i);
      if (r.fed.size() == 1) r.current = i;
      r.step_fed = true;
    }
  }
  return true;
}

void ArmService::program_tick() {
  if (!run_ || ticking_ || ctl_ == nullptr) return;
  ProgramRun& r = *run_;
  const Telemetry t = ctl_->telemetry();
  // Finished motions leave the list; its front is the running one.
  while (!r.fed.empty() && (r.fed.front().first <= t.done_id || (t.running_id != 0 && r.fed.front().first < t.running_id)))
    r.fed.pop_front();
  if (!r.fed.empty()) r.current = r.fed.front().second;
  if (program_ended_by_arm(t)) return;
  if (r.state == RunState::running && (t.mode == Mode::held || t.holding)) r.state = RunState::paused;
  const bool at_rest = t.state == ArmState::idle && ctl_->motions().empty();
  ticking_ = true;  // a member, not the run's: end_program() frees the run inside this function
  struct Busy {
    bool& b;
    ~Busy() { b = false; }
  } busy{ticking_};
  if (r.waiting) {  // a `wait` step: until the queued motions have run
    switch (t.state) {
      case ArmState::moving:
      case ArmState::stopping:
      case ArmState::jogging:
      case ArmState::homing:
      case ArmState::enabling: return;
      case ArmState::boot:
      case ArmState::disabled:
      case ArmState::idle:
      case ArmState::freedrive:
      case ArmState::fault:
      case ArmState::estop:
        if (!ctl_->motions().empty()) return;
        r.waiting = false;
        break;
    }
  }
  if (!feed_program()) return;
  if (!r.fed.empty() && r.current != r.reported) {  // the running motion is a new step's
    r.reported = r.current;
    post_program(ProgramPhase::step, r.current);
  }
  const bool rest_now = ctl_->telemetry().state == ArmState::idle && ctl_->motions().empty();
  if (r.next >= r.spec.steps.size() && rest_now && at_rest && !r.waiting) {
    end_program(ProgramEnd::done, where_step());
    return;
  }
  if ((r.state == RunState::pausing || (r.state == RunState::stepping && r.step_fed)) && rest_now && at_rest)
    r.state = RunState::paused;
}

}  // namespace servoarm::fw
