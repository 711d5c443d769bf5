// SPDX-License-Identifier: Apache-2.0
// The arm service's motion path (arm_service.hpp).
#include "servoarm/service/arm_service.hpp"
#include "servoarm/service/mcap_recorder.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <thread>
#include <cstdio>
#include <cstring>
#include <limits>

#include "servoarm/kinematics/trajectory_cartesian.hpp"
#include "servoarm/lang/text.hpp"

namespace servoarm::fw {

const char* to_string(MoveRefusal r) {
  switch (r) {
    case MoveRefusal::none: return "none";
    case MoveRefusal::arm_state: return "arm_state";
    case MoveRefusal::not_homed: return "not_homed";
    case MoveRefusal::joint_limit: return "joint_limit";
    case MoveRefusal::linear_speed: return "linear_speed";
    case MoveRefusal::plan: return "plan";
    case MoveRefusal::duration: return "duration";
    case MoveRefusal::queue_full: return "queue_full";
  }
  return "?";
}

const char* to_string(JogRefusal r) {
  switch (r) {
    case JogRefusal::none: return "none";
    case JogRefusal::range: return "range";
    case JogRefusal::at_limit: return "at_limit";
    case JogRefusal::rotation: return "rotation";
    case JogRefusal::duration: return "duration";
    case JogRefusal::unreachable: return "unreachable";
    case JogRefusal::feed: return "feed";
    case JogRefusal::control: return "control";
  }
  return "?";
}

const char* to_string(OutputRefusal r) {
  switch (r) {
    case OutputRefusal::none: return "none";
    case OutputRefusal::no_output: return "no_output";
    case OutputRefusal::sync_full: return "sync_full";
    case OutputRefusal::queue_full: return "queue_full";
  }
  return "?";
}

CmdError motion_error(kin::MotionStatus m) {
  switch (m) {
    case kin::MotionStatus::ok:
    case kin::MotionStatus::slowed_near_singularity: return CmdError::ok;
    case kin::MotionStatus::no_ik_solution: return CmdError::unreachable;
    case kin::MotionStatus::goal_out_of_limits:
    case kin::MotionStatus::path_out_of_limits: return CmdError::limits;
    case kin::MotionStatus::branch_change: return CmdError::branch;
    case kin::MotionStatus::singularity:
    case kin::MotionStatus::joint_velocity: return CmdError::singular;
    case kin::MotionStatus::bad_input:
    case kin::MotionStatus::wrong_size:
    case kin::MotionStatus::bad_limits:
    case kin::MotionStatus::no_solution: return CmdError::plan_failed;
  }
  return CmdError::plan_failed;
}

CmdError control_error(RtResult r) {
  switch (r) {
    case RtResult::ok: return CmdError::ok;
    case RtResult::bad_state: return CmdError::bad_state;
    case RtResult::fault: return CmdError::fault;
    case RtResult::busy: return CmdError::busy;
    case RtResult::start_moved:
    case RtResult::plan_failed: return CmdError::plan_failed;
    case RtResult::not_homed: return CmdError::not_homed;
  }
  return CmdError::plan_failed;
}

ArmService::ArmService(Controller& ctl, const MotionSettings& cfg)
    : ctl_(&ctl), chain_(ctl.chain()), lim_(ctl.limits()), rate_hz_(1.0 / ctl.period_s()), cfg_(cfg), n_(ctl.chain().n_joints) {
  init();
  idle_ = [] { std::this_thread::sleep_for(std::chrono::microseconds(200)); };
}

ArmService::ArmService(const kin::Chain& chain, const kin::JointLimits& limits, double rate_hz, const MotionSettings& cfg)
    : chain_(chain), lim_(limits), rate_hz_(rate_hz), cfg_(cfg), n_(chain.n_joints) {
  init();
}

void ArmService::init() {
  ring_ = std::make_unique<std::array<EventSlot, kEventRing>>();
  tail_ = kin::JointVector::Zero(n_);
  shadow_ = std::make_unique<PathShadow>();
  scratch_ = std::make_unique<MotionItem>();
  auto t0 = std::make_unique<ToolSlot>();  // tool0: the flange
  t0->def.name = "tool0";
  t0->chain = chain_;
  t0->model = ik_;
  tools_.push_back(std::move(t0));
  NamedPose base;
  base.name = "base";
  frames_.push_back(base);
  if (cfg_.home.size() != n_) {  // joint zero clamped into the limits
    cfg_.home = kin::JointVector::Zero(n_);
    for (int j = 0; j < n_; ++j)
      cfg_.home[j] = std::fmin(std::fmax(0.0, lim_.lower[static_cast<std::size_t>(j)]), lim_.upper[static_cast<std::size_t>(j)]);
  }
}

ArmService::~ArmService() = default;

kin::JointVector ArmService::tail() const {
  // Queue not empty: its end. Empty and nothing re-took the setpoint since the
  // last move was queued (no flush, no enable): that move's goal, exactly.
  // Otherwise the commanded position (the arm is at rest: moves are refused
  // while it is stopping or enabling).
  if (ctl_ == nullptr || !ctl_->motions().empty()) return tail_;
  const Telemetry t = ctl_->telemetry();
  if (tail_id_ != 0 && t.generation == tail_gen_) return tail_;
  kin::JointVector q(n_);
  for (int j = 0; j < n_; ++j) q[j] = t.q_cmd[static_cast<std::size_t>(j)];
  return q;
}

bool ArmService::request(const Request& rq, Reply& out) {
  Request r = rq;
  r.seq = ++seq_;
  if (ctl_ == nullptr || !ctl_->requests().push(r)) {
    out.result = RtResult::busy;
    std::snprintf(out.message, sizeof out.message, "request queue full");
    return true;
  }
  const auto t0 = std::chrono::steady_clock::now();
  for (;;) {
    Reply p;
    while (ctl_->replies().pop(p))
      if (p.seq == r.seq) {
        out = p;
        return true;
      }
    if (std::chrono::steady_clock::now() - t0 > std::chrono::duration<double>(cfg_.reply_timeout_s)) return false;
    idle_();
  }
}

bool ArmService::request(RequestOp op, Reply& out) {
  Request rq;
  rq.op = op;
  return request(rq, out);
}

ControlResult ArmService::control(RequestOp op) {
  ControlResult c;
  if (!request(op, c.reply)) {
    c.error = CmdError::timeout;
    c.reason = std::string("control thread did not answer ") + to_string(op);
    return c;
  }
  c.error = control_error(c.reply.result);
  c.reason = bounded_text(c.reply.message);
  return c;
}

ControlResult ArmService::enable() {
  ControlResult c = control(RequestOp::enable);
  if (c.error != CmdError::ok && c.error != CmdError::timeout)
    c.error = c.reply.result == RtResult::fault ? CmdError::fault : CmdError::bad_state;
  return c;
}

ControlResult ArmService::home(int joint) {
  ControlResult c;
  Request rq(RequestOp::home, 0);
  rq.joints = joint >= 0 ? static_cast<std::uint16_t>(1u << joint) : 0;
  if (!request(rq, c.reply)) {
    c.error = CmdError::timeout;
    c.reason = "control thread did not answer home";
    return c;
  }
  c.reason = bounded_text(c.reply.message);
  switch (c.reply.result) {
    case RtResult::ok: c.error = CmdError::ok; break;
    case RtResult::busy: c.error = CmdError::busy; break;
    case RtResult::fault: c.error = CmdError::fault; break;
    case RtResult::not_homed:
    case RtResult::bad_state:
    case RtResult::start_moved:
    case RtResult::plan_failed: c.error = CmdError::bad_state; break;
  }
  return c;
}

// A model part's refusal (a fixed line of the model's): whole, or cut after a word with "...".
static std::string model_refusal(const ModelControl& m, ModelPart p) { return bounded_text(m.refusal(p), ModelControl::kLine); }

ControlResult ArmService::freedrive(bool on) {
  ControlResult c = control(on ? RequestOp::freedrive_on : RequestOp::freedrive_off);
  if (!on || c.error == CmdError::timeout || c.reply.result == RtResult::ok) return c;
  if (const ModelControl* m = ctl_->model(); m != nullptr && m->configured() && !m->available(ModelPart::freedrive)) {
    // The reply's fixed line may hold only the start of the model's refusal: the result
    // gives it whole, from the model.
    const std::string why = model_refusal(*m, ModelPart::freedrive);
    const std::string said = c.reply.message;
    const std::size_t at = said.find(why.substr(0, 40));
    if (at != std::string::npos) c.reason = said.substr(0, at) + why;
  }
  return c;
}

ControlResult ArmService::collision_detection(bool on) {
  ControlResult c;
  if (ctl_ == nullptr || !ctl_->set_collision_detection(on)) {
    const ModelControl* m = ctl_ != nullptr ? ctl_->model() : nullptr;
    c.error = CmdError::bad_state;
    c.reason = "collision detection unavailable: " +
               (m != nullptr && m->configured() ? model_refusal(*m, ModelPart::collision) : std::string("no dynamic model"));
    return c;
  }
  c.reason = on ? "collision detection on" : "collision detection off";
  return c;
}

MoveJoints ArmService::park_request() const {
  MoveJoints m;
  m.goal = cfg_.home;
  m.speed_pct = cfg_.default_joint_speed_pct;
  return m;
}

MoveResult ArmService::refuse(MoveRefusal what, CmdError e) const {
  MoveResult r;
  r.refusal = what;
  r.error = e;
  return r;
}

MoveResult ArmService::state_check() const {
  MoveResult r;
  if (ctl_ == nullptr) return r;
  const Telemetry t = ctl_->telemetry();
  const auto bad = [&](CmdError e, std::string why) {
    r = refuse(MoveRefusal::arm_state, e);
    r.reason = std::move(why);
  };
  switch (t.state) {
    case ArmState::idle:
    case ArmState::moving: break;
    case ArmState::jogging: bad(CmdError::bad_state, "a jog is running: jog stop (or 0x85) first"); break;
    case ArmState::homing: bad(CmdError::bad_state, "homing runs: `wait` for it (or stop it)"); break;
    case ArmState::freedrive: bad(CmdError::bad_state, "free-drive is on: freedrive off first"); break;
    case ArmState::enabling: bad(CmdError::bad_state, "drives still enabling; retry (or wait)"); break;
    case ArmState::boot:
    case ArmState::disabled: bad(CmdError::bad_state, std::string("arm is ") + to_string(t.state) + ": send enable first"); break;
    case ArmState::stopping: bad(CmdError::bad_state, "arm is stopping; retry when idle"); break;
    case ArmState::fault:
      bad(CmdError::fault, "arm in fault (" + bounded_text(t.fault_text) + "): send reset, then enable");
      break;
    case ArmState::estop: bad(CmdError::fault, "arm in e-stop: send reset, then enable"); break;
  }
  return r;
}

std::string ArmService::unhomed_reason() const {
  if (ctl_ == nullptr) return "";
  return unhomed_reason(ctl_->telemetry());
}

std::string ArmService::unhomed_reason(const Telemetry& t) const {
  if (ctl_ == nullptr || t.all_homed()) return "";
  std::string j;
  int count = 0;
  for (int k = 0; k < n_; ++k)
    if (!((t.homed >> k) & 1u)) j += (count++ ? ", " : " ") + std::to_string(k + 1);
  char pct[32];
  std::snprintf(pct, sizeof pct, "%.0f", 100.0 * ctl_->config().unhomed_jog_scale);
  return std::string("joint") + (count == 1 ? "" : "s") + j +
         " not homed: run `home` (or `home jN`); until then only joint jogs move, at " + pct + " %";
}

MotionItem* ArmService::slot(bool dry, MoveResult& r) {
  if (dry) return scratch_.get();
  MotionItem* m = ctl_->motions().back();
  if (m == nullptr) r = refuse(MoveRefusal::queue_full, CmdError::busy);
  return m;
}

bool ArmService::duration_ok(double duration, MoveResult& r) const {
  if (std::isfinite(duration) && duration <= cfg_.max_move_duration_s) return true;
  r = refuse(MoveRefusal::duration, CmdError::out_of_range);
  r.duration = duration;
  return false;
}

double ArmService::blend_of(double given, bool line, const MoveContext& cx) const {
  if (given >= 0) return given;
  if (cx.step_blend >= 0) return cx.step_blend;
  return line ? cfg_.default_blend_m : cfg_.default_blend_rad;
}

namespace {

// The fastest scale of a slowed move that still keeps the envelope's limits. A speed limit's
// ratio is exact (the speeds go with the scale), but the stop limits' and the power's are
// estimates that slow more than needed ((time / limit)^2, (distance / limit)^(2/3),
// (power / limit)^(1/2)): between the scale that held (its highest ratio r_held <= kHold) and the
// lowest that failed (r_failed > kHold), each try is planned and checked again, at the scale where
// log ratio, interpolated linearly in log scale, reaches kAim (kept within the middle 80 % of
// the bracket, halved in log scale when the failed one's ratio is unknown), until the held
// ratio is kDone or more, the bracket is within kNarrow, or after kChecks tries. A scale holds
// when the envelope check passes and its highest ratio is within kHold, the stop limits taken
// at the run-time speed scale's aim (SafetyMonitor::kStopAim, in envelope_ok): a plan that holds
// keeps its predicted stop where the run-time scale aims it, so the scale does not trim it
// while it runs and the planned duration is the one that runs. (Speeds, momentum and power
// are taken at their limits, as the run-time scale takes them.)
struct ScaleSearch {
  static constexpr double kHold = 1.0 + 1e-6;  // 1, and rounding (a line planned at a speed limit: 1 to rounding)
  static constexpr int kChecks = 5;
  static constexpr double kAim = 0.99;
  static constexpr double kDone = 0.98;
  static constexpr double kNarrow = 1.01;
  double held = 0, r_held = 0;      // the highest scale that held, its highest ratio
  double failed = 0, r_failed = 0;  // the lowest scale that failed, its ratio (0: not a speed's)
  int tries = 0;
  bool done() const { return tries >= kChecks || r_held >= kDone || !(failed > held * kNarrow); }
  double next() const {
    const double lo = std::log(held), hi = std::log(failed);
    double x = 0.5 * (lo + hi);
    if (r_held > 0 && r_failed > kHold && r_failed > r_held) {
      const double y_lo = std::log(r_held), y_hi = std::log(r_failed);
      x = lo + (std::log(kAim) - y_lo) * (hi - lo) / (y_hi - y_lo);
    }
    return std::exp(std::clamp(x, lo + 0.1 * (hi - lo), hi - 0.1 * (hi - lo)));
  }
  void record(double scale, bool ok, double ratio) {
    ++tries;
    if (ok) held = scale, r_held = ratio;
    else failed = scale, r_failed = ratio;
  }
};

}  // namespace

// The checks a real move passes before it is planned: the arm takes moves, and every joint
// is homed (a target means nothing in coordinates not established). A dry run moves nothing.
static bool admitted(const ArmService& svc, const MoveContext& cx, MoveResult& r) {
  if (cx.dry != nullptr) return true;
  r = svc.state_check();
  if (!r.ok()) return false;
  if (std::string why = svc.unhomed_reason(); !why.empty()) {
    r.error = CmdError::not_homed;
    r.refusal = MoveRefusal::not_homed;
    r.reason = std::move(why);
    return false;
  }
  return true;
}

void ArmService::commit(MotionItem& m, const kin::JointVector& goal, const MoveContext& cx, MoveResult& r, bool path) {
  r.goal = goal;
  if (cx.dry != nullptr) {  // checked, not queued
    cx.dry->tail = goal;
    if (!path) cx.dry->time += r.duration, cx.dry->blends = false;
    return;
  }
  m.id = next_id_++;
  m.n_outputs = static_cast<std::uint8_t>(cx.outputs.size());
  for (std::size_t k = 0; k < cx.outputs.size() && k < m.outputs.size(); ++k) m.outputs[k] = cx.outputs[k];
  tail_ = goal;
  tail_id_ = m.id;
  shadow_tail_id_ = path ? m.id : 0;
  tail_gen_ = ctl_->telemetry().generation;
  keep_planned_path(m, cx.chain != nullptr ? *cx.chain : chain_);  // before the control thread owns m
  ctl_->motions().commit();
  r.id = m.id;
}

// The planned path of a queued move, for viewers: its plan sampled in time (the joint plan,
// the line's precomputed knots, a blended segment alone) and the tool point of the move's
// chain at each sample. Console thread, before the move is handed to the control thread.
void ArmService::keep_planned_path(const MotionItem& m, const kin::Chain& chain) {
  PlannedPath p;
  p.id = m.id;
  p.kind = m.kind();
  p.tool = tool(active_tool()).name;
  std::function<void(double, kin::JointVector&)> at;
  kin::JointVector v(n_), a(n_);
  double t0 = 0;
  switch (m.kind()) {
    case MotionKind::joint: {
      const JointMove& jm = std::get<JointMove>(m.payload);
      p.duration = jm.plan.duration;
      at = [&](double t, kin::JointVector& q) { jm.plan.sample(t, q, v, a); };
      break;
    }
    case MotionKind::cartesian: {
      const CartesianMove& cm = std::get<CartesianMove>(m.payload);
      p.duration = cm.path.duration;
      at = [&](double t, kin::JointVector& q) { cm.path.sample_precomputed(t, q, v, a); };
      break;
    }
    case MotionKind::path: {
      const kin::PathSegment& g = std::get<PathMove>(m.payload).seg;
      p.duration = g.duration;
      t0 = g.start;
      kin::JointVector seed;
      kin::path_segment_start(g, n_, seed);
      at = [&g, seed](double t, kin::JointVector& q) mutable {
        (void)kin::path_sample_pair(nullptr, g, t, seed, q);
        seed = q;
      };
      break;
    }
    case MotionKind::dwell: return;
  }
  kin::JointVector q(n_);
  for (int k = 0; k < kPlannedPathSamples; ++k) {
    at(t0 + p.duration * k / (kPlannedPathSamples - 1), q);
    kin::Pose x = kin::Pose::Identity();
    if (kin::forward(chain, q, x) == kin::Status::ok) p.points.push_back(x.translation());
  }
  if (paths_.size() >= kPlannedPaths) paths_.pop_front();
  paths_.push_back(std::move(p));
}

const ArmService::PlannedPath* ArmService::planned_path(std::uint32_t id) const {
  for (const PlannedPath& p : paths_)
    if (p.id == id) return &p;
  return nullptr;
}

MoveResult ArmService::move(const MoveJoints& req, const MoveContext& cx) { return last_ = plan(req, cx); }
MoveResult ArmService::move(const MoveLine& req, const MoveContext& cx) { return last_ = plan(req, cx); }
MoveResult ArmService::dwell(double seconds, const MoveContext& cx) { return last_ = plan_dwell(seconds, cx); }

MoveResult ArmService::plan(const MoveJoints& req, const MoveContext& cx) {
  MoveResult r;
  if (!admitted(*this, cx, r)) return r;
  const kin::JointVector& goal = req.goal;
  // the feed override (GRBL 0x90..0x94) scales moves queued from now on
  const double pct = std::fmin(100.0, std::fmax(kMinJointSpeedPct, (req.speed_pct > 0 ? req.speed_pct : cfg_.default_joint_speed_pct) *
                                                                       feed_of(cx.feed_pct) / 100.0));
  for (int j = 0; j < n_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    if (goal[j] < lim_.lower[ju] || goal[j] > lim_.upper[ju]) {
      r = refuse(MoveRefusal::joint_limit, CmdError::limits);
      r.joint = j, r.value = goal[j], r.lower = lim_.lower[ju], r.upper = lim_.upper[ju];
      return r;
    }
  }
  MotionItem* m = slot(cx.dry != nullptr, r);
  if (m == nullptr) return r;
  // The one plan of the move, from the queue's end: the RT thread runs it as it is when
  // the arm is there at start (it plans again only when it is not: Telemetry::joint_replans).
  JointMove& jm = m->payload.emplace<JointMove>();
  jm.goal = goal;
  jm.override = pct / 100.0;
  kin::MovejOptions o;
  o.override = jm.override;
  r.status = kin::plan_movej(lim_, kin::JointState::rest(cx.dry != nullptr ? cx.dry->tail : tail()), goal, o, jm.plan);
  if (!kin::is_ok(r.status)) {
    const kin::MotionStatus st = r.status;
    r = refuse(MoveRefusal::plan, motion_error(st));
    r.status = st;
    return r;
  }
  if (!duration_ok(jm.plan.duration, r)) return r;
  // The envelope along the plan. A TCP, elbow or joint speed, a stop time or distance, a
  // momentum or power above its limit slows the move down instead (the same joint path at a
  // lower override: every speed scales with it), the override divided by the highest ratio
  // along the path (sampled: a few times at most), then sped up again to the fastest that
  // holds (ScaleSearch).
  const kin::Chain& chain = cx.chain != nullptr ? *cx.chain : chain_;
  auto check = [&](MoveResult& res, kin::SafetyViolation& sv, double& ratio) {
    kin::JointVector v(n_), a(n_);
    const kin::JointTrajectory& plan_ = jm.plan;
    auto at = [&](double t, kin::JointVector& q) { plan_.sample(t, q, v, a); return true; };
    ratio = 0;
    return envelope_ok(chain, plan_.duration, at, "movej", res, &sv, &ratio);
  };
  ScaleSearch search;
  for (int attempt = 0;; ++attempt) {
    kin::SafetyViolation sv;
    double ratio = 1;
    const bool passed = check(r, sv, ratio);
    const double slower = jm.override * 0.995 / std::max(ratio, 1.0);
    const bool last = attempt >= 12 || !(slower >= kMinJointSpeedPct / 100.0);
    if (passed && (ratio <= ScaleSearch::kHold || last)) {
      search.held = jm.override, search.r_held = ratio;
      break;
    }
    if (!passed && (!kin::is_speed(sv.function) || last)) return r;
    search.failed = jm.override, search.r_failed = ratio;
    const MoveResult refused = r;
    r = MoveResult{};
    jm.override = o.override = slower;
    r.status = kin::plan_movej(lim_, kin::JointState::rest(cx.dry != nullptr ? cx.dry->tail : tail()), goal, o, jm.plan);
    if (!kin::is_ok(r.status)) {
      if (!passed) return refused;
      const kin::MotionStatus st = r.status;  // (never seen: the same move, slower)
      r = refuse(MoveRefusal::plan, motion_error(st));
      r.status = st;
      return r;
    }
    if (!duration_ok(jm.plan.duration, r)) return r;
  }
  if (search.failed > 0 && !search.done()) {
    kin::JointTrajectory best = jm.plan;
    kin::MotionStatus best_status = r.status;
    while (!search.done()) {
      o.override = search.next();
      MoveResult probe;
      kin::SafetyViolation sv;
      double ratio = 0;
      probe.status = kin::plan_movej(lim_, kin::JointState::rest(cx.dry != nullptr ? cx.dry->tail : tail()), goal, o, jm.plan);
      const bool passed = kin::is_ok(probe.status) && duration_ok(jm.plan.duration, probe) && check(probe, sv, ratio);
      const bool ok = passed && ratio <= ScaleSearch::kHold;
      search.record(o.override, ok, passed || kin::is_speed(sv.function) ? ratio : 0.0);
      if (ok) best = jm.plan, best_status = probe.status;
    }
    jm.plan = best;
    r.status = best_status;
    jm.override = o.override = search.held;
  }
  r.envelope_ratio = search.r_held;
  r.duration = jm.plan.duration;  // (jm is replaced when the move goes as a blended segment)
  const double tol = blend_of(req.blend, false, cx);
  const bool path = path_segment(*m, false, goal, kin::Pose::Identity(), cfg_.cartesian, jm.override, tol, cx, r);
  if (!path) jm.blend = tol;  // the controller blends it into the next joint move
  commit(*m, goal, cx, r, path);
  return r;
}

MoveResult ArmService::plan(const MoveLine& req, const MoveContext& cx) {
  MoveResult r;
  if (!admitted(*this, cx, r)) return r;
  double speed = req.rapid ? cfg_.max_linear_speed : (req.speed > 0 ? req.speed : cfg_.default_linear_speed);
  if (req.clamp_speed && speed > cfg_.max_linear_speed) speed = cfg_.max_linear_speed;
  if (feed_of(cx.feed_pct) != 100) speed = std::fmin(speed * feed_of(cx.feed_pct) / 100.0, cfg_.max_linear_speed);  // feed override
  if (!(speed >= kMinLinearSpeedMmS * 1e-3) || speed > cfg_.max_linear_speed + 1e-12) {
    r = refuse(MoveRefusal::linear_speed, CmdError::out_of_range);
    r.speed = speed;
    return r;
  }
  // the envelope's TCP speed limit (the mode's) caps the line's speed: slowed, not refused
  if (const double cap = cfg_.safety.enabled ? cfg_.safety.limits(plan_safety_mode()).tcp_speed : 0.0; cap > 0 && speed > cap)
    speed = cap;
  MotionItem* m = slot(cx.dry != nullptr, r);
  if (m == nullptr) return r;
  kin::CartesianLimits cl = cfg_.cartesian;
  const kin::MovelOptions mo;
  kin::PathReport rep;
  const kin::JointVector q0 = cx.dry != nullptr ? cx.dry->tail : tail();
  kin::CartesianTrajectory& traj = m->payload.emplace<CartesianMove>().path;
  const kin::Chain& chain = cx.chain != nullptr ? *cx.chain : chain_;
  kin::MotionStatus ms = kin::MotionStatus::ok;
  // The envelope along the line. A speed above its limit (a joint's, the elbow's), a stop time
  // or distance, a momentum or power slows the line down instead: planned again at its speed
  // divided by the highest ratio found, then sped up again to the fastest that holds
  // (ScaleSearch).
  auto check = [&](MoveResult& res, kin::SafetyViolation& sv, double& ratio) {
    kin::JointVector v(n_), a(n_);
    auto at = [&](double t, kin::JointVector& q) { traj.sample_precomputed(t, q, v, a); return true; };
    ratio = 0;
    return envelope_ok(chain, traj.duration, at, "movel", res, &sv, &ratio);
  };
  ScaleSearch search;
  for (int attempt = 0;; ++attempt) {
    cl.linear_velocity = speed;
    ms = kin::plan_movel(chain, q0, req.target, cl, mo, cx.ik, traj, &rep);
    if (!kin::is_ok(ms)) {
      r = refuse(MoveRefusal::plan, motion_error(ms));
      r.status = ms, r.s = rep.s, r.position = rep.position, r.joint = rep.joint;
      return r;
    }
    if (!duration_ok(traj.duration, r)) return r;
    kin::SafetyViolation sv;
    double ratio = 1;
    const bool passed = check(r, sv, ratio);
    const double slower = speed * 0.995 / std::max(ratio, 1.0);
    const bool last = attempt >= 12 || !(slower >= kMinLinearSpeedMmS * 1e-3);
    if (passed && (ratio <= ScaleSearch::kHold || last)) {
      search.held = speed, search.r_held = ratio;
      break;
    }
    if (!passed && (!kin::is_speed(sv.function) || last)) return r;
    search.failed = speed, search.r_failed = ratio;
    r = MoveResult{};
    speed = slower;
  }
  if (search.failed > 0 && !search.done()) {
    kin::CartesianTrajectory best = traj;
    kin::MotionStatus best_status = ms;
    while (!search.done()) {
      cl.linear_velocity = search.next();
      MoveResult probe;
      kin::SafetyViolation sv;
      double ratio = 0;
      const kin::MotionStatus st = kin::plan_movel(chain, q0, req.target, cl, mo, cx.ik, traj, &rep);
      const bool passed = kin::is_ok(st) && duration_ok(traj.duration, probe) && check(probe, sv, ratio);
      const bool ok = passed && ratio <= ScaleSearch::kHold;
      search.record(cl.linear_velocity, ok, passed || kin::is_speed(sv.function) ? ratio : 0.0);
      if (ok) best = traj, best_status = st;
    }
    traj = best;
    ms = best_status;
    cl.linear_velocity = speed = search.held;
  }
  r.envelope_ratio = search.r_held;
  traj.ik = cx.ik;
  r.status = ms;
  r.speed = speed;
  r.duration = traj.duration;  // (traj is replaced when the move goes as a blended segment)
  r.slowdown = traj.slowdown;
  const kin::JointVector goal = traj.goal;
  const bool path = path_segment(*m, true, goal, req.target, cl, 1.0, blend_of(req.blend, true, cx), cx, r);
  commit(*m, goal, cx, r, path);
  return r;
}

MoveResult ArmService::plan_dwell(double seconds, const MoveContext& cx) {
  MoveResult r;
  if (cx.dry != nullptr) {
    cx.dry->time += seconds;
    cx.dry->blends = false;
    r.duration = seconds;
    r.goal = cx.dry->tail;
    return r;
  }
  r = state_check();
  if (!r.ok()) return r;
  MotionItem* m = slot(false, r);
  if (m == nullptr) return r;
  const kin::JointVector q = tail();
  DwellMove& d = m->payload.emplace<DwellMove>();
  d.at = q;
  d.seconds = seconds;
  r.duration = seconds;
  MoveContext plain = cx;
  plain.outputs = {};  // M62 / M63 wait for a move
  commit(*m, q, plain, r, false);
  return r;
}

// ---------------------------------------------------------------------------
// Blended runs (docs/motion.md#blending)
// ---------------------------------------------------------------------------
// A move with a blend tolerance, and a move following one still queued, goes to the
// controller as a PathMove: its segment planned alone from rest at the previous target and
// its overlap with the segment before it chosen here by kin::PathBlendQueue (every joint's
// velocity, acceleration and jerk, the tool speed of lines, IK at every sample of a
// line-line overlap and the corner's tolerance, checked at the control rate on the run's
// time base). The controller starts the segment at that time if it still can
// (kPathLead: how far ahead of the run's newest sample a typed move is placed), else from
// rest where the one before ends.
bool ArmService::path_segment(MotionItem& m, bool line, const kin::JointVector& goal, const kin::Pose& target,
                              const kin::CartesianLimits& cl, double override, double tol, const MoveContext& cx,
                              MoveResult& r) {
  if (!std::isfinite(tol) || tol < 0) tol = 0;
  DryRun* dry = cx.dry;
  PathShadow& q = dry != nullptr ? *dry->shadow : *shadow_;
  const kin::Chain* chain = cx.chain != nullptr ? cx.chain : &chain_;
  bool linked = false;
  double t_earliest = 0;
  if (dry != nullptr) {
    linked = dry->blends && q.size() > 0 && q.core.cfg.chain == chain;
  } else {
    const Telemetry t = ctl_->telemetry();
    linked = shadow_tail_id_ != 0 && shadow_tail_id_ == tail_id_ && t.generation == tail_gen_ && t.done_id < tail_id_ &&
             !ctl_->motions().empty() && q.size() > 0 && q.core.cfg.chain == chain && q.at(q.size() - 1).tolerance > 0;
    if (linked && t.path_time >= 0) t_earliest = t.path_time + kPathLead;
  }
  // A plain move: no tolerance and nothing to blend out of; a joint move with a tolerance
  // that no line follows (as far as the front end knows: a program's next motion) blends in
  // the controller's joint queue (JointMove::blend).
  if (!linked && !(tol > 0 && (line || cx.next_line))) return false;
  if (linked) {
    if (q.size() >= 2) q.retire(q.at(q.size() - 1).start);  // keep the last two: the checks' window may reach both
  } else {
    kin::PathBlendConfig pc;
    pc.limits = lim_;
    pc.rate = rate_hz_;
    pc.chain = chain;
    pc.ik = cx.ik;
    pc.joint_share = 0.5;  // blended joint segments share acceleration and jerk with their neighbour
    q.reset(pc, dry != nullptr ? dry->tail : tail());
    if (dry != nullptr) dry->run_base = dry->time;
  }
  kin::PathBlendReport rep;
  const kin::BlendStatus st = line ? q.append_line(target, cl, kin::MovelOptions{}, tol, t_earliest, &rep)
                                   : q.append_joint(goal, override, tol, t_earliest, &rep);
  if (!kin::is_ok(st) || st == kin::BlendStatus::zero_length) {  // the plain move (checked already) instead
    if (dry != nullptr) dry->blends = false;
    else shadow_tail_id_ = 0;
    return false;
  }
  const kin::PathSegment& g = q.at(q.size() - 1);
  r.blended = true;
  r.blend = rep.blend;
  r.segment_start = g.start;
  r.segment_end = g.end();
  if (dry != nullptr) {
    dry->blends = tol > 0;
    dry->time = dry->run_base + g.end();
    return true;
  }
  PathMove& pm = m.payload.emplace<PathMove>();
  pm.seg = g;
  pm.after = linked ? tail_id_ : 0;
  pm.override = override;
  return true;
}

}  // namespace servoarm::fw

namespace servoarm::fw {

// ---------------------------------------------------------------------------
// The event stream
// ---------------------------------------------------------------------------

namespace {
ArmEventKind kind_of(EventKind k) {
  switch (k) {
    case EventKind::fault: return ArmEventKind::fault;
    case EventKind::estop: return ArmEventKind::estop;
    case EventKind::motion_done: return ArmEventKind::motion_done;
    case EventKind::motion_refused: return ArmEventKind::motion_refused;
    case EventKind::state: return ArmEventKind::state;
    case EventKind::jog_stopped: return ArmEventKind::jog_stopped;
    case EventKind::homing: return ArmEventKind::homing;
    case EventKind::freedrive: return ArmEventKind::freedrive;
    case EventKind::warning: return ArmEventKind::warning;
  }
  return ArmEventKind::state;
}
}  // namespace

const char* to_string(ArmEventKind k) {
  switch (k) {
    case ArmEventKind::fault: return "fault";
    case ArmEventKind::estop: return "estop";
    case ArmEventKind::motion_done: return "motion_done";
    case ArmEventKind::motion_refused: return "motion_refused";
    case ArmEventKind::state: return "state";
    case ArmEventKind::jog_stopped: return "jog_stopped";
    case ArmEventKind::homing: return "homing";
    case ArmEventKind::freedrive: return "freedrive";
    case ArmEventKind::program: return "program";
    case ArmEventKind::warning: return "warning";
  }
  return "?";
}

ArmService::EventSlot& ArmService::push_event() {
  EventSlot& s = (*ring_)[next_seq_ % kEventRing];
  s.ev = ArmEvent{};
  s.ev.seq = next_seq_++;
  s.detail[0] = '\0';
  s.program.clear();
  s.file.clear();
  if (ctl_ != nullptr) {
    s.ev.cycle = ctl_->telemetry().cycles;
    s.ev.t = static_cast<double>(s.ev.cycle) * ctl_->period_s();
  }
  return s;
}

std::size_t ArmService::poll_events() {
  if (ctl_ == nullptr) return 0;
  std::size_t n = 0;
  Event e;
  while (ctl_->events().pop(e)) {
    EventSlot& s = push_event();
    s.ev.kind = kind_of(e.kind);
    s.ev.state = e.state;
    s.ev.cause = e.cause;
    s.ev.joint = e.joint;
    s.ev.motion_id = e.motion_id;
    std::memcpy(s.detail, e.message, sizeof s.detail);
    if (e.kind == EventKind::fault || e.kind == EventKind::estop || e.kind == EventKind::jog_stopped)
      jog_.valid = false;  // the running jog ended: the next one starts from the commanded position
    s.detail[sizeof s.detail - 1] = '\0';
    ++n;
  }
  return n;
}

EventBatch ArmService::events_since(std::uint64_t seq) const {
  EventBatch b;
  const std::uint64_t kept_from = next_seq_ > kEventRing ? next_seq_ - kEventRing : 1;  // oldest kept
  std::uint64_t from = seq + 1;
  if (from < kept_from) {
    b.missed = kept_from - from;
    from = kept_from;
  }
  if (from < next_seq_) b.events.reserve(static_cast<std::size_t>(next_seq_ - from));
  for (std::uint64_t s = from; s < next_seq_; ++s) b.events.push_back((*ring_)[s % kEventRing].ev);
  return b;
}

std::string_view ArmService::event_detail(const ArmEvent& e) const {
  const EventSlot& s = (*ring_)[e.seq % kEventRing];
  if (e.seq == 0 || s.ev.seq != e.seq) return {};
  return std::string_view(s.detail);
}

ProgramNames ArmService::event_program(const ArmEvent& e) const {
  const EventSlot& s = (*ring_)[e.seq % kEventRing];
  if (e.seq == 0 || s.ev.seq != e.seq || e.kind != ArmEventKind::program) return {};
  return {s.program, s.file};
}

}  // namespace servoarm::fw

namespace servoarm::fw {

// ---------------------------------------------------------------------------
// Jogging (jog.hpp runs it on the control thread; here the targets are computed)
// ---------------------------------------------------------------------------

namespace {
JogResult jog_refusal(JogRefusal what, CmdError e) {
  JogResult r;
  r.error = e;
  r.refusal = what;
  return r;
}
}  // namespace

kin::JointVector ArmService::commanded() const {
  const Telemetry t = ctl_->telemetry();
  kin::JointVector q(n_);
  for (int j = 0; j < n_; ++j) q[j] = t.q_cmd[static_cast<std::size_t>(j)];
  return q;
}

kin::Pose ArmService::commanded_pose(const JogContext& cx) const {
  kin::Pose p = kin::Pose::Identity();
  if (kin::forward(cx.chain != nullptr ? *cx.chain : chain_, commanded(), p) != kin::Status::ok)
    p.translation().setConstant(std::nan(""));
  return p;
}

double ArmService::jog_pct(double speed_pct, int feed_pct) const {
  const double pct = (speed_pct >= 0 ? speed_pct : cfg_.jog_speed_pct) * feed_pct / 100.0;
  return std::fmin(100.0, std::fmax(kMinJointSpeedPct, pct));
}

JogSpec ArmService::tool_spec(double pct, const JogContext& cx) const {
  JogSpec js;
  js.space = JogSpace::tool;
  js.linear_speed = pct / 100.0 * cfg_.max_linear_speed;
  js.angular_speed = pct / 100.0 * cfg_.cartesian.angular_velocity;
  js.limits = cfg_.cartesian;
  js.ik = cx.ik;
  js.chain = cx.chain != nullptr ? cx.chain : &chain_;
  js.deadman_s = cfg_.jog_deadman_s;
  return js;
}

bool ArmService::jog_duration_ok(double duration, JogResult& r) const {
  if (std::isfinite(duration) && duration <= cfg_.max_move_duration_s) return true;
  r = jog_refusal(JogRefusal::duration, CmdError::out_of_range);
  r.duration = duration;
  return false;
}

JogResult ArmService::send_jog(const JogSpec& js) {
  Request rq;
  rq.op = RequestOp::jog;
  rq.jog = js;
  Reply rep;
  if (!request(rq, rep)) {
    JogResult r = jog_refusal(JogRefusal::control, CmdError::timeout);
    r.reason = "control thread did not answer the jog";
    return r;
  }
  JogResult r;
  r.reason = bounded_text(rep.message);
  switch (rep.result) {
    case RtResult::ok: return r;
    case RtResult::busy: r.error = CmdError::busy; break;
    case RtResult::fault: r.error = CmdError::fault; break;
    case RtResult::not_homed: r.error = CmdError::not_homed; break;
    case RtResult::bad_state:
    case RtResult::start_moved:
    case RtResult::plan_failed: r.error = CmdError::bad_state; break;
  }
  r.refusal = JogRefusal::control;
  return r;
}

JogResult ArmService::jog(const JointJog& rq, const JogContext& cx) {
  const bool jogging = ctl_->telemetry().state == ArmState::jogging && jog_.valid;
  const double pct = jog_pct(rq.speed_pct, feed_of(cx.feed_pct));
  const int j = rq.joint;
  const auto ju = static_cast<std::size_t>(j);
  const kin::JointVector from = commanded();
  kin::JointVector goal = jogging && !jog_.tool ? jog_.q : from;
  JogResult pre;
  if (rq.continuous) {
    goal[j] = rq.direction > 0 ? lim_.upper[ju] : lim_.lower[ju];
  } else {
    // An increment larger than the joint's whole range is no jog: refused, nothing moves.
    if (!(std::fabs(rq.increment) <= lim_.upper[ju] - lim_.lower[ju])) {
      JogResult r = jog_refusal(JogRefusal::range, CmdError::out_of_range);
      r.joint = j;
      r.lower = lim_.lower[ju];
      r.upper = lim_.upper[ju];
      return r;
    }
    const double asked = goal[j] + rq.increment;
    const double to = std::fmin(std::fmax(asked, lim_.lower[ju]), lim_.upper[ju]);
    if (to == goal[j]) {
      JogResult r = jog_refusal(JogRefusal::at_limit, CmdError::limits);
      r.joint = j;
      r.value = to;
      return r;
    }
    if (to != asked) {
      pre.clamped = true;
      pre.joint = j;
      pre.asked = asked;
      pre.value = to;
    }
    goal[j] = to;
    if (!jog_duration_ok(std::fabs(goal[j] - from[j]) / (pct / 100.0 * lim_.dyn[ju].max_velocity), pre)) return pre;
  }
  if (!rq.continuous) {
    const kin::JointVector q0 = from;
    auto at = [&](double t, kin::JointVector& q) { q = q0 + t * (goal - q0); return true; };
    if (std::string why = jog_envelope(cx.chain != nullptr ? *cx.chain : chain_, at); !why.empty()) {
      JogResult r = jog_refusal(JogRefusal::control, CmdError::limits);
      r.reason = "jog refused: " + why;
      return r;
    }
  }
  JogSpec js;
  js.space = JogSpace::joint;
  js.continuous = rq.continuous;
  js.deadman_s = cfg_.jog_deadman_s;
  js.q_goal = goal;
  js.axis = j;
  js.override = pct / 100.0;
  JogResult r = send_jog(js);
  r.clamped = pre.clamped;
  r.joint = pre.joint;
  r.asked = pre.asked;
  r.value = pre.value;
  if (!r.ok() && !r.clamped) return r;
  jog_.q = goal;
  jog_.tool = false;
  jog_.valid = !rq.continuous;
  return r;
}

JogResult ArmService::jog(const ToolJog& rq, const JogContext& cx) {
  const bool jogging = ctl_->telemetry().state == ArmState::jogging && jog_.valid;
  JogSpec js = tool_spec(jog_pct(rq.speed_pct, feed_of(cx.feed_pct)), cx);
  js.continuous = rq.continuous;
  const kin::Pose now = commanded_pose(cx);
  const kin::Pose here = jogging && jog_.tool ? jog_.pose : now;
  if (jogging && jog_.tool && rq.frame == jog_.frame) js.frame = jog_.axes;
  else if (rq.frame == JogFrame::tool) js.frame = now.linear();
  else if (rq.frame == JogFrame::user) js.frame = cx.user_axes;
  else js.frame = Eigen::Matrix3d::Identity();
  JogResult r;
  if (rq.continuous) {
    js.axis = rq.axis;
    js.direction = rq.direction;
  } else {
    kin::Pose target = here;
    const int k = rq.axis;
    if (k < 3) {
      target.translation() += js.frame.col(k) * rq.increment;
    } else {
      // A rotation is taken the short way round: beyond half a turn it would turn the other
      // way (or not at all at a full turn), so |angle| >= 180 deg is refused.
      if (!(std::fabs(rq.increment) < M_PI)) {
        r = jog_refusal(JogRefusal::rotation, CmdError::out_of_range);
        r.value = rq.increment;
        return r;
      }
      target.linear() = Eigen::AngleAxisd(rq.increment, js.frame.col(k - 3)).toRotationMatrix() * here.linear();
    }
    const double dist = k < 3 ? std::fabs(rq.increment) : 0.0;
    const double ang = k < 3 ? 0.0 : std::fabs(rq.increment);
    if (!jog_duration_ok(std::fmax(dist / js.linear_speed, ang / js.angular_speed), r)) return r;
    kin::JointVector q(n_);
    if (cx.ik.fn == nullptr || cx.ik.fn(*js.chain, target, commanded(), q, cx.ik.ctx) < kin::Status::ok)
      return jog_refusal(JogRefusal::unreachable, CmdError::unreachable);
    if (std::string why = jog_envelope_line(*js.chain, here, target, commanded(), cx.ik); !why.empty()) {
      r = jog_refusal(JogRefusal::control, CmdError::limits);
      r.reason = "jog refused: " + why;
      return r;
    }
    js.target = target;
    jog_.pose = target;
  }
  r = send_jog(js);
  r.speed = js.linear_speed;
  if (!r.ok()) {
    jog_.valid = false;
    return r;
  }
  jog_.tool = true;
  jog_.valid = !rq.continuous;
  jog_.axes = js.frame;
  jog_.frame = rq.frame;
  return r;
}

kin::Pose ArmService::jog_from(JogFrame frame, const JogContext& cx) const {
  const bool jogging = ctl_->telemetry().state == ArmState::jogging && jog_.valid && jog_.tool && jog_.frame == frame;
  return jogging ? jog_.pose : commanded_pose(cx);
}

JogResult ArmService::jog(const PoseJog& rq, const JogContext& cx) {
  kin::JointVector q(n_);
  const kin::Chain& chain = cx.chain != nullptr ? *cx.chain : chain_;
  if (cx.ik.fn == nullptr || cx.ik.fn(chain, rq.target, commanded(), q, cx.ik.ctx) < kin::Status::ok)
    return jog_refusal(JogRefusal::unreachable, CmdError::unreachable);
  const int feed = feed_of(cx.feed_pct);
  JogSpec js = tool_spec(feed > 100 ? 100 : feed, cx);
  // the path speed (GRBL clamps a jog's feed to the maximum rate); the override scales it
  js.linear_speed = std::fmin(rq.speed * feed / 100.0, cfg_.max_linear_speed);
  js.frame = rq.axes;
  js.target = rq.target;
  JogResult r;
  if (!(js.linear_speed >= kMinLinearSpeedMmS * 1e-3)) {
    r = jog_refusal(JogRefusal::feed, CmdError::out_of_range);
    r.speed = js.linear_speed;
    return r;
  }
  const kin::Pose from = commanded_pose(cx);  // distances and angles are the same in every frame
  const double dist = (rq.target.translation() - from.translation()).norm();
  const double ang = Eigen::AngleAxisd(rq.target.linear() * from.linear().transpose()).angle();
  if (!jog_duration_ok(std::fmax(dist / js.linear_speed, ang / js.angular_speed), r)) return r;
  if (std::string why = jog_envelope_line(chain, from, rq.target, commanded(), cx.ik); !why.empty()) {
    r = jog_refusal(JogRefusal::control, CmdError::limits);
    r.reason = "jog refused: " + why;
    return r;
  }
  r = send_jog(js);
  r.speed = js.linear_speed;
  if (!r.ok()) {
    jog_.valid = false;
    return r;
  }
  jog_.pose = rq.target;
  jog_.tool = true;
  jog_.valid = true;
  jog_.axes = js.frame;
  jog_.frame = rq.frame;
  return r;
}

ControlResult ArmService::jog_cancel() {
  ControlResult c = control(RequestOp::jog_cancel);
  jog_.valid = false;
  return c;
}

}  // namespace servoarm::fw

namespace servoarm::fw {

// ---------------------------------------------------------------------------
// Digital outputs
// ---------------------------------------------------------------------------

OutputResult ArmService::set_output(const OutputRequest& rq) {
  OutputResult r;
  r.count = cfg_.outputs.size();
  if (rq.index >= cfg_.outputs.size()) {
    r.error = CmdError::out_of_range;
    r.refusal = OutputRefusal::no_output;
    return r;
  }
  const OutputBit& o = cfg_.outputs[rq.index];
  OutputChange ch;
  ch.joint = static_cast<std::int8_t>(o.joint);
  ch.mask = 1u << o.bit;
  ch.value = rq.on ? ch.mask : 0u;
  if (rq.dry) return r;
  if (rq.sync) {  // merged into the changes the next move carries
    std::size_t k = 0;
    while (k < n_sync_out_ && sync_out_[k].joint != ch.joint) ++k;
    if (k == n_sync_out_) {
      if (n_sync_out_ >= kMotionOutputs) {
        r.error = CmdError::busy;
        r.refusal = OutputRefusal::sync_full;
        return r;
      }
      sync_out_[n_sync_out_++] = OutputChange{ch.joint, 0, 0};
    }
    sync_out_[k].mask |= ch.mask;
    sync_out_[k].value = (sync_out_[k].value & ~ch.mask) | ch.value;
    return r;
  }
  if (ctl_ == nullptr || !ctl_->outputs().push(ch)) {
    r.error = CmdError::busy;
    r.refusal = OutputRefusal::queue_full;
  }
  return r;
}

bool ArmService::output_on(std::size_t index) const {
  if (ctl_ == nullptr || index >= cfg_.outputs.size()) return false;
  const OutputBit& o = cfg_.outputs[index];
  return (ctl_->telemetry().outputs[static_cast<std::size_t>(o.joint)] >> o.bit) & 1u;
}

}  // namespace servoarm::fw

namespace servoarm::fw {

// ---------------------------------------------------------------------------
// Queries and settings
// ---------------------------------------------------------------------------

const char* to_string(Setting s) {
  switch (s) {
    case Setting::none: return "none";
    case Setting::default_joint_speed_pct: return "default_joint_speed_pct";
    case Setting::default_linear_speed: return "default_linear_speed";
    case Setting::max_linear_speed: return "max_linear_speed";
    case Setting::max_move_duration_s: return "max_move_duration_s";
    case Setting::default_blend_rad: return "default_blend_rad";
    case Setting::default_blend_m: return "default_blend_m";
    case Setting::home: return "home";
    case Setting::jog_speed_pct: return "jog_speed_pct";
    case Setting::jog_deadman_s: return "jog_deadman_s";
    case Setting::reply_timeout_s: return "reply_timeout_s";
    case Setting::outputs: return "outputs";
    case Setting::feed_override: return "feed_override";
  }
  return "?";
}

const char* to_string(JointHoming h) {
  switch (h) {
    case JointHoming::unhomed: return "unhomed";
    case JointHoming::homing: return "homing";
    case JointHoming::homed: return "homed";
    case JointHoming::failed: return "failed";
    case JointHoming::absolute: return "absolute";
  }
  return "?";
}

ArmStatus ArmService::status() const {
  ArmStatus s;
  s.feed_pct = feed_pct_;
  s.safety_on = cfg_.safety.enabled;
  s.safety_mode = plan_safety_mode();
  s.safety_checksum = cfg_.safety_checksum;
  s.q = kin::JointVector::Zero(n_);
  s.q_cmd = kin::JointVector::Zero(n_);
  s.temperature = kin::JointVector::Constant(n_, std::nan(""));
  s.homing.assign(static_cast<std::size_t>(n_), JointHoming::absolute);
  if (ctl_ == nullptr) return s;  // dry runs only: no arm to report
  const Telemetry t = ctl_->telemetry();
  s.state = t.state;
  s.safety_inputs = t.safety_inputs;
  s.mode = t.mode;
  s.holding = t.holding;
  s.queued = t.queued;
  s.running_id = t.running_id;
  s.done_id = t.done_id;
  s.cycles = t.cycles;
  s.t = static_cast<double>(t.cycles) * ctl_->period_s();
  for (int j = 0; j < n_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    s.q[j] = t.q_act[ju];
    s.q_cmd[j] = t.q_cmd[ju];
    if ((t.temperature_valid >> j) & 1u) s.temperature[j] = t.temperature[ju];
    JointHoming& h = s.homing[ju];
    if ((t.homing_now >> j) & 1u) h = JointHoming::homing;
    else if (static_cast<hal::HomingKind>(t.homing_kind[ju]) == hal::HomingKind::none) h = JointHoming::absolute;
    else if ((t.homed >> j) & 1u) h = JointHoming::homed;
    else if ((t.homing_failed >> j) & 1u) h = JointHoming::failed;
    else h = JointHoming::unhomed;
  }
  s.all_homed = t.all_homed();
  s.temperature_warning = t.temperature_warning;
  s.fault = t.cause;
  s.fault_joint = t.fault_joint;
  s.fault_text = bounded_text(t.fault_text);
  s.tool = tools_[tool_]->def.name;
  s.frame = frames_[frame_].name;
  if (kin::forward(tools_[tool_]->chain, s.q, s.pose) != kin::Status::ok) s.pose.translation().setConstant(std::nan(""));
  s.pose_in_frame = frames_[frame_].pose.inverse() * s.pose;
  s.feed_forward = static_cast<FeedForwardKind>(t.feed_forward);
  s.collision_on = t.collision_on;
  s.freedrive = static_cast<FreedrivePhase>(t.freedrive);
  return s;
}

ArmLimits ArmService::arm_limits() const {
  ArmLimits a;
  a.joints = lim_;
  for (int j = 0; j < n_; ++j) a.prismatic.push_back(chain_.joint(j).type == kin::JointType::prismatic);
  a.following_error = ctl_ != nullptr ? ctl_->config().following_error : 0.0;
  a.default_linear_speed = cfg_.default_linear_speed;
  a.max_linear_speed = cfg_.max_linear_speed;
  a.cartesian = cfg_.cartesian;
  return a;
}

namespace {
/// `v` within [lo, hi] (NaN is not); else `r` says which setting and its range.
bool in_range(Setting what, double v, double lo, double hi, SettingsResult& r) {
  if (v >= lo && v <= hi) return true;
  r.error = CmdError::out_of_range;
  r.setting = what;
  r.value = v, r.lower = lo, r.upper = hi;
  return false;
}
}  // namespace

SettingsResult ArmService::set_settings(const MotionSettings& s) {
  SettingsResult r;
  const double inf = std::numeric_limits<double>::infinity();
  const double v_min = kMinLinearSpeedMmS * 1e-3;
  if (!in_range(Setting::default_joint_speed_pct, s.default_joint_speed_pct, kMinJointSpeedPct, 100, r) ||
      !in_range(Setting::max_linear_speed, s.max_linear_speed, v_min, inf, r) ||
      !in_range(Setting::default_linear_speed, s.default_linear_speed, v_min, s.max_linear_speed, r) ||
      !in_range(Setting::max_move_duration_s, s.max_move_duration_s, 1e-3, inf, r) ||
      !in_range(Setting::default_blend_rad, s.default_blend_rad, 0, inf, r) ||
      !in_range(Setting::default_blend_m, s.default_blend_m, 0, inf, r) ||
      !in_range(Setting::jog_speed_pct, s.jog_speed_pct, kMinJointSpeedPct, 100, r) ||
      !in_range(Setting::jog_deadman_s, s.jog_deadman_s, 1e-3, 10, r) ||
      !in_range(Setting::reply_timeout_s, s.reply_timeout_s, 1e-3, 60, r))
    return r;
  if (s.home.size() != n_) {
    r.error = CmdError::bad_option;
    r.setting = Setting::home;
    r.value = static_cast<double>(s.home.size());
    r.lower = r.upper = n_;
    return r;
  }
  for (int j = 0; j < n_; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    if (!in_range(Setting::home, s.home[j], lim_.lower[ju], lim_.upper[ju], r)) {
      r.error = CmdError::limits;
      r.joint = j;
      return r;
    }
  }
  if (s.outputs.size() != cfg_.outputs.size()) {
    r.error = CmdError::bad_option;
    r.setting = Setting::outputs;
    r.value = static_cast<double>(s.outputs.size());
    r.lower = r.upper = static_cast<double>(cfg_.outputs.size());
    return r;
  }
  const std::vector<OutputBit> outputs = cfg_.outputs;  // fixed at start: the drives' wiring
  cfg_ = s;
  cfg_.outputs = outputs;
  return r;
}

SettingsResult ArmService::set_feed_override(int pct) {
  SettingsResult r;
  if (in_range(Setting::feed_override, pct, kMinFeedOverride, kMaxFeedOverride, r)) feed_pct_ = pct;
  return r;
}

}  // namespace servoarm::fw

namespace servoarm::fw {

const char* to_string(ServiceOp op) {
  for (const ServiceOpInfo& i : kServiceOps)
    if (i.op == op) return i.name;
  return "?";
}

bool service_op_from(std::string_view name, ServiceOp& op) {
  for (const ServiceOpInfo& i : kServiceOps)
    if (name == i.name) {
      op = i.op;
      return true;
    }
  return false;
}

}  // namespace servoarm::fw
