// SPDX-License-Identifier: Apache-2.0
#include "controller_rig.hpp"

#include <utility>

#include "alloc_counter.hpp"

#include <CppUTest/TestHarness.h>

namespace servoarm::test {

using namespace fw;

kin::JointVector deg(std::initializer_list<double> degrees) {
  kin::JointVector q(static_cast<Eigen::Index>(degrees.size()));
  Eigen::Index j = 0;
  for (const double d : degrees) q[j++] = d * kDeg;
  return q;
}

kin::JointVector puma_work_pose() { return deg({0, -45, 180, 0, 45, 0}); }

ControllerRig::ControllerRig(FwConfig cfg, const RigOptions& options) {
  app.sim_motor = options.motor;
  cfg.can = "sim";
  const std::string e = app.build(cfg, &clock);
  if (!e.empty()) FAIL(e.c_str());
  ctl_ = app.ctl.get();
  if (options.before_boot) options.before_boot(app);
  clock.set_idle_hook([this](hal::TimePoint t) { app.step_plants(t); });
  if (!options.boot) return;
  const std::string b = app.boot();
  if (!b.empty()) FAIL(b.c_str());
  app.console->set_idle([this] { cycle(); });
}

ControllerRig::ControllerRig(FwConfig cfg, std::function<void(SimApp&)> before_boot)
    : ControllerRig(std::move(cfg), RigOptions{sim::MotorParams{}, std::move(before_boot), true}) {}

ControllerRig::~ControllerRig() { clock.set_idle_hook(nullptr); }

kin::JointVector ControllerRig::joints(bool commanded) const {
  const Telemetry t = tel();
  const auto& src = commanded ? t.q_cmd : t.q_act;
  kin::JointVector q(static_cast<Eigen::Index>(app.chain.n_joints));
  for (Eigen::Index j = 0; j < q.size(); ++j) q[j] = src[static_cast<std::size_t>(j)];
  return q;
}

kin::JointVector ControllerRig::q_cmd() const { return joints(true); }
kin::JointVector ControllerRig::q_act() const { return joints(false); }

kin::Pose ControllerRig::flange(const kin::JointVector& q) const {
  kin::Pose p;
  CHECK(kin::forward(app.chain, q, p) == kin::Status::ok);
  return p;
}

void ControllerRig::cycle() {
  if (count_allocs) alloc_count_begin();
  ctl_->cycle(clock.now());
  if (count_allocs) rt_allocs += alloc_count_end();
  clock.advance(period);
  if (after_cycle) after_cycle();
}

void ControllerRig::cycles(int n) {
  for (int i = 0; i < n; ++i) cycle();
}

void ControllerRig::until_idle(int max_cycles) {
  for (int i = 0; i < max_cycles && (!ctl_->motions().empty() || tel().state != ArmState::idle); ++i) cycle();
}

void ControllerRig::enable() {
  const ControlResult r = svc().enable();
  CHECK_TEXT(r.ok(), r.reason.c_str());
  for (int i = 0; i < 3000 && tel().state != ArmState::idle; ++i) cycle();
  CHECK(tel().state == ArmState::idle);
}

MoveResult ControllerRig::movej(const kin::JointVector& goal, const MoveContext& cx) {
  MoveJoints m;
  m.goal = goal;
  return svc().move(m, cx);
}

MoveResult ControllerRig::movel(const kin::Pose& target, double speed) {
  MoveLine m;
  m.target = target;
  m.speed = speed;
  MoveContext cx;
  cx.ik = app.console->jog_context().ik;
  return svc().move(m, cx);
}

void ControllerRig::start_move(int more_cycles) {
  kin::JointVector goal = kin::JointVector::Zero(static_cast<Eigen::Index>(app.chain.n_joints));
  goal[0] = 60 * kDeg;
  goal[1] = -30 * kDeg;
  const MoveResult r = movej(goal);
  CHECK_TEXT(r.ok(), r.reason.c_str());
  for (int i = 0; i < 300 && tel().state != ArmState::moving; ++i) cycle();
  CHECK(tel().state == ArmState::moving);
  cycles(more_cycles);
}

void ControllerRig::queue_unchecked_joint_move(std::uint32_t id, const kin::JointVector& goal, double override) {
  MotionItem* m = ctl_->motions().back();
  CHECK(m != nullptr);
  m->id = id;
  JointMove& jm = m->payload.emplace<JointMove>();
  jm.goal = goal;
  jm.override = override;
  jm.plan.n = 0;
  ctl_->motions().commit();
}

std::string ControllerRig::console(const std::string& line) {
  session.out.clear();
  app.console->execute(session, line);
  for (int i = 0; i < 60000 && app.console->busy(session); ++i) {
    cycle();
    app.console->poll(session);
  }
  return session.out;
}

std::string ControllerRig::events() {
  svc().poll_events();
  std::string all;
  for (const ArmEvent& e : svc().events_since(0).events) all += std::string(svc().event_detail(e)) + "\n";
  return all;
}

std::string ControllerRig::last_event() {
  svc().poll_events();
  const EventBatch b = svc().events_since(0);
  return b.events.empty() ? std::string() : std::string(svc().event_detail(b.events.back()));
}

}  // namespace servoarm::test
