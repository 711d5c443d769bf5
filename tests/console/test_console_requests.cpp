// SPDX-License-Identifier: Apache-2.0
// The canonical requests (requests.hpp): movel and G0/G1 build one MoveLine, movej,
// park and G28 one MoveJoints, and one function validates and queues each. The same
// move typed either way queues the same motion (same knots, same duration).
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>

#include "console_rig.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;
using test::answer_ok;

namespace {

/// Queue `line`, copy the motion it queued, then `stop` (drops it; the queue's end is the
/// commanded position again, so the next line starts from the same place).
std::unique_ptr<MotionItem> queued_by(test::ConsoleRig& r, const std::string& line) {
  const std::string a = r.cmd(line);
  if (!answer_ok(a)) FAIL((line + ": " + a).c_str());
  MotionItem* m = r.app.ctl->motions().front();
  if (m == nullptr) FAIL((line + ": nothing queued").c_str());
  auto copy = std::make_unique<MotionItem>(*m);
  const std::string st = r.cmd("stop");
  if (!answer_ok(st)) FAIL(("stop: " + st).c_str());
  for (int i = 0; i < 3000 && r.app.ctl->telemetry().state != ArmState::idle; ++i) r.cycle();
  CHECK(r.app.ctl->motions().empty());
  return copy;
}

void check_same_line(const MotionItem& ma, const MotionItem& mb, const std::string& what) {
  CHECK_TEXT(ma.kind() == MotionKind::cartesian && mb.kind() == MotionKind::cartesian, what.c_str());
  const auto& a = *std::get_if<CartesianMove>(&ma.payload);
  const auto& b = *std::get_if<CartesianMove>(&mb.payload);
  CHECK_TEXT(a.path.duration == b.path.duration, (what + ": durations " + std::to_string(a.path.duration) + " vs " +
                                              std::to_string(b.path.duration)).c_str());
  CHECK_TEXT(a.path.n == b.path.n && a.path.n == 6, what.c_str());
  double worst = 0;
  for (int k = 0; k <= kin::kMovelKnots; ++k)
    for (int j = 0; j < a.path.n; ++j) {
      const auto ku = static_cast<std::size_t>(k), ju = static_cast<std::size_t>(j);
      worst = std::fmax(worst, std::fabs(a.path.q_knot[ku][ju] - b.path.q_knot[ku][ju]));
      worst = std::fmax(worst, std::fabs(a.path.dq_knot[ku][ju] - b.path.dq_knot[ku][ju]));
    }
  CHECK_TEXT(worst == 0, (what + ": knots differ by " + std::to_string(worst)).c_str());
  CHECK_TEXT((ma.goal() - mb.goal()).cwiseAbs().maxCoeff() == 0, what.c_str());
  CHECK_TEXT(a.path.p1 == b.path.p1, what.c_str());
}

}  // namespace

TEST_GROUP(ConsoleRequests){};

TEST(ConsoleRequests, MovelAndTheEquivalentG1QueueTheSameMotion) {
  test::ConsoleRig r;
  r.enable();
  CHECK(answer_ok(r.cmd("movej 20 -40 160 10 -50 30")));
  CHECK(answer_ok(r.cmd("wait")));
  // Position only (orientation kept), then position and orientation; mm/s vs mm/min.
  const auto a1 = queued_by(r, "movel 500 100 300 speed=50");
  const auto b1 = queued_by(r, "G1 X500 Y100 Z300 F3000");
  check_same_line(*a1, *b1, "movel x y z / G1 X Y Z");
  const auto a2 = queued_by(r, "movel 500 100 300 170 10 80 speed=120");
  const auto b2 = queued_by(r, "G1 X500 Y100 Z300 A170 B10 C80 F7200");
  check_same_line(*a2, *b2, "movel x y z rx ry rz / G1 X Y Z A B C");
  // G20: inches; G0 = the maximum linear speed = movel at that speed.
  const double vmax = r.app.console->config().max_linear_speed * 1e3;
  char l3[160];  // the millimetres G20 makes of the inches, printed exactly
  std::snprintf(l3, sizeof l3, "movel %.17g %.17g %.17g speed=%.17g", 20 * 25.4, 4 * 25.4, 12 * 25.4, vmax);
  const auto a3 = queued_by(r, l3);
  CHECK(answer_ok(r.cmd("G20")));
  const auto b3 = queued_by(r, "G0 X20 Y4 Z12");
  CHECK(answer_ok(r.cmd("G21")));
  check_same_line(*a3, *b3, "movel / G20 G0");
}

TEST(ConsoleRequests, FrontEndsBuildOneCanonicalRequest) {
  test::ConsoleRig r;
  r.enable();
  CHECK(answer_ok(r.cmd("movej 20 -40 160 10 -50 30")));
  CHECK(answer_ok(r.cmd("wait")));
  GcodeModal m;
  Command mv, g1, g0;
  CHECK(parse_line("movel 500 100 300 speed=50", 6, m, mv).ok());
  CHECK(parse_line("G1 X500 Y100 Z300 F3000", 6, m, g1).ok());
  CHECK(parse_line("G0 X500 Y100 Z300", 6, m, g0).ok());
  const MoveLine l1 = r.app.console->line_request(mv), l2 = r.app.console->line_request(g1),
                 l3 = r.app.console->line_request(g0);
  CHECK(l1.target.matrix() == l2.target.matrix() && l2.target.matrix() == l3.target.matrix());
  DOUBLES_EQUAL(0.05, l1.speed, 1e-15);
  DOUBLES_EQUAL(0.05, l2.speed, 1e-15);
  CHECK(!l1.rapid && !l2.rapid && l3.rapid);
  CHECK(!l1.clamp_speed && l2.clamp_speed);  // movel refuses above the maximum, G-code F is clamped
  // movej, park and G28: one MoveJoints.
  Command mj, home, g28;
  CHECK(parse_line("movej 0 10 20 0 30 0 speed=20", 6, m, mj).ok());
  CHECK(parse_line("park", 6, m, home).ok());
  CHECK(parse_line("G28", 6, m, g28).ok());
  const MoveJoints j1 = r.app.console->joint_request(mj);
  DOUBLES_EQUAL(20, j1.speed_pct, 0);
  DOUBLES_EQUAL(10 * M_PI / 180, j1.goal[1], 1e-15);
  const MoveJoints h1 = r.app.console->joint_request(home), h2 = r.app.console->joint_request(g28);
  CHECK(h1.goal == h2.goal && h1.speed_pct == h2.speed_pct);
  CHECK(h1.goal == r.app.console->config().home);
  // Same answers for the same refusal, whichever front end: speed above the maximum (movel) is refused,
  // the G-code F is clamped; an unreachable target is refused by both with the same code.
  const std::string too_fast = r.cmd("movel 500 100 300 speed=99999");
  CHECK_TEXT(too_fast.rfind("error: out_of_range linear speed", 0) == 0, too_fast.c_str());
  const std::string far1 = r.cmd("movel 5000 0 0"), far2 = r.cmd("G1 X5000 Y0 Z0");
  CHECK_TEXT(far1.rfind("error: ", 0) == 0 && far1.find(" movel refused: ") != std::string::npos, far1.c_str());
  STRCMP_EQUAL(far1.c_str(), far2.c_str());
  CHECK(r.app.ctl->motions().empty());
}

// A joint move is planned once: by the console, from the queue's end. Back-to-back joint
// and Cartesian moves each start exactly where the previous one ended, so the RT thread
// runs every console plan as it is (no second plan), and the setpoints it writes are the
// console plan's samples. A joint item committed without a plan (or whose start is not
// where the arm is) is planned again at start, and counted.
TEST(ConsoleRequests, AJointMoveIsPlannedOnceByTheConsole) {
  test::ConsoleRig r;
  r.enable();
  const std::uint64_t replans0 = r.app.ctl->telemetry().joint_replans;
  const std::string a = r.cmd("movej 20 -40 160 10 -50 30");
  CHECK_TEXT(answer_ok(a), a.c_str());
  const MotionItem first = *r.app.ctl->motions().front();
  CHECK(first.kind() == MotionKind::joint);
  const kin::JointTrajectory plan = std::get_if<JointMove>(&first.payload)->plan;
  CHECK(plan.n == 6 && plan.duration > 0.5);
  for (const char* l : {"movej 0 -30 150 0 -40 0 speed=50", "movel 400 100 300", "movej 10 -20 140 5 -30 10"}) {
    const std::string b = r.cmd(l);
    CHECK_TEXT(answer_ok(b), (std::string(l) + ": " + b).c_str());
  }
  // The first move's setpoints are its console plan's samples, bit for bit.
  double worst = 0;
  int n = 0;
  for (int k = 1; k < 100000 && r.app.ctl->telemetry().running_id == 0; ++k) r.cycle();  // started
  double t = 0;
  while (r.app.ctl->telemetry().running_id == first.id) {
    t += 1e-3;
    const Telemetry tel = r.app.ctl->telemetry();
    kin::JointState s;
    plan.sample(t, s);
    for (int j = 0; j < 6; ++j) worst = std::fmax(worst, std::fabs(s.pos[j] - tel.q_cmd[static_cast<std::size_t>(j)]));
    ++n;
    r.cycle();
  }
  CHECK(n > 500);
  CHECK_TEXT(worst == 0, std::to_string(worst).c_str());
  const std::string w = r.cmd("wait");
  CHECK_TEXT(answer_ok(w), w.c_str());
  LONGS_EQUAL(0, r.app.ctl->telemetry().joint_replans - replans0);
  // An item with no plan is planned at start, and that is counted.
  MotionItem* m = r.app.ctl->motions().back();
  JointMove& jm = m->payload.emplace<JointMove>();
  m->id = 9000;
  jm.goal = first.goal();
  r.app.ctl->motions().commit();
  for (int i = 0; i < 20000 && r.app.ctl->telemetry().done_id != 9000; ++i) r.cycle();
  LONGS_EQUAL(9000, r.app.ctl->telemetry().done_id);
  LONGS_EQUAL(1, r.app.ctl->telemetry().joint_replans - replans0);
}

// The park pose is the service's setting, read there: a park pose set through the service
// (set_settings) is the one the console's configuration shows and `park` goes to: the
// console keeps no copy of it.
TEST(ConsoleRequests, TheParkPoseFollowsTheServicesSettings) {
  test::ConsoleRig r;
  ArmService& svc = r.app.console->service();
  MotionSettings s = svc.settings();
  s.home = kin::JointVector::Zero(6);
  s.home[1] = -0.25;
  s.home[4] = 0.5;
  CHECK(svc.set_settings(s).ok());
  CHECK(r.app.console->config().home == s.home);
  Command park;
  GcodeModal m;
  CHECK(parse_line("park", 6, m, park).ok());
  CHECK(r.app.console->joint_request(park).goal == s.home);
}

// The safety envelope on the console: `safety` shows on/off, the mode, the checksum of the
// configuration's [safety] section (fw::safety_checksum, computed here from the same
// configuration), the stops and the mode's limits; `safety reduced` / `safety normal` switch the mode, which
// `status` shows with the checksum; without [safety] the switch is refused with one line.
TEST(ConsoleRequests, SafetyShowsModeAndChecksumAndSwitchesTheMode) {
  FwConfig c;
  c.safety_planes = {0, 0, 1, -500};
  c.safety_tcp_speed_mm_s = 1000;
  c.safety_reduced_tcp_speed_mm_s = 100;
  c.safety_joint_speed_deg_s = {90, 90, 90, 180, 180, 180};
  c.safety_reduced_joint_speed_deg_s = {30, 30, 30, 60, 60, 60};
  c.safety_stop_time_s = 0.5;
  c.safety_reduced_stop_distance_mm = 40;
  c.safety_reduced_momentum_kg_m_s = 4;
  c.safety_power_w = 80;
  test::ConsoleRig r(c);
  char sum[16];
  std::snprintf(sum, sizeof sum, "%08X", static_cast<unsigned>(safety_checksum(c)));
  const std::string a = r.cmd("safety");
  CHECK_TEXT(answer_ok(a), a.c_str());
  STRCMP_CONTAINS((std::string("safety=on mode=normal checksum=") + sum + " stops=0").c_str(), a.c_str());
  // the mode's limits, in the keys' units
  STRCMP_CONTAINS("tcp_speed_mm_s=1000 joint_speed_deg_s=[90,90,90,180,180,180] stop_time_s=0.5 power_w=80", a.c_str());
  CHECK(a.find("stop_distance_mm") == std::string::npos);  // (Reduced mode's only)
  const std::string red = r.cmd("safety reduced");
  CHECK_TEXT(answer_ok(red), red.c_str());
  STRCMP_CONTAINS("safety mode reduced", red.c_str());
  STRCMP_CONTAINS((std::string("safety=reduced checksum=") + sum).c_str(), r.cmd("status").c_str());
  STRCMP_CONTAINS("mode=reduced", r.cmd("safety").c_str());
  STRCMP_CONTAINS("tcp_speed_mm_s=100 joint_speed_deg_s=[30,30,30,60,60,60] stop_distance_mm=40 momentum_kg_m_s=4", r.cmd("safety").c_str());
  CHECK(r.app.ctl->safety_mode() == kin::SafetyMode::reduced);
  CHECK_TEXT(answer_ok(r.cmd("safety normal confirm")), "safety normal confirm");
  CHECK(r.app.ctl->safety_mode() == kin::SafetyMode::normal);

  test::ConsoleRig plain;
  STRCMP_CONTAINS("safety=off", plain.cmd("safety").c_str());
  const std::string refused = plain.cmd("safety reduced");
  STRCMP_CONTAINS("error: bad_state no safety envelope is configured", refused.c_str());
  CHECK(plain.cmd("status").find("safety=") == std::string::npos);
}

// Switching the safety mode: to Reduced (stricter) at once; Reduced -> Normal loosens the limits
// and needs `confirm`: refused in one line without it, the mode kept; Normal -> Normal changes
// nothing and needs none.
TEST(ConsoleRequests, LooseningTheSafetyModeNeedsTheConfirmation) {
  FwConfig c;
  c.safety_planes = {0, 0, 1, -500};
  c.safety_tcp_speed_mm_s = 1000;
  c.safety_reduced_tcp_speed_mm_s = 100;
  test::ConsoleRig r(c);
  CHECK_TEXT(answer_ok(r.cmd("safety normal")), "normal -> normal");
  const std::string red = r.cmd("safety reduced");
  CHECK_TEXT(answer_ok(red), red.c_str());
  const std::string refused = r.cmd("safety normal");
  STRCMP_EQUAL("error: bad_state Reduced -> Normal loosens the safety limits: confirm it (console `safety normal "
               "confirm`, API safety_mode with confirm=true); still Reduced\n",
               refused.c_str());
  CHECK(r.app.ctl->safety_mode() == kin::SafetyMode::reduced);
  STRCMP_CONTAINS("mode=reduced", r.cmd("safety").c_str());
  const std::string ok = r.cmd("safety normal confirm");
  CHECK_TEXT(answer_ok(ok), ok.c_str());
  STRCMP_CONTAINS("safety mode normal", ok.c_str());
  CHECK(r.app.ctl->safety_mode() == kin::SafetyMode::normal);
  STRCMP_CONTAINS("error: arg_count", r.cmd("safety reduced confirm").c_str());  // a stricter mode needs none
  STRCMP_CONTAINS("error: bad_option", r.cmd("safety normal yes").c_str());
}

// `safety stage` / `safety confirm` on the console: the service's stage_safety / confirm_safety
// (the API's safety_stage / safety_confirm): staged, nothing changes; a wrong checksum drops it;
// confirmed with its checksum, `status` and `safety` show the new checksum. A change longer than
// the parser's word table (an array of six values and more) is taken whole.
TEST(ConsoleRequests, SafetyStageAndConfirmChangeTheEnvelopeAtRunTime) {
  FwConfig c;
  c.safety_planes = {0, 0, 1, -500};
  c.safety_tcp_speed_mm_s = 250;
  test::ConsoleRig r(c);
  char before[16];
  std::snprintf(before, sizeof before, "%08X", static_cast<unsigned>(safety_checksum(c)));
  const std::string staged =
      r.cmd("safety stage tcp_speed_mm_s = 120; joint_speed_deg_s = [90, 90, 90, 180, 180, 180]; reduced_joint_speed_deg_s = [30, 30, 30, 60, 60, 60]; planes = [0, 0, 1, -400]");
  CHECK_TEXT(answer_ok(staged), staged.c_str());
  STRCMP_CONTAINS("safety.tcp_speed_mm_s = 250 -> 120", staged.c_str());
  STRCMP_CONTAINS((std::string("previous=") + before).c_str(), staged.c_str());
  const std::size_t at = staged.find("checksum=");
  CHECK_TEXT(at != std::string::npos, staged.c_str());
  const std::string sum = staged.substr(at + 9, 8);
  STRCMP_CONTAINS(("safety confirm " + sum).c_str(), staged.c_str());  // says how to confirm it
  STRCMP_CONTAINS((std::string("checksum=") + before).c_str(), r.cmd("status").c_str());  // nothing changed yet
  DOUBLES_EQUAL(0.25, r.app.ctl->safety_monitor().config().normal.tcp_speed, 1e-12);
  // a wrong checksum: refused, the change dropped
  const std::string wrong = r.cmd("safety confirm 0BADF00D");
  STRCMP_CONTAINS("error: bad_option checksum 0BADF00D is not the staged change's", wrong.c_str());
  STRCMP_CONTAINS("error: bad_state no safety change is staged", r.cmd("safety confirm " + sum).c_str());
  STRCMP_CONTAINS("error: bad_number", r.cmd("safety confirm 12345XYZ").c_str());
  STRCMP_CONTAINS("error: arg_count", r.cmd("safety confirm").c_str());
  STRCMP_CONTAINS("error: arg_count", r.cmd("safety stage").c_str());
  STRCMP_CONTAINS("error: bad_option safety.tcp_sped_mm_s: no such key", r.cmd("safety stage tcp_sped_mm_s = 1").c_str());
  // staged again and confirmed
  const std::string again = r.cmd("safety stage tcp_speed_mm_s = 120; joint_speed_deg_s = [90, 90, 90, 180, 180, 180]; reduced_joint_speed_deg_s = [30, 30, 30, 60, 60, 60]; planes = [0, 0, 1, -400]");
  CHECK_TEXT(answer_ok(again), again.c_str());
  const std::string ok = r.cmd("safety confirm " + sum);
  CHECK_TEXT(answer_ok(ok), ok.c_str());
  STRCMP_CONTAINS(("safety configuration " + sum + " in force (was " + before + ")").c_str(), ok.c_str());
  for (int i = 0; i < 3; ++i) r.cycle();
  DOUBLES_EQUAL(0.12, r.app.ctl->safety_monitor().config().normal.tcp_speed, 1e-12);
  STRCMP_CONTAINS(("checksum=" + sum).c_str(), r.cmd("status").c_str());
  STRCMP_CONTAINS(("checksum=" + sum).c_str(), r.cmd("safety").c_str());
  // in check mode ($C) neither runs
  CHECK(answer_ok(r.cmd("$C")));
  STRCMP_CONTAINS("check mode: not run", r.cmd("safety stage tcp_speed_mm_s = 100").c_str());
}
