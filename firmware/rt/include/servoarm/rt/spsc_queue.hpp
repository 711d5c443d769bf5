// SPDX-License-Identifier: Apache-2.0
#pragma once
// Lock-free single-producer / single-consumer ring of fixed capacity.
//
// One thread pushes, one other thread pops; no locks, no allocation after
// construction (the storage is an inline std::array), never blocks. Used for
// every hand-over between console threads and the control thread (DESIGN.md).
//
// Capacity is a compile-time power of two; the ring holds exactly Capacity
// items (head/tail are free-running counters, so no slot is wasted).
//
// In-place consumption: the consumer may look at front() and pop() later, so a
// large item (a planned trajectory) is used where it lies and never copied on
// the real-time side. Likewise the producer may fill back() and commit().
#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <type_traits>

namespace servoarm::fw {

template <typename T, std::size_t Capacity>
class SpscQueue {
  static_assert(Capacity >= 2 && (Capacity & (Capacity - 1)) == 0, "capacity must be a power of two >= 2");
  static_assert(std::is_trivially_destructible_v<T>, "items are overwritten in place, never destroyed");

 public:
  static constexpr std::size_t capacity() { return Capacity; }

  // ---- producer side -------------------------------------------------------
  /// Copy `v` in. False (nothing written) when full.
  bool push(const T& v) {
    T* slot = back();
    if (slot == nullptr) return false;
    *slot = v;
    commit();
    return true;
  }
  /// Slot to fill in place, or nullptr when full. Call commit() to publish it.
  T* back() {
    const std::uint64_t t = tail_.load(std::memory_order_relaxed);
    if (t - head_.load(std::memory_order_acquire) >= Capacity) return nullptr;
    return &buf_[t & (Capacity - 1)];
  }
  /// Publish the slot returned by back().
  void commit() { tail_.store(tail_.load(std::memory_order_relaxed) + 1, std::memory_order_release); }

  // ---- consumer side -------------------------------------------------------
  /// Copy the oldest item out. False when empty.
  bool pop(T& out) {
    const T* f = front();
    if (f == nullptr) return false;
    out = *f;
    pop();
    return true;
  }
  /// Oldest item (in place), or nullptr when empty.
  T* front() {
    const std::uint64_t h = head_.load(std::memory_order_relaxed);
    if (tail_.load(std::memory_order_acquire) == h) return nullptr;
    return &buf_[h & (Capacity - 1)];
  }
  /// Item `i` positions behind the oldest (0 = front()), or nullptr.
  T* peek(std::size_t i) {
    const std::uint64_t h = head_.load(std::memory_order_relaxed);
    if (tail_.load(std::memory_order_acquire) - h <= i) return nullptr;
    return &buf_[(h + i) & (Capacity - 1)];
  }
  const T* peek(std::size_t i) const { return const_cast<SpscQueue*>(this)->peek(i); }
  /// Drop the oldest item (no-op when empty).
  void pop() {
    const std::uint64_t h = head_.load(std::memory_order_relaxed);
    if (tail_.load(std::memory_order_acquire) == h) return;
    head_.store(h + 1, std::memory_order_release);
  }
  /// Drop everything currently queued (consumer side). Returns how many.
  std::size_t clear() {
    const std::uint64_t t = tail_.load(std::memory_order_acquire);
    const std::uint64_t h = head_.load(std::memory_order_relaxed);
    head_.store(t, std::memory_order_release);
    return static_cast<std::size_t>(t - h);
  }

  // ---- either side (a snapshot: may be stale by the time it is used) -------
  std::size_t size() const {
    return static_cast<std::size_t>(tail_.load(std::memory_order_acquire) - head_.load(std::memory_order_acquire));
  }
  bool empty() const { return size() == 0; }
  bool full() const { return size() >= Capacity; }

 private:
  alignas(64) std::atomic<std::uint64_t> head_{0};  // next to read (consumer owns)
  alignas(64) std::atomic<std::uint64_t> tail_{0};  // next to write (producer owns)
  alignas(64) std::array<T, Capacity> buf_{};
};

}  // namespace servoarm::fw
