// SPDX-License-Identifier: Apache-2.0
// Hard-stop homing, drive-neutral: the approach ramp, contact detection, back-off and the new
// zero (docs/servo-bus.md#homing). Joint units (rad or m) throughout.
#include "servoarm/hal/hard_stop_homing.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace servoarm::hal {

const char* HardStopHoming::step_name(std::uint8_t step) {
  switch (step) {
    case approach: return "approaching the hard stop";
    case backoff: return "backing off the hard stop";
    case settle: return "settling at the backed-off point";
    case done: return "done";
    default: return "idle";
  }
}

void HardStopHoming::step_to(std::uint8_t s, TimePoint now) {
  step_ = s;
  step_since_ = now;
  samples_ = 0;
}

void HardStopHoming::start(double from, double position, TimePoint now) {
  phase_ = HomingPhase::running;
  status_ = Status::ok;
  abort_ = false;
  hold_once_ = false;
  msg_[0] = '\0';
  started_ = now;
  last_ = now;
  last_sample_ = 0;
  demand_ = sent_ = from;
  v_ = 0;
  travel_ = 0;
  last_pos_ = position;
  step_to(approach, now);
}

HardStopHoming::Event HardStopHoming::fail(Status why, const HomingSpec& spec, const JointFeedback& fb, TimePoint now,
                                           const char* name) {
  if (status_ == Status::ok) status_ = why;
  if (msg_[0] == '\0') {
    if (why == Status::timeout)
      std::snprintf(msg_, sizeof msg_, "%s: homing timeout after %lld ms %s (statusword 0x%04X)", name,
                    static_cast<long long>(spec.timeout / kMillisecond), step_name(step_), unsigned(fb.statusword));
    else
      std::snprintf(msg_, sizeof msg_, "%s: homing %s while %s (statusword 0x%04X)", name, to_string(why),
                    step_name(step_), unsigned(fb.statusword));
  }
  phase_ = HomingPhase::failed;
  hold_ = fb.position;  // holds where it stands
  hold_once_ = true;
  step_to(done, now);
  return Event::failed;
}

bool HardStopHoming::travel_exceeded(const HomingSpec& spec, const JointFeedback& fb, const char* name, bool prismatic) {
  travel_ += fb.position - last_pos_;  // every change is motion (the drive keeps its coordinates)
  last_pos_ = fb.position;
  if (!(spec.max_travel > 0) || std::fabs(travel_) <= spec.max_travel) return false;
  const char* unit = prismatic ? "mm" : "deg";
  const double k = prismatic ? 1e3 : 180.0 / 3.14159265358979323846;  // deg or mm per SI unit
  const double got = std::fabs(travel_) * k, limit = spec.max_travel * k;
  int digits = 1;  // as many as show the excess
  while (digits < 6 && std::nearbyint(got * std::pow(10.0, digits)) <= std::nearbyint(limit * std::pow(10.0, digits))) ++digits;
  std::snprintf(msg_, sizeof msg_,
                "%s: homing travel %.*f %s from where it began, beyond the limit %.*f %s (the joint's range + "
                "homing.travel_margin_deg)",
                name, digits, got, unit, digits, limit, unit);
  return true;
}

HardStopHoming::Event HardStopHoming::advance(const HomingSpec& spec, const JointFeedback& fb, TimePoint now,
                                              const char* name, double resolution, bool prismatic) {
  if (phase_ != HomingPhase::running) return Event::none;
  res_ = resolution;
  if (fb.last_feedback != last_sample_) {
    last_sample_ = fb.last_feedback;
    if (samples_ < 1000) ++samples_;
  }
  Status why = Status::ok;
  if (fb.state == JointState::fault) why = fb.fault;
  else if (fb.state != JointState::enabled) why = Status::bad_state;
  else if (abort_) why = Status::aborted;
  else if (now - started_ > spec.timeout) why = Status::timeout;
  else if (travel_exceeded(spec, fb, name, prismatic)) why = Status::homing_error;
  if (why != Status::ok) return fail(why, spec, fb, now, name);
  const double dir = spec.speed_switch > 0 ? 1.0 : -1.0;
  switch (step_) {
    case approach: {
      if (samples_ < 3) break;  // positions sampled after the ramp began
      const double fe = std::fabs(sent_ - fb.position);
      const bool push = spec.torque_limit > 0 && fb.has_torque && std::fabs(fb.torque) > spec.torque_limit;
      if (fe > spec.following_limit || push) {
        // Contact: stop pushing (the demand goes to where the joint stands), then back off.
        demand_ = sent_ = fb.position;
        v_ = 0;
        goal_ = fb.position - dir * spec.backoff;
        step_to(backoff, now);
      }
      break;
    }
    case backoff:
      if (demand_ == goal_ && v_ == 0) step_to(settle, now);
      break;
    case settle:
      if (samples_ >= 3 && (std::fabs(fb.position - goal_) <= 1.5 * resolution || now - step_since_ > 500 * kMillisecond))
        return Event::settled;
      break;
    default: break;
  }
  return Event::none;
}

void HardStopHoming::finish_settled(double reads, TimePoint now) {
  status_ = Status::ok;
  msg_[0] = '\0';
  phase_ = HomingPhase::attained;
  demand_ = sent_ = hold_ = reads;
  v_ = 0;
  hold_once_ = true;
  step_to(done, now);
}

double HardStopHoming::setpoint(const HomingSpec& spec, bool following, double fallback, TimePoint now) {
  if (!following) return fallback;
  double dt = last_ != 0 && now > last_ ? double(now - last_) * 1e-9 : 0.0;
  dt = std::min(dt, 0.05);
  last_ = now;
  const double a = spec.acceleration, vmax = std::fabs(spec.speed_switch);
  const double dir = spec.speed_switch > 0 ? 1.0 : -1.0;
  switch (step_) {
    case approach:
      v_ += std::clamp(dir * vmax - v_, -a * dt, a * dt);
      demand_ += v_ * dt;
      break;
    case backoff: {
      const double d = goal_ - demand_;
      const double vt = (d > 0 ? 1.0 : -1.0) * std::min(vmax, std::sqrt(2.0 * a * std::fabs(d)));
      v_ += std::clamp(vt - v_, -a * dt, a * dt);
      const double step = v_ * dt;
      if (std::fabs(d) <= std::fabs(step) || std::fabs(d) < 0.5 * res_) {
        demand_ = goal_;
        v_ = 0;
      } else {
        demand_ += step;
      }
      break;
    }
    default: break;
  }
  sent_ = demand_;
  return demand_;
}

}  // namespace servoarm::hal
