// SPDX-License-Identifier: Apache-2.0
// The arm service's typed interface on the puma560 with virtual drives (console_rig.hpp):
// a refused move says what and by how much in SI (no text), a dry run plans the same knots
// as the real run and queues nothing, arm control answers typed results. Expected values
// come from the joint limits and the request, never from the service's code.
#include <cmath>
#include <cstdio>
#include <string>
#include <type_traits>
#include <vector>

#include "../console/console_rig.hpp"
#include "../program/tmp_dir.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/kinematics/dynamics.hpp"
#include "servoarm/service/arm_service.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;

namespace {
constexpr double kDeg = M_PI / 180.0;

/// Push `n` events into the controller's event queue (as the control thread would), the
/// service taking them into its stream whenever the queue is full.
void emit_events(test::ConsoleRig& r, int n, std::int8_t first_joint = 0) {
  for (int i = 0; i < n; ++i) {
    Event e;
    e.kind = EventKind::homing;
    e.joint = static_cast<std::int8_t>((first_joint + i) % 6);
    std::snprintf(e.message, sizeof e.message, "joint %d homed", e.joint + 1);
    if (!r.app.ctl->events().push(e)) {
      r.app.console->service().poll_events();
      CHECK(r.app.ctl->events().push(e));
    }
  }
  r.app.console->service().poll_events();
}

kin::JointVector joints(std::initializer_list<double> deg) {
  kin::JointVector q(static_cast<int>(deg.size()));
  int j = 0;
  for (double d : deg) q[j++] = d * kDeg;
  return q;
}
}  // namespace

TEST_GROUP(ArmService){};

// A goal beyond a joint limit: refused as joint_limit naming the joint, its value and limits
// in SI; nothing queued.
TEST(ArmService, AJointLimitRefusalCarriesItsFiguresInSi) {
  test::ConsoleRig r;
  r.enable();
  ArmService& svc = r.app.console->service();
  const kin::JointLimits lim = r.app.ctl->limits();
  MoveJoints m;
  m.goal = joints({0, -45, 180, 0, 45, 0});
  m.goal[3] = lim.upper[3] + 1e-12;
  MoveContext cx;
  const MoveResult res = svc.move(m, cx);
  CHECK(res.error == CmdError::limits);
  CHECK(res.refusal == MoveRefusal::joint_limit);
  LONGS_EQUAL(3, res.joint);
  DOUBLES_EQUAL(lim.upper[3] + 1e-12, res.value, 0);
  DOUBLES_EQUAL(lim.lower[3], res.lower, 0);
  DOUBLES_EQUAL(lim.upper[3], res.upper, 0);
  CHECK(res.reason.empty());
  CHECK(r.app.ctl->motions().empty());
}

// The dry run of a move plans what the real run then queues: same goal, same duration, bit
// for bit; the dry run queues nothing and keeps its own tail.
TEST(ArmService, ADryRunPlansTheKnotsTheRealRunQueues) {
  test::ConsoleRig r;
  r.enable();
  ArmService& svc = r.app.console->service();
  PathShadow shadow;
  DryRun dry;
  dry.tail = svc.tail();
  dry.shadow = &shadow;
  MoveContext dcx;
  dcx.dry = &dry;
  MoveJoints m;
  m.goal = joints({10, -40, 170, 5, 40, -5});
  m.speed_pct = 70;
  const MoveResult d = svc.move(m, dcx);
  CHECK(d.ok());
  LONGS_EQUAL(0, d.id);
  CHECK(r.app.ctl->motions().empty());
  CHECK((dry.tail - m.goal).norm() == 0);
  DOUBLES_EQUAL(d.duration, dry.time, 0);
  const MoveResult q = svc.move(m, MoveContext{});
  CHECK(q.ok());
  CHECK(q.id > 0);
  CHECK(!r.app.ctl->motions().empty());
  DOUBLES_EQUAL(d.duration, q.duration, 0);
  CHECK((q.goal - d.goal).norm() == 0);
}

// Arm control: typed results. disable is accepted; a move on the disabled arm is refused as
// arm_state with a one-line reason; enable is accepted again.
TEST(ArmService, ArmControlAnswersTypedResults) {
  test::ConsoleRig r;
  r.enable();
  ArmService& svc = r.app.console->service();
  const ControlResult off = svc.control(RequestOp::disable);
  CHECK_TEXT(off.ok(), off.reason.c_str());
  for (int i = 0; i < 200; ++i) r.cycle();
  MoveJoints m;
  m.goal = joints({0, -45, 180, 0, 45, 0});
  const MoveResult res = svc.move(m, MoveContext{});
  CHECK(res.refusal == MoveRefusal::arm_state);
  CHECK(res.error == CmdError::bad_state);
  CHECK(!res.reason.empty() && res.reason.find('\n') == std::string::npos);
  const ControlResult on = svc.enable();
  CHECK_TEXT(on.ok(), on.reason.c_str());
}

// The event stream: the service numbers every event it takes from the control thread, one
// more than the one before, and stamps it with the control cycle it saw it at (RT time).
TEST(ArmService, EventSequenceNumbersIncreaseByOne) {
  test::ConsoleRig r;
  for (int i = 0; i < 5; ++i) r.cycle();
  ArmService& svc = r.app.console->service();
  const std::uint64_t cycles_before = r.app.ctl->telemetry().cycles;
  const EventBatch start = svc.events_since(0);
  const std::uint64_t after = start.events.empty() ? 0 : start.events.back().seq;
  emit_events(r, 10, 2);
  const EventBatch b = svc.events_since(after);
  LONGS_EQUAL(0, b.missed);
  LONGS_EQUAL(10, b.events.size());
  for (std::size_t i = 0; i < b.events.size(); ++i) {
    const ArmEvent& e = b.events[i];
    CHECK(e.seq == after + 1 + i);
    CHECK(e.kind == ArmEventKind::homing);
    LONGS_EQUAL((2 + i) % 6, e.joint);
    CHECK(e.cycle >= cycles_before && e.cycle <= r.app.ctl->telemetry().cycles);
    DOUBLES_EQUAL(static_cast<double>(e.cycle) * r.app.ctl->period_s(), e.t, 1e-12);
    STRCMP_EQUAL(("joint " + std::to_string(e.joint + 1) + " homed").c_str(), std::string(svc.event_detail(e)).c_str());
  }
  CHECK(svc.events_since(b.events.back().seq).events.empty());
}

// A reader slower than the ring: it gets the oldest events still kept and a count of the
// ones it missed (the oldest seq it gets is larger than the one it asked after).
TEST(ArmService, ASlowReaderSeesHowManyEventsItMissed) {
  test::ConsoleRig r;
  ArmService& svc = r.app.console->service();
  const EventBatch start = svc.events_since(0);
  const std::uint64_t after = start.events.empty() ? 0 : start.events.back().seq;
  const int extra = 17;
  emit_events(r, static_cast<int>(kEventRing) + extra);
  const EventBatch b = svc.events_since(after);
  LONGS_EQUAL(extra, b.missed);
  LONGS_EQUAL(kEventRing, b.events.size());
  CHECK(b.events.front().seq == after + 1 + extra);
  CHECK(b.events.back().seq == after + kEventRing + extra);
  CHECK(svc.event_detail(b.events.front()).size() > 0);
}

// Two readers at their own pace each get every event once, in order.
TEST(ArmService, TwoReadersEachGetEveryEvent) {
  test::ConsoleRig r;
  ArmService& svc = r.app.console->service();
  const EventBatch start = svc.events_since(0);
  const std::uint64_t first = start.events.empty() ? 1 : start.events.back().seq + 1;
  std::uint64_t a = first - 1, b = first - 1;
  std::vector<std::uint64_t> got_a, got_b;
  for (int round = 0; round < 6; ++round) {
    emit_events(r, 7 + round);
    const EventBatch ea = svc.events_since(a);  // reader a reads every round
    LONGS_EQUAL(0, ea.missed);
    for (const ArmEvent& e : ea.events) got_a.push_back(e.seq);
    if (!ea.events.empty()) a = ea.events.back().seq;
    if (round % 3 == 2) {  // reader b every third round
      const EventBatch eb = svc.events_since(b);
      LONGS_EQUAL(0, eb.missed);
      for (const ArmEvent& e : eb.events) got_b.push_back(e.seq);
      if (!eb.events.empty()) b = eb.events.back().seq;
    }
  }
  const std::size_t total = 7 + 8 + 9 + 10 + 11 + 12;
  LONGS_EQUAL(total, got_a.size());
  LONGS_EQUAL(total, got_b.size());
  for (std::size_t i = 0; i < total; ++i) {
    CHECK(got_a[i] == first + i);
    CHECK(got_b[i] == first + i);
  }
}

// No text in an event: a fixed-size, trivially copyable record of figures (the control
// thread's own line, 120 characters, would not fit in it); front ends render it.
TEST(ArmService, AnEventIsTypedWithoutText) {
  static_assert(std::is_trivially_copyable_v<ArmEvent>);
  CHECK(sizeof(ArmEvent) < sizeof(Event::message));
}

// Jog: typed requests in SI, typed results. An increment larger than the joint's range is
// refused as `range` with the joint's limits; at a limit as `at_limit` with where it stands;
// nothing moves either way.
TEST(ArmService, AJointJogRefusalCarriesItsFigures) {
  test::ConsoleRig r;
  r.enable();
  ArmService& svc = r.app.console->service();
  const kin::JointLimits lim = r.app.ctl->limits();
  JointJog jj;
  jj.joint = 1;
  jj.increment = (lim.upper[1] - lim.lower[1]) * 1.01;
  const JogResult big = svc.jog(jj, JogContext{});
  CHECK(big.error == CmdError::out_of_range);
  CHECK(big.refusal == JogRefusal::range);
  LONGS_EQUAL(1, big.joint);
  DOUBLES_EQUAL(lim.lower[1], big.lower, 0);
  DOUBLES_EQUAL(lim.upper[1], big.upper, 0);
  CHECK(r.app.ctl->telemetry().state != ArmState::jogging);
}

// A joint jog past the limit stops on it: accepted, clamped, with the value asked and the
// limit it stops at (SI); a second one from there is refused as at_limit.
TEST(ArmService, AJointJogPastTheLimitIsClampedThenRefusedAtIt) {
  test::ConsoleRig r;
  r.enable();
  ArmService& svc = r.app.console->service();
  const kin::JointLimits lim = r.app.ctl->limits();
  const double q0 = r.app.ctl->telemetry().q_cmd[5];
  JointJog jj;
  jj.joint = 5;
  jj.increment = (lim.upper[5] - q0) + 0.01;  // 0.01 rad past the limit (within the range)
  jj.speed_pct = 100;
  const JogResult a = svc.jog(jj, JogContext{});
  CHECK_TEXT(a.ok(), a.reason.c_str());
  CHECK(a.clamped);
  LONGS_EQUAL(5, a.joint);
  DOUBLES_EQUAL(q0 + jj.increment, a.asked, 1e-12);
  DOUBLES_EQUAL(lim.upper[5], a.value, 0);
  for (int i = 0; i < 20000 && r.app.ctl->telemetry().state == ArmState::jogging; ++i) r.cycle();
  svc.poll_events();
  const JogResult b = svc.jog(jj, JogContext{});
  CHECK(b.error == CmdError::limits);
  CHECK(b.refusal == JogRefusal::at_limit);
  DOUBLES_EQUAL(lim.upper[5], b.value, 1e-9);
}

// A tool jog to a pose out of reach: refused as unreachable, nothing moves; keep-alive and
// cancel answer typed results.
TEST(ArmService, AToolJogOutOfReachIsRefusedAndCancelAnswers) {
  test::ConsoleRig r;
  r.enable();
  ArmService& svc = r.app.console->service();
  ToolJog tj;
  tj.axis = 0;
  tj.increment = 10.0;  // m: far beyond the arm's reach
  const JogResult far = svc.jog(tj, r.app.console->jog_context());
  CHECK(far.error == CmdError::unreachable);
  CHECK(far.refusal == JogRefusal::unreachable);
  CHECK(r.app.ctl->telemetry().state != ArmState::jogging);
  const ControlResult c = svc.jog_cancel();
  CHECK_TEXT(c.ok(), c.reason.c_str());
  const ControlResult k = svc.jog_keepalive();
  CHECK(k.error != CmdError::timeout);
}

// Digital outputs by index ([[output]] order): a typed result; an index beyond the table is
// refused with the table's size; on / off at once reach the drive's word; M62 / M63 wait
// for the next move (pending, not sent); a dry run checks and changes nothing.
TEST(ArmService, OutputsAreSetByIndexWithTypedResults) {
  FwConfig cfg;
  cfg.outputs = {{"gripper", 3, 16}, {"lamp", 6, 18}};  // nodes 1..6 = joints 1..6
  test::ConsoleRig r(cfg);
  r.enable();
  ArmService& svc = r.app.console->service();
  LONGS_EQUAL(2, svc.output_count());
  OutputRequest rq;
  rq.index = 2;
  rq.on = true;
  const OutputResult none = svc.set_output(rq);
  CHECK(none.error == CmdError::out_of_range);
  CHECK(none.refusal == OutputRefusal::no_output);
  rq.index = 1;
  rq.dry = true;
  CHECK(svc.set_output(rq).ok());
  for (int i = 0; i < 20; ++i) r.cycle();
  CHECK(!svc.output_on(1));
  rq.dry = false;
  CHECK(svc.set_output(rq).ok());
  for (int i = 0; i < 20; ++i) r.cycle();
  CHECK(svc.output_on(1));
  CHECK((r.app.ctl->telemetry().outputs[5] >> 18) & 1u);
  OutputRequest sync;
  sync.index = 0;
  sync.on = true;
  sync.sync = true;
  CHECK(svc.set_output(sync).ok());
  LONGS_EQUAL(1, svc.pending_outputs().size());
  LONGS_EQUAL(2, svc.pending_outputs()[0].joint);
  LONGS_EQUAL(1u << 16, svc.pending_outputs()[0].value);
  for (int i = 0; i < 20; ++i) r.cycle();
  CHECK(!svc.output_on(0));
}

// status(): one telemetry snapshot as typed figures (SI): the state, the measured and
// commanded joints, each joint's homing (joints 2 and 5 home by method 19 and are not
// homed yet; the others are absolute), the queue. A query changes nothing: asking it twice
// leaves the motion queue, the event stream and the controller's generation as they were.
TEST(ArmService, StatusIsATypedSnapshotAndChangesNothing) {
  FwConfig c;
  c.drives.resize(6);
  c.drives[1].homing_method = "19";
  c.drives[4].homing_method = "19";
  test::ConsoleRig r(c);
  r.enable();
  ArmService& svc = r.app.console->service();
  const Telemetry t = r.app.ctl->telemetry();
  const std::uint64_t seq = svc.next_event_seq();
  const ArmStatus st = svc.status();
  const ArmStatus again = svc.status();
  CHECK(st.state == ArmState::idle);
  CHECK(again.state == ArmState::idle);
  LONGS_EQUAL(0, st.queued);
  LONGS_EQUAL(6, st.q.size());
  LONGS_EQUAL(6, st.homing.size());
  for (int j = 0; j < 6; ++j) {
    DOUBLES_EQUAL(t.q_act[static_cast<std::size_t>(j)], st.q[j], 1e-9);
    DOUBLES_EQUAL(t.q_cmd[static_cast<std::size_t>(j)], st.q_cmd[j], 1e-9);
    const bool by_method = j == 1 || j == 4;
    CHECK_TEXT(st.homing[static_cast<std::size_t>(j)] == (by_method ? JointHoming::unhomed : JointHoming::absolute),
               to_string(st.homing[static_cast<std::size_t>(j)]));
  }
  CHECK(!st.all_homed);
  CHECK(st.fault_text.empty());
  LONGS_EQUAL(100, st.feed_pct);
  CHECK(r.app.ctl->motions().empty());
  LONGS_EQUAL(seq, svc.next_event_seq());
  CHECK(r.app.ctl->telemetry().generation == t.generation);
}

// arm_limits(): the chain's joint limits and kinds and the linear speeds, in SI.
TEST(ArmService, LimitsAreTheChainsInSi) {
  test::ConsoleRig r;
  const ArmLimits a = r.app.console->service().arm_limits();
  LONGS_EQUAL(6, a.prismatic.size());
  for (int j = 0; j < 6; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    DOUBLES_EQUAL(r.app.chain.joint(j).lower, a.joints.lower[ju], 0);
    DOUBLES_EQUAL(r.app.chain.joint(j).upper, a.joints.upper[ju], 0);
    CHECK(!a.prismatic[ju]);  // the puma560: six revolute joints
  }
  DOUBLES_EQUAL(FwConfig{}.max_linear_speed_mm_s * 1e-3, a.max_linear_speed, 1e-12);
  DOUBLES_EQUAL(FwConfig{}.linear_speed_mm_s * 1e-3, a.default_linear_speed, 1e-12);
}

// set_settings(): checked whole. A default line speed above the maximum is refused naming
// the setting and its range, and nothing changes; accepted settings are the ones every front
// end then uses (the console's `limits` prints the new default speed, the park move goes at
// the new joint speed).
TEST(ArmService, SettingsAreCheckedWholeAndUsedByEveryFrontEnd) {
  test::ConsoleRig r;
  ArmService& svc = r.app.console->service();
  const MotionSettings before = svc.settings();
  MotionSettings s = before;
  s.default_linear_speed = s.max_linear_speed * 2;
  s.default_joint_speed_pct = 20;
  const SettingsResult bad = svc.set_settings(s);
  CHECK(bad.error == CmdError::out_of_range);
  CHECK(bad.setting == Setting::default_linear_speed);
  DOUBLES_EQUAL(s.default_linear_speed, bad.value, 0);
  DOUBLES_EQUAL(s.max_linear_speed, bad.upper, 0);
  DOUBLES_EQUAL(before.default_joint_speed_pct, svc.settings().default_joint_speed_pct, 0);
  s.home = kin::JointVector::Zero(6);
  s.home[2] = r.app.ctl->limits().upper[2] + 0.1;
  s.default_linear_speed = 0.05;
  const SettingsResult home = svc.set_settings(s);
  CHECK(home.setting == Setting::home);
  LONGS_EQUAL(2, home.joint);
  s.home = before.home;
  const SettingsResult ok = svc.set_settings(s);
  CHECK(ok.ok());
  DOUBLES_EQUAL(0.05, svc.settings().default_linear_speed, 0);
  DOUBLES_EQUAL(20, svc.park_request().speed_pct, 0);
  const std::string lim = r.cmd("limits");
  CHECK_TEXT(lim.find("linear speed: default 50.0 mm/s") != std::string::npos, lim.c_str());
}

// The feed override lives in the service: out of 10..200 % refused with the range; set, it
// scales the moves planned from then on (a joint move at 50 % takes longer) and the console's
// status reports it.
TEST(ArmService, TheFeedOverrideIsTheServicesAndScalesMoves) {
  test::ConsoleRig r;
  r.enable();
  ArmService& svc = r.app.console->service();
  const SettingsResult big = svc.set_feed_override(250);
  CHECK(big.error == CmdError::out_of_range);
  CHECK(big.setting == Setting::feed_override);
  DOUBLES_EQUAL(200, big.upper, 0);
  LONGS_EQUAL(100, svc.feed_override());
  PathShadow shadow;
  DryRun dry;
  dry.tail = svc.tail();
  dry.shadow = &shadow;
  MoveContext cx;
  cx.dry = &dry;
  MoveJoints m;
  m.goal = joints({10, -40, 170, 5, 40, -5});
  m.speed_pct = 40;
  const double full = svc.move(m, cx).duration;
  dry.tail = svc.tail();
  CHECK(svc.set_feed_override(50).ok());
  LONGS_EQUAL(50, svc.feed_override());
  const double half = svc.move(m, cx).duration;
  CHECK(half > full * 1.2);
  const std::string st = r.cmd("status");
  CHECK_TEXT(st.find("feed_override=50%") != std::string::npos, st.c_str());
}

// The request table: every op once, in the enum's order, each name unique and found again by
// its name; the queries are the ops that only read.
TEST(ArmService, EveryRequestHasOneNameInTheTable) {
  const std::size_t n = sizeof kServiceOps / sizeof kServiceOps[0];
  for (std::size_t i = 0; i < n; ++i) {
    LONGS_EQUAL(i, static_cast<std::size_t>(kServiceOps[i].op));
    ServiceOp back{};
    CHECK_TEXT(service_op_from(kServiceOps[i].name, back), kServiceOps[i].name);
    CHECK(back == kServiceOps[i].op);
    STRCMP_EQUAL(kServiceOps[i].name, to_string(kServiceOps[i].op));
    for (std::size_t k = 0; k < i; ++k) CHECK(std::string(kServiceOps[k].name) != kServiceOps[i].name);
  }
  ServiceOp none{};
  CHECK(!service_op_from("no_such_request", none));
  CHECK(kServiceOps[static_cast<std::size_t>(ServiceOp::status)].query);
  CHECK(!kServiceOps[static_cast<std::size_t>(ServiceOp::set_settings)].query);
}

// Tools through the service: defined, selected and deleted by name with typed results; the
// active tool is the status's, and its pose is the flange's FK times the tool's (SI); a bad
// name, an unknown tool and deleting the active one are refused with what was wrong.
TEST(ArmService, ToolsAreDefinedSelectedAndDeletedByName) {
  test::ConsoleRig r;
  r.enable();
  ArmService& svc = r.app.console->service();
  LONGS_EQUAL(1, svc.tool_count());
  STRCMP_EQUAL("tool0", svc.tool(0).name.c_str());
  NamedPose g;
  g.name = "gripper";
  g.pose.translation() = Eigen::Vector3d(0, 0, 0.12);
  const FrameResult d = svc.define_tool(g);
  CHECK(d.ok());
  CHECK(!d.redefined);
  LONGS_EQUAL(2, svc.tool_count());
  NamedPose bad = g;
  bad.name = "tool0";
  CHECK(svc.define_tool(bad).refusal == FrameRefusal::bad_name);
  CHECK(svc.select_tool("nothing").refusal == FrameRefusal::not_defined);
  const FrameResult sel = svc.select_tool("gripper");
  CHECK(sel.ok());
  CHECK(sel.active);
  const ArmStatus st = svc.status();
  STRCMP_EQUAL("gripper", st.tool.c_str());
  kin::Pose flange;
  CHECK(kin::forward(r.app.chain, st.q, flange) == kin::Status::ok);
  CHECK(((flange * g.pose).translation() - st.pose.translation()).norm() < 1e-12);
  CHECK(svc.delete_tool("gripper").refusal == FrameRefusal::active);
  CHECK(svc.select_tool("tool0").ok());
  CHECK(svc.delete_tool("gripper").ok());
  LONGS_EQUAL(1, svc.tool_count());
}

// Tools and frames change only while nothing moves or is queued: with a move queued a
// select is refused as arm_busy (with the arm's state and the queue) and nothing changes.
TEST(ArmService, ToolsAndFramesDoNotChangeWhileMotionsAreQueued) {
  test::ConsoleRig r;
  r.enable();
  ArmService& svc = r.app.console->service();
  NamedPose f;
  f.name = "table";
  f.pose.translation() = Eigen::Vector3d(0.3, 0, 0);
  CHECK(svc.define_frame(f).ok());
  MoveJoints m;
  m.goal = joints({10, -40, 170, 5, 40, -5});
  CHECK(svc.move(m, MoveContext{}).ok());
  const FrameResult busy = svc.select_frame("table");
  CHECK(busy.refusal == FrameRefusal::arm_busy);
  CHECK(busy.error == CmdError::bad_state);
  CHECK(busy.queued > 0 || busy.arm == ArmState::moving);
  LONGS_EQUAL(0, svc.active_frame());
  for (int i = 0; i < 20000 && (r.app.ctl->telemetry().state != ArmState::idle || !r.app.ctl->motions().empty()); ++i) r.cycle();
  const FrameResult ok = svc.select_frame("table");
  CHECK(ok.ok());
  const ArmStatus st = svc.status();
  STRCMP_EQUAL("table", st.frame.c_str());
  CHECK(((f.pose.inverse() * st.pose).translation() - st.pose_in_frame.translation()).norm() < 1e-12);
}

// A G54..G59 frame selected before it is set is added as the identity; each change goes to
// the frames file, which a service started later loads with the same tools, frames and
// selection.
TEST(ArmService, FramesAreKeptInTheFramesFile) {
  const std::string dir = test::make_tmp_dir();
  const std::string path = dir + "/frames.toml";
  {
    test::ConsoleRig r;
    ArmService& svc = r.app.console->service();
    CHECK(svc.load_frames(path).empty());
    const FrameResult g55 = svc.select_frame("g55", true);
    CHECK(g55.ok());
    CHECK(g55.added);
    NamedPose t;
    t.name = "pen";
    t.pose.translation() = Eigen::Vector3d(0, 0, 0.05);
    CHECK(svc.define_tool(t).ok());
    CHECK(svc.select_tool("pen").ok());
  }
  test::ConsoleRig r2;
  ArmService& svc = r2.app.console->service();
  CHECK(svc.load_frames(path).empty());
  STRCMP_EQUAL("pen", svc.tool(svc.active_tool()).name.c_str());
  STRCMP_EQUAL("g55", svc.frame(svc.active_frame()).name.c_str());
  DOUBLES_EQUAL(0.05, svc.tool(svc.active_tool()).pose.translation().z(), 1e-15);
}

// Record through the service: started at a rate, the arm jogged along one joint, the path is
// its samples thinned to the two ends (a straight line in joint space) with the blend half the
// tolerance; a second start is refused as recording, a path after stop as not_recording.
TEST(ArmService, ARecordingIsTheJointPathThinnedWithinTheTolerance) {
  test::ConsoleRig r;
  r.enable();
  ArmService& svc = r.app.console->service();
  const kin::JointVector q0 = svc.status().q;
  const RecordResult start = svc.record_start(100);
  CHECK(start.ok());
  LONGS_EQUAL(1, start.samples);  // where the arm is now
  CHECK(svc.record_start(100).refusal == RecordRefusal::recording);
  JointJog jj;
  jj.joint = 0;
  jj.increment = 0.2;
  jj.speed_pct = 50;
  CHECK(svc.jog(jj, JogContext{}).ok());
  for (int i = 0; i < 20000 && (i < 10 || r.app.ctl->telemetry().state == ArmState::jogging); ++i) {
    r.cycle();
    svc.tick();
  }
  const kin::JointVector q1 = svc.status().q;
  CHECK(svc.record_samples() > 10);
  const RecordResult path = svc.record_path(0.01);
  CHECK(path.ok());
  DOUBLES_EQUAL(0.005, path.blend, 0);
  LONGS_EQUAL(2, path.waypoints.size());
  CHECK((path.waypoints.front() - q0).norm() < 1e-9);
  CHECK((path.waypoints.back() - q1).norm() < 1e-9);
  CHECK(svc.recording());
  CHECK(svc.record_stop().ok());
  CHECK(!svc.recording());
  CHECK(svc.record_path(0.01).refusal == RecordRefusal::not_recording);
}

// Douglas-Peucker keeps a corner farther than the tolerance from the chord, drops one nearer.
TEST(ArmService, DecimateKeepsCornersBeyondTheTolerance) {
  std::vector<kin::JointVector> q;
  for (double y : {0.0, 0.004, 0.02, 0.004, 0.0}) {
    kin::JointVector v(2);
    v << static_cast<double>(q.size()), y;
    q.push_back(v);
  }
  const std::vector<std::size_t> keep = decimate(q, 0.01);
  LONGS_EQUAL(3, keep.size());
  LONGS_EQUAL(0, keep[0]);
  LONGS_EQUAL(2, keep[1]);
  LONGS_EQUAL(4, keep[2]);
}

// teach_here(): at rest it gives the measured joints, the active tool's pose (FK of them) and
// the tool and frame; with a move queued it is refused as queued, the arm moving as
// arm_state; it changes nothing (the queue keeps its move).
TEST(ArmService, TeachHereGivesTheArmsPlaceOrWhyNot) {
  test::ConsoleRig r;
  r.enable();
  ArmService& svc = r.app.console->service();
  const TeachResult here = svc.teach_here();
  CHECK(here.ok());
  const Telemetry t = r.app.ctl->telemetry();
  for (int j = 0; j < 6; ++j) DOUBLES_EQUAL(t.q_act[static_cast<std::size_t>(j)], here.q[j], 1e-12);
  kin::Pose fk;
  CHECK(kin::forward(r.app.chain, here.q, fk) == kin::Status::ok);
  CHECK((fk.translation() - here.pose.translation()).norm() < 1e-12);
  STRCMP_EQUAL("tool0", here.tool.c_str());
  STRCMP_EQUAL("base", here.frame.c_str());
  MoveJoints m;
  m.goal = joints({10, -40, 170, 5, 40, -5});
  CHECK(svc.move(m, MoveContext{}).ok());
  const TeachResult queued = svc.teach_here();
  CHECK(queued.refusal == TeachRefusal::queued);
  CHECK(queued.error == CmdError::bad_state);
  LONGS_EQUAL(1, queued.queued);
  LONGS_EQUAL(1, r.app.ctl->motions().size());
  for (int i = 0; i < 20; ++i) r.cycle();
  const TeachResult moving = svc.teach_here();
  CHECK(moving.refusal == TeachRefusal::arm_state);
  CHECK(moving.arm == ArmState::moving);
}

// An unhomed arm: refused as not_homed naming the joints, the joints still given.
TEST(ArmService, TeachHereOnAnUnhomedArmNamesTheJoints) {
  FwConfig c;
  c.drives.resize(6);
  c.drives[4].homing_method = "19";
  test::ConsoleRig r(c);
  r.enable();
  const TeachResult here = r.app.console->service().teach_here();
  CHECK(here.refusal == TeachRefusal::not_homed);
  CHECK(here.error == CmdError::not_homed);
  CHECK_TEXT(here.reason.find("joint 5 not homed") != std::string::npos, here.reason.c_str());
  LONGS_EQUAL(6, here.q.size());
}

// Teach points through the service, with no console command: taught where the arm is (its
// joints, the active tool's pose and names), kept in the points file as the loader reads it,
// listed, gone to by a joint move that ends at the point's joints, deleted; an unknown name,
// a bad name and a dry run are typed results that change neither the points nor the file.
TEST(ArmService, TeachPointsAreTaughtListedGoneToAndDeletedThroughTheService) {
  test::ConsoleRig r;
  r.enable();
  ArmService& svc = r.app.console->service();
  const std::string dir = test::make_tmp_dir();
  const std::string file = dir + "/points.toml";
  STRCMP_EQUAL("", svc.load_points(file).c_str());
  STRCMP_EQUAL(file.c_str(), svc.points_file().c_str());
  TeachRequest tr;
  tr.name = "pick";
  const PointResult t = svc.teach(tr);
  CHECK(t.ok());
  CHECK(t.kept);
  CHECK(!t.replaced);
  LONGS_EQUAL(1, t.count);
  const Telemetry tel = r.app.ctl->telemetry();
  for (int j = 0; j < 6; ++j) DOUBLES_EQUAL(tel.q_act[static_cast<std::size_t>(j)], t.point.q[j], 0);
  kin::Pose fk;
  CHECK(kin::forward(r.app.chain, t.point.q, fk) == kin::Status::ok);
  CHECK((fk.translation() - t.point.pose.translation()).norm() < 1e-12);
  STRCMP_EQUAL("tool0", t.point.tool.c_str());
  prog::PointsData d;
  STRCMP_EQUAL("", prog::load_points_file(file, 6, d).c_str());
  LONGS_EQUAL(1, d.points.size());
  CHECK((d.points[0].q - t.point.q).norm() == 0);
  LONGS_EQUAL(1, svc.points().points.size());

  // a dry run and a bad name: nothing stored
  tr.name = "place";
  tr.dry = true;
  CHECK(svc.teach(tr).ok());
  LONGS_EQUAL(1, svc.points().points.size());
  tr.dry = false;
  tr.name = "9lives";
  const PointResult bad = svc.teach(tr);
  CHECK(bad.refusal == PointRefusal::bad_point);
  CHECK(bad.error == CmdError::bad_option);
  LONGS_EQUAL(1, svc.points().points.size());

  // go-to: away first, then back to the point by a joint move ending at its joints
  MoveJoints away;
  away.goal = joints({10, -40, 170, 5, 40, -5});
  CHECK(svc.move(away, MoveContext{}).ok());
  PointMove pm;
  pm.name = "nowhere";
  const PointResult none = svc.move_to_point(pm, MoveContext{});
  CHECK(none.refusal == PointRefusal::no_point);
  CHECK(none.error == CmdError::bad_option);
  LONGS_EQUAL(1, r.app.ctl->motions().size());
  pm.name = "pick";
  const PointResult go = svc.move_to_point(pm, MoveContext{});
  CHECK(go.ok());
  CHECK(go.move.id > 0);
  CHECK((go.move.goal - t.point.q).norm() == 0);

  // delete: unknown refused, known removed from the service and the file
  const PointResult gone = svc.delete_point("nowhere");
  CHECK(gone.refusal == PointRefusal::no_point);
  CHECK(svc.delete_point("pick", true).ok());
  LONGS_EQUAL(1, svc.points().points.size());
  const PointResult del = svc.delete_point("pick");
  CHECK(del.ok());
  LONGS_EQUAL(0, del.count);
  LONGS_EQUAL(0, svc.points().points.size());
  STRCMP_EQUAL("", prog::load_points_file(file, 6, d).c_str());
  LONGS_EQUAL(0, d.points.size());
  test::remove_tree(dir);
}

// ---------------------------------------------------------------------------
// The safety envelope before motion (docs/safety.md)
// ---------------------------------------------------------------------------
namespace {
// The puma560's tool point at joints q (m, base frame), computed here with the chain.
Eigen::Vector3d tool_at(const kin::Chain& c, const kin::JointVector& q) {
  kin::Pose p;
  CHECK(kin::forward(c, q, p) == kin::Status::ok);
  return p.translation();
}

// A table plane 60 mm below the tool at `work` (the park pose must stay above it).
FwConfig table_config(double below_mm) {
  const kin::LoadResult lr = kin::load_robot("puma560");
  CHECK_TEXT(lr.ok, lr.error.c_str());
  const Eigen::Vector3d p = tool_at(lr.chain, joints({0, -45, 180, 0, 45, 0}));
  FwConfig c;
  c.safety_planes = {0, 0, 1, p.z() * 1000.0 - below_mm};
  c.safety_tool_radius_mm = 10;
  c.safety_tcp_speed_mm_s = 300;
  c.safety_reduced_tcp_speed_mm_s = 100;
  return c;
}
}  // namespace

// Every planned move is checked along its path: a movel and a movej through the table plane
// are refused with one line naming the function, where along the path and the limit and
// value, and nothing is queued; the same moves above it are queued. A dry run says the same.
TEST(ArmService, MovesThroughASafetyPlaneAreRefusedNamingWhereAndByHowMuch) {
  const FwConfig c = table_config(60);
  const double plane_mm = c.safety_planes[3];
  test::ConsoleRig r(c);
  r.enable();
  ArmService& svc = r.app.console->service();
  MoveContext cx;
  cx.ik = r.app.console->jog_context().ik;
  MoveJoints mj;
  mj.goal = joints({0, -45, 180, 0, 45, 0});
  const MoveResult to_work = svc.move(mj, cx);
  CHECK_TEXT(to_work.ok(), to_work.reason.c_str());
  for (int i = 0; i < 20000 && r.app.ctl->telemetry().state != ArmState::idle; ++i) r.cycle();
  for (int i = 0; i < 20000 && !r.app.ctl->motions().empty(); ++i) r.cycle();
  const Eigen::Vector3d p = tool_at(r.app.chain, mj.goal);
  // a line 100 mm straight down: through the plane (60 mm down, minus the 10 mm sphere)
  MoveLine down;
  down.target = kin::Pose::Identity();
  kin::forward(r.app.chain, mj.goal, down.target);
  down.target.translation().z() -= 0.1;
  for (int dry_run = 0; dry_run < 2; ++dry_run) {
    PathShadow shadow;
    DryRun dry;
    dry.tail = svc.tail();
    dry.shadow = &shadow;
    MoveContext dcx = cx;
    if (dry_run) dcx.dry = &dry;
    const MoveResult res = svc.move(down, dcx);
    CHECK(res.error == CmdError::limits);
    STRCMP_CONTAINS("safety plane 0 (tool sphere) at s=", res.reason.c_str());
    char limit[48];
    std::snprintf(limit, sizeof limit, "limit %.1f mm", plane_mm);
    STRCMP_CONTAINS(limit, res.reason.c_str());
    CHECK(res.reason.find('\n') == std::string::npos);
    // where: the first sample past the plane, within a sample's travel of it (z = plane + r)
    DOUBLES_EQUAL(plane_mm * 1e-3 + 0.010, res.position.z(), 0.002);
    CHECK(res.s > 0.3 && res.s < 0.9);  // 50 of 100 mm, on a jerk-limited time law
    CHECK(r.app.ctl->motions().empty());
  }
  // 40 mm down stays 10 mm above it: queued
  MoveLine shallow = down;
  shallow.target.translation().z() = p.z() - 0.04;
  const MoveResult ok = svc.move(shallow, cx);
  CHECK_TEXT(ok.ok(), ok.reason.c_str());
  for (int i = 0; i < 20000 && !r.app.ctl->motions().empty(); ++i) r.cycle();
  for (int i = 0; i < 20000 && r.app.ctl->telemetry().state != ArmState::idle; ++i) r.cycle();
  // a joint move that swings the tool down through the table
  MoveJoints swing;
  swing.goal = joints({0, -45, 180, 0, 45, 0});
  swing.goal[1] += 25 * kDeg;
  CHECK(tool_at(r.app.chain, swing.goal).z() < plane_mm * 1e-3);
  const MoveResult sw = svc.move(swing, cx);
  CHECK(sw.error == CmdError::limits);
  STRCMP_CONTAINS("safety plane 0 (tool sphere)", sw.reason.c_str());
  CHECK(r.app.ctl->motions().empty());
}

// Planes and boxes given in a user frame (safety.plane_frames, safety.keep_out_frames): the
// table plane written as [0, 0, -1, -100] in a frame 100 mm above it and turned 180 deg about x
// refuses the line down exactly as the base frame's plane does (same limit, same place); a
// keep-out box turned 45 deg about z beside the tool refuses a line sideways into it naming
// the box; the checksum changes with a frame alone.
TEST(ArmService, ZonesInAUserFrameAreCheckedAtPlanTime) {
  FwConfig c = table_config(60);
  const double plane_mm = c.safety_planes[3];
  const kin::LoadResult lr = kin::load_robot("puma560");
  const Eigen::Vector3d w = tool_at(lr.chain, joints({0, -45, 180, 0, 45, 0})) * 1000.0;
  char toml[512];
  std::snprintf(toml, sizeof toml,
                "[safety]\nplanes = [0, 0, -1, -100]\nplane_frames = [0, 0, %.6f, 180, 0, 0]\n"
                "keep_out = [-50, -10, -10, 50, 10, 10]\nkeep_out_frames = [%.6f, %.6f, %.6f, 0, 0, 45]\n",
                plane_mm + 100.0, w.x(), w.y() + 80.0, w.z());
  const std::string e = load_config_text(toml, "zones.toml", c);
  CHECK_TEXT(e.empty(), e.c_str());
  FwConfig moved = c;
  moved.safety_plane_frames[2] += 1.0;
  CHECK(safety_checksum(c) != safety_checksum(moved));
  test::ConsoleRig r(c);
  r.enable();
  ArmService& svc = r.app.console->service();
  MoveContext cx;
  cx.ik = r.app.console->jog_context().ik;
  MoveJoints mj;
  mj.goal = joints({0, -45, 180, 0, 45, 0});
  CHECK(svc.move(mj, cx).ok());
  for (int i = 0; i < 20000 && !r.app.ctl->motions().empty(); ++i) r.cycle();
  for (int i = 0; i < 20000 && r.app.ctl->telemetry().state != ArmState::idle; ++i) r.cycle();
  MoveLine down;
  kin::forward(r.app.chain, mj.goal, down.target);
  down.target.translation().z() -= 0.1;
  const MoveResult res = svc.move(down, cx);
  CHECK(res.error == CmdError::limits);
  STRCMP_CONTAINS("safety plane 0 (tool sphere) at s=", res.reason.c_str());
  char limit[48];
  std::snprintf(limit, sizeof limit, "limit %.1f mm", plane_mm);
  STRCMP_CONTAINS(limit, res.reason.c_str());
  DOUBLES_EQUAL(plane_mm * 1e-3 + 0.010, res.position.z(), 0.002);
  // sideways +y: the turned box's nearest corner region is about 80 - 10 / cos 45 - 50 sin 45 mm away
  MoveLine side;
  kin::forward(r.app.chain, mj.goal, side.target);
  side.target.translation().y() += 0.1;
  const MoveResult sb = svc.move(side, cx);
  CHECK(sb.error == CmdError::limits);
  STRCMP_CONTAINS("safety keep-out box 0 (tool sphere)", sb.reason.c_str());
  // where it stopped: the sphere (10 mm) touches the turned box, computed here in its frame
  kin::Pose bf = kin::Pose::Identity();
  bf.linear() = Eigen::AngleAxisd(M_PI / 4, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  bf.translation() = Eigen::Vector3d(w.x(), w.y() + 80.0, w.z()) * 1e-3;
  const Eigen::Vector3d local = bf.inverse() * sb.position;
  const Eigen::Vector3d near = local.cwiseMax(Eigen::Vector3d(-0.05, -0.01, -0.01)).cwiseMin(Eigen::Vector3d(0.05, 0.01, 0.01));
  DOUBLES_EQUAL(0.010, (local - near).norm(), 0.002);
  CHECK(r.app.ctl->motions().empty());
  // a frame list that is not 6 numbers per zone is refused at load, naming the key
  FwConfig bad = table_config(60);
  const std::string e2 = load_config_text("[safety]\nplane_frames = [0, 0, 100]\n", "bad.toml", bad);
  STRCMP_CONTAINS("safety.plane_frames", e2.c_str());
  STRCMP_CONTAINS("6 numbers", e2.c_str());
}

// The tool sphere's radius is the active tool's (radius=, else safety.tool_radius_mm): a line
// 40 mm down, 10 mm clear of the table with the 10 mm default, is refused with a 40 mm tool
// selected and queued again with tool0; a tool whose sphere does not fit a keep-in box or puts
// the park pose outside the envelope is refused in one line, here and in the frames file.
TEST(ArmService, TheActiveToolsRadiusIsTheToolSphere) {
  FwConfig c = table_config(60);
  c.safety_keep_in = {-1000, -1000, -1000, 1000, 1000, 1500};
  test::ConsoleRig r(c);
  r.enable();
  ArmService& svc = r.app.console->service();
  MoveContext cx;
  cx.ik = r.app.console->jog_context().ik;
  MoveJoints mj;
  mj.goal = joints({0, -45, 180, 0, 45, 0});
  CHECK(svc.move(mj, cx).ok());
  for (int i = 0; i < 20000 && !r.app.ctl->motions().empty(); ++i) r.cycle();
  for (int i = 0; i < 20000 && r.app.ctl->telemetry().state != ArmState::idle; ++i) r.cycle();
  MoveLine down;
  kin::forward(r.app.chain, mj.goal, down.target);
  down.target.translation().z() -= 0.04;
  PathShadow shadow;
  DryRun dry;
  dry.tail = svc.tail();
  dry.shadow = &shadow;
  MoveContext dcx = cx;
  dcx.dry = &dry;
  const MoveResult ok = svc.move(down, dcx);
  CHECK_TEXT(ok.ok(), ok.reason.c_str());
  NamedPose big;
  big.name = "big";
  big.radius = 0.04;
  CHECK(svc.define_tool(big).ok());
  CHECK(svc.select_tool("big").ok());
  DOUBLES_EQUAL(0.04, svc.tool_radius(svc.tool(svc.active_tool())), 1e-12);
  dcx.chain = &svc.tool_chain(svc.active_tool());
  const MoveResult no = svc.move(down, dcx);
  CHECK(no.error == CmdError::limits);
  STRCMP_CONTAINS("safety plane 0 (tool sphere)", no.reason.c_str());
  // the refusal's value: the 40 mm sphere's lowest point
  DOUBLES_EQUAL(no.position.z() * 1000.0 - 40.0, std::strtod(no.reason.substr(no.reason.find("value ") + 6).c_str(), nullptr), 0.11);
  // too wide for the keep-in box (2000 mm): refused, one line, nothing defined
  NamedPose huge;
  huge.name = "huge";
  huge.radius = 1.2;
  const FrameResult wide = svc.define_tool(huge);
  CHECK(wide.refusal == FrameRefusal::bad_values);
  STRCMP_CONTAINS("is wider than keep-in box 0", wide.reason.c_str());
  CHECK(wide.reason.find('\n') == std::string::npos);
  CHECK(svc.find_tool("huge") == svc.tool_count());
  // a sphere that puts the park pose (all zeros: the tool above the table) below the plane:
  // one 50 mm deeper than the tool's height above the table there reaches through it
  NamedPose deep;
  deep.name = "deep";
  deep.radius = tool_at(r.app.chain, kin::JointVector::Zero(6)).z() - c.safety_planes[3] * 1e-3 + 0.05;
  CHECK(deep.radius < 0.99);
  const FrameResult park = svc.define_tool(deep);
  CHECK(park.refusal == FrameRefusal::bad_values);
  STRCMP_CONTAINS("the park pose lies outside the envelope with it: safety plane 0", park.reason.c_str());
  // the console's words
  const std::string line = r.cmd("tool fat 0 0 0 0 0 0 radius=1200");
  STRCMP_CONTAINS("error", line.c_str());
  STRCMP_CONTAINS("tool fat: its safety sphere (radius 1200.0 mm) is wider than keep-in box 0", line.c_str());
  // the frames file keeps the radius; one that does not fit is refused when the file is loaded
  const std::string dir = test::make_tmp_dir();
  FramesData d;
  d.tools.push_back(big);
  d.active_tool = "big";
  STRCMP_EQUAL("", save_frames_file(dir + "/ok.toml", d).c_str());
  FramesData back;
  STRCMP_EQUAL("", load_frames_file(dir + "/ok.toml", back).c_str());
  DOUBLES_EQUAL(0.04, back.tools.at(0).radius, 1e-12);
  d.tools.push_back(huge);
  STRCMP_EQUAL("", save_frames_file(dir + "/wide.toml", d).c_str());
  const std::string e = svc.load_frames(dir + "/wide.toml");
  STRCMP_CONTAINS("wide.toml: tool huge: its safety sphere (radius 1200.0 mm) is wider than keep-in box 0", e.c_str());
  test::remove_tree(dir);
}

// A trigger plane (safety.reduced_planes): a 200 mm/s line sideways that ends with the tool
// beyond it is planned with the Reduced TCP limit (100 mm/s), the same line short of it at 200;
// the plane refuses nothing.
TEST(ArmService, AMoveIntoATriggerZoneIsPlannedWithTheReducedLimits) {
  FwConfig c = table_config(60);
  c.safety_tcp_speed_mm_s = 300;
  c.safety_reduced_tcp_speed_mm_s = 100;
  const kin::LoadResult lr = kin::load_robot("puma560");
  const Eigen::Vector3d w = tool_at(lr.chain, joints({0, -45, 180, 0, 45, 0})) * 1000.0;
  // Reduced where the sphere (10 mm) reaches beyond y = w.y + 80 mm: n = -y, offset -(w.y + 80)
  c.safety_reduced_planes = {0, -1, 0, -(w.y() + 80.0)};
  test::ConsoleRig r(c);
  r.enable();
  ArmService& svc = r.app.console->service();
  MoveContext cx;
  cx.ik = r.app.console->jog_context().ik;
  MoveJoints mj;
  mj.goal = joints({0, -45, 180, 0, 45, 0});
  CHECK(svc.move(mj, cx).ok());
  for (int i = 0; i < 20000 && !r.app.ctl->motions().empty(); ++i) r.cycle();
  for (int i = 0; i < 20000 && r.app.ctl->telemetry().state != ArmState::idle; ++i) r.cycle();
  PathShadow shadow;
  DryRun dry;
  dry.tail = svc.tail();
  dry.shadow = &shadow;
  MoveContext dcx = cx;
  dcx.dry = &dry;
  MoveLine side;
  kin::forward(r.app.chain, mj.goal, side.target);
  side.speed = 0.2;
  side.target.translation().y() += 0.06;  // the sphere ends 10 mm short of the plane
  const MoveResult shy = svc.move(side, dcx);
  CHECK_TEXT(shy.ok(), shy.reason.c_str());
  DOUBLES_EQUAL(0.2, shy.speed, 1e-12);
  side.target.translation().y() += 0.04;  // 30 mm beyond it
  const MoveResult in = svc.move(side, dcx);
  CHECK_TEXT(in.ok(), in.reason.c_str());
  CHECK_TEXT(in.speed <= 0.1 + 1e-9 && in.speed > 0.09, std::to_string(in.speed).c_str());
  // without the trigger plane the same line runs at 200 mm/s
  FwConfig plain = table_config(60);
  test::ConsoleRig r2(plain);
  r2.enable();
  PathShadow shadow2;
  DryRun dry2;
  dry2.tail = mj.goal;
  dry2.shadow = &shadow2;
  MoveContext dcx2;
  dcx2.ik = r2.app.console->jog_context().ik;
  dcx2.dry = &dry2;
  const MoveResult fast = r2.app.console->service().move(side, dcx2);
  CHECK_TEXT(fast.ok(), fast.reason.c_str());
  DOUBLES_EQUAL(0.2, fast.speed, 1e-12);
}

// A joint jog step that would dip the tool through the plane is refused with the line. The
// TCP speed limit is the mode's and slows moves down rather than refusing them: a 200 mm/s
// line runs at 200 in Normal (300) and at 100 in Reduced (100); a movej whose tool would pass
// 300 mm/s is planned slower (its tool speed, sampled here, stays within 300); the mode and the
// checksum show in the status.
TEST(ArmService, JogStepsAndTheReducedModeAreCheckedToo) {
  const FwConfig c = table_config(60);
  test::ConsoleRig r(c);
  r.enable();
  ArmService& svc = r.app.console->service();
  MoveContext cx;
  cx.ik = r.app.console->jog_context().ik;
  MoveJoints mj;
  mj.goal = joints({0, -45, 180, 0, 45, 0});
  CHECK(svc.move(mj, cx).ok());
  for (int i = 0; i < 20000 && !r.app.ctl->motions().empty(); ++i) r.cycle();
  for (int i = 0; i < 20000 && r.app.ctl->telemetry().state != ArmState::idle; ++i) r.cycle();
  JointJog jj;
  jj.joint = 1;
  jj.increment = 25 * kDeg;
  const JogResult bad = svc.jog(jj, r.app.console->jog_context());
  CHECK(bad.error == CmdError::limits);
  STRCMP_CONTAINS("jog refused: safety plane 0 (tool sphere)", bad.reason.c_str());
  CHECK(r.app.ctl->telemetry().state != ArmState::jogging);

  const ArmStatus normal = svc.status();
  CHECK(normal.safety_on);
  CHECK(normal.safety_mode == kin::SafetyMode::normal);
  CHECK_EQUAL(safety_checksum(c), normal.safety_checksum);

  MoveLine side;
  kin::forward(r.app.chain, mj.goal, side.target);
  side.target.translation().y() += 0.1;
  side.speed = 0.2;
  PathShadow shadow;
  DryRun dry;
  dry.tail = svc.tail();
  dry.shadow = &shadow;
  MoveContext dcx = cx;
  dcx.dry = &dry;
  const MoveResult fast_ok = svc.move(side, dcx);
  CHECK_TEXT(fast_ok.ok(), fast_ok.reason.c_str());
  const ControlResult m = svc.set_safety_mode(kin::SafetyMode::reduced);
  CHECK_TEXT(m.ok(), m.reason.c_str());
  CHECK(svc.status().safety_mode == kin::SafetyMode::reduced);
  CHECK(r.app.ctl->safety_mode() == kin::SafetyMode::reduced);
  dry.tail = svc.tail();
  DOUBLES_EQUAL(0.2, fast_ok.speed, 1e-12);
  const MoveResult slow = svc.move(side, dcx);
  CHECK_TEXT(slow.ok(), slow.reason.c_str());
  DOUBLES_EQUAL(0.1, slow.speed, 1e-12);
  CHECK(slow.duration > fast_ok.duration);
  CHECK(svc.set_safety_mode(kin::SafetyMode::normal, true).ok());  // the looser mode, confirmed
  // a fast movej: slowed until its tool stays within 300 mm/s (checked here every 1 ms)
  MoveJoints quick;
  quick.goal = joints({40, -45, 180, 0, 45, 0});
  quick.speed_pct = 100;
  PathShadow shadow2;
  dry.tail = mj.goal;
  dry.shadow = &shadow2;
  const MoveResult q = svc.move(quick, dcx);
  CHECK_TEXT(q.ok(), q.reason.c_str());
  kin::MovejOptions o;
  kin::JointTrajectory full;
  CHECK(kin::plan_movej(r.app.ctl->limits(), kin::JointState::rest(mj.goal), quick.goal, o, full) == kin::MotionStatus::ok);
  CHECK(q.duration > full.duration);  // slower than at 100 %
  const double k = full.duration / q.duration;  // the override it was planned with
  kin::JointVector pos(6), vel(6), acc(6);
  double vmax = 0;
  Eigen::Vector3d prev = tool_at(r.app.chain, mj.goal);
  for (double t = 0.001 * k; t <= full.duration; t += 0.001 * k) {
    full.sample(t, pos, vel, acc);
    const Eigen::Vector3d p = tool_at(r.app.chain, pos);
    vmax = std::fmax(vmax, (p - prev).norm() / 0.001);
    prev = p;
  }
  CHECK_TEXT(vmax <= 0.3 * 1.001, std::to_string(vmax).c_str());
  CHECK_TEXT(vmax > 0.25, std::to_string(vmax).c_str());  // not slower than it needs
}

// Joint speed limits per mode slow moves down instead of refusing them: a movej of joint 1 at
// 100 % and a 400 mm/s line sideways (mostly joint 1; slowed in Reduced) are planned slower, and run on the
// controller, their commanded joint 1 speed (differenced every cycle here) stays within the
// mode's limit, 30 deg/s in Normal, 10 deg/s in Reduced, with no protective stop.
TEST(ArmService, JointSpeedLimitsOfTheModeSlowMovesDown) {
  FwConfig c = table_config(60);
  c.safety_tcp_speed_mm_s = c.safety_reduced_tcp_speed_mm_s = 0;
  c.safety_joint_speed_deg_s = {30, 0, 0, 0, 0, 0};
  c.safety_reduced_joint_speed_deg_s = {10, 0, 0, 0, 0, 0};
  c.max_linear_speed_mm_s = 500;
  test::ConsoleRig r(c);
  r.enable();
  ArmService& svc = r.app.console->service();
  MoveContext cx;
  cx.ik = r.app.console->jog_context().ik;
  const double dt = 1.0 / c.rate_hz;
  // runs the queue to rest; the highest commanded speed of joint 1 (deg/s)
  auto run = [&] {
    double prev = r.app.ctl->telemetry().q_cmd[0], vmax = 0;
    for (int i = 0; i < 60000 && (!r.app.ctl->motions().empty() || r.app.ctl->telemetry().state != ArmState::idle); ++i) {
      r.cycle();
      const double q = r.app.ctl->telemetry().q_cmd[0];
      vmax = std::fmax(vmax, std::fabs(q - prev) / dt / kDeg);
      prev = q;
    }
    return vmax;
  };
  MoveJoints mj;
  mj.goal = joints({0, -45, 180, 0, 45, 0});
  CHECK(svc.move(mj, cx).ok());
  run();
  for (const kin::SafetyMode mode : {kin::SafetyMode::normal, kin::SafetyMode::reduced}) {
    const double limit = mode == kin::SafetyMode::normal ? 30 : 10;
    CHECK(svc.set_safety_mode(mode).ok());
    MoveJoints quick;
    quick.goal = joints({40, -45, 180, 0, 45, 0});
    quick.speed_pct = 100;
    const MoveResult q = svc.move(quick, cx);
    CHECK_TEXT(q.ok(), q.reason.c_str());
    const double vj = run();
    char fig[120];
    std::snprintf(fig, sizeof fig, "%s movej: joint 1 at most %.2f deg/s (limit %.0f)", kin::to_string(mode), vj, limit);
    std::printf("\n  %s", fig);
    CHECK_TEXT(vj <= limit * 1.002, fig);
    CHECK_TEXT(vj > limit * 0.8, fig);  // not slower than it needs
    MoveLine side;
    kin::forward(r.app.chain, quick.goal, side.target);
    side.target.translation().y() -= 0.1;
    side.speed = 0.4;
    const MoveResult l = svc.move(side, cx);
    CHECK_TEXT(l.ok(), l.reason.c_str());
    if (mode == kin::SafetyMode::reduced) CHECK_TEXT(l.speed < 0.4, std::to_string(l.speed).c_str());
    const double vl = run();
    std::snprintf(fig, sizeof fig, "%s movel: %.1f mm/s, joint 1 at most %.2f deg/s (limit %.0f)", kin::to_string(mode),
                  l.speed * 1e3, vl, limit);
    std::printf("\n  %s", fig);
    CHECK_TEXT(vl <= limit * 1.002, fig);
    MoveJoints back = mj;
    CHECK(svc.move(back, cx).ok());
    run();
  }
  CHECK_EQUAL(0u, r.app.ctl->telemetry().safety_stops);
}

// Stopping distance and time limits per mode slow moves down: a movej of joint 1 at 100 % is
// planned slower so that, run on the controller, the stop predicted every cycle from its
// commanded state (computed here with plan_stop on the controller's limits and FK) stays within
// the mode's limits: 30 mm / 0.3 s in Normal, 10 mm / 0.2 s in Reduced; no protective stop.
TEST(ArmService, StoppingDistanceAndTimeLimitsOfTheModeSlowMovesDown) {
  FwConfig c = table_config(60);
  c.safety_tcp_speed_mm_s = c.safety_reduced_tcp_speed_mm_s = 0;
  c.safety_stop_distance_mm = 30;
  c.safety_stop_time_s = 0.3;
  c.safety_reduced_stop_distance_mm = 10;
  c.safety_reduced_stop_time_s = 0.2;
  test::ConsoleRig r(c);
  r.enable();
  ArmService& svc = r.app.console->service();
  MoveContext cx;
  cx.ik = r.app.console->jog_context().ik;
  const double dt = 1.0 / c.rate_hz;
  // runs the queue to rest; the longest predicted stop (s) and its farthest TCP travel (mm)
  auto run = [&](double& t_max, double& d_max) {
    t_max = d_max = 0;
    kin::JointState st;
    st.pos = st.vel = st.acc = kin::JointVector::Zero(6);
    kin::JointTrajectory stop;
    for (int i = 0; i < 60000 && (!r.app.ctl->motions().empty() || r.app.ctl->telemetry().state != ArmState::idle); ++i) {
      r.cycle();
      const Telemetry t = r.app.ctl->telemetry();
      for (int j = 0; j < 6; ++j) {
        const auto ju = static_cast<std::size_t>(j);
        st.acc[j] = (t.qd_cmd[ju] - st.vel[j]) / dt;
        st.pos[j] = t.q_cmd[ju];
        st.vel[j] = t.qd_cmd[ju];
      }
      CHECK(kin::plan_stop(r.app.ctl->limits(), st, kin::MovejOptions{}, stop) == kin::MotionStatus::ok);
      t_max = std::fmax(t_max, stop.duration);
      d_max = std::fmax(d_max, (tool_at(r.app.chain, stop.goal) - tool_at(r.app.chain, st.pos)).norm() * 1e3);
    }
  };
  MoveJoints mj;
  mj.goal = joints({0, -45, 180, 0, 45, 0});
  CHECK(svc.move(mj, cx).ok());
  double t_max = 0, d_max = 0;
  run(t_max, d_max);
  for (const kin::SafetyMode mode : {kin::SafetyMode::normal, kin::SafetyMode::reduced}) {
    const bool normal = mode == kin::SafetyMode::normal;
    const double d_lim = normal ? 30 : 10, t_lim = normal ? 0.3 : 0.2;
    CHECK(svc.set_safety_mode(mode).ok());
    MoveJoints quick;
    quick.goal = joints({60, -45, 180, 0, 45, 0});
    quick.speed_pct = 100;
    const MoveResult q = svc.move(quick, cx);
    CHECK_TEXT(q.ok(), q.reason.c_str());
    run(t_max, d_max);
    char fig[160];
    std::snprintf(fig, sizeof fig, "%s movej in %.3f s: predicted stop at most %.3f s (limit %.1f), %.2f mm (limit %.0f)",
                  kin::to_string(mode), q.duration, t_max, t_lim, d_max, d_lim);
    std::printf("\n  %s", fig);
    CHECK_TEXT(d_max <= d_lim * 1.02, fig);  // (the acceleration here is differenced: 2 %)
    CHECK_TEXT(t_max <= t_lim * 1.02, fig);
    CHECK_TEXT(d_max > d_lim * 0.5 || t_max > t_lim * 0.5, fig);  // slowed, not stopped
    MoveJoints back = mj;
    CHECK(svc.move(back, cx).ok());
    run(t_max, d_max);
  }
  CHECK_EQUAL(0u, r.app.ctl->telemetry().safety_stops);
}

// Momentum and power limits per mode slow moves down: a movej of joint 1 at 100 % is planned
// slower so that, run on the controller, the arm's momentum (each link's mass x the speed of its
// centre of mass, differenced every cycle here from FK of the commanded joints) and mechanical
// power (sum |tau qd|, tau by inverse dynamics) stay within the mode's limits: 6 kg m/s / 2 W
// in Normal (the power binds: the planner slows the move to the fastest scale that keeps it, not
// below), 2 kg m/s / 40 W in Reduced (the momentum binds: no slower than needed); no protective stop.
TEST(ArmService, MomentumAndPowerLimitsOfTheModeSlowMovesDown) {
  FwConfig c = table_config(60);
  c.safety_tcp_speed_mm_s = c.safety_reduced_tcp_speed_mm_s = 0;
  c.safety_momentum_kg_m_s = 6;
  c.safety_power_w = 2;  // (joint 1 turns about the vertical: little power, this one binds)
  c.safety_reduced_momentum_kg_m_s = 2;
  c.safety_reduced_power_w = 40;
  test::ConsoleRig r(c);
  CHECK(r.app.chain.has_inertial);
  r.enable();
  ArmService& svc = r.app.console->service();
  MoveContext cx;
  cx.ik = r.app.console->jog_context().ik;
  const double dt = 1.0 / c.rate_hz;
  const kin::Chain& ch = r.app.chain;
  auto coms = [&](const kin::JointVector& q, std::array<Eigen::Vector3d, kin::kMaxRows>& out) {
    kin::FrameSet f;
    kin::Pose p;
    CHECK(kin::forward_frames(ch, q, f, p) == kin::Status::ok);
    for (int i = 0; i < ch.n_rows; ++i) {
      const auto& in = ch.inertial[static_cast<std::size_t>(i)];
      out[static_cast<std::size_t>(i)] = f.frame[i + 1] * Eigen::Vector3d(in.com[0], in.com[1], in.com[2]);
    }
  };
  // runs the queue to rest; the highest momentum (kg m/s) and power (W)
  auto run = [&](double& p_max, double& w_max) {
    p_max = w_max = 0;
    kin::JointVector q(6), qd(6), qd_prev = kin::JointVector::Zero(6), qdd(6), tau(6);
    std::array<Eigen::Vector3d, kin::kMaxRows> c0{}, c1{};
    for (int j = 0; j < 6; ++j) q[j] = r.app.ctl->telemetry().q_cmd[static_cast<std::size_t>(j)];
    coms(q, c0);
    for (int i = 0; i < 60000 && (!r.app.ctl->motions().empty() || r.app.ctl->telemetry().state != ArmState::idle); ++i) {
      r.cycle();
      const Telemetry t = r.app.ctl->telemetry();
      for (int j = 0; j < 6; ++j) {
        const auto ju = static_cast<std::size_t>(j);
        q[j] = t.q_cmd[ju];
        qd[j] = t.qd_cmd[ju];
        qdd[j] = (qd[j] - qd_prev[j]) / dt;
      }
      qd_prev = qd;
      coms(q, c1);
      double p = 0;
      for (int k = 0; k < ch.n_rows; ++k)
        p += ch.inertial[static_cast<std::size_t>(k)].mass * (c1[std::size_t(k)] - c0[std::size_t(k)]).norm() / dt;
      c0 = c1;
      CHECK(kin::inverse_dynamics(ch, q, qd, qdd, tau) == kin::Status::ok);
      double w = 0;
      for (int j = 0; j < 6; ++j) w += std::fabs(tau[j] * qd[j]);
      p_max = std::fmax(p_max, p);
      w_max = std::fmax(w_max, w);
    }
  };
  MoveJoints mj;
  mj.goal = joints({0, -45, 180, 0, 45, 0});
  CHECK(svc.move(mj, cx).ok());
  double p_max = 0, w_max = 0;
  run(p_max, w_max);
  for (const kin::SafetyMode mode : {kin::SafetyMode::normal, kin::SafetyMode::reduced}) {
    const bool normal = mode == kin::SafetyMode::normal;
    const double p_lim = normal ? 6 : 2, w_lim = normal ? 2 : 40;
    CHECK(svc.set_safety_mode(mode).ok());
    MoveJoints quick;
    quick.goal = joints({60, -45, 180, 0, 45, 0});
    quick.speed_pct = 100;
    const MoveResult q = svc.move(quick, cx);
    CHECK_TEXT(q.ok(), q.reason.c_str());
    run(p_max, w_max);
    char fig[160];
    std::snprintf(fig, sizeof fig, "%s movej in %.3f s: momentum at most %.3f kg m/s (limit %.0f), power %.1f W (limit %.0f)",
                  kin::to_string(mode), q.duration, p_max, p_lim, w_max, w_lim);
    std::printf("\n  %s", fig);
    CHECK_TEXT(p_max <= p_lim * 1.02, fig);  // (differenced here: 2 %)
    CHECK_TEXT(w_max <= w_lim * 1.02, fig);
    // slowed: longer than at 100 %; by the momentum (proportional to speed) not more than needed
    kin::JointTrajectory full;
    CHECK(kin::plan_movej(r.app.ctl->limits(), kin::JointState::rest(mj.goal), quick.goal, kin::MovejOptions{}, full) ==
          kin::MotionStatus::ok);
    CHECK_TEXT(q.duration > full.duration * 1.5, fig);
    if (!normal) CHECK_TEXT(p_max > p_lim * 0.9, fig);
    MoveJoints back = mj;
    CHECK(svc.move(back, cx).ok());
    run(p_max, w_max);
  }
  CHECK_EQUAL(0u, r.app.ctl->telemetry().safety_stops);
}

// Without [safety], switching the mode is refused with one line and nothing changes.
TEST(ArmService, TheSafetyModeNeedsAnEnvelope) {
  test::ConsoleRig r;
  ArmService& svc = r.app.console->service();
  const ControlResult m = svc.set_safety_mode(kin::SafetyMode::reduced);
  CHECK(m.error == CmdError::bad_state);
  STRCMP_CONTAINS("no safety envelope", m.reason.c_str());
  CHECK(svc.status().safety_mode == kin::SafetyMode::normal);
  CHECK(!svc.status().safety_on);
}

// The hook for streamed targets: check_target(q_prev, q, dt) says "" for a target inside and
// the violation's line for one through the plane or one that steps faster than the TCP limit.
TEST(ArmService, AStreamedTargetIsCheckedByTheHook) {
  const FwConfig c = table_config(60);
  test::ConsoleRig r(c);
  ArmService& svc = r.app.console->service();
  const kin::JointVector work = joints({0, -45, 180, 0, 45, 0});
  kin::JointVector down = work;
  down[1] += 25 * kDeg;
  kin::JointVector near = work;
  near[0] += 0.01 * kDeg;
  STRCMP_EQUAL("", svc.check_target(work, near, 0.001).c_str());
  STRCMP_CONTAINS("safety plane 0 (tool sphere)", svc.check_target(work, down, 0).c_str());
  // 0.5 deg of the base joint in 1 ms: the tool moves at several m/s
  kin::JointVector jump = work;
  jump[0] += 0.5 * kDeg;
  STRCMP_CONTAINS("safety tcp speed", svc.check_target(work, jump, 0.001).c_str());
  STRCMP_EQUAL("", svc.check_target(work, jump, 0.5).c_str());
}
