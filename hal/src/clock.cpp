// SPDX-License-Identifier: Apache-2.0
#include "servoarm/hal/clock.hpp"

#include <cerrno>
#include <ctime>

namespace servoarm::hal {

TimePoint MonotonicClock::now() const {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return TimePoint(ts.tv_sec) * kSecond + ts.tv_nsec;
}

void MonotonicClock::sleep_until(TimePoint deadline) {
  timespec ts{};
  ts.tv_sec = deadline / kSecond;
  ts.tv_nsec = deadline % kSecond;
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

void ManualClock::sleep_until(TimePoint deadline) {
  if (deadline > now_) now_ = deadline;
  if (hook_ && !in_hook_) {
    in_hook_ = true;
    hook_(now_);
    in_hook_ = false;
  }
}

}  // namespace servoarm::hal
