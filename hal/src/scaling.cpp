// SPDX-License-Identifier: Apache-2.0
#include "servoarm/hal/scaling.hpp"

#include <cmath>
#include <numbers>

namespace servoarm::hal {

double JointScaling::counts_per_si() const {
  switch (kind) {
    case Kind::revolute: return counts_per_unit * gear_ratio / (2.0 * std::numbers::pi);
    case Kind::prismatic: return counts_per_unit * gear_ratio * 1000.0;
  }
  return 0.0;
}

bool JointScaling::valid() const {
  const double k = counts_per_si();
  return std::isfinite(k) && k > 0.0 && (direction == 1 || direction == -1);
}

bool JointScaling::to_counts(double q, std::int32_t& out) const {
  if (!std::isfinite(q)) return false;
  const double c = std::nearbyint(double(direction) * q * counts_per_si()) + double(zero_offset);
  if (!(c >= -2147483648.0 && c <= 2147483647.0)) return false;
  out = std::int32_t(c);
  return true;
}

double JointScaling::to_joint(std::int32_t counts) const {
  return double(direction) * (double(counts) - double(zero_offset)) / counts_per_si();
}

double JointScaling::velocity_to_joint(std::int32_t cps) const { return double(direction) * double(cps) / counts_per_si(); }

}  // namespace servoarm::hal
