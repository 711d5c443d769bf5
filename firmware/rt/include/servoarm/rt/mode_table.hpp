// SPDX-License-Identifier: Apache-2.0
#pragma once
// The controller's mode (the one state value of the arm) and its request table.
//
// Mode says everything the controller needs to know about where the arm is: no flag
// sits beside it. The running motion's own state is its SegPhase, also defined here
// (with what a hold and a resume do in each); the motions and the stop trajectory are
// data the mode and the phase refer to, not state. Console-facing code sees the coarse ArmState (arm_state())
// plus Telemetry::holding (holding()); tests and diagnostics read the mode itself
// (Telemetry::mode).
//
// Every request (RequestOp) in every mode is decided by one entry of kRequestTable:
// (mode x request) -> Action. The controller looks the action up and runs it; an
// action may still refuse on data (a queue that is empty, feedback that is stale).
#include <array>
#include <cstddef>
#include <cstdint>

namespace servoarm::fw {

/// Arm state as the console sees it (coarse; derived from Mode by arm_state()).
enum class ArmState : std::uint8_t {
  boot,      ///< drives not started yet
  disabled,  ///< drives up, powered down; `enable` powers them
  enabling,  ///< drives walking to operation enabled
  idle,      ///< enabled, holding position, motion queue empty
  moving,    ///< executing the motion queue (also while a feed hold ramps down / is held)
  stopping,  ///< `stop` or `disable`: ramping down; then idle (or disabled)
  fault,     ///< supervisor fault: quick stop, then drives disabled; needs `reset` + `enable`
  estop,     ///< emergency stop: quick stop, then drives disabled; needs `reset` + `enable`
  jogging,   ///< a jog (joint or tool) runs, or decelerates after `jog stop` / 0x85 / its deadman
  homing,    ///< the homing cycle runs (`home`, `$H`): the drives, not the setpoints, move the joints homed
  freedrive, ///< hand guiding (`freedrive on`): the drives in torque mode hold gravity only; the arm moves when pushed
};
const char* to_string(ArmState s);

/// set_zero: `home zero`, the current joint positions become joint zero (ServoBus::set_position_zero);
/// only in the disabled state, and only when 0 lies within every joint's limits.
/// jog: start a jog or retarget the running one (Request::jog); jog_cancel: decelerate the
/// jog to rest (`jog stop`, GRBL 0x85); jog_keepalive: refresh a continuous jog's deadman.
/// home: run the homing cycle (Request::joints: those joints as one group; 0 = every joint,
/// group after group of ControllerConfig's homing order).
/// freedrive_on / freedrive_off: hand guiding (ModelControl, docs/dynamics.md).
enum class RequestOp : std::uint8_t {
  enable, disable, stop, estop, reset, hold, resume, set_zero, jog, jog_cancel, jog_keepalive, home,
  freedrive_on, freedrive_off
};
const char* to_string(RequestOp op);
inline constexpr std::size_t kRequestOps = 14;

/// The controller's mode. "ramp" = the controller ramps every joint to rest along its
/// stop trajectory (drives powered, following the setpoints); "quick stop" = the drives
/// stop on their own CiA 402 quick-stop ramp while the controller follows their
/// measured positions (ControllerConfig::drive_quick_stop).
enum class Mode : std::uint8_t {
  boot,              ///< drives not started
  disabled,          ///< drives up, powered down
  enabling,          ///< drives walking to operation enabled
  idle,              ///< powered, at rest, no motion running
  moving,            ///< running the motion queue
  hold_ramp,         ///< feed hold of a joint move: ramping to rest (motion kept)
  hold_ramp_resume,  ///< hold_ramp with a `resume` sent during the ramp: at rest the motion resumes
  hold_line,         ///< feed hold of a Cartesian move: slowing to rest on the line (motion kept)
  held,              ///< feed hold at rest, motion kept (or a held queue not started yet)
  stopping_to_idle,  ///< `stop`: ramping to rest, then idle
  stopping_to_disabled,  ///< `disable` while moving: ramping to rest, then drives disabled
  fault_ramp,        ///< fault reaction: ramping to rest, then drives disabled
  fault_quick_stop,  ///< fault reaction: drives' quick stop, then drives disabled
  fault,             ///< fault latched, drives disabled; needs reset
  estop_ramp,        ///< emergency stop: ramping to rest, then drives disabled
  estop_quick_stop,  ///< emergency stop: drives' quick stop, then drives disabled
  estop,             ///< emergency stop latched, drives disabled; needs reset
  jogging,           ///< a jog runs (Jogger, jog.hpp), or decelerates to rest; then idle
  homing,            ///< homing groups run one after the other (the master moves the joints of the group)
  homing_abort,      ///< homing aborted (`stop`, `!`): waiting for the drives to halt and return to CSP; then idle
  freedrive,         ///< hand guiding: every drive in cyclic synchronous torque (CST) commanded gravity + friction
                     ///< - damping from the measured state (ModelControl); no setpoints; `record` reads the pose
  freedrive_end,     ///< back to CSP holding where each joint stands (`freedrive off`, `stop`, a joint that left
                     ///< CST by itself); then idle with the setpoint at the measured pose
};
inline constexpr std::size_t kModes = 22;
const char* to_string(Mode m);

/// The one function from mode to what the console sees.
constexpr ArmState arm_state(Mode m) {
  switch (m) {
    case Mode::boot: return ArmState::boot;
    case Mode::disabled: return ArmState::disabled;
    case Mode::enabling: return ArmState::enabling;
    case Mode::idle: return ArmState::idle;
    case Mode::moving:
    case Mode::hold_ramp:
    case Mode::hold_ramp_resume:
    case Mode::hold_line:
    case Mode::held: return ArmState::moving;
    case Mode::stopping_to_idle:
    case Mode::stopping_to_disabled: return ArmState::stopping;
    case Mode::fault_ramp:
    case Mode::fault_quick_stop:
    case Mode::fault: return ArmState::fault;
    case Mode::estop_ramp:
    case Mode::estop_quick_stop:
    case Mode::estop: return ArmState::estop;
    case Mode::jogging: return ArmState::jogging;
    case Mode::homing: return ArmState::homing;
    case Mode::homing_abort: return ArmState::stopping;
    case Mode::freedrive:
    case Mode::freedrive_end: return ArmState::freedrive;
  }
  return ArmState::fault;
}

/// Feed hold active (Telemetry::holding). Not in hold_ramp_resume: the hold is released
/// (the program runner and a GRBL sender see the arm running again), the ramp only ends first.
constexpr bool holding(Mode m) { return m == Mode::hold_ramp || m == Mode::hold_line || m == Mode::held; }

/// The drives are powered and follow the controller's setpoints (which are then
/// validated: finite, within the limits, not too fast). Not while enabling, nor during a
/// drive-side quick stop (the controller only follows the drives then), nor in free-drive
/// (the drives are in torque mode, or on their way back to CSP holding where they stand).
constexpr bool powered(Mode m) {
  switch (m) {
    case Mode::idle:
    case Mode::moving:
    case Mode::hold_ramp:
    case Mode::hold_ramp_resume:
    case Mode::hold_line:
    case Mode::held:
    case Mode::stopping_to_idle:
    case Mode::stopping_to_disabled:
    case Mode::fault_ramp:
    case Mode::estop_ramp:
    case Mode::jogging:
    case Mode::homing:
    case Mode::homing_abort: return true;
    case Mode::boot:
    case Mode::disabled:
    case Mode::enabling:
    case Mode::fault_quick_stop:
    case Mode::fault:
    case Mode::estop_quick_stop:
    case Mode::estop:
    case Mode::freedrive:
    case Mode::freedrive_end: return false;
  }
  return false;
}

/// The controller samples its stop trajectory (a ramp to rest is running).
constexpr bool ramping(Mode m) {
  return m == Mode::hold_ramp || m == Mode::hold_ramp_resume || m == Mode::stopping_to_idle || m == Mode::stopping_to_disabled ||
         m == Mode::fault_ramp || m == Mode::estop_ramp;
}

/// The running segment's phase: the motion executor's state (executor.hpp) while the mode
/// runs the motion queue (moving, hold_ramp, hold_ramp_resume, hold_line, held; none in every other mode). The
/// mode says what the arm does (moves, ramps down, slows on a line, holds), the phase which
/// kind of segment runs and where its run stands. The (mode x phase) cells that exist:
///   moving: every phase but none; hold_ramp and hold_ramp_resume: plan, path_to_end, path_to_start;
///   hold_line: line, path_line; held: none, plan, line, dwell, path_line, path_to_end, path_to_start.
/// A feed hold (hold_rule) and `resume` (resume_rule) are decided by the phase; a stop, fault,
/// e-stop or disable drops the queue: phase none.
enum class SegPhase : std::uint8_t {
  none,           ///< no segment runs (the queue is empty, or held before its first move started)
  plan,           ///< a joint plan sampled (the console's, or planned here at start / after a hold)
  blend_open,     ///< a blended joint run (kin::JointBlendQueue) the next queued joint move may join
  blend_closed,   ///< a blended joint run that takes no more moves: it ends at rest at its last one
  line,           ///< a straight tool line sampled with IK (also while it slows on / is held on its line)
  dwell,          ///< standing still for its time (its clock stops while held)
  path_open,      ///< a path move sampled on the run's time base; the next one may still overlap it
  path_closed,    ///< a path move the next motion does not blend out of (or came too late for): rest at its end
  path_overlap,   ///< the next path move has started: the sample is both superposed (the next is queued second)
  path_line,      ///< a path move's line held on its line, and resumed along it
  path_to_end,    ///< after a hold: a joint plan to the segment's target, then it is done
  path_to_start,  ///< after a hold in an overlap: a joint plan to the segment's start, then it runs from rest
};
inline constexpr std::size_t kSegPhases = 12;
const char* to_string(SegPhase p);

/// What a feed hold does to the running segment: the mode it enters and the phase kept for
/// `resume`. `line_alone`: a path move's line moving alone (path_open / path_closed) stops on
/// its line as a plain line does; a path move's joint segment ramps down.
struct HoldRule {
  Mode mode;
  SegPhase after;
};
constexpr HoldRule hold_rule(SegPhase p, bool line_alone) {
  switch (p) {
    case SegPhase::none: return {Mode::held, SegPhase::none};  // between two moves: the queue is held
    case SegPhase::plan:
    case SegPhase::blend_open:
    case SegPhase::blend_closed: return {Mode::hold_ramp, SegPhase::plan};  // off its plan: re-planned at resume
    case SegPhase::line: return {Mode::hold_line, SegPhase::line};
    case SegPhase::dwell: return {Mode::held, SegPhase::dwell};
    case SegPhase::path_open:
    case SegPhase::path_closed:
      return line_alone ? HoldRule{Mode::hold_line, SegPhase::path_line} : HoldRule{Mode::hold_ramp, SegPhase::path_to_end};
    case SegPhase::path_overlap: return {Mode::hold_ramp, SegPhase::path_to_start};  // the one overlapped is done
    case SegPhase::path_line: return {Mode::hold_line, SegPhase::path_line};
    case SegPhase::path_to_end: return {Mode::hold_ramp, SegPhase::path_to_end};
    case SegPhase::path_to_start: return {Mode::hold_ramp, SegPhase::path_to_start};
  }
  return {Mode::hold_ramp, SegPhase::plan};
}

/// What `resume` does to the held segment (its phase unchanged): nothing (a dwell's clock goes
/// on; a held queue starts), plan again from where it stopped (to the move's goal, the path
/// segment's end or its start: the one re-plan rule), or go on along its line.
enum class ResumeRule : std::uint8_t { nothing, replan_goal, replan_end, replan_start, on_line };
constexpr ResumeRule resume_rule(SegPhase p) {
  switch (p) {
    case SegPhase::none:
    case SegPhase::dwell: return ResumeRule::nothing;
    case SegPhase::plan: return ResumeRule::replan_goal;
    case SegPhase::line:
    case SegPhase::path_line: return ResumeRule::on_line;
    case SegPhase::path_to_end: return ResumeRule::replan_end;
    case SegPhase::path_to_start: return ResumeRule::replan_start;
    case SegPhase::blend_open:    // (never held: a hold leaves these phases)
    case SegPhase::blend_closed:
    case SegPhase::path_open:
    case SegPhase::path_closed:
    case SegPhase::path_overlap: return ResumeRule::nothing;
  }
  return ResumeRule::nothing;
}

/// What a request does in a mode. Named after what happens; the controller runs one per request.
enum class Action : std::uint8_t {
  // enable
  power_up,               ///< disabled -> enabling (refused as a fault on stale feedback)
  already_enabled,        ///< ok "already enabled"
  refuse_stopping,        ///< bad_state "stopping; retry"
  refuse_not_started,     ///< bad_state "drives not started"
  refuse_send_reset,      ///< fault "in <state>: send reset first"
  // disable
  disable_now,            ///< drop the queue, power down -> disabled
  disable_drives,         ///< drop the queue, power down, mode unchanged (boot / fault / estop)
  ramp_then_disable,      ///< drop the queue, start a ramp -> stopping_to_disabled
  keep_ramp_then_disable, ///< drop the queue, the running ramp goes on -> stopping_to_disabled
  // stop
  ramp_to_idle,           ///< drop the queue, start a ramp -> stopping_to_idle
  keep_ramp_to_idle,      ///< drop the queue, the running (hold) ramp goes on -> stopping_to_idle
  drop_queue,             ///< drop what is queued, nothing else moves ("not moving" / "stopping")
  // estop
  estop_stop,             ///< powered, no stop running: ramp or drive quick stop -> estop_ramp / estop_quick_stop
  estop_keep_ramp,        ///< a ramp is running: it goes on (drive quick stop instead when configured)
  estop_keep_quick_stop,  ///< the drives' quick stop goes on -> estop_quick_stop
  estop_at_rest,          ///< not powered: power down -> estop
  estop_again,            ///< already in e-stop: ok "estop"
  // reset
  reset_latched,          ///< fault / estop at rest -> disabled
  refuse_still_stopping,  ///< bad_state "still stopping; retry when the arm is at rest"
  nothing_to_reset,       ///< ok "nothing to reset"
  // hold
  hold_motion,            ///< moving -> hold_ramp / hold_line / held
  hold_queue,             ///< idle with a queue -> held (else "not moving")
  already_holding,        ///< ok "already holding"
  hold_drops_resume,      ///< hold_ramp_resume: ok "feed hold" -> hold_ramp (the resume kept for the ramp's end is
                          ///< dropped: the later request wins)
  not_moving,             ///< ok "not moving"
  // resume
  resume_motion,          ///< held / hold_line -> moving
  resume_after_ramp,      ///< hold_ramp: ok "resumes when the hold's ramp ends" -> hold_ramp_resume; the ramp goes
                          ///< on to rest, then the motion resumes (an operator's resume is never lost to the
                          ///< ramp's timing; a hold, stop, e-stop or disable before that drops it)
  not_holding,            ///< ok "not holding"
  // set_zero
  set_zero,               ///< disabled: joint zero = current position (all joints or none)
  refuse_set_zero,        ///< bad_state "home zero needs the arm disabled (it is <state>)"
  // jog
  start_jog,              ///< idle, nothing queued: the jog starts -> jogging (bad_state if it cannot)
  update_jog,             ///< jogging: the running jog is retargeted from where it is (no stop between)
  refuse_jog_moving,      ///< busy "a move is running (or held): jog refused" (GRBL: no $J while a program runs)
  refuse_jog_not_enabled, ///< bad_state "jog needs the arm enabled (it is <state>)"
  cancel_jog,             ///< jogging: decelerate to rest on the jog's path, then idle
  not_jogging,            ///< ok "not jogging"
  refresh_jog,            ///< jogging: the deadman is refreshed
  // home
  start_homing,           ///< idle, nothing queued: the first group starts -> homing (fault if a drive refuses)
  refuse_home_not_enabled,///< bad_state "home needs the arm enabled (it is <state>)"
  refuse_home_moving,     ///< busy "a move or jog is running (or held): home refused"
  refuse_homing,          ///< busy "homing runs: stop it first (stop, !, Ctrl-X)" (jog, home while homing)
  // stop / hold / disable / estop while homing
  abort_homing,           ///< abort the running joints (left unhomed) -> homing_abort, then idle
  abort_homing_disable,   ///< abort the running joints, power down -> disabled
  estop_abort_homing,     ///< abort the running joints, power down -> estop
  // freedrive_on / freedrive_off
  start_freedrive,        ///< idle, nothing queued: every drive to torque mode -> freedrive (refused naming the
                          ///< joint or the model when it cannot: bad_state)
  already_freedrive,      ///< ok "free-drive on"
  refuse_freedrive_not_enabled, ///< bad_state "freedrive needs the arm enabled (it is <state>)"
  refuse_freedrive_busy,  ///< busy "a move, jog or homing is running (or held): freedrive refused"
  end_freedrive,          ///< freedrive (`freedrive off`, `stop`, feed hold): back to CSP where it stands -> freedrive_end
  not_in_freedrive,       ///< ok "free-drive off" (freedrive_end: "free-drive ending")
};
inline constexpr std::size_t kActions = 50;
const char* to_string(Action a);

using RequestRow = std::array<Action, kRequestOps>;  ///< indexed by RequestOp

/// (mode x request) -> action. Rows in Mode order, columns in RequestOp order:
///   enable, disable, stop, estop, reset, hold, resume, set_zero, jog, jog_cancel, jog_keepalive, home,
///   freedrive_on, freedrive_off.
inline constexpr std::array<RequestRow, kModes> kRequestTable = {{
    // boot
    {Action::refuse_not_started, Action::disable_drives, Action::drop_queue, Action::estop_at_rest,
     Action::nothing_to_reset, Action::not_moving, Action::not_holding, Action::refuse_set_zero,
     Action::refuse_jog_not_enabled, Action::not_jogging, Action::not_jogging, Action::refuse_not_started,
     Action::refuse_not_started, Action::not_in_freedrive},
    // disabled
    {Action::power_up, Action::disable_now, Action::drop_queue, Action::estop_at_rest, Action::nothing_to_reset,
     Action::not_moving, Action::not_holding, Action::set_zero,
     Action::refuse_jog_not_enabled, Action::not_jogging, Action::not_jogging, Action::refuse_home_not_enabled,
     Action::refuse_freedrive_not_enabled, Action::not_in_freedrive},
    // enabling
    {Action::already_enabled, Action::disable_now, Action::drop_queue, Action::estop_at_rest, Action::nothing_to_reset,
     Action::not_moving, Action::not_holding, Action::refuse_set_zero,
     Action::refuse_jog_not_enabled, Action::not_jogging, Action::not_jogging, Action::refuse_home_not_enabled,
     Action::refuse_freedrive_not_enabled, Action::not_in_freedrive},
    // idle
    {Action::already_enabled, Action::disable_now, Action::drop_queue, Action::estop_stop, Action::nothing_to_reset,
     Action::hold_queue, Action::not_holding, Action::refuse_set_zero,
     Action::start_jog, Action::not_jogging, Action::not_jogging, Action::start_homing,
     Action::start_freedrive, Action::not_in_freedrive},
    // moving
    {Action::already_enabled, Action::ramp_then_disable, Action::ramp_to_idle, Action::estop_stop,
     Action::nothing_to_reset, Action::hold_motion, Action::not_holding, Action::refuse_set_zero,
     Action::refuse_jog_moving, Action::not_jogging, Action::not_jogging, Action::refuse_home_moving,
     Action::refuse_freedrive_busy, Action::not_in_freedrive},
    // hold_ramp
    {Action::already_enabled, Action::keep_ramp_then_disable, Action::keep_ramp_to_idle, Action::estop_keep_ramp,
     Action::nothing_to_reset, Action::already_holding, Action::resume_after_ramp, Action::refuse_set_zero,
     Action::refuse_jog_moving, Action::not_jogging, Action::not_jogging, Action::refuse_home_moving,
     Action::refuse_freedrive_busy, Action::not_in_freedrive},
    // hold_ramp_resume
    {Action::already_enabled, Action::keep_ramp_then_disable, Action::keep_ramp_to_idle, Action::estop_keep_ramp,
     Action::nothing_to_reset, Action::hold_drops_resume, Action::resume_after_ramp, Action::refuse_set_zero,
     Action::refuse_jog_moving, Action::not_jogging, Action::not_jogging, Action::refuse_home_moving,
     Action::refuse_freedrive_busy, Action::not_in_freedrive},
    // hold_line
    {Action::already_enabled, Action::ramp_then_disable, Action::ramp_to_idle, Action::estop_stop,
     Action::nothing_to_reset, Action::already_holding, Action::resume_motion, Action::refuse_set_zero,
     Action::refuse_jog_moving, Action::not_jogging, Action::not_jogging, Action::refuse_home_moving,
     Action::refuse_freedrive_busy, Action::not_in_freedrive},
    // held
    {Action::already_enabled, Action::ramp_then_disable, Action::ramp_to_idle, Action::estop_stop,
     Action::nothing_to_reset, Action::already_holding, Action::resume_motion, Action::refuse_set_zero,
     Action::refuse_jog_moving, Action::not_jogging, Action::not_jogging, Action::refuse_home_moving,
     Action::refuse_freedrive_busy, Action::not_in_freedrive},
    // stopping_to_idle
    {Action::refuse_stopping, Action::keep_ramp_then_disable, Action::drop_queue, Action::estop_keep_ramp,
     Action::nothing_to_reset, Action::not_moving, Action::not_holding, Action::refuse_set_zero,
     Action::refuse_stopping, Action::not_jogging, Action::not_jogging, Action::refuse_stopping,
     Action::refuse_stopping, Action::not_in_freedrive},
    // stopping_to_disabled
    {Action::refuse_stopping, Action::keep_ramp_then_disable, Action::drop_queue, Action::estop_keep_ramp,
     Action::nothing_to_reset, Action::not_moving, Action::not_holding, Action::refuse_set_zero,
     Action::refuse_stopping, Action::not_jogging, Action::not_jogging, Action::refuse_stopping,
     Action::refuse_stopping, Action::not_in_freedrive},
    // fault_ramp
    {Action::refuse_send_reset, Action::disable_drives, Action::drop_queue, Action::estop_keep_ramp,
     Action::refuse_still_stopping, Action::not_moving, Action::not_holding, Action::refuse_set_zero,
     Action::refuse_send_reset, Action::not_jogging, Action::not_jogging, Action::refuse_send_reset,
     Action::refuse_send_reset, Action::not_in_freedrive},
    // fault_quick_stop
    {Action::refuse_send_reset, Action::disable_drives, Action::drop_queue, Action::estop_keep_quick_stop,
     Action::refuse_still_stopping, Action::not_moving, Action::not_holding, Action::refuse_set_zero,
     Action::refuse_send_reset, Action::not_jogging, Action::not_jogging, Action::refuse_send_reset,
     Action::refuse_send_reset, Action::not_in_freedrive},
    // fault
    {Action::refuse_send_reset, Action::disable_drives, Action::drop_queue, Action::estop_at_rest,
     Action::reset_latched, Action::not_moving, Action::not_holding, Action::refuse_set_zero,
     Action::refuse_send_reset, Action::not_jogging, Action::not_jogging, Action::refuse_send_reset,
     Action::refuse_send_reset, Action::not_in_freedrive},
    // estop_ramp
    {Action::refuse_send_reset, Action::disable_drives, Action::drop_queue, Action::estop_again,
     Action::refuse_still_stopping, Action::not_moving, Action::not_holding, Action::refuse_set_zero,
     Action::refuse_send_reset, Action::not_jogging, Action::not_jogging, Action::refuse_send_reset,
     Action::refuse_send_reset, Action::not_in_freedrive},
    // estop_quick_stop
    {Action::refuse_send_reset, Action::disable_drives, Action::drop_queue, Action::estop_again,
     Action::refuse_still_stopping, Action::not_moving, Action::not_holding, Action::refuse_set_zero,
     Action::refuse_send_reset, Action::not_jogging, Action::not_jogging, Action::refuse_send_reset,
     Action::refuse_send_reset, Action::not_in_freedrive},
    // estop
    {Action::refuse_send_reset, Action::disable_drives, Action::drop_queue, Action::estop_again,
     Action::reset_latched, Action::not_moving, Action::not_holding, Action::refuse_set_zero,
     Action::refuse_send_reset, Action::not_jogging, Action::not_jogging, Action::refuse_send_reset,
     Action::refuse_send_reset, Action::not_in_freedrive},
    // jogging (hold = GRBL's feed hold during a jog: the jog is cancelled)
    {Action::already_enabled, Action::ramp_then_disable, Action::ramp_to_idle, Action::estop_stop,
     Action::nothing_to_reset, Action::cancel_jog, Action::not_holding, Action::refuse_set_zero,
     Action::update_jog, Action::cancel_jog, Action::refresh_jog, Action::refuse_home_moving,
     Action::refuse_freedrive_busy, Action::not_in_freedrive},
    // homing (hold = GRBL's `!`: aborts the homing cycle as `stop` does)
    {Action::already_enabled, Action::abort_homing_disable, Action::abort_homing, Action::estop_abort_homing,
     Action::nothing_to_reset, Action::abort_homing, Action::not_holding, Action::refuse_set_zero,
     Action::refuse_homing, Action::not_jogging, Action::not_jogging, Action::refuse_homing,
     Action::refuse_homing, Action::not_in_freedrive},
    // homing_abort
    {Action::refuse_stopping, Action::abort_homing_disable, Action::drop_queue, Action::estop_abort_homing,
     Action::nothing_to_reset, Action::not_moving, Action::not_holding, Action::refuse_set_zero,
     Action::refuse_stopping, Action::not_jogging, Action::not_jogging, Action::refuse_stopping,
     Action::refuse_stopping, Action::not_in_freedrive},
    // freedrive (hand guiding: stop, feed hold and `freedrive off` hold where the arm stands)
    {Action::already_enabled, Action::disable_now, Action::end_freedrive, Action::estop_stop,
     Action::nothing_to_reset, Action::end_freedrive, Action::not_holding, Action::refuse_set_zero,
     Action::refuse_jog_moving, Action::not_jogging, Action::not_jogging, Action::refuse_home_moving,
     Action::already_freedrive, Action::end_freedrive},
    // freedrive_end (the drives back to CSP: one to three cycles)
    {Action::already_enabled, Action::disable_now, Action::drop_queue, Action::estop_stop,
     Action::nothing_to_reset, Action::not_moving, Action::not_holding, Action::refuse_set_zero,
     Action::refuse_stopping, Action::not_jogging, Action::not_jogging, Action::refuse_stopping,
     Action::refuse_stopping, Action::not_in_freedrive},
}};

constexpr Action action_for(Mode m, RequestOp op) {
  return kRequestTable[static_cast<std::size_t>(m)][static_cast<std::size_t>(op)];
}

}  // namespace servoarm::fw
