// SPDX-License-Identifier: Apache-2.0
// A run-time change of the [safety] section (ArmService::stage_safety / confirm_safety, App's
// stager through the key table) on the puma560 with virtual drives: staged, nothing changes (a
// query changes nothing); applied only by its checksum, within its window, with the arm at rest;
// the monitor takes it at its next cycle without allocating; refusals in one line.
#include <chrono>
#include <cstdio>
#include <string>
#include <thread>

#include "controller_rig.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;
using Rig = servoarm::test::ControllerRig;

TEST_GROUP(SafetyChange){};

namespace {
FwConfig envelope() {
  FwConfig c;
  c.safety_planes = {0, 0, 1, -500};
  c.safety_tcp_speed_mm_s = 250;
  return c;
}
std::string hex(std::uint32_t v) {
  char b[9];
  std::snprintf(b, sizeof b, "%08X", static_cast<unsigned>(v));
  return b;
}
}  // namespace

// Staged: checked, nothing changes (status, the monitor, a query); confirmed with its checksum:
// the service and the monitor use it, status shows the new checksum; the next change starts
// from it.
TEST(SafetyChange, StagedThenConfirmedByItsChecksum) {
  Rig r(envelope());
  const std::uint32_t before = r.svc().status().safety_checksum;
  const SafetyChangeResult s = r.svc().stage_safety("tcp_speed_mm_s = 100; safety.planes = [0, 0, 1, -400]");
  CHECK_TEXT(s.ok(), s.reason.c_str());
  CHECK(s.checksum != before);
  CHECK_EQUAL(before, s.previous);
  STRCMP_CONTAINS("safety.tcp_speed_mm_s = 250 -> 100", s.changes.c_str());
  STRCMP_CONTAINS("safety.planes", s.changes.c_str());
  // nothing changed: status (a query), the service's envelope, the monitor
  CHECK_EQUAL(before, r.svc().status().safety_checksum);
  (void)r.svc().settings();
  r.cycles(5);
  CHECK_EQUAL(before, r.svc().status().safety_checksum);
  DOUBLES_EQUAL(0.25, r.svc().settings().safety.normal.tcp_speed, 1e-12);
  DOUBLES_EQUAL(0.25, r.app.ctl->safety_monitor().config().normal.tcp_speed, 1e-12);
  const SafetyChangeResult c = r.svc().confirm_safety(s.checksum);
  CHECK_TEXT(c.ok(), c.reason.c_str());
  r.count_allocs = true;  // the control thread takes the new envelope (and the tool) without allocating
  r.cycles(2);
  r.count_allocs = false;
  LONGS_EQUAL(0, r.rt_allocs);
  CHECK_EQUAL(s.checksum, r.svc().status().safety_checksum);
  DOUBLES_EQUAL(0.1, r.svc().settings().safety.normal.tcp_speed, 1e-12);
  DOUBLES_EQUAL(0.1, r.app.ctl->safety_monitor().config().normal.tcp_speed, 1e-12);
  STRCMP_CONTAINS(("safety configuration changed: checksum " + hex(before) + " -> " + hex(s.checksum)).c_str(),
                  r.events().c_str());
  // the App's configuration followed: its checksum is the one in force
  CHECK_EQUAL(s.checksum, safety_checksum(r.app.cfg, r.app.chain));
  // a second confirmation of the same checksum: nothing is staged any more
  const SafetyChangeResult again = r.svc().confirm_safety(s.checksum);
  CHECK(!again.ok());
  STRCMP_EQUAL("no safety change is staged: stage one first", again.reason.c_str());
}

// Refusals, one line each, nothing changed: an unknown key, a key set at start only, a bad value
// (the key table's line), no change, a wrong checksum (the staged change is dropped), an expired
// one, and while the arm moves (the change stays staged).
TEST(SafetyChange, RefusedInOneLine) {
  Rig r(envelope());
  const std::uint32_t before = r.svc().status().safety_checksum;
  struct Bad {
    const char* changes;
    const char* says;
  } const bad[] = {
      {"tcp_sped_mm_s = 100", "safety.tcp_sped_mm_s: no such key in [safety]"},
      {"estop_input = \"sim:x\"", "safety.estop_input is set at start only"},
      {"stop = \"drive\"", "safety.stop is set at start only"},
      {"tcp_speed_mm_s = -5", "safety.tcp_speed_mm_s"},
      {"planes = [0, 0, 0, 1]", "safety.planes"},
      {"tcp_speed_mm_s", "a change is `key = value`"},
      {"tcp_speed_mm_s = 1; tcp_speed_mm_s = 2", "given twice"},
      {"tcp_speed_mm_s = 250", "leaves the safety configuration as it is"},
      {" ; ", "no change given"},
  };
  for (const Bad& b : bad) {
    const SafetyChangeResult s = r.svc().stage_safety(b.changes);
    CHECK_TEXT(!s.ok(), b.changes);
    STRCMP_CONTAINS_TEXT(b.says, s.reason.c_str(), b.changes);
    CHECK_TEXT(s.reason.find('\n') == std::string::npos, b.changes);
  }
  SafetyChangeResult s = r.svc().stage_safety("tcp_speed_mm_s = 120");
  CHECK(s.ok());
  SafetyChangeResult c = r.svc().confirm_safety(s.checksum ^ 1u);
  CHECK(!c.ok());
  STRCMP_CONTAINS(("is not the staged change's (" + hex(s.checksum) + ")").c_str(), c.reason.c_str());
  c = r.svc().confirm_safety(s.checksum);  // dropped by the wrong one
  CHECK(!c.ok());
  STRCMP_CONTAINS("no safety change is staged", c.reason.c_str());
  r.svc().set_safety_confirm_window(0.02);
  s = r.svc().stage_safety("tcp_speed_mm_s = 120");
  CHECK(s.ok());
  std::this_thread::sleep_for(std::chrono::milliseconds(60));
  c = r.svc().confirm_safety(s.checksum);
  CHECK(!c.ok());
  STRCMP_CONTAINS(("the staged change " + hex(s.checksum) + " expired").c_str(), c.reason.c_str());
  r.svc().set_safety_confirm_window(60);
  r.enable();
  r.start_move();
  s = r.svc().stage_safety("tcp_speed_mm_s = 120");
  CHECK(s.ok());
  c = r.svc().confirm_safety(s.checksum);
  CHECK(!c.ok());
  STRCMP_CONTAINS("the arm is not at rest", c.reason.c_str());
  CHECK_EQUAL(before, r.svc().status().safety_checksum);
  for (int i = 0; i < 30000 && r.tel().state != ArmState::idle; ++i) r.cycle();
  c = r.svc().confirm_safety(s.checksum);  // still staged
  CHECK_TEXT(c.ok(), c.reason.c_str());
  CHECK_EQUAL(s.checksum, r.svc().status().safety_checksum);
}
