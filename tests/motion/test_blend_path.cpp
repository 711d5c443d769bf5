// SPDX-License-Identifier: Apache-2.0
// Blended line-to-line and mixed joint/line corners (kinematics/blend_path.hpp), sampled at
// the control rate as the RT thread samples them: the LinuxCNC #3773 tight zigzag at high
// feed (sampled joint acceleration never above its limit), every corner within its
// tolerance, mixed joint->line->joint, degradation to a smaller blend or an exact stop,
// seeded random sweeps. The references are the limits themselves and the programmed
// corners (finite differences of the samples, FK of the samples), not the planner's numbers.
#include <cmath>
#include <cstdio>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "servoarm/kinematics/blend_path.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/kinematics/ik.hpp"
#include "servoarm/kinematics/motion_ik.hpp"
#include "servoarm/kinematics/orientation.hpp"
#include "alloc_counter.hpp"

#include "sweep.hpp"  // kSlowBuild: fewer sweeps under qemu and the sanitizers

// CppUTest last: its leak detector redefines new.
#include <CppUTest/TestHarness.h>

using namespace servoarm::kin;

namespace {

constexpr int kSweeps = servoarm::test::kSlowBuild ? 3 : 12;  // sweep.hpp
constexpr double kRate = 1000;

const Chain& the_puma() {
  static const Chain c = [] {
    LoadResult r = load_robot("puma560");
    if (!r.ok) FAIL(r.error.c_str());
    Chain ch = r.chain;
    for (int i = 0; i < ch.n_joints; ++i) ch.joint(i).dynamics = JointDynamics{2.0, 10.0, 100.0};
    return ch;
  }();
  return c;
}

IkSolver real_ik(const Chain& c) {
  static IkModel model;
  static const bool ok = ik_prepare(c, model) == Status::ok;
  if (!ok) FAIL("ik_prepare failed");
  return IkSolver{&ik_nearest_for_motion, &model};
}

PathBlendConfig config(const Chain& c) {
  PathBlendConfig cfg;
  cfg.limits = limits_from(c);
  cfg.rate = kRate;
  cfg.chain = &c;
  cfg.ik = real_ik(c);
  return cfg;
}

JointVector q_start() {
  JointVector q(6);
  q << 0.2, -1.3, 0.4, 0.1, 0.9, 0.3;  // elbow bent, wrist away from q5 = 0
  return q;
}

Pose fk(const Chain& c, const JointVector& q) {
  Pose x;
  forward(c, q, x);
  return x;
}

using Queue = PathBlendQueue<48>;

struct Sampled {
  std::vector<double> t;
  std::vector<JointVector> q;
};

// The whole queue at k / rate (+ phase), IK seeded by the previous sample.
Sampled sample_all(const Queue& Q, double phase = 0) {
  Sampled s;
  const double end = Q.end_time() + 0.01;
  JointVector seed = Q.core.rest, q(6);
  for (long k = 0;; ++k) {
    const double t = (static_cast<double>(k) + phase) / kRate;
    if (t > end) break;
    const Status st = Q.sample(t, seed, q);
    if (!is_ok(st)) FAIL(("sample failed at t = " + std::to_string(t)).c_str());
    s.t.push_back(t);
    s.q.push_back(q);
    seed = q;
  }
  return s;
}

// Largest sampled |v|, |a| (every sample) and |j| (inside the blends) over the limit, per
// joint: 1 = at the limit. Finite differences at the control period.
struct Peaks {
  double v = 0, a = 0, j = 0;
};
Peaks peaks(const Chain& c, const Queue& Q, const Sampled& s) {
  const JointLimits L = limits_from(c);
  const double dt = 1.0 / kRate;
  Peaks p;
  for (std::size_t k = 3; k < s.q.size(); ++k) {
    bool in_blend = false;
    for (int i = 0; i + 1 < Q.size(); ++i) {
      const PathSegment &A = Q.at(i), &B = Q.at(i + 1);
      if (A.blend > 0 && s.t[k] > B.start && s.t[k] - 3 * dt < A.end()) in_blend = true;
    }
    for (int j = 0; j < 6; ++j) {
      const JointDynamics& d = L.dyn[static_cast<std::size_t>(j)];
      const double v = (s.q[k][j] - s.q[k - 1][j]) / dt;
      const double a = (s.q[k][j] - 2 * s.q[k - 1][j] + s.q[k - 2][j]) / (dt * dt);
      const double jk = (s.q[k][j] - 3 * s.q[k - 1][j] + 3 * s.q[k - 2][j] - s.q[k - 3][j]) / (dt * dt * dt);
      p.v = std::max(p.v, std::fabs(v) / d.max_velocity);
      p.a = std::max(p.a, std::fabs(a) / d.max_acceleration);
      if (in_blend) p.j = std::max(p.j, std::fabs(jk) / d.max_jerk);
    }
  }
  return p;
}

// Largest distance from each blended corner during its blend over its tolerance (line
// corners: the tool point, m; joint corners: joint space, rad): must be <= 1.
double worst_corner(const Chain& c, const Queue& Q, const Sampled& s) {
  double worst = 0;
  for (int i = 0; i + 1 < Q.size(); ++i) {
    const PathSegment &A = Q.at(i), &B = Q.at(i + 1);
    if (!(A.blend > 0)) continue;
    for (std::size_t k = 0; k < s.t.size(); ++k) {
      if (s.t[k] < B.start || s.t[k] >= A.end()) continue;
      const double d = A.kind == PathKind::line ? (fk(c, s.q[k]).translation() - A.x_end.translation()).norm()
                                                : (s.q[k] - A.q_end).norm();
      worst = std::max(worst, d / A.tolerance);
    }
  }
  return worst;
}

// Time the same targets take with exact stops (every segment's own duration).
double exact_stop_time(const Queue& Q) {
  double T = 0;
  for (int i = 0; i < Q.size(); ++i) T += Q.at(i).duration;
  return T;
}

}  // namespace

TEST_GROUP(BlendPath) {
  void setup() override { MemoryLeakWarningPlugin::saveAndDisableNewDeleteOverloads(); }
  void teardown() override { MemoryLeakWarningPlugin::restoreNewDeleteOverloads(); }
};

// LinuxCNC #3773: a tight zigzag at high feed overshot the acceleration limit up to 8x at
// blended corners. Here: 24 lines of ~10.4 mm at 250 mm/s, each turning 147 deg, 1 mm
// tolerance. Every sampled joint acceleration (and velocity) stays within its limit, at the
// control instants and half a period off them; the corners within 1 mm; and blending still
// shortens the program.
TEST(BlendPath, Issue3773TightZigzagAtHighFeed) {
  const Chain& c = the_puma();
  auto Q = std::make_unique<Queue>();
  Q->reset(config(c), q_start());
  const Pose x0 = fk(c, q_start());
  CartesianLimits cl;
  cl.linear_velocity = 0.25;
  int blended = 0;
  for (int i = 1; i <= 24; ++i) {
    Pose x = x0;
    x.translation() += Eigen::Vector3d(0.003 * i, (i % 2 ? 0.01 : 0.0), 0.0);
    PathBlendReport rep;
    const BlendStatus st = Q->append_line(x, cl, MovelOptions{}, i == 24 ? 0.0 : 0.001, 0.0, &rep);
    CHECK_TEXT(is_ok(st), (std::to_string(i) + ": " + to_string(st) + " " + to_string(rep.motion)).c_str());
    if (rep.blend > 0) ++blended;
  }
  const Sampled s = sample_all(*Q);
  const Peaks p = peaks(c, *Q, s);
  const Peaks p2 = peaks(c, *Q, sample_all(*Q, 0.5));
  std::printf("\n  #3773 zigzag: %d of 23 corners blended, peaks / limits: v %.3f a %.3f j %.3f (half-period phase: v %.3f a %.3f), "
              "corners %.3f of the tolerance, %.3f s vs %.3f s with exact stops\n",
              blended, p.v, p.a, p.j, p2.v, p2.a, worst_corner(c, *Q, s), Q->end_time(), exact_stop_time(*Q));
  CHECK(p.v <= 1.0 + 1e-6 && p.a <= 1.0 + 1e-6 && p.j <= 1.0 + 1e-6);  // 1e-6: rounding of the differences of a move at its limit
  CHECK(p2.v <= 1.0 + 1e-6 && p2.a <= 1.0 + 1e-6);
  CHECK(worst_corner(c, *Q, s) <= 1.0 + 1e-9);
  CHECK(blended >= 12);
  CHECK(Q->end_time() < 0.9 * exact_stop_time(*Q));
}

// The same zigzag where the joints, not the tolerance, bound the blends: acceleration
// limits 20x lower (the lines are slowed by movel to fit them; a blend that overlapped the
// deceleration and the acceleration in full would sum them). The sampled acceleration
// stays within the limit and some corners are cut short by it.
TEST(BlendPath, Issue3773ZigzagBoundByJointAcceleration) {
  Chain c = the_puma();
  for (int i = 0; i < 6; ++i) c.joint(i).dynamics = JointDynamics{2.0, 0.5, 5.0};
  PathBlendConfig cfg = config(c);
  cfg.ik = real_ik(the_puma());
  auto Q = std::make_unique<Queue>();
  Q->reset(cfg, q_start());
  const Pose x0 = fk(c, q_start());
  CartesianLimits cl;
  cl.linear_velocity = 0.25;
  int by_joints = 0, blended = 0;
  for (int i = 1; i <= 24; ++i) {
    Pose x = x0;
    x.translation() += Eigen::Vector3d(0.003 * i, (i % 2 ? 0.01 : 0.0), 0.0);
    PathBlendReport rep;
    CHECK(is_ok(Q->append_line(x, cl, MovelOptions{}, i == 24 ? 0.0 : 0.005, 0.0, &rep)));
    const std::string why = rep.limited_by;
    if (why == "acceleration" || why == "jerk" || why == "velocity") ++by_joints;
    if (rep.blend > 0) ++blended;
  }
  const Sampled s = sample_all(*Q);
  const Peaks p = peaks(c, *Q, s);
  std::printf("\n  #3773 zigzag, low joint limits: %d blended, %d cut by a joint limit; peaks v %.3f a %.3f j %.3f\n", blended,
              by_joints, p.v, p.a, p.j);
  CHECK(p.v <= 1.0 + 1e-6 && p.a <= 1.0 + 1e-6 && p.j <= 1.0 + 1e-6);
  CHECK(worst_corner(c, *Q, s) <= 1.0 + 1e-9);
  CHECK(by_joints >= 1);
}

// A square of 4 lines (90 deg corners) with a 5 mm tolerance: every corner blended, the
// tool passes each corner within 5 mm, and the time is shorter than with exact stops.
TEST(BlendPath, LineToLineCornerWithinTolerance) {
  const Chain& c = the_puma();
  auto Q = std::make_unique<Queue>();
  Q->reset(config(c), q_start());
  const Pose x0 = fk(c, q_start());
  const Eigen::Vector3d d[] = {{0.05, 0, 0}, {0.05, 0.05, 0}, {0, 0.05, 0}, {0, 0, 0}};
  for (int i = 0; i < 4; ++i) {
    Pose x = x0;
    x.translation() += d[i];
    PathBlendReport rep;
    CHECK(is_ok(Q->append_line(x, CartesianLimits{}, MovelOptions{}, i == 3 ? 0.0 : 0.005, 0.0, &rep)));
    if (i > 0) CHECK_TEXT(rep.blend > 0, ("corner " + std::to_string(i)).c_str());
  }
  const Sampled s = sample_all(*Q);
  const Peaks p = peaks(c, *Q, s);
  CHECK(p.v <= 1.0 + 1e-6 && p.a <= 1.0 + 1e-6 && p.j <= 1.0 + 1e-6);  // 1e-6: rounding of the differences of a move at its limit
  const double wc = worst_corner(c, *Q, s);
  CHECK(wc <= 1.0 + 1e-9);
  CHECK(wc > 0.1);  // it does cut the corner (a real blend, not a stop)
  CHECK(Q->end_time() < 0.95 * exact_stop_time(*Q));
  // Outside the blends the tool is on the programmed lines: the middle of each line.
  for (int i = 0; i < 4; ++i) {
    const PathSegment& g = Q->at(i);
    const double tm = g.start + 0.5 * g.duration;
    if (i > 0 && tm < Q->at(i - 1).end()) continue;
    if (i < 3 && tm >= Q->at(i + 1).start) continue;
    JointVector q(6);
    Q->sample(tm, g.line.goal, q);
    double sp, sv, sa;
    g.line.path_state(tm - g.start, sp, sv, sa);
    CHECK((fk(c, q).translation() - g.line.pose_at(sp).translation()).norm() < 1e-6);
  }
}

// joint -> line -> line -> joint: mixed transitions blended, limits held, the corners within
// their tolerances (joint corner: rad in joint space; line corners: m of the tool point).
TEST(BlendPath, MixedJointAndLineTransitions) {
  const Chain& c = the_puma();
  auto Q = std::make_unique<Queue>();
  Q->reset(config(c), q_start());
  JointVector q1 = q_start();
  q1[0] += 0.3;
  q1[1] += 0.1;
  PathBlendReport r1, r2, r3, r4;
  CHECK(is_ok(Q->append_joint(q1, 1.0, 0.05, 0.0, &r1)));
  Pose x = fk(c, q1);
  x.translation() += Eigen::Vector3d(0.0, 0.0, -0.06);
  CHECK(is_ok(Q->append_line(x, CartesianLimits{}, MovelOptions{}, 0.004, 0.0, &r2)));
  x.translation() += Eigen::Vector3d(0.06, 0.0, 0.0);
  CHECK(is_ok(Q->append_line(x, CartesianLimits{}, MovelOptions{}, 0.004, 0.0, &r3)));
  CHECK(is_ok(Q->append_joint(q_start(), 1.0, 0.0, 0.0, &r4)));
  std::printf("\n  mixed: joint->line %.3f s, line->line %.3f s, line->joint %.3f s of overlap (%d, %d, %d checks)\n", r2.blend,
              r3.blend, r4.blend, r2.checks, r3.checks, r4.checks);
  CHECK(r2.blend > 0);  // joint -> line
  CHECK(r3.blend > 0);  // line -> line
  CHECK(r4.blend > 0);  // line -> joint
  const Sampled s = sample_all(*Q);
  const Peaks p = peaks(c, *Q, s);
  std::printf("  mixed peaks / limits: v %.9f a %.9f j %.9f\n", p.v, p.a, p.j);
  CHECK(p.v <= 1.0 + 1e-6 && p.a <= 1.0 + 1e-6 && p.j <= 1.0 + 1e-6);  // 1e-6: rounding of the differences of a move at its limit
  CHECK(worst_corner(c, *Q, s) <= 1.0 + 1e-9);
  // Continuity: no jump anywhere (the largest step at 1 kHz under the velocity limit).
  for (std::size_t k = 1; k < s.q.size(); ++k) CHECK((s.q[k] - s.q[k - 1]).cwiseAbs().maxCoeff() <= 2.0 / kRate * (1 + 1e-9));
  // The end: at rest at the last target.
  CHECK((s.q.back() - q_start()).norm() < 1e-9);
}

// Degradation: a tolerance too small for any overlap, zero tolerance, t_earliest past the
// corner, and limits so low that a full blend would exceed them: a smaller blend or an
// exact stop, never a violation.
TEST(BlendPath, DegradesToSmallerBlendOrExactStop) {
  const Chain& c = the_puma();
  const Pose x0 = fk(c, q_start());
  Pose a = x0, b = x0;
  a.translation() += Eigen::Vector3d(0.05, 0, 0);
  b.translation() += Eigen::Vector3d(0.05, 0.05, 0);
  auto Q = std::make_unique<Queue>();
  // zero tolerance: exact stop, B starts when A ends
  Q->reset(config(c), q_start());
  Q->append_line(a, CartesianLimits{}, MovelOptions{}, 0.0);
  PathBlendReport rep;
  CHECK(Q->append_line(b, CartesianLimits{}, MovelOptions{}, 0.0, 0.0, &rep) == BlendStatus::ok);
  DOUBLES_EQUAL(Q->at(0).end(), Q->at(1).start, 0);
  // t_earliest past the corner: exact stop (nothing already sampled changes)
  Q->reset(config(c), q_start());
  Q->append_line(a, CartesianLimits{}, MovelOptions{}, 0.005);
  CHECK(Q->append_line(b, CartesianLimits{}, MovelOptions{}, 0.0, 100.0, &rep) == BlendStatus::exact_stop);
  DOUBLES_EQUAL(100.0, Q->at(1).start, 0);
  // a 1 micrometre tolerance: a much smaller blend than 5 mm gives, within 1 um
  Q->reset(config(c), q_start());
  Q->append_line(a, CartesianLimits{}, MovelOptions{}, 1e-6);
  const BlendStatus st = Q->append_line(b, CartesianLimits{}, MovelOptions{}, 0.0, 0.0, &rep);
  CHECK(st == BlendStatus::blend_reduced || st == BlendStatus::exact_stop);
  CHECK(rep.corner <= 1e-6 * (1 + 1e-9));
  Sampled s = sample_all(*Q);
  CHECK(worst_corner(c, *Q, s) <= 1.0 + 1e-9);
  // joint acceleration limits 20x lower than the lines need for a free blend: the lines
  // are slowed by movel, the blends are cut by the acceleration / jerk checks
  Chain slow = c;
  for (int i = 0; i < 6; ++i) slow.joint(i).dynamics = JointDynamics{2.0, 0.5, 5.0};
  PathBlendConfig cfg = config(slow);
  cfg.ik = real_ik(c);  // the same kinematics
  Q->reset(cfg, q_start());
  CartesianLimits fast;
  fast.linear_velocity = 0.25;
  Q->append_line(a, fast, MovelOptions{}, 0.02);
  Q->append_line(b, fast, MovelOptions{}, 0.0, 0.0, &rep);
  s = sample_all(*Q);
  const Peaks p = peaks(slow, *Q, s);
  std::printf("\n  low limits: blend %.3f s (%s), peaks v %.3f a %.3f j %.3f\n", rep.blend, rep.limited_by, p.v, p.a, p.j);
  CHECK(p.v <= 1.0 + 1e-6 && p.a <= 1.0 + 1e-6 && p.j <= 1.0 + 1e-6);  // 1e-6: rounding of the differences of a move at its limit
}

// Seeded random sweeps: random lines and joint moves around the start pose with random
// tolerances (0..8 mm, 0..0.1 rad): every sample within the limits, every corner within its
// tolerance, and blending never slower than exact stops.
TEST(BlendPath, SeededRandomSweeps) {
  const Chain& c = the_puma();
  std::mt19937_64 g(1818);
  auto u = [&g](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(g); };
  auto Q = std::make_unique<Queue>();
  int corners = 0, blended = 0, refused = 0;
  double worst_v = 0, worst_a = 0, worst_j = 0, worst_c = 0;
  for (int sweep = 0; sweep < kSweeps; ++sweep) {
    Q->reset(config(c), q_start());
    JointVector q = q_start();
    for (int k = 0; k < 8; ++k) {
      PathBlendReport rep;
      BlendStatus st;
      const double last = k == 7 ? 0.0 : 1.0;
      if (u(0, 1) < 0.6) {
        Pose x = fk(c, q);
        x.translation() += Eigen::Vector3d(u(-0.06, 0.06), u(-0.06, 0.06), u(-0.04, 0.04));
        st = Q->append_line(x, CartesianLimits{}, MovelOptions{}, last * u(0, 0.008), 0.0, &rep);
      } else {
        JointVector w = q;
        for (int j = 0; j < 6; ++j) w[j] += u(-0.25, 0.25);
        w[4] = std::copysign(std::max(std::fabs(w[4]), 0.3), w[4]);
        st = Q->append_joint(w, u(0.3, 1.0), last * u(0, 0.1), 0.0, &rep);
      }
      if (!is_ok(st)) {
        ++refused;  // a line movel refuses (singularity, reach): nothing queued
        continue;
      }
      if (Q->size() > 1) ++corners;
      if (rep.blend > 0) ++blended;
      q = Q->at(Q->size() - 1).q_end;
    }
    const Sampled s = sample_all(*Q);
    const Peaks p = peaks(c, *Q, s);
    worst_v = std::max(worst_v, p.v), worst_a = std::max(worst_a, p.a), worst_j = std::max(worst_j, p.j);
    worst_c = std::max(worst_c, worst_corner(c, *Q, s));
    CHECK(Q->end_time() <= exact_stop_time(*Q) * (1 + 1e-12));
  }
  std::printf("\n  random: %d corners, %d blended, %d moves refused by movel; worst v %.3f a %.3f j %.3f corner %.3f\n", corners,
              blended, refused, worst_v, worst_a, worst_j, worst_c);
  CHECK(worst_v <= 1.0 + 1e-6 && worst_a <= 1.0 + 1e-6 && worst_j <= 1.0 + 1e-6 && worst_c <= 1.0 + 1e-9);
  CHECK(blended >= corners / 3);
}

TEST(BlendPath, BadInputRefusedNothingQueued) {
  const Chain& c = the_puma();
  auto Q = std::make_unique<Queue>();
  Q->reset(config(c), q_start());
  JointVector w = q_start();
  w[0] += 0.1;
  CHECK(Q->append_joint(w, 1.0, -1.0) == BlendStatus::bad_input);
  CHECK(Q->append_joint(w, 1.0, std::nan("")) == BlendStatus::bad_input);
  CHECK(Q->append_joint(w, 0.0, 0.0) == BlendStatus::bad_input);
  JointVector far = w;
  far[0] = 10;
  CHECK(Q->append_joint(far, 1.0, 0.0) == BlendStatus::goal_out_of_limits);
  Pose x = fk(c, q_start());
  x.translation() = Eigen::Vector3d(5, 0, 0);  // out of reach
  PathBlendReport rep;
  CHECK(Q->append_line(x, CartesianLimits{}, MovelOptions{}, 0.0, 0.0, &rep) == BlendStatus::no_solution);
  CHECK(!is_ok(rep.motion));
  LONGS_EQUAL(0, Q->size());
  CHECK(Q->append_joint(q_start(), 1.0, 0.0) == BlendStatus::zero_length);
  LONGS_EQUAL(0, Q->size());
}

// Nothing on the append, sampling or retire path touches the heap (the queue lives in a
// slot allocated before).
TEST(BlendPath, AllocationFree) {
  const Chain& c = the_puma();
  auto Q = std::make_unique<Queue>();
  const PathBlendConfig cfg = config(c);
  const Pose x0 = fk(c, q_start());
  JointVector w = q_start();
  w[0] += 0.2;
  servoarm::test::AllocScope scope;
  Q->reset(cfg, q_start());
  double sink = 0;
  for (int i = 1; i <= 6; ++i) {
    Pose x = x0;
    x.translation() += Eigen::Vector3d(0.003 * i, (i % 2 ? 0.01 : 0.0), 0.0);
    sink += static_cast<int>(Q->append_line(x, CartesianLimits{}, MovelOptions{}, 0.001));
  }
  sink += static_cast<int>(Q->append_joint(w, 1.0, 0.0));
  JointVector seed = q_start(), q(6);
  for (double t = 0; t < Q->end_time(); t += 1.0 / kRate) {
    Q->sample(t, seed, q);
    seed = q;
    sink += q.sum();
  }
  Q->retire(Q->end_time());
  const std::size_t n = scope.end();
  CHECK(std::isfinite(sink));
  LONGS_EQUAL(0, n);
}

// A blended segment never ends later than it would with an exact stop at its corner (the
// same moves, every tolerance 0: each planned alone at the full limits, from rest): joint
// -> line, line -> joint, joint -> joint -> joint, with the firmware's joint_share 0.5 and
// each segment queued once the one before it runs (it can no longer be planned again).
TEST(BlendPath, NoSegmentEndsLaterThanItsExactStop) {
  const Chain& c = the_puma();
  struct Move {
    bool line;
    JointVector q;   // joint move: the target
    Eigen::Vector3d dx;  // line: the tool's displacement
    double tol;
  };
  JointVector q1 = q_start(), q2, q3;
  q1[0] += 0.5;
  q1[1] -= 0.3;
  q2 = q1;
  q2[2] += 0.4;
  q3 = q2;
  q3[0] -= 0.6;
  const std::vector<std::vector<Move>> runs = {
      {{false, q1, {}, 0.09}, {true, {}, {0, 0, -0.1}, 0.0}},
      {{true, {}, {0, 0, -0.1}, 0.01}, {false, q_start(), {}, 0.0}},
      {{false, q1, {}, 0.09}, {false, q2, {}, 0.09}, {false, q3, {}, 0.0}},
      {{false, q1, {}, 0.09}, {true, {}, {0, 0, -0.1}, 0.01}, {true, {}, {0.05, 0, 0}, 0.01}, {false, q2, {}, 0.0}},
  };
  for (std::size_t r = 0; r < runs.size(); ++r) {
    std::vector<double> ends[2];
    for (int exact = 0; exact < 2; ++exact) {
      auto Q = std::make_unique<Queue>();
      PathBlendConfig cfg = config(c);
      cfg.joint_share = 0.5;
      Q->reset(cfg, q_start());
      Pose x = fk(c, q_start());
      JointVector q = q_start();
      double t_earliest = 0;
      for (const Move& m : runs[r]) {
        const double tol = exact ? 0.0 : m.tol;
        BlendStatus st;
        if (m.line) {
          x.translation() += m.dx;
          st = Q->append_line(x, CartesianLimits{}, MovelOptions{}, tol, t_earliest);
        } else {
          st = Q->append_joint(m.q, 1.0, tol, t_earliest);
          x = fk(c, m.q);
        }
        CHECK_TEXT(is_ok(st), to_string(st));
        const PathSegment& g = Q->at(Q->size() - 1);
        ends[exact].push_back(g.end());
        t_earliest = g.start + 0.01;  // queued while this one runs
        (void)q;
      }
    }
    std::printf("\n  run %zu: blended ends at %.3f s, exact stops at %.3f s\n", r, ends[0].back(), ends[1].back());
    for (std::size_t k = 0; k < ends[0].size(); ++k)
      if (ends[0][k] > ends[1][k] + 1e-9) {
        char m[160];
        std::snprintf(m, sizeof m, "run %zu segment %zu ends at %.4f s blended, %.4f s with exact stops", r, k, ends[0][k],
                      ends[1][k]);
        FAIL(m);
      }
  }
}
