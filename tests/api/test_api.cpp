// SPDX-License-Identifier: Apache-2.0
// The network API (firmware/api) against the real server on loopback sockets: an App with
// virtual drives and its control loop, the ApiServer on free ports, and a thread that pumps the
// service as armfw's console thread does. Clients are plain sockets: newline-delimited JSON on
// the TCP port, and a hand-written WebSocket handshake and frames on the WebSocket port.
#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "servoarm/api/foxglove.hpp"
#include "servoarm/api/server.hpp"
#include "servoarm/lang/ik_options.hpp"
#include "servoarm/rt/rt_loop.hpp"
#include "servoarm/service/stream.hpp"
#include "sim_app.hpp"
#include "sweep.hpp"
#include "text_regex.hpp"

// CppUTest last: its leak detector redefines new
#include "CppUTest/TestHarness.h"
#include "CppUTest/MemoryLeakWarningPlugin.h"

using namespace servoarm;
using namespace servoarm::fw;

namespace {

double now_s() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }

/// A newline-delimited JSON client on the TCP port.
struct Client {
  int fd = -1;
  std::string buf;
  explicit Client(int port) {
    fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(static_cast<std::uint16_t>(port));
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    CHECK(::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0);
    int one = 1;
    ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  }
  ~Client() { if (fd >= 0) ::close(fd); }
  void send_raw(const std::string& s) const {
    std::size_t off = 0;
    while (off < s.size()) {
      const ssize_t w = ::write(fd, s.data() + off, s.size() - off);
      if (w <= 0) return;
      off += static_cast<std::size_t>(w);
    }
  }
  void send(const std::string& line) const { send_raw(line + "\n"); }
  /// The next line, "" after `timeout_s` or when the server closed (`closed` set).
  std::string line(double timeout_s = 5, bool* closed = nullptr) {
    const double end = now_s() + timeout_s;
    for (;;) {
      const auto nl = buf.find('\n');
      if (nl != std::string::npos) {
        std::string l = buf.substr(0, nl);
        buf.erase(0, nl + 1);
        return l;
      }
      const double left = end - now_s();
      if (left <= 0) return "";
      pollfd p{fd, POLLIN, 0};
      if (::poll(&p, 1, static_cast<int>(left * 1000) + 1) <= 0) continue;
      char b[65536];
      const ssize_t r = ::read(fd, b, sizeof b);
      if (r <= 0) {
        if (closed) *closed = true;
        return "";
      }
      buf.append(b, static_cast<std::size_t>(r));
    }
  }
  /// The answer to request `id` (lines of the streams in between are skipped).
  std::string answer(int id, double timeout_s = 10) {
    const std::string key = "\"id\":" + std::to_string(id) + ",";
    const std::string key_end = "\"id\":" + std::to_string(id) + "}";
    const double end = now_s() + timeout_s;
    while (now_s() < end) {
      const std::string l = line(end - now_s());
      if (l.find(key) != std::string::npos || l.find(key_end) != std::string::npos) return l;
    }
    return "";
  }
  std::string ask(int id, const std::string& body) {
    send("{\"id\":" + std::to_string(id) + "," + body + "}");
    return answer(id);
  }
};

bool has(const std::string& s, const std::string& what) { return s.find(what) != std::string::npos; }
bool is_ok(const std::string& s) { return has(s, "\"ok\":true"); }
std::string error_of(const std::string& s) {
  const test::Regex e("\"error\":\"([a-z_]+)\"");
  const test::Groups m = e.search(s);
  return m.empty() ? "" : m[1];
}

struct Rig {
  test::SimApp app;
  std::unique_ptr<RtLoop> loop;
  std::unique_ptr<api::ApiServer> server;
  api::ServiceContext cx;
  std::unique_ptr<StreamService> stream;
  std::thread pump_th;
  std::atomic<bool> stop{false};

  explicit Rig(api::ApiConfig ac = {}, bool collision = false, std::vector<OutputConfig> outputs = {},
               double stream_deadman_s = 0.1, FwConfig cfg = {}) {
    cfg.outputs = std::move(outputs);
    cfg.collision = collision;  // the drives map their measured torque (6077h) then
    cfg.can = "sim";
    cfg.priority = 0;
    cfg.lock_memory = false;
    cfg.console_stdin = false;
    const int slow = servoarm::test::kSlowBuild ? 10 : 1;
    cfg.feedback_timeout_ms = 1000 * slow;
    cfg.heartbeat_timeout_ms = 1000 * slow;
    cfg.sdo_timeout_ms = 1000.0 * slow;  // the simulated drives answer on a thread a busy machine may stall
    cfg.following_error_deg = 30;
    std::string e = app.build(cfg);
    CHECK_TEXT(e.empty(), e.c_str());
    e = app.boot();
    CHECK_TEXT(e.empty(), e.c_str());
    LoopConfig lc;
    lc.priority = 0;
    lc.lock_memory = false;
    loop = std::make_unique<RtLoop>(*app.ctl, lc);
    CHECK(loop->start());
    if (ac.tcp_port < 0 && ac.ws_port < 0) ac.tcp_port = 0, ac.ws_port = 0;
    ac.rate_hz = app.cfg.rate_hz;
    ac.robot = app.cfg.robot;
    if (app.console->config().safety.enabled) {  // as armfw does
      ac.safety_on = true;
      ac.safety_checksum = app.console->config().safety_checksum;
    }
    server = std::make_unique<api::ApiServer>(ac, *app.ctl, app.chain, app.ctl->limits());
    e = server->start();
    CHECK_TEXT(e.empty(), e.c_str());
    cx.svc = &app.console->service();
    cx.ctl = app.ctl.get();
    cx.chain = &app.chain;
    cx.ik = firmware_ik_solver(app.ik_ready ? app.ik.get() : nullptr);
    StreamSettings ss;
    ss.max_step.assign(6, 0.5);
    ss.deadman_s = stream_deadman_s;
    stream = std::make_unique<StreamService>(app.console->service(), *app.ctl, ss);
    cx.stream = stream.get();
    cx.units = app.console->config().units;
    cx.programs_dir = app.console->config().programs_dir;
    pump_th = std::thread([this] {
      while (!stop) {
        pollfd p{server->wake_fd(), POLLIN, 0};
        ::poll(&p, 1, 10);
        server->pump(cx);
      }
    });
  }
  ~Rig() {
    stop = true;
    if (pump_th.joinable()) pump_th.join();
    server->stop();
    loop->stop();
    app.plant->stop_thread();
  }
  int port() const { return server->tcp_port(); }
  Telemetry tel() const { return app.ctl->telemetry(); }
  /// Take control, enable and wait until idle; the client holds control after.
  void enable(Client& c) {
    CHECK(is_ok(c.ask(900, "\"cmd\":\"take_control\"")));
    const std::string r = c.ask(901, "\"cmd\":\"enable\"");
    CHECK_TEXT(is_ok(r), r.c_str());
    for (int i = 0; i < 400 && tel().state != ArmState::idle; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    CHECK_EQUAL(static_cast<int>(ArmState::idle), static_cast<int>(tel().state));
  }
};

std::string tmp_file(const std::string& name, const std::string& text, mode_t mode) {
  const std::string p = "/tmp/servoarm_fw_api_" + std::to_string(::getpid()) + "_" + name;
  std::ofstream(p) << text;
  ::chmod(p.c_str(), mode);
  return p;
}

}  // namespace

// CppUTest's leak detector is not thread-safe: the server's and the pump's threads allocate
// while a test runs, so it is off in this group (each Rig joins its threads before it ends).
TEST_GROUP(FwApi) {
  void setup() override { MemoryLeakWarningPlugin::saveAndDisableNewDeleteOverloads(); }
  void teardown() override { MemoryLeakWarningPlugin::restoreNewDeleteOverloads(); }
};

// hello answers the protocol, the robot and its joints; a movej goes from request to queued
// motion and back with its id; the state sample carries the RT clock's cycle and the joints.
TEST(FwApi, RequestAndResultRoundTrip) {
  Rig rig;
  Client c(rig.port());
  const std::string h = c.ask(1, "\"cmd\":\"hello\"");
  CHECK_TEXT(is_ok(h), h.c_str());
  CHECK_TEXT(has(h, "\"protocol\":1"), h.c_str());
  CHECK_TEXT(has(h, "\"robot\":\"puma560\""), h.c_str());
  CHECK_TEXT(has(h, "\"role\":\"operator\""), h.c_str());
  CHECK_EQUAL(6, static_cast<int>(std::count(h.begin(), h.end(), '{')) - 3);  // the answer, units, safety, 6 joints
  CHECK_TEXT(has(h, "\"safety\":{\"checksum\":\"00000000\",\"enabled\":false}"), h.c_str());  // no envelope
  rig.enable(c);
  const std::string m = c.ask(2, "\"cmd\":\"movej\",\"q\":[0.2,0,0,0,0,0],\"speed_pct\":50");
  CHECK_TEXT(is_ok(m), m.c_str());
  CHECK_TEXT(has(m, "\"motion\":1"), m.c_str());
  for (int i = 0; i < 6000 && rig.tel().done_id < 1; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  CHECK_EQUAL(1u, rig.tel().done_id);
  const std::string s = c.ask(3, "\"cmd\":\"state\"");
  CHECK_TEXT(is_ok(s) && has(s, "\"cycle\":") && has(s, "\"q_cmd\":[0.2") && has(s, "\"tool\":"), s.c_str());
}

// hello shows the checksum of the safety configuration in force: after a confirmed run-time
// change (safety_stage + safety_confirm) the new one, not the one armfw started with.
TEST(FwApi, HelloShowsTheChecksumOfTheSafetyConfigurationInForce) {
  FwConfig cfg;
  cfg.safety_planes = {0, 0, 1, -500};
  cfg.safety_tcp_speed_mm_s = 250;
  Rig rig({}, false, {}, 0.1, cfg);
  Client c(rig.port());
  char start[9];
  std::snprintf(start, sizeof start, "%08X", static_cast<unsigned>(rig.app.console->config().safety_checksum));
  std::string h = c.ask(1, "\"cmd\":\"hello\"");
  CHECK_TEXT(has(h, std::string("\"checksum\":\"") + start + "\""), h.c_str());
  CHECK(is_ok(c.ask(2, "\"cmd\":\"take_control\"")));
  const std::string staged = c.ask(3, "\"cmd\":\"safety_stage\",\"changes\":\"tcp_speed_mm_s = 120\"");
  CHECK_TEXT(is_ok(staged), staged.c_str());
  const std::size_t at = staged.find("\"checksum\":\"");
  CHECK_TEXT(at != std::string::npos, staged.c_str());
  const std::string sum = staged.substr(at + 12, 8);
  const std::string done = c.ask(4, "\"cmd\":\"safety_confirm\",\"checksum\":\"" + sum + "\"");
  CHECK_TEXT(is_ok(done), done.c_str());
  // the service thread publishes it with its next snapshot (within its 10 ms poll)
  for (int i = 0; i < 400; ++i) {
    h = c.ask(5, "\"cmd\":\"hello\"");
    if (has(h, "\"checksum\":\"" + sum + "\"")) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  CHECK_TEXT(has(h, "\"checksum\":\"" + sum + "\""), ("want " + sum + ": " + h).c_str());
}

// The state stream carries what the drives measure: joint velocity (follows the commanded one
// during a move) and torque (a number where the drive maps 6077h, null where it does not; the
// first-order plant's drives report 0), beside the setpoints.
TEST(FwApi, StateCarriesMeasuredVelocityAndTorque) {
  Rig rig({}, true);
  Client c(rig.port());
  // the observer off (the first-order plant has no arm dynamics to match): 6077h stays mapped
  CHECK(is_ok(c.ask(3, "\"cmd\":\"take_control\"")));
  const std::string off = c.ask(4, "\"cmd\":\"collision\",\"on\":false");
  CHECK_TEXT(is_ok(off), off.c_str());
  rig.enable(c);
  CHECK(is_ok(c.ask(1, "\"cmd\":\"subscribe\",\"topic\":\"state\",\"rate_hz\":200")));
  CHECK(is_ok(c.ask(2, "\"cmd\":\"movej\",\"q\":[0.5,0,0,0,0,0],\"speed_pct\":50")));
  const test::Regex qd("\"qd\":\\[([-0-9.e]+)"), qdc("\"qd_cmd\":\\[([-0-9.e]+)"),
      tau("\"torque\":\\[((null|[-0-9.e]+)(,(null|[-0-9.e]+)){5})\\]");
  double max_qd = 0, max_qdc = 0, max_tau = 0;
  int samples = 0, with_tau = 0;
  const double end = now_s() + 20;
  while (now_s() < end && (rig.tel().done_id < 1 || samples < 50)) {
    const std::string l = c.line(1);
    if (!has(l, "\"topic\":\"state\"")) continue;
    ++samples;
    test::Groups m;
    CHECK_TEXT(!(m = qd.search(l)).empty(), l.c_str());
    max_qd = std::max(max_qd, std::fabs(std::stod(m[1])));
    CHECK_TEXT(!(m = qdc.search(l)).empty(), l.c_str());
    max_qdc = std::max(max_qdc, std::fabs(std::stod(m[1])));
    CHECK_TEXT(!(m = tau.search(l)).empty(), l.c_str());
    if (m[2] != "null") ++with_tau, max_tau = std::max(max_tau, std::fabs(std::stod(m[2])));
  }
  CHECK(samples >= 50);
  // the measured velocity is the drive's, not the setpoint's: near it at the top of the move
  CHECK_TEXT(max_qd > 0.5 * max_qdc && max_qd < 1.5 * max_qdc, (std::to_string(max_qd) + " " + std::to_string(max_qdc)).c_str());
  CHECK_TEXT(with_tau == samples, std::to_string(with_tau).c_str());
  CHECK_TEXT(std::isfinite(max_tau), std::to_string(max_tau).c_str());
  // drives that do not report their torque (6077h not mapped): null, not a measured 0
  Rig plain;
  Client p(plain.port());
  const std::string st = p.ask(5, "\"cmd\":\"state\"");
  CHECK_TEXT(has(st, "\"torque\":[null,null,null,null,null,null]"), st.c_str());
}

// Bad input: every message gets one error naming what is wrong, and nothing moves.
TEST(FwApi, BadInputIsRefusedAndNothingMoves) {
  api::ApiConfig ac;
  ac.max_message = 4096;
  Rig rig(ac);
  Client c(rig.port());
  rig.enable(c);
  const Telemetry before = rig.tel();
  struct Case {
    const char* line;
    const char* error;
  } cases[] = {
      {"{\"id\":10,\"cmd\":\"movej\",\"q\":[0.1,0,0", "bad_json"},
      {"[1,2,3]", "bad_json"},
      {"{\"id\":11,\"cmd\":\"movej\",\"q\":[NaN,0,0,0,0,0]}", "bad_json"},
      {"{\"id\":12,\"cmd\":\"movej\",\"q\":[Infinity,0,0,0,0,0]}", "bad_json"},
      {"{\"id\":13,\"cmd\":\"movej\",\"q\":[1e999,0,0,0,0,0]}", "bad_json"},
      {"{\"id\":14,\"cmd\":\"movej\",\"q\":\"0.1 0 0 0 0 0\"}", "bad_number"},
      {"{\"id\":15,\"cmd\":\"movej\",\"q\":[0.1,0,0,0,0]}", "arg_count"},
      {"{\"id\":16,\"cmd\":\"movej\",\"q\":[0.1,0,0,0,0,0],\"speed_pct\":500}", "out_of_range"},
      {"{\"id\":17,\"cmd\":\"movej\",\"q\":[0.1,0,0,0,0,0],\"speed\":5}", "bad_option"},
      {"{\"id\":18,\"cmd\":\"movej\"}", "arg_count"},
      {"{\"id\":19,\"cmd\":\"teleport\"}", "unknown_command"},
      {"{\"id\":20,\"cmd\":7}", "arg_count"},
      {"{\"id\":\"x\",\"cmd\":\"stop\"}", "bad_number"},
      {"{\"id\":21,\"cmd\":\"movej\",\"q\":[9,0,0,0,0,0]}", "limits"},
      {"{\"id\":22,\"cmd\":\"home\",\"joint\":1.5}", "bad_number"},
      {"{\"id\":23,\"cmd\":\"freedrive\",\"on\":1}", "bad_option"},
  };
  for (const Case& k : cases) {
    c.send(k.line);
    const std::string a = c.line();
    STRCMP_EQUAL_TEXT(k.error, error_of(a).c_str(), (std::string(k.line) + " -> " + a).c_str());
    CHECK_TEXT(has(a, "\"message\":\""), a.c_str());
  }
  // 10 MB in one line: one overlong error, then the next line is served
  c.send(std::string(10 * 1024 * 1024, 'x'));
  const std::string big = c.line(20);
  STRCMP_EQUAL_TEXT("overlong", error_of(big).c_str(), big.c_str());
  CHECK(is_ok(c.ask(30, "\"cmd\":\"state\"")));
  const Telemetry after = rig.tel();
  CHECK_EQUAL(0u, after.running_id);
  CHECK_EQUAL(0u, after.queued);
  for (int j = 0; j < 6; ++j) DOUBLES_EQUAL(before.q_cmd[static_cast<std::size_t>(j)], after.q_cmd[static_cast<std::size_t>(j)], 1e-12);
}

// With a token file: nothing but hello before a valid token; an observer sees the state but may
// not command or take control, and its stop runs; a wrong token is refused.
TEST(FwApi, TokensAndRoles) {
  api::ApiConfig ac;
  ac.tokens_file = tmp_file("tokens", "# role token\noperator op-0123456789abcdef\nobserver ob-0123456789abcdef\n", 0640);
  Rig rig(ac);
  Client op(rig.port()), ob(rig.port()), anon(rig.port());
  STRCMP_EQUAL("unauthenticated", error_of(anon.ask(1, "\"cmd\":\"state\"")).c_str());
  STRCMP_EQUAL("unauthenticated", error_of(anon.ask(2, "\"cmd\":\"take_control\"")).c_str());
  STRCMP_EQUAL("unauthenticated", error_of(anon.ask(3, "\"cmd\":\"stop\"")).c_str());
  STRCMP_EQUAL("unauthenticated", error_of(anon.ask(4, "\"cmd\":\"hello\",\"token\":\"op-0123456789abcdeX\"")).c_str());
  STRCMP_EQUAL("unauthenticated", error_of(anon.ask(5, "\"cmd\":\"hello\"")).c_str());
  CHECK(has(op.ask(6, "\"cmd\":\"hello\",\"token\":\"op-0123456789abcdef\""), "\"role\":\"operator\""));
  CHECK(has(ob.ask(7, "\"cmd\":\"hello\",\"token\":\"ob-0123456789abcdef\""), "\"role\":\"observer\""));
  CHECK(is_ok(ob.ask(8, "\"cmd\":\"state\"")));
  STRCMP_EQUAL("forbidden", error_of(ob.ask(9, "\"cmd\":\"take_control\"")).c_str());
  STRCMP_EQUAL("forbidden", error_of(ob.ask(10, "\"cmd\":\"enable\"")).c_str());
  STRCMP_EQUAL("not_in_control", error_of(op.ask(11, "\"cmd\":\"enable\"")).c_str());
  rig.enable(op);
  // the observer was told who holds control
  bool told = false;
  for (std::string l = ob.line(2); !l.empty() && !told; l = ob.line(0.5)) told = has(l, "\"topic\":\"control\"") && !has(l, "\"holder\":0");
  CHECK(told);
  STRCMP_EQUAL("forbidden", error_of(ob.ask(12, "\"cmd\":\"movej\",\"q\":[0.1,0,0,0,0,0]")).c_str());
  CHECK(is_ok(ob.ask(13, "\"cmd\":\"stop\"")));
  CHECK_EQUAL(0u, rig.tel().queued);
  ::unlink(ac.tokens_file.c_str());
}

// One client holds control and moves the arm; a second client's stop wins at once: the arm
// ramps to rest and the queue is dropped, and the holder is still the holder.
TEST(FwApi, AnotherClientsStopWins) {
  Rig rig;
  Client a(rig.port()), b(rig.port());
  rig.enable(a);
  STRCMP_EQUAL("controlled", error_of(b.ask(1, "\"cmd\":\"take_control\"")).c_str());
  STRCMP_EQUAL("controlled", error_of(b.ask(2, "\"cmd\":\"movej\",\"q\":[0.1,0,0,0,0,0]")).c_str());
  CHECK(is_ok(a.ask(3, "\"cmd\":\"movej\",\"q\":[1.5,0,0,0,0,0],\"speed_pct\":20")));
  CHECK(is_ok(a.ask(4, "\"cmd\":\"movej\",\"q\":[-1.5,0,0,0,0,0],\"speed_pct\":20")));
  for (int i = 0; i < 400 && rig.tel().running_id != 1; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const std::string s = b.ask(5, "\"cmd\":\"stop\"");
  CHECK_TEXT(is_ok(s), s.c_str());
  for (int i = 0; i < 400 && rig.tel().state != ArmState::idle; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  const Telemetry t = rig.tel();
  CHECK_EQUAL(static_cast<int>(ArmState::idle), static_cast<int>(t.state));
  CHECK_EQUAL(0u, t.queued);
  CHECK(t.q_cmd[0] < 1.0);  // stopped on the way, long before the first goal
  CHECK(is_ok(a.ask(6, "\"cmd\":\"movej\",\"q\":[0,0,0,0,0,0]")));  // still in control
}

// A subscriber that never reads loses its own samples (counted) and delays nobody: another
// client's round trips stay fast while the first one's outbox is full.
TEST(FwApi, ANonReadingSubscriberDelaysNobody) {
  api::ApiConfig ac;
  ac.client_buffer = 16 * 1024;
  ac.max_rate_hz = 1e6;  // the other client asks as fast as it can
  Rig rig(ac);
  Client slow(rig.port()), fast(rig.port());
  CHECK(is_ok(slow.ask(1, "\"cmd\":\"subscribe\",\"topic\":\"state\",\"rate_hz\":1000")));
  // round trips of the other client until the first one's socket buffers and outbox are full
  // and it has lost samples (at least 200, at most 20 s)
  double worst = 0;
  int n = 0;
  const double until = now_s() + 20;
  for (; (n < 200 || rig.server->stats().dropped == 0) && now_s() < until; ++n) {
    const double t0 = now_s();
    const std::string a = fast.ask(100 + n, "\"cmd\":\"state\"");
    CHECK_TEXT(is_ok(a), a.c_str());
    worst = std::max(worst, now_s() - t0);
  }
  // a client held up by the other's full buffers would wait until it reads (never, here);
  // 0.1 s (1 s under the sanitizers) is a busy machine's scheduling, not a wait for it
  CHECK_TEXT(worst < 0.1 * (servoarm::test::kSlowBuild ? 10 : 1), std::to_string(worst).c_str());
  CHECK_TEXT(rig.server->stats().dropped > 0, std::to_string(n).c_str());
  // once it reads, its samples say how many it lost
  std::uint64_t dropped = 0;
  int lines = 0;
  const double end = now_s() + 10;
  const test::Regex d("\"dropped\":([0-9]+)");
  while (dropped == 0 && now_s() < end) {
    const std::string l = slow.line(1);
    ++lines;
    test::Groups m;
    if (!(m = d.search(l)).empty()) dropped = std::stoull(m[1]);
  }
  CHECK_TEXT(dropped > 0, std::to_string(lines).c_str());
}

// The WebSocket port: an RFC 6455 handshake, a masked text frame, an unmasked answer.
TEST(FwApi, WebSocketRoundTrip) {
  Rig rig;
  Client c(rig.server->ws_port());
  c.send_raw("GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
             "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n");
  std::string head;
  for (std::string l = c.line(); !l.empty() && l != "\r"; l = c.line()) head += l + "\n";
  CHECK_TEXT(has(head, "101") && has(head, "s3pPLMBiTxaQ9kYGzzhZRbK+xOo="), head.c_str());
  const std::string msg = "{\"id\":1,\"cmd\":\"hello\"}";
  std::string f;
  f += static_cast<char>(0x81);
  f += static_cast<char>(0x80 | msg.size());
  const unsigned char mask[4] = {1, 2, 3, 4};
  for (unsigned char m : mask) f += static_cast<char>(m);
  for (std::size_t i = 0; i < msg.size(); ++i) f += static_cast<char>(msg[i] ^ mask[i % 4]);
  c.send_raw(f);
  const double end = now_s() + 5;
  while (c.buf.size() < 4 && now_s() < end) c.line(0.1);
  CHECK(c.buf.size() >= 4);
  CHECK_EQUAL(0x81, static_cast<unsigned char>(c.buf[0]));
  CHECK(has(c.buf, "\"protocol\":1"));
}

// Connections beyond api.max_clients are closed at once; messages beyond api.max_rate_hz are
// refused (rate_limited), a stop is not.
TEST(FwApi, ConnectionAndRateLimits) {
  api::ApiConfig ac;
  ac.max_clients = 3;
  ac.max_rate_hz = 50;
  Rig rig(ac);
  std::vector<std::unique_ptr<Client>> cs;
  for (int i = 0; i < 3; ++i) {
    cs.push_back(std::make_unique<Client>(rig.port()));
    CHECK(is_ok(cs.back()->ask(1, "\"cmd\":\"state\"")));
  }
  Client extra(rig.port());
  bool closed = false;
  extra.send("{\"id\":1,\"cmd\":\"state\"}");
  const std::string l = extra.line(3, &closed);
  CHECK_TEXT(closed && l.empty(), l.c_str());
  CHECK(rig.server->stats().refused_connections >= 1);
  Client& c = *cs[0];
  std::string burst;
  for (int i = 0; i < 200; ++i) burst += "{\"id\":" + std::to_string(1000 + i) + ",\"cmd\":\"state\"}\n";
  c.send_raw(burst);
  int limited = 0, ok = 0;
  for (int i = 0; i < 200; ++i) {
    const std::string a = c.line();
    if (error_of(a) == "rate_limited") ++limited;
    else if (is_ok(a)) ++ok;
  }
  CHECK_TEXT(limited >= 100 && ok >= 10 && ok + limited == 200, (std::to_string(ok) + " ok, " + std::to_string(limited)).c_str());
  CHECK(is_ok(c.ask(2000, "\"cmd\":\"stop\"")));
}

// A client that begins a message and never ends it (slow loris) is closed after
// api's partial timeout; 500 connections at once are served by the one thread, and a client's
// round trip stays fast among them.
TEST(FwApi, SlowLorisAndFiveHundredConnections) {
  api::ApiConfig ac;
  ac.partial_timeout_s = 1;
  ac.max_clients = 600;
  Rig rig(ac);
  Client loris(rig.port());
  loris.send_raw("{\"id\":1,\"cmd\":\"sta");
  bool closed = false;
  const double t0 = now_s();
  const std::string l = loris.line(5, &closed);
  CHECK_TEXT(closed && l.empty(), l.c_str());
  CHECK(now_s() - t0 > 0.5);
  std::vector<std::unique_ptr<Client>> many;
  for (int i = 0; i < 500; ++i) many.push_back(std::make_unique<Client>(rig.port()));
  for (auto& c : many) c->send("{\"id\":7,\"cmd\":\"hello\"}");
  int answered = 0;
  for (auto& c : many) answered += is_ok(c->answer(7)) ? 1 : 0;
  CHECK_EQUAL(500, answered);
  CHECK_EQUAL(500, rig.server->stats().clients);  // the slow-loris client is gone
  Client c(rig.port());
  double worst = 0;
  for (int i = 0; i < 50; ++i) {
    const double t = now_s();
    CHECK(is_ok(c.ask(100 + i, "\"cmd\":\"state\"")));
    worst = std::max(worst, now_s() - t);
  }
  CHECK_TEXT(worst < 0.1, std::to_string(worst).c_str());
}

// Beyond loopback only with a token file; a token file others may read is refused.
TEST(FwApi, StartRefusals) {
  api::ApiConfig ac;
  ac.tcp_port = 0;
  ac.bind = "0.0.0.0";
  // no controller is needed to refuse: the server checks before it listens
  test::SimApp app;
  FwConfig fc;
  fc.can = "sim";
  CHECK(app.build(fc).empty());
  api::ApiServer s1(ac, *app.ctl, app.chain, app.ctl->limits());
  const std::string e1 = s1.start();
  CHECK_TEXT(has(e1, "beyond loopback only with api.tokens_file"), e1.c_str());
  ac.tokens_file = tmp_file("open_tokens", "operator op-0123456789abcdef\n", 0644);
  api::ApiServer s2(ac, *app.ctl, app.chain, app.ctl->limits());
  const std::string e2 = s2.start();
  CHECK_TEXT(has(e2, "readable or writable by others"), e2.c_str());
  ::unlink(ac.tokens_file.c_str());
  ac.tokens_file = tmp_file("short_tokens", "operator short\n", 0600);
  api::ApiServer s3(ac, *app.ctl, app.chain, app.ctl->limits());
  const std::string e3 = s3.start();
  CHECK_TEXT(has(e3, ":1: a token has at least 16 characters"), e3.c_str());
  ::unlink(ac.tokens_file.c_str());
}

// Streaming over the API: a client in control streams targets (the first says start), the arm
// tracks them; a stop from another client ends the stream, and the targets that keep coming are
// refused (bad_state) and do not move the arm; the subscriber sees the stream's end as an event.
TEST(FwApi, StreamAndAStopFromAnotherClient) {
  Rig rig;
  Client a(rig.port()), b(rig.port());
  rig.enable(a);
  CHECK(is_ok(b.ask(1, "\"cmd\":\"subscribe\",\"topic\":\"events\"")));
  STRCMP_EQUAL("controlled", error_of(b.ask(2, "\"cmd\":\"stream\",\"q\":[0,0,0,0,0,0],\"start\":true")).c_str());
  STRCMP_EQUAL("bad_state", error_of(a.ask(3, "\"cmd\":\"stream\",\"q\":[0.01,0,0,0,0,0]")).c_str());
  double q0 = 0;
  for (int i = 0; i < 30; ++i) {
    q0 += 0.01;
    char m[128];
    std::snprintf(m, sizeof m, "\"cmd\":\"stream\",\"q\":[%.3f,0,0,0,0,0]%s", q0, i == 0 ? ",\"start\":true" : "");
    const std::string r = a.ask(10 + i, m);
    CHECK_TEXT(is_ok(r), r.c_str());
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  CHECK(rig.tel().streaming);
  CHECK(rig.tel().q_cmd[0] > 0.1);
  CHECK(is_ok(b.ask(100, "\"cmd\":\"stop\"")));
  for (int i = 0; i < 400 && rig.tel().state != ArmState::idle; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  const double rest = rig.tel().q_cmd[0];
  for (int i = 0; i < 10; ++i) {
    q0 += 0.01;
    char m[96];
    std::snprintf(m, sizeof m, "\"cmd\":\"stream\",\"q\":[%.3f,0,0,0,0,0]", q0);
    STRCMP_EQUAL("bad_state", error_of(a.ask(200 + i, m)).c_str());
  }
  DOUBLES_EQUAL(rest, rig.tel().q_cmd[0], 1e-12);
  CHECK_EQUAL(static_cast<int>(ArmState::idle), static_cast<int>(rig.tel().state));
}

// Streamed targets with the client's time over the API: each answer carries the stream's counts;
// an older target is answered ok with `stale` and counted (the state sample's `stream` too); a
// negative, non-numeric or NaN time is refused in one line.
TEST(FwApi, StreamTargetsWithTheClientsTime) {
  Rig rig({}, false, {}, 30.0);  // a deadman that a loaded machine's pauses between requests do not reach
  Client a(rig.port());
  rig.enable(a);
  const std::string first = a.ask(10, "\"cmd\":\"stream\",\"q\":[0,0,0,0,0,0],\"start\":true,\"t\":1000.0");
  CHECK_TEXT(is_ok(first) && has(first, "\"stream\":{") && has(first, "\"timed\":1"), first.c_str());
  const std::string next = a.ask(11, "\"cmd\":\"stream\",\"q\":[0.01,0,0,0,0,0],\"t\":1000.02");
  CHECK_TEXT(is_ok(next) && !has(next, "\"stale\":true") && has(next, "\"targets\":2"), next.c_str());
  const std::string old = a.ask(12, "\"cmd\":\"stream\",\"q\":[0.3,0,0,0,0,0],\"t\":1000.01");
  CHECK_TEXT(is_ok(old) && has(old, "\"stale\":true") && has(old, "\"stale\":1") && has(old, "\"targets\":2"), old.c_str());
  struct Case {
    const char* line;
    const char* error;
    const char* says;
  } cases[] = {
      {"{\"id\":20,\"cmd\":\"stream\",\"q\":[0.01,0,0,0,0,0],\"t\":-1}", "out_of_range", "t: -1 is outside"},
      {"{\"id\":21,\"cmd\":\"stream\",\"q\":[0.01,0,0,0,0,0],\"t\":\"now\"}", "bad_number", "t"},
      {"{\"id\":22,\"cmd\":\"stream\",\"q\":[0.01,0,0,0,0,0],\"t\":NaN}", "bad_json", ""},
      {"{\"id\":23,\"cmd\":\"stream\",\"q\":[0.01,0,0,0,0,0],\"t\":5000}", "out_of_range", "ahead of the control thread's clock"},
  };
  for (const Case& k : cases) {
    a.send(k.line);
    std::string r;
    while (r.empty() || has(r, "\"topic\"")) r = a.line();
    STRCMP_EQUAL_TEXT(k.error, error_of(r).c_str(), (std::string(k.line) + " -> " + r).c_str());
    CHECK_TEXT(has(r, k.says), r.c_str());
  }
  // the state sample says the same counts (taken on the service thread after each round)
  std::string st;
  for (int i = 0; i < 100 && !has(st, "\"stale\":1"); ++i) {
    st = a.ask(30 + i, "\"cmd\":\"state\"");
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  CHECK_TEXT(has(st, "\"stream\":{") && has(st, "\"stale\":1"), st.c_str());
  CHECK(rig.tel().q_cmd[0] < 0.2);  // the stale 0.3 was never a target
}

// docs/api.md holds exactly what the message table produces between its markers.
TEST(FwApi, ReferencePageIsGeneratedFromTheTable) {
  std::ifstream f(std::string(SERVOARM_SOURCE_DIR) + "/docs/api.md");
  std::stringstream ss;
  ss << f.rdbuf();
  const std::string page = ss.str();
  const std::string why = api::api_reference_mismatch(page);
  if (!why.empty()) FAIL(why.c_str());
  for (const api::MessageSpec& m : api::messages()) CHECK_TEXT(has(page, std::string("| `") + m.name + "` |"), m.name);
  // the check itself: a row the table does not have
  std::string extra = page;
  const auto at = extra.find("| `stop` |");
  CHECK(at != std::string::npos);
  extra.insert(at, "| `fly` | anyone | network thread | `-` | flies |\n");
  CHECK(!api::api_reference_mismatch(extra).empty());
}

namespace {
/// One HTTP GET on the WebSocket port: the status line and the body ("" when nothing came).
std::string http_get(int port, const std::string& path, std::string* body = nullptr) {
  Client c(port);
  c.send_raw("GET " + path + " HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n");
  std::string all;
  const double end = now_s() + 10;
  for (;;) {
    bool closed = false;
    const std::string l = c.line(std::max(0.0, end - now_s()), &closed);
    if (closed || now_s() > end) break;
    all += l + "\n";
  }
  all += c.buf;
  const auto sep = all.find("\r\n\r\n");
  if (body) *body = sep == std::string::npos ? "" : all.substr(sep + 4);
  return all.substr(0, all.find('\r'));
}
}  // namespace

// The state sample carries the joint frames a viewer draws the links between (the browser
// pendant computes no kinematics): the base, one per DH row and the tool, the tool's last.
TEST(FwApi, StateCarriesJointFrames) {
  Rig rig;
  Client c(rig.port());
  const std::string s = c.ask(1, "\"cmd\":\"state\"");
  CHECK_TEXT(is_ok(s), s.c_str());
  const test::Regex fr("\"frames\":\\[((\\[[^\\]]*\\],?)+)\\]");
  test::Groups m;
  CHECK_TEXT(!(m = fr.search(s)).empty(), s.c_str());
  const std::string frames = m[1];
  CHECK_EQUAL(rig.app.chain.n_rows + 2, static_cast<int>(std::count(frames.begin(), frames.end(), '[')));
  const test::Regex tool("\"tool\":\\{\"position\":(\\[[^\\]]*\\])");
  test::Groups t;
  CHECK_TEXT(!(t = tool.search(s)).empty(), s.c_str());
  const std::string last = frames.substr(frames.rfind('['));
  CHECK_EQUAL(t[1], last);
  CHECK(frames.rfind("[0,0,0]", 0) == 0 || frames.rfind("[0.0,0.0,0.0]", 0) == 0);  // puma560's base at the origin
}

// The WebSocket port serves a folder's static files (the pendant) over HTTP GET, index.html at
// "/", nothing outside the folder; without web_root it serves no file.
TEST(FwApi, ServesStaticFilesOnTheWebSocketPort) {
  const std::string dir = "/tmp/servoarm_fw_api_web_" + std::to_string(::getpid());
  ::mkdir(dir.c_str(), 0755);
  std::ofstream(dir + "/index.html") << "<!doctype html><title>pendant test page</title>";
  std::ofstream(dir + "/app.js") << "export const x = 1;";
  {
    api::ApiConfig ac;
    ac.ws_port = 0;
    ac.tcp_port = 0;
    ac.web_root = dir;
    Rig rig(ac);
    CHECK(rig.server->serves_web());
    const int port = rig.server->ws_port();
    std::string body;
    std::string st = http_get(port, "/", &body);
    CHECK_TEXT(has(st, " 200"), st.c_str());
    CHECK_TEXT(has(body, "pendant test page"), body.c_str());
    st = http_get(port, "/app.js", &body);
    CHECK_TEXT(has(st, " 200"), st.c_str());
    CHECK_TEXT(has(body, "export const x"), body.c_str());
    st = http_get(port, "/../../etc/passwd", &body);
    CHECK_TEXT(!has(st, " 200") || !has(body, "root:"), (st + body).c_str());
    st = http_get(port, "/nothing.js", &body);
    CHECK_TEXT(has(st, " 404"), st.c_str());
    // the API still answers on the same port's TCP sibling
    Client c(rig.port());
    CHECK(is_ok(c.ask(1, "\"cmd\":\"hello\"")));
  }
  {
    api::ApiConfig ac;
    ac.ws_port = 0;
    ac.tcp_port = 0;
    Rig rig(ac);
    CHECK(!rig.server->serves_web());
    const std::string st = http_get(rig.server->ws_port(), "/");
    CHECK_TEXT(!has(st, " 200"), st.c_str());
  }
  std::remove((dir + "/index.html").c_str());
  std::remove((dir + "/app.js").c_str());
  ::rmdir(dir.c_str());
}

namespace {
/// A JSON string literal of `s` (quotes, backslashes and newlines escaped).
std::string jstr(const std::string& s) {
  std::string o = "\"";
  for (char ch : s) {
    if (ch == '\n') o += "\\n";
    else if (ch == '"' || ch == '\\') o += '\\', o += ch;
    else o += ch;
  }
  return o + "\"";
}
/// The state sample's program state ("" when it has none).
std::string program_state(const std::string& s) {
  const test::Regex e("\"program\":\\{[^}]*\"state\":\"([a-z]+)\"");
  const test::Groups m = e.search(s);
  return m.empty() ? "" : m[1];
}
int int_field(const std::string& s, const std::string& key) {
  const test::Regex e("\"" + key + "\":(-?[0-9]+)");
  const test::Groups m = e.search(s);
  return m.empty() ? -999 : std::stoi(m[1]);
}
}  // namespace

// program_check runs the whole program through the service's dry run: a line the planner
// refuses (line 3: a target 5 m away) is named with its line, file and error code, a line the
// parser refuses likewise, and a good program answers its step counts. program_run checks
// first: the bad program moves nothing and queues nothing.
// Relative G-code lines (G91) move from the previous line's target, in the check as in the run.
TEST(FwApi, ProgramCheckPlansRelativeLinesFromThePreviousTarget) {
  Rig rig;
  Client c(rig.port());
  rig.enable(c);
  // relative G-code lines move from the previous line's target, in the check as in the run:
  // from a pose away from the wrist singularity, ten 150 mm steps along x leave the arm's reach
  // part way (each step alone from where the arm is would be within it)
  CHECK(is_ok(c.ask(42, "\"cmd\":\"movej\",\"q\":[0,0.3,-0.6,0,0.6,0],\"speed_pct\":100")));
  for (const double end = now_s() + 20; now_s() < end && rig.tel().done_id < 1;) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  std::string rel = "G21\nG91\n";
  for (int k = 0; k < 10; ++k) rel += "G1 X150 F3000\n";
  const std::string one = c.ask(43, "\"cmd\":\"program_check\",\"gcode\":true,\"text\":" + jstr("G21\nG91\nG1 X150 F3000\n"));
  CHECK_TEXT(is_ok(one), one.c_str());
  const std::string rl = c.ask(44, "\"cmd\":\"program_check\",\"gcode\":true,\"text\":" + jstr(rel));
  CHECK_TEXT(!is_ok(rl) && int_field(rl, "line") > 3 && int_field(rl, "line") <= 12, rl.c_str());
}

TEST(FwApi, ProgramCheckNamesTheRefusedLineAndRunMovesNothing) {
  Rig rig;
  Client c(rig.port());
  rig.enable(c);
  const std::string bad = "movej 0 0 0 0 0 0\nmovej 10 0 0 0 0 0\nmovel 5000 0 500 0 0 0\nmovej 0 0 0 0 0 0\n";
  const std::string r = c.ask(1, "\"cmd\":\"program_check\",\"text\":" + jstr(bad));
  CHECK_TEXT(!is_ok(r), r.c_str());
  CHECK_EQUAL(3, int_field(r, "line"));
  CHECK_EQUAL(2, int_field(r, "step"));
  CHECK_TEXT(has(r, "\"file\":\"editor.arm\"") && has(r, "editor.arm:3: "), r.c_str());
  CHECK_TEXT(error_of(r) != "" && error_of(r) != "program", r.c_str());  // the planner's code
  // a line the loader refuses: its line too
  const std::string syn = c.ask(2, "\"cmd\":\"program_check\",\"text\":" + jstr("movej 0 0 0 0 0 0\nfly 3\n"));
  CHECK_TEXT(error_of(syn) == "program" && int_field(syn, "line") == 2, syn.c_str());
  // G-code: the same checks
  const std::string g = c.ask(3, "\"cmd\":\"program_check\",\"gcode\":true,\"text\":" + jstr("G21 G90\nG1 X5000 Y0 Z0 F100\n"));
  CHECK_TEXT(!is_ok(g) && int_field(g, "line") == 2 && has(g, "editor.gcode:2: "), g.c_str());
  const std::string good = c.ask(4, "\"cmd\":\"program_check\",\"text\":" + jstr("movej 10 0 0 0 0 0\ndwell 0.1\nmovej 0 0 0 0 0 0\n"));
  CHECK_TEXT(is_ok(good) && int_field(good, "steps") == 3 && int_field(good, "joint_moves") == 2 && int_field(good, "dwells") == 1 &&
                 int_field(good, "planned_steps") == 3,
             good.c_str());
  // a tool defined by the program, then selected: accepted (a check makes no definition, so the
  // moves after it are planned when they run: planned_steps says where planning stopped)
  const std::string def = c.ask(40, "\"cmd\":\"program_check\",\"text\":" +
                                        jstr("movej 10 0 0 0 0 0\ntool grip 0 0 100 0 0 0\ntool grip\nmovej 0 0 0 0 0 0\n"));
  CHECK_TEXT(is_ok(def) && int_field(def, "steps") == 4 && int_field(def, "planned_steps") == 1, def.c_str());
  CHECK_EQUAL(1u, rig.app.console->service().tool_count());  // nothing defined
  // a tool that neither exists nor is defined: its line
  const std::string nt = c.ask(41, "\"cmd\":\"program_check\",\"text\":" + jstr("movej 10 0 0 0 0 0\ntool nosuch\n"));
  CHECK_TEXT(!is_ok(nt) && int_field(nt, "line") == 2, nt.c_str());
  // the check moved nothing; the run of the bad program refuses line 3 and moves nothing
  const double q0 = rig.tel().q_cmd[0];
  const std::string run = c.ask(5, "\"cmd\":\"program_run\",\"text\":" + jstr(bad));
  CHECK_TEXT(!is_ok(run) && int_field(run, "line") == 3, run.c_str());
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  CHECK_EQUAL(0u, rig.tel().done_id);
  CHECK_EQUAL(0u, rig.tel().queued);
  DOUBLES_EQUAL(q0, rig.tel().q_cmd[0], 1e-12);
  CHECK_EQUAL(static_cast<int>(ArmState::idle), static_cast<int>(rig.tel().state));
  const std::string st = c.ask(6, "\"cmd\":\"state\"");
  CHECK_TEXT(program_state(st) == "idle", st.c_str());
}

// program_run runs a good program: the state stream names it and its line while it runs; pause
// pauses it once the running motion is done, step runs one motion, resume runs it on, abort
// ends it and stops the arm.
TEST(FwApi, ProgramRunPauseStepResumeAbort) {
  Rig rig;
  Client c(rig.port());
  rig.enable(c);
  std::string text;
  for (int k = 0; k < 6; ++k) text += (k % 2 ? "movej 0 0 0 0 0 0\n" : "movej 20 0 0 0 0 0\n");
  const std::string r = c.ask(1, "\"cmd\":\"program_run\",\"name\":\"swing\",\"text\":" + jstr(text));
  CHECK_TEXT(is_ok(r) && has(r, "\"state\":\"running\""), r.c_str());
  std::string st;
  for (int i = 0; i < 100; ++i) {
    st = c.ask(10 + i, "\"cmd\":\"state\"");
    if (has(st, "\"name\":\"swing\"") && int_field(st, "running_line") >= 1) break;
  }
  CHECK_TEXT(has(st, "\"name\":\"swing\""), st.c_str());
  CHECK_TEXT(has(st, "\"state\":\"running\""), st.c_str());
  const std::string p = c.ask(200, "\"cmd\":\"program_pause\"");
  CHECK_TEXT(is_ok(p), p.c_str());
  bool paused = false;
  for (int i = 0; i < 400 && !paused; ++i) {
    paused = has(c.ask(300 + i, "\"cmd\":\"state\""), "\"state\":\"paused\"");
    if (!paused) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  CHECK(paused);
  const std::uint32_t done = rig.tel().done_id;
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  CHECK_EQUAL(done, rig.tel().done_id);  // paused: nothing more runs
  const std::string s1 = c.ask(700, "\"cmd\":\"program_step\"");
  CHECK_TEXT(is_ok(s1), s1.c_str());
  for (int i = 0; i < 6000 && rig.tel().done_id < done + 1; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  CHECK_EQUAL(done + 1, rig.tel().done_id);
  paused = false;  // the one motion done: paused again
  for (int i = 0; i < 400 && !paused; ++i) {
    paused = has(c.ask(1000 + i, "\"cmd\":\"state\""), "\"state\":\"paused\"");
    if (!paused) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  CHECK(paused);
  const std::string rs = c.ask(701, "\"cmd\":\"resume\"");
  CHECK_TEXT(is_ok(rs), rs.c_str());
  bool running = false;
  std::string last;
  for (int i = 0; i < 100 && !running; ++i) running = has(last = c.ask(800 + i, "\"cmd\":\"state\""), "\"state\":\"running\"");
  CHECK_TEXT(running, (rs + " | " + last).c_str());
  const std::string a = c.ask(950, "\"cmd\":\"program_abort\"");
  CHECK_TEXT(is_ok(a), a.c_str());
  for (int i = 0; i < 600 && rig.tel().state != ArmState::idle; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  CHECK_EQUAL(static_cast<int>(ArmState::idle), static_cast<int>(rig.tel().state));
  const std::string end = c.ask(951, "\"cmd\":\"state\"");
  CHECK_TEXT(program_state(end) == "idle", end.c_str());
  CHECK_EQUAL(std::string("bad_state"), error_of(c.ask(952, "\"cmd\":\"program_step\"")));
}

// Teach points over the API: teach stores the arm's joints, points lists them, point_go moves
// back to one, point_delete removes it; an unknown point is refused and moves nothing. Tools and
// frames: listed with the active ones; selecting one that does not exist is refused.
TEST(FwApi, TeachPointsToolsAndFrames) {
  Rig rig;
  Client c(rig.port());
  rig.enable(c);
  CHECK(is_ok(c.ask(1, "\"cmd\":\"movej\",\"q\":[0.2,0.1,0,0,0,0],\"speed_pct\":50")));
  // The waits for a move's end allow 30 s (they end when it does): the loop runs in real time
  // and a loaded machine stretches a move of a second well beyond it.
  for (int i = 0; i < 6000 && rig.tel().done_id < 1; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  const std::string t = c.ask(2, "\"cmd\":\"teach\",\"name\":\"p1\"");
  CHECK_TEXT(is_ok(t) && has(t, "\"name\":\"p1\"") && int_field(t, "count") == 1, t.c_str());
  const std::string l = c.ask(3, "\"cmd\":\"points\"");
  CHECK_TEXT(is_ok(l) && has(l, "\"name\":\"p1\"") && has(l, "\"tool\":\"tool0\""), l.c_str());
  const test::Regex q("\"q\":\\[([-0-9.e]+),([-0-9.e]+),");  // the measured joints when taught
  test::Groups m;
  CHECK_TEXT(!(m = q.search(l)).empty(), l.c_str());
  const double q0 = std::stod(m[1]), q1 = std::stod(m[2]);
  DOUBLES_EQUAL(0.2, q0, 1e-3);
  DOUBLES_EQUAL(0.1, q1, 1e-3);
  CHECK(is_ok(c.ask(4, "\"cmd\":\"movej\",\"q\":[-0.2,0,0,0,0,0],\"speed_pct\":50")));
  for (int i = 0; i < 6000 && rig.tel().done_id < 2; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  const std::string g = c.ask(5, "\"cmd\":\"point_go\",\"name\":\"p1\"");
  CHECK_TEXT(is_ok(g) && int_field(g, "motion") == 3, g.c_str());
  for (int i = 0; i < 6000 && rig.tel().done_id < 3; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  DOUBLES_EQUAL(q0, rig.tel().q_cmd[0], 1e-9);
  DOUBLES_EQUAL(q1, rig.tel().q_cmd[1], 1e-9);
  const std::string none = c.ask(6, "\"cmd\":\"point_go\",\"name\":\"nowhere\"");
  CHECK_TEXT(!is_ok(none) && has(none, "no_point"), none.c_str());
  CHECK_EQUAL(3u, rig.tel().done_id);
  CHECK_EQUAL(0u, rig.tel().queued);
  const std::string d = c.ask(7, "\"cmd\":\"point_delete\",\"name\":\"p1\"");
  CHECK_TEXT(is_ok(d) && int_field(d, "count") == 0, d.c_str());
  CHECK_TEXT(has(c.ask(8, "\"cmd\":\"points\""), "\"points\":[]"), "p1 still listed");
  const std::string tl = c.ask(9, "\"cmd\":\"tools\"");
  CHECK_TEXT(is_ok(tl) && has(tl, "\"tool\":\"tool0\"") && has(tl, "\"frame\":\"base\"") && has(tl, "\"name\":\"tool0\""), tl.c_str());
  const std::string ts = c.ask(10, "\"cmd\":\"tool_select\",\"name\":\"gripper9\"");
  CHECK_TEXT(!is_ok(ts) && has(ts, "not_defined"), ts.c_str());
  const std::string fs = c.ask(11, "\"cmd\":\"frame_select\",\"name\":\"base\"");
  CHECK_TEXT(is_ok(fs) && has(fs, "\"frame\":\"base\""), fs.c_str());
}

// A Cartesian jog moves the tool along the axis asked (base frame: x) and not off it, by the
// increment; continuous jogs stop at the deadman; the feed override set over the API is the
// service's and shows in the state stream; out of its range it is refused.
TEST(FwApi, CartesianJogAndFeedOverride) {
  Rig rig;
  Client c(rig.port());
  rig.enable(c);
  CHECK(is_ok(c.ask(1, "\"cmd\":\"movej\",\"q\":[0,0.3,-0.6,0,0.6,0],\"speed_pct\":50")));
  for (int i = 0; i < 6000 && rig.tel().done_id < 1; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  const auto tool_at = [&](int id) {
    const std::string s = c.ask(id, "\"cmd\":\"state\"");
    const test::Regex e("\"tool\":\\{\"position\":\\[([-0-9.e]+),([-0-9.e]+),([-0-9.e]+)\\]");
    test::Groups m;
    CHECK_TEXT(!(m = e.search(s)).empty(), s.c_str());
    return std::array<double, 3>{std::stod(m[1]), std::stod(m[2]), std::stod(m[3])};
  };
  const auto p0 = tool_at(2);
  const std::string j = c.ask(3, "\"cmd\":\"jog_cartesian\",\"axis\":0,\"frame\":\"base\",\"increment\":0.02");
  CHECK_TEXT(is_ok(j), j.c_str());
  for (int i = 0; i < 600 && (rig.tel().state != ArmState::idle || i < 20); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  std::this_thread::sleep_for(std::chrono::milliseconds(100));  // the measured joints settle
  const auto p1 = tool_at(4);
  DOUBLES_EQUAL(p0[0] + 0.02, p1[0], 1e-3);
  DOUBLES_EQUAL(p0[1], p1[1], 1e-3);
  DOUBLES_EQUAL(p0[2], p1[2], 1e-3);
  const std::string bad = c.ask(5, "\"cmd\":\"jog_cartesian\",\"axis\":0,\"frame\":\"moon\",\"increment\":0.01");
  STRCMP_EQUAL("bad_option", error_of(bad).c_str());
  STRCMP_EQUAL("arg_count", error_of(c.ask(6, "\"cmd\":\"jog_cartesian\",\"axis\":2")).c_str());
  const std::string f = c.ask(7, "\"cmd\":\"feed_override\",\"pct\":40");
  CHECK_TEXT(is_ok(f) && int_field(f, "feed_pct") == 40, f.c_str());
  CHECK_EQUAL(40, rig.app.console->service().feed_override());
  std::string st;
  for (int i = 0; i < 100 && int_field(st, "feed_pct") != 40; ++i) st = c.ask(100 + i, "\"cmd\":\"state\"");
  CHECK_EQUAL(40, int_field(st, "feed_pct"));
  STRCMP_EQUAL("out_of_range", error_of(c.ask(8, "\"cmd\":\"feed_override\",\"pct\":500")).c_str());
  CHECK_EQUAL(40, rig.app.console->service().feed_override());
}

// The Foxglove server has no authentication: it listens on loopback only and refuses any other
// address in one line, before it opens anything.
TEST(FwApi, FoxgloveServerRefusesABindBeyondLoopback) {
  Rig rig;
  for (const char* bind : {"0.0.0.0", "::", "192.168.1.10"}) {
    api::FoxgloveConfig fc;
    fc.bind = bind;
    fc.port = 0;
    fc.rate_hz = rig.app.cfg.rate_hz;
    api::FoxgloveServer fox(fc, *rig.app.ctl, rig.app.chain);
    const std::string e = fox.start();
    CHECK_TEXT(e.find("loopback only") != std::string::npos, (std::string(bind) + ": " + e).c_str());
    fox.stop();
  }
  api::FoxgloveConfig lo;
  lo.port = 0;
  lo.rate_hz = rig.app.cfg.rate_hz;
  api::FoxgloveServer fox(lo, *rig.app.ctl, rig.app.chain);
  STRCMP_EQUAL("", fox.start().c_str());
  fox.stop();
}

// Tools and frames defined and deleted over the API (the service's define/delete: the console's
// calls), and movel in the active tool and user frame: after the line, the active tool's point by
// forward kinematics, in the frame, is the position asked. A bad name or value, and deleting the
// active tool, are refused; nothing is defined then.
TEST(FwApi, ToolsAndFramesDefinedAndMovelInThem) {
  Rig rig;
  Client c(rig.port());
  rig.enable(c);
  CHECK(is_ok(c.ask(1, "\"cmd\":\"movej\",\"q\":[0,0.3,-0.6,0,0.6,0],\"speed_pct\":50")));
  for (int i = 0; i < 6000 && rig.tel().done_id < 1; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  const std::string td = c.ask(2, "\"cmd\":\"tool_define\",\"name\":\"pen\",\"position\":[0,0,0.1],\"rpy\":[0,0,0]");
  CHECK_TEXT(is_ok(td) && has(td, "\"tool\":\"pen\""), td.c_str());
  const std::string fd = c.ask(3, "\"cmd\":\"frame_define\",\"name\":\"table\",\"position\":[0.05,-0.02,0.01],\"rpy\":[0,0,0.3]");
  CHECK_TEXT(is_ok(fd) && has(fd, "\"frame\":\"table\""), fd.c_str());
  STRCMP_EQUAL("bad_option", error_of(c.ask(4, "\"cmd\":\"tool_define\",\"name\":\"bad name\",\"position\":[0,0,0.1],\"rpy\":[0,0,0]")).c_str());
  STRCMP_EQUAL("out_of_range", error_of(c.ask(5, "\"cmd\":\"tool_define\",\"name\":\"huge\",\"position\":[0,0,50],\"rpy\":[0,0,0]")).c_str());
  fw::ArmService& svc = rig.app.console->service();
  CHECK_EQUAL(2u, svc.tool_count());
  CHECK(is_ok(c.ask(6, "\"cmd\":\"tool_select\",\"name\":\"pen\"")));
  CHECK(is_ok(c.ask(7, "\"cmd\":\"frame_select\",\"name\":\"table\"")));
  // where the pen is now, in the table frame; 20 mm along the frame's x from there
  const kin::Chain& pen = svc.tool_chain(svc.find_tool("pen"));
  const kin::Pose F = svc.frame(svc.find_frame("table")).pose;
  auto pen_in_table = [&] {
    const Telemetry t = rig.tel();
    kin::JointVector q(t.n);
    for (int j = 0; j < t.n; ++j) q[j] = t.q_cmd[static_cast<std::size_t>(j)];
    kin::Pose p;
    CHECK(kin::forward(pen, q, p) == kin::Status::ok);
    return F.inverse() * p;
  };
  const kin::Pose p0 = pen_in_table();
  const Eigen::Vector3d goal = p0.translation() + Eigen::Vector3d(0.02, 0, 0);
  char mv[200];
  std::snprintf(mv, sizeof mv, "\"cmd\":\"movel\",\"position\":[%.9f,%.9f,%.9f],\"speed\":0.1", goal.x(), goal.y(), goal.z());
  const std::string ml = c.ask(8, mv);
  CHECK_TEXT(is_ok(ml), ml.c_str());
  for (int i = 0; i < 6000 && rig.tel().done_id < 2; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  const kin::Pose p1 = pen_in_table();
  const std::string fig = "pen in table at " + std::to_string(p1.translation().x()) + " " + std::to_string(p1.translation().y()) +
                          " " + std::to_string(p1.translation().z()) + ", asked " + std::to_string(goal.x()) + " " +
                          std::to_string(goal.y()) + " " + std::to_string(goal.z());
  CHECK_TEXT((p1.translation() - goal).norm() < 1e-4, fig.c_str());
  CHECK_TEXT(p1.linear().isApprox(p0.linear(), 1e-6), "the orientation changed");
  // deleting the active ones is refused; after selecting others, they go
  CHECK_TEXT(has(c.ask(9, "\"cmd\":\"tool_delete\",\"name\":\"pen\""), "active"), "the active tool was deleted");
  CHECK(is_ok(c.ask(10, "\"cmd\":\"tool_select\",\"name\":\"tool0\"")));
  CHECK(is_ok(c.ask(11, "\"cmd\":\"frame_select\",\"name\":\"base\"")));
  CHECK(is_ok(c.ask(12, "\"cmd\":\"tool_delete\",\"name\":\"pen\"")));
  CHECK(is_ok(c.ask(13, "\"cmd\":\"frame_delete\",\"name\":\"table\"")));
  CHECK_EQUAL(1u, svc.tool_count());
  STRCMP_EQUAL("bad_option", error_of(c.ask(14, "\"cmd\":\"tool_delete\",\"name\":\"pen\"")).c_str());  // no longer defined
}

// TLS (api.tls_cert / api.tls_key): a certificate path that cannot be read, a file that is not a
// certificate, or one without the other refuse the start in one line; with a self-signed
// certificate (made by the openssl tool) a client speaking TLS (openssl s_client) gets hello's
// answer over the TCP port, and the token check beyond loopback is unchanged.
TEST(FwApi, TlsServesWithACertificateAndRefusesABadOne) {
  Rig rig;
  const std::string dir = "/tmp/servoarm_tls_" + std::to_string(::getpid());
  const std::string cert = dir + "/cert.pem", key = dir + "/key.pem", junk = dir + "/junk.pem";
  CHECK_EQUAL(0, std::system(("mkdir -p " + dir + " && openssl req -x509 -newkey rsa:2048 -nodes -days 2 -subj /CN=localhost -keyout " +
                              key + " -out " + cert + " >/dev/null 2>&1").c_str()));
  std::ofstream(junk) << "not a certificate\n";
  auto start = [&](const std::string& c, const std::string& k, const std::string& bind = "127.0.0.1") {
    api::ApiConfig ac;
    ac.tcp_port = 0;
    ac.bind = bind;
    ac.tls_cert = c;
    ac.tls_key = k;
    ac.rate_hz = rig.app.cfg.rate_hz;
    auto s = std::make_unique<api::ApiServer>(ac, *rig.app.ctl, rig.app.chain, rig.app.ctl->limits());
    const std::string e = s->start();
    return std::make_pair(std::move(s), e);
  };
  {
    const auto [s, e] = start(dir + "/missing.pem", key);
    CHECK_TEXT(e.find("api.tls_cert = " + dir + "/missing.pem: No such file") == 0, e.c_str());
    CHECK(e.find('\n') == std::string::npos);
  }
  {
    const auto [s, e] = start(junk, key);
    CHECK_TEXT(e.find("TLS") != std::string::npos && e.find('\n') == std::string::npos, ("[" + e + "]").c_str());
  }
  {
    const auto [s, e] = start(cert, "");
    CHECK_TEXT(e.find("both api.tls_cert and api.tls_key") != std::string::npos, e.c_str());
  }
  {
    const auto [s, e] = start(cert, key, "0.0.0.0");  // TLS is no authentication: the tokens are still needed
    CHECK_TEXT(e.find("beyond loopback only with api.tokens_file") != std::string::npos, e.c_str());
  }
  auto [s, e] = start(cert, key);
  CHECK_TEXT(e.empty(), e.c_str());
  // hello is answered on the server's own thread: no service pump is needed here
  const std::string cmd = "(printf '%s\\n' '{\"id\":1,\"cmd\":\"hello\"}'; sleep 2) | timeout 10 openssl s_client -quiet -connect 127.0.0.1:" +
                          std::to_string(s->tcp_port()) + " 2>/dev/null";
  std::string out;
  if (FILE* p = ::popen(cmd.c_str(), "r")) {
    char buf[4096];
    std::size_t n;
    while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
    ::pclose(p);
  }
  // a client without TLS gets no answer in plain text
  Client plain(s->tcp_port());
  plain.send("{\"id\":2,\"cmd\":\"hello\"}");
  const std::string no = plain.answer(2, 1.0);
  s->stop();
  std::system(("rm -rf " + dir).c_str());
  CHECK_TEXT(out.find("\"id\":1") != std::string::npos && out.find("\"protocol\":1") != std::string::npos, out.c_str());
  CHECK_TEXT(no.find("\"protocol\":1") == std::string::npos, no.c_str());
}

namespace {
/// The [x, y, z] points of a planned_path answer.
std::vector<Eigen::Vector3d> path_points(const std::string& s) {
  std::vector<Eigen::Vector3d> out;
  const auto at = s.find("\"points\":[");
  if (at == std::string::npos) return out;
  const std::string rest = s.substr(at);
  const test::Regex e("\\[(-?[0-9.eE+-]+),(-?[0-9.eE+-]+),(-?[0-9.eE+-]+)\\]");
  for (const test::Groups& g : e.search_all(rest.substr(0, rest.find("]]") + 2)))
    out.emplace_back(std::stod(g[1]), std::stod(g[2]), std::stod(g[3]));
  return out;
}
Eigen::Vector3d tool_point(const kin::Chain& ch, const kin::JointVector& q) {
  kin::Pose p = kin::Pose::Identity();
  CHECK(kin::forward(ch, q, p) == kin::Status::ok);
  return p.translation();
}
}  // namespace

// planned_path: the tool path the service planned a move with, sampled along its plan. A movej's
// path starts at the tool point where the arm is and ends at the tool point of its goal (the
// arm's own FK, not the service's); asked without a motion while it runs, it is the running
// one's. A movel's path lies on the straight line and ends at its target. A motion never queued
// is refused, and with nothing running the running one's is too.
TEST(FwApi, PlannedPathOfAJointMoveAndALine) {
  Rig rig;
  Client c(rig.port());
  rig.enable(c);
  const kin::Chain& ch = rig.app.chain;
  kin::JointVector q0(6), goal(6);
  q0 << 0, 0, 0, 0, 0, 0;
  goal << 0.4, 0.3, -0.6, 0, 0.6, 0;
  const std::string m = c.ask(1, "\"cmd\":\"movej\",\"q\":[0.4,0.3,-0.6,0,0.6,0],\"speed_pct\":20");
  CHECK_TEXT(is_ok(m), m.c_str());
  const int id = int_field(m, "motion");
  for (int i = 0; i < 400 && rig.tel().running_id != static_cast<std::uint32_t>(id); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  const std::string running = c.ask(2, "\"cmd\":\"planned_path\"");
  CHECK_TEXT(is_ok(running) && int_field(running, "motion") == id && has(running, "\"kind\":\"joint\""), running.c_str());
  const std::vector<Eigen::Vector3d> pj = path_points(c.ask(3, "\"cmd\":\"planned_path\",\"motion\":" + std::to_string(id)));
  CHECK_EQUAL(fw::ArmService::kPlannedPathSamples, static_cast<int>(pj.size()));
  CHECK_TEXT((pj.front() - tool_point(ch, q0)).norm() < 1e-6, "the path does not start where the arm is");
  CHECK_TEXT((pj.back() - tool_point(ch, goal)).norm() < 1e-6, "the path does not end at the goal's tool point");
  double len = 0;
  for (std::size_t k = 1; k < pj.size(); ++k) len += (pj[k] - pj[k - 1]).norm();
  CHECK_TEXT(len > (pj.back() - pj.front()).norm() + 1e-3, "a joint move's tool path drawn as a straight line");
  for (int i = 0; i < 1000 && rig.tel().done_id < static_cast<std::uint32_t>(id); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  CHECK_EQUAL(std::string("bad_state"), error_of(c.ask(4, "\"cmd\":\"planned_path\"")));  // nothing runs
  // a line 60 mm along x from the goal's tool point
  const Eigen::Vector3d a = tool_point(ch, goal), b = a + Eigen::Vector3d(0.06, 0, 0);
  char mv[200];
  std::snprintf(mv, sizeof mv, "\"cmd\":\"movel\",\"position\":[%.9f,%.9f,%.9f],\"speed\":0.05", b.x(), b.y(), b.z());
  const std::string ml = c.ask(5, mv);
  CHECK_TEXT(is_ok(ml), ml.c_str());
  const std::string lp = c.ask(6, "\"cmd\":\"planned_path\",\"motion\":" + std::to_string(int_field(ml, "motion")));
  const std::vector<Eigen::Vector3d> pl = path_points(lp);
  CHECK_TEXT(static_cast<int>(pl.size()) == fw::ArmService::kPlannedPathSamples, lp.c_str());
  for (const Eigen::Vector3d& x : pl) {
    const double off = ((x - a) - (x - a).dot(Eigen::Vector3d::UnitX()) * Eigen::Vector3d::UnitX()).norm();
    CHECK_TEXT(off < 1e-4 && x.x() > a.x() - 1e-4 && x.x() < b.x() + 1e-4, lp.c_str());
  }
  CHECK_TEXT((pl.back() - b).norm() < 1e-5, lp.c_str());
  CHECK_EQUAL(std::string("out_of_range"), error_of(c.ask(7, "\"cmd\":\"planned_path\",\"motion\":999")));
  CHECK_EQUAL(std::string("out_of_range"), error_of(c.ask(8, "\"cmd\":\"planned_path\",\"motion\":-1")));
}

namespace {
/// The [x, y, z] after `"key":{"position":` in a state line.
Eigen::Vector3d pose_position(const std::string& s, const std::string& key) {
  const test::Regex e("\"" + key + "\":\\{\"position\":\\[(-?[0-9.eE+-]+),(-?[0-9.eE+-]+),(-?[0-9.eE+-]+)\\]");
  test::Groups m;
  if ((m = e.search(s)).empty()) return Eigen::Vector3d::Constant(1e9);
  return {std::stod(m[1]), std::stod(m[2]), std::stod(m[3])};
}
}  // namespace

// The state carries `tcp`, the active tool's point: with tool0 the flange's (`tool`), with a
// tool defined 100 mm out along the flange's z axis and tilted, the tool chain's forward
// kinematics of the measured joints (the service's chain for it, computed by the test).
TEST(FwApi, StateCarriesTheActiveToolsPoint) {
  Rig rig;
  Client c(rig.port());
  rig.enable(c);
  CHECK(is_ok(c.ask(1, "\"cmd\":\"movej\",\"q\":[0.2,0.3,-0.6,0,0.6,0],\"speed_pct\":50")));
  for (int i = 0; i < 6000 && rig.tel().done_id < 1; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  const std::string s0 = c.ask(2, "\"cmd\":\"state\"");
  CHECK_TEXT((pose_position(s0, "tcp") - pose_position(s0, "tool")).norm() < 1e-12, s0.c_str());
  CHECK(is_ok(c.ask(3, "\"cmd\":\"tool_define\",\"name\":\"pen\",\"position\":[0.01,0,0.1],\"rpy\":[0,0.3,0]")));
  CHECK(is_ok(c.ask(4, "\"cmd\":\"tool_select\",\"name\":\"pen\"")));
  const fw::ArmService& svc = rig.app.console->service();
  // the measured joints of the same state sample (the arm may still settle after the move)
  const std::string s1 = c.ask(5, "\"cmd\":\"state\"");
  test::Groups qm;
  CHECK_TEXT(!(qm = test::regex_search(s1, "\"q\":\\[([^\\]]*)\\]")).empty(), s1.c_str());
  std::vector<double> qs;
  std::stringstream qss(qm[1]);
  for (std::string v; std::getline(qss, v, ',');) qs.push_back(std::stod(v));
  const Telemetry t = rig.tel();
  LONGS_EQUAL(t.n, static_cast<long>(qs.size()));
  kin::JointVector q(t.n);
  for (int j = 0; j < t.n; ++j) q[j] = qs[static_cast<std::size_t>(j)];
  const Eigen::Vector3d want = tool_point(svc.tool_chain(svc.find_tool("pen")), q);
  const Eigen::Vector3d tcp = pose_position(s1, "tcp");
  CHECK_TEXT((tcp - want).norm() < 1e-6, s1.c_str());
  CHECK_TEXT((tcp - pose_position(s1, "tool")).norm() > 0.09, s1.c_str());
}

// The state carries the digital outputs ([[output]] order, the index `output` takes) with their
// names and whether each is on, read back from the drives' output words: `output` 1 on turns
// the second on and leaves the first off, and off again.
TEST(FwApi, StateCarriesTheDigitalOutputs) {
  Rig rig({}, false, {OutputConfig{"gripper", 1, 16}, OutputConfig{"lamp", 2, 17}});
  Client c(rig.port());
  rig.enable(c);
  const std::string s0 = c.ask(1, "\"cmd\":\"state\"");
  CHECK_TEXT(has(s0, "\"outputs\":[{\"name\":\"gripper\",\"on\":false},{\"name\":\"lamp\",\"on\":false}]"), s0.c_str());
  CHECK(is_ok(c.ask(2, "\"cmd\":\"output\",\"index\":1,\"on\":true")));
  std::string s1;
  for (int i = 0; i < 200; ++i) {
    s1 = c.ask(10 + i, "\"cmd\":\"state\"");
    if (has(s1, "\"lamp\",\"on\":true")) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  CHECK_TEXT(has(s1, "\"outputs\":[{\"name\":\"gripper\",\"on\":false},{\"name\":\"lamp\",\"on\":true}]"), s1.c_str());
  CHECK(is_ok(c.ask(3, "\"cmd\":\"output\",\"index\":1,\"on\":false")));
  std::string s2;
  for (int i = 0; i < 200; ++i) {
    s2 = c.ask(300 + i, "\"cmd\":\"state\"");
    if (has(s2, "\"lamp\",\"on\":false")) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  CHECK_TEXT(has(s2, "\"lamp\",\"on\":false"), s2.c_str());
}
