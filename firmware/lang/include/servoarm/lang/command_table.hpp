// SPDX-License-Identifier: Apache-2.0
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

#include "servoarm/lang/commands.hpp"

namespace servoarm::fw {

/// How parse_line reads a command's arguments.
enum class ArgShape : std::uint8_t {
  none,          ///< no arguments
  topic,         ///< at most one word (help)
  joints_speed,  ///< exactly n joint values, then [speed=percent] (movej)
  pose_speed,    ///< x y z [rx ry rz], then [speed=length/s] (movel)
  pose,          ///< x y z [rx ry rz], no options (ik)
  joints_opt,    ///< nothing or exactly n joint values (fk)
  jog,           ///< nothing, `stop`, or <axis> <+v, -v, + or ->, then [speed=%] [frame=base, tool or user] (jog)
  tool,          ///< nothing, NAME, `delete NAME`, or NAME x y z rx ry rz [mass=kg] [com=x,y,z] [radius=r] (tool)
  frame,         ///< nothing, NAME, `delete NAME`, or NAME x y z rx ry rz (frame)
  joint_word,    ///< nothing or one joint jN (home)
  point_name,    ///< exactly one teach point name (teach, point delete)
  program_name,  ///< exactly one program name (run)
  record,        ///< `start [rate=Hz]` or `stop NAME [tolerance=angle]`
  output,        ///< nothing (list) or NAME on|off (out)
  confirm,       ///< nothing or the word `confirm` (safety normal)
  rest,          ///< the rest of the line as typed, at least one character (safety stage)
  checksum,      ///< exactly 8 hex digits (safety confirm)
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
    {"help", Cmd::help, ArgShape::topic, "help [topic]",
     "an overview and every command in a line, or `help CMD`: one command (or G-code) in full", "", true},
    {"quit", Cmd::quit, ArgShape::none, "quit (or exit)",
     "end this console session (also `exit`; Ctrl-D, end of input, does the same on stdin and in `armctl console`)",
     "answers `ok bye`; lines sent after it are not run (each answered `error: bad_state '...' not executed`). "
     "On stdin armfw then ends as at end of input (every line before `quit` answered); on a pty, a serial line or the CAN console only that client's session ends: a jog it runs stops, its "
     "G-code modes and check mode start afresh, and armfw goes on serving it and every other client. `armctl "
     "console` sends it, prints the answer and ends. Queued moves are not stopped (`stop` does that)",
     false},
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
    {"home", Cmd::home, ArgShape::joint_word, "home [jN]",
     "homing cycle: every joint, group after group of homing.order (or joint N alone); `wait` answers when it ends",
     "answers `ok homing: group 1 of 4 (joint 3)` at once; progress comes as `homing: joint 3 homing (group 1 of 4, "
     "cia402)`, `homing: joint 3 homed`, `homing: homing done: every joint homed` lines. Needs the arm enabled and "
     "idle. `stop`, `!` and Ctrl-X abort it (the joints being homed stay unhomed; Ctrl-X is an e-stop); a joint that "
     "fails (switch never found, timeout, drive refused) disables the arm: `alarm: fault joint 3 (node 3): homing "
     "timeout ...`. Joints with drive.homing.method = \"none\" (absolute encoders) are homed at power-up; until every "
     "joint is homed, Cartesian moves, tool jogs, movej, park and G-code moves are refused (`error: not_homed` naming "
     "the joints) and joint jogs run at homing.unhomed_jog_pct of their speed. `status` shows each joint's homing",
     false},
    {"home zero", Cmd::home_zero, ArgShape::none, "home zero",
     "(disabled arm) the current joint positions become joint zero until restart",
     "homing on the current position, for incremental encoders: the master moves each joint's zero offset in its "
     "scaling; the drives are not written to. Answers `ok zero_offset = [c1, ...]` (drive counts at the new zero, "
     "for the config file). Refused while powered (`error: bad_state`), or when 0 is outside a joint's limits. The "
     "joints count as homed afterwards (until restart)",
     false},
    {"park", Cmd::park, ArgShape::none, "park", "joint move to the park pose (motion.home_deg; G28)",
     "as `movej` to motion.home_deg at motion.joint_speed_pct; refused until every joint is homed", false},
    {"movej", Cmd::movej, ArgShape::joints_speed, "movej j1..jn or @NAME [speed=%] [blend=angle]",
     "joint move; joints in the joint units, or teach point NAME's joints; speed 1-100 % of the joint limits (default 50)",
     "answers `ok queued id=N duration=T` (the exact-stop duration; ` blend=τs` when it blends out of the move "
     "before) once the move is checked and queued. blend= (angle unit, >= 0, joint-space distance; default "
     "motion.default_blend_deg) is the tolerance the arm may pass the target by when the next move follows: the "
     "corner is blended without stopping, within every joint's limits, or is an exact stop when it cannot. A typed "
     "movej blends into a following joint move; into a line only in a program, or after a blended line "
     "(docs/motion.md#blending)", false},
    {"movel", Cmd::movel, ArgShape::pose_speed, "movel x y z [rx ry rz] or @NAME [speed=v] [blend=length]",
     "straight line of the tool point; without rx ry rz the tool keeps its orientation; @NAME: to where teach point "
     "NAME's joints put the active tool",
     "x y z in the length unit, rx ry rz in the angle unit as fixed-axis roll-pitch-yaw R = Rz(rz) Ry(ry) Rx(rx), "
     "speed in length units/s (default motion.linear_speed_mm_s, at most motion.max_linear_speed_mm_s); refused "
     "before moving with the reason (`unreachable`, `limits`, `singular`, `branch`) and where on the line. blend= "
     "(length unit, >= 0, tool-point distance; default motion.default_blend_mm): pass the target within it into the "
     "next line or joint move, the corner checked like the line (every joint's limits, the tool speed, IK) or an "
     "exact stop (docs/motion.md#blending)",
     false},
    {"stop", Cmd::stop, ArgShape::none, "stop", "ramp down and drop the queued moves",
     "drops every queued move, in any state (`ok not moving; 1 queued move dropped` when a move queued in the same "
     "cycle had not started yet)",
     false},
    {"estop", Cmd::estop, ArgShape::none, "estop", "emergency stop (quick stop, drives off, latched); then reset + enable",
     "", false},
    {"reset", Cmd::reset, ArgShape::none, "reset", "clear a fault / e-stop (drives stay disabled; MIT motors hold the arm until enable)", "", false},
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
    {"wait", Cmd::wait, ArgShape::none, "wait", "answer when every queued move has finished (or with the fault)",
     "while a program runs: when it has ended (or is paused)", false},
    {"hold", Cmd::hold, ArgShape::none, "hold", "feed hold (same as !)",
     "with moves queued but not started yet, holds the queue (GRBL Hold: `?` says `Hold`); `resume` runs it, "
     "`stop` drops it",
     false},
    {"resume", Cmd::resume, ArgShape::none, "resume", "resume after a feed hold (same as ~); sent while the hold still ramps down, the move resumes once the arm is at rest", "", false},
    {"jog", Cmd::jog, ArgShape::jog, "jog <axis> <+v, -v, + or -> [speed=%] [frame=base, tool or user]; jog stop; jog",
     "jog a joint (j1..jn) or the tool (x y z rx ry rz) by v, or continuously (+ / -); `jog` alone keeps a "
     "continuous jog alive, `jog stop` ends it",
     "a continuous jog stops by itself unless a jog line comes within console.jog_deadman_ms (the sender's "
     "keep-alive); lines streamed back to back retarget the running jog without stopping. speed: percent of the "
     "joint limits (joint jog, default console.jog_speed_pct) or of motion.max_linear_speed_mm_s and the angular "
     "limit (tool jog). frame: the base's axes, the tool's as they were when the jog started, or the active user "
     "frame's (`frame`; default base); the point moved is the active tool's (`tool`). At "
     "a joint limit a jog stops on the limit (`alarm: jog stopped: joint 3 at its limit`); near a singularity a "
     "tool jog slows, then stops and says which joint. Refused (`error: busy`) while a move runs",
     false},
    {"tool", Cmd::tool, ArgShape::tool, "tool [NAME [x y z rx ry rz [mass=kg] [com=x,y,z] [radius=r]]]; tool delete NAME",
     "tools (TCP offsets from the flange): list, select NAME, define NAME, delete NAME; tool0 is the flange",
     "`tool` lists them (`*` marks the active one); `tool NAME` selects one: Cartesian moves, jogs, fk, ik, "
     "status, M114 and the GRBL report then use its tool point; `tool NAME x y z rx ry rz` defines (or redefines) "
     "one: the tool point and orientation in the flange frame, in the length and angle units (payload: mass= in "
     "kg, com= x,y,z in the length unit, kept for dynamics; radius= in the length unit: the safety envelope's "
     "sphere around this tool point, else safety.tool_radius_mm; a radius that does not fit a keep-in box, or "
     "puts the park pose outside the envelope, is refused). Definitions and the selection are kept in the frames "
     "file (console.frames_file), written atomically; a definition that cannot be saved is not made. Refused "
     "while the arm moves, jogs or has moves queued (`error: bad_state`)",
     false},
    {"frame", Cmd::frame, ArgShape::frame, "frame [NAME [x y z rx ry rz]]; frame delete NAME",
     "user frames (work objects): list, select NAME, define NAME, delete NAME; base is the base frame",
     "a user frame is a pose in the base frame; with one selected, Cartesian targets (movel, ik, G0/G1, $J=) are "
     "in it and poses (fk, status, M114, the GRBL report) are reported in it. G54..G59 select the frames g54..g59 "
     "(identity until set), `G10 L2 Pn X.. Y.. Z.. A.. B.. C..` sets g5(3+n) (P0: the active one; axes not given "
     "are kept). Kept in the frames file like the tools; refused while the arm moves, jogs or has moves queued",
     false},
    {"teach", Cmd::teach, ArgShape::point_name, "teach NAME",
     "store where the arm is as teach point NAME: its joints, the tool pose, the active tool and frame",
     "the measured joints of a homed arm at rest (idle or disabled; refused while it moves, jogs or has moves queued); "
     "a point of that name is replaced. Points are kept in the points file (programs.points_file, next to the "
     "configuration; `armfw --points FILE`), written atomically: a point that cannot be saved is not made (`error: "
     "storage`, the old file kept). Answers `ok taught NAME joints=[...] pose=[...] tool=T frame=F`. Names: letters, "
     "digits, _ and -, starting with a letter, at most 31",
     false},
    {"points", Cmd::points, ArgShape::none, "points", "list the teach points (`movej @NAME`, `movel @NAME`)",
     "one line per point `NAME joints=[...] pose=[...] tool=T frame=F` (joints in the joint units, the pose in the "
     "base frame), then `ok N points`",
     true},
    {"point delete", Cmd::point_delete, ArgShape::point_name, "point delete NAME", "delete teach point NAME",
     "saved at once (as teach); `error: bad_option` when there is none of that name", false},
    {"programs", Cmd::programs, ArgShape::none, "programs", "list the program files of programs.dir",
     "native `.arm` and G-code `.gcode .nc .ngc .gc` files, one per line, then `ok N programs in DIR`", true},
    {"run", Cmd::run, ArgShape::program_name, "run NAME",
     "check the whole program NAME (of programs.dir), then run it; nothing moves if a line is bad",
     "every line parsed, every move planned and checked from the pose the previous line leaves (the console's own "
     "check: the one `$C` check mode makes); the first bad line is answered `error: program FILE:LINE: reason` and "
     "nothing moves. Needs an enabled, homed arm at rest with nothing queued (`error: not_homed` naming the joints). "
     "The check runs in slices of about 2 ms, every console served between two (a long program never holds up `?` or "
     "Ctrl-X; `stop`, `estop`, `disable`, Ctrl-X end the check: `error: program run: NAME: check interrupted by stop`); "
     "answers `ok running NAME: N steps` when the check has ended and the program starts (refused if the arm moved "
     "meanwhile); progress comes as `program: ...` lines (`program: NAME done`, "
     "`program: NAME aborted at FILE:LINE: reason`). The program's moves are fed to the motion queue from the console "
     "thread, one ahead of the running one. `stop`, `abort`, `disable`, an e-stop or a fault end the program (the "
     "rest is dropped); nothing resumes by itself after a restart. In check mode (`$C`) `run` checks only",
     false},
    {"pause", Cmd::pause, ArgShape::none, "pause",
     "pause the running program at the end of the moves handed to the controller (`!`: feed hold at once)",
     "no further line is fed; the arm finishes the running move and the one queued behind it, then the program is "
     "`paused` at its next line. `!` holds at once (on the path, the program paused too); `resume` (or `~`) goes on, "
     "`step` runs one more motion, `abort` ends it",
     false},
    {"step", Cmd::step, ArgShape::none, "step", "run the paused program's next motion (and the lines before it), then pause",
     "after `!` with a move held: that move (and one queued behind it) is finished first", false},
    {"abort", Cmd::abort, ArgShape::none, "abort", "end the running program: ramp down and drop its queued moves",
     "answers `ok aborted NAME at FILE:LINE`; as `stop` when no program runs", false},
    {"record", Cmd::record, ArgShape::record, "record start [rate=Hz]; record stop NAME [tolerance=angle]; record mcap [rate=Hz]; record mcap stop",
     "record the joints while jogging; `record stop NAME` writes program NAME.arm of blended joint moves; `record mcap` writes an MCAP file",
     "start samples the measured joints at rate= Hz (default 50, 1..100: on the console thread; at most 100 000 samples); stop writes "
     "NAME.arm in programs.dir (atomically; an existing program of that name is replaced): the recorded path "
     "decimated (Douglas-Peucker in joint space) so that the joint-space path of the moves, and each blend "
     "(blend= half the tolerance), stay within tolerance= (angle unit, default 0.5 deg) of the recorded path. "
     "Answers `ok recorded NAME.arm: N moves from M samples`. `record mcap [rate=Hz]` records the telemetry (every "
     "control cycle at rate= the control rate; default record.rate_hz), the setpoints, the events and the robot "
     "description into an MCAP file in record.dir (docs/foxglove-mcap.md); `record mcap stop` closes it and answers its "
     "files, frames and missed cycles",
     false},
    {"freedrive on", Cmd::freedrive_on, ArgShape::none, "freedrive on",
     "hand guiding: every drive in torque mode (CST) holding the arm against gravity and friction; push it",
     "needs an enabled, homed arm at rest with nothing queued, the robot's inertial data and drives with torque mode "
     "([dynamics] freedrive = true maps it): refused otherwise naming the joint or the model (`error: bad_state "
     "freedrive refused: joint 2: the drive has no cyclic synchronous torque mode ...`). No setpoints are sent "
     "meanwhile; `record` and `teach` read where the arm is; moves are refused. A fault, a lost heartbeat, `stop`, "
     "`!`, `disable` or `estop` end it as `freedrive off` does (then their own reaction). Collision detection is off "
     "during free-drive and starts again afresh after it",
     false},
    {"freedrive off", Cmd::freedrive_off, ArgShape::none, "freedrive off",
     "end hand guiding: back to position mode holding where the arm stands (within one cycle)",
     "answers at once (`ok free-drive off: holding where it stands`); every drive shows CSP again one to three cycles "
     "later, then the arm is idle with the setpoint at the measured pose", false},
    {"freedrive", Cmd::freedrive, ArgShape::none, "freedrive",
     "free-drive, feed-forward and collision detection: what runs, or why not",
     "`freedrive=off|entering|active|leaving feed_forward=off|velocity|torque collision=on|off peak=R joint=J "
     "alarms=N` and, for each part the configuration asks for that cannot run, its reason", true},
    {"collision on", Cmd::collision_on, ArgShape::none, "collision on",
     "collision detection on (the configuration's dynamics.collision sets it at start)",
     "refused with the reason when it cannot run (`error: bad_state collision detection unavailable: joint 2: the "
     "drive reports no torque ...`); the observer starts afresh", false},
    {"collision off", Cmd::collision_off, ArgShape::none, "collision off",
     "collision detection off: to move the arm clear of what it hit (it is still pressed against it: detected again "
     "at once otherwise), then `collision on`", "", false},
    {"safety normal", Cmd::safety_normal, ArgShape::confirm, "safety normal [confirm]",
     "the safety envelope's Normal limits ([safety], docs/safety.md); from Reduced only with `confirm`",
     "the moves planned from now on and the control thread's monitor (from its next cycle) use them. From Reduced "
     "mode this loosens the limits: refused without the word `confirm` (`error: bad_state Reduced -> Normal loosens "
     "the safety limits: confirm it ...`, the mode kept); the API's safety_mode asks the same (confirm=true). "
     "Refused (`error: bad_state no safety envelope is configured ...`) without [safety]", false},
    {"safety reduced", Cmd::safety_reduced, ArgShape::none, "safety reduced",
     "the safety envelope's Reduced limits (safety.reduced_*: TCP and elbow speed, orientation cone)",
     "as `safety normal`, but never needs a confirmation (a stricter mode is always allowed); a move faster than the "
     "Reduced TCP speed limit is refused at plan time", false},
    {"safety stage", Cmd::safety_stage, ArgShape::rest, "safety stage KEY = VALUE[; KEY = VALUE ...]",
     "stage a run-time change of the [safety] section: checked, nothing changes until `safety confirm`",
     "the rest of the line is the change as TOML `key = value` pairs (`;` between, `safety.` optional; the line's "
     "200 characters at most), checked through the configuration's key table against the robot (as at load; keys "
     "that act at start only are refused). Answers `ok staged checksum=XXXXXXXX previous=YYYYYYYY expires_s=60 "
     "changes: KEY = OLD -> NEW; ...; confirm with: safety confirm XXXXXXXX`; nothing changes yet. The service call "
     "of the API's safety_stage (docs/safety.md#confirming-a-change)", false},
    {"safety confirm", Cmd::safety_confirm, ArgShape::checksum, "safety confirm XXXXXXXX",
     "apply the staged [safety] change: its checksum (as `safety stage` answered it), in time, with the arm at rest",
     "answers `ok safety configuration XXXXXXXX in force (was YYYYYYYY): CHANGES`; the monitor takes it at its next "
     "cycle, `status`, `safety` and the API's hello show the new checksum and an event says old -> new. Refused in "
     "one line: nothing staged, another checksum or an expired one (the staged change is then dropped), the arm not "
     "at rest (the change stays staged). The service call of the API's safety_confirm", false},
    {"safety", Cmd::safety, ArgShape::none, "safety",
     "the safety envelope: on or off, the mode, the configuration's checksum and the stops it made",
     "`safety=on mode=normal|reduced checksum=XXXXXXXX stops=N [zone=reduced_plane_K] speed_scale=S tool=NAME tool_radius_mm=R` "
     "then the limits in force (`safety=off` without [safety]); not a safety-rated function: docs/safety.md", true},
    {"out", Cmd::out, ArgShape::output, "out [NAME on/off]",
     "digital output NAME ([[output]]: a drive's 60FEh:01 bit) on or off at once; `out` lists them",
     "sent to the drive with the next control cycle's PDOs (M64 / M65 P<n> the same, n the output's index in "
     "[[output]] order; M62 / M63 P<n>: at the start of the next move, in the cycle it starts). `out` lists "
     "`NAME node=N bit=B on|off` then `ok N outputs`. In a program, `out` / M64 / M65 act once the moves before "
     "them have finished (the gripper never switches mid-move); M62 / M63 ride with the next move",
     false},
};

/// Other names of commands: the parser reads `alias` as the entry `name`; `help`, `help
/// alias` and the reference page name both.
struct CommandAlias {
  const char* alias;
  const char* name;
};
inline constexpr CommandAlias kCommandAliases[] = {
    {"exit", "quit"},
};

/// GRBL '$' commands (both dialects; the GRBL dialect's `help` is `$`). `word` is what
/// follows the '$' (`J=` takes G-code words after it).
struct GrblSpec {
  const char* word;
  Cmd cmd;
  const char* usage;
  const char* help;
  bool query;
};
inline constexpr GrblSpec kGrblCommands[] = {
    {"", Cmd::grbl_help, "$", "GRBL help: the $ commands", true},
    {"$", Cmd::grbl_settings, "$$", "settings as `$N=value` (the GRBL numbers that mean something here, read-only)", true},
    {"#", Cmd::grbl_params, "$#", "coordinate offsets `[G54:x,y,z]`...", true},
    {"G", Cmd::grbl_state, "$G", "parser state `[GC:G1 G54 G17 G21 G90 G94 M5 M9 T0 F.. S0]`", true},
    {"I", Cmd::grbl_info, "$I", "build info `[VER:1.1h.servoarm:<robot>]` `[OPT:V,<blocks>,<rx bytes>]`", true},
    {"X", Cmd::grbl_unlock, "$X", "unlock: reset a fault / e-stop and enable the drives", false},
    {"H", Cmd::grbl_home, "$H", "homing cycle (as `home`; answers ok when it has ended, state `Home` meanwhile; a "
     "failure raises ALARM:9)", false},
    {"C", Cmd::grbl_check, "$C", "check mode on/off: G-code is parsed and its moves planned and checked, nothing moves; "
     "`run NAME` then checks the whole program only; a check changes nothing: `teach`, `point delete`, `record` "
     "are checked and answered, no point, points file or program file is written", false},
    {"J=", Cmd::grbl_jog, "$J=[G90 or G91] [G20 or G21] [G53] X.. Y.. Z.. [A B C] F..",
     "jog the tool point in the active user frame, G53: the base frame (G91 incremental, G90 absolute; F required, "
     "in G20/G21 units per minute); "
     "jog lines run back to back without stopping; 0x85 cancels",
     false},
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
