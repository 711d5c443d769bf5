// SPDX-License-Identifier: Apache-2.0
// Interoperability: what a CANopen master written elsewhere needs from our
// virtual drives, and what our master needs to bring up drives that are not ours.
//  - CiA 402 driven by SDO only: a controlword written by SDO acts when it is written,
//    in PRE-OPERATIONAL as in OPERATIONAL, with no SYNC and no PDO.
//  - A drive in FAULT at power-on: the master's bring-up resets it (bit 7 rising edge).
//  - PDO mapping that follows the configuration and what the drive has: optional objects
//    left out, a required missing object named in the error.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "servoarm/hal/canopen.hpp"
#include "servoarm/hal/sdo_client.hpp"
#include "sim_fixture.hpp"

// CppUTest last: its leak detector redefines `new`.
#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::hal;
namespace c402 = servoarm::hal::cia402;

namespace {
constexpr Duration kPeriod = kMillisecond;

// The statusword bits that say the CiA 402 state (0x006F mask), as a master reads them.
c402::State state_by_sdo(SdoClient& sdo, std::uint8_t node) {
  std::uint32_t sw = 0;
  const SdoResult r = sdo.read_u32(node, c402::kStatusword, 0, sw);
  if (r.status != Status::ok) return c402::State::not_ready_to_switch_on;
  return c402::decode_statusword(std::uint16_t(sw));
}

std::size_t count_sync(const std::vector<CanFrame>& fs) {
  std::size_t n = 0;
  for (const CanFrame& f : fs) n += f.id == canopen::kSync ? 1 : 0;
  return n;
}
}  // namespace

TEST_GROUP(InteropSdoOnly) {
  test::SimRig* rig = nullptr;
  SdoClient* sdo = nullptr;
  void setup() override {
    rig = new test::SimRig({5});
    sdo = new SdoClient(*rig->master_ep, rig->clock, 100 * kMillisecond);
  }
  void teardown() override {
    delete sdo;
    delete rig;
  }
  void write_cw(std::uint16_t cw) {
    LONGS_EQUAL(int(Status::ok), int(sdo->write_u16(5, c402::kControlword, 0, cw).status));
  }
};

// The exchange the issue reports (601#2B40600007000000 acknowledged, 6041h unchanged 0.3 s
// later): every controlword by SDO now takes effect before the next SDO request, in
// pre-operational, with no SYNC ever sent.
TEST(InteropSdoOnly, PowerStateMachineBySdoInPreOperational) {
  sim::VirtualDrive* d = rig->sim->node(5);
  LONGS_EQUAL(int(canopen::NmtState::pre_operational), int(d->nmt()));
  LONGS_EQUAL(int(Status::ok), int(sdo->write_u8(5, c402::kModesOfOperation, 0, 8).status));
  LONGS_EQUAL(int(c402::State::switch_on_disabled), int(state_by_sdo(*sdo, 5)));
  struct Step {
    std::uint16_t cw;
    c402::State want;
  } steps[] = {
      {0x0006, c402::State::ready_to_switch_on},   // shutdown (T2)
      {0x0007, c402::State::switched_on},          // switch on (T3)
      {0x000F, c402::State::operation_enabled},    // enable operation (T4)
      {0x0007, c402::State::switched_on},          // disable operation (T5)
      {0x000F, c402::State::operation_enabled},    // T4 again
      {0x0002, c402::State::quick_stop_active},    // quick stop (T11)
      {0x0000, c402::State::switch_on_disabled},   // disable voltage (T12)
  };
  for (const Step& s : steps) {
    write_cw(s.cw);
    // Read back at once: the answer to the very next SDO request already shows it.
    const c402::State got = state_by_sdo(*sdo, 5);
    if (got != s.want) {
      char msg[96];
      std::snprintf(msg, sizeof msg, "controlword 0x%04X by SDO: state %s, want %s", unsigned(s.cw), c402::to_string(got),
                    c402::to_string(s.want));
      FAIL(msg);
    }
  }
  LONGS_EQUAL(0, count_sync(rig->capture()));
  UNSIGNED_LONGS_EQUAL(0, d->syncs_seen());
  LONGS_EQUAL(int(canopen::NmtState::pre_operational), int(d->nmt()));
}

// Same in OPERATIONAL, and a target position written by SDO moves the motor with no SYNC.
TEST(InteropSdoOnly, EnableAndMoveBySdoInOperationalWithoutSync) {
  sim::VirtualDrive* d = rig->sim->node(5);
  rig->master_ep->send(canopen::encode_nmt(canopen::NmtCommand::start, 5));
  rig->clock.advance(kMillisecond);
  LONGS_EQUAL(int(canopen::NmtState::operational), int(d->nmt()));
  // Move the shaft away from 0 first (by hand, power off): enabling must not pull it to 0.
  LONGS_EQUAL(int(Status::ok), int(sdo->write_u8(5, c402::kModesOfOperation, 0, 8).status));
  write_cw(0x0006);
  write_cw(0x0007);
  write_cw(0x000F);
  LONGS_EQUAL(int(c402::State::operation_enabled), int(d->state()));
  // Enabling set the demand to where the shaft stands (607Ah too).
  std::uint32_t t = 1;
  LONGS_EQUAL(int(Status::ok), int(sdo->read_u32(5, c402::kTargetPosition, 0, t).status));
  LONGS_EQUAL(std::lround(d->position()), std::int32_t(t));
  LONGS_EQUAL(int(Status::ok), int(sdo->write_u32(5, c402::kTargetPosition, 0, 4000).status));
  LONGS_EQUAL(4000, d->target());  // applied when written
  rig->clock.advance(100 * kMillisecond);
  std::uint32_t pos = 0;
  LONGS_EQUAL(int(Status::ok), int(sdo->read_u32(5, c402::kPositionActual, 0, pos).status));
  CHECK(std::abs(std::int32_t(pos) - 4000) <= 1);
  LONGS_EQUAL(0, count_sync(rig->capture()));
}

// A fault by SDO: fault reset (bit 7 rising edge) written by SDO in pre-operational.
TEST(InteropSdoOnly, FaultResetBySdoInPreOperational) {
  sim::VirtualDrive* d = rig->sim->node(5);
  d->inject_emcy(0x2310, rig->clock.now(), *rig->sim_ep);
  LONGS_EQUAL(int(c402::State::fault), int(state_by_sdo(*sdo, 5)));
  std::uint32_t code = 0;
  sdo->read_u32(5, c402::kErrorCode, 0, code);
  UNSIGNED_LONGS_EQUAL(0x2310, code);
  write_cw(0x0000);
  LONGS_EQUAL(int(c402::State::fault), int(state_by_sdo(*sdo, 5)));
  write_cw(0x0080);  // rising edge of bit 7
  LONGS_EQUAL(int(c402::State::switch_on_disabled), int(state_by_sdo(*sdo, 5)));
  sdo->read_u32(5, c402::kErrorCode, 0, code);
  UNSIGNED_LONGS_EQUAL(0, code);
  write_cw(0x0080);  // bit 7 held: no edge, nothing happens
  LONGS_EQUAL(int(c402::State::switch_on_disabled), int(state_by_sdo(*sdo, 5)));
  // A fault whose cause persists: the reset is refused, the drive stays in fault.
  d->faults().fault_persists = true;
  d->inject_emcy(0x2310, rig->clock.now(), *rig->sim_ep);
  write_cw(0x0000);
  write_cw(0x0080);
  LONGS_EQUAL(int(c402::State::fault), int(state_by_sdo(*sdo, 5)));
}

// A stopped node answers no SDO (CiA 301): the controlword is not applied there.
TEST(InteropSdoOnly, StoppedNodeIgnoresSdo) {
  sim::VirtualDrive* d = rig->sim->node(5);
  rig->master_ep->send(canopen::encode_nmt(canopen::NmtCommand::stop, 5));
  rig->clock.advance(kMillisecond);
  const SdoResult r = sdo->write_u16(5, c402::kControlword, 0, 0x0006);
  LONGS_EQUAL(int(Status::timeout), int(r.status));
  LONGS_EQUAL(int(c402::State::switch_on_disabled), int(d->state()));
}

// ---------------------------------------------------------------- fault at power-on

TEST_GROUP(InteropFaultAtPowerOn) {
  test::SimRig* rig = nullptr;
  CanopenServoBus* master = nullptr;
  void setup() override {
    rig = new test::SimRig({1, 2, 3});
    CanopenMasterConfig cfg = CanopenMasterConfig::consecutive(1, 3);
    cfg.heartbeat_period = 20 * kMillisecond;
    cfg.heartbeat_timeout = 60 * kMillisecond;
    cfg.state_timeout = 200 * kMillisecond;
    master = new CanopenServoBus(*rig->master_ep, rig->clock, cfg);
  }
  void teardown() override {
    delete master;
    delete rig;
  }
};

// `armsim --emcy 1:0x2310@0` with canmaster, in process: node 1 is in FAULT before the
// master starts. Bring-up resets it (controlword 0x0000 then 0x0080 in its RPDOs) and
// enables every drive.
TEST(InteropFaultAtPowerOn, BringUpResetsADriveThatStartsInFault) {
  rig->sim->node(1)->inject_emcy(0x2310, rig->clock.now(), *rig->sim_ep);
  LONGS_EQUAL(int(c402::State::fault), int(rig->sim->node(1)->state()));
  rig->capture();
  LONGS_EQUAL(int(Status::ok), int(master->start(rig->clock.now() + 2 * kSecond)));
  const Status e = master->enable_blocking(rig->clock.now() + kSecond, kPeriod);
  STRCMP_EQUAL("", master->last_error());
  LONGS_EQUAL(int(Status::ok), int(e));
  for (std::size_t j = 0; j < 3; ++j) LONGS_EQUAL(int(JointState::enabled), int(master->feedback(j).state));
  // The spy saw node 1's controlword go 0x0000 -> 0x0080 (the rising edge), and the drive
  // said so with an EMCY "error reset" (code 0).
  bool saw_low = false, saw_edge = false, saw_reset_emcy = false;
  for (const CanFrame& f : rig->capture()) {
    std::uint16_t cw;
    std::int32_t tgt;
    if (f.id == canopen::kRpdo1 + 1 && pdo::decode_rpdo1(f, cw, tgt)) {
      if (cw == 0x0000) saw_low = true;
      if (cw == 0x0080 && saw_low) saw_edge = true;
    }
    if (f.id == canopen::kEmcy + 1 && f.len == 8 && f.data[0] == 0 && f.data[1] == 0) saw_reset_emcy = true;
  }
  CHECK(saw_edge);
  CHECK(saw_reset_emcy);
  LONGS_EQUAL(int(c402::State::operation_enabled), int(rig->sim->node(1)->state()));
}

// A fault that does not clear: bring-up fails with drive_fault and the drive's error code
// (not "drive_refused ... stayed in fault").
TEST(InteropFaultAtPowerOn, PersistentFaultNamesItsErrorCode) {
  rig->sim->node(2)->faults().fault_persists = true;
  rig->sim->node(2)->inject_emcy(0x2310, rig->clock.now(), *rig->sim_ep);
  LONGS_EQUAL(int(Status::ok), int(master->start(rig->clock.now() + 2 * kSecond)));
  const Status e = master->enable_blocking(rig->clock.now() + kSecond, kPeriod);
  LONGS_EQUAL(int(Status::drive_fault), int(e));
  STRCMP_CONTAINS("node 2: drive_fault (error code 0x2310", master->last_error());
  LONGS_EQUAL(int(Status::drive_fault), int(master->feedback(1).fault));
}

// A drive that faults after it was seen healthy is still a fault at once (not reset behind
// the supervisor's back).
TEST(InteropFaultAtPowerOn, FaultAfterEnableIsStillReported) {
  LONGS_EQUAL(int(Status::ok), int(master->start(rig->clock.now() + 2 * kSecond)));
  LONGS_EQUAL(int(Status::ok), int(master->enable_blocking(rig->clock.now() + kSecond, kPeriod)));
  rig->sim->node(3)->inject_emcy(0x4310, rig->clock.now(), *rig->sim_ep);
  double sp[3];
  Status r = Status::ok;
  for (int k = 0; k < 5; ++k) {
    for (std::size_t j = 0; j < 3; ++j) sp[j] = master->feedback(j).position;
    r = master->read(rig->clock.now());
    master->write(std::span<const double>(sp, 3), rig->clock.now());
    rig->clock.advance(kPeriod);
  }
  LONGS_EQUAL(int(Status::drive_fault), int(r));
  LONGS_EQUAL(int(JointState::fault), int(master->feedback(2).state));
  UNSIGNED_LONGS_EQUAL(0x4310, master->feedback(2).error_code);
}

// ---------------------------------------------------------------- PDO mapping

namespace {
struct MapCase {
  const char* name;
  std::vector<std::uint16_t> without;  // objects the drive lacks
  bool check_entries;                  // drive checks entries when written (else at sub 0)
  FeedbackObjects want;
  bool ok;
  bool velocity, error_code, torque;  // mapped into TPDO2
  const char* error;                  // part of last_error() when !ok
};
}  // namespace

TEST_GROUP(InteropPdoMapping){};

TEST(InteropPdoMapping, FollowsConfigurationAndWhatTheDriveHas) {
  const FeedbackObjects dflt{};
  FeedbackObjects req_vel;
  req_vel.velocity = PdoUse::required;
  FeedbackObjects with_torque;
  with_torque.torque = PdoUse::optional;
  FeedbackObjects none;
  none.velocity = none.error_code = none.torque = PdoUse::off;
  const MapCase cases[] = {
      {"everything there", {}, false, dflt, true, true, true, false, ""},
      {"no 606C (sub-0 checks)", {0x606C}, false, dflt, true, false, true, false, ""},
      {"no 606C (entry checks)", {0x606C}, true, dflt, true, false, true, false, ""},
      {"no 603F (sub-0 checks)", {0x603F}, false, dflt, true, true, false, false, ""},
      {"no 603F (entry checks)", {0x603F}, true, dflt, true, true, false, false, ""},
      {"neither (sub-0 checks)", {0x606C, 0x603F}, false, dflt, true, false, false, false, ""},
      {"neither (entry checks)", {0x606C, 0x603F}, true, dflt, true, false, false, false, ""},
      {"torque asked, there", {}, false, with_torque, true, true, true, true, ""},
      {"torque asked, absent", {0x6077}, true, with_torque, true, true, true, false, ""},
      {"TPDO2 off by configuration", {}, false, none, true, false, false, false, ""},
      {"velocity required, absent (sub 0)", {0x606C}, false, req_vel, false, false, false, false,
       "node 1: TPDO2 needs 0x606C (velocity actual), which the drive does not have"},
      {"velocity required, absent (entry)", {0x606C}, true, req_vel, false, false, false, false,
       "node 1: TPDO2 needs 0x606C (velocity actual), which the drive cannot map"},
      {"position actual absent", {0x6064}, true, dflt, false, false, false, false,
       "node 1: TPDO1 needs 0x6064 (position actual)"},
      {"position actual absent (sub 0)", {0x6064}, false, dflt, false, false, false, false,
       "node 1: TPDO1 needs 0x6064 (position actual), which the drive does not have"},
  };
  for (const MapCase& c : cases) {
    sim::MotorParams mp;
    mp.check_map_entries = c.check_entries;
    test::SimRig rig({1, 2}, mp);
    for (std::uint16_t idx : c.without) rig.sim->node(1)->od_remove(idx);
    CanopenMasterConfig cfg = CanopenMasterConfig::consecutive(1, 2);
    cfg.tpdo2 = c.want;
    CanopenServoBus m(*rig.master_ep, rig.clock, cfg);
    const Status s = m.start(rig.clock.now() + 2 * kSecond);
    std::string tag = std::string(c.name) + ": " + m.last_error();
    CHECK_TEXT((s == Status::ok) == c.ok, tag.c_str());
    if (!c.ok) {
      CHECK_TEXT(std::strstr(m.last_error(), c.error) != nullptr, tag.c_str());
      continue;
    }
    CHECK_TEXT(m.maps(0, 0x606C) == c.velocity, tag.c_str());
    CHECK_TEXT(m.maps(0, 0x603F) == c.error_code, tag.c_str());
    CHECK_TEXT(m.maps(0, 0x6077) == c.torque, tag.c_str());
    // Node 2 has everything: it gets what was asked.
    CHECK_TEXT(m.maps(1, 0x606C) == (c.want.velocity != PdoUse::off), tag.c_str());
    // The drive's own TPDO2 says the same (count, and off when empty).
    std::uint32_t count = 9, cob = 0;
    rig.sim->node(1)->od_read(0x1A01, 0, count);
    rig.sim->node(1)->od_read(0x1801, 1, cob);
    UNSIGNED_LONGS_EQUAL_TEXT(unsigned(c.velocity) + unsigned(c.error_code) + unsigned(c.torque), count, tag.c_str());
    CHECK_TEXT(((cob & 0x80000000u) != 0) == (count == 0), tag.c_str());
    // And it runs: enable, move joint 1 at 1 rad/s for 0.3 s; velocity is reported either way.
    CHECK_TEXT(m.enable_blocking(rig.clock.now() + kSecond, kPeriod) == Status::ok, tag.c_str());
    const double p0 = m.feedback(0).position;
    double sp[2] = {p0, m.feedback(1).position};
    for (int k = 0; k < 300; ++k) {
      m.read(rig.clock.now());
      sp[0] = p0 + 1.0 * k * 1e-3;
      m.write(std::span<const double>(sp, 2), rig.clock.now());
      rig.clock.advance(kPeriod);
    }
    m.read(rig.clock.now());
    // (The first-order motor's velocity within a 1 ms step of the target is a sawtooth
    // around 1 rad/s: 0.79..1.2 at the sample instants; the difference of positions, 1.0.)
    DOUBLES_EQUAL_TEXT(1.0, m.feedback(0).velocity, 0.25, tag.c_str());
    LONGS_EQUAL_TEXT(int(JointState::enabled), int(m.feedback(0).state), tag.c_str());
    CHECK_TEXT(m.feedback(0).has_torque == c.torque, tag.c_str());
  }
}
