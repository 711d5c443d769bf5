// SPDX-License-Identifier: Apache-2.0
// Jacobian against central finite differences of FK, manipulability and
// condition number at known singular configurations and against one-sided Jacobi rotations
// for every column count, Cartesian precision
// (Carrara, Apostila de Robótica, §3.14) against its closed form, and the two PUMA descriptions
// against each other.

#include <algorithm>
#include <cmath>
#include <vector>

#include "kin_test_util.hpp"

using namespace servoarm;
using namespace servoarm::test;

namespace {

// Angular velocity column from rotations at q +- h: vee(dR/dq R^T).
kin::Jacobian numeric_jacobian(const kin::Chain& c, const kin::JointVector& q, double h) {
  kin::Jacobian J(6, c.n_joints);
  for (int j = 0; j < c.n_joints; ++j) {
    kin::JointVector qp = q, qm = q;
    qp[j] += h;
    qm[j] -= h;
    const kin::Pose Tp = fk(c, qp), Tm = fk(c, qm);
    J.block<3, 1>(0, j) = (Tp.translation() - Tm.translation()) / (2 * h);
    const Eigen::Matrix3d W = (Tp.linear() - Tm.linear()) / (2 * h) * fk(c, q).linear().transpose();
    J.block<3, 1>(3, j) = Eigen::Vector3d(W(2, 1) - W(1, 2), W(0, 2) - W(2, 0), W(1, 0) - W(0, 1)) / 2;
  }
  return J;
}

}  // namespace

TEST_GROUP(Jacobian){};

TEST(Jacobian, MatchesCentralFiniteDifferencesForEveryModel) {
  for (const auto& m : kin::builtin_models()) {
    const kin::Chain c = model(m.name);
    std::mt19937_64 rng(7);
    for (int n = 0; n < 500; ++n) {
      const kin::JointVector q = random_q(c, rng);
      kin::Jacobian J;
      CHECK(kin::jacobian(c, q, J) == kin::Status::ok);
      const kin::Jacobian Jn = numeric_jacobian(c, q, 1e-6);
      const double err = (J - Jn).cwiseAbs().maxCoeff();
      if (err > 1e-7) {
        std::ostringstream os;
        os << m.name << " " << describe(q) << " |J - J_fd| = " << err << "\nJ\n" << J << "\nJ_fd\n" << Jn;
        FAIL(os.str().c_str());
      }
    }
  }
}

TEST(Jacobian, WrongSizeAndNonFiniteJointsAreRefused) {
  const kin::Chain c = model("puma560");
  kin::Jacobian J;
  kin::Pose T = kin::Pose::Identity();
  CHECK(kin::jacobian(c, kin::JointVector::Zero(5), J) == kin::Status::wrong_size);
  CHECK(kin::forward(c, kin::JointVector::Zero(7), T) == kin::Status::wrong_size);
  kin::JointVector q = kin::JointVector::Zero(6);
  q[3] = std::numeric_limits<double>::infinity();
  CHECK(kin::forward(c, q, T) == kin::Status::bad_input);
  CHECK(T.matrix().isIdentity(0));  // untouched
  q[3] = std::numeric_limits<double>::quiet_NaN();
  CHECK(kin::jacobian(c, q, J) == kin::Status::bad_input);
}

// Singular configurations (Custódio et al. (IST 2019), §4): wrist (theta5 = 0) and elbow
// stretched make the Jacobian rank-deficient; a generic pose does not.
TEST(Jacobian, ManipulabilityAndConditionAtSingularities) {
  const kin::Chain c = model("puma560");
  kin::Jacobian J;
  kin::JointVector q(6);
  q << 0.3, -0.7, 1.1, 0.4, 0.8, -0.2;
  CHECK(kin::jacobian(c, q, J) == kin::Status::ok);
  const double m_generic = kin::manipulability(J);
  CHECK(m_generic > 1e-3);
  CHECK(kin::condition_number(J) < 1e3);
  // product of singular values equals sqrt(det(J J^T)) for a square J
  DOUBLES_EQUAL(std::sqrt(std::abs((J * J.transpose()).determinant())), m_generic, 1e-12);

  kin::JointVector qw = q;
  qw[4] = 0.0;  // wrist singularity
  CHECK(kin::jacobian(c, qw, J) == kin::Status::ok);
  CHECK(kin::manipulability(J) < 1e-12);
  CHECK(kin::condition_number(J) > 1e12);

  // Elbow fully stretched: find theta3 where the in-plane distance from the
  // shoulder (joint 2 axis) to the wrist centre is largest; it must equal
  // a2 + sqrt(a3^2 + d4^2), and the Jacobian must be singular there.
  const double a2 = 0.4318, a3 = -0.02032, d4 = 0.43307;
  auto planar_reach = [&](double q3) {
    kin::JointVector qe = q;
    qe[2] = q3;
    kin::FrameSet F;
    kin::Pose T;
    kin::forward_frames(c, qe, F, T);
    const Eigen::Vector3d v = F.frame[4].translation() - F.frame[1].translation();
    const Eigen::Vector3d z1 = F.frame[1].linear().col(2);
    return (v - v.dot(z1) * z1).norm();
  };
  double best = -1, q3best = 0;
  for (double q3 = -M_PI; q3 < M_PI; q3 += 1e-5) {
    const double r = planar_reach(q3);
    if (r > best) best = r, q3best = q3;
  }
  DOUBLES_EQUAL(a2 + std::hypot(a3, d4), best, 1e-9);
  kin::JointVector qs = q;
  qs[2] = q3best;
  kin::jacobian(c, qs, J);
  CHECK(kin::manipulability(J) < 1e-4 * m_generic);
  CHECK(kin::condition_number(J) > 1e4);
}

// Carrara, Apostila de Robótica, §4.1: dx = |a1 s1 + a2 s12| dq1 + |a2 s12| dq2 (and dy likewise).
TEST(Jacobian, CartesianPrecisionMatchesSeed002ClosedForm) {
  const kin::Chain c = model("rr_planar");
  const double a1 = 0.3, a2 = 0.25;
  std::mt19937_64 rng(9);
  for (int n = 0; n < 1000; ++n) {
    const kin::JointVector q = random_q(c, rng);
    kin::JointVector dq(2);
    dq << 1e-4 * (1 + n % 3), 2e-4;
    Eigen::Vector3d dw;
    CHECK(kin::cartesian_precision(c, q, dq, dw) == kin::Status::ok);
    const double t1 = q[0], t12 = q[0] + q[1];
    DOUBLES_EQUAL(std::abs(a1 * std::sin(t1) + a2 * std::sin(t12)) * dq[0] + std::abs(a2 * std::sin(t12)) * dq[1], dw.x(), 1e-15);
    DOUBLES_EQUAL(std::abs(a1 * std::cos(t1) + a2 * std::cos(t12)) * dq[0] + std::abs(a2 * std::cos(t12)) * dq[1], dw.y(), 1e-15);
    DOUBLES_EQUAL(0.0, dw.z(), 1e-15);
  }
  kin::JointVector bad(2);
  bad << -1e-4, 1e-4;
  Eigen::Vector3d dw;
  CHECK(kin::cartesian_precision(c, kin::JointVector::Zero(2), bad, dw) == kin::Status::bad_input);
}

// The two PUMA 560 descriptions (Cinemática direta de posição, standard DH, Cinemática inversa robô PUMA 560 (after Craig) Craig) place
// their frames differently: with q_std = (q1, q2, q3 + 180, q4, q5, q6 + 180)
// they describe the same arm. Where they should agree they do: the wrist centre
// (Craig's tool point; the standard tool point minus d6 along z6), the tool
// orientation, the Jacobian once moved to the same reference point
// (v_wc = v_tool + w x (p_wc - p_tool)), and |det J| (a change of reference
// point has determinant 1).
TEST(Jacobian, TheTwoPumaDescriptionsAgree) {
  const kin::Chain S = model("puma560"), C = model("puma560_craig");
  const double d6 = 0.05625;
  std::mt19937_64 rng(17);
  for (int n = 0; n < 5000; ++n) {
    const kin::JointVector q = random_q(C, rng);
    kin::JointVector qs = q;
    qs[2] += M_PI;
    qs[5] += M_PI;
    kin::Jacobian Js, Jc;
    kin::Pose Ts, Tc;
    CHECK(kin::jacobian(S, qs, Js, &Ts) == kin::Status::ok);
    CHECK(kin::jacobian(C, q, Jc, &Tc) == kin::Status::ok);
    const Eigen::Vector3d r = -d6 * Ts.linear().col(2);  // p_wc - p_tool
    CHECK((Ts.translation() + r - Tc.translation()).norm() < 1e-12);
    CHECK((Ts.linear() - Tc.linear()).cwiseAbs().maxCoeff() < 1e-12);
    kin::Jacobian Jmoved = Js;
    for (int j = 0; j < 6; ++j) Jmoved.block<3, 1>(0, j) += Js.block<3, 1>(3, j).cross(r);
    CHECK((Jmoved - Jc).cwiseAbs().maxCoeff() < 1e-12);
    DOUBLES_EQUAL(kin::manipulability(Js), kin::manipulability(Jc), 1e-12);
  }
}

// Singular values of an m x k matrix (k <= m, column-major in a) by one-sided Jacobi rotations
// (Hestenes; Demmel and Veselic, "Jacobi's method is more accurate than QR", 1992): plane
// rotations of column pairs until every pair is orthogonal, the singular values then the
// columns' norms. Written out: the reference shares no code with Eigen's decompositions, which
// chain.cpp's singular values come from; and it works on J itself, not on its Gram matrix,
// whose eigenvalues resolve condition numbers of some 1e5 only to 1e-5.
namespace {
std::vector<double> jacobi_singular_values(std::vector<double> a, int m, int k) {
  auto col = [&a, m](int j) { return a.data() + static_cast<std::ptrdiff_t>(j) * m; };
  auto dot = [m](const double* x, const double* y) {
    double d = 0;
    for (int i = 0; i < m; ++i) d += x[i] * y[i];
    return d;
  };
  for (int sweep = 0; sweep < 60; ++sweep) {
    bool rotated = false;
    for (int p = 0; p < k - 1; ++p) {
      for (int q = p + 1; q < k; ++q) {
        double* x = col(p);
        double* y = col(q);
        const double alpha = dot(x, x), beta = dot(y, y), gamma = dot(x, y);
        if (std::abs(gamma) <= 1e-15 * std::sqrt(alpha * beta)) continue;
        rotated = true;
        // the rotation (c, s) that makes columns p and q orthogonal
        const double zeta = (beta - alpha) / (2 * gamma);
        const double t = (zeta >= 0 ? 1.0 : -1.0) / (std::abs(zeta) + std::sqrt(1 + zeta * zeta));
        const double c = 1 / std::sqrt(1 + t * t), s = t * c;
        for (int i = 0; i < m; ++i) {
          const double xi = x[i], yi = y[i];
          x[i] = c * xi - s * yi;
          y[i] = s * xi + c * yi;
        }
      }
    }
    if (!rotated) break;
  }
  std::vector<double> sv(static_cast<std::size_t>(k));
  for (int j = 0; j < k; ++j) sv[static_cast<std::size_t>(j)] = std::sqrt(dot(col(j), col(j)));
  return sv;
}
}  // namespace

// The singular values behind manipulability and condition_number, for every column count
// 1..8 (fewer, as many as and more joints than the 6 task directions), against an independent
// route: one-sided Jacobi rotations (above) of J's columns, or of J^T's for a wide J (the same
// singular values). Seeded random Jacobians, well conditioned (errors near rounding) and with
// two columns 1e-3 apart (condition numbers up to some 3e5; the two agree to 1e-11 there).
TEST(Jacobian, SingularValuesMatchTheGramMatrixEigenvaluesForEveryColumnCount) {
  std::mt19937_64 rng(23);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int n = 1; n <= kin::kMaxJoints; ++n) {
    for (int k = 0; k < 200; ++k) {
      kin::Jacobian J(6, n);
      for (int i = 0; i < 6; ++i)
        for (int j = 0; j < n; ++j) J(i, j) = u(rng);
      if (k % 2) J.col(n - 1) = J.col(0) + 1e-3 * J.col(n - 1);  // nearly dependent columns
      // J (6 x n) or, wide, J^T (n x 6), column-major
      const int rows = n > 6 ? n : 6, cols = n > 6 ? 6 : n;
      std::vector<double> a(static_cast<std::size_t>(rows * cols));
      for (int c = 0; c < cols; ++c)
        for (int r = 0; r < rows; ++r) a[static_cast<std::size_t>(c * rows + r)] = n > 6 ? J(c, r) : J(r, c);
      const std::vector<double> sv = jacobi_singular_values(a, rows, cols);
      double m = 1.0;
      for (double v : sv) m *= v;
      const double cond = *std::max_element(sv.begin(), sv.end()) / *std::min_element(sv.begin(), sv.end());
      std::ostringstream os;
      os << "n " << n << " case " << k << ": manipulability " << kin::manipulability(J) << " against "
         << m << ", condition number " << kin::condition_number(J) << " against " << cond;
      CHECK_TEXT(std::abs(kin::manipulability(J) - m) <= 1e-9 * std::max(1.0, m), os.str().c_str());
      CHECK_TEXT(std::abs(kin::condition_number(J) - cond) <= 1e-9 * cond, os.str().c_str());
    }
  }
}
