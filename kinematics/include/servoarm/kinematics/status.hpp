// SPDX-License-Identifier: Apache-2.0
#pragma once
// Status codes of the kinematics layer.
//
//   0        ok
//   > 0      degraded but usable: the result is valid, read the flag
//   < 0      failed: outputs are untouched or hold no solution
#include <cstdint>

namespace servoarm::kin {

enum class Status : std::int8_t {
  ok = 0,
  singular = 1,        ///< result valid, configuration at/near a singularity
  out_of_limits = 2,   ///< solution(s) exist but lie outside the joint limits
  not_converged = 3,   ///< numerical solver: best effort returned, residual above tolerance
  bad_input = -1,      ///< NaN/Inf, non-orthonormal rotation, zero quaternion, ...
  wrong_size = -2,     ///< joint vector length does not match the chain
  unreachable = -3,    ///< target outside the workspace
  capacity = -4,       ///< more joints/rows than the compile-time capacity
  unsupported = -5,    ///< no solver fits this chain
};

/// Human-readable name, e.g. "unreachable".
const char* to_string(Status s);

inline bool is_ok(Status s) { return static_cast<int>(s) >= 0; }

}  // namespace servoarm::kin
