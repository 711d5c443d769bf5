// SPDX-License-Identifier: Apache-2.0
// armctl program check as a process: the issue's bad-input list refused with
// file:line and exit 2, a good program answered with its moves and cycle time (checked
// against the closed form of a jerk-limited rest-to-rest move), CRLF = LF.
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <utility>
#include <string>

#include "../armctl/run_command.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/kinematics/chain.hpp"
#include "servoarm/program/points.hpp"
#include "tmp_dir.hpp"

// CppUTest last: its leak detector redefines new.
#include <CppUTest/TestHarness.h>

using servoarm::test::cycle_time;
using servoarm::test::make_tmp_dir;
using servoarm::test::program_check;
using servoarm::test::remove_tree;
using servoarm::test::run_command;
using servoarm::test::write_file;

namespace {

const std::string kArmctl = ARMCTL_PATH;

}  // namespace

TEST_GROUP(CliProgram) {
  std::string dir;
  void setup() override {
    MemoryLeakWarningPlugin::saveAndDisableNewDeleteOverloads();
    dir = make_tmp_dir();
  }
  void teardown() override {
    remove_tree(dir);
    std::string().swap(dir);  // allocated with the leak detector off: freed with it off
    MemoryLeakWarningPlugin::restoreNewDeleteOverloads();
  }
  servoarm::test::CommandResult check(const std::string& name, const std::string& text, const std::string& extra = "") {
    return program_check(kArmctl, dir + "/" + name, text, "--robot puma560 " + extra);
  }
  void bad(const std::string& name, const std::string& text, const std::string& where, const std::string& what,
           const std::string& extra = "") {
    const auto r = check(name, text, extra);
    LONGS_EQUAL_TEXT(2, r.status, (r.out + r.err).c_str());
    CHECK_TEXT(r.err.find(where) != std::string::npos, (r.err + "   [expected " + where + "]").c_str());
    CHECK_TEXT(r.err.find(what) != std::string::npos, (r.err + "   [expected " + what + "]").c_str());
    CHECK_TEXT(r.out.find("ok:") == std::string::npos, r.out.c_str());
  }
};

TEST(CliProgram, GoodProgramCycleTimeIsTheClosedForm) {
  // One movej of joint 1 by d = 90 deg at 50 %: joint 1's limits (the loader's) scaled by
  // the override s as the planner does: v s, a s^2, j s^3. Where the profile reaches both
  // (v >= a^2/j, d >= v (v/a + a/j)) the closed form is T = d/v + v/a + a/j. Then a dwell of
  // 1.25 s and the way back (the same time).
  const servoarm::kin::LoadResult lr = servoarm::kin::load_robot("puma560");
  CHECK(lr.ok);
  const servoarm::kin::JointDynamics dy = lr.chain.joint(0).dynamics;
  const double s = 0.5, d = M_PI / 2, v = dy.max_velocity * s, a = dy.max_acceleration * s * s, j = dy.max_jerk * s * s * s;
  CHECK(v >= a * a / j && d >= v * (v / a + a / j));
  const double T = d / v + v / a + a / j;
  const auto r = check("one.arm", "movej 90 0 0 0 0 0\ndwell 1.25\nmovej 0 0 0 0 0 0 speed=50\n");
  LONGS_EQUAL_TEXT(0, r.status, r.err.c_str());
  CHECK_TEXT(r.out.find(": 3 steps: 2 moves (2 joint, 0 linear), 1 dwell,") != std::string::npos, r.out.c_str());
  DOUBLES_EQUAL(T + 1.25 + T, cycle_time(r.out), 1e-6);
}

TEST(CliProgram, CrlfIsLf) {
  const std::string text = "movej 10 -20 30 0 40 0\nmovel 500 100 300\nrepeat 2\nmovej 0 -30 40 0 30 0\nend\n";
  std::string crlf;
  for (char c : text) crlf += c == '\n' ? std::string("\r\n") : std::string(1, c);
  const auto a = check("lf.arm", text), b = check("crlf.arm", crlf);
  LONGS_EQUAL_TEXT(0, a.status, a.err.c_str());
  LONGS_EQUAL_TEXT(0, b.status, b.err.c_str());
  CHECK(cycle_time(a.out) > 0);
  DOUBLES_EQUAL(cycle_time(a.out), cycle_time(b.out), 0);
}

TEST(CliProgram, UnreachableTargetAtLine317Of1000) {
  std::string text;
  for (int i = 1; i <= 1000; ++i) {
    if (i == 317) text += "movel 5000 0 0\n";  // 5 m away: the arm reaches about 0.9 m
    else if (i < 317) text += i % 2 ? "movej 10 -20 30 0 40 0\n" : "movej 0 -30 40 0 30 0\n";
    else text += "wait\n";
  }
  bad("long.arm", text, "long.arm:317:", "movel refused");
}

TEST(CliProgram, TheIssuesBadInputList) {
  bad("u.arm", "movej 0 0 0 0 0 0\nfrobnicate\n", "u.arm:2:", "unknown command");
  bad("e.arm", "wait\nrepeat 2\nwait\n", "e.arm:2:", "repeat without end");
  write_file(dir + "/r2.arm", "call r1\n");
  bad("r1.arm", "wait\ncall r2\n", "r2.arm:1:", "recursion");
  bad("p.arm", "movej @nowhere\n", "p.arm:1:", "unknown point @nowhere");
  bad("b.arm", std::string("wait\n\0\0\0\xff", 9), "b.arm:2:", "binary data");
  bad("l.arm", "movej 0 0 0 0 0 0\nmovej 200 0 0 0 0 0\n", "l.arm:2:", "joint 1 = 200 outside [-160, 160] deg");
  bad("g.gcode", "G21\nG1 X5000 Y0 Z0 F600\n", "g.gcode:2:", "movel refused");
  // 100 MB: refused by its size, before it is read
  write_file(dir + "/huge.arm", "wait\n");
  CHECK_EQUAL(0, ::truncate((dir + "/huge.arm").c_str(), 100L * 1000 * 1000));
  const auto h = run_command(kArmctl + " program check " + dir + "/huge.arm --robot puma560");
  LONGS_EQUAL(2, h.status);
  CHECK_TEXT(h.err.find("larger than") != std::string::npos, h.err.c_str());
}

TEST(CliProgram, PointsFileUsedAndACorruptOneRefused) {
  // Joints in rad: (0.2, -0.5, 0.6, 0, 0.4, 0)
  write_file(dir + "/points.toml",
             "format = \"servoarm-points-1\"\n[point.pick]\njoints = [0.2, -0.5, 0.6, 0.0, 0.4, 0.0]\n"
             "xyz = [0.0, 0.0, 0.0]\nrpy = [0.0, 0.0, 0.0]\n");
  const auto r = check("pts.arm", "movej @pick\nmovel 500 100 300\nmovel @pick\n", "--points " + dir + "/points.toml");
  LONGS_EQUAL_TEXT(0, r.status, r.err.c_str());
  CHECK_TEXT(r.out.find("3 moves (1 joint, 2 linear)") != std::string::npos, r.out.c_str());
  write_file(dir + "/bad.toml", "format = \"servoarm-points-1\"\n[point.pick]\njoints = [1, 2]\nxyz = [0,0,0]\nrpy = [0,0,0]\n");
  const auto b = check("pts.arm", "movej @pick\n", "--points " + dir + "/bad.toml");
  LONGS_EQUAL(2, b.status);
  CHECK_TEXT(b.err.find("bad.toml:3:") != std::string::npos, b.err.c_str());
}

TEST(CliProgram, UsageErrors) {
  LONGS_EQUAL(2, run_command(kArmctl + " program").status);
  LONGS_EQUAL(2, run_command(kArmctl + " program run x").status);
  LONGS_EQUAL(2, run_command(kArmctl + " program check").status);
  const auto n = run_command(kArmctl + " program check " + dir + "/none.arm --robot puma560");
  LONGS_EQUAL(2, n.status);
  CHECK(n.err.find("none.arm") != std::string::npos);
  const auto h = run_command(kArmctl + " program --help");
  LONGS_EQUAL(0, h.status);
  CHECK(h.out.find("armctl program check FILE") != std::string::npos);
}

// The example program (firmware/program/examples): each `movel @pick` / `movel @place` goes
// straight down along the tool (which points down) from its above-point, as its comments say;
// with its blends it ends earlier than with every move to rest (both times printed).
TEST(CliProgram, PickPlaceExampleGoesDownAndBlendingGains) {
  const std::string ex = std::string(SERVOARM_SOURCE_DIR) + "/firmware/program/examples";
  const servoarm::kin::LoadResult lr = servoarm::kin::load_robot("puma560");
  CHECK(lr.ok);
  servoarm::prog::PointsData pts;
  STRCMP_EQUAL("", servoarm::prog::load_points_file(ex + "/points.toml", 6, pts).c_str());
  for (const auto& [above, at] : {std::pair{"above_pick", "pick"}, std::pair{"above_place", "place"}}) {
    const servoarm::prog::TeachPoint* a = servoarm::prog::find_point(pts, above);
    const servoarm::prog::TeachPoint* p = servoarm::prog::find_point(pts, at);
    CHECK(a != nullptr && p != nullptr);
    servoarm::kin::Pose xa, xp;
    CHECK(servoarm::kin::forward(lr.chain, a->q, xa) == servoarm::kin::Status::ok);
    CHECK(servoarm::kin::forward(lr.chain, p->q, xp) == servoarm::kin::Status::ok);
    const Eigen::Vector3d tool_z = xa.linear().col(2), down = xp.translation() - xa.translation();
    std::printf("\n%s -> %s: %.1f mm along the tool axis, %.2f mm off it; tool z = (%.3f %.3f %.3f)", above, at,
                1e3 * down.dot(tool_z), 1e3 * (down - down.dot(tool_z) * tool_z).norm(), tool_z.x(), tool_z.y(), tool_z.z());
    CHECK_TEXT(tool_z.z() < -0.99, above);                   // the tool points down
    CHECK_TEXT(down.z() < -0.05, at);                        // the part is below its above-point
    CHECK_TEXT(down.dot(tool_z) > 0.05, at);                 // along the tool's axis ...
    CHECK_TEXT((down - down.dot(tool_z) * tool_z).norm() < 1e-3, at);  // ... straight
    CHECK_TEXT((xp.translation() - p->pose.translation()).norm() < 1e-6, at);  // the file's xyz is the joints'
    CHECK_TEXT((xa.translation() - a->pose.translation()).norm() < 1e-6, above);
  }
  const auto r = run_command(kArmctl + " program check " + ex + "/pick_place.arm --robot puma560 --points " + ex +
                             "/points.toml");
  LONGS_EQUAL_TEXT(0, r.status, (r.out + r.err).c_str());
  const double blended = cycle_time(r.out);
  const std::size_t k = r.out.find("; ");
  CHECK_TEXT(k != std::string::npos, r.out.c_str());
  const double exact = std::strtod(r.out.c_str() + k + 2, nullptr);
  std::printf("\npick_place.arm: %.3f s blended, %.3f s with every move to rest\n", blended, exact);
  CHECK_TEXT(blended > 0 && exact > 0 && blended < exact, r.out.c_str());
}

// [safety] from --config: the whole-program check refuses the line whose move goes through a
// safety plane, with the service's own line (function, where, limit, value), at file:line.
TEST(CliProgram, ASafetyPlaneRefusesTheLineThatCrossesIt) {
  const servoarm::kin::LoadResult lr = servoarm::kin::load_robot("puma560");
  CHECK_TEXT(lr.ok, lr.error.c_str());
  servoarm::kin::JointVector q(6);
  const double d[6] = {0, -45, 180, 0, 45, 0};
  for (int j = 0; j < 6; ++j) q[j] = d[j] * M_PI / 180.0;
  servoarm::kin::Pose p;
  CHECK(servoarm::kin::forward(lr.chain, q, p) == servoarm::kin::Status::ok);
  char cfg[200];
  std::snprintf(cfg, sizeof cfg, "robot = \"puma560\"\n[safety]\nplanes = [0, 0, 1, %.3f]\ntool_radius_mm = 10\n",
                p.translation().z() * 1000.0 - 60.0);
  write_file(dir + "/armfw.toml", cfg);
  const std::string text = "movej 0 -45 180 0 45 0\nmovej 0 -50 180 0 45 0\nmovej 0 -20 180 0 45 0\n";
  bad("plane.arm", text, "plane.arm:3:", "movej refused: safety plane 0 (tool sphere) at s=",
      "--config " + dir + "/armfw.toml");
  const auto fine = check("fine.arm", "movej 0 -45 180 0 45 0\nmovej 0 -50 180 0 45 0\n", "--config " + dir + "/armfw.toml");
  LONGS_EQUAL_TEXT(0, fine.status, (fine.out + fine.err).c_str());
}
