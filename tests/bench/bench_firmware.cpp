// SPDX-License-Identifier: Apache-2.0
// Cost of one control cycle (Controller::cycle: read feedback, supervisor,
// motion sample, limit/NaN checks, 6 RPDOs + SYNC, telemetry) for the PUMA 560
// on six virtual CiA 402 drives on the in-process bus, single thread, simulated
// clock (no sleeping, no second thread: the CPU cost only, not the wake-up latency
// that tests/bench/run_loop_bench.sh measures).
//
// Every iteration also steps the virtual drives (they answer the SYNC with their
// TPDOs, which the next cycle reads) and, when the queue runs dry, queues the next
// move through the console; only Controller::cycle is timed (manual time, one
// steady_clock pair per iteration, ~40 ns of it). Figures: tests/bench/RESULTS.md.
#include <benchmark/benchmark.h>

#include <chrono>
#include <cstdio>
#include <string>

#include "sim_app.hpp"
#include "servoarm/kinematics/chain.hpp"

namespace {

using namespace servoarm;

struct FwRig {
  hal::ManualClock clock;
  test::SimApp app;
  fw::Session s;
  bool ok = false;

  FwRig() {
    fw::FwConfig cfg;
    cfg.can = "sim";
    if (!app.build(cfg, &clock).empty()) return;
    clock.set_idle_hook([this](hal::TimePoint t) { app.plant->step(t); });
    if (!app.boot().empty()) return;
    app.console->set_idle([this] { tick(); });
    ok = command("enable") && wait_state(fw::ArmState::idle);
  }
  ~FwRig() { clock.set_idle_hook(nullptr); }
  void tick() {
    clock.advance(hal::kMillisecond);
    app.plant->step(clock.now());
    app.ctl->cycle(clock.now());
  }
  /// One period; returns the seconds spent in Controller::cycle alone.
  double timed_tick() {
    clock.advance(hal::kMillisecond);
    app.plant->step(clock.now());
    const auto t0 = std::chrono::steady_clock::now();
    app.ctl->cycle(clock.now());
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  bool command(const std::string& line) {
    s.out.clear();
    app.console->execute(s, line);
    for (int i = 0; i < 20000 && app.console->busy(s); ++i) {
      tick();
      app.console->poll(s);
    }
    return s.out.rfind("ok", 0) == 0 || s.out.find("\nok") != std::string::npos;
  }
  bool wait_state(fw::ArmState st) {
    for (int i = 0; i < 5000 && app.ctl->telemetry().state != st; ++i) tick();
    return app.ctl->telemetry().state == st;
  }
};

// Keeps a move in progress: whenever the queue runs dry, queue the next one
// (outside the timed region).
template <typename Next>
void run_cycles(benchmark::State& state, FwRig& r, Next next) {
  if (!r.ok) {
    state.SkipWithError("firmware rig did not come up");
    return;
  }
  int k = 0;
  for (auto _ : state) {
    if (r.app.ctl->motions().empty() && k >= 0 && !next(k++)) k = -1;
    state.SetIterationTime(r.timed_tick());
  }
  if (k < 0) state.SkipWithError("a move was refused");
  const fw::Telemetry t = r.app.ctl->telemetry();
  if (t.state == fw::ArmState::fault) state.SkipWithError(t.fault_text);
  state.counters["moves"] = static_cast<double>(t.done_id);  // id of the last move finished
  state.counters["blended"] = static_cast<double>(t.blended_corners);
}

void BM_FwCycle_Idle(benchmark::State& state) {
  FwRig r;
  run_cycles(state, r, [](int) { return true; });
}
BENCHMARK(BM_FwCycle_Idle)->UseManualTime();

void BM_FwCycle_Movej(benchmark::State& state) {
  FwRig r;
  run_cycles(state, r, [&r](int k) {
    return r.command(k % 2 ? "movej 20 -40 160 10 -50 30 speed=60" : "movej -20 -60 140 -10 -30 -30 speed=60");
  });
}
BENCHMARK(BM_FwCycle_Movej)->UseManualTime();

void BM_FwCycle_Movel(benchmark::State& state) {
  FwRig r;
  // From the demo's working pose, straight lines of 60 mm back and forth along x (G91).
  if (r.ok) r.ok = r.command("movej 20 -40 160 10 -50 30 speed=100") && r.command("wait") && r.command("G91");
  run_cycles(state, r, [&r](int k) { return r.command(k % 2 ? "G1 X-60 F6000" : "G1 X60 F6000"); });
}
BENCHMARK(BM_FwCycle_Movel)->UseManualTime();

// The same cycles a fixed number of times (for callgrind: instructions per Controller::cycle on
// an identical sequence, tests/bench/RESULTS.md), and the two blended runs of the executor: joint
// moves with blend= (one blend queue) and lines with blend= (path segments overlapping).
constexpr int kFixedCycles = 20000;

void BM_FwCycleFixed_Idle(benchmark::State& state) {
  FwRig r;
  run_cycles(state, r, [](int) { return true; });
}
BENCHMARK(BM_FwCycleFixed_Idle)->UseManualTime()->Iterations(kFixedCycles);

void BM_FwCycleFixed_Movej(benchmark::State& state) {
  FwRig r;
  run_cycles(state, r, [&r](int k) {
    return r.command(k % 2 ? "movej 20 -40 160 10 -50 30 speed=60" : "movej -20 -60 140 -10 -30 -30 speed=60");
  });
}
BENCHMARK(BM_FwCycleFixed_Movej)->UseManualTime()->Iterations(kFixedCycles);

// Movej while a recorder takes every cycle (Controller::start_samples(1), the ring emptied
// outside the timed cycle as the recorder's thread would): the control thread's cost of an
// MCAP recording at the control rate.
void BM_FwCycleFixed_MovejSampled(benchmark::State& state) {
  FwRig r;
  r.app.ctl->start_samples(1);
  fw::CycleSample c;
  run_cycles(state, r, [&r, &c](int k) {
    while (r.app.ctl->pop_sample(c)) {
    }
    return r.command(k % 2 ? "movej 20 -40 160 10 -50 30 speed=60" : "movej -20 -60 140 -10 -30 -30 speed=60");
  });
  state.counters["dropped"] = static_cast<double>(r.app.ctl->samples_dropped());
}
BENCHMARK(BM_FwCycleFixed_MovejSampled)->UseManualTime()->Iterations(kFixedCycles);

void BM_FwCycleFixed_Movel(benchmark::State& state) {
  FwRig r;
  if (r.ok) r.ok = r.command("movej 20 -40 160 10 -50 30 speed=100") && r.command("wait") && r.command("G91");
  run_cycles(state, r, [&r](int k) { return r.command(k % 2 ? "G1 X-60 F6000" : "G1 X60 F6000"); });
}
BENCHMARK(BM_FwCycleFixed_Movel)->UseManualTime()->Iterations(kFixedCycles);

// Three joint moves blended into one run (blend= on the first two), back and forth.
void BM_FwCycleFixed_BlendJoint(benchmark::State& state) {
  FwRig r;
  run_cycles(state, r, [&r](int k) {
    const char* a = k % 2 ? "movej 20 -40 160 10 -50 30 speed=80 blend=10" : "movej -20 -60 140 -10 -30 -30 speed=80 blend=10";
    const char* b = k % 2 ? "movej 0 -50 150 0 -40 0 speed=80 blend=10" : "movej 10 -45 150 5 -45 10 speed=80 blend=10";
    const char* c = k % 2 ? "movej -20 -60 140 -10 -30 -30 speed=80" : "movej 20 -40 160 10 -50 30 speed=80";
    return r.command(a) && r.command(b) && r.command(c);
  });
}
BENCHMARK(BM_FwCycleFixed_BlendJoint)->UseManualTime()->Iterations(kFixedCycles);

// Three lines of 40 mm blended into one run (blend=5 mm on the first two), there and back.
void BM_FwCycleFixed_BlendPath(benchmark::State& state) {
  FwRig r;
  if (r.ok) r.ok = r.command("movej 20 -40 160 10 -50 30 speed=100") && r.command("wait");
  Eigen::Vector3d p0 = Eigen::Vector3d::Zero();
  if (r.ok) {
    const fw::Telemetry t = r.app.ctl->telemetry();
    kin::JointVector q(t.n);
    for (int j = 0; j < t.n; ++j) q[j] = t.q_cmd[static_cast<std::size_t>(j)];
    kin::Pose x;
    r.ok = kin::forward(r.app.ctl->chain(), q, x) == kin::Status::ok;
    p0 = x.translation() * 1e3;  // mm
  }
  const auto movel = [&p0](double dx, double dy, double dz, const char* tail) {
    char b[160];
    std::snprintf(b, sizeof b, "movel %.6f %.6f %.6f speed=200%s", p0.x() + dx, p0.y() + dy, p0.z() + dz, tail);
    return std::string(b);
  };
  run_cycles(state, r, [&r, &movel](int k) {
    if (k % 2 == 0)
      return r.command(movel(-40, 0, 0, " blend=5")) && r.command(movel(-40, 40, 0, " blend=5")) &&
             r.command(movel(-40, 40, -20, ""));
    return r.command(movel(-40, 40, 0, " blend=5")) && r.command(movel(-40, 0, 0, " blend=5")) &&
           r.command(movel(0, 0, 0, ""));
  });
}
BENCHMARK(BM_FwCycleFixed_BlendPath)->UseManualTime()->Iterations(kFixedCycles);


}  // namespace
