// SPDX-License-Identifier: Apache-2.0
#pragma once
// Jerk-limited, time-synchronised joint trajectories (movej), stop and resume,
// speed override. Pure math: no I/O, no clock, no heap, no exceptions. The
// firmware owns time and hands `t` (seconds since the move started) to sample().
//
// Profile model (per joint)
// -------------------------
// A joint trajectory is a short list of constant-jerk segments (at most
// kMaxSegments). A move from any state (p0, v0, a0) to rest at the goal
// (pf, v = 0, a = 0) has the shape
//
//     [recovery] -> velocity change to vc -> cruise at vc -> velocity change to 0 -> hold
//
// where each velocity change is the time-optimal jerk-limited change of
// velocity ending at zero acceleration: jerk +-J up to an acceleration peak
// (<= A), hold the peak, jerk back to zero -- at most 3 segments. With the
// cruise that is the classic 7-phase profile (jerk, const acc, jerk, cruise,
// jerk, const dec, jerk); phases of zero length are dropped.
//
// The target state is always rest at the goal (zero velocity and
// acceleration): that is what a robot move needs, and it is what makes a
// plan from any start state always solvable.
//
// Time synchronisation: each joint's fastest profile in this family gives its
// minimum time; the slowest joint sets the common duration T and every other
// joint is stretched (its cruise velocity lowered, never cut short) so that
// all joints start together and arrive together at T. From a moving start
// some durations can be unreachable for a joint in this family (a short
// "blocked interval" just above its minimum time, as in Ruckig); T is then
// raised to the nearest duration every joint can meet.
//
// Start from any state (online replanning): plan_movej() takes the current
// sampled state of a running trajectory, so a new command replaces the old one
// without a jump in position, velocity or acceleration. If the start state
// exceeds the (override-scaled) limits -- e.g. the operator lowered the speed
// override during a move -- a recovery prefix first brings every joint's
// acceleration to zero and its velocity inside the scaled limit using the
// joint's full (100 %) acceleration and jerk limits; the move continues from
// there with the scaled limits.
//
// Speed override s in [0.01, 1]: velocity limits are scaled by s, acceleration
// by s^2, jerk by s^3. A move planned from rest at override s is exactly the
// 100 % move slowed down in time by 1/s (same joint path, duration / s).
//
// Stop: plan_stop() brings every joint to rest as fast as its limits allow
// (time-optimal per joint, joints not synchronised: each stops on its own as
// fast as it can). Resume: plan_movej() from the stopped state to the
// interrupted goal (JointTrajectory::goal keeps it).
//
// Real-time: sample() is O(1) (at most kMaxSegments comparisons per joint),
// heap-free and never fails. plan_movej()/plan_stop() are bounded (every
// numeric search has a fixed iteration cap) and heap-free too.
#include <array>
#include <cstdint>

#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/types.hpp"

namespace servoarm::kin {

/// Status of the motion layer. 0 ok, > 0 degraded but usable, < 0 refused
/// (the output trajectory is left untouched).
enum class MotionStatus : std::int8_t {
  ok = 0,
  slowed_near_singularity = 1,  ///< movel: speed lowered so no joint exceeds its velocity limit
  bad_input = -1,       ///< NaN/Inf in a state, goal, pose or option; override outside [0.01, 1]
  wrong_size = -2,      ///< vector length does not match the limits / chain
  bad_limits = -3,      ///< a joint's max velocity/acceleration/jerk is <= 0 or not finite
  goal_out_of_limits = -4,  ///< goal (or movel end point) outside the joint position limits
  path_out_of_limits = -5,  ///< the move would leave the joint position limits on the way
  no_ik_solution = -6,      ///< movel: a point of the line has no IK solution (unreachable)
  branch_change = -7,       ///< movel: the IK solution jumps (changes branch) along the line
  joint_velocity = -8,      ///< movel: a joint would exceed its velocity limit and slowing is off
  singularity = -9,         ///< movel: the line passes (too) close to a singularity
  no_solution = -10,        ///< internal: the numeric search found no profile (never seen in tests)
};

/// Human-readable name, e.g. "path_out_of_limits".
const char* to_string(MotionStatus s);
inline bool is_ok(MotionStatus s) { return static_cast<int>(s) >= 0; }

/// Most constant-jerk segments in one joint's trajectory (recovery 4, move 7, hold 1).
inline constexpr int kMaxSegments = 12;

/// One constant-jerk piece: starts at time t0 in state (p, v, a), jerk j.
struct JerkSegment {
  double t0 = 0, p = 0, v = 0, a = 0, j = 0;
};

/// One joint's piecewise-cubic position profile. The last segment is the
/// hold at the final position (v = a = j = 0) and lasts forever.
struct JointProfile {
  std::array<JerkSegment, kMaxSegments> seg{};
  int n = 0;
};

/// Motion limits and position limits of every joint (SI units).
struct JointLimits {
  int n = 0;
  std::array<JointDynamics, kMaxJoints> dyn{};
  std::array<double, kMaxJoints> lower{};
  std::array<double, kMaxJoints> upper{};
};

/// Copy the per-joint limits out of a chain (DhRow::dynamics, lower, upper).
JointLimits limits_from(const Chain& chain);

/// Position, velocity and acceleration of every joint.
struct JointState {
  JointVector pos, vel, acc;
  /// n joints at rest at q.
  static JointState rest(const JointVector& q);
};

/// A planned joint-space trajectory. Plain data: copy it, keep it in a
/// preallocated slot, sample it from the control loop.
struct JointTrajectory {
  int n = 0;
  double duration = 0;    ///< every joint is at rest at `goal` from here on
  double override = 1;    ///< speed override the plan was made with
  double recovery = 0;    ///< length of the recovery prefix (0 if none was needed)
  JointVector goal;       ///< target of the move (for stop: where the joints come to rest)
  std::array<JointProfile, kMaxJoints> joint{};

  /// State at time t (seconds since the plan's start). t < 0 gives the start
  /// state, t >= duration exactly the goal at rest. O(1), heap-free, never fails.
  /// Outputs are resized to n (no allocation: fixed capacity).
  void sample(double t, JointVector& pos, JointVector& vel, JointVector& acc) const;
  void sample(double t, JointState& s) const { sample(t, s.pos, s.vel, s.acc); }
  /// Position of joint i only.
  double position(int i, double t) const;
};

/// Options of a joint move.
struct MovejOptions {
  double override = 1.0;  ///< speed override in [0.01, 1]
};

/// Plan a synchronised jerk-limited move from `start` (any state) to rest at `goal`.
/// @retval ok
/// @retval wrong_size          start/goal sizes differ from limits.n (or n outside 1..kMaxJoints)
/// @retval bad_input           NaN/Inf in start or goal, override outside [0.01, 1]
/// @retval bad_limits          a joint's max_velocity/max_acceleration/max_jerk <= 0 or not finite
/// @retval goal_out_of_limits  goal outside [lower, upper] of a joint
/// @retval path_out_of_limits  the profile would overshoot a joint limit (moving start only)
/// @retval no_solution         internal search failed (a bug: please report the inputs)
/// On failure `out` is untouched.
MotionStatus plan_movej(const JointLimits& limits, const JointState& start, const JointVector& goal,
                        const MovejOptions& options, JointTrajectory& out);

/// Bring every joint to rest from `start` as fast as the limits (scaled by
/// options.override) allow. out.goal is where the joints stop. The stop may
/// cross a position limit if the joint was already about to; that is reported
/// as ok: a stop is never refused for it (the supervisor owns hard limits).
/// @retval ok
/// @retval wrong_size, bad_input, bad_limits  as plan_movej
MotionStatus plan_stop(const JointLimits& limits, const JointState& start, const MovejOptions& options,
                       JointTrajectory& out);

/// Peak |velocity|, |acceleration| and |jerk| of joint i over the whole
/// trajectory (exact: evaluated at segment ends and extrema).
struct JointPeaks {
  double velocity = 0, acceleration = 0, jerk = 0;
  double min_position = 0, max_position = 0;
};
JointPeaks peaks(const JointTrajectory& traj, int i);

// ---------------------------------------------------------------------------
// One-dimensional building block (used by movej per joint and by movel for
// the path parameter). Exposed for tests and for the Cartesian layer.
// ---------------------------------------------------------------------------

struct Limits1 {
  double v = 0, a = 0, j = 0;
};

/// Minimum-time profile in the family described above, from (p0, v0, a0) to
/// rest at pf, for limits that the start state respects (|v0| <= v, |a0| <= a,
/// and the velocity reached by bringing a0 to zero within +-v). Writes segments
/// starting at t0 into `prof` (appending) and returns the end time, or a
/// negative value on failure. If `duration` > 0 the profile is stretched to
/// end at exactly t0 + duration (must be an achievable duration; see
/// min_duration_1d()).
double plan_1d(double t0, double p0, double v0, double a0, double pf, const Limits1& lim, double duration,
               JointProfile& prof);

/// Minimum duration of plan_1d and the next achievable duration above `t`:
/// returns the smallest achievable duration >= t (t <= minimum gives the minimum).
double achievable_duration_1d(double p0, double v0, double a0, double pf, const Limits1& lim, double t);

/// Evaluate a profile at t (segment scan, O(kMaxSegments)).
void eval_profile(const JointProfile& prof, double t, double& p, double& v, double& a);

}  // namespace servoarm::kin
