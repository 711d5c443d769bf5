// SPDX-License-Identifier: Apache-2.0
#pragma once
// Linux SocketCAN backend (CAN_RAW).
//
// Set-up: open(iface) creates a non-blocking raw socket, enables error frames
// (CAN_RAW_ERR_FILTER: bus-off, controller, restarted, ...), kernel timestamps
// (SO_TIMESTAMPNS, else SO_TIMESTAMP, else none: see RxTimestamps), the drop
// counter (SO_RXQ_OVFL), sizes SO_RCVBUF for bursts and, on request, CAN FD
// after checking the interface MTU.
// Real-time: send()/receive() use only the fd and fixed members; receive waits
// with ppoll() up to an absolute CLOCK_MONOTONIC deadline. No allocation after open.
// When the interface goes down or vanishes (ENETDOWN/ENODEV/ENXIO, POLLERR) the
// calls return interface_down; a backend opened by name then reopens the socket
// once the interface exists and is up again (IFF_UP; checked at most every
// `reopen_interval`, the first time at once) and counts it in stats().reopens.
// Bus-off is seen through error frames (stats().state == bus_off, send() -> bus_off)
// until the kernel restarts the controller (restart-ms) and reports CAN_ERR_RESTARTED.
#include <cstdint>

#include "servoarm/hal/can_bus.hpp"
#include "servoarm/hal/clock.hpp"

namespace servoarm::hal {

/// Where CanFrame::rx_time comes from (all on CLOCK_MONOTONIC).
enum class RxTimestamps : std::uint8_t {
  kernel_ns = 0,  ///< SO_TIMESTAMPNS: when the frame reached the socket (ns)
  kernel_us = 1,  ///< SO_TIMESTAMP: the same with µs resolution (kernels/emulators without
                  ///< SO_TIMESTAMPNS, e.g. qemu-user 7.2 refuses it with ENOPROTOOPT)
  receive = 2,    ///< no kernel stamp: the time receive() read the frame (later by the
                  ///< time the frame waited in the socket queue)
};
const char* to_string(RxTimestamps t);

struct SocketCanOptions {
  int rcvbuf_bytes = 256 * 1024;   ///< SO_RCVBUF request (kernel doubles it)
  bool enable_fd = false;          ///< CAN FD (fails with invalid_argument if MTU says no)
  bool recv_own = false;           ///< CAN_RAW_RECV_OWN_MSGS: see our own frames
  bool auto_reopen = true;         ///< reopen after interface-down (named iface only)
  Duration reopen_interval = 100 * kMillisecond;
  bool kernel_timestamps = true;   ///< false: rx_time = receive time (RxTimestamps::receive)
};

class SocketCanBus final : public CanBus {
 public:
  /// Unopened bus; call open().
  SocketCanBus() = default;
  /// Test/adoption constructor: take ownership of an already-open fd (a CAN_RAW
  /// socket, or a SOCK_SEQPACKET socketpair end carrying struct can_frame /
  /// canfd_frame bytes). Made non-blocking; no CAN socket options are set.
  explicit SocketCanBus(int fd, const SocketCanOptions& opt = {});
  ~SocketCanBus() override;
  SocketCanBus(const SocketCanBus&) = delete;
  SocketCanBus& operator=(const SocketCanBus&) = delete;

  /// Set-up: open a raw socket bound to `iface` (e.g. "vcan0"; names longer
  /// than IFNAMSIZ-1 are rejected, never truncated).
  /// @retval ok, invalid_argument (bad name / FD unsupported), interface_down (no such iface),
  ///         io_error (socket() failed, e.g. kernel without CAN; message() tells)
  Status open(const char* iface, const SocketCanOptions& opt = {});
  void close();
  bool is_open() const { return fd_ >= 0; }

  Status send(const CanFrame& frame) override;
  Status receive(CanFrame& out, TimePoint deadline) override;
  Status set_filters(std::span<const CanFilter> filters) override;
  BusStats stats() const override { return stats_; }

  /// Last OS error text ("socket(PF_CAN): Address family not supported ..."); static storage.
  const char* message() const { return msg_; }
  int fd() const { return fd_; }
  /// Source of rx_time for frames from the current socket (decided at open / adoption).
  RxTimestamps rx_timestamps() const { return ts_; }
  /// Real-time: interface-down events seen (each ENETDOWN/ENODEV/ENXIO/POLLERR episode
  /// counts once, until the next successful reopen).
  std::uint64_t interface_downs() const { return downs_; }
  /// Real-time: true from an interface-down until a reopen succeeded (for ever on an adopted fd).
  bool is_down() const { return down_; }
  /// What reported the current (or last) interface-down episode, e.g.
  /// "vcan0: recvmsg(CAN): Network is down"; message() moves on (reopen attempts).
  const char* down_reason() const { return down_msg_; }
  /// Real-time: true while the interface is down and a reopen is pending.
  bool reopen_pending() const { return need_reopen_; }

  /// Decode a controller error frame (id has CAN_ERR_* class bits, data per
  /// linux/can/error.h) into a new error state and overrun count. Pure; exposed for tests.
  static ErrorState decode_error_frame(const CanFrame& f, ErrorState previous, std::uint64_t* overruns);

 private:
  Status fail(Status s, const char* what, int err);
  Status open_socket(bool require_up);
  void enable_timestamps(int fd);
  Status maybe_reopen();
  Status down(const char* what, int err);  ///< record an interface-down episode
  Status apply_filters();

  int fd_ = -1;
  bool named_ = false;
  bool adopted_ = false;
  char iface_[16] = {};
  SocketCanOptions opt_{};
  MonotonicClock clock_;
  TimePoint next_reopen_ = 0;
  bool need_reopen_ = false;
  bool down_ = false;
  std::uint64_t downs_ = 0;
  RxTimestamps ts_ = RxTimestamps::receive;
  std::uint32_t last_drop_count_ = 0;
  CanFilter filters_[kMaxFilters];
  std::size_t n_filters_ = 0;
  BusStats stats_;
  char msg_[160] = {};
  char down_msg_[160] = {};
};

}  // namespace servoarm::hal
