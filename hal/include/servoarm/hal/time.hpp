// SPDX-License-Identifier: Apache-2.0
#pragma once
// Time in the firmware: nanoseconds on CLOCK_MONOTONIC, as plain integers (no
// std::chrono on the real-time path: trivially copyable, usable in frames and
// messages). Clocks that produce them: clock.hpp.
#include <cstdint>

namespace servoarm::hal {

/// Nanoseconds on CLOCK_MONOTONIC (the same scale as Clock::now()).
using TimePoint = std::int64_t;
using Duration = std::int64_t;  ///< nanoseconds
inline constexpr Duration kMicrosecond = 1000;
inline constexpr Duration kMillisecond = 1000 * kMicrosecond;
inline constexpr Duration kSecond = 1000 * kMillisecond;

}  // namespace servoarm::hal
