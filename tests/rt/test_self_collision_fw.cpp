// SPDX-License-Identifier: Apache-2.0
// Self-collision through the firmware (docs/safety.md#self-collision), on a PUMA 560 whose
// description carries capsules (base column, upper arm, forearm) with virtual drives:
//  - plan time: a joint move that bends the wrist until the tool's capsule comes within the
//    margin of the forearm's is refused naming the pair, the limit and the value, nothing
//    queued; a move that stays clear is accepted;
//  - run time: the same bend queued directly (the planner never saw it) gets a protective stop
//    in the cycle its commanded pair passes the margin less the tolerance, with an event naming
//    the pair; no allocation on the control thread;
//  - load: safety.self_collision with a description without capsules, and a park pose closer
//    than the margin, are refused in one line; the checksum covers the capsules.
#include <cmath>
#include <cstdio>
#include <string>

#include "../program/tmp_dir.hpp"
#include "controller_rig.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/service/arm_service.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;

namespace {

constexpr double kMarginMm = 10.0;  // safety.self_collision_margin_mm
constexpr double kTolMm = 2.0;      // safety.tolerance_mm
constexpr double kToolMm = 30.0;    // safety.tool_radius_mm: the tool capsule's radius

// The puma560's rows (kinematics/models/puma560.toml, without its inertial data) with capsules:
// a base column below the shoulder, the upper arm from the shoulder offset to the elbow
// (frame 2: -a2 .. 0 along x), the forearm from the elbow towards the wrist, stopping 53 mm
// short of the wrist centre (frame 3: along z).
std::string puma_with_capsules(double forearm_radius_mm = 40) {
  char forearm[160];
  std::snprintf(forearm, sizeof forearm, "capsule = { from = [0, 0, 0], to = [0, 0, 380], radius = %g }\n",
                forearm_radius_mm);
  return std::string("name = \"puma560_capsules\"\nconvention = \"standard\"\nlength_unit = \"mm\"\nangle_unit = \"deg\"\n"
                     "base_capsule = { from = [0, 0, -600], to = [0, 0, -150], radius = 90 }\n"
                     "[[joint]]\ntype = \"revolute\"\nalpha = -90\nlimits = [-160, 160]\n"
                     "[[joint]]\ntype = \"revolute\"\na = 431.8\nd = 149.09\nlimits = [-225, 45]\n"
                     "capsule = { from = [-431.8, 0, 0], to = [0, 0, 0], radius = 60 }\n"
                     "[[joint]]\ntype = \"revolute\"\na = -20.32\nalpha = 90\nlimits = [-45, 225]\n") +
         forearm +
         "[[joint]]\ntype = \"revolute\"\nd = 433.07\nalpha = -90\nlimits = [-110, 170]\n"
         "[[joint]]\ntype = \"revolute\"\nalpha = 90\nlimits = [-100, 100]\n"
         "[[joint]]\ntype = \"revolute\"\nd = 56.25\nlimits = [-266, 266]\n";
}

kin::JointVector pose(double q5_deg) { return test::deg({0, -45, 180, 0, q5_deg, 0}); }

// The distance between the forearm's and the tool's capsules at q (mm), from the core.
double forearm_tool_mm(const kin::Chain& chain, const kin::JointVector& q) {
  kin::SafetyConfig c;
  c.enabled = c.self_collision = true;
  c.tool_radius = kToolMm * 1e-3;
  kin::SafetySample x;
  (void)kin::safety_sample(chain, c, q, -1.0, x);
  return x.self_distance * 1e3;
}

struct Robot {
  std::string dir = test::make_tmp_dir();
  std::string path = dir + "/puma560_capsules.toml";
  explicit Robot(const std::string& text = puma_with_capsules()) { test::write_file(path, text); }
  ~Robot() { test::remove_tree(dir); }
};

FwConfig self_collision_config(const std::string& robot) {
  FwConfig c;
  c.can = "sim";
  c.robot = robot;
  c.safety_self_collision = true;
  c.safety_self_collision_margin_mm = kMarginMm;
  c.safety_tool_radius_mm = kToolMm;
  c.safety_tolerance_mm = kTolMm;
  return c;
}

using Rig = test::ControllerRig;

}  // namespace

TEST_GROUP(SelfCollision){};

// The geometry the tests below stand on: clear at the work pose, within the margin at q5 = 95.
TEST(SelfCollision, TheRigsGeometry) {
  Robot robot;
  const kin::LoadResult lr = kin::load_robot(robot.path);
  CHECK_TEXT(lr.ok, lr.error.c_str());
  CHECK_EQUAL(5, kin::capsule_pair_count(lr.chain));  // base/link 2, base/link 3, base/tool, link 2/tool, link 3/tool
  CHECK(forearm_tool_mm(lr.chain, pose(45)) > kMarginMm + 15);
  CHECK(forearm_tool_mm(lr.chain, pose(60)) > kMarginMm + 10);
  CHECK(forearm_tool_mm(lr.chain, pose(95)) < kMarginMm - kTolMm);
}

// A joint move bending the wrist back towards the forearm (q5 45 -> 95 deg) is refused at plan
// time naming the pair; one that stays clear (45 -> 60 deg) is accepted.
TEST(SelfCollision, AFoldingMoveIsRefusedAtPlanTimeNamingThePair) {
  Robot robot;
  Rig r(self_collision_config(robot.path));
  r.enable();
  const MoveResult to_work = r.movej(pose(45));
  CHECK_TEXT(to_work.ok(), to_work.reason.c_str());
  r.until_idle(30000);
  const MoveResult bad = r.movej(pose(95));
  CHECK(!bad.ok());
  std::printf("\n  refused: %s\n", bad.reason.c_str());
  STRCMP_CONTAINS("safety self_collision link 3 and tool at s=", bad.reason.c_str());
  STRCMP_CONTAINS("limit 10.0 mm, value ", bad.reason.c_str());
  STRCMP_CONTAINS("nothing queued", bad.reason.c_str());
  CHECK(bad.s > 0 && bad.s < 1);
  CHECK(r.app.ctl->motions().empty());
  const MoveResult good = r.movej(pose(60));
  CHECK_TEXT(good.ok(), good.reason.c_str());
  r.until_idle(30000);
  CHECK((r.q_cmd() - pose(60)).norm() < 1e-6);
}

// The same bend queued directly (never planned): a protective stop starts in the cycle the
// commanded forearm/tool pair comes closer than margin - tolerance; the arm ramps to rest and
// holds; the event names the pair; nothing allocated on the control thread.
TEST(SelfCollision, AnUncheckedFoldingMoveGetsAProtectiveStop) {
  Robot robot;
  Rig r(self_collision_config(robot.path));
  const kin::Chain chain = r.app.chain;
  r.enable();
  const MoveResult to_work = r.movej(pose(45));
  CHECK_TEXT(to_work.ok(), to_work.reason.c_str());
  r.until_idle(30000);
  r.count_allocs = true;
  r.queue_unchecked_joint_move(901, pose(100), 0.5);
  int crossed = -1, stopped = -1;
  double closest = INFINITY;
  for (int i = 0; i < 20000; ++i) {
    r.cycle();
    const double d = forearm_tool_mm(chain, r.q_cmd());
    closest = std::fmin(closest, d);
    if (crossed < 0 && d < kMarginMm - kTolMm) crossed = i;
    if (stopped < 0 && r.tel().state == ArmState::stopping) stopped = i;
    if (stopped >= 0 && r.tel().state == ArmState::idle) break;
  }
  std::printf("\n  self-collision stop: commanded pair past margin - tolerance in cycle %d, stop ramp from cycle %d; "
              "closest commanded %.2f mm (margin %.0f mm)\n",
              crossed, stopped, closest, kMarginMm);
  CHECK(crossed >= 0);
  CHECK_EQUAL(crossed, stopped);
  CHECK(r.tel().state == ArmState::idle);
  CHECK(r.app.ctl->motions().empty());
  CHECK(closest > 0);  // braked before the capsules touched
  const std::string ev = r.last_event();
  STRCMP_CONTAINS("protective stop (commanded): self_collision link 3 and tool", ev.c_str());
  STRCMP_CONTAINS("limit 10.0 mm", ev.c_str());
  CHECK_EQUAL(1u, r.tel().safety_stops);
  LONGS_EQUAL(0, r.rt_allocs);
}

// Refused at load in one line: the switch on a robot without capsules; a park pose closer than
// the margin (a 45 mm margin at the zeros, where the forearm and the tool are 39 mm apart).
TEST(SelfCollision, BadConfigurationsAreRefusedAtLoad) {
  {
    test::SimApp app;
    hal::ManualClock clock;
    const std::string e = app.build(self_collision_config("puma560"), &clock);
    STRCMP_CONTAINS("safety.self_collision: puma560's description has no capsules", e.c_str());
    CHECK(e.find('\n') == std::string::npos);
  }
  {
    Robot robot;
    FwConfig c = self_collision_config(robot.path);
    c.safety_self_collision_margin_mm = 45;
    test::SimApp app;
    hal::ManualClock clock;
    const std::string e = app.build(c, &clock);
    STRCMP_CONTAINS("the park pose (motion.home_deg) lies outside the envelope: safety self_collision link 3 and tool",
                    e.c_str());
    CHECK(e.find('\n') == std::string::npos);
  }
  {
    FwConfig c;
    const std::string e = load_config_text("[safety]\nself_collision_margin_mm = -1\n", "bad.toml", c);
    STRCMP_CONTAINS("self_collision_margin_mm", e.c_str());
  }
}

// The checksum `status` shows covers the description's capsules: another forearm radius,
// another checksum; a robot without capsules keeps the [safety] section's checksum. `safety`
// shows the margin and the number of pairs checked.
TEST(SelfCollision, TheChecksumCoversTheCapsules) {
  Robot a, b(puma_with_capsules(41));
  const kin::LoadResult la = kin::load_robot(a.path), lb = kin::load_robot(b.path), plain = kin::load_robot("puma560");
  CHECK(la.ok && lb.ok && plain.ok);
  const FwConfig c = self_collision_config(a.path);
  CHECK(safety_checksum(c, la.chain) != safety_checksum(c, lb.chain));
  CHECK(safety_checksum(c, la.chain) != safety_checksum(c));
  CHECK_EQUAL(safety_checksum(c), safety_checksum(c, plain.chain));
  STRCMP_CONTAINS("capsule link 3 = from [0.000000, 0.000000, 0.000000] to [0.000000, 0.000000, 380.000000] radius 40",
                  safety_description_canonical(la.chain).c_str());
  Rig r(c);
  CHECK_EQUAL(safety_checksum(c, la.chain), r.svc().status().safety_checksum);
  char sum[16];
  std::snprintf(sum, sizeof sum, "%08X", static_cast<unsigned>(safety_checksum(c, la.chain)));
  const std::string shown = r.console("safety");
  STRCMP_CONTAINS((std::string("safety=on mode=normal checksum=") + sum).c_str(), shown.c_str());
  STRCMP_CONTAINS("self_collision_margin_mm=10 capsule_pairs=5", shown.c_str());
}
