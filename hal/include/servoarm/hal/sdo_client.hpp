#pragma once
// SDO client (CiA 301): expedited and segmented upload/download.
//
// Set-up code: every call blocks until the answer arrives or a deadline
// (now + timeout) passes; on timeout it sends an abort (0x05040000) to the
// server. Frames that are not this transfer's answer (heartbeats, EMCY, ...)
// are handed to the optional `other` sink so nothing is lost while waiting.
#include <cstddef>
#include <cstdint>

#include "servoarm/hal/can_bus.hpp"
#include "servoarm/hal/clock.hpp"

namespace servoarm::hal {

/// Callback for frames received while waiting (plain function + context: no allocation).
struct FrameSink {
  void (*fn)(void* ctx, const CanFrame& f) = nullptr;
  void* ctx = nullptr;
  void operator()(const CanFrame& f) const { if (fn) fn(ctx, f); }
};

struct SdoResult {
  Status status = Status::ok;
  std::uint32_t abort_code = 0;  ///< non-zero when status == sdo_abort (ours or the server's)
  std::size_t size = 0;          ///< bytes uploaded
};

class SdoClient {
 public:
  SdoClient(CanBus& bus, Clock& clock, Duration timeout = 100 * kMillisecond, FrameSink other = {})
      : bus_(bus), clock_(clock), timeout_(timeout), other_(other) {}

  void set_timeout(Duration t) { timeout_ = t; }
  void set_sink(FrameSink s) { other_ = s; }

  /// Set-up: write `len` bytes to node:index:sub (expedited if len <= 4, else segmented).
  /// @return status ok / timeout (abort sent) / sdo_abort (server abort; abort_code set) /
  ///         protocol_error (unexpected answer; abort sent) / invalid_argument / bus errors
  SdoResult download(std::uint8_t node, std::uint16_t index, std::uint8_t sub, const std::uint8_t* data, std::size_t len);
  /// Set-up: read node:index:sub into buf (capacity cap). A larger object aborts
  /// with 0x05040005 (out of memory) and returns sdo_abort.
  SdoResult upload(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::uint8_t* buf, std::size_t cap);

  SdoResult write_u8(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::uint8_t v);
  SdoResult write_u16(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::uint16_t v);
  SdoResult write_u32(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::uint32_t v);
  /// Reads 1..4 bytes and zero-extends.
  SdoResult read_u32(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::uint32_t& v);

 private:
  Status wait(std::uint8_t node, CanFrame& out, TimePoint deadline);
  SdoResult fail_abort(std::uint8_t node, std::uint16_t index, std::uint8_t sub, Status st, std::uint32_t code);

  CanBus& bus_;
  Clock& clock_;
  Duration timeout_;
  FrameSink other_;
};

}  // namespace servoarm::hal
