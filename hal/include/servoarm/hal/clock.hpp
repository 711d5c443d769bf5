// SPDX-License-Identifier: Apache-2.0
#pragma once
// Time source and sleeping behind a small interface so tests can drive time.
// All times are absolute CLOCK_MONOTONIC nanoseconds (TimePoint).
#include <functional>

#include "servoarm/hal/time.hpp"

namespace servoarm::hal {

class Clock {
 public:
  virtual ~Clock() = default;
  /// Real-time: current time.
  virtual TimePoint now() const = 0;
  /// Real-time: sleep until the absolute deadline (returns at once if it has passed).
  virtual void sleep_until(TimePoint deadline) = 0;
  /// True when time only moves when someone calls sleep_until()/advance() (tests).
  virtual bool simulated() const = 0;
};

/// CLOCK_MONOTONIC with clock_nanosleep(TIMER_ABSTIME).
class MonotonicClock final : public Clock {
 public:
  TimePoint now() const override;
  void sleep_until(TimePoint deadline) override;
  bool simulated() const override { return false; }
};

/// Manually driven clock for tests and in-process simulation. sleep_until()
/// jumps time forward and then calls the optional idle hook with the new time,
/// which is where a single-threaded test steps its simulated devices.
class ManualClock final : public Clock {
 public:
  explicit ManualClock(TimePoint start = kSecond) : now_(start) {}
  TimePoint now() const override { return now_; }
  void sleep_until(TimePoint deadline) override;
  bool simulated() const override { return true; }
  /// Same as sleep_until(now() + d).
  void advance(Duration d) { sleep_until(now_ + d); }
  /// Set-up: hook called after every time jump (not re-entered from inside itself).
  void set_idle_hook(std::function<void(TimePoint)> hook) { hook_ = std::move(hook); }

 private:
  TimePoint now_;
  std::function<void(TimePoint)> hook_;
  bool in_hook_ = false;
};

}  // namespace servoarm::hal
