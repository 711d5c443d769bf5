// SPDX-License-Identifier: Apache-2.0
#pragma once
// The console: turns text lines from any transport into actions and answers.
// Runs on the console thread (non-real-time: may allocate and format text).
// Talks to the control thread only through the Controller's SPSC queues and
// telemetry seqlock.
//
// Protocol (every transport): one command per line; every line is answered by
// exactly one final line, `ok [data]` or `error: <code> <message>` (multi-line
// answers -- help, config, limits, M114 -- print their data lines first).
// Asynchronous events print as `alarm: ...` lines. GRBL realtime characters
// act at once and are never part of a line: '?' prints a status report,
// '!' feed hold, '~' resume, Ctrl-X (0x18) e-stop and discards the partial line.
//
// `enable` answers once every drive is in operation enabled (or with the fault).
// Motion commands (movej, movel, park, G0/G1, G28, G4) answer `ok` when the
// move is checked and queued (GRBL semantics); `wait` / M400 answer when the
// queue has run empty. A full queue answers `error: busy` and queues nothing.
#include <cmath>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "servoarm/lang/commands.hpp"
#include "servoarm/lang/frames.hpp"
#include "servoarm/lang/requests.hpp"
#include "servoarm/program/points.hpp"
#include "servoarm/program/program.hpp"
#include "servoarm/rt/controller.hpp"
#include "servoarm/service/arm_service.hpp"
#include "servoarm/kinematics/ik.hpp"
#include "servoarm/kinematics/trajectory_cartesian.hpp"

namespace servoarm::fw {

/// How a session talks: servoarm's own language (`ok ...` / `error: <code> <text>` /
/// `alarm: ...`), or GRBL 1.1's for G-code senders (banner `Grbl 1.1h ['$' for help]`,
/// `ok` / `error:N` with a `[MSG:text]` line before it, `ALARM:N`, `<Idle|MPos:..|FS:..|
/// Ov:..|Bf:..>` reports). Both accept every command, G-code and `$` command.
enum class Dialect : std::uint8_t { native, grbl };
const char* to_string(Dialect d);

/// The console's configuration: the service's settings (MotionSettings: speeds, blend,
/// home, jog, outputs; handed to the arm service, which keeps them: the console reads them
/// there) and what only the console uses.
struct ConsoleConfig : MotionSettings {
  using Output = OutputBit;
  std::string config_text;                   ///< what `config` prints (the effective configuration)
  /// What the command language reads and writes (help and status name them); the robot
  /// description's: App sets units_of(chain). G-code keeps G20/G21 mm/inch and degrees.
  ConsoleUnits units{};
  Dialect dialect = Dialect::native;         ///< of sessions that do not choose their own
  std::string robot_name;                    ///< for $I
  /// Where the tools and user frames are kept (frames.hpp); "" = in memory only (they are
  /// lost at exit, and `tool` / `frame` say so). App resolves console.frames_file.
  std::string frames_file;
  /// Teach points and programs (App resolves programs.points_file and programs.dir):
  /// "" = points in memory only (lost at exit) / no programs folder (`run`, `programs` and
  /// `record stop` say so).
  std::string points_file;
  std::string programs_dir;
  double record_rate_hz = 50.0;              ///< record start without rate=
  double record_tolerance = 0.5 * M_PI / 180.0;  ///< rad: record stop without tolerance=
};


/// One connected client: its partial line, queued lines, G-code modal state.
struct Session {
  std::string name = "console";
  std::string partial;                 ///< bytes of the line being received
  bool discarding = false;
  bool after_cr = false;               ///< last byte was CR (CR LF is one line end)             ///< current line overflowed: drop until newline
  std::deque<std::string> lines;       ///< complete lines not executed yet (while waiting)
  /// A feed hold ('!') arrived after this many complete lines not run yet: it holds at once,
  /// and again right after the last of them has run (a move sent before the '!' is held).
  std::size_t hold_after = 0;
  /// UTF-8: continuation bytes still expected of the character begun by `utf8_lead` (a
  /// realtime byte 0x80-0xFF inside a character other than C2 xx is text, not a command).
  std::uint8_t utf8_left = 0, utf8_lead = 0;
  GcodeModal modal;
  bool waiting = false;                ///< `wait` / M400 in progress
  bool enabling = false;               ///< `enable` / M17 waits for operation enabled
  bool homing = false;                 ///< `$H` waits for the homing cycle to end
  bool checking = false;               ///< `run` waits for its program's check (run in slices)
  std::string out;                     ///< text to send to the client
  CmdError last_error = CmdError::ok;  ///< the code and text of the last error answered
  std::string last_error_text;         ///<   (a program's check reads its steps' refusals here, typed)
  std::uint64_t lines_done = 0;
  Dialect dialect = Dialect::native;
  bool check_mode = false;             ///< GRBL $C: G-code parsed and checked, nothing moves
  kin::JointVector check_tail;         ///< check mode: where the checked moves end
  std::size_t check_tool = 0;          ///< check mode: the tool / frame G-code selects for the check
  std::size_t check_frame = 0;         ///<   (definitions are not made in check mode, as GRBL's $C)
  bool check_blends = false;           ///< check mode: the last checked move is a blended segment with a tolerance
  double check_time = 0;               ///< check mode: end time of the checked moves (blended runs overlapped)
  double check_run_base = 0;           ///< check mode: check_time where the current blended run began
  bool ended = false;                  ///< `quit` / `exit` ran: the transport ends the session (ConsoleServer)
};

class Console {
 public:
  /// `ik`: the IK model of ctl.chain() (owned by the caller, e.g. App, and outliving the
  /// console); nullptr when the chain has none (the damped-Newton fallback is used).
  Console(Controller& ctl, const ConsoleConfig& cfg, const kin::IkModel* ik = nullptr);

  /// Bytes from a transport: realtime characters act now, lines are executed
  /// (or queued while the session waits). Answers go to session.out. = accept() + poll().
  void feed(Session& s, std::string_view bytes);
  /// Bytes from a transport, without executing lines: realtime characters act now
  /// (Ctrl-X answers every complete line not executed yet with `error: estop`),
  /// complete lines are queued in the session.
  void accept(Session& s, std::string_view bytes);
  /// The transport reached end of input: a last line without its newline (even an
  /// overlong one) is queued, so every line gets exactly one answer.
  void end_of_input(Session& s);
  /// Finish a wait/enable that is done, then execute at most one queued line.
  /// True when a line was executed (call again for the next one).
  bool run_one(Session& s);
  /// Execute queued lines / finish a wait when the arm is idle. Call regularly.
  void poll(Session& s);
  /// Console output a transport had to drop because its client did not read
  /// (counted by the transport layer, shown in `stats`).
  void add_output_dropped(std::uint64_t lines, std::uint64_t bytes) {
    output_dropped_lines_ += lines;
    output_dropped_bytes_ += bytes;
  }
  /// Execute one complete line now (no realtime characters). Used by feed().
  void execute(Session& s, std::string_view line);
  /// Render the events of the arm service's stream (ArmService::events_since) not rendered yet
  /// as text lines ("alarm: ...", "homing: ..."), for every session; the service takes the
  /// control thread's events into the stream first.
  std::string drain_events();
  /// The same, in both dialects at once (each session takes its own).
  void drain_events(std::string& native, std::string& grbl);

  /// True while the session has work pending (queued lines or a wait).
  bool busy(const Session& s) const { return s.waiting || s.enabling || s.homing || s.checking || !s.lines.empty(); }

  /// How to pass time while waiting for the control thread (default: sleep 200 us).
  /// Single-threaded tests set it to run a control cycle.
  void set_idle(std::function<void()> idle) { svc_->set_idle(std::move(idle)); }

  /// Status line as printed by `status` (without "ok ").
  std::string status_text() const;
  /// GRBL-style report for '?': <Idle|MPos:x,y,z|J:...|Q:n>
  std::string grbl_report() const;
  /// The report for `s`'s dialect: GRBL 1.1's `<Idle|MPos:..|FS:..|Ov:..|Bf:..>` in the GRBL dialect.
  std::string grbl_report(const Session& s) const;
  /// Human-readable statistics (the `stats` answer without "ok ").
  std::string stats_text() const;
  /// `freedrive`: free-drive, feed-forward and collision detection, and the refusals.
  std::string dynamics_text() const;

  /// Joint values of the end of the motion queue (or the commanded position).
  kin::JointVector tail() const;
  /// The configuration: the console's own part, and the service's settings as they are now.
  ConsoleConfig config() const;
  /// The canonical request of a movel or G0/G1 command (Cmd::movel, Cmd::gmove), from the queue's end.
  /// `from`: the joints relative G-code and a movel without orientation start from (default: tail()).
  MoveLine line_request(const Command& c, const kin::JointVector* from = nullptr) const;
  /// The canonical request of a movej, park or G28 command (Cmd::movej, Cmd::park).
  MoveJoints joint_request(const Command& c) const;
  /// Validate and queue a request; the answer (ok queued ... | error: ...) goes to s.out.
  void queue(Session& s, const MoveLine& m) { queue(s, m, nullptr); }
  void queue(Session& s, const MoveJoints& m) { queue(s, m, nullptr); }

  /// GRBL dialect: the start-up / reset banner into s.out (native: nothing).
  void greet(Session& s);
  /// The transport lost its client (pty closed, socket gone): a jog is cancelled at once
  /// (its deadman would stop it too).
  void client_gone(Session& s);
  /// Feed override in percent (10..200; GRBL 0x90..0x94): scales the speed of jogs and
  /// of moves queued from now on.
  int feed_override() const { return svc_->feed_override(); }

  /// Load the tools and user frames of cfg.frames_file (a missing file: none yet). Call once,
  /// before any line. "" or the one-line error (file:line:column); on error nothing is loaded
  /// and armfw does not start (the file is never overwritten).
  std::string load_frames();
  /// Names of the active tool ("tool0" = the flange) and user frame ("base").
  const std::string& active_tool() const { return svc_->tool(svc_->active_tool()).name; }
  const std::string& active_frame() const { return svc_->frame(svc_->active_frame()).name; }
  /// The tool point's pose of joints `q` in the active user frame (SI), with the active tool.
  kin::Pose pose_in_frame(const kin::JointVector& q) const;

  /// Load the teach points of cfg.points_file (a missing file: none yet). Call once, before any
  /// line; "" or the error (file:line:column; armfw does not start, the file is kept).
  std::string load_points();
  const prog::PointsData& points() const { return svc_->points(); }
  /// The program runner and the recorder: feed the running program's next lines into the
  /// motion queue (one ahead of the running move), notice its end, a hold, a fault; take a
  /// record sample. Console thread; poll() and drain_events() call it. Never blocks.
  void tick();
  RunState run_state() const { return svc_->run_state(); }
  /// `program=NAME state=... line=FILE:LINE` of the running program ("" when none).
  std::string program_text() const;

  /// Motions queued by this console so far (ids 1..n).
  std::uint32_t last_motion_id() const { return svc_->last_motion_id(); }
  /// The arm service the console renders (moves, dwells: planned, checked and queued there).
  ArmService& service() { return *svc_; }
  /// What a jog runs with now: the active tool, its IK, the feed override, the user frame.
  JogContext jog_context() const;

 private:
  /// A request to the control thread and its reply (the arm service's; false: no reply in time).
  bool request(RequestOp op, Reply& out);
  bool request(const Request& rq, Reply& out);
  /// An arm-control result answered: `ok <line>` or `error: <code> <line>`.
  void answer_control(Session& s, const ControlResult& c);
  void do_jog(Session& s, const Command& c);
  void do_grbl_jog(Session& s, const Command& c);
  /// Send a jog request; answer ok / the error. `clamped` >= 0: the target was cut at that
  /// joint's limit (answered as an error naming it, though the jog runs).
  /// A jog's result as the answer line; `what` names the request ("jog", "$J"), `given` the
  /// number the line gave (range and rotation refusals quote it).
  void answer_jog(Session& s, const JogResult& r, const char* what, double given);
  void do_grbl(Session& s, const Command& c);
  /// `home [jN]` (answered at once, progress as `homing:` lines) and `$H` (answered when it has ended).
  void do_home(Session& s, const Command& c);
  /// Cartesian moves, movej, park, G-code moves: "" when every joint is homed, else which are not.
  std::string unhomed_refusal(const Telemetry& t) const;
  /// False (and the not_homed answer) when a joint is not homed.
  bool homed_ok(Session& s);
  std::string grbl_settings() const;
  void realtime(Session& s, char ch);
  /// Feed hold: the arm (a move decelerates and stays held, a jog stops) and the program.
  void feed_hold(Session& s);
  /// The tool pose of the commanded joints.
  kin::Pose commanded_pose() const;
  kin::JointVector commanded_joints() const;
  void answer_error(Session& s, CmdError e, const std::string& msg);
  void answer_ok(Session& s, const std::string& data = {});
  /// The last line of s.out after `from` is an `error:` answer (native) or `error:N` (GRBL).
  bool last_answer_is_error(const Session& s, std::size_t from) const;
  /// A line of information (GRBL: [MSG:]) appended to s.out, before the answer that follows
  /// (nothing when `text` is empty).
  void note_line(Session& s, const std::string& text);
  /// The same, inserted before the final answer line already in s.out after `from`.
  void note_before_answer(Session& s, std::size_t from, const std::string& text);
  /// Drop the M62/M63 changes waiting for the next move: "" when none, else the line that says so.
  std::string discard_sync_outputs(const char* why);
  bool motion_state_ok(Session& s);
  /// Resolve a pending `enable` / `wait` whose outcome is known. True while still blocked.
  bool settle(Session& s);
  void queue_dwell(Session& s, double secs);
  void do_help(Session& s, std::string_view topic);
  /// `help`'s first line: the units in use.
  std::string units_line() const;
  void do_fk(Session& s, const Command& c);
  void do_ik(Session& s, const Command& c);
  void do_limits(Session& s);
  kin::Pose pose_from_values(const Command& c, const kin::JointVector& q_ref) const;
  std::string pose_text(const kin::JointVector& q) const;
  std::string joints_text(const kin::JointVector& q) const;
  double to_si(int j, double user) const;
  double to_user(int j, double si) const;

  Controller& ctl_;
  ConsoleConfig cfg_;
  const kin::Chain& chain_;
  int n_;
  std::unique_ptr<ArmService> svc_;
  // A dry run's blend state (check mode); a pending program check swaps its own in per slice.
  std::unique_ptr<PathShadow> check_shadow_;
  /// What a program step gives the move it queues (exec_step; nullptr: a line typed at a console).
  struct StepParams {
    double blend = -1;                        ///< the step's blend tolerance (SI; < 0: none given)
    /// The program's next motion after this step is a line (movel, G0/G1): a blended movej
    /// goes as a PathMove so that the joint->line corner can blend.
    bool next_line = false;
    const kin::JointVector* point = nullptr;  ///< movej / movel @NAME: the point's joints (SI)
  };
  /// Run a parsed command (execute() after parsing; a program step as the loader parsed it).
  void dispatch(Session& s, const Command& c, const StepParams* step);
  /// The command's family (dispatch() has refused moves while a program runs).
  void run_command(Session& s, const Command& c, const StepParams* step);
  void do_quit(Session& s);
  void do_enable(Session& s);
  /// disable, stop, e-stop: the program (and a pending check) ends as `how`, the M62/M63
  /// changes waiting for a move are dropped (said as `what`), then the request.
  void do_halt(Session& s, ProgramEnd how, const char* what, RequestOp op);
  void do_abort(Session& s);
  void do_switch(Session& s, const Command& c);  ///< freedrive on|off, collision on|off
  void do_safety_change(Session& s, const Command& c);  ///< safety stage | safety confirm
  void do_dynamics(Session& s);                  ///< `freedrive`
  /// park, movej, movel, G0-G3 (teach points, a program step's point joints).
  void do_move(Session& s, const Command& c, const StepParams* step);
  void do_config(Session& s);
  void do_position(Session& s);  ///< M114
  void queue(Session& s, const MoveLine& m, const StepParams* step);
  void queue(Session& s, const MoveJoints& m, const StepParams* step);
  /// A move's result (`what`: movej, movel) as the answer: queued, checked (`dry`: the dry run
  /// it was checked in, kept for the session), or the refusal.
  void answer_move(Session& s, const char* what, const MoveResult& r, const DryRun* dry);
  /// joint_request(c), with a program step's point joints as the goal (movej @NAME).
  MoveJoints step_joint_request(const Command& c, const StepParams* step) const;
  /// What a move runs with: the mode (check mode: a dry run into `dry`), the executing session's
  /// selected tool, the feed override, the M62 / M63 changes and the program step's blend.
  MoveContext move_context(DryRun* dry, const StepParams* step) const;
  /// `safety`: on / off, the mode, the checksum, the stops (a query).
  std::string safety_text() const;
  /// A check-mode session's dry-run state, and back after the move.
  DryRun dry_run(Session& s);
  static void keep_dry_run(Session& s, const DryRun& d);
  /// Render a refused move (`what`: movej, movel, dwell) as its error answer.
  void answer_refusal(Session& s, const char* what, const MoveResult& r);
  /// " blend=X.XXXs" of a blended segment, else "".
  static std::string blend_text(const MoveResult& r);
  std::uint64_t output_dropped_lines_ = 0, output_dropped_bytes_ = 0;
  kin::IkSolver ik_solver() const;
  const kin::IkModel* ik_ = nullptr;  ///< the App's (outlives the console); nullptr: numeric fallback
  // Tools and user frames: the service's (ArmService::tool, frame). A session in check mode
  // keeps its own selection (indices into the service's lists); another session may delete a
  // tool or frame meanwhile, so an index past the end falls back to tool0 / base.
  const Session* sel_ = nullptr;   ///< the session executing a line (check mode has its own selection)
  std::size_t sel_tool() const {
    const std::size_t i = sel_ != nullptr && sel_->check_mode ? sel_->check_tool : svc_->active_tool();
    return i < svc_->tool_count() ? i : 0;
  }
  std::size_t sel_frame() const {
    const std::size_t i = sel_ != nullptr && sel_->check_mode ? sel_->check_frame : svc_->active_frame();
    return i < svc_->frame_count() ? i : 0;
  }
  const kin::Chain& tool_chain() const { return svc_->tool_chain(sel_tool()); }
  const kin::Pose& user_frame() const { return svc_->frame(sel_frame()).pose; }
  /// The active tool point's pose in the base frame.
  kin::Pose tcp(const kin::JointVector& q) const;
  /// "" when tools and frames may change now, else why not (ArmService::frames_check rendered).
  std::string frames_refusal() const;
  /// A refused tool or frame request (`what`: "tool", "frame", "G10") as its error answer.
  void answer_frame_refusal(Session& s, const FrameResult& r, const std::string& what, std::string_view name);
  std::string unsaved_text() const;  ///< " (not kept: ...)" without a frames file
  void do_tool(Session& s, const Command& c);
  void do_frame(Session& s, const Command& c);
  /// A frame definition's position and roll-pitch-yaw (SI) from `frame NAME ...` or G10 L2 / L20.
  void frame_values(const Command& c, const kin::Pose& cur, double xyz[3], double rpy[3]) const;
  std::string where_text() const;  ///< "tool=NAME frame=NAME"
  std::string grbl_position(const kin::JointVector& q) const;
  std::string grbl_wcs() const;  ///< "G54".."G59" for $G
  // Teach points and programs (console_program.cpp)
  /// A loaded program: its steps (checked here through exec_step, then run by the service's
  /// own runner: ArmService::run_program(name, Program, units)) and the check's session.
  struct ProgramRun {
    std::string name;
    prog::Program prog;
    Session ps;                 ///< the program's session (moves from other sessions are refused while it runs)
  };
  /// The program the service runs (kept while it runs).
  std::unique_ptr<ProgramRun> run_;
  /// True while the service runs a program (run_ holds it).
  bool running() const { return svc_->run_state() != RunState::idle; }
  /// A `run` whose program is being checked: a slice of its steps at a time (settle()), so
  /// every transport is read between two slices. One at a time.
  struct PendingCheck {
    Session* owner = nullptr;
    std::unique_ptr<ProgramRun> run;
    Session cs;                           ///< the check's own check-mode session
    std::unique_ptr<PathShadow> shadow;   ///< its own blend shadow (check_shadow_ swapped in per slice)
    std::size_t next = 0;                 ///< next step to check
    kin::JointVector from;                ///< tail() when the check began: the run needs it unchanged
    std::size_t tool = 0, frame = 0;
    bool check_only = false;              ///< `run` in check mode: answer, do not run
  };
  std::unique_ptr<PendingCheck> pcheck_;
  /// Check the next slice of pcheck_'s steps (~2 ms); when done (or refused), answer its owner
  /// and start the program. True while it is still being checked.
  bool continue_check();
  /// End a pending check with `error: program ... check interrupted: <why>` (stop, e-stop, ...).
  void cancel_check(const std::string& why);
  std::uint64_t events_seen_ = 0;  ///< the last event of the service's stream rendered (drain_events)
  /// An event of the service's stream as its native line and its GRBL lines.
  void render_event(const ArmEvent& e, std::string& native, std::string& grbl);
  void do_teach(Session& s, const Command& c);
  void do_points(Session& s);
  void do_point_delete(Session& s, const Command& c);
  void do_programs(Session& s);
  void do_run(Session& s, const Command& c);
  void do_pause(Session& s);
  void do_step(Session& s);
  void do_resume(Session& s);
  void do_record(Session& s, const Command& c);
  void do_out(Session& s, const Command& c);
  /// movej / movel @NAME typed at the console (Command::at_point).
  void queue_at_point(Session& s, const Command& c);
  /// Run one step in `ps` (its answer in ps.out).
  void exec_step(Session& ps, const prog::Program& p, const prog::ProgramStep& st);
  /// End the program (if one runs) with `program: NAME <how>` (e.g. "aborted at f:3: stop").
  /// End the running program (if one runs; a pending check too) as `how` (stop, e-stop,
  /// disable, soft reset: the caller asks the arm), said by a program event.
  void end_program(ProgramEnd how, bool realtime = false);
  std::string program_where() const;  ///< FILE:LINE of the current step
  /// A program event as its `program: ...` line ("" for the events not rendered).
  std::string program_line(const ArmEvent& e) const;
  std::string points_refusal(const TeachResult& r) const;  ///< "" when points may change now (teach_here rendered)
  /// The service's settings (speeds, blend, home, outputs: one place).
  const MotionSettings& motion() const { return svc_->settings(); }
  double feed_now_ = 0;  ///< m/s of the last jog or linear move queued (FS:)
};

/// The receive buffer a GRBL sender counts characters against (Bf:'s second field).
inline constexpr std::size_t kGrblRxBuffer = 128;

}  // namespace servoarm::fw
