// SPDX-License-Identifier: Apache-2.0
#pragma once
// The controller test rig: fw::App (SimApp: the robot, its configuration, virtual drives on
// the in-process bus, Controller, ArmService and Console) on a ManualClock, stepped one
// control cycle at a time by the test. The virtual drives step whenever the clock advances;
// the service's waits run cycles. Helpers send moves, read telemetry and events, count the
// control thread's allocations and run console lines. A suite that runs its own Controller
// over the App's bus (a ServoBus spy, say) builds the rig without booting it and drives that
// controller with the same helpers (`drive`).
#include <cstddef>
#include <cstdint>
#include <functional>
#include <initializer_list>
#include <numbers>
#include <string>

#include "servoarm/service/arm_service.hpp"
#include "sim_app.hpp"

namespace servoarm::test {

inline constexpr double kDeg = std::numbers::pi / 180.0;

/// Joint angles in degrees as a JointVector in radians.
kin::JointVector deg(std::initializer_list<double> degrees);

/// The puma560's working pose clear of the wrist's singularity (0, -45, 180, 0, 45, 0 deg).
kin::JointVector puma_work_pose();

/// How the rig is built.
struct RigOptions {
  sim::MotorParams motor{};  ///< the virtual drives' motor model
  /// Runs after App::build and before the boot (drive input bits, a dynamic plant).
  std::function<void(SimApp&)> before_boot;
  bool boot = true;  ///< false: built only; the suite boots a controller of its own
};

class ControllerRig {
 public:
  hal::ManualClock clock;
  SimApp app;
  hal::Duration period = hal::kMillisecond;  ///< one control cycle
  bool count_allocs = false;                 ///< count the allocations of every cycle() ...
  std::size_t rt_allocs = 0;                 ///< ... into this
  /// Runs after every cycle() (the clock advanced): a trace, a per-cycle check.
  std::function<void()> after_cycle;
  fw::Session session;  ///< the console session of console()

  /// `cfg` with can = "sim"; a build or boot error fails the test with its line.
  explicit ControllerRig(fw::FwConfig cfg, const RigOptions& options = {});
  ControllerRig(fw::FwConfig cfg, std::function<void(SimApp&)> before_boot);
  ~ControllerRig();
  ControllerRig(const ControllerRig&) = delete;
  ControllerRig& operator=(const ControllerRig&) = delete;

  /// The controller cycle() steps and telemetry reads: the App's, or one of the suite's.
  void drive(fw::Controller& ctl) { ctl_ = &ctl; }
  fw::Controller& controller() const { return *ctl_; }

  fw::ArmService& svc() { return app.console->service(); }
  fw::Telemetry tel() const { return ctl_->telemetry(); }
  /// Commanded / measured joint positions (the chain's joints).
  kin::JointVector q_cmd() const;
  kin::JointVector q_act() const;
  /// The flange pose at `q` (forward kinematics of the App's chain; checks it solves).
  kin::Pose flange(const kin::JointVector& q) const;

  /// One control cycle at the clock's time, then the clock advances one period.
  void cycle();
  void cycles(int n);
  /// Cycles until the motion queue is empty and the arm idle (at most `max_cycles`).
  void until_idle(int max_cycles);
  /// Enable through the service and run until idle (at most 3000 cycles); checks both.
  void enable();
  fw::MoveResult movej(const kin::JointVector& goal, const fw::MoveContext& cx = fw::MoveContext{});
  /// A straight line of the tool to `target` at `speed` (m/s) through the service, with the
  /// console's IK.
  fw::MoveResult movel(const kin::Pose& target, double speed);
  /// A long joint move (joint 1 to 60 deg, joint 2 to -30 deg, the rest to 0) through the
  /// service, run until the arm moves (checked), then `more_cycles` cycles on.
  void start_move(int more_cycles = 0);
  /// A joint move put in the motion queue directly: the planner and the plan-time checks
  /// never see it (the run-time monitor's cases).
  void queue_unchecked_joint_move(std::uint32_t id, const kin::JointVector& goal, double override);
  /// A console line on `session`, run (cycle and poll) until the console is no longer busy
  /// (at most 60000 cycles); what it answered.
  std::string console(const std::string& line);
  /// Every event's text since the start, one a line; the last event's text ("" without one).
  std::string events();
  std::string last_event();

 private:
  kin::JointVector joints(bool commanded) const;
  fw::Controller* ctl_ = nullptr;
};

}  // namespace servoarm::test
