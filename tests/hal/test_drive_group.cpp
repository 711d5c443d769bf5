// SPDX-License-Identifier: Apache-2.0
// The drive-neutral group base (hal/drive_group.hpp): hard-stop homing on a family that is not
// CANopen — a fake group whose joints follow their setpoints with a first-order lag and stop
// at a mechanical end stop — and the arm-level composite over groups (arm_servo_bus.hpp).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "alloc_counter.hpp"
#include "servoarm/hal/arm_servo_bus.hpp"
#include "servoarm/hal/drive_group.hpp"
#include "sim_fixture.hpp"

// CppUTest last: its leak detector redefines `new`.
#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::hal;

namespace {

constexpr Duration kPeriod = kMillisecond;
constexpr double kQuantum = 1e-5;  // rad per count of the fake drive

/// Joints that follow their setpoint with a first-order lag (20 ms), quantised to kQuantum, a
/// mechanical stop below `stop`; no protocol at all. Zero: an offset in joint units.
class FakeGroup final : public DriveGroup {
 public:
  explicit FakeGroup(std::size_t n) : n_(n) {}
  std::size_t joint_count() const override { return n_; }
  void enable() override { enabled_ = true; }
  void disable() override { enabled_ = false; }
  const JointFeedback& feedback(std::size_t j) const override { return fb_[j]; }
  const char* last_error() const override { return error_; }
  const char* family() const override { return "fake"; }
  Status config_status() const override { return Status::ok; }
  JointScaling scaling(std::size_t) const override { return {}; }

  HomingSpec spec[kMaxServoJoints]{};
  double physical[kMaxServoJoints]{};  ///< where the shaft is
  double stop = -1e9;                  ///< the end stop (physical), blocking downwards
  double zero[kMaxServoJoints]{};      ///< joint = physical - zero

 protected:
  const HomingSpec& homing_spec(std::size_t j) const override { return spec[j]; }
  Status family_start(TimePoint) override { return Status::ok; }
  Status family_read(TimePoint now) override {
    for (std::size_t j = 0; j < n_; ++j) {
      JointFeedback& f = fb_[j];
      f.position = std::round(physical[j] / kQuantum) * kQuantum - zero[j];
      f.valid = true;
      f.last_feedback = f.sampled = now;
      f.state = enabled_ ? JointState::enabled : JointState::disabled;
    }
    return Status::ok;
  }
  Status family_write(std::span<const double> sp, TimePoint) override {
    if (sp.size() != n_) return Status::invalid_argument;
    for (std::size_t j = 0; j < n_; ++j) {
      if (!enabled_) continue;
      const double target = sp[j] + zero[j];
      physical[j] += (target - physical[j]) * (1.0 - std::exp(-1e-3 / 0.02));
      physical[j] = std::max(physical[j], stop);
    }
    return Status::ok;
  }
  double shift_zero(std::size_t j, double at, double reads) override {
    zero[j] += at - reads;
    fb_[j].position -= at - reads;
    return reads;
  }
  double resolution(std::size_t) const override { return kQuantum; }
  void note_error(const char* text) override { std::snprintf(error_, sizeof error_, "%s", text); }

 private:
  std::size_t n_;
  bool enabled_ = false;
  JointFeedback fb_[kMaxServoJoints]{};
  char error_[192] = {};
};

HomingSpec hard_stop_spec() {
  HomingSpec h;
  h.kind = HomingKind::hard_stop;
  h.speed_switch = -0.5;  // rad/s, towards the stop
  h.acceleration = 5;
  h.following_limit = 0.01;
  h.backoff = 0.05;
  h.offset = -1.0;
  h.timeout = 10 * kSecond;
  return h;
}

/// One cycle as the controller runs it: read, setpoints = the positions held, write.
void cycle(ServoBus& bus, TimePoint now) {
  double sp[kMaxServoJoints];
  bus.read(now);
  for (std::size_t j = 0; j < bus.joint_count(); ++j) sp[j] = bus.feedback(j).position;
  bus.write(std::span<const double>(sp, bus.joint_count()), now);
}

}  // namespace

TEST_GROUP(DriveGroup){};

// Hard stop on a family without CANopen: the group base ramps the joint to the stop, sees the
// following error, backs off and has the family move its zero so the joint reads the offset.
TEST(DriveGroup, HardStopHomingRunsOnAFamilyThatIsNotCanopen) {
  FakeGroup g(2);
  g.spec[1] = hard_stop_spec();
  g.stop = -0.3;
  TimePoint now = kSecond;
  LONGS_EQUAL(int(Status::ok), int(g.start(now)));
  g.enable();
  cycle(g, now);
  LONGS_EQUAL(int(HomingKind::hard_stop), int(g.homing_kind(1)));
  LONGS_EQUAL(int(HomingPhase::idle), int(g.homing(1).phase));
  LONGS_EQUAL(int(Status::ok), int(g.start_homing(1, now)));
  LONGS_EQUAL(int(Status::bad_state), int(g.start_homing(1, now)));  // already homing
  std::size_t allocs = 0;
  int cycles = 0;
  double peak_speed = 0, prev = g.physical[1];
  while (g.homing(1).phase == HomingPhase::running && cycles < 20000) {
    now += kPeriod;
    test::AllocScope scope;
    cycle(g, now);
    allocs += scope.end();
    peak_speed = std::max(peak_speed, std::fabs(g.physical[1] - prev) / 1e-3);
    prev = g.physical[1];
    ++cycles;
  }
  char msg[192];
  g.describe_homing(1, msg, sizeof msg);
  STRCMP_EQUAL("", msg);
  LONGS_EQUAL(int(HomingPhase::attained), int(g.homing(1).phase));
  LONGS_EQUAL(0, allocs);
  CHECK(peak_speed <= 0.5 * 1.05);
  for (int k = 0; k < 200; ++k) now += kPeriod, cycle(g, now);
  // The shaft rests backed off from the stop; the joint reads the offset there.
  DOUBLES_EQUAL(-0.3 + 0.05, g.physical[1], 3 * kQuantum);
  DOUBLES_EQUAL(-1.0, g.feedback(1).position, 3 * kQuantum);
  DOUBLES_EQUAL(0.0, g.physical[0], 1e-12);  // the other joint held
  std::printf("\n  fake family hard stop: %.3f s, %.2f quanta from stop + backoff\n", cycles * 1e-3,
              (g.physical[1] - (-0.3 + 0.05)) / kQuantum);
  // start() makes it unhomed again
  LONGS_EQUAL(int(Status::ok), int(g.start(now)));
  LONGS_EQUAL(int(HomingPhase::idle), int(g.homing(1).phase));
}

// No stop within reach: the homing fails at its timeout naming the joint, the joint holds.
TEST(DriveGroup, HardStopTimeoutOnAFamilyThatIsNotCanopenNamesTheJoint) {
  FakeGroup g(1);
  g.spec[0] = hard_stop_spec();
  g.spec[0].timeout = 500 * kMillisecond;
  TimePoint now = kSecond;
  g.start(now);
  g.enable();
  cycle(g, now);
  LONGS_EQUAL(int(Status::ok), int(g.start_homing(0, now)));
  for (int k = 0; k < 700; ++k) now += kPeriod, cycle(g, now);
  LONGS_EQUAL(int(HomingPhase::failed), int(g.homing(0).phase));
  LONGS_EQUAL(int(Status::timeout), int(g.homing(0).status));
  char msg[192];
  g.describe_homing(0, msg, sizeof msg);
  STRCMP_CONTAINS("joint 0: homing timeout after 500 ms approaching the hard stop", msg);
  STRCMP_EQUAL(msg, g.last_error());
  const double p = g.physical[0];
  for (int k = 0; k < 100; ++k) now += kPeriod, cycle(g, now);
  DOUBLES_EQUAL(p, g.physical[0], 2 * kQuantum);
}

// One arm of two families: joints 0-1 CiA 402 virtual drives on the in-process bus, joint 2 the
// fake family, hard stop, as arm joint 2. The composite drives all three; the hard stop runs in
// the fake group's base; the CANopen joints hold; a failure names the arm's joint.
TEST(DriveGroup, AnArmOfTwoFamiliesHomesTheNonCanopenJointByHardStop) {
  for (const bool reachable : {true, false}) {
    test::SimRig rig({1, 2});
    auto can = std::make_unique<CanopenServoBus>(*rig.master_ep, rig.clock, CanopenMasterConfig::consecutive(1, 2));
    auto fake = std::make_unique<FakeGroup>(1);
    FakeGroup& f = *fake;
    f.spec[0] = hard_stop_spec();
    if (reachable) f.stop = -0.3;
    else f.spec[0].timeout = 300 * kMillisecond;
    ArmServoBus arm;
    const std::size_t can_joints[] = {0, 1}, fake_joints[] = {2};
    LONGS_EQUAL(int(Status::ok), int(arm.add_group(std::move(can), can_joints)));
    LONGS_EQUAL(int(Status::ok), int(arm.add_group(std::move(fake), fake_joints)));
    LONGS_EQUAL(int(Status::ok), int(arm.config_status()));
    LONGS_EQUAL(3, long(arm.joint_count()));
    STRCMP_EQUAL("fake", arm.group(arm.slot(2).group).family());
    LONGS_EQUAL(int(Status::ok), int(arm.start(rig.clock.now() + 5 * kSecond)));
    arm.enable();
    for (int k = 0; k < 300; ++k) cycle(arm, rig.clock.now()), rig.clock.advance(kPeriod);
    for (std::size_t j = 0; j < 3; ++j) LONGS_EQUAL(int(JointState::enabled), int(arm.feedback(j).state));
    LONGS_EQUAL(int(HomingKind::hard_stop), int(arm.homing_kind(2)));
    LONGS_EQUAL(int(Status::ok), int(arm.start_homing(2, rig.clock.now())));
    const double p0 = rig.sim->at(0).physical_position(), p1 = rig.sim->at(1).physical_position();
    std::size_t allocs = 0;
    for (int k = 0; k < 5000 && arm.homing(2).phase == HomingPhase::running; ++k) {
      test::AllocScope scope;
      cycle(arm, rig.clock.now());
      allocs += scope.end();
      rig.clock.advance(kPeriod);
    }
    LONGS_EQUAL(0, allocs);
    char msg[192];
    arm.describe_homing(2, msg, sizeof msg);
    if (reachable) {
      STRCMP_EQUAL("", msg);
      LONGS_EQUAL(int(HomingPhase::attained), int(arm.homing(2).phase));
      for (int k = 0; k < 100; ++k) cycle(arm, rig.clock.now()), rig.clock.advance(kPeriod);
      DOUBLES_EQUAL(-0.3 + 0.05, f.physical[0], 3 * kQuantum);
      DOUBLES_EQUAL(-1.0, arm.feedback(2).position, 3 * kQuantum);
    } else {
      LONGS_EQUAL(int(HomingPhase::failed), int(arm.homing(2).phase));
      STRCMP_CONTAINS("joint 2: homing timeout after 300 ms approaching the hard stop", msg);
    }
    DOUBLES_EQUAL(p0, rig.sim->at(0).physical_position(), 1.0);  // the CiA 402 joints held
    DOUBLES_EQUAL(p1, rig.sim->at(1).physical_position(), 1.0);
  }
}
