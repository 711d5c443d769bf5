// SPDX-License-Identifier: Apache-2.0
#include "servoarm/rt/model_control.hpp"

#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <algorithm>
#include <cstring>

#include "servoarm/kinematics/dynamics.hpp"

namespace servoarm::fw {

const char* to_string(FeedForwardKind k) {
  switch (k) {
    case FeedForwardKind::off: return "off";
    case FeedForwardKind::velocity: return "velocity";
    case FeedForwardKind::torque: return "torque";
  }
  return "?";
}

const char* to_string(ModelPart p) {
  switch (p) {
    case ModelPart::feed_forward: return "feed-forward";
    case ModelPart::collision: return "collision detection";
    case ModelPart::freedrive: return "free-drive";
  }
  return "?";
}

const char* to_string(FreedrivePhase p) {
  switch (p) {
    case FreedrivePhase::off: return "off";
    case FreedrivePhase::entering: return "entering";
    case FreedrivePhase::active: return "active";
    case FreedrivePhase::leaving: return "leaving";
  }
  return "?";
}

void ModelControl::refuse(ModelPart p, const char* fmt, ...) {
  char* out = refusal_[static_cast<int>(p)];
  if (out[0] != '\0') return;  // the first reason is the one said
  va_list ap;
  va_start(ap, fmt);
  std::vsnprintf(out, kLine, fmt, ap);
  va_end(ap);
}

namespace {
// A deterministic pseudo-random number in [0, 1) (set-up: the damping's inertia survey).
double next_unit(std::uint64_t& s) {
  s = s * 6364136223846793005ull + 1442695040888963407ull;
  return static_cast<double>(s >> 11) * (1.0 / 9007199254740992.0);
}
}  // namespace

bool ModelControl::configure(const kin::Chain& chain, hal::ServoBus& bus, const ModelControlConfig& cfg) {
  chain_ = &chain;
  bus_ = &bus;
  cfg_ = cfg;
  n_ = chain.n_joints;
  for (auto& r : refusal_) r[0] = '\0';
  notes_[0] = error_[0] = '\0';
  stats_ = {};
  phase_ = FreedrivePhase::off;
  watching_ = false;
  ff_on_.store(false, std::memory_order_relaxed);
  coll_on_.store(false, std::memory_order_relaxed);
  q_ = qd_ = tau_ = damping_vec_ = fd_damping_ = kin::JointVector::Zero(n_);
  thr_.fill(0);
  damping_.fill(0);

  if (n_ < 1 || static_cast<std::size_t>(n_) != bus.joint_count()) {
    for (int p = 0; p < kModelParts; ++p)
      refuse(static_cast<ModelPart>(p), "the robot has %d joints, the servo bus %zu", n_, bus.joint_count());
  }
  char model[kLine];
  const bool no_model = kin::dynamics_refusal(chain, model, sizeof model);
  hal::JointCapabilities caps[kin::kMaxJoints];
  for (int j = 0; j < n_ && j < kin::kMaxJoints; ++j) caps[j] = bus.capabilities(static_cast<std::size_t>(j));

  // Feed-forward: velocity needs 60B1h on every joint; torque also the model and 60B2h.
  if (cfg.feed_forward == FeedForwardKind::torque && no_model) refuse(ModelPart::feed_forward, "%s", model);
  for (int j = 0; j < n_; ++j) {
    if (!caps[j].velocity_offset)
      refuse(ModelPart::feed_forward,
             "joint %d: the drive takes no velocity offset (60B1h not mapped into RPDO2): feed-forward needs it", j + 1);
    if (cfg.feed_forward == FeedForwardKind::torque && !caps[j].torque_offset)
      refuse(ModelPart::feed_forward,
             "joint %d: the drive takes no torque offset (60B2h not mapped into RPDO2, or no rated torque 6076h): "
             "dynamics.feed_forward = \"torque\" needs it (\"velocity\" does not)",
             j + 1);
  }

  // Collision detection: the model, 6077h on every joint, a threshold per joint.
  if (no_model) refuse(ModelPart::collision, "%s", model);
  for (int j = 0; j < n_; ++j)
    if (!caps[j].measured_torque)
      refuse(ModelPart::collision,
             "joint %d: the drive reports no torque (6077h not mapped into TPDO2): collision detection needs it", j + 1);
  kin::CollisionConfig oc;
  oc.gain = cfg.collision_gain;
  oc.sensitivity = cfg.collision_sensitivity;
  // A drive's torque at a SYNC (6077h) is its current filtered over the cycle before it: the
  // interval's torque, not a point value (the dynamic plant reports exactly the interval's mean).
  // Integrated as such, a late or stalled cycle, in which the drives brake hard on their last
  // setpoint, adds the torque they gave over that interval and not half the previous one.
  oc.torque_is_interval_mean = true;
  for (int j = 0; j < n_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    const double given = cfg.collision_threshold[ju];
    const double t = given > 0 ? given : cfg.collision_threshold_pct * 1e-2 * std::fabs(cfg.rated_torque[ju]);
    if (!(t > 0) || !std::isfinite(t))
      refuse(ModelPart::collision,
             "joint %d: no collision threshold (drive.collision_threshold not given and the drive's rated torque "
             "unknown)",
             j + 1);
    oc.threshold[ju] = std::isfinite(t) && t > 0 ? t : 0;
    thr_[ju] = oc.threshold[ju] / (cfg.collision_sensitivity > 0 ? cfg.collision_sensitivity : 1.0);
  }
  if (refusal_[static_cast<int>(ModelPart::collision)][0] == '\0') {
    const kin::Status st = observer_.configure(chain, oc);
    if (st != kin::Status::ok)
      refuse(ModelPart::collision, "the collision observer refused its settings: %s (gain %g 1/s, sensitivity %g)",
             kin::to_string(st), oc.gain, oc.sensitivity);
  }

  // Free-drive: the model and torque mode (CST) on every joint.
  if (no_model) refuse(ModelPart::freedrive, "%s", model);
  for (int j = 0; j < n_; ++j)
    if (!caps[j].torque_mode)
      refuse(ModelPart::freedrive,
             "joint %d: the drive has no cyclic synchronous torque mode (CST with 6071h, 6060h/6061h in the PDOs; "
             "dynamics.freedrive = true maps it where the drive has it): free-drive needs it",
             j + 1);
  if (!no_model && n_ > 0) {
    // Damping: cfg x the joint's largest M_jj over the zero pose and 64 poses within the limits.
    kin::MassMatrix M;
    kin::JointVector q = kin::JointVector::Zero(n_);
    std::uint64_t seed = 20;
    for (int s = 0; s <= 64; ++s) {
      if (s > 0)
        for (int j = 0; j < n_; ++j) {
          const kin::DhRow& row = chain.joint(j);
          double lo = row.lower, hi = row.upper;
          if (!std::isfinite(lo) || !std::isfinite(hi)) {
            lo = row.type == kin::JointType::prismatic ? 0.0 : -M_PI;
            hi = row.type == kin::JointType::prismatic ? 0.5 : M_PI;
          }
          q[j] = lo + (hi - lo) * next_unit(seed);
        }
      if (kin::mass_matrix(chain, q, M) != kin::Status::ok) continue;
      for (int j = 0; j < n_; ++j) damping_[static_cast<std::size_t>(j)] = std::fmax(damping_[static_cast<std::size_t>(j)], M(j, j));
    }
    for (int j = 0; j < n_; ++j) {
      damping_[static_cast<std::size_t>(j)] *= cfg.freedrive_damping;
      damping_vec_[j] = damping_[static_cast<std::size_t>(j)];
    }
  }

  // The start notes: one line per reason, naming the parts asked for that it turns off
  // ("feed-forward and collision detection off: robot 'stanford' has no inertial data ...").
  const bool asked[kModelParts] = {cfg.feed_forward != FeedForwardKind::off, cfg.collision, cfg.freedrive};
  bool said[kModelParts] = {};
  bool all = true;
  std::size_t used = 0;
  auto put = [&](const char* fmt, const char* a, const char* b) {
    const int w = std::snprintf(notes_ + used, sizeof notes_ - used, fmt, a, b);
    if (w > 0) used = std::min(sizeof notes_ - 1, used + static_cast<std::size_t>(w));
  };
  for (int p = 0; p < kModelParts; ++p) {
    if (!asked[p] || refusal_[p][0] == '\0' || said[p]) continue;
    all = false;
    int same[kModelParts], k = 0;
    for (int q = p; q < kModelParts; ++q)
      if (asked[q] && !said[q] && std::strcmp(refusal_[q], refusal_[p]) == 0) same[k++] = q, said[q] = true;
    put("%s%s", used ? "\n" : "", to_string(static_cast<ModelPart>(same[0])));
    for (int i = 1; i < k; ++i) put("%s%s", i + 1 == k ? " and " : ", ", to_string(static_cast<ModelPart>(same[i])));
    put(" off: %s%s", refusal_[p], "");
  }
  if (cfg.feed_forward != FeedForwardKind::off && available(ModelPart::feed_forward)) ff_on_.store(true, std::memory_order_relaxed);
  if (cfg.collision && available(ModelPart::collision)) coll_on_.store(true, std::memory_order_relaxed);
  return all;
}

bool ModelControl::set_feed_forward_on(bool on) {
  if (on && (!available(ModelPart::feed_forward) || cfg_.feed_forward == FeedForwardKind::off)) return false;
  ff_on_.store(on, std::memory_order_relaxed);
  return true;
}

bool ModelControl::set_collision_on(bool on) {
  if (on && !available(ModelPart::collision)) return false;
  coll_on_.store(on, std::memory_order_relaxed);
  return true;
}

double ModelControl::threshold(int j) const {
  return j >= 0 && j < n_ && available(ModelPart::collision) ? thr_[static_cast<std::size_t>(j)] : 0.0;
}

bool ModelControl::measured(kin::JointVector& q, kin::JointVector& qd, kin::JointVector* tau) const {
  bool ok = true;
  for (int j = 0; j < n_; ++j) {
    const hal::JointFeedback& fb = bus_->feedback(static_cast<std::size_t>(j));
    q[j] = fb.position;
    qd[j] = fb.velocity;
    if (tau) tau[0][j] = fb.torque;
    ok = ok && fb.valid && (!tau || fb.has_torque);
  }
  return ok;
}

void ModelControl::settle_leaving() {
  if (phase_ != FreedrivePhase::leaving) return;
  for (int j = 0; j < n_; ++j)
    if (bus_->cyclic_mode(static_cast<std::size_t>(j)).mode != hal::CyclicMode::position) return;
  phase_ = FreedrivePhase::off;
  observer_.reset();
  watching_ = false;
}

void ModelControl::feed_forward(const kin::JointState& cmd) {
  settle_leaving();
  if (!ff_on_.load(std::memory_order_relaxed) || !available(ModelPart::feed_forward) || phase_ != FreedrivePhase::off)
    return;
  if (cmd.pos.size() != n_ || cmd.vel.size() != n_ || cmd.acc.size() != n_) {
    ++stats_.ff_errors;
    return;
  }
  bool ok = true;
  if (cfg_.feed_forward == FeedForwardKind::torque) {
    if (kin::feed_forward(*chain_, cmd.pos, cmd.vel, cmd.acc, ff_) != kin::Status::ok) {
      ++stats_.ff_errors;  // NaN in the setpoint (the controller's checks fault on it): no offsets
      return;
    }
    for (int j = 0; j < n_; ++j)
      ok = bus_->set_feed_forward(static_cast<std::size_t>(j), ff_.velocity[j], ff_.torque[j]) == hal::Status::ok && ok;
  } else {
    for (int j = 0; j < n_; ++j)
      ok = bus_->set_feed_forward(static_cast<std::size_t>(j), cmd.vel[j], 0.0) == hal::Status::ok && ok;
  }
  if (ok) ++stats_.ff_cycles;
  else ++stats_.ff_errors;
}

bool ModelControl::observe(bool watch, double dt, kin::CollisionVerdict& verdict) {
  verdict = kin::CollisionVerdict{};
  settle_leaving();
  bool on = watch && coll_on_.load(std::memory_order_relaxed) && available(ModelPart::collision) &&
            phase_ == FreedrivePhase::off && dt > 0;
  for (int j = 0; on && j < n_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    const hal::JointFeedback& fb = bus_->feedback(ju);
    on = fb.state == hal::JointState::enabled && fb.valid && fb.has_torque &&
         bus_->homing(ju).phase != hal::HomingPhase::running && bus_->cyclic_mode(ju).mode == hal::CyclicMode::position;
  }
  if (!on) {
    if (watching_) observer_.reset();
    watching_ = false;
    sampled_ = 0;
    stats_.last_ratio = 0;
    return false;
  }
  // The observer integrates over the time between the two samples it compares. The cycle's period
  // is that time only on average: a late cycle (its SYNC late) or a stall (no SYNC for several
  // periods while the drives brake on their last setpoint, the largest torques of all) makes the
  // true interval longer, and the momentum change over it would be set against the torque of one
  // period. So: the interval between the drives' sample times (the SYNCs the feedback answers);
  // the latest of the joints' (a late TPDO of one joint shifts its data by a cycle, not the time
  // base); no new sample since the last update: nothing to add. `dt` only where the bus gives no
  // sample times.
  hal::TimePoint sampled = 0;
  for (int j = 0; j < n_; ++j) sampled = std::max(sampled, bus_->feedback(static_cast<std::size_t>(j)).sampled);
  double step = dt;
  if (sampled != 0) {
    if (watching_ && sampled_ != 0) {
      if (sampled <= sampled_) return false;  // the same feedback again
      step = static_cast<double>(sampled - sampled_) * 1e-9;
    }
    sampled_ = sampled;
  }
  watching_ = true;
  measured(q_, qd_, &tau_);
  if (observer_.update(q_, qd_, tau_, step, verdict) != kin::Status::ok) {
    verdict = kin::CollisionVerdict{};
    return false;
  }
  ++stats_.observer_samples;
  const kin::JointVector& r = observer_.residual();
  double worst = 0;
  int wj = -1;
  for (int j = 0; j < n_; ++j) {
    const double t = thr_[static_cast<std::size_t>(j)];
    if (!(t > 0)) continue;
    const double ratio = std::fabs(r[j]) / t;
    if (ratio > worst) worst = ratio, wj = j;
  }
  stats_.last_ratio = worst;
  if (worst > stats_.peak_ratio) stats_.peak_ratio = worst, stats_.peak_joint = wj;
  if (verdict.collision) ++stats_.collisions;
  return verdict.collision;
}

void ModelControl::describe_collision(const kin::CollisionVerdict& v, char* buf, std::size_t size) const {
  if (size == 0) return;
  const bool prismatic = chain_ && v.joint >= 0 && v.joint < n_ && chain_->joint(v.joint).type == kin::JointType::prismatic;
  const char* u = prismatic ? "N" : "N m";
  std::snprintf(buf, size, "residual %.3g %s beyond the threshold %.3g %s", v.residual, u, v.threshold, u);
}

hal::Status ModelControl::freedrive_enter() {
  if (phase_ == FreedrivePhase::entering || phase_ == FreedrivePhase::active) return hal::Status::ok;
  if (!available(ModelPart::freedrive)) {
    std::snprintf(error_, sizeof error_, "%s", configured() ? refusal(ModelPart::freedrive) : "the model is not configured");
    return hal::Status::not_supported;
  }
  if (phase_ == FreedrivePhase::leaving) {
    std::snprintf(error_, sizeof error_, "free-drive is still ending (the drives are on their way back to CSP)");
    return hal::Status::bad_state;
  }
  for (int j = 0; j < n_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    const hal::JointFeedback& fb = bus_->feedback(ju);
    const hal::CyclicModeState cm = bus_->cyclic_mode(ju);
    const bool homing = bus_->homing(ju).phase == hal::HomingPhase::running;
    if (fb.state != hal::JointState::enabled || !fb.valid || homing || cm.mode != hal::CyclicMode::position) {
      std::snprintf(error_, sizeof error_, "joint %d is not ready for free-drive (drive %s%s, %s mode)", j + 1,
                    hal::to_string(fb.state), homing ? ", homing" : "", hal::to_string(cm.mode));
      return hal::Status::bad_state;
    }
  }
  measured(q_, qd_, nullptr);
  // A drive that damps in torque mode (MIT: kd in the motor's own loop) takes the damping; the
  // model's torque is then gravity and friction alone for it.
  for (int j = 0; j < n_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    const bool drive_damps = bus_->capabilities(ju).torque_mode_damping &&
                             bus_->set_torque_damping(ju, damping_vec_[j]) == hal::Status::ok;
    fd_damping_[j] = drive_damps ? 0.0 : damping_vec_[j];
  }
  if (kin::free_drive_torque(*chain_, q_, qd_, fd_damping_, tau_) != kin::Status::ok) {
    std::snprintf(error_, sizeof error_, "the model gives no free-drive torque at the measured pose (NaN?)");
    return hal::Status::invalid_argument;
  }
  for (int j = 0; j < n_; ++j)
    if (bus_->set_target_torque(static_cast<std::size_t>(j), tau_[j]) != hal::Status::ok) {
      std::snprintf(error_, sizeof error_, "joint %d: the holding torque %.3g is beyond the drive's target torque range",
                    j + 1, tau_[j]);
      return hal::Status::invalid_argument;
    }
  for (int j = 0; j < n_; ++j) {
    const hal::Status st = bus_->set_torque_mode(static_cast<std::size_t>(j), true);
    if (st != hal::Status::ok) {
      for (int k = 0; k < j; ++k) bus_->set_torque_mode(static_cast<std::size_t>(k), false);
      std::snprintf(error_, sizeof error_, "joint %d: torque mode refused: %s", j + 1, hal::to_string(st));
      phase_ = j > 0 ? FreedrivePhase::leaving : FreedrivePhase::off;
      return st;
    }
  }
  error_[0] = '\0';
  phase_ = FreedrivePhase::entering;
  ++stats_.freedrive_entries;
  observer_.reset();
  watching_ = false;
  return hal::Status::ok;
}

FreedrivePhase ModelControl::freedrive_step() {
  if (phase_ == FreedrivePhase::off) return phase_;
  measured(q_, qd_, nullptr);
  const bool have_tau = kin::free_drive_torque(*chain_, q_, qd_, fd_damping_, tau_) == kin::Status::ok;
  bool all_torque = true, all_position = true;
  int lost = -1;
  hal::Status why = hal::Status::ok;
  for (int j = 0; j < n_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    const hal::CyclicModeState cm = bus_->cyclic_mode(ju);
    all_torque = all_torque && cm.mode == hal::CyclicMode::torque;
    all_position = all_position && cm.mode == hal::CyclicMode::position;
    // Still in (or on the way into / out of) CST: keep holding it against gravity.
    if (cm.mode != hal::CyclicMode::position && have_tau) bus_->set_target_torque(ju, tau_[j]);
    const bool left = cm.mode == hal::CyclicMode::position ||
                      (cm.mode == hal::CyclicMode::leaving_torque && cm.status != hal::Status::ok);
    if (phase_ != FreedrivePhase::leaving && left && lost < 0) lost = j, why = cm.status;
  }
  if (lost >= 0) {
    std::snprintf(error_, sizeof error_, "joint %d left torque mode: %s; free-drive ends (CSP where it stands)", lost + 1,
                  why == hal::Status::ok ? "back in position mode" : hal::to_string(why));
    ++stats_.freedrive_lost;
    freedrive_leave();
  } else if (phase_ == FreedrivePhase::entering && all_torque) {
    phase_ = FreedrivePhase::active;
  }
  if (phase_ == FreedrivePhase::leaving && all_position) {
    phase_ = FreedrivePhase::off;
    observer_.reset();
    watching_ = false;
  }
  return phase_;
}

void ModelControl::freedrive_leave() {
  if (phase_ == FreedrivePhase::off) return;
  for (int j = 0; j < n_; ++j) bus_->set_torque_mode(static_cast<std::size_t>(j), false);
  phase_ = FreedrivePhase::leaving;
}

void ModelControl::describe(char* buf, std::size_t size) const {
  if (size == 0) return;
  buf[0] = '\0';
  if (!configured()) {
    std::snprintf(buf, size, "dynamics: not configured");
    return;
  }
  std::size_t used = 0;
  auto put = [&](const char* fmt, ...) __attribute__((format(printf, 2, 3))) {
    if (used >= size) return;
    std::va_list ap;
    va_start(ap, fmt);
    const int w = std::vsnprintf(buf + used, size - used, fmt, ap);
    va_end(ap);
    if (w > 0) used = std::min(size - 1, used + static_cast<std::size_t>(w));
  };
  if (cfg_.feed_forward == FeedForwardKind::off) put("feed-forward off");
  else if (!available(ModelPart::feed_forward)) put("feed-forward refused (%s)", refusal(ModelPart::feed_forward));
  else put("feed-forward %s %s", to_string(cfg_.feed_forward), feed_forward_on() ? "on" : "off");
  if (!available(ModelPart::collision)) {
    if (cfg_.collision) put(", collision refused (%s)", refusal(ModelPart::collision));
    else put(", collision off");
  } else if (collision_on()) {
    put(", collision on (K %g/s, peak |r|/threshold %.2f", cfg_.collision_gain, stats_.peak_ratio);
    if (stats_.peak_joint >= 0) put(" joint %d", stats_.peak_joint + 1);
    put(", %llu alarms)", static_cast<unsigned long long>(stats_.collisions));
  } else {
    put(", collision off");
  }
  if (!available(ModelPart::freedrive)) put(", free-drive unavailable");
  else put(", free-drive %s", to_string(phase_));
}

}  // namespace servoarm::fw
