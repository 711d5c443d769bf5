// SPDX-License-Identifier: Apache-2.0
// armctl plan movej | movel through cli_plan(): exit codes, CSV content, SVG written.
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "servoarm/armctl/cli_plan.hpp"

// CppUTest last: its leak detector redefines new.
#include <CppUTest/TestHarness.h>

namespace {

int plan_cli(std::vector<std::string> args) {
  args.insert(args.begin(), "plan");
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  std::fflush(stdout);
  return servoarm::fw::cli_plan(static_cast<int>(argv.size()), argv.data());
}

std::string slurp(const std::string& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

}  // namespace

TEST_GROUP(CliPlan) {
  void setup() override { MemoryLeakWarningPlugin::saveAndDisableNewDeleteOverloads(); }
  void teardown() override { MemoryLeakWarningPlugin::restoreNewDeleteOverloads(); }
};

TEST(CliPlan, MovejWritesCsvAndSvg) {
  const std::string csv = "/tmp/servoarm_test_plan_movej.csv", svg = "/tmp/servoarm_test_plan_movej.svg";
  CHECK_EQUAL(0, plan_cli({"movej", "--robot", "puma560", "--from", "0", "-45", "180", "0", "45", "0", "--to", "90", "-90",
                      "150", "45", "-30", "90", "--vmax", "90", "--csv", csv, "--svg", svg}));
  const std::string c = slurp(csv);
  CHECK(c.rfind("t,q1,q2,q3,q4,q5,q6,v1,", 0) == 0);
  // First row is the start, last row the goal at rest (description units: degrees).
  CHECK(c.find("\n0.000000,0,-45,180,0,45,0,0,0,0,0,0,0,0,") != std::string::npos);
  const std::string last = c.substr(c.rfind('\n', c.size() - 2) + 1);
  CHECK(last.find(",90,-90,150,45,-30,90,0,0,0,0,0,0,0,0,0,0,0,0") != std::string::npos);
  const std::string s = slurp(svg);
  CHECK(s.rfind("<svg", 0) == 0);
  CHECK(s.find("polyline") != std::string::npos);
  CHECK(s.find("</svg>") != std::string::npos);
  std::remove(csv.c_str());
  std::remove(svg.c_str());
}

TEST(CliPlan, MovelPlansAndRefuses) {
  CHECK_EQUAL(0, plan_cli({"movel", "--robot", "puma560", "--from", "10", "-80", "40", "10", "45", "5", "--to", "20", "-70",
                      "30", "0", "30", "15"}));
  // 3 m away: outside the workspace -> refused (exit 1) with the reason.
  CHECK_EQUAL(1, plan_cli({"movel", "--robot", "puma560", "--from", "10", "-80", "40", "10", "45", "5", "--xyz", "3000",
                      "0", "0"}));
}

TEST(CliPlan, BadUsage) {
  CHECK_EQUAL(2, plan_cli({"movex"}));
  CHECK_EQUAL(2, plan_cli({"movej", "--robot", "puma560", "--from", "0", "0", "0", "0", "0", "--to", "1"}));
  CHECK_EQUAL(2, plan_cli({"movej", "--robot", "nosuchrobot", "--from", "0", "--to", "1"}));
  CHECK_EQUAL(2, plan_cli({"movej", "--robot", "puma560", "--from", "0", "0", "0", "0", "0", "0", "--to", "0", "0", "0",
                      "0", "0", "x"}));
  CHECK_EQUAL(2, plan_cli({"movej", "--robot", "puma560", "--from", "0", "0", "0", "0", "0", "0", "--to", "0", "0", "0",
                      "0", "0", "0", "--override", "0"}));
  // Goal outside the joint limits (joint 1 is +-160 deg): a valid request the planner refuses.
  CHECK_EQUAL(1, plan_cli({"movej", "--robot", "puma560", "--from", "0", "0", "0", "0", "0", "0", "--to", "170", "0",
                      "0", "0", "0", "0"}));
}
