// SPDX-License-Identifier: Apache-2.0
// The arm's ServoBus over drive groups (arm_servo_bus.hpp).
#include "servoarm/hal/arm_servo_bus.hpp"

#include <cmath>
#include <cstdio>
#include <limits>
#include <utility>

namespace servoarm::hal {

Status ArmServoBus::add_group(std::unique_ptr<DriveGroup> group, std::span<const std::size_t> arm_joints) {
  if (!group || arm_joints.size() != group->joint_count() || arm_joints.empty()) {
    std::snprintf(error_, sizeof error_, "drive group %zu: %zu arm joints for %zu drives", groups_n_, arm_joints.size(),
                  group ? group->joint_count() : std::size_t(0));
    return Status::invalid_argument;
  }
  if (groups_n_ >= kMaxServoJoints) {
    std::snprintf(error_, sizeof error_, "more than %zu drive groups", kMaxServoJoints);
    return Status::capacity;
  }
  for (std::size_t k = 0; k < arm_joints.size(); ++k) {
    const std::size_t j = arm_joints[k];
    if (j >= kMaxServoJoints) {
      std::snprintf(error_, sizeof error_, "drive group %zu: joint %zu beyond %zu joints", groups_n_, j, kMaxServoJoints);
      return Status::capacity;
    }
    if (mapped_[j]) {
      std::snprintf(error_, sizeof error_, "drive group %zu: joint %zu has a drive group already", groups_n_, j);
      return Status::invalid_argument;
    }
  }
  for (std::size_t k = 0; k < arm_joints.size(); ++k) {
    const std::size_t j = arm_joints[k];
    mapped_[j] = true;
    slot_[j] = Slot{std::uint8_t(groups_n_), std::uint8_t(k)};
    grp_[j] = group.get();
    kind_[j] = group->homing_kind(k);  // a group's homing is configured when it is made
    fb_[j] = &group->feedback(k);
    if (j + 1 > joints_n_) joints_n_ = j + 1;
  }
  identity_ = groups_n_ == 0;
  for (std::size_t k = 0; identity_ && k < arm_joints.size(); ++k) identity_ = arm_joints[k] == k;
  group->number_joints(arm_joints);  // its messages name the arm's joints
  groups_[groups_n_++] = std::move(group);
  return Status::ok;
}

Status ArmServoBus::config_status() const {
  if (joints_n_ == 0) return Status::invalid_argument;
  for (std::size_t j = 0; j < joints_n_; ++j)
    if (!mapped_[j]) return Status::invalid_argument;
  for (std::size_t g = 0; g < groups_n_; ++g)
    if (const Status s = groups_[g]->config_status(); s != Status::ok) return s;
  return Status::ok;
}

Status ArmServoBus::start(TimePoint deadline) {
  start_error_ = nullptr;
  for (std::size_t g = 0; g < groups_n_; ++g) {
    const Status s = groups_[g]->start(deadline);
    if (s != Status::ok) {
      start_error_ = groups_[g]->last_error();
      return s;
    }
  }
  return Status::ok;
}

void ArmServoBus::enable() {
  for (std::size_t g = 0; g < groups_n_; ++g) groups_[g]->enable();
}
void ArmServoBus::disable() {
  for (std::size_t g = 0; g < groups_n_; ++g) groups_[g]->disable();
}
void ArmServoBus::quick_stop() {
  for (std::size_t g = 0; g < groups_n_; ++g) groups_[g]->quick_stop();
}
bool ArmServoBus::quick_stop_holds() const {
  for (std::size_t g = 0; g < groups_n_; ++g)
    if (groups_[g]->quick_stop_holds()) return true;
  return false;
}
bool ArmServoBus::holding(std::size_t j) const { return ours(j) && sub(j).holding(slot(j).local); }
void ArmServoBus::disable_joint(std::size_t j) {
  if (ours(j)) sub(j).disable_joint(slot(j).local);
}

Status ArmServoBus::read(TimePoint now) {
  Status result = Status::ok;
  for (std::size_t g = 0; g < groups_n_; ++g) {
    const Status s = groups_[g]->read(now);
    if (result == Status::ok) result = s;
  }
  return result;
}

Status ArmServoBus::write(std::span<const double> setpoints, TimePoint now) {
  if (identity_ && groups_n_ == 1) return groups_[0]->write(setpoints, now);  // one group: the arm's own order
  Status result = setpoints.size() == joints_n_ ? Status::ok : Status::invalid_argument;
  for (std::size_t j = 0; j < joints_n_; ++j)  // a joint without a setpoint gets NaN: its drive holds
    sp_[slot_[j].group][slot_[j].local] = j < setpoints.size() ? setpoints[j] : std::numeric_limits<double>::quiet_NaN();
  for (std::size_t g = 0; g < groups_n_; ++g) {
    DriveGroup& grp = *groups_[g];
    const Status s = grp.write(std::span<const double>(sp_[g].data(), grp.joint_count()), now);
    if (result == Status::ok) result = s;
  }
  return result;
}

Status ArmServoBus::set_position_zero(std::size_t j) {
  return ours(j) ? sub(j).set_position_zero(slot(j).local) : Status::invalid_argument;
}
std::int64_t ArmServoBus::zero_offset(std::size_t j) const { return ours(j) ? sub(j).zero_offset(slot(j).local) : 0; }
Status ArmServoBus::start_homing(std::size_t j, TimePoint now) {
  return ours(j) ? sub(j).start_homing(slot(j).local, now) : Status::invalid_argument;
}
void ArmServoBus::abort_homing(std::size_t j) {
  if (ours(j)) sub(j).abort_homing(slot(j).local);
}
HomingProgress ArmServoBus::homing(std::size_t j) const {
  return ours(j) ? sub(j).homing(slot(j).local) : HomingProgress{HomingPhase::idle, Status::invalid_argument, 0};
}
void ArmServoBus::describe_homing(std::size_t j, char* buf, std::size_t size) const {
  if (ours(j)) sub(j).describe_homing(slot(j).local, buf, size);
  else if (size > 0) buf[0] = '\0';
}
HomingKind ArmServoBus::homing_kind(std::size_t j) const { return ours(j) ? kind_[j] : HomingKind::none; }
JointCapabilities ArmServoBus::capabilities(std::size_t j) const {
  return ours(j) ? sub(j).capabilities(slot(j).local) : JointCapabilities{};
}
Status ArmServoBus::set_feed_forward(std::size_t j, double velocity, double torque) {
  return ours(j) ? sub(j).set_feed_forward(slot(j).local, velocity, torque) : Status::invalid_argument;
}
Status ArmServoBus::set_torque_damping(std::size_t j, double damping) {
  return ours(j) ? sub(j).set_torque_damping(slot(j).local, damping) : Status::invalid_argument;
}
Status ArmServoBus::set_target_torque(std::size_t j, double torque) {
  return ours(j) ? sub(j).set_target_torque(slot(j).local, torque) : Status::invalid_argument;
}
Status ArmServoBus::set_torque_mode(std::size_t j, bool on) {
  return ours(j) ? sub(j).set_torque_mode(slot(j).local, on) : Status::invalid_argument;
}
CyclicModeState ArmServoBus::cyclic_mode(std::size_t j) const {
  return ours(j) ? sub(j).cyclic_mode(slot(j).local) : CyclicModeState{};
}
Status ArmServoBus::set_digital_outputs(std::size_t j, std::uint32_t value) {
  return ours(j) ? sub(j).set_digital_outputs(slot(j).local, value) : Status::invalid_argument;
}
std::uint32_t ArmServoBus::digital_outputs(std::size_t j) const {
  return ours(j) ? sub(j).digital_outputs(slot(j).local) : 0;
}
const JointFeedback& ArmServoBus::feedback(std::size_t j) const {
  return ours(j) ? *fb_[j] : none_;
}

const char* ArmServoBus::last_error() const {
  if (start_error_ != nullptr) return start_error_;
  if (error_[0] != '\0') return error_;
  for (std::size_t g = 0; g < groups_n_; ++g)
    if (const char* e = groups_[g]->last_error(); e != nullptr && e[0] != '\0') return e;
  return "";
}

}  // namespace servoarm::hal
