// SPDX-License-Identifier: Apache-2.0
#pragma once
// One CAN (or CAN FD) frame, independent of any backend.
#include <array>
#include <cstdint>
#include <cstring>
#include <initializer_list>

#include "servoarm/hal/time.hpp"  // TimePoint (rx_time)

namespace servoarm::hal {

struct CanFrame {
  static constexpr std::uint8_t kMaxClassicLen = 8;
  static constexpr std::uint8_t kMaxFdLen = 64;
  static constexpr std::uint32_t kMaxStdId = 0x7FF;
  static constexpr std::uint32_t kMaxExtId = 0x1FFFFFFF;

  std::uint32_t id = 0;     ///< 11-bit (standard) or 29-bit (extended) identifier, no flag bits
  bool extended = false;    ///< 29-bit identifier
  bool rtr = false;         ///< remote transmission request (classic CAN only)
  bool error = false;       ///< error frame reported by the controller (id = error class bits)
  bool fd = false;          ///< CAN FD frame (len up to 64)
  bool brs = false;         ///< CAN FD bit-rate switch
  std::uint8_t len = 0;     ///< payload length (DLC decoded): 0..8 classic, FD lengths up to 64
  TimePoint rx_time = 0;    ///< CLOCK_MONOTONIC time the frame arrived (SocketCAN: the kernel's
                            ///< socket timestamp, moved onto CLOCK_MONOTONIC); 0 for tx
  std::array<std::uint8_t, kMaxFdLen> data{};

  /// Classic data frame with a standard id. Real-time safe (no allocation).
  static CanFrame make(std::uint32_t id, std::initializer_list<std::uint8_t> bytes) {
    CanFrame f;
    f.id = id;
    std::uint8_t n = 0;
    for (std::uint8_t b : bytes) {
      if (n < kMaxFdLen) f.data[n] = b;
      ++n;
    }
    f.len = n > kMaxFdLen ? kMaxFdLen : n;
    if (n > kMaxClassicLen) f.fd = true;
    return f;
  }

  /// True for a length a CAN FD frame can carry (0..8, 12, 16, 20, 24, 32, 48, 64).
  static constexpr bool valid_fd_len(std::uint8_t n) {
    return n <= 8 || n == 12 || n == 16 || n == 20 || n == 24 || n == 32 || n == 48 || n == 64;
  }

  /// Frame is sendable: id within range, length legal, no RTR on FD, not an error frame.
  constexpr bool valid() const {
    if (error) return false;
    if (id > (extended ? kMaxExtId : kMaxStdId)) return false;
    if (fd) return !rtr && valid_fd_len(len);
    if (brs) return false;
    return len <= kMaxClassicLen;
  }

  /// Payload equality plus id/flags (rx_time ignored).
  bool same_as(const CanFrame& o) const {
    return id == o.id && extended == o.extended && rtr == o.rtr && error == o.error && fd == o.fd &&
           len == o.len && (rtr || std::memcmp(data.data(), o.data.data(), len) == 0);
  }
};

// Little-endian helpers used by every CANopen codec.
inline void put_u16(std::uint8_t* p, std::uint16_t v) { p[0] = std::uint8_t(v); p[1] = std::uint8_t(v >> 8); }
inline void put_u32(std::uint8_t* p, std::uint32_t v) {
  p[0] = std::uint8_t(v); p[1] = std::uint8_t(v >> 8); p[2] = std::uint8_t(v >> 16); p[3] = std::uint8_t(v >> 24);
}
inline std::uint16_t get_u16(const std::uint8_t* p) { return std::uint16_t(p[0] | (p[1] << 8)); }
inline std::uint32_t get_u32(const std::uint8_t* p) {
  return std::uint32_t(p[0]) | (std::uint32_t(p[1]) << 8) | (std::uint32_t(p[2]) << 16) | (std::uint32_t(p[3]) << 24);
}

}  // namespace servoarm::hal
