// SPDX-License-Identifier: Apache-2.0
#pragma once
// The motion executor: the one queue of segments the control thread runs (a joint plan, a
// blended joint run, a straight line, a path move, a dwell), with one start, one sample
// function, one hold, one resume (one re-plan rule) and one flush.
//
// Its state is the running segment's SegPhase (mode_table.hpp, with the hold and resume rules
// per phase); everything else here is data that phase refers to: the running item (the front
// of the queue), its clock, the blend queue of a blended joint run, the time base of a path
// run, the joint plan after a hold. The controller's Mode decides when the executor runs
// (moving, hold_line) and the executor tells it what follows (Step, HoldRule).
//
// A segment kind is one MotionItem payload (messages.hpp), one or more phases, one start case
// and one sample case. A streamed target (teleoperation) fits the same way: a payload whose
// target the console thread updates, a phase `stream` sampled by a bounded tracker toward the
// latest target, hold = ramp (as a plan), resume = nothing (it goes on tracking).
//
// Real-time: nothing here allocates, locks, throws or blocks; the console thread only pushes
// to the queue (SpscQueue: it is the producer, the executor the consumer).
#include <cstddef>
#include <cstdint>

#include "servoarm/rt/messages.hpp"
#include "servoarm/rt/mode_table.hpp"
#include "servoarm/rt/spsc_queue.hpp"
#include "servoarm/rt/time_scale.hpp"
#include "servoarm/kinematics/blend.hpp"
#include "servoarm/kinematics/blend_path.hpp"
#include "servoarm/kinematics/trajectory.hpp"

namespace servoarm::fw {

inline constexpr std::size_t kMotionQueue = 16;
static_assert(static_cast<int>(SegPhase::path_closed) == static_cast<int>(SegPhase::path_open) + 1 &&
                  static_cast<int>(SegPhase::path_overlap) == static_cast<int>(SegPhase::path_open) + 2,
              "MotionExecutor::path_run: the path run's phases are consecutive");

/// What the executor needs from its controller: whether the arm may start a move, the output
/// changes of a move that starts, and the end of every segment (done or refused: the events).
class SegmentHost {
 public:
  virtual bool may_move() const = 0;                     ///< every joint homed
  virtual void segment_started(const MotionItem& m) = 0;  ///< its M62 / M63 output changes
  virtual void segment_ended(std::uint32_t id, bool refused, RtResult why) = 0;

 protected:
  ~SegmentHost() = default;
};

class MotionExecutor {
 public:
  /// What the controller's mode does after a sample.
  enum class Step : std::uint8_t {
    running,  ///< a segment runs (or the next one started)
    idle,     ///< the last segment ended at rest and nothing is queued
    held,     ///< a hold on a line has come to rest on it
  };

  /// Set-up: `limits` outlives the executor.
  void configure(const kin::JointLimits& limits, int n_joints, double period_s, SegmentHost& host);

  SpscQueue<MotionItem, kMotionQueue>& queue() { return queue_; }
  const SpscQueue<MotionItem, kMotionQueue>& queue() const { return queue_; }
  SegPhase phase() const { return phase_; }
  const MotionItem* running() const { return running_; }

  /// Start the front of the queue from the commanded state `cmd` (at rest); the moves that
  /// cannot start are refused (segment_ended) in turn. False: nothing is queued.
  bool start(kin::JointState& cmd);
  /// One period of the running segment (moving, or hold_line slowing on its line): the new
  /// setpoint into `cmd`; a segment that ends is done and the next one starts. The one sample
  /// function: one case per kind of phase (inline: a joint plan's sample is the common cycle).
  Step step(Mode mode, kin::JointState& cmd) {
    // The period on the segment's time base: the speed scale's (a dwell's clock is real time).
    const double h = scale_.idle() ? period_s_ : scale_step(cmd);
    switch (phase_) {
      case SegPhase::none: return Step::idle;  // (not called without a segment)
      case SegPhase::plan:
      case SegPhase::path_to_end:
      case SegPhase::path_to_start:
        t_ += h;
        plan_->sample(t_, cmd);
        scaled(cmd);
        return t_ < plan_->duration ? Step::running : end_of_plan(cmd);
      case SegPhase::line:
      case SegPhase::path_line:
        // IK at the exact pose; when it fails the precomputed joint value of the path is kept
        // (the console checked the whole path with IK, and the controller checks the setpoint
        // as every other one), and the sample is counted (Telemetry::ik_fallbacks).
        t_ += h;
        if (line_->sample_ik(t_, cmd.pos, cmd.vel, cmd.acc) < kin::Status::ok) ++ik_fallbacks_;
        scaled(cmd);
        return t_ < line_->duration ? Step::running : end_of_line(mode, cmd);
      case SegPhase::blend_open:
      case SegPhase::blend_closed: return step_blend(cmd, h);
      case SegPhase::path_open:
      case SegPhase::path_closed:
      case SegPhase::path_overlap: return step_path(cmd, h);
      case SegPhase::dwell: t_ += period_s_; return step_dwell(cmd);
    }
    return Step::running;
  }
  /// Real-time: the speed scale's target (docs/safety.md#speed-scaling), in [TimeScale::kMin, 1];
  /// the scale ramps towards it from the next step on.
  void set_speed_target(double s) { scale_.set_target(s); }
  /// The speed scale of the last step (1: as planned).
  double speed_scale() const { return scale_.s; }
  /// The last step's scale would have fallen faster than the joints' acceleration limits allow.
  bool speed_scale_limited() const { return scale_.limited; }
  /// The scale back to 1 at once (the arm at rest: nothing to ramp).
  void reset_speed_scale() { scale_.reset(); }
  /// Feed hold of the running segment: its part (a line stops on its line, an overlapped
  /// path segment is done); the controller enters rule.mode (a ramp for hold_ramp).
  HoldRule hold();
  /// `resume` of the held segment from rest at `cmd`: false when it had to be planned again
  /// and could not (it is refused: plan_failed).
  bool resume(const kin::JointState& cmd);
  /// Drop every queued segment (the running one included): returns how many there were.
  std::size_t flush();

  // Telemetry
  std::uint32_t running_id() const { return running_ != nullptr ? running_->id : 0u; }
  /// The path run's time of the last sample (s), -1 when no path run is sampled.
  double path_time() const { return path_run() ? run_time() : -1.0; }
  /// The motion the newest sample of a path run belongs to (0: none).
  std::uint32_t path_id() const {
    if (!path_run()) return 0;
    return phase_ == SegPhase::path_overlap ? next_->id : running_->id;
  }
  std::uint64_t ik_fallbacks() const { return ik_fallbacks_; }
  std::uint64_t joint_replans() const { return joint_replans_; }
  std::uint64_t blended_corners() const { return blends_; }

 private:
  /// The start case of one segment kind: its phase set, or why it cannot start.
  RtResult open(MotionItem& m, kin::JointState& cmd);
  /// The one re-plan rule: a joint plan from rest at `from` to `target` at `override`.
  bool replan(const kin::JointVector& from, const kin::JointVector& target, double override,
              kin::JointTrajectory& out) const;
  /// The running segment has ended at rest at its goal (`at_goal`; a dwell stays where it is):
  /// done; the next one starts.
  Step finish(kin::JointState& cmd, bool at_goal);
  /// The running segment is refused (`why`): the next one starts.
  Step refuse(RtResult why, kin::JointState& cmd);
  /// Pop the running segment and report it (phase none, nothing running).
  void retire(bool refused, RtResult why);

  // The samplers, one per kind of phase (out of line: step() stays small enough to be inlined
  // into the controller's cycle, the joint plan's sample in it).
  [[gnu::noinline]] Step end_of_plan(kin::JointState& cmd);
  [[gnu::noinline]] Step end_of_line(Mode mode, kin::JointState& cmd);
  [[gnu::noinline]] Step step_blend(kin::JointState& cmd, double h);
  [[gnu::noinline]] Step step_path(kin::JointState& cmd, double h);
  /// The speed scale's step this period (its rate bounded by the joints' acceleration limits at
  /// the last setpoint `cmd`): the period on the segment's time base, period_s_ * s.
  [[gnu::noinline]] double scale_step(const kin::JointState& cmd);
  /// A sample of the segment's own trajectory (velocity and acceleration in its time) into real
  /// time: velocity q' s, acceleration q'' s^2 + q' ds/dt. Nothing when the scale is idle.
  void scaled(kin::JointState& cmd) const {
    if (scale_.s == 1.0 && scale_.rate == 0.0) return;
    cmd.acc = cmd.acc * (scale_.s * scale_.s) + cmd.vel * scale_.rate;
    cmd.vel *= scale_.s;
  }
  [[gnu::noinline]] Step step_dwell(kin::JointState& cmd);

  // Blended joint runs (docs/motion.md#blending)
  bool begin_blend(const JointMove& jm, const kin::JointState& cmd);
  void blend_more();
  // Path runs
  bool begin_path(MotionItem& m, const kin::JointState& cmd);
  /// Open the next path move when it blends out of the running one (phase path_open only).
  void path_look_ahead(const kin::PathSegment& g, double t, double tn);
  double run_time() const { return path_t0_ + static_cast<double>(path_k_) * period_s_ + path_lag_; }
  /// Phases path_open, path_closed, path_overlap (consecutive): sampled on the run's time base.
  bool path_run() const {
    return static_cast<unsigned>(phase_) - static_cast<unsigned>(SegPhase::path_open) <= 2u;
  }

  SpscQueue<MotionItem, kMotionQueue> queue_;
  const kin::JointLimits* limits_ = nullptr;
  SegmentHost* host_ = nullptr;
  int n_ = 0;
  double period_s_ = 0.001;

  SegPhase phase_ = SegPhase::none;  ///< the executor's state: nothing beside it
  MotionItem* running_ = nullptr;    ///< front of the queue while a segment runs (phase != none)
  MotionItem* next_ = nullptr;       ///< phase path_overlap: the path move superposed (second in the queue)
  double t_ = 0;                     ///< time into the running segment (plan, line, dwell, resume plan)
  const kin::JointTrajectory* plan_ = nullptr;  ///< what the plan / path_to_* phases sample
  kin::CartesianTrajectory* line_ = nullptr;    ///< what the line / path_line phases sample
  // Blended joint run (phases blend_*): the first blend_items_ motions of the queue (running_
  // the first) are the segments of blend_.
  static constexpr int kBlendSegments = 4;
  kin::JointBlendQueue<kBlendSegments> blend_;
  int blend_items_ = 0;
  double blend_t_ = 0;               ///< time on blend_'s time base (s)
  double blend_override_ = 1.0;
  // Path run (phases path_open / path_closed / path_overlap): the run's time is path_t0_ +
  // path_k_ / rate on the console's time base (integer steps: no drift), plus path_lag_, what
  // the speed scale has held it back (0 while it is idle).
  double path_t0_ = 0;
  std::int64_t path_k_ = 0;
  double path_lag_ = 0;
  double path_next_lag_ = 0;  ///< the lag the sample one period ahead was taken at (added next step)
  kin::JointVector path_ahead_;      ///< the sample one period ahead of the setpoint
  bool path_have_ahead_ = false;
  kin::JointTrajectory resume_plan_;  ///< phases path_to_end / path_to_start
  TimeScale scale_;                  ///< the speed scale (time_scale.hpp)
  std::uint64_t blends_ = 0;         ///< corners blended since boot
  std::uint64_t ik_fallbacks_ = 0;
  std::uint64_t joint_replans_ = 0;
};

}  // namespace servoarm::fw
