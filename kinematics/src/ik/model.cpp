// SPDX-License-Identifier: Apache-2.0
// Inverse kinematics, the model: ik_prepare() rewrites a chain as
// C0 J1 C1 ... Jn Cn and recognises which closed form fits it (IkMethod; see
// ik.hpp), ik_solve_all() checks its input and dispatches on that class
// (spherical_wrist.cpp, reduced.cpp). Set-up code: heap-free, not real-time.
#include "servoarm/kinematics/ik.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>

#include <Eigen/LU>

#include "ik_detail.hpp"
#include "servoarm/kinematics/orientation.hpp"

namespace servoarm::kin {

const char* to_string(IkMethod m) {
  switch (m) {
    case IkMethod::none: return "numeric";
    case IkMethod::spherical_wrist: return "spherical_wrist";
    case IkMethod::opw: return "opw";
    case IkMethod::ur: return "ur";
    case IkMethod::spherical_general: return "spherical_general";
    case IkMethod::planar_2r: return "planar_2r";
    case IkMethod::planar_3: return "planar_3";
    case IkMethod::spatial_3: return "spatial_3";
    case IkMethod::pitch_4: return "pitch_4";
  }
  return "unknown";
}

const char* singular_kinds_to_string(std::uint8_t kinds, char* buf, int size) {
  if (size <= 0) return buf;
  buf[0] = '\0';
  if (kinds == 0) {
    std::snprintf(buf, static_cast<std::size_t>(size), "none");
    return buf;
  }
  std::snprintf(buf, static_cast<std::size_t>(size), "%s%s%s%s%s",
                (kinds & kSingularWrist) ? "wrist" : "",
                ((kinds & kSingularWrist) && (kinds & (kSingularShoulder | kSingularElbow))) ? "|" : "",
                (kinds & kSingularShoulder) ? "shoulder" : "",
                ((kinds & kSingularShoulder) && (kinds & kSingularElbow)) ? "|" : "",
                (kinds & kSingularElbow) ? "elbow" : "");
  return buf;
}

namespace detail {

// IkModel::solver holds an IkSolverData in place (ik.hpp, ik_detail.hpp).
IkSolverStorage::IkSolverStorage() { ::new (static_cast<void*>(bytes_)) IkSolverData(); }
IkSolverStorage::IkSolverStorage(const IkSolverStorage& other) {
  ::new (static_cast<void*>(bytes_)) IkSolverData(IkSolverAccess::get(other));
}
IkSolverStorage& IkSolverStorage::operator=(const IkSolverStorage& other) {
  IkSolverAccess::get(*this) = IkSolverAccess::get(other);
  return *this;
}
IkSolverStorage::~IkSolverStorage() { IkSolverAccess::get(*this).~IkSolverData(); }

namespace {

Pose rx_pose(double a) {
  Pose T = Pose::Identity();
  const double c = std::cos(a), s = std::sin(a);
  T.linear() << 1, 0, 0, 0, c, -s, 0, s, c;
  return T;
}
Pose rz_pose(double a) {
  Pose T = Pose::Identity();
  T.linear() = rot_z(a);
  return T;
}
Pose tx_pose(double a) {
  Pose T = Pose::Identity();
  T.translation().x() = a;
  return T;
}
Pose tz_pose(double d) {
  Pose T = Pose::Identity();
  T.translation().z() = d;
  return T;
}

// R as a signed permutation, if it is one (to 1e-15).
IkSignedPerm signed_perm(const Eigen::Matrix3d& R) {
  IkSignedPerm p;
  for (int j = 0; j < 3; ++j) {
    int k = 0;
    R.col(j).cwiseAbs().maxCoeff(&k);
    if (std::abs(std::abs(R(k, j)) - 1.0) > 1e-15) return IkSignedPerm{};
    for (int r = 0; r < 3; ++r)
      if (r != k && std::abs(R(r, j)) > 1e-15) return IkSignedPerm{};
    p.idx[static_cast<std::size_t>(j)] = static_cast<std::int8_t>(k);
    p.sign[static_cast<std::size_t>(j)] = R(k, j) > 0 ? 1.0 : -1.0;
  }
  p.is = true;
  return p;
}

// Rewrite the chain as C0 J1 C1 ... Jn Cn.
void decompose(const Chain& c, IkSolverData& m) {
  Pose K = c.base;
  int j = 0;
  double scale = 0;
  for (int i = 0; i < c.n_rows; ++i) {
    const DhRow& r = c.rows[static_cast<std::size_t>(i)];
    scale += std::abs(r.a) + std::abs(r.d);
    if (r.type == JointType::prismatic) scale += std::max(std::abs(r.lower), std::abs(r.upper)) * (std::isfinite(r.upper) ? 1.0 : 0.0);
    const bool joint = r.type != JointType::fixed;
    if (c.convention == Convention::standard) {
      K = K * rz_pose(r.theta) * tz_pose(r.d);
      if (joint) {
        m.C[static_cast<std::size_t>(j)] = K;
        m.prismatic[static_cast<std::size_t>(j)] = r.type == JointType::prismatic;
        m.dir[static_cast<std::size_t>(j)] = r.direction;
        ++j;
        K = Pose::Identity();
      }
      K = K * tx_pose(r.a) * rx_pose(r.alpha);
    } else {
      K = K * rx_pose(r.alpha) * tx_pose(r.a) * rz_pose(r.theta) * tz_pose(r.d);
      if (joint) {
        m.C[static_cast<std::size_t>(j)] = K;
        m.prismatic[static_cast<std::size_t>(j)] = r.type == JointType::prismatic;
        m.dir[static_cast<std::size_t>(j)] = r.direction;
        ++j;
        K = Pose::Identity();
      }
    }
  }
  m.C[static_cast<std::size_t>(j)] = K * c.tool;
  m.n = j;
  // Rotations that are signed permutations up to rounding (the usual 0 and
  // +-90 degree DH angles) are made exact, as forward() does with alpha.
  for (int i = 0; i <= j; ++i) {
    const IkSignedPerm p = signed_perm(m.C[static_cast<std::size_t>(i)].linear());
    if (!p.is) continue;
    Eigen::Matrix3d R = Eigen::Matrix3d::Zero();
    for (int k = 0; k < 3; ++k) R(p.idx[static_cast<std::size_t>(k)], k) = p.sign[static_cast<std::size_t>(k)];
    m.C[static_cast<std::size_t>(i)].linear() = R;
  }
  scale += c.tool.translation().norm() + c.base.translation().norm();
  m.scale = std::max(scale, 1e-3);
}

// Closest points of two lines; returns the distance, s/t the parameters.
double line_closest(const Eigen::Vector3d& p, const Eigen::Vector3d& u, const Eigen::Vector3d& q,
                    const Eigen::Vector3d& v, double& s, double& t) {
  const Eigen::Vector3d w0 = p - q;
  const double a = u.dot(u), b = u.dot(v), c = v.dot(v), d = u.dot(w0), e = v.dot(w0);
  const double den = a * c - b * b;
  if (den < 1e-14) {
    s = 0;
    t = e / c;
  } else {
    s = (b * e - c * d) / den;
    t = (a * e - b * d) / den;
  }
  return ((p + s * u) - (q + t * v)).norm();
}

// Set up the position subproblem of joints 1..3 for the point w3 (frame after
// J3 motion): lambda, M1, M2, shoulder direction.
void setup_position(IkSolverData& m) {
  const Eigen::Vector3d t1 = C(m, 1).translation();
  const Eigen::Vector3d n2 = C(m, 1).linear().col(2);
  const Eigen::Vector3d ez = Eigen::Vector3d::UnitZ();
  if (n2.cross(ez).norm() < 1e-9) {
    m.lambda = t1.z();
  } else {
    double s = 0, t = 0;
    line_closest(Eigen::Vector3d::Zero(), ez, t1, n2, s, t);
    m.lambda = s;
  }
  // Sample E1, E2 on a 3x3 grid of (m2, m3) and solve for the coefficients.
  auto samples = [](bool prismatic, double out[3]) {
    if (prismatic) {
      out[0] = 0; out[1] = 1; out[2] = -1;
    } else {
      out[0] = 0; out[1] = kPi / 2; out[2] = kPi;
    }
  };
  double s2[3], s3[3];
  samples(prism(m, 1), s2);
  samples(prism(m, 2), s3);
  Eigen::Matrix3d B2, B3, V1, V2;
  for (int i = 0; i < 3; ++i) {
    B2.row(i) = basis(prism(m, 1), s2[i]).transpose();
    B3.row(i) = basis(prism(m, 2), s3[i]).transpose();
  }
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d f = f_of(m, s2[i], s3[k], m.w3);
      V1(i, k) = (f - m.lambda * ez).squaredNorm();
      V2(i, k) = f.z();
    }
  const Eigen::Matrix3d B2i = B2.inverse(), B3it = B3.inverse().transpose();
  m.M1 = B2i * V1 * B3it;
  m.M2 = B2i * V2 * B3it;
  // Clean exact zeros (sampling leaves ~1e-17 noise).
  const double tol1 = 1e-13 * m.scale * m.scale, tol2 = 1e-13 * m.scale;
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) {
      if (std::abs(m.M1(i, k)) < tol1) m.M1(i, k) = 0;
      if (std::abs(m.M2(i, k)) < tol2) m.M2(i, k) = 0;
    }
  // Shoulder direction: perpendicular to axes 1 and 2, or (axes parallel)
  // the horizontal part of axis 3.
  const Eigen::Vector3d sd = ez.cross(n2);
  if (sd.norm() > 1e-6) {
    m.shoulder_dir = sd.normalized();
  } else {
    const Eigen::Vector3d n3 = (C(m, 1) * C(m, 2)).linear().col(2);
    Eigen::Vector3d h(n3.x(), n3.y(), 0);
    if (h.norm() < 1e-6) h = Eigen::Vector3d::UnitX();
    m.shoulder_dir = h.normalized();
  }
}

// Case P of the position subproblem (IkSolverData::par23): axes 2 and 3 revolute
// and parallel, not parallel to axis 1; w: the point that follows (frame after
// the J3 motion), f_w: its place in the frame after J1 motion at m2 = m3 = 0.
bool setup_parallel(IkSolverData& m, const Eigen::Vector3d& w, const Eigen::Vector3d& f_w) {
  m.par23 = false;
  if (prism(m, 0) || prism(m, 1) || prism(m, 2)) return false;
  const Eigen::Vector3d z3 = C(m, 2).linear().col(2);  // axis 3 in the frame of joint 2
  if (std::hypot(z3.x(), z3.y()) > 1e-9) return false;
  const Eigen::Vector3d n = C(m, 1).linear().col(2);
  if (std::hypot(n.x(), n.y()) < 1e-6) return false;  // axis 2 (nearly) parallel to axis 1
  m.n_par = n;
  m.beta = n.dot(f_w);
  m.w_par = w;
  // g(m3) = |(C2 Rz(m3) w)_xy|^2 = G0 + G1 c3 + G2 s3
  auto g = [&](double a) {
    const Eigen::Vector3d v = C(m, 2) * (rot_z(a) * w);
    return v.x() * v.x() + v.y() * v.y();
  };
  const double g0 = g(0), g1 = g(kPi / 2), g2 = g(kPi);
  m.g_par = {0.5 * (g0 + g2), 0.5 * (g0 - g2), g1 - 0.5 * (g0 + g2)};
  m.par23 = true;
  return true;
}

// UR-type arm (ur.cpp): 6 revolute joints, axes 2, 3, 4 parallel and not
// parallel to axis 1, axis 5 normal to them, axes 5 and 6 meeting.
bool detect_ur(IkModel& model) {
  IkSolverData& m = solver_data(model);
  if (m.n != 6) return false;
  for (int j = 0; j < 6; ++j)
    if (prism(m, j)) return false;
  const Eigen::Vector3d z4 = C(m, 3).linear().col(2);  // axis 4 in the frame of joint 3
  if (std::hypot(z4.x(), z4.y()) > 1e-9) return false;
  // Axes 5 and 6 in the frame after the J4 motion (m5 = 0).
  const Pose T6 = C(m, 4) * C(m, 5);
  const Eigen::Vector3d a5 = C(m, 4).linear().col(2), p5 = C(m, 4).translation();
  const Eigen::Vector3d a6 = T6.linear().col(2), p6 = T6.translation();
  if (std::abs(a5.z()) > 1e-9) return false;        // axis 5 normal to axis 4
  if (a5.cross(a6).norm() < 1e-6) return false;     // axes 5, 6 parallel
  double s = 0, t = 0;
  if (line_closest(p5, a5, p6, a6, s, t) > 1e-9 * m.scale) return false;
  const Eigen::Vector3d Q4 = p5 + s * a5;
  const Eigen::Vector3d Q1 = C(m, 1) * (C(m, 2) * (C(m, 3) * Q4));
  if (!setup_parallel(m, C(m, 3).translation(), Q1)) return false;
  model.w_tool = (C(m, 4) * C(m, 5) * C(m, 6)).inverse() * Q4;
  m.w3 = Q4;
  m.ur_c4z = C(m, 4).linear().transpose().col(2);
  auto uz = [&](double a) { return C(m, 5).linear().col(2).dot(rot_z(-a) * m.ur_c4z); };
  const double u0 = uz(0), u1 = uz(kPi / 2), u2 = uz(kPi);
  m.ur_u5 = {0.5 * (u0 + u2), 0.5 * (u0 - u2), u1 - 0.5 * (u0 + u2)};
  {
    const Eigen::Matrix3d& R2 = C(m, 2).linear();
    const Eigen::Matrix3d& R3 = C(m, 3).linear();
    m.ur_zrot = std::abs(R2(2, 2) - 1.0) < 1e-15 && std::abs(R3(2, 2) - 1.0) < 1e-15;
    const double g = std::atan2(R2(1, 0), R2(0, 0)) + std::atan2(R3(1, 0), R3(0, 0));
    m.ur_gc = std::cos(g);
    m.ur_gs = std::sin(g);
  }
  m.ur_tilt = std::abs(m.ur_u5[0]) < 1e-12 && std::abs(std::hypot(m.ur_u5[1], m.ur_u5[2]) - 1.0) < 1e-12;
  if (std::hypot(m.ur_u5[1], m.ur_u5[2]) < 1e-9) {
    m.par23 = false;
    return false;
  }
  // Shoulder direction (for ik_branch_of's callers and docs): normal to axes 1 and 2.
  const Eigen::Vector3d sd = Eigen::Vector3d::UnitZ().cross(m.n_par);
  m.shoulder_dir = sd.normalized();
  return true;
}

// True when one of E1, E2 involves only q2 or only q3 (solve_position's cases A, B).
bool position_decoupled(const IkSolverData& m) {
  auto dep2 = [](const Eigen::Matrix3d& M) { return M.bottomRows<2>().cwiseAbs().maxCoeff() > 0; };
  auto dep3 = [](const Eigen::Matrix3d& M) { return M.rightCols<2>().cwiseAbs().maxCoeff() > 0; };
  const bool d12 = dep2(m.M1), d13 = dep3(m.M1), d22 = dep2(m.M2), d23 = dep3(m.M2);
  return (!d12 && d13) || (!d22 && d23) || (!d13 && d12) || (!d23 && d22);
}

bool detect_spherical_wrist(IkModel& model) {
  IkSolverData& m = solver_data(model);
  if (m.n != 6 || prism(m, 0) || prism(m, 3) || prism(m, 4) || prism(m, 5)) return false;
  // Axes 4, 5, 6 in the frame after C3 (joint 4's frame), joints at 0.
  const Pose T5 = C(m, 4);
  const Pose T6 = C(m, 4) * C(m, 5);
  const Eigen::Vector3d z4 = Eigen::Vector3d::UnitZ(), p4 = Eigen::Vector3d::Zero();
  const Eigen::Vector3d z5 = T5.linear().col(2), p5 = T5.translation();
  const Eigen::Vector3d z6 = T6.linear().col(2), p6 = T6.translation();
  if (z4.cross(z5).norm() < 1e-6 || z5.cross(z6).norm() < 1e-6) return false;
  double s = 0, t = 0;
  if (line_closest(p4, z4, p5, z5, s, t) > 1e-9 * m.scale) return false;
  const Eigen::Vector3d W = p4 + s * z4;
  const Eigen::Vector3d d6 = W - p6;
  if ((d6 - d6.dot(z6) * z6).norm() > 1e-9 * m.scale) return false;
  m.w3 = C(m, 3) * W;
  const Pose T36 = C(m, 3) * C(m, 4) * C(m, 5) * C(m, 6);
  model.w_tool = T36.inverse() * m.w3;
  m.A = C(m, 4).linear();
  m.B = C(m, 5).linear();
  const Eigen::Vector3d g = m.A.transpose().col(2), v = m.B.col(2);
  m.wrist_P = g.x() * v.x() + g.y() * v.y();
  m.wrist_Q = g.y() * v.x() - g.x() * v.y();
  m.wrist_gz_vz = g.z() * v.z();
  if (std::hypot(m.wrist_P, m.wrist_Q) < 1e-9) return false;
  setup_position(m);
  for (int i = 0; i <= 6; ++i) m.perm[static_cast<std::size_t>(i)] = signed_perm(C(m, i).linear());
  m.wrist_phi = std::atan2(m.wrist_Q, m.wrist_P);
  m.wrist_flip = true;
  const double samples[3][3] = {{0.3, 0.7, -1.1}, {-2.0, 2.5, 0.4}, {1.3, -0.2, 2.9}};
  for (const auto& a : samples) {
    const Eigen::Matrix3d W1 = rot_z(a[0]) * m.A * rot_z(a[1]) * m.B * rot_z(a[2]);
    const Eigen::Matrix3d W2 = rot_z(a[0] + kPi) * m.A * rot_z(2 * m.wrist_phi - a[1]) * m.B * rot_z(a[2] + kPi);
    if ((W1 - W2).cwiseAbs().maxCoeff() > 1e-12) m.wrist_flip = false;
  }
  return true;
}

// is_rotation() for a finite R (ik_solve_all checked that): R^T R - I by
// its six distinct entries, det R by the triple product (half the
// instructions of the general check; the reduced arms' time budget).
// The six dot products two at a time, in lane pairs of columns (a.a, b.b),
// (c.c, a.b), (a.c, b.c), each summed as Eigen's dot, (x0 y0 + x1 y1) + x2 y2,
// and a branch-free max: about as many instructions as six scalar dots and
// std::max over them, but without its branches on the data (2-5 ns per solve
// of the reduced arms, RESULTS.md 2026-12-04 sixth session).
bool rotation_within(const Eigen::Matrix3d& R, double tol) {
  const double* m = R.data();  // column-major: column j at m + 3 j
  const v2d A{m[0], m[1]}, B{m[3], m[4]}, C{m[6], m[7]};
  const double a2 = m[2], b2 = m[5], c2 = m[8];
  auto hsum = [](v2d x, v2d y) { return v2d{x[0], y[0]} + v2d{x[1], y[1]}; };  // (sum x, sum y)
  const v2d d1 = hsum(A * A, B * B) + v2d{a2, b2} * v2d{a2, b2};
  const v2d d2 = hsum(C * C, A * B) + v2d{c2, a2} * v2d{c2, b2};
  const v2d d3 = hsum(A * C, B * C) + v2d{a2, b2} * bc<v2d>(c2);
  const v2m sign = (v2m)bc<v2d>(-0.0);
  auto vabs = [&](v2d x) { return (v2d)((v2m)x & ~sign); };
  const v2d e = lmax(lmax(vabs(d1 - bc<v2d>(1.0)), vabs(d2 - v2d{1.0, 0.0})), vabs(d3));
  if (!both(e <= bc<v2d>(tol))) return false;
  const Eigen::Vector3d a(m[0], m[1], a2), b(m[3], m[4], b2), c(m[6], m[7], c2);
  return std::abs(a.dot(b.cross(c)) - 1.0) <= tol;
}

void finish_status(IkResult& res) {
  res.singular_kinds = 0;
  bool any_in = false;
  for (int i = 0; i < res.count; ++i) {
    const IkSolution& s = res.solutions[static_cast<std::size_t>(i)];
    res.singular_kinds |= s.singular;
    any_in = any_in || s.within_limits;
  }
  if (res.count == 0) res.status = Status::unreachable;
  else if (!any_in) res.status = Status::out_of_limits;
  else if (res.singular_kinds) res.status = Status::singular;
  else res.status = Status::ok;
}

// Reduced arms (Carrara, Apostila de Robótica, chapter 4, reduced.cpp): which one the chain is.
bool parallel(const Eigen::Vector3d& a, const Eigen::Vector3d& b) { return a.cross(b).norm() < 1e-9; }

// Joint axes (directions, in the frame after C0) at q = 0.
void axes_at_zero(const IkSolverData& m, Eigen::Vector3d* z) {
  Pose T = Pose::Identity();
  for (int j = 0; j < m.n; ++j) {
    if (j > 0) T = T * C(m, j);
    z[j] = T.linear().col(2);
  }
}

// Coefficients (a, b, c) of g(m) = a + b x + c y in the basis of a joint's
// motion, from three samples of g (as reduced.cpp's fit_basis did per call).
template <typename G>
Eigen::Vector3d fit_reduced(bool prismatic, G g) {
  const double s[3] = {0.0, prismatic ? 1.0 : kPi / 2, prismatic ? -1.0 : kPi};
  Eigen::Matrix3d B;
  Eigen::Vector3d v;
  for (int i = 0; i < 3; ++i) {
    B.row(i) = basis(prismatic, s[i]).transpose();
    v[i] = g(s[i]);
  }
  return B.inverse() * v;
}

// The reduced arms' 2-D forms (IkSolverData::Planar, reduced.cpp). The
// parallel axes are z of the frame F = C(first): the joints turn about z
// there, the middle one turns about z too or slides in the plane. first = 0
// (planar_2r, planar_3) or 1 (pitch_4: joint 2's frame). Switched on only
// where the 2-D form reproduces the decomposition (F's part of it: J C ... J Cn)
// to 1e-12 on sample joint values (a flipped z between the axes, or a
// constant rotation that is not about z, leaves it off).
void setup_planar(IkSolverData& m, int first, bool heading) {
  IkSolverData::Planar pl;
  const int b = first + 1;            // the middle joint
  const int last = heading ? first + 2 : first + 1;
  const Pose& Cb = C(m, b);           // after joint `first`'s motion to joint b's frame
  const Eigen::Vector3d wb = C(m, b + 1).translation();  // the point after b's motion
  pl.pri = prism(m, b);
  if (pl.pri) {
    pl.sa = Cb.translation() + Cb.linear() * wb;
    pl.w = Cb.linear().col(2);
  } else {
    pl.sa = Cb.translation();
    pl.w = Cb.linear() * wb;
    const double hb = m.red_co[1], hcoef = m.red_co[2];
    pl.h = std::sqrt(hb * hb + hcoef * hcoef);
    if (!(pl.h > 1e-12 * m.scale * m.scale)) return;  // the equation free of b (solve_basis's tolerance)
    pl.hc = hb / pl.h;
    pl.hs = hcoef / pl.h;
    pl.phase = std::atan2(pl.hs, pl.hc);
  }
  if (heading) {
    const Eigen::Matrix3d G = Cb.linear() * C(m, b + 1).linear();
    const double g = std::atan2(G(1, 0), G(0, 0));
    pl.gc = std::cos(g);
    pl.gs = std::sin(g);
    pl.gamma = g;
    pl.tn = C(m, last + 1).translation();
  }
  if (first == 1) {
    pl.z1 = C(m, 1).linear().transpose().col(2);
    pl.o1 = -(C(m, 1).linear().transpose() * C(m, 1).translation());
  }
  // the check: F's part of the decomposition against the 2-D form
  const double samples[4][3] = {{0.3, 0.7, -1.1}, {-2.0, 2.5, 0.4}, {1.3, -0.2, 2.9}, {-0.6, -2.8, -1.7}};
  const double tol = 1e-12 * m.scale;
  for (const auto& v : samples) {
    const double mb = pl.pri ? v[1] * m.scale : v[1];
    Pose T = joint_motion(false, v[0]) * Cb * joint_motion(pl.pri, mb);
    Eigen::Vector3d f2;
    if (heading) {
      T = T * C(m, b + 1) * joint_motion(false, v[2]) * C(m, last + 1);
    } else {
      T = T * C(m, b + 1);
    }
    const Eigen::Vector3d f = pl.pri ? Eigen::Vector3d(pl.sa + mb * pl.w) : Eigen::Vector3d(pl.sa + rot_z(mb) * pl.w);
    f2 = rot_z(v[0]) * f;
    if (heading) {
      const double hd = v[0] + (pl.pri ? 0.0 : mb) + v[2] + std::atan2(pl.gs, pl.gc);
      f2 += rot_z(hd) * pl.tn;
      const Eigen::Matrix3d R2 = rot_z(hd) * C(m, last + 1).linear();
      if ((R2 - T.linear()).cwiseAbs().maxCoeff() > 1e-12) return;
    }
    if ((f2 - T.translation()).norm() > tol || !all_finite(f2)) return;
  }
  if (pl.pri && std::abs(pl.w.z()) > 1e-12) return;
  pl.on = true;
  m.pl = pl;
}

// IkSolverData::Spatial3: solve_position's case A (the same test on the
// same matrices, so the lanes take the case solve_position takes), joints
// 1-3 revolute.
void setup_spatial3(IkSolverData& m) {
  IkSolverData::Spatial3 s;
  if (prism(m, 0) || prism(m, 1) || prism(m, 2)) return;
  auto dep2 = [](const Eigen::Matrix3d& M) { return M.bottomRows<2>().cwiseAbs().maxCoeff() > 0; };
  auto dep3 = [](const Eigen::Matrix3d& M) { return M.rightCols<2>().cwiseAbs().maxCoeff() > 0; };
  const double tol1 = 1e-12 * m.scale * m.scale, tol2 = 1e-12 * m.scale;
  const Eigen::Matrix3d* Mq3 = nullptr;
  double tq3 = 0;
  if (!dep2(m.M1) && dep3(m.M1)) {
    Mq3 = &m.M1;
    s.Mo = m.M2;
    s.q3_from_e1 = true;
    tq3 = tol1;
    s.tol2 = tol2;
  } else if (!dep2(m.M2) && dep3(m.M2)) {
    Mq3 = &m.M2;
    s.Mo = m.M1;
    s.q3_from_e1 = false;
    tq3 = tol2;
    s.tol2 = tol1;
  } else {
    return;
  }
  s.a3 = (*Mq3)(0, 0);
  s.h3 = std::sqrt((*Mq3)(0, 1) * (*Mq3)(0, 1) + (*Mq3)(0, 2) * (*Mq3)(0, 2));
  if (!(s.h3 > tq3)) return;  // free of m3 too: solve_position's answer (free or none)
  const double hc3 = (*Mq3)(0, 1) / s.h3, hs3 = (*Mq3)(0, 2) / s.h3;  // (cos, sin) of phase3
  s.hc3i = hc3 / s.h3;
  s.hs3i = hs3 / s.h3;
  s.on = std::isfinite(s.a3 + hc3 + hs3) && detail::all_finite(s.Mo);
  m.s3 = s;
}

bool detect_reduced(IkModel& model) {
  IkSolverData& m = solver_data(model);
  if (m.n < 2 || m.n > 4 || prism(m, 0)) return false;
  // reduced.cpp multiplies by these as copies of signed columns where they are one
  for (int i = 0; i <= m.n; ++i) m.perm[static_cast<std::size_t>(i)] = signed_perm(C(m, i).linear());
  Eigen::Vector3d z[kMaxJoints];
  axes_at_zero(m, z);
  const Eigen::Vector3d ez = Eigen::Vector3d::UnitZ();
  bool planar = true;
  for (int j = 1; j < m.n; ++j) {
    if (prism(m, j)) planar = planar && std::abs(z[j].dot(ez)) < 1e-9;
    else planar = planar && parallel(z[j], ez);
  }
  if (planar && m.n == 2 && !prism(m, 1)) {
    model.method = IkMethod::planar_2r;
    m.w3 = C(m, 2).translation();  // tool point after the J2 motion
    auto g = [&](double a) {
      const Eigen::Vector3d f = C(m, 1) * (rot_z(a) * m.w3);
      return f.x() * f.x() + f.y() * f.y();
    };
    const double g0 = g(0), g1 = g(kPi / 2), g2 = g(kPi);
    m.red_co = {0.5 * (g0 + g2), 0.5 * (g0 - g2), g1 - 0.5 * (g0 + g2)};
    m.red_fast = true;
    setup_planar(m, 0, false);
    return true;
  }
  if (planar && m.n == 3 && !prism(m, 2)) {
    model.method = IkMethod::planar_3;
    m.w3 = C(m, 2).translation();  // a point of axis 3, frame after J2 motion
    m.red_co = fit_reduced(prism(m, 1), [&](double m2) {
      const Eigen::Vector3d f = C(m, 1) * (joint_motion(prism(m, 1), m2) * m.w3);
      return f.x() * f.x() + f.y() * f.y();
    });
    m.red_fast = detail::all_finite(m.red_co);
    if (m.red_fast) setup_planar(m, 0, true);
    return true;
  }
  if (m.n == 3) {
    model.method = IkMethod::spatial_3;
    m.w3 = C(m, 3).translation();  // tool point after the J3 motion
    setup_position(m);
    m.red_fast = true;  // reduced.cpp's cheap path (solve_position's pairs)
    setup_spatial3(m);
    // Position only: needs one equation free of q2 or of q3, or the resultant.
    return true;
  }
  if (m.n == 4 && !prism(m, 1) && !prism(m, 3) && parallel(z[1], z[3]) && std::abs(z[1].dot(ez)) < 1e-9 &&
      (prism(m, 2) || parallel(z[2], z[1]))) {
    model.method = IkMethod::pitch_4;
    m.w3 = C(m, 3).translation();  // a point of axis 4, frame after J3 motion
    m.red_co = fit_reduced(prism(m, 2), [&](double m3) {
      return (C(m, 2) * (joint_motion(prism(m, 2), m3) * m.w3)).squaredNorm();
    });
    m.red_Rrest = C(m, 2).linear() * C(m, 3).linear() * C(m, 4).linear();
    m.red_n2 = m.red_Rrest.transpose().col(2);
    m.red_vtool = C(m, m.n).linear().transpose() * C(m, m.n).translation();
    m.red_rhs_direct = C(m, 1).translation().head<2>().norm() <= 1e-12 * m.scale;
    const Eigen::Vector3d n21 = C(m, 1).linear().col(2);
    const double h = std::hypot(n21.x(), n21.y());
    if (h > 1e-9) {
      m.red_u = n21.x() / h;
      m.red_v = n21.y() / h;
      m.red_fast = detail::all_finite(m.red_co);
      if (m.red_fast) setup_planar(m, 1, true);
    }
    return true;
  }
  return false;
}

}  // namespace
}  // namespace detail

Status ik_prepare(const Chain& chain, IkModel& model) {
  model = IkModel{};
  if (chain.n_joints > kMaxJoints || chain.n_rows > kMaxRows) return Status::capacity;
  model.chain = chain;
  detail::IkSolverData& d = detail::solver_data(model);
  for (int j = 0; j < chain.n_joints; ++j) d.wrap[static_cast<std::size_t>(j)] = detail::make_joint_wrap(chain.joint(j));
  detail::decompose(chain, d);
  model.method = IkMethod::none;
  if (detail::detect_spherical_wrist(model)) {
    // Which position subproblem (position.cpp): one of E1, E2 involves only
    // q2 or only q3 (PUMA, Stanford); else axes 2 and 3 parallel (OPW class:
    // joint 1 first); else the degree-8 resultant.
    model.method = detail::position_decoupled(d)      ? IkMethod::spherical_wrist
                   : detail::setup_parallel(d, d.w3, detail::f_of(d, 0, 0, d.w3)) ? IkMethod::opw
                                                                        : IkMethod::spherical_general;
    return Status::ok;
  }
  if (detail::detect_ur(model)) {
    model.method = IkMethod::ur;
    return Status::ok;
  }
  if (detail::detect_reduced(model)) {
    if (model.method == IkMethod::spatial_3 && !detail::position_decoupled(d))
      detail::setup_parallel(d, d.w3, detail::f_of(d, 0, 0, d.w3));
    return Status::ok;
  }
  return Status::ok;
}

void ik_solve_all(const IkModel& model, const Pose& target, const JointVector* q_ref, IkResult& result) {
  result.count = 0;
  result.singular_kinds = 0;
  if (model.method == IkMethod::none) {
    result.status = Status::unsupported;
    return;
  }
  bool ref_finite = true;
  if (q_ref)
    for (int j = 0; j < q_ref->size(); ++j) ref_finite = ref_finite && std::isfinite((*q_ref)[j]);
  if (q_ref && (q_ref->size() != model.chain.n_joints || !ref_finite)) {
    result.status = q_ref->size() != model.chain.n_joints ? Status::wrong_size : Status::bad_input;
    return;
  }
  // finite: every exponent field below 0x7ff (adding 1 to it carries into bit 63 only
  // for Inf/NaN); integer operations, no floating-point exception, vectorised
  std::uint64_t carry = 0;
  for (int i = 0; i < 16; ++i) {
    std::uint64_t u;
    std::memcpy(&u, target.matrix().data() + i, sizeof u);
    carry |= (u & 0x7ff0000000000000ull) + 0x0010000000000000ull;
  }
  const bool finite = (carry >> 63) == 0;
  if (!finite || !detail::rotation_within(target.linear(), 1e-6)) {
    result.status = Status::bad_input;
    return;
  }
  switch (model.method) {
    case IkMethod::spherical_wrist:
    case IkMethod::opw:
    case IkMethod::spherical_general: detail::solve_spherical(model, target, q_ref, result); break;
    case IkMethod::ur: detail::solve_ur(model, target, q_ref, result); break;
    case IkMethod::planar_2r:
    case IkMethod::planar_3:
    case IkMethod::spatial_3:
    case IkMethod::pitch_4: detail::solve_reduced(model, target, q_ref, result); break;
    case IkMethod::none: break;
  }
  detail::finish_status(result);
}

}  // namespace servoarm::kin
