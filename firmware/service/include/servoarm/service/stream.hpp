// SPDX-License-Identifier: Apache-2.0
#pragma once
// Streaming targets (servo mode) through the arm service: a client sends joint targets at any
// rate (10 to 1 000 Hz, irregularly spaced), latest wins, and the control thread tracks the
// newest one with a jerk-limited trajectory replanned from where the arm is (jog.hpp,
// JogSpec::stream): never above the joints' velocity, acceleration and jerk limits, a jump is a
// smooth move. No target within the deadman time: the arm brakes to rest on its limits and the
// stream ends with an event (jog_stopped, "stream stopped: ..."). A stop, hold, e-stop or fault
// from anywhere ends it too, and a stream once ended stays ended: the next target must say
// `start` (a client that keeps sending after someone stopped the arm does not move it again).
//
// A target carries its joint velocities, or they are estimated here from it and the target
// before (over the time between them: the client's times `t` below, else their arrival on the
// control thread's clock): the control thread tracks the target moving at them for up to twice
// that time (at most the deadman time), so the arm moves with a stream instead of stopping at
// each target. A velocity that would carry the target
// out of the joint limits or the safety envelope within that time is dropped.
//
// A target may carry its sampling time `t` on the client's clock (s, monotonic, any origin: only
// differences count). Targets with times are spaced by them instead of by their arrival: the
// velocity estimate divides by the client's interval, and the target is moved on by its velocity
// over its delivery delay, the time it arrived later than the stream's fastest delivery
// (arrival minus `t`, against the smallest of that seen since the stream started), so a target
// delayed on the way joins the path where the earlier one has got to instead of pulling it back.
// A timed target not newer than the stream's newest (out of order, or a duplicate) is dropped:
// nothing sent, counted in StreamStats::stale and said in its result. A time that is not finite
// or negative is refused (not_finite, out_of_range), and so is one that puts the client's clock
// more than kStreamClockAheadS ahead of the control thread's since the stream's fastest delivery
// (out_of_range: a clock that jumped forward would otherwise make every later target stale).
// `start` begins the stream's clock anew; a target without `t` is spaced by its arrival.
//
// Each target is checked here first: one value per joint, finite, within the joint limits
// (refused: limits), and at most its `max_step` from the target before it on every joint
// (clamped or refused, StreamSettings::clamp_step).
//
// Service thread (non-real-time); talks to the control thread through ArmService::request.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "servoarm/service/arm_service.hpp"

namespace servoarm::fw {

struct StreamSettings {
  double deadman_s = 0.1;   ///< no target this long: brake to rest, the stream ends
  /// Per joint (rad / m): the largest change from one target to the next; empty or <= 0: none.
  std::vector<double> max_step;
  bool clamp_step = true;   ///< a larger step: clamped to max_step (true) or refused (false)
  double speed_pct = 100;   ///< percent of the joints' velocity limits the tracking may use
};

/// How far (s) a target's time may run ahead of the control thread's clock, counted from the
/// stream's fastest delivery: beyond it the target is refused (out_of_range).
inline constexpr double kStreamClockAheadS = 1.0;

/// The running stream's counts since its `start` (service thread).
struct StreamStats {
  std::uint64_t targets = 0;  ///< targets sent to the control thread
  std::uint64_t timed = 0;    ///< of them, those with a client time
  std::uint64_t stale = 0;    ///< timed targets dropped: not newer than the newest (never sent)
  double late_s = 0;          ///< the newest timed target's delay beyond the fastest delivery (s)
  double late_max_s = 0;      ///< the largest late_s
  double jitter_s = 0;        ///< standard deviation of late_s over the timed targets (s)
};

struct StreamResult {
  CmdError error = CmdError::ok;
  std::string reason;      ///< one line: why refused
  bool clamped = false;    ///< the step was clamped to max_step
  bool stale = false;      ///< ok, but dropped: its time is not newer than the stream's newest
  StreamStats stats;       ///< the stream's counts after this target
  bool ok() const { return error == CmdError::ok; }
};

class StreamService {
 public:
  StreamService(ArmService& svc, Controller& ctl, const StreamSettings& cfg) : svc_(svc), ctl_(ctl), cfg_(cfg) {}
  /// The newest target (SI). `start`: begins a stream (from idle, or retargets the running one);
  /// without it the target continues the running stream and is refused (bad_state) when none
  /// runs (it was never started, or it ended: deadman, stop, fault).
  StreamResult target(const kin::JointVector& q, bool start) { return target(q, start, kin::JointVector()); }
  /// The same with the target's joint velocities `qd` (SI per s; empty: estimated from this
  /// target and the one before, by their arrival on the control thread's clock).
  StreamResult target(const kin::JointVector& q, bool start, const kin::JointVector& qd) {
    return joint_target(q, start, qd, std::nullopt, cfg_.clamp_step);
  }
  /// The same with the target's sampling time `t` on the client's clock (s; nullopt: none, spaced
  /// by its arrival). See the top of this file for what a time changes.
  StreamResult target(const kin::JointVector& q, bool start, const kin::JointVector& qd, std::optional<double> t) {
    return joint_target(q, start, qd, t, cfg_.clamp_step);
  }
  /// A Cartesian target: the active tool's pose in the base frame, or in the active user frame
  /// (`in_frame`), solved by the active tool's IK here on the service thread (nearest to the last
  /// target) and streamed as its joint target. Refused in one line, nothing sent, when a value is
  /// not finite (not_finite), the pose has no solution within the joint limits (unreachable), or
  /// its solution is more than max_step from the last target on a joint (out_of_range: never
  /// clamped, a clamped joint would be another pose); then the checks of target().
  /// `t`: the pose's sampling time, as for target().
  StreamResult target_pose(const kin::Pose& pose, bool in_frame, bool start, std::optional<double> t = std::nullopt);
  const StreamSettings& settings() const { return cfg_; }
  /// The stream's counts since its last `start` (what the state samples carry).
  const StreamStats& stats() const { return stats_; }

 private:
  StreamResult joint_target(const kin::JointVector& q, bool start, const kin::JointVector& qd, std::optional<double> t,
                            bool clamp_step);
  /// The stream runs (the last target was taken and no stop, deadman or fault ended it since).
  bool running(const Telemetry& t) const { return sent_ && (t.streaming || t.cycles <= sent_cycle_ + 1); }

  ArmService& svc_;
  Controller& ctl_;
  StreamSettings cfg_;
  kin::JointVector last_;        ///< the last target sent
  std::uint64_t sent_cycle_ = 0; ///< the control cycle the last target was accepted in
  double gap_avg_ = 0;           ///< the running average of the time between targets (s)
  double sent_t_ = 0;            ///< the control thread's clock (s) when the last target was sent
  bool sent_ = false;
  // the client's clock, since the stream's start
  bool clock_ = false;           ///< a timed target was sent in this stream
  bool last_timed_ = false;      ///< the last target sent had a time
  double t_newest_ = 0;          ///< the newest time sent (client clock, s)
  double offset_min_ = 0;        ///< the smallest arrival - t seen (s): the fastest delivery
  double late_mean_ = 0, late_m2_ = 0;  ///< running mean and sum of squares of late_s (Welford)
  StreamStats stats_;
};

}  // namespace servoarm::fw
