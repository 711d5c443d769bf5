// SPDX-License-Identifier: Apache-2.0
// The MQTT bridge (docs/api.md#mqtt) end to end: a mosquitto broker on a loopback port, two
// `armfw --sim` processes connected to it as arm1 and arm2, and mosquitto_pub / mosquitto_sub
// as the cell controller (an independent MQTT client). Each arm announces itself online
// (retained), takes commands on its own topic, answers on `result`, publishes its state and
// events; a bad command moves nothing; a killed arm is marked offline by its last will.
// Every wait polls for its condition with a generous bound (the machine may be busy).
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <thread>

#include "text_regex.hpp"

#include <CppUTest/TestHarness.h>

namespace test = servoarm::test;

namespace {

std::string dir() { return "/tmp/servoarm_mqtt_" + std::to_string(::getpid()); }

int free_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
  socklen_t n = sizeof a;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &n);
  ::close(fd);
  return ntohs(a.sin_port);
}

/// `sh -c "exec CMD"` in the background, its output into `log`. Returns the pid.
pid_t spawn(const std::string& cmd, const std::string& log) {
  const pid_t pid = fork();
  if (pid == 0) {
    std::freopen(log.c_str(), "w", stdout);
    std::freopen(log.c_str(), "a", stderr);
    std::freopen("/dev/null", "r", stdin);
    execl("/bin/sh", "sh", "-c", ("exec " + cmd).c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  return pid;
}

void end(pid_t pid, int sig = SIGTERM) {
  if (pid <= 0) return;
  ::kill(pid, sig);
  int st = 0;
  for (int i = 0; i < 500 && ::waitpid(pid, &st, WNOHANG) == 0; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  if (::waitpid(pid, &st, WNOHANG) == 0) {
    ::kill(pid, SIGKILL);
    ::waitpid(pid, &st, 0);
  }
}

std::string slurp(const std::string& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

/// Polls `cond` every 50 ms for up to `s` seconds.
bool until(double s, const std::function<bool()>& cond) {
  const auto end_t = std::chrono::steady_clock::now() + std::chrono::milliseconds(static_cast<int>(s * 1000));
  while (std::chrono::steady_clock::now() < end_t) {
    if (cond()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return cond();
}

bool has(const std::string& s, const std::string& w) { return s.find(w) != std::string::npos; }

/// The first joint of the newest state sample of `arm` in mosquitto_sub -v output.
bool last_q0(const std::string& log, const std::string& arm, double& q0) {
  const std::string key = "servoarm/" + arm + "/state ";
  const auto p = log.rfind(key);
  if (p == std::string::npos) return false;
  const auto q = log.find("\"q\":[", p);
  return q != std::string::npos && std::sscanf(log.c_str() + q + 5, "%lf", &q0) == 1;
}

/// The largest |first joint| over every state sample of `arm` in mosquitto_sub -v output
/// (parsed as a number: a tiny value such as 9.4e-17 is near zero, not 9).
double max_abs_q0(const std::string& log, const std::string& arm) {
  const std::string key = "servoarm/" + arm + "/state ";
  double m = 0;
  for (auto p = log.find(key); p != std::string::npos; p = log.find(key, p + 1)) {
    const auto q = log.find("\"q\":[", p);
    double v = 0;
    if (q != std::string::npos && std::sscanf(log.c_str() + q + 5, "%lf", &v) == 1) m = std::max(m, std::abs(v));
  }
  return m;
}

struct Cell {
  int port = free_port();
  std::string d = dir();
  pid_t broker = -1, arm1 = -1, arm2 = -1, sub = -1;
  std::string sub_log = d + "/sub.log";

  Cell() {
    (void)std::system(("mkdir -p " + d).c_str());
    std::ofstream(d + "/mosquitto.conf") << "listener " << port << " 127.0.0.1\nallow_anonymous true\npersistence false\n";
    broker = spawn(std::string(MOSQUITTO_PATH) + " -c " + d + "/mosquitto.conf", d + "/broker.log");
    CHECK_TEXT(until(30, [&] { return has(slurp(d + "/broker.log"), "running"); }), slurp(d + "/broker.log").c_str());
    sub = spawn("stdbuf -oL " + std::string(MOSQUITTO_SUB_PATH) + " -p " + std::to_string(port) + " -v -t 'servoarm/#'", sub_log);
    arm1 = start_arm("arm1");
    arm2 = start_arm("arm2");
  }
  ~Cell() {
    end(arm1);
    end(arm2);
    end(sub);
    end(broker);
    (void)std::system(("rm -rf " + d).c_str());
  }
  pid_t start_arm(const std::string& name) {
    const std::string cfg = d + "/" + name + ".toml";
    std::ofstream(cfg) << "[mqtt]\nenabled = true\nport = " << port << "\nname = \"" << name
                       << "\"\nstate_rate_hz = 20\nkeepalive_s = 5\n";
    return spawn(std::string(ARMFW_PATH) + " --sim --config " + cfg + " --no-stdin --priority 0", d + "/" + name + ".log");
  }
  void pub(const std::string& arm, const std::string& msg) {
    const std::string c = std::string(MOSQUITTO_PUB_PATH) + " -p " + std::to_string(port) + " -q 1 -t servoarm/" + arm +
                          "/cmd -m '" + msg + "'";
    CHECK_EQUAL(0, std::system(c.c_str()));
  }
  std::string log() const { return slurp(sub_log); }
};

}  // namespace

TEST_GROUP(FwMqtt){};

TEST(FwMqtt, ACellControllerCommandsTwoArmsThroughTheBroker) {
  Cell cell;
  // both arms online (retained status), publishing state
  CHECK_TEXT(until(60, [&] {
               const std::string l = cell.log();
               return has(l, "servoarm/arm1/status online") && has(l, "servoarm/arm2/status online") &&
                      has(l, "servoarm/arm1/state {") && has(l, "servoarm/arm2/state {");
             }),
             (cell.log() + slurp(cell.d + "/arm1.log")).c_str());
  // a bad command: one error on result, nothing moves
  cell.pub("arm1", "{\"id\":7,\"cmd\":\"movej\",\"q\":[99,0,0,0,0,0]}");
  CHECK_TEXT(until(30, [&] { return has(cell.log(), "servoarm/arm1/result {\"error\""); }), cell.log().c_str());
  cell.pub("arm1", "{\"id\":8,\"cmd\":\"frobnicate\"}");
  CHECK_TEXT(until(30, [&] { return !test::regex_search(cell.log(), "arm1/result [^\\n]*\"id\":8").empty(); }),
             cell.log().c_str());
  // the cell controller moves each arm somewhere of its own
  cell.pub("arm1", "{\"id\":1,\"cmd\":\"enable\"}");
  cell.pub("arm2", "{\"id\":1,\"cmd\":\"enable\"}");
  CHECK_TEXT(until(60, [&] {
               const std::string l = cell.log();
               return !test::regex_search(l, "arm1/result [^\\n]*\"id\":1[,}][^\\n]*\"ok\":true|arm1/result [^\\n]*\"ok\":true[^\\n]*\"id\":1[,}]").empty() &&
                      !test::regex_search(l, "arm2/result [^\\n]*\"id\":1[,}][^\\n]*\"ok\":true|arm2/result [^\\n]*\"ok\":true[^\\n]*\"id\":1[,}]").empty();
             }),
             cell.log().c_str());
  // enable is answered at once; the arm is idle a little later: retry the move until it is queued
  double q1 = 0, q2 = 0;
  CHECK_TEXT(until(60, [&] {
               cell.pub("arm1", "{\"id\":2,\"cmd\":\"movej\",\"q\":[0.3,0,0,0,0,0]}");
               cell.pub("arm2", "{\"id\":2,\"cmd\":\"movej\",\"q\":[-0.2,0,0,0,0,0]}");
               return until(5, [&] {
                 const std::string l = cell.log();
                 return last_q0(l, "arm1", q1) && last_q0(l, "arm2", q2) && std::abs(q1 - 0.3) < 1e-3 &&
                        std::abs(q2 + 0.2) < 1e-3;
               });
             }),
             (std::to_string(q1) + " " + std::to_string(q2) + "\n" + cell.log().substr(cell.log().size() > 4000 ? cell.log().size() - 4000 : 0)).c_str());
  // the bad movej did not move arm1 before (its state never showed 99) and events were published
  CHECK_TEXT(max_abs_q0(cell.log(), "arm1") < 1.0, cell.log().c_str());
  CHECK_TEXT(!test::regex_search(cell.log(), "servoarm/arm1/events \\{[^\\n]*\"seq\":[0-9]+").empty(), cell.log().c_str());
  // arm2 killed without a word: the broker publishes its last will
  end(cell.arm2, SIGKILL);
  cell.arm2 = -1;
  CHECK_TEXT(until(60, [&] { return has(cell.log(), "servoarm/arm2/status offline"); }), cell.log().c_str());
  CHECK(!has(cell.log(), "servoarm/arm1/status offline"));
}
