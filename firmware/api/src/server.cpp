// SPDX-License-Identifier: Apache-2.0
// The network API's server (server.hpp): libwebsockets' event loop on its own thread, one
// Client per connection (WebSocket or raw TCP), the cross-thread hand-over to the service
// thread (pump) and back. No JSON here: protocol.cpp parses and renders.
#include "servoarm/api/server.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <sys/socket.h>
#include <sys/eventfd.h>
#include <sys/stat.h>
#include <sys/timerfd.h>
#include <unistd.h>

#include <libwebsockets.h>
#include <openssl/ssl.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <deque>
#include <fstream>
#include <map>
#include <mutex>
#include <sstream>
#include <thread>
#include <utility>
#include <vector>

namespace servoarm::api {

namespace {

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

/// Equal without an early exit: the time taken does not depend on where they differ.
bool same_token(const std::string& a, const std::string& b) {
  const std::size_t n = std::max(a.size(), b.size());
  unsigned diff = a.size() == b.size() ? 0u : 1u;
  for (std::size_t i = 0; i < n; ++i) {
    const unsigned char x = i < a.size() ? static_cast<unsigned char>(a[i]) : 0;
    const unsigned char y = i < b.size() ? static_cast<unsigned char>(b[i]) : 0;
    diff |= static_cast<unsigned>(x ^ y);
  }
  return diff == 0;
}

enum class Role : std::uint8_t { none, observer, operator_ };
const char* role_name(Role r) {
  switch (r) {
    case Role::none: return "none";
    case Role::observer: return "observer";
    case Role::operator_: return "operator";
  }
  return "?";
}

struct Token {
  Role role;
  std::string token;
};

}  // namespace

struct Client {
  std::uint64_t id = 0;
  lws* wsi = nullptr;
  bool ws = false;
  Role role = Role::none;
  std::string rx;          ///< raw: bytes of the line being received; ws: the message's fragments
  bool skipping = false;   ///< the message being received is too long: dropped up to its end
  std::deque<std::string> out;
  std::size_t out_bytes = 0;
  bool reading = true;     ///< rx flow control
  std::uint64_t dropped = 0;
  double tokens = 0;       ///< the rate limit's bucket
  std::int64_t tokens_at = 0;
  std::int64_t state_period = 0, state_due = 0;  ///< ns; 0: not subscribed
  bool events = false;
};

struct Job {
  std::uint64_t client;
  ApiRequest rq;
};

struct ApiServer::Impl {
  ApiConfig cfg;
  fw::Controller& ctl;
  const kin::Chain& chain;
  kin::JointLimits limits;
  std::vector<Token> tokens;
  lws_context* ctx = nullptr;
  lws_vhost* ws_vh = nullptr;
  lws_vhost* raw_vh = nullptr;
  lws_http_mount web_mount{};  ///< the static files of cfg.web_root (must outlive the vhost)
  bool web = false;
  std::thread th;
  std::atomic<bool> quit{false};
  int efd = -1;
  std::uint64_t next_client = 1;
  std::map<std::uint64_t, std::unique_ptr<Client>> clients;  // network thread only
  std::atomic<std::uint64_t> controller{0};                  // written by the network thread only
  int tfd = -1;             ///< timerfd of the state streams (µs resolution; poll's ms would halve 1 kHz)
  bool timer_armed = false;
  // network thread -> service thread
  std::mutex in_mu;
  std::deque<Job> inbox;
  // service thread -> network thread
  std::mutex out_mu;
  std::vector<std::pair<std::uint64_t, std::string>> results;
  std::vector<std::string> event_lines;
  std::uint64_t event_seq = 0;      ///< the service thread's place in the event stream
  bool event_seq_set = false;
  std::uint64_t events_missed = 0;
  std::atomic<int> n_event_subs{0};
  // the service's part of the state samples (taken on the service thread in pump())
  std::mutex snap_mu;
  ServiceSnapshot snap;
  ServiceSnapshot snapshot() {
    std::lock_guard<std::mutex> l(snap_mu);
    return snap;
  }
  // stats
  mutable std::mutex st_mu;
  ApiStats st;

  Impl(const ApiConfig& c, fw::Controller& k, const kin::Chain& ch, const kin::JointLimits& l)
      : cfg(c), ctl(k), chain(ch), limits(l) {
    snap.safety_on = cfg.safety_on;  // until the service thread's first snapshot
    snap.safety_checksum = cfg.safety_checksum;
  }

  // --- network thread ---------------------------------------------------------------------
  Client* client_of(lws* wsi) {
    auto** pc = static_cast<Client**>(lws_wsi_user(wsi));
    return pc != nullptr ? *pc : nullptr;
  }

  bool open_client(lws* wsi, bool ws) {
    auto** pc = static_cast<Client**>(lws_wsi_user(wsi));
    if (static_cast<int>(clients.size()) >= cfg.max_clients || pc == nullptr) {
      std::lock_guard<std::mutex> l(st_mu);
      ++st.refused_connections;
      return false;
    }
    auto c = std::make_unique<Client>();
    c->id = next_client++;
    c->wsi = wsi;
    c->ws = ws;
    c->role = tokens.empty() ? Role::operator_ : Role::none;
    c->tokens = cfg.max_rate_hz;
    c->tokens_at = now_ns();
    *pc = c.get();
    // The kernel keeps little of a slow client's output: what it does not take waits in the
    // outbox, where the client's limit counts it and its stream drops (rather than megabytes
    // of stale samples in a socket buffer).
    const int sndbuf = static_cast<int>(std::min<std::size_t>(cfg.client_buffer, 256 * 1024));
    ::setsockopt(lws_get_socket_fd(wsi), SOL_SOCKET, SO_SNDBUF, &sndbuf, sizeof sndbuf);
    clients.emplace(c->id, std::move(c));
    std::lock_guard<std::mutex> l(st_mu);
    ++st.connections;
    st.clients = static_cast<int>(clients.size());
    return true;
  }

  void close_client(lws* wsi) {
    Client* c = client_of(wsi);
    if (c == nullptr) return;
    *static_cast<Client**>(lws_wsi_user(wsi)) = nullptr;
    const std::uint64_t id = c->id;
    if (c->events) n_event_subs.fetch_sub(1);
    clients.erase(id);
    if (controller == id) set_controller(0);
    std::lock_guard<std::mutex> l(st_mu);
    st.clients = static_cast<int>(clients.size());
  }

  void set_controller(std::uint64_t id) {
    controller = id;
    const std::string line = control_line(id);
    for (auto& [cid, c] : clients)
      if (c->role != Role::none) send(*c, line, true);
  }

  /// Queue a line for the client. Stream lines (`answer` false) are dropped, and counted, while
  /// its outbox is full; answers never are, but the client is not read while they fill it.
  void send(Client& c, std::string line, bool answer) {
    if (!answer && c.out_bytes >= cfg.client_buffer) {
      ++c.dropped;
      lws_callback_on_writable(c.wsi);  // (a write lws buffered may have taken the last request)
      std::lock_guard<std::mutex> l(st_mu);
      ++st.dropped;
      return;
    }
    c.out_bytes += line.size() + 1;
    c.out.push_back(std::move(line));
    if (c.reading && c.out_bytes >= cfg.client_buffer) {
      c.reading = false;
      lws_rx_flow_control(c.wsi, 0);
    }
    lws_callback_on_writable(c.wsi);
  }

  void answer_error(Client& c, const ApiRequest& rq, std::string_view code, std::string_view msg) {
    {
      std::lock_guard<std::mutex> l(st_mu);
      ++st.errors;
    }
    send(c, error_line(rq.has_id, rq.id, code, msg), true);
  }

  bool take_rate_token(Client& c) {
    const std::int64_t t = now_ns();
    c.tokens = std::min(cfg.max_rate_hz, c.tokens + static_cast<double>(t - c.tokens_at) * 1e-9 * cfg.max_rate_hz);
    c.tokens_at = t;
    if (c.tokens < 1) return false;
    c.tokens -= 1;
    return true;
  }

  void on_message(Client& c, std::string_view text) {
    {
      std::lock_guard<std::mutex> l(st_mu);
      ++st.messages;
    }
    ApiRequest rq;
    const ParseError pe = parse_request(text, rq);
    if (!pe.code.empty()) return answer_error(c, rq, pe.code, pe.message);
    const MessageSpec& m = *rq.spec;
    if (m.gate != Gate::stop && !take_rate_token(c))
      return answer_error(c, rq, to_string(ApiError::rate_limited), "more than api.max_rate_hz messages per second");
    if (m.gate != Gate::open && c.role == Role::none)
      return answer_error(c, rq, to_string(ApiError::unauthenticated), "send hello with a token first");
    if ((m.gate == Gate::operator_ || m.gate == Gate::control) && c.role != Role::operator_)
      return answer_error(c, rq, to_string(ApiError::forbidden), std::string(m.name) + ": an observer may not send it");
    if (m.gate == Gate::control && controller != c.id) {
      if (controller == 0) return answer_error(c, rq, to_string(ApiError::not_in_control), std::string(m.name) + ": take_control first");
      return answer_error(c, rq, to_string(ApiError::controlled),
                          std::string(m.name) + ": client " + std::to_string(controller.load()) + " holds control");
    }
    if (m.where == Where::service) {
      {
        std::lock_guard<std::mutex> l(in_mu);
        if (m.gate == Gate::stop) inbox.push_front(Job{c.id, std::move(rq)});  // a stop runs first
        else inbox.push_back(Job{c.id, std::move(rq)});
      }
      const std::uint64_t one = 1;
      [[maybe_unused]] const ssize_t w = ::write(efd, &one, sizeof one);
      return;
    }
    session(c, rq);
  }

  void session(Client& c, const ApiRequest& rq) {
    const std::string_view name = rq.spec->name;
    if (name == "hello") {
      const ArgValue* tok = rq.arg("token");
      if (!tokens.empty()) {
        Role found = Role::none;
        for (const Token& t : tokens)  // every entry compared: no early exit
          if (tok->present && same_token(tok->text, t.token) && found == Role::none) found = t.role;
        if (found == Role::none) return answer_error(c, rq, to_string(ApiError::unauthenticated), "token not accepted");
        c.role = found;
      }
      HelloInfo h;
      h.robot = cfg.robot;
      h.rate_hz = cfg.rate_hz;
      h.role = role_name(c.role);
      h.client = c.id;
      h.controller = controller.load();
      const ServiceSnapshot sn = snapshot();  // the envelope in force (a confirmed change's checksum)
      h.safety_on = sn.safety_on;
      h.safety_checksum = sn.safety_checksum;
      return send(c, hello_line(rq, h, chain, limits), true);
    }
    if (name == "subscribe" || name == "unsubscribe") {
      const std::string& topic = rq.arg("topic")->text;
      const bool on = name == "subscribe";
      if (topic == "state") {
        const ArgValue* r = rq.arg("rate_hz");
        const double hz = r != nullptr && r->present ? r->num : 50.0;
        if (on && hz > cfg.rate_hz)
          return answer_error(c, rq, fw::to_string(fw::CmdError::out_of_range),
                              "rate_hz: above the control rate " + std::to_string(static_cast<int>(cfg.rate_hz)));
        c.state_period = on ? static_cast<std::int64_t>(1e9 / hz) : 0;
        c.state_due = now_ns();
        if (on) schedule();
      } else if (topic == "events") {
        if (on != c.events) n_event_subs.fetch_add(on ? 1 : -1);
        c.events = on;
      } else {
        return answer_error(c, rq, fw::to_string(fw::CmdError::bad_option), "topic: state or events");
      }
      return send(c, ok_line(rq), true);
    }
    if (name == "state") {
      const ServiceSnapshot sn = snapshot();
      std::string s = state_line(ctl.telemetry(), cfg.rate_hz, chain, c.dropped, &sn);
      return send(c, ok_line(rq, s), true);
    }
    if (name == "take_control") {
      if (controller != 0 && controller != c.id)
        return answer_error(c, rq, to_string(ApiError::controlled), "client " + std::to_string(controller.load()) + " holds control");
      send(c, ok_line(rq), true);
      if (controller != c.id) set_controller(c.id);
      return;
    }
    if (name == "release_control") {
      send(c, ok_line(rq), true);
      if (controller == c.id) set_controller(0);
      return;
    }
    answer_error(c, rq, fw::to_string(fw::CmdError::internal), "no session handler");
  }

  /// A message begun and not ended (a slow-loris client holds a connection so): closed after
  /// cfg.partial_timeout_s unless it ends.
  void partial_timer(Client& c) {
    const bool partial = !c.rx.empty() || c.skipping;
    lws_set_timeout(c.wsi, partial ? PENDING_TIMEOUT_USER_OK : NO_PENDING_TIMEOUT, partial ? cfg.partial_timeout_s : 0);
  }

  void receive(Client& c, const char* data, std::size_t n, bool final_fragment) {
    receive_bytes(c, data, n, final_fragment);
    if (clients.count(c.id) != 0) partial_timer(c);
  }

  void receive_bytes(Client& c, const char* data, std::size_t n, bool final_fragment) {
    if (c.ws) {
      if (!c.skipping) {
        if (c.rx.size() + n > cfg.max_message) {
          c.skipping = true;
          c.rx.clear();
          ApiRequest none;
          answer_error(c, none, fw::to_string(fw::CmdError::overlong),
                       "message longer than api.max_message_kb (" + std::to_string(cfg.max_message) + " bytes)");
        } else {
          c.rx.append(data, n);
        }
      }
      if (final_fragment) {
        if (!c.skipping) on_message(c, c.rx);
        c.rx.clear();
        c.skipping = false;
      }
      return;
    }
    // raw TCP: newline-delimited
    std::size_t a = 0;
    while (a < n) {
      const void* nl = std::memchr(data + a, '\n', n - a);
      const std::size_t b = nl ? static_cast<std::size_t>(static_cast<const char*>(nl) - data) : n;
      if (!c.skipping) {
        if (c.rx.size() + (b - a) > cfg.max_message) {
          c.skipping = true;
          c.rx.clear();
          ApiRequest none;
          answer_error(c, none, fw::to_string(fw::CmdError::overlong),
                       "message longer than api.max_message_kb (" + std::to_string(cfg.max_message) + " bytes)");
        } else {
          c.rx.append(data + a, b - a);
        }
      }
      if (nl == nullptr) break;
      if (!c.skipping) {
        if (!c.rx.empty() && c.rx.back() == '\r') c.rx.pop_back();
        if (!c.rx.empty()) on_message(c, c.rx);
      }
      c.rx.clear();
      c.skipping = false;
      a = b + 1;
      if (c.wsi == nullptr) return;
    }
  }

  int writable(Client& c) {
    if (c.out.empty()) return 0;
    if (c.ws && lws_send_pipe_choked(c.wsi)) {
      lws_callback_on_writable(c.wsi);
      return 0;
    }
    if (c.ws) {
      std::string& s = c.out.front();
      std::vector<unsigned char> buf(LWS_PRE + s.size());
      std::memcpy(buf.data() + LWS_PRE, s.data(), s.size());
      const int w = lws_write(c.wsi, buf.data() + LWS_PRE, s.size(), LWS_WRITE_TEXT);
      if (w < static_cast<int>(s.size())) return -1;
      c.out_bytes -= s.size() + 1;
      c.out.pop_front();
    } else if (!cfg.tls_cert.empty()) {
      // Raw TCP in TLS: through lws_write, which encrypts (and keeps what the kernel does not take
      // of one write: it is written only when the connection is not choked, so that stays small).
      if (lws_send_pipe_choked(c.wsi)) {
        lws_callback_on_writable(c.wsi);
        return 0;
      }
      std::string s;  // several lines in one write
      while (!c.out.empty() && s.size() < 16 * 1024) {
        s += c.out.front();
        s += '\n';
        c.out_bytes -= c.out.front().size() + 1;
        c.out.pop_front();
      }
      std::vector<unsigned char> buf(LWS_PRE + s.size());
      std::memcpy(buf.data() + LWS_PRE, s.data(), s.size());
      if (lws_write(c.wsi, buf.data() + LWS_PRE, s.size(), LWS_WRITE_RAW) < static_cast<int>(s.size())) return -1;
    } else {
      // Raw TCP: written on the socket here, without lws_write, so what the kernel does not
      // take stays in this client's outbox (counted by its limit), never in a buffer of lws.
      std::string buf;  // several lines in one write
      while (!c.out.empty() && buf.size() < 64 * 1024) {
        buf += c.out.front();
        buf += '\n';
        c.out_bytes -= c.out.front().size() + 1;
        c.out.pop_front();
      }
      const ssize_t w = ::send(lws_get_socket_fd(c.wsi), buf.data(), buf.size(), MSG_DONTWAIT | MSG_NOSIGNAL);
      if (w < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) return -1;
      const std::size_t sent = w > 0 ? static_cast<std::size_t>(w) : 0;
      if (sent < buf.size()) {  // the rest goes first next time (as one entry: its own newline kept)
        std::string rest = buf.substr(sent);
        rest.pop_back();
        c.out_bytes += rest.size() + 1;
        c.out.push_front(std::move(rest));
      }
    }
    if (!c.reading && c.out_bytes < cfg.client_buffer / 2) {
      c.reading = true;
      lws_rx_flow_control(c.wsi, 1);
    }
    if (!c.out.empty()) lws_callback_on_writable(c.wsi);
    return 0;
  }

  /// Results and events from the service thread into the outboxes.
  void collect() {
    std::vector<std::pair<std::uint64_t, std::string>> res;
    std::vector<std::string> evs;
    {
      std::lock_guard<std::mutex> l(out_mu);
      res.swap(results);
      evs.swap(event_lines);
    }
    for (auto& [id, line] : res) {
      auto it = clients.find(id);
      if (it != clients.end()) send(*it->second, std::move(line), true);
    }
    if (!evs.empty())
      for (auto& [id, c] : clients)
        if (c->events)
          for (const std::string& e : evs) send(*c, e, false);
  }

  /// The state streams (the timer's tick): every client whose sample is due gets one.
  void tick() {
    const std::int64_t t = now_ns();
    bool any = false;
    fw::Telemetry tel;
    ServiceSnapshot sn;
    bool have = false;
    for (auto& [id, c] : clients) {
      if (c->state_period == 0) continue;
      any = true;
      if (c->state_due - c->state_period / 2 <= t) {  // due within half a period: this tick
        if (!have) tel = ctl.telemetry(), sn = snapshot(), have = true;
        send(*c, state_line(tel, cfg.rate_hz, chain, c->dropped, &sn), false);
        c->state_due += c->state_period;
        if (c->state_due <= t) c->state_due = t + c->state_period;  // behind: skip, do not burst
      }
    }
    if (!any) arm_timer(false);
  }
  /// The state streams' tick: every control period while a client subscribes.
  void arm_timer(bool on) {
    if (on == timer_armed || tfd < 0) return;
    itimerspec its{};
    if (on) {
      const long ns = static_cast<long>(1e9 / cfg.rate_hz);
      its.it_interval.tv_nsec = ns;
      its.it_value.tv_nsec = ns;
    }
    ::timerfd_settime(tfd, 0, &its, nullptr);
    timer_armed = on;
  }
  void schedule() { arm_timer(true); }

  void run() {
    while (!quit.load()) lws_service(ctx, 0);
  }
};

namespace {

int callback(lws* wsi, lws_callback_reasons reason, void* user, void* in, size_t len) {
  lws_context* cx = lws_get_context(wsi);
  auto* self = cx ? static_cast<ApiServer::Impl*>(lws_context_user(cx)) : nullptr;
  if (self == nullptr) return 0;
  switch (reason) {
    case LWS_CALLBACK_EVENT_WAIT_CANCELLED:
      self->collect();
      return 0;
    case LWS_CALLBACK_RAW_RX_FILE: {  // the state streams' timerfd
      std::uint64_t n = 0;
      [[maybe_unused]] const ssize_t r = ::read(self->tfd, &n, sizeof n);
      self->tick();
      return 0;
    }
    case LWS_CALLBACK_RAW_ADOPT_FILE:
    case LWS_CALLBACK_RAW_CLOSE_FILE:
      return 0;
    case LWS_CALLBACK_ESTABLISHED:
    case LWS_CALLBACK_RAW_ADOPT:
      return self->open_client(wsi, reason == LWS_CALLBACK_ESTABLISHED) ? 0 : -1;
    case LWS_CALLBACK_RECEIVE:
    case LWS_CALLBACK_RAW_RX: {
      Client* c = self->client_of(wsi);
      if (c == nullptr) return -1;
      const bool final_fragment = reason == LWS_CALLBACK_RAW_RX || (lws_is_final_fragment(wsi) && lws_remaining_packet_payload(wsi) == 0);
      self->receive(*c, static_cast<const char*>(in), len, final_fragment);
      return 0;
    }
    case LWS_CALLBACK_SERVER_WRITEABLE:
    case LWS_CALLBACK_RAW_WRITEABLE: {
      Client* c = self->client_of(wsi);
      return c == nullptr ? -1 : self->writable(*c);
    }
    case LWS_CALLBACK_CLOSED:
    case LWS_CALLBACK_RAW_CLOSE:
      self->close_client(wsi);
      return 0;
    default:
      break;
  }
  return lws_callback_http_dummy(wsi, reason, user, in, len);
}

const lws_protocols kWsProtocols[] = {
    {"servoarm", callback, sizeof(Client*), 4096, 0, nullptr, 0},
    {nullptr, nullptr, 0, 0, 0, nullptr, 0},
};
const lws_protocols kRawProtocols[] = {
    {"servoarm-raw", callback, sizeof(Client*), 4096, 0, nullptr, 0},
    {nullptr, nullptr, 0, 0, 0, nullptr, 0},
};

std::string load_tokens(const std::string& path, std::vector<Token>& out) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return "api.tokens_file: " + path + ": " + std::strerror(errno);
  if ((st.st_mode & (S_IROTH | S_IWOTH)) != 0)
    return "api.tokens_file: " + path + ": readable or writable by others (chmod o-rw)";
  if (st.st_size > 1024 * 1024) return "api.tokens_file: " + path + ": larger than 1 MiB";
  std::ifstream f(path);
  if (!f) return "api.tokens_file: " + path + ": cannot be read";
  std::string line;
  int n = 0;
  while (std::getline(f, line)) {
    ++n;
    std::istringstream ls(line);
    std::string role, tok, extra;
    ls >> role;
    if (role.empty() || role[0] == '#') continue;
    ls >> tok >> extra;
    const std::string at = "api.tokens_file: " + path + ":" + std::to_string(n) + ": ";
    if (role != "observer" && role != "operator") return at + "role must be observer or operator";
    if (tok.size() < 16) return at + "a token has at least 16 characters";
    if (!extra.empty()) return at + "expected \"<role> <token>\"";
    out.push_back({role == "operator" ? Role::operator_ : Role::observer, tok});
  }
  if (out.empty()) return "api.tokens_file: " + path + ": no tokens";
  return "";
}

}  // namespace

ApiServer::ApiServer(const ApiConfig& cfg, fw::Controller& ctl, const kin::Chain& chain, const kin::JointLimits& limits)
    : impl_(std::make_unique<Impl>(cfg, ctl, chain, limits)) {}

ApiServer::~ApiServer() { stop(); }

std::string ApiServer::start() {
  Impl& s = *impl_;
  if (s.ctx != nullptr) return "";
  if (s.cfg.ws_port < 0 && s.cfg.tcp_port < 0) return "api: no port (api.ws_port and api.tcp_port are off)";
  if (!s.cfg.tokens_file.empty()) {
    const std::string e = load_tokens(s.cfg.tokens_file, s.tokens);
    if (!e.empty()) return e;
  } else if (!is_loopback(s.cfg.bind)) {
    return "api.bind = " + s.cfg.bind + ": beyond loopback only with api.tokens_file";
  }
  const bool tls = !s.cfg.tls_cert.empty() || !s.cfg.tls_key.empty();
  if (tls) {
    if (s.cfg.tls_cert.empty() || s.cfg.tls_key.empty()) return "api: TLS needs both api.tls_cert and api.tls_key";
    for (const auto& [key, path] : {std::pair<const char*, const std::string&>{"api.tls_cert", s.cfg.tls_cert},
                                    std::pair<const char*, const std::string&>{"api.tls_key", s.cfg.tls_key}}) {
      const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
      if (fd < 0) return std::string(key) + " = " + path + ": " + std::strerror(errno);
      ::close(fd);
    }
  }
  lws_set_log_level(LLL_ERR, nullptr);
  lws_context_creation_info info;
  std::memset(&info, 0, sizeof info);
  info.options = LWS_SERVER_OPTION_EXPLICIT_VHOSTS | (tls ? LWS_SERVER_OPTION_DO_SSL_GLOBAL_INIT : 0);
  info.user = &s;
  info.port = CONTEXT_PORT_NO_LISTEN;
  s.ctx = lws_create_context(&info);
  if (s.ctx == nullptr) return "api: cannot create the server (libwebsockets)";
  const std::string iface = s.cfg.bind == "localhost" ? "127.0.0.1" : s.cfg.bind;
  auto vhost = [&](const char* name, int port, const lws_protocols* protos, bool raw) -> lws_vhost* {
    lws_context_creation_info v;
    std::memset(&v, 0, sizeof v);
    v.vhost_name = name;
    v.port = port;
    v.iface = iface.c_str();
    v.protocols = protos;
    v.user = &s;
    if (tls) {  // (libwebsockets serves TLS on a vhost only with this option in the vhost's own info)
      v.options |= LWS_SERVER_OPTION_DO_SSL_GLOBAL_INIT;
      v.ssl_cert_filepath = s.cfg.tls_cert.c_str();
      v.ssl_private_key_filepath = s.cfg.tls_key.c_str();
    }
    if (!raw && s.web) v.mounts = &s.web_mount;
    if (raw) {
      // TLS 1.2 at most on the raw TCP port: with libwebsockets 4.1 (Debian 12) its raw-socket
      // role lets about one TLS 1.3 connection in 15 stall after the client's handshake (the
      // first line is never answered; libwebsockets closes the connection after 5 s); with
      // TLS 1.2 none of 180 did (fw_python_client's TlsTest connects 60 times).
      if (tls) v.ssl_options_set = SSL_OP_NO_TLSv1_3;
      v.options |= LWS_SERVER_OPTION_ADOPT_APPLY_LISTEN_ACCEPT_CONFIG;
      v.listen_accept_role = "raw-skt";
      v.listen_accept_protocol = "servoarm-raw";
    }
    return lws_create_vhost(s.ctx, &v);
  };
  // the pendant's files: GET on the WebSocket port; a request that is not a WebSocket upgrade
  // gets a file of the folder (libwebsockets refuses paths leaving it and sends 404 for others)
  struct stat wst {};
  s.web = s.cfg.ws_port >= 0 && !s.cfg.web_root.empty() && ::stat((s.cfg.web_root + "/index.html").c_str(), &wst) == 0;
  if (s.web) {
    std::memset(&s.web_mount, 0, sizeof s.web_mount);
    s.web_mount.mountpoint = "/";
    s.web_mount.mountpoint_len = 1;
    s.web_mount.origin = s.cfg.web_root.c_str();
    s.web_mount.def = "index.html";
    s.web_mount.origin_protocol = LWSMPRO_FILE;
    s.web_mount.cache_max_age = 0;
  }
  std::string err;
  const std::string tls_why = tls ? ", TLS: is api.tls_cert a PEM certificate and api.tls_key its key?" : "";
  if (s.cfg.ws_port >= 0 && (s.ws_vh = vhost("ws", s.cfg.ws_port, kWsProtocols, false)) == nullptr)
    err = "api: cannot listen on " + s.cfg.bind + ":" + std::to_string(s.cfg.ws_port) + " (WebSocket" + tls_why + ")";
  if (err.empty() && s.cfg.tcp_port >= 0 && (s.raw_vh = vhost("tcp", s.cfg.tcp_port, kRawProtocols, true)) == nullptr)
    err = "api: cannot listen on " + s.cfg.bind + ":" + std::to_string(s.cfg.tcp_port) + " (TCP" + tls_why + ")";
  if (err.empty()) {
    s.efd = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
    if (s.efd < 0) err = std::string("api: eventfd: ") + std::strerror(errno);
  }
  if (err.empty()) {
    s.tfd = ::timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC);
    lws_sock_file_fd_type fd;
    fd.filefd = s.tfd;
    if (s.tfd < 0 || lws_adopt_descriptor_vhost(s.ws_vh ? s.ws_vh : s.raw_vh, LWS_ADOPT_RAW_FILE_DESC, fd,
                                                 s.ws_vh ? "servoarm" : "servoarm-raw", nullptr) == nullptr)
      err = "api: cannot start the state streams' timer";
  }
  if (!err.empty()) {
    lws_context_destroy(s.ctx);
    s.ctx = nullptr;
    s.ws_vh = s.raw_vh = nullptr;
    if (s.efd >= 0) ::close(s.efd);
    if (s.tfd >= 0) ::close(s.tfd);
    s.efd = s.tfd = -1;
    return err;
  }
  s.quit = false;
  s.th = std::thread([&s] { s.run(); });
  return "";
}

void ApiServer::stop() {
  Impl& s = *impl_;
  if (s.ctx == nullptr) return;
  s.quit = true;
  lws_cancel_service(s.ctx);
  if (s.th.joinable()) s.th.join();
  lws_context_destroy(s.ctx);
  s.ctx = nullptr;
  s.ws_vh = s.raw_vh = nullptr;
  s.clients.clear();
  if (s.efd >= 0) ::close(s.efd);
  s.efd = -1;
  if (s.tfd >= 0) ::close(s.tfd);
  s.tfd = -1;
  s.timer_armed = false;
}

int ApiServer::ws_port() const { return impl_->ws_vh ? lws_get_vhost_listen_port(impl_->ws_vh) : -1; }
bool ApiServer::serves_web() const { return impl_->ws_vh != nullptr && impl_->web; }
int ApiServer::tcp_port() const { return impl_->raw_vh ? lws_get_vhost_listen_port(impl_->raw_vh) : -1; }
int ApiServer::wake_fd() const { return impl_->efd; }

ApiStats ApiServer::stats() const {
  std::lock_guard<std::mutex> l(impl_->st_mu);
  return impl_->st;
}

std::size_t ApiServer::pump(ServiceContext& cx) {
  Impl& s = *impl_;
  if (s.ctx == nullptr) return 0;
  if (s.efd >= 0) {
    std::uint64_t v = 0;
    [[maybe_unused]] const ssize_t r = ::read(s.efd, &v, sizeof v);
  }
  std::size_t ran = 0;
  std::vector<std::pair<std::uint64_t, std::string>> res;
  for (;;) {
    Job job;
    {
      std::lock_guard<std::mutex> l(s.in_mu);
      if (s.inbox.empty()) break;
      job = std::move(s.inbox.front());
      s.inbox.pop_front();
    }
    res.emplace_back(job.client, execute(cx, job.rq));
    ++ran;
  }
  // the service's new events, for the subscribers (the service is polled here as by the console)
  std::vector<std::string> evs;
  if (cx.svc != nullptr) {
    cx.svc->tick();  // its periodic work, as the console's poll does: a program started here runs on
    ServiceSnapshot sn;
    sn.program = cx.svc->program_status();
    sn.feed_pct = cx.svc->feed_override();
    sn.tool = cx.svc->tool(cx.svc->active_tool()).name;
    sn.tool_pose = cx.svc->tool(cx.svc->active_tool()).pose;
    for (std::size_t i = 0; i < cx.svc->output_count(); ++i)
      sn.outputs.emplace_back(cx.svc->settings().outputs[i].name, cx.svc->output_on(i));
    sn.frame = cx.svc->frame(cx.svc->active_frame()).name;
    if (cx.stream != nullptr) sn.stream = cx.stream->stats();
    sn.safety_on = s.cfg.safety_on;
    sn.safety_checksum = s.cfg.safety_checksum;
    if (cx.svc->settings().safety.enabled) sn.safety_on = true, sn.safety_checksum = cx.svc->settings().safety_checksum;
    {
      std::lock_guard<std::mutex> l(s.snap_mu);
      s.snap = std::move(sn);
    }
    cx.svc->poll_events();
    if (!s.event_seq_set) {
      s.event_seq = cx.svc->next_event_seq() - 1;
      s.event_seq_set = true;
    }
    if (cx.svc->next_event_seq() - 1 > s.event_seq) {
      const fw::EventBatch b = cx.svc->events_since(s.event_seq);
      s.events_missed += b.missed;
      for (const fw::ArmEvent& e : b.events) {
        if (s.n_event_subs.load() > 0) evs.push_back(event_line(e, cx.svc->event_detail(e), s.events_missed));
        s.event_seq = e.seq;
      }
    }
  }
  if (!res.empty() || !evs.empty()) {
    {
      std::lock_guard<std::mutex> l(s.out_mu);
      for (auto& r : res) s.results.push_back(std::move(r));
      for (auto& e : evs) s.event_lines.push_back(std::move(e));
    }
    lws_cancel_service(s.ctx);
  }
  return ran;
}

std::uint64_t ApiServer::controller() const { return impl_->controller.load(); }

bool is_loopback(const std::string& addr) {
  if (addr == "localhost" || addr == "::1") return true;
  in_addr a{};
  return inet_pton(AF_INET, addr.c_str(), &a) == 1 && (ntohl(a.s_addr) >> 24) == 127;
}

}  // namespace servoarm::api
