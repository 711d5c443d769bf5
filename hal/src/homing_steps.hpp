// SPDX-License-Identifier: Apache-2.0
#pragma once
// Steps of the CANopen master's homing state machine (HomingProgress::step), shared by the
// master (canopen_master.cpp) and its hard-stop homing (hard_stop_homing.cpp).
#include <cstdint>

namespace servoarm::hal {
enum HStep : std::uint8_t {
  hs_idle = 0,
  hs_w_method,
  hs_w_speed1,
  hs_w_speed2,
  hs_w_accel,
  hs_w_offset,
  hs_r_mode,
  hs_w_mode,
  hs_r_mode_check,
  hs_start_low,
  hs_running,
  hs_halting,
  hs_unhalt,
  hs_w_csp,
  hs_r_csp,
  hs_done,
  hs_approach = 20,
  hs_backoff,
  hs_settle,
};
}  // namespace servoarm::hal
