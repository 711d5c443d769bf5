// SPDX-License-Identifier: Apache-2.0
// Zero heap in every IK solver (closed forms, choice, numerical), counted by
// the malloc hook; this file and the library are built with EIGEN_NO_MALLOC.
#include "servoarm/kinematics/ik.hpp"
#include "alloc_counter.hpp"
#include "kin_test_util.hpp"

using namespace servoarm;
using namespace servoarm::test;

TEST_GROUP(IkZeroHeap){};

TEST(IkZeroHeap, EverySolverAllocatesNothing) {
  if (alloc_counter_counts()) {
    AllocScope probe;
    probe_malloc_free();
    LONGS_EQUAL(1, probe.end());
  } else {
    UT_PRINT("allocation counter off in this build (memcheck): the zero counts below prove nothing here");
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

// The issue-19 paths: opw, ur, spherical_general (an OPW arm with a 0.01 deg
// twist between axes 2 and 3), at generic poses and where the closed form
// hands candidates to add_candidate's FK + Gauss-Newton (theta5 = 0 and
// 1e-9, the elbow stretched); every method named is exercised.
TEST(IkZeroHeap, OpwUrAndGeneralPathsAllocateNothing) {
  struct Case {
    const char* name;
    bool twist;
    const char* method;
  };
  const Case cases[] = {{"abb_irb2400", false, "opw"},
                        {"kuka_kr6_r700", false, "opw"},
                        {"ur5e", false, "ur"},
                        {"ur10e", false, "ur"},
                        {"abb_irb2400", true, "spherical_general"}};
  for (const Case& k : cases) {
    kin::Chain c = model(k.name);
    if (k.twist) {
      kin::Chain t = c;
      t.n_rows = 0;
      t.n_joints = 0;
      for (int i = 0; i < c.n_rows; ++i) {
        kin::DhRow r = c.rows[static_cast<std::size_t>(i)];
        if (i == 1) r.alpha += 0.01 * M_PI / 180;
        kin::add_row(t, r);
      }
      c = t;
    }
    kin::IkModel m;
    kin::ik_prepare(c, m);
    STRCMP_EQUAL_TEXT(k.method, kin::to_string(m.method), k.name);
    std::mt19937_64 rng(11);
    kin::JointVector qs[12];
    for (int i = 0; i < 12; ++i) {
      qs[i] = random_q(c, rng);
      if (i % 3 == 1) qs[i][4] = (i % 2) ? 0.0 : 1e-9;  // wrist singular
      if (i % 3 == 2) qs[i][2] = k.method[0] == 'u' ? 0.0 : qs[i][2];  // UR: elbow stretched
    }
    AllocScope scope;
    double sink = 0;
    for (const auto& q : qs) {
      kin::Pose T;
      kin::forward(c, q, T);
      kin::IkResult r;
      kin::ik_solve_all(m, T, &q, r);
      sink += r.count;
      kin::JointVector out;
      sink += static_cast<int>(kin::ik_solve_nearest(m, T, q, out));
    }
    const std::size_t allocations = scope.end();
    CHECK(sink > 0);
    if (allocations != 0) FAIL((std::string(k.name) + ": heap allocations: " + std::to_string(allocations)).c_str());
  }
}
