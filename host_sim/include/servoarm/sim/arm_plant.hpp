// SPDX-License-Identifier: Apache-2.0
#pragma once
// ArmPlant: the virtual drives of one arm on a shared rigid-body plant ("a
// virtual arm with physics"). Each drive closes its own loops like a real CSP drive
// (position loop P, velocity loop PI, torque limit, the CSP offsets 60B1h/60B2h) and
// commands a joint torque; the arm's forward dynamics (kinematics' dynamics.hpp: mass
// matrix by composite rigid body, c + g by Newton-Euler) with gravity, friction,
// holding brakes, an optional external force and an optional rigid stop are integrated
// with classical Runge-Kutta 4 at a fixed step (default 100 us = 10 kHz), the drives'
// torques held over each step (their loop rate). Each drive reports position 6064h,
// velocity 606Ch and its torque 6077h from the plant.
//
// Set-up: configure() (allocates nothing after it, throws nothing). The stepping is
// heap-free (fixed-size Eigen, bounded loops).
#include <array>
#include <cstdint>
#include <span>
#include <string>

#include "servoarm/hal/can_bus.hpp"
#include "servoarm/hal/scaling.hpp"
#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/dynamics.hpp"

namespace servoarm::sim {

class VirtualDrive;

/// One drive's servo loop, joint side (like a drive's gains, scaled by the gear ratio
/// squared from the motor side). 0 = chosen by configure() from the model (see auto_*).
struct ServoGains {
  double kp = 0;            ///< 1/s, position loop: velocity demand = kp (target - q) + 60B1h
  double kv = 0;            ///< N m s/rad (N s/m), velocity loop proportional gain
  double ki = 0;            ///< 1/s, velocity loop integral (torque += kv ki integral of the error); 0 = off
  double torque_limit = 0;  ///< N m (N), peak torque the drive commands
};

/// A rigid stop of one joint (joint space): the joint cannot pass `position` in the
/// direction `side` (+1: blocks q > position, -1: blocks q < position). A stiff
/// spring-damper contact (penalty method), stiffness and damping from the model unless given.
struct JointStop {
  int joint = -1;           ///< -1 = none
  double position = 0;      ///< rad (m)
  int side = 1;
  double stiffness = 0;     ///< N m/rad; 0 = (2 pi 200 Hz)^2 x the joint's largest inertia
  double damping = 0;       ///< N m s/rad; 0 = critical for that inertia / 2 (zeta 0.5)
};

struct ArmPlantParams {
  hal::Duration step = 100 * hal::kMicrosecond;  ///< RK4 step = the drives' loop period
  /// Auto gains: velocity loop bandwidth (kv = 2 pi f x the joint's largest inertia over
  /// the workspace) and position loop kp = 2 pi f / 4 (damping ratio about 1).
  double velocity_bandwidth_hz = 40;
  /// Auto torque limit: 2 x (largest gravity torque + largest inertia x this acceleration,
  /// or the joint's max_acceleration from the description when it is larger).
  double sizing_acceleration = 10;  ///< rad/s^2 (m/s^2)
  std::array<ServoGains, kin::kMaxJoints> gains{};
  /// Friction on top of the description's (viscous N m s/rad, Coulomb N m). Coulomb
  /// friction is smoothed: coulomb x tanh(qd / coulomb_velocity).
  std::array<double, kin::kMaxJoints> extra_viscous{};
  std::array<double, kin::kMaxJoints> extra_coulomb{};
  double coulomb_velocity = 0.01;  ///< rad/s (m/s)
  /// Holding brakes: a joint whose drive is not powered (not operation enabled, not quick
  /// stop active) is locked where it is (its velocity set to 0), as on most arms.
  /// false: an unpowered joint swings freely.
  bool brakes = true;
  bool gravity = true;             ///< false: the description's gravity is ignored
  JointStop stop{};
  /// Constant external load: a force at the tool point in the world frame (N), and
  /// joint torques (N m / N). Applied as tau_ext = J^T f + external_torque.
  Eigen::Vector3d tool_force = Eigen::Vector3d::Zero();
  std::array<double, kin::kMaxJoints> external_torque{};
  /// Scripted external load, on top of the constant one: each push is a joint torque
  /// amplitude x sin(2 pi frequency t + phase) from the plant's start (t = 0) on, a hand moving
  /// an arm in free-drive (a teleoperation leader), t in s from the plant's first advance().
  /// Pushes on the same joint add up.
  struct Push {
    int joint = -1;          ///< -1 = none
    double amplitude = 0;    ///< N m (N)
    double frequency = 0;    ///< Hz; 0 = constant
    double phase = 0;        ///< rad
  };
  static constexpr std::size_t kMaxPushes = 8;
  std::array<Push, kMaxPushes> pushes{};
};

/// Per joint: the figures configure() chose (tests, armsim --verbose, docs).
struct ArmPlantJointInfo {
  ServoGains gains;
  double max_inertia = 0;   ///< largest M_jj over the sampled workspace (kg m^2 / kg)
  double max_gravity = 0;   ///< largest |g_j| over the sampled workspace
  double rated_torque_mnm = 0;  ///< 6076h: torque_limit / 3, motor side (/ gear ratio), mN m
  double stop_stiffness = 0, stop_damping = 0;
};

class ArmPlant {
 public:
  /// Set-up: the chain must carry inertial data. `scaling[j]` converts drive j's counts to
  /// joint j (the firmware's JointScaling). "" or the reason (names the model/joint).
  std::string configure(const kin::Chain& chain, std::span<const hal::JointScaling> scaling,
                        const ArmPlantParams& params);
  /// Set-up: attach the drive of joint j (after configure). The plant's state starts at the
  /// drives' positions.
  void attach(int j, VirtualDrive* drive);

  /// Advance every attached drive's loop and the dynamics to `now` (whole steps). Called by
  /// any drive's tick/SYNC; re-entrant calls and times already reached return at once.
  void advance(hal::TimePoint now, hal::CanBus& bus);
  /// The time up to `now` passes without motion (ArmSim::skip_to): the state stays, the
  /// clock moves on.
  void skip_to(hal::TimePoint now) {
    if (now > t_) t_ = now;
  }

  int joints() const { return n_; }
  const kin::JointVector& q() const { return q_; }
  const kin::JointVector& qd() const { return qd_; }
  /// Torques of the last step: the drives' commands, and the stop's contact torque.
  const kin::JointVector& motor_torque() const { return tau_motor_; }
  const kin::JointVector& contact_torque() const { return tau_contact_; }
  const ArmPlantJointInfo& info(int j) const { return info_[static_cast<std::size_t>(j)]; }
  const hal::JointScaling& scaling(int j) const { return scaling_[static_cast<std::size_t>(j)]; }
  const ArmPlantParams& params() const { return params_; }
  ArmPlantParams& params() { return params_; }  ///< change the load or the stop between steps
  const kin::Chain& chain() const { return chain_; }
  hal::TimePoint time() const { return t_; }
  /// Kinetic energy 1/2 qd^T M qd (rotors included), J.
  double kinetic_energy() const;
  /// Set the state (tests): positions and velocities, joint units.
  void set_state(const kin::JointVector& q, const kin::JointVector& qd);
  std::uint64_t steps() const { return steps_; }

 private:
  /// qdd from the state and the held torques (brakes, friction, stop, external load).
  void acceleration(const kin::JointVector& q, const kin::JointVector& qd, kin::JointVector& qdd);
  bool locked(int j) const { return locked_[static_cast<std::size_t>(j)]; }

  kin::Chain chain_;  ///< the description's, friction removed (the plant applies its own)
  std::array<double, kin::kMaxJoints> viscous_{}, coulomb_{};
  std::array<hal::JointScaling, kin::kMaxJoints> scaling_{};
  std::array<ArmPlantJointInfo, kin::kMaxJoints> info_{};
  std::array<VirtualDrive*, kin::kMaxJoints> drives_{};
  std::array<bool, kin::kMaxJoints> locked_{};
  ArmPlantParams params_;
  int n_ = 0;
  bool configured_ = false, busy_ = false, started_ = false;
  hal::TimePoint t_ = 0;
  hal::TimePoint t0_ = -1;  ///< the first advance(): t = 0 of the pushes
  std::uint64_t steps_ = 0;
  kin::JointVector q_, qd_, tau_motor_, tau_ext_, tau_contact_;
};

/// Set-up helper: gains/limits as configure() would choose them (sampled workspace).
/// Exposed for docs and tests.
void auto_size(const kin::Chain& chain, const ArmPlantParams& params, std::array<ArmPlantJointInfo, kin::kMaxJoints>& out);

}  // namespace servoarm::sim
