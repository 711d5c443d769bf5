// SPDX-License-Identifier: Apache-2.0
#pragma once
// Jogging on the RT thread: a joint or a tool-space jog that can be started, retargeted,
// refreshed and stopped from whatever state the arm is in, jerk-limited throughout.
//
// A joint jog is a jerk-limited joint trajectory to a target (the next increment's end,
// or the joint's limit for a continuous jog), replanned from the current state whenever
// the target changes (so GRBL jog lines streamed back to back never stop between them).
//
// A tool-space jog moves the tool along / about the axes of a frame fixed at the jog's
// start (the base, or the tool as it was then): six "virtual axes" c = (x, y, z, rx, ry,
// rz) -- the tool point's offset from its start in that frame and the rotation vector
// applied in that frame -- follow a jerk-limited trajectory (the same planner as joint
// moves, with the tool-space limits), and each cycle the pose c(t) is solved by the
// console's IK (nearest to the current joints). What it refuses to do:
//  - spin a joint to keep the tool on the line near a singularity: when a joint would
//    need more than kSlowRatio of its velocity limit the jog slows (its clock runs slower,
//    the rate of slowing bounded), and when that is not enough it stops in joint space
//    and says which joint (JogEnd::singular);
//  - run into a joint limit: when a joint's stopping distance reaches its limit the jog
//    stops in joint space before it (JogEnd::limit, naming the joint);
//  - move without being asked: a continuous jog stops (on its line) when it has not been
//    refreshed within its deadman time (JogEnd::deadman).
// The safety envelope's speed limits (docs/safety.md#speed-scaling) act on a jog twice: its
// clock runs on a speed scale (time_scale.hpp, the target set by the controller every cycle:
// the running plan slows on its path), and every plan it makes (a new target, a streamed
// target, the end of a target's horizon) is made within the speed caps the controller sets
// (SpeedCap), from the real-time state, the scale back at 1: a re-plan never speeds up again
// past a limit the scale had slowed the jog to.
// Heap-free, no locks, no exceptions: it runs inside Controller::cycle.
#include <cstdint>

#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/trajectory.hpp"
#include "servoarm/kinematics/trajectory_cartesian.hpp"
#include "servoarm/hal/time.hpp"
#include "servoarm/rt/time_scale.hpp"

namespace servoarm::fw {

enum class JogSpace : std::uint8_t { joint, tool };

/// What the console asks for (Request::jog). SI units.
struct JogSpec {
  JogSpace space = JogSpace::joint;
  /// Continuous: runs until stopped, at a limit, or when not refreshed within deadman_s.
  bool continuous = false;
  /// A streamed target (joint space, servo mode): q_goal is the newest target, latest wins;
  /// each one retargets the trajectory from where the arm is, jerk-limited. Reaching it is no
  /// end: the arm holds there for the next target. No target within deadman_s: it brakes to rest
  /// on its limits and ends (JogEnd::deadman).
  bool stream = false;
  double deadman_s = 0.25;
  /// Stream: the target's joint velocities (SI per s; empty or all zero: rest at the target).
  /// The target then moves on at them, and the arm tracks it moving: the trajectory is planned
  /// in the frame moving with the target (relative velocity limit: the joint's limit less the
  /// target's speed, accelerations and jerks its own), so the arm matches the target's velocity
  /// instead of coming to rest at each one. After `horizon_s` without a newer target it comes to
  /// rest where the target has got to. A target velocity whose path over the horizon and its
  /// braking would leave a joint's limits is dropped (rest at the target).
  kin::JointVector qd_goal;
  double horizon_s = 0;  ///< stream with qd_goal: how long the target moves on at qd_goal
  // joint jog
  kin::JointVector q_goal;       ///< absolute joint target (continuous: the limit in the jog's direction)
  double override = 1.0;         ///< fraction of the joint limits, [0.01, 1]
  // tool-space jog
  kin::Pose target = kin::Pose::Identity();  ///< increment: the tool pose to end at (base frame)
  int axis = 0;                  ///< joint jog: the joint (0-based); tool jog (continuous): 0..5 = x y z rx ry rz
  int direction = 1;             ///< continuous: +1 / -1
  Eigen::Matrix3d frame = Eigen::Matrix3d::Identity();  ///< the frame's orientation in the base (columns = its axes)
  double linear_speed = 0.05;    ///< m/s along the path
  double angular_speed = 0.5;    ///< rad/s about the path
  kin::CartesianLimits limits{}; ///< accelerations and jerks (velocities are the speeds above)
  kin::IkSolver ik{};            ///< the console's IK (nearest, within the limits)
  /// Tool jog: the chain whose tool point moves (the active tool's: its `tool` is the TCP),
  /// the one `ik` solves; nullptr = the controller's chain (the flange, tool0). The console
  /// keeps it alive and unchanged while a jog may run (tool changes are refused then).
  const kin::Chain* chain = nullptr;
};

/// Why a jog ended (Jogger::step's result once it is over).
enum class JogEnd : std::uint8_t {
  running,    ///< still moving
  done,       ///< at rest at its target, or stopped as asked
  deadman,    ///< continuous jog not refreshed in time: stopped on its path
  limit,      ///< stopped before a joint limit (joint named)
  singular,   ///< stopped near a singularity: a joint would exceed its velocity limit (joint named)
  unreachable,///< the IK found no solution for the next pose: stopped (joint -1)
};
const char* to_string(JogEnd e);

class Jogger {
 public:
  /// A joint needing more than this fraction of its velocity limit slows the tool jog.
  static constexpr double kSlowRatio = 0.7;
  /// Slowed below this fraction of its speed, the tool jog stops (JogEnd::singular).
  static constexpr double kMinScale = 0.05;
  /// A joint that would need more than this fraction of its velocity limit stops the tool jog.
  static constexpr double kStopRatio = 0.9;
  /// A streamed target's velocity is held to this fraction of the joint's velocity limit.
  static constexpr double kMovingShare = 0.9;

  void configure(const kin::Chain& chain, const kin::JointLimits& limits, double period_s);

  /// Start a jog, or retarget the running one, from `cmd` (any state). False (and
  /// `why` set, nothing changed) when it cannot: a tool jog while a joint jog runs or the
  /// other way round, a tool jog in another frame than the running one, a bad spec.
  bool set(const JogSpec& spec, const kin::JointState& cmd, hal::TimePoint now, const char*& why);
  /// A continuous jog's deadman is refreshed.
  void refresh(hal::TimePoint now) { last_refresh_ = now; }
  /// Decelerate to rest on the path (joint: in joint space; tool: on the tool's line).
  void stop(const kin::JointState& cmd);
  bool active() const { return active_; }
  bool stopping() const { return stopping_; }
  JogSpace space() const { return spec_.space; }
  double deadman_s() const { return spec_.deadman_s; }
  /// The running jog is a stream of targets (JogSpec::stream) and not braking.
  bool streaming() const { return active_ && spec_.stream && !stopping_; }
  bool stream_jog() const { return spec_.stream; }

  /// One control period: the next commanded state into `cmd`. Returns running until the
  /// jog is over; then why (joint(): the joint concerned, or -1). After an end other than
  /// done / deadman the caller ramps the arm to rest in joint space (stop_in_joint_space()).
  JogEnd step(kin::JointState& cmd, hal::TimePoint now);
  int joint() const { return joint_; }
  /// The tool jog gave up its line (limit / singular / unreachable): the caller ramps down.
  bool needs_joint_ramp() const { return needs_ramp_; }
  /// Current time scaling of a tool jog (1 = full speed; < 1 slowed near a singularity).
  double scale() const { return scale_; }
  void reset() {
    active_ = stopping_ = needs_ramp_ = deadman_ = moving_ = false;
    safe_.reset();
  }

  /// Real-time: the safety envelope's speed caps for the plans made from now on.
  void set_speed_cap(const SpeedCap& c) { cap_ = c; }
  /// Real-time: the speed scale's target (docs/safety.md#speed-scaling), in [TimeScale::kMin, 1];
  /// the jog's clock ramps towards it from the next step on (not while it brakes to rest).
  void set_speed_target(double s) { safe_.set_target(s); }
  /// The speed scale of the last step (1: as planned).
  double speed_scale() const { return safe_.s; }
  /// The last step's scale would have fallen faster than the joints' acceleration limits allow.
  bool speed_scale_limited() const { return safe_.limited; }

 private:
  bool plan_joint(const kin::JointState& cmd);
  /// Stream with a target velocity: the plan in the target's moving frame (moving_), or false
  /// (nothing changed) when the velocity cannot be followed within the limits.
  bool plan_moving(const kin::JointState& cmd);
  bool plan_tool(const kin::JointVector& c_goal);
  void tool_pose(const kin::JointState& c, kin::Pose& out) const;
  JogEnd end(JogEnd e, int joint, bool ramp);
  /// The speed scale's step this period (its rate bounded by the joints' acceleration limits at
  /// the last setpoint `cmd`): the period on the jog's clock, dt_ * s.
  double scale_step(const kin::JointState& cmd);
  /// A joint plan's sample into real time on the speed scale: velocity q' s, acceleration
  /// q'' s^2 + q' ds/dt.
  void scaled(kin::JointState& cmd) const {
    if (safe_.s == 1.0 && safe_.rate == 0.0) return;
    cmd.acc = cmd.acc * (safe_.s * safe_.s) + cmd.vel * safe_.rate;
    cmd.vel *= safe_.s;
  }

  const kin::Chain* chain_ = nullptr;
  kin::JointLimits limits_{};
  double dt_ = 1e-3;
  int n_ = 0;

  JogSpec spec_{};
  bool active_ = false;
  bool stopping_ = false;
  bool needs_ramp_ = false;
  bool deadman_ = false;          ///< the running stop is the deadman's
  int joint_ = -1;
  hal::TimePoint last_refresh_ = 0;

  // joint jog, and the tool jog's virtual axes: the plan being sampled
  kin::JointTrajectory plan_{};
  double t_ = 0;
  // stream with a target velocity: plan_ is relative to the target q_ref_ + v_ref_ t
  bool moving_ = false;
  kin::JointVector q_ref_, v_ref_;
  double horizon_ = 0;
  // tool jog
  kin::Pose origin_ = kin::Pose::Identity();  ///< tool pose at the jog's start
  Eigen::Matrix3d frame_ = Eigen::Matrix3d::Identity();
  kin::JointLimits vlimits_{};                 ///< limits of the six virtual axes
  kin::JointState c_;                          ///< virtual axes' state at t_
  double scale_ = 1.0;
  kin::JointVector q_prev_;
  // the safety envelope's speed limits
  TimeScale safe_;  ///< the speed scale of the jog's clock
  SpeedCap cap_;    ///< the caps of its plans
};

}  // namespace servoarm::fw
