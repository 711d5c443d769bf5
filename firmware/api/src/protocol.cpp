// SPDX-License-Identifier: Apache-2.0
// The API's message table, parser, service dispatch and JSON rendering: the one translation
// unit that includes nlohmann-json (Debian nlohmann-json3-dev 3.11; header-only and slow to
// compile, so no header of the project includes it). Non-real-time threads only.
#include "servoarm/api/protocol.hpp"

#include <stdlib.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <optional>

#include <nlohmann/json.hpp>

#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/orientation.hpp"
#include "servoarm/lang/markdown.hpp"
#include "servoarm/lang/number.hpp"
#include "servoarm/service/stream.hpp"

namespace servoarm::api {

using nlohmann::json;
using fw::CmdError;

struct ResultFields {
  json j = json::object();
  std::string error;    ///< "" ok, else the code's name
  std::string message;  ///< one line with the error
  void fail(CmdError e, std::string m) {
    error = fw::to_string(e);
    message = std::move(m);
  }
  void fail(std::string code, std::string m) {
    error = std::move(code);
    message = std::move(m);
  }
};

const char* to_string(ApiError e) {
  switch (e) {
    case ApiError::bad_json: return "bad_json";
    case ApiError::unauthenticated: return "unauthenticated";
    case ApiError::forbidden: return "forbidden";
    case ApiError::not_in_control: return "not_in_control";
    case ApiError::controlled: return "controlled";
    case ApiError::rate_limited: return "rate_limited";
  }
  return "?";
}

const char* to_string(Gate g) {
  switch (g) {
    case Gate::open: return "anyone";
    case Gate::observer: return "observer";
    case Gate::stop: return "any client (wins over control)";
    case Gate::operator_: return "operator";
    case Gate::control: return "operator in control";
  }
  return "?";
}

const char* to_string(ArgType t) {
  switch (t) {
    case ArgType::number: return "number";
    case ArgType::integer: return "integer";
    case ArgType::boolean: return "boolean";
    case ArgType::text: return "string";
    case ArgType::numbers: return "number[]";
  }
  return "?";
}

namespace {


// ---------------------------------------------------------------------------------------------
// Rendering of the service's typed results
// ---------------------------------------------------------------------------------------------

json vec(const kin::JointVector& q) {
  json a = json::array();
  for (int i = 0; i < q.size(); ++i) a.push_back(q[i]);
  return a;
}

void control_result(const fw::ControlResult& r, ResultFields& out) {
  if (!r.ok()) return out.fail(r.error, r.reason);
  out.j["reason"] = r.reason;
}

void move_result(const fw::MoveResult& r, ResultFields& out) {
  if (!r.ok()) {
    std::string m = fw::to_string(r.refusal);
    char b[200] = {};
    switch (r.refusal) {
      case fw::MoveRefusal::joint_limit:
        std::snprintf(b, sizeof b, ": joint %d = %.6g outside [%.6g, %.6g]", r.joint, r.value, r.lower, r.upper);
        break;
      case fw::MoveRefusal::duration: std::snprintf(b, sizeof b, ": %.3f s", r.duration); break;
      case fw::MoveRefusal::plan:
        std::snprintf(b, sizeof b, ": %s at s = %.3f joint %d", kin::to_string(r.status), r.s, r.joint);
        break;
      case fw::MoveRefusal::linear_speed: std::snprintf(b, sizeof b, ": %.6g m/s", r.speed); break;
      case fw::MoveRefusal::none:
      case fw::MoveRefusal::arm_state:
      case fw::MoveRefusal::not_homed:
      case fw::MoveRefusal::queue_full: break;
    }
    m += b;
    if (!r.reason.empty()) m += ": " + r.reason;
    return out.fail(r.error, m);
  }
  out.j["motion"] = r.id;
  out.j["duration"] = r.duration;
  out.j["goal"] = vec(r.goal);
  if (r.speed > 0) out.j["speed"] = r.speed;
}

void jog_result(const fw::JogResult& r, ResultFields& out) {
  if (!r.ok()) {
    std::string m = fw::to_string(r.refusal);
    if (r.joint >= 0) m += ": joint " + std::to_string(r.joint);
    if (!r.reason.empty()) m += ": " + r.reason;
    return out.fail(r.error, m);
  }
  out.j["reason"] = r.reason;
  if (r.clamped) out.j["clamped_at"] = r.value;
}

/// The joints given (rad / m): exactly the arm's count, each finite.
bool joints_of(ServiceCall& c, const char* name, kin::JointVector& q, ResultFields& out) {
  const ArgValue* a = c.rq.arg(name);
  const int n = c.cx.chain->n_joints;
  if (a == nullptr || static_cast<int>(a->list.size()) != n) {
    out.fail(CmdError::arg_count, std::string(name) + ": expected " + std::to_string(n) + " joint values, got " +
                                      std::to_string(a ? a->list.size() : 0));
    return false;
  }
  q.resize(n);
  for (int j = 0; j < n; ++j) q[j] = a->list[static_cast<std::size_t>(j)];
  return true;
}

double num_or(const ServiceCall& c, const char* name, double dflt) {
  const ArgValue* a = c.rq.arg(name);
  return a != nullptr && a->present ? a->num : dflt;
}

/// A stream's counts (a `stream` answer's and the state's `stream`).
json stream_json(const fw::StreamStats& s) {
  return {{"targets", s.targets}, {"timed", s.timed}, {"stale", s.stale}, {"late_ms", s.late_s * 1e3},
          {"late_max_ms", s.late_max_s * 1e3}, {"jitter_ms", s.jitter_s * 1e3}};
}

/// A streamed target's client time `t` (s), when given.
std::optional<double> time_of(const ServiceCall& c) {
  const ArgValue* a = c.rq.arg("t");
  return a != nullptr && a->present ? std::optional<double>(a->num) : std::nullopt;
}

// The active tool's chain and IK, as the console's moves have them.
fw::MoveContext move_cx(ServiceCall& c) {
  fw::MoveContext m;
  m.chain = &c.cx.svc->tool_chain(c.cx.svc->active_tool());
  m.ik = c.cx.svc->tool_ik(c.cx.svc->active_tool());
  return m;
}

// Resume: the arm after a hold, and a paused program (which needs no held move to resume).
void resume_result(ServiceCall& c, ResultFields& out);

// ---------------------------------------------------------------------------------------------
// The message table
// ---------------------------------------------------------------------------------------------

constexpr ArgSpec kNone[] = {{"", ArgType::number, false, 0, 0, ""}};
constexpr std::span<const ArgSpec> none() { return {kNone, 0}; }

constexpr ArgSpec kHello[] = {
    {"token", ArgType::text, false, 1, 256, "the client's token (required when api.tokens_file is set)"}};
constexpr ArgSpec kSubscribe[] = {
    {"topic", ArgType::text, true, 1, 16, "`state` or `events`"},
    {"rate_hz", ArgType::number, false, 1, 4000, "state: samples per second (at most the loop rate; default 50)"}};
constexpr ArgSpec kTopic[] = {{"topic", ArgType::text, true, 1, 16, "`state` or `events`"}};
constexpr ArgSpec kHome[] = {{"joint", ArgType::integer, false, -1, kin::kMaxJoints - 1, "0-based; -1 or left out: every joint"}};
constexpr ArgSpec kMovej[] = {
    {"q", ArgType::numbers, true, -1e6, 1e6, "the goal, one value per joint (rad / m)"},
    {"speed_pct", ArgType::number, false, 1, 100, "percent of the joint limits (default motion.joint_speed_pct)"},
    {"blend", ArgType::number, false, 0, 1e3, "blend tolerance at the goal (rad); 0: exact stop"}};
constexpr ArgSpec kMovel[] = {
    {"position", ArgType::numbers, true, -1e3, 1e3, "the active tool's point [x, y, z] in the active user frame (m)"},
    {"rpy", ArgType::numbers, false, -10, 10, "the tool orientation [roll, pitch, yaw] in the active user frame (rad); left out: the orientation the queue ends with"},
    {"speed", ArgType::number, false, 1e-6, 1e3, "tool speed (m/s; default motion.linear_speed_mm_s)"},
    {"blend", ArgType::number, false, 0, 1e3, "blend tolerance at the target (m)"}};
constexpr ArgSpec kJog[] = {
    {"joint", ArgType::integer, true, 0, kin::kMaxJoints - 1, "0-based"},
    {"increment", ArgType::number, false, -1e3, 1e3, "by this much (rad / m); left out: continuous towards `direction`"},
    {"direction", ArgType::integer, false, -1, 1, "continuous jog: +1 or -1 (kept alive by repeating it within console.jog_deadman_ms)"},
    {"speed_pct", ArgType::number, false, 1, 100, "percent of the joint limits (default console.jog_speed_pct)"}};
constexpr ArgSpec kOn[] = {{"on", ArgType::boolean, true, 0, 1, "on (true) or off"}};
constexpr ArgSpec kOutput[] = {{"index", ArgType::integer, true, 0, 1023, "the [[output]] index (0-based)"},
                               {"on", ArgType::boolean, true, 0, 1, "on (true) or off"}};
constexpr ArgSpec kEvents[] = {{"since", ArgType::integer, false, 0, 9e15, "the last sequence number the client has (default 0: every event kept)"}};
constexpr ArgSpec kRecordMcap[] = {
    {"rate_hz", ArgType::number, false, 1e-3, 1e5, "state samples per second, at most the control rate (default record.rate_hz)"},
    {"stop", ArgType::boolean, false, 0, 1, "true: ends the recording"}};
constexpr ArgSpec kStream[] = {
    {"q", ArgType::numbers, true, -1e6, 1e6, "the newest joint target, one value per joint (rad / m)"},
    {"start", ArgType::boolean, false, 0, 1, "true: begins a stream (the first target; again after the stream ended)"},
    {"qd", ArgType::numbers, false, -1e6, 1e6,
     "the target's joint velocities (rad/s / m/s); left out: estimated from this target and the one before"},
    {"t", ArgType::number, false, 0, 1e10,
     "when the client sampled the target (s on its own monotonic clock, any origin): targets are spaced by it, not "
     "by their arrival; one not newer than the stream's newest is dropped (answered with `stale`); see Streaming targets"}};
constexpr ArgSpec kStreamPose[] = {
    {"position", ArgType::numbers, true, -1000, 1000, "the tool point [x, y, z] (m), in the base frame or the active user frame"},
    {"rpy", ArgType::numbers, true, -10, 10, "the tool orientation [roll, pitch, yaw] (rad) in the same frame"},
    {"frame", ArgType::text, false, 4, 4, "`base` (default) or `user` (the active user frame)"},
    {"start", ArgType::boolean, false, 0, 1, "true: begins a stream (the first target; again after the stream ended)"},
    {"t", ArgType::number, false, 0, 1e10, "when the client sampled the pose (s on its own monotonic clock), as for `stream`"}};

using C = ServiceCall;
using R = ResultFields;

// Programs, teach points, tools and frames: the answers' fields.

/// The program a program_check / program_run names: its text (loaded as the program loader
/// reads a file, from a private temporary folder; `call` looks in the programs folder), or a
/// program of the programs folder. False: `out` has the error (a line the loader refuses: its
/// file and line too).
bool load_api_program(C& c, prog::Program& p, std::string& name, R& out) {
  const ArgValue* text = c.rq.arg("text");
  const ArgValue* nm = c.rq.arg("name");
  const bool gcode = num_or(c, "gcode", 0) != 0;
  if (!text->present && !nm->present) return out.fail(CmdError::arg_count, "give text or name"), false;
  if (nm->present) {
    if (std::string why = prog::check_program_name(nm->text); !why.empty()) return out.fail(CmdError::bad_option, "name: " + why), false;
    name = nm->text;
  } else {
    name = gcode ? "editor.gcode" : "editor.arm";
  }
  prog::ProgramContext px;
  px.chain = c.cx.chain;
  px.units = c.cx.units;
  px.dir = c.cx.programs_dir;
  px.points = &c.cx.svc->points();
  std::string err, path, dir;
  if (text->present) {
    char tmpl[] = "/tmp/servoarm_api_XXXXXX";
    if (::mkdtemp(tmpl) == nullptr) return out.fail(CmdError::storage, "cannot make a temporary folder for the program"), false;
    dir = tmpl;
    std::string file = name;
    if (gcode != prog::is_gcode_file(file)) file += gcode ? ".gcode" : ".arm";
    path = dir + "/" + file;
    {
      std::ofstream f(path, std::ios::binary);
      f << text->text;
      if (!f) err = "cannot write the program to a temporary file";
    }
    if (err.empty()) err = prog::load_program(path, px, p);
    ::unlink(path.c_str());
    ::rmdir(dir.c_str());
    // the temporary folder is nobody's business: the program is shown by its name
    for (std::string* s : {&err}) {
      for (auto at = s->find(dir + "/"); at != std::string::npos; at = s->find(dir + "/")) s->erase(at, dir.size() + 1);
    }
    for (std::string& f : p.files)
      if (f.rfind(dir + "/", 0) == 0) f.erase(0, dir.size() + 1);
  } else {
    if (c.cx.programs_dir.empty()) return out.fail(CmdError::program, "name: no programs folder (programs.dir)"), false;
    path = prog::find_program(c.cx.programs_dir, name);
    if (path.empty()) return out.fail(CmdError::program, "name: no program '" + name + "' in " + c.cx.programs_dir), false;
    err = prog::load_program(path, px, p);
  }
  if (err.empty()) return true;
  // "<file>:<line>: <reason>": the place as fields too
  const auto colon = err.find(':');
  if (colon != std::string::npos) {
    std::size_t k = colon + 1;
    int line = 0;
    while (k < err.size() && err[k] >= '0' && err[k] <= '9' && line < 100000000) line = line * 10 + (err[k++] - '0');
    if (k > colon + 1 && k < err.size() && err[k] == ':') {
      out.j["file"] = err.substr(0, colon);
      out.j["line"] = line;
    }
  }
  out.fail(CmdError::program, err);
  return false;
}

void check_refusal(const fw::ProgramCheckResult& r, R& out) {
  R m;
  if (r.move.error != CmdError::ok) move_result(r.move, m);
  out.j["file"] = r.file;
  out.j["line"] = r.line;
  out.j["step"] = r.step;
  out.fail(r.error, r.file + ":" + std::to_string(r.line) + ": " + (m.message.empty() ? r.reason : m.message));
}

void counts_result(const fw::ProgramCheckResult& r, R& out) {
  out.j["steps"] = r.counts.steps;
  out.j["moves"] = r.counts.moves;
  out.j["joint_moves"] = r.counts.joint_moves;
  out.j["line_moves"] = r.counts.line_moves;
  out.j["dwells"] = r.counts.dwells;
  out.j["duration"] = r.duration;
  out.j["summary"] = prog::counts_text(r.counts);
  out.j["planned_steps"] = r.planned;  // fewer than steps: a tool / frame definition at that step
}

json program_json(const fw::ProgramStatus& p) {
  return {{"state", fw::to_string(p.state)}, {"name", p.name},   {"file", p.file},
          {"line", p.line},                  {"step", p.step},   {"steps", p.steps},
          {"running_line", p.running_line}};
}

void program_refusal(const fw::ProgramResult& r, R& out) {
  std::string m = fw::to_string(r.refusal);
  switch (r.refusal) {
    case fw::ProgramRefusal::running: m += ": program " + r.status.name + " is " + fw::to_string(r.status.state); break;
    case fw::ProgramRefusal::program_state: m += ": the program is " + std::string(fw::to_string(r.status.state)) + ", not paused"; break;
    case fw::ProgramRefusal::arm_not_ready:
      m += ": needs the arm at rest with nothing queued and every joint homed (it is " + std::string(fw::to_string(r.arm)) + ", " +
           std::to_string(r.queued) + " queued)";
      break;
    case fw::ProgramRefusal::none:
    case fw::ProgramRefusal::no_program: break;
  }
  out.fail(r.error, m);
}

void program_answer(const fw::ProgramResult& r, R& out) {
  if (!r.ok()) return program_refusal(r, out);
  out.j["program"] = program_json(r.status);
}

void resume_result(C& c, R& out) {
  const fw::ControlResult r = c.cx.svc->resume();
  const bool program = c.cx.svc->run_state() != fw::RunState::idle;
  if (r.error == CmdError::timeout || (!r.ok() && !program)) return control_result(r, out);
  c.cx.svc->program_tick();
  out.j["reason"] = r.reason;
  if (program) out.j["program"] = program_json(c.cx.svc->program_status());
}

json pose_json(const kin::Pose& p) {
  const Eigen::Vector3d rpy = kin::rpy_from_rotation(p.linear());
  return {{"position", {p.translation().x(), p.translation().y(), p.translation().z()}}, {"rpy", {rpy.x(), rpy.y(), rpy.z()}}};
}

json point_json(const prog::TeachPoint& t) {
  return {{"name", t.name}, {"q", vec(t.q)}, {"pose", pose_json(t.pose)}, {"tool", t.tool}, {"frame", t.frame}};
}

json named_pose_json(const fw::NamedPose& n) {
  json j = pose_json(n.pose);
  j["name"] = n.name;
  if (n.has_payload) j["mass"] = n.mass;
  return j;
}

void point_answer(const fw::PointResult& r, R& out) {
  if (!r.ok()) {
    std::string m = fw::to_string(r.refusal);
    switch (r.refusal) {
      case fw::PointRefusal::not_here:
        m += ": " + std::string(fw::to_string(r.here.refusal));
        if (!r.here.reason.empty()) m += ": " + r.here.reason;
        break;
      case fw::PointRefusal::no_point: m += " (" + std::to_string(r.count) + " points)"; break;
      case fw::PointRefusal::joint_count: m += ": the point has " + std::to_string(r.joints) + " joints"; break;
      case fw::PointRefusal::program: m += ": a program runs"; break;
      case fw::PointRefusal::none:
      case fw::PointRefusal::bad_point:
      case fw::PointRefusal::storage: if (!r.reason.empty()) m += ": " + r.reason; break;
    }
    return out.fail(r.error, m);
  }
  out.j["point"] = point_json(r.point);
  out.j["count"] = r.count;
  out.j["kept"] = r.kept;
}

void frame_answer(const fw::FrameResult& r, const char* what, R& out) {
  if (!r.ok()) {
    std::string m = std::string(what) + ": " + fw::to_string(r.refusal);
    if (r.refusal == fw::FrameRefusal::arm_busy)
      m += " (" + std::string(fw::to_string(r.arm)) + ", " + std::to_string(r.queued) + " queued)";
    if (!r.reason.empty()) m += ": " + r.reason;
    return out.fail(r.error, m);
  }
  out.j[what] = r.def.name;
}

constexpr ArgSpec kProgram[] = {
    {"text", ArgType::text, false, 1, 1 << 20, "the program's text (the native language, or G-code when `gcode` is true); left out: `name` is a program of the programs folder"},
    {"gcode", ArgType::boolean, false, 0, 1, "`text` is G-code (default false: the native language)"},
    {"name", ArgType::text, false, 1, 63, "a program of the programs folder (programs.dir); with `text`: the name the text is shown and run by"}};
constexpr ArgSpec kPointName[] = {{"name", ArgType::text, true, 1, 31, "the teach point's name"}};
constexpr ArgSpec kPointGo[] = {
    {"name", ArgType::text, true, 1, 31, "the teach point's name"},
    {"line", ArgType::boolean, false, 0, 1, "true: a straight tool line to it; false (default): a joint move to its joints"},
    {"speed", ArgType::number, false, 1e-6, 1e3, "joint move: percent of the joint limits; line: m/s (default: the configured)"}};
constexpr ArgSpec kProgramSave[] = {
    {"name", ArgType::text, true, 1, 63, "the program's name in the programs folder"},
    {"text", ArgType::text, true, 1, 1 << 20, "the program's text (the native language, or G-code when `gcode` is true)"},
    {"gcode", ArgType::boolean, false, 0, 1, "`text` is G-code, saved as `name`.gcode (default false: `name`.arm)"}};

constexpr ArgSpec kToolDefine[] = {
    {"name", ArgType::text, true, 1, 23, "the tool's name (letters, digits, `_`, `-`; not tool0)"},
    {"position", ArgType::numbers, true, -10, 10, "the tool point [x, y, z] in the flange frame (m)"},
    {"rpy", ArgType::numbers, true, -10, 10, "the tool's orientation [roll, pitch, yaw] in the flange frame (rad)"},
    {"mass", ArgType::number, false, 0, 1000, "its payload (kg); left out: none"},
    {"com", ArgType::numbers, false, -10, 10, "the payload's centre of mass [x, y, z] in the tool frame (m; with mass)"}};
constexpr ArgSpec kFrameDefine[] = {
    {"name", ArgType::text, true, 1, 23, "the user frame's name (letters, digits, `_`, `-`; not base)"},
    {"position", ArgType::numbers, true, -10, 10, "the frame's origin [x, y, z] in the base frame (m)"},
    {"rpy", ArgType::numbers, true, -10, 10, "the frame's orientation [roll, pitch, yaw] in the base frame (rad)"}};

// A tool's or frame's definition from its arguments; false (answered) on a wrong count.
bool named_pose_of(ServiceCall& c, fw::NamedPose& d, R& out) {
  const ArgValue* p = c.rq.arg("position");
  const ArgValue* r = c.rq.arg("rpy");
  if (p->list.size() != 3) return out.fail(CmdError::arg_count, "position: expected [x, y, z]"), false;
  if (r->list.size() != 3) return out.fail(CmdError::arg_count, "rpy: expected [roll, pitch, yaw]"), false;
  d.name = c.rq.arg("name")->text;
  d.pose.linear() = kin::rotation_from_rpy(r->list[0], r->list[1], r->list[2]);
  d.pose.translation() = Eigen::Vector3d(p->list[0], p->list[1], p->list[2]);
  const ArgValue* m = c.rq.arg("mass");
  const ArgValue* com = c.rq.arg("com");
  if (com != nullptr && com->present && !(m != nullptr && m->present)) return out.fail(CmdError::bad_option, "com: only with mass"), false;
  if (m != nullptr && m->present) {
    d.has_payload = true;
    d.mass = m->num;
    if (com != nullptr && com->present) {
      if (com->list.size() != 3) return out.fail(CmdError::arg_count, "com: expected [x, y, z]"), false;
      d.com = Eigen::Vector3d(com->list[0], com->list[1], com->list[2]);
    }
  }
  return true;
}

constexpr ArgSpec kFrameName[] = {{"name", ArgType::text, true, 1, 23, "the tool's / user frame's name"}};
constexpr ArgSpec kJogCartesian[] = {
    {"axis", ArgType::integer, true, 0, 5, "0..2: along x, y, z (m); 3..5: about x, y, z (rad)"},
    {"frame", ArgType::text, false, 4, 4, "whose axes: `base` (default), `tool` or `user` (the active user frame)"},
    {"increment", ArgType::number, false, -10, 10, "by this much (m / rad); left out: continuous towards `direction`"},
    {"direction", ArgType::integer, false, -1, 1, "continuous jog: +1 or -1 (kept alive by repeating it within console.jog_deadman_ms)"},
    {"speed_pct", ArgType::number, false, 1, 100, "percent of the linear and angular limits (default console.jog_speed_pct)"}};
constexpr ArgSpec kMotion[] = {
    {"motion", ArgType::integer, false, 0, 4e9, "the motion's id (a move's answer, the state's `running`); left out: the running motion"}};
constexpr ArgSpec kFeed[] = {{"pct", ArgType::integer, true, fw::kMinFeedOverride, fw::kMaxFeedOverride, "the feed override (percent): scales jogs and the moves queued from now on"}};

constexpr ArgSpec kSafetyStage[] = {
    {"changes", ArgType::text, true, 1, 4096,
     "[safety] keys and their new values as TOML, `key = value` lines (newline or `;` between), e.g. "
     "`tcp_speed_mm_s = 200; reduced_tcp_speed_mm_s = 50`"}};
constexpr ArgSpec kSafetyMode[] = {
    {"mode", ArgType::text, true, 1, 16, "`normal` or `reduced`"},
    {"confirm", ArgType::boolean, false, 0, 1,
     "true: the operator confirms a switch that loosens the limits (Reduced -> Normal; refused without it)"}};
constexpr ArgSpec kSafetyConfirm[] = {
    {"checksum", ArgType::text, true, 8, 8, "the staged change's checksum as `safety_stage` answered it (8 hex digits)"}};

// A safety change's answer: the checksums (8 hex digits), what changes, the seconds left to confirm.
void safety_change_result(const fw::SafetyChangeResult& r, bool staged, R& out) {
  if (!r.ok()) return out.fail(r.error, r.reason);
  char now[9], was[9];
  std::snprintf(now, sizeof now, "%08X", static_cast<unsigned>(r.checksum));
  std::snprintf(was, sizeof was, "%08X", static_cast<unsigned>(r.previous));
  out.j["checksum"] = now;
  out.j["previous"] = was;
  out.j["changes"] = r.changes;
  if (staged) out.j["expires_s"] = r.expires_s;
}

constexpr MessageSpec kMessages[] = {
    {"hello", kHello, Gate::open, Where::session, "-",
     "authenticates (with a token when the server has a token file) and answers protocol, robot, joints with their "
     "limits, units, rate, the client's role and id, and who holds control",
     nullptr},
    {"subscribe", kSubscribe, Gate::observer, Where::session, "Controller::telemetry / ArmService::events_since",
     "starts a stream: `state` samples at `rate_hz`, or every `event` with its sequence number", nullptr},
    {"unsubscribe", kTopic, Gate::observer, Where::session, "-", "ends a stream", nullptr},
    {"state", none(), Gate::observer, Where::session, "Controller::telemetry", "one state sample as the result", nullptr},
    {"take_control", none(), Gate::operator_, Where::session, "-",
     "makes this client the one in control (refused as `controlled` while another holds it); every client is told",
     nullptr},
    {"release_control", none(), Gate::operator_, Where::session, "-", "gives control up; every client is told", nullptr},
    {"events", kEvents, Gate::observer, Where::service, "ArmService::events_since",
     "the events after `since` still kept, and how many of them are no longer kept (`missed`)",
     +[](C& c, R& out) {
       c.cx.svc->poll_events();
       const fw::EventBatch b = c.cx.svc->events_since(static_cast<std::uint64_t>(num_or(c, "since", 0)));
       json a = json::array();
       for (const fw::ArmEvent& e : b.events) a.push_back(json::parse(event_line(e, c.cx.svc->event_detail(e), 0)));
       out.j["events"] = std::move(a);
       out.j["missed"] = b.missed;
     }},
    {"stop", none(), Gate::stop, Where::service, "ArmService::control(stop)", "stops on the limits and drops the queue",
     +[](C& c, R& out) { control_result(c.cx.svc->control(fw::RequestOp::stop), out); }},
    {"hold", none(), Gate::stop, Where::service, "ArmService::hold", "feed hold: ramps down, keeps the queue (a running program pauses)",
     +[](C& c, R& out) { control_result(c.cx.svc->hold(), out); }},
    {"estop", none(), Gate::stop, Where::service, "ArmService::control(estop)", "emergency stop (needs `reset`)",
     +[](C& c, R& out) { control_result(c.cx.svc->control(fw::RequestOp::estop), out); }},
    {"resume", none(), Gate::control, Where::service, "ArmService::resume", "resumes after a hold; a paused program runs on",
     +[](C& c, R& out) { resume_result(c, out); }},
    {"enable", none(), Gate::control, Where::service, "ArmService::enable", "powers the drives",
     +[](C& c, R& out) { control_result(c.cx.svc->enable(), out); }},
    {"disable", none(), Gate::control, Where::service, "ArmService::control(disable)", "powers the drives down",
     +[](C& c, R& out) { control_result(c.cx.svc->control(fw::RequestOp::disable), out); }},
    {"reset", none(), Gate::control, Where::service, "ArmService::control(reset)", "clears a fault or an e-stop",
     +[](C& c, R& out) { control_result(c.cx.svc->control(fw::RequestOp::reset), out); }},
    {"home", kHome, Gate::control, Where::service, "ArmService::home", "starts the homing cycle (progress as events)",
     +[](C& c, R& out) {
       const int j = static_cast<int>(num_or(c, "joint", -1));
       if (j >= c.cx.chain->n_joints)
         return out.fail(CmdError::out_of_range, "joint: " + std::to_string(j) + " is not a joint of the arm");
       control_result(c.cx.svc->home(j), out);
     }},
    {"park", none(), Gate::control, Where::service, "ArmService::move(park_request)", "joint move to the park pose",
     +[](C& c, R& out) { move_result(c.cx.svc->move(c.cx.svc->park_request(), move_cx(c)), out); }},
    {"movej", kMovej, Gate::control, Where::service, "ArmService::move(MoveJoints)",
     "jerk-limited joint move, queued; the result has the motion's id and duration",
     +[](C& c, R& out) {
       fw::MoveJoints m;
       if (!joints_of(c, "q", m.goal, out)) return;
       m.speed_pct = num_or(c, "speed_pct", 0);
       m.blend = num_or(c, "blend", -1);
       move_result(c.cx.svc->move(m, move_cx(c)), out);
     }},
    {"movel", kMovel, Gate::control, Where::service, "ArmService::move(MoveLine)",
     "straight line of the active tool in the active user frame, path-checked and queued",
     +[](C& c, R& out) {
       const ArgValue* p = c.rq.arg("position");
       const ArgValue* r = c.rq.arg("rpy");
       if (p->list.size() != 3) return out.fail(CmdError::arg_count, "position: expected [x, y, z]");
       if (r->present && r->list.size() != 3) return out.fail(CmdError::arg_count, "rpy: expected [roll, pitch, yaw]");
       fw::MoveLine m;
       const fw::MoveContext cx = move_cx(c);
       const kin::Pose F = c.cx.svc->frame(c.cx.svc->active_frame()).pose;  // the active user frame
       kin::Pose at = kin::Pose::Identity();  // where the queue ends, in the frame
       kin::forward(*cx.chain, c.cx.svc->tail(), at);
       at = F.inverse() * at;
       if (r->present) at.linear() = kin::rotation_from_rpy(r->list[0], r->list[1], r->list[2]);
       at.translation() = Eigen::Vector3d(p->list[0], p->list[1], p->list[2]);
       m.target = F * at;
       m.speed = num_or(c, "speed", 0);
       m.blend = num_or(c, "blend", -1);
       move_result(c.cx.svc->move(m, cx), out);
     }},
    {"jog", kJog, Gate::control, Where::service, "ArmService::jog(JointJog)",
     "joint jog by an increment, or continuous (stops unless repeated within the deadman time)",
     +[](C& c, R& out) {
       fw::JointJog j;
       j.joint = static_cast<int>(num_or(c, "joint", 0));
       if (j.joint >= c.cx.chain->n_joints)
         return out.fail(CmdError::out_of_range, "joint: " + std::to_string(j.joint) + " is not a joint of the arm");
       const ArgValue* inc = c.rq.arg("increment");
       const ArgValue* dir = c.rq.arg("direction");
       if (inc->present == dir->present) return out.fail(CmdError::arg_count, "give one of increment and direction");
       j.continuous = dir->present;
       j.direction = dir->num < 0 ? -1 : 1;
       if (j.continuous && dir->num == 0) return out.fail(CmdError::out_of_range, "direction: +1 or -1");
       j.increment = inc->num;
       j.speed_pct = num_or(c, "speed_pct", -1);
       fw::JogContext jx;
       jx.chain = c.cx.chain;
       jx.ik = c.cx.ik;
       jog_result(c.cx.svc->jog(j, jx), out);
     }},
    {"jog_cancel", none(), Gate::control, Where::service, "ArmService::jog_cancel", "ends the running jog",
     +[](C& c, R& out) { control_result(c.cx.svc->jog_cancel(), out); }},
    {"freedrive", kOn, Gate::control, Where::service, "ArmService::freedrive", "hand guiding on or off",
     +[](C& c, R& out) { control_result(c.cx.svc->freedrive(c.rq.arg("on")->num != 0), out); }},
    {"collision", kOn, Gate::control, Where::service, "ArmService::collision_detection", "collision detection on or off",
     +[](C& c, R& out) { control_result(c.cx.svc->collision_detection(c.rq.arg("on")->num != 0), out); }},
    {"record_mcap", kRecordMcap, Gate::operator_, Where::service, "ArmService::record_mcap_start / record_mcap_stop",
     "records the telemetry, setpoints, events and robot description into an MCAP file in record.dir "
     "(docs/foxglove-mcap.md); answers the file, or at stop its files, frames and missed cycles",
     +[](C& c, R& out) {
       if (c.rq.arg("stop")->present && c.rq.arg("stop")->num != 0) {
         if (!c.cx.svc->mcap_status().active && c.cx.svc->mcap_status().error.empty())
           return out.fail(CmdError::bad_state, "no MCAP recording");
         const fw::McapStatus s = c.cx.svc->record_mcap_stop();
         out.j = {{"file", s.file}, {"files", s.files}, {"frames", s.frames}, {"missed", s.missed}, {"events", s.events},
                  {"bytes", s.bytes}, {"rate_hz", s.rate_hz}, {"ended", s.error}};
         return;
       }
       const std::string e = c.cx.svc->record_mcap_start(num_or(c, "rate_hz", c.cx.svc->mcap_settings().rate_hz));
       if (!e.empty()) return out.fail(CmdError::bad_state, e);
       out.j = {{"file", c.cx.svc->mcap_status().file}, {"rate_hz", c.cx.svc->mcap_status().rate_hz}};
     }},
    {"output", kOutput, Gate::control, Where::service, "ArmService::set_output", "sets a digital output at once",
     +[](C& c, R& out) {
       fw::OutputRequest o;
       o.index = static_cast<std::size_t>(num_or(c, "index", 0));
       o.on = c.rq.arg("on")->num != 0;
       const fw::OutputResult r = c.cx.svc->set_output(o);
       if (!r.ok()) return out.fail(r.error, std::string(fw::to_string(r.refusal)) + " (" + std::to_string(r.count) + " outputs)");
     }},
    {"safety_mode", kSafetyMode, Gate::control, Where::service, "ArmService::set_safety_mode",
     "switches the safety envelope's mode (docs/safety.md#normal-and-reduced-mode): Reduced at once; Reduced -> Normal loosens the "
     "limits and needs `confirm`: true (refused in one line without it, the mode kept)",
     +[](C& c, R& out) {
       const std::string& m = c.rq.arg("mode")->text;
       if (m != "normal" && m != "reduced") return out.fail(CmdError::bad_option, "mode: normal or reduced, not \"" + m + "\"");
       const ArgValue* cf = c.rq.arg("confirm");
       control_result(c.cx.svc->set_safety_mode(m == "reduced" ? kin::SafetyMode::reduced : kin::SafetyMode::normal,
                                                 cf != nullptr && cf->present && cf->num != 0),
                      out);
     }},
    {"safety_stage", kSafetyStage, Gate::control, Where::service, "ArmService::stage_safety",
     "stages a run-time change of the [safety] section (docs/safety.md#confirming-a-change): checked against the "
     "robot, nothing changes yet; answers the `checksum` the configuration will have, the one in force "
     "(`previous`), what changes and the seconds left to confirm it (`expires_s`)",
     +[](C& c, R& out) { safety_change_result(c.cx.svc->stage_safety(c.rq.arg("changes")->text), true, out); }},
    {"safety_confirm", kSafetyConfirm, Gate::control, Where::service, "ArmService::confirm_safety",
     "applies the staged [safety] change when `checksum` is its checksum, in time, with the arm at rest; "
     "refused in one line otherwise (nothing staged, another checksum, expired: the change is then dropped)",
     +[](C& c, R& out) {
       const std::string& t = c.rq.arg("checksum")->text;
       std::uint32_t v = 0;
       if (!fw::parse_checksum(t, v)) return out.fail(CmdError::bad_number, "checksum: \"" + t + "\" is not 8 hex digits");
       safety_change_result(c.cx.svc->confirm_safety(v), false, out);
     }},
    {"stream", kStream, Gate::control, Where::service, "StreamService::target",
     "streaming (servo) mode: the newest joint target, latest wins, moving on at its velocity (`qd`, or estimated) "
     "for up to twice the time between targets; the arm tracks it jerk-limited within its limits, matching its "
     "velocity rather than stopping at each target, and brakes to rest, ending the stream with an event, when no target comes within api.stream_deadman_ms; a stop "
     "ends it (the next target must say start)",
     +[](C& c, R& out) {
       if (c.cx.stream == nullptr) return out.fail(CmdError::unsupported, "streaming targets are not available here");
       kin::JointVector q;
       if (!joints_of(c, "q", q, out)) return;
       kin::JointVector qd;
       if (const ArgValue* v = c.rq.arg("qd"); v != nullptr && v->present && !joints_of(c, "qd", qd, out)) return;
       const fw::StreamResult r = c.cx.stream->target(q, num_or(c, "start", 0) != 0, qd, time_of(c));
       if (!r.ok()) return out.fail(r.error, r.reason);
       if (r.clamped) out.j["clamped"] = true;
       if (r.stale) out.j["stale"] = true;
       out.j["stream"] = stream_json(r.stats);
     }},
    {"stream_pose", kStreamPose, Gate::control, Where::service, "StreamService::target_pose",
     "streaming (servo) mode with a Cartesian target: the active tool's pose, solved by the active tool's IK on the "
     "service thread (nearest to the last target) and streamed as `stream` streams joints; refused in one line, the arm "
     "keeping its last target, when the pose has no solution within the joint limits (`unreachable`), its solution is "
     "more than api.stream_max_step_deg from the last target on a joint (`out_of_range`, never clamped) or it is "
     "outside the safety envelope (`limits`)",
     +[](C& c, R& out) {
       if (c.cx.stream == nullptr) return out.fail(CmdError::unsupported, "streaming targets are not available here");
       const ArgValue* p = c.rq.arg("position");
       const ArgValue* r = c.rq.arg("rpy");
       if (p->list.size() != 3) return out.fail(CmdError::arg_count, "position: expected [x, y, z]");
       if (r->list.size() != 3) return out.fail(CmdError::arg_count, "rpy: expected [roll, pitch, yaw]");
       const ArgValue* f = c.rq.arg("frame");
       const bool user = f != nullptr && f->present && f->text == "user";
       if (f != nullptr && f->present && !user && f->text != "base")
         return out.fail(CmdError::bad_option, "frame: `base` or `user`, not `" + f->text + "`");
       kin::Pose pose = kin::Pose::Identity();
       pose.linear() = kin::rotation_from_rpy(r->list[0], r->list[1], r->list[2]);
       pose.translation() = Eigen::Vector3d(p->list[0], p->list[1], p->list[2]);
       const fw::StreamResult res = c.cx.stream->target_pose(pose, user, num_or(c, "start", 0) != 0, time_of(c));
       if (!res.ok()) return out.fail(res.error, res.reason);
       if (res.stale) out.j["stale"] = true;
       out.j["stream"] = stream_json(res.stats);
     }},
    {"program_save", kProgramSave, Gate::control, Where::service, "prog::load_program",
     "saves a program into the programs folder (programs.dir) as `name`.arm, or `name`.gcode for G-code, replacing "
     "one of that name; the text must load first (as `program_check` reads it: an error answers with its `line`, "
     "nothing written); written whole (a temporary file renamed)",
     +[](C& c, R& out) {
       if (c.cx.programs_dir.empty()) return out.fail(CmdError::storage, "no programs folder (programs.dir)");
       prog::Program p;
       std::string name;
       if (!load_api_program(c, p, name, out)) return;
       const bool gcode = num_or(c, "gcode", 0) != 0;
       std::string file = name;
       const bool has_arm = file.size() > 4 && file.compare(file.size() - 4, 4, ".arm") == 0;
       if (gcode ? !prog::is_gcode_file(file) : !has_arm) file += gcode ? ".gcode" : ".arm";
       const std::string path = c.cx.programs_dir + "/" + file, tmp = path + ".saving";
       {
         std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
         f << c.rq.arg("text")->text;
         f.flush();
         if (!f) {
           ::unlink(tmp.c_str());
           return out.fail(CmdError::storage, "cannot write " + tmp);
         }
       }
       if (::rename(tmp.c_str(), path.c_str()) != 0) {
         const std::string why = std::strerror(errno);
         ::unlink(tmp.c_str());
         return out.fail(CmdError::storage, "cannot save " + path + ": " + why);
       }
       out.j["file"] = file;
     }},
    {"program_check", kProgram, Gate::observer, Where::service, "ArmService::check_program",
     "checks a whole program without running it (the service's dry run: the planning and checks of a real run, from "
     "where the motion queue ends): ok with its step counts, planned time and `planned_steps` (fewer than `steps`: "
     "the moves after a tool or frame definition, which a check does not make, are planned when they run), or the "
     "first error with its `file`, `line`, `step`, the error code and one line",
     +[](C& c, R& out) {
       prog::Program p;
       std::string name;
       if (!load_api_program(c, p, name, out)) return;
       const fw::ProgramCheckResult r = c.cx.svc->check_program(p, c.cx.units);
       if (!r.ok()) return check_refusal(r, out);
       counts_result(r, out);
     }},
    {"program_run", kProgram, Gate::control, Where::service, "ArmService::check_program, ArmService::run_program",
     "checks the whole program as `program_check` does, then runs it (nothing moves when the check refuses a line); "
     "its place is in the state stream (`program`), its steps in the event stream",
     +[](C& c, R& out) {
       prog::Program p;
       std::string name;
       if (!load_api_program(c, p, name, out)) return;
       const fw::ProgramCheckResult r = c.cx.svc->check_program(p, c.cx.units);
       if (!r.ok()) return check_refusal(r, out);
       const fw::ProgramResult pr = c.cx.svc->run_program(name, std::move(p), c.cx.units);
       if (!pr.ok()) return program_refusal(pr, out);
       counts_result(r, out);
       out.j["program"] = program_json(pr.status);
     }},
    {"program_pause", none(), Gate::stop, Where::service, "ArmService::program_pause",
     "the running program pauses once its queued motions are done (`resume` runs it on)",
     +[](C& c, R& out) { program_answer(c.cx.svc->program_pause(), out); }},
    {"program_step", none(), Gate::control, Where::service, "ArmService::program_step",
     "a paused program runs its next motion, then pauses again",
     +[](C& c, R& out) { program_answer(c.cx.svc->program_step(), out); }},
    {"program_abort", none(), Gate::stop, Where::service, "ArmService::program_abort",
     "ends the running program now and stops the arm",
     +[](C& c, R& out) { program_answer(c.cx.svc->program_abort(), out); }},
    {"points", none(), Gate::observer, Where::service, "ArmService::points", "the teach points: name, joints, tool pose, tool and frame",
     +[](C& c, R& out) {
       json a = json::array();
       for (const prog::TeachPoint& t : c.cx.svc->points().points) a.push_back(point_json(t));
       out.j["points"] = std::move(a);
     }},
    {"teach", kPointName, Gate::control, Where::service, "ArmService::teach",
     "stores where the arm is as teach point `name` (replacing one of that name), kept in the points file",
     +[](C& c, R& out) {
       fw::TeachRequest rq;
       rq.name = c.rq.arg("name")->text;
       point_answer(c.cx.svc->teach(rq), out);
     }},
    {"point_delete", kPointName, Gate::control, Where::service, "ArmService::delete_point", "deletes teach point `name`",
     +[](C& c, R& out) { point_answer(c.cx.svc->delete_point(c.rq.arg("name")->text), out); }},
    {"point_go", kPointGo, Gate::control, Where::service, "ArmService::move_to_point",
     "moves to teach point `name` (a joint move to its joints, or a line with the active tool), queued",
     +[](C& c, R& out) {
       fw::PointMove pm;
       pm.name = c.rq.arg("name")->text;
       pm.line = num_or(c, "line", 0) != 0;
       pm.speed = num_or(c, "speed", -1);
       const fw::MoveContext m = move_cx(c);
       const fw::PointResult r = c.cx.svc->move_to_point(pm, m);
       if (r.refusal != fw::PointRefusal::none) return point_answer(r, out);
       move_result(r.move, out);
     }},
    {"tools", none(), Gate::observer, Where::service, "ArmService::tool / frame",
     "the tools and user frames (name, pose in the flange / base frame) and which are active",
     +[](C& c, R& out) {
       const fw::ArmService& s = *c.cx.svc;
       json t = json::array(), f = json::array();
       for (std::size_t i = 0; i < s.tool_count(); ++i) t.push_back(named_pose_json(s.tool(i)));
       for (std::size_t i = 0; i < s.frame_count(); ++i) f.push_back(named_pose_json(s.frame(i)));
       out.j["tools"] = std::move(t);
       out.j["frames"] = std::move(f);
       out.j["tool"] = s.tool(s.active_tool()).name;
       out.j["frame"] = s.frame(s.active_frame()).name;
     }},
    {"planned_path", kMotion, Gate::observer, Where::service, "ArmService::planned_path",
     "the tool path a move was planned with, for drawing it: `points`, the tool point of the move's `tool` in the base "
     "frame (m) at instants evenly spaced along its plan from its start to its goal, with its `kind` and `duration`; "
     "kept for the last 64 moves (not dwells)",
     +[](C& c, R& out) {
       const ArgValue* m = c.rq.arg("motion");
       const std::uint32_t id = m->present ? static_cast<std::uint32_t>(m->num)
                                           : (c.cx.ctl != nullptr ? c.cx.ctl->telemetry().running_id : 0u);
       if (id == 0) return out.fail(CmdError::bad_state, "no motion runs");
       const fw::ArmService::PlannedPath* p = c.cx.svc->planned_path(id);
       if (p == nullptr) return out.fail(CmdError::out_of_range, "motion " + std::to_string(id) + ": no planned path kept (a dwell, or not among the last 64 moves)");
       json pts = json::array();
       for (const Eigen::Vector3d& x : p->points) pts.push_back({x.x(), x.y(), x.z()});
       out.j["motion"] = p->id;
       out.j["kind"] = fw::to_string(p->kind);
       out.j["tool"] = p->tool;
       out.j["duration"] = p->duration;
       out.j["points"] = std::move(pts);
     }},
    {"tool_select", kFrameName, Gate::control, Where::service, "ArmService::select_tool",
     "makes tool `name` the active one (only while nothing moves or is queued)",
     +[](C& c, R& out) { frame_answer(c.cx.svc->select_tool(c.rq.arg("name")->text), "tool", out); }},
    {"frame_select", kFrameName, Gate::control, Where::service, "ArmService::select_frame",
     "makes user frame `name` the active one (only while nothing moves or is queued)",
     +[](C& c, R& out) { frame_answer(c.cx.svc->select_frame(c.rq.arg("name")->text), "frame", out); }},
    {"tool_define", kToolDefine, Gate::control, Where::service, "ArmService::define_tool",
     "defines tool `name` (or replaces the one of that name) by its pose in the flange frame and its payload, kept in "
     "the frames file (only while nothing moves or is queued)",
     +[](C& c, R& out) {
       fw::NamedPose d;
       if (named_pose_of(c, d, out)) frame_answer(c.cx.svc->define_tool(d), "tool", out);
     }},
    {"tool_delete", kFrameName, Gate::control, Where::service, "ArmService::delete_tool",
     "deletes tool `name` (not the active one; only while nothing moves or is queued)",
     +[](C& c, R& out) { frame_answer(c.cx.svc->delete_tool(c.rq.arg("name")->text), "tool", out); }},
    {"frame_define", kFrameDefine, Gate::control, Where::service, "ArmService::define_frame",
     "defines user frame `name` (or replaces the one of that name) by its pose in the base frame, kept in the frames "
     "file (only while nothing moves or is queued)",
     +[](C& c, R& out) {
       fw::NamedPose d;
       if (named_pose_of(c, d, out)) frame_answer(c.cx.svc->define_frame(d), "frame", out);
     }},
    {"frame_delete", kFrameName, Gate::control, Where::service, "ArmService::delete_frame",
     "deletes user frame `name` (not the active one; only while nothing moves or is queued)",
     +[](C& c, R& out) { frame_answer(c.cx.svc->delete_frame(c.rq.arg("name")->text), "frame", out); }},
    {"jog_cartesian", kJogCartesian, Gate::control, Where::service, "ArmService::jog(ToolJog)",
     "jogs the active tool along or about an axis of the base, tool or user frame, by an increment or continuously "
     "(stops unless repeated within the deadman time)",
     +[](C& c, R& out) {
       fw::ToolJog j;
       j.axis = static_cast<int>(num_or(c, "axis", 0));
       const ArgValue* fr = c.rq.arg("frame");
       if (!fr->present || fr->text == "base") j.frame = fw::JogFrame::base;
       else if (fr->text == "tool") j.frame = fw::JogFrame::tool;
       else if (fr->text == "user") j.frame = fw::JogFrame::user;
       else return out.fail(CmdError::bad_option, "frame: base, tool or user");
       const ArgValue* inc = c.rq.arg("increment");
       const ArgValue* dir = c.rq.arg("direction");
       if (inc->present == dir->present) return out.fail(CmdError::arg_count, "give one of increment and direction");
       j.continuous = dir->present;
       j.direction = dir->num < 0 ? -1 : 1;
       if (j.continuous && dir->num == 0) return out.fail(CmdError::out_of_range, "direction: +1 or -1");
       j.increment = inc->num;
       j.speed_pct = num_or(c, "speed_pct", -1);
       fw::ArmService& s = *c.cx.svc;
       fw::JogContext jx;
       jx.chain = &s.tool_chain(s.active_tool());
       jx.ik = s.tool_ik(s.active_tool());
       jx.user_axes = s.frame(s.active_frame()).pose.linear();
       jog_result(s.jog(j, jx), out);
     }},
    {"feed_override", kFeed, Gate::control, Where::service, "ArmService::set_feed_override",
     "sets the feed override (percent; in the state stream as `feed_pct`)",
     +[](C& c, R& out) {
       const fw::SettingsResult r = c.cx.svc->set_feed_override(static_cast<int>(num_or(c, "pct", 100)));
       if (!r.ok()) return out.fail(r.error, "pct: outside [" + std::to_string(fw::kMinFeedOverride) + ", " + std::to_string(fw::kMaxFeedOverride) + "]");
       out.j["feed_pct"] = c.cx.svc->feed_override();
     }},
};

bool is_loopish(double v) { return std::isfinite(v); }

}  // namespace

std::span<const MessageSpec> messages() { return kMessages; }

const MessageSpec* find_message(std::string_view name) {
  for (const MessageSpec& m : kMessages)
    if (name == m.name) return &m;
  return nullptr;
}

const ArgValue* ApiRequest::arg(std::string_view name) const {
  if (spec == nullptr) return nullptr;
  for (std::size_t i = 0; i < spec->args.size() && i < args.size(); ++i)
    if (name == spec->args[i].name) return &args[i];
  return nullptr;
}

ParseError parse_request(std::string_view text, ApiRequest& out) {
  out = ApiRequest{};
  const json j = json::parse(text.begin(), text.end(), nullptr, false);
  if (j.is_discarded()) return {to_string(ApiError::bad_json), "not JSON (NaN and Infinity are not JSON either)"};
  if (!j.is_object()) return {to_string(ApiError::bad_json), "a message is a JSON object"};
  if (const auto id = j.find("id"); id != j.end()) {
    if (!id->is_number_integer()) return {to_string(CmdError::bad_number), "id: expected an integer"};
    out.id = id->get<std::int64_t>();
    out.has_id = true;
  }
  const auto cmd = j.find("cmd");
  if (cmd == j.end() || !cmd->is_string()) return {to_string(CmdError::arg_count), "cmd: expected the command's name"};
  const std::string name = cmd->get<std::string>();
  out.spec = find_message(name);
  if (out.spec == nullptr) {
    std::string shown = name.substr(0, 40);
    for (char& ch : shown)
      if (static_cast<unsigned char>(ch) < 0x20 || static_cast<unsigned char>(ch) >= 0x7f) ch = '?';
    return {to_string(CmdError::unknown_command), "cmd: no command '" + shown + "'"};
  }
  const auto& args = out.spec->args;
  out.args.resize(args.size());
  for (auto it = j.begin(); it != j.end(); ++it) {
    if (it.key() == "id" || it.key() == "cmd") continue;
    bool known = false;
    for (const ArgSpec& a : args) known = known || it.key() == a.name;
    if (!known) {
      std::string k = it.key().substr(0, 40);
      for (char& ch : k)
        if (static_cast<unsigned char>(ch) < 0x20 || static_cast<unsigned char>(ch) >= 0x7f) ch = '?';
      return {to_string(CmdError::bad_option), name + ": no argument '" + k + "'"};
    }
  }
  for (std::size_t i = 0; i < args.size(); ++i) {
    const ArgSpec& a = args[i];
    ArgValue& v = out.args[i];
    const auto f = j.find(a.name);
    if (f == j.end()) {
      if (a.required) return {to_string(CmdError::arg_count), std::string(a.name) + ": missing"};
      continue;
    }
    v.present = true;
    const std::string at = std::string(a.name) + ": ";
    auto number = [&](const json& e, double& d, bool integer) -> ParseError {
      if (!e.is_number() || (integer && !e.is_number_integer()))
        return {to_string(CmdError::bad_number), at + "expected " + (integer ? "an integer" : "a number")};
      d = e.get<double>();
      if (!is_loopish(d)) return {to_string(CmdError::not_finite), at + "not finite"};
      if (d < a.lo || d > a.hi) {
        char b[120];
        std::snprintf(b, sizeof b, "%.9g is outside [%.9g, %.9g]", d, a.lo, a.hi);
        return {to_string(CmdError::out_of_range), at + b};
      }
      return {};
    };
    switch (a.type) {
      case ArgType::number:
      case ArgType::integer: {
        ParseError e = number(*f, v.num, a.type == ArgType::integer);
        if (!e.code.empty()) return e;
        break;
      }
      case ArgType::boolean:
        if (!f->is_boolean()) return {to_string(CmdError::bad_option), at + "expected true or false"};
        v.num = f->get<bool>() ? 1 : 0;
        break;
      case ArgType::text:
        if (!f->is_string()) return {to_string(CmdError::bad_option), at + "expected a string"};
        v.text = f->get<std::string>();
        if (v.text.size() < a.lo || v.text.size() > a.hi)
          return {to_string(CmdError::out_of_range), at + "length outside " + std::to_string(int(a.lo)) + ".." +
                                                         std::to_string(int(a.hi))};
        break;
      case ArgType::numbers:
        if (!f->is_array() || f->size() > kin::kMaxJoints)
          return {to_string(CmdError::bad_number), at + "expected an array of at most " + std::to_string(kin::kMaxJoints) + " numbers"};
        v.list.resize(f->size());
        for (std::size_t k = 0; k < f->size(); ++k) {
          ParseError e = number((*f)[k], v.list[k], false);
          if (!e.code.empty()) return e;
        }
        break;
    }
  }
  return {};
}

std::string ok_line(const ApiRequest& rq, std::string_view fields_json) {
  json j = json::object();
  if (rq.has_id) j["id"] = rq.id;
  j["ok"] = true;
  std::string s = j.dump();
  if (fields_json.size() > 2) {  // "{...}": merge its members
    s.pop_back();
    s += ',';
    s.append(fields_json.substr(1));
  }
  return s;
}

std::string error_line(bool has_id, std::int64_t id, std::string_view code, std::string_view message) {
  json j = json::object();
  if (has_id) j["id"] = id;
  j["error"] = code;
  j["message"] = message;
  return j.dump(-1, ' ', false, json::error_handler_t::replace);
}

std::string execute(ServiceContext& cx, const ApiRequest& rq) {
  if (rq.spec == nullptr || rq.spec->handler == nullptr)
    return error_line(rq.has_id, rq.id, fw::to_string(CmdError::internal), "not a service message");
  ServiceCall call{cx, rq};
  ResultFields out;
  rq.spec->handler(call, out);
  if (!out.error.empty()) {  // with the fields the refusal filled (a program's line)
    std::string e = error_line(rq.has_id, rq.id, out.error, out.message);
    if (!out.j.empty()) {
      e.pop_back();
      e += ',' + out.j.dump(-1, ' ', false, json::error_handler_t::replace).substr(1);
    }
    return e;
  }
  return ok_line(rq, out.j.dump(-1, ' ', false, json::error_handler_t::replace));
}

std::string hello_line(const ApiRequest& rq, const HelloInfo& h, const kin::Chain& chain, const kin::JointLimits& lim) {
  json f = json::object();
  f["protocol"] = kProtocolVersion;
  f["robot"] = h.robot;
  f["rate_hz"] = h.rate_hz;
  f["units"] = {{"length", "m"}, {"angle", "rad"}, {"time", "s"}};
  json joints = json::array();
  for (int j = 0; j < chain.n_joints; ++j) {
    const kin::DhRow& r = chain.joint(j);
    const auto u = static_cast<std::size_t>(j);
    json o = {{"type", kin::to_string(r.type)},
              {"max_velocity", lim.dyn[u].max_velocity},
              {"max_acceleration", lim.dyn[u].max_acceleration},
              {"max_jerk", lim.dyn[u].max_jerk}};
    // an unbounded joint has no limit to say (JSON has no infinity)
    o["lower"] = std::isfinite(lim.lower[u]) ? json(lim.lower[u]) : json(nullptr);
    o["upper"] = std::isfinite(lim.upper[u]) ? json(lim.upper[u]) : json(nullptr);
    joints.push_back(std::move(o));
  }
  f["joints"] = std::move(joints);
  f["role"] = h.role;
  f["client"] = h.client;
  f["controller"] = h.controller;
  char crc[9];
  std::snprintf(crc, sizeof crc, "%08X", static_cast<unsigned>(h.safety_checksum));
  f["safety"] = {{"enabled", h.safety_on}, {"checksum", crc}};
  return ok_line(rq, f.dump(-1, ' ', false, json::error_handler_t::replace));
}

std::string state_line(const fw::Telemetry& t, double rate_hz, const kin::Chain& chain, std::uint64_t dropped,
                       const ServiceSnapshot* svc) {
  json j = json::object();
  j["topic"] = "state";
  j["cycle"] = t.cycles;
  j["t"] = rate_hz > 0 ? static_cast<double>(t.cycles) / rate_hz : 0.0;
  j["state"] = fw::to_string(t.state);
  j["mode"] = fw::to_string(t.mode);
  j["holding"] = t.holding;
  j["safety_mode"] = kin::to_string(static_cast<kin::SafetyMode>(t.safety_mode));
  j["safety_stops"] = t.safety_stops;
  j["speed_scale"] = t.speed_scale;
  j["safety_inputs"] = {{"estop", (t.safety_inputs & 1u) != 0},
                        {"estop_lost", (t.safety_inputs & 2u) != 0},
                        {"reduced", (t.safety_inputs & 4u) != 0},
                        {"reduced_lost", (t.safety_inputs & 8u) != 0}};
  json q = json::array(), qc = json::array(), fe = json::array();
  kin::JointVector qa(chain.n_joints);
  for (int i = 0; i < t.n && i < chain.n_joints; ++i) {
    const auto u = static_cast<std::size_t>(i);
    q.push_back(t.q_act[u]);
    qc.push_back(t.q_cmd[u]);
    fe.push_back(t.q_cmd[u] - t.q_act[u]);
    qa[i] = t.q_act[u];
  }
  json qd = json::array(), qdm = json::array(), tau = json::array(), temp = json::array();
  for (int i = 0; i < t.n && i < chain.n_joints; ++i) {
    const auto u = static_cast<std::size_t>(i);
    qd.push_back(t.qd_cmd[u]);
    qdm.push_back(t.qd_act[u]);
    // a drive that does not report its torque or temperature: null (not a measured 0)
    tau.push_back((t.torque_valid >> i) & 1u ? json(t.tau_act[u]) : json(nullptr));
    temp.push_back((t.temperature_valid >> i) & 1u ? json(t.temperature[u]) : json(nullptr));
  }
  j["temperature"] = std::move(temp);
  j["temperature_warning"] = t.temperature_warning;
  j["q"] = std::move(q);
  j["qd"] = std::move(qdm);
  j["torque"] = std::move(tau);
  j["q_cmd"] = std::move(qc);
  j["qd_cmd"] = std::move(qd);
  j["streaming"] = t.streaming;
  if (svc != nullptr) j["stream"] = stream_json(svc->stream);
  j["following_error"] = std::move(fe);
  kin::Pose p = kin::Pose::Identity();
  kin::FrameSet fs;
  if (t.n == chain.n_joints && kin::forward_frames(chain, qa, fs, p) == kin::Status::ok) {
    const Eigen::Vector3d rpy = kin::rpy_from_rotation(p.linear());
    j["tool"] = {{"position", {p.translation().x(), p.translation().y(), p.translation().z()}},
                 {"rpy", {rpy.x(), rpy.y(), rpy.z()}}};
    // the origins of the base frame, of the frame after each DH row and of the tool: what a
    // viewer draws the links between (the pendant computes no kinematics of its own)
    json fr = json::array();
    for (int i = 0; i < fs.count; ++i) {
      const Eigen::Vector3d o = fs.frame[i].translation();
      fr.push_back({o.x(), o.y(), o.z()});
    }
    fr.push_back({p.translation().x(), p.translation().y(), p.translation().z()});
    j["frames"] = std::move(fr);
    if (svc != nullptr) {  // the active tool's point and orientation (tool0: the same as `tool`)
      const kin::Pose x = p * svc->tool_pose;
      const Eigen::Vector3d r = kin::rpy_from_rotation(x.linear());
      j["tcp"] = {{"position", {x.translation().x(), x.translation().y(), x.translation().z()}}, {"rpy", {r.x(), r.y(), r.z()}}};
    }
  }
  j["queued"] = t.queued;
  j["running"] = t.running_id;
  j["done"] = t.done_id;
  j["homed"] = t.homed;
  j["homing"] = t.homing_now;
  j["fault"] = {{"cause", fw::to_string(t.cause)}, {"joint", t.fault_joint}, {"text", std::string(t.fault_text)}};
  j["freedrive"] = t.freedrive != 0;
  j["collision_detection"] = t.collision_on;
  j["dropped"] = dropped;
  if (svc != nullptr) {
    j["program"] = program_json(svc->program);
    j["feed_pct"] = svc->feed_pct;
    j["active_tool"] = svc->tool;
    j["active_frame"] = svc->frame;
    json outs = json::array();
    for (const auto& [name, on] : svc->outputs) outs.push_back({{"name", name}, {"on", on}});
    j["outputs"] = std::move(outs);
  }
  return j.dump(-1, ' ', false, json::error_handler_t::replace);
}

std::string event_line(const fw::ArmEvent& e, std::string_view detail, std::uint64_t missed) {
  json j = json::object();
  j["topic"] = "event";
  j["seq"] = e.seq;
  j["cycle"] = e.cycle;
  j["t"] = e.t;
  j["kind"] = fw::to_string(e.kind);
  j["state"] = fw::to_string(e.state);
  if (e.kind == fw::ArmEventKind::fault) j["cause"] = fw::to_string(e.cause);
  j["joint"] = e.joint;
  j["motion"] = e.motion_id;
  j["detail"] = std::string(detail);
  j["missed"] = missed;
  return j.dump(-1, ' ', false, json::error_handler_t::replace);
}

std::string control_line(std::uint64_t holder) {
  json j = {{"topic", "control"}, {"holder", holder}};
  return j.dump();
}

namespace {
constexpr const char* kBegin = "<!-- BEGIN api-reference (generated by armfw --api-reference; do not edit) -->";
constexpr const char* kEnd = "<!-- END api-reference -->";

std::string range_text(const ArgSpec& a) {
  char b[96];
  switch (a.type) {
    case ArgType::boolean: return "true / false";
    case ArgType::text: std::snprintf(b, sizeof b, "%g..%g chars", a.lo, a.hi); return b;
    case ArgType::number:
    case ArgType::integer:
    case ArgType::numbers: std::snprintf(b, sizeof b, "[%g, %g]", a.lo, a.hi); return b;
  }
  return "";
}
}  // namespace

std::string api_reference_markdown() {
  std::string o = std::string(kBegin) + "\n\n";
  o += "Protocol version " + std::to_string(kProtocolVersion) + ".\n\n";
  o += "| message | who may send it | runs | calls | what it does |\n| --- | --- | --- | --- | --- |\n";
  for (const MessageSpec& m : kMessages)
    o += std::string("| `") + m.name + "` | " + to_string(m.gate) + " | " +
         (m.where == Where::session ? "network thread" : "service thread") + " | `" + fw::md_cell(m.call) + "` | " +
         fw::md_cell(m.doc) + " |\n";
  o += "\n### Arguments\n\n| message | argument | type | required | range | meaning |\n| --- | --- | --- | --- | --- | --- |\n";
  for (const MessageSpec& m : kMessages)
    for (const ArgSpec& a : m.args)
      o += std::string("| `") + m.name + "` | `" + a.name + "` | " + to_string(a.type) + " | " + (a.required ? "yes" : "no") +
           " | " + range_text(a) + " | " + fw::md_cell(a.doc) + " |\n";
  o += "\n### Error codes\n\nThe service calls answer with the console's codes (`CmdError`):";
  for (int e = 1; e <= static_cast<int>(CmdError::internal); ++e) o += std::string(" `") + fw::to_string(static_cast<CmdError>(e)) + "`";
  o += ". The API adds:\n\n| code | meaning |\n| --- | --- |\n";
  const char* api_doc[] = {"the message is not a JSON object (NaN and Infinity are not JSON)",
                           "no `hello` with a valid token yet (the server has a token file)",
                           "the client's role may not send it (an observer's command)",
                           "the command moves or changes the arm: `take_control` first",
                           "another client holds control (the message names it)",
                           "more than api.max_rate_hz messages per second: this one did not run"};
  for (int e = 0; e <= static_cast<int>(ApiError::rate_limited); ++e)
    o += std::string("| `") + to_string(static_cast<ApiError>(e)) + "` | " + api_doc[e] + " |\n";
  o += std::string("\n") + kEnd + "\n";
  return o;
}

std::string api_reference_mismatch(const std::string& page) {
  return fw::generated_section_mismatch(page, api_reference_markdown(),
                                        {"<!-- BEGIN api-reference", kEnd, "docs/api.md differs from armfw --api-reference",
                                         "regenerate the section: armfw --api-reference, pasted between the markers of docs/api.md"});
}

}  // namespace servoarm::api
