#pragma once
// Seqlock: one writer (the RT thread), any number of readers that retry. The
// telemetry snapshot is published through one; the writer never waits.
#include <atomic>
#include <cstdint>
#include <cstring>

namespace servoarm::fw {

template <typename T>
class Seqlock {
 public:
  /// Real-time (single writer): publish v.
  void write(const T& v) {
    const std::uint32_t s = seq_.load(std::memory_order_relaxed);
    seq_.store(s + 1, std::memory_order_relaxed);
    std::atomic_thread_fence(std::memory_order_release);
    std::memcpy(static_cast<void*>(&data_), &v, sizeof(T));
    std::atomic_thread_fence(std::memory_order_release);
    seq_.store(s + 2, std::memory_order_release);
  }
  /// Any thread: a consistent copy (retries while a write is in progress).
  T read() const {
    T out;
    for (;;) {
      const std::uint32_t s0 = seq_.load(std::memory_order_acquire);
      if (s0 & 1u) continue;
      std::memcpy(static_cast<void*>(&out), &data_, sizeof(T));
      std::atomic_thread_fence(std::memory_order_acquire);
      if (seq_.load(std::memory_order_relaxed) == s0) return out;
    }
  }

 private:
  std::atomic<std::uint32_t> seq_{0};
  T data_{};
};

}  // namespace servoarm::fw
