// SPDX-License-Identifier: Apache-2.0
// armctl program check: whole-program validation offline (cli_program.hpp).
#include "servoarm/armctl/cli_program.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "servoarm/armctl/cli_common.hpp"
#include "servoarm/armctl/cli_plan.hpp"
#include "servoarm/lang/units.hpp"
#include "servoarm/config/config.hpp"
#include "servoarm/lang/commands.hpp"
#include "servoarm/lang/ik_options.hpp"
#include "servoarm/lang/requests.hpp"
#include "servoarm/lang/units.hpp"
#include "servoarm/lang/text.hpp"
#include "servoarm/kinematics/blend.hpp"
#include "servoarm/kinematics/blend_path.hpp"
#include "servoarm/kinematics/ik.hpp"
#include "servoarm/kinematics/orientation.hpp"
#include "servoarm/kinematics/trajectory.hpp"
#include "servoarm/kinematics/trajectory_cartesian.hpp"
#include "servoarm/program/points.hpp"
#include "servoarm/program/program.hpp"
#include "servoarm/service/arm_service.hpp"

namespace servoarm::fw {

namespace {

const char* kProgramUsage =
    "usage: armctl program check FILE --robot NAME|FILE [--config FILE] [--points FILE] [--programs DIR]\n"
    "                            [--from q1..qn] [--unhomed] [--stream] [--joint-speed PCT] [--linear-speed V]\n"
    "\n"
    "Checks a whole program offline, as armfw checks it before anything moves: every line\n"
    "parsed by the console's parser (repeat/end and call expanded, @points resolved), every\n"
    "target solved by the firmware's IK from the pose the previous line leaves, every path\n"
    "checked (movej/park/G28: joint limits; movel/G0/G1: movel's path check -- IK at every point,\n"
    "joint limits, branch changes, singularities). The first bad line is answered\n"
    "FILE:LINE: reason (exit 2); a good program prints its moves and planned cycle time.\n"
    "Units are the description's (built-in models: mm and degrees); G-code's are mm and deg.\n"
    "\n"
    "By default the program is checked as armfw's `run` runs it: `home`, `enable` and `disable`\n"
    "are not run inside a program (home and enable the arm first), and an unhomed arm (--unhomed)\n"
    "runs none. With --stream it is checked as lines sent one by one to the console (armctl\n"
    "console -c, a G-code sender), where\n"
    "`home` / `home jN` is the homing cycle, as armfw runs it: each joint it homes is left at its\n"
    "drive.homing.offset (method \"none\", an absolute encoder: where it was); refused when moves\n"
    "are still queued (put `wait` before it) or when the homed position is outside the joint's\n"
    "limits; a move right after it without `wait` is refused (armfw refuses moves while homing\n"
    "runs). The homing itself is not timed. `park` / G28 is the joint move to motion.home_deg.\n"
    "\n"
    "options:\n"
    "  --robot NAME|FILE     the arm (a built-in model or a description file); required unless\n"
    "                        --config names it (robot = ...)\n"
    "  --config FILE         armfw's configuration: the homing of each joint (drive.homing.*),\n"
    "                        the park pose (motion.home_deg), drive.limits, drive.max_velocity and\n"
    "                        the motion.* speed defaults; without it armfw's defaults (no [[drive]]\n"
    "                        tables: every joint absolute, `home` moves nothing)\n"
    "  --points FILE         teach points for @NAME (a servoarm-points-1 file)\n"
    "  --programs DIR        where `call NAME` looks (default: the program's own folder)\n"
    "  --from q1..qn         where the arm starts, at rest (default: joint zero clamped into the\n"
    "                        limits, armfw's default park pose)\n"
    "  --unhomed             start as at power-up: joints whose homing.method is not \"none\" are not\n"
    "                        homed; every move before `home` has homed them is refused (not_homed)\n"
    "  --stream              lines sent one by one to the console, not armfw's `run`: `home`,\n"
    "                        `enable`, `disable` allowed (home checked as above)\n"
    "  --joint-speed PCT     movej / park without speed= (default 50, motion.joint_speed_pct)\n"
    "  --linear-speed V      movel / G1 without speed= / F, length units/s (default 100 mm/s,\n"
    "                        motion.linear_speed_mm_s; at most 250 mm/s, motion.max_linear_speed_mm_s)\n"
    "Joints without limits in the description get 90 deg/s, 360 deg/s^2, 3600 deg/s^3\n"
    "(prismatic: 250 mm/s, 1000 mm/s^2, 10000 mm/s^3), as armctl plan.\n"
    "The cycle time blends as armfw does (docs/programs.md, armctl program check): blend=,\n"
    "G64 P / G61 and motion.default_blend_mm / _deg (--config) give the tolerances; runs of joint\n"
    "moves blend as the controller's joint queue, lines and the joint moves beside them as the\n"
    "console's path segments; the time with every move to rest is printed beside it.\n"
    "Every move is planned and checked by the arm service's dry run, the code armfw queues moves\n"
    "with. `tool tool0` and `frame base` are accepted (the only ones offline); other tool and\n"
    "frame changes are not checked offline yet (refused: check those with armfw's $C).\n";

bool is_option(const char* s) { return s[0] == '-' && s[1] == '-'; }

// What armfw's `run` answers for a line it does not run inside a program (console_program.cpp).
const char* const kNotInRunTail =
    " is not run inside a program by armfw's `run` (enable and home the arm before `run`); "
    "--stream checks the file as lines sent one by one to the console";

// The description's joint limits, the armctl plan defaults where it has none.
void default_limits(kin::Chain& c) {
  for (int j = 0; j < c.n_joints; ++j) {
    kin::JointDynamics& d = c.joint(j).dynamics;
    const bool prismatic = c.joint(j).type == kin::JointType::prismatic;
    if (!(d.max_velocity > 0)) d.max_velocity = prismatic ? 0.25 : M_PI / 2;
    if (!(d.max_acceleration > 0)) d.max_acceleration = prismatic ? 1.0 : 2 * M_PI;
    if (!(d.max_jerk > 0)) d.max_jerk = prismatic ? 10.0 : 20 * M_PI;
  }
}

// What armfw takes from its configuration for a program (App::build / console_config, which
// this mirrors: drive.limits narrow the description's, drive.max_velocity lowers its velocity
// limit; motion.* are the console's defaults; drive.homing.* say how each joint homes).
// `cfg` passed validate_for_chain. Returns "" or why the configuration cannot apply.
}  // namespace

std::string apply_config(const FwConfig& cfg, kin::Chain& chain, ProgramCheckOptions& opt) {
  const int n = chain.n_joints;
  for (int j = 0; j < n && j < static_cast<int>(cfg.drives.size()); ++j) {
    const DriveConfig& d = cfg.drives[static_cast<std::size_t>(j)];
    kin::DhRow& row = chain.joint(j);
    const double unit = kConfigUnits.joint_in(chain, j, 1.0);  // SI per deg / mm
    if (!d.limits.empty()) row.lower = d.limits[0] * unit, row.upper = d.limits[1] * unit;
    if (d.max_velocity > 0) {
      const double v = d.max_velocity * unit;
      if (row.dynamics.max_velocity > 0 && v > row.dynamics.max_velocity * (1 + 1e-12))
        return "drive[" + std::to_string(j + 1) + "].max_velocity: " + num(d.max_velocity) + " is above the robot description's " +
               num(row.dynamics.max_velocity / unit);
      row.dynamics.max_velocity = v;
    }
    JointHomingPlan h;
    h.method = d.homing_method;
    h.absolute = d.homing_method == "none";
    h.offset = d.homing_offset * unit;
    opt.homing.push_back(h);
  }
  if (!cfg.home_deg.empty()) {
    opt.park.resize(n);  // (resize, not a moved temporary: gcc 12 -O2 warns on Eigen's copy)
    for (int j = 0; j < n; ++j)
      opt.park[j] = kConfigUnits.joint_in(chain, j, cfg.home_deg[static_cast<std::size_t>(j)]);
  }
  opt.joint_speed_pct = cfg.joint_speed_pct;
  opt.linear_speed = kConfigUnits.length_in(cfg.linear_speed_mm_s);
  opt.max_linear_speed = kConfigUnits.length_in(cfg.max_linear_speed_mm_s);
  opt.max_move_duration = cfg.max_move_duration_s;
  opt.rate_hz = cfg.rate_hz;
  opt.default_blend_rad = kConfigUnits.angle_in(cfg.default_blend_deg);
  opt.default_blend_m = kConfigUnits.length_in(cfg.default_blend_mm);
  if (const std::string e = safety_envelope(cfg, chain, opt.safety); !e.empty()) return e;
  return "";
}

namespace {

struct Checker {
  const kin::Chain& chain;
  const prog::Program& prog;
  const prog::PointsData* points;
  const ProgramCheckOptions& opt;
  ConsoleUnits units;
  kin::JointLimits lim;
  ProgramCheck out;
  kin::JointVector q;
  std::uint32_t homed = ~0u;                   ///< bit j: joint j homed (established this power cycle)
  int queued = 0;                              ///< moves and dwells queued since the last `wait`
  const prog::ProgramStep* homing = nullptr;   ///< the `home` line whose cycle runs (until `wait`)

  // Blending, as armfw runs the program. A move with a blend tolerance that is a line, or a
  // joint move whose next motion is a line, or any move following a path segment that has a
  // tolerance, is a path segment (ArmService's blended runs: kin::PathBlendQueue, blended joint
  // segments at joint_share 0.5, sampled at the control rate); other joint moves with a
  // tolerance run in the controller's joint queue (controller.cpp begin_blend / blend_more:
  // kin::JointBlendQueue<4>, limits scaled by the run's speed override, which every move of
  // the run shares). Anything else, a move that carries M62 / M63 outputs, and every step that
  // waits for the arm at rest (wait, dwell, out, home) start the next move from rest.
  // When the next move reaches the planner: armfw's `run` keeps one move queued behind the
  // running one (console_program.cpp), so a move is queued when the one two back has ended;
  // lines sent one by one (--stream) fill the 16-move queue at once and the controller's
  // joint queue takes a move when one of its 4 segments has ended.
  enum class Run { none, joint, path };
  Run run = Run::none;
  double run_base = 0;          ///< cycle time where the current run starts
  double joint_override = 0;    ///< the joint run's speed override
  bool joint_open = false;      ///< the joint run's last target has a tolerance: a joint move may join
  bool outputs_next = false;    ///< M62 / M63 given: the next move carries them, from rest
  double step_blend = -1;       ///< the step's G64 P / blend (SI), as the runner gives it; < 0 none
  bool next_line = false;       ///< the step's next motion is a line (prog::next_motion_is_line)
  std::unique_ptr<kin::IkModel> path_model = std::make_unique<kin::IkModel>();
  kin::IkSolver path_ik{};
  std::unique_ptr<kin::PathBlendQueue<4>> pq = std::make_unique<kin::PathBlendQueue<4>>();
  std::unique_ptr<kin::JointBlendQueue<4>> jq = std::make_unique<kin::JointBlendQueue<4>>();
  // The firmware's planning and checks: the arm service in a dry run (its own tail and blend
  // state), so a move is accepted, refused and planned exactly as armfw's console does it.
  std::unique_ptr<ArmService> svc{};
  std::unique_ptr<PathShadow> dry_shadow = std::make_unique<PathShadow>();
  DryRun dry{};

  // The dry run of a move from where the program is (`q`), as armfw's console runs it.
  MoveContext dry_context() {
    dry.tail = q;
    dry.shadow = dry_shadow.get();
    MoveContext cx;
    cx.dry = &dry;
    cx.chain = &chain;
    cx.ik = path_ik;
    cx.step_blend = step_blend;
    cx.next_line = next_line;
    return cx;
  }
  template <class Request>
  MoveResult dry_run(const Request& req) {
    return svc->move(req, dry_context());
  }
  void keep(const prog::ProgramStep& s, const MoveResult& r) {
    ProgramKnot k;
    k.line = s.line;
    k.goal = r.goal;
    k.duration = r.duration;
    k.blended = r.blended;
    k.blend = r.blend;
    k.segment_end = r.segment_end;
    out.knots.push_back(k);
  }

  // The console's blend_of: blend= on the line, else the program's, else the configured default.
  double blend_of(double given, bool line) const {
    if (given >= 0) return given;
    if (step_blend >= 0) return step_blend;
    return line ? opt.default_blend_m : opt.default_blend_rad;
  }
  void end_run() { run = Run::none; }
  double period() const { return 1.0 / opt.rate_hz; }

  // The move as a path segment timed as the runner feeds it (ArmService's blended runs); false: not one.
  bool path_segment(bool line, const kin::JointVector& goal, const kin::Pose& target, const kin::CartesianLimits& cl,
                    double override, double tol) {
    if (!std::isfinite(tol) || tol < 0) tol = 0;
    const bool linked = run == Run::path && !outputs_next && pq->size() > 0 && pq->at(pq->size() - 1).tolerance > 0;
    if (!linked && !(tol > 0 && (line || next_line))) return false;
    double t_earliest = 0;
    if (linked) {
      if (!opt.stream)  // queued when the segment two back has ended, kPathLead ahead of the run
        t_earliest = (pq->size() >= 2 ? pq->at(pq->size() - 2).end() : pq->at(pq->size() - 1).start) + period() + kPathLead;
      if (pq->size() >= 2) pq->retire(pq->at(pq->size() - 1).start);  // the last two, as the console keeps
    } else {
      end_run();
      kin::PathBlendConfig pc;
      pc.limits = lim;
      pc.rate = opt.rate_hz;
      pc.chain = &chain;
      pc.ik = path_ik;
      pc.joint_share = 0.5;
      pq->reset(pc, q);
      run_base = out.cycle_time;
    }
    kin::PathBlendReport rep;
    const kin::BlendStatus st = line ? pq->append_line(target, cl, kin::MovelOptions{}, tol, t_earliest, &rep)
                                     : pq->append_joint(goal, override, tol, t_earliest, &rep);
    if (!kin::is_ok(st) || st == kin::BlendStatus::zero_length) {  // the plain move instead
      end_run();
      return false;
    }
    run = Run::path;
    if (rep.blend > 0) ++out.blended_corners;
    out.cycle_time = run_base + pq->at(pq->size() - 1).end();
    return true;
  }

  // A joint move that is no path segment: the controller's joint queue when it has a tolerance
  // or joins the running joint run, else its own plan (`duration`).
  void joint_queue(const kin::JointVector& goal, double override, double tol, double duration) {
    if (!std::isfinite(tol) || tol < 0) tol = 0;
    if (run == Run::joint && joint_open && override == joint_override && !outputs_next) {
      // appended by the controller the cycle after the move was queued
      const int older = opt.stream ? 4 : 2;
      double t_earliest = 2 * period();
      if (jq->size() >= older) {
        const double t = jq->at(jq->size() - older).end();
        jq->retire(t);
        t_earliest = t + 2 * period();
      } else if (!opt.stream) {
        t_earliest = jq->at(jq->size() - 1).start + 2 * period();
      }
      kin::BlendReport rep;
      const kin::BlendStatus st = jq->append(goal, tol, t_earliest, &rep);
      if (kin::is_ok(st) && st != kin::BlendStatus::zero_length) {
        joint_open = tol > 0;
        if (rep.blend > 0) ++out.blended_corners;
        out.cycle_time = run_base + jq->end_time();
        return;
      }
    }
    end_run();
    if (tol > 0 && override >= 0.01 && override <= 1.0) {  // begin_blend: a run from rest
      kin::JointLimits l = lim;
      for (int j = 0; j < chain.n_joints; ++j) {
        kin::JointDynamics& d = l.dyn[static_cast<std::size_t>(j)];
        d.max_velocity *= override;
        d.max_acceleration *= override * override;
        d.max_jerk *= override * override * override;
      }
      jq->reset(l, q);
      const kin::BlendStatus st = jq->append(goal, tol, 0.0);
      if (kin::is_ok(st) && st != kin::BlendStatus::zero_length) {
        run = Run::joint;
        joint_open = true;
        joint_override = override;
        run_base = out.cycle_time;
        out.cycle_time = run_base + jq->end_time();
        return;
      }
    }
    out.cycle_time += duration;
  }

  bool fail(const prog::ProgramStep& s, const std::string& why) {
    out.ok = false;
    out.error = prog.where(s) + ": " + why;
    return false;
  }
  std::string joints_text(const kin::JointVector& v) const {
    std::string t;
    for (int j = 0; j < v.size(); ++j) t += (j ? " " : "") + num(units.joint_out(chain, j, v[j]));
    return t;
  }

  // "joints 1, 3" (or "joint 2") not homed yet; "" when every joint is homed.
  std::string unhomed_joints() const {
    std::string j;
    int count = 0;
    for (int k = 0; k < chain.n_joints; ++k)
      if (!((homed >> k) & 1u)) j += (count++ ? ", " : " ") + std::to_string(k + 1);
    return count == 0 ? "" : std::string("joint") + (count == 1 ? "" : "s") + j;
  }

  // What the console answers a move (or dwell) in this state, "" when it would accept it.
  std::string refusal(const char* what, bool needs_homed) const {
    if (homing != nullptr)
      return std::string(what) + " refused: the homing cycle of " + prog.where(*homing) +
             " still runs (armfw refuses moves until it ends: put `wait` after `home`)";
    if (!needs_homed) return "";
    const std::string j = unhomed_joints();
    if (j.empty()) return "";
    return std::string(what) + " refused: not_homed: " + j + " not homed (armfw refuses every move of an unhomed arm: `home` first)";
  }

  bool movej(const prog::ProgramStep& s, const kin::JointVector& goal, double pct, double given_blend) {
    if (const std::string r = refusal(to_string(s.cmd.cmd), true); !r.empty()) return fail(s, r);
    MoveJoints req;
    req.goal = goal;
    req.speed_pct = pct;
    req.blend = given_blend;
    const MoveResult r = dry_run(req);
    if (!r.ok()) return fail(s, refusal_text("movej", r));
    keep(s, r);
    out.cycle_time_exact += r.duration;
    const double tol = blend_of(given_blend, false);
    if (!path_segment(false, goal, kin::Pose::Identity(), kin::CartesianLimits{}, pct / 100.0, tol))
      joint_queue(goal, pct / 100.0, tol, r.duration);
    outputs_next = false;
    ++out.moves;
    ++out.joint_moves;
    ++queued;
    q = r.goal;
    return true;
  }

  // A refusal of the service, in armctl's words and the description's units.
  std::string refusal_text(const char* what, const MoveResult& r) const {
    switch (r.refusal) {
      case MoveRefusal::none:
      case MoveRefusal::arm_state:
      case MoveRefusal::not_homed:
      case MoveRefusal::queue_full: return std::string(what) + " refused: " + r.reason;
      case MoveRefusal::joint_limit:
        return std::string(what) + " refused: joint " + std::to_string(r.joint + 1) + " = " + num(units.joint_out(chain, r.joint, r.value)) +
               " outside [" + num(units.joint_out(chain, r.joint, r.lower)) + ", " + num(units.joint_out(chain, r.joint, r.upper)) + "] " +
               units.joint_name(chain, r.joint);
      case MoveRefusal::linear_speed:
        return "linear speed " + num(units.length_out(r.speed)) + " " + units.length_name() + "/s outside [" +
               num(units.length_out(kMinLinearSpeedMmS * 1e-3)) + ", " + num(units.length_out(opt.max_linear_speed)) + "]";
      case MoveRefusal::plan: {
        if (std::string(what) != "movel") return std::string(what) + " refused: " + kin::to_string(r.status);
        const Eigen::Vector3d& p = r.position;
        auto r3 = [&](double si) { return units.length_text(si); };
        std::string why = std::string("movel refused: ") + kin::to_string(r.status) + " at " + num(std::round(100 * r.s)) +
                          " % of the line, tool at (" + r3(p.x()) + ", " + r3(p.y()) + ", " + r3(p.z()) + ") " + units.length_name();
        if (r.joint >= 0) why += ", joint " + std::to_string(r.joint + 1);
        if (r.status == kin::MotionStatus::no_ik_solution && r.s >= 1 - 1e-9) why += " (the target is out of reach)";
        return why;
      }
      case MoveRefusal::duration:
        return std::string(what) + " refused: it would take " + seconds_text(r.duration) + " s, more than " + num(opt.max_move_duration) + " s";
    }
    return std::string(what) + " refused";
  }

  // A line (movel, G0/G1): `req.speed` 0 is the configured default.
  bool movel(const prog::ProgramStep& s, const MoveLine& req) {
    if (const std::string r = refusal(s.cmd.cmd == Cmd::gmove ? "G-code move" : "movel", true); !r.empty()) return fail(s, r);
    const MoveResult r = dry_run(req);
    if (!r.ok()) return fail(s, refusal_text("movel", r));
    keep(s, r);
    out.cycle_time_exact += r.duration;
    kin::CartesianLimits cl;
    cl.linear_velocity = r.speed;
    if (!path_segment(true, r.goal, req.target, cl, 1.0, blend_of(req.blend, true))) {
      end_run();
      out.cycle_time += r.duration;
    }
    outputs_next = false;
    ++out.moves;
    ++out.line_moves;
    ++queued;
    q = r.goal;
    return true;
  }

  // park / G28: the joint move to motion.home_deg (armfw's default: joint zero clamped into the
  // limits), as the arm service makes it.
  bool step_park(const prog::ProgramStep& s) {
    const MoveJoints m = svc->park_request();
    return movej(s, m.goal, m.speed_pct, m.blend);
  }

  // home / home jN: the homing cycle, as the console and the controller run it. Refused with
  // moves queued (the controller's "moves are queued: home refused") or while a cycle runs;
  // each joint homed reads its drive.homing.offset afterwards (the drive holds at its mark,
  // hard_stop at the backed-off point), which must lie within its limits (else armfw fails
  // that joint's homing and disables the arm); "none" joints stay where they are.
  bool step_home(const prog::ProgramStep& s) {
    const Command& c = s.cmd;
    if (homing != nullptr)
      return fail(s, "home refused: the homing cycle of " + prog.where(*homing) + " still runs (put `wait` after it)");
    if (queued > 0)
      return fail(s, "home refused: " + std::to_string(queued) + " move" + (queued == 1 ? " is" : "s are") +
                         " still queued (armfw homes an arm at rest only: put `wait` before `home`)");
    for (int j = 0; j < chain.n_joints; ++j) {
      if (c.home_joint >= 0 && j != c.home_joint) continue;
      const auto k = static_cast<std::size_t>(j);
      const bool absolute = opt.homing.size() != static_cast<std::size_t>(chain.n_joints) || opt.homing[k].absolute;
      if (!absolute) {
        const double p = opt.homing[k].offset;
        if (!(p >= lim.lower[k] - 1e-9 && p <= lim.upper[k] + 1e-9))
          return fail(s, "home refused: joint " + std::to_string(j + 1) + " (homing.method " + opt.homing[k].method +
                             ") homes to " + num(units.joint_out(chain, j, p)) + " " + units.joint_name(chain, j) +
                             " (drive[" + std::to_string(j + 1) + "].homing.offset), outside its limits [" +
                             num(units.joint_out(chain, j, lim.lower[k])) + ", " + num(units.joint_out(chain, j, lim.upper[k])) +
                             "] " + units.joint_name(chain, j) + ": armfw fails that homing and disables the arm");
        q[j] = p;
      }
      homed |= 1u << j;
    }
    ++out.homings;
    homing = &s;
    return true;
  }

  bool step(const prog::ProgramStep& s, std::size_t index) {
    const Command& c = s.cmd;
    // What the runner gives the move it queues (console_program.cpp exec_step); lines sent
    // one by one (--stream) carry only their own blend= (own_blend).
    const bool gcode = static_cast<std::size_t>(s.file) < prog.files.size() &&
                       prog::is_gcode_file(prog.files[static_cast<std::size_t>(s.file)]);
    step_blend = opt.stream || s.blend < 0 ? -1.0
                 : gcode                   ? s.blend * 1e-3  // G-code: mm
                 : c.cmd == Cmd::movej     ? units.angle_in(s.blend)
                                           : units.length_in(s.blend);
    next_line = !opt.stream && prog::next_motion_is_line(prog, index);
    // A line sent one by one (--stream) carries its blend= as its own, as the console reads it.
    const double own_blend = !opt.stream || s.blend < 0 || gcode ? -1.0
                             : c.cmd == Cmd::movej           ? units.angle_in(s.blend)
                                                             : units.length_in(s.blend);
    const prog::StepKind kind = prog::kind_of(c);
    if (kind == prog::StepKind::needs_idle || kind == prog::StepKind::wait || kind == prog::StepKind::refused) end_run();
    if (c.cmd == Cmd::out && c.out_sync) outputs_next = true;
    switch (c.cmd) {
      case Cmd::movej: {
        kin::JointVector goal(chain.n_joints);
        if (s.point >= 0) goal = points->points[static_cast<std::size_t>(s.point)].q;
        else
          for (int j = 0; j < chain.n_joints; ++j) goal[j] = units.joint_in(chain, j, c.vals[static_cast<std::size_t>(j)]);
        return movej(s, goal, c.has_speed ? c.speed : opt.joint_speed_pct, c.has_blend ? units.angle_in(c.blend) : own_blend);
      }
      case Cmd::home:
        if (!opt.stream) return fail(s, std::string("home") + kNotInRunTail);
        return step_home(s);
      case Cmd::enable:
      case Cmd::disable:
        if (!opt.stream) return fail(s, std::string(to_string(c.cmd)) + kNotInRunTail);
        return true;
      case Cmd::park: return step_park(s);
      case Cmd::wait:  // the console's: until the queued moves (and a homing cycle) are done
        queued = 0;
        homing = nullptr;
        return true;
      case Cmd::movel: {
        kin::Pose target;
        if (s.point >= 0) {
          if (kin::forward(chain, points->points[static_cast<std::size_t>(s.point)].q, target) != kin::Status::ok)
            return fail(s, "movel refused: the point's pose is not finite");
        } else {
          kin::forward(chain, q, target);  // orientation kept when only x y z are given
          target.translation() = Eigen::Vector3d(units.length_in(c.vals[0]), units.length_in(c.vals[1]), units.length_in(c.vals[2]));
          if (c.count == 6)
            target.linear() = kin::rotation_from_rpy(units.angle_in(c.vals[3]), units.angle_in(c.vals[4]), units.angle_in(c.vals[5]));
        }
        // (a point's line takes the program's blend only, as the runner queues it)
        MoveLine req;
        req.target = target;
        req.speed = c.has_speed ? units.length_in(c.speed) : 0.0;
        req.blend = c.has_blend && s.point < 0 ? units.length_in(c.blend) : own_blend;
        return movel(s, req);
      }
      case Cmd::gmove: {  // as the console's line_request: G-code mm / deg, the base frame (offline)
        const ConsoleUnits& u = kGcodeUnits;
        kin::Pose cur;
        kin::forward(chain, q, cur);
        kin::Pose target = cur;
        Eigen::Vector3d rpy = kin::rpy_from_rotation(cur.linear());
        for (int k = 0; k < 6; ++k) {
          if (!(c.axis_mask & (1u << k))) continue;
          const double v = c.vals[static_cast<std::size_t>(k)];
          if (k < 3) target.translation()[k] = u.length_in(c.relative ? u.length_out(cur.translation()[k]) + v : v);
          else rpy[k - 3] = c.relative ? rpy[k - 3] + u.angle_in(v) : u.angle_in(v);
        }
        if (c.axis_mask & 0x38) target.linear() = kin::rotation_from_rpy(rpy[0], rpy[1], rpy[2]);
        if (c.axis_mask == 0) return true;  // G1 F.. alone: modal only
        MoveLine req;
        req.target = target;
        req.rapid = c.rapid;
        req.speed = c.has_speed ? u.length_in(c.speed) : 0.0;
        req.clamp_speed = true;  // senders' F is clamped, as GRBL does
        return movel(s, req);
      }
      case Cmd::dwell:  // queued as a motion (the console refuses it while homing runs)
        if (const std::string r = refusal("dwell", false); !r.empty()) return fail(s, r);
        svc->dwell(c.vals[0], dry_context());
        end_run();
        outputs_next = false;
        out.cycle_time += c.vals[0];
        out.cycle_time_exact += c.vals[0];
        ++out.dwells;
        ++queued;
        return true;
      case Cmd::tool:
      case Cmd::frame:
        if (c.frame_op == FrameOp::list) return true;
        // Offline the arm has the flange and the base frame only: selecting them changes nothing.
        // The console refuses a change while moves are queued; armfw's `run` waits for them first.
        if (c.frame_op == FrameOp::select && std::string(c.name.data()) == (c.cmd == Cmd::tool ? "tool0" : "base")) {
          if (opt.stream && queued > 0)
            return fail(s, std::string(to_string(c.cmd)) + " refused: " + std::to_string(queued) + " move" +
                               (queued == 1 ? " is" : "s are") + " still queued (armfw changes tools and frames at rest only: put `wait` before it)");
          if (!opt.stream) queued = 0;
          return true;
        }
        return fail(s, "tool and frame changes are not checked offline yet (check this program with armfw's $C)");
      default:
        return true;  // no motion: enable, status, queries, modal-only G-code
    }
  }
};

}  // namespace

ProgramCheck check_program(const kin::Chain& chain, const prog::Program& prog, const prog::PointsData* points,
                           const kin::JointVector& q0, const ProgramCheckOptions& options) {
  Checker ck{chain, prog, points, options, units_of(chain), kin::limits_from(chain), ProgramCheck{}, q0};
  MotionSettings ms;  // armfw's console settings (App::console_config), from the options
  ms.default_joint_speed_pct = options.joint_speed_pct;
  ms.default_linear_speed = options.linear_speed;
  ms.max_linear_speed = options.max_linear_speed;
  ms.max_move_duration_s = options.max_move_duration;
  ms.cartesian.linear_velocity = options.max_linear_speed;
  ms.default_blend_rad = options.default_blend_rad;
  ms.default_blend_m = options.default_blend_m;
  ms.home = options.park;
  ms.safety = options.safety;
  ck.svc = std::make_unique<ArmService>(chain, ck.lim, options.rate_hz, ms);
  ck.q = q0;
  ck.out.ok = true;
  if (options.start_unhomed && options.homing.size() == static_cast<std::size_t>(chain.n_joints))
    for (int j = 0; j < chain.n_joints; ++j)
      if (!options.homing[static_cast<std::size_t>(j)].absolute) ck.homed &= ~(1u << j);
  if (!options.stream && !prog.steps.empty()) {
    // armfw's `run` starts only on a homed arm (the console's not_homed answer)
    const std::string j = ck.unhomed_joints();
    if (!j.empty()) {
      ck.fail(prog.steps.front(), "run refused: not_homed: " + j +
                                      " not homed (armfw's `run` starts only on a homed arm: home it first; --stream checks a "
                                      "file that homes)");
      ck.out.q_end = ck.q;
      return ck.out;
    }
  }
  {
    const bool prepared = kin::ik_prepare(chain, *ck.path_model) == kin::Status::ok;
    ck.path_ik = firmware_ik_solver(prepared ? ck.path_model.get() : nullptr);
  }
  for (std::size_t i = 0; i < prog.steps.size(); ++i)
    if (!ck.step(prog.steps[i], i)) break;
  ck.out.q_end = ck.q;
  return ck.out;
}

int cli_program(int argc, char** argv) {
  for (int i = 1; i < argc; ++i)
    if (!std::strcmp(argv[i], "--help") || !std::strcmp(argv[i], "-h")) {
      std::fputs(kProgramUsage, stdout);
      return kExitOk;
    }
  if (argc < 2 || std::strcmp(argv[1], "check") != 0)
    return usage_error(argc < 2 ? "program needs a command: check (see armctl program --help)"
                                : std::string("unknown program command '") + argv[1] + "' (check)");
  std::string file, robot, points_file, dir, config_file;
  std::vector<double> from;
  double joint_pct = 0, linear = 0;
  bool unhomed = false, stream = false;
  for (int i = 2; i < argc; ++i) {
    const std::string o = argv[i];
    auto text = [&](std::string& out) -> std::string {
      if (i + 1 >= argc || is_option(argv[i + 1])) return o + " needs a value";
      out = argv[++i];
      return "";
    };
    auto one = [&](double& out) -> std::string {
      if (i + 1 >= argc || is_option(argv[i + 1])) return o + " needs a value";
      if (!parse_number(argv[i + 1], out)) return o + ": '" + argv[i + 1] + "' is not a finite number";
      ++i;
      return "";
    };
    std::string e;
    if (o == "--robot") e = text(robot);
    else if (o == "--config") e = text(config_file);
    else if (o == "--unhomed") unhomed = true;
    else if (o == "--stream") stream = true;
    else if (o == "--points") e = text(points_file);
    else if (o == "--programs") e = text(dir);
    else if (o == "--joint-speed") e = one(joint_pct);
    else if (o == "--linear-speed") e = one(linear);
    else if (o == "--from") {
      while (i + 1 < argc && !is_option(argv[i + 1])) {
        double v;
        if (!parse_number(argv[i + 1], v)) return usage_error("--from: '" + std::string(argv[i + 1]) + "' is not a finite number");
        from.push_back(v);
        ++i;
      }
      if (from.empty()) e = "--from needs values";
    } else if (!is_option(argv[i]) && file.empty()) file = o;
    else return usage_error("unknown option '" + o + "' (see armctl program --help)");
    if (!e.empty()) return usage_error(e);
  }
  if (file.empty()) return usage_error("program check needs a program FILE");
  FwConfig cfg;  // armfw's defaults unless --config
  if (!config_file.empty()) {
    if (const std::string e = load_config_file(config_file, cfg); !e.empty()) return usage_error(e);
    if (robot.empty()) robot = cfg.robot;
  }
  if (robot.empty()) return usage_error("--robot is required (or a --config that names the robot)");
  if (joint_pct != 0 && !(joint_pct >= 1 && joint_pct <= 100)) return usage_error("--joint-speed must be within 1..100 (percent)");
  const kin::LoadResult r = load_robot_checked(robot);
  if (!r.ok) return usage_error(r.error);
  kin::Chain chain = r.chain;
  ProgramCheckOptions opt;
  if (!config_file.empty()) {
    cfg.robot = robot;
    if (const std::string e = validate_for_chain(cfg, chain); !e.empty()) return usage_error(config_file + ": " + e);
    if (const std::string e = apply_config(cfg, chain, opt); !e.empty()) return usage_error(config_file + ": " + e);
  }
  default_limits(chain);
  const ConsoleUnits units = units_of(chain);
  opt.start_unhomed = unhomed;
  opt.stream = stream;
  if (joint_pct != 0) opt.joint_speed_pct = joint_pct;
  if (linear != 0) {
    opt.linear_speed = units.length_in(linear);
    if (!(opt.linear_speed > 0 && opt.linear_speed <= opt.max_linear_speed))
      return usage_error("--linear-speed must be > 0 and at most " + num(units.length_out(opt.max_linear_speed)) + " " +
                         units.length_name() + "/s");
  }
  kin::JointVector q0(chain.n_joints);
  if (!from.empty()) {
    std::string e;
    if (!joints_from_user(chain, from, q0, e)) return usage_error("--from: " + e);
    std::string rep;
    if (limit_violations(chain, q0, rep) > 0) return usage_error("--from is outside the joint limits:\n" + rep);
  } else {
    for (int j = 0; j < chain.n_joints; ++j) q0[j] = std::clamp(0.0, chain.joint(j).lower, chain.joint(j).upper);
  }
  prog::PointsData points;
  if (!points_file.empty()) {
    bool missing = false;
    const std::string e = prog::load_points_file(points_file, chain.n_joints, points, &missing);
    if (!e.empty()) return usage_error(e);
    if (missing) return usage_error(points_file + ": no such points file");
  }
  prog::ProgramContext ctx;
  ctx.chain = &chain;
  ctx.units = units;
  ctx.dir = dir;
  ctx.points = points_file.empty() ? nullptr : &points;
  prog::Program program;
  if (const std::string e = prog::load_program(file, ctx, program); !e.empty()) return usage_error(e);
  const ProgramCheck ck = check_program(chain, program, ctx.points, q0, opt);
  if (!ck.ok) return usage_error(ck.error);
  std::string homings;
  if (ck.homings > 0)
    homings = ", " + count_text(ck.homings, "homing cycle") + " (not timed" +
              (opt.homing.empty() ? ": no [[drive]] tables, every joint absolute, nothing moved" : "") + ")";
  // The counts in the words armfw's `run` answers with (prog::counts_text).
  std::printf("ok: %s on %s (%s): %s%s, planned cycle time %s s (%s; %s s with every move to rest)\n", file.c_str(),
              chain.name.data(), count_text(static_cast<long long>(program.files.size()), "file").c_str(),
              prog::counts_text(prog::count_steps(program)).c_str(), homings.c_str(), seconds_text(ck.cycle_time).c_str(),
              count_text(ck.blended_corners, "blended corner").c_str(), seconds_text(ck.cycle_time_exact).c_str());
  return kExitOk;
}

}  // namespace servoarm::fw
