// SPDX-License-Identifier: Apache-2.0
#pragma once
// ISO-TP (ISO 15765-2) transport protocol over any CanBus: messages of 1..4095
// bytes in classic CAN frames (8 bytes), normal addressing, 11-bit (or 29-bit)
// ids; one endpoint = one (tx id, rx id) pair, full duplex (one message being
// sent and one being received at the same time).
//
//   single frame      0x0L d1..dL                 L = 1..7
//   first frame       0x1H LL d1..d6              FF_DL = 0xHLL, 8..4095
//                     0x10 00 L3 L2 L1 L0 ...     escape: 32-bit FF_DL (> 4095: refused, overflow)
//   consecutive frame 0x2N d1..d7                 N = sequence number 1, 2, .. 15, 0, 1, ..
//   flow control      0x3S BS STmin               S: 0 continue, 1 wait, 2 overflow
//
// Why hand-written: Linux has ISO-TP in the kernel (can-isotp, CAN_ISOTP sockets,
// used by can-utils isotpsend / isotprecv), but only on SocketCAN; the in-process
// SimBus (armfw --sim, the tests) and the control loop's CanBus abstraction need
// it in user space over the CanBus interface, and Debian packages no C/C++
// ISO-TP library. The kernel's implementation is the independent reference this
// one is tested against (tests/vcan/s5_can_console.sh drives armfw with
// isotpsend / isotprecv); tests/hal/test_isotp.cpp checks the byte layouts
// written out from the standard.
//
// Heap-free: both message buffers are members (2 x 4095 bytes). Not thread-safe:
// one thread drives an endpoint (on_frame / poll / send), e.g. with service().
// Protocol errors never crash and never block: they end the message in progress
// with an IsoTpResult (the ISO N_Result names) and the endpoint is ready again.
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

#include "servoarm/hal/can_bus.hpp"
#include "servoarm/hal/clock.hpp"

namespace servoarm::hal {

/// Outcome of a message or of a call. 0 ok, > 0 nothing to report / retry, < 0 failed
/// (the ISO 15765-2 N_Result values where there is one).
enum class IsoTpResult : std::int8_t {
  ok = 0,               ///< message complete (rx) / on the bus (tx) / send accepted
  none = 1,             ///< nothing happened in this direction
  busy = 2,             ///< send() refused: the previous message is still being sent
  timeout_a = -1,       ///< N_TIMEOUT_A: a frame could not be handed to the bus within N_As/N_Ar
  timeout_bs = -2,      ///< N_TIMEOUT_Bs: no flow control frame within N_Bs
  timeout_cr = -3,      ///< N_TIMEOUT_Cr: no consecutive frame within N_Cr
  wrong_sn = -4,        ///< N_WRONG_SN: consecutive frame with an unexpected sequence number
  invalid_fs = -5,      ///< N_INVALID_FS: flow control with a reserved flow status
  unexp_pdu = -6,       ///< N_UNEXP_PDU: a new single/first frame interrupted a reception
  wft_ovrn = -7,        ///< N_WFT_OVRN: more flow-control WAIT frames than max_wft
  buffer_overflow = -8, ///< N_BUFFER_OVFLW: message longer than the receive limit (rx), peer said overflow (tx)
  bus_error = -9,       ///< N_ERROR: the CanBus refused a frame (bus-off, interface down, io error)
  invalid_length = -10, ///< send(): length 0 or above 4095
  malformed = -11,      ///< frame ignored as ISO 15765-2 requires (bad PCI type, length); reception continues
};
const char* to_string(IsoTpResult r);

struct IsoTpConfig {
  std::uint32_t tx_id = 0x7E8;     ///< id of the frames this endpoint sends (SF/FF/CF, and FC of its receptions)
  std::uint32_t rx_id = 0x7E0;     ///< id of the frames it receives (SF/FF/CF, and FC of its transmissions)
  bool extended = false;           ///< 29-bit ids
  bool padding = false;            ///< send every frame with 8 bytes, unused ones = pad_byte
  std::uint8_t pad_byte = 0xCC;
  std::uint8_t block_size = 0;     ///< BS announced in our flow control (0 = no further FC)
  std::uint8_t st_min = 0;         ///< STmin announced, ISO encoding (0x00-0x7F ms, 0xF1-0xF9 100-900 us)
  std::uint8_t max_wft = 8;        ///< flow-control WAIT frames accepted in a row
  std::size_t rx_limit = 4095;     ///< longest message accepted (<= 4095); longer: FC overflow
  Duration n_as = 1000 * kMillisecond;  ///< N_As / N_Ar: time to get one frame onto the bus
  Duration n_bs = 1000 * kMillisecond;  ///< N_Bs: wait for a flow control frame
  Duration n_cr = 1000 * kMillisecond;  ///< N_Cr: wait for the next consecutive frame
};

/// What one on_frame() / poll() / service() call produced.
struct IsoTpEvent {
  IsoTpResult rx = IsoTpResult::none;  ///< ok: rx_message() holds a complete message (until the next on_frame())
  IsoTpResult tx = IsoTpResult::none;  ///< ok: the message given to send() is on the bus; < 0: it failed
  bool any() const { return rx != IsoTpResult::none || tx != IsoTpResult::none; }
};

struct IsoTpStats {
  std::uint64_t rx_messages = 0, tx_messages = 0;
  std::uint64_t rx_errors = 0, tx_errors = 0;  ///< messages ended by an error
  std::uint64_t ignored = 0;                   ///< malformed frames ignored
};

class IsoTpEndpoint {
 public:
  static constexpr std::size_t kMaxMessage = 4095;
  static constexpr TimePoint kNever = INT64_MAX;

  /// Set-up. The caller sets the bus's receive filter (rx_filter()) if it wants one.
  IsoTpEndpoint(CanBus& bus, Clock& clock, const IsoTpConfig& cfg);

  /// Start sending a message (copied). A single frame goes out now (sending() is false
  /// again when it did); longer messages continue in on_frame()/poll(), whose event
  /// reports the end (tx ok or the error). @retval ok, busy, invalid_length, bus_error (nothing sent)
  IsoTpResult send(std::span<const std::uint8_t> msg);
  /// Feed one received frame (any id: frames not on rx_id are ignored silently).
  IsoTpEvent on_frame(const CanFrame& f);
  /// Timers and pending consecutive frames. Call by next_deadline() at the latest.
  IsoTpEvent poll();
  /// Earliest time poll() has something to do (kNever when idle).
  TimePoint next_deadline() const;
  /// Drive the endpoint on its bus (receive with deadlines, on_frame, poll) until
  /// something happened or `deadline` passed. Waits in CanBus::receive only.
  IsoTpEvent service(TimePoint deadline);

  bool sending() const { return tx_state_ != TxState::idle; }
  bool receiving() const { return rx_state_ == RxState::receiving; }
  std::span<const std::uint8_t> rx_message() const { return {rx_buf_.data(), rx_len_}; }
  const IsoTpStats& stats() const { return stats_; }
  const IsoTpConfig& config() const { return cfg_; }
  /// Filter passing exactly rx_id in the configured id format.
  CanFilter rx_filter() const { return CanFilter{cfg_.rx_id, cfg_.extended ? CanFrame::kMaxExtId : CanFrame::kMaxStdId, cfg_.extended}; }
  /// Last CanBus status of a refused frame (for messages).
  Status last_bus_status() const { return last_bus_; }

  /// STmin byte -> nanoseconds (reserved values count as 127 ms, as ISO 15765-2 says).
  static Duration st_min_ns(std::uint8_t st);

 private:
  enum class TxState : std::uint8_t { idle, first, wait_fc, send_cf };
  enum class RxState : std::uint8_t { idle, receiving };
  CanFrame frame(std::uint8_t n) const;
  Status put(const CanFrame& f);
  void tx_end(IsoTpResult r);
  void rx_end(IsoTpResult r);
  void handle_fc(const CanFrame& f, TimePoint now);
  void send_fc(std::uint8_t fs, TimePoint now);
  void tx_pump(TimePoint now);

  CanBus& bus_;
  Clock& clock_;
  IsoTpConfig cfg_;
  IsoTpEvent ev_;
  IsoTpStats stats_;
  Status last_bus_ = Status::ok;

  // transmit side
  TxState tx_state_ = TxState::idle;
  std::array<std::uint8_t, kMaxMessage> tx_buf_{};
  std::size_t tx_len_ = 0, tx_off_ = 0;
  std::uint8_t tx_sn_ = 0;
  std::uint8_t tx_bs_ = 0, tx_block_ = 0, tx_wft_ = 0;
  Duration tx_stmin_ = 0;
  TimePoint tx_next_ = 0;       ///< send_cf: next CF not before; first/send_cf after would_block: retry
  TimePoint tx_deadline_ = 0;   ///< wait_fc: N_Bs; first/send_cf: N_As for the frame being retried

  // receive side
  RxState rx_state_ = RxState::idle;
  std::array<std::uint8_t, kMaxMessage> rx_buf_{};
  std::size_t rx_len_ = 0, rx_expect_ = 0, rx_off_ = 0;
  std::uint8_t rx_sn_ = 0, rx_block_ = 0;
  TimePoint rx_deadline_ = 0;   ///< N_Cr
  bool fc_pending_ = false;     ///< an FC (CTS) could not be sent yet (would_block)
  TimePoint fc_deadline_ = 0;   ///< N_Ar for it
};

}  // namespace servoarm::hal
