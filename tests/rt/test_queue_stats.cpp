// SPDX-License-Identifier: Apache-2.0
// SPSC queue: order, capacity, wrap-around, in-place use, two-thread stress.
// Cycle statistics: exact min/mean/max, histogram percentile, overflow bin, no heap.
#include <atomic>
#include <cstdint>
#include <thread>

#include "alloc_counter.hpp"
#include "servoarm/rt/spsc_queue.hpp"
#include "servoarm/rt/stats.hpp"

#include <CppUTest/TestHarness.h>

using servoarm::fw::CycleStat;
using servoarm::fw::SpscQueue;

TEST_GROUP(SpscQueue){};

TEST(SpscQueue, FifoOrderAndFullAndEmpty) {
  SpscQueue<int, 4> q;
  int v = 0;
  CHECK_FALSE(q.pop(v));
  CHECK(q.empty());
  for (int i = 0; i < 4; ++i) CHECK(q.push(i));
  CHECK(q.full());
  CHECK_FALSE(q.push(99));  // full: refused, never overwrites
  LONGS_EQUAL(4, q.size());
  for (int i = 0; i < 4; ++i) {
    CHECK(q.pop(v));
    LONGS_EQUAL(i, v);
  }
  CHECK_FALSE(q.pop(v));
}

TEST(SpscQueue, WrapsAroundManyTimes) {
  SpscQueue<std::uint32_t, 8> q;
  std::uint32_t next_in = 0, next_out = 0, v = 0;
  for (int round = 0; round < 1000; ++round) {
    const int k = 1 + round % 8;
    for (int i = 0; i < k; ++i) CHECK(q.push(next_in++));
    for (int i = 0; i < k; ++i) {
      CHECK(q.pop(v));
      LONGS_EQUAL(next_out++, v);
    }
  }
  CHECK(q.empty());
}

TEST(SpscQueue, InPlaceFrontBackPeekClear) {
  SpscQueue<int, 4> q;
  int* b = q.back();
  CHECK(b != nullptr);
  *b = 7;
  CHECK(q.front() == nullptr);  // not visible before commit
  q.commit();
  CHECK(q.front() != nullptr);
  LONGS_EQUAL(7, *q.front());
  q.push(8);
  LONGS_EQUAL(8, *q.peek(1));
  CHECK(q.peek(2) == nullptr);
  LONGS_EQUAL(2, q.clear());
  CHECK(q.empty());
  q.pop();  // pop on empty is a no-op
  CHECK(q.empty());
}

TEST(SpscQueue, TwoThreadsNoLossNoReorderNoHeap) {
  static SpscQueue<std::uint64_t, 64> q;
  constexpr std::uint64_t kN = 300000;
  std::atomic<std::size_t> consumer_allocs{0};
  std::atomic<bool> bad{false};
  std::thread consumer([&] {
    servoarm::test::alloc_count_begin();
    std::uint64_t expect = 0, v = 0;
    while (expect < kN) {
      if (q.pop(v)) {
        if (v != expect) bad = true;
        ++expect;
      }
    }
    consumer_allocs = servoarm::test::alloc_count_end();
  });
  servoarm::test::AllocScope scope;
  for (std::uint64_t i = 0; i < kN;)
    if (q.push(i)) ++i;
  const std::size_t producer_allocs = scope.end();
  consumer.join();
  CHECK_FALSE(bad.load());
  LONGS_EQUAL(0, producer_allocs);
  LONGS_EQUAL(0, consumer_allocs.load());
}

TEST_GROUP(CycleStat){};

TEST(CycleStat, MinMeanMaxExactAndP99FromHistogram) {
  CycleStat s;
  servoarm::test::AllocScope scope;
  // 1000 samples: 990 at 10 us, 10 at 500 us.
  for (int i = 0; i < 990; ++i) s.add(10'000);
  for (int i = 0; i < 10; ++i) s.add(500'000);
  LONGS_EQUAL(0, scope.end());
  const auto sum = s.summary();
  LONGS_EQUAL(1000, sum.count);
  DOUBLES_EQUAL(10.0, sum.min_us, 1e-9);
  DOUBLES_EQUAL(500.0, sum.max_us, 1e-9);
  DOUBLES_EQUAL((990 * 10.0 + 10 * 500.0) / 1000.0, sum.mean_us, 1e-9);
  // p99: 990 samples are <= 11 us (the upper edge of the 10 us bin).
  DOUBLES_EQUAL(11.0, sum.p99_us, 1e-9);
  DOUBLES_EQUAL(500.0, s.percentile_us(100), 1e-9);
  DOUBLES_EQUAL(500.0, s.percentile_us(99.5), 1.0);
}

TEST(CycleStat, OverflowBinAndNegativeAndEmpty) {
  CycleStat s;
  const auto e = s.summary();
  LONGS_EQUAL(0, e.count);
  DOUBLES_EQUAL(0.0, e.p99_us, 0);
  s.add(-5);                  // negative latency (early wake) counts as 0
  s.add(50'000'000);          // 50 ms: overflow bin, exact max kept
  const auto sum = s.summary();
  DOUBLES_EQUAL(0.0, sum.min_us, 1e-9);
  DOUBLES_EQUAL(50'000.0, sum.max_us, 1e-9);
  DOUBLES_EQUAL(50'000.0, s.percentile_us(99), 1e-9);
  LONGS_EQUAL(1, s.histogram()[CycleStat::kBins - 1]);
  LONGS_EQUAL(1, s.histogram()[0]);
}
