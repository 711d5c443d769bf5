// SPDX-License-Identifier: Apache-2.0
// armctl plan movej | movel: plan offline, print duration and peaks, write the
// sampled trajectory as CSV and as an SVG plot (position / velocity /
// acceleration per joint, drawn by hand as SVG text).
#include "servoarm/armctl/cli_plan.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "servoarm/armctl/cli_common.hpp"
#include "servoarm/armctl/cli_svg.hpp"
#include "servoarm/lang/ik_options.hpp"
#include "servoarm/lang/text.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/kinematics/ik.hpp"
#include "servoarm/kinematics/motion_ik.hpp"
#include "servoarm/kinematics/orientation.hpp"
#include "servoarm/kinematics/trajectory.hpp"
#include "servoarm/kinematics/trajectory_cartesian.hpp"

namespace servoarm::fw {

namespace {

const char* kPlanUsage =
    "usage: armctl plan movej --robot NAME|FILE --from q1..qn --to q1..qn [options]\n"
    "       armctl plan movel --robot NAME|FILE --from q1..qn\n"
    "                         (--to q1..qn | --xyz X Y Z [--rpy R P Y | --quat W X Y Z]) [options]\n"
    "\n"
    "Plans a jerk-limited move offline and prints its duration and peak values.\n"
    "movej: every joint starts and arrives together (time-synchronised), from rest to rest.\n"
    "movel: the tool follows the straight line (orientation by slerp); the path is checked\n"
    "       first (IK at every point, joint limits, branch, singularity) and the move is\n"
    "       refused with the reason and place, or slowed near a singularity. IK is armfw's\n"
    "       own (nearest solution within the joint limits), so the samples are armfw's.\n"
    "Units are the description's (built-in models: mm and degrees).\n"
    "\n"
    "options:\n"
    "  --vmax V / --amax A / --jmax J   cap every joint's velocity / acceleration / jerk\n"
    "                                   (joint units per s, s^2, s^3; > 0: leave an option out for\n"
    "                                   the description's limits). Joints without limits in the\n"
    "                                   description get 90 deg/s, 360 deg/s^2, 3600 deg/s^3\n"
    "                                   (prismatic: 250 mm/s, 1000 mm/s^2, 10000 mm/s^3).\n"
    "  --override PCT                   speed override 1..100 (default 100)\n"
    "  --speed V --accel A              movel: tool speed / acceleration (length units/s, /s^2, > 0;\n"
    "                                   default 250 mm/s, 1000 mm/s^2; jerk = 10 x accel, as armfw)\n"
    "  --angular W                      movel: tool angular speed (angle units/s, > 0, default 57.3 deg/s)\n"
    "  --no-slowdown                    movel: refuse instead of slowing near a singularity\n"
    "  --max-duration S                 refuse a move that lasts longer (0 < S <= 86400, default 600 s,\n"
    "                                   armfw's motion.max_move_duration_s)\n"
    "  --rate HZ                        sample rate of the CSV/SVG (1..100000, default 1000; at most\n"
    "                                   1000000 samples per move)\n"
    "  --csv FILE                       t, q1..qn, v1..vn, a1..an per sample (description units)\n"
    "  --svg FILE                       plot of position, velocity, acceleration per joint against time\n"
    "                                   (round ticks, units, legend); movel: and the tool path seen\n"
    "                                   from above (x-y) and from the side (x-z)\n"
    "Bad input (exit 2, one line naming the option): a limit <= 0, a missing value, a movel option\n"
    "given to movej, a move longer than --max-duration or with too many samples (nothing is written),\n"
    "--xyz beyond 1 km, --rpy angles beyond 3600 deg, a --to pose that is not finite.\n";

// Bounds of what armctl plans and writes: a move longer than --max-duration (default
// armfw's motion.max_move_duration_s, 600 s) or more than kMaxSamples samples is refused
// (exit 2) naming the option, before anything is sampled or written.
constexpr double kDefaultMaxDuration = 600;  // s
constexpr double kMaxMaxDuration = 86400;    // s: --max-duration at most one day
constexpr long kMaxSamples = 1000000;
// (--xyz and --rpy bounds: kMaxPositionM, kMaxOrientationDeg in cli_common.hpp)

struct Args {
  std::string kind, robot, csv, svg;
  std::vector<double> from, to, xyz, rpy, quat;
  double vmax = 0, amax = 0, jmax = 0, override_pct = 100, rate = 1000;
  double speed = 0, accel = 0, angular = 0, max_duration = kDefaultMaxDuration;
  bool no_slowdown = false;
  std::vector<std::string> lowered;  // "--vmax 1e-06": the limit options given, for messages
};

bool is_option(const char* s) { return s[0] == '-' && s[1] == '-'; }

// Parses argv (argv[0] = "plan", argv[1] = kind). Returns "" or an error.
std::string parse(int argc, char** argv, Args& a) {
  if (argc < 2) return "plan needs a move kind: movej or movel";
  a.kind = argv[1];
  if (a.kind != "movej" && a.kind != "movel") return "unknown plan kind '" + a.kind + "' (movej or movel)";
  const bool movej = a.kind == "movej";
  for (int i = 2; i < argc; ++i) {
    const std::string o = argv[i];
    auto list = [&](std::vector<double>& out) -> std::string {
      out.clear();
      while (i + 1 < argc && !is_option(argv[i + 1])) {
        double v;
        if (!parse_number(argv[i + 1], v)) return o + ": '" + argv[i + 1] + "' is not a finite number";
        out.push_back(v);
        ++i;
      }
      if (out.empty()) return o + " needs values";
      return "";
    };
    auto one = [&](double& out) -> std::string {
      if (i + 1 >= argc || is_option(argv[i + 1])) return o + " needs a value";
      if (!parse_number(argv[i + 1], out)) return o + ": '" + argv[i + 1] + "' is not a finite number";
      ++i;
      return "";
    };
    // A limit: > 0 (0 does not mean "default": leave the option out for that).
    auto limit = [&](double& out) -> std::string {
      std::string e = one(out);
      if (!e.empty()) return e;
      if (!(out > 0)) return o + " must be > 0, got " + argv[i] + " (leave it out for the default)";
      a.lowered.push_back(o + " " + argv[i]);
      return "";
    };
    auto text = [&](std::string& out) -> std::string {
      if (i + 1 >= argc || is_option(argv[i + 1])) return o + " needs a value";
      out = argv[++i];
      return "";
    };
    auto movel_only = [&]() -> std::string {
      return movej ? o + " is a movel option (movej takes --vmax, --amax, --jmax, --override)" : "";
    };
    std::string e;
    if (o == "--robot") e = text(a.robot);
    else if (o == "--csv") e = text(a.csv);
    else if (o == "--svg") e = text(a.svg);
    else if (o == "--from") e = list(a.from);
    else if (o == "--to") e = list(a.to);
    else if (o == "--xyz") e = movej ? movel_only() : list(a.xyz);
    else if (o == "--rpy") e = movej ? movel_only() : list(a.rpy);
    else if (o == "--quat") e = movej ? movel_only() : list(a.quat);
    else if (o == "--vmax") e = limit(a.vmax);
    else if (o == "--amax") e = limit(a.amax);
    else if (o == "--jmax") e = limit(a.jmax);
    else if (o == "--override") e = one(a.override_pct);
    else if (o == "--rate") e = one(a.rate);
    else if (o == "--max-duration") e = one(a.max_duration);
    else if (o == "--speed") e = movej ? movel_only() : limit(a.speed);
    else if (o == "--accel") e = movej ? movel_only() : limit(a.accel);
    else if (o == "--angular") e = movej ? movel_only() : limit(a.angular);
    else if (o == "--no-slowdown") e = movel_only(), a.no_slowdown = true;
    else return "unknown option '" + o + "' (see armctl plan --help)";
    if (!e.empty()) return e;
  }
  if (a.robot.empty()) return "--robot is required";
  if (a.from.empty()) return "--from is required";
  if (a.kind == "movej" && a.to.empty()) return "movej needs --to";
  if (a.kind == "movel" && a.to.empty() && a.xyz.empty()) return "movel needs --to q1..qn or --xyz X Y Z";
  if (!a.xyz.empty() && a.xyz.size() != 3) return "--xyz needs 3 values";
  if (!a.rpy.empty() && a.rpy.size() != 3) return "--rpy needs 3 values";
  if (!a.quat.empty() && a.quat.size() != 4) return "--quat needs 4 values";
  if (!a.rpy.empty() && !a.quat.empty()) return "give either --rpy or --quat, not both";
  if (!a.to.empty() && !a.xyz.empty()) return "give either --to or --xyz, not both";
  if (!a.to.empty() && (!a.rpy.empty() || !a.quat.empty())) return "--rpy and --quat go with --xyz, not with --to";
  if (!(a.override_pct >= 1 && a.override_pct <= 100)) return "--override must be within 1..100";
  if (a.override_pct < 100) a.lowered.push_back("--override " + num(a.override_pct));
  if (!(a.rate >= 1 && a.rate <= 100000)) return "--rate must be within 1..100000 Hz";
  if (!(a.max_duration > 0 && a.max_duration <= kMaxMaxDuration))
    return "--max-duration must be within 0..86400 s, got " + num(a.max_duration);
  return "";
}

// Refuses (exit 2) a move longer than --max-duration, or with more samples than
// kMaxSamples at --rate, naming what to change. Returns -1 to go on.
int check_duration(const Args& a, double duration) {
  if (!(duration <= a.max_duration)) {
    std::string why;
    for (const std::string& l : a.lowered) why += (why.empty() ? "" : ", ") + l;
    std::fprintf(stderr, "armctl: the move would take %s s, more than --max-duration %s s%s\n", seconds_text(duration).c_str(),
                 num(a.max_duration).c_str(),
                 why.empty() ? " (the description's limits are too low for it)"
                             : (": " + why + (a.lowered.size() > 1 ? " (one of them is too low)" : " is too low")).c_str());
    return kExitUsage;
  }
  const double n = std::floor(duration * a.rate) + 2;
  if (n > static_cast<double>(kMaxSamples)) {
    std::fprintf(stderr, "armctl: --rate %s Hz over the %s s move gives %s samples, more than %ld: lower --rate\n",
                 num(a.rate).c_str(), seconds_text(duration).c_str(), num(n).c_str(), kMaxSamples);
    return kExitUsage;
  }
  return -1;
}

// Joint limits in SI: the description's, defaults where missing, capped by --vmax/--amax/--jmax.
bool apply_limits(kin::Chain& c, const Args& a, bool& defaulted) {
  defaulted = false;
  for (int j = 0; j < c.n_joints; ++j) {
    kin::JointDynamics& d = c.joint(j).dynamics;
    const bool prismatic = c.joint(j).type == kin::JointType::prismatic;
    const double unit = 1.0 / c.joint_user_scale(j);  // SI per user unit
    const double dv = prismatic ? 0.25 : M_PI / 2, da = prismatic ? 1.0 : 2 * M_PI, dj = prismatic ? 10.0 : 20 * M_PI;
    if (!(d.max_velocity > 0)) d.max_velocity = dv, defaulted = true;
    if (!(d.max_acceleration > 0)) d.max_acceleration = da, defaulted = true;
    if (!(d.max_jerk > 0)) d.max_jerk = dj, defaulted = true;
    if (a.vmax > 0) d.max_velocity = std::min(d.max_velocity, a.vmax * unit);
    if (a.amax > 0) d.max_acceleration = std::min(d.max_acceleration, a.amax * unit);
    if (a.jmax > 0) d.max_jerk = std::min(d.max_jerk, a.jmax * unit);
  }
  return true;
}

struct Samples {
  std::vector<double> t;
  std::vector<std::vector<double>> q, v, a;  // [joint][sample], description units
  std::vector<double> x, y, z;               // movel: tool position per sample (length unit)
};

bool write_csv(const std::string& path, const kin::Chain& c, const Samples& s) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) return false;
  const int n = c.n_joints;
  std::fprintf(f, "t");
  for (const char* k : {"q", "v", "a"})
    for (int j = 0; j < n; ++j) std::fprintf(f, ",%s%d", k, j + 1);
  std::fprintf(f, "\n");
  for (std::size_t k = 0; k < s.t.size(); ++k) {
    std::fprintf(f, "%.6f", s.t[k]);
    for (const auto* m : {&s.q, &s.v, &s.a})
      for (int j = 0; j < n; ++j) std::fprintf(f, ",%.9g", (*m)[static_cast<std::size_t>(j)][k]);
    std::fprintf(f, "\n");
  }
  return std::fclose(f) == 0;
}

// A number for a title: 4 significant digits.
std::string short_num(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.4g", std::abs(v) < 5e-13 ? 0.0 : v);
  return b;
}

// Three stacked panels (position, velocity, acceleration against time), one line per
// joint, ticks at round values, a legend; for movel also the tool path seen from above
// (x-y) and from the side (x-z), one scale on both axes, with its start and end.
bool write_svg(const std::string& path, const kin::Chain& c, const Samples& s, const std::string& title) {
  namespace sv = svg;
  const int n = c.n_joints;
  const bool tool = !s.x.empty();
  const double left = 92, pw = 620, ph = 210, top = 54, gap = 62;
  const double legend_x = left + pw + 16, path_x = legend_x + 150, path_w = 400;
  const double W = tool ? path_x + path_w + 30 : legend_x + 150, H = top + 3 * ph + 2 * gap + 50;
  sv::Doc d(W, H);
  d.text(left, 26, title, "start", 15);
  // units: one name when every joint has the same, otherwise "deg, mm"
  std::string unit = joint_unit_name(c, 0);
  for (int j = 1; j < n; ++j)
    if (unit.find(joint_unit_name(c, j)) == std::string::npos) unit += std::string(", ") + joint_unit_name(c, j);
  const bool mixed = unit.find(',') != std::string::npos;
  const char* names[] = {"position", "velocity", "acceleration"};
  const std::string per[] = {"", "/s", "/s\u00b2"};
  const std::vector<std::vector<double>>* data[] = {&s.q, &s.v, &s.a};
  const double T = s.t.empty() ? 1.0 : std::max(s.t.back(), 1e-9);
  for (int p = 0; p < 3; ++p) {
    double lo = 1e300, hi = -1e300;
    for (int j = 0; j < n; ++j)
      for (double x : (*data[p])[static_cast<std::size_t>(j)]) lo = std::min(lo, x), hi = std::max(hi, x);
    if (lo > hi) lo = hi = 0;
    const double pad = 0.04 * (hi - lo);
    sv::Panel pn = sv::make_panel(left, top + p * (ph + gap), pw, ph, 0, T, lo - pad, hi + pad);
    pn.x0 = 0, pn.x1 = T, pn.xstep = sv::nice_step(T, 8);  // time: exactly the move
    std::string u = mixed ? "" : unit + per[p];
    if (mixed) {
      for (int j = 0; j < n; ++j)
        if (u.find(std::string(joint_unit_name(c, j)) + per[p]) == std::string::npos)
          u += (u.empty() ? "" : ", ") + std::string(joint_unit_name(c, j)) + per[p];
    }
    d.axes(pn, p == 2 ? "time [s]" : "", std::string(names[p]) + " [" + u + "]");
    if (p < 2) d.text(pn.px + pn.pw / 2, pn.py + pn.ph + 32, "time [s]", "middle", 11, "#555");
    for (int j = 0; j < n; ++j) d.polyline(pn, s.t, (*data[p])[static_cast<std::size_t>(j)], sv::color(j));
  }
  std::vector<sv::Doc::Entry> legend;
  for (int j = 0; j < n; ++j)
    legend.push_back({"joint " + std::to_string(j + 1) + (mixed ? std::string(" (") + joint_unit_name(c, j) + ")" : ""),
                      sv::color(j), "line"});
  d.legend(legend_x, top, legend);
  if (tool)  // the path views' legend under the joints', clear of the paths
    d.legend(legend_x, top + 18.0 * n + 30, {{"tool path", "#333", "line"}, {"start", "#2ca02c", "dot"}, {"end", "#d62728", "dot"}});
  if (tool) {
    const std::string L = length_unit_name(c);
    const std::vector<double>* other[] = {&s.y, &s.z};
    const char* oname[] = {"y", "z"};
    const char* view[] = {"tool path from above (x-y)", "tool path from the side (x-z)"};
    const double vh = (3 * ph + 2 * gap - 60) / 2;
    for (int k = 0; k < 2; ++k) {
      const auto& ox = s.x;
      const auto& oy = *other[k];
      double xl = *std::min_element(ox.begin(), ox.end()), xh = *std::max_element(ox.begin(), ox.end());
      double yl = *std::min_element(oy.begin(), oy.end()), yh = *std::max_element(oy.begin(), oy.end());
      const double span = std::max({xh - xl, yh - yl, 10e-3 / c.length_unit});  // at least 10 mm wide
      const double cx = (xl + xh) / 2, cy = (yl + yh) / 2;
      const double h = 0.6 * span;
      const double py = top + k * (vh + 60);
      sv::Panel pn = sv::make_panel(path_x + 20, py + 18, path_w - 20, vh - 18, cx - h, cx + h, cy - h, cy + h, true);
      d.text(pn.px, py + 10, view[k], "start", 12);
      d.axes(pn, std::string("x [") + L + "]", std::string(oname[k]) + " [" + L + "]");
      d.polyline(pn, ox, oy, "#333", 2);
      char b[200];
      std::snprintf(b, sizeof b, "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"5\" fill=\"#2ca02c\"/>\n", pn.X(ox.front()), pn.Y(oy.front()));
      d.raw(b);
      std::snprintf(b, sizeof b, "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"5\" fill=\"#d62728\"/>\n", pn.X(ox.back()), pn.Y(oy.back()));
      d.raw(b);
    }
  }
  return d.write(path);
}

void print_peaks(const kin::Chain& c, const Samples& s) {
  std::printf("joint  peak |v|        limit v      peak |a|        limit a      unit\n");
  for (int j = 0; j < c.n_joints; ++j) {
    const auto k = static_cast<std::size_t>(j);
    double pv = 0, pa = 0;
    for (double x : s.v[k]) pv = std::max(pv, std::fabs(x));
    for (double x : s.a[k]) pa = std::max(pa, std::fabs(x));
    const double sc = c.joint_user_scale(j);
    std::printf("%-6d %-15s %-12s %-15s %-12s %s\n", j + 1, num(pv).c_str(), num(c.joint(j).dynamics.max_velocity * sc).c_str(),
                num(pa).c_str(), num(c.joint(j).dynamics.max_acceleration * sc).c_str(), joint_unit_name(c, j));
  }
}

int outputs(const Args& a, const kin::Chain& c, const Samples& s, const std::string& title) {
  if (!a.csv.empty()) {
    if (!write_csv(a.csv, c, s)) return usage_error("cannot write " + a.csv);
    std::printf("csv: %s (%zu samples)\n", a.csv.c_str(), s.t.size());
  }
  if (!a.svg.empty()) {
    if (!write_svg(a.svg, c, s, title)) return usage_error("cannot write " + a.svg);
    std::printf("svg: %s\n", a.svg.c_str());
  }
  return kExitOk;
}

template <class SampleFn>
Samples sample_all(const kin::Chain& c, double duration, double rate, SampleFn fn) {
  Samples s;
  const int n = c.n_joints;
  s.q.assign(static_cast<std::size_t>(n), {});
  s.v = s.a = s.q;
  const long steps = static_cast<long>(std::ceil(duration * rate));
  kin::JointVector q(n), v(n), acc(n);
  for (long k = 0; k <= steps; ++k) {
    const double t = std::min(duration, static_cast<double>(k) / rate);
    fn(t, q, v, acc);
    s.t.push_back(t);
    for (int j = 0; j < n; ++j) {
      const double sc = c.joint_user_scale(j);
      s.q[static_cast<std::size_t>(j)].push_back(q[j] * sc);
      s.v[static_cast<std::size_t>(j)].push_back(v[j] * sc);
      s.a[static_cast<std::size_t>(j)].push_back(acc[j] * sc);
    }
  }
  return s;
}

}  // namespace

kin::MotionStatus plan_movel_preview(const kin::Chain& chain, const kin::JointVector& q0, const kin::Pose& target,
                                     const kin::CartesianLimits& limits, const kin::MovelOptions& options,
                                     kin::IkModel& model, kin::CartesianTrajectory& out, kin::PathReport* report) {
  // The firmware's IK (armfw's App passes the console no model when ik_prepare fails or
  // finds no closed form: firmware_ik_solver then uses the Newton fallback, as here).
  const bool prepared = kin::ik_prepare(chain, model) == kin::Status::ok;
  const kin::IkSolver ik = firmware_ik_solver(prepared ? &model : nullptr);
  const kin::MotionStatus st = kin::plan_movel(chain, q0, target, limits, options, ik, out, report);
  out.ik = ik;
  return st;
}

int cli_plan(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--help") || !std::strcmp(argv[i], "-h")) {
      std::fputs(kPlanUsage, stdout);
      return kExitOk;
    }
  }
  Args a;
  const std::string err = parse(argc, argv, a);
  if (!err.empty()) return usage_error(err);
  const kin::LoadResult r = load_robot_checked(a.robot);
  if (!r.ok) return usage_error(r.error);
  kin::Chain chain = r.chain;
  bool defaulted = false;
  apply_limits(chain, a, defaulted);
  if (defaulted) std::printf("note: joints without limits in the description use the armctl defaults (see --help)\n");
  std::string e;
  kin::JointVector q0;
  if (!joints_from_user(chain, a.from, q0, e)) return usage_error("--from: " + e);
  std::string report;
  if (limit_violations(chain, q0, report) > 0) return usage_error("--from is outside the joint limits:\n" + report);
  const double ov = a.override_pct / 100.0;

  if (a.kind == "movej") {
    kin::JointVector q1;
    if (!joints_from_user(chain, a.to, q1, e)) return usage_error("--to: " + e);
    // A lower bound of the duration is checked before planning: with absurd limits the
    // planner's own result depends on the platform's rounding. Rest to rest over a distance
    // d: T >= d / v, T >= 2 sqrt(d / a) and T >= cbrt(32 d / j), with the override scaling
    // v, a and j as the planner does (v s, a s^2, j s^3).
    const kin::JointLimits lim = kin::limits_from(chain);
    double at_least = 0;
    for (int j = 0; j < chain.n_joints; ++j) {
      const kin::JointDynamics& dy = lim.dyn[static_cast<std::size_t>(j)];
      const double d = std::fabs(q1[j] - q0[j]);
      at_least = std::max({at_least, d / (dy.max_velocity * ov), 2.0 * std::sqrt(d / (dy.max_acceleration * ov * ov)),
                           std::cbrt(32.0 * d / (dy.max_jerk * ov * ov * ov))});
    }
    if (at_least > a.max_duration) return check_duration(a, at_least);
    kin::JointTrajectory tr;
    const kin::MotionStatus st = kin::plan_movej(lim, kin::JointState::rest(q0), q1, kin::MovejOptions{ov}, tr);
    if (!kin::is_ok(st)) {
      std::string rep;
      limit_violations(chain, q1, rep);
      std::fprintf(stderr, "armctl: movej refused: %s\n%s", kin::to_string(st), rep.c_str());
      return kExitFailed;
    }
    if (const int rc = check_duration(a, tr.duration); rc >= 0) return rc;
    std::printf("movej on %s: duration %s s (override %s %%)\n", chain.name.data(), seconds_text(tr.duration).c_str(),
                num(a.override_pct).c_str());
    const Samples s = sample_all(chain, tr.duration, a.rate, [&tr](double t, kin::JointVector& q, kin::JointVector& v,
                                                                  kin::JointVector& acc) { tr.sample(t, q, v, acc); });
    print_peaks(chain, s);
    return outputs(a, chain, s, std::string("movej ") + chain.name.data() + ", " + short_num(tr.duration) + " s");
  }

  // movel
  kin::Pose x0;
  kin::forward(chain, q0, x0);
  kin::Pose target = x0;
  if (!a.to.empty()) {
    kin::JointVector q1;
    if (!joints_from_user(chain, a.to, q1, e)) return usage_error("--to: " + e);
    kin::forward(chain, q1, target);
    if (!all_finite(target.matrix().data(), 16)) return usage_error("--to: the tool pose is not finite for these joint values");
  } else {
    if (const std::string e2 = check_position("--xyz", a.xyz, chain); !e2.empty()) return usage_error(e2);
    if (const std::string e2 = check_angles("--rpy", a.rpy, chain); !e2.empty()) return usage_error(e2);
    target.translation() = Eigen::Vector3d(a.xyz[0], a.xyz[1], a.xyz[2]) * chain.length_unit;
    if (!a.rpy.empty()) {
      target.linear() = kin::rotation_from_rpy(a.rpy[0] * chain.angle_unit, a.rpy[1] * chain.angle_unit,
                                               a.rpy[2] * chain.angle_unit);
    } else if (!a.quat.empty()) {
      Eigen::Matrix3d R;
      if (kin::rotation_from_quaternion(a.quat[0], a.quat[1], a.quat[2], a.quat[3], R) != kin::Status::ok)
        return usage_error("--quat: not a valid quaternion");
      target.linear() = R;
    }
  }
  kin::CartesianLimits cl;
  if (a.speed > 0) cl.linear_velocity = a.speed * chain.length_unit;
  if (a.accel > 0) cl.linear_acceleration = a.accel * chain.length_unit, cl.linear_jerk = 10 * cl.linear_acceleration;
  if (a.angular > 0) cl.angular_velocity = a.angular * chain.angle_unit;
  kin::MovelOptions opt;
  opt.override = ov;
  opt.allow_slowdown = !a.no_slowdown;
  {
    // As for movej: a lower bound of the duration before planning (the planner's answer to
    // absurd limits depends on the platform's rounding). Unscaled limits: an override only
    // lengthens the move, so the bound holds.
    const double len = (target.translation() - x0.translation()).norm();
    const double ang = Eigen::AngleAxisd(x0.linear().transpose() * target.linear()).angle();
    const double at_least = std::max({len / cl.linear_velocity, ang / cl.angular_velocity,
                                      2.0 * std::sqrt(len / cl.linear_acceleration)});
    if (at_least > a.max_duration) return check_duration(a, at_least);
  }
  auto tr = std::make_unique<kin::CartesianTrajectory>();  // ~40 kB: not on the stack
  auto model = std::make_unique<kin::IkModel>();
  kin::PathReport rep;
  const kin::MotionStatus st = plan_movel_preview(chain, q0, target, cl, opt, *model, *tr, &rep);
  const double L = chain.length_unit;
  if (!kin::is_ok(st)) {
    std::fprintf(stderr, "armctl: movel refused: %s at %s %% of the line, tool at (%s, %s, %s) %s", kin::to_string(st),
                 fixed(100 * rep.s, 1).c_str(), length_text(chain, rep.position.x() / L).c_str(),
                 length_text(chain, rep.position.y() / L).c_str(), length_text(chain, rep.position.z() / L).c_str(),
                 length_unit_name(chain));
    if (rep.joint >= 0) std::fprintf(stderr, ", joint %d", rep.joint + 1);
    if (rep.slowdown > 1) std::fprintf(stderr, ", would need %sx slower", num(rep.slowdown).c_str());
    std::fprintf(stderr, "\n");
    return kExitFailed;
  }
  if (const int rc = check_duration(a, tr->duration); rc >= 0) return rc;
  std::printf("movel on %s: duration %s s, line %s %s, rotation %s %s (override %s %%)\n", chain.name.data(),
              seconds_text(tr->duration).c_str(), length_text(chain, tr->length / L).c_str(), length_unit_name(chain),
              angle_text(chain, tr->angle / chain.angle_unit).c_str(), angle_unit_name(chain), num(a.override_pct).c_str());
  if (st == kin::MotionStatus::slowed_near_singularity)
    std::printf("slowed %sx near a singularity at %s %% of the line (joint %d sets the pace)\n", num(rep.slowdown).c_str(),
                fixed(100 * rep.s, 1).c_str(), rep.joint + 1);
  std::printf("largest Jacobian condition number on the line: %s\n", num(rep.max_condition).c_str());
  Samples s = sample_all(chain, tr->duration, a.rate, [&tr](double t, kin::JointVector& q, kin::JointVector& v,
                                                           kin::JointVector& acc) { tr->sample_ik(t, q, v, acc); });
  if (!a.svg.empty()) {  // the tool path (top and side views): FK of the sampled joints
    kin::JointVector q(chain.n_joints);
    kin::Pose T;
    for (std::size_t k = 0; k < s.t.size(); ++k) {
      for (int j = 0; j < chain.n_joints; ++j) q[j] = s.q[static_cast<std::size_t>(j)][k] / chain.joint_user_scale(j);
      kin::forward(chain, q, T);
      s.x.push_back(T.translation().x() / L);
      s.y.push_back(T.translation().y() / L);
      s.z.push_back(T.translation().z() / L);
    }
  }
  print_peaks(chain, s);
  return outputs(a, chain, s, std::string("movel ") + chain.name.data() + ", " + short_num(tr->duration) + " s, line " +
                                  short_num(tr->length / L) + " " + length_unit_name(chain) + ", rotation " +
                                  short_num(tr->angle / chain.angle_unit) + " " + angle_unit_name(chain));
}

}  // namespace servoarm::fw
