// SPDX-License-Identifier: Apache-2.0
// The GRBL dialect: what a GRBL sender sees. Answers `ok` / `error:N` with a
// [MSG:] line, the `<State|MPos|FS|Ov|Bf>` report, the $ commands, a motion line waiting
// for room in a full queue (character-counting senders), bytes above 0x7F dropped, G4 P in
// seconds, Ctrl-X as a soft reset; and on a real pty (ConsoleServer): the banner when a
// client opens it, a jog cancelled when the client hangs up.
#include <fcntl.h>
#include <poll.h>
#include <unistd.h>

#include <chrono>
#include <memory>
#include <cmath>
#include <cstdio>
#include <string>
#include <thread>

#include "console_rig.hpp"
#include "servoarm/console/transport.hpp"
#include "servoarm/kinematics/orientation.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;

namespace {
bool has(const std::string& s, const std::string& p) { return s.find(p) != std::string::npos; }

struct GrblRig : test::ConsoleRig {
  GrblRig() {
    s.dialect = Dialect::grbl;
    s.modal.dwell_p_seconds = true;
  }
  ArmState state() const { return app.ctl->telemetry().state; }
  /// The rig's enable, which reads native answers.
  void enable() {
    s.dialect = Dialect::native;
    test::ConsoleRig::enable();
    s.dialect = Dialect::grbl;
  }
  /// Lines in, answers out, cycles run until the session is done (bounded).
  std::string feed(const std::string& bytes) {
    s.out.clear();
    app.console->feed(s, bytes);
    for (int i = 0; i < 60000 && app.console->busy(s); ++i) {
      cycle();
      app.console->poll(s);
    }
    return s.out;
  }
};
}  // namespace

TEST_GROUP(ConsoleGrbl){};

TEST(ConsoleGrbl, AnswersReportsAndDollarCommandsAreGrbls) {
  GrblRig r;
  std::string o = r.feed("$I\n");
  CHECK_TEXT(has(o, "[VER:1.1h.servoarm:puma560]\n[OPT:V,16,128]\nok\n"), o.c_str());
  o = r.feed("$$\n");
  CHECK_TEXT(has(o, "$110=15000.000\n") && has(o, "$120=1000.000\n") && o.size() > 40 && has(o, "\nok\n"), o.c_str());
  o = r.feed("$#\n");
  CHECK_TEXT(has(o, "[G54:0.000,0.000,0.000]") && has(o, "[G28:") && has(o, "\nok\n"), o.c_str());
  o = r.feed("G20 G91\n$G\n");
  CHECK_TEXT(has(o, "[GC:G0 G54 G17 G20 G91 G94 M5 M9 T0 F0 S0]"), o.c_str());
  r.feed("G21 G90\n");
  // an error: the reason on a [MSG:] line, then error:N (GRBL's number)
  o = r.feed("G1 X1 Q5\n");
  CHECK_TEXT(o.rfind("[MSG:unsupported: ", 0) == 0 && has(o, "]\nerror:20\n"), o.c_str());
  o = r.feed("$J=G91 X10\n");
  CHECK_TEXT(has(o, "error:33\n"), o.c_str());
  o = r.feed("$100=5\n");
  CHECK_TEXT(has(o, "error:20\n"), o.c_str());
  o = r.feed("$H\n");  // the homing cycle needs the drives powered ($X): locked
  CHECK_TEXT(has(o, "home needs the arm enabled") && has(o, "error:9\n"), o.c_str());
  // drives off: Alarm; $X powers them up: Idle
  o = r.feed("?");
  CHECK_TEXT(o.rfind("<Alarm|MPos:", 0) == 0 && has(o, "|FS:0,0|Ov:100,100,100|Bf:16,128>"), o.c_str());
  o = r.feed("$X\n");
  CHECK_TEXT(has(o, "ok\n"), o.c_str());
  CHECK(r.state() == ArmState::idle);
  o = r.feed("?");
  CHECK_TEXT(o.rfind("<Idle|MPos:", 0) == 0, o.c_str());
}

TEST(ConsoleGrbl, AFullQueueDelaysTheOkInsteadOfAnsweringAnError) {
  GrblRig r;
  r.enable();
  r.feed("G1 F6000\n");
  CHECK(test::answer_ok(r.cmd("movej 20 -40 160 10 -50 30")));
  CHECK(test::answer_ok(r.cmd("wait")));
  // 24 short moves in one write: more than the queue holds; each gets its ok, in order,
  // none an error, and the arm ends at the last one.
  std::string prog;
  for (int k = 0; k < 24; ++k) prog += k % 2 ? "G1 X-2 G91\n" : "G1 X2 G91\n";
  prog += "G90\n";
  const std::string o = r.feed(prog);
  int oks = 0;
  for (std::size_t p = 0; (p = o.find("ok\n", p)) != std::string::npos; ++p) ++oks;
  CHECK_TEXT(!has(o, "error"), o.c_str());
  LONGS_EQUAL(25, oks);
  CHECK(test::answer_ok(r.cmd("wait")));
}

TEST(ConsoleGrbl, BytesAbove0x7FAreDroppedAndUtf8RealtimeBytesStillAct) {
  GrblRig r;
  r.enable();
  // cncjs sends 0x85 and the overrides UTF-8 encoded: C2 85, C2 91. The C2 must not end
  // up in the next line.
  std::string o = r.feed(std::string("\xC2\x91\xC2\x91$G\n"));
  CHECK_TEXT(has(o, "[GC:") && !has(o, "error"), o.c_str());
  CHECK_EQUAL(120, r.app.console->feed_override());
  o = r.feed(std::string("\xC2\x90"));
  CHECK_EQUAL(100, r.app.console->feed_override());
  o = r.feed("?");
  CHECK_TEXT(has(o, "|Ov:100,"), o.c_str());
  CHECK(test::answer_ok(r.cmd("jog j1 +")));
  r.feed(std::string("\xC2\x85"));  // jog cancel
  for (int i = 0; i < 2000 && r.state() == ArmState::jogging; ++i) r.cycle();
  CHECK(r.state() == ArmState::idle);
}

TEST(ConsoleGrbl, G4PIsSecondsAndCtrlXIsASoftReset) {
  GrblRig r;
  r.enable();
  std::string o = r.feed("G4 P0.5\n");
  CHECK_TEXT(o == "[MSG:queued id=1 dwell=0.500s]\nok\n", o.c_str());
  o = r.feed("M400\n");  // the dwell runs out: at rest
  CHECK_TEXT(has(o, "ok\n"), o.c_str());
  // Ctrl-X at rest: no e-stop, the queue dropped, the banner again
  o = r.feed(std::string("\x18"));
  CHECK_TEXT(has(o, "Grbl 1.1h ['$' for help]"), o.c_str());
  CHECK(r.state() == ArmState::idle || r.state() == ArmState::moving);
  for (int i = 0; i < 50; ++i) r.cycle();
  CHECK(r.state() == ArmState::idle);
  // Ctrl-X while moving: an e-stop (ALARM:10 among the events)
  CHECK(test::answer_ok(r.cmd("movej 30 0 0 0 0 0")));
  for (int i = 0; i < 100; ++i) r.cycle();
  r.feed(std::string("\x18"));
  for (int i = 0; i < 3000 && r.state() != ArmState::estop; ++i) r.cycle();
  CHECK(r.state() == ArmState::estop);
  std::string native, grbl;
  r.app.console->drain_events(native, grbl);
  CHECK_TEXT(has(grbl, "ALARM:10\n"), grbl.c_str());
  o = r.feed("?");
  CHECK_TEXT(o.rfind("<Alarm|", 0) == 0, o.c_str());
}

TEST(ConsoleGrbl, CheckModePlansEveryMoveAndMovesNothing) {
  GrblRig r;
  r.enable();
  CHECK(test::answer_ok(r.cmd("movej 20 -40 160 10 -50 30")));
  CHECK(test::answer_ok(r.cmd("wait")));
  const Telemetry t0 = r.app.ctl->telemetry();
  std::string o = r.feed("$C\n");
  CHECK_TEXT(has(o, "[MSG:Enabled]\nok\n"), o.c_str());
  o = r.feed("?");
  CHECK_TEXT(o.rfind("<Check|", 0) == 0, o.c_str());
  o = r.feed("G91\nG1 X10 F600\nG1 Y10\nG1 X5000\nG90\n");
  // the first two check, the third is unreachable from where the second ends
  CHECK_TEXT(has(o, "ok\nok\nok\n[MSG:") && has(o, "error:"), o.c_str());
  for (int i = 0; i < 200; ++i) r.cycle();
  const Telemetry t1 = r.app.ctl->telemetry();
  for (int j = 0; j < 6; ++j) DOUBLES_EQUAL(t0.q_cmd[static_cast<std::size_t>(j)], t1.q_cmd[static_cast<std::size_t>(j)], 0.0);
  LONGS_EQUAL(0, t1.queued);
  o = r.feed("$C\n");
  CHECK_TEXT(has(o, "[MSG:Disabled]"), o.c_str());
}

// On a real pty: the banner reaches a client that opens it after armfw started, and a
// client that hangs up mid-jog stops the jog at once (not at its deadman).
TEST(ConsoleGrbl, OnAPtyTheBannerComesOnOpenAndAHangUpStopsTheJog) {
  test::ConsoleRig r;
  ConsoleConfig cfg = r.app.console->config();
  cfg.jog_deadman_s = 5.0;  // longer than the test: only the hang-up can stop the jog
  r.app.console = std::make_unique<Console>(*r.app.ctl, cfg, r.app.ik_ready ? r.app.ik.get() : nullptr);
  r.app.console->set_idle([&r] { r.cycle(); });
  r.enable();
  FdTransport pt;
  CHECK(open_pty(pt).empty());
  pt.dialect = Dialect::grbl;
  ConsoleServer srv(*r.app.console, {&pt});
  for (int i = 0; i < 5; ++i) {
    srv.round(0, false);
    r.cycle();
  }
  const int c = ::open(pt.path.c_str(), O_RDWR | O_NOCTTY);
  CHECK(c >= 0);
  std::string got;
  for (int i = 0; i < 200 && !has(got, "for help]"); ++i) {
    srv.round(1, false);
    r.cycle();
    char b[256];
    pollfd p{c, POLLIN, 0};
    if (::poll(&p, 1, 1) > 0) {
      const ssize_t n = ::read(c, b, sizeof b);
      if (n > 0) got.append(b, static_cast<std::size_t>(n));
    }
  }
  CHECK_TEXT(has(got, "Grbl 1.1h ['$' for help]"), got.c_str());
  const std::string line = "jog j1 +\n";
  CHECK(::write(c, line.data(), line.size()) == static_cast<ssize_t>(line.size()));
  for (int i = 0; i < 300 && r.app.ctl->telemetry().state != ArmState::jogging; ++i) {
    srv.round(1, false);
    r.cycle();
  }
  CHECK(r.app.ctl->telemetry().state == ArmState::jogging);
  for (int i = 0; i < 200; ++i) r.cycle();
  ::close(c);  // the sender crashes
  int cycles = 0;
  for (; cycles < 3000 && r.app.ctl->telemetry().state == ArmState::jogging; ++cycles) {
    srv.round(0, false);
    r.cycle();
  }
  CHECK(r.app.ctl->telemetry().state == ArmState::idle);
  CHECK_TEXT(cycles < 1000, std::to_string(cycles).c_str());  // the stop, not the 5 s deadman
}

// A feed hold right after a move in the same write holds that move: the '!' applies to the
// lines received before it (a move is held as soon as it is queued, until '~'), for every
// kind of move, from rest, while a move runs and while one is held. A jog is cancelled.
TEST(ConsoleGrbl, AFeedHoldRightAfterAMoveInTheSameWriteHoldsIt) {
  const char* kinds[] = {"movej 60 -60 120 60 -60 60 speed=20", "movel", "jog j1 +30", "$J=G91 X20 F600",
                         "G91 G1 Z-20 F600", "G91 G0 Z-20"};
  const char* states[] = {"idle", "moving", "held"};
  for (const char* kind : kinds) {
    for (const char* state : states) {
      test::ConsoleRig r;
      r.enable();
      CHECK(test::answer_ok(r.cmd("movej 20 -40 160 10 -50 30")));
      CHECK(test::answer_ok(r.cmd("wait")));
      std::string line = kind;
      if (line == "movel") {  // 20 mm down from here, same orientation
        const Telemetry t = r.app.ctl->telemetry();
        kin::JointVector q(6);
        for (int j = 0; j < 6; ++j) q[j] = t.q_act[static_cast<std::size_t>(j)];
        const kin::Pose p = r.app.console->pose_in_frame(q);
        const Eigen::Vector3d rpy = kin::rpy_from_rotation(p.linear()) * 180.0 / M_PI;
        char b[160];
        std::snprintf(b, sizeof b, "movel %.3f %.3f %.3f %.4f %.4f %.4f speed=50", p.translation().x() * 1e3,
                      p.translation().y() * 1e3, p.translation().z() * 1e3 - 20, rpy[0], rpy[1], rpy[2]);
        line = b;
      }
      const std::string st = state;
      if (st != "idle") {
        CHECK(test::answer_ok(r.cmd("movej 25 -40 160 10 -50 30 speed=2")));
        for (int i = 0; i < 300; ++i) r.cycle();
        if (st == "held") {
          r.app.console->feed(r.s, "!");
          for (int i = 0; i < 2000; ++i) r.cycle();
        }
      }
      const bool jog = line.rfind("jog", 0) == 0 || line.rfind("$J", 0) == 0;
      auto joints = [&r] {
        const Telemetry t = r.app.ctl->telemetry();
        kin::JointVector q(6);
        for (int j = 0; j < 6; ++j) q[j] = t.q_cmd[static_cast<std::size_t>(j)];
        return q;
      };
      const kin::JointVector q0 = joints();
      r.s.out.clear();
      r.app.console->feed(r.s, line + "\n!");
      const std::string what = line + " + ! while " + st + ": " + r.s.out;
      for (int i = 0; i < 3000; ++i) r.cycle();
      const kin::JointVector q1 = joints();
      for (int i = 0; i < 500; ++i) r.cycle();
      const kin::JointVector q2 = joints();
      // at rest, held
      CHECK_TEXT((q2 - q1).norm() < 1e-9, what.c_str());
      const Telemetry t = r.app.ctl->telemetry();
      CHECK_TEXT(t.state == ArmState::idle || t.holding, what.c_str());
      // from rest: nothing moved (at most the cycle before the hold, at rest speed)
      if (st == "idle") CHECK_TEXT((q2 - q0).norm() < 0.05 * M_PI / 180.0, what.c_str());
      if (jog) continue;
      // `~`: the held move runs (it was held, not dropped)
      r.app.console->feed(r.s, "~");
      for (int i = 0; i < 1000; ++i) r.cycle();
      CHECK_TEXT((joints() - q2).norm() > 1e-4, what.c_str());
    }
  }
}

// Bytes 0x80-0xFF are realtime only where GRBL puts them: a UTF-8 `Ñ` (C3 91) in a refused
// line holds the byte 0x91 (feed +10 %) and changes nothing; status and ? show the override.
TEST(ConsoleGrbl, BytesInsideAUtf8CharacterAreNoRealtimeCommands) {
  test::ConsoleRig r;
  r.enable();
  std::string line = "; ";
  for (int i = 0; i < 10; ++i) line += "\xC3\x91";
  r.s.out.clear();
  r.app.console->feed(r.s, line + "\n");
  CHECK_TEXT(has(r.s.out, "error: binary"), r.s.out.c_str());
  LONGS_EQUAL(100, r.app.console->feed_override());
  // the GRBL places still act: bare, and UTF-8 encoded as C2 91
  r.app.console->feed(r.s, "\x91\xC2\x91");
  LONGS_EQUAL(120, r.app.console->feed_override());
  CHECK_TEXT(has(r.cmd("status"), " feed_override=120%"), r.s.out.c_str());
  r.s.out.clear();
  r.app.console->feed(r.s, "?");
  CHECK_TEXT(has(r.s.out, "|Ov:120"), r.s.out.c_str());
}
