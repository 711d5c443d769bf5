#pragma once
// Internal helpers shared by the IK sources (not installed).
#include <cmath>

#include "servoarm/kinematics/ik.hpp"

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


}  // namespace servoarm::kin::detail
