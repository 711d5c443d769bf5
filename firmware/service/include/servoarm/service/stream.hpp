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
// before (over the time between them, by the control thread's clock): the control thread tracks
// the target moving at them for up to twice that time (at most the deadman time), so the arm
// moves with a stream instead of stopping at each target. A velocity that would carry the target
// out of the joint limits or the safety envelope within that time is dropped.
//
// Each target is checked here first: one value per joint, finite, within the joint limits
// (refused: limits), and at most its `max_step` from the target before it on every joint
// (clamped or refused, StreamSettings::clamp_step).
//
// Service thread (non-real-time); talks to the control thread through ArmService::request.
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

struct StreamResult {
  CmdError error = CmdError::ok;
  std::string reason;      ///< one line: why refused
  bool clamped = false;    ///< the step was clamped to max_step
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
  /// target and the one before, by the control thread's clock).
  StreamResult target(const kin::JointVector& q, bool start, const kin::JointVector& qd) { return joint_target(q, start, qd, cfg_.clamp_step); }
  /// A Cartesian target: the active tool's pose in the base frame, or in the active user frame
  /// (`in_frame`), solved by the active tool's IK here on the service thread (nearest to the last
  /// target) and streamed as its joint target. Refused in one line, nothing sent, when a value is
  /// not finite (not_finite), the pose has no solution within the joint limits (unreachable), or
  /// its solution is more than max_step from the last target on a joint (out_of_range: never
  /// clamped, a clamped joint would be another pose); then the checks of target().
  StreamResult target_pose(const kin::Pose& pose, bool in_frame, bool start);
  const StreamSettings& settings() const { return cfg_; }

 private:
  StreamResult joint_target(const kin::JointVector& q, bool start, const kin::JointVector& qd, bool clamp_step);
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
};

}  // namespace servoarm::fw
