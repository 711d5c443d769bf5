// SPDX-License-Identifier: Apache-2.0
// The command parser, pure: case tables of good and malformed lines for every
// command and G-code (overlong, binary garbage, wrong argument counts, NaN).
#include <cmath>
#include <cstring>
#include <string>

#include "servoarm/lang/commands.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm::fw;

namespace {
struct Good {
  const char* line;
  Cmd cmd;
  int count;
};
struct Bad {
  const char* line;
  CmdError err;
};
constexpr int kN = 6;

std::string show(const char* line) {
  std::string s;
  for (const char* p = line; *p; ++p) {
    const auto u = static_cast<unsigned char>(*p);
    if (u < 0x20 || u >= 0x7f) {
      char b[8];
      std::snprintf(b, sizeof b, "\\x%02X", u);
      s += b;
    } else {
      s += *p;
    }
  }
  return s;
}
}  // namespace

TEST_GROUP(Parser){};

TEST(Parser, GoodCommands) {
  const Good cases[] = {
      {"help", Cmd::help, 0},
      {"help movel", Cmd::help, 0},
      {"status", Cmd::status, 0},
      {"  STATUS  ", Cmd::status, 0},
      {"enable", Cmd::enable, 0},
      {"disable", Cmd::disable, 0},
      {"home", Cmd::home, 0},
      {"home j3", Cmd::home, 0},
      {"HOME J6", Cmd::home, 0},
      {"park", Cmd::park, 0},
      {"movej 0 45 -45 0 0 0", Cmd::movej, 6},
      {"movej 0 45 -45 0 0 0 speed=20", Cmd::movej, 6},
      {"movej 1e1 -2.5 .5 3. +4 0 speed=100", Cmd::movej, 6},
      {"movel 400 0 300", Cmd::movel, 3},
      {"movel 400 0 300 speed=50", Cmd::movel, 3},
      {"movel 400 0 300 180 0 90", Cmd::movel, 6},
      {"movel 400 0 300 180 0 90 speed=250", Cmd::movel, 6},
      {"stop", Cmd::stop, 0},
      {"estop", Cmd::estop, 0},
      {"reset", Cmd::reset, 0},
      {"fk", Cmd::fk, 0},
      {"fk 0 0 0 0 0 0", Cmd::fk, 6},
      {"ik 400 0 300", Cmd::ik, 3},
      {"ik 400 0 300 0 90 0", Cmd::ik, 6},
      {"limits", Cmd::limits, 0},
      {"stats", Cmd::stats, 0},
      {"config", Cmd::config, 0},
      {"wait", Cmd::wait, 0},
      {"hold", Cmd::hold, 0},
      {"resume", Cmd::resume, 0},
      {"", Cmd::none, 0},
      {"   ", Cmd::none, 0},
      {"# a comment", Cmd::none, 0},
      {"movej 0 0 0 0 0 0\r", Cmd::movej, 6},
  };
  for (const Good& g : cases) {
    GcodeModal m;
    Command c;
    const ParseResult r = parse_line(g.line, kN, m, c);
    if (!r.ok()) FAIL(("'" + show(g.line) + "' refused: " + r.message.data()).c_str());
    if (c.cmd != g.cmd || c.count != g.count)
      FAIL(("'" + show(g.line) + "' parsed as " + to_string(c.cmd) + " with " + std::to_string(c.count) + " values").c_str());
  }
}

TEST(Parser, ValuesAndSpeed) {
  GcodeModal m;
  Command c;
  CHECK(parse_line("movej 10 -20 30.5 0 0 1e-3 speed=25", kN, m, c).ok());
  DOUBLES_EQUAL(10, c.vals[0], 0);
  DOUBLES_EQUAL(-20, c.vals[1], 0);
  DOUBLES_EQUAL(30.5, c.vals[2], 0);
  DOUBLES_EQUAL(1e-3, c.vals[5], 0);
  CHECK(c.has_speed);
  DOUBLES_EQUAL(25, c.speed, 0);
}

TEST(Parser, MalformedCommands) {
  std::string overlong = "movej " + std::string(kMaxLine, '1');
  const std::string bin1 = std::string("movej 0 0 0 0 0 0") + '\x01';
  const std::string bin2 = "\xff\xfe\x80garbage";
  const std::string bin3 = std::string("sta\x7ftus");
  const Bad cases[] = {
      {overlong.c_str(), CmdError::overlong},
      {bin1.c_str(), CmdError::binary},
      {bin2.c_str(), CmdError::binary},
      {bin3.c_str(), CmdError::binary},
      {"frobnicate", CmdError::unknown_command},
      {"move", CmdError::unknown_command},
      // an orientation beyond a turn names no orientation; G53 only with a G0/G1 move
      {"ik 0.4 0.1 0.3 1e300 0 0", CmdError::out_of_range},
      {"movel 0.4 0.1 0.3 0 0 -1e300", CmdError::out_of_range},
      {"movel 0.4 0.1 0.3 0 1e9 0 speed=0.1", CmdError::out_of_range},
      {"G53", CmdError::arg_count},
      {"G53 G4 P1", CmdError::arg_count},
      {"G53 G0", CmdError::arg_count},
      {"help a b", CmdError::arg_count},
      {"status now", CmdError::arg_count},
      {"enable 1", CmdError::arg_count},
      {"disable x", CmdError::arg_count},
      {"home 0", CmdError::arg_count},
      {"home j0", CmdError::out_of_range},
      {"home j7", CmdError::out_of_range},
      {"home j1 j2", CmdError::arg_count},
      {"home jx", CmdError::arg_count},
      {"park 1", CmdError::arg_count},
      {"stop now", CmdError::arg_count},
      {"estop 1", CmdError::arg_count},
      {"reset all", CmdError::arg_count},
      {"limits 1", CmdError::arg_count},
      {"stats reset", CmdError::arg_count},
      {"config x", CmdError::arg_count},
      {"wait 5", CmdError::arg_count},
      {"movej", CmdError::arg_count},
      {"movej 0 0 0 0 0", CmdError::arg_count},
      {"movej 0 0 0 0 0 0 0", CmdError::arg_count},
      {"movej 0 0 0 0 0 nan", CmdError::not_finite},
      {"movej 0 0 0 0 0 NaN", CmdError::not_finite},
      {"movej 0 0 0 0 0 -inf", CmdError::not_finite},
      {"movej 0 0 0 0 0 1e400", CmdError::not_finite},
      {"movej 0 0 0 0 0 0x10", CmdError::bad_number},
      {"movej 0 0 0 0 0 1..2", CmdError::bad_number},
      {"movej 0 0 0 0 0 abc", CmdError::bad_number},
      {"movej 0 0 0 0 0 1e", CmdError::bad_number},
      {"movej 0 0 0 0 0 0 speed=0", CmdError::out_of_range},
      {"movej 0 0 0 0 0 0 speed=-5", CmdError::out_of_range},
      {"movej 0 0 0 0 0 0 speed=101", CmdError::out_of_range},
      {"movej 0 0 0 0 0 0 speed=nan", CmdError::not_finite},
      {"movej 0 0 0 0 0 0 speed=", CmdError::bad_number},
      {"movej 0 0 0 0 0 0 fast=1", CmdError::bad_option},
      {"movej 0 0 0 0 0 0 speed=5 speed=6", CmdError::bad_option},
      {"movej speed=5 0 0 0 0 0 0", CmdError::bad_option},
      {"movel", CmdError::arg_count},
      {"movel 1 2", CmdError::arg_count},
      {"movel 1 2 3 4", CmdError::arg_count},
      {"movel 1 2 3 4 5", CmdError::arg_count},
      {"movel 1 2 3 4 5 6 7", CmdError::arg_count},
      {"movel 1 2 nan", CmdError::not_finite},
      {"movel 1 2 3 speed=0", CmdError::out_of_range},
      {"ik", CmdError::arg_count},
      {"ik 1 2", CmdError::arg_count},
      {"ik 1 2 3 speed=4", CmdError::bad_option},
      {"ik 1 2 inf", CmdError::not_finite},
      {"fk 1 2 3", CmdError::arg_count},
      {"fk 0 0 0 0 0 nan", CmdError::not_finite},
      // A query never changes state: `stats zero` used to fall through into `home zero`.
      {"stats zero", CmdError::arg_count},
      {"stats 1", CmdError::arg_count},
      {"status zero", CmdError::arg_count},
      {"limits zero", CmdError::arg_count},
      {"config zero", CmdError::arg_count},
      {"home zero 1", CmdError::arg_count},
      {"home one", CmdError::arg_count},
      // Speeds have lower bounds (a move at 1e-9 mm/s never ends).
      {"movel 1 2 3 speed=0.000000001", CmdError::out_of_range},
      {"movel 1 2 3 speed=0.009", CmdError::out_of_range},
      {"movej 0 0 0 0 0 0 speed=0.000001", CmdError::out_of_range},
      {"movej 0 0 0 0 0 0 speed=0.09", CmdError::out_of_range},
      {"movej 0 0 0 0 0 0 speed=0.99", CmdError::out_of_range},
  };
  for (const Bad& b : cases) {
    GcodeModal m;
    m.relative = true;  // must stay untouched by failed lines
    Command c;
    c.cmd = Cmd::status;
    const ParseResult r = parse_line(b.line, kN, m, c);
    if (r.error != b.err)
      FAIL(("'" + show(b.line).substr(0, 60) + "': expected " + to_string(b.err) + ", got " + to_string(r.error) + " (" +
            r.message.data() + ")").c_str());
    CHECK(r.message[0] != '\0');
    CHECK(c.cmd == Cmd::status);  // output untouched
    CHECK(m.relative);
  }
}

// Every command word with arguments it does not take: refused with arg_count, and
// the message names the command typed (not another one), so no case of the parser
// can fall through into a different command.
TEST(Parser, EveryCommandRefusesWrongArgumentsNamingItself) {
  struct Case {
    const char* word;
    const char* args;
  };
  const Case cases[] = {
      {"status", "zero"}, {"status", "1"},       {"enable", "zero"},  {"disable", "zero"}, {"stop", "zero"},
      {"estop", "zero"},  {"reset", "zero"},     {"limits", "zero"},  {"stats", "zero"},   {"stats", "1"},
      {"stats", "x y"},   {"config", "zero"},    {"wait", "zero"},    {"hold", "zero"},    {"resume", "zero"},
      {"home", "1"},      {"home", "zero zero"}, {"help", "a b"},     {"movej", "1 2 3"},  {"movel", "1 2"},
      {"ik", "1 2"},      {"fk", "1 2 3"},       {"movej", "zero"},   {"fk", "zero"},      {"ik", "zero 1 2"},
      {"park", "1"},      {"home", "j1 j2"},
  };
  for (const Case& k : cases) {
    const std::string line = std::string(k.word) + " " + k.args;
    GcodeModal m;
    Command c;
    c.cmd = Cmd::status;
    const ParseResult r = parse_line(line, kN, m, c);
    if (r.ok()) FAIL(("'" + line + "' was accepted as " + to_string(c.cmd)).c_str());
    if (r.error != CmdError::arg_count && r.error != CmdError::bad_number)
      FAIL(("'" + line + "': expected arg_count or bad_number, got " + to_string(r.error)).c_str());
    const std::string msg = r.message.data();
    if (msg.rfind(k.word, 0) != 0)
      FAIL(("'" + line + "': the message does not name '" + k.word + "': " + msg).c_str());
    CHECK(c.cmd == Cmd::status);
  }
}

TEST(Parser, GoodGcode) {
  const Good cases[] = {
      {"G0 X10 Y20 Z30", Cmd::gmove, 6},
      {"G1 X10 F600", Cmd::gmove, 6},
      {"g1 x10 y-5.5", Cmd::gmove, 6},
      {"G1X10Y20Z30A0B90C0", Cmd::gmove, 6},
      {"G01 Z-3", Cmd::gmove, 6},
      {"G1 F1200", Cmd::none, 0},
      {"G90", Cmd::none, 0},
      {"G91", Cmd::none, 0},
      {"G20", Cmd::none, 0},
      {"G21 G90", Cmd::none, 0},
      {"G28", Cmd::park, 0},
      {"G4 P500", Cmd::dwell, 1},
      {"G4 S2", Cmd::dwell, 1},
      {"M17", Cmd::enable, 0},
      {"M18", Cmd::disable, 0},
      {"M84", Cmd::disable, 0},
      {"M112", Cmd::estop, 0},
      {"M114", Cmd::position, 0},
      {"M400", Cmd::wait, 0},
      {"M105", Cmd::temperature, 0},
      {"M110 N0", Cmd::none, 0},
      {"N5 G1 X1", Cmd::gmove, 6},
      {"G1 X1 ; comment", Cmd::gmove, 6},
      {"G1 (inline) X1", Cmd::gmove, 6},
      {"N1 G1 X1*96", Cmd::gmove, 6},  // checksum of "N1 G1 X1"
      {"; only a comment", Cmd::none, 0},
  };
  for (const Good& g : cases) {
    GcodeModal m;
    Command c;
    const ParseResult r = parse_line(g.line, kN, m, c);
    if (!r.ok()) FAIL(("'" + show(g.line) + "' refused: " + r.message.data()).c_str());
    if (c.cmd != g.cmd || c.count != g.count)
      FAIL(("'" + show(g.line) + "' parsed as " + to_string(c.cmd) + " with " + std::to_string(c.count) + " values").c_str());
  }
}

TEST(Parser, GcodeModalStateAndUnits) {
  GcodeModal m;
  Command c;
  CHECK(parse_line("G91", kN, m, c).ok());
  CHECK(m.relative);
  CHECK(parse_line("G20", kN, m, c).ok());
  DOUBLES_EQUAL(25.4, m.unit_mm, 0);
  CHECK(parse_line("G1 X1 Y-2 F60", kN, m, c).ok());  // inches: 1 in, F 60 in/min = 25.4 mm/s
  CHECK(c.relative);
  LONGS_EQUAL(0x3, c.axis_mask);
  DOUBLES_EQUAL(25.4, c.vals[0], 1e-12);
  DOUBLES_EQUAL(-50.8, c.vals[1], 1e-12);
  CHECK(c.has_speed);
  DOUBLES_EQUAL(25.4, c.speed, 1e-12);
  CHECK(parse_line("G1 A90", kN, m, c).ok());  // angles are not scaled by G20
  DOUBLES_EQUAL(90, c.vals[3], 0);
  LONGS_EQUAL(0x8, c.axis_mask);
  CHECK(parse_line("G21 G90", kN, m, c).ok());
  CHECK_FALSE(m.relative);
  DOUBLES_EQUAL(1.0, m.unit_mm, 0);
  CHECK(parse_line("G0 Z5", kN, m, c).ok());
  CHECK(c.rapid);
  CHECK(parse_line("G4 P250", kN, m, c).ok());
  DOUBLES_EQUAL(0.25, c.vals[0], 1e-12);
}

TEST(Parser, MalformedGcode) {
  const Bad cases[] = {
      {"G2 X1 Y1 I1", CmdError::unsupported},
      {"G18", CmdError::unsupported},  // (G17, the XY plane, is accepted: senders send it)
      {"M3 S1000", CmdError::unsupported},
      {"M999", CmdError::unsupported},
      {"G1 E5", CmdError::unsupported},
      {"G1 X", CmdError::bad_number},
      {"G1 Xnan", CmdError::bad_number},
      {"G1 X1.2.3", CmdError::bad_number},
      {"G1 X1 X2", CmdError::arg_count},
      {"G0 G1 X1", CmdError::arg_count},
      {"G1 X1 M17", CmdError::arg_count},
      {"X10", CmdError::unknown_command},
      {"G4", CmdError::arg_count},
      {"G4 P1 S1", CmdError::arg_count},
      {"G4 X1", CmdError::arg_count},
      {"G4 P9999999", CmdError::out_of_range},
      {"G1 X1 F0", CmdError::out_of_range},
      {"G1 X1 F0.00001", CmdError::out_of_range},
      {"G1 X1 F0.02", CmdError::out_of_range},  // modal G20 here: 0.02 in/min = 0.51 mm/min
      {"G21 G1 F0.5", CmdError::out_of_range},  // 0.5 mm/min: below 0.6 mm/min
      {"G20 G1 X1 F0.02", CmdError::out_of_range},
      {"G1 X1 F-10", CmdError::out_of_range},
      {"G1 X1 P5", CmdError::bad_option},
      {"M17 X1", CmdError::arg_count},
      {"M114 P1", CmdError::bad_option},
      {"N1 G1 X1*97", CmdError::checksum},
      {"N1 G1 X1*abc", CmdError::checksum},
      {"G1 (unclosed X1", CmdError::bad_number},
      {"G1 X1)", CmdError::bad_number},
      {"G1 $1", CmdError::bad_number},
  };
  for (const Bad& b : cases) {
    GcodeModal m;
    m.relative = true;
    m.unit_mm = 25.4;
    Command c;
    c.cmd = Cmd::status;
    const ParseResult r = parse_line(b.line, kN, m, c);
    if (r.error != b.err)
      FAIL(("'" + show(b.line) + "': expected " + to_string(b.err) + ", got " + to_string(r.error) + " (" + r.message.data() + ")").c_str());
    CHECK(c.cmd == Cmd::status);
    CHECK(m.relative);
    DOUBLES_EQUAL(25.4, m.unit_mm, 0);
  }
}

TEST(Parser, SeededRandomGarbageNeverCrashesAndNeverMoves) {
  // Random printable and binary lines: the parser answers, never crashes, and a
  // line with a control byte is always refused.
  std::uint64_t x = 0x9E3779B97F4A7C15ull;
  auto rnd = [&] {
    x ^= x >> 12;
    x ^= x << 25;
    x ^= x >> 27;
    return x * 2685821657736338717ull;
  };
  for (int i = 0; i < 20000; ++i) {
    char line[96];
    const int len = static_cast<int>(rnd() % 90);
    bool ctrl = false;
    for (int k = 0; k < len; ++k) {
      char ch = static_cast<char>(rnd() % 256);
      if (ch == '\0') ch = ' ';
      const auto u = static_cast<unsigned char>(ch);
      if ((u < 0x20 && ch != '\t') || u >= 0x7f) ctrl = true;
      line[k] = ch;
    }
    line[len] = '\0';
    // Trailing CR / blanks are line-end noise the parser strips before looking.
    int end = len;
    while (end > 0 && (line[end - 1] == '\r' || line[end - 1] == ' ' || line[end - 1] == '\t')) --end;
    ctrl = false;
    for (int k = 0; k < end; ++k) {
      const auto u = static_cast<unsigned char>(line[k]);
      if ((u < 0x20 && line[k] != '\t') || u >= 0x7f) ctrl = true;
    }
    GcodeModal m;
    Command c;
    const ParseResult r = parse_line(std::string_view(line, static_cast<std::size_t>(len)), kN, m, c);
    if (ctrl) CHECK(r.error == CmdError::binary);
    if (!r.ok()) CHECK(r.message[0] != '\0');
  }
}

TEST(Parser, EveryErrorCodeHasAName) {
  for (int e = 0; e <= static_cast<int>(CmdError::internal); ++e)
    CHECK(std::strcmp(to_string(static_cast<CmdError>(e)), "?") != 0);
}

// `home` alone homes every joint (home_joint -1), `home jN` joint N (0-based N-1); G28 is park.
TEST(Parser, HomeNamesTheJointAndG28IsPark) {
  const struct {
    const char* line;
    Cmd cmd;
    int joint;
  } cases[] = {{"home", Cmd::home, -1}, {"home j1", Cmd::home, 0}, {"home J6", Cmd::home, 5},
               {"park", Cmd::park, -1}, {"G28", Cmd::park, -1},    {"$H", Cmd::grbl_home, -1}};
  for (const auto& k : cases) {
    GcodeModal m;
    Command c;
    const ParseResult r = parse_line(k.line, 6, m, c);
    CHECK_TEXT(r.ok(), k.line);
    CHECK_TEXT(c.cmd == k.cmd, k.line);
    LONGS_EQUAL_TEXT(k.joint, c.home_joint, k.line);
  }
}
