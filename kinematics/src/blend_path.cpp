// SPDX-License-Identifier: Apache-2.0
// Blended line and joint segments (blend_path.hpp): superposition, window checks sampled
// at the control rate, the largest overlap that passes.
#include "servoarm/kinematics/blend_path.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

namespace servoarm::kin {

namespace {

constexpr double kPosTol = 1e-9;  // rad / m, as plan_movej
constexpr double kRel = 1e-9;     // relative slack on the limit comparisons (rounding)

std::size_t slot(std::span<const PathSegment> seg, std::uint64_t seq) { return static_cast<std::size_t>(seq % seg.size()); }

// A segment's own joints at absolute time t (clamped to its span).
Status own_q(const PathSegment& g, double t, JointVector& q) {
  const double u = std::clamp(t - g.start, 0.0, g.duration);
  if (g.kind == PathKind::joint) {
    double p = 1, v, a;
    if (u < g.duration) eval_profile(g.s, u, p, v, a);
    q = g.from + std::clamp(p, 0.0, 1.0) * g.delta;
    return Status::ok;
  }
  JointVector qd, qdd;
  return g.line.sample_ik(u, q, qd, qdd);
}

// Both segments moving (t in [B.start, A.end)): the sum of the motions. Line-line: the
// IK of B's line (the chain and solver it was planned with, as the firmware's cfg).
Status blended(const PathSegment& A, const PathSegment& B, double t, const JointVector& seed, JointVector& q) {
  if (A.kind == PathKind::line && B.kind == PathKind::line) {
    double sa, va, aa, sb, vb, ab;
    A.line.path_state(t - A.start, sa, va, aa);
    B.line.path_state(t - B.start, sb, vb, ab);
    Pose x = Pose::Identity();
    x.translation() = B.line.p0 + (sa - 1.0) * (A.line.p1 - A.line.p0) + sb * (B.line.p1 - B.line.p0);
    const Eigen::Quaterniond ra = A.line.r0.slerp(sa, A.line.r1), rb = B.line.r0.slerp(sb, B.line.r1);
    x.linear() = (ra * A.line.r1.conjugate() * rb).normalized().toRotationMatrix();
    if (B.line.chain == nullptr || B.line.ik.fn == nullptr) return Status::bad_input;
    return B.line.ik.fn(*B.line.chain, x, seed, q, B.line.ik.ctx);
  }
  JointVector qa, qb;
  const Status s1 = own_q(A, t, qa);
  const Status s2 = own_q(B, t, qb);
  q = qa + qb - A.q_end;
  return !is_ok(s1) ? s1 : s2;
}

bool positive_finite(double x) { return std::isfinite(x) && x > 0; }

// Straight joint segment from rest to rest, override o: v o, a o^2 sa, j o^3 sj.
bool plan_joint(const JointLimits& L, double o, double sa, double sj, PathSegment& b) {
  Limits1 sl{1e300, 1e300, 1e300};
  for (int i = 0; i < L.n; ++i) {
    const double di = std::fabs(b.delta[i]);
    if (!(di > 0)) continue;
    const JointDynamics& d = L.dyn[static_cast<std::size_t>(i)];
    sl.v = std::min(sl.v, o * d.max_velocity / di);
    sl.a = std::min(sl.a, sa * o * o * d.max_acceleration / di);
    sl.j = std::min(sl.j, sj * o * o * o * d.max_jerk / di);
  }
  b.s.n = 0;
  const double T = plan_1d(0.0, 0.0, 0.0, 0.0, 1.0, sl, 0.0, b.s);
  if (!(T > 0) || !std::isfinite(T)) return false;
  b.duration = T;
  return true;
}

// Exact bound of the corner distance over the whole blend (both segments straight in the
// same space: line-line in m, joint-joint in rad), or -1 where there is none (mixed).
double corner_bound(const PathSegment& A, const PathSegment& B, double tau) {
  double pa, pb, v, a;
  if (A.kind == PathKind::line && B.kind == PathKind::line) {
    A.line.path_state(A.duration - tau, pa, v, a);
    B.line.path_state(tau, pb, v, a);
    const Eigen::Vector3d dA = A.line.p1 - A.line.p0, dB = B.line.p1 - B.line.p0;
    const double din = (1.0 - pa) * dA.norm(), dout = pb * dB.norm();
    const double c = (din > 0 && dout > 0) ? std::clamp(dA.dot(dB) / (dA.norm() * dB.norm()), -1.0, 1.0) : 0.0;
    return std::max({din, dout, std::sqrt(std::max(din * din + dout * dout - 2 * din * dout * c, 0.0))});
  }
  if (A.kind == PathKind::joint && B.kind == PathKind::joint) {
    eval_profile(A.s, A.duration - tau, pa, v, a);
    eval_profile(B.s, tau, pb, v, a);
    const double la = A.delta.norm(), lb = B.delta.norm();
    const double din = (1.0 - std::clamp(pa, 0.0, 1.0)) * la, dout = std::clamp(pb, 0.0, 1.0) * lb;
    const double c = (la > 0 && lb > 0) ? std::clamp(A.delta.dot(B.delta) / (la * lb), -1.0, 1.0) : 0.0;
    return std::max({din, dout, std::sqrt(std::max(din * din + dout * dout - 2 * din * dout * c, 0.0))});
  }
  return -1;
}

// Tool speed a line moves at (its s_limits and override).
double line_speed(const PathSegment& g) {
  return g.line.s_limits.v * g.line.timing.override * g.line.length;
}

struct Window {
  const char* why = "";
  double corner = 0;
  int samples = 0;
};

// Every check of overlap tau between A (queued last) and B (in its slot, counted).
bool check(const PathBlendCore& core, std::span<const PathSegment> seg, const PathSegment& A, PathSegment& B, double tau,
           Window& w) {
  const PathBlendConfig& cfg = core.cfg;
  const JointLimits& L = cfg.limits;
  const int n = L.n;
  B.start = A.end() - tau;
  const double dt = 1.0 / cfg.rate;
  w = Window{};
  const double bound = corner_bound(A, B, tau);
  if (bound > A.tolerance * (1 + kRel)) {
    w.why = "tolerance";
    return false;
  }
  w.corner = std::max(bound, 0.0);
  // The RT thread samples at integer multiples of dt on the queue's time base: so do the checks.
  const double t0 = std::floor((B.start - 3 * dt) / dt) * dt;
  const int count = static_cast<int>(std::ceil((A.end() + 3 * dt - t0) / dt)) + 1;
  if (count > kPathMaxWindow + 8) {
    w.why = "window";
    return false;
  }
  const bool lines = A.kind == PathKind::line && B.kind == PathKind::line;
  const double vtool = lines ? std::max(line_speed(A), line_speed(B)) * (1 + 1e-6) : 0.0;
  const Eigen::Vector3d dA = lines ? Eigen::Vector3d(A.line.p1 - A.line.p0) : Eigen::Vector3d::Zero();
  const Eigen::Vector3d dB = lines ? Eigen::Vector3d(B.line.p1 - B.line.p0) : Eigen::Vector3d::Zero();
  JointVector q = JointVector::Zero(n), q1 = q, q2 = q, q3 = q, seed = q;
  if (!is_ok(own_q(A, t0, seed))) {
    w.why = "ik";
    return false;
  }
  Pose fk = Pose::Identity();
  for (int i = 0; i < count; ++i) {
    const double t = t0 + i * dt;
    ++w.samples;
    if (!is_ok(path_sample(core, seg, t, seed, q)) || !q.allFinite()) {
      w.why = "ik";
      return false;
    }
    for (int k = 0; k < n; ++k) {
      const auto j = static_cast<std::size_t>(k);
      if (q[k] < L.lower[j] - kPosTol || q[k] > L.upper[j] + kPosTol) {
        w.why = "limits";
        return false;
      }
    }
    const bool in = t >= B.start && t < A.end();
    if (i >= 1) {
      for (int k = 0; k < n; ++k) {
        const JointDynamics& d = L.dyn[static_cast<std::size_t>(k)];
        if (std::fabs(q[k] - q1[k]) > cfg.max_joint_step) {
          w.why = "ik";
          return false;
        }
        if (std::fabs(q[k] - q1[k]) > cfg.margin * d.max_velocity * dt * (1 + kRel)) {
          w.why = "velocity";
          return false;
        }
        if (i >= 2 && std::fabs(q[k] - 2 * q1[k] + q2[k]) > cfg.margin * d.max_acceleration * dt * dt * (1 + kRel)) {
          w.why = "acceleration";
          return false;
        }
        const bool stencil_in = t > B.start && t - 3 * dt < A.end();
        if (i >= 3 && stencil_in &&
            std::fabs(q[k] - 3 * q1[k] + 3 * q2[k] - q3[k]) > d.max_jerk * dt * dt * dt * (1 + kRel)) {
          w.why = "jerk";
          return false;
        }
      }
    }
    if (in) {
      double dist;
      if (A.kind == PathKind::line) {
        forward(*cfg.chain, q, fk);
        dist = (fk.translation() - A.x_end.translation()).norm();
      } else {
        dist = (q - A.q_end).norm();
      }
      if (dist > A.tolerance * (1 + kRel) + 1e-12) {
        w.why = "tolerance";
        return false;
      }
      w.corner = std::max(w.corner, dist);
      if (lines) {
        double s, sa, sb, a;
        A.line.path_state(t - A.start, s, sa, a);
        B.line.path_state(t - B.start, s, sb, a);
        if ((sa * dA + sb * dB).norm() > vtool) {
          w.why = "tool_speed";
          return false;
        }
      }
    }
    q3 = q2;
    q2 = q1;
    q1 = q;
    seed = q;
  }
  return true;
}

// Blend the corner between the last queued segment and nb (planned, in its slot, not yet
// counted); sets nb.start and the overlaps.
BlendStatus blend_corner(PathBlendCore& core, std::span<PathSegment> seg, PathSegment& nb, double t_earliest,
                         PathBlendReport* rep) {
  if (core.count == 0) {
    nb.start = t_earliest;
    return BlendStatus::ok;
  }
  PathSegment& A = seg[slot(seg, core.head + core.count - 1)];
  if (!(A.tolerance > 0)) {
    nb.start = std::max(A.end(), t_earliest);
    return BlendStatus::ok;
  }
  if (!(A.end() > t_earliest)) {
    nb.start = t_earliest;
    return BlendStatus::exact_stop;
  }
  const double dt = 1.0 / core.cfg.rate;
  const double top = std::min({A.duration - A.blend_in, nb.duration, A.end() - t_earliest, (kPathMaxWindow - 8) * dt});
  ++core.count;  // nb sampled as part of the queue by the checks
  Window w;
  double best = 0, fail = top;
  const char* why = "";
  int checks = 0, samples = 0;
  for (int k = 0; k < kPathScan && top > 0; ++k) {
    const double tau = top * (1.0 - static_cast<double>(k) / kPathScan);
    ++checks;
    const bool ok = check(core, seg, A, nb, tau, w);
    samples += w.samples;
    if (ok) {
      best = tau;
      break;
    }
    why = w.why;
    fail = tau;
  }
  if (best < top) {
    double lo = best, hi = fail;
    for (int it = 0; it < kPathBisect; ++it) {
      const double m = 0.5 * (lo + hi);
      ++checks;
      const bool ok = check(core, seg, A, nb, m, w);
      samples += w.samples;
      if (ok) lo = m;
      else hi = m, why = w.why;
    }
    best = lo;
  }
  double corner = 0;
  if (best > 0) {
    ++checks;
    const bool ok = check(core, seg, A, nb, best, w);  // final state, and the invariant
    samples += w.samples;
    if (!ok) best = 0;
    corner = w.corner;
  }
  --core.count;
  BlendStatus st = BlendStatus::ok;
  if (best > 0) {
    nb.start = A.end() - best;
    nb.blend_in = best;
    A.blend = best;
    A.corner = corner;
    if (best < top * (1 - 1e-9) || top < A.duration - A.blend_in) st = BlendStatus::blend_reduced;
  } else {
    nb.start = A.end();
    nb.blend_in = 0;
    A.blend = 0;
    A.corner = 0;
    st = BlendStatus::exact_stop;
  }
  if (rep) {
    rep->blend = best;
    rep->corner = corner;
    rep->checks = checks;
    rep->samples = samples;
    rep->limited_by = st == BlendStatus::ok ? "" : why;
  }
  return st;
}

BlendStatus common_checks(const PathBlendCore& core, std::span<const PathSegment> seg, double tolerance, double t_earliest) {
  const JointLimits& L = core.cfg.limits;
  if (L.n < 1 || L.n > kMaxJoints || core.cfg.chain == nullptr || core.cfg.chain->n_joints != L.n)
    return BlendStatus::bad_limits;
  for (int i = 0; i < L.n; ++i) {
    const JointDynamics& d = L.dyn[static_cast<std::size_t>(i)];
    if (!positive_finite(d.max_velocity) || !positive_finite(d.max_acceleration) || !positive_finite(d.max_jerk))
      return BlendStatus::bad_limits;
  }
  if (!positive_finite(core.cfg.rate) || !(core.cfg.margin > 0 && core.cfg.margin <= 1)) return BlendStatus::bad_limits;
  if (!std::isfinite(tolerance) || tolerance < 0 || !std::isfinite(t_earliest)) return BlendStatus::bad_input;
  if (core.count >= seg.size()) return BlendStatus::queue_full;
  return BlendStatus::ok;
}

JointVector last_target(const PathBlendCore& core, std::span<const PathSegment> seg) {
  return core.count ? seg[slot(seg, core.head + core.count - 1)].q_end : core.rest;
}

}  // namespace

void path_reset(PathBlendCore& core, const PathBlendConfig& cfg, const JointVector& rest) {
  core.cfg = cfg;
  core.rest = rest;
  core.head = 0;
  core.count = 0;
}

BlendStatus path_append_joint(PathBlendCore& core, std::span<PathSegment> seg, const JointVector& goal, double override,
                              double tolerance, double t_earliest, PathBlendReport* report) {
  if (report) *report = PathBlendReport{};
  if (const BlendStatus s = common_checks(core, seg, tolerance, t_earliest); s != BlendStatus::ok) return s;
  const JointLimits& L = core.cfg.limits;
  if (goal.size() != L.n) return BlendStatus::wrong_size;
  if (!goal.allFinite() || !(override >= 0.01 && override <= 1)) return BlendStatus::bad_input;
  for (int i = 0; i < L.n; ++i) {
    const auto k = static_cast<std::size_t>(i);
    if (goal[i] < L.lower[k] - kPosTol || goal[i] > L.upper[k] + kPosTol) return BlendStatus::goal_out_of_limits;
  }
  const JointVector from = last_target(core, seg);
  if ((goal - from).norm() <= 1e-12) {
    if (core.count) seg[slot(seg, core.head + core.count - 1)].tolerance = tolerance;
    return BlendStatus::zero_length;
  }
  PathSegment& nb = seg[slot(seg, core.head + core.count)];
  nb.kind = PathKind::joint;
  nb.from = from;
  nb.delta = JointVector::Zero(L.n);
  nb.delta = goal - from;
  nb.q_end = goal;
  if (forward(*core.cfg.chain, goal, nb.x_end) != Status::ok) return BlendStatus::bad_input;
  nb.tolerance = tolerance;
  nb.blend_in = nb.blend = nb.corner = 0;
  // A segment that blends in (the one before it has a tolerance) tries its plan at the full
  // limits, at full acceleration with a share of the jerk, and at a share of both
  // (PathBlendConfig::joint_share: a slower segment whose overlap with its neighbour can stay
  // within the limits), each blended as far as the checks pass, and keeps what ends first.
  // The full-limit plan never ends later than the exact stop would (it starts at the latest
  // where the previous segment ends), so neither does the one kept. A segment that does not
  // blend in is planned at the full limits: a share would make it end later than its exact
  // stop, for an overlap with a next segment not known yet.
  const bool blends_in = core.count > 0 && seg[slot(seg, core.head + core.count - 1)].tolerance > 0;
  const double sh = std::clamp(core.cfg.joint_share, 0.05, 1.0);
  double best_sa = 1.0, best_sj = 1.0;
  if (blends_in && sh < 1) {
    double best_end = INFINITY;
    for (const auto& [sa, sj] : {std::pair{1.0, 1.0}, std::pair{1.0, sh}, std::pair{sh, sh}}) {
      if (!plan_joint(L, override, sa, sj, nb)) continue;
      PathBlendReport r;
      if (!is_ok(blend_corner(core, seg, nb, t_earliest, &r))) continue;
      if (nb.end() < best_end - 1e-9) best_end = nb.end(), best_sa = sa, best_sj = sj;
    }
  }
  // (the winner again: blend_corner sets the previous segment's fields for it)
  if (!plan_joint(L, override, best_sa, best_sj, nb)) return BlendStatus::no_solution;
  const BlendStatus st = blend_corner(core, seg, nb, t_earliest, report);
  ++core.count;
  if (report) report->status = st;
  return st;
}

BlendStatus path_append_line(PathBlendCore& core, std::span<PathSegment> seg, const Pose& target,
                             const CartesianLimits& limits, const MovelOptions& options, double tolerance,
                             double t_earliest, PathBlendReport* report) {
  if (report) *report = PathBlendReport{};
  if (const BlendStatus s = common_checks(core, seg, tolerance, t_earliest); s != BlendStatus::ok) return s;
  const JointVector from = last_target(core, seg);
  PathSegment& nb = seg[slot(seg, core.head + core.count)];
  PathReport pr;
  const MotionStatus ms = plan_movel(*core.cfg.chain, from, target, limits, options, core.cfg.ik, nb.line, &pr);
  if (report) report->motion = ms, report->path = pr;
  if (!is_ok(ms)) return BlendStatus::no_solution;
  if (!(nb.line.length > 1e-12 || nb.line.angle > 1e-12)) {
    if (core.count) seg[slot(seg, core.head + core.count - 1)].tolerance = tolerance;
    return BlendStatus::zero_length;
  }
  nb.kind = PathKind::line;
  nb.q_end = nb.line.goal;
  if (forward(*core.cfg.chain, nb.q_end, nb.x_end) != Status::ok) return BlendStatus::bad_input;
  nb.duration = nb.line.duration;
  nb.tolerance = tolerance;
  nb.blend_in = nb.blend = nb.corner = 0;
  const BlendStatus st = blend_corner(core, seg, nb, t_earliest, report);
  ++core.count;
  if (report) report->status = st;
  return st;
}

Status path_sample(const PathBlendCore& core, std::span<const PathSegment> seg, double t, const JointVector& seed,
                   JointVector& q) {
  if (core.count == 0) {
    q = core.rest;
    return Status::ok;
  }
  const PathSegment& first = seg[slot(seg, core.head)];
  if (!(t >= first.start)) return own_q(first, first.start, q);
  std::uint64_t lo = 0, hi = core.count;
  while (hi - lo > 1) {
    const std::uint64_t m = (lo + hi) / 2;
    if (seg[slot(seg, core.head + m)].start <= t) lo = m;
    else hi = m;
  }
  const PathSegment& K = seg[slot(seg, core.head + lo)];
  if (lo > 0) {
    const PathSegment& J = seg[slot(seg, core.head + lo - 1)];
    if (t < J.end()) return blended(J, K, t, seed, q);
  }
  return own_q(K, t, q);
}

Status path_sample_pair(const PathSegment* a, const PathSegment& b, double t, const JointVector& seed, JointVector& q) {
  if (a != nullptr && t >= b.start && t < a->end()) return blended(*a, b, t, seed, q);
  if (a != nullptr && t < b.start) return own_q(*a, t, q);
  return own_q(b, t, q);
}

void path_segment_start(const PathSegment& g, int n, JointVector& q) {
  q = JointVector::Zero(n);
  if (g.kind == PathKind::joint) {
    q = g.from;
    return;
  }
  for (int i = 0; i < n; ++i) q[i] = g.line.q_knot[0][static_cast<std::size_t>(i)];
}

void path_retire(PathBlendCore& core, std::span<const PathSegment> seg, double t) {
  while (core.count > 1) {  // the last segment stays: it holds the arm at its target
    const PathSegment& h = seg[slot(seg, core.head)];
    const PathSegment& nx = seg[slot(seg, core.head + 1)];
    if (!(h.end() <= t && nx.start <= t)) break;
    core.rest = h.q_end;
    ++core.head;
    --core.count;
  }
}

}  // namespace servoarm::kin
