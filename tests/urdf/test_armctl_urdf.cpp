// SPDX-License-Identifier: Apache-2.0
// armctl urdf import / export as a process: bad input is one line, exit 2, nothing
// written (malformed XML, a loop, no path base -> tip, a zero axis, NaN, a 50 MB file,
// mimic / floating joints on the chain, two tips); a good import writes a description
// that armctl kin fk reads with the URDF's joint values; export -> import -> same FK.
#include <sys/stat.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <iterator>
#include <string>

#include "../armctl/run_command.hpp"

#include <CppUTest/TestHarness.h>

using servoarm::test::run_command;

namespace {
const std::string kArmctl = ARMCTL_PATH;
const std::string kData = URDF_DATA_DIR;

std::string tmp(const std::string& name) { return "/tmp/servoarm_urdf_" + std::to_string(getpid()) + "_" + name; }

bool exists(const std::string& p) {
  struct stat st {};
  return ::stat(p.c_str(), &st) == 0;
}

int lines(const std::string& s) {
  int n = 0;
  for (char c : s) n += c == '\n';
  return n;
}

void write(const std::string& path, const std::string& text) { std::ofstream(path) << text; }
std::string read(const std::string& path) {
  std::ifstream f(path);
  return std::string(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
}

const char* kTwoLinks =
    "<robot name=\"r\">\n"
    "  <link name=\"base\"/><link name=\"l1\"/><link name=\"l2\"/>\n"
    "  <joint name=\"j1\" type=\"revolute\"><parent link=\"base\"/><child link=\"l1\"/>\n"
    "    <origin xyz=\"0 0 0.1\" rpy=\"0 0 0\"/><axis xyz=\"AXIS\"/><limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/></joint>\n"
    "  <joint name=\"j2\" type=\"TYPE2\"><parent link=\"l1\"/><child link=\"l2\"/>\n"
    "    <origin xyz=\"ORIGIN\" rpy=\"0 0 0\"/><axis xyz=\"0 1 0\"/><limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/>MIMIC</joint>\n"
    "EXTRA</robot>\n";

std::string two_links(const std::string& axis, const std::string& type2, const std::string& origin, const std::string& mimic,
                      const std::string& extra = "") {
  std::string s = kTwoLinks;
  auto rep = [&](const std::string& k, const std::string& v) { s.replace(s.find(k), k.size(), v); };
  rep("AXIS", axis);
  rep("TYPE2", type2);
  rep("ORIGIN", origin);
  rep("MIMIC", mimic);
  rep("EXTRA", extra);
  return s;
}

struct Bad {
  std::string file_text;  // "" = use `file` as is
  std::string file;
  std::string options;
  std::string names;  // the error names this
};

}  // namespace

TEST_GROUP(ArmctlUrdf){};

TEST(ArmctlUrdf, TiedFingersEndTheChainAtTool0OrWhereTheyBranch) {
  // Two gripper fingers tie as the ends of the longest chain: without --tip the arm ends at
  // tool0 when there is one (the same description as --tip tool0), else where they branch.
  const std::string a = tmp("tie_a.toml"), b = tmp("tie_b.toml");
  const auto r1 = run_command(kArmctl + " urdf import " + kData + "/tool_beyond_flange.urdf -o " + a);
  CHECK_TEXT(r1.status == 0, r1.err.c_str());
  const auto r2 = run_command(kArmctl + " urdf import " + kData + "/tool_beyond_flange.urdf --tip tool0 -o " + b);
  CHECK_TEXT(r2.status == 0, r2.err.c_str());
  const auto fk1 = run_command(kArmctl + " kin fk --robot " + a + " 10 -20 30 40 50 60");
  const auto fk2 = run_command(kArmctl + " kin fk --robot " + b + " 10 -20 30 40 50 60");
  CHECK_TEXT(fk1.status == 0 && !fk1.out.empty(), fk1.err.c_str());
  STRCMP_EQUAL(fk2.out.c_str(), fk1.out.c_str());
  // Without tool0: the chain ends at gripper_base, where the fingers branch off.
  std::string text = read(kData + "/tool_beyond_flange.urdf");
  for (std::size_t p; (p = text.find("\"tool0\"")) != std::string::npos;) text.replace(p, 7, "\"tool9\"");
  const std::string in = tmp("no_tool0.urdf");
  write(in, text);
  const auto r3 = run_command(kArmctl + " urdf import " + in + " -o " + a);
  CHECK_TEXT(r3.status == 0, r3.err.c_str());
  const std::string conv = read(a);
  CHECK_TEXT(conv.find("gripper_base") != std::string::npos, conv.c_str());
  std::remove(in.c_str());
  std::remove(a.c_str());
  std::remove(b.c_str());
}

TEST(ArmctlUrdf, BadInputIsOneLineExitTwoAndNothingWritten) {
  const std::string in = tmp("bad.urdf"), out = tmp("bad.toml");
  const Bad cases[] = {
      {"<robot name=\"r\"><link name=\"a\">", in, "", "not a valid URDF"},
      {two_links("0 0 1", "revolute", "0 0 0.2", "",
                 "  <joint name=\"back\" type=\"fixed\"><parent link=\"l2\"/><child link=\"l1\"/></joint>\n"),
       in, "", "loop"},
      {"", kData + "/opw_like.urdf", "--base flange --tip base_link", "no path from 'flange' to 'base_link'"},
      {"", kData + "/opw_like.urdf", "--tip nowhere", "no link 'nowhere'"},
      {two_links("0 0 0", "revolute", "0 0 0.2", ""), in, "", "joint 'j1': <axis> is zero"},
      {two_links("0 0 1", "revolute", "nan 0 0.2", ""), in, "", "[nan]"},
      {two_links("0 0 1", "revolute", "0 0 0.2", "", "  <link name=\"l3\"><inertial><mass value=\"nan\"/></inertial></link>\n"), in, "", "nan"},
      {two_links("0 0 1", "revolute", "0 0 0.2", "<mimic joint=\"j1\" multiplier=\"1\"/>"), in, "", "joint 'j2': mimics joint 'j1'"},
      {two_links("0 0 1", "floating", "0 0 0.2", ""), in, "", "joint 'j2': floating joints are not supported"},
      {two_links("0 0 1", "planar", "0 0 0.2", ""), in, "", "joint 'j2': planar joints are not supported"},
      {"", kData + "/missing.urdf", "", "missing.urdf"},
  };
  for (const Bad& b : cases) {
    if (!b.file_text.empty()) write(b.file, b.file_text);
    std::remove(out.c_str());
    const auto r = run_command(kArmctl + " urdf import " + b.file + " " + b.options + " -o " + out);
    const std::string what = b.names + "\n  rc " + std::to_string(r.status) + "\n  stderr: " + r.err;
    CHECK_TEXT(r.status == 2, what.c_str());
    CHECK_TEXT(r.err.find(b.names) != std::string::npos, what.c_str());
    CHECK_TEXT(lines(r.err) == 1 && r.err.rfind("armctl: ", 0) == 0, what.c_str());
    CHECK_TEXT(!exists(out), what.c_str());
  }
  std::remove(in.c_str());
}

TEST(ArmctlUrdf, FiftyMegabyteFileIsRefusedBySizeBeforeParsing) {
  const std::string in = tmp("big.urdf"), out = tmp("big.toml");
  {
    std::ofstream f(in);
    f << "<robot name=\"big\"><!--";
    const std::string chunk(1 << 20, 'x');
    for (int i = 0; i < 50; ++i) f << chunk;
    f << "--></robot>\n";
  }
  const auto r = run_command(kArmctl + " urdf import " + in + " -o " + out);
  CHECK_EQUAL(2, r.status);
  CHECK_TEXT(r.err.find("larger than 4194304 bytes") != std::string::npos, r.err.c_str());
  CHECK_EQUAL(1, lines(r.err));
  CHECK(!exists(out));
  std::remove(in.c_str());
}

TEST(ArmctlUrdf, ImportWritesADescriptionThatKinFkReadsWithTheUrdfsJointValues) {
  const std::string out = tmp("ur.toml");
  auto r = run_command(kArmctl + " urdf import " + kData + "/ur_like.urdf -o " + out);
  CHECK_EQUAL(0, r.status);
  CHECK_TEXT(r.out.find("6 joints, standard DH, IK: ur") != std::string::npos, r.out.c_str());
  // At zero the URDF's flange is at (1.18, 0.25, 0.06) m: the converted file's zero is the URDF's.
  r = run_command(kArmctl + " kin fk --robot " + out + " --json 0 0 0 0 0 0");
  CHECK_EQUAL(0, r.status);
  CHECK_TEXT(r.out.find("[1180, 250, 60]") != std::string::npos, r.out.c_str());
  // The URDF itself as --robot: converted at load, same answer.
  const auto direct = run_command(kArmctl + " kin fk --robot " + kData + "/ur_like.urdf --json 0 0 0 0 0 0");
  CHECK_EQUAL(0, direct.status);
  CHECK_TEXT(direct.out.find("[1180, 250, 60]") != std::string::npos, direct.out.c_str());
  std::remove(out.c_str());
}

TEST(ArmctlUrdf, ExportThenImportGivesTheSameFk) {
  const std::string urdf = tmp("puma.urdf"), back = tmp("puma.toml");
  auto r = run_command(kArmctl + " urdf export --robot puma560 -o " + urdf);
  CHECK_EQUAL(0, r.status);
  r = run_command(kArmctl + " urdf import " + urdf + " -o " + back);
  CHECK_EQUAL(0, r.status);
  const std::string q = " --json 10 -40 150 20 30 40";
  const auto a = run_command(kArmctl + " kin fk --robot puma560" + q);
  const auto b = run_command(kArmctl + " kin fk --robot " + back + q);
  CHECK_EQUAL(0, b.status);
  const auto pos = [](const std::string& s) { return s.substr(s.find("\"position\""), 60); };
  STRCMP_EQUAL(pos(a.out).c_str(), pos(b.out).c_str());
  std::remove(urdf.c_str());
  std::remove(back.c_str());
}
