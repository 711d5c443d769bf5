// SPDX-License-Identifier: Apache-2.0
#pragma once
// Program files: the native command language (the console's, one command per
// line) and G-code (as senders write it), loaded into a flat, bounded list of steps.
//
// Native language (files NAME.arm, or any name not ending in a G-code extension):
//   every console command a program may run (movej, movel, G0/G1, home, wait, enable, ...),
//   checked by the console's own parser (fw::parse_line), so the language is exactly the
//   console's; plus, handled here because they structure a file rather than move the arm:
//     # comment, ; comment        to the end of the line (also after a command)
//     repeat N  ...  end          the lines between run N times (1 <= N <= kMaxRepeat); nests
//     call OTHER                  the lines of program OTHER (in the programs folder), as if
//                                 written here; recursion and depth > kMaxCallDepth refused
//     dwell S                     stand still S seconds (0..3600; as G4 S)
//     movej @NAME / movel @NAME   to teach point NAME (points.hpp): movej to its joints,
//                                 movel on a straight line to where its joints put the tool
//     blend=T                     on movej (deg or rad) / movel (mm or m): the tolerance the arm
//                                 may pass that target by when the next move follows (0: exact
//                                 stop; the console's units)
// G-code files (.gcode .nc .ngc .gc): lines as senders send them (the console's G-code), plus
//   G64 P<tol> (blend tolerance in mm for the following moves) and G61 (exact stop), each on a
//   line of its own; M2 / M30 end the program (later lines are not read); '%' lines skipped.
//
// Refused, with "<file>:<line>: <reason>" (nothing is half-loaded: `out` is set only when
// the whole program loads): a file larger than ProgramLimits::max_file_bytes (refused by
// its size before it is read), binary data (a NUL or another control byte), a line the
// parser refuses (unknown command, bad numbers, ...), a command no program may run (jog,
// help, $ commands, reset), `end` without `repeat`, `repeat` without `end`, recursion in
// `call`, calls nested deeper than max_call_depth, an unknown program or @point, more than
// max_steps steps once the repeats and calls are expanded. CRLF and LF line ends are both
// accepted.
//
// Set-up / console-thread code (allocates, does I/O), never on the control path.
#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include "servoarm/lang/commands.hpp"
#include "servoarm/lang/units.hpp"
#include "servoarm/kinematics/chain.hpp"
#include "servoarm/program/points.hpp"

namespace servoarm::prog {

inline constexpr int kMaxRepeat = 100000;
inline constexpr const char* kNativeExtension = ".arm";

struct ProgramLimits {
  std::size_t max_file_bytes = 4 * 1024 * 1024;  ///< per file (4 MiB: about 100 000 lines)
  std::size_t max_steps = 200000;                ///< after expansion
  int max_call_depth = 8;                        ///< call nesting
};

/// What loading needs: the arm (joint count and units for the parser and for @points) and
/// where the programs and points are.
struct ProgramContext {
  const kin::Chain* chain = nullptr;  ///< required: joint count, revolute / prismatic for @points
  fw::ConsoleUnits units{};           ///< the console's (the description's: fw::units_of(chain))
  std::string dir;                    ///< programs folder (programs.dir): where `call` looks
  const PointsData* points = nullptr; ///< teach points for @NAME (nullptr: none)
  ProgramLimits limits{};
};

/// One executable line of a loaded program.
struct ProgramStep {
  int file = 0;          ///< index into Program::files
  int line = 0;          ///< 1-based line number in that file
  std::string text;      ///< the line as given to the parser (comment stripped, @NAME replaced)
  fw::Command cmd;       ///< what the parser made of it: what the runner runs (the text is not parsed again)
  int point = -1;        ///< index into the points for movej / movel @NAME, else -1. movel @NAME:
                         ///< the target is FK(point's joints) with the active tool (cmd.vals unused)
  double blend = -1;     ///< blend tolerance of this move's target (console units: mm/m, deg/rad;
                         ///< G-code: mm, from G64 P / G61), 0 = exact stop, < 0 = none given (the
                         ///< console's configured default)
  fw::GcodeModal modal;  ///< the G-code modal state after this line (the runner's, as it runs the step)
};

/// What a program holds, counted one way for armfw's `run` and `armctl program check`:
/// moves are movej / park / G28 (joint) and movel / G0 / G1 (linear); dwells are dwell / G4.
struct StepCounts {
  std::size_t steps = 0;
  int moves = 0, joint_moves = 0, line_moves = 0, dwells = 0;
};
struct Program;
StepCounts count_steps(const Program& p);
/// "29 steps: 20 moves (8 joint, 12 linear), 6 dwells": the one wording of both.
std::string counts_text(const StepCounts& c);

struct Program {
  std::vector<std::string> files;   ///< paths of the files read (files[0] the program itself)
  std::vector<ProgramStep> steps;   ///< in execution order (repeats and calls expanded)
  /// "<file>:<line>" of a step.
  std::string where(const ProgramStep& s) const;
};

/// What a step is to the program runner: a motion it queues (movej, movel, G0-G3, park,
/// dwell), a step that needs the arm at rest first (tool, frame, out / M64 / M65), `wait`,
/// something refused inside a program (enable, home, stop, run, ...), or other (queries,
/// modal-only lines, M62 / M63: they ride with the next move).
enum class StepKind { motion, needs_idle, wait, other, refused };
StepKind kind_of(const fw::Command& c);
StepKind kind_of(fw::Cmd c);  ///< (`out` as needs_idle: kind_of(Command) tells M62 / M63 apart)

/// True when the first motion or needs_idle step after step i is a line (movel, G0-G3): the
/// runner then sends a blended joint move at i as a path segment, so its corner with the
/// line can blend (docs/motion.md#blending).
bool next_motion_is_line(const Program& p, std::size_t i);

/// True for the G-code extensions (.gcode .nc .ngc .gc, any case).
bool is_gcode_file(std::string_view path);

/// "" when `name` may name a program for `call` / `run` (1..63 letters, digits, '_', '-',
/// '.', starting with a letter or digit: no path); else the reason.
std::string check_program_name(std::string_view name);

/// Path of program `name` in `dir`: dir/name if it exists, else dir/name.arm, name.gcode,
/// name.nc, name.ngc (the first that exists); "" if none does.
std::string find_program(const std::string& dir, const std::string& name);

/// Load `path` (a file path; `call` resolves in ctx.dir, or in the file's own folder when
/// ctx.dir is empty). Returns "" and fills `out`, or the one-line error naming file and line.
std::string load_program(const std::string& path, const ProgramContext& ctx, Program& out);

/// Program files of `dir` (native and G-code), sorted; "" or the error.
std::string list_programs(const std::string& dir, std::vector<std::string>& names);

}  // namespace servoarm::prog
