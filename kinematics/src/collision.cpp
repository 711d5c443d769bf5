// SPDX-License-Identifier: Apache-2.0
// Feed-forward, free-drive torque and the generalized-momentum collision observer.
// See collision.hpp for the method and why.
#include "servoarm/kinematics/collision.hpp"

#include <cmath>
#include <cstdio>

namespace servoarm::kin {

namespace {
bool finite(const JointVector& v) { return v.allFinite(); }
}  // namespace

bool dynamics_refusal(const Chain& chain, char* buf, std::size_t size) {
  if (chain.has_inertial) {
    if (size > 0) buf[0] = '\0';
    return false;
  }
  if (size > 0)
    std::snprintf(buf, size,
                  "robot '%s' has no inertial data (mass, com, inertia per joint in its description; "
                  "docs/dynamics.md): feed-forward, free-drive and collision detection need them",
                  chain.name.data());
  return true;
}

Status feed_forward(const Chain& chain, const JointVector& q, const JointVector& qd, const JointVector& qdd,
                    FeedForward& out) {
  const int n = chain.n_joints;
  if (q.size() != n || qd.size() != n || qdd.size() != n) return Status::wrong_size;
  if (!finite(q) || !finite(qd) || !finite(qdd)) return Status::bad_input;
  if (!chain.has_inertial) return Status::unsupported;
  JointVector tau = JointVector::Zero(n);
  const Status s = inverse_dynamics(chain, q, qd, qdd, tau);  // friction included
  if (s != Status::ok) return s;
  out.torque = tau;
  out.velocity = qd;
  return Status::ok;
}

Status free_drive_torque(const Chain& chain, const JointVector& q, const JointVector& qd, JointVector& tau) {
  return free_drive_torque(chain, q, qd, JointVector(), tau);
}

Status free_drive_torque(const Chain& chain, const JointVector& q, const JointVector& qd,
                         const JointVector& damping, JointVector& tau) {
  const int n = chain.n_joints;
  if (q.size() != n || qd.size() != n) return Status::wrong_size;
  if (damping.size() != 0 && damping.size() != n) return Status::wrong_size;
  if (!finite(q) || !finite(qd) || !finite(damping) || (damping.size() > 0 && damping.minCoeff() < 0))
    return Status::bad_input;
  if (!chain.has_inertial) return Status::unsupported;
  JointVector g = JointVector::Zero(n), f = JointVector::Zero(n);
  Status s = gravity_torques(chain, q, g);
  if (s != Status::ok) return s;
  s = friction_torques(chain, qd, f);
  if (s != Status::ok) return s;
  tau = g + f;
  if (damping.size() > 0) tau -= damping.cwiseProduct(qd);
  return Status::ok;
}

Status CollisionObserver::configure(const Chain& chain, const CollisionConfig& cfg) {
  chain_ = nullptr;
  started_ = false;
  if (!chain.has_inertial) return Status::unsupported;
  if (!(cfg.gain > 0 && cfg.gain <= 1e4) || !(cfg.sensitivity > 0 && std::isfinite(cfg.sensitivity)))
    return Status::bad_input;
  for (int j = 0; j < chain.n_joints; ++j) {
    const double t = cfg.threshold[static_cast<std::size_t>(j)];
    if (!(t >= 0 && std::isfinite(t))) return Status::bad_input;
  }
  chain_ = &chain;
  cfg_ = cfg;
  n_ = chain.n_joints;
  p0_ = JointVector::Zero(n_);
  integral_ = JointVector::Zero(n_);
  r_ = JointVector::Zero(n_);
  m_prev_ = MassMatrix::Zero(n_, n_);
  return Status::ok;
}

Status CollisionObserver::update(const JointVector& q, const JointVector& qd, const JointVector& tau, double dt,
                                 CollisionVerdict& verdict) {
  verdict = CollisionVerdict{};
  if (chain_ == nullptr) return Status::unsupported;
  if (q.size() != n_ || qd.size() != n_ || tau.size() != n_) return Status::wrong_size;
  if (!finite(q) || !finite(qd) || !finite(tau)) return Status::bad_input;
  if (started_ && !(dt > 0 && std::isfinite(dt))) return Status::bad_input;
  const Chain& c = *chain_;
  MassMatrix M = MassMatrix::Zero(n_, n_);
  JointVector cqd = JointVector::Zero(n_), g = JointVector::Zero(n_), f = JointVector::Zero(n_);
  if (mass_matrix(c, q, M) != Status::ok || coriolis(c, q, qd, cqd) != Status::ok ||
      gravity_torques(c, q, g) != Status::ok || friction_torques(c, qd, f) != Status::ok)
    return Status::unsupported;
  const JointVector p = M * qd;
  if (!started_) {
    p0_ = p;
    integral_.setZero();
    r_.setZero();
    m_prev_ = M;
    prev_ = (cfg_.torque_is_interval_mean ? JointVector::Zero(n_) : tau) - g - f;  // C^T qd unknown yet (usually qd = 0)
    started_ = true;
    return Status::ok;
  }
  // C^T qd = dM/dt qd - C qd (dM/dt = C + C^T).
  MassMatrix Md = (M - m_prev_) / dt;
  m_prev_ = M;
  // Trapezoidal rule for the model part (samples of a continuous signal at the sample times); the
  // drives' torque likewise, or, when it is the mean over the interval, that mean times dt.
  if (cfg_.torque_is_interval_mean) {
    const JointVector beta = (Md * qd - cqd) - g - f;
    integral_ += (tau + 0.5 * (beta + prev_) + r_) * dt;
    prev_ = beta;
  } else {
    const JointVector beta = tau + (Md * qd - cqd) - g - f;
    integral_ += (0.5 * (beta + prev_) + r_) * dt;
    prev_ = beta;
  }
  r_ = cfg_.gain * (p - p0_ - integral_);
  double worst = 1.0;
  for (int j = 0; j < n_; ++j) {
    const double thr = cfg_.threshold[static_cast<std::size_t>(j)] / cfg_.sensitivity;
    if (!(thr > 0)) continue;
    const double ratio = std::fabs(r_[j]) / thr;
    if (ratio > worst) {
      worst = ratio;
      verdict.collision = true;
      verdict.joint = j;
      verdict.residual = r_[j];
      verdict.threshold = thr;
    }
  }
  return Status::ok;
}

}  // namespace servoarm::kin
