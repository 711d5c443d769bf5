// SPDX-License-Identifier: Apache-2.0
// armsim's virtual MIT motors (--mit) as a separate process, over a socketpair passed with --fd
// (the frames of a vcan interface, without kernel CAN), driven by the firmware's hal::MitGroup on
// the real clock: bring-up writes the mode and the watchdog, the motors follow, the watchdog stops
// them once nothing is sent; a motor whose mode cannot be written refuses the bring-up in one line.
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "servoarm/hal/clock.hpp"
#include "servoarm/hal/mit_group.hpp"
#include "servoarm/hal/socketcan_bus.hpp"
#include "target_exec.hpp"

// CppUTest last: its leak detector redefines `new`.
#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::hal;

namespace {

struct Armsim {
  pid_t pid = -1;
  int out = -1;
  int bus_fd = -1;  ///< our end of the socketpair
  explicit Armsim(std::vector<std::string> args) {
    int sv[2];
    if (socketpair(AF_UNIX, SOCK_SEQPACKET, 0, sv) != 0) return;
    args.insert(args.begin(), {ARMSIM_PATH, "--fd", std::to_string(sv[1])});
    const std::vector<std::string> full = test::target_argv(args);
    std::vector<char*> argv;
    for (auto& a : full) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    int p[2];
    if (pipe(p) != 0) return;
    pid = fork();
    if (pid == 0) {
      dup2(p[1], 1);
      close(p[0]);
      close(p[1]);
      close(sv[0]);
      execv(argv[0], argv.data());
      _exit(127);
    }
    close(p[1]);
    close(sv[1]);
    out = p[0];
    bus_fd = sv[0];
  }
  /// Waits for the process (its --duration) and returns its stdout.
  std::string finish(int& rc) {
    std::string s;
    char buf[4096];
    ssize_t n;
    while ((n = read(out, buf, sizeof buf)) > 0) s.append(buf, std::size_t(n));
    close(out);
    int status = 0;
    waitpid(pid, &status, 0);
    rc = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    return s;
  }
};

MitGroupConfig two_j4340() {
  MitGroupConfig c;
  c.joint_count = 2;
  c.reply_timeout = 200 * kMillisecond;  // two processes on a shared machine
  c.feedback_timeout = 500 * kMillisecond;
  c.motor_timeout = 500 * kMillisecond;  // the motors' own watchdog: longer than a loaded machine stalls the test
  for (std::size_t i = 0; i < 2; ++i) {
    c.joints[i].motor_id = static_cast<std::uint16_t>(i + 1);
    c.joints[i].profile = mit::find_profile("DM-J4340");
  }
  return c;
}

/// The last "armsim mit ... id=0xID ..." status line.
std::string last_status(const std::string& out, const char* id) {
  std::string last;
  std::size_t pos = 0;
  while ((pos = out.find("armsim mit ", pos)) != std::string::npos) {
    const std::size_t end = out.find('\n', pos);
    const std::string line = out.substr(pos, end - pos);
    if (line.find(std::string("id=") + id + " ") != std::string::npos) last = line;
    pos = end;
  }
  return last;
}

}  // namespace

TEST_GROUP(ArmsimMit){};

TEST(ArmsimMit, BringUpFollowAndTheWatchdogAcrossProcesses) {
  Armsim sim({"--nodes", "none", "--mit", "DM-J4340:1", "--mit", "DM-J4340:2", "--mit-mode", "2:2", "--duration", "3",
              "--status-every", "0.25"});
  CHECK(sim.pid > 0);
  MonotonicClock clock;
  SocketCanBus bus(sim.bus_fd);
  MitGroup g(bus, clock, two_j4340());
  const Status s = g.start(clock.now() + 2 * kSecond);
  STRCMP_EQUAL("", g.last_error());
  LONGS_EQUAL(int(Status::ok), int(s));
  g.enable();
  TimePoint t = clock.now();
  for (int i = 0; i < 1000; ++i) {
    g.read(t);
    const double sp[2] = {0.2, -0.1};
    g.write(std::span<const double>(sp, 2), t);
    t += kMillisecond;
    clock.sleep_until(t);
  }
  g.read(clock.now());
  LONGS_EQUAL(int(JointState::enabled), int(g.feedback(0).state));
  DOUBLES_EQUAL(0.2, g.feedback(0).position, 0.01);
  DOUBLES_EQUAL(-0.1, g.feedback(1).position, 0.01);
  // armfw is gone: nothing is sent; armsim runs on to its --duration
  int rc = -1;
  const std::string out = sim.finish(rc);
  LONGS_EQUAL(0, rc);
  CHECK_TEXT(out.find("armsim ready iface=fd:") != std::string::npos && out.find("nodes=none mit=DM-J4340:0x01:0x011") != std::string::npos,
             out.c_str());
  const std::string m2 = last_status(out, "0x02");
  CHECK_TEXT(m2.find("mode=1 timeout=10000") != std::string::npos, out.c_str());  // written by the bring-up
  CHECK_TEXT(m2.find("enabled=0 error=0xD") != std::string::npos, out.c_str());  // its watchdog stopped it
}

TEST(ArmsimMit, AModeThatWillNotChangeRefusesTheBringUp) {
  Armsim sim({"--nodes", "none", "--mit", "DM-J4340:1", "--mit", "DM-J4340:2", "--mit-mode", "1:3", "--mit-locked", "1",
              "--duration", "1.5"});
  MonotonicClock clock;
  SocketCanBus bus(sim.bus_fd);
  MitGroup g(bus, clock, two_j4340());
  LONGS_EQUAL(int(Status::drive_refused), int(g.start(clock.now() + 2 * kSecond)));
  STRCMP_EQUAL(
      "joint 0 (damiao id 0x01): control mode 3 (velocity), not MIT (1), and CTRL_MODE = 1 did not take: in that mode it "
      "answers no MIT frame; set it to MIT with the Damiao tool",
      g.last_error());
  int rc = -1;
  sim.finish(rc);
  LONGS_EQUAL(0, rc);
}

TEST(ArmsimMit, UsageErrors) {
  for (const char* bad : {"DM-J9:1", "DM-J4340", "DM-J4340:0", "DM-J4340:1:0x900"}) {
    Armsim sim({"--nodes", "none", "--mit", bad, "--duration", "0.1"});
    int rc = -1;
    sim.finish(rc);
    LONGS_EQUAL_TEXT(2, rc, bad);
  }
}
