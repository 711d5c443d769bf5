// SPDX-License-Identifier: Apache-2.0
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
  TimePoint sampled = 0;        ///< when the drive took position, velocity and torque: the SYNC the
                                ///< feedback answers (CANopen: the last SYNC the master sent before the
                                ///< TPDO arrived), else the frame's arrival; 0 = none. Successive values
                                ///< give the true interval between samples when the cycle jitters
  TimePoint last_heartbeat = 0; ///< time of the last heartbeat (0 = none)
  TimePoint fault_since = 0;    ///< when the fault was detected
  Duration age = -1;            ///< now - last_feedback at the last read(), -1 = none yet
  /// The drive's hottest reported temperature (deg C: MIT motors' MOSFET or winding), with the
  /// limits the family supervises it against (below the motor's own cut-off). has_temperature
  /// false: the drive reports none (CiA 402 here), the three values are 0.
  bool has_temperature = false;
  double temperature = 0.0;
  double temperature_warning = 0.0;  ///< deg C: from here on the joint is hot (a warning)
  double temperature_limit = 0.0;    ///< deg C: here the family faults the joint (drive_fault)
  double temperature_cutoff = 0.0;   ///< deg C: where the motor stops by itself
  /// The drive's digital inputs (CiA 402 60FDh, when mapped: CanopenJointConfig::digital_inputs):
  /// has_inputs false when the drive does not report them; inputs_time the last frame that
  /// carried them (0 = none yet), so a reader can tell a stale word (safety inputs).
  bool has_inputs = false;
  std::uint32_t digital_inputs = 0;
  TimePoint inputs_time = 0;
};

/// How a joint establishes its zero at power-up (docs/servo-bus.md#homing).
enum class HomingKind : std::uint8_t {
  none,       ///< absolute encoder: the drive's position is valid at power-up, no homing
  cia402,     ///< the drive's own Homing Mode (6060h = 6) with method HomingSpec::method (6098h)
  hard_stop,  ///< no switch: the master moves the joint slowly in cyclic position mode until the
              ///< following error or the torque passes a threshold, backs off, takes that as offset
};
const char* to_string(HomingKind k);

/// One joint's homing parameters, in joint units (rad or m), set up before ServoBus::start().
struct HomingSpec {
  HomingKind kind = HomingKind::none;
  std::int8_t method = 0;         ///< cia402: CiA 402 homing method number (6098h)
  double speed_switch = 0.0;      ///< cia402: 6099h:01 search for switch; hard_stop: approach speed,
                                  ///< its sign is the direction (joint units / s)
  double speed_zero = 0.0;        ///< cia402: 6099h:02 search for zero (joint units / s)
  double acceleration = 0.0;      ///< cia402: 609Ah; hard_stop: approach/back-off acceleration
  double offset = 0.0;            ///< joint position at the home mark (cia402: 607Ch), or at the
                                  ///< backed-off point (hard_stop)
  Duration timeout = 0;           ///< the whole homing of this joint; 0 = not set (refused)
  double following_limit = 0.0;   ///< hard_stop: |demanded - actual| that means contact
  double torque_limit = 0.0;      ///< hard_stop: |torque| (N m / N) that means contact; 0 = unused
  double backoff = 0.0;           ///< hard_stop: distance moved back from the contact (> 0)
  /// Supervision of both kinds: the homing fails (homing_error, the distance in the message)
  /// once the joint stands farther than this from where its homing began (joint units; the
  /// joint's range plus a margin); 0 = not supervised.
  double max_travel = 0.0;
};

/// Where one joint's homing stands (ServoBus::homing()).
enum class HomingPhase : std::uint8_t {
  idle,      ///< not started since power-up (or aborted): not homed unless kind == none
  running,   ///< in progress: the master, not the caller's setpoints, moves this joint
  attained,  ///< done: the joint's position is valid in joint coordinates; the drive is back in
             ///< cyclic synchronous position mode holding its actual position
  failed,    ///< homing error, timeout or abort: see HomingProgress::status / ServoBus::last_error()
};
const char* to_string(HomingPhase p);

struct HomingProgress {
  HomingPhase phase = HomingPhase::idle;
  Status status = Status::ok;   ///< why failed: timeout, drive_refused (homing error bit 13 or the
                                ///< mode was not accepted), bad_state, drive_fault, heartbeat_lost...
  std::uint8_t step = 0;        ///< protocol-specific step, for progress reports
};

/// Cyclic mode of one joint (docs/servo-bus.md#feed-forward-and-torque-mode).
enum class CyclicMode : std::uint8_t {
  position,         ///< cyclic synchronous position (CiA 402 CSP, 6060h = 8): write()'s setpoints
  entering_torque,  ///< asked for torque mode (6060h = 10 sent), the drive does not show it yet
  torque,           ///< cyclic synchronous torque (CST, 6061h = 10): set_target_torque()'s torque
  leaving_torque,   ///< back to CSP asked (6060h = 8 sent, holding where the joint was)
};
const char* to_string(CyclicMode m);

struct CyclicModeState {
  CyclicMode mode = CyclicMode::position;
  Status status = Status::ok;  ///< why the last torque mode ended other than by request:
                               ///< drive_refused (6061h never showed 10), the joint's fault,
                               ///< aborted (disable / quick stop); ok otherwise
};

/// What one joint can do beyond CSP, as brought up (all false for protocols without it).
struct JointCapabilities {
  bool velocity_offset = false;  ///< set_feed_forward's velocity reaches the drive (CANopen: 60B1h mapped)
  bool torque_offset = false;    ///< set_feed_forward's torque reaches the drive (60B2h mapped)
  bool torque_mode = false;      ///< set_torque_mode works (CST supported and 6060h/6061h/6071h mapped)
  bool measured_torque = false;  ///< JointFeedback::torque comes from the drive (6077h mapped)
  bool digital_outputs = false;  ///< set_digital_outputs reaches the drive (CANopen: 60FEh:01 mapped)
  /// In torque mode the drive damps the joint's motion itself (MIT motors: kd with kp = 0), so a
  /// caller adds no damping torque of its own (free-drive).
  bool torque_mode_damping = false;
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
  /// After quick_stop() the drives hold where they stopped, powered, until enable() or
  /// disable() (drives without brakes, whose arm falls when powered down: MIT motors). The
  /// controller then powers down only a stop that does not come to rest.
  virtual bool quick_stop_holds() const { return false; }
  /// Real-time: joint `j` holds at rest after quick_stop() (quick_stop_holds()): powered, its
  /// velocity within the drive's rest band.
  virtual bool holding(std::size_t j) const {
    (void)j;
    return false;
  }
  /// Real-time: power joint `j` down and leave the others as they are (a held joint that does not
  /// come to rest while the others hold the arm). Buses that cannot power one joint down alone
  /// power every joint down (disable()).
  virtual void disable_joint(std::size_t j) {
    (void)j;
    disable();
  }

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

  /// Real-time: start homing joint `j` as configured (HomingSpec). The joint must be enabled
  /// (operation enabled); from then until the phase leaves `running` the master moves it and
  /// write() ignores its setpoint. When attained, the joint's feedback position jumps to its
  /// homed coordinates: the caller re-reads it before sending setpoints again.
  /// @retval ok (started; also when kind == none: attained at once); invalid_argument (no such
  ///         joint); bad_state (joint not enabled, or already homing); not_supported
  virtual Status start_homing(std::size_t j, TimePoint now) {
    (void)j;
    (void)now;
    return Status::not_supported;
  }
  /// Real-time: abort joint `j`'s homing (no-op if not running): the drive stops (halt, then
  /// back to cyclic position mode at its actual position) and the phase becomes failed with
  /// status `aborted`; the joint stays unhomed.
  virtual void abort_homing(std::size_t j) { (void)j; }
  /// Real-time: joint `j`'s homing phase. Joints with kind == none report attained.
  virtual HomingProgress homing(std::size_t j) const {
    (void)j;
    return {HomingPhase::attained, Status::ok, 0};
  }
  /// Real-time: one line on joint `j`'s failed homing, naming the joint and the cause, into
  /// `buf` (e.g. "joint 1 (node 2): homing timeout after 1500 ms waiting for homing attained
  /// (statusword bits 10, 12) (statusword 0x0637)"); "" when its homing did not fail.
  virtual void describe_homing(std::size_t j, char* buf, std::size_t size) const {
    (void)j;
    if (size > 0) buf[0] = '\0';
  }
  /// Joint `j`'s configured homing kind (none when the protocol has no homing).
  virtual HomingKind homing_kind(std::size_t j) const {
    (void)j;
    return HomingKind::none;
  }

  // --- Feed-forward and torque mode. Defaults: not supported. -----------------

  /// Joint `j`'s capabilities as brought up (after start()).
  virtual JointCapabilities capabilities(std::size_t j) const {
    (void)j;
    return {};
  }
  /// Real-time: feed-forward for joint `j`'s next write() in position mode: `velocity` (rad/s or
  /// m/s, CANopen 60B1h) added to the drive's velocity demand and `torque` (N m or N, joint side,
  /// CANopen 60B2h) added to its torque demand. One-shot: write() sends it once and clears it,
  /// so the caller gives it every cycle and a caller that stops giving it sends none (offsets are
  /// 0 while a joint is not following: disabled, homing, in torque mode). A part the drive does
  /// not take (capabilities()) is dropped.
  /// @retval ok; invalid_argument (no such joint; NaN/Inf, or beyond the drive's object range:
  ///         this joint's offsets are cleared); not_supported (neither offset mapped)
  virtual Status set_feed_forward(std::size_t j, double velocity, double torque) {
    (void)j;
    (void)velocity;
    (void)torque;
    return Status::not_supported;
  }
  /// Real-time: the torque (N m or N, joint side; CANopen 6071h) joint `j` applies in torque
  /// mode, sent with every write() from now on (kept until changed). Give it before
  /// set_torque_mode(j, true).
  /// @retval ok; invalid_argument (no such joint, NaN/Inf or beyond the object's range:
  ///         unchanged); not_supported (no torque mode on this joint)
  virtual Status set_target_torque(std::size_t j, double torque) {
    (void)j;
    (void)torque;
    return Status::not_supported;
  }
  /// Real-time: the viscous damping (N m s / rad or N s / m, joint side) a drive with
  /// JointCapabilities::torque_mode_damping applies itself to joint `j` in torque mode (kept
  /// until changed).
  /// @retval ok; invalid_argument (no such joint, negative or not finite); not_supported
  virtual Status set_torque_damping(std::size_t j, double damping) {
    (void)j;
    (void)damping;
    return Status::not_supported;
  }
  /// Real-time: switch joint `j` to torque mode (on) or back to position mode (off). On: the
  /// joint must be enabled, in position mode, not homing, with a target torque given since it
  /// last left torque mode; the mode is reached when the drive shows it (cyclic_mode()). Off:
  /// from the next write() the joint holds where it stands (the caller's setpoint for it is
  /// ignored until cyclic_mode() says position again, and in the write() of the cycle whose
  /// read() saw it turn; the caller then re-reads its position).
  /// A fault, heartbeat loss, disable() or quick_stop() takes the joint back to position mode
  /// by itself (status says why).
  /// @retval ok (also when already in / on the way to the asked mode); invalid_argument (no such
  ///         joint); not_supported (no torque mode here); bad_state (on: not enabled, homing,
  ///         leaving torque mode, or no target torque given)
  virtual Status set_torque_mode(std::size_t j, bool on) {
    (void)j;
    return on ? Status::not_supported : Status::ok;
  }
  /// Real-time: joint `j`'s cyclic mode and why its last torque mode ended.
  virtual CyclicModeState cyclic_mode(std::size_t j) const {
    (void)j;
    return {};
  }

  /// Real-time: the physical digital outputs of joint `j`'s drive (CANopen 60FEh:01, one bit per
  /// output), sent with every write() from now on (kept until changed).
  /// @retval ok; invalid_argument (no such joint); not_supported (no outputs mapped on this joint)
  virtual Status set_digital_outputs(std::size_t j, std::uint32_t value) {
    (void)j;
    (void)value;
    return Status::not_supported;
  }
  /// Real-time: the outputs word joint `j`'s write() sends (0 when none are mapped).
  virtual std::uint32_t digital_outputs(std::size_t j) const {
    (void)j;
    return 0;
  }

  /// Real-time: latest feedback of joint `j` (j < joint_count()).
  virtual const JointFeedback& feedback(std::size_t j) const = 0;

  /// Set-up/diagnostics: text of the last failure ("" if none). Points into the object.
  virtual const char* last_error() const = 0;
};

}  // namespace servoarm::hal
