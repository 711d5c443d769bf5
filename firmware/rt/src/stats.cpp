// SPDX-License-Identifier: Apache-2.0
#include "servoarm/rt/stats.hpp"

namespace servoarm::fw {

double CycleStat::percentile_us(double pct) const {
  if (count_ == 0) return 0.0;
  if (pct >= 100.0) return static_cast<double>(max_) / 1000.0;
  if (pct < 0.0) pct = 0.0;
  // Smallest bin b such that at least pct% of the samples are <= its upper edge.
  const double need = pct / 100.0 * static_cast<double>(count_);
  std::uint64_t acc = 0;
  for (int b = 0; b < kBins; ++b) {
    acc += hist_[static_cast<std::size_t>(b)];
    if (static_cast<double>(acc) >= need && acc > 0) {
      const double edge = (b == kBins - 1) ? static_cast<double>(max_) / 1000.0 : static_cast<double>(b + 1);
      const double mx = static_cast<double>(max_) / 1000.0;
      const double mn = static_cast<double>(min_) / 1000.0;
      double v = edge < mx ? edge : mx;
      if (v < mn) v = mn;
      return v;
    }
  }
  return static_cast<double>(max_) / 1000.0;
}

StatSummary CycleStat::summary() const {
  StatSummary s;
  s.count = count_;
  if (count_ == 0) return s;
  s.min_us = static_cast<double>(min_) / 1000.0;
  s.max_us = static_cast<double>(max_) / 1000.0;
  s.mean_us = sum_ / static_cast<double>(count_) / 1000.0;
  s.p99_us = percentile_us(99.0);
  return s;
}

}  // namespace servoarm::fw
