// SPDX-License-Identifier: Apache-2.0
#pragma once
// The MQTT bridge of armfw (docs/api.md#mqtt): a cell controller talks to arms through a broker.
// Topics under `servoarm/<name>/`:
//   state   (published, QoS 0) the API's state sample, at mqtt.state_rate_hz
//   events  (published, QoS 1) each event of the arm's event stream, with its sequence number
//   cmd     (subscribed, QoS 1) a request: the API's typed messages, parsed and run through the same
//           message table (protocol.hpp), so MQTT and the sockets speak one protocol
//   result  (published, QoS 1) the answer to each request (its `id`)
//   status  (published, QoS 1, retained) "online"; the broker's last will sets "offline"
// Library: libmosquitto (Debian libmosquitto-dev): its own network thread (mosquitto_loop_start),
// TLS and username / password as the broker takes them. The bridge's service calls run in pump()
// on the service thread, as the API server's do; the control thread is never touched.
#include <cstdint>
#include <memory>
#include <string>

#include "servoarm/api/protocol.hpp"

namespace servoarm::api {

class ApiServer;

struct MqttConfig {
  std::string host = "127.0.0.1";
  int port = 1883;
  std::string name = "arm";        ///< topics under servoarm/<name>/
  std::string username;            ///< "" none
  std::string password_file;       ///< the password (first line); "" none
  std::string cafile;              ///< TLS: the broker's CA (PEM); "" plain TCP
  std::string certfile, keyfile;   ///< TLS client certificate and key; "" none
  double state_rate_hz = 10;       ///< state samples per second (at most 100: pump()'s rounds)
  int keepalive_s = 10;            ///< the broker declares the arm offline after 1.5 x this without traffic
  double rate_hz = 1000;           ///< the control rate (the state's time base)
};

class MqttBridge {
 public:
  MqttBridge(const MqttConfig& cfg, fw::Controller& ctl, const kin::Chain& chain);
  ~MqttBridge();
  MqttBridge(const MqttBridge&) = delete;
  MqttBridge& operator=(const MqttBridge&) = delete;
  /// Connect (asynchronously: a broker not up yet is retried) and start the network thread.
  /// "" or the error (one line: bad TLS files, unreadable password file, ...).
  std::string start();
  void stop();
  /// Readable while commands wait for pump() (an eventfd).
  int wake_fd() const;
  /// Service thread: run the commands waiting (stop, hold, estop first), publish their results,
  /// the new events and, when due, a state sample. `api` (may be nullptr): a socket client that
  /// holds control makes the arm's moving commands from MQTT `controlled`.
  std::size_t pump(ServiceContext& cx, const ApiServer* api);
  bool connected() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace servoarm::api
