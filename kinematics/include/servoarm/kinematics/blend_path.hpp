// SPDX-License-Identifier: Apache-2.0
#pragma once
// Blended paths of straight-line and joint moves: line-to-line corners and mixed
// joint->line / line->joint transitions (joint-to-joint alone: blend.hpp).
// Pure math: no I/O, no clock, no heap, no exceptions; the caller owns time and capacity.
//
// Method: superposition, as blend.hpp, of rest-to-rest moves that overlap in time
// --------------------------------------------------------------------------------
// Every segment is planned alone from rest at the previous target: a line by plan_movel
// (its path check, IK at every knot, its slowdown near singularities: the line's own
// s(t) profile), a joint move as a straight joint-space segment with a jerk-limited s(t).
// A blend starts segment B (the new one) tau seconds before segment A ends. In the overlap:
//   line -> line:  the tool pose is the sum of the two motions,
//                    p(t) = pA(sA) + (pB(sB) - corner),   R(t) = RA(sA) RB(0)^-1 RB(sB)
//                  and the joints are solved by IK (the firmware's, as movel) nearest the
//                  previous sample;
//   mixed or joint -> joint:  the joint motions add,  q(t) = qA(t) + qB(t) - q_corner
//                  (a line's qX(t) is its own IK path).
// Outside overlaps one segment moves, as planned alone. At most two segments move at once.
//
// Checks of an overlap (each candidate tau, before it is accepted): the whole window, from
// 3 control periods before B starts to 3 after A ends, is sampled at the control rate
// (`rate`, at the instants k / rate of the queue's time base) exactly as the RT thread will
// sample it, and at every sample
//   - IK solves (line-line), the solution is within the joint limits and does not jump
//     (|dq| <= max_joint_step between samples: no branch change);
//   - every joint's velocity and acceleration (finite differences of the samples) are
//     within `margin` of its limits, and its jerk (third differences, inside the overlap)
//     within its jerk limit;
//   - line-line: the tool speed |sA' dA + sB' dB| (exact at the sample) is within the
//     larger of the two lines' speeds, and the tool point stays within the corner's
//     tolerance (m): |p - corner| <= r = max(d_in, d_out, sqrt(d_in^2 + d_out^2 -
//     2 d_in d_out cos theta)) -- the exact bound of blend.hpp, valid for the whole blend,
//     not only at samples;
//   - the segment into the corner is a joint move: |q - W| <= tolerance (rad, joint space)
//     by the same exact bound when both are joint moves, at every sample when B is a line;
//     into the corner a line and out of it a joint move: the tool point (FK) within the
//     tolerance (m) at every sample.
// The largest tau that passes (a scan of kPathScan values from the top, then kPathBisect
// bisection steps; every accepted tau was checked) is taken; none: an exact stop. A limit
// is never exceeded for a blend: tau = 0 (stop at the corner) always passes. Sampled
// checks hold at the control-rate samples, which is what the drives are sent (the RT
// thread samples this queue at the same rate; `margin` covers a different sampling phase).
//
// Bounded: an overlap is at most kPathMaxWindow samples (longer overlaps are not tried),
// so appending a segment costs at most kPathScan + kPathBisect window checks of at most
// kPathMaxWindow samples (one IK each for line-line), plus plan_movel for a line.
// See tests/bench/bench_blend.cpp (blend_path/append_*) for the time per segment.
#include <array>
#include <cstdint>
#include <span>

#include "servoarm/kinematics/blend.hpp"
#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/trajectory.hpp"
#include "servoarm/kinematics/trajectory_cartesian.hpp"

namespace servoarm::kin {

inline constexpr int kPathScan = 8;          ///< coarse values of tau tried, largest first
inline constexpr int kPathBisect = 10;       ///< refinements after the scan
inline constexpr int kPathMaxWindow = 2048;  ///< samples of one overlap check (2 s at 1 kHz)

enum class PathKind : std::uint8_t { joint, line };

/// One segment of a blended path (about 38 kB: the line's knot tables).
struct PathSegment {
  PathKind kind = PathKind::joint;
  CartesianTrajectory line;  ///< kind == line: planned alone from rest at the previous target
  JointVector from, delta;   ///< kind == joint: W(k-1), W(k) - W(k-1)
  JointProfile s{};          ///< kind == joint: path parameter, rest to rest
  JointVector q_end;         ///< joints at the segment's target
  Pose x_end = Pose::Identity();  ///< tool pose at the target (FK of q_end)
  double start = 0, duration = 0;
  double tolerance = 0;      ///< of this segment's target: m (line) or rad (joint move), 0 exact stop
  double blend_in = 0, blend = 0;  ///< overlaps with the previous / next segment (s)
  double corner = 0;         ///< largest distance from the target during its blend (m or rad; bound or sampled)
  double end() const { return start + duration; }
};

struct PathBlendConfig {
  JointLimits limits{};      ///< joint limits (SI): what every sample is checked against
  double rate = 1000;        ///< Hz, the control rate the checks sample at
  double margin = 0.95;      ///< fraction of the velocity / acceleration limits a blend may use
  double max_joint_step = 0.25;  ///< rad (m) between samples: more is a branch change
  /// Fraction of the acceleration and jerk limits a joint segment that blends in (the segment
  /// before it has a tolerance) may be planned with: it tries the full limits, the full
  /// acceleration with this share of the jerk, and this share of both, and keeps what ends
  /// first (never later than its exact stop: the full-limit plan ends no later than that).
  /// A segment that does not blend in is planned at the full limits. 1: full limits only
  /// (the jerk phases of two overlapping segments, A's last and B's first, then add up to
  /// twice the limit, so the checks leave small blends or none); 0.5: their sum stays within
  /// the limits (the firmware's choice).
  double joint_share = 1.0;
  const Chain* chain = nullptr;  ///< for FK (tool distances) and the lines' IK
  IkSolver ik{};             ///< the firmware's (make_ik_solver / firmware_ik_solver)
};

struct PathBlendCore {
  PathBlendConfig cfg{};
  JointVector rest;          ///< at rest here before the first segment
  std::uint64_t head = 0, count = 0;
};

/// What an append decided.
struct PathBlendReport {
  BlendStatus status = BlendStatus::ok;
  MotionStatus motion = MotionStatus::ok;  ///< the line's plan_movel answer (lines)
  PathReport path{};                       ///< where plan_movel refused (lines)
  double blend = 0;          ///< overlap chosen at the previous corner (s)
  double corner = 0;         ///< its distance bound (m or rad)
  int checks = 0;            ///< window checks made
  int samples = 0;           ///< samples (IK solves for line-line) made by the checks
  const char* limited_by = "";  ///< what stopped a larger blend: "tolerance", "velocity", "acceleration", "jerk", "tool_speed", "ik", "limits", "" 
};

void path_reset(PathBlendCore& core, const PathBlendConfig& cfg, const JointVector& rest);
/// Append a joint move to `goal` at speed override `override` (0.01..1); `tolerance` (rad)
/// is how far the arm may pass `goal` when the next segment comes.
BlendStatus path_append_joint(PathBlendCore& core, std::span<PathSegment> seg, const JointVector& goal,
                              double override, double tolerance, double t_earliest, PathBlendReport* report);
/// Append a straight line to `target` (tool pose, base frame); `tolerance` (m) likewise.
/// A line plan_movel refuses is refused (BlendStatus::no_solution, report->motion says why).
BlendStatus path_append_line(PathBlendCore& core, std::span<PathSegment> seg, const Pose& target,
                             const CartesianLimits& limits, const MovelOptions& options, double tolerance,
                             double t_earliest, PathBlendReport* report);
/// Joints at absolute time t; IK (line-line overlaps) nearest `seed` (the previous sample).
/// Returns the IK status (ok outside line-line overlaps). Heap-free.
Status path_sample(const PathBlendCore& core, std::span<const PathSegment> seg, double t, const JointVector& seed,
                   JointVector& q);
void path_retire(PathBlendCore& core, std::span<const PathSegment> seg, double t);
/// The same sample as path_sample, from two segments held elsewhere (the firmware's RT
/// thread runs the segments in place in its motion queue): `b` at absolute time t, summed
/// with `a` (the segment before it, or nullptr) while both move (b.start <= t < a->end()),
/// `a` alone before b starts. Line-line overlaps solve IK with b.line's chain and solver.
/// Returns the IK status (ok elsewhere). Heap-free.
/// Joints where segment g starts (n joints): a joint move's `from`, a line's first knot.
void path_segment_start(const PathSegment& g, int n, JointVector& q);
Status path_sample_pair(const PathSegment* a, const PathSegment& b, double t, const JointVector& seed, JointVector& q);

/// A queue of blended line and joint segments (Capacity x about 38 kB: keep it in a
/// preallocated slot, never on a stack).
template <int Capacity>
struct PathBlendQueue {
  static_assert(Capacity >= 2 && Capacity <= 1024, "a path blend queue holds 2..1024 segments");
  PathBlendCore core;
  std::array<PathSegment, Capacity> seg{};
  void reset(const PathBlendConfig& cfg, const JointVector& rest) { path_reset(core, cfg, rest); }
  BlendStatus append_joint(const JointVector& goal, double override, double tolerance, double t_earliest = 0,
                           PathBlendReport* report = nullptr) {
    return path_append_joint(core, seg, goal, override, tolerance, t_earliest, report);
  }
  BlendStatus append_line(const Pose& target, const CartesianLimits& limits, const MovelOptions& options,
                          double tolerance, double t_earliest = 0, PathBlendReport* report = nullptr) {
    return path_append_line(core, seg, target, limits, options, tolerance, t_earliest, report);
  }
  Status sample(double t, const JointVector& seed, JointVector& q) const { return path_sample(core, seg, t, seed, q); }
  void retire(double t) { path_retire(core, seg, t); }
  int size() const { return static_cast<int>(core.count); }
  const PathSegment& at(int i) const {
    return seg[static_cast<std::size_t>((core.head + static_cast<std::uint64_t>(i)) % Capacity)];
  }
  double end_time() const { return core.count ? at(size() - 1).end() : 0.0; }
};

}  // namespace servoarm::kin
