// SPDX-License-Identifier: Apache-2.0
#pragma once
// Master + virtual drives on one in-process SimBus, single-threaded: the
// ManualClock's idle hook steps the drives whenever time moves (the master's
// blocking SDO waits included), so every run is deterministic.
#include <memory>
#include <vector>

#include "servoarm/hal/canopen_master.hpp"
#include "servoarm/hal/sim_bus.hpp"
#include "servoarm/sim/virtual_drive.hpp"

namespace servoarm::test {

struct SimRig {
  hal::ManualClock clock;
  hal::SimBus bus{clock, 50 * hal::kMicrosecond};
  std::unique_ptr<hal::SimBusEndpoint> master_ep = bus.open(4096);
  std::unique_ptr<hal::SimBusEndpoint> sim_ep = bus.open(4096);
  std::unique_ptr<hal::SimBusEndpoint> spy_ep = bus.open(65536);  // sees every frame (like candump)
  std::unique_ptr<sim::ArmSim> sim;

  explicit SimRig(std::vector<std::uint8_t> nodes, const sim::MotorParams& motor = {}) {
    sim = std::make_unique<sim::ArmSim>(*sim_ep, nodes, motor, 7);
    sim->power_on(clock.now());
    clock.set_idle_hook([this](hal::TimePoint t) { sim->step(t); });
  }
  ~SimRig() { clock.set_idle_hook(nullptr); }

  /// Frames the spy captured since the last call.
  std::vector<hal::CanFrame> capture() {
    std::vector<hal::CanFrame> v;
    hal::CanFrame f;
    while (spy_ep->receive(f, 0) == hal::Status::ok) v.push_back(f);
    return v;
  }
};

}  // namespace servoarm::test
