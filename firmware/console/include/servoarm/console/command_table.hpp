#pragma once
// The console's command table: every command of the line language declared once
// (name, Cmd, argument shape, usage, help, query). parse_line() dispatches on it,
// `help` / `help <topic>` print it, and the command reference of docs/console.md is
// generated from it (console_reference_markdown(), printed by `armctl console
// --reference`; tests/console/test_command_table.cpp fails with the diff when the
// committed page differs). To add a command: a Cmd value, a row here, its action in
// Console::execute, then regenerate the page (docs/console.md says how).
//
// Units: usage and help say "length" and "angle" units; the console states which
// ones are in use (ConsoleUnits) at the top of `help` and in `status`.
#include <cstdint>
#include <string>
#include <string_view>

#include "servoarm/console/commands.hpp"

namespace servoarm::fw {

/// How parse_line reads a command's arguments.
enum class ArgShape : std::uint8_t {
  none,          ///< no arguments
  topic,         ///< at most one word (help)
  joints_speed,  ///< exactly n joint values, then [speed=percent] (movej)
  pose_speed,    ///< x y z [rx ry rz], then [speed=length/s] (movel)
  pose,          ///< x y z [rx ry rz], no options (ik)
  joints_opt,    ///< nothing or exactly n joint values (fk)
};
const char* to_string(ArgShape a);

struct CommandSpec {
  const char* name;     ///< one word, or two ("home zero": matched before "home")
  Cmd cmd;
  ArgShape args;
  const char* usage;    ///< one line: name and arguments
  const char* help;     ///< one line for `help`
  const char* details;  ///< more for `help <topic>` and the reference page ("" = none)
  bool query;           ///< never changes the arm's state (answers only)
};

inline constexpr CommandSpec kCommands[] = {
    {"help", Cmd::help, ArgShape::topic, "help [topic]", "this text, or the entries about one topic", "", true},
    {"status", Cmd::status, ArgShape::none, "status", "state, queue, joints, tool pose (and the units they are in)",
     "answers `ok state=idle queue=0 joints=[...] <joint units> pose=[x= y= z= rx= ry= rz=] <length>,<angle> "
     "[fault=\"...\"]`",
     true},
    {"enable", Cmd::enable, ArgShape::none, "enable", "power the drives up",
     "answers when every drive is operation enabled, sends position feedback younger than "
     "`safety.feedback_timeout_ms` and a heartbeat within its consumer time (`bus.heartbeat_timeout_ms`); a drive "
     "that has gone silent answers `error: fault enable failed: joint 3 feedback_invalid: ...` (or `heartbeat_lost`) "
     "and nothing is powered",
     false},
    {"disable", Cmd::disable, ArgShape::none, "disable", "power the drives down (while moving: stops first)",
     "drops every queued move, also one queued in the same cycle", false},
    {"home", Cmd::home, ArgShape::none, "home", "joint move to the home pose (motion.home_deg)", "", false},
    {"home zero", Cmd::home_zero, ArgShape::none, "home zero",
     "(disabled arm) the current joint positions become joint zero until restart",
     "homing on the current position, for incremental encoders: the master moves each joint's zero offset in its "
     "scaling; the drives are not written to. Answers `ok zero_offset = [c1, ...]` (drive counts at the new zero, "
     "for the config file). Refused while powered (`error: bad_state`), or when 0 is outside a joint's limits",
     false},
    {"movej", Cmd::movej, ArgShape::joints_speed, "movej j1..jn [speed=%]",
     "joint move; joints in the joint units; speed 1-100 % of the joint limits (default 50)",
     "answers `ok queued id=N duration=T` once the move is checked and queued", false},
    {"movel", Cmd::movel, ArgShape::pose_speed, "movel x y z [rx ry rz] [speed=v]",
     "straight line of the tool point; without rx ry rz the tool keeps its orientation",
     "x y z in the length unit, rx ry rz in the angle unit as fixed-axis roll-pitch-yaw R = Rz(rz) Ry(ry) Rx(rx), "
     "speed in length units/s (default motion.linear_speed_mm_s, at most motion.max_linear_speed_mm_s); refused "
     "before moving with the reason (`unreachable`, `limits`, `singular`, `branch`) and where on the line",
     false},
    {"stop", Cmd::stop, ArgShape::none, "stop", "ramp down and drop the queued moves",
     "drops every queued move, in any state (`ok not moving; 1 queued move dropped` when a move queued in the same "
     "cycle had not started yet)",
     false},
    {"estop", Cmd::estop, ArgShape::none, "estop", "emergency stop (quick stop, drives off, latched); then reset + enable",
     "", false},
    {"reset", Cmd::reset, ArgShape::none, "reset", "clear a fault / e-stop (drives stay disabled)", "", false},
    {"fk", Cmd::fk, ArgShape::joints_opt, "fk [j1..jn]", "tool pose of the given (or current) joints", "", true},
    {"ik", Cmd::ik, ArgShape::pose, "ik x y z [rx ry rz]", "joints for a tool pose, nearest to the current joints",
     "the nearest solution within the joint limits, and how many solutions exist", true},
    {"limits", Cmd::limits, ArgShape::none, "limits", "joint limits and speeds", "", true},
    {"stats", Cmd::stats, ArgShape::none, "stats", "control-loop statistics (cycles, overruns, latency, compute)",
     "`cycles overruns rate_hz latency_us={min mean p99 max} compute_us={...} max_following_error_deg "
     "[estop_latency_us] [events_dropped] [output_dropped_lines output_dropped_bytes]`; takes no argument (`stats "
     "zero` is refused: a query never changes state)",
     true},
    {"config", Cmd::config, ArgShape::none, "config", "effective configuration (TOML)", "", true},
    {"wait", Cmd::wait, ArgShape::none, "wait", "answer when every queued move has finished (or with the fault)", "",
     false},
    {"hold", Cmd::hold, ArgShape::none, "hold", "feed hold (same as !)",
     "with moves queued but not started yet, holds the queue (GRBL Hold: `?` says `Hold`); `resume` runs it, "
     "`stop` drops it",
     false},
    {"resume", Cmd::resume, ArgShape::none, "resume", "resume after a feed hold (same as ~)", "", false},
};

/// The table entry of `cmd`, nullptr for the kinds no command word names (none,
/// dwell, position, gmove, temperature: G-code only).
const CommandSpec* find_command(Cmd cmd);

/// `help` (topic empty) or `help <topic>`: the entry named `topic` (with its
/// details), else every entry and G-code line mentioning it. False: nothing
/// about the topic (out untouched). `units_line` is printed first in `help`.
bool help_text(std::string_view topic, std::string_view units_line, std::string& out);

/// The command reference section of docs/console.md, markers included
/// (printed by `armctl console --reference`).
std::string console_reference_markdown();
/// "" when `page` holds exactly console_reference_markdown() between its
/// markers; else what differs (a line diff) and how to regenerate.
std::string console_reference_mismatch(const std::string& page);

}  // namespace servoarm::fw
