// SPDX-License-Identifier: Apache-2.0
// Arms of MIT-mode actuators through armfw's App (docs/mit-motors.md): the drive-family factory
// builds a hal::MitGroup from [[drive]] family = "damiao"; virtual DM-J4340 motors
// (host_sim/mit_motor.hpp) stand in for the arm, single-threaded on a ManualClock. A six-joint
// arm runs a movej through the console (following error with and without feed-forward) and
// free-drive against gravity; a mixed arm (4 Damiao + 2 CiA 402 on two buses) moves; each
// bring-up quirk ends the boot with its one line; bad configurations are refused at load.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "alloc_counter.hpp"
#include "servoarm/app/app.hpp"
#include "servoarm/config/config.hpp"
#include "servoarm/hal/mit_group.hpp"
#include "servoarm/kinematics/dynamics.hpp"
#include "servoarm/rt/controller.hpp"
#include "servoarm/sim/mit_motor.hpp"
#include "servoarm/sim/sim_plant.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;

namespace {

constexpr double kDeg = M_PI / 180.0;

/// fw::App whose in-process buses carry virtual MIT motors or virtual CiA 402 drives, whichever
/// family the configuration gives the bus's first drive.
struct MitApp : App {
  std::vector<std::unique_ptr<sim::MitPlant>> mit;
  std::vector<std::unique_ptr<sim::SimPlant>> cia;

  std::string build(const FwConfig& c, hal::Clock* clk) {
    sim_group = [this, c](hal::Clock& clock, const DriveGroupPlan& p) -> hal::CanBus* {
      std::vector<sim::MitMotorSpec> specs;
      for (std::size_t k = 0; k < p.joints.size(); ++k) {
        const DriveConfig& d = c.drives[static_cast<std::size_t>(p.joints[k])];
        sim::MitMotorSpec s;
        s.profile = hal::mit::find_profile(d.motor);
        s.id = p.ids[k];
        s.master = static_cast<std::uint16_t>(mit_master_id(d, p.ids[k]));
        s.fd = d.can_fd;
        specs.push_back(s);
      }
      mit.push_back(std::make_unique<sim::MitPlant>(clock, specs));
      return &mit.back()->master_bus();
    };
    return App::build(c, clk, [this](hal::Clock& clock, const std::vector<std::uint8_t>& ids) -> hal::CanBus* {
      cia.push_back(std::make_unique<sim::SimPlant>(clock, ids));
      return &cia.back()->master_bus();
    });
  }
  void step(hal::TimePoint t) {
    for (auto& p : mit) p->step(t);
    for (auto& p : cia) p->step(t);
  }
  ~MitApp() {
    console.reset();
    ctl.reset();
    servo.reset();
  }
};

/// The arm, its console and the cycles. With `gravity`, each cycle loads every motor with the
/// arm's gravity torque at its present position (the model's g(q), actuator side).
struct Arm {
  hal::ManualClock clock;
  MitApp app;
  Session s;
  std::size_t rt_allocs = 0;
  std::string events, grbl, boot_error;
  bool gravity = false;
  double max_fe = 0;  ///< largest |q_cmd - q_act| (rad) since reset
  explicit Arm(const FwConfig& cfg, void (*before_boot)(MitApp&) = nullptr) {
    const std::string e = app.build(cfg, &clock);
    if (!e.empty()) FAIL(e.c_str());
    clock.set_idle_hook([this](hal::TimePoint t) { app.step(t); });
    if (before_boot != nullptr) before_boot(app);
    boot_error = app.boot();
    app.console->set_idle([this] { cycle(); });
  }
  ~Arm() { clock.set_idle_hook(nullptr); }
  sim::VirtualMitMotor& motor(std::size_t j) {
    const hal::ArmServoBus::Slot sl = app.servo->slot(j);
    return app.mit.at(sl.group)->at(sl.local);
  }
  /// Each motor moves the arm's own inertia (the mass matrix's diagonal at `q`, actuator side)
  /// instead of the default 0.01 kg m^2: what free-drive's damping and the model expect.
  void arm_inertia(const kin::JointVector& q) {
    kin::MassMatrix M;
    kin::mass_matrix(app.chain, q, M);
    for (std::size_t j = 0; j < 6; ++j) {
      const double k = app.servo->scaling(j).gear_ratio;
      motor(j).params().inertia = M(static_cast<int>(j), static_cast<int>(j)) / (k * k);
    }
  }
  void load_gravity() {
    kin::JointVector q = kin::JointVector::Zero(6), g = kin::JointVector::Zero(6);
    for (std::size_t j = 0; j < 6; ++j) q[static_cast<int>(j)] = app.servo->feedback(j).position;
    kin::gravity_torques(app.chain, q, g);
    for (std::size_t j = 0; j < 6; ++j) {
      const double k = app.servo->scaling(j).gear_ratio * app.servo->scaling(j).direction;
      motor(j).load_torque = -g[static_cast<int>(j)] / k;
    }
  }
  void cycle() {
    if (gravity) load_gravity();
    test::alloc_count_begin();
    app.ctl->cycle(clock.now());
    rt_allocs += test::alloc_count_end();
    clock.advance(hal::kMillisecond);
    const Telemetry t = app.ctl->telemetry();
    for (std::size_t j = 0; j < 6; ++j) max_fe = std::max(max_fe, std::fabs(t.q_cmd[j] - t.q_act[j]));
    app.console->drain_events(events, grbl);
  }
  void run(double secs) {
    for (int i = 0; i < static_cast<int>(secs * 1000); ++i) {
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
  Telemetry tel() const { return app.ctl->telemetry(); }
};

bool ok(const std::string& a) { return a.rfind("ok", 0) == 0 || a.find("\nok") != std::string::npos; }
bool has(const std::string& a, const std::string& b) { return a.find(b) != std::string::npos; }

/// The puma560 on six DM-J4340 (ids 1..6, bus.can = "sim"); joints 2 and 3 through a 4:1
/// transmission (a DM-J4340 gives 28 N m; the puma's shoulder needs more against gravity).
FwConfig damiao_arm(const char* ff = "off") {
  FwConfig c;
  c.can = "sim";
  c.feed_forward = ff;
  c.drives.resize(6);
  for (std::size_t j = 0; j < 6; ++j) {
    DriveConfig& d = c.drives[j];
    d.family = "damiao";
    d.motor = "DM-J4340";
    d.node = static_cast<int>(j + 1);
    d.mit_kp = 60;
    d.mit_kd = 2;
  }
  c.drives[1].gear_ratio = c.drives[2].gear_ratio = 4;
  return c;
}

double movej_following_error(const char* ff, std::size_t& allocs) {
  Arm a(damiao_arm(ff));
  CHECK_TEXT(a.boot_error.empty(), a.boot_error.c_str());
  CHECK_TEXT(ok(a.cmd("enable")), a.s.out.c_str());
  a.max_fe = 0;
  CHECK_TEXT(ok(a.cmd("movej 20 -30 40 15 -20 30")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("wait")), (a.s.out + a.events).c_str());
  const double fe = a.max_fe;
  a.run(0.5);
  const Telemetry t = a.tel();
  CHECK_TEXT(t.state == ArmState::idle, t.fault_text);
  const double goal[6] = {20, -30, 40, 15, -20, 30};
  for (std::size_t j = 0; j < 6; ++j) DOUBLES_EQUAL(goal[j] * kDeg, t.q_act[j], 0.05 * kDeg);
  // the MIT frames carry the configured gains; the motors follow
  const auto& g = static_cast<const hal::MitGroup&>(a.app.servo->group(0));
  DOUBLES_EQUAL(60, g.last_command(0).kp, 0.2);
  DOUBLES_EQUAL(2, g.last_command(0).kd, 0.01);
  DOUBLES_EQUAL(30 * kDeg, a.motor(5).position(), 0.05 * kDeg);
  DOUBLES_EQUAL(-30 * kDeg * 4, a.motor(1).position(), 0.2 * kDeg);  // through the 4:1 transmission
  allocs = a.rt_allocs;
  return fe;
}

// The arm's inertia taken at the work pose (0 -30 60 0 20 0), gravity on, enabled and moved
// there, at rest.
void enable_at_work_pose(Arm& a) {
  kin::JointVector q = kin::JointVector::Zero(6);
  q << 0, -30 * kDeg, 60 * kDeg, 0, 20 * kDeg, 0;
  a.arm_inertia(q);
  a.gravity = true;
  CHECK_TEXT(ok(a.cmd("enable")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("movej 0 -30 60 0 20 0")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("wait")), (a.s.out + a.events).c_str());
}

}  // namespace

TEST_GROUP(FwMitArm){};

TEST(FwMitArm, SixDamiaoJ4340RunAMovejWithAndWithoutFeedForward) {
  std::size_t allocs_off = 1, allocs_vel = 1;
  const double off = movej_following_error("off", allocs_off);
  const double vel = movej_following_error("velocity", allocs_vel);
  std::printf("\n  six virtual DM-J4340 (kp 60, kd 2), movej 20 -30 40 15 -20 30 through App: largest following "
              "error %.4f deg without feed-forward, %.4f deg with velocity feed-forward (%.1fx)\n",
              off / kDeg, vel / kDeg, off / vel);
  CHECK(vel < off / 2);
  LONGS_EQUAL(0, long(allocs_off));
  LONGS_EQUAL(0, long(allocs_vel));
}

TEST(FwMitArm, FreeDriveHoldsAgainstGravityAndMovesWhenPushed) {
  FwConfig c = damiao_arm("torque");
  c.freedrive = true;
  Arm a(c);
  CHECK_TEXT(a.boot_error.empty(), a.boot_error.c_str());
  enable_at_work_pose(a);
  a.run(0.3);
  const std::string on = a.cmd("freedrive on");
  CHECK_TEXT(has(on, "ok free-drive on"), (on + a.events).c_str());
  a.run(0.05);
  const auto& g = static_cast<const hal::MitGroup&>(a.app.servo->group(0));
  DOUBLES_EQUAL(0, g.last_command(1).kp, 0);  // free-drive: kp = 0, the damping as the motor's kd, gravity
  CHECK(g.last_command(1).kd > 0);
  CHECK(std::fabs(g.last_command(1).t) > 0.5);
  Telemetry t0 = a.tel();
  a.run(1.0);
  Telemetry t1 = a.tel();
  double drift = 0;
  for (std::size_t j = 0; j < 6; ++j) drift = std::max(drift, std::fabs(t1.q_act[j] - t0.q_act[j]));
  // a push on joint 1 (8 N m for 0.5 s): it moves, the virtual damping stops it
  a.motor(0).load_torque = 0;
  a.gravity = false;
  for (int i = 0; i < 500; ++i) {
    a.load_gravity();
    a.motor(0).load_torque += 8.0;
    a.cycle();
  }
  a.gravity = true;
  a.run(1.5);
  const Telemetry t2 = a.tel();
  const double moved = std::fabs(t2.q_act[0] - t1.q_act[0]);
  std::printf("\n  free-drive on six virtual DM-J4340 under gravity: drift %.3f deg in 1 s, pushed joint 1 moved %.1f deg\n",
              drift / kDeg, moved / kDeg);
  CHECK_TEXT(t2.state == ArmState::freedrive, (t2.fault_text + a.events).c_str());
  CHECK(drift < 1.0 * kDeg);
  CHECK(moved > 2.0 * kDeg);
  CHECK(std::fabs(a.app.servo->feedback(0).velocity) < 0.05);  // came to rest
  CHECK_TEXT(ok(a.cmd("freedrive off")), a.s.out.c_str());
  LONGS_EQUAL(0, long(a.rt_allocs));
}

TEST(FwMitArm, MixedArmFourDamiaoAndTwoCia402OnTwoBuses) {
  FwConfig c = damiao_arm("off");
  for (std::size_t j = 4; j < 6; ++j) {
    DriveConfig& d = c.drives[j];
    d = DriveConfig{};
    d.node = static_cast<int>(j + 1);
    d.can = "sim1";
  }
  Arm a(c);
  CHECK_TEXT(a.boot_error.empty(), a.boot_error.c_str());
  LONGS_EQUAL(2, long(a.app.servo->group_count()));
  STRCMP_EQUAL("damiao", a.app.servo->group(0).family());
  STRCMP_EQUAL("cia402", a.app.servo->group(1).family());
  LONGS_EQUAL(4, long(a.app.servo->group(0).joint_count()));
  LONGS_EQUAL(1, long(a.app.mit.size()));
  LONGS_EQUAL(1, long(a.app.cia.size()));
  CHECK_TEXT(ok(a.cmd("enable")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("movej 20 -30 40 15 -20 30")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("wait")), (a.s.out + a.events).c_str());
  a.run(0.5);
  const Telemetry t = a.tel();
  CHECK_TEXT(t.state == ArmState::idle, t.fault_text);
  const double goal[6] = {20, -30, 40, 15, -20, 30};
  for (std::size_t j = 0; j < 6; ++j) DOUBLES_EQUAL(goal[j] * kDeg, t.q_act[j], 0.05 * kDeg);
  DOUBLES_EQUAL(15 * kDeg, a.motor(3).position(), 0.05 * kDeg);
  LONGS_EQUAL(0, long(a.rt_allocs));
}

TEST(FwMitArm, EachBringUpQuirkEndsTheBootWithItsOneLine) {
  struct Case {
    void (*setup)(MitApp&);
    const char* expect;
  };
  const Case cases[] = {
      {[](MitApp& a) { a.mit[0]->at(2).quirks().silent = true; },
       "drive bring-up failed: timeout: joint 2 (damiao id 0x03): no answer to a register read (CTRL_MODE) on 0x7FF in "
       "300 ms: the motor is not on this bus at this bitrate and frame format (classic CAN / CAN FD), not powered, or "
       "has another id"},
      {[](MitApp& a) {
         a.mit[0]->at(1).set_reg(hal::mit::Reg::ctrl_mode, 2);
         a.mit[0]->at(1).quirks().mode_locked = true;
       },
       "drive bring-up failed: drive_refused: joint 1 (damiao id 0x02): control mode 2 (position-velocity), not MIT "
       "(1), and CTRL_MODE = 1 did not take: in that mode it answers no MIT frame; set it to MIT with the Damiao tool"},
      {[](MitApp& a) { a.mit[0]->at(4).set_reg(hal::mit::Reg::mst_id, 0x14); },
       "drive bring-up failed: protocol_error: joint 4 (damiao id 0x05): answers on 0x014, joint 3's master id "
       "(configured 0x015): master id clash, their feedback cannot be told apart; write its MST_ID to 0x015"},
      {[](MitApp& a) { a.mit[0]->at(0).quirks().late = 400 * hal::kMillisecond; },
       "drive bring-up failed: timeout: joint 0 (damiao id 0x01): no answer to a register read (CTRL_MODE) on 0x7FF in "
       "300 ms"},
  };
  for (const Case& k : cases) {
    Arm a(damiao_arm(), k.setup);
    CHECK_TEXT(has(a.boot_error, k.expect), a.boot_error.c_str());
    CHECK_TEXT(a.boot_error.find('\n') == std::string::npos, a.boot_error.c_str());
  }
  // a motor left in position-velocity mode whose mode can be written: brought up, it moves
  Arm a(damiao_arm(), [](MitApp& m) { m.mit[0]->at(3).set_reg(hal::mit::Reg::ctrl_mode, 2); });
  CHECK_TEXT(a.boot_error.empty(), a.boot_error.c_str());
  CHECK_TEXT(ok(a.cmd("enable")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("movej 0 0 0 10 0 0")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("wait")), (a.s.out + a.events).c_str());
  DOUBLES_EQUAL(10 * kDeg, a.motor(3).position(), 0.05 * kDeg);
  // the motor's own watchdog is armed: bus.heartbeat_timeout_ms (150) in 50 us units
  UNSIGNED_LONGS_EQUAL(3000, a.motor(3).reg(hal::mit::Reg::timeout));
}

TEST(FwMitArm, BadMitConfigurationsAreRefusedAtLoad) {
  struct Case {
    const char* toml;
    const char* expect;
  };
  const std::string six = "[[drive]]\n[[drive]]\n[[drive]]\n[[drive]]\n[[drive]]\n";
  const Case cases[] = {
      {"[[drive]]\nfamily = \"damiao\"\nmotor = \"DM-J9999\"\n",
       "drive[1].motor: unknown motor model \"DM-J9999\"; known: DM-J4310-2EC (damiao), DM-J4340 (damiao), DM-J8006 "
       "(damiao), AK80-9 (cubemars_mit), RS00 (robstride_mit)"},
      {"[[drive]]\nfamily = \"damiao\"\n", "drive[1].motor: is required with drive.family = \"damiao\"; known: "},
      {"[[drive]]\nfamily = \"damiao\"\nmotor = \"AK80-9\"\n", "drive[1].motor: AK80-9 is a cubemars_mit motor, not damiao"},
      {"[[drive]]\n[[drive]]\nfamily = \"damiao\"\nmotor = \"DM-J4340\"\nmaster_id = 0x080\n",
       "drive[2].master_id: is CANopen's SYNC id (0x080), and a CiA 402 drive is on the same interface"},
      {"[[drive]]\n[[drive]]\nfamily = \"damiao\"\nmotor = \"DM-J4340\"\nmaster_id = 0x085\n",
       "drive[2].master_id: is a CANopen EMCY id (0x081..0x0FF), and a CiA 402 drive is on the same interface"},
      {"[[drive]]\nfamily = \"damiao\"\nmotor = \"DM-J4340\"\nmit_kd = 6\n",
       "drive[1].mit_kd: must be at most 5, the DM-J4340's KD range"},
      {"[[drive]]\nfamily = \"damiao\"\nmotor = \"DM-J4340\"\nnode = 128\n", "drive[1].node: "},
      {"[[drive]]\nfamily = \"damiao\"\nmotor = \"DM-J4340\"\nmaster_id = 0x7FF\n",
       "drive[1].master_id: is the Damiao register id (0x7FF)"},
      {"[[drive]]\nfamily = \"damiao\"\nmotor = \"DM-J4340\"\nmit_kp = 600\n",
       "drive[1].mit_kp: must be at most 500, the DM-J4340's KP range"},
      {"[[drive]]\nmotor = \"DM-J4340\"\n", "drive[1].motor: is for the MIT families only"},
  };
  for (const Case& k : cases) {
    FwConfig c;
    const std::string e = load_config_text(k.toml, "mit.toml", c);
    CHECK_TEXT(!e.empty() && has(e, k.expect), (std::string(k.toml) + " -> " + e).c_str());
  }
  {
    // without CANopen drives on the interface the same ids are free: a Damiao master 0x085 loads
    FwConfig c;
    STRCMP_EQUAL("", load_config_text("[[drive]]\nfamily = \"damiao\"\nmotor = \"DM-J4340\"\nmaster_id = 0x085\n",
                                      "mit.toml", c).c_str());
  }
  // ids clash at App::build (they need the whole arm): a default master id that is SYNC on an
  // interface with CiA 402 drives, and a master id that is another drive's id
  FwConfig c = damiao_arm();
  c.drives[5].node = 0x70;  // default master 0x80
  c.drives[0] = DriveConfig{};  // a CiA 402 drive on the same interface
  c.drives[0].node = 1;
  hal::ManualClock clock;
  MitApp app;
  std::string e = app.build(c, &clock);
  CHECK_TEXT(has(e, "config: drive[6].master_id: 0x080 (the damiao default) is CANopen's SYNC id (0x080), and a CiA 402 "
                    "drive is on sim"),
             e.c_str());
  // CubeMars motors answer on 0x000 by default (drive.master_id 0 is the default): CANopen's NMT
  // id beside the CiA 402 drive
  FwConfig c1 = damiao_arm();
  for (DriveConfig& d : c1.drives) {
    d.family = "cubemars_mit";
    d.motor = "AK80-9";
  }
  c1.drives[0] = DriveConfig{};
  c1.drives[0].node = 1;
  MitApp app1;
  e = app1.build(c1, &clock);
  CHECK_TEXT(has(e, "config: drive[2].master_id: 0x000 (the cubemars_mit default) is CANopen's NMT id (0x000), and a "
                    "CiA 402 drive is on sim"),
             e.c_str());
  FwConfig c2 = damiao_arm();
  c2.drives[2].master_id = 0x02;
  MitApp app2;
  e = app2.build(c2, &clock);
  CHECK_TEXT(has(e, "config: drive[3].master_id: 0x002 is joint 2's drive id"), e.c_str());
  FwConfig c3 = damiao_arm();
  c3.drives[3].homing_method = "19";
  MitApp app3;
  e = app3.build(c3, &clock);
  CHECK_TEXT(has(e, "drive[4].homing.method: 19 is a CiA 402 drive's own homing"), e.c_str());
  // bus.can = "sim" with only CiA 402 virtual drives at hand (what armfw --sim gives today)
  App plain;
  e = plain.build(damiao_arm(), &clock, [](hal::Clock&, const std::vector<std::uint8_t>&) -> hal::CanBus* { return nullptr; });
  STRCMP_EQUAL("drive.family: \"damiao\" with bus.can = \"sim\": no virtual damiao motors here (the virtual drives of "
               "armfw --sim are CiA 402)",
               e.c_str());
}

// drive.can_fd: the MIT frames go out as CAN FD with bit-rate switch, which motors set to CAN FD
// answer; one interface is FD or not for all its drives.
TEST(FwMitArm, CanFdArm) {
  FwConfig c = damiao_arm();
  for (DriveConfig& d : c.drives) d.can_fd = true;
  Arm a(c);
  CHECK_TEXT(a.boot_error.empty(), a.boot_error.c_str());
  CHECK_TEXT(ok(a.cmd("enable")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("movej 10 -10 10 10 -10 10")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("wait")), (a.s.out + a.events).c_str());
  DOUBLES_EQUAL(10 * kDeg, a.motor(0).position(), 0.05 * kDeg);
  // a motor left at classic CAN on the FD chain: not seen, said in one line
  Arm b(c, [](MitApp& m) { m.mit[0]->at(1) = sim::VirtualMitMotor([] {
                             sim::MitMotorSpec s;
                             s.profile = hal::mit::find_profile("DM-J4340");
                             s.id = 2;
                             s.master = 0x12;
                             return s;
                           }()); });
  CHECK_TEXT(has(b.boot_error, "joint 1 (damiao id 0x02): no answer to a register read (CTRL_MODE) on 0x7FF in 300 ms: "
                               "the motor is not on this bus at this bitrate and frame format (classic CAN / CAN FD)"),
             b.boot_error.c_str());
  FwConfig m = damiao_arm();
  m.drives[3].can_fd = true;
  hal::ManualClock clock;
  MitApp app;
  const std::string e = app.build(m, &clock);
  STRCMP_EQUAL("config: drive[4].can_fd: true, but joint 1 on the same interface (sim) says false", e.c_str());
}

// The bus-load check runs per interface: each drive counts on its own drive.can, CiA 402 drives
// with their PDOs, SYNC and heartbeat, MIT motors with one command and one feedback frame each.
TEST(FwMitArm, BusLoadIsCheckedPerInterface) {
  FwConfig c;
  c.can = "can0";
  c.rate_hz = 1000;
  c.drives.resize(6);
  for (std::size_t j = 0; j < 6; ++j) c.drives[j].node = static_cast<int>(j + 1);
  for (std::size_t j = 3; j < 6; ++j) c.drives[j].can = "can1";
  // 3 CiA 402 drives per 1 Mbit/s bus at 1 kHz: (55 + 6 x 115) bits a cycle + heartbeats
  STRCMP_EQUAL("", validate(c).c_str());
  std::printf("\n  3 CiA 402 drives per bus: %s\n", bus_load_warning(c, 6).c_str());
  CHECK_TEXT(has(bus_load_warning(c, 6), "with 3 drives (7 frames per cycle: SYNC, 3 RPDO1, 3 TPDO1"),
             bus_load_warning(c, 6).c_str());
  // six DM-J4340: 12 frames of 135 bits a cycle on one bus is 162 %
  FwConfig m = damiao_arm();
  m.can = "can0";
  m.rate_hz = 1000;
  std::string e = validate(m);
  CHECK_TEXT(has(e, "loop.rate_hz: bus load 162.0 % of bus.bitrate 1000000 bit/s at loop.rate_hz 1000 with 6 drives "
                    "(12 frames per cycle: 6 MIT command, 6 MIT feedback, worst-case bit stuffing) is above 85 %: at "
                    "most 524 Hz fits"),
             e.c_str());
  // three of them on can1: 81 % each, within 85 % (warned)
  for (std::size_t j = 3; j < 6; ++j) m.drives[j].can = "can1";
  STRCMP_EQUAL("", validate(m).c_str());
  CHECK_TEXT(has(bus_load_warning(m, 6), "bus load 81.0 %"), bus_load_warning(m, 6).c_str());
  // five on can1: that bus is named
  m.drives[1].can = m.drives[2].can = "can1";
  e = validate(m);
  CHECK_TEXT(has(e, "loop.rate_hz: drive.can \"can1\": bus load 135.0 %"), e.c_str());
}

// Homing by hard stop on an MIT joint: the drive-neutral homing of the group base drives joint 5
// against its stop (8 deg below zero), backs off 3 deg and takes homing.offset there.
TEST(FwMitArm, HardStopHomingOnADamiaoJoint) {
  FwConfig c = damiao_arm();
  DriveConfig& h = c.drives[4];
  h.homing_method = "hard_stop";
  h.homing_direction = -1;
  h.homing_speed_switch = 5;
  h.homing_acceleration = 50;
  h.homing_following_limit = 0.5;
  h.homing_backoff = 3;
  h.homing_offset = -60;
  Arm a(c, [](MitApp& m) { m.mit[0]->at(4).stop_lo = -8 * kDeg; });
  CHECK_TEXT(a.boot_error.empty(), a.boot_error.c_str());
  CHECK_TEXT(ok(a.cmd("enable")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("home")), (a.s.out + a.events).c_str());
  CHECK_TEXT(ok(a.cmd("wait")), (a.s.out + a.events).c_str());
  CHECK(a.tel().all_homed());
  DOUBLES_EQUAL(-5 * kDeg, a.motor(4).position(), 0.2 * kDeg);  // the stop + the back-off
  DOUBLES_EQUAL(-60 * kDeg, a.tel().q_act[4], 0.2 * kDeg);
  CHECK_TEXT(ok(a.cmd("movej 0 0 0 0 -50 0")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("wait")), (a.s.out + a.events).c_str());
  DOUBLES_EQUAL(5 * kDeg, a.motor(4).position(), 0.1 * kDeg);  // -50 in the homed coordinates
  LONGS_EQUAL(0, long(a.rt_allocs));
}

// Collision detection on the motors' measured torque: a movej under gravity raises no alarm; a
// push on joint 2 while it holds stops the arm with fault collision naming the joint.
TEST(FwMitArm, CollisionDetectionOnMeasuredTorque) {
  FwConfig c = damiao_arm("torque");
  c.collision = true;
  Arm a(c);
  CHECK_TEXT(a.boot_error.empty(), a.boot_error.c_str());
  kin::JointVector q = kin::JointVector::Zero(6);
  a.arm_inertia(q);
  a.gravity = true;
  CHECK_TEXT(ok(a.cmd("enable")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("movej 10 -20 30 10 -10 10")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("wait")), (a.s.out + a.events).c_str());
  a.run(0.5);
  Telemetry t = a.tel();
  CHECK_TEXT(t.collision_on, a.app.dynamics_notes().c_str());
  LONGS_EQUAL(0, long(t.collisions));
  std::printf("\n  collision observer on six virtual DM-J4340 after a movej under gravity: peak |r|/threshold %.2f\n",
              t.collision_peak);
  a.gravity = false;
  for (int i = 0; i < 300 && a.tel().state != ArmState::fault; ++i) {
    a.load_gravity();
    a.motor(1).load_torque += 10.0;  // 40 N m at joint 2 through its 4:1 transmission
    a.cycle();
  }
  t = a.tel();
  CHECK_TEXT(t.state == ArmState::fault, a.events.c_str());
  CHECK_TEXT(t.cause == FaultCause::collision, t.fault_text);
  LONGS_EQUAL(1, t.fault_joint);
}

// The other MIT vendors through the same factory entry point: six Robstride RS00 answering on
// one master id (0x0FD), told apart by the motor id in the frame.
TEST(FwMitArm, RobstrideArmMoves) {
  FwConfig c = damiao_arm();
  for (DriveConfig& d : c.drives) {
    d.family = "robstride_mit";
    d.motor = "RS00";
  }
  Arm a(c);
  CHECK_TEXT(a.boot_error.empty(), a.boot_error.c_str());
  STRCMP_EQUAL("robstride_mit", a.app.servo->group(0).family());
  CHECK_TEXT(ok(a.cmd("enable")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("movej 10 -10 10 10 -10 10")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("wait")), (a.s.out + a.events).c_str());
  a.run(0.3);
  const double goal[6] = {10, -10, 10, 10, -10, 10};
  for (std::size_t j = 0; j < 6; ++j) DOUBLES_EQUAL(goal[j] * kDeg, a.tel().q_act[j], 0.05 * kDeg);
  LONGS_EQUAL(0, long(a.rt_allocs));
}

// Temperatures: each MIT joint's hottest reported temperature (MOSFET or winding) reaches the
// service's status and the console's `status`; a CiA 402 joint, whose drive reports none, shows
// "-". DM-J4340's OT_Value is 100 deg C (the virtual motor's register): warning from 85, fault at
// 95, before the motor's own cut-off.
TEST(FwMitArm, TemperaturesReachStatusWarnAndFaultBeforeTheMotorsCutOff) {
  FwConfig c = damiao_arm("off");
  c.drives[5] = DriveConfig{};  // a CiA 402 wrist on a second bus
  c.drives[5].node = 6;
  c.drives[5].can = "sim1";
  Arm a(c);
  CHECK_TEXT(a.boot_error.empty(), a.boot_error.c_str());
  CHECK_TEXT(ok(a.cmd("enable")), a.s.out.c_str());
  a.motor(2).set_temperature(60.4);
  a.run(0.05);
  std::string st = a.cmd("status");
  CHECK_TEXT(has(st, " temperature_c=[30 30 60 30 30 -]"), st.c_str());
  CHECK_TEXT(!has(st, "hot="), st.c_str());
  ArmStatus s = a.app.console->service().status();
  LONGS_EQUAL(6, long(s.temperature.size()));
  DOUBLES_EQUAL(60, s.temperature[2], 1.0);
  CHECK(std::isnan(s.temperature[5]));
  LONGS_EQUAL(0, long(s.temperature_warning));
  // 88 deg C: at or above the warning (85), below the fault (95): status says so, the arm runs on
  a.motor(2).set_temperature(88.4);
  a.run(0.05);
  st = a.cmd("status");
  CHECK_TEXT(has(st, "temperature_c=[30 30 88 30 30 -] hot=[3]"), st.c_str());
  s = a.app.console->service().status();
  LONGS_EQUAL(1 << 2, long(s.temperature_warning));
  CHECK_TEXT(s.state == ArmState::idle, s.fault_text.c_str());
  CHECK_TEXT(has(a.events, "joint 3 at 88 deg C: over-temperature warning (from 85 deg C; the arm stops at 95)"),
             a.events.c_str());
  CHECK_TEXT(ok(a.cmd("movej 0 0 5 0 0 0")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("wait")), (a.s.out + a.events).c_str());
  // 97 deg C: the arm stops in fault, one line naming the joint, the temperature and the limit,
  // while the motor (cut-off 100) has not tripped itself
  a.motor(2).set_temperature(97.4);
  a.run(0.05);
  const Telemetry t = a.tel();
  CHECK_TEXT(t.state == ArmState::fault, a.events.c_str());
  CHECK_TEXT(t.cause == FaultCause::over_temperature, t.fault_text);
  LONGS_EQUAL(2, t.fault_joint);
  STRCMP_EQUAL("joint 3 over_temperature: 97 deg C, at or above its limit 95 deg C (the motor's own cut-off 100 deg C)",
               t.fault_text);
  CHECK_TEXT(has(a.events, "alarm: fault joint 3 over_temperature: 97 deg C"), a.events.c_str());
  LONGS_EQUAL(0, long(a.motor(2).error()));
  LONGS_EQUAL(0, long(a.rt_allocs));
}

// E-stop on an arm of MIT motors, which have no brakes: the motors hold where the arm came to
// rest (the measured position, zero velocity, the configured kp / kd and the torque they gave
// then) instead of being powered down, so a heavy arm does not fall. On the dynamic plant under
// gravity, with the controller's ramp (safety.stop = "ramp") and with the drives' own stop
// ("drive"); a joint that does not come to rest (pushed beyond T_MAX) is powered down after
// safety.drive_stop_timeout_s, as CiA 402 drives are (the timeout here is 4 s; the default's
// case is EstopBrakesAHeavyBaseWithinTheDefaultTimeout*).
void estop_holds(const char* stop) {
  FwConfig c = damiao_arm("torque");
  c.stop = stop;
  c.drive_stop_timeout_s = 4;
  Arm a(c);
  CHECK_TEXT(a.boot_error.empty(), a.boot_error.c_str());
  enable_at_work_pose(a);
  a.run(0.3);
  CHECK_TEXT(ok(a.cmd("movej 20 -10 40 10 0 10")), a.s.out.c_str());
  a.run(0.4);  // mid-move
  CHECK_TEXT(ok(a.cmd("estop")), a.s.out.c_str());
  // the motors brake on their damping and hold where the arm comes to rest: the e-stop is latched
  // with the motors powered
  int ms = 0;
  for (; ms < 4000 && a.tel().mode != Mode::estop; ++ms) a.run(0.001);
  CHECK_TEXT(a.tel().mode == Mode::estop, a.events.c_str());
  for (std::size_t j = 0; j < 6; ++j) CHECK_TEXT(a.motor(j).enabled(), a.events.c_str());
  const Telemetry t0 = a.tel();
  a.run(4.5);  // past safety.drive_stop_timeout_s
  const Telemetry t1 = a.tel();
  CHECK_TEXT(t1.state == ArmState::estop, a.events.c_str());
  double drop = 0;
  for (std::size_t j = 0; j < 6; ++j) drop = std::max(drop, std::fabs(t1.q_act[j] - t0.q_act[j]));
  std::printf("\n  e-stop (safety.stop = \"%s\") mid-move on six virtual DM-J4340 under gravity: at rest and held "
              "%d ms after it, then moved %.4f deg in 4.5 s\n", stop, ms, drop / kDeg);
  CHECK(drop < 0.2 * kDeg);
  for (std::size_t j = 0; j < 6; ++j) CHECK_TEXT(a.motor(j).enabled(), a.events.c_str());
  const auto& g = static_cast<const hal::MitGroup&>(a.app.servo->group(0));
  DOUBLES_EQUAL(60, g.last_command(1).kp, 0.2);
  DOUBLES_EQUAL(5, g.last_command(1).kd, 0.01);  // KD_MAX
  DOUBLES_EQUAL(0, g.last_command(1).v, 0);
  CHECK(std::fabs(a.app.servo->feedback(1).velocity) < 0.01);
  // reset, enable: it moves on from where it held
  CHECK_TEXT(ok(a.cmd("reset")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("enable")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("movej 0 -30 60 0 20 0")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("wait")), (a.s.out + a.events).c_str());
  CHECK_TEXT(a.tel().state == ArmState::idle, (a.tel().fault_text + a.events).c_str());
  // e-stop while joint 1 is pushed beyond its T_MAX: it does not come to rest, so its motor is
  // powered down after the timeout; the others keep holding
  CHECK_TEXT(ok(a.cmd("estop")), a.s.out.c_str());
  a.gravity = false;  // (cycle() would set the load back to gravity alone)
  for (int i = 0; i < 4500; ++i) {
    a.load_gravity();
    a.motor(0).load_torque += 40.0;
    a.cycle();
    a.app.console->poll(a.s);

  }
  CHECK_TEXT(a.tel().state == ArmState::estop, a.events.c_str());
  CHECK_FALSE(a.motor(0).enabled());
  CHECK(a.motor(3).enabled());
  LONGS_EQUAL(0, long(a.rt_allocs));
}

TEST(FwMitArm, EstopHoldsTheArmAgainstGravityWithTheControllersRamp) { estop_holds("ramp"); }

TEST(FwMitArm, EstopHoldsTheArmAgainstGravityWithTheDrivesStop) { estop_holds("drive"); }

// E-stop mid-move with the default safety.drive_stop_timeout_s (2 s): the puma's base, whose
// inertia KD_MAX alone would take about 2.3 s to brake from the speed it has here, brakes on its
// deceleration limit instead and holds well within the timeout; no motor is powered down, and
// the joints that were not moving never drop. (They move a little while the base brakes: the
// model's feed-forward gives them the torque the base's deceleration couples into a real arm,
// which these motors, each moving an inertia of its own, do not feel: up to 0.7 deg on joint 2.)
void estop_base_brakes_within_the_default_timeout(const char* stop) {
  FwConfig c = damiao_arm("torque");
  c.stop = stop;  // safety.drive_stop_timeout_s left at its default
  Arm a(c);
  CHECK_TEXT(a.boot_error.empty(), a.boot_error.c_str());
  DOUBLES_EQUAL(2.0, c.drive_stop_timeout_s, 0);
  enable_at_work_pose(a);
  a.run(0.3);
  CHECK_TEXT(ok(a.cmd("movej 60 -30 60 0 20 0")), a.s.out.c_str());  // the base alone
  a.run(0.6);  // mid-move, the base near its top speed
  const double v0 = a.app.servo->feedback(0).velocity;
  const Telemetry before = a.tel();
  CHECK_TEXT(ok(a.cmd("estop")), a.s.out.c_str());
  int rest_ms = -1;
  double moved_others = 0;
  for (int ms = 0; ms < 4000; ++ms) {
    a.run(0.001);
    if (rest_ms < 0 && a.app.servo->holding(0)) rest_ms = ms;
    const Telemetry t = a.tel();
    for (std::size_t j = 1; j < 6; ++j) moved_others = std::max(moved_others, std::fabs(t.q_act[j] - before.q_act[j]));
  }
  const Telemetry t = a.tel();
  std::printf("\n  e-stop (safety.stop = \"%s\", drive_stop_timeout_s 2) with the puma's base at %.2f rad/s: base at rest "
              "and held after %d ms, motors %s, the other joints moved at most %.4f deg in 4 s\n",
              stop, v0, rest_ms, a.motor(0).enabled() && a.motor(1).enabled() ? "powered" : "powered DOWN",
              moved_others / kDeg);
  CHECK(std::fabs(v0) > 0.5);
  CHECK_TEXT(t.state == ArmState::estop, a.events.c_str());
  for (std::size_t j = 0; j < 6; ++j) CHECK_TEXT(a.motor(j).enabled(), a.events.c_str());
  CHECK(rest_ms >= 0 && rest_ms < 1500);
  CHECK(moved_others < 1.0 * kDeg);
  CHECK(std::fabs(a.app.servo->feedback(0).velocity) < 0.01);
  LONGS_EQUAL(0, long(a.rt_allocs));
}

TEST(FwMitArm, EstopBrakesAHeavyBaseWithinTheDefaultTimeoutWithTheDrivesStop) {
  estop_base_brakes_within_the_default_timeout("drive");
}

TEST(FwMitArm, EstopBrakesAHeavyBaseWithinTheDefaultTimeoutWithTheControllersRamp) {
  estop_base_brakes_within_the_default_timeout("ramp");
}

// Without the model's torque feed-forward nothing but the hold frame's KD_MAX would brake the
// base after a stop (its inertia over KD_MAX: about 0.85 s, more than 2 s to rest from here, past
// the default timeout, which would then power it down and let it coast). The hold brakes it with
// the stop damping (its largest inertia over 0.1 s, beyond KD_MAX through tau_ff, at most T_MAX),
// with the drives' stop and with the controller's ramp, whose end finds the base still moving:
// kp alone lags its inertia far behind the setpoints. (No gravity here: without the model's
// torque nothing holds the puma against it.)
void estop_without_the_model_brakes_within_the_default_timeout(const char* stop) {
  FwConfig c = damiao_arm("velocity");
  c.stop = stop;  // safety.drive_stop_timeout_s left at its default
  c.following_error_deg = 45;
  Arm a(c);
  CHECK_TEXT(a.boot_error.empty(), a.boot_error.c_str());
  kin::JointVector q = kin::JointVector::Zero(6);
  q << 0, -30 * kDeg, 60 * kDeg, 0, 20 * kDeg, 0;
  a.arm_inertia(q);
  CHECK_TEXT(ok(a.cmd("enable")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("movej 0 -30 60 0 20 0")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("wait")), (a.s.out + a.events).c_str());
  CHECK_TEXT(ok(a.cmd("movej 60 -30 60 0 20 0")), a.s.out.c_str());  // the base alone
  a.run(0.6);
  const double v0 = a.app.servo->feedback(0).velocity;
  CHECK_TEXT(ok(a.cmd("estop")), a.s.out.c_str());
  int rest_ms = -1;
  double top = 0;
  for (int ms = 0; ms < 4000; ++ms) {
    a.run(0.001);
    top = std::max(top, std::fabs(a.app.servo->feedback(0).velocity));
    if (rest_ms < 0 && a.app.servo->holding(0)) rest_ms = ms;
  }
  std::printf("\n  e-stop (safety.stop = \"%s\", velocity feed-forward, drive_stop_timeout_s 2) with the puma's base at "
              "%.2f rad/s (at most %.2f after it): at rest and held after %d ms, base motor %s\n",
              stop, v0, top, rest_ms, a.motor(0).enabled() ? "powered" : "powered DOWN");
  CHECK(std::fabs(v0) > 0.5);
  CHECK_TEXT(a.tel().state == ArmState::estop, a.events.c_str());
  for (std::size_t j = 0; j < 6; ++j) CHECK_TEXT(a.motor(j).enabled(), a.events.c_str());
  CHECK(rest_ms >= 0 && rest_ms < 1500);
  CHECK(std::fabs(a.app.servo->feedback(0).velocity) < 0.01);
  LONGS_EQUAL(0, long(a.rt_allocs));
}

TEST(FwMitArm, WithoutTheModelsTorqueTheHoldBrakesAHeavyBaseWithinTheDefaultTimeoutWithTheDrivesStop) {
  estop_without_the_model_brakes_within_the_default_timeout("drive");
}

TEST(FwMitArm, WithoutTheModelsTorqueTheHoldBrakesAHeavyBaseWithinTheDefaultTimeoutWithTheControllersRamp) {
  estop_without_the_model_brakes_within_the_default_timeout("ramp");
}

// A joint that does not come to rest within safety.drive_stop_timeout_s (the base, pushed beyond
// its motor's T_MAX from the e-stop on, let go once powered down) is powered down alone at the
// timeout; the other motors, at rest, keep holding the arm against gravity (within a fraction of
// a degree: the model's feed-forward gives them the coupling torques of the base's motion, which
// these separate virtual motors do not feel).
TEST(FwMitArm, AJointNotAtRestAtTheTimeoutIsPoweredDownAloneTheOthersHold) {
  FwConfig c = damiao_arm("torque");
  c.stop = "drive";
  Arm a(c);
  CHECK_TEXT(a.boot_error.empty(), a.boot_error.c_str());
  enable_at_work_pose(a);
  a.run(0.3);
  const Telemetry before = a.tel();
  CHECK_TEXT(ok(a.cmd("estop")), a.s.out.c_str());
  a.gravity = false;  // (cycle() would set the load back to gravity alone)
  double moved_others = 0;
  int base_off_ms = -1;
  for (int ms = 0; ms < 4000; ++ms) {
    a.load_gravity();
    if (base_off_ms < 0) a.motor(0).load_torque += 32.0;  // beyond the DM-J4340's 28 N m, until it is let go
    a.cycle();
    a.app.console->poll(a.s);
    if (base_off_ms < 0 && !a.motor(0).enabled()) base_off_ms = ms;
    const Telemetry t = a.tel();
    for (std::size_t j = 1; j < 6; ++j) moved_others = std::max(moved_others, std::fabs(t.q_act[j] - before.q_act[j]));
  }
  const Telemetry t = a.tel();
  int powered = 0;
  for (std::size_t j = 1; j < 6; ++j) powered += a.motor(j).enabled() ? 1 : 0;
  std::printf("\n  e-stop with the base pushed beyond T_MAX: base powered down %d ms after it, %d of the 5 other motors "
              "powered, which moved at most %.4f deg in 4 s\n", base_off_ms, powered, moved_others / kDeg);
  CHECK_TEXT(t.state == ArmState::estop, a.events.c_str());
  CHECK(base_off_ms >= 2000 && base_off_ms < 2100);
  LONGS_EQUAL(5, powered);
  CHECK(moved_others < 1.0 * kDeg);
  LONGS_EQUAL(0, long(a.rt_allocs));
}

// `reset` after an e-stop on MIT motors (no brakes): the motors keep holding the arm where it
// came to rest until the next `enable` (back to the setpoints, no jump) or `disable` (powered
// down); a heavy arm does not drop between the two commands.
TEST(FwMitArm, ResetKeepsTheMotorsHoldingUntilTheNextEnable) {
  FwConfig c = damiao_arm("torque");
  c.stop = "drive";
  Arm a(c);
  CHECK_TEXT(a.boot_error.empty(), a.boot_error.c_str());
  enable_at_work_pose(a);
  a.run(0.3);
  CHECK_TEXT(ok(a.cmd("estop")), a.s.out.c_str());
  a.run(0.5);
  CHECK_TEXT(a.tel().mode == Mode::estop, a.events.c_str());
  const Telemetry t0 = a.tel();
  const std::string r = a.cmd("reset");
  CHECK_TEXT(ok(r), r.c_str());
  a.run(3.0);  // longer than any operator takes to send enable
  const Telemetry t1 = a.tel();
  double drop = 0;
  for (std::size_t j = 0; j < 6; ++j) drop = std::max(drop, std::fabs(t1.q_act[j] - t0.q_act[j]));
  int powered = 0;
  for (std::size_t j = 0; j < 6; ++j) powered += a.motor(j).enabled() ? 1 : 0;
  std::printf("\n  reset after an e-stop on six virtual DM-J4340 under gravity: '%s', 3 s later %d of 6 motors powered, the "
              "arm moved %.4f deg\n", r.substr(0, r.find('\n')).c_str(), powered, drop / kDeg);
  CHECK_TEXT(has(r, "the motors hold the arm until enable"), r.c_str());
  LONGS_EQUAL(6, powered);
  CHECK(drop < 0.2 * kDeg);
  CHECK_TEXT(t1.state == ArmState::disabled, a.events.c_str());
  // enable: back to the setpoints from where the arm holds, then it moves
  CHECK_TEXT(ok(a.cmd("enable")), a.s.out.c_str());
  a.run(0.1);
  CHECK_TEXT(a.tel().state == ArmState::idle, (a.tel().fault_text + a.events).c_str());
  double jump = 0;
  for (std::size_t j = 0; j < 6; ++j) jump = std::max(jump, std::fabs(a.tel().q_act[j] - t0.q_act[j]));
  CHECK(jump < 0.2 * kDeg);
  CHECK_TEXT(ok(a.cmd("movej 10 -30 60 0 20 0")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("wait")), (a.s.out + a.events).c_str());
  DOUBLES_EQUAL(10 * kDeg, a.tel().q_act[0], 0.1 * kDeg);
  // e-stop, reset, disable: powered down
  CHECK_TEXT(ok(a.cmd("estop")), a.s.out.c_str());
  a.run(0.5);
  CHECK_TEXT(ok(a.cmd("reset")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("disable")), a.s.out.c_str());
  a.run(0.05);
  for (std::size_t j = 0; j < 6; ++j) CHECK_FALSE(a.motor(j).enabled());
  LONGS_EQUAL(0, long(a.rt_allocs));
}

// Free-drive on MIT motors: kp = 0, the free-drive damping (dynamics.freedrive_damping x the
// joint's largest inertia) as the motor's kd (it damps the hand's motion in its own loop, so the
// model adds no damping torque of its own) and the gravity torque as tau_ff. A
// joint the hand carries past its joint limit stops the arm in fault, one line naming the joint
// and the limit.
TEST(FwMitArm, FreeDriveDampsWithTheMotorsKdAndFaultsPastAJointLimit) {
  FwConfig c = damiao_arm("torque");
  c.freedrive = true;
  Arm a(c);
  CHECK_TEXT(a.boot_error.empty(), a.boot_error.c_str());
  kin::JointVector q = kin::JointVector::Zero(6);
  q << 0, -30 * kDeg, 60 * kDeg, 0, 95 * kDeg, 0;
  a.arm_inertia(q);
  a.gravity = true;
  CHECK_TEXT(ok(a.cmd("enable")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("movej 0 -30 60 0 95 0")), a.s.out.c_str());
  CHECK_TEXT(ok(a.cmd("wait")), (a.s.out + a.events).c_str());
  a.run(0.3);
  CHECK_TEXT(has(a.cmd("freedrive on"), "ok free-drive on"), (a.s.out + a.events).c_str());
  a.run(0.05);
  // the hand pushes joint 5 (0.5 N m) towards its upper limit (100 deg)
  a.gravity = false;
  double max_ff_error = 0, speed = 0, kd = 0;
  int i = 0;
  for (; i < 3000 && a.tel().state == ArmState::freedrive; ++i) {
    a.load_gravity();
    a.motor(4).load_torque += 0.5;
    a.cycle();
    a.app.console->poll(a.s);
    const auto& g = static_cast<const hal::MitGroup&>(a.app.servo->group(0));
    if (a.tel().state != ArmState::freedrive || i < 20) continue;
    DOUBLES_EQUAL(0, g.last_command(4).kp, 0);
    kd = g.last_command(4).kd;
    // tau_ff: the gravity torque alone, however fast the hand moves the joint
    kin::JointVector qa = kin::JointVector::Zero(6), gr = kin::JointVector::Zero(6);
    for (std::size_t j = 0; j < 6; ++j) qa[static_cast<int>(j)] = a.app.servo->feedback(j).position;
    kin::gravity_torques(a.app.chain, qa, gr);
    max_ff_error = std::max(max_ff_error, std::fabs(g.last_command(4).t - gr[4]));
    speed = std::max(speed, std::fabs(a.app.servo->feedback(4).velocity));
  }
  const Telemetry t = a.tel();
  std::printf("\n  free-drive, joint 5 pushed with 0.5 N m: top speed %.3f rad/s (kd %.3f in the motor), tau_ff within %.4f "
              "N m of gravity, fault after %d ms: %s\n", speed, kd, max_ff_error, i, t.fault_text);
  CHECK(kd > 0);
  CHECK(speed > 0.6 * 0.5 / kd && speed < 1.05 * 0.5 / kd);  // the motor's damping alone: 0.5 N m / kd
  CHECK(max_ff_error < 0.02);
  CHECK_TEXT(t.state == ArmState::fault, a.events.c_str());
  CHECK_TEXT(t.cause == FaultCause::joint_limit, t.fault_text);
  LONGS_EQUAL(4, t.fault_joint);
  CHECK_TEXT(has(t.fault_text, "joint 5 joint_limit: free-drive carried it to 1.74"), t.fault_text);
  CHECK_TEXT(has(t.fault_text, "beyond its upper limit 1.7453 rad"), t.fault_text);
  CHECK_TEXT(has(a.events, "alarm: fault joint 5 joint_limit"), a.events.c_str());
  // the arm stops (the hand lets go): the motors brake it and hold it there
  a.gravity = true;
  a.run(1.5);
  std::printf("  after the fault: %s, joint 5 at %.3f deg, motor %s\n", to_string(a.tel().mode), a.tel().q_act[4] / kDeg,
              a.motor(4).enabled() ? "enabled" : "disabled");
  CHECK(a.tel().q_act[4] < 101 * kDeg);
  CHECK(a.tel().mode == Mode::fault);
  CHECK(a.motor(4).enabled());
  CHECK(std::fabs(a.app.servo->feedback(4).velocity) < 0.01);
  LONGS_EQUAL(0, long(a.rt_allocs));
}
