// SPDX-License-Identifier: Apache-2.0
#pragma once
// The network API of armfw (docs/api.md): the arm service on a WebSocket port and on a plain TCP
// port of newline-delimited JSON, served by one non-real-time thread.
//
// Library: libwebsockets (Debian libwebsockets-dev 4.1): one C event loop (poll) serves every
// connection without a thread per client (500 connections are 500 entries of one poll set),
// WebSocket and raw TCP listeners side by side as two vhosts of one context, TLS where the
// package is built with it, static file mounts (a browser pendant's files) and timers
// (the state streams), and a thread-safe wake-up (lws_cancel_service). Boost.Beast would need
// an asio thread pool and much longer compile times; civetweb has no raw TCP channel.
//
// Threads:
// - the network thread (start()): accepts, reads, parses (protocol.hpp), authenticates, checks
//   the role and control, answers session messages, samples the telemetry for state streams,
//   writes. It never calls the arm service and never blocks on a client: each client has its own
//   bounded outbox; a client that does not read loses its own stream messages (counted, sent
//   as `dropped` in the next state sample) and, once its answers fill the outbox, is no longer
//   read until it drains (its requests wait in the kernel).
// - the service thread (the one that owns the ArmService: armfw's console thread) calls pump():
//   it runs the requests waiting (stop, hold, e-stop first), hands the results back, and passes
//   the service's new events to the subscribers. wake_fd() becomes readable when requests wait.
// The control thread is never touched: it sees the service's SPSC queues and publishes the
// telemetry through its seqlock, both as for the console.
#include <cstdint>
#include <memory>
#include <string>

#include "servoarm/api/protocol.hpp"

namespace servoarm::api {

struct ApiConfig {
  std::string bind = "127.0.0.1";  ///< listen address; beyond loopback only with tokens_file
  int ws_port = -1;                ///< WebSocket port; -1 off, 0 any free port (tests)
  int tcp_port = -1;               ///< newline-delimited JSON port; -1 off, 0 any free port
  std::string tokens_file;         ///< "<role> <token>" lines (role observer / operator); "" none
  std::size_t max_message = 64 * 1024;   ///< bytes of one message (a longer one is refused, overlong)
  double max_rate_hz = 2000;       ///< messages per second per client (stop, hold, estop exempt)
  int max_clients = 64;            ///< connections at once (more are closed at once)
  std::size_t client_buffer = 1024 * 1024;  ///< bytes of unsent output per client before its stream drops
  int partial_timeout_s = 10;      ///< a message begun and not ended within this: the connection is closed (slow loris)
  double rate_hz = 1000;           ///< the control rate (state streams at most this)
  std::string robot;               ///< hello's robot name
  /// A folder of static files (the browser pendant, docs/pendant.md) served over HTTP GET on the
  /// WebSocket port, index.html at "/"; "" serves none. The files hold no secret: what the page
  /// may do is decided by its WebSocket's token and role, as for every client.
  std::string web_root;
  /// TLS on both ports: the server's certificate (PEM, its chain after it) and its private key;
  /// both or neither ("": plain). A file that cannot be read or loaded refuses the start.
  std::string tls_cert;
  std::string tls_key;
  /// The safety envelope the service checks with ([safety], docs/safety.md; fixed at start):
  /// configured or not and its checksum, which hello tells every client.
  bool safety_on = false;
  std::uint32_t safety_checksum = 0;
};

/// Counters (diagnostics; read any time).
struct ApiStats {
  std::uint64_t connections = 0, refused_connections = 0, messages = 0, errors = 0, dropped = 0;
  int clients = 0;
};

/// A loopback address (127.0.0.0/8, ::1, localhost): a listener there is reachable from this
/// machine only.
bool is_loopback(const std::string& addr);

class ApiServer {
 public:
  ApiServer(const ApiConfig& cfg, fw::Controller& ctl, const kin::Chain& chain, const kin::JointLimits& limits);
  ~ApiServer();
  ApiServer(const ApiServer&) = delete;
  ApiServer& operator=(const ApiServer&) = delete;

  /// Check the configuration (a non-loopback bind needs a token file; the token file must be
  /// readable, not readable by others, and hold at least one valid line), open the listeners and
  /// start the network thread. "" or the error (one line).
  std::string start();
  /// Stop the network thread and close every connection (idempotent).
  void stop();
  /// The ports listened on (the free port chosen for 0), -1 when off.
  int ws_port() const;
  int tcp_port() const;
  /// Whether web_root is served (start() succeeded with a web_root that holds index.html).
  bool serves_web() const;
  /// Readable while requests wait for pump() (an eventfd); -1 before start().
  int wake_fd() const;
  /// Service thread: run every request waiting, hand back their results, pass new events on.
  /// Returns how many requests ran.
  std::size_t pump(ServiceContext& cx);
  ApiStats stats() const;
  /// The client holding control (0: nobody); read from any thread.
  std::uint64_t controller() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace servoarm::api
