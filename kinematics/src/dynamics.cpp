// SPDX-License-Identifier: Apache-2.0
// Rigid-body dynamics over DH rows: recursive Newton-Euler, composite rigid body,
// forward dynamics by a fixed-size LDL^T. Real-time code: no heap, no exceptions.
//
// Every DH row is split into a joint motion along/about z and a constant transform:
//   standard  A_i = [Rz(theta_i) Tz(d_i)] [Tx(a_i) Rx(alpha_i)]
//   modified  A_i = [Rx(alpha_{i-1}) Tx(a_{i-1})] [Rz(theta_i) Tz(d_i)]
// so that in the "joint frame" J_i (the frame right after Rz Tz) the joint axis is
// always +z, and the transform from J_{i-1} to J_i is
//   R = Rx(alpha') Rz(theta),   p = (a', -sin(alpha') d, cos(alpha') d)
// with (alpha', a') the previous row's (standard; 0 for the first row) or the row's
// own (modified). Bodies are described in their joint frame: set_inertial() moves the
// description's COM and inertia (given in the DH frame i) there once. For the modified
// convention J_i is the DH frame i; for the standard one J_i = frame_i (Tx(a) Rx(alpha))^-1.
//
// Newton-Euler in body frames (Luh, Walker, Paul 1980), base acceleration -g so
// gravity costs nothing extra:
//   w_i  = R^T w_{i-1} + s qd_i                       (revolute, s = direction * z)
//   wd_i = R^T wd_{i-1} + (R^T w_{i-1}) x s qd_i + s qdd_i
//   a_i  = R^T (a_{i-1} + wd_{i-1} x p + w_{i-1} x (w_{i-1} x p))
//          (+ 2 w_i x s qd_i + s qdd_i for a prismatic joint)
//   f_i  = m a_i + wd_i x h + w_i x (w_i x h),   h = m c (c: COM in J_i)
//   n_i  = I_o wd_i + w_i x (I_o w_i) + h x a_i   (I_o: inertia about J_i's origin)
//   F_i  = f_i + R_{i+1} F_{i+1},  N_i = n_i + R_{i+1} N_{i+1} + p_{i+1} x R_{i+1} F_{i+1}
//   tau_i = s . N_i (revolute) or s . F_i (prismatic)
// Composite rigid body (Walker-Orin method 3): composite inertias (m, h, I_o) summed from
// the tip, each column of M the force of a unit joint motion carried down to the base.
#include "servoarm/kinematics/dynamics.hpp"

#include <cmath>

#include "fast_trig.hpp"

namespace servoarm::kin {
namespace {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;

struct RowX {
  Mat3 R;  // rotation J_{i-1} -> J_i (columns: J_i's axes in J_{i-1})
  Vec3 p;  // origin of J_i in J_{i-1}
};

inline bool finite(const JointVector& v) {
  for (int i = 0; i < v.size(); ++i)
    if (!std::isfinite(v[i])) return false;
  return true;
}

inline Status check(const Chain& chain, const JointVector& v) {
  if (v.size() != chain.n_joints) return Status::wrong_size;
  if (!finite(v)) return Status::bad_input;
  return Status::ok;
}

// The row transforms at q. For alpha' the precomputed cos/sin of the row that owns it.
void transforms(const Chain& chain, const JointVector& q, RowX* X) {
  const bool modified = chain.convention == Convention::modified;
  double th[kMaxJoints], sn[kMaxJoints], cs[kMaxJoints];
  const int nj = chain.n_joints;
  for (int j = 0; j < nj; ++j) {
    const DhRow& r = chain.joint(j);
    th[j] = r.type == JointType::revolute ? r.theta + r.direction * q[j] : r.theta;
  }
  for (int j = 0; j < nj; ++j) detail::sincos_poly(th[j], sn[j], cs[j]);
  int j = 0;
  for (int i = 0; i < chain.n_rows; ++i) {
    const DhRow& r = chain.rows[static_cast<std::size_t>(i)];
    double ca = 1, sa = 0, a = 0;
    if (modified) {
      ca = r.ca, sa = r.sa, a = r.a;
    } else if (i > 0) {
      const DhRow& pr = chain.rows[static_cast<std::size_t>(i - 1)];
      ca = pr.ca, sa = pr.sa, a = pr.a;
    }
    double ct = r.ct, st = r.st, d = r.d;
    if (r.type == JointType::revolute) {
      ct = cs[j], st = sn[j];
    } else if (r.type == JointType::prismatic) {
      d = r.d + r.direction * q[j];
    }
    if (r.type != JointType::fixed) ++j;
    Mat3& R = X[i].R;
    R << ct, -st, 0, ca * st, ca * ct, -sa, sa * st, sa * ct, ca;
    X[i].p = Vec3(a, -sa * d, ca * d);
  }
}

inline Vec3 sym_mul(const std::array<double, 6>& I, const Vec3& v) {
  // I: xx yy zz xy xz yz
  return Vec3(I[0] * v.x() + I[3] * v.y() + I[4] * v.z(), I[3] * v.x() + I[1] * v.y() + I[5] * v.z(),
              I[4] * v.x() + I[5] * v.y() + I[2] * v.z());
}

inline Vec3 vec(const std::array<double, 3>& a) { return Vec3(a[0], a[1], a[2]); }

// Newton-Euler. kMotion false: q only (gravity). qdd may be null (zero acceleration).
// with_gravity: base acceleration -g (in the base frame) or zero.
template <bool kMotion>
void rnea(const Chain& chain, const RowX* X, const JointVector* qd, const JointVector* qdd,
          bool with_gravity, JointVector& tau) {
  Vec3 f[kMaxRows], n[kMaxRows];
  Vec3 w = Vec3::Zero(), wd = Vec3::Zero(), a = Vec3::Zero();
  if (with_gravity) a = -(chain.base.linear().transpose() * vec(chain.gravity));
  int j = 0;
  const int N = chain.n_rows;
  for (int i = 0; i < N; ++i) {
    const DhRow& r = chain.rows[static_cast<std::size_t>(i)];
    const Mat3& R = X[i].R;
    const Vec3& p = X[i].p;
    if constexpr (kMotion) {
      a = R.transpose() * (a + wd.cross(p) + w.cross(w.cross(p)));
      w = R.transpose() * w;
      wd = R.transpose() * wd;
      if (r.type != JointType::fixed) {
        const double v = r.direction * (*qd)[j];
        const double acc = qdd ? r.direction * (*qdd)[j] : 0.0;
        if (r.type == JointType::revolute) {
          wd += Vec3(w.y() * v, -w.x() * v, acc);
          w.z() += v;
        } else {
          a += Vec3(2 * w.y() * v, -2 * w.x() * v, acc);
        }
        ++j;
      }
    } else {
      a = R.transpose() * a;
    }
    const LinkInertial& L = chain.inertial[static_cast<std::size_t>(i)];
    const Vec3 h = vec(L.mc);
    if constexpr (kMotion) {
      const Vec3 Iw = sym_mul(L.io, w);
      f[i] = L.mass * a + wd.cross(h) + w.cross(w.cross(h));
      n[i] = sym_mul(L.io, wd) + w.cross(Iw) + h.cross(a);
    } else {
      f[i] = L.mass * a;
      n[i] = h.cross(a);
    }
  }
  // Backward: accumulate the forces from the tip.
  Vec3 F = Vec3::Zero(), Nm = Vec3::Zero();
  j = chain.n_joints - 1;
  for (int i = N - 1; i >= 0; --i) {
    if (i < N - 1) {
      const Vec3 RF = X[i + 1].R * F;
      Nm = n[i] + X[i + 1].R * Nm + X[i + 1].p.cross(RF);
      F = f[i] + RF;
    } else {
      F = f[i];
      Nm = n[i];
    }
    const DhRow& r = chain.rows[static_cast<std::size_t>(i)];
    if (r.type == JointType::fixed) continue;
    tau[j] = r.direction * (r.type == JointType::revolute ? Nm.z() : F.z());
    --j;
  }
}

inline double rotor(const LinkInertial& L) { return L.gear_ratio * L.gear_ratio * L.rotor_inertia; }

void add_friction(const Chain& chain, const JointVector& qd, JointVector& tau) {
  for (int j = 0; j < chain.n_joints; ++j) {
    const LinkInertial& L = chain.inertial[static_cast<std::size_t>(chain.joint_row[static_cast<std::size_t>(j)])];
    const double v = qd[j];
    tau[j] += L.viscous * v + (v > 0 ? L.coulomb : v < 0 ? -L.coulomb : 0.0);
  }
}

void crba(const Chain& chain, const RowX* X, MassMatrix& M) {
  const int N = chain.n_rows;
  const int nj = chain.n_joints;
  M.resize(nj, nj);
  // Composite inertia of rows i..N-1 in J_i.
  double m = 0;
  Vec3 h = Vec3::Zero();
  Mat3 I = Mat3::Zero();
  int j = nj - 1;
  for (int i = N - 1; i >= 0; --i) {
    if (i < N - 1) {
      const Mat3& R = X[i + 1].R;
      const Vec3& p = X[i + 1].p;
      const Vec3 u = R * h;
      Mat3 In = R * I * R.transpose();
      In -= u * p.transpose() + p * u.transpose() + m * (p * p.transpose());
      In.diagonal().array() += 2 * p.dot(u) + m * p.squaredNorm();
      I = In;
      h = u + m * p;
    }
    const LinkInertial& L = chain.inertial[static_cast<std::size_t>(i)];
    m += L.mass;
    h += vec(L.mc);
    I(0, 0) += L.io[0];
    I(1, 1) += L.io[1];
    I(2, 2) += L.io[2];
    I(0, 1) += L.io[3];
    I(1, 0) += L.io[3];
    I(0, 2) += L.io[4];
    I(2, 0) += L.io[4];
    I(1, 2) += L.io[5];
    I(2, 1) += L.io[5];
    const DhRow& r = chain.rows[static_cast<std::size_t>(i)];
    if (r.type == JointType::fixed) continue;
    // Force of a unit motion of joint j on the composite body, in J_i.
    const double s = r.direction;
    Vec3 f, n;
    if (r.type == JointType::revolute) {
      f = s * Vec3(-h.y(), h.x(), 0);
      n = s * I.col(2);
    } else {
      f = Vec3(0, 0, s * m);
      n = s * Vec3(h.y(), -h.x(), 0);
    }
    M(j, j) = s * (r.type == JointType::revolute ? n.z() : f.z()) + rotor(L);
    int k = j - 1;
    for (int row = i; row > 0; --row) {
      const Vec3 f2 = X[row].R * f;
      n = X[row].R * n + X[row].p.cross(f2);
      f = f2;
      const DhRow& pr = chain.rows[static_cast<std::size_t>(row - 1)];
      if (pr.type == JointType::fixed) continue;
      M(k, j) = M(j, k) = pr.direction * (pr.type == JointType::revolute ? n.z() : f.z());
      --k;
    }
    --j;
  }
}

}  // namespace

Status set_inertial(Chain& chain, int row, const LinkInertial& in) {
  if (row < 0 || row >= chain.n_rows) return Status::bad_input;
  const double vals[] = {in.mass, in.com[0], in.com[1], in.com[2], in.inertia[0], in.inertia[1],
                         in.inertia[2], in.inertia[3], in.inertia[4], in.inertia[5], in.rotor_inertia,
                         in.gear_ratio, in.viscous, in.coulomb};
  for (double v : vals)
    if (!std::isfinite(v)) return Status::bad_input;
  LinkInertial L = in;
  const DhRow& r = chain.rows[static_cast<std::size_t>(row)];
  Vec3 c = vec(in.com);
  Mat3 Ic;
  Ic << in.inertia[0], in.inertia[3], in.inertia[4], in.inertia[3], in.inertia[1], in.inertia[5],
      in.inertia[4], in.inertia[5], in.inertia[2];
  if (chain.convention == Convention::standard) {
    // x_J = Tx(a) Rx(alpha) x_DH.
    Mat3 Rx;
    Rx << 1, 0, 0, 0, r.ca, -r.sa, 0, r.sa, r.ca;
    c = Vec3(r.a, 0, 0) + Rx * c;
    Ic = Rx * Ic * Rx.transpose();
  }
  const Mat3 Io = Ic + in.mass * (c.squaredNorm() * Mat3::Identity() - c * c.transpose());
  for (int k = 0; k < 3; ++k) L.mc[static_cast<std::size_t>(k)] = in.mass * c[k];
  L.io = {Io(0, 0), Io(1, 1), Io(2, 2), Io(0, 1), Io(0, 2), Io(1, 2)};
  chain.inertial[static_cast<std::size_t>(row)] = L;
  chain.has_inertial = true;
  return Status::ok;
}

Status inverse_dynamics(const Chain& chain, const JointVector& q, const JointVector& qd,
                        const JointVector& qdd, JointVector& tau) {
  Status s = check(chain, q);
  if (s == Status::ok) s = check(chain, qd);
  if (s == Status::ok) s = check(chain, qdd);
  if (s != Status::ok) return s;
  if (!chain.has_inertial) return Status::unsupported;
  RowX X[kMaxRows];
  transforms(chain, q, X);
  tau.resize(chain.n_joints);
  rnea<true>(chain, X, &qd, &qdd, true, tau);
  for (int j = 0; j < chain.n_joints; ++j)
    tau[j] += rotor(chain.inertial[static_cast<std::size_t>(chain.joint_row[static_cast<std::size_t>(j)])]) * qdd[j];
  add_friction(chain, qd, tau);
  return Status::ok;
}

Status gravity_torques(const Chain& chain, const JointVector& q, JointVector& tau) {
  const Status s = check(chain, q);
  if (s != Status::ok) return s;
  if (!chain.has_inertial) return Status::unsupported;
  RowX X[kMaxRows];
  transforms(chain, q, X);
  tau.resize(chain.n_joints);
  rnea<false>(chain, X, nullptr, nullptr, true, tau);
  return Status::ok;
}

Status coriolis(const Chain& chain, const JointVector& q, const JointVector& qd, JointVector& c) {
  Status s = check(chain, q);
  if (s == Status::ok) s = check(chain, qd);
  if (s != Status::ok) return s;
  if (!chain.has_inertial) return Status::unsupported;
  RowX X[kMaxRows];
  transforms(chain, q, X);
  c.resize(chain.n_joints);
  rnea<true>(chain, X, &qd, nullptr, false, c);
  return Status::ok;
}

Status friction_torques(const Chain& chain, const JointVector& qd, JointVector& tau) {
  const Status s = check(chain, qd);
  if (s != Status::ok) return s;
  if (!chain.has_inertial) return Status::unsupported;
  tau.setZero(chain.n_joints);
  add_friction(chain, qd, tau);
  return Status::ok;
}

Status mass_matrix(const Chain& chain, const JointVector& q, MassMatrix& M) {
  const Status s = check(chain, q);
  if (s != Status::ok) return s;
  if (!chain.has_inertial) return Status::unsupported;
  RowX X[kMaxRows];
  transforms(chain, q, X);
  crba(chain, X, M);
  return Status::ok;
}

Status forward_dynamics(const Chain& chain, const JointVector& q, const JointVector& qd,
                        const JointVector& tau, JointVector& qdd) {
  Status s = check(chain, q);
  if (s == Status::ok) s = check(chain, qd);
  if (s == Status::ok) s = check(chain, tau);
  if (s != Status::ok) return s;
  if (!chain.has_inertial) return Status::unsupported;
  RowX X[kMaxRows];
  transforms(chain, q, X);
  MassMatrix M;
  crba(chain, X, M);
  const int n = chain.n_joints;
  JointVector b(n);
  rnea<true>(chain, X, &qd, nullptr, true, b);  // c + g
  add_friction(chain, qd, b);
  // LDL^T in place (lower triangle of M: L below the diagonal, D on it). Written out:
  // n <= 8, and the pivot test must be ours (Eigen's LDLT pivots and reports through info()).
  const double scale = M.diagonal().cwiseAbs().maxCoeff();
  for (int k = 0; k < n; ++k) {
    double d = M(k, k);
    for (int p = 0; p < k; ++p) d -= M(k, p) * M(k, p) * M(p, p);
    if (!(d > 1e-14 * scale)) return Status::unsupported;
    M(k, k) = d;
    for (int i = k + 1; i < n; ++i) {
      double v = M(i, k);
      for (int p = 0; p < k; ++p) v -= M(i, p) * M(k, p) * M(p, p);
      M(i, k) = v / d;
    }
  }
  JointVector x = tau - b;
  for (int i = 0; i < n; ++i)
    for (int p = 0; p < i; ++p) x[i] -= M(i, p) * x[p];
  for (int i = 0; i < n; ++i) x[i] /= M(i, i);
  for (int i = n - 1; i >= 0; --i)
    for (int p = i + 1; p < n; ++p) x[i] -= M(p, i) * x[p];
  qdd = x;
  return Status::ok;
}

}  // namespace servoarm::kin
