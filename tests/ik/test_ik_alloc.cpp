// Zero heap in every IK solver (closed forms, choice, numerical), counted by
// the malloc hook; this file and the library are built with EIGEN_NO_MALLOC.
#include "servoarm/kinematics/ik.hpp"
#include "alloc_counter.hpp"
#include "kin_test_util.hpp"

using namespace servoarm;
using namespace servoarm::test;

TEST_GROUP(IkZeroHeap){};

TEST(IkZeroHeap, EverySolverAllocatesNothing) {
  {
    AllocScope probe;
    probe_malloc_free();
    LONGS_EQUAL(1, probe.end());
  }
  for (const auto& bm : kin::builtin_models()) {
    const kin::Chain c = model(bm.name);
    kin::IkModel m;
    std::mt19937_64 rng(3);
    kin::JointVector qs[16], q0s[16];
    for (auto& q : qs) q = random_q(c, rng);
    for (auto& q : q0s) q = random_q(c, rng);
    AllocScope scope;
    kin::ik_prepare(c, m);  // set-up is heap-free too
    double sink = 0;
    for (int k = 0; k < 16; ++k) {
      kin::Pose T;
      kin::forward(c, qs[k], T);
      kin::IkResult r;
      kin::ik_solve_all(m, T, &q0s[k], r);
      kin::IkChoice keep;
      keep.keep_branch = true;
      sink += kin::ik_choose(m, r, q0s[k]) + kin::ik_choose(m, r, q0s[k], keep);
      kin::JointVector out;
      sink += static_cast<int>(kin::ik_solve_nearest(m, T, q0s[k], out));
      kin::IkNumericOptions o;
      o.max_iterations = 50;
      o.max_restarts = 2;
      o.position_only = (k & 1) != 0;
      kin::IkNumericResult nr;
      kin::ik_numeric(c, T, q0s[k], o, nr);
      sink += nr.position_error + nr.iterations;
    }
    const std::size_t allocations = scope.end();
    CHECK(std::isfinite(sink));
    if (allocations != 0) FAIL((std::string(bm.name) + ": heap allocations in IK: " + std::to_string(allocations)).c_str());
  }
}
