// SPDX-License-Identifier: Apache-2.0
#include "servoarm/console/console.hpp"

#include <utility>

#include <chrono>
#include <cstdarg>
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <memory>
#include <thread>

#include "servoarm/lang/command_table.hpp"
#include "servoarm/lang/ik_options.hpp"
#include "servoarm/lang/text.hpp"
#include "servoarm/kinematics/motion_ik.hpp"
#include "servoarm/kinematics/orientation.hpp"
#include "servoarm/kinematics/ik.hpp"

namespace servoarm::fw {

namespace {
/// GRBL 1.1's error numbers (grbl/report.h) for our codes, where one applies.
int grbl_error(CmdError e) {
  switch (e) {
    case CmdError::ok: return 0;
    case CmdError::overlong: return 11;         // line overflow
    case CmdError::binary: return 1;            // expected command letter
    case CmdError::unknown_command: return 20;  // unsupported command (a '$' one: 3)
    case CmdError::arg_count: return 28;        // value word missing / wrong count
    case CmdError::bad_number: return 2;        // bad number format
    case CmdError::not_finite: return 2;
    case CmdError::bad_option: return 20;
    case CmdError::out_of_range: return 33;     // invalid target (also F <= 0)
    case CmdError::unsupported: return 20;
    case CmdError::checksum: return 20;
    case CmdError::busy: return 8;              // not idle
    case CmdError::bad_state: return 9;         // locked (alarm / jog state)
    case CmdError::fault: return 9;
    case CmdError::unreachable: return 15;      // (jog) target exceeds travel
    case CmdError::limits: return 15;
    case CmdError::singular: return 33;
    case CmdError::branch: return 33;
    case CmdError::plan_failed: return 33;
    case CmdError::timeout: return 20;
    case CmdError::estop: return 9;
    case CmdError::storage: return 7;           // setting read fail (GRBL's EEPROM error)
    case CmdError::not_homed: return 9;        // locked (GRBL: alarm until homed)
    case CmdError::program: return 33;       // invalid target (a program line refused)
    case CmdError::internal: return 20;
  }
  return 20;
}
constexpr double kDeg = M_PI / 180.0;

/// Commands that move the arm or queue motion (refused from other consoles while a program runs).
bool moves_arm(const Command& c) {
  switch (c.cmd) {
    case Cmd::home:
    case Cmd::movej:
    case Cmd::movel:
    case Cmd::dwell:
    case Cmd::gmove:
    case Cmd::park:
    case Cmd::grbl_jog:
    case Cmd::grbl_home:
    case Cmd::freedrive_on: return true;
    case Cmd::jog: return c.jog_op == JogOp::increment || c.jog_op == JogOp::continuous;
    case Cmd::out: return c.out_sync && c.out_index != -1;  // M62/M63 ride on the program's next move
    case Cmd::none:
    case Cmd::help:
    case Cmd::status:
    case Cmd::enable:
    case Cmd::disable:
    case Cmd::stop:
    case Cmd::estop:
    case Cmd::reset:
    case Cmd::fk:
    case Cmd::ik:
    case Cmd::limits:
    case Cmd::stats:
    case Cmd::config:
    case Cmd::wait:
    case Cmd::hold:
    case Cmd::resume:
    case Cmd::position:
    case Cmd::home_zero:
    case Cmd::temperature:
    case Cmd::tool:
    case Cmd::frame:
    case Cmd::grbl_settings:
    case Cmd::grbl_params:
    case Cmd::grbl_state:
    case Cmd::grbl_info:
    case Cmd::grbl_unlock:
    case Cmd::grbl_check:
    case Cmd::grbl_help:
    case Cmd::teach:
    case Cmd::points:
    case Cmd::point_delete:
    case Cmd::programs:
    case Cmd::run:  // refused by itself while a program runs (one program at a time)
    case Cmd::pause:
    case Cmd::step:
    case Cmd::abort:
    case Cmd::record:
    case Cmd::freedrive:
    case Cmd::freedrive_off:
    case Cmd::collision_on:
    case Cmd::collision_off:
    case Cmd::safety:
    case Cmd::safety_normal:
    case Cmd::safety_reduced:
    case Cmd::safety_stage:
    case Cmd::safety_confirm:
    case Cmd::quit: return false;
  }
  return false;
}

/// Commands whose move takes the waiting M62/M63 changes (movej, movel, G0/G1, park / G28).
bool carries_outputs(Cmd c) { return c == Cmd::movej || c == Cmd::movel || c == Cmd::gmove || c == Cmd::park; }

std::string fmt(const char* f, ...) __attribute__((format(printf, 1, 2)));
/// printf into a string sized for the text: an answer is never cut.
std::string fmt(const char* f, ...) {
  va_list ap, again;
  va_start(ap, f);
  va_copy(again, ap);
  const int n = std::vsnprintf(nullptr, 0, f, ap);
  va_end(ap);
  std::string out(n > 0 ? static_cast<std::size_t>(n) : 0, '\0');
  if (n > 0) std::vsnprintf(out.data(), out.size() + 1, f, again);
  va_end(again);
  return out;
}

/// A position (m) as G-code and GRBL print it: "x,y,z" in mm to 0.001 mm.
std::string mm_triple(const Eigen::Vector3d& p, const char* sep = ",") {
  return fixed(p.x() * 1e3, 3) + sep + fixed(p.y() * 1e3, 3) + sep + fixed(p.z() * 1e3, 3);
}

/// A model part's refusal (a fixed line of the model's): whole, or cut after a word with "...".
std::string refusal_text(const ModelControl& m, ModelPart p) { return bounded_text(m.refusal(p), ModelControl::kLine); }

}  // namespace

Console::Console(Controller& ctl, const ConsoleConfig& cfg, const kin::IkModel* ik)
    : ctl_(ctl), cfg_(cfg), chain_(ctl.chain()), n_(ctl.chain().n_joints), ik_(ik) {
  svc_ = std::make_unique<ArmService>(ctl_, cfg_);
  static_cast<MotionSettings&>(cfg_) = MotionSettings{};  // the service keeps them: config() reads them there
  svc_->set_ik_model(ik_);
  check_shadow_ = std::make_unique<PathShadow>();
}

// IK of movel's path check and of the control thread's Cartesian sampling: the App's
// model (closed form or numeric) when the chain has one, else the damped-Newton fallback.
// The firmware's options (ik_options.hpp), the same armctl plan previews with.
ConsoleConfig Console::config() const {
  ConsoleConfig c = cfg_;
  static_cast<MotionSettings&>(c) = svc_->settings();
  return c;
}

kin::IkSolver Console::ik_solver() const { return svc_->tool_ik(sel_tool()); }

kin::Pose Console::tcp(const kin::JointVector& q) const {
  kin::Pose p = kin::Pose::Identity();
  if (kin::forward(tool_chain(), q, p) != kin::Status::ok) p.translation().setConstant(std::nan(""));
  return p;
}

kin::Pose Console::pose_in_frame(const kin::JointVector& q) const { return user_frame().inverse() * tcp(q); }

std::string Console::where_text() const {
  return "tool=" + svc_->tool(sel_tool()).name + " frame=" + svc_->frame(sel_frame()).name;
}

double Console::to_si(int j, double user) const {
  return cfg_.units.joint_in(chain_, j, user);
}
double Console::to_user(int j, double si) const {
  return cfg_.units.joint_out(chain_, j, si);
}

kin::JointVector Console::tail() const { return svc_->tail(); }

std::string Console::joints_text(const kin::JointVector& q) const {
  std::string s;
  const ConsoleUnits& u = cfg_.units;
  for (int j = 0; j < q.size(); ++j) s += (j ? " " : "") + u.joint_text(chain_, j, q[j]);
  return s;
}

std::string Console::pose_text(const kin::JointVector& q) const {
  kin::Pose p;
  p = pose_in_frame(q);
  if (!p.translation().allFinite()) return "x=nan";
  return cfg_.units.pose_text(p);
}

void Console::answer_error(Session& s, CmdError e, const std::string& msg) {
  s.last_error = e;
  s.last_error_text = msg;
  if (s.dialect == Dialect::grbl) {
    // GRBL senders match `error:N`; the text goes on a [MSG:] line before it.
    s.out += fmt("[MSG:%s: %s]\nerror:%d\n", to_string(e), msg.c_str(), grbl_error(e));
    return;
  }
  s.out += "error: ";
  s.out += to_string(e);
  s.out += ' ';
  s.out += msg;
  s.out += '\n';
}

void Console::answer_ok(Session& s, const std::string& data) {
  if (s.dialect == Dialect::grbl) {
    if (!data.empty()) s.out += "[MSG:" + data + "]\n";
    s.out += "ok\n";
    return;
  }
  s.out += data.empty() ? "ok\n" : "ok " + data + "\n";
}

bool Console::last_answer_is_error(const Session& s, std::size_t from) const {
  if (s.out.size() <= from || s.out.back() != '\n') return false;
  const std::size_t nl = s.out.rfind('\n', s.out.size() - 2);
  const std::size_t at = nl == std::string::npos || nl < from ? from : nl + 1;
  return s.out.compare(at, 6, "error:") == 0;
}

void Console::note_line(Session& s, const std::string& text) {
  if (text.empty()) return;
  s.out += s.dialect == Dialect::grbl ? "[MSG:" + text + "]\n" : text + "\n";
}

void Console::note_before_answer(Session& s, std::size_t from, const std::string& text) {
  if (text.empty() || s.out.size() <= from) return;
  const std::size_t nl = s.out.rfind('\n', s.out.size() - 2);
  const std::size_t at = nl == std::string::npos || nl < from ? from : nl + 1;
  // GRBL: the answer's [MSG:] line stays right before its error:N
  std::size_t ins = at;
  if (s.dialect == Dialect::grbl && at > from) {
    const std::size_t p = s.out.rfind('\n', at - 2);
    const std::size_t msg = p == std::string::npos || p < from ? from : p + 1;
    if (s.out.compare(msg, 5, "[MSG:") == 0) ins = msg;
  }
  s.out.insert(ins, s.dialect == Dialect::grbl ? "[MSG:" + text + "]\n" : text + "\n");
}

std::string Console::discard_sync_outputs(const char* why) {
  const std::span<const OutputChange> pending = svc_->pending_outputs();
  if (pending.empty()) return {};
  std::string names;
  for (const OutputChange& ch : pending)
    for (const ConsoleConfig::Output& o : motion().outputs)
      if (o.joint == ch.joint && ((ch.mask >> o.bit) & 1u))
        names += fmt("%s%s %s", names.empty() ? "" : ", ", o.name.c_str(), ((ch.value >> o.bit) & 1u) ? "on" : "off");
  svc_->clear_pending_outputs();
  return fmt("outputs: M62/M63 change%s waiting for the next move discarded (%s): %s",
             names.find(',') == std::string::npos ? "" : "s", why, names.c_str());
}

bool Console::request(const Request& rq, Reply& out) { return svc_->request(rq, out); }
bool Console::request(RequestOp op, Reply& out) { return svc_->request(op, out); }

void Console::answer_control(Session& s, const ControlResult& c) {
  if (c.ok()) answer_ok(s, c.reason);
  else answer_error(s, c.error, c.reason);
}

const char* to_string(Dialect d) {
  switch (d) {
    case Dialect::native: return "native";
    case Dialect::grbl: return "grbl";
  }
  return "?";
}

kin::JointVector Console::commanded_joints() const {
  const Telemetry t = ctl_.telemetry();
  kin::JointVector q(n_);
  for (int j = 0; j < n_; ++j) q[j] = t.q_cmd[static_cast<std::size_t>(j)];
  return q;
}

kin::Pose Console::commanded_pose() const { return tcp(commanded_joints()); }

std::string Console::status_text() const {
  const ArmStatus st = svc_->status();
  const ConsoleUnits& u = cfg_.units;
  // the joints' units: the angle unit, or one per joint when a joint is prismatic (a length)
  std::string ju = u.angle_name();
  bool prismatic = false;
  for (int j = 0; j < n_; ++j) prismatic = prismatic || std::string_view(u.joint_name(chain_, j)) != u.angle_name();
  if (prismatic) {
    ju.clear();
    for (int j = 0; j < n_; ++j) ju += std::string(j ? "," : "") + u.joint_name(chain_, j);
  }
  std::string s = fmt("state=%s%s queue=%u joints=[%s] %s pose=[%s] %s,%s %s", to_string(st.state), st.holding ? " hold=1" : "",
                      unsigned(st.queued), joints_text(st.q).c_str(), ju.c_str(), pose_text(st.q).c_str(), u.length_name(),
                      u.angle_name(), where_text().c_str());
  s += " homing=[";
  for (std::size_t j = 0; j < st.homing.size(); ++j) s += std::string(j ? " " : "") + to_string(st.homing[j]);
  s += "]";
  s += fmt(" feed_override=%d%%", st.feed_pct);
  if (st.temperature.size() > 0 && st.temperature.array().isFinite().any()) {  // drives that report one
    s += " temperature_c=[";
    for (int j = 0; j < st.temperature.size(); ++j)
      s += (j ? " " : "") + (std::isfinite(st.temperature[j]) ? fmt("%.0f", st.temperature[j]) : std::string("-"));
    s += "]";
    if (st.temperature_warning != 0) {
      s += " hot=[";
      for (int j = 0, k = 0; j < st.temperature.size(); ++j)
        if ((st.temperature_warning >> j) & 1u) s += fmt("%s%d", k++ ? " " : "", j + 1);
      s += "]";
    }
  }
  if (running()) s += " " + program_text();
  if (svc_->recording()) s += fmt(" recording=%zu", svc_->record_samples());
  if (st.feed_forward != FeedForwardKind::off || st.collision_on || st.freedrive != FreedrivePhase::off)  // (the dynamics parts, when one runs)
    s += fmt(" feed_forward=%s collision=%s freedrive=%s", to_string(st.feed_forward), st.collision_on ? "on" : "off",
             to_string(st.freedrive));
  if (st.safety_on)
    s += fmt(" safety=%s checksum=%08X", kin::to_string(st.safety_mode), static_cast<unsigned>(st.safety_checksum));
  if (!st.fault_text.empty()) s += fmt(" fault=\"%s\"", st.fault_text.c_str());
  return s;
}

std::string Console::safety_text() const {
  const ArmStatus st = svc_->status();
  if (!st.safety_on) return "safety=off";
  const Telemetry tel = ctl_.telemetry();
  std::string s = fmt("safety=on mode=%s checksum=%08X stops=%u", kin::to_string(st.safety_mode),
                      static_cast<unsigned>(st.safety_checksum), static_cast<unsigned>(tel.safety_stops));
  if (tel.safety_zone >= 0) s += fmt(" zone=reduced_plane_%d", static_cast<int>(tel.safety_zone));
  s += fmt(" speed_scale=%.2f", tel.speed_scale);  // the run-time speed scale (docs/safety.md#speed-scaling)
  // the mode's limits that are set, in the [safety] keys' units (docs/safety.md)
  const kin::SafetyConfig& env = svc_->settings().safety;
  const kin::SafetyLimits& lim = env.limits(tel.safety_zone >= 0 ? kin::SafetyMode::reduced : st.safety_mode);
  const NamedPose& tool = svc_->tool(svc_->active_tool());
  s += fmt(" tool=%s tool_radius_mm=%g", tool.name.c_str(), svc_->tool_radius(tool) * 1e3);
  if (lim.tcp_speed > 0) s += fmt(" tcp_speed_mm_s=%g", lim.tcp_speed * 1e3);
  if (lim.elbow_speed > 0 && env.elbow_frame >= 0) s += fmt(" elbow_speed_mm_s=%g", lim.elbow_speed * 1e3);
  const int n = std::min(chain_.n_joints, kin::kMaxJoints);
  std::string js;
  bool any = false;
  for (int j = 0; j < n; ++j) {
    const double v = lim.joint_speed[static_cast<std::size_t>(j)];
    any = any || v > 0;
    js += fmt("%s%g", j ? "," : "", ((env.prismatic >> j) & 1u) ? v * 1e3 : v * 180.0 / M_PI);
  }
  if (any) s += " joint_speed_deg_s=[" + js + "]";
  if (lim.stop_time > 0) s += fmt(" stop_time_s=%g", lim.stop_time);
  if (lim.stop_distance > 0) s += fmt(" stop_distance_mm=%g", lim.stop_distance * 1e3);
  if (lim.momentum > 0) s += fmt(" momentum_kg_m_s=%g", lim.momentum);
  if (lim.power > 0) s += fmt(" power_w=%g", lim.power);
  if (env.self_collision)
    s += fmt(" self_collision_margin_mm=%g capsule_pairs=%d", env.self_collision_margin * 1e3,
             kin::capsule_pair_count(chain_));
  return s;
}

std::string Console::dynamics_text() const {
  const Telemetry t = ctl_.telemetry();
  const ModelControl* m = ctl_.model();
  std::string s = fmt("freedrive=%s feed_forward=%s collision=%s", to_string(static_cast<FreedrivePhase>(t.freedrive)),
                      to_string(static_cast<FeedForwardKind>(t.feed_forward)), t.collision_on ? "on" : "off");
  if (t.collision_on || t.collisions > 0)
    s += fmt(" peak=%.2f joint=%d alarms=%llu", t.collision_peak, t.collision_peak_joint + 1,
             static_cast<unsigned long long>(t.collisions));
  if (m == nullptr || !m->configured()) return s + " (no dynamic model)";
  for (const ModelPart p : {ModelPart::feed_forward, ModelPart::collision, ModelPart::freedrive})
    if (!m->available(p)) s += fmt("\n%s unavailable: %s", to_string(p), refusal_text(*m, p).c_str());
  return s;
}

std::string Console::unhomed_refusal(const Telemetry& t) const { return svc_->unhomed_reason(t); }

// The position field of a GRBL report, in mm, of the active tool's point: `MPos:` (the base
// frame) with no user frame active; with one, `WPos:` in it and `WCO:` its origin in the
// base (what GRBL reports for a work offset; a sender shows WPos either way).
std::string Console::grbl_position(const kin::JointVector& q) const {
  if (svc_->active_frame() == 0) {
    const kin::Pose p = tcp(q);
    return "MPos:" + mm_triple(p.translation());
  }
  const kin::Pose w = pose_in_frame(q);
  return "WPos:" + mm_triple(w.translation()) + "|WCO:" + mm_triple(svc_->frame(svc_->active_frame()).pose.translation());
}

std::string Console::grbl_wcs() const {
  const std::string& n = svc_->frame(sel_frame()).name;
  if (n.size() == 3 && n[0] == 'g' && n[1] == '5' && n[2] >= '4' && n[2] <= '9') return "G" + n.substr(1);
  return "G54";  // base or a named frame: GRBL has no word for it (`frame` says which)
}

std::string Console::grbl_report() const {
  const Telemetry t = ctl_.telemetry();
  const char* st = "Idle";
  switch (t.state) {
    case ArmState::boot: st = "Boot"; break;
    case ArmState::disabled: st = "Disabled"; break;
    case ArmState::enabling: st = "Enabling"; break;
    case ArmState::idle: st = "Idle"; break;
    case ArmState::moving: st = t.holding ? "Hold" : "Run"; break;
    case ArmState::stopping: st = "Stop"; break;
    case ArmState::fault: st = "Alarm"; break;
    case ArmState::estop: st = "Estop"; break;
    case ArmState::jogging: st = "Jog"; break;
    case ArmState::homing: st = "Home"; break;
    case ArmState::freedrive: st = "Freedrive"; break;
  }
  kin::JointVector q(n_);
  for (int j = 0; j < n_; ++j) q[j] = t.q_act[static_cast<std::size_t>(j)];
  std::string s = fmt("<%s|%s|J:", st, grbl_position(q).c_str());
  // MPos: G-code lengths (mm, as GRBL reports them); J: the console's joint units.
  const int d = cfg_.units.angle == AngleUnit::deg && cfg_.units.length == LengthUnit::mm ? 2 : 5;
  for (int j = 0; j < n_; ++j) s += (j ? "," : "") + fixed(to_user(j, q[j]), d);
  s += fmt("|Q:%u|Ov:%d", unsigned(t.queued), svc_->feed_override());
  if (running()) {
    const ProgramStatus p = svc_->program_status();
    s += fmt("|Pgm:%s,%s,%s", p.name.c_str(), to_string(p.state), program_where().c_str());
  }
  return s + ">";
}

std::string Console::grbl_report(const Session& s) const {
  if (s.dialect != Dialect::grbl) return grbl_report();
  // GRBL 1.1: <State|MPos:x,y,z|FS:feed,spindle|Ov:feed,rapid,spindle|Bf:blocks,bytes>
  const Telemetry t = ctl_.telemetry();
  const char* st = "Idle";
  switch (t.state) {
    case ArmState::boot:
    case ArmState::disabled:
    case ArmState::fault:
    case ArmState::estop: st = "Alarm"; break;  // GRBL locks out motion until $X
    case ArmState::enabling:
    case ArmState::stopping: st = "Run"; break;
    case ArmState::idle: st = s.check_mode ? "Check" : "Idle"; break;
    case ArmState::moving: st = t.mode == Mode::held ? "Hold:0" : t.holding ? "Hold:1" : "Run"; break;
    case ArmState::jogging: st = "Jog"; break;
    case ArmState::homing: st = "Home"; break;
    case ArmState::freedrive: st = "Hold:0"; break;  // hand guiding: a sender must not stream moves
  }
  kin::JointVector q(n_);
  for (int j = 0; j < n_; ++j) q[j] = t.q_act[static_cast<std::size_t>(j)];
  std::size_t pending = s.partial.size();
  for (const std::string& l : s.lines) pending += l.size() + 1;
  const long rx_free = static_cast<long>(kGrblRxBuffer) - static_cast<long>(pending);
  const long blocks_free = static_cast<long>(kMotionQueue) - static_cast<long>(t.queued);
  std::string pgm;  // GRBL 1.1's Ln: (the line), and the program and its state
  if (const ProgramStatus p = svc_->program_status(); p.state != RunState::idle && p.running < p.steps)
    pgm = fmt("|Ln:%d|Pgm:%s,%s", p.running_line, p.name.c_str(), to_string(p.state));
  return fmt("<%s|%s|FS:%.0f,0|Ov:%d,100,100|Bf:%ld,%ld%s>", st, grbl_position(q).c_str(), feed_now_ * 60e3, svc_->feed_override(),
             blocks_free < 0 ? 0 : blocks_free, rx_free < 0 ? 0 : rx_free, pgm.c_str());
}

std::string Console::stats_text() const {
  const Telemetry t = ctl_.telemetry();
  auto one = [](const StatSummary& s) {
    return fmt("{min=%.1f mean=%.1f p99=%.1f max=%.1f}", s.min_us, s.mean_us, s.p99_us, s.max_us);
  };
  std::string s = fmt("cycles=%llu overruns=%llu rate_hz=%.0f latency_us=%s compute_us=%s max_following_error_deg=%.4f",
                      static_cast<unsigned long long>(t.cycles), static_cast<unsigned long long>(t.overruns),
                      ctl_.config().rate_hz, one(t.latency).c_str(), one(t.compute).c_str(), t.max_following_error / kDeg);
  if (t.estop_latency_ns >= 0) s += fmt(" estop_latency_us=%.1f", static_cast<double>(t.estop_latency_ns) / 1e3);
  if (t.feed_forward != 0 || t.collision_on)  // the model's figures, when a part runs
    s += fmt(" feed_forward_cycles=%llu collision_peak=%.2f collision_peak_joint=%d collisions=%llu",
             static_cast<unsigned long long>(t.feed_forward_cycles), t.collision_peak, t.collision_peak_joint + 1,
             static_cast<unsigned long long>(t.collisions));
  const auto dropped = ctl_.events_dropped();
  if (dropped) s += fmt(" events_dropped=%llu", static_cast<unsigned long long>(dropped));
  if (output_dropped_lines_ || output_dropped_bytes_)
    s += fmt(" output_dropped_lines=%llu output_dropped_bytes=%llu", static_cast<unsigned long long>(output_dropped_lines_),
             static_cast<unsigned long long>(output_dropped_bytes_));
  return s;
}

std::string Console::drain_events() {
  std::string native, grbl;
  drain_events(native, grbl);
  return native;
}

void Console::drain_events(std::string& native, std::string& grbl) {
  tick();
  svc_->poll_events();
  const EventBatch b = svc_->events_since(events_seen_);
  if (b.missed > 0) {  // another reader polled the stream faster than this console read it
    native += fmt("alarm: %llu events missed\n", static_cast<unsigned long long>(b.missed));
    grbl += fmt("[MSG:%llu events missed]\n", static_cast<unsigned long long>(b.missed));
  }
  for (const ArmEvent& e : b.events) render_event(e, native, grbl);
  if (!b.events.empty()) events_seen_ = b.events.back().seq;
}

void Console::render_event(const ArmEvent& e, std::string& native, std::string& grbl) {
  // the control thread's line, from its fixed buffer: whole, or cut after a word with "..."
  const std::string detail = bounded_text(std::string(svc_->event_detail(e)).c_str(), sizeof(Event::message));
  switch (e.kind) {
    case ArmEventKind::fault:
      native += fmt("alarm: fault %s\n", detail.c_str());
      // ALARM:1 hard limit (a drive or supervisor fault), 2 soft limit (a setpoint outside the limits),
      // 9 homing fail (GRBL: the switch not found)
      grbl += fmt("ALARM:%d\n[MSG:fault %s]\n",
                  e.cause == FaultCause::setpoint_position ? 2 : e.cause == FaultCause::homing_failed ? 9 : 1, detail.c_str());
            break;
    case ArmEventKind::estop: {
      // The control thread's text is "emergency stop" (a command), or "emergency stop: " and
      // the cause (an input: "e-stop input gpio:gpiochip0:17 asserted"): the cause is shown.
      constexpr std::string_view kPlain = "emergency stop";
      std::string_view cause = detail;
      if (cause == kPlain) cause = {};
      else if (cause.substr(0, kPlain.size() + 2) == "emergency stop: ") cause.remove_prefix(kPlain.size() + 2);
      if (cause.empty()) {
        native += "alarm: estop (send reset, then enable)\n";
        grbl += "ALARM:10\n[MSG:e-stop: $X to reset and enable]\n";  // grblHAL: 10 = e-stop
      } else {
        const int n = static_cast<int>(cause.size());
        native += fmt("alarm: estop: %.*s (send reset, then enable)\n", n, cause.data());
        grbl += fmt("ALARM:10\n[MSG:e-stop: %.*s ($X to reset and enable)]\n", n, cause.data());
      }
      break;
    }
    case ArmEventKind::motion_refused:
      native += fmt("alarm: %s\n", detail.c_str());
      grbl += fmt("[MSG:%s]\n", detail.c_str());
      break;
    case ArmEventKind::jog_stopped:
      native += fmt("alarm: %s\n", detail.c_str());
      grbl += fmt("[MSG:%s]\n", detail.c_str());
            break;
    case ArmEventKind::homing:
      native += fmt("homing: %s\n", detail.c_str());
      grbl += fmt("[MSG:homing: %s]\n", detail.c_str());
      break;
    case ArmEventKind::warning:
      native += fmt("warning: %s\n", detail.c_str());
      grbl += fmt("[MSG:warning: %s]\n", detail.c_str());
      break;
    case ArmEventKind::freedrive:
      native += fmt("freedrive: %s\n", detail.c_str());
      grbl += fmt("[MSG:freedrive: %s]\n", detail.c_str());
      break;
    case ArmEventKind::program:
      if (const std::string l = program_line(e); !l.empty()) {
        native += l + "\n";
        grbl += "[MSG:" + l + "]\n";  // GRBL: as a [MSG:] line
      }
      break;
    case ArmEventKind::motion_done:
    case ArmEventKind::state: break;
  }
}

bool Console::motion_state_ok(Session& s) {
  const MoveResult r = svc_->state_check();
  if (r.ok()) return true;
  answer_error(s, r.error, r.reason);
  return false;
}

MoveJoints Console::joint_request(const Command& c) const {
  MoveJoints m;
  if (c.cmd == Cmd::park) return svc_->park_request();
  m.goal = kin::JointVector(n_);
  for (int j = 0; j < n_; ++j) m.goal[j] = to_si(j, c.vals[static_cast<std::size_t>(j)]);
  m.speed_pct = c.has_speed ? c.speed : motion().default_joint_speed_pct;
  m.blend = c.has_blend ? cfg_.units.angle_in(c.blend) : -1.0;
  return m;
}

MoveJoints Console::step_joint_request(const Command& c, const StepParams* step) const {
  MoveJoints m = joint_request(c);
  if (step != nullptr && step->point != nullptr && c.cmd == Cmd::movej) m.goal = *step->point;  // exactly as taught (SI)
  return m;
}

bool Console::homed_ok(Session& s) {
  if (s.check_mode) return true;  // nothing moves
  const std::string why = unhomed_refusal(ctl_.telemetry());
  if (why.empty()) return true;
  answer_error(s, CmdError::not_homed, why);
  return false;
}

// ---------------------------------------------------------------------------
// Moves and dwells: planned, checked and queued by the arm service (arm_service.hpp);
// the console builds the request and renders the result.
// ---------------------------------------------------------------------------

MoveContext Console::move_context(DryRun* dry, const StepParams* step) const {
  MoveContext cx;
  cx.dry = dry;
  cx.chain = &tool_chain();
  cx.ik = ik_solver();
  cx.outputs = svc_->pending_outputs();
  if (step != nullptr) {
    cx.step_blend = step->blend;
    cx.next_line = step->next_line;
  }
  return cx;
}

DryRun Console::dry_run(Session& s) {
  DryRun d;
  d.tail = s.check_tail;
  d.time = s.check_time;
  d.run_base = s.check_run_base;
  d.blends = s.check_blends;
  d.shadow = check_shadow_.get();
  return d;
}

void Console::keep_dry_run(Session& s, const DryRun& d) {
  s.check_tail = d.tail;
  s.check_time = d.time;
  s.check_run_base = d.run_base;
  s.check_blends = d.blends;
}

std::string Console::blend_text(const MoveResult& r) {
  return r.blended && r.blend > 0 ? " blend=" + fixed(r.blend, kTimeDecimals) + "s" : std::string();
}

void Console::answer_refusal(Session& s, const char* what, const MoveResult& r) {
  const ConsoleUnits& u = cfg_.units;
  switch (r.refusal) {
    case MoveRefusal::none: return;
    case MoveRefusal::arm_state:
    case MoveRefusal::not_homed: answer_error(s, r.error, r.reason); return;
    case MoveRefusal::joint_limit:
      answer_error(s, r.error, fmt("joint %d = %s outside [%s, %s]", r.joint + 1, u.joint_text(chain_, r.joint, r.value).c_str(),
                                   u.joint_text(chain_, r.joint, r.lower).c_str(), u.joint_text(chain_, r.joint, r.upper).c_str()));
      return;
    case MoveRefusal::linear_speed:
      answer_error(s, r.error, fmt("linear speed %g %s/s outside [%g, %g]", u.length_out(r.speed), u.length_name(),
                                   u.length == LengthUnit::mm ? kMinLinearSpeedMmS : kMinLinearSpeedMmS * 1e-3,
                                   u.length_out(motion().max_linear_speed)));
      return;
    case MoveRefusal::plan: {
      if (std::string_view(what) != "movel") {
        answer_error(s, r.error, fmt("%s refused: %s", what, kin::to_string(r.status)));
        return;
      }
      const int L = u.length == LengthUnit::mm ? 1 : 4;
      const Eigen::Vector3d at = user_frame().inverse() * r.position;
      std::string where = fmt("at s=%s (x=%s y=%s z=%s %s)", fixed(r.s, 2).c_str(), fixed(u.length_out(at.x()), L).c_str(),
                              fixed(u.length_out(at.y()), L).c_str(), fixed(u.length_out(at.z()), L).c_str(), u.length_name());
      if (r.joint >= 0) where += fmt(" joint %d", r.joint + 1);
      answer_error(s, r.error, fmt("movel refused: %s %s", kin::to_string(r.status), where.c_str()));
      return;
    }
    case MoveRefusal::duration:
      answer_error(s, r.error, fmt("%s refused: it would take %.6gs, more than motion.max_move_duration_s = %gs "
                                   "(raise the speed); nothing queued", what, r.duration, motion().max_move_duration_s));
      return;
    case MoveRefusal::queue_full:
      answer_error(s, r.error, fmt("motion queue full (%zu moves); nothing queued", kMotionQueue));
      return;
  }
}

void Console::answer_move(Session& s, const char* what, const MoveResult& r, const DryRun* dry) {
  if (!r.ok()) {
    answer_refusal(s, what, r);
    return;
  }
  if (dry != nullptr) {  // checked, not queued
    keep_dry_run(s, *dry);
    answer_ok(s, s.dialect == Dialect::grbl ? "" : "checked duration=" + fixed(r.duration, kTimeDecimals) + "s" + blend_text(r));
    return;
  }
  const bool line = std::string_view(what) == "movel";
  if (line) feed_now_ = r.speed;
  svc_->clear_pending_outputs();
  answer_ok(s, fmt("queued id=%u duration=%ss%s%s", unsigned(r.id), fixed(r.duration, kTimeDecimals).c_str(),
                   line && r.status == kin::MotionStatus::slowed_near_singularity ? fmt(" slowed=%.2fx", r.slowdown).c_str() : "",
                   blend_text(r).c_str()));
}

void Console::queue(Session& s, const MoveJoints& req, const StepParams* step) {
  DryRun dry;
  if (s.check_mode) dry = dry_run(s);
  answer_move(s, "movej", svc_->move(req, move_context(s.check_mode ? &dry : nullptr, step)), s.check_mode ? &dry : nullptr);
}

void Console::queue(Session& s, const MoveLine& req, const StepParams* step) {
  DryRun dry;
  if (s.check_mode) dry = dry_run(s);
  answer_move(s, "movel", svc_->move(req, move_context(s.check_mode ? &dry : nullptr, step)), s.check_mode ? &dry : nullptr);
}

void Console::queue_dwell(Session& s, double secs) {
  DryRun dry;
  if (s.check_mode) dry = dry_run(s);
  const MoveResult r = svc_->dwell(secs, move_context(s.check_mode ? &dry : nullptr, nullptr));
  if (!r.ok()) {
    answer_refusal(s, "dwell", r);
    return;
  }
  if (s.check_mode) {
    keep_dry_run(s, dry);
    answer_ok(s, s.dialect == Dialect::grbl ? "" : "checked");
    return;
  }
  answer_ok(s, fmt("queued id=%u dwell=%ss", unsigned(r.id), fixed(secs, kTimeDecimals).c_str()));
}

// x y z [rx ry rz] in the active user frame (orientation kept when not given) -> the base frame.
kin::Pose Console::pose_from_values(const Command& c, const kin::JointVector& q_ref) const {
  kin::Pose p = pose_in_frame(q_ref);
  const ConsoleUnits& u = cfg_.units;
  p.translation() = Eigen::Vector3d(u.length_in(c.vals[0]), u.length_in(c.vals[1]), u.length_in(c.vals[2]));
  if (c.count == 6) p.linear() = kin::rotation_from_rpy(u.angle_in(c.vals[3]), u.angle_in(c.vals[4]), u.angle_in(c.vals[5]));
  return user_frame() * p;
}

MoveLine Console::line_request(const Command& c, const kin::JointVector* from) const {
  MoveLine m;
  const kin::JointVector base = from != nullptr ? *from : tail();
  if (c.cmd == Cmd::movel) {
    m.target = pose_from_values(c, base);
    m.speed = c.has_speed ? cfg_.units.length_in(c.speed) : 0.0;
    m.blend = c.has_blend ? cfg_.units.length_in(c.blend) : -1.0;
    return m;
  }
  // G0/G1: the axes given replace (G90) or move (G91) the queue's end pose; the others keep it.
  // G-code's units (the parser made G20 inches mm): mm, degrees, F in mm/s.
  // The axes are the active user frame's (G54..G59), the point the active tool's.
  const ConsoleUnits& u = kGcodeUnits;
  const kin::Pose F = c.g53 ? kin::Pose::Identity() : user_frame();  // G53: machine coordinates
  const kin::Pose cur = F.inverse() * tcp(base);
  m.target = cur;
  Eigen::Vector3d rpy = kin::rpy_from_rotation(cur.linear());
  for (int k = 0; k < 6; ++k) {
    if (!(c.axis_mask & (1u << k))) continue;
    const double v = c.vals[static_cast<std::size_t>(k)];
    if (k < 3) m.target.translation()[k] = u.length_in(c.relative ? u.length_out(cur.translation()[k]) + v : v);
    else rpy[k - 3] = c.relative ? rpy[k - 3] + u.angle_in(v) : u.angle_in(v);
  }
  if (c.axis_mask & 0x38) m.target.linear() = kin::rotation_from_rpy(rpy[0], rpy[1], rpy[2]);
  m.target = F * m.target;
  m.rapid = c.rapid;
  m.speed = c.has_speed ? u.length_in(c.speed) : 0.0;
  m.clamp_speed = true;  // senders' F is clamped, as GRBL does
  return m;
}

void Console::do_fk(Session& s, const Command& c) {
  kin::JointVector q(n_);
  if (c.count == 0) {
    const Telemetry t = ctl_.telemetry();
    for (int j = 0; j < n_; ++j) q[j] = t.q_act[static_cast<std::size_t>(j)];
  } else {
    for (int j = 0; j < n_; ++j) q[j] = to_si(j, c.vals[static_cast<std::size_t>(j)]);
  }
  const bool inside = kin::within_limits(chain_, q);
  const std::string pose = pose_text(q);
  if (pose.rfind("x=nan", 0) == 0) {
    answer_error(s, CmdError::not_finite, "fk: the pose of these joints is not finite");
    return;
  }
  answer_ok(s, pose + " " + where_text() + (inside ? "" : " warning=outside_joint_limits"));
}

void Console::do_ik(Session& s, const Command& c) {
  const Telemetry t = ctl_.telemetry();
  kin::JointVector qc(n_);
  for (int j = 0; j < n_; ++j) qc[j] = t.q_cmd[static_cast<std::size_t>(j)];
  const kin::Pose target = pose_from_values(c, qc);
  kin::JointVector q(n_);
  kin::Status st = kin::Status::unreachable;
  int solutions = -1;
  if (const kin::IkModel* model = svc_->tool_model(sel_tool()); model != nullptr) {
    auto res = std::make_unique<kin::IkResult>();
    kin::ik_solve_all(*model, target, &qc, *res);
    solutions = res->count;
    st = kin::ik_solve_nearest(*model, target, qc, q);
  } else {
    st = kin::ik_nearest_newton(tool_chain(), target, qc, q, nullptr);
  }
  if (!kin::is_ok(st)) {
    answer_error(s, st == kin::Status::out_of_limits ? CmdError::limits : CmdError::unreachable,
                 fmt("no IK solution within the joint limits: %s", kin::to_string(st)));
    return;
  }
  if (!kin::within_limits(chain_, q, 1e-9)) {
    answer_error(s, CmdError::limits, fmt("nearest solution [%s] is outside the joint limits", joints_text(q).c_str()));
    return;
  }
  std::string d = fmt("joints=[%s] %s", joints_text(q).c_str(), cfg_.units.angle_name());
  if (solutions >= 0) d += fmt(" solutions=%d", solutions);
  d += " " + where_text();
  if (st == kin::Status::singular) d += " warning=singular";
  answer_ok(s, d);
}

void Console::do_limits(Session& s) {
  const ArmLimits a = svc_->arm_limits();
  const auto& lim = a.joints;
  const ConsoleUnits& u = cfg_.units;
  for (int j = 0; j < n_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    const bool pr = a.prismatic[ju];
    const int d = pr ? u.length_decimals() : u.angle_decimals();
    const auto f = [&](double si) { return fixed(to_user(j, si), d); };
    s.out += fmt("joint %d: %s [%s, %s] %s  vmax=%s amax=%s jmax=%s %s/s^k\n", j + 1, pr ? "prismatic" : "revolute",
                 f(lim.lower[ju]).c_str(), f(lim.upper[ju]).c_str(), u.joint_name(chain_, j), f(lim.dyn[ju].max_velocity).c_str(),
                 f(lim.dyn[ju].max_acceleration).c_str(), f(lim.dyn[ju].max_jerk).c_str(), u.joint_name(chain_, j));
  }
  const int v = u.length == LengthUnit::mm ? 1 : 4;
  s.out += fmt("linear speed: default %s %s/s, max %s %s/s; following error limit %s %s\n",
               fixed(u.length_out(a.default_linear_speed), v).c_str(), u.length_name(),
               fixed(u.length_out(a.max_linear_speed), v).c_str(), u.length_name(), u.angle_text(a.following_error).c_str(),
               u.angle_name());
  answer_ok(s);
}

void Console::do_help(Session& s, std::string_view topic) {
  if (!help_text(topic, units_line(), s.out)) {
    answer_error(s, CmdError::unknown_command, fmt("no help on '%.*s'", int(topic.size()), topic.data()));
    return;
  }
  answer_ok(s);
}

std::string Console::units_line() const {
  return cfg_.units.help_line();
}

void Console::execute(Session& s, std::string_view line) {
  ++s.lines_done;
  struct Selected {  // the session whose tool/frame selection applies (check mode has its own)
    const Session*& sel;
    ~Selected() { sel = nullptr; }
  } selected{sel_};
  sel_ = &s;
  Command c;
  const ParseResult pr = parse_line(line, n_, s.modal, c, cfg_.units);
  if (!pr.ok()) {
    answer_error(s, pr.error, pr.message.data());
    return;
  }
  dispatch(s, c, nullptr);
}

void Console::dispatch(Session& s, const Command& c, const StepParams* step) {
  // While a program runs, motion comes from the program only: a move, jog, dwell, homing or
  // M62/M63 from any console is refused (stop, hold, resume, abort and queries still work).
  if (running() && (!run_ || &s != &run_->ps) && !s.check_mode && moves_arm(c)) {
    answer_error(s, CmdError::busy, fmt("program %s is running (%s): stop, pause or abort it first; nothing queued",
                                        svc_->program_status().name.c_str(), program_where().c_str()));
    return;
  }
  const std::size_t sync_before = svc_->pending_outputs().size();
  const std::size_t out_before = s.out.size();
  run_command(s, c, step);
  // A move refused: the M62/M63 changes waiting for it are dropped with it (and said so).
  if (sync_before == 0 || svc_->pending_outputs().size() != sync_before || s.check_mode || !carries_outputs(c.cmd)) return;
  if (last_answer_is_error(s, out_before)) note_before_answer(s, out_before, discard_sync_outputs("the move was refused"));
}

// One case per command, each handed to its family: arm control, moves and jogs, queries,
// G-code senders' `$` commands, teach points, programs, record and outputs.
void Console::run_command(Session& s, const Command& c, const StepParams* step) {
  switch (c.cmd) {
    case Cmd::none: answer_ok(s); return;
    case Cmd::help: do_help(s, std::string_view(c.topic.data())); return;
    case Cmd::quit: do_quit(s); return;
    case Cmd::status: answer_ok(s, status_text()); return;
    case Cmd::enable: do_enable(s); return;
    case Cmd::disable: do_halt(s, ProgramEnd::disable, "disable", RequestOp::disable); return;
    case Cmd::stop: do_halt(s, ProgramEnd::stop, "stop", RequestOp::stop); return;
    case Cmd::estop: do_halt(s, ProgramEnd::estop, "e-stop", RequestOp::estop); return;
    case Cmd::reset: answer_control(s, svc_->control(RequestOp::reset)); return;
    case Cmd::hold: answer_control(s, svc_->hold()); return;
    case Cmd::resume: do_resume(s); return;
    case Cmd::home_zero: answer_control(s, svc_->control(RequestOp::set_zero)); return;
    case Cmd::home: do_home(s, c); return;
    case Cmd::park:
    case Cmd::movej:
    case Cmd::movel:
    case Cmd::gmove: do_move(s, c, step); return;
    case Cmd::dwell: queue_dwell(s, c.vals[0]); return;
    case Cmd::fk: do_fk(s, c); return;
    case Cmd::ik: do_ik(s, c); return;
    case Cmd::limits: do_limits(s); return;
    case Cmd::stats: answer_ok(s, stats_text()); return;
    case Cmd::config: do_config(s); return;
    case Cmd::wait: s.waiting = true; settle(s); return;
    case Cmd::position: do_position(s); return;
    case Cmd::temperature: answer_ok(s, "T:0 /0 B:0 /0"); return;
    case Cmd::jog: do_jog(s, c); return;
    case Cmd::tool: do_tool(s, c); return;
    case Cmd::frame: do_frame(s, c); return;
    case Cmd::grbl_jog: do_grbl_jog(s, c); return;
    case Cmd::grbl_settings:
    case Cmd::grbl_params:
    case Cmd::grbl_state:
    case Cmd::grbl_info:
    case Cmd::grbl_unlock:
    case Cmd::grbl_home:
    case Cmd::grbl_check:
    case Cmd::grbl_help: do_grbl(s, c); return;
    case Cmd::teach: do_teach(s, c); return;
    case Cmd::points: do_points(s); return;
    case Cmd::point_delete: do_point_delete(s, c); return;
    case Cmd::programs: do_programs(s); return;
    case Cmd::run: do_run(s, c); return;
    case Cmd::pause: do_pause(s); return;
    case Cmd::step: do_step(s); return;
    case Cmd::abort: do_abort(s); return;
    case Cmd::record: do_record(s, c); return;
    case Cmd::out: do_out(s, c); return;
    case Cmd::freedrive: do_dynamics(s); return;
    case Cmd::freedrive_on:
    case Cmd::freedrive_off:
    case Cmd::collision_on:
    case Cmd::collision_off: do_switch(s, c); return;
    case Cmd::safety: answer_ok(s, safety_text()); return;
    case Cmd::safety_normal:
    case Cmd::safety_reduced:
      if (s.check_mode) {
        answer_ok(s, "check mode: not run");
        return;
      }
      answer_control(s, svc_->set_safety_mode(c.cmd == Cmd::safety_reduced ? kin::SafetyMode::reduced
                                                                              : kin::SafetyMode::normal,
                                              c.confirm));
      return;
    case Cmd::safety_stage:
    case Cmd::safety_confirm: do_safety_change(s, c); return;
  }
}

// A run-time change of [safety]: the service's stage_safety / confirm_safety (the API's
// safety_stage / safety_confirm), rendered in one line.
void Console::do_safety_change(Session& s, const Command& c) {
  if (s.check_mode) {
    answer_ok(s, "check mode: not run");
    return;
  }
  if (c.cmd == Cmd::safety_stage) {
    const SafetyChangeResult r = svc_->stage_safety(c.text.data());
    if (!r.ok()) return answer_error(s, r.error, r.reason);
    answer_ok(s, fmt("staged checksum=%08X previous=%08X expires_s=%.0f changes: %s; confirm with: safety confirm %08X",
                     static_cast<unsigned>(r.checksum), static_cast<unsigned>(r.previous), r.expires_s,
                     r.changes.c_str(), static_cast<unsigned>(r.checksum)));
    return;
  }
  const SafetyChangeResult r = svc_->confirm_safety(c.checksum);
  if (!r.ok()) return answer_error(s, r.error, r.reason);
  answer_ok(s, fmt("safety configuration %08X in force (was %08X): %s", static_cast<unsigned>(r.checksum),
                   static_cast<unsigned>(r.previous), r.changes.c_str()));
}

// ---------------------------------------------------------------------------
// Arm control
// ---------------------------------------------------------------------------

void Console::do_quit(Session& s) {
  // The session ends here (ConsoleServer ends it as its transport says); lines the client
  // sent after it are not run, each answered so.
  answer_ok(s, "bye");
  for (const std::string& l : s.lines)
    answer_error(s, CmdError::bad_state, fmt("'%s' not executed: the session ended (quit)", l.c_str()));
  s.lines.clear();
  s.hold_after = 0;
  s.ended = true;
}

void Console::do_enable(Session& s) {
  if (s.check_mode) {
    answer_ok(s, "check mode: not run");
    return;
  }
  if (const ControlResult e = svc_->enable(); !e.ok()) {
    answer_control(s, e);
    return;
  }
  s.enabling = true;
  settle(s);
}

void Console::do_halt(Session& s, ProgramEnd how, const char* what, RequestOp op) {
  end_program(how);
  note_line(s, discard_sync_outputs(what));
  answer_control(s, svc_->control(op));
}

void Console::do_abort(Session& s) {
  note_line(s, discard_sync_outputs("abort"));
  if (!running()) {
    answer_control(s, svc_->control(RequestOp::stop));
    return;
  }
  const std::string at = program_where(), name = svc_->program_status().name;
  if (svc_->program_abort().error == CmdError::timeout) {
    answer_error(s, CmdError::timeout, "control thread did not answer stop");
    return;
  }
  answer_ok(s, "aborted " + name + " at " + at);
}

// Free-drive and collision detection on or off (a check runs neither).
void Console::do_switch(Session& s, const Command& c) {
  if (s.check_mode) {
    answer_ok(s, "check mode: not run");
    return;
  }
  const bool collision = c.cmd == Cmd::collision_on || c.cmd == Cmd::collision_off;
  answer_control(s, collision ? svc_->collision_detection(c.cmd == Cmd::collision_on) : svc_->freedrive(c.cmd == Cmd::freedrive_on));
}

// `freedrive`: the refusals as lines of their own, then `ok <state>`.
void Console::do_dynamics(Session& s) {
  std::string d = dynamics_text();
  const std::size_t nl = d.find('\n');
  if (nl != std::string::npos) {
    s.out += d.substr(nl + 1) + "\n";
    d.resize(nl);
  }
  answer_ok(s, d);
}

// ---------------------------------------------------------------------------
// Moves and queries
// ---------------------------------------------------------------------------

void Console::do_move(Session& s, const Command& c, const StepParams* step) {
  if ((c.cmd == Cmd::movej || c.cmd == Cmd::park || c.cmd == Cmd::movel) && c.at_point) {
    queue_at_point(s, c);
    return;
  }
  if (c.cmd == Cmd::movej || c.cmd == Cmd::park) {
    queue(s, step_joint_request(c, step), step);
    return;
  }
  if (c.cmd == Cmd::movel && step != nullptr && step->point != nullptr) {  // a program's movel @NAME: the point's joints
    MoveLine m;
    m.target = tcp(*step->point);  // where they put the active tool, on a straight line
    m.speed = c.has_speed ? cfg_.units.length_in(c.speed) : 0.0;
    queue(s, m, step);
    return;
  }
  queue(s, line_request(c, s.check_mode ? &s.check_tail : nullptr), step);
}

void Console::do_config(Session& s) {
  s.out += cfg_.config_text;
  if (!cfg_.config_text.empty() && cfg_.config_text.back() != '\n') s.out += '\n';
  answer_ok(s);
}

// M114: the active tool's point in the active user frame, in the session's G-code units.
void Console::do_position(Session& s) {
  const Telemetry t = ctl_.telemetry();
  kin::JointVector q(n_);
  for (int j = 0; j < n_; ++j) q[j] = t.q_act[static_cast<std::size_t>(j)];
  const kin::Pose p = pose_in_frame(q);
  const Eigen::Vector3d rpy = kGcodeUnits.rpy_of(p.linear()) / kDeg;
  const double u = s.modal.unit_mm;
  s.out += "X:" + fixed(p.translation().x() * 1e3 / u, 3) + " Y:" + fixed(p.translation().y() * 1e3 / u, 3) +
           " Z:" + fixed(p.translation().z() * 1e3 / u, 3) + " A:" + fixed(rpy[0], 3) + " B:" + fixed(rpy[1], 3) +
           " C:" + fixed(rpy[2], 3) + "\n";
  answer_ok(s);
}

bool Console::settle(Session& s) {
  if (s.checking) {  // `run`: its program's check goes on a slice at a time
    if (pcheck_ && pcheck_->owner == &s) {
      if (continue_check()) return true;
    } else {
      s.checking = false;
    }
  }
  if (s.enabling) {
    const Telemetry t = ctl_.telemetry();
    switch (t.state) {
      case ArmState::enabling: return true;
      case ArmState::idle:
      case ArmState::moving:
      case ArmState::jogging:
      case ArmState::homing:
      case ArmState::freedrive:
        s.enabling = false;
        answer_ok(s, "enabled");
        break;
      case ArmState::fault:
        s.enabling = false;
        answer_error(s, CmdError::fault, fmt("enable failed: %s", bounded_text(t.fault_text).c_str()));
        break;
      case ArmState::boot:
      case ArmState::disabled:
      case ArmState::stopping:
      case ArmState::estop:
        s.enabling = false;
        answer_error(s, CmdError::bad_state, fmt("enable interrupted: arm is %s", to_string(t.state)));
        break;
    }
  }
  if (s.homing) {  // $H: answered when the homing cycle has ended
    const Telemetry t = ctl_.telemetry();
    if (t.state == ArmState::homing || t.mode == Mode::homing_abort) return true;
    s.homing = false;
    if (t.state == ArmState::fault) answer_error(s, CmdError::fault, fmt("homing failed: %s", bounded_text(t.fault_text).c_str()));
    else if (t.state == ArmState::estop) answer_error(s, CmdError::fault, "homing aborted: e-stop");
    else if (!t.all_homed()) answer_error(s, CmdError::not_homed, "homing stopped: " + unhomed_refusal(t));
    else answer_ok(s, "homed");
  }
  if (s.waiting) {
    const Telemetry t = ctl_.telemetry();
    switch (t.state) {
      case ArmState::fault:
        s.waiting = false;
        answer_error(s, CmdError::fault, fmt("arm in fault while waiting: %s", bounded_text(t.fault_text).c_str()));
        break;
      case ArmState::estop:
        s.waiting = false;
        answer_error(s, CmdError::fault, "e-stop while waiting");
        break;
      case ArmState::moving:
      case ArmState::stopping:
      case ArmState::jogging:
      case ArmState::homing:
      case ArmState::enabling: return true;  // still busy
      case ArmState::boot:
      case ArmState::disabled:
      case ArmState::idle:
      case ArmState::freedrive:
        if (!ctl_.motions().empty()) return true;  // producer-side view: exact, never stale
        // a running program has more to come (its own `wait` lines wait for the queue only)
        if (running() && (!run_ || &s != &run_->ps) && svc_->run_state() != RunState::paused) return true;
        s.waiting = false;
        answer_ok(s, fmt("idle %s", pose_text(tail()).c_str()));
        break;
    }
  }
  return false;
}

bool Console::run_one(Session& s) {
  if (settle(s) || s.lines.empty()) return false;
  if (s.dialect == Dialect::grbl && !s.check_mode && ctl_.motions().full()) {
    // GRBL: a motion line waits for room in the queue (its `ok` comes then: senders count
    // characters and stream ahead); the native language answers `error: busy` instead.
    Command c;
    GcodeModal m = s.modal;
    if (parse_line(s.lines.front(), n_, m, c, cfg_.units).ok() &&
        (c.cmd == Cmd::gmove || c.cmd == Cmd::movel || c.cmd == Cmd::movej || c.cmd == Cmd::park || c.cmd == Cmd::dwell))
      return false;
  }
  const std::string line = std::move(s.lines.front());
  s.lines.pop_front();
  execute(s, line);
  if (s.hold_after > 0 && --s.hold_after == 0) feed_hold(s);  // the '!' that came after this line
  return true;
}

void Console::feed_hold(Session& s) {
  if (svc_->hold().error == CmdError::timeout) s.out += "error: timeout feed hold not acknowledged\n";
}

void Console::poll(Session& s) {
  while (run_one(s)) {
  }
  tick();
}

void Console::feed(Session& s, std::string_view bytes) {
  accept(s, bytes);
  poll(s);
}

void Console::end_of_input(Session& s) {
  if (!s.partial.empty() || s.discarding) accept(s, "\n");
}

void Console::realtime(Session& s, char ch) {
  Reply r;
  if (is_feed_override(ch)) {
    // GRBL feed override, 10..200 %: the speed of jogs and of moves queued from now on.
    const auto u = static_cast<unsigned char>(ch);
    int v = svc_->feed_override();
    if (u == kRtFeed100) v = 100;
    else if (u == kRtFeedPlus10) v += 10;
    else if (u == kRtFeedMinus10) v -= 10;
    else if (u == kRtFeedPlus1) v += 1;
    else if (u == kRtFeedMinus1) v -= 1;
    svc_->set_feed_override(std::clamp(v, kMinFeedOverride, kMaxFeedOverride));
    return;
  }
  switch (ch) {
    case kRtStatus: s.out += grbl_report(s) + "\n"; break;
    case kRtHold:
      feed_hold(s);
      // Lines received before the '!' and not run yet: the hold applies to them too (a move
      // sent right before a '!' is held as soon as it is queued, until '~').
      s.hold_after = s.lines.size();
      break;
    case kRtResume:
      s.hold_after = 0;  // a '!' still waiting for the lines before it is resumed too
      if (svc_->resume(false).error == CmdError::timeout) s.out += "error: timeout resume not acknowledged\n";
      break;
    case kRtJogCancel: {
      if (svc_->jog_cancel().error == CmdError::timeout) s.out += "error: timeout jog cancel not acknowledged\n";
      // Jog lines received but not run yet are answered, not run: a cancel always wins.
      for (auto it = s.lines.begin(); it != s.lines.end();) {
        const std::string_view l(*it);
        const std::size_t k = l.find_first_not_of(" \t");
        const bool jog_line = k != std::string_view::npos &&
                              (l.substr(k, 3) == "$J=" || l.substr(k, 3) == "$j=" || l.substr(k, 4) == "jog ");
        if (!jog_line) {
          ++it;
          continue;
        }
        answer_error(s, CmdError::estop, fmt("'%.40s' not run: jog cancelled (0x85)", it->c_str()));
        it = s.lines.erase(it);
      }
      if (s.hold_after > s.lines.size()) s.hold_after = s.lines.size();
      break;
    }
    case kRtReset: {
      // GRBL dialect: a soft reset; it stops the arm (an e-stop) only when something moves,
      // else the queue is dropped and the banner printed again. Native: always an e-stop.
      const Telemetry t = ctl_.telemetry();
      const bool moving = t.state == ArmState::moving || t.state == ArmState::jogging || t.state == ArmState::stopping ||
                          t.state == ArmState::homing;  // Ctrl-X during homing: an e-stop (the joints stay unhomed)
      const RequestOp op = s.dialect == Dialect::grbl && !moving ? RequestOp::stop : RequestOp::estop;
      end_program(op == RequestOp::estop ? ProgramEnd::estop : ProgramEnd::soft_reset, true);
      note_line(s, discard_sync_outputs("Ctrl-X"));
      if (!request(op, r)) s.out += "error: timeout e-stop not acknowledged\n";
      s.partial.clear();
      s.discarding = false;
      // A pending wait / enable is answered first (in order), then every complete line
      // not executed yet gets its answer: not executing them is right, leaving them
      // unanswered would hang a sender that counts answers.
      settle(s);
      for (const std::string& l : s.lines)
        answer_error(s, CmdError::estop,
                     fmt("'%.40s%s' not executed: e-stop (Ctrl-X) before it ran", l.c_str(), l.size() > 40 ? "..." : ""));
      s.lines.clear();
      s.hold_after = 0;
      s.check_mode = false;
      svc_->jog_forget();
      greet(s);
      break;
    }
    default: break;
  }
}

void Console::greet(Session& s) {
  if (s.dialect != Dialect::grbl) return;
  s.out += "\r\nGrbl 1.1h ['$' for help]\r\n";
  const ArmState st = ctl_.telemetry().state;
  if (st == ArmState::disabled || st == ArmState::fault || st == ArmState::estop || st == ArmState::boot)
    s.out += "[MSG:'$X' to unlock (reset and enable the drives)]\r\n";
}

void Console::client_gone(Session& s) {
  if (pcheck_ && pcheck_->owner == &s) cancel_check("the client hanging up");
  if (ctl_.telemetry().state == ArmState::jogging) svc_->jog_cancel();
  svc_->jog_forget();
  s.partial.clear();
  s.check_mode = false;
}

void Console::accept(Session& s, std::string_view bytes) {
  for (char ch : bytes) {
    // Bytes 0x80-0xFF are realtime only where GRBL's protocol puts them: bare, or UTF-8
    // encoded as C2 xx (what cncjs sends: the code point U+0085, U+0090..). A continuation
    // byte of any other multi-byte character (C3 91 is `Ñ`) is part of the text.
    const auto u = static_cast<unsigned char>(ch);
    bool in_char = false;
    if (s.utf8_left > 0 && u >= 0x80 && u <= 0xBF) {
      in_char = s.utf8_lead != 0xC2;
      --s.utf8_left;
    } else {
      s.utf8_left = u >= 0xC2 && u <= 0xDF ? 1 : u >= 0xE0 && u <= 0xEF ? 2 : u >= 0xF0 && u <= 0xF4 ? 3 : 0;
      s.utf8_lead = u;
    }
    if (!in_char && is_realtime(ch)) {
      realtime(s, ch);
      continue;
    }
    // GRBL: bytes above 0x7F that are no realtime command are dropped unanswered (cncjs
    // sends 0x85 / 0x90.. UTF-8 encoded, as C2 85...). The native language refuses them in
    // the line (error: binary).
    if (s.dialect == Dialect::grbl && static_cast<unsigned char>(ch) >= 0x80) continue;
    const bool crlf = ch == '\n' && s.after_cr;
    s.after_cr = ch == '\r';
    if (crlf) continue;  // CR LF ends one line, not two
    if (ch == '\n' || ch == '\r') {
      if (s.discarding) {
        s.discarding = false;
        s.partial.clear();
        s.lines.emplace_back(std::string(kMaxLine + 1, 'x'));  // answered as overlong, in order
        continue;
      }
      s.lines.push_back(std::move(s.partial));
      s.partial.clear();
      continue;
    }
    if (s.discarding) continue;
    s.partial += ch;
    if (s.partial.size() > kMaxLine) {
      s.discarding = true;
      s.partial.clear();
    }
  }
}

// ---------------------------------------------------------------------------
// Jogging (jog.hpp runs it on the control thread; here the targets are computed)
// ---------------------------------------------------------------------------

void Console::do_home(Session& s, const Command& c) {
  if (s.check_mode) {
    answer_ok(s, "check mode: not run");
    return;
  }
  const ControlResult h = svc_->home(c.home_joint);
  if (!h.ok()) {
    answer_control(s, h);
    return;
  }
  svc_->jog_forget();
  if (c.cmd == Cmd::grbl_home) {  // GRBL: $H answers when the cycle has ended (state Home meanwhile)
    s.homing = true;
    if (s.dialect == Dialect::grbl) s.out += fmt("[MSG:%s]\n", h.reason.c_str());
    settle(s);
    return;
  }
  answer_ok(s, h.reason);
}

JogContext Console::jog_context() const {
  JogContext cx;
  cx.chain = &tool_chain();
  cx.ik = ik_solver();
  cx.user_axes = user_frame().linear();
  return cx;
}

void Console::answer_jog(Session& s, const JogResult& r, const char* what, double given) {
  const ConsoleUnits& u = cfg_.units;
  const int j = r.joint;
  switch (r.refusal) {
    case JogRefusal::none: break;
    case JogRefusal::range:
      answer_error(s, r.error, fmt("%s: increment %g %s larger than joint %d's range [%s, %s]; nothing moved", what, given,
                                   u.joint_name(chain_, j), j + 1, u.joint_text(chain_, j, r.lower).c_str(),
                                   u.joint_text(chain_, j, r.upper).c_str()));
      return;
    case JogRefusal::at_limit:
      answer_error(s, r.error, fmt("%s: joint %d is at its limit %s %s; nothing moved", what, j + 1,
                                   u.joint_text(chain_, j, r.value).c_str(), u.joint_name(chain_, j)));
      return;
    case JogRefusal::rotation:
      answer_error(s, r.error, fmt("%s: rotation %g %s: at most half a turn per jog (|angle| < %g); nothing moved", what, given,
                                   u.angle_name(), u.angle_out(M_PI)));
      return;
    case JogRefusal::duration:
      answer_error(s, r.error, fmt("jog refused: it would take %.6gs, more than motion.max_move_duration_s = %gs "
                                   "(raise the speed); nothing moved", r.duration, motion().max_move_duration_s));
      return;
    case JogRefusal::unreachable:
      answer_error(s, r.error, fmt("%s: the target has no IK solution within the joint limits; nothing moved", what));
      return;
    case JogRefusal::feed:
      answer_error(s, r.error, fmt("%s: feed %g mm/min (with the %d %% override) below %g mm/min; nothing moved", what,
                                   r.speed * 6e4, svc_->feed_override(), kMinLinearSpeedMmS * 60));
      return;
    case JogRefusal::control: answer_error(s, r.error, r.reason); return;
  }
  if (r.clamped)  // it moves: ok, and where it stops
    answer_ok(s, fmt("%s; joint %d stops at its limit %s %s (asked %s)", r.reason.c_str(), j + 1,
                     u.joint_text(chain_, j, r.value).c_str(), u.joint_name(chain_, j), u.joint_text(chain_, j, r.asked).c_str()));
  else answer_ok(s, r.reason);
}

void Console::do_jog(Session& s, const Command& c) {
  if (c.jog_op == JogOp::keepalive || c.jog_op == JogOp::stop) {
    const ControlResult r = c.jog_op == JogOp::stop ? svc_->jog_cancel() : svc_->jog_keepalive();
    if (r.error == CmdError::timeout) answer_error(s, r.error, r.reason);
    else answer_ok(s, r.reason);
    return;
  }
  if (s.check_mode) {
    answer_ok(s, "check mode: jog not run");
    return;
  }
  const bool continuous = c.jog_op == JogOp::continuous;
  const double speed = c.has_speed ? c.speed : -1.0;
  if (!c.jog_tool) {
    JointJog jj;
    jj.joint = c.jog_axis;
    jj.continuous = continuous;
    jj.direction = c.jog_dir;
    jj.increment = continuous ? 0.0 : to_si(c.jog_axis, c.vals[0]);
    jj.speed_pct = speed;
    answer_jog(s, svc_->jog(jj, jog_context()), "jog", c.vals[0]);
    return;
  }
  // Tool jog: along / about an axis of the base, the tool (as it is at the jog's start) or the user frame.
  ToolJog tj;
  tj.axis = c.jog_axis;
  tj.continuous = continuous;
  tj.direction = c.jog_dir;
  tj.increment = continuous ? 0.0 : c.jog_axis < 3 ? cfg_.units.length_in(c.vals[0]) : cfg_.units.angle_in(c.vals[0]);
  tj.speed_pct = speed;
  tj.frame = c.jog_frame;
  const JogResult r = svc_->jog(tj, jog_context());
  if (r.ok()) feed_now_ = r.speed;
  answer_jog(s, r, "jog", c.vals[0]);
}

void Console::do_grbl_jog(Session& s, const Command& c) {
  if (s.check_mode) {
    answer_ok(s);
    return;
  }
  // In the active user frame (G54..G59), or the base with G53 (machine coordinates).
  const kin::Pose F = c.g53 ? kin::Pose::Identity() : user_frame();
  const JogFrame kind = c.g53 || svc_->active_frame() == 0 ? JogFrame::base : JogFrame::user;
  const JogContext cx = jog_context();
  const kin::Pose here = F.inverse() * svc_->jog_from(kind, cx);
  kin::Pose target = here;
  Eigen::Vector3d rpy = kin::rpy_from_rotation(here.linear());
  for (int k = 3; k < 6; ++k) {  // relative rotations: the short way round, so less than half a turn
    if (!(c.axis_mask & (1u << k)) || !c.relative) continue;
    if (!(std::fabs(c.vals[static_cast<std::size_t>(k)]) < 180.0)) {
      answer_error(s, CmdError::out_of_range, fmt("$J: rotation %c%g deg: at most half a turn per jog; nothing moved",
                                                  "ABC"[k - 3], c.vals[static_cast<std::size_t>(k)]));
      return;
    }
  }
  for (int k = 0; k < 6; ++k) {
    if (!(c.axis_mask & (1u << k))) continue;
    const double v = c.vals[static_cast<std::size_t>(k)];  // mm / deg (the parser converted G20)
    if (k < 3) target.translation()[k] = c.relative ? here.translation()[k] + v * 1e-3 : v * 1e-3;
    else rpy[k - 3] = c.relative ? rpy[k - 3] + v * kDeg : v * kDeg;
  }
  if (c.axis_mask & 0x38) target.linear() = kin::rotation_from_rpy(rpy[0], rpy[1], rpy[2]);
  PoseJog pj;
  pj.target = F * target;
  pj.speed = c.speed * 1e-3;  // the parser's mm/s
  pj.frame = kind;
  pj.axes = F.linear();
  const JogResult r = svc_->jog(pj, cx);
  if (r.ok()) feed_now_ = r.speed;
  answer_jog(s, r, "$J", 0);
}

// ---------------------------------------------------------------------------
// GRBL $ commands
// ---------------------------------------------------------------------------

std::string Console::grbl_settings() const {
  // Only the GRBL settings that mean something on an arm; the configuration file sets them.
  double reach = 0;
  for (int j = 0; j < n_; ++j) reach += std::hypot(chain_.joint(j).a, chain_.joint(j).d);
  const double vmax = motion().max_linear_speed * 60e3;       // mm/min
  const double amax = motion().cartesian.linear_acceleration * 1e3;  // mm/s^2
  std::string o;
  o += "$10=3\n";   // status report: MPos and buffer data
  o += "$13=0\n";   // report in mm
  o += "$20=1\n";   // soft limits: the joint limits, always on
  o += "$21=0\n";   // hard limits: none (the drives' own)
  o += "$22=1\n";   // homing cycle: $H runs it (drive.homing.method per joint)
  o += "$30=0\n$31=0\n$32=0\n";  // no spindle, no laser
  for (int k = 0; k < 3; ++k) o += fmt("$%d=%.3f\n", 110 + k, vmax);
  for (int k = 0; k < 3; ++k) o += fmt("$%d=%.3f\n", 120 + k, amax);
  for (int k = 0; k < 3; ++k) o += fmt("$%d=%.3f\n", 130 + k, 2e3 * reach);
  return o;
}

void Console::do_grbl(Session& s, const Command& c) {
  Reply r;
  switch (c.cmd) {
    case Cmd::grbl_help:
      s.out += "[HLP:$$ $# $G $I $X $H $C $J=line ? ! ~ ctrl-x 0x85]\n";
      answer_ok(s);
      return;
    case Cmd::grbl_settings:
      s.out += grbl_settings();
      answer_ok(s);
      return;
    case Cmd::grbl_params: {
      // Work offsets: the origins of the user frames g54..g59 in the base (mm; their
      // orientations are in the frames file and `frame`).
      for (int g = 54; g <= 59; ++g) {
        Eigen::Vector3d o = Eigen::Vector3d::Zero();
        if (const std::size_t k = svc_->find_frame("g" + std::to_string(g)); k < svc_->frame_count())
          o = svc_->frame(k).pose.translation();
        s.out += fmt("[G%d:%s]\n", g, mm_triple(o, ",").c_str());
      }
      const kin::Pose h = tcp(motion().home);
      s.out += fmt("[G28:%s]\n[G30:0.000,0.000,0.000]\n[G92:0.000,0.000,0.000]\n[TLO:0.000]\n"
                   "[PRB:0.000,0.000,0.000:0]\n",
                   mm_triple(h.translation()).c_str());
      answer_ok(s);
      return;
    }
    case Cmd::grbl_state:
      s.out += fmt("[GC:G0 %s G17 %s %s G94 M5 M9 T0 F%.0f S0]\n", grbl_wcs().c_str(), s.modal.unit_mm == 1.0 ? "G21" : "G20",
                   s.modal.relative ? "G91" : "G90", s.modal.feed_mm_s * 60.0 / s.modal.unit_mm);
      answer_ok(s);
      return;
    case Cmd::grbl_info:
      s.out += fmt("[VER:1.1h.servoarm:%s]\n[OPT:V,%zu,%zu]\n", cfg_.robot_name.c_str(), kMotionQueue, kGrblRxBuffer);
      answer_ok(s);
      return;
    case Cmd::grbl_unlock: {
      // GRBL's "kill alarm lock": here, reset a fault / e-stop, then power the drives up.
      const ArmState st = ctl_.telemetry().state;
      if (st == ArmState::fault || st == ArmState::estop) {
        if (!request(RequestOp::reset, r) || r.result != RtResult::ok) {
          answer_error(s, CmdError::bad_state, fmt("$X: reset refused: %s", bounded_text(r.message).c_str()));
          return;
        }
      }
      const ArmState now = ctl_.telemetry().state;
      if (now == ArmState::idle || now == ArmState::moving || now == ArmState::jogging) {
        answer_ok(s, "already unlocked");
        return;
      }
      if (const ControlResult e = svc_->enable(); !e.ok()) {
        answer_control(s, e);
        return;
      }
      s.enabling = true;
      settle(s);
      return;
    }
    case Cmd::grbl_home: do_home(s, c); return;
    case Cmd::grbl_check:
      if (!s.check_mode) {
        const ArmState st = ctl_.telemetry().state;
        if (st != ArmState::idle && st != ArmState::disabled) {
          answer_error(s, CmdError::busy, fmt("$C: check mode needs the arm at rest (it is %s)", to_string(st)));
          return;
        }
        s.check_mode = true;
        s.check_tail = tail();
        s.check_tool = svc_->active_tool();
        s.check_frame = svc_->active_frame();
        s.out += s.dialect == Dialect::grbl ? "[MSG:Enabled]\n" : "";
        answer_ok(s, s.dialect == Dialect::grbl ? "" : "check mode on: G-code is parsed and checked, nothing moves");
      } else {
        s.check_mode = false;
        s.out += s.dialect == Dialect::grbl ? "[MSG:Disabled]\n" : "";
        answer_ok(s, s.dialect == Dialect::grbl ? "" : "check mode off");
      }
      return;
    default: answer_error(s, CmdError::internal, "not a $ command"); return;
  }
}

}  // namespace servoarm::fw

// ---------------------------------------------------------------------------
// Tools and user frames (frames.hpp)
// ---------------------------------------------------------------------------

namespace servoarm::fw {

std::string Console::frames_refusal() const {
  const FrameResult r = svc_->frames_check();
  if (r.ok()) return "";
  switch (r.arm) {
    case ArmState::moving:
    case ArmState::jogging:
    case ArmState::stopping:
    case ArmState::homing:
    case ArmState::freedrive: return fmt("refused while the arm is %s", to_string(r.arm));
    case ArmState::boot:
    case ArmState::disabled:
    case ArmState::enabling:
    case ArmState::idle:
    case ArmState::fault:
    case ArmState::estop: break;
  }
  return fmt("refused while %u moves are queued (wait, or stop)", unsigned(r.queued));
}

std::string Console::load_frames() { return svc_->load_frames(cfg_.frames_file); }

std::string Console::unsaved_text() const {
  return cfg_.frames_file.empty() ? " (not kept: no frames file, console.frames_file)" : "";
}

namespace {
std::string pose_values(const kin::Pose& p, const ConsoleUnits& u) { return u.pose_text(p); }
template <class List, class Name>
std::size_t find_named(const List& l, std::string_view n, Name name) {
  for (std::size_t i = 0; i < l.size(); ++i)
    if (name(l[i]) == n) return i;
  return l.size();
}
}  // namespace

// A refused tool / frame change whose answer is the same for each request: the name or the
// arm's state ("<what>: <why>"), a full list.
void Console::answer_frame_refusal(Session& s, const FrameResult& r, const std::string& what, std::string_view name) {
  switch (r.refusal) {
    case FrameRefusal::bad_name: answer_error(s, r.error, what + ": " + r.reason); return;
    case FrameRefusal::arm_busy: answer_error(s, r.error, what + ": " + frames_refusal()); return;
    case FrameRefusal::full:
      answer_error(s, r.error, fmt("%s: %zu %s already (%s delete NAME first)", what.c_str(), what == "tool" ? kMaxTools : kMaxFrames,
                                   what == "tool" ? "tools" : "frames", what.c_str()));
      return;
    case FrameRefusal::bad_values: answer_error(s, r.error, what + " " + std::string(name) + ": " + r.reason); return;
    case FrameRefusal::none:
    case FrameRefusal::not_defined:
    case FrameRefusal::active:
    case FrameRefusal::storage: answer_error(s, r.error, what + ": " + to_string(r.refusal)); return;
  }
}

void Console::do_tool(Session& s, const Command& c) {
  const ConsoleUnits& u = cfg_.units;
  const std::string_view name(c.name.data());
  const std::string nm(name);
  const std::string unsaved = unsaved_text();
  if (c.frame_op == FrameOp::list) {
    for (std::size_t i = 0; i < svc_->tool_count(); ++i) {
      const NamedPose& t = svc_->tool(i);
      s.out += fmt("%s %s %s", i == sel_tool() ? "*" : " ", t.name.c_str(), i == 0 ? "(the flange)" : pose_values(t.pose, u).c_str());
      if (t.has_payload)
        s.out += fmt(" mass=%g com=%g,%g,%g", t.mass, u.length_out(t.com.x()), u.length_out(t.com.y()), u.length_out(t.com.z()));
      s.out += '\n';
    }
    answer_ok(s, fmt("%zu tools, active %s%s", svc_->tool_count(), svc_->tool(sel_tool()).name.c_str(), unsaved.c_str()));
    return;
  }
  if (c.frame_op == FrameOp::select) {
    const std::size_t at = svc_->find_tool(name);
    if (at == svc_->tool_count()) {
      answer_error(s, CmdError::bad_option, "tool " + nm + " is not defined (tool lists them)");
      return;
    }
    if (s.check_mode) {
      s.check_tool = at;
      answer_ok(s, "check mode: tool=" + nm + " for the check");
      return;
    }
    const FrameResult r = svc_->select_tool(name);
    if (r.refusal == FrameRefusal::storage) answer_error(s, r.error, "tool not changed: " + r.reason);
    else if (!r.ok()) answer_frame_refusal(s, r, "tool", name);
    else answer_ok(s, "tool=" + r.def.name + unsaved);
    return;
  }
  if (s.check_mode) {  // as GRBL's $C: definitions are not made in check mode
    answer_ok(s, "check mode: not run");
    return;
  }
  if (c.frame_op == FrameOp::remove) {
    const FrameResult r = svc_->delete_tool(name);
    switch (r.refusal) {
      case FrameRefusal::none: answer_ok(s, "tool " + nm + " deleted"); return;
      case FrameRefusal::not_defined: answer_error(s, r.error, "tool " + nm + " is not defined"); return;
      case FrameRefusal::active: answer_error(s, r.error, "tool " + nm + " is active: select another first"); return;
      case FrameRefusal::storage: answer_error(s, r.error, "tool not deleted: " + r.reason); return;
      case FrameRefusal::bad_name:
      case FrameRefusal::bad_values:
      case FrameRefusal::arm_busy:
      case FrameRefusal::full: answer_frame_refusal(s, r, "tool", name); return;
    }
    return;
  }
  // define: the name and the arm first, then the values as given (console units -> SI)
  if (FrameResult no = svc_->frames_check(); check_frame_name(name, true).empty() && !no.ok()) {
    answer_frame_refusal(s, no, "tool", name);
    return;
  }
  const double xyz[3] = {u.length_in(c.vals[0]), u.length_in(c.vals[1]), u.length_in(c.vals[2])};
  const double rpy[3] = {u.angle_in(c.vals[3]), u.angle_in(c.vals[4]), u.angle_in(c.vals[5])};
  const double com[3] = {u.length_in(c.com[0]), u.length_in(c.com[1]), u.length_in(c.com[2])};
  if (const std::string why = check_frame_values(xyz, rpy, c.has_mass, c.mass, com); !why.empty() && check_frame_name(name, true).empty()) {
    answer_error(s, CmdError::out_of_range, "tool " + nm + ": " + why);
    return;
  }
  NamedPose def;
  def.name = nm;
  def.pose.translation() = Eigen::Vector3d(xyz[0], xyz[1], xyz[2]);
  def.pose.linear() = kin::rotation_from_rpy(rpy[0], rpy[1], rpy[2]);
  def.has_payload = c.has_mass;
  def.mass = c.mass;
  def.com = Eigen::Vector3d(com[0], com[1], com[2]);
  if (c.has_radius) {
    def.radius = u.length_in(c.radius);
    if (const std::string why = check_tool_radius(def.radius); !why.empty()) {
      answer_error(s, CmdError::out_of_range, "tool " + nm + ": " + why);
      return;
    }
  }
  const FrameResult r = svc_->define_tool(def);
  if (r.refusal == FrameRefusal::storage) answer_error(s, r.error, "tool not defined: " + r.reason);
  else if (!r.ok()) answer_frame_refusal(s, r, "tool", name);
  else
    answer_ok(s, fmt("tool %s %s %s%s", def.name.c_str(), r.redefined ? "redefined" : "defined", pose_values(def.pose, u).c_str(),
                     ((r.active ? " (active)" : "") + unsaved).c_str()));
}

void Console::do_frame(Session& s, const Command& c) {
  const ConsoleUnits& u = cfg_.units;
  std::string name(c.name.data());
  const std::string unsaved = unsaved_text();
  const std::string full = fmt("frame: %zu frames already (frame delete NAME first)", kMaxFrames);
  if (c.frame_op == FrameOp::list) {
    for (std::size_t i = 0; i < svc_->frame_count(); ++i)
      s.out += fmt("%s %s %s\n", i == sel_frame() ? "*" : " ", svc_->frame(i).name.c_str(),
                   i == 0 ? "(the base frame)" : pose_values(svc_->frame(i).pose, u).c_str());
    answer_ok(s, fmt("%zu frames, active %s%s", svc_->frame_count(), svc_->frame(sel_frame()).name.c_str(), unsaved.c_str()));
    return;
  }
  if (c.frame_op == FrameOp::set_axes) {  // G10 L2 Pn
    if (c.g10_p == 0) {
      name = svc_->frame(sel_frame()).name;
      if (sel_frame() == 0) {
        answer_error(s, CmdError::bad_state, "G10 L2 P0: the active frame is base, which cannot be set (select G54..G59 first)");
        return;
      }
    } else {
      name = "g5" + std::to_string(3 + c.g10_p);
    }
  }
  const std::size_t at = svc_->find_frame(name);
  const bool defined = at < svc_->frame_count();
  const bool g5x = name.size() == 3 && name[0] == 'g' && name[1] == '5' && name[2] >= '4' && name[2] <= '9';
  const bool quiet = s.dialect == Dialect::grbl && c.gcode;  // GRBL: G-code answers a bare ok
  if (c.frame_op == FrameOp::select) {
    if (!defined && !g5x) {
      answer_error(s, CmdError::bad_option, "frame " + name + " is not defined (frame lists them)");
      return;
    }
    if (s.check_mode) {  // g54..g59 not set yet: the identity, as the active one would be
      s.check_frame = defined ? at : 0;
      answer_ok(s, quiet ? "" : "check mode: frame=" + name + (defined ? " for the check" : " (not set: the base frame)"));
      return;
    }
    const FrameResult r = svc_->select_frame(name, g5x);
    if (r.refusal == FrameRefusal::arm_busy)
      answer_error(s, r.error, (c.gcode ? fmt("G%s: ", name.c_str() + 1) : std::string("frame: ")) + frames_refusal());
    else if (r.refusal == FrameRefusal::full) answer_error(s, r.error, full);
    else if (!r.ok()) answer_error(s, r.error, "frame not changed: " + r.reason);
    else answer_ok(s, quiet ? "" : "frame=" + name + unsaved);
    return;
  }
  if (s.check_mode) {
    answer_ok(s, quiet ? "" : "check mode: not run");
    return;
  }
  const std::string prefix = c.gcode ? "G10" : "frame";
  if (c.frame_op == FrameOp::remove) {
    const FrameResult r = svc_->delete_frame(name);
    switch (r.refusal) {
      case FrameRefusal::none: answer_ok(s, "frame " + name + " deleted"); return;
      case FrameRefusal::not_defined: answer_error(s, r.error, "frame " + name + " is not defined"); return;
      case FrameRefusal::active: answer_error(s, r.error, "frame " + name + " is active: select another first"); return;
      case FrameRefusal::storage: answer_error(s, r.error, "frame not deleted: " + r.reason); return;
      case FrameRefusal::bad_name:
      case FrameRefusal::bad_values:
      case FrameRefusal::arm_busy:
      case FrameRefusal::full: answer_frame_refusal(s, r, prefix, name); return;
    }
    return;
  }
  // define (frame NAME x y z rx ry rz: console units) or G10 L2 / L20 (mm / deg, axes not given kept)
  if (const std::string why = check_frame_name(name, false); !why.empty()) {
    answer_error(s, CmdError::bad_option, prefix + ": " + why);
    return;
  }
  if (const FrameResult no = svc_->frames_check(); !no.ok()) {
    answer_frame_refusal(s, no, prefix, name);
    return;
  }
  double xyz[3], rpy[3];
  frame_values(c, defined ? svc_->frame(at).pose : kin::Pose::Identity(), xyz, rpy);
  const double none[3] = {0, 0, 0};
  if (const std::string why = check_frame_values(xyz, rpy, false, 0, none); !why.empty()) {
    answer_error(s, CmdError::out_of_range, (c.gcode ? std::string("G10: frame ") : std::string("frame ")) + name + ": " + why);
    return;
  }
  NamedPose def;
  def.name = name;
  def.pose.translation() = Eigen::Vector3d(xyz[0], xyz[1], xyz[2]);
  def.pose.linear() = kin::rotation_from_rpy(rpy[0], rpy[1], rpy[2]);
  const FrameResult r = svc_->define_frame(def);
  if (r.refusal == FrameRefusal::full) answer_error(s, r.error, full);
  else if (r.refusal == FrameRefusal::storage) answer_error(s, r.error, "frame not set: " + r.reason);
  else if (!r.ok()) answer_frame_refusal(s, r, prefix, name);
  else
    answer_ok(s, quiet ? ""
                       : fmt("frame %s %s %s%s", name.c_str(), r.redefined ? "redefined" : "defined", pose_values(def.pose, u).c_str(),
                             ((r.active ? " (active)" : "") + unsaved).c_str()));
}

// A frame definition's values in SI: `frame NAME x y z rx ry rz` in the console's units;
// G10 L2 in mm / deg, the axes not given kept from `cur`; G10 L20 moves the origin (its axes
// kept) so that the tool point, where it is now, has the given coordinates in it:
// w = R^T (p - t), w_k := v_k, t = p - R w.
void Console::frame_values(const Command& c, const kin::Pose& cur, double xyz[3], double rpy[3]) const {
  const ConsoleUnits& u = cfg_.units;
  if (c.frame_op == FrameOp::set_axes && c.g10_l20) {
    const Eigen::Vector3d p = tcp(tail()).translation();
    Eigen::Vector3d w = cur.linear().transpose() * (p - cur.translation());
    for (int k = 0; k < 3; ++k)
      if (c.axis_mask & (1u << k)) w[k] = c.vals[static_cast<std::size_t>(k)] * 1e-3;
    const Eigen::Vector3d t = p - cur.linear() * w;
    const Eigen::Vector3d r = kin::rpy_from_rotation(cur.linear());
    for (int k = 0; k < 3; ++k) xyz[k] = t[k], rpy[k] = r[k];
  } else if (c.frame_op == FrameOp::set_axes) {
    const Eigen::Vector3d r = kin::rpy_from_rotation(cur.linear());
    for (int k = 0; k < 3; ++k) {
      xyz[k] = c.axis_mask & (1u << k) ? c.vals[static_cast<std::size_t>(k)] * 1e-3 : cur.translation()[k];
      rpy[k] = c.axis_mask & (1u << (k + 3)) ? c.vals[static_cast<std::size_t>(k + 3)] * kDeg : r[k];
    }
  } else {
    for (int k = 0; k < 3; ++k) {
      xyz[k] = u.length_in(c.vals[static_cast<std::size_t>(k)]);
      rpy[k] = u.angle_in(c.vals[static_cast<std::size_t>(k + 3)]);
    }
  }
}

}  // namespace servoarm::fw
