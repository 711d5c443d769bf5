// SPDX-License-Identifier: Apache-2.0
// The plan-time envelope check slows a move that a stop distance or a power limit binds to the
// fastest scale that keeps the limit, not below it (docs/safety.md#before-motion): the check's
// own highest ratio along the plan (MoveResult::envelope_ratio, the stop limits at the run-time
// speed scale's aim SafetyMonitor::kStopAim) is within 1 and within 2 % of it, the motion run on the controller (its predicted stop, its power, from the
// commanded state every cycle) comes near the aimed limit without passing it, and it runs for
// the planned duration (within two cycles: the run-time scale does not engage on it). Prints the planned
// and run durations and the planning time (the median of 7 dry runs; no timing assert: the
// machine is shared).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "../console/console_rig.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/kinematics/dynamics.hpp"
#include "servoarm/service/arm_service.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;

namespace {

constexpr double kDeg = M_PI / 180.0;

kin::JointVector joints(std::initializer_list<double> deg) {
  kin::JointVector q(static_cast<int>(deg.size()));
  int j = 0;
  for (double d : deg) q[j++] = d * kDeg;
  return q;
}

const kin::JointVector& start() {
  static const kin::JointVector q = joints({0, -45, 180, 0, 45, 0});
  return q;
}

Eigen::Vector3d tool_at(const kin::Chain& c, const kin::JointVector& q) {
  kin::Pose p;
  CHECK(kin::forward(c, q, p) == kin::Status::ok);
  return p.translation();
}

/// An envelope with only the limits the test sets: a plane far below the start pose (the
/// envelope needs a function to be on), no TCP speed limit.
FwConfig envelope() {
  const kin::LoadResult lr = kin::load_robot("puma560");
  CHECK_TEXT(lr.ok, lr.error.c_str());
  FwConfig c;
  c.safety_planes = {0, 0, 1, tool_at(lr.chain, start()).z() * 1000.0 - 500.0};
  c.safety_tool_radius_mm = 10;
  return c;
}

/// The median wall time (ms) of planning `plan` 7 times as a dry run from the start pose.
template <class F>
double median_plan_ms(ArmService& svc, const MoveContext& cx, F plan) {
  std::vector<double> ms;
  for (int i = 0; i < 7; ++i) {
    PathShadow shadow;
    DryRun dry;
    dry.tail = start();
    dry.shadow = &shadow;
    MoveContext d = cx;
    d.dry = &dry;
    const auto t0 = std::chrono::steady_clock::now();
    const MoveResult res = plan(svc, d);
    ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    CHECK_TEXT(res.ok(), res.reason.c_str());
  }
  std::sort(ms.begin(), ms.end());
  return ms[ms.size() / 2];
}

/// Runs the queue to rest; the highest predicted stop distance (mm, plan_stop on the
/// controller's limits from the commanded state) and mechanical power (W, inverse dynamics at
/// the commanded state), the acceleration differenced from the velocities.
void run_to_rest(test::ConsoleRig& r, double& stop_mm, double& power_w, double* run_s = nullptr) {
  stop_mm = power_w = 0;
  int cycles = 0;
  const kin::Chain& ch = r.app.chain;
  const double dt = 1e-3;
  kin::JointState st;
  st.pos = st.vel = st.acc = kin::JointVector::Zero(6);
  kin::JointVector tau(6);
  kin::JointTrajectory stop;
  for (int i = 0; i < 60000 && (!r.app.ctl->motions().empty() || r.app.ctl->telemetry().state != ArmState::idle); ++i) {
    r.cycle();
    const Telemetry t = r.app.ctl->telemetry();
    ++cycles;
    for (int j = 0; j < 6; ++j) {
      const auto ju = static_cast<std::size_t>(j);
      st.acc[j] = i == 0 ? 0.0 : (t.qd_cmd[ju] - st.vel[j]) / dt;
      st.pos[j] = t.q_cmd[ju];
      st.vel[j] = t.qd_cmd[ju];
    }
    CHECK(kin::plan_stop(r.app.ctl->limits(), st, kin::MovejOptions{}, stop) == kin::MotionStatus::ok);
    stop_mm = std::fmax(stop_mm, (tool_at(ch, stop.goal) - tool_at(ch, st.pos)).norm() * 1e3);
    if (ch.has_inertial && kin::inverse_dynamics(ch, st.pos, st.vel, st.acc, tau) == kin::Status::ok) {
      double w = 0;
      for (int j = 0; j < 6; ++j) w += std::fabs(tau[j] * st.vel[j]);
      power_w = std::fmax(power_w, w);
    }
  }
  if (run_s != nullptr) *run_s = cycles * dt;
}

void back_to_start(test::ConsoleRig& r, ArmService& svc, const MoveContext& cx) {
  MoveJoints back;
  back.goal = start();
  CHECK(svc.move(back, cx).ok());
  double d = 0, w = 0;
  run_to_rest(r, d, w);
}

}  // namespace

TEST_GROUP(EnvelopeScale){};

// A movej of joints 1 and 2 at 100 % and a 250 mm/s movel, each under a 12 mm stop distance:
// slowed to within 2 % of the fastest scale the check passes (its highest ratio, the stop
// limits at the run-time aim of 0.85 of them, 0.98..1). Run on the controller, the predicted
// stop stays within 0.85 of the limit (+2 %: differenced) and reaches 0.8 of that, and the move
// runs for its planned duration (docs/safety.md#speed-scaling).
TEST(EnvelopeScale, AStopDistanceLimitedMoveRunsAtTheLimitNotBelowIt) {
  FwConfig c = envelope();
  constexpr double kLimitMm = 12;
  c.safety_stop_distance_mm = kLimitMm;
  test::ConsoleRig r(c);
  r.enable();
  ArmService& svc = r.app.console->service();
  MoveContext cx;
  cx.ik = r.app.console->jog_context().ik;
  back_to_start(r, svc, cx);
  MoveJoints quick;
  quick.goal = joints({60, -25, 180, 0, 45, 0});
  quick.speed_pct = 100;
  MoveLine side;
  kin::forward(r.app.chain, start(), side.target);
  side.target.translation().y() -= 0.2;
  side.speed = 0.25;
  double plan_ms[2] = {0, 0};  // (timed first: the figures of both, whatever the checks below find)
  for (const bool line : {false, true})
    plan_ms[line] = median_plan_ms(svc, cx, [&](ArmService& s, const MoveContext& m) {
      return line ? s.move(side, m) : s.move(quick, m);
    });
  std::printf("\n  planning time (median of 7 dry runs): movej %.2f ms, movel %.2f ms", plan_ms[0], plan_ms[1]);
  for (const bool line : {false, true}) {
    const MoveResult q = line ? svc.move(side, cx) : svc.move(quick, cx);
    CHECK_TEXT(q.ok(), q.reason.c_str());
    double stop_mm = 0, power_w = 0, run_s = 0;
    run_to_rest(r, stop_mm, power_w, &run_s);
    char fig[240];
    std::snprintf(fig, sizeof fig,
                  "%s under a %.0f mm stop distance: planned %.3f s (%s), the check's highest ratio %.4f; ran %.3f s, "
                  "predicted stop at most %.2f mm; planned in %.2f ms (median of 7)",
                  line ? "movel" : "movej", kLimitMm, q.duration,
                  line ? (std::to_string(int(std::lround(q.speed * 1e3))) + " mm/s").c_str() : "joints 1 and 2",
                  q.envelope_ratio, run_s, stop_mm, plan_ms[line]);
    std::printf("\n  %s", fig);
    const double aimed_mm = kLimitMm * SafetyMonitor::kStopAim;
    CHECK_TEXT(q.envelope_ratio <= 1.0, fig);
    CHECK_TEXT(q.envelope_ratio >= 0.98, fig);
    CHECK_TEXT(stop_mm <= aimed_mm * 1.02, fig);
    CHECK_TEXT(stop_mm >= aimed_mm * 0.8, fig);
    CHECK_TEXT(std::fabs(run_s - q.duration) <= 2e-3 + 1e-9, fig);
    back_to_start(r, svc, cx);
  }
  CHECK_EQUAL(0u, r.app.ctl->telemetry().safety_stops);
}

// A movej of joints 1 and 2 at 100 % under a 20 W power limit (the puma560's inertial data):
// slowed to within 2 % of the fastest scale the check passes, and run on the controller its
// power reaches 0.9 of the limit without passing it (+3 %: the acceleration differenced) and it
// runs for its planned duration (power is aimed at the limit itself, as the run-time scale does).
TEST(EnvelopeScale, APowerLimitedMoveRunsAtTheLimitNotBelowIt) {
  FwConfig c = envelope();
  constexpr double kLimitW = 20;
  c.safety_power_w = kLimitW;
  test::ConsoleRig r(c);
  CHECK(r.app.chain.has_inertial);
  r.enable();
  ArmService& svc = r.app.console->service();
  MoveContext cx;
  cx.ik = r.app.console->jog_context().ik;
  back_to_start(r, svc, cx);
  MoveJoints quick;
  quick.goal = joints({60, -25, 180, 0, 45, 0});
  quick.speed_pct = 100;
  auto plan = [&](ArmService& s, const MoveContext& m) { return s.move(quick, m); };
  const double plan_ms = median_plan_ms(svc, cx, plan);
  const MoveResult q = plan(svc, cx);
  CHECK_TEXT(q.ok(), q.reason.c_str());
  double stop_mm = 0, power_w = 0, run_s = 0;
  run_to_rest(r, stop_mm, power_w, &run_s);
  char fig[240];
  std::snprintf(fig, sizeof fig,
                "movej under a %.0f W power limit: planned %.3f s, the check's highest ratio %.4f; ran %.3f s, power at "
                "most %.2f W; planned in %.1f ms (median of 7)",
                kLimitW, q.duration, q.envelope_ratio, run_s, power_w, plan_ms);
  std::printf("\n  %s", fig);
  CHECK_TEXT(q.envelope_ratio <= 1.0, fig);
  CHECK_TEXT(q.envelope_ratio >= 0.98, fig);
  CHECK_TEXT(std::fabs(run_s - q.duration) <= 2e-3 + 1e-9, fig);
  CHECK_TEXT(power_w <= kLimitW * 1.03, fig);
  CHECK_TEXT(power_w >= kLimitW * 0.9, fig);
  CHECK_EQUAL(0u, r.app.ctl->telemetry().safety_stops);
}
