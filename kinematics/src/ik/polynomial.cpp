// Inverse kinematics, the general position subproblem: when neither equation
// of (E1, E2) is free of q2 or of q3 (e.g. ist6, whose axes 1 and 2 do not
// meet), q2 is eliminated by the resultant, a polynomial of degree <= 8 in
// tan(q3/2) (or d3) whose real roots come from its 8x8 companion matrix
// (compile-time maximum size: heap-free), each polished by Newton on (E1, E2).
#include <algorithm>
#include <cmath>
#include <complex>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include "ik_detail.hpp"

namespace servoarm::kin::detail {
namespace {

// Polynomial up to degree 8, coefficient k of x^k.
struct Poly {
  double c[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
  int deg = 0;
};
Poly pmul(const Poly& a, const Poly& b) {
  Poly r;
  r.deg = std::min(8, a.deg + b.deg);
  for (int i = 0; i <= a.deg; ++i)
    for (int j = 0; j <= b.deg && i + j <= 8; ++j) r.c[i + j] += a.c[i] * b.c[j];
  return r;
}
Poly psub(const Poly& a, const Poly& b) {
  Poly r;
  r.deg = std::max(a.deg, b.deg);
  for (int i = 0; i <= r.deg; ++i) r.c[i] = a.c[i] - b.c[i];
  return r;
}
Poly padd(const Poly& a, const Poly& b) {
  Poly r;
  r.deg = std::max(a.deg, b.deg);
  for (int i = 0; i <= r.deg; ++i) r.c[i] = a.c[i] + b.c[i];
  return r;
}

// Real roots of p (degree <= 8) via the companion matrix. Not inlined: so
// the eigen-solver is inlined into it, as GCC chose when this was one file
// with the rest of the IK (ist6 92 387 -> 92 259 instructions per solve).
[[gnu::noinline]] int real_roots(const Poly& p, double* out) {
  double mx = 0;
  for (int i = 0; i <= p.deg; ++i) mx = std::max(mx, std::abs(p.c[i]));
  if (!(mx > 0)) return 0;
  int deg = p.deg;
  while (deg > 0 && std::abs(p.c[deg]) <= 1e-13 * mx) --deg;
  if (deg == 0) return 0;
  using Mat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor, 8, 8>;
  Mat comp = Mat::Zero(deg, deg);
  for (int i = 1; i < deg; ++i) comp(i, i - 1) = 1.0;
  for (int i = 0; i < deg; ++i) comp(i, deg - 1) = -p.c[i] / p.c[deg];
  Eigen::EigenSolver<Mat> es(comp, false);
  if (es.info() != Eigen::Success) return 0;
  int n = 0;
  for (int i = 0; i < deg; ++i) {
    const std::complex<double> z = es.eigenvalues()[i];
    if (std::abs(z.imag()) <= 1e-4 * (1.0 + std::abs(z.real()))) out[n++] = z.real();
  }
  return n;
}

// One coefficient row (v0, v1, v2) of the q3 basis as a quadratic in x:
// revolute, m3 = sigma + 2 atan(x), times (1 + x^2); prismatic: v0 + v1 x + v2 x^2.
Poly row_poly(const Eigen::Vector3d& v, bool prismatic, double sigma) {
  Poly p;
  p.deg = 2;
  if (prismatic) {
    p.c[0] = v[0]; p.c[1] = v[1]; p.c[2] = v[2];
    return p;
  }
  const double cs = std::cos(sigma), sn = std::sin(sigma);
  const double v1 = v[1] * cs + v[2] * sn, v2 = -v[1] * sn + v[2] * cs;
  p.c[0] = v[0] + v1;
  p.c[1] = 2 * v2;
  p.c[2] = v[0] - v1;
  return p;
}

void newton_polish(const IkSolverData& m, const Eigen::Matrix3d& M1, const Eigen::Matrix3d& M2, double& m2,
                   double& m3) {
  const bool p2 = prism(m, 1), p3 = prism(m, 2);
  for (int it = 0; it < 8; ++it) {
    const Eigen::Vector3d b2 = basis(p2, m2), b3 = basis(p3, m3);
    const Eigen::Vector3d d2 = dbasis(p2, m2), d3 = dbasis(p3, m3);
    const double e1 = b2.dot(M1 * b3), e2 = b2.dot(M2 * b3);
    if (std::abs(e1) < 1e-15 * m.scale * m.scale && std::abs(e2) < 1e-15 * m.scale) return;
    Eigen::Matrix2d J;
    J << d2.dot(M1 * b3), b2.dot(M1 * d3), d2.dot(M2 * b3), b2.dot(M2 * d3);
    const double det = J.determinant();
    if (!(std::abs(det) > 1e-300)) return;
    const Eigen::Vector2d dx = J.inverse() * Eigen::Vector2d(e1, e2);
    if (!detail::all_finite(dx) || dx.norm() > 0.5) return;
    m2 -= dx[0];
    m3 -= dx[1];
  }
}

}  // namespace

int solve_position_resultant(const IkSolverData& m, const Eigen::Matrix3d& M1, const Eigen::Matrix3d& M2, double tol1,
                             PosCand* out) {
  const bool p2 = prism(m, 1), p3 = prism(m, 2);
  int n = 0;
  // Case C: eliminate q2 (resultant), polynomial of degree <= 8 in x.
  double sigma = 0;
  if (!p3) {
    double best = -1;
    for (int k = 0; k < 8; ++k) {
      const double s = 0.3 + k * kPi / 4;
      const Eigen::Vector3d b3 = basis(false, s + kPi);
      const Eigen::Vector3d a1 = M1 * b3, a2 = M2 * b3;
      double F;
      if (!p2) {
        const double D = a1[1] * a2[2] - a2[1] * a1[2];
        const double Nc = a2[0] * a1[2] - a1[0] * a2[2], Ns = a1[0] * a2[1] - a2[0] * a1[1];
        F = Nc * Nc + Ns * Ns - D * D;
      } else {
        const double x = a1[2] * a2[0] - a1[0] * a2[2];
        F = x * x - (a1[2] * a2[1] - a1[1] * a2[2]) * (a1[1] * a2[0] - a1[0] * a2[1]);
      }
      if (std::abs(F) > best) {
        best = std::abs(F);
        sigma = s;
      }
    }
  }
  const Poly al1 = row_poly(M1.row(0).transpose(), p3, sigma), be1 = row_poly(M1.row(1).transpose(), p3, sigma),
             ga1 = row_poly(M1.row(2).transpose(), p3, sigma);
  const Poly al2 = row_poly(M2.row(0).transpose(), p3, sigma), be2 = row_poly(M2.row(1).transpose(), p3, sigma),
             ga2 = row_poly(M2.row(2).transpose(), p3, sigma);
  Poly F;
  if (!p2) {
    const Poly D = psub(pmul(be1, ga2), pmul(be2, ga1));
    const Poly Nc = psub(pmul(al2, ga1), pmul(al1, ga2));
    const Poly Ns = psub(pmul(al1, be2), pmul(al2, be1));
    F = psub(padd(pmul(Nc, Nc), pmul(Ns, Ns)), pmul(D, D));
  } else {
    const Poly X = psub(pmul(ga1, al2), pmul(al1, ga2));
    F = psub(pmul(X, X), pmul(psub(pmul(ga1, be2), pmul(be1, ga2)), psub(pmul(be1, al2), pmul(al1, be2))));
  }
  double xs[8];
  const int nr = real_roots(F, xs);
  for (int i = 0; i < nr && n < 8; ++i) {
    const double m3 = p3 ? xs[i] : sigma + 2.0 * std::atan(xs[i]);
    const Eigen::Vector3d b3 = basis(p3, m3);
    const Eigen::Vector3d a1 = M1 * b3, a2 = M2 * b3;
    double c2[2];
    int nc = 0;
    if (!p2) {
      const double D = a1[1] * a2[2] - a2[1] * a1[2];
      const double Nc = a2[0] * a1[2] - a1[0] * a2[2], Ns = a1[0] * a2[1] - a2[0] * a1[1];
      if (std::abs(D) > 1e-9 * (std::abs(Nc) + std::abs(Ns))) {
        c2[nc++] = D > 0 ? std::atan2(Ns, Nc) : std::atan2(-Ns, -Nc);  // (cos, sin) = (Nc, Ns) / D
      } else {
        const Roots r = solve_basis(a1[0], a1[1], a1[2], false, tol1);
        for (int k = 0; k < r.n; ++k) c2[nc++] = r.v[k];
      }
    } else {
      const double den = a2[2] * a1[1] - a1[2] * a2[1];
      if (std::abs(den) > 1e-300) {
        c2[nc++] = -(a2[2] * a1[0] - a1[2] * a2[0]) / den;
      } else {
        const Roots r = solve_basis(a1[0], a1[1], a1[2], true, tol1);
        for (int k = 0; k < r.n; ++k) c2[nc++] = r.v[k];
      }
    }
    for (int k = 0; k < nc && n < 8; ++k) {
      double m2 = c2[k], mm3 = m3;
      newton_polish(m, M1, M2, m2, mm3);
      const double e1 = basis(p2, m2).dot(M1 * basis(p3, mm3)), e2 = basis(p2, m2).dot(M2 * basis(p3, mm3));
      if (!(std::abs(e1) < 1e-8 * m.scale * m.scale && std::abs(e2) < 1e-8 * m.scale)) continue;
      PosCand& o = out[n++];
      o = {m2, mm3, 0, false};
      set_pair(p2, m2, o.c2, o.s2);
      set_pair(p3, mm3, o.c3, o.s3);
    }
  }
  return n;
}

}  // namespace servoarm::kin::detail
