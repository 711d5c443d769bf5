// SPDX-License-Identifier: Apache-2.0
#include "servoarm/hal/status.hpp"

namespace servoarm::hal {

const char* to_string(Status s) {
  switch (s) {
    case Status::ok: return "ok";
    case Status::timeout: return "timeout";
    case Status::would_block: return "would_block";
    case Status::error_passive: return "error_passive";
    case Status::invalid_argument: return "invalid_argument";
    case Status::io_error: return "io_error";
    case Status::bus_off: return "bus_off";
    case Status::interface_down: return "interface_down";
    case Status::not_open: return "not_open";
    case Status::sdo_abort: return "sdo_abort";
    case Status::protocol_error: return "protocol_error";
    case Status::drive_fault: return "drive_fault";
    case Status::drive_refused: return "drive_refused";
    case Status::heartbeat_lost: return "heartbeat_lost";
    case Status::not_configured: return "not_configured";
    case Status::capacity: return "capacity";
    case Status::not_supported: return "not_supported";
    case Status::bad_state: return "bad_state";
    case Status::aborted: return "aborted";
    case Status::homing_error: return "homing_error";
  }
  return "unknown_status";
}

const char* describe(Status s) {
  switch (s) {
    case Status::ok: return "success";
    case Status::timeout: return "deadline reached before the awaited frame or event";
    case Status::would_block: return "transmit queue full; frame not sent";
    case Status::error_passive: return "frame sent but the CAN controller is error-passive";
    case Status::invalid_argument: return "invalid argument (frame id/length/flags, node id or config value)";
    case Status::io_error: return "unexpected operating-system error";
    case Status::bus_off: return "CAN controller is bus-off; nothing can be sent";
    case Status::interface_down: return "CAN interface is down or missing";
    case Status::not_open: return "bus backend is not open";
    case Status::sdo_abort: return "SDO transfer aborted by the peer or by timeout";
    case Status::protocol_error: return "unexpected answer from the peer";
    case Status::drive_fault: return "drive reports a fault";
    case Status::drive_refused: return "drive did not follow the state-machine command in time";
    case Status::heartbeat_lost: return "node heartbeat not received within the consumer time";
    case Status::not_configured: return "not configured or not brought up yet";
    case Status::capacity: return "more items than the fixed capacity";
    case Status::not_supported: return "operation not supported by this backend";
    case Status::bad_state: return "not allowed in the current state";
    case Status::aborted: return "stopped on request before it completed";
    case Status::homing_error: return "homing failed: homing error reported, or the home mark or hard stop was not found";
  }
  return "unknown status";
}

}  // namespace servoarm::hal
