// SPDX-License-Identifier: Apache-2.0
#pragma once
// Denavit-Hartenberg chains, forward kinematics and the geometric Jacobian.
//
// Both conventions are first-class (DESIGN.md):
//   standard (distal, Spong / Cinemática direta de posição):  A_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)
//   modified (proximal, Craig): A_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i)
// For the modified convention a row stores (alpha_{i-1}, a_{i-1}, theta_i, d_i)
// in its alpha, a, theta, d fields.
//
// A row is revolute (theta = theta + direction*q), prismatic
// (d = d + direction*q) or fixed (no joint: an auxiliary frame).
// Pose = base * A_1 * ... * A_rows * tool.
//
// Real-time: forward(), forward_frames(), jacobian(), manipulability(),
// condition_number() and cartesian_precision() neither allocate, lock nor
// throw. Building a chain (add_row) is set-up work but is heap-free too.
#include <array>
#include <cstdint>
#include <limits>

#include "servoarm/kinematics/status.hpp"
#include "servoarm/kinematics/types.hpp"

namespace servoarm::kin {

enum class Convention : std::uint8_t { standard, modified };
enum class JointType : std::uint8_t { revolute, prismatic, fixed };

const char* to_string(Convention c);
const char* to_string(JointType t);

/// Per-joint motion limits used by the trajectory generator and supervisor
/// (SI: rad/s, rad/s^2, rad/s^3 or m/s, m/s^2, m/s^3).
struct JointDynamics {
  double max_velocity = 0;
  double max_acceleration = 0;
  double max_jerk = 0;
};

struct DhRow {
  JointType type = JointType::revolute;
  double theta = 0;      ///< rad; the fixed part (offset) for a revolute joint
  double d = 0;          ///< m; the fixed part for a prismatic joint
  double a = 0;          ///< m
  double alpha = 0;      ///< rad
  double direction = 1;  ///< +1 or -1
  double lower = -std::numeric_limits<double>::infinity();  ///< joint limit (rad or m)
  double upper = std::numeric_limits<double>::infinity();
  JointDynamics dynamics{};
  double max_effort = 0;  ///< N m (N for a prismatic joint); 0: not given. Carried, not enforced here.
  // Precomputed by add_row(): cos/sin of alpha, and of theta for rows whose theta is constant;
  // alpha_kind: 0 general, 1 alpha = 0, 2 alpha = +90 deg, 3 alpha = -90 deg (exactly, to 1e-15),
  // so forward() can skip the multiplications by 0 and 1 of the common cases.
  double ca = 1, sa = 0, ct = 1, st = 0;
  std::uint8_t alpha_kind = 0;
};

/// Inertial parameters of the rigid body attached to one DH row (SI), read from the
/// description's mass/com/inertia/rotor_inertia/gear_ratio/friction keys (docs/dynamics.md).
/// The body of row i moves with frame i; a fixed row's body is rigidly attached to the
/// body before it. Set with set_inertial() (dynamics.hpp), which fills the derived part.
struct LinkInertial {
  double mass = 0;                     ///< kg
  std::array<double, 3> com{};         ///< m, centre of mass in the row's DH frame
  std::array<double, 6> inertia{};     ///< kg m^2 about the COM, DH frame: ixx iyy izz ixy ixz iyz
  double rotor_inertia = 0;            ///< kg m^2 (or kg), motor side
  double gear_ratio = 1;               ///< motor turns per joint turn; reflected inertia G^2 Jm
  double viscous = 0;                  ///< N m s/rad (N s/m), joint side
  double coulomb = 0;                  ///< N m (N), joint side
  // Derived by set_inertial(), in the frame right after the row's joint motion
  // (standard: frame i * (Tx(a) Rx(alpha))^-1; modified: frame i): m*com and the
  // inertia about that frame's origin (xx yy zz xy xz yz).
  std::array<double, 3> mc{};
  std::array<double, 6> io{};
};

/// A capsule: every point within `radius` of the segment from `a` to `b` (m, in the frame of
/// the link it belongs to). The self-collision check of the safety envelope (safety.hpp,
/// docs/safety.md) keeps the capsules of non-adjacent links apart.
struct Capsule {
  Eigen::Vector3d a{0, 0, 0}, b{0, 0, 0};
  double radius = 0;
};

/// Capsule slots of a chain: 0 the base (in the base frame), k = 1..kMaxRows the link of DH
/// row k (in the frame after row k, as FrameSet::frame[k]), and kToolCapsule the tool's (from
/// the flange to the TCP, made from the active tool when the envelope is checked).
inline constexpr int kMaxCapsules = kMaxRows + 2;
inline constexpr int kToolCapsule = kMaxRows + 1;
static_assert(kMaxCapsules <= 32, "the capsule pair masks are 32-bit");

/// A serial chain of up to kMaxRows DH rows (kMaxJoints of them joints).
struct Chain {
  std::array<char, 48> name{};
  Convention convention = Convention::standard;
  std::array<DhRow, kMaxRows> rows{};
  int n_rows = 0;
  int n_joints = 0;
  std::array<std::int8_t, kMaxJoints> joint_row{};  ///< DH row index of joint j
  Pose base = Pose::Identity();
  Pose tool = Pose::Identity();
  bool tool_is_identity = true;  ///< set by set_tool(); skips a product in forward()
  /// Units the description was written in (display/console only; the chain is SI).
  double length_unit = 1.0;  ///< metres per user length unit (0.001 for mm)
  double angle_unit = 1.0;   ///< radians per user angle unit (pi/180 for deg)
  /// Dynamics (dynamics.hpp): per-row inertial data, parallel to rows; gravity in the
  /// world frame (the frame chain.base is given in), m/s^2.
  std::array<LinkInertial, kMaxRows> inertial{};
  bool has_inertial = false;  ///< false: the dynamics functions return unsupported
  std::array<double, 3> gravity{0.0, 0.0, -9.81};
  /// Self-collision geometry from the description (slots as kMaxCapsules says; the tool slot
  /// is never stored here). capsule_mask bit k: slot k holds a capsule. capsule_pairs[i] bit j
  /// (j > i): the pair (i, j) is checked: both present (the tool always is), their links not
  /// the same body nor joined by one joint, and not in the description's ignore list.
  std::array<Capsule, kMaxRows + 1> capsule{};
  std::uint32_t capsule_mask = 0;
  std::array<std::uint32_t, kMaxCapsules> capsule_pairs{};

  const DhRow& joint(int j) const { return rows[static_cast<std::size_t>(joint_row[static_cast<std::size_t>(j)])]; }
  DhRow& joint(int j) { return rows[static_cast<std::size_t>(joint_row[static_cast<std::size_t>(j)])]; }
  /// Scale from SI to the user's unit for joint j (1/angle_unit or 1/length_unit).
  double joint_user_scale(int j) const {
    return joint(j).type == JointType::prismatic ? 1.0 / length_unit : 1.0 / angle_unit;
  }
};

/// Append a row. Returns capacity if the chain is full (rows or joints), bad_input
/// if a value is not finite, the direction is not +-1, or lower > upper.
Status add_row(Chain& chain, const DhRow& row);

/// Set the tool transform (keeps tool_is_identity right). Set-up code.
void set_tool(Chain& chain, const Pose& tool);

/// Set the chain's name (truncated to fit).
void set_name(Chain& chain, const char* name);

/// Tool pose in the base frame.
/// @retval ok
/// @retval wrong_size  q.size() != chain.n_joints
/// @retval bad_input   q holds NaN or Inf (pose untouched)
Status forward(const Chain& chain, const JointVector& q, Pose& pose);

/// Every intermediate frame (see FrameSet) and the tool pose.
Status forward_frames(const Chain& chain, const JointVector& q, FrameSet& frames, Pose& pose);

/// Geometric Jacobian at the tool point, expressed in the base frame:
/// rows 0-2 linear velocity, rows 3-5 angular velocity. Optionally the tool pose.
Status jacobian(const Chain& chain, const JointVector& q, Jacobian& J, Pose* pose = nullptr);

/// Yoshikawa manipulability: the product of the singular values of J
/// (= sqrt(det(J J^T)) for n >= 6, sqrt(det(J^T J)) for n < 6).
double manipulability(const Jacobian& J);

/// Ratio of the largest to the smallest of the min(6, n) singular values of J;
/// +inf at a singularity.
double condition_number(const Jacobian& J);

/// Worst-case tool position error from per-joint resolutions (Carrara, Apostila de Robótica, §3.14):
/// dw_k = sum_i |dw_k/dq_i| * dq_i, at configuration q. dq in SI units.
Status cartesian_precision(const Chain& chain, const JointVector& q, const JointVector& dq,
                           Eigen::Vector3d& dw);

/// True if q is within every joint's limits (inclusive, tolerance tol).
bool within_limits(const Chain& chain, const JointVector& q, double tol = 1e-12);

}  // namespace servoarm::kin
