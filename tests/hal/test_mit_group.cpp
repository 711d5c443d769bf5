// SPDX-License-Identifier: Apache-2.0
// The MIT-mode drive family (hal/mit_group.hpp) against virtual Damiao motors
// (host_sim/mit_motor.hpp) on an in-process bus, single-threaded on a ManualClock: bring-up over
// the registers (mode, ranges, watchdog), tracking with feed-forward, the quirks users meet each
// giving one line, the motor's own watchdog, temperatures, the multi-turn position, torque mode.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "alloc_counter.hpp"
#include "servoarm/hal/clock.hpp"
#include "servoarm/hal/mit_group.hpp"
#include "servoarm/sim/mit_motor.hpp"

// CppUTest last: its leak detector redefines `new`.
#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::hal;

namespace {

const mit::MotorProfile& j4340() { return *mit::find_profile("DM-J4340"); }

std::vector<sim::MitMotorSpec> motors(std::size_t n, std::uint32_t mode = 1) {
  std::vector<sim::MitMotorSpec> v;
  for (std::size_t i = 0; i < n; ++i) {
    sim::MitMotorSpec s;
    s.profile = &j4340();
    s.id = static_cast<std::uint16_t>(i + 1);
    s.master = static_cast<std::uint16_t>(i + 1 + 0x10);
    s.ctrl_mode = mode;
    v.push_back(s);
  }
  return v;
}

MitGroupConfig group_config(std::size_t n) {
  MitGroupConfig c;
  c.vendor = mit::Vendor::damiao;
  c.joint_count = n;
  for (std::size_t i = 0; i < n; ++i) {
    c.joints[i].motor_id = static_cast<std::uint16_t>(i + 1);
    c.joints[i].profile = &j4340();
    c.joints[i].kp = 30;
    c.joints[i].kd = 1;
  }
  return c;
}

/// Motors and the group on one bus; the clock's idle hook steps the motors.
struct Rig {
  ManualClock clock;
  std::unique_ptr<sim::MitPlant> plant;
  std::unique_ptr<MitGroup> group;
  Rig(const std::vector<sim::MitMotorSpec>& m, const MitGroupConfig& c, void (*tweak)(sim::MitPlant&) = nullptr) {
    plant = std::make_unique<sim::MitPlant>(clock, m);
    if (tweak != nullptr) tweak(*plant);
    group = std::make_unique<MitGroup>(plant->master_bus(), clock, c);
    clock.set_idle_hook([this](TimePoint t) { plant->step(t); });
  }
  ~Rig() { clock.set_idle_hook(nullptr); }
  Status start() { return group->start(clock.now() + kSecond); }
  /// One control cycle: read, the setpoints, write, 1 ms.
  Status cycle(const std::vector<double>& sp) {
    const Status r = group->read(clock.now());
    group->write(sp, clock.now());
    clock.advance(kMillisecond);
    return r;
  }
  std::vector<double> held() const {
    std::vector<double> v;
    for (std::size_t j = 0; j < group->joint_count(); ++j) v.push_back(group->feedback(j).position);
    return v;
  }
  bool enable() {
    group->enable();
    for (int i = 0; i < 20; ++i) {
      cycle(held());
      bool all = true;
      for (std::size_t j = 0; j < group->joint_count(); ++j) all = all && group->feedback(j).state == JointState::enabled;
      if (all) return true;
    }
    return false;
  }
};

}  // namespace

TEST_GROUP(MitGroup){};

TEST(MitGroup, BringUpPutsTheMotorInMitModeAndSetsItsWatchdog) {
  Rig rig(motors(2, 2), group_config(2));  // both in position-velocity mode at power-up
  LONGS_EQUAL(int(Status::ok), int(rig.group->config_status()));
  const Status s = rig.start();
  STRCMP_EQUAL("", rig.group->last_error());
  LONGS_EQUAL(int(Status::ok), int(s));
  for (std::size_t j = 0; j < 2; ++j) {
    UNSIGNED_LONGS_EQUAL(1, rig.plant->at(j).reg(mit::Reg::ctrl_mode));  // written to MIT
    UNSIGNED_LONGS_EQUAL(2000, rig.plant->at(j).reg(mit::Reg::timeout));  // 100 ms in 50 us units
    CHECK(rig.group->feedback(j).valid);
    LONGS_EQUAL(int(JointState::disabled), int(rig.group->feedback(j).state));
  }
  STRCMP_EQUAL("damiao", rig.group->family());
  DOUBLES_EQUAL(8, rig.group->ranges(0).v_max, 1e-6);  // the motor's VMAX register
}

TEST(MitGroup, RangesReadFromTheMotorAreUsedAndNoted) {
  Rig rig(motors(1), group_config(1), [](sim::MitPlant& p) { p.at(0).set_reg_f(mit::Reg::vmax, 10.0f); });
  LONGS_EQUAL(int(Status::ok), int(rig.start()));
  DOUBLES_EQUAL(10, rig.group->ranges(0).v_max, 1e-6);
  STRCMP_CONTAINS("VMAX reads 10, the DM-J4340 profile says 8", rig.group->notes());
}

TEST(MitGroup, TracksASineWithFeedForwardAndAllocatesNothing) {
  Rig rig(motors(2), group_config(2));
  LONGS_EQUAL(int(Status::ok), int(rig.start()));
  CHECK(rig.enable());
  const JointCapabilities caps = rig.group->capabilities(0);
  CHECK(caps.velocity_offset && caps.torque_offset && caps.torque_mode && caps.measured_torque);
  double worst = 0, worst_ff = 0, torque_seen = 0;
  std::size_t allocs = 0;
  const double a = 0.5, w = 2.0;
  for (int pass = 0; pass < 2; ++pass) {
    const TimePoint t0 = rig.clock.now();
    double err = 0;
    for (int i = 0; i < 3000; ++i) {
      const double t = static_cast<double>(rig.clock.now() - t0) * 1e-9;
      std::vector<double> sp{a * std::sin(w * t), -a * std::sin(w * t)};
      test::alloc_count_begin();
      rig.group->read(rig.clock.now());
      if (i > 1000) err = std::fmax(err, std::fabs(rig.group->feedback(0).position - a * std::sin(w * (t - 1e-3))));
      torque_seen = std::fmax(torque_seen, std::fabs(rig.group->feedback(0).torque));
      if (pass == 1) {
        // velocity and the torque the inertia needs, as the dynamics model would give them
        rig.group->set_feed_forward(0, a * w * std::cos(w * t), -0.01 * a * w * w * std::sin(w * t));
        rig.group->set_feed_forward(1, -a * w * std::cos(w * t), 0.01 * a * w * w * std::sin(w * t));
      }
      rig.group->write(sp, rig.clock.now());
      allocs += test::alloc_count_end();
      rig.clock.advance(kMillisecond);
    }
    (pass == 0 ? worst : worst_ff) = err;
  }
  LONGS_EQUAL(0, allocs);
  std::printf("\nMIT sine 0.5 rad at 2 rad/s, DM-J4340 kp 30 kd 1: following error %.5f rad, with feed-forward %.5f rad\n",
              worst, worst_ff);
  CHECK(worst < 0.05);
  CHECK(worst_ff < worst / 3);  // the feed-forward takes most of the lag away
  CHECK(torque_seen > 0.01);     // measured torque comes back
  CHECK(rig.group->last_command(0).kp > 29.9 && rig.group->last_command(0).kd > 0.99);
}

TEST(MitGroup, NoReplyAtThisBitrateIsOneLine) {
  Rig rig(motors(2), group_config(2), [](sim::MitPlant& p) { p.at(1).quirks().silent = true; });
  LONGS_EQUAL(int(Status::timeout), int(rig.start()));
  STRCMP_EQUAL(
      "joint 1 (damiao id 0x02): no answer to a register read (CTRL_MODE) on 0x7FF in 60 ms: the motor is not on this bus "
      "at this bitrate and frame format (classic CAN / CAN FD), not powered, or has another id",
      rig.group->last_error());
}

TEST(MitGroup, AModeThatWillNotChangeIsOneLine) {
  Rig rig(motors(1, 2), group_config(1), [](sim::MitPlant& p) { p.at(0).quirks().mode_locked = true; });
  LONGS_EQUAL(int(Status::drive_refused), int(rig.start()));
  STRCMP_EQUAL(
      "joint 0 (damiao id 0x01): control mode 2 (position-velocity), not MIT (1), and CTRL_MODE = 1 did not take: in "
      "that mode it answers no MIT frame; set it to MIT with the Damiao tool",
      rig.group->last_error());
}

TEST(MitGroup, WrongModeMotorAnswersNoMitFrame) {
  // What the bring-up guards against: a motor left in position-velocity mode takes the enable
  // frame but answers no MIT frame and does not move.
  ManualClock clock;
  sim::MitPlant plant(clock, motors(1, 2));
  CanFrame f;
  plant.master_bus().send(mit::special_frame(1, mit::Special::enable));
  mit::pack_command(mit::ranges_of(j4340()), 1, {1.0, 0, 30, 1, 0}, f);
  plant.master_bus().send(f);
  plant.step(clock.now());
  int answers = 0;
  CanFrame in;
  while (plant.master_bus().receive(in, 0) == Status::ok) ++answers;
  LONGS_EQUAL(1, answers);  // the enable frame's only
  UNSIGNED_LONGS_EQUAL(0, plant.at(0).mit_frames());
}

TEST(MitGroup, MasterIdClashIsOneLine) {
  auto m = motors(2);
  m[1].master = 0x11;  // motor 2 answers on motor 1's master id
  Rig rig(m, group_config(2));
  LONGS_EQUAL(int(Status::protocol_error), int(rig.start()));
  STRCMP_EQUAL(
      "joint 1 (damiao id 0x02): answers on 0x011, joint 0's master id (configured 0x012): master id clash, their "
      "feedback cannot be told apart; write its MST_ID to 0x012",
      rig.group->last_error());
}

TEST(MitGroup, LateAnswersWithinTheRetriesAreTakenTooLateOnesAreOneLine) {
  {
    Rig rig(motors(1), group_config(1), [](sim::MitPlant& p) { p.at(0).quirks().late = 5 * kMillisecond; });
    LONGS_EQUAL(int(Status::ok), int(rig.start()));
  }
  Rig rig(motors(1), group_config(1), [](sim::MitPlant& p) { p.at(0).quirks().late = 200 * kMillisecond; });
  LONGS_EQUAL(int(Status::timeout), int(rig.start()));
  STRCMP_CONTAINS("joint 0 (damiao id 0x01): no answer to a register read (CTRL_MODE) on 0x7FF in 60 ms", rig.group->last_error());
}

TEST(MitGroup, ConfigurationClashesAreRefusedBeforeTheBus) {
  ManualClock clock;
  sim::MitPlant plant(clock, motors(2));
  MitGroupConfig c = group_config(2);
  c.joints[1].master_id = 0x11;  // joint 0's default master id
  MitGroup g(plant.master_bus(), clock, c);
  LONGS_EQUAL(int(Status::invalid_argument), int(g.config_status()));
  STRCMP_EQUAL("joint 1 (damiao id 0x02): master id 0x011 is joint 0's too: their feedback could not be told apart",
               g.last_error());
  MitGroupConfig c2 = group_config(2);
  c2.joints[0].master_id = 0x02;  // joint 1's command id
  MitGroup g2(plant.master_bus(), clock, c2);
  STRCMP_EQUAL("joint 1 (damiao id 0x02): master id 0x002 clashes with joint 0's motor id", g2.last_error());
  MitGroupConfig c3 = group_config(1);
  c3.joints[0].profile = mit::find_profile("AK80-9");
  MitGroup g3(plant.master_bus(), clock, c3);
  STRCMP_EQUAL("joint 0 (damiao id 0x01): AK80-9 is a cubemars_mit motor, not damiao", g3.last_error());
  MitGroupConfig c4 = group_config(1);
  c4.joints[0].kp = 900;
  MitGroup g4(plant.master_bus(), clock, c4);
  STRCMP_EQUAL("joint 0 (damiao id 0x01): kp 900 / kd 1 outside the DM-J4340's 0..500 / 0..5", g4.last_error());
}

TEST(MitGroup, TheMotorsWatchdogStopsItWhenTheFirmwareStopsTalking) {
  Rig rig(motors(1), group_config(1));
  LONGS_EQUAL(int(Status::ok), int(rig.start()));
  CHECK(rig.enable());
  CHECK(rig.plant->at(0).enabled());
  rig.clock.advance(150 * kMillisecond);  // the firmware is gone: nothing sent
  CHECK_FALSE(rig.plant->at(0).enabled());
  LONGS_EQUAL(0xD, rig.plant->at(0).error());
  // the firmware back: the group saw no feedback, then the motor's own error
  LONGS_EQUAL(int(Status::heartbeat_lost), int(rig.group->read(rig.clock.now())));
  STRCMP_CONTAINS("no feedback for", rig.group->last_error());
}

TEST(MitGroup, MotorErrorsAndTemperatures) {
  Rig rig(motors(1), group_config(1));
  LONGS_EQUAL(int(Status::ok), int(rig.start()));
  CHECK(rig.enable());
  // DM OT_Value 100 deg C: warning from 85, fault from 95, before the motor's own cut-off
  rig.plant->at(0).set_temperature(88);
  rig.cycle(rig.held());
  rig.cycle(rig.held());
  CHECK(rig.group->temperature_warning(0));
  DOUBLES_EQUAL(88, rig.group->temperature_rotor(0), 0.5);
  LONGS_EQUAL(int(JointState::enabled), int(rig.group->feedback(0).state));
  rig.plant->at(0).set_temperature(96);
  rig.cycle(rig.held());
  LONGS_EQUAL(int(Status::drive_fault), int(rig.cycle(rig.held())));
  STRCMP_EQUAL("joint 0 (damiao id 0x01): 96 deg C, at or above its fault temperature 95 deg C", rig.group->last_error());
  rig.cycle(rig.held());
  CHECK_FALSE(rig.plant->at(0).enabled());  // the group disabled it
  // cooled down, enabled again; then an under-voltage from the motor
  rig.plant->at(0).set_temperature(40);
  CHECK(rig.enable());  // the answers still in flight say 96: the clear-error frame's answer decides
  rig.plant->at(0).inject_error(0x9);
  rig.cycle(rig.held());
  LONGS_EQUAL(int(Status::drive_fault), int(rig.cycle(rig.held())));
  STRCMP_EQUAL("joint 0 (damiao id 0x01): motor error 0x9: under-voltage", rig.group->last_error());
  LONGS_EQUAL(9, rig.group->feedback(0).error_code);
  // enable() clears it (clear-error frame, then enable)
  CHECK(rig.enable());
  LONGS_EQUAL(0, rig.plant->at(0).error());
}

TEST(MitGroup, AJointThatTurnsPastPmaxKeepsItsTruePosition) {
  Rig rig(motors(1), group_config(1));
  LONGS_EQUAL(int(Status::ok), int(rig.start()));
  // turned by hand (disabled) from 0 to 30 rad and back to -30: past +-P_MAX (12.5) both ways
  double worst = 0;
  for (int i = 0; i <= 600; ++i) {
    rig.plant->at(0).set_position(0.05 * i);
    rig.cycle(rig.held());
    rig.group->read(rig.clock.now());
    worst = std::fmax(worst, std::fabs(rig.group->feedback(0).position - 0.05 * i));
  }
  for (int i = 600; i >= -600; --i) {
    rig.plant->at(0).set_position(0.05 * i);
    rig.cycle(rig.held());
    rig.group->read(rig.clock.now());
    worst = std::fmax(worst, std::fabs(rig.group->feedback(0).position - 0.05 * i));
  }
  CHECK(worst < 1e-3);
  DOUBLES_EQUAL(-30, rig.group->feedback(0).position, 1e-3);
}

TEST(MitGroup, JointMappingGearDirectionOffset) {
  MitGroupConfig c = group_config(1);
  c.joints[0].scaling.gear_ratio = 2;   // two actuator turns per joint turn
  c.joints[0].scaling.direction = -1;
  c.joints[0].scaling.zero_offset = 500000;  // joint zero at actuator +0.5 rad
  Rig rig(motors(1), c);
  rig.plant->at(0).set_position(1.5);
  LONGS_EQUAL(int(Status::ok), int(rig.start()));
  DOUBLES_EQUAL(-0.5, rig.group->feedback(0).position, 1e-3);  // -(1.5 - 0.5) / 2
  CHECK(rig.enable());
  for (int i = 0; i < 1500; ++i) rig.cycle({-0.2});
  DOUBLES_EQUAL(0.9, rig.plant->at(0).position(), 5e-3);  // 0.5 + 2 x (-1) x (-0.2)
  DOUBLES_EQUAL(-0.2, rig.group->feedback(0).position, 5e-3);
  DOUBLES_EQUAL(rig.plant->at(0).torque() * -2, rig.group->feedback(0).torque, 0.05);
}

TEST(MitGroup, TorqueModeIsKpZeroAndTheTargetTorque) {
  Rig rig(motors(1), group_config(1));
  LONGS_EQUAL(int(Status::ok), int(rig.start()));
  LONGS_EQUAL(int(Status::bad_state), int(rig.group->set_torque_mode(0, true)));  // not enabled
  CHECK(rig.enable());
  LONGS_EQUAL(int(Status::bad_state), int(rig.group->set_torque_mode(0, true)));  // no target torque
  LONGS_EQUAL(int(Status::invalid_argument), int(rig.group->set_target_torque(0, 100)));  // beyond T_MAX
  LONGS_EQUAL(int(Status::ok), int(rig.group->set_target_torque(0, 1.5)));
  LONGS_EQUAL(int(Status::ok), int(rig.group->set_torque_mode(0, true)));
  rig.cycle(rig.held());
  LONGS_EQUAL(int(CyclicMode::torque), int(rig.group->cyclic_mode(0).mode));
  DOUBLES_EQUAL(0, rig.group->last_command(0).kp, 0);
  DOUBLES_EQUAL(1, rig.group->last_command(0).kd, 0);  // the configured kd damps (no set_torque_damping given)
  DOUBLES_EQUAL(1.5, rig.group->last_command(0).t, 0);
  // the damping a caller gives (free-drive), as the actuator's kd; none: the target torque alone
  LONGS_EQUAL(int(Status::invalid_argument), int(rig.group->set_torque_damping(0, -1)));
  LONGS_EQUAL(int(Status::ok), int(rig.group->set_torque_damping(0, 0)));
  rig.cycle(rig.held());
  DOUBLES_EQUAL(0, rig.group->last_command(0).kd, 0);
  rig.cycle(rig.held());
  DOUBLES_EQUAL(1.5, rig.plant->at(0).torque(), 28.0 / 4095);
  LONGS_EQUAL(int(Status::ok), int(rig.group->set_torque_mode(0, false)));
  rig.cycle(rig.held());
  rig.cycle(rig.held());
  LONGS_EQUAL(int(CyclicMode::position), int(rig.group->cyclic_mode(0).mode));
  DOUBLES_EQUAL(30, rig.group->last_command(0).kp, 0);
}

// CubeMars and Robstride motors all answer on one master id and are told apart by byte 0:
// a shared master id is their normal set-up, not a clash; the group brings them up and drives them.
TEST(MitGroup, RobstrideMotorsShareTheirMasterId) {
  const mit::MotorProfile& rs = *mit::find_profile("RS00");
  std::vector<sim::MitMotorSpec> m(2);
  MitGroupConfig c;
  c.vendor = mit::Vendor::robstride;
  c.joint_count = 2;
  for (std::size_t i = 0; i < 2; ++i) {
    m[i].profile = &rs;
    m[i].id = static_cast<std::uint16_t>(i + 1);
    m[i].master = 0xFD;
    c.joints[i].motor_id = static_cast<std::uint16_t>(i + 1);
    c.joints[i].profile = &rs;
  }
  Rig rig(m, c);
  STRCMP_EQUAL("", rig.group->last_error());
  LONGS_EQUAL(int(Status::ok), int(rig.start()));
  CHECK(rig.enable());
  for (int i = 0; i < 1000; ++i) rig.cycle({0.3, -0.2});
  DOUBLES_EQUAL(0.3, rig.plant->at(0).position(), 2e-3);
  DOUBLES_EQUAL(-0.2, rig.plant->at(1).position(), 2e-3);
  STRCMP_EQUAL("robstride_mit", rig.group->family());
}

// CAN FD: motors set to CAN FD take and send FD frames only. A group sending FD (with bit-rate
// switch) brings them up and drives them; a classic group gets no answer, said in one line, and
// so does an FD group on classic motors.
TEST(MitGroup, CanFdMotorsNeedFdFramesAndAMismatchIsOneLine) {
  auto fd = motors(2);
  for (auto& m : fd) m.fd = true;
  MitGroupConfig c = group_config(2);
  c.fd = true;
  {
    Rig rig(fd, c);
    LONGS_EQUAL(int(Status::ok), int(rig.start()));
    CHECK(rig.enable());
    for (int i = 0; i < 800; ++i) rig.cycle({0.25, -0.25});
    DOUBLES_EQUAL(0.25, rig.plant->at(0).position(), 2e-3);
  }
  const char* expect =
      "joint 0 (damiao id 0x01): no answer to a register read (CTRL_MODE) on 0x7FF in 60 ms: the motor is not on this "
      "bus at this bitrate and frame format (classic CAN / CAN FD), not powered, or has another id";
  {
    Rig rig(fd, group_config(2));  // classic frames to FD motors
    LONGS_EQUAL(int(Status::timeout), int(rig.start()));
    STRCMP_EQUAL(expect, rig.group->last_error());
  }
  Rig rig(motors(2), c);  // FD frames to classic motors
  LONGS_EQUAL(int(Status::timeout), int(rig.start()));
  STRCMP_EQUAL(expect, rig.group->last_error());
}

// Enabled, a joint commanded past +P_MAX: the frame's position goes out in the motor's wrapped
// range (true target - turns x 2 P_MAX); near the wrap the law goes out as kp = 0 and a velocity
// (no error of 2 P_MAX if the motor crosses first); it crosses smoothly and holds at the target.
TEST(MitGroup, AnEnabledJointMovesPastPmaxAndHolds) {
  Rig rig(motors(1), group_config(1));
  rig.plant->at(0).set_position(12.0);
  LONGS_EQUAL(int(Status::ok), int(rig.start()));
  CHECK(rig.enable());
  double worst = 0;
  for (int i = 0; i <= 2000; ++i) {
    const double sp = 12.0 + 1.0 * std::fmin(1.0, i / 1000.0);  // 1 rad in 1 s, then hold at 13
    rig.cycle({sp});
    if (i > 5) worst = std::fmax(worst, std::fabs(rig.group->feedback(0).position - sp));
  }
  std::printf("\n  past P_MAX enabled: largest |position - setpoint| %.4f rad\n", worst);
  DOUBLES_EQUAL(13.0, rig.plant->at(0).position(), 2e-3);
  DOUBLES_EQUAL(13.0, rig.group->feedback(0).position, 2e-3);
  CHECK(worst < 0.04);  // the ramp's own lag, kd v / kp = 0.033 rad: nothing more at the crossing
  CHECK(rig.group->last_command(0).p > -12.1 && rig.group->last_command(0).p < -11.9);  // 13 - 25: the wrapped range
}

// A bus-off controller reaches no motor: every joint faults with bus_off at the next read.
TEST(MitGroup, BusOffFaultsEveryJoint) {
  Rig rig(motors(2), group_config(2));
  LONGS_EQUAL(int(Status::ok), int(rig.start()));
  CHECK(rig.enable());
  rig.plant->bus().set_error_state(ErrorState::bus_off);
  LONGS_EQUAL(int(Status::bus_off), int(rig.group->read(rig.clock.now())));
  for (std::size_t j = 0; j < 2; ++j) {
    LONGS_EQUAL(int(JointState::fault), int(rig.group->feedback(j).state));
    LONGS_EQUAL(int(Status::bus_off), int(rig.group->feedback(j).fault));
  }
  STRCMP_CONTAINS("the CAN controller is bus-off", rig.group->last_error());
}

// Damiao's other two control modes on the virtual motor: in position-velocity mode (CTRL_MODE 2)
// it takes [p, v] on 0x100 + id and moves to p no faster than v; in velocity mode (3) it takes v
// on 0x200 + id and turns at v; each frame is answered with a feedback frame. A frame of another
// mode than the motor's is not its own: no answer, no motion (an MIT frame in mode 2, a velocity
// frame in MIT mode). CTRL_MODE is written through 0x7FF while the motor is disabled.
TEST(MitGroup, DamiaoPositionVelocityAndVelocityModesOnTheVirtualMotor) {
  ManualClock clock;
  sim::MitPlant plant(clock, motors(1, 2));
  CanBus& bus = plant.master_bus();
  auto exchange = [&](const CanFrame& f) {  // one frame, 1 ms, the answers counted
    bus.send(f);
    clock.advance(kMillisecond);
    plant.step(clock.now());
    int n = 0;
    CanFrame in;
    while (bus.receive(in, 0) == Status::ok) ++n;
    return n;
  };
  LONGS_EQUAL(1, exchange(mit::special_frame(1, mit::Special::enable)));
  CanFrame f;
  mit::pack_command(mit::ranges_of(j4340()), 1, {1.0, 0, 30, 1, 0}, f);
  LONGS_EQUAL(0, exchange(f));  // an MIT frame in position-velocity mode
  double peak = 0;
  int answered = 0;
  for (int i = 0; i < 1500; ++i) {
    CHECK(mit::pack_pos_vel(1, 1.0, 2.0, f));
    answered += exchange(f);
    peak = std::fmax(peak, std::fabs(plant.at(0).velocity()));
  }
  std::printf("\n  virtual DM-J4340 in position-velocity mode: to 1.0 rad at most 2.0 rad/s: at %.4f rad, peak %.3f rad/s\n",
              plant.at(0).position(), peak);
  LONGS_EQUAL(1500, answered);
  DOUBLES_EQUAL(1.0, plant.at(0).position(), 2e-3);
  CHECK(peak > 1.9 && peak < 2.05);
  CHECK(mit::pack_vel(1, -3.0, f));
  LONGS_EQUAL(0, exchange(f));  // a velocity frame in position-velocity mode
  // velocity mode: CTRL_MODE = 3 while disabled, then enable
  LONGS_EQUAL(1, exchange(mit::special_frame(1, mit::Special::disable)));
  LONGS_EQUAL(1, exchange(mit::reg_write_u32(1, static_cast<std::uint8_t>(mit::Reg::ctrl_mode), 3)));
  UNSIGNED_LONGS_EQUAL(3, plant.at(0).reg(mit::Reg::ctrl_mode));
  LONGS_EQUAL(1, exchange(mit::special_frame(1, mit::Special::enable)));
  answered = 0;
  for (int i = 0; i < 500; ++i) answered += exchange(f);
  LONGS_EQUAL(500, answered);
  DOUBLES_EQUAL(-3.0, plant.at(0).velocity(), 0.05);
  CHECK(mit::pack_pos_vel(1, 1.0, 2.0, f));
  LONGS_EQUAL(0, exchange(f));  // a position-velocity frame in velocity mode
}
