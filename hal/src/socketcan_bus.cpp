// SPDX-License-Identifier: Apache-2.0
#include "servoarm/hal/socketcan_bus.hpp"

#include <fcntl.h>
#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <ctime>

#ifndef CAN_ERR_CRTL_ACTIVE
#define CAN_ERR_CRTL_ACTIVE 0x40
#endif

namespace servoarm::hal {

namespace {

void to_kernel(const CanFrame& f, canfd_frame& k) {
  std::memset(&k, 0, sizeof k);
  k.can_id = f.id | (f.extended ? CAN_EFF_FLAG : 0u) | (f.rtr ? CAN_RTR_FLAG : 0u);
  k.len = f.len;
  if (f.fd && f.brs) k.flags |= CANFD_BRS;
  std::memcpy(k.data, f.data.data(), f.len);
}

void from_kernel(const canfd_frame& k, bool fd, CanFrame& f) {
  f = CanFrame{};
  f.error = (k.can_id & CAN_ERR_FLAG) != 0;
  f.extended = (k.can_id & CAN_EFF_FLAG) != 0;
  f.rtr = (k.can_id & CAN_RTR_FLAG) != 0;
  f.id = k.can_id & (f.error ? CAN_ERR_MASK : f.extended ? CAN_EFF_MASK : CAN_SFF_MASK);
  f.fd = fd;
  f.brs = fd && (k.flags & CANFD_BRS);
  const std::uint8_t max = fd ? CanFrame::kMaxFdLen : CanFrame::kMaxClassicLen;
  f.len = k.len > max ? max : k.len;
  if (!f.rtr) std::memcpy(f.data.data(), k.data, f.len);
}

}  // namespace

const char* to_string(RxTimestamps t) {
  switch (t) {
    case RxTimestamps::kernel_ns:
      return "kernel_ns";
    case RxTimestamps::kernel_us:
      return "kernel_us";
    case RxTimestamps::receive:
      return "receive";
  }
  return "?";
}

SocketCanBus::SocketCanBus(int fd, const SocketCanOptions& opt) : fd_(fd), adopted_(true), opt_(opt) {
  if (fd_ >= 0) {
    const int fl = fcntl(fd_, F_GETFL, 0);
    if (fl >= 0) fcntl(fd_, F_SETFL, fl | O_NONBLOCK);
    enable_timestamps(fd_);  // works on AF_UNIX too
  }
}

// Nanosecond kernel stamps if the kernel takes SO_TIMESTAMPNS; microsecond ones
// (SO_TIMESTAMP) otherwise - qemu-user 7.2 answers SO_TIMESTAMPNS with ENOPROTOOPT
// but translates SO_TIMESTAMP; else rx_time is the time receive() read the frame.
void SocketCanBus::enable_timestamps(int fd) {
  ts_ = RxTimestamps::receive;
  if (!opt_.kernel_timestamps) return;
  const int on = 1;
  if (setsockopt(fd, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof on) == 0) ts_ = RxTimestamps::kernel_ns;
  else if (setsockopt(fd, SOL_SOCKET, SO_TIMESTAMP, &on, sizeof on) == 0) ts_ = RxTimestamps::kernel_us;
}

SocketCanBus::~SocketCanBus() { close(); }

void SocketCanBus::close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

// Real-time safe: formats into the fixed msg_ buffer (snprintf), no heap.
Status SocketCanBus::fail(Status s, const char* what, int err) {
  const char* sep = iface_[0] ? ": " : "";
  if (err) std::snprintf(msg_, sizeof msg_, "%s%s%s: %s", iface_, sep, what, std::strerror(err));
  else std::snprintf(msg_, sizeof msg_, "%s%s%s", iface_, sep, what);
  return s;
}

Status SocketCanBus::open(const char* iface, const SocketCanOptions& opt) {
  close();
  opt_ = opt;
  std::memset(iface_, 0, sizeof iface_);
  named_ = false;
  if (iface == nullptr || iface[0] == '\0') return fail(Status::invalid_argument, "empty interface name", 0);
  const std::size_t n = strnlen(iface, sizeof iface_);
  if (n >= sizeof iface_ || n >= IFNAMSIZ) return fail(Status::invalid_argument, "interface name too long", 0);
  std::memcpy(iface_, iface, n);
  named_ = true;
  adopted_ = false;
  need_reopen_ = false;
  down_ = false;
  stats_.state = ErrorState::active;
  return open_socket(false);
}

// Set-up (also the reopen path, which passes require_up: a socket bound to a down
// interface binds fine but only reports ENETDOWN, so wait for IFF_UP instead).
Status SocketCanBus::open_socket(bool require_up) {
  close();
  const std::size_t n = strnlen(iface_, sizeof iface_);
  const int fd = ::socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW);
  if (fd < 0) return fail(Status::io_error, "socket(PF_CAN, SOCK_RAW, CAN_RAW)", errno);

  ifreq ifr;
  std::memset(&ifr, 0, sizeof ifr);
  std::memcpy(ifr.ifr_name, iface_, n);  // bounded: n < IFNAMSIZ, rest stays zero
  if (ioctl(fd, SIOCGIFINDEX, &ifr) < 0) {
    const int e = errno;
    ::close(fd);
    return fail(Status::interface_down, "SIOCGIFINDEX (no such CAN interface?)", e);
  }
  const int ifindex = ifr.ifr_ifindex;
  if (require_up) {
    if (ioctl(fd, SIOCGIFFLAGS, &ifr) < 0) {
      const int e = errno;
      ::close(fd);
      return fail(Status::interface_down, "SIOCGIFFLAGS", e);
    }
    if (!(ifr.ifr_flags & IFF_UP)) {
      ::close(fd);
      return fail(Status::interface_down, "interface is down (waiting for it to come up)", 0);
    }
  }

  if (opt_.enable_fd) {
    if (ioctl(fd, SIOCGIFMTU, &ifr) < 0 || ifr.ifr_mtu != CANFD_MTU) {
      ::close(fd);
      return fail(Status::invalid_argument, "interface is not CAN FD capable (MTU)", 0);
    }
    const int on = 1;
    if (setsockopt(fd, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &on, sizeof on) < 0) {
      const int e = errno;
      ::close(fd);
      return fail(Status::io_error, "CAN_RAW_FD_FRAMES", e);
    }
  }
  const can_err_mask_t err_mask = CAN_ERR_TX_TIMEOUT | CAN_ERR_CRTL | CAN_ERR_BUSOFF | CAN_ERR_RESTARTED |
                                  CAN_ERR_BUSERROR | CAN_ERR_PROT | CAN_ERR_ACK;
  if (setsockopt(fd, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &err_mask, sizeof err_mask) < 0) {
    const int e = errno;
    ::close(fd);
    return fail(Status::io_error, "CAN_RAW_ERR_FILTER", e);
  }
  const int own = opt_.recv_own ? 1 : 0;
  setsockopt(fd, SOL_CAN_RAW, CAN_RAW_RECV_OWN_MSGS, &own, sizeof own);
  const int rcvbuf = opt_.rcvbuf_bytes;
  if (rcvbuf > 0) setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof rcvbuf);
  const int on = 1;
  enable_timestamps(fd);
  setsockopt(fd, SOL_SOCKET, SO_RXQ_OVFL, &on, sizeof on);

  sockaddr_can addr;
  std::memset(&addr, 0, sizeof addr);
  addr.can_family = AF_CAN;
  addr.can_ifindex = ifindex;
  if (bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) < 0) {
    const int e = errno;
    ::close(fd);
    return fail(e == ENETDOWN ? Status::interface_down : Status::io_error, "bind(AF_CAN)", e);
  }
  fd_ = fd;
  last_drop_count_ = 0;
  if (n_filters_ > 0) return apply_filters();
  return Status::ok;
}

Status SocketCanBus::apply_filters() {
  if (fd_ < 0 || adopted_) return Status::ok;  // socketpair ends: filters applied in user space
  can_filter k[kMaxFilters];
  for (std::size_t i = 0; i < n_filters_; ++i) {
    k[i].can_id = filters_[i].id | (filters_[i].extended ? CAN_EFF_FLAG : 0u);
    k[i].can_mask = filters_[i].mask | CAN_EFF_FLAG;  // also match the id format
  }
  const socklen_t len = socklen_t(n_filters_ * sizeof(can_filter));
  if (setsockopt(fd_, SOL_CAN_RAW, CAN_RAW_FILTER, n_filters_ ? k : nullptr, len) < 0)
    return fail(Status::io_error, "CAN_RAW_FILTER", errno);
  return Status::ok;
}

Status SocketCanBus::set_filters(std::span<const CanFilter> filters) {
  if (filters.size() > kMaxFilters) return Status::capacity;
  n_filters_ = filters.size();
  for (std::size_t i = 0; i < n_filters_; ++i) filters_[i] = filters[i];
  if (n_filters_ == 0 && fd_ >= 0 && !adopted_) {
    // Back to "accept all": the kernel default filter is id 0 / mask 0.
    can_filter all{0, 0};
    if (setsockopt(fd_, SOL_CAN_RAW, CAN_RAW_FILTER, &all, sizeof all) < 0)
      return fail(Status::io_error, "CAN_RAW_FILTER", errno);
    return Status::ok;
  }
  return apply_filters();
}

Status SocketCanBus::down(const char* what, int err) {
  fail(Status::interface_down, what, err);
  if (down_) return Status::interface_down;  // same episode
  down_ = true;
  ++downs_;
  std::memcpy(down_msg_, msg_, sizeof down_msg_);
  if (named_ && opt_.auto_reopen) {
    need_reopen_ = true;
    const TimePoint now = clock_.now();
    if (next_reopen_ < now) next_reopen_ = now;  // first attempt at once, then rate-limited
  }
  return Status::interface_down;
}

Status SocketCanBus::maybe_reopen() {
  if (!need_reopen_) return Status::ok;
  const TimePoint now = clock_.now();
  if (now < next_reopen_) return Status::interface_down;
  next_reopen_ = now + opt_.reopen_interval;
  // No heap: socket()/ioctl()/setsockopt()/bind() only. Filters are re-applied.
  const Status st = open_socket(true);
  if (st == Status::ok) {
    need_reopen_ = false;
    down_ = false;
    ++stats_.reopens;
    stats_.state = ErrorState::active;
    return Status::ok;
  }
  return Status::interface_down;
}

Status SocketCanBus::send(const CanFrame& frame) {
  if (!frame.valid() || (frame.fd && !opt_.enable_fd && !adopted_)) {
    ++stats_.tx_errors;
    return Status::invalid_argument;
  }
  if (const Status r = maybe_reopen(); r != Status::ok) {
    ++stats_.tx_errors;
    return r;
  }
  if (fd_ < 0) {
    ++stats_.tx_errors;
    return Status::not_open;
  }
  if (stats_.state == ErrorState::bus_off) {
    // Not queued: the controller would send it after its restart, by then stale.
    ++stats_.tx_errors;
    return Status::bus_off;
  }
  canfd_frame k;
  to_kernel(frame, k);
  const std::size_t size = frame.fd ? CANFD_MTU : CAN_MTU;
  const ssize_t n = ::write(fd_, &k, size);
  if (n == ssize_t(size)) {
    ++stats_.tx_frames;
    return stats_.state == ErrorState::passive ? Status::error_passive : Status::ok;
  }
  ++stats_.tx_errors;
  if (n >= 0) return fail(Status::io_error, "short write on CAN socket", 0);
  const int e = errno;
  switch (e) {
    case EAGAIN:
    case ENOBUFS:
      // ENOBUFS: the tx queue is full - or the controller is bus-off and not draining it.
      return stats_.state == ErrorState::bus_off ? Status::bus_off : Status::would_block;
    case ENETDOWN:
    case ENODEV:
    case ENXIO:
      return down("write(CAN)", e);
    default:
      return fail(Status::io_error, "write(CAN)", e);
  }
}

ErrorState SocketCanBus::decode_error_frame(const CanFrame& f, ErrorState previous, std::uint64_t* overruns) {
  ErrorState s = previous;
  if (f.id & CAN_ERR_RESTARTED) s = ErrorState::active;
  if ((f.id & CAN_ERR_CRTL) && f.len >= 2) {
    const std::uint8_t c = f.data[1];
    if (c & (CAN_ERR_CRTL_RX_OVERFLOW | CAN_ERR_CRTL_TX_OVERFLOW)) {
      if (overruns) ++*overruns;
    }
    if (c & CAN_ERR_CRTL_ACTIVE) s = ErrorState::active;
    if (c & (CAN_ERR_CRTL_RX_WARNING | CAN_ERR_CRTL_TX_WARNING)) s = ErrorState::warning;
    if (c & (CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE)) s = ErrorState::passive;
  }
  if (f.id & CAN_ERR_BUSOFF) s = ErrorState::bus_off;
  return s;
}

Status SocketCanBus::receive(CanFrame& out, TimePoint deadline) {
  for (;;) {
    if (const Status r = maybe_reopen(); r != Status::ok) {
      if (clock_.now() >= deadline) return r;
      clock_.sleep_until(deadline < next_reopen_ ? deadline : next_reopen_);
      continue;
    }
    if (fd_ < 0) return Status::not_open;

    canfd_frame k;
    iovec iov{&k, sizeof k};
    alignas(cmsghdr) char ctrl[CMSG_SPACE(sizeof(timespec) > sizeof(timeval) ? sizeof(timespec) : sizeof(timeval)) +
                               CMSG_SPACE(sizeof(std::uint32_t))];
    msghdr msg;
    std::memset(&msg, 0, sizeof msg);
    msg.msg_iov = &iov;
    msg.msg_iovlen = 1;
    msg.msg_control = ctrl;
    msg.msg_controllen = sizeof ctrl;
    const ssize_t n = ::recvmsg(fd_, &msg, MSG_DONTWAIT);
    if (n > 0) {
      if (n != ssize_t(CAN_MTU) && n != ssize_t(CANFD_MTU)) {
        ++stats_.error_frames;
        fail(Status::protocol_error, "recvmsg: frame of unexpected size ignored", 0);
        continue;
      }
      TimePoint kernel_rx = 0;  // CLOCK_REALTIME ns when the frame reached the socket
      for (cmsghdr* c = CMSG_FIRSTHDR(&msg); c != nullptr; c = CMSG_NXTHDR(&msg, c)) {
        if (c->cmsg_level != SOL_SOCKET) continue;
        if (c->cmsg_type == SCM_TIMESTAMPNS && c->cmsg_len >= CMSG_LEN(sizeof(timespec))) {
          timespec ts;
          std::memcpy(&ts, CMSG_DATA(c), sizeof ts);
          kernel_rx = TimePoint(ts.tv_sec) * kSecond + ts.tv_nsec;
        }
        if (c->cmsg_type == SCM_TIMESTAMP && c->cmsg_len >= CMSG_LEN(sizeof(timeval))) {
          timeval tv;
          std::memcpy(&tv, CMSG_DATA(c), sizeof tv);
          kernel_rx = TimePoint(tv.tv_sec) * kSecond + TimePoint(tv.tv_usec) * kMicrosecond;
        }
        if (c->cmsg_type == SO_RXQ_OVFL && c->cmsg_len >= CMSG_LEN(sizeof(std::uint32_t))) {
          std::uint32_t drops;
          std::memcpy(&drops, CMSG_DATA(c), sizeof drops);
          if (drops > last_drop_count_) stats_.rx_overruns += drops - last_drop_count_;
          last_drop_count_ = drops;
        }
      }
      from_kernel(k, n == ssize_t(CANFD_MTU), out);
      const TimePoint mono_now = clock_.now();
      out.rx_time = mono_now;
      if (kernel_rx != 0) {
        // Kernel stamps are CLOCK_REALTIME: move them onto CLOCK_MONOTONIC (vDSO, no syscall).
        timespec rt{};
        clock_gettime(CLOCK_REALTIME, &rt);
        const TimePoint mono = mono_now - ((TimePoint(rt.tv_sec) * kSecond + rt.tv_nsec) - kernel_rx);
        if (mono <= mono_now && mono > mono_now - kSecond) out.rx_time = mono;  // ignore clock steps
      }
      if (out.error) {
        ++stats_.error_frames;
        // Bus-off is reported, not "fixed" by reopening: the controller restart is the
        // kernel's (ip link ... restart-ms N), which sends CAN_ERR_RESTARTED -> active.
        stats_.state = decode_error_frame(out, stats_.state, &stats_.rx_overruns);
        return Status::ok;
      }
      if (adopted_ && n_filters_ > 0) {
        bool pass = false;
        for (std::size_t i = 0; i < n_filters_ && !pass; ++i) pass = filters_[i].matches(out);
        if (!pass) continue;
      }
      ++stats_.rx_frames;
      return Status::ok;
    }
    if (n == 0) {  // socketpair peer gone (a CAN_RAW socket never reads 0 bytes)
      return down("recvmsg: peer closed", 0);
    }
    const int e = errno;
    if (e == EINTR) continue;
    if (e == ENETDOWN || e == ENODEV || e == ENXIO) {
      return down("recvmsg(CAN)", e);
    }
    if (e != EAGAIN) return fail(Status::io_error, "recvmsg(CAN)", e);

    const TimePoint now = clock_.now();
    if (now >= deadline) return Status::timeout;
    const Duration left = deadline - now;
    timespec ts{time_t(left / kSecond), long(left % kSecond)};
    pollfd p{fd_, POLLIN, 0};
    const int r = ::ppoll(&p, 1, &ts, nullptr);
    if (r < 0 && errno != EINTR) return fail(Status::io_error, "ppoll(CAN)", errno);
    if (r > 0 && (p.revents & (POLLERR | POLLHUP | POLLNVAL)) && !(p.revents & POLLIN)) {
      return down("ppoll: socket error/hangup", 0);
    }
  }
}

}  // namespace servoarm::hal
