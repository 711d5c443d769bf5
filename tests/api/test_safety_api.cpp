// SPDX-License-Identifier: Apache-2.0
// The API's safety_stage / safety_confirm messages (firmware/api/src/protocol.cpp): gated to the
// operator holding control, parsed and run through the message table on the service (the server's
// gate itself is fw_api's TokensAndRoles), answers and refusals rendered in one line.
#include <cstdio>
#include <string>

#include "../support/sim_app.hpp"
#include "servoarm/api/protocol.hpp"
#include "text_regex.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;

namespace {
std::string ask(api::ServiceContext& cx, const std::string& text) {
  api::ApiRequest rq;
  const api::ParseError pe = api::parse_request(text, rq);
  if (!pe.code.empty()) return "parse: " + pe.code + " " + pe.message;
  return api::execute(cx, rq);
}
std::string field(const std::string& line, const char* name) {
  const test::Groups m = test::regex_search(line, std::string("\"") + name + "\":\"([^\"]*)\"");
  return m.empty() ? "" : m[1];
}
}  // namespace

TEST_GROUP(SafetyApi){};

// Both messages need the operator holding control; neither is a query.
TEST(SafetyApi, GatedToTheOperatorInControl) {
  for (const char* name : {"safety_stage", "safety_confirm"}) {
    const api::MessageSpec* m = api::find_message(name);
    CHECK_TEXT(m != nullptr, name);
    CHECK_TEXT(m->gate == api::Gate::control, name);
    CHECK_TEXT(m->where == api::Where::service, name);
  }
  ServiceOp op;
  CHECK(service_op_from("safety_stage", op));
  CHECK(!kServiceOps[static_cast<std::size_t>(op)].query);
  CHECK(service_op_from("safety_confirm", op));
  CHECK(!kServiceOps[static_cast<std::size_t>(op)].query);
}

// Stage answers the new checksum, the one in force and what changes; a confirmation with another
// checksum, or one that is not 8 hex digits, is refused in one line; with the staged one it applies.
TEST(SafetyApi, StageAndConfirmRoundTrip) {
  test::SimApp app;
  hal::ManualClock clock;
  FwConfig c;
  c.can = "sim";
  c.safety_planes = {0, 0, 1, -500};
  c.safety_tcp_speed_mm_s = 250;
  std::string e = app.build(c, &clock);
  CHECK_TEXT(e.empty(), e.c_str());
  clock.set_idle_hook([&](hal::TimePoint t) { app.plant->step(t); });
  e = app.boot();
  CHECK_TEXT(e.empty(), e.c_str());
  app.console->set_idle([&] {
    app.ctl->cycle(clock.now());
    clock.advance(hal::kMillisecond);
  });
  api::ServiceContext cx;
  cx.svc = &app.console->service();
  cx.ctl = app.ctl.get();
  cx.chain = &app.chain;
  const std::string staged = ask(cx, R"({"id":1,"cmd":"safety_stage","changes":"tcp_speed_mm_s = 120"})");
  STRCMP_CONTAINS("\"ok\":true", staged.c_str());
  STRCMP_CONTAINS("safety.tcp_speed_mm_s = 250 -> 120", staged.c_str());
  STRCMP_CONTAINS("\"expires_s\":60", staged.c_str());
  const std::string sum = field(staged, "checksum");
  LONGS_EQUAL(8, sum.size());
  char before[9];
  std::snprintf(before, sizeof before, "%08X", static_cast<unsigned>(cx.svc->status().safety_checksum));
  STRCMP_EQUAL(before, field(staged, "previous").c_str());
  std::string bad = ask(cx, R"({"id":2,"cmd":"safety_confirm","checksum":"XYZ12345"})");
  STRCMP_CONTAINS("\"error\":\"bad_number\"", bad.c_str());
  STRCMP_CONTAINS("is not 8 hex digits", bad.c_str());
  bad = ask(cx, R"({"id":3,"cmd":"safety_confirm","checksum":"1234"})");
  STRCMP_CONTAINS("parse:", bad.c_str());  // the table's length check
  const std::string ok = ask(cx, "{\"id\":4,\"cmd\":\"safety_confirm\",\"checksum\":\"" + sum + "\"}");
  STRCMP_CONTAINS("\"ok\":true", ok.c_str());
  char now[9];
  std::snprintf(now, sizeof now, "%08X", static_cast<unsigned>(cx.svc->status().safety_checksum));
  STRCMP_EQUAL(sum.c_str(), now);
  bad = ask(cx, "{\"id\":5,\"cmd\":\"safety_confirm\",\"checksum\":\"" + sum + "\"}");
  STRCMP_CONTAINS("no safety change is staged", bad.c_str());
  clock.set_idle_hook(nullptr);
}

// safety_mode: to Reduced at once; Reduced -> Normal loosens the limits and needs confirm=true,
// refused in the service's one line without it (the console's `safety normal` gives the same).
TEST(SafetyApi, LooseningTheSafetyModeNeedsTheConfirmation) {
  const api::MessageSpec* m = api::find_message("safety_mode");
  CHECK(m != nullptr);
  CHECK(m->gate == api::Gate::control);
  test::SimApp app;
  hal::ManualClock clock;
  FwConfig c;
  c.can = "sim";
  c.safety_planes = {0, 0, 1, -500};
  c.safety_tcp_speed_mm_s = 250;
  c.safety_reduced_tcp_speed_mm_s = 100;
  std::string e = app.build(c, &clock);
  CHECK_TEXT(e.empty(), e.c_str());
  clock.set_idle_hook([&](hal::TimePoint t) { app.plant->step(t); });
  e = app.boot();
  CHECK_TEXT(e.empty(), e.c_str());
  api::ServiceContext cx;
  cx.svc = &app.console->service();
  cx.ctl = app.ctl.get();
  cx.chain = &app.chain;
  std::string a = ask(cx, R"({"id":1,"cmd":"safety_mode","mode":"reduced"})");
  STRCMP_CONTAINS("\"ok\":true", a.c_str());
  CHECK(app.ctl->safety_mode() == kin::SafetyMode::reduced);
  a = ask(cx, R"({"id":2,"cmd":"safety_mode","mode":"normal"})");
  STRCMP_CONTAINS("\"error\":\"bad_state\"", a.c_str());
  STRCMP_CONTAINS("Reduced -> Normal loosens the safety limits: confirm it", a.c_str());
  CHECK(app.ctl->safety_mode() == kin::SafetyMode::reduced);
  a = ask(cx, R"({"id":3,"cmd":"safety_mode","mode":"normal","confirm":true})");
  STRCMP_CONTAINS("\"ok\":true", a.c_str());
  CHECK(app.ctl->safety_mode() == kin::SafetyMode::normal);
  a = ask(cx, R"({"id":4,"cmd":"safety_mode","mode":"fast"})");
  STRCMP_CONTAINS("mode: normal or reduced", a.c_str());
  CHECK(app.ctl->safety_mode() == kin::SafetyMode::normal);
  clock.set_idle_hook(nullptr);
}

// The state sample (the `state` answer and stream, state_line) carries the safety inputs
// (asserted, lost) and the speed scale, as the control thread publishes them: a Reduced input on a simulated contact, released, asserted, then lost.
TEST(SafetyApi, TheStateSampleCarriesTheInputsAndTheSpeedScale) {
  test::SimApp app;
  hal::ManualClock clock;
  FwConfig c;
  c.can = "sim";
  c.safety_planes = {0, 0, 1, -500};
  c.safety_reduced_input = "sim:door";
  std::string e = app.build(c, &clock);
  CHECK_TEXT(e.empty(), e.c_str());
  clock.set_idle_hook([&](hal::TimePoint t) { app.plant->step(t); });
  e = app.boot();
  CHECK_TEXT(e.empty(), e.c_str());
  auto run = [&](int cycles) {
    for (int i = 0; i < cycles; ++i) {
      app.ctl->cycle(clock.now());
      clock.advance(hal::kMillisecond);
    }
  };
  hal::SimInput* door = app.sim_input("door");
  CHECK(door != nullptr);
  struct Step {
    hal::InputLevel level;  // the contact (asserted when low: safety.reduced_input_active)
    const char* inputs;     // the state's safety_inputs
    const char* mode;       // and safety_mode
  } const steps[] = {
      {hal::InputLevel::high, R"("safety_inputs":{"estop":false,"estop_lost":false,"reduced":false,"reduced_lost":false})",
       R"("safety_mode":"normal")"},
      {hal::InputLevel::low, R"("safety_inputs":{"estop":false,"estop_lost":false,"reduced":true,"reduced_lost":false})",
       R"("safety_mode":"reduced")"},
      {hal::InputLevel::lost, R"("safety_inputs":{"estop":false,"estop_lost":false,"reduced":true,"reduced_lost":true})",
       R"("safety_mode":"reduced")"},
  };
  for (const Step& s : steps) {
    door->set(s.level);
    run(2 * static_cast<int>(c.safety_input_debounce_ms) + 20);  // a release counts after the debounce
    const std::string st = api::state_line(app.ctl->telemetry(), 1000.0, app.chain, 0, nullptr);
    STRCMP_CONTAINS(s.inputs, st.c_str());
    STRCMP_CONTAINS(s.mode, st.c_str());
    STRCMP_CONTAINS("\"speed_scale\":1.0", st.c_str());  // at rest: nothing to scale
  }
  clock.set_idle_hook(nullptr);
}
