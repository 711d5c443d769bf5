// SPDX-License-Identifier: Apache-2.0
// The safety envelope's run-time monitor in the control cycle (firmware/rt/src/safety_monitor.cpp,
// Controller::step_safety) on the puma560 with virtual drives, sampled every cycle:
//  - a continuous tool jog straight down towards a table plane at 100, 250 and 500 mm/s comes
//    to rest at the plane (the tool sphere's commanded and measured lowest point within the
//    tolerance of it), with an event naming the plane; a jog away from it is let go;
//  - a move the planner never saw (put in the motion queue directly) that dips through the
//    plane is stopped by a protective stop (ramp to rest, then idle) in the cycle its commanded
//    TCP passes the tolerance, with an event naming the function, limit and value;
//  - no allocation on the control thread (the allocation counter around every cycle).
// The figures (overshoot, cycles from violation to stop) are printed for tests/bench/RESULTS.md.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "../support/sim_app.hpp"
#include "alloc_counter.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/service/arm_service.hpp"
#include "servoarm/service/stream.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;

namespace {

constexpr double kDeg = M_PI / 180.0;
constexpr double kBelowMm = 60.0;   // the plane below the tool at the work pose
constexpr double kRadiusMm = 10.0;  // the tool sphere
constexpr double kTolMm = 2.0;      // safety.tolerance_mm

kin::JointVector work_pose() {
  kin::JointVector q(6);
  const double d[6] = {0, -45, 180, 0, 45, 0};
  for (int j = 0; j < 6; ++j) q[j] = d[j] * kDeg;
  return q;
}

double plane_mm() {
  const kin::LoadResult lr = kin::load_robot("puma560");
  kin::Pose p;
  (void)kin::forward(lr.chain, work_pose(), p);
  return p.translation().z() * 1000.0 - kBelowMm;
}

struct Trace;
void trace_add(Trace& t, struct Rig& r);

struct Rig {
  hal::ManualClock clock;
  test::SimApp app;
  hal::Duration period = hal::kMillisecond;
  std::size_t rt_allocs = 0;
  double low_cmd = INFINITY, low_act = INFINITY;  // lowest sphere bottom (mm), commanded / measured
  Trace* trace = nullptr;  // set: every cycle is added to it

  explicit Rig(FwConfig cfg) {
    cfg.can = "sim";
    const std::string e = app.build(cfg, &clock);
    if (!e.empty()) FAIL(e.c_str());
    clock.set_idle_hook([this](hal::TimePoint t) { app.plant->step(t); });
    const std::string b = app.boot();
    if (!b.empty()) FAIL(b.c_str());
    app.console->set_idle([this] { cycle(); });
  }
  ~Rig() { clock.set_idle_hook(nullptr); }
  ArmService& svc() { return app.console->service(); }
  Telemetry tel() const { return app.ctl->telemetry(); }
  double tool_z_mm(bool commanded) const {
    const Telemetry t = tel();
    kin::JointVector q(6);
    for (int j = 0; j < 6; ++j) q[j] = commanded ? t.q_cmd[std::size_t(j)] : t.q_act[std::size_t(j)];
    kin::Pose p;
    (void)kin::forward(app.chain, q, p);
    return p.translation().z() * 1000.0;
  }
  void cycle() {
    test::alloc_count_begin();
    app.ctl->cycle(clock.now());
    rt_allocs += test::alloc_count_end();
    clock.advance(period);
    low_cmd = std::fmin(low_cmd, tool_z_mm(true) - kRadiusMm);
    low_act = std::fmin(low_act, tool_z_mm(false) - kRadiusMm);
    if (trace != nullptr) trace_add(*trace, *this);
  }
  void until_idle(int max_cycles) {
    for (int i = 0; i < max_cycles && (!app.ctl->motions().empty() || tel().state != ArmState::idle); ++i) cycle();
  }
  void enable() {
    CHECK(svc().enable().ok());
    for (int i = 0; i < 3000 && tel().state != ArmState::idle; ++i) cycle();
    CHECK(tel().state == ArmState::idle);
  }
  void to_work() {
    MoveJoints m;
    m.goal = work_pose();
    const MoveResult r = svc().move(m, MoveContext{});
    CHECK_TEXT(r.ok(), r.reason.c_str());
    until_idle(30000);
    low_cmd = low_act = INFINITY;
  }
  std::string last_event() {
    svc().poll_events();
    const EventBatch b = svc().events_since(0);
    return b.events.empty() ? std::string() : std::string(svc().event_detail(b.events.back()));
  }
};

FwConfig table(double max_speed_mm_s) {
  FwConfig c;
  c.safety_planes = {0, 0, 1, plane_mm()};
  c.safety_tool_radius_mm = kRadiusMm;
  c.safety_tolerance_mm = kTolMm;
  c.max_linear_speed_mm_s = max_speed_mm_s;
  return c;
}

}  // namespace

TEST_GROUP(SafetyMonitor){};

// A continuous tool jog straight down at 100, 250 and 500 mm/s stops at the plane: the
// commanded and the measured sphere stay above plane - tolerance; the event names the plane.
// Then a jog straight up (away) runs.
TEST(SafetyMonitor, AJogTowardsAPlaneStopsAtItAndMayMoveAway) {
  for (const double speed : {100.0, 250.0, 500.0}) {
    Rig r(table(500));
    r.enable();
    r.to_work();
    const double plane = plane_mm();
    ToolJog down;
    down.axis = 2;
    down.continuous = true;
    down.direction = -1;
    down.speed_pct = speed / 500.0 * 100.0;
    const JogContext jc = r.app.console->jog_context();
    const JogResult j = r.svc().jog(down, jc);
    CHECK_TEXT(j.ok(), j.reason.c_str());
    int cycles = 0;
    for (; cycles < 20000; ++cycles) {
      if (cycles % 100 == 0 && r.tel().state == ArmState::jogging) (void)r.svc().jog_keepalive();
      r.cycle();
      if (r.tel().state == ArmState::idle) break;
    }
    for (int i = 0; i < 200; ++i) r.cycle();  // the measured arm settles
    char fig[160];
    std::snprintf(fig, sizeof fig, "jog at %.0f mm/s: commanded %.3f mm, measured %.3f mm past the plane (tolerance %.1f)",
                  speed, plane - r.low_cmd, plane - r.low_act, kTolMm);
    std::printf("\n  %s", fig);
    CHECK_TEXT(r.tel().state == ArmState::idle, fig);
    CHECK_TEXT(r.low_cmd >= plane - kTolMm, fig);
    CHECK_TEXT(r.low_act >= plane - kTolMm, fig);
    CHECK_TEXT(r.low_cmd <= plane + 5.0, fig);  // it did come down to the plane
    const std::string ev = r.last_event();
    STRCMP_CONTAINS("jog stopped at the plane 0 (tool sphere)", ev.c_str());
    // away from it: the jog runs, the tool rises
    const double z0 = r.tool_z_mm(true);
    ToolJog up = down;
    up.direction = 1;
    up.continuous = false;
    up.increment = 0.02;
    const JogResult u = r.svc().jog(up, jc);
    CHECK_TEXT(u.ok(), u.reason.c_str());
    for (int i = 0; i < 5000 && r.tel().state == ArmState::jogging; ++i) r.cycle();
    DOUBLES_EQUAL(z0 + 20.0, r.tool_z_mm(true), 0.5);
    LONGS_EQUAL(0, r.rt_allocs);
  }
}

// A move the planner never checked (queued directly) dips through the plane: a protective
// stop starts in the cycle the commanded sphere passes the tolerance, the arm ramps to rest and
// stays powered (idle), the queue is emptied, the event names the plane, limit and value.
TEST(SafetyMonitor, AnUncheckedMoveThroughAPlaneGetsAProtectiveStop) {
  Rig r(table(250));
  r.enable();
  r.to_work();
  const double plane = plane_mm();
  MotionItem* m = r.app.ctl->motions().back();
  CHECK(m != nullptr);
  m->id = 900;
  JointMove& jm = m->payload.emplace<JointMove>();
  jm.goal = work_pose();
  jm.goal[1] += 25 * kDeg;  // swings the tool down through the table
  jm.override = 0.5;
  jm.plan.n = 0;
  r.app.ctl->motions().commit();
  int crossed = -1, stopped = -1;
  for (int i = 0; i < 20000; ++i) {
    r.cycle();
    const double bottom = r.tool_z_mm(true) - kRadiusMm;
    if (crossed < 0 && bottom < plane - kTolMm) crossed = i;
    if (stopped < 0 && r.tel().state == ArmState::stopping) stopped = i;
    if (stopped >= 0 && r.tel().state == ArmState::idle) break;
  }
  std::printf("\n  protective stop: commanded sphere past the tolerance in cycle %d, stop ramp from cycle %d; "
              "lowest commanded %.3f mm past the plane",
              crossed, stopped, plane - r.low_cmd);
  CHECK(crossed >= 0);
  CHECK(stopped == crossed);  // the same cycle
  CHECK(r.tel().state == ArmState::idle);  // at rest, powered, holding
  CHECK(r.app.ctl->motions().empty());
  const std::string ev = r.last_event();
  STRCMP_CONTAINS("protective stop (commanded): plane 0 (tool sphere)", ev.c_str());
  STRCMP_CONTAINS("limit ", ev.c_str());
  STRCMP_CONTAINS("value ", ev.c_str());
  CHECK_EQUAL(1u, r.tel().safety_stops);
  LONGS_EQUAL(0, r.rt_allocs);
}

// The same table plane given in a user frame (safety.plane_frames: [0, 0, -1, -100] in a frame
// 100 mm above the table turned 180 deg about x): the unchecked move through it gets the
// protective stop in the cycle its commanded sphere passes the tolerance, naming the plane.
TEST(SafetyMonitor, APlaneInAUserFrameStopsAnUncheckedMove) {
  FwConfig c = table(250);
  const double plane = plane_mm();
  char toml[256];
  std::snprintf(toml, sizeof toml, "[safety]\nplanes = [0, 0, -1, -100]\nplane_frames = [0, 0, %.6f, 180, 0, 0]\n",
                plane + 100.0);
  const std::string e = load_config_text(toml, "frame.toml", c);
  CHECK_TEXT(e.empty(), e.c_str());
  Rig r(c);
  r.enable();
  r.to_work();
  MotionItem* m = r.app.ctl->motions().back();
  CHECK(m != nullptr);
  m->id = 901;
  JointMove& jm = m->payload.emplace<JointMove>();
  jm.goal = work_pose();
  jm.goal[1] += 25 * kDeg;
  jm.override = 0.5;
  jm.plan.n = 0;
  r.app.ctl->motions().commit();
  int crossed = -1, stopped = -1;
  for (int i = 0; i < 20000; ++i) {
    r.cycle();
    if (crossed < 0 && r.tool_z_mm(true) - kRadiusMm < plane - kTolMm) crossed = i;
    if (stopped < 0 && r.tel().state == ArmState::stopping) stopped = i;
    if (stopped >= 0 && r.tel().state == ArmState::idle) break;
  }
  CHECK(crossed >= 0);
  CHECK_EQUAL(crossed, stopped);
  STRCMP_CONTAINS("protective stop (commanded): plane 0 (tool sphere)", r.last_event().c_str());
  LONGS_EQUAL(0, r.rt_allocs);
}

// The active tool's own sphere (tool define ... radius=): with a tool whose sphere is 40 mm
// (safety.tool_radius_mm 10), the unchecked move through the table gets its protective stop in
// the cycle the 40 mm sphere passes the tolerance, cycles before a 10 mm one would.
TEST(SafetyMonitor, TheActiveToolsRadiusIsTheMonitorsSphere) {
  int at_radius[2] = {-1, -1};
  for (int k = 0; k < 2; ++k) {
    const double radius = k == 0 ? kRadiusMm : 40.0;
    Rig r(table(250));
    r.enable();
    r.to_work();
    if (k == 1) {
      NamedPose big;
      big.name = "big";
      big.radius = radius * 1e-3;
      const FrameResult d = r.svc().define_tool(big);
      CHECK_TEXT(d.ok(), d.reason.c_str());
      CHECK(r.svc().select_tool("big").ok());
    }
    const double plane = plane_mm();
    MotionItem* m = r.app.ctl->motions().back();
    CHECK(m != nullptr);
    m->id = 902;
    JointMove& jm = m->payload.emplace<JointMove>();
    jm.goal = work_pose();
    jm.goal[1] += 25 * kDeg;
    jm.override = 0.5;
    jm.plan.n = 0;
    r.app.ctl->motions().commit();
    int crossed = -1, stopped = -1;
    for (int i = 0; i < 20000; ++i) {
      r.cycle();
      if (crossed < 0 && r.tool_z_mm(true) - radius < plane - kTolMm) crossed = i;
      if (stopped < 0 && r.tel().state == ArmState::stopping) stopped = i;
      if (stopped >= 0 && r.tel().state == ArmState::idle) break;
    }
    CHECK(crossed >= 0);
    CHECK_EQUAL(crossed, stopped);
    STRCMP_CONTAINS("protective stop (commanded): plane 0 (tool sphere)", r.last_event().c_str());
    LONGS_EQUAL(0, r.rt_allocs);
    at_radius[k] = stopped;
  }
  std::printf("\n  protective stop in cycle %d with a 10 mm sphere, %d with the 40 mm tool", at_radius[0], at_radius[1]);
  CHECK(at_radius[1] < at_radius[0]);
}

// A trigger plane at run time: a planned line sideways into the zone and back runs without a
// protective stop (planned at the Reduced 100 mm/s), the monitor switches to Reduced with an
// event naming the plane as the commanded sphere crosses it and back to Normal when it leaves;
// a joint move the planner never saw, fast (no Normal TCP limit), gets a protective stop on the
// Reduced TCP limit once inside.
TEST(SafetyMonitor, ATriggerPlaneSwitchesToReducedWhileTheToolIsBeyondIt) {
  FwConfig c = table(250);
  c.safety_tcp_speed_mm_s = 0;
  c.safety_reduced_tcp_speed_mm_s = 100;
  kin::Pose w;
  {
    const kin::LoadResult lr = kin::load_robot("puma560");
    (void)kin::forward(lr.chain, work_pose(), w);
  }
  const double y_plane = w.translation().y() * 1000.0 + 50.0;
  c.safety_reduced_planes = {0, -1, 0, -y_plane};  // Reduced where the sphere reaches past y_plane
  Rig r(c);
  r.enable();
  r.to_work();
  MoveContext cx;
  cx.ik = r.app.console->jog_context().ik;
  MoveLine side;
  side.target = w;
  side.target.translation().y() += 0.1;
  side.speed = 0.2;
  const MoveResult in = r.svc().move(side, cx);
  CHECK_TEXT(in.ok(), in.reason.c_str());
  MoveLine back = side;
  back.target = w;
  const MoveResult out = r.svc().move(back, cx);
  CHECK_TEXT(out.ok(), out.reason.c_str());
  int entered = -1, left = -1;
  double vmax_in = 0, y_prev = NAN;
  std::string ev_in, ev_out;
  for (int i = 0; i < 20000 && (!r.app.ctl->motions().empty() || r.tel().state != ArmState::idle); ++i) {
    r.cycle();
    const Telemetry t = r.tel();
    kin::JointVector q(6);
    for (int j = 0; j < 6; ++j) q[j] = t.q_cmd[std::size_t(j)];
    kin::Pose p;
    (void)kin::forward(r.app.chain, q, p);
    const double y = p.translation().y() * 1000.0;
    const bool beyond = y + kRadiusMm > y_plane;
    if (beyond && !std::isnan(y_prev)) vmax_in = std::fmax(vmax_in, std::fabs(y - y_prev) / 1e-3);
    y_prev = y;
    if (entered < 0 && t.safety_zone == 0) {
      entered = i;
      ev_in = r.last_event();
      CHECK(beyond);
    }
    if (entered >= 0 && left < 0 && t.safety_zone < 0) {
      left = i;
      ev_out = r.last_event();
      CHECK(!beyond);
    }
  }
  std::printf("\n  trigger plane: entered in cycle %d, left in cycle %d, highest speed inside %.1f mm/s", entered, left,
              vmax_in);
  CHECK(entered >= 0 && left > entered);
  STRCMP_CONTAINS("safety mode reduced: the tool entered reduced plane 0", ev_in.c_str());
  STRCMP_CONTAINS("safety mode normal: the tool left reduced plane 0", ev_out.c_str());
  CHECK(vmax_in <= 100.0 + 1.0);
  CHECK_EQUAL(0u, r.tel().safety_stops);
  // an unchecked fast joint move into the zone (joint 1 swings the tool towards +y)
  MotionItem* m = r.app.ctl->motions().back();
  CHECK(m != nullptr);
  m->id = 903;
  JointMove& jm = m->payload.emplace<JointMove>();
  jm.goal = work_pose();
  jm.goal[0] += (w.translation().x() > 0 ? 20 : -20) * kDeg;
  jm.override = 1.0;
  jm.plan.n = 0;
  r.app.ctl->motions().commit();
  for (int i = 0; i < 20000; ++i) {
    r.cycle();
    if (r.tel().safety_stops > 0 && r.tel().state == ArmState::idle) break;
  }
  CHECK_EQUAL(1u, r.tel().safety_stops);
  STRCMP_CONTAINS("protective stop (commanded): tcp speed", r.last_event().c_str());
  STRCMP_CONTAINS("limit 100.0 mm/s", r.last_event().c_str());
  LONGS_EQUAL(0, r.rt_allocs);
}

// The elbow sphere (safety.elbow_frame = 3, 30 mm) against a vertical plane (x = const) the
// elbow crosses half-way through a 40 deg turn of joint 1 (the tool stays on the allowed side): the planner
// refuses the movej naming the elbow sphere; the same move queued directly gets a protective
// stop in the cycle the commanded elbow sphere passes the tolerance, computed here by FK.
TEST(SafetyMonitor, TheElbowSphereAgainstAVerticalPlane) {
  const kin::LoadResult lr = kin::load_robot("puma560");
  kin::JointVector goal = work_pose();
  goal[0] += 40 * kDeg;
  auto elbow_at = [&](const kin::JointVector& q) {
    kin::FrameSet f;
    kin::Pose t;
    (void)kin::forward_frames(lr.chain, q, f, t);
    return Eigen::Vector3d(f.frame[3].translation());
  };
  // the plane x = midway between where the elbow starts and ends (joint 1 turns both the elbow
  // and the tool about z, their x shrinking; the tool, further out, stays beyond the plane)
  const Eigen::Vector3d e0 = elbow_at(work_pose()), e1 = elbow_at(goal);
  const Eigen::Vector3d n(1, 0, 0);
  const double off_mm = n.dot(0.5 * (e0 + e1)) * 1000.0;
  constexpr double kElbowMm = 30.0;
  FwConfig c;
  c.safety_planes = {n.x(), n.y(), 0.0, off_mm};
  c.safety_tool_radius_mm = kRadiusMm;
  c.safety_elbow_frame = 3;
  c.safety_elbow_radius_mm = kElbowMm;
  c.safety_tolerance_mm = kTolMm;
  // the tool stays on the allowed side all along (so the elbow is what the plane stops)
  for (int k = 0; k <= 40; ++k) {
    kin::JointVector q = work_pose();
    q[0] += k * kDeg;
    kin::Pose t;
    (void)kin::forward(lr.chain, q, t);
    CHECK(n.dot(t.translation()) * 1000.0 - kRadiusMm > off_mm + 5.0);
  }
  Rig r(c);
  r.enable();
  r.to_work();
  MoveJoints mj;
  mj.goal = goal;
  const MoveResult no = r.svc().move(mj, MoveContext{});
  CHECK(no.error == CmdError::limits);
  STRCMP_CONTAINS("safety plane 0 (elbow sphere)", no.reason.c_str());
  MotionItem* m = r.app.ctl->motions().back();
  CHECK(m != nullptr);
  m->id = 904;
  JointMove& jm = m->payload.emplace<JointMove>();
  jm.goal = goal;
  jm.override = 0.5;
  jm.plan.n = 0;
  r.app.ctl->motions().commit();
  int crossed = -1, stopped = -1;
  double worst = -INFINITY;
  for (int i = 0; i < 20000; ++i) {
    r.cycle();
    const Telemetry t = r.tel();
    kin::JointVector q(6);
    for (int j = 0; j < 6; ++j) q[j] = t.q_cmd[std::size_t(j)];
    const double past = off_mm - (n.dot(elbow_at(q)) * 1000.0 - kElbowMm);  // mm beyond the plane
    worst = std::fmax(worst, past);
    if (crossed < 0 && past > kTolMm) crossed = i;
    if (stopped < 0 && t.state == ArmState::stopping) stopped = i;
    if (stopped >= 0 && t.state == ArmState::idle) break;
  }
  std::printf("\n  elbow: past the tolerance in cycle %d, stop from cycle %d, elbow sphere at most %.2f mm past the plane",
              crossed, stopped, worst);
  CHECK(crossed >= 0);
  CHECK_EQUAL(crossed, stopped);
  STRCMP_CONTAINS("protective stop (commanded): plane 0 (elbow sphere)", r.last_event().c_str());
  LONGS_EQUAL(0, r.rt_allocs);
}

// Joint speed limits per mode: a joint move of joint 1 the planner never saw (queued
// directly, at full speed) runs in Normal mode (limit 200 deg/s) and, in Reduced mode (limit
// 20 deg/s) switched on well before it (past the speed scale's grace after a switch), gets a
// protective stop in the cycle its commanded speed passes limit + tolerance (the scale could not
// slow a plan that speeds up at the joint's acceleration limit soon enough); the event names the
// joint, its speed and the limit.
TEST(SafetyMonitor, AJointFasterThanItsModesSpeedLimitGetsAProtectiveStopNamingIt) {
  FwConfig c = table(250);
  c.safety_joint_speed_deg_s = {200, 200, 200, 200, 200, 200};
  c.safety_reduced_joint_speed_deg_s = {20, 200, 200, 200, 200, 200};
  c.safety_tolerance_deg_s = 2;
  for (const kin::SafetyMode mode : {kin::SafetyMode::normal, kin::SafetyMode::reduced}) {
    Rig r(c);
    r.enable();
    r.to_work();
    CHECK(r.svc().set_safety_mode(mode).ok());
    for (int i = 0; i < 600; ++i) r.cycle();  // past the scale's grace after a switch (0.5 s)
    MotionItem* m = r.app.ctl->motions().back();
    CHECK(m != nullptr);
    m->id = 901;
    JointMove& jm = m->payload.emplace<JointMove>();
    jm.goal = work_pose();
    jm.goal[0] += 40 * kDeg;
    jm.override = 1.0;
    jm.plan.n = 0;
    r.app.ctl->motions().commit();
    double prev = r.tel().q_cmd[0], vmax = 0;
    int crossed = -1, stopped = -1;
    for (int i = 0; i < 20000; ++i) {
      r.cycle();
      const double q0 = r.tel().q_cmd[0];
      const double v = std::fabs(q0 - prev) / 0.001 / kDeg;  // deg/s
      prev = q0;
      vmax = std::fmax(vmax, v);
      if (crossed < 0 && v > 22.0 + 1e-9) crossed = i;
      if (stopped < 0 && r.tel().state == ArmState::stopping) stopped = i;
      if (i > 10 && r.tel().state == ArmState::idle && r.app.ctl->motions().empty()) break;
    }
    std::printf("\n  joint speed (%s): joint 1 at most %.1f deg/s; past 22 deg/s in cycle %d, stop from cycle %d",
                kin::to_string(mode), vmax, crossed, stopped);
    CHECK(vmax > 22.0);  // the move is faster than the Reduced limit
    if (mode == kin::SafetyMode::normal) {
      CHECK_EQUAL(-1, stopped);
      CHECK_EQUAL(0u, r.tel().safety_stops);
      DOUBLES_EQUAL(work_pose()[0] + 40 * kDeg, r.tel().q_cmd[0], 1e-6);
      continue;
    }
    CHECK(crossed >= 0);
    CHECK(stopped == crossed);
    CHECK(r.tel().state == ArmState::idle);
    CHECK(r.app.ctl->motions().empty());
    CHECK(r.tel().q_cmd[0] < work_pose()[0] + 20 * kDeg);  // stopped well short of the goal
    const std::string ev = r.last_event();
    STRCMP_CONTAINS("protective stop (commanded): joint 1 speed", ev.c_str());
    STRCMP_CONTAINS("limit 20.0 deg/s, value 2", ev.c_str());
    CHECK_EQUAL(1u, r.tel().safety_stops);
    LONGS_EQUAL(0, r.rt_allocs);
  }
}

// Stopping distance and time (Reduced mode's limits, switched on past the scale's grace): a fast
// joint move of joint 1 the planner never saw (queued directly) accelerates faster than the speed
// scale can slow it, and gets a protective stop in the cycle before the stop predicted from its
// commanded state (braked on the joints' limits, as the stop brakes; its growth over the last
// cycle added) would take the TCP further than 20 mm, or last longer than 0.15 s, beyond the
// tolerances; the arm then comes to rest within that: the TCP's travel from the stop's start to
// rest is at most the limit plus the tolerance, and the stop lasts at most the time limit plus its
// tolerance (plus two cycles). The event names the limit.
TEST(SafetyMonitor, APredictedStopBeyondTheStoppingDistanceOrTimeGetsAProtectiveStop) {
  for (const bool distance : {true, false}) {
    FwConfig c = table(250);
    if (distance)
      c.safety_reduced_stop_distance_mm = 20;
    else
      c.safety_reduced_stop_time_s = 0.15;
    c.safety_tolerance_s = 0.01;
    Rig r(c);
    r.enable();
    r.to_work();
    CHECK(r.svc().set_safety_mode(kin::SafetyMode::reduced).ok());
    for (int i = 0; i < 600; ++i) r.cycle();  // past the scale's grace after a switch (0.5 s)
    MotionItem* m = r.app.ctl->motions().back();
    CHECK(m != nullptr);
    m->id = 902;
    JointMove& jm = m->payload.emplace<JointMove>();
    jm.goal = work_pose();
    jm.goal[0] += 90 * kDeg;
    jm.override = 1.0;
    jm.plan.n = 0;
    r.app.ctl->motions().commit();
    auto tcp = [&r] {
      const Telemetry t = r.tel();
      kin::JointVector q(6);
      for (int j = 0; j < 6; ++j) q[j] = t.q_cmd[std::size_t(j)];
      kin::Pose p;
      (void)kin::forward(r.app.chain, q, p);
      return Eigen::Vector3d(p.translation());
    };
    Eigen::Vector3d at_stop = Eigen::Vector3d::Zero();
    int stopped = -1, rest = -1;
    for (int i = 0; i < 20000; ++i) {
      r.cycle();
      if (stopped < 0 && r.tel().state == ArmState::stopping) {
        stopped = i;
        at_stop = tcp();
      }
      if (stopped >= 0 && r.tel().state == ArmState::idle) {
        rest = i;
        break;
      }
    }
    const double travel_mm = (tcp() - at_stop).norm() * 1e3;
    const double stop_s = (rest - stopped) * 0.001;
    std::printf("\n  stop %s: protective stop from cycle %d, TCP travel to rest %.2f mm, stop %.3f s: %s",
                distance ? "distance 20 mm" : "time 0.15 s", stopped, travel_mm, stop_s, r.last_event().c_str());
    CHECK(stopped >= 0 && rest > stopped);
    CHECK(r.tel().q_cmd[0] < work_pose()[0] + 80 * kDeg);  // well short of the goal
    CHECK(r.app.ctl->motions().empty());
    const std::string ev = r.last_event();
    if (distance) {
      STRCMP_CONTAINS("protective stop (commanded): stop distance", ev.c_str());
      STRCMP_CONTAINS("limit 20.0 mm", ev.c_str());
      CHECK(travel_mm <= 20.0 + kTolMm);
      CHECK(travel_mm > 15.0);  // stopped at the limit, not far before it
    } else {
      STRCMP_CONTAINS("protective stop (commanded): stop time", ev.c_str());
      STRCMP_CONTAINS("limit 0.150 s", ev.c_str());
      CHECK(stop_s <= 0.15 + 0.01 + 0.0025);  // (whole cycles, from the first "stopping" to the first "idle")
      CHECK(stop_s > 0.12);
    }
    CHECK_EQUAL(1u, r.tel().safety_stops);
    LONGS_EQUAL(0, r.rt_allocs);
  }
}

// Momentum and power (Reduced mode's limits, switched on past the scale's grace; the puma560's
// masses): a fast joint move of joint 1 the planner never saw (queued directly), accelerating
// faster than the speed scale can slow it, gets a protective stop once the arm's momentum passes
// 2 kg m/s (or its mechanical power 40 W) plus the tolerance; the event names the function and
// the limit.
TEST(SafetyMonitor, MomentumOrPowerAboveTheModesLimitGetsAProtectiveStop) {
  for (const bool momentum : {true, false}) {
    FwConfig c = table(250);
    if (momentum)
      c.safety_reduced_momentum_kg_m_s = 2;
    else
      c.safety_reduced_power_w = 40;
    c.safety_tolerance_kg_m_s = 0.2;
    c.safety_tolerance_w = 2;
    Rig r(c);
    r.enable();
    r.to_work();
    CHECK(r.svc().set_safety_mode(kin::SafetyMode::reduced).ok());
    for (int i = 0; i < 600; ++i) r.cycle();  // past the scale's grace after a switch (0.5 s)
    MotionItem* m = r.app.ctl->motions().back();
    CHECK(m != nullptr);
    m->id = 903;
    JointMove& jm = m->payload.emplace<JointMove>();
    jm.goal = work_pose();
    jm.goal[0] += 90 * kDeg;
    jm.override = 1.0;
    jm.plan.n = 0;
    r.app.ctl->motions().commit();
    int stopped = -1;
    for (int i = 0; i < 20000; ++i) {
      r.cycle();
      if (stopped < 0 && r.tel().state == ArmState::stopping) stopped = i;
      if (stopped >= 0 && r.tel().state == ArmState::idle) break;
    }
    const std::string ev = r.last_event();
    std::printf("\n  %s: protective stop from cycle %d: %s", momentum ? "momentum 2 kg m/s" : "power 40 W", stopped,
                ev.c_str());
    CHECK(stopped >= 0);
    CHECK(r.tel().state == ArmState::idle);
    CHECK(r.tel().q_cmd[0] < work_pose()[0] + 60 * kDeg);  // well short of the goal
    CHECK(r.app.ctl->motions().empty());
    if (momentum) {
      STRCMP_CONTAINS("protective stop (commanded): momentum", ev.c_str());
      STRCMP_CONTAINS("limit 2.00 kg m/s, value 2.2", ev.c_str());
    } else {
      STRCMP_CONTAINS("protective stop (commanded): power", ev.c_str());
      STRCMP_CONTAINS("limit 40.0 W, value 4", ev.c_str());
    }
    CHECK_EQUAL(1u, r.tel().safety_stops);
    LONGS_EQUAL(0, r.rt_allocs);
  }
}

// ---------------------------------------------------------------------------
// Speed scaling (docs/safety.md#speed-scaling): a speed limit that the running motion exceeds
// at run time (Reduced switched on mid-move, a trigger plane crossed by a move or a jog the
// planner did not slow) slows the motion on its path by the executor's ramped time scale
// instead of stopping it; a protective stop only where the scale cannot keep the limit.
// ---------------------------------------------------------------------------

namespace {

/// Every cycle's commanded joints and TCP (from the telemetry), for speeds, accelerations and
/// the path.
struct Trace {
  std::vector<kin::JointVector> q;
  std::vector<Eigen::Vector3d> x;
  std::vector<std::uint64_t> cycle;  ///< the control cycle of each sample (a service request runs cycles of its own)
  void add(Rig& r) {
    const Telemetry t = r.tel();
    cycle.push_back(t.cycles);
    kin::JointVector v(6);
    for (int j = 0; j < 6; ++j) v[j] = t.q_cmd[std::size_t(j)];
    kin::Pose p;
    (void)kin::forward(r.app.chain, v, p);
    q.push_back(v);
    x.push_back(p.translation());
  }
  /// TCP speed (mm/s) between sample i-1 and i (over the cycles between them).
  double speed(std::size_t i) const {
    if (i == 0) return 0.0;
    const double cycles = cycle[i] > cycle[i - 1] ? static_cast<double>(cycle[i] - cycle[i - 1]) : 1.0;
    return (x[i] - x[i - 1]).norm() / (cycles * 1e-3) * 1e3;
  }
  /// Highest |second difference| / dt^2 over each joint's acceleration limit, from sample `from` on.
  double acc_ratio(const kin::JointLimits& lim, std::size_t from = 1) const {
    double worst = 0;
    for (std::size_t i = std::max<std::size_t>(from, 1); i + 1 < q.size(); ++i)
      for (int j = 0; j < 6; ++j) {
        const double a = std::fabs(q[i + 1][j] - 2 * q[i][j] + q[i - 1][j]) / 1e-6;
        worst = std::fmax(worst, a / lim.dyn[std::size_t(j)].max_acceleration);
      }
    return worst;
  }
  /// Largest distance (mm) of any sample from the polyline of `ref`'s samples. Exact, and not
  /// quadratic in practice: each sample's segments are searched outward from the previous
  /// sample's nearest one, and the search ends at the first segment no farther than the largest
  /// distance so far (that sample cannot raise it); a sample farther than that gets a full search.
  /// (Two traces of 7 000 and 3 600 samples took 25 M segment distances the quadratic way, most
  /// of the 11.6 s of a test under qemu.)
  double deviation_from(const Trace& ref) const {
    const std::size_t n = ref.x.size();
    auto dist = [&](const Eigen::Vector3d& p, std::size_t k) {  // to segment k-1 .. k
      const Eigen::Vector3d a = ref.x[k - 1], d = ref.x[k] - a;
      const double len2 = d.squaredNorm();
      const double u = len2 > 0 ? std::clamp((p - a).dot(d) / len2, 0.0, 1.0) : 0.0;
      return (a + u * d - p).norm();
    };
    double worst = 0;
    std::size_t hint = 1;
    for (const Eigen::Vector3d& p : x) {
      double best = INFINITY;
      std::size_t best_k = hint;
      for (std::size_t off = 0; best > worst; ++off) {
        const bool up = hint + off < n, down = off > 0 && hint >= off + 1;
        if (!up && !down) break;  // every segment searched
        for (const std::size_t k : {up ? hint + off : 0, down ? hint - off : 0}) {
          if (k == 0) continue;
          const double e = dist(p, k);
          if (e < best) best = e, best_k = k;
        }
      }
      worst = std::fmax(worst, best);
      hint = best_k;
    }
    return worst * 1e3;
  }
};

void trace_add(Trace& t, Rig& r) { t.add(r); }

/// Runs until the queue is empty and the arm idle (or max_cycles), tracing every cycle;
/// `at(i)` is called before cycle i.
template <class F>
void run_traced(Rig& r, Trace& tr, int max_cycles, F at) {
  r.trace = &tr;  // every cycle, those a request runs too
  for (int i = 0; i < max_cycles; ++i) {
    at(i);
    r.cycle();
    if (i > 10 && r.app.ctl->motions().empty() && r.tel().state == ArmState::idle) break;
  }
  r.trace = nullptr;
}

FwConfig reduced_100(double normal_mm_s) {
  FwConfig c = table(500);
  c.safety_tcp_speed_mm_s = normal_mm_s;
  c.safety_reduced_tcp_speed_mm_s = 100;
  return c;
}

kin::Pose work_tcp() {
  const kin::LoadResult lr = kin::load_robot("puma560");
  kin::Pose w;
  (void)kin::forward(lr.chain, work_pose(), w);
  return w;
}

}  // namespace

TEST_GROUP(SpeedScaling){};

// A movel at 200 mm/s (Normal limit 250 mm/s) with `safety reduced` (100 mm/s) switched on
// half-way: no protective stop; the TCP is under 100 mm/s within the ramp (0.35 s) and stays
// there; the path is the planned line (every commanded sample within 0.1 mm of the run without
// the switch); the move ends at its target; no joint beyond its acceleration limit; no allocation.
TEST(SpeedScaling, ReducedSwitchedOnMidLineSlowsItOnItsPath) {
  const kin::Pose w = work_tcp();
  MoveLine side;
  side.target = w;
  side.target.translation().y() += 0.15;
  side.speed = 0.2;
  Trace ref, tr;
  int switched = -1;
  kin::JointLimits lim;
  for (int k = 0; k < 2; ++k) {
    Rig r(reduced_100(250));
    lim = r.app.ctl->limits();
    r.enable();
    r.to_work();
    MoveContext cx;
    cx.ik = r.app.console->jog_context().ik;
    const MoveResult m = r.svc().move(side, cx);
    CHECK_TEXT(m.ok(), m.reason.c_str());
    Trace& t = k == 0 ? ref : tr;
    run_traced(r, t, 20000, [&](int) {
      if (k == 1 && switched < 0 && t.x.size() > 400 && t.speed(t.x.size() - 1) > 199.0) {
        switched = int(t.x.size());  // (the trace's index: the request runs cycles too)
        CHECK(r.svc().set_safety_mode(kin::SafetyMode::reduced).ok());
      }
    });
    CHECK_EQUAL(0u, r.tel().safety_stops);
    CHECK(r.tel().state == ArmState::idle);
    CHECK((t.x.back() - side.target.translation()).norm() < 1e-6);
    LONGS_EQUAL(0, r.rt_allocs);
    if (k == 1) {
      const std::string ev = r.last_event();
      CHECK(ev.find("protective stop") == std::string::npos);
    }
  }
  CHECK(switched > 0);
  // the first sample from which the TCP stays at or under 100 mm/s
  std::size_t under = tr.x.size();
  for (std::size_t i = tr.x.size(); i-- > static_cast<std::size_t>(switched);)
    if (tr.speed(i) > 100.0 + 0.5) break;
    else under = i;
  double peak_after = 0;
  for (std::size_t i = static_cast<std::size_t>(switched); i < tr.x.size(); ++i) peak_after = std::fmax(peak_after, tr.speed(i));
  const double dev = tr.deviation_from(ref), acc = tr.acc_ratio(lim);
  std::printf("\n  scaled line: Reduced switched on at cycle %d (200 mm/s), under 100 mm/s from cycle %zu (%.0f ms), "
              "peak after the switch %.1f mm/s, path deviation %.4f mm, joint acceleration %.3f of its limit",
              switched, under, double(under - std::size_t(switched)), peak_after, dev, acc);
  CHECK(under - std::size_t(switched) <= 350);
  CHECK(peak_after <= 200.0 + 2.0);
  CHECK(dev < 0.1);
  CHECK(acc <= 1.0 + 1e-3);
  CHECK(tr.x.size() > ref.x.size() + 200);  // it did run slower
}

namespace {

/// The service plans without the trigger planes (its copy of the envelope; the controller's
/// monitor keeps them): the move or jog is not slowed at plan time, as one queued before the
/// zone existed.
void plan_without_trigger_planes(Rig& r) {
  MotionSettings s = r.svc().settings();
  s.safety.trigger_count = 0;
  const SettingsResult sr = r.svc().set_settings(s);
  CHECK(sr.error == CmdError::ok);
}

/// A trigger plane across +y, `ahead_mm` beyond the work pose's TCP: Reduced where the tool
/// sphere reaches past it.
FwConfig trigger_ahead_y(double ahead_mm, double* y_plane) {
  FwConfig c = reduced_100(0);
  *y_plane = work_tcp().translation().y() * 1000.0 + ahead_mm;
  c.safety_reduced_planes = {0, -1, 0, -*y_plane};
  return c;
}

}  // namespace

// A 200 mm/s line the planner did not slow (planned without the trigger plane) runs into a
// trigger zone (Reduced, 100 mm/s): the look-ahead slows it before the plane, so it crosses at
// 100 mm/s or less and stays under it inside; no protective stop; the line kept (within 0.1 mm
// of the straight segment); the move ends at its target; accelerations within the limits.
TEST(SpeedScaling, ALineIntoATriggerZoneIsSlowedBeforeThePlane) {
  double y_plane = 0;
  Rig r(trigger_ahead_y(100, &y_plane));
  r.enable();
  r.to_work();
  plan_without_trigger_planes(r);
  const kin::Pose w = work_tcp();
  MoveLine side;
  side.target = w;
  side.target.translation().y() += 0.15;
  side.speed = 0.2;
  MoveContext cx;
  cx.ik = r.app.console->jog_context().ik;
  const MoveResult m = r.svc().move(side, cx);
  CHECK_TEXT(m.ok(), m.reason.c_str());
  Trace tr;
  run_traced(r, tr, 20000, [](int) {});
  int crossed = -1;
  double peak_before = 0, peak_past = 0, at_cross = 0;
  for (std::size_t i = 1; i < tr.x.size(); ++i) {
    const bool past = tr.x[i].y() * 1e3 + kRadiusMm > y_plane;
    if (!past) peak_before = std::fmax(peak_before, tr.speed(i));
    if (past && crossed < 0) crossed = int(i), at_cross = tr.speed(i);
    if (past) peak_past = std::fmax(peak_past, tr.speed(i));
  }
  double dev = 0;
  const Eigen::Vector3d a = w.translation(), d = (side.target.translation() - a).normalized();
  for (const Eigen::Vector3d& p : tr.x) dev = std::fmax(dev, ((p - a) - (p - a).dot(d) * d).norm() * 1e3);
  const double acc = tr.acc_ratio(r.app.ctl->limits());
  std::printf("\n  line into a trigger zone: peak %.1f mm/s before the plane, %.1f mm/s as it crosses (cycle %d), "
              "peak past the plane %.1f mm/s; path deviation %.4f mm; joint acceleration %.3f of its limit",
              peak_before, at_cross, crossed, peak_past, dev, acc);
  CHECK(crossed > 0);
  CHECK(peak_before > 190.0);  // it ran fast outside
  CHECK(peak_past <= 100.0 + 1.0);
  CHECK_EQUAL(0u, r.tel().safety_stops);
  CHECK(dev < 0.1);
  CHECK(acc <= 1.0 + 1e-3);
  CHECK((tr.x.back() - side.target.translation()).norm() < 1e-6);
  LONGS_EQUAL(0, r.rt_allocs);
}

// ---------------------------------------------------------------------------
// Blended runs on the speed scale: a blended path run (lines with blend=) and a blended joint
// run (movej with blend=) slow on their path as single moves do.
// ---------------------------------------------------------------------------

namespace {

/// A blended run from the work pose: three lines with blend= (`lines`) or three joint moves
/// with blend= (the joint queue's run), queued before the first cycle (nothing queued late).
std::vector<MoveResult> queue_blended_run(Rig& r, bool lines) {
  std::vector<MoveResult> out;
  MoveContext cx;
  cx.ik = r.app.console->jog_context().ik;
  if (lines) {
    const kin::Pose w = work_tcp();
    const Eigen::Vector3d steps[3] = {{0, 0.07, 0}, {0, 0.04, 0.04}, {0, 0.03, -0.04}};
    kin::Pose p = w;
    for (int k = 0; k < 3; ++k) {
      MoveLine m;
      p.translation() += steps[k];
      m.target = p;
      m.speed = 0.2;
      m.blend = k < 2 ? 0.015 : 0.0;
      out.push_back(r.svc().move(m, cx));
    }
  } else {
    const double d[3][6] = {{12, 0, -8, 0, 0, 0}, {22, 6, -14, 0, 0, 0}, {30, 0, -6, 0, 0, 0}};
    for (int k = 0; k < 3; ++k) {
      MoveJoints m;
      m.goal = work_pose();
      for (int j = 0; j < 6; ++j) m.goal[j] += d[k][j] * kDeg * (work_tcp().translation().x() > 0 ? 1 : -1);
      m.speed_pct = 100;
      m.blend = k < 2 ? 5 * kDeg : 0.0;
      out.push_back(r.svc().move(m, cx));
    }
  }
  return out;
}

}  // namespace

// A blended run (three lines at 200 mm/s with blend=15 mm; three joint moves at 100 % with
// blend=5 deg, the planner keeping them at the Normal 250 mm/s) with `safety reduced` (100 mm/s)
// switched on while it runs above 150 mm/s: no protective stop; the TCP is under 100 mm/s + 1
// within 0.4 s of the switch and stays there; the path is the unswitched run's (every sample
// within 0.1 mm of its polyline); the run ends at its target; no joint beyond its acceleration
// limit; no allocation.
TEST(SpeedScaling, ReducedSwitchedOnMidBlendedRunSlowsItOnItsPath) {
  for (const bool lines : {true, false}) {
    Trace ref, tr;
    int switched = -1;
    kin::JointLimits lim;
    std::string scale_shown;
    double scale_tel = 1;
    for (int k = 0; k < 2; ++k) {
      Rig r(reduced_100(250));
      lim = r.app.ctl->limits();
      r.enable();
      r.to_work();
      for (const MoveResult& m : queue_blended_run(r, lines)) CHECK_TEXT(m.ok(), m.reason.c_str());
      Trace& t = k == 0 ? ref : tr;
      run_traced(r, t, 30000, [&](int) {
        if (k == 1 && switched < 0 && t.x.size() > 100 && t.speed(t.x.size() - 1) > 150.0) {
          switched = int(t.x.size());  // (the trace's index: the request runs cycles too)
          CHECK(r.svc().set_safety_mode(kin::SafetyMode::reduced).ok());
        }
        if (k == 1 && switched > 0 && int(t.x.size()) == switched + 300) {  // slowed: the console's `safety` shows the scale
          Session s;
          r.app.console->execute(s, "safety");
          scale_shown = s.out;
          scale_tel = r.tel().speed_scale;
        }
      });
      const std::string ev = r.last_event();
      std::printf("\n  blended %s run %d: %zu cycles, last event: %s", lines ? "path" : "joint", k, t.x.size(), ev.c_str());
      CHECK_EQUAL(0u, r.tel().safety_stops);
      CHECK(r.tel().state == ArmState::idle);
      CHECK(ev.find("protective stop") == std::string::npos);
      LONGS_EQUAL(0, r.rt_allocs);
    }
    CHECK(switched > 0);
    CHECK((tr.x.back() - ref.x.back()).norm() < 1e-6);  // at the run's target
    std::size_t under = tr.x.size();
    for (std::size_t i = tr.x.size(); i-- > static_cast<std::size_t>(switched);)
      if (tr.speed(i) > 100.0 + 1.0) break;
      else under = i;
    double peak_ref = 0, peak_after = 0;
    for (std::size_t i = 1; i < ref.x.size(); ++i) peak_ref = std::fmax(peak_ref, ref.speed(i));
    for (std::size_t i = std::size_t(switched); i < tr.x.size(); ++i) peak_after = std::fmax(peak_after, tr.speed(i));
    const double dev = tr.deviation_from(ref), acc = tr.acc_ratio(lim);
    std::printf("\n  scaled blended %s run: %.3f s unswitched (peak %.1f mm/s), %.3f s with Reduced switched on at cycle %d; "
                "under 100 mm/s %.0f ms after the switch; peak after it %.1f mm/s; path deviation %.4f mm; joint "
                "acceleration %.3f of its limit",
                lines ? "path" : "joint", double(ref.x.size()) * 1e-3, peak_ref, double(tr.x.size()) * 1e-3, switched,
                double(under) - double(switched), peak_after, dev, acc);
    CHECK(peak_ref > 150.0 && peak_ref < 250.0 + 1.0);
    CHECK(double(under) - double(switched) <= 400);
    CHECK(dev < 0.1);
    CHECK(acc <= 1.0 + 1e-3);
    CHECK(tr.x.size() > ref.x.size() + 100);  // it did run slower
    CHECK(scale_tel < 0.9);
    char want[32];
    std::snprintf(want, sizeof want, " speed_scale=%.2f", scale_tel);
    STRCMP_CONTAINS(want, scale_shown.c_str());
  }
}

// A blended path run at 200 mm/s (planned without the trigger plane) whose first corner's
// blend crosses into a trigger zone (Reduced, 100 mm/s): slowed before the plane by the
// look-ahead, under 100 mm/s + 1 from the crossing on, no protective stop, the path the
// unslowed run's (within 0.1 mm), at its target at the end.
TEST(SpeedScaling, ABlendedRunIntoATriggerZoneIsSlowedBeforeThePlane) {
  double y_plane = 0;
  Trace ref, tr;
  for (int k = 0; k < 2; ++k) {
    FwConfig c = trigger_ahead_y(75, &y_plane);
    if (k == 0) c.safety_reduced_planes.clear();  // the reference: no zone
    Rig r(c);
    r.enable();
    r.to_work();
    plan_without_trigger_planes(r);
    for (const MoveResult& m : queue_blended_run(r, true)) CHECK_TEXT(m.ok(), m.reason.c_str());
    run_traced(r, k == 0 ? ref : tr, 30000, [](int) {});
    const std::string ev = r.last_event();
    CHECK_TEXT(ev.find("protective stop") == std::string::npos, ev.c_str());
    CHECK_EQUAL(0u, r.tel().safety_stops);
    CHECK(r.tel().state == ArmState::idle);
    LONGS_EQUAL(0, r.rt_allocs);
  }
  int crossed = -1;
  double peak_before = 0, peak_past = 0, at_cross = 0;
  for (std::size_t i = 1; i < tr.x.size(); ++i) {
    const bool past = tr.x[i].y() * 1e3 + kRadiusMm > y_plane;
    if (!past && crossed < 0) peak_before = std::fmax(peak_before, tr.speed(i));
    if (past && crossed < 0) crossed = int(i), at_cross = tr.speed(i);
    if (past) peak_past = std::fmax(peak_past, tr.speed(i));
  }
  const double dev = tr.deviation_from(ref);
  std::printf("\n  blended run into a trigger zone: %.3f s without the zone, %.3f s with it; peak %.1f mm/s before the "
              "plane, %.1f mm/s as it crosses (cycle %d), peak past it %.1f mm/s; path deviation %.4f mm",
              double(ref.x.size()) * 1e-3, double(tr.x.size()) * 1e-3, peak_before, at_cross, crossed, peak_past, dev);
  CHECK(crossed > 0);
  CHECK(peak_before > 190.0);
  CHECK(peak_past <= 100.0 + 1.0);
  CHECK(dev < 0.1);
  CHECK((tr.x.back() - ref.x.back()).norm() < 1e-6);
}

// ---------------------------------------------------------------------------
// Jogs and streamed targets into a trigger zone: slowed to the Reduced limits (the jog's clock
// on the speed scale, its re-plans capped at the limits), not stopped.
// ---------------------------------------------------------------------------

namespace {

/// What a traced jog or stream did about the trigger plane at y_plane (mm; the tool sphere's
/// edge): its peak speed before the plane, at the crossing, past it, and how far past the plane
/// the sphere went while faster than the Reduced 100 mm/s + 1 (the overshoot, mm).
struct ZoneFigures {
  int crossed = -1;
  double before = 0, at = 0, past = 0, overshoot = 0;
};
ZoneFigures zone_figures(const Trace& tr, double y_plane) {
  ZoneFigures f;
  for (std::size_t i = 1; i < tr.x.size(); ++i) {
    const double edge = tr.x[i].y() * 1e3 + kRadiusMm;
    const bool past = edge > y_plane;
    if (!past && f.crossed < 0) f.before = std::fmax(f.before, tr.speed(i));
    if (past && f.crossed < 0) f.crossed = int(i), f.at = tr.speed(i);
    if (past) f.past = std::fmax(f.past, tr.speed(i));
    if (past && tr.speed(i) > 100.0 + 1.0) f.overshoot = std::fmax(f.overshoot, edge - y_plane);
  }
  return f;
}

/// Runs a continuous jog (started already) until the tool's centre is `past_mm` beyond y_plane
/// (or max_cycles), keeping it alive; then cancels it and runs to rest.
void run_jog_past(Rig& r, Trace& tr, double y_plane, double past_mm, int max_cycles) {
  r.trace = &tr;  // every cycle, those the keep-alive and the cancel run too
  for (int i = 0; i < max_cycles && r.tel().state == ArmState::jogging; ++i) {
    if (i % 50 == 0) (void)r.svc().jog_keepalive();
    r.cycle();
    if (tr.x.back().y() * 1e3 > y_plane + past_mm) break;
  }
  (void)r.svc().jog_cancel();
  for (int i = 0; i < 5000 && r.tel().state != ArmState::idle; ++i) r.cycle();
  r.trace = nullptr;
}

}  // namespace

// A continuous tool jog along +y at 100, 250 and 500 mm/s towards a trigger plane 150 mm ahead
// (Reduced: 100 mm/s): no stop of any kind; from the plane on the TCP is at 100 mm/s + 1 or
// under (the sphere's overshoot past the plane above that speed: 0); the jog runs on in the
// zone until cancelled. Then a continuous joint jog of joint 1 (swinging the tool towards +y,
// 30 % of the joint's limit, faster than 100 mm/s) into the same zone: the same.
TEST(SpeedScaling, AJogIntoATriggerZoneIsSlowedNotStopped) {
  for (const double speed : {100.0, 250.0, 500.0, -1.0}) {
    double y_plane = 0;
    FwConfig c = trigger_ahead_y(150, &y_plane);
    c.max_linear_speed_mm_s = 500;
    Rig r(c);
    r.enable();
    r.to_work();
    const JogContext jc = r.app.console->jog_context();
    JogResult j;
    if (speed > 0) {
      ToolJog tj;
      tj.axis = 1;
      tj.continuous = true;
      tj.direction = 1;
      tj.speed_pct = speed / 500.0 * 100.0;
      j = r.svc().jog(tj, jc);
    } else {
      JointJog jj;
      jj.joint = 0;
      jj.continuous = true;
      jj.direction = work_tcp().translation().x() > 0 ? 1 : -1;
      jj.speed_pct = 30;
      j = r.svc().jog(jj, jc);
    }
    CHECK_TEXT(j.ok(), j.reason.c_str());
    Trace tr;
    run_jog_past(r, tr, y_plane, 40, 20000);
    const ZoneFigures f = zone_figures(tr, y_plane);
    const std::string ev = r.last_event();
    std::printf("\n  %s jog into a trigger zone: peak %.1f mm/s before the plane, %.1f mm/s as it crosses (cycle %d), "
                "peak past it %.1f mm/s, overshoot above 101 mm/s %.2f mm; last event: %s",
                speed > 0 ? (std::to_string(int(speed)) + " mm/s tool").c_str() : "joint 1", f.before, f.at, f.crossed,
                f.past, f.overshoot, ev.c_str());
    CHECK(f.crossed > 0);
    if (speed != 100.0) CHECK(f.before > (speed > 0 ? 0.7 * speed : 135.0));  // it ran fast outside
    CHECK(f.past <= 100.0 + 1.0);
    CHECK_EQUAL(0.0, f.overshoot);
    CHECK_EQUAL(0u, r.tel().safety_stops);
    CHECK(ev.find("protective stop") == std::string::npos);
    CHECK(ev.find("jog stopped") == std::string::npos);
    CHECK(tr.x.back().y() * 1e3 > y_plane + 40);  // it went on into the zone
    CHECK(r.tel().state == ArmState::idle);
    LONGS_EQUAL(0, r.rt_allocs);
  }
}

// Streamed poses (every 10 ms, with their times) along +y at 250 mm/s into a trigger zone 140 and
// 100 mm ahead (Reduced: 100 mm/s), then the last one held: no stop of any kind; from the plane
// on the TCP at 100 mm/s + 1 or under, and crossing near it (at least 90 mm/s: the stream,
// catching up from rest, is slowed to the Reduced limit at the plane, not below it); the arm
// ends at the last target.
TEST(SpeedScaling, AStreamIntoATriggerZoneIsSlowedNotStopped) {
  for (const double ahead : {140.0, 100.0}) {
    double y_plane = 0;
    FwConfig c = trigger_ahead_y(ahead, &y_plane);
    c.max_linear_speed_mm_s = 500;
    Rig r(c);
    r.enable();
    r.to_work();
    StreamSettings ss;
    ss.max_step.assign(6, 0.5);
    StreamService st(r.svc(), *r.app.ctl, ss);
    const kin::Pose w = work_tcp();
    Trace tr;
    kin::Pose target = w;
    bool reached = false;
    const auto c0 = r.tel().cycles;  // (t from the cycle count: a contracted multiply-subtract can make 0 slightly negative)
    for (int k = 0; k < 3000 && !reached; ++k) {  // about 10 ms apart: 30 s at most
      const double t = double(r.tel().cycles - c0) * 1e-3;  // the control thread's clock (see below)
      target.translation().y() = w.translation().y() + std::fmin(0.2, 0.25 * t);
      const StreamResult sr = st.target_pose(target, false, k == 0, t);
      CHECK_TEXT(sr.ok(), sr.reason.c_str());
      if (!sr.ok()) break;
      for (int i = 0; i < 10; ++i) {
        r.cycle();
        tr.add(r);
      }
      reached = (tr.x.back() - (w.translation() + Eigen::Vector3d(0, 0.2, 0))).norm() < 1e-5;
    }
    const ZoneFigures f = zone_figures(tr, y_plane);
    const std::string ev = r.last_event();
    char fig[320];
    std::snprintf(fig, sizeof fig,
                  "stream at 250 mm/s into a trigger zone %.0f mm ahead: peak %.1f mm/s before the plane, %.1f mm/s as it "
                  "crosses (cycle %d), peak past it %.1f mm/s, overshoot above 101 mm/s %.2f mm; last event: %s",
                  ahead, f.before, f.at, f.crossed, f.past, f.overshoot, ev.c_str());
    std::printf("\n  %s", fig);
    CHECK_TEXT(reached, fig);
    CHECK_TEXT(f.crossed > 0, fig);
    CHECK_TEXT(f.before > 200.0, fig);
    CHECK_TEXT(f.at >= 90.0, fig);
    CHECK_TEXT(f.past <= 100.0 + 1.0, fig);
    CHECK_EQUAL(0u, r.tel().safety_stops);
    CHECK_TEXT(ev.find("protective stop") == std::string::npos, fig);
    LONGS_EQUAL(0, r.rt_allocs);
  }
}

// A stream under a TCP speed limit it keeps within (100 mm/s; the stream's targets move at
// 90 mm/s along y): tracked at the targets' speed, not slowed below it by the plans' TCP cap
// (the cap bounds the TCP's speed for the direction the stream moves in, not for every joint at
// its own limit at once); no stop, and the TCP never beyond its limit.
TEST(SpeedScaling, AStreamWithinTheTcpSpeedLimitIsNotSlowedByTheCap) {
  FwConfig c = table(500);
  c.safety_tcp_speed_mm_s = 100;
  Rig r(c);
  r.enable();
  r.to_work();
  StreamSettings ss;
  ss.max_step.assign(6, 0.5);
  StreamService st(r.svc(), *r.app.ctl, ss);
  const kin::Pose w = work_tcp();
  Trace tr;
  kin::Pose target = w;
  bool reached = false;
  const auto c0 = r.tel().cycles;  // (t from the cycle count: a contracted multiply-subtract can make 0 slightly negative)
  for (int k = 0; k < 3000 && !reached; ++k) {  // about 10 ms apart: 30 s at most
    // sampled on the control thread's clock (as a leader's state samples are): each target
    // costs the rig a cycle of its own to answer, which would otherwise make the targets' time
    // fall behind the clock and leave them late, and without their velocity
    const double t = double(r.tel().cycles - c0) * 1e-3;
    target.translation().y() = w.translation().y() + std::fmin(0.15, 0.09 * t);
    const StreamResult sr = st.target_pose(target, false, k == 0, t);
    CHECK_TEXT(sr.ok(), sr.reason.c_str());
    if (!sr.ok()) break;
    for (int i = 0; i < 10; ++i) {
      r.cycle();
      tr.add(r);
    }
    reached = (tr.x.back() - (w.translation() + Eigen::Vector3d(0, 0.15, 0))).norm() < 1e-5;
  }
  double peak = 0;
  for (std::size_t i = 1; i < tr.x.size(); ++i) peak = std::fmax(peak, tr.speed(i));
  char fig[200];
  std::snprintf(fig, sizeof fig, "stream at 90 mm/s under a 100 mm/s TCP limit: peak %.1f mm/s, %zu cycles to the end, %u stops",
                peak, tr.x.size(), unsigned(r.tel().safety_stops));
  std::printf("\n  %s", fig);
  CHECK_TEXT(reached, fig);
  CHECK_TEXT(peak >= 88.0, fig);
  CHECK_TEXT(peak <= 100.0 + 1.0, fig);
  CHECK_EQUAL(0u, r.tel().safety_stops);
  LONGS_EQUAL(0, r.rt_allocs);
}

// A stream whose last target is held still while the arm is still far from it (one target
// 120 mm away along y, then the same target again every 10 ms, under a 100 mm/s TCP limit):
// the catch-up to it is capped along its own straight line to the target, so it runs near the
// TCP limit (not at the cap spread over every joint's limit at once, about a third of it), and
// the TCP never beyond its limit.
TEST(SpeedScaling, AHeldStreamTargetIsCaughtUpNearTheTcpLimit) {
  FwConfig c = table(500);
  c.safety_tcp_speed_mm_s = 100;
  Rig r(c);
  r.enable();
  r.to_work();
  StreamSettings ss;
  ss.max_step.assign(6, 0.5);
  StreamService st(r.svc(), *r.app.ctl, ss);
  const kin::Pose w = work_tcp();
  Trace tr;
  kin::Pose target = w;
  target.translation().y() += 0.12;
  bool reached = false;
  const auto c0 = r.tel().cycles;
  for (int k = 0; k < 3000 && !reached; ++k) {  // about 10 ms apart: 30 s at most
    const double t = double(r.tel().cycles - c0) * 1e-3;
    const StreamResult sr = st.target_pose(target, false, k == 0, t);
    CHECK_TEXT(sr.ok(), sr.reason.c_str());
    if (!sr.ok()) break;
    for (int i = 0; i < 10; ++i) {
      r.cycle();
      tr.add(r);
    }
    reached = (tr.x.back() - target.translation()).norm() < 1e-5;
  }
  double peak = 0;
  for (std::size_t i = 1; i < tr.x.size(); ++i) peak = std::fmax(peak, tr.speed(i));
  char fig[200];
  std::snprintf(fig, sizeof fig, "held stream target 120 mm away under a 100 mm/s TCP limit: peak %.1f mm/s, %zu cycles to it, %u stops",
                peak, tr.x.size(), unsigned(r.tel().safety_stops));
  std::printf("\n  %s", fig);
  CHECK_TEXT(reached, fig);
  CHECK_TEXT(peak >= 85.0, fig);
  CHECK_TEXT(peak <= 100.0 + 1.0, fig);
  CHECK_EQUAL(0u, r.tel().safety_stops);
  LONGS_EQUAL(0, r.rt_allocs);
}

// ---------------------------------------------------------------------------
// Stopping distance on the speed scale: the stop predicted from the commanded state (braked
// on the joints' limits, as the protective stop brakes) is kept within the mode's limit by
// slowing the motion, before the limit is reached.
// ---------------------------------------------------------------------------

namespace {

/// The TCP's travel (mm) during the stop predicted from the commanded state after the last
/// cycle (the telemetry's joints and velocities, the acceleration from the velocities'
/// difference with `qd_prev`, which it updates); `time_s`: how long that stop lasts.
double predicted_stop_mm(Rig& r, kin::JointVector& qd_prev, kin::JointTrajectory& scratch, double* time_s = nullptr) {
  const Telemetry t = r.tel();
  kin::JointState st;
  st.pos.resize(6);
  st.vel.resize(6);
  st.acc.resize(6);
  for (int j = 0; j < 6; ++j) {
    st.pos[j] = t.q_cmd[std::size_t(j)];
    st.vel[j] = t.qd_cmd[std::size_t(j)];
    st.acc[j] = qd_prev.size() == 6 ? (st.vel[j] - qd_prev[j]) / 1e-3 : 0.0;
  }
  qd_prev = st.vel;
  kin::SafetySample x;
  (void)kin::forward(r.app.chain, st.pos, x.tcp);
  if (!kin::stop_prediction(r.app.chain, r.app.ctl->limits(), st, scratch, x)) return 0;
  if (time_s != nullptr) *time_s = x.stop_time;
  return x.stop_distance * 1e3;
}

}  // namespace

// A movel at 200 mm/s (no speed limits) with `safety reduced` switched on while it accelerates
// (at 60 mm/s), Reduced mode's stop distance limit 5 mm (the stop predicted at 200 mm/s, 10.5 mm, is
// longer): no protective stop; the stop predicted from the commanded state is within 5 mm plus
// the tolerance at every cycle after the switch; the path is the unswitched run's (within 0.1 mm);
// the move ends at its target; no joint beyond its acceleration limit; no allocation.
TEST(SpeedScaling, ReducedSwitchedOnMidLineKeepsThePredictedStopWithinItsDistance) {
  constexpr double kStopMm = 5.0;
  const kin::Pose w = work_tcp();
  MoveLine side;
  side.target = w;
  side.target.translation().y() += 0.15;
  side.speed = 0.2;
  Trace ref, tr;
  int switched = -1;
  double worst_ref = 0, worst_after = 0, at_switch = 0;
  kin::JointLimits lim;
  std::string ev;
  for (int k = 0; k < 2; ++k) {
    FwConfig c = table(500);
    c.safety_reduced_stop_distance_mm = kStopMm;
    Rig r(c);
    lim = r.app.ctl->limits();
    r.enable();
    r.to_work();
    MoveContext cx;
    cx.ik = r.app.console->jog_context().ik;
    const MoveResult m = r.svc().move(side, cx);
    CHECK_TEXT(m.ok(), m.reason.c_str());
    Trace& t = k == 0 ? ref : tr;
    kin::JointVector qd_prev;
    kin::JointTrajectory scratch;
    run_traced(r, t, 20000, [&](int) {
      const double d = predicted_stop_mm(r, qd_prev, scratch);
      if (k == 0) worst_ref = std::fmax(worst_ref, d);
      if (k == 1 && switched >= 0) worst_after = std::fmax(worst_after, d);
      if (k == 1 && switched < 0 && t.x.size() > 2 && t.speed(t.x.size() - 1) > 60.0) {
        switched = int(t.x.size());
        at_switch = d;
        CHECK(r.svc().set_safety_mode(kin::SafetyMode::reduced).ok());
      }
    });
    if (k == 1) ev = r.last_event();
    std::printf("\n  stop distance run %d: %zu cycles, %u safety stops, last event: %s", k, t.x.size(),
                unsigned(r.tel().safety_stops), r.last_event().c_str());
    CHECK_EQUAL(0u, r.tel().safety_stops);
    CHECK(r.tel().state == ArmState::idle);
    CHECK((t.x.back() - side.target.translation()).norm() < 1e-6);
    LONGS_EQUAL(0, r.rt_allocs);
  }
  CHECK(switched > 0);
  double peak_after = 0;
  for (std::size_t i = std::size_t(switched); i < tr.x.size(); ++i) peak_after = std::fmax(peak_after, tr.speed(i));
  const double dev = tr.deviation_from(ref), acc = tr.acc_ratio(lim);
  std::printf("\n  line with a %.0f mm Reduced stop distance: predicted stop up to %.2f mm unswitched; Reduced switched "
              "on at cycle %d (60 mm/s, predicted %.2f mm), then predicted up to %.2f mm, peak %.1f mm/s; %.3f s "
              "unswitched, %.3f s switched; path deviation %.4f mm; joint acceleration %.3f of its limit",
              kStopMm, worst_ref, switched, at_switch, worst_after, peak_after, double(ref.x.size()) * 1e-3,
              double(tr.x.size()) * 1e-3, dev, acc);
  CHECK(worst_ref > 1.5 * kStopMm);  // unslowed, the line would break the limit
  CHECK(at_switch < kStopMm);        // within it when the limit came down
  CHECK(worst_after <= kStopMm + kTolMm);
  CHECK(ev.find("protective stop") == std::string::npos);
  CHECK(dev < 0.1);
  CHECK(acc <= 1.0 + 1e-3);
  CHECK(tr.x.size() > ref.x.size() + 100);  // it did run slower
}

// The speed scale keeps the predicted stop under the limit itself, not only under limit +
// tolerance: a movel at 200 mm/s with `safety reduced` switched on while it accelerates (at
// 60 mm/s), Reduced mode's stop distance limit 5 mm, then (a run of its own) its stop time limit
// 0.08 s; the stop predicted from the commanded state at every cycle after the switch stays
// within the limit and a numeric margin of 1 % (the prediction from the telemetry's differenced
// acceleration is not the monitor's own to the last bit); no protective stop.
TEST(SpeedScaling, AScaledLineKeepsThePredictedStopUnderItsLimitNotOnlyItsTolerance) {
  const kin::Pose w = work_tcp();
  MoveLine side;
  side.target = w;
  side.target.translation().y() += 0.15;
  side.speed = 0.2;
  struct Case {
    const char* what;
    double distance_mm, time_s;
  } const cases[] = {{"stop distance 5 mm", 5.0, 0}, {"stop time 0.08 s", 0, 0.08}};
  for (const Case& k : cases) {
    FwConfig c = table(500);
    if (k.distance_mm > 0) c.safety_reduced_stop_distance_mm = k.distance_mm;
    if (k.time_s > 0) c.safety_reduced_stop_time_s = k.time_s;
    Rig r(c);
    r.enable();
    r.to_work();
    MoveContext cx;
    cx.ik = r.app.console->jog_context().ik;
    const MoveResult m = r.svc().move(side, cx);
    CHECK_TEXT(m.ok(), m.reason.c_str());
    Trace t;
    kin::JointVector qd_prev;
    kin::JointTrajectory scratch;
    int switched = -1;
    double worst_mm = 0, worst_s = 0, unswitched_mm = 0, unswitched_s = 0;
    run_traced(r, t, 20000, [&](int) {
      double ts = 0;
      const double d = predicted_stop_mm(r, qd_prev, scratch, &ts);
      if (switched >= 0) worst_mm = std::fmax(worst_mm, d), worst_s = std::fmax(worst_s, ts);
      if (switched < 0 && t.x.size() > 2 && t.speed(t.x.size() - 1) > 60.0) {
        switched = int(t.x.size());
        unswitched_mm = d, unswitched_s = ts;
        CHECK(r.svc().set_safety_mode(kin::SafetyMode::reduced).ok());
      }
    });
    char fig[300];
    std::snprintf(fig, sizeof fig, "%s: at the switch %.2f mm / %.3f s; after it predicted up to %.3f mm / %.4f s; %u stops, last event: %s",
                  k.what, unswitched_mm, unswitched_s, worst_mm, worst_s, unsigned(r.tel().safety_stops), r.last_event().c_str());
    std::printf("\n  %s", fig);
    CHECK_TEXT(switched > 0, fig);
    CHECK_EQUAL(0u, r.tel().safety_stops);
    if (k.distance_mm > 0) CHECK_TEXT(worst_mm <= k.distance_mm * 1.01, fig);
    if (k.time_s > 0) CHECK_TEXT(worst_s <= k.time_s * 1.01, fig);
    CHECK((t.x.back() - side.target.translation()).norm() < 1e-6);
    LONGS_EQUAL(0, r.rt_allocs);
  }
}

// The trigger look-ahead takes the Reduced mode's stop limits: a 200 mm/s line (planned without
// the trigger plane) towards a trigger plane 100 mm ahead, Reduced mode with a 5 mm stop distance
// and no Reduced speed limit, Normal with no limits. The look-ahead slows the line before the
// plane so that the stop predicted from the commanded state as the tool crosses it, and after,
// is within 5 mm (+ the 1 % margin of the prediction from the telemetry): no protective stop.
// Were the Reduced stop limits left out of the look-ahead, the line would cross at full speed
// (predicted stop ~10 mm) and be stopped at once.
TEST(SpeedScaling, TheTriggerLookAheadKeepsTheReducedStopDistance) {
  constexpr double kStopMm = 5.0;
  double y_plane = 0;
  FwConfig c = table(500);
  y_plane = work_tcp().translation().y() * 1000.0 + 100;
  c.safety_reduced_planes = {0, -1, 0, -y_plane};
  c.safety_reduced_stop_distance_mm = kStopMm;
  Rig r(c);
  r.enable();
  r.to_work();
  plan_without_trigger_planes(r);
  const kin::Pose w = work_tcp();
  MoveLine side;
  side.target = w;
  side.target.translation().y() += 0.15;
  side.speed = 0.2;
  MoveContext cx;
  cx.ik = r.app.console->jog_context().ik;
  const MoveResult m = r.svc().move(side, cx);
  CHECK_TEXT(m.ok(), m.reason.c_str());
  Trace tr;
  kin::JointVector qd_prev;
  kin::JointTrajectory scratch;
  double before = 0, past = 0;
  bool crossed = false;
  run_traced(r, tr, 20000, [&](int) {
    const double d = predicted_stop_mm(r, qd_prev, scratch);
    crossed = crossed || (!tr.x.empty() && tr.x.back().y() * 1e3 + kRadiusMm > y_plane);
    (crossed ? past : before) = std::fmax(crossed ? past : before, d);
  });
  char fig[240];
  std::snprintf(fig, sizeof fig, "line into a trigger zone with a %.0f mm Reduced stop distance: predicted stop up to %.2f mm "
                "before the plane, %.3f mm past it; %u stops, last event: %s",
                kStopMm, before, past, unsigned(r.tel().safety_stops), r.last_event().c_str());
  std::printf("\n  %s", fig);
  CHECK_TEXT(crossed, fig);
  CHECK_TEXT(before > 1.5 * kStopMm, fig);  // it ran fast outside
  CHECK_TEXT(past <= kStopMm * 1.01, fig);
  CHECK_EQUAL(0u, r.tel().safety_stops);
  CHECK((tr.x.back() - side.target.translation()).norm() < 1e-6);
  LONGS_EQUAL(0, r.rt_allocs);
}
