#pragma once
// Assembly of one firmware instance from a FwConfig (set-up code): robot
// chain, CAN bus (SocketCAN, or the in-process SimBus with virtual CiA 402
// drives stepped on their own thread), CANopen master, Controller, Console.
// Shared by armfw_main.cpp and the in-process tests.
#include <atomic>
#include <memory>
#include <string>
#include <thread>

#include "servoarm/config/config.hpp"
#include "servoarm/console/console.hpp"
#include "servoarm/rt/controller.hpp"
#include "servoarm/hal/canopen_master.hpp"
#include "servoarm/hal/clock.hpp"
#include "servoarm/hal/sim_bus.hpp"
#include "servoarm/hal/socketcan_bus.hpp"
#include "servoarm/kinematics/chain.hpp"
#include "servoarm/sim/virtual_drive.hpp"

namespace servoarm::fw {

/// Virtual drives on an in-process bus, stepped by a thread on CLOCK_MONOTONIC
/// (what `--sim` runs: the drives behave like separate devices, with lag).
class SimPlant {
 public:
  /// Virtual drives with these node ids (one per joint) on a fresh in-process bus.
  SimPlant(hal::Clock& clock, const std::vector<std::uint8_t>& nodes, const sim::MotorParams& motor = {});
  ~SimPlant();
  hal::CanBus& master_bus() { return *master_ep_; }
  /// Start the drive thread (real time). Tests with a ManualClock call step() instead.
  void start_thread();
  void stop_thread();
  /// Single-threaded use: drain frames and tick the drives at `now`.
  void step(hal::TimePoint now);
  /// RtLoop::PreCycle that steps the plant `ctx` (a SimPlant*): what `armfw --sim` runs
  /// on the control thread once the drives are up (the drive thread is stopped then).
  static void step_hook(void* ctx, std::int64_t now_ns) { static_cast<SimPlant*>(ctx)->step(now_ns); }
  sim::ArmSim& arm() { return *arm_; }
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
  std::unique_ptr<sim::ArmSim> arm_;
  std::thread th_;
  std::atomic<bool> stop_{false};
  std::atomic<int> silent_{-1};
  std::atomic<int> hb_stop_{-1};
  std::atomic<int> emcy_joint_{-1};
  std::atomic<std::uint16_t> emcy_code_{0};
};

struct App {
  FwConfig cfg;
  sim::MotorParams sim_motor{};  ///< virtual drive motor model (set before build(); tests)
  kin::Chain chain;
  hal::MonotonicClock mono;
  hal::Clock* clock = &mono;
  std::unique_ptr<SimPlant> plant;
  std::unique_ptr<hal::SocketCanBus> socketcan;
  std::unique_ptr<hal::CanopenServoBus> servo;
  std::unique_ptr<Controller> ctl;
  std::unique_ptr<Console> console;

  /// Build everything (no threads started, drives not started). "" or the error.
  /// `clock` overrides the monotonic clock (tests pass a ManualClock).
  std::string build(const FwConfig& c, hal::Clock* clock_override = nullptr);
  /// Start the drives (blocking, bounded by bus.start_timeout_s). "" or the error.
  /// With a real clock and the sim bus, starts the drive thread first.
  std::string boot();
  ControllerConfig controller_config() const;
  ConsoleConfig console_config() const;
};

}  // namespace servoarm::fw
