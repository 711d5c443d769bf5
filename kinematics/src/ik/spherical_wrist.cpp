// SPDX-License-Identifier: Apache-2.0
// Inverse kinematics, the spherical-wrist arm (ik.hpp: Pieper's
// decomposition): joint 1 from the wrist centre, (q2, q3) from position.cpp,
// the wrist by atan2, two arm configurations per register (lanes.hpp), every
// solution verified through the model's decomposition. Real-time, heap-free.
#include <algorithm>
#include <cmath>

#include "../fast_trig.hpp"
#include "../lanes.hpp"
#include "ik_detail.hpp"

namespace servoarm::kin::detail {
namespace {

/// |axis 6 x axis 4|^2 below which q4 is kept at the reference (theta5 = 0).
constexpr double kKeepQ4 = 1e-20;

// ---------------------------------------------------------------------------
// Spherical wrist
//
// Everything runs on (cos, sin) pairs; the angles are computed at the end in
// one batch (atan2_poly_x2, two at a time) and never fed back. The arm
// configurations (up to 4 for a 6R arm) go through the arm and wrist stages
// two at a time, one per lane of a two-lane vector (arm_lanes, wrist_lanes).
// Constant rotations that are signed permutations (the usual 0 / +-90 degree
// DH angles) multiply as copies. Each candidate is verified by forward kinematics of its joint
// values through the model's decomposition C0 J1 C1 ... J6 C6, with the part
// shared by the two wrist solutions of one arm configuration computed once:
//   wrist centre   W_fk = C0 Rz(m1) f(m2, m3)          (per arm configuration)
//   rotation       R_fk = R3 X C6,  X = Rz(m4) C4 Rz(m5) C5 Rz(m6)
// against the target's M = R3^T R_target C6^T:  |X - M|_F = 2 sqrt(2) sin(err/2)
// (R3 orthonormal), and the tool position error
//   p_fk - p = (W_fk - W) - R3 (X - M) C6 w_tool,
// both exact to rounding. The second wrist solution of an arm configuration,
// when derived by the wrist flip (m4 + pi, 2 phi5 - m5, m6 + pi: the same X,
// an identity checked at set-up), shares the first one's errors and flags.
// A candidate that misses 1e-9 m / 1e-9 rad (a root
// clamped at the reach limit, precision lost at a singularity) goes through
// add_candidate: the chain's own FK and a few Gauss-Newton steps.
// ---------------------------------------------------------------------------
// R x with R given also as a signed permutation.
EIGEN_ALWAYS_INLINE Eigen::Vector3d apply(const Eigen::Matrix3d& R, const IkSignedPerm& p, const Eigen::Vector3d& x) {
  if (!p.is) return R * x;
  Eigen::Vector3d y;
  for (int j = 0; j < 3; ++j) y[p.idx[static_cast<std::size_t>(j)]] = p.sign[static_cast<std::size_t>(j)] * x[j];
  return y;
}

// ---------------------------------------------------------------------------
// The per-arm-configuration part of the spherical-wrist solver, written once
// for a lane type T (lanes.hpp): double for one configuration, v2d for two at
// a time. The 4 configurations of a generic 6R pose are independent chains of
// ~10 dependent sqrt/div each, so two lanes take about the time of one.
// Selects replace the branches of the scalar formulation; every value
// selected away stays finite (safe denominators).
// ---------------------------------------------------------------------------
using detail::bc;
using detail::lane;
using detail::select;
using detail::v2d;

template <class T>
struct L3 {
  T x, y, z;
};

/// Constants of one solve, shared by every arm configuration.
struct SphCtx {
  const IkSolverData* m;
  bool p2, p3;
  Eigen::Vector3d p0, u;
  Eigen::Matrix3d Rt0;    ///< C0^T R_target C6^T
  double c1ref, s1ref;    ///< q1 kept at a shoulder singularity
  double c4ref, s4ref;    ///< q4 kept in the theta5 = 0 family
  double p0xy2, tiny_xy2;
  double h5, cphi5, sphi5;
  bool tilt_pos, tilt_neg;
};

/// Arm stage of one or two configurations.
template <class T>
struct ArmL {
  T c1, s1;             ///< joint 1
  T fxy2, sh, det, den2;  ///< shoulder and elbow tests (see solve_spherical)
  L3<T> e3;             ///< wrist-centre error, frame of joint 4
  T M[3][3];            ///< wrist target rotation in the frame of joint 4
  T um, up;             ///< 1 -+ cos t (either < -1e-9: no wrist solution)
  T st, ct;             ///< joint 5 roots phi5 +- t
};

/// One wrist root of one or two configurations.
template <class T>
struct WristL {
  T c4, s4, c6, s6;
  T wxy2;  ///< |axis 6 x axis 4|^2 (the theta5 = 0 test)
  T ep;    ///< tool position error
  T f2;    ///< |X - M|_F^2 (rotation error 2 asin(sqrt(f2 / 8)))
};

// (c, s) of the angle from a to b in the xy plane; (1, 0) where either is 0.
template <class T>
EIGEN_ALWAYS_INLINE void angle_between_l(T ax, T ay, T bx, T by, T& c, T& s) {
  const T cr = ax * by - ay * bx, dt = ax * bx + ay * by;
  const T r2 = cr * cr + dt * dt;
  const auto pos = r2 > 0.0;
  const T ir = 1.0 / detail::lsqrt(select(pos, r2, bc<T>(1.0)));
  c = select(pos, dt * ir, bc<T>(1.0));
  s = select(pos, cr * ir, bc<T>(0.0));
}

// y = R x with R also as a signed permutation (x, y: arrays of 3).
template <class T>
EIGEN_ALWAYS_INLINE void apply_l(const Eigen::Matrix3d& R, const IkSignedPerm& p, const T* x, T* y) {
  if (p.is) {
    for (int j = 0; j < 3; ++j) y[p.idx[static_cast<std::size_t>(j)]] = p.sign[static_cast<std::size_t>(j)] * x[j];
  } else {
    for (int r = 0; r < 3; ++r) y[r] = R(r, 0) * x[0] + R(r, 1) * x[1] + R(r, 2) * x[2];
  }
}
// y = R^T x.
template <class T>
EIGEN_ALWAYS_INLINE void apply_t_l(const Eigen::Matrix3d& R, const IkSignedPerm& p, const T* x, T* y) {
  if (p.is) {
    for (int j = 0; j < 3; ++j) y[j] = p.sign[static_cast<std::size_t>(j)] * x[p.idx[static_cast<std::size_t>(j)]];
  } else {
    for (int r = 0; r < 3; ++r) y[r] = R(0, r) * x[0] + R(1, r) * x[1] + R(2, r) * x[2];
  }
}
// Y = X R (X: rows of 3 lanes).
template <class T>
EIGEN_ALWAYS_INLINE void mul_right_l(const T (&X)[3][3], const Eigen::Matrix3d& R, const IkSignedPerm& p, T (&Y)[3][3]) {
  for (int r = 0; r < 3; ++r) {
    if (p.is) {
      for (int j = 0; j < 3; ++j)
        Y[r][j] = p.sign[static_cast<std::size_t>(j)] * X[r][p.idx[static_cast<std::size_t>(j)]];
    } else {
      for (int j = 0; j < 3; ++j) Y[r][j] = X[r][0] * R(0, j) + X[r][1] * R(1, j) + X[r][2] * R(2, j);
    }
  }
}

// Arm stage: frames after the J2 and J3 motions (in the frame after J1's
// motion), the wrist centre f, joint 1 turning f onto p0, the shoulder and
// elbow tests, the wrist-centre error and the wrist's target rotation
// M = R3^T R_target C6^T, joint 5's roots.
template <class T>
EIGEN_ALWAYS_INLINE void arm_lanes(const SphCtx& x, T c2, T s2, T c3, T s3, ArmL<T>& o) {
  const IkSolverData& m = *x.m;
  const Eigen::Matrix3d& R1 = C(m, 1).linear();
  const Eigen::Vector3d& t1 = C(m, 1).translation();
  const Eigen::Vector3d& t2 = C(m, 2).translation();
  T R12[3][3], t12[3];
  for (int r = 0; r < 3; ++r) {
    if (x.p2) {
      R12[r][0] = bc<T>(R1(r, 0));
      R12[r][1] = bc<T>(R1(r, 1));
      t12[r] = t1[r] + c2 * R1(r, 2);
    } else {
      R12[r][0] = c2 * R1(r, 0) + s2 * R1(r, 1);
      R12[r][1] = c2 * R1(r, 1) - s2 * R1(r, 0);
      t12[r] = bc<T>(t1[r]);
    }
    R12[r][2] = bc<T>(R1(r, 2));
  }
  T K[3][3], tK[3], R13[3][3], t13[3];
  mul_right_l(R12, C(m, 2).linear(), m.perm[2], K);
  for (int r = 0; r < 3; ++r) tK[r] = R12[r][0] * t2[0] + R12[r][1] * t2[1] + R12[r][2] * t2[2] + t12[r];
  for (int r = 0; r < 3; ++r) {
    if (x.p3) {
      R13[r][0] = K[r][0];
      R13[r][1] = K[r][1];
      t13[r] = tK[r] + c3 * K[r][2];
    } else {
      R13[r][0] = c3 * K[r][0] + s3 * K[r][1];
      R13[r][1] = c3 * K[r][1] - s3 * K[r][0];
      t13[r] = tK[r];
    }
    R13[r][2] = K[r][2];
  }
  T f[3];
  for (int r = 0; r < 3; ++r) f[r] = R13[r][0] * m.w3[0] + R13[r][1] * m.w3[1] + R13[r][2] * m.w3[2] + t13[r];
  // Joint 1: turn f onto p0 about z (wrist centre on axis 1: keep q1).
  o.fxy2 = f[0] * f[0] + f[1] * f[1];
  T c1, s1;
  angle_between_l(f[0], f[1], bc<T>(x.p0.x()), bc<T>(x.p0.y()), c1, s1);
  if (x.p0xy2 < x.tiny_xy2) {
    const auto on_axis = o.fxy2 < x.tiny_xy2;
    c1 = select(on_axis, bc<T>(x.c1ref), c1);
    s1 = select(on_axis, bc<T>(x.s1ref), s1);
  }
  o.c1 = c1;
  o.s1 = s1;
  o.sh = f[0] * m.shoulder_dir.x() + f[1] * m.shoulder_dir.y() + f[2] * m.shoulder_dir.z();
  {
    // Position Jacobian of the wrist centre (frame after J1 motion): its
    // normalised determinant gives the elbow side and the elbow singularity.
    const T j1[3] = {-f[1], f[0], bc<T>(0.0)};
    T j2[3], j3[3];
    if (x.p2) {
      for (int r = 0; r < 3; ++r) j2[r] = bc<T>(R1(r, 2));
    } else {
      const T d[3] = {f[0] - t1[0], f[1] - t1[1], f[2] - t1[2]};
      j2[0] = R1(1, 2) * d[2] - R1(2, 2) * d[1];
      j2[1] = R1(2, 2) * d[0] - R1(0, 2) * d[2];
      j2[2] = R1(0, 2) * d[1] - R1(1, 2) * d[0];
    }
    if (x.p3) {
      for (int r = 0; r < 3; ++r) j3[r] = K[r][2];
    } else {
      const T d[3] = {f[0] - tK[0], f[1] - tK[1], f[2] - tK[2]};
      j3[0] = K[1][2] * d[2] - K[2][2] * d[1];
      j3[1] = K[2][2] * d[0] - K[0][2] * d[2];
      j3[2] = K[0][2] * d[1] - K[1][2] * d[0];
    }
    auto n2 = [](const T* a) { return a[0] * a[0] + a[1] * a[1] + a[2] * a[2]; };
    o.den2 = n2(j1) * n2(j2) * n2(j3);
    o.det = j1[0] * (j2[1] * j3[2] - j2[2] * j3[1]) + j1[1] * (j2[2] * j3[0] - j2[0] * j3[2]) +
            j1[2] * (j2[0] * j3[1] - j2[1] * j3[0]);
  }
  // Everything in the frame of joint 4 (after C3).
  const T p1[3] = {c1 * x.p0.x() + s1 * x.p0.y(), c1 * x.p0.y() - s1 * x.p0.x(), bc<T>(x.p0.z())};  // Rz(-m1) p0
  T K3[3][3];
  mul_right_l(R13, C(m, 3).linear(), m.perm[3], K3);
  const T d[3] = {f[0] - p1[0], f[1] - p1[1], f[2] - p1[2]};
  o.e3.x = K3[0][0] * d[0] + K3[1][0] * d[1] + K3[2][0] * d[2];
  o.e3.y = K3[0][1] * d[0] + K3[1][1] * d[1] + K3[2][1] * d[2];
  o.e3.z = K3[0][2] * d[0] + K3[1][2] * d[1] + K3[2][2] * d[2];
  T Y[3][3];  // Rz(-m1) Rt0
  for (int j = 0; j < 3; ++j) {
    Y[0][j] = c1 * x.Rt0(0, j) + s1 * x.Rt0(1, j);
    Y[1][j] = c1 * x.Rt0(1, j) - s1 * x.Rt0(0, j);
    Y[2][j] = bc<T>(x.Rt0(2, j));
  }
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) o.M[i][j] = K3[0][i] * Y[0][j] + K3[1][i] * Y[1][j] + K3[2][i] * Y[2][j];
  // Joint 5: a + P cos m5 + Q sin m5 = 0, roots phi5 +- t.
  const T M22 = o.M[2][2];
  const T k5 = (M22 - m.wrist_gz_vz) / x.h5;  // cos t
  // 1 - k and 1 + k, exact near the ends (theta5 -> 0: the tilt of axis 6,
  // sin(tau) = |M(0:1, 2)|, is exact where M(2, 2) = cos(tau) is not).
  const T stau2 = o.M[0][2] * o.M[0][2] + o.M[1][2] * o.M[1][2];
  T um = 1.0 - k5, up = 1.0 + k5;
  if (x.tilt_pos) {
    const auto near = (k5 > 0.99) & (M22 > 0.0);
    um = select(near, stau2 / select(near, 1.0 + M22, bc<T>(1.0)) / x.h5, um);
  }
  if (x.tilt_neg) {
    const auto near = (k5 < -0.99) & (M22 < 0.0);
    up = select(near, stau2 / select(near, 1.0 - M22, bc<T>(1.0)) / x.h5, up);
  }
  o.um = um;
  o.up = up;
  um = select(um < 0.0, bc<T>(0.0), um);
  up = select(up < 0.0, bc<T>(0.0), up);
  const T ct = 0.5 * (up - um);
  const auto merged = detail::lsqrt(0.5 * um) < 0.5e-10;  // t < 1e-10: the two roots merge
  o.st = select(merged, bc<T>(0.0), detail::lsqrt(um * up));
  o.ct = select(merged, bc<T>(1.0), select(ct < -1.0, bc<T>(-1.0), select(ct > 1.0, bc<T>(1.0), ct)));
}

// One wrist root (m5 = phi5 + sgn t): joint 4 turns w = A Rz(m5) v (axis 6
// before joint 4) onto M's z column, joint 6 from N = (Rz(m4) A Rz(m5) B)^T M,
// then the verification: X = Rz(m4) A Rz(m5) B Rz(m6) against M column by
// column and the tool position error.
template <class T>
EIGEN_ALWAYS_INLINE void wrist_lanes(const SphCtx& x, const ArmL<T>& a, T sgn, WristL<T>& o) {
  const IkSolverData& m = *x.m;
  const Eigen::Matrix3d& A = m.A;
  const Eigen::Matrix3d& B = m.B;
  const IkSignedPerm &pA = m.perm[4], &pB = m.perm[5];
  const T c5 = x.cphi5 * a.ct - sgn * x.sphi5 * a.st, s5 = x.sphi5 * a.ct + sgn * x.cphi5 * a.st;
  auto rz = [](T c, T s, const T* v, T* r) {
    r[0] = c * v[0] - s * v[1];
    r[1] = s * v[0] + c * v[1];
    r[2] = v[2];
  };
  T w[3];
  const T v5[3] = {c5 * B(0, 2) - s5 * B(1, 2), s5 * B(0, 2) + c5 * B(1, 2), bc<T>(B(2, 2))};
  apply_l(A, pA, v5, w);
  o.wxy2 = w[0] * w[0] + w[1] * w[1];
  T c4, s4;
  angle_between_l(w[0], w[1], a.M[0][2], a.M[1][2], c4, s4);
  const auto keep4 = o.wxy2 < kKeepQ4;  // theta5 = 0 family: keep q4
  c4 = o.c4 = select(keep4, bc<T>(x.c4ref), c4);
  s4 = o.s4 = select(keep4, bc<T>(x.s4ref), s4);
  const T xv[3] = {c4 * a.M[0][0] + s4 * a.M[1][0], c4 * a.M[1][0] - s4 * a.M[0][0], a.M[2][0]};
  T y[3], z[3];
  apply_t_l(A, pA, xv, y);
  const T y5[3] = {c5 * y[0] + s5 * y[1], c5 * y[1] - s5 * y[0], y[2]};
  apply_t_l(B, pB, y5, z);
  T c6, s6;
  angle_between_l(bc<T>(1.0), bc<T>(0.0), z[0], z[1], c6, s6);
  o.c6 = c6;
  o.s6 = s6;
  // x_k = Rz(m4) A Rz(m5) b_k for B's columns b_k; x_2 = Rz(m4) w.
  T x0[3], x1[3], tmp[3], tmp2[3], x2[3];
  {
    const T b0[3] = {bc<T>(B(0, 0)), bc<T>(B(1, 0)), bc<T>(B(2, 0))};
    rz(c5, s5, b0, tmp);
    apply_l(A, pA, tmp, tmp2);
    rz(c4, s4, tmp2, x0);
    const T b1[3] = {bc<T>(B(0, 1)), bc<T>(B(1, 1)), bc<T>(B(2, 1))};
    rz(c5, s5, b1, tmp);
    apply_l(A, pA, tmp, tmp2);
    rz(c4, s4, tmp2, x1);
    rz(c4, s4, w, x2);
  }
  T f2 = bc<T>(0.0);
  T e[3] = {a.e3.x, a.e3.y, a.e3.z};
  for (int r = 0; r < 3; ++r) {
    const T d0 = c6 * x0[r] + s6 * x1[r] - a.M[r][0];
    const T d1 = c6 * x1[r] - s6 * x0[r] - a.M[r][1];
    const T d2 = x2[r] - a.M[r][2];
    f2 = f2 + d0 * d0 + d1 * d1 + d2 * d2;
    e[r] = e[r] - (x.u.x() * d0 + x.u.y() * d1 + x.u.z() * d2);
  }
  o.f2 = f2;
  o.ep = detail::lsqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
}

}  // namespace

void solve_spherical(const IkModel& model, const Pose& target, const JointVector* q_ref, IkResult& res) {
  const IkSolverData& m = solver_data(model);
  const Eigen::Vector3d W = target * model.w_tool;
  const Eigen::Matrix3d& C0R = C(m, 0).linear();
  const Eigen::Vector3d p0 = C0R.transpose() * (W - C(m, 0).translation());
  double mref[6] = {0, 0, 0, 0, 0, 0};
  if (q_ref)
    for (int j = 0; j < 6; ++j) mref[j] = m.dir[static_cast<std::size_t>(j)] * (*q_ref)[j];
  PosCand pc[8];
  const int np = solve_position(m, p0, q_ref ? &mref[1] : nullptr, pc, false);
  if (np == 0) return;
  SphCtx x;
  x.m = &m;
  x.p2 = prism(m, 1);
  x.p3 = prism(m, 2);
  x.p0 = p0;
  x.Rt0 = C0R.transpose() * target.linear() * C(m, 6).linear().transpose();
  x.u = apply(C(m, 6).linear(), m.perm[6], model.w_tool);
  detail::sincos_poly(mref[0], x.s1ref, x.c1ref);
  detail::sincos_poly(mref[3], x.s4ref, x.c4ref);
  x.p0xy2 = p0.x() * p0.x() + p0.y() * p0.y();
  x.tiny_xy2 = 1e-18 * m.scale * m.scale;  // (1e-9 scale)^2
  x.h5 = std::sqrt(m.wrist_P * m.wrist_P + m.wrist_Q * m.wrist_Q);
  x.cphi5 = m.wrist_P / x.h5;
  x.sphi5 = m.wrist_Q / x.h5;
  x.tilt_pos = std::abs(x.h5 + m.wrist_gz_vz - 1.0) < 1e-12;
  x.tilt_neg = std::abs(x.h5 - m.wrist_gz_vz - 1.0) < 1e-12;

  // atan2 arguments, evaluated in one batch at the end.
  double sy[8 * 6 + 1], sx[8 * 6 + 1];
  int ns = 0;
  auto slot = [&](double y, double x) {
    sy[ns] = y;
    sx[ns] = x;
    return ns++;
  };
  struct Arm {
    int s1, s2, s3, st;  ///< slots of m1, m2, m3 (-1: prismatic, value in v2/v3), t of m5
    double v2, v3;
    bool used;  ///< has wrist candidates
  };
  struct Cand {
    int arm, s4, s6, base;  ///< base >= 0: wrist flip of candidate `base` (m4, m6 + pi)
    double sgn;             ///< m5 = phi5 + sgn t
    Branch br;
    std::uint8_t sing;
    double ep, er;
  };
  Arm arms[8];
  int gslot2[2] = {-1, -1}, gslot3[2] = {-1, -1};  // shared root slots (PosCand g2, g3)
  Cand cand[16];
  int nc = 0;
  // Bookkeeping of arm configuration i from lane l of the arm stage and of
  // the wrist roots (w2: the second root, when it was computed).
  auto take = [&](int i, int l, const auto& a, const auto& w1, const auto* w2) {
    const PosCand& P = pc[i];
    arms[i].used = false;
    std::uint8_t sing = 0;
    if (lane(a.fxy2, l) < x.tiny_xy2 && x.p0xy2 < x.tiny_xy2) sing |= kSingularShoulder;
    Branch br;
    const double sh = lane(a.sh, l);
    br.shoulder = sh >= 0 ? 1 : -1;
    if (std::abs(sh) < kNearSingular * m.scale) sing |= kSingularShoulder;
    const double det = lane(a.det, l);
    br.elbow = P.elbow != 0 ? P.elbow : static_cast<std::int8_t>((det >= 0 ? 1 : -1) * br.shoulder);
    if (det * det <= kNearSingular * kNearSingular * lane(a.den2, l) && !(sing & kSingularShoulder))
      sing |= kSingularElbow;
    if (P.free2) sing |= kSingularShoulder;
    if (lane(a.um, l) < -1e-9 || lane(a.up, l) < -1e-9) return;  // |k| > 1 + 1e-9: no wrist solution
    const double st = lane(a.st, l);
    const int n5 = st > 0 ? 2 : 1;
    Arm& arm = arms[i];
    arm.used = true;
    arm.s1 = slot(lane(a.s1, l), lane(a.c1, l));
    if (x.p2) arm.s2 = -1;
    else if (P.g2 >= 0 && gslot2[P.g2] >= 0) arm.s2 = gslot2[P.g2];
    else if (P.g2 >= 0) arm.s2 = gslot2[P.g2] = slot(P.s2, P.c2);
    else arm.s2 = slot(P.s2, P.c2);
    if (x.p3) arm.s3 = -1;
    else if (P.g3 >= 0 && gslot3[P.g3] >= 0) arm.s3 = gslot3[P.g3];
    else if (P.g3 >= 0) arm.s3 = gslot3[P.g3] = slot(P.s3, P.c3);
    else arm.s3 = slot(P.s3, P.c3);
    arm.v2 = P.c2;
    arm.v3 = P.c3;
    arm.st = slot(st, lane(a.ct, l));
    for (int k = 0; k < n5; ++k) {
      const double sgn = k == 0 ? 1.0 : -1.0;
      Cand& cd = cand[nc];
      if (k == 1 && m.wrist_flip && !(lane(w1.wxy2, l) < kKeepQ4)) {
        // (m4 + pi, 2 phi5 - m5, m6 + pi): the same wrist rotation X as the
        // first root's (identity checked at set-up), so the same errors and
        // the same |w_xy| (the wrist-singularity test): nothing to compute.
        // Also near the singularity (theta5 -> 0, q4 ill-conditioned but
        // q4 + q6 not): the identity holds for any q4. Only where q4 was
        // kept at the reference is the second root computed.
        cd = cand[nc - 1];
        cd.sgn = sgn;
        cd.base = nc - 1;
        cd.s4 = cd.s6 = -1;
        cd.br.wrist = static_cast<std::int8_t>(sgn);
        ++nc;
        continue;
      }
      const auto& w = k == 0 ? w1 : *w2;
      cd.arm = i;
      cd.sgn = sgn;
      cd.base = -1;
      cd.sing = sing;
      if (lane(w.wxy2, l) < kNearSingular * kNearSingular) cd.sing |= kSingularWrist;
      cd.s4 = slot(lane(w.s4, l), lane(w.c4, l));
      cd.s6 = slot(lane(w.s6, l), lane(w.c6, l));
      cd.ep = lane(w.ep, l);
      const double f2 = lane(w.f2, l);
      cd.er = f2 < 1e-8 ? std::sqrt(0.5 * f2) : 2.0 * std::asin(std::min(1.0, std::sqrt(f2 / 8.0)));
      cd.br = br;
      cd.br.wrist = static_cast<std::int8_t>(sgn);
      ++nc;
    }
  };
  // Whether lane l needs its second wrist root computed (no wrist flip).
  auto second = [&](const auto& a, const auto& w1, int l) {
    return lane(a.st, l) > 0 && !(lane(a.um, l) < -1e-9 || lane(a.up, l) < -1e-9) &&
           !(m.wrist_flip && !(lane(w1.wxy2, l) < kKeepQ4));
  };
  int i = 0;
  for (; i + 1 < np; i += 2) {  // two arm configurations at a time
    ArmL<v2d> a;
    arm_lanes(x, v2d{pc[i].c2, pc[i + 1].c2}, v2d{pc[i].s2, pc[i + 1].s2}, v2d{pc[i].c3, pc[i + 1].c3},
              v2d{pc[i].s3, pc[i + 1].s3}, a);
    WristL<v2d> w1, w2;
    wrist_lanes(x, a, bc<v2d>(1.0), w1);
    const bool need2 = second(a, w1, 0) || second(a, w1, 1);
    if (need2) wrist_lanes(x, a, bc<v2d>(-1.0), w2);
    take(i, 0, a, w1, need2 ? &w2 : nullptr);
    take(i + 1, 1, a, w1, need2 ? &w2 : nullptr);
  }
  if (i < np) {
    ArmL<double> a;
    arm_lanes(x, pc[i].c2, pc[i].s2, pc[i].c3, pc[i].s3, a);
    WristL<double> w1, w2;
    wrist_lanes(x, a, 1.0, w1);
    const bool need2 = second(a, w1, 0);
    if (need2) wrist_lanes(x, a, -1.0, w2);
    take(i, 0, a, w1, need2 ? &w2 : nullptr);
  }
  // Every angle in one batch, then wrapped into the limits (joints 1-3 once
  // per arm configuration).
  double ang[8 * 6 + 1];
  if (ns & 1) {  // pad to pairs
    sy[ns] = 0.0;
    sx[ns] = 1.0;
  }
  for (int i = 0; i < ns; i += 2) detail::atan2_poly_x2(sy + i, sx + i, ang + i);
  // Wrapping into the limits with the per-joint table of ik_prepare(): a
  // joint whose limits span less than a turn has at most one equivalent
  // inside (no reference needed: branch-free), others follow the rule.
  double ref[6], dir[6];
  bool narrow[6];
  for (int j = 0; j < 6; ++j) {
    ref[j] = q_ref ? (*q_ref)[j] : 0.0;
    dir[j] = m.dir[static_cast<std::size_t>(j)];
    narrow[j] = detail::narrow_applies(m.wrap[static_cast<std::size_t>(j)], ref[j]);
  }
  // v = dir * motion, |v| < 3 pi (atan2 output, or that + pi)
  auto wrap = [&](int j, double v) {
    const IkJointWrap& jw = m.wrap[static_cast<std::size_t>(j)];
    if (jw.kind == 0) return v;
    const double w = v > kPi ? v - 2.0 * kPi : (v <= -kPi ? v + 2.0 * kPi : v);
    if (narrow[j]) return detail::wrap_narrow(jw, w);
    return detail::wrap_into_limits(w, jw.lo, jw.hi, ref[j]);
  };
  // one step of fast_wrap (|a| < 3 pi)
  auto wrap1 = [](double a) { return a > kPi ? a - 2.0 * kPi : (a <= -kPi ? a + 2.0 * kPi : a); };
  // Same joint value: within 1e-7 (revolute: modulo 2 pi). Most pairs
  // differ by more than 1e-7 and less than 2 pi - 2e-7 (no wrap needed).
  auto same_joint = [&](int j, double a, double b) {
    const double d = std::abs(a - b);
    if (d <= 1e-7) return true;
    return m.wrap[static_cast<std::size_t>(j)].kind != 0 && d >= 2.0 * kPi - 2e-7 && std::abs(fast_wrap(a - b)) <= 1e-7;
  };
  auto in_limits = [&](int j, double q) {
    const IkJointWrap& jw = m.wrap[static_cast<std::size_t>(j)];
    return (q >= jw.lo9) & (q <= jw.hi9);
  };
  // Arm joints: wrapped and checked against the limits once per arm
  // configuration; which configurations have the same arm joints (only
  // their solutions can be duplicates of each other: near a double root).
  double qarm[8 * 3], mot_arm[8 * 3];
  bool in_arm[8];
  unsigned arm_same[8];
  for (int i = 0; i < np; ++i) {
    const Arm& a = arms[i];
    if (!a.used) continue;
    mot_arm[i * 3] = ang[a.s1];
    mot_arm[i * 3 + 1] = a.s2 >= 0 ? ang[a.s2] : a.v2;
    mot_arm[i * 3 + 2] = a.s3 >= 0 ? ang[a.s3] : a.v3;
    bool in = true;
    for (int j = 0; j < 3; ++j) {
      qarm[i * 3 + j] = wrap(j, dir[j] * mot_arm[i * 3 + j]);
      in &= in_limits(j, qarm[i * 3 + j]);
    }
    in_arm[i] = in;
    arm_same[i] = 1u << i;
    for (int t = 0; t < i; ++t) {
      if (!arms[t].used) continue;
      bool same = true;
      for (int j = 0; j < 3 && same; ++j) same = same_joint(j, qarm[i * 3 + j], qarm[t * 3 + j]);
      if (same) {
        arm_same[i] |= 1u << t;
        arm_same[t] |= 1u << i;
      }
    }
  }
  double wm[16][3];
  int owner[kMaxIkSolutions];  // candidate index of each stored solution (-1: add_candidate's)
  int stored[8] = {0, 0, 0, 0, 0, 0, 0, 0};  // solutions stored per arm configuration
  bool foreign = false;                       // add_candidate stored one
  for (int k = 0; k < nc; ++k) {
    const Cand& cd = cand[k];
    const int i = cd.arm;
    wm[k][1] = m.wrist_phi + cd.sgn * ang[arms[i].st];
    if (cd.base >= 0) {
      wm[k][0] = wm[cd.base][0] + kPi;
      wm[k][2] = wm[cd.base][2] + kPi;
    } else {
      wm[k][0] = ang[cd.s4];
      wm[k][2] = ang[cd.s6];
    }
    if (cd.ep <= kVerifyPos && cd.er <= kVerifyRot) {
      if (res.count >= kMaxIkSolutions) break;
      IkSolution& sol = res.solutions[static_cast<std::size_t>(res.count)];
      sol.q.resize(6);
      double q[6];
      for (int j = 0; j < 3; ++j) q[j] = qarm[i * 3 + j];
      for (int j = 3; j < 6; ++j) q[j] = wrap(j, dir[j] * wrap1(wm[k][j - 3]));
      // De-duplication (every joint the same): against solutions of arm
      // configurations with the same arm joints, wrist joints only; a wrist
      // flip (m4 + pi) never repeats its base. add_candidate's: all joints.
      // Generic pose: no other arm configuration has the same arm joints and
      // this is the first solution of its own or the flip of it: none to test.
      const bool alone = arm_same[i] == (1u << i) && !foreign &&
                         (cd.base >= 0 ? stored[i] == 1 && owner[res.count - 1] == cd.base : stored[i] == 0);
      bool dup = false;
      for (int t = 0; t < res.count && !dup && !alone; ++t) {
        const int ot = owner[t];
        const JointVector& o = res.solutions[static_cast<std::size_t>(t)].q;
        int j0 = 0;
        if (ot >= 0) {
          if (!((arm_same[i] >> cand[ot].arm) & 1u) || cd.base == ot) continue;
          j0 = 3;
        }
        bool same = true;
        for (int j = j0; j < 6 && same; ++j) same = same_joint(j, q[j], o[j]);
        dup = same;
      }
      if (dup) continue;
      bool in = in_arm[i];
      for (int j = 0; j < 6; ++j) sol.q[j] = q[j];
      for (int j = 3; j < 6; ++j) in &= in_limits(j, q[j]);
      owner[res.count] = k;
      ++stored[i];
      sol.branch = cd.br;
      sol.within_limits = in;
      sol.singular = cd.sing;
      sol.position_error = cd.ep;
      sol.rotation_error = cd.er;
      ++res.count;
    } else if (cd.ep < 1e-4 * m.scale && cd.er < 1e-4) {
      const double all[6] = {mot_arm[i * 3], mot_arm[i * 3 + 1], mot_arm[i * 3 + 2], wm[k][0], wm[k][1], wm[k][2]};
      const int before = res.count;
      add_candidate(model, target, q_ref, all, cd.br, cd.sing, false, res);
      for (int t = before; t < res.count; ++t) owner[t] = -1;
      foreign = foreign || res.count > before;
    }
  }
}

}  // namespace servoarm::kin::detail
