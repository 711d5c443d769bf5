// SPDX-License-Identifier: Apache-2.0
// Feed-forward, free-drive torque and the generalized-momentum collision observer (
// kinematics/include/servoarm/kinematics/collision.hpp).
//  - feed_forward = M(q) qdd + c + g + friction assembled from the mass matrix (composite
//    rigid body) and the Coriolis / gravity / friction terms, a different algorithm from the
//    Newton-Euler pass feed_forward uses; free_drive_torque = g + friction, g checked against
//    the gradient of the potential energy (COMs placed by forward_frames);
//  - the observer on an arm simulated here (RK4 of forward dynamics at 0.1 ms, the torques held
//    over each 1 ms sample): with no external torque the residual stays near 0 while the arm
//    moves fast; a step of external torque on one joint shows as tau_ext (1 - exp(-K t)), the
//    closed-form response of the first-order filter, on that joint only;
//  - thresholds, sensitivity, the joint named; a model without inertial data refused with the
//    reason; bad input; no heap in update().
#include <cmath>
#include <cstdio>
#include <random>

#include "../support/alloc_counter.hpp"
#include "servoarm/kinematics/collision.hpp"
#include "servoarm/kinematics/dynamics.hpp"
#include "kin_test_util.hpp"

using namespace servoarm;
using namespace servoarm::test;

namespace {

double potential(const kin::Chain& c, const kin::JointVector& q) {
  kin::FrameSet F;
  kin::Pose T;
  CHECK(kin::forward_frames(c, q, F, T) == kin::Status::ok);
  const Eigen::Vector3d g(c.gravity[0], c.gravity[1], c.gravity[2]);
  double V = 0;
  for (int i = 0; i < c.n_rows; ++i) {
    const auto& L = c.inertial[static_cast<std::size_t>(i)];
    V -= L.mass * g.dot(F.frame[i + 1] * Eigen::Vector3d(L.com[0], L.com[1], L.com[2]));
  }
  return V;
}

// The arm simulated in the test: a PD + gravity controller tracking a fast sinusoid (so that
// velocities and Coriolis terms are large), an external joint torque from t_ext on.
struct Sim {
  const kin::Chain& c;
  int n;
  kin::JointVector q, qd, q0;
  double t = 0;
  Sim(const kin::Chain& chain, const kin::JointVector& start) : c(chain), n(chain.n_joints), q(start), qd(kin::JointVector::Zero(chain.n_joints)), q0(start) {}
  kin::JointVector control() const {
    kin::JointVector g(n), tau(n);
    CHECK(kin::gravity_torques(c, q, g) == kin::Status::ok);
    kin::MassMatrix M(n, n);
    CHECK(kin::mass_matrix(c, q, M) == kin::Status::ok);
    for (int j = 0; j < n; ++j) {
      const double w = 2.0 + 0.7 * j;  // rad/s
      // From rest: 0.6 (1 - cos w t), so the motion starts without a velocity step.
      const double ref = q0[j] + 0.6 * (1.0 - std::cos(w * t)), vref = 0.6 * w * std::sin(w * t);
      tau[j] = g[j] + M(j, j) * (400.0 * (ref - q[j]) + 40.0 * (vref - qd[j]));
    }
    return tau;
  }
  void acc(const kin::JointVector& qq, const kin::JointVector& vv, const kin::JointVector& tau, kin::JointVector& a) {
    CHECK(kin::forward_dynamics(c, qq, vv, tau, a) == kin::Status::ok);
  }
  // Advance `dt` with the torque tau + ext held (RK4, 10 substeps).
  void step(const kin::JointVector& tau, double dt) {
    const int k = 10;
    const double h = dt / k;
    kin::JointVector a1(n), a2(n), a3(n), a4(n);
    for (int i = 0; i < k; ++i) {
      acc(q, qd, tau, a1);
      acc(q + 0.5 * h * qd, qd + 0.5 * h * a1, tau, a2);
      acc(q + 0.5 * h * (qd + 0.5 * h * a1), qd + 0.5 * h * a2, tau, a3);
      acc(q + h * (qd + 0.5 * h * a2), qd + h * a3, tau, a4);
      q += h / 6.0 * (qd + 2 * (qd + 0.5 * h * a1) + 2 * (qd + 0.5 * h * a2) + (qd + h * a3));
      qd += h / 6.0 * (a1 + 2 * a2 + 2 * a3 + a4);
    }
    t += dt;
  }
};

}  // namespace

TEST_GROUP(Collision){};

TEST(Collision, FeedForwardIsMassMatrixTimesAccelerationPlusBiasTerms) {
  std::mt19937_64 rng(20);
  std::uniform_real_distribution<double> u(-2, 2);
  for (const char* name : {"puma560", "trr", "cylindrical_rpp_rrr"}) {
    kin::Chain c = model(name);
    const int n = c.n_joints;
    // Friction on, so the helper is seen to include it.
    for (int j = 0; j < n; ++j) {
      auto& L = c.inertial[static_cast<std::size_t>(c.joint_row[static_cast<std::size_t>(j)])];
      L.viscous = 0.5 + 0.1 * j;
      L.coulomb = 0.3;
    }
    double worst = 0;
    for (int s = 0; s < 500; ++s) {
      const kin::JointVector q = random_q(c, rng);
      kin::JointVector qd(n), qdd(n);
      for (int j = 0; j < n; ++j) qd[j] = u(rng), qdd[j] = 2.5 * u(rng);
      kin::FeedForward ff;
      LONGS_EQUAL(int(kin::Status::ok), int(kin::feed_forward(c, q, qd, qdd, ff)));
      kin::MassMatrix M(n, n);
      kin::JointVector cc(n), g(n), f(n);
      CHECK(kin::mass_matrix(c, q, M) == kin::Status::ok);
      CHECK(kin::coriolis(c, q, qd, cc) == kin::Status::ok);
      CHECK(kin::gravity_torques(c, q, g) == kin::Status::ok);
      for (int j = 0; j < n; ++j) f[j] = (0.5 + 0.1 * j) * qd[j] + 0.3 * (qd[j] > 0 ? 1.0 : -1.0);
      const kin::JointVector want = M * qdd + cc + g + f;
      worst = std::max(worst, (ff.torque - want).cwiseAbs().maxCoeff() / (1.0 + want.cwiseAbs().maxCoeff()));
      CHECK((ff.velocity - qd).cwiseAbs().maxCoeff() == 0.0);
    }
    char msg[120];
    std::snprintf(msg, sizeof msg, "%s: feed-forward vs M qdd + c + g + f: %.3g relative", name, worst);
    CHECK_TEXT(worst < 1e-10, msg);
  }
}

TEST(Collision, FreeDriveTorqueIsTheGradientOfThePotentialPlusFriction) {
  kin::Chain c = model("puma560");
  const int n = c.n_joints;
  for (int j = 0; j < n; ++j) c.inertial[static_cast<std::size_t>(c.joint_row[static_cast<std::size_t>(j)])].viscous = 1.5;
  std::mt19937_64 rng(3);
  for (int s = 0; s < 50; ++s) {
    const kin::JointVector q = random_q(c, rng);
    kin::JointVector qd = kin::JointVector::Constant(n, 0.2), tau(n);
    LONGS_EQUAL(int(kin::Status::ok), int(kin::free_drive_torque(c, q, qd, tau)));
    for (int j = 0; j < n; ++j) {
      const double h = 1e-6;
      kin::JointVector qp = q, qm = q;
      qp[j] += h;
      qm[j] -= h;
      const double dV = (potential(c, qp) - potential(c, qm)) / (2 * h);
      DOUBLES_EQUAL(dV + 1.5 * 0.2, tau[j], 1e-6 * (1 + std::fabs(dV)));
    }
  }
}

TEST(Collision, ModelWithoutInertialDataIsRefusedSayingWhy) {
  const kin::Chain c = model("stanford");
  CHECK(!c.has_inertial);
  char buf[256];
  CHECK(kin::dynamics_refusal(c, buf, sizeof buf));
  STRCMP_EQUAL(
      "robot 'stanford' has no inertial data (mass, com, inertia per joint in its description; docs/dynamics.md): "
      "feed-forward, free-drive and collision detection need them",
      buf);
  const kin::Chain p = model("puma560");
  CHECK(!kin::dynamics_refusal(p, buf, sizeof buf));
  STRCMP_EQUAL("", buf);
  const int n = c.n_joints;
  const kin::JointVector z = kin::JointVector::Zero(n);
  kin::FeedForward ff;
  kin::JointVector tau(n);
  LONGS_EQUAL(int(kin::Status::unsupported), int(kin::feed_forward(c, z, z, z, ff)));
  LONGS_EQUAL(int(kin::Status::unsupported), int(kin::free_drive_torque(c, z, z, tau)));
  kin::CollisionObserver obs;
  LONGS_EQUAL(int(kin::Status::unsupported), int(obs.configure(c, {})));
  kin::CollisionVerdict v;
  LONGS_EQUAL(int(kin::Status::unsupported), int(obs.update(z, z, z, 1e-3, v)));
  CHECK(!v.collision);
}

TEST(Collision, BadInputIsRefused) {
  const kin::Chain c = model("puma560");
  const kin::JointVector z = kin::JointVector::Zero(6), z5 = kin::JointVector::Zero(5);
  kin::JointVector nan = z;
  nan[2] = std::nan("");
  kin::FeedForward ff;
  ff.torque = kin::JointVector::Constant(6, 7.0);
  LONGS_EQUAL(int(kin::Status::wrong_size), int(kin::feed_forward(c, z5, z, z, ff)));
  LONGS_EQUAL(int(kin::Status::bad_input), int(kin::feed_forward(c, z, nan, z, ff)));
  DOUBLES_EQUAL(7.0, ff.torque[0], 0);  // untouched
  kin::CollisionObserver obs;
  kin::CollisionConfig cfg;
  cfg.gain = 0;
  LONGS_EQUAL(int(kin::Status::bad_input), int(obs.configure(c, cfg)));
  cfg = {};
  cfg.sensitivity = 0;
  LONGS_EQUAL(int(kin::Status::bad_input), int(obs.configure(c, cfg)));
  cfg = {};
  cfg.threshold[1] = -1;
  LONGS_EQUAL(int(kin::Status::bad_input), int(obs.configure(c, cfg)));
  cfg = {};
  LONGS_EQUAL(int(kin::Status::ok), int(obs.configure(c, cfg)));
  kin::CollisionVerdict v;
  LONGS_EQUAL(int(kin::Status::ok), int(obs.update(z, z, z, 0, v)));  // first sample: dt unused
  LONGS_EQUAL(int(kin::Status::bad_input), int(obs.update(z, z, z, 0, v)));
  LONGS_EQUAL(int(kin::Status::bad_input), int(obs.update(z, nan, z, 1e-3, v)));
  LONGS_EQUAL(int(kin::Status::wrong_size), int(obs.update(z5, z5, z5, 1e-3, v)));
}

// The observer on the simulated arm: 1 ms samples, K = 100 /s. Moving fast (joint speeds up
// to 3.5 rad/s) with no external torque, the residual stays within 1 % of the largest motor
// torque; after a 15 N m step on joint 2 at t = 1 s it follows 15 (1 - exp(-K (t - 1)))
// within 2 % of 15 N m + that bound, the other joints stay near 0, and a 5 N m threshold
// trips on joint 2 (the joint named) in the time the closed form predicts (ln(3/2) / K =
// 4.1 ms, within 2 samples); with sensitivity 0.5 (threshold 10) it takes ln 3 / K.
TEST(Collision, MomentumObserverEstimatesTheExternalTorque) {
  const kin::Chain c = model("puma560");
  const int n = c.n_joints;
  kin::JointVector q0(n);
  q0 << 0.2, -0.6, 0.8, 0.1, -0.7, 0.3;
  for (double sens : {1.0, 0.5}) {
    Sim sim(c, q0);
    kin::CollisionObserver obs;
    kin::CollisionConfig cfg;
    cfg.gain = 100;
    for (int j = 0; j < n; ++j) cfg.threshold[static_cast<std::size_t>(j)] = 5.0;
    cfg.sensitivity = sens;
    LONGS_EQUAL(int(kin::Status::ok), int(obs.configure(c, cfg)));
    const double dt = 1e-3, t_ext = 1.0, ext = 15.0;
    double free_worst = 0, tau_max = 0, follow_worst = 0, others_worst = 0, vmax = 0, tripped = -1;
    int trip_joint = -1;
    for (int k = 0; k < 1300; ++k) {
      const kin::JointVector tau = sim.control();
      kin::CollisionVerdict v;
      LONGS_EQUAL(int(kin::Status::ok), int(obs.update(sim.q, sim.qd, tau, dt, v)));
      const double t = sim.t;
      tau_max = std::max(tau_max, tau.cwiseAbs().maxCoeff());
      vmax = std::max(vmax, sim.qd.cwiseAbs().maxCoeff());
      if (t < t_ext) {
        free_worst = std::max(free_worst, obs.residual().cwiseAbs().maxCoeff());
        if (v.collision) std::printf("\n  false alarm at t %.3f: joint %d residual %.3g\n", t, v.joint + 1, v.residual);
        CHECK(!v.collision);
      } else {
        // The torque applied over the sample that ended at t: the response lags by one sample.
        const double want = t > t_ext ? ext * (1.0 - std::exp(-cfg.gain * (t - t_ext))) : 0.0;
        follow_worst = std::max(follow_worst, std::fabs(obs.residual()[1] - want));
        for (int j = 0; j < n; ++j)
          if (j != 1) others_worst = std::max(others_worst, std::fabs(obs.residual()[j]));
        if (v.collision && tripped < 0) tripped = t - t_ext, trip_joint = v.joint;
      }
      kin::JointVector load = tau;
      if (t >= t_ext) load[1] += ext;  // external torque on joint 2 from t_ext on
      sim.step(load, dt);
    }
    const double bound = 1e-2 * tau_max;
    const double predicted = std::log(ext / (ext - 5.0 / sens)) / cfg.gain;
    std::printf("\n  observer K 100/s sens %.1f: free motion residual <= %.3g N m (motor torque up to %.3g, speed %.2g "
                "rad/s); step 15 N m followed within %.3g, other joints <= %.3g; tripped after %.1f ms on joint %d "
                "(closed form %.1f ms)\n",
                sens, free_worst, tau_max, vmax, follow_worst, others_worst, tripped * 1e3, trip_joint + 1,
                predicted * 1e3);
    CHECK(vmax > 1.5);
    CHECK(free_worst < bound);
    CHECK(follow_worst < 0.02 * ext + bound);
    CHECK(others_worst < 0.02 * ext + bound);
    LONGS_EQUAL(1, trip_joint);
    CHECK(std::fabs(tripped - predicted) <= 2.0 * dt);
  }
}

TEST(Collision, UpdateDoesNotAllocate) {
  const kin::Chain c = model("puma560");
  kin::CollisionObserver obs;
  kin::CollisionConfig cfg;
  cfg.threshold.fill(1.0);
  CHECK(obs.configure(c, cfg) == kin::Status::ok);
  kin::JointVector q = kin::JointVector::Constant(6, 0.3), qd = kin::JointVector::Constant(6, 0.5), tau(6);
  CHECK(kin::gravity_torques(c, q, tau) == kin::Status::ok);
  kin::CollisionVerdict v;
  kin::FeedForward ff;
  std::size_t n = 0;
  {
    AllocScope scope;
    for (int k = 0; k < 100; ++k) {
      q.array() += 1e-4;
      obs.update(q, qd, tau, 1e-3, v);
      kin::feed_forward(c, q, qd, qd, ff);
      kin::free_drive_torque(c, q, qd, tau);
    }
    n = scope.end();
  }
  UNSIGNED_LONGS_EQUAL(0, n);
}
