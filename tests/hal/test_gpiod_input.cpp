// SPDX-License-Identifier: Apache-2.0
// GpiodInput without GPIO hardware (no gpio-sim on the build machines; vcan_s10_gpio reads real
// lines in the VM): the refresh period it derives from the staleness limit, and a reading
// thread with no chip to read that wakes at that refresh, not at the poll period, stays lost
// in one line, and stops.
#include <chrono>
#include <cstdio>
#include <cstring>
#include <thread>

#include "servoarm/hal/safety_input.hpp"

// CppUTest last: its leak detector redefines `new`.
#include <CppUTest/TestHarness.h>

using namespace servoarm::hal;

namespace {
constexpr Duration kMs = kMillisecond;
}

TEST_GROUP(GpiodInput){};

// A quarter of the staleness limit (three late refreshes before the control thread takes the
// line for lost), at most 50 ms, at least the poll period.
TEST(GpiodInput, RefreshIsAQuarterOfTheStalenessWithinThePeriodAnd50Ms) {
  LONGS_EQUAL(25 * kMs, GpiodInput("c", 0, kMs, 100 * kMs).refresh());  // safety.input_timeout_ms's default
  LONGS_EQUAL(50 * kMs, GpiodInput("c", 0, kMs, 3000 * kMs).refresh());
  LONGS_EQUAL(5 * kMs / 4, GpiodInput("c", 0, kMs, 5 * kMs).refresh());  // the key's least value
  LONGS_EQUAL(2 * kMs, GpiodInput("c", 0, 2 * kMs, 5 * kMs).refresh());
  CHECK(!GpiodInput("c", 0, kMs, 100 * kMs).polling());
}

// No such chip: lost, in one line naming the source; the thread keeps its count moving at the
// refresh period (25 ms here), which a 1 kHz loop would exceed tenfold; stop() joins it and
// the count stands still. (Only an upper bound on wake-ups: a loaded machine makes fewer.)
TEST(GpiodInput, WithoutAChipTheThreadWakesAtTheRefreshAndStops) {
  GpiodInput in("servoarm-no-such-chip", 3, kMs, 100 * kMs);
  if (!gpiod_available()) {
    CHECK(!in.start());
    CHECK(in.read(0) == InputLevel::lost);
    STRCMP_CONTAINS("built without libgpiod", in.why_lost());
    return;
  }
  CHECK(in.start());
  for (int i = 0; i < 2000 && in.polls() == 0; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  CHECK(in.polls() > 0);
  const std::uint32_t c0 = in.polls();
  const auto t0 = std::chrono::steady_clock::now();
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  const std::uint32_t c1 = in.polls();
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  // 500 ms at 25 ms: 20 wake-ups, plus one more reading per second for the chip's retry
  std::printf("\nno chip: %u readings in %.0f ms (refresh 25 ms; a 1 ms poll: about %.0f)\n", c1 - c0, ms, ms);
  CHECK_TEXT(c1 - c0 <= static_cast<std::uint32_t>(ms / 25.0) + 4, "the thread wakes more often than its refresh");
  CHECK(in.read(kMs) == InputLevel::lost);
  STRCMP_EQUAL("gpio:servoarm-no-such-chip:3: the chip cannot be opened (errno 2)", in.why_lost());
  CHECK(!in.polling());
  in.stop();
  const std::uint32_t c2 = in.polls();
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  LONGS_EQUAL(c2, in.polls());
  CHECK(in.read(500 * kMs) == InputLevel::lost);
}
