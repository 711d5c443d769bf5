// SPDX-License-Identifier: Apache-2.0
#pragma once
// The drive doctor's scan (docs/mit-motors.md#finding-the-motors): what answers on a bus, found
// without any configuration. Set-up code: blocks, bounded by the probes' timeouts.
//
//   CANopen: an expedited SDO upload of 1000h (device type) to every node id in the range, sent
//            as a burst (0x600 + id), answers collected (0x580 + id); each node that answers is
//            asked 1018h:01..03 (vendor id, product code, revision).
//   Damiao:  a register read of CTRL_MODE (0x7FF) to every id in the range, as a burst; the
//            reply's id is the motor's master id; each motor that answers is asked PMAX, VMAX,
//            TMAX, Gr, TIMEOUT and sw_ver, and its model is the profile with that gear ratio and
//            TMAX (mit.hpp).
// A motor at another bitrate or frame format, or in a protocol the scan does not speak, is not
// seen: `armctl drives scan` and `check` (firmware/armctl/src/cli_drives.cpp) say so and what to check.
#include <cstddef>
#include <cstdint>
#include <span>

#include "servoarm/hal/can_bus.hpp"
#include "servoarm/hal/clock.hpp"
#include "servoarm/hal/mit.hpp"

namespace servoarm::hal {

struct ScannedDrive {
  enum class Kind : std::uint8_t { canopen, damiao };
  Kind kind = Kind::canopen;
  std::uint16_t id = 0;           ///< node id / motor id (ESC_ID)
  // CANopen
  std::uint32_t device_type = 0;  ///< 1000h (low 16 bits 402 = a CiA 402 drive)
  std::uint32_t vendor = 0, product = 0, revision = 0;  ///< 1018h:01..03 (0 = not read)
  // Damiao
  std::uint32_t ctrl_mode = 0;
  std::uint16_t master_id = 0;    ///< the id it answered on
  float pmax = 0, vmax = 0, tmax = 0, gear = 0;
  std::uint32_t timeout = 0;      ///< TIMEOUT, 50 us units (0 = off)
  std::uint32_t sw_ver = 0;
  const mit::MotorProfile* model = nullptr;  ///< matched by gear ratio and TMAX; nullptr = none
};

struct ScanOptions {
  std::uint16_t first_id = 1, last_id = 127;
  bool canopen = true, damiao = true;
  Duration window = 50 * kMillisecond;   ///< how long the answers to a burst are collected
  Duration timeout = 50 * kMillisecond;  ///< one follow-up question
  bool fd = false;                       ///< probe with CAN FD frames (Damiao motors set to FD)
};

/// Scans `bus`; fills `out` (CANopen nodes first, then Damiao motors, each by id) and returns how
/// many were found (at most out.size()).
std::size_t scan_drives(CanBus& bus, Clock& clock, const ScanOptions& opt, std::span<ScannedDrive> out);

/// What a drive says about its state now (read_drive_status).
struct DriveStatus {
  bool answered = false;       ///< false: the status query got no answer in opt.timeout
  bool fd = false;             ///< Damiao: the answer came as a CAN FD frame
  std::uint8_t error = 0;      ///< Damiao: the feedback's error nibble; CANopen: 1001h (error register)
  std::uint16_t error_code = 0;  ///< CANopen: 603Fh (0 = none or not read)
  bool has_temperature = false;
  float t_mos = 0, t_rotor = 0;  ///< deg C (Damiao feedback)
  double position = 0;         ///< Damiao: the feedback's position (rad, within +-PMAX)
};

/// Asks one drive the scan found for its state: Damiao, a refresh (0x7FF, 0xCC) answered by a
/// feedback frame (error nibble, MOSFET and rotor temperature), decoded with the ranges its
/// registers read; CANopen, 1001h and 603Fh by SDO. Queries only: nothing is written.
bool read_drive_status(CanBus& bus, Clock& clock, const ScanOptions& opt, const ScannedDrive& d, DriveStatus& out);

/// The status part of a drive's line, e.g. "CAN FD, no error, MOS 31 C, rotor 30 C" or
/// "classic CAN, error under-voltage (9)" or "status: no answer".
void describe_status(const ScannedDrive& d, const DriveStatus& s, char* buf, std::size_t size);

/// One line per drive, e.g. "id 0x01: damiao DM-J4340 (Gr 40, TMAX 28), mode MIT, master 0x011,
/// CAN timeout 100 ms, PMAX 12.5, VMAX 8" (a mode other than MIT and a CAN timeout of 0 say what
/// to change).
void describe_drive(const ScannedDrive& d, char* buf, std::size_t size);

}  // namespace servoarm::hal
