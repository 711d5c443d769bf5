// SPDX-License-Identifier: Apache-2.0
#pragma once
// The dynamic model in the control cycle (docs/dynamics.md#using-the-model-in-the-firmware):
// feed-forward of every setpoint (60B1h velocity / 60B2h torque offsets in CSP), hand guiding
// (free-drive: CST with gravity + friction compensation and a virtual damping) and collision
// detection (kin::CollisionObserver on the drives' measured torque 6077h).
//
// A plain class the controller holds (by pointer: App owns it, configures it after the drives
// are up, the controller calls it from its cycle). Set-up: configure() decides, per part, whether
// it can run on this robot and these drives, and says why not in one line naming the joint or the
// model (refusal()). Real time (the control thread): feed_forward(), observe(), freedrive_enter(),
// freedrive_step(), freedrive_leave(): heap-free, lock-free, no exceptions, bounded loops
// (fixed-size Eigen, kin:: functions that never allocate). set_feed_forward_on() and
// set_collision_on() may be called from any thread (atomics); the rest only from the control
// thread once configured.
//
// Where the controller calls it (cycle order):
//   read() -> observe(watch, dt, verdict)   in the supervisor; on verdict.collision: stop the arm,
//                                           FaultCause::collision, describe_collision() as detail
//   step_motion() -> feed_forward(cmd)      before validate_and_write() (bus.write())
//   free-drive mode: freedrive_enter() on the request, freedrive_step() every cycle after read(),
//                    freedrive_leave() on off / any stop / fault / disable; the mode ends when
//                    freedrive_step() returns FreedrivePhase::off (every joint back in CSP holding
//                    where it stood: restart the setpoint from the measured position).
#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>

#include "servoarm/hal/servo_bus.hpp"
#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/collision.hpp"
#include "servoarm/kinematics/trajectory.hpp"

namespace servoarm::fw {

/// What feed-forward sends with each CSP setpoint (dynamics.feed_forward).
enum class FeedForwardKind : std::uint8_t {
  off,       ///< nothing (the frames of before)
  velocity,  ///< the setpoint's velocity as 60B1h (needs no model)
  torque,    ///< 60B1h and the model torque M(q) qdd + c + g + friction as 60B2h (inertial data)
};
const char* to_string(FeedForwardKind k);

/// The three parts, for refusal() / available().
enum class ModelPart : std::uint8_t { feed_forward, collision, freedrive };
inline constexpr int kModelParts = 3;
const char* to_string(ModelPart p);

/// Where free-drive stands (freedrive_step()).
enum class FreedrivePhase : std::uint8_t {
  off,       ///< not in free-drive: every joint in CSP
  entering,  ///< torque mode asked, not every drive shows it yet
  active,    ///< every joint in CST, commanded gravity + friction - damping
  leaving,   ///< back to CSP asked (off, a stop, a fault, or a joint that left by itself)
};
const char* to_string(FreedrivePhase p);

struct ModelControlConfig {
  FeedForwardKind feed_forward = FeedForwardKind::off;
  bool collision = false;                   ///< collision detection asked for (dynamics.collision)
  bool freedrive = false;                   ///< free-drive asked for (dynamics.freedrive): configure()'s
                                            ///< result includes it; `freedrive on` works whenever available
  double collision_gain = 100.0;            ///< K, 1/s
  double collision_sensitivity = 1.0;       ///< thresholds / sensitivity
  /// Per joint, N m (N) joint side; 0 = collision_threshold_pct of rated_torque[j].
  std::array<double, kin::kMaxJoints> collision_threshold{};
  double collision_threshold_pct = 15.0;    ///< % of rated_torque[j] (joint side) where no threshold is given
  /// Per joint, N m (N) joint side (CANopen: 1000 x CanopenServoBus::torque_unit(j)); 0 = unknown.
  std::array<double, kin::kMaxJoints> rated_torque{};
  double freedrive_damping = 10.0;          ///< 1/s: joint j's damping is this x its largest M_jj
};

struct ModelControlStats {
  std::uint64_t ff_cycles = 0;        ///< cycles feed-forward was given to the bus
  std::uint64_t ff_errors = 0;        ///< cycles the model or the bus refused it (NaN, beyond 60B2h's range)
  std::uint64_t observer_samples = 0; ///< observer updates since configure()
  std::uint64_t collisions = 0;       ///< verdicts (collision) since configure()
  double peak_ratio = 0;              ///< largest |r_j| / threshold_j seen (sensitivity applied)
  int peak_joint = -1;                ///< its joint (0-based)
  double last_ratio = 0;              ///< largest |r_j| / threshold_j of the last sample
  std::uint64_t freedrive_entries = 0;
  std::uint64_t freedrive_lost = 0;   ///< free-drives ended by a joint leaving torque mode by itself
};

class ModelControl {
 public:
  static constexpr std::size_t kLine = 200;

  /// Set-up, after the drives are started (capabilities are those brought up). `chain` and `bus`
  /// must outlive the object. Each part asked for that cannot run is refused with one line
  /// (refusal()) and stays off; the others work. Free-drive is available whenever every joint has
  /// torque mode and the model inertial data. Returns true when every part `cfg` asks for
  /// (feed_forward != off, collision, freedrive) is available.
  bool configure(const kin::Chain& chain, hal::ServoBus& bus, const ModelControlConfig& cfg);
  bool configured() const { return chain_ != nullptr; }
  const ModelControlConfig& config() const { return cfg_; }

  /// Whether part `p` can run ("" refusal), and why not: one line naming the model ("robot
  /// 'stanford' has no inertial data ...") or the joint ("joint 2: the drive reports no torque
  /// (6077h not mapped into TPDO2): collision detection needs it").
  bool available(ModelPart p) const { return refusal_[static_cast<int>(p)][0] == '\0' && configured(); }
  const char* refusal(ModelPart p) const { return refusal_[static_cast<int>(p)]; }
  /// The refusals of the parts `cfg` asked for, one per line ("" when none): what armfw says at start.
  const char* start_notes() const { return notes_; }

  // --- run-time switches (any thread) ---------------------------------------------------
  /// Feed-forward / collision detection on or off; on is refused (false) when not available.
  /// configure() switches on what the configuration asks for and is available.
  bool set_feed_forward_on(bool on);
  bool set_collision_on(bool on);
  bool feed_forward_on() const { return ff_on_.load(std::memory_order_relaxed); }
  bool collision_on() const { return coll_on_.load(std::memory_order_relaxed); }
  FeedForwardKind feed_forward_kind() const { return cfg_.feed_forward; }

  // --- real time (control thread) ---------------------------------------------------------
  /// Feed-forward of the commanded state `cmd` (after the motion step, before bus.write()):
  /// per joint bus.set_feed_forward(). Nothing when off, not available, or in free-drive.
  void feed_forward(const kin::JointState& cmd);
  /// One observer sample from the bus feedback (after bus.read()). The time step is the interval
  /// between the feedback's sample times (JointFeedback::sampled: the SYNCs it answers), so a late
  /// cycle or a stall does not count as one period; feedback already used (no new sample) adds
  /// nothing. `dt`, s, is the step only where the bus reports no sample times.
  /// `watch` false (modes where the controller does not watch: not powered, homing, stopping...)
  /// and a joint not enabled, homing or without torque feedback, free-drive, or detection off:
  /// the observer is reset (it starts again, residual 0, at the next watched sample).
  /// Returns verdict.collision.
  bool observe(bool watch, double dt, kin::CollisionVerdict& verdict);
  /// "residual -31.2 N m beyond the threshold 6.65 N m" (N for a prismatic joint) into buf.
  void describe_collision(const kin::CollisionVerdict& v, char* buf, std::size_t size) const;
  const kin::JointVector& residual() const { return observer_.residual(); }
  /// Joint j's threshold as checked (sensitivity applied), N m (N); 0 = none.
  double threshold(int j) const;

  /// Free-drive on: every joint's target torque from the measured state, then torque mode.
  /// @retval ok (also when already in free-drive); not_supported (not available: refusal());
  ///         bad_state (a joint not enabled, homing, or not in position mode: last_error() names it);
  ///         invalid_argument (the model's torque beyond a drive's 6071h range). Nothing changed
  ///         unless ok.
  hal::Status freedrive_enter();
  /// Every cycle after bus.read() while not off: the target torques from the measured state; a
  /// joint that left torque mode by itself (fault, heartbeat loss, disable, quick stop, refused)
  /// takes every joint back to CSP (leaving; last_error() says which and why). Returns the phase
  /// after this step: off once every joint is in CSP again.
  FreedrivePhase freedrive_step();
  /// Back to CSP holding where each joint stands (from the next write()). No-op when off. The
  /// phase becomes off once every drive shows CSP (freedrive_step(), or feed_forward() / observe()
  /// of a later cycle).
  void freedrive_leave();
  FreedrivePhase freedrive_phase() const { return phase_; }
  /// Joint j's free-drive damping, N m s/rad (N s/m).
  double damping(int j) const { return damping_[j]; }

  const ModelControlStats& stats() const { return stats_; }
  void reset_peak() { stats_.peak_ratio = 0, stats_.peak_joint = -1; }
  /// The last RT refusal or loss (free-drive), "" when none.
  const char* last_error() const { return error_; }
  /// One line for `status`: "feed-forward torque on, collision on (peak |r|/threshold 0.12 joint 2),
  /// free-drive off" / "... collision refused: <why>".
  void describe(char* buf, std::size_t size) const;

 private:
  bool measured(kin::JointVector& q, kin::JointVector& qd, kin::JointVector* tau) const;
  /// leaving -> off once every joint shows CSP again (also when freedrive_step() is no longer
  /// called: the controller left free-drive for a fault reaction).
  void settle_leaving();
  void refuse(ModelPart p, const char* fmt, ...) __attribute__((format(printf, 3, 4)));

  const kin::Chain* chain_ = nullptr;
  hal::ServoBus* bus_ = nullptr;
  ModelControlConfig cfg_{};
  int n_ = 0;
  char refusal_[kModelParts][kLine] = {};
  char notes_[kModelParts * (kLine + 1)] = {};
  char error_[kLine] = {};
  std::atomic<bool> ff_on_{false};
  std::atomic<bool> coll_on_{false};
  kin::CollisionObserver observer_;
  std::array<double, kin::kMaxJoints> thr_{};  ///< sensitivity applied
  bool watching_ = false;
  hal::TimePoint sampled_ = 0;  ///< sample time of the feedback of the last update (0 = none)
  kin::FeedForward ff_;
  kin::JointVector q_, qd_, tau_, damping_vec_;
  kin::JointVector fd_damping_;  ///< free-drive's: damping_vec_, 0 where the drive damps itself (torque_mode_damping)
  std::array<double, kin::kMaxJoints> damping_{};
  FreedrivePhase phase_ = FreedrivePhase::off;
  ModelControlStats stats_{};
};

}  // namespace servoarm::fw
