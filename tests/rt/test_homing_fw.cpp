// SPDX-License-Identifier: Apache-2.0
// The firmware's homing on the puma560 with virtual CiA 402 drives on the in-process
// bus (ManualClock, single-threaded; every control cycle counted for allocations): the homing
// order's groups run one after another (seen from the drives' own 6061h mode display, not
// from the controller), where each joint ends up against the simulated switch, a failing
// joint disables the arm naming it, stop / ! / Ctrl-X abort leaving the joints unhomed and the
// arm at rest, the gating of an unhomed arm, $H in the GRBL dialect, park / G28.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <functional>
#include <string>
#include <vector>

#include "alloc_counter.hpp"
#include "sim_app.hpp"
#include "servoarm/hal/scaling.hpp"
#include "servoarm/rt/controller.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;

namespace {

constexpr double kDeg = M_PI / 180.0;
const double kCountsPerRad = hal::JointScaling{}.counts_per_si();  // bus defaults: 131072 counts/rev, gear 1
double counts(double deg) { return deg * kDeg * kCountsPerRad; }
constexpr double kInf = sim::DriveSwitches::kNone;

struct Rig {
  hal::ManualClock clock;
  test::SimApp app;
  Session s;
  hal::Duration period = hal::kMillisecond;
  std::size_t rt_allocs = 0;
  /// Per cycle, per joint: the drive's mode display (6061h) as the drive has it.
  std::vector<std::array<std::int8_t, 6>> modes;
  std::string native, grbl;  ///< events drained so far

  explicit Rig(FwConfig cfg, const std::function<void(Rig&)>& drives = {}) {
    cfg.can = "sim";
    const std::string e = app.build(cfg, &clock);
    if (!e.empty()) FAIL(e.c_str());
    clock.set_idle_hook([this](hal::TimePoint t) { app.plant->step(t); });
    if (drives) drives(*this);
    const std::string b = app.boot();
    if (!b.empty()) FAIL(b.c_str());
    app.console->set_idle([this] { cycle(); });
  }
  ~Rig() { clock.set_idle_hook(nullptr); }
  sim::VirtualDrive& drive(int j) { return app.plant->arm().at(static_cast<std::size_t>(j)); }
  void cycle() {
    test::alloc_count_begin();
    app.ctl->cycle(clock.now());
    rt_allocs += test::alloc_count_end();
    clock.advance(period);
    std::array<std::int8_t, 6> m{};
    for (int j = 0; j < 6; ++j) m[static_cast<std::size_t>(j)] = drive(j).mode_display();
    modes.push_back(m);
    app.console->drain_events(native, grbl);
  }
  void run(double secs) {
    const auto n = static_cast<int>(secs * 1e9 / static_cast<double>(period));
    for (int i = 0; i < n; ++i) {
      cycle();
      app.console->poll(s);
    }
  }
  std::string cmd(const std::string& line) {
    s.out.clear();
    app.console->execute(s, line);
    for (int i = 0; i < 120000 && app.console->busy(s); ++i) {
      cycle();
      app.console->poll(s);
    }
    return s.out;
  }
  std::string feed(const std::string& bytes) {
    s.out.clear();
    app.console->feed(s, bytes);
    return s.out;
  }
  void enable() {
    const std::string a = cmd("enable");
    if (a.rfind("ok", 0) != 0) FAIL(("enable: " + a).c_str());
  }
  Telemetry tel() const { return app.ctl->telemetry(); }
};

bool is_ok(const std::string& a) { return a.rfind("ok", 0) == 0 || a.find("\nok") != std::string::npos; }
bool has(const std::string& a, const std::string& b) { return a.find(b) != std::string::npos; }

FwConfig six_drives() {
  FwConfig c;
  c.drives.resize(6);
  for (DriveConfig& d : c.drives) {
    d.homing_speed_switch = 20;
    d.homing_speed_zero = 2;
    d.homing_acceleration = 200;
    d.homing_timeout_s = 20;
  }
  return c;
}

/// One joint (j) homing with method 19 and no switch: the search runs until the timeout.
FwConfig searching(int j, double timeout_s) {
  FwConfig c = six_drives();
  c.drives[static_cast<std::size_t>(j)].homing_method = "19";
  c.drives[static_cast<std::size_t>(j)].homing_speed_switch = 5;
  c.drives[static_cast<std::size_t>(j)].homing_timeout_s = timeout_s;
  return c;
}

}  // namespace

TEST_GROUP(FwHoming){};

// homing.order = [[3], [2], [1], [4, 5, 6]]: the drives' own mode display (6061h = 6, homing
// mode) shows joint 3 first, then 2, then 1, then 4-6 together; every joint reads its
// homing.offset at the switch edge (within a count of the drive's physical mark); the
// setpoint is the measured (jumped) position afterwards; park then moves; nothing allocates.
TEST(FwHoming, OrderGroupsRunOneAfterAnotherAndEveryJointLandsOnItsMark) {
  FwConfig c = six_drives();
  c.homing_order = {{3}, {2}, {1}, {4, 5, 6}};
  const double off_deg[6] = {10, -5, 5, 0, 0, 0};
  const char* method[6] = {"19", "21", "19", "35", "35", "37"};
  for (int j = 0; j < 6; ++j) {
    c.drives[static_cast<std::size_t>(j)].homing_method = method[j];
    c.drives[static_cast<std::size_t>(j)].homing_offset = off_deg[j];
  }
  const double edge[3] = {counts(4), counts(-3), counts(2)};  // physical switch edges of joints 1-3
  Rig r(c, [&](Rig& rig) {
    rig.drive(0).switches().home_lo = edge[0];  // positive home switch (19): active at or above
    rig.drive(0).switches().home_hi = kInf;
    rig.drive(1).switches().home_lo = -kInf;    // negative home switch (21): active at or below
    rig.drive(1).switches().home_hi = edge[1];
    rig.drive(2).switches().home_lo = edge[2];
    rig.drive(2).switches().home_hi = kInf;
  });
  r.enable();
  CHECK(!r.tel().all_homed());
  const std::size_t from = r.modes.size();
  const std::string a = r.cmd("home");
  CHECK_TEXT(has(a, "ok homing: group 1 of 4 (joint 3)"), a.c_str());
  const std::string w = r.cmd("wait");
  CHECK_TEXT(is_ok(w), (w + r.native).c_str());
  const Telemetry t = r.tel();
  CHECK(t.state == ArmState::idle);
  CHECK(t.all_homed());
  // the timeline of the drives' mode displays
  long first[6], last[6];
  for (int j = 0; j < 6; ++j) first[j] = last[j] = -1;
  for (std::size_t i = from; i < r.modes.size(); ++i)
    for (int j = 0; j < 6; ++j)
      if (r.modes[i][static_cast<std::size_t>(j)] == 6) {
        if (first[j] < 0) first[j] = static_cast<long>(i);
        last[j] = static_cast<long>(i);
      }
  for (int j = 0; j < 6; ++j) CHECK_TEXT(first[j] >= 0, ("joint never in homing mode: " + std::to_string(j + 1)).c_str());
  CHECK(last[2] < first[1]);  // group [3] ends before [2] starts
  CHECK(last[1] < first[0]);  // [2] before [1]
  for (int j = 3; j < 6; ++j) CHECK(last[0] < first[j]);  // [1] before [4, 5, 6]
  // 4, 5, 6 together: their homing-mode spans overlap
  const long lo = std::max(first[3], std::max(first[4], first[5])), hi = std::min(last[3], std::min(last[4], last[5]));
  CHECK_TEXT(lo <= hi, "joints 4-6 not homed together");
  for (int j = 0; j < 6; ++j) LONGS_EQUAL(8, r.drive(j).mode_display());  // back to CSP
  // positions: the drive's mark is the switch edge (to a count), and the joint reads its offset there
  for (int j = 0; j < 3; ++j) {
    sim::VirtualDrive& d = r.drive(j);
    DOUBLES_EQUAL_TEXT(edge[j], d.home_mark(), 1.0, ("mark of joint " + std::to_string(j + 1)).c_str());
    const double want = off_deg[j] * kDeg + (d.physical_position() - d.home_mark()) / kCountsPerRad;
    DOUBLES_EQUAL_TEXT(want, t.q_act[static_cast<std::size_t>(j)], 1.5 / kCountsPerRad, ("joint " + std::to_string(j + 1)).c_str());
  }
  // the setpoint was re-taken from the measured (jumped) positions
  for (int j = 0; j < 6; ++j)
    DOUBLES_EQUAL(t.q_act[static_cast<std::size_t>(j)], t.q_cmd[static_cast<std::size_t>(j)], 2.0 / kCountsPerRad);
  CHECK_TEXT(has(r.native, "homing: joint 3 homing (group 1 of 4, cia402)"), r.native.c_str());
  CHECK_TEXT(has(r.native, "homing: joint 3 homed"), r.native.c_str());
  CHECK_TEXT(has(r.native, "homing: homing done: every joint homed"), r.native.c_str());
  const std::string st = r.cmd("status");
  CHECK_TEXT(has(st, "homing=[homed homed homed homed homed homed]"), st.c_str());
  CHECK_TEXT(is_ok(r.cmd("park")), r.native.c_str());
  CHECK(is_ok(r.cmd("wait")));
  CHECK(r.tel().state == ArmState::idle);
  LONGS_EQUAL(0, r.rt_allocs);
}

// A joint that fails (its switch is never found: the timeout; or the drive's homing error
// after its maximum travel) leaves the arm disabled, the joint named, the cause reported.
TEST(FwHoming, AFailingJointDisablesTheArmNamingIt) {
  for (const bool timeout : {true, false}) {
    Rig r(searching(1, timeout ? 0.4 : 20), [&](Rig& rig) {
      if (!timeout) rig.drive(1).switches().max_travel = counts(1);  // homing error (bit 13) after 1 deg
    });
    r.enable();
    CHECK(is_ok(r.cmd("home")));
    const std::string w = r.cmd("wait");
    CHECK_TEXT(has(w, "error: fault") && has(w, "joint 2"), w.c_str());
    r.run(0.2);
    const Telemetry t = r.tel();
    CHECK(t.state == ArmState::fault);
    CHECK(t.cause == FaultCause::homing_failed);
    LONGS_EQUAL(1, t.fault_joint);
    CHECK_TEXT(has(t.fault_text, timeout ? "homing timeout" : "homing homing_error"), t.fault_text);
    CHECK_TEXT(has(r.native, "alarm: fault joint 2"), r.native.c_str());
    for (std::size_t j = 0; j < 6; ++j) CHECK(r.app.servo->feedback(j).state == hal::JointState::disabled);
    CHECK(!((t.homed >> 1) & 1u));
    CHECK_TEXT(has(r.cmd("status"), "homing=[absolute failed absolute"), r.s.out.c_str());
    // nothing moves until reset + enable; the joint is still not homed then
    CHECK(has(r.cmd("movej 0 0 0 0 0 0"), "error: fault"));
    CHECK(is_ok(r.cmd("reset")));
    r.enable();
    CHECK_TEXT(has(r.cmd("movej 0 -10 0 0 0 0"), "error: not_homed joint 2 not homed"), r.s.out.c_str());
    LONGS_EQUAL(0, r.rt_allocs);
  }
}

// stop, ! (feed hold) and Ctrl-X abort the homing cycle: the joint stays unhomed, the arm comes to
// rest (stop / !: idle, the drive back in CSP; Ctrl-X: an e-stop, drives disabled).
TEST(FwHoming, StopHoldAndCtrlXAbortLeavingTheJointUnhomedAndTheArmAtRest) {
  for (const char* how : {"stop", "!", "\x18"}) {
    Rig r(searching(0, 60));
    r.enable();
    CHECK(is_ok(r.cmd("home")));
    r.run(0.5);
    CHECK(r.tel().state == ArmState::homing);
    const double moved = std::fabs(r.drive(0).physical_position());
    CHECK_TEXT(moved > counts(1), how);  // the drive was searching
    if (std::string(how) == "stop") CHECK_TEXT(has(r.cmd("stop"), "ok homing aborted: joint 1 left unhomed"), r.s.out.c_str());
    else r.feed(how);
    r.run(0.5);
    const Telemetry t = r.tel();
    const bool estop = how[0] == '\x18';
    CHECK_TEXT(t.state == (estop ? ArmState::estop : ArmState::idle), how);
    CHECK_TEXT(!((t.homed >> 0) & 1u), how);
    const double p0 = r.drive(0).physical_position();
    r.run(0.3);
    DOUBLES_EQUAL_TEXT(p0, r.drive(0).physical_position(), 2.0, how);  // at rest
    if (estop) {
      for (std::size_t j = 0; j < 6; ++j) CHECK(r.app.servo->feedback(j).state == hal::JointState::disabled);
    } else {
      LONGS_EQUAL(8, r.drive(0).mode_display());
      CHECK_TEXT(has(r.cmd("status"), "homing=[unhomed absolute"), r.s.out.c_str());
      CHECK(has(r.cmd("movel 500 100 300"), "error: not_homed"));
    }
    LONGS_EQUAL(0, r.rt_allocs);
  }
}

// An unhomed arm refuses Cartesian moves, G-code moves, movej, park and tool jogs naming the
// joints; a joint jog runs at homing.unhomed_jog_pct of its speed (peak joint speed checked
// against the joint's limit); `home j1` homes joint 1 alone, then everything is allowed.
TEST(FwHoming, AnUnhomedArmRefusesAllButSlowJointJogs) {
  FwConfig c = searching(0, 20);
  c.homing_unhomed_jog_pct = 25;
  Rig r(c, [](Rig& rig) {
    rig.drive(0).switches().home_lo = counts(2);
    rig.drive(0).switches().home_hi = kInf;
  });
  r.enable();
  for (const char* line : {"movel 500 100 300", "movej 0 -10 0 0 0 0", "park", "G1 X500 F600", "G28", "jog x +5"}) {
    const std::string a = r.cmd(line);
    CHECK_TEXT(has(a, "error: not_homed") && has(a, "joint 1 not homed"), (std::string(line) + ": " + a).c_str());
  }
  CHECK(r.app.ctl->motions().empty());
  // a joint jog runs, at a quarter of its speed
  const double vmax = r.app.ctl->limits().dyn[1].max_velocity;
  const double q0 = r.tel().q_cmd[1];
  CHECK_TEXT(is_ok(r.cmd("jog j2 -30 speed=100")), r.s.out.c_str());
  double peak = 0, prev = q0;
  for (int i = 0; i < 20000 && r.tel().state == ArmState::jogging; ++i) {
    r.cycle();
    const double q = r.tel().q_cmd[1];
    peak = std::fmax(peak, std::fabs(q - prev) / 1e-3);
    prev = q;
  }
  DOUBLES_EQUAL(q0 - 30 * kDeg, r.tel().q_cmd[1], 1e-6);
  CHECK_TEXT(peak <= 0.25 * vmax * (1 + 1e-6), std::to_string(peak / vmax).c_str());
  CHECK_TEXT(peak >= 0.2 * vmax, std::to_string(peak / vmax).c_str());
  // home joint 1 alone, then moves are allowed
  CHECK_TEXT(has(r.cmd("home j1"), "ok homing: group 1 of 1 (joint 1)"), r.s.out.c_str());
  CHECK_TEXT(is_ok(r.cmd("wait")), r.s.out.c_str());
  CHECK(r.tel().all_homed());
  CHECK_TEXT(is_ok(r.cmd("movej 0 -10 0 0 0 0")), r.s.out.c_str());
  CHECK(is_ok(r.cmd("wait")));
  LONGS_EQUAL(0, r.rt_allocs);
}

// GRBL: $H answers when the cycle has ended, the report says Home meanwhile; a failure is ALARM:9.
TEST(FwHoming, DollarHInTheGrblDialect) {
  for (const bool fails : {false, true}) {
    Rig r(searching(0, fails ? 0.3 : 20), [&](Rig& rig) {
      if (fails) return;
      rig.drive(0).switches().home_lo = counts(2);
      rig.drive(0).switches().home_hi = kInf;
    });
    r.s.dialect = Dialect::grbl;
    CHECK(is_ok(r.cmd("$X")));
    r.s.out.clear();
    r.app.console->execute(r.s, "$H");
    CHECK(r.app.console->busy(r.s));  // not answered yet
    CHECK_TEXT(!has(r.s.out, "ok\n") && !has(r.s.out, "error:"), r.s.out.c_str());
    for (int i = 0; i < 50; ++i) r.cycle();
    CHECK_TEXT(r.app.console->grbl_report(r.s).rfind("<Home|", 0) == 0, r.app.console->grbl_report(r.s).c_str());
    for (int i = 0; i < 60000 && r.app.console->busy(r.s); ++i) {
      r.cycle();
      r.app.console->poll(r.s);
    }
    if (fails) {
      CHECK_TEXT(has(r.s.out, "error:9"), r.s.out.c_str());
      CHECK_TEXT(has(r.grbl, "ALARM:9"), r.grbl.c_str());
      CHECK(r.app.console->grbl_report(r.s).rfind("<Alarm|", 0) == 0);
    } else {
      CHECK_TEXT(has(r.s.out, "ok\n") && !has(r.s.out, "error"), r.s.out.c_str());
      CHECK(r.tel().all_homed());
      CHECK(r.app.console->grbl_report(r.s).rfind("<Idle|", 0) == 0);
    }
  }
}

// park and G28 move to the park pose (motion.home_deg).
TEST(FwHoming, ParkAndG28GoToTheParkPose) {
  FwConfig c;
  c.home_deg = {10, -20, 30, 0, -40, 5};
  Rig r(c);
  r.enable();
  for (const char* line : {"park", "G28"}) {
    CHECK(is_ok(r.cmd("movej 0 0 0 0 0 0")));
    CHECK(is_ok(r.cmd("wait")));
    CHECK_TEXT(is_ok(r.cmd(line)), r.s.out.c_str());
    CHECK(is_ok(r.cmd("wait")));
    r.run(0.2);
    const Telemetry t = r.tel();
    for (int j = 0; j < 6; ++j)
      DOUBLES_EQUAL_TEXT(c.home_deg[static_cast<std::size_t>(j)] * kDeg, t.q_act[static_cast<std::size_t>(j)], 0.01 * kDeg, line);
  }
  LONGS_EQUAL(0, r.rt_allocs);
}

namespace {

FwConfig hard_stop_joint2(double timeout_s) {
  FwConfig c = six_drives();
  DriveConfig& d = c.drives[1];
  d.homing_method = "hard_stop";
  d.homing_direction = -1;          // towards the negative stop
  d.homing_speed_switch = 5;        // deg/s: the slow approach
  d.homing_acceleration = 50;       // deg/s^2
  d.homing_following_limit = 0.5;   // deg of following error = contact
  d.homing_backoff = 3;             // deg back from the stop
  d.homing_offset = -60;            // deg there
  d.homing_timeout_s = timeout_s;
  return c;
}

/// Runs the cycles of a homing started by `home` until the arm leaves homing (or `limit_s`),
/// recording per cycle what the drive of joint j does.
struct Watch {
  double peak_speed = 0;   ///< counts/s, over 100 ms windows of the shaft position
  std::vector<double> pos; ///< the shaft, per cycle
  bool touched = false;    ///< the shaft was at the end stop
  bool csp = true;         ///< the drive stayed in cyclic synchronous position (6061h = 8)
  double secs = 0;
};
Watch watch_homing(Rig& r, int j, double limit_s) {
  Watch w;
  const auto n = static_cast<int>(limit_s * 1e3);
  for (int i = 0; i < n && (r.tel().state == ArmState::homing || i == 0); ++i) {
    r.cycle();
    r.app.console->poll(r.s);
    sim::VirtualDrive& d = r.drive(j);
    w.pos.push_back(d.physical_position());
    if (w.pos.size() > 100) w.peak_speed = std::max(w.peak_speed, std::fabs(w.pos.back() - w.pos[w.pos.size() - 101]) / 0.1);
    w.touched = w.touched || d.at_end_stop();
    w.csp = w.csp && d.mode_display() == 8;
    w.secs += 1e-3;
  }
  return w;
}

}  // namespace

// hard_stop through the firmware (console `home`, controller, CANopen master, virtual drive
// with a mechanical end stop): the master drives joint 2 slowly in cyclic position mode (the
// drive never leaves CSP; peak speed homing.speed_switch) until the following error passes
// homing.following_limit at the stop, backs off homing.backoff and takes homing.offset there:
// the shaft ends at the stop + 3 deg, the joint reads -60 deg, homed; the arm can park.
TEST(FwHoming, HardStopFindsTheEndStopBacksOffAndTakesTheOffset) {
  const double stop = counts(-8);
  Rig r(hard_stop_joint2(20), [&](Rig& rig) { rig.drive(1).switches().end_neg = stop; });
  r.enable();
  CHECK(!r.tel().all_homed());
  CHECK_TEXT(has(r.cmd("home"), "ok homing: group 1 of 1"), r.s.out.c_str());
  const Watch w = watch_homing(r, 1, 20);
  CHECK_TEXT(is_ok(r.cmd("wait")), (r.s.out + r.native).c_str());
  const Telemetry t = r.tel();
  CHECK(t.state == ArmState::idle);
  CHECK(t.all_homed());
  CHECK(w.touched);  // it went to the stop
  CHECK(w.csp);      // in cyclic synchronous position mode throughout (the master moves it)
  CHECK(!r.drive(1).at_end_stop());  // and came back off it
  CHECK_TEXT(w.peak_speed <= counts(5) * 1.1, std::to_string(w.peak_speed / counts(1)).c_str());  // slowly: 5 deg/s
  CHECK(w.peak_speed >= counts(5) * 0.9);
  DOUBLES_EQUAL(stop + counts(3), r.drive(1).physical_position(), 2.0);         // the stop + backoff, to 2 counts
  DOUBLES_EQUAL(-60 * kDeg, t.q_act[1], 2.0 / kCountsPerRad);                    // reads homing.offset there
  DOUBLES_EQUAL(t.q_act[1], t.q_cmd[1], 2.0 / kCountsPerRad);                    // setpoint re-taken
  CHECK_TEXT(has(r.native, "homing: joint 2 homing (group 1 of 1, hard_stop)"), r.native.c_str());
  CHECK_TEXT(has(r.native, "homing: joint 2 homed"), r.native.c_str());
  CHECK_TEXT(has(r.cmd("status"), "homing=[absolute homed absolute absolute absolute absolute]"), r.s.out.c_str());
  std::printf("\n  fw hard_stop: joint 2 homed in %.3f s (stop 8 deg away at 5 deg/s, backoff 3 deg), %.2f counts from stop + backoff\n",
              w.secs, r.drive(1).physical_position() - (stop + counts(3)));
  CHECK(is_ok(r.cmd("park")));
  CHECK(is_ok(r.cmd("wait")));
  LONGS_EQUAL(0, r.rt_allocs);
}

// A configured method the drive lacks (6502h without homing mode, armsim --no-homing) is
// refused when armfw starts (App::boot fails), naming the drive's node and the method.
TEST(FwHoming, AMethodTheDriveLacksIsRefusedAtStartNamingTheJoint) {
  FwConfig c = six_drives();
  c.can = "sim";
  c.drives[2].homing_method = "19";
  hal::ManualClock clock;
  test::SimApp app;
  const std::string e = app.build(c, &clock);
  CHECK_TEXT(e.empty(), e.c_str());
  clock.set_idle_hook([&](hal::TimePoint t) { app.plant->step(t); });
  sim::DriveQuirks q;
  q.no_homing = true;
  app.plant->arm().at(2).set_quirks(q);
  const std::string b = app.boot();
  clock.set_idle_hook(nullptr);
  // (The master's bring-up messages number joints from 0: "joint 2 (node 3)" here, while the
  // controller's homing failures say "joint 3"; the node is what both agree on.)
  CHECK_TEXT(has(b, "drive bring-up failed") && has(b, "(node 3)"), b.c_str());
  CHECK_TEXT(has(b, "homing method 19") && has(b, "does not support homing mode"), b.c_str());
}

// The way back to CSP survives a lost SDO request (the VM's starved armsim dropped the 6060h = 8
// write): the master sends it again (up to 3 times) and the joint ends homed, in CSP, and the
// arm moves; 4 lost in a row fail the homing naming the joint.
TEST(FwHoming, ALostModeWriteOnTheWayBackToCspIsSentAgain) {
  for (const int lost : {1, 3, 4}) {
    FwConfig c = six_drives();
    c.drives[0].homing_method = "35";
    Rig r(c);
    sim::DriveQuirks q;
    q.lose_csp_writes = lost;  // after boot: bring-up's own 6060h = 8 went through
    r.drive(0).set_quirks(q);
    r.enable();
    CHECK(is_ok(r.cmd("home")));
    const std::string w = r.cmd("wait");
    const std::string what = std::to_string(lost) + " lost: " + w + r.native;
    if (lost <= 3) {
      CHECK_TEXT(is_ok(w), what.c_str());
      CHECK_TEXT(r.tel().all_homed(), what.c_str());
      LONGS_EQUAL(8, r.drive(0).mode_display());
      CHECK_TEXT(is_ok(r.cmd("park")), r.s.out.c_str());
      CHECK(is_ok(r.cmd("wait")));
    } else {
      CHECK_TEXT(has(w, "error: fault") && has(w, "joint 1"), what.c_str());
    }
    LONGS_EQUAL(0, r.rt_allocs);
  }
}

// homing.torque_limit through the firmware: armfw maps 6077h (torque actual) into TPDO2 for it,
// and the push on the stop is seen by the torque long before the 20 deg following limit would
// see it (that would take 4 s more of pushing at 5 deg/s): the same end position, sooner.
TEST(FwHoming, HardStopByTorqueWhenTheLimitIsSet) {
  FwConfig c = hard_stop_joint2(20);
  c.drives[1].homing_following_limit = 20;  // deg: far beyond what the push reaches first
  c.drives[1].homing_torque_limit = 0.005;  // N m (the drive's 6076h: 1 N m; 6077h per mille)
  const double stop = counts(-8);
  Rig r(c, [&](Rig& rig) { rig.drive(1).switches().end_neg = stop; });
  r.enable();
  CHECK(is_ok(r.cmd("home")));
  const Watch w = watch_homing(r, 1, 20);
  CHECK_TEXT(is_ok(r.cmd("wait")), (r.s.out + r.native).c_str());
  CHECK(r.tel().all_homed());
  CHECK(w.touched);
  CHECK_TEXT(r.app.servo->feedback(1).has_torque, "6077h not mapped");
  CHECK_TEXT(w.secs < 3.5, std::to_string(w.secs).c_str());  // by following error: > 6 s
  DOUBLES_EQUAL(stop + counts(3), r.drive(1).physical_position(), 2.0);
  DOUBLES_EQUAL(-60 * kDeg, r.tel().q_act[1], 2.0 / kCountsPerRad);
  std::printf("\n  fw hard_stop by torque: joint 2 homed in %.3f s\n", w.secs);
  LONGS_EQUAL(0, r.rt_allocs);
}

// No stop within reach: the approach runs until homing.timeout_s; the arm is disabled, the
// fault names joint 2 and the timeout, the joint stays unhomed and nothing moves afterwards.
TEST(FwHoming, HardStopNeverReachedTimesOutNamingTheJoint) {
  Rig r(hard_stop_joint2(1.0));  // no end stop at all
  r.enable();
  CHECK(is_ok(r.cmd("home")));
  const Watch w = watch_homing(r, 1, 5);
  CHECK(!w.touched);
  DOUBLES_EQUAL(1.0, w.secs, 0.05);  // failed at the timeout
  const std::string a = r.cmd("wait");
  CHECK_TEXT(has(a, "error: fault") && has(a, "joint 2"), a.c_str());
  const Telemetry t = r.tel();
  CHECK(t.state == ArmState::fault);
  CHECK(t.cause == FaultCause::homing_failed);
  LONGS_EQUAL(1, t.fault_joint);
  CHECK_TEXT(has(t.fault_text, "joint 2") && has(t.fault_text, "timeout"), t.fault_text);
  CHECK_TEXT(has(r.native, "alarm: fault joint 2"), r.native.c_str());
  CHECK(!((t.homed >> 1) & 1u));
  r.run(0.2);
  for (std::size_t j = 0; j < 6; ++j) CHECK(r.app.servo->feedback(j).state == hal::JointState::disabled);
  const double p0 = r.drive(1).physical_position();
  CHECK(p0 < counts(-3));  // it had moved towards the (missing) stop: about 4.5 deg in 1 s
  r.run(0.5);
  DOUBLES_EQUAL(p0, r.drive(1).physical_position(), 2.0);  // and nothing moves now
  CHECK_TEXT(has(r.cmd("status"), "homing=[absolute failed"), r.s.out.c_str());
  LONGS_EQUAL(0, r.rt_allocs);
}

// Figures (docs/results): the homing time of each joint through the firmware, six methods in the
// order groups [[3], [2], [1], [4, 5, 6]], 1 ms cycle, on the virtual drives; the timeline from the
// controller's telemetry (homing_now per cycle). Asserted: the groups run one after another,
// every joint homed, the whole cycle = the sum of the group spans (to a few cycles).
TEST(FwHoming, FiguresTimePerMethodAndGroup) {
  FwConfig c = six_drives();
  c.homing_order = {{3}, {2}, {1}, {4, 5, 6}};
  const char* method[6] = {"19", "hard_stop", "21", "34", "35", "17"};
  for (int j = 0; j < 6; ++j) c.drives[static_cast<std::size_t>(j)].homing_method = method[j];
  DriveConfig& h = c.drives[1];
  h.homing_direction = -1;
  h.homing_speed_switch = 5;
  h.homing_acceleration = 50;
  h.homing_following_limit = 0.5;
  h.homing_backoff = 3;
  h.homing_offset = -60;
  Rig r(c, [&](Rig& rig) {
    rig.drive(0).switches().home_lo = counts(4);   // 19: positive home switch 4 deg away
    rig.drive(0).switches().home_hi = kInf;
    rig.drive(1).switches().end_neg = counts(-8);  // hard_stop: the end stop 8 deg away
    rig.drive(2).switches().home_lo = -kInf;       // 21: negative home switch, edge 3 deg away
    rig.drive(2).switches().home_hi = counts(-3);
    rig.drive(3).switches().index_phase = counts(5);  // 34: the index pulse 5 deg ahead
    rig.drive(5).switches().neg_limit = counts(-6);   // 17: negative limit switch 6 deg away
  });
  r.enable();
  CHECK(is_ok(r.cmd("home")));
  long start[6], end[6];
  for (int j = 0; j < 6; ++j) start[j] = end[j] = -1;
  long k = 0;
  for (; k < 60000 && (r.tel().state == ArmState::homing || k == 0); ++k) {
    r.cycle();
    r.app.console->poll(r.s);
    const Telemetry t = r.tel();
    for (int j = 0; j < 6; ++j) {
      if ((t.homing_now >> j) & 1u) {
        if (start[j] < 0) start[j] = k;
        end[j] = k + 1;
      }
    }
  }
  CHECK_TEXT(is_ok(r.cmd("wait")), (r.s.out + r.native).c_str());
  CHECK(r.tel().all_homed());
  for (int j = 0; j < 6; ++j) CHECK_TEXT(start[j] >= 0, ("joint never homing: " + std::to_string(j + 1)).c_str());
  CHECK(end[2] <= start[1]);
  CHECK(end[1] <= start[0]);
  for (int j = 3; j < 6; ++j) CHECK(end[0] <= start[j]);
  const long g4 = *std::max_element(end + 3, end + 6) - std::min({start[3], start[4], start[5]});
  const long spans = (end[2] - start[2]) + (end[1] - start[1]) + (end[0] - start[0]) + g4;
  CHECK(std::labs(k - spans) <= 20);
  std::printf("\n  fw homing, order [[3], [2], [1], [4, 5, 6]], 1 ms cycle (ms per joint, from telemetry):\n");
  const char* what[6] = {"19 home switch 4 deg", "hard_stop, stop 8 deg, 5 deg/s", "21 home switch 3 deg",
                         "34 index 5 deg", "35 current position", "17 limit switch 6 deg"};
  const int group[6] = {3, 2, 1, 4, 4, 4};
  for (int j = 0; j < 6; ++j)
    std::printf("    joint %d group %d %-32s %6ld ms\n", j + 1, group[j], what[j], end[j] - start[j]);
  std::printf("    group 4 span %ld ms; whole cycle %ld ms (sum of group spans %ld ms)\n", g4, k, spans);
  LONGS_EQUAL(0, r.rt_allocs);
}

// bus.sdo_timeout_ms / boot_timeout_ms / boot_retry_ms / state_timeout_ms reach the CANopen
// master: a drive whose SDO answers come 150 ms late fails the bring-up with the default
// 100 ms timeout (naming its node) and starts with bus.sdo_timeout_ms = 300.
TEST(FwHoming, BusTimeoutKeysReachTheMaster) {
  for (const double sdo_ms : {100.0, 300.0}) {
    FwConfig c;
    c.can = "sim";
    c.start_timeout_s = 20;
    c.sdo_timeout_ms = sdo_ms;
    c.boot_timeout_ms = 1500;
    c.boot_retry_ms = 250;
    c.state_timeout_ms = 700;
    hal::ManualClock clock;
    test::SimApp app;
    const std::string e = app.build(c, &clock);
    CHECK_TEXT(e.empty(), e.c_str());
    const hal::CanopenMasterConfig& mc = app.canopen().config();
    LONGS_EQUAL(static_cast<long>(sdo_ms) * hal::kMillisecond, mc.sdo_timeout);
    LONGS_EQUAL(1500 * hal::kMillisecond, mc.boot_timeout);
    LONGS_EQUAL(250 * hal::kMillisecond, mc.boot_retry);
    LONGS_EQUAL(700 * hal::kMillisecond, mc.state_timeout);
    clock.set_idle_hook([&](hal::TimePoint t) { app.plant->step(t); });
    sim::DriveQuirks q;
    q.sdo_delay = 150 * hal::kMillisecond;
    app.plant->arm().at(0).set_quirks(q);
    const std::string b = app.boot();
    clock.set_idle_hook(nullptr);
    if (sdo_ms < 150) CHECK_TEXT(has(b, "drive bring-up failed") && has(b, "node 1"), b.c_str());
    else CHECK_TEXT(b.empty(), b.c_str());
  }
}
