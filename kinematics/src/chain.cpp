// SPDX-License-Identifier: Apache-2.0
// Forward kinematics and the geometric Jacobian over DH rows.
//
// Real-time code: no heap, no exceptions. The product of the row transforms is
// accumulated column by column instead of as 4x4 matrix products: for a
// standard row, T <- T Rz(theta) Tz(d) Tx(a) Rx(alpha) is
//   x' =  ct*x + st*y          (Rz)
//   y' = -st*x + ct*y
//   p  += d*z + a*x'           (Tz, Tx)
//   y'' = ca*y' + sa*z,  z' = -sa*y' + ca*z     (Rx)
// and for a modified row, T <- T Rx(alpha) Tx(a) Rz(theta) Tz(d) is
//   p  += a*x;  y' = ca*y + sa*z;  z' = -sa*y + ca*z;
//   x'' = ct*x + st*y';  y'' = -st*x + ct*y';  p += d*z'.
// That is 2 sincos and ~40 flops per revolute row, against ~64 multiplies for
// a general 4x4 product.
#include <cmath>
#include <cstring>

#include <Eigen/SVD>

#include "servoarm/kinematics/chain.hpp"
#include "fast_trig.hpp"

namespace servoarm::kin {

const char* to_string(Convention c) {
  switch (c) {
    case Convention::standard: return "standard";
    case Convention::modified: return "modified";
  }
  return "unknown";
}

const char* to_string(JointType t) {
  switch (t) {
    case JointType::revolute: return "revolute";
    case JointType::prismatic: return "prismatic";
    case JointType::fixed: return "fixed";
  }
  return "unknown";
}

void set_name(Chain& chain, const char* name) {
  chain.name.fill('\0');
  if (name) std::strncpy(chain.name.data(), name, chain.name.size() - 1);
}

void set_tool(Chain& chain, const Pose& tool) {
  chain.tool = tool;
  chain.tool_is_identity = tool.matrix().isIdentity(0.0);
}

Status add_row(Chain& chain, const DhRow& in) {
  if (chain.n_rows >= kMaxRows) return Status::capacity;
  const bool is_joint = in.type != JointType::fixed;
  if (is_joint && chain.n_joints >= kMaxJoints) return Status::capacity;
  if (!std::isfinite(in.theta) || !std::isfinite(in.d) || !std::isfinite(in.a) ||
      !std::isfinite(in.alpha))
    return Status::bad_input;
  if (is_joint && in.direction != 1.0 && in.direction != -1.0) return Status::bad_input;
  if (std::isnan(in.lower) || std::isnan(in.upper) || in.lower > in.upper) return Status::bad_input;
  DhRow row = in;
  if (!is_joint) {
    row.direction = 1.0;
    row.lower = row.upper = 0.0;
  }
  row.ca = std::cos(row.alpha);
  row.sa = std::sin(row.alpha);
  row.alpha_kind = 0;
  if (std::abs(row.sa) < 1e-15) {
    if (row.ca > 0) row.alpha_kind = 1, row.ca = 1, row.sa = 0;
  } else if (std::abs(row.ca) < 1e-15) {
    row.alpha_kind = row.sa > 0 ? 2 : 3;
    row.ca = 0;
    row.sa = row.sa > 0 ? 1 : -1;
  }
  row.ct = std::cos(row.theta);
  row.st = std::sin(row.theta);
  if (is_joint) chain.joint_row[static_cast<std::size_t>(chain.n_joints++)] = static_cast<std::int8_t>(chain.n_rows);
  chain.rows[static_cast<std::size_t>(chain.n_rows++)] = row;
  return Status::ok;
}

namespace {

// Rotation columns and origin of the running frame.
struct Acc {
  Eigen::Vector3d x, y, z, p;
  void from(const Pose& T) {
    x = T.linear().col(0);
    y = T.linear().col(1);
    z = T.linear().col(2);
    p = T.translation();
  }
  void to(Pose& T) const {
    T.linear().col(0) = x;
    T.linear().col(1) = y;
    T.linear().col(2) = z;
    T.translation() = p;
  }
};

inline Status check_q(const Chain& chain, const JointVector& q) {
  if (q.size() != chain.n_joints) return Status::wrong_size;
  for (int i = 0; i < q.size(); ++i)
    if (!std::isfinite(q[i])) return Status::bad_input;
  return Status::ok;
}

// Advance the accumulator across one row whose joint value has been resolved
// into (ct, st, d). `axis_z`/`axis_p` receive the joint axis (direction and a
// point on it) in the base frame.
// Frame update by Rx(alpha): y' = ca y + sa z, z' = ca z - sa y, with the
// common alphas (0, +90, -90 deg) special-cased.
inline void rot_x(const DhRow& r, const Eigen::Vector3d& y, Eigen::Vector3d& y_out, Eigen::Vector3d& z) {
  switch (r.alpha_kind) {
    case 1:
      y_out = y;
      return;
    case 2: {
      y_out = z;
      z = -y;
      return;
    }
    case 3: {
      y_out = -z;
      z = y;
      return;
    }
    default: {
      const Eigen::Vector3d z0 = z;
      y_out = r.ca * y + r.sa * z0;
      z = r.ca * z0 - r.sa * y;
      return;
    }
  }
}

template <bool kModified>
inline void step(const DhRow& r, double ct, double st, double d, Acc& t, Eigen::Vector3d* axis_z,
                 Eigen::Vector3d* axis_p) {
  if constexpr (!kModified) {
    if (axis_z) {
      *axis_z = t.z;
      *axis_p = t.p;
    }
    const Eigen::Vector3d x1 = ct * t.x + st * t.y;
    const Eigen::Vector3d y1 = ct * t.y - st * t.x;
    if (d != 0.0) t.p += d * t.z;
    if (r.a != 0.0) t.p += r.a * x1;
    t.x = x1;
    rot_x(r, y1, t.y, t.z);
  } else {
    if (r.a != 0.0) t.p += r.a * t.x;
    Eigen::Vector3d y1;
    rot_x(r, t.y, y1, t.z);
    if (axis_z) {
      *axis_z = t.z;
      *axis_p = t.p;
    }
    const Eigen::Vector3d x2 = ct * t.x + st * y1;
    t.y = ct * y1 - st * t.x;
    t.x = x2;
    if (d != 0.0) t.p += d * t.z;
  }
}

template <bool kModified>
inline void run(const Chain& chain, const JointVector& q, Acc& t, FrameSet* frames,
                Eigen::Vector3d* zs, Eigen::Vector3d* ps) {
  // Resolve every row's theta first, so the sines and cosines are computed in
  // one branch-free batch (vectorised), then walk the rows.
  const int nj = chain.n_joints;
  double th[kMaxJoints];
  double sn[kMaxJoints];
  double cs[kMaxJoints];
  for (int j = 0; j < nj; ++j) {
    const DhRow& r = chain.joint(j);
    th[j] = r.theta + r.direction * q[j];
  }
  for (int j = 0; j < nj; ++j) detail::sincos_poly(th[j], sn[j], cs[j]);
  t.from(chain.base);
  if (frames) {
    frames->frame[0] = chain.base;
    frames->count = chain.n_rows + 1;
  }
  int j = 0;
  for (int i = 0; i < chain.n_rows; ++i) {
    const DhRow& r = chain.rows[static_cast<std::size_t>(i)];
    switch (r.type) {
      case JointType::revolute:
        step<kModified>(r, cs[j], sn[j], r.d, t, zs ? &zs[j] : nullptr, ps ? &ps[j] : nullptr);
        ++j;
        break;
      case JointType::prismatic:
        step<kModified>(r, r.ct, r.st, r.d + r.direction * q[j], t, zs ? &zs[j] : nullptr,
                        ps ? &ps[j] : nullptr);
        ++j;
        break;
      case JointType::fixed:
        step<kModified>(r, r.ct, r.st, r.d, t, nullptr, nullptr);
        break;
    }
    if (frames) t.to(frames->frame[i + 1]);
  }
}

inline void finish(const Chain& chain, const Acc& t, Pose& pose) {
  if (chain.tool_is_identity) {
    t.to(pose);
    pose.matrix().row(3) << 0, 0, 0, 1;
    return;
  }
  Pose T;
  T.matrix().row(3) << 0, 0, 0, 1;
  t.to(T);
  pose = T * chain.tool;
}

}  // namespace

Status forward(const Chain& chain, const JointVector& q, Pose& pose) {
  const Status s = check_q(chain, q);
  if (s != Status::ok) return s;
  Acc t;
  if (chain.convention == Convention::standard)
    run<false>(chain, q, t, nullptr, nullptr, nullptr);
  else
    run<true>(chain, q, t, nullptr, nullptr, nullptr);
  finish(chain, t, pose);
  return Status::ok;
}

Status forward_frames(const Chain& chain, const JointVector& q, FrameSet& frames, Pose& pose) {
  const Status s = check_q(chain, q);
  if (s != Status::ok) return s;
  Acc t;
  if (chain.convention == Convention::standard)
    run<false>(chain, q, t, &frames, nullptr, nullptr);
  else
    run<true>(chain, q, t, &frames, nullptr, nullptr);
  finish(chain, t, pose);
  return Status::ok;
}

Status jacobian(const Chain& chain, const JointVector& q, Jacobian& J, Pose* pose_out) {
  const Status s = check_q(chain, q);
  if (s != Status::ok) return s;
  Eigen::Vector3d zs[kMaxJoints];
  Eigen::Vector3d ps[kMaxJoints];
  Acc t;
  if (chain.convention == Convention::standard)
    run<false>(chain, q, t, nullptr, zs, ps);
  else
    run<true>(chain, q, t, nullptr, zs, ps);
  Pose pose;
  finish(chain, t, pose);
  const Eigen::Vector3d tip = pose.translation();
  J.resize(6, chain.n_joints);
  for (int j = 0; j < chain.n_joints; ++j) {
    const DhRow& r = chain.joint(j);
    const Eigen::Vector3d z = r.direction * zs[j];
    if (r.type == JointType::revolute) {
      J.block<3, 1>(0, j) = z.cross(tip - ps[j]);
      J.block<3, 1>(3, j) = z;
    } else {
      J.block<3, 1>(0, j) = z;
      J.block<3, 1>(3, j).setZero();
    }
  }
  if (pose_out) *pose_out = pose;
  return Status::ok;
}

namespace {
using SingularValues = Eigen::Matrix<double, Eigen::Dynamic, 1, Eigen::ColMajor, 6, 1>;
// Every SVD here is of a 6 x 6 matrix, so Eigen's QR preconditioner (which only a rectangular
// one needs, and which instantiates three QR decompositions for each shape) is left out: the
// same singular values, a fraction of the compile time.
using Square6 = Eigen::Matrix<double, 6, 6>;
SingularValues singular_values(const Jacobian& J) {
  const int n = static_cast<int>(J.cols());
  if (n == 0) return SingularValues();
  Square6 A = Square6::Zero();
  if (n <= 6) {
    // 6 x n, n <= 6: [J 0] has J's n singular values and 6 - n zeros, so (sorted, largest
    // first) its first n are J's.
    A.leftCols(n) = J;
  } else {
    // 6 x n, n > 6: J^T = Q R, and R^T (6 x 6) has J's singular values; this is the step
    // Eigen's column-pivoting preconditioner takes for a matrix wider than it is tall.
    using Tall = Eigen::Matrix<double, Eigen::Dynamic, 6, Eigen::ColMajor, kMaxJoints, 6>;
    Eigen::ColPivHouseholderQR<Tall> qr(Tall(J.transpose()));
    A = qr.matrixQR().topRows<6>().triangularView<Eigen::Upper>().transpose();
  }
  Eigen::JacobiSVD<Square6, Eigen::NoQRPreconditioner> svd(A);
  return svd.singularValues().head(std::min(n, 6));
}
}  // namespace

double manipulability(const Jacobian& J) {
  const SingularValues sv = singular_values(J);
  double m = 1.0;
  for (int i = 0; i < sv.size(); ++i) m *= sv[i];
  return sv.size() ? m : 0.0;
}

double condition_number(const Jacobian& J) {
  const SingularValues sv = singular_values(J);
  if (sv.size() == 0) return std::numeric_limits<double>::infinity();
  const double smax = sv.maxCoeff();
  const double smin = sv.minCoeff();
  if (smin <= smax * 1e-15) return std::numeric_limits<double>::infinity();
  return smax / smin;
}

Status cartesian_precision(const Chain& chain, const JointVector& q, const JointVector& dq,
                           Eigen::Vector3d& dw) {
  if (dq.size() != chain.n_joints) return Status::wrong_size;
  for (int i = 0; i < dq.size(); ++i)
    if (!std::isfinite(dq[i]) || dq[i] < 0) return Status::bad_input;
  Jacobian J;
  const Status s = jacobian(chain, q, J);
  if (s != Status::ok) return s;
  dw = J.topRows<3>().cwiseAbs() * dq;
  return Status::ok;
}

bool within_limits(const Chain& chain, const JointVector& q, double tol) {
  if (q.size() != chain.n_joints) return false;
  for (int j = 0; j < chain.n_joints; ++j) {
    const DhRow& r = chain.joint(j);
    if (!(q[j] >= r.lower - tol && q[j] <= r.upper + tol)) return false;
  }
  return true;
}

}  // namespace servoarm::kin
