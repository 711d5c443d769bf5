// SPDX-License-Identifier: Apache-2.0
// The arm service's whole-program check (arm_service.hpp: check_program): every step of a
// loaded program through the service's dry run, as run_step() would run it (step_move with a
// DryRun: the same planning and checks, nothing queued), from where the motion queue ends.
// The first step refused ends the check with its place. A tool or frame definition, deletion
// or G10 is not made by a check (it would change the arm's tools and frames): the moves after it
// are not planned (they are when they run), the steps the runner refuses still are. Console
// thread.
#include <memory>
#include <string>

#include "servoarm/service/arm_service.hpp"

namespace servoarm::fw {

using prog::kind_of;
using prog::StepKind;

ProgramCheckResult ArmService::check_program(const prog::Program& p, const ConsoleUnits& u) {
  ProgramCheckResult res;
  res.counts = prog::count_steps(p);
  auto shadow = std::make_unique<PathShadow>();
  DryRun dry;
  dry.tail = tail();
  dry.shadow = shadow.get();
  // A frame selection changes how the later steps' coordinates are read (step_move reads the
  // active frame): followed here, and the active frame is put back however the check ends.
  struct Restore {
    std::size_t& at;
    std::size_t was;
    ~Restore() { at = was; }
  } restore{frame_, frame_};
  std::size_t tool = tool_;
  bool planning = true;  // false after a definition the check does not make
  res.planned = p.steps.size();
  for (std::size_t i = 0; i < p.steps.size(); ++i) {
    const prog::ProgramStep& st = p.steps[i];
    const fw::Command& c = st.cmd;
    const auto refuse = [&](CmdError e, std::string why) {
      res.error = e;
      res.step = i;
      res.line = st.line;
      res.file = st.file >= 0 && static_cast<std::size_t>(st.file) < p.files.size() ? p.files[static_cast<std::size_t>(st.file)] : "?";
      res.reason = std::move(why);
      return res;
    };
    if (c.cmd == Cmd::out) {
      if (c.out_index == -1) continue;  // the list: a query
      OutputRequest rq;
      rq.on = c.out_on;
      rq.sync = c.out_sync;
      rq.dry = true;
      rq.index = c.out_index >= 0 ? static_cast<std::size_t>(c.out_index) : cfg_.outputs.size();
      for (std::size_t k = 0; c.out_index == -2 && k < cfg_.outputs.size(); ++k)
        if (cfg_.outputs[k].name == c.word.data()) rq.index = k;
      const OutputResult r = set_output(rq);
      if (!r.ok()) return refuse(r.error, to_string(r.refusal));
      continue;
    }
    switch (kind_of(c)) {
      case StepKind::refused: return refuse(CmdError::program, std::string(to_string(c.cmd)) + " is not run inside a program");
      case StepKind::wait:
      case StepKind::other: continue;
      case StepKind::needs_idle:
      case StepKind::motion: break;
    }
    if (!planning) continue;
    if (c.cmd == Cmd::tool || c.cmd == Cmd::frame) {
      if (c.frame_op == FrameOp::list) continue;  // a query
      if (c.frame_op != FrameOp::select) {  // a definition: not made, so not followed
        planning = false;
        res.planned = i;
        continue;
      }
      const std::string name(c.name.data());
      if (c.cmd == Cmd::tool) {
        const std::size_t at = find_tool(name);
        if (at == tools_.size()) return refuse(CmdError::bad_option, "tool " + name + ": " + to_string(FrameRefusal::not_defined));
        tool = at;
      } else {
        const bool g5x = name.size() == 3 && name[0] == 'g' && name[1] == '5' && name[2] >= '4' && name[2] <= '9';
        const std::size_t at = find_frame(name);
        if (at == frames_.size() && !g5x) return refuse(CmdError::bad_option, "frame " + name + ": " + to_string(FrameRefusal::not_defined));
        frame_ = at == frames_.size() ? 0 : at;  // a G54..G59 frame not set yet: the identity, as base
      }
      continue;
    }
    const bool gcode = static_cast<std::size_t>(st.file) < p.files.size() && prog::is_gcode_file(p.files[static_cast<std::size_t>(st.file)]);
    MoveContext cx;
    cx.dry = &dry;
    cx.chain = &tools_[tool]->chain;
    cx.ik = tool_ik(tool);
    cx.step_blend = st.blend < 0 ? -1.0 : gcode ? st.blend * 1e-3 : c.cmd == Cmd::movej ? u.angle_in(st.blend) : u.length_in(st.blend);
    cx.next_line = prog::next_motion_is_line(p, i);
    const MoveResult r = step_move(p, st, u, cx);
    if (!r.ok()) {
      res.move = r;
      return refuse(r.error, r.reason.empty() ? std::string(to_string(r.refusal)) : r.reason);
    }
  }
  res.duration = dry.time;
  return res;
}

}  // namespace servoarm::fw
