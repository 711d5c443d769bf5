// SPDX-License-Identifier: Apache-2.0
// Joint moves: jerk-limited, time-synchronised profiles, replanning, stop, override.
// Every trajectory is sampled at 1 kHz and checked against the limits,
// continuity, endpoints and synchronisation (check_trajectory below).
#include <cmath>
#include <cstdio>
#include <random>
#include <string>

#include "alloc_counter.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/kinematics/trajectory.hpp"
#include "sweep.hpp"  // sweep(): fewer cases under qemu and the sanitizers

// CppUTest last: its leak detector redefines new.
#include <CppUTest/TestHarness.h>

using namespace servoarm::kin;

namespace {

constexpr double kDt = 1e-3;  // 1 kHz control period

// Random-sweep sizes. The host runs the full counts written at each sweep. A cross
// build under qemu-user and the sanitizer/valgrind builds run this suite some 10-40x
// slower (tests/support/sweep.hpp): the same sweeps, same seeds, with the first
// 1/20 of the cases (500 instead of 10 000), so it finishes in CI time.
using servoarm::test::sweep;  // sweep.hpp: 1/20 of the cases under qemu and the sanitizers

struct Rng {
  std::mt19937_64 g;
  explicit Rng(unsigned long long seed) : g(seed) {}
  double uni(double a, double b) { return std::uniform_real_distribution<double>(a, b)(g); }
  double logu(double a, double b) { return std::exp(uni(std::log(a), std::log(b))); }
  int integer(int a, int b) { return std::uniform_int_distribution<int>(a, b)(g); }
};

JointLimits random_limits(Rng& r, int n, double pos_limit) {
  JointLimits l;
  l.n = n;
  for (int i = 0; i < n; ++i) {
    const auto k = static_cast<std::size_t>(i);
    l.dyn[k].max_velocity = r.logu(0.3, 4.0);
    l.dyn[k].max_acceleration = r.logu(1.0, 40.0);
    l.dyn[k].max_jerk = r.logu(5.0, 2000.0);
    l.lower[k] = -pos_limit;
    l.upper[k] = pos_limit;
  }
  return l;
}

JointVector random_q(Rng& r, int n, double range) {
  JointVector q(n);
  for (int i = 0; i < n; ++i) q[i] = r.uni(-range, range);
  return q;
}

std::string fmt(const char* f, double a = 0, double b = 0, double c = 0, double d = 0) {
  char buf[256];
  std::snprintf(buf, sizeof buf, f, a, b, c, d);
  return buf;
}

// Checks one trajectory. Limits: `full` during the recovery prefix, `scale`d
// (override) limits after it. Returns "" if fine, else what failed.
std::string check_trajectory(const JointTrajectory& tr, const JointLimits& lim, const JointState& start,
                             double scale, bool synchronised) {
  const int n = tr.n;
  const double tol = 1e-9;
  // Start state exact.
  JointState s0;
  tr.sample(0.0, s0);
  for (int i = 0; i < n; ++i) {
    if (std::fabs(s0.pos[i] - start.pos[i]) > 1e-12 || std::fabs(s0.vel[i] - start.vel[i]) > 1e-12 ||
        std::fabs(s0.acc[i] - start.acc[i]) > 1e-12)
      return fmt("joint %g: start state differs", i);
  }
  // Segment boundaries: position, velocity, acceleration continuous; final hold at the goal.
  for (int i = 0; i < n; ++i) {
    const JointProfile& p = tr.joint[static_cast<std::size_t>(i)];
    if (p.n < 1) return fmt("joint %g: no segments", i);
    for (int k = 1; k < p.n; ++k) {
      const JerkSegment& a = p.seg[static_cast<std::size_t>(k - 1)];
      const JerkSegment& b = p.seg[static_cast<std::size_t>(k)];
      const double dt = b.t0 - a.t0;
      if (dt < 0) return fmt("joint %g: segment %g starts before its predecessor", i, k);
      const double pe = a.p + a.v * dt + a.a * dt * dt / 2 + a.j * dt * dt * dt / 6;
      const double ve = a.v + a.a * dt + a.j * dt * dt / 2;
      const double ae = a.a + a.j * dt;
      const double sc = 1 + std::fabs(pe);
      if (std::fabs(pe - b.p) > 1e-9 * sc || std::fabs(ve - b.v) > 1e-9 * (1 + std::fabs(ve)) ||
          std::fabs(ae - b.a) > 1e-9 * (1 + std::fabs(ae)))
        return fmt("joint %g: discontinuity at segment %g (dp %.3g dv %.3g)", i, k, pe - b.p, ve - b.v);
    }
    const JerkSegment& h = p.seg[static_cast<std::size_t>(p.n - 1)];
    if (h.v != 0 || h.a != 0 || h.j != 0 || h.p != tr.goal[i]) return fmt("joint %g: final hold not at goal", i);
    if (h.t0 > tr.duration + tol) return fmt("joint %g: arrives after the duration (%g > %g)", i, h.t0, tr.duration);
    if (synchronised && h.t0 < tr.duration - 1e-9) {
      // Only a joint that simply stops where it is (no distance to cover) may arrive early.
      const JerkSegment& f = p.seg[0];
      const bool trivial = std::fabs(f.v) < 1e-15 && std::fabs(f.a) < 1e-15 && std::fabs(f.p - tr.goal[i]) < 1e-12;
      if (!trivial && tr.recovery == 0) return fmt("joint %g: arrives early (%g < %g)", i, h.t0, tr.duration);
    }
  }
  // 1 kHz samples: limits, jerk-bounded changes, exact end.
  JointState prev = s0, cur;
  const int steps = static_cast<int>(std::ceil(tr.duration / kDt)) + 2;
  for (int k = 1; k <= steps; ++k) {
    const double t = k * kDt;
    tr.sample(t, cur);
    const bool in_recovery = t < tr.recovery;
    for (int i = 0; i < n; ++i) {
      const JointDynamics& d = lim.dyn[static_cast<std::size_t>(i)];
      const double sv = in_recovery ? 1.0 : scale;
      // A state that started outside the limits may stay above the scaled velocity
      // limit while it is brought back (still inside the full limits).
      const double V = (in_recovery ? std::max(d.max_velocity, std::fabs(start.vel[i])) : d.max_velocity * sv);
      const double A = in_recovery ? std::max(d.max_acceleration, std::fabs(start.acc[i])) : d.max_acceleration * sv * sv;
      const double J = d.max_jerk * (in_recovery ? 1.0 : sv * sv * sv);
      const double Jmax = d.max_jerk;  // across the recovery boundary
      if (!std::isfinite(cur.pos[i]) || !std::isfinite(cur.vel[i]) || !std::isfinite(cur.acc[i]))
        return fmt("joint %g: not finite at t=%g", i, t);
      if (std::fabs(cur.vel[i]) > V * (1 + tol) + tol) return fmt("joint %g: |v| %g > %g at t=%g", i, cur.vel[i], V, t);
      if (std::fabs(cur.acc[i]) > A * (1 + tol) + tol) return fmt("joint %g: |a| %g > %g at t=%g", i, cur.acc[i], A, t);
      const double jl = (tr.recovery > 0 ? Jmax : J) * kDt * (1 + 1e-6) + 1e-9;
      if (std::fabs(cur.acc[i] - prev.acc[i]) > jl) return fmt("joint %g: acceleration jump %g at t=%g", i, cur.acc[i] - prev.acc[i], t);
      const double amax = std::max(std::fabs(cur.acc[i]), std::fabs(prev.acc[i])) + jl;
      if (std::fabs(cur.vel[i] - prev.vel[i]) > amax * kDt * (1 + 1e-6) + 1e-9)
        return fmt("joint %g: velocity jump at t=%g", i, t);
      const double vmax = std::max(std::fabs(cur.vel[i]), std::fabs(prev.vel[i])) + amax * kDt;
      if (std::fabs(cur.pos[i] - prev.pos[i]) > vmax * kDt * (1 + 1e-6) + 1e-9)
        return fmt("joint %g: position jump at t=%g", i, t);
    }
    prev = cur;
  }
  tr.sample(tr.duration, cur);
  for (int i = 0; i < n; ++i) {
    if (cur.pos[i] != tr.goal[i] || cur.vel[i] != 0 || cur.acc[i] != 0) return fmt("joint %g: end state not exact", i);
    double p, v, a;  // just before the end: already (almost) there
    eval_profile(tr.joint[static_cast<std::size_t>(i)], tr.duration - 1e-12, p, v, a);
    if (std::fabs(p - tr.goal[i]) > 1e-9 || std::fabs(v) > 1e-6 || std::fabs(a) > 1e-3)
      return fmt("joint %g: profile does not reach the goal (dp %.3g, v %.3g)", i, p - tr.goal[i], v);
  }
  return "";
}

#define CHECK_TRAJ(tr, lim, start, scale, sync, ctx)                                                   \
  do {                                                                                                 \
    const std::string e_ = check_trajectory(tr, lim, start, scale, sync);                              \
    if (!e_.empty()) FAIL((std::string(ctx) + ": " + e_).c_str());                                     \
  } while (0)

}  // namespace

TEST_GROUP(Movej){};

// Closed forms for rest-to-rest single-joint moves.
TEST(Movej, ClosedFormDurations) {
  struct Case {
    double D, V, A, J, T;
    const char* what;
  } cases[] = {
      {10, 1, 1, 1, 10.0 / 1 + 1.0 / 1 + 1.0 / 1, "full 7 phases: D/V + V/A + A/J"},
      {20, 2, 4, 16, 20.0 / 2 + 2.0 / 4 + 4.0 / 16, "full 7 phases, other limits"},
      {-20, 2, 4, 16, 20.0 / 2 + 2.0 / 4 + 4.0 / 16, "negative direction"},
      // V reached without hitting A (V < A^2/J): T = D/V + 2 sqrt(V/J)
      {10, 1, 10, 1, 10.0 + 2.0, "no constant-acceleration phase"},
      // Short move, neither V nor A reached: T = 4 (D / (2J))^(1/3)
      {0.002, 10, 10, 1, 4 * std::cbrt(0.002 / 2), "jerk only"},
      {0, 1, 1, 1, 0, "zero move"},
  };
  for (const Case& c : cases) {
    JointLimits l;
    l.n = 1;
    l.dyn[0] = {c.V, c.A, c.J};
    l.lower[0] = -100;
    l.upper[0] = 100;
    JointVector q0 = JointVector::Zero(1), q1(1);
    q1[0] = c.D;
    JointTrajectory tr;
    const MotionStatus st = plan_movej(l, JointState::rest(q0), q1, {}, tr);
    CHECK_EQUAL_TEXT(static_cast<int>(MotionStatus::ok), static_cast<int>(st), c.what);
    DOUBLES_EQUAL_TEXT(c.T, tr.duration, 1e-9 * (1 + c.T), c.what);
    CHECK_TRAJ(tr, l, JointState::rest(q0), 1.0, true, c.what);
    const JointPeaks pk = peaks(tr, 0);
    CHECK_TEXT(pk.velocity <= c.V * (1 + 1e-12), c.what);
  }
}

TEST(Movej, RandomSynchronisedMovesFromRest) {
  Rng r(4001);
  for (int m = 0; m < sweep(10000); ++m) {
    const int n = r.integer(1, 8);
    const JointLimits l = random_limits(r, n, 3.2);
    const JointState s = JointState::rest(random_q(r, n, 3.0));
    JointVector goal = random_q(r, n, 3.0);
    if (r.integer(0, 9) == 0) goal[0] = s.pos[0];  // some joints do not move
    if (r.integer(0, 9) == 0) goal[n - 1] = s.pos[n - 1] + r.uni(-1e-6, 1e-6);  // tiny moves
    JointTrajectory tr;
    const MotionStatus st = plan_movej(l, s, goal, {}, tr);
    const std::string ctx = "move " + std::to_string(m);
    CHECK_EQUAL_TEXT(static_cast<int>(MotionStatus::ok), static_cast<int>(st), ctx.c_str());
    // The slowest joint's own minimum time is the duration.
    double tmin = 0;
    for (int i = 0; i < n; ++i) {
      const auto k = static_cast<std::size_t>(i);
      Limits1 L1{l.dyn[k].max_velocity, l.dyn[k].max_acceleration, l.dyn[k].max_jerk};
      tmin = std::max(tmin, achievable_duration_1d(s.pos[i], 0, 0, goal[i], L1, 0));
    }
    DOUBLES_EQUAL_TEXT(tmin, tr.duration, 1e-12 * (1 + tmin), ctx.c_str());
    CHECK_TRAJ(tr, l, s, 1.0, true, ctx);
  }
}

// A new command replaces a running move at any instant: the new plan starts
// from the sampled state (no jump), honours the limits and arrives in sync.
TEST(Movej, RandomReplanningMidMove) {
  Rng r(4002);
  int planned = 0;
  for (int m = 0; m < sweep(10000); ++m) {
    const int n = r.integer(1, 8);
    JointLimits l = random_limits(r, n, 1e9);  // overshoot limits tested separately
    const JointState s = JointState::rest(random_q(r, n, 3.0));
    JointTrajectory first;
    CHECK(plan_movej(l, s, random_q(r, n, 3.0), {}, first) == MotionStatus::ok);
    const double ts = r.uni(0.0, first.duration);
    JointState mid;
    first.sample(ts, mid);
    JointVector goal = random_q(r, n, 3.0);
    if (r.integer(0, 4) == 0) goal = mid.pos;  // "stay here"
    JointTrajectory second;
    const std::string ctx = "replan " + std::to_string(m);
    const MotionStatus st = plan_movej(l, mid, goal, {}, second);
    CHECK_EQUAL_TEXT(static_cast<int>(MotionStatus::ok), static_cast<int>(st), ctx.c_str());
    CHECK_EQUAL_TEXT(0.0, second.recovery, ctx.c_str());
    CHECK_TRAJ(second, l, mid, 1.0, true, ctx);
    ++planned;
  }
  CHECK_EQUAL(sweep(10000), planned);
}

TEST(Movej, RandomStopFromAnyState) {
  Rng r(4003);
  for (int m = 0; m < sweep(10000); ++m) {
    const int n = r.integer(1, 8);
    const JointLimits l = random_limits(r, n, 1e9);
    JointTrajectory first;
    CHECK(plan_movej(l, JointState::rest(random_q(r, n, 3.0)), random_q(r, n, 3.0), {}, first) == MotionStatus::ok);
    JointState mid;
    first.sample(r.uni(0.0, first.duration), mid);
    JointTrajectory stop;
    const std::string ctx = "stop " + std::to_string(m);
    CHECK_EQUAL_TEXT(static_cast<int>(MotionStatus::ok), static_cast<int>(plan_stop(l, mid, {}, stop)), ctx.c_str());
    CHECK_TRAJ(stop, l, mid, 1.0, false, ctx);
    // As fast as the limits allow: each joint stops no later than the
    // time-optimal deceleration bound |v|/A + A/J (at full peak) ... and the
    // stop takes no longer than moving-to-rest does.
    for (int i = 0; i < n; ++i) {
      const JointDynamics& d = l.dyn[static_cast<std::size_t>(i)];
      const double bound = std::fabs(mid.vel[i]) / d.max_acceleration + 2 * d.max_acceleration / d.max_jerk +
                           std::fabs(mid.acc[i]) / d.max_jerk;
      const JointProfile& p = stop.joint[static_cast<std::size_t>(i)];
      CHECK_TEXT(p.seg[static_cast<std::size_t>(p.n - 1)].t0 <= bound + 1e-9, ctx.c_str());
    }
    // Resume: from the stopped state to the interrupted goal.
    JointTrajectory resume;
    CHECK(plan_movej(l, JointState::rest(stop.goal), first.goal, {}, resume) == MotionStatus::ok);
    CHECK_TRAJ(resume, l, JointState::rest(stop.goal), 1.0, true, ctx + " resume");
  }
}

TEST(Movej, OverrideScalesTimeExactly) {
  Rng r(4004);
  for (int m = 0; m < sweep(1000); ++m) {
    const int n = r.integer(1, 8);
    const JointLimits l = random_limits(r, n, 3.2);
    const JointState s = JointState::rest(random_q(r, n, 3.0));
    const JointVector goal = random_q(r, n, 3.0);
    const double ov = r.uni(0.01, 1.0);
    JointTrajectory full, slow;
    CHECK(plan_movej(l, s, goal, {}, full) == MotionStatus::ok);
    CHECK(plan_movej(l, s, goal, MovejOptions{ov}, slow) == MotionStatus::ok);
    const std::string ctx = "override " + std::to_string(m);
    DOUBLES_EQUAL_TEXT(full.duration / ov, slow.duration, 1e-9 * slow.duration, ctx.c_str());
    for (int k = 0; k <= 20; ++k) {
      const double t = full.duration * k / 20.0;
      JointState a, b;
      full.sample(t, a);
      slow.sample(t / ov, b);
      for (int i = 0; i < n; ++i) {
        DOUBLES_EQUAL_TEXT(a.pos[i], b.pos[i], 1e-7, ctx.c_str());
        DOUBLES_EQUAL_TEXT(a.vel[i] * ov, b.vel[i], 1e-7, ctx.c_str());
        DOUBLES_EQUAL_TEXT(a.acc[i] * ov * ov, b.acc[i], 1e-6, ctx.c_str());
      }
    }
    CHECK_TRAJ(slow, l, s, ov, true, ctx);
  }
}

// Lowering the override during a move: the recovery prefix brings the state
// inside the new limits (with the full limits), then the move continues slower.
TEST(Movej, OverrideChangeMidMove) {
  Rng r(4005);
  int recovered = 0;
  for (int m = 0; m < sweep(10000); ++m) {
    const int n = r.integer(1, 8);
    const JointLimits l = random_limits(r, n, 1e9);
    const double ov0 = r.uni(0.01, 1.0), ov1 = r.uni(0.01, 1.0);
    JointTrajectory first;
    CHECK(plan_movej(l, JointState::rest(random_q(r, n, 3.0)), random_q(r, n, 3.0), MovejOptions{ov0}, first) ==
          MotionStatus::ok);
    JointState mid;
    first.sample(r.uni(0.0, first.duration), mid);
    JointTrajectory second;
    const std::string ctx = "override change " + std::to_string(m);
    CHECK_EQUAL_TEXT(static_cast<int>(MotionStatus::ok),
                     static_cast<int>(plan_movej(l, mid, first.goal, MovejOptions{ov1}, second)), ctx.c_str());
    if (second.recovery > 0) ++recovered;
    CHECK_TRAJ(second, l, mid, ov1, true, ctx);
  }
  CHECK(recovered > sweep(10000) / 10);
}

TEST(Movej, RefusesBadInputAndLeavesOutputUntouched) {
  JointLimits l;
  l.n = 2;
  l.dyn[0] = l.dyn[1] = {1, 2, 10};
  l.lower[0] = l.lower[1] = -1;
  l.upper[0] = l.upper[1] = 1;
  const JointState s = JointState::rest(JointVector::Zero(2));
  JointVector g(2);
  g << 0.5, -0.5;
  JointTrajectory tr;
  tr.duration = 42;
  struct Case {
    const char* what;
    MotionStatus expect;
  };
  auto run = [&](const JointLimits& lim, const JointState& st, const JointVector& goal, double ov) {
    return plan_movej(lim, st, goal, MovejOptions{ov}, tr);
  };
  JointVector nan_goal = g;
  nan_goal[1] = std::numeric_limits<double>::quiet_NaN();
  JointVector far_goal = g;
  far_goal[0] = 1.5;
  JointLimits bad = l;
  bad.dyn[1].max_jerk = 0;
  JointLimits inf = l;
  inf.dyn[0].max_velocity = std::numeric_limits<double>::infinity();
  JointState moving = s;
  moving.vel[0] = 1.0;  // 1 rad/s towards +1 with 2 rad/s^2: overshoots the limit at 1
  moving.pos[0] = 0.9;
  CHECK(run(l, s, JointVector::Zero(3), 1) == MotionStatus::wrong_size);
  CHECK(run(l, s, nan_goal, 1) == MotionStatus::bad_input);
  CHECK(run(l, s, g, 0.0) == MotionStatus::bad_input);
  CHECK(run(l, s, g, 1.5) == MotionStatus::bad_input);
  CHECK(run(bad, s, g, 1) == MotionStatus::bad_limits);
  CHECK(run(inf, s, g, 1) == MotionStatus::bad_limits);
  CHECK(run(l, s, far_goal, 1) == MotionStatus::goal_out_of_limits);
  CHECK(run(l, moving, g, 1) == MotionStatus::path_out_of_limits);
  DOUBLES_EQUAL(42, tr.duration, 0);
  STRCMP_EQUAL("path_out_of_limits", to_string(MotionStatus::path_out_of_limits));
  STRCMP_EQUAL("ok", to_string(MotionStatus::ok));
  // The stop from that state is never refused.
  CHECK(plan_stop(l, moving, {}, tr) == MotionStatus::ok);
  CHECK(tr.goal[0] > 1.0);
}

TEST(Movej, ZeroHeapInPlanAndSample) {
  Rng r(4006);
  const JointLimits l = random_limits(r, 6, 3.2);
  const JointState s = JointState::rest(random_q(r, 6, 3.0));
  const JointVector goal = random_q(r, 6, 3.0);
  JointTrajectory tr, stop, re;
  JointState st;
  servoarm::test::AllocScope scope;
  CHECK(plan_movej(l, s, goal, {}, tr) == MotionStatus::ok);
  for (int k = 0; k < 1000; ++k) tr.sample(k * tr.duration / 1000, st);
  CHECK(plan_stop(l, st, {}, stop) == MotionStatus::ok);
  tr.sample(tr.duration * 0.5, st);
  CHECK(plan_movej(l, st, s.pos, MovejOptions{0.2}, re) == MotionStatus::ok);
  CHECK_EQUAL(0u, scope.end());
}

// A joint already at its goal to within rounding (a residual of ~1e-17 rad and
// ~1e-16 rad/s, as a stream or jog leaves it) or whose goal is exactly its
// stopping point: its profile is "stop, then wait at the goal". When another
// joint sets a longer duration the wait stretches; the joint must stay at its
// goal for all of it, not drift away under the stop's last jerk segment.
namespace {

// Sampled at the loop rate and at the exact extrema: every position of joint i
// within [min(start, goal), max(start, goal)] +- tol. "" if fine.
std::string stays_between(const JointTrajectory& tr, int i, double start, double goal, double tol) {
  const double lo = std::min(start, goal) - tol, hi = std::max(start, goal) + tol;
  const JointPeaks pk = peaks(tr, i);
  if (pk.min_position < lo || pk.max_position > hi)
    return fmt("positions [%.3g, %.3g] leave [%.3g, %.3g]", pk.min_position - goal, pk.max_position - goal, lo - goal, hi - goal);
  const int steps = static_cast<int>(std::ceil(tr.duration / kDt)) + 1;
  for (int k = 0; k <= steps; ++k) {
    const double p = tr.position(i, k * kDt);
    if (!(p >= lo && p <= hi)) return fmt("joint %g: %.3g at t=%g outside the band", i, p, k * kDt);
  }
  if (tr.position(i, tr.duration) != goal) return fmt("joint %g: does not end at the goal", i);
  return "";
}

}  // namespace

TEST(Movej, NearRestJointStaysAtItsGoalWhileAnotherJointMoves) {
  struct Case {
    double d0;        // joint 0's distance to go
    double p1, v1;    // joint 1's offset from its goal (0) and velocity
    const char* what;
  } cases[] = {
      {0.001, 2.01e-17, 1.18e-16, "1 mrad, rounding residual"},
      {0.01, 2.01e-17, 1.18e-16, "10 mrad, rounding residual"},
      {0.05, 2.01e-17, 1.18e-16, "50 mrad, rounding residual"},
      {0.2, 2.01e-17, 1.18e-16, "200 mrad, rounding residual"},
      {0.2, -2.01e-17, 1.18e-16, "residual behind, moving towards"},
      {0.2, 2.01e-17, -1.18e-16, "residual ahead, moving away"},
      {0.2, -2.01e-17, -1.18e-16, "both negative"},
      {0.2, 0.0, 0.0, "exactly at rest"},
      {0.2, 1e-9, 1e-9, "nanoradian residual"},
  };
  JointLimits l;
  l.n = 2;
  for (int k = 0; k < 2; ++k) {
    l.dyn[static_cast<std::size_t>(k)] = {0.0958, 12.57, 200.0};
    l.lower[static_cast<std::size_t>(k)] = -3;
    l.upper[static_cast<std::size_t>(k)] = 3;
  }
  for (const Case& c : cases) {
    JointState s = JointState::rest(JointVector::Zero(2));
    s.pos[1] = c.p1;
    s.vel[1] = c.v1;
    JointVector goal = JointVector::Zero(2);
    goal[0] = c.d0;
    JointTrajectory tr;
    const MotionStatus st = plan_movej(l, s, goal, {}, tr);
    CHECK_EQUAL_TEXT(std::string("ok"), std::string(to_string(st)), c.what);
    const std::string e = stays_between(tr, 1, c.p1, 0.0, 1e-12);
    if (!e.empty()) FAIL((std::string(c.what) + ": " + e).c_str());
    CHECK_TRAJ(tr, l, s, 1.0, true, c.what);
  }
  // The same with a joint really moving whose goal is exactly its stopping
  // point (the plan_stop target): stop, then wait there while joint 0 moves.
  JointState s = JointState::rest(JointVector::Zero(2));
  s.vel[1] = 0.05;
  s.acc[1] = -2.0;
  JointTrajectory stop, tr;
  CHECK(plan_stop(l, s, {}, stop) == MotionStatus::ok);
  JointVector goal = stop.goal;
  goal[0] = 0.2;
  CHECK_EQUAL(std::string("ok"), std::string(to_string(plan_movej(l, s, goal, {}, tr))));
  const std::string e = stays_between(tr, 1, 0.0, stop.goal[1], 1e-12);
  if (!e.empty()) FAIL(("moving joint at its stopping point: " + e).c_str());
  CHECK_TRAJ(tr, l, s, 1.0, true, "moving joint at its stopping point");
}

// Seeded sweep over the built-in robots' jerk-limited limits: one joint within
// 1e-18..1e-6 rad of its goal with a velocity of 1e-18..1e-6 rad/s (either
// sign, or zero), the others with random distances to go, override 1 or random.
// The near-rest joint stays within [start, goal] +- (1e-9 rad + its own
// stopping distance, which it cannot avoid) and every plan ends at its goal.
TEST(Movej, RandomNearRestJointsOnTheBuiltinRobots) {
  Rng r(4007);
  int planned = 0;
  for (const BuiltinModel& bm : builtin_models()) {
    const LoadResult lr = load_robot(bm.name);
    CHECK_TEXT(lr.ok, bm.name);
    const JointLimits l = limits_from(lr.chain);
    const int n = l.n;
    for (int m = 0; m < sweep(2000); ++m) {
      JointVector goal(n);
      for (int i = 0; i < n; ++i) {
        const auto k = static_cast<std::size_t>(i);
        const double lo = std::max(l.lower[k], -3.0), hi = std::min(l.upper[k], 3.0);
        goal[i] = r.uni(lo + 0.25 * (hi - lo), hi - 0.25 * (hi - lo));
      }
      JointState s = JointState::rest(goal);
      const int near = r.integer(0, n - 1);
      const auto sign = [&r] { return r.integer(0, 1) ? 1.0 : -1.0; };
      for (int i = 0; i < n; ++i) {
        if (i == near) {
          s.pos[i] = goal[i] + sign() * r.logu(1e-18, 1e-6);
          s.vel[i] = r.integer(0, 9) == 0 ? 0.0 : sign() * r.logu(1e-18, 1e-6);
        } else {
          s.pos[i] = goal[i] + sign() * r.logu(1e-4, 0.5);
        }
      }
      const double ov = r.integer(0, 1) ? 1.0 : r.uni(0.05, 1.0);
      JointTrajectory tr;
      const std::string ctx = std::string(bm.name) + " move " + std::to_string(m) +
                              fmt(" (joint %g at %.3g rad, %.3g rad/s from its goal)", near, s.pos[near] - goal[near],
                                  s.vel[near]);
      const MotionStatus st = plan_movej(l, s, goal, MovejOptions{ov}, tr);
      CHECK_EQUAL_TEXT(std::string("ok"), std::string(to_string(st)), ctx.c_str());
      // Its own stopping distance from |v| (at zero acceleration, override-scaled
      // limits) is unavoidable: v T / 2, T = v/A + A/J or 2 sqrt(v/J).
      const JointDynamics& d = l.dyn[static_cast<std::size_t>(near)];
      const double v = std::fabs(s.vel[near]), A = d.max_acceleration * ov * ov, J = d.max_jerk * ov * ov * ov;
      const double t_stop = v * J >= A * A ? v / A + A / J : 2.0 * std::sqrt(v / J);
      const std::string e = stays_between(tr, near, s.pos[near], goal[near], 1e-9 + 0.5 * v * t_stop);
      if (!e.empty()) FAIL((ctx + ": " + e).c_str());
      CHECK_TRAJ(tr, l, s, ov, true, ctx);
      ++planned;
    }
  }
  CHECK(planned >= sweep(2000));
}
