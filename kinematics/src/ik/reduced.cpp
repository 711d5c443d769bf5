// SPDX-License-Identifier: Apache-2.0
// Inverse kinematics, the reduced arms of Carrara, Apostila de Robótica, chapter 4 (ik.hpp):
// planar_2r (4.1), planar_3 (RRR, RLR: 4.2, 4.3), spatial_3 (TRR: 4.4, the
// position machinery of position.cpp with W = the tool point) and pitch_4
// (TRL:R, VVL:R: 4.5, 4.6). Real-time, heap-free.
#include <cmath>
#include <limits>

#include <Eigen/LU>

#include "ik_detail.hpp"

namespace servoarm::kin::detail {
// Not inlined into the flattened solve_reduced: the fallbacks are
// rare, and inlined they made every call pay for a larger frame and for
// Eigen's cache-size query of the slow path's dynamic-size product.
[[gnu::noinline]] void solve_reduced_slow(const IkModel& model, const Pose& target, const JointVector* q_ref,
                                          IkResult& res);
[[gnu::noinline]] void solve_reduced_3d(const IkModel& model, const Pose& target, const JointVector* q_ref,
                                        IkResult& res);
namespace {

// Coefficients (a, b, c) of g(m) = a + b x + c y in the basis of joint j,
// from three samples of g.
template <typename G>
Eigen::Vector3d fit_basis(bool prismatic, G g) {
  const double s[3] = {0.0, prismatic ? 1.0 : kPi / 2, prismatic ? -1.0 : kPi};
  Eigen::Matrix3d B;
  Eigen::Vector3d v;
  for (int i = 0; i < 3; ++i) {
    B.row(i) = basis(prismatic, s[i]).transpose();
    v[i] = g(s[i]);
  }
  return B.inverse() * v;
}

// solve_basis for a revolute joint with (h, phase) of (b, c) precomputed: the
// same roots bit for bit (h, hc, hs computed as solve_basis computes them).
inline Roots roots_rev(double a, const IkSolverData::Planar& pl, double* kst = nullptr) {
  Roots r;
  double k = -a / pl.h;
  if (!clamp_cos(k)) return r;
  const double st = std::sqrt((1.0 - k) * (1.0 + k));
  if (kst) {  // the roots are phase +- atan2(st, k)
    kst[0] = k;
    kst[1] = st;
  }
  r.c[0] = pl.hc * k - pl.hs * st;
  r.s[0] = pl.hs * k + pl.hc * st;
  r.c[1] = pl.hc * k + pl.hs * st;
  r.s[1] = pl.hs * k - pl.hc * st;
  r.n = st > 0 ? 2 : 1;
  return r;
}

// One joint value v = dir * motion (|v| <= pi) into the limits: what
// wrap_into_limits gives, branch-free for a joint whose limits span less than
// a turn (wrap_narrow; as the spherical-wrist and UR paths do).
// The quick exit first: |w| < in_abs is what both rules give (the seeds'
// reduced arms have +-180 degree limits: all but the angles within ~1e-7 of
// +-pi leave here).
// `in` cleared when the result is outside the limits widened by 1e-9 (the
// quick exit's w is inside them: in_abs <= hi - 1e-9, -in_abs >= lo + 1e-9).
// in_abs < pi (0 for a prismatic joint): |v| < in_abs is its own wrap, so
// that test comes before fast_wrap.
inline double wrap_joint(const IkJointWrap& jw, double v, double ref, bool& in) {
  if (std::abs(v) < jw.in_abs) return v;
  double q = v;
  if (jw.kind != 0) {
    const double w = fast_wrap(v);
    if (std::abs(w) < jw.in_abs) return w;
    q = narrow_applies(jw, ref) ? wrap_narrow(jw, w) : wrap_into_limits(w, jw.lo, jw.hi, ref);
  }
  in &= (q >= jw.lo9) & (q <= jw.hi9);
  return q;
}

// planar_2r (RR) in closed form with the cheap check (reduced arms
// <= 100 ns): the coefficients of |f(m2)_xy|^2 are fitted at set-up
// (IkSolverData::red_co); each root's tool point is verified through the
// decomposition, |Rz(m1) C1 Rz(m2) w - p0| (exact to rounding, C0 rigid),
// wrapped and stored here; only a candidate that misses 1e-9 m goes through
// add_candidate (the chain's FK and Gauss-Newton). Elbow singular: the two
// roots merged (|sin 2t| < 2e-6, as merge_close_roots).
void solve_planar_2r(const IkModel& model, const Pose& target, const JointVector* q_ref, IkResult& res) {
  const IkSolverData& m = solver_data(model);
  const Eigen::Vector3d p0 = C(m, 0).linear().transpose() * (target.translation() - C(m, 0).translation());
  const double tol = 1e-12 * m.scale * m.scale;
  // the 2-D form's (h, phase) when set up (IkSolverData::Planar): the same roots, no sqrt or division
  const double a2 = m.red_co[0] - (p0.x() * p0.x() + p0.y() * p0.y());
  Roots r2 = m.pl.on ? roots_rev(a2, m.pl) : solve_basis(a2, m.red_co[1], m.red_co[2], false, tol, false);
  if (r2.free || r2.n == 0) return;
  const bool merged = r2.n == 1 || merge_close_roots(r2);
  const Eigen::Matrix3d& R1 = C(m, 1).linear();
  const Eigen::Vector3d& t1 = C(m, 1).translation();
  const double ref0 = q_ref ? (*q_ref)[0] : 0.0, ref1 = q_ref ? (*q_ref)[1] : 0.0;
  const double p0xy2 = p0.x() * p0.x() + p0.y() * p0.y();
  double sy[4], sx[4], ang[4];
  double ep[2];
  std::uint8_t sing[2];
  for (int i = 0; i < r2.n; ++i) {
    const double c2 = r2.c[i], s2 = r2.s[i];
    Eigen::Vector3d f;
    if (m.pl.on) {  // f = sa + Rz(m2) w in the plane (setup_planar checked it against C1 Rz(m2) w3)
      f = Eigen::Vector3d(m.pl.sa.x() + (c2 * m.pl.w.x() - s2 * m.pl.w.y()),
                          m.pl.sa.y() + (s2 * m.pl.w.x() + c2 * m.pl.w.y()), m.pl.sa.z() + m.pl.w.z());
    } else {
      const Eigen::Vector3d w(c2 * m.w3.x() - s2 * m.w3.y(), s2 * m.w3.x() + c2 * m.w3.y(), m.w3.z());
      f = R1 * w + t1;
    }
    const double cr = f.x() * p0.y() - f.y() * p0.x(), dt = f.x() * p0.x() + f.y() * p0.y();
    const double r = cr * cr + dt * dt;
    double c1 = 1, s1 = 0;
    sing[i] = merged ? kSingularElbow : 0;
    if (r > 1e-36 * m.scale * m.scale * m.scale * m.scale && p0xy2 > 1e-18 * m.scale * m.scale) {
      const double ir = 1.0 / std::sqrt(r);
      c1 = dt * ir;
      s1 = cr * ir;
    } else {  // tool point on axis 1: joint 1 free (kept)
      detail::sincos_poly(m.dir[0] * ref0, s1, c1);
      sing[i] |= kSingularShoulder;
    }
    const Eigen::Vector3d d(c1 * f.x() - s1 * f.y() - p0.x(), s1 * f.x() + c1 * f.y() - p0.y(), f.z() - p0.z());
    ep[i] = d.norm();
    sy[2 * i] = s1;
    sx[2 * i] = c1;
    sy[2 * i + 1] = s2;
    sx[2 * i + 1] = c2;
  }
  if (r2.n == 1) {
    sy[2] = sy[3] = 0;
    sx[2] = sx[3] = 1;
  }
  detail::atan2_poly_x2(sy, sx, ang);
  detail::atan2_poly_x2(sy + 2, sx + 2, ang + 2);
  for (int i = 0; i < r2.n; ++i) {
    const double mot[2] = {ang[2 * i], ang[2 * i + 1]};
    Branch br;
    br.elbow = r2.label[i];
    if (!(ep[i] <= kVerifyPos)) {  // misses the tolerance: the chain's FK and Gauss-Newton
      if (ep[i] < 1e-4 * m.scale) add_candidate(model, target, q_ref, mot, br, sing[i], true, res);
      continue;
    }
    double q[2];
    bool in = true;
    for (int j = 0; j < 2; ++j) {
      const IkJointWrap& jw = m.wrap[static_cast<std::size_t>(j)];
      const double v = m.dir[static_cast<std::size_t>(j)] * mot[j];
      q[j] = wrap_joint(jw, v, j == 0 ? ref0 : ref1, in);
    }
    bool dup = false;
    for (int t = 0; t < res.count && !dup; ++t) {
      const JointVector& o = res.solutions[static_cast<std::size_t>(t)].q;
      dup = joint_distance(model.chain, 0, q[0], o[0]) <= 1e-7 && joint_distance(model.chain, 1, q[1], o[1]) <= 1e-7;
    }
    if (dup || res.count >= kMaxIkSolutions) continue;
    IkSolution& sol = res.solutions[static_cast<std::size_t>(res.count++)];
    sol.q.resize(2);
    sol.q[0] = q[0];
    sol.q[1] = q[1];
    sol.branch = br;
    sol.within_limits = in;
    sol.singular = sing[i];
    sol.position_error = ep[i];
    sol.rotation_error = 0;
  }
}

// ---------------------------------------------------------------------------
// The cheap path of planar_3, spatial_3 and pitch_4 (reduced arms
// <= 100 ns for all their solutions). Each joint's motion as its (cos, sin)
// pair (prismatic: the value in c), the angle by one atan2_poly; the
// candidate verified through the decomposition C0 J1 C1 ... Jn Cn (exact to
// rounding, as planar_2r) against the target, the elbow flag from the
// Jacobian columns of that same product (what the chain's Jacobian gave);
// only a candidate that misses 1e-9 goes through add_candidate (the chain's
// FK and Gauss-Newton).
// ---------------------------------------------------------------------------
struct MotCs {
  double v[4] = {0, 0, 0, 0};  ///< motion values (angles, or the prismatic value)
  double c[4] = {1, 1, 1, 1};  ///< revolute: cos; prismatic: the value
  double s[4] = {0, 0, 0, 0};
};

inline void set_rev(MotCs& mc, int j, double c, double s) {
  mc.c[j] = c;
  mc.s[j] = s;
}
inline void set_pri(MotCs& mc, int j, double v) {
  mc.v[j] = mc.c[j] = v;
  mc.s[j] = 0;
}

// R Rz(c, s) in place (the columns mixed), or nothing for a prismatic joint.
inline void turn(Eigen::Matrix3d& R, bool prismatic, double c, double s) {
  if (prismatic) return;
  const Eigen::Vector3d a = R.col(0), b = R.col(1);
  R.col(0) = c * a + s * b;
  R.col(1) = c * b - s * a;
}

// A times the rotation of C_i: where that is a signed permutation (the usual
// 0 / +-90 degree DH angles; IkSolverData::perm) a copy of signed columns.
inline Eigen::Matrix3d mul_c(const IkSolverData& m, const Eigen::Matrix3d& A, int i) {
  const IkSignedPerm& p = m.perm[static_cast<std::size_t>(i)];
  if (!p.is) return A * C(m, i).linear();
  Eigen::Matrix3d out;
  for (int k = 0; k < 3; ++k)
    out.col(k) = p.sign[static_cast<std::size_t>(k)] * A.col(p.idx[static_cast<std::size_t>(k)]);
  return out;
}

// (c, s) of atan2(y1, x1) - atan2(y0, x0) for (x0, y0) -> (x1, y1) (the
// rotation about z turning one onto the other); false when either is ~0.
inline bool turn_between(double x0, double y0, double x1, double y1, double eps2, double& c, double& s) {
  const double cr = x0 * y1 - y0 * x1, dt = x0 * x1 + y0 * y1;
  const double r = cr * cr + dt * dt;
  if (!(r > eps2)) return false;
  const double ir = 1.0 / std::sqrt(r);
  c = dt * ir;
  s = cr * ir;
  return true;
}

// Verify the candidate through the decomposition and store it (wrapped,
// de-duplicated, as add_candidate does); k_elbow > 0: the elbow flag from
// the position columns of the first k joints at the tool point.
void store_reduced(const IkModel& model, const Pose& target, const JointVector* q_ref, MotCs& mc, Branch br,
                   std::uint8_t sing, bool position_only, int k_elbow, IkResult& res) {
  const IkSolverData& m = solver_data(model);
  for (int j = 0; j < m.n; ++j)
    if (!prism(m, j)) mc.v[j] = detail::atan2_poly(mc.s[j], mc.c[j]);
  Eigen::Matrix3d R = C(m, 0).linear();
  Eigen::Vector3d t = C(m, 0).translation();
  Eigen::Vector3d z[4], o[4];
  for (int j = 0; j < m.n; ++j) {
    z[j] = R.col(2);
    o[j] = t;
    if (prism(m, j)) t += mc.c[j] * R.col(2);
    else turn(R, false, mc.c[j], mc.s[j]);
    t += R * C(m, j + 1).translation();
    R = mul_c(m, R, j + 1);
  }
  if (k_elbow > 0) {
    Eigen::Vector3d col[3];
    for (int j = 0; j < k_elbow; ++j) col[j] = prism(m, j) ? z[j] : Eigen::Vector3d(z[j].cross(t - o[j]));
    double prod = 1, det;
    if (k_elbow == 2) {
      const double g00 = col[0].squaredNorm(), g11 = col[1].squaredNorm(), g01 = col[0].dot(col[1]);
      prod = g00 * g11;
      det = g00 * g11 - g01 * g01;
    } else {
      Eigen::Matrix3d J;
      J << col[0], col[1], col[2];
      const Eigen::Matrix3d G = J.transpose() * J;
      prod = G(0, 0) * G(1, 1) * G(2, 2);
      det = G.determinant();
    }
    if (prod > 0 && det / prod < kNearSingular * kNearSingular) sing |= kSingularElbow;
  }
  const double ep = (t - target.translation()).norm();
  // |R - Rt|_F = 2 sqrt(2) sin(angle / 2): the angle to O(angle^3)
  const double er = position_only ? 0.0 : (R - target.linear()).norm() * M_SQRT1_2;
  if (!(ep <= kVerifyPos) || !(er <= kVerifyRot)) {  // the chain's FK and Gauss-Newton
    if (ep < 1e-4 * m.scale && er < 1e-4) add_candidate(model, target, q_ref, mc.v, br, sing, position_only, res);
    return;
  }
  double q[4] = {0, 0, 0, 0};
  bool in = true;
  for (int j = 0; j < m.n; ++j) {
    const IkJointWrap& jw = m.wrap[static_cast<std::size_t>(j)];
    const double v = m.dir[static_cast<std::size_t>(j)] * mc.v[j];
    q[j] = wrap_joint(jw, v, q_ref ? (*q_ref)[j] : 0.0, in);
  }
  if (!std::isfinite(q[0] + q[1] + q[2] + q[3])) return;
  for (int i = 0; i < res.count; ++i) {
    const JointVector& x = res.solutions[static_cast<std::size_t>(i)].q;
    bool same = true;
    for (int j = 0; j < m.n && same; ++j) same = joint_distance(model.chain, j, q[j], x[j]) <= 1e-7;
    if (same) return;
  }
  if (res.count >= kMaxIkSolutions) return;
  IkSolution& sol = res.solutions[static_cast<std::size_t>(res.count++)];
  sol.q.resize(m.n);
  for (int j = 0; j < m.n; ++j) sol.q[j] = q[j];
  sol.branch = br;
  sol.within_limits = in;
  sol.singular = sing;
  sol.position_error = ep;
  sol.rotation_error = er;
}

// planar_3 (RRR, RLR): the heading psi about the base z from the target, the
// point on axis 3 from the reachable pose, J2 from its distance to axis 1
// (red_co), J1 by one turn, J3 from the rotation left.
void solve_planar_3_fast(const IkModel& model, const Pose& target, const double* mref, const JointVector* q_ref,
                         IkResult& res) {
  const IkSolverData& m = solver_data(model);
  const Eigen::Matrix3d& R0 = C(m, 0).linear();
  const Eigen::Matrix3d& Rn = C(m, m.n).linear();
  // X = R0^T R_target Rn^T: only X(0, 0), X(1, 0) are needed
  const Eigen::Vector3d xv = target.linear() * Rn.row(0).transpose();
  double cp = R0.col(0).dot(xv), sp = R0.col(1).dot(xv);
  const double hp = cp * cp + sp * sp;
  if (!(hp > 1e-24)) return solve_reduced_slow(model, target, q_ref, res);
  const double ih = 1.0 / std::sqrt(hp);
  cp *= ih;
  sp *= ih;
  Eigen::Matrix3d R0z = R0;  // R0 Rz(psi) = eff.R Rn^T
  turn(R0z, false, cp, sp);
  Pose eff;
  eff.linear() = mul_c(m, R0z, m.n);
  eff.translation() = target.translation();
  // frame after the last joint motion: P = eff.t - R0z Rn^T... = eff.t - eff.R Cn^-1 part
  const Eigen::Vector3d P = target.translation() - R0z * C(m, m.n).translation();
  const Eigen::Vector3d p0 = R0.transpose() * (P - C(m, 0).translation());
  const double tol = 1e-12 * m.scale * m.scale;
  const double p0xy2 = p0.x() * p0.x() + p0.y() * p0.y();
  const bool p1 = prism(m, 1);
  Roots r2 = solve_basis(m.red_co[0] - p0xy2, m.red_co[1], m.red_co[2], p1, tol, false);
  if (r2.free) return solve_reduced_slow(model, target, q_ref, res);
  if (!p1) merge_close_roots(r2);  // stretched / folded: one configuration (as planar_2r)
  for (int i = 0; i < r2.n; ++i) {
    MotCs mc;
    Eigen::Vector3d w = m.w3;
    if (p1) {
      set_pri(mc, 1, r2.c[i]);
      w.z() += r2.c[i];
    } else {
      set_rev(mc, 1, r2.c[i], r2.s[i]);
      w = Eigen::Vector3d(r2.c[i] * m.w3.x() - r2.s[i] * m.w3.y(), r2.s[i] * m.w3.x() + r2.c[i] * m.w3.y(), m.w3.z());
    }
    const Eigen::Vector3d f = C(m, 1) * w;
    double c1, s1;
    if (f.x() * f.x() + f.y() * f.y() < 1e-18 * m.scale * m.scale ||
        !turn_between(f.x(), f.y(), p0.x(), p0.y(), 1e-36 * m.scale * m.scale * m.scale * m.scale, c1, s1))
      detail::sincos_poly(mref[0], s1, c1);
    set_rev(mc, 0, c1, s1);
    // J3 from the rotation: Rz(m3) = (R_before)^T eff.R Rn^T, R_before = R0 Rz1 C1 J2 C2
    Eigen::Matrix3d Rb = R0;
    turn(Rb, false, c1, s1);
    Rb = mul_c(m, Rb, 1);
    turn(Rb, p1, mc.c[1], mc.s[1]);
    Rb = mul_c(m, Rb, 2);
    double c3 = Rb.col(0).dot(R0z.col(0)), s3 = Rb.col(1).dot(R0z.col(0));
    const double h3 = c3 * c3 + s3 * s3;
    if (!(h3 > 1e-24)) continue;
    const double i3 = 1.0 / std::sqrt(h3);
    set_rev(mc, 2, c3 * i3, s3 * i3);
    Branch br;
    br.elbow = r2.label[i];
    store_reduced(model, eff, q_ref, mc, br, 0, false, 2, res);
  }
}

// pitch_4 (TRL:R, VVL:R): J1 from where axis 2 (= axis 4) points, the pitch
// about it, J3 from the distance |C2 J3 w3| (red_co), J2 by one turn, J4
// from the rotation left.
void solve_pitch_4_fast(const IkModel& model, const Pose& target, const JointVector* q_ref, IkResult& res) {
  const IkSolverData& m = solver_data(model);
  const Eigen::Matrix3d& R0 = C(m, 0).linear();
  const Eigen::Vector3d n2 = R0.transpose() * (target.linear() * m.red_n2);
  const double hn = n2.x() * n2.x() + n2.y() * n2.y();
  if (!(hn > 1e-24)) return solve_reduced_slow(model, target, q_ref, res);
  const double in = 1.0 / std::sqrt(hn);
  const double a = n2.x() * in, b = n2.y() * in;
  // m1 = atan2(b, a) - atan2(v, u)
  const double c1 = a * m.red_u + b * m.red_v, s1 = b * m.red_u - a * m.red_v;
  Eigen::Matrix3d R1 = R0;
  turn(R1, false, c1, s1);
  R1 = mul_c(m, R1, 1);
  // X = R1^T R_target Rrest^T: only X(0, 0), X(1, 0) are needed
  const Eigen::Vector3d xv = target.linear() * m.red_Rrest.row(0).transpose();
  double cs = R1.col(0).dot(xv), ss = R1.col(1).dot(xv);
  const double hs = cs * cs + ss * ss;
  if (!(hs > 1e-24)) return solve_reduced_slow(model, target, q_ref, res);
  const double is = 1.0 / std::sqrt(hs);
  cs *= is;
  ss *= is;
  Eigen::Matrix3d R1z = R1;  // eff.R Rrest^T
  turn(R1z, false, cs, ss);
  Pose eff;
  eff.linear() = R1z * m.red_Rrest;
  eff.translation() = target.translation();
  const Eigen::Matrix3d Rt = eff.linear() * C(m, m.n).linear().transpose();
  const Eigen::Vector3d P = target.translation() - Rt * C(m, m.n).translation();
  const Eigen::Vector3d p0 = R0.transpose() * (P - C(m, 0).translation());
  const Eigen::Vector3d g(c1 * p0.x() + s1 * p0.y(), c1 * p0.y() - s1 * p0.x(), p0.z());  // Rz(-m1) p0
  const Eigen::Vector3d gl = C(m, 1).linear().transpose() * (g - C(m, 1).translation());
  const double tol = 1e-12 * m.scale * m.scale;
  const bool p2 = prism(m, 2);
  const Roots r3 = solve_basis(m.red_co[0] - gl.squaredNorm(), m.red_co[1], m.red_co[2], p2, tol, false);
  if (r3.free) return solve_reduced_slow(model, target, q_ref, res);
  for (int i = 0; i < r3.n; ++i) {
    MotCs mc;
    set_rev(mc, 0, c1, s1);
    Eigen::Vector3d w = m.w3;
    if (p2) {
      set_pri(mc, 2, r3.c[i]);
      w.z() += r3.c[i];
    } else {
      set_rev(mc, 2, r3.c[i], r3.s[i]);
      w = Eigen::Vector3d(r3.c[i] * m.w3.x() - r3.s[i] * m.w3.y(), r3.s[i] * m.w3.x() + r3.c[i] * m.w3.y(), m.w3.z());
    }
    const Eigen::Vector3d h = C(m, 2) * w;
    double c2, s2;
    if (!turn_between(h.x(), h.y(), gl.x(), gl.y(), 1e-36 * m.scale * m.scale * m.scale * m.scale, c2, s2)) {
      c2 = 1;  // h or gl on axis 2 (atan2(0, 0) = 0 as before)
      s2 = 0;
    }
    set_rev(mc, 1, c2, s2);
    // J4: Rz(m4) = (R1 Rz2 C2 J3 C3)^T Rt
    Eigen::Matrix3d Rb = R1;
    turn(Rb, false, c2, s2);
    Rb = mul_c(m, Rb, 2);
    turn(Rb, p2, mc.c[2], mc.s[2]);
    Rb = mul_c(m, Rb, 3);
    double c4 = Rb.col(0).dot(Rt.col(0)), s4 = Rb.col(1).dot(Rt.col(0));
    const double h4 = c4 * c4 + s4 * s4;
    if (!(h4 > 1e-24)) continue;
    const double i4 = 1.0 / std::sqrt(h4);
    set_rev(mc, 3, c4 * i4, s4 * i4);
    Branch br;
    br.elbow = r3.label[i];
    store_reduced(model, eff, q_ref, mc, br, 0, false, 3, res);
  }
}

// spatial_3 (TRR): position only, (m2, m3) from solve_position as pairs, J1
// by one turn of the point onto the target.
void solve_spatial_3_fast(const IkModel& model, const Pose& target, const double* mref, const JointVector* q_ref,
                          IkResult& res) {
  const IkSolverData& m = solver_data(model);
  const Eigen::Vector3d p0 = C(m, 0).linear().transpose() * (target.translation() - C(m, 0).translation());
  PosCand pc[8];
  const int np = solve_position(m, p0, &mref[1], pc, false);
  for (int i = 0; i < np; ++i) {
    MotCs mc;
    Eigen::Vector3d w = m.w3;
    if (prism(m, 2)) {
      set_pri(mc, 2, pc[i].c3);
      w.z() += pc[i].c3;
    } else {
      set_rev(mc, 2, pc[i].c3, pc[i].s3);
      w = Eigen::Vector3d(pc[i].c3 * m.w3.x() - pc[i].s3 * m.w3.y(), pc[i].s3 * m.w3.x() + pc[i].c3 * m.w3.y(), m.w3.z());
    }
    w = C(m, 2) * w;
    if (prism(m, 1)) {
      set_pri(mc, 1, pc[i].c2);
      w.z() += pc[i].c2;
    } else {
      set_rev(mc, 1, pc[i].c2, pc[i].s2);
      w = Eigen::Vector3d(pc[i].c2 * w.x() - pc[i].s2 * w.y(), pc[i].s2 * w.x() + pc[i].c2 * w.y(), w.z());
    }
    const Eigen::Vector3d f = C(m, 1) * w;
    std::uint8_t sing = 0;
    double c1, s1;
    if (f.x() * f.x() + f.y() * f.y() < 1e-18 * m.scale * m.scale ||
        !turn_between(f.x(), f.y(), p0.x(), p0.y(), 1e-36 * m.scale * m.scale * m.scale * m.scale, c1, s1)) {
      detail::sincos_poly(mref[0], s1, c1);
      sing |= kSingularShoulder;
    }
    set_rev(mc, 0, c1, s1);
    Branch br;
    const double sh = f.dot(m.shoulder_dir);
    br.shoulder = sh >= 0 ? 1 : -1;
    if (std::abs(sh) < kNearSingular * m.scale) sing |= kSingularShoulder;
    br.elbow = pc[i].elbow;
    store_reduced(model, target, q_ref, mc, br, sing, true, 0, res);
  }
}

// ---------------------------------------------------------------------------
// The 2-D closed forms (reduced arms <= 100 ns for all their
// solutions). In the frame F of the parallel axes (IkSolverData::Planar,
// checked at set-up against the decomposition) the arm is a planar chain:
// the distance of the point f = sa + Rz(b) w (or sa + b w) from the first
// axis gives the middle joint (red_co, its (h, phase) precomputed), one turn
// of f onto the target point the first, the heading left the last. Each
// solution is verified by the same 2-D forward map (tool point and heading
// from its (cos, sin) pairs: the position error in metres, the heading's
// |(cos, sin) - (cos, sin)_target| = 2 sin(angle / 2) as the rotation error,
// what the 3-D paths measure), the elbow flag from the 2-D Jacobian columns
// at that tool point. All or nothing: a degenerate target (heading or turn
// undefined, an equation free) or a solution that misses 1e-9 hands the
// whole target to the 3-D cheap path (solve_*_fast above: their answers).
// ---------------------------------------------------------------------------

// Wrap, limit flags, de-duplication and storage of one verified solution (as
// store_reduced's tail; mot: the motion values).
inline void emit(const IkSolverData& m, const JointVector* q_ref, const double* mot, Branch br, std::uint8_t sing,
                 double ep, double er, IkResult& res) {
  const int n = m.n;
  double q[4] = {0, 0, 0, 0};
  bool in = true;
  for (int j = 0; j < n; ++j) {
    const IkJointWrap& jw = m.wrap[static_cast<std::size_t>(j)];
    const double v = m.dir[static_cast<std::size_t>(j)] * mot[j];
    q[j] = wrap_joint(jw, v, q_ref ? (*q_ref)[j] : 0.0, in);
  }
  if (!std::isfinite(q[0] + q[1] + q[2] + q[3])) return;
  for (int i = 0; i < res.count; ++i) {
    const JointVector& x = res.solutions[static_cast<std::size_t>(i)].q;
    bool same = true;
    for (int j = 0; j < n && same; ++j) {
      const double d = q[j] - x[j];
      same = (prism(m, j) ? std::abs(d) : std::abs(fast_wrap(d))) <= 1e-7;
    }
    if (same) return;
  }
  if (res.count >= kMaxIkSolutions) return;
  IkSolution& sol = res.solutions[static_cast<std::size_t>(res.count++)];
  sol.q.resize(n);
  double* d = sol.q.data();  // storage for kMaxJoints: four stores, not a memcpy of n
  d[0] = q[0];
  d[1] = q[1];
  d[2] = q[2];
  d[3] = q[3];
  sol.branch = br;
  sol.within_limits = in;
  sol.singular = sing;
  sol.position_error = ep;
  sol.rotation_error = er;
}

// One solution's fields (N joints, q wrapped): store_q's tail, and the
// stores of the lanes' solutions (emit_pair, solve_spatial_3_lanes) that
// need no search.
template <int N>
inline void set_solution(IkSolution& sol, const double* q, Branch br, bool in, std::uint8_t sing, double ep,
                         double er) {
  sol.q.resize(N);
  double* d = sol.q.data();
  for (int j = 0; j < N; ++j) d[j] = q[j];
  sol.branch = br;
  sol.within_limits = in;
  sol.singular = sing;
  sol.position_error = ep;
  sol.rotation_error = er;
}

// emit's de-duplication and storage for an N-joint solution q already
// wrapped (in: within the limits).
template <int N>
inline void store_q(const IkSolverData& m, const double* q, bool in, Branch br, std::uint8_t sing, double ep,
                    double er, IkResult& res) {
  for (int i = 0; i < res.count; ++i) {
    const JointVector& x = res.solutions[static_cast<std::size_t>(i)].q;
    bool same = true;
    for (int j = 0; j < N && same; ++j) {
      const double d = q[j] - x[j];
      same = (prism(m, j) ? std::abs(d) : std::abs(fast_wrap(d))) <= 1e-7;
    }
    if (same) return;
  }
  if (res.count >= kMaxIkSolutions) return;
  set_solution<N>(res.solutions[static_cast<std::size_t>(res.count++)], q, br, in, sing, ep, er);
}

// emit for the two lanes of a pair of N-joint solutions (motion values
// mot[j], lane i: solution i, emitted in that order): when every joint of
// both is a quick exit of wrap_joint (|dir * mot| < in_abs: its own wrap,
// within the limits, finite) or a prismatic joint with a finite value (not
// wrapped: its limit flag only), the wrap is one compare per joint and lane
// and the solutions go straight to store_q; else each through emit, as before.
// Mid: the middle joint, whose two roots the lanes hold (the other joints
// follow from it). WrapLast: the last joint (a revolute one) first takes two steps of
// fast_wrap in the lanes (the same subtractions: its value bit for bit where
// two steps suffice; planar_3's psi - gamma - a - b and pitch_4's s - a2 (- a3) lie outside (-pi, pi]
// for most targets), so that it can pass the quick exit.
template <int N, int Mid, bool WrapLast = false>
inline void emit_pair(const IkSolverData& m, const JointVector* q_ref, const v2d* mot, const std::int8_t* elbow,
                      v2m el, v2d ep, v2d er, IkResult& res) {
  v2d q[N];
  v2m quick = bc<v2d>(0.0) == bc<v2d>(0.0), in = quick;
  const v2m sign = (v2m)bc<v2d>(-0.0);
  for (int j = 0; j < N; ++j) {
    const IkJointWrap& jw = m.wrap[static_cast<std::size_t>(j)];
    q[j] = m.dir[static_cast<std::size_t>(j)] * mot[j];
    if (WrapLast && j == N - 1)
      for (int k = 0; k < 2; ++k)
        q[j] = select(q[j] > bc<v2d>(kPi), q[j] - 2.0 * kPi,
                      select(q[j] <= bc<v2d>(-kPi), q[j] + 2.0 * kPi, q[j]));
    const v2d aq = (v2d)((v2m)q[j] & ~sign);
    if (jw.kind == 0) {  // not wrapped (wrap_joint): the limit flag, and finite
      quick &= aq <= bc<v2d>(std::numeric_limits<double>::max());
      in &= (q[j] >= bc<v2d>(jw.lo9)) & (q[j] <= bc<v2d>(jw.hi9));
    } else {
      quick &= aq < bc<v2d>(static_cast<double>(jw.in_abs));
    }
  }
  const bool fast = both(quick);
  if (fast && res.count == 0) {
    // Two distinct configurations (the middle joint's roots more than 1e-7 apart:
    // store_q's rule, with margin; a revolute value lies in (-pi, pi), so also short
    // of 2 pi - 1e-6; else store_q decides): both stored as they are, without
    // store_q's search (unrolled: constant lane indices).
    const double d = std::abs(q[Mid][0] - q[Mid][1]);
    if ((d > 1e-7) & (prism(m, Mid) | (d < kTwoPi - 1e-6))) {
      IkSolution* out = res.solutions.data();
      res.count = 2;
      auto put = [&](IkSolution& sol, int i) {
        double qi[N];
        for (int j = 0; j < N; ++j) qi[j] = q[j][i];
        Branch br;
        br.elbow = elbow[i];
        set_solution<N>(sol, qi, br, in[i] != 0, el[i] ? kSingularElbow : 0, ep[i], er[i]);
      };
      put(out[0], 0);
      put(out[1], 1);
      return;
    }
  }
  for (int i = 0; i < 2; ++i) {
    Branch br;
    br.elbow = elbow[i];
    const std::uint8_t sing = el[i] ? kSingularElbow : 0;
    double qi[N];
    for (int j = 0; j < N; ++j) qi[j] = fast ? q[j][i] : mot[j][i];
    if (fast) store_q<N>(m, qi, in[i] != 0, br, sing, ep[i], er[i], res);
    else emit(m, q_ref, qi, br, sing, ep[i], er[i], res);
  }
}

// One 2-D solution: the pairs of the first and middle joint and, with a
// heading, the last joint's pair from the target heading (cp, sp) left.
struct Sol2d {             // every field set by core_2d (no initialisers: not zeroed per call)
  double ca, sa;  // first joint
  double cb, sb;  // middle joint (prismatic: the value in cb)
  double cc, sc;  // last joint (1, 0 without a heading)
  double ep, er;
  double tool[3];  // the verified tool point (F)
  std::uint8_t sing;
  std::int8_t elbow;
};

// Two solutions with a heading, one in each lane of a v2d (lanes.hpp):
// core_2d's forward map and checks on both roots at once, the same
// operations in the same order as its loop but the first joint's turn
// (1 / |P_xy|^2 for 1 / sqrt(rr): the same pair to rounding, see pair_2d;
// the rest of each lane is the loop's arithmetic, x86-64's baseline has no
// FMA to contract it).
struct Pair2d {
  v2d ca, sa;  // first joint
  v2d cb, sb;  // middle joint (prismatic: the value in cb)
  v2d cc, sc;  // last joint
  v2d ep, er;
  v2d tx, ty;  // the verified tool point (F)
  double tz;
  std::int8_t elbow[2];
};

inline bool pair_2d(const IkSolverData& m, const Eigen::Vector3d& pt, double Px, double Py, double cp, double sp,
                    const Roots& r, Pair2d& o) {
  const IkSolverData::Planar& pl = m.pl;
  const double sc2 = m.scale * m.scale;
  o.elbow[0] = r.label[0];
  o.elbow[1] = r.label[1];
  o.cb = v2d{r.c[0], r.c[1]};
  v2d fx, fy;
  double fz;
  if (pl.pri) {
    o.sb = bc<v2d>(0.0);
    fx = pl.sa.x() + o.cb * pl.w.x();
    fy = pl.sa.y() + o.cb * pl.w.y();
    fz = pl.sa.z();
  } else {
    o.sb = v2d{r.s[0], r.s[1]};
    fx = pl.sa.x() + (o.cb * pl.w.x() - o.sb * pl.w.y());
    fy = pl.sa.y() + (o.sb * pl.w.x() + o.cb * pl.w.y());
    fz = pl.sa.z() + pl.w.z();
  }
  const v2d cr = fx * Py - fy * Px, dt = fx * Px + fy * Py;
  const v2d rr = cr * cr + dt * dt;
  if (!both((rr > bc<v2d>(1e-36 * sc2 * sc2)) & (fx * fx + fy * fy > bc<v2d>(1e-18 * sc2)))) return false;
  // the turn of f onto P: (dt, cr) / (|f_xy| |P_xy|), and |f_xy| = |P_xy| at a root (its
  // equation; pitch_4's 3-D one with f_z = P_z where the target is in the arm's plane),
  // so (dt, cr) / |P_xy|^2: 1 / P2 needs no root, so no square root and division wait
  // for it (core_2d's loop divides by sqrt(rr); the same pair to rounding). A target
  // where they differ is out of reach: the forward map below misses it and hands over.
  const v2d ir = bc<v2d>(1.0 / (Px * Px + Py * Py));
  o.ca = dt * ir;
  o.sa = cr * ir;
  v2d tx = o.ca * fx - o.sa * fy, ty = o.sa * fx + o.ca * fy;
  double tz = fz;
  v2d hc = o.ca * pl.gc - o.sa * pl.gs, hs = o.sa * pl.gc + o.ca * pl.gs;
  if (!pl.pri) {
    const v2d x = hc * o.cb - hs * o.sb;
    hs = hs * o.cb + hc * o.sb;
    hc = x;
  }
  o.cc = cp * hc + sp * hs;
  o.sc = sp * hc - cp * hs;
  const v2d gc = hc * o.cc - hs * o.sc, gs = hs * o.cc + hc * o.sc;  // heading'
  tx += gc * pl.tn.x() - gs * pl.tn.y();
  ty += gs * pl.tn.x() + gc * pl.tn.y();
  tz += pl.tn.z();
  o.er = lsqrt((gc - cp) * (gc - cp) + (gs - sp) * (gs - sp));
  const v2d ex = tx - pt.x(), ey = ty - pt.y();
  const double ez = tz - pt.z();
  o.ep = lsqrt(ex * ex + ey * ey + ez * ez);
  if (!both((o.ep <= bc<v2d>(kVerifyPos)) & (o.er <= bc<v2d>(kVerifyRot)))) return false;
  o.tx = tx;
  o.ty = ty;
  o.tz = tz;
  return true;
}

// The core: target point pt (F; the tool point) and heading (cp, sp) (with
// heading) -> at most two verified solutions; false: hand over. With
// `pair`, two solutions with a heading go there (pair_2d), not to out, and
// ns = -2.
inline bool core_2d(const IkSolverData& m, const Eigen::Vector3d& pt, bool heading, bool merge, double cp, double sp,
                    const double* root_rhs, Sol2d* out, int& ns, double* kst = nullptr, bool* two_roots = nullptr,
                    Pair2d* pair = nullptr) {
  const IkSolverData::Planar& pl = m.pl;
  // the point that the first and middle joints place: joint 3's origin, or the tool point
  const double Px = heading ? pt.x() - (cp * pl.tn.x() - sp * pl.tn.y()) : pt.x();
  const double Py = heading ? pt.y() - (sp * pl.tn.x() + cp * pl.tn.y()) : pt.y();
  const double P2 = Px * Px + Py * Py;
  const double sc2 = m.scale * m.scale;
  Roots r;
  std::uint8_t merged = 0;
  // root_rhs: the distance equation's right-hand side when it is not |P_xy|^2 (pitch_4: |g|^2)
  const double rhs = root_rhs ? *root_rhs : P2;
  if (pl.pri) {
    r = solve_basis(m.red_co[0] - rhs, m.red_co[1], m.red_co[2], true, 1e-12 * sc2, false);
    if (r.free) return false;
  } else {
    r = roots_rev(m.red_co[0] - rhs, pl, kst);
    // stretched / folded: one configuration (as the 3-D paths); planar_2r flags it
    if (merge && r.n >= 1 && (merge_close_roots(r) || r.n == 1) && !heading) merged = kSingularElbow;
    // the two roots phase +- t as roots_rev gave them (not merged into one)
    if (two_roots) *two_roots = r.n == 2;
  }
  if (!(P2 > 1e-18 * sc2)) return false;  // point on the first axis: that joint is free
  ns = r.n;
  if (pair && heading && r.n == 2) {
    ns = -2;  // the pair's two (the callers read them from pair, not out)
    return pair_2d(m, pt, Px, Py, cp, sp, r, *pair);
  }
  for (int i = 0; i < r.n; ++i) {
    Sol2d& o = out[i];
    o.elbow = r.label[i];
    o.sing = merged;
    o.er = 0;
    o.cc = 1;
    o.sc = 0;
    double fx, fy, fz;
    if (pl.pri) {
      const double d = r.c[i];
      o.cb = d;
      o.sb = 0;
      fx = pl.sa.x() + d * pl.w.x();
      fy = pl.sa.y() + d * pl.w.y();
      fz = pl.sa.z();
    } else {
      o.cb = r.c[i];
      o.sb = r.s[i];
      fx = pl.sa.x() + (o.cb * pl.w.x() - o.sb * pl.w.y());
      fy = pl.sa.y() + (o.sb * pl.w.x() + o.cb * pl.w.y());
      fz = pl.sa.z() + pl.w.z();
    }
    const double cr = fx * Py - fy * Px, dt = fx * Px + fy * Py;
    const double rr = cr * cr + dt * dt;
    if (!(rr > 1e-36 * sc2 * sc2) || !(fx * fx + fy * fy > 1e-18 * sc2)) return false;
    const double ir = 1.0 / std::sqrt(rr);
    o.ca = dt * ir;
    o.sa = cr * ir;
    // the forward map: P' = Rz(a) f, heading' = a + b + c + gamma, tool' = P' + Rz(heading') tn
    double tx = o.ca * fx - o.sa * fy, ty = o.sa * fx + o.ca * fy, tzv = fz;
    if (heading) {
      // H = a + gamma (+ b): the heading before the last joint; c = psi - H
      double hc = o.ca * pl.gc - o.sa * pl.gs, hs = o.sa * pl.gc + o.ca * pl.gs;
      if (!pl.pri) {
        const double x = hc * o.cb - hs * o.sb;
        hs = hs * o.cb + hc * o.sb;
        hc = x;
      }
      o.cc = cp * hc + sp * hs;
      o.sc = sp * hc - cp * hs;
      const double gc = hc * o.cc - hs * o.sc, gs = hs * o.cc + hc * o.sc;  // heading'
      tx += gc * pl.tn.x() - gs * pl.tn.y();
      ty += gs * pl.tn.x() + gc * pl.tn.y();
      tzv += pl.tn.z();
      o.er = std::sqrt((gc - cp) * (gc - cp) + (gs - sp) * (gs - sp));
    }
    const double ex = tx - pt.x(), ey = ty - pt.y(), ez = tzv - pt.z();
    o.ep = std::sqrt(ex * ex + ey * ey + ez * ez);
    if (!(o.ep <= kVerifyPos) || !(o.er <= kVerifyRot)) return false;
    o.tool[0] = tx;
    o.tool[1] = ty;
    o.tool[2] = tzv;
  }
  return true;
}

// Elbow flag of planar_3 from the position columns of the first two joints at
// the tool point (F: their axes along z): ez x tool, ez x (tool - Rz(a) sa) or
// the prismatic axis Rz(a) w; |c1 x c2|^2 / (|c1|^2 |c2|^2) < kNearSingular^2
// (the Gram determinant the 3-D path takes, by Lagrange's identity).
inline bool elbow_2(const IkSolverData::Planar& pl, const Sol2d& o) {
  const double ax = -o.tool[1], ay = o.tool[0];
  double bx, by;
  if (pl.pri) {
    bx = o.ca * pl.w.x() - o.sa * pl.w.y();
    by = o.sa * pl.w.x() + o.ca * pl.w.y();
  } else {
    const double ox = o.ca * pl.sa.x() - o.sa * pl.sa.y(), oy = o.sa * pl.sa.x() + o.ca * pl.sa.y();
    bx = -(o.tool[1] - oy);
    by = o.tool[0] - ox;
  }
  const double g00 = ax * ax + ay * ay, g11 = bx * bx + by * by, g01 = ax * bx + ay * by;
  const double prod = g00 * g11, det = g00 * g11 - g01 * g01;
  return prod > 0 && det / prod < kNearSingular * kNearSingular;
}

// elbow_2 on a Pair2d (the mask of the lanes flagged).
inline v2m elbow_2_pair(const IkSolverData::Planar& pl, const Pair2d& o) {
  const v2d ax = -o.ty, ay = o.tx;
  v2d bx, by;
  if (pl.pri) {
    bx = o.ca * pl.w.x() - o.sa * pl.w.y();
    by = o.sa * pl.w.x() + o.ca * pl.w.y();
  } else {
    const v2d ox = o.ca * pl.sa.x() - o.sa * pl.sa.y(), oy = o.sa * pl.sa.x() + o.ca * pl.sa.y();
    bx = -(o.ty - oy);
    by = o.tx - ox;
  }
  const v2d g00 = ax * ax + ay * ay, g11 = bx * bx + by * by, g01 = ax * bx + ay * by;
  const v2d prod = g00 * g11, det = g00 * g11 - g01 * g01;
  const v2m pos = prod > bc<v2d>(0.0);
  return pos & (det / select(pos, prod, bc<v2d>(1.0)) < bc<v2d>(kNearSingular * kNearSingular));
}

// planar_2r and planar_3 in 2-D (F = the frame after C0).
// GCC 12 takes s[0] for unset after core_2d's pair exit (ns = -2, s unread
// then): a false positive of the flattened solve_reduced, here and in solve_pitch_4_2d
// below. (GCC only: clang has no such warning group and -Werror refuses an unknown one.)
#pragma GCC diagnostic push
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
bool solve_planar_2d(const IkModel& model, const Pose& target, const JointVector* q_ref, IkResult& res) {
  const IkSolverData& m = solver_data(model);
  const bool heading = model.method == IkMethod::planar_3;
  const Eigen::Matrix3d& R0 = C(m, 0).linear();
  const Eigen::Vector3d pt = R0.transpose() * (target.translation() - C(m, 0).translation());
  double cp = 1, sp = 0;
  if (heading) {
    const Eigen::Vector3d xv = target.linear() * C(m, m.n).linear().row(0).transpose();
    cp = R0.col(0).dot(xv);
    sp = R0.col(1).dot(xv);
    const double hp = cp * cp + sp * sp;
    if (!(hp > 1e-24)) return false;
    const double ih = 1.0 / std::sqrt(hp);
    cp *= ih;
    sp *= ih;
  }
  Sol2d s[2];
  int ns = 0;
  double kst[2] = {1, 0};
  bool two = false;
  Pair2d pr;
  if (!core_2d(m, pt, heading, !m.pl.pri, cp, sp, nullptr, s, ns, kst, &two, &pr)) return false;
  if (ns == -2) {
    // planar_3, two solutions (core_2d gave them in the lanes of pr): four
    // angles in two atan2_poly_v2, not six in three -- the first
    // joint's two, then (revolute middle joint, RRR) t (its roots are
    // phase +- t, roots_rev) and the target heading psi, the last joint
    // psi - gamma - a - b (the heading left: its pair (cc, sc) is what the
    // forward map verified, the same angle to rounding); prismatic middle
    // joint (RLR): the last joint's two.
    const v2d a = detail::atan2_poly_v2(pr.sa, pr.ca);
    v2d b = pr.cb, c;
    if (!m.pl.pri) {  // two roots: phase +- t
      const v2d tp = detail::atan2_poly_v2(v2d{kst[1], sp}, v2d{kst[0], cp});
      b = v2d{m.pl.phase + tp[0], m.pl.phase - tp[0]};
      const double h0 = tp[1] - m.pl.gamma;
      c = h0 - a - b;
    } else {
      c = detail::atan2_poly_v2(pr.sc, pr.cc);
    }
    const v2d mot[3] = {a, b, c};
    if (!m.pl.pri) emit_pair<3, 1, true>(m, q_ref, mot, pr.elbow, elbow_2_pair(m.pl, pr), pr.ep, pr.er, res);
    else emit_pair<3, 1>(m, q_ref, mot, pr.elbow, elbow_2_pair(m.pl, pr), pr.ep, pr.er, res);
    return true;
  }
  // the angles two at a time: (a, b) per solution, then the two c (planar_3)
  double y[6] = {0, 0, 0, 0, 0, 0}, x[6] = {1, 1, 1, 1, 1, 1}, ang[6];
  for (int i = 0; i < ns; ++i) {
    y[2 * i] = s[i].sa;
    x[2 * i] = s[i].ca;
    y[2 * i + 1] = s[i].sb;
    x[2 * i + 1] = s[i].cb;
    y[4 + i] = s[i].sc;
    x[4 + i] = s[i].cc;
  }
  detail::atan2_poly_x2(y, x, ang);
  if (ns == 2) detail::atan2_poly_x2(y + 2, x + 2, ang + 2);
  if (heading) detail::atan2_poly_x2(y + 4, x + 4, ang + 4);
  for (int i = 0; i < ns; ++i) {
    double mot[3] = {ang[2 * i], m.pl.pri ? s[i].cb : ang[2 * i + 1], ang[4 + i]};
    Branch br;
    br.elbow = s[i].elbow;
    const std::uint8_t sing = heading ? (elbow_2(m.pl, s[i]) ? kSingularElbow : 0) : s[i].sing;
    emit(m, q_ref, mot, br, sing, s[i].ep, s[i].er, res);
  }
  return true;
}

// pitch_4 in 2-D: joint 1 and the pitch as solve_pitch_4_fast takes them,
// then the core in joint 2's frame (F = C1 after the J1 motion); the elbow
// flag from the first three joints' position columns (triple product).
bool solve_pitch_4_2d(const IkModel& model, const Pose& target, const JointVector* q_ref, IkResult& res) {
  const IkSolverData& m = solver_data(model);
  const IkSolverData::Planar& pl = m.pl;
  const Eigen::Matrix3d& R0 = C(m, 0).linear();
  const Eigen::Vector3d n2 = R0.transpose() * (target.linear() * m.red_n2);
  const double hn = n2.x() * n2.x() + n2.y() * n2.y();
  if (!(hn > 1e-24)) return false;
  const double in = 1.0 / std::sqrt(hn);
  // joint 1's pair scaled by |n2_xy| (c1u, s1u) turns R1 for the pitch, a direction
  // normalised below anyway: its square root need not wait for this one (the path's
  // time is its chain of square roots and divisions, not its instruction count)
  const double c1u = n2.x() * m.red_u + n2.y() * m.red_v, s1u = n2.y() * m.red_u - n2.x() * m.red_v;
  const double c1 = c1u * in, s1 = s1u * in;
  Eigen::Matrix3d R1 = R0;
  turn(R1, false, c1u, s1u);
  R1 = mul_c(m, R1, 1);
  const Eigen::Vector3d xv = target.linear() * m.red_Rrest.row(0).transpose();
  double cs = R1.col(0).dot(xv), ss = R1.col(1).dot(xv);
  const double hs = cs * cs + ss * ss;  // |n2_xy|^2 times the unscaled one
  if (!(hs > 1e-24 * hn)) return false;
  const double is = 1.0 / std::sqrt(hs);
  cs *= is;
  ss *= is;
  // heading in F: s + gamma
  const double cp = cs * pl.gc - ss * pl.gs, sp = ss * pl.gc + cs * pl.gs;
  // the tool point in F: C1^-1 Rz(-m1) R0^T (p - t0)
  const Eigen::Vector3d p0 = R0.transpose() * (target.translation() - C(m, 0).translation());
  const Eigen::Vector3d g(c1 * p0.x() + s1 * p0.y(), c1 * p0.y() - s1 * p0.x(), p0.z());
  const Eigen::Vector3d pt = C(m, 1).linear().transpose() * (g - C(m, 1).translation());
  // the distance equation in 3-D, as the 3-D path: |joint 4's origin|^2 in F, that
  // origin o4 = p - R red_vtool taken straight from the target, so that its roots need
  // not wait for the pitch's square root and division (and, with C1's offset along axis
  // 1, red_rhs_direct, not for joint 1's either). The same value where the target's
  // rotation is one the arm reaches; where it is not, the 2-D map misses and hands over,
  // as before.
  const Eigen::Vector3d o4 = R0.transpose() * (target.translation() - target.linear() * m.red_vtool -
                                               C(m, 0).translation());
  const Eigen::Vector3d& t1 = C(m, 1).translation();
  double ox = o4.x(), oy = o4.y();
  if (!m.red_rhs_direct) {
    ox -= c1 * t1.x() - s1 * t1.y();
    oy -= s1 * t1.x() + c1 * t1.y();
  }
  const double oz = o4.z() - t1.z();
  const double rhs = ox * ox + oy * oy + oz * oz;
  Sol2d s[2];
  int ns = 0;
  Pair2d pr;
  if (!core_2d(m, pt, true, false, cp, sp, &rhs, s, ns, nullptr, nullptr, &pr)) return false;
  if (ns == -2) {  // the two solutions in the lanes of pr: the angles and the elbow flags two at a time
    // joint 1 and the pitch s (the target heading less gamma) in one atan2_poly_v2, then
    // joint 2's two (and, revolute, joint 3's); joint 4 = s - a2 (- a3): the heading
    // left, whose pair (cc, sc) the forward map verified (the same angle to rounding;
    // the last joint wrapped in the lanes, as planar_3's)
    const v2d a1s = detail::atan2_poly_v2(v2d{s1, ss}, v2d{c1, cs});
    const v2d a2 = detail::atan2_poly_v2(pr.sa, pr.ca);
    const v2d a3 = pl.pri ? pr.cb : detail::atan2_poly_v2(pr.sb, pr.cb);
    const v2d a4 = pl.pri ? a1s[1] - a2 : (a1s[1] - a2) - a3;
    // elbow: columns of joints 1, 2, 3 at the tool point (F), as below, with k2z = k3z
    // = 0 (joint 3 revolute: its column lies in the plane; prismatic: the 2-D forward map
    // takes w.z as 0, set-up checked |w.z| <= 1e-12), so k2 x k3 = (0, 0, cz)
    const v2d dx = pr.tx - pl.o1.x(), dy = pr.ty - pl.o1.y();
    const double dz = pr.tz - pl.o1.z();
    const v2d k1x = pl.z1.y() * dz - pl.z1.z() * dy, k1y = pl.z1.z() * dx - pl.z1.x() * dz,
              k1z = pl.z1.x() * dy - pl.z1.y() * dx;
    const v2d k2x = -pr.ty, k2y = pr.tx;
    v2d k3x, k3y;
    if (pl.pri) {
      k3x = pr.ca * pl.w.x() - pr.sa * pl.w.y();
      k3y = pr.sa * pl.w.x() + pr.ca * pl.w.y();
    } else {
      const v2d ox = pr.ca * pl.sa.x() - pr.sa * pl.sa.y(), oy = pr.sa * pl.sa.x() + pr.ca * pl.sa.y();
      k3x = -(pr.ty - oy);
      k3y = pr.tx - ox;
    }
    const v2d det = k1z * (k2x * k3y - k2y * k3x);
    const v2d prod = (k1x * k1x + k1y * k1y + k1z * k1z) * (k2x * k2x + k2y * k2y) * (k3x * k3x + k3y * k3y);
    const v2m pos = prod > bc<v2d>(0.0);
    const v2m el = pos & (det * det / select(pos, prod, bc<v2d>(1.0)) < bc<v2d>(kNearSingular * kNearSingular));
    const v2d mot[4] = {bc<v2d>(a1s[0]), a2, a3, a4};
    emit_pair<4, 2, true>(m, q_ref, mot, pr.elbow, el, pr.ep, pr.er, res);
    return true;
  }
  double y[6] = {0, 0, 0, 0, 0, 0}, x[6] = {1, 1, 1, 1, 1, 1}, ang[6];
  y[0] = s1;
  x[0] = c1;
  for (int i = 0; i < ns; ++i) {
    y[1 + 2 * i] = s[i].sa;
    x[1 + 2 * i] = s[i].ca;
    y[2 + 2 * i] = s[i].sc;
    x[2 + 2 * i] = s[i].cc;
  }
  detail::atan2_poly_x2(y, x, ang);
  detail::atan2_poly_x2(y + 2, x + 2, ang + 2);
  if (ns == 2) ang[4] = detail::atan2_poly(y[4], x[4]);
  double mb[2] = {0, 0}, yb[2] = {0, 0}, xb[2] = {1, 1};
  for (int i = 0; i < ns; ++i) {
    mb[i] = xb[i] = s[i].cb;
    yb[i] = s[i].sb;
  }
  if (!pl.pri) detail::atan2_poly_x2(yb, xb, mb);
  for (int i = 0; i < ns; ++i) {
    const Sol2d& o = s[i];
    // elbow: columns of joints 1, 2, 3 at the tool point (F)
    const Eigen::Vector3d t(o.tool[0], o.tool[1], o.tool[2]);
    const Eigen::Vector3d k1 = pl.z1.cross(t - pl.o1);
    const Eigen::Vector3d k2(-t.y(), t.x(), 0.0);
    Eigen::Vector3d k3;
    if (pl.pri) {
      k3 = Eigen::Vector3d(o.ca * pl.w.x() - o.sa * pl.w.y(), o.sa * pl.w.x() + o.ca * pl.w.y(), pl.w.z());
    } else {
      const double ox = o.ca * pl.sa.x() - o.sa * pl.sa.y(), oy = o.sa * pl.sa.x() + o.ca * pl.sa.y();
      k3 = Eigen::Vector3d(-(t.y() - oy), t.x() - ox, 0.0);
    }
    const double det = k1.dot(k2.cross(k3));
    const double prod = k1.squaredNorm() * k2.squaredNorm() * k3.squaredNorm();
    const std::uint8_t sing = (prod > 0 && det * det / prod < kNearSingular * kNearSingular) ? kSingularElbow : 0;
    const double mot[4] = {ang[0], ang[1 + 2 * i], mb[i], ang[2 + 2 * i]};
    Branch br;
    br.elbow = o.elbow;
    emit(m, q_ref, mot, br, sing, o.ep, o.er, res);
  }
  return true;
}

#pragma GCC diagnostic pop

// spatial_3 (TRR) with the cheap check on the point only: solve_position's
// pairs, J1 by one turn, the tool point Rz(m1) f against the target (no
// rotation products: the arm places a point), the angles in pairs.
bool solve_spatial_3_2d(const IkModel& model, const Pose& target, const double* mref, const JointVector* q_ref,
                        IkResult& res) {
  const IkSolverData& m = solver_data(model);
  const Eigen::Vector3d p0 = C(m, 0).linear().transpose() * (target.translation() - C(m, 0).translation());
  PosCand pc[8];
  const int np = solve_position(m, p0, &mref[1], pc, false);
  if (np > 4) return false;
  const double sc2 = m.scale * m.scale;
  double y[12], x[12], ang[12];
  double ep[4];
  Branch br[4];
  std::uint8_t sing[4];
  for (int i = 0; i < np; ++i) {
    Eigen::Vector3d w = m.w3;
    if (prism(m, 2)) w.z() += pc[i].c3;
    else w = Eigen::Vector3d(pc[i].c3 * m.w3.x() - pc[i].s3 * m.w3.y(), pc[i].s3 * m.w3.x() + pc[i].c3 * m.w3.y(), m.w3.z());
    w = C(m, 2) * w;
    if (prism(m, 1)) w.z() += pc[i].c2;
    else w = Eigen::Vector3d(pc[i].c2 * w.x() - pc[i].s2 * w.y(), pc[i].s2 * w.x() + pc[i].c2 * w.y(), w.z());
    const Eigen::Vector3d f = C(m, 1) * w;
    const double cr = f.x() * p0.y() - f.y() * p0.x(), dt = f.x() * p0.x() + f.y() * p0.y();
    const double rr = cr * cr + dt * dt;
    if (!(f.x() * f.x() + f.y() * f.y() >= 1e-18 * sc2) || !(rr > 1e-36 * sc2 * sc2)) return false;
    const double ir = 1.0 / std::sqrt(rr);
    const double c1 = dt * ir, s1 = cr * ir;
    const double ex = c1 * f.x() - s1 * f.y() - p0.x(), ey = s1 * f.x() + c1 * f.y() - p0.y(), ez = f.z() - p0.z();
    ep[i] = std::sqrt(ex * ex + ey * ey + ez * ez);
    if (!(ep[i] <= kVerifyPos)) return false;
    sing[i] = 0;
    const double sh = f.dot(m.shoulder_dir);
    br[i].shoulder = sh >= 0 ? 1 : -1;
    if (std::abs(sh) < kNearSingular * m.scale) sing[i] |= kSingularShoulder;
    br[i].elbow = pc[i].elbow;
    y[3 * i] = s1;
    x[3 * i] = c1;
    y[3 * i + 1] = pc[i].s2;
    x[3 * i + 1] = pc[i].c2;
    y[3 * i + 2] = pc[i].s3;
    x[3 * i + 2] = pc[i].c3;
  }
  const int na = 3 * np;
  for (int k = na; k < 12; ++k) {
    y[k] = 0;
    x[k] = 1;
  }
  for (int k = 0; k < na; k += 2) detail::atan2_poly_x2(y + k, x + k, ang + k);
  for (int i = 0; i < np; ++i) {
    const double mot[3] = {ang[3 * i], prism(m, 1) ? pc[i].c2 : ang[3 * i + 1], prism(m, 2) ? pc[i].c3 : ang[3 * i + 2]};
    emit(m, q_ref, mot, br[i], sing[i], ep[i], 0.0, res);
  }
  return true;
}

// spatial_3 (TRR) two configurations at a time (four solutions
// in <= 100 ns): solve_position's case A (IkSolverData::Spatial3) with the
// two roots of m3 (the elbow) in the lanes of a v2d: for each, the two roots
// of m2 (m2's equation with that m3), the point f = C1 Rz(m2) C2 Rz(m3) w3,
// m1 by one turn of f onto the target (the shoulder branch from f, as
// solve_spatial_3_fast), the tool point Rz(m1) f checked against it (1e-9).
// The solutions in solve_position's order (m3 roots outer, m2 roots inner).
// Hands over (false, nothing stored) unless all four exist and verify and
// every root pair is at least 1e-6 apart in its sine: the forms before it
// (solve_spatial_3_2d, the 3-D path) answer those targets. Roots that far
// apart are four distinct configurations, so no de-duplication; the quick
// wrap exit of every joint value, or emit for each.
bool solve_spatial_3_lanes(const IkSolverData& m, const Eigen::Vector3d& p0, const JointVector* q_ref,
                           IkResult& res) {
  const IkSolverData::Spatial3& sp = m.s3;
  const double e1 = (p0 - m.lambda * Eigen::Vector3d::UnitZ()).squaredNorm(), e2 = p0.z();
  // m3: a3 - rhs + h3 cos(m3 - phase3) = 0 (solve_basis's roots; (hc3i, hs3i) h3 = (cos, sin) phase3):
  // k = cos t = -A / h3 (A = a3 - rhs), h3 sin t = sqrt(h3^2 - A^2); sin t > 1e-6 on the
  // squares (it also refuses |k| > 1), no division in the chain
  const double A = sp.a3 - (sp.q3_from_e1 ? e1 : e2);
  const double D3 = sp.h3 * sp.h3 - A * A;
  if (!(D3 > 1e-12 * (sp.h3 * sp.h3))) return false;
  const double sD3 = std::sqrt(D3);  // h3 sin t
  const v2d pm = v2d{1.0, -1.0};
  const v2d c3 = bc<v2d>(-A * sp.hc3i) - pm * (sp.hs3i * sD3), s3 = bc<v2d>(-A * sp.hs3i) + pm * (sp.hc3i * sD3);
  // m2's equation per m3 root: u = Mo b3 (Mo(0, 0) less its rhs)
  const Eigen::Matrix3d& Mo = sp.Mo;
  const double mo00 = Mo(0, 0) - (sp.q3_from_e1 ? e2 : e1);
  const v2d u0 = mo00 + Mo(0, 1) * c3 + Mo(0, 2) * s3;
  const v2d u1 = Mo(1, 0) + Mo(1, 1) * c3 + Mo(1, 2) * s3;
  const v2d u2 = Mo(2, 0) + Mo(2, 1) * c3 + Mo(2, 2) * s3;
  // its roots as solve_basis gives them, with H = u1^2 + u2^2 = h^2 and k = cos t =
  // -u0 / h: (cos, sin) of phase -+ t = (-u1 u0 -+ u2 sD, -u2 u0 +- u1 sD) / H with
  // sD = sqrt(H - u0^2) = h sin t. The same checks on the squares (h > tol2; sin t >
  // 1e-6, which also refuses |k| > 1); no sqrt of H: the path's time is its chain of
  // square roots and divisions, and the two left here (1 / H, sD) do not wait for
  // each other.
  const v2d H = u1 * u1 + u2 * u2;
  if (!both(H > bc<v2d>(sp.tol2 * sp.tol2))) return false;
  const v2d iH = 1.0 / H;
  const v2d D = H - u0 * u0;  // H sin^2 t
  if (!both(D > bc<v2d>(1e-12) * H)) return false;
  const v2d sD = lsqrt(D);
  const v2d nu0 = -u0;
  // the two m2 roots of each lane: A = phase + t, B = phase - t (solve_basis's order)
  const v2d c2[2] = {(u1 * nu0 - u2 * sD) * iH, (u1 * nu0 + u2 * sD) * iH};
  const v2d s2[2] = {(u2 * nu0 + u1 * sD) * iH, (u2 * nu0 - u1 * sD) * iH};
  // v = C2 Rz(m3) w3 per lane
  const Eigen::Matrix3d& R2 = C(m, 2).linear();
  const Eigen::Vector3d& t2 = C(m, 2).translation();
  const v2d wx = c3 * m.w3.x() - s3 * m.w3.y(), wy = s3 * m.w3.x() + c3 * m.w3.y();
  const double wz = m.w3.z();
  const v2d vx = R2(0, 0) * wx + R2(0, 1) * wy + (R2(0, 2) * wz + t2.x());
  const v2d vy = R2(1, 0) * wx + R2(1, 1) * wy + (R2(1, 2) * wz + t2.y());
  const v2d vz = R2(2, 0) * wx + R2(2, 1) * wy + (R2(2, 2) * wz + t2.z());
  const Eigen::Matrix3d& R1 = C(m, 1).linear();
  const Eigen::Vector3d& t1 = C(m, 1).translation();
  const double sc2 = m.scale * m.scale;
  v2d c1[2], s1[2], x1[2], y1[2], ep[2];
  v2m shp[2], shs[2];
  for (int g = 0; g < 2; ++g) {
    const v2d gx = c2[g] * vx - s2[g] * vy, gy = s2[g] * vx + c2[g] * vy;
    const v2d fx = R1(0, 0) * gx + R1(0, 1) * gy + R1(0, 2) * vz + t1.x();
    const v2d fy = R1(1, 0) * gx + R1(1, 1) * gy + R1(1, 2) * vz + t1.y();
    const v2d fz = R1(2, 0) * gx + R1(2, 1) * gy + R1(2, 2) * vz + t1.z();
    const v2d cr = fx * p0.y() - fy * p0.x(), dt = fx * p0.x() + fy * p0.y();
    const v2d rr = cr * cr + dt * dt;
    if (!both((fx * fx + fy * fy >= bc<v2d>(1e-18 * sc2)) & (rr > bc<v2d>(1e-36 * sc2 * sc2)))) return false;
    // (dt, cr) / sqrt(rr), not pair_2d's 1 / |p0_xy|^2: |f_xy| = |p0_xy| holds here only
    // as well as both roots do, and near a folded elbow the error then reported missed
    // the FK's by more than 1e-12 (ik_reduced with SERVOARM_IK_SAMPLES=200000)
    const v2d ir = 1.0 / lsqrt(rr);
    x1[g] = dt;  // its angle from the unscaled pair: not after this square root and division
    y1[g] = cr;
    c1[g] = dt * ir;
    s1[g] = cr * ir;
    const v2d ex = c1[g] * fx - s1[g] * fy - p0.x(), ey = s1[g] * fx + c1[g] * fy - p0.y(), ez = fz - p0.z();
    ep[g] = lsqrt(ex * ex + ey * ey + ez * ez);
    if (!both(ep[g] <= bc<v2d>(kVerifyPos))) return false;
    const v2d sh = fx * m.shoulder_dir.x() + fy * m.shoulder_dir.y() + fz * m.shoulder_dir.z();
    shp[g] = sh >= bc<v2d>(0.0);
    shs[g] = (v2d)((v2m)sh & ~(v2m)bc<v2d>(-0.0)) < bc<v2d>(kNearSingular * m.scale);
  }
  // the angles, two at a time: m1 and m2 of each m2 root (lanes: the m3 roots), m3
  const v2d a1[2] = {detail::atan2_poly_v2(y1[0], x1[0]), detail::atan2_poly_v2(y1[1], x1[1])};
  const v2d a2[2] = {detail::atan2_poly_v2(s2[0], c2[0]), detail::atan2_poly_v2(s2[1], c2[1])};
  const v2d a3 = detail::atan2_poly_v2(s3, c3);
  // the quick wrap exit (wrap_joint) of all twelve values
  const IkJointWrap* jw = m.wrap.data();
  v2d q[3][2];
  v2m quick = bc<v2d>(0.0) == bc<v2d>(0.0);
  const v2m sign = (v2m)bc<v2d>(-0.0);
  const v2d lim[3] = {bc<v2d>(static_cast<double>(jw[0].in_abs)), bc<v2d>(static_cast<double>(jw[1].in_abs)),
                      bc<v2d>(static_cast<double>(jw[2].in_abs))};
  q[2][0] = q[2][1] = m.dir[2] * a3;
  for (int g = 0; g < 2; ++g) {
    q[0][g] = m.dir[0] * a1[g];
    q[1][g] = m.dir[1] * a2[g];
  }
  for (int j = 0; j < 3; ++j) quick &= ((v2d)((v2m)q[j][0] & ~sign) < lim[j]) & ((v2d)((v2m)q[j][1] & ~sign) < lim[j]);
  if (!both(quick) || res.count > kMaxIkSolutions - 4) {
    for (int e = 0; e < 2; ++e)  // m3 root (lane e), then m2 root g
      for (int g = 0; g < 2; ++g) {
        Branch br;
        br.shoulder = shp[g][e] ? 1 : -1;
        br.elbow = static_cast<std::int8_t>(e == 0 ? 1 : -1);
        const double mot[3] = {a1[g][e], a2[g][e], a3[e]};
        emit(m, q_ref, mot, br, shs[g][e] ? kSingularShoulder : 0, ep[g][e], 0.0, res);
      }
    return true;
  }
  // every value its own wrap, within the limits, finite: stored as they are (unrolled:
  // the lanes read at constant indices)
  IkSolution* out = &res.solutions[static_cast<std::size_t>(res.count)];
  res.count += 4;
  auto put = [&](IkSolution& sol, int e, int g) {
    const double qs[3] = {q[0][g][e], q[1][g][e], q[2][g][e]};
    Branch br;
    br.shoulder = shp[g][e] ? 1 : -1;
    br.elbow = static_cast<std::int8_t>(e == 0 ? 1 : -1);
    set_solution<3>(sol, qs, br, true, shs[g][e] ? kSingularShoulder : 0, ep[g][e], 0.0);
  };
  put(out[0], 0, 0);
  put(out[1], 0, 1);
  put(out[2], 1, 0);
  put(out[3], 1, 1);
  return true;
}

// Which 2-D form answers (false: not set up, or handed over).
inline bool reduced_2d(const IkModel& model, const Pose& target, const double* mref, const JointVector* q_ref,
                       IkResult& res) {
  const IkSolverData& m = solver_data(model);
  switch (model.method) {
    case IkMethod::planar_2r:
    case IkMethod::planar_3: return m.pl.on && solve_planar_2d(model, target, q_ref, res);
    case IkMethod::pitch_4: return m.pl.on && solve_pitch_4_2d(model, target, q_ref, res);
    case IkMethod::spatial_3:
      if (m.s3.on) {
        const Eigen::Vector3d p0 = C(m, 0).linear().transpose() * (target.translation() - C(m, 0).translation());
        if (solve_spatial_3_lanes(m, p0, q_ref, res)) return true;
      }
      return solve_spatial_3_2d(model, target, mref, q_ref, res);
    default: return false;
  }
}

}  // namespace

[[gnu::flatten]] bool solve_reduced_2d(const IkModel& model, const Pose& target, const JointVector* q_ref,
                                       IkResult& res) {
  const IkSolverData& m = solver_data(model);
  double mref[kMaxJoints] = {0, 0, 0, 0, 0, 0, 0, 0};
  if (q_ref)
    for (int j = 0; j < m.n; ++j) mref[j] = m.dir[static_cast<std::size_t>(j)] * (*q_ref)[j];
  return m.red_fast && reduced_2d(model, target, mref, q_ref, res);
}

[[gnu::flatten]] bool solve_spatial_3_lanes(const IkModel& model, const Pose& target, const JointVector* q_ref,
                                            IkResult& res) {
  const IkSolverData& m = solver_data(model);
  if (model.method != IkMethod::spatial_3 || !m.red_fast || !m.s3.on) return false;
  const Eigen::Vector3d p0 = C(m, 0).linear().transpose() * (target.translation() - C(m, 0).translation());
  return solve_spatial_3_lanes(m, p0, q_ref, res);
}

// Flattened (the Eigen products and decompositions of the elbow test and
// fit_basis inlined): split out of the one IK file GCC stopped inlining them
// (rrr_planar 11 046 -> 11 089 instructions per solve); flattened 9 784.
[[gnu::flatten]] void solve_reduced(const IkModel& model, const Pose& target, const JointVector* q_ref, IkResult& res) {
  const IkSolverData& m = solver_data(model);
  if (!m.red_fast) return solve_reduced_slow(model, target, q_ref, res);
  // rr_planar: solve_planar_2r (atan2_poly_x2, its own 2-D check) is already
  // the short form; the generic 2-D planar form was slower for it (
  // 156-158 -> 166-170 ns), so it keeps its own path (before mref: it needs none).
  if (model.method == IkMethod::planar_2r) return solve_planar_2r(model, target, q_ref, res);
  double mref[kMaxJoints] = {0, 0, 0, 0, 0, 0, 0, 0};
  if (q_ref)
    for (int j = 0; j < m.n; ++j) mref[j] = m.dir[static_cast<std::size_t>(j)] * (*q_ref)[j];
  const int count0 = res.count;
  if (reduced_2d(model, target, mref, q_ref, res)) return;
  res.count = count0;  // handed over: the 3-D cheap paths
  solve_reduced_3d(model, target, q_ref, res);
}

// The 3-D cheap paths alone (the 2-D forms' fallback; what ik_solve_all ran
// before them: the benchmark's same-run comparison).
[[gnu::flatten, gnu::noinline]] void solve_reduced_3d(const IkModel& model, const Pose& target, const JointVector* q_ref,
                                       IkResult& res) {
  const IkSolverData& m = solver_data(model);
  double mref[kMaxJoints] = {0, 0, 0, 0, 0, 0, 0, 0};
  if (q_ref)
    for (int j = 0; j < m.n; ++j) mref[j] = m.dir[static_cast<std::size_t>(j)] * (*q_ref)[j];
  if (!m.red_fast) return solve_reduced_slow(model, target, q_ref, res);
  if (model.method == IkMethod::planar_2r) return solve_planar_2r(model, target, q_ref, res);
  if (model.method == IkMethod::planar_3) return solve_planar_3_fast(model, target, mref, q_ref, res);
  if (model.method == IkMethod::pitch_4) return solve_pitch_4_fast(model, target, q_ref, res);
  if (model.method == IkMethod::spatial_3) return solve_spatial_3_fast(model, target, mref, q_ref, res);
  solve_reduced_slow(model, target, q_ref, res);
}

// What solve_reduced did before the cheap paths (every candidate through
// add_candidate, the elbow flag from the chain's Jacobian): the fallback for
// the degenerate targets the cheap paths hand over (heading undefined, an
// equation free).
[[gnu::flatten, gnu::noinline]] void solve_reduced_slow(const IkModel& model, const Pose& target, const JointVector* q_ref,
                                         IkResult& res) {
  const IkSolverData& m = solver_data(model);
  double mref[kMaxJoints] = {0, 0, 0, 0, 0, 0, 0, 0};
  if (q_ref)
    for (int j = 0; j < m.n; ++j) mref[j] = m.dir[static_cast<std::size_t>(j)] * (*q_ref)[j];
  const Pose C0i = C(m, 0).inverse();
  const double tol = 1e-12 * m.scale * m.scale;
  if (model.method == IkMethod::spatial_3) {
    const Eigen::Vector3d p0 = C0i * target.translation();
    PosCand pc[8];
    const int np = solve_position(m, p0, &mref[1], pc);
    for (int i = 0; i < np; ++i) {
      double mot[3] = {0, pc[i].m2, pc[i].m3};
      const Eigen::Vector3d f = f_of(m, mot[1], mot[2], m.w3);
      std::uint8_t sing = 0;
      if (std::hypot(f.x(), f.y()) < 1e-9 * m.scale) {
        mot[0] = mref[0];
        sing |= kSingularShoulder;
      } else {
        mot[0] = std::atan2(p0.y(), p0.x()) - std::atan2(f.y(), f.x());
      }
      Branch br;
      const double sh = f.dot(m.shoulder_dir);
      br.shoulder = sh >= 0 ? 1 : -1;
      if (std::abs(sh) < kNearSingular * m.scale) sing |= kSingularShoulder;
      br.elbow = pc[i].elbow;
      add_candidate(model, target, q_ref, mot, br, sing, true, res);
    }
    return;
  }
  // Planar and pitch arms: build the reachable target (position + the
  // rotation part the arm controls), then the point on the last axis.
  Pose eff = target;
  double m1_fixed = 0;
  bool have_m1 = false;
  const int last = m.n - 1;
  if (model.method == IkMethod::planar_3) {
    // R = R_C0 Rz(sum) R_C(last): heading psi of the tool about the base z.
    const Eigen::Matrix3d X = C(m, 0).linear().transpose() * target.linear() * C(m, m.n).linear().transpose();
    const double psi = std::atan2(X(1, 0), X(0, 0));
    eff.linear() = C(m, 0).linear() * rot_z(psi) * C(m, m.n).linear();
  } else if (model.method == IkMethod::pitch_4) {
    // Axis 2 (= axis 4) in the tool frame is constant: it fixes q1 from the
    // target rotation; then the pitch about that axis.
    const Eigen::Matrix3d Rrest = C(m, 2).linear() * C(m, 3).linear() * C(m, 4).linear();  // J3 prismatic or parallel
    const Eigen::Vector3d n2_tool = Rrest.transpose().col(2);
    const Eigen::Vector3d n2 = C(m, 0).linear().transpose() * (target.linear() * n2_tool);
    const Eigen::Vector3d n2_1 = C(m, 1).linear().col(2);  // axis 2 in the frame after J1 motion
    m1_fixed = std::atan2(n2.y(), n2.x()) - std::atan2(n2_1.y(), n2_1.x());
    have_m1 = true;
    const Eigen::Matrix3d R1 = C(m, 0).linear() * rot_z(m1_fixed) * C(m, 1).linear();
    const Eigen::Matrix3d X = R1.transpose() * target.linear() * Rrest.transpose();
    const double s = std::atan2(X(1, 0), X(0, 0));
    eff.linear() = R1 * rot_z(s) * Rrest;
  }
  Pose after_last = eff * C(m, m.n).inverse();  // frame after the last joint motion
  const Eigen::Vector3d P = (model.method == IkMethod::planar_2r) ? eff.translation() : after_last.translation();
  const Eigen::Vector3d p0 = C0i * P;
  // Position of the point (m.w3, frame after the motion of joint `k`) with k = 1 (planar) or 2 (pitch).
  double sols[4][kMaxJoints];
  std::int8_t elbows[4];
  int ns = 0;
  if (model.method == IkMethod::pitch_4) {
    // g = Rz(-m1) p0 = C1 Rz(m2) C2 J3(m3) w3: |g - t1| = |h(m3)|, then m2.
    const Eigen::Vector3d g = rot_z(-m1_fixed) * p0;
    const Eigen::Vector3d gl = C(m, 1).inverse() * g;  // in axis 2's frame
    const Eigen::Vector3d co = fit_basis(prism(m, 2), [&](double m3) {
      return (C(m, 2) * (joint_motion(prism(m, 2), m3) * m.w3)).squaredNorm();
    });
    const Roots r3 = solve_basis(co[0] - gl.squaredNorm(), co[1], co[2], prism(m, 2), tol);
    for (int i = 0; i < r3.n; ++i) {
      const Eigen::Vector3d h = C(m, 2) * (joint_motion(prism(m, 2), r3.v[i]) * m.w3);
      sols[ns][0] = m1_fixed;
      sols[ns][1] = std::atan2(gl.y(), gl.x()) - std::atan2(h.y(), h.x());
      sols[ns][2] = r3.v[i];
      elbows[ns++] = r3.label[i];
    }
  } else {
    // Distance from axis 1 of f(m2) = C1 J2(m2) w: |f_xy| = |p0_xy|.
    const Eigen::Vector3d co = fit_basis(prism(m, 1), [&](double m2) {
      const Eigen::Vector3d f = C(m, 1) * (joint_motion(prism(m, 1), m2) * m.w3);
      return f.x() * f.x() + f.y() * f.y();
    });
    Roots r2 = solve_basis(co[0] - (p0.x() * p0.x() + p0.y() * p0.y()), co[1], co[2], prism(m, 1), tol);
    // stretched / folded: one configuration, by the rule the cheap paths take (solve_planar_2r,
    // core_2d, solve_planar_3_fast); without it the two paths disagreed for roots ~1e-6
    // apart, beyond add_candidate's 1e-7 (rrr_planar, q2 = 9.1e-7, 10^6 samples of ik_reduced)
    if (!prism(m, 1)) merge_close_roots(r2);
    for (int i = 0; i < r2.n; ++i) {
      const Eigen::Vector3d f = C(m, 1) * (joint_motion(prism(m, 1), r2.v[i]) * m.w3);
      sols[ns][0] = std::hypot(f.x(), f.y()) < 1e-9 * m.scale ? mref[0]
                                                               : std::atan2(p0.y(), p0.x()) - std::atan2(f.y(), f.x());
      sols[ns][1] = r2.v[i];
      elbows[ns++] = r2.label[i];
    }
  }
  (void)have_m1;
  for (int i = 0; i < ns; ++i) {
    double* mot = sols[i];
    // Last joint from the rotation: Rz(m_last) = R_before^T R_eff R_C(n)^T.
    if (model.method != IkMethod::planar_2r) {
      Pose T = C(m, 0);
      for (int j = 0; j < last; ++j) T = T * joint_motion(prism(m, j), mot[j]) * C(m, j + 1);
      const Eigen::Matrix3d N = T.linear().transpose() * eff.linear() * C(m, m.n).linear().transpose();
      mot[last] = std::atan2(N(1, 0), N(0, 0));
    }
    Branch br;
    br.elbow = elbows[i];
    std::uint8_t sing = 0;
    // Elbow singular: the two roots merged (stretched / folded).
    if (ns >= 1) {
      Jacobian J;
      JointVector q(m.n);
      for (int j = 0; j < m.n; ++j) q[j] = m.dir[static_cast<std::size_t>(j)] * mot[j];
      if (jacobian(model.chain, q, J) == Status::ok) {
        // position rows of the joints that place the point: small singular value
        const int k = model.method == IkMethod::pitch_4 ? 3 : 2;
        Eigen::Matrix<double, 3, Eigen::Dynamic, Eigen::ColMajor, 3, kMaxJoints> Jp = J.topRows<3>().leftCols(k);
        const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor, kMaxJoints, kMaxJoints> G =
            Jp.transpose() * Jp;
        const double det = G.determinant();
        double prod = 1;
        for (int j = 0; j < k; ++j) prod *= G(j, j);
        if (prod > 0 && det / prod < kNearSingular * kNearSingular) sing |= kSingularElbow;
      }
    }
    add_candidate(model, eff, q_ref, mot, br, sing, model.method == IkMethod::planar_2r, res);
  }
}

}  // namespace servoarm::kin::detail
