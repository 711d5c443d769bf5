// SPDX-License-Identifier: Apache-2.0
#pragma once
// Seqlock: one writer (the RT thread), any number of readers that retry. The
// telemetry snapshot is published through one; the writer never waits.
//
// The payload is kept as relaxed atomic 64-bit words (Boehm, "Can seqlocks get along with
// programming language memory models?", 2012): a reader's copy may overlap a write, and
// with plain accesses that overlap is a data race in the C++ memory model (ThreadSanitizer
// reported it) even though the sequence check discards the torn copy. Relaxed word loads
// and stores compile to the same plain moves on x86-64 and AArch64/ARMv7.
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <type_traits>

namespace servoarm::fw {

template <typename T>
class Seqlock {
  static_assert(std::is_trivially_copyable_v<T>, "a Seqlock publishes trivially copyable data");
  static_assert(std::atomic<std::uint64_t>::is_always_lock_free,
                "the RT thread never locks: 64-bit atomics must be lock-free (ARMv7: ldrexd/strexd)");
  static constexpr std::size_t kWords = (sizeof(T) + 7) / 8;

 public:
  Seqlock() {
    const T zero{};
    store_words(zero);
  }
  /// Real-time (single writer): publish v.
  void write(const T& v) {
    const std::uint32_t s = seq_.load(std::memory_order_relaxed);
    seq_.store(s + 1, std::memory_order_relaxed);
    std::atomic_thread_fence(std::memory_order_release);
    store_words(v);
    seq_.store(s + 2, std::memory_order_release);
  }
  /// Any thread: a consistent copy (retries while a write is in progress).
  T read() const {
    T out;
    for (;;) {
      const std::uint32_t s0 = seq_.load(std::memory_order_acquire);
      if (s0 & 1u) continue;
      auto* bytes = reinterpret_cast<unsigned char*>(&out);
      for (std::size_t i = 0; i < kWords; ++i) {
        const std::uint64_t w = words_[i].load(std::memory_order_relaxed);
        std::memcpy(bytes + 8 * i, &w, chunk(i));
      }
      std::atomic_thread_fence(std::memory_order_acquire);
      if (seq_.load(std::memory_order_relaxed) == s0) return out;
    }
  }

 private:
  static constexpr std::size_t chunk(std::size_t i) { return i + 1 < kWords ? 8 : sizeof(T) - 8 * i; }
  void store_words(const T& v) {
    const auto* bytes = reinterpret_cast<const unsigned char*>(&v);
    for (std::size_t i = 0; i < kWords; ++i) {
      std::uint64_t w = 0;
      std::memcpy(&w, bytes + 8 * i, chunk(i));
      words_[i].store(w, std::memory_order_relaxed);
    }
  }

  std::atomic<std::uint32_t> seq_{0};
  std::atomic<std::uint64_t> words_[kWords];
};

}  // namespace servoarm::fw
