// SPDX-License-Identifier: Apache-2.0
// The console's command table (command_table.hpp): every entry is reachable by the
// parser and appears in `help`; docs/console.md holds exactly the reference the table
// produces between its markers (a command added without regenerating the page fails
// here, with the diff).
#include <fstream>
#include <set>
#include <sstream>
#include <string>

#include "servoarm/lang/command_table.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm::fw;

namespace {
constexpr int kN = 6;

bool has(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

std::string read_file(const std::string& path) {
  std::ifstream f(path);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

/// A line with arguments of the entry's shape that must parse.
std::string sample_line(const CommandSpec& e) {
  std::string l = e.name;
  switch (e.args) {
    case ArgShape::none: break;
    case ArgShape::topic: l += " movel"; break;
    case ArgShape::joints_speed: l += " 0 10 20 0 30 0 speed=20"; break;
    case ArgShape::pose_speed: l += " 400 0 300 180 0 90 speed=50"; break;
    case ArgShape::pose: l += " 400 0 300"; break;
    case ArgShape::joints_opt: l += " 0 10 20 0 30 0"; break;
    case ArgShape::jog: l += " j3 +5 speed=20"; break;
    case ArgShape::tool: l += " grip 0 0 100 0 0 0 mass=1 com=0,0,40"; break;
    case ArgShape::frame: l += " table 400 0 0 0 0 90"; break;
    case ArgShape::joint_word: l += " j3"; break;
    case ArgShape::point_name: l += " pick"; break;
    case ArgShape::program_name: l += " pick_place"; break;
    case ArgShape::record: l += " start rate=50"; break;
    case ArgShape::output: l += " gripper on"; break;
    case ArgShape::confirm: l += " confirm"; break;
    case ArgShape::rest: l += " tcp_speed_mm_s = 100; reduced_tcp_speed_mm_s = 50"; break;
    case ArgShape::checksum: l += " 0123abCD"; break;
  }
  return l;
}
}  // namespace

TEST_GROUP(CommandTable){};

TEST(CommandTable, EveryEntryIsReachableByTheParser) {
  std::set<std::string> names;
  std::set<int> cmds;
  for (const CommandSpec& e : kCommands) {
    CHECK_TEXT(names.insert(e.name).second, e.name);                    // one row per name
    CHECK_TEXT(cmds.insert(static_cast<int>(e.cmd)).second, e.name);    // one row per Cmd
    CHECK_TEXT(std::string(e.usage).rfind(e.name, 0) == 0, e.usage);    // usage starts with the name
    CHECK_TEXT(*e.help != '\0', e.name);
    CHECK_TEXT(find_command(e.cmd) == &e, e.name);
    for (const std::string& line : {sample_line(e), std::string(e.name)}) {
      if (line == e.name && (e.args == ArgShape::joints_speed || e.args == ArgShape::pose_speed || e.args == ArgShape::pose ||
                             e.args == ArgShape::point_name || e.args == ArgShape::program_name || e.args == ArgShape::record ||
                             e.args == ArgShape::rest || e.args == ArgShape::checksum))
        continue;  // these need values
      GcodeModal m;
      Command c;
      const ParseResult r = parse_line(line, kN, m, c);
      if (!r.ok()) FAIL(("'" + line + "' refused: " + r.message.data()).c_str());
      if (c.cmd != e.cmd) FAIL(("'" + line + "' parsed as " + to_string(c.cmd) + ", not " + to_string(e.cmd)).c_str());
      // upper case too
      std::string up = line;
      for (char& ch : up) ch = static_cast<char>(ch >= 'a' && ch <= 'z' ? ch - 'a' + 'A' : ch);
      Command cu;
      CHECK_TEXT(parse_line(up, kN, m, cu).ok() && cu.cmd == e.cmd, up.c_str());
    }
  }
  // The kinds no command word names are the G-code ones (and none).
  for (Cmd k : {Cmd::none, Cmd::dwell, Cmd::position, Cmd::gmove, Cmd::temperature}) CHECK(find_command(k) == nullptr);
}

TEST(CommandTable, EveryEntryAppearsInHelp) {
  std::string all;
  CHECK(help_text("", "units: test", all));
  CHECK_TEXT(all.find("\ncommands (one per line") != std::string::npos, all.c_str());  // after the overview
  CHECK_TEXT(has(all, "\nunits: test\n"), all.c_str());
  for (const CommandSpec& e : kCommands) {
    CHECK_TEXT(has(all, std::string("  ") + e.usage + " "), e.usage);
    CHECK_TEXT(has(all, e.help), e.help);
    std::string one;
    CHECK_TEXT(help_text(e.name, "", one), e.name);
    CHECK_TEXT(has(one, e.usage), one.c_str());
    if (*e.details) CHECK_TEXT(has(one, e.details), one.c_str());
  }
  // `help home` is both home entries; a G-code or a word gives the lines mentioning it.
  std::string home;
  CHECK(help_text("home", "", home));
  CHECK_TEXT(has(home, "  home ") && has(home, "  home zero"), home.c_str());
  std::string g1;
  CHECK(help_text("G1", "", g1));
  CHECK_TEXT(has(g1, "G1 X Y Z") && !has(g1, "movej"), g1.c_str());
  std::string none = "untouched";
  CHECK(!help_text("frobnicate", "", none));
  STRCMP_EQUAL("untouched", none.c_str());
}

TEST(CommandTable, ReferencePageIsGeneratedFromTheTable) {
  const std::string page = read_file(std::string(SERVOARM_SOURCE_DIR) + "/docs/console.md");
  CHECK(page.size() > 1000);
  const std::string why = console_reference_mismatch(page);
  if (!why.empty()) FAIL(why.c_str());
  for (const CommandSpec& e : kCommands) CHECK_TEXT(has(page, std::string("| `") + e.usage + "` |"), e.usage);
  // the check itself: a row added by hand, a row missing, a changed text, no markers
  const std::string row = "| `stop` |";
  const auto at = page.find(row);
  CHECK(at != std::string::npos);
  const auto eol = page.find('\n', at);
  std::string extra = page;
  extra.insert(eol + 1, "| `frobnicate` | a command added by hand |  |\n");
  const std::string e1 = console_reference_mismatch(extra);
  CHECK_TEXT(has(e1, "- line ") && has(e1, "frobnicate") && has(e1, "regenerate"), e1.c_str());
  std::string missing = page;
  missing.erase(at, eol + 1 - at);
  const std::string e2 = console_reference_mismatch(missing);
  CHECK_TEXT(has(e2, "+ " + row), e2.c_str());
  std::string changed = page;
  changed.replace(at + row.size(), 5, " RAMP");
  CHECK(!console_reference_mismatch(changed).empty());
  CHECK(has(console_reference_mismatch("# no markers\n"), "markers"));
}

// The GRBL '$' table: every entry parses to its Cmd (the $J= one with G-code words), is in
// `help` and in the reference page; settings writes and unknown $ words are refused.
TEST(CommandTable, EveryGrblEntryIsReachableAndListed) {
  std::string help;
  CHECK(help_text("", "", help));
  const std::string ref = console_reference_markdown();
  for (const GrblSpec& g : kGrblCommands) {
    const std::string line = std::string("$") + g.word + (std::string(g.word) == "J=" ? "G91 X1 F100" : "");
    GcodeModal m;
    Command c;
    const ParseResult r = parse_line(line, kN, m, c);
    if (!r.ok()) FAIL(("'" + line + "' refused: " + r.message.data()).c_str());
    CHECK_TEXT(c.cmd == g.cmd, line.c_str());
    CHECK_TEXT(has(help, g.usage), g.usage);
    CHECK_TEXT(has(ref, g.usage), g.usage);
  }
  for (const char* bad : {"$Q", "$100=5", "$J", "$JG91 X1 F100", "$RST=*"}) {
    GcodeModal m;
    Command c;
    CHECK_TEXT(!parse_line(bad, kN, m, c).ok(), bad);
  }
}

namespace {
std::size_t line_count(const std::string& s) {
  std::size_t n = 0;
  for (char ch : s) n += ch == '\n';
  return n;
}
}  // namespace

// `help` opens with a short overview: what the console is, the commands to start with,
// how to stop the arm and how to end the session (quit, exit, Ctrl-D), and `help CMD`
// for the rest; then the one-line list of every command.
TEST(CommandTable, HelpOpensWithAShortOverview) {
  std::string all;
  CHECK(help_text("", "units: test", all));
  const std::size_t list = all.find("commands (one per line");
  CHECK_TEXT(list != std::string::npos && list > 0, all.c_str());
  const std::string overview = all.substr(0, list);
  CHECK_TEXT(line_count(overview) <= 14, overview.c_str());  // short: a screen's top
  for (const char* w : {"help CMD", "status", "enable", "home", "movej", "stop", "Ctrl-X", "quit", "exit", "Ctrl-D"})
    CHECK_TEXT(has(overview, w), (std::string(w) + " missing from:\n" + overview).c_str());
  // the details of a command are in `help CMD`, not in `help`
  for (const CommandSpec& e : kCommands)
    if (*e.details) CHECK_TEXT(!has(all, e.details), e.name);
}

// `quit` and `exit` are commands of the table (one entry, `exit` its other name): they
// parse, take no argument, and `help quit` / `help exit` describe them per transport.
TEST(CommandTable, QuitAndExitEndTheSession) {
  const CommandSpec* quit = nullptr;
  for (const CommandSpec& e : kCommands)
    if (std::string(e.name) == "quit") quit = &e;
  if (quit == nullptr) FAIL("no quit entry in the command table");
  for (const char* line : {"quit", "exit", "QUIT", "Exit"}) {
    GcodeModal m;
    Command c;
    const ParseResult r = parse_line(line, kN, m, c);
    if (!r.ok()) FAIL((std::string(line) + " refused: " + r.message.data()).c_str());
    CHECK_TEXT(c.cmd == quit->cmd, line);
  }
  GcodeModal m;
  Command c;
  const ParseResult r = parse_line("exit now", kN, m, c);
  CHECK_TEXT(!r.ok() && r.error == CmdError::arg_count, r.message.data());
  for (const char* topic : {"quit", "exit"}) {
    std::string h;
    CHECK_TEXT(help_text(topic, "", h), topic);
    CHECK_TEXT(has(h, "quit") && has(h, "exit") && has(h, "stdin") && has(h, "Ctrl-D"), h.c_str());
  }
}

// `safety stage` takes the rest of the line as typed, also beyond the parser's 24 words (an
// array of six values and more), into the Command's fixed field; `safety confirm` reads exactly
// 8 hex digits; `safety normal` takes only the word `confirm`.
TEST(CommandTable, SafetyStageTakesTheRestOfTheLineAndConfirmAChecksum) {
  const std::string change =
      "joint_speed_deg_s = [90, 90, 90, 180, 180, 180]; reduced_joint_speed_deg_s = [30, 30, 30, 60, 60, 60]; planes = [0, 0, 1, -400, 1, 0, 0, 800]";
  GcodeModal m;
  Command c;
  ParseResult r = parse_line("  safety   stage " + change + "  ", kN, m, c);
  CHECK_TEXT(r.ok(), r.message.data());
  CHECK(c.cmd == Cmd::safety_stage);
  STRCMP_EQUAL(change.c_str(), c.text.data());
  r = parse_line("movej 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20 21 22 23 24 25", kN, m, c);  // any other: too many words
  STRCMP_CONTAINS("too many words", r.message.data());
  r = parse_line("safety confirm 0123abCD", kN, m, c);
  CHECK_TEXT(r.ok(), r.message.data());
  CHECK_EQUAL(0x0123ABCDu, c.checksum);
  for (const char* bad : {"safety confirm 0123abC", "safety confirm 0123abCDE", "safety confirm 0x23abCD", "safety confirm"}) {
    r = parse_line(bad, kN, m, c);
    CHECK_TEXT(!r.ok(), bad);
  }
  r = parse_line("safety normal confirm", kN, m, c);
  CHECK_TEXT(r.ok() && c.confirm && c.cmd == Cmd::safety_normal, r.message.data());
  r = parse_line("safety normal", kN, m, c);
  CHECK_TEXT(r.ok() && !c.confirm, r.message.data());
  STRCMP_CONTAINS("is not `confirm`", parse_line("safety normal please", kN, m, c).message.data());
}
