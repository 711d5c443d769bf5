// SPDX-License-Identifier: Apache-2.0
// Blended joint moves through the firmware: console + controller in-process,
// puma560 on the sim bus with virtual CiA 402 drives, single-threaded on a ManualClock,
// the commanded joints sampled every control cycle and every cycle inside an allocation
// counter. A 3-point movej sequence with blend= passes its intermediate corners within
// the tolerance without stopping, every joint within its velocity / acceleration / jerk
// limits (finite differences of the cycle samples: each bounded by the true peak); the
// same sequence without blend= stops at each corner; a stop, and a feed hold, in the
// middle of a blend.
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "alloc_counter.hpp"
#include "sim_app.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;

namespace {

constexpr double kDeg = M_PI / 180.0;

struct Rig {
  hal::ManualClock clock;
  test::SimApp app;
  Session s;
  hal::Duration period = hal::kMillisecond;
  std::size_t rt_allocs = 0;
  std::vector<kin::JointVector> q;  ///< q_cmd after every cycle (when recording)
  bool recording = false;

  explicit Rig(FwConfig cfg = {}) {
    cfg.can = "sim";
    const std::string e = app.build(cfg, &clock);
    if (!e.empty()) FAIL(e.c_str());
    period = static_cast<hal::Duration>(1e9 / cfg.rate_hz);
    clock.set_idle_hook([this](hal::TimePoint t) { app.plant->step(t); });
    const std::string b = app.boot();
    if (!b.empty()) FAIL(b.c_str());
    app.console->set_idle([this] { cycle(); });
  }
  ~Rig() { clock.set_idle_hook(nullptr); }

  void cycle() {
    test::alloc_count_begin();
    app.ctl->cycle(clock.now());
    rt_allocs += test::alloc_count_end();
    clock.advance(period);
    if (recording) q.push_back(q_cmd());
  }
  void step() {
    cycle();
    app.console->poll(s);
  }
  std::string cmd(const std::string& line) {
    s.out.clear();
    app.console->execute(s, line);
    for (int i = 0; i < 60000 && app.console->busy(s); ++i) step();
    return s.out;
  }
  Telemetry tel() const { return app.ctl->telemetry(); }
  kin::JointVector q_cmd() const {
    const Telemetry t = tel();
    kin::JointVector v(6);
    for (int j = 0; j < 6; ++j) v[j] = t.q_cmd[static_cast<std::size_t>(j)];
    return v;
  }
  void enable() {
    const std::string a = cmd("enable");
    if (a.rfind("ok", 0) != 0) FAIL(("enable: " + a).c_str());
    for (int i = 0; i < 2000 && tel().state == ArmState::enabling; ++i) cycle();
    if (tel().state != ArmState::idle) FAIL("not idle after enable");
  }
  double dt() const { return static_cast<double>(period) * 1e-9; }
};

bool is_ok(const std::string& a) { return a.rfind("ok", 0) == 0 || a.find("\nok") != std::string::npos; }

kin::JointVector deg6(std::initializer_list<double> l) {
  kin::JointVector v(6);
  int k = 0;
  for (double x : l) v[k++] = x * kDeg;
  return v;
}

std::string movej(const kin::JointVector& g, double blend_deg) {
  std::string t = "movej";
  for (int j = 0; j < 6; ++j) {
    char b[40];
    std::snprintf(b, sizeof b, " %.12g", g[j] / kDeg);
    t += b;
  }
  t += " speed=100";
  if (blend_deg > 0) {
    char b[40];
    std::snprintf(b, sizeof b, " blend=%g", blend_deg);
    t += b;
  }
  return t;
}

/// Peak |velocity|, |acceleration|, |jerk| over the limits (finite differences of the samples).
struct Peaks {
  double v = 0, a = 0, j = 0;
};
Peaks peaks(const std::vector<kin::JointVector>& q, const kin::JointLimits& lim, double dt, std::size_t from = 0) {
  Peaks p;
  for (std::size_t i = from + 3; i < q.size(); ++i)
    for (int j = 0; j < 6; ++j) {
      const auto& d = lim.dyn[static_cast<std::size_t>(j)];
      const double v = (q[i][j] - q[i - 1][j]) / dt;
      const double a = (q[i][j] - 2 * q[i - 1][j] + q[i - 2][j]) / (dt * dt);
      const double jk = (q[i][j] - 3 * q[i - 1][j] + 3 * q[i - 2][j] - q[i - 3][j]) / (dt * dt * dt);
      p.v = std::fmax(p.v, std::fabs(v) / d.max_velocity);
      p.a = std::fmax(p.a, std::fabs(a) / d.max_acceleration);
      p.j = std::fmax(p.j, std::fabs(jk) / d.max_jerk);
    }
  return p;
}

/// Largest joint speed |q_i - q_{i-1}| / dt over the joints.
double speed_at(const std::vector<kin::JointVector>& q, std::size_t i, double dt) {
  return (q[i] - q[i - 1]).cwiseAbs().maxCoeff() / dt;
}

const kin::JointVector kA = deg6({30, -20, 40, 0, 20, 0});
const kin::JointVector kB = deg6({70, -30, 60, 20, 30, 30});
const kin::JointVector kC = deg6({100, -10, 90, 30, 20, 40});
constexpr double kTolDeg = 20.0;

struct RunResult {
  std::vector<kin::JointVector> q;
  double corner[2] = {0, 0};        ///< closest approach to A, B (rad)
  std::size_t at[2] = {0, 0};       ///< sample index of it
  double min_speed = 0;             ///< smallest joint speed from 50 cycles before the first corner to 50 after the second
  std::size_t first_move = 0, last_move = 0;
  std::uint64_t blended = 0;
  Peaks p;
  std::size_t allocs = 0;
};

RunResult run_sequence(double blend_deg) {
  Rig r;
  r.enable();
  const std::uint64_t b0 = r.tel().blended_corners;
  r.recording = true;
  r.q.push_back(r.q_cmd());
  CHECK(is_ok(r.cmd(movej(kA, blend_deg))));
  CHECK(is_ok(r.cmd(movej(kB, blend_deg))));
  CHECK(is_ok(r.cmd(movej(kC, 0))));
  for (int i = 0; i < 20000 && !(r.tel().state == ArmState::idle && r.app.ctl->motions().empty()); ++i) r.step();
  for (int i = 0; i < 10; ++i) r.step();
  CHECK(r.tel().state == ArmState::idle);
  RunResult res;
  res.q = r.q;
  res.blended = r.tel().blended_corners - b0;
  const double dt = r.dt();
  CHECK((r.q_cmd() - kC).norm() < 1e-12);
  const kin::JointVector* corners[2] = {&kA, &kB};
  for (int k = 0; k < 2; ++k) {
    res.corner[k] = INFINITY;
    for (std::size_t i = 0; i < r.q.size(); ++i) {
      const double d = (r.q[i] - *corners[k]).norm();
      if (d < res.corner[k]) {
        res.corner[k] = d;
        res.at[k] = i;
      }
    }
  }
  std::size_t first = 0, last = 0;
  for (std::size_t i = 1; i < r.q.size(); ++i)
    if (speed_at(r.q, i, dt) > 0) {
      if (first == 0) first = i;
      last = i;
    }
  res.first_move = first;
  res.last_move = last;
  res.min_speed = INFINITY;
  for (std::size_t i = res.at[0] - 50; i <= res.at[1] + 50; ++i) res.min_speed = std::fmin(res.min_speed, speed_at(r.q, i, dt));
  res.p = peaks(r.q, r.app.ctl->limits(), dt);
  res.allocs = r.rt_allocs;
  return res;
}

}  // namespace

TEST_GROUP(FwBlend){};

TEST(FwBlend, ThreePointMovejBlendsItsCornersWithinTheToleranceAndTheLimits) {
  const RunResult b = run_sequence(kTolDeg);
  const RunResult x = run_sequence(0);
  const double dt = 1e-3;
  std::printf("\nfw blend 3-point movej: exact %.3f s, blend=%g deg %.3f s; corners %.3f %.3f deg; min speed %.4f rad/s; "
              "peaks v %.6f a %.6f j %.6f (exact: %.6f %.6f %.6f)\n",
              double(x.last_move - x.first_move) * dt, kTolDeg, double(b.last_move - b.first_move) * dt, b.corner[0] / kDeg,
              b.corner[1] / kDeg, b.min_speed, b.p.v, b.p.a, b.p.j, x.p.v, x.p.a, x.p.j);
  // blended: each intermediate corner passed within the tolerance, never at rest on the way
  for (int k = 0; k < 2; ++k) {
    CHECK(b.corner[k] <= kTolDeg * kDeg + 1e-9);
    CHECK(b.corner[k] > 1e-3);  // not through the corner: it was rounded
    CHECK(speed_at(b.q, b.at[k], dt) > 0.05);
  }
  CHECK(b.min_speed > 0.05);  // rad/s: the arm never comes to rest between the corners
  LONGS_EQUAL(2, b.blended);
  CHECK(b.p.v <= 1.0 + 1e-6);
  CHECK(b.p.a <= 1.0 + 1e-6);
  CHECK(b.p.j <= 1.0 + 1e-6);
  CHECK(b.last_move - b.first_move < x.last_move - x.first_move);
  LONGS_EQUAL(0, b.allocs);
  // without blend: through each corner, at rest there
  for (int k = 0; k < 2; ++k) CHECK(x.corner[k] < 1e-9);
  for (int k = 0; k < 2; ++k) CHECK(speed_at(x.q, x.at[k], dt) < 1e-3);
  CHECK(x.min_speed < 1e-3);
  LONGS_EQUAL(0, x.blended);
  CHECK(x.p.v <= 1.0 + 1e-6);
  CHECK(x.p.a <= 1.0 + 1e-6);
  CHECK(x.p.j <= 1.0 + 1e-6);
  LONGS_EQUAL(0, x.allocs);
}

namespace {
/// The usual bound on a stop: the longest jerk-limited ramp to rest of any joint from its
/// velocity limit with its acceleration limit in the wrong direction, plus two cycles.
double stop_bound(const kin::JointLimits& lim, double dt) {
  double t = 0;
  for (int j = 0; j < lim.n; ++j) {
    const auto& d = lim.dyn[static_cast<std::size_t>(j)];
    t = std::fmax(t, d.max_velocity / d.max_acceleration + 3 * d.max_acceleration / d.max_jerk);
  }
  return t + 2 * dt;
}
}  // namespace

TEST(FwBlend, StopOrHoldInTheMiddleOfABlend) {
  const RunResult ref = run_sequence(kTolDeg);
  for (const char* how : {"stop", "hold"}) {
    Rig r;
    r.enable();
    r.recording = true;
    r.q.push_back(r.q_cmd());
    CHECK(is_ok(r.cmd(movej(kA, kTolDeg))));
    CHECK(is_ok(r.cmd(movej(kB, kTolDeg))));
    CHECK(is_ok(r.cmd(movej(kC, 0))));
    while (r.q.size() < ref.at[0] + 1) r.step();  // at the closest approach to A: in the blend
    const std::size_t at = r.q.size() - 1;
    CHECK((r.q[at] - kA).norm() <= kTolDeg * kDeg);
    CHECK(speed_at(r.q, at, r.dt()) > 0.05);
    CHECK(is_ok(r.cmd(how)));
    const double bound = stop_bound(r.app.ctl->limits(), r.dt());
    std::size_t rest = 0;
    for (int i = 0; i < 5000 && rest == 0; ++i) {
      r.step();
      if (speed_at(r.q, r.q.size() - 1, r.dt()) == 0.0) rest = r.q.size() - 1;
    }
    CHECK(rest > 0);
    const double t_stop = double(rest - at) * r.dt();
    std::printf("\nfw blend: %s in the blend at A: at rest after %.3f s (bound %.3f s)\n", how, t_stop, bound);
    CHECK(t_stop <= bound);
    const Peaks p = peaks(r.q, r.app.ctl->limits(), r.dt());
    CHECK(p.v <= 1.0 + 1e-6);
    CHECK(p.a <= 1.0 + 1e-6);
    CHECK(p.j <= 1.0 + 1e-6);
    if (std::string(how) == "stop") {
      r.q.clear();
      for (int i = 0; i < 100; ++i) r.step();
      CHECK(r.tel().state == ArmState::idle);
      CHECK(r.app.ctl->motions().empty());
    } else {
      CHECK(r.tel().holding);
      CHECK(is_ok(r.cmd("resume")));
      for (int i = 0; i < 20000 && !(r.tel().state == ArmState::idle && r.app.ctl->motions().empty()); ++i) r.step();
      CHECK(r.tel().state == ArmState::idle);
      CHECK((r.q_cmd() - kC).norm() < 1e-12);  // the rest of the sequence ran to its end
      const Peaks p2 = peaks(r.q, r.app.ctl->limits(), r.dt());
      CHECK(p2.v <= 1.0 + 1e-6);
      CHECK(p2.a <= 1.0 + 1e-6);
    }
    LONGS_EQUAL(0, r.rt_allocs);
  }
}

// ---------------------------------------------------------------------------
// Line-to-line and mixed blends (PathMove: planned and blended by the console, run in
// place by the controller; docs/motion.md#blending)
// ---------------------------------------------------------------------------

namespace {

const kin::JointVector kS = deg6({0, -30, 60, 0, 40, 0});  // a pose well inside the workspace

kin::Pose flange(const Rig& r, const kin::JointVector& q) {
  kin::Pose x;
  CHECK(kin::forward(r.app.ctl->chain(), q, x) == kin::Status::ok);
  return x;
}

/// movel to p (m, base frame) keeping the orientation, speed mm/s, blend mm (< 0: none given).
std::string movel(const Eigen::Vector3d& p, double speed, double blend_mm) {
  char b[160];
  std::snprintf(b, sizeof b, "movel %.9g %.9g %.9g speed=%g", p.x() * 1e3, p.y() * 1e3, p.z() * 1e3, speed);
  std::string t = b;
  if (blend_mm >= 0) {
    std::snprintf(b, sizeof b, " blend=%g", blend_mm);
    t += b;
  }
  return t;
}

struct PathRun {
  std::vector<kin::JointVector> q;
  std::vector<Eigen::Vector3d> x;   ///< flange point of every sample
  std::size_t first_move = 0, last_move = 0;
  std::uint64_t blended = 0;
  Peaks p;
  double tool_speed = 0;            ///< largest |dx|/dt (m/s)
  std::size_t allocs = 0;
  double duration() const { return double(last_move - first_move) * 1e-3; }
  /// Closest approach of the flange point to c (m) and its sample.
  double closest(const Eigen::Vector3d& c, std::size_t* at = nullptr) const {
    double d = INFINITY;
    for (std::size_t i = 0; i < x.size(); ++i)
      if ((x[i] - c).norm() < d) {
        d = (x[i] - c).norm();
        if (at) *at = i;
      }
    return d;
  }
};

/// From rest at kS: the lines (and joint moves) of `moves`, run to the end.
PathRun run_path(Rig& r, const std::vector<std::string>& moves) {
  r.enable();
  CHECK(is_ok(r.cmd(movej(kS, 0))));
  for (int i = 0; i < 20000 && !(r.tel().state == ArmState::idle && r.app.ctl->motions().empty()); ++i) r.step();
  const std::uint64_t b0 = r.tel().blended_corners;
  r.rt_allocs = 0;
  r.q.clear();
  r.recording = true;
  r.q.push_back(r.q_cmd());
  for (const std::string& m : moves) {
    const std::string a = r.cmd(m);
    if (!is_ok(a)) FAIL((m + ": " + a).c_str());
  }
  for (int i = 0; i < 60000 && !(r.tel().state == ArmState::idle && r.app.ctl->motions().empty()); ++i) r.step();
  for (int i = 0; i < 10; ++i) r.step();
  CHECK(r.tel().state == ArmState::idle);
  PathRun res;
  res.q = r.q;
  res.blended = r.tel().blended_corners - b0;
  for (const auto& q : r.q) res.x.push_back(flange(r, q).translation());
  const double dt = r.dt();
  for (std::size_t i = 1; i < r.q.size(); ++i) {
    if (speed_at(r.q, i, dt) > 0) {
      if (res.first_move == 0) res.first_move = i;
      res.last_move = i;
    }
    res.tool_speed = std::fmax(res.tool_speed, (res.x[i] - res.x[i - 1]).norm() / dt);
  }
  res.p = peaks(r.q, r.app.ctl->limits(), dt);
  res.allocs = r.rt_allocs;
  return res;
}

double min_speed_between(const PathRun& p, std::size_t a, std::size_t b) {
  double m = INFINITY;
  for (std::size_t i = a; i <= b && i < p.q.size(); ++i) m = std::fmin(m, speed_at(p.q, i, 1e-3));
  return m;
}

}  // namespace

TEST_GROUP(FwPathBlend){};

TEST(FwPathBlend, ThreeLinesBlendTheirCornersWithinTheToleranceTheToolSpeedAndTheLimits) {
  Rig r0;
  const Eigen::Vector3d p0 = flange(r0, kS).translation();
  const Eigen::Vector3d A = p0 + Eigen::Vector3d(-0.10, 0, 0), B = A + Eigen::Vector3d(0, 0.10, 0),
                        C = B + Eigen::Vector3d(0, 0, -0.10);
  constexpr double kTolMm = 10, kSpeed = 100;  // mm, mm/s
  Rig rb, rx;
  const PathRun b = run_path(rb, {movel(A, kSpeed, kTolMm), movel(B, kSpeed, kTolMm), movel(C, kSpeed, -1)});
  const PathRun x = run_path(rx, {movel(A, kSpeed, -1), movel(B, kSpeed, -1), movel(C, kSpeed, -1)});
  std::size_t at_a = 0, at_b = 0;
  const double ca = b.closest(A, &at_a), cb = b.closest(B, &at_b);
  std::printf("\nfw path blend 3 lines: exact %.3f s, blend=%g mm %.3f s; corners %.2f %.2f mm; tool speed %.1f mm/s; "
              "peaks v %.4f a %.4f j %.4f\n",
              x.duration(), kTolMm, b.duration(), ca * 1e3, cb * 1e3, b.tool_speed * 1e3, b.p.v, b.p.a, b.p.j);
  CHECK(ca <= kTolMm * 1e-3 + 1e-9);
  CHECK(cb <= kTolMm * 1e-3 + 1e-9);
  CHECK(ca > 1e-4);  // rounded, not through the corner
  CHECK(cb > 1e-4);
  CHECK(min_speed_between(b, at_a - 20, at_b + 20) > 0.01);  // never at rest between the corners
  LONGS_EQUAL(2, b.blended);
  CHECK(b.duration() < x.duration());
  CHECK(b.tool_speed <= kSpeed * 1e-3 * 1.02);  // within the lines' speed (finite differences: 2 %)
  CHECK(b.p.v <= 1.0 + 1e-6);
  CHECK(b.p.a <= 1.0 + 1e-6);
  CHECK(b.p.j <= 1.0 + 1e-6);
  LONGS_EQUAL(0, b.allocs);
  CHECK((b.x.back() - C).norm() < 1e-6);
  // exact stops: through each corner
  CHECK(x.closest(A) < 1e-6);
  CHECK(x.closest(B) < 1e-6);
  LONGS_EQUAL(0, x.blended);
}

// line -> joint -> line: both corners mixed. (A typed movej with blend= followed by a movel
// blends in the controller's joint queue, which stops at a line; a program's movej before a
// line goes as a path segment: FwPathBlend.ProgramMovejBeforeALineBlends.)
TEST(FwPathBlend, MixedJointAndLineCornersBlend) {
  Rig r0;
  const kin::JointVector kJ = deg6({25, -35, 70, 10, 35, 10});  // a joint target near kS
  const Eigen::Vector3d p0 = flange(r0, kS).translation(), pJ = flange(r0, kJ).translation();
  const Eigen::Vector3d L0 = p0 + Eigen::Vector3d(0, 0, -0.08), L = pJ + Eigen::Vector3d(0, 0, -0.12);
  Rig rb, rx;
  const PathRun b = run_path(rb, {movel(L0, 150, 25), movej(kJ, 20), movel(L, 150, -1)});
  const PathRun x = run_path(rx, {movel(L0, 150, -1), movej(kJ, 0), movel(L, 150, -1)});
  std::size_t at_j = 0, at_l = 0;
  double cj = INFINITY;
  for (std::size_t i = 0; i < b.q.size(); ++i)
    if ((b.q[i] - kJ).norm() < cj) cj = (b.q[i] - kJ).norm(), at_j = i;
  const double cl = b.closest(L0, &at_l);
  std::printf("\nfw path blend line->joint->line: exact %.3f s, blended %.3f s; corners %.2f mm, %.3f deg; peaks v %.4f a %.4f j %.4f\n",
              x.duration(), b.duration(), cl * 1e3, cj / kDeg, b.p.v, b.p.a, b.p.j);
  CHECK(cl <= 25e-3 + 1e-9);      // line corner: tool point
  CHECK(cj <= 20 * kDeg + 1e-9);  // joint corner: joint-space distance
  CHECK(cj > 1e-4);
  CHECK(cl > 1e-4);
  LONGS_EQUAL(2, b.blended);
  CHECK(min_speed_between(b, at_l - 10, at_j + 10) > 0.01);
  CHECK(b.duration() < x.duration());
  CHECK(b.p.v <= 1.0 + 1e-6);
  CHECK(b.p.a <= 1.0 + 1e-6);
  CHECK(b.p.j <= 1.0 + 1e-6);
  LONGS_EQUAL(0, b.allocs);
  CHECK((b.x.back() - L).norm() < 1e-6);
}

// LinuxCNC #3773: blended corners of a tight zigzag at high feed overshot the acceleration
// limit up to 8x. Here: 12 lines of 8 mm alternating at 250 mm/s, blend=3 mm: every sampled
// joint velocity, acceleration and jerk within its limit, every corner within 3 mm.
TEST(FwPathBlend, TightZigzagAtHighFeedStaysWithinEveryLimit) {
  Rig r0;
  const Eigen::Vector3d p0 = flange(r0, kS).translation();
  std::vector<std::string> moves;
  std::vector<Eigen::Vector3d> corners;
  Eigen::Vector3d p = p0;
  for (int k = 0; k < 12; ++k) {
    p += Eigen::Vector3d(-0.008, (k % 2 == 0 ? 1 : -1) * 0.008, 0);
    corners.push_back(p);
    moves.push_back(movel(p, 250, k == 11 ? -1 : 3));
  }
  Rig r;
  const PathRun b = run_path(r, moves);
  double worst = 0;
  for (std::size_t k = 0; k + 1 < corners.size(); ++k) worst = std::fmax(worst, b.closest(corners[k]));
  std::printf("\nfw path blend zigzag 12 x 8 mm at 250 mm/s blend=3 mm: %.3f s, %llu corners blended, worst corner %.2f mm, "
              "tool speed %.1f mm/s, peaks v %.4f a %.4f j %.4f\n",
              b.duration(), static_cast<unsigned long long>(b.blended), worst * 1e3, b.tool_speed * 1e3, b.p.v, b.p.a, b.p.j);
  CHECK(worst <= 3e-3 + 1e-9);
  CHECK(b.blended >= 6);
  CHECK(b.p.v <= 1.0 + 1e-6);
  CHECK(b.p.a <= 1.0 + 1e-6);
  CHECK(b.p.j <= 1.0 + 1e-6);
  CHECK(b.tool_speed <= 0.250 * 1.02);
  CHECK((b.x.back() - corners.back()).norm() < 1e-6);
  LONGS_EQUAL(0, b.allocs);
}

// A line typed after the run has passed the time it would have had to start at: the
// corner is an exact stop (nothing already commanded changes), never a jump.
TEST(FwPathBlend, AMoveQueuedTooLateForItsBlendStopsAtTheCorner) {
  Rig r0;
  const Eigen::Vector3d p0 = flange(r0, kS).translation();
  const Eigen::Vector3d A = p0 + Eigen::Vector3d(-0.05, 0, 0), B = A + Eigen::Vector3d(0, 0.05, 0);
  Rig r;
  r.enable();
  CHECK(is_ok(r.cmd(movej(kS, 0))));
  for (int i = 0; i < 20000 && !(r.tel().state == ArmState::idle && r.app.ctl->motions().empty()); ++i) r.step();
  r.recording = true;
  r.q.push_back(r.q_cmd());
  CHECK(is_ok(r.cmd(movel(A, 100, 10))));
  // run until 20 ms before A's end: its blend would have begun long ago
  for (int i = 0; i < 20000; ++i) {
    r.step();
    const kin::Pose xa = flange(r, r.q_cmd());
    if ((xa.translation() - A).norm() < 1e-3) break;
  }
  const std::uint64_t b0 = r.tel().blended_corners;
  CHECK(is_ok(r.cmd(movel(B, 100, -1))));
  for (int i = 0; i < 20000 && !(r.tel().state == ArmState::idle && r.app.ctl->motions().empty()); ++i) r.step();
  CHECK(r.tel().state == ArmState::idle);
  LONGS_EQUAL(0, r.tel().blended_corners - b0);
  PathRun res;
  for (const auto& q : r.q) res.x.push_back(flange(r, q).translation());
  std::size_t at = 0;
  CHECK(res.closest(A, &at) < 1e-6);  // through A, at rest there
  CHECK(speed_at(r.q, at, r.dt()) < 1e-3);
  const Peaks p = peaks(r.q, r.app.ctl->limits(), r.dt());
  CHECK(p.v <= 1.0 + 1e-6);
  CHECK(p.a <= 1.0 + 1e-6);
  CHECK(p.j <= 1.0 + 1e-6);
  CHECK((res.x.back() - B).norm() < 1e-6);
}

// A feed hold while a line of a blended run moves alone stops on its line (as a plain
// movel); held in an overlap it ramps down and resume goes back to the corner it rounded,
// then on. A stop in the blend leaves nothing queued. Every limit kept throughout.
TEST(FwPathBlend, HoldAndStopInABlendedRun) {
  Rig r0;
  const Eigen::Vector3d p0 = flange(r0, kS).translation();
  const Eigen::Vector3d A = p0 + Eigen::Vector3d(-0.10, 0, 0), B = A + Eigen::Vector3d(0, 0.10, 0),
                        C = B + Eigen::Vector3d(0, 0, -0.08);
  Rig rr;
  const PathRun ref = run_path(rr, {movel(A, 100, 10), movel(B, 100, 10), movel(C, 100, -1)});
  std::size_t at_a = 0;
  ref.closest(A, &at_a);
  struct Case {
    const char* how;
    std::size_t at;   ///< sample of the request
    bool on_line;     ///< the hold comes while one line moves alone
  };
  for (const Case& c : {Case{"hold", at_a / 2, true}, Case{"hold", at_a, false}, Case{"stop", at_a, false}}) {
    Rig r;
    r.enable();
    CHECK(is_ok(r.cmd(movej(kS, 0))));
    for (int i = 0; i < 20000 && !(r.tel().state == ArmState::idle && r.app.ctl->motions().empty()); ++i) r.step();
    r.recording = true;
    r.q.clear();
    r.q.push_back(r.q_cmd());
    CHECK(is_ok(r.cmd(movel(A, 100, 10))));
    CHECK(is_ok(r.cmd(movel(B, 100, 10))));
    CHECK(is_ok(r.cmd(movel(C, 100, -1))));
    while (r.q.size() < c.at + 1) r.step();
    CHECK(is_ok(r.cmd(c.how)));
    for (int i = 0; i < 5000 && speed_at(r.q, r.q.size() - 1, r.dt()) != 0.0; ++i) r.step();
    const std::size_t rest = r.q.size() - 1;
    if (c.on_line) {  // stopped on the line p0 -> A
      const Eigen::Vector3d x = flange(r, r.q.back()).translation();
      const Eigen::Vector3d d = (A - p0).normalized();
      CHECK(((x - p0) - d * d.dot(x - p0)).norm() < 1e-6);
    }
    if (std::string(c.how) == "stop") {
      for (int i = 0; i < 100; ++i) r.step();
      CHECK(r.tel().state == ArmState::idle);
      CHECK(r.app.ctl->motions().empty());
    } else {
      CHECK(r.tel().holding);
      CHECK(is_ok(r.cmd("resume")));
      for (int i = 0; i < 30000 && !(r.tel().state == ArmState::idle && r.app.ctl->motions().empty()); ++i) r.step();
      CHECK(r.tel().state == ArmState::idle);
      CHECK((flange(r, r.q_cmd()).translation() - C).norm() < 1e-6);  // the rest of the run went to its end
    }
    const Peaks p = peaks(r.q, r.app.ctl->limits(), r.dt());
    std::printf("\nfw path blend: %s at sample %zu (%s): at rest after %.3f s; peaks v %.4f a %.4f j %.4f\n", c.how, c.at,
                c.on_line ? "a line alone" : "in an overlap", double(rest - c.at) * r.dt(), p.v, p.a, p.j);
    CHECK(p.v <= 1.0 + 1e-6);
    CHECK(p.a <= 1.0 + 1e-6);
    CHECK(p.j <= 1.0 + 1e-6);
    LONGS_EQUAL(0, r.rt_allocs);
  }
}

// motion.default_blend_mm / _deg: the tolerance of moves that give none; blend=0 still stops.
TEST(FwPathBlend, TheConfiguredDefaultBlendsMovesWithoutBlend) {
  Rig r0;
  const Eigen::Vector3d p0 = flange(r0, kS).translation();
  const Eigen::Vector3d A = p0 + Eigen::Vector3d(-0.10, 0, 0), B = A + Eigen::Vector3d(0, 0.10, 0),
                        C = B + Eigen::Vector3d(0, 0, -0.10);
  FwConfig cfg;
  cfg.default_blend_mm = 10;
  cfg.default_blend_deg = 20;
  Rig rd(cfg), rz(cfg);
  const PathRun d = run_path(rd, {movel(A, 100, -1), movel(B, 100, -1), movel(C, 100, -1), movej(kS, -1)});
  const PathRun z = run_path(rz, {movel(A, 100, 0), movel(B, 100, 0), movel(C, 100, 0), movej(kS, -1)});
  std::printf("\nfw path blend default 10 mm / 20 deg: %.3f s (%llu corners); blend=0 given: %.3f s (%llu)\n", d.duration(),
              static_cast<unsigned long long>(d.blended), z.duration(), static_cast<unsigned long long>(z.blended));
  LONGS_EQUAL(3, d.blended);
  CHECK(d.closest(A) <= 10e-3 + 1e-9);
  CHECK(d.closest(A) > 1e-4);
  LONGS_EQUAL(0, z.blended);
  CHECK(z.closest(A) < 1e-6);
  CHECK(d.duration() < z.duration());
  CHECK(d.p.v <= 1.0 + 1e-6);
  CHECK(d.p.a <= 1.0 + 1e-6);
  CHECK(d.p.j <= 1.0 + 1e-6);
}
