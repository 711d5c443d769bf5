// SPDX-License-Identifier: Apache-2.0
#pragma once
// What the controller and the console threads exchange: requests and replies,
// queued motions, events and the telemetry snapshot (controller.hpp has the queues).
#include <array>
#include <cstdint>
#include <variant>

#include "servoarm/rt/jog.hpp"
#include "servoarm/rt/mode_table.hpp"
#include "servoarm/rt/stats.hpp"
#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/trajectory.hpp"
#include "servoarm/kinematics/blend_path.hpp"
#include "servoarm/kinematics/trajectory_cartesian.hpp"

namespace servoarm::fw {

/// Why the supervisor faulted (one per cause; the joint is reported alongside).
enum class FaultCause : std::uint8_t {
  none,
  heartbeat_lost,     ///< no heartbeat within the consumer time
  drive_fault,        ///< drive reports fault (EMCY or statusword)
  drive_refused,      ///< drive did not reach operation enabled in time
  left_enabled,       ///< drive left operation enabled on its own
  emcy,               ///< EMCY frame received
  bus_off,            ///< CAN controller bus-off / bus write failed
  bus_error,          ///< other bus/servo error
  following_error,    ///< |commanded - actual| above the limit
  setpoint_nan,       ///< motion produced a non-finite setpoint
  setpoint_position,  ///< setpoint outside the joint position limits
  setpoint_velocity,  ///< setpoint step faster than the joint velocity limit
  feedback_invalid,   ///< no (or stale) position feedback from an enabled joint
  homing_failed,      ///< a joint's homing failed (timeout, homing error, refused): the arm is disabled
  collision,          ///< the collision observer's residual on a joint above its threshold
  over_temperature,   ///< a drive's reported temperature at or above its limit (JointFeedback::temperature_limit)
  joint_limit,        ///< free-drive: the hand carried a joint past its position limit
};
const char* to_string(FaultCause c);

/// Result codes of requests and motions as seen by the console.
enum class RtResult : std::uint8_t {
  ok,
  bad_state,   ///< not allowed in the current state (message says which)
  fault,       ///< refused: arm in fault / e-stop (needs reset)
  busy,        ///< queue full
  start_moved, ///< a planned Cartesian move no longer starts where the arm is
  plan_failed, ///< the RT-side plan of a joint move failed
  not_homed,   ///< refused: a joint is not homed (its zero not established this power cycle)
};
const char* to_string(RtResult r);

struct Request {
  RequestOp op = RequestOp::stop;
  std::uint32_t seq = 0;
  JogSpec jog;  ///< RequestOp::jog: what to jog (SI)
  std::uint16_t joints = 0;  ///< RequestOp::home: bit j = joint j, as one group; 0 = every joint by the homing order
  Request() = default;
  Request(RequestOp o, std::uint32_t s) : op(o), seq(s) {}
};

struct Reply {
  std::uint32_t seq = 0;
  RtResult result = RtResult::ok;
  char message[160] = {};
};

enum class MotionKind : std::uint8_t { joint, cartesian, dwell, path };  // the index of MotionItem::payload
const char* to_string(MotionKind k);

/// A joint move, planned by the console thread from the queue's end (a rest at the
/// previous motion's goal). The RT thread runs that plan as it is when the arm is where
/// it starts (the usual case: one plan per move); only when it is not (no plan given, or
/// the arm is elsewhere) does it plan again from the actual state at start, and counts
/// it (Telemetry::joint_replans).
struct JointMove {
  kin::JointVector goal;          ///< target (rad / m)
  double override = 1.0;          ///< speed override 0.01..1
  kin::JointTrajectory plan;      ///< plan.n == 0: none given (the RT thread plans at start)
  /// Blend tolerance at `goal` (rad, joint-space Euclidean norm; 0 = exact stop): when the
  /// next queued motion is a joint move with the same override and no output changes, the
  /// RT thread runs both through one blend queue (kin::JointBlendQueue) and the arm passes
  /// within this distance of `goal` without stopping (docs/motion.md#blending). Corners with
  /// a line are PathMoves.
  double blend = 0.0;
};

/// A straight tool line, planned and path-checked by the console thread from the
/// queue's end; refused at start (start_moved) when the arm is not where it begins.
struct CartesianMove {
  kin::CartesianTrajectory path;  ///< path.goal: joint values at the end
};

/// Standing still where the previous motion ended.
struct DwellMove {
  kin::JointVector at;            ///< the joint values held
  double seconds = 0.0;
};

/// One segment of a blended run (docs/motion.md#blending): a joint move or a straight line,
/// planned alone from rest at the previous target and blended into the one before it by the
/// console thread (kin::PathBlendQueue: the overlap chosen by checks sampled at the control
/// rate). `seg.start` is on the run's time base (the console's). The RT thread starts the
/// segment at that time while the motion `after` is still moving, so both overlap as checked
/// (kin::path_sample_pair); when it comes too late for that, `after` is not the motion before
/// it, or it carries output changes, it starts from rest where that one ends (an exact stop,
/// still within every limit: each segment alone is a rest-to-rest plan).
struct PathMove {
  kin::PathSegment seg;
  std::uint32_t after = 0;        ///< id of the motion it blends out of (0: none, from rest)
  double override = 1.0;          ///< speed override it was planned with (a joint segment's; the move after a hold)
};

/// A digital output change: joint `joint`'s drive outputs word (60FEh:01) becomes
/// (word & ~mask) | value.
struct OutputChange {
  std::int8_t joint = -1;
  std::uint32_t mask = 0;
  std::uint32_t value = 0;
};
inline constexpr std::size_t kMotionOutputs = 4;  ///< output changes one motion carries (M62 / M63)

/// One queued motion: an id and one payload (one goal), never two.
struct MotionItem {
  std::uint32_t id = 0;
  std::variant<JointMove, CartesianMove, DwellMove, PathMove> payload;
  /// Output changes made in the cycle the motion starts (M62 / M63: in sync with it).
  std::array<OutputChange, kMotionOutputs> outputs{};
  std::uint8_t n_outputs = 0;

  MotionKind kind() const { return static_cast<MotionKind>(payload.index()); }
  /// Where the arm is at rest when the motion has finished.
  const kin::JointVector& goal() const {
    if (const auto* j = std::get_if<JointMove>(&payload)) return j->goal;
    if (const auto* c = std::get_if<CartesianMove>(&payload)) return c->path.goal;
    if (const auto* p = std::get_if<PathMove>(&payload)) return p->seg.q_end;
    return std::get_if<DwellMove>(&payload)->at;
  }
};

/// jog_stopped: a jog ended on its own other than at its target (deadman, a joint limit,
/// a singularity, no IK solution); the message says why and names the joint.
/// homing: progress of the homing cycle (a joint started, homed, aborted; the cycle done), `joint` named.
/// freedrive: free-drive on / off, or ended by a joint that left torque mode by itself.
/// warning: something the operator should know that does not stop the arm (a hot joint).
enum class EventKind : std::uint8_t { fault, estop, motion_done, motion_refused, state, jog_stopped, homing, freedrive, warning };
const char* to_string(EventKind k);

struct Event {
  EventKind kind = EventKind::state;
  ArmState state = ArmState::boot;
  FaultCause cause = FaultCause::none;
  std::int8_t joint = -1;  ///< joint index (0-based) concerned, -1 = none/all
  std::uint32_t motion_id = 0;
  char message[120] = {};
};

struct Telemetry {
  ArmState state = ArmState::boot;
  bool holding = false;           ///< feed hold active (moving state, ramped down or ramping)
  Mode mode = Mode::boot;         ///< the controller's mode (detail of `state`: state == arm_state(mode))
  int n = 0;
  std::array<double, kin::kMaxJoints> q_cmd{};  ///< last commanded (SI)
  std::array<double, kin::kMaxJoints> q_act{};  ///< last measured (SI)
  std::array<double, kin::kMaxJoints> qd_cmd{}; ///< last commanded velocity (SI per s)
  std::array<double, kin::kMaxJoints> qd_act{}; ///< last measured velocity (SI per s), as the drive reports it
  std::array<double, kin::kMaxJoints> tau_act{}; ///< last measured torque (N m / N, joint side); see torque_valid
  std::uint16_t torque_valid = 0;  ///< bit j: joint j's drive reports its torque (tau_act[j] is measured, else 0)
  std::array<double, kin::kMaxJoints> temperature{};  ///< deg C, the drive's hottest reported; see temperature_valid
  std::uint16_t temperature_valid = 0;    ///< bit j: joint j's drive reports a temperature
  std::uint16_t temperature_warning = 0;  ///< bit j: joint j at or above its warning temperature
  bool streaming = false;          ///< a stream of targets runs (JogSpec::stream) and is not braking
  std::array<std::uint8_t, kin::kMaxJoints> joint_state{};  ///< hal::JointState
  std::uint32_t queued = 0;        ///< motions in the queue (including the running one)
  std::uint32_t running_id = 0;    ///< id of the running motion (0 = none)
  std::uint32_t done_id = 0;       ///< id of the last motion finished
  FaultCause cause = FaultCause::none;
  std::int8_t fault_joint = -1;
  char fault_text[120] = {};
  std::uint64_t cycles = 0;
  std::uint64_t overruns = 0;
  std::uint64_t generation = 0;    ///< bumps whenever the queue is flushed or the setpoint is re-taken from the drives
  StatSummary latency, compute;
  double max_following_error = 0;  ///< rad/m, since the last reset
  std::int64_t estop_latency_ns = -1;  ///< request seen -> quick stop first setpoint written
  /// Cartesian samples whose IK at the exact pose failed: the cycle kept the precomputed
  /// (path-checked) joint value there instead; counted since boot, never reset.
  std::uint64_t ik_fallbacks = 0;
  /// Joint moves the RT thread had to plan again at start because the arm was not where
  /// the console's plan begins (or none was given); since boot.
  std::uint64_t joint_replans = 0;
  /// Corners of blended runs the controller passed without stopping (a segment started while
  /// the one before it still moved); since boot.
  std::uint64_t blended_corners = 0;
  /// Blended run (PathMove): the time on the run's time base of the last sample (s), -1 when
  /// no run is sampled; path_id: the motion whose segment that run's newest sample belongs to.
  double path_time = -1;
  std::uint32_t path_id = 0;
  // Homing (ServoBus::homing, docs/firmware.md#homing)
  std::uint16_t homed = 0;         ///< bit j: joint j's zero is established this power cycle (or it is absolute)
  std::uint16_t homing_now = 0;    ///< bit j: the master homes joint j now
  std::uint16_t homing_failed = 0; ///< bit j: joint j's last homing failed (not aborted: that leaves it unhomed)
  std::array<std::uint8_t, kin::kMaxJoints> homing_phase{};  ///< hal::HomingPhase per joint
  std::array<std::uint8_t, kin::kMaxJoints> homing_kind{};   ///< hal::HomingKind per joint
  std::uint8_t homing_group = 0;   ///< group running (1-based; 0 = none)
  std::uint8_t homing_groups = 0;  ///< groups of the running cycle
  /// Digital outputs: the 60FEh:01 word each joint's drive is sent.
  std::array<std::uint32_t, kin::kMaxJoints> outputs{};
  // The dynamic model (ModelControl): what runs, and the collision observer's figures.
  std::uint8_t feed_forward = 0;   ///< FeedForwardKind sent now (0 = off: none, refused, or switched off)
  bool collision_on = false;       ///< the collision observer watches (detection on; it resets when not watched)
  std::uint8_t freedrive = 0;      ///< FreedrivePhase
  double collision_peak = 0;       ///< largest |r_j| / threshold_j since boot (sensitivity applied)
  std::int8_t collision_peak_joint = -1;
  double collision_ratio = 0;      ///< largest |r_j| / threshold_j of the last cycle
  std::uint64_t collisions = 0;    ///< collision verdicts since boot
  std::uint64_t feed_forward_cycles = 0;  ///< cycles with feed-forward given to the drives
  /// True when every joint is homed.
  bool all_homed() const { return n > 0 && homed == static_cast<std::uint16_t>((1u << n) - 1u); }
  std::uint8_t safety_mode = 0;    ///< kin::SafetyMode the monitor runs with
  std::uint32_t safety_stops = 0;  ///< protective stops and jogs stopped by the safety envelope
  std::int8_t safety_zone = -1;    ///< the trigger plane the commanded tool sphere reaches beyond (Reduced), -1: none
  double speed_scale = 1.0;        ///< the speed scale the motion or jog runs at (docs/safety.md#speed-scaling; 1: as planned)
  /// The safety inputs (docs/safety.md#safety-inputs): bit 0 the e-stop input asserted, 1 it
  /// cannot be read, 2 the Reduced input asserted, 3 it cannot be read (lost counts as asserted).
  std::uint8_t safety_inputs = 0;
};

/// One control cycle's joint sample for a recorder (Controller::start_samples): what an MCAP
/// state and setpoint message carry, copied by the control thread in that cycle, so a recorder
/// that was not scheduled for a while still gets every cycle due.
struct CycleSample {
  std::uint64_t cycles = 0;
  ArmState state = ArmState::boot;
  Mode mode = Mode::boot;
  bool holding = false;
  std::uint8_t n = 0;
  std::uint16_t torque_valid = 0;  ///< bit j: tau_act[j] is measured
  std::uint16_t homed = 0;
  std::uint32_t running_id = 0;
  std::uint32_t queued = 0;
  std::array<double, kin::kMaxJoints> q_cmd{}, qd_cmd{}, q_act{}, qd_act{}, tau_act{};
};

}  // namespace servoarm::fw
