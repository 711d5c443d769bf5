// SPDX-License-Identifier: Apache-2.0
#pragma once
// The arm service: the one place a canonical move (MoveJoints, MoveLine, a dwell) is planned,
// checked and queued. Typed requests in, typed results out (MoveResult: a CmdError, what was
// refused with its figures, or the planned knots); no text and no units of its own beyond a
// one-line reason: SI inside, every front end (the console, the GRBL dialect, the program
// runner, `armctl program check`) converts and renders.
//
// Two modes, one code path:
// - real run (MoveContext::dry == nullptr): the move is planned from the end of the motion
//   queue and committed to the Controller's queue;
// - dry run (MoveContext::dry set): the same planning and checks from the DryRun's own tail
//   and blend state, nothing queued; the result reports the same knots and times. The
//   console's `check` and GRBL's $C run it, and so does `armctl program check` (which has no
//   Controller: the service is built from the chain, limits and rate alone).
//
// Events: the service is the one consumer of the Controller's event queue. poll_events() takes
// every event into a bounded ring of typed records (ArmEvent: a sequence number one more than the
// one before, the control cycle, what happened, the joint, the motion); each reader (the
// console, a network client) keeps its own place and asks events_since(seq). A reader slower
// than the ring gets the oldest events still kept and how many it missed.
//
// Console thread (non-real-time: may allocate). Talks to the control thread only through the
// Controller's SPSC queues and telemetry.
#include <array>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "servoarm/kinematics/blend_path.hpp"
#include "servoarm/kinematics/ik.hpp"
#include "servoarm/kinematics/safety.hpp"
#include "servoarm/kinematics/trajectory.hpp"
#include "servoarm/lang/commands.hpp"
#include "servoarm/lang/frames.hpp"
#include "servoarm/lang/requests.hpp"
#include "servoarm/lang/units.hpp"
#include "servoarm/program/points.hpp"
#include "servoarm/program/program.hpp"
#include "servoarm/rt/controller.hpp"

namespace servoarm::fw {

/// What a move request refused (MoveResult::refusal); none: accepted.
enum class MoveRefusal : std::uint8_t {
  none,
  arm_state,     ///< the arm takes no moves now (bad_state / fault; `reason` says why)
  not_homed,     ///< a joint is not homed (`reason` names them)
  joint_limit,   ///< the goal's joint `joint` = `value` is outside [`lower`, `upper`]
  linear_speed,  ///< the line's speed `speed` is outside [kMinLinearSpeedMmS, max_linear_speed]
  plan,          ///< the planner refused (`status`; lines: at fraction `s`, tool point `position`, `joint`)
  duration,      ///< the plan takes `duration` s, more than max_move_duration_s
  queue_full,    ///< the motion queue is full (real run)
};
const char* to_string(MoveRefusal r);

/// The safety envelope at one target (docs/safety.md): the tool (and elbow) sphere at joints q
/// against the planes, boxes and orientation cone of `env` in `mode`, and, when dt > 0, the
/// TCP and elbow speeds of the step from q_prev to q taken in dt seconds. "" inside, else the
/// one line naming the function, where and the limit and value. The hook for streamed targets
/// (service/stream.hpp): ArmService::check_target calls it with the service's envelope and mode.
std::string envelope_violation_at(const kin::SafetyConfig& env, kin::SafetyMode mode, const kin::Chain& chain,
                                  const kin::JointVector& q_prev, const kin::JointVector& q, double dt);

/// The error code of a planner status.
CmdError motion_error(kin::MotionStatus m);

/// The answer to a move or a dwell: accepted with its knots, or refused with what and why.
struct MoveResult {
  CmdError error = CmdError::ok;
  MoveRefusal refusal = MoveRefusal::none;
  std::string reason;              ///< arm_state / not_homed: one line (no units in it)
  std::uint32_t id = 0;            ///< the motion's id (real run; 0 in a dry run)
  kin::MotionStatus status = kin::MotionStatus::ok;  ///< the planner's (slowed_near_singularity is ok)
  double duration = 0;             ///< s: the move planned alone, from rest to rest; a dwell's seconds
  kin::JointVector goal;           ///< where the move (or dwell) ends
  double speed = 0;                ///< lines: the tool speed planned (m/s: default, override and clamp applied)
  double slowdown = 1;             ///< lines slowed near a singularity: the factor
  double envelope_ratio = 0;       ///< the planned move's highest ratio to the envelope's speed, stop and dynamics limits (kin::speed_ratio; <= 1: within, 0: none set)
  bool blended = false;            ///< went as a blended path segment (PathMove)
  double blend = 0;                ///< s: its overlap with the segment before it
  double segment_start = 0;        ///< s: the segment's start and end on its blended run's time base
  double segment_end = 0;
  // what a refusal found
  int joint = -1;                  ///< joint_limit, plan (lines): the joint (0-based), -1 none
  double value = 0, lower = 0, upper = 0;  ///< joint_limit: SI
  double s = 0;                    ///< plan (lines): where along the line (0..1)
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  ///< plan (lines): the tool point there (base frame, m)
  bool ok() const { return error == CmdError::ok; }
};

/// The segments of a blended run (docs/motion.md#blending), planned and blended by the service.
using PathShadow = kin::PathBlendQueue<4>;

/// A dry run's own state: where the checked moves end and when.
struct DryRun {
  kin::JointVector tail;     ///< where the checked moves end
  double time = 0;           ///< end time of the checked moves (blended runs overlapped)
  double run_base = 0;       ///< `time` where the current blended run began
  bool blends = false;       ///< the last checked move is a blended segment with a tolerance
  PathShadow* shadow = nullptr;  ///< its blend state (the owner keeps it; required)
};

/// What a request runs with: the mode, and what the front end has selected.
struct MoveContext {
  DryRun* dry = nullptr;            ///< set: a dry run (planned and checked, nothing queued)
  const kin::Chain* chain = nullptr;  ///< the active tool's chain; nullptr: the arm's
  kin::IkSolver ik{};               ///< its IK (movel's path check and the controller's sampling)
  int feed_pct = -1;                ///< feed override (10..200) scaling the move's speed; < 0: the service's
  std::span<const OutputChange> outputs{};  ///< M62 / M63 changes the move carries (real run)
  double step_blend = -1;           ///< a program step's blend tolerance (SI; < 0 none)
  bool next_line = false;           ///< a program step whose next motion is a line
};

/// The answer to an arm-control request (enable, disable, stop, e-stop, reset, hold, set zero)
/// or any other request the control thread answers.
struct ControlResult {
  CmdError error = CmdError::ok;  ///< timeout: the control thread did not answer in time
  std::string reason;             ///< the control thread's one line (or why it did not answer)
  Reply reply{};                  ///< the control thread's reply (when it answered)
  bool ok() const { return error == CmdError::ok; }
};

/// A proposed [safety] section (docs/safety.md#confirming-a-change): what the SafetyStager made
/// of a change, validated against the robot.
struct SafetyProposal {
  kin::SafetyConfig safety{};    ///< the envelope in SI
  std::uint32_t checksum = 0;    ///< as `status` shows it (the section and the description's capsules)
  std::string changes;           ///< the keys that change, `key = old -> new`, "; " between
  std::function<void()> commit;  ///< called when it is applied (keeps the caller's configuration in step)
};
/// Makes a proposal from TOML lines of [safety] keys (`key = value`, newline or `;` between,
/// `safety.` optional): "" or why not (one line naming the key).
using SafetyStager = std::function<std::string(const std::string& changes, SafetyProposal& out)>;

/// The answer to ArmService::stage_safety / confirm_safety.
struct SafetyChangeResult {
  CmdError error = CmdError::ok;
  std::string reason;          ///< a refusal's one line
  std::uint32_t checksum = 0;  ///< staged: the checksum to confirm; confirmed: the one in force now
  std::uint32_t previous = 0;  ///< the checksum in force before
  double expires_s = 0;        ///< staged: seconds left to confirm it
  std::string changes;         ///< SafetyProposal::changes
  bool ok() const { return error == CmdError::ok; }
};

/// The error code of a control-thread result.
CmdError control_error(RtResult r);

/// A digital output ([[output]]): bit `bit` of joint `joint`'s drive outputs word, and the
/// name it is asked by.
struct OutputBit {
  std::string name;
  int joint = 0;
  int bit = 0;
};

/// Set digital output `index` (the [[output]] order) on or off: at once (M64 / M65, `out`),
/// or with the next move (`sync`: M62 / M63); `dry`: checked only.
struct OutputRequest {
  std::size_t index = 0;
  bool on = false;
  bool sync = false;
  bool dry = false;
};

/// What an output request refused (OutputResult::refusal); none: accepted.
enum class OutputRefusal : std::uint8_t {
  none,
  no_output,   ///< no output `index` (`count` outputs)
  sync_full,   ///< sync: outputs of more than kMotionOutputs drives already wait for the next move
  queue_full,  ///< at once: the control thread's output queue is full; not set
};
const char* to_string(OutputRefusal r);

struct OutputResult {
  CmdError error = CmdError::ok;
  OutputRefusal refusal = OutputRefusal::none;
  std::size_t count = 0;  ///< the outputs configured
  bool ok() const { return error == CmdError::ok; }
};

/// The service's settings (SI), in one place: the configuration gives them at start
/// (App::console_config), set_settings() changes them; every front end reads them here.
struct MotionSettings {
  double default_joint_speed_pct = 50.0;  ///< movej / park without a speed: percent of the joint limits
  double default_linear_speed = 0.1;   ///< m/s: movel / G1 without a speed
  double max_linear_speed = 0.25;      ///< m/s: upper bound of a line's speed, and G0
  double max_move_duration_s = 600.0;  ///< longest move or jog accepted: out_of_range beyond
  kin::CartesianLimits cartesian{};    ///< linear_velocity is replaced per move
  double default_blend_rad = 0.0;      ///< blend tolerance of a movej that gives none (0: exact stop)
  double default_blend_m = 0.0;        ///< the same of movel, G0/G1 (tool-point distance)
  kin::JointVector home;               ///< the park pose (`park`, G28; SI); empty: every joint's zero clamped into its limits
  double jog_speed_pct = 10.0;         ///< jog speed without one given: percent of the joint / tool limits
  double jog_deadman_s = 0.25;         ///< a continuous jog not refreshed this long stops
  double reply_timeout_s = 1.0;        ///< wait for the control thread to answer a request
  std::vector<OutputBit> outputs;      ///< the digital outputs, in [[output]] order (fixed at start)
  /// The safety envelope ([safety], docs/safety.md) every planned move, blended run, program
  /// step and jog step is checked against; disabled: none. Fixed at start.
  kin::SafetyConfig safety{};
  std::uint32_t safety_checksum = 0;   ///< CRC-32 of the [safety] section's canonical form (fw::safety_checksum)
};

/// A setting set_settings() checks (SettingsResult::setting).
enum class Setting : std::uint8_t {
  none,
  default_joint_speed_pct,
  default_linear_speed,
  max_linear_speed,
  max_move_duration_s,
  default_blend_rad,
  default_blend_m,
  home,
  jog_speed_pct,
  jog_deadman_s,
  reply_timeout_s,
  outputs,
  feed_override,
};
const char* to_string(Setting s);

/// The answer to set_settings() / set_feed_override(): done, or the setting refused with its
/// value and range (SI; home: joint `joint`'s value against its limits).
struct SettingsResult {
  CmdError error = CmdError::ok;
  Setting setting = Setting::none;
  double value = 0, lower = 0, upper = 0;
  int joint = -1;
  bool ok() const { return error == CmdError::ok; }
};

/// The feed override's range (percent; GRBL 0x90..0x94 step it within it).
inline constexpr int kMinFeedOverride = 10;
inline constexpr int kMaxFeedOverride = 200;

/// A joint's homing as the status reports it.
enum class JointHoming : std::uint8_t {
  unhomed,   ///< its zero is not established (not homed since power-on)
  homing,    ///< it homes now
  homed,     ///< homed this power cycle
  failed,    ///< its last homing failed
  absolute,  ///< an absolute encoder: needs no homing
};
const char* to_string(JointHoming h);

/// The answer to status(): what the arm does and where it is (SI), read from one telemetry
/// snapshot. A query: it changes nothing.
struct ArmStatus {
  ArmState state = ArmState::boot;
  Mode mode = Mode::boot;
  bool holding = false;            ///< a feed hold is active
  std::uint32_t queued = 0;        ///< motions in the queue (the running one included)
  std::uint32_t running_id = 0;    ///< the running motion (0 none)
  std::uint32_t done_id = 0;       ///< the last motion finished
  std::uint64_t cycles = 0;        ///< control cycles since start (RT time)
  double t = 0;                    ///< the same in s
  kin::JointVector q;              ///< measured joint positions
  kin::JointVector q_cmd;          ///< commanded joint positions
  /// Per joint: the drive's hottest reported temperature (deg C; MIT motors: MOSFET or winding),
  /// NaN for a drive that reports none (CiA 402).
  kin::JointVector temperature;
  std::uint16_t temperature_warning = 0;  ///< bit j: joint j at or above its warning temperature
  std::vector<JointHoming> homing; ///< per joint
  bool all_homed = false;
  FaultCause fault = FaultCause::none;  ///< the fault's cause (state fault)
  int fault_joint = -1;            ///< the joint concerned (0-based), -1 none
  std::string fault_text;          ///< the control thread's line for it ("" none)
  int feed_pct = 100;              ///< the feed override
  std::string tool = "tool0";      ///< the active tool
  std::string frame = "base";      ///< the active user frame
  kin::Pose pose = kin::Pose::Identity();  ///< the active tool point at q, in the base frame (m)
  kin::Pose pose_in_frame = kin::Pose::Identity();  ///< the same in the active user frame
  FeedForwardKind feed_forward = FeedForwardKind::off;
  bool collision_on = false;
  FreedrivePhase freedrive = FreedrivePhase::off;
  bool safety_on = false;                              ///< a safety envelope is configured
  kin::SafetyMode safety_mode = kin::SafetyMode::normal;  ///< Normal or Reduced (Reduced while the Reduced input is)
  std::uint8_t safety_inputs = 0;                      ///< Telemetry::safety_inputs
  std::uint32_t safety_checksum = 0;                   ///< of the [safety] section (MotionSettings::safety_checksum)
};

/// The answer to arm_limits(): the joint limits, the joints' kinds and the Cartesian limits (SI).
struct ArmLimits {
  kin::JointLimits joints;              ///< lower, upper, max velocity / acceleration / jerk per joint
  std::vector<bool> prismatic;          ///< per joint: a length (m), else an angle (rad)
  double following_error = 0;           ///< the supervisor's following-error limit (rad)
  double default_linear_speed = 0, max_linear_speed = 0;  ///< m/s
  kin::CartesianLimits cartesian{};
};

/// What a jog request refused (JogResult::refusal); none: accepted.
enum class JogRefusal : std::uint8_t {
  none,
  range,        ///< joint jog: the increment is larger than joint `joint`'s range [`lower`, `upper`]
  at_limit,     ///< joint jog: joint `joint` stands at its limit `value` already
  rotation,     ///< tool jog: the rotation `value` (rad) is half a turn or more
  duration,     ///< it would take `duration` s, more than max_move_duration_s
  unreachable,  ///< tool jog: the target has no IK solution within the joint limits
  feed,         ///< pose jog: the speed `speed` (m/s, override applied) is below kMinLinearSpeedMmS
  control,      ///< the control thread refused it (`reason` is its line)
};
const char* to_string(JogRefusal r);

/// A joint jog: joint `joint` (0-based) by `increment` (rad or m), or continuously towards
/// its limit in `direction` (+1 / -1), at `speed_pct` percent of the joint limits (< 0: the
/// default jog speed); the feed override scales it.
struct JointJog {
  int joint = 0;
  bool continuous = false;
  int direction = 1;
  double increment = 0;
  double speed_pct = -1;
};

/// A tool jog: along (axis 0..2, m) or about (3..5, rad) an axis of `frame` by `increment`,
/// or continuously in `direction`; at `speed_pct` percent of the linear and angular limits.
struct ToolJog {
  int axis = 0;
  bool continuous = false;
  int direction = 1;
  double increment = 0;
  double speed_pct = -1;
  JogFrame frame = JogFrame::base;
};

/// A jog of the tool to a pose (GRBL $J): `target` in the base frame, at `speed` m/s along
/// the path (before the feed override); `frame`/`axes`: the frame it is given in.
struct PoseJog {
  kin::Pose target = kin::Pose::Identity();
  double speed = 0;
  JogFrame frame = JogFrame::base;
  Eigen::Matrix3d axes = Eigen::Matrix3d::Identity();
};

/// What a jog runs with: the active tool's chain and IK, the feed override, the user frame.
struct JogContext {
  const kin::Chain* chain = nullptr;  ///< nullptr: the arm's
  kin::IkSolver ik{};  ///< tool and pose jogs check their target with it (none: refused as unreachable)
  int feed_pct = -1;   ///< < 0: the service's feed override
  Eigen::Matrix3d user_axes = Eigen::Matrix3d::Identity();  ///< the active user frame's orientation
};

/// The answer to a jog: accepted (the control thread's line in `reason`), or what was refused.
struct JogResult {
  CmdError error = CmdError::ok;
  JogRefusal refusal = JogRefusal::none;
  std::string reason;           ///< the control thread's one line (accepted, or its refusal)
  int joint = -1;               ///< range, at_limit, clamped: the joint (0-based)
  bool clamped = false;         ///< accepted, stopping at joint `joint`'s limit `value` (asked `asked`)
  double asked = 0;             ///< clamped: where the increment would have taken the joint (SI)
  double value = 0;             ///< at_limit / clamped: the limit; rotation: the angle (rad)
  double lower = 0, upper = 0;  ///< range: the joint's limits (SI)
  double duration = 0;          ///< duration: s
  double speed = 0;             ///< tool and pose jogs: the path speed (m/s)
  bool ok() const { return error == CmdError::ok; }
};

/// What an event of the stream is: the control thread's kinds (EventKind, same order), and
/// the program runner's.
enum class ArmEventKind : std::uint8_t {
  fault,
  estop,
  motion_done,
  motion_refused,
  state,
  jog_stopped,
  homing,
  freedrive,
  program,  ///< the program runner: ArmEvent::program says what (started, a step, ended)
  warning,  ///< the arm runs on, but the operator should know (a joint at its warning temperature)
};
const char* to_string(ArmEventKind k);

/// A program run by the service (run_program): idle = none.
enum class RunState : std::uint8_t {
  idle,       ///< no program
  running,    ///< steps are fed to the motion queue
  pausing,    ///< paused: nothing more is fed; paused once the queued moves are done
  paused,     ///< stopped between two steps (or held mid-move)
  stepping,   ///< one motion fed, paused when it is done
};
const char* to_string(RunState r);

/// A program event (ArmEventKind::program): what happened.
enum class ProgramPhase : std::uint8_t {
  started,  ///< the program runs (`steps` steps)
  step,     ///< the running motion is now step `step` (`file`, `line`)
  ended,    ///< it ended: `end` says how
};
const char* to_string(ProgramPhase p);

/// How a program ended.
enum class ProgramEnd : std::uint8_t {
  none,
  done,           ///< every step ran (`steps` steps in `seconds`)
  stop,           ///< a stop request
  estop,          ///< an e-stop request (`realtime`: asked by a realtime byte), or the arm went into e-stop
  soft_reset,     ///< a soft reset (a stop asked by a realtime byte)
  disable,        ///< a disable request
  abort,          ///< program_abort()
  fault,          ///< the arm went into fault (event_detail: the fault's line)
  arm_state,      ///< the arm was disabled, or began jogging, homing or free-drive (`state`)
  queue_dropped,  ///< the motion queue was dropped (a stop from elsewhere, a refused move)
  step_refused,   ///< step `step` was refused (`error`; event_detail: the front end's line)
};
const char* to_string(ProgramEnd e);

/// One event of the arm's event stream: figures only, no text (the control thread's own line
/// for it, when it sent one, is ArmService::event_detail; a program event's names are
/// ArmService::event_program).
struct ArmEvent {
  std::uint64_t seq = 0;        ///< 1, 2, 3, ...: one more than the event before it
  std::uint64_t cycle = 0;      ///< RT time stamp: the control cycle (Telemetry::cycles) the service took it at
  double t = 0;                 ///< the same in s (cycle times the control period)
  ArmEventKind kind = ArmEventKind::state;
  ArmState state = ArmState::boot;  ///< the arm's state when the control thread sent it
  FaultCause cause = FaultCause::none;  ///< fault: the cause
  std::int8_t joint = -1;       ///< the joint concerned (0-based), -1 none or every joint
  std::uint32_t motion_id = 0;  ///< motion_done / motion_refused: the motion (0 none)
  // program events
  ProgramPhase program = ProgramPhase::started;
  ProgramEnd end = ProgramEnd::none;  ///< ended: how
  bool realtime = false;        ///< ended by estop / soft_reset: asked by a realtime byte (Ctrl-X)
  CmdError error = CmdError::ok;  ///< step_refused: the step's error
  std::uint32_t step = 0;       ///< the step concerned (0-based; ended: where it ended)
  std::uint32_t steps = 0;      ///< the program's steps
  std::int32_t line = 0;        ///< the step's line in its file (1-based; 0: none)
  double seconds = 0;           ///< done: how long it ran (s)
};

/// A program event's names (event_program): the program and the file of its step.
struct ProgramNames {
  std::string_view program;
  std::string_view file;
};

/// Events the service keeps for its readers (the oldest is overwritten first).
inline constexpr std::size_t kEventRing = 256;

/// The answer to events_since(seq): the events after it still kept, oldest first.
struct EventBatch {
  std::vector<ArmEvent> events;
  std::uint64_t missed = 0;  ///< events after `seq` no longer kept (overwritten before this read)
};

/// What a program step is to the runner (the front end that loaded the program says).
enum class StepClass : std::uint8_t {
  motion,      ///< queues one motion (a move, a dwell): fed one ahead of the running motion
  needs_idle,  ///< runs with the arm at rest and nothing queued (tool, frame, an output at once)
  wait,        ///< waits until the queued motions have run (the runner does it)
  other,       ///< runs at once (a query, a modal line, an output with the next move)
};

/// A loaded program as the runner sees it: its name, its files (as a step's place names
/// them) and each step's kind and place.
struct ProgramSpec {
  struct Step {
    StepClass kind = StepClass::other;
    int file = 0;  ///< index into files
    int line = 0;  ///< 1-based
  };
  std::string name;
  std::vector<std::string> files;
  std::vector<Step> steps;
};

/// One step's outcome, from the front end that runs it (StepExecutor): ok, or refused with
/// the error and the front end's one line for it.
struct StepOutcome {
  CmdError error = CmdError::ok;
  std::string reason;
  bool ok() const { return error == CmdError::ok; }
};
/// Runs step `i` of the running program (a motion step queues its motion through move() /
/// dwell(): the runner takes its id from the service).
using StepExecutor = std::function<StepOutcome(std::size_t i)>;

/// The answer to program_status(): the running program and where it is. A query.
struct ProgramStatus {
  RunState state = RunState::idle;
  std::string name;
  std::size_t steps = 0;
  std::size_t step = 0;       ///< the step of the running motion (or the next to run): its place
  std::string file;           ///< that step's file ("" when no program or no steps)
  int line = 0;               ///< and line (0: none)
  std::size_t running = 0;    ///< the step of the running motion (or the last fed)
  int running_line = 0;       ///< its line (0: none)
  std::uint64_t started_cycle = 0;  ///< the control cycle it started at
};

/// The answer to check_program(): ok, or the first step refused with its place and one line.
struct ProgramCheckResult {
  CmdError error = CmdError::ok;
  std::size_t step = 0;     ///< the refused step (index into the program's steps)
  std::string file;         ///< its file and line (1-based)
  int line = 0;
  std::string reason;       ///< one line: why
  MoveResult move;          ///< a refused move or dwell: what the planner found
  prog::StepCounts counts;  ///< the program's steps (prog::count_steps)
  double duration = 0;      ///< s: the planned time of its moves and dwells (blended runs overlapped)
  std::size_t planned = 0;  ///< steps dry-run: all, or up to a tool / frame definition (not made by a check)
  bool ok() const { return error == CmdError::ok; }
};

/// What a program request refused (ProgramResult::refusal); none: accepted.
enum class ProgramRefusal : std::uint8_t {
  none,
  no_program,     ///< no program runs (pause, step, abort)
  running,        ///< run: a program runs already (`status` is it)
  program_state,  ///< step: the program is not paused (`status.state`)
  arm_not_ready,  ///< run: the arm is not at rest with nothing queued, or a joint is not homed (`arm`)
};
const char* to_string(ProgramRefusal r);

struct ProgramResult {
  CmdError error = CmdError::ok;
  ProgramRefusal refusal = ProgramRefusal::none;
  ProgramStatus status;       ///< the program after the request (ended: state idle)
  ArmState arm = ArmState::idle;  ///< arm_not_ready: the arm's state
  std::uint32_t queued = 0;   ///< arm_not_ready: motions queued
  bool ok() const { return error == CmdError::ok; }
};

/// What a tool or user-frame request refused (FrameResult::refusal); none: done.
enum class FrameRefusal : std::uint8_t {
  none,
  not_defined,  ///< no tool / frame of that name
  bad_name,     ///< the name may not name one (`reason`: check_frame_name's line)
  bad_values,   ///< the pose or payload is out of range (`reason`: check_frame_values's line)
  arm_busy,     ///< the arm moves, jogs, homes or is in free-drive (`arm`), or motions are queued (`queued`)
  active,       ///< delete: it is the active one
  full,         ///< define: kMaxTools / kMaxFrames already
  storage,      ///< the frames file could not be written (`reason`); nothing changed
};
const char* to_string(FrameRefusal r);

/// The answer to a tool or frame request: done (the definition concerned, whether it
/// replaced one, whether it is the active one), or what was refused.
struct FrameResult {
  CmdError error = CmdError::ok;
  FrameRefusal refusal = FrameRefusal::none;
  std::string reason;
  ArmState arm = ArmState::idle;  ///< arm_busy: the arm's state
  std::uint32_t queued = 0;       ///< arm_busy: motions queued
  NamedPose def;                  ///< the tool / frame concerned
  bool redefined = false;         ///< define: it replaced one of that name
  bool active = false;            ///< it is the active one
  bool added = false;             ///< select_frame: a G54..G59 frame not set yet was added (identity)
  bool ok() const { return error == CmdError::ok; }
};

/// What a record request refused (RecordResult::refusal); none: done.
enum class RecordRefusal : std::uint8_t {
  none,
  recording,      ///< start: already recording (`samples` so far)
  not_recording,  ///< path / stop: nothing is recorded
  not_homed,      ///< start: a joint is not homed (`reason` names them)
  bad_value,      ///< start: the rate, path: the tolerance is not a positive finite number
};
const char* to_string(RecordRefusal r);

/// MCAP recording (`record mcap`, mcap_recorder.hpp): where and how big.
struct McapSettings {
  std::string dir;                 ///< the folder the files go to; "" none (recording refused)
  double rate_hz = 100;            ///< state samples per second without rate= (at most the control rate)
  double max_file_mb = 256;        ///< a file reaching this size is closed and the next begun
  int max_files = 0;               ///< files of one recording at most (then it ends); 0 no limit
  std::size_t chunk_kb = 256;      ///< chunk size (also flushed every second: the loss at a power cut)
  int priority = 0;                ///< the recorder thread's SCHED_FIFO priority (below the control thread's); 0 normal
  bool threaded = true;            ///< false: no recorder thread, the caller polls (mcap_poll(); tests on a manual clock)
};

struct McapStatus {
  bool active = false;
  double rate_hz = 0;
  std::string file;                ///< the file being written (the last one after stop)
  std::uint64_t frames = 0;        ///< state samples written
  std::uint64_t missed = 0;        ///< due cycles the control thread could not keep for the recorder (not written)
  std::uint64_t events = 0;
  int files = 0;
  std::uint64_t bytes = 0;         ///< in all files
  std::string error;               ///< why the recording ended on its own ("" none)
};

class McapRecorder;

/// Samples a recording keeps at most (later ones are not taken).
inline constexpr std::size_t kMaxRecordSamples = 100000;

/// The answer to a record request: the rate and samples, and for record_path() the recorded
/// path thinned to the waypoints within `tolerance` of it (SI joints; the first and last
/// sample included), each corner to be blended by `blend` (= tolerance / 2).
struct RecordResult {
  CmdError error = CmdError::ok;
  RecordRefusal refusal = RecordRefusal::none;
  std::string reason;
  double rate_hz = 0;
  std::size_t samples = 0;
  double tolerance = 0, blend = 0;  ///< rad (joint-space distance)
  std::vector<kin::JointVector> waypoints;
  bool ok() const { return error == CmdError::ok; }
};

/// Douglas-Peucker on joint vectors (Euclidean in SI joint space): the indices of the samples
/// kept within `tol` of the polyline, first and last included.
std::vector<std::size_t> decimate(const std::vector<kin::JointVector>& q, double tol);

/// What teach_here() refused (TeachResult::refusal); none: the arm may be taught here.
enum class TeachRefusal : std::uint8_t {
  none,
  program,    ///< a program runs (`program`)
  arm_state,  ///< the arm is not at rest (`arm`; idle, disabled and free-drive are)
  queued,     ///< motions are queued (`queued`)
  not_homed,  ///< a joint is not homed (`reason` names them; the pose is still given)
};
const char* to_string(TeachRefusal r);

/// The answer to teach_here(): where the arm is (SI joints, the active tool's pose in the base
/// frame, the active tool and frame), or why it may not be taught now. The front end keeps the
/// point (a points file, by name).
struct TeachResult {
  CmdError error = CmdError::ok;
  TeachRefusal refusal = TeachRefusal::none;
  std::string reason;
  ArmState arm = ArmState::idle;
  std::uint32_t queued = 0;
  ProgramStatus program;
  kin::JointVector q;
  kin::Pose pose = kin::Pose::Identity();
  std::string tool, frame;
  bool ok() const { return error == CmdError::ok; }
};

/// What a teach-point request refused (PointResult::refusal); none: done.
enum class PointRefusal : std::uint8_t {
  none,
  not_here,     ///< teach: the arm may not be taught now (`here` says why: teach_here's refusal)
  bad_point,    ///< teach: the name or the values may not be stored, or the points are full (`reason`: put_point's line)
  no_point,     ///< delete, go-to: no point of that name (`count` points)
  joint_count,  ///< go-to: the point has `joints` joints, not the arm's
  program,      ///< delete: a program runs (`here.program`)
  storage,      ///< the points file could not be written (`reason`); nothing changed
};
const char* to_string(PointRefusal r);

/// Teach a point (ArmService::teach): the arm's joints now, under `name`, with the pose and
/// names of `tool` / `frame` (indices; the count of tools / frames: the active one); `dry`:
/// checked only (nothing stored, no file written).
struct TeachRequest {
  std::string name;
  std::size_t tool = static_cast<std::size_t>(-1);
  std::size_t frame = static_cast<std::size_t>(-1);
  bool dry = false;
};

/// Go to a point (ArmService::move_to_point): a joint move to its joints, or (`line`) a
/// straight line to where its joints put the tool of the context's chain; speed and blend as
/// in MoveJoints (percent) / MoveLine (m/s), SI.
struct PointMove {
  std::string name;
  bool line = false;
  double speed = -1;   ///< joint: percent of the joint limits; line: m/s; <= 0: the default
  double blend = -1;   ///< rad (joint) / m (line); < 0: the default
};

/// The answer to a teach-point request: the point concerned, or what was refused.
struct PointResult {
  CmdError error = CmdError::ok;
  PointRefusal refusal = PointRefusal::none;
  std::string reason;
  TeachResult here;             ///< teach, delete: the arm's place and state (teach_here())
  prog::TeachPoint point;       ///< the point taught, deleted or gone to
  bool replaced = false;        ///< teach: a point of that name was replaced
  bool kept = false;            ///< the change is in the points file (false: no points file)
  std::size_t count = 0;        ///< points after the request
  int joints = 0;               ///< joint_count: the point's
  MoveResult move;              ///< go-to: the move's result (refusal none: the point was found)
  bool ok() const { return error == CmdError::ok; }
};

/// Every request the service takes, by one name each: a front end that speaks in messages
/// (a network API) maps one message to one of these; `query` ones read and change nothing.
/// kServiceOps lists each once, in this order (a test checks): the names live there only.
enum class ServiceOp : std::uint8_t {
  move_joints,          ///< move(MoveJoints) -> MoveResult
  move_line,            ///< move(MoveLine) -> MoveResult
  dwell,                ///< dwell(s) -> MoveResult
  park,                 ///< move(park_request()) -> MoveResult
  enable,               ///< enable() -> ControlResult
  disable,              ///< control(disable)
  stop,                 ///< control(stop)
  estop,                ///< control(estop)
  reset,                ///< control(reset)
  hold,                 ///< hold() -> ControlResult (a running program pauses with it)
  resume,               ///< resume() -> ControlResult (a paused program runs on)
  set_zero,             ///< control(set_zero)
  home,                 ///< home(joint) -> ControlResult
  freedrive,            ///< freedrive(on) -> ControlResult
  collision_detection,  ///< collision_detection(on) -> ControlResult
  jog_joint,            ///< jog(JointJog) -> JogResult
  jog_tool,             ///< jog(ToolJog) -> JogResult
  jog_pose,             ///< jog(PoseJog) -> JogResult
  jog_keepalive,        ///< jog_keepalive() -> ControlResult
  jog_cancel,           ///< jog_cancel() -> ControlResult
  set_output,           ///< set_output(OutputRequest) -> OutputResult
  events,               ///< events_since(seq) -> EventBatch
  status,               ///< status() -> ArmStatus
  limits,               ///< arm_limits() -> ArmLimits
  settings,             ///< settings() -> MotionSettings
  set_settings,         ///< set_settings(MotionSettings) -> SettingsResult
  set_feed_override,    ///< set_feed_override(pct) -> SettingsResult
  program_run,          ///< run_program(ProgramSpec, StepExecutor) -> ProgramResult
  program_pause,        ///< program_pause() -> ProgramResult
  program_step,         ///< program_step() -> ProgramResult
  program_abort,        ///< program_abort() -> ProgramResult
  program_status,       ///< program_status() -> ProgramStatus
  tools,                ///< tool_count() / tool(i) / active_tool()
  tool_select,          ///< select_tool(name) -> FrameResult
  tool_define,          ///< define_tool(NamedPose) -> FrameResult
  tool_delete,          ///< delete_tool(name) -> FrameResult
  frames,               ///< frame_count() / frame(i) / active_frame()
  frame_select,         ///< select_frame(name) -> FrameResult
  frame_define,         ///< define_frame(NamedPose) -> FrameResult
  frame_delete,         ///< delete_frame(name) -> FrameResult
  record_start,         ///< record_start(rate) -> RecordResult
  record_stop,          ///< record_path(tolerance), then record_stop() -> RecordResult
  teach_here,           ///< teach_here() -> TeachResult
  points,               ///< points() -> the teach points
  point_teach,          ///< teach(TeachRequest) -> PointResult
  point_delete,         ///< delete_point(name, dry) -> PointResult
  point_move,           ///< move_to_point(PointMove, MoveContext) -> PointResult
  safety_mode,          ///< set_safety_mode(mode, confirm) -> ControlResult (Normal / Reduced)
  safety_stage,         ///< stage_safety(changes) -> SafetyChangeResult
  safety_confirm,       ///< confirm_safety(checksum) -> SafetyChangeResult
};

struct ServiceOpInfo {
  ServiceOp op;
  const char* name;
  bool query;  ///< reads only: never changes the arm, the queue or the service
};
inline constexpr ServiceOpInfo kServiceOps[] = {
    {ServiceOp::move_joints, "move_joints", false},
    {ServiceOp::move_line, "move_line", false},
    {ServiceOp::dwell, "dwell", false},
    {ServiceOp::park, "park", false},
    {ServiceOp::enable, "enable", false},
    {ServiceOp::disable, "disable", false},
    {ServiceOp::stop, "stop", false},
    {ServiceOp::estop, "estop", false},
    {ServiceOp::reset, "reset", false},
    {ServiceOp::hold, "hold", false},
    {ServiceOp::resume, "resume", false},
    {ServiceOp::set_zero, "set_zero", false},
    {ServiceOp::home, "home", false},
    {ServiceOp::freedrive, "freedrive", false},
    {ServiceOp::collision_detection, "collision_detection", false},
    {ServiceOp::jog_joint, "jog_joint", false},
    {ServiceOp::jog_tool, "jog_tool", false},
    {ServiceOp::jog_pose, "jog_pose", false},
    {ServiceOp::jog_keepalive, "jog_keepalive", false},
    {ServiceOp::jog_cancel, "jog_cancel", false},
    {ServiceOp::set_output, "set_output", false},
    {ServiceOp::events, "events", true},
    {ServiceOp::status, "status", true},
    {ServiceOp::limits, "limits", true},
    {ServiceOp::settings, "settings", true},
    {ServiceOp::set_settings, "set_settings", false},
    {ServiceOp::set_feed_override, "set_feed_override", false},
    {ServiceOp::program_run, "program_run", false},
    {ServiceOp::program_pause, "program_pause", false},
    {ServiceOp::program_step, "program_step", false},
    {ServiceOp::program_abort, "program_abort", false},
    {ServiceOp::program_status, "program_status", true},
    {ServiceOp::tools, "tools", true},
    {ServiceOp::tool_select, "tool_select", false},
    {ServiceOp::tool_define, "tool_define", false},
    {ServiceOp::tool_delete, "tool_delete", false},
    {ServiceOp::frames, "frames", true},
    {ServiceOp::frame_select, "frame_select", false},
    {ServiceOp::frame_define, "frame_define", false},
    {ServiceOp::frame_delete, "frame_delete", false},
    {ServiceOp::record_start, "record_start", false},
    {ServiceOp::record_stop, "record_stop", false},
    {ServiceOp::teach_here, "teach_here", true},
    {ServiceOp::points, "points", true},
    {ServiceOp::point_teach, "point_teach", false},
    {ServiceOp::point_delete, "point_delete", false},
    {ServiceOp::point_move, "point_move", false},
    {ServiceOp::safety_mode, "safety_mode", false},
    {ServiceOp::safety_stage, "safety_stage", false},
    {ServiceOp::safety_confirm, "safety_confirm", false},
};
const char* to_string(ServiceOp op);
/// The op named `name` (kServiceOps); false: none is.
bool service_op_from(std::string_view name, ServiceOp& op);

class ArmService {
 public:
  /// Real runs and dry runs on the controller's arm.
  ArmService(Controller& ctl, const MotionSettings& cfg);
  /// Dry runs only (no controller: `armctl program check`): the arm's chain, limits and rate.
  ArmService(const kin::Chain& chain, const kin::JointLimits& limits, double rate_hz, const MotionSettings& cfg);
  ~ArmService();
  ArmService(const ArmService&) = delete;
  ArmService& operator=(const ArmService&) = delete;

  /// Plan, check and (real run) queue a move or a dwell.
  MoveResult move(const MoveJoints& req, const MoveContext& cx);
  MoveResult move(const MoveLine& req, const MoveContext& cx);
  MoveResult dwell(double seconds, const MoveContext& cx);

  /// Send a request to the control thread and wait for its reply (at most `reply_timeout_s`,
  /// passing time with the idle hook). False: no reply in time. A full request queue is
  /// answered busy at once.
  bool request(const Request& rq, Reply& out);
  bool request(RequestOp op, Reply& out);
  /// Arm control: one request (disable, stop, estop, reset, hold, set_zero, ...), its reply
  /// as a result (`control thread did not answer <op>` on a timeout).
  ControlResult control(RequestOp op);
  /// `enable`: accepted (the drives are enabling), or why not (fault, else bad_state).
  ControlResult enable();
  /// The homing cycle of joint `joint` (0-based; -1: every joint): started, or why not (busy,
  /// fault, else bad_state). Progress comes as homing events.
  ControlResult home(int joint);
  /// Free-drive (hand guiding) on or off: done, or why not (the dynamic model's refusal whole).
  ControlResult freedrive(bool on);
  /// Collision detection on or off: done (reason "collision detection on|off"), or why not.
  ControlResult collision_detection(bool on);
  /// Jogs (jog.hpp runs them on the control thread; the service computes the targets from
  /// where the running jog ends, or the commanded position).
  JogResult jog(const JointJog& rq, const JogContext& cx);
  JogResult jog(const ToolJog& rq, const JogContext& cx);
  JogResult jog(const PoseJog& rq, const JogContext& cx);
  /// Where a pose jog given in `frame` starts: the running jog's target, else the commanded pose.
  kin::Pose jog_from(JogFrame frame, const JogContext& cx) const;
  /// Keep a continuous jog alive; end the running jog.
  ControlResult jog_keepalive() { return control(RequestOp::jog_keepalive); }
  ControlResult jog_cancel();
  /// Forget where the running jog ends (the next jog starts from the commanded position).
  void jog_forget() { jog_.valid = false; }
  /// Digital outputs: set one (typed result), read one (as the drive is sent it), and the
  /// M62 / M63 changes waiting for the next move (a queued move carries and clears them).
  OutputResult set_output(const OutputRequest& rq);
  std::size_t output_count() const { return cfg_.outputs.size(); }
  bool output_on(std::size_t index) const;
  std::span<const OutputChange> pending_outputs() const { return {sync_out_.data(), n_sync_out_}; }
  void clear_pending_outputs() { n_sync_out_ = 0; }
  /// The park move (`park`, G28): to the park pose at the default joint speed.
  MoveJoints park_request() const;

  /// Hold: the arm holds (a move decelerates and stays held, a jog stops) and a running
  /// program pauses. Resume: the arm resumes and a paused program runs on (one still
  /// pausing too, unless `end_pause` is false: GRBL's cycle start resumes a hold only).
  ControlResult hold();
  ControlResult resume(bool end_pause = true);

  /// Programs (the runner): run a loaded program whose steps the front end runs (`exec`),
  /// fed one motion ahead of the running one. The arm must be at rest, nothing queued,
  /// every joint homed. A step refused, a fault, an e-stop, the arm disabled, jogging,
  /// homing or in free-drive, or the queue dropped ends it (a program event says how).
  ProgramResult run_program(ProgramSpec spec, StepExecutor exec);
  /// Run a loaded program's typed steps (the parser made them once) on the service itself, no
  /// front end in between: each step becomes its request in SI (`units`: the program's, for its
  /// numbers; G-code files in mm and degrees) with its blend tolerance, teach point and whether
  /// the next motion is a line. A refused step ends the program with its typed CmdError.
  ProgramResult run_program(const std::string& name, prog::Program p, const ConsoleUnits& units);
  /// Run step `i` of `p` now (what run_program feeds): ok, or the step's error and one line.
  StepOutcome run_step(const prog::Program& p, std::size_t i, const ConsoleUnits& units);
  /// The runner's view of a loaded program (each step's class and place).
  static ProgramSpec spec_of(const std::string& name, const prog::Program& p);
  /// Pause (nothing more is fed; paused once the queued motions are done), step (a paused
  /// program runs one motion, a held move is resumed first), abort (ended now and the arm
  /// stopped; `why` says how it ends: abort, or a front end's stop / e-stop / disable /
  /// soft reset already asked).
  ProgramResult program_pause();
  ProgramResult program_step();
  ProgramResult program_abort(ProgramEnd why = ProgramEnd::abort, bool realtime = false);
  ProgramStatus program_status() const;
  /// Check a whole loaded program without running it: each step through the dry run of what
  /// run_step() does (the same planning and checks, from where the motion queue ends; tool and
  /// frame selections followed), nothing queued or changed. A tool or frame definition is not
  /// made by a check: the moves after it are not planned (`planned`). ok with its counts and
  /// planned time, or the first step refused (program_check.cpp).
  ProgramCheckResult check_program(const prog::Program& p, const ConsoleUnits& units);
  RunState run_state() const;
  /// Feed the running program's next steps; notice its end, a hold, a fault. The front end
  /// calls it regularly (the console from its poll). Never blocks.
  void program_tick();
  /// A program event's names (empty when the event is no longer kept or is no program event).
  ProgramNames event_program(const ArmEvent& e) const;

  /// Tools and user frames (frames.hpp). [0] is tool0 (the flange) / base and is always
  /// there. A tool's chain is the arm's with its TCP appended (with its own IK model when
  /// the arm has one); queued Cartesian moves and jogs point at it, so tools and frames
  /// change only while nothing moves, jogs or is queued. Each change is saved to the frames
  /// file (set_frames_file; "" keeps them in memory only) before it is answered.
  /// `ik`: the arm's IK model (the caller's, outliving the service; nullptr: numeric fallback).
  void set_ik_model(const kin::IkModel* ik);
  /// Load the tools and frames of `path` ("": none, in memory only). "" or the one-line
  /// error (file:line:column); on error nothing is loaded.
  std::string load_frames(const std::string& path);
  const std::string& frames_file() const { return frames_file_; }
  std::size_t tool_count() const { return tools_.size(); }
  const NamedPose& tool(std::size_t i) const { return tools_[i]->def; }
  const kin::Chain& tool_chain(std::size_t i) const { return tools_[i]->chain; }
  kin::IkSolver tool_ik(std::size_t i) const;
  const kin::IkModel* tool_model(std::size_t i) const { return tools_[i]->model; }  ///< nullptr: numeric fallback
  std::size_t active_tool() const { return tool_; }
  std::size_t frame_count() const { return frames_.size(); }
  const NamedPose& frame(std::size_t i) const { return frames_[i]; }
  std::size_t active_frame() const { return frame_; }
  /// The index of the tool / frame called `name`; the count when there is none.
  std::size_t find_tool(std::string_view name) const;
  std::size_t find_frame(std::string_view name) const;
  FrameResult select_tool(std::string_view name);
  FrameResult define_tool(const NamedPose& def);
  FrameResult delete_tool(std::string_view name);
  /// `add_identity`: a frame not defined yet is added as the identity (G54..G59 before G10 set it).
  FrameResult select_frame(std::string_view name, bool add_identity = false);
  FrameResult define_frame(const NamedPose& def);
  FrameResult delete_frame(std::string_view name);
  /// arm_busy when tools and frames may not change now, else ok.
  FrameResult frames_check() const;

  /// Record: sample the measured joints at `rate_hz` (the arm moved by jogs or by hand)
  /// from now on; record_path(): the path so far (the arm's position now its last sample)
  /// thinned within `tolerance`, still recording; record_stop(): end it (the samples are
  /// dropped). The front end keeps the path (as a program) between the two.
  RecordResult record_start(double rate_hz);
  RecordResult record_path(double tolerance);
  RecordResult record_stop();
  bool recording() const { return rec_.active; }
  /// MCAP recording (mcap_recorder.hpp): the telemetry at `rate_hz` (up to the control rate),
  /// the setpoints, the events and the robot description into files in settings().dir.
  /// Start: "" or why not (no folder, a rate out of range, already recording); stop: the
  /// recording's figures (files, frames, missed cycles), error bad_state when none runs.
  /// `threaded` false (or the settings' `threaded` false): the caller polls (mcap_poll(); tests
  /// on a manual clock). mcap_poll() polls only such a recording: a recorder thread is the only
  /// writer of its file.
  void set_mcap_settings(const McapSettings& s) { mcap_cfg_ = s; }
  const McapSettings& mcap_settings() const { return mcap_cfg_; }
  std::string record_mcap_start(double rate_hz, bool threaded = true);
  McapStatus record_mcap_stop();
  McapStatus mcap_status() const;
  void mcap_poll();
  std::size_t record_samples() const { return rec_.samples.size(); }
  /// The service's periodic work on the console thread: a record sample when one is due,
  /// then program_tick(). Never blocks.
  void tick();

  /// Teach: where the arm is now and whether it may be taught there (no program runs, the
  /// arm at rest with nothing queued, every joint homed). A query: the front end keeps the
  /// point and goes back to it with a MoveJoints to its joints.
  TeachResult teach_here() const;

  /// Teach points (program/points.hpp), kept in the points file (set by load_points; "" keeps
  /// them in memory only) before a change is answered: a change the file refuses is not made.
  /// load_points: "" or the file's one-line error (nothing loaded; a missing file: no points).
  std::string load_points(const std::string& path);
  const std::string& points_file() const { return points_file_; }
  const prog::PointsData& points() const { return points_; }
  /// Store the arm's place as point `rq.name` (refused as teach_here() refuses, except that a
  /// dry run may teach an unhomed arm: it stores nothing).
  PointResult teach(const TeachRequest& rq);
  /// Delete point `name` (not while a program runs); `dry`: checked only.
  PointResult delete_point(std::string_view name, bool dry = false);
  /// Move to point `rq.name` (move(), real or dry run as `cx` says).
  PointResult move_to_point(const PointMove& rq, const MoveContext& cx);

  /// Switch the safety envelope's mode (docs/safety.md): the planning checks of the moves
  /// queued from now on and the control thread's monitor (from its next cycle) use the
  /// mode's limits. Refused (bad_state, one line) when no envelope is configured, and from
  /// Reduced to Normal (which loosens the limits) unless `confirm` (the operator's explicit
  /// confirmation: console `safety normal confirm`, the API's safety_mode confirm=true); a
  /// switch to Reduced, the stricter mode, never needs it. The console and the API call this.
  ControlResult set_safety_mode(kin::SafetyMode mode, bool confirm = false);
  /// A tool's safety sphere radius (m): its radius=, else safety.tool_radius_mm.
  double tool_radius(const NamedPose& def) const { return def.radius >= 0 ? def.radius : cfg_.safety.tool_radius; }
  kin::SafetyMode safety_mode() const { return safety_mode_; }
  /// Set-up: what turns a change of [safety] into a proposal (the App: the key table's checks);
  /// unset, stage_safety() refuses.
  void set_safety_stager(SafetyStager s) { stager_ = std::move(s); }
  /// Seconds a staged change waits for its confirmation (60 unless set: tests).
  void set_safety_confirm_window(double s) { safety_window_s_ = s; }
  /// A run-time change of [safety], first step: checked and staged, nothing changes; the answer
  /// carries the checksum the configuration will have, which confirm_safety() must repeat
  /// within the confirmation window. A new stage replaces the one staged.
  SafetyChangeResult stage_safety(const std::string& changes);
  /// Second step: applies the staged change when `checksum` is its checksum, it has not expired
  /// and the arm is at rest (not moving, jogging, homing, stopping or in free-drive): the moves
  /// planned from then on and the monitor from its next cycle use it. Refused in one line
  /// otherwise (nothing staged, another checksum, expired, the arm moving); a refusal because
  /// of another checksum or an expiry drops the staged change.
  SafetyChangeResult confirm_safety(std::uint32_t checksum);
  /// The mode moves are planned and checked in: Reduced while the controller's Reduced input is
  /// asserted (Controller::reduced_by_input), else safety_mode().
  kin::SafetyMode plan_safety_mode() const {
    return ctl_ != nullptr && ctl_->reduced_by_input() ? kin::SafetyMode::reduced : safety_mode_;
  }
  /// One streamed target against the envelope (envelope_violation_at with the service's
  /// envelope and mode, the arm's chain unless `chain` is given): "" or the refusal's line.
  std::string check_target(const kin::JointVector& q_prev, const kin::JointVector& q, double dt,
                           const kin::Chain* chain = nullptr) const;

  /// Queries: they read and change nothing.
  ArmStatus status() const;
  ArmLimits arm_limits() const;
  const MotionSettings& settings() const { return cfg_; }
  int feed_override() const { return feed_pct_; }
  /// Settings: all of them at once (checked whole: nothing changes when one is refused; the
  /// outputs are fixed at start), and the feed override (percent, kMinFeedOverride..
  /// kMaxFeedOverride): scales jogs and the moves queued from now on.
  SettingsResult set_settings(const MotionSettings& s);
  SettingsResult set_feed_override(int pct);
  /// How to pass time while waiting for the control thread (default: sleep 200 us).
  void set_idle(std::function<void()> idle) { idle_ = std::move(idle); }

  /// Take every event the control thread has sent into the event ring (numbered and stamped).
  /// Returns how many. The service is the queue's one consumer: nothing else pops it.
  std::size_t poll_events();
  /// The events with a sequence number above `seq` (0: from the first kept), oldest first,
  /// and how many of those are no longer kept. A reader passes the last seq it got.
  EventBatch events_since(std::uint64_t seq) const;
  /// The control thread's one line for event `e` (fault text, homing progress, why a jog
  /// stopped; no units of the service's); empty when the event is no longer kept.
  std::string_view event_detail(const ArmEvent& e) const;
  /// The sequence number the next event gets.
  std::uint64_t next_event_seq() const { return next_seq_; }

  /// The result of the last move or dwell asked (either mode).
  const MoveResult& last() const { return last_; }
  /// Real run: arm_state when the arm takes no moves now (reason set), else ok.
  MoveResult state_check() const;
  /// Real run: "" when every joint is homed, else which are not (one line).
  std::string unhomed_reason() const;
  /// The same, of telemetry `t`.
  std::string unhomed_reason(const Telemetry& t) const;
  /// Joint values of the end of the motion queue (or the commanded position).
  kin::JointVector tail() const;
  /// The tool path a queued move was planned with (kept for the last kPlannedPaths moves):
  /// the tool point of the move's tool in the base frame (m), kPlannedPathSamples points
  /// evenly spaced in time along its plan, from where it starts to its goal. A viewer draws it
  /// (the pendant's 3D view); nullptr when motion `id` is a dwell or no longer kept.
  struct PlannedPath {
    std::uint32_t id = 0;
    MotionKind kind = MotionKind::joint;
    std::string tool;     ///< the tool whose point it is
    double duration = 0;  ///< s, the plan's (a blended segment: alone, from rest)
    std::vector<Eigen::Vector3d> points;
  };
  static constexpr std::size_t kPlannedPaths = 64;
  static constexpr int kPlannedPathSamples = 48;
  const PlannedPath* planned_path(std::uint32_t id) const;
  /// Motions queued so far (ids 1..n).
  std::uint32_t last_motion_id() const { return next_id_ - 1; }
  const kin::JointLimits& limits() const { return lim_; }

 private:
  void init();
  MoveResult plan(const MoveJoints& req, const MoveContext& cx);
  MoveResult plan(const MoveLine& req, const MoveContext& cx);
  MoveResult plan_dwell(double seconds, const MoveContext& cx);
  void keep_planned_path(const MotionItem& m, const kin::Chain& chain);
  MotionItem* slot(bool dry, MoveResult& r);
  bool duration_ok(double duration, MoveResult& r) const;
  MoveResult refuse(MoveRefusal what, CmdError e) const;
  /// The move as a blended path segment into m's payload (dry run: only checked); false: the plain move.
  bool path_segment(MotionItem& m, bool line, const kin::JointVector& goal, const kin::Pose& target,
                    const kin::CartesianLimits& cl, double override, double tol, const MoveContext& cx, MoveResult& r);
  double blend_of(double given, bool line, const MoveContext& cx) const;
  void commit(MotionItem& m, const kin::JointVector& goal, const MoveContext& cx, MoveResult& r, bool path);

  Controller* ctl_ = nullptr;
  const kin::Chain& chain_;
  kin::JointLimits lim_;
  double rate_hz_;
  MotionSettings cfg_;
  int n_;
  std::uint32_t next_id_ = 1;
  kin::JointVector tail_;
  std::uint32_t tail_id_ = 0;   ///< id of the motion whose goal tail_ holds (0: none)
  std::uint64_t tail_gen_ = 0;  ///< controller generation when tail_ was set
  std::unique_ptr<PathShadow> shadow_;  ///< the real run's blended segments (the controller runs copies)
  std::uint32_t shadow_tail_id_ = 0;    ///< the motion the newest segment was queued as (0: none)
  std::unique_ptr<MotionItem> scratch_;  ///< a dry run's motion (planned, never queued)
  kin::SafetyMode safety_mode_ = kin::SafetyMode::normal;
  SafetyStager stager_;
  std::unique_ptr<SafetyProposal> staged_;  ///< the change waiting for confirm_safety
  double staged_until_ = 0;                 ///< steady clock, s
  double safety_window_s_ = 60.0;
  /// The envelope check of a planned motion whose joints at time t (0..duration) `at` gives:
  /// true when inside; false with r refused (limits, the violation's line in r.reason).
  /// `violation` (optional): the function found; `speed_ratio` (optional): the highest
  /// kin::speed_ratio (speeds, stop limits, momentum, power) along the whole path.
  bool envelope_ok(const kin::Chain& chain, double duration, const std::function<bool(double, kin::JointVector&)>& at,
                   const char* what, MoveResult& r, kin::SafetyViolation* violation = nullptr,
                   double* speed_ratio = nullptr) const;
  /// A jog step's path (joints at the fraction s in 0..1 from `at`) against the envelope,
  /// positions and orientation only (a jog's speed is the jog's): "" or the violation's line.
  std::string jog_envelope(const kin::Chain& chain, const std::function<bool(double, kin::JointVector&)>& at) const;
  /// The envelope a move with `chain` (a tool's chain, or chain_: tool0) is checked against:
  /// the configured one with that tool's sphere radius (its radius=, else safety.tool_radius_mm).
  kin::SafetyConfig envelope_for(const kin::Chain& chain) const;
  /// The active tool to the control thread's monitor (Controller::set_safety_tool).
  void push_safety_tool();
  /// A tool jog's straight line from pose `a` to `b` (IK along it from `seed`): as jog_envelope.
  std::string jog_envelope_line(const kin::Chain& chain, const kin::Pose& a, const kin::Pose& b,
                                const kin::JointVector& seed, const kin::IkSolver& ik) const;
  MoveResult last_;
  std::deque<PlannedPath> paths_;  ///< the last kPlannedPaths moves' tool paths, oldest first
  std::uint32_t seq_ = 0;  ///< request sequence numbers (replies are matched by them)
  std::array<OutputChange, kMotionOutputs> sync_out_{};  ///< M62 / M63 changes for the next move (one per joint, merged)
  std::uint8_t n_sync_out_ = 0;
  /// Where the running jog ends (its target), to add the next increment to.
  struct JogTail {
    bool valid = false;
    bool tool = false;
    kin::JointVector q;
    kin::Pose pose = kin::Pose::Identity();
    Eigen::Matrix3d axes = Eigen::Matrix3d::Identity();
    JogFrame frame = JogFrame::base;
  } jog_;
  JogSpec tool_spec(double pct, const JogContext& cx) const;
  double jog_pct(double speed_pct, int feed_pct) const;
  kin::JointVector commanded() const;
  kin::Pose commanded_pose(const JogContext& cx) const;
  bool jog_duration_ok(double duration, JogResult& r) const;
  JogResult send_jog(const JogSpec& js);
  struct EventSlot {
    ArmEvent ev;
    char detail[sizeof(Event::message)] = {};
    std::string program, file;  ///< program events: the names
  };
  EventSlot& push_event();
  struct ProgramRun {
    ProgramSpec spec;
    StepExecutor exec;
    std::size_t next = 0;       ///< next step to feed
    std::size_t current = 0;    ///< step of the running motion (or the last fed)
    RunState state = RunState::running;
    bool waiting = false;       ///< a `wait` step waits for the queue to run empty
    bool step_fed = false;      ///< stepping: the one motion has been fed
    std::deque<std::pair<std::uint32_t, std::size_t>> fed;  ///< motion id -> step, not finished yet
    std::size_t reported = static_cast<std::size_t>(-1);    ///< the step the last step event named
    std::uint64_t generation = 0;
    std::uint64_t started_cycle = 0;
  };
  std::unique_ptr<ProgramRun> run_;
  bool ticking_ = false;  ///< program_tick() runs (no re-entry: the run may end inside it)
  std::size_t where_step() const;
  void post_program(ProgramPhase phase, std::size_t step, ProgramEnd end = ProgramEnd::none);
  void end_program(ProgramEnd how, std::size_t step, bool realtime = false, CmdError error = CmdError::ok,
                   std::string_view detail = {});
  bool program_ended_by_arm(const Telemetry& t);
  bool feed_program();
  FrameResult step_frame(const fw::Command& c, const ConsoleUnits& u);
  MoveResult step_move(const prog::Program& p, const prog::ProgramStep& st, const ConsoleUnits& u, const MoveContext& cx);
  std::unique_ptr<std::array<EventSlot, kEventRing>> ring_;  ///< slot seq % kEventRing
  std::uint64_t next_seq_ = 1;
  std::function<void()> idle_;
  int feed_pct_ = 100;
  struct Recording {
    bool active = false;
    double rate_hz = 50;
    std::uint64_t last_cycle = 0;
    std::vector<kin::JointVector> samples;
  } rec_;
  void record_sample();
  McapSettings mcap_cfg_;
  std::unique_ptr<McapRecorder> mcap_;
  std::uint64_t mcap_seq_ = 0;  ///< the last event handed to the recorder
  void mcap_events();
  // Tools and user frames (tools_frames.cpp). unique_ptr: stable chain addresses.
  struct ToolSlot {
    NamedPose def;
    kin::Chain chain;
    std::unique_ptr<kin::IkModel> own;
    const kin::IkModel* model = nullptr;  ///< own.get(), ik_ for tool0, nullptr: numeric fallback
  };
  /// "" or why tool `t` contradicts the envelope (one line, without the tool's name): its
  /// sphere wider than a keep-in box, or the park pose outside the planes and boxes with its
  /// TCP and sphere.
  std::string tool_envelope_problem(const ToolSlot& t) const;
  std::vector<std::unique_ptr<ToolSlot>> tools_;
  std::vector<NamedPose> frames_;
  std::size_t tool_ = 0, frame_ = 0;
  std::string frames_file_;
  prog::PointsData points_;
  std::string points_file_;
  PointResult store_points(prog::PointsData d, PointResult r);
  const kin::IkModel* ik_ = nullptr;
  std::unique_ptr<ToolSlot> make_tool(const NamedPose& def) const;
  std::string save_frames() const;
  FrameResult named(bool tool, std::string_view name) const;
  int feed_of(int given) const { return given < 0 ? feed_pct_ : given; }
};

}  // namespace servoarm::fw
