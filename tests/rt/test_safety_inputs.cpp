// SPDX-License-Identifier: Apache-2.0
// The safety inputs (hal/safety_input.hpp, Controller::watch_safety_inputs) on the puma560 with
// virtual drives, sampled every cycle:
//  - the sources' parser: every form and every refusal, one line each;
//  - InputWatch: active level, debounce of the release only, lost counts as asserted;
//  - the e-stop input (simulated, and a drive's 60FDh bit through TPDO3): asserted in the middle
//    of a move -> emergency stop within 2 cycles, its event naming the input; `reset` refused
//    while it is asserted; a drive that falls silent -> its input lost -> emergency stop naming it;
//  - the Reduced input: asserted -> the envelope in Reduced mode (telemetry, status, planning), a
//    running line slowed on its path; lost -> Reduced;
//  - DriveBitInput's fail-safe reasons (a bus without 60FDh, none yet, stale) on a fake bus;
//  - GpiodInput without a chip (or without libgpiod): lost, in one line; App refuses what the
//    build or the arm cannot read;
//  - no allocation on the control thread with both inputs configured.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "controller_rig.hpp"
#include "servoarm/hal/safety_input.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/service/arm_service.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;

namespace {

using Rig = test::ControllerRig;

/// Cycles until the arm is in an e-stop mode (at most `max`); how many it took (max + 1: never).
int cycles_to_estop(Rig& r, int max) {
  for (int i = 1; i <= max; ++i) {
    r.cycle();
    if (r.tel().state == ArmState::estop) return i;
  }
  return max + 1;
}

FwConfig with_inputs(const char* estop, const char* reduced) {
  FwConfig c;
  c.safety_estop_input = estop;
  c.safety_reduced_input = reduced;
  return c;
}

/// A fake bus of one joint whose feedback the test writes (DriveBitInput's reasons).
class FeedbackBus final : public hal::ServoBus {
 public:
  hal::JointFeedback fb;
  std::size_t joint_count() const override { return 1; }
  hal::Status start(hal::TimePoint) override { return hal::Status::ok; }
  void enable() override {}
  void disable() override {}
  hal::Status read(hal::TimePoint) override { return hal::Status::ok; }
  hal::Status write(std::span<const double>, hal::TimePoint) override { return hal::Status::ok; }
  const hal::JointFeedback& feedback(std::size_t) const override { return fb; }
  const char* last_error() const override { return ""; }
};

}  // namespace

TEST_GROUP(SafetyInputSources){};

// Every form of a source, and each refusal in one line naming what is wrong.
TEST(SafetyInputSources, ParseEveryFormAndRefuseInOneLine) {
  struct Case {
    const char* text;
    bool ok;
    hal::InputKind kind;
    const char* detail;  // ok: "joint bit" / chip:line / name; refused: a part of the line
  } const cases[] = {
      {"", true, hal::InputKind::none, ""},
      {"drive:2:bit16", true, hal::InputKind::drive, "1 16"},
      {"drive:8:bit31", true, hal::InputKind::drive, "7 31"},
      {"drive:0:bit16", false, hal::InputKind::none, "the joint is 1-based, 1..8"},
      {"drive:9:bit1", false, hal::InputKind::none, "the joint is 1-based"},
      {"drive:2:bit32", false, hal::InputKind::none, "the bit of 60FDh is 0..31"},
      {"drive:2:16", false, hal::InputKind::none, "drive:JOINT:bitN"},
      {"drive:2:bit", false, hal::InputKind::none, "0..31"},
      {"drive:x:bit1", false, hal::InputKind::none, "1-based"},
      {"gpio:gpiochip0:17", true, hal::InputKind::gpio, "gpiochip0:17"},
      {"gpio:/dev/gpiochip1:3", true, hal::InputKind::gpio, "/dev/gpiochip1:3"},
      {"gpio:gpiochip0", false, hal::InputKind::none, "gpio:CHIP:LINE"},
      {"gpio:gpiochip0:x", false, hal::InputKind::none, "the line is its offset on the chip"},
      {"gpio::4", false, hal::InputKind::none, "gpio:CHIP:LINE"},
      {"gpio:chip 0:4", false, hal::InputKind::none, "gpio:CHIP:LINE"},
      {"gpio:gpiochip0:1024", false, hal::InputKind::none, "0..1023"},
      {"gpio:gpiochip0:-1", false, hal::InputKind::none, "0..1023"},
      {"sim:estop", true, hal::InputKind::sim, "estop"},
      {"sim:", false, hal::InputKind::none, "sim:NAME"},
      {"sim:a/b", false, hal::InputKind::none, "sim:NAME"},
      {"relay:1", false, hal::InputKind::none, "drive:JOINT:bitN, gpio:CHIP:LINE, sim:NAME"},
      {"drive", false, hal::InputKind::none, "drive:JOINT:bitN"},
  };
  for (const Case& c : cases) {
    hal::InputSource s;
    char err[160] = {};
    const bool ok = hal::parse_input_source(c.text, s, err, sizeof err);
    CHECK_TEXT(ok == c.ok, c.text);
    if (!ok) {
      STRCMP_CONTAINS_TEXT(c.detail, err, c.text);
      CHECK_TEXT(std::strchr(err, '\n') == nullptr, c.text);
      CHECK_TEXT(std::strncmp(err, "\"", 1) == 0, c.text);  // names the text given
      continue;
    }
    CHECK_TEXT(s.kind == c.kind, c.text);
    char got[96];
    switch (s.kind) {
      case hal::InputKind::drive: std::snprintf(got, sizeof got, "%d %d", s.joint, s.bit); break;
      case hal::InputKind::gpio: std::snprintf(got, sizeof got, "%s:%d", s.chip, s.line); break;
      case hal::InputKind::sim: std::snprintf(got, sizeof got, "%s", s.name); break;
      case hal::InputKind::none: got[0] = '\0'; break;
    }
    STRCMP_EQUAL_TEXT(c.detail, got, c.text);
  }
}

// The configuration refuses a bad source at load, in one line naming the key.
TEST(SafetyInputSources, ConfigurationRefusesABadSourceNamingTheKey) {
  FwConfig c;
  std::string e = load_config_text("[safety]\nestop_input = \"drive:0:bit3\"\n", "t", c, false);
  STRCMP_CONTAINS("safety.estop_input", e.c_str());
  STRCMP_CONTAINS("1-based", e.c_str());
  e = load_config_text("[safety]\nreduced_input = \"gpio:gpiochip0\"\n", "t", c, false);
  STRCMP_CONTAINS("safety.reduced_input", e.c_str());
  e = load_config_text("[safety]\nestop_input_active = \"open\"\n", "t", c, false);
  STRCMP_CONTAINS("safety.estop_input_active", e.c_str());
  e = load_config_text("[safety]\ninput_timeout_ms = 1\n", "t", c, false);
  STRCMP_CONTAINS("safety.input_timeout_ms", e.c_str());
  e = load_config_text("[safety]\nestop_input = \"drive:2:bit16\"\nestop_input_active = \"high\"\n"
                       "reduced_input = \"gpio:gpiochip0:17\"\ninput_debounce_ms = 20\n",
                       "t", c, false);
  STRCMP_EQUAL("", e.c_str());
  STRCMP_EQUAL("drive:2:bit16", c.safety_estop_input.c_str());
  STRCMP_EQUAL("high", c.safety_estop_input_active.c_str());
  DOUBLES_EQUAL(20, c.safety_input_debounce_ms, 0);
}

// The arm and the build: a drive input beyond the arm's joints, and a GPIO input in a build
// without libgpiod, are refused by App::build naming the key.
TEST(SafetyInputSources, AppRefusesWhatItCannotRead) {
  test::SimApp app;
  hal::ManualClock clock;
  FwConfig c = with_inputs("drive:7:bit16", "");
  c.can = "sim";
  std::string e = app.build(c, &clock);
  STRCMP_CONTAINS("safety.estop_input: \"drive:7:bit16\": the robot has 6 joints", e.c_str());
  if (!hal::gpiod_available()) {
    test::SimApp app2;
    FwConfig g = with_inputs("", "gpio:gpiochip0:17");
    g.can = "sim";
    e = app2.build(g, &clock);
    STRCMP_CONTAINS("safety.reduced_input", e.c_str());
    STRCMP_CONTAINS("libgpiod", e.c_str());
  }
}

TEST_GROUP(InputWatch){};

// Active low: low asserts at once, a release counts after the debounce without a break, a lost
// read asserts at once; active high the other way round.
TEST(InputWatch, AssertAtOnceReleaseAfterDebounceLostAsserts) {
  hal::SimInput in("x");
  hal::InputWatch w;
  const hal::Duration ms = hal::kMillisecond;
  w.configure(&in, true, 10 * ms);
  in.set(hal::InputLevel::high);
  CHECK(!w.update(0));
  in.set(hal::InputLevel::low);
  CHECK(w.update(1 * ms));  // at once
  in.set(hal::InputLevel::high);
  CHECK(w.update(2 * ms));
  CHECK(w.update(11 * ms));  // 9 ms released
  in.set(hal::InputLevel::low);
  CHECK(w.update(12 * ms));  // a bounce: the debounce starts again
  in.set(hal::InputLevel::high);
  CHECK(w.update(13 * ms));
  CHECK(w.update(22 * ms));
  CHECK(!w.update(23 * ms));  // 10 ms released without a break
  in.set(hal::InputLevel::lost);
  CHECK(w.update(24 * ms));
  CHECK(w.lost());
  STRCMP_CONTAINS("sim:x", in.why_lost());
  hal::InputWatch hi;
  hi.configure(&in, false, 0);
  in.set(hal::InputLevel::low);
  CHECK(!hi.update(0));
  in.set(hal::InputLevel::high);
  CHECK(hi.update(ms));
  in.set(hal::InputLevel::low);
  CHECK(!hi.update(2 * ms));  // no debounce: released at once
  hal::InputWatch none;
  CHECK(!none.update(0));
}

// DriveBitInput's fail-safe reasons: a drive that does not report 60FDh, none received yet, an
// old one (older than its timeout); in time, the bit.
TEST(InputWatch, DriveBitLostWhenNotMappedNotYetOrStale) {
  FeedbackBus bus;
  const hal::Duration ms = hal::kMillisecond;
  hal::DriveBitInput in(bus, 0, 16, 20 * ms);
  STRCMP_EQUAL("drive:1:bit16", in.source());
  {  // pending (mapped, nothing yet, within the timeout): the watch keeps its state
    FeedbackBus b2;
    b2.fb.has_inputs = true;
    hal::DriveBitInput in2(b2, 0, 16, 20 * ms);
    hal::InputWatch w;
    w.configure(&in2, true, 0);
    CHECK(!w.update(0));
    CHECK(!w.update(20 * ms));
    CHECK(!w.lost());
    CHECK(w.update(21 * ms));  // the timeout passed without one: lost, asserted
    CHECK(w.lost());
  }
  CHECK(in.read(100 * ms) == hal::InputLevel::lost);
  STRCMP_CONTAINS("does not report its digital inputs (60FDh not mapped)", in.why_lost());
  bus.fb.has_inputs = true;
  CHECK(in.read(120 * ms) == hal::InputLevel::pending);  // within 20 ms of the first read
  CHECK(in.read(121 * ms) == hal::InputLevel::lost);
  STRCMP_CONTAINS("no digital inputs (60FDh) received from joint 1's drive in 21.0 ms", in.why_lost());
  bus.fb.inputs_time = 90 * ms;
  bus.fb.digital_inputs = 1u << 16;
  CHECK(in.read(100 * ms) == hal::InputLevel::high);
  STRCMP_EQUAL("", in.why_lost());
  bus.fb.digital_inputs = 1u << 15;
  CHECK(in.read(110 * ms) == hal::InputLevel::low);
  CHECK(in.read(110 * ms + 1) == hal::InputLevel::lost);
  STRCMP_EQUAL("drive:1:bit16: joint 1's digital inputs (60FDh) not received for 20.0 ms", in.why_lost());
}

// A GPIO line on a chip that does not exist (or a build without libgpiod) reads lost, in one
// line; no gpio-sim / gpio-mockup on these machines, so a line's levels are not tested here.
TEST(InputWatch, GpiodWithoutAChipIsLost) {
  const hal::Duration ms = hal::kMillisecond;
  hal::GpiodInput in("servoarm-no-such-chip", 3, ms, 100 * ms);
  STRCMP_EQUAL("gpio:servoarm-no-such-chip:3", in.source());
  CHECK(in.read(0) == hal::InputLevel::lost);
  if (!hal::gpiod_available()) {
    CHECK(!in.start());
    STRCMP_CONTAINS("built without libgpiod", in.why_lost());
    return;
  }
  CHECK(in.start());
  for (int i = 0; i < 2000 && in.polls() == 0; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  CHECK(in.polls() > 0);
  CHECK(in.read(ms) == hal::InputLevel::lost);
  STRCMP_CONTAINS("gpio:servoarm-no-such-chip:3: the chip cannot be opened", in.why_lost());
  CHECK(std::strchr(in.why_lost(), '\n') == nullptr);
  in.stop();
  // the thread stopped: its count no longer moves (a lost line stays lost)
  CHECK(in.read(500 * ms) == hal::InputLevel::lost);
}

TEST_GROUP(SafetyInputs){};

// The simulated e-stop input asserted in the middle of a move: emergency stop within 2 cycles,
// its event naming the input; `reset` refused while it is asserted, accepted once it is released.
TEST(SafetyInputs, EstopInputStopsAMoveAndBlocksReset) {
  Rig r(with_inputs("sim:estop", ""));
  hal::SimInput* in = r.app.sim_input("estop");
  CHECK(in != nullptr);
  r.enable();
  r.start_move(200);
  in->set(hal::InputLevel::low);  // active low: the contact opened
  const int n = cycles_to_estop(r, 50);
  std::printf("\n  e-stop input (sim) asserted -> estop state after %d cycle(s)\n", n);
  CHECK(n <= 2);
  CHECK(r.tel().estop_latency_ns >= 0);
  STRCMP_CONTAINS("emergency stop: e-stop input sim:estop asserted", r.events().c_str());
  CHECK(r.app.ctl->motions().empty());
  r.cycles(3000);
  ControlResult reset = r.svc().control(RequestOp::reset);
  CHECK(!reset.ok());
  STRCMP_CONTAINS("the e-stop input sim:estop is asserted: release it first", reset.reason.c_str());
  CHECK(r.tel().state == ArmState::estop);
  in->set(hal::InputLevel::high);
  r.cycles(20);  // more than the 10 ms debounce
  STRCMP_CONTAINS("e-stop input sim:estop released", r.events().c_str());
  reset = r.svc().control(RequestOp::reset);
  CHECK_TEXT(reset.ok(), reset.reason.c_str());
  r.enable();
}

// An e-stop input that cannot be read stops the arm, and says why in one line.
TEST(SafetyInputs, EstopInputLostStops) {
  Rig r(with_inputs("sim:estop", ""));
  r.enable();
  r.start_move(200);
  r.app.sim_input("estop")->set(hal::InputLevel::lost);
  CHECK(cycles_to_estop(r, 50) <= 2);
  STRCMP_CONTAINS("emergency stop: e-stop input cannot be read: sim:estop cannot be read", r.events().c_str());
  CHECK(r.tel().safety_inputs & 2u);
}

// The e-stop on bit 16 of joint 2's drive (60FDh in TPDO3): released (high) at start, cleared
// in the middle of a move -> emergency stop within 3 cycles (the drive samples it at a SYNC, its
// TPDO3 is read the next cycle), the event naming the input.
TEST(SafetyInputs, DriveBitEstopStopsAMove) {
  Rig r(with_inputs("drive:2:bit16", ""), [](test::SimApp& a) { a.plant->arm().at(1).set_input_bits(1u << 16, 1u << 16); });
  CHECK(r.app.canopen().config().joints[1].digital_inputs);
  CHECK(!r.app.canopen().config().joints[0].digital_inputs);
  r.enable();
  CHECK(r.tel().safety_inputs == 0);
  r.start_move(200);
  r.app.plant->arm().at(1).set_input_bits(1u << 16, 0);
  const int n = cycles_to_estop(r, 50);
  std::printf("\n  e-stop input (drive:2:bit16) cleared -> estop state after %d cycle(s)\n", n);
  CHECK(n <= 3);
  STRCMP_CONTAINS("emergency stop: e-stop input drive:2:bit16 asserted", r.events().c_str());
}

// The drive carrying the e-stop input falls silent: its 60FDh goes stale after
// safety.input_timeout_ms and the arm stops naming the input, before the feedback timeout.
TEST(SafetyInputs, DriveBitEstopLostWhenTheDriveFallsSilent) {
  FwConfig c = with_inputs("drive:2:bit16", "");
  c.safety_input_timeout_ms = 20;
  c.feedback_timeout_ms = 200;
  Rig r(c, [](test::SimApp& a) { a.plant->arm().at(1).set_input_bits(1u << 16, 1u << 16); });
  r.enable();
  r.start_move(200);
  r.app.plant->arm().at(1).faults().silent = true;
  const int n = cycles_to_estop(r, 200);
  std::printf("\n  joint 2's drive silent (input timeout 20 ms) -> estop state after %d cycle(s)\n", n);
  CHECK(n <= 25);
  STRCMP_CONTAINS("emergency stop: e-stop input cannot be read: drive:2:bit16: joint 2's digital inputs (60FDh) not "
                  "received for",
                  r.events().c_str());
}

// The Reduced input: asserted -> Reduced mode in telemetry, status and planning (a line is
// planned at the Reduced TCP speed), a running line slowed on its path; released -> the mode
// `safety` set; lost -> Reduced, said in one line.
TEST(SafetyInputs, ReducedInputReducesAndLostReduces) {
  FwConfig c = with_inputs("", "sim:reduced");
  c.safety_tcp_speed_mm_s = 250;
  c.safety_reduced_tcp_speed_mm_s = 50;
  c.max_linear_speed_mm_s = 250;
  Rig r(c);
  hal::SimInput* in = r.app.sim_input("reduced");
  r.enable();
  CHECK(r.tel().safety_mode == static_cast<std::uint8_t>(kin::SafetyMode::normal));
  // at a pose clear of the wrist's singularity, a line at 200 mm/s, the Reduced input asserted
  // while it runs
  const kin::JointVector q = test::puma_work_pose();
  const MoveResult wr = r.movej(q);
  CHECK_TEXT(wr.ok(), wr.reason.c_str());
  r.until_idle(30000);
  kin::Pose p;
  (void)kin::forward(r.app.chain, q, p);
  p.translation().y() += 0.15;
  const MoveResult mr = r.movel(p, 0.2);
  CHECK_TEXT(mr.ok(), (std::string(to_string(mr.error)) + " " + to_string(mr.refusal) + " " + mr.reason).c_str());
  for (int i = 0; i < 400 && r.tel().state != ArmState::moving; ++i) r.cycle();
  r.cycles(300);
  in->set(hal::InputLevel::low);
  r.cycle();
  CHECK(r.tel().safety_mode == static_cast<std::uint8_t>(kin::SafetyMode::reduced));
  CHECK(r.svc().status().safety_mode == kin::SafetyMode::reduced);
  CHECK(r.svc().plan_safety_mode() == kin::SafetyMode::reduced);
  CHECK(r.svc().safety_mode() == kin::SafetyMode::normal);  // the operator's mode is unchanged
  STRCMP_CONTAINS("safety mode reduced: Reduced input sim:reduced asserted", r.events().c_str());
  double scale_min = 1;
  for (int i = 0; i < 600 && r.tel().state == ArmState::moving; ++i) {
    r.cycle();
    scale_min = std::fmin(scale_min, r.tel().speed_scale);
  }
  std::printf("\n  Reduced input mid-line (200 mm/s, Reduced 50 mm/s): speed scale down to %.3f, stops %u\n", scale_min,
              static_cast<unsigned>(r.tel().safety_stops));
  CHECK(scale_min < 0.3 || r.tel().safety_stops > 0);  // slowed on its path (or the existing rules stopped it)
  for (int i = 0; i < 30000 && (r.tel().state == ArmState::moving || r.tel().state == ArmState::stopping); ++i) r.cycle();
  in->set(hal::InputLevel::high);
  r.cycles(20);
  CHECK(r.tel().safety_mode == static_cast<std::uint8_t>(kin::SafetyMode::normal));
  STRCMP_CONTAINS("safety mode normal: Reduced input sim:reduced released", r.events().c_str());
  in->set(hal::InputLevel::lost);
  r.cycle();
  CHECK(r.tel().safety_mode == static_cast<std::uint8_t>(kin::SafetyMode::reduced));
  CHECK(r.tel().safety_inputs & 8u);
  STRCMP_CONTAINS("safety mode reduced: Reduced input cannot be read: sim:reduced cannot be read", r.events().c_str());
}

// Both inputs configured (a drive bit each): no allocation on the control thread in any cycle,
// moving, stopped by the input, released.
TEST(SafetyInputs, NoAllocationInTheCycle) {
  Rig r(with_inputs("drive:2:bit16", "drive:3:bit17"), [](test::SimApp& a) {
    a.plant->arm().at(1).set_input_bits(1u << 16, 1u << 16);
    a.plant->arm().at(2).set_input_bits(1u << 17, 1u << 17);
  });
  r.enable();
  r.start_move(200);
  r.count_allocs = true;
  r.cycles(100);
  r.app.plant->arm().at(2).set_input_bits(1u << 17, 0);
  r.cycles(100);
  r.app.plant->arm().at(1).set_input_bits(1u << 16, 0);
  r.cycles(300);
  r.app.plant->arm().at(1).set_input_bits(1u << 16, 1u << 16);
  r.cycles(100);
  CHECK(r.tel().state == ArmState::estop);
  LONGS_EQUAL(0, r.rt_allocs);
}

