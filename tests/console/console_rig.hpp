// SPDX-License-Identifier: Apache-2.0
#pragma once
// A console on the puma560 with virtual drives on the sim bus, single-threaded on a
// ManualClock (the console's idle hook runs a control cycle): for the console tests.
#include <string>

#include "sim_app.hpp"

#include <CppUTest/TestHarness.h>

namespace servoarm::test {

struct ConsoleRig {
  hal::ManualClock clock;
  SimApp app;
  fw::Session s;
  hal::Duration period = hal::kMillisecond;

  explicit ConsoleRig(fw::FwConfig cfg = {}) {
    cfg.can = "sim";
    const std::string e = app.build(cfg, &clock);
    if (!e.empty()) FAIL(e.c_str());
    period = static_cast<hal::Duration>(1e9 / cfg.rate_hz);
    clock.set_idle_hook([this](hal::TimePoint t) { app.plant->step(t); });
    const std::string b = app.boot();
    if (!b.empty()) FAIL(b.c_str());
    app.console->set_idle([this] { cycle(); });
  }
  ~ConsoleRig() { clock.set_idle_hook(nullptr); }
  void cycle() {
    app.ctl->cycle(clock.now());
    clock.advance(period);
  }
  /// Execute a line and run cycles until the answer is complete (bounded).
  std::string cmd(const std::string& line) {
    s.out.clear();
    app.console->execute(s, line);
    for (int i = 0; i < 60000 && app.console->busy(s); ++i) {
      cycle();
      app.console->poll(s);
    }
    return s.out;
  }
  void enable() {
    const std::string a = cmd("enable");
    if (a.rfind("ok", 0) != 0) FAIL(("enable: " + a).c_str());
    for (int i = 0; i < 2000 && app.ctl->telemetry().state == fw::ArmState::enabling; ++i) cycle();
    if (app.ctl->telemetry().state != fw::ArmState::idle) FAIL("not idle after enable");
  }
};

inline bool answer_ok(const std::string& a) {
  if (a.empty() || a.back() != '\n') return false;
  const auto p = a.rfind('\n', a.size() - 2);
  return a.compare(p == std::string::npos ? 0 : p + 1, 2, "ok") == 0;
}

}  // namespace servoarm::test
