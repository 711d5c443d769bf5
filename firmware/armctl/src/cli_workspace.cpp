// SPDX-License-Identifier: Apache-2.0
// armctl kin workspace (see cli_workspace.hpp).
#include "servoarm/armctl/cli_workspace.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>

#include "servoarm/armctl/cli_common.hpp"
#include "servoarm/armctl/cli_svg.hpp"

namespace servoarm::fw {
namespace {

constexpr double kTwoPi = 2 * M_PI;

const char* kWorkspaceUsage =
    "usage: armctl kin workspace --robot NAME|FILE [--plane xz|xy|yz] [--grid N] [--pose q1..qn]\n"
    "                            [--svg FILE] [--csv FILE]\n"
    "  The region the tool point reaches in a plane through the base, joint limits respected\n"
    "  (Carrara, Apostila de Robótica, 3.8), and its area. A planar arm (every tool point in one base plane, e.g.\n"
    "  rr_planar) is drawn in its own plane; an arm whose joint 1 turns about the base z axis\n"
    "  in the plane given (default xz: the side view; xy: the top view at z = 0).\n"
    "  --grid N     raster cells along the longer side (100..2000, default 400)\n"
    "  --pose q..   the reference pose drawn (description units; default 0, clamped to the limits)\n"
    "  --svg FILE   the filled region, the arm in the reference pose, axes in the length unit, legend\n"
    "  --csv FILE   the region as runs of cells: one row per run, v, u_from, u_to (cell centres,\n"
    "               length unit; header names the axes, e.g. z,x_from,x_to)\n"
    "  Exit: 0 ok, 1 no area in that plane (a planar arm's other planes) or an arm of another\n"
    "  kind, 2 bad usage.\n";

int axis_index(char c) { return c == 'x' ? 0 : c == 'y' ? 1 : 2; }

struct Range {
  double lo, hi;
};

// The quad raster: cells [u0 + i cell, ...) x [v0 + j cell, ...).
struct Raster {
  double u0 = 0, v0 = 0, cell = 1;
  int nu = 0, nv = 0;
  std::vector<std::uint8_t> on;
  // Blocks of 8 x 8 cells: the set cells of each and how many it has (fewer at the edges).
  int nbu = 0;
  std::vector<std::uint8_t> block_set, block_cells;
  void clear() {
    on.assign(static_cast<std::size_t>(nu) * nv, 0);
    nbu = (nu + 7) / 8;
    const int nbv = (nv + 7) / 8;
    block_set.assign(static_cast<std::size_t>(nbu) * nbv, 0);
    block_cells.resize(block_set.size());
    for (int bj = 0; bj < nbv; ++bj)
      for (int bi = 0; bi < nbu; ++bi)
        block_cells[static_cast<std::size_t>(bj) * nbu + bi] = static_cast<std::uint8_t>(std::min(8, nu - 8 * bi) * std::min(8, nv - 8 * bj));
  }
  void mark(int i, int j) {
    std::uint8_t& c = on[static_cast<std::size_t>(j) * nu + i];
    if (!c) c = 1, ++block_set[static_cast<std::size_t>(j >> 3) * nbu + (i >> 3)];
  }
  // Cells i0..i1 of row j all set? A cell holds 0 or 1: eight set cells read as one word.
  bool row_full(int j, int i0, int i1) const {
    const std::uint8_t* r = on.data() + static_cast<std::size_t>(j) * nu;
    constexpr std::uint64_t kAll = 0x0101010101010101u;
    std::uint64_t w;
    if (i1 - i0 < 7) {
      if constexpr (std::endian::native == std::endian::little) {
        if (nu >= 8) {  // one word holding the cells, the others masked off
          const int st = std::min(i0, nu - 8);
          std::memcpy(&w, r + st, 8);
          const std::uint64_t mask = (~std::uint64_t{0} << (8 * (i0 - st))) & (~std::uint64_t{0} >> (8 * (7 - (i1 - st))));
          return (w & mask) == (kAll & mask);
        }
      }
      for (int i = i0; i <= i1; ++i)
        if (!r[i]) return false;
      return true;
    }
    for (int i = i0; i + 7 < i1; i += 8)
      if (std::memcpy(&w, r + i, 8), w != kAll) return false;
    return std::memcpy(&w, r + i1 - 7, 8), w == kAll;
  }
  // Every cell of [i0, i1] x [j0, j1] set (an empty box: true)? The blocks it touches first.
  bool box_full(int i0, int i1, int j0, int j1) const {
    if (i0 > i1 || j0 > j1) return true;
    bool blocks = true;
    for (int bj = j0 >> 3; bj <= j1 >> 3 && blocks; ++bj)
      for (int bi = i0 >> 3; bi <= i1 >> 3 && blocks; ++bi) {
        const std::size_t b = static_cast<std::size_t>(bj) * nbu + bi;
        blocks = block_set[b] == block_cells[b];
      }
    if (blocks) return true;
    for (int j = j0; j <= j1; ++j)
      if (!row_full(j, i0, i1)) return false;
    return true;
  }
  // The cell index of u (v: with v0, nv) rounded down, clipped to [-2, n + 1]: a box
  // beyond the raster stays beyond it.
  static int index(double x, int n) { return static_cast<int>(std::clamp(x, -2.0, n + 1.0) + 2) - 2; }
  // The cells fill() can set for these corners: those of the corners' bounding box widened
  // by one cell on every side (fill sets only cells of corners and cells whose centre the
  // polygon covers, all inside the box; the widening absorbs rounding of the crossings and
  // of the inverse), clipped to the raster (i0 > i1 or j0 > j1: none).
  void box(const double (*p)[2], int n, int& i0, int& i1, int& j0, int& j1) const {
    double ulo = p[0][0], uhi = p[0][0], vlo = p[0][1], vhi = p[0][1];
    for (int k = 1; k < n; ++k) ulo = std::min(ulo, p[k][0]), uhi = std::max(uhi, p[k][0]), vlo = std::min(vlo, p[k][1]), vhi = std::max(vhi, p[k][1]);
    const double inv = 1 / cell;
    i0 = std::max(0, index((ulo - u0) * inv - 1, nu)), i1 = std::min(nu - 1, index((uhi - u0) * inv + 1, nu));
    j0 = std::max(0, index((vlo - v0) * inv - 1, nv)), j1 = std::min(nv - 1, index((vhi - v0) * inv + 1, nv));
  }
  void set(double u, double v) {
    const int i = static_cast<int>(std::floor((u - u0) / cell)), j = static_cast<int>(std::floor((v - v0) / cell));
    if (i >= 0 && i < nu && j >= 0 && j < nv) mark(i, j);
  }
  // Fill the cells whose centre lies inside the polygon (even-odd), and the cells of its corners.
  // A row of the box whose cells are all set is skipped: fill would set nothing there.
  void fill(const double (*p)[2], int n) {
    int bi0, bi1, bj0, bj1;
    box(p, n, bi0, bi1, bj0, bj1);
    if (bi0 > bi1) return;
    int open = bj0;  // the first row of the box with an empty cell
    while (open <= bj1 && row_full(open, bi0, bi1)) ++open;
    if (open > bj1) return;
    double vmin = p[0][1], vmax = p[0][1];
    for (int k = 0; k < n; ++k) {
      set(p[k][0], p[k][1]);
      vmin = std::min(vmin, p[k][1]), vmax = std::max(vmax, p[k][1]);
    }
    const int j0 = std::max(0, static_cast<int>(std::ceil((vmin - v0) / cell - 0.5)));
    const int j1 = std::min(nv - 1, static_cast<int>(std::floor((vmax - v0) / cell - 0.5)));
    for (int j = std::max(j0, open); j <= j1; ++j) {
      if (j >= bj0 && j <= bj1 && row_full(j, bi0, bi1)) continue;
      const double v = v0 + (j + 0.5) * cell;
      double xs[8];
      int m = 0;
      for (int k = 0; k < n && m < 8; ++k) {
        const double* a = p[k];
        const double* b = p[(k + 1) % n];
        if ((a[1] <= v) != (b[1] <= v)) xs[m++] = a[0] + (v - a[1]) * (b[0] - a[0]) / (b[1] - a[1]);
      }
      for (int a = 1; a < m; ++a)  // insertion sort of at most n crossings
        for (int b = a; b > 0 && xs[b - 1] > xs[b]; --b) std::swap(xs[b - 1], xs[b]);
      for (int k = 0; k + 1 < m; k += 2) {
        const int i0 = std::max(0, static_cast<int>(std::ceil((xs[k] - u0) / cell - 0.5)));
        const int i1 = std::min(nu - 1, static_cast<int>(std::floor((xs[k + 1] - u0) / cell - 0.5)));
        for (int i = i0; i <= i1; ++i) mark(i, j);
      }
    }
  }
};

// Points of one joint-space slice: the tool position of every (a, b) grid node.
struct Kind {
  bool planar = false;
  int normal = 2;      // planar: the constant coordinate
  double level = 0;    // planar: its value
  bool turning = false;
  double sign = 1;     // turning: azimuth change per joint 1 change (+1 or -1)
};

[[gnu::always_inline]] inline double wrap(double a) { return a - kTwoPi * std::floor((a + M_PI) / kTwoPi); }  // to [-pi, pi)

// Azimuth psi reachable from azimuth phi (at q0ref) by joint 1 within [lo, hi]? (Inlined:
// every tool point of a turning arm asks it twice.)
struct Reach {
  bool full;            // joint 1 turns a whole turn
  double shift, sign;   // the azimuth interval starts at phi + shift (sign > 0), phi - shift
  double span;          // its length, with a tolerance
  Reach(const Range& r0, double q0ref, double sign)
      : full(r0.hi - r0.lo >= kTwoPi - 1e-9), shift(sign > 0 ? r0.lo - q0ref : r0.hi - q0ref), sign(sign), span((r0.hi - r0.lo) + 1e-12) {}
  [[gnu::always_inline]] bool operator()(double phi, double psi) const {
    if (full) return true;
    const double a = sign > 0 ? phi + shift : phi - shift;  // azimuth interval [a, a + span]
    const double d = wrap(psi - a);
    const double off = d + (d < 0 ? kTwoPi : 0);  // psi - a in [0, 2pi)
    return off <= span;
  }
};

// Reach's answer for most tool points without their azimuth: the azimuths joint 1 brings
// to psi are [theta - span, theta]; the side of the tool point (x, y) relative to the two
// directions that bound them decides where it is certain (the point more than 1e-9 rad
// from both lines, far beyond the rounding of either form). 1 reached, 0 not, -1 ask Reach.
struct ReachSector {
  double ux, uy, wx, wy;  // directions theta and theta - span
  bool wide;              // span > pi: the test is of the arc outside it
  ReachSector(const Reach& r, double psi) {
    const double theta = r.sign > 0 ? psi - r.shift : psi + r.shift;
    ux = std::cos(theta), uy = std::sin(theta), wx = std::cos(theta - r.span), wy = std::sin(theta - r.span);
    wide = r.span > M_PI;
  }
  int operator()(double x, double y, double rho) const {
    const double margin = 1e-9 * rho;
    const double cw = wx * y - wy * x;  // w x p: > 0 when p lies counter-clockwise of w
    const double cu = x * uy - y * ux;  // p x u: > 0 when u lies counter-clockwise of p
    if (std::abs(cw) <= margin || std::abs(cu) <= margin) return -1;
    if (!wide) return cw > 0 && cu > 0;
    return !(cw < 0 && cu < 0);  // outside the arc from u to w (shorter than pi)
  }
};

// Forward kinematics split at the joints that vary over a slice. kin::forward walks the
// rows from chain.base, and each row's step reads only the frame before it and the row's
// own joint value: so kin::forward over the rows from a joint on, started from the frame
// before that joint (a copy of the chain holding those rows, its base set to that frame),
// gives bit for bit the pose kin::forward gives over the whole chain. The frame before a
// varying joint depends only on the joints before it, so it is computed once for all the
// values of the joints after it.
class SplitFk {
 public:
  // cuts: the varying joints, ascending; q: the value of every other joint. Segment s
  // holds the rows from cuts[s - 1] (from the first row, s = 0) to cuts[s] (to the last
  // row and the tool, s = cuts.size()).
  SplitFk(const kin::Chain& chain, const std::vector<int>& cuts, const kin::JointVector& q) {
    const int k = static_cast<int>(cuts.size());
    for (int s = 0; s <= k; ++s) {
      const int j0 = s == 0 ? 0 : cuts[static_cast<std::size_t>(s - 1)];
      const int j1 = s == k ? chain.n_joints : cuts[static_cast<std::size_t>(s)];
      const int r0 = s == 0 ? 0 : chain.joint_row[static_cast<std::size_t>(j0)];
      const int r1 = s == k ? chain.n_rows : chain.joint_row[static_cast<std::size_t>(j1)];
      Segment g;
      g.chain = chain;
      g.chain.n_rows = r1 - r0;
      for (int r = r0; r < r1; ++r) g.chain.rows[static_cast<std::size_t>(r - r0)] = chain.rows[static_cast<std::size_t>(r)];
      g.chain.n_joints = j1 - j0;
      for (int j = j0; j < j1; ++j)
        g.chain.joint_row[static_cast<std::size_t>(j - j0)] = static_cast<std::int8_t>(chain.joint_row[static_cast<std::size_t>(j)] - r0);
      if (s < k) g.chain.tool = kin::Pose::Identity(), g.chain.tool_is_identity = true;
      g.q = q.segment(j0, j1 - j0);
      seg_.push_back(std::move(g));
    }
  }
  // The frame after segment s (after the last: the tool pose), from the frame before it,
  // the segment's first joint (a varying one, s > 0) at x.
  void advance(int s, const kin::Pose& before, double x, kin::Pose& after) {
    Segment& g = seg_[static_cast<std::size_t>(s)];
    g.chain.base = before;
    if (s > 0) g.q[0] = x;
    kin::forward(g.chain, g.q, after);
  }

 private:
  struct Segment {
    kin::Chain chain;
    kin::JointVector q;
  };
  std::vector<Segment> seg_;
};

}  // namespace

WorkspaceResult compute_workspace(const kin::Chain& chain, const WorkspaceOptions& opt) {
  WorkspaceResult res;
  auto fail = [&](int st, const std::string& e) {
    res.status = st;
    res.error = e;
    return res;
  };
  const int n = chain.n_joints;
  if (n < 1) return fail(2, "the robot has no joints");
  if (opt.grid < 100 || opt.grid > 2000) return fail(2, "--grid must be within 100..2000, got " + std::to_string(opt.grid));
  // Joint ranges: the limits; a revolute joint turns at most one turn.
  std::vector<Range> rg(static_cast<std::size_t>(n));
  for (int j = 0; j < n; ++j) {
    const kin::DhRow& r = chain.joint(j);
    Range x{r.lower, r.upper};
    if (r.type == kin::JointType::prismatic) {
      if (!std::isfinite(x.lo) || !std::isfinite(x.hi))
        return fail(2, "joint " + std::to_string(j + 1) + " is prismatic without limits: its stroke is needed");
    } else {
      if (!std::isfinite(x.lo)) x.lo = std::isfinite(x.hi) ? x.hi - kTwoPi : -M_PI;
      if (!std::isfinite(x.hi) || x.hi - x.lo > kTwoPi) x.hi = x.lo + kTwoPi;
    }
    rg[static_cast<std::size_t>(j)] = x;
  }
  // The reference pose.
  kin::JointVector qref(n);
  if (!opt.pose.empty()) {
    std::string e;
    if (!joints_from_user(chain, opt.pose, qref, e)) return fail(2, "--pose: " + e);
    std::string rep;
    if (limit_violations(chain, qref, rep) > 0) return fail(2, "--pose is outside the joint limits: " + rep.substr(0, rep.find('\n')));
  } else {
    for (int j = 0; j < n; ++j) qref[j] = std::clamp(0.0, rg[static_cast<std::size_t>(j)].lo, rg[static_cast<std::size_t>(j)].hi);
  }
  res.pose = qref;

  // What kind of arm: sample it.
  std::mt19937 rng(20261201);
  auto random_q = [&]() {
    kin::JointVector q(n);
    for (int j = 0; j < n; ++j)
      q[j] = std::uniform_real_distribution<double>(rg[static_cast<std::size_t>(j)].lo, rg[static_cast<std::size_t>(j)].hi)(rng);
    return q;
  };
  kin::Pose T;
  auto tip = [&](const kin::JointVector& q) {
    kin::forward(chain, q, T);
    ++res.evaluations;
    return Eigen::Vector3d(T.translation());
  };
  double scale = 0;
  Eigen::Vector3d lo3 = Eigen::Vector3d::Constant(1e300), hi3 = Eigen::Vector3d::Constant(-1e300);
  std::vector<kin::JointVector> probes;
  for (int k = 0; k < 64; ++k) {
    probes.push_back(random_q());
    const Eigen::Vector3d p = tip(probes.back());
    if (!p.allFinite()) return fail(2, "the tool position is not finite inside the joint limits");
    lo3 = lo3.cwiseMin(p), hi3 = hi3.cwiseMax(p);
    scale = std::max(scale, p.norm());
  }
  const double tol = 1e-9 * std::max(scale, 1e-3);
  Kind kind;
  for (int k = 0; k < 3; ++k)
    if (hi3[k] - lo3[k] < tol) {
      kind.planar = true;
      kind.normal = k;
      kind.level = (hi3[k] + lo3[k]) / 2;
    }
  if (!kind.planar && chain.joint(0).type == kin::JointType::revolute) {
    bool ok = true;
    double sgn = 0;
    for (int k = 0; k < 16 && ok; ++k) {
      kin::JointVector q = probes[static_cast<std::size_t>(k)];
      const Eigen::Vector3d p = tip(q);
      const double rho = std::hypot(p.x(), p.y());
      for (double d : {0.3, -0.7}) {
        kin::JointVector q2 = q;
        q2[0] += d;
        const Eigen::Vector3d p2 = tip(q2);
        if (std::abs(p2.z() - p.z()) > tol || std::abs(std::hypot(p2.x(), p2.y()) - rho) > tol) ok = false;
        if (rho > 1e-6 * scale) {
          const double turn = wrap(std::atan2(p2.y(), p2.x()) - std::atan2(p.y(), p.x()));
          const double s = std::abs(turn - d) < 1e-6 ? 1 : std::abs(turn + d) < 1e-6 ? -1 : 0;
          if (s == 0 || (sgn != 0 && s != sgn)) ok = false;
          sgn = s;
        }
      }
    }
    kind.turning = ok && sgn != 0;
    kind.sign = sgn;
  }
  std::string plane = opt.plane;
  if (plane.empty()) plane = kind.planar ? (kind.normal == 2 ? "xy" : kind.normal == 1 ? "xz" : "yz") : "xz";
  if (plane != "xz" && plane != "xy" && plane != "yz") return fail(2, "--plane must be xz, xy or yz, got '" + plane + "'");
  res.plane = plane;
  res.u = plane[0], res.v = plane[1];
  const int normal = 3 - axis_index(res.u) - axis_index(res.v);
  if (kind.planar) {
    if (normal != kind.normal) {
      const std::string own = kind.normal == 2 ? "xy" : kind.normal == 1 ? "xz" : "yz";
      return fail(1, std::string(chain.name.data()) + " moves in the " + own + " plane: its " + plane +
                         " section is a line, not an area (use --plane " + own + ")");
    }
    res.method = "planar";
    res.level = kind.level;
  } else if (kind.turning) {
    res.method = "turning";
  } else {
    return fail(1, std::string(chain.name.data()) +
                       ": neither planar nor turned about the base z axis by joint 1: kin workspace does not handle this arm");
  }

  // The joints that move the tool point (joint 1 of a turning arm is solved for).
  const int first = kind.turning ? 1 : 0;
  std::vector<double> sweep(static_cast<std::size_t>(n), 0);
  for (int k = 0; k < 16; ++k) {
    const kin::JointVector& q = probes[static_cast<std::size_t>(k)];
    const Eigen::Vector3d p = tip(q);
    for (int j = first; j < n; ++j) {
      kin::JointVector q2 = q;
      q2[j] += 1e-5;
      const double sens = (tip(q2) - p).norm() / 1e-5;
      const Range& r = rg[static_cast<std::size_t>(j)];
      sweep[static_cast<std::size_t>(j)] = std::max(sweep[static_cast<std::size_t>(j)], sens * (r.hi - r.lo));
    }
  }
  std::vector<int> moving;
  for (int j = first; j < n; ++j)
    if (sweep[static_cast<std::size_t>(j)] > 1e-6 * std::max(scale, 1e-3)) moving.push_back(j);
  std::sort(moving.begin(), moving.end(), [&](int a, int b) { return sweep[static_cast<std::size_t>(a)] > sweep[static_cast<std::size_t>(b)]; });
  const bool one_side_only = kind.turning && moving.size() == 1;  // e.g. a turning arm with one more joint
  if (moving.size() < 2 && !one_side_only)
    return fail(1, std::string(chain.name.data()) + ": the tool point moves along a curve, not over an area");
  if (one_side_only) return fail(1, std::string(chain.name.data()) + ": in the " + plane + " plane the tool point moves along a curve");
  const int ja = moving[0], jb = moving[1];
  const Range r0 = rg[0];
  const double q0ref = kind.turning ? qref[0] : 0;

  // Map one tool point to plane points: up to two (u, v) for a turning arm in xz / yz.
  const int iu = axis_index(res.u), iv = axis_index(res.v);
  const bool slice = kind.turning && plane == "xy";
  const double psi_plus = iu == 0 ? 0 : M_PI / 2;  // azimuth of the +u half-plane (xz: +x, yz: +y)
  const Reach reaches(r0, q0ref, kind.sign);

  // Pass 0 (coarse) estimates the extent, the next pass fills the raster over it. The
  // coarse pass can miss the far reach (e.g. an offset tool turned sideways by wrist joints
  // at values between its few steps, brought into the plane by joint 1 near its limit): a
  // fill pass whose points leave the raster is run again over their whole extent, so the
  // raster holds every point the fill pass sampled.
  struct Node {
    double u[2], v[2];
    bool ok[2];
    double rho, z, phi;
    double s, w;  // turning: along / across the slice's reference azimuth (see below)
    double x, y;  // turning: the tool point's x and y
    int ci[2], cj;  // fill pass: the raster cell of (u[s], v[s]), rounded down (Raster::index)
    int s_sign;     // turning: 1 s > 0, 2 s < 0, 0 s = 0
    bool exact;   // turning: s and w computed
    bool has_phi;  // turning: phi computed (always in the xy plane, else where needed)
  };
  // phi = atan2(y, x) of the tool point, computed once where it is needed
  auto phi_of = [](Node& nd) {
    if (!nd.has_phi) nd.phi = std::atan2(nd.y, nd.x), nd.has_phi = true;
    return nd.phi;
  };
  const ReachSector sector[2] = {ReachSector(reaches, psi_plus), ReachSector(reaches, psi_plus + M_PI)};
  Raster ras;
  std::vector<std::uint8_t> polar;  // slice: [rho bin][azimuth bin]
  int n_rho = 0, n_az = 0;
  double umin = 1e300, umax = -1e300, vmin = 1e300, vmax = -1e300;
  constexpr int kMaxPasses = 4;  // the coarse pass and at most three fill passes
  bool regrow = true;
  for (int pass = 0; pass < 2 || (regrow && pass < kMaxPasses); ++pass) {
    const bool coarse = pass == 0;
    double fu0 = 1e300, fu1 = -1e300, fv0 = 1e300, fv1 = -1e300;  // extent of this fill pass's points
    if (!coarse) {
      // the coarse pass saw fewer points: widen its extent by 5 % on every side
      const double pu = 0.05 * (umax - umin), pv = 0.05 * (vmax - vmin), pm = std::max(pu, pv);
      const double u_lo = umin - pm, u_hi = umax + pm, v_lo = vmin - pm, v_hi = vmax + pm;
      const double su = u_hi - u_lo, sv = v_hi - v_lo;
      if (slice) {
        const double rmax = std::max({std::abs(u_lo), std::abs(u_hi), 1e-6});
        ras.cell = 2 * rmax / opt.grid;
        n_rho = static_cast<int>(std::ceil(rmax / ras.cell)) + 3;
        n_az = std::clamp(static_cast<int>(std::ceil(kTwoPi * rmax / ras.cell)), 360, 8192);
        polar.assign(static_cast<std::size_t>(n_rho) * n_az, 0);
      } else {
        ras.cell = std::max(su, sv) / opt.grid;
        if (!(ras.cell > 0)) return fail(1, std::string(chain.name.data()) + ": the reachable set is a point");
        ras.u0 = u_lo - 3 * ras.cell, ras.v0 = v_lo - 3 * ras.cell;
        ras.nu = static_cast<int>(std::ceil(su / ras.cell)) + 6;
        ras.nv = static_cast<int>(std::ceil(sv / ras.cell)) + 6;
        ras.clear();
      }
    }
    // The quadrilaterals interpolate between the two gridded joints' steps; nothing
    // interpolates between the other joints' steps, and a small sideways move of the tool
    // (a wrist joint) can move a point a long way in the plane when joint 1's limit decides
    // where it lands. So the fill pass spends its FK evaluations on those joints: 61 x 61
    // points per slice, up to 33 steps per other joint and about 1200 slices.
    const int m = coarse ? 24 : 60;  // steps of the two quad joints
    std::vector<int> steps;          // of the other moving joints
    long combos = 1;
    for (std::size_t k = 2; k < moving.size(); ++k) {
      const double cell_est = coarse ? 1e300 : ras.cell;
      int s = coarse ? 9 : static_cast<int>(std::ceil(sweep[static_cast<std::size_t>(moving[k])] / (3 * cell_est)));
      s = std::clamp(s, 3, 33);
      steps.push_back(s);
      combos *= s;
    }
    while (combos > (coarse ? 300 : 1200)) {  // budget: about 1200 slices of (m + 1)^2 points
      auto it = std::max_element(steps.begin(), steps.end());
      combos = combos / *it * (*it - 1);
      --*it;
    }
    std::vector<Node> grid(static_cast<std::size_t>((m + 1) * (m + 1)));
    // The joints that vary over the slices, in chain order: the two gridded ones (m + 1
    // values) and the stepped ones. The slices run through the stepped joints' values
    // with the joint last in the chain fastest, so a frame before a stepped joint serves
    // every slice that differs only in joints after it (SplitFk). The raster is the union
    // of the quads' cells: the order of the slices does not change it.
    struct Var {
      int joint;
      bool gridded;
      std::vector<double> value;
    };
    std::vector<Var> vars;
    auto add_var = [&](int j, bool gridded, int count) {
      const Range& r = rg[static_cast<std::size_t>(j)];
      Var v{j, gridded, {}};
      for (int i = 0; i < count; ++i) v.value.push_back(gridded ? r.lo + (r.hi - r.lo) * i / m : r.lo + (r.hi - r.lo) * i / (count - 1));
      vars.push_back(std::move(v));
    };
    add_var(ja, true, m + 1);
    add_var(jb, true, m + 1);
    for (std::size_t k = 0; k < steps.size(); ++k) add_var(moving[k + 2], false, steps[k]);
    std::sort(vars.begin(), vars.end(), [](const Var& x, const Var& y) { return x.joint < y.joint; });
    const int nvar = static_cast<int>(vars.size());
    std::vector<int> cuts;
    for (const Var& v : vars) cuts.push_back(v.joint);
    kin::JointVector q = qref;
    if (kind.turning) q[0] = q0ref;
    SplitFk fk(chain, cuts, q);
    // level[i]: the frames before vars[i], one per combination of the gridded joints before it
    std::vector<std::vector<kin::Pose>> level(static_cast<std::size_t>(nvar));
    level[0].resize(1);
    fk.advance(0, chain.base, 0, level[0][0]);
    std::vector<int> digit(static_cast<std::size_t>(nvar), 0);  // the stepped joints' value index
    const bool a_first = ja < jb;  // the gridded index at the tips is a (m + 1) + b, else b (m + 1) + a
    for (long c = 0; c < combos; ++c) {
      int from = 1;  // the first level whose frames change
      if (c > 0) {
        int i = nvar - 1;
        for (; i >= 0; --i) {
          if (vars[static_cast<std::size_t>(i)].gridded) continue;
          if (++digit[static_cast<std::size_t>(i)] < static_cast<int>(vars[static_cast<std::size_t>(i)].value.size())) break;
          digit[static_cast<std::size_t>(i)] = 0;
        }
        from = i + 1;
      }
      auto values = [&](int i, int& x0, int& x1) {  // the value indices of vars[i] in this slice
        const Var& v = vars[static_cast<std::size_t>(i)];
        x0 = v.gridded ? 0 : digit[static_cast<std::size_t>(i)];
        x1 = v.gridded ? m : x0;
      };
      for (int i = from; i < nvar; ++i) {
        int x0, x1;
        values(i - 1, x0, x1);
        const std::vector<kin::Pose>& before = level[static_cast<std::size_t>(i - 1)];
        std::vector<kin::Pose>& after = level[static_cast<std::size_t>(i)];
        after.resize(before.size() * static_cast<std::size_t>(x1 - x0 + 1));
        std::size_t o = 0;
        for (const kin::Pose& f : before)
          for (int x = x0; x <= x1; ++x) fk.advance(i, f, vars[static_cast<std::size_t>(i - 1)].value[static_cast<std::size_t>(x)], after[o++]);
      }
      int x0, x1;
      values(nvar - 1, x0, x1);
      const std::vector<kin::Pose>& before = level[static_cast<std::size_t>(nvar - 1)];
      std::size_t g = 0;  // the gridded joints' combined index, in chain order
      kin::Pose T;
      for (const kin::Pose& f : before)
        for (int x = x0; x <= x1; ++x, ++g) {
          fk.advance(nvar, f, vars[static_cast<std::size_t>(nvar - 1)].value[static_cast<std::size_t>(x)], T);
          ++res.evaluations;
          const Eigen::Vector3d p = T.translation();
          const std::size_t mm = static_cast<std::size_t>(m + 1);
          Node& nd = grid[a_first ? g : (g % mm) * mm + g / mm];
          if (kind.planar) {
            nd.u[0] = p[iu], nd.v[0] = p[iv], nd.ok[0] = true, nd.ok[1] = false;
          } else {
            nd.rho = std::hypot(p.x(), p.y()), nd.z = p.z();
            nd.x = p.x(), nd.y = p.y(), nd.has_phi = false;
            if (slice) phi_of(nd);
            nd.u[0] = nd.rho, nd.u[1] = -nd.rho, nd.v[0] = nd.v[1] = nd.z;
            for (int s = 0; s < 2; ++s) {
              const int k = reaches.full ? 1 : sector[s](nd.x, nd.y, nd.rho);
              nd.ok[s] = k >= 0 ? k == 1 : reaches(phi_of(nd), s == 0 ? psi_plus : psi_plus + M_PI);
            }
          }
          if (!coarse && !slice) {
            const double inv = 1 / ras.cell;
            nd.ci[0] = Raster::index((nd.u[0] - ras.u0) * inv, ras.nu), nd.cj = Raster::index((nd.v[0] - ras.v0) * inv, ras.nv);
            if (nd.ok[1]) nd.ci[1] = Raster::index((nd.u[1] - ras.u0) * inv, ras.nu);
          }
          for (int s = 0; s < 2; ++s) {
            if (!nd.ok[s] && !slice) continue;
            fu0 = std::min(fu0, nd.u[s]), fu1 = std::max(fu1, nd.u[s]);
            fv0 = std::min(fv0, nd.v[s]), fv1 = std::max(fv1, nd.v[s]);
          }
        }
      // A quad whose corners lie on both sides of the z axis would fold over at rho = 0
      // (rho = |s|) and leave holes along the axis. When the slice's points lie in one
      // vertical plane through the axis (w ~ 0), such a quad is turned as a whole instead:
      // its corners keep their signed distance s along the plane's direction e.
      double ex = 1, ey = 0, best = -1;
      auto exact_sw = [&](Node& nd) {
        const double x = nd.rho * std::cos(phi_of(nd)), y = nd.rho * std::sin(phi_of(nd));
        nd.s = x * ex + y * ey, nd.w = -x * ey + y * ex;
        nd.s_sign = nd.s > 0 ? 1 : nd.s < 0 ? 2 : 0;
        nd.exact = true;
      };
      if (kind.turning) {
        for (Node& nd : grid)
          if (nd.rho > best) best = nd.rho, ex = std::cos(phi_of(nd)), ey = std::sin(phi_of(nd));
        // s and w from the polar form (rho, phi), as every quad uses them. Outside the xy
        // plane a quad needs only the sign of s at its corners unless they have both signs:
        // the sign from the tool point's own x and y where it is certain (|s| well above the
        // few ulps of rho by which the two forms differ), s and w themselves when needed.
        for (Node& nd : grid) {
          nd.exact = false;
          if (!slice && !coarse) {
            const double s_near = nd.x * ex + nd.y * ey;
            if (std::abs(s_near) > 1e-12 * nd.rho) {
              nd.s_sign = s_near > 0 ? 1 : 2;
              continue;
            }
          }
          if (!coarse) exact_sw(nd);
        }
      }
      const double phi_e = std::atan2(ey, ex);
      const bool e_plus = kind.turning && reaches(phi_e, psi_plus);
      const bool e_minus = kind.turning && reaches(phi_e, psi_plus + M_PI);
      if (!coarse) {
        // The quads in groups of kGroup x kGroup: when every cell a group's quads can set on
        // a side (the box of its nodes' cells widened by one) is set, none of them is filled
        // there. (The raster is a union of cells: the order of the quads does not matter.)
        constexpr int kGroup = 4;
        for (int ga = 0; ga < m; ga += kGroup)
          for (int gb = 0; gb < m; gb += kGroup) {
          const int ga1 = std::min(m, ga + kGroup), gb1 = std::min(m, gb + kGroup);
          bool group_full[2] = {false, false};
          for (int s = 0; s < 2 && !slice; ++s) {
            int i0 = ras.nu, i1 = -1, j0 = ras.nv, j1 = -1;
            for (int a = ga; a <= ga1; ++a)
              for (int b = gb; b <= gb1; ++b) {
                const Node& nd = grid[static_cast<std::size_t>(a * (m + 1) + b)];
                if (!nd.ok[s]) continue;
                i0 = std::min(i0, nd.ci[s]), i1 = std::max(i1, nd.ci[s]), j0 = std::min(j0, nd.cj), j1 = std::max(j1, nd.cj);
              }
            group_full[s] = ras.box_full(std::max(0, i0 - 1), std::min(ras.nu - 1, i1 + 1), std::max(0, j0 - 1), std::min(ras.nv - 1, j1 + 1));
          }
          if (!slice && group_full[0] && group_full[1]) {  // nothing to fill unless a quad has corners with s of both signs
            int signs = 0;
            for (int a = ga; a <= ga1 && kind.turning; ++a)
              for (int b = gb; b <= gb1; ++b) signs |= grid[static_cast<std::size_t>(a * (m + 1) + b)].s_sign;
            if (signs != 3) continue;
          }
        for (int a = ga; a < ga1; ++a)
          for (int b = gb; b < gb1; ++b) {
            const Node* c4[4] = {&grid[static_cast<std::size_t>(a * (m + 1) + b)], &grid[static_cast<std::size_t>((a + 1) * (m + 1) + b)],
                                 &grid[static_cast<std::size_t>((a + 1) * (m + 1) + b + 1)], &grid[static_cast<std::size_t>(a * (m + 1) + b + 1)]};
            if (slice) {
              // Where the quad (rho, z) crosses z = 0, and the azimuths joint 1 gives it.
              // (A quad across the axis in one vertical plane: its signed s, as above.)
              bool pos = false, neg = false;
              double wmax = 0;
              for (int k = 0; k < 4; ++k) pos = pos || c4[k]->s > 0, neg = neg || c4[k]->s < 0, wmax = std::max(wmax, std::abs(c4[k]->w));
              const bool signed_s = pos && neg && wmax < 2 * ras.cell;
              double rlo = 1e300, rhi = -1e300;
              for (int k = 0; k < 4; ++k) {
                const Node& e = *c4[k];
                const Node& f = *c4[(k + 1) % 4];
                const double re = signed_s ? e.s : e.rho, rf = signed_s ? f.s : f.rho;
                if (e.z == 0) rlo = std::min(rlo, re), rhi = std::max(rhi, re);
                if ((e.z < 0) != (f.z < 0) && e.z != f.z) {
                  const double r = re + (0 - e.z) * (rf - re) / (f.z - e.z);
                  rlo = std::min(rlo, r), rhi = std::max(rhi, r);
                }
              }
              if (rlo > rhi) continue;
              if (signed_s) {  // the crossing spans the axis when its ends have both signs
                const double a0 = std::abs(rlo), a1 = std::abs(rhi);
                rhi = std::max(a0, a1);
                rlo = rlo < 0 && rhi > 0 ? 0.0 : std::min(a0, a1);
                rhi = std::max(a0, a1);
              }
              double plo = c4[0]->phi, phi_hi = c4[0]->phi;
              for (int k = 1; k < 4; ++k) {
                const double d = c4[0]->phi + wrap(c4[k]->phi - c4[0]->phi);
                plo = std::min(plo, d), phi_hi = std::max(phi_hi, d);
              }
              const bool full = r0.hi - r0.lo >= kTwoPi - 1e-9;
              const double a0 = kind.sign > 0 ? plo + (r0.lo - q0ref) : plo - (r0.hi - q0ref);
              const double a1 = a0 + (r0.hi - r0.lo) + (phi_hi - plo);
              const int b0 = static_cast<int>(std::floor(rlo / ras.cell)), b1 = std::min(n_rho - 1, static_cast<int>(std::floor(rhi / ras.cell)));
              for (int rb = std::max(0, b0); rb <= b1; ++rb) {
                std::uint8_t* row = &polar[static_cast<std::size_t>(rb) * n_az];
                if (full) {
                  std::fill(row, row + n_az, 1);
                  continue;
                }
                const int k0 = static_cast<int>(std::floor((a0 + M_PI) / kTwoPi * n_az));
                const int k1 = static_cast<int>(std::ceil((a1 + M_PI) / kTwoPi * n_az));
                for (int k = k0; k <= k1 && k - k0 <= n_az; ++k) row[((k % n_az) + n_az) % n_az] = 1;
              }
              continue;
            }
            if (kind.turning) {
              const int signs = c4[0]->s_sign | c4[1]->s_sign | c4[2]->s_sign | c4[3]->s_sign;
              const bool pos = (signs & 1) != 0, neg = (signs & 2) != 0;
              double wmax = 0;
              for (int k = 0; k < 4 && pos && neg; ++k) {
                Node& nd = grid[static_cast<std::size_t>(c4[k] - grid.data())];
                if (!nd.exact) exact_sw(nd);
                wmax = std::max(wmax, std::abs(nd.w));
              }
              if (pos && neg && wmax < 2 * ras.cell) {
                for (int side = 0; side < 2; ++side) {
                  if (!(side == 0 ? e_plus : e_minus)) continue;
                  double poly[4][2];
                  for (int k = 0; k < 4; ++k) poly[k][0] = side == 0 ? c4[k]->s : -c4[k]->s, poly[k][1] = c4[k]->z;
                  ras.fill(poly, 4);
                }
                continue;
              }
            }
            for (int s = 0; s < 2; ++s) {
              if (group_full[s] || !(c4[0]->ok[s] && c4[1]->ok[s] && c4[2]->ok[s] && c4[3]->ok[s])) continue;
              // every cell fill() can set (the corners' cells widened by one) set already: skip
              const int i0 = std::max(0, std::min({c4[0]->ci[s], c4[1]->ci[s], c4[2]->ci[s], c4[3]->ci[s]}) - 1);
              const int i1 = std::min(ras.nu - 1, std::max({c4[0]->ci[s], c4[1]->ci[s], c4[2]->ci[s], c4[3]->ci[s]}) + 1);
              const int j0 = std::max(0, std::min({c4[0]->cj, c4[1]->cj, c4[2]->cj, c4[3]->cj}) - 1);
              const int j1 = std::min(ras.nv - 1, std::max({c4[0]->cj, c4[1]->cj, c4[2]->cj, c4[3]->cj}) + 1);
              if (ras.box_full(i0, i1, j0, j1)) continue;
              double poly[4][2];
              for (int k = 0; k < 4; ++k) poly[k][0] = c4[k]->u[s], poly[k][1] = c4[k]->v[s];
              ras.fill(poly, 4);
            }
          }
          }
      }
    }
    // Does the raster hold every point of this pass? If not, the next pass covers their extent.
    if (!coarse) {
      regrow = slice ? std::max(std::abs(fu0), std::abs(fu1)) > (n_rho - 3) * ras.cell
                     : fu0 < ras.u0 || fu1 > ras.u0 + ras.nu * ras.cell || fv0 < ras.v0 || fv1 > ras.v0 + ras.nv * ras.cell;
    }
    umin = std::min(umin, fu0), umax = std::max(umax, fu1), vmin = std::min(vmin, fv0), vmax = std::max(vmax, fv1);
  }
  if (slice) {  // the xy plane from the ring of radii reached at z = 0
    const double rmax = (n_rho - 3) * ras.cell;
    ras.u0 = ras.v0 = -rmax - 2 * ras.cell;
    ras.nu = ras.nv = static_cast<int>(std::ceil(2 * rmax / ras.cell)) + 4;
    ras.on.assign(static_cast<std::size_t>(ras.nu) * ras.nv, 0);
    for (int j = 0; j < ras.nv; ++j)
      for (int i = 0; i < ras.nu; ++i) {
        const double x = ras.u0 + (i + 0.5) * ras.cell, y = ras.v0 + (j + 0.5) * ras.cell;
        const int rb = static_cast<int>(std::floor(std::hypot(x, y) / ras.cell));
        if (rb >= n_rho) continue;
        const int k = std::clamp(static_cast<int>(std::floor((std::atan2(y, x) + M_PI) / kTwoPi * n_az)), 0, n_az - 1);
        ras.on[static_cast<std::size_t>(j) * ras.nu + i] = polar[static_cast<std::size_t>(rb) * n_az + k];
      }
  }
  // Area: full cells, boundary cells (a 4-neighbour empty) counted half.
  long full = 0, edge = 0;
  for (int j = 0; j < ras.nv; ++j)
    for (int i = 0; i < ras.nu; ++i) {
      if (!ras.on[static_cast<std::size_t>(j) * ras.nu + i]) continue;
      auto at = [&](int a, int b) { return a >= 0 && a < ras.nu && b >= 0 && b < ras.nv && ras.on[static_cast<std::size_t>(b) * ras.nu + a]; };
      if (at(i - 1, j) && at(i + 1, j) && at(i, j - 1) && at(i, j + 1)) ++full;
      else ++edge;
    }
  res.area = (static_cast<double>(full) + 0.5 * static_cast<double>(edge)) * ras.cell * ras.cell;
  if (!(res.area > 0)) return fail(1, std::string(chain.name.data()) + ": no reachable area in the " + plane + " plane");
  res.u0 = ras.u0, res.v0 = ras.v0, res.cell = ras.cell, res.nu = ras.nu, res.nv = ras.nv;
  res.on = std::move(ras.on);
  return res;
}

namespace {

bool write_csv(const std::string& path, const kin::Chain& c, const WorkspaceResult& w) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) return false;
  const double L = c.length_unit;
  std::fprintf(f, "%c,%c_from,%c_to\n", w.v, w.u, w.u);
  for (int j = 0; j < w.nv; ++j)
    for (int i = 0; i < w.nu; ++i) {
      if (!w.at(i, j) || (i > 0 && w.at(i - 1, j))) continue;
      int k = i;
      while (k + 1 < w.nu && w.at(k + 1, j)) ++k;
      std::fprintf(f, "%.6g,%.6g,%.6g\n", w.vc(j) / L, w.uc(i) / L, w.uc(k) / L);
    }
  return std::fclose(f) == 0;
}

std::string area_text(const kin::Chain& c, double area_m2) {
  char b[120];
  const double user = area_m2 / (c.length_unit * c.length_unit);
  if (c.length_unit == 1.0) std::snprintf(b, sizeof b, "%.4g m\u00b2", area_m2);
  else std::snprintf(b, sizeof b, "%.4g m\u00b2 (%.4g %s\u00b2)", area_m2, user, length_unit_name(c));
  return b;
}

bool write_svg(const std::string& path, const kin::Chain& c, const WorkspaceResult& w) {
  namespace sv = svg;
  const double L = c.length_unit;
  const std::string lu = length_unit_name(c);
  // The arm in the reference pose: frame origins, then the tool point (turned into the
  // plane's +u side by joint 1 when the arm turns and its limits allow).
  kin::JointVector q = w.pose;
  kin::Pose T;
  kin::forward(c, q, T);
  if (w.method == "turning") {
    const double phi = std::atan2(T.translation().y(), T.translation().x());
    const double target = w.u == 'x' ? 0 : w.u == 'y' ? M_PI / 2 : 0;
    for (double s : {1.0, -1.0}) {
      kin::JointVector q2 = q;
      q2[0] = q[0] + s * wrap(target - phi);
      kin::Pose T2;
      kin::forward(c, q2, T2);
      const double phi2 = std::atan2(T2.translation().y(), T2.translation().x());
      if (std::abs(wrap(phi2 - target)) < 1e-6 && q2[0] >= c.joint(0).lower && q2[0] <= c.joint(0).upper) {
        q = q2;
        break;
      }
    }
  }
  kin::FrameSet fs;
  kin::forward_frames(c, q, fs, T);
  const int iu = axis_index(w.u), iv = axis_index(w.v);
  std::vector<double> au, av;
  for (int k = 0; k <= c.n_rows; ++k) au.push_back(fs.frame[k].translation()[iu] / L), av.push_back(fs.frame[k].translation()[iv] / L);
  au.push_back(T.translation()[iu] / L), av.push_back(T.translation()[iv] / L);

  double ulo = 1e300, uhi = -1e300, vlo = 1e300, vhi = -1e300;
  for (int j = 0; j < w.nv; ++j)
    for (int i = 0; i < w.nu; ++i)
      if (w.at(i, j)) ulo = std::min(ulo, w.uc(i)), uhi = std::max(uhi, w.uc(i)), vlo = std::min(vlo, w.vc(j)), vhi = std::max(vhi, w.vc(j));
  ulo = std::min(ulo / L, 0.0), uhi = std::max(uhi / L, 0.0), vlo = std::min(vlo / L, 0.0), vhi = std::max(vhi / L, 0.0);
  for (std::size_t k = 0; k < au.size(); ++k) ulo = std::min(ulo, au[k]), uhi = std::max(uhi, au[k]), vlo = std::min(vlo, av[k]), vhi = std::max(vhi, av[k]);
  const double pad = 0.05 * std::max(uhi - ulo, vhi - vlo);
  const double W = 900, H = 820;
  sv::Doc d(W, H);
  const sv::Panel p = sv::make_panel(90, 60, 560, 700, ulo - pad, uhi + pad, vlo - pad, vhi + pad, true, 7, 8);
  char title[200];
  std::snprintf(title, sizeof title, "%s: workspace in the %s plane (%c = %s %s), area %s", c.name.data(), w.plane.c_str(),
                "xyz"[3 - iu - iv], num(w.level / L).c_str(), lu.c_str(), area_text(c, w.area).c_str());
  d.text(90, 28, title, "start", 15);
  char cell[32];
  std::snprintf(cell, sizeof cell, "%.3g", w.cell / L);
  d.text(90, 46, "tool point, joint limits respected; grid " + std::to_string(std::max(w.nu, w.nv)) + " cells of " + cell + " " + lu,
         "start", 11, "#555");
  d.axes(p, std::string(1, w.u) + " [" + lu + "]", std::string(1, w.v) + " [" + lu + "]");
  // The region: one rectangle per run of cells in a row.
  std::string g = "<g fill=\"#9ecae1\" stroke=\"none\" shape-rendering=\"crispEdges\">\n";
  char b[200];
  const double px = p.pw / (p.x1 - p.x0);  // pixels per length unit
  for (int j = 0; j < w.nv; ++j)
    for (int i = 0; i < w.nu; ++i) {
      if (!w.at(i, j) || (i > 0 && w.at(i - 1, j))) continue;
      int k = i;
      while (k + 1 < w.nu && w.at(k + 1, j)) ++k;
      const double x0 = p.X((w.u0 + i * w.cell) / L), y1 = p.Y((w.v0 + (j + 1) * w.cell) / L);
      std::snprintf(b, sizeof b, "<rect x=\"%.2f\" y=\"%.2f\" width=\"%.2f\" height=\"%.2f\"/>\n", x0, y1,
                    (k - i + 1) * w.cell / L * px + 0.05, w.cell / L * px + 0.05);
      g += b;
    }
  g += "</g>\n";
  d.raw(g);
  d.polyline(p, au, av, "#222", 3);
  for (std::size_t k = 0; k + 1 < au.size(); ++k) {
    std::snprintf(b, sizeof b, "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"3.5\" fill=\"white\" stroke=\"#222\" stroke-width=\"1.5\"/>\n",
                  p.X(au[k]), p.Y(av[k]));
    d.raw(b);
  }
  std::snprintf(b, sizeof b, "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"5\" fill=\"#d62728\"/>\n", p.X(au.back()), p.Y(av.back()));
  d.raw(b);
  std::snprintf(b, sizeof b, "<rect x=\"%.1f\" y=\"%.1f\" width=\"12\" height=\"12\" fill=\"#222\"/>\n", p.X(0) - 6, p.Y(0) - 6);
  d.raw(b);
  std::string pose;
  const std::vector<double> qu = joints_to_user(c, q);
  for (double x : qu) pose += (pose.empty() ? "" : " ") + num(std::round(x * 100) / 100);
  d.legend(p.px + p.pw + 20, p.py, {{"reachable region", "#9ecae1", "fill"},
                                     {"arm, reference pose", "#222", "line"},
                                     {"tool point", "#d62728", "dot"},
                                     {"base (origin)", "#222", "fill"}});
  d.text(p.px + p.pw + 20, p.py + 110, "reference pose [" + std::string(angle_unit_name(c)) + "/" + lu + "]:", "start", 11);
  d.text(p.px + p.pw + 20, p.py + 126, pose, "start", 11);
  d.text(p.px + p.pw + 20, p.py + 150, w.method == "planar" ? "planar arm" : "joint 1 turns about z", "start", 11, "#555");
  return d.write(path);
}

}  // namespace

int cli_kin_workspace(int argc, char** argv) {
  std::string robot, svg_path, csv_path;
  WorkspaceOptions opt;
  for (int i = 1; i < argc; ++i) {
    const std::string s = argv[i];
    auto value = [&]() -> const char* {
      return i + 1 < argc && !(argv[i + 1][0] == '-' && argv[i + 1][1] == '-') ? argv[++i] : nullptr;
    };
    if (s == "--help" || s == "-h") {
      std::fputs(kWorkspaceUsage, stdout);
      return kExitOk;
    } else if (s == "--robot" || s == "--svg" || s == "--csv" || s == "--plane") {
      const char* v = value();
      if (!v) return usage_error(s + " needs a value");
      (s == "--robot" ? robot : s == "--svg" ? svg_path : s == "--csv" ? csv_path : opt.plane) = v;
    } else if (s == "--grid") {
      const char* v = value();
      double g = 0;
      if (!v || !parse_number(v, g) || g != std::floor(g) || g < 100 || g > 2000)
        return usage_error(std::string("--grid needs a whole number of cells within 100..2000, got '") + (v ? v : "") + "'");
      opt.grid = static_cast<int>(g);
    } else if (s == "--pose") {
      opt.pose.clear();
      while (i + 1 < argc && !(argv[i + 1][0] == '-' && argv[i + 1][1] == '-')) {
        double x;
        if (!parse_number(argv[i + 1], x)) return usage_error(std::string("--pose: '") + argv[i + 1] + "' is not a finite number");
        opt.pose.push_back(x);
        ++i;
      }
      if (opt.pose.empty()) return usage_error("--pose needs the joint values");
    } else {
      return usage_error("unknown argument '" + s + "' (see armctl kin workspace --help)");
    }
  }
  if (robot.empty()) return usage_error("--robot is required (see armctl kin models)");
  if (!opt.plane.empty() && opt.plane != "xz" && opt.plane != "xy" && opt.plane != "yz")
    return usage_error("--plane must be xz, xy or yz, got '" + opt.plane + "'");
  const kin::LoadResult lr = load_robot_checked(robot);
  if (!lr.ok) return usage_error(lr.error);
  const kin::Chain& chain = lr.chain;
  const WorkspaceResult w = compute_workspace(chain, opt);
  if (w.status != 0) {
    std::fprintf(stderr, "armctl: %s\n", w.error.c_str());
    return w.status == 2 ? kExitUsage : kExitFailed;
  }
  const double L = chain.length_unit;
  double ulo = 1e300, uhi = -1e300, vlo = 1e300, vhi = -1e300;
  for (int j = 0; j < w.nv; ++j)
    for (int i = 0; i < w.nu; ++i)
      if (w.at(i, j)) ulo = std::min(ulo, w.uc(i)), uhi = std::max(uhi, w.uc(i)), vlo = std::min(vlo, w.vc(j)), vhi = std::max(vhi, w.vc(j));
  const char* lu = length_unit_name(chain);
  const int normal = 3 - axis_index(w.u) - axis_index(w.v);
  std::printf("workspace of %s in the %s plane (%c = %s %s): area %s\n", chain.name.data(), w.plane.c_str(), "xyz"[normal],
              num(w.level / L).c_str(), lu, area_text(chain, w.area).c_str());
  auto g4 = [](double v) {  // 4 significant digits, whatever the unit
    char b[32];
    std::snprintf(b, sizeof b, "%.4g", std::abs(v) < 5e-13 ? 0.0 : v);
    return std::string(b);
  };
  std::printf("  %c from %s to %s %s, %c from %s to %s %s (cell centres); grid of %s %s cells, %ld FK evaluations; %s\n",
              w.u, g4(ulo / L).c_str(), g4(uhi / L).c_str(), lu, w.v, g4(vlo / L).c_str(), g4(vhi / L).c_str(), lu,
              g4(w.cell / L).c_str(), lu, w.evaluations,
              w.method == "planar" ? "planar arm" : "joint 1 turns about the base z axis (solved for, limits kept)");
  if (!csv_path.empty()) {
    if (!write_csv(csv_path, chain, w)) return usage_error("cannot write " + csv_path);
    std::printf("csv: %s\n", csv_path.c_str());
  }
  if (!svg_path.empty()) {
    if (!write_svg(svg_path, chain, w)) return usage_error("cannot write " + svg_path);
    std::printf("svg: %s\n", svg_path.c_str());
  }
  return kExitOk;
}

}  // namespace servoarm::fw
