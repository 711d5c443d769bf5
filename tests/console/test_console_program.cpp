// SPDX-License-Identifier: Apache-2.0
// Teach points and programs through the console, on the puma560 with virtual
// drives (console_rig.hpp: mm and degrees): teach / points / point delete / movej @NAME /
// movel @NAME, run (whole-program check first: a bad line 7 answers line 7 and nothing
// moves), pause / step / resume / abort, stop and faults ending a program with its line,
// an unhomed arm refused naming the joints, $C + run = check only, record -> replay
// within the tolerance of the recorded path, and digital outputs on the virtual drives. Expected values come from the chain's FK and
// the test's own samples, never from the console's code.
#include <unistd.h>
#include <cmath>
#include <string>
#include <vector>

#include "console_rig.hpp"
#include "../program/tmp_dir.hpp"
#include "servoarm/armctl/cli_program.hpp"
#include "servoarm/program/program.hpp"
#include "servoarm/program/points.hpp"
#include "servoarm/lang/text.hpp"
#include "servoarm/sim/virtual_drive.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;
using test::answer_ok;

namespace {
constexpr double kDeg = M_PI / 180.0;
bool has(const std::string& s, const std::string& p) { return s.find(p) != std::string::npos; }

// `armctl program check`'s cycle time (fw::check_program, the offline planner) of program
// `name` in the rig's folder, from rest at `from`, with the rig's configuration: what the
// measured run is compared with.
double offline_cycle(const App& app, const std::string& dir, const std::string& name, const kin::JointVector& from,
                     int* blended = nullptr) {
  kin::Chain chain = app.chain;
  ProgramCheckOptions opt;
  const std::string ce = apply_config(app.cfg, chain, opt);
  CHECK_TEXT(ce.empty(), ce.c_str());
  prog::ProgramContext ctx;
  ctx.chain = &chain;
  ctx.units = units_of(chain);
  ctx.dir = dir;
  prog::Program program;
  const std::string e = prog::load_program(dir + "/" + name, ctx, program);
  CHECK_TEXT(e.empty(), e.c_str());
  const ProgramCheck ck = check_program(chain, program, nullptr, from, opt);
  CHECK_TEXT(ck.ok, ck.error.c_str());
  if (blended != nullptr) *blended = ck.blended_corners;
  return ck.cycle_time;
}

FwConfig with_dir(const std::string& dir, FwConfig c = {}) {
  c.programs_dir = dir;
  c.programs_points_file = dir + "/points.toml";
  return c;
}

struct ProgRig : test::ConsoleRig {
  std::string dir;
  std::string events;
  explicit ProgRig(const std::string& d, FwConfig c = {}) : test::ConsoleRig(with_dir(d, c)), dir(d) {}
  Telemetry tel() const { return app.ctl->telemetry(); }
  kin::JointVector q_cmd() const {
    const Telemetry t = tel();
    kin::JointVector v(6);
    for (int j = 0; j < 6; ++j) v[j] = t.q_cmd[static_cast<std::size_t>(j)];
    return v;
  }
  kin::JointVector q_act() const {
    const Telemetry t = tel();
    kin::JointVector v(6);
    for (int j = 0; j < 6; ++j) v[j] = t.q_act[static_cast<std::size_t>(j)];
    return v;
  }
  /// One control cycle, then the console's program runner and event drain.
  void step1() {
    cycle();
    events += app.console->drain_events();
  }
  /// Cycles until pred() (true) or max cycles (false).
  template <class P>
  bool until(P pred, int max = 60000) {
    for (int i = 0; i < max; ++i) {
      if (pred()) return true;
      step1();
    }
    return pred();
  }
  bool program_ended(int max = 60000) {
    return until([&] { return app.console->run_state() == RunState::idle; }, max);
  }
  bool at_rest(int max = 60000) {
    return until([&] { return tel().state == ArmState::idle && app.ctl->motions().empty(); }, max);
  }
  void write(const std::string& name, const std::string& text) { test::write_file(dir + "/" + name, text); }
};

struct Tmp {
  std::string dir = test::make_tmp_dir();
  ~Tmp() { test::remove_tree(dir); }
};

}  // namespace

TEST_GROUP(ConsoleProgram){};

// teach stores the measured joints (and the tool pose), kept in the points file; movej @NAME
// goes back to them exactly; movel @NAME ends where FK of them puts the tool; point delete.
TEST(ConsoleProgram, TeachThenMovejAtNameReachesIt) {
  Tmp tmp;
  ProgRig r(tmp.dir);
  r.enable();
  CHECK(answer_ok(r.cmd("movej 20 -40 160 10 -50 30")));
  CHECK(answer_ok(r.cmd("wait")));
  for (int i = 0; i < 300; ++i) r.step1();  // settle: the measured joints are where the setpoint is
  const kin::JointVector taught = r.q_act();
  const std::string a = r.cmd("teach pick");
  CHECK_TEXT(answer_ok(a) && has(a, "taught pick") && has(a, "tool=tool0 frame=base"), a.c_str());
  // kept in the points file, atomically, as the loader reads it
  prog::PointsData d;
  STRCMP_EQUAL("", prog::load_points_file(tmp.dir + "/points.toml", 6, d).c_str());
  LONGS_EQUAL(1, d.points.size());
  CHECK((d.points[0].q - taught).norm() == 0);
  kin::Pose flange;
  kin::forward(r.app.chain, taught, flange);
  CHECK((d.points[0].pose.translation() - flange.translation()).norm() < 1e-12);
  CHECK(has(r.cmd("points"), "pick joints=["));
  // away, then back with movej @pick: exactly the taught joints
  CHECK(answer_ok(r.cmd("movej 0 -45 180 0 45 0")));
  CHECK(answer_ok(r.cmd("wait")));
  CHECK(answer_ok(r.cmd("movej @pick speed=80")));
  CHECK(answer_ok(r.cmd("wait")));
  CHECK_TEXT((r.q_cmd() - taught).norm() < 1e-9, r.s.out.c_str());
  // away, then movel @pick: the tool point where FK(taught) puts it
  CHECK(answer_ok(r.cmd("movej 25 -40 160 10 -50 30")));
  CHECK(answer_ok(r.cmd("wait")));
  const std::string ml = r.cmd("movel @pick speed=100");
  CHECK_TEXT(answer_ok(ml), ml.c_str());
  CHECK(answer_ok(r.cmd("wait")));
  kin::Pose end;
  kin::forward(r.app.chain, r.q_cmd(), end);
  CHECK((end.translation() - flange.translation()).norm() < 1e-6);
  // bad names and unknown points: one line, nothing moves
  CHECK(has(r.cmd("movej @nowhere"), "error: bad_option movej: no point 'nowhere'"));
  CHECK(has(r.cmd("movej @pick 1 2 3"), "error: arg_count"));
  CHECK(has(r.cmd("teach 9lives"), "error: bad_option"));
  CHECK(answer_ok(r.cmd("point delete pick")));
  CHECK(has(r.cmd("movej @pick"), "error: bad_option"));
  STRCMP_EQUAL("", prog::load_points_file(tmp.dir + "/points.toml", 6, d).c_str());
  LONGS_EQUAL(0, d.points.size());
  CHECK(has(r.cmd("point delete pick"), "error: bad_option"));
}

// A points file that cannot be written: the point is not taught, the old file is kept.
TEST(ConsoleProgram, ATeachThatCannotBeSavedIsNotMade) {
  Tmp tmp;
  FwConfig c;
  c.programs_dir = tmp.dir;
  c.programs_points_file = tmp.dir + "/no/such/dir/points.toml";
  test::ConsoleRig r(c);
  r.enable();
  const std::string a = r.cmd("teach p");
  CHECK_TEXT(has(a, "error: storage teach:"), a.c_str());
  CHECK(has(r.cmd("points"), "ok 0 points"));
}

// run checks the whole program first: the first bad line is answered with file:line and the
// reason, and nothing moves (the positions, the queue and the motion ids unchanged).
TEST(ConsoleProgram, RunOfAProgramWithABadLine7AnswersLine7AndNothingMoves) {
  struct Case {
    const char* line7;
    const char* expect;
  };
  const Case cases[] = {
      {"movej 200 -45 180 0 45 0", "limits"},  // joint 1 outside [-160, 160]
      {"movel 3000 0 0", "unreachable"},      // out of reach
      {"frobnicate 1 2", "unknown command"},   // the loader's parser
      {"movej @nowhere", "unknown point"},
      {"enable", "not run inside a program"},
  };
  Tmp tmp;
  ProgRig r(tmp.dir);
  r.enable();
  for (const Case& k : cases) {
    r.write("bad.arm", std::string("movej 0 -45 180 0 45 0\n"
                                   "movej 10 -45 180 0 45 0\n"
                                   "# a comment\n"
                                   "movej 20 -45 180 0 45 0 blend=5\n"
                                   "dwell 0.1\n"
                                   "movej 30 -45 180 0 45 0\n") +
                           k.line7 + "\nmovej 0 -45 180 0 45 0\n");
    const kin::JointVector q0 = r.q_act();
    const std::uint32_t id0 = r.app.console->last_motion_id();
    const std::string a = r.cmd("run bad");
    const std::string want = "error: program " + tmp.dir + "/bad.arm:7: ";
    CHECK_TEXT(has(a, want) && has(a, k.expect) && has(a, "nothing moved"), (std::string(k.line7) + " -> " + a).c_str());
    CHECK(r.app.console->run_state() == RunState::idle);
    for (int i = 0; i < 500; ++i) r.step1();
    CHECK_TEXT((r.q_act() - q0).norm() < 1e-9, k.line7);
    LONGS_EQUAL(id0, r.app.console->last_motion_id());
    LONGS_EQUAL(0, r.tel().queued);
  }
  // G-code files too, and a program that does not exist
  CHECK(answer_ok(r.cmd("movej 20 -40 160 10 -50 30")));
  CHECK(answer_ok(r.cmd("wait")));
  r.write("bad.nc", "G21 G91\nG1 X10 F3000\nG1 X3000\n");
  const std::string g = r.cmd("run bad.nc");
  CHECK_TEXT(has(g, "bad.nc:3: unreachable"), g.c_str());
  CHECK(has(r.cmd("run none"), "error: program run: no program 'none'"));
  CHECK(has(r.cmd("run ../x"), "error: bad_option"));
  // $C (check mode): run checks only
  r.write("good.arm", "movej 0 -45 180 0 45 0\nmovej 10 -45 180 0 45 0\n");
  CHECK(answer_ok(r.cmd("$C")));
  for (int i = 0; i < 500; ++i) r.step1();  // the measured joints settle after the last move
  const kin::JointVector q0 = r.q_act();
  const std::string c = r.cmd("run good");
  CHECK_TEXT(answer_ok(c) && has(c, "checked good: 2 steps: 2 moves (2 joint, 0 linear), 0 dwells"), c.c_str());
  const std::string cb = r.cmd("run bad");
  CHECK_TEXT(has(cb, "bad.arm:7: enable is not run inside a program"), cb.c_str());
  CHECK(answer_ok(r.cmd("$C")));
  for (int i = 0; i < 300; ++i) r.step1();
  CHECK((r.q_act() - q0).norm() < 1e-6);
  CHECK(has(r.cmd("programs"), "bad.arm\nbad.nc\ngood.arm\nok 3 programs"));
}

// armfw's `run` (and its check mode) and `armctl program check` count a program the same
// way, in the same words: steps, moves (joint, linear), dwells, "1 dwell" in the singular.
TEST(ConsoleProgram, RunAndProgramCheckCountAlike) {
  Tmp tmp;
  ProgRig r(tmp.dir);
  r.enable();
  r.write("c.arm", "movej 0 -45 180 0 45 0\ndwell 0.1\nwait\nmovej 10 -45 180 0 45 0\n");
  const std::string want = "4 steps: 2 moves (2 joint, 0 linear), 1 dwell";
  CHECK(answer_ok(r.cmd("$C")));
  const std::string c = r.cmd("run c");
  CHECK_TEXT(answer_ok(c) && has(c, "checked c: " + want), c.c_str());
  CHECK(answer_ok(r.cmd("$C")));
  const std::string a = r.cmd("run c");
  CHECK_TEXT(answer_ok(a) && has(a, "running c: " + want), a.c_str());
}

// A program runs to its end; status and the report name the program, the line, the state.
// pause stops it after the moves handed over; step runs exactly one more motion; resume ends it.
TEST(ConsoleProgram, PauseStepResumeAndTheReports) {
  Tmp tmp;
  ProgRig r(tmp.dir);
  r.enable();
  std::string p;
  for (int i = 0; i < 8; ++i) p += i % 2 ? "movej 0 -45 170 0 45 0\n" : "movej 20 -35 160 10 35 10\n";
  r.write("p.arm", "# eight moves\n" + p);
  const std::string a = r.cmd("run p");
  CHECK_TEXT(answer_ok(a) && has(a, "running p: 8 steps: 8 moves (8 joint, 0 linear), 0 dwells"), a.c_str());
  for (int i = 0; i < 200; ++i) r.step1();
  const std::string st = r.cmd("status");
  CHECK_TEXT(has(st, "program=p program_state=running line=" + tmp.dir + "/p.arm:2"), st.c_str());
  CHECK(has(r.app.console->grbl_report(), "|Pgm:p,running," + tmp.dir + "/p.arm:2>"));
  CHECK(has(r.cmd("run p"), "error: bad_state"));            // one program at a time
  CHECK(has(r.cmd("teach x"), "error: bad_state teach: refused while program p"));
  CHECK(answer_ok(r.cmd("pause")));
  CHECK(r.until([&] { return r.app.console->run_state() == RunState::paused; }));
  CHECK(r.at_rest());
  const std::uint32_t done = r.tel().done_id;
  CHECK(done >= 1 && done <= 2);  // the running move and the one queued behind it
  const kin::JointVector held = r.q_cmd();
  for (int i = 0; i < 1000; ++i) r.step1();
  CHECK((r.q_cmd() - held).norm() == 0);
  CHECK(has(r.cmd("status"), "program_state=paused"));
  // step: one motion, then paused again
  CHECK(answer_ok(r.cmd("step")));
  CHECK(r.until([&] { return r.tel().done_id == done + 1 && r.app.console->run_state() == RunState::paused; }));
  for (int i = 0; i < 500; ++i) r.step1();
  LONGS_EQUAL(done + 1, r.tel().done_id);
  // resume: to the end
  CHECK(answer_ok(r.cmd("resume")));
  CHECK(r.program_ended());
  CHECK_TEXT(has(r.events, "program: p done: 8 steps in"), r.events.c_str());
  LONGS_EQUAL(8, r.tel().done_id);
  // `!` mid-move holds at once and pauses the program; `~` goes on
  r.events.clear();
  CHECK(answer_ok(r.cmd("run p")));
  for (int i = 0; i < 300; ++i) r.step1();
  r.app.console->feed(r.s, "!");
  for (int i = 0; i < 1500; ++i) r.step1();
  CHECK(r.app.console->run_state() == RunState::paused);
  const kin::JointVector h2 = r.q_cmd();
  for (int i = 0; i < 500; ++i) r.step1();
  CHECK((r.q_cmd() - h2).norm() == 0);
  r.app.console->feed(r.s, "~");
  // `wait` typed at the console answers when the program has ended (not between its moves)
  CHECK(answer_ok(r.cmd("wait")));
  CHECK(r.app.console->run_state() == RunState::idle);
  r.step1();
  CHECK(has(r.events, "program: p done"));
  LONGS_EQUAL(16, r.tel().done_id);
}

// abort, stop and an e-stop end the program saying where; the rest is dropped.
TEST(ConsoleProgram, AbortStopAndEstopDropTheRest) {
  Tmp tmp;
  ProgRig r(tmp.dir);
  r.enable();
  r.write("p.arm", "movej 0 -45 170 0 45 0\nmovej 20 -35 160 10 35 10\nmovej 0 -45 170 0 45 0\nmovej 20 -35 160 10 35 10\n");
  const char* how[] = {"abort", "stop", "estop"};
  for (const char* h : how) {
    r.events.clear();
    if (r.tel().state != ArmState::idle) {
      CHECK(answer_ok(r.cmd("reset")));
      r.enable();
    }
    const std::uint32_t id0 = r.app.console->last_motion_id();
    CHECK(answer_ok(r.cmd("run p")));
    for (int i = 0; i < 300; ++i) r.step1();
    const std::string a = r.cmd(h);
    CHECK_TEXT(answer_ok(a), (std::string(h) + ": " + a).c_str());
    CHECK(r.program_ended(10));
    for (int i = 0; i < 5000; ++i) r.step1();
    CHECK_TEXT(has(r.events, "program: p aborted at " + tmp.dir + "/p.arm:1: "), (std::string(h) + ": " + r.events).c_str());
    CHECK_TEXT(r.app.console->last_motion_id() <= id0 + 2, h);  // nothing fed after it
    CHECK(r.tel().done_id < id0 + 1 + 1);
    CHECK(r.app.ctl->motions().empty());
  }
}

// A drive fault during a run aborts it naming the line of the running move.
TEST(ConsoleProgram, AFaultAbortsTheProgramWithItsLine) {
  Tmp tmp;
  ProgRig r(tmp.dir);
  r.enable();
  r.write("f.arm", "# a fault on the second move\nmovej 0 -45 170 0 45 0\nmovej 20 -35 160 10 35 10\nmovej 0 0 0 0 0 0\n");
  const std::uint32_t id0 = r.app.console->last_motion_id();
  CHECK(answer_ok(r.cmd("run f")));
  CHECK(r.until([&] { return r.tel().running_id == id0 + 2; }));  // the second move (line 3) runs
  for (int i = 0; i < 100; ++i) r.step1();
  r.app.plant->inject_emcy(1, 0x2310);
  CHECK(r.program_ended(5000));
  CHECK_TEXT(has(r.events, "program: f aborted at " + tmp.dir + "/f.arm:3: fault"), r.events.c_str());
  // nothing resumes by itself
  for (int i = 0; i < 2000; ++i) r.step1();
  CHECK(r.app.console->run_state() == RunState::idle);
  CHECK(r.app.ctl->motions().empty());
}

// An unhomed arm refuses run, naming the joints; nothing is checked or moved.
TEST(ConsoleProgram, AnUnhomedArmRefusesRunNamingTheJoints) {
  Tmp tmp;
  FwConfig c;
  c.drives.resize(6);
  c.drives[1].homing_method = "19";
  c.drives[4].homing_method = "19";
  ProgRig r(tmp.dir, c);
  r.enable();
  r.write("p.arm", "movej 0 -45 170 0 45 0\n");
  const std::string a = r.cmd("run p");
  CHECK_TEXT(has(a, "error: not_homed joints 2, 5 not homed"), a.c_str());
  CHECK(r.app.console->run_state() == RunState::idle);
  CHECK(has(r.cmd("teach x"), "error: not_homed"));
  // disabled: refused too
  CHECK(answer_ok(r.cmd("disable")));
  for (int i = 0; i < 200; ++i) r.step1();
  CHECK(has(r.cmd("run p"), "error: bad_state"));
}

namespace {
/// Distance (rad, joint-space Euclidean) from q to the polyline `path`.
double distance_to(const std::vector<kin::JointVector>& path, const kin::JointVector& q) {
  double best = INFINITY;
  for (std::size_t i = 0; i + 1 < path.size(); ++i) {
    const kin::JointVector d = path[i + 1] - path[i], v = q - path[i];
    const double dd = d.squaredNorm();
    const double s = dd > 0 ? std::fmax(0.0, std::fmin(1.0, v.dot(d) / dd)) : 0.0;
    best = std::fmin(best, (v - s * d).norm());
  }
  return best;
}
}  // namespace

// record start / jogging / record stop NAME writes a program of blended joint moves; replaying
// it keeps the arm within 0.5 deg (the default tolerance) of the path the joints took.
TEST(ConsoleProgram, RecordThenReplayStaysWithinTheTolerance) {
  Tmp tmp;
  ProgRig r(tmp.dir);
  r.enable();
  CHECK(answer_ok(r.cmd("movej 0 -45 170 0 45 0")));
  CHECK(answer_ok(r.cmd("wait")));
  for (int i = 0; i < 300; ++i) r.step1();
  std::vector<kin::JointVector> path{r.q_act()};
  CHECK(answer_ok(r.cmd("record start rate=100")));
  const char* jogs[] = {"jog j1 +25 speed=30", "jog j2 +15 speed=30", "jog j3 -20 speed=30", "jog j1 -10 speed=30", "jog j5 +20 speed=30"};
  for (const char* j : jogs) {
    const std::string a = r.cmd(j);
    CHECK_TEXT(answer_ok(a), a.c_str());
    for (int i = 0; i < 20000; ++i) {
      r.step1();
      path.push_back(r.q_act());
      if (i > 10 && r.tel().state == ArmState::idle) break;
    }
  }
  for (int i = 0; i < 300; ++i) {
    r.step1();
    path.push_back(r.q_act());
  }
  CHECK(has(r.cmd("status"), "recording="));
  const std::string a = r.cmd("record stop rec");
  CHECK_TEXT(answer_ok(a) && has(a, "recorded rec.arm:"), a.c_str());
  const std::string text = test::read_file(tmp.dir + "/rec.arm");
  CHECK_TEXT(has(text, "blend=0.25") && has(text, "movej "), text.c_str());
  // back to the start, then replay
  CHECK(answer_ok(r.cmd("movej 0 -45 170 0 45 0")));
  CHECK(answer_ok(r.cmd("wait")));
  const std::uint32_t first = r.app.console->last_motion_id() + 1;
  CHECK(answer_ok(r.cmd("run rec")));
  double worst = 0;
  int samples = 0;
  for (int i = 0; i < 200000 && r.app.console->run_state() != RunState::idle; ++i) {
    r.step1();
    if (r.tel().done_id < first) continue;  // the first move goes to the first sample
    worst = std::fmax(worst, distance_to(path, r.q_cmd()));
    ++samples;
  }
  CHECK_TEXT(has(r.events, "program: rec done"), r.events.c_str());
  CHECK(samples > 1000);
  CHECK_TEXT(worst <= 0.5 * kDeg, std::to_string(worst / kDeg).c_str());
  CHECK((r.q_cmd() - path.back()).norm() < 0.5 * kDeg);
  // bad input
  CHECK(has(r.cmd("record stop x"), "error: bad_state"));
  CHECK(has(r.cmd("record start rate=0"), "error: out_of_range"));
  CHECK(has(r.cmd("record start rate=500"), "error: out_of_range"));
  CHECK(has(r.cmd("record go"), "error: bad_option"));
}

namespace {
FwConfig with_outputs() {
  FwConfig c;
  c.outputs = {{"gripper", 3, 16}, {"vacuum", 3, 17}, {"lamp", 6, 18}};  // nodes 1..6 = joints 1..6
  return c;
}
}  // namespace

// Digital outputs ([[output]]: a drive's 60FEh:01 bit, RPDO3): `out NAME on|off` and M64 / M65
// at once, M62 / M63 in the cycle the next move starts; what the virtual drive has received.
TEST(ConsoleProgram, DigitalOutputsReachTheDriveAtTheRightTime) {
  Tmp tmp;
  ProgRig r(tmp.dir, with_outputs());
  r.enable();
  sim::VirtualDrive& d3 = r.app.plant->arm().at(2);
  sim::VirtualDrive& d6 = r.app.plant->arm().at(5);
  LONGS_EQUAL(0, d3.digital_outputs());
  // at once: within the PDO latency (sent with the next write, acted on at its SYNC)
  CHECK(answer_ok(r.cmd("out gripper on")));
  CHECK(r.until([&] { return d3.digital_outputs() == (1u << 16); }, 3));
  CHECK(answer_ok(r.cmd("M64 P2")));  // lamp: joint 6 bit 18
  CHECK(r.until([&] { return d6.digital_outputs() == (1u << 18); }, 3));
  CHECK(answer_ok(r.cmd("M65 P0")));
  CHECK(r.until([&] { return d3.digital_outputs() == 0u; }, 3));
  const std::string l = r.cmd("out");
  CHECK_TEXT(has(l, "gripper joint=3 bit=16 off\nvacuum joint=3 bit=17 off\nlamp joint=6 bit=18 on\nok 3 outputs"), l.c_str());
  // M62 / M63: nothing until the next move starts, then in the cycle it starts
  CHECK(answer_ok(r.cmd("M62 P1")));
  CHECK(answer_ok(r.cmd("M63 P2")));
  for (int i = 0; i < 200; ++i) r.step1();
  LONGS_EQUAL(0, d3.digital_outputs());
  LONGS_EQUAL(1u << 18, d6.digital_outputs());
  const std::uint32_t id = r.app.console->last_motion_id() + 1;
  r.s.out.clear();
  r.app.console->execute(r.s, "movej 10 0 -10 0 0 0");
  CHECK(answer_ok(r.s.out));
  int started = -1, set = -1;
  for (int i = 0; i < 50; ++i) {
    if (started < 0 && r.tel().running_id == id) started = i;
    if (set < 0 && r.tel().outputs[2] == (1u << 17) && r.tel().outputs[5] == 0) set = i;
    r.step1();
  }
  CHECK(started >= 0);
  LONGS_EQUAL(started, set);  // in the cycle the move starts
  CHECK(r.until([&] { return d3.digital_outputs() == (1u << 17) && d6.digital_outputs() == 0; }, 3));
  CHECK(answer_ok(r.cmd("wait")));
  // bad input: one line, nothing set
  CHECK(has(r.cmd("out nothing on"), "error: bad_option out: no output 'nothing'"));
  CHECK(has(r.cmd("out gripper maybe"), "error: bad_option"));
  CHECK(has(r.cmd("M64 P7"), "error: out_of_range"));
  CHECK(has(r.cmd("M64"), "error: arg_count"));
  // in a program: out after the move it follows has finished, M62 with the next move
  r.write("g.arm", "movej 0 0 0 0 0 0\nout gripper on\nM62 P2\nmovej 10 0 -10 0 0 0\n");
  CHECK(answer_ok(r.cmd("out vacuum off")));
  const std::uint32_t first = r.app.console->last_motion_id() + 1;
  CHECK(answer_ok(r.cmd("run g")));
  bool early = false;
  for (int i = 0; i < 20000 && r.app.console->run_state() != RunState::idle; ++i) {
    const Telemetry t = r.tel();
    if (t.done_id < first && (t.outputs[2] & (1u << 16))) early = true;       // gripper before move 1 ended
    if (t.running_id != first + 1 && t.done_id < first + 1 && (t.outputs[5] & (1u << 18))) early = true;  // lamp before move 2
    r.step1();
  }
  CHECK(!early);
  CHECK(has(r.events, "program: g done"));
  LONGS_EQUAL((1u << 16), r.tel().outputs[2]);
  LONGS_EQUAL(1u << 18, r.tel().outputs[5]);
}

// Figures (docs/programs.md, /work/notes results): the documented 20-point pick-and-place
// program (tests/motion/test_blend.cpp's points, on the puma560's own limits) run through the
// console at speed=100, with blend= on the above-points and without: cycle time, the largest
// distance from each programmed corner, peak sampled joint velocity / acceleration / jerk
// against the limits. The controller blends the joint moves' corners: the blended
// run must be at least 30 % shorter, each corner within its tolerance, every sampled peak
// within the limits; the test asserts those and prints the figures.
TEST(ConsoleProgram, FiguresTwentyPointPickAndPlace) {
  Tmp tmp;
  ProgRig r(tmp.dir);
  r.enable();
  std::vector<kin::JointVector> pts;
  std::vector<bool> blended;
  auto v6 = [](std::initializer_list<double> l) {
    kin::JointVector v(6);
    int k = 0;
    for (double x : l) v[k++] = x;
    return v;
  };
  const kin::JointVector home = v6({0, -0.6, 1.2, 0, 0.9, 0});
  pts.push_back(home);
  blended.push_back(false);
  for (int c = 0; c < 3; ++c) {
    const double pick = -0.9 + 0.25 * c, place = 0.8 - 0.2 * c;
    const kin::JointVector ap = v6({pick, -0.3, 1.0, 0.1, 0.9, pick}), p = v6({pick, -0.05, 1.15, 0.1, 0.6, pick});
    const kin::JointVector aq = v6({place, -0.35, 0.95, -0.1, 0.9, place + 0.5}), q = v6({place, -0.1, 1.1, -0.1, 0.65, place + 0.5});
    for (const kin::JointVector* x : {&ap, &p, &ap, &aq, &q, &aq}) {
      pts.push_back(*x);
      blended.push_back(x == &ap || x == &aq);
    }
  }
  pts.push_back(home);
  blended.push_back(false);
  LONGS_EQUAL(20, pts.size());
  const kin::JointLimits& lim = r.app.ctl->limits();
  double cycle_s[2] = {0, 0};
  for (const bool blend : {false, true}) {
    std::string text = "# the 20-point pick-and-place program\n";
    for (std::size_t i = 0; i < pts.size(); ++i) {
      text += "movej";
      for (int j = 0; j < 6; ++j) { char b[32]; std::snprintf(b, sizeof b, " %.10g", pts[i][j] / kDeg); text += b; }
      text += " speed=100";
      if (blend && blended[i]) text += " blend=57.3";
      text += "\n";
    }
    r.write("pp.arm", text);
    CHECK(answer_ok(r.cmd("movej 0 -34.3774677 68.7549354 0 51.5662016 0")));  // home
    CHECK(answer_ok(r.cmd("wait")));
    const std::uint32_t first = r.app.console->last_motion_id() + 1;
    const std::string a = r.cmd("run pp");
    CHECK_TEXT(answer_ok(a), a.c_str());
    std::vector<kin::JointVector> q;
    for (int i = 0; i < 200000 && r.app.console->run_state() != RunState::idle; ++i) {
      r.step1();
      if (r.tel().running_id >= first || r.tel().done_id >= first) q.push_back(r.q_cmd());
    }
    CHECK(has(r.events, "program: pp done"));
    const double dt = 1.0 / r.app.ctl->config().rate_hz;
    double vr = 0, ar = 0, jr = 0;  // peak / limit over the joints
    for (std::size_t i = 3; i < q.size(); ++i)
      for (int j = 0; j < 6; ++j) {
        const auto& d = lim.dyn[static_cast<std::size_t>(j)];
        const double v = (q[i][j] - q[i - 1][j]) / dt;
        const double acc = (q[i][j] - 2 * q[i - 1][j] + q[i - 2][j]) / (dt * dt);
        const double jerk = (q[i][j] - 3 * q[i - 1][j] + 3 * q[i - 2][j] - q[i - 3][j]) / (dt * dt * dt);
        vr = std::fmax(vr, std::fabs(v) / d.max_velocity);
        ar = std::fmax(ar, std::fabs(acc) / d.max_acceleration);
        jr = std::fmax(jr, std::fabs(jerk) / d.max_jerk);
      }
    double corner = 0;  // the largest of the closest approaches to each programmed point
    for (std::size_t k = 1; k + 1 < pts.size(); ++k) {
      double best = INFINITY;
      for (const kin::JointVector& x : q) best = std::fmin(best, (x - pts[k]).norm());
      corner = std::fmax(corner, best);
    }
    cycle_s[blend ? 1 : 0] = static_cast<double>(q.size()) * dt;
    // armctl program check plans the same blends: its cycle time within 1 ms a move + 0.1 %
    // of the run's (the run's samples start with the program's first move)
    int offline_blends = 0;
    const double offline = offline_cycle(r.app, r.dir, "pp.arm", home, &offline_blends);
    std::printf("\narmctl program check: %.3f s (%d blended corners), the run %.3f s\n", offline, offline_blends,
                cycle_s[blend ? 1 : 0]);
    CHECK(std::fabs(offline - cycle_s[blend ? 1 : 0]) <= 1e-3 * 20 + 1e-3 * cycle_s[blend ? 1 : 0]);
    LONGS_EQUAL(blend ? 12 : 0, offline_blends);
    std::printf("\n20-point pick-and-place through the console, %s: cycle %.3f s, largest corner distance %.4f deg, "
                "peak velocity %.6f, acceleration %.6f, jerk %.6f of the limits\n",
                blend ? "blend=57.3 deg on the above-points" : "exact stops", static_cast<double>(q.size()) * dt,
                corner / kDeg, vr, ar, jr);
    CHECK(vr <= 1.0 + 1e-6);
    CHECK(ar <= 1.0 + 1e-3);
    CHECK(jr <= 1.0 + 1e-3);
    CHECK(corner <= 1e-6 + (blend ? 1.0 : 0.0));  // the program's numbers: 10 digits of a degree
    r.events.clear();
  }
  // the controller blends: at least 30 % shorter than with exact stops
  CHECK(cycle_s[1] <= 0.7 * cycle_s[0]);
}

// Blended lines and mixed corners in programs: a movej with blend= before a movel
// goes as a path segment (the runner looks at the next motion), so joint->line and
// line->joint corners blend; a G-code program's G64 P blends its G1 corners, G61 stops
// exactly. Corners checked against FK of the samples and the program's own numbers.
TEST(ConsoleProgram, BlendedLinesAndMixedCornersInPrograms) {
  Tmp tmp;
  ProgRig r(tmp.dir);
  r.enable();
  const kin::Chain& chain = r.app.ctl->chain();
  auto flange = [&](const kin::JointVector& q) {
    kin::Pose x;
    CHECK(kin::forward(chain, q, x) == kin::Status::ok);
    return Eigen::Vector3d(x.translation());
  };
  auto v6deg = [](std::initializer_list<double> l) {
    kin::JointVector v(6);
    int k = 0;
    for (double x : l) v[k++] = x * kDeg;
    return v;
  };
  auto joints = [](const kin::JointVector& q) {
    std::string t;
    for (int j = 0; j < 6; ++j) { char b[32]; std::snprintf(b, sizeof b, " %.10g", q[j] / kDeg); t += b; }
    return t;
  };
  auto xyz = [](const Eigen::Vector3d& p) {
    char b[96];
    std::snprintf(b, sizeof b, " %.6f %.6f %.6f", p.x() * 1e3, p.y() * 1e3, p.z() * 1e3);
    return std::string(b);
  };
  const kin::JointVector home = v6deg({0, -30, 60, 0, 40, 0}), above = v6deg({25, -35, 70, 10, 35, 10}),
                         other = v6deg({-20, -30, 65, -5, 40, -10});
  const Eigen::Vector3d pa = flange(above), pick = pa + Eigen::Vector3d(0, 0, -0.08);
  struct Out {
    double cycle = 0;
    std::uint64_t blended = 0;
    std::vector<kin::JointVector> q;
  };
  auto run = [&](const std::string& name, const std::string& text) {
    r.write(name, text);
    CHECK(answer_ok(r.cmd("movej" + joints(home) + " speed=100")));
    CHECK(answer_ok(r.cmd("wait")));
    Out o;
    const std::uint64_t b0 = r.tel().blended_corners;
    const std::uint32_t first = r.app.console->last_motion_id() + 1;
    const std::string a = r.cmd("run " + name);
    CHECK_TEXT(answer_ok(a), a.c_str());
    for (int i = 0; i < 200000 && r.app.console->run_state() != RunState::idle; ++i) {
      r.step1();
      if (r.tel().running_id >= first || r.tel().done_id >= first) o.q.push_back(r.q_cmd());
    }
    CHECK_TEXT(has(r.events, "program: " + name + " done"), r.events.c_str());
    r.events.clear();
    o.cycle = static_cast<double>(o.q.size()) / r.app.ctl->config().rate_hz;
    o.blended = r.tel().blended_corners - b0;
    // armctl program check plans the same: within 1 ms a move + 0.1 % of the run's, the same corners
    int offline_blends = -1;
    const double offline = offline_cycle(r.app, r.dir, name, home, &offline_blends);
    std::printf("\n%s: the run %.3f s (%llu corners), armctl program check %.3f s (%d)\n", name.c_str(), o.cycle,
                static_cast<unsigned long long>(o.blended), offline, offline_blends);
    CHECK(std::fabs(offline - o.cycle) <= 1e-3 * 7 + 1e-3 * o.cycle);
    LONGS_EQUAL(static_cast<long>(o.blended), offline_blends);
    return o;
  };
  auto mixed = [&](bool blend) {
    return "movej" + joints(above) + " speed=100" + (blend ? " blend=20" : "") + "\n" +  //
           "movel" + xyz(pick) + " speed=150\n" +                                           // the pick: exact
           "movel" + xyz(pa) + " speed=150" + (blend ? " blend=25" : "") + "\n" +         //
           "movej" + joints(other) + " speed=100\n";
  };
  const Out mb = run("mixed.arm", mixed(true)), mx = run("mixed_x.arm", mixed(false));
  double c_above = INFINITY, c_up = INFINITY, c_pick = INFINITY;
  for (const auto& q : mb.q) {
    c_above = std::fmin(c_above, (q - above).norm());
    c_pick = std::fmin(c_pick, (flange(q) - pick).norm());
  }
  // the way up passes pa a second time: the closest approach after the pick
  std::size_t ip = 0;
  for (std::size_t i = 0; i < mb.q.size(); ++i)
    if ((flange(mb.q[i]) - pick).norm() <= c_pick + 1e-12) ip = i;
  for (std::size_t i = ip; i < mb.q.size(); ++i) c_up = std::fmin(c_up, (flange(mb.q[i]) - pa).norm());
  std::printf("\nprogram movej->movel->movel->movej: exact %.3f s, blended %.3f s (%llu corners); above %.3f deg, up %.2f mm, pick %.2e m\n",
              mx.cycle, mb.cycle, static_cast<unsigned long long>(mb.blended), c_above / kDeg, c_up * 1e3, c_pick);
  LONGS_EQUAL(2, mb.blended);
  LONGS_EQUAL(0, mx.blended);
  CHECK(c_above <= 20 * kDeg + 1e-9);  // (rounded only as far as that ends no later than the exact stop)
  CHECK(c_up <= 25e-3 + 1e-9);
  CHECK(c_up > 1e-5);
  CHECK(c_pick < 1e-6);  // the exact stop is reached
  CHECK(mb.cycle < mx.cycle);

  // G-code: G64 P2 blends the corners of a zigzag, G61 stops at each
  const Eigen::Vector3d p0 = flange(home);
  auto zig = [&](const char* mode) {
    std::string t = std::string("G21 G90\n") + mode + "\n";
    Eigen::Vector3d p = p0;
    for (int k = 0; k < 6; ++k) {
      p += Eigen::Vector3d(-0.01, k % 2 == 0 ? 0.01 : -0.01, 0);
      char b[96];
      std::snprintf(b, sizeof b, "G1 X%.4f Y%.4f Z%.4f F6000\n", p.x() * 1e3, p.y() * 1e3, p.z() * 1e3);
      t += b;
    }
    return t + "M30\n";
  };
  const Out gb = run("zig.nc", zig("G64 P2")), gx = run("zigx.nc", zig("G61"));
  std::printf("\nG-code zigzag 6 x 14 mm at F6000: G61 %.3f s, G64 P2 %.3f s (%llu corners)\n", gx.cycle, gb.cycle,
              static_cast<unsigned long long>(gb.blended));
  LONGS_EQUAL(5, gb.blended);
  LONGS_EQUAL(0, gx.blended);
  CHECK(gb.cycle < gx.cycle);
}

// While a program runs, motion commands from any other console are refused `busy` (they
// would run inside the checked program); stop, hold, resume and queries still work.
TEST(ConsoleProgram, MotionFromAnotherConsoleIsRefusedWhileAProgramRuns) {
  Tmp tmp;
  ProgRig r(tmp.dir);
  r.enable();
  r.write("p.arm", "movej 20 -35 160 10 35 10 speed=10\nmovej 40 -45 170 0 45 0 speed=10\nmovej 20 -35 160 10 35 10 speed=10\n");
  CHECK(answer_ok(r.cmd("run p")));
  CHECK(r.until([&] { return r.tel().state == ArmState::moving; }, 2000));
  const std::uint32_t last = r.app.console->last_motion_id();
  Session other;
  const char* moves[] = {"movej 0 -30 150 0 -30 0", "movel 500 100 300", "G91 G1 X10 F600", "park", "G4 P1",
                         "jog j1 +5", "$J=G91 X5 F600", "M62 P0"};
  for (const char* m : moves) {
    other.out.clear();
    r.app.console->execute(other, m);
    CHECK_TEXT(has(other.out, "error: busy program p is running"), (std::string(m) + " -> " + other.out).c_str());
  }
  LONGS_EQUAL(last, r.app.console->last_motion_id());  // nothing queued from outside
  other.out.clear();
  r.app.console->execute(other, "status");
  CHECK(answer_ok(other.out));
  CHECK(r.program_ended(200000));
  CHECK(!has(r.events, "aborted"));
  CHECK(r.at_rest());
  DOUBLES_EQUAL(20.0, r.q_act()[0] / kDeg, 0.1);  // where the program ends, nothing from outside
  // no program: the same moves are accepted again
  other.out.clear();
  r.app.console->execute(other, "movej 0 -30 150 0 -30 0");
  CHECK_TEXT(answer_ok(other.out), other.out.c_str());
}

// M62/M63 changes waiting for the next move are discarded by stop, e-stop, Ctrl-X, disable
// and a refused move, and the answer says so: a later, unrelated move switches nothing.
TEST(ConsoleProgram, PendingSynchronizedOutputsDieWithAStopOrARefusal) {
  const char* stops[] = {"stop", "estop", "\x18", "disable", "movej 0 0 500 0 0 0"};
  for (const char* how : stops) {
    Tmp tmp;
    ProgRig r(tmp.dir, with_outputs());
    r.enable();
    sim::VirtualDrive& d3 = r.app.plant->arm().at(2);
    CHECK(answer_ok(r.cmd("M62 P0")));  // gripper on at the next move
    r.s.out.clear();
    if (how[0] == 0x18) r.app.console->accept(r.s, how);
    else r.app.console->execute(r.s, how);
    for (int i = 0; i < 50; ++i) r.step1();
    CHECK_TEXT(has(r.s.out, "M62/M63 change waiting for the next move discarded") && has(r.s.out, "gripper on"),
               (std::string(how) + " -> " + r.s.out).c_str());
    if (r.tel().state != ArmState::idle) {
      CHECK(answer_ok(r.cmd("reset")));
      r.enable();
    }
    CHECK(answer_ok(r.cmd("movej 10 0 -10 0 0 0")));
    CHECK(answer_ok(r.cmd("wait")));
    LONGS_EQUAL(0, d3.digital_outputs());
  }
}

// Check mode ($C) changes nothing: teach, point delete and record start / stop are checked
// and answered, the points and the points file and the programs folder stay as they were.
TEST(ConsoleProgram, CheckModeTeachesDeletesAndRecordsNothing) {
  Tmp tmp;
  ProgRig r(tmp.dir);
  r.enable();
  CHECK(answer_ok(r.cmd("teach keep")));
  const std::string before = test::read_file(tmp.dir + "/points.toml");
  CHECK(has(r.cmd("$C"), "ok"));
  const char* lines[] = {"teach extra", "point delete keep", "record start", "record stop rec"};
  for (const char* l : lines) {
    const std::string a = r.cmd(l);
    CHECK_TEXT(answer_ok(a), (std::string(l) + " -> " + a).c_str());
  }
  CHECK(has(r.cmd("point delete nothere"), "error: bad_option"));  // still checked
  CHECK(has(r.cmd("$C"), "ok"));
  STRCMP_EQUAL(before.c_str(), test::read_file(tmp.dir + "/points.toml").c_str());
  LONGS_EQUAL(1, r.app.console->points().points.size());
  CHECK(::access((tmp.dir + "/rec.arm").c_str(), F_OK) != 0);
  CHECK(has(r.cmd("record stop rec"), "error: bad_state"));  // no recording was started
}

// A program's steps run as the loader parsed them (typed), not as text parsed again: a
// `movej @NAME` step goes to the point's joints exactly as taught (SI, bit for bit), as the
// same line typed at the console does; the text form of the step (the joints written in
// degrees) would round each joint on its way through the units.
TEST(ConsoleProgram, AProgramsMovejAtNameGoesToTheTaughtJointsExactly) {
  Tmp tmp;
  // joints chosen so that each one's degrees (to 17 digits) and back is not the joint itself
  const double q[6] = {-0.04528848651449163, -0.5892868885942255, 3.1878544227602923,
                       -0.07656147436456126, 0.8936381473065198, 0.0984913232848047};
  std::string pts = "format = \"servoarm-points-1\"\n\n[point.pick]\njoints = [";
  for (int j = 0; j < 6; ++j) pts += (j ? ", " : "") + std::string(fw::fixed(q[j], 17));
  test::write_file(tmp.dir + "/points.toml", pts + "]\nxyz = [0.5, 0.1, 0.4]\nrpy = [0, 0, 0]\ntool = \"tool0\"\nframe = \"base\"\n");
  ProgRig r(tmp.dir);
  r.enable();
  const kin::JointVector taught = r.app.console->points().points.at(0).q;
  for (int j = 0; j < 6; ++j) CHECK(taught[j] == q[j]);
  r.write("at.arm", "movej @pick speed=80\n");
  const std::string a = r.cmd("run at");
  CHECK_TEXT(answer_ok(a), a.c_str());
  CHECK(r.program_ended());
  const MoveResult& last = r.app.console->service().last();
  CHECK_TEXT(last.ok(), to_string(last.refusal));
  std::string diff;
  for (int j = 0; j < 6; ++j)
    if (last.goal[j] != taught[j]) diff += " joint " + std::to_string(j + 1) + " off by " + std::to_string((last.goal[j] - taught[j]) * 1e18) + "e-18";
  CHECK_TEXT(diff.empty(), ("goal differs from the taught point:" + diff).c_str());
}
