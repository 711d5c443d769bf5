// Blended joint moves through the firmware (issue 18): console + controller in-process,
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

  Rig() {
    FwConfig cfg;
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
