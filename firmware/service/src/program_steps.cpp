// SPDX-License-Identifier: Apache-2.0
// The arm service's own program steps (arm_service.hpp): a loaded program's typed steps
// (program/program.hpp: the parser made each line a fw::Command once) turned into the
// service's requests in SI with their parameters (blend, whether the next motion is a line,
// a teach point's joints) and run by the program runner. No console and no text in between:
// a refused step ends the program with its typed CmdError. Console thread.
#include <cmath>
#include <memory>
#include <utility>

#include "servoarm/kinematics/orientation.hpp"
#include "servoarm/service/arm_service.hpp"

namespace servoarm::fw {

using prog::kind_of;
using prog::StepKind;

namespace {

StepOutcome outcome(CmdError e, std::string reason) {
  StepOutcome o;
  o.error = e;
  o.reason = std::move(reason);
  return o;
}

kin::Pose fk_or_nan(const kin::Chain& ch, const kin::JointVector& q) {
  kin::Pose p = kin::Pose::Identity();
  if (kin::forward(ch, q, p) != kin::Status::ok) p.translation().setConstant(std::nan(""));
  return p;
}

}  // namespace

ProgramSpec ArmService::spec_of(const std::string& name, const prog::Program& p) {
  ProgramSpec sp;
  sp.name = name;
  sp.files = p.files;
  sp.steps.reserve(p.steps.size());
  for (const prog::ProgramStep& st : p.steps) {
    ProgramSpec::Step x;
    x.file = st.file;
    x.line = st.line;
    switch (kind_of(st.cmd)) {
      case StepKind::motion: x.kind = StepClass::motion; break;
      case StepKind::needs_idle: x.kind = StepClass::needs_idle; break;
      case StepKind::wait: x.kind = StepClass::wait; break;
      case StepKind::other:
      case StepKind::refused: x.kind = StepClass::other; break;  // (a refused step is refused when it is run)
    }
    sp.steps.push_back(x);
  }
  return sp;
}

ProgramResult ArmService::run_program(const std::string& name, prog::Program p, const ConsoleUnits& units) {
  auto shared = std::make_shared<const prog::Program>(std::move(p));
  ProgramSpec spec = spec_of(name, *shared);
  return run_program(std::move(spec), [this, shared, units](std::size_t i) { return run_step(*shared, i, units); });
}

// The step's move: its goal or target in SI, its blend tolerance (none given: the default).
MoveResult ArmService::step_move(const prog::Program&, const prog::ProgramStep& st, const ConsoleUnits& u, const MoveContext& cx) {
  const fw::Command& c = st.cmd;
  const kin::JointVector* point = st.point >= 0 && static_cast<std::size_t>(st.point) < points_.points.size()
                                      ? &points_.points[static_cast<std::size_t>(st.point)].q
                                      : nullptr;
  const kin::Chain& ch = *cx.chain;
  if (c.cmd == Cmd::dwell) {  // a dwell carries no blend: it is an exact stop
    MoveContext plain = cx;
    plain.step_blend = -1;
    plain.next_line = false;
    return dwell(c.vals[0], plain);
  }
  if (c.cmd == Cmd::movej || c.cmd == Cmd::park) {
    MoveJoints m = park_request();
    if (c.cmd == Cmd::movej) {
      m.goal = kin::JointVector(n_);
      for (int j = 0; j < n_; ++j) m.goal[j] = u.joint_in(chain_, j, c.vals[static_cast<std::size_t>(j)]);
      if (point != nullptr) m.goal = *point;  // exactly as taught (SI)
      m.speed_pct = c.has_speed ? c.speed : cfg_.default_joint_speed_pct;
      m.blend = c.has_blend ? u.angle_in(c.blend) : -1.0;
    }
    return move(m, cx);
  }
  MoveLine m;
  const kin::Pose F = frames_[frame_].pose;  // the active user frame
  if (c.cmd == Cmd::movel) {
    if (point != nullptr) {
      m.target = fk_or_nan(ch, *point);  // where the point's joints put the tool, on a straight line
    } else {
      kin::Pose at = F.inverse() * fk_or_nan(ch, cx.dry != nullptr ? cx.dry->tail : tail());
      at.translation() = Eigen::Vector3d(u.length_in(c.vals[0]), u.length_in(c.vals[1]), u.length_in(c.vals[2]));
      if (c.count == 6) at.linear() = kin::rotation_from_rpy(u.angle_in(c.vals[3]), u.angle_in(c.vals[4]), u.angle_in(c.vals[5]));
      m.target = F * at;
      m.blend = c.has_blend ? u.length_in(c.blend) : -1.0;
    }
    m.speed = c.has_speed ? u.length_in(c.speed) : 0.0;
    return move(m, cx);
  }
  // G0 / G1: the axes given replace (G90) or move (G91) the queue's end pose, in G-code's units.
  const ConsoleUnits& g = kGcodeUnits;
  const kin::Pose G = c.g53 ? kin::Pose::Identity() : F;
  const kin::Pose cur = G.inverse() * fk_or_nan(ch, cx.dry != nullptr ? cx.dry->tail : tail());
  m.target = cur;
  Eigen::Vector3d rpy = kin::rpy_from_rotation(cur.linear());
  for (int k = 0; k < 6; ++k) {
    if (!(c.axis_mask & (1u << k))) continue;
    const double v = c.vals[static_cast<std::size_t>(k)];
    if (k < 3) m.target.translation()[k] = g.length_in(c.relative ? g.length_out(cur.translation()[k]) + v : v);
    else rpy[k - 3] = c.relative ? rpy[k - 3] + g.angle_in(v) : g.angle_in(v);
  }
  if (c.axis_mask & 0x38) m.target.linear() = kin::rotation_from_rpy(rpy[0], rpy[1], rpy[2]);
  m.target = G * m.target;
  m.rapid = c.rapid;
  m.speed = c.has_speed ? g.length_in(c.speed) : 0.0;
  m.clamp_speed = true;
  return move(m, cx);
}

// A tool or frame step: select, define, delete (the program's units), G10 L2 / L20 (mm, deg).
FrameResult ArmService::step_frame(const fw::Command& c, const ConsoleUnits& u) {
  const bool tool = c.cmd == Cmd::tool;
  std::string name(c.name.data());
  FrameResult r;
  if (c.frame_op == FrameOp::set_axes && c.g10_p == 0) {
    if (frame_ == 0) {
      r.error = CmdError::bad_state;
      r.reason = "G10 L2 P0: the active frame is base, which cannot be set (select G54..G59 first)";
      return r;
    }
    name = frames_[frame_].name;
  } else if (c.frame_op == FrameOp::set_axes) {
    name = "g5" + std::to_string(3 + c.g10_p);
  }
  const bool g5x = name.size() == 3 && name[0] == 'g' && name[1] == '5' && name[2] >= '4' && name[2] <= '9';
  switch (c.frame_op) {
    case FrameOp::list: return r;  // a query
    case FrameOp::select: return tool ? select_tool(name) : select_frame(name, g5x);
    case FrameOp::remove: return tool ? delete_tool(name) : delete_frame(name);
    case FrameOp::define:
    case FrameOp::set_axes: break;
  }
  NamedPose def;
  def.name = name;
  const std::size_t at = find_frame(name);
  const kin::Pose cur = !tool && at < frames_.size() ? frames_[at].pose : kin::Pose::Identity();
  Eigen::Vector3d xyz, rpy = kin::rpy_from_rotation(cur.linear());
  if (c.frame_op == FrameOp::set_axes && c.g10_l20) {  // the axes given are where the tool point is now
    const Eigen::Vector3d p = fk_or_nan(tools_[tool_]->chain, tail()).translation();
    Eigen::Vector3d w = cur.linear().transpose() * (p - cur.translation());
    for (int k = 0; k < 3; ++k)
      if (c.axis_mask & (1u << k)) w[k] = c.vals[static_cast<std::size_t>(k)] * 1e-3;
    xyz = p - cur.linear() * w;
  } else if (c.frame_op == FrameOp::set_axes) {
    for (int k = 0; k < 3; ++k) {
      xyz[k] = c.axis_mask & (1u << k) ? kGcodeUnits.length_in(c.vals[static_cast<std::size_t>(k)]) : cur.translation()[k];
      if (c.axis_mask & (1u << (k + 3))) rpy[k] = kGcodeUnits.angle_in(c.vals[static_cast<std::size_t>(k + 3)]);
    }
  } else {
    for (int k = 0; k < 3; ++k) {
      xyz[k] = u.length_in(c.vals[static_cast<std::size_t>(k)]);
      rpy[k] = u.angle_in(c.vals[static_cast<std::size_t>(k + 3)]);
    }
  }
  def.pose = kin::Pose::Identity();
  def.pose.translation() = xyz;
  def.pose.linear() = kin::rotation_from_rpy(rpy[0], rpy[1], rpy[2]);
  if (tool && c.has_mass) {
    def.has_payload = true;
    def.mass = c.mass;
    def.com = Eigen::Vector3d(u.length_in(c.com[0]), u.length_in(c.com[1]), u.length_in(c.com[2]));
  }
  if (tool && c.has_radius) def.radius = u.length_in(c.radius);
  return tool ? define_tool(def) : define_frame(def);
}

StepOutcome ArmService::run_step(const prog::Program& p, std::size_t i, const ConsoleUnits& u) {
  if (i >= p.steps.size()) return {};
  const prog::ProgramStep& st = p.steps[i];
  const fw::Command& c = st.cmd;
  if (c.cmd == Cmd::out && c.out_index == -1) return {};  // the list: a query
  if (c.cmd == Cmd::out) {  // at once (M64 / M65, out: the arm at rest), or with the next move (M62 / M63)
    OutputRequest rq;
    rq.on = c.out_on;
    rq.sync = c.out_sync;
    rq.index = c.out_index >= 0 ? static_cast<std::size_t>(c.out_index) : cfg_.outputs.size();
    for (std::size_t k = 0; c.out_index == -2 && k < cfg_.outputs.size(); ++k)
      if (cfg_.outputs[k].name == c.word.data()) rq.index = k;
    const OutputResult r = set_output(rq);
    return r.ok() ? StepOutcome{} : outcome(r.error, to_string(r.refusal));
  }
  switch (kind_of(c)) {
    case StepKind::refused: return outcome(CmdError::program, std::string(to_string(c.cmd)) + " is not run inside a program");
    case StepKind::wait:
    case StepKind::other: return {};  // queries and modal-only lines: nothing to do here
    case StepKind::needs_idle:
    case StepKind::motion: break;
  }
  if (c.cmd == Cmd::tool || c.cmd == Cmd::frame) {
    const FrameResult r = step_frame(c, u);
    return r.ok() ? StepOutcome{} : outcome(r.error, r.reason.empty() ? std::string(to_string(r.refusal)) : r.reason);
  }
  const bool gcode = static_cast<std::size_t>(st.file) < p.files.size() && prog::is_gcode_file(p.files[static_cast<std::size_t>(st.file)]);
  MoveContext cx;
  cx.chain = &tools_[tool_]->chain;
  cx.ik = tool_ik(tool_);
  cx.outputs = pending_outputs();
  cx.step_blend = st.blend < 0 ? -1.0 : gcode ? st.blend * 1e-3 : c.cmd == Cmd::movej ? u.angle_in(st.blend) : u.length_in(st.blend);
  cx.next_line = prog::next_motion_is_line(p, i);
  const MoveResult r = step_move(p, st, u, cx);
  if (!r.ok()) return outcome(r.error, r.reason.empty() ? std::string(to_string(r.refusal)) : r.reason);
  clear_pending_outputs();
  return {};
}

}  // namespace servoarm::fw
