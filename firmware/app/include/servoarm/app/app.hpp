// SPDX-License-Identifier: Apache-2.0
#pragma once
// Assembly of one firmware instance from a FwConfig (set-up code): robot
// chain, CAN buses (SocketCAN, or for bus.can = "sim" the buses a SimFactory hands
// over: armfw --sim and the tests build virtual drives, host_sim's SimPlant), the
// drive groups from the drive-family factory (drive_factory.hpp) in one ArmServoBus,
// the IK model the control thread samples with, Controller, Console. App depends on no simulator: the robot-controller build of armfw can
// leave host_sim out. Shared by armfw_main.cpp and the in-process tests.
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "servoarm/app/drive_factory.hpp"
#include "servoarm/config/config.hpp"
#include "servoarm/console/console.hpp"
#include "servoarm/rt/controller.hpp"
#include "servoarm/rt/model_control.hpp"
#include "servoarm/hal/arm_servo_bus.hpp"
#include "servoarm/hal/clock.hpp"
#include "servoarm/hal/safety_input.hpp"
#include "servoarm/hal/socketcan_bus.hpp"
#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/ik.hpp"

namespace servoarm::fw {

struct App {
  /// Makes a CAN bus for bus.can = "sim": virtual drives with these node ids (one per joint of
  /// the bus, chain order) on an in-process bus driven by `clock`; called once per interface
  /// the configuration names (bus.can, drive.can). Returns the bus the drives' group talks on
  /// (owned by the caller), or nullptr.
  using SimFactory = std::function<hal::CanBus*(hal::Clock& clock, const std::vector<std::uint8_t>& nodes)>;
  /// Makes the bus of a group whose family is not CiA 402 for bus.can = "sim" (virtual MIT-mode
  /// motors: host_sim's MitPlant, one per interface, from the plan's joints and their [[drive]]
  /// tables in `cfg`); set before build(). Unset: such a group is refused at build() naming its
  /// family, since SimFactory's virtual drives are CiA 402.
  using SimGroupFactory = std::function<hal::CanBus*(hal::Clock& clock, const DriveGroupPlan& plan)>;
  SimGroupFactory sim_group;

  FwConfig cfg;
  kin::Chain chain;
  hal::MonotonicClock mono;
  hal::Clock* clock = &mono;
  std::vector<std::unique_ptr<hal::SocketCanBus>> socketcan;
  /// Each interface the configuration names and its bus (a socketcan one, or the SimFactory's).
  std::vector<std::pair<std::string, hal::CanBus*>> buses;
  /// The arm's drives: one group per (drive.family, interface), what the controller drives.
  std::unique_ptr<hal::ArmServoBus> servo;
  /// IK model of `chain` (closed form or numeric), used by the console's path checks
  /// and by the control thread's Cartesian sampling; lives as long as the App.
  std::unique_ptr<kin::IkModel> ik;
  bool ik_ready = false;
  /// [[output]] i is on joint output_joint[i]'s drive (its node), set by build().
  std::vector<int> output_joint;
  std::unique_ptr<Controller> ctl;
  std::unique_ptr<Console> console;
  /// The dynamic model in the control cycle ([dynamics] keys): made by build(), configured by
  /// boot() once the drives are up (their capabilities and rated torques are known then).
  std::unique_ptr<ModelControl> model;
  /// The [safety] inputs (safety.estop_input, safety.reduced_input; docs/safety.md#safety-inputs),
  /// made by build() and handed to the controller; a GPIO input's thread starts in boot().
  std::unique_ptr<hal::SafetyInput> estop_input, reduced_input;
  /// A simulated safety input ("sim:NAME") of this App, for tests and armfw --sim; nullptr when
  /// neither input is that one.
  hal::SimInput* sim_input(const std::string& name) const;

  /// Build everything (no threads started, drives not started). "" or the error.
  /// `clock` overrides the monotonic clock (tests pass a ManualClock); `sim` makes the
  /// bus when cfg.can is "sim" (without one, "sim" is refused).
  std::string build(const FwConfig& c, hal::Clock* clock_override = nullptr, const SimFactory& sim = {});
  /// Start the drives (blocking, bounded by bus.start_timeout_s). "" or the error. With
  /// virtual drives on a real clock, their thread must be running (SimPlant::start_thread).
  std::string boot();
  ControllerConfig controller_config() const;
  /// The [dynamics] and drive.collision_threshold keys in SI, with each joint's rated torque
  /// (joint side) as the master brought it up: after boot().
  ModelControlConfig model_config() const;
  /// What boot() found about the [dynamics] parts asked for: one line per part refused ("" when
  /// every part asked for runs); armfw prints it at start. The parts refused stay off.
  std::string dynamics_notes() const { return model && model->configured() ? model->start_notes() : ""; }
  /// Joint j's homing (drive.homing.*, deg / mm -> SI) as the drive groups take it.
  hal::HomingSpec homing_spec(int j) const;
  ConsoleConfig console_config() const;

 private:
  /// The bus of plan `p`'s interface: SocketCAN, or the SimFactory's for bus.can = "sim".
  std::string open_bus(const DriveGroupPlan& p, const SimFactory& sim, hal::CanBus*& bus);
  /// Check one safety input's source against the arm and this build (`key` names it in the
  /// error), and make it (after the servo bus exists): "" or the error.
  std::string check_safety_input(const char* key, const std::string& text, const std::vector<DriveGroupPlan>& plans) const;
  std::unique_ptr<hal::SafetyInput> make_safety_input(const std::string& text) const;
  static hal::SimInput* sim_input_of(hal::SafetyInput* in);
  /// The ArmService's SafetyStager: `changes` applied to the [safety] section of `cfg` through the
  /// key table (load_config_text, validate_for_chain, safety_envelope): "" or the refusal.
  std::string stage_safety_change(const std::string& changes, SafetyProposal& out) const;
};

}  // namespace servoarm::fw
