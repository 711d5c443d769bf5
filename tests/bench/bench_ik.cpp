// Inverse kinematics: closed form (all solutions) and the numerical solver,
// against Orocos KDL's ChainIkSolverPos_NR_JL and ChainIkSolverPos_LMA on the
// same targets and starts, same run.
//   ik/<model>/servoarm            every closed-form solution of one pose
//   ik_class/puma560/<class>/servoarm  the same on PUMA pose classes near the
//                                  wrist singularity and out of reach (worst case)
//   ik_numeric/<model>/servoarm    DLS/LM from a random start (counter: success)
//   ik_numeric/<model>/kdl_nr_jl   KDL Newton-Raphson with joint limits
//   ik_numeric/<model>/kdl_lma     KDL Levenberg-Marquardt (no limits; success
//                                  counts only results within the limits)
// Success: |dp| <= 1e-6 m, |drot| <= 1e-6 rad, within the limits.
#include <benchmark/benchmark.h>

#include <random>
#include <string>
#include <vector>

#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/kinematics/ik.hpp"
#include "servoarm/kinematics/orientation.hpp"

#ifdef SERVOARM_WITH_KDL
#include <kdl/chainfksolverpos_recursive.hpp>
#include <kdl/chainiksolverpos_lma.hpp>
#include <kdl/chainiksolverpos_nr_jl.hpp>
#include <kdl/chainiksolvervel_pinv.hpp>

#include "../support/kdl_reference.hpp"
#endif

namespace {
using namespace servoarm;

constexpr int kTargets = 256;

struct IkFixture {
  kin::Chain chain;
  kin::IkModel model;
  std::vector<kin::Pose> targets;
  std::vector<kin::JointVector> starts;
};

kin::JointVector random_joints(const kin::Chain& c, std::mt19937_64& rng) {
  kin::JointVector q(c.n_joints);
  for (int j = 0; j < c.n_joints; ++j) {
    const auto& row = c.joint(j);
    const double lo = std::isfinite(row.lower) ? row.lower : -M_PI;
    const double hi = std::isfinite(row.upper) ? row.upper : M_PI;
    q[j] = std::uniform_real_distribution<double>(lo, hi)(rng);
  }
  return q;
}

const IkFixture& ik_fixture(const char* name) {
  static std::vector<std::pair<std::string, IkFixture>> cache;
  for (auto& [n, f] : cache)
    if (n == name) return f;
  IkFixture f;
  const auto r = kin::load_robot(name);
  if (!r.ok) std::abort();
  f.chain = r.chain;
  kin::ik_prepare(f.chain, f.model);
  std::mt19937_64 rng(2026);
  for (int i = 0; i < kTargets; ++i) {
    kin::Pose T;
    kin::forward(f.chain, random_joints(f.chain, rng), T);
    f.targets.push_back(T);
    f.starts.push_back(random_joints(f.chain, rng));
  }
  cache.emplace_back(name, std::move(f));
  return cache.back().second;
}

bool success(const kin::Chain& c, const kin::JointVector& q, const kin::Pose& T) {
  kin::Pose X;
  if (kin::forward(c, q, X) != kin::Status::ok) return false;
  return (X.translation() - T.translation()).norm() <= 1e-6 &&
         kin::rotation_error(X.linear(), T.linear()).norm() <= 1e-6 && kin::within_limits(c, q, 1e-9);
}

void ik_closed(benchmark::State& st, const char* name) {
  const IkFixture& f = ik_fixture(name);
  kin::IkResult r;
  std::size_t i = 0;
  long sols = 0, n = 0;
  for (auto _ : st) {
    kin::ik_solve_all(f.model, f.targets[i++ % kTargets], nullptr, r);
    benchmark::DoNotOptimize(r);
    sols += r.count;
    ++n;
  }
  st.counters["solutions"] = static_cast<double>(sols) / static_cast<double>(n);
}

// Pose classes of the PUMA for the worst case of the closed form: 256 poses
// each, from random in-limit joints with theta5 forced (0 with a random
// reference: the singular family; 1e-9: the two wrist roots do not merge
// and the second is computed, not flipped; 1e-5: near-singular), or the
// position scaled out of reach.
enum class PoseClass { theta5_zero, theta5_1e9, theta5_1e5, unreachable };

void ik_class(benchmark::State& st, PoseClass cls) {
  const IkFixture& f = ik_fixture("puma560");
  std::mt19937_64 rng(7 + static_cast<int>(cls));
  std::vector<kin::Pose> targets;
  std::vector<kin::JointVector> refs;
  for (int k = 0; k < kTargets; ++k) {
    kin::JointVector q = random_joints(f.chain, rng);
    if (cls == PoseClass::theta5_zero) q[4] = 0;
    if (cls == PoseClass::theta5_1e9) q[4] = 1e-9;
    if (cls == PoseClass::theta5_1e5) q[4] = 1e-5;
    kin::Pose T;
    kin::forward(f.chain, q, T);
    if (cls == PoseClass::unreachable) T.translation() *= 3.0;
    targets.push_back(T);
    refs.push_back(random_joints(f.chain, rng));
  }
  kin::IkResult r;
  std::size_t i = 0;
  long sols = 0, n = 0;
  for (auto _ : st) {
    const std::size_t k = i++ % kTargets;
    kin::ik_solve_all(f.model, targets[k], cls == PoseClass::theta5_zero ? &refs[k] : nullptr, r);
    benchmark::DoNotOptimize(r);
    sols += r.count;
    ++n;
  }
  st.counters["solutions"] = static_cast<double>(sols) / static_cast<double>(n);
}

void ik_numeric_servoarm(benchmark::State& st, const char* name) {
  const IkFixture& f = ik_fixture(name);
  kin::IkNumericOptions o;
  kin::IkNumericResult r;
  std::size_t i = 0;
  long ok = 0, n = 0, it = 0;
  for (auto _ : st) {
    const std::size_t k = i++ % kTargets;
    kin::ik_numeric(f.chain, f.targets[k], f.starts[k], o, r);
    benchmark::DoNotOptimize(r);
    ok += success(f.chain, r.q, f.targets[k]) ? 1 : 0;
    it += r.iterations;
    ++n;
  }
  st.counters["success"] = static_cast<double>(ok) / static_cast<double>(n);
  st.counters["iterations"] = static_cast<double>(it) / static_cast<double>(n);
}

#ifdef SERVOARM_WITH_KDL
struct KdlSolvers {
  KDL::Chain chain;
  KDL::JntArray qmin, qmax;
  explicit KdlSolvers(const kin::Chain& c) : chain(test::to_kdl(c)), qmin(static_cast<unsigned>(c.n_joints)), qmax(static_cast<unsigned>(c.n_joints)) {
    for (int j = 0; j < c.n_joints; ++j) {
      qmin(static_cast<unsigned>(j)) = c.joint(j).lower;
      qmax(static_cast<unsigned>(j)) = c.joint(j).upper;
    }
  }
};

template <bool kLma>
void ik_numeric_kdl(benchmark::State& st, const char* name) {
  const IkFixture& f = ik_fixture(name);
  KdlSolvers s(f.chain);
  KDL::ChainFkSolverPos_recursive fk(s.chain);
  KDL::ChainIkSolverVel_pinv vel(s.chain);
  KDL::ChainIkSolverPos_NR_JL nr(s.chain, s.qmin, s.qmax, fk, vel, 500, 1e-9);
  KDL::ChainIkSolverPos_LMA lma(s.chain, 1e-9, 500);
  std::vector<KDL::Frame> targets;
  std::vector<KDL::JntArray> starts;
  for (int k = 0; k < kTargets; ++k) {
    targets.push_back(test::to_kdl(f.targets[static_cast<std::size_t>(k)]));
    starts.push_back(test::to_kdl(f.starts[static_cast<std::size_t>(k)]));
  }
  KDL::JntArray out(static_cast<unsigned>(f.chain.n_joints));
  std::size_t i = 0;
  long ok = 0, n = 0;
  kin::JointVector q(f.chain.n_joints);
  for (auto _ : st) {
    const std::size_t k = i++ % kTargets;
    if constexpr (kLma) lma.CartToJnt(starts[k], targets[k], out);
    else nr.CartToJnt(starts[k], targets[k], out);
    benchmark::DoNotOptimize(out);
    for (int j = 0; j < f.chain.n_joints; ++j) q[j] = out(static_cast<unsigned>(j));
    bool finite = true;
    for (int j = 0; j < f.chain.n_joints; ++j) finite = finite && std::isfinite(q[j]);
    ok += finite && success(f.chain, q, f.targets[k]) ? 1 : 0;
    ++n;
  }
  st.counters["success"] = static_cast<double>(ok) / static_cast<double>(n);
}
#endif

const char* const kClosed[] = {"puma560", "puma560_craig", "stanford", "cylindrical_rpp_rrr", "ist6",
                               "rr_planar", "rrr_planar", "rlr_planar", "trr", "trl_r", "vvl_r"};
const char* const kNumeric[] = {"puma560", "stanford", "ist6", "vvr_vr"};

[[maybe_unused]] const bool registered = [] {
  for (const char* m : kClosed)
    benchmark::RegisterBenchmark((std::string("ik/") + m + "/servoarm").c_str(), ik_closed, m);
  benchmark::RegisterBenchmark("ik_class/puma560/theta5_zero/servoarm", ik_class, PoseClass::theta5_zero);
  benchmark::RegisterBenchmark("ik_class/puma560/theta5_1e-9/servoarm", ik_class, PoseClass::theta5_1e9);
  benchmark::RegisterBenchmark("ik_class/puma560/theta5_1e-5/servoarm", ik_class, PoseClass::theta5_1e5);
  benchmark::RegisterBenchmark("ik_class/puma560/unreachable/servoarm", ik_class, PoseClass::unreachable);
  for (const char* m : kNumeric) {
    benchmark::RegisterBenchmark((std::string("ik_numeric/") + m + "/servoarm").c_str(), ik_numeric_servoarm, m);
#ifdef SERVOARM_WITH_KDL
    benchmark::RegisterBenchmark((std::string("ik_numeric/") + m + "/kdl_nr_jl").c_str(), ik_numeric_kdl<false>, m);
    benchmark::RegisterBenchmark((std::string("ik_numeric/") + m + "/kdl_lma").c_str(), ik_numeric_kdl<true>, m);
#endif
  }
  return true;
}();

}  // namespace
