// SPDX-License-Identifier: Apache-2.0
// armctl kin ... end to end. Expected values come from the seed closed forms
// (rr_planar, V. Carrara, Apostila de Robótica, §4.1) and from the orientation definitions, not from
// armctl's own code path.
#include <cmath>
#include <string>
#include <vector>

#include "run_command.hpp"

#include <CppUTest/TestHarness.h>

using servoarm::test::json_numbers;
using servoarm::test::run_command;

namespace {
const std::string kArmctl = ARMCTL_PATH;
double rad(double d) { return d * M_PI / 180; }
}  // namespace

TEST_GROUP(ArmctlKin){};

TEST(ArmctlKin, FkJsonOfThePlanarArmMatchesTheSeedClosedFormInMillimetres) {
  for (double q1 : {-150.0, -30.0, 0.0, 45.0, 170.0}) {
    for (double q2 : {-90.0, 10.0, 120.0}) {
      const auto r = run_command(kArmctl + " kin fk --robot rr_planar --json " + std::to_string(q1) + " " + std::to_string(q2));
      LONGS_EQUAL(0, r.status);
      const auto p = json_numbers(r.out, "position");
      LONGS_EQUAL(3, p.size());
      DOUBLES_EQUAL(300 * std::cos(rad(q1)) + 250 * std::cos(rad(q1 + q2)), p[0], 1e-6);
      DOUBLES_EQUAL(300 * std::sin(rad(q1)) + 250 * std::sin(rad(q1 + q2)), p[1], 1e-6);
      const auto R = json_numbers(r.out, "rotation");
      LONGS_EQUAL(9, R.size());
      DOUBLES_EQUAL(std::cos(rad(q1 + q2)), R[0], 1e-9);  // x axis of the last link
      DOUBLES_EQUAL(std::sin(rad(q1 + q2)), R[3], 1e-9);
      const auto rpy = json_numbers(r.out, "rpy");  // planar: yaw = q1 + q2 (wrapped), degrees
      LONGS_EQUAL(3, rpy.size());
      DOUBLES_EQUAL(0.0, std::remainder(rpy[2] - (q1 + q2), 360.0), 1e-7);
      const auto quat = json_numbers(r.out, "quaternion");
      LONGS_EQUAL(4, quat.size());
      DOUBLES_EQUAL(std::abs(std::cos(rad(q1 + q2) / 2)), quat[0], 1e-9);
      CHECK(r.out.find("\"zyz\"") != std::string::npos);
    }
  }
}

TEST(ArmctlKin, TextOutputNamesTheUnits) {
  const auto r = run_command(kArmctl + " kin fk --robot puma560 0 0 0 0 0 0");
  LONGS_EQUAL(0, r.status);
  CHECK(r.out.find("position [mm]") != std::string::npos);
  CHECK(r.out.find("ZYZ [deg]") != std::string::npos);
  CHECK(r.out.find("RPY [deg]") != std::string::npos);
  CHECK(r.out.find("quaternion") != std::string::npos);
}

TEST(ArmctlKin, JacobianJsonHasSixRowsOfNAndTheRrClosedForm) {
  const auto r = run_command(kArmctl + " kin jacobian --robot rr_planar --json 30 60");
  LONGS_EQUAL(0, r.status);
  const auto J = json_numbers(r.out, "jacobian");
  LONGS_EQUAL(12, J.size());
  // dx/dq1 = -(a1 s1 + a2 s12) in mm/rad
  DOUBLES_EQUAL(-(300 * std::sin(rad(30)) + 250 * std::sin(rad(90))), J[0], 1e-6);
  DOUBLES_EQUAL(-250 * std::sin(rad(90)), J[1], 1e-6);
  DOUBLES_EQUAL(1.0, J[10], 1e-12);  // wz per joint 1
  CHECK(r.out.find("\"manipulability\"") != std::string::npos);
}

TEST(ArmctlKin, ModelsListsEveryBuiltin) {
  const auto r = run_command(kArmctl + " kin models");
  LONGS_EQUAL(0, r.status);
  for (const char* n : {"puma560", "puma560_craig", "stanford", "cylindrical_rpp_rrr", "ist6", "rr_planar",
                        "rrr_planar", "rlr_planar", "trr", "trl_r", "vvl_r", "vvr_vr"})
    CHECK_TEXT(r.out.find(n) != std::string::npos, n);
}

TEST(ArmctlKin, BadInputIsOneLineOnStderrAndExitStatus2) {
  struct Case {
    const char* args;
    const char* expect;
  } cases[] = {
      {"kin fk --robot puma560 1 2 3", "has 6 joints, got 3"},
      {"kin fk --robot puma560 1 2 3 4 5 6 7", "has 6 joints, got 7"},
      {"kin fk --robot puma560 1 2 3 4 5 nan", "'nan' is not a finite number"},
      {"kin fk --robot puma560 1 2 3 4 5 1e999", "not a finite number"},
      {"kin fk --robot puma560 1 2 3 4 5 6x", "'6x' is not a finite number"},
      {"kin fk --robot puma561 0 0 0 0 0 0", "unknown robot 'puma561'"},
      {"kin fk --robot /nonexistent/arm.toml 0", "cannot open"},
      {"kin fk 0 0 0", "--robot is required"},
      {"kin fk --robot", "--robot needs"},
      {"kin fk --robot puma560 --bogus 0 0 0 0 0 0", "unknown option '--bogus'"},
      {"kin fk --robot puma560 --strict 200 0 0 0 0 0", "joint 1: value 200 is outside [-160, 160] deg"},
      {"kin jacobian --robot ist6 1 2", "has 6 joints, got 2"},
      {"kin frobnicate", "unknown kin command 'frobnicate'"},
      {"fly", "unknown command 'fly'"},
  };
  for (const Case& c : cases) {
    const auto r = run_command(kArmctl + " " + c.args);
    const std::string label = std::string(c.args) + " -> " + r.err;
    LONGS_EQUAL_TEXT(2, r.status, label.c_str());
    CHECK_TEXT(r.err.find(c.expect) != std::string::npos, label.c_str());
    CHECK_TEXT(r.err.find("armctl: ") == 0, label.c_str());
    CHECK_TEXT(r.err.find('\n') == r.err.size() - 1, label.c_str());  // one line
    CHECK_TEXT(r.out.empty(), label.c_str());
  }
}

TEST(ArmctlKin, OutOfLimitsWarnsWithoutStrictAndStillAnswers) {
  const auto r = run_command(kArmctl + " kin fk --robot puma560 --json 200 0 0 0 0 0");
  LONGS_EQUAL(0, r.status);
  CHECK(r.err.find("warning: joint 1: value 200 is outside") != std::string::npos);
  LONGS_EQUAL(3, json_numbers(r.out, "position").size());
}

TEST(ArmctlKin, MalformedDescriptionFileNamesFileJointAndKey) {
  const std::string path = "/tmp/servoarm_cli_bad.toml";
  {
    std::ofstream f(path);
    f << "name = \"bad\"\nconvention = \"standard\"\nlength_unit = \"mm\"\nangle_unit = \"deg\"\n"
         "[[joint]]\ntype = \"revolute\"\n[[joint]]\ntype = \"revolute\"\nalpah = 90\n";
  }
  const auto r = run_command(kArmctl + " kin fk --robot " + path + " 0 0");
  LONGS_EQUAL(2, r.status);
  // file:line:column (the file input unit), the joint and the key
  CHECK_TEXT(r.err.find(path + ":9:9: joint 2: key 'alpah' is not known") != std::string::npos, r.err.c_str());
}

namespace {
/// The number right after `key` in `text` (up to the next space), "" when absent.
std::string number_after(const std::string& text, const std::string& key) {
  const auto at = text.find(key);
  if (at == std::string::npos) return "";
  const auto b = at + key.size();
  return text.substr(b, text.find_first_of(" ,)\n", b) - b);
}
/// "1.322": digits, a point, then exactly `decimals` digits.
bool has_decimals(const std::string& v, std::size_t decimals) {
  const auto dot = v.find('.');
  if (v.empty() || dot == std::string::npos || v.size() - dot - 1 != decimals) return false;
  for (std::size_t i = 0; i < v.size(); ++i)
    if (i != dot && !(v[i] >= '0' && v[i] <= '9') && !(i == 0 && v[i] == '-')) return false;
  return true;
}
}  // namespace

// Times print to 1 ms and lengths and angles at the description units' resolution (0.001
// mm, 0.001 deg), not to 10 significant digits: plan movej / movel and program check.
TEST(ArmctlKin, TimesAndLengthsPrintAtTheirUnitsResolution) {
  const auto j = run_command(kArmctl + " plan movej --robot puma560 --from 0 -45 180 0 45 0 --to 90 -90 150 45 -30 90");
  LONGS_EQUAL(0, j.status);
  const std::string dj = number_after(j.out, "duration ");
  CHECK_TEXT(has_decimals(dj, 3), j.out.c_str());
  const auto l = run_command(kArmctl + " plan movel --robot puma560 --from 10 -80 40 10 45 5 --to 20 -70 30 0 30 15");
  LONGS_EQUAL(0, l.status);
  CHECK_TEXT(has_decimals(number_after(l.out, "duration "), 3), l.out.c_str());
  CHECK_TEXT(has_decimals(number_after(l.out, "line "), 3), l.out.c_str());
  CHECK_TEXT(has_decimals(number_after(l.out, "rotation "), 3), l.out.c_str());
}
