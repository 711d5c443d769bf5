// SPDX-License-Identifier: Apache-2.0
// The arm service's typed interface on the puma560 with virtual drives (console_rig.hpp):
// a refused move says what and by how much in SI (no text), a dry run plans the same knots
// as the real run and queues nothing, arm control answers typed results. Expected values
// come from the joint limits and the request, never from the service's code.
#include <cmath>

#include "../console/console_rig.hpp"
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
