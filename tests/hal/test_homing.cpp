// SPDX-License-Identifier: Apache-2.0
// Homing: the CANopen master's homing state machine against virtual CiA 402 drives
// with simulated switches, index pulses and end stops, on the in-process bus; and the drive
// behaviours real masters trip over (conformance quirks).
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <random>
#include <vector>

#include "alloc_counter.hpp"
#include "servoarm/hal/canopen.hpp"
#include "servoarm/hal/sdo_client.hpp"
#include "sim_fixture.hpp"
#include "sweep.hpp"

// CppUTest last: its leak detector redefines `new`.
#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::hal;

namespace {
constexpr Duration kPeriod = kMillisecond;
constexpr double kRev = 2 * 3.141592653589793;  // rad per motor revolution (gear 1)
const double kCps = JointScaling{}.counts_per_si();  // counts per rad

/// One master + `n` virtual drives; `tune` edits the master config before construction.
struct Rig {
  test::SimRig rig;
  CanopenMasterConfig cfg;
  CanopenServoBus* master = nullptr;
  explicit Rig(std::size_t n, const std::function<void(CanopenMasterConfig&)>& tune = {},
               const std::function<void(test::SimRig&)>& drives = {})
      : rig(nodes(n)) {
    cfg = CanopenMasterConfig::consecutive(1, n);
    cfg.heartbeat_period = 20 * kMillisecond;
    cfg.heartbeat_timeout = 80 * kMillisecond;
    if (tune) tune(cfg);
    if (drives) drives(rig);
    master = new CanopenServoBus(*rig.master_ep, rig.clock, cfg);
  }
  ~Rig() { delete master; }
  static std::vector<std::uint8_t> nodes(std::size_t n) {
    std::vector<std::uint8_t> v;
    for (std::size_t i = 1; i <= n; ++i) v.push_back(std::uint8_t(i));
    return v;
  }
  sim::VirtualDrive& drive(std::size_t j) { return rig.sim->at(j); }
  Status start() { return master->start(rig.clock.now() + 20 * kSecond); }
  void bring_up() {
    LONGS_EQUAL(int(Status::ok), int(master->config_status()));
    const Status s = start();
    STRCMP_EQUAL("", master->last_error());
    LONGS_EQUAL(int(Status::ok), int(s));
    const Status e = master->enable_blocking(rig.clock.now() + kSecond, kPeriod);
    STRCMP_EQUAL("", master->last_error());
    LONGS_EQUAL(int(Status::ok), int(e));
  }
  void cycle() {
    double sp[kMaxServoJoints];
    const TimePoint now = rig.clock.now();
    master->read(now);
    for (std::size_t j = 0; j < cfg.joint_count; ++j) sp[j] = master->feedback(j).position;
    master->write(std::span<const double>(sp, cfg.joint_count), now);
    rig.clock.advance(kPeriod);
  }
  /// Runs cycles until joint j's homing leaves `running` (or `max` passes); the time it took.
  Duration home(std::size_t j, Duration max = 30 * kSecond) {
    const TimePoint t0 = rig.clock.now();
    LONGS_EQUAL(int(Status::ok), int(master->start_homing(j, t0)));
    while (master->homing(j).phase == HomingPhase::running && rig.clock.now() - t0 < max) cycle();
    return rig.clock.now() - t0;
  }
};

HomingSpec drive_homing(int method) {
  HomingSpec h;
  h.kind = HomingKind::cia402;
  h.method = std::int8_t(method);
  h.speed_switch = 1.0 * kRev;  // 1 rev/s
  h.speed_zero = 0.1 * kRev;
  h.acceleration = 20 * kRev;
  h.offset = 0.0;
  h.timeout = 20 * kSecond;
  return h;
}

struct MethodCase {
  int method;
  double neg_limit, pos_limit, home_lo, home_hi;  // physical counts; inf = none
  double expect;                                  // physical counts of the home mark
};
constexpr double kInf = sim::DriveSwitches::kNone;
// Index pulses at 1000 + k x 131072 (DriveSwitches::index_phase = 1000); the drive starts at 0.
const MethodCase kCases[] = {
    {1, -150000, kInf, kInf, -kInf, 1000.0 - 131072},    // neg. limit, then the index to its right
    {2, -kInf, 200000, kInf, -kInf, 1000.0 + 131072},     // pos. limit, then the index to its left
    {17, -150000, kInf, kInf, -kInf, -150000},            // neg. limit edge
    {18, -kInf, 200000, kInf, -kInf, 200000},             // pos. limit edge
    {3, -kInf, kInf, 50000, kInf, 1000},                  // positive home switch + index left of it
    {19, -kInf, kInf, 50000, kInf, 50000},                // positive home switch, from below
    {19, -kInf, kInf, -30000, kInf, -30000},              // ... starting on it
    {20, -kInf, kInf, 50000, kInf, 50000},
    {21, -kInf, kInf, -kInf, -40000, -40000},             // negative home switch, from above
    {22, -kInf, kInf, -kInf, -40000, -40000},
    {5, -kInf, kInf, -kInf, -40000, 1000},                // negative home switch + index right of it
    {23, -300000, 300000, 60000, 90000, 60000},           // home cam, from below
    {23, -300000, 150000, -90000, -60000, -90000},        // ... from above: reversal at the pos. limit
    {7, -300000, 300000, 60000, 90000, 1000},             // ... + index left of the lower edge
    {27, -300000, 300000, -90000, -60000, -60000},        // home cam, initial direction negative
    {27, -150000, 300000, 60000, 90000, 90000},           // ... from below: reversal at the neg. limit
    {11, -300000, 300000, -90000, -60000, 1000},          // ... + index right of the upper edge
    {33, -kInf, kInf, kInf, -kInf, 1000.0 - 131072},      // index, negative
    {34, -kInf, kInf, kInf, -kInf, 1000},                 // index, positive
    {35, -kInf, kInf, kInf, -kInf, 0},                    // current position
    {37, -kInf, kInf, kInf, -kInf, 0},
};

/// The first index pulse strictly beyond p moving in dir (period 131072, phase `ph`).
double next_index(double p, int dir, double ph) {
  const double k = (p - ph) / 131072.0;
  return ph + (dir > 0 ? std::floor(k) + 1 : std::ceil(k) - 1) * 131072.0;
}

void set_switches(sim::VirtualDrive& d, const MethodCase& c) {
  auto& s = d.switches();
  s.neg_limit = c.neg_limit;
  s.pos_limit = c.pos_limit;
  s.home_lo = c.home_lo;
  s.home_hi = c.home_hi;
  s.index_phase = 1000;
}
}  // namespace

TEST_GROUP(Homing){};

TEST(Homing, EveryMethodHomesOnTheSimulatedMarkWithinOneCount) {
  for (const MethodCase& c : kCases) {
    char what[96];
    std::snprintf(what, sizeof what, "method %d (switches %g %g [%g, %g])", c.method, c.neg_limit, c.pos_limit,
                  c.home_lo, c.home_hi);
    Rig r(1, [&](CanopenMasterConfig& cfg) {
      cfg.joints[0].homing = drive_homing(c.method);
      cfg.joints[0].homing.offset = 0.1;  // joint reads 0.1 rad on the mark
    });
    set_switches(r.drive(0), c);
    r.bring_up();
    const double start_phys = r.drive(0).physical_position();
    const Duration took = r.home(0);
    const HomingProgress p = r.master->homing(0);
    char msg[192];
    r.master->describe_homing(0, msg, sizeof msg);
    STRCMP_EQUAL_TEXT("", msg, what);
    LONGS_EQUAL_TEXT(int(HomingPhase::attained), int(p.phase), what);
    LONGS_EQUAL_TEXT(int(Status::ok), int(p.status), what);
    const double expect = (c.method == 35 || c.method == 37) ? start_phys : c.expect;
    DOUBLES_EQUAL_TEXT(expect, r.drive(0).home_mark(), 1.0, what);
    // Independent of what the drive says: where the shaft is (the switches' coordinates)...
    for (int k = 0; k < 50; ++k) r.cycle();
    DOUBLES_EQUAL_TEXT(expect, r.drive(0).physical_position(), 1.0, what);
    // ...and what the master reports there: the configured offset.
    DOUBLES_EQUAL_TEXT(std::nearbyint(0.1 * kCps) / kCps, r.master->feedback(0).position, 1.001 / kCps, what);
    // Back in CSP, enabled, holding: no jump, no fault.
    LONGS_EQUAL_TEXT(cia402::kModeCsp, r.drive(0).mode_display(), what);
    LONGS_EQUAL_TEXT(int(JointState::enabled), int(r.master->feedback(0).state), what);
    std::printf("\n  homing method %2d: %6.3f s", c.method, double(took) * 1e-9);
  }
  std::printf("\n");
}

TEST(Homing, SwitchNeverFoundIsAHomingError) {
  // No home switch; an end stop at +100000 counts: the search reaches it.
  Rig r(1, [](CanopenMasterConfig& cfg) { cfg.joints[0].homing = drive_homing(19); });
  r.drive(0).switches().end_pos = 100000;
  r.bring_up();
  r.home(0);
  const HomingProgress p = r.master->homing(0);
  LONGS_EQUAL(int(HomingPhase::failed), int(p.phase));
  LONGS_EQUAL(int(Status::homing_error), int(p.status));
  char msg[192];
  r.master->describe_homing(0, msg, sizeof msg);
  STRCMP_CONTAINS("joint 0 (node 1): homing homing_error", msg);
  LONGS_EQUAL(cia402::kModeCsp, r.drive(0).mode_display());
  LONGS_EQUAL(int(JointState::enabled), int(r.master->feedback(0).state));
  CHECK(r.drive(0).physical_position() <= 100000.5);
  // A limit switch method without the limit: the travel limit ends it too.
  Rig r2(1, [](CanopenMasterConfig& cfg) { cfg.joints[0].homing = drive_homing(17); });
  r2.drive(0).switches().max_travel = 200000;
  r2.bring_up();
  r2.home(0);
  LONGS_EQUAL(int(Status::homing_error), int(r2.master->homing(0).status));
}

TEST(Homing, NeverAttainedTimesOutNamingTheJoint) {
  Rig r(2, [](CanopenMasterConfig& cfg) {
    cfg.joints[1].homing = drive_homing(19);
    cfg.joints[1].homing.timeout = 1500 * kMillisecond;
  });
  sim::DriveQuirks q;
  q.never_attained = true;
  r.drive(1).set_quirks(q);
  r.drive(1).switches().home_lo = 20000;
  r.drive(1).switches().home_hi = kInf;
  r.bring_up();
  const Duration took = r.home(1);
  const HomingProgress p = r.master->homing(1);
  LONGS_EQUAL(int(HomingPhase::failed), int(p.phase));
  LONGS_EQUAL(int(Status::timeout), int(p.status));
  CHECK(took >= 1500 * kMillisecond && took < 3 * kSecond);
  char msg[192];
  r.master->describe_homing(1, msg, sizeof msg);
  STRCMP_CONTAINS("joint 1 (node 2): homing timeout after 1500 ms", msg);
  STRCMP_CONTAINS("homing attained", msg);
  STRCMP_CONTAINS("joint 1 (node 2)", r.master->last_error());
  // It did reach home (the quirk only hides bit 12), and it is back in CSP.
  DOUBLES_EQUAL(20000, r.drive(1).home_mark(), 1.0);
  LONGS_EQUAL(cia402::kModeCsp, r.drive(1).mode_display());
  // Joint 0 (kind none) counts as homed.
  LONGS_EQUAL(int(HomingPhase::attained), int(r.master->homing(0).phase));
}

TEST(Homing, AbortHaltsAndReturnsToCspUnhomed) {
  for (bool halt_quirk : {false, true}) {
    Rig r(1, [](CanopenMasterConfig& cfg) { cfg.joints[0].homing = drive_homing(19); });
    sim::DriveQuirks q;
    q.halt_blocks_mode_change = halt_quirk;  // some drives take no mode change while halted
    r.drive(0).set_quirks(q);
    r.drive(0).switches().home_lo = 1e7;  // far away
    r.drive(0).switches().home_hi = kInf;
    r.bring_up();
    LONGS_EQUAL(int(Status::ok), int(r.master->start_homing(0, r.rig.clock.now())));
    for (int k = 0; k < 400; ++k) r.cycle();
    CHECK(std::fabs(r.drive(0).velocity()) > 1000);  // moving
    r.master->abort_homing(0);
    for (int k = 0; k < 2000 && r.master->homing(0).phase == HomingPhase::running; ++k) r.cycle();
    const HomingProgress p = r.master->homing(0);
    LONGS_EQUAL(int(HomingPhase::failed), int(p.phase));
    LONGS_EQUAL(int(Status::aborted), int(p.status));
    LONGS_EQUAL(cia402::kModeCsp, r.drive(0).mode_display());
    CHECK(std::isnan(r.drive(0).home_mark()));  // never homed
    for (int k = 0; k < 100; ++k) r.cycle();
    CHECK(std::fabs(r.drive(0).velocity()) < 50);
    LONGS_EQUAL(int(JointState::enabled), int(r.master->feedback(0).state));
    // Holding its actual position in CSP.
    CHECK(std::abs(r.master->last_target_counts(0) - std::int32_t(r.drive(0).position())) <= 2);
    // Homing again is possible.
    LONGS_EQUAL(int(Status::ok), int(r.master->start_homing(0, r.rig.clock.now())));
  }
}

TEST(Homing, SetpointsOfAHomingJointAreIgnored) {
  Rig r(1, [](CanopenMasterConfig& cfg) { cfg.joints[0].homing = drive_homing(34); });
  r.drive(0).switches().index_phase = 1000;
  r.bring_up();
  LONGS_EQUAL(int(Status::ok), int(r.master->start_homing(0, r.rig.clock.now())));
  const double junk[1] = {2.5};
  for (int k = 0; k < 3000 && r.master->homing(0).phase == HomingPhase::running; ++k) {
    const TimePoint now = r.rig.clock.now();
    r.master->read(now);
    LONGS_EQUAL(int(Status::ok), int(r.master->write(std::span<const double>(junk, 1), now)));
    r.rig.clock.advance(kPeriod);
  }
  LONGS_EQUAL(int(HomingPhase::attained), int(r.master->homing(0).phase));
  DOUBLES_EQUAL(1000, r.drive(0).physical_position(), 1.0);
}

TEST(Homing, DriveWithoutHomingIsRefusedAtStartNamingTheJoint) {
  Rig r(3, [](CanopenMasterConfig& cfg) { cfg.joints[2].homing = drive_homing(19); });
  sim::DriveQuirks q;
  q.no_homing = true;
  r.drive(2).set_quirks(q);
  LONGS_EQUAL(int(Status::not_supported), int(r.start()));
  STRCMP_EQUAL("joint 2 (node 3): homing method 19 configured but the drive does not support homing mode "
               "(6502h = 0x00000080)",
               r.master->last_error());
  // The same drive without homing configured is fine.
  Rig r2(3);
  r2.drive(2).set_quirks(q);
  r2.bring_up();
}

TEST(Homing, Epos4StyleModeMaskAndAMethodTheDriveLacks) {
  // 0x252 in CiA 402's layout: bits 1, 4, 6, 9 - neither CSP (bit 7) nor homing (bit 5).
  Rig r(2, [](CanopenMasterConfig& cfg) { cfg.check_supported_modes = true; });
  sim::DriveQuirks q;
  q.supported_modes = 0x252;
  r.drive(1).set_quirks(q);
  LONGS_EQUAL(int(Status::not_supported), int(r.start()));
  STRCMP_EQUAL("joint 1 (node 2): the drive does not support cyclic synchronous position mode (6502h = 0x00000252)",
               r.master->last_error());
  // Not asked (the default, no drive homing): the 6060h = 8 request decides, as before.
  Rig r0(2);
  r0.drive(1).set_quirks(q);
  LONGS_EQUAL(int(Status::sdo_abort), int(r0.start()));
  STRCMP_CONTAINS("node 2: SDO write 0x6060:0 = 0x8 (mode of operation: cyclic synchronous position) failed",
                  r0.master->last_error());
  // A homing joint reads 6502h anyway, and 0x252 has no homing (bit 5) either.
  Rig r1(2, [](CanopenMasterConfig& cfg) { cfg.joints[1].homing = drive_homing(21); });
  r1.drive(1).set_quirks(q);
  LONGS_EQUAL(int(Status::not_supported), int(r1.start()));
  STRCMP_CONTAINS("joint 1 (node 2): the drive does not support cyclic synchronous position mode", r1.master->last_error());
  // With CSP but without homing, and homing configured:
  Rig r2(2, [](CanopenMasterConfig& cfg) { cfg.joints[1].homing = drive_homing(21); });
  q.supported_modes = 0x252 | cia402::kSupportsCsp;
  r2.drive(1).set_quirks(q);
  LONGS_EQUAL(int(Status::not_supported), int(r2.start()));
  STRCMP_CONTAINS("joint 1 (node 2): homing method 21 configured but the drive does not support homing mode "
                  "(6502h = 0x000002D2)",
                  r2.master->last_error());
  // A method the drive does not implement (24) is refused at bring-up, naming the joint.
  Rig r3(2, [](CanopenMasterConfig& cfg) { cfg.joints[0].homing = drive_homing(24); });
  LONGS_EQUAL(int(Status::sdo_abort), int(r3.start()));
  STRCMP_CONTAINS("joint 0 (node 1): homing method 24 refused by the drive (6098h)", r3.master->last_error());
}

TEST(Homing, BadSpecsAreRefusedNamingTheField) {
  struct {
    std::function<void(HomingSpec&)> edit;
    const char* expect;
  } cases[] = {
      {[](HomingSpec& h) { h.method = 36; }, "homing method must be"},
      {[](HomingSpec& h) { h.method = 0; }, "homing method must be"},
      {[](HomingSpec& h) { h.speed_switch = NAN; }, "homing speed_switch must be finite and > 0"},
      {[](HomingSpec& h) { h.speed_zero = 0; }, "homing speed_zero must be finite and > 0"},
      {[](HomingSpec& h) { h.acceleration = -1; }, "homing acceleration"},
      {[](HomingSpec& h) { h.timeout = 0; }, "homing timeout must be > 0"},
      {[](HomingSpec& h) { h.offset = 1e9; }, "homing offset"},
      {[](HomingSpec& h) { h.kind = HomingKind::hard_stop; h.backoff = 0; h.following_limit = 0.01; },
       "homing backoff must be"},
      {[](HomingSpec& h) { h.kind = HomingKind::hard_stop; h.backoff = 0.1; h.following_limit = 0; },
       "homing following_limit must be"},
  };
  for (auto& c : cases) {
    test::SimRig rig({1, 2});
    CanopenMasterConfig cfg = CanopenMasterConfig::consecutive(1, 2);
    cfg.joints[1].homing = drive_homing(19);
    c.edit(cfg.joints[1].homing);
    CanopenServoBus m(*rig.master_ep, rig.clock, cfg);
    LONGS_EQUAL_TEXT(int(Status::invalid_argument), int(m.config_status()), c.expect);
    STRCMP_CONTAINS_TEXT("joint 1 (node 2)", m.last_error(), c.expect);
    STRCMP_CONTAINS_TEXT(c.expect, m.last_error(), c.expect);
  }
}

TEST(Homing, FaultResetNeedsARisingEdgeOfBit7) {
  // Drive side: bit 7 held high does not reset a second fault; 0 then 1 does.
  for (bool lenient : {false, true}) {
    test::SimRig rig({1});
    sim::DriveQuirks q;
    q.fault_reset_on_level = lenient;
    rig.sim->at(0).set_quirks(q);
    SdoClient sdo(*rig.master_ep, rig.clock);
    sim::VirtualDrive& d = rig.sim->at(0);
    d.inject_emcy(0x2310, rig.clock.now(), *rig.sim_ep);
    LONGS_EQUAL(int(Status::ok), int(sdo.write_u16(1, cia402::kControlword, 0, 0x80).status));
    STRCMP_EQUAL("switch_on_disabled", cia402::to_string(d.state()));
    d.inject_emcy(0x2310, rig.clock.now(), *rig.sim_ep);
    LONGS_EQUAL(int(Status::ok), int(sdo.write_u16(1, cia402::kControlword, 0, 0x80).status));
    STRCMP_EQUAL(lenient ? "switch_on_disabled" : "fault", cia402::to_string(d.state()));
    LONGS_EQUAL(int(Status::ok), int(sdo.write_u16(1, cia402::kControlword, 0, 0x00).status));
    LONGS_EQUAL(int(Status::ok), int(sdo.write_u16(1, cia402::kControlword, 0, 0x80).status));
    STRCMP_EQUAL("switch_on_disabled", cia402::to_string(d.state()));
  }
  // Master side: after a fault, enable() sends 0x00 then 0x80 (not 0x80 twice) and the drive resets.
  Rig r(1);
  r.bring_up();
  for (int k = 0; k < 20; ++k) r.cycle();
  r.drive(0).inject_emcy(0x2310, r.rig.clock.now(), *r.rig.sim_ep);
  for (int k = 0; k < 20; ++k) r.cycle();
  LONGS_EQUAL(int(JointState::fault), int(r.master->feedback(0).state));
  r.master->enable();
  for (int k = 0; k < 50; ++k) r.cycle();
  LONGS_EQUAL(int(JointState::enabled), int(r.master->feedback(0).state));
  // In the controlwords node 1 got: a 0x80 right after one with bit 7 clear, never two in a row.
  std::uint16_t prev = 0x0F;
  int resets = 0;
  for (const CanFrame& f : r.rig.capture()) {
    std::uint16_t cw;
    std::int32_t t;
    if (f.id != canopen::kRpdo1 + 1 || !pdo::decode_rpdo1(f, cw, t)) continue;
    if (cw & 0x80) {
      CHECK_FALSE(prev & 0x80);
      ++resets;
    }
    prev = cw;
  }
  CHECK(resets >= 1);
}

TEST(Homing, ModeChangeWhileHaltedTakesEffectWhenHaltClears) {
  for (bool quirk : {false, true}) {
    test::SimRig rig({1});
    sim::DriveQuirks q;
    q.halt_blocks_mode_change = quirk;
    rig.sim->at(0).set_quirks(q);
    SdoClient sdo(*rig.master_ep, rig.clock);
    sim::VirtualDrive& d = rig.sim->at(0);
    LONGS_EQUAL(int(Status::ok), int(sdo.write_u8(1, cia402::kModesOfOperation, 0, 8).status));
    for (std::uint16_t cw : {0x06, 0x07, 0x0F}) LONGS_EQUAL(int(Status::ok), int(sdo.write_u16(1, 0x6040, 0, cw).status));
    STRCMP_EQUAL("operation_enabled", cia402::to_string(d.state()));
    LONGS_EQUAL(int(Status::ok), int(sdo.write_u16(1, 0x6040, 0, 0x10F).status));  // halt
    LONGS_EQUAL(int(Status::ok), int(sdo.write_u8(1, cia402::kModesOfOperation, 0, 6).status));
    std::uint32_t shown = 0;
    sdo.read_u32(1, cia402::kModesDisplay, 0, shown);
    LONGS_EQUAL(quirk ? 8 : 6, int(shown));
    LONGS_EQUAL(int(Status::ok), int(sdo.write_u16(1, 0x6040, 0, 0x0F).status));  // halt cleared
    sdo.read_u32(1, cia402::kModesDisplay, 0, shown);
    LONGS_EQUAL(6, int(shown));
  }
}

TEST(Homing, ReRequestingTheActiveModeIsAvoided) {
  // The drive aborts a request for the mode it is already in (08000022h).
  test::SimRig rig({1});
  sim::DriveQuirks q;
  q.refuse_same_mode = true;
  rig.sim->at(0).set_quirks(q);
  SdoClient sdo(*rig.master_ep, rig.clock);
  LONGS_EQUAL(int(Status::ok), int(sdo.write_u8(1, cia402::kModesOfOperation, 0, 8).status));
  const SdoResult again = sdo.write_u8(1, cia402::kModesOfOperation, 0, 8);
  LONGS_EQUAL(int(Status::sdo_abort), int(again.status));
  UNSIGNED_LONGS_EQUAL(0x08000022u, again.abort_code);
  // The master reads 6061h first: bring-up twice, homing (6 then 8) all succeed.
  Rig r(1, [](CanopenMasterConfig& cfg) { cfg.joints[0].homing = drive_homing(35); });
  r.drive(0).set_quirks(q);
  r.bring_up();
  r.bring_up();
  r.home(0);
  LONGS_EQUAL(int(HomingPhase::attained), int(r.master->homing(0).phase));
  LONGS_EQUAL(int(Status::ok), int(r.master->start_homing(0, r.rig.clock.now())));
  while (r.master->homing(0).phase == HomingPhase::running) r.cycle();
  LONGS_EQUAL(int(HomingPhase::attained), int(r.master->homing(0).phase));
}

TEST(Homing, SdoRepliesTenMillisecondsLate) {
  sim::DriveQuirks q;
  q.sdo_delay = 10 * kMillisecond;
  {
    Rig r(2, [](CanopenMasterConfig& cfg) { cfg.sdo_timeout = 5 * kMillisecond; });
    r.drive(1).set_quirks(q);
    CHECK(r.start() == Status::timeout);
    STRCMP_CONTAINS("node 2", r.master->last_error());
  }
  Rig r(2, [](CanopenMasterConfig& cfg) {
    cfg.sdo_timeout = 30 * kMillisecond;
    cfg.joints[1].homing = drive_homing(19);
  });
  r.drive(1).set_quirks(q);
  r.drive(1).switches().home_lo = 30000;
  r.drive(1).switches().home_hi = kInf;
  r.bring_up();
  r.home(1);
  char msg[192];
  r.master->describe_homing(1, msg, sizeof msg);
  STRCMP_EQUAL("", msg);
  LONGS_EQUAL(int(HomingPhase::attained), int(r.master->homing(1).phase));
  DOUBLES_EQUAL(30000, r.drive(1).physical_position(), 1.0);
}

TEST(Homing, SlowBootUpWithBootTimeoutAndRetry) {
  sim::DriveQuirks q;
  q.boot_delay = 3 * kSecond;
  {
    Rig r(2, [](CanopenMasterConfig& cfg) { cfg.boot_timeout = 1 * kSecond; });
    r.drive(1).set_quirks(q);
    r.drive(1).power_on(r.rig.clock.now(), *r.rig.sim_ep);
    CHECK(r.start() == Status::timeout);
    STRCMP_CONTAINS("node 2: no answer to SDO 0x1000 (device type) within the boot timeout of 1000 ms",
                    r.master->last_error());
  }
  Rig r(2, [](CanopenMasterConfig& cfg) { cfg.boot_timeout = 5 * kSecond; });
  r.drive(1).set_quirks(q);
  const TimePoint t0 = r.rig.clock.now();
  r.drive(1).power_on(t0, *r.rig.sim_ep);
  r.bring_up();
  CHECK(r.rig.clock.now() - t0 >= 3 * kSecond);
}

TEST(Homing, HardStopBacksOffAndTakesTheOffsetThere) {
  for (bool by_torque : {false, true}) {
    Rig r(1, [&](CanopenMasterConfig& cfg) {
      HomingSpec& h = cfg.joints[0].homing;
      h.kind = HomingKind::hard_stop;
      h.speed_switch = -0.5;  // rad/s, towards the negative stop
      h.acceleration = 5;
      h.following_limit = by_torque ? 0.05 : 0.01;
      h.torque_limit = by_torque ? 0.005 : 0;  // N m; 6077h per mille of 6076h = 1 N m
      h.backoff = 0.05;
      h.offset = -1.0;
      h.timeout = 10 * kSecond;
      if (by_torque) cfg.tpdo2.torque = PdoUse::required;
    });
    r.drive(0).switches().end_neg = -60000;
    r.bring_up();
    const Duration took = r.home(0);
    char msg[192];
    r.master->describe_homing(0, msg, sizeof msg);
    STRCMP_EQUAL("", msg);
    LONGS_EQUAL(int(HomingPhase::attained), int(r.master->homing(0).phase));
    for (int k = 0; k < 100; ++k) r.cycle();
    // The bound: end stop + backoff within 2 counts (contact is seen at the stop, the
    // backed-off point is a whole count).
    const double expect = -60000 + 0.05 * kCps;
    DOUBLES_EQUAL(expect, r.drive(0).physical_position(), 2.0);
    DOUBLES_EQUAL(-1.0, r.master->feedback(0).position, 2.0 / kCps);
    CHECK(!r.drive(0).at_end_stop());
    char f[160];
    r.master->describe_fault(0, f, sizeof f);
    STRCMP_EQUAL("", r.master->feedback(0).state == JointState::fault ? f : "");
    std::printf("\n  hard_stop (%s): %.3f s, %.2f counts from end stop + backoff", by_torque ? "torque" : "following error",
                double(took) * 1e-9, r.drive(0).physical_position() - expect);
  }
  std::printf("\n");
}

TEST(Homing, ControlPathIsAllocationFreeWhileHoming) {
  Rig r(2, [](CanopenMasterConfig& cfg) {
    cfg.joints[0].homing = drive_homing(19);
    HomingSpec& h = cfg.joints[1].homing;
    h.kind = HomingKind::hard_stop;
    h.speed_switch = 0.5;
    h.acceleration = 5;
    h.following_limit = 0.01;
    h.backoff = 0.05;
    h.timeout = 10 * kSecond;
  });
  r.drive(0).switches().home_lo = 40000;
  r.drive(0).switches().home_hi = kInf;
  r.drive(1).switches().end_pos = 50000;
  r.bring_up();
  std::size_t allocs = 0;
  double sp[2] = {0, 0};
  char buf[160];
  for (int k = 0; k < 6000; ++k) {
    const TimePoint now = r.rig.clock.now();
    {
      test::AllocScope scope;
      if (k == 0) r.master->start_homing(0, now), r.master->start_homing(1, now);
      r.master->read(now);
      for (std::size_t j = 0; j < 2; ++j) sp[j] = r.master->feedback(j).position;
      r.master->write(std::span<const double>(sp, 2), now);
      (void)r.master->homing(0);
      r.master->describe_homing(0, buf, sizeof buf);
      if (k == 5000) r.master->start_homing(0, now), r.master->abort_homing(0);
      allocs += scope.end();
    }
    r.rig.clock.advance(kPeriod);
  }
  LONGS_EQUAL(0, allocs);
  LONGS_EQUAL(int(HomingPhase::attained), int(r.master->homing(1).phase));
}

TEST(Homing, SeededRunsSpreadOfThePositionAfterHoming) {
  // 100 runs per method family: random switch / index positions and start positions; the
  // spread (max - min) of (physical position after homing - the simulated mark), in counts.
  // Under qemu and the sanitizers the first 1/20 of the runs (tests/support/sweep.hpp).
  const int methods[] = {1, 17, 19, 21, 23, 27, 33, 35};
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u(0, 1);
  std::printf("\n");
  for (int m : methods) {
    double lo = 1e9, hi = -1e9, tsum = 0;
    const int runs = test::sweep(100);
    for (int k = 0; k < runs; ++k) {
      Rig r(1, [&](CanopenMasterConfig& cfg) { cfg.joints[0].homing = drive_homing(m); });
      sim::DriveSwitches& s = r.drive(0).switches();
      s.index_phase = std::floor(u(rng) * 131072);
      const double a = 20000 + u(rng) * 60000;
      double expect = 0;
      switch (m) {
        case 1: s.neg_limit = -a; expect = next_index(-a, +1, s.index_phase); break;
        case 17: s.neg_limit = -a; expect = -a; break;
        case 19: s.home_lo = a; s.home_hi = kInf; expect = a; break;
        case 21: s.home_lo = -kInf; s.home_hi = -a; expect = -a; break;
        case 23: s.home_lo = a; s.home_hi = a + 30000; s.pos_limit = 200000; s.neg_limit = -200000; expect = a; break;
        case 27: s.home_lo = -a - 30000; s.home_hi = -a; s.pos_limit = 200000; s.neg_limit = -200000; expect = -a; break;
        case 33: break;  // from the start position, below
        default: break;
      }
      r.bring_up();
      // A random start position: move there in CSP first.
      const double start = (u(rng) - 0.5) * 20000 / kCps;
      for (int c = 0; c < 400; ++c) {
        const double sp[1] = {start * std::min(1.0, c / 300.0)};
        const TimePoint now = r.rig.clock.now();
        r.master->read(now);
        r.master->write(std::span<const double>(sp, 1), now);
        r.rig.clock.advance(kPeriod);
      }
      if (m == 35) expect = r.drive(0).physical_position();
      if (m == 33) expect = next_index(r.drive(0).physical_position(), -1, s.index_phase);
      const Duration took = r.home(0);
      for (int c = 0; c < 30; ++c) r.cycle();
      char what[64];
      std::snprintf(what, sizeof what, "method %d run %d", m, k);
      LONGS_EQUAL_TEXT(int(HomingPhase::attained), int(r.master->homing(0).phase), what);
      const double e = r.drive(0).physical_position() - expect;
      DOUBLES_EQUAL_TEXT(0, e, 1.0, what);
      lo = std::min(lo, e);
      hi = std::max(hi, e);
      tsum += double(took) * 1e-9;
    }
    std::printf("  method %2d: %d runs, position after homing - mark in [%+.3f, %+.3f] counts (spread %.3f), "
                "mean homing time %.3f s\n",
                m, runs, lo, hi, hi - lo, tsum / runs);
  }
}

TEST(Homing, AFaultOrHeartbeatLossDuringHomingFailsIt) {
  for (int kind = 0; kind < 2; ++kind) {
    Rig r(2, [](CanopenMasterConfig& cfg) { cfg.joints[1].homing = drive_homing(19); });
    r.drive(1).switches().home_lo = 1e7;  // far away: still searching
    r.drive(1).switches().home_hi = kInf;
    r.bring_up();
    LONGS_EQUAL(int(Status::ok), int(r.master->start_homing(1, r.rig.clock.now())));
    for (int k = 0; k < 300; ++k) r.cycle();
    if (kind == 0) r.drive(1).inject_emcy(0x2310, r.rig.clock.now(), *r.rig.sim_ep);
    else r.drive(1).faults().silent = true;
    for (int k = 0; k < 3000 && r.master->homing(1).phase == HomingPhase::running; ++k) r.cycle();
    const HomingProgress p = r.master->homing(1);
    LONGS_EQUAL(int(HomingPhase::failed), int(p.phase));
    LONGS_EQUAL(int(kind == 0 ? Status::drive_fault : Status::heartbeat_lost), int(p.status));
    char msg[192];
    r.master->describe_homing(1, msg, sizeof msg);
    STRCMP_CONTAINS(kind == 0 ? "joint 1 (node 2): homing drive_fault" : "joint 1 (node 2): homing heartbeat_lost", msg);
    LONGS_EQUAL(int(JointState::fault), int(r.master->feedback(1).state));
    // The other joint is untouched; the faulted drive was taken back to CSP when it could answer.
    LONGS_EQUAL(int(JointState::enabled), int(r.master->feedback(0).state));
    if (kind == 0) LONGS_EQUAL(cia402::kModeCsp, r.drive(1).mode_display());
  }
}

namespace {
/// Runs joint 0's homing to its end; the largest |position - start| seen (rad, from the drive's
/// physical position, independent of what the master reports) and the message.
struct TravelRun {
  double peak = 0;
  HomingProgress p{};
  char msg[192] = {};
  Duration took = 0;
};
TravelRun run_supervised(Rig& r) {
  TravelRun t;
  const double start = r.drive(0).physical_position();
  const TimePoint t0 = r.rig.clock.now();
  LONGS_EQUAL(int(Status::ok), int(r.master->start_homing(0, t0)));
  for (int k = 0; k < 60000 && r.master->homing(0).phase == HomingPhase::running; ++k) {
    r.cycle();
    t.peak = std::max(t.peak, std::fabs(r.drive(0).physical_position() - start) / kCps);
  }
  t.took = r.rig.clock.now() - t0;
  for (int k = 0; k < 500; ++k) {  // it stays stopped
    r.cycle();
    t.peak = std::max(t.peak, std::fabs(r.drive(0).physical_position() - start) / kCps);
  }
  t.p = r.master->homing(0);
  r.master->describe_homing(0, t.msg, sizeof t.msg);
  return t;
}
}  // namespace

// Homing travel is supervised: a switch method whose switch is missing, and a hard stop that is
// missing, end once the joint is farther than HomingSpec::max_travel (the joint's range + the
// margin) from where homing began, with one line naming the joint and the distance; the drive
// stopped and back in CSP, long before the timeout.
TEST(Homing, TravelBeyondRangePlusMarginAbortsNamingJointAndDistance) {
  constexpr double kMaxTravel = 1.0;  // rad: e.g. a range of 50 deg + a margin of 7 deg
  // Method 17 (negative limit switch) on a drive with no switch and no end stop.
  {
    Rig r(1, [&](CanopenMasterConfig& cfg) {
      cfg.joints[0].homing = drive_homing(17);
      cfg.joints[0].homing.max_travel = kMaxTravel;
    });
    r.bring_up();
    const TravelRun t = run_supervised(r);
    std::printf("\n  method 17 without its switch: stopped after %.3f s, peak travel %.4f rad (limit %.4f): %s",
                double(t.took) * 1e-9, t.peak, kMaxTravel, t.msg);
    LONGS_EQUAL(int(HomingPhase::failed), int(t.p.phase));
    LONGS_EQUAL(int(Status::homing_error), int(t.p.status));
    STRCMP_CONTAINS("joint 0 (node 1): homing travel 57.", t.msg);  // 1 rad = 57.30 deg, just past it
    STRCMP_CONTAINS("from where it began, beyond the limit 57.", t.msg);
    CHECK(std::strchr(t.msg, '\n') == nullptr);
    // At rest within the PDO round trip's travel (5 cycles) plus the braking distance at the
    // homing acceleration (609Ah: the drive's halt ramp) beyond the limit.
    const double v = 1.0 * kRev, a = 20 * kRev;
    CHECK_TEXT(t.peak <= kMaxTravel + v * 0.005 + v * v / (2 * a), t.msg);
    CHECK(t.took < 5 * kSecond);  // the timeout is 20 s
    LONGS_EQUAL(cia402::kModeCsp, r.drive(0).mode_display());
    LONGS_EQUAL(int(JointState::enabled), int(r.master->feedback(0).state));
    CHECK(std::fabs(r.drive(0).velocity()) < 50);
  }
  // Hard stop homing with the stop missing.
  {
    Rig r(1, [&](CanopenMasterConfig& cfg) {
      HomingSpec& h = cfg.joints[0].homing;
      h.kind = HomingKind::hard_stop;
      h.speed_switch = -0.5;
      h.acceleration = 5;
      h.following_limit = 0.01;
      h.backoff = 0.05;
      h.offset = -1.0;
      h.timeout = 30 * kSecond;
      h.max_travel = kMaxTravel;
    });
    r.bring_up();
    const TravelRun t = run_supervised(r);
    std::printf("\n  hard stop missing: stopped after %.3f s, peak travel %.4f rad (limit %.4f): %s\n",
                double(t.took) * 1e-9, t.peak, kMaxTravel, t.msg);
    LONGS_EQUAL(int(HomingPhase::failed), int(t.p.phase));
    LONGS_EQUAL(int(Status::homing_error), int(t.p.status));
    STRCMP_CONTAINS("joint 0 (node 1): homing travel 57.", t.msg);
    STRCMP_CONTAINS("from where it began, beyond the limit 57.", t.msg);
    CHECK_TEXT(t.peak <= kMaxTravel + 0.5 * 0.005 + 0.5 * 0.5 / (2 * 5), t.msg);
    CHECK(t.took < 5 * kSecond);
    LONGS_EQUAL(int(JointState::enabled), int(r.master->feedback(0).state));
    CHECK(std::fabs(r.drive(0).velocity()) < 50);
  }
}

// The drive's position jumps to 607Ch when it latches the mark (before it reports bit 12 on
// some drives): that is no travel. Home switch at 50000 counts (2.4 rad from the start),
// offset -3 rad: the reported position jumps by 5.4 rad, the joint travelled 2.4 rad < 2.8.
TEST(Homing, TheMarksCoordinateJumpIsNotTravel) {
  Rig r(1, [](CanopenMasterConfig& cfg) {
    cfg.joints[0].homing = drive_homing(19);
    cfg.joints[0].homing.offset = -3.0;
    cfg.joints[0].homing.max_travel = 2.8;
  });
  r.drive(0).switches().home_lo = 50000;
  r.drive(0).switches().home_hi = kInf;
  r.bring_up();
  const TravelRun t = run_supervised(r);
  STRCMP_EQUAL("", t.msg);
  LONGS_EQUAL(int(HomingPhase::attained), int(t.p.phase));
  DOUBLES_EQUAL(-3.0, r.master->feedback(0).position, 2.0 / kCps);
}
