// SPDX-License-Identifier: Apache-2.0
// armfw --sim as a process on arms of MIT-mode actuators (docs/mit-motors.md): virtual Damiao
// motors stand in for the [[drive]] tables of the configuration, stepped by the control thread
// before each cycle. Six DM-J4340 answer `status`, enable and run a movej; a mixed arm (four
// Damiao on one bus, two CiA 402 drives on a second) does the same; the demo passes while the
// host stalls armfw's loop.
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <string>
#include <utility>

#include "target_exec.hpp"

#include <CppUTest/TestHarness.h>

namespace {

using servoarm::test::emulator_prefix;
using servoarm::test::run_capture;

/// A configuration file for the puma560 whose joint j is `family(j)`: Damiao DM-J4340 (kp 60,
/// kd 2, shoulder and elbow through 4:1) or CiA 402 on drive.can = "can1". Returns its path.
std::string write_config(const char* name, bool mixed, const char* extra = "", bool base_geared = false) {
  const std::string path = "/tmp/" + std::string(name) + "-" + std::to_string(getpid()) + ".toml";
  std::ofstream f(path);
  // feedback: armfw's control loop starts slowly under qemu (35 cycles with 9 overruns before an
  // enable saw no position feedback for 283 ms at the default): 2 s here.
  // heartbeat_timeout_ms is the MIT motors' own CAN watchdog (and armfw's feedback timeout for
  // them): the virtual motors run on the wall clock, so a busy host that stalls the loop longer
  // than the default 150 ms trips it (error 0xD) although nothing broke. These cases check the
  // bring-up, moves, the demo and homing, not the watchdog (FwMitArm and MitGroup tests do): 2 s.
  f << "robot = \"puma560\"\n[bus]\ncan = \"sim\"\nheartbeat_timeout_ms = 2000\n[safety]\nfeedback_timeout_ms = 2000\n"
    << extra;
  for (int j = 0; j < 6; ++j) {
    f << "[[drive]]\nnode = " << j + 1 << "\n";
    if (mixed && j >= 4) {
      f << "can = \"can1\"\n";
      continue;
    }
    f << "family = \"damiao\"\nmotor = \"DM-J4340\"\nmit_kp = 60\nmit_kd = 2\n";
    if (j == 1 || j == 2 || (base_geared && j == 0)) f << "gear_ratio = 4\n";
  }
  return path;
}

/// Runs `armfw --sim --config FILE [args]` with a script on stdin; stdout+stderr.
std::string run_script(const std::string& cfg, const std::string& script, int& st, const std::string& args = "") {
  return run_capture("printf '" + script + "' | " + emulator_prefix() + ARMFW_PATH " --sim --config " + cfg + " " + args +
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

// The named scenarios on six Damiao DM-J4340 (velocity feed-forward): the demo (not under an
// emulator: a wall-clock run of the 1 kHz loop, as fw_demo_models), a jog and a program.
TEST(MitProcess, DemoOnSixDamiaoMotorsPasses) {
  if (!emulator_prefix().empty()) return;  // qemu-user does not keep the 1 kHz loop
  const std::string cfg = write_config("armfw-damiao-demo", false, "[dynamics]\nfeed_forward = \"velocity\"\n");
  int st = 0;
  const std::string out = run_capture(emulator_prefix() + ARMFW_PATH " --sim --config " + cfg +
                                          " --demo --priority 0 2>&1 </dev/null", st);
  std::remove(cfg.c_str());
  CHECK_TEXT(WIFEXITED(st) && WEXITSTATUS(st) == 0, out.c_str());
  CHECK_TEXT(out.find("result: PASS") != std::string::npos, out.c_str());
  CHECK_TEXT(out.find("unexpected errors: 0") != std::string::npos, out.c_str());
}

/// The demo summary's loop line ("loop: N cycles at R Hz, M overruns, ..."), or "".
static std::string loop_line(const std::string& out) {
  const auto at = out.find("  loop: ");
  return at == std::string::npos ? std::string() : out.substr(at + 2, out.find('\n', at) - at - 2);
}

/// The largest final errors in the demo's "move / final error" table: {mm, deg}, -1 if none.
static std::pair<double, double> final_errors(const std::string& out) {
  std::pair<double, double> worst{-1, -1};
  std::size_t at = out.find("final error\n");
  while (at != std::string::npos && (at = out.find('\n', at)) != std::string::npos && ++at < out.size() &&
         out.compare(at, 20, "  unexpected errors:") != 0) {
    const std::string line = out.substr(at, out.find('\n', at) - at);
    const auto u = line.rfind(' ');
    const auto v = u == std::string::npos || u == 0 ? std::string::npos : line.rfind(' ', u - 1);
    if (v == std::string::npos) continue;
    const double x = std::strtod(line.c_str() + v + 1, nullptr);
    if (line.compare(u + 1, std::string::npos, "mm") == 0) worst.first = std::max(worst.first, x);
    if (line.compare(u + 1, std::string::npos, "deg") == 0) worst.second = std::max(worst.second, x);
  }
  return worst;
}

/// Whether the demo's loop was starved: it overran in more than 2 % of its cycles, or one
/// wake-up came more than 20 cycles (20 ms) late. A single such stall lets the arm fall behind
/// its plan by degrees, which decides a run's largest following error by itself (seen under
/// ASan on a quiet machine: 1.2 % overruns, one wake-up 39 ms late, the torque run's largest
/// following error 2.5 deg against 4.8 with the velocity feed-forward).
static bool starved(const std::string& out) {
  long cycles = 0, overruns = 0;
  double worst_us = 0;
  const std::string l = loop_line(out);
  const int n = std::sscanf(l.c_str(), "loop: %ld cycles at %*d Hz, %ld overruns, wake-up latency us min/mean/p99/max %*f/%*f/%*f/%lf",
                            &cycles, &overruns, &worst_us);
  return n >= 2 && cycles > 0 && (overruns * 50 > cycles || (n == 3 && worst_us > 20000));
}

// The demo on the dynamic plant (armfw --sim --plant dynamic): each virtual motor moves its
// joint's inertia of the arm (the mass matrix's diagonal at the measured pose) and, while
// powered, carries the arm's gravity torque. The puma's base, shoulder and elbow through 4:1
// (a DM-J4340 alone gives 28 N m). With the model's torque as tau_ff the demo passes; with the
// velocity feed-forward alone kp (60 N m/rad) lets the arm sag under gravity: the demo ends its
// moves millimetres off (the torque run: hundredths of a millimetre) and, with the loop on
// time, its largest following error is several times the torque's.
TEST(MitProcess, DemoOnSixDamiaoMotorsWithTheModelsTorqueOnTheDynamicPlantPasses) {
  if (!emulator_prefix().empty()) return;  // qemu-user does not keep the 1 kHz loop
  double fe[2] = {-1, -1};
  const char* kinds[2] = {"velocity", "torque"};
  std::string outs[2];
  for (int k = 0; k < 2; ++k) {
    const std::string cfg = write_config("armfw-damiao-dyn", false,
                                         (std::string("[dynamics]\nfeed_forward = \"") + kinds[k] + "\"\n").c_str(), true);
    int st = 0;
    const std::string cmd = emulator_prefix() + ARMFW_PATH " --sim --config " + cfg + " --plant dynamic --demo --priority 0 2>&1 </dev/null";
    outs[k] = run_capture(cmd, st);
    const auto following = [&] {
      const auto at = outs[k].find("max following error ");
      CHECK_TEXT(at != std::string::npos && std::sscanf(outs[k].c_str() + at + 20, "%lf", &fe[k]) == 1, outs[k].c_str());
    };
    following();
    // The virtual motors keep the wall clock: a loop starved for a tenth of a second (seen under
    // ASan at a load average of 4-5: 14 % of the cycles overran, one wake-up 117 ms late) lets
    // the arm fall behind its plan by more than the following-error limit, although nothing is
    // wrong with the controller. A torque run whose demo failed with a starved loop (starved(),
    // above) runs once more; a second starved failure stays a failure.
    if (k == 1 && outs[k].find("result: PASS") == std::string::npos && starved(outs[k])) {
      std::printf("\n  the torque run failed with a starved loop (%s, largest following error %.3f deg): run once more\n",
                  loop_line(outs[k]).c_str(), fe[1]);
      outs[k] = run_capture(cmd, st);
      following();
    }
    std::remove(cfg.c_str());
    if (k == 1) CHECK_TEXT(WIFEXITED(st) && WEXITSTATUS(st) == 0, outs[k].c_str());
  }
  std::printf("\n  demo on six virtual DM-J4340 on the dynamic plant: largest following error %.3f deg with velocity "
              "feed-forward, %.3f deg with the model's torque\n", fe[0], fe[1]);
  CHECK_TEXT(outs[1].find("result: PASS") != std::string::npos, outs[1].c_str());
  CHECK_TEXT(outs[1].find("unexpected errors: 0") != std::string::npos, outs[1].c_str());
  // At rest the sag is gravity over kp whatever the loop's timing: the velocity run ends its
  // moves millimetres and tenths of a degree off (sagging, or further when its following-error
  // limit stops a move), the torque run within a tenth of that.
  const auto fin_v = final_errors(outs[0]), fin_t = final_errors(outs[1]);
  std::printf("  largest final error: %.4f mm, %.4f deg with velocity feed-forward; %.4f mm, %.4f deg with the "
              "model's torque\n", fin_v.first, fin_v.second, fin_t.first, fin_t.second);
  CHECK_TEXT(fin_v.first > 1.0 && fin_v.second > 0.1, outs[0].c_str());
  CHECK_TEXT(fin_t.first >= 0 && fin_t.second >= 0 && fin_t.first < fin_v.first / 10 && fin_t.second < fin_v.second / 10,
             (outs[0] + outs[1]).c_str());
  // Tracking while moving depends on the loop keeping its clock: compared only when neither run
  // was starved (both halves of a starved comparison move with the load, not with the model).
  if (!starved(outs[0]) && !starved(outs[1])) CHECK_TEXT(fe[1] < fe[0] / 2, (outs[0] + outs[1]).c_str());
  else std::printf("  tracking not compared: a starved loop (%s; %s)\n", loop_line(outs[0]).c_str(), loop_line(outs[1]).c_str());
}

#if !SERVOARM_TEST_EMULATED && !SERVOARM_TEST_INSTRUMENTED
// A busy host stops armfw's loop for hundreds of milliseconds (190-360 ms seen at a load
// average of 10); the virtual motors keep the wall clock, so each stall is as long a silence on
// their bus. The demo on the configuration above passes through such stalls, made here on
// purpose: armfw stopped 300 ms (SIGSTOP), then 2 s running, over the whole demo.
TEST(MitProcess, DemoOnSixDamiaoMotorsPassesWhileTheHostStallsTheLoop) {
  const std::string cfg = write_config("armfw-damiao-stall", false, "[dynamics]\nfeed_forward = \"velocity\"\n");
  // armfw itself is stopped (not a wrapper); after 300 rounds (690 s) it is killed.
  const std::string cmd = std::string(ARMFW_PATH) + " --sim --config " + cfg +
                          " --demo --priority 0 </dev/null 2>&1 & p=$!; n=0; sleep 1; "
                          "while kill -0 $p 2>/dev/null; do n=$((n+1)); [ $n -gt 300 ] && kill -KILL $p; "
                          "kill -STOP $p 2>/dev/null; sleep 0.3; kill -CONT $p 2>/dev/null; sleep 2; done; wait $p";
  int st = 0;
  const std::string out = run_capture("sh -c '" + cmd + "'", st);
  std::remove(cfg.c_str());
  CHECK_TEXT(WIFEXITED(st) && WEXITSTATUS(st) == 0, out.c_str());
  CHECK_TEXT(out.find("result: PASS") != std::string::npos, out.c_str());
  CHECK_TEXT(out.find("unexpected errors: 0") != std::string::npos, out.c_str());
  // the stalls happened: the loop saw a wake-up at least 300 ms late
  const auto at = out.find("wake-up latency us min/mean/p99/max ");
  double lat[4] = {};
  CHECK_TEXT(at != std::string::npos && std::sscanf(out.c_str() + at + 36, "%lf/%lf/%lf/%lf", &lat[0], &lat[1], &lat[2],
                                                    &lat[3]) == 4,
             out.c_str());
  CHECK_TEXT(lat[3] >= 300e3, out.c_str());
}
#endif

TEST(MitProcess, JogAndAProgramOnSixDamiaoMotors) {
  const std::string cfg = write_config("armfw-damiao-prog", false, "[dynamics]\nfeed_forward = \"velocity\"\n");
  const std::string dir = "/tmp/armfw-damiao-programs-" + std::to_string(getpid());
  mkdir(dir.c_str(), 0755);
  {
    std::ofstream p(dir + "/two.arm");
    p << "movej 0 -30 60 0 20 0 speed=50\nmovej 10 -20 50 5 10 5 speed=50\n";
  }
  int st = 0;
  const std::string out =
      run_script(cfg, "enable\\njog j1 10\\nwait\\nstatus\\nrun two\\nwait\\nstatus\\n", st, "--programs " + dir);
  std::remove(cfg.c_str());
  std::remove((dir + "/two.arm").c_str());
  rmdir(dir.c_str());
  CHECK_TEXT(WIFEXITED(st) && WEXITSTATUS(st) == 0, out.c_str());
  CHECK_TEXT(out.find("error:") == std::string::npos && out.find("alarm:") == std::string::npos, out.c_str());
  // the jog: joint 1 10 deg on
  const auto first = out.find("joints=[");
  double j1 = 0;
  CHECK_TEXT(first != std::string::npos && std::sscanf(out.c_str() + first + 8, "%lf", &j1) == 1, out.c_str());
  CHECK_TEXT(std::fabs(j1 - 10) < 0.5, out.c_str());
  // the program: its two moves ran, the arm stands at the second
  CHECK_TEXT(out.find("program: two done: 2 steps") != std::string::npos, out.c_str());
  double q[6] = {};
  CHECK_TEXT(last_joints(out, q), out.c_str());
  const double target[6] = {10, -20, 50, 5, 10, 5};
  for (int j = 0; j < 6; ++j) CHECK_TEXT(std::fabs(q[j] - target[j]) < 0.5, out.c_str());
}

// Homing by hard stop on a Damiao joint through armfw --sim: the virtual motor has an end stop
// 10 deg from where it starts in the joint's homing direction; joint 5 homes against it, backs
// off 3 deg and takes homing.offset (-60 deg) there.
TEST(MitProcess, HardStopHomingOnADamiaoJoint) {
  const std::string cfg = write_config("armfw-damiao-home", false);
  // joint 5's table with hard-stop homing, the others as write_config gives them
  std::ifstream in(cfg);
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  in.close();
  const std::string j5 = "node = 5\nfamily = \"damiao\"\nmotor = \"DM-J4340\"\nmit_kp = 60\nmit_kd = 2\n";
  const auto at = text.find(j5);
  CHECK(at != std::string::npos);
  text.insert(at + j5.size(),
              "homing.method = \"hard_stop\"\nhoming.direction = -1\nhoming.speed_switch = 5\nhoming.acceleration = 50\n"
              "homing.following_limit = 0.5\nhoming.backoff = 3\nhoming.offset = -60\n");
  {
    std::ofstream f(cfg);
    f << text;
  }
  int st = 0;
  const std::string out = run_script(cfg, "enable\\nhome\\nwait\\nstatus\\n", st);
  std::remove(cfg.c_str());
  CHECK_TEXT(WIFEXITED(st) && WEXITSTATUS(st) == 0, out.c_str());
  CHECK_TEXT(out.find("error:") == std::string::npos && out.find("alarm:") == std::string::npos, out.c_str());
  CHECK_TEXT(out.find("homing=[absolute absolute absolute absolute homed absolute]") != std::string::npos, out.c_str());
  double q[6] = {};
  CHECK_TEXT(last_joints(out, q), out.c_str());
  CHECK_TEXT(std::fabs(q[4] - -60) < 0.5, out.c_str());
}
