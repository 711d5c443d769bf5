// SPDX-License-Identifier: Apache-2.0
#include "servoarm/hal/cia402.hpp"

namespace servoarm::hal::cia402 {

const char* to_string(State s) {
  switch (s) {
    case State::not_ready_to_switch_on: return "not_ready_to_switch_on";
    case State::switch_on_disabled: return "switch_on_disabled";
    case State::ready_to_switch_on: return "ready_to_switch_on";
    case State::switched_on: return "switched_on";
    case State::operation_enabled: return "operation_enabled";
    case State::quick_stop_active: return "quick_stop_active";
    case State::fault_reaction_active: return "fault_reaction_active";
    case State::fault: return "fault";
  }
  return "unknown";
}

State decode_statusword(std::uint16_t sw) {
  if ((sw & 0x4F) == 0x00) return State::not_ready_to_switch_on;
  if ((sw & 0x4F) == 0x40) return State::switch_on_disabled;
  if ((sw & 0x6F) == 0x21) return State::ready_to_switch_on;
  if ((sw & 0x6F) == 0x23) return State::switched_on;
  if ((sw & 0x6F) == 0x27) return State::operation_enabled;
  if ((sw & 0x6F) == 0x07) return State::quick_stop_active;
  if ((sw & 0x4F) == 0x0F) return State::fault_reaction_active;
  if ((sw & 0x4F) == 0x08) return State::fault;
  // Bit patterns the table leaves undefined: treat as not ready (safe side).
  return State::not_ready_to_switch_on;
}

std::uint16_t encode_state_bits(State s) {
  switch (s) {
    case State::not_ready_to_switch_on: return 0x00;
    case State::switch_on_disabled: return 0x40;
    case State::ready_to_switch_on: return 0x21;
    case State::switched_on: return 0x23;
    case State::operation_enabled: return 0x27;
    case State::quick_stop_active: return 0x07;
    case State::fault_reaction_active: return 0x0F;
    case State::fault: return 0x08;
  }
  return 0x00;
}

std::uint16_t next_controlword(State state, Target target, bool reset_phase) {
  switch (target) {
    case Target::enabled:
      switch (state) {
        case State::not_ready_to_switch_on: return cw::kDisableVoltage;  // wait for the drive
        case State::switch_on_disabled: return cw::kShutdown;
        case State::ready_to_switch_on: return cw::kSwitchOn;
        case State::switched_on: return cw::kEnableOperation;
        case State::operation_enabled: return cw::kEnableOperation;
        case State::quick_stop_active: return cw::kDisableVoltage;
        case State::fault_reaction_active: return cw::kDisableVoltage;
        case State::fault: return reset_phase ? cw::kFaultReset : cw::kDisableVoltage;
      }
      break;
    case Target::disabled:
      switch (state) {
        case State::not_ready_to_switch_on: return cw::kDisableVoltage;
        case State::switch_on_disabled: return cw::kDisableVoltage;
        case State::ready_to_switch_on: return cw::kShutdown;
        case State::switched_on: return cw::kShutdown;
        case State::operation_enabled: return cw::kDisableOperation;
        case State::quick_stop_active: return cw::kDisableVoltage;
        case State::fault_reaction_active: return cw::kDisableVoltage;
        case State::fault: return cw::kDisableVoltage;  // no automatic reset when disabling
      }
      break;
    case Target::quick_stop:
      switch (state) {
        case State::not_ready_to_switch_on: return cw::kDisableVoltage;
        case State::switch_on_disabled: return cw::kDisableVoltage;
        case State::ready_to_switch_on: return cw::kQuickStop;   // T7
        case State::switched_on: return cw::kQuickStop;          // T10
        case State::operation_enabled: return cw::kQuickStop;    // T11
        case State::quick_stop_active: return cw::kQuickStop;    // stay
        case State::fault_reaction_active: return cw::kDisableVoltage;
        case State::fault: return cw::kDisableVoltage;
      }
      break;
  }
  return cw::kDisableVoltage;
}

bool reached(State state, Target target) {
  switch (target) {
    case Target::enabled: return state == State::operation_enabled;
    case Target::disabled:
      return state == State::switch_on_disabled || state == State::ready_to_switch_on || state == State::switched_on;
    case Target::quick_stop: return state == State::quick_stop_active || state == State::switch_on_disabled;
  }
  return false;
}

namespace {
bool is_shutdown(std::uint16_t c) { return (c & 0x87) == 0x06; }
bool is_switch_on(std::uint16_t c) { return (c & 0x8F) == 0x07; }
bool is_disable_voltage(std::uint16_t c) { return (c & 0x82) == 0x00; }
bool is_quick_stop(std::uint16_t c) { return (c & 0x86) == 0x02; }
bool is_enable_op(std::uint16_t c) { return (c & 0x8F) == 0x0F; }
}  // namespace

State apply_controlword(State s, std::uint16_t c, std::uint16_t prev, int* transition) {
  int t = 0;
  State n = s;
  switch (s) {
    case State::not_ready_to_switch_on:
    case State::fault_reaction_active:
      break;  // automatic transitions only
    case State::switch_on_disabled:
      if (is_shutdown(c)) { n = State::ready_to_switch_on; t = 2; }
      break;
    case State::ready_to_switch_on:
      if (is_switch_on(c) || is_enable_op(c)) { n = State::switched_on; t = 3; }
      else if (is_disable_voltage(c) || is_quick_stop(c)) { n = State::switch_on_disabled; t = 7; }
      break;
    case State::switched_on:
      if (is_enable_op(c)) { n = State::operation_enabled; t = 4; }
      else if (is_shutdown(c)) { n = State::ready_to_switch_on; t = 6; }
      else if (is_disable_voltage(c) || is_quick_stop(c)) { n = State::switch_on_disabled; t = 10; }
      break;
    case State::operation_enabled:
      if (is_switch_on(c)) { n = State::switched_on; t = 5; }
      else if (is_shutdown(c)) { n = State::ready_to_switch_on; t = 8; }
      else if (is_disable_voltage(c)) { n = State::switch_on_disabled; t = 9; }
      else if (is_quick_stop(c)) { n = State::quick_stop_active; t = 11; }
      break;
    case State::quick_stop_active:
      if (is_disable_voltage(c)) { n = State::switch_on_disabled; t = 12; }
      else if (is_enable_op(c)) { n = State::operation_enabled; t = 16; }
      break;
    case State::fault:
      if ((c & cw::kFaultReset) && !(prev & cw::kFaultReset)) { n = State::switch_on_disabled; t = 15; }
      break;
  }
  if (transition) *transition = t;
  return n;
}

}  // namespace servoarm::hal::cia402
