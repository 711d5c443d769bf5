// SPDX-License-Identifier: Apache-2.0
#pragma once
// Cartesian straight-line moves (movel): the tool point follows the segment
// from the start pose to the target pose, its orientation is interpolated by
// slerp, and a single path parameter s in [0, 1] carries the timing:
//
//   p(s) = p0 + s (p1 - p0),   R(s) = slerp(R0, R1, s)
//
// s(t) is a jerk-limited rest-to-rest profile (the 1-D case of movej) whose
// limits come from the linear and angular velocity/acceleration/jerk limits:
// ds/dt <= min(v_lin / L, v_ang / theta), likewise for d2s/dt2 and d3s/dt3
// (L = line length, theta = rotation angle).
//
// Path check (before the move starts): the line is cut into kMovelKnots
// intervals; at every knot IK is solved nearest to the previous knot's
// solution. The move is refused (with the reason, the path fraction s and the
// tool position) if a knot has no IK solution, the solution leaves the joint
// limits, the solution jumps (a branch change), or the line comes too close to
// a singularity (Jacobian condition number above MovelOptions::max_condition).
// Joint speeds needed along the line (dq/ds * ds/dt, and the acceleration
// q'' s_dot^2 + q' s_ddot) are compared with the joint limits: if a joint would
// be too fast -- typically when the line passes near a singularity -- the whole
// move is slowed uniformly (time-scaled) until every joint is within its
// limits, and the status says slowed_near_singularity. If the slowdown would
// exceed MovelOptions::max_slowdown the move is refused as singularity (or as
// joint_velocity when slowing is disabled).
//
// Sampling: sample_ik() solves IK at the exact pose of s(t) (seeded from the
// precomputed joint path, so it converges at once) -- the tool is on the line
// to IK precision; sample_precomputed() interpolates the precomputed joint path
// (cubic Hermite in s) without IK -- cheaper, the tool deviates from the line
// by the interpolation error (reported by tests). Both are heap-free.
//
// Stop / resume / override: the timing lives in `timing` (a one-joint
// JointTrajectory over s), so stop_movel() brings s to rest as fast as the
// limits allow -- the tool stops ON the line -- and resume_movel() continues
// from there to s = 1. An override change re-plans the s profile from its
// current state (see trajectory.hpp for the recovery rule).
#include <array>

#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/status.hpp"
#include "servoarm/kinematics/trajectory.hpp"

namespace servoarm::kin {

/// IK "nearest to q_near": a solution of chain at `target` closest to q_near,
/// written to q_out. Return ok (or a degraded status >= 0) when q_out is a
/// solution, a failure status (< 0) when there is none. Must be heap-free.
using IkNearestFn = Status (*)(const Chain& chain, const Pose& target, const JointVector& q_near,
                               JointVector& q_out, void* ctx);

/// Built by make_ik_solver(model, options) (motion_ik.hpp), the one adapter
/// armfw and armctl plan share; any IkNearestFn works.
struct IkSolver {
  IkNearestFn fn = nullptr;
  void* ctx = nullptr;
};

/// Tool-space limits of a movel (SI: m/s, m/s^2, m/s^3, rad/s, rad/s^2, rad/s^3).
struct CartesianLimits {
  double linear_velocity = 0.25, linear_acceleration = 1.0, linear_jerk = 10.0;
  double angular_velocity = 1.0, angular_acceleration = 4.0, angular_jerk = 40.0;
};

struct MovelOptions {
  double override = 1.0;        ///< speed override in [0.01, 1]
  bool allow_slowdown = true;   ///< slow down near singularities instead of refusing
  double max_slowdown = 20.0;   ///< slowdown factor above which the move is refused (singularity)
  double max_condition = 1e4;   ///< Jacobian condition number treated as singular
  double max_joint_step = 0.25; ///< rad (or m) between neighbouring knots; more is a branch change
  double joint_margin = 0.95;   ///< plan joint speeds to this fraction of the limits
};

/// Intervals of the precomputed joint path (knots = kMovelKnots + 1).
inline constexpr int kMovelKnots = 256;

/// Where and why a movel was refused (or slowed).
struct PathReport {
  MotionStatus status = MotionStatus::ok;
  double s = 0;                                       ///< path fraction of the problem (0..1)
  Eigen::Vector3d position = Eigen::Vector3d::Zero(); ///< tool position there (base frame, m)
  int joint = -1;                                     ///< joint concerned (-1: none/all)
  double slowdown = 1;                                ///< time-scale factor applied (>= 1)
  double max_condition = 0;                           ///< largest Jacobian condition number seen
};

/// A planned movel. Holds a pointer to the chain and the IK context it was
/// planned with: both must outlive it. About 37 kB (the knot tables): keep it in
/// a preallocated slot, not on a small RT stack.
struct CartesianTrajectory {
  const Chain* chain = nullptr;
  IkSolver ik{};
  int n = 0;
  Eigen::Vector3d p0 = Eigen::Vector3d::Zero(), p1 = Eigen::Vector3d::Zero();
  Eigen::Quaterniond r0 = Eigen::Quaterniond::Identity(), r1 = Eigen::Quaterniond::Identity();
  double length = 0;  ///< m
  double angle = 0;   ///< rad
  JointTrajectory timing;  ///< one "joint": the path parameter s in [0, 1]
  double duration = 0;
  double slowdown = 1;
  MotionStatus status = MotionStatus::ok;  ///< ok or slowed_near_singularity
  JointVector goal;                         ///< joint values at the end of the line
  JointLimits limits{};                     ///< joint limits the path was checked against
  Limits1 s_limits{};                       ///< path-parameter limits (override 1, after slowdown)
  /// Precomputed joint path: q and dq/ds at s_k = k / kMovelKnots.
  std::array<std::array<double, kMaxJoints>, kMovelKnots + 1> q_knot{};
  std::array<std::array<double, kMaxJoints>, kMovelKnots + 1> dq_knot{};

  /// Tool pose at path fraction s (clamped to [0, 1]).
  Pose pose_at(double s) const;
  /// s, ds/dt, d2s/dt2 at time t.
  void path_state(double t, double& s, double& sd, double& sdd) const;
  /// Joint state at t from the precomputed path (cubic Hermite in s). O(1), no IK.
  void sample_precomputed(double t, JointVector& q, JointVector& qd, JointVector& qdd) const;
  /// Joint state at t with IK at the exact pose (seeded from the precomputed
  /// path); velocity and acceleration from the precomputed path. Returns the
  /// IK status (on failure q holds the precomputed value).
  Status sample_ik(double t, JointVector& q, JointVector& qd, JointVector& qdd) const;
};

/// Plan a straight-line move from joint configuration q_start (at rest) to `target`.
/// @retval ok
/// @retval slowed_near_singularity  planned, slowed by report.slowdown so no joint exceeds its limits
/// @retval wrong_size      q_start.size() != chain.n_joints
/// @retval bad_input       NaN/Inf, target rotation not orthonormal, no IK function, bad option
/// @retval bad_limits      a joint's (or the Cartesian) velocity/acceleration/jerk <= 0 or not finite
/// @retval no_ik_solution  a point of the line has no IK solution       (report: s, position)
/// @retval path_out_of_limits  a point's solution is outside the joint limits (report: s, joint)
/// @retval branch_change   the solution jumps between neighbouring points (report: s, joint)
/// @retval singularity     too close to a singularity: condition number > max_condition or the
///                         slowdown needed > max_slowdown                 (report: s, position)
/// @retval joint_velocity  a joint would be too fast and allow_slowdown is false (report: s, joint)
/// On failure `out` is untouched. `report` (optional) is filled in every case.
MotionStatus plan_movel(const Chain& chain, const JointVector& q_start, const Pose& target,
                        const CartesianLimits& limits, const MovelOptions& options, IkSolver ik,
                        CartesianTrajectory& out, PathReport* report = nullptr);

/// Replace `traj`'s timing by a stop along the line from its state at time t
/// (the tool stops on the line as fast as the path limits allow). Time restarts at 0.
MotionStatus stop_movel(CartesianTrajectory& traj, double t);
/// Continue a stopped (or running) movel from its state at time t to the end
/// of the line, at `override`. Time restarts at 0. Also used for an override change.
MotionStatus resume_movel(CartesianTrajectory& traj, double t, double override = 1.0);

}  // namespace servoarm::kin
