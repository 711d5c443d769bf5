// SPDX-License-Identifier: Apache-2.0
// parse_decimal (servoarm/lang/number.hpp): the one decimal reader of the console,
// G-code, armctl and armfw's flags. A case table of accepted and refused spellings; the
// accepted values are compared with the literal the compiler reads.
#include <cmath>
#include <string>

#include "servoarm/lang/number.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm::fw;

TEST_GROUP(Number){};

TEST(Number, AcceptedSpellingsGiveTheCompilersValue) {
  struct Case { const char* text; double value; };
  const Case cases[] = {
      {"0", 0.0},       {"-0", -0.0},      {"+5", 5.0},       {"12.5", 12.5},   {".5", .5},
      {"5.", 5.},       {"-1e3", -1e3},    {"1E-3", 1e-3},    {"2.5e+2", 2.5e2}, {"1e308", 1e308},
      {"1e-400", 0.0},  // underflow rounds to zero, a finite value
      {"0000000000000000000000000000000000000001", 1.0},  // 40 characters: the cap
  };
  for (const Case& c : cases) {
    double v = 99;
    CHECK_EQUAL_TEXT(int(Num::ok), int(parse_decimal(c.text, v)), c.text);
    DOUBLES_EQUAL(c.value, v, 0.0);
  }
}

TEST(Number, RefusedSpellingsLeaveTheOutputAlone) {
  struct Case { const char* text; Num why; };
  const Case cases[] = {
      {"", Num::bad},        {"+", Num::bad},      {".", Num::bad},        {"e5", Num::bad},
      {"1e", Num::bad},      {"1e+", Num::bad},    {"0x10", Num::bad},     {" 5", Num::bad},
      {"5 ", Num::bad},      {"5mm", Num::bad},    {"1,5", Num::bad},      {"--5", Num::bad},
      {"1.2.3", Num::bad},   {"00000000000000000000000000000000000000001", Num::bad},  // 41
      {"nan", Num::not_finite}, {"-inf", Num::not_finite}, {"Infinity", Num::not_finite},
      {"1e400", Num::not_finite}, {"-1e309", Num::not_finite},
  };
  for (const Case& c : cases) {
    double v = 99;
    CHECK_EQUAL_TEXT(int(c.why), int(parse_decimal(c.text, v)), c.text);
    DOUBLES_EQUAL(99, v, 0.0);
  }
}

TEST(Number, ReadsOnlyTheViewNotTheBytesAfterIt) {
  const std::string s = "12345";
  double v = 0;
  CHECK(parse_decimal(std::string_view(s).substr(0, 2), v) == Num::ok);
  DOUBLES_EQUAL(12, v, 0.0);
}
