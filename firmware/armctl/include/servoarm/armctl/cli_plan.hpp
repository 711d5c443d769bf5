// SPDX-License-Identifier: Apache-2.0
#pragma once
// armctl plan movej | movel  (offline trajectory planning, non-real-time)
//
//   armctl plan movej --robot NAME|FILE --from q1..qn --to q1..qn
//                     [--vmax V] [--amax A] [--jmax J] [--override PCT]
//                     [--rate HZ] [--csv FILE] [--svg FILE]
//   armctl plan movel --robot NAME|FILE --from q1..qn
//                     (--to q1..qn | --xyz X Y Z [--rpy R P Y | --quat W X Y Z])
//                     [--speed V] [--accel A] [--angular W] [--override PCT] [--no-slowdown]
//                     [--vmax V] [--amax A] [--jmax J] [--rate HZ] [--csv FILE] [--svg FILE]
//
// Units are the robot description's (built-in models: mm and degrees).
//
// movel is planned as armfw plans it: plan_movel with the firmware's IK adapter
// (firmware_ik_solver, firmware/lang/ik_options.hpp): the nearest solution within the
// joint limits, closed form where the chain has one, damped Newton where not.
#include "servoarm/kinematics/ik.hpp"
#include "servoarm/kinematics/trajectory_cartesian.hpp"

namespace servoarm::fw {
/// What `armctl plan movel` plans (SI): `model` is prepared from `chain` (its joint limits
/// are the ones IK keeps to) and must outlive `out`, whose IkSolver points at it.
kin::MotionStatus plan_movel_preview(const kin::Chain& chain, const kin::JointVector& q0, const kin::Pose& target,
                                     const kin::CartesianLimits& limits, const kin::MovelOptions& options,
                                     kin::IkModel& model, kin::CartesianTrajectory& out, kin::PathReport* report);

/// argv[0] is "plan", argv[1] the move kind. Returns an exit code
/// (0 planned, 1 refused by the planner, 2 bad usage / bad input).
int cli_plan(int argc, char** argv);
}  // namespace servoarm::fw
