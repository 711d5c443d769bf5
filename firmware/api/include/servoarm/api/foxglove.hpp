// SPDX-License-Identifier: Apache-2.0
#pragma once
// The Foxglove WebSocket server of armfw (docs/foxglove-mcap.md): live data for Foxglove or
// Lichtblick over the `foxglove.websocket.v1` protocol, on a port of its own (loopback unless
// foxglove.bind says otherwise). Read-only: it takes no commands.
// Channels (JSON messages, JSON schemas advertised with them):
//   /arm/state   servoarm.State          the API's state sample (protocol.hpp state_line: joints,
//                                        speeds, torques, setpoints, the tool pose, faults)
//   /tf          foxglove.FrameTransforms every link's frame (base -> link1 -> ... -> tool), so
//                                        the 3D panel shows the arm without configuration
//   /tool_pose   foxglove.PoseInFrame    the tool pose in the base frame
//   /events      foxglove.Log            each event of the service's stream (faults as errors)
// The state comes from the controller's telemetry seqlock, as the API's state stream reads it.
//
// Threads: a publisher thread reads the telemetry at foxglove.state_rate_hz / tf_rate_hz and
// builds the messages of subscribed channels only; the network thread (libwebsockets, its own
// context) hands each to its subscribers' bounded outboxes. A client that does not read loses
// its own messages (counted), never delays another or the control thread. Events reach the
// server from the service thread through pump().
#include <cstdint>
#include <memory>
#include <string>

#include "servoarm/api/protocol.hpp"

namespace servoarm::api {

struct FoxgloveConfig {
  std::string bind = "127.0.0.1";
  int port = 8767;                     ///< 0: any free port (port() tells)
  double state_rate_hz = 50;           ///< /arm/state and /tool_pose
  double tf_rate_hz = 30;              ///< /tf
  double rate_hz = 1000;               ///< the control rate (the state's time base)
  std::size_t client_buffer = 1024 * 1024;  ///< bytes of unsent messages per client before its messages drop
  std::string name = "servoarm";
};

struct FoxgloveStats {
  int clients = 0;
  std::uint64_t sent = 0, dropped = 0;
};

class FoxgloveServer {
 public:
  FoxgloveServer(const FoxgloveConfig& cfg, fw::Controller& ctl, const kin::Chain& chain);
  ~FoxgloveServer();
  FoxgloveServer(const FoxgloveServer&) = delete;
  FoxgloveServer& operator=(const FoxgloveServer&) = delete;
  /// Listen and start the threads. "" or the error (one line).
  std::string start();
  void stop();
  int port() const;
  /// Service thread: pass the service's new events on as log messages.
  void pump(ServiceContext& cx);
  FoxgloveStats stats() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace servoarm::api
