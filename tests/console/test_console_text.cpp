// SPDX-License-Identifier: Apache-2.0
// Answers are never cut inside a word: every message the parser, the console and the
// control thread's texts (replies, events, fault texts) produce, rendered with the
// longest names and values, is either whole or ends with "..." after a whole word.
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "console_rig.hpp"
#include "servoarm/hal/safety_input.hpp"
#include "servoarm/kinematics/orientation.hpp"
#include "servoarm/lang/command_table.hpp"
#include "servoarm/lang/commands.hpp"
#include "servoarm/lang/text.hpp"
#include "servoarm/rt/model_control.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;

namespace {

bool ends_with(const std::string& s, const std::string& e) {
  return s.size() >= e.size() && s.compare(s.size() - e.size(), e.size(), e) == 0;
}

/// `shown` is `full` whole, or a prefix of it cut after a whole word followed by "...".
bool whole_or_ellipsis(const std::string& shown, const std::string& full) {
  if (shown == full) return true;
  if (!ends_with(shown, "...")) return false;
  const std::string head = shown.substr(0, shown.size() - 3);
  if (head.empty() || full.compare(0, head.size(), head) != 0 || head.size() >= full.size()) return false;
  const char next = full[head.size()];
  const char last = head.back();
  const auto word = [](char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.'; };
  return !(word(last) && word(next));  // the cut is between words, never inside one
}

/// The lines of `text` that start with `prefix`, the prefix taken off.
std::vector<std::string> lines_after(const std::string& text, const std::string& prefix) {
  std::vector<std::string> out;
  std::size_t a = 0;
  while (a < text.size()) {
    std::size_t b = text.find('\n', a);
    if (b == std::string::npos) b = text.size();
    const std::string l = text.substr(a, b - a);
    if (l.rfind(prefix, 0) == 0) out.push_back(l.substr(prefix.size()));
    a = b + 1;
  }
  return out;
}

/// The longest text the control thread formats for a homing fault (hal's homing messages,
/// the largest joint and node numbers, the longest phase name) and other long event texts.
std::vector<std::string> longest_rt_texts() {
  return {
      "joint 16 (node 127): homing timeout after 9223372036854775807 ms searching the home switch towards the "
      "negative limit switch (statusword 0x0237)",
      "joint 16 (node 127): homing error while moving off the home switch towards the index pulse of the motor "
      "encoder (statusword 0x2637)",
      "joint 16: the drive has no cyclic synchronous torque mode (CST with 6071h, 6060h/6061h in the PDOs; "
      "dynamics.freedrive = true maps it where the drive has it): free-drive needs it",
  };
}

}  // namespace

TEST_GROUP(ConsoleText){};

// `freedrive on` on drives without a torque mode: the refusal names the drive's missing
// mode and the configuration key in full (the model's own refusal text).
TEST(ConsoleText, FreedriveRefusalIsWhole) {
  test::ConsoleRig rig;
  rig.enable();
  const ModelControl* m = rig.app.ctl->model();
  if (m == nullptr || !m->configured() || m->available(ModelPart::freedrive))
    FAIL("the puma560 sim is expected to refuse free-drive (no CST on its drives)");
  const std::string refusal = m->refusal(ModelPart::freedrive);
  const std::string a = rig.cmd("freedrive on");
  std::printf("\nfreedrive on -> %s", a.c_str());
  const auto err = lines_after(a, "error: ");
  CHECK_EQUAL_TEXT(1u, err.size(), a.c_str());
  CHECK_TEXT(err[0].find(refusal) != std::string::npos, a.c_str());
}

// Events from the control thread whose text fills its fixed buffer: every console line
// (native and GRBL) is whole, or ends with "..." after a whole word.
TEST(ConsoleText, LongestEventTextsAreWholeOrEndWithAnEllipsis) {
  test::ConsoleRig rig;
  for (const std::string& full : longest_rt_texts())
    for (const EventKind k : {EventKind::fault, EventKind::motion_refused, EventKind::jog_stopped, EventKind::homing,
                              EventKind::freedrive}) {
      Event e;
      e.kind = k;
      e.cause = FaultCause::homing_failed;
      std::snprintf(e.message, sizeof e.message, "%s", full.c_str());  // what the control thread sends
      CHECK(rig.app.ctl->events().push(e));
      std::string native, grbl;
      rig.app.console->drain_events(native, grbl);
      const char* prefix = k == EventKind::fault ? "alarm: fault " : k == EventKind::homing ? "homing: "
                           : k == EventKind::freedrive                                   ? "freedrive: "
                                                                                         : "alarm: ";
      const auto n = lines_after(native, prefix);
      CHECK_EQUAL_TEXT(1u, n.size(), native.c_str());
      if (!whole_or_ellipsis(n[0], full)) FAIL(("cut inside a word: " + native).c_str());
      std::string gp = k == EventKind::fault ? "[MSG:fault " : k == EventKind::homing ? "[MSG:homing: "
                       : k == EventKind::freedrive                                   ? "[MSG:freedrive: "
                                                                                     : "[MSG:";
      const auto g = lines_after(grbl, gp);
      CHECK_EQUAL_TEXT(1u, g.size(), grbl.c_str());
      const std::string gt = ends_with(g[0], "]") ? g[0].substr(0, g[0].size() - 1) : g[0];
      if (!whole_or_ellipsis(gt, full)) FAIL(("cut inside a word: " + grbl).c_str());
    }
}

// An e-stop from the simulated e-stop input while a movej runs: the alarm names its cause in
// both dialects; an e-stop by command has no cause beyond itself and keeps the plain line.
TEST(ConsoleText, EstopAlarmNamesItsCause) {
  FwConfig cfg;
  cfg.safety_estop_input = "sim:estop";
  test::ConsoleRig rig(cfg);
  hal::SimInput* in = rig.app.sim_input("estop");
  CHECK(in != nullptr);
  in->set(hal::InputLevel::high);  // active low: released
  for (int i = 0; i < 100; ++i) rig.cycle();  // the debounce (10 ms)
  rig.enable();
  CHECK(test::answer_ok(rig.cmd("movej 30 0 0 0 0 0")));
  for (int i = 0; i < 100; ++i) rig.cycle();
  std::string native, grbl;
  rig.app.console->drain_events(native, grbl);
  in->set(hal::InputLevel::low);
  for (int i = 0; i < 3000 && rig.app.ctl->telemetry().state != ArmState::estop; ++i) rig.cycle();
  CHECK(rig.app.ctl->telemetry().state == ArmState::estop);
  native.clear(), grbl.clear();
  rig.app.console->drain_events(native, grbl);
  std::printf("\ne-stop input -> %sGRBL: %s", native.c_str(), grbl.c_str());
  CHECK_TEXT(native.find("alarm: estop: e-stop input sim:estop asserted (send reset, then enable)\n") !=
                 std::string::npos,
             native.c_str());
  CHECK_TEXT(grbl.find("ALARM:10\n[MSG:e-stop: e-stop input sim:estop asserted ($X to reset and enable)]\n") !=
                 std::string::npos,
             grbl.c_str());
  // released, reset, enabled again; then `estop` by command
  in->set(hal::InputLevel::high);
  for (int i = 0; i < 200; ++i) rig.cycle();
  CHECK_TEXT(test::answer_ok(rig.cmd("reset")), rig.s.out.c_str());
  rig.enable();
  rig.app.console->drain_events(native, grbl);
  native.clear(), grbl.clear();
  rig.cmd("estop");
  for (int i = 0; i < 3000 && rig.app.ctl->telemetry().state != ArmState::estop; ++i) rig.cycle();
  rig.app.console->drain_events(native, grbl);
  std::printf("estop command -> %sGRBL: %s", native.c_str(), grbl.c_str());
  CHECK_TEXT(native.find("alarm: estop (send reset, then enable)\n") != std::string::npos, native.c_str());
  CHECK_TEXT(grbl.find("ALARM:10\n[MSG:e-stop: $X to reset and enable]\n") != std::string::npos, grbl.c_str());
}

// Every command of the table and the G-code words with the longest arguments a line may
// carry: every refusal is whole (shorter than its buffer) or ends with "..." after a word.
TEST(ConsoleText, EveryParserRefusalWithLongArgumentsIsWholeOrEndsWithAnEllipsis) {
  const std::string w(63, 'w');  // the longest point / program name the parser keeps is 63
  const std::string num = "-123456789012345678901234567890.1234567";  // 40 characters
  std::vector<std::string> lines;
  for (const CommandSpec& e : kCommands) {
    const std::string n = e.name;
    for (const std::string& a : {w, num, w + " " + w, num + " " + w, "j" + num, num + " speed=" + num,
                                 "j3 " + num + " speed=" + w, w + " " + num + " " + num + " " + num + " " + num,
                                 "@" + w, w + "=" + num, "rate=" + w})
      lines.push_back(n + " " + a);
  }
  for (const char* g : {"G0", "G1", "G4", "G10 L2 P1", "$J=G91", "M62", "M63", "G28", "G53 G0", "G54", "F", "T"})
    for (const std::string& a : {" X" + num, " X" + w, " " + w, " P" + num + " Q" + w, " Y" + num + " Z" + num + " A" + num})
      lines.push_back(g + a);
  int refused = 0, long_ones = 0;
  for (const std::string& line : lines) {
    GcodeModal m;
    Command c;
    const ParseResult r = parse_line(line, 6, m, c);
    if (r.ok()) continue;
    ++refused;
    const std::string msg = r.message.data();
    if (msg.size() + 1 >= r.message.size()) {  // it filled the buffer: cut
      ++long_ones;
      if (!ends_with(msg, "...") || msg[msg.size() - 4] == ' ')
        FAIL(("cut inside a word: '" + line + "' -> " + msg).c_str());
    }
  }
  std::printf("\n%d of %zu lines refused, %d of them at the message's cap\n", refused, lines.size(), long_ones);
  CHECK(refused > 100);
}

// The two cuts themselves: a buffer snprintf filled (a fault text, a reply) and a refusal
// written into a buffer too small for it: whole words, then "...".
TEST(ConsoleText, CutsFallBetweenWords) {
  for (const std::string& full : longest_rt_texts())
    for (std::size_t cap : {std::size_t(20), std::size_t(64), std::size_t(120), std::size_t(121), std::size_t(160)}) {
      std::vector<char> buf(cap);
      std::snprintf(buf.data(), cap, "%s", full.c_str());
      const std::string shown = bounded_text(buf.data(), cap);
      if (!whole_or_ellipsis(shown, full)) FAIL(("bounded_text cut inside a word: " + shown).c_str());
      std::vector<char> b2(cap);
      const int n = std::snprintf(b2.data(), cap, "%s", full.c_str());
      if (n >= static_cast<int>(cap)) ellipsize(b2.data(), cap);
      const std::string e = b2.data();
      CHECK(e.size() < cap);
      if (!whole_or_ellipsis(e, full)) FAIL(("ellipsize cut inside a word: " + e).c_str());
    }
  char fits[16] = "short and whole";  // 15 characters + NUL: full, so marked
  CHECK_EQUAL(std::string("short and..."), bounded_text(fits));
  char room[32] = "short and whole";
  CHECK_EQUAL(std::string("short and whole"), bounded_text(room));
}

namespace {
/// A signed zero as an answer prints it: '-' then only zeros (and a '.'), e.g. "-0.000",
/// "-0.0", "-0" — a number that rounded to zero but kept its sign.
std::string negative_zero_in(const std::string& text) {
  for (std::size_t i = 0; i < text.size(); ++i) {
    if (text[i] != '-' || i + 1 >= text.size() || text[i + 1] != '0') continue;
    if (i > 0 && (std::isalnum(static_cast<unsigned char>(text[i - 1])) || text[i - 1] == '_')) continue;
    std::size_t k = i + 1;
    while (k < text.size() && (text[k] == '0' || text[k] == '.')) ++k;
    if (k == text.size() || !std::isdigit(static_cast<unsigned char>(text[k]))) {
      const std::size_t a = text.rfind('\n', i), b = text.find('\n', i);
      return text.substr(a == std::string::npos ? 0 : a + 1, b == std::string::npos ? std::string::npos : b - a - 1);
    }
  }
  return "";
}
}  // namespace

// Values that round to zero print as 0.000 in every answer, never -0.000: joints at
// -0.0000001 and -0.0, a tool and a user frame whose values are -0.0000001 (so the pose in
// the frame is a tiny negative), in status, fk, wait's `ok idle`, M114, the reports, points,
// tool, frame, $# and limits, in both dialects.
TEST(ConsoleText, NoNegativeZeroInAnyAnswer) {
  test::ConsoleRig rig;
  rig.enable();
  std::string all, answers;  // the transcript (lines typed too), the answers alone
  const auto run = [&](const std::string& line) {
    const std::string a = rig.cmd(line);
    all += "> " + line + "\n" + a;
    answers += a;
    return a;
  };
  const std::string z = "-0.0000001";
  CHECK_TEXT(test::answer_ok(run("movej " + z + " -0.0 -0 " + z + " 30 " + z)), all.c_str());
  run("wait");
  run("status");
  run("fk");
  run("fk " + z + " -0.0 " + z + " -0 " + z + " " + z);
  run("M114");
  run("teach zero");
  run("points");
  run("tool tz " + z + " -0.0 " + z + " -0 " + z + " " + z);
  run("tool");
  run("fk");
  run("frame fz " + z + " -0.0 " + z + " -0 " + z + " " + z);
  run("frame");
  run("status");
  run("M114");
  run("G10 L2 P1 X" + z + " Y-0.0 Z" + z);
  run("$#");
  run("limits");
  answers += rig.app.console->grbl_report() + "\n" + rig.app.console->status_text() + "\n";
  rig.s.dialect = Dialect::grbl;
  answers += rig.app.console->grbl_report(rig.s) + "\n";
  run("M114");
  all += answers;
  const std::string bad = negative_zero_in(answers);
  if (!bad.empty()) {
    std::printf("\n%s", all.c_str());
    FAIL(("a signed zero in: " + bad).c_str());
  }
}

namespace {
/// The value of `key` ("rx=") in an answer, NAN when absent.
double value_after(const std::string& text, const std::string& key) {
  const auto at = text.find(" " + key);
  if (at == std::string::npos) return NAN;
  return std::strtod(text.c_str() + at + 1 + key.size(), nullptr);
}
}  // namespace

// At a gimbal lock (ry = 90: rx and rz not unique) `status` (from the measured joints)
// prints the same rx ry rz as `wait`'s answer `ok idle x=...` (from the move's goal) and
// M114 the same A B C: one conversion for every answer. The tool is chosen so that a short
// movel ends exactly at ry = 90; the virtual drives' encoders put the measured joints a
// fraction of a count off the goal.
TEST(ConsoleText, GimbalLockPrintsOneOrientationInStatusWaitAndM114) {
  test::ConsoleRig rig;
  rig.enable();
  CHECK(test::answer_ok(rig.cmd("movej 20 -40 160 10 -50 30")));
  CHECK(test::answer_ok(rig.cmd("wait")));
  kin::JointVector q0(6);
  q0 << 20, -40, 160, 10, -50, 30;
  q0 *= M_PI / 180.0;
  const kin::Pose f = rig.app.console->pose_in_frame(q0);  // the flange (tool0), base frame
  const Eigen::Matrix3d want = kin::rotation_from_rpy(0, M_PI / 2, 0);
  const Eigen::Vector3d t = kin::rpy_from_rotation(f.linear().transpose() * want) * 180.0 / M_PI;
  char line[200];
  std::snprintf(line, sizeof line, "tool lock 0 0 0 %.6f %.6f %.6f", t[0], t[1], t[2]);
  CHECK_TEXT(test::answer_ok(rig.cmd(line)), line);
  CHECK(test::answer_ok(rig.cmd("tool lock")));
  std::snprintf(line, sizeof line, "movel %.3f %.3f %.3f 0 90 0 speed=10", f.translation().x() * 1e3,
                f.translation().y() * 1e3, f.translation().z() * 1e3);
  const std::string moved = rig.cmd(line);
  CHECK_TEXT(test::answer_ok(moved), (std::string(line) + " -> " + moved).c_str());
  const std::string idle = rig.cmd("wait");
  for (int i = 0; i < 500; ++i) rig.cycle();  // the drives settle on the goal
  const std::string status = rig.cmd("status");
  const std::string m114 = rig.cmd("M114");
  const std::string all = idle + status + m114;
  std::printf("\n%s", all.c_str());
  DOUBLES_EQUAL_TEXT(90.0, value_after(idle, "ry="), 1e-3, all.c_str());
  for (const char* k : {"rx=", "ry=", "rz="})
    DOUBLES_EQUAL_TEXT(value_after(idle, k), value_after(status, k), 0.01, (std::string(k) + "\n" + all).c_str());
  const auto a = m114.find("A:"), b = m114.find("B:"), c = m114.find("C:");
  CHECK_TEXT(a != std::string::npos && b != std::string::npos && c != std::string::npos, m114.c_str());
  DOUBLES_EQUAL_TEXT(value_after(idle, "rx="), std::strtod(m114.c_str() + a + 2, nullptr), 0.01, all.c_str());
  DOUBLES_EQUAL_TEXT(value_after(idle, "ry="), std::strtod(m114.c_str() + b + 2, nullptr), 0.01, all.c_str());
  DOUBLES_EQUAL_TEXT(value_after(idle, "rz="), std::strtod(m114.c_str() + c + 2, nullptr), 0.01, all.c_str());
}
