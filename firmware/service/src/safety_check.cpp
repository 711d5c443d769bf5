// SPDX-License-Identifier: Apache-2.0
// The safety envelope before motion (docs/safety.md): every planned move, jog step and
// streamed target is sampled along its path and checked with the kinematics core's geometry
// (servoarm/kinematics/safety.hpp), the same functions the control thread's monitor runs.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "servoarm/service/arm_service.hpp"

namespace servoarm::fw {

namespace {

std::string line_of(const kin::SafetyViolation& v) {
  char buf[320];
  return kin::describe(v, buf, sizeof buf);
}

}  // namespace

std::string envelope_violation_at(const kin::SafetyConfig& env, kin::SafetyMode mode, const kin::Chain& chain,
                                  const kin::JointVector& q_prev, const kin::JointVector& q, double dt) {
  if (!env.enabled) return "";
  kin::SafetySample x;
  if (!kin::safety_sample(chain, env, q, 1.0, x)) return "";  // a bad q is refused by the joint checks
  kin::SafetySample p;
  if (dt > 0 && q_prev.size() == q.size() && kin::safety_sample(chain, env, q_prev, 0.0, p))
    kin::set_velocity(x, p, q_prev, q, dt);
  kin::SafetyViolation v;
  if (kin::check_sample(env, kin::effective_mode(env, mode, x), x, 0.0, 0.0, 0.0, v)) return line_of(v);
  return "";
}

std::string ArmService::check_target(const kin::JointVector& q_prev, const kin::JointVector& q, double dt,
                                     const kin::Chain* chain) const {
  const kin::Chain& c = chain != nullptr ? *chain : chain_;
  return envelope_violation_at(envelope_for(c), plan_safety_mode(), c, q_prev, q, dt);
}

kin::SafetyConfig ArmService::envelope_for(const kin::Chain& chain) const {
  kin::SafetyConfig env = cfg_.safety;
  for (const auto& t : tools_)
    if (&t->chain == &chain) env.tool_radius = tool_radius(t->def);
  return env;
}

std::string ArmService::tool_envelope_problem(const ToolSlot& t) const {
  const kin::SafetyConfig& base = cfg_.safety;
  if (!base.enabled) return "";
  const double r = tool_radius(t.def);
  char line[256];
  for (int i = 0; i < base.box_count; ++i) {
    const kin::SafetyBox& b = base.boxes[static_cast<std::size_t>(i)];
    const double w = (b.max - b.min).minCoeff();
    if (b.keep_in && w < 2.0 * r) {
      std::snprintf(line, sizeof line, "its safety sphere (radius %.1f mm) is wider than keep-in box %d (%.1f mm)",
                    r * 1000.0, i, w * 1000.0);
      return line;
    }
  }
  kin::SafetyConfig positions = base;  // the park pose: positions only, with this tool
  positions.tool_radius = r;
  positions.cone = false;
  kin::SafetySample x;
  kin::SafetyViolation v;
  if (kin::safety_sample(t.chain, positions, cfg_.home, 0.0, x) &&
      kin::check_sample(positions, kin::SafetyMode::normal, x, 0.0, 0.0, 0.0, v)) {
    char what[256];
    std::snprintf(line, sizeof line, "the park pose lies outside the envelope with it: %s", kin::describe(v, what, sizeof what));
    return line;
  }
  return "";
}

void ArmService::push_safety_tool() {
  if (ctl_ == nullptr || !cfg_.safety.enabled || tool_ >= tools_.size()) return;
  (void)ctl_->set_safety_tool(tools_[tool_]->def.pose, tool_radius(tools_[tool_]->def));
}

bool ArmService::envelope_ok(const kin::Chain& chain, double duration,
                             const std::function<bool(double, kin::JointVector&)>& at, const char* /*what*/,
                             MoveResult& r, kin::SafetyViolation* violation, double* speed_ratio) const {
  const kin::SafetyConfig env = envelope_for(chain);
  if (!env.enabled || !(duration >= 0) || !std::isfinite(duration)) return true;
  // Sampled at the control rate, at most 4000 samples a move (a 10 s move every 2.5 ms): at
  // 250 mm/s the tool moves at most 0.6 mm between two samples.
  const double dt = std::max(1.0 / rate_hz_, duration / 4000.0);
  const int n = std::max(1, static_cast<int>(std::ceil(duration / dt)));
  kin::JointVector q(n_), q_prev(n_);
  // the predicted stop at each sample (stop limits): from the sampled joints, their velocities
  // and accelerations by differences, braked with the joints' limits as the controller brakes;
  // the momentum and power (their limits) at the same state
  // (with trigger planes a sample may run in either mode)
  const bool zones = env.trigger_count > 0;
  const bool stops = env.limits(plan_safety_mode()).has_stop_limit() || (zones && env.reduced.has_stop_limit());
  const bool dynamics = env.limits(plan_safety_mode()).has_dynamics_limit() || (zones && env.reduced.has_dynamics_limit());
  kin::JointState st;
  st.pos = st.vel = st.acc = kin::JointVector::Zero(n_);
  kin::JointVector v_prev = kin::JointVector::Zero(n_);
  kin::JointTrajectory ramp;
  kin::SafetySample prev, x;
  bool have_prev = false;
  kin::SafetyViolation v;
  double ratio = 0;  // the highest speed / limit along the whole path
  bool refused = false;
  for (int k = 0; k <= n; ++k) {
    const double t = std::min(duration, k * dt);
    if (!at(t, q) || !kin::safety_sample(chain, env, q, duration > 0 ? t / duration : 1.0, x)) continue;
    const double h = t - prev.s * duration;
    if (have_prev) kin::set_velocity(x, prev, q_prev, q, h);
    // (not on a last sample much closer than dt: its acceleration by difference would blow up)
    if ((stops || dynamics) && x.has_velocity && h >= 0.5 * dt) {
      st.pos = q;
      for (int j = 0; j < n_; ++j) {
        st.vel[j] = x.joint_velocity[static_cast<std::size_t>(j)];
        st.acc[j] = (st.vel[j] - v_prev[j]) / h;
      }
      v_prev = st.vel;
      if (stops) (void)kin::stop_prediction(chain, lim_, st, ramp, x);
      if (dynamics) (void)kin::dynamics_prediction(chain, st, x);
    }
    // the mode at this sample: Reduced where the tool reaches beyond a trigger plane
    const kin::SafetyMode mode = kin::effective_mode(env, plan_safety_mode(), x);
    // (the stop limits at the run-time speed scale's aim: a plan the scale would trim is not one that holds)
    ratio = std::max(ratio, kin::speed_ratio(env, mode, x, SafetyMonitor::kStopAim));
    // (speeds: 1e-6 m/s of rounding, so that a line planned at the limit passes)
    if (!refused && kin::check_sample(env, mode, x, 0.0, 0.0, 1e-6, v)) {
      r = refuse(MoveRefusal::arm_state, CmdError::limits);
      r.s = v.s;
      r.position = v.where;
      // (the front ends put "movej refused: " or their own words in front)
      r.reason = line_of(v) + "; nothing queued";
      if (violation != nullptr) *violation = v;
      refused = true;
      if (speed_ratio == nullptr || !kin::is_speed(v.function)) return false;  // (a speed: on to the path's highest)
    }
    prev = x;
    q_prev = q;
    have_prev = true;
  }
  if (speed_ratio != nullptr) *speed_ratio = ratio;
  return !refused;
}

std::string ArmService::jog_envelope(const kin::Chain& chain,
                                     const std::function<bool(double, kin::JointVector&)>& at) const {
  const kin::SafetyConfig env = envelope_for(chain);
  if (!env.enabled) return "";
  constexpr int kSamples = 200;
  kin::JointVector q(n_);
  kin::SafetySample x;
  kin::SafetyViolation v;
  for (int k = 0; k <= kSamples; ++k) {
    const double s = static_cast<double>(k) / kSamples;
    if (!at(s, q) || !kin::safety_sample(chain, env, q, s, x)) continue;
    if (kin::check_sample(env, kin::effective_mode(env, plan_safety_mode(), x), x, 0.0, 0.0, 0.0, v)) return line_of(v);
  }
  return "";
}

std::string ArmService::jog_envelope_line(const kin::Chain& chain, const kin::Pose& a, const kin::Pose& b,
                                          const kin::JointVector& seed, const kin::IkSolver& ik) const {
  if (!cfg_.safety.enabled) return "";
  const Eigen::Quaterniond qa(a.linear()), qb(b.linear());
  kin::JointVector last = seed;
  auto at = [&](double s, kin::JointVector& q) {
    kin::Pose p = kin::Pose::Identity();
    p.linear() = qa.slerp(s, qb).toRotationMatrix();
    p.translation() = a.translation() + s * (b.translation() - a.translation());
    if (ik.fn == nullptr || ik.fn(chain, p, last, q, ik.ctx) < kin::Status::ok) return false;
    last = q;
    return true;
  };
  return jog_envelope(chain, at);
}

ControlResult ArmService::set_safety_mode(kin::SafetyMode mode, bool confirm) {
  ControlResult c;
  if (!cfg_.safety.enabled) {
    c.error = CmdError::bad_state;
    c.reason = "no safety envelope is configured ([safety] in the configuration, docs/safety.md)";
    return c;
  }
  // Only a looser mode needs the operator's confirmation; a stricter one is always allowed.
  switch (mode) {
    case kin::SafetyMode::normal:
      if (safety_mode_ == kin::SafetyMode::reduced && !confirm) {
        c.error = CmdError::bad_state;
        c.reason = "Reduced -> Normal loosens the safety limits: confirm it (console `safety normal confirm`, API "
                   "safety_mode with confirm=true); still Reduced";
        return c;
      }
      break;
    case kin::SafetyMode::reduced: break;
  }
  safety_mode_ = mode;
  if (ctl_ != nullptr) ctl_->set_safety_mode(mode);
  c.reason = std::string("safety mode ") + kin::to_string(mode);
  return c;
}

}  // namespace servoarm::fw
