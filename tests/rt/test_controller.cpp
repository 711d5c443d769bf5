// SPDX-License-Identifier: Apache-2.0
// Controller + console in-process: puma560 on the sim bus with virtual CiA 402
// drives, single-threaded on a ManualClock (deterministic: the clock's idle
// hook steps the drives). Every control cycle runs inside an allocation
// counter. Last group: the real RT thread (RtLoop) on CLOCK_MONOTONIC.
#include <fcntl.h>
#include <poll.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <cstdio>
#include <string>
#include <thread>
#include <vector>

#include "alloc_counter.hpp"
#include "sim_app.hpp"
#include "sweep.hpp"
#include "servoarm/rt/rt_loop.hpp"
#include "servoarm/console/transport.hpp"
#include "servoarm/hal/can_frame.hpp"
#include "servoarm/kinematics/orientation.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;

namespace {

constexpr double kDeg = M_PI / 180.0;

struct Rig {
  hal::ManualClock clock;
  test::SimApp app;
  Session s;
  hal::Duration period = hal::kMillisecond;
  std::size_t rt_allocs = 0;
  std::uint64_t cycles = 0;

  explicit Rig(const sim::MotorParams& motor = {}, FwConfig cfg = {}) {
    cfg.can = "sim";
    app.sim_motor = motor;
    const std::string e = app.build(cfg, &clock);
    if (!e.empty()) FAIL(e.c_str());
    period = static_cast<hal::Duration>(1e9 / cfg.rate_hz);
    clock.set_idle_hook([this](hal::TimePoint t) { app.plant->step(t); });
    const std::string b = app.boot();
    if (!b.empty()) FAIL(b.c_str());
    app.console->set_idle([this] { cycle(); });
  }
  ~Rig() { clock.set_idle_hook(nullptr); }

  void cycle() {
    test::alloc_count_begin();
    app.ctl->cycle(clock.now());
    rt_allocs += test::alloc_count_end();
    ++cycles;
    clock.advance(period);
  }
  void run(double secs) {
    const auto n = static_cast<int>(secs * 1e9 / static_cast<double>(period));
    for (int i = 0; i < n; ++i) {
      cycle();
      app.console->poll(s);
    }
  }
  /// Execute a line and run cycles until the answer is complete (bounded).
  std::string cmd(const std::string& line) {
    s.out.clear();
    app.console->execute(s, line);
    for (int i = 0; i < 60000 && app.console->busy(s); ++i) {
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
  Telemetry tel() const { return app.ctl->telemetry(); }
  kin::JointVector q_act() const {
    const Telemetry t = tel();
    kin::JointVector q(6);
    for (int j = 0; j < 6; ++j) q[j] = t.q_act[static_cast<std::size_t>(j)];
    return q;
  }
  kin::JointVector q_cmd() const {
    const Telemetry t = tel();
    kin::JointVector q(6);
    for (int j = 0; j < 6; ++j) q[j] = t.q_cmd[static_cast<std::size_t>(j)];
    return q;
  }
  /// Some drive still powered (enabling, enabled, or stopping: on its way down / quick stop
  /// active with speed).
  bool any_powered() const {
    const Telemetry t = tel();
    for (int j = 0; j < 6; ++j)
      if (t.joint_state[std::size_t(j)] == std::uint8_t(hal::JointState::enabling) ||
          t.joint_state[std::size_t(j)] == std::uint8_t(hal::JointState::enabled) ||
          t.joint_state[std::size_t(j)] == std::uint8_t(hal::JointState::stopping))
        return true;
    return false;
  }
  void enable() {
    const std::string a = cmd("enable");
    if (a.rfind("ok", 0) != 0) FAIL(("enable: " + a).c_str());
    for (int i = 0; i < 2000 && tel().state == ArmState::enabling; ++i) cycle();
    if (tel().state != ArmState::idle)
      FAIL((std::string("not idle after enable: ") + to_string(tel().state) + " " + tel().fault_text).c_str());
  }
};

bool is_ok(const std::string& a) {
  // The final line of the answer starts with "ok".
  if (a.empty() || a.back() != '\n') return false;
  const auto p = a.rfind('\n', a.size() - 2);
  const std::string last = a.substr(p == std::string::npos ? 0 : p + 1);
  return last.rfind("ok", 0) == 0;
}
bool is_error(const std::string& a) { return a.rfind("error: ", 0) == 0 && a.find('\n') == a.size() - 1; }

double max_abs_diff(const kin::JointVector& a, const kin::JointVector& b) { return (a - b).cwiseAbs().maxCoeff(); }

}  // namespace

TEST_GROUP(Controller){};

TEST(Controller, BootsDisabledAndEnables) {
  Rig r;
  CHECK(r.tel().state == ArmState::disabled);
  CHECK(is_error(r.cmd("movej 0 0 0 0 0 0")));  // not enabled: refused
  r.enable();
  LONGS_EQUAL(0, r.rt_allocs);
}

TEST(Controller, MovejReachesTarget) {
  Rig r;
  r.enable();
  const std::string a = r.cmd("movej 10 -20 30 5 20 -15 speed=100");
  CHECK_TEXT(is_ok(a), a.c_str());
  CHECK(is_ok(r.cmd("wait")));
  r.run(0.05);
  kin::JointVector goal(6);
  goal << 10, -20, 30, 5, 20, -15;
  goal *= kDeg;
  CHECK(r.tel().state == ArmState::idle);
  CHECK(max_abs_diff(r.q_act(), goal) < 0.02 * kDeg);
  CHECK(max_abs_diff(r.q_cmd(), goal) < 1e-12);
  LONGS_EQUAL(0, r.rt_allocs);
}

TEST(Controller, MovelAndGcodeReachTargetsOnTheLine) {
  Rig r;
  r.enable();
  CHECK(is_ok(r.cmd("movej 20 -40 160 10 -50 30")));
  CHECK(is_ok(r.cmd("wait")));
  kin::Pose p0;
  kin::forward(r.app.chain, r.q_cmd(), p0);
  const Eigen::Vector3d c = p0.translation() * 1e3;
  char line[128];
  std::snprintf(line, sizeof line, "movel %.3f %.3f %.3f speed=200", c.x() + 60, c.y() - 30, c.z() + 20);
  const std::string a = r.cmd(line);
  CHECK_TEXT(is_ok(a), a.c_str());
  // Sample the path while moving: every commanded tool point on the segment.
  const Eigen::Vector3d target = (c + Eigen::Vector3d(60, -30, 20)) * 1e-3;
  const Eigen::Vector3d dir = (target - p0.translation()).normalized();
  double worst = 0;
  for (int i = 0; i < 4000 && !r.app.ctl->motions().empty(); ++i) {
    r.cycle();
    kin::Pose x;
    kin::forward(r.app.chain, r.q_cmd(), x);
    const Eigen::Vector3d d = x.translation() - p0.translation();
    worst = std::fmax(worst, (d - d.dot(dir) * dir).norm());
  }
  CHECK(r.tel().state == ArmState::idle);
  CHECK_TEXT(worst < 1e-6, std::to_string(worst).c_str());
  r.run(0.05);
  kin::Pose x;
  kin::forward(r.app.chain, r.q_act(), x);
  CHECK_TEXT((x.translation() - target).norm() < 0.3e-3, std::to_string((x.translation() - target).norm()).c_str());
  // Orientation kept.
  CHECK(kin::rotation_error(x.linear(), p0.linear()).norm() < 1e-3);
  // G-code relative move from there.
  CHECK(is_ok(r.cmd("G91")));
  CHECK(is_ok(r.cmd("G1 Z-25 F3000")));
  CHECK(is_ok(r.cmd("G90")));
  CHECK(is_ok(r.cmd("M400")));
  r.run(0.05);
  kin::forward(r.app.chain, r.q_act(), x);
  CHECK((x.translation() - (target + Eigen::Vector3d(0, 0, -0.025))).norm() < 0.3e-3);
  const std::string m114 = r.cmd("M114");
  CHECK_TEXT(m114.rfind("X:", 0) == 0 && is_ok(m114), m114.c_str());
  LONGS_EQUAL(0, r.rt_allocs);
}

TEST(Controller, GoodCommandsAnswerOk) {
  Rig r;
  r.enable();
  const char* lines[] = {"help", "help movej", "status", "fk", "fk 0 10 20 0 30 0", "ik 500 150 300", "limits", "stats",
                         "config", "wait", "stop", "hold", "resume", "reset", "G21", "G90", "M105", "M110 N0", "M114",
                         "M400", "", "# comment", "G1 F600"};
  for (const char* l : lines) {
    const std::string a = r.cmd(l);
    if (!is_ok(a)) FAIL((std::string("'") + l + "' answered: " + a).c_str());
  }
  CHECK(r.tel().state == ArmState::idle);
}

TEST(Controller, MalformedAndRefusedCommandsAnswerErrorAndNothingMoves) {
  Rig r;
  r.enable();
  CHECK(is_ok(r.cmd("movej 10 -30 150 0 -40 0")));
  CHECK(is_ok(r.cmd("wait")));
  const kin::JointVector q0 = r.q_cmd();
  const std::string overlong = "movej " + std::string(400, '9');
  const std::string binary = std::string("movej 0 0\x01 0 0 0 0");
  const std::string garbage = "\xde\xad\xbe\xef";
  const char* bad[] = {
      "movej 0 0 0 0 0",                 // too few
      "movej 0 0 0 0 0 0 0",             // too many
      "movej 0 0 0 0 0 nan",             // NaN
      "movej 0 0 0 0 0 inf",
      "movej 500 0 0 0 0 0",             // outside joint 1 limits
      "movej 0 0 0 0 0 0 speed=0",
      "movel 5000 0 0",                  // unreachable
      "movel 1 2",                       // wrong count
      "movel 500 100 300 speed=99999",   // faster than max_linear_speed
      "movel nan 0 0",
      "ik 5000 0 0",                     // unreachable
      "frobnicate",
      "G1 X5000",                        // unreachable
      "G2 X1 Y1",                        // unsupported
      "G1 Xnan",
      "G4",
      "M999",
      "N3 G1 X1*0",                      // checksum
      "status 1",
      overlong.c_str(),
      binary.c_str(),
      garbage.c_str(),
  };
  for (const char* l : bad) {
    const std::string a = r.cmd(l);
    if (!is_error(a)) FAIL((std::string("'") + l + "' answered: " + a).c_str());
    r.run(0.01);
    CHECK(r.app.ctl->motions().empty());
    CHECK(r.tel().state == ArmState::idle);
    if (max_abs_diff(r.q_cmd(), q0) != 0) FAIL((std::string("'") + l + "' moved the arm").c_str());
  }
  // Overlong lines arriving byte by byte through feed(): one error, the next line works.
  std::string bytes(1000, 'a');
  bytes += "\nstatus\n";
  const std::string a = r.feed(bytes);
  CHECK_TEXT(a.rfind("error: overlong", 0) == 0, a.c_str());
  CHECK_TEXT(a.find("\nok state=idle") != std::string::npos, a.c_str());
  LONGS_EQUAL(0, r.rt_allocs);
}

TEST(Controller, FeedHoldAndResumeJointAndLinear) {
  Rig r;
  r.enable();
  CHECK(is_ok(r.cmd("movej 40 -40 120 30 -40 60 speed=40")));
  r.run(0.6);
  CHECK(r.tel().state == ArmState::moving);
  r.feed("!");
  r.run(0.5);
  const Telemetry held = r.tel();
  CHECK(held.holding);
  const kin::JointVector qh = r.q_cmd();
  r.run(0.2);
  CHECK(max_abs_diff(r.q_cmd(), qh) == 0);  // at rest while held
  const std::string rep = r.feed("?");
  CHECK_TEXT(rep.rfind("<Hold|", 0) == 0, rep.c_str());
  r.feed("~");
  CHECK(is_ok(r.cmd("wait")));
  kin::JointVector goal(6);
  goal << 40, -40, 120, 30, -40, 60;
  CHECK(max_abs_diff(r.q_cmd(), goal * kDeg) < 1e-12);
  // Linear: hold stops on the line, resume finishes it.
  kin::Pose p0;
  kin::forward(r.app.chain, r.q_cmd(), p0);
  const Eigen::Vector3d c = p0.translation() * 1e3;
  char line[128];
  std::snprintf(line, sizeof line, "movel %.3f %.3f %.3f speed=50", c.x() - 80, c.y(), c.z());
  CHECK(is_ok(r.cmd(line)));
  r.run(0.5);
  r.feed("!");
  r.run(0.6);
  kin::Pose x;
  kin::forward(r.app.chain, r.q_cmd(), x);
  CHECK(std::fabs(x.translation().y() - p0.translation().y()) < 1e-6);
  CHECK(x.translation().x() < p0.translation().x() - 0.005);
  CHECK(x.translation().x() > p0.translation().x() - 0.075);
  r.feed("~");
  CHECK(is_ok(r.cmd("wait")));
  kin::forward(r.app.chain, r.q_cmd(), x);
  CHECK((x.translation() - (c + Eigen::Vector3d(-80, 0, 0)) * 1e-3).norm() < 1e-6);
  LONGS_EQUAL(0, r.rt_allocs);
}

TEST(Controller, EstopFromEveryState) {
  // both e-stop reactions: the controller's ramp (default) and the drives' CiA 402 quick stop
  for (int k = 0; k < 10; ++k) {
    const int which = k % 5;
    FwConfig cfg;
    cfg.stop = k < 5 ? "ramp" : "drive";
    Rig r({}, cfg);
    const char* name = "";
    switch (which) {
      case 0: name = "disabled"; break;
      case 1: name = "idle"; r.enable(); break;
      case 2:
        name = "moving";
        r.enable();
        CHECK(is_ok(r.cmd("movej 60 -60 100 0 30 0 speed=100")));
        r.run(0.4);
        break;
      case 3:
        name = "stopping";
        r.enable();
        CHECK(is_ok(r.cmd("movej 60 -60 100 0 30 0 speed=100")));
        r.run(0.4);
        r.app.ctl->requests().push(Request{RequestOp::stop, 999});
        r.cycle();
        CHECK(r.tel().state == ArmState::stopping);
        break;
      case 4:
        name = "fault";
        r.enable();
        r.app.plant->inject_silent(1);
        r.run(0.4);
        CHECK(r.tel().state == ArmState::fault);
        break;
    }
    // Ctrl-X through the byte stream: acts in the next cycle.
    r.app.ctl->requests().push(Request{RequestOp::estop, 1000});
    r.cycle();
    if (r.tel().state != ArmState::estop)
      FAIL((std::string("estop (") + cfg.stop + ") from " + name + " gave " + to_string(r.tel().state)).c_str());
    const kin::JointVector q_after_first = r.q_cmd();
    r.run(1.0);
    // At rest, drives powered down, queue empty.
    const kin::JointVector qr = r.q_cmd();
    r.run(0.1);
    CHECK(max_abs_diff(r.q_cmd(), qr) < 1e-3 * kDeg);
    CHECK(r.app.ctl->motions().empty());
    for (int j = 0; j < 6; ++j) CHECK(r.app.servo->feedback(static_cast<std::size_t>(j)).state != hal::JointState::enabled);
    (void)q_after_first;
    // Nothing moves until reset + enable.
    CHECK(is_error(r.cmd("movej 0 0 0 0 0 0")));
    CHECK(is_error(r.cmd("enable")));
    CHECK(is_error(r.cmd("park")));
    if (which == 4) continue;  // the silent drive stays silent: enable would fault again
    CHECK(is_ok(r.cmd("reset")));
    CHECK(r.tel().state == ArmState::disabled);
    r.enable();
    CHECK(is_ok(r.cmd("park")));
    CHECK(is_ok(r.cmd("wait")));
    LONGS_EQUAL(0, r.rt_allocs);
  }
}

namespace {
// Controlwords of the RPDOs (0x201..0x206) the spy saw, per node, consecutive repeats collapsed.
void collect_controlwords(hal::SimBusEndpoint& spy, std::vector<std::uint16_t> (&cws)[6]) {
  hal::CanFrame f;
  while (spy.receive(f, 0) == hal::Status::ok) {
    if (f.id < 0x201 || f.id > 0x206 || f.len < 2) continue;
    auto& v = cws[f.id - 0x201];
    const std::uint16_t cw = hal::get_u16(f.data.data());
    if (v.empty() || v.back() != cw) v.push_back(cw);
  }
}
std::string cw_text(const std::vector<std::uint16_t>& v) {
  std::string t;
  char b[8];
  for (std::uint16_t c : v) {
    std::snprintf(b, sizeof b, "%04X ", c);
    t += b;
  }
  return t;
}
}  // namespace

// safety.stop = "drive": an e-stop during a fast joint move sends the CiA 402
// Quick Stop command (controlword 0x0002) to every drive in the next cycle; the
// (virtual) drives ramp down on their own -- the arm keeps moving for a while,
// it does not freeze -- and once every drive reports rest the controller powers
// them down (controlword 0x0000, disable voltage). Nothing moves again until
// reset + enable, and the control cycle allocates nothing on the way.
TEST(Controller, DriveQuickStopSendsCia402QuickStopThenPowersDownAtRest) {
  FwConfig cfg;
  cfg.stop = "drive";
  // drives that decelerate at 4 rev/s^2 (twice the joints' 4 pi rad/s^2 limit; the
  // default virtual motor's 400 rev/s^2 would stop within 2-3 cycles)
  sim::MotorParams motor;
  motor.max_accel = 4.0 * 131072;
  Rig r(motor, cfg);
  auto spy = r.app.plant->bus().open(16384);
  r.enable();
  CHECK(is_ok(r.cmd("movej 60 -60 100 0 30 0 speed=100")));
  r.run(0.4);
  CHECK(r.tel().state == ArmState::moving);
  std::vector<std::uint16_t> before[6];
  collect_controlwords(*spy, before);
  for (int j = 0; j < 6; ++j) CHECK_EQUAL(0x000F, before[j].back());  // enable operation while moving
  const kin::JointVector q_estop = r.q_act();
  r.app.ctl->requests().push(Request{RequestOp::estop, 77});
  r.cycle();
  CHECK(r.tel().state == ArmState::estop);
  std::vector<std::uint16_t> cws[6];
  collect_controlwords(*spy, cws);
  for (int j = 0; j < 6; ++j) {
    const std::string t = cw_text(cws[j]);
    CHECK_TEXT(cws[j].size() == 1 && cws[j][0] == 0x0002, ("node " + std::to_string(j + 1) + ": " + t).c_str());
  }
  // the drives ramp down on their own; the power-down follows when all are at rest
  int n = 0;
  while (r.any_powered() && n < 3000) {
    r.cycle();
    collect_controlwords(*spy, cws);
    ++n;
  }
  const double t_stop = n * 1e-3;
  CHECK_TEXT(!r.any_powered(), "drives still powered 3 s after the quick stop");
  // it took the drives' deceleration (the fastest joint was at speed: v / 8 pi rad/s^2),
  // not one cycle, and not the 2 s timeout either
  CHECK_TEXT(t_stop > 0.02 && t_stop < 1.0, std::to_string(t_stop).c_str());
  const kin::JointVector q_rest = r.q_act();
  CHECK_TEXT(max_abs_diff(q_rest, q_estop) > 0.01 * kDeg, "the arm froze instead of ramping down");
  r.run(0.2);
  collect_controlwords(*spy, cws);
  CHECK(max_abs_diff(r.q_act(), q_rest) < 0.001 * kDeg);
  for (int j = 0; j < 6; ++j) {
    const std::string t = cw_text(cws[j]);
    CHECK_TEXT(t == "0002 0000 ", ("node " + std::to_string(j + 1) + ": " + t).c_str());
  }
  std::printf("\n[drive quick stop] moving at speed -> all drives at rest and powered down in %.3f s\n", t_stop);
  CHECK(is_error(r.cmd("movej 0 0 0 0 0 0")));
  CHECK(is_ok(r.cmd("reset")));
  r.enable();
  CHECK(is_ok(r.cmd("movej 10 -10 20 0 10 0 speed=100")));
  CHECK(is_ok(r.cmd("wait")));
  kin::JointVector goal(6);
  goal << 10, -10, 20, 0, 10, 0;
  CHECK(max_abs_diff(r.q_act(), goal * kDeg) < 0.1 * kDeg);
  LONGS_EQUAL(0, r.rt_allocs);
}

// drive.quick_stop_decel: armfw writes the drives' 6085h at bring-up (joint
// deg/s^2 -> motor counts/s^2), and the virtual drives stop on it: the time
// from the Quick Stop command to rest is the fastest joint's speed over that
// deceleration (here 180 deg/s^2 = 0.5 motor rev/s^2, far below the motor's
// own 400 rev/s^2).
TEST(Controller, DriveQuickStopUsesTheConfiguredDeceleration) {
  FwConfig cfg;
  cfg.stop = "drive";
  DriveConfig d;
  d.quick_stop_decel = 180;
  cfg.drives.assign(6, d);
  cfg.drives[2].quick_stop_decel = 360;  // a drive of its own: twice as fast
  Rig r({}, cfg);
  for (int j = 0; j < 6; ++j) {
    std::uint32_t v = 0;
    CHECK(r.app.plant->arm().at(std::size_t(j)).od_read(0x6085, 0, v));
    LONGS_EQUAL(j == 2 ? 131072 : 65536, v);
  }
  r.enable();
  CHECK(is_ok(r.cmd("movej 150 -150 150 0 30 0 speed=60")));
  r.run(0.7);
  CHECK(r.tel().state == ArmState::moving);
  r.app.ctl->requests().push(Request{RequestOp::estop, 78});
  r.cycle();
  // Each drive's speed when it took the Quick Stop (its 606Ch; the virtual
  // drive's position loop makes it vary within a cycle): the slowest to stop
  // sets the time, |v| / 6085h.
  double t_expect = 0;
  for (int j = 0; j < 6; ++j) {
    std::uint32_t vel = 0;
    CHECK(r.app.plant->arm().at(std::size_t(j)).od_read(0x606C, 0, vel));
    t_expect = std::max(t_expect, std::abs(double(std::int32_t(vel))) / (j == 2 ? 131072.0 : 65536.0));
  }
  CHECK(t_expect > 0.2);
  int n = 0;
  while (r.any_powered() && n < 5000) {
    r.cycle();
    ++n;
  }
  const double t_stop = n * 1e-3;
  std::printf("\n[drive quick stop, 6085h from the config] at rest and powered down in %.3f s, expected %.3f s\n", t_stop,
              t_expect);
  CHECK_TEXT(t_stop > 0.97 * t_expect && t_stop < 1.03 * t_expect + 0.005,
             (std::to_string(t_stop) + " s, expected " + std::to_string(t_expect)).c_str());
  LONGS_EQUAL(0, r.rt_allocs);
}

// safety.stop = "drive" and a fault: a silent drive (joint 3) during a move; the
// fault reaction is the Quick Stop command to the drives still on the bus.
TEST(Controller, DriveQuickStopIsTheFaultReaction) {
  FwConfig cfg;
  cfg.stop = "drive";
  Rig r({}, cfg);
  auto spy = r.app.plant->bus().open(16384);
  r.enable();
  CHECK(is_ok(r.cmd("movej 30 -30 60 0 30 0 speed=50")));
  r.run(0.3);
  std::vector<std::uint16_t> cws[6];
  collect_controlwords(*spy, cws);
  for (auto& v : cws) v.clear();
  r.app.plant->inject_silent(2);
  int n = 0;
  while (r.tel().state != ArmState::fault && n < 1000) {
    r.cycle();
    ++n;
  }
  CHECK_TEXT(std::string(r.tel().fault_text).find("joint 3 ") == 0, r.tel().fault_text);
  r.run(1.0);
  collect_controlwords(*spy, cws);
  for (int j = 0; j < 6; ++j) {
    const std::string t = cw_text(cws[j]);
    // joint 3's RPDOs are still sent (its drive just does not listen); its last known
    // state is operation enabled, so the power-down there starts with "disable operation"
    const bool ok = j == 2 ? t.rfind("000F 0002 ", 0) == 0 : t == "000F 0002 0000 ";
    CHECK_TEXT(ok, ("node " + std::to_string(j + 1) + ": " + t).c_str());
  }
  const kin::JointVector q1 = r.q_cmd();
  r.run(0.1);
  CHECK(max_abs_diff(r.q_cmd(), q1) < 1e-9);
  LONGS_EQUAL(0, r.rt_allocs);
}

TEST(Controller, CtrlXIsEstopAndDropsThePartialLine) {
  Rig r;
  r.enable();
  const std::string a = r.feed(std::string("movej 1 2") + '\x18' + "\n");
  r.cycle();
  CHECK(r.tel().state == ArmState::estop);
  // The partial line was dropped: the newline gives an empty line (ok), not a movej error.
  CHECK_TEXT(a.find("arg_count") == std::string::npos, a.c_str());
  const std::string ev = r.app.console->drain_events();
  CHECK_TEXT(ev.find("alarm: estop") != std::string::npos, ev.c_str());
}

TEST(Controller, SilentNodeStopsTheArmWithinHeartbeatTimeoutNamingTheJoint) {
  Rig r;
  r.enable();
  CHECK(is_ok(r.cmd("movej 30 -30 60 0 30 0 speed=50")));
  r.run(0.3);
  r.app.plant->inject_silent(2);
  const hal::TimePoint t0 = r.clock.now();
  int n = 0;
  while (r.tel().state != ArmState::fault && n < 1000) {
    r.cycle();
    ++n;
  }
  CHECK_TEXT(r.tel().state == ArmState::fault, r.tel().fault_text);
  // Within heartbeat_timeout (150 ms) + 2 cycles (stale feedback is usually seen first).
  const double dt = static_cast<double>(r.clock.now() - t0) * 1e-9;
  CHECK_TEXT(dt <= 0.150 + 0.002 + 1e-9, std::to_string(dt).c_str());
  const Telemetry t = r.tel();
  LONGS_EQUAL(2, t.fault_joint);
  CHECK_TEXT(std::string(t.fault_text).find("joint 3 ") == 0, t.fault_text);
  const std::string ev = r.app.console->drain_events();
  CHECK_TEXT(ev.find("alarm: fault joint 3 ") != std::string::npos, ev.c_str());
  // Quick stop: the commanded joints come to rest.
  r.run(1.0);
  const kin::JointVector q1 = r.q_cmd();
  r.run(0.1);
  CHECK(max_abs_diff(r.q_cmd(), q1) < 1e-9);
  const std::string a = r.cmd("movej 0 0 0 0 0 0");
  CHECK_TEXT(a.rfind("error: fault", 0) == 0, a.c_str());
  LONGS_EQUAL(0, r.rt_allocs);
}

TEST(Controller, HeartbeatLossFaultsAsHeartbeatLost) {
  Rig r;
  r.enable();
  r.run(0.1);
  r.app.plant->inject_heartbeat_stop(4);  // PDOs keep coming, only the heartbeat stops
  const hal::TimePoint t0 = r.clock.now();
  int n = 0;
  while (r.tel().state != ArmState::fault && n < 1000) {
    r.cycle();
    ++n;
  }
  const Telemetry t = r.tel();
  CHECK_TEXT(t.cause == FaultCause::heartbeat_lost, t.fault_text);
  LONGS_EQUAL(4, t.fault_joint);
  CHECK_TEXT(std::string(t.fault_text).find("joint 5 heartbeat_lost") == 0, t.fault_text);
  const double dt = static_cast<double>(r.clock.now() - t0) * 1e-9;
  CHECK_TEXT(dt <= 0.150 + 0.050 + 0.002, std::to_string(dt).c_str());  // timeout after the last heartbeat
  LONGS_EQUAL(0, r.rt_allocs);
}

TEST(Controller, EmcyFaultsNamingTheJoint) {
  Rig r;
  r.enable();
  CHECK(is_ok(r.cmd("movej 30 -30 60 0 30 0 speed=50")));
  r.run(0.3);
  r.app.plant->inject_emcy(1, 0x2310);
  r.run(0.01);
  const Telemetry t = r.tel();
  CHECK(t.state == ArmState::fault);
  LONGS_EQUAL(1, t.fault_joint);
  CHECK_TEXT(std::string(t.fault_text).find("joint 2") != std::string::npos, t.fault_text);
  CHECK_TEXT(std::string(t.fault_text).find("2310") != std::string::npos, t.fault_text);
  // reset + enable recovers (the drive's fault is reset by enable).
  r.run(1.0);
  CHECK(is_ok(r.cmd("reset")));
  r.enable();
  CHECK(is_ok(r.cmd("park")));
  CHECK(is_ok(r.cmd("wait")));
  LONGS_EQUAL(0, r.rt_allocs);
}

TEST(Controller, FollowingErrorFaults) {
  sim::MotorParams slow;
  slow.max_velocity = 0.02 * 131072;  // the motor cannot follow: 7 deg/s
  FwConfig cfg;
  cfg.following_error_deg = 2.0;
  Rig r(slow, cfg);
  r.enable();
  CHECK(is_ok(r.cmd("movej 0 -40 0 0 0 0 speed=100")));
  r.run(1.0);
  const Telemetry t = r.tel();
  CHECK(t.state == ArmState::fault);
  CHECK(t.cause == FaultCause::following_error);
  CHECK_TEXT(std::string(t.fault_text).find("joint 2 following_error") != std::string::npos, t.fault_text);
  // The error and the limit with their unit, the error visibly beyond the limit.
  double e = 0, lim = 0;
  const char* at = std::strstr(t.fault_text, "following_error: ");
  CHECK_TEXT(at != nullptr && std::sscanf(at, "following_error: %lf rad > limit %lf rad", &e, &lim) == 2, t.fault_text);
  CHECK_TEXT(e > lim, t.fault_text);
  DOUBLES_EQUAL(2.0 * M_PI / 180.0, lim, 1e-4);
  LONGS_EQUAL(0, r.rt_allocs);
}

TEST(Controller, FullQueueAnswersBusyAndDropsNothing) {
  Rig r;
  r.enable();
  int ok = 0;
  // Nothing runs a cycle while the queue fills, so short fast moves fill it as well as
  // long slow ones and take a fraction of the simulated time to run out.
  for (std::size_t i = 0; i < kMotionQueue; ++i) {
    const std::string a = r.feed(i % 2 ? "movej 2 0 0 0 0 0 speed=100\n" : "movej -2 0 0 0 0 0 speed=100\n");
    ok += is_ok(a);
  }
  LONGS_EQUAL(static_cast<long>(kMotionQueue), ok);
  const std::string busy = r.feed("movej 20 0 0 0 0 0\n");
  CHECK_TEXT(busy.rfind("error: busy", 0) == 0, busy.c_str());
  CHECK_TEXT(r.feed("G4 P10\n").rfind("error: busy", 0) == 0, "dwell");
  LONGS_EQUAL(static_cast<long>(kMotionQueue), r.app.ctl->motions().size());
  // Every accepted move runs: ids 1..16 finish in order.
  std::uint32_t last_done = 0;
  bool in_order = true;
  for (int i = 0; i < 200000 && !r.app.ctl->motions().empty(); ++i) {
    r.cycle();
    const std::uint32_t d = r.tel().done_id;
    if (d != last_done) {
      in_order = in_order && d == last_done + 1;
      last_done = d;
    }
  }
  CHECK(in_order);
  LONGS_EQUAL(static_cast<long>(kMotionQueue), last_done);
  LONGS_EQUAL(0, r.rt_allocs);
}

TEST(Controller, HomeZeroMakesTheCurrentPositionJointZeroOnlyWhenDisabled) {
  Rig r;
  r.enable();
  CHECK(is_ok(r.cmd("movej 10 -20 30 5 20 -15 speed=100")));
  CHECK(is_ok(r.cmd("wait")));
  const kin::JointVector before = r.q_act();
  // Powered arm: refused, nothing changes.
  const std::string powered = r.cmd("home zero");
  CHECK_TEXT(powered.rfind("error: bad_state", 0) == 0, powered.c_str());
  CHECK(max_abs_diff(r.q_act(), before) < 1e-9);
  CHECK(is_error(r.cmd("home zero now")));
  CHECK(is_error(r.cmd("home 1")));

  CHECK(is_ok(r.cmd("disable")));
  r.run(0.2);
  const std::string a = r.cmd("home zero");
  CHECK_TEXT(is_ok(a), a.c_str());
  r.run(0.01);
  // Every joint now reads zero where it stands ...
  CHECK_TEXT(r.q_act().cwiseAbs().maxCoeff() < 1e-12, a.c_str());
  // ... and the reported offsets are the drive counts of the old positions
  // (default scaling: 131072 counts per joint revolution, direction +1).
  const std::size_t lb = a.find('['), rb = a.find(']');
  CHECK_TEXT(lb != std::string::npos && rb != std::string::npos, a.c_str());
  std::vector<double> offs;
  for (std::size_t p = lb + 1; p < rb;) {
    std::size_t used = 0;
    offs.push_back(std::stod(a.substr(p, rb - p), &used));
    p += used;
    while (p < rb && (a[p] == ',' || a[p] == ' ')) ++p;
  }
  LONGS_EQUAL(6, static_cast<long>(offs.size()));
  for (int j = 0; j < 6; ++j)
    DOUBLES_EQUAL(before[j] * 131072.0 / (2 * M_PI), offs[static_cast<std::size_t>(j)], 1.0);
  // Moves are relative to the new zero; the drives keep their physical positions.
  r.enable();
  CHECK(is_ok(r.cmd("movej 5 0 0 0 0 0 speed=100")));
  CHECK(is_ok(r.cmd("wait")));
  r.run(0.05);
  kin::JointVector goal = kin::JointVector::Zero(6);
  goal[0] = 5 * kDeg;
  CHECK(max_abs_diff(r.q_act(), goal) < 0.02 * kDeg);
  DOUBLES_EQUAL(offs[0] + 5 * kDeg * 131072.0 / (2 * M_PI), static_cast<double>(r.app.canopen().last_target_counts(0)), 1.0);
  LONGS_EQUAL(0, r.rt_allocs);
}

TEST(Controller, DriveTablesSetNodesScalingAndNarrowLimits) {
  // Bad [[drive]] sets are refused at build time naming the drive and key.
  struct Bad {
    int count;
    int joint;  // 0-based joint given the bad value
    const char* what;
    const char* must_contain;
  };
  const Bad bad[] = {
      {5, -1, "", "drive: 5 [[drive]] tables"},
      {6, 1, "limits", "drive[2].limits"},
      {6, 2, "node", "drive[3].node"},
      {6, 3, "max_velocity", "drive[4].max_velocity"},
  };
  for (const Bad& b : bad) {
    FwConfig c;
    c.can = "sim";
    c.drives.resize(static_cast<std::size_t>(b.count));
    if (b.joint >= 0) {
      DriveConfig& d = c.drives[static_cast<std::size_t>(b.joint)];
      if (std::string(b.what) == "limits") d.limits = {-400, 10};
      if (std::string(b.what) == "node") {
        c.drives[0].node = 40;
        d.node = 40;
      }
      if (std::string(b.what) == "max_velocity") d.max_velocity = 1e6;
    }
    hal::ManualClock clock;
    test::SimApp app;
    const std::string e = app.build(c, &clock);
    CHECK_TEXT(e.find(b.must_contain) != std::string::npos, (std::string(b.must_contain) + " <- " + e).c_str());
  }

  // Node ids 20..25 in reverse joint order, joint 2 reversed with a gear, joint 1 offset and narrowed.
  FwConfig c;
  c.drives.resize(6);
  for (int j = 0; j < 6; ++j) c.drives[static_cast<std::size_t>(j)].node = 25 - j;
  c.drives[0].zero_offset = 5000;
  c.drives[0].limits = {-30, 30};
  c.drives[1].direction = -1;
  c.drives[1].gear_ratio = 2;
  Rig r({}, c);
  r.enable();
  CHECK(is_error(r.cmd("movej 40 0 0 0 0 0")));  // outside the narrowed limit of joint 1
  const std::string lim = r.cmd("limits");
  CHECK_TEXT(lim.find("[-30.000, 30.000]") != std::string::npos, lim.c_str());
  CHECK(is_ok(r.cmd("movej 20 10 0 0 0 0 speed=100")));
  CHECK(is_ok(r.cmd("wait")));
  r.run(0.05);
  kin::JointVector goal = kin::JointVector::Zero(6);
  goal[0] = 20 * kDeg;
  goal[1] = 10 * kDeg;
  CHECK(max_abs_diff(r.q_act(), goal) < 0.02 * kDeg);
  const double cpr = 131072.0 / (2 * M_PI);
  DOUBLES_EQUAL(5000 + 20 * kDeg * cpr, static_cast<double>(r.app.canopen().last_target_counts(0)), 1.0);
  DOUBLES_EQUAL(-2 * 10 * kDeg * cpr, static_cast<double>(r.app.canopen().last_target_counts(1)), 1.0);
  LONGS_EQUAL(0, r.rt_allocs);
}

TEST(Controller, StopDropsQueueAndDisableWhileMovingStopsFirst) {
  Rig r;
  r.enable();
  CHECK(is_ok(r.cmd("movej 60 0 0 0 0 0 speed=50")));
  CHECK(is_ok(r.cmd("movej 0 0 0 0 0 0 speed=50")));
  r.run(0.3);
  CHECK(is_ok(r.cmd("stop")));
  r.run(1.0);
  CHECK(r.tel().state == ArmState::idle);
  CHECK(r.app.ctl->motions().empty());
  CHECK(is_ok(r.cmd("movej 0 0 0 0 0 0 speed=100")));
  r.run(0.2);
  CHECK(is_ok(r.cmd("disable")));
  r.run(1.0);
  CHECK(r.tel().state == ArmState::disabled);
  LONGS_EQUAL(0, r.rt_allocs);
}

TEST(Controller, AllocationFreeOverAFullRunWithEveryKindOfMove) {
  Rig r;
  r.enable();
  const char* script[] = {"park", "movej 20 -40 160 10 -50 30 speed=80", "wait", "movel 650 380 150 speed=150",
                          "G91", "G1 X-20 Z10 F3000", "G90", "G4 P50", "G0 X640", "M400", "stats", "status", "fk",
                          "ik 600 380 150"};
  for (const char* l : script) {
    const std::string a = r.cmd(l);
    if (!is_ok(a)) FAIL((std::string("'") + l + "': " + a).c_str());
  }
  CHECK(is_ok(r.cmd("movej 0 -20 100 0 -30 0 speed=30")));
  r.run(0.3);
  r.feed("!");
  r.run(0.3);
  r.feed("~");
  r.run(0.2);
  CHECK(is_ok(r.cmd("stop")));
  r.run(0.5);
  CHECK(is_ok(r.cmd("movej 10 -20 100 0 -30 0 speed=30")));
  r.run(0.2);
  r.feed("\x18");
  r.run(0.5);
  CHECK(is_ok(r.cmd("reset")));
  r.enable();
  CHECK(is_ok(r.cmd("park")));
  r.run(0.1);
  r.app.plant->inject_silent(4);
  r.run(0.5);
  CHECK(r.tel().state == ArmState::fault);
  CHECK(r.cycles > 5000);
  LONGS_EQUAL(0, r.rt_allocs);
}

// ---------------------------------------------------------------------------
// Safety defects: each test failed on the code before the fix.
// ---------------------------------------------------------------------------

namespace {

/// Push a request straight into the controller's queue (as the console does) and
/// run exactly one cycle: the request is handled in the same cycle as whatever
/// the console committed just before it. Returns the reply's message.
std::string request_in_this_cycle(Rig& r, RequestOp op) {
  static std::uint32_t seq = 100000;
  const std::uint32_t my = ++seq;
  CHECK(r.app.ctl->requests().push(Request{op, my}));
  r.cycle();
  Reply rep;
  while (r.app.ctl->replies().pop(rep))
    if (rep.seq == my) return rep.message;
  FAIL("no reply in the same cycle");
  return "";
}

/// Lines of an answer that are final answers (ok / error:), not data, alarms or reports.
int answers(const std::string& out) {
  int n = 0;
  std::size_t p = 0;
  while (p < out.size()) {
    const std::size_t e = out.find('\n', p);
    const std::string l = out.substr(p, e == std::string::npos ? std::string::npos : e - p);
    if (l.rfind("ok", 0) == 0 || l.rfind("error: ", 0) == 0) ++n;
    if (e == std::string::npos) break;
    p = e + 1;
  }
  return n;
}

}  // namespace

TEST(Controller, StopHoldDisableInTheCycleAMoveIsQueuedCancelIt) {
  // A move committed by the console starts at the control thread's next cycle,
  // after that cycle's requests: a request in the same cycle must still act on it.
  const RequestOp ops[] = {RequestOp::stop, RequestOp::hold, RequestOp::disable, RequestOp::estop};
  for (RequestOp op : ops) {
    for (int moving = 0; moving < 2; ++moving) {
      const std::string what = std::string(to_string(op)) + (moving ? " while moving" : " from idle");
      Rig r;
      r.enable();
      if (moving) {
        CHECK(is_ok(r.cmd("movej 10 0 0 0 0 0 speed=20")));
        r.run(0.2);
        CHECK_TEXT(r.tel().state == ArmState::moving, what.c_str());
      }
      const kin::JointVector q0 = r.q_cmd();
      const std::string a = r.cmd("movej 60 -60 120 60 -60 60 speed=20");
      CHECK_TEXT(is_ok(a), (what + ": " + a).c_str());
      const std::string rep = request_in_this_cycle(r, op);
      r.run(1.5);
      const Telemetry t = r.tel();
      const kin::JointVector q1 = r.q_cmd();
      r.run(0.3);
      const double drift = max_abs_diff(r.q_cmd(), q1);  // at rest by now?
      // Whatever the request, the arm never heads for the second move's goal.
      CHECK_TEXT(r.q_cmd()[3] < 1 * kDeg, (what + ": joint 4 moved towards 60 deg").c_str());
      CHECK_TEXT(drift < 1e-9, (what + ": still moving").c_str());
      switch (op) {
        case RequestOp::stop:
          CHECK_TEXT(t.state == ArmState::idle, (what + ": " + to_string(t.state)).c_str());
          LONGS_EQUAL(0, t.queued);
          if (!moving) {
            CHECK_TEXT(rep.find("1 queued move dropped") != std::string::npos, (what + ": " + rep).c_str());
            CHECK_TEXT(max_abs_diff(r.q_cmd(), q0) < 1e-12, what.c_str());
          }
          break;
        case RequestOp::hold: {
          // GRBL Hold: the queue is held, not dropped, and resume runs it.
          CHECK_TEXT(t.holding, what.c_str());
          CHECK_TEXT(t.queued >= 1, what.c_str());
          const std::string grbl = r.feed("?");
          CHECK_TEXT(grbl.rfind("<Hold|", 0) == 0, (what + ": " + grbl).c_str());
          if (!moving) CHECK_TEXT(max_abs_diff(r.q_cmd(), q0) < 1e-12, what.c_str());
          r.feed("~");
          CHECK(is_ok(r.cmd("wait")));
          kin::JointVector goal(6);
          goal << 60, -60, 120, 60, -60, 60;
          CHECK_TEXT(max_abs_diff(r.q_cmd(), goal * kDeg) < 1e-9, what.c_str());
          break;
        }
        case RequestOp::disable: {
          CHECK_TEXT(t.state == ArmState::disabled, (what + ": " + to_string(t.state)).c_str());
          LONGS_EQUAL(0, t.queued);
          // The next enable, at any later time, never starts the old move.
          r.enable();
          const kin::JointVector qe = r.q_cmd();
          r.run(1.0);
          CHECK_TEXT(max_abs_diff(r.q_cmd(), qe) < 1e-12, (what + ": the old move started after enable").c_str());
          LONGS_EQUAL(0, r.tel().queued);
          break;
        }
        case RequestOp::estop:
        case RequestOp::enable:
        case RequestOp::reset:
        case RequestOp::resume:
        case RequestOp::set_zero:
        case RequestOp::jog:
        case RequestOp::jog_cancel:
        case RequestOp::jog_keepalive:
        case RequestOp::home:
        case RequestOp::freedrive_on:
        case RequestOp::freedrive_off:  // (not among the requests of this test)
          CHECK_TEXT(t.state == ArmState::estop, what.c_str());
          LONGS_EQUAL(0, t.queued);
          break;
      }
      LONGS_EQUAL(0, r.rt_allocs);
    }
  }
}

TEST(Controller, MoveCommittedOnAStaleStateNeverStartsAndIsReported) {
  // The console decides on the last published state; a move it commits just as the
  // control thread faults, e-stops or disables never starts (not even at the next
  // enable), and the console hears that it was dropped.
  for (int k = 0; k < 3; ++k) {
    Rig r;
    r.enable();
    if (k == 0) {
      r.app.plant->inject_emcy(1, 0x2310);
      r.run(0.05);
      CHECK(r.tel().state == ArmState::fault);
    } else if (k == 1) {
      r.feed("\x18");
      r.run(0.05);
      CHECK(r.tel().state == ArmState::estop);
    } else {
      CHECK(is_ok(r.cmd("disable")));
      CHECK(r.tel().state == ArmState::disabled);
    }
    r.app.console->drain_events();
    // What the console commits on a stale "idle": a joint move to joint 4 = 90 deg.
    MotionItem* m = r.app.ctl->motions().back();
    CHECK(m != nullptr);
    JointMove& jm = m->payload.emplace<JointMove>();
    m->id = 4242;
    jm.goal = r.q_cmd();
    jm.goal[3] = 90 * kDeg;
    jm.override = 0.5;
    r.app.ctl->motions().commit();
    r.cycle();
    LONGS_EQUAL(0, r.tel().queued);
    const std::string ev = r.app.console->drain_events();
    CHECK_TEXT(ev.find("alarm: 1 queued move dropped: arm is ") != std::string::npos, ev.c_str());
    if (k != 2) CHECK(is_ok(r.cmd("reset")));
    r.enable();
    r.run(1.0);
    CHECK_TEXT(std::fabs(r.q_cmd()[3]) < 1e-9, "the stale move started after enable");
    LONGS_EQUAL(0, r.rt_allocs);
  }
}

TEST(Controller, QueriesNeverChangeState) {
  Rig r;
  r.enable();
  CHECK(is_ok(r.cmd("movej 20 -40 160 10 -50 30 speed=100")));
  CHECK(is_ok(r.cmd("wait")));
  CHECK(is_ok(r.cmd("disable")));
  r.run(0.1);
  const char* queries[] = {"status", "stats", "stats zero", "stats 1", "limits", "config", "fk", "fk 0 0 0 0 0 0",
                           "ik 600 380 150", "help", "help home", "M114", "M105", "status zero", "limits zero"};
  for (const char* q : queries) {
    const Telemetry t0 = r.tel();
    std::int64_t z0[6];
    for (int j = 0; j < 6; ++j) z0[j] = r.app.servo->zero_offset(std::size_t(j));
    const std::string a = r.cmd(q);
    r.run(0.05);
    const Telemetry t1 = r.tel();
    CHECK_TEXT(t1.state == t0.state, q);
    CHECK_TEXT(t1.generation == t0.generation, q);
    for (int j = 0; j < 6; ++j) {
      CHECK_TEXT(r.app.servo->zero_offset(std::size_t(j)) == z0[j], (std::string(q) + ": zero offset changed: " + a).c_str());
      CHECK_TEXT(std::fabs(t1.q_act[std::size_t(j)] - t0.q_act[std::size_t(j)]) < 1e-9, (std::string(q) + ": " + a).c_str());
    }
  }
  // ... and `park` afterwards still has the way back to do.
  r.enable();
  const std::string h = r.cmd("park");
  CHECK_TEXT(h.find("duration=0.000s") == std::string::npos, h.c_str());
}

TEST(Controller, EnableRefusesADriveThatHasGoneSilent) {
  Rig r;
  r.enable();
  r.run(0.1);
  r.app.plant->inject_silent(2);
  r.run(0.5);
  CHECK(r.tel().state == ArmState::fault);
  CHECK(is_ok(r.cmd("reset")));
  r.run(0.05);
  const kin::JointVector q0 = r.q_cmd();
  const std::string a = r.cmd("enable");
  CHECK_TEXT(a.rfind("error: fault enable failed: joint 3 feedback_invalid", 0) == 0, a.c_str());
  const std::string m = r.cmd("movej 10 10 10 10 10 10 speed=100");
  CHECK_TEXT(m.rfind("error: ", 0) == 0, m.c_str());
  r.run(0.5);
  CHECK(!r.any_powered());
  CHECK(max_abs_diff(r.q_cmd(), q0) < 1e-9);
  LONGS_EQUAL(0, r.rt_allocs);
}

TEST(Controller, EnableWaitsForAHeartbeatFromEveryDrive) {
  Rig r;
  r.enable();
  r.run(0.1);
  r.app.plant->inject_heartbeat_stop(2);  // PDOs keep coming, the heartbeat stops
  r.run(0.5);
  CHECK(r.tel().state == ArmState::fault);
  CHECK(is_ok(r.cmd("reset")));
  r.run(0.05);
  const kin::JointVector q0 = r.q_cmd();
  // enable + movej in one go, as a script sends them: the move must never start.
  r.s.out.clear();
  r.app.console->feed(r.s, "enable\nmovej 10 10 10 10 10 10 speed=100\n");
  for (int i = 0; i < 1000; ++i) {
    r.cycle();
    r.app.console->poll(r.s);
    CHECK_TEXT(max_abs_diff(r.q_cmd(), q0) < 1e-9, "a joint moved during enable with a drive without heartbeat");
  }
  const std::string out = r.s.out;
  CHECK_TEXT(out.rfind("error: fault enable failed: joint 3 heartbeat_lost", 0) == 0, out.c_str());
  LONGS_EQUAL(2, answers(out));
  CHECK_TEXT(out.find("ok enabled") == std::string::npos, out.c_str());
  LONGS_EQUAL(0, r.rt_allocs);
}

TEST(Controller, CtrlXAnswersEveryCompleteLineItDrops) {
  Rig r;
  r.enable();
  // Lines queued behind a wait: 4 lines, 4 answers.
  r.s.out.clear();
  r.app.console->feed(r.s, "movej 10 0 0 0 0 0 speed=10\nwait\nstatus\nmovej 0 0 0 0 0 0\n");
  r.run(0.2);
  r.app.console->feed(r.s, "\x18");
  r.run(0.05);
  std::string out = r.s.out;
  LONGS_EQUAL_TEXT(4, answers(out), out.c_str());
  CHECK_TEXT(out.find("error: estop 'status' not executed") != std::string::npos, out.c_str());
  CHECK_TEXT(out.find("error: estop 'movej 0 0 0 0 0 0' not executed") != std::string::npos, out.c_str());
  CHECK(r.tel().state == ArmState::estop);
  // A complete line in the same read as the Ctrl-X: answered, not executed.
  CHECK(is_ok(r.cmd("reset")));
  r.enable();
  r.s.out.clear();
  r.app.console->feed(r.s, "movej 0 0 0 30 0 0\n\x18");
  r.run(0.5);
  out = r.s.out;
  LONGS_EQUAL_TEXT(1, answers(out), out.c_str());
  CHECK_TEXT(out.rfind("error: estop", 0) == 0, out.c_str());
  CHECK(std::fabs(r.q_cmd()[3]) < 1e-9);
}

TEST(Controller, MovesThatWouldNeverEndAreRefused) {
  FwConfig cfg;
  cfg.max_move_duration_s = 5;
  Rig r({}, cfg);
  r.enable();
  CHECK(is_ok(r.cmd("movej 20 -40 160 10 -50 30 speed=100")));  // a working pose (the zero pose is singular)
  CHECK(is_ok(r.cmd("wait")));
  const char* bad[] = {"movel 600 380 150 speed=0.000000001", "G1 X600 F0.00001", "movej 150 0 0 0 0 0 speed=10",
                       "movej 150 0 0 0 0 0 speed=1", "movej 150 0 0 0 0 0 speed=0.5"};
  for (const char* l : bad) {
    const std::string a = r.cmd(l);
    CHECK_TEXT(a.rfind("error: out_of_range", 0) == 0, (std::string(l) + ": " + a).c_str());
  }
  // A straight line at the slowest accepted speed that would take hours.
  kin::Pose p0;
  kin::forward(r.app.chain, r.q_cmd(), p0);
  char line[128];
  std::snprintf(line, sizeof line, "movel %.3f %.3f %.3f speed=0.01", p0.translation().x() * 1e3 - 50,
                p0.translation().y() * 1e3, p0.translation().z() * 1e3);
  const std::string a = r.cmd(line);
  CHECK_TEXT(a.rfind("error: out_of_range", 0) == 0 && a.find("max_move_duration_s") != std::string::npos, a.c_str());
  LONGS_EQUAL(0, r.tel().queued);
  CHECK(is_ok(r.cmd("wait")));  // answers at once: nothing was queued
  CHECK(is_ok(r.cmd("movej 150 0 0 0 0 0 speed=100")));
  CHECK(is_ok(r.cmd("wait")));
}

TEST(Controller, OverlongLastLineAtEndOfInputIsAnswered) {
  Rig r;
  r.s.out.clear();
  r.app.console->accept(r.s, std::string(300, 'a'));
  r.app.console->end_of_input(r.s);
  r.app.console->poll(r.s);
  LONGS_EQUAL_TEXT(1, answers(r.s.out), r.s.out.c_str());
  CHECK_TEXT(r.s.out.rfind("error: overlong", 0) == 0, r.s.out.c_str());
  r.s.out.clear();
  r.app.console->accept(r.s, "status");
  r.app.console->end_of_input(r.s);
  r.app.console->poll(r.s);
  LONGS_EQUAL_TEXT(1, answers(r.s.out), r.s.out.c_str());
}

TEST_GROUP(RtThread){};

TEST(RtThread, RealLoopRunsMovesWithoutAllocatingOnTheControlThread) {
  test::SimApp app;
  FwConfig cfg;
  cfg.can = "sim";
  cfg.priority = 0;  // tests run without RT privileges everywhere
  cfg.lock_memory = false;
  // A shared 2-core machine can stall the drive thread: generous timeouts (the
  // deterministic tests above check the real ones).
  cfg.feedback_timeout_ms = 1000;
  cfg.heartbeat_timeout_ms = 1000;
  // the simulated drives answer SDOs on a thread a busy machine may stall (bring-up)
  cfg.sdo_timeout_ms = 1000.0 * (servoarm::test::kSlowBuild ? 10 : 1);
  cfg.following_error_deg = 30;
  const std::string e = app.build(cfg);
  CHECK_TEXT(e.empty(), e.c_str());
  const std::string b = app.boot();
  CHECK_TEXT(b.empty(), b.c_str());
  LoopConfig lc;
  lc.priority = 0;
  lc.lock_memory = false;
  std::size_t allocs = 999;  // before the loop: a failed check ends the test with the loop's thread still running
  RtLoop loop(*app.ctl, lc);
  loop.on_thread_start = [] { test::alloc_count_begin(); };
  loop.on_thread_exit = [&] { allocs = test::alloc_count_end(); };
  CHECK(loop.start());
  Session s;
  auto run = [&](const std::string& line) {
    s.out.clear();
    app.console->execute(s, line);
    for (int i = 0; i < 20000 && app.console->busy(s); ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
      app.console->poll(s);
    }
    return s.out;
  };
  auto ok = [&](const std::string& line) {
    const std::string out = run(line);
    CHECK_TEXT(is_ok(out), (line + ": " + out).c_str());
  };
  ok("enable");
  for (int i = 0; i < 2000 && app.ctl->telemetry().state != ArmState::idle; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  ok("movej 20 -40 160 10 -50 30 speed=100");
  ok("wait");
  ok("movel 700 380 120 speed=250");
  ok("G4 P20");
  ok("park");
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  app.console->feed(s, "!");
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  app.console->feed(s, "~");
  ok("wait");
  ok("movej 10 0 0 0 0 0");
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  ok("stop");
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  ok("estop");
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  loop.stop();
  app.plant->stop_thread();
  CHECK(loop.cycles() > 500);
  LONGS_EQUAL(0, allocs);
  const Telemetry t = app.ctl->telemetry();
  CHECK(t.state == ArmState::estop);
}

namespace {

/// Read what arrives on fd until `want` appears or `secs` pass.
std::string read_until(int fd, const std::string& want, double secs, std::string& acc) {
  const auto t0 = std::chrono::steady_clock::now();
  while (acc.find(want) == std::string::npos &&
         std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() < secs) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 10) > 0) {
      char b[4096];
      const ssize_t n = ::read(fd, b, sizeof b);
      if (n > 0) acc.append(b, static_cast<std::size_t>(n));
    }
  }
  return acc;
}

}  // namespace

TEST(RtThread, StalledPtyClientDelaysNeitherAnEstopNorOtherClients) {
  // Client A on a pty floods `limits` and does not read its answers; client B (a pipe
  // pair, like stdin/stdout) moves joint 1 and sends Ctrl-X. The e-stop must act at
  // once; A's lines wait for it to read (back-pressure), and then each gets its answer.
  test::SimApp app;
  FwConfig cfg;
  cfg.can = "sim";
  cfg.priority = 0;
  cfg.lock_memory = false;
  cfg.feedback_timeout_ms = 1000;  // a shared 2-core machine can stall the drive thread
  cfg.heartbeat_timeout_ms = 1000;
  // the simulated drives answer SDOs on a thread a busy machine may stall (bring-up)
  cfg.sdo_timeout_ms = 1000.0 * (servoarm::test::kSlowBuild ? 10 : 1);
  cfg.following_error_deg = 30;
  CHECK(app.build(cfg).empty());
  CHECK(app.boot().empty());
  LoopConfig lc;
  lc.priority = 0;
  lc.lock_memory = false;
  RtLoop loop(*app.ctl, lc);
  CHECK(loop.start());

  FdTransport pty;
  CHECK(open_pty(pty).empty());
  const int client = ::open(pty.path.c_str(), O_RDWR | O_NOCTTY);
  CHECK(client >= 0);
  int in[2], out[2];
  CHECK(::pipe(in) == 0 && ::pipe(out) == 0);
  fcntl(in[0], F_SETFL, fcntl(in[0], F_GETFL) | O_NONBLOCK);
  FdTransport op;
  op.name = "op";
  op.rd = in[0];
  op.wr = out[1];
  std::atomic<bool> stop{false};
  std::vector<FdTransport*> ts{&pty, &op};
  std::thread server([&] { serve_consoles(*app.console, ts, false, nullptr, &stop); });

  std::string acc;
  auto say = [&](const std::string& l) { CHECK(::write(in[1], l.data(), l.size()) == static_cast<ssize_t>(l.size())); };
  say("enable\n");
  read_until(out[0], "ok enabled", 10, acc);
  CHECK_TEXT(acc.find("ok enabled") != std::string::npos, acc.c_str());
  std::atomic<int> flooded{0};
  std::thread flood([&] {
    const std::string l = "limits\n";
    for (int i = 0; i < 2000; ++i) {
      if (::write(client, l.data(), l.size()) <= 0) break;
      ++flooded;
    }
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  say("movej 150 0 0 0 0 0 speed=20\n");
  read_until(out[0], "ok queued", 10, acc);
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  const auto t0 = std::chrono::steady_clock::now();
  say("\x18");
  double latency = 99;
  while (std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() < 10) {
    if (app.ctl->telemetry().state == ArmState::estop) {
      latency = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      break;
    }
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
  CHECK_TEXT(latency < 0.5, ("e-stop took " + std::to_string(latency) + " s with a stalled client").c_str());
  CHECK_TEXT(acc.find("ok queued") != std::string::npos, acc.c_str());
  // The stalled client, once it reads, gets an answer to every line it sent, none dropped.
  std::string got;
  fcntl(client, F_SETFL, fcntl(client, F_GETFL) | O_NONBLOCK);
  int oks = 0;
  for (int k = 0; k < 2000 && !(flooded.load() == 2000 && oks == 2000); ++k) {
    char b[65536];
    const ssize_t n = ::read(client, b, sizeof b);
    if (n > 0) got.append(b, static_cast<std::size_t>(n));
    std::size_t nl;
    while ((nl = got.find('\n')) != std::string::npos) {
      if (got.compare(0, 2, "ok") == 0) ++oks;
      CHECK(got.compare(0, 30, "alarm: console output overflow") != 0);
      got.erase(0, nl + 1);
    }
    if (n <= 0) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  flood.join();
  LONGS_EQUAL(2000, flooded.load());
  LONGS_EQUAL(2000, oks);
  stop = true;
  server.join();
  loop.stop();
  app.plant->stop_thread();
  ::close(client);
  ::close(in[1]);
  ::close(out[0]);
  ::close(out[1]);
  ::close(in[0]);
  op.rd = op.wr = -1;
}

namespace {
struct StallingPlant {
  sim::SimPlant* plant = nullptr;
  std::atomic<int> stall_ms{0};
  static void hook(void* ctx, std::int64_t now) {
    auto* self = static_cast<StallingPlant*>(ctx);
    const int ms = self->stall_ms.exchange(0);
    if (ms > 0) std::this_thread::sleep_for(std::chrono::milliseconds(ms));
    sim::SimPlant::step_hook(self->plant, ms > 0 ? now + ms * 1000000LL : now);
  }
};
}  // namespace

TEST(RtThread, SimDrivesSteppedOnTheControlThreadRideThroughAStall) {
  // What armfw --sim runs: the drives are stepped right before each cycle, so a
  // control thread held off the CPU (a busy desktop) stalls the drives with it:
  // with the default 50 ms feedback and 150 ms heartbeat timeouts, a 300 ms stall
  // in the middle of a move faults nothing.
  test::SimApp app;
  FwConfig cfg;
  cfg.can = "sim";
  cfg.priority = 0;
  cfg.lock_memory = false;
  CHECK(app.build(cfg).empty());
  CHECK(app.boot().empty());
  app.plant->stop_thread();
  LoopConfig lc;
  lc.priority = 0;
  lc.lock_memory = false;
  RtLoop loop(*app.ctl, lc);
  StallingPlant sp;
  sp.plant = app.plant.get();
  loop.set_pre_cycle(&StallingPlant::hook, &sp);
  CHECK(loop.start());
  Session s;
  auto run = [&](const std::string& line) {
    s.out.clear();
    app.console->execute(s, line);
    for (int i = 0; i < 20000 && app.console->busy(s); ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
      app.console->poll(s);
    }
    return s.out;
  };
  CHECK(is_ok(run("enable")));
  CHECK(is_ok(run("movej 40 -30 60 0 30 0 speed=50")));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  sp.stall_ms = 300;
  const std::string w = run("wait");
  CHECK_TEXT(is_ok(w), (w + " " + app.ctl->telemetry().fault_text).c_str());
  loop.stop();
  const Telemetry t = app.ctl->telemetry();
  CHECK_TEXT(t.state == ArmState::idle, t.fault_text);
  kin::JointVector goal(6), q(6);
  goal << 40, -30, 60, 0, 30, 0;
  for (int j = 0; j < 6; ++j) q[j] = t.q_act[std::size_t(j)];
  CHECK(max_abs_diff(q, goal * kDeg) < 0.01 * kDeg);
}

// The sample ring a recorder reads (Controller::start_samples): every cycle due, in order, with
// the joints the cycle commanded and measured; a full ring counts the cycles it could not keep;
// the control cycle allocates nothing while it fills the ring.
TEST(Controller, SampleRingCarriesEveryCycleDueAndCountsTheOnesItCouldNotKeep) {
  Rig r;
  r.enable();
  r.app.ctl->start_samples(1);
  CHECK(is_ok(r.cmd("movej 10 -20 30 5 20 -15 speed=100")));
  r.run(1.0);  // 1 000 cycles of the move: fewer than the ring holds
  CycleSample c;
  std::uint64_t prev = 0, taken = 0;
  double largest_step = 0;
  kin::JointVector q_prev(6);
  while (r.app.ctl->pop_sample(c)) {
    if (taken > 0) LONGS_EQUAL(prev + 1, c.cycles);
    LONGS_EQUAL(6, c.n);
    kin::JointVector q(6);
    for (int j = 0; j < 6; ++j) q[j] = c.q_cmd[static_cast<std::size_t>(j)];
    if (taken > 0) largest_step = std::max(largest_step, max_abs_diff(q, q_prev));
    q_prev = q;
    prev = c.cycles;
    ++taken;
  }
  CHECK(taken > 10);
  CHECK(largest_step > 0);  // the samples carry the moving setpoint
  LONGS_EQUAL(r.tel().cycles, prev);  // up to the last cycle run
  LONGS_EQUAL(0, r.app.ctl->samples_dropped());

  r.app.ctl->start_samples(10);  // every 10th cycle; then nobody reads for longer than the ring
  const std::uint64_t from = r.tel().cycles;
  for (std::size_t i = 0; i < 10 * Controller::kSampleRing + 55; ++i) r.cycle();
  std::uint64_t kept = 0;
  while (r.app.ctl->pop_sample(c)) {
    LONGS_EQUAL(0, c.cycles % 10);
    ++kept;
  }
  LONGS_EQUAL(Controller::kSampleRing, kept);
  const std::uint64_t due = (r.tel().cycles / 10) - (from / 10);
  LONGS_EQUAL(due - Controller::kSampleRing, r.app.ctl->samples_dropped());
  r.app.ctl->stop_samples();
  r.run(0.05);
  CHECK(!r.app.ctl->pop_sample(c));  // stopped: nothing more is taken
  LONGS_EQUAL(0, r.rt_allocs);
}
