// SPDX-License-Identifier: Apache-2.0
#pragma once
// Cycle statistics without allocation: min / mean / p99 / max and a histogram
// of one quantity measured every cycle (wake-up latency, compute time), in ns.
//
// Real-time: add() is O(1), heap-free, lock-free (single writer). summary()
// walks the histogram (O(kBins)); the control loop calls it every few hundred
// cycles and publishes the result, never per cycle.
#include <array>
#include <cstdint>

namespace servoarm::fw {

struct StatSummary {
  std::uint64_t count = 0;
  double min_us = 0, mean_us = 0, p99_us = 0, max_us = 0;
};

class CycleStat {
 public:
  /// Histogram: 1 us bins from 0 to kBins-1 us; larger values land in the last bin.
  static constexpr int kBins = 2000;

  void reset() { *this = CycleStat{}; }
  /// Real-time: record one sample (ns; negative values count as 0).
  void add(std::int64_t ns) {
    if (ns < 0) ns = 0;
    if (count_ == 0 || ns < min_) min_ = ns;
    if (ns > max_) max_ = ns;
    sum_ += static_cast<double>(ns);
    ++count_;
    std::int64_t b = ns / 1000;
    if (b >= kBins) b = kBins - 1;
    ++hist_[static_cast<std::size_t>(b)];
  }
  std::uint64_t count() const { return count_; }
  /// Percentile (0..100) in us: the upper edge of the bin holding it (exact max
  /// when it lands in the overflow bin or the max's own bin).
  double percentile_us(double pct) const;
  StatSummary summary() const;
  const std::array<std::uint32_t, kBins>& histogram() const { return hist_; }

 private:
  std::uint64_t count_ = 0;
  std::int64_t min_ = 0, max_ = 0;
  double sum_ = 0;
  std::array<std::uint32_t, kBins> hist_{};
};

}  // namespace servoarm::fw
