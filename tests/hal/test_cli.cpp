// SPDX-License-Identifier: Apache-2.0
// Argument parsers of the armsim / canmaster binaries.
#include <string>
#include <vector>

#include "servoarm/sim/cli.hpp"

// CppUTest last: its leak detector redefines `new`.
#include <CppUTest/TestHarness.h>

using namespace servoarm::sim::cli;

TEST_GROUP(Cli){};

TEST(Cli, NodeLists) {
  struct Case {
    const char* text;
    bool ok;
    std::vector<std::uint8_t> nodes;
  } cases[] = {
      {"1-6", true, {1, 2, 3, 4, 5, 6}},
      {"1,3,5", true, {1, 3, 5}},
      {"2-4,7", true, {2, 3, 4, 7}},
      {"5,1-2,5", true, {1, 2, 5}},
      {"127", true, {127}},
      {"0", false, {}},
      {"128", false, {}},
      {"6-1", false, {}},
      {"", false, {}},
      {"1,,2", false, {}},
      {"a-b", false, {}},
      {"1-", false, {}},
      {"-3", false, {}},
  };
  for (const Case& c : cases) {
    std::vector<std::uint8_t> out;
    CHECK_EQUAL_TEXT(c.ok, parse_nodes(c.text, out), c.text);
    if (c.ok) CHECK_TEXT(out == c.nodes, c.text);
  }
}

TEST(Cli, FaultArguments) {
  FaultArg f;
  CHECK(parse_fault("3@1.5", false, f));
  LONGS_EQUAL(3, f.node);
  DOUBLES_EQUAL(1.5, f.at, 0);
  CHECK(parse_fault("all", false, f));
  LONGS_EQUAL(0, f.node);
  CHECK(parse_fault("2:0x2310@0.25", true, f));
  STRCMP_EQUAL("0x2310", f.value.c_str());
  DOUBLES_EQUAL(0.25, f.at, 0);
  CHECK_FALSE(parse_fault("2", true, f));        // value missing
  CHECK_FALSE(parse_fault("2:5", false, f));     // value not expected
  CHECK_FALSE(parse_fault("0", false, f));
  CHECK_FALSE(parse_fault("3@-1", false, f));
  CHECK_FALSE(parse_fault("3@x", false, f));
  std::uint32_t u;
  CHECK(parse_uint("0x10", 0xFF, u));
  LONGS_EQUAL(16, u);
  CHECK_FALSE(parse_uint("256", 0xFF, u));
  CHECK_FALSE(parse_uint("-1", 0xFF, u));
  double d;
  CHECK_FALSE(parse_double("nan", d));
  CHECK_FALSE(parse_double("1.5x", d));
}
