// SPDX-License-Identifier: Apache-2.0
// Inverse kinematics, the general position subproblem: when neither equation
// of (E1, E2) is free of q2 or of q3 (e.g. ist6, whose axes 1 and 2 do not
// meet), q2 is eliminated by the resultant, a polynomial of degree <= 8 in
// tan(q3/2) (or d3) whose real roots are isolated along its derivative
// chain (the 8x8 companion matrix's eigenvalues where the isolation is
// unsure: real_roots), each polished by Newton on (E1, E2). Heap-free.
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

constexpr double kEps = 2.220446049250313e-16;
// A complex pair closer than this (times 1 + |x|) to the real axis counts as
// a (double) real root: the companion path's imaginary-part tolerance.
constexpr double kTangent = 1e-4;

// Value of the monic polynomial a of degree N (a[N] = 1, not read).
template <int N>
inline double horner(const double* a, double x) {
  double p = 1;
#pragma GCC unroll 8
  for (int i = N - 1; i >= 0; --i) p = p * x + a[i];
  return p;
}

// The root of the monic a (degree N) in [lo, hi], where it is monotone, has
// the sign pos_lo at lo and the other at hi, from x in [lo, hi]: Newton,
// bisection when a step leaves the bracket. A Newton step of at most
// tol (1 + |x|) is the last: after it the error is of the order of the step
// squared (times p'' / 2p'). false: not converged in 100 steps.
template <int N>
bool refine_root(const double* a, double lo, double hi, bool pos_lo, double x, double tol, double& root) {
  for (int it = 0; it < 100; ++it) {
    double p = 1, d = 0;
#pragma GCC unroll 8
    for (int i = N - 1; i >= 0; --i) {
      d = d * x + p;
      p = p * x + a[i];
    }
    if (p == 0) {
      root = x;
      return true;
    }
    if ((p > 0) == pos_lo) lo = x;
    else hi = x;
    const double xn = d != 0 ? x - p / d : hi + (hi - lo);  // d = 0 (a critical end point): bisect
    const bool inside = xn >= lo && xn <= hi;  // false for NaN too
    const double scale = 1 + std::abs(x);
    if (inside && std::abs(xn - x) <= tol * scale) {
      root = xn;
      return true;
    }
    if (hi - lo <= 2 * kEps * scale) {
      root = 0.5 * (lo + hi);
      return true;
    }
    x = inside ? xn : 0.5 * (lo + hi);
  }
  return false;
}

// Newton's last step: 1e-8 for the split points (the next level needs them to
// well within kTangent), 1e-10 for the roots of p (then polished on (E1, E2)).
constexpr double kStepSplit = 1e-8, kStepRoot = 1e-10;

// One level of the derivative chain: the real roots of P[N] (monic, degree
// N), ascending, into o, from the split points r[0..nr): the real roots of
// P[N - 1] = P[N]' / N and the points where P[N - 1] nearly touches zero
// (nr = 0: none; P[N] is then monotone and is split at the roots' centroid).
// P[N - 2] gives the second derivative. top: P[N] is p. Returns the count or
// -1 (unsure, see real_roots_isolated).
template <int N>
int chain_level(const double (&P)[9][9], bool top, double* r, int nr, double* o) {
  const double* a = P[N];
  double v[8];
  int sg[8];
  const bool virt = nr == 0;  // the split point is not a critical point
  if (virt) {
    r[0] = -a[N - 1] / N;
    nr = 1;
  }
  for (int j = 0; j < nr; ++j) {
    // Horner with its running error bound (Higham, Accuracy and Stability of
    // Numerical Algorithms, 5.1): |computed - exact| <= eps (2 e - |p|).
    const double x = r[j], ax = std::abs(x);
    double p = 1, e = 0.5;
#pragma GCC unroll 8
    for (int i = N - 1; i >= 0; --i) {
      p = p * x + a[i];
      e = e * ax + std::abs(p);
    }
    if (!std::isfinite(p) || !std::isfinite(e)) return -1;
    v[j] = p;
    // Below the rounding bound at a critical point: a (near-)double root
    // whose two real roots cannot be told from a complex pair: unsure.
    const bool zero = std::abs(p) <= 2 * kEps * (2 * e - std::abs(p));
    if (zero && !virt) return -1;
    sg[j] = zero ? 0 : (p > 0 ? 1 : -1);
  }
  // P[N]'' at split point j (P[0] = 1).
  auto second = [&](int j) { return N * (N - 1) * horner<N - 2>(P[N - 2], r[j]); };
  const double tol = top ? kStepRoot : kStepSplit;
  const int s_minf = (N % 2 == 0) ? 1 : -1;  // the sign at -infinity (monic)
  int nn = 0;
  for (int k = 0; k <= nr; ++k) {
    if (k > 0) {  // split point k - 1: a root, or a near-touching extremum
      const int j = k - 1;
      bool add = sg[j] == 0;
      if (!add && !virt) {
        const int sl = j == 0 ? s_minf : sg[j - 1], sr = j + 1 == nr ? 1 : sg[j + 1];
        if (sl != -sg[j] && sr != -sg[j]) {  // no root beside it
          // v + P'' h^2 / 2 = 0 at h = i t: a complex pair within t of the axis
          const double t = kTangent * (1 + std::abs(r[j]));
          add = 2 * std::abs(v[j]) <= std::abs(second(j)) * t * t;
        }
      }
      if (add) {
        // A near-double root of p itself: unsure (the companion matrix's
        // pair of eigenvalues there is what the path did before).
        if (top && sg[j] != 0) return -1;
        if (nn >= N) return -1;
        o[nn++] = r[j];
      }
    }
    const int sl = k == 0 ? s_minf : sg[k - 1], sr = k == nr ? 1 : sg[k];
    if (sl == 0 || sr == 0 || sl == sr) continue;
    if (nn >= N) return -1;
    if (k > 0 && k < nr) {  // between two split points: P[N] monotone
      if (!refine_root<N>(a, r[k - 1], r[k], sl > 0, 0.5 * (r[k - 1] + r[k]), tol, o[nn])) return -1;
      ++nn;
      continue;
    }
    // Unbounded: from the split point's Taylor expansion v + P'' h^2 / 2 = 0
    // (exact for N = 2), widened until the sign is the one at infinity.
    const int j = k == 0 ? 0 : nr - 1;
    const double x0 = r[j], dirn = k == 0 ? -1.0 : 1.0;
    const int s_inf = k == 0 ? s_minf : 1;
    double h = 0;
    if (!virt) {
      const double p2 = second(j);
      if (p2 * v[j] < 0) h = std::sqrt(-2 * v[j] / p2);
    }
    if (N == 2 && h > 0) {
      o[nn++] = x0 + dirn * h;
      continue;
    }
    if (!(h > 0 && std::isfinite(h))) h = 1 + std::abs(x0);
    double near = x0, far = x0 + dirn * h, f = 2;
    int w = 0;
    for (;; ++w) {
      const double pf = horner<N>(a, far);
      if (!std::isfinite(pf) || w >= 60) return -1;
      if (pf == 0 || (pf > 0) == (s_inf > 0)) break;
      near = far;
      h *= f;
      f = std::min(2 * f, 16.0);
      far = x0 + dirn * h;
    }
    // Newton from the Taylor point (w = 0: of the sign at infinity) or the
    // last point short of the root.
    if (!refine_root<N>(a, std::min(near, far), std::max(near, far), k == 0 ? s_inf > 0 : sl > 0,
                        w == 0 ? far : near, tol, o[nn]))
      return -1;
    ++nn;
  }
  return nn;
}

}  // namespace

// Derivative chain (ik_detail.hpp). P[n] is the monic derivative of p of
// degree n: P[deg] = p / c[deg], P[n - 1] = P[n]' / n. The real roots of
// P[n - 1] (and its near-touching critical points) split the line into
// intervals where P[n] is monotone: one root per sign change. Adding split
// points never loses a root (P[n] stays monotone on each piece), which is why
// the near-touching points of the derivatives are added. Heap-free.
int real_roots_isolated(const double* c, int deg, double* out) {
  if (deg < 1 || deg > 8 || !(c[deg] != 0)) return -1;
  double P[9][9];
  const double inv = 1.0 / c[deg];
  for (int i = 0; i < deg; ++i) P[deg][i] = c[i] * inv;
  P[deg][deg] = 1;
  for (int n = deg; n > 1; --n) {
    const double in = 1.0 / n;
    for (int i = 0; i < n - 1; ++i) P[n - 1][i] = (i + 1) * P[n][i + 1] * in;
    P[n - 1][n - 1] = 1;
  }
  P[0][0] = 1;
  double buf[2][8];
  double *r = buf[0], *o = buf[1];
  int nr = 1;
  r[0] = -P[1][0];
  if (!std::isfinite(r[0])) return -1;
  for (int n = 2; n <= deg; ++n) {
    const bool top = n == deg;
    int nn = -1;
    switch (n) {
      case 2: nn = chain_level<2>(P, top, r, nr, o); break;
      case 3: nn = chain_level<3>(P, top, r, nr, o); break;
      case 4: nn = chain_level<4>(P, top, r, nr, o); break;
      case 5: nn = chain_level<5>(P, top, r, nr, o); break;
      case 6: nn = chain_level<6>(P, top, r, nr, o); break;
      case 7: nn = chain_level<7>(P, top, r, nr, o); break;
      case 8: nn = chain_level<8>(P, top, r, nr, o); break;
      default: break;
    }
    if (nn < 0) return -1;
    std::swap(r, o);
    nr = nn;
  }
  for (int i = 0; i < nr; ++i) out[i] = r[i];
  return nr;
}

// Real roots via the companion matrix. Not inlined: so the eigen-solver is
// inlined into it, as GCC chose when this was one file with the rest of the IK.
[[gnu::noinline]] int real_roots_eigen(const double* c, int deg, double* out) {
  if (deg < 1 || deg > 8 || !(c[deg] != 0)) return 0;
  using Mat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor, 8, 8>;
  Mat comp = Mat::Zero(deg, deg);
  for (int i = 1; i < deg; ++i) comp(i, i - 1) = 1.0;
  for (int i = 0; i < deg; ++i) comp(i, deg - 1) = -c[i] / c[deg];
  Eigen::EigenSolver<Mat> es(comp, false);
  if (es.info() != Eigen::Success) return 0;
  int n = 0;
  for (int i = 0; i < deg; ++i) {
    const std::complex<double> z = es.eigenvalues()[i];
    if (std::abs(z.imag()) <= kTangent * (1.0 + std::abs(z.real()))) out[n++] = z.real();
  }
  std::sort(out, out + n);
  return n;
}

namespace {

// Real roots of p (degree <= 8, trailing coefficients below 1e-13 of the
// largest dropped): isolation, the companion matrix where it is unsure (or
// where the model asks for it: IkSolverData::eigen_roots).
int real_roots(const Poly& p, double* out, bool eigen_only) {
  double mx = 0;
  for (int i = 0; i <= p.deg; ++i) mx = std::max(mx, std::abs(p.c[i]));
  if (!(mx > 0)) return 0;
  int deg = p.deg;
  while (deg > 0 && std::abs(p.c[deg]) <= 1e-13 * mx) --deg;
  if (deg == 0) return 0;
  if (!eigen_only) {
    const int n = real_roots_isolated(p.c, deg, out);
    if (n >= 0) return n;
  }
  return real_roots_eigen(p.c, deg, out);
}

// One coefficient row (v0, v1, v2) of the q3 basis as a quadratic in x:
// revolute, m3 = sigma + 2 atan(x) (cs, sn = cos, sin sigma), times (1 + x^2);
// prismatic: v0 + v1 x + v2 x^2.
Poly row_poly(const Eigen::Vector3d& v, bool prismatic, double cs, double sn) {
  Poly p;
  p.deg = 2;
  if (prismatic) {
    p.c[0] = v[0]; p.c[1] = v[1]; p.c[2] = v[2];
    return p;
  }
  const double v1 = v[1] * cs + v[2] * sn, v2 = -v[1] * sn + v[2] * cs;
  p.c[0] = v[0] + v1;
  p.c[1] = 2 * v2;
  p.c[2] = v[0] - v1;
  return p;
}

// A motion value with its basis pair: revolute (m, cos m, sin m), prismatic
// (m, m, m^2) (the basis is (1, c, s) either way).
struct Motion {
  double m, c, s;
};
inline Motion motion(bool prismatic, double m) {
  Motion r{m, m, m * m};
  if (!prismatic) sincos_poly(m, r.s, r.c);
  return r;
}

// Newton on (E1, E2) = (b2 . M1 b3, b2 . M2 b3) from (u2, u3), at most 8
// steps (stops when converged, singular or the step exceeds 0.5); true if
// the result satisfies E1 < 1e-8 scale^2, E2 < 1e-8 scale. The pairs come in
// with the candidate (no sine or cosine for a root that needs no step).
bool newton_polish(const IkSolverData& m, const Eigen::Matrix3d& M1, const Eigen::Matrix3d& M2, Motion& u2,
                   Motion& u3) {
  const bool p2 = prism(m, 1), p3 = prism(m, 2);
  for (int it = 0;; ++it) {
    const Eigen::Vector3d b2(1.0, u2.c, u2.s), b3(1.0, u3.c, u3.s);
    const Eigen::Vector3d a1 = M1 * b3, a2 = M2 * b3;
    const double e1 = b2.dot(a1), e2 = b2.dot(a2);
    const bool ok = std::abs(e1) < 1e-8 * m.scale * m.scale && std::abs(e2) < 1e-8 * m.scale;
    if (it == 8 || (std::abs(e1) < 1e-15 * m.scale * m.scale && std::abs(e2) < 1e-15 * m.scale)) return ok;
    const Eigen::Vector3d d2 = p2 ? Eigen::Vector3d(0.0, 1.0, 2.0 * u2.m) : Eigen::Vector3d(0.0, -u2.s, u2.c);
    const Eigen::Vector3d d3 = p3 ? Eigen::Vector3d(0.0, 1.0, 2.0 * u3.m) : Eigen::Vector3d(0.0, -u3.s, u3.c);
    Eigen::Matrix2d J;
    J << d2.dot(a1), b2.dot(M1 * d3), d2.dot(a2), b2.dot(M2 * d3);
    const double det = J.determinant();
    if (!(std::abs(det) > 1e-300)) return ok;
    const Eigen::Vector2d dx = J.inverse() * Eigen::Vector2d(e1, e2);
    if (!detail::all_finite(dx) || dx.norm() > 0.5) return ok;
    u2 = motion(p2, u2.m - dx[0]);
    u3 = motion(p3, u3.m - dx[1]);
  }
}

}  // namespace

int solve_position_resultant(const IkSolverData& m, const Eigen::Matrix3d& M1, const Eigen::Matrix3d& M2, double tol1,
                             PosCand* out) {
  const bool p2 = prism(m, 1), p3 = prism(m, 2);
  int n = 0;
  // Case C: eliminate q2 (resultant), polynomial of degree <= 8 in x. The
  // half-angle origin sigma (revolute q3) is the one of eight where the
  // resultant is largest at x = infinity (m3 = sigma + pi): its leading
  // coefficient is not small.
  double sigma = 0, cs = 1, sn = 0;
  if (!p3) {
    double best = -1;
    for (int k = 0; k < 8; ++k) {
      const double s = 0.3 + k * kPi / 4;
      double ck, sk;
      sincos_poly(s, sk, ck);
      const Eigen::Vector3d b3(1.0, -ck, -sk);  // basis at s + pi
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
        cs = ck;
        sn = sk;
      }
    }
  }
  const Poly al1 = row_poly(M1.row(0).transpose(), p3, cs, sn), be1 = row_poly(M1.row(1).transpose(), p3, cs, sn),
             ga1 = row_poly(M1.row(2).transpose(), p3, cs, sn);
  const Poly al2 = row_poly(M2.row(0).transpose(), p3, cs, sn), be2 = row_poly(M2.row(1).transpose(), p3, cs, sn),
             ga2 = row_poly(M2.row(2).transpose(), p3, cs, sn);
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
  const int nr = real_roots(F, xs, m.eigen_roots);
  for (int i = 0; i < nr && n < 8; ++i) {
    Motion u3;
    if (p3) {
      u3 = {xs[i], xs[i], xs[i] * xs[i]};
    } else {  // m3 = sigma + 2 atan(x): (cos, sin) of 2 atan(x) rotated by sigma
      const double x = xs[i], q = 1.0 / (1.0 + x * x);
      const double ct = (1.0 - x * x) * q, st = 2.0 * x * q;
      u3 = {sigma + 2.0 * atan2_poly(x, 1.0), cs * ct - sn * st, sn * ct + cs * st};
    }
    const Eigen::Vector3d b3(1.0, u3.c, u3.s);
    const Eigen::Vector3d a1 = M1 * b3, a2 = M2 * b3;
    Motion c2[2];
    int nc = 0;
    if (!p2) {
      const double D = a1[1] * a2[2] - a2[1] * a1[2];
      const double Nc = a2[0] * a1[2] - a1[0] * a2[2], Ns = a1[0] * a2[1] - a2[0] * a1[1];
      const double nn = Nc * Nc + Ns * Ns;
      if (nn > 0 && std::abs(D) > 1e-9 * (std::abs(Nc) + std::abs(Ns))) {
        // (cos, sin) = (Nc, Ns) / D, normalised
        const double sg = D > 0 ? 1.0 : -1.0, h = sg / std::sqrt(nn);
        c2[nc++] = {atan2_poly(sg * Ns, sg * Nc), Nc * h, Ns * h};
      } else {
        const Roots r = solve_basis(a1[0], a1[1], a1[2], false, tol1);
        for (int k = 0; k < r.n; ++k) c2[nc++] = {r.v[k], r.c[k], r.s[k]};
      }
    } else {
      const double den = a2[2] * a1[1] - a1[2] * a2[1];
      if (std::abs(den) > 1e-300) {
        const double d2 = -(a2[2] * a1[0] - a1[2] * a2[0]) / den;
        c2[nc++] = {d2, d2, d2 * d2};
      } else {
        const Roots r = solve_basis(a1[0], a1[1], a1[2], true, tol1);
        for (int k = 0; k < r.n; ++k) c2[nc++] = {r.v[k], r.v[k], r.v[k] * r.v[k]};
      }
    }
    for (int k = 0; k < nc && n < 8; ++k) {
      Motion u2 = c2[k], v3 = u3;
      if (!newton_polish(m, M1, M2, u2, v3)) continue;
      PosCand& o = out[n++];
      o = {u2.m, v3.m, 0, false};
      o.c2 = u2.c;
      o.s2 = p2 ? 0 : u2.s;
      o.c3 = v3.c;
      o.s3 = p3 ? 0 : v3.s;
    }
  }
  return n;
}

}  // namespace servoarm::kin::detail
