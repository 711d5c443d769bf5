// SPDX-License-Identifier: Apache-2.0
// Inverse kinematics, the arm's position: the subproblem of joints 1-3
// (E1, E2 of ik.hpp) in closed form where one equation involves only one of
// q2, q3 (PUMA, Stanford, cylindrical arms: atan2/acos or a quadratic), the
// general case in polynomial.cpp; and the candidates' last step shared by
// every closed form: wrap into the limits, verify by the chain's FK (polish
// with a few Gauss-Newton steps), de-duplicate. Real-time, heap-free.
#include <cmath>

#include <Eigen/Cholesky>

#include "ik_detail.hpp"
#include "servoarm/kinematics/orientation.hpp"

namespace servoarm::kin::detail {

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


namespace {

// Wrap a revolute joint into its limits where a 2*pi equivalent fits (nearest
// to ref); prismatic joints are left alone (rule: detail::wrap_into_limits).
inline double wrap_joint(const DhRow& r, double q, double ref) {
  if (r.type != JointType::revolute) return q;
  return detail::wrap_into_limits(fast_wrap(q), r.lower - 1e-12, r.upper + 1e-12, ref);
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

}  // namespace

// (m2, m3) candidates (see ik_detail.hpp).
int solve_position(const IkSolverData& m, const Eigen::Vector3d& p0, const double* ref_m2, PosCand* out, bool angles) {
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
  if (m.par23) return solve_position_parallel(m, p0, ref_m2, out, angles);
  return solve_position_resultant(m, M1, M2, tol1, out);
}

// Case P (axes 2 and 3 parallel, see IkSolverData::par23): m1 from the
// component along n_par, m3 from the distance to axis 2, m2 by one angle.
int solve_position_parallel(const IkSolverData& m, const Eigen::Vector3d& p0, const double* ref_m2, PosCand* out,
                            bool angles) {
  const Eigen::Vector3d& n = m.n_par;
  const double tol1 = 1e-12 * m.scale * m.scale, tol2 = 1e-12 * m.scale;
  Roots r1 = solve_basis(p0.z() * n.z() - m.beta, p0.x() * n.x() + p0.y() * n.y(), p0.y() * n.x() - p0.x() * n.y(),
                         false, tol2, false);
  if (r1.free) {  // p0 on axis 1: every m1 gives the same point in the frame after J1
    r1.n = 1;
    r1.c[0] = 1;
    r1.s[0] = 0;
  }
  merge_close_roots(r1);
  const Eigen::Matrix3d& R1 = C(m, 1).linear();
  const Eigen::Vector3d& t1 = C(m, 1).translation();
  const Eigen::Matrix3d& R2 = C(m, 2).linear();
  const Eigen::Vector3d& t2 = C(m, 2).translation();
  int n_out = 0;
  for (int i = 0; i < r1.n; ++i) {
    const double c1 = r1.c[i], s1 = r1.s[i];
    const Eigen::Vector3d p1(c1 * p0.x() + s1 * p0.y(), c1 * p0.y() - s1 * p0.x(), p0.z());  // Rz(-m1) p0
    const Eigen::Vector3d u = R1.transpose() * (p1 - t1);  // frame of joint 2
    const double d2 = u.x() * u.x() + u.y() * u.y();
    Roots r3 = solve_basis(m.g_par[0] - d2, m.g_par[1], m.g_par[2], false, tol1, angles);
    if (r3.free) continue;  // w on axis 3 and axis 3 on axis 2: not an arm
    merge_close_roots(r3);
    for (int k = 0; k < r3.n; ++k) {
      const double c3 = r3.c[k], s3 = r3.s[k];
      const Eigen::Vector3d w(c3 * m.w_par.x() - s3 * m.w_par.y(), s3 * m.w_par.x() + c3 * m.w_par.y(), m.w_par.z());
      const Eigen::Vector3d v = R2 * w + t2;
      PosCand& o = out[n_out++];
      o = PosCand{};
      o.c3 = c3;
      o.s3 = s3;
      o.m3 = r3.v[k];
      o.elbow = r3.label[k];
      const double cr = v.x() * u.y() - v.y() * u.x(), dt = v.x() * u.x() + v.y() * u.y();
      const double r2 = cr * cr + dt * dt;
      if (r2 <= 1e-24 * m.scale * m.scale * m.scale * m.scale) {  // w on axis 2: m2 free (keep it)
        o.free2 = true;
        o.m2 = ref_m2 ? *ref_m2 : 0.0;
        set_pair(false, o.m2, o.c2, o.s2);
      } else {
        const double ir = 1.0 / std::sqrt(r2);
        o.c2 = dt * ir;
        o.s2 = cr * ir;
        o.m2 = angles ? detail::atan2_poly(o.s2, o.c2) : 0.0;
      }
    }
  }
  return n_out;
}

// Finish a candidate (motion values m, SI joints = dir*m): wrap, verify by
// the chain's FK (a few Gauss-Newton steps if it is close but not within
// the tolerance, e.g. a root clamped at the reach limit), add. Flattened
// (everything of this file and the headers inlined into it): with
// solve_reduced flattened, the reduced arms take ~11 % fewer instructions
// than when all of the IK was one file.
[[gnu::flatten]] void add_candidate(const IkModel& model, const Pose& target, const JointVector* q_ref, const double* mot,
                   Branch br, std::uint8_t singular, bool position_only, IkResult& res) {
  const IkSolverData& m = solver_data(model);
  const Chain& c = model.chain;
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
  store_solution(model, q, br, singular, ep, er, res);
}

}  // namespace servoarm::kin::detail
