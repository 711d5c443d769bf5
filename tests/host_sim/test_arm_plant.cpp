// SPDX-License-Identifier: Apache-2.0
// The dynamic plant: virtual drives on one rigid-body arm. Driven through the
// CANopen master on the in-process bus with a ManualClock (deterministic), or directly.
//  - a free swing with the drives disabled and the brakes off conserves energy;
//  - a held pose under gravity shows the steady following error g / (kp kv) of the loops
//    (and none with the velocity-loop integral on);
//  - the torque the drives report (6077h, through TPDO2) equals the model's gravity
//    torque at rest;
//  - a rigid stop stops the joint and the drive's torque rises to its limit;
//  - the loops are stable at the drives' rates (steps of 100 and 250 us);
//  - a model without inertial data is refused, saying why; no heap while stepping.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "alloc_counter.hpp"
#include "servoarm/hal/canopen_master.hpp"
#include "servoarm/hal/sim_bus.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/kinematics/dynamics.hpp"
#include "servoarm/sim/arm_plant.hpp"
#include "servoarm/sim/sim_plant.hpp"
#include "servoarm/sim/virtual_drive.hpp"
#include "sweep.hpp"  // kSlowBuild: three models hold a pose under qemu and the sanitizers

// CppUTest last: its leak detector redefines `new`.
#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::hal;

namespace {

constexpr Duration kPeriod = kMillisecond;

kin::Chain load(const char* name) {
  kin::LoadResult lr = kin::load_robot(name);
  if (!lr.ok) FAIL(lr.error.c_str());
  return lr.chain;
}

double energy(const kin::Chain& c, const kin::JointVector& q, const kin::JointVector& qd) {
  kin::MassMatrix M(c.n_joints, c.n_joints);
  CHECK(kin::mass_matrix(c, q, M) == kin::Status::ok);
  kin::FrameSet F;
  kin::Pose T;
  CHECK(kin::forward_frames(c, q, F, T) == kin::Status::ok);
  const Eigen::Vector3d g(c.gravity[0], c.gravity[1], c.gravity[2]);
  double V = 0;
  for (int i = 0; i < c.n_rows; ++i) {
    const auto& L = c.inertial[static_cast<std::size_t>(i)];
    V -= L.mass * g.dot(F.frame[i + 1] * Eigen::Vector3d(L.com[0], L.com[1], L.com[2]));
  }
  return 0.5 * qd.dot(M * qd) + V;
}

// Master + virtual drives on the dynamic plant, single-threaded on a ManualClock.
struct Rig {
  ManualClock clock;
  SimBus bus{clock, 50 * kMicrosecond};
  std::unique_ptr<SimBusEndpoint> master_ep = bus.open(4096);
  std::unique_ptr<SimBusEndpoint> sim_ep = bus.open(4096);
  std::unique_ptr<sim::ArmSim> sim;
  std::unique_ptr<CanopenServoBus> master;
  kin::Chain chain;
  std::vector<JointScaling> sc;
  std::string error;

  Rig(const char* model, const sim::ArmPlantParams& p, double gear = 1.0, bool torque = true) {
    chain = load(model);
    const int n = chain.n_joints;
    std::vector<std::uint8_t> nodes;
    for (int j = 0; j < n; ++j) nodes.push_back(std::uint8_t(1 + j));
    sim = std::make_unique<sim::ArmSim>(*sim_ep, nodes, sim::MotorParams{}, 7);
    sim->power_on(clock.now());
    CanopenMasterConfig cfg = CanopenMasterConfig::consecutive(1, std::size_t(n));
    for (int j = 0; j < n; ++j) {
      cfg.joints[std::size_t(j)].scaling.gear_ratio = gear;
      if (chain.joint(j).type == kin::JointType::prismatic) {
        // 1000 counts per mm: the drive's default window (13107 counts) is 13 mm and its
        // velocity limit (1.3e6 counts/s) 1.3 m/s (at 131072 counts/mm they would be 0.1 mm, 10 mm/s).
        cfg.joints[std::size_t(j)].scaling.kind = JointScaling::Kind::prismatic;
        cfg.joints[std::size_t(j)].scaling.counts_per_unit = 1000;
      }
      sc.push_back(cfg.joints[std::size_t(j)].scaling);
    }
    cfg.heartbeat_period = 20 * kMillisecond;
    cfg.heartbeat_timeout = 60 * kMillisecond;
    if (torque) cfg.tpdo2.torque = PdoUse::required;
    error = sim->use_dynamic_plant(chain, sc, p);
    clock.set_idle_hook([this](TimePoint t) { sim->step(t); });
    master = std::make_unique<CanopenServoBus>(*master_ep, clock, cfg);
  }
  ~Rig() { clock.set_idle_hook(nullptr); }
  sim::ArmPlant& plant() { return *sim->plant(); }
  void bring_up() {
    STRCMP_EQUAL("", error.c_str());
    LONGS_EQUAL(int(Status::ok), int(master->start(clock.now() + 2 * kSecond)));
    STRCMP_EQUAL("", master->last_error());
    LONGS_EQUAL(int(Status::ok), int(master->enable_blocking(clock.now() + kSecond, kPeriod)));
  }
  // Hold the setpoints `sp` for `cycles` control cycles (1 kHz: read, write + SYNC).
  void run(const kin::JointVector& sp, int cycles) {
    for (int k = 0; k < cycles; ++k) {
      master->read(clock.now());
      master->write(std::span<const double>(sp.data(), std::size_t(sp.size())), clock.now());
      clock.advance(kPeriod);
    }
    master->read(clock.now());
  }
  kin::JointVector positions() const {
    kin::JointVector q(chain.n_joints);
    for (int j = 0; j < chain.n_joints; ++j) q[j] = master->feedback(std::size_t(j)).position;
    return q;
  }
};

}  // namespace

TEST_GROUP(ArmPlant){};

TEST(ArmPlant, RefusesAModelWithoutInertialData) {
  kin::LoadResult lr = kin::load_description(
      "name = \"bare\"\nconvention = \"standard\"\nlength_unit = \"m\"\nangle_unit = \"rad\"\n[[joint]]\ntype = \"revolute\"\na = 0.3\n"
      "[[joint]]\ntype = \"revolute\"\na = 0.2\n",
      "bare.toml");
  CHECK_TEXT(lr.ok, lr.error.c_str());
  ManualClock clock;
  SimBus bus(clock, 0);
  auto ep = bus.open(64);
  const std::uint8_t nodes[] = {1, 2};
  sim::ArmSim arm(*ep, nodes);
  const JointScaling sc[2] = {};
  const std::string e = arm.use_dynamic_plant(lr.chain, sc, {});
  STRCMP_EQUAL(
      "robot 'bare' has no inertial data (mass, com, inertia per joint in its description; docs/dynamics.md): the "
      "dynamic plant needs them (the first-order plant does not)",
      e.c_str());
  CHECK(arm.plant() == nullptr);
  // Wrong drive count and a bad step are refused too.
  const kin::Chain puma = load("puma560");
  STRCMP_CONTAINS("2 drives for the 6 joints of 'puma560'", arm.use_dynamic_plant(puma, sc, {}).c_str());
  sim::ArmSim six(*ep, std::vector<std::uint8_t>{1, 2, 3, 4, 5, 6});
  const std::vector<JointScaling> s6(6);
  sim::ArmPlantParams bad;
  bad.step = 5 * kMillisecond;
  STRCMP_CONTAINS("step must be within", six.use_dynamic_plant(puma, s6, bad).c_str());
  bad = {};
  bad.stop.joint = 7;
  STRCMP_CONTAINS("stop on joint 8, which does not exist", six.use_dynamic_plant(puma, s6, bad).c_str());
}

// Drives never enabled, brakes off, no friction (the PUMA data have none): the arm swings
// under gravity alone from a tilted pose with some speed, 5 s of RK4 at 100 us through the
// drives' ticks. Total energy (kinetic with rotors + potential, computed here from
// forward_frames, independently of the plant) drifts by less than 1e-6 of the largest
// kinetic energy reached; the drives report the plant's positions (6064h, whole counts).
TEST(ArmPlant, FreeSwingWithDrivesDisabledConservesEnergy) {
  sim::ArmPlantParams p;
  p.brakes = false;
  Rig rig("puma560", p);
  STRCMP_EQUAL("", rig.error.c_str());
  kin::JointVector q0(6), qd0(6);
  q0 << 0.3, -0.8, 0.5, 0.2, 0.6, -0.4;
  qd0 << 0.5, -0.3, 0.8, 1.0, -0.7, 0.4;
  rig.plant().set_state(q0, qd0);
  const double e0 = energy(rig.chain, q0, qd0);
  double tmax = 0, drift = 0;
  for (int k = 0; k < 5000; ++k) {
    rig.clock.advance(kMillisecond);  // the idle hook ticks the drives, which step the plant
    const kin::JointVector& q = rig.plant().q();
    const kin::JointVector& qd = rig.plant().qd();
    tmax = std::max(tmax, rig.plant().kinetic_energy());
    drift = std::max(drift, std::fabs(energy(rig.chain, q, qd) - e0));
  }
  std::printf("\n  free swing puma560 5 s: energy drift %.3g J, largest kinetic energy %.3g J (ratio %.3g)\n", drift,
              tmax, drift / tmax);
  CHECK(tmax > 1.0);  // it really swung
  CHECK(drift < 1e-6 * tmax);
  UNSIGNED_LONGS_EQUAL(50000, rig.plant().steps());
  for (int j = 0; j < 6; ++j) {
    std::uint32_t raw = 0;
    CHECK(rig.sim->at(std::size_t(j)).od_read(0x6064, 0, raw));
    const double want = rig.sc[std::size_t(j)].counts_per_si() * rig.plant().q()[j];
    CHECK(std::fabs(double(std::int32_t(raw)) - want) <= 1.0);
    DOUBLES_EQUAL(0.0, rig.sim->at(std::size_t(j)).torque(), 0.0);  // unpowered: no torque
  }
}

// With the brakes on (default), a disabled arm does not fall.
TEST(ArmPlant, BrakesHoldADisabledArm) {
  Rig rig("puma560", {});
  kin::JointVector q0(6), qd0 = kin::JointVector::Zero(6);
  q0 << 0.3, -0.8, 0.5, 0.2, 0.6, -0.4;
  rig.plant().set_state(q0, qd0);
  rig.clock.advance(500 * kMillisecond);
  CHECK((rig.plant().q() - q0).cwiseAbs().maxCoeff() < 1e-12);
}

// Enabled and holding a pose where gravity loads joints 2, 3 and 5: with the velocity loop
// P only, the steady following error is g_j / (kp kv_j) per joint (the drive's 60F4h,
// counts), and the torque each drive reports through TPDO2 (6077h) is the model's gravity
// torque g_j(q). With the velocity-loop integral on, the error goes to 0 (whole counts).
TEST(ArmPlant, HeldPoseUnderGravity) {
  for (double ki : {0.0, 20.0}) {
    sim::ArmPlantParams p;
    for (auto& g : p.gains) g.ki = ki;
    Rig rig("puma560", p);
    kin::JointVector q0(6), qd0 = kin::JointVector::Zero(6);
    q0 << 0.2, -0.7, 0.9, 0.1, -0.8, 0.3;
    rig.plant().set_state(q0, qd0);
    rig.bring_up();
    const kin::JointVector hold = rig.positions();
    rig.run(hold, ki > 0 ? 3000 : 1500);
    kin::JointVector g(6);
    CHECK(kin::gravity_torques(rig.chain, rig.plant().q(), g) == kin::Status::ok);
    for (int j = 0; j < 6; ++j) {
      const auto& in = rig.plant().info(j);
      const double cps = rig.sc[std::size_t(j)].counts_per_si();
      std::uint32_t raw = 0;
      CHECK(rig.sim->at(std::size_t(j)).od_read(0x60F4, 0, raw));
      const double fe = double(std::int32_t(raw)) / cps;  // rad, target - actual
      const double want = ki > 0 ? 0.0 : g[j] / (in.gains.kp * in.gains.kv);
      char msg[200];
      std::snprintf(msg, sizeof msg, "ki %g joint %d: following error %.4g rad, want %.4g (g %.4g N m)", ki, j + 1, fe,
                    want, g[j]);
      CHECK_TEXT(std::fabs(fe - want) <= 0.02 * std::fabs(want) + 1.5 / cps, msg);
      // Torque by TPDO2 (6077h x 6076h), joint side, against the model: quantisation (1 per
      // mille of the rated torque) plus 0.2 % of the largest gravity torque.
      const JointFeedback& fb = rig.master->feedback(std::size_t(j));
      CHECK(fb.has_torque);
      const double unit = in.rated_torque_mnm * 1e-6;
      std::snprintf(msg, sizeof msg, "ki %g joint %d: torque %.5g N m by 6077h, model gravity %.5g", ki, j + 1, fb.torque,
                    g[j]);
      CHECK_TEXT(std::fabs(fb.torque - g[j]) <= 1.5 * unit + 2e-3 * in.max_gravity, msg);
      DOUBLES_EQUAL(rig.plant().motor_torque()[j], rig.sim->at(std::size_t(j)).torque(), 1e-12);
    }
    if (ki == 0.0) std::printf("\n  held pose puma560: joint 2 following error %.3g rad, gravity %.4g N m\n",
                               g[1] / (rig.plant().info(1).gains.kp * rig.plant().info(1).gains.kv), g[1]);
  }
}

// A rigid stop on joint 1 at 0.1 rad; the master ramps joint 1 from 0 to 0.3 rad at
// 0.5 rad/s. The joint stops at the stop (penetration below 1e-4 rad), its velocity goes
// to 0, and the drive's torque rises to its limit, balanced by the contact.
TEST(ArmPlant, ObstacleStopsTheJointAndTheTorqueRises) {
  sim::ArmPlantParams p;
  p.stop.joint = 0;
  p.stop.position = 0.1;
  p.stop.side = 1;
  Rig rig("puma560", p);
  rig.bring_up();
  kin::JointVector sp = rig.positions();
  const double start = sp[0];
  double torque_free = 0;
  for (int k = 0; k < 600; ++k) {
    sp[0] = start + std::min(0.3, 0.5 * k * 1e-3);
    rig.run(sp, 1);
    // Moving freely at constant speed (past the velocity step of the ramp's start):
    const double qn = rig.plant().q()[0];
    if (qn > 0.04 && qn < 0.09) torque_free = std::max(torque_free, std::fabs(rig.master->feedback(0).torque));
  }
  const double q1 = rig.plant().q()[0];
  const double tl = rig.plant().info(0).gains.torque_limit;
  std::printf("\n  stop: joint 1 at %.6f rad (stop 0.1), torque %.4g N m (limit %.4g, free motion %.3g), contact %.4g\n", q1,
              rig.master->feedback(0).torque, tl, torque_free, rig.plant().contact_torque()[0]);
  CHECK(q1 > 0.0999 && q1 < 0.1001);
  CHECK(std::fabs(rig.plant().qd()[0]) < 1e-3);
  CHECK(rig.master->feedback(0).torque > 0.95 * tl);       // pushing against the stop at the limit
  CHECK(torque_free < 0.5 * tl);                          // far below it while moving freely
  DOUBLES_EQUAL(-rig.plant().motor_torque()[0], rig.plant().contact_torque()[0], 1e-3 * tl);
  // Without the stop the same ramp reaches 0.3 rad.
  Rig free("puma560", {});
  free.bring_up();
  kin::JointVector sp2 = free.positions();
  for (int k = 0; k < 1200; ++k) {
    sp2[0] = start + std::min(0.3, 0.5 * k * 1e-3);
    free.run(sp2, 1);
  }
  DOUBLES_EQUAL(0.3, free.plant().q()[0], 1e-3);
}

// Stability at the drives' rates: a 0.05 rad step on every joint at once (the drives'
// following window allows it), at loop steps of 100 us and 250 us. The error falls below
// 1e-4 rad within 0.5 s and stays there; the velocity dies out (no limit cycle).
TEST(ArmPlant, StableAtTheDriveRate) {
  for (Duration step : {100 * kMicrosecond, 250 * kMicrosecond}) {
    sim::ArmPlantParams p;
    p.step = step;
    Rig rig("puma560", p);
    rig.bring_up();
    kin::JointVector sp = rig.positions();
    sp.array() += 0.05;
    rig.run(sp, 500);
    std::vector<kin::JointVector> qs;
    double vel = 0;
    for (int k = 0; k < 500; ++k) {
      rig.run(sp, 1);
      qs.push_back(rig.plant().q());
      vel = std::max(vel, rig.plant().qd().cwiseAbs().maxCoeff());
    }
    // Settled: within 2e-5 rad of where it ends, and that is the gravity sag g / (kp kv).
    double spread = 0, sag_err = 0;
    for (const auto& q : qs) spread = std::max(spread, (q - qs.back()).cwiseAbs().maxCoeff());
    kin::JointVector g(6);
    CHECK(kin::gravity_torques(rig.chain, qs.back(), g) == kin::Status::ok);
    for (int j = 0; j < 6; ++j) {
      const auto& in = rig.plant().info(j);
      sag_err = std::max(sag_err, std::fabs(sp[j] - qs.back()[j] - g[j] / (in.gains.kp * in.gains.kv)));
    }
    char msg[160];
    std::snprintf(msg, sizeof msg, "step %lld us: spread %.3g rad, off the gravity sag by %.3g rad, velocity %.3g rad/s",
                  static_cast<long long>(step / kMicrosecond), spread, sag_err, vel);
    CHECK_TEXT(spread < 2e-5, msg);
    CHECK_TEXT(sag_err < 2e-5, msg);
    CHECK_TEXT(vel < 1e-3, msg);
    for (std::size_t j = 0; j < 6; ++j) LONGS_EQUAL(int(JointState::enabled), int(rig.master->feedback(j).state));
  }
}

// Stepping the plant allocates nothing (the control thread steps it under armfw --sim).
TEST(ArmPlant, SteppingDoesNotAllocate) {
  Rig rig("puma560", {});
  rig.bring_up();
  const kin::JointVector hold = rig.positions();
  rig.run(hold, 10);
  std::size_t n = 0;
  {
    test::AllocScope scope;
    for (int k = 0; k < 100; ++k) rig.sim->step(rig.clock.now() + k * kMillisecond);
    n = scope.end();
  }
  UNSIGNED_LONGS_EQUAL(0, n);
}

// Every built-in model with inertial data (published or estimated) runs on the plant: the
// drives enable at a pose within the limits and hold it, settled (no drift, no limit
// cycle) after 1 s, at the gravity sag g / (kp kv) the loops predict, within 2e-5 rad.
// Every model the plant accepts holds a pose on the host; under qemu and the sanitizers
// (sweep.hpp) the first three in name order (cylindrical_rpp_rrr with its prismatic joints,
// ist6, puma560: 1.6 s each there) while every model is still loaded, accepted or refused.
TEST(ArmPlant, EveryBuiltInModelWithInertialDataHoldsAPose) {
  const int hold_models = servoarm::test::kSlowBuild ? 3 : 1000;
  int models = 0, held = 0;
  std::string held_names;
  for (const kin::BuiltinModel& bm : kin::builtin_models()) {
    const kin::Chain c = load(std::string(bm.name).c_str());
    if (!c.has_inertial) continue;
    Rig rig(std::string(bm.name).c_str(), {});
    if (!rig.error.empty()) {
      // Point-mass data without rotor inertia (ur5e, ur10e): the last joint moves no
      // inertia, forward dynamics cannot run, and the plant says so.
      STRCMP_CONTAINS("moves no inertia", rig.error.c_str());
      std::printf("\n  %s: refused: %s\n", std::string(bm.name).c_str(), rig.error.c_str());
      continue;
    }
    if (++models > hold_models) continue;
    ++held;
    held_names += " " + std::string(bm.name);
    kin::JointVector q0(c.n_joints), qd0 = kin::JointVector::Zero(c.n_joints);
    for (int j = 0; j < c.n_joints; ++j) {
      const auto& r = c.joint(j);
      const double lo = std::isfinite(r.lower) ? r.lower : -1.0, hi = std::isfinite(r.upper) ? r.upper : 1.0;
      q0[j] = lo + (hi - lo) * (0.3 + 0.05 * j);
    }
    rig.plant().set_state(q0, qd0);
    rig.bring_up();
    const kin::JointVector hold = rig.positions();
    rig.run(hold, 1000);
    const kin::JointVector qa = rig.plant().q();
    rig.run(hold, 200);
    kin::JointVector g(c.n_joints);
    CHECK(kin::gravity_torques(rig.chain, rig.plant().q(), g) == kin::Status::ok);
    for (int j = 0; j < c.n_joints; ++j) {
      const auto& in = rig.plant().info(j);
      const double sag = g[j] / (in.gains.kp * in.gains.kv);
      char msg[200];
      std::snprintf(msg, sizeof msg, "%s joint %d: drift %.3g, error %.4g vs sag %.4g (torque %.4g, g %.4g, q %.4g)",
                    std::string(bm.name).c_str(), j + 1, std::fabs(rig.plant().q()[j] - qa[j]),
                    hold[j] - rig.plant().q()[j], sag, rig.plant().motor_torque()[j], g[j], rig.plant().q()[j]);
      CHECK_TEXT(std::fabs(rig.plant().q()[j] - qa[j]) < 2e-6, msg);
      CHECK_TEXT(std::fabs(hold[j] - rig.plant().q()[j] - sag) < 2e-5, msg);
      LONGS_EQUAL_TEXT(int(JointState::enabled), int(rig.master->feedback(std::size_t(j)).state), msg);
    }
  }
  std::printf("\n  %d models accepted, %d held a pose:%s\n", models, held, held_names.c_str());
  CHECK(models >= 9);  // puma560 and 8 estimates (stanford, rr_planar keep none: docs/dynamics.md)
  LONGS_EQUAL(std::min(models, hold_models), held);
}

// armfw --sim: the virtual drives start with every joint inside its limits, at the in-limit
// value closest to 0 (the Stanford arm's prismatic joint 3, limits [0.2, 0.9] m, at 0.2 m;
// the others at 0), read back through the CANopen master as the firmware reads them.
TEST_GROUP(SimStart){};

TEST(SimStart, EveryJointStartsInsideItsLimitsClosestToZero) {
  for (const char* model : {"stanford", "puma560", "rr_planar"}) {
    const kin::Chain chain = load(model);
    const int n = chain.n_joints;
    ManualClock clock;
    std::vector<std::uint8_t> nodes;
    for (int j = 0; j < n; ++j) nodes.push_back(std::uint8_t(1 + j));
    sim::SimPlant plant(clock, nodes);
    CanopenMasterConfig cfg = CanopenMasterConfig::consecutive(1, std::size_t(n));
    std::vector<JointScaling> sc;
    for (int j = 0; j < n; ++j) {
      JointScaling& s = cfg.joints[std::size_t(j)].scaling;
      s.gear_ratio = 3;
      s.direction = j % 2 ? -1 : 1;
      s.zero_offset = 1000 * j;
      if (chain.joint(j).type == kin::JointType::prismatic) {
        s.kind = JointScaling::Kind::prismatic;
        s.counts_per_unit = 1000;
      }
      sc.push_back(s);
    }
    plant.place_within_limits(chain, sc);
    cfg.heartbeat_period = 20 * kMillisecond;
    cfg.heartbeat_timeout = 60 * kMillisecond;
    clock.set_idle_hook([&](TimePoint t) { plant.step(t); });
    CanopenServoBus master(plant.master_bus(), clock, cfg);
    LONGS_EQUAL(int(Status::ok), int(master.start(clock.now() + 2 * kSecond)));
    STRCMP_EQUAL("", master.last_error());
    std::vector<double> hold(std::size_t(n), 0.0);
    for (int k = 0; k < 20; ++k) {  // SYNCs: the drives' TPDO1 (6064h)
      master.read(clock.now());
      for (int j = 0; j < n; ++j) hold[std::size_t(j)] = master.feedback(std::size_t(j)).position;
      master.write(std::span<const double>(hold.data(), hold.size()), clock.now());
      clock.advance(kPeriod);
    }
    master.read(clock.now());
    for (int j = 0; j < n; ++j) {
      const kin::DhRow& row = chain.joint(j);
      const double want = std::clamp(0.0, row.lower, row.upper);
      const double q = master.feedback(std::size_t(j)).position;
      char what[128];
      std::snprintf(what, sizeof what, "%s joint %d at %.6f, limits [%g, %g]", model, j + 1, q, row.lower, row.upper);
      CHECK_TEXT(q >= row.lower && q <= row.upper, what);
      DOUBLES_EQUAL_TEXT(want, q, 1.0 / sc[std::size_t(j)].counts_per_si(), what);
    }
    clock.set_idle_hook(nullptr);
  }
}
