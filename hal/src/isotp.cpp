// SPDX-License-Identifier: Apache-2.0
#include "servoarm/hal/isotp.hpp"

#include <algorithm>
#include <cstring>

namespace servoarm::hal {

namespace {
constexpr std::uint8_t kSF = 0x0, kFF = 0x1, kCF = 0x2, kFC = 0x3;
constexpr std::uint8_t kCTS = 0, kWAIT = 1, kOVFLW = 2;
constexpr Duration kRetry = 200 * kMicrosecond;  // re-offer a frame the bus refused with would_block
}  // namespace

const char* to_string(IsoTpResult r) {
  switch (r) {
    case IsoTpResult::ok: return "ok";
    case IsoTpResult::none: return "none";
    case IsoTpResult::busy: return "busy";
    case IsoTpResult::timeout_a: return "timeout_a";
    case IsoTpResult::timeout_bs: return "timeout_bs";
    case IsoTpResult::timeout_cr: return "timeout_cr";
    case IsoTpResult::wrong_sn: return "wrong_sn";
    case IsoTpResult::invalid_fs: return "invalid_fs";
    case IsoTpResult::unexp_pdu: return "unexp_pdu";
    case IsoTpResult::wft_ovrn: return "wft_ovrn";
    case IsoTpResult::buffer_overflow: return "buffer_overflow";
    case IsoTpResult::bus_error: return "bus_error";
    case IsoTpResult::invalid_length: return "invalid_length";
    case IsoTpResult::malformed: return "malformed";
  }
  return "unknown";
}

Duration IsoTpEndpoint::st_min_ns(std::uint8_t st) {
  if (st <= 0x7F) return Duration(st) * kMillisecond;
  if (st >= 0xF1 && st <= 0xF9) return Duration(st - 0xF0) * 100 * kMicrosecond;
  return 0x7F * kMillisecond;
}

IsoTpEndpoint::IsoTpEndpoint(CanBus& bus, Clock& clock, const IsoTpConfig& cfg) : bus_(bus), clock_(clock), cfg_(cfg) {
  if (cfg_.rx_limit > kMaxMessage) cfg_.rx_limit = kMaxMessage;
}

CanFrame IsoTpEndpoint::frame(std::uint8_t n) const {
  CanFrame f;
  f.id = cfg_.tx_id;
  f.extended = cfg_.extended;
  f.len = cfg_.padding ? 8 : n;
  if (cfg_.padding) std::fill(f.data.begin() + n, f.data.begin() + 8, cfg_.pad_byte);
  return f;
}

Status IsoTpEndpoint::put(const CanFrame& f) {
  const Status s = bus_.send(f);
  if (s != Status::ok && s != Status::error_passive) last_bus_ = s;
  return s;
}

void IsoTpEndpoint::tx_end(IsoTpResult r) {
  tx_state_ = TxState::idle;
  ev_.tx = r;
  if (r == IsoTpResult::ok) ++stats_.tx_messages;
  else ++stats_.tx_errors;
}

void IsoTpEndpoint::rx_end(IsoTpResult r) {
  rx_state_ = RxState::idle;
  fc_pending_ = false;
  if (r == IsoTpResult::ok) {
    rx_len_ = rx_expect_;
    ++stats_.rx_messages;
    ev_.rx = r;
  } else {
    ++stats_.rx_errors;
    if (ev_.rx != IsoTpResult::ok) ev_.rx = r;  // a message completed in the same call wins
  }
}

IsoTpResult IsoTpEndpoint::send(std::span<const std::uint8_t> msg) {
  if (msg.empty() || msg.size() > kMaxMessage) return IsoTpResult::invalid_length;
  if (tx_state_ != TxState::idle) return IsoTpResult::busy;
  std::memcpy(tx_buf_.data(), msg.data(), msg.size());
  tx_len_ = msg.size();
  const TimePoint now = clock_.now();
  if (tx_len_ <= 7) {
    CanFrame f = frame(static_cast<std::uint8_t>(1 + tx_len_));
    f.data[0] = static_cast<std::uint8_t>((kSF << 4) | tx_len_);
    std::memcpy(&f.data[1], tx_buf_.data(), tx_len_);
    const Status s = put(f);
    if (!is_ok(s)) return IsoTpResult::bus_error;
    if (s == Status::would_block) {  // keep it and retry from poll(); N_As applies
      tx_state_ = TxState::first;
      tx_off_ = 0;
      tx_next_ = now + kRetry;
      tx_deadline_ = now + cfg_.n_as;
      return IsoTpResult::ok;
    }
    tx_end(IsoTpResult::ok);
    return IsoTpResult::ok;
  }
  tx_state_ = TxState::first;
  tx_off_ = 0;
  tx_next_ = now;
  tx_deadline_ = now + cfg_.n_as;
  tx_pump(now);
  if (tx_state_ == TxState::idle && ev_.tx == IsoTpResult::bus_error) {
    ev_.tx = IsoTpResult::none;
    return IsoTpResult::bus_error;
  }
  return IsoTpResult::ok;
}

// Send whatever the transmit state allows at `now`: the SF/FF being retried, or
// consecutive frames up to the block size, paced by STmin.
void IsoTpEndpoint::tx_pump(TimePoint now) {
  for (;;) {
    if (tx_state_ == TxState::first) {
      if (now < tx_next_) return;
      CanFrame f;
      if (tx_len_ <= 7) {
        f = frame(static_cast<std::uint8_t>(1 + tx_len_));
        f.data[0] = static_cast<std::uint8_t>((kSF << 4) | tx_len_);
        std::memcpy(&f.data[1], tx_buf_.data(), tx_len_);
      } else {
        f = frame(8);
        f.data[0] = static_cast<std::uint8_t>((kFF << 4) | ((tx_len_ >> 8) & 0x0F));
        f.data[1] = static_cast<std::uint8_t>(tx_len_ & 0xFF);
        std::memcpy(&f.data[2], tx_buf_.data(), 6);
      }
      const Status s = put(f);
      if (!is_ok(s)) return tx_end(IsoTpResult::bus_error);
      if (s == Status::would_block) {
        if (now >= tx_deadline_) return tx_end(IsoTpResult::timeout_a);
        tx_next_ = now + kRetry;
        return;
      }
      if (tx_len_ <= 7) return tx_end(IsoTpResult::ok);
      tx_off_ = 6;
      tx_sn_ = 1;
      tx_wft_ = 0;
      tx_state_ = TxState::wait_fc;
      tx_deadline_ = now + cfg_.n_bs;
      return;
    }
    if (tx_state_ != TxState::send_cf || now < tx_next_) return;
    const std::size_t n = std::min<std::size_t>(7, tx_len_ - tx_off_);
    CanFrame f = frame(static_cast<std::uint8_t>(1 + n));
    f.data[0] = static_cast<std::uint8_t>((kCF << 4) | (tx_sn_ & 0x0F));
    std::memcpy(&f.data[1], tx_buf_.data() + tx_off_, n);
    const Status s = put(f);
    if (!is_ok(s)) return tx_end(IsoTpResult::bus_error);
    if (s == Status::would_block) {
      if (tx_deadline_ == 0) tx_deadline_ = now + cfg_.n_as;
      if (now >= tx_deadline_) return tx_end(IsoTpResult::timeout_a);
      tx_next_ = now + kRetry;
      return;
    }
    tx_deadline_ = 0;
    tx_off_ += n;
    tx_sn_ = static_cast<std::uint8_t>((tx_sn_ + 1) & 0x0F);
    if (tx_off_ >= tx_len_) return tx_end(IsoTpResult::ok);
    if (tx_bs_ != 0 && ++tx_block_ >= tx_bs_) {
      tx_state_ = TxState::wait_fc;
      tx_deadline_ = now + cfg_.n_bs;
      return;
    }
    tx_next_ = now + tx_stmin_;
    if (tx_stmin_ > 0) return;
  }
}

void IsoTpEndpoint::handle_fc(const CanFrame& f, TimePoint now) {
  if (tx_state_ != TxState::wait_fc) return;  // ISO: an unexpected FC is ignored
  if (f.len < 3) {
    ++stats_.ignored;
    if (ev_.tx == IsoTpResult::none) ev_.tx = IsoTpResult::malformed;
    return;
  }
  const std::uint8_t fs = f.data[0] & 0x0F;
  switch (fs) {
    case kCTS:
      tx_bs_ = f.data[1];
      tx_block_ = 0;
      tx_wft_ = 0;
      tx_stmin_ = st_min_ns(f.data[2]);
      tx_state_ = TxState::send_cf;
      tx_next_ = now;
      tx_deadline_ = 0;
      tx_pump(now);
      return;
    case kWAIT:
      if (++tx_wft_ > cfg_.max_wft) return tx_end(IsoTpResult::wft_ovrn);
      tx_deadline_ = now + cfg_.n_bs;
      return;
    case kOVFLW:
      return tx_end(IsoTpResult::buffer_overflow);
    default:
      return tx_end(IsoTpResult::invalid_fs);
  }
}

void IsoTpEndpoint::send_fc(std::uint8_t fs, TimePoint now) {
  CanFrame f = frame(3);
  f.data[0] = static_cast<std::uint8_t>((kFC << 4) | fs);
  f.data[1] = cfg_.block_size;
  f.data[2] = cfg_.st_min;
  const Status s = put(f);
  if (fs != kCTS) return;  // overflow: best effort, the reception is over anyway
  if (!is_ok(s)) return rx_end(IsoTpResult::bus_error);
  if (s == Status::would_block) {
    if (!fc_pending_) fc_deadline_ = now + cfg_.n_as;
    fc_pending_ = true;
    if (now >= fc_deadline_) rx_end(IsoTpResult::timeout_a);
    return;
  }
  fc_pending_ = false;
  rx_deadline_ = now + cfg_.n_cr;
}

IsoTpEvent IsoTpEndpoint::on_frame(const CanFrame& f) {
  ev_ = IsoTpEvent{};
  if (f.error || f.rtr || f.fd || f.extended != cfg_.extended || f.id != cfg_.rx_id) return ev_;
  const TimePoint now = clock_.now();
  auto ignore = [&] {
    ++stats_.ignored;
    if (ev_.rx == IsoTpResult::none) ev_.rx = IsoTpResult::malformed;
  };
  if (f.len == 0) {
    ignore();
    return ev_;
  }
  const std::uint8_t pci = f.data[0] >> 4;
  switch (pci) {
    case kSF: {
      const std::size_t n = f.data[0] & 0x0F;
      if (n == 0 || n > 7 || n + 1 > f.len) {
        ignore();
        break;
      }
      if (rx_state_ == RxState::receiving) rx_end(IsoTpResult::unexp_pdu);
      std::memcpy(rx_buf_.data(), &f.data[1], n);
      rx_expect_ = n;
      rx_end(IsoTpResult::ok);
      break;
    }
    case kFF: {
      if (f.len < 8) {
        ignore();
        break;
      }
      std::size_t n = (std::size_t(f.data[0] & 0x0F) << 8) | f.data[1];
      std::size_t hdr = 2;
      if (n == 0) {  // escape sequence: 32-bit length (only meaningful above 4095)
        n = (std::size_t(f.data[2]) << 24) | (std::size_t(f.data[3]) << 16) | (std::size_t(f.data[4]) << 8) | f.data[5];
        hdr = 6;
        if (n <= kMaxMessage) {
          ignore();
          break;
        }
      } else if (n < 8) {  // would have fit a single frame
        ignore();
        break;
      }
      if (rx_state_ == RxState::receiving) rx_end(IsoTpResult::unexp_pdu);
      if (n > cfg_.rx_limit) {
        send_fc(kOVFLW, now);
        ++stats_.rx_errors;
        if (ev_.rx != IsoTpResult::ok) ev_.rx = IsoTpResult::buffer_overflow;
        break;
      }
      rx_expect_ = n;
      rx_off_ = 8 - hdr;
      std::memcpy(rx_buf_.data(), &f.data[hdr], rx_off_);
      rx_sn_ = 1;
      rx_block_ = 0;
      rx_state_ = RxState::receiving;
      send_fc(kCTS, now);
      break;
    }
    case kCF: {
      if (rx_state_ != RxState::receiving || fc_pending_) break;  // ISO: an unexpected CF is ignored
      const std::size_t want = std::min<std::size_t>(7, rx_expect_ - rx_off_);
      if (std::size_t(f.len) < want + 1) {
        ignore();
        break;
      }
      if ((f.data[0] & 0x0F) != rx_sn_) {
        rx_end(IsoTpResult::wrong_sn);
        break;
      }
      std::memcpy(rx_buf_.data() + rx_off_, &f.data[1], want);
      rx_off_ += want;
      rx_sn_ = static_cast<std::uint8_t>((rx_sn_ + 1) & 0x0F);
      if (rx_off_ >= rx_expect_) {
        rx_end(IsoTpResult::ok);
        break;
      }
      rx_deadline_ = now + cfg_.n_cr;
      if (cfg_.block_size != 0 && ++rx_block_ >= cfg_.block_size) {
        rx_block_ = 0;
        send_fc(kCTS, now);
      }
      break;
    }
    case kFC:
      handle_fc(f, now);
      break;
    default:
      ignore();
      break;
  }
  return ev_;
}

IsoTpEvent IsoTpEndpoint::poll() {
  ev_ = IsoTpEvent{};
  const TimePoint now = clock_.now();
  if (rx_state_ == RxState::receiving) {
    if (fc_pending_) send_fc(kCTS, now);
    else if (now >= rx_deadline_) rx_end(IsoTpResult::timeout_cr);
  }
  if (tx_state_ == TxState::wait_fc && now >= tx_deadline_) tx_end(IsoTpResult::timeout_bs);
  tx_pump(now);
  return ev_;
}

TimePoint IsoTpEndpoint::next_deadline() const {
  TimePoint t = kNever;
  if (rx_state_ == RxState::receiving) t = fc_pending_ ? clock_.now() + kRetry : rx_deadline_;
  switch (tx_state_) {
    case TxState::idle: break;
    case TxState::wait_fc: t = std::min(t, tx_deadline_); break;
    case TxState::first:
    case TxState::send_cf: t = std::min(t, tx_next_); break;
  }
  return t;
}

IsoTpEvent IsoTpEndpoint::service(TimePoint deadline) {
  for (;;) {
    IsoTpEvent ev = poll();
    if (ev.any() && ev.rx != IsoTpResult::malformed && ev.tx != IsoTpResult::malformed) return ev;
    const TimePoint until = std::min(deadline, next_deadline());
    CanFrame f;
    const Status s = bus_.receive(f, until);
    if (s == Status::ok) {
      ev = on_frame(f);
      if (ev.any() && ev.rx != IsoTpResult::malformed && ev.tx != IsoTpResult::malformed) return ev;
      continue;
    }
    if (s != Status::timeout) {
      last_bus_ = s;
      // A dead bus: do not spin. Report it on the receive side once the deadline passed.
      if (clock_.now() >= deadline) return IsoTpEvent{IsoTpResult::bus_error, IsoTpResult::none};
      clock_.sleep_until(std::min(deadline, clock_.now() + 10 * kMillisecond));
      continue;
    }
    if (clock_.now() >= deadline) return poll();
  }
}

}  // namespace servoarm::hal
