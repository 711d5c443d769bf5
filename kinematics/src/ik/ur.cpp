// SPDX-License-Identifier: Apache-2.0
// Inverse kinematics, the UR-type arm (IkMethod::ur): six revolute joints,
// axes 2, 3, 4 parallel (direction n) and not parallel to axis 1, axis 5
// normal to n, axes 5 and 6 meeting at a point Q fixed in the tool
// (IkModel::w_tool). Recognised from the decomposition C0 J1 C1 ... J6 C6
// (either DH convention, offsets, reversed joints), never from the name.
//
//   joint 1   Q is fixed in the link after joint 4, so its component along n
//             is a constant beta:  Q0 . Rz(m1) n = beta          (2 roots)
//   joint 5   axis 4 seen from the frame after joint 6, u(m5) = C5^T Rz(-m5)
//             C4^T e_z, has the z component (axis 6 . n) of the target:
//             u5 . (1, c5, s5) = (Rz(m1) n) . z6                 (2 roots)
//   joint 6   u(m5) = Rz(m6) v with v = axis 4 in the target's frame after
//             joint 6: one angle (free at theta5 = 0: kept at the reference)
//   2, 3, 4   the frame after joint 4 follows from the target and m1, m5, m6;
//             its origin's distance from axis 2 gives m3 (2 roots), one angle
//             gives m2, the rotation left about n gives m4.
// Up to 8 solutions, tagged shoulder (m1 root), wrist (m5 root), elbow (m3
// root). Each is verified exactly to rounding through the same decomposition:
// the target's frame after joint 4 against the one that (m2, m3, m4) produce,
//   rotation  |Rz(m4) - X|_F,  X = (C1 Rz2 C2 Rz3 C3)^T R14
//   position  |(Rz(m4) - X) L + Y^T (o_fk - o)|   (L: tool origin in frame 4)
// A candidate that misses 1e-9 m / 1e-9 rad (a root clamped at the reach
// limit, digits lost at a singularity) goes through add_candidate (the
// chain's FK and a few Gauss-Newton steps). Real-time, heap-free.
#include <algorithm>
#include <cmath>

#include "../fast_trig.hpp"
#include "ik_detail.hpp"

namespace servoarm::kin::detail {
namespace {

struct Rot2 {
  double c = 1, s = 0;
};

// (c, s) of the angle that turns (ax, ay) onto (bx, by); false if either is ~0.
inline bool angle_from_to(double ax, double ay, double bx, double by, double tiny2, Rot2& r) {
  const double cr = ax * by - ay * bx, dt = ax * bx + ay * by;
  const double r2 = cr * cr + dt * dt;
  if (!(r2 > tiny2)) return false;
  const double ir = 1.0 / std::sqrt(r2);
  r.c = dt * ir;
  r.s = cr * ir;
  return true;
}

// Rz(c, s) * v
inline Eigen::Vector3d rz(const Rot2& a, const Eigen::Vector3d& v) {
  return {a.c * v.x() - a.s * v.y(), a.s * v.x() + a.c * v.y(), v.z()};
}
// R * Rz(c, s)
inline Eigen::Matrix3d mul_rz(const Eigen::Matrix3d& R, const Rot2& a) {
  Eigen::Matrix3d Y;
  Y.col(0) = a.c * R.col(0) + a.s * R.col(1);
  Y.col(1) = a.c * R.col(1) - a.s * R.col(0);
  Y.col(2) = R.col(2);
  return Y;
}

// |sin 2t| of a pair of roots phi +- t (0 when they merge, t = 0 or pi).
inline double merge_measure(const Roots& r) {
  if (r.n < 2) return 0.0;
  if (r.c[0] * r.c[1] + r.s[0] * r.s[1] < 0) return 1.0;  // t near pi/2
  return std::abs(r.s[0] * r.c[1] - r.c[0] * r.s[1]);
}

// Joint 5: u5 . (1, c5, s5) = vz, i.e. cos t = k = (vz - W0) / h with the
// roots phi5 +- t. Near theta5 = 0 (k -> +-1) 1 -+ k computed as 1 -+ vz
// loses every digit of t (acos near 1): where u_z = cos(m5 - phi5) exactly
// (W0 = 0, h = 1: axis 5 normal to axes 4 and 6, the UR wrist) they come from
// the tilt |v_xy|^2 = 1 - vz^2 instead, exact to rounding:
// 1 - vz = |v_xy|^2 / (1 + vz). No merging: theta5 = +-t are two wrist
// configurations (q4, q6 differ by pi) however small t is.
Roots wrist_roots(const IkSolverData& m, double vz, double vxy2) {
  Roots r;
  const double W0 = m.ur_u5[0], W1 = m.ur_u5[1], W2 = m.ur_u5[2];
  const double h = std::sqrt(W1 * W1 + W2 * W2);
  const double k = (vz - W0) / h;
  double um = 1.0 - k, up = 1.0 + k;
  if (m.ur_tilt) {
    if (vz > 0.5) um = vxy2 / (1.0 + vz);
    else if (vz < -0.5) up = vxy2 / (1.0 - vz);
  }
  if (um < -1e-9 || up < -1e-9) return r;
  um = std::max(um, 0.0);
  up = std::max(up, 0.0);
  const double st = std::sqrt(um * up);
  const double ct = std::clamp(0.5 * (up - um), -1.0, 1.0);
  const double cp = W1 / h, sp = W2 / h;
  r.c[0] = cp * ct - sp * st;  // phi + t
  r.s[0] = sp * ct + cp * st;
  r.c[1] = cp * ct + sp * st;  // phi - t
  r.s[1] = sp * ct - cp * st;
  r.n = st > 0 ? 2 : 1;
  return r;
}

}  // namespace

// Flattened (the Eigen products, solve_basis and the helpers inlined), as
// solve_reduced and add_candidate are.
[[gnu::flatten]] void solve_ur(const IkModel& model, const Pose& target, const JointVector* q_ref, IkResult& res) {
  const IkSolverData& m = solver_data(model);
  double mref[6] = {0, 0, 0, 0, 0, 0};
  if (q_ref)
    for (int j = 0; j < 6; ++j) mref[j] = m.dir[static_cast<std::size_t>(j)] * (*q_ref)[j];
  const Eigen::Matrix3d& C0R = C(m, 0).linear();
  // The target in the frame after C0: tool rotation, the frame after the J6
  // motion (F, t6), the wrist point Q.
  const Eigen::Matrix3d F0 = C0R.transpose() * target.linear();
  const Eigen::Vector3d pt0 = C0R.transpose() * (target.translation() - C(m, 0).translation());
  const Eigen::Matrix3d F = F0 * C(m, 6).linear().transpose();
  const Eigen::Vector3d t6 = pt0 - F * C(m, 6).translation();
  const Eigen::Vector3d q0 = pt0 + F0 * model.w_tool;
  const Eigen::Vector3d z6 = F.col(2);
  const Eigen::Vector3d& n = m.n_par;
  const double tol1 = 1e-12 * m.scale * m.scale, tol2 = 1e-12 * m.scale;
  const double tiny2 = 1e-36 * m.scale * m.scale * m.scale * m.scale;

  Roots r1 = solve_basis(q0.z() * n.z() - m.beta, q0.x() * n.x() + q0.y() * n.y(), q0.y() * n.x() - q0.x() * n.y(),
                         false, tol2, false);
  bool free1 = false;
  if (r1.free) {  // Q on axis 1 and beta = Q.n: joint 1 free (kept)
    free1 = true;
    r1.n = 1;
    detail::sincos_poly(mref[0], r1.s[0], r1.c[0]);
  }
  const double sh_merge = merge_measure(r1);
  merge_close_roots(r1);
  const std::uint8_t sing1 = (free1 || r1.n == 1 || sh_merge < 2.0 * kNearSingular) ? kSingularShoulder : 0;

  const Eigen::Matrix3d& R1 = C(m, 1).linear();
  const Eigen::Vector3d& t1 = C(m, 1).translation();
  const Eigen::Matrix3d& R2 = C(m, 2).linear();
  const Eigen::Vector3d& t2 = C(m, 2).translation();
  const Eigen::Matrix3d& R3 = C(m, 3).linear();
  const Eigen::Matrix3d& R4 = C(m, 4).linear();
  const Eigen::Vector3d& t4 = C(m, 4).translation();
  const Eigen::Matrix3d& R5 = C(m, 5).linear();
  const Eigen::Vector3d& t5 = C(m, 5).translation();
  const Eigen::Vector3d& t6c = C(m, 6).translation();

  // Candidates: (s, c) pairs of every motion, angles in one batch at the end.
  // Every (cos, sin) pair once, in slots (joint 1: per shoulder root; 5, 6:
  // per wrist root; 2, 3, 4 per candidate): one atan2 and one wrap each.
  double sy[36], sx[36];
  std::int8_t sj[36];
  int ns = 0;
  auto slot = [&](const Rot2& a, int j) {
    sy[ns] = a.s;
    sx[ns] = a.c;
    sj[ns] = static_cast<std::int8_t>(j);
    return static_cast<std::int8_t>(ns++);
  };
  struct Cand {
    std::int8_t sl[6];
    Branch br;
    std::uint8_t sing;
    double ep, er;
  };
  Cand cand[8];
  int nc = 0;
  for (int i = 0; i < r1.n; ++i) {
    const Rot2 a1{r1.c[i], r1.s[i]};
    std::int8_t sl1 = -1;
    const Eigen::Vector3d nb = rz(a1, n);       // n in the frame after C0
    const Eigen::Vector3d v = F.transpose() * nb;  // n in the target's frame after J6
    const Roots r5 = wrist_roots(m, nb.dot(z6), v.x() * v.x() + v.y() * v.y());
    if (r5.n == 0) continue;
    const double wr_merge = merge_measure(r5);
    for (int k = 0; k < r5.n; ++k) {
      const Rot2 a5{r5.c[k], r5.s[k]};
      std::int8_t sl5 = -1, sl6 = -1;
      const Eigen::Vector3d u = R5.transpose() * rz({a5.c, -a5.s}, m.ur_c4z);
      std::uint8_t sing = sing1;
      const double uxy2 = u.x() * u.x() + u.y() * u.y();
      if (uxy2 < kNearSingular * kNearSingular || wr_merge < 2.0 * kNearSingular) sing |= kSingularWrist;
      Rot2 a6;
      if (!angle_from_to(v.x(), v.y(), u.x(), u.y(), 1e-40, a6))  // theta5 = 0: joint 6 kept
        detail::sincos_poly(mref[5], a6.s, a6.c);
      // K = C4 Rz5 C5 Rz6: the frame after J4 motion is P6 K^-1.
      const Eigen::Matrix3d R45 = mul_rz(R4, a5) * R5;
      const Eigen::Matrix3d KR = mul_rz(R45, a6);
      const Eigen::Vector3d Kt = t4 + mul_rz(R4, a5) * t5;
      const Eigen::Vector3d L = Kt + KR * t6c;  // tool origin in the frame after J4 motion
      const Eigen::Matrix3d P4R = F * KR.transpose();
      const Eigen::Vector3d P4t = t6 - P4R * Kt;
      // In the frame after J1 motion.
      const Rot2 a1i{a1.c, -a1.s};
      Eigen::Matrix3d R14;
      for (int c = 0; c < 3; ++c) R14.col(c) = rz(a1i, P4R.col(c));
      const Eigen::Vector3d o = rz(a1i, P4t);
      const Eigen::Vector3d u2 = R1.transpose() * (o - t1);  // frame of joint 2
      const double d2 = u2.x() * u2.x() + u2.y() * u2.y();
      Roots r3 = solve_basis(m.g_par[0] - d2, m.g_par[1], m.g_par[2], false, tol1, false);
      if (r3.free) continue;
      const double el_merge = r3.n == 1 ? 0.0 : merge_measure(r3);
      merge_close_roots(r3);
      // C2, C3 rotations about z (ur_zrot, the usual DH rows): then
      // C1 Rz2 C2 Rz3 C3 = C1 Rz(sigma), sigma = m2 + m3 + gamma, and with
      // Z = C1^T R14 = Rz(mu) (exactly, for a solution) m4 = mu - sigma; the
      // rotation error |Rz(mu) - Z|_F and the part (Rz(mu) - Z) L of the
      // position error are the same for both elbow roots (computed once):
      // per root only |E5 + Rz(m2) w - u2| remains (rotation-invariant form
      // of the verification above).
      Rot2 mu;
      double f2z = 0;
      Eigen::Vector3d E5 = Eigen::Vector3d::Zero();
      if (m.ur_zrot) {
        const Eigen::Matrix3d Z = R1.transpose() * R14;
        if (!angle_from_to(1.0, 0.0, Z(0, 0), Z(1, 0), 1e-40, mu)) mu = Rot2{};
        Eigen::Matrix3d Dz;
        Dz << mu.c - Z(0, 0), -mu.s - Z(0, 1), -Z(0, 2), mu.s - Z(1, 0), mu.c - Z(1, 1), -Z(1, 2), -Z(2, 0), -Z(2, 1),
            1.0 - Z(2, 2);
        f2z = Dz.squaredNorm();
        E5 = Dz * L;
      }
      for (int e = 0; e < r3.n && nc < 8; ++e) {
        const Rot2 a3{r3.c[e], r3.s[e]};
        const Eigen::Vector3d w = R2 * rz(a3, m.w_par) + t2;
        Cand& cd = cand[nc];
        cd.sing = sing;
        if (el_merge < 2.0 * kNearSingular) cd.sing |= kSingularElbow;
        Rot2 a2;
        if (!angle_from_to(w.x(), w.y(), u2.x(), u2.y(), tiny2, a2)) {  // frame-4 origin on axis 2
          detail::sincos_poly(mref[1], a2.s, a2.c);
          cd.sing |= kSingularShoulder;
        }
        Rot2 a4;
        double f2 = f2z;
        if (m.ur_zrot) {
          const Rot2 s23{a2.c * a3.c - a2.s * a3.s, a2.s * a3.c + a2.c * a3.s};
          const Rot2 sg{s23.c * m.ur_gc - s23.s * m.ur_gs, s23.s * m.ur_gc + s23.c * m.ur_gs};
          a4 = Rot2{mu.c * sg.c + mu.s * sg.s, mu.s * sg.c - mu.c * sg.s};  // mu - sigma
          cd.ep = (E5 + rz(a2, w) - u2).norm();
        } else {
          const Eigen::Matrix3d Y = mul_rz(mul_rz(R1, a2) * R2, a3) * R3;
          const Eigen::Matrix3d X = Y.transpose() * R14;
          if (!angle_from_to(1.0, 0.0, X(0, 0), X(1, 0), 1e-40, a4)) a4 = Rot2{};
          // Verification (exact to rounding): the frame after J4 motion that
          // (m2, m3, m4) give against the target's.
          Eigen::Matrix3d D;
          D << a4.c - X(0, 0), -a4.s - X(0, 1), -X(0, 2), a4.s - X(1, 0), a4.c - X(1, 1), -X(1, 2), -X(2, 0),
              -X(2, 1), 1.0 - X(2, 2);
          const Eigen::Vector3d o_fk = R1 * rz(a2, w) + t1;
          const Eigen::Vector3d ev = D * L + Y.transpose() * (o_fk - o);
          f2 = D.squaredNorm();
          cd.ep = ev.norm();
        }
        cd.er = f2 < 1e-8 ? std::sqrt(0.5 * f2) : 2.0 * std::asin(std::min(1.0, std::sqrt(f2 / 8.0)));
        if (sl1 < 0) sl1 = slot(a1, 0);
        if (sl5 < 0) {
          sl5 = slot(a5, 4);
          sl6 = slot(a6, 5);
        }
        cd.sl[0] = sl1;
        cd.sl[1] = slot(a2, 1);
        cd.sl[2] = slot(a3, 2);
        cd.sl[3] = slot(a4, 3);
        cd.sl[4] = sl5;
        cd.sl[5] = sl6;
        cd.br.shoulder = r1.label[i];
        cd.br.wrist = r5.label[k];
        cd.br.elbow = r3.label[e];
        ++nc;
      }
    }
  }
  if (nc == 0) return;
  // Every angle in one batch (pairs).
  double ang[36];
  if (ns & 1) {
    sy[ns] = 0.0;
    sx[ns] = 1.0;
    sj[ns] = 0;
  }
  for (int i = 0; i < ns; i += 2) detail::atan2_poly_x2(sy + i, sx + i, ang + i);
  double ref[6], dir[6];
  bool narrow[6];
  for (int j = 0; j < 6; ++j) {
    ref[j] = q_ref ? (*q_ref)[j] : 0.0;
    dir[j] = m.dir[static_cast<std::size_t>(j)];
    narrow[j] = detail::narrow_applies(m.wrap[static_cast<std::size_t>(j)], ref[j]);
  }
  auto wrap = [&](int j, double v) {
    const IkJointWrap& jw = m.wrap[static_cast<std::size_t>(j)];
    const double w = v > kPi ? v - 2.0 * kPi : (v <= -kPi ? v + 2.0 * kPi : v);
    if (narrow[j]) return detail::wrap_narrow(jw, w);
    return detail::wrap_into_limits(w, jw.lo, jw.hi, ref[j]);
  };
  auto same_joint = [](double a, double b) {
    const double d = std::abs(a - b);
    return d <= 1e-7 || (d >= 2.0 * kPi - 2e-7 && std::abs(fast_wrap(a - b)) <= 1e-7);
  };
  // Joint values and limit checks per slot.
  double qs[36];
  bool ins[36];
  for (int i = 0; i < ns; ++i) {
    const int j = sj[i];
    qs[i] = wrap(j, dir[j] * ang[i]);
    const IkJointWrap& jw = m.wrap[static_cast<std::size_t>(j)];
    ins[i] = (qs[i] >= jw.lo9) & (qs[i] <= jw.hi9);
  }
  bool foreign = false;
  for (int k = 0; k < nc; ++k) {
    const Cand& cd = cand[k];
    double mot[6];
    for (int j = 0; j < 6; ++j) mot[j] = ang[cd.sl[j]];
    if (!(cd.ep <= kVerifyPos && cd.er <= kVerifyRot)) {
      if (cd.ep < 1e-4 * m.scale && cd.er < 1e-4) {
        const int before = res.count;
        add_candidate(model, target, q_ref, mot, cd.br, cd.sing, false, res);
        foreign = foreign || res.count > before;
      }
      continue;
    }
    if (res.count >= kMaxIkSolutions) break;
    double q[6];
    bool in = true;
    for (int j = 0; j < 6; ++j) {
      q[j] = qs[cd.sl[j]];
      in &= ins[cd.sl[j]];
    }
    // Duplicates only where roots (nearly) merged: singular candidates, or
    // against add_candidate's solutions.
    if (cd.sing || foreign) {
      bool dup = false;
      for (int t = 0; t < res.count && !dup; ++t) {
        const JointVector& o = res.solutions[static_cast<std::size_t>(t)].q;
        bool same = true;
        for (int j = 0; j < 6 && same; ++j) same = same_joint(q[j], o[j]);
        dup = same;
      }
      if (dup) continue;
    }
    IkSolution& sol = res.solutions[static_cast<std::size_t>(res.count++)];
    sol.q.resize(6);
    for (int j = 0; j < 6; ++j) sol.q[j] = q[j];
    sol.branch = cd.br;
    sol.within_limits = in;
    sol.singular = cd.sing;
    sol.position_error = cd.ep;
    sol.rotation_error = cd.er;
  }
}

}  // namespace servoarm::kin::detail
