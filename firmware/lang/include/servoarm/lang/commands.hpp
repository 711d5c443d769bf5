// SPDX-License-Identifier: Apache-2.0
#pragma once
// The console command language: one line in, one Command out. Pure: no I/O, no
// clock, no allocation; the only state is the G-code modal state passed in,
// which changes only when the line parses.
//
// Units on the console (stated in `help`, units.hpp): the robot description's
// (mm or m, deg or rad): joint values in the angle unit (revolute) or the length
// unit (prismatic); positions in the length unit; orientations rx ry rz in the
// angle unit as fixed-axis roll-pitch-yaw: R = Rz(rz) * Ry(ry) * Rx(rx). The
// parser keeps the values as typed; the console converts them (ConsoleUnits).
// G-code X Y Z follow G20/G21 (inches/mm; the parser converts them to mm), A B C
// are rx ry rz in degrees, F is in G20/G21 length units per minute.
#include <array>
#include <cstdint>
#include <string_view>

#include "servoarm/lang/units.hpp"
#include "servoarm/kinematics/types.hpp"

namespace servoarm::fw {

/// Longest accepted line (characters, without the newline).
inline constexpr std::size_t kMaxLine = 200;
/// Slowest accepted speeds (every front end: movel speed=, G-code F, the configuration):
/// slower moves would practically never end (the console also caps a move's duration).
inline constexpr double kMinLinearSpeedMmS = 0.01;  ///< mm/s (G-code F: 0.6 mm/min)
inline constexpr double kMinJointSpeedPct = 1.0;    ///< movej speed=, percent (the planner's override floor, 0.01)

enum class CmdError : std::uint8_t {
  ok,
  overlong,          ///< line longer than kMaxLine
  binary,            ///< control or non-ASCII bytes in the line
  unknown_command,   ///< first word is no command / G-code
  arg_count,         ///< wrong number of arguments
  bad_number,        ///< an argument is not a decimal number
  not_finite,        ///< NaN / Inf / overflow
  bad_option,        ///< unknown key=value option or malformed option
  out_of_range,      ///< a value outside its allowed range (e.g. speed <= 0)
  unsupported,       ///< a G/M code or word this firmware does not implement
  checksum,          ///< G-code line checksum (*nn) does not match
  // Errors the console (not the parser) reports, listed here so every `error:` code has one home.
  busy,              ///< motion queue full: the command was NOT queued
  bad_state,         ///< not allowed in the current state
  fault,             ///< arm in fault / e-stop: reset first
  unreachable,       ///< target outside the workspace / no IK solution
  limits,            ///< target or path outside the joint limits
  singular,          ///< path too close to a singularity
  branch,            ///< path changes IK branch
  plan_failed,       ///< planner refused (message says why)
  timeout,           ///< control thread did not answer in time
  estop,             ///< line dropped, not executed: an e-stop (Ctrl-X) arrived before it ran
  storage,           ///< a file could not be written (the frames file): nothing changed, the old file kept
  not_homed,         ///< refused: a joint is not homed (message names them): `home` first
  program,           ///< a program refused before it ran (file:line: reason), or aborted (the line named)
  internal,          ///< should not happen (message says what)
};
const char* to_string(CmdError e);

enum class Cmd : std::uint8_t {
  none,      ///< empty line / comment / modal-only G-code: answer ok, do nothing
  help, status, enable, disable, home, movej, movel, stop, estop, reset, fk, ik, limits, stats, config, wait,
  hold,      ///< feed hold (also realtime '!')
  resume,    ///< resume after feed hold (also realtime '~')
  dwell,     ///< G4
  position,  ///< M114
  gmove,     ///< G0/G1 (axes in `axis_mask`, values in vals[0..5])
  home_zero, ///< `home zero`: the current joint positions become joint zero (arm disabled)
  park,      ///< `park` / G28: joint move to the park pose (motion.home_deg); `home` is the homing cycle
  temperature,  ///< M105 (senders poll it): answers ok T:0 /0
  jog,       ///< `jog ...` (JogOp in Command::jog_op); GRBL `$J=` is grbl_jog
  tool,      ///< `tool [NAME [x y z rx ry rz [mass= com=]]]`, `tool delete NAME` (FrameOp in frame_op)
  frame,     ///< `frame ...` likewise; G54..G59 select g54..g59; G10 L2 Pn sets one (frame_op set_axes)
  // GRBL '$' commands (the GRBL dialect's, accepted in both dialects)
  grbl_jog,       ///< $J=<G-code words> (axes in axis_mask / vals, relative, speed from F: required)
  grbl_settings,  ///< $$
  grbl_params,    ///< $#
  grbl_state,     ///< $G
  grbl_info,      ///< $I
  grbl_unlock,    ///< $X
  grbl_home,      ///< $H
  grbl_check,     ///< $C
  grbl_help,      ///< $
  // Teach points and programs (the console's program runner, console.hpp)
  teach,          ///< `teach NAME`: store the current joints (and tool pose) as point NAME
  points,         ///< `points`: list the teach points
  point_delete,   ///< `point delete NAME`
  programs,       ///< `programs`: list the program files of programs.dir
  run,            ///< `run NAME`: check the whole program, then run it (in check mode: check only)
  pause,          ///< `pause`: feed hold, the program stops feeding moves (`pause !`: the same at once)
  step,           ///< `step`: run the program's next motion, then pause
  abort,          ///< `abort`: stop the arm and end the program
  record,         ///< `record start [rate=Hz]` / `record stop NAME [tolerance=deg]`
  out,            ///< `out [NAME on|off]`; M62/M63 P<n> (at the next move's start), M64/M65 P<n> (at once)
  // Hand guiding (ModelControl)
  freedrive,      ///< `freedrive`: free-drive, feed-forward and collision detection state (query)
  freedrive_on,   ///< `freedrive on`: the drives to torque mode, gravity compensated; the arm moves when pushed
  freedrive_off,  ///< `freedrive off`: back to position mode, holding where it stands
  collision_on,   ///< `collision on`: collision detection on (when available)
  collision_off,  ///< `collision off`: collision detection off (to move clear of what the arm hit)
  safety,         ///< `safety`: the safety envelope's mode, checksum and stops (query)
  safety_normal,  ///< `safety normal`: the envelope's Normal limits
  safety_reduced, ///< `safety reduced`: the envelope's Reduced limits
  safety_stage,   ///< `safety stage KEY = VALUE; ...`: stage a run-time change of [safety] (text)
  safety_confirm, ///< `safety confirm XXXXXXXX`: apply the staged change with that checksum
  quit,           ///< `quit` / `exit`: end this console session (the transport decides what ends: ConsoleServer)
};

/// What a `jog` line asks for.
enum class JogOp : std::uint8_t {
  keepalive,    ///< `jog` alone: refreshes a continuous jog's deadman
  stop,         ///< `jog stop`: decelerate to rest
  increment,    ///< `jog j3 +5`, `jog x -10`: by vals[0] (joint units / length / angle unit)
  continuous,   ///< `jog j3 +`, `jog rz -`: until stopped, a limit, or the deadman
};
/// The frame of a tool jog (`frame=`): the base's axes, the tool's, or the active user frame's.
enum class JogFrame : std::uint8_t { base, tool, user };
/// What a `tool` / `frame` line (or G54..G59, G10 L2) asks for.
enum class FrameOp : std::uint8_t {
  list,      ///< `tool` / `frame`: list them, the active one marked
  select,    ///< `tool NAME` / `frame NAME` / G54..G59
  define,    ///< `tool NAME x y z rx ry rz [mass=kg com=x,y,z radius=r]` / `frame NAME x y z rx ry rz`
  remove,    ///< `tool delete NAME` / `frame delete NAME`
  set_axes,  ///< G10 L2 Pn: the axes in axis_mask (vals[0..5], mm / deg) replace frame gN's; P0 = the active one
};
const char* to_string(Cmd c);

struct GcodeModal {
  bool relative = false;   ///< G91
  double unit_mm = 1.0;    ///< 1 (G21) or 25.4 (G20)
  double feed_mm_s = 0.0;  ///< last F (0 = none given yet: use the default speed)
  bool dwell_p_seconds = false;  ///< G4 P in seconds (GRBL, LinuxCNC) rather than milliseconds (RepRap)
};

struct Command {
  Cmd cmd = Cmd::none;
  int count = 0;                        ///< numbers in vals
  std::array<double, 8> vals{};         ///< as typed (console units), G-code converted to mm / deg
  bool has_speed = false;
  double speed = 0;                     ///< movej: percent (0,100]; movel: length unit/s; gmove: mm/s (from F)
  std::uint8_t axis_mask = 0;           ///< gmove: bit 0..5 = X Y Z A B C given
  bool relative = false;                ///< gmove: G91 in effect
  bool rapid = false;                   ///< gmove: G0
  bool gcode = false;                   ///< line was G-code
  bool g53 = false;                     ///< $J=: G53 (machine coordinates: the base frame, not the user frame)
  std::array<char, 16> topic{};         ///< `help <topic>`
  int home_joint = -1;                  ///< `home jN`: joint N-1; -1 = every joint, by homing.order
  // jog
  JogOp jog_op = JogOp::keepalive;
  bool jog_tool = false;                ///< tool-space axis (x y z rx ry rz) rather than a joint
  int jog_axis = 0;                     ///< joint (0-based), or 0..5 = x y z rx ry rz
  int jog_dir = 1;                      ///< continuous: +1 / -1
  JogFrame jog_frame = JogFrame::base;
  // tool / frame
  FrameOp frame_op = FrameOp::list;
  std::array<char, 24> name{};          ///< tool / frame name (checked: letters, digits, _ -)
  int g10_p = -1;                       ///< G10 L2 / L20 P: 0 = active user frame, 1..6 = g54..g59
  bool g10_l20 = false;                 ///< G10 L20: the axes given are where the tool point is now, in that frame
  bool has_mass = false;
  double mass = 0;                      ///< kg
  bool has_com = false;
  std::array<double, 3> com{};          ///< length unit, in the tool frame
  bool has_radius = false;
  double radius = 0;                    ///< length unit: the tool's safety sphere (radius=)
  // teach points and programs
  std::array<char, 64> word{};          ///< point name (teach, point delete, movej/movel @NAME) or program name (run, record stop)
  bool at_point = false;                ///< movej / movel @NAME: the target is teach point `word`
  bool has_blend = false;
  double blend = 0;                     ///< movej (angle unit) / movel (length unit) blend=: tolerance >= 0
  bool record_stop = false;             ///< record: stop (else start)
  bool record_mcap = false;             ///< record mcap: an MCAP file (record_stop: end it)
  double rate = 0;                      ///< record start rate= (Hz; 0: the default)
  double tolerance = 0;                 ///< record stop tolerance= (angle unit; 0: the default)
  int out_index = -1;                   ///< out: -1 list, -2 by name (word), >= 0 M62..M65 P
  bool out_on = false;
  bool out_sync = false;                ///< M62 / M63: at the start of the next move
  // safety
  bool confirm = false;                 ///< `safety normal confirm`: the operator confirms the looser mode
  std::uint32_t checksum = 0;           ///< `safety confirm XXXXXXXX`: the staged change's checksum
  std::array<char, kMaxLine + 1> text{};  ///< `safety stage ...`: the rest of the line as typed
};

struct ParseResult {
  CmdError error = CmdError::ok;
  /// One line naming what is wrong. Sized for the longest refusal with a 63-character name
  /// quoted; a longer one ends with "..." after a whole word (servoarm/lang/text.hpp).
  std::array<char, 192> message{};
  bool ok() const { return error == CmdError::ok; }
};

/// Parse one line (without the newline). `n_joints` sets how many values movej
/// and fk take. `modal` is updated only on success. `units`: the console's (the
/// bounds of movel's speed= are checked in them).
ParseResult parse_line(std::string_view line, int n_joints, GcodeModal& modal, Command& out,
                       const ConsoleUnits& units = {});

/// GRBL-style realtime characters, acted on as soon as they arrive (never part of a line).
inline constexpr char kRtStatus = '?';
inline constexpr char kRtHold = '!';
inline constexpr char kRtResume = '~';
inline constexpr char kRtReset = 0x18;  ///< Ctrl-X: e-stop / soft reset
inline constexpr char kRtJogCancel = static_cast<char>(0x85);  ///< GRBL jog cancel: decelerate the jog to rest
/// GRBL feed override bytes: 0x90 100 %, 0x91 +10 %, 0x92 -10 %, 0x93 +1 %, 0x94 -1 %.
inline constexpr unsigned char kRtFeed100 = 0x90, kRtFeedPlus10 = 0x91, kRtFeedMinus10 = 0x92, kRtFeedPlus1 = 0x93,
                               kRtFeedMinus1 = 0x94;
inline bool is_feed_override(char c) {
  const auto u = static_cast<unsigned char>(c);
  return u >= kRtFeed100 && u <= kRtFeedMinus1;
}
inline bool is_realtime(char c) {
  return c == kRtStatus || c == kRtHold || c == kRtResume || c == kRtReset || c == kRtJogCancel || is_feed_override(c);
}

}  // namespace servoarm::fw
