// SPDX-License-Identifier: Apache-2.0
// armfw --sim as a process on arms of MIT-mode actuators (docs/mit-motors.md): virtual Damiao
// motors stand in for the [[drive]] tables of the configuration, stepped by the control thread
// before each cycle. Six DM-J4340 answer `status`, enable and run a movej; a mixed arm (four
// Damiao on one bus, two CiA 402 drives on a second) does the same.
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>

#include "target_exec.hpp"

#include <CppUTest/TestHarness.h>

namespace {

using servoarm::test::emulator_prefix;
using servoarm::test::run_capture;

/// A configuration file for the puma560 whose joint j is `family(j)`: Damiao DM-J4340 (kp 60,
/// kd 2, shoulder and elbow through 4:1) or CiA 402 on drive.can = "can1". Returns its path.
std::string write_config(const char* name, bool mixed) {
  const std::string path = "/tmp/" + std::string(name) + "-" + std::to_string(getpid()) + ".toml";
  std::ofstream f(path);
  f << "robot = \"puma560\"\n[bus]\ncan = \"sim\"\n";
  for (int j = 0; j < 6; ++j) {
    f << "[[drive]]\nnode = " << j + 1 << "\n";
    if (mixed && j >= 4) {
      f << "can = \"can1\"\n";
      continue;
    }
    f << "family = \"damiao\"\nmotor = \"DM-J4340\"\nmit_kp = 60\nmit_kd = 2\n";
    if (j == 1 || j == 2) f << "gear_ratio = 4\n";
  }
  return path;
}

/// Runs `armfw --sim --config FILE` with a script on stdin; stdout+stderr.
std::string run_script(const std::string& cfg, const std::string& script, int& st) {
  return run_capture("printf '" + script + "' | " + emulator_prefix() + ARMFW_PATH " --sim --config " + cfg +
                         " --priority 0 2>&1",
                     st);
}

/// The joints=[...] of the last status line, degrees.
bool last_joints(const std::string& out, double (&q)[6]) {
  const auto p = out.rfind("joints=[");
  if (p == std::string::npos) return false;
  return std::sscanf(out.c_str() + p + 8, "%lf %lf %lf %lf %lf %lf", &q[0], &q[1], &q[2], &q[3], &q[4], &q[5]) == 6 ||
         std::sscanf(out.c_str() + p + 8, "%lf,%lf,%lf,%lf,%lf,%lf", &q[0], &q[1], &q[2], &q[3], &q[4], &q[5]) == 6;
}

void check_arm(bool mixed) {
  const std::string cfg = write_config(mixed ? "armfw-mixed" : "armfw-damiao", mixed);
  int st = 0;
  const std::string out =
      run_script(cfg, "status\\nenable\\nmovej 20 -30 40 15 -20 30 speed=100\\nwait\\nstatus\\n", st);
  std::remove(cfg.c_str());
  CHECK_TEXT(WIFEXITED(st) && WEXITSTATUS(st) == 0, out.c_str());
  CHECK_TEXT(out.find("error:") == std::string::npos && out.find("failed") == std::string::npos, out.c_str());
  double q[6] = {};
  CHECK_TEXT(last_joints(out, q), out.c_str());
  const double target[6] = {20, -30, 40, 15, -20, 30};
  for (int j = 0; j < 6; ++j) CHECK_TEXT(std::fabs(q[j] - target[j]) < 0.5, out.c_str());
}

}  // namespace

TEST_GROUP(MitProcess){};

TEST(MitProcess, SixDamiaoMotorsAnswerEnableAndMove) { check_arm(false); }

TEST(MitProcess, MixedArmOnTwoBusesMoves) { check_arm(true); }
