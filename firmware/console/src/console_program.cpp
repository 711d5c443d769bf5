// SPDX-License-Identifier: Apache-2.0
// The console's teach points, program runner and recorder (console.hpp, docs/programs.md).
// Console thread: allocates, does file I/O; talks to the control thread only through the
// motion queue and requests, like every other command.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdarg>
#include <cstdio>

#include "servoarm/console/console.hpp"
#include "servoarm/lang/text.hpp"
#include "servoarm/kinematics/io/file_input.hpp"
#include "servoarm/kinematics/orientation.hpp"

namespace servoarm::fw {

using prog::kind_of;
using prog::StepKind;

namespace {

std::string fmt(const char* f, ...) __attribute__((format(printf, 1, 2)));
std::string fmt(const char* f, ...) {
  char buf[512];
  va_list ap;
  va_start(ap, f);
  std::vsnprintf(buf, sizeof buf, f, ap);
  va_end(ap);
  return buf;
}

}  // namespace

// ---------------------------------------------------------------------------
// Teach points
// ---------------------------------------------------------------------------

std::string Console::load_points() { return svc_->load_points(cfg_.points_file); }

std::string Console::points_refusal(const TeachResult& r) const {
  switch (r.refusal) {
    case TeachRefusal::program:
      return fmt("refused while program %s is %s (abort it first)", r.program.name.c_str(), to_string(r.program.state));
    case TeachRefusal::arm_state: return fmt("refused while the arm is %s (teach at rest)", to_string(r.arm));
    case TeachRefusal::queued: return "refused while moves are queued";
    case TeachRefusal::none:
    case TeachRefusal::not_homed: break;
  }
  return "";
}

void Console::do_teach(Session& s, const Command& c) {
  TeachRequest rq;
  rq.name = c.word.data();
  rq.tool = sel_tool();  // the session's selection (check mode has its own)
  rq.frame = sel_frame();
  rq.dry = s.check_mode;
  const PointResult r = svc_->teach(rq);
  switch (r.refusal) {
    case PointRefusal::none: break;
    case PointRefusal::not_here:
      if (const std::string no = points_refusal(r.here); !no.empty()) answer_error(s, CmdError::bad_state, "teach: " + no);
      else answer_error(s, r.error, r.reason);
      return;
    case PointRefusal::storage: answer_error(s, r.error, "teach: " + r.reason + "; point not taught, the file kept"); return;
    case PointRefusal::bad_point:
    case PointRefusal::no_point:
    case PointRefusal::joint_count:
    case PointRefusal::program: answer_error(s, r.error, "teach: " + r.reason); return;
  }
  if (s.check_mode) {  // checked: nothing stored, no file written
    answer_ok(s, s.dialect == Dialect::grbl ? "" : fmt("checked: teach %s (check mode: nothing stored)", rq.name.c_str()));
    return;
  }
  const prog::TeachPoint& p = r.point;
  answer_ok(s, fmt("taught %s joints=[%s] pose=[%s] %s%s", p.name.c_str(), joints_text(p.q).c_str(), pose_text(p.q).c_str(),
                   where_text().c_str(), r.kept ? "" : " (not kept: no points file)"));
}

void Console::do_points(Session& s) {
  const prog::PointsData& pts = svc_->points();
  for (const prog::TeachPoint& p : pts.points) {
    s.out += fmt("%s joints=[%s] pose=[%s] tool=%s frame=%s\n", p.name.c_str(), joints_text(p.q).c_str(),
                 cfg_.units.pose_text(p.pose).c_str(), p.tool.c_str(), p.frame.c_str());
  }
  answer_ok(s, fmt("%zu points%s", pts.points.size(), svc_->points_file().empty() ? " (not kept: no points file)" : ""));
}

void Console::do_point_delete(Session& s, const Command& c) {
  const std::string name(c.word.data());
  const PointResult r = svc_->delete_point(name, s.check_mode);
  switch (r.refusal) {
    case PointRefusal::none: break;
    case PointRefusal::program: answer_error(s, r.error, "point delete: " + points_refusal(r.here)); return;
    case PointRefusal::no_point:
      answer_error(s, r.error, fmt("point delete: no point '%s' (%zu points: see points)", name.c_str(), r.count));
      return;
    case PointRefusal::storage: answer_error(s, r.error, "point delete: " + r.reason + "; nothing deleted, the file kept"); return;
    case PointRefusal::not_here:
    case PointRefusal::bad_point:
    case PointRefusal::joint_count: answer_error(s, r.error, "point delete: " + r.reason); return;
  }
  if (s.check_mode) {  // checked: nothing deleted, no file written
    answer_ok(s, s.dialect == Dialect::grbl ? "" : fmt("checked: point delete %s (check mode: nothing deleted)", name.c_str()));
    return;
  }
  answer_ok(s, "deleted " + name);
}

void Console::queue_at_point(Session& s, const Command& c) {
  PointMove pm;
  pm.name = c.word.data();
  pm.line = c.cmd == Cmd::movel;
  if (c.has_speed) pm.speed = pm.line ? cfg_.units.length_in(c.speed) : c.speed;
  if (c.has_blend) pm.blend = pm.line ? cfg_.units.length_in(c.blend) : cfg_.units.angle_in(c.blend);
  DryRun dry;
  if (s.check_mode) dry = dry_run(s);
  const PointResult r = svc_->move_to_point(pm, move_context(s.check_mode ? &dry : nullptr, nullptr));
  switch (r.refusal) {
    case PointRefusal::none: break;
    case PointRefusal::no_point:
      answer_error(s, r.error, fmt("%s: no point '%s' (%zu points: see points)", to_string(c.cmd), pm.name.c_str(), r.count));
      return;
    case PointRefusal::joint_count:
      answer_error(s, r.error, fmt("%s: point '%s' has %d joints, the arm %d", to_string(c.cmd), pm.name.c_str(), r.joints, n_));
      return;
    case PointRefusal::not_here:
    case PointRefusal::bad_point:
    case PointRefusal::program:
    case PointRefusal::storage: answer_error(s, r.error, std::string(to_string(c.cmd)) + ": " + r.reason); return;
  }
  answer_move(s, pm.line ? "movel" : "movej", r.move, s.check_mode ? &dry : nullptr);
}

// ---------------------------------------------------------------------------
// Programs
// ---------------------------------------------------------------------------

void Console::do_programs(Session& s) {
  if (cfg_.programs_dir.empty()) {
    answer_error(s, CmdError::bad_state, "programs: no programs folder (programs.dir, armfw --programs DIR)");
    return;
  }
  std::vector<std::string> names;
  if (const std::string e = prog::list_programs(cfg_.programs_dir, names); !e.empty()) {
    answer_error(s, CmdError::storage, "programs: " + e);
    return;
  }
  for (const std::string& n : names) s.out += n + "\n";
  answer_ok(s, fmt("%zu programs in %s", names.size(), cfg_.programs_dir.c_str()));
}

void Console::exec_step(Session& ps, const prog::Program& p, const prog::ProgramStep& st) {
  const Session* prev = sel_;
  sel_ = &ps;
  // The step as the loader parsed it, with its parameters: the blend tolerance (blend=, or
  // the G-code program's G64 P / G61) in SI, none given (< 0): the configured default; whether
  // the next motion is a line; a point's joints.
  const bool gcode = static_cast<std::size_t>(st.file) < p.files.size() && prog::is_gcode_file(p.files[static_cast<std::size_t>(st.file)]);
  StepParams sp;
  sp.blend = st.blend < 0 ? -1.0
             : gcode      ? st.blend * 1e-3  // G-code: mm
             : st.cmd.cmd == Cmd::movej ? cfg_.units.angle_in(st.blend)
                                        : cfg_.units.length_in(st.blend);
  sp.next_line = &st >= p.steps.data() && &st < p.steps.data() + p.steps.size() &&
                 prog::next_motion_is_line(p, static_cast<std::size_t>(&st - p.steps.data()));
  const prog::PointsData& pts = svc_->points();
  if (st.point >= 0 && static_cast<std::size_t>(st.point) < pts.points.size() && pts.points[static_cast<std::size_t>(st.point)].q.size() == n_)
    sp.point = &pts.points[static_cast<std::size_t>(st.point)].q;
  ++ps.lines_done;
  ps.modal = st.modal;  // the G-code modal state after the line, as parsing it would leave it
  dispatch(ps, st.cmd, &sp);
  sel_ = prev;
}

void Console::do_run(Session& s, const Command& c) {
  const std::string name(c.word.data());
  if (cfg_.programs_dir.empty()) {
    answer_error(s, CmdError::program, "run: no programs folder (programs.dir, armfw --programs DIR)");
    return;
  }
  if (running()) {
    const ProgramStatus p = svc_->program_status();
    answer_error(s, CmdError::bad_state, fmt("run: program %s is %s (abort it first)", p.name.c_str(), to_string(p.state)));
    return;
  }
  if (!s.check_mode) {
    if (!motion_state_ok(s)) return;
    if (!homed_ok(s)) return;
    const Telemetry t = ctl_.telemetry();
    if (t.state != ArmState::idle || !ctl_.motions().empty()) {
      answer_error(s, CmdError::bad_state, fmt("run: needs the arm at rest with nothing queued (it is %s, %zu queued)",
                                               to_string(t.state), ctl_.motions().size()));
      return;
    }
  }
  const std::string path = prog::find_program(cfg_.programs_dir, name);
  if (path.empty()) {
    answer_error(s, CmdError::program, fmt("run: no program '%s' in %s (see programs)", name.c_str(), cfg_.programs_dir.c_str()));
    return;
  }
  if (pcheck_) {
    answer_error(s, CmdError::busy, fmt("run: program %s is being checked (one at a time)", pcheck_->run->name.c_str()));
    return;
  }
  auto r = std::make_unique<ProgramRun>();
  prog::ProgramContext ctx;
  ctx.chain = &chain_;
  ctx.units = cfg_.units;
  ctx.dir = cfg_.programs_dir;
  ctx.points = &svc_->points();
  if (const std::string e = prog::load_program(path, ctx, r->prog); !e.empty()) {
    answer_error(s, CmdError::program, e + "; nothing moved");
    return;
  }
  // The whole-program check runs in slices (continue_check, from settle()): the consoles'
  // realtime characters and other lines are served between two slices; `run` is answered
  // when the check has ended.
  r->name = name;
  auto pc = std::make_unique<PendingCheck>();
  pc->owner = &s;
  pc->run = std::move(r);
  pc->cs.name = "check";
  pc->cs.check_mode = true;
  pc->from = tail();
  pc->cs.check_tail = pc->from;
  pc->tool = svc_->active_tool();
  pc->frame = svc_->active_frame();
  pc->cs.check_tool = pc->tool;
  pc->cs.check_frame = pc->frame;
  pc->shadow = std::make_unique<PathShadow>();
  pc->check_only = s.check_mode;
  pcheck_ = std::move(pc);
  s.checking = true;
  settle(s);
}

void Console::cancel_check(const std::string& why) {
  if (!pcheck_) return;
  Session& o = *pcheck_->owner;
  const std::string name = pcheck_->run->name;
  pcheck_.reset();
  o.checking = false;
  answer_error(o, CmdError::program, fmt("run: %s: check interrupted by %s; nothing moved", name.c_str(), why.c_str()));
}

bool Console::continue_check() {
  if (!pcheck_) return false;
  PendingCheck& pc = *pcheck_;
  Session& o = *pc.owner;
  const prog::Program& p = pc.run->prog;
  std::string err;
  {
    std::swap(check_shadow_, pc.shadow);  // the check's own blend state, whatever other sessions check meanwhile
    const auto t0 = std::chrono::steady_clock::now();
    while (pc.next < p.steps.size() && err.empty()) {
      const prog::ProgramStep& st = p.steps[pc.next++];
      switch (kind_of(st.cmd)) {
        case StepKind::refused:
          err = p.where(st) + ": " + to_string(st.cmd.cmd) +
                " is not run inside a program (enable and home the arm before `run`; stop / abort from the console)";
          continue;
        case StepKind::wait:
        case StepKind::other: continue;
        case StepKind::motion:
        case StepKind::needs_idle: break;
      }
      pc.cs.out.clear();
      pc.cs.last_error = CmdError::ok;
      exec_step(pc.cs, p, st);
      if (pc.cs.last_error != CmdError::ok)
        err = p.where(st) + ": " + to_string(pc.cs.last_error) + ": " + pc.cs.last_error_text;
      if (std::chrono::steady_clock::now() - t0 > std::chrono::milliseconds(2)) break;
    }
    std::swap(check_shadow_, pc.shadow);
  }
  if (err.empty() && pc.next < p.steps.size()) return true;  // more slices to come
  std::unique_ptr<PendingCheck> done = std::move(pcheck_);
  o.checking = false;
  if (!err.empty()) {
    answer_error(o, CmdError::program, err + "; nothing moved");
    return false;
  }
  std::unique_ptr<ProgramRun> r = std::move(done->run);
  const std::string name = r->name;
  const std::string counts = prog::counts_text(prog::count_steps(r->prog));  // as armctl program check says
  if (done->check_only) {
    answer_ok(o, fmt("checked %s: %s; nothing moved (check mode)", name.c_str(), counts.c_str()));
    return false;
  }
  // Checked from where the arm was when the check began: it must still be there, at rest,
  // with the same tool and frame, and no other program may have started meanwhile.
  const Telemetry t = ctl_.telemetry();
  if (running() || t.state != ArmState::idle || !ctl_.motions().empty() || (tail() - done->from).norm() > 1e-9 ||
      svc_->active_tool() != done->tool || svc_->active_frame() != done->frame) {
    answer_error(o, CmdError::bad_state,
                 fmt("run: %s: the arm moved, or the tool / frame / program changed, while it was checked (it is %s); "
                     "nothing moved: run it again", name.c_str(), to_string(t.state)));
    return false;
  }
  r->ps.name = "program " + name;
  run_ = std::move(r);
  const ProgramResult started = svc_->run_program(name, run_->prog, cfg_.units);  // the typed steps, run by the service
  if (!started.ok()) {  // (checked above: the arm at rest, nothing queued, homed)
    answer_error(o, started.error, fmt("run: %s: %s; nothing moved", name.c_str(), to_string(started.refusal)));
    return false;
  }
  answer_ok(o, fmt("running %s: %s", name.c_str(), counts.c_str()));
  return false;
}

void Console::do_pause(Session& s) {
  const ProgramResult r = svc_->program_pause();
  if (r.refusal == ProgramRefusal::no_program) {
    answer_error(s, CmdError::bad_state, "pause: no program runs (`hold` or `!` holds a move)");
    return;
  }
  const bool on = r.status.state != RunState::idle;
  answer_ok(s, fmt("%s %s at %s", on ? to_string(r.status.state) : "ended", on ? r.status.name.c_str() : "",
                   on ? program_where().c_str() : ""));
}

void Console::do_step(Session& s) {
  const ProgramResult r = svc_->program_step();
  switch (r.refusal) {
    case ProgramRefusal::none: break;
    case ProgramRefusal::no_program: answer_error(s, CmdError::bad_state, "step: no program runs"); return;
    case ProgramRefusal::program_state:
    case ProgramRefusal::running:
    case ProgramRefusal::arm_not_ready:
      answer_error(s, CmdError::bad_state, fmt("step: program %s is %s (pause it first)", r.status.name.c_str(), to_string(r.status.state)));
      return;
  }
  const bool on = r.status.state != RunState::idle;
  answer_ok(s, fmt("stepping %s at %s", on ? r.status.name.c_str() : "", on ? program_where().c_str() : "(ended)"));
}

void Console::do_resume(Session& s) {
  const ControlResult c = svc_->resume();
  if (c.error == CmdError::timeout) {
    answer_error(s, CmdError::timeout, "control thread did not answer resume");
    return;
  }
  if (c.reply.result != RtResult::ok && !running()) {
    answer_error(s, c.reply.result == RtResult::fault ? CmdError::fault : CmdError::bad_state, c.reason);
    return;
  }
  svc_->program_tick();
  if (running()) {
    const ProgramStatus p = svc_->program_status();
    answer_ok(s, fmt("%s %s at %s", to_string(p.state), p.name.c_str(), program_where().c_str()));
  } else {
    answer_ok(s, c.reason);
  }
}

std::string Console::program_where() const {
  const ProgramStatus p = svc_->program_status();
  if (p.state == RunState::idle || p.steps == 0) return "-";
  return p.file + ":" + std::to_string(p.line);
}

std::string Console::program_text() const {
  const ProgramStatus p = svc_->program_status();
  if (p.state == RunState::idle) return "";
  return fmt("program=%s program_state=%s line=%s", p.name.c_str(), to_string(p.state), program_where().c_str());
}

void Console::end_program(ProgramEnd how, bool realtime) {
  if (pcheck_) {  // a stop, e-stop, disable or Ctrl-X ends a pending check as it ends a program
    switch (how) {
      case ProgramEnd::estop: cancel_check(realtime ? "e-stop (Ctrl-X)" : "e-stop"); break;
      case ProgramEnd::soft_reset: cancel_check("soft reset (Ctrl-X)"); break;
      case ProgramEnd::stop:
      case ProgramEnd::disable:
      case ProgramEnd::abort: cancel_check(to_string(how)); break;
      case ProgramEnd::none:
      case ProgramEnd::done:
      case ProgramEnd::fault:
      case ProgramEnd::arm_state:
      case ProgramEnd::queue_dropped:
      case ProgramEnd::step_refused: break;  // (the runner's own ends: no check is pending while a program runs)
    }
  }
  svc_->program_abort(how, realtime);
}

std::string Console::program_line(const ArmEvent& e) const {
  if (e.program != ProgramPhase::ended) return "";
  const ProgramNames n = svc_->event_program(e);
  const std::string name(n.program);
  if (e.end == ProgramEnd::done)
    return "program: " + name + " done: " + count_text(static_cast<long long>(e.steps), "step") + " in " +
           fixed(e.seconds, kTimeDecimals) + " s";
  const std::string at = e.steps == 0 || n.file.empty() ? "-" : std::string(n.file) + ":" + std::to_string(e.line);
  const std::string detail(svc_->event_detail(e));
  std::string why;
  switch (e.end) {
    case ProgramEnd::none:
    case ProgramEnd::done: break;
    case ProgramEnd::stop: why = "stop"; break;
    case ProgramEnd::estop: why = e.realtime ? "e-stop (Ctrl-X)" : "e-stop"; break;
    case ProgramEnd::soft_reset: why = "soft reset (Ctrl-X)"; break;
    case ProgramEnd::disable: why = "disable"; break;
    case ProgramEnd::abort: why = "abort"; break;
    case ProgramEnd::fault: why = "fault " + detail; break;
    case ProgramEnd::arm_state:
      why = e.state == ArmState::boot || e.state == ArmState::disabled ? std::string("the arm was disabled")
                                                                       : std::string("the arm is ") + to_string(e.state);
      break;
    case ProgramEnd::queue_dropped: why = "the motion queue was dropped"; break;
    case ProgramEnd::step_refused: why = std::string(to_string(e.error)) + ": " + detail; break;
  }
  return "program: " + name + " aborted at " + at + ": " + why;
}

void Console::tick() {
  svc_->tick();  // a record sample, the running program's next steps
  if (!running()) run_.reset();  // the service's run ended: its steps are no longer run
}

// ---------------------------------------------------------------------------
// Record and playback
// ---------------------------------------------------------------------------

void Console::do_record(Session& s, const Command& c) {
  if (s.check_mode) {  // a check changes nothing: no recording started or stopped, no file written
    answer_ok(s, "check mode: not run");
    return;
  }
  if (c.record_mcap) {  // an MCAP file of the telemetry, setpoints and events (docs/foxglove-mcap.md)
    if (!c.record_stop) {
      const std::string e = svc_->record_mcap_start(c.rate > 0 ? c.rate : svc_->mcap_settings().rate_hz);
      if (!e.empty()) return answer_error(s, CmdError::bad_state, "record mcap: " + e);
      const McapStatus st = svc_->mcap_status();
      answer_ok(s, fmt("recording MCAP at %g Hz to %s", st.rate_hz, st.file.c_str()));
      return;
    }
    if (!svc_->mcap_status().active && svc_->mcap_status().error.empty())
      return answer_error(s, CmdError::bad_state, "record mcap stop: no MCAP recording (record mcap first)");
    const McapStatus st = svc_->record_mcap_stop();
    answer_ok(s, fmt("recorded MCAP %s: %d files, %llu frames at %g Hz, %llu missed, %llu events, %llu bytes%s%s", st.file.c_str(), st.files,
                     static_cast<unsigned long long>(st.frames), st.rate_hz, static_cast<unsigned long long>(st.missed),
                     static_cast<unsigned long long>(st.events), static_cast<unsigned long long>(st.bytes),
                     st.error.empty() ? "" : "; ended: ", st.error.c_str()));
    return;
  }
  if (!c.record_stop) {
    const RecordResult r = svc_->record_start(c.rate > 0 ? c.rate : cfg_.record_rate_hz);
    switch (r.refusal) {
      case RecordRefusal::none: answer_ok(s, fmt("recording at %g Hz: jog, then record stop NAME", r.rate_hz)); return;
      case RecordRefusal::recording:
        answer_error(s, r.error, fmt("record: already recording (%zu samples): record stop NAME", r.samples));
        return;
      case RecordRefusal::not_homed: answer_error(s, r.error, r.reason); return;
      case RecordRefusal::not_recording:
      case RecordRefusal::bad_value: answer_error(s, r.error, std::string("record: ") + to_string(r.refusal)); return;
    }
    return;
  }
  if (!svc_->recording()) {
    answer_error(s, CmdError::bad_state, "record stop: nothing is recorded (record start first)");
    return;
  }
  std::string name(c.word.data());
  if (cfg_.programs_dir.empty()) {
    answer_error(s, CmdError::storage, "record stop: no programs folder (programs.dir, armfw --programs DIR); still recording");
    return;
  }
  const double tol = c.tolerance > 0 ? cfg_.units.angle_in(c.tolerance) : cfg_.record_tolerance;
  const RecordResult r = svc_->record_path(tol);
  if (!r.ok()) {
    answer_error(s, r.error, std::string("record stop: ") + to_string(r.refusal) + "; still recording");
    return;
  }
  const ConsoleUnits& u = cfg_.units;
  std::string text = fmt("# recorded by armfw: record stop %s (%zu samples at %g Hz; within %g %s of the recorded path)\n",
                         name.c_str(), r.samples, r.rate_hz, u.angle_out(tol), u.angle_name());
  int moves = 0;
  for (std::size_t k = 0; k < r.waypoints.size(); ++k) {
    std::string line = "movej";
    for (int j = 0; j < n_; ++j) line += fmt(" %.10g", to_user(j, r.waypoints[k][j]));
    line += fmt(" speed=%g", motion().default_joint_speed_pct);
    if (k > 0 && k + 1 < r.waypoints.size()) line += fmt(" blend=%.6g", u.angle_out(r.blend));
    text += line + "\n";
    ++moves;
  }
  if (name.size() < 4 || name.compare(name.size() - 4, 4, prog::kNativeExtension) != 0) name += prog::kNativeExtension;
  const std::string path = cfg_.programs_dir + "/" + name;
  if (const std::string e = kin::write_text_file_atomic(path, text); !e.empty()) {
    answer_error(s, CmdError::storage, "record stop: " + e + "; still recording");
    return;
  }
  svc_->record_stop();
  answer_ok(s, fmt("recorded %s: %d moves from %zu samples", name.c_str(), moves, r.samples));
}

// ---------------------------------------------------------------------------
// Digital outputs
// ---------------------------------------------------------------------------

void Console::do_out(Session& s, const Command& c) {
  const auto& outs = motion().outputs;
  if (c.out_index == -1) {  // list
    for (std::size_t k = 0; k < outs.size(); ++k) {
      const ConsoleConfig::Output& o = outs[k];
      s.out += fmt("%s joint=%d bit=%d %s\n", o.name.c_str(), o.joint + 1, o.bit, svc_->output_on(k) ? "on" : "off");
    }
    answer_ok(s, fmt("%zu outputs", outs.size()));
    return;
  }
  OutputRequest rq;
  rq.on = c.out_on;
  rq.sync = c.out_sync;
  rq.dry = s.check_mode;
  rq.index = outs.size();
  if (c.out_index == -2) {  // by name
    for (std::size_t k = 0; k < outs.size(); ++k)
      if (outs[k].name == c.word.data()) rq.index = k;
    if (rq.index == outs.size()) {
      answer_error(s, CmdError::bad_option, fmt("out: no output '%s' (%zu outputs: [[output]] in the configuration)", c.word.data(), outs.size()));
      return;
    }
  } else {
    rq.index = static_cast<std::size_t>(c.out_index);
  }
  const OutputResult r = svc_->set_output(rq);
  switch (r.refusal) {
    case OutputRefusal::none: break;
    case OutputRefusal::no_output:
      answer_error(s, r.error, fmt("M6%d P%d: no output %d (%zu outputs: [[output]], 0-based)", c.out_sync ? (c.out_on ? 2 : 3) : (c.out_on ? 4 : 5),
                                   c.out_index, c.out_index, r.count));
      return;
    case OutputRefusal::sync_full:
      answer_error(s, r.error, fmt("M62/M63: outputs of more than %zu drives wait for the next move", kMotionOutputs));
      return;
    case OutputRefusal::queue_full: answer_error(s, r.error, "out: output queue full; not set"); return;
  }
  const ConsoleConfig::Output& o = outs[rq.index];
  if (s.check_mode) answer_ok(s, s.dialect == Dialect::grbl ? "" : "checked");
  else if (c.out_sync) answer_ok(s, fmt("%s %s at the start of the next move", o.name.c_str(), c.out_on ? "on" : "off"));
  else answer_ok(s, fmt("%s %s", o.name.c_str(), c.out_on ? "on" : "off"));
}

}  // namespace servoarm::fw
