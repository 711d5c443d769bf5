// SPDX-License-Identifier: Apache-2.0
#include "servoarm/rt/rt_loop.hpp"

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <time.h>

#include <cerrno>
#include <cstring>

namespace servoarm::fw {

namespace {
// Touch the stack the loop will use so no page fault happens in a cycle.
__attribute__((noinline)) void prefault_stack() {
  constexpr std::size_t kBytes = 256 * 1024;
  unsigned char buf[kBytes];
  for (std::size_t i = 0; i < kBytes; i += 4096) static_cast<volatile unsigned char*>(buf)[i] = 0;
  asm volatile("" : : "r"(buf) : "memory");  // keep the writes
}
}  // namespace

std::string validate(const LoopConfig& c) {
  if (!(c.rate_hz >= 250.0 && c.rate_hz <= 4000.0)) return "rate_hz must be within 250..4000";
  if (c.priority < 0 || c.priority > 99) return "priority must be within 0..99 (0 = normal scheduling)";
  if (c.cpu < -1 || c.cpu > 1023) return "cpu must be -1 (none) or a CPU index";
  return "";
}

bool RtLoop::start() {
  if (running_) return true;
  warnings_.clear();
  if (cfg_.lock_memory && mlockall(MCL_CURRENT | MCL_FUTURE) != 0)
    warnings_ += std::string("warning: mlockall failed (") + std::strerror(errno) + "): memory may be paged\n";
  stop_ = false;
  ready_ = false;
  const int e = pthread_create(&th_, nullptr, &RtLoop::entry, this);
  if (e != 0) {
    warnings_ += std::string("error: cannot create the real-time thread (") + std::strerror(e) + ")\n";
    return false;
  }
  joinable_ = true;
  while (!ready_.load()) sched_yield();
  return true;
}

void RtLoop::stop() {
  stop_ = true;
  if (joinable_) {
    pthread_join(th_, nullptr);
    joinable_ = false;
  }
}

void* RtLoop::entry(void* self) {
  static_cast<RtLoop*>(self)->thread_main();
  return nullptr;
}

void RtLoop::thread_main() {
  pthread_setname_np(pthread_self(), "armfw-rt");
  if (cfg_.cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(static_cast<unsigned>(cfg_.cpu), &set);
    const int e = pthread_setaffinity_np(pthread_self(), sizeof set, &set);
    if (e != 0) warnings_ += "warning: CPU affinity " + std::to_string(cfg_.cpu) + " not set (" + std::strerror(e) + ")\n";
  }
  if (cfg_.priority > 0) {
    sched_param sp{};
    sp.sched_priority = cfg_.priority;
    const int e = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
    if (e == 0) {
      realtime_ = true;
    } else {
      warnings_ += "warning: SCHED_FIFO priority " + std::to_string(cfg_.priority) + " not permitted (" + std::strerror(e) +
                   "); running with normal scheduling (grant CAP_SYS_NICE or an rtprio limit for real-time)\n";
    }
  }
  prefault_stack();
  if (on_thread_start) on_thread_start();
  running_ = true;
  ready_ = true;

  const std::int64_t period = static_cast<std::int64_t>(1e9 / cfg_.rate_hz + 0.5);
  std::int64_t next = clock_.now() + period;
  while (!stop_.load(std::memory_order_relaxed)) {
    clock_.sleep_until(next);
    const std::int64_t woke = clock_.now();
    if (pre_cycle_ != nullptr) pre_cycle_(pre_cycle_ctx_, woke);
    ctl_.cycle(woke);
    const std::int64_t end = clock_.now();
    next += period;
    std::uint32_t missed = 0;  // deadlines that passed during this cycle: skipped, each counted
    while (end > next) {
      next += period;
      ++missed;
    }
    ctl_.record_timing(woke - (next - static_cast<std::int64_t>(missed + 1) * period), end - woke, missed);
    cycles_.fetch_add(1, std::memory_order_relaxed);
  }
  running_ = false;
  if (on_thread_exit) on_thread_exit();
}

}  // namespace servoarm::fw
