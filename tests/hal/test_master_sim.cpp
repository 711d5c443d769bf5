// SPDX-License-Identifier: Apache-2.0
// CANopen master (CanopenServoBus) against six virtual CiA 402 drives on the in-process bus.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <atomic>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "alloc_counter.hpp"
#include "servoarm/hal/canopen.hpp"
#include "sim_fixture.hpp"

// CppUTest last: its leak detector redefines `new`.
#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::hal;

namespace {
constexpr Duration kPeriod = kMillisecond;  // 1 kHz cycle = SYNC period

double sine(double t, std::size_t j) { return 0.4 * std::sin(2 * 3.141592653589793 * 0.5 * t + 0.3 * double(j)); }
}  // namespace

TEST_GROUP(MasterSim) {
  test::SimRig* rig = nullptr;
  CanopenServoBus* master = nullptr;
  void setup() override {
    rig = new test::SimRig({1, 2, 3, 4, 5, 6});
    CanopenMasterConfig cfg = CanopenMasterConfig::consecutive(1, 6);
    cfg.heartbeat_period = 20 * kMillisecond;
    cfg.heartbeat_timeout = 60 * kMillisecond;
    master = new CanopenServoBus(*rig->master_ep, rig->clock, cfg);
  }
  void teardown() override {
    delete master;
    delete rig;
  }
  void bring_up() {
    LONGS_EQUAL(int(Status::ok), int(master->config_status()));
    const Status s = master->start(rig->clock.now() + 2 * kSecond);
    STRCMP_EQUAL("", master->last_error());
    LONGS_EQUAL(int(Status::ok), int(s));
    const Status e = master->enable_blocking(rig->clock.now() + kSecond, kPeriod);
    STRCMP_EQUAL("", master->last_error());
    LONGS_EQUAL(int(Status::ok), int(e));
  }
  // One control cycle: read feedback, write setpoints + SYNC, then time passes (drives run).
  Status cycle(const double* sp) {
    const TimePoint now = rig->clock.now();
    const Status r = master->read(now);
    master->write(std::span<const double>(sp, 6), now);
    rig->clock.advance(kPeriod);
    return r;
  }
  void hold_cycles(int n) {
    double sp[6];
    for (int k = 0; k < n; ++k) {
      for (std::size_t j = 0; j < 6; ++j) sp[j] = master->feedback(j).position;
      cycle(sp);
    }
  }
};

TEST(MasterSim, BringUpConfiguresEveryDriveExplicitly) {
  bring_up();
  for (std::uint8_t n = 1; n <= 6; ++n) {
    sim::VirtualDrive* d = rig->sim->node(n);
    std::uint32_t v = 0;
    struct {
      std::uint16_t index;
      std::uint8_t sub;
      std::uint32_t value;
    } expect[] = {
        {0x6060, 0, 8},          {0x1017, 0, 20},         {0x1600, 0, 2},          {0x1600, 1, 0x60400010},
        {0x1600, 2, 0x607A0020}, {0x1400, 1, 0x200u + n}, {0x1400, 2, 1},          {0x1A00, 0, 2},
        {0x1A00, 1, 0x60410010}, {0x1A00, 2, 0x60640020}, {0x1800, 1, 0x180u + n}, {0x1800, 2, 1},
        {0x1A01, 1, 0x606C0020}, {0x1A01, 2, 0x603F0010}, {0x1801, 1, 0x280u + n},
    };
    for (auto& e : expect) {
      CHECK(d->od_read(e.index, e.sub, v));
      char msg[64];
      std::snprintf(msg, sizeof msg, "node %u 0x%04X:%u", unsigned(n), unsigned(e.index), unsigned(e.sub));
      UNSIGNED_LONGS_EQUAL_TEXT(e.value, v, msg);
    }
    LONGS_EQUAL(int(canopen::NmtState::operational), int(d->nmt()));
    STRCMP_EQUAL("operation_enabled", cia402::to_string(d->state()));
  }
  STRCMP_CONTAINS("virtual drive 4", master->device_name(3));
  for (std::size_t j = 0; j < 6; ++j) LONGS_EQUAL(int(JointState::enabled), int(master->feedback(j).state));
}

TEST(MasterSim, StreamedSetpointsAreFollowedLikeADrive) {
  bring_up();
  // Ramp in from the current position (0) over 0.5 s, then a sine for 2 s.
  double sp[6];
  double max_err = 0, max_err_late = 0;
  for (int k = 0; k < 2500; ++k) {
    const double t = k * 1e-3;
    const double ramp = t < 0.5 ? t / 0.5 : 1.0;
    for (std::size_t j = 0; j < 6; ++j) sp[j] = ramp * sine(t, j);
    LONGS_EQUAL(int(Status::ok), int(cycle(sp)));
    if (k > 10) {
      for (std::size_t j = 0; j < 6; ++j) {
        // Feedback read this cycle belongs to the SYNC two cycles back.
        const double t_fb = (k - 2) * 1e-3;
        const double ramp_fb = t_fb < 0.5 ? t_fb / 0.5 : 1.0;
        const double err = std::fabs(master->feedback(j).position - ramp_fb * sine(t_fb, j));
        max_err = std::max(max_err, err);
        if (k > 600) max_err_late = std::max(max_err_late, err);
        LONGS_EQUAL(int(JointState::enabled), int(master->feedback(j).state));
        CHECK(master->feedback(j).age >= 0 && master->feedback(j).age <= 2 * kPeriod);
      }
    }
  }
  // Within tolerance (2 mrad = 0.11 deg for a 0.4 rad, 0.5 Hz sine)...
  CHECK(max_err < 2e-3);
  // ...but not an echo: the first-order lag shows up as a measurable error.
  CHECK(max_err_late > 1e-5);
  // The drives hold exactly the counts the master sent (no corruption).
  for (std::size_t j = 0; j < 6; ++j) LONGS_EQUAL(master->last_target_counts(j), rig->sim->at(j).target());
  // Velocity feedback matches the derivative of the sine (amplitude 0.4 * pi rad/s).
  double vmax = 0;
  for (std::size_t j = 0; j < 6; ++j) vmax = std::max(vmax, std::fabs(master->feedback(j).velocity));
  CHECK(vmax < 0.4 * 3.141592653589793 * 1.05);
}

TEST(MasterSim, HeartbeatLossReportedWithinTimeoutPlusOnePeriod) {
  bring_up();
  hold_cycles(100);
  rig->sim->node(3)->faults().silent = true;
  const TimePoint silenced = rig->clock.now();
  TimePoint detected = 0;
  for (int k = 0; k < 500 && detected == 0; ++k) {
    double sp[6];
    for (std::size_t j = 0; j < 6; ++j) sp[j] = master->feedback(j).position;
    const Status s = cycle(sp);
    if (s == Status::heartbeat_lost) detected = master->feedback(2).fault_since;
  }
  CHECK(detected != 0);
  const JointFeedback& fb = master->feedback(2);
  LONGS_EQUAL(int(JointState::fault), int(fb.state));
  LONGS_EQUAL(int(Status::heartbeat_lost), int(fb.fault));
  CHECK(fb.last_heartbeat <= silenced);
  const Duration latency = detected - fb.last_heartbeat;
  CHECK(latency > 60 * kMillisecond);
  CHECK(latency <= 60 * kMillisecond + kPeriod);
  // No false faults on the others.
  for (std::size_t j : {0u, 1u, 3u, 4u, 5u}) LONGS_EQUAL(int(JointState::enabled), int(master->feedback(j).state));
  char text[128];
  master->describe_fault(2, text, sizeof text);
  STRCMP_CONTAINS("node 3: heartbeat_lost", text);
}

TEST(MasterSim, EmcyDecodedAndFaultResetOnEnable) {
  bring_up();
  hold_cycles(10);
  rig->sim->node(2)->inject_emcy(0x2310, rig->clock.now(), *rig->sim_ep);
  hold_cycles(5);
  const JointFeedback& fb = master->feedback(1);
  LONGS_EQUAL(int(JointState::fault), int(fb.state));
  LONGS_EQUAL(int(Status::drive_fault), int(fb.fault));
  UNSIGNED_LONGS_EQUAL(0x2310, fb.error_code);
  UNSIGNED_LONGS_EQUAL(1, fb.emcy_count);
  STRCMP_EQUAL("fault", cia402::to_string(cia402::State(fb.drive_state)));
  char text[128];
  master->describe_fault(1, text, sizeof text);
  STRCMP_CONTAINS("0x2310", text);
  STRCMP_CONTAINS("over-current", text);
  // EMCY frame on the wire: 0x082, code LE, error register bit 1 (current) + bit 0 (generic).
  bool seen = false;
  for (auto& f : rig->capture())
    if (f.id == 0x082 && f.len == 8 && f.data[0] == 0x10 && f.data[1] == 0x23 && f.data[2] == 0x03) seen = true;
  CHECK(seen);
  // Re-enable: fault reset edge, drive comes back, EMCY 0x0000 (error reset) follows.
  LONGS_EQUAL(int(Status::ok), int(master->enable_blocking(rig->clock.now() + kSecond, kPeriod)));
  LONGS_EQUAL(int(JointState::enabled), int(master->feedback(1).state));
  UNSIGNED_LONGS_EQUAL(2, master->feedback(1).emcy_count);
}

TEST(MasterSim, RefusedEnableIsReportedWithTheState) {
  rig->sim->node(4)->faults().refuse_enable = true;
  LONGS_EQUAL(int(Status::ok), int(master->start(rig->clock.now() + 2 * kSecond)));
  const Status s = master->enable_blocking(rig->clock.now() + 2 * kSecond, kPeriod);
  LONGS_EQUAL(int(Status::drive_refused), int(s));
  STRCMP_CONTAINS("node 4: drive_refused (stayed in switched_on", master->last_error());
  LONGS_EQUAL(int(Status::drive_refused), int(master->feedback(3).fault));
  // The other drives did enable; a refusing drive never got torque.
  LONGS_EQUAL(int(JointState::enabled), int(master->feedback(0).state));
  STRCMP_EQUAL("switched_on", cia402::to_string(rig->sim->node(4)->state()));
}

TEST(MasterSim, FollowingErrorFaultsTheDrive) {
  bring_up();
  double sp[6] = {0, 0, 0, 0, 0, 0};
  sp[5] = 3.0;  // a 3 rad step: far beyond the 0.1 rev following window
  for (int k = 0; k < 50; ++k) cycle(sp);
  LONGS_EQUAL(int(Status::drive_fault), int(master->feedback(5).fault));
  UNSIGNED_LONGS_EQUAL(0x8611, master->feedback(5).error_code);
}

TEST(MasterSim, NonFiniteSetpointIsRejectedAndHeld) {
  bring_up();
  hold_cycles(5);
  double sp[6] = {0.01, 0.01, 0.01, 0.01, 0.01, 0.01};
  for (int k = 0; k < 5; ++k) cycle(sp);
  const std::int32_t before = master->last_target_counts(2);
  sp[2] = std::nan("");
  const TimePoint now = rig->clock.now();
  master->read(now);
  LONGS_EQUAL(int(Status::invalid_argument), int(master->write(std::span<const double>(sp, 6), now)));
  LONGS_EQUAL(before, master->last_target_counts(2));
  // Wrong size: nothing is trusted beyond the given values, error reported.
  LONGS_EQUAL(int(Status::invalid_argument), int(master->write(std::span<const double>(sp, 3), now)));
}

TEST(MasterSim, PerCycleReadWriteDoesNotAllocate) {
  bring_up();
  hold_cycles(20);
  double sp[6];
  std::size_t allocs = 0;
  for (int k = 0; k < 1000; ++k) {
    for (std::size_t j = 0; j < 6; ++j) sp[j] = 0.1 * std::sin(k * 1e-3 + double(j));
    const TimePoint now = rig->clock.now();
    {
      test::AllocScope scope;
      master->read(now);
      master->write(std::span<const double>(sp, 6), now);
      allocs += scope.end();
    }
    rig->clock.advance(kPeriod);  // the simulated drives may allocate; they are not the RT path
  }
  LONGS_EQUAL(0, allocs);
}

TEST(MasterSim, RandomFloodCausesNoFalseFault) {
  bring_up();
  auto flood = rig->bus.open(16);
  std::mt19937 rng(5);
  double sp[6];
  for (int k = 0; k < 1000; ++k) {
    for (int i = 0; i < 20; ++i) {
      CanFrame f;
      f.extended = rng() % 2;
      if (f.extended) {
        f.id = rng() & 0x1FFFFFFF;
      } else {
        // Random standard ids except NMT/SYNC and the COB-ids of nodes 1..6 (a real
        // foreign device would not use those either).
        do f.id = rng() & 0x7FF; while (f.id <= 0x080 || (canopen::node_of(f.id) >= 1 && canopen::node_of(f.id) <= 6));
      }
      f.len = std::uint8_t(rng() % 9);
      for (auto& b : f.data) b = std::uint8_t(rng());
      flood->send(f);
    }
    for (std::size_t j = 0; j < 6; ++j) sp[j] = 0.2 * std::sin(k * 2e-3 + double(j));
    LONGS_EQUAL(int(Status::ok), int(cycle(sp)));
  }
  CHECK(master->ignored_frames() > 10000);
  for (std::size_t j = 0; j < 6; ++j) {
    LONGS_EQUAL(int(JointState::enabled), int(master->feedback(j).state));
    LONGS_EQUAL(master->last_target_counts(j), rig->sim->at(j).target());
  }
}

TEST(MasterSim, SurvivesOnePercentFrameLoss) {
  bring_up();
  SimFaults faults;
  faults.drop_rate = 0.01;
  faults.seed = 77;
  rig->bus.set_faults(faults);
  double sp[6];
  double max_err = 0;
  for (int k = 0; k < 2000; ++k) {
    const double t = k * 1e-3;
    for (std::size_t j = 0; j < 6; ++j) sp[j] = 0.1 * std::sin(2 * 3.141592653589793 * 0.5 * t) * std::min(1.0, t);
    LONGS_EQUAL(int(Status::ok), int(cycle(sp)));
    if (k > 10)
      for (std::size_t j = 0; j < 6; ++j) max_err = std::max(max_err, std::fabs(master->feedback(j).position - sp[j]));
  }
  CHECK(max_err < 5e-3);
}

TEST(MasterSim, StartFailsClearlyWhenANodeIsMissing) {
  rig->sim->node(5)->faults().silent = true;
  const Status s = master->start(rig->clock.now() + 2 * kSecond);
  LONGS_EQUAL(int(Status::timeout), int(s));
  STRCMP_CONTAINS("node 5", master->last_error());
  STRCMP_CONTAINS("0x1000", master->last_error());
}

TEST(MasterSim, InvalidConfigRejected) {
  CanopenMasterConfig cfg = CanopenMasterConfig::consecutive(1, 2);
  cfg.joints[1].node_id = 1;  // duplicate
  CanopenServoBus m(*rig->master_ep, rig->clock, cfg);
  LONGS_EQUAL(int(Status::invalid_argument), int(m.config_status()));
  LONGS_EQUAL(int(Status::invalid_argument), int(m.start(rig->clock.now() + kSecond)));
  CanopenMasterConfig cfg2 = CanopenMasterConfig::consecutive(1, 9);
  cfg2.joint_count = 9;
  CanopenServoBus m2(*rig->master_ep, rig->clock, cfg2);
  LONGS_EQUAL(int(Status::capacity), int(m2.config_status()));
  LONGS_EQUAL(int(Status::not_configured), int(m.read(rig->clock.now())));
}

TEST(MasterSim, NodeResetIsReported) {
  bring_up();
  hold_cycles(50);  // heartbeats have shown every node operational
  auto other = rig->bus.open(16);
  other->send(canopen::encode_nmt(canopen::NmtCommand::reset_node, 2));
  hold_cycles(5);
  LONGS_EQUAL(int(JointState::fault), int(master->feedback(1).state));
  LONGS_EQUAL(int(Status::protocol_error), int(master->feedback(1).fault));
  for (std::size_t j : {0u, 2u, 3u, 4u, 5u}) LONGS_EQUAL(int(JointState::enabled), int(master->feedback(j).state));
  // After a reset the drive lost its PDO configuration: start() configures it again.
  LONGS_EQUAL(int(Status::ok), int(master->start(rig->clock.now() + 2 * kSecond)));
  LONGS_EQUAL(int(Status::ok), int(master->enable_blocking(rig->clock.now() + kSecond, kPeriod)));
  LONGS_EQUAL(int(JointState::enabled), int(master->feedback(1).state));
}

TEST(MasterSim, StaleHeartbeatDuringStartIsNoFault) {
  // A pre-operational heartbeat that crosses the NMT start on the wire (sent by the node
  // before it processed the start) must not count as "node left operational".
  LONGS_EQUAL(int(Status::ok), int(master->start(rig->clock.now() + 2 * kSecond)));
  auto other = rig->bus.open(16);
  other->send(canopen::encode_heartbeat(3, canopen::NmtState::pre_operational));
  const Status s = master->enable_blocking(rig->clock.now() + kSecond, kPeriod);
  STRCMP_EQUAL("", master->last_error());
  LONGS_EQUAL(int(Status::ok), int(s));
  hold_cycles(20);
  for (std::size_t j = 0; j < 6; ++j) LONGS_EQUAL(int(JointState::enabled), int(master->feedback(j).state));
}

TEST(MasterSim, PerNodeHeartbeatTimeout) {
  // Node 5 gets a tighter consumer time than the rest.
  CanopenMasterConfig cfg = CanopenMasterConfig::consecutive(1, 6);
  cfg.heartbeat_period = 10 * kMillisecond;
  cfg.heartbeat_timeout = 200 * kMillisecond;
  cfg.joints[4].heartbeat_timeout = 25 * kMillisecond;
  CanopenServoBus m(*rig->master_ep, rig->clock, cfg);
  LONGS_EQUAL(int(Status::ok), int(m.start(rig->clock.now() + 2 * kSecond)));
  LONGS_EQUAL(int(Status::ok), int(m.enable_blocking(rig->clock.now() + kSecond, kPeriod)));
  rig->sim->node(5)->faults().heartbeat_stopped = true;
  rig->sim->node(6)->faults().heartbeat_stopped = true;
  double sp[6];
  TimePoint detected5 = 0;
  for (int k = 0; k < 100; ++k) {
    for (std::size_t j = 0; j < 6; ++j) sp[j] = m.feedback(j).position;
    const TimePoint now = rig->clock.now();
    m.read(now);
    if (!detected5 && m.feedback(4).state == JointState::fault) detected5 = now;
    m.write(std::span<const double>(sp, 6), now);
    rig->clock.advance(kPeriod);
  }
  CHECK(detected5 != 0);
  LONGS_EQUAL(int(Status::heartbeat_lost), int(m.feedback(4).fault));
  CHECK(detected5 - m.feedback(4).last_heartbeat <= 25 * kMillisecond + kPeriod);
  // Node 6 (200 ms) has not timed out yet 100 ms later; PDOs still flow, so it is healthy.
  LONGS_EQUAL(int(JointState::enabled), int(m.feedback(5).state));
}

TEST(MasterSim, QuickStopRampsDownThenEnableResumes) {
  bring_up();
  // Move joint 0 at speed, then quick-stop.
  double sp[6] = {};
  for (int k = 0; k < 300; ++k) {
    sp[0] = 1.0 * k * 1e-3;  // 1 rad/s ramp
    cycle(sp);
  }
  // Sampled at SYNC, just before the next setpoint step: the low point of the staircase
  // response (a drive interpolating between setpoints would be smoother).
  CHECK(master->feedback(0).velocity > 0.6 && master->feedback(0).velocity < 1.4);
  master->quick_stop();
  for (int k = 0; k < 10; ++k) cycle(sp);
  STRCMP_EQUAL("quick_stop_active", cia402::to_string(rig->sim->node(1)->state()));
  // The drive stops (deceleration-limited) and keeps holding in quick stop active.
  for (int k = 0; k < 100; ++k) cycle(sp);
  DOUBLES_EQUAL(0.0, master->feedback(0).velocity, 1e-6);
  LONGS_EQUAL(int(JointState::disabled), int(master->feedback(0).state));
  for (std::size_t j = 0; j < 6; ++j) CHECK(master->feedback(j).state != JointState::fault);
  // Resume: the drive holds where it stopped (no jump back to the last setpoint).
  const double stopped_at = master->feedback(0).position;
  LONGS_EQUAL(int(Status::ok), int(master->enable_blocking(rig->clock.now() + kSecond, kPeriod)));
  DOUBLES_EQUAL(stopped_at, master->feedback(0).position, 1e-3);
}

// enable() right after disable(), before the drives have answered the disable's
// controlword: their last statusword still says operation enabled, but they are about to
// leave it. Reported as enabled then, a joint dropped back to enabling a cycle later, and
// the controller, idle already, faulted the arm "left_enabled: drive now enabling" (seen
// under ASan in fw_can_console's reset + enable after an e-stop).
TEST(MasterSim, EnableRightAfterDisableWaitsForTheDrivesToAnswer) {
  bring_up();
  hold_cycles(5);
  double sp[6];
  for (std::size_t j = 0; j < 6; ++j) sp[j] = master->feedback(j).position;
  master->disable();
  const TimePoint now = rig->clock.now();
  master->read(now);
  master->write(std::span<const double>(sp, 6), now);  // disable operation goes out
  master->enable();
  master->read(now);  // no drive has run since: every statusword is the old one
  for (std::size_t j = 0; j < 6; ++j) {
    LONGS_EQUAL_TEXT(int(cia402::State::operation_enabled), int(rig->sim->node(std::uint8_t(j + 1))->state()),
                     "the drive has not processed the disable yet");
    LONGS_EQUAL_TEXT(int(JointState::enabling), int(master->feedback(j).state), "reported enabled on a stale statusword");
  }
  // Once reported enabled, a joint stays enabled.
  bool seen[6] = {};
  for (int k = 0; k < 200; ++k) {
    cycle(sp);
    for (std::size_t j = 0; j < 6; ++j) {
      const JointState st = master->feedback(j).state;
      if (st == JointState::enabled) seen[j] = true;
      else if (seen[j]) FAIL(("joint " + std::to_string(j + 1) + " left enabled at cycle " + std::to_string(k)).c_str());
    }
  }
  for (std::size_t j = 0; j < 6; ++j) CHECK_TEXT(seen[j], ("joint " + std::to_string(j + 1) + " never enabled").c_str());
}

// CanopenJointConfig::quick_stop_decel is written to 6085h at bring-up (only
// where set); the drive then stops on it, and its 605Ah option code decides
// what follows: 6 holds quick stop active, 2 goes to switch on disabled at
// rest, 0 powers off at once.
TEST(MasterSim, QuickStopDecelerationWrittenAndOptionCodesFollowed) {
  delete master;
  CanopenMasterConfig cfg = CanopenMasterConfig::consecutive(1, 6);
  cfg.heartbeat_period = 20 * kMillisecond;
  cfg.heartbeat_timeout = 60 * kMillisecond;
  cfg.joints[0].quick_stop_decel = 2.0 * 131072;  // 2 rev/s^2
  cfg.joints[1].quick_stop_decel = 2.0 * 131072;
  cfg.joints[2].quick_stop_decel = 2.0 * 131072;
  master = new CanopenServoBus(*rig->master_ep, rig->clock, cfg);
  bring_up();
  std::uint32_t v = 0;
  CHECK(rig->sim->node(1)->od_read(0x6085, 0, v));
  UNSIGNED_LONGS_EQUAL(262144u, v);
  CHECK(rig->sim->node(4)->od_read(0x6085, 0, v));
  UNSIGNED_LONGS_EQUAL(400u * 131072u, v);  // not configured: the drive's own
  CHECK(rig->sim->node(2)->od_write(0x605A, 0, 2));
  CHECK(rig->sim->node(3)->od_write(0x605A, 0, 0));
  // joints 0-2 at 1 rev/s (2 pi rad/s motor side, gear 1), then quick stop
  double sp[6] = {};
  for (int k = 0; k < 600; ++k) {
    const double w = std::min(k * 1e-3 / 0.5, 1.0) * 2 * M_PI;  // ramp to 2 pi rad/s in 0.5 s
    for (int j = 0; j < 3; ++j) sp[j] += w * 1e-3;
    cycle(sp);
  }
  master->quick_stop();
  cycle(sp);
  // About 1 rev/s at 2 rev/s^2: about 0.5 s to rest, exactly |606Ch| / 6085h
  // from the speed the drive had when it took the command (joint 3, option 0:
  // off at once).
  CHECK(rig->sim->node(1)->od_read(0x606C, 0, v));
  const double t_expect = std::abs(double(std::int32_t(v))) / 262144.0;
  CHECK_TEXT(t_expect > 0.4 && t_expect < 0.55, std::to_string(t_expect).c_str());
  int stopped0 = -1;
  for (int k = 0; k < 800; ++k) {
    cycle(sp);
    if (k == 5) STRCMP_EQUAL("switch_on_disabled", cia402::to_string(rig->sim->node(3)->state()));
    if (stopped0 < 0 && std::abs(master->feedback(0).velocity) < 1e-9) stopped0 = k;
  }
  CHECK_TEXT(stopped0 * 1e-3 > 0.97 * t_expect - 0.003 && stopped0 * 1e-3 < 1.03 * t_expect + 0.003,
             (std::to_string(stopped0) + " cycles, expected " + std::to_string(t_expect) + " s").c_str());
  STRCMP_EQUAL("quick_stop_active", cia402::to_string(rig->sim->node(1)->state()));   // option 6
  STRCMP_EQUAL("switch_on_disabled", cia402::to_string(rig->sim->node(2)->state()));  // option 2
}

TEST(MasterSim, BusFiltersKeepForeignFramesOut) {
  CanopenMasterConfig cfg = CanopenMasterConfig::consecutive(1, 6);
  cfg.set_bus_filters = true;
  CanopenServoBus m(*rig->master_ep, rig->clock, cfg);
  LONGS_EQUAL(int(Status::ok), int(m.start(rig->clock.now() + 2 * kSecond)));
  LONGS_EQUAL(int(Status::ok), int(m.enable_blocking(rig->clock.now() + kSecond, kPeriod)));
  auto flood = rig->bus.open(16);
  double sp[6] = {};
  for (int k = 0; k < 50; ++k) {
    for (std::uint32_t id = 0x107; id < 0x180; ++id) flood->send(CanFrame::make(id, {1, 2, 3}));  // nodes 7..127
    const TimePoint now = rig->clock.now();
    LONGS_EQUAL(int(Status::ok), int(m.read(now)));
    m.write(std::span<const double>(sp, 6), now);
    rig->clock.advance(kPeriod);
  }
  UNSIGNED_LONGS_EQUAL(0, m.ignored_frames());  // never delivered to the master
  CHECK(rig->master_ep->stats().rx_overruns == 0);
  for (std::size_t j = 0; j < 6; ++j) LONGS_EQUAL(int(JointState::enabled), int(m.feedback(j).state));
}

TEST(MasterSim, NmtCommandsReachTheNodes) {
  bring_up();
  hold_cycles(30);
  LONGS_EQUAL(int(Status::invalid_argument), int(master->nmt(canopen::NmtCommand::stop, 9)));
  LONGS_EQUAL(int(Status::ok), int(master->nmt(canopen::NmtCommand::stop, 4)));
  hold_cycles(60);  // > one heartbeat period (20 ms)
  LONGS_EQUAL(int(canopen::NmtState::stopped), int(rig->sim->node(4)->nmt()));
  LONGS_EQUAL(int(Status::protocol_error), int(master->feedback(3).fault));
  LONGS_EQUAL(int(Status::ok), int(master->nmt(canopen::NmtCommand::enter_pre_operational, 0)));
  hold_cycles(5);
  for (std::uint8_t n = 1; n <= 6; ++n) LONGS_EQUAL(int(canopen::NmtState::pre_operational), int(rig->sim->node(n)->nmt()));
  // Wire format of the broadcast: 0x000 [0x80, 0x00].
  bool seen = false;
  for (auto& f : rig->capture())
    if (f.id == 0x000 && f.len == 2 && f.data[0] == 0x80 && f.data[1] == 0x00) seen = true;
  CHECK(seen);
  // Back to work: start() reconfigures and restarts every node.
  LONGS_EQUAL(int(Status::ok), int(master->start(rig->clock.now() + 2 * kSecond)));
  LONGS_EQUAL(int(Status::ok), int(master->enable_blocking(rig->clock.now() + kSecond, kPeriod)));
}

TEST(MasterSim, BusOffFaultsEveryJoint) {
  bring_up();
  hold_cycles(10);
  rig->bus.set_error_state(ErrorState::bus_off);
  double sp[6] = {};
  const TimePoint now = rig->clock.now();
  LONGS_EQUAL(int(Status::bus_off), int(master->read(now)));
  LONGS_EQUAL(int(Status::bus_off), int(master->write(std::span<const double>(sp, 6), now)));
  for (std::size_t j = 0; j < 6; ++j) LONGS_EQUAL(int(Status::bus_off), int(master->feedback(j).fault));
  // Recovery is explicit: bus back, enable() resets the latched faults.
  rig->bus.set_error_state(ErrorState::active);
  rig->clock.advance(kPeriod);
  LONGS_EQUAL(int(Status::ok), int(master->enable_blocking(rig->clock.now() + kSecond, kPeriod)));
}

TEST_GROUP(MasterRealTime){};

TEST(MasterRealTime, DrivesOnTheirOwnThreadWithTheRealClock) {
  // The path a host build of the firmware takes: SimBus with CLOCK_MONOTONIC, drives
  // stepped by their own thread (condition-variable wake-ups), master cycling at 2 ms.
  MonotonicClock clock;
  SimBus bus(clock);
  auto master_ep = bus.open(4096);
  auto sim_ep = bus.open(4096);
  std::vector<std::uint8_t> nodes{1, 2, 3, 4, 5, 6};
  sim::ArmSim arm(*sim_ep, nodes);
  arm.power_on(clock.now());
  std::atomic<bool> stop{false};
  std::atomic<int> drive_stalls{0};
  std::thread drives([&] {
    TimePoint next = clock.now();
    while (!stop.load()) {
      CanFrame f;
      if (sim_ep->receive(f, next) == Status::ok) arm.handle(f, clock.now());
      if (clock.now() >= next) {
        const TimePoint t = clock.now();
        if (t - next > 5 * kMillisecond) drive_stalls.fetch_add(1);  // this thread woke late
        arm.tick(t);
        next = t + kMillisecond;
      }
    }
  });
  CanopenMasterConfig cfg = CanopenMasterConfig::consecutive(1, 6);
  cfg.heartbeat_timeout = 500 * kMillisecond;  // a loaded CI machine may stall a thread for a while
  CanopenServoBus m(*master_ep, clock, cfg);
  const Status s1 = m.start(clock.now() + 5 * kSecond);
  const Status s2 = s1 == Status::ok ? m.enable_blocking(clock.now() + 5 * kSecond, 2 * kMillisecond) : s1;
  double max_err = 0;
  int judged = 0;  // cycles whose following was judged
  Status worst = Status::ok;
  if (s2 == Status::ok) {
    double sp[6], hist[6][8] = {};
    TimePoint next = clock.now();
    int settle = 20;  // cycles to skip: start-up, and after any cycle the OS started late
    int seen_stalls = drive_stalls.load();
    for (int k = 0; k < 250; ++k) {
      const TimePoint now = clock.now();
      if (now - next > 5 * kMillisecond) settle = 10;  // a stalled machine is not a master fault
      if (drive_stalls.load() != seen_stalls) {        // nor is a stalled drive thread
        seen_stalls = drive_stalls.load();
        settle = 10;
      }
      const Status r = m.read(now);
      if (r != Status::ok && worst == Status::ok) worst = r;
      if (settle > 0) --settle;
      if (settle == 0) ++judged;
      for (std::size_t j = 0; j < 6; ++j) {
        sp[j] = 0.2 * std::sin(2 * 3.141592653589793 * k * 2e-3);
        if (settle == 0) {
          double best = 1e9;  // best-matching recent setpoint: thread wake-ups vary
          for (int l = 1; l < 8; ++l) best = std::min(best, std::fabs(m.feedback(j).position - hist[j][(k - l) % 8]));
          max_err = std::max(max_err, best);
        }
        hist[j][k % 8] = sp[j];
      }
      m.write(std::span<const double>(sp, 6), now);
      next += 2 * kMillisecond;
      clock.sleep_until(next);
    }
  }
  stop = true;
  drives.join();
  if ((s2 != Status::ok || worst != Status::ok) && drive_stalls.load() > 0) {  // starved: said, not failed
    std::printf("\nreal clock: the drive thread stalled %d times (> 5 ms late) and the master saw %s (%s): not judged\n",
                drive_stalls.load(), hal::to_string(s2 != Status::ok ? s2 : worst), m.last_error());
    return;
  }
  STRCMP_EQUAL("", m.last_error());
  LONGS_EQUAL(int(Status::ok), int(s2));
  LONGS_EQUAL(int(Status::ok), int(worst));
  if (judged < 50) {  // a starved machine (qemu beside other jobs): said, not failed
    std::printf("\nreal clock: only %d of 250 cycles free of stalls: following not judged (max_err %.4f)\n", judged,
                max_err);
    return;
  }
  // followed (not following at all would be up to 0.2)
  CHECK_TEXT(max_err < 0.02, ("max_err " + std::to_string(max_err) + " rad over " + std::to_string(judged) +
                              " judged cycles, drive thread stalls " + std::to_string(drive_stalls.load()))
                                 .c_str());
}

// Drive set-up: 60C2h from the SYNC period and a per-drive list of SDO writes, written at
// bring-up and read back; a drive that lacks an object fails the bring-up naming it.
TEST(MasterSim, BringUpWritesTheInterpolationPeriodAndTheDrivesSdoList) {
  CanopenMasterConfig cfg = CanopenMasterConfig::consecutive(1, 6);
  cfg.interpolation_period = 2500 * kMicrosecond;  // 400 Hz: 25 x 10^-4 s
  CanopenJointConfig& j2 = cfg.joints[1];
  j2.sdo_writes[0] = SdoWrite{0x6065, 0, 4, false, 20000};             // following error window
  j2.sdo_writes[1] = SdoWrite{0x607D, 1, 4, true, std::uint32_t(-400000)};  // software limit min
  j2.sdo_writes[2] = SdoWrite{0x607D, 2, 4, true, 400000};               // software limit max
  j2.sdo_writes[3] = SdoWrite{0x6072, 0, 2, false, 1500};                // max torque, per mille
  j2.sdo_write_count = 4;
  delete master;
  master = new CanopenServoBus(*rig->master_ep, rig->clock, cfg);
  bring_up();
  std::uint32_t v = 0;
  for (std::uint8_t n = 1; n <= 6; ++n) {
    CHECK(rig->sim->node(n)->od_read(0x60C2, 1, v));
    LONGS_EQUAL(25, v);
    CHECK(rig->sim->node(n)->od_read(0x60C2, 2, v));
    LONGS_EQUAL(-4, std::int8_t(v));
  }
  sim::VirtualDrive* d = rig->sim->node(2);
  CHECK(d->od_read(0x6065, 0, v));
  LONGS_EQUAL(20000, v);
  CHECK(d->od_read(0x607D, 1, v));
  LONGS_EQUAL(-400000, std::int32_t(v));
  CHECK(d->od_read(0x607D, 2, v));
  LONGS_EQUAL(400000, v);
  CHECK(d->od_read(0x6072, 0, v));
  LONGS_EQUAL(1500, v);
  CHECK(rig->sim->node(1)->od_read(0x6065, 0, v));
  CHECK(v != 20000);  // only joint 2's list went to node 2
}

TEST(MasterSim, ADriveThatRefusesAnSdoListEntryFailsTheBringUpNamingIt) {
  CanopenMasterConfig cfg = CanopenMasterConfig::consecutive(1, 6);
  cfg.joints[2].sdo_writes[0] = SdoWrite{0x6065, 0, 4, false, 20000};
  cfg.joints[2].sdo_writes[1] = SdoWrite{0x2345, 0, 2, false, 2000};  // an object the virtual drive does not have
  cfg.joints[2].sdo_write_count = 2;
  delete master;
  master = new CanopenServoBus(*rig->master_ep, rig->clock, cfg);
  const Status s = master->start(rig->clock.now() + 2 * kSecond);
  LONGS_EQUAL(int(Status::sdo_abort), int(s));
  STRCMP_CONTAINS("node 3: drive.sdo 2345h:0 = 2000 refused", master->last_error());
  STRCMP_CONTAINS("abort 0x06020000", master->last_error());
  CHECK(std::strchr(master->last_error(), '\n') == nullptr);
  // a value of the wrong size for the object: the drive's own abort, named the same way
  cfg.joints[2].sdo_writes[1] = SdoWrite{0x6065, 0, 2, false, 7};
  delete master;
  master = new CanopenServoBus(*rig->master_ep, rig->clock, cfg);
  LONGS_EQUAL(int(Status::sdo_abort), int(master->start(rig->clock.now() + 2 * kSecond)));
  STRCMP_CONTAINS("node 3: drive.sdo 6065h:0 = 7 refused", master->last_error());
  STRCMP_CONTAINS("abort 0x06070013", master->last_error());
}

// A drive that acknowledges a write but keeps another value (a limit saturated at its own
// ceiling): the read-back catches it and the bring-up fails naming the node, the object
// and both values. The virtual drive keeps 6073h (max current) at most 3000 per mille.
TEST(MasterSim, ADriveThatReadsBackAnotherValueFailsTheBringUpNamingBoth) {
  CanopenMasterConfig cfg = CanopenMasterConfig::consecutive(1, 6);
  cfg.joints[3].sdo_writes[0] = SdoWrite{0x6072, 0, 2, false, 1500};  // within the drive's range: kept
  cfg.joints[3].sdo_writes[1] = SdoWrite{0x6073, 0, 2, false, 5000};  // above its ceiling: kept as 3000
  cfg.joints[3].sdo_writes[2] = SdoWrite{0x6066, 0, 2, false, 20};    // after the mismatch: not written
  cfg.joints[3].sdo_write_count = 3;
  delete master;
  master = new CanopenServoBus(*rig->master_ep, rig->clock, cfg);
  const Status s = master->start(rig->clock.now() + 2 * kSecond);
  LONGS_EQUAL(int(Status::protocol_error), int(s));
  STRCMP_CONTAINS("node 4: drive.sdo 6073h:0 reads back 3000 (2 bytes) after writing 5000", master->last_error());
  CHECK(std::strchr(master->last_error(), '\n') == nullptr);
  std::uint32_t v = 0;
  sim::VirtualDrive* d = rig->sim->node(4);
  CHECK(d->od_read(0x6072, 0, v));
  LONGS_EQUAL(1500, v);  // the entry before was written
  CHECK(d->od_read(0x6073, 0, v));
  LONGS_EQUAL(3000, v);  // what the drive kept, the figure the message names
  CHECK(d->od_read(0x6066, 0, v));
  LONGS_EQUAL(10, v);    // the bring-up stopped at the mismatch
  // a negative value the drive keeps as written passes the read-back (compared as the
  // bytes written, two's complement)
  cfg.joints[3].sdo_writes[0] = SdoWrite{0x607D, 1, 4, true, std::uint32_t(-400000)};
  cfg.joints[3].sdo_write_count = 1;
  delete master;
  master = new CanopenServoBus(*rig->master_ep, rig->clock, cfg);
  LONGS_EQUAL(int(Status::ok), int(master->start(rig->clock.now() + 2 * kSecond)));
  STRCMP_EQUAL("", master->last_error());
}
