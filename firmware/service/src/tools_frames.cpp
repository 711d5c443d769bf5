// SPDX-License-Identifier: Apache-2.0
// The arm service's tools and user frames (arm_service.hpp, frames.hpp): selected, defined
// and deleted by name, each change saved to the frames file before it is answered.
// Console thread.
#include <algorithm>
#include <utility>

#include "servoarm/kinematics/ik.hpp"
#include "servoarm/kinematics/orientation.hpp"
#include "servoarm/lang/ik_options.hpp"
#include "servoarm/service/arm_service.hpp"

namespace servoarm::fw {

const char* to_string(FrameRefusal r) {
  switch (r) {
    case FrameRefusal::none: return "none";
    case FrameRefusal::not_defined: return "not_defined";
    case FrameRefusal::bad_name: return "bad_name";
    case FrameRefusal::bad_values: return "bad_values";
    case FrameRefusal::arm_busy: return "arm_busy";
    case FrameRefusal::active: return "active";
    case FrameRefusal::full: return "full";
    case FrameRefusal::storage: return "storage";
  }
  return "?";
}

namespace {
FrameResult frame_refusal(FrameRefusal what, CmdError e, std::string reason = {}) {
  FrameResult r;
  r.refusal = what;
  r.error = e;
  r.reason = std::move(reason);
  return r;
}
}  // namespace

void ArmService::set_ik_model(const kin::IkModel* ik) {
  ik_ = ik;
  if (!tools_.empty()) tools_[0]->model = ik;
}

std::unique_ptr<ArmService::ToolSlot> ArmService::make_tool(const NamedPose& def) const {
  auto t = std::make_unique<ToolSlot>();
  t->def = def;
  t->chain = chain_;
  kin::set_tool(t->chain, chain_.tool * def.pose);
  // The tool's own IK model: the closed form of the arm still holds with any TCP (it is
  // a fixed transform after the last joint); without one, the numeric fallback.
  if (ik_ != nullptr) {
    t->own = std::make_unique<kin::IkModel>();
    if (kin::ik_prepare(t->chain, *t->own) == kin::Status::ok && t->own->method != kin::IkMethod::none) t->model = t->own.get();
    else t->own.reset();
  }
  return t;
}

// IK of a line's path check and of the control thread's Cartesian sampling with tool i: the
// model (closed form or numeric) when the chain has one, else the damped-Newton fallback.
kin::IkSolver ArmService::tool_ik(std::size_t i) const { return firmware_ik_solver(tools_[i]->model); }

std::size_t ArmService::find_tool(std::string_view name) const {
  for (std::size_t i = 0; i < tools_.size(); ++i)
    if (tools_[i]->def.name == name) return i;
  return tools_.size();
}

std::size_t ArmService::find_frame(std::string_view name) const {
  for (std::size_t i = 0; i < frames_.size(); ++i)
    if (frames_[i].name == name) return i;
  return frames_.size();
}

FrameResult ArmService::frames_check() const {
  FrameResult r;
  if (ctl_ == nullptr) return r;
  const Telemetry t = ctl_->telemetry();
  r.arm = t.state;
  r.queued = t.queued;
  switch (t.state) {
    case ArmState::moving:
    case ArmState::jogging:
    case ArmState::stopping:
    case ArmState::homing:
    case ArmState::freedrive: r.refusal = FrameRefusal::arm_busy; break;
    case ArmState::boot:
    case ArmState::disabled:
    case ArmState::enabling:
    case ArmState::idle:
    case ArmState::fault:
    case ArmState::estop: break;
  }
  if (r.refusal == FrameRefusal::none && (!ctl_->motions().empty() || t.queued > 0)) {
    r.refusal = FrameRefusal::arm_busy;
    // queued now but not taken by the control thread yet: the producer's count
    r.queued = std::max(r.queued, static_cast<std::uint32_t>(ctl_->motions().size()));
  }
  if (r.refusal != FrameRefusal::none) r.error = CmdError::bad_state;
  return r;
}

std::string ArmService::save_frames() const {
  if (frames_file_.empty()) return "";
  FramesData d;
  for (std::size_t i = 1; i < tools_.size(); ++i) d.tools.push_back(tools_[i]->def);
  for (std::size_t i = 1; i < frames_.size(); ++i) d.frames.push_back(frames_[i]);
  d.active_tool = tools_[tool_]->def.name;
  d.active_frame = frames_[frame_].name;
  return save_frames_file(frames_file_, d);
}

std::string ArmService::load_frames(const std::string& path) {
  frames_file_ = path;
  if (path.empty()) return "";
  FramesData d;
  const std::string err = load_frames_file(path, d);
  if (!err.empty()) return err;
  tools_.resize(1);
  frames_.resize(1);
  tool_ = frame_ = 0;
  for (const NamedPose& t : d.tools) {
    tools_.push_back(make_tool(t));
    if (std::string why = tool_envelope_problem(*tools_.back()); !why.empty()) {
      tools_.resize(1);
      tool_ = 0;
      return path + ": tool " + t.name + ": " + why;
    }
    if (t.name == d.active_tool) tool_ = tools_.size() - 1;
  }
  for (const NamedPose& f : d.frames) {
    frames_.push_back(f);
    if (f.name == d.active_frame) frame_ = frames_.size() - 1;
  }
  push_safety_tool();
  return "";
}

// A definition or deletion: the name must be one (tool0 / base are not) and the arm at rest.
FrameResult ArmService::named(bool tool, std::string_view name) const {
  if (std::string why = check_frame_name(name, tool); !why.empty())
    return frame_refusal(FrameRefusal::bad_name, CmdError::bad_option, std::move(why));
  return frames_check();
}

FrameResult ArmService::select_tool(std::string_view name) {
  const std::size_t at = find_tool(name);
  if (at == tools_.size()) return frame_refusal(FrameRefusal::not_defined, CmdError::bad_option);
  if (FrameResult busy = frames_check(); !busy.ok()) return busy;
  const std::size_t old = tool_;
  tool_ = at;
  if (std::string err = save_frames(); !err.empty()) {
    tool_ = old;
    return frame_refusal(FrameRefusal::storage, CmdError::storage, std::move(err));
  }
  push_safety_tool();
  FrameResult r;
  r.def = tools_[at]->def;
  r.active = true;
  return r;
}

FrameResult ArmService::define_tool(const NamedPose& def) {
  if (FrameResult no = named(true, def.name); !no.ok()) return no;
  const double xyz[3] = {def.pose.translation().x(), def.pose.translation().y(), def.pose.translation().z()};
  const Eigen::Vector3d r3 = kin::rpy_from_rotation(def.pose.linear());
  const double rpy[3] = {r3[0], r3[1], r3[2]};
  const double com[3] = {def.com.x(), def.com.y(), def.com.z()};
  if (std::string why = check_frame_values(xyz, rpy, def.has_payload, def.mass, com); !why.empty())
    return frame_refusal(FrameRefusal::bad_values, CmdError::out_of_range, std::move(why));
  const std::size_t at = find_tool(def.name);
  if (at == tools_.size() && tools_.size() >= kMaxTools) return frame_refusal(FrameRefusal::full, CmdError::busy);
  std::unique_ptr<ToolSlot> fresh = make_tool(def);
  if (std::string why = tool_envelope_problem(*fresh); !why.empty())
    return frame_refusal(FrameRefusal::bad_values, CmdError::limits, std::move(why));
  std::unique_ptr<ToolSlot> old;
  if (at == tools_.size()) tools_.push_back(std::move(fresh));
  else old = std::exchange(tools_[at], std::move(fresh));
  if (std::string err = save_frames(); !err.empty()) {
    if (old) tools_[at] = std::move(old);
    else tools_.pop_back();
    return frame_refusal(FrameRefusal::storage, CmdError::storage, std::move(err));
  }
  if (at == tool_) push_safety_tool();
  FrameResult r;
  r.def = def;
  r.redefined = old != nullptr;
  r.active = at == tool_;
  return r;
}

FrameResult ArmService::delete_tool(std::string_view name) {
  if (FrameResult no = named(true, name); !no.ok()) return no;
  const std::size_t at = find_tool(name);
  if (at == tools_.size()) return frame_refusal(FrameRefusal::not_defined, CmdError::bad_option);
  if (at == tool_) return frame_refusal(FrameRefusal::active, CmdError::bad_state);
  std::unique_ptr<ToolSlot> keep = std::move(tools_[at]);
  tools_.erase(tools_.begin() + static_cast<std::ptrdiff_t>(at));
  if (tool_ > at) --tool_;
  if (std::string err = save_frames(); !err.empty()) {
    tools_.insert(tools_.begin() + static_cast<std::ptrdiff_t>(at), std::move(keep));
    if (tool_ >= at) ++tool_;
    return frame_refusal(FrameRefusal::storage, CmdError::storage, std::move(err));
  }
  FrameResult r;
  r.def = keep->def;
  return r;
}

FrameResult ArmService::select_frame(std::string_view name, bool add_identity) {
  const std::size_t at = find_frame(name);
  if (at == frames_.size() && !add_identity) return frame_refusal(FrameRefusal::not_defined, CmdError::bad_option);
  if (FrameResult busy = frames_check(); !busy.ok()) return busy;
  FrameResult r;
  if (at == frames_.size()) {  // not set yet: an identity frame of that name
    if (frames_.size() >= kMaxFrames) return frame_refusal(FrameRefusal::full, CmdError::busy);
    NamedPose f;
    f.name = std::string(name);
    frames_.push_back(f);
    r.added = true;
  }
  const std::size_t old = frame_;
  frame_ = at;
  if (std::string err = save_frames(); !err.empty()) {
    frame_ = old;
    if (r.added) frames_.pop_back();
    return frame_refusal(FrameRefusal::storage, CmdError::storage, std::move(err));
  }
  r.def = frames_[at];
  r.active = true;
  return r;
}

FrameResult ArmService::define_frame(const NamedPose& def) {
  if (FrameResult no = named(false, def.name); !no.ok()) return no;
  const double xyz[3] = {def.pose.translation().x(), def.pose.translation().y(), def.pose.translation().z()};
  const Eigen::Vector3d r3 = kin::rpy_from_rotation(def.pose.linear());
  const double rpy[3] = {r3[0], r3[1], r3[2]};
  const double none[3] = {0, 0, 0};
  if (std::string why = check_frame_values(xyz, rpy, false, 0, none); !why.empty())
    return frame_refusal(FrameRefusal::bad_values, CmdError::out_of_range, std::move(why));
  const std::size_t at = find_frame(def.name);
  if (at == frames_.size() && frames_.size() >= kMaxFrames) return frame_refusal(FrameRefusal::full, CmdError::busy);
  const bool fresh = at == frames_.size();
  NamedPose old;
  if (fresh) frames_.push_back(def);
  else old = std::exchange(frames_[at], def);
  if (std::string err = save_frames(); !err.empty()) {
    if (fresh) frames_.pop_back();
    else frames_[at] = old;
    return frame_refusal(FrameRefusal::storage, CmdError::storage, std::move(err));
  }
  FrameResult r;
  r.def = def;
  r.redefined = !fresh;
  r.active = at == frame_;
  return r;
}

FrameResult ArmService::delete_frame(std::string_view name) {
  if (FrameResult no = named(false, name); !no.ok()) return no;
  const std::size_t at = find_frame(name);
  if (at == frames_.size()) return frame_refusal(FrameRefusal::not_defined, CmdError::bad_option);
  if (at == frame_) return frame_refusal(FrameRefusal::active, CmdError::bad_state);
  const NamedPose keep = frames_[at];
  frames_.erase(frames_.begin() + static_cast<std::ptrdiff_t>(at));
  if (frame_ > at) --frame_;
  if (std::string err = save_frames(); !err.empty()) {
    frames_.insert(frames_.begin() + static_cast<std::ptrdiff_t>(at), keep);
    if (frame_ >= at) ++frame_;
    return frame_refusal(FrameRefusal::storage, CmdError::storage, std::move(err));
  }
  FrameResult r;
  r.def = keep;
  return r;
}

}  // namespace servoarm::fw

namespace servoarm::fw {

// ---------------------------------------------------------------------------
// Teach
// ---------------------------------------------------------------------------

const char* to_string(TeachRefusal r) {
  switch (r) {
    case TeachRefusal::none: return "none";
    case TeachRefusal::program: return "program";
    case TeachRefusal::arm_state: return "arm_state";
    case TeachRefusal::queued: return "queued";
    case TeachRefusal::not_homed: return "not_homed";
  }
  return "?";
}

TeachResult ArmService::teach_here() const {
  TeachResult r;
  const ArmStatus st = status();
  r.q = st.q;
  r.pose = st.pose;
  r.tool = st.tool;
  r.frame = st.frame;
  r.arm = st.state;
  r.queued = ctl_ != nullptr ? static_cast<std::uint32_t>(ctl_->motions().size()) : 0;
  r.program = program_status();
  const auto refuse = [&r](TeachRefusal what, CmdError e) {
    r.refusal = what;
    r.error = e;
  };
  if (r.program.state != RunState::idle) {
    refuse(TeachRefusal::program, CmdError::bad_state);
    return r;
  }
  switch (st.state) {
    case ArmState::idle:
    case ArmState::disabled:
    case ArmState::freedrive: break;  // teach where the hand put it
    case ArmState::boot:
    case ArmState::enabling:
    case ArmState::moving:
    case ArmState::stopping:
    case ArmState::fault:
    case ArmState::estop:
    case ArmState::jogging:
    case ArmState::homing: refuse(TeachRefusal::arm_state, CmdError::bad_state); return r;
  }
  if (r.queued > 0) {
    refuse(TeachRefusal::queued, CmdError::bad_state);
    return r;
  }
  if (std::string why = unhomed_reason(); !why.empty()) {  // a pose in coordinates not established means nothing
    refuse(TeachRefusal::not_homed, CmdError::not_homed);
    r.reason = std::move(why);
  }
  return r;
}

}  // namespace servoarm::fw
