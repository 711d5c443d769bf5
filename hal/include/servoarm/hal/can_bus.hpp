// SPDX-License-Identifier: Apache-2.0
#pragma once
// The CAN hardware boundary: one small virtual interface, backends side by side
// (socketcan_bus.hpp: Linux SocketCAN; sim_bus.hpp: in-process bus with vcan semantics).
#include <cstddef>
#include <cstdint>
#include <span>

#include "servoarm/hal/can_frame.hpp"
#include "servoarm/hal/status.hpp"

namespace servoarm::hal {

/// Controller error state (ISO 11898 fault confinement).
enum class ErrorState : std::uint8_t {
  active = 0,   ///< normal operation
  warning = 1,  ///< error counters above 96, still error-active
  passive = 2,  ///< error counters above 127: may not send active error flags
  bus_off = 3,  ///< TEC above 255: controller disconnected from the bus
};
const char* to_string(ErrorState s);

/// Receive filter with SocketCAN semantics: a frame passes when
/// (frame.id & mask) == (id & mask) and its id format equals `extended`.
/// An empty filter list passes every frame. Error frames always pass.
struct CanFilter {
  std::uint32_t id = 0;
  std::uint32_t mask = 0;
  bool extended = false;
  bool matches(const CanFrame& f) const { return f.extended == extended && (f.id & mask) == (id & mask); }
};

/// Counters since open. Monotonic; never reset by reopen.
struct BusStats {
  std::uint64_t tx_frames = 0;    ///< frames accepted for transmission
  std::uint64_t rx_frames = 0;    ///< data/RTR frames delivered to the caller
  std::uint64_t tx_errors = 0;    ///< sends refused (bus-off, down, queue full, io error)
  std::uint64_t error_frames = 0; ///< controller error frames received
  std::uint64_t rx_overruns = 0;  ///< frames lost because a receive queue was full
  std::uint64_t reopens = 0;      ///< times the backend reopened its interface
  ErrorState state = ErrorState::active;
};

/// Abstract CAN bus endpoint.
class CanBus {
 public:
  static constexpr std::size_t kMaxFilters = 16;
  virtual ~CanBus() = default;

  /// Real-time: queue one frame for transmission without blocking.
  /// @retval ok               frame queued
  /// @retval would_block      transmit queue full (frame dropped, counted in tx_errors)
  /// @retval invalid_argument frame.valid() is false
  /// @retval bus_off          controller bus-off
  /// @retval interface_down   interface down (backends may reopen later)
  /// @retval not_open / io_error
  virtual Status send(const CanFrame& frame) = 0;

  /// Real-time: wait for the next frame until `deadline` (absolute, CLOCK_MONOTONIC ns;
  /// a deadline in the past polls). Error frames are returned too (frame.error set) after
  /// updating stats().state, so callers can log them; protocol code skips them.
  /// @retval ok       `out` holds a frame
  /// @retval timeout  nothing arrived before the deadline
  /// @retval interface_down / not_open / io_error
  virtual Status receive(CanFrame& out, TimePoint deadline) = 0;

  /// Set-up: replace the receive filters (at most kMaxFilters; empty = accept all).
  /// @retval ok, capacity, io_error
  virtual Status set_filters(std::span<const CanFilter> filters) = 0;

  /// Real-time: a copy of the counters and the error state.
  virtual BusStats stats() const = 0;
};

}  // namespace servoarm::hal
