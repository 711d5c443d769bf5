// SPDX-License-Identifier: Apache-2.0
// Frame bit counts and bus load against figures worked out by hand from ISO 11898-1 as
// Linux's include/linux/can/length.h counts them, and from R. I. Davis et al., "Controller
// Area Network (CAN) schedulability analysis: Refuted, revisited and revised" (2007), eq. (2):
// a classical frame with s data bytes is g + 8s + 13 bits before stuffing (g = 34 for 11-bit
// ids, 54 for 29-bit ids) plus floor((g + 8s - 1) / 4) worst-case stuff bits.
#include <cmath>
#include <cstdio>

#include "servoarm/hal/bus_load.hpp"

// CppUTest last: its leak detector redefines `new`.
#include <CppUTest/TestHarness.h>

using namespace servoarm::hal;

TEST_GROUP(BusLoad){};

TEST(BusLoad, ClassicalFramesMatchTheHandCount) {
  const struct {
    bool extended;
    unsigned len;
    int unstuffed, worst;
  } cases[] = {
      // 11-bit: 47 + 8n before stuffing, floor((34 + 8n - 1) / 4) stuff bits
      {false, 8, 111, 111 + 24},  // floor(97 / 4) = 24: 135
      {false, 6, 95, 95 + 20},    // floor(81 / 4) = 20: 115 (RPDO1, TPDO1)
      {false, 0, 47, 47 + 8},     // floor(33 / 4) = 8: 55 (SYNC)
      {false, 1, 55, 55 + 10},    // floor(41 / 4) = 10: 65 (heartbeat)
      // 29-bit: 67 + 8n, floor((54 + 8n - 1) / 4)
      {true, 8, 131, 131 + 29},   // floor(117 / 4) = 29: 160
      {true, 0, 67, 67 + 13},     // floor(53 / 4) = 13: 80
  };
  for (const auto& c : cases) {
    char msg[80];
    std::snprintf(msg, sizeof msg, "%s id, %u bytes", c.extended ? "29-bit" : "11-bit", c.len);
    const FrameBits w = can_frame_bits(false, false, c.extended, c.len, true);
    const FrameBits b = can_frame_bits(false, false, c.extended, c.len, false);
    LONGS_EQUAL_TEXT(c.worst, w.total(), msg);
    LONGS_EQUAL_TEXT(c.unstuffed, b.total(), msg);
    LONGS_EQUAL_TEXT(0, w.data, msg);
  }
}

TEST(BusLoad, CanFdFramesMatchTheHandCount) {
  // 11-bit FD, 8 bytes: header 22 + 64 stuffed -> 86 + floor(85 / 4) = 107; CRC field 28
  // (stuff count 4, CRC 17, delimiter 1, 6 fixed stuff bits); ACK 2, EOF 7, intermission 3.
  FrameBits f = can_frame_bits(true, false, false, 8, true);
  LONGS_EQUAL(107 + 28 + 12, f.total());
  // With bit rate switching: SOF .. BRS (17 bits) and their floor(16 / 4) = 4 stuff bits, the
  // CRC delimiter, ACK, EOF and intermission nominal: 21 + 1 + 12 = 34; the rest at the data rate.
  f = can_frame_bits(true, true, false, 8, true);
  LONGS_EQUAL(34, f.nominal);
  LONGS_EQUAL(147 - 34, f.data);
  // 64 bytes: 22 + 512 = 534 stuffed -> 534 + 133 = 667; CRC 21 field 33; 12.
  LONGS_EQUAL(667 + 33 + 12, can_frame_bits(true, false, false, 64, true).total());
  // 9 bytes go in a 12-byte frame: 22 + 96 = 118 -> 118 + 29 = 147; 28; 12.
  LONGS_EQUAL(147 + 28 + 12, can_frame_bits(true, false, false, 9, true).total());
  // 29-bit FD, 0 bytes, no dynamic stuffing: 41 + 28 + 12.
  LONGS_EQUAL(41 + 28 + 12, can_frame_bits(true, false, true, 0, false).total());
}

TEST(BusLoad, SixJointsAtOneKilohertzOnOneMegabit) {
  BusTraffic t;  // 6 joints, 1 kHz, RPDO1 + TPDO1 (6 bytes), SYNC, heartbeats every 50 ms
  BusLoad l = bus_load(t, 1e6);
  // to the drives: SYNC 55 + 6 x RPDO1 115 bits per cycle
  DOUBLES_EQUAL((55 + 6 * 115) * 1000 / 1e6, l.to_drives, 1e-12);
  // from the drives: 6 x TPDO1 115 per cycle + 6 heartbeats (65 bits) every 50 ms
  DOUBLES_EQUAL((6 * 115) * 1000 / 1e6 + 6 * 20 * 65 / 1e6, l.from_drives, 1e-12);
  DOUBLES_EQUAL(13, l.frames_per_cycle, 0);
  // TPDO2 (velocity + error code, 6 bytes) on every drive: 6 x 115 more from the drives.
  t.tpdo2_len = 6;
  l = bus_load(t, 1e6);
  DOUBLES_EQUAL((12 * 115) * 1000 / 1e6 + 6 * 20 * 65 / 1e6, l.from_drives, 1e-12);
  DOUBLES_EQUAL(19, l.frames_per_cycle, 0);
  CHECK(l.total() > 2.1);  // 2.13 Mbit/s of wire time asked of a 1 Mbit/s bus
  // 400 Hz without TPDO2 fits under 60 %: (55 + 12 x 115) x 400 + 7800 bit/s.
  t.tpdo2_len = 0;
  t.rate_hz = 400;
  l = bus_load(t, 1e6);
  DOUBLES_EQUAL(((55 + 12 * 115) * 400 + 7800) / 1e6, l.total(), 1e-12);
  CHECK(l.total() < 0.6);
  // The same traffic as CAN FD frames at 1 / 5 Mbit/s: each frame's nominal bits at 1 Mbit/s,
  // its data-phase bits at 5 Mbit/s.
  l = bus_load(t, 1e6, 5e6);
  const FrameBits six = can_frame_bits(true, true, false, 6), none = can_frame_bits(true, true, false, 0),
                  one = can_frame_bits(true, true, false, 1);
  const auto time = [](const FrameBits& b) { return b.nominal / 1e6 + b.data / 5e6; };
  DOUBLES_EQUAL(400 * (time(none) + 12 * time(six)) + 6 * 20 * time(one), l.total(), 1e-12);
}

// Six MIT motors (one 8-byte command and one 8-byte feedback frame each per cycle, no SYNC, no
// heartbeat) per loop rate, on one bus and split over two, classic CAN at 1 Mbit/s and CAN FD
// with bit-rate switch at 1 Mbit/s nominal and 2 or 5 Mbit/s data: the table of RESULTS
// ("MIT motors: bus load per rate"); the 1 kHz figures are the ones the bus-load check names
// (fw_mit_arm BusLoadIsCheckedPerInterface, docs/mit-motors.md).
TEST(BusLoad, SixMitMotorsPerLoopRate) {
  const double rates[] = {250, 500, 1000};
  const double data[] = {0, 2e6, 5e6};
  std::printf("\n  six MIT motors, worst-case bit stuffing: load %% of 1 Mbit/s (one bus / three motors per bus)\n");
  std::printf("  %-8s %-18s %-18s %-18s\n", "rate", "classic", "FD data 2 Mbit/s", "FD data 5 Mbit/s");
  double at1k[3] = {};
  for (const double r : rates) {
    std::printf("  %-8.0f", r);
    for (std::size_t k = 0; k < 3; ++k) {
      BusTraffic t;
      t.joints = 0;
      t.mit_joints = 6;
      t.rate_hz = r;
      const double one = bus_load(t, 1e6, data[k]).total();
      t.mit_joints = 3;
      const double two = bus_load(t, 1e6, data[k]).total();
      std::printf(" %6.1f / %6.1f    ", one * 100, two * 100);
      if (r == 1000) at1k[k] = one;
      DOUBLES_EQUAL(one / 2, two, 1e-12);  // no shared frame: half the motors, half the load
    }
    std::printf("\n");
  }
  DOUBLES_EQUAL(1.620, at1k[0], 5e-4);
  DOUBLES_EQUAL(1.086, at1k[1], 5e-4);
  DOUBLES_EQUAL(0.679, at1k[2], 5e-4);
}
