// SPDX-License-Identifier: Apache-2.0
#include "servoarm/console/transport.hpp"

#include <fcntl.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "servoarm/lang/commands.hpp"
#include "servoarm/console/console.hpp"
#include "servoarm/hal/serial_port.hpp"

namespace servoarm::fw {

FdTransport::~FdTransport() {
  if (owns) {
    if (rd >= 0) ::close(rd);
    if (wr >= 0 && wr != rd) ::close(wr);
  }
  if (keep >= 0) ::close(keep);
}

// Opening is hal's (serial_port.hpp); the transport takes the descriptors over.
std::string open_pty(FdTransport& t) {
  hal::PtyPair pty;
  std::string e;
  if (hal::open_pty(pty, e) != hal::Status::ok) return e;
  t.name = "pty";
  t.path = pty.slave.path();
  t.rd = t.wr = pty.master.release();
  // No slave fd of our own: with none open the master reports POLLHUP, which is how a
  // client's coming and going is seen (the tty's raw settings stay with the master).
  pty.slave.close();
  t.owns = true;
  t.no_peer = true;
  return "";
}

std::string open_serial(FdTransport& t, const std::string& path, int baud) {
  hal::SerialPort port;
  if (port.open(path, baud) != hal::Status::ok) return port.message();
  t.name = "serial";
  t.path = path;
  t.rd = t.wr = port.release();
  t.owns = true;
  return "";
}

bool write_all(int fd, const std::string& s) {
  std::size_t off = 0;
  int spins = 0;
  while (off < s.size()) {
    const ssize_t w = ::write(fd, s.data() + off, s.size() - off);
    if (w > 0) {
      off += static_cast<std::size_t>(w);
      continue;
    }
    if (w < 0 && (errno == EINTR)) continue;
    if (w < 0 && (errno == EAGAIN || errno == EWOULDBLOCK) && ++spins < 200) {
      pollfd p{fd, POLLOUT, 0};
      ::poll(&p, 1, 10);
      continue;
    }
    return false;
  }
  return true;
}

ConsoleServer::ConsoleServer(Console& console, const std::vector<FdTransport*>& ts)
    : console_(console), ts_(ts), sessions_(ts.size()), pfds_(2 * ts.size()) {
  for (std::size_t i = 0; i < ts.size(); ++i) {
    sessions_[i].name = ts[i]->name;
    sessions_[i].dialect = ts[i]->dialect;
    sessions_[i].modal.dwell_p_seconds = ts[i]->dialect == Dialect::grbl;  // GRBL's G4 P is seconds
    if (!ts[i]->no_peer) console_.greet(sessions_[i]);  // GRBL dialect: the banner senders look for (a pty: when a client opens it)
    const int fl = ts[i]->wr >= 0 ? fcntl(ts[i]->wr, F_GETFL) : -1;
    ts[i]->wr_nonblocking = fl >= 0 && (fl & O_NONBLOCK) != 0;
  }
}

// Read what every transport has (one chunk each), so realtime characters act before
// any line of any client runs and before any output is written. A client with
// kMaxQueuedLines lines waiting is not read (its bytes stay in the kernel).
void ConsoleServer::sweep(int timeout_ms) {
  for (std::size_t i = 0; i < ts_.size(); ++i) {
    FdTransport& t = *ts_[i];
    if (t.no_peer) {  // a pty nobody has open: has a client come?
      pollfd p{t.rd, POLLIN, 0};
      if (::poll(&p, 1, 0) >= 0 && !(p.revents & POLLHUP)) {
        t.no_peer = false;
        t.pending.clear();
        console_.greet(sessions_[i]);  // what a GRBL sender waits for after opening the port
      }
    }
    // Room for more: fewer than kMaxQueuedLines lines waiting, and output read (a client that
    // sends '?' and reads nothing cannot grow its reports without bound).
    const bool room = sessions_[i].lines.size() < kMaxQueuedLines && t.pending.size() < kMaxPendingEvents;
    pfds_[2 * i] = pollfd{t.eof || t.no_peer || !room ? -1 : t.rd, POLLIN, 0};
    const bool want_out = !t.pending.empty() && t.wr >= 0 && !t.no_peer;
    pfds_[2 * i + 1] = pollfd{want_out ? t.wr : -1, POLLOUT, 0};
  }
  ::poll(pfds_.data(), pfds_.size(), timeout_ms);
  for (std::size_t i = 0; i < ts_.size(); ++i) {
    FdTransport& t = *ts_[i];
    Session& s = sessions_[i];
    if (pfds_[2 * i].fd < 0 || t.eof || t.no_peer || !(pfds_[2 * i].revents & (POLLIN | POLLHUP | POLLERR))) continue;
    if (t.name == "pty" && (pfds_[2 * i].revents & POLLHUP) && !(pfds_[2 * i].revents & POLLIN)) {
      // The client closed the pty: it is gone. Its jog stops now; what it sent and did not
      // run yet is dropped (nobody is there to read the answers).
      t.no_peer = true;
      t.pending.clear();
      s.lines.clear();
      s.hold_after = 0;
      console_.client_gone(s);
      continue;
    }
    char buf[kReadChunk];
    const ssize_t r = ::read(t.rd, buf, sizeof buf);
    if (r > 0) {
      console_.accept(s, std::string_view(buf, static_cast<std::size_t>(r)));
      queue_output(i);  // realtime answers ('?', Ctrl-X's) in order, ahead of later lines
    } else if (r == 0 || (r < 0 && errno != EAGAIN && errno != EINTR && errno != EIO)) {
      if (t.name == "stdin") {
        t.eof = true;
        console_.end_of_input(s);  // a last line without newline (even an overlong one) is answered
        console_.client_gone(s);   // and a jog it ran stops now, not at its deadman
      } else if (t.name == "can") {
        t.eof = true;  // the bridge thread is gone
        console_.client_gone(s);
      }
    }
  }
}

void ConsoleServer::queue_output(std::size_t i) {
  FdTransport& t = *ts_[i];
  Session& s = sessions_[i];
  if (s.out.empty()) return;
  t.pending += s.out;  // answers are never dropped: may_run() stops this client's lines instead
  s.out.clear();
}

// Asynchronous lines for client i: dropped (counted, told later) only when it has not
// read kMaxPendingEvents of output.
void ConsoleServer::queue_events(std::size_t i, const std::string& ev) {
  FdTransport& t = *ts_[i];
  if (ev.empty()) return;
  if (t.pending.size() + ev.size() > kMaxPendingEvents) {
    std::uint64_t lines = 0;
    for (char c : ev) lines += c == '\n';
    t.dropped_lines += lines;
    t.dropped_bytes += ev.size();
    t.dropped_unreported += lines;
    console_.add_output_dropped(lines, ev.size());
    return;
  }
  t.pending += ev;
}

void ConsoleServer::end_session(std::size_t i) {
  FdTransport& t = *ts_[i];
  Session& s = sessions_[i];
  queue_output(i);          // `ok bye` and the answers to the lines sent after it
  console_.client_gone(s);  // a jog it ran stops now, a program check it started ends
  if (t.name == "stdin") {  // nothing more is read: armfw ends as at end of input
    t.eof = true;
    s.ended = false;
    return;
  }
  // A pty, serial line or CAN client stays connected: its next line starts a new session
  // (G-code modes, check mode, a held queue's count as a new client's).
  Session fresh;
  fresh.name = s.name;
  fresh.dialect = s.dialect;
  fresh.modal.dwell_p_seconds = s.dialect == Dialect::grbl;  // GRBL's G4 P is seconds
  s = std::move(fresh);
}

bool ConsoleServer::may_run(std::size_t i) const {
  return ts_[i]->pending.size() + sessions_[i].out.size() < kMaxPendingOutput;
}

void ConsoleServer::write_some(std::size_t i) {
  FdTransport& t = *ts_[i];
  if (t.wr < 0) {
    t.pending.clear();
    return;
  }
  if (t.pending.empty() && t.dropped_unreported > 0) {
    char b[160];
    std::snprintf(b, sizeof b, "alarm: console output overflow: %llu event lines dropped (this client did not read its output)\n",
                  static_cast<unsigned long long>(t.dropped_unreported));
    t.pending = b;
    t.dropped_unreported = 0;
  }
  // Never block on one client: a non-blocking fd takes what fits; a blocking one (stdout
  // of the calling shell) gets at most PIPE_BUF bytes per write, and only when poll()
  // says it is writable (a pipe then takes them without blocking).
  for (int k = 0; k < 64 && !t.pending.empty(); ++k) {
    std::size_t n = t.pending.size();
    if (!t.wr_nonblocking) {
      pollfd p{t.wr, POLLOUT, 0};
      if (::poll(&p, 1, 0) <= 0 || !(p.revents & POLLOUT)) return;
      if (n > 512) n = 512;
    }
    const ssize_t w = ::write(t.wr, t.pending.data(), n);
    if (w > 0) {
      t.pending.erase(0, static_cast<std::size_t>(w));
      continue;
    }
    if (w < 0 && errno == EINTR) continue;
    if (w < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) return;
    // The other end is gone (EIO on a pty without a client, EPIPE): nobody to tell.
    t.pending.clear();
    return;
  }
}

bool ConsoleServer::round(int timeout_ms, bool exit_on_eof) {
  sweep(more_ ? 0 : timeout_ms);
  // Lines one at a time, round-robin over the clients, one line per client per turn;
  // between two lines every transport is read again, so a realtime character waits at
  // most for the line being executed (a movel path check: a few ms), never for another
  // client's backlog. A client whose output is backed up runs nothing (back-pressure).
  more_ = false;
  for (int turn = 0; turn < kTurnsPerRound; ++turn) {
    bool any = false;
    for (std::size_t i = 0; i < ts_.size(); ++i) {
      if (!may_run(i) || !console_.run_one(sessions_[i])) continue;
      any = true;
      queue_output(i);
      if (sessions_[i].ended) end_session(i);
      write_some(i);
      sweep(0);
    }
    if (!any) break;
    more_ = turn + 1 == kTurnsPerRound;
  }
  console_.tick();  // the program runner: its next lines into the motion queue
  std::string ev, ev_grbl;
  console_.drain_events(ev, ev_grbl);
  bool all_eof_done = true;
  for (std::size_t i = 0; i < ts_.size(); ++i) {
    FdTransport& t = *ts_[i];
    Session& s = sessions_[i];
    if (may_run(i) && console_.run_one(s)) more_ = true;  // a wait that is done answers now
    queue_output(i);
    if (s.ended) end_session(i);
    queue_events(i, s.dialect == Dialect::grbl ? ev_grbl : ev);
    write_some(i);
    if (t.name == "stdin" && !(t.eof && !console_.busy(s))) all_eof_done = false;
    if (t.name != "stdin") all_eof_done = all_eof_done && exit_on_eof;
  }
  if (exit_on_eof && all_eof_done) {
    // Last answers out before returning; a client that takes nothing for 2 s loses them.
    int idle_ms = 0;
    while (idle_ms < 2000) {
      bool left = false;
      std::size_t before = 0, after = 0;
      for (std::size_t i = 0; i < ts_.size(); ++i) {
        before += ts_[i]->pending.size();
        write_some(i);
        after += ts_[i]->pending.size();
        left = left || !ts_[i]->pending.empty();
      }
      if (!left) break;
      idle_ms = after < before ? 0 : idle_ms + 5;
      pollfd p{-1, 0, 0};
      ::poll(&p, 0, 5);
    }
    return false;
  }
  return true;
}

void serve_consoles(Console& console, const std::vector<FdTransport*>& ts, bool exit_on_eof,
                    const volatile std::sig_atomic_t* quit, const std::atomic<bool>* stop) {
  ConsoleServer srv(console, ts);
  for (;;) {
    if ((quit != nullptr && *quit) || (stop != nullptr && stop->load())) break;
    if (!srv.round(10, exit_on_eof)) break;
  }
}

std::string isotp_message_to_console(const std::uint8_t* data, std::size_t n) {
  std::string s(reinterpret_cast<const char*>(data), n);
  bool only_rt = n > 0;
  for (char c : s) only_rt = only_rt && is_realtime(c);
  if (!only_rt && (s.empty() || (s.back() != '\n' && s.back() != '\r'))) s += '\n';
  return s;
}

CanConsole::~CanConsole() { stop(); }

std::string CanConsole::open(const CanConsoleConfig& cfg, hal::SimBus* sim, FdTransport& t) {
  stop();
  cfg_ = cfg;
  if (cfg.iface == "sim") {
    if (sim == nullptr) return "console.can = \"sim\" needs the in-process bus (bus.can = \"sim\" or --sim)";
    bus_ = sim->open(1024);
  } else {
    auto sc = std::make_unique<hal::SocketCanBus>();
    if (sc->open(cfg.iface.c_str()) != hal::Status::ok) {
      const std::string m = sc->message();  // names the interface itself in newer hal versions
      return "cannot open " + (m.rfind(cfg.iface + ":", 0) == 0 ? m : cfg.iface + ": " + m);
    }
    bus_ = std::move(sc);
  }
  hal::IsoTpConfig ic;
  ic.rx_id = cfg.rx_id;
  ic.tx_id = cfg.tx_id;
  iso_ = std::make_unique<hal::IsoTpEndpoint>(*bus_, clock_, ic);
  const hal::CanFilter f = iso_->rx_filter();
  if (bus_->set_filters({&f, 1}) != hal::Status::ok) return "cannot set the receive filter on " + cfg.iface;
  int sv[2];
  if (::socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, sv) != 0) return std::string("socketpair: ") + std::strerror(errno);
  fcntl(sv[0], F_SETFL, fcntl(sv[0], F_GETFL) | O_NONBLOCK);
  fcntl(sv[1], F_SETFL, fcntl(sv[1], F_GETFL) | O_NONBLOCK);
  fd_ = sv[1];
  t.name = "can";
  t.rd = t.wr = sv[0];
  char b[64];
  std::snprintf(b, sizeof b, "%s rx 0x%X tx 0x%X", cfg.iface.c_str(), unsigned(cfg.rx_id), unsigned(cfg.tx_id));
  t.path = b;
  t.owns = true;
  stop_ = false;
  th_ = std::thread([this] { run(); });
  return "";
}

void CanConsole::stop() {
  stop_ = true;
  if (th_.joinable()) th_.join();
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

// The bridge thread: ISO-TP messages -> socketpair (console input), socketpair
// (console output) -> ISO-TP messages of whole lines. Waits in CanBus::receive
// at most 2 ms, so console output leaves within ~2 ms of being written.
void CanConsole::run() {
  std::string out;       // console output not sent yet
  std::string in;        // console input not written to the socketpair yet
  bool warned = false;
  while (!stop_.load(std::memory_order_relaxed)) {
    const hal::IsoTpEvent ev = iso_->service(clock_.now() + 2 * hal::kMillisecond);
    if (ev.rx == hal::IsoTpResult::ok) {
      const auto m = iso_->rx_message();
      in += isotp_message_to_console(m.data(), m.size());
    } else if (static_cast<int>(ev.rx) < 0 && ev.rx != hal::IsoTpResult::malformed) {
      std::fprintf(stderr, "armfw: can console: receive: %s\n", hal::to_string(ev.rx));
    }
    if (static_cast<int>(ev.tx) < 0 && ev.tx != hal::IsoTpResult::malformed)
      std::fprintf(stderr, "armfw: can console: send: %s (answer lost)\n", hal::to_string(ev.tx));
    if (ev.rx == hal::IsoTpResult::bus_error && !warned) {
      std::fprintf(stderr, "armfw: can console: bus: %s\n", hal::describe(iso_->last_bus_status()));
      warned = true;
    }
    while (!in.empty()) {
      const ssize_t w = ::write(fd_, in.data(), in.size());
      if (w <= 0) break;  // the console loop is behind: keep the rest for the next round
      in.erase(0, static_cast<std::size_t>(w));
    }
    char buf[4096];
    for (;;) {
      const ssize_t r = ::read(fd_, buf, sizeof buf);
      if (r > 0) {
        out.append(buf, static_cast<std::size_t>(r));
        continue;
      }
      if (r == 0) stop_ = true;  // console side closed
      break;
    }
    if (!out.empty() && !iso_->sending()) {
      std::size_t n = std::min<std::size_t>(out.size(), hal::IsoTpEndpoint::kMaxMessage);
      if (n < out.size()) {
        const std::size_t nl = out.rfind('\n', n - 1);
        if (nl != std::string::npos) n = nl + 1;
      }
      const hal::IsoTpResult r =
          iso_->send({reinterpret_cast<const std::uint8_t*>(out.data()), n});
      if (r == hal::IsoTpResult::ok) out.erase(0, n);
      else if (r != hal::IsoTpResult::busy) {
        std::fprintf(stderr, "armfw: can console: send: %s (answer lost)\n", hal::to_string(r));
        out.erase(0, n);
      }
    }
  }
}

}  // namespace servoarm::fw
