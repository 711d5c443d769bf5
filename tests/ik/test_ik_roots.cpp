// SPDX-License-Identifier: Apache-2.0
// The general path's real-root finder (polynomial.cpp): isolation
// along the derivative chain, the companion matrix's eigenvalues as its
// fallback.
//  - Polynomials built from known roots (the reference: the roots they were
//    built from, not either solver): separated roots, exact double roots,
//    near-double real pairs (1e-3 .. 1e-9 apart), complex pairs near the real
//    axis (imaginary part 1e-2 .. 1e-9), scaled by 1e-4 .. 1e4. Every real
//    root is found, no root is invented, and isolation says "unsure" only
//    where two real roots cannot be told from a complex pair in doubles.
//  - Seeded IK sweeps on arms that take the general path (ist6 forced onto
//    it, the OPW near-miss models, 24 random general arms with a spherical
//    wrist in both conventions): random poses, the wrist centre on the
//    workspace boundary and 1e-9 .. 1e-3 in or out of it (the resultant's
//    double roots: tangency), near-singular wrists (theta5 in {0, +-1e-9,
//    +-1e-7, +-1e-5}). Every arm configuration the companion path finds is
//    found with the isolation (joints 1-3, what the roots decide), every
//    solution reproduces the pose (chain FK), the original configuration is
//    found.
#include <algorithm>
#include <cfenv>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "ik_class_util.hpp"
#include "../../kinematics/src/ik/ik_detail.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::test;

namespace {

struct Built {
  double c[9] = {1, 0, 0, 0, 0, 0, 0, 0, 0};
  int deg = 0;
  std::vector<double> real;                        // real roots (with multiplicity)
  std::vector<std::pair<double, double>> complex;  // (re, im) pairs
  void mul_root(double x) {
    double n[9] = {0};
    for (int i = 0; i <= deg; ++i) {
      n[i + 1] += c[i];
      n[i] -= x * c[i];
    }
    ++deg;
    std::copy(n, n + 9, c);
    real.push_back(x);
  }
  void mul_pair(double re, double im) {
    const double q[3] = {re * re + im * im, -2 * re, 1};
    double n[9] = {0};
    for (int i = 0; i <= deg; ++i)
      for (int j = 0; j < 3; ++j) n[i + j] += c[i] * q[j];
    deg += 2;
    std::copy(n, n + 9, c);
    complex.push_back({re, im});
  }
};

enum Kind { separated, exact_double, near_double, near_axis_pair, kinds };

// Degree 2..8: the kind's feature first, the rest separated by >= 1e-2
// (real roots or complex pairs with imaginary part >= 0.05).
Built build(Kind kind, int deg, double sep, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> U(-3, 3);
  Built b;
  if (kind == exact_double) {
    const double x = U(rng);
    b.mul_root(x);
    b.mul_root(x);
  } else if (kind == near_double) {
    const double x = U(rng);
    b.mul_root(x);
    b.mul_root(x + sep);
  } else if (kind == near_axis_pair) {
    b.mul_pair(U(rng), sep);
  }
  while (b.deg < deg) {
    double x;
    bool ok;
    do {
      x = U(rng);
      ok = true;
      for (double y : b.real) ok = ok && std::abs(x - y) >= 1e-2;
      for (auto& z : b.complex) ok = ok && std::abs(x - z.first) >= 1e-2;
    } while (!ok);
    if (deg - b.deg >= 2 && rng() % 2) b.mul_pair(x, 0.05 + std::abs(U(rng)));
    else b.mul_root(x);
  }
  const double s = std::pow(10.0, static_cast<int>(rng() % 9) - 4);
  for (int i = 0; i <= b.deg; ++i) b.c[i] *= s;
  return b;
}

double nearest(const double* r, int n, double x) {
  double best = 1e300;
  for (int i = 0; i < n; ++i) best = std::min(best, std::abs(r[i] - x));
  return best;
}

}  // namespace

TEST_GROUP(IkRoots){};

TEST(IkRoots, IsolationFindsEveryRealRootOfPolynomialsOfKnownRoots) {
  std::mt19937_64 rng(19);
  int unsure[kinds] = {0}, tried[kinds] = {0}, unsure_wide = 0, eig_missed = 0;
  for (int t = 0; t < 40000; ++t) {
    const Kind kind = static_cast<Kind>(t % kinds);
    const int deg = 2 + (t / kinds) % 7;
    const double sep = std::pow(10.0, -2.0 - static_cast<double>(rng() % 8));  // 1e-2 .. 1e-9
    const Built b = build(kind, deg, sep, rng);
    double r[8], e[8];
    const int n = kin::detail::real_roots_isolated(b.c, b.deg, r);
    const int ne = kin::detail::real_roots_eigen(b.c, b.deg, e);
    ++tried[kind];
    if (n < 0) {
      ++unsure[kind];
      // Unsure only where a pair cannot be resolved or is the companion
      // path's: never for separated roots, never for a real pair 1e-4 or more apart.
      if (kind == separated || (kind == near_double && sep >= 1e-4)) ++unsure_wide;
      continue;
    }
    CHECK(n <= b.deg);
    for (int i = 1; i < n; ++i) CHECK(r[i - 1] <= r[i]);
    // Every real root found (a near-double pair 1e-4 or more apart: both, as
    // two roots; closer: at least one candidate within the pair's scale).
    for (double x : b.real) {
      const double tol = (kind == separated || sep >= 1e-4) ? 2e-5 * (1 + std::abs(x)) : 1e-3 * (1 + std::abs(x));
      if (!(nearest(r, n, x) <= tol)) {
        std::printf("\nkind %d deg %d sep %g: root %.17g missed (%d found)", kind, b.deg, sep, x, n);
        FAIL("a real root missed");
      }
    }
    if (kind == near_double && sep >= 1e-4) {
      for (int k = 0; k < 2; ++k) {
        int close = 0;
        for (int i = 0; i < n; ++i) close += std::abs(r[i] - b.real[static_cast<std::size_t>(k)]) <= sep / 4 ? 1 : 0;
        LONGS_EQUAL(1, close);
      }
    }
    // No root invented: each is one of the real roots, or near a complex
    // pair within 1e-7 of the axis (its square below the coefficients'
    // rounding: in doubles it may be a real pair).
    for (int i = 0; i < n; ++i) {
      bool known = false;
      for (double x : b.real) known = known || std::abs(r[i] - x) <= 1e-3 * (1 + std::abs(x));
      for (auto& z : b.complex) known = known || (z.second <= 1e-7 && std::abs(r[i] - z.first) <= 1e-3);
      if (!known) std::printf("\nkind %d deg %d sep %g: invented root %.17g", kind, b.deg, sep, r[i]);
      CHECK(known);
    }
    // A complex pair 1e-7 .. 0.5e-4 (1 + |re|) from the axis is the
    // companion path's (double) real root: the isolation must have said unsure.
    for (auto& z : b.complex) CHECK(!(z.second > 1e-7 && z.second <= 0.5e-4 * (1 + std::abs(z.first))));
    // The companion path finds nothing the isolation does not.
    for (int i = 0; i < ne; ++i)
      if (nearest(r, n, e[i]) > 1e-3 * (1 + std::abs(e[i]))) ++eig_missed;
  }
  std::printf("\n  isolation unsure (companion fallback): separated %d/%d, exact double %d/%d, near double %d/%d, "
              "near-axis pair %d/%d",
              unsure[separated], tried[separated], unsure[exact_double], tried[exact_double], unsure[near_double],
              tried[near_double], unsure[near_axis_pair], tried[near_axis_pair]);
  LONGS_EQUAL(0, unsure_wide);
  LONGS_EQUAL(0, eig_missed);
}

TEST(IkRoots, DegenerateInputs) {
  double r[8];
  const double lin[2] = {-3, 2};  // 2x - 3
  LONGS_EQUAL(1, kin::detail::real_roots_isolated(lin, 1, r));
  DOUBLES_EQUAL(1.5, r[0], 1e-15);
  const double none[3] = {1, 0, 1};  // x^2 + 1: no real root
  LONGS_EQUAL(0, kin::detail::real_roots_isolated(none, 2, r));
  const double odd[4] = {0, 1, 0, 1};  // x^3 + x: derivative without real roots, root 0
  LONGS_EQUAL(1, kin::detail::real_roots_isolated(odd, 3, r));
  DOUBLES_EQUAL(0, r[0], 1e-15);
  const double zero_lead[3] = {1, 2, 0};
  LONGS_EQUAL(-1, kin::detail::real_roots_isolated(zero_lead, 2, r));
  const double nan[3] = {NAN, 1, 1};
  LONGS_EQUAL(-1, kin::detail::real_roots_isolated(nan, 2, r));
  const double big[9] = {1e300, 0, 0, 0, 0, 0, 0, 0, 1e-300};  // overflows: unsure
  LONGS_EQUAL(-1, kin::detail::real_roots_isolated(big, 8, r));
  std::feclearexcept(FE_ALL_EXCEPT);  // the overflow it ran into (CppUTest's IEEE754 plugin)
  // (x - 1)^2 (x + 2): the double root is unsure (companion fallback)
  const double dbl[4] = {2, -3, 0, 1};
  LONGS_EQUAL(-1, kin::detail::real_roots_isolated(dbl, 3, r));
}

namespace {

kin::IkModel general_model(const char* name, bool twist) {
  kin::Chain c = model(name);
  if (twist) c = perturbed(c, 1, 't');
  kin::IkModel m;
  LONGS_EQUAL(0, static_cast<int>(kin::ik_prepare(c, m)));
  if (!twist) {  // ist6 forced onto the degree-8 path (as armbench's general_path)
    kin::detail::solver_data(m).par23 = false;
    m.method = kin::IkMethod::spherical_general;
  }
  STRCMP_EQUAL("spherical_general", kin::to_string(m.method));
  return m;
}

// Wrist centre W = T w_tool and its Jacobian over joints 1-3.
Eigen::Matrix3d wrist_jacobian(const kin::IkModel& m, const kin::JointVector& q, Eigen::Vector3d& W) {
  kin::Jacobian J;
  kin::Pose T;
  kin::jacobian(m.chain, q, J, &T);
  W = T * m.w_tool;
  Eigen::Matrix3d Jw;
  for (int j = 0; j < 3; ++j) {
    const Eigen::Vector3d v = J.col(j).head<3>(), w = J.col(j).tail<3>();
    Jw.col(j) = v + w.cross(W - T.translation());
  }
  return Jw;
}

// q with q3 moved to where the wrist Jacobian is singular (the workspace
// boundary), and the boundary's normal; false if no such q3.
bool on_boundary(const kin::IkModel& m, kin::JointVector& q, Eigen::Vector3d& normal) {
  Eigen::Vector3d W;
  auto det = [&](double q3) {
    kin::JointVector x = q;
    x[2] = q3;
    return wrist_jacobian(m, x, W).determinant();
  };
  double lo = -M_PI, flo = det(lo);
  for (int k = 1; k <= 90; ++k) {
    const double hi = -M_PI + k * (2 * M_PI / 90), fhi = det(hi);
    if ((flo > 0) != (fhi > 0)) {
      double a = lo, b = hi, fa = flo;
      for (int it = 0; it < 80; ++it) {
        const double mid = 0.5 * (a + b), fm = det(mid);
        if ((fm > 0) == (fa > 0)) { a = mid; fa = fm; }
        else b = mid;
      }
      q[2] = 0.5 * (a + b);
      const Eigen::Matrix3d Jw = wrist_jacobian(m, q, W);
      Eigen::Vector3d best = Eigen::Vector3d::Zero();
      for (int i = 0; i < 3; ++i) {
        const Eigen::Vector3d n = Jw.col(i).cross(Jw.col((i + 1) % 3));
        if (n.norm() > best.norm()) best = n;
      }
      if (!(best.norm() > 0)) return false;
      normal = best.normalized();
      return true;
    }
    lo = hi;
    flo = fhi;
  }
  return false;
}

std::string sci(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", v);
  return b;
}

struct SweepStats {
  int poses = 0, eigen_configs = 0, isolation_configs = 0;
};

// Every joints-1-3 configuration of the companion path within tol of one of
// the isolation path; every solution of both reproduces the pose.
// j0 = 1: joints 2-3 only (on the boundary the wrist centre may also be near
// axis 1, where q1 is ill-conditioned: a 5e-6 change of q2 moved it 0.04 rad).
void compare_paths(const kin::IkModel& iso, const kin::IkModel& eig, const kin::Pose& T, const kin::JointVector* q0,
                   double tol, int j0, const std::string& what, SweepStats& st) {
  kin::IkResult ri, re;
  kin::ik_solve_all(iso, T, nullptr, ri);
  kin::ik_solve_all(eig, T, nullptr, re);
  ++st.poses;
  st.eigen_configs += re.count;
  st.isolation_configs += ri.count;
  // Through the chain's FK (the solver verified them to 1e-9, partly through
  // its own DH decomposition: a rounding apart at the boundary's 1e-9 residuals).
  auto check = [&](const kin::IkResult& r, const char* path) {
    for (int i = 0; i < r.count; ++i) {
      const kin::JointVector& q = r.solutions[static_cast<std::size_t>(i)].q;
      const kin::Pose X = fk(iso.chain, q);
      const double ep = (X.translation() - T.translation()).norm();
      const double er = kin::rotation_error(X.linear(), T.linear()).norm();
      if (!(ep <= 1.01e-9 && er <= 1.01e-9))
        FAIL((what + ": " + path + " path's " + describe(q) + " ep " + std::to_string(ep * 1e9) + " nm, er " +
              std::to_string(er * 1e9) + " nrad")
                 .c_str());
    }
  };
  check(ri, "isolation");
  check(re, "companion");
  auto gap3 = [&](const kin::JointVector& a, const kin::JointVector& b) {
    double g = 0;
    for (int j = j0; j < 3; ++j) g = std::max(g, std::abs(kin::wrap_pi(a[j] - b[j])));
    return g;
  };
  for (int i = 0; i < re.count; ++i) {
    double best = 1e300;
    for (int k = 0; k < ri.count; ++k)
      best = std::min(best, gap3(re.solutions[static_cast<std::size_t>(i)].q, ri.solutions[static_cast<std::size_t>(k)].q));
    if (!(best <= tol))
      FAIL((what + ": the companion path's " + describe(re.solutions[static_cast<std::size_t>(i)].q) +
            " not found by the isolation (" + std::to_string(ri.count) + " vs " + std::to_string(re.count) +
            " solutions, nearest " + std::to_string(best) + ")")
               .c_str());
  }
  if (q0) {
    auto found = [&](const kin::IkResult& r) {
      for (int i = 0; i < r.count; ++i)
        if (gap3(r.solutions[static_cast<std::size_t>(i)].q, *q0) <= tol) return true;
      return false;
    };
    if (found(re) || tol < 1e-5) CHECK_TEXT(found(ri), (what + ": original not found").c_str());
  }
}

const struct {
  const char* name;
  bool twist;
} kGeneralArms[] = {{"ist6", false}, {"abb_irb2400", true}, {"kuka_kr6_r700", true}};

}  // namespace

TEST(IkRoots, GeneralPathRandomPosesSameConfigurationsAsTheCompanionPath) {
  for (const auto& arm : kGeneralArms) {
    const kin::IkModel iso = general_model(arm.name, arm.twist);
    kin::IkModel eig = iso;
    kin::detail::solver_data(eig).eigen_roots = true;
    std::mt19937_64 rng(1900);
    SweepStats st;
    for (int k = 0; k < 1500; ++k) {
      const kin::JointVector q = random_q(iso.chain, rng);
      compare_paths(iso, eig, fk(iso.chain, q), &q, 1e-6, 0, std::string(arm.name) + " random " + describe(q), st);
    }
    std::printf("\n  %-14s random: %d poses, solutions: companion %d, isolation %d", arm.name, st.poses,
                st.eigen_configs, st.isolation_configs);
  }
}

TEST(IkRoots, GeneralPathWorkspaceBoundaryAndSingularWristLoseNoConfiguration) {
  const double offsets[] = {0, 1e-9, -1e-9, 1e-7, -1e-7, 1e-5, -1e-5, 1e-3, -1e-3};
  for (const auto& arm : kGeneralArms) {
    const kin::IkModel iso = general_model(arm.name, arm.twist);
    kin::IkModel eig = iso;
    kin::detail::solver_data(eig).eigen_roots = true;
    std::mt19937_64 rng(1901);
    SweepStats sb, sw;
    int boundary = 0;
    while (boundary < 120) {
      kin::JointVector q = random_q(iso.chain, rng);
      Eigen::Vector3d n;
      if (!on_boundary(iso, q, n)) continue;
      ++boundary;
      const kin::Pose T0 = fk(iso.chain, q);
      for (double off : offsets) {
        kin::Pose T = T0;
        T.translation() += off * n;
        // At the boundary the configurations are defined to ~sqrt(1e-9 m).
        compare_paths(iso, eig, T, off == 0 ? &q : nullptr, 1e-3, 1,
                      std::string(arm.name) + " boundary " + sci(off) + " " + describe(q), sb);
      }
    }
    const double t5s[] = {0, 1e-9, -1e-9, 1e-7, -1e-7, 1e-5, -1e-5};
    for (int k = 0; k < 150; ++k) {
      kin::JointVector q = random_q(iso.chain, rng);
      for (double t5 : t5s) {
        q[4] = t5;
        compare_paths(iso, eig, fk(iso.chain, q), &q, 1e-6, 0,
                      std::string(arm.name) + " theta5 " + sci(t5) + " " + describe(q), sw);
      }
    }
    std::printf("\n  %-14s boundary +-1e-9..1e-3: %d poses, solutions companion %d, isolation %d; wrist: %d poses, "
                "%d / %d",
                arm.name, sb.poses, sb.eigen_configs, sb.isolation_configs, sw.poses, sw.eigen_configs,
                sw.isolation_configs);
  }
}

// Random general arms: the first three DH rows with random link lengths,
// offsets and twists (no two of axes 1-3 parallel or meeting by design), a
// spherical wrist after them, in both conventions: every one takes the
// general path, and on random poses and with theta5 near 0 the isolation
// finds every configuration the companion path finds.
TEST(IkRoots, RandomGeneralArmsSameConfigurationsAsTheCompanionPath) {
  std::mt19937_64 rng(1902);
  std::uniform_real_distribution<double> len(0.05, 0.6), off(-0.3, 0.3), tw(0.3, 2.8), th(-M_PI, M_PI);
  SweepStats st;
  int arms = 0;
  for (int a = 0; a < 24; ++a) {
    const double s1 = rng() % 2 ? 1 : -1, s2 = rng() % 2 ? 1 : -1;
    const std::vector<kin::DhRow> rows = {rev(th(rng), len(rng), off(rng), s1 * tw(rng)),
                                          rev(th(rng), off(rng), len(rng), s2 * tw(rng)),
                                          rev(th(rng), off(rng), off(rng), M_PI / 2),
                                          rev(0, len(rng), 0, -M_PI / 2),
                                          rev(0, 0, 0, M_PI / 2),
                                          rev(0, 0.1, 0, 0)};
    const kin::Chain c = chain_of(rows, a % 2 == 1, "random_general");
    kin::IkModel iso;
    LONGS_EQUAL(0, static_cast<int>(kin::ik_prepare(c, iso)));
    STRCMP_EQUAL("spherical_general", kin::to_string(iso.method));
    kin::IkModel eig = iso;
    kin::detail::solver_data(eig).eigen_roots = true;
    ++arms;
    for (int k = 0; k < 200; ++k) {
      kin::JointVector q = random_q(iso.chain, rng);
      if (k % 4 == 3) q[4] = (k % 8 == 3) ? 0.0 : 1e-9;
      compare_paths(iso, eig, fk(iso.chain, q), &q, 1e-6, 0, "random general arm " + std::to_string(a) + " " + describe(q),
                    st);
    }
  }
  std::printf("\n  %d random general arms: %d poses, solutions companion %d, isolation %d", arms, st.poses,
              st.eigen_configs, st.isolation_configs);
}
