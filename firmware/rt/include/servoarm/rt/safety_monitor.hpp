// SPDX-License-Identifier: Apache-2.0
#pragma once
// The safety envelope's run-time monitor (docs/safety.md): every control cycle, the commanded
// and the measured TCP (and elbow) against the planes, boxes, orientation cone and speed
// limits (TCP, elbow, each joint's) of kin::SafetyConfig, and the stop predicted from the
// commanded state (its duration and the TCP's travel) against the stop time and distance limits,
// and the arm's momentum and power (inverse dynamics at the commanded state) against theirs, with the functions' tolerances; and, while jogging, the
// predicted stop (the ramp the controller would brake with now) against the planes and boxes,
// so that a jog towards a plane comes to rest at it and a jog away from it is let go.
//
// Real-time: update() and predict_stop() are heap-free, lock-free and throw nothing
// (fixed-size Eigen, the kinematics core's FK and plan_stop); configure() is set-up code.
#include <cstdint>

#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/safety.hpp"
#include "servoarm/kinematics/trajectory.hpp"
#include "servoarm/rt/time_scale.hpp"

namespace servoarm::fw {

class SafetyMonitor {
 public:
  /// Set-up: the monitor keeps a copy of `chain` (its tool becomes the active tool's);
  /// `period_s` is the control period.
  void configure(const kin::Chain& chain, const kin::SafetyConfig& cfg, double period_s);
  /// Real-time: the active tool, its TCP in the chain's tool frame (TCP = FK(chain) * tool) and
  /// its sphere's radius (m); the next update() checks that sphere and computes no speed.
  void set_tool(const kin::Pose& tool, double radius);
  bool enabled() const { return cfg_.enabled; }
  const kin::SafetyConfig& config() const { return cfg_; }

  /// Forget the previous samples (the next update() computes no speed): after a power-up, a
  /// free-drive, anything that moved the arm without the commanded path.
  void reset() { have_prev_ = false; }

  /// One cycle: the commanded and measured joints, in `mode` or Reduced while the commanded
  /// tool sphere reaches beyond a trigger plane (zone()). True when a function is beyond its limit
  /// by more than its tolerance on either, `out` naming it and `on_actual` which one.
  /// `only_growing` (a jog): a function already beyond is reported only while its excess grows
  /// on the commanded state (so that a jog may move back in). `speeds_scaled`: the motion runs
  /// on the speed scale, so a speed function (kin::is_speed) beyond its limit on the commanded
  /// state is not reported here but kept (speed_over()) for the caller to judge, and the
  /// measured state is still checked.
  bool update(const kin::JointVector& q_cmd, const kin::JointVector& q_act, kin::SafetyMode mode, bool only_growing,
              kin::SafetyViolation& out, bool& on_actual, bool speeds_scaled = false);

  /// While jogging: the commanded state `cmd` braked to rest now with `limits` (the
  /// controller's ramp) ends outside a plane or box, further out than `cmd` itself is (a jog
  /// towards it, not one moving back in): true, `out` naming it at the stop point.
  bool predict_stop(const kin::JointLimits& limits, const kin::JointState& cmd, kin::SafetyMode mode,
                    kin::SafetyViolation& out);

  /// After update(), while the arm moves: the stop predicted from the commanded state `cmd`
  /// braked with `limits` (the controller's ramp) takes longer than the mode's stop time limit,
  /// or moves the TCP further than its stop distance limit, or the arm's momentum or power at
  /// `cmd` is above the mode's limit, beyond the tolerances: true, `out` naming it. Nothing is
  /// computed for the limits the mode does not set.
  /// `speeds_scaled` (the motion runs on the speed scale): their ratios to the limits join
  /// speed_ratio() (kin::speed_ratio), so the scale keeps them as it keeps the speeds; the stop
  /// time and distance are checked as predicted one cycle on (their growth over the last cycle
  /// added, the event showing the value predicted now), still a protective stop in this cycle
  /// (the stop is the ramp predicted); momentum and power beyond their limits are not reported
  /// here but kept (speed_over()) for the caller to judge, as the speeds are. Outside a trigger
  /// zone in Normal mode the Reduced stop and dynamics ratios are kept for time_to_trigger().
  bool check_state(const kin::JointLimits& limits, const kin::JointState& cmd, kin::SafetyMode mode,
                  kin::SafetyViolation& out, bool speeds_scaled = false);

  /// After update(): the commanded state's highest value / limit of the mode's TCP, elbow and
  /// joint speed limits (kin::speed_ratio), 0 without a speed; after check_state() with
  /// speeds_scaled, its stop and dynamics ratios too.
  double speed_ratio() const { return ratio_; }
  /// After update() and check_state() with speeds_scaled: a speed function beyond its limit and
  /// tolerance on the commanded state (true, `out` naming the first one found).
  bool speed_over(kin::SafetyViolation& out) const {
    if (!speed_over_) return false;
    out = speed_v_;
    return true;
  }
  /// After update(), outside every trigger zone: how long (s) the commanded tool sphere, moving
  /// on at `per_scale` times its present velocity, takes to reach the nearest trigger plane it
  /// moves towards (INFINITY: none), and the Reduced mode's speed ratio at the commanded state
  /// (its TCP, elbow and joint speeds; after check_state() with speeds_scaled, its stop and
  /// dynamics limits too) into `reduced_ratio`.
  double time_to_trigger(double per_scale, double& reduced_ratio) const;

  /// After update(): the speed caps for a jog's or stream's plans at the commanded pose
  /// (docs/safety.md#speed-scaling): the TCP and joint speed limits of `mode` (Reduced in a
  /// trigger zone) times `aim`, and the TCP's speed per unit speed of each joint there (the
  /// linear Jacobian's columns; computed only when a TCP limit is set). Outside a trigger zone,
  /// in Normal mode, the Reduced limits times max(1, g / (horizon_s v)) cap them too, with g the
  /// tool sphere's distance to the nearest trigger plane and v the Reduced TCP speed limit
  /// (kCapSpeed without one): a plan started near a trigger plane is slow enough that the speed
  /// scale can bring it to the Reduced limits before it gets there (in any direction: the plan's
  /// is not known yet). Nothing capped when the envelope is off.
  void speed_cap(kin::SafetyMode mode, double aim, double horizon_s, SpeedCap& out) const;
  /// The stop limits the speed scale aims at, as a fraction of their value: the scale's ramp
  /// lags a motion that still speeds up, and the predicted stop grows meanwhile
  /// (docs/safety.md#speed-scaling).
  static constexpr double kStopAim = 0.85;
  static constexpr double kCapSpeed = 0.25;  ///< m/s: speed_cap's speed per distance without a Reduced TCP limit

  /// The trigger plane the commanded tool sphere reaches beyond at the last update() (its
  /// functions then ran in Reduced mode), -1 when none.
  int zone() const { return zone_; }
  /// The mode the functions run in: Reduced when `mode` is or the tool is in a trigger zone.
  kin::SafetyMode effective(kin::SafetyMode mode) const { return zone_ >= 0 ? kin::SafetyMode::reduced : mode; }

  /// The last commanded TCP sample (base frame) update() computed.
  const kin::SafetySample& commanded() const { return cmd_; }

 private:
  const kin::Chain* chain_ = nullptr;  ///< &own_ once configured
  kin::Chain own_{};                   ///< the chain with the active tool
  kin::Pose flange_{kin::Pose::Identity()};  ///< the configured chain's own tool (tool0)
  kin::SafetyConfig cfg_{};
  double period_s_ = 0.001;
  kin::SafetySample cmd_{}, act_{}, prev_cmd_{}, prev_act_{};
  kin::JointVector prev_q_cmd_{};  ///< the joint speeds' previous commanded joints
  bool have_prev_ = false;
  int zone_ = -1;  ///< trigger plane of the last commanded sample
  double ratio_ = 0;  ///< speed_ratio()
  double reduced_state_ratio_ = 0;  ///< check_state(): the Reduced stop and dynamics ratios (time_to_trigger)
  bool has_stop_ = false, had_stop_ = false;  ///< check_state() predicted a stop this cycle / the previous one
  double prev_stop_distance_ = 0, prev_stop_time_ = 0;  ///< the previous cycle's predicted stop (m, s)
  bool speed_over_ = false;  ///< speed_over()
  kin::SafetyViolation speed_v_{};
  kin::JointTrajectory stop_{};  ///< predict_stop's ramp (kept here: no stack copy per cycle)
};

}  // namespace servoarm::fw
