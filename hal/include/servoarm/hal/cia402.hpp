// SPDX-License-Identifier: Apache-2.0
#pragma once
// CiA 402 (drives and motion control) power state machine: statusword
// decoding, controlword commands, and the drive-side transition table used by
// the virtual servos. Pure functions: real-time safe.
#include <cstdint>

namespace servoarm::hal::cia402 {

// Object indices used by the master and the virtual drives.
inline constexpr std::uint16_t kErrorCode = 0x603F;
inline constexpr std::uint16_t kControlword = 0x6040;
inline constexpr std::uint16_t kStatusword = 0x6041;
inline constexpr std::uint16_t kModesOfOperation = 0x6060;
inline constexpr std::uint16_t kModesDisplay = 0x6061;
inline constexpr std::uint16_t kPositionActual = 0x6064;
inline constexpr std::uint16_t kFollowingErrorWindow = 0x6065;
inline constexpr std::uint16_t kVelocityActual = 0x606C;
inline constexpr std::uint16_t kTargetPosition = 0x607A;
inline constexpr std::uint16_t kQuickStopOption = 0x605A;  ///< INTEGER16 quick stop option code
inline constexpr std::uint16_t kQuickStopDecel = 0x6085;   ///< UNSIGNED32 quick stop deceleration
inline constexpr std::uint16_t kFollowingErrorActual = 0x60F4;
inline constexpr std::uint16_t kRatedTorque = 0x6076;    ///< UNSIGNED32 motor rated torque, mN m
inline constexpr std::uint16_t kTorqueActual = 0x6077;   ///< INTEGER16 per mille of 6076h
inline constexpr std::uint16_t kVelocityOffset = 0x60B1; ///< INTEGER32 velocity feed-forward, counts/s
inline constexpr std::uint16_t kTorqueOffset = 0x60B2;   ///< INTEGER16 torque feed-forward, per mille of 6076h
inline constexpr std::uint16_t kHomeOffset = 0x607C;      ///< INTEGER32 home offset (6064h at the home mark)
inline constexpr std::uint16_t kHomingMethod = 0x6098;    ///< INTEGER8 homing method
inline constexpr std::uint16_t kHomingSpeeds = 0x6099;    ///< :01 search for switch, :02 search for zero (UNSIGNED32)
inline constexpr std::uint16_t kHomingAccel = 0x609A;     ///< UNSIGNED32 homing acceleration
inline constexpr std::uint16_t kDigitalOutputs = 0x60FE;  ///< :01 UNSIGNED32 physical outputs (bits 16..31 manufacturer's)
inline constexpr std::uint16_t kDigitalInputs = 0x60FD;   ///< UNSIGNED32: bit 0 neg. limit, 1 pos. limit, 2 home
inline constexpr std::uint16_t kInterpolationPeriod = 0x60C2;  ///< :01 UNSIGNED8 value, :02 INTEGER8 index (value x 10^index s)
inline constexpr std::uint16_t kSupportedModes = 0x6502;  ///< UNSIGNED32 supported drive modes
inline constexpr std::uint16_t kTargetTorque = 0x6071;   ///< INTEGER16 CST target torque, per mille of 6076h
inline constexpr std::int8_t kModeCsp = 8;  ///< cyclic synchronous position
inline constexpr std::int8_t kModeCst = 10; ///< cyclic synchronous torque
inline constexpr std::int8_t kModeHoming = 6;
/// 6502h bits (CiA 402): 0 pp, 1 vl, 2 pv, 3 tq, 5 hm, 6 ip, 7 csp, 8 csv, 9 cst.
inline constexpr std::uint32_t kSupportsHoming = 1u << 5;
inline constexpr std::uint32_t kSupportsCsp = 1u << 7;
inline constexpr std::uint32_t kSupportsCst = 1u << 9;
/// 60FDh bits.
inline constexpr std::uint32_t kDiNegLimit = 1u << 0;
inline constexpr std::uint32_t kDiPosLimit = 1u << 1;
inline constexpr std::uint32_t kDiHome = 1u << 2;
inline constexpr std::uint32_t kDeviceTypeProfile = 402;  ///< low 16 bits of 0x1000

enum class State : std::uint8_t {
  not_ready_to_switch_on,
  switch_on_disabled,
  ready_to_switch_on,
  switched_on,
  operation_enabled,
  quick_stop_active,
  fault_reaction_active,
  fault,
};
const char* to_string(State s);

/// Statusword bits.
inline constexpr std::uint16_t kSwReadyToSwitchOn = 1u << 0;
inline constexpr std::uint16_t kSwSwitchedOn = 1u << 1;
inline constexpr std::uint16_t kSwOperationEnabled = 1u << 2;
inline constexpr std::uint16_t kSwFault = 1u << 3;
inline constexpr std::uint16_t kSwVoltageEnabled = 1u << 4;
inline constexpr std::uint16_t kSwQuickStop = 1u << 5;  ///< active low: 0 = quick stop active
inline constexpr std::uint16_t kSwSwitchOnDisabled = 1u << 6;
inline constexpr std::uint16_t kSwWarning = 1u << 7;
inline constexpr std::uint16_t kSwRemote = 1u << 9;
inline constexpr std::uint16_t kSwTargetReached = 1u << 10;
inline constexpr std::uint16_t kSwFollowingError = 1u << 13;  ///< CSP: following error
inline constexpr std::uint16_t kSwHomingAttained = 1u << 12;  ///< homing mode: homing attained
inline constexpr std::uint16_t kSwHomingError = 1u << 13;     ///< homing mode: homing error
/// Controlword bits beside the state commands.
inline constexpr std::uint16_t kCwHomingStart = 1u << 4;  ///< homing mode: 0->1 starts, 1->0 interrupts
inline constexpr std::uint16_t kCwHalt = 1u << 8;

/// State from a statusword (CiA 402 table 30, masks 0x4F / 0x6F).
State decode_statusword(std::uint16_t sw);
/// Canonical statusword bits 0..6 for a state (drive side); other bits are 0.
std::uint16_t encode_state_bits(State s);

/// Controlword commands (CiA 402 table 28; bit 7 = fault reset on a rising edge).
namespace cw {
inline constexpr std::uint16_t kShutdown = 0x0006;
inline constexpr std::uint16_t kSwitchOn = 0x0007;
inline constexpr std::uint16_t kDisableVoltage = 0x0000;
inline constexpr std::uint16_t kQuickStop = 0x0002;
inline constexpr std::uint16_t kDisableOperation = 0x0007;
inline constexpr std::uint16_t kEnableOperation = 0x000F;
inline constexpr std::uint16_t kFaultReset = 0x0080;
}  // namespace cw

/// What the master wants the drive to be.
enum class Target : std::uint8_t {
  disabled,    ///< powered down (shutdown / disable voltage)
  enabled,     ///< operation enabled
  quick_stop,  ///< controlled stop with the drive's quick-stop ramp, then hold in quick stop active
};

/// Master side, real-time: the controlword that moves a drive in `state` one
/// step towards `target`. `reset_phase` alternates each cycle while in fault so
/// bit 7 produces the rising edge the drive needs (0x00 then 0x80).
std::uint16_t next_controlword(State state, Target target, bool reset_phase);

/// True when `state` is where `target` wants it (enabled: operation_enabled;
/// disabled: switch_on_disabled or ready_to_switch_on or switched_on;
/// quick_stop: quick_stop_active or switch_on_disabled).
bool reached(State state, Target target);

/// Drive side: the state after the drive sees controlword `cw` (previous
/// controlword `prev_cw`, for the fault-reset edge) in `state`. Transitions
/// 2..12, 15, 16 of CiA 402 figure 13; automatic ones (0, 1, 13, 14) are the
/// drive's business. `*transition` receives the transition number or 0.
State apply_controlword(State state, std::uint16_t cw, std::uint16_t prev_cw, int* transition = nullptr);

}  // namespace servoarm::hal::cia402
