// SPDX-License-Identifier: Apache-2.0
// The armsim and canmaster binaries as separate processes, talking SocketCAN
// frames (struct can_frame records) over a socketpair(AF_UNIX, SOCK_SEQPACKET)
// passed with --fd: the shell scenarios of the vcan VM, without kernel CAN.
#include <poll.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "target_exec.hpp"

// CppUTest last: its leak detector redefines `new`.
#include <CppUTest/TestHarness.h>

namespace {

// Heartbeat consumer time for runs that are not about heartbeats: a shared CI machine can
// stall both processes for a few hundred ms, which would (correctly) be a heartbeat loss.
const char* const kSlowHb = "1500";
// Tracking tolerance for the same runs (canmaster's default is 0.02 rad): a stall of either
// process lags the positions it sees or reports (seen under ASan with two suites beside it:
// 0.026 rad, one late cycle). 0.15 rad passes a stall of ~150 ms at the 0.3 rad, 0.5 Hz
// sine's top speed and still fails a drive that does not follow (its error reaches 0.3 rad);
// following accuracy is checked in-process (hal_master_sim: 2 mrad) and on vcan (vcan_s2_follow).
const char* const kSlowTrack = "0.15";

struct Proc {
  pid_t pid = -1;
  int out = -1;  // read end of stdout
};

// In a cross build args[0] runs under the emulator (target_exec.hpp), not through binfmt_misc.
Proc spawn(const std::vector<std::string>& args, int keep_fd, int close_fd) {
  const std::vector<std::string> full = servoarm::test::target_argv(args);
  std::vector<char*> argv;
  for (auto& a : full) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  int pipefd[2];
  if (pipe(pipefd) != 0) return {};
  const pid_t pid = fork();
  if (pid == 0) {
    dup2(pipefd[1], 1);
    close(pipefd[0]);
    close(pipefd[1]);
    if (close_fd >= 0) close(close_fd);
    (void)keep_fd;
    execv(argv[0], argv.data());
    _exit(127);
  }
  close(pipefd[1]);
  return {pid, pipefd[0]};
}

std::string read_all(int fd) {
  std::string s;
  char buf[4096];
  ssize_t n;
  while ((n = read(fd, buf, sizeof buf)) > 0) s.append(buf, std::size_t(n));
  close(fd);
  return s;
}

int wait_rc(pid_t pid) {
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

struct Run {
  int master_rc, sim_rc;
  std::string master_out, sim_out;
};

Run run_pair(std::vector<std::string> master_args, std::vector<std::string> sim_args) {
  int sv[2];
  socketpair(AF_UNIX, SOCK_SEQPACKET, 0, sv);
  sim_args.insert(sim_args.begin(), {ARMSIM_PATH, "--fd", std::to_string(sv[1])});
  // SDO answers within 2 s, not a real drive's 200 ms: two emulated processes on a loaded
  // machine are descheduled for longer than that, and no case here tests SDO timeouts.
  master_args.insert(master_args.begin(), {CANMASTER_PATH, "--fd", std::to_string(sv[0]), "--sdo-timeout-ms", "2000"});
  Proc sim = spawn(sim_args, sv[1], sv[0]);
  // The master starts once armsim says it is ready: its SDO timeouts are the drive's, and
  // an armsim still starting (qemu on a loaded machine takes seconds) is not a drive that
  // does not answer. Up to 60 s; armsim failing to start shows in its output.
  std::string sim_head;
  for (int waited = 0; sim_head.find("armsim ready") == std::string::npos && waited < 60000;) {
    pollfd p{sim.out, POLLIN, 0};
    if (poll(&p, 1, 100) <= 0) {
      waited += 100;
      continue;
    }
    char buf[512];
    const ssize_t n = read(sim.out, buf, sizeof buf);
    if (n <= 0) break;
    sim_head.append(buf, std::size_t(n));
  }
  Proc master = spawn(master_args, sv[0], sv[1]);
  close(sv[0]);
  close(sv[1]);
  Run r;
  r.master_out = read_all(master.out);
  r.master_rc = wait_rc(master.pid);
  r.sim_out = sim_head + read_all(sim.out);
  r.sim_rc = wait_rc(sim.pid);
  return r;
}

int run_alone(const std::vector<std::string>& args) {
  Proc p = spawn(args, -1, -1);
  read_all(p.out);
  return wait_rc(p.pid);
}

}  // namespace

TEST_GROUP(Binaries){};

TEST(Binaries, BringUpAndStreamAcrossProcesses) {
  Run r = run_pair({"--nodes", "1-6", "--bringup", "--stream-sine", "1.5", "--period-ms", "2", "--hb-timeout-ms", kSlowHb,
                    "--tolerance", kSlowTrack},
                   {"--nodes", "1-6", "--duration", "6"});
  STRCMP_CONTAINS("bringup status=ok", r.master_out.c_str());
  STRCMP_CONTAINS("node id=6 name=\"servoarm virtual drive 6\" state=enabled", r.master_out.c_str());
  STRCMP_CONTAINS("result status=ok", r.master_out.c_str());
  LONGS_EQUAL(0, r.master_rc);
  STRCMP_CONTAINS("armsim ready", r.sim_out.c_str());
  LONGS_EQUAL(0, r.sim_rc);
}

TEST(Binaries, SilentNodeHeartbeatLossReportedInTime) {
  // 600 ms consumer time: long enough that a loaded machine stalling both processes does not
  // also time out nodes 1 and 3 (which would fail the run as "unexpected fault").
  Run r = run_pair({"--nodes", "1-3", "--bringup", "--hold", "2.5", "--hb-ms", "100", "--hb-timeout-ms", "600",
                    "--expect-hb-loss", "2"},
                   {"--nodes", "1-3", "--silent", "2@1.2", "--duration", "6"});
  if (r.master_out.find("result status=ok") == std::string::npos) std::printf("%s\n", r.master_out.c_str());
  STRCMP_CONTAINS("fault t=", r.master_out.c_str());
  STRCMP_CONTAINS("node=2 reason=heartbeat_lost", r.master_out.c_str());
  STRCMP_CONTAINS("result status=ok", r.master_out.c_str());
  LONGS_EQUAL(0, r.master_rc);
  STRCMP_CONTAINS("node=2 kind=silent", r.sim_out.c_str());
}

TEST(Binaries, RefusingDriveFailsBringUpWithExitCode4) {
  Run r = run_pair({"--nodes", "1-2", "--bringup", "--hold", "0.2", "--enable-timeout-ms", "300", "--hb-timeout-ms", kSlowHb},
                   {"--nodes", "1-2", "--refuse-enable", "2", "--duration", "4"});
  STRCMP_CONTAINS("bringup status=drive_refused", r.master_out.c_str());
  STRCMP_CONTAINS("node 2: drive_refused (stayed in switched_on", r.master_out.c_str());
  LONGS_EQUAL(4, r.master_rc);
}

TEST(Binaries, EmcyFromArmsimIsAFaultWithItsCode) {
  Run r = run_pair({"--nodes", "1-3", "--bringup", "--hold", "1.5", "--hb-timeout-ms", kSlowHb},
                   {"--nodes", "1-3", "--emcy", "2:0x2310@1.0", "--duration", "5"});
  STRCMP_CONTAINS("node=2 reason=drive_fault", r.master_out.c_str());
  STRCMP_CONTAINS("error_code=0x2310", r.master_out.c_str());
  STRCMP_CONTAINS("continuous over-current", r.master_out.c_str());
  STRCMP_CONTAINS("result status=fail", r.master_out.c_str());
  LONGS_EQUAL(1, r.master_rc);
  STRCMP_CONTAINS("node=2 kind=emcy code=0x2310", r.sim_out.c_str());
}

TEST(Binaries, StoppedHeartbeatAndNoisyEncoders) {
  // Heartbeat producer of node 1 stops while its PDOs keep flowing: still a heartbeat loss.
  const auto stopped_heartbeat = [] {
    return run_pair({"--nodes", "1-2", "--bringup", "--hold", "2", "--hb-ms", "100", "--hb-timeout-ms", "600",
                     "--expect-hb-loss", "1"},
                    {"--nodes", "1-2", "--stop-heartbeat", "1@0.8", "--duration", "5"});
  };
  Run r = stopped_heartbeat();
  // Node 2's heartbeat is never stopped: its loss too means armsim went 600 ms without
  // running (seen once at load average 10 on 2 cores). Said, and run once more; a second
  // such loss, or any other outcome, is judged.
  if (r.master_rc != 0 && r.master_out.find("node=2 reason=heartbeat_lost") != std::string::npos) {
    std::printf("\nstopped heartbeat: node 2's heartbeat lost as well (armsim starved 600 ms?); once more:\n%s\n",
                r.master_out.c_str());
    r = stopped_heartbeat();
  }
  if (r.master_rc != 0) std::printf("\n%s\n", r.master_out.c_str());
  STRCMP_CONTAINS("node=1 reason=heartbeat_lost", r.master_out.c_str());
  LONGS_EQUAL(0, r.master_rc);
  // +-1000 counts of position noise (48 mrad) on the reported position.
  Run n = run_pair({"--nodes", "1-2", "--bringup", "--stream-sine", "1", "--tolerance", "0.1", "--hb-timeout-ms", kSlowHb},
                   {"--nodes", "1-2", "--noise", "all:1000", "--duration", "5"});
  // A starved machine (the cross suites under qemu beside other jobs) is not a master
  // fault: with a tenth of the cycles or more started late, the tracking error is
  // that of the scheduler, so the noise figures are not judged (said, not failed).
  unsigned long long cycles = 0, late = 0;
  const std::size_t res = n.master_out.find("result status=");
  if (res != std::string::npos) {
    const std::size_t c = n.master_out.find("cycles=", res), l = n.master_out.find("late_cycles=", res);
    if (c != std::string::npos) std::sscanf(n.master_out.c_str() + c, "cycles=%llu", &cycles);
    if (l != std::string::npos) std::sscanf(n.master_out.c_str() + l, "late_cycles=%llu", &late);
  }
  if (n.master_out.find("result status=fail") != std::string::npos && cycles > 0 && late * 10 >= cycles &&
      n.master_out.find("tracking error above tolerance") != std::string::npos) {
    std::printf("\nnoisy encoders: %llu of %llu cycles late (starved machine): tracking not judged\n", late, cycles);
    return;
  }
  STRCMP_CONTAINS("result status=ok", n.master_out.c_str());
  LONGS_EQUAL(0, n.master_rc);
  // The noise shows in the tracking error (noise-free runs: a few mrad).
  const std::size_t at = n.master_out.find("result status=ok");
  double err = 0;
  CHECK(at != std::string::npos &&
        std::sscanf(n.master_out.c_str() + n.master_out.find("max_err_rad=", at), "max_err_rad=%lf", &err) == 1);
  CHECK(err > 0.02);
  CHECK(err < 0.1);
}

TEST(Binaries, UsageErrorsExit2) {
  LONGS_EQUAL(2, run_alone({CANMASTER_PATH}));
  LONGS_EQUAL(2, run_alone({CANMASTER_PATH, "--sim"}));  // nothing to do
  LONGS_EQUAL(2, run_alone({CANMASTER_PATH, "--sim", "--bringup", "--nodes", "0-3"}));
  LONGS_EQUAL(2, run_alone({CANMASTER_PATH, "--sim", "--iface", "vcan0", "--bringup"}));
  LONGS_EQUAL(2, run_alone({ARMSIM_PATH, "--iface", "vcan0", "--emcy", "3"}));  // code missing
  LONGS_EQUAL(2, run_alone({ARMSIM_PATH, "--iface", "vcan0", "--nodes", "1-2", "--silent", "5"}));
  LONGS_EQUAL(2, run_alone({ARMSIM_PATH, "--bogus"}));
  LONGS_EQUAL(0, run_alone({ARMSIM_PATH, "--help"}));
  LONGS_EQUAL(0, run_alone({CANMASTER_PATH, "--help"}));
}

TEST(Binaries, SimModeScenarios) {
  LONGS_EQUAL(0, run_alone({CANMASTER_PATH, "--sim", "--bringup", "--stream-sine", "1", "--quiet"}));
  LONGS_EQUAL(0, run_alone({CANMASTER_PATH, "--sim", "--bringup", "--hold", "1", "--expect-hb-loss", "4",
                            "--sim-silent", "4@0.3", "--quiet"}));
  // Expecting a loss that never happens is a failure.
  LONGS_EQUAL(1, run_alone({CANMASTER_PATH, "--sim", "--bringup", "--hold", "0.5", "--expect-hb-loss", "4", "--quiet"}));
  // A drive fault during the run fails the scenario.
  LONGS_EQUAL(1, run_alone({CANMASTER_PATH, "--sim", "--bringup", "--hold", "0.5", "--sim-emcy", "2:0x4310@0.1",
                            "--quiet"}));
}

// Issue 15: `armsim --emcy 1:0x2310@0` with canmaster. Node 1 is in FAULT before the master
// starts; bring-up resets it (controlword bit 7 rising edge) and enables every node.
TEST(Binaries, DriveInFaultAtPowerOnIsResetByBringUp) {
  Run r = run_pair({"--nodes", "1-3", "--bringup", "--hold", "0.5", "--hb-timeout-ms", kSlowHb},
                   {"--nodes", "1-3", "--emcy", "1:0x2310@0", "--duration", "5"});
  if (r.master_rc != 0) std::printf("%s\n", r.master_out.c_str());
  STRCMP_CONTAINS("node=1 kind=emcy code=0x2310", r.sim_out.c_str());
  STRCMP_CONTAINS("bringup status=ok", r.master_out.c_str());
  STRCMP_CONTAINS("node id=1 name=\"servoarm virtual drive 1\" state=enabled", r.master_out.c_str());
  STRCMP_CONTAINS("result status=ok", r.master_out.c_str());
  LONGS_EQUAL(0, r.master_rc);
}

// Issue 15: a CSP drive without 606Ch and 603Fh is brought up without TPDO2 (both are
// optional by default); asking for velocity as required names the missing object (exit 4).
TEST(Binaries, DriveWithoutOptionalObjectsIsBroughtUp) {
  Run r = run_pair({"--nodes", "1-2", "--bringup", "--stream-sine", "1", "--hb-timeout-ms", kSlowHb, "--tolerance",
                    kSlowTrack},
                   {"--nodes", "1-2", "--without", "0x606C,0x603F", "--duration", "5"});
  if (r.master_rc != 0) std::printf("%s\n", r.master_out.c_str());
  STRCMP_CONTAINS("bringup status=ok", r.master_out.c_str());
  STRCMP_CONTAINS("node id=2 name=\"servoarm virtual drive 2\" state=enabled tpdo2=none", r.master_out.c_str());
  STRCMP_CONTAINS("result status=ok", r.master_out.c_str());
  LONGS_EQUAL(0, r.master_rc);
  Run q = run_pair({"--nodes", "1-2", "--bringup", "--hold", "0.2", "--tpdo2", "velocity:required,error_code",
                    "--hb-timeout-ms", kSlowHb},
                   {"--nodes", "1-2", "--without", "0x606C", "--check-map-entries", "--duration", "4"});
  STRCMP_CONTAINS("TPDO2 needs 0x606C (velocity actual), which the drive cannot map", q.master_out.c_str());
  LONGS_EQUAL(4, q.master_rc);
  LONGS_EQUAL(2, run_alone({CANMASTER_PATH, "--sim", "--bringup", "--tpdo2", "speed"}));
  LONGS_EQUAL(2, run_alone({ARMSIM_PATH, "--iface", "vcan0", "--without", "0x60"}));
}
