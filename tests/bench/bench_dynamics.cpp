// SPDX-License-Identifier: Apache-2.0
// Dynamics: servoarm against Orocos KDL on the same states, same run.
// Names: rnea/<model>/{servoarm,kdl} (ChainIdSolver_RNE), mass_matrix/<model>/...
// (ChainDynParam::JntToMass), gravity/<model>/... (ChainDynParam::JntToGravity).
// Models: every built-in with inertial data (today puma560, AKB 1986).
#include <benchmark/benchmark.h>

#include <random>
#include <string>
#include <vector>

#include "servoarm/kinematics/description.hpp"
#include "servoarm/kinematics/dynamics.hpp"

#ifdef SERVOARM_WITH_KDL
#include <kdl/chaindynparam.hpp>
#include <kdl/chainidsolver_recursive_newton_euler.hpp>
#include <kdl/jntspaceinertiamatrix.hpp>

#include "../support/kdl_reference.hpp"
#endif

namespace {
using namespace servoarm;

constexpr int kStates = 1024;

struct DynFixture {
  kin::Chain chain;
  std::vector<kin::JointVector> q, qd, qdd;
};

const DynFixture& dyn_fixture(const char* model) {
  static std::vector<std::pair<std::string, DynFixture>> cache;
  for (auto& [n, f] : cache)
    if (n == model) return f;
  DynFixture f;
  const auto r = kin::load_robot(model);
  if (!r.ok) std::abort();
  f.chain = r.chain;
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  const int n = f.chain.n_joints;
  for (int i = 0; i < kStates; ++i) {
    kin::JointVector q(n), qd(n), qdd(n);
    for (int j = 0; j < n; ++j) q[j] = M_PI * u(rng), qd[j] = 2 * u(rng), qdd[j] = 5 * u(rng);
    f.q.push_back(q), f.qd.push_back(qd), f.qdd.push_back(qdd);
  }
  cache.emplace_back(model, std::move(f));
  return cache.back().second;
}

void rnea_servoarm(benchmark::State& st, const char* model) {
  const DynFixture& f = dyn_fixture(model);
  kin::JointVector tau;
  std::size_t i = 0;
  for (auto _ : st) {
    const std::size_t k = i++ & (kStates - 1);
    kin::inverse_dynamics(f.chain, f.q[k], f.qd[k], f.qdd[k], tau);
    benchmark::DoNotOptimize(tau);
  }
}

void mass_servoarm(benchmark::State& st, const char* model) {
  const DynFixture& f = dyn_fixture(model);
  kin::MassMatrix M;
  std::size_t i = 0;
  for (auto _ : st) {
    kin::mass_matrix(f.chain, f.q[i++ & (kStates - 1)], M);
    benchmark::DoNotOptimize(M);
  }
}

void gravity_servoarm(benchmark::State& st, const char* model) {
  const DynFixture& f = dyn_fixture(model);
  kin::JointVector g;
  std::size_t i = 0;
  for (auto _ : st) {
    kin::gravity_torques(f.chain, f.q[i++ & (kStates - 1)], g);
    benchmark::DoNotOptimize(g);
  }
}

void fd_servoarm(benchmark::State& st, const char* model) {
  const DynFixture& f = dyn_fixture(model);
  kin::JointVector qdd;
  std::size_t i = 0;
  for (auto _ : st) {
    const std::size_t k = i++ & (kStates - 1);
    kin::forward_dynamics(f.chain, f.q[k], f.qd[k], f.qdd[k], qdd);
    benchmark::DoNotOptimize(qdd);
  }
}

#ifdef SERVOARM_WITH_KDL
KDL::RigidBodyInertia kdl_inertia(const kin::LinkInertial& L) {
  return KDL::RigidBodyInertia(
      L.mass, KDL::Vector(L.com[0], L.com[1], L.com[2]),
      KDL::RotationalInertia(L.inertia[0], L.inertia[1], L.inertia[2], L.inertia[3], L.inertia[4], L.inertia[5]));
}

// The chain of test_dynamics.cpp: each body on the segment whose tip is its DH frame,
// the reflected rotor inertia as the joint's inertia.
KDL::Chain to_kdl_dyn(const kin::Chain& chain) {
  using kin::JointType;
  KDL::Chain out;
  if (!chain.base.matrix().isIdentity(0)) out.addSegment(KDL::Segment(KDL::Joint(KDL::Joint::None), test::to_kdl(chain.base)));
  for (int i = 0; i < chain.n_rows; ++i) {
    const kin::DhRow& r = chain.rows[static_cast<std::size_t>(i)];
    const kin::LinkInertial& L = chain.inertial[static_cast<std::size_t>(i)];
    const KDL::Joint::JointType jt = r.type == JointType::revolute    ? KDL::Joint::RotZ
                                     : r.type == JointType::prismatic ? KDL::Joint::TransZ
                                                                      : KDL::Joint::None;
    const KDL::Joint joint = jt == KDL::Joint::None
                                 ? KDL::Joint(KDL::Joint::None)
                                 : KDL::Joint(jt, r.direction, 0.0, L.gear_ratio * L.gear_ratio * L.rotor_inertia);
    if (chain.convention == kin::Convention::standard) {
      out.addSegment(KDL::Segment(joint, KDL::Frame::DH(r.a, r.alpha, r.d, r.theta), kdl_inertia(L)));
    } else {
      out.addSegment(KDL::Segment(KDL::Joint(KDL::Joint::None),
                                  KDL::Frame(KDL::Rotation::RotX(r.alpha), KDL::Vector(r.a, 0, 0))));
      out.addSegment(KDL::Segment(joint, KDL::Frame(KDL::Rotation::RotZ(r.theta), KDL::Vector(0, 0, r.d)),
                                  kdl_inertia(L)));
    }
  }
  return out;
}

struct KdlStates {
  std::vector<KDL::JntArray> q, qd, qdd;
};
KdlStates kdl_states(const DynFixture& f) {
  KdlStates s;
  for (int i = 0; i < kStates; ++i) {
    s.q.push_back(test::to_kdl(f.q[static_cast<std::size_t>(i)]));
    s.qd.push_back(test::to_kdl(f.qd[static_cast<std::size_t>(i)]));
    s.qdd.push_back(test::to_kdl(f.qdd[static_cast<std::size_t>(i)]));
  }
  return s;
}
KDL::Vector kdl_gravity(const kin::Chain& c) { return KDL::Vector(c.gravity[0], c.gravity[1], c.gravity[2]); }

void rnea_kdl(benchmark::State& st, const char* model) {
  const DynFixture& f = dyn_fixture(model);
  const KDL::Chain kc = to_kdl_dyn(f.chain);
  KDL::ChainIdSolver_RNE rne(kc, kdl_gravity(f.chain));
  const KdlStates s = kdl_states(f);
  KDL::JntArray tau(kc.getNrOfJoints());
  KDL::Wrenches fext(kc.getNrOfSegments(), KDL::Wrench::Zero());
  std::size_t i = 0;
  for (auto _ : st) {
    const std::size_t k = i++ & (kStates - 1);
    rne.CartToJnt(s.q[k], s.qd[k], s.qdd[k], fext, tau);
    benchmark::DoNotOptimize(tau.data);
  }
}

void mass_kdl(benchmark::State& st, const char* model) {
  const DynFixture& f = dyn_fixture(model);
  const KDL::Chain kc = to_kdl_dyn(f.chain);
  KDL::ChainDynParam dyn(kc, kdl_gravity(f.chain));
  const KdlStates s = kdl_states(f);
  KDL::JntSpaceInertiaMatrix M(kc.getNrOfJoints());
  std::size_t i = 0;
  for (auto _ : st) {
    dyn.JntToMass(s.q[i++ & (kStates - 1)], M);
    benchmark::DoNotOptimize(M.data);
  }
}

void gravity_kdl(benchmark::State& st, const char* model) {
  const DynFixture& f = dyn_fixture(model);
  const KDL::Chain kc = to_kdl_dyn(f.chain);
  KDL::ChainDynParam dyn(kc, kdl_gravity(f.chain));
  const KdlStates s = kdl_states(f);
  KDL::JntArray g(kc.getNrOfJoints());
  std::size_t i = 0;
  for (auto _ : st) {
    dyn.JntToGravity(s.q[i++ & (kStates - 1)], g);
    benchmark::DoNotOptimize(g.data);
  }
}
#endif

const int registered = [] {
  for (const auto& m : kin::builtin_models()) {
    const auto r = kin::load_robot(m.name);
    if (!r.ok || !r.chain.has_inertial) continue;
    const std::string n = m.name;
    benchmark::RegisterBenchmark(("rnea/" + n + "/servoarm").c_str(), rnea_servoarm, m.name);
#ifdef SERVOARM_WITH_KDL
    benchmark::RegisterBenchmark(("rnea/" + n + "/kdl").c_str(), rnea_kdl, m.name);
#endif
    benchmark::RegisterBenchmark(("mass_matrix/" + n + "/servoarm").c_str(), mass_servoarm, m.name);
#ifdef SERVOARM_WITH_KDL
    benchmark::RegisterBenchmark(("mass_matrix/" + n + "/kdl").c_str(), mass_kdl, m.name);
#endif
    benchmark::RegisterBenchmark(("gravity/" + n + "/servoarm").c_str(), gravity_servoarm, m.name);
#ifdef SERVOARM_WITH_KDL
    benchmark::RegisterBenchmark(("gravity/" + n + "/kdl").c_str(), gravity_kdl, m.name);
#endif
    benchmark::RegisterBenchmark(("forward_dynamics/" + n + "/servoarm").c_str(), fd_servoarm, m.name);
  }
  return 0;
}();

}  // namespace
