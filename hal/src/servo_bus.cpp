// SPDX-License-Identifier: Apache-2.0
#include "servoarm/hal/servo_bus.hpp"

namespace servoarm::hal {

const char* to_string(HomingKind k) {
  switch (k) {
    case HomingKind::none: return "none";
    case HomingKind::cia402: return "cia402";
    case HomingKind::hard_stop: return "hard_stop";
  }
  return "unknown";
}

const char* to_string(HomingPhase p) {
  switch (p) {
    case HomingPhase::idle: return "idle";
    case HomingPhase::running: return "running";
    case HomingPhase::attained: return "attained";
    case HomingPhase::failed: return "failed";
  }
  return "unknown";
}

const char* to_string(CyclicMode m) {
  switch (m) {
    case CyclicMode::position: return "position";
    case CyclicMode::entering_torque: return "entering_torque";
    case CyclicMode::torque: return "torque";
    case CyclicMode::leaving_torque: return "leaving_torque";
  }
  return "unknown";
}

}  // namespace servoarm::hal
