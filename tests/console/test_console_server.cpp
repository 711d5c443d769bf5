// SPDX-License-Identifier: Apache-2.0
// ConsoleServer over pipes, with the App's Console and Controller (console_rig.hpp): what
// one client sends never delays another's realtime bytes, every line gets exactly one
// answer however large or many the answers, and what a client sends ahead is left in the
// kernel beyond a bounded receive buffer.
#include <fcntl.h>
#include <poll.h>
#include <unistd.h>
#include <time.h>

#include <atomic>
#include <chrono>
#include <memory>
#include <string>
#include <thread>

#include "console_rig.hpp"
#include "sweep.hpp"
#include "target_exec.hpp"
#include "../program/tmp_dir.hpp"
#include "servoarm/console/transport.hpp"
#include "servoarm/kinematics/orientation.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;

// Wall-clock bounds: under qemu and the sanitizers every line takes several times longer
// (the backlog's own length, which the checks also bound, is what tells the defect).
#if SERVOARM_TEST_EMULATED || SERVOARM_TEST_INSTRUMENTED  // (both 0 on the host: sweep.hpp, target_exec.hpp)
constexpr double kSlow = 10.0;
#else
constexpr double kSlow = 1.0;
#endif

namespace {
bool has(const std::string& s, const std::string& p) { return s.find(p) != std::string::npos; }

double thread_cpu_ms() {
  timespec ts{};
  ::clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

std::size_t count_lines_starting(const std::string& s, const std::string& p) {
  std::size_t n = 0, at = 0;
  while (at < s.size()) {
    if (s.compare(at, p.size(), p) == 0) ++n;
    const std::size_t nl = s.find('\n', at);
    if (nl == std::string::npos) break;
    at = nl + 1;
  }
  return n;
}

/// A client on two pipes: `in` is what the server reads (the test writes its write end),
/// `out` what it writes (the test reads its read end). Both test ends non-blocking.
struct PipeClient {
  FdTransport t;
  int to_server = -1, from_server = -1;
  std::string unsent, got;
  explicit PipeClient(const char* name) {
    int a[2], b[2];
    if (::pipe(a) != 0 || ::pipe(b) != 0) FAIL("pipe");
    t.name = name;
    t.rd = a[0];
    t.wr = b[1];
    t.owns = true;
    to_server = a[1];
    from_server = b[0];
    ::fcntl(to_server, F_SETFL, ::fcntl(to_server, F_GETFL) | O_NONBLOCK);
    ::fcntl(from_server, F_SETFL, ::fcntl(from_server, F_GETFL) | O_NONBLOCK);
    ::fcntl(t.rd, F_SETFL, ::fcntl(t.rd, F_GETFL) | O_NONBLOCK);
  }
  ~PipeClient() {
    ::close(to_server);
    ::close(from_server);
  }
  /// Queue bytes and write what the pipe takes now. Bytes the pipe took so far.
  std::size_t send(const std::string& s) {
    unsent += s;
    return push();
  }
  std::size_t push() {
    std::size_t took = 0;
    while (!unsent.empty()) {
      const ssize_t w = ::write(to_server, unsent.data(), unsent.size());
      if (w <= 0) break;
      unsent.erase(0, static_cast<std::size_t>(w));
      took += static_cast<std::size_t>(w);
    }
    return took;
  }
  /// Read at most `max` bytes of answers.
  void read_some(std::size_t max = 1 << 20) {
    char b[4096];
    while (max > 0) {
      const ssize_t r = ::read(from_server, b, std::min(sizeof b, max));
      if (r <= 0) break;
      got.append(b, static_cast<std::size_t>(r));
      max -= static_cast<std::size_t>(r);
    }
  }
};
}  // namespace

TEST_GROUP(ConsoleServer){};

// A client streaming a long backlog of lines (here `$C` and 3000 movel lines, each checked
// in a millisecond or two) never delays another client's Ctrl-X: the server reads every
// transport between two lines and runs one line per client per turn. One round runs a
// bounded slice of a backlog, never all of it.
TEST(ConsoleServer, ACtrlXActsAtOnceWhateverAnotherClientStreams) {
  test::ConsoleRig r;
  r.enable();
  PipeClient a("a"), b("b");
  ConsoleServer srv(*r.app.console, {&a.t, &b.t});
  // movel lines between the pose where check mode starts and 20 mm below it (each a full path check)
  kin::JointVector qt(6);
  CHECK(test::answer_ok(r.cmd("movej 20 -40 160 10 -50 30")));  // away from the singular zero pose
  CHECK(test::answer_ok(r.cmd("wait")));
  qt << 20, -40, 160, 10, -50, 30;
  const kin::Pose p = r.app.console->pose_in_frame(qt * M_PI / 180.0);
  const Eigen::Vector3d rpy = kin::rpy_from_rotation(p.linear()) * 180.0 / M_PI;
  std::string backlog;
  for (int i = 0; i < 3000; ++i) {
    char l[160];
    std::snprintf(l, sizeof l, "movel %.3f %.3f %.3f %.4f %.4f %.4f\n", p.translation().x() * 1e3, p.translation().y() * 1e3,
                  p.translation().z() * 1e3 - (i % 2 ? 0 : 20), rpy[0], rpy[1], rpy[2]);
    backlog += l;
  }
  a.send("$C\n");  // check mode (at rest): a's lines are checked, nothing moves
  for (int i = 0; i < 20 && !has(a.got, "\n"); ++i) {
    srv.round(0, false);
    a.read_some();
  }
  CHECK_TEXT(has(a.got, "ok check mode on"), a.got.c_str());
  b.send("movej 60 -60 120 60 -60 60 speed=20\n");
  for (int i = 0; i < 20; ++i) {
    srv.round(0, false);
    r.cycle();
  }
  CHECK(r.app.ctl->telemetry().state == ArmState::moving);
  a.send(backlog);
  // one round with a backlog waiting: a bounded slice of it runs
  const std::uint64_t before = srv.session(0).lines_done;
  a.push();
  srv.round(0, false);
  const std::uint64_t ran = srv.session(0).lines_done - before;
  CHECK_TEXT(ran >= 1 && ran <= 64, std::to_string(ran).c_str());
  // Ctrl-X from b while a's backlog runs: written by another thread, 1.5 s into it
  std::atomic<bool> go{false};
  std::atomic<long long> written_ns{0};
  const int fd = b.to_server;
  std::thread writer([&] {
    while (!go.load()) std::this_thread::yield();
    std::this_thread::sleep_for(std::chrono::milliseconds(1500));  // well into a's backlog
    written_ns = std::chrono::steady_clock::now().time_since_epoch().count();
    const char x = 0x18;
    if (::write(fd, &x, 1) != 1) written_ns = -1;
  });
  // when the e-stop acts: the control cycle that runs while the console waits for its answer
  long long seen_ns = 0;
  std::uint64_t lines_after = 0;
  r.app.console->set_idle([&] {
    r.cycle();
    if (seen_ns == 0 && r.app.ctl->telemetry().state == ArmState::estop) {
      seen_ns = std::chrono::steady_clock::now().time_since_epoch().count();
      lines_after = srv.session(0).lines_done;
    }
  });
  for (int i = 0; i < 100000 && seen_ns == 0; ++i) {
    a.push();
    a.read_some();
    go = true;
    srv.round(0, false);
    r.cycle();
  }
  writer.join();
  CHECK(written_ns > 0);
  CHECK(r.app.ctl->telemetry().state == ArmState::estop);
  const double delay_ms = static_cast<double>(seen_ns - written_ns) * 1e-6;
  std::printf("\nCtrl-X from b acted %.1f ms after it was written (a had run %llu lines)\n", delay_ms,
              static_cast<unsigned long long>(lines_after));
  CHECK_TEXT(delay_ms < 300 * kSlow, std::to_string(delay_ms).c_str());
  CHECK_TEXT(lines_after < 3001, "a's backlog ran to its end before the Ctrl-X acted");
  CHECK_TEXT(has(a.got, "ok checked duration="), a.got.substr(0, 300).c_str());
}

// 1000 `status` lines from a client that reads its answers (slowly): 1000 answers, none
// dropped, no overflow alarm; the server stops running the client's lines while its
// answers wait to be written (back-pressure), never throws answers away.
TEST(ConsoleServer, EveryLineIsAnsweredToAClientThatReadsSlowly) {
  test::ConsoleRig r;
  r.enable();
  PipeClient a("a");
  ConsoleServer srv(*r.app.console, {&a.t});
  std::string lines;
  for (int i = 0; i < 1000; ++i) lines += "status\n";
  a.send(lines);
  for (int i = 0; i < 20000 && count_lines_starting(a.got, "ok") < 1000; ++i) {
    a.push();
    srv.round(0, false);
    if (i % 4 == 0) a.read_some(2048);
  }
  a.read_some();
  LONGS_EQUAL(1000, count_lines_starting(a.got, "ok "));
  CHECK_TEXT(!has(a.got, "overflow"), a.got.substr(0, 300).c_str());
}

// An answer larger than any output bound (`points` with 1000 teach points) is answered
// whole, to a client that reads.
TEST(ConsoleServer, AVeryLargeAnswerIsAnsweredWhole) {
  test::ConsoleRig r;
  r.enable();
  for (int i = 0; i < 1000; ++i) CHECK(test::answer_ok(r.cmd("teach p" + std::to_string(i))));
  PipeClient a("a");
  ConsoleServer srv(*r.app.console, {&a.t});
  a.send("points\nstatus\n");
  for (int i = 0; i < 20000 && count_lines_starting(a.got, "ok") < 2; ++i) {
    srv.round(0, false);
    if (i % 2 == 0) a.read_some(4096);
  }
  a.read_some();
  CHECK_TEXT(has(a.got, "p999 joints=["), a.got.substr(0, 200).c_str());
  LONGS_EQUAL(2, count_lines_starting(a.got, "ok"));
  CHECK(!has(a.got, "overflow"));
}

// Lines behind a pending `wait` are not buffered without bound: the server holds a bounded
// number of them and leaves the rest in the kernel (the sender's writes block). Another
// client's Ctrl-X still acts, and the waiting client's lines then each get an answer.
TEST(ConsoleServer, TheReceiveBufferIsBoundedBehindAWait) {
  test::ConsoleRig r;
  r.enable();
  PipeClient a("a"), b("b");
  ConsoleServer srv(*r.app.console, {&a.t, &b.t});
  a.send("movej 60 -60 120 60 -60 60 speed=5\nwait\n");
  std::size_t sent = 0;
  const std::string line = "status\n";
  for (int i = 0; i < 400; ++i) {
    std::string chunk;
    for (int k = 0; k < 1000; ++k) chunk += line;
    sent += a.send(chunk);
    a.unsent.clear();
    srv.round(0, false);
    r.cycle();
  }
  CHECK(r.app.ctl->telemetry().state == ArmState::moving);
  const std::size_t held = srv.session(0).lines.size();
  std::printf("\nbehind a wait: %zu lines held by the server, %zu bytes taken by the kernel and the server\n", held,
              sent);
  CHECK_TEXT(held <= 1024, std::to_string(held).c_str());
  CHECK_TEXT(sent < 400 * 1000 * line.size() / 4, std::to_string(sent).c_str());
  b.send("\x18");
  for (int i = 0; i < 50 && r.app.ctl->telemetry().state != ArmState::estop; ++i) {
    srv.round(0, false);
    r.cycle();
  }
  CHECK(r.app.ctl->telemetry().state == ArmState::estop);
}

// `run` of a long program (2 000 checked movel lines, seconds of path checks) never holds
// up the consoles: the check runs in slices, every transport is read between two, and no
// round of the server lasts longer than a slice; another client's `?` is answered at once,
// and `run` is answered (and the program starts) when the check has ended. Under qemu and
// the sanitizers, where each line checks some 20x slower, 200 lines take the check as long.
TEST(ConsoleServer, CheckingALongProgramNeverBlocksTheConsoles) {
  const std::string dir = test::make_tmp_dir();
  FwConfig cfg;
  cfg.programs_dir = dir;
  {
    test::ConsoleRig r(cfg);
    r.enable();
    CHECK(test::answer_ok(r.cmd("movej 20 -40 160 10 -50 30")));
    CHECK(test::answer_ok(r.cmd("wait")));
    const Telemetry t = r.app.ctl->telemetry();
    kin::JointVector q(6);
    for (int j = 0; j < 6; ++j) q[j] = t.q_cmd[static_cast<std::size_t>(j)];
    const kin::Pose p = r.app.console->pose_in_frame(q);
    const Eigen::Vector3d rpy = kin::rpy_from_rotation(p.linear()) * 180.0 / M_PI;
    const int lines = test::kSlowBuild ? 200 : 2000;
    std::string text;
    for (int i = 0; i < lines; ++i) {
      char b[160];
      std::snprintf(b, sizeof b, "movel %.3f %.3f %.3f %.4f %.4f %.4f speed=200\n", p.translation().x() * 1e3,
                    p.translation().y() * 1e3, p.translation().z() * 1e3 - (i % 2 ? 0 : 20), rpy[0], rpy[1], rpy[2]);
      text += b;
    }
    test::write_file(dir + "/long.arm", text);
    PipeClient a("a"), b("b");
    ConsoleServer srv(*r.app.console, {&a.t, &b.t});
    a.send("run long\n");
    // A round's length as the CPU time this thread spent in it: the work one round does,
    // which is what slicing bounds; wall time would also count the time a busy machine
    // gave the CPU to other processes (a 265 ms round at load 8 was such a preemption).
    double worst_ms = 0, worst_wall_ms = 0;
    int reports = 0;
    for (int i = 0; i < 100000 && !has(a.got, "\n"); ++i) {
      b.send("?");
      const double c0 = thread_cpu_ms();
      const auto t0 = std::chrono::steady_clock::now();
      srv.round(0, false);
      const double ms = thread_cpu_ms() - c0;
      const double wall_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
      if (ms > worst_ms) worst_ms = ms;
      if (wall_ms > worst_wall_ms) worst_wall_ms = wall_ms;
      r.cycle();
      a.read_some();
      b.read_some();
    }
    for (std::size_t at = 0; (at = b.got.find("<", at)) != std::string::npos; ++at) ++reports;
    std::printf("\nrun long: longest server round %.1f ms of CPU time (%.1f ms of wall time) while checking, %d reports "
                "to the other client\n",
                worst_ms, worst_wall_ms, reports);
    CHECK_TEXT(has(a.got, "ok running long: " + std::to_string(lines) + " steps"), a.got.c_str());
    CHECK_TEXT(worst_ms < 200 * kSlow, std::to_string(worst_ms).c_str());
    CHECK(reports > 10);
    // the program runs; abort it
    a.got.clear();
    a.send("abort\n");
    for (int i = 0; i < 20000 && (!has(a.got, "ok aborted") || r.app.ctl->telemetry().state != ArmState::idle); ++i) {
      srv.round(0, false);
      r.cycle();
      a.read_some();
    }
    CHECK_TEXT(has(a.got, "ok aborted long"), a.got.c_str());
    // a stop from another client while a check runs: the check ends, `run` is answered, nothing moves
    a.got.clear();
    a.send("run long\n");
    for (int i = 0; i < 5; ++i) {
      srv.round(0, false);
      a.read_some();
    }
    CHECK_TEXT(!has(a.got, "\n"), a.got.c_str());
    b.send("stop\n");
    for (int i = 0; i < 200 && !has(a.got, "\n"); ++i) {
      srv.round(0, false);
      r.cycle();
      a.read_some();
    }
    CHECK_TEXT(has(a.got, "error: program run: long: check interrupted"), a.got.c_str());
  }
  test::remove_tree(dir);
}

// `quit` on stdin: answered `ok bye`, the lines sent after it answered as not run, and the
// server then ends as at end of input although stdin is still open (armfw exits).
TEST(ConsoleServer, QuitOnStdinEndsTheServerAsEndOfInputDoes) {
  test::ConsoleRig r;
  PipeClient in("stdin");
  ConsoleServer srv(*r.app.console, {&in.t});
  in.send("status\nquit\nstatus\n");
  bool ended = false;
  for (int i = 0; i < 400 && !ended; ++i) {
    ended = !srv.round(5, true);
    in.read_some();
  }
  in.read_some();
  std::printf("\n%s", in.got.c_str());
  CHECK_TEXT(ended, ("the server did not end after quit:\n" + in.got).c_str());
  CHECK_TEXT(count_lines_starting(in.got, "ok state=") == 1, in.got.c_str());
  CHECK_TEXT(has(in.got, "ok bye\n"), in.got.c_str());
  CHECK_TEXT(has(in.got, "error: bad_state 'status' not executed"), in.got.c_str());
}

// `exit` on a serial line (or a pty, the CAN console): that client's session ends (its
// G-code modes start afresh), the client stays connected and its next line is answered;
// the server goes on.
TEST(ConsoleServer, ExitOnASerialLineEndsThatSessionOnly) {
  test::ConsoleRig r;
  PipeClient a("serial"), b("pty-less");
  ConsoleServer srv(*r.app.console, {&a.t, &b.t});
  a.send("G91\n");
  b.send("G91\n");
  for (int i = 0; i < 50; ++i) srv.round(2, false), a.read_some(), b.read_some();
  CHECK(srv.session(0).modal.relative && srv.session(1).modal.relative);
  a.send("exit\n");
  bool going = true;
  for (int i = 0; i < 50; ++i) going = srv.round(2, false) && going, a.read_some();
  CHECK(going);
  CHECK_TEXT(has(a.got, "ok bye\n"), a.got.c_str());
  CHECK_TEXT(!srv.session(0).modal.relative, "the session's G91 outlived exit");
  CHECK_TEXT(srv.session(1).modal.relative, "another client's session changed");
  a.send("status\n");
  for (int i = 0; i < 50; ++i) srv.round(2, false), a.read_some();
  CHECK_TEXT(count_lines_starting(a.got, "ok state=") == 1, a.got.c_str());
}
