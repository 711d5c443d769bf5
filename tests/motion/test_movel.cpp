// SPDX-License-Identifier: Apache-2.0
// Cartesian moves: tool on the line, path check refusals with reason and place,
// singularity slowdown/refusal, stop/resume on the line, zero heap.
#include <cmath>
#include <cstdio>
#include <random>
#include <string>

#include "alloc_counter.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/kinematics/ik.hpp"
#include "servoarm/kinematics/motion_ik.hpp"
#include "servoarm/kinematics/orientation.hpp"
#include "servoarm/kinematics/trajectory_cartesian.hpp"
#include "sweep.hpp"  // sweep(): fewer cases under qemu and the sanitizers

// CppUTest last: its leak detector redefines new.
#include <CppUTest/TestHarness.h>

using namespace servoarm::kin;

namespace {

constexpr double kDt = 1e-3;

// Random-sweep sizes. The host runs the full counts written at each sweep. A cross
// build under qemu-user and the sanitizer/valgrind builds run this suite some 10-40x
// slower (tests/support/sweep.hpp): the same sweeps, same seeds, with the first
// 1/20 of the cases (e.g. 500 fallback-IK lines instead of 10 000, 20 closed-form
// instead of 400; the 100 stop/resume lines stay), so it finishes in CI time.
using servoarm::test::sweep;  // sweep.hpp: 1/20 of the cases under qemu and the sanitizers

Chain puma() {
  LoadResult r = load_robot("puma560");
  if (!r.ok) FAIL(r.error.c_str());
  Chain c = r.chain;
  for (int i = 0; i < c.n_joints; ++i) c.joint(i).dynamics = JointDynamics{2.0, 10.0, 100.0};
  return c;
}

const Chain& the_puma() {
  static const Chain c = puma();
  return c;
}

// kinematics/ik (closed form for the PUMA), as the firmware and armctl use it.
IkSolver real_ik(const Chain& c) {
  static IkModel model;
  if (ik_prepare(c, model) != Status::ok) FAIL("ik_prepare failed");
  return IkSolver{&ik_nearest_for_motion, &model};
}

Pose fk(const Chain& c, const JointVector& q) {
  Pose x;
  forward(c, q, x);
  return x;
}

// A comfortable PUMA configuration: elbow bent, wrist away from q5 = 0.
JointVector random_q(std::mt19937_64& g) {
  auto u = [&g](double a, double b) { return std::uniform_real_distribution<double>(a, b)(g); };
  JointVector q(6);
  q << u(-1.5, 1.5), u(-2.2, -0.8), u(-0.6, 1.0), u(-1.2, 1.2), u(0.5, 1.4) * (u(0, 1) < 0.5 ? -1 : 1), u(-2, 2);
  return q;
}

double line_distance(const CartesianTrajectory& tr, const Eigen::Vector3d& x, double& along) {
  const Eigen::Vector3d d = tr.p1 - tr.p0;
  const double L = d.norm();
  if (L < 1e-12) {
    along = 0;
    return (x - tr.p0).norm();
  }
  const Eigen::Vector3d u = d / L;
  along = (x - tr.p0).dot(u);
  const double a = std::clamp(along, 0.0, L);
  return (x - tr.p0 - a * u).norm();
}

// Samples a planned movel at 1 kHz with per-sample IK; returns "" or what failed.
std::string check_movel(const Chain& c, const CartesianTrajectory& tr, const CartesianLimits& cl, bool ik_mode,
                        double line_tol, double& worst_dev, bool to_target = true) {
  JointVector q, qd, qdd, prev;
  tr.sample_precomputed(0, prev, qd, qdd);
  Eigen::Vector3d prev_x = fk(c, prev).translation();
  const int steps = static_cast<int>(std::ceil(tr.duration / kDt)) + 1;
  char buf[200];
  for (int k = 1; k <= steps; ++k) {
    const double t = k * kDt;
    if (ik_mode) {
      if (!is_ok(tr.sample_ik(t, q, qd, qdd))) return "IK failed while sampling at t=" + std::to_string(t);
    } else {
      tr.sample_precomputed(t, q, qd, qdd);
    }
    const Pose x = fk(c, q);
    double along;
    const double dev = line_distance(tr, x.translation(), along);
    worst_dev = std::max(worst_dev, dev);
    if (dev > line_tol) {
      std::snprintf(buf, sizeof buf, "tool %.3g m off the line at t=%g", dev, t);
      return buf;
    }
    double s, sd, sdd;
    tr.path_state(t, s, sd, sdd);
    const double rot = rotation_error(x.linear(), tr.pose_at(s).linear()).norm();
    if (ik_mode && rot > 1e-6) return "orientation off the slerp at t=" + std::to_string(t);
    for (int i = 0; i < tr.n; ++i) {
      const JointDynamics& d = c.joint(i).dynamics;
      const double v = (q[i] - prev[i]) / kDt;
      if (std::fabs(v) > d.max_velocity * (1 + 1e-6)) {
        std::snprintf(buf, sizeof buf, "joint %d at %.4g rad/s > %.4g at t=%g (s=%.4f)", i, v, d.max_velocity, t, s);
        return buf;
      }
    }
    const double lin = (x.translation() - prev_x).norm() / kDt;
    if (lin > cl.linear_velocity * (1 + 1e-3) + 1e-9) {
      std::snprintf(buf, sizeof buf, "tool speed %.4g > %.4g at t=%g", lin, cl.linear_velocity, t);
      return buf;
    }
    prev = q;
    prev_x = x.translation();
  }
  // End exactly at the target pose.
  tr.sample_ik(tr.duration, q, qd, qdd);
  const Pose xe = fk(c, q);
  if (to_target && (xe.translation() - tr.p1).norm() > 1e-9) return "end position off target";
  return "";
}

}  // namespace

// The chain is not a member of the fixture: Chain is 16-byte aligned (Eigen), more
// than operator new guarantees on 32-bit ARM (8), and CppUTest's `new` macro, which
// allocates the fixture, has no aligned overload; on armhf the fixture was freed
// behind the leak detector's back (reported as a leak, then a corrupt heap).
TEST_GROUP(Movel) {
  const Chain& c = the_puma();
  IkSolver ik;
  void setup() override { ik = real_ik(c); }
};

// Random lines on a PUMA 560: every planned one is sampled at 1 kHz with IK per
// sample (tool on the line, orientation on the slerp, joint and tool speeds within
// limits, end on target); every 10th also from the precomputed joint path.
void random_lines(const Chain& c, IkSolver ik, int count, unsigned seed) {
  std::mt19937_64 g(seed);
  const CartesianLimits cl{};
  int planned = 0, slowed = 0, refused = 0;
  double worst_ik = 0, worst_pre = 0;
  CartesianTrajectory tr;
  for (int m = 0; m < count; ++m) {
    const JointVector q0 = random_q(g);
    JointVector q1 = q0;
    for (int i = 0; i < 6; ++i) q1[i] += std::uniform_real_distribution<double>(-0.25, 0.25)(g);
    const Pose target = fk(c, q1);
    PathReport rep;
    const MotionStatus st = plan_movel(c, q0, target, cl, MovelOptions{}, ik, tr, &rep);
    const std::string ctx = "line " + std::to_string(m) + " (" + to_string(st) + ")";
    if (!is_ok(st)) {
      ++refused;
      CHECK_TEXT(rep.status == st, ctx.c_str());
      CHECK_TEXT(rep.s >= 0 && rep.s <= 1, ctx.c_str());
      continue;
    }
    ++planned;
    if (st == MotionStatus::slowed_near_singularity) ++slowed;
    // Per-sample IK on every move; the precomputed path on every 10th.
    const std::string e = check_movel(c, tr, cl, true, 1e-6, worst_ik);
    if (!e.empty()) FAIL((ctx + ": " + e).c_str());
    if (m % 10 == 0) {
      const std::string e2 = check_movel(c, tr, cl, false, 1e-3, worst_pre);
      if (!e2.empty()) FAIL((ctx + " precomputed: " + e2).c_str());
    }
  }
  std::printf("\n  movel sweep: %d planned (%d slowed), %d refused; worst deviation ik %.2e m, precomputed %.2e m\n",
              planned, slowed, refused, worst_ik, worst_pre);
  CHECK(planned > count * 8 / 10);
}

// 10 000 lines with the library's damped-Newton fallback (fast), 400 with
// kinematics/ik (closed form, what armctl and the firmware use); 1/20 of that
// under emulation (sweep()), and of the fallback's 1/40: its first 250 lines
// (75 ms each under qemu, per-sample IK at 1 kHz) hold slowed and refused lines.
TEST(Movel, RandomLinesStayOnTheLineFallbackIk) {
  random_lines(c, IkSolver{&ik_nearest_newton, nullptr}, sweep(10000) / (servoarm::test::kSlowBuild ? 2 : 1), 5001);
}
TEST(Movel, RandomLinesStayOnTheLineClosedFormIk) { random_lines(c, ik, sweep(400), 5005); }

TEST(Movel, RefusedMovesNameReasonAndPlace) {
  const JointVector q0 = (JointVector(6) << 0.2, -1.4, 1.5, 0.3, 0.8, 0.1).finished();
  const Pose x0 = fk(c, q0);
  CartesianTrajectory tr;
  tr.duration = 42;
  PathReport rep;
  {  // Unreachable: 3 m away along x.
    Pose t = x0;
    t.translation() += Eigen::Vector3d(3, 0, 0);
    CHECK_EQUAL(static_cast<int>(MotionStatus::no_ik_solution),
                static_cast<int>(plan_movel(c, q0, t, {}, {}, ik, tr, &rep)));
    CHECK(rep.s > 0 && rep.s < 1);  // the line leaves the workspace part way
    DOUBLES_EQUAL((x0.translation() + rep.s * Eigen::Vector3d(3, 0, 0) - rep.position).norm(), 0, 1e-9);
  }
  {  // A joint limit crossed on the way: tighten joint 0 around its start.
    Chain tight = c;
    tight.joint(0).lower = 0.1;
    tight.joint(0).upper = 0.3;
    const Pose t = fk(c, (JointVector(6) << 0.6, -1.4, 1.5, 0.3, 0.8, 0.1).finished());
    CHECK_EQUAL(static_cast<int>(MotionStatus::path_out_of_limits),
                static_cast<int>(plan_movel(tight, q0, t, {}, {}, ik, tr, &rep)));
    CHECK_EQUAL(0, rep.joint);
    CHECK(rep.s > 0 && rep.s < 1);
  }
  {  // Bad input.
    Pose t = x0;
    t.linear() *= 2.0;
    CHECK(plan_movel(c, q0, t, {}, {}, ik, tr) == MotionStatus::bad_input);
    CHECK(plan_movel(c, q0, x0, {}, {}, IkSolver{}, tr) == MotionStatus::bad_input);
    CHECK(plan_movel(c, JointVector::Zero(5), x0, {}, {}, ik, tr) == MotionStatus::wrong_size);
    CartesianLimits bad;
    bad.linear_velocity = 0;
    CHECK(plan_movel(c, q0, x0, bad, {}, ik, tr) == MotionStatus::bad_limits);
  }
  DOUBLES_EQUAL(42, tr.duration, 0);
  STRCMP_EQUAL("no_ik_solution", to_string(MotionStatus::no_ik_solution));
  STRCMP_EQUAL("slowed_near_singularity", to_string(MotionStatus::slowed_near_singularity));
}

// Lines whose wrist passes near q5 = 0 (the PUMA wrist singularity): every
// one is refused as a singularity (or branch change) or slowed so that the
// sampled joint speeds stay within the limits.
TEST(Movel, SingularityRefusedOrSlowedNeverTooFast) {
  std::mt19937_64 g(5002);
  auto u = [&g](double a, double b) { return std::uniform_real_distribution<double>(a, b)(g); };
  const CartesianLimits cl{};
  int slowed = 0, singular = 0, other = 0, fine = 0;
  double worst = 0;
  CartesianTrajectory tr;
  for (int m = 0; m < sweep(600); ++m) {
    JointVector q0(6), q1(6);
    q0 << u(-1, 1), u(-2, -1), u(-0.5, 1.0), u(-0.5, 0.5), u(0.02, 0.4), u(-1, 1);
    q1 = q0;
    for (int i = 0; i < 4; ++i) q1[i] += u(-0.1, 0.1);
    q1[4] = -u(0.02, 0.4);  // the wrist crosses q5 = 0 (in joint space)
    q1[5] += u(-0.3, 0.3);
    PathReport rep;
    const MotionStatus st = plan_movel(c, q0, fk(c, q1), cl, MovelOptions{}, ik, tr, &rep);
    const std::string ctx = "singular line " + std::to_string(m) + " (" + to_string(st) + ")";
    switch (st) {
      case MotionStatus::singularity: ++singular; break;
      case MotionStatus::slowed_near_singularity: ++slowed; break;
      case MotionStatus::ok: ++fine; break;
      case MotionStatus::branch_change:
      case MotionStatus::path_out_of_limits:
      case MotionStatus::no_ik_solution: ++other; break;
      default: FAIL((ctx + ": unexpected status").c_str());
    }
    if (!is_ok(st)) {
      CHECK_TEXT(rep.status == st && rep.s >= 0 && rep.s <= 1, ctx.c_str());
      continue;
    }
    if (st == MotionStatus::slowed_near_singularity) CHECK_TEXT(rep.slowdown > 1, ctx.c_str());
    const std::string e = check_movel(c, tr, cl, true, 1e-6, worst);
    if (!e.empty()) FAIL((ctx + ": " + e).c_str());
  }
  std::printf("\n  singular lines: %d refused as singularity, %d slowed, %d ok, %d other refusals\n", singular, slowed,
              fine, other);
  CHECK(singular + slowed > sweep(600) / 4);
  // Slowing disabled: the same kind of line is refused as joint_velocity or singularity.
  MovelOptions strict;
  strict.allow_slowdown = false;
  int refused = 0;
  for (int m = 0; m < 50; ++m) {
    JointVector q0(6), q1(6);
    q0 << 0.1, -1.5, 1.6, 0.2, 0.05, 0.1;
    q1 = q0;
    q1[4] = -0.05;
    q1[5] += 0.01 * m;
    PathReport rep;
    const MotionStatus st = plan_movel(c, q0, fk(c, q1), cl, strict, ik, tr, &rep);
    if (st == MotionStatus::joint_velocity || st == MotionStatus::singularity) ++refused;
    CHECK(st != MotionStatus::slowed_near_singularity);
  }
  CHECK(refused > 40);
}

TEST(Movel, StopStaysOnTheLineAndResumeFinishes) {
  std::mt19937_64 g(5003);
  const CartesianLimits cl{};
  CartesianTrajectory tr;
  for (int m = 0; m < 100; ++m) {
    const JointVector q0 = random_q(g);
    JointVector q1 = q0;
    for (int i = 0; i < 6; ++i) q1[i] += std::uniform_real_distribution<double>(-0.25, 0.25)(g);
    if (!is_ok(plan_movel(c, q0, fk(c, q1), cl, {}, ik, tr))) continue;
    const double ts = std::uniform_real_distribution<double>(0, tr.duration)(g);
    JointVector before, qd, qdd;
    tr.sample_ik(ts, before, qd, qdd);
    CHECK(stop_movel(tr, ts) == MotionStatus::ok);
    JointVector after;
    tr.sample_ik(0, after, qd, qdd);
    CHECK((after - before).norm() < 1e-9);  // no jump at the switch
    double worst = 0;
    const std::string e = check_movel(c, tr, cl, true, 1e-6, worst, false);
    if (!e.empty()) FAIL(("stop: " + e).c_str());
    CHECK(resume_movel(tr, tr.duration, 0.5) == MotionStatus::ok);
    JointVector end;
    tr.sample_ik(tr.duration, end, qd, qdd);
    CHECK((fk(c, end).translation() - tr.p1).norm() < 1e-9);
  }
}

TEST(Movel, ZeroHeapInPlanAndSample) {
  const JointVector q0 = (JointVector(6) << 0.2, -1.4, 1.5, 0.3, 0.8, 0.1).finished();
  const JointVector q1 = (JointVector(6) << 0.4, -1.2, 1.3, 0.1, 0.6, 0.3).finished();
  const Pose t = fk(c, q1);
  static CartesianTrajectory tr;
  JointVector q, qd, qdd;
  servoarm::test::AllocScope scope;
  CHECK(is_ok(plan_movel(c, q0, t, {}, {}, ik, tr)));
  for (int k = 0; k < 100; ++k) {
    tr.sample_ik(k * tr.duration / 100, q, qd, qdd);
    tr.sample_precomputed(k * tr.duration / 100, q, qd, qdd);
  }
  CHECK(stop_movel(tr, 0.1) == MotionStatus::ok);
  CHECK_EQUAL(0u, scope.end());
}

