// SPDX-License-Identifier: Apache-2.0
// CiA 402 state machine (statusword decoding, transitions) and joint scaling.
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>

#include "servoarm/hal/cia402.hpp"
#include "servoarm/hal/scaling.hpp"

// CppUTest last: its leak detector redefines `new`.
#include <CppUTest/TestHarness.h>

using namespace servoarm::hal;
using namespace servoarm::hal::cia402;

TEST_GROUP(Cia402){};

TEST(Cia402, StatuswordTable) {
  // CiA 402 table 30, with unrelated bits (voltage enabled, remote, target reached, warning) set.
  struct Case {
    std::uint16_t sw;
    State state;
  } cases[] = {
      {0x0000, State::not_ready_to_switch_on}, {0x0010, State::not_ready_to_switch_on},
      {0x0040, State::switch_on_disabled},     {0x0250, State::switch_on_disabled},
      {0x0060, State::switch_on_disabled},     // bit 5 is "don't care" here
      {0x0021, State::ready_to_switch_on},     {0x0231, State::ready_to_switch_on},
      {0x0023, State::switched_on},            {0x0233, State::switched_on},
      {0x0027, State::operation_enabled},      {0x0637, State::operation_enabled},
      {0x0007, State::quick_stop_active},      {0x0217, State::quick_stop_active},
      {0x000F, State::fault_reaction_active},  {0x002F, State::fault_reaction_active},
      {0x0008, State::fault},                  {0x0228, State::fault},
      {0x0088, State::fault},                  // warning bit
  };
  for (const Case& c : cases) {
    char msg[64];
    std::snprintf(msg, sizeof msg, "statusword 0x%04X", unsigned(c.sw));
    STRCMP_EQUAL_TEXT(to_string(c.state), to_string(decode_statusword(c.sw)), msg);
  }
  // The drive-side encoding decodes to itself for every state.
  for (int s = 0; s <= int(State::fault); ++s)
    LONGS_EQUAL(s, int(decode_statusword(encode_state_bits(State(s)))));
}

TEST(Cia402, DriveTransitionTable) {
  struct Case {
    State from;
    std::uint16_t cw, prev;
    State to;
    int transition;
  } cases[] = {
      {State::switch_on_disabled, 0x0006, 0, State::ready_to_switch_on, 2},
      {State::switch_on_disabled, 0x0007, 0, State::switch_on_disabled, 0},   // switch on needs shutdown first
      {State::switch_on_disabled, 0x000F, 0, State::switch_on_disabled, 0},
      {State::ready_to_switch_on, 0x0007, 0, State::switched_on, 3},
      {State::ready_to_switch_on, 0x0000, 0, State::switch_on_disabled, 7},
      {State::ready_to_switch_on, 0x0002, 0, State::switch_on_disabled, 7},
      {State::switched_on, 0x000F, 0, State::operation_enabled, 4},
      {State::switched_on, 0x0006, 0, State::ready_to_switch_on, 6},
      {State::switched_on, 0x0000, 0, State::switch_on_disabled, 10},
      {State::operation_enabled, 0x0007, 0, State::switched_on, 5},
      {State::operation_enabled, 0x0006, 0, State::ready_to_switch_on, 8},
      {State::operation_enabled, 0x0000, 0, State::switch_on_disabled, 9},
      {State::operation_enabled, 0x000B, 0, State::quick_stop_active, 11},   // quick stop bit 2 low
      {State::operation_enabled, 0x000F, 0, State::operation_enabled, 0},
      {State::quick_stop_active, 0x0000, 0, State::switch_on_disabled, 12},
      {State::quick_stop_active, 0x000F, 0, State::operation_enabled, 16},
      {State::fault, 0x0080, 0x0000, State::switch_on_disabled, 15},
      {State::fault, 0x0080, 0x0080, State::fault, 0},                    // no edge, no reset
      {State::fault, 0x000F, 0x0000, State::fault, 0},
      {State::fault_reaction_active, 0x0080, 0x0000, State::fault_reaction_active, 0},
      {State::not_ready_to_switch_on, 0x0006, 0, State::not_ready_to_switch_on, 0},
  };
  for (const Case& c : cases) {
    int t = -1;
    const State got = apply_controlword(c.from, c.cw, c.prev, &t);
    char msg[128];
    std::snprintf(msg, sizeof msg, "%s + cw 0x%04X (prev 0x%04X)", to_string(c.from), unsigned(c.cw), unsigned(c.prev));
    STRCMP_EQUAL_TEXT(to_string(c.to), to_string(got), msg);
    LONGS_EQUAL_TEXT(c.transition, t, msg);
  }
}

TEST(Cia402, MasterWalksEveryStateToEnabledAndBack) {
  // The controlwords the master chooses, applied by the drive-side table, reach the target
  // from every stable state within a few steps. Quick stop from operation enabled must go
  // through quick_stop_active (T11), not drop the power (T9).
  const State starts[] = {State::switch_on_disabled, State::ready_to_switch_on, State::switched_on,
                          State::operation_enabled, State::quick_stop_active, State::fault};
  for (Target target : {Target::enabled, Target::disabled, Target::quick_stop}) {
    for (State s0 : starts) {
      State s = s0;
      std::uint16_t prev = 0;
      bool phase = false;
      int steps = 0;
      while (!reached(s, target) && steps < 10) {
        const std::uint16_t c = next_controlword(s, target, phase);
        phase = !phase;
        s = apply_controlword(s, c, prev);
        prev = c;
        ++steps;
      }
      char msg[96];
      std::snprintf(msg, sizeof msg, "from %s to target %d", to_string(s0), int(target));
      if (target != Target::enabled && s0 == State::fault) {
        STRCMP_EQUAL_TEXT("fault", to_string(s), msg);  // only enabling resets a fault
      } else {
        CHECK_TEXT(reached(s, target), msg);
        CHECK_TEXT(steps <= 5, msg);
        if (target == Target::quick_stop && s0 == State::operation_enabled)
          STRCMP_EQUAL_TEXT("quick_stop_active", to_string(s), msg);
      }
    }
  }
}

TEST_GROUP(Scaling){};

TEST(Scaling, HandComputedValues) {
  JointScaling s;
  s.counts_per_unit = 4096;
  s.gear_ratio = 100;
  // 4096 * 100 counts per joint revolution: a quarter turn is 102400 counts.
  std::int32_t c = 0;
  CHECK(s.to_counts(std::numbers::pi / 2, c));
  LONGS_EQUAL(102400, c);
  s.direction = -1;
  s.zero_offset = 1000;
  CHECK(s.to_counts(std::numbers::pi / 2, c));
  LONGS_EQUAL(1000 - 102400, c);
  DOUBLES_EQUAL(std::numbers::pi / 2, s.to_joint(1000 - 102400), 1e-12);
  // 409600 counts/s = one joint revolution per second.
  DOUBLES_EQUAL(-2 * std::numbers::pi, s.velocity_to_joint(409600), 1e-12);

  JointScaling p;
  p.kind = JointScaling::Kind::prismatic;
  p.counts_per_unit = 1000;  // counts per mm of motor-side travel
  p.gear_ratio = 2;
  CHECK(p.to_counts(0.010, c));  // 10 mm
  LONGS_EQUAL(20000, c);
  DOUBLES_EQUAL(0.0105, p.to_joint(21000), 1e-12);
}

TEST(Scaling, RejectsNonFiniteAndOverflow) {
  JointScaling s;
  std::int32_t c = 77;
  CHECK_FALSE(s.to_counts(std::nan(""), c));
  CHECK_FALSE(s.to_counts(INFINITY, c));
  CHECK_FALSE(s.to_counts(1e9, c));  // 1e9 rad * 20861 counts/rad > int32
  LONGS_EQUAL(77, c);
  JointScaling bad;
  bad.direction = 0;
  CHECK_FALSE(bad.valid());
  bad.direction = 1;
  bad.gear_ratio = 0;
  CHECK_FALSE(bad.valid());
  CHECK(JointScaling{}.valid());
}

TEST(Scaling, SeededRoundTripSweep) {
  std::mt19937_64 rng(20261122);
  std::uniform_real_distribution<double> cpr(256, 1 << 20), gear(1, 160), q(-10, 10), off(-1e6, 1e6);
  for (int i = 0; i < 2000; ++i) {
    JointScaling s;
    s.kind = (i & 1) ? JointScaling::Kind::prismatic : JointScaling::Kind::revolute;
    s.counts_per_unit = std::floor(cpr(rng));
    s.gear_ratio = gear(rng);
    s.direction = (i & 2) ? -1 : 1;
    s.zero_offset = std::int32_t(off(rng));
    const double x = s.kind == JointScaling::Kind::prismatic ? q(rng) * 0.01 : q(rng);
    std::int32_t c;
    if (!s.to_counts(x, c)) continue;  // out of int32 for this scaling
    const double back = s.to_joint(c);
    // Quantisation: within half a count.
    CHECK(std::fabs(back - x) <= 0.5 / s.counts_per_si() + 1e-12);
    // counts -> joint -> counts is exact.
    std::int32_t c2;
    CHECK(s.to_counts(back, c2));
    LONGS_EQUAL(c, c2);
  }
}
