// SPDX-License-Identifier: Apache-2.0
#pragma once
// CANopen master for CiA 402 drives in cyclic synchronous position mode,
// implementing ServoBus over any CanBus.
//
// Process data (set up explicitly by start(), classic CAN, 8-byte limit):
//   RPDO1 0x200+n  controlword 0x6040 (u16) + target position 0x607A (i32)  6 bytes, acted on at SYNC
//   TPDO1 0x180+n  statusword 0x6041 (u16) + position actual 0x6064 (i32)   6 bytes, every SYNC
//   TPDO2 0x280+n  what CanopenMasterConfig::tpdo2 asks for and the drive has, in this order:
//                  velocity actual 0x606C (i32), error code 0x603F (u16), torque actual
//                  0x6077 (i16); by default velocity + error code (6 bytes), each optional:
//                  a drive without one is brought up without it; with none, TPDO2 stays off.
// (statusword + position + velocity is 10 bytes, more than one classic frame holds.)
//   RPDO2 0x300+n  what CanopenMasterConfig::rpdo2 asks for (off by default): velocity
//                  offset 0x60B1 (i32), torque offset 0x60B2 (i16), target torque 0x6071 (i16);
//                  torque mode adds 0x6060 (i8) to RPDO1 and 0x6061 (i8) to TPDO1 (7 bytes each).
// RPDO1 and TPDO1's objects are required: a drive that lacks one is refused, naming it.
// Without 606Ch the velocity is the difference of successive positions over their receive times.
// Each write() sends the RPDOs then one SYNC (0x080), so the master is the SYNC producer.
// Heartbeat consumer: each node produces every `heartbeat_period`; a node is
// reported lost when nothing arrived for its `heartbeat_timeout`, checked at
// every read() - so within timeout + one cycle.
//
// Homing (docs/servo-bus.md#homing), per joint (CanopenJointConfig::homing):
//   start():  6502h read (for HomingKind::cia402 joints, or every joint with
//             check_supported_modes): a drive without CSP (bit 7), or without homing mode
//             (bit 5) for a cia402 joint, is refused naming the joint; 6098h written (a
//             method the drive refuses is refused at bring-up, naming the joint).
//   cia402:   a per-joint state machine advanced in read() with non-blocking expedited SDO
//             (one outstanding per node; answers routed from read(), timed against `now`):
//             6098h, 6099h:01/:02, 609Ah, 607Ch, 6061h read (6060h = 6 written only when the
//             drive is not already in it, then checked in 6061h), controlword bit 4 low then
//             high in RPDO1, statusword bits 10/12/13 from TPDO1, bit 4 low, 6060h = 8 checked
//             in 6061h; the RPDO target follows the actual position throughout, so nothing
//             jumps when CSP resumes. 607Ch = zero_offset + round(direction x offset x counts
//             per unit): the drive's 6064h at the mark is 607Ch, so the joint reads `offset`
//             there with the configured JointScaling::zero_offset unchanged.
//   hard_stop: drive-neutral, run by the group base (DriveGroup, hard_stop_homing.hpp) with
//             position setpoints in CSP; the master only moves zero_offset (shift_zero) at the end.
//   travel:   cia402 (hard_stop: the same in hard_stop_homing.hpp): the master sums the actual position's changes from where homing began
//             (one change larger than twice the homing speed allows is the drive's coordinate
//             change at the mark, not motion) and fails the homing (homing_error) once the sum
//             exceeds HomingSpec::max_travel: a missing switch or stop ends within the joint's
//             range plus a margin, not at the timeout.
//   Failures: timeout (HomingSpec::timeout), homing_error (bit 13, no contact, travel), aborted,
//             drive_refused (mode not taken), the joint's fault (drive_fault, heartbeat_lost):
//             the drive is halted (bit 8), taken back to CSP at its actual position, unhomed.
#include <array>
#include <cmath>
#include <cstdint>

#include "servoarm/hal/can_bus.hpp"
#include "servoarm/hal/canopen.hpp"
#include "servoarm/hal/cia402.hpp"
#include "servoarm/hal/clock.hpp"
#include "servoarm/hal/drive_group.hpp"
#include "servoarm/hal/scaling.hpp"
#include "servoarm/hal/sdo_client.hpp"
#include "servoarm/hal/servo_bus.hpp"

namespace servoarm::hal {

/// One object written at bring-up and read back (CanopenJointConfig::sdo_writes): `size`
/// bytes (1, 2, 4) of `value` (two's complement for a signed type), little-endian.
struct SdoWrite {
  std::uint16_t index = 0;
  std::uint8_t sub = 0;
  std::uint8_t size = 4;
  bool is_signed = false;  ///< for messages: the value shown as a signed number
  std::uint32_t value = 0;
};
inline constexpr std::size_t kMaxSdoWrites = 16;

struct CanopenJointConfig {
  std::uint8_t node_id = 0;
  JointScaling scaling{};
  Duration heartbeat_timeout = 0;  ///< 0 = use CanopenMasterConfig::heartbeat_timeout
  /// Quick-stop deceleration written to the drive's 6085h at bring-up, in drive
  /// acceleration units (counts/s^2, rounded, at most 2^32 - 1); 0 = leave the
  /// drive's own setting. The drive ramps down with it on the Quick Stop command
  /// (and on its 605Ah option code's terms).
  double quick_stop_decel = 0;
  /// How this joint establishes its zero (docs/servo-bus.md#homing); validated by the constructor.
  HomingSpec homing{};
  /// Motor rated torque in N m (motor side), the unit of 6071h/6077h/60B2h (per mille of it):
  /// 0 = read the drive's 6076h at bring-up (when a torque object is mapped).
  double rated_torque = 0;
  /// Digital outputs: map 60FEh:01 into RPDO3 (0x400 + node) and send
  /// ServoBus::set_digital_outputs' word with every write(); false = no RPDO3 (same frames).
  bool digital_outputs = false;
  /// Digital inputs: map 60FDh into TPDO3 (0x380 + node), sent at every SYNC, into
  /// JointFeedback::digital_inputs; false = no TPDO3 (same frames).
  bool digital_inputs = false;
  /// Objects written in this order at the end of the drive's bring-up (after the PDO maps and
  /// 6085h), each read back: a drive that refuses one (SDO abort) or reads back another value
  /// fails start() naming the node, the object and the abort code or both values.
  std::array<SdoWrite, kMaxSdoWrites> sdo_writes{};
  std::size_t sdo_write_count = 0;
};

/// How bring-up treats one feedback object of TPDO2.
enum class PdoUse : std::uint8_t {
  off,       ///< not mapped
  optional,  ///< mapped when the drive has it and can map it, left out otherwise
  required,  ///< bring-up fails, naming the object, when the drive lacks it or cannot map it
};
const char* to_string(PdoUse u);

/// The objects bring-up maps into TPDO2 (order in the frame: velocity, error code, torque).
struct FeedbackObjects {
  PdoUse velocity = PdoUse::optional;    ///< 606Ch velocity actual (INTEGER32, counts/s)
  PdoUse error_code = PdoUse::optional;  ///< 603Fh error code (UNSIGNED16)
  /// 6077h torque actual (INTEGER16, per mille of the rated torque 6076h, read at bring-up;
  /// JointFeedback::torque = it x 6076h x gear ratio x direction, joint side).
  PdoUse torque = PdoUse::off;
};

/// The command objects bring-up maps beyond RPDO1's. RPDO2 0x300+n carries, in this
/// order, velocity offset 60B1h (INTEGER32, counts/s), torque offset 60B2h (INTEGER16, per mille
/// of the rated torque) and target torque 6071h (INTEGER16, per mille): 8 bytes with all three.
/// Torque mode also appends modes of operation 6060h (INTEGER8) to RPDO1 (7 bytes) and modes of
/// operation display 6061h (INTEGER8) to TPDO1 (7 bytes), so that the mode changes at a SYNC,
/// within one cycle, and is checked at the next; 6502h must show CST (bit 9) where the drive has
/// 6502h. All off by default: the frames are those of before.
struct CommandObjects {
  PdoUse velocity_offset = PdoUse::off;  ///< 60B1h: ServoBus::set_feed_forward's velocity
  PdoUse torque_offset = PdoUse::off;    ///< 60B2h: ServoBus::set_feed_forward's torque
  PdoUse torque_mode = PdoUse::off;      ///< 6071h + 6060h + 6061h: ServoBus::set_torque_mode
};

struct CanopenMasterConfig {
  std::array<CanopenJointConfig, kMaxServoJoints> joints{};
  std::size_t joint_count = 0;
  Duration heartbeat_period = 50 * kMillisecond;    ///< written to each node's 0x1017
  Duration heartbeat_timeout = 150 * kMillisecond;  ///< consumer time (default per node)
  Duration sdo_timeout = 100 * kMillisecond;        ///< SDO answer timeout (bring-up and homing)
  /// Boot-up: a node that does not answer its first SDO (0x1000) is asked again (NMT
  /// pre-operational + SDO) every `boot_retry` until `boot_timeout` has passed since start();
  /// 0 = one attempt (a drive that is still booting is refused at once).
  Duration boot_timeout = 0;
  Duration boot_retry = 200 * kMillisecond;
  /// Read 6502h (supported drive modes) at bring-up for every joint and refuse a drive without
  /// CSP (bit 7). Off by default: then only joints with HomingKind::cia402 read it (and need
  /// bits 5 and 7), and a plain CSP bring-up sends the same frames as a master without homing.
  bool check_supported_modes = false;
  Duration state_timeout = 500 * kMillisecond;      ///< max time a drive may sit in one state while enabling
  /// Written to each drive's 60C2h interpolation time period at bring-up (sub 1 = value, sub 2 =
  /// index: value x 10^index s, e.g. 1 and -3 for 1 ms), so that its interpolator spans the SYNC
  /// period; 0 = not written. A drive without 60C2h (abort 06020000h / 06090011h) is brought up
  /// without it (it times the SYNC itself); any other refusal fails start() naming the node.
  Duration interpolation_period = 0;
  bool produce_sync = true;
  /// start() installs receive filters on the bus that pass only frames whose node part
  /// (id & 0x7F) is one of the configured nodes (EMCY, TPDOs, SDO answers, heartbeats):
  /// a flood of foreign frames then never reaches the cycle. Off by default because the
  /// bus may be shared (e.g. a console over ISO-TP on the same endpoint).
  bool set_bus_filters = false;
  /// TPDO2's feedback objects (see the top of this file).
  FeedbackObjects tpdo2{};
  /// Feed-forward and torque mode objects (RPDO2; see CommandObjects).
  CommandObjects rpdo2{};

  /// Convenience: nodes first..first+count-1 with the same scaling.
  static CanopenMasterConfig consecutive(std::uint8_t first, std::size_t count, const JointScaling& s = {});
};

// Process-data codecs for the mapping above. Real-time safe.
namespace pdo {
CanFrame encode_rpdo1(std::uint8_t node, std::uint16_t controlword, std::int32_t target);
bool decode_rpdo1(const CanFrame& f, std::uint16_t& controlword, std::int32_t& target);
CanFrame encode_tpdo1(std::uint8_t node, std::uint16_t statusword, std::int32_t position);
bool decode_tpdo1(const CanFrame& f, std::uint16_t& statusword, std::int32_t& position);
CanFrame encode_tpdo2(std::uint8_t node, std::int32_t velocity, std::uint16_t error_code);
bool decode_tpdo2(const CanFrame& f, std::int32_t& velocity, std::uint16_t& error_code);
}  // namespace pdo

class CanopenServoBus final : public DriveGroup {
 public:
  /// Set-up: validates the config (see config_status()); no I/O.
  CanopenServoBus(CanBus& bus, Clock& clock, const CanopenMasterConfig& cfg);

  /// invalid_argument (bad node id / scaling / duplicate node) or capacity; ok otherwise.
  Status config_status() const override { return config_status_; }
  const char* family() const override { return "cia402"; }
  /// Joint-side N m (N) of the rated torque (1000 x torque_unit(j)); 0 when no torque object is mapped.
  double rated_torque(std::size_t j) const override { return std::fabs(torque_unit(j)) * 1000.0; }
  /// "joint 1 (node 2)".
  void joint_name(std::size_t j, char* buf, std::size_t size) const override;
  /// The configuration as given (armfw maps its bus.* keys into it).
  const CanopenMasterConfig& config() const { return cfg_; }

  std::size_t joint_count() const override { return cfg_.joint_count; }
  void enable() override;
  void disable() override;
  void quick_stop() override;
  Status set_position_zero(std::size_t j) override;
  std::int64_t zero_offset(std::size_t j) const override {
    return j < cfg_.joint_count ? cfg_.joints[j].scaling.zero_offset : 0;
  }
  const JointFeedback& feedback(std::size_t j) const override { return fb_[j < cfg_.joint_count ? j : 0]; }
  const char* last_error() const override { return error_; }

  JointCapabilities capabilities(std::size_t j) const override;
  Status set_digital_outputs(std::size_t j, std::uint32_t value) override;
  std::uint32_t digital_outputs(std::size_t j) const override;
  Status set_target_torque(std::size_t j, double torque) override;
  CyclicModeState cyclic_mode(std::size_t j) const override {
    return j < cfg_.joint_count ? CyclicModeState{joints_[j].cmode, joints_[j].cstatus} : CyclicModeState{};
  }
  /// Real-time: the last RPDO2 values sent for joint j (tests/diagnostics): 60B1h counts/s,
  /// 60B2h and 6071h per mille.
  std::int32_t last_velocity_offset(std::size_t j) const { return joints_[j].sent_vel_off; }
  std::int16_t last_torque_offset(std::size_t j) const { return joints_[j].sent_tq_off; }
  std::int16_t last_target_torque(std::size_t j) const { return joints_[j].sent_tq_target; }
  /// Joint-side N m (N) per unit of 6071h/6077h/60B2h (0 when no torque object is mapped).
  double torque_unit(std::size_t j) const { return j < cfg_.joint_count ? joints_[j].torque_per_mille : 0; }

  /// Set-up/diagnostics: 6502h as read by start() (0 when the drive has none).
  std::uint32_t supported_modes(std::size_t j) const { return j < cfg_.joint_count ? joints_[j].modes : 0; }
  /// Name of a homing step (HomingProgress::step) for progress reports.
  static const char* homing_step_name(std::uint8_t step);

  /// Set-up helper: run read/write cycles with the current measured positions
  /// held, every `period`, until every joint is enabled (ok), a joint faults, or
  /// the deadline passes (drive_refused / the fault). Sleeps on the clock.
  Status enable_blocking(TimePoint deadline, Duration period);

  /// Set-up/diagnostics: send an NMT command to one configured node, or to all of them
  /// (node 0: one broadcast frame). A stop/reset makes the joints fault (protocol_error,
  /// seen in the next heartbeats); start() configures them again.
  /// @retval ok, invalid_argument (node not configured), bus errors from CanBus::send
  Status nmt(canopen::NmtCommand cmd, std::uint8_t node);

  /// Real-time: the last commanded position in counts for joint j (tests/diagnostics).
  std::int32_t last_target_counts(std::size_t j) const { return joints_[j].target_counts; }
  /// Frames received that no codec accepted (unknown ids, wrong lengths): robustness counter.
  std::uint64_t ignored_frames() const { return ignored_; }
  /// Joint j's scaling as the master uses it (zero offset included): what a simulator needs
  /// to turn the drive's counts into the joint (armfw --sim --plant dynamic).
  JointScaling scaling(std::size_t j) const override { return cfg_.joints[j < cfg_.joint_count ? j : 0].scaling; }
  /// Set-up/diagnostics: true when start() mapped `object` (0x606C, 0x603F, 0x6077) into
  /// joint j's TPDO2.
  bool maps(std::size_t j, std::uint16_t object) const;
  /// Set-up/diagnostics: device name read from 0x1008 during start() ("" if none).
  const char* device_name(std::size_t j) const { return joints_[j].name; }
  /// Set-up/diagnostics: describe joint j's fault in `buf` ("node 3: heartbeat_lost ...").
  void describe_fault(std::size_t j, char* buf, std::size_t size) const;

  /// Real-time: handle one received frame (read() calls this; exposed for SDO waits and tests).
  void dispatch(const CanFrame& f, TimePoint now);

 protected:
  const HomingSpec& homing_spec(std::size_t j) const override { return cfg_.joints[j < kMaxServoJoints ? j : 0].homing; }
  Status family_start(TimePoint deadline) override;
  Status family_read(TimePoint now) override;
  Status family_write(std::span<const double> setpoints, TimePoint now) override;
  /// CiA 402 homing (6060h = 6) with the drive's method.
  Status family_start_homing(std::size_t j, TimePoint now) override;
  void family_abort_homing(std::size_t j) override;
  HomingProgress family_homing(std::size_t j) const override;
  /// "joint 3 (node 3): homing timeout after 2000 ms waiting for homing attained (statusword
  /// 0x0637)"; "" when not failed.
  void family_describe_homing(std::size_t j, char* buf, std::size_t size) const override;
  Status family_set_feed_forward(std::size_t j, double velocity, double torque) override;
  Status family_set_torque_mode(std::size_t j, bool on) override;
  /// Moves JointScaling::zero_offset (nothing is written to the drive).
  double shift_zero(std::size_t j, double at, double reads) override;
  double resolution(std::size_t j) const override { return 1.0 / cfg_.joints[j < kMaxServoJoints ? j : 0].scaling.counts_per_si(); }
  void note_error(const char* text) override;

 private:
  struct Joint {
    std::uint8_t node = 0;
    cia402::State state = cia402::State::not_ready_to_switch_on;
    cia402::State refused_in = cia402::State::not_ready_to_switch_on;
    canopen::NmtState nmt = canopen::NmtState::boot_up;
    bool have_status = false;
    bool reset_phase = false;
    bool need_nmt_start = false;
    bool resetting = false;  ///< enable() is walking this drive out of fault
    /// A controlword that ends operation enabled (disable operation, quick stop, ...) went
    /// to this drive while its last statusword said operation enabled, and no statusword
    /// since has shown it leave. Until one does, "operation enabled" is the drive's state
    /// from before that command, not an answer to enable(): not reported as enabled.
    bool leaving_op = false;
    TimePoint state_since = 0;
    std::int32_t actual_counts = 0;
    std::int32_t target_counts = 0;
    Duration hb_timeout = 0;
    TimePoint hb_watch_since = 0;  ///< heartbeat consumer start (start(), enable() out of a fault)
    // TPDO2 layout as mapped by start(): frame length and byte offsets (-1 = not mapped).
    std::uint8_t tpdo2_len = 0;
    std::int8_t off_velocity = -1, off_error = -1, off_torque = -1;
    double torque_per_mille = 0;  ///< joint-side N m (N) per 6077h/60B2h/6071h unit
    // Issue 20: RPDO1/TPDO1 lengths (7 with 6060h/6061h), RPDO2 layout (-1 = not mapped).
    std::uint8_t rpdo1_len = 6, tpdo1_len = 6, rpdo2_len = 0;
    bool rpdo3 = false;             ///< 60FEh:01 mapped (digital outputs)
    bool tpdo3 = false;             ///< 60FDh mapped (digital inputs)
    std::uint32_t outputs = 0;      ///< the 60FEh:01 word sent
    std::int8_t off_vel_off = -1, off_tq_off = -1, off_tq_target = -1;
    bool torque_mode = false;       ///< CST usable on this joint
    std::int8_t mode_shown = 0;     ///< 6061h from TPDO1 (0 = not mapped / not seen)
    CyclicMode cmode = CyclicMode::position;
    Status cstatus = Status::ok;
    TimePoint cmode_since = 0;
    bool have_tq_target = false;
    bool ff_pending = false;        ///< set_feed_forward() since the last write()
    std::int32_t ff_vel = 0;        ///< counts/s
    std::int16_t ff_tq = 0, tq_target = 0;  ///< per mille
    std::int32_t sent_vel_off = 0;
    std::int16_t sent_tq_off = 0, sent_tq_target = 0;
    TimePoint prev_pos_time = 0;  ///< without 606Ch: the previous TPDO1's time and position
    std::int32_t prev_pos = 0;
    char name[32] = {};
    std::uint32_t modes = 0;  ///< 6502h (0 = not read)
    // Homing (real time).
    SdoTransfer sdo{};
    HomingPhase hphase = HomingPhase::idle;
    Status hstatus = Status::ok;   ///< the outcome reported once back in CSP
    std::uint8_t hstep = 0;        ///< HStep
    bool habort = false;           ///< abort_homing() asked
    bool hold_once = false;        ///< the write() after homing ended holds (old-coordinate setpoint)
    std::uint16_t cw_extra = 0;    ///< bits or-ed into the controlword (4: homing start, 8: halt)
    TimePoint hstarted = 0, hstep_since = 0;
    int tpdos = 0;                 ///< TPDO1 frames seen since the step began
    int writes = 0;                ///< write() cycles since the step began
    int retries = 0;
    double htravel = 0;            ///< counts moved since homing began (signed, the mark's jump excluded)
    std::int32_t hlast = 0;        ///< actual position (counts) when htravel was last updated
    TimePoint hlast_t = 0;         ///< ... and when it last changed
    bool hrebased = false;         ///< the drive's one coordinate change at the mark was seen
    char hmsg[192] = {};
  };
  struct MapEntry {
    std::uint16_t index;
    std::uint8_t bits;
    PdoUse use;
    const char* what;
    std::uint8_t sub = 0;
  };
  void set_fault(std::size_t j, Status why, TimePoint now);
  void advance_cyclic_mode(std::size_t j, TimePoint now);
  std::int8_t mode_to_send(std::size_t j) const;
  Status setup_node(std::size_t j, TimePoint deadline);
  Status sdo_write(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::uint8_t size, std::uint32_t value,
                   const char* what);
  /// 60C2h from cfg_.interpolation_period, then joint j's sdo_writes with their read-back.
  Status write_drive_objects(std::size_t j);
  /// Map `entries` into one PDO (comm 0x14xx/0x18xx, map 0x16xx/0x1Axx) and enable it with
  /// `cob` (left disabled when nothing was mapped); `mapped[k]` says which entries made it.
  Status map_pdo(std::size_t j, std::uint16_t comm, std::uint16_t map, std::uint32_t cob, const MapEntry* entries,
                 std::size_t count, bool* mapped, const char* pdo_name);
  static void sink(void* ctx, const CanFrame& f);
  Status validate_homing(std::size_t j);
  void advance_homing(std::size_t j, TimePoint now);
  /// Real-time: adds the actual position's change to the homing travel; true (message set)
  /// once it is beyond HomingSpec::max_travel.
  bool travel_exceeded(std::size_t j, TimePoint now);
  void homing_step(std::size_t j, std::uint8_t step, TimePoint now);
  void homing_fail(std::size_t j, Status why, TimePoint now);
  void homing_finish(std::size_t j, TimePoint now);
  std::int32_t home_offset_counts(std::size_t j) const;

  CanBus& bus_;
  Clock& clock_;
  CanopenMasterConfig cfg_;
  Status config_status_ = Status::ok;
  SdoClient sdo_;
  std::array<Joint, kMaxServoJoints> joints_{};
  std::array<JointFeedback, kMaxServoJoints> fb_{};
  std::array<std::int8_t, 128> joint_of_node_{};  // -1 = not ours
  cia402::Target target_ = cia402::Target::disabled;
  bool started_ = false;
  TimePoint boot_end_ = 0;  ///< start(): until when a silent node is asked again
  TimePoint last_sync_ = 0;  ///< when write() last sent the SYNC (the drives sample at it)
  std::uint64_t ignored_ = 0;
  char error_[192] = {};
};

}  // namespace servoarm::hal
