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
// Time is passed in (TimePoint, ns): the simulation runs on a ManualClock in
// tests and on CLOCK_MONOTONIC in `armsim`.
#include <array>
#include <cstdint>
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
  std::uint8_t node() const { return node_; }
  hal::cia402::State state() const { return state_; }
  hal::canopen::NmtState nmt() const { return nmt_; }
  double position() const { return pos_; }        ///< counts, unquantised
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
  Entry* find(std::uint16_t index, std::uint8_t sub);
  const Entry* find(std::uint16_t index, std::uint8_t sub) const;
  void add(std::uint16_t index, std::uint8_t sub, std::uint8_t size, bool writable, bool mappable, std::uint32_t value);
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

  std::uint8_t node_;
  MotorParams motor_;
  DriveFaults faults_;
  std::vector<Entry> od_;
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
  std::int32_t target_ = 0;
  std::uint64_t syncs_ = 0;
  std::uint64_t rng_;
  // Latched synchronous RPDO payloads (applied at the next SYNC).
  std::array<CanFrame, 2> rpdo_latch_{};
  std::array<bool, 2> rpdo_pending_{};
  // SDO server state.
  enum class SdoMode : std::uint8_t { idle, download, upload };
  SdoMode sdo_mode_ = SdoMode::idle;
  std::uint16_t sdo_index_ = 0;
  std::uint8_t sdo_sub_ = 0;
  bool sdo_toggle_ = false;
  std::size_t sdo_off_ = 0, sdo_size_ = 0;
  std::array<std::uint8_t, 64> sdo_buf_{};
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
  /// The shared plant, or nullptr (first-order motors).
  ArmPlant* plant() { return plant_.get(); }
  void power_on(TimePoint now);
  /// Drain everything received so far (poll), then tick every drive. For single-threaded use.
  void step(TimePoint now);
  void handle(const CanFrame& f, TimePoint now);
  void tick(TimePoint now);
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
