// SPDX-License-Identifier: Apache-2.0
// armctl program check and the homing cycle, as a process: `home` leaves each joint
// at its drive.homing.offset (armfw's --config; "none" joints where they were), `park` / G28
// go to motion.home_deg, and what the console would refuse is refused naming the line: `home`
// with moves queued, a move while the homing cycle runs (no `wait`), a homed position outside
// the joint's limits, every move of an unhomed arm (--unhomed) naming the joints.
#include <cstdio>
#include <cstdlib>
#include <string>

#include "../program/tmp_dir.hpp"
#include "run_command.hpp"

// CppUTest last: its leak detector redefines new.
#include <CppUTest/TestHarness.h>

using servoarm::test::cycle_time;
using servoarm::test::make_tmp_dir;
using servoarm::test::program_check;
using servoarm::test::remove_tree;
using servoarm::test::write_file;

namespace {

const std::string kArmctl = ARMCTL_PATH;

// puma560, joints 1-3 and 5 home (19, hard_stop, 21, 35), 4 and 6 are absolute; the order of
// the wrist first; park pose and joint speed from [motion].
const char* kConfig =
    "robot = \"puma560\"\n"
    "[motion]\nhome_deg = [0, -45, 180, 0, 45, 0]\njoint_speed_pct = 40\n"
    "[homing]\norder = [[3], [2], [1], [4, 5, 6]]\n"
    "[[drive]]\nhoming.method = 19\nhoming.offset = 10\n"
    "[[drive]]\nhoming.method = \"hard_stop\"\nhoming.offset = -100\n"
    "[[drive]]\nhoming.method = 21\nhoming.offset = 170\n"
    "[[drive]]\n"
    "[[drive]]\nhoming.method = 35\nhoming.offset = 20\n"
    "[[drive]]\n";
// where `home` leaves the arm from --from 30 -20 40 15 25 35: 4 and 6 stay
const char* kHomedFrom = "--from 10 -100 170 15 20 35";

}  // namespace

TEST_GROUP(ProgramHoming) {
  std::string dir;
  void setup() override {
    MemoryLeakWarningPlugin::saveAndDisableNewDeleteOverloads();
    dir = make_tmp_dir();
    write_file(dir + "/armfw.toml", kConfig);
  }
  void teardown() override {
    remove_tree(dir);
    std::string().swap(dir);
    MemoryLeakWarningPlugin::restoreNewDeleteOverloads();
  }
  servoarm::test::CommandResult check(const std::string& name, const std::string& text, const std::string& extra) {
    return program_check(kArmctl, dir + "/" + name, text, extra);
  }
  std::string cfg() const { return "--config " + dir + "/armfw.toml --stream"; }
  double good(const std::string& name, const std::string& text, const std::string& extra) {
    const auto r = check(name, text, extra);
    LONGS_EQUAL_TEXT(0, r.status, (r.out + r.err).c_str());
    CHECK_TEXT(r.out.find("ok:") == 0, r.out.c_str());
    return cycle_time(r.out);
  }
  void bad(const std::string& name, const std::string& text, const std::string& extra, const std::string& where,
           const std::string& what) {
    const auto r = check(name, text, extra);
    LONGS_EQUAL_TEXT(2, r.status, (r.out + r.err).c_str());
    CHECK_TEXT(r.err.find(where) != std::string::npos, (r.err + "   [expected " + where + "]").c_str());
    CHECK_TEXT(r.err.find(what) != std::string::npos, (r.err + "   [expected " + what + "]").c_str());
    CHECK_TEXT(r.out.find("ok:") == std::string::npos, r.out.c_str());
  }
};

// After `home` + `wait` the next move is planned from the homed pose: the same cycle time as
// that move alone from the homed pose, and not the one from where the arm was (or from the park pose).
TEST(ProgramHoming, HomeLeavesEachJointAtItsOffset) {
  const std::string move = "movej -20 -60 120 -10 50 5\n";
  const double after_home = good("h.arm", "home\nwait\n" + move, cfg() + " --from 30 -20 40 15 25 35");
  const double from_homed = good("m.arm", move, cfg() + " " + kHomedFrom);
  const double from_start = good("s.arm", move, cfg() + " --from 30 -20 40 15 25 35");
  CHECK(after_home > 0);
  DOUBLES_EQUAL(from_homed, after_home, 1e-9);
  CHECK(std::abs(from_start - after_home) > 0.01);
  const auto r = check("h.arm", "home\nwait\n" + move, cfg());
  CHECK_TEXT(r.out.find("1 homing cycle (not timed)") != std::string::npos, r.out.c_str());
  // home j2 homes joint 2 alone: the others stay where they were
  const double j2 = good("j2.arm", "home j2\nwait\n" + move, cfg() + " --from 30 -20 40 15 25 35");
  const double j2_from = good("m.arm", move, cfg() + " --from 30 -100 40 15 25 35");
  DOUBLES_EQUAL(j2_from, j2, 1e-9);
}

// Without --config armfw has no [[drive]] tables: every joint is absolute, `home` moves nothing.
TEST(ProgramHoming, WithoutAConfigEveryJointIsAbsolute) {
  const std::string move = "movej -20 -60 120 -10 50 5\n";
  const double a = good("h.arm", "home\nwait\n" + move, "--robot puma560 --stream --from 30 -20 40 15 25 35 --unhomed");
  const double b = good("m.arm", move, "--robot puma560 --from 30 -20 40 15 25 35");
  DOUBLES_EQUAL(b, a, 1e-9);
  const auto r = check("h.arm", "home\nwait\n" + move, "--robot puma560 --stream");
  CHECK_TEXT(r.out.find("every joint absolute, nothing moved") != std::string::npos, r.out.c_str());
}

// park and G28: the joint move to motion.home_deg at motion.joint_speed_pct (the config's 40 %).
TEST(ProgramHoming, ParkAndG28GoToTheParkPose) {
  const double park = good("p.arm", "park\n", cfg() + " --from 30 -20 40 15 25 35");
  const double movej = good("j.arm", "movej 0 -45 180 0 45 0 speed=40\n", cfg() + " --from 30 -20 40 15 25 35");
  const double g28 = good("p.gcode", "G21\nG28\n", cfg() + " --from 30 -20 40 15 25 35");
  CHECK(park > 0);
  DOUBLES_EQUAL(movej, park, 1e-9);
  DOUBLES_EQUAL(movej, g28, 1e-9);
  // home is not park: a program of `home` alone plans no move
  const auto r = check("h.arm", "home\n", cfg() + " --from 30 -20 40 15 25 35");
  LONGS_EQUAL_TEXT(0, r.status, r.err.c_str());
  CHECK_TEXT(r.out.find("0 moves") != std::string::npos, r.out.c_str());
}

// What the console refuses is refused offline, naming the line.
TEST(ProgramHoming, WhatArmfwRefusesIsRefused) {
  const std::string c = cfg();
  bad("q.arm", "movej 0 -30 40 0 30 0\nhome\n", c, "q.arm:2:", "home refused: 1 move is still queued");
  bad("q2.arm", "movej 0 -30 40 0 30 0\ndwell 1\nhome\n", c, "q2.arm:3:", "2 moves are still queued");
  bad("w.arm", "home\npark\n", c, "w.arm:2:", "park refused: the homing cycle of");
  bad("w2.arm", "home\nmovel 500 100 300\n", c, "w2.arm:2:", "movel refused: the homing cycle of");
  bad("w3.arm", "home\ndwell 1\n", c, "w3.arm:2:", "dwell refused: the homing cycle");
  bad("w4.arm", "home\nhome j1\n", c, "w4.arm:2:", "home refused: the homing cycle of");
  bad("w5.gcode", "G21\n$H\n", c, "w5.gcode:2:", "");  // $H is the operator's (interactive only)
  // an unhomed arm (--unhomed: as at power-up): every move refused naming the joints not homed
  // (4 and 6 are absolute); `home j1` leaves 2, 3, 5; dwells are not moves
  bad("u.arm", "dwell 0.5\nmovej 0 -30 40 0 30 0\n", c + " --unhomed", "u.arm:2:",
      "movej refused: not_homed: joints 1, 2, 3, 5 not homed");
  bad("u2.arm", "home j1\nwait\npark\n", c + " --unhomed", "u2.arm:3:", "park refused: not_homed: joints 2, 3, 5 not homed");
  bad("u3.gcode", "G21\nG1 X500 Y100 Z300 F600\n", c + " --unhomed", "u3.gcode:2:", "not_homed: joints 1, 2, 3, 5");
  const double t = good("u4.arm", "home\nwait\npark\n", c + " --unhomed");
  CHECK(t > 0);
  // a homed position outside the joint's limits: the configuration is refused (as armfw refuses it
  // at start), naming the key, before any line is checked
  std::string off = kConfig;
  off.replace(off.find("homing.offset = 170"), 19, "homing.offset = 300");
  write_file(dir + "/off.toml", off);
  bad("o.arm", "home\n", "--stream --config " + dir + "/off.toml", dir + "/off.toml: ",
      "drive[3].homing.offset: 300 deg is outside joint 3's limits");
}

// Without --stream the file is checked as armfw's `run` runs it: `home`, `enable`, `disable`
// are not run inside a program, and an unhomed arm runs nothing (the console's not_homed).
TEST(ProgramHoming, AsArmfwsRunHomeIsNotRunInsideAProgram) {
  const std::string c = "--config " + dir + "/armfw.toml";
  bad("r.arm", "park\nhome\n", c, "r.arm:2:", "home is not run inside a program by armfw's `run`");
  bad("r2.arm", "enable\npark\n", c, "r2.arm:1:", "enable is not run inside a program");
  bad("r3.arm", "park\ndisable\n", "--robot puma560", "r3.arm:2:", "disable is not run inside a program");
  bad("r4.arm", "park\n", c + " --unhomed", "r4.arm:1:", "run refused: not_homed: joints 1, 2, 3, 5 not homed");
  // a homed arm runs it (the default), and so does an all-absolute arm from power-up
  CHECK(good("r5.arm", "park\nmovej 0 -30 40 0 30 0\n", c) > 0);
  CHECK(good("r6.arm", "park\nmovej 0 -30 40 0 30 0\n", "--robot puma560 --unhomed") > 0);
  // the same lines sent one by one: home allowed
  CHECK(good("r7.arm", "enable\nhome\nwait\npark\n", c + " --stream --unhomed") > 0);
}

// A configuration armfw refuses is refused, naming the key; --robot may come from it.
TEST(ProgramHoming, BadConfigurationsAreRefusedNamingTheKey) {
  std::string twice = kConfig;
  twice.replace(twice.find("[[3], [2], [1], [4, 5, 6]]"), 26, "[[3], [3], [1], [4, 5, 6]]");
  write_file(dir + "/twice.toml", twice);
  const auto a = check("a.arm", "home\n", "--config " + dir + "/twice.toml");
  LONGS_EQUAL_TEXT(2, a.status, a.err.c_str());
  CHECK_TEXT(a.err.find("homing.order") != std::string::npos, a.err.c_str());
  std::string method = kConfig;
  method.replace(method.find("homing.method = 21"), 18, "homing.method = 36");
  write_file(dir + "/method.toml", method);
  const auto b = check("a.arm", "home\n", "--config " + dir + "/method.toml");
  LONGS_EQUAL_TEXT(2, b.status, b.err.c_str());
  CHECK_TEXT(b.err.find("homing.method") != std::string::npos, b.err.c_str());
  const auto n = check("a.arm", "home\n", "--config " + dir + "/none.toml");
  LONGS_EQUAL_TEXT(2, n.status, n.err.c_str());
  CHECK_TEXT(n.err.find("none.toml") != std::string::npos, n.err.c_str());
  const auto r = check("a.arm", "home\n", "--from 0 0 0");
  LONGS_EQUAL(2, r.status);
  CHECK_TEXT(r.err.find("--robot is required") != std::string::npos, r.err.c_str());
}
