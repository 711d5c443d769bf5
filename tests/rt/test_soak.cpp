// SPDX-License-Identifier: Apache-2.0
// Soak: the firmware's own pieces as `armfw --sim` runs them (App, console, the real RT
// thread on CLOCK_MONOTONIC at 1 kHz, the virtual drives stepped on the control thread
// right before each cycle) running a looping program of joint moves, straight lines,
// G-code, a dwell, a feed hold, a stop and jogs for SERVOARM_SOAK_S seconds (default 20),
// and in every pass seeded random moves (SERVOARM_SOAK_SEED, default 1): joint moves to
// random in-limit targets at random speeds, relative straight lines of random length and
// feed, a feed hold and a stop each at a random moment of a random joint move. A random
// line may be refused for what its path meets (unreachable, singular, limits, branch):
// that is an answer, counted and printed; any other error fails.
// SERVOARM_SOAK_PRIORITY=N runs the control thread at SCHED_FIFO N with its memory locked,
// as armfw runs on the robot (loop.priority, default 80 there; 0 here by default: tests
// run without RT privileges everywhere).
// At the end:
//  - no fault: the arm is idle, no fault cause, no fault event seen;
//  - late cycles: missed deadlines (Telemetry::overruns) at most 1 % of the cycles, judged
//    only with SERVOARM_SOAK_STRICT=1 (this runs without RT priority on shared machines
//    beside other suites; the figure is always printed);
//  - memory: no allocation on the RT thread over the whole run (the allocation counter),
//    and the resident set (/proc/self/statm) grown by at most 1 MiB after the first pass
//    of the program (not judged in sanitizer builds: ASan's quarantine holds freed blocks);
//  - every command answered: each line sent got one final answer (ok / error), and
//    every one that should succeed did.
// The figures (cycles, overruns, latency p99 / max, RSS, lines) are printed; a long run:
// SERVOARM_SOAK_S=600 tests/rt/fw_soak (docs/building-and-testing.md, "Soak").
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "alloc_counter.hpp"
#include "sim_app.hpp"
#include "servoarm/rt/mode_table.hpp"
#include "servoarm/rt/rt_loop.hpp"

#if defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
#define SERVOARM_SOAK_SANITIZER 1
#endif
#endif

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;

namespace {

long rss_kib() {
  long pages_total = 0, pages_rss = 0;
  std::FILE* f = std::fopen("/proc/self/statm", "r");
  if (f == nullptr) return -1;
  const int n = std::fscanf(f, "%ld %ld", &pages_total, &pages_rss);
  std::fclose(f);
  if (n != 2) return -1;
  return pages_rss * (::sysconf(_SC_PAGESIZE) / 1024);
}

double load_average() {
  double l = -1;
  std::FILE* f = std::fopen("/proc/loadavg", "r");
  if (f == nullptr) return -1;
  if (std::fscanf(f, "%lf", &l) != 1) l = -1;
  std::fclose(f);
  return l;
}

double soak_seconds() {
  const char* s = std::getenv("SERVOARM_SOAK_S");
  if (s == nullptr || *s == '\0') return 20.0;
  char* end = nullptr;
  const double v = std::strtod(s, &end);
  if (end == s || *end != '\0' || !(v > 0) || v > 86400) {
    std::fprintf(stderr, "SERVOARM_SOAK_S=%s: not a number of seconds in (0, 86400]; using 20\n", s);
    return 20.0;
  }
  return v;
}

// SERVOARM_SOAK_PRIORITY / SERVOARM_SOAK_SEED: a whole number in [lo, hi], else def.
long env_long(const char* name, long def, long lo, long hi) {
  const char* s = std::getenv(name);
  if (s == nullptr || *s == '\0') return def;
  char* end = nullptr;
  const long v = std::strtol(s, &end, 10);
  if (end == s || *end != '\0' || v < lo || v > hi) {
    std::fprintf(stderr, "%s=%s: not a whole number in [%ld, %ld]; using %ld\n", name, s, lo, hi, def);
    return def;
  }
  return v;
}

// The final line of an answer: "ok..." or "error: ...".
std::string last_line(const std::string& a) {
  if (a.empty() || a.back() != '\n') return "";
  const auto p = a.rfind('\n', a.size() - 2);
  return a.substr(p == std::string::npos ? 0 : p + 1);
}

}  // namespace

TEST_GROUP(Soak){};

TEST(Soak, LoopingProgramRunsCleanWithFlatMemory) {
  const double duration = soak_seconds();
  test::SimApp app;
  FwConfig cfg;
  cfg.can = "sim";
  const long priority = env_long("SERVOARM_SOAK_PRIORITY", 0, 0, 99);
  const long seed = env_long("SERVOARM_SOAK_SEED", 1, 0, 2147483647);
  cfg.priority = static_cast<int>(priority);  // 0 by default: tests run without RT privileges everywhere
  cfg.lock_memory = priority > 0;
  const std::string e = app.build(cfg);
  CHECK_TEXT(e.empty(), e.c_str());
  const std::string b = app.boot();
  CHECK_TEXT(b.empty(), b.c_str());
  app.plant->stop_thread();  // from here the drives are stepped on the control thread (armfw --sim)
  LoopConfig lc;
  lc.priority = static_cast<int>(priority);
  lc.lock_memory = priority > 0;
  RtLoop loop(*app.ctl, lc);
  loop.set_pre_cycle(&sim::SimPlant::step_hook, app.plant.get());
  std::size_t rt_allocs = 999;
  loop.on_thread_start = [] { test::alloc_count_begin(); };
  loop.on_thread_exit = [&] { rt_allocs = test::alloc_count_end(); };
  CHECK(loop.start());

  Session s;
  long lines = 0, answered = 0, errors = 0, refused = 0;
  std::string events, first_bad, first_refusal;
  // may_refuse: a random straight line, which the console may refuse for its path.
  auto run = [&](const std::string& line, bool may_refuse = false) {
    s.out.clear();
    app.console->execute(s, line);
    for (int i = 0; i < 60000 && app.console->busy(s); ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
      app.console->poll(s);
    }
    ++lines;
    const std::string last = last_line(s.out);
    if (last.rfind("ok", 0) == 0) {
      ++answered;
    } else if (last.rfind("error: ", 0) == 0) {
      ++answered;
      const std::string code = last.substr(7, last.find(' ', 7) - 7);
      if (may_refuse && (code == "unreachable" || code == "singular" || code == "limits" || code == "branch")) {
        ++refused;
        if (first_refusal.empty()) first_refusal = "'" + line + "' answered " + last;
        events += app.console->drain_events();
        return;
      }
      ++errors;
      if (first_bad.empty()) first_bad = "'" + line + "' answered " + last;
    } else if (first_bad.empty()) {
      const Telemetry t = app.ctl->telemetry();
      first_bad = "'" + line + "' not answered: '" + s.out + "' (state " + to_string(t.state) + ", mode " + to_string(t.mode) + ")";
    }
    events += app.console->drain_events();
  };
  auto sleep_ms = [](int ms) { std::this_thread::sleep_for(std::chrono::milliseconds(ms)); };

  run("enable");
  for (int i = 0; i < 2000 && app.ctl->telemetry().state != ArmState::idle; ++i) sleep_ms(1);
  // Seeded random moves, inside the joint limits with a margin (the middle 70 % of each
  // range, joint 5 kept at least 15 deg from its wrist singularity).
  std::mt19937 rng(static_cast<std::uint32_t>(seed));
  auto uni = [&](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); };
  auto random_joints = [&] {
    std::string l = "movej";
    char v[32];
    for (int j = 0; j < app.chain.n_joints; ++j) {
      const double lo = app.chain.joint(j).lower * 180 / M_PI, hi = app.chain.joint(j).upper * 180 / M_PI;
      const double c = 0.5 * (lo + hi), h = 0.35 * (hi - lo);
      double q = uni(c - h, c + h);
      if (j == 4 && std::fabs(q) < 15) q = q < 0 ? -15 - uni(0, 30) : 15 + uni(0, 30);
      std::snprintf(v, sizeof v, " %.2f", q);
      l += v;
    }
    std::snprintf(v, sizeof v, " speed=%.0f", uni(30, 100));
    return l + v;
  };
  auto random_moves = [&] {
    char l[160];
    for (int i = 0; i < 3; ++i) {
      run(random_joints());
      run("G91");  // a relative straight line of random length and feed from wherever the joint move ends
      std::snprintf(l, sizeof l, "G1 X%.1f Y%.1f Z%.1f F%.0f", uni(-60, 60), uni(-60, 60), uni(-60, 60), uni(300, 6000));
      run(l, true);
      run("G90");
      run("wait");
    }
    run(random_joints());  // a feed hold at a random moment, then resume
    sleep_ms(static_cast<int>(uni(20, 600)));
    app.console->feed(s, "!");
    for (int i = 0; i < 5000 && app.ctl->telemetry().mode != Mode::held && app.ctl->telemetry().state != ArmState::idle; ++i) sleep_ms(1);
    app.console->feed(s, "~");
    s.out.clear();
    run("wait");
    run(random_joints());  // a stop at a random moment
    sleep_ms(static_cast<int>(uni(20, 600)));
    run("stop");
    run("wait");
  };
  // One pass of the program: about 6 s of motion, then the random moves.
  auto pass = [&](int k) {
    const int d = k % 3;  // a little variation between passes
    char l[160];
    std::snprintf(l, sizeof l, "movej %d -40 160 10 -50 30 speed=100", 20 + 5 * d);
    run(l);
    run("wait");
    run("movel 700 380 120 speed=250");
    run("movel 650 300 200 speed=200");
    run("G91");
    run("G1 Z-20 F3000");
    run("G1 X10 Y-10 F2400");
    run("G90");
    run("G4 P20");
    run("M400");
    run("jog j1 +5");
    run("jog j6 -10");
    run("wait");
    run("movej 10 -20 30 5 20 -15 speed=80");
    sleep_ms(150);
    app.console->feed(s, "!");  // feed hold; resume once held (a resume during the hold ramp is ignored)
    for (int i = 0; i < 5000 && app.ctl->telemetry().mode != Mode::held; ++i) sleep_ms(1);
    app.console->feed(s, "~");
    s.out.clear();
    run("wait");
    run("movej 40 -30 60 0 30 0 speed=60");
    sleep_ms(200);
    run("stop");
    run("wait");
    run("park");
    run("wait");
    run("status");
    random_moves();
  };
  const auto t0 = std::chrono::steady_clock::now();
  auto elapsed = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };
  pass(0);
  const long rss0 = rss_kib();
  long rss_max = rss0;
  int passes = 1;
  while (elapsed() < duration && first_bad.empty() && app.ctl->telemetry().cause == FaultCause::none) {
    pass(passes++);
    rss_max = std::max(rss_max, rss_kib());
  }
  loop.stop();
  const long rss1 = rss_kib();
  const Telemetry t = app.ctl->telemetry();
  const double secs = elapsed();
  std::printf("\n[soak] seed %ld, SCHED_FIFO priority %ld%s; %ld random lines refused for their path%s%s\n", seed, priority,
              priority > 0 ? " (memory locked)" : " (normal scheduling)", refused, refused ? ", first: " : "",
              first_refusal.c_str());
  std::printf("[soak] %.0f s, %d passes, %ld lines (%ld answered, %ld errors), %llu cycles, %llu overruns "
              "(%.4f %%), latency p99 %.1f us max %.1f us, RSS %ld -> %ld KiB (max %ld), RT allocations %zu, "
              "max following error %.4f deg\n",
              secs, passes, lines, answered, errors, static_cast<unsigned long long>(t.cycles),
              static_cast<unsigned long long>(t.overruns), 100.0 * double(t.overruns) / double(std::max<std::uint64_t>(1, t.cycles)),
              t.latency.p99_us, t.latency.max_us, rss0, rss1, rss_max, rt_allocs,
              t.max_following_error * 180 / M_PI);
  CHECK_TEXT(first_bad.empty(), first_bad.c_str());
  LONGS_EQUAL(lines, answered);
  LONGS_EQUAL(0, errors);
  CHECK_TEXT(t.state == ArmState::idle && t.cause == FaultCause::none, (std::string(to_string(t.state)) + " " + t.fault_text).c_str());
  CHECK_TEXT(events.find("alarm") == std::string::npos, events.c_str());
  CHECK(t.cycles > static_cast<std::uint64_t>(0.5 * secs * 1000));  // the loop kept running
  // The late-cycle bound is a real-time figure: judged only with SERVOARM_SOAK_STRICT=1 (a
  // run on a quiet or PREEMPT_RT machine). The 1-minute load average lags: in the CI run of
  // 2026-12-02 it read <= 2 while the suites running beside this one starved the loop
  // (1 110 of 23 521 cycles late), so it cannot tell a busy machine from a slow loop. The
  // figure is always printed; the other checks hold everywhere.
  const double load = load_average();
  const unsigned cores = std::max(1u, std::thread::hardware_concurrency());
  const char* strict = std::getenv("SERVOARM_SOAK_STRICT");
  if (strict != nullptr && std::string(strict) == "1") {
    CHECK_TEXT(double(t.overruns) <= 0.01 * double(t.cycles),
               (std::to_string(t.overruns) + " of " + std::to_string(t.cycles) + " cycles late").c_str());
  } else {
    std::printf("[soak] late-cycle bound (1 %% of cycles) not judged (load average %.2f on %u cores; "
                "SERVOARM_SOAK_STRICT=1 judges it)\n", load, cores);
  }
  LONGS_EQUAL(0, rt_allocs);
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__) || defined(SERVOARM_SOAK_SANITIZER)
  // ASan keeps freed blocks in its quarantine (and TSan its shadow), so the resident set
  // grows with the console's ordinary churn: not a leak; the RT counter above still holds.
  std::printf("[soak] RSS bound not judged in a sanitizer build\n");
#else
  CHECK_TEXT(rss_max - rss0 <= 1024, (std::to_string(rss0) + " -> " + std::to_string(rss_max) + " KiB").c_str());
#endif
}
