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
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "servoarm/kinematics/blend_path.hpp"
#include "servoarm/kinematics/ik.hpp"
#include "servoarm/kinematics/trajectory.hpp"
#include "servoarm/lang/commands.hpp"
#include "servoarm/lang/requests.hpp"
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
  int feed_pct = 100;               ///< feed override (10..200): scales the speed of the move
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

/// The error code of a control-thread result.
CmdError control_error(RtResult r);

/// A digital output ([[output]]): bit `bit` of joint `joint`'s drive outputs word.
struct OutputBit {
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

/// The service's motion settings (SI): the console's configuration of them.
struct MotionSettings {
  double default_joint_speed_pct = 50.0;
  double default_linear_speed = 0.1;   ///< m/s
  double max_linear_speed = 0.25;      ///< m/s
  double max_move_duration_s = 600.0;
  kin::CartesianLimits cartesian{};    ///< linear_velocity is replaced per move
  double default_blend_rad = 0.0;      ///< movej without blend=
  double default_blend_m = 0.0;        ///< movel, G0/G1 without blend=
  kin::JointVector park;               ///< the park pose (SI); empty: every joint's zero clamped into its limits
  double jog_speed_pct = 10.0;         ///< jog speed without one given: percent of the joint / tool limits
  double jog_deadman_s = 0.25;         ///< a continuous jog not refreshed this long stops
  std::vector<OutputBit> outputs;      ///< the digital outputs, in [[output]] order
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
  int feed_pct = 100;
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

/// One event of the arm's event stream: figures only, no text (the control thread's own line
/// for it, when it sent one, is ArmService::event_detail).
struct ArmEvent {
  std::uint64_t seq = 0;        ///< 1, 2, 3, ...: one more than the event before it
  std::uint64_t cycle = 0;      ///< RT time stamp: the control cycle (Telemetry::cycles) the service took it at
  double t = 0;                 ///< the same in s (cycle times the control period)
  EventKind kind = EventKind::state;
  ArmState state = ArmState::boot;  ///< the arm's state when the control thread sent it
  FaultCause cause = FaultCause::none;  ///< fault: the cause
  std::int8_t joint = -1;       ///< the joint concerned (0-based), -1 none or every joint
  std::uint32_t motion_id = 0;  ///< motion_done / motion_refused: the motion (0 none)
};

/// Events the service keeps for its readers (the oldest is overwritten first).
inline constexpr std::size_t kEventRing = 256;

/// The answer to events_since(seq): the events after it still kept, oldest first.
struct EventBatch {
  std::vector<ArmEvent> events;
  std::uint64_t missed = 0;  ///< events after `seq` no longer kept (overwritten before this read)
};

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
  /// How to pass time while waiting for the control thread (default: sleep 200 us).
  void set_idle(std::function<void()> idle) { idle_ = std::move(idle); }
  void set_reply_timeout(double s) { reply_timeout_s_ = s; }

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
  /// Motions queued so far (ids 1..n).
  std::uint32_t last_motion_id() const { return next_id_ - 1; }
  const MotionSettings& settings() const { return cfg_; }
  const kin::JointLimits& limits() const { return lim_; }

 private:
  void init();
  MoveResult plan(const MoveJoints& req, const MoveContext& cx);
  MoveResult plan(const MoveLine& req, const MoveContext& cx);
  MoveResult plan_dwell(double seconds, const MoveContext& cx);
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
  MoveResult last_;
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
  };
  std::unique_ptr<std::array<EventSlot, kEventRing>> ring_;  ///< slot seq % kEventRing
  std::uint64_t next_seq_ = 1;
  std::function<void()> idle_;
  double reply_timeout_s_ = 1.0;
};

}  // namespace servoarm::fw
