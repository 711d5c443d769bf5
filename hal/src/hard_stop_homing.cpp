// SPDX-License-Identifier: Apache-2.0
// Hard-stop homing of the CANopen master: the approach ramp, contact detection, back-off and
// the new zero (docs/servo-bus.md#homing).
#include <algorithm>
#include <cmath>

#include "homing_steps.hpp"
#include "servoarm/hal/canopen_master.hpp"

namespace servoarm::hal {

void CanopenServoBus::hard_stop_write(std::size_t j, TimePoint now) {
  Joint& jt = joints_[j];
  const HomingSpec& hs = cfg_.joints[j].homing;
  const JointScaling& sc = cfg_.joints[j].scaling;
  double dt = jt.hs_last != 0 && now > jt.hs_last ? double(now - jt.hs_last) * 1e-9 : 0.0;
  dt = std::min(dt, 0.05);
  jt.hs_last = now;
  const double cps = sc.counts_per_si();
  const double a = hs.acceleration * cps, vmax = std::fabs(hs.speed_switch) * cps;
  const double dir = (hs.speed_switch > 0 ? 1.0 : -1.0) * double(sc.direction);  // in counts
  switch (jt.hstep) {
    case hs_approach: {
      jt.hs_v += std::clamp(dir * vmax - jt.hs_v, -a * dt, a * dt);
      jt.hs_demand += jt.hs_v * dt;
      break;
    }
    case hs_backoff: {
      const double d = jt.hs_goal - jt.hs_demand;
      const double vt = (d > 0 ? 1.0 : -1.0) * std::min(vmax, std::sqrt(2.0 * a * std::fabs(d)));
      jt.hs_v += std::clamp(vt - jt.hs_v, -a * dt, a * dt);
      const double step = jt.hs_v * dt;
      if (std::fabs(d) <= std::fabs(step) || std::fabs(d) < 0.5) {
        jt.hs_demand = jt.hs_goal;
        jt.hs_v = 0;
      } else {
        jt.hs_demand += step;
      }
      break;
    }
    default: break;
  }
  jt.target_counts = std::int32_t(std::lround(std::clamp(jt.hs_demand, -2147483648.0, 2147483647.0)));
}

void CanopenServoBus::advance_hard_stop(std::size_t j, TimePoint now) {
  Joint& jt = joints_[j];
  JointFeedback& fb = fb_[j];
  const HomingSpec& hs = cfg_.joints[j].homing;
  const JointScaling& sc = cfg_.joints[j].scaling;
  const double cps = sc.counts_per_si();
  switch (jt.hstep) {
    case hs_approach: {
      if (jt.tpdos < 3) break;
      const double fe = std::fabs(double(jt.target_counts) - double(jt.actual_counts)) / cps;
      const bool push = hs.torque_limit > 0 && fb.has_torque && std::fabs(fb.torque) > hs.torque_limit;
      if (fe > hs.following_limit || push) {
        // Contact: stop pushing (the demand goes to where the joint stands), then back off.
        const double dir = (hs.speed_switch > 0 ? 1.0 : -1.0) * double(sc.direction);
        jt.hs_demand = double(jt.actual_counts);
        jt.hs_v = 0;
        jt.hs_goal = std::nearbyint(double(jt.actual_counts) - dir * hs.backoff * cps);
        jt.target_counts = jt.actual_counts;
        homing_step(j, hs_backoff, now);
      }
      break;
    }
    case hs_backoff:
      if (jt.hs_demand == jt.hs_goal && jt.hs_v == 0) homing_step(j, hs_settle, now);
      break;
    case hs_settle:
      if (jt.tpdos >= 3 && (std::abs(double(jt.actual_counts) - jt.hs_goal) <= 1.0 ||
                            now - jt.hstep_since > 500 * kMillisecond)) {
        // The backed-off point reads `offset` from now on.
        JointScaling& s = cfg_.joints[j].scaling;
        const std::int32_t goal = std::int32_t(jt.hs_goal);
        s.zero_offset = std::int32_t(std::clamp(double(goal) - std::nearbyint(double(s.direction) * hs.offset * cps),
                                                -2147483648.0, 2147483647.0));
        fb.position = s.to_joint(jt.actual_counts);
        jt.hstatus = Status::ok;
        jt.hmsg[0] = '\0';
        homing_finish(j, now);
        jt.target_counts = goal;
        jt.hs_demand = double(goal);
      }
      break;
    default:
      break;
  }
}

}  // namespace servoarm::hal
