// SPDX-License-Identifier: Apache-2.0
// The MQTT bridge (mqtt.hpp): libmosquitto's thread takes the commands into a queue and wakes the
// service thread, which runs them through the API's message table and publishes what they answer.
#include "servoarm/api/mqtt.hpp"

#include <mosquitto.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <deque>
#include <fstream>
#include <mutex>
#include <string>
#include <utility>

#include "servoarm/api/server.hpp"

namespace servoarm::api {

struct MqttBridge::Impl {
  MqttConfig cfg;
  fw::Controller& ctl;
  const kin::Chain& chain;
  mosquitto* m = nullptr;
  int wake = -1;
  bool started = false;
  std::atomic<bool> up{false};
  std::mutex mu;
  std::deque<std::string> inbox;  // raw command texts, stops first
  std::uint64_t event_seq = 0;
  bool event_seq_set = false;
  std::uint64_t events_missed = 0;
  std::chrono::steady_clock::time_point next_state{};
  std::string base;

  Impl(const MqttConfig& c, fw::Controller& k, const kin::Chain& ch) : cfg(c), ctl(k), chain(ch) {
    base = "servoarm/" + cfg.name + "/";
  }
  void publish(const std::string& sub, const std::string& text, int qos, bool retain = false) {
    mosquitto_publish(m, nullptr, (base + sub).c_str(), static_cast<int>(text.size()), text.data(), qos, retain);
  }
  static void on_connect(mosquitto* m, void* self, int rc) {
    auto* s = static_cast<Impl*>(self);
    if (rc != 0) return;
    mosquitto_subscribe(m, nullptr, (s->base + "cmd").c_str(), 1);
    s->publish("status", "online", 1, true);
    s->up = true;
  }
  static void on_disconnect(mosquitto*, void* self, int) { static_cast<Impl*>(self)->up = false; }
  static void on_message(mosquitto*, void* self, const mosquitto_message* msg) {
    auto* s = static_cast<Impl*>(self);
    if (msg->payloadlen <= 0 || msg->payloadlen > 64 * 1024) return;
    std::string text(static_cast<const char*>(msg->payload), static_cast<std::size_t>(msg->payloadlen));
    {
      std::lock_guard<std::mutex> l(s->mu);
      // a stop, hold or e-stop goes before the commands waiting, as on the sockets
      ApiRequest rq;
      const bool stop = parse_request(text, rq).code.empty() && rq.spec->gate == Gate::stop;
      if (stop) s->inbox.push_front(std::move(text));
      else s->inbox.push_back(std::move(text));
    }
    const std::uint64_t one = 1;
    [[maybe_unused]] const ssize_t n = ::write(s->wake, &one, sizeof one);
  }
};

MqttBridge::MqttBridge(const MqttConfig& cfg, fw::Controller& ctl, const kin::Chain& chain)
    : impl_(std::make_unique<Impl>(cfg, ctl, chain)) {}

MqttBridge::~MqttBridge() { stop(); }

std::string MqttBridge::start() {
  Impl& s = *impl_;
  mosquitto_lib_init();
  const std::string id = "servoarm-" + s.cfg.name + "-" + std::to_string(::getpid());
  s.m = mosquitto_new(id.c_str(), true, &s);
  if (s.m == nullptr) return "mqtt: cannot make a client";
  s.wake = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  mosquitto_connect_callback_set(s.m, &Impl::on_connect);
  mosquitto_disconnect_callback_set(s.m, &Impl::on_disconnect);
  mosquitto_message_callback_set(s.m, &Impl::on_message);
  const std::string status = s.base + "status";
  if (mosquitto_will_set(s.m, status.c_str(), 7, "offline", 1, true) != MOSQ_ERR_SUCCESS)
    return "mqtt.name: \"" + s.cfg.name + "\" does not make a valid topic";
  if (!s.cfg.username.empty()) {
    std::string pw;
    if (!s.cfg.password_file.empty()) {
      std::ifstream f(s.cfg.password_file);
      if (!f) return "mqtt.password_file: cannot read " + s.cfg.password_file;
      std::getline(f, pw);
    }
    mosquitto_username_pw_set(s.m, s.cfg.username.c_str(), s.cfg.password_file.empty() ? nullptr : pw.c_str());
  }
  if (!s.cfg.cafile.empty()) {
    const int rc = mosquitto_tls_set(s.m, s.cfg.cafile.c_str(), nullptr,
                                     s.cfg.certfile.empty() ? nullptr : s.cfg.certfile.c_str(),
                                     s.cfg.keyfile.empty() ? nullptr : s.cfg.keyfile.c_str(), nullptr);
    if (rc != MOSQ_ERR_SUCCESS) return std::string("mqtt.cafile / certfile / keyfile: ") + mosquitto_strerror(rc);
  }
  mosquitto_reconnect_delay_set(s.m, 1, 5, false);
  // connect_async: a broker that is not up yet is reached when it is (the thread retries)
  int rc = mosquitto_connect_async(s.m, s.cfg.host.c_str(), s.cfg.port, s.cfg.keepalive_s);
  if (rc != MOSQ_ERR_SUCCESS && rc != MOSQ_ERR_ERRNO)
    return "mqtt.host: " + s.cfg.host + ":" + std::to_string(s.cfg.port) + ": " + mosquitto_strerror(rc);
  rc = mosquitto_loop_start(s.m);
  if (rc != MOSQ_ERR_SUCCESS) return std::string("mqtt: ") + mosquitto_strerror(rc);
  s.started = true;
  return "";
}

void MqttBridge::stop() {
  Impl& s = *impl_;
  if (s.m != nullptr) {
    if (s.started) {
      if (s.up) s.publish("status", "offline", 1, true);  // a clean stop says so too
      mosquitto_disconnect(s.m);
      mosquitto_loop_stop(s.m, false);
    }
    mosquitto_destroy(s.m);
    s.m = nullptr;
    mosquitto_lib_cleanup();
  }
  if (s.wake >= 0) ::close(s.wake), s.wake = -1;
  s.started = false;
}

int MqttBridge::wake_fd() const { return impl_->wake; }
bool MqttBridge::connected() const { return impl_->up; }

std::size_t MqttBridge::pump(ServiceContext& cx, const ApiServer* api) {
  Impl& s = *impl_;
  if (s.m == nullptr) return 0;
  std::uint64_t n = 0;
  [[maybe_unused]] const ssize_t r = ::read(s.wake, &n, sizeof n);
  std::size_t ran = 0;
  for (;;) {
    std::string text;
    {
      std::lock_guard<std::mutex> l(s.mu);
      if (s.inbox.empty()) break;
      text = std::move(s.inbox.front());
      s.inbox.pop_front();
    }
    ApiRequest rq;
    const ParseError pe = parse_request(text, rq);
    std::string out;
    if (!pe.code.empty()) {
      out = error_line(rq.has_id, rq.id, pe.code, pe.message);
    } else if (rq.spec->where == Where::session) {
      out = error_line(rq.has_id, rq.id, "unsupported",
                       std::string(rq.spec->name) + ": a socket client's message (MQTT has no session: state and events are "
                                                    "published, control is the broker's access rule)");
    } else if (rq.spec->gate == Gate::control && api != nullptr && api->controller() != 0) {
      out = error_line(rq.has_id, rq.id, to_string(ApiError::controlled),
                       std::string(rq.spec->name) + ": API client " + std::to_string(api->controller()) + " holds control");
    } else {
      out = execute(cx, rq);
      ++ran;
    }
    s.publish("result", out, 1);
  }
  if (cx.svc != nullptr) {
    cx.svc->poll_events();
    if (!s.event_seq_set) {
      s.event_seq = cx.svc->next_event_seq() - 1;
      s.event_seq_set = true;
    }
    if (cx.svc->next_event_seq() - 1 > s.event_seq) {
      const fw::EventBatch b = cx.svc->events_since(s.event_seq);
      s.events_missed += b.missed;
      for (const fw::ArmEvent& e : b.events) {
        if (s.up) s.publish("events", event_line(e, cx.svc->event_detail(e), s.events_missed), 1);
        s.event_seq = e.seq;
      }
    }
  }
  const auto now = std::chrono::steady_clock::now();
  if (s.up && now >= s.next_state) {
    s.publish("state", state_line(s.ctl.telemetry(), s.cfg.rate_hz, s.chain, 0), 0);
    const auto period = std::chrono::nanoseconds(static_cast<std::int64_t>(1e9 / s.cfg.state_rate_hz));
    s.next_state = now - s.next_state > 2 * period ? now + period : s.next_state + period;
  }
  return ran;
}

}  // namespace servoarm::api
