// SPDX-License-Identifier: Apache-2.0
// Jerk-limited, time-synchronised joint trajectories. See trajectory.hpp for
// the profile model; the derivations are in the comments below.
#include "servoarm/kinematics/trajectory.hpp"

#include <algorithm>
#include <cmath>

namespace servoarm::kin {

const char* to_string(MotionStatus s) {
  switch (s) {
    case MotionStatus::ok: return "ok";
    case MotionStatus::slowed_near_singularity: return "slowed_near_singularity";
    case MotionStatus::bad_input: return "bad_input";
    case MotionStatus::wrong_size: return "wrong_size";
    case MotionStatus::bad_limits: return "bad_limits";
    case MotionStatus::goal_out_of_limits: return "goal_out_of_limits";
    case MotionStatus::path_out_of_limits: return "path_out_of_limits";
    case MotionStatus::no_ik_solution: return "no_ik_solution";
    case MotionStatus::branch_change: return "branch_change";
    case MotionStatus::joint_velocity: return "joint_velocity";
    case MotionStatus::singularity: return "singularity";
    case MotionStatus::no_solution: return "no_solution";
  }
  return "unknown";
}

JointLimits limits_from(const Chain& chain) {
  JointLimits l;
  l.n = chain.n_joints;
  for (int i = 0; i < chain.n_joints && i < kMaxJoints; ++i) {
    const auto k = static_cast<std::size_t>(i);
    l.dyn[k] = chain.joint(i).dynamics;
    l.lower[k] = chain.joint(i).lower;
    l.upper[k] = chain.joint(i).upper;
  }
  return l;
}

JointState JointState::rest(const JointVector& q) {
  JointState s;
  s.pos = q;
  s.vel = JointVector::Zero(q.size());
  s.acc = JointVector::Zero(q.size());
  return s;
}

namespace {

constexpr int kRootIterations = 100;  // cap of every 1-D search (bisection would need ~60)
constexpr int kGoldenIterations = 48;

// --------------------------------------------------------------------------
// Velocity change: from (v0, a0) to (v1, a = 0) in minimum time with
// |a| <= A (after an initial ramp if |a0| > A) and |jerk| <= J.
//
// Bringing a0 to zero at jerk J reaches v_nat = v0 + a0|a0|/(2J). If v1 >= v_nat
// the profile is "jerk +J to a peak ap, hold ap, jerk -J to 0" (mirror it for
// v1 < v_nat). Velocity gained: ramp 1 (ap^2 - a0^2)/(2J) (for ap >= a0), ramp 3
// ap^2/(2J), so without a hold 2 J dv = 2 ap^2 - a0^2, ap = sqrt(J dv + a0^2/2).
// If ap > A the peak is clipped to A and the hold makes up the rest:
// t2 = (dv - dv1 - dv3) / A. When a0 > A the first ramp goes *down* to A.
// --------------------------------------------------------------------------
struct VelChange {
  double t[3];
  double j[3];
  double dp;  // displacement
  double T;   // duration
};

inline void propagate(double& p, double& v, double& a, double j, double t) {
  p += t * (v + t * (0.5 * a + t * (j / 6.0)));
  v += t * (a + 0.5 * j * t);
  a += j * t;
}

VelChange velocity_change(double v0, double a0, double v1, double A, double J) {
  VelChange r{};
  const double vnat = v0 + a0 * std::fabs(a0) / (2.0 * J);
  const double s = (v1 >= vnat) ? 1.0 : -1.0;
  const double b0 = s * a0;
  const double dv = s * (v1 - v0);
  double ap = std::sqrt(std::max(J * dv + 0.5 * b0 * b0, 0.0));
  if (ap <= A) {
    r.t[0] = std::max((ap - b0) / J, 0.0);
    r.j[0] = s * J;
    r.t[1] = 0;
    r.t[2] = ap / J;
  } else {
    ap = A;
    r.t[0] = std::fabs(A - b0) / J;
    r.j[0] = (A >= b0 ? s : -s) * J;
    const double dv1 = 0.5 * (b0 + A) * r.t[0];
    const double dv3 = 0.5 * A * A / J;
    r.t[1] = std::max((dv - dv1 - dv3) / A, 0.0);
    r.t[2] = A / J;
  }
  r.j[1] = 0;
  r.j[2] = -s * J;
  double p = 0, v = v0, a = a0;
  for (int k = 0; k < 3; ++k) propagate(p, v, a, r.j[k], r.t[k]);
  r.dp = p;
  r.T = r.t[0] + r.t[1] + r.t[2];
  return r;
}

// --------------------------------------------------------------------------
// One joint, mirrored so that the goal lies beyond the stopping point
// (diff = D - d_stop > 0): the cruise velocity vc is then in (0, V].
//   F(vc) = disp(vc) - D   (disp: acc part to vc + dec part from vc, no cruise)
//   a profile with cruise vc exists iff F(vc) <= 0; cruise time tc = -F/vc
//   T(vc) = t_acc + t_dec + tc
// From rest F is increasing and T decreasing in vc. With the joint already
// moving towards the goal at w = v_nat > 0, lowering vc below w makes the
// profile dip (decelerate, cruise slower, decelerate again): F rises again
// below w, can become positive, and the durations between T(r2) and T(r1)
// (r1 < r2 the roots of F below w) cannot be met: a blocked interval.
// --------------------------------------------------------------------------
struct Joint1 {
  double D = 0, v0 = 0, a0 = 0;  // mirrored
  double sigma = 1;
  Limits1 L{};
  bool hold = false;  // goal == stopping point: stop, then wait
  double t_stop = 0;
  double vc_star = 0, T_min = 0;
  double lo2 = 0, T_lo2 = 0;  // feasible vc interval [lo2, vc_star]; lo2 == 0: open, T -> inf
  bool gap = false;
  double r1 = 0, T_r1 = 0;  // second feasible interval (0, r1] when gap
};

struct Eval {
  double F;
  double T;
};

// Stopping from cruise (vc >= 0, a = 0) is symmetric in time: the mean velocity is
// vc / 2, so dp = vc T / 2 with T = vc/A + A/J (A reached) or 2 sqrt(vc/J).
inline void stop_from_cruise(double vc, double A, double J, double& T, double& dp) {
  T = vc * J >= A * A ? vc / A + A / J : 2.0 * std::sqrt(vc / J);
  dp = 0.5 * vc * T;
}

Eval eval(const Joint1& P, double vc) {
  const VelChange a = velocity_change(P.v0, P.a0, vc, P.L.a, P.L.j);
  double Td, dpd;
  stop_from_cruise(vc, P.L.a, P.L.j, Td, dpd);
  Eval e{};
  e.F = a.dp + dpd - P.D;
  e.T = a.T + Td;
  if (vc > 0 && e.F < 0) e.T += -e.F / vc;
  return e;
}

// Root of F on [lo, hi] with F(lo) <= 0 < F(hi) (Illinois / regula falsi with
// bisection fallback). Returns the last point with F <= 0 (the feasible side).
template <class Fn>
double root_feasible_low(Fn f, double lo, double flo, double hi, double fhi) {
  int side = 0;
  for (int it = 0; it < kRootIterations; ++it) {
    if (hi - lo <= 1e-15 * std::max(1.0, hi)) break;
    double x = (fhi - flo) > 0 ? lo - flo * (hi - lo) / (fhi - flo) : 0.5 * (lo + hi);
    if (!(x > lo && x < hi) || it % 8 == 7) x = 0.5 * (lo + hi);
    const double fx = f(x);
    if (fx <= 0) {
      lo = x;
      flo = fx;
      if (side == -1) fhi *= 0.5;
      side = -1;
      if (fx > -1e-15) break;
    } else {
      hi = x;
      fhi = fx;
      if (side == 1) flo *= 0.5;
      side = 1;
    }
  }
  return lo;
}

// Same, with F(lo) > 0 >= F(hi): returns the last point with F <= 0.
template <class Fn>
double root_feasible_high(Fn f, double lo, double flo, double hi, double fhi) {
  int side = 0;
  for (int it = 0; it < kRootIterations; ++it) {
    if (hi - lo <= 1e-15 * std::max(1.0, hi)) break;
    double x = (flo - fhi) > 0 ? lo + flo * (hi - lo) / (flo - fhi) : 0.5 * (lo + hi);
    if (!(x > lo && x < hi) || it % 8 == 7) x = 0.5 * (lo + hi);
    const double fx = f(x);
    if (fx <= 0) {
      hi = x;
      fhi = fx;
      if (side == -1) flo *= 0.5;
      side = -1;
      if (fx > -1e-15) break;
    } else {
      lo = x;
      flo = fx;
      if (side == 1) fhi *= 0.5;
      side = 1;
    }
  }
  return hi;
}

void analyse(Joint1& P, double p0, double v0, double a0, double pf, const Limits1& L) {
  P.L = L;
  const VelChange st = velocity_change(v0, a0, 0.0, L.a, L.j);
  P.t_stop = st.T;
  const double D = pf - p0;
  const double diff = D - st.dp;
  const double tol = 1e-13 * std::max(1.0, std::fabs(D) + std::fabs(st.dp));
  if (std::fabs(diff) <= tol) {
    P.hold = true;
    P.sigma = 1;
    P.D = D;
    P.v0 = v0;
    P.a0 = a0;
    P.T_min = st.T;
    return;
  }
  P.hold = false;
  P.sigma = diff > 0 ? 1.0 : -1.0;
  P.D = P.sigma * D;
  P.v0 = P.sigma * v0;
  P.a0 = P.sigma * a0;
  const double V = L.v;
  auto F = [&P](double vc) { return eval(P, vc).F; };
  const double F0 = -std::fabs(diff);
  const double w = P.v0 + P.a0 * std::fabs(P.a0) / (2.0 * L.j);
  P.gap = false;
  P.lo2 = 0;
  if (w <= 1e-12 * V) {
    // From rest or moving away: F increasing on (0, V].
    const double FV = F(V);
    P.vc_star = FV <= 0 ? V : root_feasible_low(F, 0.0, F0, V, FV);
  } else {
    const double wA = std::min(w, V);
    const double Fw = F(wA);
    if (Fw > 0) {
      P.vc_star = root_feasible_low(F, 0.0, F0, wA, Fw);
    } else {
      const double FV = F(V);
      P.vc_star = FV <= 0 ? V : root_feasible_low(F, wA, Fw, V, FV);
      // Is there a bump of F above zero in (0, wA)? Golden-section search for its maximum.
      const double g = 0.5 * (std::sqrt(5.0) - 1.0);
      double lo = 0, hi = wA;
      double x1 = hi - g * (hi - lo), x2 = lo + g * (hi - lo);
      double f1 = F(x1), f2 = F(x2);
      for (int it = 0; it < kGoldenIterations && (f1 <= 0 || f2 <= 0); ++it) {
        if (f1 < f2) {
          lo = x1;
          x1 = x2;
          f1 = f2;
          x2 = lo + g * (hi - lo);
          f2 = F(x2);
        } else {
          hi = x2;
          x2 = x1;
          f2 = f1;
          x1 = hi - g * (hi - lo);
          f1 = F(x1);
        }
      }
      const double m = f1 > f2 ? x1 : x2;
      const double fm = std::max(f1, f2);
      if (fm > 0) {
        P.gap = true;
        P.r1 = root_feasible_low(F, 0.0, F0, m, fm);
        P.lo2 = root_feasible_high(F, m, fm, wA, Fw);
        P.T_lo2 = eval(P, P.lo2).T;
        P.T_r1 = P.r1 > 0 ? eval(P, P.r1).T : 0.0;
        if (!(P.r1 > 0)) {  // (0, r1] empty: only [lo2, vc_star] (never seen; F(0) < 0)
          P.gap = false;
        }
      }
    }
  }
  if (!(P.vc_star > 0)) {  // goal a hair beyond the stopping point: stop there
    P.hold = true;
    P.sigma = 1;
    P.D = D;
    P.v0 = v0;
    P.a0 = a0;
    P.T_min = st.T;
    return;
  }
  P.T_min = eval(P, P.vc_star).T;
}

// Smallest achievable duration >= t.
double achievable(const Joint1& P, double t) {
  if (t <= P.T_min) return P.T_min;
  if (P.hold) return t;
  if (!P.gap) return t;
  if (t <= P.T_lo2 || t >= P.T_r1) return t;
  return P.T_r1;
}

// Cruise velocity giving duration T (T achievable, T > T_min).
double vc_for_duration(const Joint1& P, double T) {
  auto G = [&P, T](double vc) { return eval(P, vc).T - T; };
  double hi = P.vc_star;
  double lo = P.lo2;
  if (P.gap && T > P.T_lo2) {
    hi = P.r1;
    lo = 0;
  }
  double ghi = G(hi);
  if (ghi >= 0) return hi;
  // G(lo) > 0 (lo == 0: +inf). Bisect until lo is a finite positive point.
  double glo = 0;
  if (lo > 0) {
    glo = G(lo);
    if (glo <= 0) return lo;
  } else {
    double x = hi;
    for (int it = 0; it < kRootIterations; ++it) {
      x *= 0.5;
      const double gx = G(x);
      if (gx > 0) {
        lo = x;
        glo = gx;
        break;
      }
      hi = x;
      ghi = gx;
    }
    if (!(lo > 0)) return hi;
  }
  // G decreasing in vc: root with G(lo) > 0 >= G(hi).
  int side = 0;
  for (int it = 0; it < kRootIterations; ++it) {
    double x = lo + glo * (hi - lo) / (glo - ghi);
    if (!(x > lo && x < hi) || it % 8 == 7) x = 0.5 * (lo + hi);
    const double gx = G(x);
    if (std::fabs(gx) <= 1e-13 * std::max(1.0, T)) return x;
    if (gx > 0) {
      lo = x;
      glo = gx;
      if (side == 1) ghi *= 0.5;
      side = 1;
    } else {
      hi = x;
      ghi = gx;
      if (side == -1) glo *= 0.5;
      side = -1;
    }
    if (hi - lo <= 1e-16 * hi) break;
  }
  return hi;
}

struct Writer {
  JointProfile& prof;
  double t, p, v, a;
  bool full = false;
  void add(double j, double dt) {
    if (!(dt > 0)) return;
    if (prof.n >= kMaxSegments - 1) {
      full = true;
      return;
    }
    prof.seg[static_cast<std::size_t>(prof.n++)] = JerkSegment{t, p, v, a, j};
    propagate(p, v, a, j, dt);
    t += dt;
  }
  void add(const VelChange& c, double sigma) {
    for (int k = 0; k < 3; ++k) add(sigma * c.j[k], c.t[k]);
  }
  void hold_at(double pf) {
    prof.seg[static_cast<std::size_t>(prof.n++)] = JerkSegment{t, pf, 0.0, 0.0, 0.0};
  }
};

// Append the profile of an analysed joint, ending (at rest at pf) exactly at
// t0 + T. Returns false if the segment table overflowed (cannot happen for
// the shapes built here; checked anyway).
bool build(const Joint1& P, double t0, double p0, double v0, double a0, double pf, double T,
           JointProfile& prof, bool hold_final) {
  Writer w{prof, t0, p0, v0, a0};
  if (P.hold) {
    // Stop, then wait at the goal until t0 + T. The wait is a segment of its
    // own (zero jerk from the stopped state): a segment lasts until the next
    // one starts, so without it the stop's last jerk ramp would run on over
    // the whole stretched duration (+-J t^3 / 6: 0.1 rad after 0.15 s at 200
    // rad/s^3 for a joint that was at its goal to rounding).
    w.add(velocity_change(v0, a0, 0.0, P.L.a, P.L.j), 1.0);
    w.add(0.0, t0 + T - w.t);
  } else {
    const double vc = T > P.T_min * (1 + 1e-15) ? vc_for_duration(P, T) : P.vc_star;
    const VelChange acc = velocity_change(P.v0, P.a0, vc, P.L.a, P.L.j);
    const VelChange dec = velocity_change(vc, 0.0, 0.0, P.L.a, P.L.j);
    double tc = std::max(-(acc.dp + dec.dp - P.D) / vc, 0.0);
    // Absorb the search's last ~1e-13 s in the cruise so every joint ends at exactly T.
    const double slack = T - (acc.T + dec.T + tc);
    if (std::fabs(slack) < 1e-9 * std::max(1.0, T)) tc = std::max(tc + slack, 0.0);
    w.add(acc, P.sigma);
    w.add(0.0, tc);
    w.add(dec, P.sigma);
  }
  // Rounding (a few ulp of T): the final hold starts at t0 + T.
  w.t = std::max(w.t, t0 + T);
  if (hold_final) w.hold_at(pf);
  return !w.full;
}

bool finite(const JointVector& v) { return v.allFinite(); }

MotionStatus check_common(const JointLimits& limits, const JointState& start, double override) {
  if (limits.n < 1 || limits.n > kMaxJoints) return MotionStatus::wrong_size;
  if (start.pos.size() != limits.n || start.vel.size() != limits.n || start.acc.size() != limits.n)
    return MotionStatus::wrong_size;
  if (!finite(start.pos) || !finite(start.vel) || !finite(start.acc)) return MotionStatus::bad_input;
  if (!(override >= 0.01 && override <= 1.0)) return MotionStatus::bad_input;
  for (int i = 0; i < limits.n; ++i) {
    const JointDynamics& d = limits.dyn[static_cast<std::size_t>(i)];
    const auto ok = [](double x) { return std::isfinite(x) && x > 0; };
    if (!ok(d.max_velocity) || !ok(d.max_acceleration) || !ok(d.max_jerk)) return MotionStatus::bad_limits;
  }
  return MotionStatus::ok;
}

Limits1 scaled(const JointDynamics& d, double s) {
  return Limits1{d.max_velocity * s, d.max_acceleration * s * s, d.max_jerk * s * s * s};
}

}  // namespace

void eval_profile(const JointProfile& prof, double t, double& p, double& v, double& a) {
  int i = prof.n - 1;
  while (i > 0 && t < prof.seg[static_cast<std::size_t>(i)].t0) --i;
  const JerkSegment& s = prof.seg[static_cast<std::size_t>(i)];
  const double dt = std::max(t - s.t0, 0.0);
  const double j6 = s.j * (1.0 / 6.0);
  p = s.p + dt * (s.v + dt * (0.5 * s.a + dt * j6));
  v = s.v + dt * (s.a + 0.5 * s.j * dt);
  a = s.a + s.j * dt;
}

double plan_1d(double t0, double p0, double v0, double a0, double pf, const Limits1& lim, double duration,
               JointProfile& prof) {
  Joint1 P;
  analyse(P, p0, v0, a0, pf, lim);
  double T = duration > 0 ? achievable(P, duration) : P.T_min;
  if (!build(P, t0, p0, v0, a0, pf, T, prof, true)) return -1;
  return t0 + T;
}

double achievable_duration_1d(double p0, double v0, double a0, double pf, const Limits1& lim, double t) {
  Joint1 P;
  analyse(P, p0, v0, a0, pf, lim);
  return achievable(P, t);
}

void JointTrajectory::sample(double t, JointVector& pos, JointVector& vel, JointVector& acc) const {
  pos.resize(n);
  vel.resize(n);
  acc.resize(n);
  if (t >= duration) {
    pos = goal;
    vel.setZero();
    acc.setZero();
    return;
  }
  for (int i = 0; i < n; ++i) {
    double p, v, a;
    eval_profile(joint[static_cast<std::size_t>(i)], t, p, v, a);
    pos[i] = p;
    vel[i] = v;
    acc[i] = a;
  }
}

double JointTrajectory::position(int i, double t) const {
  if (t >= duration) return goal[i];
  double p, v, a;
  eval_profile(joint[static_cast<std::size_t>(i)], t, p, v, a);
  return p;
}

JointPeaks peaks(const JointTrajectory& traj, int i) {
  JointPeaks pk;
  const JointProfile& prof = traj.joint[static_cast<std::size_t>(i)];
  pk.min_position = pk.max_position = prof.n > 0 ? prof.seg[0].p : 0.0;
  for (int k = 0; k < prof.n; ++k) {
    const JerkSegment& s = prof.seg[static_cast<std::size_t>(k)];
    const double len = k + 1 < prof.n ? prof.seg[static_cast<std::size_t>(k + 1)].t0 - s.t0 : 0.0;
    auto at = [&s](double dt, double& p, double& v, double& a) {
      p = s.p + dt * (s.v + dt * (0.5 * s.a + dt * s.j / 6.0));
      v = s.v + dt * (s.a + 0.5 * s.j * dt);
      a = s.a + s.j * dt;
    };
    auto note = [&pk](double p, double v, double a) {
      pk.min_position = std::min(pk.min_position, p);
      pk.max_position = std::max(pk.max_position, p);
      pk.velocity = std::max(pk.velocity, std::fabs(v));
      pk.acceleration = std::max(pk.acceleration, std::fabs(a));
    };
    double p, v, a;
    at(0, p, v, a);
    note(p, v, a);
    at(len, p, v, a);
    note(p, v, a);
    if (len > 0) pk.jerk = std::max(pk.jerk, std::fabs(s.j));
    // Velocity extremum where a = 0; position extrema where v = 0.
    if (s.j != 0) {
      const double tv = -s.a / s.j;
      if (tv > 0 && tv < len) {
        at(tv, p, v, a);
        note(p, v, a);
      }
      // v(dt) = s.v + s.a dt + s.j dt^2 / 2 = 0
      const double disc = s.a * s.a - 2.0 * s.j * s.v;
      if (disc >= 0) {
        const double r = std::sqrt(disc);
        for (double tr : {(-s.a + r) / s.j, (-s.a - r) / s.j}) {
          if (tr > 0 && tr < len) {
            at(tr, p, v, a);
            note(p, v, a);
          }
        }
      }
    } else if (s.a != 0) {
      const double tr = -s.v / s.a;
      if (tr > 0 && tr < len) {
        at(tr, p, v, a);
        note(p, v, a);
      }
    }
  }
  return pk;
}

MotionStatus plan_stop(const JointLimits& limits, const JointState& start, const MovejOptions& options,
                       JointTrajectory& out) {
  const MotionStatus c = check_common(limits, start, options.override);
  if (c != MotionStatus::ok) return c;
  JointTrajectory tr;
  tr.n = limits.n;
  tr.override = options.override;
  tr.goal.resize(limits.n);
  double T = 0;
  for (int i = 0; i < limits.n; ++i) {
    const auto k = static_cast<std::size_t>(i);
    const Limits1 L = scaled(limits.dyn[k], options.override);
    Writer w{tr.joint[k], 0.0, start.pos[i], start.vel[i], start.acc[i]};
    w.add(velocity_change(start.vel[i], start.acc[i], 0.0, L.a, L.j), 1.0);
    tr.goal[i] = w.p;
    w.hold_at(w.p);
    T = std::max(T, w.t);
  }
  tr.duration = T;
  out = tr;
  return MotionStatus::ok;
}

MotionStatus plan_movej(const JointLimits& limits, const JointState& start, const JointVector& goal,
                        const MovejOptions& options, JointTrajectory& out) {
  const MotionStatus c = check_common(limits, start, options.override);
  if (c != MotionStatus::ok) return c;
  const int n = limits.n;
  if (goal.size() != n) return MotionStatus::wrong_size;
  if (!finite(goal)) return MotionStatus::bad_input;
  constexpr double kPosTol = 1e-9;
  for (int i = 0; i < n; ++i) {
    const auto k = static_cast<std::size_t>(i);
    if (goal[i] < limits.lower[k] - kPosTol || goal[i] > limits.upper[k] + kPosTol)
      return MotionStatus::goal_out_of_limits;
  }
  const double s = options.override;
  JointTrajectory tr;
  tr.n = n;
  tr.override = s;
  tr.goal = goal;

  // 1. Recovery prefix if the start state is outside the scaled limits.
  std::array<double, kMaxJoints> p0{}, v0{}, a0{};
  std::array<Limits1, kMaxJoints> L{};
  bool recover = false;
  for (int i = 0; i < n; ++i) {
    const auto k = static_cast<std::size_t>(i);
    L[k] = scaled(limits.dyn[k], s);
    p0[k] = start.pos[i];
    v0[k] = start.vel[i];
    a0[k] = start.acc[i];
    const double vn = v0[k] + a0[k] * std::fabs(a0[k]) / (2.0 * L[k].j);
    const double vt = L[k].v * (1 + 1e-9), at = L[k].a * (1 + 1e-9);
    if (std::fabs(v0[k]) > vt || std::fabs(a0[k]) > at || std::fabs(vn) > vt) recover = true;
  }
  double t0 = 0;
  if (recover) {
    std::array<VelChange, kMaxJoints> rc{};
    std::array<double, kMaxJoints> vr{};
    for (int i = 0; i < n; ++i) {
      const auto k = static_cast<std::size_t>(i);
      const Limits1 F = scaled(limits.dyn[k], 1.0);
      const double vn = v0[k] + a0[k] * std::fabs(a0[k]) / (2.0 * F.j);
      vr[k] = std::clamp(vn, -L[k].v, L[k].v);
      rc[k] = velocity_change(v0[k], a0[k], vr[k], F.a, F.j);
      t0 = std::max(t0, rc[k].T);
    }
    for (int i = 0; i < n; ++i) {
      const auto k = static_cast<std::size_t>(i);
      Writer w{tr.joint[k], 0.0, p0[k], v0[k], a0[k]};
      w.add(rc[k], 1.0);
      w.add(0.0, t0 - w.t);  // cruise at vr until every joint has recovered
      if (w.full) return MotionStatus::no_solution;
      p0[k] = w.p;
      v0[k] = vr[k];
      a0[k] = 0.0;
    }
  }
  tr.recovery = t0;

  // 2. Minimum time per joint, then the smallest duration every joint can meet.
  std::array<Joint1, kMaxJoints> P{};
  double T = 0;
  for (int i = 0; i < n; ++i) {
    const auto k = static_cast<std::size_t>(i);
    analyse(P[k], p0[k], v0[k], a0[k], goal[i], L[k]);
    T = std::max(T, P[k].T_min);
  }
  for (int pass = 0; pass <= n; ++pass) {
    bool changed = false;
    for (int i = 0; i < n; ++i) {
      const double Ti = achievable(P[static_cast<std::size_t>(i)], T);
      if (Ti > T) {
        T = Ti;
        changed = true;
      }
    }
    if (!changed) break;
  }
  for (int i = 0; i < n; ++i) {
    if (achievable(P[static_cast<std::size_t>(i)], T) > T * (1 + 1e-12)) return MotionStatus::no_solution;
  }

  // 3. Build every joint to end at t0 + T.
  for (int i = 0; i < n; ++i) {
    const auto k = static_cast<std::size_t>(i);
    if (!build(P[k], t0, p0[k], v0[k], a0[k], goal[i], T, tr.joint[k], true)) return MotionStatus::no_solution;
  }
  tr.duration = t0 + T;

  // 4. Overshoot (moving start) must stay inside the position limits.
  for (int i = 0; i < n; ++i) {
    const auto k = static_cast<std::size_t>(i);
    const JointPeaks pk = peaks(tr, i);
    const bool was_outside = start.pos[i] < limits.lower[k] || start.pos[i] > limits.upper[k];
    if (!was_outside && (pk.min_position < limits.lower[k] - kPosTol || pk.max_position > limits.upper[k] + kPosTol))
      return MotionStatus::path_out_of_limits;
  }
  out = tr;
  return MotionStatus::ok;
}

}  // namespace servoarm::kin
