// SPDX-License-Identifier: Apache-2.0
// Numerical IK: damped least squares with Levenberg-Marquardt damping.
//
// Each iteration: J (geometric Jacobian, weighted), e (weighted pose error),
//   (J^T J + mu (diag(J^T J) + 1e-6 I)) dq = J^T e,   q' = clamp(q + dq)
// accepted if the weighted error drops, mu then updated after Nielsen (gain
// ratio), else rejected (mu *= nu, nu doubling). A start that does not halve
// its error within stall_iterations iterations is abandoned for a restart.
// 6 joints: fixed-size normal equations and an unrolled LDL^T.
// Clamping to the limits after each step keeps every iterate inside them.
// Random restarts (deterministic generator) run only if the start fails.
// Worst case: (1 + max_restarts) * max_iterations iterations, each one
// Jacobian, one FK and one n x n LDLT (n <= 8). Heap-free.
#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>

#include "ik_detail.hpp"
#include "servoarm/kinematics/orientation.hpp"

namespace servoarm::kin {

namespace {

using MatN = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor, kMaxJoints, kMaxJoints>;
using Vec6 = Eigen::Matrix<double, 6, 1>;

std::uint64_t splitmix(std::uint64_t& s) {
  std::uint64_t z = (s += 0x9e3779b97f4a7c15ULL);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}
double uniform(std::uint64_t& s) { return static_cast<double>(splitmix(s) >> 11) * (1.0 / 9007199254740992.0); }

void clamp_limits(const Chain& c, JointVector& q) {
  for (int j = 0; j < c.n_joints; ++j) {
    const DhRow& r = c.joint(j);
    if (r.type == JointType::revolute) {
      if (!(std::isfinite(r.lower) && std::isfinite(r.upper))) {
        q[j] = wrap_pi(q[j]);
      } else if (r.upper - r.lower >= 2 * M_PI - 1e-12 && !(q[j] >= r.lower && q[j] < r.lower + 2 * M_PI)) {
        // a full turn fits: wrap into [lower, lower + 2 pi) instead of stopping at the limit
        q[j] = r.lower + std::fmod(std::fmod(q[j] - r.lower, 2 * M_PI) + 2 * M_PI, 2 * M_PI);
      }
    }
    q[j] = std::clamp(q[j], r.lower, r.upper);
  }
}

struct Err {
  Vec6 e;          // unweighted (position, rotation)
  double cost = 0; // weighted squared norm
  double ep = 0, er = 0;
};

bool evaluate(const Chain& c, const Pose& target, const JointVector& q, const IkNumericOptions& o, Err& out,
              Jacobian* J) {
  Pose T;
  if (J) {
    if (jacobian(c, q, *J, &T) != Status::ok) return false;
  } else if (forward(c, q, T) != Status::ok) {
    return false;
  }
  out.e.head<3>() = target.translation() - T.translation();
  if (o.position_only) {
    out.e.tail<3>().setZero();
  } else {
    out.e.tail<3>() = rotation_error(T.linear(), target.linear());
  }
  out.ep = out.e.head<3>().norm();
  out.er = out.e.tail<3>().norm();
  out.cost = (o.task_weights.cwiseProduct(out.e)).squaredNorm();
  return std::isfinite(out.cost);
}

bool converged(const Err& e, const IkNumericOptions& o) {
  return e.ep <= o.tolerance_position && (o.position_only || e.er <= o.tolerance_rotation);
}

// LDL^T solve of an N x N symmetric positive definite system, written out so
// the compiler unrolls it (Eigen's LLT ran its loops for a 6 x 6 at run time:
// 30 % of an LM iteration) and without square roots. False if A is not
// positive definite.
template <int N>
bool ldlt_solve(const Eigen::Matrix<double, N, N>& A, const Eigen::Matrix<double, N, 1>& b,
                Eigen::Matrix<double, N, 1>& x) {
  double L[N][N];  // unit lower triangle (below the diagonal)
  double D[N], inv[N];
  for (int j = 0; j < N; ++j) {
    double d = A(j, j);
    for (int k = 0; k < j; ++k) d -= L[j][k] * L[j][k] * D[k];
    if (!(d > 0)) return false;
    D[j] = d;
    inv[j] = 1.0 / d;
    for (int i = j + 1; i < N; ++i) {
      double v = A(i, j);
      for (int k = 0; k < j; ++k) v -= L[i][k] * L[j][k] * D[k];
      L[i][j] = v * inv[j];
    }
  }
  double y[N];
  for (int i = 0; i < N; ++i) {
    double v = b[i];
    for (int k = 0; k < i; ++k) v -= L[i][k] * y[k];
    y[i] = v;
  }
  for (int i = N - 1; i >= 0; --i) {
    double v = y[i] * inv[i];
    for (int k = i + 1; k < N; ++k) v -= L[k][i] * x[k];
    x[i] = v;
  }
  return true;
}

// Solve (H + mu (diag(H) + 1e-6)) dq = g; fixed-size Cholesky for 6 joints.
bool solve_step(const Jacobian& Jw, const Vec6& ew, double mu, int n, JointVector& dq, double& predicted) {
  if (n == 6) {
    using M6 = Eigen::Matrix<double, 6, 6>;
    const M6 J6 = Jw.leftCols<6>();
    const M6 H = J6.transpose() * J6;
    const Vec6 g = J6.transpose() * ew;
    M6 A = H;
    Vec6 D;
    for (int j = 0; j < 6; ++j) D[j] = H(j, j) + 1e-6, A(j, j) += mu * D[j];
    Vec6 h;
    if (!ldlt_solve<6>(A, g, h)) return false;
    dq = h;
    // decrease of |e - J h|^2 the linear model predicts
    predicted = h.dot(g) + mu * h.dot(D.cwiseProduct(h));
    return detail::all_finite(h);
  }
  const MatN H = Jw.transpose() * Jw;
  const JointVector g = Jw.transpose() * ew;
  MatN A = H;
  JointVector D(n);
  for (int j = 0; j < n; ++j) D[j] = H(j, j) + 1e-6, A(j, j) += mu * D[j];
  dq = A.ldlt().solve(g);
  predicted = dq.dot(g) + mu * dq.dot(D.cwiseProduct(dq));
  return detail::all_finite(dq);
}

// One LM run from q (in place). Returns iterations used. Damping after
// Nielsen: a step is accepted if the weighted error drops; mu then shrinks by
// max(1/3, 1 - (2 rho - 1)^3) with rho the actual over the predicted decrease,
// else it grows by nu (doubling on every rejection in a row). A start that
// has not halved its error within stall_iterations iterations is abandoned
// (a joint limit or a local minimum holds it): the caller restarts.
int run_lm(const Chain& c, const Pose& target, JointVector& q, const IkNumericOptions& o, Err& err) {
  const int n = c.n_joints;
  double mu = o.initial_damping, nu = 2.0;
  // Two Jacobians, swapped on acceptance (no copies); the weighted copy
  // only when weights or position-only ask for one.
  Jacobian Ja, Jb, Jw;
  Jacobian* J = &Ja;
  Jacobian* J2 = &Jb;
  const bool plain = !o.position_only && (o.task_weights.array() == 1.0).all();
  if (!evaluate(c, target, q, o, err, J)) return 0;
  int it = 0;
  double cost_mark = err.cost;
  int it_mark = 0;
  while (it < o.max_iterations && !converged(err, o)) {
    ++it;
    const Jacobian* Jx = J;
    if (!plain) {
      Jw = *J;
      for (int r = 0; r < 6; ++r) Jw.row(r) *= o.task_weights[r];
      if (o.position_only) Jw.bottomRows<3>().setZero();
      Jx = &Jw;
    }
    const Vec6 ew = o.task_weights.cwiseProduct(err.e);
    JointVector dq(n);
    double predicted = 0;
    bool ok = solve_step(*Jx, ew, mu, n, dq, predicted);
    JointVector q2 = q + dq;
    clamp_limits(c, q2);
    Err e2;
    ok = ok && evaluate(c, target, q2, o, e2, J2);
    if (ok && e2.cost < err.cost) {
      const double rho = predicted > 0 ? (err.cost - e2.cost) / predicted : 1.0;
      q = q2;
      err = e2;
      std::swap(J, J2);
      const double t = 2.0 * rho - 1.0;
      mu = std::max(mu * std::max(1.0 / 3.0, 1.0 - t * t * t), 1e-12);
      nu = 2.0;
    } else {
      mu *= nu;
      nu *= 2.0;
      if (mu >= 1e8) break;  // stuck (limit or local minimum): restart
    }
    if (o.stall_iterations > 0 && it - it_mark >= o.stall_iterations) {
      if (!(err.cost < 0.5 * cost_mark)) break;
      cost_mark = err.cost;
      it_mark = it;
    }
  }
  return it;
}

}  // namespace

void ik_numeric(const Chain& chain, const Pose& target, const JointVector& q_start, const IkNumericOptions& o,
                IkNumericResult& res) {
  res.iterations = 0;
  res.restarts = 0;
  if (q_start.size() != chain.n_joints) {
    res.status = Status::wrong_size;
    return;
  }
  if (!detail::all_finite(q_start) || !detail::all_finite(target.matrix()) ||
      (!o.position_only && !is_rotation(target.linear(), 1e-6)) || !detail::all_finite(o.task_weights) ||
      o.max_iterations < 0 || o.max_restarts < 0) {
    res.status = Status::bad_input;
    res.q = q_start;
    clamp_limits(chain, res.q);
    if (!detail::all_finite(res.q)) res.q.setZero();
    return;
  }
  JointVector q = q_start;
  clamp_limits(chain, q);
  Err err;
  res.iterations += run_lm(chain, target, q, o, err);
  JointVector best = q;
  Err best_err = err;
  std::uint64_t s = o.seed;
  while (!converged(best_err, o) && res.restarts < o.max_restarts) {
    ++res.restarts;
    JointVector r(chain.n_joints);
    for (int j = 0; j < chain.n_joints; ++j) {
      const DhRow& row = chain.joint(j);
      const double lo = std::isfinite(row.lower) ? row.lower : -M_PI;
      const double hi = std::isfinite(row.upper) ? row.upper : M_PI;
      r[j] = lo + (hi - lo) * uniform(s);
    }
    Err e;
    res.iterations += run_lm(chain, target, r, o, e);
    if (e.cost < best_err.cost) {
      best = r;
      best_err = e;
    }
  }
  res.q = best;
  res.position_error = best_err.ep;
  res.rotation_error = o.position_only ? 0.0 : best_err.er;
  res.status = converged(best_err, o) ? Status::ok : Status::not_converged;
}

}  // namespace servoarm::kin
