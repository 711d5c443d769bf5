// SPDX-License-Identifier: Apache-2.0
#pragma once
// Blended joint motion: a queue of joint waypoints the arm passes without
// stopping, each corner within its tolerance, every joint within its velocity,
// acceleration and jerk limits at every instant. Pure math: no I/O, no clock,
// no heap, no exceptions. The caller owns time (absolute seconds on the
// queue's time base) and capacity (a template parameter).
//
// Method: superposition of straight segments ("overlap blending")
// ----------------------------------------------------------------
// Segment k goes from waypoint W(k-1) to W(k) along the straight joint-space
// line, timed by one scalar path parameter s_k(t) in [0, 1], a jerk-limited
// rest-to-rest profile (plan_1d, trajectory.hpp) whose limits are the joints'
// limits divided by |W(k) - W(k-1)| per joint (so every joint stays within its
// own limits on the segment):
//
//     q(t) = W(0) + sum_k s_k(t - start_k) (W(k) - W(k-1))
//
// Without blending segment k+1 starts when segment k has come to rest
// (start_{k+1} = end_k: an exact stop). Blending starts it earlier, an overlap
// tau_k = end_k - start_{k+1} > 0: during the overlap both segments move and
// their motions add; segment k's deceleration and segment k+1's acceleration
// overlap, so the arm rounds the corner W(k) without stopping.
//
// Why the limits hold (not only at samples: everywhere)
// - Outside the overlaps one segment moves, within its own limits.
// - Overlaps never meet: segment k+1 starts no earlier than segment k-1 ends,
//   so at most two segments move at any instant.
// - In an overlap the sum is piecewise cubic per joint. An overlap is accepted
//   only if the exact peaks of |velocity|, |acceleration| and |jerk| of the sum
//   over the whole overlap window (every breakpoint of either profile, every
//   zero of the acceleration) are within every joint's limits.
// - To leave room for the sum, the new segment is planned with one of three
//   shares of the acceleration / jerk limits: (1, 1), (1, 1/2), (1/2, 1/2)
//   (kBlendShare). With half jerk, a joint that keeps its direction through
//   the corner can overlap deceleration and acceleration (the jerks would add);
//   with half acceleration, a joint that reverses can overlap them too (the
//   accelerations would add). The candidate whose segment comes to rest first
//   is kept (greedy; a segment that may be blended at its end but has nothing
//   to blend at its start takes half jerk).
// - Position limits: during the blend q = W(k) - x u_k + y u_{k+1} with
//   x in [0, d_in], y in [0, d_out] (u unit directions, d_in the distance
//   segment k still has to go when the blend starts, d_out the distance segment
//   k+1 has gone when it ends). q is affine in (x, y), so the blended corner
//   lies in the parallelogram of the four corners (x, y) in {0, d_in} x {0, d_out};
//   its fourth vertex is checked against the joint limits.
// - Tolerance: |q - W(k)|^2 = x^2 + y^2 - 2 x y cos(theta) is convex in (x, y),
//   so over the whole blend |q - W(k)| <= r = max(d_in, d_out,
//   sqrt(d_in^2 + d_out^2 - 2 d_in d_out cos theta)); the overlap is accepted
//   only with r <= tolerance. The blended path therefore never leaves the ball
//   of radius `tolerance` around the corner (Euclidean norm in joint space,
//   rad -- or m for a prismatic joint), and it lies exactly on the programmed
//   segments outside the blends.
//
// Degradation: the overlap is the largest one (searched with a fixed number of
// exact checks) for which all of the above hold, and for which the new segment
// starts no earlier than `t_earliest` (the past, and what the RT thread is
// about to sample, is never changed). If no overlap > 0 passes, the corner is
// an exact stop (also chosen where stopping is faster than the best blend). A limit is never exceeded: every accepted overlap has been
// checked, and tau = 0 (an exact stop) always passes.
//
// Appending is bounded work: appending segment k+1 plans at most four 1-D
// profiles (three candidates for k+1, and k again at full limits) and searches
// the overlap with segment k only: at most 6 searches (3 candidates, with k as
// it is and replanned) of at most 43 exact checks each. Nothing
// that has started changes: segment k is replanned only if it starts after
// t_earliest and from rest (then nothing before it depends on its profile), and
// superposition adds segment k+1 on top of what is queued. See
// tests/bench/bench_blend.cpp for the time per segment.
//
// Real-time: sample() is O(log Capacity) and never fails; retire() is O(1)
// amortised. Both heap-free.
#include <array>
#include <cstdint>
#include <span>

#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/trajectory.hpp"
#include "servoarm/kinematics/types.hpp"

namespace servoarm::kin {

/// Status of a blend append. 0 ok, > 0 degraded but usable (the segment is
/// queued), < 0 refused (the queue is untouched).
enum class BlendStatus : std::int8_t {
  ok = 0,                  ///< queued; the previous corner blended as its tolerance allows (or exact stop asked)
  blend_reduced = 1,       ///< queued; the previous corner's blend made smaller than its tolerance allows
                           ///< (a velocity/acceleration/jerk or position limit, the length of a neighbouring segment, or t_earliest)
  exact_stop = 2,          ///< queued; the previous corner could not be blended at all: the arm stops there
  zero_length = 3,         ///< nothing queued: the waypoint equals the previous one (its tolerance replaces the previous)
  bad_input = -1,          ///< NaN/Inf in the waypoint, tolerance < 0 or not finite, t_earliest not finite
  wrong_size = -2,         ///< waypoint size differs from the limits' joint count
  bad_limits = -3,         ///< a joint's max velocity/acceleration/jerk is <= 0 or not finite, or n outside 1..kMaxJoints
  goal_out_of_limits = -4, ///< waypoint outside the joint position limits
  queue_full = -5,         ///< no free slot (retire() finished segments first)
  no_solution = -6,        ///< internal: the 1-D profile could not be built (never seen in tests)
};

/// Human-readable name, e.g. "blend_reduced".
const char* to_string(BlendStatus s);
inline bool is_ok(BlendStatus s) { return static_cast<int>(s) >= 0; }

/// Reduced share of the acceleration and/or jerk limits a blended segment may be planned with.
inline constexpr double kBlendShare = 0.5;
/// Most of a segment's duration (what its incoming blend leaves) one blend may overlap.
inline constexpr double kBlendMaxFraction = 1.0;

/// One straight joint-space segment of a blend queue.
struct BlendSegment {
  JointVector from;        ///< W(k-1)
  JointVector delta;       ///< W(k) - W(k-1)
  double length = 0;       ///< |delta| (Euclidean)
  double start = 0;        ///< absolute time s starts rising
  double duration = 0;     ///< the segment's own rest-to-rest duration; end = start + duration
  double tolerance = 0;    ///< blend tolerance of W(k) (as appended)
  double blend = 0;        ///< overlap with the next segment (s); 0: exact stop or none yet
  double blend_in = 0;     ///< overlap with the previous segment (s)
  double corner_radius = 0;///< bound r on |q - W(k)| during that blend (0: passes through W(k))
  double share = 1;        ///< smallest share of the acceleration/jerk limits s was planned with
  JointProfile s{};        ///< path parameter, t = 0 at `start`
  double end() const { return start + duration; }
};

/// Queue bookkeeping (the segments live beside it, see JointBlendQueue).
struct BlendCore {
  JointLimits limits{};
  JointVector rest;        ///< where the arm is at rest before the first queued segment
  std::uint64_t head = 0;  ///< sequence number of the oldest queued segment
  std::uint64_t count = 0; ///< queued segments
};

/// What append() decided (optional out-parameter).
struct BlendReport {
  BlendStatus status = BlendStatus::ok;
  double blend = 0;          ///< overlap chosen at the previous corner (s)
  double blend_max = 0;      ///< overlap the tolerance alone would allow (s)
  double corner_radius = 0;  ///< bound on |q - corner| over that blend
  int checks = 0;            ///< exact limit checks made by the search
};

// Non-template core (ring of `seg.size()` slots, index = sequence % size).
void blend_reset(BlendCore& core, const JointLimits& limits, const JointVector& rest);
BlendStatus blend_append(BlendCore& core, std::span<BlendSegment> seg, const JointVector& waypoint, double tolerance,
                         double t_earliest, BlendReport* report);
void blend_sample(const BlendCore& core, std::span<const BlendSegment> seg, double t, JointVector& pos,
                  JointVector& vel, JointVector& acc);
void blend_retire(BlendCore& core, std::span<const BlendSegment> seg, double t);

/// A queue of blended joint segments with room for Capacity segments.
/// Plain data, no heap: keep it in a preallocated slot (about 0.6 kB per segment).
template <int Capacity>
struct JointBlendQueue {
  static_assert(Capacity >= 2 && Capacity <= 4096, "a blend queue holds 2..4096 segments");
  BlendCore core;
  std::array<BlendSegment, Capacity> seg{};

  /// Empty queue, the arm at rest at `rest` (size limits.n). Limits are copied.
  void reset(const JointLimits& limits, const JointVector& rest) { blend_reset(core, limits, rest); }

  /// Append a segment from the queue's last waypoint (or `rest`) to `waypoint`;
  /// `tolerance` (>= 0, joint-space Euclidean, rad/m) is how far the arm may
  /// pass from `waypoint` when the next segment is appended (0: exact stop).
  /// The corner at the previous waypoint is blended now, with the new segment
  /// starting no earlier than `t_earliest` (pass the time the queue is sampled
  /// at plus a margin for the planning; on an empty or finished queue the new
  /// segment starts at max(t_earliest, end of the last one)).
  /// @retval ok, blend_reduced, exact_stop  queued (see BlendStatus)
  /// @retval zero_length         not queued: waypoint == previous waypoint
  /// @retval bad_input, wrong_size, bad_limits, goal_out_of_limits, queue_full, no_solution  refused, nothing changes
  BlendStatus append(const JointVector& waypoint, double tolerance, double t_earliest = 0,
                     BlendReport* report = nullptr) {
    return blend_append(core, seg, waypoint, tolerance, t_earliest, report);
  }
  /// State at absolute time t. O(log Capacity), heap-free, never fails; before
  /// the first segment / after the last: at rest there. Outputs resized to n.
  void sample(double t, JointVector& pos, JointVector& vel, JointVector& acc) const {
    blend_sample(core, seg, t, pos, vel, acc);
  }
  /// Drop segments that have ended by t (frees their slots).
  void retire(double t) { blend_retire(core, seg, t); }

  int size() const { return static_cast<int>(core.count); }
  bool empty() const { return core.count == 0; }
  /// Segment i of the queue (0 = oldest), i < size().
  const BlendSegment& at(int i) const {
    return seg[static_cast<std::size_t>((core.head + static_cast<std::uint64_t>(i)) % Capacity)];
  }
  /// Time the last queued segment comes to rest (the queue's end), or 0 if empty.
  double end_time() const { return core.count ? at(size() - 1).end() : 0.0; }
};

/// A joint-space tolerance that keeps the tool point within `tool_tolerance`
/// (m) of the corner's tool point: |x(q) - x(W)| <= sum_j R_j |q_j - W_j|
/// <= sqrt(sum_j R_j^2) |q - W|, with R_j an upper bound of the distance from
/// joint j's axis to the tool point over all configurations (sum of |a| and |d|
/// of the rows after it, plus the tool offset; 1 for a prismatic joint).
/// Conservative (often by 2-3x). Returns 0 for a non-positive or non-finite input.
double joint_tolerance_for_tool(const Chain& chain, double tool_tolerance);

}  // namespace servoarm::kin
