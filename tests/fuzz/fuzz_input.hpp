// SPDX-License-Identifier: Apache-2.0
#pragma once
// Helpers shared by the libFuzzer targets (tests/fuzz): fuzz bytes -> CAN frames, a bus
// that hands the fuzzer's frames to the code under test and swallows what it sends.
#include <cstddef>
#include <cstdint>
#include <deque>

#include "servoarm/hal/can_bus.hpp"
#include "servoarm/hal/can_frame.hpp"

namespace servoarm::fuzz {

/// Reads frames from the fuzz input: [flags][id lo][id hi][len][data...]. flags bit 0
/// extended id, bit 1 RTR, bit 2 FD, bit 3 error frame; the id's high byte is folded
/// into 11 bits for standard frames. `node` (when non-zero) replaces the id's node part
/// with it on most frames, so the decoders see frames addressed to them.
class FrameSource {
 public:
  FrameSource(const std::uint8_t* data, std::size_t size, std::uint8_t node = 0)
      : p_(data), end_(data + size), node_(node) {}
  bool next(hal::CanFrame& f) {
    if (end_ - p_ < 4) return false;
    const std::uint8_t flags = *p_++;
    const std::uint32_t lo = *p_++, hi = *p_++;
    f = hal::CanFrame{};
    f.extended = flags & 1;
    f.rtr = flags & 2;
    f.fd = flags & 4;
    f.error = flags & 8;
    f.id = f.extended ? ((hi << 8 | lo) * 0x9E3779B1u) & hal::CanFrame::kMaxExtId : (hi << 8 | lo) & hal::CanFrame::kMaxStdId;
    if (node_ && !f.extended && !(flags & 0x10)) f.id = (f.id & 0x780) | node_;
    const std::uint8_t max = f.fd ? hal::CanFrame::kMaxFdLen : hal::CanFrame::kMaxClassicLen;
    f.len = static_cast<std::uint8_t>(*p_++ % (max + 1));
    for (std::uint8_t i = 0; i < f.len; ++i) f.data[i] = p_ < end_ ? *p_++ : 0;
    return true;
  }
  bool empty() const { return end_ - p_ < 4; }
  /// One byte of the input for the harness's own choices (0 when used up).
  std::uint8_t byte() { return p_ < end_ ? *p_++ : 0; }

 private:
  const std::uint8_t* p_;
  const std::uint8_t* end_;
  std::uint8_t node_;
};

/// A bus whose receive() returns the queued frames (then timeout), and whose send()
/// accepts everything (counted) or, when `refuse_sends`, reports would_block.
class FuzzBus final : public hal::CanBus {
 public:
  std::deque<hal::CanFrame> rx;
  std::size_t sent = 0;
  bool refuse_sends = false;
  hal::Status send(const hal::CanFrame&) override {
    if (refuse_sends) return hal::Status::would_block;
    ++sent;
    return hal::Status::ok;
  }
  hal::Status receive(hal::CanFrame& out, hal::TimePoint) override {
    if (rx.empty()) return hal::Status::timeout;
    out = rx.front();
    rx.pop_front();
    return hal::Status::ok;
  }
  hal::Status set_filters(std::span<const hal::CanFilter>) override { return hal::Status::ok; }
  hal::BusStats stats() const override { return {}; }
};

}  // namespace servoarm::fuzz
