#pragma once
// The control cycle: state machine, safety supervisor and motion execution.
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
//   events    (RT -> console)  Event: faults, move finished/refused, state changes
//   telemetry (RT -> anyone)   Telemetry snapshot (seqlock), published every cycle
#include <array>
#include <atomic>
#include <cstdint>
#include <cstring>

#include "servoarm/rt/spsc_queue.hpp"
#include "servoarm/rt/stats.hpp"
#include "servoarm/hal/servo_bus.hpp"
#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/trajectory.hpp"
#include "servoarm/kinematics/trajectory_cartesian.hpp"

namespace servoarm::fw {

using hal::Duration;
using hal::TimePoint;

/// Arm state (the firmware's state machine).
enum class ArmState : std::uint8_t {
  boot,      ///< drives not started yet
  disabled,  ///< drives up, powered down; `enable` powers them
  enabling,  ///< drives walking to operation enabled
  idle,      ///< enabled, holding position, motion queue empty
  moving,    ///< executing the motion queue (also while a feed hold ramps down / is held)
  stopping,  ///< `stop` or `disable`: ramping down; then idle (or disabled)
  fault,     ///< supervisor fault: quick stop, then drives disabled; needs `reset` + `enable`
  estop,     ///< emergency stop: quick stop, then drives disabled; needs `reset` + `enable`
};
const char* to_string(ArmState s);

/// Why the supervisor faulted (one per cause; the joint is reported alongside).
enum class FaultCause : std::uint8_t {
  none,
  heartbeat_lost,     ///< no heartbeat within the consumer time
  drive_fault,        ///< drive reports fault (EMCY or statusword)
  drive_refused,      ///< drive did not reach operation enabled in time
  left_enabled,       ///< drive left operation enabled on its own
  emcy,               ///< EMCY frame received
  bus_off,            ///< CAN controller bus-off / bus write failed
  bus_error,          ///< other bus/servo error
  following_error,    ///< |commanded - actual| above the limit
  setpoint_nan,       ///< motion produced a non-finite setpoint
  setpoint_position,  ///< setpoint outside the joint position limits
  setpoint_velocity,  ///< setpoint step faster than the joint velocity limit
  feedback_invalid,   ///< no (or stale) position feedback from an enabled joint
};
const char* to_string(FaultCause c);

/// Result codes of requests and motions as seen by the console.
enum class RtResult : std::uint8_t {
  ok,
  bad_state,   ///< not allowed in the current state (message says which)
  fault,       ///< refused: arm in fault / e-stop (needs reset)
  busy,        ///< queue full
  start_moved, ///< a planned Cartesian move no longer starts where the arm is
  plan_failed, ///< the RT-side plan of a joint move failed
};
const char* to_string(RtResult r);

/// set_zero: `home zero`, the current joint positions become joint zero (ServoBus::set_position_zero);
/// only in the disabled state, and only when 0 lies within every joint's limits.
enum class RequestOp : std::uint8_t { enable, disable, stop, estop, reset, hold, resume, set_zero };
const char* to_string(RequestOp op);

struct Request {
  RequestOp op = RequestOp::stop;
  std::uint32_t seq = 0;
};

struct Reply {
  std::uint32_t seq = 0;
  RtResult result = RtResult::ok;
  char message[160] = {};
};

enum class MotionKind : std::uint8_t { joint, cartesian, dwell };
const char* to_string(MotionKind k);

/// One queued motion. Joint moves are planned on the RT thread when they start
/// (plan_movej from the actual state: ~us, bounded, heap-free); Cartesian moves
/// come planned (path checked) by the console thread from the queue's end pose.
struct MotionItem {
  MotionKind kind = MotionKind::joint;
  std::uint32_t id = 0;
  kin::JointVector goal;          ///< joint: target; cartesian: joint values at the end
  double override = 1.0;          ///< joint: speed override 0.01..1
  double dwell_s = 0.0;           ///< dwell: seconds
  kin::JointTrajectory jt;        ///< joint: filled by the RT thread at start
  kin::CartesianTrajectory ct;    ///< cartesian: planned by the console thread
};

enum class EventKind : std::uint8_t { fault, estop, motion_done, motion_refused, state };
const char* to_string(EventKind k);

struct Event {
  EventKind kind = EventKind::state;
  ArmState state = ArmState::boot;
  FaultCause cause = FaultCause::none;
  std::int8_t joint = -1;  ///< joint index (0-based) concerned, -1 = none/all
  std::uint32_t motion_id = 0;
  char message[120] = {};
};

struct Telemetry {
  ArmState state = ArmState::boot;
  bool holding = false;           ///< feed hold active (moving state, ramped down or ramping)
  int n = 0;
  std::array<double, kin::kMaxJoints> q_cmd{};  ///< last commanded (SI)
  std::array<double, kin::kMaxJoints> q_act{};  ///< last measured (SI)
  std::array<std::uint8_t, kin::kMaxJoints> joint_state{};  ///< hal::JointState
  std::uint32_t queued = 0;        ///< motions in the queue (including the running one)
  std::uint32_t running_id = 0;    ///< id of the running motion (0 = none)
  std::uint32_t done_id = 0;       ///< id of the last motion finished
  FaultCause cause = FaultCause::none;
  std::int8_t fault_joint = -1;
  char fault_text[120] = {};
  std::uint64_t cycles = 0;
  std::uint64_t overruns = 0;
  std::uint64_t generation = 0;    ///< bumps whenever the queue is flushed or the setpoint is re-taken from the drives
  StatSummary latency, compute;
  double max_following_error = 0;  ///< rad/m, since the last reset
  std::int64_t estop_latency_ns = -1;  ///< request seen -> quick stop first setpoint written
};

/// Seqlock: one writer (RT thread), any number of readers that retry.
template <typename T>
class Seqlock {
 public:
  void write(const T& v) {
    const std::uint32_t s = seq_.load(std::memory_order_relaxed);
    seq_.store(s + 1, std::memory_order_relaxed);
    std::atomic_thread_fence(std::memory_order_release);
    std::memcpy(static_cast<void*>(&data_), &v, sizeof(T));
    std::atomic_thread_fence(std::memory_order_release);
    seq_.store(s + 2, std::memory_order_release);
  }
  T read() const {
    T out;
    for (;;) {
      const std::uint32_t s0 = seq_.load(std::memory_order_acquire);
      if (s0 & 1u) continue;
      std::memcpy(static_cast<void*>(&out), &data_, sizeof(T));
      std::atomic_thread_fence(std::memory_order_acquire);
      if (seq_.load(std::memory_order_relaxed) == s0) return out;
    }
  }

 private:
  std::atomic<std::uint32_t> seq_{0};
  T data_{};
};

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
};

inline constexpr std::size_t kMotionQueue = 16;
inline constexpr std::size_t kRequestQueue = 16;
inline constexpr std::size_t kEventQueue = 64;

class Controller {
 public:
  /// Set-up: `chain` must outlive the controller.
  Controller(hal::ServoBus& bus, const kin::Chain& chain, const ControllerConfig& cfg);

  /// Set-up (blocking, on the calling thread): start the drives (bus.start) and
  /// take the first feedback. Returns the bus status; on error bus.last_error() says why.
  hal::Status boot(TimePoint now, TimePoint deadline);

  /// Real-time: one control cycle at time `now`.
  void cycle(TimePoint now);
  /// Real-time: the loop reports its timing here (added to the statistics); every missed
  /// deadline counts as one overrun.
  void record_timing(std::int64_t latency_ns, std::int64_t compute_ns, std::uint32_t missed_deadlines);

  // Queues (the console side is the producer of requests/motions and the consumer of replies/events).
  SpscQueue<Request, kRequestQueue>& requests() { return requests_; }
  SpscQueue<Reply, kRequestQueue>& replies() { return replies_; }
  SpscQueue<MotionItem, kMotionQueue>& motions() { return motions_; }
  SpscQueue<Event, kEventQueue>& events() { return events_; }
  Telemetry telemetry() const { return telemetry_.read(); }

  const kin::Chain& chain() const { return chain_; }
  const kin::JointLimits& limits() const { return limits_; }
  const ControllerConfig& config() const { return cfg_; }
  double period_s() const { return period_s_; }

  /// Events dropped because the event queue was full (counted, never silent).
  std::uint64_t events_dropped() const { return events_dropped_.load(std::memory_order_relaxed); }

 private:
  void handle_request(const Request& r, TimePoint now);
  void reply(std::uint32_t seq, RtResult res, const char* msg);
  void emit(EventKind k, FaultCause c, int joint, std::uint32_t id, const char* msg);
  void set_state(ArmState s);
  void supervise(TimePoint now);
  void raise_fault(FaultCause c, int joint, const char* detail);
  void begin_quick_stop();
  void begin_emergency_stop();      ///< e-stop / fault reaction: ramp or drive quick stop (cfg_)
  void step_drive_stop();
  bool start_next_motion();
  void step_motion();
  void finish_motion(bool refused, RtResult why);
  void validate_and_write(TimePoint now);
  void publish();
  void hold_measured();
  /// Drop every queued motion (the running one included), forget a feed hold, bump the
  /// generation. Returns how many were queued.
  std::size_t flush_motions();

  hal::ServoBus& bus_;
  const kin::Chain& chain_;
  ControllerConfig cfg_;
  kin::JointLimits limits_;
  int n_ = 0;
  double period_s_ = 0.001;

  SpscQueue<Request, kRequestQueue> requests_;
  SpscQueue<Reply, kRequestQueue> replies_;
  SpscQueue<MotionItem, kMotionQueue> motions_;
  SpscQueue<Event, kEventQueue> events_;
  Seqlock<Telemetry> telemetry_;
  std::atomic<std::uint64_t> events_dropped_{0};

  ArmState state_ = ArmState::boot;
  TimePoint now_ = 0;
  TimePoint state_since_ = 0;
  kin::JointState cmd_;             ///< commanded state (pos/vel/acc), SI
  kin::JointVector q_act_;
  kin::JointVector q_prev_;         ///< last setpoint written
  bool have_prev_ = false;
  kin::JointTrajectory stop_traj_;  ///< quick stop / stop / joint feed hold
  bool stop_active_ = false;
  bool drive_stop_ = false;         ///< the stop in progress is the drives' CiA 402 quick stop
  double stop_t_ = 0;
  MotionItem* running_ = nullptr;   ///< front of motions_ while executing
  double motion_t_ = 0;
  bool holding_ = false;            ///< feed hold requested (moving state)
  bool disable_after_stop_ = false;
  std::uint32_t done_id_ = 0;
  std::uint64_t generation_ = 0;
  FaultCause cause_ = FaultCause::none;
  int fault_joint_ = -1;
  char fault_text_[120] = {};
  std::array<std::uint32_t, kin::kMaxJoints> emcy_seen_{};
  double max_follow_ = 0;
  TimePoint estop_seen_ = -1;
  std::int64_t estop_latency_ = -1;

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
