// SPDX-License-Identifier: Apache-2.0
// Blended joint motion (overlap of straight segments). See blend.hpp for the
// method and the guarantees; the checks are written out below.
#include "servoarm/kinematics/blend.hpp"

#include <algorithm>
#include <cmath>

namespace servoarm::kin {

const char* to_string(BlendStatus s) {
  switch (s) {
    case BlendStatus::ok: return "ok";
    case BlendStatus::blend_reduced: return "blend_reduced";
    case BlendStatus::exact_stop: return "exact_stop";
    case BlendStatus::zero_length: return "zero_length";
    case BlendStatus::bad_input: return "bad_input";
    case BlendStatus::wrong_size: return "wrong_size";
    case BlendStatus::bad_limits: return "bad_limits";
    case BlendStatus::goal_out_of_limits: return "goal_out_of_limits";
    case BlendStatus::queue_full: return "queue_full";
    case BlendStatus::no_solution: return "no_solution";
  }
  return "unknown";
}

namespace {

constexpr double kLimitTol = 1e-9;    // relative slack on the exact peak checks (rounding)
constexpr double kPosTol = 1e-9;      // rad / m, as plan_movej
constexpr double kZeroLength = 1e-12; // shorter segments are zero-length
constexpr int kScan = 12;             // coarse scan of the overlap (largest first)
constexpr int kBisect = 30;           // refinements after the scan

std::size_t slot(std::span<const BlendSegment> seg, std::uint64_t seq) {
  return static_cast<std::size_t>(seq % seg.size());
}

// Index of the profile piece active at time t (t relative to the profile start).
int piece_at(const JointProfile& p, double t) {
  int i = p.n - 1;
  while (i > 0 && t < p.seg[static_cast<std::size_t>(i)].t0) --i;
  return i;
}

struct State3 {
  double p, v, a, j;
};

State3 eval_piece(const JointProfile& p, int i, double t) {
  const JerkSegment& s = p.seg[static_cast<std::size_t>(i)];
  const double dt = std::max(t - s.t0, 0.0);
  return State3{s.p + dt * (s.v + dt * (0.5 * s.a + dt * s.j / 6.0)), s.v + dt * (s.a + 0.5 * s.j * dt),
                s.a + s.j * dt, s.j};
}

// Exact peaks of |v|, |a|, |j| of every joint of
//   q(t) = sA(t - startA) dA + sB(t - startB) dB     over [t1, t2]
// (both profiles piecewise cubic: between the union of their breakpoints the
// sum is one cubic per joint; |v| peaks at the ends or where a = 0, |a| at the
// ends, |j| is constant). Returns false as soon as a joint exceeds its limits.
bool sum_within_limits(const JointLimits& lim, const BlendSegment& A, const BlendSegment& B, double t1, double t2) {
  if (!(t2 > t1)) return true;
  // Breakpoints inside (t1, t2), in order: merge the two profiles' piece starts.
  std::array<double, 2 * kMaxSegments + 2> bp{};
  int nb = 0;
  bp[static_cast<std::size_t>(nb++)] = t1;
  int ia = 0, ib = 0;
  while (ia < A.s.n || ib < B.s.n) {
    const double ta = ia < A.s.n ? A.start + A.s.seg[static_cast<std::size_t>(ia)].t0 : 1e300;
    const double tb = ib < B.s.n ? B.start + B.s.seg[static_cast<std::size_t>(ib)].t0 : 1e300;
    const double t = std::min(ta, tb);
    if (ta <= tb) ++ia; else ++ib;
    if (t > bp[static_cast<std::size_t>(nb - 1)] && t < t2) bp[static_cast<std::size_t>(nb++)] = t;
  }
  bp[static_cast<std::size_t>(nb++)] = t2;
  for (int k = 0; k + 1 < nb; ++k) {
    const double a = bp[static_cast<std::size_t>(k)], b = bp[static_cast<std::size_t>(k + 1)];
    const double mid = 0.5 * (a + b);
    const int pa = piece_at(A.s, mid - A.start), pb = piece_at(B.s, mid - B.start);
    const State3 sa0 = eval_piece(A.s, pa, a - A.start), sb0 = eval_piece(B.s, pb, a - B.start);
    const double len = b - a;
    for (int i = 0; i < lim.n; ++i) {
      const JointDynamics& d = lim.dyn[static_cast<std::size_t>(i)];
      const double da = A.delta[i], db = B.delta[i];
      const double v0 = sa0.v * da + sb0.v * db, a0 = sa0.a * da + sb0.a * db, j = sa0.j * da + sb0.j * db;
      const double a1 = a0 + j * len;
      const double vmax = d.max_velocity * (1 + kLimitTol), amax = d.max_acceleration * (1 + kLimitTol),
                   jmax = d.max_jerk * (1 + kLimitTol);
      if (std::fabs(j) > jmax || std::fabs(a0) > amax || std::fabs(a1) > amax) return false;
      const double v1 = v0 + len * (a0 + 0.5 * j * len);
      if (std::fabs(v0) > vmax || std::fabs(v1) > vmax) return false;
      if (j != 0) {
        const double tv = -a0 / j;
        if (tv > 0 && tv < len && std::fabs(v0 + tv * (a0 + 0.5 * j * tv)) > vmax) return false;
      }
    }
  }
  return true;
}

struct Corner {
  const JointLimits* lim;
  const BlendSegment* A;  // segment into the corner (its profile, start, delta)
  BlendSegment* B;        // segment out of the corner; B->start is set by try_overlap
  double cos_theta;       // angle between the two directions
  JointVector corner;     // W(k)
  double d_in = 0, d_out = 0, radius = 0;
};

// Geometry of an overlap tau: d_in, d_out and the radius bound (see blend.hpp).
void geometry(Corner& c, double tau) {
  double p, v, a;
  eval_profile(c.A->s, c.A->duration - tau, p, v, a);
  c.d_in = std::max(1.0 - p, 0.0) * c.A->length;
  eval_profile(c.B->s, tau, p, v, a);
  c.d_out = std::max(p, 0.0) * c.B->length;
  const double r2 = c.d_in * c.d_in + c.d_out * c.d_out - 2.0 * c.d_in * c.d_out * c.cos_theta;
  c.radius = std::max({c.d_in, c.d_out, std::sqrt(std::max(r2, 0.0))});
}

// Every check for an overlap tau (tolerance, position limits, exact v/a/j peaks).
bool feasible(Corner& c, double tau, double tol) {
  geometry(c, tau);
  if (c.radius > tol) return false;
  // Fourth vertex of the parallelogram: W - d_in u_A + d_out u_B.
  for (int i = 0; i < c.lim->n; ++i) {
    const auto k = static_cast<std::size_t>(i);
    const double x = c.corner[i] - c.d_in * c.A->delta[i] / c.A->length + c.d_out * c.B->delta[i] / c.B->length;
    if (x < c.lim->lower[k] - kPosTol || x > c.lim->upper[k] + kPosTol) return false;
  }
  const double start_b = c.A->end() - tau;
  c.B->start = start_b;
  return sum_within_limits(*c.lim, *c.A, *c.B, start_b, c.A->end());
}

bool positive_finite(double x) { return std::isfinite(x) && x > 0; }

// Rest-to-rest path-parameter profile of b (delta, length set) with shares of the
// acceleration (sa) and jerk (sj) limits: the slowest joint sets each limit.
bool plan_profile(const JointLimits& L, double sa, double sj, BlendSegment& b) {
  Limits1 sl{1e300, 1e300, 1e300};
  for (int i = 0; i < L.n; ++i) {
    const double di = std::fabs(b.delta[i]);
    if (!(di > 0)) continue;
    const JointDynamics& d = L.dyn[static_cast<std::size_t>(i)];
    sl.v = std::min(sl.v, d.max_velocity / di);
    sl.a = std::min(sl.a, sa * d.max_acceleration / di);
    sl.j = std::min(sl.j, sj * d.max_jerk / di);
  }
  b.share = std::min(sa, sj);
  b.s.n = 0;
  const double T = plan_1d(0.0, 0.0, 0.0, 0.0, 1.0, sl, 0.0, b.s);
  if (!(T > 0) || !std::isfinite(T)) return false;
  b.duration = T;
  return true;
}

}  // namespace

void blend_reset(BlendCore& core, const JointLimits& limits, const JointVector& rest) {
  core.limits = limits;
  core.rest = rest;
  core.head = 0;
  core.count = 0;
}

BlendStatus blend_append(BlendCore& core, std::span<BlendSegment> seg, const JointVector& w, double tolerance,
                         double t_earliest, BlendReport* report) {
  if (report) *report = BlendReport{};
  const JointLimits& L = core.limits;
  const int n = L.n;
  if (n < 1 || n > kMaxJoints) return BlendStatus::bad_limits;
  for (int i = 0; i < n; ++i) {
    const JointDynamics& d = L.dyn[static_cast<std::size_t>(i)];
    if (!positive_finite(d.max_velocity) || !positive_finite(d.max_acceleration) || !positive_finite(d.max_jerk))
      return BlendStatus::bad_limits;
  }
  if (w.size() != n || core.rest.size() != n) return BlendStatus::wrong_size;
  if (!w.allFinite() || !std::isfinite(tolerance) || tolerance < 0 || !std::isfinite(t_earliest))
    return BlendStatus::bad_input;
  for (int i = 0; i < n; ++i) {
    const auto k = static_cast<std::size_t>(i);
    if (w[i] < L.lower[k] - kPosTol || w[i] > L.upper[k] + kPosTol) return BlendStatus::goal_out_of_limits;
  }
  BlendSegment* prev = core.count ? &seg[slot(seg, core.head + core.count - 1)] : nullptr;
  const JointVector from = prev ? JointVector(prev->from + prev->delta) : core.rest;
  // Zero-filled first: gcc 12 for armhf (-O3) warns that the fixed-capacity vector's
  // coefficients "may be used uninitialized" after `w - from` (-Werror breaks that build).
  JointVector delta = JointVector::Zero(w.size());
  delta = w - from;
  const double length = delta.norm();
  if (!(length > kZeroLength)) {
    if (prev) prev->tolerance = tolerance;
    if (report) report->status = BlendStatus::zero_length;
    return BlendStatus::zero_length;
  }
  if (core.count >= seg.size()) return BlendStatus::queue_full;

  // Candidate profiles for the new segment (rest to rest in s): full limits,
  // half the jerk, half the acceleration and jerk. Less jerk/acceleration makes
  // the segment slower but lets its start overlap more of the previous one; the
  // candidate whose segment ends first is taken (greedy, bounded: 3 candidates).
  BlendSegment& nb = seg[slot(seg, core.head + core.count)];
  const double prev_tol = prev ? prev->tolerance : 0.0;
  const bool may_blend = prev && prev_tol > 0 && prev->end() > t_earliest;
  struct Share {
    double a, j;
  };
  const Share shares[] = {{1.0, 1.0}, {1.0, kBlendShare}, {kBlendShare, kBlendShare}};
  const int n_cand = may_blend ? 3 : (tolerance > 0 ? 2 : 1);
  const int first_cand = (!may_blend && tolerance > 0) ? 1 : 0;  // blended end ahead: half jerk
  BlendSegment best_seg;
  BlendStatus best_status = BlendStatus::ok;
  BlendReport best_rep;
  double best_end = 1e300;
  bool have = false;
  // The previous segment may be replanned at full limits if it has not started
  // and starts from rest (nothing before it depends on its profile): a corner
  // that cannot gain from blending is then an exact stop at full limits.
  BlendSegment prev_full;
  const bool replan_prev = prev && prev->share < 1 && prev->blend_in == 0 && prev->start >= t_earliest &&
                           (prev_full = *prev, plan_profile(L, 1.0, 1.0, prev_full));
  bool prev_replanned = false;
  for (int pv = 0; pv < (replan_prev ? 2 : 1); ++pv)
  for (int ci = (pv ? 0 : first_cand); ci < n_cand; ++ci) {
    BlendSegment b;
    const BlendSegment* A = pv ? &prev_full : prev;
    b.from = from;
    b.delta = delta;
    b.length = length;
    b.tolerance = tolerance;
    if (!plan_profile(L, shares[ci].a, shares[ci].j, b)) continue;
    const double T = b.duration;
    BlendStatus status = BlendStatus::ok;
    BlendReport rep;
    double tau_best = 0;
    if (!prev || A->end() <= t_earliest) {
      b.start = prev ? std::max(A->end(), t_earliest) : t_earliest;
      if (prev && prev_tol > 0) status = BlendStatus::exact_stop;
    } else if (!(prev_tol > 0)) {
      b.start = A->end();
    } else {
      Corner c{&L, A, &b, 0.0, from};
      c.cos_theta = std::clamp(A->delta.dot(delta) / (A->length * length), -1.0, 1.0);
      // Largest overlap: half of either segment, and not before t_earliest.
      // At most two segments move at once: the new one starts no earlier than the
      // end of the one before `prev` (A->blend_in is that overlap).
      const double tau_half = kBlendMaxFraction * std::min(A->duration - A->blend_in, T);
      const double tau_cap = std::min(tau_half, A->end() - t_earliest);
      // Tolerance alone (monotone in tau: d_in and d_out grow with it).
      auto tol_ok = [&](double tau) {
        geometry(c, tau);
        return c.radius <= prev_tol;
      };
      double tau_tol = tau_half;
      const bool half_binds = tol_ok(tau_half);  // the tolerance would allow more than half a segment
      if (!half_binds) {
        double lo = 0, hi = tau_half;
        for (int it = 0; it < 50; ++it) {
          const double m = 0.5 * (lo + hi);
          (tol_ok(m) ? lo : hi) = m;
        }
        tau_tol = lo;
      }
      const double tau_top = std::min(tau_tol, tau_cap);
      int checks = 0;
      double best = 0, fail = tau_top;
      // Coarse scan from the top down; then bisect between the first feasible
      // value and the infeasible one above it (best stays feasible throughout).
      for (int k = 0; k < kScan; ++k) {
        const double tau = tau_top * (1.0 - static_cast<double>(k) / kScan);
        ++checks;
        if (tau > 0 && feasible(c, tau, prev_tol)) {
          best = tau;
          break;
        }
        fail = tau;
      }
      if (best < tau_top) {
        double lo = best, hi = fail;
        for (int it = 0; it < kBisect && hi - lo > 1e-9 * std::max(1.0, hi); ++it) {
          const double m = 0.5 * (lo + hi);
          ++checks;
          if (feasible(c, m, prev_tol)) lo = m; else hi = m;
        }
        best = lo;
      }
      if (best > 0) {
        ++checks;
        if (!feasible(c, best, prev_tol)) best = 0;  // cannot happen (best was checked); kept as the invariant
      }
      if (best > 0) {
        geometry(c, best);
        b.start = A->end() - best;
        b.blend_in = best;
        if (best < tau_tol * (1 - 1e-6) || half_binds) status = BlendStatus::blend_reduced;
        rep.corner_radius = c.radius;
      } else {
        b.start = A->end();
        b.blend_in = 0;
        status = BlendStatus::exact_stop;
      }
      tau_best = best;
      rep.blend = best;
      rep.blend_max = tau_tol;
      rep.checks = checks;
    }
    rep.status = status;
    if (!have || b.end() < best_end * (1 - 1e-12)) {
      have = true;
      best_end = b.end();
      best_seg = b;
      best_status = status;
      best_rep = rep;
      best_rep.blend = tau_best;
      prev_replanned = pv == 1;
    }
  }
  if (!have) return BlendStatus::no_solution;
  if (prev_replanned) *prev = prev_full;
  if (prev) {
    prev->blend = best_rep.blend;
    prev->corner_radius = best_rep.blend > 0 ? best_rep.corner_radius : 0.0;
  }
  BlendSegment& b = best_seg;
  const BlendStatus status = best_status;
  if (report) *report = best_rep;
  b.blend = 0;
  b.corner_radius = 0;
  nb = b;
  ++core.count;
  return status;
}

void blend_sample(const BlendCore& core, std::span<const BlendSegment> seg, double t, JointVector& pos,
                  JointVector& vel, JointVector& acc) {
  const int n = core.limits.n;
  pos.resize(n);
  vel.resize(n);
  acc.resize(n);
  vel.setZero();
  acc.setZero();
  if (core.count == 0) {
    pos = core.rest;
    return;
  }
  const BlendSegment& first = seg[slot(seg, core.head)];
  if (!(t >= first.start)) {  // also NaN: hold
    pos = first.from;
    return;
  }
  // Last segment with start <= t (starts are non-decreasing).
  std::uint64_t lo = 0, hi = core.count;  // invariant: start(lo) <= t, start(hi) > t or hi == count
  while (hi - lo > 1) {
    const std::uint64_t m = (lo + hi) / 2;
    if (seg[slot(seg, core.head + m)].start <= t) lo = m; else hi = m;
  }
  const BlendSegment& k = seg[slot(seg, core.head + lo)];
  double p, v, a;
  eval_profile(k.s, t - k.start, p, v, a);
  pos = k.from + p * k.delta;
  vel = v * k.delta;
  acc = a * k.delta;
  if (lo > 0) {
    const BlendSegment& j = seg[slot(seg, core.head + lo - 1)];
    if (t < j.end()) {
      eval_profile(j.s, t - j.start, p, v, a);
      pos += (p - 1.0) * j.delta;
      vel += v * j.delta;
      acc += a * j.delta;
    }
  }
}

void blend_retire(BlendCore& core, std::span<const BlendSegment> seg, double t) {
  while (core.count > 0) {
    const BlendSegment& h = seg[slot(seg, core.head)];
    if (!(h.end() <= t)) break;
    core.rest = h.from + h.delta;
    ++core.head;
    --core.count;
  }
}

double joint_tolerance_for_tool(const Chain& chain, double tool_tolerance) {
  if (!positive_finite(tool_tolerance) || chain.n_joints < 1) return 0.0;
  double sum2 = 0;
  const double tool = chain.tool.translation().norm();
  for (int j = 0; j < chain.n_joints; ++j) {
    const DhRow& row = chain.joint(j);
    double R = 1.0;  // prismatic: the tool point moves by exactly |dq|
    if (row.type != JointType::prismatic) {
      R = tool;
      for (int r = chain.joint_row[static_cast<std::size_t>(j)]; r < chain.n_rows; ++r) {
        const DhRow& x = chain.rows[static_cast<std::size_t>(r)];
        R += std::fabs(x.a) + std::fabs(x.d);
        if (x.type == JointType::prismatic) R += std::max(std::fabs(x.lower), std::fabs(x.upper));
      }
    }
    sum2 += R * R;
  }
  if (!std::isfinite(sum2) || !(sum2 > 0)) return 0.0;
  return tool_tolerance / std::sqrt(sum2);
}

}  // namespace servoarm::kin
