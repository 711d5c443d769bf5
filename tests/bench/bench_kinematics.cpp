// SPDX-License-Identifier: Apache-2.0
// FK and Jacobian: servoarm against Orocos KDL on the same inputs, same run.
// Names: fk/<model>/servoarm vs fk/<model>/kdl, jacobian/<model>/...
#include <benchmark/benchmark.h>

#include <random>
#include <vector>

#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/description.hpp"

#ifdef SERVOARM_WITH_KDL
#include <kdl/chainfksolverpos_recursive.hpp>
#include <kdl/chainjnttojacsolver.hpp>

#include "../support/kdl_reference.hpp"
#endif

namespace {
using namespace servoarm;

constexpr int kInputs = 1024;

struct Fixture {
  kin::Chain chain;
  std::vector<kin::JointVector> qs;
};

const Fixture& fixture(const char* model) {
  static std::vector<std::pair<std::string, Fixture>> cache;
  for (auto& [n, f] : cache)
    if (n == model) return f;
  Fixture f;
  const auto r = kin::load_robot(model);
  if (!r.ok) std::abort();
  f.chain = r.chain;
  std::mt19937_64 rng(42);
  for (int i = 0; i < kInputs; ++i) {
    kin::JointVector q(f.chain.n_joints);
    for (int j = 0; j < f.chain.n_joints; ++j) {
      const auto& row = f.chain.joint(j);
      const double lo = std::isfinite(row.lower) ? row.lower : -M_PI;
      const double hi = std::isfinite(row.upper) ? row.upper : M_PI;
      q[j] = std::uniform_real_distribution<double>(lo, hi)(rng);
    }
    f.qs.push_back(q);
  }
  cache.emplace_back(model, std::move(f));
  return cache.back().second;
}

void fk_servoarm(benchmark::State& st, const char* model) {
  const Fixture& f = fixture(model);
  kin::Pose T;
  std::size_t i = 0;
  for (auto _ : st) {
    kin::forward(f.chain, f.qs[i++ & (kInputs - 1)], T);
    benchmark::DoNotOptimize(T);
  }
}

void jac_servoarm(benchmark::State& st, const char* model) {
  const Fixture& f = fixture(model);
  kin::Jacobian J;
  std::size_t i = 0;
  for (auto _ : st) {
    kin::jacobian(f.chain, f.qs[i++ & (kInputs - 1)], J);
    benchmark::DoNotOptimize(J);
  }
}

#ifdef SERVOARM_WITH_KDL
void fk_kdl(benchmark::State& st, const char* model) {
  const Fixture& f = fixture(model);
  KDL::Chain kc = test::to_kdl(f.chain);
  KDL::ChainFkSolverPos_recursive solver(kc);
  std::vector<KDL::JntArray> qs;
  for (const auto& q : f.qs) qs.push_back(test::to_kdl(q));
  KDL::Frame F;
  std::size_t i = 0;
  for (auto _ : st) {
    solver.JntToCart(qs[i++ & (kInputs - 1)], F);
    benchmark::DoNotOptimize(F);
  }
}

void jac_kdl(benchmark::State& st, const char* model) {
  const Fixture& f = fixture(model);
  KDL::Chain kc = test::to_kdl(f.chain);
  KDL::ChainJntToJacSolver solver(kc);
  std::vector<KDL::JntArray> qs;
  for (const auto& q : f.qs) qs.push_back(test::to_kdl(q));
  KDL::Jacobian J(kc.getNrOfJoints());
  std::size_t i = 0;
  for (auto _ : st) {
    solver.JntToJac(qs[i++ & (kInputs - 1)], J);
    benchmark::DoNotOptimize(J.data.data());
  }
}
#endif

int register_all() {
  for (const auto& m : kin::builtin_models()) {
    const std::string n = m.name;
    benchmark::RegisterBenchmark(("fk/" + n + "/servoarm").c_str(), fk_servoarm, m.name);
#ifdef SERVOARM_WITH_KDL
    benchmark::RegisterBenchmark(("fk/" + n + "/kdl").c_str(), fk_kdl, m.name);
#endif
    benchmark::RegisterBenchmark(("jacobian/" + n + "/servoarm").c_str(), jac_servoarm, m.name);
#ifdef SERVOARM_WITH_KDL
    benchmark::RegisterBenchmark(("jacobian/" + n + "/kdl").c_str(), jac_kdl, m.name);
#endif
  }
  return 0;
}
const int registered = register_all();

}  // namespace
