// SPDX-License-Identifier: Apache-2.0
#pragma once
// What the IK sources (kinematics/src/ik/*.cpp) share; not installed.
//  * IkSolverData: what ik_prepare() precomputes, held in IkModel::solver,
//    and the one way to it (solver_data);
//  * the rules for wrapping a joint into its limits and their per-joint form;
//  * the model's decomposition C0 J1 C1 ... Jn Cn, the bases of a joint's
//    motion, the univariate equations every closed form solves;
//  * the solver parts' entry points (which file defines each is said there).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <new>

#include "../fast_trig.hpp"
#include "servoarm/kinematics/ik.hpp"
#include "servoarm/kinematics/orientation.hpp"

namespace servoarm::kin {

/// A rotation that is a signed permutation (column j = sign[j] * unit vector
/// idx[j]), as the constant transforms of DH rows with angles in multiples of
/// 90 degrees are: products with it are copies (set by ik_prepare()).
struct IkSignedPerm {
  bool is = false;
  std::array<std::int8_t, 3> idx{0, 1, 2};
  std::array<double, 3> sign{1, 1, 1};
};

/// How ik_solve_all wraps one joint into its limits (set by ik_prepare()).
/// kind 0: not revolute (never wrapped); 1: revolute whose limits span less
/// than a turn and lie within (-3 pi, 3 pi) -- at most one 2*pi equivalent of
/// an angle fits, found without the reference (for references within a
/// turn of the limits); 2: any other revolute joint (nearest to the reference).
struct IkJointWrap {
  std::uint8_t kind = 0;
  /// Revolute: an angle w in (-pi, pi] with |w| < in_abs is within the
  /// limits and its only 2*pi equivalent there, so every rule keeps it (the
  /// reduced paths' quick exit): 1e-9 or more inside the exact
  /// bounds (a float rounded down: it fills the padding after kind); 0: none.
  /// Always below pi (make_joint_wrap), so any v with |v| < in_abs is already
  /// in (-pi, pi): its own wrap, kept as it is.
  float in_abs = 0;
  double lo = 0, hi = 0;    ///< limits widened by 1e-12 (wrapping)
  double lo9 = 0, hi9 = 0;  ///< limits widened by 1e-9 (within_limits)
};

namespace detail {

/// What ik_prepare() precomputes for the closed-form solvers, held in place
/// in IkModel::solver (ik.hpp: IkSolverStorage). Plain data.
struct IkSolverData {
  int n = 0;  ///< joints
  // C0 J1 C1 ... Jn Cn
  std::array<Pose, kMaxJoints + 1> C{};
  std::array<bool, kMaxJoints> prismatic{};
  std::array<double, kMaxJoints> dir{};
  // Position subproblem (joints 1..3): E_k = b2^T M_k b3 (- right-hand side).
  Eigen::Matrix3d M1 = Eigen::Matrix3d::Zero(), M2 = Eigen::Matrix3d::Zero();
  double lambda = 0;                                  ///< l in E1
  Eigen::Vector3d w3 = Eigen::Vector3d::Zero();       ///< point after J3 motion (wrist centre; IkModel::w_tool in the tool frame)
  Eigen::Vector3d shoulder_dir = Eigen::Vector3d::UnitX();  ///< shoulder-branch direction (frame after J1)
  double scale = 1;                                   ///< typical length of the arm (m)
  // Wrist (spherical_wrist): M = Rz(m4) A Rz(m5) B Rz(m6).
  Eigen::Matrix3d A = Eigen::Matrix3d::Identity(), B = Eigen::Matrix3d::Identity();
  double wrist_P = 0, wrist_Q = 0, wrist_gz_vz = 0;
  /// The rotations of C0..C6 as signed permutations where they are one.
  std::array<IkSignedPerm, 7> perm{};
  /// Wrist flip: (m4 + pi, 2 phi5 - m5, m6 + pi) gives the same rotation as
  /// (m4, m5, m6), phi5 = atan2(wrist_Q, wrist_P) -- true when axes 4, 5 and
  /// 5, 6 are perpendicular (checked numerically at set-up). The solver then
  /// derives the second wrist solution from the first (no atan2).
  bool wrist_flip = false;
  double wrist_phi = 0;
  /// Per joint: wrapping into the limits (see IkJointWrap).
  std::array<IkJointWrap, kMaxJoints> wrap{};
  // Axes 2 and 3 parallel, not parallel to axis 1 (the OPW class; solve_position's
  // case P): joint 1 first. Every point fixed after the J3 motion keeps its
  // component along n_par, so  p0 . Rz(m1) n_par = beta  gives m1; then the
  // distance from axis 2, g(m3) = |(C2 Rz(m3) w)_xy|^2 = g_par . (1, c3, s3)
  // in the frame of joint 2 (C1), gives m3, and m2 turns it onto the target.
  // The UR arm (axes 2, 3, 4 parallel, ur.cpp) uses the same data with
  // n_par = axis 4 and w = the frame-4 origin (C3's translation).
  bool par23 = false;
  /// The general path's roots from the companion matrix's eigenvalues only,
  /// without the isolation tried first (polynomial.cpp: real_roots): for the
  /// tests and benchmarks that compare the two; false after ik_prepare.
  bool eigen_roots = false;
  Eigen::Vector3d n_par = Eigen::Vector3d::UnitZ();  ///< frame after J1 motion
  double beta = 0;                                   ///< n_par . (w3 or the UR wrist point)
  Eigen::Vector3d w_par = Eigen::Vector3d::Zero();   ///< the point w, frame after J3 motion
  Eigen::Vector3d g_par = Eigen::Vector3d::Zero();
  // UR wrist (ur.cpp): axis 5 normal to axis 4, axes 5 and 6 meet at a point fixed in
  // the tool (IkModel::w_tool). Axis 4 seen from the frame after the J6 motion:
  // u(m5) = C5^T Rz(-m5) C4^T e_z, whose z component is ur_u5 . (1, c5, s5).
  Eigen::Vector3d ur_u5 = Eigen::Vector3d::Zero();
  Eigen::Vector3d ur_c4z = Eigen::Vector3d::UnitZ();  ///< C4^T e_z
  // planar_2r (reduced.cpp): |(C1 Rz(m2) w3)_xy|^2 = red_co . (1, c2, s2).
  // planar_3: the same for J2 (revolute or prismatic basis); pitch_4:
  // |C2 J3(m3) w3|^2 = red_co . basis(m3). Fitted at set-up (target-independent).
  Eigen::Vector3d red_co = Eigen::Vector3d::Zero();
  bool red_fast = false;
  // pitch_4 (reduced.cpp): Rrest = C2 C3 C4 rotations, axis 2 in the tool frame
  // (red_n2 = row 2 of Rrest), and axis 2 in the frame after J1 motion as a unit
  // (cos, sin) pair of its xy direction (red_u, red_v).
  Eigen::Matrix3d red_Rrest = Eigen::Matrix3d::Identity();
  Eigen::Vector3d red_n2 = Eigen::Vector3d::UnitZ();
  double red_u = 1, red_v = 0;
  // pitch_4: joint 4's origin is p - R red_vtool for any target (red_vtool = C4^T t4, in
  // the tool frame); its squared distance from joint 2's origin, the distance equation's
  // right-hand side, is |R0^T (o4 - t0) - Rz(m1) t1|^2, with no pitch in it, and with C1's
  // offset along axis 1 (red_rhs_direct: its xy within 1e-12 scale) no joint 1 either.
  Eigen::Vector3d red_vtool = Eigen::Vector3d::Zero();
  bool red_rhs_direct = false;
  bool ur_zrot = false;           ///< C2, C3 rotate about z: C1 Rz2 C2 Rz3 C3 = C1 Rz(m2 + m3 + gamma)
  double ur_gc = 1, ur_gs = 0;     ///< cos, sin gamma
  bool ur_tilt = false;  ///< u_z = cos(m5 - phi5) exactly (ur_u5 = (0, h = 1)): see ur.cpp wrist_roots
  /// The reduced arms' 2-D closed forms (reduced.cpp), set up by
  /// model.cpp's detect_reduced and checked there against the decomposition
  /// on sample joint values (off where the check fails: the 3-D cheap paths
  /// answer). In the frame F whose z is the parallel axes (planar_2r,
  /// planar_3: the frame after C0; pitch_4: joint 2's frame, C1) the point f
  /// that the first of those joints turns is  f = sa + Rz(b) w  (middle joint
  /// revolute, angle b) or  sa + b w  (prismatic, w its unit in-plane axis),
  /// and the heading of the frame after the last motion is the sum of the
  /// revolute angles plus gamma (planar_3, pitch_4); tn: the last constant
  /// transform's translation (the tool point from that frame).
  struct Planar {
    bool on = false;
    bool pri = false;                                ///< middle joint prismatic
    double h = 0, hc = 1, hs = 0;                    ///< red_co's (b, c) = h (hc, hs), revolute middle joint
    Eigen::Vector3d sa = Eigen::Vector3d::Zero(), w = Eigen::Vector3d::Zero(), tn = Eigen::Vector3d::Zero();
    double gc = 1, gs = 0;                           ///< cos, sin gamma
    double gamma = 0, phase = 0;                     ///< gamma; the phase atan2(hs, hc) (planar_3's angles)
    Eigen::Vector3d z1 = Eigen::Vector3d::UnitZ(), o1 = Eigen::Vector3d::Zero();  ///< pitch_4: axis 1 in F
  } pl;
  /// spatial_3 with joints 1-3 revolute where solve_position takes its case A
  /// (one equation free of m2; TRR): that case's constants, so that
  /// reduced.cpp's solve_spatial_3_lanes solves the four configurations two
  /// at a time. The equation free of m2 is
  /// a3 - rhs + h3 cos(m3 - phase3) = 0 with rhs = |p0 - lambda ez|^2 (E1) or
  /// p0.z (E2); the other, (Mo b3) . (1, c2, s2) = 0 with Mo(0, 0) less its
  /// rhs; tol2: solve_basis's tolerance for that one.
  struct Spatial3 {
    bool on = false;
    bool q3_from_e1 = true;  ///< the equation free of m2 is E1 (else E2)
    double a3 = 0, h3 = 0, tol2 = 0;
    double hc3i = 0, hs3i = 0;  ///< (cos, sin) of phase3, over h3
    Eigen::Matrix3d Mo = Eigen::Matrix3d::Zero();
  } s3;
};
static_assert(sizeof(IkSolverData) <= IkSolverStorage::kBytes, "raise IkSolverStorage::kBytes (ik.hpp)");
static_assert(IkSolverStorage::kBytes - sizeof(IkSolverData) < 256, "lower IkSolverStorage::kBytes (ik.hpp)");
static_assert(alignof(IkSolverData) <= IkSolverStorage::kAlign, "raise IkSolverStorage::kAlign (ik.hpp)");

/// The one way to the data in an IkModel's storage (constructed there by
/// IkSolverStorage's constructors, model.cpp).
struct IkSolverAccess {
  static IkSolverData& get(IkSolverStorage& s) { return *std::launder(reinterpret_cast<IkSolverData*>(s.bytes_)); }
  static const IkSolverData& get(const IkSolverStorage& s) {
    return *std::launder(reinterpret_cast<const IkSolverData*>(s.bytes_));
  }
};
inline IkSolverData& solver_data(IkModel& m) { return IkSolverAccess::get(m.solver); }
inline const IkSolverData& solver_data(const IkModel& m) { return IkSolverAccess::get(m.solver); }

}  // namespace detail

}  // namespace servoarm::kin

namespace servoarm::kin::detail {

/// True if every coefficient is finite. Unlike Eigen's allFinite() (x - x
/// == 0) it raises no floating-point exception on Inf.
template <typename D>
inline bool all_finite(const Eigen::DenseBase<D>& m) {
  for (Eigen::Index c = 0; c < m.cols(); ++c)
    for (Eigen::Index r = 0; r < m.rows(); ++r)
      if (!std::isfinite(m(r, c))) return false;
  return true;
}

/// Motion of joint j by m: Rz(m) (revolute) or Tz(m) (prismatic).
inline Pose joint_motion(bool prismatic, double m) {
  Pose T = Pose::Identity();
  if (prismatic) {
    T.translation().z() = m;
  } else {
    const double c = std::cos(m), s = std::sin(m);
    T.linear() << c, -s, 0, s, c, 0, 0, 0, 1;
  }
  return T;
}

inline Eigen::Matrix3d rot_z(double m) {
  const double c = std::cos(m), s = std::sin(m);
  Eigen::Matrix3d R;
  R << c, -s, 0, s, c, 0, 0, 0, 1;
  return R;
}

// ---------------------------------------------------------------------------
// Wrapping a revolute joint into its limits (ik_solve_all): the rule, and the
// per-joint fast form that ik_prepare() sets up (IkJointWrap).
// ---------------------------------------------------------------------------
inline constexpr double kTwoPi = 2.0 * M_PI;

/// The rule: w (already in (-pi, pi]) -> the 2*pi equivalent within
/// [lo, hi] (the limits widened by 1e-12) nearest to ref; w itself if none
/// fits. O(1) but for far-off references: the equivalent nearest to ref, then
/// moved into the limits by at most 4 turns each way.
inline double wrap_into_limits(double w, double lo, double hi, double ref) {
  if (w >= lo && w <= hi && w + kTwoPi > hi && w - kTwoPi < lo) return w;  // the only equivalent inside
  // round((ref - w) / 2 pi) without a libm call (see sincos_poly)
  constexpr double magic = 6755399441055744.0;
  const double x = (ref - w) * (0.5 / M_PI);
  const double k = std::abs(x) < 1e15 ? (x + magic) - magic : 0.0;
  double v = w + kTwoPi * k;
  for (int i = 0; i < 4 && v > hi; ++i) v -= kTwoPi;
  for (int i = 0; i < 4 && v < lo; ++i) v += kTwoPi;
  return v >= lo && v <= hi ? v : w;
}

/// Set-up: the wrap data of one joint row.
inline IkJointWrap make_joint_wrap(const DhRow& r) {
  IkJointWrap j;
  j.lo = r.lower - 1e-12;
  j.hi = r.upper + 1e-12;
  j.lo9 = r.lower - 1e-9;
  j.hi9 = r.upper + 1e-9;
  if (r.type != JointType::revolute) return j;
  j.kind = (j.hi - j.lo < kTwoPi && j.lo > -3.0 * M_PI && j.hi < 3.0 * M_PI) ? 1 : 2;
  // w >= lo, w <= hi, w + 2 pi > hi, w - 2 pi < lo (wrap_into_limits' first test), with margin
  // (-in_abs, in_abs) within (a, b); b - a <= 2 pi - 2e-9, so half < pi
  const double a = std::max(j.lo, j.hi - kTwoPi) + 1e-9, b = std::min(j.hi, j.lo + kTwoPi) - 1e-9;
  const double half = std::min(-a, b);
  if (half > 0) {
    j.in_abs = static_cast<float>(std::min(half, 4.0));
    if (!(j.in_abs <= half)) j.in_abs = std::nextafter(j.in_abs, 0.0f);
  }
  return j;
}

/// True when wrap_narrow() gives what wrap_into_limits() gives for this
/// reference: kind 1 and ref within a turn of the limits (then the rule's
/// nearest equivalent lies within 3 turns of the range, inside the 4 it tries).
inline bool narrow_applies(const IkJointWrap& j, double ref) {
  return j.kind == 1 && ref >= j.lo - kTwoPi && ref <= j.hi + kTwoPi;
}

/// wrap_into_limits() for a kind-1 joint (span < 2 pi, limits within
/// (-3 pi, 3 pi)) and w in (-pi, pi]: at most one of w, w + 2 pi, w - 2 pi
/// fits, whatever the reference (below the limits only w + 2 pi can, above
/// them only w - 2 pi); w if none does. Branch-free.
inline double wrap_narrow(const IkJointWrap& j, double w) {
  const double r = w < j.lo ? w + kTwoPi : (w > j.hi ? w - kTwoPi : w);
  return ((r >= j.lo) & (r <= j.hi)) ? r : w;
}

/// Position and rotation error of q against target; false on FK failure.
bool pose_error(const Chain& chain, const JointVector& q, const Pose& target, double& ep, double& er);

/// A few Gauss-Newton/DLS steps on the full pose (position-only if asked):
/// polishes a closed-form solution that lost digits near a singularity.
void refine(const Chain& chain, const Pose& target, JointVector& q, int iterations, bool position_only);

// ---------------------------------------------------------------------------
// Shared by the parts of the closed-form solver (src/ik/*.cpp). The model's
// decomposition C0 J1 C1 ... Jn Cn and its joint kinds, the bases of a joint's
// motion, the univariate equations every part solves.
// ---------------------------------------------------------------------------
inline constexpr double kPi = M_PI;
inline constexpr double kVerifyPos = 1e-9;
inline constexpr double kVerifyRot = 1e-9;
inline constexpr double kNearSingular = 1e-6;

inline const Pose& C(const IkSolverData& m, int i) { return m.C[static_cast<std::size_t>(i)]; }
inline bool prism(const IkSolverData& m, int j) { return m.prismatic[static_cast<std::size_t>(j)]; }

// Basis of a joint's motion: (1, cos m, sin m) or (1, m, m^2), and its derivative.
inline Eigen::Vector3d basis(bool prismatic, double m) {
  if (prismatic) return {1.0, m, m * m};
  return {1.0, std::cos(m), std::sin(m)};
}
inline Eigen::Vector3d dbasis(bool prismatic, double m) {
  if (prismatic) return {0.0, 1.0, 2.0 * m};
  return {0.0, -std::sin(m), std::cos(m)};
}

// Point w (frame after J3 motion) in the frame after J1 motion.
inline Eigen::Vector3d f_of(const IkSolverData& m, double m2, double m3, const Eigen::Vector3d& w) {
  return C(m, 1) * (joint_motion(prism(m, 1), m2) * (C(m, 2) * (joint_motion(prism(m, 2), m3) * w)));
}

// ---------------------------------------------------------------------------
// Univariate equations and polynomials
// ---------------------------------------------------------------------------
struct Roots {
  double v[2] = {0, 0};  ///< the roots (revolute: angles, only if asked for)
  double c[2] = {0, 0};  ///< revolute: cos of the roots; prismatic: the roots
  double s[2] = {0, 0};  ///< revolute: sin of the roots
  std::int8_t label[2] = {1, -1};
  int n = 0;
  bool free = false;  ///< the equation holds for every value
};

/// k = cos t of a revolute root, clamped into [-1, 1] when it lies within
/// 1e-9 outside (rounding at a stretched / folded arm); false: no root.
/// solve_basis's and reduced.cpp's roots_rev's one rule.
inline bool clamp_cos(double& k) {
  if (k > 1.0) {
    if (k > 1.0 + 1e-9) return false;
    k = 1.0;
  } else if (k < -1.0) {
    if (k < -1.0 - 1e-9) return false;
    k = -1.0;
  }
  return true;
}

// a + b*x + c*y = 0 in the basis of a revolute (cos, sin) or prismatic (m, m^2) joint.
// Revolute: h cos(m - phi) = -a with (b, c) = h (cos phi, sin phi), so the
// roots are phi +- t, cos t = k = -a/h; their cosines and sines follow
// without trigonometry (sin t = sqrt((1 - k)(1 + k))), and the angles (one
// atan2 each) only when `angles` is set.
inline Roots solve_basis(double a, double b, double c, bool prismatic, double tol, bool angles = true) {
  Roots r;
  if (!prismatic) {
    const double h = std::sqrt(b * b + c * c);
    if (h <= tol) {
      r.free = std::abs(a) <= tol;
      return r;
    }
    double k = -a / h;
    if (!clamp_cos(k)) return r;
    const double cp = b / h, sp = c / h;
    const double st = std::sqrt((1.0 - k) * (1.0 + k));
    r.c[0] = cp * k - sp * st;  // phi + t
    r.s[0] = sp * k + cp * st;
    r.c[1] = cp * k + sp * st;  // phi - t
    r.s[1] = sp * k - cp * st;
    r.n = st > 0 ? 2 : 1;
    if (angles)
      for (int i = 0; i < r.n; ++i) r.v[i] = detail::atan2_poly(r.s[i], r.c[i]);
    return r;
  }
  const double sc = std::max({std::abs(a), std::abs(b), std::abs(c)});
  if (sc <= tol) {
    r.free = true;
    return r;
  }
  if (std::abs(c) <= 1e-12 * sc) {
    if (std::abs(b) <= 1e-12 * sc) return r;
    r.v[0] = r.c[0] = -a / b;
    r.n = 1;
    return r;
  }
  double disc = b * b - 4 * a * c;
  if (disc < 0) {
    if (disc < -1e-9 * b * b - 1e-18 * sc * sc) return r;
    disc = 0;
  }
  const double sq = std::sqrt(disc);
  // +label: the root with the + square root (per the sign of c)
  r.v[0] = r.c[0] = (-b + sq) / (2 * c);
  r.v[1] = r.c[1] = (-b - sq) / (2 * c);
  r.n = sq > 0 ? 2 : 1;
  return r;
}

/// Revolute roots phi +- t closer than 2e-6 rad (|sin 2t| < 2e-6: t near 0
/// or pi) are one configuration, the stretched / folded arm or the shoulder
/// at its boundary: keep one root, phi (or phi + pi), labelled +1. The kept
/// root is verified like any other (it misses the exact roots by ~t^2).
/// Not for joint 5 (theta5 = +-t are the two wrist configurations).
inline bool merge_close_roots(Roots& r) {
  if (r.n != 2) return false;
  // sin 2t and cos 2t from the two roots (t = pi/2 also has sin 2t = 0)
  if (!(std::abs(r.s[0] * r.c[1] - r.c[0] * r.s[1]) < 2e-6) || r.c[0] * r.c[1] + r.s[0] * r.s[1] < 0) return false;
  const double c = r.c[0] + r.c[1], s = r.s[0] + r.s[1];
  const double h = std::sqrt(c * c + s * s);
  r.c[0] = c / h;
  r.s[0] = s / h;
  r.v[0] = detail::atan2_poly(r.s[0], r.c[0]);
  r.n = 1;
  return true;
}

// ---------------------------------------------------------------------------
// Position subproblem: (m2, m3) candidates
// ---------------------------------------------------------------------------
struct PosCand {
  double m2 = 0, m3 = 0;  ///< motion values (revolute: angles, set only if asked for)
  std::int8_t elbow = 0;  ///< from the root (0: decide from the Jacobian)
  bool free2 = false;
  double c2 = 1, s2 = 0, c3 = 1, s3 = 0;  ///< revolute: cos, sin of m2, m3; prismatic: c = m
  /// Candidates with the same g2 (g3) >= 0 share the root m2 (m3) bit for
  /// bit (one atan2 for them).
  std::int8_t g2 = -1, g3 = -1;
};

// Motion value and its (cos, sin) pair (prismatic: the value in c).
inline void set_pair(bool prismatic, double v, double& c, double& s) {
  if (prismatic) {
    c = v;
    s = 0;
  } else {
    detail::sincos_poly(v, s, c);
  }
}
inline Eigen::Vector3d basis_cs(bool prismatic, double c, double s) {
  if (prismatic) return {1.0, c, c * c};
  return {1.0, c, s};
}

/// (m2, m3) candidates of the position subproblem for the point p0 (frame
/// after C0) with their (cos, sin) pairs; the angles m2, m3 only if `angles`
/// (the spherical-wrist solver computes every angle in one batch at the end).
/// Cases: one equation free of q2 or of q3 (closed form, position.cpp), else
/// the degree-8 resultant (solve_position_resultant, polynomial.cpp). <= 8.
int solve_position(const IkSolverData& m, const Eigen::Vector3d& p0, const double* ref_m2, PosCand* out,
                   bool angles = true);

/// Case P of solve_position (IkSolverData::par23; position.cpp): <= 4 candidates.
int solve_position_parallel(const IkSolverData& m, const Eigen::Vector3d& p0, const double* ref_m2, PosCand* out,
                            bool angles);

/// The general case of solve_position: q2 eliminated by the resultant, a
/// polynomial of degree <= 8 in tan(q3/2) (or d3), roots from its companion
/// matrix polished by Newton. M1, M2: the equations with the target's
/// right-hand sides subtracted. Returns the number of candidates (<= 8).
int solve_position_resultant(const IkSolverData& m, const Eigen::Matrix3d& M1, const Eigen::Matrix3d& M2, double tol1,
                             PosCand* out);

/// Real roots of c[0] + c[1] x + ... + c[deg] x^deg (1 <= deg <= 8,
/// c[deg] != 0), ascending, by isolation along the derivative chain
/// (polynomial.cpp): each root of p^(k) between consecutive real roots of
/// p^(k+1), where p^(k) is monotone, by safeguarded Newton in the bracket
/// (the critical points where a derivative nearly touches zero, a complex
/// pair within 1e-4 (1 + |x|) of the real axis, added as split points).
/// Returns the count (<= deg) or -1 when unsure, for the companion matrix to
/// answer: p itself nearly touches zero at a critical point (a near-double
/// root, by the same 1e-4 rule: the companion path's pair there is what the
/// path did before), some p^(k) at a root of its derivative is below
/// Horner's running rounding bound (a double root), a non-finite value, a
/// bracket not converged in 100 steps, an outer bracket not found in 60
/// widenings, more roots than the degree.
int real_roots_isolated(const double* c, int deg, double* out);
/// The same from the eigenvalues of the deg x deg companion matrix (the
/// fallback; imaginary part <= 1e-4 (1 + |real part|) counts as real).
int real_roots_eigen(const double* c, int deg, double* out);

// wrap_pi without a libm call for the small multiples of 2 pi that atan2
// sums produce (std::remainder costs ~20 ns; it ran 100+ times per solve).
inline double fast_wrap(double a) {
  for (int i = 0; i < 4; ++i) {
    if (a > kPi) a -= 2.0 * kPi;
    else if (a <= -kPi) a += 2.0 * kPi;
    else return a;
  }
  return wrap_pi(a);
}

inline double joint_distance(const Chain& c, int j, double a, double b) {
  const double d = a - b;
  return c.joint(j).type == JointType::revolute ? std::abs(fast_wrap(d)) : std::abs(d);
}

/// Finish a candidate (motion values mot, SI joints = dir * mot): wrap into
/// the limits, verify by the chain's FK (a few Gauss-Newton steps if it is
/// close but not within the tolerance), add unless a duplicate (position.cpp).
void add_candidate(const IkModel& m, const Pose& target, const JointVector* q_ref, const double* mot, Branch br,
                   std::uint8_t singular, bool position_only, IkResult& res);

/// Every solution of a spherical-wrist arm (spherical_wrist.cpp).
void solve_spherical(const IkModel& m, const Pose& target, const JointVector* q_ref, IkResult& res);
/// ik_solve_nearest's numerical path (and IkFallback::numeric's): ik_numeric
/// from q_current with no restarts, 100 iterations (selection.cpp).
/// ok: q_out set; unreachable: no convergence; bad_input / wrong_size.
Status ik_nearest_numeric(const Chain& chain, const Pose& target, const JointVector& q_current, JointVector& q_out);

/// Every solution of a UR-type arm (ur.cpp).
void solve_ur(const IkModel& m, const Pose& target, const JointVector* q_ref, IkResult& res);

/// Every solution of a reduced arm: planar_2r, planar_3, spatial_3, pitch_4 (reduced.cpp).
void solve_reduced(const IkModel& m, const Pose& target, const JointVector* q_ref, IkResult& res);
/// The 2-D closed forms alone (what solve_reduced tries first): true when
/// they answered (res holds their solutions), false when they hand the
/// target over (not set up for this arm, degenerate, a solution missing
/// 1e-9; res.count may have grown then). For the tests.
bool solve_reduced_2d(const IkModel& m, const Pose& target, const JointVector* q_ref, IkResult& res);
/// spatial_3's lanes alone (solve_spatial_3_lanes: case A, four configurations two at a
/// time; tests): false when not set up (IkSolverData::Spatial3) or handed over.
bool solve_spatial_3_lanes(const IkModel& m, const Pose& target, const JointVector* q_ref, IkResult& res);
/// The 3-D cheap paths alone (every joint's (cos, sin) pair, each candidate
/// verified through the decomposition's 3x3 products): the 2-D forms'
/// fallback, and what solve_reduced was before them (benchmark).
void solve_reduced_3d(const IkModel& m, const Pose& target, const JointVector* q_ref, IkResult& res);
/// The same through the chain's FK and Jacobian for every candidate (what
/// solve_reduced did before its cheap paths; their fallback for degenerate
/// targets, and the reference they are tested against). Not for planar_2r.
void solve_reduced_slow(const IkModel& m, const Pose& target, const JointVector* q_ref, IkResult& res);

}  // namespace servoarm::kin::detail
