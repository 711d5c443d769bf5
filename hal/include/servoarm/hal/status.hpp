// SPDX-License-Identifier: Apache-2.0
#pragma once
// Status codes of the hal layer (CAN backends, CANopen master, servo bus).
//
//   0        ok
//   > 0      degraded but usable / nothing happened yet: retry or read the flag
//   < 0      failed: the operation did not take effect
#include <cstdint>

namespace servoarm::hal {

enum class Status : std::int8_t {
  ok = 0,
  timeout = 1,           ///< deadline reached before the awaited frame/event
  would_block = 2,       ///< transmit queue full; frame not sent, try next cycle
  error_passive = 3,     ///< frame sent, but the controller is error-passive
  invalid_argument = -1, ///< bad frame (id/len/flags), bad node id, bad config value
  io_error = -2,         ///< unexpected errno from the OS (message says which call)
  bus_off = -3,          ///< controller is bus-off; nothing can be sent
  interface_down = -4,   ///< network interface is down or vanished (reopen pending)
  not_open = -5,         ///< backend has no open socket/endpoint
  sdo_abort = -6,        ///< SDO transfer aborted (see the abort code)
  protocol_error = -7,   ///< peer answered with an unexpected frame/command/size
  drive_fault = -8,      ///< CiA 402 drive is in fault / fault reaction active
  drive_refused = -9,    ///< drive did not follow a state-machine command in time
  heartbeat_lost = -10,  ///< no heartbeat within the configured consumer time
  not_configured = -11,  ///< call order: configure()/bring-up not done yet
  capacity = -12,        ///< more nodes/filters/joints than the fixed capacity
  not_supported = -13,   ///< the backend/protocol does not offer this operation
  bad_state = -14,       ///< not allowed in the joint's current state (e.g. enabled)
  aborted = -15,         ///< stopped on request before it completed (e.g. homing aborted)
  homing_error = -16,    ///< homing failed: the drive's homing error bit (6041h bit 13), or the
                         ///< home mark / hard stop was not found within the travel or timeout
};

/// Short name of a status, e.g. "bus_off". Never returns null.
const char* to_string(Status s);
/// One-sentence human description, e.g. "controller is bus-off; nothing can be sent".
const char* describe(Status s);

inline bool is_ok(Status s) { return static_cast<int>(s) >= 0; }

}  // namespace servoarm::hal
