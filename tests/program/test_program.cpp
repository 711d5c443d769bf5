// SPDX-License-Identifier: Apache-2.0
// Program files (firmware/program/program.hpp): the flat list of (file, line, text) steps,
// repeats and calls expanded, @points, blend=, G-code; the issue's bad input refused with
// file and line named, nothing half-loaded. Expected steps are written out by hand.
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <string>
#include <vector>

#include "servoarm/lang/units.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/program/program.hpp"
#include "tmp_dir.hpp"

// CppUTest last: its leak detector redefines new.
#include <CppUTest/TestHarness.h>

using namespace servoarm;
using servoarm::test::make_tmp_dir;
using servoarm::test::remove_tree;
using servoarm::test::write_file;

TEST_GROUP(Program) {
  std::string dir;
  kin::Chain chain;
  prog::PointsData points;
  prog::ProgramContext ctx;
  // CppUTest's leak detector stays on: the group's members are destroyed before its
  // check. (Turning it off in setup and on in teardown made every member allocated in
  // setup a "Deallocating non-allocated memory" at their destruction, reported after each
  // test, and a LeakSanitizer abort under the asan preset.)
  void setup() override {
    dir = make_tmp_dir();
    const kin::LoadResult r = kin::load_robot("puma560");  // mm, deg, 6 revolute joints
    CHECK(r.ok);
    chain = r.chain;
    prog::TeachPoint p;
    p.name = "pick";
    p.q = kin::JointVector::Zero(6);
    p.q << 0.5, -0.25, 0.75, 0, 0.125, 0;  // rad: exact in binary
    kin::forward(chain, p.q, p.pose);
    points.points.push_back(p);
    ctx.chain = &chain;
    ctx.units = fw::units_of(chain);
    ctx.dir = dir;
    ctx.points = &points;
  }
  void teardown() override {
    remove_tree(dir);
  }
  std::string load(const std::string& name, const std::string& text, prog::Program& out) {
    write_file(dir + "/" + name, text);
    return prog::load_program(dir + "/" + name, ctx, out);
  }
  // The error of loading `text` as main.arm; it must name `where` (file:line) and `what`.
  void refused(const std::string& text, const std::string& where, const std::string& what, const char* name = "main.arm") {
    prog::Program out;
    out.steps.resize(1);  // "nothing half-loaded": untouched on failure
    const std::string e = load(name, text, out);
    CHECK_TEXT(!e.empty(), text.substr(0, 60).c_str());
    CHECK_TEXT(e.find(where) != std::string::npos, (e + "   [expected " + where + "]").c_str());
    CHECK_TEXT(e.find(what) != std::string::npos, (e + "   [expected " + what + "]").c_str());
    CHECK_TEXT(e.find('\n') == std::string::npos, e.c_str());
    LONGS_EQUAL(1, out.steps.size());
  }
};

TEST(Program, FlatStepsWithRepeatCallCommentsAndCrlf) {
  write_file(dir + "/sub.arm", "# a sub-program\nmovej 0 0 0 0 0 0\nwait\n");
  prog::Program p;
  const std::string e = load("main.arm",
                             "# pick and place\r\n"                // 1
                             "movej 10 20 30 0 0 0 speed=50\r\n"    // 2
                             "\r\n"                                 // 3
                             "repeat 2   ; twice\r\n"               // 4
                             "  movel 400 0 300 blend=2\r\n"        // 5
                             "  call sub\r\n"                       // 6
                             "end\r\n"                              // 7
                             "dwell 0.5 # half a second\r\n"        // 8
                             "movej @pick blend=5\r\n",             // 9 (no newline at the end of the file)
                             p);
  STRCMP_EQUAL("", e.c_str());
  LONGS_EQUAL(2, p.files.size());
  // Hand-expanded: 2, then (5, sub:2, sub:3) twice, 8, 9.
  const int file[] = {0, 0, 1, 1, 0, 1, 1, 0, 0};
  const int line[] = {2, 5, 2, 3, 5, 2, 3, 8, 9};
  const fw::Cmd cmd[] = {fw::Cmd::movej, fw::Cmd::movel, fw::Cmd::movej, fw::Cmd::wait, fw::Cmd::movel,
                         fw::Cmd::movej, fw::Cmd::wait,  fw::Cmd::dwell, fw::Cmd::movej};
  LONGS_EQUAL(9, p.steps.size());
  for (int i = 0; i < 9; ++i) {
    const prog::ProgramStep& s = p.steps[static_cast<std::size_t>(i)];
    LONGS_EQUAL_TEXT(file[i], s.file, p.where(s).c_str());
    LONGS_EQUAL_TEXT(line[i], s.line, p.where(s).c_str());
    CHECK_TEXT(cmd[i] == s.cmd.cmd, p.where(s).c_str());
  }
  DOUBLES_EQUAL(50, p.steps[0].cmd.speed, 0);
  DOUBLES_EQUAL(2, p.steps[1].blend, 0);             // blend= taken off the line, kept on the step
  STRCMP_EQUAL("movel 400 0 300", p.steps[1].text.c_str());
  DOUBLES_EQUAL(0.5, p.steps[7].cmd.vals[0], 0);      // dwell: the console's G4 S
  // @pick: its joints in the console's units (deg), exactly
  const prog::ProgramStep& pk = p.steps[8];
  LONGS_EQUAL(0, pk.point);
  DOUBLES_EQUAL(5, pk.blend, 0);
  DOUBLES_EQUAL(0.5 * 180 / M_PI, pk.cmd.vals[0], 1e-12);
  DOUBLES_EQUAL(0.75 * 180 / M_PI, pk.cmd.vals[2], 1e-12);
  CHECK(p.where(pk).find("main.arm:9") != std::string::npos);
  CHECK(p.where(p.steps[2]).find("sub.arm:2") != std::string::npos);
}

TEST(Program, GcodeFileWithG64AndM30) {
  prog::Program p;
  const std::string e = load("part.nc",
                             "%\n"                     // 1 skipped
                             "G21 G90 (metric)\n"      // 2 modal: a step doing nothing
                             "G64 P0.5\n"              // 3 blend 0.5 mm from here
                             "G1 X400 Y0 Z300 F600\n"  // 4
                             "G61\n"                   // 5 exact stop
                             "G1 X410\n"               // 6
                             "M30\n"                   // 7 end: nothing after is read
                             "this is not G-code\n",
                             p);
  STRCMP_EQUAL("", e.c_str());
  LONGS_EQUAL(4, p.steps.size());
  LONGS_EQUAL(2, p.steps[0].line);
  LONGS_EQUAL(4, p.steps[1].line);
  CHECK(fw::Cmd::gmove == p.steps[1].cmd.cmd);
  DOUBLES_EQUAL(0.5, p.steps[1].blend, 0);
  DOUBLES_EQUAL(10.0, p.steps[1].cmd.speed, 1e-12);  // F600 mm/min
  DOUBLES_EQUAL(0.0, p.steps[2].blend, 0);
  LONGS_EQUAL(7, p.steps[3].line);
}

TEST(Program, NestedRepeatsMultiply) {
  prog::Program p;
  STRCMP_EQUAL("", load("m.arm", "repeat 3\n repeat 4\n  wait\n end\n wait\nend\n", p).c_str());
  LONGS_EQUAL(3 * (4 + 1), p.steps.size());
}

TEST(Program, TheIssuesBadInput) {
  refused("movej 0 0 0 0 0 0\nfrobnicate 3\n", "main.arm:2:", "unknown command 'frobnicate'");
  refused("repeat 3\nmovej 0 0 0 0 0 0\n", "main.arm:1:", "repeat without end");
  refused("wait\nend\n", "main.arm:2:", "end without repeat");
  refused("wait\nmovej @nowhere\n", "main.arm:2:", "unknown point @nowhere");
  refused("movej 0 0 0 0 0\n", "main.arm:1:", "needs 6 joint values");
  refused("movel 1 2 3 blend=-1\n", "main.arm:1:", "blend=");
  refused("wait\njog j1 +5\n", "main.arm:2:", "not allowed in a program");
  refused("repeat 0\nend\n", "main.arm:1:", "repeat needs a count");
  refused("call ../etc/passwd\n", "main.arm:1:", "no path");
  refused("call missing\n", "main.arm:1:", "no program 'missing'");
  refused("G64\n", "main.gcode:1:", "G64 needs P", "main.gcode");
}

TEST(Program, RecursionAndDepthRefused) {
  write_file(dir + "/a.arm", "wait\ncall b\n");
  write_file(dir + "/b.arm", "wait\nwait\ncall a\n");
  refused("call a\n", "b.arm:3:", "recursion");
  refused("wait\ncall main\n", "main.arm:2:", "recursion");  // itself
  // A chain 12 deep: refused at the 9th call (max_call_depth 8), naming that line.
  for (int i = 1; i < 12; ++i) write_file(dir + "/d" + std::to_string(i) + ".arm", "call d" + std::to_string(i + 1) + "\n");
  write_file(dir + "/d12.arm", "wait\n");
  refused("call d1\n", "d8.arm:1:", "nested deeper than 8");
  // The same sub-program called twice (not recursion) is fine.
  write_file(dir + "/s.arm", "wait\n");
  prog::Program p;
  STRCMP_EQUAL("", load("twice.arm", "call s\ncall s\n", p).c_str());
  LONGS_EQUAL(2, p.steps.size());
}

TEST(Program, BinaryGarbageRefusedWithTheLine) {
  refused(std::string("wait\nwait\nmo\0vej\n", 17), "main.arm:3:", "binary data (byte 0x00");
  refused("wait\r\rwait\n", "main.arm:1:", "binary data (byte 0x0D");  // a lone CR is no line end
  std::string elf = "\x7f" "ELF\x02\x01\x01";
  refused(elf, "main.arm:1:", "binary data");
  refused("wait\nmovej 1 2 3 4 5 \xc3\xa9\n", "main.arm:2:", "non-ASCII");
}

TEST(Program, HugeFileRefusedFastBySize) {
  const std::string path = dir + "/huge.arm";
  write_file(path, "wait\n");
  CHECK_EQUAL(0, ::truncate(path.c_str(), 100L * 1000 * 1000));  // 100 MB (sparse: no disk used)
  prog::Program p;
  const auto t0 = std::chrono::steady_clock::now();
  const std::string e = prog::load_program(path, ctx, p);
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  CHECK_TEXT(e.find("larger than") != std::string::npos, e.c_str());
  CHECK_TEXT(ms < 5000, e.c_str());  // refused by fstat, not read (generous: qemu, loaded host)
}

TEST(Program, ExpansionBoundedBeforeAnythingIsExpanded) {
  // 10^15 steps on paper: refused from the counts, at once.
  const auto t0 = std::chrono::steady_clock::now();
  refused("repeat 100000\nrepeat 100000\nrepeat 100000\nwait\nend\nend\nend\n", "main.arm", "more than 200000 steps");
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  CHECK(ms < 5000);
  // Nothing inside: nothing to do, however large the counts, and at once (it took 10^10
  // empty passes, 9 s, before).
  prog::Program p;
  const auto t1 = std::chrono::steady_clock::now();
  STRCMP_EQUAL("", load("empty.arm", "repeat 100000\nrepeat 100000\n# nothing\nend\nend\n", p).c_str());
  LONGS_EQUAL(0, p.steps.size());
  const double ms1 = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t1).count();
  CHECK(ms1 < 2000);
}

TEST(Program, NoPointsFileNamesThat) {
  ctx.points = nullptr;
  refused("movel @pick\n", "main.arm:1:", "no points file");
}

TEST(Program, ListsProgramsAndFindsByName) {
  write_file(dir + "/a.arm", "wait\n");
  write_file(dir + "/b.gcode", "G4 P1\n");
  write_file(dir + "/notes.md", "x\n");
  std::vector<std::string> names;
  STRCMP_EQUAL("", prog::list_programs(dir, names).c_str());
  LONGS_EQUAL(2, names.size());
  STRCMP_EQUAL("a.arm", names[0].c_str());
  STRCMP_EQUAL("b.gcode", names[1].c_str());
  STRCMP_EQUAL((dir + "/b.gcode").c_str(), prog::find_program(dir, "b").c_str());
  STRCMP_EQUAL("", prog::find_program(dir, "notes").c_str());
}
