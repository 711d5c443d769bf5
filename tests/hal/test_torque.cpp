// SPDX-License-Identifier: Apache-2.0
// Feed-forward and torque mode through the CANopen master: RPDO2 with the CSP
// offsets 60B1h/60B2h and the target torque 6071h, 6060h/6061h in RPDO1/TPDO1, the switch
// CSP <-> CST on virtual drives on the dynamic plant; what a default configuration sends is
// unchanged. Expected values are computed here from the drive's own objects (6076h) and the
// scaling, not from the master.
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "alloc_counter.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/kinematics/dynamics.hpp"
#include "servoarm/sim/arm_plant.hpp"
#include "sim_fixture.hpp"

// CppUTest last: its leak detector redefines `new`.
#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::hal;
using servoarm::test::SimRig;

namespace {

constexpr Duration kPeriod = kMillisecond;

kin::Chain puma() {
  kin::LoadResult lr = kin::load_robot("puma560");
  if (!lr.ok) FAIL(lr.error.c_str());
  return lr.chain;
}

// Six drives, on the dynamic plant of the PUMA 560 unless `plant` is false.
struct Rig {
  SimRig rig{{1, 2, 3, 4, 5, 6}};
  kin::Chain chain = puma();
  CanopenMasterConfig cfg = CanopenMasterConfig::consecutive(1, 6);
  std::unique_ptr<CanopenServoBus> master;

  explicit Rig(bool plant = true, double gear = 1.0, int direction = 1) {
    for (auto& j : cfg.joints) j.scaling.gear_ratio = gear, j.scaling.direction = direction;
    cfg.heartbeat_period = 20 * kMillisecond;
    cfg.heartbeat_timeout = 60 * kMillisecond;
    if (plant) {
      std::vector<JointScaling> sc;
      for (std::size_t j = 0; j < 6; ++j) sc.push_back(cfg.joints[j].scaling);
      const std::string e = rig.sim->use_dynamic_plant(chain, sc, {});
      STRCMP_EQUAL("", e.c_str());
    }
  }
  Status start() {
    master = std::make_unique<CanopenServoBus>(*rig.master_ep, rig.clock, cfg);
    return master->start(rig.clock.now() + 2 * kSecond);
  }
  void bring_up() {
    LONGS_EQUAL(int(Status::ok), int(start()));
    STRCMP_EQUAL("", master->last_error());
    LONGS_EQUAL(int(Status::ok), int(master->enable_blocking(rig.clock.now() + kSecond, kPeriod)));
  }
  std::vector<double> positions() const {
    std::vector<double> q;
    for (std::size_t j = 0; j < 6; ++j) q.push_back(master->feedback(j).position);
    return q;
  }
  void cycle(const std::vector<double>& sp) {
    master->read(rig.clock.now());
    master->write(sp, rig.clock.now());
    rig.clock.advance(kPeriod);
  }
  std::uint32_t od(std::size_t j, std::uint16_t index) {
    std::uint32_t v = 0;
    CHECK(rig.sim->at(j).od_read(index, 0, v));
    return v;
  }
  // Joint-side N m per per-mille unit, from the drive's 6076h and the scaling.
  double unit(std::size_t j) {
    const JointScaling& s = cfg.joints[j].scaling;
    return double(od(j, cia402::kRatedTorque)) * 1e-6 * s.gear_ratio * double(s.direction);
  }
};

}  // namespace

TEST_GROUP(TorqueObjects){};

// Default configuration: no RPDO2, RPDO1 6 bytes, nothing of it reachable through the API.
TEST(TorqueObjects, DefaultConfigurationSendsTheFramesOfBefore) {
  Rig r(true);
  r.bring_up();
  r.rig.capture();
  const std::vector<double> hold = r.positions();
  r.cycle(hold);
  int rpdo1 = 0;
  for (const CanFrame& f : r.rig.capture()) {
    CHECK((f.id & 0x780) != 0x300);  // no RPDO2
    if ((f.id & 0x780) == 0x200) {
      ++rpdo1;
      LONGS_EQUAL(6, f.len);
    }
    if ((f.id & 0x780) == 0x180) LONGS_EQUAL(6, f.len);
  }
  LONGS_EQUAL(6, rpdo1);
  const JointCapabilities c = r.master->capabilities(0);
  CHECK(!c.velocity_offset && !c.torque_offset && !c.torque_mode && !c.measured_torque);
  LONGS_EQUAL(int(Status::not_supported), int(r.master->set_feed_forward(0, 0.1, 1.0)));
  LONGS_EQUAL(int(Status::not_supported), int(r.master->set_target_torque(0, 1.0)));
  LONGS_EQUAL(int(Status::not_supported), int(r.master->set_torque_mode(0, true)));
  LONGS_EQUAL(int(Status::ok), int(r.master->set_torque_mode(0, false)));
}

// The offsets reach the drive in joint units converted by the scaling (gear 3, direction -1):
// 60B1h = dir x v x counts/rad, 60B2h = torque / (6076h x G x dir) per mille; once per call.
TEST(TorqueObjects, FeedForwardReachesTheDriveOncePerCall) {
  Rig r(true, 3.0, -1);
  r.cfg.rpdo2.velocity_offset = PdoUse::required;
  r.cfg.rpdo2.torque_offset = PdoUse::required;
  r.bring_up();
  const JointCapabilities c = r.master->capabilities(2);
  CHECK(c.velocity_offset && c.torque_offset && !c.torque_mode);
  const std::vector<double> hold = r.positions();
  r.cycle(hold);
  r.rig.capture();
  LONGS_EQUAL(int(Status::ok), int(r.master->set_feed_forward(2, 0.5, 12.0)));
  r.cycle(hold);
  const double cps = r.cfg.joints[2].scaling.counts_per_si();
  LONGS_EQUAL(std::lround(-0.5 * cps), std::int32_t(r.od(2, cia402::kVelocityOffset)));
  LONGS_EQUAL(std::lround(12.0 / r.unit(2)), std::int16_t(r.od(2, cia402::kTorqueOffset)));
  CHECK(std::int16_t(r.od(2, cia402::kTorqueOffset)) < 0);  // direction -1
  int rpdo2 = 0;
  for (const CanFrame& f : r.rig.capture()) {
    if ((f.id & 0x780) == 0x300) {
      ++rpdo2;
      LONGS_EQUAL(6, f.len);  // 60B1h (4) + 60B2h (2)
    }
  }
  LONGS_EQUAL(6, rpdo2);
  r.cycle(hold);  // not given again: 0
  LONGS_EQUAL(0, std::int32_t(r.od(2, cia402::kVelocityOffset)));
  LONGS_EQUAL(0, std::int16_t(r.od(2, cia402::kTorqueOffset)));
  // Bad values: refused, and nothing is sent for them.
  LONGS_EQUAL(int(Status::ok), int(r.master->set_feed_forward(1, 0.2, 3.0)));
  LONGS_EQUAL(int(Status::invalid_argument), int(r.master->set_feed_forward(1, std::nan(""), 3.0)));
  r.cycle(hold);
  LONGS_EQUAL(0, std::int16_t(r.od(1, cia402::kTorqueOffset)));
  LONGS_EQUAL(int(Status::invalid_argument), int(r.master->set_feed_forward(1, 0.0, 1e9)));
  LONGS_EQUAL(int(Status::invalid_argument), int(r.master->set_feed_forward(1, 1e12, 0.0)));
  LONGS_EQUAL(int(Status::invalid_argument), int(r.master->set_feed_forward(9, 0.0, 0.0)));
  // Not following (disabled): offsets are 0 whatever is given.
  r.master->disable();
  for (int k = 0; k < 20; ++k) r.cycle(hold);
  LONGS_EQUAL(int(Status::ok), int(r.master->set_feed_forward(1, 0.2, 3.0)));
  r.cycle(hold);
  LONGS_EQUAL(0, std::int16_t(r.od(1, cia402::kTorqueOffset)));
  // A configured rated torque replaces 6076h: 2.5 N m motor side, gear 3, direction -1.
  r.cfg.joints[4].rated_torque = 2.5;
  LONGS_EQUAL(int(Status::ok), int(r.start()));
  DOUBLES_EQUAL(2.5e-3 * 3.0 * -1.0, r.master->torque_unit(4), 1e-15);
}

// Feed-forward on a joint moving at constant speed: the velocity lag v / kp of the drive's
// position loop is gone with 60B1h = v (the following error 60F4h falls >= 20x).
TEST(TorqueObjects, VelocityOffsetRemovesTheVelocityLag) {
  double fe[2] = {};
  for (int with = 0; with < 2; ++with) {
    Rig r(true);
    r.cfg.rpdo2.velocity_offset = PdoUse::required;
    r.cfg.rpdo2.torque_offset = PdoUse::required;
    r.bring_up();
    std::vector<double> sp = r.positions();
    const double q0 = sp[0], v = 0.4;
    kin::JointVector q(6), qd = kin::JointVector::Zero(6), qdd = kin::JointVector::Zero(6), tau(6);
    for (int k = 0; k < 600; ++k) {
      sp[0] = q0 + v * std::max(0, k - 50) * 1e-3;
      for (int j = 0; j < 6; ++j) q[j] = sp[std::size_t(j)];
      qd[0] = k >= 50 ? v : 0;
      CHECK(kin::inverse_dynamics(r.chain, q, qd, qdd, tau) == kin::Status::ok);
      if (with)
        for (std::size_t j = 0; j < 6; ++j) r.master->set_feed_forward(j, qd[int(j)], tau[int(j)]);
      r.cycle(sp);
      if (k > 400) fe[with] = std::max(fe[with], std::fabs(double(std::int32_t(r.od(0, 0x60F4)))));
    }
  }
  std::printf("\n  joint 1 at 0.4 rad/s: following error %.0f counts without feed-forward, %.0f with\n", fe[0], fe[1]);
  CHECK(fe[0] > 100);
  CHECK(fe[1] * 20 < fe[0]);
}

// Torque mode on the plant: the master refuses without a target torque, then switches the
// joints to CST (6061h = 10 within 3 cycles) with gravity compensation as target torque (the
// arm holds: drift below 5 mrad in 1 s), and back to CSP where the joints stand (no jump).
TEST(TorqueObjects, SwitchesToTorqueModeAndBack) {
  Rig r(true);
  r.cfg.rpdo2.torque_mode = PdoUse::required;
  r.bring_up();
  for (std::size_t j = 0; j < 6; ++j) CHECK(r.master->capabilities(j).torque_mode);
  CHECK(r.od(0, cia402::kSupportedModes) & cia402::kSupportsCst);
  std::vector<double> hold = r.positions();
  r.cycle(hold);
  LONGS_EQUAL(int(Status::bad_state), int(r.master->set_torque_mode(0, true)));  // no target torque yet
  kin::JointVector q(6), g(6);
  for (int j = 0; j < 6; ++j) q[j] = hold[std::size_t(j)];
  CHECK(kin::gravity_torques(r.chain, q, g) == kin::Status::ok);
  for (std::size_t j = 0; j < 6; ++j) {
    LONGS_EQUAL(int(Status::ok), int(r.master->set_target_torque(j, g[int(j)])));
    LONGS_EQUAL(int(Status::ok), int(r.master->set_torque_mode(j, true)));
    LONGS_EQUAL(int(CyclicMode::entering_torque), int(r.master->cyclic_mode(j).mode));
  }
  int cycles = 0;
  while (r.master->cyclic_mode(1).mode != CyclicMode::torque && cycles < 50) r.cycle(hold), ++cycles;
  CHECK(cycles <= 3);
  for (std::size_t j = 0; j < 6; ++j) {
    LONGS_EQUAL(int(CyclicMode::torque), int(r.master->cyclic_mode(j).mode));
    LONGS_EQUAL(cia402::kModeCst, r.rig.sim->at(j).mode_display());
    LONGS_EQUAL(std::lround(g[int(j)] / r.unit(j)), std::int16_t(r.od(j, cia402::kTargetTorque)));
  }
  // Gravity compensation in CST, updated each cycle from the measured pose, with a virtual
  // damping of 5 /s x the joint's largest inertia (the PUMA data have no friction: without it
  // the 1 per mille quantisation of 6071h alone makes the wrist creep).
  std::vector<double> junk(6, 100.0);  // ignored in torque mode
  for (int k = 0; k < 1000; ++k) {
    for (int j = 0; j < 6; ++j) q[j] = r.master->feedback(std::size_t(j)).position;
    CHECK(kin::gravity_torques(r.chain, q, g) == kin::Status::ok);
    for (std::size_t j = 0; j < 6; ++j)
      r.master->set_target_torque(j, g[int(j)] - 5.0 * r.rig.sim->plant()->info(int(j)).max_inertia *
                                                     r.master->feedback(j).velocity);
    r.cycle(junk);
  }
  double drift = 0;
  for (std::size_t j = 0; j < 6; ++j) drift = std::max(drift, std::fabs(r.master->feedback(j).position - hold[j]));
  std::printf("\n  CST with gravity compensation, 1 s: drift %.3g rad\n", drift);
  CHECK(drift < 5e-3);
  LONGS_EQUAL(int(JointState::enabled), int(r.master->feedback(0).state));
  // Back to CSP: holds where it stood when asked; the caller's setpoint is ignored meanwhile.
  const std::vector<double> at = r.positions();
  for (std::size_t j = 0; j < 6; ++j) LONGS_EQUAL(int(Status::ok), int(r.master->set_torque_mode(j, false)));
  LONGS_EQUAL(int(CyclicMode::leaving_torque), int(r.master->cyclic_mode(0).mode));
  cycles = 0;
  while (r.master->cyclic_mode(1).mode != CyclicMode::position && cycles < 50) r.cycle(junk), ++cycles;
  CHECK(cycles <= 3);
  for (std::size_t j = 0; j < 6; ++j) LONGS_EQUAL(cia402::kModeCsp, r.rig.sim->at(j).mode_display());
  const std::vector<double> now = r.positions();
  for (int k = 0; k < 300; ++k) r.cycle(now);
  for (std::size_t j = 0; j < 6; ++j) {
    CHECK(std::fabs(r.master->feedback(j).position - at[j]) < 2e-3);
    LONGS_EQUAL(int(JointState::enabled), int(r.master->feedback(j).state));
    LONGS_EQUAL(int(Status::ok), int(r.master->cyclic_mode(j).status));
  }
  // A new torque mode needs a new target torque.
  LONGS_EQUAL(int(Status::bad_state), int(r.master->set_torque_mode(0, true)));
}

// A fault in torque mode takes the joint back to position mode by itself, with the cause;
// so does quick_stop() (aborted).
TEST(TorqueObjects, FaultOrStopLeavesTorqueMode) {
  Rig r(true);
  r.cfg.rpdo2.torque_mode = PdoUse::required;
  r.bring_up();
  std::vector<double> hold = r.positions();
  kin::JointVector q(6), g(6);
  for (int j = 0; j < 6; ++j) q[j] = hold[std::size_t(j)];
  CHECK(kin::gravity_torques(r.chain, q, g) == kin::Status::ok);
  for (std::size_t j = 0; j < 6; ++j) r.master->set_target_torque(j, g[int(j)]), r.master->set_torque_mode(j, true);
  for (int k = 0; k < 5; ++k) r.cycle(hold);
  LONGS_EQUAL(int(CyclicMode::torque), int(r.master->cyclic_mode(2).mode));
  r.rig.sim->at(2).inject_emcy(0x2310, r.rig.clock.now(), r.rig.sim->bus());
  for (int k = 0; k < 4; ++k) r.cycle(hold);
  const CyclicModeState st = r.master->cyclic_mode(2);
  LONGS_EQUAL(int(CyclicMode::position), int(st.mode));
  LONGS_EQUAL(int(Status::drive_fault), int(st.status));
  LONGS_EQUAL(cia402::kModeCsp, r.rig.sim->at(2).mode_display());
  r.master->quick_stop();
  for (int k = 0; k < 4; ++k) r.cycle(hold);
  LONGS_EQUAL(int(CyclicMode::position), int(r.master->cyclic_mode(0).mode));
  LONGS_EQUAL(int(Status::aborted), int(r.master->cyclic_mode(0).status));
  LONGS_EQUAL(cia402::kModeCsp, r.rig.sim->at(0).mode_display());
}

// A drive without CST: refused at bring-up, naming the joint, when torque mode is required;
// brought up without it when optional (the first-order motor offers no CST either).
TEST(TorqueObjects, DriveWithoutTorqueModeIsRefusedOrLeftWithout) {
  {
    Rig r(true);
    sim::DriveQuirks qk;
    qk.no_cst = true;
    r.rig.sim->at(3).set_quirks(qk);
    r.cfg.rpdo2.torque_mode = PdoUse::required;
    LONGS_EQUAL(int(Status::not_supported), int(r.start()));
    STRCMP_EQUAL("joint 3 (node 4): torque mode required but the drive does not support cyclic synchronous torque "
                 "mode (6502h = 0x000000A0)",
                 r.master->last_error());
    r.cfg.rpdo2.torque_mode = PdoUse::optional;
    LONGS_EQUAL(int(Status::ok), int(r.start()));
    CHECK(!r.master->capabilities(3).torque_mode);
    CHECK(r.master->capabilities(2).torque_mode);
    LONGS_EQUAL(int(Status::not_supported), int(r.master->set_torque_mode(3, true)));
  }
  {
    Rig r(false);
    r.cfg.rpdo2.torque_mode = PdoUse::optional;
    r.bring_up();
    CHECK(!r.master->capabilities(0).torque_mode);
    r.rig.capture();
    const std::vector<double> hold = r.positions();
    r.cycle(hold);
    for (const CanFrame& f : r.rig.capture())
      if ((f.id & 0x780) == 0x200) LONGS_EQUAL(6, f.len);
  }
}

// The real-time calls allocate nothing.
TEST(TorqueObjects, RealTimeCallsDoNotAllocate) {
  Rig r(true);
  r.cfg.rpdo2 = {PdoUse::required, PdoUse::required, PdoUse::required};
  r.bring_up();
  const std::vector<double> hold = r.positions();
  r.cycle(hold);
  std::size_t n = 0;
  {
    test::AllocScope scope;
    for (int k = 0; k < 50; ++k) {
      for (std::size_t j = 0; j < 6; ++j) {
        r.master->set_feed_forward(j, 0.01, 0.5);
        r.master->set_target_torque(j, 1.0);
      }
      if (k == 10) r.master->set_torque_mode(5, true);
      if (k == 30) r.master->set_torque_mode(5, false);
      r.master->read(r.rig.clock.now());
      r.master->write(hold, r.rig.clock.now());
      (void)r.master->cyclic_mode(5);
      (void)r.master->capabilities(5);
    }
    n = scope.end();
  }
  UNSIGNED_LONGS_EQUAL(0, n);
}
