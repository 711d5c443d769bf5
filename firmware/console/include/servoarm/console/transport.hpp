// SPDX-License-Identifier: Apache-2.0
#pragma once
// Console transports (console thread, non-real-time): byte streams on file
// descriptors. stdin/stdout, a pseudo-terminal whose slave path is printed
// (screen / minicom / pronsole connect to it), a serial TTY in raw mode, and
// CAN: ISO-TP (ISO 15765-2) messages on a CAN interface, bridged to a byte
// stream by a thread of its own (CanConsole).
#include <poll.h>

#include <atomic>
#include <csignal>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "servoarm/hal/isotp.hpp"
#include "servoarm/hal/sim_bus.hpp"
#include "servoarm/hal/socketcan_bus.hpp"
#include "servoarm/console/console.hpp"

namespace servoarm::fw {

struct FdTransport {
  std::string name;
  int rd = -1, wr = -1;
  int keep = -1;          ///< a slave fd kept open (none for armfw's pty: a client's hang-up is then seen)
  /// pty: no client has the slave open (the master reports POLLHUP). ConsoleServer leaves
  /// it out of its poll then, checks each round whether a client has come (then greets
  /// it: the GRBL banner), and treats a hang-up as the client gone (a jog it ran stops,
  /// the lines it sent and that did not run yet are dropped).
  bool no_peer = false;
  std::string path;       ///< pty slave / serial device path
  bool eof = false;
  bool owns = false;
  Dialect dialect = Dialect::native;  ///< how its session talks (ConsoleServer greets GRBL ones)
  // Output side (ConsoleServer): answers not written yet, and what a client that did
  // not read lost.
  std::string pending;
  bool wr_nonblocking = false;
  std::uint64_t dropped_lines = 0, dropped_bytes = 0;
  std::uint64_t dropped_unreported = 0;  ///< lines dropped since the client was last told
  ~FdTransport();
};

/// Open a pty (raw, no echo). "" or the error; t.path = slave path.
std::string open_pty(FdTransport& t);
/// Open a serial TTY in raw 8N1 at `baud`. "" or the error.
std::string open_serial(FdTransport& t, const std::string& path, int baud);
/// Write all of `s` (blocking, retries on EINTR/EAGAIN with a short poll). False on error.
bool write_all(int fd, const std::string& s);


/// Back-pressure: while more than this much output waits to be written to a client
/// (bytes), none of its lines runs; its answers are never thrown away. One answer may be
/// larger (`points`, `config`): it is queued whole.
inline constexpr std::size_t kMaxPendingOutput = 64 * 1024;
/// Asynchronous lines (`alarm:` / `program:` events) are dropped for a client whose
/// unwritten output exceeds this (it does not read), counted in its transport and in
/// `stats` (output_dropped_lines); it gets one `alarm: console output overflow` line once
/// it reads again. Answers to its lines are never dropped (see kMaxPendingOutput).
inline constexpr std::size_t kMaxPendingEvents = 1024 * 1024;
/// The receive buffer per client: while this many complete lines of a client wait to run,
/// the server reads nothing more from it (the rest stays in the kernel; the sender's
/// writes block). Each read takes at most kReadChunk bytes, so a client holds at most
/// kMaxQueuedLines + kReadChunk lines in the server.
inline constexpr std::size_t kMaxQueuedLines = 256;
inline constexpr std::size_t kReadChunk = 4096;
/// Lines one round runs at most per client (one per client per turn, every transport
/// read between two lines).
inline constexpr int kTurnsPerRound = 16;

/// The console thread's work over several transports. Each round: read every
/// transport (realtime characters act at once, before any line runs or any output is
/// written), then run lines one at a time round-robin, one line per client per turn and
/// at most kTurnsPerRound turns, with a fresh read of every transport between two lines,
/// then write to each client only what it takes without blocking. One client's backlog
/// never delays another client's realtime characters by more than the line being run.
/// A client is read only while fewer than kMaxQueuedLines of its lines wait, and its lines
/// run only while less than kMaxPendingOutput of its output waits (back-pressure): every
/// line gets exactly one answer, and memory stays bounded whatever a client sends.
class ConsoleServer {
 public:
  ConsoleServer(Console& console, const std::vector<FdTransport*>& ts);
  /// One round, waiting up to timeout_ms for input. False when exit_on_eof and
  /// stdin has ended and its last line has been answered.
  bool round(int timeout_ms, bool exit_on_eof);
  Session& session(std::size_t i) { return sessions_[i]; }

 private:
  void sweep(int timeout_ms);
  void queue_output(std::size_t i);
  void queue_events(std::size_t i, const std::string& ev);
  void write_some(std::size_t i);
  /// Session i ran `quit` / `exit`: on stdin as at end of input (armfw then ends); on any
  /// other transport the client's session starts afresh (its jog stopped) and it stays connected.
  void end_session(std::size_t i);
  /// Lines of session i may run now (its output is not backed up).
  bool may_run(std::size_t i) const;
  Console& console_;
  std::vector<FdTransport*> ts_;
  std::vector<Session> sessions_;
  std::vector<pollfd> pfds_;
  bool more_ = false;  ///< the last round stopped with lines left to run: the next does not wait for input
};

/// The console loop (console thread): ConsoleServer rounds until `quit` / `stop`
/// is set, or (exit_on_eof) once stdin reached end of file and its last line finished.
void serve_consoles(Console& console, const std::vector<FdTransport*>& ts, bool exit_on_eof,
                    const volatile std::sig_atomic_t* quit, const std::atomic<bool>* stop = nullptr);

/// Console over CAN (ISO-TP). Its own thread owns its own CAN endpoint (a
/// SocketCAN socket, or an endpoint of the in-process SimBus) and an ISO-TP
/// endpoint (hal/isotp.hpp) and bridges it to a local socketpair, whose other
/// end is an ordinary FdTransport for serve_consoles(): the console sees the
/// same byte stream as on a serial line, and only the console thread talks to
/// the control thread (through the Controller's SPSC queues).
///
/// Framing: each ISO-TP message received is one command line (a trailing
/// newline is added when missing) or realtime characters (a message of only
/// ?, !, ~, Ctrl-X is passed as is, so `echo 18 | isotpsend ...` is an e-stop);
/// answers go out as ISO-TP messages of whole lines, up to 4095 bytes each.
struct CanConsoleConfig {
  std::string iface;                ///< "sim" (needs the in-process bus) or a SocketCAN interface
  std::uint32_t rx_id = 0x7E0;      ///< armfw receives requests on this id
  std::uint32_t tx_id = 0x7E8;      ///< and answers on this one
};

class CanConsole {
 public:
  CanConsole() = default;
  ~CanConsole();
  CanConsole(const CanConsole&) = delete;
  CanConsole& operator=(const CanConsole&) = delete;
  /// Open the CAN endpoint (sim: a new endpoint on `sim`, which must be non-null),
  /// start the bridge thread, fill `t` (name "can"). "" or the error.
  std::string open(const CanConsoleConfig& cfg, hal::SimBus* sim, FdTransport& t);
  void stop();
  /// ISO-TP counters (read after stop(), or racy while running: diagnostics only).
  hal::IsoTpStats stats() const { return iso_ ? iso_->stats() : hal::IsoTpStats{}; }

 private:
  void run();
  CanConsoleConfig cfg_;
  hal::MonotonicClock clock_;
  std::unique_ptr<hal::CanBus> bus_;
  std::unique_ptr<hal::IsoTpEndpoint> iso_;
  std::thread th_;
  std::atomic<bool> stop_{false};
  int fd_ = -1;  ///< the bridge thread's end of the socketpair
};

/// Message bytes -> console bytes: a trailing newline is added to a command line
/// that lacks one; realtime-only messages pass unchanged. Exposed for tests.
std::string isotp_message_to_console(const std::uint8_t* data, std::size_t n);

}  // namespace servoarm::fw
