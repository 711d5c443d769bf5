// SPDX-License-Identifier: Apache-2.0
#pragma once
// The MIT-mode drive family (docs/servo-bus.md#mit-mode-actuators): Damiao, CubeMars AK and
// Robstride actuators that take the MIT frame (mit.hpp) on one CanBus, as one DriveGroup.
//
// Bring-up (start(), blocking, bounded by its deadline), per motor in joint order:
//   Damiao:  CTRL_MODE read through 0x7FF (the reply's id is the motor's master id: one other than
//            configured, or another joint's, is refused as a master id clash); PMAX/VMAX/TMAX read
//            (the frame is packed with what the motor reads; a value other than the profile's is
//            noted in notes()); OT_Value read (the over-temperature cut-off the warning and the
//            fault sit below); CTRL_MODE written to 1 (MIT) when it is not, and read back;
//            TIMEOUT written (MitGroupConfig::motor_timeout, 50 us units) and read back, so the
//            motor disables itself when the firmware stops talking.
//   every vendor: a disable frame, answered by a feedback frame (the start position).
// A motor that does not answer, or answers other than it must, is refused with one line naming
// the joint, the motor id, what was found and the likely cause.
//
// Each cycle (write()), one frame per motor: enabled joints the MIT command (position from the
// setpoint through the joint mapping, kp/kd as configured, velocity and torque feed-forward from
// set_feed_forward(); in torque mode kp = 0, the configured kd and the target torque: free-drive,
// damped in the motor), joints
// being enabled the enable frame (a latched fault is cleared first), the others the disable frame
// (which the motor answers with feedback, so a disabled joint's position stays fresh). read()
// takes the feedback: position (multi-turn, from the +-P_MAX wrapped value), velocity, measured
// torque, temperatures, error nibble. No feedback within feedback_timeout: heartbeat_lost.
// A temperature at temp_warning sets a warning (warning()); at temp_fault the joint faults and is
// disabled, before the motor's own cut-off.
// Joint mapping: actuator position (rad, multi-turn) = zero + direction x q x k, with k the
// actuator radians per joint unit (JointScaling: counts are actuator microradians).
// Real time: read()/write()/the per-joint calls allocate nothing, lock nothing, never block.
#include <array>
#include <cstdint>

#include "servoarm/hal/can_bus.hpp"
#include "servoarm/hal/clock.hpp"
#include "servoarm/hal/drive_group.hpp"
#include "servoarm/hal/mit.hpp"

namespace servoarm::hal {

struct MitJointConfig {
  std::uint16_t motor_id = 1;   ///< the id the motor takes commands on (Damiao ESC_ID)
  /// The id it answers on (Damiao MST_ID); kDefaultMaster = the vendor's default (Damiao
  /// motor_id + 0x10, CubeMars 0x000, Robstride 0x0FD).
  std::uint16_t master_id = 0xFFFF;
  static constexpr std::uint16_t kDefaultMaster = 0xFFFF;
  const mit::MotorProfile* profile = nullptr;
  double kp = 30;   ///< N m / rad, actuator side, in position mode
  double kd = 1;    ///< N m s / rad
  /// counts = actuator microradians: counts_per_unit = 2 pi 1e6 per actuator turn (revolute);
  /// gear_ratio = actuator turns per joint turn (a transmission after the actuator), direction,
  /// zero_offset = actuator microradians at joint zero.
  JointScaling scaling{JointScaling::Kind::revolute, 2.0 * 3.14159265358979323846 * 1e6, 1.0, 1, 0};
  HomingSpec homing{};
  double temp_warning = 0;  ///< deg C; 0 = 15 below the motor's cut-off
  double temp_fault = 0;    ///< deg C; 0 = 5 below the motor's cut-off
  /// N m s / rad, joint side: the damping the hold after quick_stop() brakes the joint with in
  /// the cycles without a torque feed-forward (the rest beyond KD_MAX through tau_ff from the
  /// measured velocity, at most T_MAX): KD_MAX alone takes a heavy joint seconds to stop. 0: KD_MAX.
  double stop_damping = 0;
};

struct MitGroupConfig {
  mit::Vendor vendor = mit::Vendor::damiao;
  std::array<MitJointConfig, kMaxServoJoints> joints{};
  std::size_t joint_count = 0;
  Duration reply_timeout = 20 * kMillisecond;     ///< one register / feedback answer at bring-up
  int attempts = 3;                                ///< tries per answer at bring-up
  Duration feedback_timeout = 50 * kMillisecond;   ///< no feedback this long: heartbeat_lost
  Duration motor_timeout = 100 * kMillisecond;     ///< the motor's own CAN timeout (Damiao TIMEOUT)
  Duration state_timeout = 500 * kMillisecond;     ///< enable frame not taken this long: drive_refused
  bool set_mode = true;                            ///< write CTRL_MODE = MIT when the motor is in another
  /// Send every frame as CAN FD with bit-rate switch (Damiao motors set to CAN FD answer only
  /// those); the interface must be opened for FD (SocketCanOptions::enable_fd).
  bool fd = false;
};

class MitGroup final : public DriveGroup {
 public:
  MitGroup(CanBus& bus, Clock& clock, const MitGroupConfig& cfg);

  const char* family() const override { return mit::to_string(cfg_.vendor); }
  Status config_status() const override { return config_status_; }
  JointScaling scaling(std::size_t j) const override { return cfg_.joints[j < cfg_.joint_count ? j : 0].scaling; }
  double rated_torque(std::size_t j) const override;
  void joint_name(std::size_t j, char* buf, std::size_t size) const override;

  std::size_t joint_count() const override { return cfg_.joint_count; }
  void enable() override;
  void disable() override;
  /// Every powered joint stops and holds where it comes to rest: the MIT frame with the measured
  /// position (each cycle until the joint is at rest, then that one), zero velocity, the
  /// configured kp, KD_MAX (the most damping the frame carries) and as tau_ff the torque feed-forward of the cycle
  /// (set_feed_forward: the model's gravity at the measured pose), or without one the torque the
  /// motor measured when the stop began, so an arm without brakes does not fall; the joint reports `stopping`. Joints
  /// not powered are disabled. enable() takes the joints back to the setpoints, disable() powers
  /// them down.
  void quick_stop() override;
  bool quick_stop_holds() const override { return true; }
  /// Joint j holds after quick_stop(), has come to rest and is at rest now (its velocity within
  /// 0.05 rad/s at the actuator, at least four codes of the frame's velocity).
  bool holding(std::size_t j) const override;
  /// Joint j alone gets the disable frame from the next write(); the others keep what they do.
  void disable_joint(std::size_t j) override;
  Status set_position_zero(std::size_t j) override;
  std::int64_t zero_offset(std::size_t j) const override {
    return j < cfg_.joint_count ? cfg_.joints[j].scaling.zero_offset : 0;
  }
  JointCapabilities capabilities(std::size_t j) const override;
  Status set_target_torque(std::size_t j, double torque) override;
  /// Torque mode's kd (free-drive): `damping` joint side, as the actuator's kd (clamped to
  /// KD_MAX); until given, the configured kd.
  Status set_torque_damping(std::size_t j, double damping) override;
  CyclicModeState cyclic_mode(std::size_t j) const override {
    return j < cfg_.joint_count ? CyclicModeState{joints_[j].mode, joints_[j].mode_status} : CyclicModeState{};
  }
  const JointFeedback& feedback(std::size_t j) const override { return fb_[j < cfg_.joint_count ? j : 0]; }
  const char* last_error() const override { return error_; }

  // --- what the family adds -------------------------------------------------------------
  /// Joint j's temperatures (deg C) from its last feedback: MOSFET and rotor (one sensor: both).
  double temperature_mos(std::size_t j) const { return j < cfg_.joint_count ? joints_[j].t_mos : 0; }
  double temperature_rotor(std::size_t j) const { return j < cfg_.joint_count ? joints_[j].t_rotor : 0; }
  /// Joint j is at or above its warning temperature.
  bool temperature_warning(std::size_t j) const { return j < cfg_.joint_count && joints_[j].hot; }
  /// The ranges joint j's frames are packed with (the motor's registers for Damiao).
  const mit::Ranges& ranges(std::size_t j) const { return joints_[j < cfg_.joint_count ? j : 0].r; }
  /// The last command sent to joint j (actuator side), for tests and the state stream.
  const mit::Command& last_command(std::size_t j) const { return joints_[j < cfg_.joint_count ? j : 0].sent; }
  /// What the bring-up noticed but accepted (a range other than the profile's), one line each.
  const char* notes() const { return notes_; }
  const MitGroupConfig& config() const { return cfg_; }

 protected:
  const HomingSpec& homing_spec(std::size_t j) const override { return cfg_.joints[j < kMaxServoJoints ? j : 0].homing; }
  Status family_start(TimePoint deadline) override;
  Status family_read(TimePoint now) override;
  Status family_write(std::span<const double> setpoints, TimePoint now) override;
  /// Kind none (an absolute joint): homed at once (ok), as ServoBus::start_homing says; the MIT
  /// family has no homing of its own (hard_stop runs in the group base).
  Status family_start_homing(std::size_t j, TimePoint now) override;
  Status family_set_feed_forward(std::size_t j, double velocity, double torque) override;
  Status family_set_torque_mode(std::size_t j, bool on) override;
  double shift_zero(std::size_t j, double at, double reads) override;
  double resolution(std::size_t j) const override;
  void note_error(const char* text) override;

 private:
  struct Joint {
    mit::Ranges r{};
    mit::Unwrap unwrap{};
    double k = 1;            ///< actuator rad per joint unit (direction included)
    double zero = 0;         ///< actuator rad at joint zero
    double p_act = 0;        ///< actuator position, multi-turn
    double t_mos = 0, t_rotor = 0;
    double temp_warning = 0, temp_fault = 0, temp_cutoff = 0;
    bool hot = false;
    std::uint8_t error = 0;  ///< the last error nibble / code
    bool want = false;       ///< enable() asked for operation
    bool clear = false;      ///< a latched fault to clear before enabling
    bool overheated = false; ///< our own temperature fault (latched until enable())
    TimePoint enabling_since = 0;
    bool enable_sent = false;   ///< this cycle's frame was the enable frame
    bool answered = false;      ///< CubeMars / Robstride: an enable frame was answered (enabled)
    bool ff = false;
    double ff_v = 0, ff_t = 0;  ///< actuator side
    bool have_target = false;
    double target_t = 0;        ///< joint side
    double torque_kd = -1;      ///< actuator kd in torque mode (set_torque_damping); < 0: the configured kd
    double torque_kd_rest = 0;  ///< the part of it beyond KD_MAX, applied through tau_ff
    CyclicMode mode = CyclicMode::position;
    Status mode_status = Status::ok;
    bool hold = false;          ///< hold where it stands in the next write (leaving torque mode)
    bool qstop = false;         ///< quick_stop(): holds at qstop_at with qstop_t until enable() / disable()
    bool qstop_rest = false;    ///< the held joint came to rest: qstop_at is fixed, kp holds it there
    double qstop_at = 0, qstop_t = 0;  ///< actuator rad, N m
    double stop_kd_rest = 0;    ///< MitJointConfig::stop_damping beyond KD_MAX, actuator side: tau_ff in the hold
    double v_act = 0, t_act = 0;       ///< the last feedback's velocity and torque, actuator side
    double hold_at = 0;         ///< actuator rad
    mit::Command sent{};
  };
  /// set_feed_forward has given a torque other than 0 (the model's torque feed-forward runs; a
  /// velocity feed-forward comes with torque 0): the controller brakes the hold through it, so
  /// the hold leaves out the stop damping.
  bool model_torque_ = false;
  static double rest_band(const Joint& J);
  std::uint16_t master(std::size_t j) const;
  bool is_feedback_of(std::size_t j, const CanFrame& f) const;
  void take_feedback(std::size_t j, const mit::Feedback& m, TimePoint now);
  void fault(std::size_t j, Status why, std::uint16_t code, TimePoint now);
  Status send(const CanFrame& f);
  /// Bring-up: send `req` and wait for a frame `match` accepts (attempts x reply_timeout).
  template <class Match>
  bool ask(const CanFrame& req, Match&& match, TimePoint deadline);
  Status bring_up(std::size_t j, TimePoint deadline);
  bool reg_read(std::size_t j, mit::Reg rid, std::uint32_t& raw, std::uint32_t& answered_on, TimePoint deadline);
  bool reg_write(std::size_t j, mit::Reg rid, std::uint32_t raw, TimePoint deadline);
  Status refuse(std::size_t j, Status why, const char* fmt, ...) __attribute__((format(printf, 4, 5)));

  CanBus& bus_;
  Clock& clock_;
  MitGroupConfig cfg_;
  Status config_status_ = Status::ok;
  bool started_ = false;
  std::array<Joint, kMaxServoJoints> joints_{};
  std::array<JointFeedback, kMaxServoJoints> fb_{};
  char error_[256] = {};
  char notes_[512] = {};
};

}  // namespace servoarm::hal
