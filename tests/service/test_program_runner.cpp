// SPDX-License-Identifier: Apache-2.0
// The arm service's program runner, driven through its typed calls with no console in the
// loop: a ProgramSpec whose steps a test executor queues through ArmService::move, typed
// program status, pause / step / abort, and the program events in the service's stream.
// Expected values come from the spec and the requests, never from the runner's code.
#include <cmath>
#include <string>
#include <vector>

#include "../console/console_rig.hpp"
#include "../program/tmp_dir.hpp"
#include "servoarm/program/program.hpp"
#include "servoarm/service/arm_service.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;

namespace {
constexpr double kDeg = M_PI / 180.0;

kin::JointVector joints(std::initializer_list<double> deg) {
  kin::JointVector q(static_cast<int>(deg.size()));
  int j = 0;
  for (double d : deg) q[j++] = d * kDeg;
  return q;
}

/// A program of joint moves (and `wait` where a goal is empty) in file "p.arm", one step a line.
struct Prog {
  std::vector<kin::JointVector> goals;
  ProgramSpec spec() const {
    ProgramSpec s;
    s.name = "p";
    s.files = {"p.arm"};
    for (std::size_t i = 0; i < goals.size(); ++i)
      s.steps.push_back({goals[i].size() == 0 ? StepClass::wait : StepClass::motion, 0, static_cast<int>(10 + i)});
    return s;
  }
  StepExecutor exec(ArmService& svc) const {
    return [&svc, this](std::size_t i) {
      StepOutcome o;
      MoveJoints m;
      m.goal = goals[i];
      m.speed_pct = 100;
      const MoveResult r = svc.move(m, MoveContext{});
      if (!r.ok()) {
        o.error = r.error;
        o.reason = std::string("refused: ") + to_string(r.refusal);
      }
      return o;
    };
  }
};

/// Run control cycles (the runner ticking) until `done` or a bound.
template <class F>
void run_until(test::ConsoleRig& r, F done, int max_cycles = 60000) {
  for (int i = 0; i < max_cycles && !done(); ++i) {
    r.cycle();
    r.app.console->service().program_tick();
  }
}

std::vector<ArmEvent> program_events(const ArmService& svc, std::uint64_t after) {
  std::vector<ArmEvent> out;
  for (const ArmEvent& e : svc.events_since(after).events)
    if (e.kind == ArmEventKind::program) out.push_back(e);
  return out;
}
}  // namespace

TEST_GROUP(ProgramRunner){};

// A program of two moves around a `wait` runs to its end: the status names the running
// step's place while it runs, the stream has started, a step event for each motion step
// and `ended done` with the step count and the time it took; the arm ends at the last goal.
TEST(ProgramRunner, AProgramRunsItsStepsAndEndsWithTypedEvents) {
  test::ConsoleRig r;
  r.enable();
  ArmService& svc = r.app.console->service();
  Prog p;
  p.goals = {joints({10, -40, 170, 5, 40, -5}), kin::JointVector(), joints({-10, -50, 160, 0, 30, 10})};
  const std::uint64_t seq0 = svc.next_event_seq() - 1;
  const std::uint64_t c0 = r.app.ctl->telemetry().cycles;
  const ProgramResult started = svc.run_program(p.spec(), p.exec(svc));
  CHECK_TEXT(started.ok(), to_string(started.refusal));
  const ProgramStatus st = svc.program_status();
  CHECK(st.state == RunState::running);
  STRCMP_EQUAL("p", st.name.c_str());
  LONGS_EQUAL(3, st.steps);
  LONGS_EQUAL(0, st.step);
  STRCMP_EQUAL("p.arm", st.file.c_str());
  LONGS_EQUAL(10, st.line);
  run_until(r, [&] { return svc.run_state() == RunState::idle; });
  CHECK(svc.run_state() == RunState::idle);
  const std::uint64_t c1 = r.app.ctl->telemetry().cycles;
  const std::vector<ArmEvent> ev = program_events(svc, seq0);
  LONGS_EQUAL(4, ev.size());
  CHECK(ev[0].program == ProgramPhase::started);
  CHECK(ev[1].program == ProgramPhase::step);
  LONGS_EQUAL(0, ev[1].step);
  LONGS_EQUAL(10, ev[1].line);
  CHECK(ev[2].program == ProgramPhase::step);
  LONGS_EQUAL(2, ev[2].step);
  LONGS_EQUAL(12, ev[2].line);
  const ArmEvent& end = ev[3];
  CHECK(end.program == ProgramPhase::ended);
  CHECK(end.end == ProgramEnd::done);
  LONGS_EQUAL(3, end.steps);
  CHECK(end.seconds > 0 && end.seconds <= static_cast<double>(c1 - c0) * r.app.ctl->period_s() + 1e-9);
  STRCMP_EQUAL("p", std::string(svc.event_program(end).program).c_str());
  for (int j = 0; j < 6; ++j) DOUBLES_EQUAL(p.goals[2][j], r.app.ctl->telemetry().q_cmd[static_cast<std::size_t>(j)], 1e-6);
}

// A step the front end refuses ends the program: `ended step_refused` at that step with its
// error and the front end's line; the arm stops (nothing more queued), the status is idle.
TEST(ProgramRunner, ARefusedStepEndsTheProgramWithItsErrorAndLine) {
  test::ConsoleRig r;
  r.enable();
  ArmService& svc = r.app.console->service();
  Prog p;
  kin::JointVector bad = joints({0, -45, 180, 0, 45, 0});
  bad[3] = r.app.ctl->limits().upper[3] + 0.1;  // beyond joint 4's limit: the move is refused
  p.goals = {joints({10, -40, 170, 5, 40, -5}), bad, joints({-10, -50, 160, 0, 30, 10})};
  const std::uint64_t seq0 = svc.next_event_seq() - 1;
  CHECK(svc.run_program(p.spec(), p.exec(svc)).ok());
  run_until(r, [&] { return svc.run_state() == RunState::idle; });
  const std::vector<ArmEvent> ev = program_events(svc, seq0);
  CHECK(!ev.empty());
  const ArmEvent& end = ev.back();
  CHECK(end.program == ProgramPhase::ended);
  CHECK_TEXT(end.end == ProgramEnd::step_refused, to_string(end.end));
  LONGS_EQUAL(1, end.step);
  LONGS_EQUAL(11, end.line);
  CHECK(end.error == CmdError::limits);
  STRCMP_EQUAL("refused: joint_limit", std::string(svc.event_detail(end)).c_str());
  STRCMP_EQUAL("p.arm", std::string(svc.event_program(end).file).c_str());
  CHECK(svc.program_status().state == RunState::idle);
  run_until(r, [&] { return r.app.ctl->telemetry().state == ArmState::idle; });
  CHECK(r.app.ctl->motions().empty());
}

// Pause, step and abort as typed requests: paused once the queued motion is done, a step
// feeds exactly one more motion and pauses again, abort ends it (`ended abort`) and stops
// the arm. Status queries in between change nothing; requests without a program are
// refused as no_program, a second run while one runs as running.
TEST(ProgramRunner, PauseStepAndAbortAreTypedRequests) {
  test::ConsoleRig r;
  r.enable();
  ArmService& svc = r.app.console->service();
  CHECK(svc.program_pause().refusal == ProgramRefusal::no_program);
  CHECK(svc.program_step().refusal == ProgramRefusal::no_program);
  CHECK(svc.program_abort().refusal == ProgramRefusal::no_program);
  Prog p;
  p.goals = {joints({10, -40, 170, 5, 40, -5}), joints({0, -45, 175, 0, 40, 0}), joints({-10, -50, 160, 0, 30, 10}),
             joints({5, -45, 170, 0, 45, 0})};
  const std::uint64_t seq0 = svc.next_event_seq() - 1;
  CHECK(svc.run_program(p.spec(), p.exec(svc)).ok());
  const ProgramResult again = svc.run_program(p.spec(), p.exec(svc));
  CHECK(again.refusal == ProgramRefusal::running);
  const ProgramResult paused = svc.program_pause();
  CHECK(paused.ok());
  CHECK(paused.status.state == RunState::pausing);
  run_until(r, [&] { return svc.run_state() == RunState::paused; });
  CHECK(svc.run_state() == RunState::paused);
  const std::uint32_t fed = svc.last_motion_id();
  const ProgramStatus a = svc.program_status(), b = svc.program_status();
  CHECK(a.state == b.state && a.step == b.step && a.line == b.line);
  LONGS_EQUAL(fed, svc.last_motion_id());
  const ProgramResult one = svc.program_step();
  CHECK(one.ok());
  run_until(r, [&] { return svc.run_state() == RunState::paused; });
  CHECK(svc.run_state() == RunState::paused);
  LONGS_EQUAL(fed + 1, svc.last_motion_id());  // exactly one motion fed
  const ProgramResult ab = svc.program_abort();
  CHECK(ab.ok());
  CHECK(svc.run_state() == RunState::idle);
  const std::vector<ArmEvent> ev = program_events(svc, seq0);
  CHECK(ev.back().program == ProgramPhase::ended);
  CHECK(ev.back().end == ProgramEnd::abort);
}

// run needs the arm at rest, nothing queued and every joint homed: a disabled arm is refused
// as arm_not_ready with its state; nothing starts.
TEST(ProgramRunner, RunIsRefusedWhenTheArmIsNotReady) {
  test::ConsoleRig r;
  ArmService& svc = r.app.console->service();
  Prog p;
  p.goals = {joints({10, -40, 170, 5, 40, -5})};
  const ProgramResult res = svc.run_program(p.spec(), p.exec(svc));
  CHECK(res.refusal == ProgramRefusal::arm_not_ready);
  CHECK(res.error == CmdError::bad_state);
  CHECK(res.arm != ArmState::idle);
  CHECK(svc.run_state() == RunState::idle);
  CHECK(r.app.ctl->motions().empty());
}

// An e-stop while a program runs ends it as `ended estop` (not asked by a realtime byte).
TEST(ProgramRunner, AnEstopEndsTheProgram) {
  test::ConsoleRig r;
  r.enable();
  ArmService& svc = r.app.console->service();
  Prog p;
  p.goals = {joints({10, -40, 170, 5, 40, -5}), joints({-10, -50, 160, 0, 30, 10})};
  const std::uint64_t seq0 = svc.next_event_seq() - 1;
  CHECK(svc.run_program(p.spec(), p.exec(svc)).ok());
  for (int i = 0; i < 50; ++i) r.cycle();
  CHECK(svc.control(RequestOp::estop).ok());
  run_until(r, [&] { return svc.run_state() == RunState::idle; }, 2000);
  const std::vector<ArmEvent> ev = program_events(svc, seq0);
  CHECK(!ev.empty());
  CHECK(ev.back().program == ProgramPhase::ended);
  CHECK_TEXT(ev.back().end == ProgramEnd::estop, to_string(ev.back().end));
  CHECK(!ev.back().realtime);
}

namespace {
/// Load program file `name` holding `text` (the rig's units: mm and degrees).
prog::Program load(test::ConsoleRig& r, const std::string& dir, const std::string& name, const std::string& text) {
  test::write_file(dir + "/" + name, text);
  prog::ProgramContext ctx;
  ctx.chain = &r.app.chain;
  ctx.units = units_of(r.app.chain);
  ctx.dir = dir;
  ctx.points = &r.app.console->service().points();
  prog::Program p;
  const std::string e = prog::load_program(dir + "/" + name, ctx, p);
  CHECK_TEXT(e.empty(), e.c_str());
  return p;
}
}  // namespace

// A loaded program's typed steps run by the service itself (no console executes a step, no
// answer text exists): two joint moves around `wait` and a dwell end where the last movej
// goes (its joints, degrees in the file, in SI), `ended done` with every step counted.
TEST(ProgramRunner, AParsedProgramRunsOnTheServiceWithNoConsole) {
  test::ConsoleRig r;
  r.enable();
  ArmService& svc = r.app.console->service();
  const std::string dir = test::make_tmp_dir();
  prog::Program p = load(r, dir, "p.arm", "movej 10 -40 170 5 40 -5 speed=100\nwait\ndwell 0.1\nmovej -10 -50 160 0 30 10 speed=100\n");
  const std::uint64_t seq0 = svc.next_event_seq() - 1;
  const ProgramResult started = svc.run_program("p", std::move(p), units_of(r.app.chain));
  CHECK_TEXT(started.ok(), to_string(started.refusal));
  LONGS_EQUAL(4, started.status.steps);
  run_until(r, [&] { return svc.run_state() == RunState::idle; });
  const std::vector<ArmEvent> ev = program_events(svc, seq0);
  CHECK(!ev.empty());
  CHECK(ev.back().program == ProgramPhase::ended);
  CHECK_TEXT(ev.back().end == ProgramEnd::done, to_string(ev.back().end));
  LONGS_EQUAL(4, ev.back().steps);
  const kin::JointVector last = joints({-10, -50, 160, 0, 30, 10});
  for (int j = 0; j < 6; ++j) DOUBLES_EQUAL(last[j], r.app.ctl->telemetry().q_cmd[static_cast<std::size_t>(j)], 1e-6);
  test::remove_tree(dir);
}

// A step the service refuses ends the program with the step's typed error: a movej beyond
// joint 3's limit is `limits` at its line, nothing after it queued.
TEST(ProgramRunner, AParsedProgramsFailingStepEndsItWithTheTypedError) {
  test::ConsoleRig r;
  r.enable();
  ArmService& svc = r.app.console->service();
  const std::string dir = test::make_tmp_dir();
  prog::Program p = load(r, dir, "p.arm", "movej 10 -40 170 5 40 -5 speed=100\nmovej 0 -45 999 0 45 0\nmovej 0 0 0 0 0 0\n");
  const std::uint64_t seq0 = svc.next_event_seq() - 1;
  CHECK(svc.run_program("p", std::move(p), units_of(r.app.chain)).ok());
  run_until(r, [&] { return svc.run_state() == RunState::idle; });
  const std::vector<ArmEvent> ev = program_events(svc, seq0);
  CHECK(!ev.empty());
  const ArmEvent& end = ev.back();
  CHECK_TEXT(end.end == ProgramEnd::step_refused, to_string(end.end));
  LONGS_EQUAL(1, end.step);
  LONGS_EQUAL(2, end.line);
  CHECK_TEXT(end.error == CmdError::limits, to_string(end.error));
  run_until(r, [&] { return r.app.ctl->telemetry().state == ArmState::idle; });
  CHECK(r.app.ctl->motions().empty());
  test::remove_tree(dir);
}

// A program's movel and G1 run in the active tool and user frame, as a movel request does
// (the service's move context: the active tool's chain and IK, coordinates in the active
// frame): with a 100 mm tool and a frame shifted and turned about z, the checked and the run
// program both end with the tool point at the program's coordinates in that frame, where a
// movel through ArmService::move with the same tool and frame goes.
TEST(ProgramRunner, AProgramsLinesRunInTheActiveToolAndUserFrame) {
  test::ConsoleRig r;
  r.enable();
  ArmService& svc = r.app.console->service();
  CHECK(r.app.console->service().move([] {
    MoveJoints m;
    m.goal = joints({10, -40, 170, 5, 40, -5});
    m.speed_pct = 100;
    return m;
  }(), MoveContext{}).ok());
  run_until(r, [&] { return r.app.ctl->telemetry().state == ArmState::idle && r.app.ctl->motions().empty(); });
  NamedPose t;
  t.name = "pen";
  t.pose = kin::Pose::Identity();
  t.pose.translation() = Eigen::Vector3d(0, 0, 0.1);
  CHECK(svc.define_tool(t).ok());
  CHECK(svc.select_tool("pen").ok());
  NamedPose f;
  f.name = "table";
  f.pose = kin::Pose::Identity();
  f.pose.translation() = Eigen::Vector3d(0.1, -0.05, 0.02);
  f.pose.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  CHECK(svc.define_frame(f).ok());
  CHECK(svc.select_frame("table").ok());
  const ArmStatus s0 = svc.status();
  STRCMP_EQUAL("pen", s0.tool.c_str());
  STRCMP_EQUAL("table", s0.frame.c_str());
  // 30 mm along the frame's x and -20 mm along its z from where the pen's point is now
  const Eigen::Vector3d goal = s0.pose_in_frame.translation() + Eigen::Vector3d(0.03, 0, -0.02);
  char line[160];
  std::snprintf(line, sizeof line, "movel %.4f %.4f %.4f speed=50\n", goal.x() * 1e3, goal.y() * 1e3, goal.z() * 1e3);
  const std::string dir = test::make_tmp_dir();
  prog::Program p = load(r, dir, "p.arm", line);
  const ProgramCheckResult chk = svc.check_program(p, units_of(r.app.chain));
  CHECK_TEXT(chk.ok(), chk.reason.c_str());
  // the check's dry run ends where the pen's point is at the goal in the frame
  CHECK(svc.run_program("p", std::move(p), units_of(r.app.chain)).ok());
  run_until(r, [&] { return svc.run_state() == RunState::idle; });
  run_until(r, [&] { return r.app.ctl->telemetry().state == ArmState::idle && r.app.ctl->motions().empty(); });
  const ArmStatus s1 = svc.status();
  std::printf("\n  program movel with tool pen (z 100 mm) in frame table: the pen's point ends %.3f mm from the program's "
              "coordinates in the frame\n", (s1.pose_in_frame.translation() - goal).norm() * 1e3);
  CHECK((s1.pose_in_frame.translation() - goal).norm() < 1e-4);
  CHECK(s1.pose_in_frame.linear().isApprox(s0.pose_in_frame.linear(), 1e-4));
  // a G-code G1 likewise (mm, G90), back to where it started
  const Eigen::Vector3d back = s0.pose_in_frame.translation();
  std::snprintf(line, sizeof line, "G21 G90\nG1 X%.4f Y%.4f Z%.4f F1500\n", back.x() * 1e3, back.y() * 1e3, back.z() * 1e3);
  prog::Program g = load(r, dir, "p.gcode", line);
  CHECK(svc.check_program(g, units_of(r.app.chain)).ok());
  CHECK(svc.run_program("p", std::move(g), units_of(r.app.chain)).ok());
  run_until(r, [&] { return svc.run_state() == RunState::idle; });
  run_until(r, [&] { return r.app.ctl->telemetry().state == ArmState::idle && r.app.ctl->motions().empty(); });
  CHECK((svc.status().pose_in_frame.translation() - back).norm() < 1e-4);
  test::remove_tree(dir);
}
