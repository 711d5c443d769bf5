// SPDX-License-Identifier: Apache-2.0
// armctl console as a process against a scripted firmware on a pty: realtime
// characters sent with -c expect no `ok` (`?` prints the status report that arrives and
// returns; `!`, `~`, Ctrl-X, 0x85 are followed by a `?` whose report ends them), and in
// the interactive console (libedit, on a second pty as armctl's terminal) a line from
// the firmware that arrives while a line is half typed is printed above it and the
// half-typed line is redrawn, then sent whole.
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <termios.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <string>
#include <vector>

#include "target_exec.hpp"

#include <CppUTest/TestHarness.h>

namespace {

using Clock = std::chrono::steady_clock;

// A pty pair: the test holds the master; `slave` is the path armctl opens.
struct Pty {
  int master = -1;
  std::string slave;
  Pty() {
    master = posix_openpt(O_RDWR | O_NOCTTY);
    if (master < 0 || grantpt(master) != 0 || unlockpt(master) != 0) return;
    slave = ptsname(master);
    fcntl(master, F_SETFL, fcntl(master, F_GETFL) | O_NONBLOCK);
  }
  ~Pty() {
    if (master >= 0) close(master);
  }
  void write_str(const std::string& s) const {
    std::size_t off = 0;
    while (off < s.size()) {
      const ssize_t w = ::write(master, s.data() + off, s.size() - off);
      if (w > 0) off += static_cast<std::size_t>(w);
      else poll(nullptr, 0, 1);
    }
  }
  // Read into `acc` until it contains `what` (true) or `seconds` pass (false).
  bool read_until(std::string& acc, const std::string& what, double seconds) const {
    const auto t0 = Clock::now();
    for (;;) {
      if (acc.find(what) != std::string::npos) return true;
      if (std::chrono::duration<double>(Clock::now() - t0).count() > seconds) return false;
      pollfd p{master, POLLIN, 0};
      poll(&p, 1, 20);
      char b[512];
      const ssize_t r = ::read(master, b, sizeof b);
      if (r > 0) acc.append(b, static_cast<std::size_t>(r));
    }
  }
};

std::string g_home;  // HOME of an interactive armctl (a temporary directory)

struct Child {
  pid_t pid = -1;
  int out = -1;  // armctl's stdout + stderr (one-shot runs), -1 when on a terminal
};

// Starts armctl with `args`; stdin/stdout/stderr on `tty` when given (interactive),
// else stdin /dev/null and stdout+stderr into a pipe.
Child start_armctl(const std::vector<std::string>& args, const std::string& tty = "") {
  std::vector<std::string> full = {ARMCTL_PATH};
  full.insert(full.end(), args.begin(), args.end());
  const std::vector<std::string> av = servoarm::test::target_argv(full);
  std::vector<char*> argv;
  for (const auto& a : av) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  int p[2] = {-1, -1};
  if (tty.empty() && pipe(p) != 0) return {};
  const pid_t pid = fork();
  if (pid == 0) {
    if (tty.empty()) {
      const int null = open("/dev/null", O_RDONLY);
      dup2(null, 0);
      dup2(p[1], 1);
      dup2(p[1], 2);
      close(p[0]);
    } else {
      setsid();
      const int t = open(tty.c_str(), O_RDWR);  // becomes the controlling terminal
      dup2(t, 0);
      dup2(t, 1);
      dup2(t, 2);
      setenv("TERM", "xterm", 1);
      if (!g_home.empty()) setenv("HOME", g_home.c_str(), 1);  // the history file goes there, not into ~
    }
    execv(argv[0], argv.data());
    _exit(127);
  }
  Child c;
  c.pid = pid;
  if (tty.empty()) {
    close(p[1]);
    c.out = p[0];
    fcntl(c.out, F_SETFL, fcntl(c.out, F_GETFL) | O_NONBLOCK);
  }
  return c;
}

// Waits up to `seconds` for the child, collecting its output; -1 on timeout (killed).
int finish(Child& c, std::string& out, double seconds) {
  const auto t0 = Clock::now();
  for (;;) {
    char b[512];
    ssize_t r;
    while (c.out >= 0 && (r = ::read(c.out, b, sizeof b)) > 0) out.append(b, static_cast<std::size_t>(r));
    int st = 0;
    if (waitpid(c.pid, &st, WNOHANG) == c.pid) {
      while (c.out >= 0 && (r = ::read(c.out, b, sizeof b)) > 0) out.append(b, static_cast<std::size_t>(r));
      if (c.out >= 0) close(c.out);
      return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
    }
    if (std::chrono::duration<double>(Clock::now() - t0).count() > seconds) {
      kill(c.pid, SIGKILL);
      waitpid(c.pid, &st, 0);
      if (c.out >= 0) close(c.out);
      return -1;
    }
    poll(nullptr, 0, 10);
  }
}

const char* kReport = "<Idle|MPos:411.480,149.090,489.320|J:0.0,0.0,0.0,0.0,0.0,0.0|Q:0>\r\n";

}  // namespace

TEST_GROUP(ArmctlConsole){};

TEST(ArmctlConsole, StatusReportCharacterPrintsTheReportAndReturnsAtOnce) {
  Pty fw;
  CHECK(!fw.slave.empty());
  const auto t0 = Clock::now();
  Child c = start_armctl({"console", "--serial", fw.slave, "--timeout", "30", "-c", "?"});
  std::string got;
  CHECK_TEXT(fw.read_until(got, "?", 10), got.c_str());
  STRCMP_EQUAL("?", got.c_str());  // the character alone: no newline, no line
  fw.write_str(kReport);
  std::string out;
  const int rc = finish(c, out, 10);
  const double s = std::chrono::duration<double>(Clock::now() - t0).count();
  LONGS_EQUAL_TEXT(0, rc, out.c_str());
  CHECK_TEXT(out.find("<Idle|MPos:411.480,149.090,489.320|") != std::string::npos, out.c_str());
  CHECK_TEXT(s < 5, out.c_str());  // was: 60 s waiting for an ok, then exit 1
}

TEST(ArmctlConsole, OtherRealtimeCharactersAreFollowedByAStatusReportThenTheNextLine) {
  // -c '!' -c '~' -c '^X' -c 0x85 -c status: each realtime character, then its ?, then
  // the report ends it; the line after still gets its ok.
  Pty fw;
  Child c = start_armctl({"console", "--serial", fw.slave, "--timeout", "30", "-c", "!", "-c", "~", "-c", "^X", "-c",
                          "0x85", "-c", "status"});
  std::string got;
  for (const std::string expect : {"!?", "~?", "\x18?", "\x85?"}) {
    got.clear();
    CHECK_TEXT(fw.read_until(got, expect, 10), (expect + " expected, got " + got).c_str());
    STRCMP_EQUAL(expect.c_str(), got.c_str());
    fw.write_str(expect[0] == '\x18' ? "alarm: e-stop (Ctrl-X)\r\n" : "");
    fw.write_str(expect[0] == '!' ? "<Hold:0|MPos:0,0,0|Q:0>\r\n" : kReport);
  }
  got.clear();
  CHECK_TEXT(fw.read_until(got, "status\n", 10), got.c_str());
  fw.write_str("ok state=idle\r\n");
  std::string out;
  LONGS_EQUAL_TEXT(0, finish(c, out, 10), out.c_str());
  CHECK_TEXT(out.find("<Hold:0|") != std::string::npos, out.c_str());
  CHECK_TEXT(out.find("alarm: e-stop") != std::string::npos, out.c_str());  // alarms on stderr, shown
  CHECK_TEXT(out.find("ok state=idle") != std::string::npos, out.c_str());
}

TEST(ArmctlConsole, RealtimeCharacterWithoutReportTimesOutAndAnErrorFails) {
  {
    Pty fw;  // the firmware never answers: exit 1 after --timeout, naming what was missing
    const auto t0 = Clock::now();
    Child c = start_armctl({"console", "--serial", fw.slave, "--timeout", "1", "-c", "?"});
    std::string out;
    LONGS_EQUAL_TEXT(1, finish(c, out, 10), out.c_str());
    CHECK_TEXT(out.find("no status report within 1 s") != std::string::npos, out.c_str());
    CHECK(std::chrono::duration<double>(Clock::now() - t0).count() < 5);
  }
  {
    Pty fw;  // the feed hold answered an error before the report: exit 1, both printed
    Child c = start_armctl({"console", "--serial", fw.slave, "--timeout", "30", "-c", "!"});
    std::string got;
    CHECK(fw.read_until(got, "!?", 10));
    fw.write_str("error: timeout feed hold not acknowledged\r\n");
    fw.write_str(kReport);
    std::string out;
    LONGS_EQUAL_TEXT(1, finish(c, out, 10), out.c_str());
    CHECK_TEXT(out.find("error: timeout feed hold") != std::string::npos, out.c_str());
    CHECK_TEXT(out.find("<Idle|") != std::string::npos, out.c_str());
  }
}

TEST(ArmctlConsole, BadOptionValuesAreRefused) {
  for (const std::vector<std::string>& a : std::vector<std::vector<std::string>>{
           {"console", "--serial", "/dev/null", "--timeout", "1e300"},
           {"console", "--serial", "/dev/null", "--timeout", "0"},
           {"console", "--serial", "/dev/null", "--timeout"},
           {"console", "--serial", "/dev/null", "--baud", "1e300"},
           {"console", "--serial", "/dev/null", "--baud", "115200.5"},
           {"console", "--serial", "/dev/null", "-c"},
           {"console", "--serial"}}) {
    Child c = start_armctl(a);
    std::string out;
    std::string what;
    for (const auto& w : a) what += w + " ";
    LONGS_EQUAL_TEXT(2, finish(c, out, 10), (what + "\n" + out).c_str());
    CHECK_TEXT(out.rfind("armctl: ", 0) == 0, (what + "\n" + out).c_str());
  }
}

#ifdef SERVOARM_TEST_LIBEDIT
TEST(ArmctlConsole, AnswerWhileTypingRedrawsTheHalfTypedLine) {
  Pty fw, term;
  char home[] = "/tmp/servoarm_armctl_home_XXXXXX";
  CHECK(mkdtemp(home) != nullptr);
  g_home = home;
  Child c = start_armctl({"console", "--serial", fw.slave}, term.slave);
  std::string screen;
  CHECK_TEXT(term.read_until(screen, "arm> ", 10), screen.c_str());
  term.write_str("sta");  // half a line typed
  CHECK_TEXT(term.read_until(screen, "arm> sta", 10), screen.c_str());
  screen.clear();
  fw.write_str("alarm: joint 3 near its limit\r\n");  // arrives while typing
  CHECK_TEXT(term.read_until(screen, "alarm: joint 3 near its limit", 10), screen.c_str());
  const std::size_t at = screen.find("alarm: joint 3");
  // ... printed on a line of its own, and then the prompt and the half-typed line again
  CHECK_TEXT(term.read_until(screen, "sta", 10) && screen.find("arm> sta", at) != std::string::npos,
             screen.c_str());
  term.write_str("tus\r");  // finish the line: the whole of it goes to the firmware
  std::string got;
  CHECK_TEXT(fw.read_until(got, "status\n", 10), got.c_str());
  STRCMP_EQUAL("status\n", got.c_str());
  fw.write_str("ok state=idle\r\n");
  CHECK_TEXT(term.read_until(screen, "ok state=idle", 10), screen.c_str());
  term.write_str("\x04");  // Ctrl-D quits
  std::string out;
  LONGS_EQUAL(0, finish(c, out, 10));
  const std::string hist = g_home + "/.armctl_history";
  CHECK_TEXT(std::remove(hist.c_str()) == 0, "no history written");  // the line went into the history
  rmdir(g_home.c_str());
  g_home = std::string();  // (its buffer is freed here, inside the test, for the leak detector)
  g_home.shrink_to_fit();
}
#endif

// `quit` or `exit` typed at an interactive armctl console (a terminal: line editing when
// built with libedit) goes to the firmware, whose answer is printed, and armctl ends (exit
// status 0) without a Ctrl-D.
TEST(ArmctlConsole, TypedQuitOrExitEndsTheInteractiveConsole) {
  for (const char* word : {"quit", "exit"}) {
    Pty fw, term;
    char home[] = "/tmp/servoarm_armctl_home_XXXXXX";
    CHECK(mkdtemp(home) != nullptr);
    g_home = home;
    Child c = start_armctl({"console", "--serial", fw.slave}, term.slave);
    std::string screen;
    CHECK_TEXT(term.read_until(screen, "arm> ", 10) || term.read_until(screen, "connected", 1), screen.c_str());
    term.write_str(std::string(word) + "\r");
    std::string got;
    CHECK_TEXT(fw.read_until(got, std::string(word) + "\n", 10), got.c_str());
    fw.write_str("ok bye\r\n");
    std::string out;
    const int rc = finish(c, out, 5);
    term.read_until(screen, "ok bye", 1);
    LONGS_EQUAL_TEXT(0, rc, (std::string(word) + ": armctl still running or failed:\n" + screen).c_str());
    CHECK_TEXT(screen.find("ok bye") != std::string::npos, screen.c_str());
    std::remove((g_home + "/.armctl_history").c_str());
    rmdir(g_home.c_str());
    g_home = std::string();
    g_home.shrink_to_fit();
  }
}
