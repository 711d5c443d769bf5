#pragma once
// The joint-driver interface the firmware uses. One implementation per drive
// protocol (canopen_master.hpp: CANopen CiA 402 over any CanBus); the firmware
// sees only joints in SI units.
#include <cstddef>
#include <cstdint>
#include <span>

#include "servoarm/hal/can_frame.hpp"
#include "servoarm/hal/status.hpp"

namespace servoarm::hal {

/// Most joints one ServoBus drives (matches kin::kMaxJoints).
inline constexpr std::size_t kMaxServoJoints = 8;

enum class JointState : std::uint8_t {
  offline,   ///< not started, or never heard from
  disabled,  ///< powered down (no torque)
  enabling,  ///< powering up: walking the power state machine towards operation enabled
  enabled,   ///< operation enabled: following setpoints
  fault,     ///< latched fault: see JointFeedback::fault and error_code
  stopping,  ///< asked to power down or quick stop but still powered: operation enabled
             ///< on its way down, or quick stop active while still moving (its own ramp)
};
const char* to_string(JointState s);

struct JointFeedback {
  double position = 0.0;        ///< rad (revolute) or m (prismatic)
  double velocity = 0.0;        ///< rad/s or m/s
  double torque = 0.0;          ///< N m (N), joint side, as the drive measures it (CANopen: 6077h
                                ///< when mapped, FeedbackObjects::torque); 0 when not reported
  bool has_torque = false;      ///< torque comes from the drive
  std::uint16_t statusword = 0; ///< raw drive status (CiA 402 0x6041 for CANopen)
  std::uint8_t drive_state = 0; ///< protocol state (cia402::State for CANopen)
  JointState state = JointState::offline;
  Status fault = Status::ok;    ///< why state == fault: drive_fault, heartbeat_lost, drive_refused,
                                ///< protocol_error (node left operational), bus_off
  std::uint16_t error_code = 0; ///< last drive error code (EMCY / 0x603F), 0 = none
  std::uint32_t emcy_count = 0; ///< EMCY frames received from this drive
  bool valid = false;           ///< position/velocity come from at least one feedback frame
  TimePoint last_feedback = 0;  ///< time of the last feedback frame (0 = none)
  TimePoint last_heartbeat = 0; ///< time of the last heartbeat (0 = none)
  TimePoint fault_since = 0;    ///< when the fault was detected
  Duration age = -1;            ///< now - last_feedback at the last read(), -1 = none yet
};

class ServoBus {
 public:
  virtual ~ServoBus() = default;

  virtual std::size_t joint_count() const = 0;

  /// Set-up (blocking, bounded by `deadline`): configure every drive and start
  /// communication. Drives stay disabled. last_error() says what failed.
  virtual Status start(TimePoint deadline) = 0;

  /// Real-time: ask every drive to power up (progress happens in read/write
  /// cycles; clears latched faults so a drive in fault gets a fault reset).
  virtual void enable() = 0;
  /// Real-time: ask every drive to power down (disable operation / shutdown).
  virtual void disable() = 0;
  /// Real-time: controlled stop on the drives' own quick-stop ramp, then hold there
  /// (CiA 402 quick stop). enable() resumes. Protocols without one just disable().
  virtual void quick_stop() { disable(); }

  /// Real-time: consume received frames and update feedback; checks heartbeat
  /// and state-machine timeouts against `now`. Never blocks.
  /// @retval ok               all joints healthy
  /// @retval heartbeat_lost / drive_fault / drive_refused / protocol_error / bus_off
  ///                          at least one joint in fault (the first one's reason; see feedback)
  /// @retval interface_down / io_error   the bus failed while reading (joints fault on heartbeat loss)
  /// @retval not_configured   start() not done
  virtual Status read(TimePoint now) = 0;

  /// Real-time: send one setpoint per joint (rad or m) plus the cycle trigger.
  /// Joints that are not enabled hold their measured position instead. No rate limiting
  /// here: the caller sends a continuous trajectory (a jump trips the drive's following-error
  /// window, which reports a drive_fault).
  /// @retval ok; invalid_argument (size mismatch or non-finite/out-of-range setpoint:
  ///         nothing is sent for that joint, it holds); bus errors from CanBus::send
  virtual Status write(std::span<const double> setpoints, TimePoint now) = 0;

  /// Real-time: make joint `j`'s measured position its zero from now on (homing on the
  /// current position, for drives with incremental encoders). The CANopen master moves its
  /// own zero offset (JointScaling::zero_offset): nothing is written to the drive and the
  /// drive's position is untouched, so it lasts until restart; zero_offset() gives the value
  /// to put into the configuration. Only while the joint is not powered (a powered joint
  /// would see its setpoint jump).
  /// @retval ok; invalid_argument (no such joint); not_configured (no position feedback yet);
  ///         bad_state (joint enabled, enabling or stopping); not_supported (protocol without it)
  virtual Status set_position_zero(std::size_t j) {
    (void)j;
    return Status::not_supported;
  }
  /// Real-time: drive position (drive units, e.g. counts) at joint zero; 0 when not applicable.
  virtual std::int64_t zero_offset(std::size_t j) const {
    (void)j;
    return 0;
  }

  /// Real-time: latest feedback of joint `j` (j < joint_count()).
  virtual const JointFeedback& feedback(std::size_t j) const = 0;

  /// Set-up/diagnostics: text of the last failure ("" if none). Points into the object.
  virtual const char* last_error() const = 0;
};

}  // namespace servoarm::hal
