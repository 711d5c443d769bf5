// SPDX-License-Identifier: Apache-2.0
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
//   ik/<opw|ur model>/servoarm     every solution (verified) of 1 024 poses
//   ik/<opw model>/general_path    the same arm forced onto the degree-8 path
//                                  (what it took before the OPW closed form)
//   ik/<ur model>/numeric_near     what a UR arm had before: one numerical
//                                  solution from a start 0.05 rad away
//   ik/abb_irb2400_twist/servoarm  near-miss (0.01 deg twist of axes 2, 3): the
//                                  general path it takes, with ist6 forced onto it
//   ik/ist6/general_path_eigen     the general path with the companion matrix's
//   ik/abb_irb2400_twist/eigen_roots  eigenvalues only (before the root isolation)
//   ik_class/ist6/<class>/general_path[_eigen]  its worst cases: theta5 = 0, 1e-9,
//                                  elbow stretched (double roots), unreachable
//   ik_reduced/<model>/servoarm    the reduced arms, 1 024 poses, all solutions
//   ik_reduced/<model>/path_3d     the 3-D cheap paths alone (what ik_solve_all ran
//                                  before the 2-D closed forms; without its input checks)
//   ik_reduced/<model>/chain_path  the same verified through the chain's FK (before that)
//   ik_class/<model>/<class>/servoarm  per-class worst cases of the OPW and UR
//                                  arms: theta5 = 0, 1e-9, 1e-5, elbow stretched,
//                                  shoulder singular, unreachable
// Success: |dp| <= 1e-6 m, |drot| <= 1e-6 rad, within the limits.
#include <benchmark/benchmark.h>

#include <random>
#include <string>
#include <vector>

#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/kinematics/ik.hpp"
#include "servoarm/kinematics/orientation.hpp"
#include "../../kinematics/src/ik/ik_detail.hpp"

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

// ---------------------------------------------------------------------------
// Issue 19: the OPW and UR classes, 1 024 poses each.
// ---------------------------------------------------------------------------
constexpr int kPoses19 = 1024;

enum class Path19 { closed, general, general_eigen, numeric_near };

struct Fixture19 {
  kin::Chain chain;
  kin::IkModel model;
  std::vector<kin::Pose> targets;
  std::vector<kin::JointVector> qs, refs;
};

// The model of `name`; twist: axes 2 and 3 0.01 deg out of parallel.
kin::Chain chain19(const char* name, bool twist) {
  const auto r = kin::load_robot(name);
  if (!r.ok) std::abort();
  if (!twist) return r.chain;
  kin::Chain t = r.chain;
  t.n_rows = 0;
  t.n_joints = 0;
  for (int i = 0; i < r.chain.n_rows; ++i) {
    kin::DhRow row = r.chain.rows[static_cast<std::size_t>(i)];
    if (i == 1) row.alpha += 0.01 * M_PI / 180;
    kin::add_row(t, row);
  }
  return t;
}

// Motion of joint 1 and the key point (OPW: wrist centre, UR: where axes 5
// and 6 meet) in the frame after the J1 motion.
Eigen::Vector3d key_point_j1(const kin::IkModel& m, const kin::JointVector& q) {
  const auto& d = kin::detail::solver_data(m);
  kin::Pose T;
  kin::forward(m.chain, q, T);
  const Eigen::Vector3d p0 = d.C[0].inverse() * (T * m.w_tool);
  const double m1 = d.dir[0] * q[0];
  return Eigen::AngleAxisd(-m1, Eigen::Vector3d::UnitZ()) * p0;
}

// q with joint 2 moved so that the key point lies in the plane of axes 1 and
// 2 (shoulder singular: the two joint-1 roots merge); false if no sign change.
bool make_shoulder_singular(const kin::IkModel& m, kin::JointVector& q) {
  const Eigen::Vector3d sd = kin::detail::solver_data(m).shoulder_dir;
  auto g = [&](double q2) {
    kin::JointVector x = q;
    x[1] = q2;
    return sd.dot(key_point_j1(m, x));
  };
  const double lo = m.chain.joint(1).lower, hi = m.chain.joint(1).upper;
  double a = lo, ga = g(a);
  for (int i = 1; i <= 64; ++i) {
    double b = lo + (hi - lo) * i / 64.0;
    const double gb = g(b);
    if ((ga < 0) != (gb < 0)) {
      for (int it = 0; it < 80; ++it) {
        const double c = 0.5 * (a + b), gc = g(c);
        if ((ga < 0) != (gc < 0)) b = c;
        else { a = c; ga = gc; }
      }
      q[1] = 0.5 * (a + b);
      return true;
    }
    a = b;
    ga = gb;
  }
  return false;
}

enum class Class19 { random, theta5_zero, theta5_1e9, theta5_1e5, elbow_stretched, shoulder_singular, unreachable };

// Classes where a joint is free (theta5 = 0; the shoulder singularity of an
// arm without lateral offset: the wrist centre on axis 1): solved with a
// random reference joint vector (the free joint keeps it).
bool family(Class19 c) { return c == Class19::theta5_zero || c == Class19::shoulder_singular; }

const Fixture19& fixture19(const char* name, bool twist, Class19 cls) {
  static std::vector<std::pair<std::string, Fixture19>> cache;
  const std::string key = std::string(name) + (twist ? "+twist" : "") + std::to_string(static_cast<int>(cls));
  for (auto& [n, f] : cache)
    if (n == key) return f;
  Fixture19 f;
  f.chain = chain19(name, twist);
  kin::ik_prepare(f.chain, f.model);
  const auto& d = kin::detail::solver_data(f.model);
  std::mt19937_64 rng(1900 + static_cast<int>(cls));
  while (static_cast<int>(f.targets.size()) < kPoses19) {
    kin::JointVector q = random_joints(f.chain, rng);
    if (cls == Class19::theta5_zero) q[4] = 0;
    if (cls == Class19::theta5_1e9) q[4] = 1e-9;
    if (cls == Class19::theta5_1e5) q[4] = 1e-5;
    if (cls == Class19::elbow_stretched)  // maximum distance from axis 2: m3 = atan2(G2, G1)
      q[2] = std::atan2(d.g_par[2], d.g_par[1]) / d.dir[2];
    if (cls == Class19::shoulder_singular && !make_shoulder_singular(f.model, q)) continue;
    kin::Pose T;
    kin::forward(f.chain, q, T);
    if (cls == Class19::unreachable) T.translation() *= 3.0;
    f.targets.push_back(T);
    f.qs.push_back(q);
    kin::JointVector near = q;
    for (int j = 0; j < near.size(); ++j) near[j] += 0.05;
    f.refs.push_back(family(cls) ? random_joints(f.chain, rng) : near);
  }
  cache.emplace_back(key, std::move(f));
  return cache.back().second;
}

void ik19(benchmark::State& st, const char* name, bool twist, Path19 path, Class19 cls) {
  const Fixture19& f0 = fixture19(name, twist, cls);
  kin::IkModel model = f0.model;
  if (path == Path19::general || path == Path19::general_eigen) {  // the degree-8 resultant, as before the OPW case
    kin::detail::solver_data(model).par23 = false;
    model.method = kin::IkMethod::spherical_general;
  }
  if (path == Path19::general_eigen) kin::detail::solver_data(model).eigen_roots = true;  // companion matrix only
  kin::IkResult r;
  kin::JointVector out;
  std::size_t i = 0;
  long sols = 0, n = 0, found = 0;
  for (auto _ : st) {
    const std::size_t k = i++ % kPoses19;
    if (path == Path19::numeric_near) {
      const kin::Status s = kin::detail::ik_nearest_numeric(f0.chain, f0.targets[k], f0.refs[k], out);
      benchmark::DoNotOptimize(out);
      sols += s == kin::Status::ok ? 1 : 0;
    } else {
      kin::ik_solve_all(model, f0.targets[k], family(cls) ? &f0.refs[k] : nullptr, r);
      benchmark::DoNotOptimize(r);
      sols += r.count;
    }
    ++n;
  }
  // Outside the timing: how often the original configuration is among them.
  // Singular families (a joint free): the original as the reference.
  if (path != Path19::numeric_near && cls != Class19::unreachable) {
    for (int k = 0; k < kPoses19; ++k) {
      kin::ik_solve_all(model, f0.targets[static_cast<std::size_t>(k)],
                        family(cls) ? &f0.qs[static_cast<std::size_t>(k)] : nullptr, r);
      for (int s = 0; s < r.count; ++s) {
        double g = 0;
        for (int j = 0; j < 6; ++j)
          g = std::max(g, std::abs(kin::wrap_pi(r.solutions[static_cast<std::size_t>(s)].q[j] - f0.qs[static_cast<std::size_t>(k)][j])));
        if (g < 1e-6) {
          ++found;
          break;
        }
      }
    }
    st.counters["original_found"] = static_cast<double>(found) / kPoses19;
  }
  st.counters["solutions"] = static_cast<double>(sols) / static_cast<double>(n);
}

// Issue 19, reduced arms (<= 100 ns for all their solutions): 1 024 poses from random
// in-limit joints; servoarm = ik_solve_all (the 2-D closed forms, verified by their own
// forward map), path_3d = the 3-D cheap paths (verified through the decomposition's
// products: ik_solve_all before the 2-D forms), chain_path = the same candidates each
// through the chain's FK and Jacobian (detail::solve_reduced_slow; not planar_2r).
enum class Reduced { solve_all, path_3d, chain_path };
void ik_reduced(benchmark::State& st, const char* name, Reduced path) {
  const Fixture19& f = fixture19(name, false, Class19::random);
  kin::IkResult r;
  std::size_t i = 0;
  long sols = 0, n = 0;
  for (auto _ : st) {
    const kin::Pose& T = f.targets[i++ % kPoses19];
    if (path == Reduced::chain_path) {
      r.count = 0;
      kin::detail::solve_reduced_slow(f.model, T, nullptr, r);
    } else if (path == Reduced::path_3d) {
      r.count = 0;
      kin::detail::solve_reduced_3d(f.model, T, nullptr, r);
    } else {
      kin::ik_solve_all(f.model, T, nullptr, r);
    }
    benchmark::DoNotOptimize(r);
    sols += r.count;
    ++n;
  }
  st.counters["solutions"] = static_cast<double>(sols) / static_cast<double>(n);
}

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
  for (const char* m : {"abb_irb2400", "kuka_kr6_r700", "ur5e", "ur10e"}) {
    const bool opw = m[0] != 'u';
    benchmark::RegisterBenchmark((std::string("ik/") + m + "/servoarm").c_str(), ik19, m, false, Path19::closed,
                                 Class19::random);
    if (opw)
      benchmark::RegisterBenchmark((std::string("ik/") + m + "/general_path").c_str(), ik19, m, false, Path19::general,
                                   Class19::random);
    else
      benchmark::RegisterBenchmark((std::string("ik/") + m + "/numeric_near").c_str(), ik19, m, false,
                                   Path19::numeric_near, Class19::random);
  }
  for (const char* m : {"rr_planar", "rrr_planar", "rlr_planar", "trr", "trl_r", "vvl_r"}) {
    benchmark::RegisterBenchmark((std::string("ik_reduced/") + m + "/servoarm").c_str(), ik_reduced, m,
                                 Reduced::solve_all);
    benchmark::RegisterBenchmark((std::string("ik_reduced/") + m + "/path_3d").c_str(), ik_reduced, m, Reduced::path_3d);
    if (std::string(m) != "rr_planar")
      benchmark::RegisterBenchmark((std::string("ik_reduced/") + m + "/chain_path").c_str(), ik_reduced, m,
                                   Reduced::chain_path);
  }
  benchmark::RegisterBenchmark("ik/ist6/general_path", ik19, "ist6", false, Path19::general, Class19::random);
  benchmark::RegisterBenchmark("ik/ist6/general_path_eigen", ik19, "ist6", false, Path19::general_eigen,
                               Class19::random);
  benchmark::RegisterBenchmark("ik/abb_irb2400_twist/servoarm", ik19, "abb_irb2400", true, Path19::closed,
                               Class19::random);
  benchmark::RegisterBenchmark("ik/abb_irb2400_twist/eigen_roots", ik19, "abb_irb2400", true, Path19::general_eigen,
                               Class19::random);
  {  // the general path's worst cases (ist6 forced onto it), isolation and companion matrix
    const std::pair<const char*, Class19> classes[] = {{"theta5_zero", Class19::theta5_zero},
                                                       {"theta5_1e-9", Class19::theta5_1e9},
                                                       {"elbow_stretched", Class19::elbow_stretched},
                                                       {"unreachable", Class19::unreachable}};
    for (const auto& [cn, cls] : classes) {
      benchmark::RegisterBenchmark((std::string("ik_class/ist6/") + cn + "/general_path").c_str(), ik19, "ist6", false,
                                   Path19::general, cls);
      benchmark::RegisterBenchmark((std::string("ik_class/ist6/") + cn + "/general_path_eigen").c_str(), ik19, "ist6",
                                   false, Path19::general_eigen, cls);
    }
  }
  for (const char* m : {"abb_irb2400", "ur5e"}) {
    const std::pair<const char*, Class19> classes[] = {{"theta5_zero", Class19::theta5_zero},
                                                       {"theta5_1e-9", Class19::theta5_1e9},
                                                       {"theta5_1e-5", Class19::theta5_1e5},
                                                       {"elbow_stretched", Class19::elbow_stretched},
                                                       {"shoulder_singular", Class19::shoulder_singular},
                                                       {"unreachable", Class19::unreachable}};
    for (const auto& [cn, cls] : classes)
      benchmark::RegisterBenchmark((std::string("ik_class/") + m + "/" + cn + "/servoarm").c_str(), ik19, m, false,
                                   Path19::closed, cls);
  }
  benchmark::RegisterBenchmark("ik_numeric/ur5e/servoarm", ik_numeric_servoarm, "ur5e");
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
