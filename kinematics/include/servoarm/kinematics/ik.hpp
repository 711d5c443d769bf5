// SPDX-License-Identifier: Apache-2.0
#pragma once
// Inverse kinematics: every solution in closed form where the chain allows it,
// bounded damped-least-squares otherwise.
//
// Set-up (not real-time, but heap-free): ik_prepare() analyses a Chain once --
// it rewrites the DH rows (either convention, fixed rows, offsets, directions)
// as  C0 J1(m1) C1 J2(m2) ... Jn(mn) Cn  with constant transforms C and joint
// motions J = Rz(m) (revolute) or Tz(m) (prismatic), m = direction * q, and
// recognises which closed form fits (IkMethod). Real-time: ik_solve_all(),
// ik_solve_nearest(), ik_numeric() neither allocate, lock nor throw; their
// worst-case time is bounded (no unbounded loops).
//
// Closed forms (chosen from the DH structure, never from the model name):
//  * spherical_wrist: 6 joints, joint 1 revolute, joints 4-6 revolute with
//    intersecting axes (checked from the rows). Pieper's decomposition: the
//    wrist centre W is fixed in the tool frame and in the frame after joint 3.
//    With joint 1 about z, two equations in (q2, q3) do not involve q1:
//        E1: |f(q2,q3) - l z|^2 = |p - l z|^2     (l: where axes 1, 2 are closest)
//        E2:  f_z(q2,q3)        = p_z
//    Each is bilinear in the bases (1, cos q, sin q) of a revolute joint or
//    (1, d, d^2) of a prismatic one; the 3x3 coefficient matrices are found
//    at set-up by sampling the chain. When one equation involves only one of
//    q2, q3 (PUMA, Stanford, cylindrical arms) both are solved in closed form
//    (atan2/acos or a quadratic); otherwise (e.g. ist6, whose axes 1 and 2 do
//    not meet) q2 is eliminated by the resultant, a polynomial of degree <= 8
//    in tan(q3/2) (or d3) whose real roots are isolated along its
//    derivative chain (its companion matrix's eigenvalues where that is
//    unsure: near-double roots) and polished by Newton. q1 follows from atan2; the wrist from
//        R3^T R C6^T = Rz(m4) C4 Rz(m5) C5 Rz(m6)
//    (two m5 roots, then m4 and m6 by atan2). Up to 8 solutions.
//    The method names the position subproblem: spherical_wrist (one of E1,
//    E2 decoupled), opw (axes 2 and 3 parallel and not parallel to axis 1:
//    the ortho-parallel arms of ABB, KUKA, Fanuc... with any shoulder offset
//    a1, elbow offset a2, lateral offset b -- every point after joint 3 keeps
//    its component along axis 2, which gives q1 first (two roots), then the
//    distance from axis 2 gives q3 (two), one angle q2), spherical_general
//    (neither: the degree-8 resultant, the general path).
//  * ur: 6 revolute joints, axes 2, 3, 4 parallel (not parallel to axis 1),
//    axis 5 normal to them, axes 5 and 6 meeting (Universal Robots and the
//    cobots built like them). q1 from the point where axes 5 and 6 meet (its
//    component along axis 2 is constant), q5 from axis 6's component along
//    axis 2, q6 from the direction of axis 4 in the tool, then q3, q2, q4 in
//    the plane of the parallel axes (ur.cpp). Up to 8 solutions.
//  * planar_2r (RR; chapter 4.1 of Carrara's Apostila de Robótica): two parallel revolute axes.
//  * planar_3 (RRR and RLR with tool angle phi; Carrara, Apostila de Robótica, 4.2, 4.3):
//    three joints whose rotation axes are all parallel.
//  * spatial_3 (TRR; Carrara, Apostila de Robótica, 4.4): three joints, position only, solved with
//    the same (E1, E2) machinery as the spherical-wrist arm (W = tool point).
//  * pitch_4 (TRL:R, VVL:R with wrist pitch phi; Carrara, Apostila de Robótica, 4.5, 4.6): four
//    joints, joint 1 about the base z axis, joints 2 and 4 revolute about
//    parallel axes perpendicular to it: the point before the last link is
//    found from the target and phi, then the spatial_3 machinery.
// Every closed-form solution is checked by FK (1e-9 m, 1e-9 rad on what the
// method controls) and duplicates are removed. The spherical-wrist solver
// evaluates that FK through its own decomposition C0 J1 C1 ... J6 C6 with the
// part shared by the two wrist solutions of an arm configuration computed once
// (wrist centre, then the wrist rotation against the target's), exact to
// rounding; a candidate that misses goes through the chain's forward() and a
// few Gauss-Newton steps. It works on (cos, sin) pairs and computes every
// angle in one batch at the end (fast_trig.hpp atan2_poly, 4.4e-16 rad).
//
// Sources, kinematics/src/ik/: model.cpp (ik_prepare: decomposition and
// classification; ik_solve_all's dispatch), position.cpp (joints 1-3 in
// closed form, candidate verification), polynomial.cpp (the degree-8
// resultant path), spherical_wrist.cpp, ur.cpp, reduced.cpp (the chapter-4 arms),
// selection.cpp (ik_branch_of, ik_choose, ik_solve_nearest), numeric.cpp
// (ik_numeric); ik_detail.hpp: what they share. The IkSolver adapter for
// motion: motion_ik.hpp.
#include <array>
#include <cstddef>
#include <cstdint>

#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/status.hpp"
#include "servoarm/kinematics/types.hpp"

namespace servoarm::kin {

inline constexpr int kMaxIkSolutions = 16;

enum class IkMethod : std::uint8_t {
  none,             ///< no closed form fits: use ik_numeric()
  spherical_wrist,  ///< 6 joints, spherical wrist (Pieper), one of E1/E2 decoupled (PUMA, Stanford)
  opw,              ///< 6 joints, spherical wrist, axes 2 and 3 parallel (OPW class: ABB, KUKA, ...)
  ur,               ///< 6 joints, axes 2, 3, 4 parallel, UR wrist (Universal Robots and alike)
  spherical_general,  ///< 6 joints, spherical wrist, neither: the degree-8 resultant (general path)
  planar_2r,        ///< RR planar: position in the plane
  planar_3,         ///< RRR / RLR planar: position in the plane + tool angle phi
  spatial_3,        ///< TRR-like: 3 joints, tool position
  pitch_4,          ///< TRL:R / VVL:R: tool position + wrist pitch phi
};
const char* to_string(IkMethod m);

/// Kinds of singularity, as bits.
enum SingularKind : std::uint8_t {
  kSingularNone = 0,
  kSingularWrist = 1,     ///< axes of joints 4 and 6 aligned (theta5 = 0 family)
  kSingularShoulder = 2,  ///< wrist centre on joint 1's axis / in the plane of axes 1 and 2
  kSingularElbow = 4,     ///< arm fully stretched or folded (elbow branches merge)
};
/// "wrist|shoulder" etc.; "none" for 0. Writes into buf (>= 32 chars) and returns it.
const char* singular_kinds_to_string(std::uint8_t kinds, char* buf, int size);

/// Branch of a solution: +1 / -1 each (0 where the method has no such branch).
struct Branch {
  std::int8_t shoulder = 0;
  std::int8_t elbow = 0;
  std::int8_t wrist = 0;
  bool operator==(const Branch&) const = default;
};

struct IkSolution {
  JointVector q;                ///< SI, wrapped into the limits where a 2*pi equivalent fits
  Branch branch{};
  bool within_limits = false;
  std::uint8_t singular = kSingularNone;  ///< SingularKind bits (0: regular)
  double position_error = 0;    ///< |p_fk - p_target| (m) of what the method controls
  double rotation_error = 0;    ///< rad
};

struct IkResult {
  /// ok            >= 1 solution, one within limits, none singular
  /// singular      as ok, but the target is at a singularity (see singular_kinds)
  /// out_of_limits solutions exist, none within the joint limits
  /// unreachable   no solution (count = 0)
  /// bad_input     NaN/Inf target, rotation not orthonormal (count = 0)
  /// wrong_size    the reference joints do not match the chain
  /// unsupported   no closed form fits this chain (use ik_numeric)
  Status status = Status::unreachable;
  int count = 0;
  std::uint8_t singular_kinds = kSingularNone;  ///< union over the solutions
  std::array<IkSolution, kMaxIkSolutions> solutions{};
};

namespace detail {
struct IkSolverData;    // kinematics/src/ik/ik_detail.hpp
struct IkSolverAccess;  // idem
/// In-place storage of what ik_prepare() precomputes for the closed-form
/// solvers (detail::IkSolverData, private to kinematics/src/ik/: the chain
/// rewritten as C0 J1 C1 ... Jn Cn, the coefficient matrices of the position
/// subproblem, the wrist's constant rotations, the per-joint wrap table...).
/// Fixed size, no heap; copying copies the data. kBytes is checked against
/// sizeof(IkSolverData) where that is defined (static_assert).
class IkSolverStorage {
 public:
  static constexpr std::size_t kBytes = 2944;
  static constexpr std::size_t kAlign = EIGEN_MAX_STATIC_ALIGN_BYTES > 16 ? EIGEN_MAX_STATIC_ALIGN_BYTES : 16;
  IkSolverStorage();
  IkSolverStorage(const IkSolverStorage& other);
  IkSolverStorage& operator=(const IkSolverStorage& other);
  ~IkSolverStorage();

 private:
  friend struct IkSolverAccess;
  alignas(kAlign) unsigned char bytes_[kBytes];
};
}  // namespace detail

/// A chain analysed for IK: build with ik_prepare(). A plain value of fixed
/// size (no heap; copies are independent), what the solvers precompute is
/// opaque (`solver`).
struct IkModel {
  IkMethod method = IkMethod::none;  ///< the closed form that fits (none: use ik_numeric)
  /// The chain analysed; its joint limits are the ones solutions are checked
  /// against (within_limits) and wrapped into.
  Chain chain{};
  /// spherical_wrist: the wrist centre (where axes 4, 5, 6 meet) in the tool
  /// frame, so that W = target * w_tool; zero for the other methods.
  Eigen::Vector3d w_tool = Eigen::Vector3d::Zero();
  detail::IkSolverStorage solver{};  ///< set-up data of the solvers (private to kinematics/src/ik/)
};

/// Analyse `chain`. ok (method set, possibly none), capacity, or bad_input.
Status ik_prepare(const Chain& chain, IkModel& model);

/// Every closed-form solution of `target` (tool pose in the base frame, SI).
/// `q_ref` (optional, SI, n joints): the current joints -- used for the free
/// joint of a singular family (keep it) and to pick the 2*pi equivalent inside
/// the limits. Arms with fewer than six joints read from the pose what they
/// control: planar_2r and spatial_3 the tool position only; planar_3 the
/// position and the heading phi about the base z axis (the rotation's z-angle);
/// pitch_4 the position, joint 1 from the direction of axis 2 (= axis 4) that
/// the target rotation implies, and the pitch phi about that axis. Their
/// solutions are verified against that reachable part (position_error,
/// rotation_error say how far it is from the full target).
/// Never returns NaN: failures leave count = 0.
void ik_solve_all(const IkModel& model, const Pose& target, const JointVector* q_ref, IkResult& result);

/// Weights and options for choosing one solution.
struct IkChoice {
  JointVector weights;           ///< per joint (empty: all 1)
  bool keep_branch = false;      ///< only solutions on q_current's branch
  bool allow_out_of_limits = false;
};

/// Branch of a configuration (what ik_solve_all would label it).
Branch ik_branch_of(const IkModel& model, const JointVector& q);

/// Index of the solution nearest to q_current (weighted, within limits unless
/// allowed, same branch if asked); -1 if none qualifies.
int ik_choose(const IkModel& model, const IkResult& result, const JointVector& q_current,
              const IkChoice& choice = {});

// ---------------------------------------------------------------------------
// Numerical IK: damped least squares with adaptive (Levenberg-Marquardt)
// damping, joint limits (clamping + limit-aware steps), optional weights.
// ---------------------------------------------------------------------------
struct IkNumericOptions {
  bool position_only = false;
  /// Task weights: position x, y, z (per metre), rotation x, y, z (per radian).
  Eigen::Matrix<double, 6, 1> task_weights = Eigen::Matrix<double, 6, 1>::Ones();
  int max_iterations = 50;        ///< per start
  int max_restarts = 16;          ///< extra random starts if the first fails (worst case 850 iterations)
  double tolerance_position = 1e-9;  ///< m
  double tolerance_rotation = 1e-9;  ///< rad
  double initial_damping = 1e-2;   ///< mu, relative to diag(J^T J)
  /// A start that has not halved its weighted error within this many
  /// iterations is abandoned (restart); 0: never (ik_solve_nearest: 0).
  int stall_iterations = 4;
  std::uint64_t seed = 0x5eed;    ///< restarts are deterministic
};

struct IkNumericResult {
  Status status = Status::not_converged;  ///< ok / not_converged / bad_input / wrong_size
  JointVector q;                          ///< best found, always within limits
  double position_error = 0;              ///< m
  double rotation_error = 0;              ///< rad (0 when position_only)
  int iterations = 0;                     ///< total over all starts
  int restarts = 0;
};

/// Solve from q_start (clamped into the limits). Worst case:
/// (1 + max_restarts) * max_iterations Jacobian evaluations and 6x6 solves.
void ik_numeric(const Chain& chain, const Pose& target, const JointVector& q_start,
                const IkNumericOptions& options, IkNumericResult& result);

/// One nearest solution for a control loop: closed form where the model has
/// one (nearest to q_current, within limits, keep_branch as asked), otherwise
/// the numerical solver from q_current. ok/singular: q_out set.
Status ik_solve_nearest(const IkModel& model, const Pose& target, const JointVector& q_current,
                        JointVector& q_out, const IkChoice& choice = {});

/// Adapter for kin::IkSolver (trajectory_cartesian.hpp): ctx = const IkModel*.
/// The chain argument must be the model's chain. Kept for the firmware until
/// it switches to make_ik_solver(model, {}) (motion_ik.hpp), which it wraps.
Status ik_nearest_fn(const Chain& chain, const Pose& target, const JointVector& q_near,
                     JointVector& q_out, void* ctx);

}  // namespace servoarm::kin
