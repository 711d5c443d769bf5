// SPDX-License-Identifier: Apache-2.0
#pragma once
// fw::App with virtual drives for the in-process tests and benchmarks: host_sim's
// SimPlant made through App's SimFactory, started before boot() on a real clock
// (what armfw_main.cpp does for --sim). App itself depends on no simulator.
#include <memory>
#include <string>
#include <vector>

#include "servoarm/app/app.hpp"
#include "servoarm/sim/sim_plant.hpp"

namespace servoarm::test {

struct SimApp : fw::App {
  sim::MotorParams sim_motor{};         ///< virtual drive motor model (set before build())
  std::unique_ptr<sim::SimPlant> plant;  ///< the virtual drives (after build())

  std::string build(const fw::FwConfig& c, hal::Clock* clock_override = nullptr) {
    return fw::App::build(c, clock_override, [this](hal::Clock& clk, const std::vector<std::uint8_t>& nodes) -> hal::CanBus* {
      plant = std::make_unique<sim::SimPlant>(clk, nodes, sim_motor);
      return &plant->master_bus();
    });
  }
  /// With a real clock the drives answer the bring-up from their own thread.
  std::string boot() {
    if (plant && !clock->simulated()) plant->start_thread();
    return fw::App::boot();
  }
  ~SimApp() {
    if (plant) plant->stop_thread();
    console.reset();  // everything that talks on the plant's bus goes first
    ctl.reset();
    servo.reset();
  }
};

}  // namespace servoarm::test
