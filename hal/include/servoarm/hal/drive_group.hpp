// SPDX-License-Identifier: Apache-2.0
#pragma once
// One drive family's joints on one bus (docs/servo-bus.md#drive-families-groups-and-the-arm):
// a ServoBus over the group's own joints (local indices 0..joint_count()-1) plus what set-up
// code asks of any family. A family implements the family_* calls and the queries below; the
// protocol's vocabulary (controlwords, PDOs, MIT fields) stays inside it. The group base runs
// what is drive-neutral for every family: hard-stop homing (hard_stop_homing.hpp), which needs
// only feedback and position setpoints. ArmServoBus (arm_servo_bus.hpp) puts groups together
// into the joint-indexed ServoBus the controller drives.
#include <array>
#include <cstddef>
#include <span>

#include "servoarm/hal/hard_stop_homing.hpp"
#include "servoarm/hal/scaling.hpp"
#include "servoarm/hal/servo_bus.hpp"

namespace servoarm::hal {

class DriveGroup : public ServoBus {
 public:
  DriveGroup() {
    for (std::size_t j = 0; j < kMaxServoJoints; ++j) arm_number_[j] = j;
  }
  /// Set-up: the arm's number of each local joint, for messages ("joint 3 (node 4)" for the
  /// first joint of a group that drives arm joints 3..5). ArmServoBus::add_group sets it;
  /// until then a joint is named by its local index.
  void number_joints(std::span<const std::size_t> arm_joints) {
    for (std::size_t k = 0; k < arm_joints.size() && k < kMaxServoJoints; ++k) arm_number_[k] = arm_joints[k];
  }
  /// The arm's number of local joint j.
  std::size_t arm_joint(std::size_t j) const { return j < kMaxServoJoints ? arm_number_[j] : j; }

  // --- ServoBus calls the group base takes part in (hard-stop homing) ------------------
  Status start(TimePoint deadline) final;
  Status read(TimePoint now) final;
  Status write(std::span<const double> setpoints, TimePoint now) final;
  Status start_homing(std::size_t j, TimePoint now) final;
  void abort_homing(std::size_t j) final;
  HomingProgress homing(std::size_t j) const final {
    if (!started_) return homing_before_start(j);
    if (j >= n_) return {HomingPhase::idle, Status::invalid_argument, 0};
    switch (kind_[j]) {
      case HomingKind::none: return {HomingPhase::attained, Status::ok, 0};  // absolute: homed at once
      case HomingKind::hard_stop: return hard_stop_[j].progress();
      case HomingKind::cia402: break;
    }
    return family_homing(j);
  }
  void describe_homing(std::size_t j, char* buf, std::size_t size) const final;
  HomingKind homing_kind(std::size_t j) const final {
    if (!started_) return kind_before_start(j);
    return j < n_ ? kind_[j] : HomingKind::none;
  }
  /// Dropped (ok) while joint j homes by hard stop: the homing, not the caller, moves it.
  Status set_feed_forward(std::size_t j, double velocity, double torque) final;
  /// On: bad_state while joint j homes by hard stop.
  /// (feedback(j) must return a reference that stays at one address for the group's lifetime:
  /// ArmServoBus keeps it.)
  Status set_torque_mode(std::size_t j, bool on) final;

  // --- Set-up queries every family answers ---------------------------------------------
  /// The family's name as the configuration writes it ("cia402").
  virtual const char* family() const = 0;
  /// ok, or why the configuration was refused (last_error() says more).
  virtual Status config_status() const = 0;
  /// Joint j's conversion between drive units and the joint (what a simulator needs).
  virtual JointScaling scaling(std::size_t j) const = 0;
  /// Joint j's rated torque, joint side, N m (N), as brought up; 0 = unknown / not used.
  virtual double rated_torque(std::size_t j) const {
    (void)j;
    return 0;
  }
  /// One name for joint j in messages, with its arm number ("joint 1 (node 2)"; default "joint 1").
  virtual void joint_name(std::size_t j, char* buf, std::size_t size) const;

 protected:
  /// Joint j's homing as configured.
  virtual const HomingSpec& homing_spec(std::size_t j) const = 0;
  virtual Status family_start(TimePoint deadline) = 0;
  virtual Status family_read(TimePoint now) = 0;
  virtual Status family_write(std::span<const double> setpoints, TimePoint now) = 0;
  /// The family's own homing methods (kinds other than none and hard_stop).
  virtual Status family_start_homing(std::size_t j, TimePoint now) {
    (void)j;
    (void)now;
    return Status::not_supported;
  }
  virtual void family_abort_homing(std::size_t j) { (void)j; }
  virtual HomingProgress family_homing(std::size_t j) const {
    (void)j;
    return {HomingPhase::attained, Status::ok, 0};
  }
  virtual void family_describe_homing(std::size_t j, char* buf, std::size_t size) const {
    (void)j;
    if (size > 0) buf[0] = '\0';
  }
  virtual Status family_set_feed_forward(std::size_t j, double velocity, double torque) {
    (void)j;
    (void)velocity;
    (void)torque;
    return Status::not_supported;
  }
  virtual Status family_set_torque_mode(std::size_t j, bool on) {
    (void)j;
    return on ? Status::not_supported : Status::ok;
  }
  /// Real time: from now on joint j's present coordinate `at` reads `reads` (the family moves its
  /// own zero; nothing is written to the drive), and its feedback says so at once. Returns the
  /// new coordinate of `at` as the drive's resolution gives it.
  virtual double shift_zero(std::size_t j, double at, double reads) = 0;
  /// Joint j's position resolution (joint units per drive count).
  virtual double resolution(std::size_t j) const = 0;
  /// Real time: the group's last_error() from now on (a homing failure).
  virtual void note_error(const char* text) = 0;

 private:
  HomingKind kind_before_start(std::size_t j) const;
  HomingProgress homing_before_start(std::size_t j) const;
  /// Real time: true while a joint homes by hard stop or holds after it (write() substitutes).
  bool hard_stop_active() const;

  std::array<std::size_t, kMaxServoJoints> arm_number_{};
  // Set by start() (what the cycle asks every time, without a virtual call): joint count and kinds.
  bool started_ = false;
  std::size_t n_ = 0;
  std::array<HomingKind, kMaxServoJoints> kind_{};
  bool active_ = false;  ///< a hard-stop homing runs or holds (write()/read() have work to do)
  std::array<HardStopHoming, kMaxServoJoints> hard_stop_{};
  std::array<double, kMaxServoJoints> last_setpoint_{};
  std::array<double, kMaxServoJoints> sp_{};
};

}  // namespace servoarm::hal
