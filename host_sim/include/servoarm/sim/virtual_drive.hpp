// SPDX-License-Identifier: Apache-2.0
#pragma once
// Virtual CiA 402 servo drives for tests and the `armsim` binary.
//
// Each VirtualDrive is one CANopen node: an object-dictionary subset, NMT
// slave, SDO server (expedited + segmented), heartbeat producer, EMCY producer,
// PDOs configured through the dictionary exactly as on a real drive (mapping
// validated, SYNC-triggered), the CiA 402 power state machine and a motor
// model in cyclic synchronous position mode: first-order lag towards the
// target, velocity and acceleration limits, encoder quantisation, following
// error monitoring (0x6065 window -> EMCY 0x8611 + fault). It behaves like a
// drive, not an echo: the position it reports trails the setpoint.
//
// Homing (docs/servo-bus.md#homing): simulated limit switches, a home switch,
// an index pulse once per motor revolution and mechanical end stops (DriveSwitches, in the
// drive's physical counts: the position before any homing); 60FDh reports the switches
// (bit 0 negative limit, bit 1 positive limit, bit 2 home switch). Homing Mode (6060h = 6)
// with 6098h, 6099h:01/:02, 609Ah, 607Ch: controlword bit 4 rising edge starts, falling edge
// interrupts, bit 8 halts; statusword bits 10/12/13 as CiA 402 defines them in homing mode.
// At the home mark the drive's position becomes 607Ch (6064h = 607Ch there) and it stops on
// the mark. Methods 1-7, 11, 17-23, 27 (switches, with or without index), 33, 34 (index),
// 35, 37 (current position); others are refused when written to 6098h (06090030h).
//
// Torque: on the dynamic plant (ArmPlant) the drive also offers cyclic synchronous
// torque (6060h = 10, 6502h bit 9, target torque 6071h + 60B2h, saturated), and 6060h may be
// mapped into an RPDO (a mode change at the SYNC); docs/servo-bus.md#feed-forward-and-torque-mode.
//
// Time is passed in (TimePoint, ns): the simulation runs on a ManualClock in
// tests and on CLOCK_MONOTONIC in `armsim`.
#include <array>
#include <atomic>
#include <cstdint>
#include <limits>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "servoarm/hal/can_bus.hpp"
#include "servoarm/hal/canopen.hpp"
#include "servoarm/hal/cia402.hpp"
#include "servoarm/hal/scaling.hpp"
#include "servoarm/kinematics/chain.hpp"

namespace servoarm::sim {

using hal::CanBus;
using hal::CanFrame;
using hal::Duration;
using hal::TimePoint;

struct MotorParams {
  double max_velocity = 10.0 * 131072;   ///< counts/s (10 rev/s at 17 bit)
  double max_accel = 400.0 * 131072;     ///< counts/s^2
  double lag = 0.002;                    ///< s, first-order time constant of the position loop
  std::uint32_t following_window = 13107;///< counts (0x6065 default; 0.1 rev)
  Duration substep = 100 * hal::kMicrosecond;  ///< integration step
  /// PDO mapping entries (16xxh/1Axxh sub 1..8) checked when written (abort 06040041h for an
  /// object the drive lacks or cannot map), as many drives do; false: only when sub 0 (the
  /// count) is written, as others do. Masters must cope with both.
  bool check_map_entries = false;
  /// 6076h motor rated torque, mN m (6077h/60B2h are per mille of it).
  std::uint32_t rated_torque_mnm = 1000;
};

/// Fault injection. Change at any time (tests) or from the armsim command line.
struct DriveFaults {
  bool silent = false;             ///< node sends nothing and ignores everything (unplugged)
  bool heartbeat_stopped = false;  ///< only the heartbeat producer stops
  bool refuse_enable = false;      ///< stays in switched_on when told to enable operation
  double position_noise = 0.0;     ///< counts: uniform +-amplitude added to reported position
  double tx_drop_rate = 0.0;       ///< probability each transmitted frame is lost
  bool fault_persists = false;     ///< a fault reset (6040h bit 7 rising) leaves the drive in fault
};

/// Switches and mechanics, in the drive's physical counts (its position before any homing).
struct DriveSwitches {
  static constexpr double kNone = std::numeric_limits<double>::infinity();
  double neg_limit = -kNone;  ///< negative limit switch: active at or below (60FDh bit 0)
  double pos_limit = kNone;   ///< positive limit switch: active at or above (60FDh bit 1)
  /// Home switch: active on [home_lo, home_hi] (60FDh bit 2). An infinite end makes a one-sided
  /// switch: home_hi = +inf is a "positive home switch" (methods 3, 4, 19, 20), home_lo = -inf
  /// a "negative" one (5, 6, 21, 22); a cam of finite width suits 7, 11, 23, 27. home_lo >
  /// home_hi (the default) = no home switch.
  double home_lo = kNone, home_hi = -kNone;
  double index_period = 131072;  ///< index pulse every this many counts (one motor revolution)
  double index_phase = 0;        ///< ... at index_phase + k x index_period
  double end_neg = -kNone;       ///< mechanical end stops: the position is clamped there; the
  double end_pos = kNone;        ///< following error grows and 6077h reports the push
  double max_travel = 0;         ///< homing error after this much travel without the mark (0 = none)
};

/// Behaviours of real drives that masters trip over. Set before power_on()
/// (boot_delay) or at any time (the others); set_quirks() keeps 6502h in step.
struct DriveQuirks {
  bool no_homing = false;            ///< 6502h without homing mode (bit 5); 6060h = 6 aborts 06090030h
  std::uint32_t supported_modes = 0; ///< 6502h as reported (0 = the model's: 0xA0, CSP + homing)
  bool halt_blocks_mode_change = false;  ///< 6060h written while 6040h bit 8 is set shows in 6061h
                                         ///< (and acts) only once bit 8 is clear again
  bool refuse_same_mode = false;     ///< writing 6060h with the mode already shown in 6061h aborts 08000022h
  Duration sdo_delay = 0;            ///< every SDO reply is sent this much later
  Duration boot_delay = 0;           ///< power_on(): silent for this long, then the boot-up heartbeat
  bool never_attained = false;       ///< homing reaches home and stops but never sets statusword bit 12
  bool fault_reset_on_level = false; ///< lenient: bit 7 set resets a fault without a rising edge
                                     ///< (default: only a rising edge does, as CiA 402 says)
  bool no_cst = false;               ///< on the dynamic plant, still no cyclic synchronous torque
                                     ///< (6502h without bit 9; 6060h = 10 aborts 06090030h)
  int lose_csp_writes = 0;           ///< the next N SDO writes of 6060h = 8 are lost (neither acted on
                                     ///< nor answered: a frame dropped by a starved receiver)
};

class ArmPlant;
struct ArmPlantParams;

class VirtualDrive {
 public:
  /// Set-up: builds the object dictionary (allocates).
  explicit VirtualDrive(std::uint8_t node, const MotorParams& motor = {}, std::uint64_t seed = 1);

  /// Boot: sends the boot-up heartbeat and enters pre-operational.
  void power_on(TimePoint now, CanBus& bus);
  /// Handle one received frame (ignores what is not for this node).
  void handle(const CanFrame& f, TimePoint now, CanBus& bus);
  /// Advance the motor model and produce heartbeats up to `now`.
  void tick(TimePoint now, CanBus& bus);
  /// Raise an error: EMCY with `code` and the drive goes to fault (code 0: no-op).
  void inject_emcy(std::uint16_t code, TimePoint now, CanBus& bus);

  DriveFaults& faults() { return faults_; }
  DriveSwitches& switches() { return switches_; }
  const DriveQuirks& quirks() const { return quirks_; }
  void set_quirks(const DriveQuirks& q);
  std::uint8_t node() const { return node_; }
  /// Counts added to the physical position by the last homing (reported = physical + shift).
  double home_shift() const { return shift_; }
  /// Physical position (counts): what the switches see.
  double physical_position() const { return pos_ - shift_; }
  /// Where the last homing found its mark, in physical counts (NaN before).
  double home_mark() const { return home_mark_; }
  /// 60FDh as it is now: the switches' bits and the wired inputs (set_input_bits).
  std::uint32_t digital_inputs() const;
  /// Any thread: the inputs wired to the drive (an e-stop contact, a Reduced-mode switch):
  /// bits `mask` of 60FDh become those of `value` from the next SYNC's TPDO on.
  void set_input_bits(std::uint32_t mask, std::uint32_t value) {
    std::atomic_ref<std::uint32_t> bits(input_bits_);
    std::uint32_t old = bits.load(std::memory_order_relaxed);
    while (!bits.compare_exchange_weak(old, (old & ~mask) | (value & mask), std::memory_order_relaxed)) {
    }
  }
  /// 60FEh:01: the physical digital outputs as last written (SDO or RPDO, acted on at the SYNC).
  std::uint32_t digital_outputs() const { return get(hal::cia402::kDigitalOutputs, 1); }
  /// True while the position is clamped at a mechanical end stop.
  bool at_end_stop() const { return at_stop_; }
  std::int8_t mode_display() const { return std::int8_t(value_at(mode_at_)); }
  hal::cia402::State state() const { return state_; }
  hal::canopen::NmtState nmt() const { return nmt_; }
  double position() const { return pos_; }        ///< counts, unquantised
  /// Set-up, not while enabled: the shaft stands at `counts` (physical and reported, no homing
  /// shift), at rest, the target there too.
  void place_at(double counts);
  /// Set-up: a motor that can follow a joint moving at up to `velocity` counts/s with up to
  /// `acceleration` counts/s^2: the speed and acceleration limits raised to 1.5x those (never
  /// lowered), the following-error window (6065h) to at least 4x the lag at that speed.
  /// The defaults fit a revolute joint (10 rev/s); a prismatic joint's counts per metre
  /// need more.
  void fit_motion(double velocity, double acceleration);
  /// The time up to `now` passes without motion: the motor (first-order) stands where it is
  /// and its clock moves on. ArmSim::skip_to for the plant.
  void skip_to(TimePoint now);
  double velocity() const { return vel_; }        ///< counts/s
  std::int32_t target() const { return target_; } ///< counts, last applied at SYNC
  std::uint64_t syncs_seen() const { return syncs_; }
  /// Torque the drive commands (dynamic plant: joint side, N m or N; first-order: 0).
  double torque() const { return torque_; }
  /// True when this drive runs on an ArmPlant (ArmPlant::attach).
  bool on_plant() const { return plant_ != nullptr; }

  /// Object dictionary access for tests (expedited-size objects only).
  bool od_read(std::uint16_t index, std::uint8_t sub, std::uint32_t& value) const;
  /// Set an object directly (configuration/tests; bypasses access rights and checks).
  bool od_write(std::uint16_t index, std::uint8_t sub, std::uint32_t value);
  /// Set-up: the drive lacks object `index` (every sub-index): SDO access aborts with
  /// 0x06020000 and mapping it aborts with 0x06040041, as on a drive that never had it
  /// (interoperability tests: a CSP drive without 606Ch or 603Fh). False if it was absent.
  bool od_remove(std::uint16_t index);

 private:
  struct Entry {
    std::uint16_t index;
    std::uint8_t sub;
    std::uint8_t size;  ///< bytes: 1, 2, 4; 0 = domain (bytes in `domain`)
    bool writable;
    bool mappable;
    std::uint32_t value;
    std::uint32_t initial;
    std::vector<std::uint8_t> domain;
    std::size_t domain_cap = 0;
  };
  static constexpr std::uint32_t od_key(std::uint16_t index, std::uint8_t sub) { return std::uint32_t(index) << 8 | sub; }
  Entry* find(std::uint16_t index, std::uint8_t sub);
  const Entry* find(std::uint16_t index, std::uint8_t sub) const;
  void add(std::uint16_t index, std::uint8_t sub, std::uint8_t size, bool writable, bool mappable, std::uint32_t value);
  void index_dictionary();
  void reset_dictionary(bool communication_only);
  std::uint32_t sdo_write(Entry& e, const std::uint8_t* data, std::size_t len);
  std::uint32_t check_mapping(std::uint16_t map_index, std::uint32_t count) const;
  void handle_sdo(const CanFrame& f, TimePoint now, CanBus& bus);
  void serve_sdo(const CanFrame& f, CanBus& bus);
  void handle_nmt(hal::canopen::NmtCommand cmd, TimePoint now, CanBus& bus);
  void on_sync(TimePoint now, CanBus& bus);
  void apply_rpdo(int pdo, const CanFrame& f);
  void send_tpdo(int pdo, CanBus& bus);
  void apply_controlword(TimePoint now, CanBus& bus);
  void advance(TimePoint now, CanBus& bus);
  void update_statusword();
  void after_substep(CanBus& bus, bool at_rest);
  void publish_feedback();
  // ArmPlant's side (the drive on the shared plant): set-up, the loop per step, feedback.
  friend class ArmPlant;
  void attach_plant(ArmPlant* plant, const hal::JointScaling& s, double kp, double kv, double ki, double torque_limit,
                    std::uint32_t rated_torque_mnm);
  double servo_torque(double q, double qd, double h);
  void plant_update(TimePoint t, double q, double qd, double torque, CanBus& bus);
  bool powered() const {
    return state_ == hal::cia402::State::operation_enabled || state_ == hal::cia402::State::quick_stop_active;
  }
  void set(std::uint16_t index, std::uint32_t v);
  std::uint32_t get(std::uint16_t index, std::uint8_t sub = 0) const;
  void tx(CanBus& bus, const CanFrame& f);
  double uniform();  // [0,1)
  // Homing: the demand generator (per motor substep), its switch/edge logic, the mode change.
  void homing_start();
  void homing_substep(double dt, bool halt);
  void homing_after(double p0, double p1);
  void homing_capture(double mark);
  void homing_fail();
  void set_mode(std::int8_t m);
  void update_supported_modes();
  bool mode_allowed(std::int8_t m) const;
  bool home_active(double p) const { return p >= switches_.home_lo && p <= switches_.home_hi; }
  bool signal_at(double p) const;
  void boot(TimePoint now, CanBus& bus);

  std::uint8_t node_;
  MotorParams motor_;
  DriveFaults faults_;
  std::vector<Entry> od_;
  /// find()'s hash table over od_ (open addressing, linear probing; -1 = empty slot), at
  /// most a quarter full; rebuilt by index_dictionary() whenever od_ changes shape.
  std::vector<std::int16_t> od_slots_;
  unsigned od_shift_ = 32;
  /// Positions in od_ of the entries read for every frame and sub-step, -1 if absent (set
  /// with od_slots_): 6061h, and each RPDO's COB-ID (sub 1) and transmission type (sub 2).
  std::int16_t mode_at_ = -1;
  std::int16_t rpdo_cob_at_[3] = {-1, -1, -1};
  std::int16_t rpdo_type_at_[3] = {-1, -1, -1};
  std::uint32_t value_at(std::int16_t k) const { return k < 0 ? 0 : od_[std::size_t(k)].value; }
  hal::canopen::NmtState nmt_ = hal::canopen::NmtState::boot_up;
  hal::cia402::State state_ = hal::cia402::State::not_ready_to_switch_on;
  std::uint16_t prev_cw_ = 0;
  bool sdo_actuate_ = false;  ///< the SDO request being served wrote 6040h or 607Ah
  bool booted_ = false;
  TimePoint t_ = 0;
  TimePoint next_hb_ = 0;
  double pos_ = 0.0, vel_ = 0.0, torque_ = 0.0;
  // On an ArmPlant: the plant, this joint's scaling and loop (joint units).
  ArmPlant* plant_ = nullptr;
  hal::JointScaling scaling_{};
  double kp_ = 0, kv_ = 0, ki_ = 0, tmax_ = 0;
  double integ_ = 0;        ///< velocity-loop integral (rad/s s)
  double qs_vref_ = 0;      ///< quick stop: the ramped velocity demand
  double hold_q_ = 0;       ///< quick stop at rest: where it holds
  bool qs_ramping_ = false;
  double torque_unit_ = 0;  ///< joint N m per 6077h/60B2h unit (per mille of 6076h x G x dir)
  double tq_sum_ = 0;       ///< plant: the loop's torque summed over the steps since the last SYNC
  int tq_n_ = 0;
  std::int32_t target_ = 0;
  std::uint64_t syncs_ = 0;
  /// set_input_bits: the wired inputs of 60FDh, read and written through std::atomic_ref (the
  /// drives live in a vector, which needs them movable).
  alignas(std::atomic_ref<std::uint32_t>::required_alignment) mutable std::uint32_t input_bits_ = 0;
  std::uint64_t rng_;
  // Latched synchronous RPDO payloads (applied at the next SYNC).
  std::array<CanFrame, 3> rpdo_latch_{};   // RPDO1..3 (RPDO3: digital outputs)
  std::array<bool, 3> rpdo_pending_{};
  // SDO server state.
  enum class SdoMode : std::uint8_t { idle, download, upload };
  SdoMode sdo_mode_ = SdoMode::idle;
  std::uint16_t sdo_index_ = 0;
  std::uint8_t sdo_sub_ = 0;
  bool sdo_toggle_ = false;
  std::size_t sdo_off_ = 0, sdo_size_ = 0;
  std::array<std::uint8_t, 64> sdo_buf_{};
  // Switches, quirks, homing.
  DriveSwitches switches_{};
  DriveQuirks quirks_{};
  TimePoint now_ = 0;      ///< time of the frame being handled (SDO delay)
  TimePoint boot_at_ = 0;  ///< boot_delay: when the boot-up happens (0 = not pending)
  std::vector<std::pair<TimePoint, CanFrame>> delayed_;  ///< SDO replies not yet sent
  std::int8_t pending_mode_ = 0;  ///< halt_blocks_mode_change: written, not yet shown
  bool has_pending_mode_ = false;
  bool at_stop_ = false;
  double shift_ = 0;       ///< reported = physical + shift_
  double home_mark_ = std::numeric_limits<double>::quiet_NaN();
  enum class HPhase : std::uint8_t { idle, search, final_edge, index, to_home, attained, error, interrupted };
  struct Homing {
    HPhase phase = HPhase::idle;
    int dir = 0;            ///< direction of the demand, +1 / -1
    double speed = 0;       ///< counts/s of the current phase
    double v = 0;           ///< demand velocity, counts/s
    double demand = 0;      ///< demand position, reported counts
    double goal = 0;        ///< to_home: the mark (607Ch)
    double travel = 0;      ///< |distance| since the start
    double edge = 0;        ///< the edge sought, physical counts
    double index_at = 0;    ///< index phase: the pulse sought, physical counts
    int d_final = 0;        ///< direction in which the edge is crossed
    bool want_before = false;  ///< the signal's state just before the edge (moving d_final)
    bool use_index = false;
    bool may_reverse = false;  ///< a limit switch reverses the search (methods 7-14, 23-30)
    bool reversed = false;
    int signal = 0;         ///< 0 home switch, 1 negative limit, 2 positive limit
  } h_{};
};

/// A set of virtual drives sharing one bus endpoint (what `armsim` runs).
class ArmSim {
 public:
  ArmSim(CanBus& bus, std::span<const std::uint8_t> nodes, const MotorParams& motor = {}, std::uint64_t seed = 1);
  ~ArmSim();
  ArmSim(const ArmSim&) = delete;
  ArmSim& operator=(const ArmSim&) = delete;
  /// Set-up, after power_on: run the drives on one shared rigid-body plant of `chain`
  /// (drive i = joint i; `scaling[i]` converts its counts to the joint, as the master's
  /// JointScaling does). "" or the reason (e.g. the model has no inertial data). Without
  /// it each drive runs its own first-order motor (the default, for fast tests).
  std::string use_dynamic_plant(const kin::Chain& chain, std::span<const hal::JointScaling> scaling,
                                const ArmPlantParams& params);
  /// Set-up: every drive i to joint i's in-limit value closest to 0 in `chain` (counts through
  /// `scaling[i]`), the dynamic plant's state too. Drives beyond the chain's joints are left.
  void place_within_limits(const kin::Chain& chain, std::span<const hal::JointScaling> scaling);
  /// The shared plant, or nullptr (first-order motors).
  ArmPlant* plant() { return plant_.get(); }
  void power_on(TimePoint now);
  /// Drain everything received so far (poll), then tick every drive. For single-threaded use.
  void step(TimePoint now);
  void handle(const CanFrame& f, TimePoint now);
  void tick(TimePoint now);
  /// The time up to `now` passes with the arm paused: every motor and the plant stand still
  /// and their clocks move on (SimPlant's pause for a host that stalled the loop).
  void skip_to(TimePoint now);
  std::size_t size() const { return drives_.size(); }
  VirtualDrive& at(std::size_t i) { return drives_[i]; }
  /// Drive with CANopen node id `node`, or nullptr.
  VirtualDrive* node(std::uint8_t node);
  /// Frames the sim could not buffer/handle (diagnostics).
  CanBus& bus() { return bus_; }

 private:
  CanBus& bus_;
  std::vector<VirtualDrive> drives_;
  std::unique_ptr<ArmPlant> plant_;
};

}  // namespace servoarm::sim
