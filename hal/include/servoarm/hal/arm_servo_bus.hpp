// SPDX-License-Identifier: Apache-2.0
#pragma once
// The arm's ServoBus over drive groups (docs/servo-bus.md#drive-families-groups-and-the-arm):
// each group (drive_group.hpp) is one family's joints on one bus; arm joint j is local joint
// slot(j).local of group slot(j).group. The controller drives this one joint-indexed ServoBus
// whatever families and buses are under it. read()/write() and the per-joint calls are real
// time: fixed arrays, one virtual call per group (read, write) or per call (the joint's group),
// no allocation, lock, throw or blocking. Groups are added at set-up.
#include <array>
#include <cstdint>
#include <memory>
#include <span>

#include "servoarm/hal/drive_group.hpp"

namespace servoarm::hal {

class ArmServoBus final : public ServoBus {
 public:
  struct Slot {
    std::uint8_t group = 0;
    std::uint8_t local = 0;
  };

  /// Set-up: adds `group`, whose local joint k is arm joint arm_joints[k]. capacity (more than
  /// kMaxServoJoints groups or joints), invalid_argument (a joint given twice, or as many arm
  /// joints as the group has joints not given); last_error() says which.
  Status add_group(std::unique_ptr<DriveGroup> group, std::span<const std::size_t> arm_joints);
  /// ok once arm joints 0..joint_count()-1 each have a group, else invalid_argument.
  Status config_status() const;

  std::size_t group_count() const { return groups_n_; }
  DriveGroup& group(std::size_t g) { return *groups_[g]; }
  const DriveGroup& group(std::size_t g) const { return *groups_[g]; }
  Slot slot(std::size_t j) const { return slot_[j < kMaxServoJoints ? j : 0]; }
  /// Joint j's group's conversion between drive units and the joint (a simulator needs it).
  JointScaling scaling(std::size_t j) const { return sub(j).scaling(slot(j).local); }
  /// Joint j's rated torque, joint side (N m or N); 0 = unknown.
  double rated_torque(std::size_t j) const { return sub(j).rated_torque(slot(j).local); }

  std::size_t joint_count() const override { return joints_n_; }
  /// Starts the groups in order; the first that fails ends it (last_error() is its message).
  Status start(TimePoint deadline) override;
  void enable() override;
  void disable() override;
  void quick_stop() override;
  /// True when a group holds after quick_stop() (an MIT group).
  bool quick_stop_holds() const override;
  bool holding(std::size_t j) const override;
  /// Joint j's group powers it down (an MIT group that joint alone, a CiA 402 group all its drives).
  void disable_joint(std::size_t j) override;
  /// Every group's read(); the first group status that is not ok.
  Status read(TimePoint now) override;
  /// Each group's setpoints from the arm's; the first group status that is not ok.
  Status write(std::span<const double> setpoints, TimePoint now) override;
  Status set_position_zero(std::size_t j) override;
  std::int64_t zero_offset(std::size_t j) const override;
  Status start_homing(std::size_t j, TimePoint now) override;
  void abort_homing(std::size_t j) override;
  HomingProgress homing(std::size_t j) const override;
  void describe_homing(std::size_t j, char* buf, std::size_t size) const override;
  HomingKind homing_kind(std::size_t j) const override;
  JointCapabilities capabilities(std::size_t j) const override;
  Status set_feed_forward(std::size_t j, double velocity, double torque) override;
  Status set_target_torque(std::size_t j, double torque) override;
  Status set_torque_damping(std::size_t j, double damping) override;
  Status set_torque_mode(std::size_t j, bool on) override;
  CyclicModeState cyclic_mode(std::size_t j) const override;
  Status set_digital_outputs(std::size_t j, std::uint32_t value) override;
  std::uint32_t digital_outputs(std::size_t j) const override;
  const JointFeedback& feedback(std::size_t j) const override;
  /// The message of the failed start(), else the first group's that has one ("" if none).
  const char* last_error() const override;

 private:
  bool ours(std::size_t j) const { return j < joints_n_; }
  DriveGroup& sub(std::size_t j) { return *grp_[j]; }
  const DriveGroup& sub(std::size_t j) const { return *grp_[j]; }

  std::array<std::unique_ptr<DriveGroup>, kMaxServoJoints> groups_{};
  std::size_t groups_n_ = 0;
  std::array<Slot, kMaxServoJoints> slot_{};
  // Per arm joint, so that a call costs one lookup: its group, its feedback (a group's feedback
  // stays at one address), and whether the arm is one group with joint j = local joint j.
  std::array<DriveGroup*, kMaxServoJoints> grp_{};
  std::array<const JointFeedback*, kMaxServoJoints> fb_{};
  std::array<HomingKind, kMaxServoJoints> kind_{};  ///< each joint's homing kind, fixed by its group
  bool identity_ = false;
  std::array<bool, kMaxServoJoints> mapped_{};
  std::size_t joints_n_ = 0;
  std::array<std::array<double, kMaxServoJoints>, kMaxServoJoints> sp_{};  ///< per group, per local joint
  JointFeedback none_{};
  const char* start_error_ = nullptr;
  char error_[96] = {};
};

}  // namespace servoarm::hal
