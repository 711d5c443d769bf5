// SPDX-License-Identifier: Apache-2.0
#pragma once
// Hard-stop homing, drive-neutral (docs/servo-bus.md#homing): one joint is moved in cyclic
// position mode on an acceleration-limited ramp at HomingSpec::speed_switch (its sign is the
// direction) until |setpoint - position| > following_limit or, with measured torque and
// torque_limit > 0, |torque| > torque_limit; the demand then goes to where the joint stands,
// the joint backs off by `backoff` on the same ramp, settles (within 1.5 position resolutions,
// or 0.5 s) and the family moves its zero so that the joint reads `offset` there.
// It needs only the joint's feedback (position, torque, state) and sends only position
// setpoints, so DriveGroup runs it for every family. Real time: no allocation, lock, throw
// or blocking.
#include <cstddef>
#include <cstdint>

#include "servoarm/hal/servo_bus.hpp"

namespace servoarm::hal {

class HardStopHoming {
 public:
  /// HomingProgress::step values while hard-stop homing runs (and `done` once it ended).
  enum Step : std::uint8_t { done = 15, approach = 20, backoff = 21, settle = 22 };
  static const char* step_name(std::uint8_t step);

  /// What advance() asks its caller to do.
  enum class Event : std::uint8_t {
    none,     ///< keep going
    settled,  ///< move the zero: the position settle_at() (present coordinates) reads spec.offset
    failed,   ///< ended without a zero: message() says why; the joint holds where it stands
  };

  /// Start: `from` is the setpoint the joint last had (the ramp starts there), `position` where
  /// it stands (the travel is counted from there).
  void start(double from, double position, TimePoint now);
  void abort() { abort_ = phase_ == HomingPhase::running; }
  /// After ServoBus::start(): unhomed again.
  void reset() { *this = HardStopHoming{}; }

  /// Real time, after the family's read(): `fb` is the joint's fresh feedback, `name` names it in
  /// messages ("joint 1 (node 2)"), `resolution` is its position quantum (rad or m per count),
  /// `prismatic` picks mm over deg in the travel message.
  Event advance(const HomingSpec& spec, const JointFeedback& fb, TimePoint now, const char* name, double resolution,
                bool prismatic);
  /// After Event::settled: the family moved its zero; `reads` is the backed-off point's position
  /// in the new coordinates, which the joint holds.
  void finish_settled(double reads, TimePoint now);
  /// Real time, in write(): the setpoint for this joint (ramp while following, else `fallback`).
  double setpoint(const HomingSpec& spec, bool following, double fallback, TimePoint now);

  bool running() const { return phase_ == HomingPhase::running; }
  /// The next write() holds where the homing ended (take_hold() not called yet).
  bool holding() const { return hold_once_; }
  /// The write() after the homing ended holds the position it ended at (the caller's setpoint of
  /// that cycle was computed in the old coordinates); true once, then false.
  bool take_hold(double& hold) {
    if (!hold_once_) return false;
    hold_once_ = false;
    hold = hold_;
    return true;
  }
  HomingProgress progress() const { return {phase_, status_, step_}; }
  const char* message() const { return msg_; }
  double settle_at() const { return goal_; }

 private:
  void step_to(std::uint8_t s, TimePoint now);
  Event fail(Status why, const HomingSpec& spec, const JointFeedback& fb, TimePoint now, const char* name);
  bool travel_exceeded(const HomingSpec& spec, const JointFeedback& fb, const char* name, bool prismatic);

  HomingPhase phase_ = HomingPhase::idle;
  Status status_ = Status::ok;
  std::uint8_t step_ = 0;
  bool abort_ = false;
  bool hold_once_ = false;
  double hold_ = 0;
  TimePoint started_ = 0, step_since_ = 0, last_ = 0, last_sample_ = 0;
  int samples_ = 0;     ///< fresh feedback samples since the step began
  double demand_ = 0, v_ = 0, goal_ = 0, sent_ = 0;
  double travel_ = 0, last_pos_ = 0;
  double res_ = 0;  ///< position resolution (joint units per count)
  char msg_[192] = {};
};

}  // namespace servoarm::hal
