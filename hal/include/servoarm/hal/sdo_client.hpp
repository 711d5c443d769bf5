// SPDX-License-Identifier: Apache-2.0
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
  /// wait() for the answer to an initiate request for index:sub: an initiate
  /// response or abort naming another object is a late answer to an earlier,
  /// timed-out request (a slow drive), skipped, not taken as this one's.
  Status wait_initiate(std::uint8_t node, std::uint16_t index, std::uint8_t sub, CanFrame& out, TimePoint deadline);
  SdoResult fail_abort(std::uint8_t node, std::uint16_t index, std::uint8_t sub, Status st, std::uint32_t code);

  CanBus& bus_;
  Clock& clock_;
  Duration timeout_;
  FrameSink other_;
};

/// Real-time: one non-blocking expedited SDO transfer (1..4 bytes) to one node. begin_*()
/// sends the request; the owner hands every received SDO answer frame (0x580 + node) to
/// on_frame() and calls poll() each cycle; poll() times the transfer out (and sends the abort
/// 05040000h) when `now` passes the deadline. One transfer outstanding per object (one per
/// node: the SDO server answers one request at a time). No allocation, no blocking.
class SdoTransfer {
 public:
  enum class State : std::uint8_t { idle, pending, done };

  /// @retval ok (sent); bad_state (one is pending); invalid_argument (node, size); bus errors
  Status begin_write(CanBus& bus, std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::uint8_t size,
                     std::uint32_t value, TimePoint now, Duration timeout);
  Status begin_read(CanBus& bus, std::uint8_t node, std::uint16_t index, std::uint8_t sub, TimePoint now,
                    Duration timeout);
  /// True when `f` was this transfer's answer (consumed: state done, result set), or a
  /// late answer (initiate response or abort) naming another object, to an earlier
  /// timed-out request (consumed: still pending).
  bool on_frame(const CanFrame& f);
  /// Times a pending transfer out against `now` (result timeout, abort sent).
  void poll(CanBus& bus, TimePoint now);
  /// done -> idle (the result stays readable).
  void clear() { state_ = State::idle; }

  State state() const { return state_; }
  bool pending() const { return state_ == State::pending; }
  bool done() const { return state_ == State::done; }
  /// ok, timeout, sdo_abort (abort_code()), protocol_error (a command that does not fit).
  Status result() const { return result_; }
  std::uint32_t abort_code() const { return abort_code_; }
  std::uint32_t value() const { return value_; }  ///< read: the value, zero-extended
  std::uint16_t index() const { return index_; }
  std::uint8_t sub() const { return sub_; }

 private:
  State state_ = State::idle;
  bool write_ = false;
  std::uint8_t node_ = 0;
  std::uint16_t index_ = 0;
  std::uint8_t sub_ = 0;
  TimePoint deadline_ = 0;
  Status result_ = Status::ok;
  std::uint32_t abort_code_ = 0;
  std::uint32_t value_ = 0;
};

}  // namespace servoarm::hal
