// SPDX-License-Identifier: Apache-2.0
// The Foxglove WebSocket server (foxglove.hpp). Protocol: https://github.com/foxglove/ws-protocol
// (foxglove.websocket.v1): the server sends `serverInfo` and `advertise` (text, JSON) on
// connect; a client sends `subscribe` / `unsubscribe`; each message goes to a subscriber as a
// binary frame: opcode 0x01, subscription id (u32 LE), receive time (u64 LE, ns), the JSON.
#include "servoarm/api/foxglove.hpp"
#include "servoarm/api/server.hpp"

#include <libwebsockets.h>
#include <time.h>

#include <array>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <map>
#include <mutex>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "servoarm/kinematics/orientation.hpp"

namespace servoarm::api {

using json = nlohmann::json;

namespace {

enum Channel : std::uint16_t { kState = 1, kTf = 2, kToolPose = 3, kEvents = 4, kChannels = 5 };

const char* const kTimeSchema = R"j({"type":"object","properties":{"sec":{"type":"integer"},"nsec":{"type":"integer"}}})j";
std::string vec3_schema() { return R"j({"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}})j"; }
std::string quat_schema() {
  return R"j({"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}})j";
}
std::string transform_schema() {
  return std::string(R"j({"type":"object","properties":{"timestamp":)j") + kTimeSchema +
         R"j(,"parent_frame_id":{"type":"string"},"child_frame_id":{"type":"string"},"translation":)j" + vec3_schema() +
         R"j(,"rotation":)j" + quat_schema() + "}}";
}

struct ChannelInfo {
  Channel id;
  const char* topic;
  const char* schema_name;
  std::string schema;
};
std::vector<ChannelInfo> channel_infos() {
  const std::string nums = R"j({"type":"array","items":{"type":"number"}})j";
  return {
      {kState, "/arm/state", "servoarm.State",
       std::string(R"j({"type":"object","properties":{"cycle":{"type":"integer"},"t":{"type":"number"},"state":{"type":"string"},)j") +
           R"j("mode":{"type":"string"},"q":)j" + nums + R"j(,"qd":)j" + nums + R"j(,"q_cmd":)j" + nums + R"j(,"qd_cmd":)j" + nums +
           R"j(,"following_error":)j" + nums + R"j(,"torque":{"type":"array","items":{"type":["number","null"]}},)j" +
           R"j("tool":{"type":"object","properties":{"position":)j" + nums + R"j(,"rpy":)j" + nums + R"j(}},)j" +
           R"j("fault":{"type":"object","properties":{"cause":{"type":"string"},"joint":{"type":"integer"},"text":{"type":"string"}}}}})j"},
      {kTf, "/tf", "foxglove.FrameTransforms",
       R"j({"type":"object","properties":{"transforms":{"type":"array","items":)j" + transform_schema() + "}}}"},
      {kToolPose, "/tool_pose", "foxglove.PoseInFrame",
       std::string(R"j({"type":"object","properties":{"timestamp":)j") + kTimeSchema +
           R"j(,"frame_id":{"type":"string"},"pose":{"type":"object","properties":{"position":)j" + vec3_schema() +
           R"j(,"orientation":)j" + quat_schema() + "}}}}"},
      {kEvents, "/events", "foxglove.Log",
       std::string(R"j({"type":"object","properties":{"timestamp":)j") + kTimeSchema +
           R"j(,"level":{"type":"integer","description":"1 debug, 2 info, 3 warning, 4 error, 5 fatal"},)j"
           R"j("message":{"type":"string"},"name":{"type":"string"},"file":{"type":"string"},"line":{"type":"integer"}}})j"},
  };
}

std::int64_t wall_ns() {
  timespec ts{};
  ::clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}
json stamp(std::int64_t ns) { return {{"sec", ns / 1000000000}, {"nsec", ns % 1000000000}}; }
json transform(std::int64_t ns, const std::string& parent, const std::string& child, const kin::Pose& p) {
  const Eigen::Quaterniond q(p.linear());
  return {{"timestamp", stamp(ns)},
          {"parent_frame_id", parent},
          {"child_frame_id", child},
          {"translation", {{"x", p.translation().x()}, {"y", p.translation().y()}, {"z", p.translation().z()}}},
          {"rotation", {{"x", q.x()}, {"y", q.y()}, {"z", q.z()}, {"w", q.w()}}}};
}

// A service event's log level: faults and e-stops are errors, refusals and stopped jogs warnings.
int level_of(fw::ArmEventKind k) {
  switch (k) {
    case fw::ArmEventKind::fault:
    case fw::ArmEventKind::estop: return 4;
    case fw::ArmEventKind::motion_refused:
    case fw::ArmEventKind::jog_stopped:
    case fw::ArmEventKind::warning: return 3;
    case fw::ArmEventKind::motion_done:
    case fw::ArmEventKind::state:
    case fw::ArmEventKind::homing:
    case fw::ArmEventKind::freedrive:
    case fw::ArmEventKind::program: return 2;
  }
  return 2;
}

struct Client {
  lws* wsi = nullptr;
  std::map<std::uint32_t, std::uint16_t> subs;  ///< subscription id -> channel
  std::deque<std::pair<bool, std::string>> out;  ///< (binary, payload)
  std::size_t out_bytes = 0;
  std::string rx;
};

}  // namespace

struct FoxgloveServer::Impl {
  FoxgloveConfig cfg;
  fw::Controller& ctl;
  const kin::Chain& chain;
  lws_context* ctx = nullptr;
  lws_vhost* vh = nullptr;
  std::thread net, pub;
  std::atomic<bool> quit{false};
  std::mutex pub_mu;
  std::condition_variable pub_cv;
  std::array<std::atomic<int>, kChannels> subscribers{};
  std::mutex mu;  ///< pending
  std::vector<std::pair<std::uint16_t, std::string>> pending;
  std::map<lws*, std::unique_ptr<Client>> clients;  ///< network thread only
  std::atomic<std::uint64_t> sent{0}, dropped{0};
  std::atomic<int> n_clients{0};
  std::uint64_t event_seq = 0;
  bool event_seq_set = false;
  std::vector<ChannelInfo> infos = channel_infos();

  Impl(const FoxgloveConfig& c, fw::Controller& t, const kin::Chain& ch) : cfg(c), ctl(t), chain(ch) {}

  void post(std::uint16_t ch, std::string payload) {
    {
      std::lock_guard<std::mutex> l(mu);
      pending.emplace_back(ch, std::move(payload));
    }
    if (ctx) lws_cancel_service(ctx);
  }

  void enqueue(Client& c, bool binary, std::string s, bool droppable) {
    if (droppable && c.out_bytes + s.size() > cfg.client_buffer) {
      ++dropped;
      return;
    }
    c.out_bytes += s.size();
    c.out.emplace_back(binary, std::move(s));
    lws_callback_on_writable(c.wsi);
  }

  void open_client(lws* wsi) {
    auto c = std::make_unique<Client>();
    c->wsi = wsi;
    Client& r = *c;
    clients[wsi] = std::move(c);
    ++n_clients;
    json info = {{"op", "serverInfo"}, {"name", cfg.name}, {"capabilities", json::array()},
                 {"supportedEncodings", json::array()}, {"metadata", {{"robot", std::string(chain.name.data())}}},
                 {"sessionId", std::to_string(wall_ns())}};
    enqueue(r, false, info.dump(), false);
    json chans = json::array();
    for (const ChannelInfo& ci : infos)
      chans.push_back({{"id", ci.id}, {"topic", ci.topic}, {"encoding", "json"}, {"schemaName", ci.schema_name},
                       {"schema", ci.schema}, {"schemaEncoding", "jsonschema"}});
    enqueue(r, false, json{{"op", "advertise"}, {"channels", chans}}.dump(), false);
  }
  void close_client(lws* wsi) {
    auto it = clients.find(wsi);
    if (it == clients.end()) return;
    for (const auto& [sid, ch] : it->second->subs) --subscribers[ch];
    clients.erase(it);
    --n_clients;
  }
  void on_text(Client& c, const std::string& text) {
    const json j = json::parse(text, nullptr, false);
    if (!j.is_object() || !j.contains("op") || !j["op"].is_string()) return;
    const std::string op = j["op"];
    auto status = [&](int level, const std::string& msg) {
      enqueue(c, false, json{{"op", "status"}, {"level", level}, {"message", msg}}.dump(), false);
    };
    if (op == "subscribe" && j.contains("subscriptions") && j["subscriptions"].is_array()) {
      for (const json& s : j["subscriptions"]) {
        if (!s.is_object() || !s.contains("id") || !s.contains("channelId") || !s["id"].is_number_unsigned() ||
            !s["channelId"].is_number_unsigned()) {
          status(2, "subscribe: each subscription needs id and channelId");
          continue;
        }
        const auto sid = s["id"].get<std::uint32_t>();
        const auto ch = s["channelId"].get<std::uint32_t>();
        if (ch < 1 || ch >= kChannels) {
          status(2, "subscribe: no channel " + std::to_string(ch));
          continue;
        }
        if (c.subs.count(sid)) {
          status(2, "subscribe: subscription id " + std::to_string(sid) + " is taken");
          continue;
        }
        c.subs[sid] = static_cast<std::uint16_t>(ch);
        ++subscribers[ch];
      }
      pub_cv.notify_all();
    } else if (op == "unsubscribe" && j.contains("subscriptionIds") && j["subscriptionIds"].is_array()) {
      for (const json& s : j["subscriptionIds"]) {
        if (!s.is_number_unsigned()) continue;
        auto it = c.subs.find(s.get<std::uint32_t>());
        if (it == c.subs.end()) continue;
        --subscribers[it->second];
        c.subs.erase(it);
      }
    } else {
      status(1, "unsupported op " + op.substr(0, 40) + ": this server publishes only");
    }
  }
  void distribute() {
    std::vector<std::pair<std::uint16_t, std::string>> msgs;
    {
      std::lock_guard<std::mutex> l(mu);
      msgs.swap(pending);
    }
    const std::int64_t now = wall_ns();
    for (const auto& [ch, payload] : msgs)
      for (auto& [wsi, c] : clients)
        for (const auto& [sid, sch] : c->subs) {
          if (sch != ch) continue;
          std::string f;
          f.reserve(13 + payload.size());
          f.push_back('\x01');
          for (int i = 0; i < 4; ++i) f.push_back(static_cast<char>((sid >> (8 * i)) & 0xFF));
          for (int i = 0; i < 8; ++i) f.push_back(static_cast<char>((static_cast<std::uint64_t>(now) >> (8 * i)) & 0xFF));
          f += payload;
          enqueue(*c, true, std::move(f), true);
        }
  }
  int writable(Client& c) {
    if (c.out.empty()) return 0;
    if (lws_send_pipe_choked(c.wsi)) {
      lws_callback_on_writable(c.wsi);
      return 0;
    }
    auto& [binary, s] = c.out.front();
    std::vector<unsigned char> buf(LWS_PRE + s.size());
    std::memcpy(buf.data() + LWS_PRE, s.data(), s.size());
    const int w = lws_write(c.wsi, buf.data() + LWS_PRE, s.size(), binary ? LWS_WRITE_BINARY : LWS_WRITE_TEXT);
    if (w < static_cast<int>(s.size())) return -1;
    if (binary) ++sent;
    c.out_bytes -= s.size();
    c.out.pop_front();
    if (!c.out.empty()) lws_callback_on_writable(c.wsi);
    return 0;
  }

  /// The publisher thread: the messages of the channels someone subscribes to, at their rates.
  void publish_loop() {
    const auto period = [](double hz) { return static_cast<std::int64_t>(1e9 / hz); };
    const std::int64_t ps = period(std::min(cfg.state_rate_hz, cfg.rate_hz)), pt = period(std::min(cfg.tf_rate_hz, cfg.rate_hz));
    timespec t0{};
    ::clock_gettime(CLOCK_MONOTONIC, &t0);
    std::int64_t now = static_cast<std::int64_t>(t0.tv_sec) * 1000000000 + t0.tv_nsec;
    std::int64_t due_s = now, due_t = now;
    kin::FrameSet frames;
    while (!quit.load()) {
      const std::int64_t next = std::min(due_s, due_t);
      timespec d{static_cast<time_t>(next / 1000000000), static_cast<long>(next % 1000000000)};
      ::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &d, nullptr);
      if (quit.load()) break;
      ::clock_gettime(CLOCK_MONOTONIC, &t0);
      now = static_cast<std::int64_t>(t0.tv_sec) * 1000000000 + t0.tv_nsec;
      const bool do_s = now >= due_s, do_t = now >= due_t;
      if (do_s) due_s = std::max(due_s + ps, now - ps);  // behind: skip, do not burst
      if (do_t) due_t = std::max(due_t + pt, now - pt);
      const bool want_state = do_s && subscribers[kState] > 0, want_pose = do_s && subscribers[kToolPose] > 0,
                 want_tf = do_t && subscribers[kTf] > 0;
      if (!want_state && !want_pose && !want_tf) continue;
      const fw::Telemetry tel = ctl.telemetry();
      const std::int64_t wall = wall_ns();
      if (want_state) post(kState, state_line(tel, cfg.rate_hz, chain, 0));
      if ((want_pose || want_tf) && tel.n == chain.n_joints) {
        kin::JointVector q(chain.n_joints);
        for (int j = 0; j < chain.n_joints; ++j) q[j] = tel.q_act[static_cast<std::size_t>(j)];
        kin::Pose tool = kin::Pose::Identity();
        if (kin::forward_frames(chain, q, frames, tool) != kin::Status::ok) continue;
        if (want_pose) {
          const Eigen::Quaterniond o(tool.linear());
          post(kToolPose, json{{"timestamp", stamp(wall)},
                               {"frame_id", "world"},
                               {"pose", {{"position", {{"x", tool.translation().x()}, {"y", tool.translation().y()}, {"z", tool.translation().z()}}},
                                         {"orientation", {{"x", o.x()}, {"y", o.y()}, {"z", o.z()}, {"w", o.w()}}}}}}
                                  .dump());
        }
        if (want_tf) {
          json ts = json::array();
          ts.push_back(transform(wall, "world", "base", frames.frame[0]));
          std::string parent = "base";
          const int n = std::min(chain.n_rows, frames.count - 1);
          for (int k = 1; k <= n; ++k) {
            const std::string child = "link" + std::to_string(k);
            ts.push_back(transform(wall, parent, child, frames.frame[k - 1].inverse() * frames.frame[k]));
            parent = child;
          }
          ts.push_back(transform(wall, parent, "tool", frames.frame[n].inverse() * tool));
          post(kTf, json{{"transforms", ts}}.dump());
        }
      }
    }
  }
};

namespace {

int callback(lws* wsi, lws_callback_reasons reason, void* user, void* in, size_t len) {
  lws_context* cx = lws_get_context(wsi);
  auto* self = cx ? static_cast<FoxgloveServer::Impl*>(lws_context_user(cx)) : nullptr;
  if (self == nullptr) return 0;
  switch (reason) {
    case LWS_CALLBACK_EVENT_WAIT_CANCELLED: self->distribute(); return 0;
    case LWS_CALLBACK_ESTABLISHED: self->open_client(wsi); return 0;
    case LWS_CALLBACK_RECEIVE: {
      auto it = self->clients.find(wsi);
      if (it == self->clients.end()) return -1;
      Client& c = *it->second;
      if (c.rx.size() + len > 64 * 1024) return -1;  // a client's request is small: a flood closes it
      c.rx.append(static_cast<const char*>(in), len);
      if (lws_is_final_fragment(wsi) && lws_remaining_packet_payload(wsi) == 0) {
        if (!lws_frame_is_binary(wsi)) self->on_text(c, c.rx);
        c.rx.clear();
      }
      return 0;
    }
    case LWS_CALLBACK_SERVER_WRITEABLE: {
      auto it = self->clients.find(wsi);
      return it == self->clients.end() ? -1 : self->writable(*it->second);
    }
    case LWS_CALLBACK_CLOSED: self->close_client(wsi); return 0;
    default: break;
  }
  return lws_callback_http_dummy(wsi, reason, user, in, len);
}

const lws_protocols kProtocols[] = {
    {"foxglove.websocket.v1", callback, 0, 4096, 0, nullptr, 0},
    {nullptr, nullptr, 0, 0, 0, nullptr, 0},
};

}  // namespace

FoxgloveServer::FoxgloveServer(const FoxgloveConfig& cfg, fw::Controller& ctl, const kin::Chain& chain)
    : impl_(std::make_unique<Impl>(cfg, ctl, chain)) {}
FoxgloveServer::~FoxgloveServer() { stop(); }

std::string FoxgloveServer::start() {
  Impl& s = *impl_;
  if (s.ctx != nullptr) return "";
  if (!(s.cfg.state_rate_hz > 0) || !(s.cfg.tf_rate_hz > 0)) return "foxglove: rates must be > 0";
  // The Foxglove WebSocket protocol carries no authentication: the server listens on this
  // machine only, and a viewer elsewhere reaches it through a tunnel (ssh -L).
  if (!is_loopback(s.cfg.bind))
    return "foxglove.bind = " + s.cfg.bind + ": loopback only (the Foxglove protocol has no authentication; use ssh -L from the viewer)";
  lws_set_log_level(LLL_ERR, nullptr);
  lws_context_creation_info info;
  std::memset(&info, 0, sizeof info);
  info.options = LWS_SERVER_OPTION_EXPLICIT_VHOSTS;
  info.user = &s;
  info.port = CONTEXT_PORT_NO_LISTEN;
  s.ctx = lws_create_context(&info);
  if (s.ctx == nullptr) return "foxglove: cannot create the server (libwebsockets)";
  const std::string iface = s.cfg.bind == "localhost" ? "127.0.0.1" : s.cfg.bind;
  lws_context_creation_info v;
  std::memset(&v, 0, sizeof v);
  v.vhost_name = "foxglove";
  v.port = s.cfg.port;
  v.iface = iface.c_str();
  v.protocols = kProtocols;
  v.user = &s;
  s.vh = lws_create_vhost(s.ctx, &v);
  if (s.vh == nullptr) {
    lws_context_destroy(s.ctx);
    s.ctx = nullptr;
    return "foxglove: cannot listen on " + s.cfg.bind + ":" + std::to_string(s.cfg.port);
  }
  s.quit = false;
  s.net = std::thread([&s] {
    while (!s.quit.load()) lws_service(s.ctx, 0);
  });
  s.pub = std::thread([&s] { s.publish_loop(); });
  return "";
}

void FoxgloveServer::stop() {
  Impl& s = *impl_;
  if (s.ctx == nullptr) return;
  s.quit = true;
  if (s.pub.joinable()) s.pub.join();
  lws_cancel_service(s.ctx);
  if (s.net.joinable()) s.net.join();
  lws_context_destroy(s.ctx);
  s.ctx = nullptr;
  s.vh = nullptr;
  s.clients.clear();
}

int FoxgloveServer::port() const { return impl_->vh ? lws_get_vhost_listen_port(impl_->vh) : -1; }

void FoxgloveServer::pump(ServiceContext& cx) {
  Impl& s = *impl_;
  if (cx.svc == nullptr) return;
  if (!s.event_seq_set) {  // events from the server's start on
    s.event_seq = cx.svc->next_event_seq() - 1;
    s.event_seq_set = true;
  }
  const fw::EventBatch b = cx.svc->events_since(s.event_seq);
  if (b.events.empty()) return;
  const std::int64_t wall = wall_ns();
  for (const fw::ArmEvent& e : b.events) {
    s.event_seq = e.seq;
    if (s.subscribers[kEvents] == 0) continue;
    const std::string detail(cx.svc->event_detail(e));
    std::string msg = std::string(fw::to_string(e.kind)) + ": state " + fw::to_string(e.state);
    if (e.cause != fw::FaultCause::none) msg += ", cause " + std::string(fw::to_string(e.cause));
    if (e.joint >= 0) msg += ", joint " + std::to_string(e.joint + 1);
    if (e.motion_id != 0) msg += ", motion " + std::to_string(e.motion_id);
    if (!detail.empty()) msg += ": " + detail;
    s.post(kEvents, json{{"timestamp", stamp(wall)}, {"level", level_of(e.kind)}, {"message", msg}, {"name", "servoarm"},
                         {"file", ""}, {"line", 0}}
                        .dump(-1, ' ', false, json::error_handler_t::replace));
  }
}

FoxgloveStats FoxgloveServer::stats() const {
  return {impl_->n_clients.load(), impl_->sent.load(), impl_->dropped.load()};
}

}  // namespace servoarm::api
