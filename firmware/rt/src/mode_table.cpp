// SPDX-License-Identifier: Apache-2.0
#include "servoarm/rt/mode_table.hpp"

namespace servoarm::fw {

const char* to_string(ArmState s) {
  switch (s) {
    case ArmState::boot: return "boot";
    case ArmState::disabled: return "disabled";
    case ArmState::enabling: return "enabling";
    case ArmState::idle: return "idle";
    case ArmState::moving: return "moving";
    case ArmState::stopping: return "stopping";
    case ArmState::fault: return "fault";
    case ArmState::estop: return "estop";
    case ArmState::jogging: return "jogging";
    case ArmState::homing: return "homing";
    case ArmState::freedrive: return "freedrive";
  }
  return "?";
}

const char* to_string(RequestOp op) {
  switch (op) {
    case RequestOp::enable: return "enable";
    case RequestOp::disable: return "disable";
    case RequestOp::stop: return "stop";
    case RequestOp::estop: return "estop";
    case RequestOp::reset: return "reset";
    case RequestOp::hold: return "hold";
    case RequestOp::resume: return "resume";
    case RequestOp::set_zero: return "set_zero";
    case RequestOp::jog: return "jog";
    case RequestOp::jog_cancel: return "jog_cancel";
    case RequestOp::jog_keepalive: return "jog_keepalive";
    case RequestOp::home: return "home";
    case RequestOp::freedrive_on: return "freedrive_on";
    case RequestOp::freedrive_off: return "freedrive_off";
  }
  return "?";
}

const char* to_string(Mode m) {
  switch (m) {
    case Mode::boot: return "boot";
    case Mode::disabled: return "disabled";
    case Mode::enabling: return "enabling";
    case Mode::idle: return "idle";
    case Mode::moving: return "moving";
    case Mode::hold_ramp: return "hold_ramp";
    case Mode::hold_ramp_resume: return "hold_ramp_resume";
    case Mode::hold_line: return "hold_line";
    case Mode::held: return "held";
    case Mode::stopping_to_idle: return "stopping_to_idle";
    case Mode::stopping_to_disabled: return "stopping_to_disabled";
    case Mode::fault_ramp: return "fault_ramp";
    case Mode::fault_quick_stop: return "fault_quick_stop";
    case Mode::fault: return "fault";
    case Mode::estop_ramp: return "estop_ramp";
    case Mode::estop_quick_stop: return "estop_quick_stop";
    case Mode::estop: return "estop";
    case Mode::jogging: return "jogging";
    case Mode::homing: return "homing";
    case Mode::homing_abort: return "homing_abort";
    case Mode::freedrive: return "freedrive";
    case Mode::freedrive_end: return "freedrive_end";
  }
  return "?";
}

const char* to_string(SegPhase p) {
  switch (p) {
    case SegPhase::none: return "none";
    case SegPhase::plan: return "plan";
    case SegPhase::blend_open: return "blend_open";
    case SegPhase::blend_closed: return "blend_closed";
    case SegPhase::line: return "line";
    case SegPhase::dwell: return "dwell";
    case SegPhase::path_open: return "path_open";
    case SegPhase::path_closed: return "path_closed";
    case SegPhase::path_overlap: return "path_overlap";
    case SegPhase::path_line: return "path_line";
    case SegPhase::path_to_end: return "path_to_end";
    case SegPhase::path_to_start: return "path_to_start";
  }
  return "?";
}

const char* to_string(Action a) {
  switch (a) {
    case Action::power_up: return "power_up";
    case Action::already_enabled: return "already_enabled";
    case Action::refuse_stopping: return "refuse_stopping";
    case Action::refuse_not_started: return "refuse_not_started";
    case Action::refuse_send_reset: return "refuse_send_reset";
    case Action::disable_now: return "disable_now";
    case Action::disable_drives: return "disable_drives";
    case Action::ramp_then_disable: return "ramp_then_disable";
    case Action::keep_ramp_then_disable: return "keep_ramp_then_disable";
    case Action::ramp_to_idle: return "ramp_to_idle";
    case Action::keep_ramp_to_idle: return "keep_ramp_to_idle";
    case Action::drop_queue: return "drop_queue";
    case Action::estop_stop: return "estop_stop";
    case Action::estop_keep_ramp: return "estop_keep_ramp";
    case Action::estop_keep_quick_stop: return "estop_keep_quick_stop";
    case Action::estop_at_rest: return "estop_at_rest";
    case Action::estop_again: return "estop_again";
    case Action::reset_latched: return "reset_latched";
    case Action::refuse_still_stopping: return "refuse_still_stopping";
    case Action::nothing_to_reset: return "nothing_to_reset";
    case Action::hold_motion: return "hold_motion";
    case Action::hold_queue: return "hold_queue";
    case Action::already_holding: return "already_holding";
    case Action::hold_drops_resume: return "hold_drops_resume";
    case Action::not_moving: return "not_moving";
    case Action::resume_motion: return "resume_motion";
    case Action::resume_after_ramp: return "resume_after_ramp";
    case Action::not_holding: return "not_holding";
    case Action::set_zero: return "set_zero";
    case Action::refuse_set_zero: return "refuse_set_zero";
    case Action::start_jog: return "start_jog";
    case Action::update_jog: return "update_jog";
    case Action::refuse_jog_moving: return "refuse_jog_moving";
    case Action::refuse_jog_not_enabled: return "refuse_jog_not_enabled";
    case Action::cancel_jog: return "cancel_jog";
    case Action::not_jogging: return "not_jogging";
    case Action::refresh_jog: return "refresh_jog";
    case Action::start_homing: return "start_homing";
    case Action::refuse_home_not_enabled: return "refuse_home_not_enabled";
    case Action::refuse_home_moving: return "refuse_home_moving";
    case Action::refuse_homing: return "refuse_homing";
    case Action::abort_homing: return "abort_homing";
    case Action::abort_homing_disable: return "abort_homing_disable";
    case Action::estop_abort_homing: return "estop_abort_homing";
    case Action::start_freedrive: return "start_freedrive";
    case Action::already_freedrive: return "already_freedrive";
    case Action::refuse_freedrive_not_enabled: return "refuse_freedrive_not_enabled";
    case Action::refuse_freedrive_busy: return "refuse_freedrive_busy";
    case Action::end_freedrive: return "end_freedrive";
    case Action::not_in_freedrive: return "not_in_freedrive";
  }
  return "?";
}

// Every mode's row names its own mode's expected ArmState in the comments above; what
// can be checked at compile time is checked here.
static_assert(kRequestTable.size() == kModes);
static_assert(static_cast<std::size_t>(Mode::freedrive_end) + 1 == kModes);
static_assert(static_cast<std::size_t>(RequestOp::freedrive_off) + 1 == kRequestOps);
static_assert(static_cast<std::size_t>(Action::not_in_freedrive) + 1 == kActions);
static_assert(action_for(Mode::idle, RequestOp::freedrive_on) == Action::start_freedrive);
static_assert(action_for(Mode::freedrive, RequestOp::freedrive_off) == Action::end_freedrive);
static_assert(action_for(Mode::disabled, RequestOp::enable) == Action::power_up);
static_assert(action_for(Mode::estop, RequestOp::reset) == Action::reset_latched);

}  // namespace servoarm::fw
