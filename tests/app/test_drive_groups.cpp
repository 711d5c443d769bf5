// SPDX-License-Identifier: Apache-2.0
// Drives chosen per joint (docs/servo-bus.md#drive-families-groups-and-the-arm): App builds the
// arm's ServoBus from the drive-family factory, one group per (drive.family, interface). The
// puma560 with joints 1-3 on one in-process bus and 4-6 on a second (drive.can), CiA 402
// virtual drives on both, boots, enables, homes (a CiA 402 method on the first bus, hard stop
// on the second) and moves exactly as the same arm on one bus; a drive fault on the second bus
// reaches the controller as it does on one bus.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "alloc_counter.hpp"
#include "sim_app.hpp"
#include "servoarm/app/drive_factory.hpp"
#include "servoarm/config/config.hpp"
#include "servoarm/rt/controller.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;

namespace {

constexpr double kDeg = M_PI / 180.0;
const double kCountsPerRad = hal::JointScaling{}.counts_per_si();
double counts(double deg) { return deg * kDeg * kCountsPerRad; }

/// The arm, its console and the cycles, single-threaded on a ManualClock.
struct Arm {
  hal::ManualClock clock;
  test::SimApp app;
  Session s;
  std::size_t rt_allocs = 0;
  std::string events, grbl;
  std::vector<std::array<double, 6>> q_act, q_cmd;  ///< per cycle

  explicit Arm(FwConfig cfg) {
    cfg.can = "sim";
    const std::string e = app.build(cfg, &clock);
    if (!e.empty()) FAIL(e.c_str());
    clock.set_idle_hook([this](hal::TimePoint t) { app.step_plants(t); });
    drive(0).switches().home_lo = counts(4);  // joint 1: method 19, positive home switch
    drive(0).switches().home_hi = sim::DriveSwitches::kNone;
    drive(4).switches().end_neg = counts(-8);  // joint 5: hard stop 8 deg below
    const std::string b = app.boot();
    if (!b.empty()) FAIL(b.c_str());
    app.console->set_idle([this] { cycle(); });
  }
  ~Arm() { clock.set_idle_hook(nullptr); }
  /// Joint j's virtual drive, on whichever bus it is.
  sim::VirtualDrive& drive(int j) {
    const auto ju = static_cast<std::size_t>(j);
    if (app.more_plants.empty()) return app.plant->arm().at(ju);
    const hal::ArmServoBus::Slot sl = app.servo->slot(ju);
    return sl.group == 0 ? app.plant->arm().at(sl.local) : app.more_plants[sl.group - 1u]->arm().at(sl.local);
  }
  void cycle() {
    test::alloc_count_begin();
    app.ctl->cycle(clock.now());
    rt_allocs += test::alloc_count_end();
    clock.advance(hal::kMillisecond);
    const Telemetry t = app.ctl->telemetry();
    std::array<double, 6> a{}, c{};
    std::copy_n(t.q_act.begin(), 6, a.begin());
    std::copy_n(t.q_cmd.begin(), 6, c.begin());
    q_act.push_back(a);
    q_cmd.push_back(c);
    app.console->drain_events(events, grbl);
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
  Telemetry tel() const { return app.ctl->telemetry(); }
};

bool ok(const std::string& a) { return a.rfind("ok", 0) == 0 || a.find("\nok") != std::string::npos; }
bool has(const std::string& a, const std::string& b) { return a.find(b) != std::string::npos; }

/// Six CiA 402 drives: joint 1 homes by method 19, joint 5 by hard stop, the others absolute;
/// `second_bus`: joints 4-6 on drive.can = "sim1" (an in-process bus of their own).
FwConfig arm_config(bool second_bus) {
  FwConfig c;
  c.drives.resize(6);
  for (DriveConfig& d : c.drives) {
    d.homing_speed_switch = 20;
    d.homing_speed_zero = 2;
    d.homing_acceleration = 200;
    d.homing_timeout_s = 20;
  }
  c.drives[0].homing_method = "19";
  c.drives[0].homing_offset = 10;
  DriveConfig& h = c.drives[4];
  h.homing_method = "hard_stop";
  h.homing_direction = -1;
  h.homing_speed_switch = 5;
  h.homing_acceleration = 50;
  h.homing_following_limit = 0.5;
  h.homing_backoff = 3;
  h.homing_offset = -60;
  if (second_bus)
    for (int j = 3; j < 6; ++j) c.drives[static_cast<std::size_t>(j)].can = "sim1";
  return c;
}

/// Boot, enable, home, a joint move, park: what both arms run.
void run_script(Arm& a) {
  CHECK_TEXT(ok(a.cmd("enable")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("home")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("wait")), (a.s.out + a.events).c_str());
  CHECK(a.tel().all_homed());
  // joint 5 homed by hard stop: the shaft at the stop + backoff, reading homing.offset there
  DOUBLES_EQUAL(counts(-8) + counts(3), a.drive(4).physical_position(), 2.0);
  DOUBLES_EQUAL(-60 * kDeg, a.tel().q_act[4], 2.0 / kCountsPerRad);
  CHECK_TEXT(ok(a.cmd("movej 20 -30 40 15 -20 30")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("wait")), (a.s.out + a.events).c_str());
  for (int i = 0; i < 200; ++i) a.cycle();
}

}  // namespace

TEST_GROUP(FwDriveGroups){};

TEST(FwDriveGroups, TwoBusesOfCia402DrivesMoveLikeOneBus) {
  Arm one(arm_config(false));
  Arm two(arm_config(true));
  // The factory: one group per interface, each a CiA 402 group of three joints.
  LONGS_EQUAL(1, long(one.app.servo->group_count()));
  LONGS_EQUAL(2, long(two.app.servo->group_count()));
  STRCMP_EQUAL("cia402", two.app.servo->group(1).family());
  LONGS_EQUAL(3, long(two.app.servo->group(1).joint_count()));
  LONGS_EQUAL(1, two.app.servo->slot(4).group);
  LONGS_EQUAL(1, two.app.servo->slot(4).local);
  LONGS_EQUAL(1, long(two.app.more_plants.size()));
  run_script(one);
  run_script(two);
  DOUBLES_EQUAL(-30 * kDeg, two.tel().q_act[1], 2.0 / kCountsPerRad);  // where the move went
  DOUBLES_EQUAL(-20 * kDeg, two.tel().q_act[4], 2.0 / kCountsPerRad);
  LONGS_EQUAL(long(one.q_act.size()), long(two.q_act.size()));
  double max_act = 0, max_cmd = 0;
  for (std::size_t k = 0; k < one.q_act.size() && k < two.q_act.size(); ++k)
    for (std::size_t j = 0; j < 6; ++j) {
      max_act = std::max(max_act, std::fabs(one.q_act[k][j] - two.q_act[k][j]));
      max_cmd = std::max(max_cmd, std::fabs(one.q_cmd[k][j] - two.q_cmd[k][j]));
    }
  std::printf("\n  two buses vs one: %zu cycles, max |q_act diff| %.3g rad, max |q_cmd diff| %.3g rad\n",
              one.q_act.size(), max_act, max_cmd);
  DOUBLES_EQUAL(0.0, max_act, 1e-12);
  DOUBLES_EQUAL(0.0, max_cmd, 1e-12);
  for (int j = 0; j < 6; ++j) DOUBLES_EQUAL(one.drive(j).physical_position(), two.drive(j).physical_position(), 0.0);
  LONGS_EQUAL(0, long(one.rt_allocs));
  LONGS_EQUAL(0, long(two.rt_allocs));
}

TEST(FwDriveGroups, AFaultOnTheSecondBusReachesTheControllerAsOnOneBus) {
  for (const bool second_bus : {false, true}) {
    Arm a(arm_config(second_bus));
    CHECK(ok(a.cmd("enable")));
    // joint 5's drive (node 5) sends EMCY 2310h (overcurrent) and faults
    if (second_bus) a.app.more_plants[0]->inject_emcy(1, 0x2310);
    else a.app.plant->inject_emcy(4, 0x2310);
    for (int i = 0; i < 50; ++i) a.cycle();
    const Telemetry t = a.tel();
    const std::string what = std::string(second_bus ? "two buses: " : "one bus: ") + a.events;
    CHECK_TEXT(t.state == ArmState::fault, what.c_str());
    LONGS_EQUAL_TEXT(4, t.fault_joint, what.c_str());
    CHECK_TEXT(t.cause == FaultCause::drive_fault || t.cause == FaultCause::emcy, what.c_str());
    CHECK_TEXT(has(a.events, "alarm: fault joint 5"), what.c_str());
    CHECK_TEXT(has(t.fault_text, "2310"), t.fault_text);
    for (std::size_t j = 0; j < 6; ++j) CHECK(a.app.servo->feedback(j).state != hal::JointState::enabled);
  }
}

// A group's messages name the arm's joints: joint 4 (node 4) is the first joint of the second
// bus's group; its drive lacks homing mode, so the bring-up fails naming "joint 3 (node 4)"
// (the master numbers joints from 0, as on one bus), not the group's local "joint 0".
TEST(FwDriveGroups, ABringUpFailureOnTheSecondBusNamesTheArmsJoint) {
  FwConfig c = arm_config(true);
  c.can = "sim";
  c.drives[3].homing_method = "19";
  hal::ManualClock clock;
  test::SimApp app;
  const std::string e = app.build(c, &clock);
  CHECK_TEXT(e.empty(), e.c_str());
  clock.set_idle_hook([&](hal::TimePoint t) { app.step_plants(t); });
  sim::DriveQuirks q;
  q.no_homing = true;
  app.more_plants.at(0)->arm().at(0).set_quirks(q);
  const std::string b = app.boot();
  clock.set_idle_hook(nullptr);
  CHECK_TEXT(has(b, "drive bring-up failed") && has(b, "joint 3 (node 4)"), b.c_str());
  CHECK_TEXT(has(b, "homing method 19") && has(b, "does not support homing mode"), b.c_str());
}

// drive.family's values (the key table, firmware/config) and the factory's families
// (firmware/app) are one list: a family the configuration accepts has a builder, and the other
// way round; an unknown family is refused when the configuration loads, naming the key.
TEST(FwDriveGroups, TheConfigurationsFamiliesAreTheFactorysFamilies) {
  const DriveKey* family = nullptr;
  for (const DriveKey& k : drive_keys())
    if (std::string(k.name) == "family") family = &k;
  CHECK(family != nullptr);
  LONGS_EQUAL(long(drive_families().size()), long(family->one_of_text.size()));
  for (const DriveFamily& f : drive_families()) {
    bool listed = false;
    for (const char* n : family->one_of_text) listed = listed || std::string(n) == f.name;
    CHECK_TEXT(listed, f.name);
  }
  FwConfig c;
  const std::string e = load_config_text("[[drive]]\nfamily = \"ethercat\"\n", "f.toml", c);
  CHECK_TEXT(has(e, "drive[1].family") && has(e, "cia402"), e.c_str());
}
