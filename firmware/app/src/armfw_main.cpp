// SPDX-License-Identifier: Apache-2.0
// armfw: the firmware binary. Control loop on its own thread, consoles on the
// main thread (stdin/stdout, pty, serial, CAN ISO-TP through its bridge thread),
// drives through the CANopen master.
//
//   armfw --sim [--robot puma560]          virtual servos on the in-process bus
//   armfw --config FILE                    everything from a TOML file
//   armfw --sim --demo [--interactive]     play the demo program, print a summary
//   armfw --sim --bench-loop SEC [--rate HZ]   loop statistics as one JSON line
//   armfw --sim --api-tcp 0 --no-stdin       the network API (docs/api.md) on a free port
#include <poll.h>
#include <sys/stat.h>
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "servoarm/app/app.hpp"
#ifdef SERVOARM_WITH_API
#include "servoarm/api/server.hpp"  // the network API (optional: libwebsockets)
#include "servoarm/api/foxglove.hpp"  // the Foxglove WebSocket server (same library)
#ifdef SERVOARM_WITH_MQTT
#include "servoarm/api/mqtt.hpp"  // the MQTT bridge (optional: libmosquitto)
#endif
#include "servoarm/lang/ik_options.hpp"
#include "servoarm/service/stream.hpp"
#endif
#ifdef SERVOARM_WITH_SIM
#include "servoarm/sim/sim_plant.hpp"  // --sim: the only firmware file that uses host_sim
#include "servoarm/sim/mit_motor.hpp"
#endif
#include "servoarm/rt/rt_loop.hpp"
#include "servoarm/lang/number.hpp"
#include "servoarm/console/transport.hpp"
#include "servoarm/kinematics/collision.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/kinematics/dynamics.hpp"
#include "servoarm/kinematics/orientation.hpp"

using namespace servoarm;
using namespace servoarm::fw;

namespace {

volatile sig_atomic_t g_quit = 0;
void on_signal(int) { g_quit = 1; }

int usage(FILE* f, int code) {
  std::fprintf(f,
               "usage: armfw (--sim [--robot NAME|FILE] | --config FILE) [options]\n"
               "  --sim                 virtual CiA 402 servos on the in-process bus (no config needed)\n"
               "  --robot NAME|FILE     robot model (default puma560; see armctl kin models)\n"
               "  --config FILE         TOML configuration (armfw --config-keys lists every key)\n"
               "  --frames FILE         the tools and user frames file (default: console.frames_file, frames.toml\n"
               "                        next to --config; without --config none: tools and frames are not kept)\n"
               "  --programs DIR        the programs folder (run, programs, record stop; default: programs.dir,\n"
               "                        programs/ next to --config; without --config none)\n"
               "  --points FILE         the teach points file (default: programs.points_file, points.toml next to\n"
               "                        --config; without --config none: points are not kept)\n"
               "  --config-keys         print every configuration key (default, range, unit, doc) and exit\n"
               "  --config-reference    print the generated reference section of docs/configuration.md and exit\n"
               "  --bus-load            with --config (or --sim): print the drive bus load of the configured\n"
               "                        traffic, one table per CAN interface at its own bit rates (frames,\n"
               "                        bits, load per direction and in all) and exit\n"
               "  --bus-load-reference  print the bus-load table of docs/deployment.md and exit\n"
               "  --demo                play a demo derived from the robot through the console, print a summary, exit\n"
               "  --interactive         after --demo, leave the console open on stdin\n"
               "  --bench-loop SEC      run the loop SEC seconds with moves in progress; print one JSON line\n"
               "  --rate HZ             control rate 250..4000 (default 1000)\n"
               "  --priority N          SCHED_FIFO priority 1..99, 0 = normal scheduling (default 80)\n"
               "  --cpu N               pin the control thread to CPU N\n"
               "  --plant KIND          with --sim: first-order (default) or dynamic (rigid-body arm; needs inertial data;\n"
               "                        virtual MIT motors: each moves its joint's inertia and carries the arm's gravity)\n"
               "  --push J:NM:HZ[:DEG]  with --plant dynamic: a scripted external torque NM x sin(2 pi HZ t + DEG) on\n"
               "                        joint J (HZ 0: constant), t from the plant's start; up to 8, added up (a hand\n"
               "                        moving the arm in free-drive, e.g. a teleoperation leader)\n"
               "  --motor-temperature J:DEGC  with --sim: joint J's virtual MIT motor stands at DEGC (its ambient;\n"
               "                        the temperature warning and fault are the drive family's own)\n"
               "  --pty                 also open a pty console and print its path\n"
               "  --dialect grbl|native the consoles' language: GRBL 1.1 for G-code senders (cncjs, UGS,\n"
               "                        bCNC: banner, $ commands, error:N, <Idle|MPos:..> reports) or servoarm's\n"
               "                        own (default; console.dialect, console.pty_dialect, console.serial_dialect)\n"
               "  --serial PATH [--baud N]   also run a console on a serial TTY\n"
               "  --can-console IFACE   also run a console over CAN (ISO-TP) on IFACE (vcan0, can0, or sim);\n"
               "                        ids from console.can_rx_id / can_tx_id (default 0x7E0 in, 0x7E8 out)\n"
               "  --no-stdin            no console on stdin/stdout\n"
               "  --api-ws PORT         serve the network API's WebSocket on PORT (0: a free port, printed); turns\n"
               "                        api.enabled on (docs/api.md)\n"
               "  --api-tcp PORT        serve the network API's newline-delimited JSON on PORT (0: a free port)\n"
               "  --api-tokens FILE     the API's tokens file (api.tokens_file)\n"
               "  --api-tls-cert FILE   TLS on the API's ports: the certificate (api.tls_cert)\n"
               "  --api-tls-key FILE    and its key (api.tls_key)\n"
               "  --foxglove-port PORT  serve live data to Foxglove / Lichtblick on PORT (0: a free port, printed); turns\n"
               "                        foxglove.enabled on (docs/foxglove-mcap.md)\n"
               "  --record-dir DIR      where `record mcap` writes its MCAP files (record.dir)\n"
               "  --api-reference       print the generated reference section of docs/api.md and exit\n"
               "  (safety inputs: the safety.estop_input / safety.reduced_input keys, a drive's 60FDh bit or a GPIO\n"
               "  line; run-time [safety] changes: the console's safety stage + safety confirm, or the API's\n"
               "  safety_stage + safety_confirm; docs/safety.md)\n"
               "  -h, --help            this text\n");
  return code;
}

double now_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

void print_stats_json(const Telemetry& t, double rate) {
  auto obj = [](const StatSummary& s) {
    char b[160];
    std::snprintf(b, sizeof b, "{\"min\": %.2f, \"mean\": %.2f, \"p99\": %.2f, \"max\": %.2f}", s.min_us, s.mean_us, s.p99_us,
                  s.max_us);
    return std::string(b);
  };
  std::printf("{\"rate_hz\": %.0f, \"cycles\": %llu, \"overruns\": %llu, \"latency_us\": %s, \"compute_us\": %s}\n", rate,
              static_cast<unsigned long long>(t.cycles), static_cast<unsigned long long>(t.overruns), obj(t.latency).c_str(),
              obj(t.compute).c_str());
  std::fflush(stdout);
}

// Run one console line in a session, wait for it to finish (showing progress), print the answer.
struct DemoRunner {
  App& app;
  Session s;
  int errors = 0;
  bool verbose = true;

  std::string run(const std::string& line, bool show_progress = true) {
    if (g_quit) return "";  // SIGINT / SIGTERM: the demo ends here (nothing more is sent)
    if (verbose) std::printf("> %s\n", line.c_str());
    s.out.clear();
    app.console->execute(s, line);
    double last = now_s();
    while (app.console->busy(s)) {
      if (g_quit) {  // a signal during a move or a wait: the arm is stopped, the demo ends
        Session stop;
        app.console->execute(stop, "stop");
        std::printf("%s", stop.out.c_str());
        std::fflush(stdout);
        return "";
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
      app.console->poll(s);
      const std::string ev = app.console->drain_events();
      if (!ev.empty()) std::printf("%s", ev.c_str());
      if (show_progress && now_s() - last > 0.25) {
        last = now_s();
        std::printf("    progress: %s\n", app.console->status_text().c_str());
      }
    }
    const std::string ev = app.console->drain_events();
    if (!ev.empty()) std::printf("%s", ev.c_str());
    if (verbose) std::printf("%s", s.out.c_str());
    if (s.out.find("error:") != std::string::npos) ++errors;
    std::fflush(stdout);
    return s.out;
  }
};

struct Reached {
  std::string what;
  double err;
  const char* unit;
};

// The demo's moves, derived from the robot: a joint pose at a fraction of each joint's
// range from the park pose, away from singularities, and a rectangle in the tool's plane
// there, every line checked by the console's own path check (check mode, $C) before it is
// used. Arms with fewer than 6 joints, or where no line passes, get joint moves only.
struct DemoPlan {
  std::string movej;                 ///< the joint move to the work pose (console units)
  kin::JointVector work;             ///< its joints as typed (SI)
  std::string movej2;                ///< joint moves only: a second pose, and back
  kin::JointVector work2;
  std::vector<std::string> movel;    ///< the rectangle's corners (console units)
  std::vector<Eigen::Vector3d> corner;  ///< the same, SI
  std::vector<std::string> gcode;    ///< relative G-code moves after the rectangle
  Eigen::Vector3d gcode_end = Eigen::Vector3d::Zero();
  std::string why_joints_only;       ///< "" when the lines are used
};

double joint_to_user(const kin::Chain& ch, int j, double v) { return kConfigUnits.joint_out(ch, j, v); }
double joint_from_user(const kin::Chain& ch, int j, double v) { return kConfigUnits.joint_in(ch, j, v); }

/// "movej ..." for q (3 decimals of deg / mm); `typed` gets the joints the text says.
std::string movej_text(const kin::Chain& ch, const kin::JointVector& q, kin::JointVector& typed) {
  std::string l = "movej";
  typed = q;
  for (int j = 0; j < ch.n_joints; ++j) {
    char b[40];
    const double u = std::round(joint_to_user(ch, j, q[j]) * 1000.0) / 1000.0;
    std::snprintf(b, sizeof b, " %.3f", u == 0.0 ? 0.0 : u);
    l += b;
    typed[j] = joint_from_user(ch, j, u);
  }
  return l + " speed=60";
}

/// "movel x y z speed=150" (0.1 mm); `typed` gets the point the text says (m).
std::string movel_text(const Eigen::Vector3d& p, Eigen::Vector3d& typed) {
  char b[128];
  const Eigen::Vector3d mm = (p * 1e4).array().round() / 10.0;
  std::snprintf(b, sizeof b, "movel %.1f %.1f %.1f speed=150", mm.x() + 0.0, mm.y() + 0.0, mm.z() + 0.0);
  typed = mm * 1e-3;
  return b;
}

std::string gmove_text(const Eigen::Vector3d& d, Eigen::Vector3d& typed, const char* feed) {
  char b[128];
  const Eigen::Vector3d mm = (d * 1e4).array().round() / 10.0;
  std::snprintf(b, sizeof b, "G1 X%.1f Y%.1f Z%.1f%s", mm.x() + 0.0, mm.y() + 0.0, mm.z() + 0.0, feed);
  typed = mm * 1e-3;
  return b;
}

/// Every line answers ok in a check-mode session starting at `from`.
bool passes_check(App& app, const kin::JointVector& from, const std::vector<std::string>& lines) {
  Session cs;
  app.console->execute(cs, "$C");
  if (!cs.check_mode) return false;
  cs.check_tail = from;
  for (const std::string& l : lines) {
    cs.out.clear();
    app.console->execute(cs, l);
    for (int i = 0; i < 2000 && app.console->busy(cs); ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
      app.console->poll(cs);
    }
    if (cs.out.rfind("ok", 0) != 0) return false;
  }
  return true;
}

DemoPlan plan_demo(App& app, const kin::JointVector& park) {
  const kin::Chain& ch = app.chain;
  const int n = ch.n_joints;
  DemoPlan plan;
  // Candidate joint poses: park + f * (room to the limit on side sign_j), alternating sides.
  auto candidate = [&](double f, int pattern) {
    kin::JointVector q = park;
    for (int j = 0; j < n; ++j) {
      const kin::DhRow& r = ch.joint(j);
      const bool prismatic = r.type == kin::JointType::prismatic;
      const double span = prismatic ? 0.5 : M_PI;  // an unbounded joint: half a turn, or 0.5 m
      const double lo = std::isfinite(r.lower) ? r.lower : park[j] - span;
      const double hi = std::isfinite(r.upper) ? r.upper : park[j] + span;
      const bool up = pattern == 0 ? (j % 2 == 0) : pattern == 1 ? (j % 2 == 1) : true;
      q[j] = park[j] + f * (up ? hi - park[j] : lo - park[j]);
    }
    return q;
  };
  auto well_conditioned = [&](const kin::JointVector& q) {
    if (n < 6) return true;
    kin::Jacobian J;
    if (kin::jacobian(ch, q, J) != kin::Status::ok) return false;
    const double c = kin::condition_number(J);
    return std::isfinite(c) && c < 200.0;
  };
  const double fractions[] = {0.3, 0.2, 0.4, 0.15, 0.5, 0.1};
  std::vector<kin::JointVector> poses;  // in-limit, well-conditioned, movej checked
  for (double f : fractions)
    for (int pattern = 0; pattern < 3; ++pattern) {
      const kin::JointVector q = candidate(f, pattern);
      if (!kin::within_limits(ch, q) || !well_conditioned(q)) continue;
      kin::JointVector typed;
      const std::string mj = movej_text(ch, q, typed);
      if (!passes_check(app, park, {mj})) continue;
      poses.push_back(typed);
    }
  if (poses.empty()) {
    plan.why_joints_only = "no joint pose passed";
    return plan;
  }
  plan.movej = movej_text(ch, poses[0], plan.work);
  if (n >= 6) {
    for (const kin::JointVector& q : poses) {
      kin::Pose p;
      if (kin::forward(ch, q, p) != kin::Status::ok) continue;
      const Eigen::Vector3d c = p.translation();
      const Eigen::Vector3d x = p.linear().col(0), y = p.linear().col(1), z = p.linear().col(2);
      // Start at 80 mm or a seventh of the tool's distance from the base, shrink until it passes.
      for (double a = std::min(0.08, c.norm() / 7.0); a >= 0.005; a *= 0.7) {
        DemoPlan t;
        t.movej = movej_text(ch, q, t.work);
        kin::Pose pw;
        kin::forward(ch, t.work, pw);
        const Eigen::Vector3d c0 = pw.translation();
        const Eigen::Vector3d pts[] = {c0 + a * x, c0 + a * x + a * y, c0 + a * y, c0};
        for (const Eigen::Vector3d& pt : pts) {
          Eigen::Vector3d typed;
          t.movel.push_back(movel_text(pt, typed));
          t.corner.push_back(typed);
        }
        // As a sender would stream it: back off along the tool axis, then across, relative.
        Eigen::Vector3d d1, d2;
        t.gcode = {"G21 G91", gmove_text(-0.4 * a * z, d1, " F6000"), gmove_text(-0.5 * a * (x + y), d2, ""), "G90"};
        t.gcode_end = t.corner.back() + d1 + d2;
        std::vector<std::string> all = t.movel;
        all.insert(all.end(), t.gcode.begin(), t.gcode.end());
        if (passes_check(app, t.work, all)) return t;
      }
    }
    plan.why_joints_only = "no rectangle in the tool's plane passed the path check";
  } else {
    plan.why_joints_only = "fewer than 6 joints";
  }
  // Joint moves only: to the first pose, to another, and back.
  for (std::size_t i = 1; i < poses.size(); ++i) {
    kin::JointVector typed;
    const std::string mj = movej_text(ch, poses[i], typed);
    if ((typed - plan.work).cwiseAbs().maxCoeff() > 1e-3 && passes_check(app, plan.work, {mj})) {
      plan.movej2 = mj;
      plan.work2 = typed;
      break;
    }
  }
  return plan;
}

int run_demo(App& app) {
  DemoRunner d{app, {}, 0, true};
  std::vector<Reached> reached;
  const kin::Chain& ch = app.chain;
  const int n = ch.n_joints;
  bool prismatic = false;
  for (int j = 0; j < n; ++j) prismatic = prismatic || ch.joint(j).type == kin::JointType::prismatic;
  const char* joint_unit = prismatic ? "deg/mm" : "deg";
  auto q_act = [&] {
    const Telemetry t = app.ctl->telemetry();
    kin::JointVector q(n);
    for (int j = 0; j < n; ++j) q[j] = t.q_act[static_cast<std::size_t>(j)];
    return q;
  };
  // The error once the drives have settled: `wait` answers when the trajectory ends, and the
  // drives' feedback arrives a cycle or two later (more on a loaded machine), so the error
  // is sampled for up to 1 s until it is under 0.01 (deg or mm) and the smallest is taken,
  // as a drive's in-position window would.
  auto settled = [](const auto& err) {
    double e = err();
    for (int i = 0; i < 100 && e >= 0.01; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
      e = std::min(e, err());
    }
    return e;
  };
  // Largest joint error in deg (mm for a prismatic joint).
  auto joint_err = [&](const kin::JointVector& goal) {
    return settled([&] {
      const kin::JointVector q = q_act();
      double e = 0;
      for (int j = 0; j < n; ++j) e = std::max(e, std::fabs(joint_to_user(ch, j, q[j] - goal[j])));
      return e;
    });
  };
  auto pos_err_mm = [&](const Eigen::Vector3d& p) {
    return settled([&] {
      kin::Pose x;
      kin::forward(ch, q_act(), x);
      return (x.translation() - p).norm() * 1e3;
    });
  };
  std::printf("== armfw demo: %s, %d joints, virtual drives on the in-process CAN bus, %.0f Hz loop\n",
              app.cfg.robot.c_str(), n, app.cfg.rate_hz);
  std::printf("   (progress lines while a move runs are the `status` answer)\n");
  d.run("help movel", false);
  d.run("enable", false);
  // Wait for operation enabled.
  for (int i = 0; i < 400 && app.ctl->telemetry().state == ArmState::enabling; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  d.run("status", false);
  d.run("park");
  d.run("wait");
  const kin::JointVector park = app.console->tail();
  reached.push_back({"park", joint_err(park), joint_unit});

  const DemoPlan plan = plan_demo(app, park);
  if (plan.movej.empty()) {
    std::printf("== no work pose of %s passed the checks (%s)\n", app.cfg.robot.c_str(), plan.why_joints_only.c_str());
    ++d.errors;
  } else {
    std::printf("== work pose: a fraction of each joint's range from the park pose, checked (limits, Jacobian, path)%s%s\n",
                plan.why_joints_only.empty() ? "" : "; joint moves only: ", plan.why_joints_only.c_str());
    d.run(plan.movej);
    d.run("wait");
    reached.push_back({"movej work pose", joint_err(plan.work), joint_unit});
    d.run("fk", false);
  }
  if (!plan.movel.empty()) {
    for (std::size_t k = 0; k < plan.movel.size(); ++k) {
      d.run(plan.movel[k]);
      d.run("wait");
      reached.push_back({"movel corner " + std::to_string(k + 1), pos_err_mm(plan.corner[k]), "mm"});
    }
    // The same as G-code (as a sender would stream it), relative moves.
    for (const std::string& l : plan.gcode) d.run(l);
    d.run("M400");
    reached.push_back({"G-code relative moves", pos_err_mm(plan.gcode_end), "mm"});
    d.run("M114", false);
  } else if (!plan.movej2.empty()) {
    d.run(plan.movej2);
    d.run("wait");
    reached.push_back({"movej second pose", joint_err(plan.work2), joint_unit});
    d.run(plan.movej);
    d.run("wait");
    reached.push_back({"movej back to the work pose", joint_err(plan.work), joint_unit});
  }
  // A refused target: far outside the workspace, nothing moves.
  double reach = 1.0;
  for (int r = 0; r < ch.n_rows; ++r) reach += std::fabs(ch.rows[static_cast<std::size_t>(r)].a) + std::fabs(ch.rows[static_cast<std::size_t>(r)].d);
  for (int j = 0; j < n; ++j)
    if (ch.joint(j).type == kin::JointType::prismatic && std::isfinite(ch.joint(j).upper)) reach += std::fabs(ch.joint(j).upper);
  char far[64];
  std::snprintf(far, sizeof far, "movel %.0f 0 0", 10.0 * reach * 1e3);
  std::printf("== a target outside the workspace (refused, nothing moves):\n");
  const int before = d.errors;
  d.run(far);
  if (d.errors == before) ++d.errors;  // it had to be refused
  else --d.errors;                     // expected
  // Feed hold during a move, then resume.
  d.run("park");
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  std::printf("> ! (feed hold)\n");
  app.console->feed(d.s, "!");
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  std::printf("    status: %s\n", app.console->status_text().c_str());
  std::printf("> ~ (resume)\n");
  app.console->feed(d.s, "~");
  d.run("wait");
  reached.push_back({"park after feed hold", joint_err(park), joint_unit});
  d.run("stats", false);
  d.run("disable", false);

  if (g_quit) {
    std::printf("\n== interrupted (SIGINT or SIGTERM): the arm was stopped\n  result: FAIL\n");
    std::fflush(stdout);
    return 1;
  }
  const Telemetry t = app.ctl->telemetry();
  std::printf("\n== summary\n");
  std::printf("  %-34s %s\n", "move", "final error");
  for (const auto& r : reached) std::printf("  %-34s %.4f %s\n", r.what.c_str(), r.err, r.unit);
  std::printf("  unexpected errors: %d\n", d.errors);
  std::printf("  loop: %llu cycles at %.0f Hz, %llu overruns, wake-up latency us min/mean/p99/max %.1f/%.1f/%.1f/%.1f, "
              "compute us %.1f/%.1f/%.1f/%.1f, max following error %.3f deg\n",
              static_cast<unsigned long long>(t.cycles), app.cfg.rate_hz, static_cast<unsigned long long>(t.overruns),
              t.latency.min_us, t.latency.mean_us, t.latency.p99_us, t.latency.max_us, t.compute.min_us, t.compute.mean_us,
              t.compute.p99_us, t.compute.max_us, t.max_following_error * 180.0 / M_PI);
  bool ok = d.errors == 0;
  for (const auto& r : reached) ok = ok && r.err < (std::strcmp(r.unit, "mm") == 0 ? 1.0 : 0.1);
  std::printf("  result: %s\n", ok ? "PASS" : "FAIL");
  std::fflush(stdout);
  return ok ? 0 : 1;
}

int run_bench(App& app, double seconds) {
  // Keep moves of every kind in progress: alternate joint moves and a dwell.
  DemoRunner d{app, {}, 0, false};
  d.run("enable", false);
  for (int i = 0; i < 400 && app.ctl->telemetry().state == ArmState::enabling; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  const double t_end = now_s() + seconds;
  const int n = app.chain.n_joints;
  int flip = 0;
  while (now_s() < t_end && !g_quit) {
    if (app.ctl->telemetry().queued < 2) {
      std::string mj = "movej";
      for (int j = 0; j < n; ++j) mj += flip ? " 20" : " -20";
      flip ^= 1;
      Session s;
      app.console->execute(s, mj + " speed=80");
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  // Force a summary refresh: the RT thread publishes summaries every 64 cycles.
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  print_stats_json(app.ctl->telemetry(), app.cfg.rate_hz);
  return 0;
}

#ifdef SERVOARM_WITH_SIM
/// The virtual buses of --sim, stepped by one RtLoop pre-cycle hook before each control cycle:
/// the CiA 402 drives' plant (if any joint is CiA 402) and one MitPlant per MIT interface.
/// With --plant dynamic on an arm of MIT motors (`arm` set), before the step each virtual motor
/// moves its joint's inertia of the arm (the mass matrix's diagonal at the pose the controller
/// last read, actuator side) and, while powered, carries the arm's gravity torque at that pose;
/// an unpowered one carries none (the arm rests as if supported). Joints are decoupled: what
/// one joint's motion does to another is not modelled.
struct SimPlants {
  sim::SimPlant* cia = nullptr;
  std::vector<sim::MitPlant*> mit;
  struct MitJoint {
    sim::VirtualMitMotor* motor;
    int joint;
    double k;  ///< actuator rad per joint rad (direction x transmission)
  };
  std::vector<MitJoint> mit_joints;
  const kin::Chain* arm = nullptr;
  hal::ServoBus* servo = nullptr;
  kin::MassMatrix M;
  kin::JointVector q, g;
  void load_arm() {
    q = kin::JointVector::Zero(arm->n_joints);
    for (int j = 0; j < arm->n_joints; ++j) q[j] = servo->feedback(static_cast<std::size_t>(j)).position;
    if (kin::mass_matrix(*arm, q, M) != kin::Status::ok || kin::gravity_torques(*arm, q, g) != kin::Status::ok) return;
    for (const MitJoint& m : mit_joints) {
      m.motor->params().inertia = M(m.joint, m.joint) / (m.k * m.k);
      m.motor->load_torque = m.motor->enabled() ? -g[m.joint] / m.k : 0.0;
    }
  }
  static void step_hook(void* ctx, std::int64_t now_ns) {
    auto* s = static_cast<SimPlants*>(ctx);
    if (s->cia != nullptr) s->cia->step(now_ns);
    if (s->arm != nullptr) s->load_arm();
    for (sim::MitPlant* m : s->mit) m->step(now_ns);
  }
};
#endif

}  // namespace

int main(int argc, char** argv) {
  FwConfig cfg;
  bool sim = false, demo = false, interactive = false, pty = false, no_stdin = false, bus_load = false;
  std::string dialect;
  std::string plant_kind = "first-order";
  struct Push {
    int joint;
    double amplitude, frequency, phase;
  };
  std::vector<Push> pushes;
  std::vector<std::pair<int, double>> motor_temps;  // --motor-temperature: (joint, deg C)
  std::string config_file, frames_file, programs_dir, points_file, robot, serial, can_console;
  double bench = -1, rate = -1;
  int priority = -1, cpu = -2, baud = -1;
  int api_ws = -2, api_tcp = -2;  // -2: not given
  int foxglove_port = -2;
  std::string record_dir;
  std::string api_tokens;
  std::string api_tls_cert, api_tls_key;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&](const char* what) -> const char* {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "armfw: %s needs a value\n", what);
        std::exit(2);
      }
      return argv[++i];
    };
    auto number = [&](const char* what, double lo, double hi) {
      const char* v = value(what);
      double d = 0;
      if (parse_decimal(v, d) != Num::ok || d < lo || d > hi) {
        std::fprintf(stderr, "armfw: %s: '%s' is not a number within %g..%g\n", what, v, lo, hi);
        std::exit(2);
      }
      return d;
    };
    if (a == "--sim") sim = true;
    else if (a == "--robot") robot = value("--robot");
    else if (a == "--config") config_file = value("--config");
    else if (a == "--frames") frames_file = value("--frames");
    else if (a == "--programs") programs_dir = value("--programs");
    else if (a == "--points") points_file = value("--points");
    else if (a == "--demo") demo = true;
    else if (a == "--interactive") interactive = true;
    else if (a == "--bench-loop") bench = number("--bench-loop", 0.1, 86400);
    else if (a == "--rate") rate = number("--rate", 250, 4000);
    else if (a == "--priority") priority = static_cast<int>(number("--priority", 0, 99));
    else if (a == "--cpu") cpu = static_cast<int>(number("--cpu", 0, 1023));
    else if (a == "--pty") pty = true;
    else if (a == "--plant") {
      plant_kind = value("--plant");
      if (plant_kind != "first-order" && plant_kind != "dynamic") {
        std::fprintf(stderr, "armfw: --plant: '%s' is not first-order or dynamic\n", plant_kind.c_str());
        return 2;
      }
    }
    else if (a == "--push") {
      const char* v = value("--push");
      Push p{0, 0, 0, 0};
      double deg = 0;
      char tail = 0;
      const int got = std::sscanf(v, "%d:%lf:%lf:%lf%c", &p.joint, &p.amplitude, &p.frequency, &deg, &tail);
      if ((got != 3 && got != 4) || p.joint < 1 || p.joint > 16 || !std::isfinite(p.amplitude) ||
          std::fabs(p.amplitude) > 1e4 || !(p.frequency >= 0 && p.frequency <= 100) || !std::isfinite(deg)) {
        std::fprintf(stderr, "armfw: --push: '%s' is not J:NM:HZ[:DEG] (joint 1..16, |NM| <= 10000, HZ 0..100)\n", v);
        return 2;
      }
      if (pushes.size() >= 8) {
        std::fprintf(stderr, "armfw: --push: at most 8\n");
        return 2;
      }
      p.joint -= 1;
      p.phase = deg * M_PI / 180.0;
      pushes.push_back(p);
    }
    else if (a == "--motor-temperature") {
      const char* v = value("--motor-temperature");
      int j = 0;
      double t = 0;
      char tail = 0;
      if (std::sscanf(v, "%d:%lf%c", &j, &t, &tail) != 2 || j < 1 || j > 16 || !(t >= -40 && t <= 200)) {
        std::fprintf(stderr, "armfw: --motor-temperature: '%s' is not J:DEGC (joint 1..16, -40..200 deg C)\n", v);
        return 2;
      }
      motor_temps.emplace_back(j - 1, t);
    }
    else if (a == "--dialect") {
      dialect = value("--dialect");
      if (dialect != "grbl" && dialect != "native") {
        std::fprintf(stderr, "armfw: --dialect: '%s' is not grbl or native\n", dialect.c_str());
        return 2;
      }
    }
    else if (a == "--serial") serial = value("--serial");
    else if (a == "--can-console") can_console = value("--can-console");
    else if (a == "--baud") baud = static_cast<int>(number("--baud", 1, 4000000));
    else if (a == "--no-stdin") no_stdin = true;
    else if (a == "--api-ws") api_ws = static_cast<int>(number("--api-ws", 0, 65535));
    else if (a == "--api-tcp") api_tcp = static_cast<int>(number("--api-tcp", 0, 65535));
    else if (a == "--api-tokens") api_tokens = value("--api-tokens");
    else if (a == "--api-tls-cert") api_tls_cert = value("--api-tls-cert");
    else if (a == "--api-tls-key") api_tls_key = value("--api-tls-key");
    else if (a == "--foxglove-port") foxglove_port = static_cast<int>(number("--foxglove-port", 0, 65535));
    else if (a == "--record-dir") record_dir = value("--record-dir");
    else if (a == "--api-reference") {
#ifdef SERVOARM_WITH_API
      std::fputs(api::api_reference_markdown().c_str(), stdout);
      return 0;
#else
      std::fprintf(stderr, "armfw: built without the network API (libwebsockets-dev, nlohmann-json3-dev)\n");
      return 2;
#endif
    }
    else if (a == "--bus-load") bus_load = true;
    else if (a == "--bus-load-reference") {
      std::fputs(bus_load_reference_markdown().c_str(), stdout);
      return 0;
    }
    else if (a == "--config-keys") {
      std::fputs(config_keys_text().c_str(), stdout);
      return 0;
    } else if (a == "--config-reference") {
      std::fputs(config_reference_markdown().c_str(), stdout);
      return 0;
    } else if (a == "-h" || a == "--help") return usage(stdout, 0);
    else {
      std::fprintf(stderr, "armfw: unknown argument '%s'\n", a.c_str());
      return usage(stderr, 2);
    }
  }
  if (!pushes.empty() && plant_kind != "dynamic") {
    std::fprintf(stderr, "armfw: --push needs --plant dynamic (it is an external torque on the rigid-body arm)\n");
    return 2;
  }
  if (plant_kind == "dynamic" && !sim) {
    std::fprintf(stderr, "armfw: --plant dynamic needs --sim (it is the virtual drives' arm)\n");
    return 2;
  }
  if (!sim && config_file.empty()) {
    std::fprintf(stderr, "armfw: give --sim or --config FILE\n");
    return usage(stderr, 2);
  }
  if (!config_file.empty()) {
    // --bus-load shows a load the check refuses: everything else is checked as at start.
    const std::string e = load_config_file(config_file, cfg, !bus_load);
    if (!e.empty()) {
      std::fprintf(stderr, "armfw: config refused: %s\n", e.c_str());
      return 2;
    }
  }
  if (bus_load) {
    if (sim) cfg.can = "sim";
    if (!robot.empty()) cfg.robot = robot;
    if (rate > 0) cfg.rate_hz = rate;
    std::size_t joints = cfg.drives.size();
    if (joints == 0) {
      const kin::LoadResult lr = kin::load_robot(cfg.robot);
      if (!lr.ok) {
        std::fprintf(stderr, "armfw: robot: %s\n", lr.error.c_str());
        return 2;
      }
      joints = static_cast<std::size_t>(lr.chain.n_joints);
    }
    std::fputs(bus_load_table(cfg, joints).c_str(), stdout);
    return bus_load_problem(cfg, joints).empty() ? 0 : 1;
  }
  if (!config_file.empty()) {
    const std::string w = bus_load_warning(cfg, cfg.drives.size());
    if (!w.empty()) std::fprintf(stderr, "armfw: warning: %s\n", w.c_str());
  }
  // The frames file: next to the configuration file (a relative console.frames_file), or
  // --frames; armfw --sim without --config keeps none unless told.
  // App keeps only an absolute path (a relative one would depend on the working directory).
  // The same for the programs folder and the teach points (programs.dir, programs.points_file).
  const auto resolve = [&](std::string& key, const std::string& flag) {
    if (!flag.empty()) key = flag;
    else if (config_file.empty()) key.clear();
    else if (!key.empty() && key[0] != '/') {
      const std::size_t slash = config_file.rfind('/');
      key = (slash == std::string::npos ? std::string() : config_file.substr(0, slash + 1)) + key;
    }
    if (!key.empty() && key[0] != '/') {
      char cwd[4096];
      if (::getcwd(cwd, sizeof cwd) != nullptr) key = std::string(cwd) + "/" + key;
    }
  };
  resolve(cfg.console_frames_file, frames_file);
  resolve(cfg.programs_dir, programs_dir);
  resolve(cfg.programs_points_file, points_file);
  resolve(cfg.api_tokens_file, api_tokens);
  resolve(cfg.api_tls_cert, api_tls_cert);
  resolve(cfg.api_tls_key, api_tls_key);
  resolve(cfg.record_dir, record_dir);
  // Where armfw keeps files must exist at start, not first fail when a tool, point or
  // program is saved: the programs folder, and the folders of the frames and points files.
  // Given on the command line, a missing one is refused; from the configuration (which may
  // be checked on another machine than the robot's) it is named in a warning at start.
  {
    const auto is_dir = [](const std::string& p) {
      struct stat st {};
      return ::stat(p.c_str(), &st) == 0 && S_ISDIR(st.st_mode);
    };
    const auto folder = [](const std::string& p) { return p.substr(0, std::max<std::size_t>(p.rfind('/'), 1)); };
    const struct {
      const char* key;
      std::string path;
      bool is_folder, flag;
    } places[] = {{"programs.dir", cfg.programs_dir, true, !programs_dir.empty()},
                  {"console.frames_file", cfg.console_frames_file, false, !frames_file.empty()},
                  {"programs.points_file", cfg.programs_points_file, false, !points_file.empty()}};
    for (const auto& w : places) {
      if (w.path.empty()) continue;
      const std::string f = w.is_folder ? w.path : folder(w.path);
      if (is_dir(f)) continue;
      if (w.flag) {
        std::fprintf(stderr, "armfw: config refused: %s: %s: no such folder\n", w.key, f.c_str());
        return 2;
      }
      std::fprintf(stderr, "armfw: warning: %s: %s: no such folder (saving there fails until it exists)\n", w.key,
                   f.c_str());
    }
  }
  if (sim) cfg.can = "sim";
  // The virtual drives answer the bring-up's SDOs from a thread of normal priority: on a busy
  // host it can be starved past the 100 ms a real drive is given, and the bring-up would fail
  // naming a drive that is not at fault. Without a configuration file they are given 1 s.
  if (sim && config_file.empty()) cfg.sdo_timeout_ms = std::max(cfg.sdo_timeout_ms, 1000.0);
  if (!robot.empty()) cfg.robot = robot;
  if (rate > 0) cfg.rate_hz = rate;
  if (priority >= 0) cfg.priority = priority;
  if (cpu >= -1) cfg.cpu = cpu;
  if (pty) cfg.console_pty = true;
  if (!dialect.empty()) cfg.console_dialect = dialect, cfg.console_pty_dialect = cfg.console_serial_dialect = "";
  if (!serial.empty()) cfg.console_serial = serial;
  if (baud > 0) cfg.console_baud = baud;
  if (!can_console.empty()) cfg.console_can = can_console;
  if (no_stdin) cfg.console_stdin = false;

  App app;
  App::SimFactory make_sim;
#ifdef SERVOARM_WITH_SIM
  std::unique_ptr<sim::SimPlant> plant;
  make_sim = [&plant](hal::Clock& clock, const std::vector<std::uint8_t>& nodes) -> hal::CanBus* {
    if (plant) return nullptr;  // --sim runs one in-process bus: a second interface (drive.can) is refused
    plant = std::make_unique<sim::SimPlant>(clock, nodes);
    return &plant->master_bus();
  };
  // Drive groups of the MIT families: one MitPlant per interface, a virtual motor per joint
  // from its [[drive]] table (model, id, master id, CAN FD). A joint homed by hard stop gets an
  // end stop 10 deg (joint side) from where its motor starts, in its homing direction.
  std::vector<std::unique_ptr<sim::MitPlant>> mit_plants;
  std::vector<int> temps_applied;  // the joints of --motor-temperature that are virtual MIT motors
  app.sim_group = [&mit_plants, &cfg, &motor_temps, &temps_applied](hal::Clock& clock,
                                                                   const DriveGroupPlan& p) -> hal::CanBus* {
    std::vector<sim::MitMotorSpec> specs;
    for (std::size_t k = 0; k < p.joints.size(); ++k) {
      const DriveConfig& d = cfg.drives[static_cast<std::size_t>(p.joints[k])];
      sim::MitMotorSpec s;
      s.profile = hal::mit::find_profile(d.motor);
      if (s.profile == nullptr) return nullptr;
      s.id = p.ids[k];
      s.master = static_cast<std::uint16_t>(mit_master_id(d, p.ids[k]));
      s.fd = d.can_fd;
      for (const auto& [j, t] : motor_temps) {
        if (j != p.joints[k]) continue;
        s.params.ambient = t;
        temps_applied.push_back(j);
      }
      specs.push_back(s);
    }
    mit_plants.push_back(std::make_unique<sim::MitPlant>(clock, specs));
    for (std::size_t k = 0; k < p.joints.size(); ++k) {
      const DriveConfig& d = cfg.drives[static_cast<std::size_t>(p.joints[k])];
      if (d.homing_method != "hard_stop") continue;
      const double gear = d.gear_ratio != 0 ? d.gear_ratio : 1.0;  // as the drive factory maps it
      const double at = d.homing_direction * d.direction * gear * 10.0 * M_PI / 180.0;  // actuator rad
      sim::VirtualMitMotor& m = mit_plants.back()->at(k);
      (at < 0 ? m.stop_lo : m.stop_hi) = at;
    }
    return &mit_plants.back()->master_bus();
  };
#else  // built without host_sim (robot-controller build): no virtual drives
  if (cfg.can == "sim") {
    std::fprintf(stderr, "armfw: bus.can = \"sim\" (--sim): this armfw was built without the virtual drives (host_sim)\n");
    return 2;
  }
#endif
  std::string err = app.build(cfg, nullptr, make_sim);
  if (!err.empty()) {
    std::fprintf(stderr, "armfw: %s\n", err.c_str());
    return 2;
  }
#ifdef SERVOARM_WITH_SIM
  for (const auto& mt : motor_temps) {
    if (std::find(temps_applied.begin(), temps_applied.end(), mt.first) == temps_applied.end()) {
      std::fprintf(stderr, "armfw: --motor-temperature: joint %d is not a virtual MIT motor (--sim with a [[drive]] "
                   "family damiao, cubemars_mit or robstride_mit)\n", mt.first + 1);
      return 2;
    }
  }
#else
  if (!motor_temps.empty()) {
    std::fprintf(stderr, "armfw: --motor-temperature: this armfw was built without the virtual drives (host_sim)\n");
    return 2;
  }
#endif
  hal::SimBus* sim_bus = nullptr;  // the virtual drives' bus (console.can = "sim")
#ifdef SERVOARM_WITH_SIM
  if (plant && plant_kind == "dynamic") {
    std::vector<hal::JointScaling> sc;
    for (std::size_t j = 0; j < app.servo->joint_count(); ++j) sc.push_back(app.servo->scaling(j));
    sim::ArmPlantParams pp;
    for (std::size_t k = 0; k < pushes.size(); ++k) {
      if (pushes[k].joint >= static_cast<int>(app.servo->joint_count())) {
        std::fprintf(stderr, "armfw: --push: joint %d, the arm has %zu\n", pushes[k].joint + 1, app.servo->joint_count());
        return 2;
      }
      pp.pushes[k] = {pushes[k].joint, pushes[k].amplitude, pushes[k].frequency, pushes[k].phase};
    }
    const std::string e = plant->use_dynamic_plant(app.chain, sc, pp);
    if (!e.empty()) {
      std::fprintf(stderr, "armfw: --plant dynamic: %s\n", e.c_str());
      return 2;
    }
  }
  if (plant && mit_plants.empty()) {
    // Virtual drives start at the in-limit value closest to 0 (a prismatic joint whose
    // range excludes 0 could otherwise never be enabled). Their drive i is joint i: with MIT
    // joints on other buses that is not so, and they stay at 0.
    std::vector<hal::JointScaling> sc;
    for (std::size_t j = 0; j < app.servo->joint_count(); ++j) sc.push_back(app.servo->scaling(j));
    plant->place_within_limits(app.chain, sc);
  }
  if (plant) {
    plant->start_thread();  // the drives answer the bring-up's SDOs from their own thread
    sim_bus = &plant->bus();
  }
  for (auto& m : mit_plants) m->start_thread();  // and the MIT motors the register reads
#endif
  err = app.boot();
  if (!err.empty()) {
    std::fprintf(stderr, "armfw: %s\n", err.c_str());
    return 1;
  }
  // [dynamics] parts asked for that cannot run on this robot / these drives: said, left off
  // (everything else runs; docs/dynamics.md#using-the-model-in-the-firmware).
  {
    const std::string notes = app.dynamics_notes();
    std::size_t a = 0;
    while (a < notes.size()) {
      std::size_t b = notes.find('\n', a);
      if (b == std::string::npos) b = notes.size();
      std::fprintf(stderr, "armfw: dynamics: %s\n", notes.substr(a, b - a).c_str());
      a = b + 1;
    }
  }
  LoopConfig lc;
  lc.rate_hz = app.cfg.rate_hz;
  lc.priority = app.cfg.priority;
  lc.cpu = app.cfg.cpu;
  lc.lock_memory = app.cfg.lock_memory;
#ifdef SERVOARM_WITH_SIM
  SimPlants sim_plants;
#endif
  RtLoop loop(*app.ctl, lc);
#ifdef SERVOARM_WITH_SIM
  if (plant) {
    // --sim: the drive thread served the bring-up (SDO); from now on the control thread
    // steps the virtual drives right before each cycle (docs: firmware, "--sim").
    plant->stop_thread();
    plant->set_frames_at_arrival(true);  // the drives sample at the SYNC, not at the next cycle
    // a host that stalls the loop for more than two cycles pauses the virtual arm with it
    plant->set_pause_after(2 * static_cast<hal::Duration>(1e9 / app.cfg.rate_hz + 0.5));
  }
  for (auto& m : mit_plants) m->stop_thread();
  if (!mit_plants.empty() || plant) {
    // One pre-cycle hook steps every virtual bus: the CiA 402 plant and each MIT plant.
    sim_plants.cia = plant.get();
    for (auto& m : mit_plants) sim_plants.mit.push_back(m.get());
    if (plant_kind == "dynamic" && !plant) {  // an arm of MIT motors on the dynamic plant
      char why[256];
      if (kin::dynamics_refusal(app.chain, why, sizeof why)) {
        std::fprintf(stderr, "armfw: --plant dynamic: %s\n", why);
        return 2;
      }
      if (!pushes.empty()) {
        std::fprintf(stderr, "armfw: --push: the virtual MIT motors take no scripted torque (CiA 402 virtual drives do)\n");
        return 2;
      }
      for (std::size_t j = 0; j < app.servo->joint_count(); ++j) {
        const hal::ArmServoBus::Slot sl = app.servo->slot(j);
        const hal::JointScaling sc = app.servo->scaling(j);
        sim_plants.mit_joints.push_back({&mit_plants.at(sl.group)->at(sl.local), static_cast<int>(j),
                                         sc.direction * (sc.gear_ratio != 0 ? sc.gear_ratio : 1.0)});
      }
      sim_plants.arm = &app.chain;
      sim_plants.servo = app.servo.get();
    }
    loop.set_pre_cycle(&SimPlants::step_hook, &sim_plants);
  }
#endif
  if (!loop.start()) {
    std::fprintf(stderr, "armfw: cannot start the control thread\n");
    return 1;
  }
  if (!loop.warnings().empty()) std::fprintf(stderr, "armfw: %s", loop.warnings().c_str());
  // The network API: its own thread for the sockets; its service calls run on this (the
  // console) thread, in pump(), as the console's do: the service has one caller.
#ifdef SERVOARM_WITH_API
  std::unique_ptr<api::ApiServer> api_server;
  api::ServiceContext api_cx;
  std::unique_ptr<StreamService> stream;
  std::unique_ptr<api::FoxgloveServer> foxglove;
#else
  struct NoApi {
    int wake_fd() const { return -1; }
    void pump(int) {}
    void stop() {}
  };
  std::unique_ptr<NoApi> api_server, foxglove;
  const int api_cx = 0;
#endif
#ifdef SERVOARM_WITH_MQTT
  std::unique_ptr<api::MqttBridge> mqtt;
#else
  struct NoMqtt {
    int wake_fd() const { return -1; }
    void stop() {}
  };
  std::unique_ptr<NoMqtt> mqtt;
#endif
  const bool want_api = app.cfg.api_enabled || api_ws >= 0 || api_tcp >= 0;
  const bool want_foxglove = app.cfg.foxglove_enabled || foxglove_port >= 0;
  if (want_api || app.cfg.mqtt_enabled || want_foxglove) {
#ifndef SERVOARM_WITH_API
    std::fprintf(stderr, "armfw: built without the network API (libwebsockets-dev, nlohmann-json3-dev)%s\n",
                 want_api ? "" : ": mqtt.enabled and foxglove.enabled need it");
    loop.stop();
    return 2;
#else
#ifndef SERVOARM_WITH_MQTT
    if (app.cfg.mqtt_enabled) {
      std::fprintf(stderr, "armfw: mqtt.enabled: built without the MQTT bridge (libmosquitto-dev)\n");
      loop.stop();
      return 2;
    }
#endif
    api::ApiConfig ac;
    ac.bind = app.cfg.api_bind;
    const bool flags = api_ws >= 0 || api_tcp >= 0;  // the flags name the ports: only those listen
    ac.ws_port = flags ? (api_ws >= 0 ? api_ws : -1) : (app.cfg.api_ws_port > 0 ? app.cfg.api_ws_port : -1);
    ac.tcp_port = flags ? (api_tcp >= 0 ? api_tcp : -1) : (app.cfg.api_tcp_port > 0 ? app.cfg.api_tcp_port : -1);
    ac.tokens_file = app.cfg.api_tokens_file;
    ac.tls_cert = app.cfg.api_tls_cert;
    ac.tls_key = app.cfg.api_tls_key;
    ac.max_message = static_cast<std::size_t>(app.cfg.api_max_message_kb) * 1024;
    ac.max_rate_hz = app.cfg.api_max_rate_hz;
    ac.max_clients = app.cfg.api_max_clients;
    ac.client_buffer = static_cast<std::size_t>(app.cfg.api_client_buffer_kb) * 1024;
    ac.partial_timeout_s = app.cfg.api_partial_timeout_s;
    ac.rate_hz = app.cfg.rate_hz;
    ac.robot = app.cfg.robot;
    ac.safety_on = app.console->config().safety.enabled;
    ac.safety_checksum = app.console->config().safety_checksum;
    // the browser pendant (docs/pendant.md): the installed files; with --sim the source tree's
    // built page first, so a build tree's armfw serves the page of its own sources
    for (const char* dir : {sim ? SERVOARM_WEB_TREE_DIR : "", SERVOARM_WEB_INSTALL_DIR, "/usr/share/servoarm/web"}) {
      struct stat wst {};
      if (*dir != '\0' && ::stat((std::string(dir) + "/index.html").c_str(), &wst) == 0) {
        ac.web_root = dir;
        break;
      }
    }
    if (want_api) {
      api_server = std::make_unique<api::ApiServer>(ac, *app.ctl, app.chain, app.ctl->limits());
      const std::string e = api_server->start();
      if (!e.empty()) {
        std::fprintf(stderr, "armfw: %s\n", e.c_str());
        loop.stop();
        return 2;
      }
    }
    api_cx.svc = &app.console->service();
    api_cx.ctl = app.ctl.get();
    api_cx.chain = &app.chain;
    api_cx.ik = firmware_ik_solver(app.ik_ready ? app.ik.get() : nullptr);
    api_cx.units = app.console->config().units;
    api_cx.programs_dir = app.console->config().programs_dir;
    StreamSettings ss;
    ss.deadman_s = app.cfg.api_stream_deadman_ms * 1e-3;
    ss.clamp_step = app.cfg.api_stream_step == "clamp";
    for (int j = 0; j < app.chain.n_joints; ++j) ss.max_step.push_back(kConfigUnits.joint_in(app.chain, j, app.cfg.api_stream_max_step_deg));
    stream = std::make_unique<StreamService>(app.console->service(), *app.ctl, ss);
    api_cx.stream = stream.get();
    if (api_server)
      std::fprintf(stderr, "armfw: api: WebSocket port %d, TCP port %d on %s\n", api_server->ws_port(),
                   api_server->tcp_port(), ac.bind.c_str());
    if (api_server && api_server->serves_web()) {
      const bool any = ac.bind == "0.0.0.0" || ac.bind == "::";
      const bool v6 = ac.bind.find(':') != std::string::npos && !any;
      std::fprintf(stderr, "armfw: pendant: http://%s%s%s:%d/\n", v6 ? "[" : "", any ? "<this host>" : ac.bind.c_str(),
                   v6 ? "]" : "", api_server->ws_port());
    } else if (api_server && api_server->ws_port() >= 0) {
      std::fprintf(stderr, "armfw: pendant: not served (no index.html in %s)\n", SERVOARM_WEB_INSTALL_DIR);
    }
#ifdef SERVOARM_WITH_MQTT
    if (app.cfg.mqtt_enabled) {
      api::MqttConfig mc;
      mc.host = app.cfg.mqtt_host;
      mc.port = app.cfg.mqtt_port;
      mc.name = app.cfg.mqtt_name;
      mc.username = app.cfg.mqtt_username;
      mc.password_file = app.cfg.mqtt_password_file;
      mc.cafile = app.cfg.mqtt_cafile;
      mc.certfile = app.cfg.mqtt_certfile;
      mc.keyfile = app.cfg.mqtt_keyfile;
      mc.state_rate_hz = app.cfg.mqtt_state_rate_hz;
      mc.keepalive_s = app.cfg.mqtt_keepalive_s;
      mc.rate_hz = app.cfg.rate_hz;
      mqtt = std::make_unique<api::MqttBridge>(mc, *app.ctl, app.chain);
      const std::string e = mqtt->start();
      if (!e.empty()) {
        std::fprintf(stderr, "armfw: %s\n", e.c_str());
        loop.stop();
        return 2;
      }
      std::fprintf(stderr, "armfw: mqtt: servoarm/%s/ at %s:%d\n", mc.name.c_str(), mc.host.c_str(), mc.port);
    }
#endif
#endif
  }
#ifdef SERVOARM_WITH_API
  if (want_foxglove) {
    api::FoxgloveConfig fc;
    fc.bind = app.cfg.foxglove_bind;
    fc.port = foxglove_port >= 0 ? foxglove_port : app.cfg.foxglove_port;
    fc.state_rate_hz = app.cfg.foxglove_state_rate_hz;
    fc.tf_rate_hz = app.cfg.foxglove_tf_rate_hz;
    fc.rate_hz = app.cfg.rate_hz;
    fc.name = "servoarm " + app.cfg.robot;
    foxglove = std::make_unique<api::FoxgloveServer>(fc, *app.ctl, app.chain);
    if (const std::string e = foxglove->start(); !e.empty()) {
      std::fprintf(stderr, "armfw: %s\n", e.c_str());
      loop.stop();
      return 2;
    }
    std::fprintf(stderr, "armfw: foxglove: ws://%s:%d (foxglove.websocket.v1)\n", fc.bind.c_str(), foxglove->port());
  }
#endif
  // The API's and the MQTT bridge's requests run here, on the console thread (the service's one caller).
  const auto pump_network = [&] {
    if (api_server) api_server->pump(api_cx);
    if (foxglove) foxglove->pump(api_cx);
#ifdef SERVOARM_WITH_MQTT
    if (mqtt) mqtt->pump(api_cx, api_server.get());
#endif
  };
  const auto network_fds = [&](std::vector<pollfd>& pf) {
    if (api_server) pf.push_back({api_server->wake_fd(), POLLIN, 0});
    if (mqtt) pf.push_back({mqtt->wake_fd(), POLLIN, 0});
  };
  signal(SIGINT, on_signal);
  signal(SIGTERM, on_signal);
  signal(SIGPIPE, SIG_IGN);

  int rc = 0;
  if (bench > 0) {
    rc = run_bench(app, bench);
  } else {
    if (demo) rc = run_demo(app);
    if (!demo || interactive) {
      std::vector<FdTransport*> ts;
      FdTransport in, pt, se, ct;
      CanConsole can;
      auto dialect_of = [&](const std::string& own) {
        const std::string& d = own.empty() ? app.cfg.console_dialect : own;
        return d == "grbl" ? Dialect::grbl : Dialect::native;
      };
      in.dialect = dialect_of("");
      pt.dialect = dialect_of(app.cfg.console_pty_dialect);
      se.dialect = dialect_of(app.cfg.console_serial_dialect);
      ct.dialect = dialect_of("");
      if (app.cfg.console_stdin) {
        in.name = "stdin";
        in.rd = 0;
        in.wr = 1;
        ts.push_back(&in);
      }
      if (app.cfg.console_pty) {
        const std::string e = open_pty(pt);
        if (!e.empty()) {
          std::fprintf(stderr, "armfw: pty: %s\n", e.c_str());
          rc = 1;
        } else {
          std::fprintf(stderr, "armfw: console pty: %s\n", pt.path.c_str());
          ts.push_back(&pt);
        }
      }
      if (!app.cfg.console_serial.empty()) {
        const std::string e = open_serial(se, app.cfg.console_serial, app.cfg.console_baud);
        if (!e.empty()) {
          std::fprintf(stderr, "armfw: serial console: %s\n", e.c_str());
          rc = 1;
        } else {
          std::fprintf(stderr, "armfw: serial console on %s at %d baud\n", se.path.c_str(), app.cfg.console_baud);
          ts.push_back(&se);
        }
      }
      if (!app.cfg.console_can.empty()) {
        CanConsoleConfig cc;
        cc.iface = app.cfg.console_can;
        cc.rx_id = static_cast<std::uint32_t>(app.cfg.console_can_rx_id);
        cc.tx_id = static_cast<std::uint32_t>(app.cfg.console_can_tx_id);
        const std::string e = can.open(cc, sim_bus, ct);
        if (!e.empty()) {
          std::fprintf(stderr, "armfw: can console: %s\n", e.c_str());
          rc = 1;
        } else {
          std::fprintf(stderr, "armfw: can console: ISO-TP on %s\n", ct.path.c_str());
          ts.push_back(&ct);
        }
      }
      if (rc == 0 && !ts.empty()) {
        std::fprintf(stderr, "armfw: %s ready (%d joints, %.0f Hz); type help\n", app.cfg.robot.c_str(), app.chain.n_joints,
                     app.cfg.rate_hz);
        if (!api_server && !mqtt && !foxglove) {
          serve_consoles(*app.console, ts, app.cfg.console_stdin, &g_quit);
        } else {
          // Consoles and the API on one thread: wait for console input or API requests (at most
          // 10 ms, the console's own round), then run the API's requests and one console round.
          ConsoleServer srv(*app.console, ts);
          for (;;) {
            if (g_quit) break;
            std::vector<pollfd> pf;
            network_fds(pf);
            for (const FdTransport* t : ts) {
              if (t->rd >= 0 && !t->eof && !t->no_peer) pf.push_back({t->rd, POLLIN, 0});
              if (t->wr >= 0 && !t->pending.empty()) pf.push_back({t->wr, POLLOUT, 0});
            }
            ::poll(pf.data(), pf.size(), 10);
            pump_network();
            if (!srv.round(0, app.cfg.console_stdin)) break;
          }
        }
      } else if (rc == 0 && (api_server || mqtt)) {
        std::fprintf(stderr, "armfw: %s ready (%d joints, %.0f Hz); API only\n", app.cfg.robot.c_str(), app.chain.n_joints,
                     app.cfg.rate_hz);
        while (!g_quit) {
          std::vector<pollfd> pf;
          network_fds(pf);
          ::poll(pf.data(), pf.size(), 10);
          pump_network();
        }
      }
      can.stop();
    }
  }
  // Shut down: stop motion, power down, stop the loop, statistics at exit.
  if (api_server) api_server->stop();
  if (foxglove) foxglove->stop();
  if (mqtt) mqtt->stop();
  {
    Session s;
    app.console->execute(s, "stop");
    for (int i = 0; i < 400 && app.ctl->telemetry().state == ArmState::stopping; ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    app.console->execute(s, "disable");
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  loop.stop();
#ifdef SERVOARM_WITH_SIM
  if (plant) plant->stop_thread();
#endif
  if (bench <= 0) std::fprintf(stderr, "armfw: exit: %s\n", app.console->stats_text().c_str());
#ifdef SERVOARM_WITH_SIM
  if (plant && plant->paused() > 0)
    std::fprintf(stderr, "armfw: the virtual arm paused %.0f ms in all while the host did not run the loop\n",
                 double(plant->paused()) * 1e-6);
#endif
  return rc;
}
