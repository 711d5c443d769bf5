// SPDX-License-Identifier: Apache-2.0
#pragma once
// fw::App with virtual drives for the in-process tests and benchmarks: host_sim's
// SimPlant made through App's SimFactory, started before boot() on a real clock
// (what armfw_main.cpp does for --sim). App itself depends on no simulator.
#include <memory>
#include <string>
#include <vector>

#include "servoarm/app/app.hpp"
#include "servoarm/hal/canopen_master.hpp"
#include "servoarm/sim/sim_plant.hpp"

namespace servoarm::test {

struct SimApp : fw::App {
  sim::MotorParams sim_motor{};         ///< virtual drive motor model (set before build())
  std::unique_ptr<sim::SimPlant> plant;  ///< the virtual drives of the first bus (after build())
  /// The virtual drives of each further interface (drive.can), in the order App made them.
  std::vector<std::unique_ptr<sim::SimPlant>> more_plants;

  std::string build(const fw::FwConfig& c, hal::Clock* clock_override = nullptr) {
    return fw::App::build(c, clock_override, [this](hal::Clock& clk, const std::vector<std::uint8_t>& nodes) -> hal::CanBus* {
      auto p = std::make_unique<sim::SimPlant>(clk, nodes, sim_motor);
      hal::CanBus* bus = &p->master_bus();
      if (!plant) plant = std::move(p);
      else more_plants.push_back(std::move(p));
      return bus;
    });
  }
  /// With a real clock the drives answer the bring-up from their own thread.
  std::string boot() {
    if (!clock->simulated()) {
      if (plant) plant->start_thread();
      for (auto& p : more_plants) p->start_thread();
    }
    return fw::App::boot();
  }
  /// Steps every bus's virtual drives (a ManualClock's idle hook).
  void step_plants(hal::TimePoint t) {
    if (plant) plant->step(t);
    for (auto& p : more_plants) p->step(t);
  }
  /// Group g's CANopen master (the tests look at what it sends).
  hal::CanopenServoBus& canopen(std::size_t g = 0) { return static_cast<hal::CanopenServoBus&>(servo->group(g)); }
  ~SimApp() {
    if (plant) plant->stop_thread();
    for (auto& p : more_plants) p->stop_thread();
    console.reset();  // everything that talks on the plant's bus goes first
    ctl.reset();
    servo.reset();
  }
};

}  // namespace servoarm::test
