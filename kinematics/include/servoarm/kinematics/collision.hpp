// SPDX-License-Identifier: Apache-2.0
#pragma once
// Using the dynamic model in the control loop: the feed-forward of a setpoint, the
// torque that compensates gravity and friction (hand guiding), and a collision observer.
//
// Collision observer: the generalized-momentum observer of De Luca and Mattone (ICRA 2003;
// De Luca, Albu-Schaeffer, Haddadin, Hirzinger, IROS 2006). With p = M(q) qd,
//
//   dp/dt = tau + C(q, qd)^T qd - g(q) - friction(qd) + tau_ext
//   r(t)  = K (p(t) - p(0) - integral_0^t (tau + C^T qd - g - friction + r) ds)
//
// so that dr/dt = K (tau_ext - r): r is the external torque seen through a first-order filter
// of time constant 1/K, per joint and decoupled. Why this and not a filtered torque residual
// (tau_measured - ID(q_cmd, qd_cmd, qdd_cmd)): it needs no joint acceleration (a second
// difference of encoder counts is noisy) and it uses the motion the arm made, not the one it
// was told to make, so following errors, feed-forward on or off and the drives' own loops do
// not show up in it; its bandwidth is one number (K). tau is the motor torque the drives
// report (CANopen 6077h), q and qd the measured positions and velocities. C^T qd is computed
// as dM/dt qd - C qd, with C qd from Newton-Euler (kin::coriolis) and dM/dt the difference of
// M between two updates, and the integral by the trapezoidal rule over the samples (the
// approximations: O(dt)); the drives' torque either so (point samples) or, when they report
// their mean over the interval (CollisionConfig::torque_is_interval_mean), as that mean.
//
// Real-time: everything here except CollisionObserver::configure() is heap-free, lock-free,
// throws nothing (fixed-size Eigen, bounded loops); configure() too, in fact, but it is
// set-up code.
#include <array>
#include <cstddef>
#include <cstdint>

#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/dynamics.hpp"
#include "servoarm/kinematics/status.hpp"
#include "servoarm/kinematics/types.hpp"

namespace servoarm::kin {

/// Why `chain` cannot be used for feed-forward, free-drive and collision detection: one line
/// into `buf` ("robot 'stanford' has no inertial data (mass, com, inertia per joint in its
/// description; docs/dynamics.md): feed-forward, free-drive and collision detection need
/// them") and true; "" and false when it can.
bool dynamics_refusal(const Chain& chain, char* buf, std::size_t size);

/// Feed-forward of a setpoint: what a CSP drive adds to its loops (CANopen 60B1h / 60B2h).
struct FeedForward {
  JointVector velocity;  ///< rad/s (m/s): the setpoint's velocity
  JointVector torque;    ///< N m (N): M(q) qdd + c(q, qd) + g(q) + friction(qd)
};

/// Model torque of the setpoint (q, qd, qdd), friction included, and its velocity.
/// @retval ok; wrong_size; bad_input (NaN/Inf: out untouched); unsupported (no inertial data:
///         see dynamics_refusal())
Status feed_forward(const Chain& chain, const JointVector& q, const JointVector& qd, const JointVector& qdd,
                    FeedForward& out);

/// Hand guiding (free-drive): the torque that holds the arm against gravity and friction at
/// (q, qd), minus a virtual viscous damping: g(q) + friction(qd) - damping .* qd. The damping
/// (N m s/rad, N s/m, >= 0 per joint; empty = none) keeps a frictionless arm from drifting on
/// the model's and the torque's quantisation errors. Returns as feed_forward(); bad_input also
/// for a negative damping or a damping vector of the wrong size.
Status free_drive_torque(const Chain& chain, const JointVector& q, const JointVector& qd, JointVector& tau);
Status free_drive_torque(const Chain& chain, const JointVector& q, const JointVector& qd,
                         const JointVector& damping, JointVector& tau);

struct CollisionConfig {
  double gain = 100.0;  ///< K, 1/s: the residual follows the external torque with time constant 1/K
  /// Per joint: |r_j| above threshold[j] / sensitivity is a collision (N m or N); 0 = joint
  /// not checked.
  std::array<double, kMaxJoints> threshold{};
  double sensitivity = 1.0;  ///< > 0: 2 halves every threshold, 0.5 doubles them
  /// What the torques given to update() are. false: samples of a continuous signal at the sample
  /// time (integrated with the model terms by the trapezoidal rule). true: each is the mean torque
  /// over the interval since the previous sample, as a drive reports its current averaged over
  /// the SYNC period (the dynamic plant's 6077h): integrated as that mean times the interval,
  /// which is exact however long the interval and however the torque changed within it (a
  /// trapezoid would mix in the previous interval's torque).
  bool torque_is_interval_mean = false;
};

struct CollisionVerdict {
  bool collision = false;
  int joint = -1;          ///< the joint with the largest |r_j| / threshold_j above 1 (0-based)
  double residual = 0;     ///< its residual, N m (N)
  double threshold = 0;    ///< its threshold (sensitivity applied)
};

class CollisionObserver {
 public:
  /// Set-up. `chain` must outlive the observer.
  /// @retval ok; unsupported (no inertial data); bad_input (gain not in (0, 1e4], sensitivity
  ///         not > 0, a negative or non-finite threshold)
  Status configure(const Chain& chain, const CollisionConfig& cfg);
  /// Start again at the next update() (its state becomes p(0); the residual 0). Call when the
  /// drives (re)enable, after a fault, when the model or the payload change.
  void reset() { started_ = false; }
  /// Real-time: one sample: measured q, qd, the drives' torques tau (joint side), `dt` seconds
  /// since the previous sample (> 0; ignored on the first after reset()).
  /// @retval ok; wrong_size; bad_input (NaN/Inf, dt <= 0: state untouched); unsupported (not
  ///         configured, or the model failed: the verdict is no collision)
  Status update(const JointVector& q, const JointVector& qd, const JointVector& tau, double dt,
                CollisionVerdict& verdict);
  /// The residual r (estimated external torque, N m / N) after the last update.
  const JointVector& residual() const { return r_; }
  const CollisionConfig& config() const { return cfg_; }

 private:
  const Chain* chain_ = nullptr;
  CollisionConfig cfg_{};
  bool started_ = false;
  int n_ = 0;
  JointVector p0_, integral_, r_, prev_;
  MassMatrix m_prev_;
};

}  // namespace servoarm::kin
