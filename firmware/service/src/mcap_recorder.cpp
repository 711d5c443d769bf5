// SPDX-License-Identifier: Apache-2.0
// The MCAP recording (mcap_recorder.hpp): file naming and rotation, the JSON messages and
// their schemas, the recorder thread. Non-real-time.
#include "servoarm/service/mcap_recorder.hpp"

#include <fcntl.h>
#include <pthread.h>
#include <sched.h>
#include <sys/stat.h>
#include <time.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>

namespace servoarm::fw {

namespace {

constexpr const char* kNumbers = R"({"type":"array","items":{"type":"number"}})";

std::string schema_state() {
  return std::string(R"({"title":"servoarm.State","description":"the control thread's telemetry of one cycle in SI units: rad, m, s, N m","type":"object","properties":{)") +
         R"("cycle":{"type":"integer","description":"control cycle counter"},"t":{"type":"number","description":"cycle x control period in s"},)" +
         R"("state":{"type":"string"},"mode":{"type":"string"},"holding":{"type":"boolean"},)" +
         R"("q":)" + kNumbers + R"(,"qd":)" + kNumbers +
         R"(,"torque":{"type":"array","items":{"type":["number","null"]},"description":"null: the drive reports none"},)" +
         R"("following_error":)" + kNumbers + R"(,"running":{"type":"integer"},"queued":{"type":"integer"},"homed":{"type":"integer"},)" +
         R"("missed":{"type":"integer","description":"due cycles the control thread could not keep for the recorder (its sample ring full), since the recording began"}}})";
}
std::string schema_setpoint() {
  return std::string(R"({"title":"servoarm.Setpoint","description":"the setpoints the control thread sent to the drives","type":"object","properties":{)") +
         R"("cycle":{"type":"integer"},"t":{"type":"number"},"q_cmd":)" + kNumbers + R"(,"qd_cmd":)" + kNumbers + "}}";
}
std::string schema_event() {
  return R"({"title":"servoarm.Event","description":"an event of the arm service's stream","type":"object","properties":{)"
         R"("seq":{"type":"integer"},"cycle":{"type":"integer"},"t":{"type":"number"},"kind":{"type":"string"},"state":{"type":"string"},)"
         R"("cause":{"type":"string"},"joint":{"type":"integer"},"motion_id":{"type":"integer"},"detail":{"type":"string"}}})";
}
std::string schema_robot() {
  return R"({"title":"servoarm.RobotDescription","description":"the kinematic chain as DH rows in SI units, base and tool as 4x4 row-major matrices","type":"object","properties":{)"
         R"("name":{"type":"string"},"convention":{"type":"string"},"joints":{"type":"integer"},"rate_hz":{"type":"number"},)"
         R"("rows":{"type":"array","items":{"type":"object"}},"base":{"type":"array","items":{"type":"number"}},"tool":{"type":"array","items":{"type":"number"}}}})";
}

void num(std::string& s, double v) {
  if (!std::isfinite(v)) {
    s += "null";
    return;
  }
  char b[32];
  std::snprintf(b, sizeof b, "%.9g", v);
  s += b;
}
void integer(std::string& s, std::uint64_t v) { s += std::to_string(v); }
void text(std::string& s, std::string_view v) {
  s += '"';
  for (const char ch : v) {
    const auto u = static_cast<unsigned char>(ch);
    if (ch == '"' || ch == '\\') s += '\\', s += ch;
    else if (u < 0x20) {
      char b[8];
      std::snprintf(b, sizeof b, "\\u%04x", u);
      s += b;
    } else s += ch;
  }
  s += '"';
}
template <typename F>
void array(std::string& s, int n, F f) {
  s += '[';
  for (int i = 0; i < n; ++i) {
    if (i) s += ',';
    f(static_cast<std::size_t>(i));
  }
  s += ']';
}
void matrix(std::string& s, const kin::Pose& p) {
  s += '[';
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) {
      if (r || c) s += ',';
      num(s, p.matrix()(r, c));
    }
  s += ']';
}

std::int64_t wall_ns() {
  timespec ts{};
  ::clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}
std::int64_t mono_ns() {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

}  // namespace

std::uint64_t McapRecorder::t_ns(std::uint64_t cycle) const {
  const double dc = cycle >= start_cycle_ ? static_cast<double>(cycle - start_cycle_) : 0.0;
  return static_cast<std::uint64_t>(epoch_ns_ + static_cast<std::int64_t>(std::llround(dc * period_ns_)));
}

std::string McapRecorder::open_next() {
  char stamp[32];
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  ::gmtime_r(&now, &tm);
  std::strftime(stamp, sizeof stamp, "%Y%m%d-%H%M%S", &tm);
  std::string err;
  for (int k = 0; k < 1000; ++k) {
    char name[96];
    std::snprintf(name, sizeof name, "/servoarm-%s-%03d.mcap", stamp, k);
    const std::string path = cfg_.dir + name;
    err = w_.open(path, cfg_.chunk_kb * 1024);
    if (err.empty()) {
      {
        std::lock_guard<std::mutex> l(mu_);
        status_.file = path;
        ++status_.files;
      }
      ch_state_ = w_.add_channel(w_.add_schema("servoarm.State", schema_state()), "/arm/state");
      ch_setpoint_ = w_.add_channel(w_.add_schema("servoarm.Setpoint", schema_setpoint()), "/arm/setpoint");
      ch_event_ = w_.add_channel(w_.add_schema("servoarm.Event", schema_event()), "/arm/events");
      ch_robot_ = w_.add_channel(w_.add_schema("servoarm.RobotDescription", schema_robot()), "/robot_description");
      // The robot description, first in every file (a file of a rotation reads on its own).
      std::string s = "{\"name\":";
      text(s, chain_.name.data());
      s += ",\"convention\":";
      text(s, kin::to_string(chain_.convention));
      s += ",\"joints\":" + std::to_string(chain_.n_joints) + ",\"rate_hz\":";
      num(s, 1e9 / period_ns_);
      s += ",\"rows\":";
      array(s, chain_.n_rows, [&](std::size_t i) {
        const kin::DhRow& r = chain_.rows[i];
        s += "{\"type\":";
        text(s, kin::to_string(r.type));
        s += ",\"theta\":", num(s, r.theta);
        s += ",\"d\":", num(s, r.d);
        s += ",\"a\":", num(s, r.a);
        s += ",\"alpha\":", num(s, r.alpha);
        s += ",\"direction\":", num(s, r.direction);
        s += ",\"lower\":", num(s, r.lower);
        s += ",\"upper\":", num(s, r.upper);
        s += '}';
      });
      s += ",\"base\":", matrix(s, chain_.base);
      s += ",\"tool\":", matrix(s, chain_.tool);
      s += '}';
      return w_.write(ch_robot_, t_ns(next_ > every_ ? next_ - every_ : start_cycle_), s);
    }
    if (err.find(std::strerror(EEXIST)) == std::string::npos) return err;
  }
  return err;
}

std::string McapRecorder::start(const McapSettings& s, double rate_hz, bool threaded) {
  if (active_.load()) return "already recording to " + status().file;
  if (s.dir.empty()) return "no recordings folder (record.dir)";
  struct stat st {};
  if (::stat(s.dir.c_str(), &st) != 0 || !S_ISDIR(st.st_mode)) return "record.dir " + s.dir + ": not a folder";
  const double loop = ctl_.config().rate_hz;
  if (!(rate_hz > 0) || !std::isfinite(rate_hz) || rate_hz > loop * (1 + 1e-9)) {
    char b[96];
    std::snprintf(b, sizeof b, "rate %g Hz: outside (0, %g] (the control rate)", rate_hz, loop);
    return b;
  }
  cfg_ = s;
  every_ = static_cast<std::uint64_t>(std::max(1.0, std::ceil(loop / rate_hz - 1e-9)));
  period_ns_ = 1e9 / loop;
  const Telemetry t = ctl_.telemetry();
  start_cycle_ = t.cycles;
  epoch_ns_ = wall_ns();
  next_ = (t.cycles / every_ + 1) * every_;
  ctl_.start_samples(every_);
  dropped_at_start_ = ctl_.samples_dropped();
  {
    std::lock_guard<std::mutex> l(mu_);
    status_ = McapStatus{};
    status_.rate_hz = loop / static_cast<double>(every_);
    events_.clear();
  }
  bytes_before_ = 0;
  if (std::string e = open_next(); !e.empty()) return e;
  last_flush_ns_ = mono_ns();
  active_ = true;
  {
    std::lock_guard<std::mutex> l(mu_);
    status_.active = true;
  }
  quit_ = false;
  threaded_ = threaded;
  if (threaded) {
    thread_ = std::thread([this] {
      ::pthread_setname_np(::pthread_self(), "mcap-recorder");  // top -H, the CPU figures in tests/bench
      if (cfg_.priority > 0) {  // best effort: without the right to, the thread runs at normal priority
        sched_param sp{};
        sp.sched_priority = cfg_.priority;
        ::pthread_setschedparam(::pthread_self(), SCHED_FIFO, &sp);
      }
      while (!quit_.load()) {
        poll();
        // The control thread keeps every cycle due in its sample ring (Controller::kSampleRing
        // cycles, about 2 s at 1 kHz): a look every 10 ms writes them in batches.
        timespec d{0, 10 * 1000 * 1000};
        ::nanosleep(&d, nullptr);
      }
    });
  }
  return "";
}

void McapRecorder::event(const ArmEvent& e, std::string_view detail) {
  if (!active_.load()) return;
  std::string s = "{\"seq\":";
  integer(s, e.seq);
  s += ",\"cycle\":", integer(s, e.cycle);
  s += ",\"t\":", num(s, e.t);
  s += ",\"kind\":", text(s, to_string(e.kind));
  s += ",\"state\":", text(s, to_string(e.state));
  s += ",\"cause\":", text(s, to_string(e.cause));
  s += ",\"joint\":" + std::to_string(e.joint);
  s += ",\"motion_id\":" + std::to_string(e.motion_id);
  s += ",\"detail\":", text(s, detail);
  s += '}';
  std::lock_guard<std::mutex> l(mu_);
  events_.emplace_back(e.cycle, std::move(s));
}

void McapRecorder::write_state(const CycleSample& t) {
  const int n = std::min(static_cast<int>(t.n), chain_.n_joints);
  const std::uint64_t ts = t_ns(t.cycles);
  std::uint64_t missed = 0;
  {
    std::lock_guard<std::mutex> l(mu_);
    missed = status_.missed;
  }
  std::string& s = json_;
  s.clear();
  s += "{\"cycle\":", integer(s, t.cycles);
  s += ",\"t\":", num(s, static_cast<double>(t.cycles) * period_ns_ * 1e-9);
  s += ",\"state\":", text(s, to_string(t.state));
  s += ",\"mode\":", text(s, to_string(t.mode));
  s += t.holding ? ",\"holding\":true" : ",\"holding\":false";
  s += ",\"q\":", array(s, n, [&](std::size_t i) { num(s, t.q_act[i]); });
  s += ",\"qd\":", array(s, n, [&](std::size_t i) { num(s, t.qd_act[i]); });
  s += ",\"torque\":", array(s, n, [&](std::size_t i) {
    if ((t.torque_valid >> i) & 1u) num(s, t.tau_act[i]);
    else s += "null";
  });
  s += ",\"following_error\":", array(s, n, [&](std::size_t i) { num(s, t.q_cmd[i] - t.q_act[i]); });
  s += ",\"running\":" + std::to_string(t.running_id) + ",\"queued\":" + std::to_string(t.queued) +
       ",\"homed\":" + std::to_string(t.homed) + ",\"missed\":" + std::to_string(missed) + "}";
  std::string e = w_.write(ch_state_, ts, s);
  if (e.empty()) {
    s.clear();
    s += "{\"cycle\":", integer(s, t.cycles);
    s += ",\"t\":", num(s, static_cast<double>(t.cycles) * period_ns_ * 1e-9);
    s += ",\"q_cmd\":", array(s, n, [&](std::size_t i) { num(s, t.q_cmd[i]); });
    s += ",\"qd_cmd\":", array(s, n, [&](std::size_t i) { num(s, t.qd_cmd[i]); });
    s += '}';
    e = w_.write(ch_setpoint_, ts, s);
  }
  if (!e.empty()) return end(e);
  std::lock_guard<std::mutex> l(mu_);
  ++status_.frames;
  status_.bytes = bytes_before_ + w_.size();
}

void McapRecorder::end(std::string why) {
  ctl_.stop_samples();
  w_.close();
  active_ = false;
  std::lock_guard<std::mutex> l(mu_);
  status_.active = false;
  status_.error = std::move(why);
}

void McapRecorder::poll() {
  if (!active_.load()) return;
  CycleSample c;
  while (active_.load() && ctl_.pop_sample(c)) {
    if (c.cycles < next_) continue;  // left from before this recording began
    next_ = c.cycles + every_;
    write_state(c);
  }
  {
    std::lock_guard<std::mutex> l(mu_);
    status_.missed = ctl_.samples_dropped() - dropped_at_start_;
  }
  if (!active_.load()) return;
  std::vector<std::pair<std::uint64_t, std::string>> evs;
  {
    std::lock_guard<std::mutex> l(mu_);
    evs.swap(events_);
  }
  for (auto& [cycle, json] : evs) {
    if (std::string e = w_.write(ch_event_, t_ns(cycle), json); !e.empty()) return end(e);
    std::lock_guard<std::mutex> l(mu_);
    ++status_.events;
  }
  const std::int64_t now = mono_ns();
  if (now - last_flush_ns_ >= 1000000000) {  // a chunk at least every second: the most a power cut loses
    last_flush_ns_ = now;
    if (std::string e = w_.flush(); !e.empty()) return end(e);
  }
  if (static_cast<double>(w_.size()) >= cfg_.max_file_mb * 1e6) {
    const std::uint64_t size = w_.size();
    if (std::string e = w_.close(); !e.empty()) return end(e);
    bytes_before_ += size;
    int files = 0;
    {
      std::lock_guard<std::mutex> l(mu_);
      files = status_.files;
    }
    if (cfg_.max_files > 0 && files >= cfg_.max_files) return end("record.max_files reached (" + std::to_string(files) + " files)");
    if (std::string e = open_next(); !e.empty()) return end(e);
  }
}

McapStatus McapRecorder::stop() {
  quit_ = true;
  if (thread_.joinable()) thread_.join();
  ctl_.stop_samples();
  if (active_.load()) {
    poll();  // the cycles and the events handed over last
    const std::uint64_t size = w_.size();
    const std::string e = w_.close();
    active_ = false;
    std::lock_guard<std::mutex> l(mu_);
    status_.active = false;
    status_.bytes = bytes_before_ + size;
    if (!e.empty()) status_.error = e;
  }
  return status();
}

McapStatus McapRecorder::status() const {
  std::lock_guard<std::mutex> l(mu_);
  return status_;
}

}  // namespace servoarm::fw
