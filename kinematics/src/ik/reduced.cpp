// Inverse kinematics, the reduced arms of seed 002 chapter 4 (ik.hpp):
// planar_2r (4.1), planar_3 (RRR, RLR: 4.2, 4.3), spatial_3 (TRR: 4.4, the
// position machinery of position.cpp with W = the tool point) and pitch_4
// (TRL:R, VVL:R: 4.5, 4.6). Real-time, heap-free.
#include <cmath>

#include <Eigen/LU>

#include "ik_detail.hpp"

namespace servoarm::kin::detail {
void solve_reduced_slow(const IkModel& model, const Pose& target, const JointVector* q_ref, IkResult& res);
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

// planar_2r (RR) in closed form with the cheap check (issue 19: reduced arms
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
  Roots r2 = solve_basis(m.red_co[0] - (p0.x() * p0.x() + p0.y() * p0.y()), m.red_co[1], m.red_co[2], false, tol, false);
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
    const Eigen::Vector3d w(c2 * m.w3.x() - s2 * m.w3.y(), s2 * m.w3.x() + c2 * m.w3.y(), m.w3.z());
    const Eigen::Vector3d f = R1 * w + t1;
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
      q[j] = jw.kind == 0 ? v : detail::wrap_into_limits(fast_wrap(v), jw.lo, jw.hi, j == 0 ? ref0 : ref1);
      in &= (q[j] >= jw.lo9) & (q[j] <= jw.hi9);
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
// The cheap path of planar_3, spatial_3 and pitch_4 (issue 19: reduced arms
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
    q[j] = jw.kind == 0 ? v : detail::wrap_into_limits(fast_wrap(v), jw.lo, jw.hi, q_ref ? (*q_ref)[j] : 0.0);
    in &= (q[j] >= jw.lo9) & (q[j] <= jw.hi9);
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

}  // namespace

// Flattened (the Eigen products and decompositions of the elbow test and
// fit_basis inlined): split out of the one IK file GCC stopped inlining them
// (rrr_planar 11 046 -> 11 089 instructions per solve); flattened 9 784.
[[gnu::flatten]] void solve_reduced(const IkModel& model, const Pose& target, const JointVector* q_ref, IkResult& res) {
  const IkSolverData& m = solver_data(model);
  double mref[kMaxJoints] = {0, 0, 0, 0, 0, 0, 0, 0};
  if (q_ref)
    for (int j = 0; j < m.n; ++j) mref[j] = m.dir[static_cast<std::size_t>(j)] * (*q_ref)[j];
  if (model.method == IkMethod::planar_2r && m.red_fast) {
    solve_planar_2r(model, target, q_ref, res);
    return;
  }
  if (model.method == IkMethod::planar_3 && m.red_fast) return solve_planar_3_fast(model, target, mref, q_ref, res);
  if (model.method == IkMethod::pitch_4 && m.red_fast) return solve_pitch_4_fast(model, target, q_ref, res);
  if (model.method == IkMethod::spatial_3 && m.red_fast) return solve_spatial_3_fast(model, target, mref, q_ref, res);
  solve_reduced_slow(model, target, q_ref, res);
}

// What solve_reduced did before the cheap paths (every candidate through
// add_candidate, the elbow flag from the chain's Jacobian): the fallback for
// the degenerate targets the cheap paths hand over (heading undefined, an
// equation free).
[[gnu::flatten]] void solve_reduced_slow(const IkModel& model, const Pose& target, const JointVector* q_ref,
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
    const Roots r2 = solve_basis(co[0] - (p0.x() * p0.x() + p0.y() * p0.y()), co[1], co[2], prism(m, 1), tol);
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
