// SPDX-License-Identifier: Apache-2.0
// The one motion IK adapter, make_ik_solver(model, options) (motion_ik.hpp):
// with each option set it gives exactly (status and joints, bit for bit) what
// the adapter it replaces gave, on seeded sweeps of poses -- near seeds (how
// movel calls it: each knot seeded with the previous one), far seeds, and
// targets out of reach -- for puma560, stanford, rrr_planar, ist6 (closed
// forms, ist6 through the degree-8 path) and vvr_vr (no closed form: the
// numerical fallback). The old adapters are compared twice: the functions
// kept for the firmware (now wrappers of the adapter) and their bodies as
// they were before the adapter (written out below on the public API); and
// plan_movel through it plans and samples the same lines bit for bit. The
// adapter allocates nothing. This file and the library are built with
// EIGEN_NO_MALLOC. Last, IkModel (its solver data private since the split)
// is still a plain value.
#include <cstring>
#include <string>
#include <type_traits>

#include "servoarm/kinematics/ik.hpp"
#include "servoarm/kinematics/motion_ik.hpp"
#include "alloc_counter.hpp"
#include "kin_test_util.hpp"

using namespace servoarm;
using namespace servoarm::test;

namespace {

// The adapters as they were before make_ik_solver (ik_numeric.cpp and
// motion_ik.cpp of 2026-11-30).
kin::Status old_ik_nearest_fn(const kin::Chain& chain, const kin::Pose& target, const kin::JointVector& q_near,
                              kin::JointVector& q_out, void* ctx) {
  const auto* model = static_cast<const kin::IkModel*>(ctx);
  if (!model || model->chain.n_joints != chain.n_joints) return kin::Status::bad_input;
  return kin::ik_solve_nearest(*model, target, q_near, q_out);
}
kin::Status old_ik_nearest_for_motion(const kin::Chain& /*chain*/, const kin::Pose& target,
                                      const kin::JointVector& q_near, kin::JointVector& q_out, void* ctx) {
  if (!ctx) return kin::Status::bad_input;
  const kin::IkModel& model = *static_cast<const kin::IkModel*>(ctx);
  kin::IkChoice choice;
  choice.allow_out_of_limits = true;
  return kin::ik_solve_nearest(model, target, q_near, q_out, choice);
}

struct Case {
  const char* what;
  kin::IkSolverOptions options;
  kin::IkNearestFn kept;  ///< the function kept for the firmware
  kin::IkNearestFn old;   ///< its body before the adapter (nullptr: kept is the implementation itself)
  bool old_takes_model;
};

const Case kCases[] = {
    {"ik_nearest_fn: within limits, numeric fallback", {}, &kin::ik_nearest_fn, &old_ik_nearest_fn, true},
    {"ik_nearest_for_motion: out of limits allowed, numeric fallback", {true, true, kin::IkFallback::numeric},
     &kin::ik_nearest_for_motion, &old_ik_nearest_for_motion, true},
    {"ik_nearest_newton: no closed form, Newton", {false, false, kin::IkFallback::newton}, &kin::ik_nearest_newton,
     nullptr, false},
};

bool same(kin::Status sa, const kin::JointVector& a, kin::Status sb, const kin::JointVector& b) {
  if (sa != sb) return false;
  if (!kin::is_ok(sa)) return true;  // q_out is only meaningful on success
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), sizeof(double) * static_cast<std::size_t>(a.size())) == 0;
}

// Poses of one sweep: FK of random in-limit joints; the seed near them
// (movel), far (any joints) or the target scaled out of reach.
struct Sweep {
  kin::Pose target;
  kin::JointVector seed;
};

Sweep make_pose(const kin::Chain& c, std::mt19937_64& rng, int k) {
  const kin::JointVector q = random_q(c, rng);
  Sweep s{fk(c, q), q};
  if (k % 3 == 0) {
    std::uniform_real_distribution<double> d(-0.02, 0.02);
    for (int j = 0; j < c.n_joints; ++j) s.seed[j] += d(rng);
  } else {
    s.seed = random_q(c, rng);
  }
  if (k % 17 == 5) s.target.translation() *= 4.0;
  return s;
}

// Returns on how many poses allowing solutions out of the limits changed the
// answer (the options matter on this sweep).
int compare(const char* name, int poses, unsigned seed) {
  const kin::Chain c = model(name);
  static kin::IkModel m;  // ~5 kB
  CHECK(kin::ik_prepare(c, m) == kin::Status::ok);
  std::mt19937_64 rng(seed);
  int solved = 0, differ = 0;
  for (int k = 0; k < poses; ++k) {
    const Sweep s = make_pose(c, rng, k);
    kin::Status first = kin::Status::ok;
    kin::JointVector q_first;
    for (const Case& cs : kCases) {
      const kin::IkSolver ik = kin::make_ik_solver(m, cs.options);
      kin::JointVector qa = kin::JointVector::Constant(c.n_joints, 7.0), qk = qa, qo = qa;
      const kin::Status sa = ik.fn(c, s.target, s.seed, qa, ik.ctx);
      const kin::Status sk = cs.kept(c, s.target, s.seed, qk, cs.old_takes_model ? &m : nullptr);
      kin::Status so = sk;
      if (cs.old) so = cs.old(c, s.target, s.seed, qo, &m);
      else qo = qk;
      if (!same(sa, qa, sk, qk) || !same(sa, qa, so, qo)) {
        FAIL((std::string(name) + " pose " + std::to_string(k) + ", " + cs.what + ": adapter " + kin::to_string(sa) +
              " " + describe(qa) + ", kept " + kin::to_string(sk) + " " + describe(qk) + ", old " +
              kin::to_string(so) + " " + describe(qo))
                 .c_str());
      }
      solved += kin::is_ok(sa) ? 1 : 0;
      if (&cs == &kCases[0]) {
        first = sa;
        q_first = qa;
      } else if (&cs == &kCases[1] && !same(first, q_first, sa, qa)) {
        ++differ;
      }
    }
  }
  CHECK(solved >= poses / 2);  // the sweep is not all failures
  return differ;
}

}  // namespace

TEST_GROUP(IkAdapter){};

TEST(IkAdapter, Puma560SameAsTheAdaptersItReplaces) { CHECK(compare("puma560", 3000, 14001) > 0); }
TEST(IkAdapter, StanfordSameAsTheAdaptersItReplaces) { compare("stanford", 3000, 14002); }
TEST(IkAdapter, RrrPlanarSameAsTheAdaptersItReplaces) { compare("rrr_planar", 3000, 14003); }
TEST(IkAdapter, Ist6SameAsTheAdaptersItReplaces) { compare("ist6", 1000, 14004); }
TEST(IkAdapter, NumericFallbackSameAsTheAdaptersItReplaces) { compare("vvr_vr", 200, 14005); }

TEST(IkAdapter, OptionsChooseTheFallback) {
  const kin::Chain c = model("vvr_vr");  // no closed form
  static kin::IkModel m;
  CHECK(kin::ik_prepare(c, m) == kin::Status::ok);
  CHECK(m.method == kin::IkMethod::none);
  std::mt19937_64 rng(14006);
  const kin::JointVector q = random_q(c, rng);
  const kin::Pose T = fk(c, q);
  kin::JointVector out;
  kin::IkSolverOptions none;
  none.fallback = kin::IkFallback::none;
  kin::IkSolver ik = kin::make_ik_solver(m, none);
  STRCMP_EQUAL("unsupported", kin::to_string(ik.fn(c, T, q, out, ik.ctx)));
  // A closed-form arm with closed_form off: the fallback only.
  const kin::Chain p = model("puma560");
  static kin::IkModel mp;
  CHECK(kin::ik_prepare(p, mp) == kin::Status::ok);
  const kin::JointVector qp = random_q(p, rng);
  const kin::Pose Tp = fk(p, qp);
  kin::IkSolverOptions numeric;
  numeric.closed_form = false;
  ik = kin::make_ik_solver(mp, numeric);
  kin::JointVector qn;
  CHECK(kin::is_ok(ik.fn(p, Tp, qp, qn, ik.ctx)));
  CHECK(kin::within_limits(p, qn, 1e-9));
  DOUBLES_EQUAL(0.0, (fk(p, qn).translation() - Tp.translation()).norm(), 1e-9);
  numeric.fallback = kin::IkFallback::none;
  ik = kin::make_ik_solver(mp, numeric);
  STRCMP_EQUAL("unsupported", kin::to_string(ik.fn(p, Tp, qp, qn, ik.ctx)));
  // Misuse: a chain that is not the model's, no model.
  ik = kin::make_ik_solver(mp, {});
  STRCMP_EQUAL("bad_input", kin::to_string(ik.fn(c, T, q, out, ik.ctx)));
  STRCMP_EQUAL("bad_input", kin::to_string(ik.fn(p, Tp, qp, out, nullptr)));
  STRCMP_EQUAL("wrong_size", kin::to_string(ik.fn(p, Tp, q.head(3), out, ik.ctx)));
  STRCMP_EQUAL("numeric", kin::to_string(kin::IkFallback::numeric));
  STRCMP_EQUAL("newton", kin::to_string(kin::IkFallback::newton));
  STRCMP_EQUAL("none", kin::to_string(kin::IkFallback::none));
}

TEST(IkAdapter, AllocatesNothing) {
  const char* names[] = {"puma560", "stanford", "rrr_planar", "ist6", "vvr_vr"};
  for (const char* name : names) {
    const kin::Chain c = model(name);
    static kin::IkModel m;
    std::mt19937_64 rng(14007);
    Sweep s[12];
    for (int k = 0; k < 12; ++k) s[k] = make_pose(c, rng, k);
    AllocScope scope;
    kin::ik_prepare(c, m);
    double sink = 0;
    for (int k = 0; k < 12; ++k) {
      for (const Case& cs : kCases) {
        const kin::IkSolver ik = kin::make_ik_solver(m, cs.options);
        kin::JointVector out(c.n_joints);
        sink += static_cast<int>(ik.fn(c, s[k].target, s[k].seed, out, ik.ctx));
      }
    }
    const std::size_t allocations = scope.end();
    CHECK(std::isfinite(sink));
    if (allocations != 0) FAIL((std::string(name) + ": heap allocations in the IK adapter: " + std::to_string(allocations)).c_str());
  }
}

// IkModel is a value: copies (construction, assignment) hold their own
// set-up data, made without the heap, and solve as the original did after
// the original is re-prepared for another arm.
TEST(IkAdapter, ModelIsAPlainValue) {
  static_assert(std::is_copy_constructible_v<kin::IkModel> && std::is_copy_assignable_v<kin::IkModel>);
  const kin::Chain p = model("puma560"), s = model("stanford");
  static kin::IkModel a, b, fresh;
  CHECK(kin::ik_prepare(p, a) == kin::Status::ok);
  CHECK(kin::ik_prepare(p, fresh) == kin::Status::ok);
  kin::IkModel* c = nullptr;
  {
    AllocScope scope;
    b = a;
    static kin::IkModel copy(a);
    c = &copy;
    LONGS_EQUAL(0, scope.end());
  }
  CHECK(kin::ik_prepare(s, a) == kin::Status::ok);  // the original now analyses another arm
  std::mt19937_64 rng(14008);
  for (int k = 0; k < 50; ++k) {
    const kin::JointVector q = random_q(p, rng);
    const kin::Pose T = fk(p, q);
    static kin::IkResult rf, rb, rc;
    kin::ik_solve_all(fresh, T, &q, rf);
    kin::ik_solve_all(b, T, &q, rb);
    kin::ik_solve_all(*c, T, &q, rc);
    LONGS_EQUAL(rf.count, rb.count);
    LONGS_EQUAL(rf.count, rc.count);
    for (int i = 0; i < rf.count; ++i) {
      CHECK(rf.solutions[static_cast<std::size_t>(i)].q == rb.solutions[static_cast<std::size_t>(i)].q);
      CHECK(rf.solutions[static_cast<std::size_t>(i)].q == rc.solutions[static_cast<std::size_t>(i)].q);
    }
  }
}

// movel through the adapter: the same plan (status, duration, every knot) and
// the same per-sample IK, bit for bit, as through the adapters it replaces,
// on random short lines (PUMA 560; ist6 through the degree-8 path). Refused
// lines count too: the same refusal.
void compare_movel(const char* name, int lines, unsigned seed) {
  const kin::Chain c = model(name);
  static kin::IkModel m;
  CHECK(kin::ik_prepare(c, m) == kin::Status::ok);
  struct Pair {
    kin::IkSolverOptions options;
    kin::IkNearestFn old;
  };
  kin::IkSolverOptions motion;
  motion.allow_out_of_limits = true;
  const Pair pairs[] = {{motion, &old_ik_nearest_for_motion}, {kin::IkSolverOptions{}, &old_ik_nearest_fn}};
  static kin::CartesianTrajectory ta, tb;
  std::mt19937_64 rng(seed);
  int planned = 0;
  for (int k = 0; k < lines; ++k) {
    const kin::JointVector q0 = random_q(c, rng);
    kin::JointVector q1(c.n_joints);  // element by element: GCC 12 -O3 warns falsely on the vector copy
    for (int j = 0; j < c.n_joints; ++j) q1[j] = q0[j] + std::uniform_real_distribution<double>(-0.3, 0.3)(rng);
    const kin::Pose target = fk(c, q1);
    for (const Pair& p : pairs) {
      const kin::MotionStatus sa =
          kin::plan_movel(c, q0, target, {}, {}, kin::make_ik_solver(m, p.options), ta, nullptr);
      const kin::MotionStatus sb = kin::plan_movel(c, q0, target, {}, {}, kin::IkSolver{p.old, &m}, tb, nullptr);
      const std::string ctx = std::string(name) + " line " + std::to_string(k) + ": " + kin::to_string(sa) + " / " +
                              kin::to_string(sb);
      CHECK_TEXT(sa == sb, ctx.c_str());
      if (!kin::is_ok(sa)) continue;
      ++planned;
      CHECK_TEXT(ta.duration == tb.duration, ctx.c_str());
      CHECK_TEXT(std::memcmp(ta.q_knot.data(), tb.q_knot.data(), sizeof ta.q_knot) == 0, ctx.c_str());
      CHECK_TEXT(std::memcmp(ta.dq_knot.data(), tb.dq_knot.data(), sizeof ta.dq_knot) == 0, ctx.c_str());
      for (int i = 0; i <= 10; ++i) {
        const double t = ta.duration * i / 10.0;
        kin::JointVector qa, qda, qdda, qb, qdb, qddb;
        const kin::Status ia = ta.sample_ik(t, qa, qda, qdda), ib = tb.sample_ik(t, qb, qdb, qddb);
        CHECK_TEXT(ia == ib && same(ia, qa, ib, qb), ctx.c_str());
      }
    }
  }
  CHECK(planned >= lines / 2);  // pairs planned, of 2 * lines
}

TEST(IkAdapter, MovelPlansAndSamplesAsBeforePuma560) { compare_movel("puma560", 40, 14009); }
TEST(IkAdapter, MovelPlansAndSamplesAsBeforeIst6) { compare_movel("ist6", 10, 14010); }
