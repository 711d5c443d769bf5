// SPDX-License-Identifier: Apache-2.0
#pragma once
// The real-time thread: runs Controller::cycle() at a fixed rate.
//
// Set-up (start(), on the calling thread and then once on the new thread
// before the first cycle): mlockall(MCL_CURRENT | MCL_FUTURE), SCHED_FIFO at
// the configured priority when permitted (else one warning line and normal
// scheduling), optional CPU affinity, a prefaulted stack.
// Per cycle: hal::Clock::sleep_until() to the absolute deadline (the default
// hal::MonotonicClock: clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)), wake-up
// latency = wake time - deadline, Controller::cycle(), compute
// time, overrun when the cycle ends after the next deadline (missed periods are
// skipped, counted once each, never silently absorbed).
// The thread is created with pthread_create (firmware/rt is built without exceptions:
// std::thread reports failure by throwing).
#include <pthread.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <string>

#include "servoarm/rt/controller.hpp"
#include "servoarm/hal/clock.hpp"

namespace servoarm::fw {

struct LoopConfig {
  double rate_hz = 1000.0;  ///< 250 .. 4000
  int priority = 80;        ///< SCHED_FIFO priority 1..99; 0 = normal scheduling
  int cpu = -1;             ///< pin to this CPU (-1 = no affinity)
  bool lock_memory = true;  ///< mlockall
};

/// "" when valid, else which setting is wrong and why.
std::string validate(const LoopConfig& c);

class RtLoop {
 public:
  /// Time from CLOCK_MONOTONIC (hal::MonotonicClock).
  RtLoop(Controller& ctl, const LoopConfig& cfg) : ctl_(ctl), cfg_(cfg), clock_(mono_) {}
  /// Time from `clock` (must outlive the loop, and be usable from the RT thread alone:
  /// nothing else may advance a ManualClock while the loop runs on it).
  RtLoop(Controller& ctl, const LoopConfig& cfg, hal::Clock& clock) : ctl_(ctl), cfg_(cfg), clock_(clock) {}
  RtLoop(const RtLoop&) = delete;
  RtLoop& operator=(const RtLoop&) = delete;
  ~RtLoop() { stop(); }

  /// Hooks run on the RT thread: before the first cycle and after the last
  /// (e.g. tests start/stop an allocation counter there). Set before start().
  std::function<void()> on_thread_start, on_thread_exit;

  /// Work run on the RT thread right before every Controller::cycle(now), with the
  /// same `now` (set before start()). `armfw --sim` steps its virtual drives here,
  /// so drives and controller advance together: a busy machine that delays the
  /// control thread delays the drives with it and cannot starve them into a
  /// feedback or heartbeat fault.
  using PreCycle = void (*)(void* ctx, std::int64_t now_ns);
  void set_pre_cycle(PreCycle fn, void* ctx) {
    pre_cycle_ = fn;
    pre_cycle_ctx_ = ctx;
  }

  /// Start the thread. Warnings (no RT priority, mlockall failed, affinity
  /// failed) are collected in warnings() -- one line each. False if the thread
  /// could not be created (warnings() says why).
  bool start();
  /// Ask the loop to stop and join it (idempotent).
  void stop();
  bool running() const { return running_.load(); }
  /// Warnings collected during set-up (valid after start() returns).
  std::string warnings() const { return warnings_; }
  bool realtime() const { return realtime_; }
  std::uint64_t cycles() const { return cycles_.load(std::memory_order_relaxed); }

 private:
  static void* entry(void* self);
  void thread_main();

  Controller& ctl_;
  LoopConfig cfg_;
  hal::MonotonicClock mono_;
  hal::Clock& clock_;
  pthread_t th_{};
  bool joinable_ = false;
  std::atomic<bool> stop_{false}, running_{false}, ready_{false};
  std::atomic<std::uint64_t> cycles_{0};
  std::string warnings_;
  bool realtime_ = false;
  PreCycle pre_cycle_ = nullptr;
  void* pre_cycle_ctx_ = nullptr;
};

}  // namespace servoarm::fw
