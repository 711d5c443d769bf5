// SPDX-License-Identifier: Apache-2.0
#pragma once
// The MIT-mode frame of quasi-direct-drive CAN actuators (docs/servo-bus.md#mit-mode-actuators):
// pure codecs, no I/O, no heap, no throw (real-time safe), and the motor profiles.
//
// The command frame (classic CAN, 8 bytes, big-endian bit fields) carries the five values of the
// drive's own control law  tau = kp (p_des - q) + kd (v_des - qd) + tau_ff:
//   p_des 16 bits | v_des 12 bits | kp 12 bits | kd 12 bits | tau_ff 12 bits
// each mapped linearly onto [min, max] of the motor's ranges (p, v, t symmetric +-P_MAX,
// +-V_MAX, +-T_MAX; kp in [0, KP_MAX], kd in [0, KD_MAX]); u = 0 is min, u = 2^bits - 1 is max.
// Values beyond a range are clamped to it; a value is rounded to the nearest code.
// Special frames on the command id: FF FF FF FF FF FF FF xx with xx = FC enable, FD disable,
// FE save zero (the present position becomes 0), FB clear error.
//
// Feedback (the drive answers every command frame with one):
//   Damiao:    id = MST_ID; byte 0 = error nibble << 4 | motor id & 0x0F; p 16 | v 12 | t 12;
//              byte 6 MOSFET temperature, byte 7 rotor temperature (deg C).
//   CubeMars:  byte 0 = motor id; p 16 | v 12 | current as torque 12; byte 6 temperature (deg C),
//              byte 7 error code.
//   Robstride: id = master id; byte 0 = motor id; p 16 | v 12 | t 12; bytes 6-7 temperature x 10.
// Damiao's other modes: position-velocity on 0x100 + id (position, velocity limit: float32 LE),
// velocity on 0x200 + id (float32 LE).
// Damiao registers through id 0x7FF: [id lo, id hi, 0x33 read | 0x55 write | 0xAA save, RID,
// value (4 bytes little-endian: uint32 or float32 by register)]; the reply comes on MST_ID with
// the same first four bytes and the value. Refresh (a feedback frame, nothing changes):
// [id lo, id hi, 0xCC, 0].
//
// Sources (facts only; no code taken from them):
//  - Damiao DM-J4310-2EC V1.1 manual (gitee.com/kit-miao/DM-J4310-2EC): MIT frame layout, special
//    frames, feedback layout and error codes (0 disabled, 1 enabled, 8 over-voltage, 9 under-voltage,
//    A over-current, B MOSFET over-temperature, C rotor over-temperature, D communication lost,
//    E overload), register protocol on 0x7FF, CTRL_MODE values (1 MIT, 2 position-velocity,
//    3 velocity, 4 torque-position), TIMEOUT in units of 50 us.
//  - Seeed Studio wiki "Damiao Series Motors" (specification table): reduction ratio, torque
//    constant and default PMAX/VMAX/TMAX of DM-J4310-2EC V1.1, DM-J4340-2EC, DM-J8006-2EC V1.1;
//    OT (coil over-temperature) recommended at most 100 deg C.
//  - enactic/openarm_can (dm_motor_constants) and lerobot's Damiao bus tables: the same ranges,
//    except that openarm_can gives DM-J4340 V_MAX 10 rad/s where the Damiao table gives 8 (the
//    bring-up reads PMAX/VMAX/TMAX from the motor, so the motor's own value is what is used).
//  - CubeMars AK Series Actuator Driver Manual V1.0.8, "MIT power mode": frame layouts and the
//    AK80-9 ranges (P +-12.5 rad, V +-50 rad/s, T +-18 N m, KP 0..500, KD 0..5), gear ratio 9:1,
//    torque constant 0.091 N m/A (motor side).
//  - Robstride RS00 manual (MIT protocol, standard frames): ranges P +-12.57 rad, V +-33 rad/s,
//    T +-14 N m, KP 0..500, KD 0..5, 10:1 reduction, over-temperature at 145 deg C, temperature
//    x 10 in bytes 6-7.
#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>

#include "servoarm/hal/can_frame.hpp"

namespace servoarm::hal::mit {

/// Which vendor's variant of the frame (feedback layout, registers).
enum class Vendor : std::uint8_t { damiao, cubemars, robstride };
const char* to_string(Vendor v);

/// One motor model: the ranges its MIT frame maps onto and what the firmware needs about it.
struct MotorProfile {
  const char* name;        ///< as drive.motor writes it ("DM-J4340")
  Vendor vendor;
  double p_max;            ///< rad, output side: p in [-p_max, p_max]
  double v_max;            ///< rad/s
  double t_max;            ///< N m
  double kp_max;           ///< N m / rad: kp in [0, kp_max]
  double kd_max;           ///< N m s / rad
  double gear_ratio;       ///< the actuator's own reduction (rotor turns per output turn)
  double torque_constant;  ///< N m / A, output side (Damiao table) or motor side (CubeMars); 0 = not published
  double temp_cutoff;      ///< deg C where the motor itself stops (its over-temperature protection)
  const char* source;      ///< where the figures come from
};

/// Every profile armfw knows.
std::span<const MotorProfile> motor_profiles();
/// The profile named `name` (exact, case-insensitive), or nullptr.
const MotorProfile* find_profile(std::string_view name);

/// Value -> code: clamped to [min, max], rounded to the nearest of 2^bits codes. NaN gives min's code
/// (callers refuse NaN first).
std::uint32_t to_code(double x, double min, double max, int bits);
/// Code -> value.
double from_code(std::uint32_t u, double min, double max, int bits);

/// The ranges the frame maps onto (a profile's, or what the motor's registers read).
struct Ranges {
  double p_max = 12.5, v_max = 30, t_max = 10, kp_max = 500, kd_max = 5;
};
Ranges ranges_of(const MotorProfile& p);

struct Command {
  double p = 0, v = 0, kp = 0, kd = 0, t = 0;
};

/// The 8-byte MIT command frame on `can_id`. False (out untouched) when a value is not finite.
bool pack_command(const Ranges& r, std::uint32_t can_id, const Command& c, CanFrame& out);
/// The command a frame carries (what a drive decodes). False unless it is an 8-byte data frame
/// that is not a special frame.
bool unpack_command(const Ranges& r, const CanFrame& f, Command& out);

/// Damiao position-velocity mode (CTRL_MODE 2): id 0x100 + motor id, 8 bytes: position (rad) and
/// the velocity limit of the move (rad/s), each float32 little-endian. False for a value that is
/// not finite.
bool pack_pos_vel(std::uint16_t motor_id, double p, double v, CanFrame& out);
/// Damiao velocity mode (CTRL_MODE 3): id 0x200 + motor id, 4 bytes: velocity (rad/s), float32
/// little-endian.
bool pack_vel(std::uint16_t motor_id, double v, CanFrame& out);
/// What a position-velocity / velocity frame carries (`motor_id` from its id). False otherwise.
bool unpack_pos_vel(const CanFrame& f, std::uint16_t& motor_id, double& p, double& v);
bool unpack_vel(const CanFrame& f, std::uint16_t& motor_id, double& v);

enum class Special : std::uint8_t { enable = 0xFC, disable = 0xFD, save_zero = 0xFE, clear_error = 0xFB };
const char* to_string(Special s);
CanFrame special_frame(std::uint32_t can_id, Special s);
/// True (and `s` set) when `f` is one of the special frames.
bool is_special(const CanFrame& f, Special& s);

/// What one feedback frame says.
struct Feedback {
  std::uint8_t id = 0;        ///< motor id as the frame carries it (Damiao: its low 4 bits)
  std::uint8_t error = 0;     ///< Damiao error nibble / CubeMars error code; 0 or 1 = no fault
  double p = 0, v = 0, t = 0; ///< rad (wrapped into +-p_max), rad/s, N m
  double t_mos = 0;           ///< deg C (MOSFET; CubeMars/Robstride: the one temperature)
  double t_rotor = 0;         ///< deg C (Damiao rotor; others: the one temperature)
};
bool decode_feedback(Vendor v, const Ranges& r, const CanFrame& f, Feedback& out);
/// The feedback frame a drive sends (virtual drives, tests).
CanFrame encode_feedback(Vendor v, const Ranges& r, std::uint32_t feedback_id, const Feedback& fb);

/// Damiao feedback error nibble.
enum class DamiaoError : std::uint8_t {
  disabled = 0x0,
  enabled = 0x1,
  over_voltage = 0x8,
  under_voltage = 0x9,
  over_current = 0xA,
  mos_over_temperature = 0xB,
  rotor_over_temperature = 0xC,
  communication_lost = 0xD,
  overload = 0xE,
};
/// "under-voltage", ..., or "unknown error" for other codes.
const char* damiao_error_name(std::uint8_t code);
/// True for a nibble that means a latched fault (8..E and anything else not 0/1).
inline bool damiao_is_fault(std::uint8_t code) { return code > 1; }

// ---- Damiao registers ---------------------------------------------------------------------
inline constexpr std::uint32_t kRegisterId = 0x7FF;
enum class RegCmd : std::uint8_t { read = 0x33, write = 0x55, save = 0xAA, refresh = 0xCC };
/// The registers the bring-up uses (RID).
enum class Reg : std::uint8_t {
  uv_value = 0,   ///< under-voltage threshold, V (float)
  kt_value = 1,   ///< torque constant (float)
  ot_value = 2,   ///< over-temperature threshold, deg C (float)
  oc_value = 3,   ///< over-current (float)
  acc = 4,
  dec = 5,
  max_spd = 6,
  mst_id = 7,     ///< the id the motor answers on (uint32)
  esc_id = 8,     ///< the motor's own command id (uint32)
  timeout = 9,    ///< CAN timeout, 50 us units, 0 = off (uint32)
  ctrl_mode = 10, ///< 1 MIT, 2 position-velocity, 3 velocity, 4 torque-position (uint32)
  damp = 11,
  inertia = 12,
  hw_ver = 13,
  sw_ver = 14,
  sn = 15,
  npp = 16,
  rs = 17,
  ls = 18,
  flux = 19,
  gr = 20,        ///< gear ratio (float)
  pmax = 21,      ///< P_MAX, rad (float)
  vmax = 22,      ///< V_MAX, rad/s (float)
  tmax = 23,      ///< T_MAX, N m (float)
  i_bw = 24,
  kp_asr = 25,
  ki_asr = 26,
  kp_apr = 27,
  ki_apr = 28,
  ov_value = 29,
  gref = 30,
  deta = 31,
  v_bw = 32,
  iq_c1 = 33,
  vl_c1 = 34,
  can_br = 35,    ///< bitrate setting (uint32)
  sub_ver = 36,
};
inline constexpr std::uint8_t kLastReg = 36;
/// True for a register whose value is a uint32 (7..10, 13..16, 35, 36), false for a float32.
bool reg_is_uint(std::uint8_t rid);
/// Name as the Damiao manual writes it ("CTRL_MODE"), "?" for an unknown RID.
const char* reg_name(std::uint8_t rid);
/// CTRL_MODE value names ("MIT", "position-velocity", ...), "unknown" otherwise.
const char* ctrl_mode_name(std::uint32_t mode);
inline constexpr std::uint32_t kModeMit = 1;
inline constexpr std::uint32_t kTimeoutUnitNs = 50'000;  ///< one TIMEOUT count

CanFrame reg_read(std::uint16_t motor_id, std::uint8_t rid);
CanFrame reg_write_u32(std::uint16_t motor_id, std::uint8_t rid, std::uint32_t value);
CanFrame reg_write_f32(std::uint16_t motor_id, std::uint8_t rid, float value);
CanFrame reg_save(std::uint16_t motor_id);
CanFrame refresh_frame(std::uint16_t motor_id);

/// A register request (on 0x7FF) or reply (on MST_ID).
struct RegMessage {
  std::uint16_t motor_id = 0;
  RegCmd cmd = RegCmd::read;
  std::uint8_t rid = 0;
  std::uint32_t raw = 0;  ///< the 4 value bytes (little-endian); as_float() for float registers
  float as_float() const;
};
/// False unless `f` is 8 bytes (4 for read/save/refresh) with a known command byte.
bool decode_register(const CanFrame& f, RegMessage& out);
/// A register reply (what a Damiao motor sends on its MST_ID).
CanFrame reg_reply(std::uint32_t master_id, const RegMessage& m);

// ---- Multi-turn position -------------------------------------------------------------------
/// The true position of a joint from the +-p_max wrapped value the frame carries: each sample
/// moves by the shortest way round (|step| < p_max between samples), so a joint that turns past
/// p_max keeps counting. Real time.
class Unwrap {
 public:
  /// The first sample is taken as it is.
  double update(double wrapped, double p_max);
  /// Whole wraps so far (true = wrapped + turns() * 2 p_max).
  std::int32_t turns() const { return turns_; }
  bool primed() const { return primed_; }
  void reset() { *this = Unwrap{}; }

 private:
  bool primed_ = false;
  double last_ = 0;
  std::int32_t turns_ = 0;
};

}  // namespace servoarm::hal::mit
