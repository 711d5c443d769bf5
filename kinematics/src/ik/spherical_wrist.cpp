// Closed-form inverse kinematics (see ik.hpp for the method).
//
// Real-time parts (ik_solve_all and what it calls) are heap-free: fixed-size
// Eigen types only, the root finder works on an 8x8 companion matrix with
// compile-time maximum size.
#include "servoarm/kinematics/ik.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include "fast_trig.hpp"
#include "lanes.hpp"
#include "ik_detail.hpp"
#include "servoarm/kinematics/orientation.hpp"

namespace servoarm::kin {

const char* to_string(IkMethod m) {
  switch (m) {
    case IkMethod::none: return "numeric";
    case IkMethod::spherical_wrist: return "spherical_wrist";
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

bool pose_error(const Chain& chain, const JointVector& q, const Pose& target, double& ep, double& er) {
  Pose T;
  if (forward(chain, q, T) != Status::ok) return false;
  ep = (T.translation() - target.translation()).norm();
  er = rotation_error(T.linear(), target.linear()).norm();
  return std::isfinite(ep) && std::isfinite(er);
}

void refine(const Chain& chain, const Pose& target, JointVector& q, int iterations, bool position_only) {
  const int n = chain.n_joints;
  using MatN = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor, kMaxJoints, kMaxJoints>;
  for (int it = 0; it < iterations; ++it) {
    Jacobian J;
    Pose T;
    if (jacobian(chain, q, J, &T) != Status::ok) return;
    Eigen::Matrix<double, 6, 1> e;
    e.head<3>() = target.translation() - T.translation();
    e.tail<3>() = position_only ? Eigen::Vector3d::Zero() : rotation_error(T.linear(), target.linear());
    if (position_only) J.bottomRows<3>().setZero();
    if (e.norm() < 1e-15) return;
    MatN A = J.transpose() * J;
    A.diagonal().array() += 1e-12;
    const JointVector g = J.transpose() * e;
    const JointVector dq = A.ldlt().solve(g);
    if (!detail::all_finite(dq)) return;
    JointVector q2 = q + dq;
    double ep0, er0, ep1, er1;
    if (!pose_error(chain, q, target, ep0, er0) || !pose_error(chain, q2, target, ep1, er1)) return;
    if (ep1 + (position_only ? 0 : er1) >= ep0 + (position_only ? 0 : er0)) return;
    q = q2;
    (void)n;
  }
}

}  // namespace detail

namespace {

using detail::joint_motion;
using detail::rot_z;

constexpr double kPi = M_PI;
constexpr double kVerifyPos = 1e-9;
constexpr double kVerifyRot = 1e-9;
constexpr double kNearSingular = 1e-6;
/// |axis 6 x axis 4|^2 below which q4 is kept at the reference (theta5 = 0).
constexpr double kKeepQ4 = 1e-20;

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
void decompose(const Chain& c, IkModel& m) {
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

const Pose& C(const IkModel& m, int i) { return m.C[static_cast<std::size_t>(i)]; }
bool prism(const IkModel& m, int j) { return m.prismatic[static_cast<std::size_t>(j)]; }

// Basis of a joint's motion: (1, cos m, sin m) or (1, m, m^2), and its derivative.
Eigen::Vector3d basis(bool prismatic, double m) {
  if (prismatic) return {1.0, m, m * m};
  return {1.0, std::cos(m), std::sin(m)};
}
Eigen::Vector3d dbasis(bool prismatic, double m) {
  if (prismatic) return {0.0, 1.0, 2.0 * m};
  return {0.0, -std::sin(m), std::cos(m)};
}

// Point w (frame after J3 motion) in the frame after J1 motion.
Eigen::Vector3d f_of(const IkModel& m, double m2, double m3, const Eigen::Vector3d& w) {
  return C(m, 1) * (joint_motion(prism(m, 1), m2) * (C(m, 2) * (joint_motion(prism(m, 2), m3) * w)));
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
void setup_position(IkModel& m) {
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

bool detect_spherical_wrist(IkModel& m) {
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
  m.w_tool = T36.inverse() * m.w3;
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

// a + b*x + c*y = 0 in the basis of a revolute (cos, sin) or prismatic (m, m^2) joint.
// Revolute: h cos(m - phi) = -a with (b, c) = h (cos phi, sin phi), so the
// roots are phi +- t, cos t = k = -a/h; their cosines and sines follow
// without trigonometry (sin t = sqrt((1 - k)(1 + k))), and the angles (one
// atan2 each) only when `angles` is set.
Roots solve_basis(double a, double b, double c, bool prismatic, double tol, bool angles = true) {
  Roots r;
  if (!prismatic) {
    const double h = std::sqrt(b * b + c * c);
    if (h <= tol) {
      r.free = std::abs(a) <= tol;
      return r;
    }
    double k = -a / h;
    if (k > 1.0) {
      if (k > 1.0 + 1e-9) return r;
      k = 1.0;
    } else if (k < -1.0) {
      if (k < -1.0 - 1e-9) return r;
      k = -1.0;
    }
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

// Polynomial up to degree 8, coefficient k of x^k.
struct Poly {
  double c[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
  int deg = 0;
};
Poly pmul(const Poly& a, const Poly& b) {
  Poly r;
  r.deg = std::min(8, a.deg + b.deg);
  for (int i = 0; i <= a.deg; ++i)
    for (int j = 0; j <= b.deg && i + j <= 8; ++j) r.c[i + j] += a.c[i] * b.c[j];
  return r;
}
Poly psub(const Poly& a, const Poly& b) {
  Poly r;
  r.deg = std::max(a.deg, b.deg);
  for (int i = 0; i <= r.deg; ++i) r.c[i] = a.c[i] - b.c[i];
  return r;
}
Poly padd(const Poly& a, const Poly& b) {
  Poly r;
  r.deg = std::max(a.deg, b.deg);
  for (int i = 0; i <= r.deg; ++i) r.c[i] = a.c[i] + b.c[i];
  return r;
}

// Real roots of p (degree <= 8) via the companion matrix.
int real_roots(const Poly& p, double* out) {
  double mx = 0;
  for (int i = 0; i <= p.deg; ++i) mx = std::max(mx, std::abs(p.c[i]));
  if (!(mx > 0)) return 0;
  int deg = p.deg;
  while (deg > 0 && std::abs(p.c[deg]) <= 1e-13 * mx) --deg;
  if (deg == 0) return 0;
  using Mat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor, 8, 8>;
  Mat comp = Mat::Zero(deg, deg);
  for (int i = 1; i < deg; ++i) comp(i, i - 1) = 1.0;
  for (int i = 0; i < deg; ++i) comp(i, deg - 1) = -p.c[i] / p.c[deg];
  Eigen::EigenSolver<Mat> es(comp, false);
  if (es.info() != Eigen::Success) return 0;
  int n = 0;
  for (int i = 0; i < deg; ++i) {
    const std::complex<double> z = es.eigenvalues()[i];
    if (std::abs(z.imag()) <= 1e-4 * (1.0 + std::abs(z.real()))) out[n++] = z.real();
  }
  return n;
}

// One coefficient row (v0, v1, v2) of the q3 basis as a quadratic in x:
// revolute, m3 = sigma + 2 atan(x), times (1 + x^2); prismatic: v0 + v1 x + v2 x^2.
Poly row_poly(const Eigen::Vector3d& v, bool prismatic, double sigma) {
  Poly p;
  p.deg = 2;
  if (prismatic) {
    p.c[0] = v[0]; p.c[1] = v[1]; p.c[2] = v[2];
    return p;
  }
  const double cs = std::cos(sigma), sn = std::sin(sigma);
  const double v1 = v[1] * cs + v[2] * sn, v2 = -v[1] * sn + v[2] * cs;
  p.c[0] = v[0] + v1;
  p.c[1] = 2 * v2;
  p.c[2] = v[0] - v1;
  return p;
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

void newton_polish(const IkModel& m, const Eigen::Matrix3d& M1, const Eigen::Matrix3d& M2, double& m2,
                   double& m3) {
  const bool p2 = prism(m, 1), p3 = prism(m, 2);
  for (int it = 0; it < 8; ++it) {
    const Eigen::Vector3d b2 = basis(p2, m2), b3 = basis(p3, m3);
    const Eigen::Vector3d d2 = dbasis(p2, m2), d3 = dbasis(p3, m3);
    const double e1 = b2.dot(M1 * b3), e2 = b2.dot(M2 * b3);
    if (std::abs(e1) < 1e-15 * m.scale * m.scale && std::abs(e2) < 1e-15 * m.scale) return;
    Eigen::Matrix2d J;
    J << d2.dot(M1 * b3), b2.dot(M1 * d3), d2.dot(M2 * b3), b2.dot(M2 * d3);
    const double det = J.determinant();
    if (!(std::abs(det) > 1e-300)) return;
    const Eigen::Vector2d dx = J.inverse() * Eigen::Vector2d(e1, e2);
    if (!detail::all_finite(dx) || dx.norm() > 0.5) return;
    m2 -= dx[0];
    m3 -= dx[1];
  }
}

// (m2, m3) candidates with their (cos, sin) pairs; the angles m2, m3 only
// if `angles` (the spherical-wrist solver computes every angle in one batch
// at the end).
int solve_position(const IkModel& m, const Eigen::Vector3d& p0, const double* ref_m2, PosCand* out,
                   bool angles = true) {
  const bool p2 = prism(m, 1), p3 = prism(m, 2);
  Eigen::Matrix3d M1 = m.M1, M2 = m.M2;
  const Eigen::Vector3d ez = Eigen::Vector3d::UnitZ();
  M1(0, 0) -= (p0 - m.lambda * ez).squaredNorm();
  M2(0, 0) -= p0.z();
  const double tol1 = 1e-12 * m.scale * m.scale, tol2 = 1e-12 * m.scale;
  auto dep2 = [](const Eigen::Matrix3d& M) { return M.bottomRows<2>().cwiseAbs().maxCoeff() > 0; };
  auto dep3 = [](const Eigen::Matrix3d& M) { return M.rightCols<2>().cwiseAbs().maxCoeff() > 0; };
  const bool d12 = dep2(m.M1), d13 = dep3(m.M1), d22 = dep2(m.M2), d23 = dep3(m.M2);
  int n = 0;
  // Case A: one equation involves only q3.
  const Eigen::Matrix3d* Mq3 = nullptr;
  const Eigen::Matrix3d* Mo = nullptr;
  double tq3 = 0, to = 0;
  if (!d12 && d13) { Mq3 = &M1; Mo = &M2; tq3 = tol1; to = tol2; }
  else if (!d22 && d23) { Mq3 = &M2; Mo = &M1; tq3 = tol2; to = tol1; }
  if (Mq3) {
    const Roots r3 = solve_basis((*Mq3)(0, 0), (*Mq3)(0, 1), (*Mq3)(0, 2), p3, tq3, angles);
    for (int i = 0; i < r3.n; ++i) {
      const Eigen::Vector3d u = (*Mo) * basis_cs(p3, r3.c[i], r3.s[i]);
      const Roots r2 = solve_basis(u[0], u[1], u[2], p2, to, angles);
      if (r2.free) {
        PosCand& o = out[n++];
        o = {ref_m2 ? *ref_m2 : 0.0, r3.v[i], r3.label[i], true};
        set_pair(p2, o.m2, o.c2, o.s2);
        o.c3 = r3.c[i];
        o.s3 = r3.s[i];
        o.g3 = static_cast<std::int8_t>(i);
        continue;
      }
      for (int k = 0; k < r2.n; ++k) {
        PosCand& o = out[n++];
        o = {r2.v[k], r3.v[i], r3.label[i], false};
        o.c2 = r2.c[k];
        o.s2 = r2.s[k];
        o.c3 = r3.c[i];
        o.s3 = r3.s[i];
        o.g3 = static_cast<std::int8_t>(i);
      }
    }
    return n;
  }
  // Case B: one equation involves only q2.
  const Eigen::Matrix3d* Mq2 = nullptr;
  if (!d13 && d12) { Mq2 = &M1; Mo = &M2; tq3 = tol1; to = tol2; }
  else if (!d23 && d22) { Mq2 = &M2; Mo = &M1; tq3 = tol2; to = tol1; }
  if (Mq2) {
    const Roots r2 = solve_basis((*Mq2)(0, 0), (*Mq2)(1, 0), (*Mq2)(2, 0), p2, tq3, angles);
    for (int i = 0; i < r2.n; ++i) {
      const Eigen::Vector3d u = Mo->transpose() * basis_cs(p2, r2.c[i], r2.s[i]);
      const Roots r3 = solve_basis(u[0], u[1], u[2], p3, to, angles);
      for (int k = 0; k < r3.n; ++k) {
        PosCand& o = out[n++];
        o = {r2.v[i], r3.v[k], r3.label[k], false};
        o.c2 = r2.c[i];
        o.s2 = r2.s[i];
        o.c3 = r3.c[k];
        o.s3 = r3.s[k];
        o.g2 = static_cast<std::int8_t>(i);
      }
    }
    return n;
  }
  // Case C: eliminate q2 (resultant), polynomial of degree <= 8 in x.
  double sigma = 0;
  if (!p3) {
    double best = -1;
    for (int k = 0; k < 8; ++k) {
      const double s = 0.3 + k * kPi / 4;
      const Eigen::Vector3d b3 = basis(false, s + kPi);
      const Eigen::Vector3d a1 = M1 * b3, a2 = M2 * b3;
      double F;
      if (!p2) {
        const double D = a1[1] * a2[2] - a2[1] * a1[2];
        const double Nc = a2[0] * a1[2] - a1[0] * a2[2], Ns = a1[0] * a2[1] - a2[0] * a1[1];
        F = Nc * Nc + Ns * Ns - D * D;
      } else {
        const double x = a1[2] * a2[0] - a1[0] * a2[2];
        F = x * x - (a1[2] * a2[1] - a1[1] * a2[2]) * (a1[1] * a2[0] - a1[0] * a2[1]);
      }
      if (std::abs(F) > best) {
        best = std::abs(F);
        sigma = s;
      }
    }
  }
  const Poly al1 = row_poly(M1.row(0).transpose(), p3, sigma), be1 = row_poly(M1.row(1).transpose(), p3, sigma),
             ga1 = row_poly(M1.row(2).transpose(), p3, sigma);
  const Poly al2 = row_poly(M2.row(0).transpose(), p3, sigma), be2 = row_poly(M2.row(1).transpose(), p3, sigma),
             ga2 = row_poly(M2.row(2).transpose(), p3, sigma);
  Poly F;
  if (!p2) {
    const Poly D = psub(pmul(be1, ga2), pmul(be2, ga1));
    const Poly Nc = psub(pmul(al2, ga1), pmul(al1, ga2));
    const Poly Ns = psub(pmul(al1, be2), pmul(al2, be1));
    F = psub(padd(pmul(Nc, Nc), pmul(Ns, Ns)), pmul(D, D));
  } else {
    const Poly X = psub(pmul(ga1, al2), pmul(al1, ga2));
    F = psub(pmul(X, X), pmul(psub(pmul(ga1, be2), pmul(be1, ga2)), psub(pmul(be1, al2), pmul(al1, be2))));
  }
  double xs[8];
  const int nr = real_roots(F, xs);
  for (int i = 0; i < nr && n < 8; ++i) {
    const double m3 = p3 ? xs[i] : sigma + 2.0 * std::atan(xs[i]);
    const Eigen::Vector3d b3 = basis(p3, m3);
    const Eigen::Vector3d a1 = M1 * b3, a2 = M2 * b3;
    double c2[2];
    int nc = 0;
    if (!p2) {
      const double D = a1[1] * a2[2] - a2[1] * a1[2];
      const double Nc = a2[0] * a1[2] - a1[0] * a2[2], Ns = a1[0] * a2[1] - a2[0] * a1[1];
      if (std::abs(D) > 1e-9 * (std::abs(Nc) + std::abs(Ns))) {
        c2[nc++] = D > 0 ? std::atan2(Ns, Nc) : std::atan2(-Ns, -Nc);  // (cos, sin) = (Nc, Ns) / D
      } else {
        const Roots r = solve_basis(a1[0], a1[1], a1[2], false, tol1);
        for (int k = 0; k < r.n; ++k) c2[nc++] = r.v[k];
      }
    } else {
      const double den = a2[2] * a1[1] - a1[2] * a2[1];
      if (std::abs(den) > 1e-300) {
        c2[nc++] = -(a2[2] * a1[0] - a1[2] * a2[0]) / den;
      } else {
        const Roots r = solve_basis(a1[0], a1[1], a1[2], true, tol1);
        for (int k = 0; k < r.n; ++k) c2[nc++] = r.v[k];
      }
    }
    for (int k = 0; k < nc && n < 8; ++k) {
      double m2 = c2[k], mm3 = m3;
      newton_polish(m, M1, M2, m2, mm3);
      const double e1 = basis(p2, m2).dot(M1 * basis(p3, mm3)), e2 = basis(p2, m2).dot(M2 * basis(p3, mm3));
      if (!(std::abs(e1) < 1e-8 * m.scale * m.scale && std::abs(e2) < 1e-8 * m.scale)) continue;
      PosCand& o = out[n++];
      o = {m2, mm3, 0, false};
      set_pair(p2, m2, o.c2, o.s2);
      set_pair(p3, mm3, o.c3, o.s3);
    }
  }
  return n;
}

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

// Wrap a revolute joint into its limits where a 2*pi equivalent fits (nearest
// to ref); prismatic joints are left alone (rule: detail::wrap_into_limits).
inline double wrap_joint(const DhRow& r, double q, double ref) {
  if (r.type != JointType::revolute) return q;
  return detail::wrap_into_limits(fast_wrap(q), r.lower - 1e-12, r.upper + 1e-12, ref);
}

double joint_distance(const Chain& c, int j, double a, double b) {
  const double d = a - b;
  return c.joint(j).type == JointType::revolute ? std::abs(fast_wrap(d)) : std::abs(d);
}

bool same_solution(const Chain& c, const JointVector& a, const JointVector& b) {
  for (int j = 0; j < c.n_joints; ++j)
    if (joint_distance(c, j, a[j], b[j]) > 1e-7) return false;
  return true;
}

// Add a verified solution (SI joints, wrapped) unless it is a duplicate.
void store_solution(const IkModel& m, const JointVector& q, Branch br, std::uint8_t singular, double ep, double er,
                    IkResult& res) {
  const Chain& c = m.chain;
  for (int i = 0; i < res.count; ++i)
    if (same_solution(c, res.solutions[static_cast<std::size_t>(i)].q, q)) return;
  if (res.count >= kMaxIkSolutions) return;
  IkSolution& s = res.solutions[static_cast<std::size_t>(res.count++)];
  s.q = q;
  s.branch = br;
  s.within_limits = within_limits(c, q, 1e-9);
  s.singular = singular;
  s.position_error = ep;
  s.rotation_error = er;
}

// Finish a candidate (motion values m, SI joints = dir*m): wrap, verify by
// the chain's FK (a few Gauss-Newton steps if it is close but not within
// the tolerance, e.g. a root clamped at the reach limit), add.
void add_candidate(const IkModel& m, const Pose& target, const JointVector* q_ref, const double* mot,
                   Branch br, std::uint8_t singular, bool position_only, IkResult& res) {
  const Chain& c = m.chain;
  JointVector q(c.n_joints);
  for (int j = 0; j < c.n_joints; ++j) {
    const double v = m.dir[static_cast<std::size_t>(j)] * mot[j];
    q[j] = wrap_joint(c.joint(j), v, q_ref ? (*q_ref)[j] : 0.0);
  }
  if (!detail::all_finite(q)) return;
  double ep = 0, er = 0;
  if (!detail::pose_error(c, q, target, ep, er)) return;
  if (position_only) er = 0;
  if (ep > kVerifyPos || er > kVerifyRot) {
    if (ep < 1e-4 * m.scale && er < 1e-4) {
      detail::refine(c, target, q, 4, position_only);
      for (int j = 0; j < c.n_joints; ++j) q[j] = wrap_joint(c.joint(j), q[j], q_ref ? (*q_ref)[j] : 0.0);
      if (!detail::pose_error(c, q, target, ep, er)) return;
      if (position_only) er = 0;
    }
    if (ep > kVerifyPos || er > kVerifyRot) return;
  }
  store_solution(m, q, br, singular, ep, er, res);
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
  const IkModel* m;
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
  const IkModel& m = *x.m;
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
  const IkModel& m = *x.m;
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

void solve_spherical(const IkModel& m, const Pose& target, const JointVector* q_ref, IkResult& res) {
  const Eigen::Vector3d W = target * m.w_tool;
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
  x.u = apply(C(m, 6).linear(), m.perm[6], m.w_tool);
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
      add_candidate(m, target, q_ref, all, cd.br, cd.sing, false, res);
      for (int t = before; t < res.count; ++t) owner[t] = -1;
      foreign = foreign || res.count > before;
    }
  }
}

// ---------------------------------------------------------------------------
// Reduced arms of seed 002 chapter 4
// ---------------------------------------------------------------------------
bool parallel(const Eigen::Vector3d& a, const Eigen::Vector3d& b) { return a.cross(b).norm() < 1e-9; }

// Joint axes (directions, in the frame after C0) at q = 0.
void axes_at_zero(const IkModel& m, Eigen::Vector3d* z) {
  Pose T = Pose::Identity();
  for (int j = 0; j < m.n; ++j) {
    if (j > 0) T = T * C(m, j);
    z[j] = T.linear().col(2);
  }
}

bool detect_reduced(IkModel& m) {
  if (m.n < 2 || m.n > 4 || prism(m, 0)) return false;
  Eigen::Vector3d z[kMaxJoints];
  axes_at_zero(m, z);
  const Eigen::Vector3d ez = Eigen::Vector3d::UnitZ();
  bool planar = true;
  for (int j = 1; j < m.n; ++j) {
    if (prism(m, j)) planar = planar && std::abs(z[j].dot(ez)) < 1e-9;
    else planar = planar && parallel(z[j], ez);
  }
  if (planar && m.n == 2 && !prism(m, 1)) {
    m.method = IkMethod::planar_2r;
    m.w3 = C(m, 2).translation();  // tool point after the J2 motion
    return true;
  }
  if (planar && m.n == 3 && !prism(m, 2)) {
    m.method = IkMethod::planar_3;
    m.w3 = C(m, 2).translation();  // a point of axis 3, frame after J2 motion
    return true;
  }
  if (m.n == 3) {
    m.method = IkMethod::spatial_3;
    m.w3 = C(m, 3).translation();  // tool point after the J3 motion
    setup_position(m);
    // Position only: needs one equation free of q2 or of q3, or the resultant.
    return true;
  }
  if (m.n == 4 && !prism(m, 1) && !prism(m, 3) && parallel(z[1], z[3]) && std::abs(z[1].dot(ez)) < 1e-9 &&
      (prism(m, 2) || parallel(z[2], z[1]))) {
    m.method = IkMethod::pitch_4;
    m.w3 = C(m, 3).translation();  // a point of axis 4, frame after J3 motion
    return true;
  }
  return false;
}

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

void solve_reduced(const IkModel& m, const Pose& target, const JointVector* q_ref, IkResult& res) {
  double mref[kMaxJoints] = {0, 0, 0, 0, 0, 0, 0, 0};
  if (q_ref)
    for (int j = 0; j < m.n; ++j) mref[j] = m.dir[static_cast<std::size_t>(j)] * (*q_ref)[j];
  const Pose C0i = C(m, 0).inverse();
  const double tol = 1e-12 * m.scale * m.scale;
  if (m.method == IkMethod::spatial_3) {
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
      add_candidate(m, target, q_ref, mot, br, sing, true, res);
    }
    return;
  }
  // Planar and pitch arms: build the reachable target (position + the
  // rotation part the arm controls), then the point on the last axis.
  Pose eff = target;
  double m1_fixed = 0;
  bool have_m1 = false;
  const int last = m.n - 1;
  if (m.method == IkMethod::planar_3) {
    // R = R_C0 Rz(sum) R_C(last): heading psi of the tool about the base z.
    const Eigen::Matrix3d X = C(m, 0).linear().transpose() * target.linear() * C(m, m.n).linear().transpose();
    const double psi = std::atan2(X(1, 0), X(0, 0));
    eff.linear() = C(m, 0).linear() * rot_z(psi) * C(m, m.n).linear();
  } else if (m.method == IkMethod::pitch_4) {
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
  const Eigen::Vector3d P = (m.method == IkMethod::planar_2r) ? eff.translation() : after_last.translation();
  const Eigen::Vector3d p0 = C0i * P;
  // Position of the point (m.w3, frame after the motion of joint `k`) with k = 1 (planar) or 2 (pitch).
  double sols[4][kMaxJoints];
  std::int8_t elbows[4];
  int ns = 0;
  if (m.method == IkMethod::pitch_4) {
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
    if (m.method != IkMethod::planar_2r) {
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
      if (jacobian(m.chain, q, J) == Status::ok) {
        // position rows of the joints that place the point: small singular value
        const int k = m.method == IkMethod::pitch_4 ? 3 : 2;
        Eigen::Matrix<double, 3, Eigen::Dynamic, Eigen::ColMajor, 3, kMaxJoints> Jp = J.topRows<3>().leftCols(k);
        const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor, kMaxJoints, kMaxJoints> G =
            Jp.transpose() * Jp;
        const double det = G.determinant();
        double prod = 1;
        for (int j = 0; j < k; ++j) prod *= G(j, j);
        if (prod > 0 && det / prod < kNearSingular * kNearSingular) sing |= kSingularElbow;
      }
    }
    add_candidate(m, eff, q_ref, mot, br, sing, m.method == IkMethod::planar_2r, res);
  }
}

}  // namespace

Status ik_prepare(const Chain& chain, IkModel& model) {
  model = IkModel{};
  if (chain.n_joints > kMaxJoints || chain.n_rows > kMaxRows) return Status::capacity;
  model.chain = chain;
  for (int j = 0; j < chain.n_joints; ++j) model.wrap[static_cast<std::size_t>(j)] = detail::make_joint_wrap(chain.joint(j));
  decompose(chain, model);
  model.method = IkMethod::none;
  if (detect_spherical_wrist(model)) {
    model.method = IkMethod::spherical_wrist;
    return Status::ok;
  }
  if (detect_reduced(model)) return Status::ok;
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
  bool finite = true;
  for (int i = 0; i < 16; ++i) finite = finite && std::isfinite(target.matrix().data()[i]);
  if (!finite || !is_rotation(target.linear(), 1e-6)) {
    result.status = Status::bad_input;
    return;
  }
  if (model.method == IkMethod::spherical_wrist) {
    solve_spherical(model, target, q_ref, result);
  } else {
    solve_reduced(model, target, q_ref, result);
  }
  finish_status(result);
}

Branch ik_branch_of(const IkModel& model, const JointVector& q) {
  Pose T;
  if (forward(model.chain, q, T) != Status::ok) return {};
  IkResult r;
  ik_solve_all(model, T, &q, r);
  int best = -1;
  double bd = 0;
  for (int i = 0; i < r.count; ++i) {
    double d = 0;
    for (int j = 0; j < q.size(); ++j) d += joint_distance(model.chain, j, r.solutions[static_cast<std::size_t>(i)].q[j], q[j]);
    if (best < 0 || d < bd) {
      best = i;
      bd = d;
    }
  }
  return best >= 0 ? r.solutions[static_cast<std::size_t>(best)].branch : Branch{};
}

int ik_choose(const IkModel& model, const IkResult& result, const JointVector& q_current, const IkChoice& choice) {
  const Chain& c = model.chain;
  if (q_current.size() != c.n_joints) return -1;
  Branch want{};
  if (choice.keep_branch) want = ik_branch_of(model, q_current);
  int best = -1;
  double bd = 0;
  for (int i = 0; i < result.count; ++i) {
    const IkSolution& s = result.solutions[static_cast<std::size_t>(i)];
    if (!s.within_limits && !choice.allow_out_of_limits) continue;
    if (choice.keep_branch && !(s.branch == want)) continue;
    double d = 0;
    for (int j = 0; j < c.n_joints; ++j) {
      const double w = choice.weights.size() == c.n_joints ? choice.weights[j] : 1.0;
      const double dj = s.q[j] - q_current[j];  // wrapped solutions: the travel really needed
      d += w * dj * dj;
    }
    if (best < 0 || d < bd) {
      best = i;
      bd = d;
    }
  }
  return best;
}

}  // namespace servoarm::kin
