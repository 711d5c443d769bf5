// SPDX-License-Identifier: Apache-2.0
// What the command table (command_table.hpp) produces besides the parser's
// dispatch: `help`, `help <topic>` and the command reference of docs/console.md.
// Console thread / armctl: allocates.
#include "servoarm/lang/command_table.hpp"
#include "servoarm/lang/markdown.hpp"
#include "servoarm/lang/number.hpp"

#include <algorithm>
#include <cstring>
#include <vector>

namespace servoarm::fw {

const char* to_string(ArgShape a) {
  switch (a) {
    case ArgShape::none: return "none";
    case ArgShape::topic: return "topic";
    case ArgShape::joints_speed: return "joints_speed";
    case ArgShape::pose_speed: return "pose_speed";
    case ArgShape::pose: return "pose";
    case ArgShape::joints_opt: return "joints_opt";
    case ArgShape::jog: return "jog";
    case ArgShape::tool: return "tool";
    case ArgShape::frame: return "frame";
    case ArgShape::joint_word: return "joint_word";
    case ArgShape::point_name: return "point_name";
    case ArgShape::program_name: return "program_name";
    case ArgShape::record: return "record";
    case ArgShape::output: return "output";
    case ArgShape::confirm: return "confirm";
    case ArgShape::rest: return "rest";
    case ArgShape::checksum: return "checksum";
  }
  return "?";
}

const CommandSpec* find_command(Cmd cmd) {
  for (const CommandSpec& e : kCommands)
    if (e.cmd == cmd) return &e;
  return nullptr;
}

namespace {

/// G-code and realtime characters: what `help` and the reference list after the commands.
struct CodeSpec {
  const char* code;
  const char* help;
};
constexpr CodeSpec kGcodes[] = {
    {"G0 X Y Z [A B C]", "linear tool move at the maximum linear speed (A B C = rx ry rz in degrees); X Y Z A B C "
                         "are the active tool's point in the active user frame (`tool`, `frame`, G54..G59)"},
    {"G1 X Y Z [A B C] [F]", "linear tool move; F in G20/G21 length units per minute, clamped to the maximum"},
    {"G4 P<ms> | S<s>", "dwell (GRBL dialect: P in seconds, as GRBL and LinuxCNC read it)"},
    {"G20 | G21", "X Y Z and F in inches | millimetres"},
    {"G28", "park: joint move to the park pose (as `park`)"},
    {"G90 | G91", "absolute | relative X Y Z A B C"},
    {"G10 L2 P<0-6> [X Y Z A B C]", "set work offset n (frame g5(3+n), P0 the active one): its origin X Y Z (mm) and "
                                     "orientation A B C (deg) in the base; axes not given are kept; kept in the frames file"},
    {"G10 L20 P<0-6> [X Y Z]", "set work offset n so that the tool point, where it is now, has these coordinates in it "
                               "(the frame's orientation kept): a sender's \"zero here\""},
    {"G54 .. G59", "select the user frame g54 .. g59 (identity until G10 L2 sets it), on a line of its own"},
    {"G53", "on a G0/G1 line: that line in machine coordinates (the base frame)"},
    {"G17 G94 | M5 M9 | M2 M30", "accepted, nothing to do (the only plane and feed mode; no spindle or coolant; program end)"},
    {"M17", "enable"},
    {"M18 | M84", "disable"},
    {"M112", "e-stop"},
    {"M114", "position of the active tool's point in the active user frame: `X: Y: Z: A: B: C:` (G20/G21 length "
             "units, degrees), then `ok`"},
    {"M400", "wait"},
    {"M62 | M63 P<n>", "digital output n (0-based, [[output]] order) on | off at the start of the next move"},
    {"M64 | M65 P<n>", "digital output n on | off at once"},
    {"M105 | M110", "accepted so that senders connect (`ok T:0 /0 B:0 /0` | line numbers not tracked)"},
};
constexpr CodeSpec kRealtime[] = {
    {"?", "status report `<Idle|MPos:x,y,z|J:j1,...|Q:n>` (MPos in mm, J in the joint units)"},
    {"!", "feed hold (linear moves stop on the line; a running program is paused; a jog stops); aborts a homing cycle. "
          "Lines received before it and not run yet are held too: a move sent right before `!` is held as soon as it is "
          "queued, until `~` (a `!` at rest with nothing before it holds nothing)"},
    {"~", "resume (a paused program goes on; during the hold's ramp, once the arm is at rest)"},
    {"Ctrl-X (0x18)",
     "e-stop; discards the partial line, answers every line not executed yet with `error: estop` (GRBL dialect: a "
     "soft reset, the banner again; an e-stop only while the arm moves)"},
    {"0x85", "jog cancel: the jog decelerates to rest; jog lines not executed yet are answered, not run"},
    {"other bytes >= 0x80", "GRBL dialect: dropped unanswered (senders send 0x85 and the overrides UTF-8 encoded); native: refused in the line"},
    {"0x90 0x91 0x92 0x93 0x94", "feed override: 100 %, +10 %, -10 %, +1 %, -1 % (10-200 %); acts on jogs and moves; `status` (feed_override=) and `?` (Ov:) show it"},
    {"bytes 0x80-0xBF in UTF-8 text", "realtime only bare or UTF-8 encoded as C2 xx (U+0085, U+0090..U+0094, as senders send them); inside any other multi-byte character (C3 91 is `Ñ`) they are text: no override, no jog cancel (native: the line answers error: binary)"},
};


std::string pad(std::string s, std::size_t w) { return s.size() < w ? s.append(w - s.size(), ' ') : s + "  "; }

std::string entry_line(const CommandSpec& e) { return "  " + pad(e.usage, 32) + e.help + (e.query ? " [query]" : "") + "\n"; }

/// What `help` opens with: what the console is, the commands to start with, how to stop the
/// arm and how to end the session; `help CMD` has the rest.
constexpr const char* kOverview =
    "servoarm console: one command per line, each answered `ok [data]` or `error: <code> <message>`;\n"
    "  events come as `alarm: ...` lines.\n"
    "start:  status (state, joints, pose), enable (power the drives), home (when a joint is not homed),\n"
    "        movej j1..jn | movel x y z [rx ry rz] (move), wait (until the moves are done)\n"
    "stop:   stop (ramp down, queued moves dropped), ! (feed hold, ~ resumes),\n"
    "        estop or Ctrl-X (emergency stop, then reset and enable)\n"
    "quit:   quit or exit ends this session (on stdin armfw ends too), as Ctrl-D (end of input) does on\n"
    "        stdin and in armctl console\n"
    "more:   help CMD for one command in full (help movel), help G1 for a G-code\n";

std::string full_help(std::string_view units_line) {
  std::string o = kOverview;
  o += "commands (one per line; answers: ok [data] | error: <code> <message>):\n";
  if (!units_line.empty()) o += std::string(units_line) + "\n";
  for (const CommandSpec& e : kCommands) o += entry_line(e);
  o += "realtime characters (act at once, never part of a line):\n";
  for (const CodeSpec& r : kRealtime) o += "  " + pad(r.code, 32) + r.help + "\n";
  o += "G-code:\n";
  for (const CodeSpec& g : kGcodes) o += "  " + pad(g.code, 32) + g.help + "\n";
  o += "GRBL $ commands:\n";
  for (const GrblSpec& g : kGrblCommands) o += "  " + pad(g.usage, 32) + g.help + (g.query ? " [query]" : "") + "\n";
  return o;
}

}  // namespace

bool help_text(std::string_view topic, std::string_view units_line, std::string& out) {
  for (const CommandAlias& a : kCommandAliases)
    if (ieq(topic, a.alias)) topic = a.name;  // `help exit` is `help quit`
  if (topic.empty()) {
    out += full_help(units_line);
    return true;
  }
  // A command name (or its first word: `help home` is home and home zero): its entries in full.
  bool any = false;
  for (const CommandSpec& e : kCommands) {
    const std::string_view name(e.name);
    if (!ieq(name, topic) && !ieq(name.substr(0, name.find(' ')), topic)) continue;
    out += entry_line(e);
    if (*e.details) out += std::string(34, ' ') + e.details + "\n";
    any = true;
  }
  if (any) return true;
  // Anything else (a G-code, a word): the lines of the full help that mention it.
  const std::string h = full_help(units_line);
  std::size_t pos = 0;
  while (pos < h.size()) {
    const std::size_t e = h.find('\n', pos);
    const std::string_view line = std::string_view(h).substr(pos, e - pos);
    if (line.find(topic) != std::string_view::npos) {
      out += line;
      out += '\n';
      any = true;
    }
    pos = e + 1;
  }
  return any;
}

// ---------------------------------------------------------------------------
// The reference page section
// ---------------------------------------------------------------------------

namespace {

constexpr const char* kBegin =
    "<!-- BEGIN console-reference: generated by `armctl console --reference` from the command table in "
    "firmware/lang/include/servoarm/lang/command_table.hpp. Do not edit by hand: change the table, then "
    "regenerate (see above). -->";
constexpr const char* kEnd = "<!-- END console-reference -->";


}  // namespace

std::string console_reference_markdown() {
  std::string o = std::string(kBegin) + "\n\n### Commands\n\n";
  o += "Lengths are in the length unit and angles in the angle unit in use (`help` and `status` say which; "
       "joint values: the angle unit for revolute joints, the length unit for prismatic ones). "
       "A query never changes the arm's state.\n\n";
  o += "| command | what it does | query |\n| --- | --- | --- |\n";
  for (const CommandSpec& e : kCommands) {
    std::string what = e.help;
    if (*e.details) what += "; " + std::string(e.details);
    o += "| `" + md_cell(e.usage) + "` | " + md_cell(what) + " | " + (e.query ? "yes" : "") + " |\n";
  }
  o += "\n### Realtime characters\n\nThey act at once and are never part of a line.\n\n"
       "| character | effect |\n| --- | --- |\n";
  for (const CodeSpec& r : kRealtime) o += "| `" + md_cell(r.code) + "` | " + md_cell(r.help) + " |\n";
  o += "\n### G-code\n\n| code | effect |\n| --- | --- |\n";
  for (const CodeSpec& g : kGcodes) o += "| `" + md_cell(g.code) + "` | " + md_cell(g.help) + " |\n";
  o += "\n### GRBL $ commands\n\n| command | what it does | query |\n| --- | --- | --- |\n";
  for (const GrblSpec& g : kGrblCommands)
    o += "| `" + md_cell(g.usage) + "` | " + md_cell(g.help) + " | " + (g.query ? "yes" : "") + " |\n";
  o += std::string("\n") + kEnd + "\n";
  return o;
}

std::string console_reference_mismatch(const std::string& page) {
  return generated_section_mismatch(
      page, console_reference_markdown(),
      {"<!-- BEGIN console-reference", kEnd, "docs/console.md differs from armctl console --reference",
       "regenerate the section: see \"Regenerating the reference\" in docs/console.md (armctl console --reference)"});
}

}  // namespace servoarm::fw
