// SPDX-License-Identifier: Apache-2.0
// armctl probed as a user would: tiny, huge, zero, negative and missing
// option values, joint values that make the kinematics overflow, paths that are not
// files. Each case: the exit status, a one-line error naming the option or the thing
// that is wrong, nothing written, no long run; and every --json output is valid JSON
// (checked by a strict reader, json_check.hpp), never holding nan or inf.
#include <sys/stat.h>

#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include "json_check.hpp"
#include "run_command.hpp"
#include "sweep.hpp"  // kSlowBuild: the in-bounds plan sampled at 100 Hz under qemu and the sanitizers

#include <CppUTest/TestHarness.h>

using servoarm::test::run_command;

namespace {
const std::string kArmctl = ARMCTL_PATH;
const std::string kMovej = " plan movej --robot puma560 --from 0 -45 180 0 45 0 --to 90 -90 150 45 -30 90";
const std::string kMovel = " plan movel --robot puma560 --from 10 -80 40 10 45 5";

bool exists(const std::string& p) {
  struct stat st {};
  return ::stat(p.c_str(), &st) == 0;
}

int lines(const std::string& s) {
  int n = 0;
  for (char c : s) n += c == '\n';
  return n;
}

struct Case {
  std::string args;   // after "armctl"
  int status;         // expected exit status
  std::string names;  // the error names this (option, thing)
};

// Runs every case; fails with the case when the status, the naming or the one-line
// rule does not hold, or when a refusal took longer than 20 s (the bugs: minutes, gigabytes).
void run_cases(const std::vector<Case>& cases) {
  for (const Case& c : cases) {
    const auto t0 = std::chrono::steady_clock::now();
    const auto r = run_command(kArmctl + c.args);
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const std::string what = "armctl" + c.args + "\n  rc " + std::to_string(r.status) + "\n  stderr: " + r.err;
    // A refusal is immediate: 20 s means it went on planning or writing. (A plan inside the
    // bounds does real work: 180 001 samples took 40 s under qemu-aarch64 on a busy host.)
    if (c.status != 0) CHECK_TEXT(s < 20, what.c_str());
    CHECK_TEXT(r.status == c.status, what.c_str());
    if (c.status == 2) {
      CHECK_TEXT(r.err.find(c.names) != std::string::npos, what.c_str());
      CHECK_TEXT(r.err.rfind("armctl: ", 0) == 0, what.c_str());
    }
  }
}

}  // namespace

TEST_GROUP(ArmctlRobust){};

TEST(ArmctlRobust, TinyLimitsAreRefusedNamingTheOptionBeforeAnythingIsWritten) {
  const std::string csv = "/tmp/servoarm_robust_" + std::to_string(getpid()) + ".csv";
  std::remove(csv.c_str());
  run_cases({
      {kMovej + " --vmax 1e-6", 2, "--vmax 1e-6"},     // was: 5 GB in 10 s
      {kMovej + " --jmax 1e-6 --csv " + csv, 2, "--jmax 1e-6"},  // was: 1.2 GB of CSV in 30 s
      {kMovej + " --vmax 1e-300 --csv " + csv, 2, "--vmax 1e-300"},  // was: rc 0, empty CSV
      {kMovej + " --amax 1e-300", 2, "--amax"},
      {kMovej + " --vmax 1 --override 1", 2, "--override 1"},
      {kMovel + " --to 20 -70 30 0 30 15 --speed 1e-6", 2, "--speed 1e-6"},
      {kMovel + " --to 20 -70 30 0 30 15 --accel 1e-300", 2, "--accel"},
      {kMovel + " --to 20 -70 30 0 30 15 --angular 1e-300", 2, "--angular"},
      // 18 s at 100 kHz = 1.8 million samples: over the bound, --rate named
      {kMovej + " --vmax 5 --rate 100000", 2, "--rate"},
      {kMovej + " --vmax 10 --max-duration 5", 2, "--max-duration 5"},
  });
  CHECK_TEXT(!exists(csv), "a refused plan wrote its CSV");
  // Inside the bounds the same options plan (180 s move, 180 001 samples; under qemu and the
  // sanitizers 18 001 at --rate 100: writing the 180 001 rows took qemu 7.4 s).
  run_cases({{kMovej + " --vmax 1 --override 50 --csv " + csv + (servoarm::test::kSlowBuild ? " --rate 100" : ""), 0, ""}});
  CHECK(exists(csv));
  std::remove(csv.c_str());
}

TEST(ArmctlRobust, ZeroNegativeAndMissingValuesAreRefusedNotTakenAsTheDefault) {
  run_cases({
      {kMovej + " --vmax 0", 2, "--vmax must be > 0"},
      {kMovej + " --amax -5", 2, "--amax must be > 0"},
      {kMovej + " --jmax 0", 2, "--jmax must be > 0"},
      {kMovel + " --to 20 -70 30 0 30 15 --speed 0", 2, "--speed must be > 0"},
      {kMovel + " --to 20 -70 30 0 30 15 --accel 0", 2, "--accel must be > 0"},
      {kMovel + " --to 20 -70 30 0 30 15 --angular -1", 2, "--angular must be > 0"},
      {kMovej + " --vmax", 2, "--vmax needs a value"},
      {kMovej + " --vmax --csv /tmp/x.csv", 2, "--vmax needs a value"},
      {kMovej + " --csv", 2, "--csv needs a value"},
      {kMovej + " --svg --vmax 5", 2, "--svg needs a value"},
      {kMovej + " --vmax nan", 2, "--vmax"},
      {kMovej + " --vmax 1e400", 2, "--vmax"},
      {kMovej + " --rate 0", 2, "--rate"},
      {kMovej + " --speed 100", 2, "--speed is a movel option"},
      {" plan movej --robot", 2, "--robot needs a value"},
      {kMovel + " --xyz 500 0 0 --rpy 1e300 0 0", 2, "--rpy"},  // orientations of 1e300 deg
      {kMovel + " --xyz 500 0 0 --rpy 0 -1e300 0", 2, "--rpy"},
      {kMovel + " --xyz 1e300 0 0", 2, "--xyz"},
      {kMovel + " --to 1e308 0 0 0 0 0", 2, "--to"},
      {kMovel + " --xyz 500 0 0 --rpy 0 0 0 --quat 1 0 0 0", 2, "--rpy or --quat"},
  });
}

TEST(ArmctlRobust, NonFiniteKinematicsAreOneLineErrorsAndNoJsonIsPrinted) {
  for (const char* c : {" kin fk --robot puma560 --json 1e308 0 0 0 0 0", " kin fk --robot puma560 1e308 0 0 0 0 0",
                        " kin jacobian --robot puma560 --json 1e308 0 0 0 0 0",
                        " kin jacobian --robot puma560 0 1e308 0 0 0 0", " kin fk --robot trl_r --json 0 1e308 1e308 0"}) {
    const auto r = run_command(kArmctl + c);
    const std::string what = std::string("armctl") + c + "\n  rc " + std::to_string(r.status) + "\n  out: " + r.out +
                             "\n  err: " + r.err;
    CHECK_TEXT(r.status == 2, what.c_str());
    CHECK_TEXT(r.out.empty(), what.c_str());  // no pose, no JSON with nan in it
    CHECK_TEXT(r.err.find("is not finite") != std::string::npos, what.c_str());
    // the warnings (one per joint outside its limits) and one error line
    const std::size_t last = r.err.rfind("armctl: ", r.err.size() - 2);
    CHECK_TEXT(r.err.find('\n', last) == r.err.size() - 1, what.c_str());
    CHECK_TEXT(r.err.find("joint ") != std::string::npos, what.c_str());
  }
  // Huge but finite entries print in %g, not as 300-digit fixed-point numbers.
  const auto r = run_command(kArmctl + " kin jacobian --robot stanford 0 0 1e300 0 0 0");
  LONGS_EQUAL(0, r.status);
  std::size_t longest = 0, b = 0;
  for (std::size_t e; (e = r.out.find('\n', b)) != std::string::npos; b = e + 1) longest = std::max(longest, e - b);
  CHECK_TEXT(longest < 120, r.out.c_str());
}

TEST(ArmctlRobust, EveryJsonOutputIsValidJson) {
  servoarm::test::JsonCheck j;
  const std::vector<std::string> cmds = {
      " kin fk --robot puma560 --json 0 -45 180 0 45 0",
      " kin fk --robot puma560 --json 0 0 0 0 0 0",  // ZYZ singular
      " kin fk --robot rr_planar --json 1e-320 -0",
      " kin fk --robot trl_r --json 0 0 300 0",
      " kin fk --robot stanford --json 0 0 1e300 0 0 0",  // huge but finite, far outside the limits
      " kin jacobian --robot puma560 --json 0 -45 180 0 45 0",
      " kin jacobian --robot puma560 --json 0 0 0 0 0 0",  // singular: condition number null
      " kin jacobian --robot rr_planar --json 0 0",        // stretched: singular
      " kin ik --robot puma560 --xyz 500 100 400 --rpy 0 90 0 --all --json",
      " kin ik --robot puma560 --xyz 5000 0 0 --rpy 0 0 0 --json",  // unreachable
      " kin precision --robot rr_planar --resolution 0.1 0.1 10 20 --json",
      " kin precision --robot rr_planar --resolution 1e308 1e308 10 20 --json",  // overflow
      " kin precision --robot rr_planar --resolution 0.1 0.1 1e308 20 --json",
  };
  for (const std::string& c : cmds) {
    const auto r = run_command(kArmctl + c);
    const std::string what = "armctl" + c + "\n  rc " + std::to_string(r.status) + "\n  out: " + r.out + "\n  err: " + r.err;
    if (r.out.empty()) {  // refused: an error line, no JSON at all
      CHECK_TEXT(r.status != 0 && !r.err.empty(), what.c_str());
      continue;
    }
    CHECK_TEXT(lines(r.out) == 1, what.c_str());
    CHECK_TEXT(j.valid(r.out), (what + "\n  " + j.error).c_str());
    for (const char* bad : {"nan", "inf"}) CHECK_TEXT(r.out.find(bad) == std::string::npos, what.c_str());
  }
  // The reader itself refuses what armctl used to print.
  CHECK(!j.valid("{\"position\": [nan, nan, nan]}"));
  CHECK(!j.valid("{\"dx\": inf}"));
  CHECK(!j.valid("[1, -nan]"));
  CHECK(j.valid("{\"a\": [1, -2.5e-3, null, true], \"b\": \"x\\\"y\"}"));
}

TEST(ArmctlRobust, RobotPathsThatAreNotFilesAreRefusedNamingThePath) {
  run_cases({
      {" kin fk --robot /tmp 0", 2, "/tmp: not a regular file (a directory)"},
      {" kin fk --robot /dev/zero 0", 2, "/dev/zero: not a regular file"},  // used to hang reading forever
      {" kin jacobian --robot /dev/null 0", 2, "/dev/null: not a regular file"},
      {" plan movej --robot /tmp --from 0 --to 1", 2, "/tmp: not a regular file"},
  });
}
