// SPDX-License-Identifier: Apache-2.0
#pragma once
// The arm service's MCAP recording (`record mcap`, docs/foxglove-mcap.md): the control
// thread's telemetry at a chosen rate up to the control rate, the setpoints, the service's
// events and the robot description, as JSON messages with JSON schemas in MCAP files
// (mcap_writer.hpp) in a configured folder. A new file begins when one reaches its size limit;
// at the file limit the recording ends. Files are never overwritten (O_EXCL; a taken name
// gets the next number).
//
// Threads: the control thread copies every cycle due (cycle % decimation == 0) into its sample
// ring (Controller::start_samples; a fixed ring allocated before the recording starts, never
// waited on); a recorder thread of its own (non-real-time) empties it every 10 ms and writes
// the cycles. A cycle due while the ring was full (the recorder kept off the CPU for longer
// than the ring holds) is counted as missed, never silently: the count is in every state
// message after it (`missed`) and in the result of `record mcap stop`. Events are handed over
// by the service thread (event()) through a mutex-guarded list.
#include <atomic>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "servoarm/kinematics/chain.hpp"
#include "servoarm/rt/controller.hpp"
#include "servoarm/service/arm_service.hpp"
#include "servoarm/service/mcap_writer.hpp"

namespace servoarm::fw {

class McapRecorder {
 public:
  McapRecorder(Controller& ctl, const kin::Chain& chain) : ctl_(ctl), chain_(chain) {}
  ~McapRecorder() { stop(); }
  McapRecorder(const McapRecorder&) = delete;
  McapRecorder& operator=(const McapRecorder&) = delete;

  /// Begin recording at `rate_hz` (the control rate divided by a whole number: the nearest
  /// such rate at or below it). `threaded` false: nothing polls; the caller calls poll()
  /// (tests driving the controller by hand). "" or the error (one line).
  std::string start(const McapSettings& s, double rate_hz, bool threaded = true);
  /// End the recording, close the file (summary and footer written). Its status.
  McapStatus stop();
  McapStatus status() const;
  bool active() const { return active_.load(); }
  /// The recording runs on its own thread (poll() is that thread's).
  bool threaded() const { return threaded_; }
  /// Service thread: an event of the service's stream and its detail line.
  void event(const ArmEvent& e, std::string_view detail);
  /// One look at the telemetry: writes the cycle when due, and the events waiting.
  void poll();

 private:
  std::string open_next();
  void write_state(const CycleSample& t);
  void end(std::string why);
  std::uint64_t t_ns(std::uint64_t cycle) const;
  Controller& ctl_;
  const kin::Chain& chain_;
  McapSettings cfg_;
  McapWriter w_;
  std::uint16_t ch_state_ = 0, ch_setpoint_ = 0, ch_event_ = 0, ch_robot_ = 0;
  std::atomic<bool> active_{false};
  std::atomic<bool> quit_{false};
  std::thread thread_;
  bool threaded_ = false;  ///< set by start() before the thread begins
  mutable std::mutex mu_;  ///< status_, events_
  McapStatus status_;
  std::vector<std::pair<std::uint64_t, std::string>> events_;
  std::uint64_t every_ = 1;      ///< decimation
  std::uint64_t next_ = 0;       ///< next cycle due (the recorder's thread, or the caller of poll())
  std::uint64_t dropped_at_start_ = 0;  ///< Controller::samples_dropped() when the recording began
  std::uint64_t start_cycle_ = 0;
  std::int64_t epoch_ns_ = 0;    ///< wall clock (ns) of cycle start_cycle_
  double period_ns_ = 1e6;
  std::int64_t last_flush_ns_ = 0;
  std::uint64_t bytes_before_ = 0;  ///< of the files closed
  std::string json_;
};

}  // namespace servoarm::fw
