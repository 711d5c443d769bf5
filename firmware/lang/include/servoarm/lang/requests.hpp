// SPDX-License-Identifier: Apache-2.0
#pragma once
// The canonical motion requests of the console. Every front end builds one of
// these and hands it to the arm service (ArmService::move), which validates and queues it, the way
// LinuxCNC's interpreter turns any G-code into canon.hh calls (STRAIGHT_FEED,
// STRAIGHT_TRAVERSE): `movel` and G0/G1 build a MoveLine; `movej`, `home` and
// G28 a MoveJoints. Units: SI (the front ends convert what the user typed).
#include "servoarm/kinematics/types.hpp"

namespace servoarm::fw {

/// A straight tool line from the end of the motion queue (STRAIGHT_FEED / _TRAVERSE).
struct MoveLine {
  kin::Pose target = kin::Pose::Identity();  ///< tool pose in the base frame (m, rotation)
  double speed = 0;          ///< m/s; 0: the console's default linear speed
  bool rapid = false;        ///< G0: at the maximum linear speed (speed ignored)
  bool clamp_speed = false;  ///< G-code F: above the maximum is clamped (as GRBL does), not refused
  double blend = -1;         ///< blend tolerance at `target` (m, tool point; movel blend=); 0: exact stop, < 0: the default
};

/// A jerk-limited, time-synchronised joint move from the end of the motion queue.
struct MoveJoints {
  kin::JointVector goal;  ///< joint values (rad / m)
  double speed_pct = 0;   ///< percent of the joint limits, [1, 100]; 0: the console's default
  double blend = -1;      ///< blend tolerance at `goal` (rad, joint-space Euclidean; movej blend=); 0: exact stop, < 0: the default
};

/// How far ahead of a blended run's newest sample the console places the start of a segment
/// it queues now (s): console line handling + telemetry age, with margin (the arm
/// service's blended segments; armctl program check times programs with it).
inline constexpr double kPathLead = 0.15;

}  // namespace servoarm::fw
