// SPDX-License-Identifier: Apache-2.0
#pragma once
// Virtual MIT-mode actuators (docs/servo-bus.md#virtual-mit-motors): Damiao, CubeMars or
// Robstride motors that behave like the drives, not an echo of the commands. Each runs the MIT
// law in the drive, tau = kp (p_des - q) + kd (v_des - qd) + tau_ff saturated at T_MAX, on the
// quantised values of the last frame it took, and moves a rigid inertia with viscous damping,
// an optional constant load torque (a gravity stand-in) and end stops. It answers every command
// and special frame with a feedback frame on its master id (quantised, position wrapped into
// +-P_MAX), keeps the Damiao registers (0x7FF read / write / save), disables itself with error
// 0xD when nothing arrived for its CAN timeout (TIMEOUT x 50 us), and faults on its own
// over-temperature (OT_Value). Quirks users meet: in a control mode other than MIT it answers no
// MIT frame; a CTRL_MODE it will not change; silent (another bitrate or frame format); answers
// late; set to CAN FD on a classic bus (or the other way round): nothing seen, no answer.
// Damiao's position-velocity (CTRL_MODE 2: [p, v] on 0x100 + id, to p at most at v) and velocity
// (3: v on 0x200 + id) modes run the drive's own position and velocity loops (time constants
// 50 ms and 1 ms, T_MAX) and answer each such frame with a feedback frame, in that mode only.
// MitPlant puts motors on a fresh in-process bus, stepped by a thread or by the caller.
#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <thread>
#include <vector>

#include "servoarm/hal/can_bus.hpp"
#include "servoarm/hal/clock.hpp"
#include "servoarm/hal/mit.hpp"
#include "servoarm/hal/sim_bus.hpp"

namespace servoarm::sim {

struct MitMotorParams {
  double inertia = 0.01;      ///< kg m^2 at the output (rotor reflected + link)
  double damping = 0.05;      ///< N m s / rad, viscous
  double ambient = 30;        ///< deg C
  double heating = 0;         ///< deg C / s per (N m)^2 of output torque (0: no self-heating)
  double cooling_tau = 120;   ///< s
};

struct MitQuirks {
  bool silent = false;        ///< answers nothing (another bitrate, classic vs FD)
  bool mode_locked = false;   ///< a CTRL_MODE write is answered but not taken
  hal::Duration late = 0;     ///< every answer goes out this long after the request
};

struct MitMotorSpec {
  const hal::mit::MotorProfile* profile = nullptr;
  std::uint16_t id = 1;
  std::uint16_t master = 0x11;  ///< the id it answers on
  std::uint32_t ctrl_mode = 1;  ///< Damiao CTRL_MODE at power-up
  bool fd = false;              ///< set to CAN FD: takes (and sends) FD frames only, classic ones are not seen
  MitMotorParams params{};
};

class VirtualMitMotor {
 public:
  explicit VirtualMitMotor(const MitMotorSpec& spec);

  /// One frame from the bus at `now` (the dynamics are first brought up to `now`).
  void handle(const hal::CanFrame& f, hal::TimePoint now, hal::CanBus& out);
  /// Moves the motor on to `now`, runs the watchdog, sends answers that are due.
  void tick(hal::TimePoint now, hal::CanBus& out);

  double position() const { return q_; }        ///< rad, output, multi-turn (the truth)
  double velocity() const { return qd_; }
  double torque() const { return tau_; }        ///< the law's output, saturated
  bool enabled() const { return enabled_; }
  std::uint8_t error() const { return error_; }  ///< latched error nibble (0 = none)
  double temperature() const { return temp_; }
  const hal::mit::Command& command() const { return cmd_; }  ///< the last MIT command taken
  std::uint64_t mit_frames() const { return mit_frames_; }

  void set_position(double q) { q_ = q; }
  std::uint32_t reg(hal::mit::Reg r) const { return regs_[static_cast<std::size_t>(r)]; }
  float reg_f(hal::mit::Reg r) const;
  void set_reg(hal::mit::Reg r, std::uint32_t v) { regs_[static_cast<std::size_t>(r)] = v; }
  void set_reg_f(hal::mit::Reg r, float v);

  MitQuirks& quirks() { return quirks_; }
  MitMotorParams& params() { return p_; }
  /// Latches an error nibble (over-voltage 8, under-voltage 9, ...): the motor disables itself.
  void inject_error(std::uint8_t code);
  /// Sets the winding temperature (deg C) now.
  void set_temperature(double t) { temp_ = t; }
  double load_torque = 0;            ///< N m, constant, added to the law's (gravity stand-in)
  double stop_lo = -1e300, stop_hi = 1e300;  ///< end stops (rad, output)

 private:
  void integrate_to(hal::TimePoint now);
  void answer(const hal::CanFrame& f, hal::TimePoint now, hal::CanBus& out);
  void send_feedback(hal::TimePoint now, hal::CanBus& out);
  hal::mit::Ranges ranges() const;
  double wrapped() const;

  const hal::mit::MotorProfile* profile_;
  hal::mit::Vendor vendor_;
  bool fd_ = false;
  MitMotorParams p_;
  MitQuirks quirks_{};
  std::array<std::uint32_t, hal::mit::kLastReg + 1> regs_{};
  bool enabled_ = false;
  std::uint8_t error_ = 0;
  static constexpr std::uint32_t kModePosVel = 2, kModeVel = 3;
  static constexpr double kPosGain = 20;     ///< 1/s, position loop of mode 2
  static constexpr double kVelTime = 1e-3;   ///< s, velocity loop of modes 2 and 3
  hal::mit::Command cmd_{};
  double pv_p_ = 0, pv_v_ = 0, vel_v_ = 0;  ///< the last position-velocity / velocity frame taken
  double q_ = 0, qd_ = 0, tau_ = 0, temp_ = 0;
  hal::TimePoint t_ = 0, last_rx_ = 0;
  std::uint64_t mit_frames_ = 0;
  struct Pending {
    hal::CanFrame f;
    hal::TimePoint due;
  };
  std::array<Pending, 32> late_{};
  std::size_t late_n_ = 0;
};

/// Virtual MIT motors on a fresh in-process bus (what SimPlant is for CiA 402 drives).
class MitPlant {
 public:
  MitPlant(hal::Clock& clock, const std::vector<MitMotorSpec>& motors);
  ~MitPlant();
  hal::CanBus& master_bus() { return *master_ep_; }
  hal::SimBus& bus() { return *bus_; }
  std::size_t size() const { return motors_.size(); }
  VirtualMitMotor& at(std::size_t i) { return *motors_[i]; }
  /// Single-threaded use: every frame received so far at its arrival time, then tick to `now`.
  void step(hal::TimePoint now);
  void start_thread();
  void stop_thread();
  /// RtLoop::PreCycle that steps the plant `ctx` (a MitPlant*) before each control cycle, as
  /// SimPlant::step_hook does for the CiA 402 drives.
  static void step_hook(void* ctx, std::int64_t now_ns) { static_cast<MitPlant*>(ctx)->step(now_ns); }

 private:
  hal::Clock& clock_;
  std::unique_ptr<hal::SimBus> bus_;
  std::unique_ptr<hal::SimBusEndpoint> master_ep_, sim_ep_;
  std::vector<std::unique_ptr<VirtualMitMotor>> motors_;
  std::thread th_;
  std::atomic<bool> stop_{false};
};

}  // namespace servoarm::sim
