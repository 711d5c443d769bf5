// SPDX-License-Identifier: Apache-2.0
// The MIT-mode frame codec (hal/mit.hpp) against byte layouts written out by hand from the
// Damiao / CubeMars / Robstride manuals: range edges, rounding, special frames, every Damiao
// register, feedback of each vendor, and the multi-turn unwrap of the +-P_MAX wrapped position.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <initializer_list>
#include <random>

#include "alloc_counter.hpp"
#include "servoarm/hal/mit.hpp"

// CppUTest last: its leak detector redefines `new`.
#include <CppUTest/TestHarness.h>

using namespace servoarm::hal;
using namespace servoarm::hal::mit;

namespace {
void expect_bytes(const CanFrame& f, std::uint32_t id, std::initializer_list<std::uint8_t> bytes, const char* what) {
  char msg[160];
  std::snprintf(msg, sizeof msg, "%s: id 0x%03X len %u", what, unsigned(f.id), unsigned(f.len));
  UNSIGNED_LONGS_EQUAL_TEXT(id, f.id, msg);
  CHECK_FALSE_TEXT(f.extended || f.rtr || f.fd || f.error, msg);
  UNSIGNED_LONGS_EQUAL_TEXT(bytes.size(), f.len, msg);
  std::size_t i = 0;
  for (std::uint8_t b : bytes) {
    char m2[200];
    std::snprintf(m2, sizeof m2, "%s byte %zu", msg, i);
    BYTES_EQUAL_TEXT(b, f.data[i], m2);
    ++i;
  }
}
const Ranges kJ4310{12.5, 30, 10, 500, 5};
}  // namespace

TEST_GROUP(MitCodec){};

TEST(MitCodec, CommandAtTheRangeEdges) {
  CanFrame f;
  // p = +P_MAX -> 0xFFFF, v = -V_MAX -> 0x000, kp = KP_MAX -> 0xFFF, kd = 0 -> 0x000, t = +T_MAX -> 0xFFF
  CHECK(pack_command(kJ4310, 0x01, {12.5, -30, 500, 0, 10}, f));
  expect_bytes(f, 0x01, {0xFF, 0xFF, 0x00, 0x0F, 0xFF, 0x00, 0x0F, 0xFF}, "max p, min v");
  CHECK(pack_command(kJ4310, 0x02, {-12.5, 30, 0, 5, -10}, f));
  expect_bytes(f, 0x02, {0x00, 0x00, 0xFF, 0xF0, 0x00, 0xFF, 0xF0, 0x00}, "min p, max v");
  // beyond the ranges: clamped to the edge codes, never wrapped
  CHECK(pack_command(kJ4310, 0x03, {100, -1e9, 1e6, -3, 1e3}, f));
  expect_bytes(f, 0x03, {0xFF, 0xFF, 0x00, 0x0F, 0xFF, 0x00, 0x0F, 0xFF}, "clamped high");
  CHECK(pack_command(kJ4310, 0x03, {-100, 1e9, -1, 99, -1e3}, f));
  expect_bytes(f, 0x03, {0x00, 0x00, 0xFF, 0xF0, 0x00, 0xFF, 0xF0, 0x00}, "clamped low");
  // 0 lies half-way between two codes of the 16-bit / 12-bit fields: 32767.5 -> 32768, 2047.5 -> 2048
  CHECK(pack_command(kJ4310, 0x04, {0, 0, 0, 0, 0}, f));
  expect_bytes(f, 0x04, {0x80, 0x00, 0x80, 0x00, 0x00, 0x00, 0x08, 0x00}, "zeros");
  // not finite: refused, the frame untouched
  const CanFrame before = f;
  CHECK_FALSE(pack_command(kJ4310, 0x05, {NAN, 0, 0, 0, 0}, f));
  CHECK_FALSE(pack_command(kJ4310, 0x05, {0, 0, 0, 0, INFINITY}, f));
  CHECK(f.same_as(before));
}

TEST(MitCodec, RoundsToTheNearestCode) {
  const double q = 25.0 / 65535.0;  // one position code on +-12.5
  UNSIGNED_LONGS_EQUAL(1, to_code(-12.5 + 0.6 * q, -12.5, 12.5, 16));  // truncation would give 0
  UNSIGNED_LONGS_EQUAL(0, to_code(-12.5 + 0.4 * q, -12.5, 12.5, 16));
  UNSIGNED_LONGS_EQUAL(65534, to_code(12.5 - 0.6 * q, -12.5, 12.5, 16));
  UNSIGNED_LONGS_EQUAL(4095, to_code(500 - 0.4 * 500.0 / 4095, 0, 500, 12));
  UNSIGNED_LONGS_EQUAL(0, to_code(NAN, 0, 500, 12));
  // Seeded sweep: a round trip through the frame errs by at most half a code on every field.
  std::mt19937 rng(39);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 20000; ++i) {
    const Command c{12.5 * u(rng), 30 * u(rng), 250 * (1 + u(rng)), 2.5 * (1 + u(rng)), 10 * u(rng)};
    CanFrame f;
    Command back;
    CHECK(pack_command(kJ4310, 7, c, f));
    CHECK(unpack_command(kJ4310, f, back));
    char msg[160];
    std::snprintf(msg, sizeof msg, "case %d: p %.6f v %.6f kp %.4f kd %.5f t %.5f", i, c.p, c.v, c.kp, c.kd, c.t);
    CHECK_TEXT(std::fabs(back.p - c.p) <= 0.5 * 25 / 65535 + 1e-12, msg);
    CHECK_TEXT(std::fabs(back.v - c.v) <= 0.5 * 60 / 4095 + 1e-12, msg);
    CHECK_TEXT(std::fabs(back.kp - c.kp) <= 0.5 * 500 / 4095 + 1e-12, msg);
    CHECK_TEXT(std::fabs(back.kd - c.kd) <= 0.5 * 5.0 / 4095 + 1e-12, msg);
    CHECK_TEXT(std::fabs(back.t - c.t) <= 0.5 * 20 / 4095 + 1e-12, msg);
  }
}

TEST(MitCodec, PackingAllocatesNothing) {
  servoarm::test::alloc_count_begin();
  CanFrame f;
  Feedback fb;
  Unwrap w;
  double sum = 0;
  for (int i = 0; i < 100; ++i) {
    pack_command(kJ4310, 1, {0.01 * i, 0, 10, 1, 0.5}, f);
    decode_feedback(Vendor::damiao, kJ4310, f, fb);
    sum += w.update(fb.p, kJ4310.p_max);
  }
  LONGS_EQUAL(0, servoarm::test::alloc_count_end());
  CHECK(std::isfinite(sum));
}

TEST(MitCodec, SpecialFrames) {
  expect_bytes(special_frame(0x01, Special::enable), 0x01, {0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFC}, "enable");
  expect_bytes(special_frame(0x02, Special::disable), 0x02, {0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFD}, "disable");
  expect_bytes(special_frame(0x03, Special::save_zero), 0x03, {0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFE}, "zero");
  expect_bytes(special_frame(0x04, Special::clear_error), 0x04, {0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFB},
               "clear");
  Special s;
  CHECK(is_special(special_frame(9, Special::save_zero), s));
  LONGS_EQUAL(int(Special::save_zero), int(s));
  CHECK_FALSE(is_special(CanFrame::make(9, {0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFA}), s));
  CHECK_FALSE(is_special(CanFrame::make(9, {0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFE, 0xFC}), s));
  // a special frame is no command
  Command c;
  CHECK_FALSE(unpack_command(kJ4310, special_frame(1, Special::enable), c));
}

TEST(MitCodec, DamiaoFeedback) {
  // error 1 (enabled), id 3; p code 0xFFFF (+P_MAX); v code 0x000 (-V_MAX); t code 0xFFF (+T_MAX);
  // MOSFET 40 deg C, rotor 55 deg C
  const CanFrame f = CanFrame::make(0x13, {0x13, 0xFF, 0xFF, 0x00, 0x0F, 0xFF, 40, 55});
  Feedback fb;
  CHECK(decode_feedback(Vendor::damiao, kJ4310, f, fb));
  LONGS_EQUAL(3, fb.id);
  LONGS_EQUAL(1, fb.error);
  DOUBLES_EQUAL(12.5, fb.p, 1e-12);
  DOUBLES_EQUAL(-30, fb.v, 1e-12);
  DOUBLES_EQUAL(10, fb.t, 1e-12);
  DOUBLES_EQUAL(40, fb.t_mos, 0);
  DOUBLES_EQUAL(55, fb.t_rotor, 0);
  // error nibble 9 = under-voltage
  CHECK(decode_feedback(Vendor::damiao, kJ4310, CanFrame::make(0x11, {0x91, 0, 0, 0, 0, 0, 0, 0}), fb));
  LONGS_EQUAL(9, fb.error);
  CHECK(damiao_is_fault(fb.error));
  STRCMP_EQUAL("under-voltage", damiao_error_name(fb.error));
  STRCMP_EQUAL("communication lost (its CAN timeout)", damiao_error_name(0xD));
  CHECK_FALSE(damiao_is_fault(1));
  CHECK_FALSE(decode_feedback(Vendor::damiao, kJ4310, CanFrame::make(0x11, {0x11, 0, 0}), fb));  // short
  // encode is decode's inverse (what the virtual motors send)
  Feedback in;
  in.id = 5;
  in.error = 0xB;
  in.p = -1.25;
  in.v = 2.0;
  in.t = -3.0;
  in.t_mos = 71;
  in.t_rotor = 64;
  CHECK(decode_feedback(Vendor::damiao, kJ4310, encode_feedback(Vendor::damiao, kJ4310, 0x15, in), fb));
  LONGS_EQUAL(5, fb.id);
  LONGS_EQUAL(0xB, fb.error);
  DOUBLES_EQUAL(-1.25, fb.p, 25.0 / 65535);
  DOUBLES_EQUAL(2.0, fb.v, 60.0 / 4095);
  DOUBLES_EQUAL(-3.0, fb.t, 20.0 / 4095);
  DOUBLES_EQUAL(71, fb.t_mos, 0);
}

TEST(MitCodec, CubeMarsAndRobstrideFeedback) {
  const Ranges ak = ranges_of(*find_profile("AK80-9"));
  Feedback fb;
  // CubeMars: byte 0 id 7, p 0x0000 (-12.5), v 0xFFF (+50), current-as-torque 0x000 (-18), 45 deg C, error 0
  CHECK(decode_feedback(Vendor::cubemars, ak, CanFrame::make(0x00, {7, 0x00, 0x00, 0xFF, 0xF0, 0x00, 45, 0}), fb));
  LONGS_EQUAL(7, fb.id);
  DOUBLES_EQUAL(-12.5, fb.p, 1e-12);
  DOUBLES_EQUAL(50, fb.v, 1e-12);
  DOUBLES_EQUAL(-18, fb.t, 1e-12);
  DOUBLES_EQUAL(45, fb.t_mos, 0);
  const Ranges rs = ranges_of(*find_profile("rs00"));
  // Robstride: temperature x 10 big-endian: 0x01C2 = 450 -> 45.0 deg C
  CHECK(decode_feedback(Vendor::robstride, rs, CanFrame::make(0xFD, {1, 0xFF, 0xFF, 0x80, 0x08, 0x00, 0x01, 0xC2}), fb));
  LONGS_EQUAL(1, fb.id);
  DOUBLES_EQUAL(12.57, fb.p, 1e-12);
  DOUBLES_EQUAL(45.0, fb.t_mos, 1e-12);
}

TEST(MitCodec, EveryDamiaoRegister) {
  int uints = 0;
  for (std::uint8_t rid = 0; rid <= kLastReg; ++rid) {
    char msg[64];
    std::snprintf(msg, sizeof msg, "RID %u (%s)", unsigned(rid), reg_name(rid));
    CHECK_TEXT(std::strcmp(reg_name(rid), "?") != 0, msg);
    // read: [id lo, id hi, 0x33, RID, 0, 0, 0, 0] on 0x7FF
    expect_bytes(reg_read(0x0102, rid), 0x7FF, {0x02, 0x01, 0x33, rid, 0, 0, 0, 0}, msg);
    // write: [id lo, id hi, 0x55, RID, value little-endian]
    RegMessage m;
    if (reg_is_uint(rid)) {
      ++uints;
      expect_bytes(reg_write_u32(0x0003, rid, 0x11223344u), 0x7FF, {0x03, 0x00, 0x55, rid, 0x44, 0x33, 0x22, 0x11}, msg);
      CHECK_TEXT(decode_register(reg_write_u32(3, rid, 0x11223344u), m), msg);
      UNSIGNED_LONGS_EQUAL_TEXT(0x11223344u, m.raw, msg);
    } else {
      // 12.5f = 0x41480000
      expect_bytes(reg_write_f32(0x0003, rid, 12.5f), 0x7FF, {0x03, 0x00, 0x55, rid, 0x00, 0x00, 0x48, 0x41}, msg);
      CHECK_TEXT(decode_register(reg_write_f32(3, rid, 12.5f), m), msg);
      DOUBLES_EQUAL(12.5, m.as_float(), 0);
    }
    LONGS_EQUAL_TEXT(int(RegCmd::write), int(m.cmd), msg);
    LONGS_EQUAL_TEXT(rid, m.rid, msg);
    LONGS_EQUAL_TEXT(3, m.motor_id, msg);
    // the reply comes on the master id with the same layout
    const CanFrame r = reg_reply(0x13, m);
    UNSIGNED_LONGS_EQUAL_TEXT(0x13, r.id, msg);
    RegMessage back;
    CHECK_TEXT(decode_register(r, back), msg);
    UNSIGNED_LONGS_EQUAL_TEXT(m.raw, back.raw, msg);
  }
  LONGS_EQUAL(10, uints);  // 7..10, 13..16, 35, 36
  STRCMP_EQUAL("CTRL_MODE", reg_name(10));
  STRCMP_EQUAL("TIMEOUT", reg_name(9));
  STRCMP_EQUAL("PMAX", reg_name(21));
  STRCMP_EQUAL("?", reg_name(37));
  expect_bytes(reg_save(0x0001), 0x7FF, {0x01, 0x00, 0xAA, 0x00, 0, 0, 0, 0}, "save");
  expect_bytes(refresh_frame(0x0001), 0x7FF, {0x01, 0x00, 0xCC, 0x00, 0, 0, 0, 0}, "refresh");
  RegMessage m;
  CHECK_FALSE(decode_register(CanFrame::make(0x7FF, {1, 0, 0x34, 10, 0, 0, 0, 0}), m));  // unknown command
  CHECK_FALSE(decode_register(CanFrame::make(0x7FF, {1, 0, 0x55, 10}), m));              // write without value
  STRCMP_EQUAL("MIT", ctrl_mode_name(1));
  STRCMP_EQUAL("position-velocity", ctrl_mode_name(2));
}

TEST(MitCodec, MultiTurnUnwrapKeepsTheTruePosition) {
  // A joint turns from 0 to +40 rad and back to -40 rad at 0.02 rad a sample; the frame carries
  // it wrapped into [-12.5, 12.5) (and quantised); the unwrap keeps the true position.
  const double pm = 12.5, q = 25.0 / 65535;
  Unwrap w;
  double truth = 0;
  auto sample = [&](double x) {
    const double wrapped = x - 2 * pm * std::floor((x + pm) / (2 * pm));
    const double sent = from_code(to_code(wrapped, -pm, pm, 16), -pm, pm, 16);
    return w.update(sent, pm);
  };
  double worst = 0;
  for (int i = 0; i <= 2000; ++i) {
    truth = 0.02 * i;
    worst = std::fmax(worst, std::fabs(sample(truth) - truth));
  }
  DOUBLES_EQUAL(40.0, sample(40.0), q);
  CHECK(w.turns() == 2);  // 40 = 15 + 25
  for (int i = 2000; i >= -2000; --i) {
    truth = 0.02 * i;
    worst = std::fmax(worst, std::fabs(sample(truth) - truth));
  }
  CHECK_TRUE(worst <= q);
  CHECK(w.turns() == -2);
  // without the unwrap the value past +P_MAX would read 2 P_MAX lower
  Unwrap fresh;
  DOUBLES_EQUAL(12.4, fresh.update(12.4, pm), 1e-12);
  DOUBLES_EQUAL(12.6, fresh.update(12.6 - 25, pm), 1e-12);
}

TEST(MitCodec, Profiles) {
  const char* expect[] = {"DM-J4310-2EC", "DM-J4340", "DM-J8006", "AK80-9", "RS00"};
  for (const char* n : expect) {
    const MotorProfile* p = find_profile(n);
    CHECK_TEXT(p != nullptr, n);
    CHECK_TEXT(p->p_max > 0 && p->v_max > 0 && p->t_max > 0 && p->kp_max > 0 && p->kd_max > 0, n);
    CHECK_TEXT(p->gear_ratio >= 1, n);
    CHECK_TEXT(std::strlen(p->source) > 10, n);
  }
  CHECK(find_profile("dm-j4340") == find_profile("DM-J4340"));  // case-insensitive
  CHECK(find_profile("DM-J4341") == nullptr);
  CHECK(find_profile("") == nullptr);
  // the published ranges (Damiao table, CubeMars and Robstride manuals)
  DOUBLES_EQUAL(28, find_profile("DM-J4340")->t_max, 0);
  DOUBLES_EQUAL(40, find_profile("DM-J4340")->gear_ratio, 0);
  DOUBLES_EQUAL(40, find_profile("DM-J8006")->t_max, 0);
  DOUBLES_EQUAL(18, find_profile("AK80-9")->t_max, 0);
  LONGS_EQUAL(int(Vendor::robstride), int(find_profile("RS00")->vendor));
}

TEST(MitCodec, DamiaoPositionVelocityAndVelocityFrames) {
  CanFrame f;
  // 1.0f = 0x3F800000, 2.0f = 0x40000000, -0.5f = 0xBF000000, little-endian
  CHECK(pack_pos_vel(0x01, 1.0, 2.0, f));
  expect_bytes(f, 0x101, {0x00, 0x00, 0x80, 0x3F, 0x00, 0x00, 0x00, 0x40}, "position-velocity");
  CHECK(pack_vel(0x03, -0.5, f));
  expect_bytes(f, 0x203, {0x00, 0x00, 0x00, 0xBF}, "velocity");
  std::uint16_t id = 0;
  double p = 0, v = 0;
  CHECK(unpack_pos_vel(CanFrame::make(0x105, {0x00, 0x00, 0x80, 0x3F, 0x00, 0x00, 0x00, 0x40}), id, p, v));
  LONGS_EQUAL(5, id);
  DOUBLES_EQUAL(1.0, p, 0);
  DOUBLES_EQUAL(2.0, v, 0);
  CHECK(unpack_vel(CanFrame::make(0x207, {0x00, 0x00, 0x00, 0xBF}), id, v));
  LONGS_EQUAL(7, id);
  DOUBLES_EQUAL(-0.5, v, 0);
  CHECK_FALSE(unpack_vel(CanFrame::make(0x107, {0x00, 0x00, 0x00, 0xBF}), id, v));
  CHECK_FALSE(pack_vel(1, NAN, f));
  CHECK_FALSE(pack_pos_vel(0x100, 0, 0, f));  // the id does not fit the 0x100 + id scheme
}
