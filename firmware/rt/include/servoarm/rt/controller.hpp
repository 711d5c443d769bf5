// SPDX-License-Identifier: Apache-2.0
#pragma once
// The control cycle: state machine, safety supervisor and motion execution.
//
// State: one Mode (mode_table.hpp); requests are decided by its (mode x request)
// table; the console sees arm_state(mode) and holding(mode).
//
// Controller::cycle(now) is the whole per-period work of the real-time thread
// (DESIGN.md data flow): read drive feedback -> supervisor -> motion sample ->
// limit + NaN check -> write setpoints + SYNC -> publish telemetry. It never
// allocates, locks (except inside the in-process SimBus test backend), throws
// or blocks. Time is passed in, so tests drive it with a ManualClock and the
// RT loop (rt_loop.hpp) drives it with CLOCK_MONOTONIC.
//
// Everything the controller talks to the outside with is a lock-free SPSC
// queue or a seqlock snapshot:
//   requests  (console -> RT)  Request: enable, disable, stop, estop, reset, hold, resume
//   replies   (RT -> console)  Reply to each request, same sequence number
//   motions   (console -> RT)  MotionItem: joint move, planned Cartesian move, dwell;
//                              consumed in place (never copied on the RT side)
//   outputs   (console -> RT)  OutputChange: a digital output set at once (M64 / M65, `out`)
//   events    (RT -> console)  Event: faults, move finished/refused, state changes
//   telemetry (RT -> anyone)   Telemetry snapshot (seqlock), published every cycle
//   samples   (RT -> recorder) CycleSample of every cycle due, while a recorder asks for them
#include <array>
#include <atomic>
#include <cstdint>
#include <memory>

#include "servoarm/rt/executor.hpp"
#include "servoarm/rt/jog.hpp"
#include "servoarm/rt/messages.hpp"
#include "servoarm/rt/mode_table.hpp"
#include "servoarm/rt/model_control.hpp"
#include "servoarm/rt/safety_monitor.hpp"
#include "servoarm/rt/seqlock.hpp"
#include "servoarm/rt/spsc_queue.hpp"
#include "servoarm/rt/stats.hpp"
#include "servoarm/hal/safety_input.hpp"
#include "servoarm/hal/servo_bus.hpp"
#include "servoarm/kinematics/blend.hpp"
#include "servoarm/kinematics/blend_path.hpp"
#include "servoarm/kinematics/chain.hpp"

namespace servoarm::fw {

using hal::Duration;
using hal::TimePoint;

struct ControllerConfig {
  double rate_hz = 1000.0;
  double following_error = 0.1;        ///< rad (or m): supervisor limit per joint
  double enable_timeout = 2.0;         ///< s to reach operation enabled
  double feedback_timeout = 0.05;      ///< s without position feedback from an enabled drive -> fault
  double position_tolerance = 1e-6;    ///< rad: setpoint check slack on the position limits
  double velocity_margin = 1.10;       ///< setpoint step may reach this x max_velocity
  bool check_following_error = true;
  /// How e-stop and fault reactions stop a powered arm (normal `stop`, feed hold
  /// and `disable` always ramp in the controller):
  ///  - false (ramp): the controller ramps every joint to rest with the full
  ///    limits, then powers the drives down (category 1);
  ///  - true (drive): every drive gets the CiA 402 Quick Stop command
  ///    (controlword 0x0002) in the same cycle and stops on its own quick-stop
  ///    ramp (its 605Ah/6085h settings); the controller follows the measured
  ///    positions and powers the drives down once every drive reports rest
  ///    (or after drive_stop_timeout).
  bool drive_quick_stop = false;
  double drive_stop_timeout = 2.0;     ///< s: longest drive-side quick stop before power-down anyway
  /// Homing (RequestOp::home): the groups of joints homed together, in order (bit j = joint j);
  /// homing_groups == 0: one group of every joint.
  std::array<std::uint16_t, kin::kMaxJoints> homing_group_mask{};
  int homing_groups = 0;
  /// While a joint is not homed: joint jogs run at this fraction of the speed asked; tool jogs and
  /// every queued joint / Cartesian move are refused (RtResult::not_homed).
  double unhomed_jog_scale = 0.25;
  /// The safety envelope the monitor checks every cycle (docs/safety.md); disabled: none.
  kin::SafetyConfig safety{};
};

/// The safety inputs the cycle reads (docs/safety.md#safety-inputs), each with its active level:
/// the e-stop input makes the emergency stop, the Reduced input holds the envelope in Reduced
/// mode. An input that cannot be read counts as asserted. Asserting acts in the cycle it is read,
/// releasing once the input has read released for `debounce`.
struct SafetyInputs {
  hal::SafetyInput* estop = nullptr;    ///< none: no e-stop input
  bool estop_active_low = true;
  hal::SafetyInput* reduced = nullptr;  ///< none: no Reduced input
  bool reduced_active_low = true;
  hal::Duration debounce = 10 * hal::kMillisecond;
};

inline constexpr std::size_t kRequestQueue = 16;
inline constexpr std::size_t kEventQueue = 64;
inline constexpr std::size_t kOutputQueue = 16;

class Controller final : private SegmentHost {
 public:
  /// Set-up: `chain` must outlive the controller.
  Controller(hal::ServoBus& bus, const kin::Chain& chain, const ControllerConfig& cfg);

  /// Set-up (blocking, on the calling thread): start the drives (bus.start) and
  /// take the first feedback. Returns the bus status; on error bus.last_error() says why.
  hal::Status boot(TimePoint now, TimePoint deadline);

  /// Set-up (before the control thread runs): the dynamic model the cycle uses:
  /// feed-forward of every setpoint, collision detection in the supervisor, the freedrive mode.
  /// Configured (ModelControl::configure) on this controller's bus; outlives the controller.
  /// nullptr (the default): none of them.
  void set_model(ModelControl* m) { model_ = m; }
  /// Set-up / the console: the model (its refusals are fixed once configured); nullptr = none.
  const ModelControl* model() const { return model_; }
  /// Any thread: collision detection on / off at run time (ModelControl::set_collision_on, an
  /// atomic): false when there is no model or detection is not available (its refusal says why).
  bool set_collision_detection(bool on) { return model_ != nullptr && model_->set_collision_on(on); }

  /// Real-time: one control cycle at time `now`.
  void cycle(TimePoint now);
  /// Real-time: the loop reports its timing here (added to the statistics); every missed
  /// deadline counts as one overrun.
  void record_timing(std::int64_t latency_ns, std::int64_t compute_ns, std::uint32_t missed_deadlines);

  // Queues (the console side is the producer of requests/motions and the consumer of replies/events).
  SpscQueue<Request, kRequestQueue>& requests() { return requests_; }
  SpscQueue<Reply, kRequestQueue>& replies() { return replies_; }
  SpscQueue<MotionItem, kMotionQueue>& motions() { return exec_.queue(); }
  SpscQueue<Event, kEventQueue>& events() { return events_; }
  SpscQueue<OutputChange, kOutputQueue>& outputs() { return outputs_; }
  Telemetry telemetry() const { return telemetry_.read(); }

  const kin::Chain& chain() const { return chain_; }
  const kin::JointLimits& limits() const { return limits_; }
  const ControllerConfig& config() const { return cfg_; }
  double period_s() const { return period_s_; }

  /// Any thread: the safety envelope's mode (docs/safety.md); the monitor uses it from its next
  /// cycle. Lock-free (one atomic byte).
  void set_safety_mode(kin::SafetyMode m) { safety_mode_.store(static_cast<std::uint8_t>(m), std::memory_order_relaxed); }
  kin::SafetyMode safety_mode() const {
    return static_cast<kin::SafetyMode>(safety_mode_.load(std::memory_order_relaxed));
  }
  /// Console thread: the active tool for the safety monitor (docs/safety.md): its TCP in the
  /// flange frame (as ArmService's tools: TCP = FK(chain) * tool) and its sphere's radius (m).
  /// The monitor takes it in its next cycle. False when the queue is full (not taken).
  bool set_safety_tool(const kin::Pose& tool, double radius) {
    SafetyToolChange c;
    for (int i = 0; i < 16; ++i) c.m[static_cast<std::size_t>(i)] = tool.matrix().data()[i];
    c.radius = radius;
    return safety_tools_.push(c);
  }
  /// Set-up (before the control thread runs): the safety inputs; the inputs outlive the controller.
  void set_safety_inputs(const SafetyInputs& in) {
    estop_in_.configure(in.estop, in.estop_active_low, in.debounce);
    reduced_in_.configure(in.reduced, in.reduced_active_low, in.debounce);
  }
  /// Any thread: the Reduced input is asserted (or lost): the envelope runs in Reduced mode
  /// whatever set_safety_mode() said, and moves are planned so.
  bool reduced_by_input() const { return reduced_by_input_.load(std::memory_order_relaxed); }
  /// Console thread: a new safety envelope for the monitor (a confirmed run-time change of
  /// [safety]); the monitor takes it at its next cycle with the chain's own tool: send the active
  /// tool after it (set_safety_tool). False when the queue is full (not taken).
  bool set_safety_config(const kin::SafetyConfig& c) { return safety_configs_.push(c); }
  /// Real-time / tests: the safety monitor (its last commanded TCP sample).
  const SafetyMonitor& safety_monitor() const { return safety_; }

  /// Events dropped because the event queue was full (counted, never silent).
  std::uint64_t events_dropped() const { return events_dropped_.load(std::memory_order_relaxed); }

  /// Cycles the sample ring holds: at 1 kHz, a recorder may be kept off the CPU this many
  /// periods (about 2 s) and still write every cycle.
  static constexpr std::size_t kSampleRing = 2048;
  /// One consumer thread (a recorder): from the next cycle on, every cycle whose number is a
  /// multiple of `every` is copied into the sample ring by the control thread. The ring is
  /// allocated here the first time (never on the control thread) and kept until destruction;
  /// samples left from an earlier recording are dropped.
  void start_samples(std::uint64_t every);
  /// The consumer: no further samples are taken (those in the ring stay until popped).
  void stop_samples() { sampling_.store(false, std::memory_order_release); }
  /// The consumer: the oldest sample, false when none waits.
  bool pop_sample(CycleSample& out) { return samples_ != nullptr && samples_->pop(out); }
  /// Cycles due while the ring was full (not taken; counted, never silent), since construction.
  std::uint64_t samples_dropped() const { return samples_dropped_.load(std::memory_order_relaxed); }

 /// Real-time / tests: the mode right now (the RT thread's view; others read Telemetry::mode).
  Mode mode() const { return mode_; }
  /// Real-time / tests: the running segment's phase (the motion executor's state, mode_table.hpp).
  SegPhase segment_phase() const { return exec_.phase(); }

 private:
  void handle_request(const Request& r, TimePoint now);
  /// The safety inputs, read after the feedback: the e-stop input asserted makes the emergency
  /// stop in this cycle, the Reduced input sets reduced_by_input_; a change is an event naming
  /// the input.
  void watch_safety_inputs(TimePoint now);
  void run(Action a, const Request& r, TimePoint now);
  void reply(std::uint32_t seq, RtResult res, const char* msg);
  void emit(EventKind k, FaultCause c, int joint, std::uint32_t id, const char* msg);
  void set_mode(Mode m);
  void supervise(TimePoint now);
  /// Over-temperature warnings: one `warning` event when a joint's drive reports it at or
  /// above its warning temperature (again after it has cooled below).
  void watch_temperatures();
  /// fault / estop, and disabled after reset, with the drives holding the arm after a quick
  /// stop: powers down a hold that does not stay at rest (controller.cpp).
  void watch_hold();
  /// With drives that hold after a quick stop: this cycle's setpoint velocity and acceleration
  /// brake every joint on its acceleration limit through the torque feed-forward (controller.cpp).
  void brake_holding_drives();
  /// With drives that hold after a quick stop: power down each joint that is powered and not
  /// held at rest, that joint alone.
  void power_down_moving_holds();
  void raise_fault(FaultCause c, int joint, const char* detail);
  /// Start the controller's ramp to rest from the commanded state and enter `ramp` (a
  /// ramping mode); when no ramp can be planned (never seen) the arm is at rest at once.
  void begin_ramp(Mode ramp);
  /// The ramp of mode `ramp` is over: cmd at rest, enter where that ramp leads.
  void end_of_ramp(Mode ramp);
  /// Fault / e-stop reaction of a powered arm: the drives' quick stop (cfg_.drive_quick_stop)
  /// or the controller's ramp.
  void begin_emergency_stop(Mode ramp, Mode quick_stop);
  /// Power the drives down and enter `m` (disabled, fault, estop).
  void power_down(Mode m);
  void step_ramp();
  void step_drive_stop();
  void follow_measured();
  void step_jog();
  void step_motion();
  /// The safety envelope's monitor, after the motion's sample: a protective stop (ramp to rest
  /// on the limits, then idle holding) with an event naming the function and values.
  void step_safety();
  /// The speed scale's target from the monitor's speed ratio (and, outside a trigger zone, the
  /// Reduced mode's when the tool would reach a trigger plane before the scale could come down
  /// to it), for the executor or the jog, held at its lowest for kTargetHoldS. True when a
  /// speed function is beyond its limit and tolerance and the scale may not cure it (only
  /// within kScaleGrace of Reduced mode switched on, while the scale it needs is not below
  /// TimeScale::kMin): `v` names it, the caller stops.
  bool scale_speed(kin::SafetyViolation& v);
  /// The speed caps of the jog's plans from the monitor's last sample (SafetyMonitor::speed_cap).
  void update_jog_cap();
  /// The speed scale's aim: just below each limit (the scale lags a plan that speeds up by a cycle).
  static constexpr double kScaleAim = 0.995;
  // SegmentHost: the executor's calls
  bool may_move() const override;
  void segment_started(const MotionItem& m) override;
  void segment_ended(std::uint32_t id, bool refused, RtResult why) override;
  void validate_and_write(TimePoint now);
  void publish();
  void hold_measured();
  /// Drop every queued motion (the running one included), bump the generation.
  /// Returns how many were queued. The only flush.
  std::size_t flush_motions();

  // Actions of the request table (mode_table.hpp), one per Action value.
  void power_up(const Request& r);
  void disable_now(const Request& r);
  void set_zero(const Request& r);
  std::size_t begin_estop(TimePoint now);  ///< flush, note the time; returns how many were dropped
  void estop_done(const Request& r, std::size_t dropped);
  void reset_latched(const Request& r);
  void hold_motion(const Request& r);
  void resume_motion(const Request& r);
  void resume_held();  ///< a hold's ramp at rest with a resume sent during it (Mode::hold_ramp_resume)
  void start_homing(const Request& r);
  void start_freedrive(const Request& r);
  /// One cycle of the freedrive modes: the setpoint follows the measured pose, the model's
  /// torques; freedrive_end -> idle once every drive is back in CSP.
  void step_freedrive();

  // Homing (the homing modes' data: the groups, the one running, the joints the master moves)
  /// Bit j: joint j is homed (the bus says attained, or `home zero` set it this power cycle).
  std::uint16_t homed_mask() const;
  bool all_homed() const { return homed_mask() == all_joints(); }
  std::uint16_t all_joints() const { return static_cast<std::uint16_t>((1u << n_) - 1u); }
  /// Start group hgroup_i_: false when a drive refused (homing failed, arm disabled).
  bool start_homing_group();
  void step_homing();
  /// Abort every joint the master homes now (they stay unhomed); hrunning_ is kept (homing_abort waits for them).
  void abort_running_homing();
  /// Joint j's homing failed: the arm is disabled, the cause (`why`, or ServoBus::describe_homing) latched.
  void homing_failed(int j, const char* why);
  /// "joints 2, 3" of `mask` into buf.
  static void joints_text(char* buf, std::size_t cap, std::uint16_t mask);

  hal::ServoBus& bus_;
  const kin::Chain& chain_;
  ModelControl* model_ = nullptr;   ///< the dynamic model, or none
  ControllerConfig cfg_;
  kin::JointLimits limits_;
  int n_ = 0;
  double period_s_ = 0.001;

  SpscQueue<Request, kRequestQueue> requests_;
  SpscQueue<Reply, kRequestQueue> replies_;
  MotionExecutor exec_;             ///< the motion queue and the running segment (its phase)
  SpscQueue<Event, kEventQueue> events_;
  SpscQueue<OutputChange, kOutputQueue> outputs_;
  std::array<std::uint32_t, kin::kMaxJoints> out_words_{};  ///< digital outputs sent (60FEh:01 per joint)
  void apply_output(const OutputChange& c);
  Seqlock<Telemetry> telemetry_;
  std::atomic<std::uint64_t> events_dropped_{0};
  void take_sample(const Telemetry& t);
  std::unique_ptr<SpscQueue<CycleSample, kSampleRing>> samples_;  ///< allocated by start_samples()
  std::atomic<bool> sampling_{false};
  std::atomic<std::uint64_t> sample_every_{1};
  std::atomic<std::uint64_t> samples_dropped_{0};

  Mode mode_ = Mode::boot;          ///< the arm's state: nothing beside it
  TimePoint now_ = 0;
  TimePoint mode_since_ = 0;
  kin::JointState cmd_;             ///< commanded state (pos/vel/acc), SI
  kin::JointVector q_act_;
  kin::JointVector q_prev_;         ///< last setpoint written
  bool have_prev_ = false;
  Jogger jog_;                      ///< data of the jogging mode
  kin::JointTrajectory stop_traj_;  ///< data of the ramping modes (ramping(mode_))
  double stop_t_ = 0;               ///< time into stop_traj_, or into the drives' quick stop
  std::array<std::uint16_t, kin::kMaxJoints> hgroups_{};
  int hgroup_n_ = 0, hgroup_i_ = 0;
  std::uint16_t hrunning_ = 0;      ///< joints the master moves now (homing / homing_abort): their setpoints follow
  std::uint16_t zeroed_ = 0;        ///< joints whose zero `home zero` set this power cycle
  std::uint32_t done_id_ = 0;
  std::uint64_t generation_ = 0;
  FaultCause cause_ = FaultCause::none;
  int fault_joint_ = -1;
  char fault_text_[120] = {};
  std::array<std::uint32_t, kin::kMaxJoints> emcy_seen_{};
  std::uint16_t hot_ = 0;  ///< joints warned of as hot (watch_temperatures)
  double max_follow_ = 0;
  TimePoint estop_seen_ = -1;
  SafetyMonitor safety_;
  struct SafetyToolChange {
    std::array<double, 16> m{};  ///< the tool's 4x4 matrix, column-major
    double radius = 0;
  };
  SpscQueue<SafetyToolChange, 8> safety_tools_;  ///< set_safety_tool -> the monitor
  std::atomic<std::uint8_t> safety_mode_{0};  ///< kin::SafetyMode
  SpscQueue<kin::SafetyConfig, 2> safety_configs_;  ///< set_safety_config -> the monitor
  kin::SafetyConfig safety_next_{};                 ///< (the cycle's copy of one taken from it)
  std::uint32_t safety_stops_ = 0;
  int speed_over_cycles_ = 0;  ///< cycles in a row a scaled speed has been beyond its limit and tolerance
  double target_hold_ = 1.0;              ///< the lowest speed scale target of the last kTargetHoldS
  std::int64_t target_hold_since_ = 0;    ///< the cycle it was set in
  kin::SafetyViolation over_last_{};  ///< the speed function beyond in the last of them
  kin::SafetyMode last_op_ = kin::SafetyMode::normal;  ///< safety_mode() at the last step_safety
  std::int64_t reduced_since_ = -1000000000;  ///< cycles_ when Reduced mode was switched on last
  std::int64_t estop_latency_ = -1;
  hal::InputWatch estop_in_, reduced_in_;
  std::atomic<bool> reduced_by_input_{false};
  const char* estop_why_ = nullptr;  ///< the event's text of an e-stop made by the e-stop input

  // Replies are committed after the cycle's telemetry is published, so a
  // console that sees a reply also sees the state it produced.
  std::array<Reply, 4> pending_replies_{};
  int n_pending_ = 0;
  void flush_replies();

  CycleStat latency_, compute_;
  StatSummary latency_sum_, compute_sum_;
  std::uint64_t cycles_ = 0, overruns_ = 0;
};

}  // namespace servoarm::fw
