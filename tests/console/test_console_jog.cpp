// SPDX-License-Identifier: Apache-2.0
// Jogging through the console: `jog` and GRBL `$J=`, the deadman, jog cancel
// (0x85), soft limits, tool jogs in the base and tool frames, and bad input. A puma560
// with virtual drives on the sim bus, one control cycle per millisecond of ManualClock
// (the rig runs the cycles); what is checked is what the controller commanded, cycle by
// cycle (Telemetry::q_cmd), and the tool pose computed from it by FK.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "console_rig.hpp"
#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/orientation.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;
using test::answer_ok;

namespace {
constexpr double kDeg = M_PI / 180.0;
bool has(const std::string& s, const std::string& p) { return s.find(p) != std::string::npos; }

struct JogRig : test::ConsoleRig {
  std::string events;  ///< every alarm line drained so far
  kin::JointVector q() const {
    const Telemetry t = app.ctl->telemetry();
    kin::JointVector v(6);
    for (int j = 0; j < 6; ++j) v[j] = t.q_cmd[static_cast<std::size_t>(j)];
    return v;
  }
  kin::Pose x() const {
    kin::Pose p;
    kin::forward(app.chain, q(), p);
    return p;
  }
  ArmState state() const { return app.ctl->telemetry().state; }
  void drain() { events += app.console->drain_events(); }
  /// Cycles until the arm is idle (bounded); the trace of commanded joints on the way.
  std::vector<kin::JointVector> run_to_idle(int max_cycles) {
    std::vector<kin::JointVector> trace;
    for (int i = 0; i < max_cycles && state() != ArmState::idle; ++i) {
      cycle();
      trace.push_back(q());
    }
    drain();
    return trace;
  }
  void working_pose() {
    enable();
    CHECK(answer_ok(cmd("movej 20 -40 160 10 -50 30")));
    CHECK(answer_ok(cmd("wait")));
  }
  /// The largest joint speed of a trace (per joint, as a fraction of its limit).
  double worst_speed_ratio(const std::vector<kin::JointVector>& tr) const {
    const kin::JointLimits l = kin::limits_from(app.chain);
    double w = 0;
    for (std::size_t k = 1; k < tr.size(); ++k)
      for (int j = 0; j < 6; ++j)
        w = std::fmax(w, std::fabs(tr[k][j] - tr[k - 1][j]) / 1e-3 / l.dyn[static_cast<std::size_t>(j)].max_velocity);
    return w;
  }
};
}  // namespace

TEST_GROUP(ConsoleJog){};

TEST(ConsoleJog, AJointIncrementMovesExactlyThatJointByThatMuch) {
  JogRig r;
  r.enable();
  const kin::JointVector q0 = r.q();
  const std::string a = r.cmd("jog j3 +5");
  CHECK_TEXT(answer_ok(a), a.c_str());
  CHECK(r.state() == ArmState::jogging);
  // command to the first changed setpoint: the cycle that took the request already moves
  CHECK(r.q()[2] > q0[2]);
  r.run_to_idle(20000);
  const kin::JointVector q1 = r.q();
  DOUBLES_EQUAL(q0[2] + 5 * kDeg, q1[2], 1e-12);
  for (int j : {0, 1, 3, 4, 5}) DOUBLES_EQUAL(q0[j], q1[j], 0.0);
  CHECK(r.app.ctl->telemetry().cause == FaultCause::none);
  // in the angle unit, negative, at a speed: back where it started
  CHECK(answer_ok(r.cmd("jog j3 -5 speed=50")));
  r.run_to_idle(20000);
  DOUBLES_EQUAL(q0[2], r.q()[2], 1e-12);
}

// A continuous jog that nobody refreshes starts decelerating at its deadman, not later:
// the first slower setpoint comes at most one cycle after console.jog_deadman_ms.
TEST(ConsoleJog, AContinuousJogStopsByItselfAtItsDeadman) {
  JogRig r;
  r.enable();
  CHECK(answer_ok(r.cmd("jog j1 + speed=5")));  // (at cruise well before the deadman)
  const std::uint64_t refreshed = r.app.ctl->telemetry().cycles;  // the cycle that took the jog
  std::vector<double> q1{r.q()[0]};
  std::vector<std::uint64_t> at{refreshed};
  for (int i = 0; i < 3000 && r.state() == ArmState::jogging; ++i) {
    r.cycle();
    q1.push_back(r.q()[0]);
    at.push_back(r.app.ctl->telemetry().cycles);
  }
  r.drain();
  CHECK(r.state() == ArmState::idle);
  CHECK_TEXT(has(r.events, "jog stopped: not refreshed within its deadman time (250 ms)"), r.events.c_str());
  // the first cycle whose step is smaller than the one before (after cruising)
  std::size_t k = 2;
  while (k < q1.size() && !(q1[k] - q1[k - 1] < q1[k - 1] - q1[k - 2] - 1e-12 && at[k] - refreshed > 100)) ++k;
  CHECK(k < q1.size());
  const double ms = static_cast<double>(at[k] - refreshed);
  CHECK_TEXT(ms >= 250 && ms <= 252, std::to_string(ms).c_str());
  CHECK(r.app.ctl->telemetry().cause == FaultCause::none);
}

TEST(ConsoleJog, KeepAlivesKeepItGoingAndJogStopEndsIt) {
  JogRig r;
  r.enable();
  const double q0 = r.q()[0];
  CHECK(answer_ok(r.cmd("jog j1 + speed=10")));
  for (int i = 0; i < 1500; ++i) {
    r.cycle();
    if (i % 100 == 99) CHECK(answer_ok(r.cmd("jog")));  // the sender's keep-alive
  }
  CHECK(r.state() == ArmState::jogging);
  const std::string st = r.cmd("jog stop");
  CHECK_TEXT(answer_ok(st) && has(st, "jog cancelled"), st.c_str());
  const auto tr = r.run_to_idle(3000);
  CHECK(r.state() == ArmState::idle);
  const double v = 0.1 * kin::limits_from(r.app.chain).dyn[0].max_velocity;  // 10 % of joint 1's limit
  CHECK_TEXT(r.q()[0] > q0 + 0.8 * v * 1.5, std::to_string(r.q()[0] - q0).c_str());
  CHECK(tr.size() < 1000);  // decelerated, it did not run on
  CHECK(r.app.ctl->telemetry().cause == FaultCause::none);
}

TEST(ConsoleJog, AtAJointLimitAJogStopsOnTheLimitWithoutAFault) {
  JogRig r;
  r.enable();
  const kin::JointLimits l = kin::limits_from(r.app.chain);
  // an increment past the limit (within the joint's range): the arm moves, so `ok`, saying where it stops
  const std::string a = r.cmd("jog j2 +" + std::to_string((l.upper[1] - l.lower[1]) / kDeg - 1) + " speed=100");
  CHECK_TEXT(a.rfind("ok ", 0) == 0 && has(a, "joint 2 stops at its limit"), a.c_str());
  CHECK(r.state() == ArmState::jogging);
  r.run_to_idle(30000);
  DOUBLES_EQUAL(l.upper[1], r.q()[1], 1e-12);
  const std::string again = r.cmd("jog j2 +1");
  CHECK_TEXT(again.rfind("error: limits jog: joint 2 is at its limit", 0) == 0, again.c_str());
  CHECK(r.state() == ArmState::idle);
  // continuous, kept alive: it ends on the lower limit and says so
  CHECK(answer_ok(r.cmd("jog j2 - speed=100")));
  for (int i = 0; i < 60000 && r.state() == ArmState::jogging; ++i) {
    r.cycle();
    if (i % 100 == 99) r.cmd("jog");
  }
  r.drain();
  DOUBLES_EQUAL(l.lower[1], r.q()[1], 1e-12);
  CHECK_TEXT(has(r.events, "jog stopped: joint 2 at its limit"), r.events.c_str());
  CHECK(r.app.ctl->telemetry().cause == FaultCause::none);
}

TEST(ConsoleJog, ToolJogsAreStraightLinesInTheBaseAndToolFrames) {
  JogRig r;
  r.working_pose();
  struct Case {
    const char* line;
    int axis;         // 0..5
    double amount;    // m or rad
    bool tool_frame;
  };
  const Case cases[] = {{"jog x +10", 0, 0.010, false},  {"jog y -7.5", 1, -0.0075, false},
                        {"jog z -5 frame=tool", 2, -0.005, true}, {"jog rz +10", 5, 10 * kDeg, false},
                        {"jog rx -4 frame=tool", 3, -4 * kDeg, true}};
  for (const Case& c : cases) {
    const kin::Pose x0 = r.x();
    const std::string a = r.cmd(c.line);
    CHECK_TEXT(answer_ok(a), (std::string(c.line) + ": " + a).c_str());
    const auto tr = r.run_to_idle(20000);
    const kin::Pose x1 = r.x();
    const Eigen::Matrix3d F = c.tool_frame ? Eigen::Matrix3d(x0.linear()) : Eigen::Matrix3d::Identity();
    Eigen::Vector3d dp_want = Eigen::Vector3d::Zero();
    Eigen::Matrix3d R_want = x0.linear();
    if (c.axis < 3) dp_want = F.col(c.axis) * c.amount;
    else R_want = Eigen::AngleAxisd(c.amount, F.col(c.axis - 3)).toRotationMatrix() * x0.linear();
    CHECK_TEXT((x1.translation() - x0.translation() - dp_want).norm() < 1e-7, c.line);
    CHECK_TEXT((x1.linear() - R_want).norm() < 1e-7, c.line);
    // on the way: on the line (position) and, for a translation, the orientation kept
    double off = 0;
    // the line's unit vector without a division: clang -O1 (tsan preset) computed
    // dp_want.normalized() for the rotations too, 0/0 behind a select, and raised FE_INVALID
    const Eigen::Vector3d u = c.axis < 3 ? Eigen::Vector3d(F.col(c.axis) * (c.amount < 0 ? -1.0 : 1.0)) : Eigen::Vector3d::Zero();
    for (const auto& qk : tr) {
      kin::Pose xk;
      kin::forward(r.app.chain, qk, xk);
      const Eigen::Vector3d d = xk.translation() - x0.translation();
      if (c.axis < 3) {
        off = std::fmax(off, (d - u * u.dot(d)).norm());
        off = std::fmax(off, (xk.linear() - x0.linear()).norm());
      } else {
        off = std::fmax(off, d.norm());
      }
    }
    CHECK_TEXT(off < 1e-6, (std::string(c.line) + " off the line by " + std::to_string(off)).c_str());
    CHECK(r.worst_speed_ratio(tr) <= 1.0);
  }
  CHECK(r.app.ctl->telemetry().cause == FaultCause::none);
}

// Jogging the tool outwards until the arm stretches: the jog slows near the elbow
// singularity and stops there with a message; no joint ever goes faster than its limit,
// and nothing faults.
TEST(ConsoleJog, AToolJogIntoASingularitySlowsThenStopsWithoutSpinningAJoint) {
  JogRig r;
  r.enable();
  CHECK(answer_ok(r.cmd("movej 0 -30 120 0 30 0")));
  CHECK(answer_ok(r.cmd("wait")));
  const kin::Pose x0 = r.x();
  CHECK(answer_ok(r.cmd("jog z + speed=60")));
  std::vector<kin::JointVector> tr;
  for (int i = 0; i < 60000 && r.state() == ArmState::jogging; ++i) {
    r.cycle();
    tr.push_back(r.q());
    if (i % 100 == 99) {
      r.cmd("jog");  // (runs a cycle too)
      tr.push_back(r.q());
    }
  }
  r.run_to_idle(5000);
  CHECK_TEXT(r.state() == ArmState::idle, (std::string(to_string(r.state())) + " " + r.events + " " + r.app.ctl->telemetry().fault_text).c_str());
  CHECK_TEXT(has(r.events, "jog stopped"), r.events.c_str());
  CHECK(r.app.ctl->telemetry().cause == FaultCause::none);
  CHECK((r.x().translation() - x0.translation()).norm() > 0.05);
  CHECK(r.worst_speed_ratio(tr) <= 1.0);
}

// GRBL jog lines streamed back to back run without stopping between them (a joystick
// sends short increments): the tool's speed never drops near zero until the last one.
TEST(ConsoleJog, GrblJogLinesRunBackToBackWithoutStopping) {
  JogRig r;
  r.working_pose();
  const kin::Pose x0 = r.x();
  std::vector<double> speed;
  kin::Pose prev = x0;
  for (int k = 0; k < 5; ++k) {
    const std::string a = r.cmd("$J=G91 X2 F600");  // 2 mm at 10 mm/s
    CHECK_TEXT(answer_ok(a), a.c_str());
    for (int i = 0; i < 150; ++i) {  // the next line comes before this one ends (0.2 s of travel)
      r.cycle();
      const kin::Pose x = r.x();
      speed.push_back((x.translation() - prev.translation()).norm() / 1e-3);
      prev = x;
    }
  }
  r.run_to_idle(5000);
  CHECK(((r.x().translation() - x0.translation()) - Eigen::Vector3d(0.010, 0, 0)).norm() < 1e-7);
  // after the start ramp, until the last line: always moving at a good part of F
  double slowest = 1;
  for (std::size_t i = 100; i < speed.size(); ++i) slowest = std::fmin(slowest, speed[i]);
  CHECK_TEXT(slowest > 0.005, std::to_string(slowest).c_str());
  // absolute, G90, in mm of the base frame
  char line[96];
  std::snprintf(line, sizeof line, "$J=G90 X%.3f Y%.3f F1200", x0.translation().x() * 1e3, x0.translation().y() * 1e3);
  CHECK(answer_ok(r.cmd(line)));
  r.run_to_idle(10000);
  CHECK((r.x().translation() - x0.translation()).norm() < 2e-6);  // (printed to 1 um)
}

// 0x85: the jog decelerates to rest at once; jog lines received but not run are answered, not run.
TEST(ConsoleJog, JogCancelStopsTheJogAndDropsQueuedJogLines) {
  JogRig r;
  r.working_pose();
  CHECK(answer_ok(r.cmd("$J=G91 X40 F1200")));
  for (int i = 0; i < 400; ++i) r.cycle();
  CHECK(r.state() == ArmState::jogging);
  r.s.out.clear();
  r.app.console->accept(r.s, "$J=G91 X5 F600\n\x85");  // a queued jog line, then the cancel
  const std::uint64_t c0 = r.app.ctl->telemetry().cycles;
  CHECK_TEXT(has(r.s.out, "error: estop '$J=G91 X5 F600' not run: jog cancelled (0x85)"), r.s.out.c_str());
  CHECK(r.s.lines.empty());
  const kin::Pose x_cancel = r.x();
  r.run_to_idle(3000);
  const std::uint64_t stopped = r.app.ctl->telemetry().cycles - c0;
  CHECK(r.state() == ArmState::idle);
  // 0x85 to standstill = the jerk-limited stopping time (+ at most a cycle): from 20 mm/s
  // with a jerk of 10 m/s^3 (acceleration 1 m/s^2 not reached) it is 2 sqrt(v / j) = 89.4 ms.
  const double t_stop_ms = 2e3 * std::sqrt(0.020 / kin::CartesianLimits{}.linear_jerk);
  CHECK_TEXT(std::fabs(static_cast<double>(stopped) - t_stop_ms) <= 1.5,
             (std::to_string(stopped) + " cycles, wanted " + std::to_string(t_stop_ms) + " ms").c_str());
  CHECK((r.x().translation() - x_cancel.translation()).norm() < 0.003);
  CHECK(r.app.ctl->telemetry().cause == FaultCause::none);
}

TEST(ConsoleJog, BadJogInputIsRefusedNothingMovesNothingQueuedIsLost) {
  JogRig r;
  r.enable();
  // a queued move, held before it starts: it must survive every refused line
  r.s.out.clear();
  r.app.console->feed(r.s, "movej 10 0 0 0 0 0\nhold\n");  // the hold comes in the cycle the move would start
  CHECK_TEXT(has(r.s.out, "ok queued") && has(r.s.out, "ok feed hold (queue held)"), r.s.out.c_str());
  const kin::JointVector q0 = r.q();
  struct Case {
    const char* line;
    const char* error;  ///< the answer starts with this
  };
  const Case cases[] = {
      {"jog j3", "error: arg_count jog j3 needs a value"},
      {"jog j3 +nan", "error: not_finite"},
      {"jog j3 1e309", "error: not_finite"},
      {"jog j3 +inf", "error: not_finite"},
      {"jog j3 0", "error: out_of_range"},
      {"jog j9 +5", "error: out_of_range jog: no joint 'j9'"},
      {"jog q +5", "error: bad_option jog: unknown axis 'q'"},
      {"jog j3 +5 speed=0", "error: out_of_range"},
      {"jog j3 +5 speed=abc", "error: bad_number"},
      {"jog j3 +5 frame=tool", "error: bad_option"},
      {"jog x +5 frame=moon", "error: bad_option"},
      {"jog x +5 foo=1", "error: bad_option"},
      {"jog stop now", "error: arg_count"},
      {"$J=G91 X10", "error: out_of_range $J: a jog line needs F"},
      {"$J=G91 X10 F0", "error: out_of_range"},
      {"$J=G91 X10 F-5", "error: out_of_range"},
      {"$J=G1 X10 F100", "error: unsupported"},
      {"$J=G91 F100", "error: arg_count $J: no axis words"},
      {"$J=G91 X1e3 F100", "error: unsupported"},  // G-code numbers have no exponent: E is a word
      {"$J=G91 Xnan F100", "error: bad_number"},
      {"$J G91 X1 F100", "error: bad_option"},
      {"$Q", "error: unknown_command"},
      {"$100=5", "error: unsupported"},
      {"jog j1 +5", "error: busy"},  // (valid, but a move is queued and held)
  };
  for (const Case& c : cases) {
    const std::string a = r.cmd(c.line);
    CHECK_TEXT(a.rfind(c.error, 0) == 0, (std::string(c.line) + " -> " + a).c_str());
    CHECK_TEXT(std::count(a.begin(), a.end(), '\n') == 1, (std::string(c.line) + ": one line: " + a).c_str());
    for (int i = 0; i < 20; ++i) r.cycle();
    CHECK_TEXT(r.q() == q0, c.line);
  }
  CHECK(r.app.ctl->telemetry().queued == 1);
  CHECK(answer_ok(r.cmd("resume")));
  CHECK(answer_ok(r.cmd("wait")));
  DOUBLES_EQUAL(10 * kDeg, r.q()[0], 1e-12);
}

TEST(ConsoleJog, AJogIsRefusedWhileAMoveRunsAndStopOrEstopAlwaysWin) {
  JogRig r;
  r.enable();
  CHECK(answer_ok(r.cmd("movej 30 0 0 0 0 0")));
  r.cycle();
  const std::string a = r.cmd("jog j2 +5");
  CHECK_TEXT(a.rfind("error: busy a move is running", 0) == 0, a.c_str());
  const std::string g = r.cmd("$J=G91 X5 F600");
  CHECK_TEXT(g.rfind("error: busy", 0) == 0, g.c_str());
  CHECK(answer_ok(r.cmd("wait")));
  DOUBLES_EQUAL(30 * kDeg, r.q()[0], 1e-12);
  // stop during a jog: the controller's ramp, then idle
  CHECK(answer_ok(r.cmd("jog j1 +")));
  for (int i = 0; i < 100; ++i) r.cycle();
  const std::string st = r.cmd("stop");
  CHECK_TEXT(answer_ok(st), st.c_str());
  CHECK(r.state() == ArmState::stopping || r.state() == ArmState::idle);
  r.run_to_idle(3000);
  CHECK(r.state() == ArmState::idle);
  // e-stop during a jog
  CHECK(answer_ok(r.cmd("jog j1 -")));
  for (int i = 0; i < 100; ++i) r.cycle();
  r.cmd("estop");
  for (int i = 0; i < 3000 && r.state() != ArmState::estop; ++i) r.cycle();
  CHECK(r.state() == ArmState::estop);
  // and a jog is refused there
  const std::string j = r.cmd("jog j1 +5");
  CHECK_TEXT(j.rfind("error: fault", 0) == 0, j.c_str());
}

// A jog answers `ok` when the arm moves and `error` when it does not: an increment beyond the
// joint's whole range, a tool rotation of half a turn or more (it would be taken the short
// way, the wrong way round), and a jog that would outlast motion.max_move_duration_s are
// refused and nothing moves; a rotation below half a turn turns by the amount and sign given.
TEST(ConsoleJog, AbsurdJogsAreRefusedAndRotationsTurnTheWayAsked) {
  JogRig r;
  r.working_pose();
  const kin::JointVector q0 = r.q();
  const char* refused[] = {"jog j1 +1e300 speed=100", "jog j1 -400", "jog rz +350", "jog rz +190", "jog rz +360",
                           "jog rz +1e300", "jog rx -180", "$J=G91 C200 F600", "$J=G91 X50 F0.6", "jog x +1e300"};
  for (const char* j : refused) {
    const std::string a = r.cmd(j);
    CHECK_TEXT(a.rfind("error: ", 0) == 0, (std::string(j) + " -> " + a).c_str());
    for (int i = 0; i < 50; ++i) r.cycle();
    CHECK_TEXT(r.state() == ArmState::idle && (r.q() - q0).norm() == 0, j);
  }
  // +170 about the tool's z: the orientation turns by +170 deg (not -190)
  const kin::Pose x0 = r.x();
  const std::string a = r.cmd("jog rz +170 frame=tool speed=100");
  CHECK_TEXT(answer_ok(a), a.c_str());
  r.run_to_idle(60000);
  const Eigen::Matrix3d d = x0.linear().transpose() * r.x().linear();  // in the tool frame
  const Eigen::AngleAxisd aa(d);
  DOUBLES_EQUAL(170.0, aa.angle() / kDeg, 0.01);
  CHECK(aa.axis().z() > 0.999);
}
