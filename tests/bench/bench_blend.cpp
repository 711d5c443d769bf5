// SPDX-License-Identifier: Apache-2.0
// Blending (blend.hpp): the cost of appending one blended segment to a queue
// that is executing, and of one sample.
//   plan/blend_append6/servoarm   append one random 6-joint waypoint with a blend
//                                 tolerance (1-D profile x 3 candidate shares, the
//                                 overlap search with its exact limit checks);
//                                 the queue is retired as it goes, t_earliest = the
//                                 time 10 ms after the previous segment's start
//   plan/blend_append6_exact/servoarm  same with tolerance 0 (exact stops): the
//                                 cost of one segment without the search
//   sample/blend6/servoarm        one sample (pos, vel, acc) of the queue
//   plan/blend_path_line/servoarm  append one line of the #3773 zigzag (PUMA 560, 10.4 mm
//                                 at 250 mm/s, 147 deg turns, 1 mm tolerance) to a
//                                 PathBlendQueue (blend_path.hpp): plan_movel (IK at 257
//                                 knots) and the overlap search, each check sampling the
//                                 window at 1 kHz with one IK per sample
//   plan/blend_path_line_exact/servoarm  the same lines with exact stops (plan_movel only)
// Counters: checks = exact limit checks per append (mean); samples = sampled IK solves per
// append (blend_path).
#include <benchmark/benchmark.h>

#include <memory>
#include <random>
#include <vector>

#include "servoarm/kinematics/blend.hpp"
#include "servoarm/kinematics/blend_path.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/kinematics/ik.hpp"
#include "servoarm/kinematics/motion_ik.hpp"

namespace {
using namespace servoarm;

constexpr int kInputs = 1024;

kin::JointLimits blend_limits() {
  kin::JointLimits l;
  l.n = 6;
  for (int i = 0; i < 6; ++i) {
    const auto k = static_cast<std::size_t>(i);
    l.dyn[k] = i < 3 ? kin::JointDynamics{2.0, 8.0, 80.0} : kin::JointDynamics{3.0, 15.0, 150.0};
    l.lower[k] = -3.0;
    l.upper[k] = 3.0;
  }
  return l;
}

const std::vector<kin::JointVector>& waypoints() {
  static const std::vector<kin::JointVector> w = [] {
    std::mt19937_64 rng(99);
    std::uniform_real_distribution<double> u(-2.0, 2.0);
    std::vector<kin::JointVector> v;
    for (int k = 0; k < kInputs; ++k) {
      kin::JointVector q(6);
      for (int i = 0; i < 6; ++i) q[i] = u(rng);
      v.push_back(q);
    }
    return v;
  }();
  return w;
}

kin::JointBlendQueue<16> g_queue;

void append_bench(benchmark::State& state, double tol) {
  const auto& w = waypoints();
  g_queue.reset(blend_limits(), w[0]);
  std::size_t k = 1;
  double checks = 0, appends = 0;
  for (auto _ : state) {
    if (g_queue.size() >= 8) {
      // The RT thread has moved on: retire what has ended (not timed).
      state.PauseTiming();
      g_queue.retire(g_queue.at(g_queue.size() - 4).end());
      state.ResumeTiming();
    }
    const double t_earliest = g_queue.empty() ? 0.0 : g_queue.at(g_queue.size() - 1).start + 0.01;
    kin::BlendReport rep;
    const kin::BlendStatus s = g_queue.append(w[k], tol, t_earliest, &rep);
    benchmark::DoNotOptimize(s);
    checks += rep.checks;
    appends += 1;
    k = k + 1 < w.size() ? k + 1 : 1;
  }
  state.counters["checks"] = checks / std::max(appends, 1.0);
}

void BM_BlendAppend(benchmark::State& state) { append_bench(state, 0.3); }
BENCHMARK(BM_BlendAppend)->Name("plan/blend_append6/servoarm");

void BM_BlendAppendExact(benchmark::State& state) { append_bench(state, 0.0); }
BENCHMARK(BM_BlendAppendExact)->Name("plan/blend_append6_exact/servoarm");

void BM_BlendSample(benchmark::State& state) {
  const auto& w = waypoints();
  g_queue.reset(blend_limits(), w[0]);
  for (int k = 1; k < 12; ++k) g_queue.append(w[static_cast<std::size_t>(k)], 0.3);
  const double T = g_queue.end_time();
  kin::JointVector p, v, a;
  double t = 0;
  for (auto _ : state) {
    g_queue.sample(t, p, v, a);
    benchmark::DoNotOptimize(p.data());
    t += 0.000731;
    if (t > T) t = 0;
  }
}
BENCHMARK(BM_BlendSample)->Name("sample/blend6/servoarm");

struct PumaPath {
  kin::Chain chain;
  kin::IkModel model;
  kin::PathBlendConfig cfg;
  kin::JointVector q0;
  kin::Pose x0;
  PumaPath() {
    chain = kin::load_robot("puma560").chain;
    for (int i = 0; i < chain.n_joints; ++i) chain.joint(i).dynamics = kin::JointDynamics{2.0, 10.0, 100.0};
    kin::ik_prepare(chain, model);
    cfg.limits = kin::limits_from(chain);
    cfg.chain = &chain;
    cfg.ik = kin::IkSolver{&kin::ik_nearest_for_motion, &model};
    q0 = kin::JointVector(6);
    q0 << 0.2, -1.3, 0.4, 0.1, 0.9, 0.3;
    kin::forward(chain, q0, x0);
  }
};

void path_append_bench(benchmark::State& state, double tol) {
  static PumaPath P;
  static auto Q = std::make_unique<kin::PathBlendQueue<16>>();
  Q->reset(P.cfg, P.q0);
  kin::CartesianLimits cl;
  cl.linear_velocity = 0.25;
  int i = 0;
  double checks = 0, samples = 0, appends = 0;
  for (auto _ : state) {
    if (Q->size() >= 8 || i >= 40) {  // the RT thread has moved on / start the zigzag again (not timed)
      state.PauseTiming();
      if (i >= 40) {
        Q->reset(P.cfg, P.q0);
        i = 0;
      } else {
        Q->retire(Q->at(Q->size() - 3).end());
      }
      state.ResumeTiming();
    }
    ++i;
    kin::Pose x = P.x0;
    x.translation() += Eigen::Vector3d(0.003 * i, (i % 2 ? 0.01 : 0.0), 0.0);
    const double t_earliest = Q->size() ? Q->at(Q->size() - 1).start + 0.01 : 0.0;
    kin::PathBlendReport rep;
    benchmark::DoNotOptimize(Q->append_line(x, cl, kin::MovelOptions{}, tol, t_earliest, &rep));
    checks += rep.checks;
    samples += rep.samples;
    appends += 1;
  }
  state.counters["checks"] = checks / std::max(appends, 1.0);
  state.counters["samples"] = samples / std::max(appends, 1.0);
}

void BM_PathAppendLine(benchmark::State& state) { path_append_bench(state, 0.001); }
BENCHMARK(BM_PathAppendLine)->Name("plan/blend_path_line/servoarm")->Unit(benchmark::kMicrosecond);

void BM_PathAppendLineExact(benchmark::State& state) { path_append_bench(state, 0.0); }
BENCHMARK(BM_PathAppendLineExact)->Name("plan/blend_path_line_exact/servoarm")->Unit(benchmark::kMicrosecond);

}  // namespace
