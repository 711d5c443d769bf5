// SPDX-License-Identifier: Apache-2.0
#pragma once
// Per-joint scaling between drive units (encoder counts, counts/s) and joint
// units (radians / metres, SI). Real-time safe: no allocation, no throw.
#include <cstdint>

namespace servoarm::hal {

struct JointScaling {
  enum class Kind : std::uint8_t { revolute, prismatic };
  Kind kind = Kind::revolute;
  /// Encoder counts per motor revolution (revolute) or per millimetre of motor-side travel (prismatic).
  double counts_per_unit = 131072.0;
  /// Motor units per joint unit (motor revolutions per joint revolution, or motor mm per joint mm).
  double gear_ratio = 1.0;
  /// +1 or -1: sign between joint and drive directions.
  int direction = 1;
  /// Drive position (counts) at joint zero.
  std::int32_t zero_offset = 0;

  /// Counts per joint radian (or per metre).
  double counts_per_si() const;
  /// True when the parameters are usable (finite, non-zero, direction +/-1).
  bool valid() const;

  /// Real-time: joint position -> drive counts. False (out untouched) for NaN/Inf
  /// or a result outside int32.
  bool to_counts(double q, std::int32_t& out) const;
  /// Real-time: drive counts -> joint position.
  double to_joint(std::int32_t counts) const;
  /// Real-time: drive velocity (counts/s) -> joint velocity (rad/s or m/s).
  double velocity_to_joint(std::int32_t counts_per_s) const;
};

}  // namespace servoarm::hal
