// SPDX-License-Identifier: Apache-2.0
#pragma once
// CAN bus load: bits of one frame on the wire and the share of the bus the cyclic
// CiA 402 (and MIT-mode) traffic of one control cycle takes. Pure functions, no I/O, no allocation.
//
// Frame lengths follow ISO 11898-1 with worst-case bit stuffing, as Linux's
// include/linux/can/length.h (can_frame_bits(), v6.5) counts them:
//   classical, 11-bit id, n data bytes: SOF 1, id 11, RTR 1, IDE 1, r0 1, DLC 4, data 8n,
//     CRC 15, CRC delimiter 1 (35 + 8n bits that are stuffed), ACK 2, EOF 7, intermission 3:
//     47 + 8n bits before stuffing (111 for 8 bytes);
//   worst-case stuffing: after the first bit, one stuff bit every 4 bits of the stuffed part:
//     floor((L - 1) / 4) for L stuffed bits. For a classical 11-bit frame this is
//     floor((34 + 8n - 1) / 4) = 2n + 8 (24 for 8 bytes: 135 bits in all), the term of
//     R. I. Davis, A. Burns, R. J. Bril, J. J. Lukkien, "Controller Area Network (CAN)
//     schedulability analysis: Refuted, revisited and revised", Real-Time Systems 35(3),
//     2007, equation (2), with g = 34 (11-bit ids) or 54 (29-bit ids).
//   CAN FD: header (SOF .. DLC, ESI included) 22 bits (41 with a 29-bit id) and the data are
//     stuffed dynamically; the CRC field has fixed stuff bits: stuff count 4 + CRC 17 + delimiter 1
//     + 6 fixed stuff bits = 28 bits up to 16 data bytes, with CRC 21 and 7 fixed stuff bits
//     33 bits above; then ACK 2, EOF 7, intermission 3. With bit rate switching the bits from
//     ESI to the CRC sequence run at the data bit rate, the rest (arbitration up to BRS and its
//     stuff bits, CRC delimiter, ACK, EOF, intermission) at the nominal one.
#include <cstddef>
#include <cstdint>

namespace servoarm::hal {

/// Bits of one frame: `nominal` at the nominal bit rate, `data` at the data bit rate (CAN FD
/// with bit rate switching; 0 otherwise). Intermission included: the time from one frame's
/// start of frame to the next one's on a busy bus.
struct FrameBits {
  int nominal = 0;
  int data = 0;
  int total() const { return nominal + data; }
};

/// The frame of `data_len` bytes (classical: 0..8; FD: rounded up to the next FD length,
/// at most 64). `worst_stuffing` false: no dynamic stuff bits (the best case; FD's fixed
/// stuff bits are always counted). `brs`: FD bit rate switch (ignored for classical frames).
FrameBits can_frame_bits(bool fd, bool brs, bool extended, unsigned data_len, bool worst_stuffing = true);

/// Which way a frame goes.
enum class BusDirection : std::uint8_t { to_drives, from_drives };
const char* to_string(BusDirection d);

/// One kind of frame of the cyclic traffic.
struct BusFrameKind {
  const char* name = "";        ///< "SYNC", "RPDO1", "TPDO2", "heartbeat"
  BusDirection direction = BusDirection::to_drives;
  std::uint8_t data_len = 0;    ///< bytes
  double per_second = 0;        ///< frames per second (every drive's together)
};

/// The cyclic CiA 402 traffic the master sets up (docs/servo-bus.md): per joint and cycle
/// RPDO1 and TPDO1, RPDO2 / RPDO3 / TPDO2 where mapped (length 0 = not mapped), one SYNC
/// per cycle, and every drive's heartbeat.
struct BusTraffic {
  double rate_hz = 1000;          ///< SYNC (control) rate
  std::size_t joints = 6;
  std::uint8_t rpdo1_len = 6;     ///< controlword + target position (+ 6060h: 7)
  std::uint8_t rpdo2_len = 0;     ///< 60B1h / 60B2h / 6071h
  std::uint8_t rpdo3_len = 0;     ///< 60FEh:01
  std::size_t rpdo3_joints = 0;   ///< joints with RPDO3
  std::uint8_t tpdo1_len = 6;     ///< statusword + position actual (+ 6061h: 7)
  std::uint8_t tpdo2_len = 0;     ///< 606Ch / 603Fh / 6077h
  double heartbeat_period_s = 0.05;  ///< each drive's heartbeat; 0 = none
  /// MIT-mode motors on the same bus (mit.hpp): per motor and cycle one 8-byte command and one
  /// 8-byte feedback frame, no SYNC and no heartbeat of theirs. `joints` counts the CiA 402
  /// drives only; with none, no SYNC either.
  std::size_t mit_joints = 0;
};

inline constexpr std::size_t kMaxBusFrameKinds = 9;

/// The load of a BusTraffic at a bit rate.
struct BusLoad {
  BusFrameKind kinds[kMaxBusFrameKinds]{};
  FrameBits bits[kMaxBusFrameKinds]{};  ///< of one frame of each kind
  double seconds[kMaxBusFrameKinds]{};  ///< bus time per second each kind takes
  std::size_t count = 0;
  double frames_per_cycle = 0;          ///< every cyclic frame (heartbeats left out)
  double to_drives = 0;                 ///< share of the bus (1 = 100 %)
  double from_drives = 0;
  double total() const { return to_drives + from_drives; }
};

/// The load of `t` at `bitrate` bit/s (> 0). `data_bitrate` > 0: the frames are CAN FD with
/// bit rate switching at that data bit rate; 0: classical CAN frames.
BusLoad bus_load(const BusTraffic& t, double bitrate, double data_bitrate = 0);

}  // namespace servoarm::hal
