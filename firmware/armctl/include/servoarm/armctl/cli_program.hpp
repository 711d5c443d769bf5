// SPDX-License-Identifier: Apache-2.0
#pragma once
// armctl program check FILE --robot NAME|FILE [--config FILE] [--points FILE] [--programs DIR]
//                       [--from q1..qn] [--unhomed] [--joint-speed PCT] [--linear-speed V]
//
// Whole-program validation offline: the program is loaded as armfw loads it
// (servoarm_program: the console's parser, repeats and calls expanded, @points resolved),
// then every move is planned from the pose the previous line leaves by the arm service's dry
// run (ArmService: the code armfw's console queues moves with), with the firmware's own IK
// (firmware_ik_solver): movej and park / G28 against the joint limits, movel / G0 / G1 with
// movel's path check (IK at every knot, limits, branch, singularity); the knots of every
// accepted move are in ProgramCheck::knots. By default as armfw's `run` runs a program: `home`, `enable`, `disable` are
// refused inside it (home the arm before `run`) and an unhomed arm (--unhomed) runs nothing.
// With --stream, as lines sent one by one to the console: `home` is the homing cycle,
// as the console runs it: it leaves
// each joint at its drive.homing.offset (method "none": where it was), refused when moves
// are still queued (no `wait` before it), when the homed position is outside the joint's
// limits, and a move that follows it without `wait` is refused (the console refuses moves
// while homing runs). With --unhomed the arm starts as at power-up: every move before `home`
// has homed every joint is refused naming the joints (not_homed). The first bad line is
// answered "<file>:<line>: <reason>" (exit 2); a good program prints the number of steps and
// moves and the planned cycle time (exit 0).
#include <string>
#include <vector>

#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/safety.hpp"
#include "servoarm/program/program.hpp"

namespace servoarm::fw {

struct FwConfig;  // servoarm/config/config.hpp

/// One accepted move as the firmware plans it (the arm service's dry run): its knots.
struct ProgramKnot {
  int line = 0;             ///< the step's line in its file
  kin::JointVector goal;    ///< where the move ends
  double duration = 0;      ///< s: the move planned alone, rest to rest
  bool blended = false;     ///< a blended path segment
  double blend = 0;         ///< s: its overlap with the segment before it
  double segment_end = 0;   ///< s: its end on its blended run's time base
};

/// What checking a loaded program found.
struct ProgramCheck {
  bool ok = false;
  std::string error;        ///< "<file>:<line>: <reason>" when !ok
  int moves = 0, joint_moves = 0, line_moves = 0, dwells = 0;
  int homings = 0;          ///< `home` / `home jN` lines (homing cycles: not timed offline)
  double cycle_time = 0;    ///< s: the moves blended as armfw blends them, plus the dwells
  double cycle_time_exact = 0;  ///< s: every move to rest, plus the dwells
  int blended_corners = 0;  ///< corners the plan blends (each joins two moves without a stop)
  kin::JointVector q_end;   ///< where the program leaves the arm
  std::vector<ProgramKnot> knots;  ///< every accepted move, in order
};

/// How one joint homes, as armfw's configuration says (drive.homing.method, .offset).
struct JointHomingPlan {
  bool absolute = true;             ///< method "none": homed at power-up, `home` leaves it where it is
  std::string method = "none";      ///< "none", "hard_stop" or the CiA 402 number ("19"), for messages
  double offset = 0;                ///< SI: the joint's position after homing (607Ch / the backed-off point)
};

/// Defaults a program's moves take without speed= / F (armfw's motion.joint_speed_pct and
/// motion.linear_speed_mm_s), and the limit it may not exceed (motion.max_linear_speed_mm_s);
/// the park pose and how each joint homes (armfw's configuration, armctl program check --config).
struct ProgramCheckOptions {
  double joint_speed_pct = 50;
  double linear_speed = 0.1;        ///< m/s
  double max_linear_speed = 0.25;   ///< m/s
  double max_move_duration = 600;   ///< s (motion.max_move_duration_s)
  kin::JointVector park;            ///< park / G28 goal (motion.home_deg); empty: joint zero clamped into the limits
  std::vector<JointHomingPlan> homing;  ///< per joint; empty: every joint absolute (armfw without [[drive]] tables)
  bool start_unhomed = false;       ///< start as at power-up: non-absolute joints not homed until `home`
  /// false (default): as armfw's `run` runs it (`home`, `enable`, `disable` are not run inside a
  /// program; an unhomed arm runs none); true (--stream): as lines sent one by one to the console
  /// (armctl console -c, a G-code sender), where `home` runs the homing cycle.
  bool stream = false;
  double rate_hz = 1000;            ///< loop.rate_hz: the rate the path blends are checked at
  double default_blend_rad = 0;     ///< motion.default_blend_deg (SI): movej without blend=
  double default_blend_m = 0;       ///< motion.default_blend_mm (SI): movel / G1 without blend=
  kin::SafetyConfig safety{};       ///< [safety]: the envelope every step is checked against (docs/safety.md)
};

/// What armfw takes from its configuration for a program (App::build and console_config,
/// which this mirrors): drive.limits and drive.max_velocity into `chain`, motion.* and the
/// homing of each joint into `opt`. `cfg` passed validate_for_chain. "" or why it cannot apply.
std::string apply_config(const FwConfig& cfg, kin::Chain& chain, ProgramCheckOptions& opt);

/// Plan every step of `prog` on `chain` (SI limits set) from rest at `q0`.
ProgramCheck check_program(const kin::Chain& chain, const prog::Program& prog, const prog::PointsData* points,
                           const kin::JointVector& q0, const ProgramCheckOptions& options);

/// argv[0] is "program". Returns 0 (valid), 2 (bad usage, bad input or a bad line).
int cli_program(int argc, char** argv);

}  // namespace servoarm::fw
