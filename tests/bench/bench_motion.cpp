// SPDX-License-Identifier: Apache-2.0
// Motion: planning and sampling trajectories.
//   plan/movej6/servoarm          6-joint synchronised jerk-limited plan from rest
//   plan/movej6_moving/servoarm   same, replanning from a moving state (mid-move)
//   sample/movej6/servoarm        one sample of all 6 joints (pos, vel, acc)
//   plan/movej6/kdl_trap          reference: Orocos KDL VelocityProfile_Trap per
//                                 joint + SetProfileDuration sync (trapezoidal
//                                 velocity, NOT jerk-limited: a lower bound on cost)
//   plan/movel/servoarm           PUMA 560 straight line incl. its path check
//                                 (257 IK solutions by kinematics/ik + Jacobian condition numbers)
//   sample/movel_ik/servoarm      one movel sample with IK at the exact pose
//   sample/movel_pre/servoarm     one movel sample from the precomputed joint path
// Ruckig/Reflexxes are not Debian packages, so they are not run here.
#include <benchmark/benchmark.h>

#include <random>
#include <vector>

#include "servoarm/kinematics/description.hpp"
#include "servoarm/kinematics/ik.hpp"
#include "servoarm/kinematics/motion_ik.hpp"
#include "servoarm/kinematics/trajectory.hpp"
#include "servoarm/kinematics/trajectory_cartesian.hpp"

#ifdef SERVOARM_WITH_KDL
#include <kdl/velocityprofile_trap.hpp>
#endif

namespace {
using namespace servoarm;

constexpr int kInputs = 1024;

struct MovejFixture {
  kin::JointLimits limits;
  std::vector<kin::JointState> starts, moving;
  std::vector<kin::JointVector> goals;
};

const MovejFixture& movej_fixture() {
  static MovejFixture f = [] {
    MovejFixture x;
    std::mt19937_64 g(42);
    auto u = [&g](double a, double b) { return std::uniform_real_distribution<double>(a, b)(g); };
    x.limits.n = 6;
    for (int i = 0; i < 6; ++i) {
      const auto k = static_cast<std::size_t>(i);
      x.limits.dyn[k] = kin::JointDynamics{u(1, 3), u(5, 20), u(50, 500)};
      x.limits.lower[k] = -3.2;
      x.limits.upper[k] = 3.2;
    }
    for (int m = 0; m < kInputs; ++m) {
      kin::JointVector a(6), b(6), c(6);
      for (int i = 0; i < 6; ++i) {
        a[i] = u(-3, 3);
        b[i] = u(-3, 3);
        c[i] = u(-3, 3);
      }
      x.starts.push_back(kin::JointState::rest(a));
      x.goals.push_back(b);
      kin::JointTrajectory tr;
      kin::plan_movej(x.limits, x.starts.back(), c, {}, tr);
      kin::JointState s;
      tr.sample(u(0, tr.duration), s);
      x.moving.push_back(s);
    }
    return x;
  }();
  return f;
}

void plan_movej6(benchmark::State& st, bool moving) {
  const MovejFixture& f = movej_fixture();
  kin::JointTrajectory tr;
  std::size_t i = 0;
  for (auto _ : st) {
    const std::size_t k = i++ & (kInputs - 1);
    const auto r = kin::plan_movej(f.limits, moving ? f.moving[k] : f.starts[k], f.goals[k], {}, tr);
    benchmark::DoNotOptimize(r);
    benchmark::DoNotOptimize(tr.duration);
  }
}
BENCHMARK_CAPTURE(plan_movej6, servoarm, false)->Name("plan/movej6/servoarm");
BENCHMARK_CAPTURE(plan_movej6, servoarm_moving, true)->Name("plan/movej6_moving/servoarm");

void sample_movej6(benchmark::State& st) {
  const MovejFixture& f = movej_fixture();
  kin::JointTrajectory tr;
  kin::plan_movej(f.limits, f.starts[0], f.goals[0], {}, tr);
  std::vector<double> ts(kInputs);
  std::mt19937_64 g(7);
  for (double& t : ts) t = std::uniform_real_distribution<double>(0, tr.duration)(g);
  kin::JointVector p(6), v(6), a(6);
  std::size_t i = 0;
  for (auto _ : st) {
    tr.sample(ts[i++ & (kInputs - 1)], p, v, a);
    benchmark::DoNotOptimize(p);
    benchmark::DoNotOptimize(v);
    benchmark::DoNotOptimize(a);
  }
}
BENCHMARK(sample_movej6)->Name("sample/movej6/servoarm");

#ifdef SERVOARM_WITH_KDL
void plan_movej6_kdl(benchmark::State& st) {
  const MovejFixture& f = movej_fixture();
  std::vector<KDL::VelocityProfile_Trap> prof;
  for (int i = 0; i < 6; ++i)
    prof.emplace_back(f.limits.dyn[static_cast<std::size_t>(i)].max_velocity,
                      f.limits.dyn[static_cast<std::size_t>(i)].max_acceleration);
  std::size_t i = 0;
  for (auto _ : st) {
    const std::size_t k = i++ & (kInputs - 1);
    double T = 0;
    for (int j = 0; j < 6; ++j) {
      prof[static_cast<std::size_t>(j)].SetProfile(f.starts[k].pos[j], f.goals[k][j]);
      T = std::max(T, prof[static_cast<std::size_t>(j)].Duration());
    }
    for (int j = 0; j < 6; ++j)
      prof[static_cast<std::size_t>(j)].SetProfileDuration(f.starts[k].pos[j], f.goals[k][j], T);
    benchmark::DoNotOptimize(T);
  }
}
BENCHMARK(plan_movej6_kdl)->Name("plan/movej6/kdl_trap");
#endif

struct MovelFixture {
  kin::Chain chain;
  kin::IkModel model;  // kinematics/ik: closed form for the PUMA
  // The motion IK adapter as armctl plan movel uses it (solutions outside the limits returned).
  kin::IkSolver ik() const {
    kin::IkSolverOptions o;
    o.allow_out_of_limits = true;
    return kin::make_ik_solver(model, o);
  }
  std::vector<kin::JointVector> q0;
  std::vector<kin::Pose> target;
};

const MovelFixture& movel_fixture() {
  static MovelFixture f = [] {
    MovelFixture x;  // (static below: IkModel is large)
    const auto r = kin::load_robot("puma560");
    if (!r.ok) std::abort();
    x.chain = r.chain;
    for (int i = 0; i < 6; ++i) x.chain.joint(i).dynamics = kin::JointDynamics{2.0, 10.0, 100.0};
    kin::ik_prepare(x.chain, x.model);
    std::mt19937_64 g(43);
    auto u = [&g](double a, double b) { return std::uniform_real_distribution<double>(a, b)(g); };
    while (x.q0.size() < 64) {
      kin::JointVector q(6), q1(6);
      q << u(-1.5, 1.5), u(-2.2, -0.8), u(0.6, 2.4), u(-1.2, 1.2), u(0.5, 1.4), u(-2, 2);
      for (int i = 0; i < 6; ++i) q1[i] = q[i] + u(-0.25, 0.25);
      kin::Pose t;
      kin::forward(x.chain, q1, t);
      kin::CartesianTrajectory tr;
      if (kin::plan_movel(x.chain, q, t, {}, {}, x.ik(), tr) != kin::MotionStatus::ok) continue;
      x.q0.push_back(q);
      x.target.push_back(t);
    }
    return x;
  }();
  return f;
}

void plan_movel(benchmark::State& st) {
  const MovelFixture& f = movel_fixture();
  static kin::CartesianTrajectory tr;
  std::size_t i = 0;
  for (auto _ : st) {
    const std::size_t k = i++ & 63;
    const auto r = kin::plan_movel(f.chain, f.q0[k], f.target[k], {}, {}, f.ik(), tr);
    benchmark::DoNotOptimize(r);
  }
}
BENCHMARK(plan_movel)->Name("plan/movel/servoarm")->Unit(benchmark::kMicrosecond);

void sample_movel(benchmark::State& st, bool ik) {
  const MovelFixture& f = movel_fixture();
  static kin::CartesianTrajectory tr;
  kin::plan_movel(f.chain, f.q0[0], f.target[0], {}, {}, f.ik(), tr);
  std::vector<double> ts(kInputs);
  std::mt19937_64 g(8);
  for (double& t : ts) t = std::uniform_real_distribution<double>(0, tr.duration)(g);
  kin::JointVector q(6), qd(6), qdd(6);
  std::size_t i = 0;
  for (auto _ : st) {
    const double t = ts[i++ & (kInputs - 1)];
    if (ik)
      tr.sample_ik(t, q, qd, qdd);
    else
      tr.sample_precomputed(t, q, qd, qdd);
    benchmark::DoNotOptimize(q);
  }
}
BENCHMARK_CAPTURE(sample_movel, ik, true)->Name("sample/movel_ik/servoarm");
BENCHMARK_CAPTURE(sample_movel, pre, false)->Name("sample/movel_pre/servoarm");

}  // namespace
