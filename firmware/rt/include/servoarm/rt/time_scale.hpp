// SPDX-License-Identifier: Apache-2.0
#pragma once
// The run-time speed scale (docs/safety.md#speed-scaling): a factor s in [kMin, 1] on the time of
// the motion being sampled. The trajectory is sampled at tau with dtau/dt = s, so the path is kept
// exactly and every speed along it is s times the planned one; with q' and q'' the trajectory's
// derivatives in tau, the commanded velocity is q' s and the acceleration q'' s^2 + q' ds/dt.
//
// s follows a target (the safety monitor's, set every cycle), ramped:
//  - its rate ds/dt is at most kRate, and at most what the joints' acceleration limits leave at
//    the present sample (rate_bounds: q'' s^2 + q' ds/dt within +-kAccShare of each joint's
//    limit), so that no joint exceeds its acceleration limit while s changes;
//  - the rate itself changes by at most kJerk per second (the ramp is jerk-limited in s), and
//    brakes so that s comes to the target without overshooting it.
// With s = 1, its target 1 and no rate, nothing is scaled (idle(): the sample is the plan's own).
//
// Real-time: plain arithmetic on a small struct, no allocation.
#include <algorithm>
#include <array>
#include <cmath>

#include "servoarm/kinematics/trajectory.hpp"

namespace servoarm::fw {

struct TimeScale {
  static constexpr double kRate = 8.0;       ///< 1/s: at most full speed to 5 % in 0.12 s
  static constexpr double kJerk = 100.0;     ///< 1/s^2: the rate's own change
  static constexpr double kMin = 0.05;       ///< the lowest scale (slower is a protective stop)
  static constexpr double kAccShare = 0.98;  ///< of each joint's acceleration limit while s changes

  double s = 1.0;       ///< the scale now
  double rate = 0.0;    ///< ds/dt (1/s)
  double target = 1.0;  ///< where s goes, in [kMin, 1]
  bool limited = false; ///< the last step would have slowed faster than the joints' acceleration limits let it

  bool idle() const { return s == 1.0 && rate == 0.0 && target == 1.0; }
  void reset() {
    s = 1.0;
    rate = 0.0;
    target = 1.0;
    limited = false;
  }
  void set_target(double t) { target = std::isfinite(t) ? std::clamp(t, kMin, 1.0) : kMin; }

  /// How fast s may fall (`down`) and rise (`up`), both >= 0 (1/s), so that the commanded state
  /// `cmd` (real time: velocity q' s, acceleration q'' s^2 + q' rate) keeps every joint's
  /// acceleration within kAccShare of its limit: per joint, with c = q'' s^2 the planned part,
  /// |c + q' ds/dt| <= a.
  void rate_bounds(const kin::JointLimits& lim, int n, const kin::JointState& cmd, double& down, double& up) const {
    down = up = kRate;
    const double si = 1.0 / s;
    for (int j = 0; j < n; ++j) {
      const double p = cmd.vel[j] * si;               // q'
      const double c = cmd.acc[j] - p * rate;         // q'' s^2
      const double ap = std::fabs(p);
      if (!(ap > 1e-9) || !std::isfinite(c)) continue;
      const double a = kAccShare * lim.dyn[static_cast<std::size_t>(j)].max_acceleration;
      const double sc = p > 0 ? c : -c;  // the planned acceleration along q'
      down = std::fmin(down, std::fmax(0.0, (a + sc) / ap));
      up = std::fmin(up, std::fmax(0.0, (a - sc) / ap));
    }
  }

  /// One period dt: the rate towards the one that brings s to the target without overshoot
  /// (at most kRate, braking at kJerk), changed by at most kJerk dt, within [-down, up].
  void step(double dt, double down, double up) {
    const double e = target - s;
    double want = std::copysign(std::fmin(kRate, std::sqrt(2.0 * kJerk * std::fabs(e))), e);
    limited = want < -down;
    want = std::clamp(want, -down, up);
    rate += std::clamp(want - rate, -kJerk * dt, kJerk * dt);
    rate = std::clamp(rate, -down, up);
    s += rate * dt;
    const double e2 = target - s;
    if (e == 0.0 || e2 == 0.0 || (e > 0) != (e2 > 0)) {  // at the target (or past it): rest there
      s = target;
      rate = 0.0;
    }
    s = std::clamp(s, kMin, 1.0);
  }

  /// The time s takes from `from` to `to` at the nominal limits (kRate, kJerk), from no rate.
  static double ramp_time(double from, double to) {
    const double d = std::fabs(from - to);
    if (d >= kRate * kRate / kJerk) return d / kRate + kRate / kJerk;
    return 2.0 * std::sqrt(d / kJerk);
  }
};

/// The speed caps a jog's or stream's plans are made with (docs/safety.md#speed-scaling): the
/// safety envelope's speed limits turned into joint velocity limits for the planner, so that a
/// re-plan (a new jog target, a streamed target) starts within them instead of speeding up
/// again for the scale to catch. Filled by SafetyMonitor::speed_cap, used by Jogger.
struct SpeedCap {
  std::array<double, kin::kMaxJoints> joint;     ///< per joint: the highest speed a plan may use (rad/s, m/s); INFINITY: none
  std::array<double, kin::kMaxJoints> tcp_gain;  ///< per joint: the TCP's speed per unit joint speed at the pose (m/rad, |linear Jacobian column|)
  std::array<std::array<double, 3>, kin::kMaxJoints> tcp_col;  ///< per joint: the linear Jacobian's column at the pose (m/rad)
  double tcp = INFINITY;                         ///< the TCP speed a plan may reach (m/s)
  SpeedCap() {
    joint.fill(INFINITY);
    tcp_gain.fill(0.0);
    tcp_col.fill({0.0, 0.0, 0.0});
  }
  /// `L`'s velocity limits capped for a plan from `from` towards `goal`, or moving at `qd`
  /// (may be empty): each joint's at its cap, and those of the joints that move (goal, velocity
  /// or qd not zero) lowered together so that the sum of their TCP gains times their limits is
  /// within the TCP cap (the TCP's speed is at most that sum, whatever the direction).
  void apply(kin::JointLimits& L, const kin::JointState& from, const kin::JointVector& goal, const kin::JointVector& qd) const {
    apply_joints(L);
    double sum = 0;
    std::array<bool, kin::kMaxJoints> moves{};
    for (int j = 0; j < L.n && j < kin::kMaxJoints; ++j) {
      const auto u = static_cast<std::size_t>(j);
      moves[u] = goal[j] != from.pos[j] || from.vel[j] != 0.0 || (qd.size() > j && qd[j] != 0.0);
      if (moves[u]) sum += tcp_gain[u] * L.dyn[u].max_velocity;
    }
    if (!(sum > tcp)) return;
    const double f = tcp / sum;
    for (int j = 0; j < L.n && j < kin::kMaxJoints; ++j)
      if (moves[static_cast<std::size_t>(j)]) L.dyn[static_cast<std::size_t>(j)].max_velocity *= f;
  }
  /// `L`'s velocity limits, each within its joint's cap.
  void apply_joints(kin::JointLimits& L) const {
    for (int j = 0; j < L.n && j < kin::kMaxJoints; ++j) {
      double& v = L.dyn[static_cast<std::size_t>(j)].max_velocity;
      v = std::fmin(v, joint[static_cast<std::size_t>(j)]);
    }
  }
  /// The TCP cap of a plan that follows a moving target (a stream), each part along its own
  /// direction with the linear Jacobian's columns at the pose: the target's velocity `v` (joint
  /// speeds) slowed as a whole until its TCP speed |J v| is within `target_share` of the cap;
  /// then the relative (catch-up) limits `rel` lowered together until the catch-up from
  /// `rel_pos` (the arm less the target) straight to the target, at the highest speed they
  /// allow, adds at most the rest of the cap. A target within the cap is followed at its own
  /// speed, not held to the cap spread over every joint's limit at once.
  void apply_moving(kin::JointLimits& rel, kin::JointVector& v, const kin::JointVector& rel_pos, double target_share) const {
    if (!(tcp < INFINITY)) return;
    const int n = static_cast<int>(v.size()) < rel.n ? static_cast<int>(v.size()) : rel.n;
    const double sv = tcp_speed(v, n);
    if (sv > target_share * tcp) {
      const double f = target_share * tcp / sv;
      for (int j = 0; j < n && j < kin::kMaxJoints; ++j) {
        rel.dyn[static_cast<std::size_t>(j)].max_velocity += std::fabs(v[j]) * (1.0 - f);  // the room the target no longer takes
        v[j] *= f;
      }
    }
    // the catch-up at its highest common speed k along -rel_pos
    double k = INFINITY;
    for (int j = 0; j < n && j < kin::kMaxJoints; ++j)
      if (rel_pos[j] != 0.0) k = std::fmin(k, rel.dyn[static_cast<std::size_t>(j)].max_velocity / std::fabs(rel_pos[j]));
    if (!(k < INFINITY)) return;
    const double catch_up = k * tcp_speed(rel_pos, n), room = tcp - std::fmin(sv, target_share * tcp);
    if (!(catch_up > room)) return;
    const double g = room / catch_up;
    for (int j = 0; j < n && j < kin::kMaxJoints; ++j) rel.dyn[static_cast<std::size_t>(j)].max_velocity *= g;
  }
  /// |J q̇|: the TCP's speed of joint speeds `qd` at the pose (m/s).
  double tcp_speed(const kin::JointVector& qd, int n) const {
    double t[3] = {0, 0, 0};
    for (int j = 0; j < n && j < kin::kMaxJoints; ++j)
      for (std::size_t a = 0; a < 3; ++a) t[a] += tcp_col[static_cast<std::size_t>(j)][a] * qd[j];
    return std::sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]);
  }
};

}  // namespace servoarm::fw
