// SPDX-License-Identifier: Apache-2.0
// armctl kin workspace against the closed-form envelopes of the textbook arms (V. Carrara, Apostila de Robótica,
// §3.8: the reach in a plane; §4.1-4.5 for the arms), cell by cell and by area; and the
// SVG plots (kin workspace, plan movej, plan movel) rendered to PNG by rsvg-convert
// (Debian librsvg2-bin) so a malformed file fails, with checks that a person can read
// them: tick labels at round values with few digits, every text inside the canvas,
// a legend, the tool path views of movel.
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <functional>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "run_command.hpp"
#include "sweep.hpp"
#include "text_regex.hpp"
#include "servoarm/armctl/cli_workspace.hpp"
#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/description.hpp"

// CppUTest last: its leak detector redefines new.
#include <CppUTest/TestHarness.h>

using servoarm::fw::compute_workspace;
using servoarm::fw::WorkspaceOptions;
using servoarm::fw::WorkspaceResult;
using servoarm::test::run_command;
using servoarm::test::slurp;
namespace test = servoarm::test;

namespace {

const std::string kArmctl = ARMCTL_PATH;
constexpr double kDeg = M_PI / 180;

// Closed-form membership of a point (u, v) in mm.
using Inside = std::function<bool(double, double)>;

Inside ring(double cu, double cv, double r_in, double r_out) {
  return [=](double u, double v) {
    const double r = std::hypot(u - cu, v - cv);
    return r >= r_in && r <= r_out;
  };
}

// RR planar (a1, a2) with q1 in [a, b], q2 in [c, d], 0 <= c < d <= 180 deg (one elbow
// sign): r fixes q2 (law of cosines), then q1 = atan2(y, x) - atan2(a2 s2, a1 + a2 c2).
Inside rr_limited(double a1, double a2, double a, double b, double c, double d) {
  return [=](double x, double y) {
    const double r2 = x * x + y * y;
    const double c2 = (r2 - a1 * a1 - a2 * a2) / (2 * a1 * a2);
    if (c2 < -1 || c2 > 1) return false;
    const double q2 = std::acos(c2);
    if (q2 < c * kDeg || q2 > d * kDeg) return false;
    double q1 = std::atan2(y, x) - std::atan2(a2 * std::sin(q2), a1 + a2 * std::cos(q2));
    q1 = std::remainder(q1, 2 * M_PI);
    return q1 >= a * kDeg && q1 <= b * kDeg;
  };
}

std::string write_temp(const std::string& name, const std::string& text) {
  const std::string p = "/tmp/servoarm_ws_" + std::to_string(getpid()) + "_" + name;
  std::ofstream(p) << text;
  return p;
}

struct Envelope {
  std::string robot, plane, what;
  Inside inside;
  double area_mm2;
  // Points of the region's edge (closed form): a cell within a cell of one may be filled
  // though the region there is a sliver thinner than any sample spacing (a cusp).
  std::vector<std::array<double, 2>> edge = {};
};

// Every cell must match the closed form up to the raster's resolution: a filled cell
// needs a point of the region within one cell of it, an empty one a point outside
// within one cell (9 x 9 points over the cell widened by a cell on every side); a hole
// inside the region or a spill outside it fails. The area within 1 %.
void check_envelope(const Envelope& e) {
  const servoarm::kin::LoadResult lr = servoarm::kin::load_robot(e.robot);
  CHECK_TEXT(lr.ok, (e.robot + ": " + lr.error).c_str());
  WorkspaceOptions o;
  o.plane = e.plane;
  const WorkspaceResult w = compute_workspace(lr.chain, o);
  CHECK_TEXT(w.status == 0, (e.what + ": " + w.error).c_str());
  const double mm = 1000, c = w.cell * mm;
  int checked = 0, wrong = 0, inside = 0;
  std::string first;
  for (int j = 0; j < w.nv; ++j)
    for (int i = 0; i < w.nu; ++i) {
      const double u = w.uc(i) * mm, v = w.vc(j) * mm;
      const bool filled = w.at(i, j);
      ++checked;
      inside += e.inside(u, v);
      if (e.inside(u, v) == filled) continue;
      bool near = false;
      for (const auto& k : e.edge) near = near || (filled && std::abs(k[0] - u) <= 1.5 * c && std::abs(k[1] - v) <= 1.5 * c);  // a point of the other kind (as the raster says) within a cell
      for (int a = 0; a <= 8 && !near; ++a)
        for (int b = 0; b <= 8 && !near; ++b) near = e.inside(u + c * (a / 4.0 - 1) * 1.5, v + c * (b / 4.0 - 1) * 1.5) == filled;
      if (near) continue;
      if (wrong++ == 0)
        first = "cell at (" + std::to_string(u) + ", " + std::to_string(v) + ") mm is " + (filled ? "filled" : "empty") +
                ", the closed form says " + (filled ? "outside" : "inside") + " for a cell around it";
    }
  const double area = w.area * mm * mm;
  const std::string msg = e.what + ": " + std::to_string(wrong) + " of " + std::to_string(checked) +
                          " cells wrong (" + first + "); area " + std::to_string(area) + " mm^2 vs " +
                          std::to_string(e.area_mm2) + " closed form, cell " + std::to_string(c) + " mm";
  CHECK_TEXT(checked > 10000 && inside > 10000, msg.c_str());
  CHECK_TEXT(wrong == 0, msg.c_str());
  CHECK_TEXT(std::abs(area - e.area_mm2) < 0.01 * e.area_mm2, msg.c_str());
}

bool have_rsvg() { return std::system("command -v rsvg-convert >/dev/null 2>&1") == 0; }

// Renders the SVG to PNG; fails when rsvg-convert refuses it (a malformed file) or
// writes no PNG.
void render(const std::string& svg) {
  CHECK_TEXT(have_rsvg(), "rsvg-convert not found: install librsvg2-bin (.ci/packages [suites])");
  const std::string png = svg + ".png";
  std::remove(png.c_str());
  const auto r = run_command("rsvg-convert -o " + png + " " + svg);
  CHECK_TEXT(r.status == 0, (svg + ": rsvg-convert: " + r.err).c_str());
  const std::string b = slurp(png);
  CHECK_TEXT(b.size() > 2000 && b.compare(1, 3, "PNG") == 0, (svg + ": no PNG written").c_str());
  std::remove(png.c_str());
}

// Legibility: every text inside the canvas (its estimated box), tick labels (the
// grey 11 px texts) numbers with at most 4 significant digits, at least 4 of them.
void check_readable(const std::string& svg_text, const std::string& what) {
  test::Groups m;
  CHECK_TEXT(!(m = test::regex_search(svg_text, "width=\"([0-9.]+)\" height=\"([0-9.]+)\"")).empty(), what.c_str());
  const double W = std::stod(m[1]), H = std::stod(m[2]);
  const test::Regex text_re("<text x=\"([-0-9.]+)\" y=\"([-0-9.]+)\" text-anchor=\"(start|middle|end)\" font-size=\"([0-9.]+)\" fill=\"([^\"]*)\"([^>]*)>([^<]*)</text>");
  int ticks = 0;
  for (const test::Groups& t : text_re.search_all(svg_text)) {
    const double x = std::stod(t[1]), y = std::stod(t[2]), size = std::stod(t[4]);
    const std::string anchor = t[3], s = t[7];
    const bool rotated = t[6].find("rotate") != std::string::npos;
    const double w = 0.58 * size * static_cast<double>(s.size());
    const double x0 = rotated ? x - size : anchor == "start" ? x : anchor == "middle" ? x - w / 2 : x - w;
    const double x1 = rotated ? x + size : x0 + w;
    const double y0 = rotated ? y - w / 2 : y - size, y1 = rotated ? y + w / 2 : y;
    const std::string where = what + ": text '" + s + "' at (" + t[1] + ", " + t[2] + ") leaves the canvas";
    CHECK_TEXT(x0 >= 0 && x1 <= W && y0 >= 0 && y1 <= H, where.c_str());
    if (t[5] == "#333" && size == 11) {  // a tick label
      ++ticks;
      int digits = 0;
      bool lead = true;
      for (char ch : s)
        if (ch >= '1' && ch <= '9') lead = false, ++digits;
        else if (ch == '0' && !lead) ++digits;
      // trailing zeros of integers (1000) are not significant
      std::string z = s;
      if (z.find('.') == std::string::npos)
        while (z.size() > 1 && z.back() == '0') z.pop_back(), --digits;
      CHECK_TEXT(digits <= 4, (what + ": tick label '" + s + "' has too many digits").c_str());
    }
  }
  CHECK_TEXT(ticks >= 4, (what + ": no tick labels").c_str());
}

}  // namespace

TEST_GROUP(Workspace) {
  void setup() override { MemoryLeakWarningPlugin::saveAndDisableNewDeleteOverloads(); }
  void teardown() override { MemoryLeakWarningPlugin::restoreNewDeleteOverloads(); }
};

TEST(Workspace, PlanarArmsMatchTheirClosedFormEnvelopes) {
  // rr_planar: the annulus between |a1 - a2| and a1 + a2 (V. Carrara, Apostila de Robótica, §4.1, joints +-180 deg)
  check_envelope({"rr_planar", "", "rr_planar xy", ring(0, 0, 50, 550), M_PI * (550.0 * 550 - 50.0 * 50)});
  // rrr_planar: a1 - a2 - a3 < 0, so the full disk of radius a1 + a2 + a3 (§4.2)
  check_envelope({"rrr_planar", "xy", "rrr_planar xy", ring(0, 0, -1, 650), M_PI * 650.0 * 650});
  // rlr_planar: telescope 100..500 and a3 = 100 turning fully: the disk of radius 600 (§4.3)
  check_envelope({"rlr_planar", "", "rlr_planar xy", ring(0, 0, -1, 600), M_PI * 600.0 * 600});
  // rr with limits q1 in [-90, 90], q2 in [0, 135]: area (b - a) a1 a2 (cos c - cos d),
  // the image of the joint box (the map is one-to-one for one elbow sign).
  const std::string f = write_temp("rr_lim.toml",
                                   "name = \"rr_limited\"\nconvention = \"standard\"\nlength_unit = \"mm\"\nangle_unit = \"deg\"\n"
                                   "[[joint]]\ntype = \"revolute\"\na = 300\nlimits = [-90, 90]\n"
                                   "[[joint]]\ntype = \"revolute\"\na = 250\nlimits = [0, 135]\n");
  // its edge: the image of the joint box's boundary (V. Carrara, Apostila de Robótica, §4.1: x = a1 c1 + a2 c12, y = a1 s1 + a2 s12)
  std::vector<std::array<double, 2>> edge;
  auto rr = [&](double q1, double q2) {
    edge.push_back({300 * std::cos(q1 * kDeg) + 250 * std::cos((q1 + q2) * kDeg),
                    300 * std::sin(q1 * kDeg) + 250 * std::sin((q1 + q2) * kDeg)});
  };
  for (int k = 0; k <= 2000; ++k) {
    const double t = k / 2000.0;
    rr(-90, 135 * t), rr(90, 135 * t), rr(-90 + 180 * t, 0), rr(-90 + 180 * t, 135);
  }
  check_envelope({f, "xy", "rr limited xy", rr_limited(300, 250, -90, 90, 0, 135),
                  M_PI * 300 * 250 * (1 - std::cos(135 * kDeg)), edge});
  std::remove(f.c_str());
}

TEST(Workspace, TurningArmsMatchTheSphereAndTorusSectionsThroughTheBase) {
  // trl_r, the spherical TRL arm of §3.8 ("the volume of the sphere whose radius is the
  // stretched arm"): in the xz plane the disk of radius 500 + 100 about the shoulder (0, 300).
  check_envelope({"trl_r", "xz", "trl_r xz", ring(0, 300, -1, 600), M_PI * 600.0 * 600});
  check_envelope({"trl_r", "yz", "trl_r yz", ring(0, 300, -1, 600), M_PI * 600.0 * 600});
  // trr (§4.4): the annulus 250 - 200 .. 250 + 200 about the shoulder (0, 300)
  check_envelope({"trr", "xz", "trr xz", ring(0, 300, 50, 450), M_PI * (450.0 * 450 - 50.0 * 50)});
  // trr at z = 0 (the xy plane through the base): the shoulder is 300 above, so the disk
  // of radius sqrt(450^2 - 300^2)
  const double r0 = std::sqrt(450.0 * 450 - 300.0 * 300);
  check_envelope({"trr", "xy", "trr xy", ring(0, 0, -1, r0), M_PI * r0 * r0});
}

// An AR4-like desktop arm (Annin Robotics AR4's modified DH table and joint limits as
// printed in the robotkinematicscatalogue Python package, class Annin_Robotics_AR4) with a
// 60 mm gripper on the flange: joint 1 spans +-170 deg, the reach is about 690 mm. Behind
// the base (x < 0) much of the xz section is reached only with joint 1 near +-170 deg and
// the gripper turned sideways by joints 4 and 5 (joint 4 near +-90 deg).
const char* kAr4 =
    "name = \"ar4_like\"\nconvention = \"modified\"\nlength_unit = \"mm\"\nangle_unit = \"deg\"\n"
    "[[joint]]\ntype = \"revolute\"\nd = 169.77\nlimits = [-170, 170]\n"
    "[[joint]]\ntype = \"revolute\"\nalpha = -90\na = 64.2\ntheta = -90\nlimits = [-42, 90]\n"
    "[[joint]]\ntype = \"revolute\"\na = 305\nlimits = [-89, 52]\n"
    "[[joint]]\ntype = \"revolute\"\nalpha = -90\nd = 222.63\nlimits = [-165, 165]\n"
    "[[joint]]\ntype = \"revolute\"\nalpha = 90\nlimits = [-105, 105]\n"
    "[[joint]]\ntype = \"revolute\"\nalpha = -90\nd = 36.25\ntheta = 180\nlimits = [-155, 155]\n"
    "[tool]\nxyz = [0, 0, 60]\n";

// The printed extent "u from A to B mm, v from C to D mm" of `armctl kin workspace`.
bool printed_extent(const std::string& out, double e[4]) {
  test::Groups m;
  const test::Regex re("([xyz]) from ([-0-9.e+]+) to ([-0-9.e+]+) mm, ([xyz]) from ([-0-9.e+]+) to ([-0-9.e+]+) mm");
  if ((m = re.search(out)).empty()) return false;
  for (int k = 0; k < 2; ++k) e[k] = std::stod(m[2 + k]), e[2 + k] = std::stod(m[5 + k]);
  return true;
}

// The raster `armctl kin workspace --csv` wrote (runs of cell centres, mm), back on a grid:
// the cell size from the printed one (4 digits) refined over the rows' span, so the cell
// boundaries are the command's own to the CSV's 6 digits.
struct CsvRaster {
  double u0 = 0, v0 = 0, cell = 0;  // mm: lower-left corner of cell (0, 0)
  int nu = 0, nv = 0;
  std::vector<std::uint8_t> on;
  bool at(int i, int j) const { return on[static_cast<std::size_t>(j) * nu + i] != 0; }
};

bool read_csv_raster(const std::string& csv, double printed_cell, CsvRaster& r, std::string& err) {
  std::istringstream in(csv);
  std::string line;
  std::getline(in, line);  // the header
  std::vector<std::array<double, 3>> runs;
  double ulo = 1e300, uhi = -1e300, vlo = 1e300, vhi = -1e300;
  while (std::getline(in, line)) {
    std::array<double, 3> x{};
    if (std::sscanf(line.c_str(), "%lf,%lf,%lf", &x[0], &x[1], &x[2]) != 3) return err = "bad CSV row '" + line + "'", false;
    runs.push_back(x);
    vlo = std::min(vlo, x[0]), vhi = std::max(vhi, x[0]), ulo = std::min(ulo, x[1]), uhi = std::max(uhi, x[2]);
  }
  if (runs.size() < 100 || !(printed_cell > 0)) return err = "CSV of " + std::to_string(runs.size()) + " runs", false;
  const long n_v = std::lround((vhi - vlo) / printed_cell), n_u = std::lround((uhi - ulo) / printed_cell);
  r.cell = n_v >= n_u ? (vhi - vlo) / static_cast<double>(n_v) : (uhi - ulo) / static_cast<double>(n_u);
  r.u0 = ulo - r.cell / 2, r.v0 = vlo - r.cell / 2;
  r.nu = static_cast<int>(n_u) + 1, r.nv = static_cast<int>(n_v) + 1;
  r.on.assign(static_cast<std::size_t>(r.nu) * r.nv, 0);
  auto index = [&](double x, double lo, int n, int& k) {
    const double f = (x - lo) / r.cell;
    k = static_cast<int>(std::lround(f));
    return std::abs(f - k) < 0.01 && k >= 0 && k < n;
  };
  for (const auto& x : runs) {
    int j = 0, i0 = 0, i1 = 0;
    if (!index(x[0], vlo, r.nv, j) || !index(x[1], ulo, r.nu, i0) || !index(x[2], ulo, r.nu, i1) || i1 < i0)
      return err = "CSV run off the cell grid: " + std::to_string(x[0]) + "," + std::to_string(x[1]) + "," + std::to_string(x[2]), false;
    for (int i = i0; i <= i1; ++i) r.on[static_cast<std::size_t>(j) * r.nu + i] = 1;
  }
  return true;
}

TEST(Workspace, TurningArmWithOffsetWristHoldsEveryPointDenseFkSamplingReaches) {
  // Dense seeded sampling of the joint box (joints 2..6 uniform, a quarter of the values
  // at a limit), each sample turned by joint 1 into the plane's two half-planes where
  // joint 1's limits allow; FK of the turned joints gives a point of the section. The
  // extent the command prints (cell centres) must hold every such point to within one
  // cell, and every point must lie within two cells of a filled cell of the raster its
  // --csv writes (no cut, no hole wider than about two cells: joints 4 and 5 are sampled
  // in steps, the gripper's sideways offset between two steps is not drawn). Under qemu
  // and the sanitizers the first 1/20 of the samples (tests/support/sweep.hpp), in the xz
  // plane only (the command's workspace of one plane took qemu some 13 s).
  constexpr int kReachCells = 2;  // a sampled point's distance to a filled cell, at most (cells)
  const std::string f = write_temp("ar4_like.toml", kAr4), csv = write_temp("ar4_like.csv", "");
  const servoarm::kin::LoadResult lr = servoarm::kin::load_robot(f);
  CHECK_TEXT(lr.ok, lr.error.c_str());
  const servoarm::kin::Chain& c = lr.chain;
  std::mt19937 rng(35);
  std::uniform_real_distribution<double> unit(0, 1);
  const char* const planes[] = {"xz", "yz"};
  for (int pl = 0; pl < (servoarm::test::kSlowBuild ? 1 : 2); ++pl) {
    const char* const plane = planes[pl];
    const int iu = plane[0] == 'x' ? 0 : 1, iv = 2;
    const double psi0 = iu == 0 ? 0 : M_PI / 2;  // azimuth of the +u half-plane
    const double mm = 1000;
    const auto r = run_command(kArmctl + " kin workspace --robot " + f + " --plane " + plane + " --csv " + csv);
    double e[4];
    CHECK_TEXT(r.status == 0 && printed_extent(r.out, e), (r.out + r.err).c_str());
    test::Groups m;
    CHECK_TEXT(!(m = test::regex_search(r.out, "grid of ([0-9.e+-]+) mm cells")).empty(), r.out.c_str());
    CsvRaster w;
    std::string err;
    CHECK_TEXT(read_csv_raster(slurp(csv), std::stod(m[1]), w, err), (std::string(plane) + ": " + err).c_str());
    const double cell = w.cell;
    double lo[2] = {1e300, 1e300}, hi[2] = {-1e300, -1e300};
    int points = 0, uncovered = 0;
    std::string first;
    const int samples = servoarm::test::sweep(400000);
    for (int k = 0; k < samples; ++k) {
      servoarm::kin::JointVector q(c.n_joints);
      q[0] = 0;
      for (int j = 1; j < c.n_joints; ++j) {
        const double a = c.joint(j).lower, b = c.joint(j).upper, t = unit(rng);
        q[j] = t < 0.125 ? a : t < 0.25 ? b : a + (b - a) * unit(rng);
      }
      servoarm::kin::Pose T;
      servoarm::kin::forward(c, q, T);
      const double phi = std::atan2(T.translation().y(), T.translation().x());
      for (const double psi : {psi0, psi0 + M_PI}) {
        const double d = std::remainder(psi - phi, 2 * M_PI);
        double q1 = NAN;
        for (const double cand : {d, d - 2 * M_PI, d + 2 * M_PI})
          if (cand >= c.joint(0).lower && cand <= c.joint(0).upper) q1 = cand;
        if (std::isnan(q1)) continue;
        servoarm::kin::JointVector q2 = q;
        q2[0] = q1;
        servoarm::kin::forward(c, q2, T);
        const Eigen::Vector3d p = T.translation() * mm;
        CHECK_TEXT(std::abs(p[1 - iu]) < 1e-6, "joint 1 of the AR4-like arm does not turn about the base z axis");
        const double u = p[iu], v = p[iv];
        ++points;
        lo[0] = std::min(lo[0], u), hi[0] = std::max(hi[0], u), lo[1] = std::min(lo[1], v), hi[1] = std::max(hi[1], v);
        const int i = static_cast<int>(std::floor((u - w.u0) / cell)), j = static_cast<int>(std::floor((v - w.v0) / cell));
        bool near = false;
        for (int a = i - kReachCells; a <= i + kReachCells && !near; ++a)
          for (int b = j - kReachCells; b <= j + kReachCells && !near; ++b) near = a >= 0 && a < w.nu && b >= 0 && b < w.nv && w.at(a, b);
        if (!near && uncovered++ == 0) {
          char b[200];
          std::snprintf(b, sizeof b, "(%s, %s) = (%.1f, %.1f) mm", plane == std::string("xz") ? "x" : "y",
                        "z", u, v);
          first = b;
        }
      }
    }
    char msg[400];
    std::snprintf(msg, sizeof msg,
                  "%s: printed %c %.1f..%.1f, z %.1f..%.1f mm; FK sampling %.1f..%.1f, z %.1f..%.1f mm (%d points, cell %.2f mm); "
                  "%d points farther than %d cells from a filled cell, first %s",
                  plane, plane[0], e[0], e[1], e[2], e[3], lo[0], hi[0], lo[1], hi[1], points, cell, uncovered, kReachCells, first.c_str());
    CHECK_TEXT(points > samples / 4, msg);
    CHECK_TEXT(e[0] <= lo[0] + cell && e[1] >= hi[0] - cell && e[2] <= lo[1] + cell && e[3] >= hi[1] - cell, msg);
    CHECK_TEXT(uncovered == 0, msg);
  }
  std::remove(f.c_str());
  std::remove(csv.c_str());
}

TEST(Workspace, PlanesWithoutAreaAndBadOptionsAreRefused) {
  const servoarm::kin::LoadResult lr = servoarm::kin::load_robot("rr_planar");
  WorkspaceOptions o;
  o.plane = "xz";
  WorkspaceResult w = compute_workspace(lr.chain, o);
  LONGS_EQUAL(1, w.status);
  CHECK_TEXT(w.error.find("moves in the xy plane") != std::string::npos, w.error.c_str());
  o.plane = "xw";
  LONGS_EQUAL(2, compute_workspace(lr.chain, o).status);
  o.plane = "";
  o.grid = 5;
  LONGS_EQUAL(2, compute_workspace(lr.chain, o).status);
  o.grid = 400;
  o.pose = {0, 0, 0};
  LONGS_EQUAL(2, compute_workspace(lr.chain, o).status);
  for (const char* c : {" kin workspace", " kin workspace --robot", " kin workspace --robot rr_planar --plane",
                        " kin workspace --robot rr_planar --plane ab", " kin workspace --robot rr_planar --grid 1e9",
                        " kin workspace --robot rr_planar --grid 50.5", " kin workspace --robot rr_planar --pose 1 nan",
                        " kin workspace --robot rr_planar --pose 500 0", " kin workspace --robot rr_planar --svg",
                        " kin workspace --robot /tmp", " kin workspace --robot rr_planar --frobnicate"}) {
    const auto r = run_command(kArmctl + c);
    CHECK_TEXT(r.status == 2 && r.err.rfind("armctl: ", 0) == 0, (std::string(c) + ": " + r.err).c_str());
  }
  const auto r = run_command(kArmctl + " kin workspace --robot rr_planar --plane xz");
  CHECK_TEXT(r.status == 1 && r.err.find("use --plane xy") != std::string::npos, r.err.c_str());
}

TEST(Workspace, CsvAndSvgOfTheCommandRenderAndRead) {
  const std::string base = "/tmp/servoarm_ws_" + std::to_string(getpid());
  for (const char* robot : {"rr_planar", "puma560"}) {
    const std::string svg = base + "_" + robot + ".svg", csv = base + "_" + robot + ".csv";
    const auto r = run_command(kArmctl + " kin workspace --robot " + robot + " --svg " + svg + " --csv " + csv);
    CHECK_TEXT(r.status == 0, r.err.c_str());
    CHECK_TEXT(r.out.find("area ") != std::string::npos, r.out.c_str());
    const std::string s = slurp(svg);
    CHECK(s.find("reachable region") != std::string::npos);  // the legend
    CHECK(s.find("x [mm]") != std::string::npos);            // axis titles with the unit
    check_readable(s, svg);
    render(svg);
    // The CSV's runs hold the area the command printed (within the half-cell boundary rule).
    std::istringstream in(slurp(csv));
    std::string line;
    std::getline(in, line);
    CHECK_TEXT(line == (std::string(robot) == "puma560" ? "z,x_from,x_to" : "y,x_from,x_to"), line.c_str());
    int rows = 0;
    while (std::getline(in, line)) ++rows;
    CHECK(rows > 300);
    std::remove(svg.c_str());
    std::remove(csv.c_str());
  }
}

TEST(Workspace, PlanPlotsRenderWithRoundTicksALegendAndTheToolPath) {
  const std::string j = "/tmp/servoarm_plot_" + std::to_string(getpid()) + "_movej.svg";
  const std::string l = "/tmp/servoarm_plot_" + std::to_string(getpid()) + "_movel.svg";
  auto r = run_command(kArmctl + " plan movej --robot puma560 --from 0 -45 180 0 45 0 --to 90 -90 150 45 -30 90 --vmax 77 --svg " + j);
  CHECK_TEXT(r.status == 0, r.err.c_str());
  r = run_command(kArmctl + " plan movel --robot puma560 --from 10 -80 40 10 45 5 --xyz 0 300 600 --svg " + l);
  CHECK_TEXT(r.status == 0, r.err.c_str());
  for (const std::string& f : {j, l}) {
    const std::string s = slurp(f);
    check_readable(s, f);  // was: ticks like 0.3574474512 s, y labels cut at the left edge
    CHECK(s.find("joint 6") != std::string::npos);
    CHECK(s.find("time [s]") != std::string::npos);
    CHECK(s.find("velocity [deg/s]") != std::string::npos);
    render(f);
  }
  const std::string s = slurp(l);
  CHECK(s.find("tool path from above (x-y)") != std::string::npos);
  CHECK(s.find("tool path from the side (x-z)") != std::string::npos);
  CHECK(s.find("y [mm]") != std::string::npos);
  CHECK(s.find("z [mm]") != std::string::npos);
  CHECK(slurp(j).find("tool path") == std::string::npos);  // movej: joint curves only
  std::remove(j.c_str());
  std::remove(l.c_str());
}
