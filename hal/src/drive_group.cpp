// SPDX-License-Identifier: Apache-2.0
// The group base: hard-stop homing around any family's read/write (drive_group.hpp).
#include "servoarm/hal/drive_group.hpp"

#include <algorithm>
#include <cstdio>

namespace servoarm::hal {

void DriveGroup::joint_name(std::size_t j, char* buf, std::size_t size) const {
  if (size > 0) std::snprintf(buf, size, "joint %zu", arm_joint(j));
}

HomingKind DriveGroup::kind_before_start(std::size_t j) const {
  return j < joint_count() && j < kMaxServoJoints ? homing_spec(j).kind : HomingKind::none;
}

HomingProgress DriveGroup::homing_before_start(std::size_t j) const {
  if (j >= joint_count() || j >= kMaxServoJoints) return {HomingPhase::idle, Status::invalid_argument, 0};
  return homing_spec(j).kind == HomingKind::hard_stop ? hard_stop_[j].progress() : family_homing(j);
}

bool DriveGroup::hard_stop_active() const {
  for (std::size_t j = 0; j < n_; ++j)
    if (hard_stop_[j].running() || hard_stop_[j].holding()) return true;
  return false;
}

Status DriveGroup::start(TimePoint deadline) {
  for (auto& h : hard_stop_) h.reset();  // a zero lasts one power cycle
  last_setpoint_.fill(0);
  active_ = false;
  n_ = joint_count() < kMaxServoJoints ? joint_count() : kMaxServoJoints;
  for (std::size_t j = 0; j < n_; ++j) kind_[j] = homing_spec(j).kind;
  started_ = true;
  return family_start(deadline);
}

Status DriveGroup::read(TimePoint now) {
  const Status s = family_read(now);
  if (!active_) return s;
  for (std::size_t j = 0; j < n_; ++j) {
    HardStopHoming& h = hard_stop_[j];
    if (!h.running()) continue;
    char name[64];
    joint_name(j, name, sizeof name);
    const HomingSpec& spec = homing_spec(j);
    switch (h.advance(spec, feedback(j), now, name, resolution(j), scaling(j).kind == JointScaling::Kind::prismatic)) {
      case HardStopHoming::Event::none: break;
      case HardStopHoming::Event::settled: h.finish_settled(shift_zero(j, h.settle_at(), spec.offset), now); break;
      case HardStopHoming::Event::failed: note_error(h.message()); break;
    }
  }
  return s;
}

Status DriveGroup::write(std::span<const double> setpoints, TimePoint now) {
  const std::size_t n = setpoints.size();
  if (!started_ || n != n_) return family_write(setpoints, now);  // the family refuses it
  std::copy(setpoints.begin(), setpoints.end(), last_setpoint_.begin());  // where a homing's ramp starts
  if (!active_) return family_write(setpoints, now);
  for (std::size_t j = 0; j < n; ++j) {
    double sp = setpoints[j];
    HardStopHoming& h = hard_stop_[j];
    if (h.take_hold(sp)) {
      // homing ended in this cycle's read(): the caller's setpoint is in the old coordinates
    } else if (h.running()) {
      const JointFeedback& fb = feedback(j);
      sp = h.setpoint(homing_spec(j), fb.state == JointState::enabled, fb.position, now);
    }
    sp_[j] = sp;
    last_setpoint_[j] = sp;
  }
  active_ = hard_stop_active();
  return family_write(std::span<const double>(sp_.data(), n), now);
}

Status DriveGroup::start_homing(std::size_t j, TimePoint now) {
  if (j >= joint_count() || j >= kMaxServoJoints) return Status::invalid_argument;
  if (homing_kind(j) != HomingKind::hard_stop || !started_) return family_start_homing(j, now);
  const JointFeedback& fb = feedback(j);
  if (hard_stop_[j].running() || fb.state != JointState::enabled) return Status::bad_state;
  hard_stop_[j].start(last_setpoint_[j], fb.position, now);
  active_ = true;
  return Status::ok;
}

void DriveGroup::abort_homing(std::size_t j) {
  if (j >= joint_count() || j >= kMaxServoJoints) return;
  if (homing_kind(j) == HomingKind::hard_stop) hard_stop_[j].abort();
  else family_abort_homing(j);
}

void DriveGroup::describe_homing(std::size_t j, char* buf, std::size_t size) const {
  if (size == 0) return;
  buf[0] = '\0';
  if (j >= joint_count() || j >= kMaxServoJoints) return;
  if (homing_kind(j) == HomingKind::hard_stop) std::snprintf(buf, size, "%s", hard_stop_[j].message());
  else family_describe_homing(j, buf, size);
}

Status DriveGroup::set_feed_forward(std::size_t j, double velocity, double torque) {
  if (j < kMaxServoJoints && hard_stop_[j].running()) return Status::ok;  // no offsets while homing
  return family_set_feed_forward(j, velocity, torque);
}

Status DriveGroup::set_torque_mode(std::size_t j, bool on) {
  if (on && j < kMaxServoJoints && hard_stop_[j].running()) return Status::bad_state;
  return family_set_torque_mode(j, on);
}

}  // namespace servoarm::hal
