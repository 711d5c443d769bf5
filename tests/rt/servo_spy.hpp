// SPDX-License-Identifier: Apache-2.0
#pragma once
// ServoSpy: a hal::ServoBus that forwards to a real one (the CANopen master on the
// in-process bus) and records what the controller asked for, cycle by cycle: every
// setpoint vector written and every power command (enable / disable / quick stop /
// set zero), each with the cycle it happened in. A cycle starts at read(), which the
// controller calls once per cycle first. Tests read the record instead of decoding
// CAN frames; the power commands map one to one onto the CiA 402 controlwords the
// master sends (enable -> 0x000F after the walk, disable -> 0x0006/0x0007, quick stop
// -> 0x0002).
//
// Optional fault injection: fail_next_write(status) makes the next write() return
// `status` (after forwarding it), as a bus error would.
#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "servoarm/hal/servo_bus.hpp"

namespace servoarm::test {

class ServoSpy final : public hal::ServoBus {
 public:
  enum class Call : std::uint8_t { enable, disable, quick_stop, set_zero, start_homing, abort_homing };
  static const char* to_string(Call c) {
    switch (c) {
      case Call::enable: return "enable";
      case Call::disable: return "disable";
      case Call::quick_stop: return "quick_stop";
      case Call::set_zero: return "set_zero";
      case Call::start_homing: return "start_homing";
      case Call::abort_homing: return "abort_homing";
    }
    return "?";
  }
  struct CallRecord {
    std::uint64_t cycle = 0;
    Call call = Call::enable;
  };
  struct WriteRecord {
    std::uint64_t cycle = 0;
    std::size_t n = 0;
    std::array<double, hal::kMaxServoJoints> setpoint{};
    hal::Status result = hal::Status::ok;
  };

  /// Records kept, reserved up front so that the controller's cycle never allocates; later
  /// ones are not recorded (a test reading them finds none). The longest mode-table case
  /// writes 1 750 setpoint vectors. A larger reservation is a fresh multi-megabyte mapping
  /// per rig under ASan (poisoned, faulted in, unpoisoned at the end): with 1 << 16 records
  /// that was half of fw_mode_table's CPU time there.
  static constexpr std::size_t kMaxWrites = 1 << 13;
  static constexpr std::size_t kMaxCalls = 4096;
  explicit ServoSpy(hal::ServoBus& inner) : inner_(inner) {
    calls.reserve(kMaxCalls);
    writes.reserve(kMaxWrites);
  }

  std::size_t joint_count() const override { return inner_.joint_count(); }
  hal::Status start(hal::TimePoint deadline) override { return inner_.start(deadline); }
  void enable() override {
    record(Call::enable);
    inner_.enable();
  }
  void disable() override {
    record(Call::disable);
    inner_.disable();
  }
  void quick_stop() override {
    record(Call::quick_stop);
    inner_.quick_stop();
  }
  hal::Status read(hal::TimePoint now) override {
    ++cycle;
    return inner_.read(now);
  }
  hal::Status write(std::span<const double> setpoints, hal::TimePoint now) override {
    hal::Status st = inner_.write(setpoints, now);
    if (fail_next_ != hal::Status::ok) {
      st = fail_next_;
      fail_next_ = hal::Status::ok;
    }
    if (writes.size() < writes.capacity()) {
      WriteRecord w;
      w.cycle = cycle;
      w.n = setpoints.size();
      for (std::size_t j = 0; j < setpoints.size() && j < w.setpoint.size(); ++j) w.setpoint[j] = setpoints[j];
      w.result = st;
      writes.push_back(w);
    }
    return st;
  }
  hal::Status set_position_zero(std::size_t j) override {
    record(Call::set_zero);
    return inner_.set_position_zero(j);
  }
  std::int64_t zero_offset(std::size_t j) const override { return inner_.zero_offset(j); }
  hal::Status start_homing(std::size_t j, hal::TimePoint now) override {
    record(Call::start_homing);
    return inner_.start_homing(j, now);
  }
  void abort_homing(std::size_t j) override {
    if (inner_.homing(j).phase == hal::HomingPhase::running) record(Call::abort_homing);
    inner_.abort_homing(j);
  }
  hal::HomingProgress homing(std::size_t j) const override { return inner_.homing(j); }
  void describe_homing(std::size_t j, char* buf, std::size_t size) const override { inner_.describe_homing(j, buf, size); }
  hal::HomingKind homing_kind(std::size_t j) const override { return inner_.homing_kind(j); }
  const hal::JointFeedback& feedback(std::size_t j) const override { return inner_.feedback(j); }
  const char* last_error() const override { return inner_.last_error(); }
  // Feed-forward and torque mode: passed through.
  hal::JointCapabilities capabilities(std::size_t j) const override { return inner_.capabilities(j); }
  hal::Status set_feed_forward(std::size_t j, double v, double t) override { return inner_.set_feed_forward(j, v, t); }
  hal::Status set_target_torque(std::size_t j, double t) override { return inner_.set_target_torque(j, t); }
  hal::Status set_torque_mode(std::size_t j, bool on) override { return inner_.set_torque_mode(j, on); }
  hal::CyclicModeState cyclic_mode(std::size_t j) const override { return inner_.cyclic_mode(j); }

  /// The next write() reports `st` (the frames still go out).
  void fail_next_write(hal::Status st) { fail_next_ = st; }

  /// Power commands of cycle `c`, in order.
  std::vector<Call> calls_in(std::uint64_t c) const {
    std::vector<Call> out;
    for (const CallRecord& r : calls)
      if (r.cycle == c) out.push_back(r.call);
    return out;
  }
  /// Writes of cycle `c`.
  std::vector<WriteRecord> writes_in(std::uint64_t c) const {
    std::vector<WriteRecord> out;
    for (const WriteRecord& w : writes)
      if (w.cycle == c) out.push_back(w);
    return out;
  }

  std::uint64_t cycle = 0;  ///< reads seen (= controller cycles, + the one in boot())
  std::vector<CallRecord> calls;
  std::vector<WriteRecord> writes;

 private:
  void record(Call c) {
    if (calls.size() < calls.capacity()) calls.push_back(CallRecord{cycle, c});
  }
  hal::ServoBus& inner_;
  hal::Status fail_next_ = hal::Status::ok;
};

}  // namespace servoarm::test
