// SPDX-License-Identifier: Apache-2.0
#pragma once
// SimPlant: a set of virtual CiA 402 drives (ArmSim) on a fresh in-process bus,
// for `armfw --sim` and the in-process tests. The firmware's App only sees the
// CanBus it returns (master_bus()); armfw_main.cpp is the one firmware file that
// uses this header.
#include <atomic>
#include <cstdint>
#include <memory>
#include <thread>
#include <vector>

#include "servoarm/hal/clock.hpp"
#include "servoarm/hal/sim_bus.hpp"
#include "servoarm/sim/arm_plant.hpp"
#include "servoarm/sim/virtual_drive.hpp"

namespace servoarm::sim {

/// Virtual drives on an in-process bus, stepped by a thread on CLOCK_MONOTONIC
/// (what `--sim` runs: the drives behave like separate devices, with lag).
class SimPlant {
 public:
  /// Virtual drives with these node ids (one per joint) on a fresh in-process bus.
  SimPlant(hal::Clock& clock, const std::vector<std::uint8_t>& nodes, const MotorParams& motor = {});
  ~SimPlant();
  hal::CanBus& master_bus() { return *master_ep_; }
  /// Start the drive thread (real time). Tests with a ManualClock call step() instead.
  void start_thread();
  void stop_thread();
  /// Single-threaded use: drain frames and tick the drives at `now`. Each frame is handled at
  /// `now`, or, with set_frames_at_arrival(true), at the time it arrived (CanFrame::rx_time).
  void step(hal::TimePoint now);
  /// Frames handled at their arrival rather than at the step's time: a drive then samples at
  /// the SYNC, as on a bus, however late the next step comes (what `armfw --sim` runs: stepped
  /// before each control cycle, a SYNC would otherwise be sampled at the next cycle's start,
  /// and after a late cycle the feedback's sample would not be the SYNC's). Off by default (the
  /// in-process tests' timing: the drives act at the step after the SYNC).
  void set_frames_at_arrival(bool on) { at_arrival_ = on; }
  /// With frames at arrival: when a step comes more than `gap` after the last frame or step
  /// (the host did not run the loop: a loaded or instrumented build), the drives and the plant
  /// pause for the rest of that time, as if the loop and the arm had stopped together, and
  /// move on for `gap` only. A control loop that stalls on a real arm leaves the drives
  /// holding the last setpoint and the joints braking against it, which on a busy host would
  /// end the run in following-error faults that the firmware on its target never sees. 0
  /// (the default): never pause. `paused()`: the time skipped so far.
  void set_pause_after(hal::Duration gap) { pause_after_ = gap; }
  hal::Duration paused() const { return paused_; }
  /// RtLoop::PreCycle that steps the plant `ctx` (a SimPlant*): what `armfw --sim` runs
  /// on the control thread once the drives are up (the drive thread is stopped then).
  static void step_hook(void* ctx, std::int64_t now_ns) { static_cast<SimPlant*>(ctx)->step(now_ns); }
  /// Set-up, before start_thread(): run the drives on the dynamic arm plant (ArmPlant) of
  /// `chain`; `scaling[j]` is joint j's drive scaling as the master uses it (armfw:
  /// `hal::ArmServoBus::scaling(j)`, the drive group's). "" or the reason (a model without
  /// inertial data is refused, saying so). Without it: first-order motors.
  std::string use_dynamic_plant(const kin::Chain& chain, std::span<const hal::JointScaling> scaling,
                                const ArmPlantParams& params = {}) {
    return arm_->use_dynamic_plant(chain, scaling, params);
  }
  /// Set-up, before the bring-up: put every joint inside its limits in `chain`, at the
  /// in-limit value closest to 0 (a prismatic joint with limits [0.2, 0.9] m at 0.2 m), in
  /// drive counts through `scaling[j]` (the master's JointScaling). The drives otherwise start
  /// at count 0, which may lie outside a joint's limits: the arm could then never be enabled.
  void place_within_limits(const kin::Chain& chain, std::span<const hal::JointScaling> scaling) {
    arm_->place_within_limits(chain, scaling);
  }
  ArmSim& arm() { return *arm_; }
  hal::SimBus& bus() { return *bus_; }
  /// Fault injection from another thread: applied by the drive thread at its next step.
  void inject_silent(int joint);
  void inject_heartbeat_stop(int joint);
  void inject_emcy(int joint, std::uint16_t code);

 private:
  void apply_injections(hal::TimePoint now);
  hal::Clock& clock_;
  std::unique_ptr<hal::SimBus> bus_;
  std::unique_ptr<hal::SimBusEndpoint> master_ep_, sim_ep_;
  std::unique_ptr<ArmSim> arm_;
  std::thread th_;
  std::atomic<bool> stop_{false};
  bool at_arrival_ = false;
  hal::Duration pause_after_ = 0;
  hal::Duration paused_ = 0;
  hal::TimePoint last_step_ = 0;
  std::atomic<int> silent_{-1};
  std::atomic<int> hb_stop_{-1};
  std::atomic<int> emcy_joint_{-1};
  std::atomic<std::uint16_t> emcy_code_{0};
};

}  // namespace servoarm::sim
