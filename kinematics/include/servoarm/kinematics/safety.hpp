// SPDX-License-Identifier: Apache-2.0
#pragma once
// The safety envelope's geometry: planes, keep-in and keep-out boxes, a tool sphere at the
// TCP, an optional elbow sphere at a joint frame, a tool-orientation cone and TCP / elbow
// speed limits, as pure functions over plain structs (docs/safety.md).
//
// These are monitoring functions, not a safety-rated controller: they catch a jog into the
// table or a program line through a fixture; the safety chain is the drives' STO and an
// external safety relay.
//
// Conventions (base frame, SI: metres, radians, m/s):
//  - a plane is the set n.p = offset with n a unit normal; the allowed side is n.p >= offset.
//    The tool sphere (centre c, radius r) is inside when n.c - r >= offset: value n.c - r,
//    limit offset.
//  - a box is axis-aligned in its own frame (SafetyBox::frame, the base frame unless given):
//    the sphere's centre is taken into that frame first; a plane given in a user frame is
//    turned into the base frame when the configuration is loaded.
//  - a keep-in box holds the whole sphere: min + r <= c <= max - r per axis; the value is the
//    worst axis's distance from c to the box face minus r (limit 0).
//  - a keep-out box must not touch the sphere: the distance from c to the box is at least r
//    (value the distance, negative inside the box: minus the clearance to its nearest face;
//    limit r).
//  - the cone: the angle between the tool's z axis and `axis` is at most `half_angle`.
//  - speeds: |v| of the TCP / of the elbow frame's origin at most the limit; |qd_j| of each
//    joint at most its limit (rad/s, m/s for a prismatic joint).
//  - the predicted stop: from the state (positions, velocities, accelerations) braked with the
//    joints' limits (plan_stop, the ramp the controller stops with), its duration at most the
//    stop time limit and the TCP's straight-line travel to where it rests at most the stop
//    distance limit.
//  - momentum: the sum over the links of mass x the speed of its centre of mass (kg m/s), and
//    mechanical power: the sum over the joints of |torque x velocity| (W, torques by inverse
//    dynamics: inertia, Coriolis, gravity, friction), each at most its limit (needs the
//    description's inertial data).
//  - self-collision: the description's capsules (Chain::capsule, one per link and the base)
//    and the tool's (the segment from the flange to the TCP, radius tool_radius), each pair
//    the chain checks (Chain::capsule_pairs: non-adjacent links, minus an ignore list) at least
//    self_collision_margin apart, surface to surface: value the smallest such distance
//    (negative when two overlap), limit the margin. The segment distance is exact (closed
//    form, segment_distance).
// A function is violated when its value is beyond its limit by more than the margin the
// caller passes (0 at plan time, the function's tolerance in the run-time monitor).
//
// Real-time: every function here is heap-free, lock-free and throws nothing.
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/trajectory.hpp"
#include "servoarm/kinematics/types.hpp"

namespace servoarm::kin {

inline constexpr int kMaxSafetyPlanes = 8;
inline constexpr int kMaxSafetyBoxes = 8;

struct SafetyPlane {
  Eigen::Vector3d normal{0, 0, 1};  ///< unit, towards the allowed side
  double offset = 0;                ///< m: the allowed side is normal.p >= offset
  bool elbow = true;                ///< restricts the elbow sphere too (when there is one)
};

struct SafetyBox {
  Eigen::Vector3d min{0, 0, 0}, max{0, 0, 0};  ///< m, in the box's frame, min <= max per axis
  bool keep_in = true;                         ///< true: the sphere stays inside; false: outside
  bool elbow = true;
  /// The box's frame in the base frame (a user frame: the box is axis-aligned in it). The
  /// sphere's centre c (base frame) is checked at frame^-1 * c; identity = the base frame.
  Pose frame = Pose::Identity();
};

/// The values that differ between Normal and Reduced mode.
struct SafetyLimits {
  double tcp_speed = 0;    ///< m/s; 0 = no limit
  double elbow_speed = 0;  ///< m/s; 0 = no limit
  double cone_half_angle = 0;  ///< rad; used when SafetyConfig::cone is set
  std::array<double, kMaxJoints> joint_speed{};  ///< rad/s (m/s prismatic) per joint; 0 = no limit
  double stop_time = 0;      ///< s: the predicted stop's duration; 0 = no limit
  double stop_distance = 0;  ///< m: the TCP's travel during the predicted stop; 0 = no limit
  bool has_stop_limit() const { return stop_time > 0 || stop_distance > 0; }
  double momentum = 0;  ///< kg m/s; 0 = no limit
  double power = 0;     ///< W; 0 = no limit
  bool has_dynamics_limit() const { return momentum > 0 || power > 0; }
};

enum class SafetyMode : std::uint8_t { normal, reduced };

struct SafetyConfig {
  bool enabled = false;
  std::array<SafetyPlane, kMaxSafetyPlanes> planes{};
  int plane_count = 0;
  std::array<SafetyBox, kMaxSafetyBoxes> boxes{};
  int box_count = 0;
  /// Trigger planes: the arm runs in Reduced mode while the tool sphere reaches beyond one
  /// (n.c - r < offset: not wholly on the side the normal points to), Normal again once it is
  /// wholly back (trigger_plane, effective_mode). They restrict nothing.
  std::array<SafetyPlane, kMaxSafetyPlanes> trigger_planes{};
  int trigger_count = 0;
  double tool_radius = 0;  ///< m: the sphere around the TCP
  int elbow_frame = -1;    ///< FrameSet index of the elbow sphere's centre; -1 = no elbow sphere
  double elbow_radius = 0; ///< m
  bool cone = false;
  Eigen::Vector3d cone_axis{0, 0, -1};  ///< unit: the tool's z axis stays within the cone around it
  SafetyLimits normal{}, reduced{};
  double position_tolerance = 0.002;  ///< m: run-time margin of planes and boxes
  double angle_tolerance = 0.035;     ///< rad: run-time margin of the cone
  double speed_tolerance = 0.02;      ///< m/s: run-time margin of the speed limits
  std::array<double, kMaxJoints> joint_speed_tolerance{};  ///< rad/s (m/s): run-time margin per joint
  double stop_time_tolerance = 0.02;  ///< s: run-time margin of the stop time (the stop distance's: position_tolerance)
  double momentum_tolerance = 0.5;    ///< kg m/s: run-time margin of the momentum
  double power_tolerance = 5;         ///< W: run-time margin of the power
  /// Self-collision: safety_sample finds the closest pair of the chain's capsules (and the
  /// tool's) and check_sample keeps it self_collision_margin apart (run-time margin:
  /// position_tolerance). Needs a description with capsules.
  bool self_collision = false;
  double self_collision_margin = 0;  ///< m: least distance between two capsules' surfaces
  std::uint32_t prismatic = 0;  ///< bit j: joint j is prismatic (its speeds in mm/s, not deg/s)
  const SafetyLimits& limits(SafetyMode m) const;
};

enum class SafetyFunction : std::uint8_t {
  none,
  plane,        ///< index = plane
  keep_in,      ///< index = box
  keep_out,     ///< index = box
  orientation,  ///< the tool-orientation cone
  tcp_speed,
  elbow_speed,
  joint_speed,  ///< index = joint (0-based; "joint j+1" in text)
  stop_time,      ///< the predicted stop's duration
  stop_distance,  ///< the TCP's travel during the predicted stop
  momentum,       ///< the links' mass x centre-of-mass speed, summed
  power,          ///< the joints' |torque x velocity|, summed
  self_collision,  ///< index, other = the two capsules (0 base, k link k, kToolCapsule the tool)
};
const char* to_string(SafetyFunction f);
const char* to_string(SafetyMode m);

struct SafetyViolation {
  SafetyFunction function = SafetyFunction::none;
  int index = -1;      ///< plane or box index
  int other = -1;      ///< self_collision: the second capsule (index is the first)
  bool elbow = false;  ///< the elbow sphere, not the tool sphere
  bool linear = false; ///< joint_speed of a prismatic joint: m/s (mm/s in text), else rad/s (deg/s)
  double s = 0;        ///< where along the path (the sample's s; 0..1 for a move; < 0 at run time)
  Eigen::Vector3d where{0, 0, 0};  ///< m: the sphere's centre (TCP or elbow)
  double limit = 0;    ///< m, rad or m/s (see the conventions above)
  double value = 0;
  /// How far beyond the limit (>= 0 when violated): m, rad or m/s.
  double excess() const;
};

/// One line into buf, in the firmware's units (mm, deg, mm/s): "safety plane 0 (tool sphere)
/// at s=0.420 (x=250.0, y=-100.0, z=110.0 mm): limit 100.0 mm, value 90.0 mm" (no "at s=" when
/// s < 0: a run-time sample). Returns buf.
const char* describe(const SafetyViolation& v, char* buf, std::size_t size);

/// One state to check: the TCP pose, the elbow frame's origin (when the config has one) and,
/// for the speed limits, their velocities and the joints' (has_velocity; joint_count joints).
struct SafetySample {
  double s = 0;
  Pose tcp = Pose::Identity();
  Eigen::Vector3d elbow{0, 0, 0};
  bool has_velocity = false;
  Eigen::Vector3d tcp_velocity{0, 0, 0};
  Eigen::Vector3d elbow_velocity{0, 0, 0};
  int joint_count = 0;
  std::array<double, kMaxJoints> joint_velocity{};  ///< rad/s (m/s prismatic)
  bool has_stop = false;     ///< stop_time / stop_distance hold the predicted stop (stop_prediction)
  double stop_time = 0;      ///< s
  double stop_distance = 0;  ///< m
  bool has_dynamics = false;  ///< momentum / power hold the state's (dynamics_prediction)
  double momentum = 0;        ///< kg m/s
  double power = 0;           ///< W
  /// Self-collision (cfg.self_collision and the chain has capsules): the closest checked pair.
  bool has_self = false;
  double self_distance = 0;  ///< m: between the pair's surfaces (negative: they overlap)
  std::int8_t self_a = -1, self_b = -1;  ///< its capsules (a < b; slots as kMaxCapsules)
  Eigen::Vector3d self_where{0, 0, 0};   ///< m: midway between the pair's closest points
};

/// The functions at `x` in order (planes, boxes, cone, self-collision, then the speeds when x.has_velocity):
/// true and `out` filled for the first one beyond its limit by more than its margin
/// (position_margin m, angle_margin rad, speed_margin m/s; a joint's speed tolerance_scale
/// times its joint_speed_tolerance, 1 in the monitor, or speed_margin when the scale is 0: plan
/// time; the stop time tolerance_scale times stop_time_tolerance, the stop distance
/// position_margin); false (out untouched) when none is.
bool check_sample(const SafetyConfig& cfg, SafetyMode mode, const SafetySample& x, double position_margin,
                  double angle_margin, double speed_margin, SafetyViolation& out, double tolerance_scale = 0.0);

/// The stop functions (stop time, stop distance; x.has_stop) and the dynamics functions
/// (momentum, power; x.has_dynamics) only, margins as check_sample (the momentum's and the
/// power's: tolerance_scale times their tolerances).
bool check_stop(const SafetyConfig& cfg, SafetyMode mode, const SafetySample& x, double position_margin,
                double tolerance_scale, SafetyViolation& out);

/// The stop predicted from `from` braked with `limits` (plan_stop: the controller's ramp): its
/// duration and the TCP's straight-line travel from x.tcp (the TCP at from.pos) to where the
/// joints rest, into x.stop_time / x.stop_distance (x.has_stop). `scratch` holds the ramp (kept
/// by the caller: no stack copy per call). False (x untouched) when the stop cannot be planned.
bool stop_prediction(const Chain& chain, const JointLimits& limits, const JointState& from, JointTrajectory& scratch,
                     SafetySample& x);

/// How far beyond its limit the function `which` names (function, index, elbow) is at `x`
/// (m, rad or m/s; negative inside). Lets a monitor tell a move back towards the inside
/// (the excess shrinks) from one further out.
double safety_excess(const SafetyConfig& cfg, SafetyMode mode, const SafetySample& x, const SafetyViolation& which);

/// The first trigger plane the tool sphere at x reaches beyond (index), -1 when none.
int trigger_plane(const SafetyConfig& cfg, const SafetySample& x);

/// The mode the functions run in at x: Reduced when `mode` is or when the tool sphere reaches
/// beyond a trigger plane, else Normal.
inline SafetyMode effective_mode(const SafetyConfig& cfg, SafetyMode mode, const SafetySample& x) {
  return mode == SafetyMode::reduced || trigger_plane(cfg, x) >= 0 ? SafetyMode::reduced : SafetyMode::normal;
}

/// The first sample of a path whose check fails with zero margins (plan time): true and
/// `out` filled, false when the whole path is inside.
bool check_path(const SafetyConfig& cfg, SafetyMode mode, std::span<const SafetySample> path, SafetyViolation& out);

/// The sample for joint values q (FK of the chain; elbow from forward_frames; with
/// cfg.self_collision the closest capsule pair, self_capsules). Returns false on a bad q
/// (NaN, wrong size).
bool safety_sample(const Chain& chain, const SafetyConfig& cfg, const JointVector& q, double s, SafetySample& out);

/// The distance between the segments p1-q1 and p2-q2 (closed form: Ericson, Real-Time
/// Collision Detection, 2005, section 5.1.9, ClosestPtSegmentSegment; a segment of zero length
/// is a point, parallel segments take the first end's projection). c1, c2: the closest points.
double segment_distance(const Eigen::Vector3d& p1, const Eigen::Vector3d& q1, const Eigen::Vector3d& p2,
                        const Eigen::Vector3d& q2, Eigen::Vector3d& c1, Eigen::Vector3d& c2);

/// The closest pair of capsules the chain checks (Chain::capsule_pairs) placed by `frames`
/// (forward_frames at some q): the description's, and with `with_tool` the tool's from the
/// flange (frames.frame[n_rows]) to tcp with radius tool_radius. Fills x.has_self and the
/// self_ fields; x.has_self false when no pair is checked. Heap-free; cost: one
/// segment_distance per checked pair.
void self_capsules(const Chain& chain, const FrameSet& frames, const Pose& tcp, bool with_tool, double tool_radius,
                   SafetySample& x);

/// Fills chain.capsule_pairs from its capsules, its joints (a link is adjacent to the one
/// joined to it by one joint; a fixed row's link is the body before it; the tool is the last
/// body's) and `ignore` (pairs of slots, either order). Set-up code (the description loader).
void set_capsule_pairs(Chain& chain, std::span<const std::array<int, 2>> ignore);

/// How many capsule pairs self_capsules checks with the tool's capsule (0 without capsules).
int capsule_pair_count(const Chain& chain);

/// "base", "link k" or "tool" for a capsule slot, into buf. Returns buf.
const char* capsule_name(int slot, char* buf, std::size_t size);

/// Fills x's velocities (has_velocity) from the previous sample p, h seconds earlier, at joints
/// q_prev -> q: the TCP's, the elbow's and each joint's difference over h. Does nothing when h <= 0.
void set_velocity(SafetySample& x, const SafetySample& p, const JointVector& q_prev, const JointVector& q, double h);

/// The highest value / limit of the mode's speed limits (TCP, elbow, joints) at x and of its
/// stop limits ((time / limit)^2 and (distance / limit)^(2/3): how speed goes with a
/// jerk-limited stop's duration and travel from low speeds) and its momentum limit (value /
/// limit) and power limit (its square root: power goes with speed to the first (gravity) to the
/// third (inertia) power, so a caller plans again until it holds) (0 when none is set or x has
/// neither velocity nor stop): a path whose highest ratio is k runs within them k times slower.
/// `stop_aim` (0, 1]: the stop limits taken at that fraction of their value (a margin for a
/// caller whose slowing lags the prediction: the run-time speed scale).
double speed_ratio(const SafetyConfig& cfg, SafetyMode mode, const SafetySample& x, double stop_aim = 1.0);

/// The arm's momentum and mechanical power at state s (see the conventions above) into
/// x.momentum / x.power (x.has_dynamics); the centres of mass' speeds from FK at s.pos and a
/// step along s.vel. False (x untouched) when the chain has no inertial data or s is bad.
bool dynamics_prediction(const Chain& chain, const JointState& s, SafetySample& x);

/// True for the functions a lower speed cures (TCP, elbow and joint speeds, stop time and distance).
bool is_speed(SafetyFunction f);

/// "" when the config is consistent, else why not (written into buf, one line): a NaN, a zero
/// normal, an inverted box, a keep-in box smaller than the tool sphere, a negative radius,
/// limit or self-collision margin. Returns buf or "".
const char* safety_config_problem(const SafetyConfig& cfg, char* buf, std::size_t size);

}  // namespace servoarm::kin
