// SPDX-License-Identifier: Apache-2.0
// The safety envelope's geometry (servoarm/kinematics/safety.hpp): heap-free, no I/O.
#include "servoarm/kinematics/safety.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdio>

#include "servoarm/kinematics/dynamics.hpp"

namespace servoarm::kin {

namespace {

constexpr double kPi = 3.14159265358979323846;

bool finite3(const Eigen::Vector3d& v) { return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z()); }

// Signed clearance of point c inside box b: the smallest distance to a face (negative outside).
double inside_clearance(const SafetyBox& b, const Eigen::Vector3d& c_base) {
  const Eigen::Vector3d c = b.frame.inverse(Eigen::Isometry) * c_base;
  double d = INFINITY;
  for (int i = 0; i < 3; ++i) d = std::min({d, c[i] - b.min[i], b.max[i] - c[i]});
  return d;
}

// Signed distance from point c to box b: positive outside, minus the clearance to the
// nearest face inside (so that a centre deep inside is further from allowed than one at a face).
double outside_distance(const SafetyBox& b, const Eigen::Vector3d& c_base) {
  const Eigen::Vector3d c = b.frame.inverse(Eigen::Isometry) * c_base;
  const Eigen::Vector3d q = c.cwiseMax(b.min).cwiseMin(b.max);
  const double d = (c - q).norm();
  return d > 0 ? d : -inside_clearance(b, c_base);
}

double tool_angle(const SafetyConfig& cfg, const Pose& tcp) {
  const Eigen::Vector3d z = tcp.linear().col(2);
  const double cosang = std::clamp(z.dot(cfg.cone_axis) / std::max(z.norm() * cfg.cone_axis.norm(), 1e-300), -1.0, 1.0);
  return std::acos(cosang);
}

// Fills v for the function `fn` at sample x; returns its excess (m, rad, m/s; negative inside).
double evaluate(const SafetyConfig& cfg, SafetyMode mode, const SafetySample& x, SafetyFunction fn, int index,
                bool elbow, SafetyViolation& v) {
  v.function = fn;
  v.index = index;
  v.other = -1;
  v.elbow = elbow;
  v.s = x.s;
  const Eigen::Vector3d c = elbow ? x.elbow : Eigen::Vector3d(x.tcp.translation());
  const double r = elbow ? cfg.elbow_radius : cfg.tool_radius;
  v.where = c;
  const SafetyLimits& lim = cfg.limits(mode);
  switch (fn) {
    case SafetyFunction::none:
      v.limit = v.value = 0;
      return -INFINITY;
    case SafetyFunction::plane: {
      const SafetyPlane& p = cfg.planes[static_cast<std::size_t>(index)];
      v.limit = p.offset;
      v.value = p.normal.dot(c) - r;
      return v.limit - v.value;
    }
    case SafetyFunction::keep_in:
      v.limit = r;
      v.value = inside_clearance(cfg.boxes[static_cast<std::size_t>(index)], c);
      return v.limit - v.value;
    case SafetyFunction::keep_out:
      v.limit = r;
      v.value = outside_distance(cfg.boxes[static_cast<std::size_t>(index)], c);
      return v.limit - v.value;
    case SafetyFunction::orientation:
      v.where = x.tcp.translation();
      v.limit = lim.cone_half_angle;
      v.value = tool_angle(cfg, x.tcp);
      return v.value - v.limit;
    case SafetyFunction::tcp_speed:
      v.where = x.tcp.translation();
      v.limit = lim.tcp_speed;
      v.value = x.tcp_velocity.norm();
      return lim.tcp_speed > 0 ? v.value - v.limit : -INFINITY;
    case SafetyFunction::elbow_speed:
      v.where = x.elbow;
      v.limit = lim.elbow_speed;
      v.value = x.elbow_velocity.norm();
      return lim.elbow_speed > 0 && cfg.elbow_frame >= 0 ? v.value - v.limit : -INFINITY;
    case SafetyFunction::joint_speed: {
      const auto j = static_cast<std::size_t>(index);
      v.where = x.tcp.translation();
      v.linear = ((cfg.prismatic >> j) & 1u) != 0;
      v.limit = lim.joint_speed[j];
      v.value = std::abs(x.joint_velocity[j]);
      return v.limit > 0 ? v.value - v.limit : -INFINITY;
    }
    case SafetyFunction::stop_time:
      v.where = x.tcp.translation();
      v.limit = lim.stop_time;
      v.value = x.stop_time;
      return v.limit > 0 && x.has_stop ? v.value - v.limit : -INFINITY;
    case SafetyFunction::stop_distance:
      v.where = x.tcp.translation();
      v.limit = lim.stop_distance;
      v.value = x.stop_distance;
      return v.limit > 0 && x.has_stop ? v.value - v.limit : -INFINITY;
    case SafetyFunction::momentum:
      v.where = x.tcp.translation();
      v.limit = lim.momentum;
      v.value = x.momentum;
      return v.limit > 0 && x.has_dynamics ? v.value - v.limit : -INFINITY;
    case SafetyFunction::power:
      v.where = x.tcp.translation();
      v.limit = lim.power;
      v.value = x.power;
      return v.limit > 0 && x.has_dynamics ? v.value - v.limit : -INFINITY;
    case SafetyFunction::self_collision:
      // the sample's closest pair (the closest is the first beyond a margin common to all pairs)
      v.index = x.self_a;
      v.other = x.self_b;
      v.where = x.self_where;
      v.limit = cfg.self_collision_margin;
      v.value = x.self_distance;
      return cfg.self_collision && x.has_self ? v.limit - v.value : -INFINITY;
  }
  return -INFINITY;
}

}  // namespace

const SafetyLimits& SafetyConfig::limits(SafetyMode m) const {
  switch (m) {
    case SafetyMode::normal: return normal;
    case SafetyMode::reduced: return reduced;
  }
  return normal;
}

const char* to_string(SafetyFunction f) {
  switch (f) {
    case SafetyFunction::none: return "none";
    case SafetyFunction::plane: return "plane";
    case SafetyFunction::keep_in: return "keep-in box";
    case SafetyFunction::keep_out: return "keep-out box";
    case SafetyFunction::orientation: return "tool orientation";
    case SafetyFunction::tcp_speed: return "tcp speed";
    case SafetyFunction::elbow_speed: return "elbow speed";
    case SafetyFunction::joint_speed: return "joint speed";
    case SafetyFunction::stop_time: return "stop time";
    case SafetyFunction::stop_distance: return "stop distance";
    case SafetyFunction::momentum: return "momentum";
    case SafetyFunction::power: return "power";
    case SafetyFunction::self_collision: return "self_collision";
  }
  return "?";
}

const char* to_string(SafetyMode m) {
  switch (m) {
    case SafetyMode::normal: return "normal";
    case SafetyMode::reduced: return "reduced";
  }
  return "?";
}

double SafetyViolation::excess() const {
  switch (function) {
    case SafetyFunction::none: return -INFINITY;
    case SafetyFunction::plane:
    case SafetyFunction::keep_in:
    case SafetyFunction::keep_out:
    case SafetyFunction::self_collision: return limit - value;
    case SafetyFunction::orientation:
    case SafetyFunction::tcp_speed:
    case SafetyFunction::elbow_speed:
    case SafetyFunction::joint_speed:
    case SafetyFunction::stop_time:
    case SafetyFunction::stop_distance:
    case SafetyFunction::momentum:
    case SafetyFunction::power: return value - limit;
  }
  return -INFINITY;
}

const char* describe(const SafetyViolation& v, char* buf, std::size_t size) {
  if (size == 0) return buf;
  const char* who = v.elbow ? "elbow" : "tool";
  char name[64];
  switch (v.function) {
    case SafetyFunction::plane:
    case SafetyFunction::keep_in:
    case SafetyFunction::keep_out:
      std::snprintf(name, sizeof name, "%s %d (%s sphere)", to_string(v.function), v.index, who);
      break;
    case SafetyFunction::none:
    case SafetyFunction::orientation:
    case SafetyFunction::tcp_speed:
    case SafetyFunction::elbow_speed:
    case SafetyFunction::stop_time:
    case SafetyFunction::stop_distance:
    case SafetyFunction::momentum:
    case SafetyFunction::power:
      std::snprintf(name, sizeof name, "%s", to_string(v.function));
      break;
    case SafetyFunction::joint_speed:
      std::snprintf(name, sizeof name, "joint %d speed", v.index + 1);
      break;
    case SafetyFunction::self_collision: {
      char a[16], b[16];
      std::snprintf(name, sizeof name, "%s %s and %s", to_string(v.function), capsule_name(v.index, a, sizeof a),
                    capsule_name(v.other, b, sizeof b));
      break;
    }
  }
  double scale = 1000.0;
  const char* unit = "mm";
  int digits = 1;
  switch (v.function) {
    case SafetyFunction::none:
    case SafetyFunction::plane:
    case SafetyFunction::keep_in:
    case SafetyFunction::keep_out:
    case SafetyFunction::self_collision:
    case SafetyFunction::stop_distance: break;
    case SafetyFunction::stop_time:
      scale = 1.0;
      unit = "s";
      digits = 3;
      break;
    case SafetyFunction::momentum:
      scale = 1.0;
      unit = "kg m/s";
      digits = 2;
      break;
    case SafetyFunction::power:
      scale = 1.0;
      unit = "W";
      break;
    case SafetyFunction::orientation: scale = 180.0 / kPi; unit = "deg"; break;
    case SafetyFunction::tcp_speed:
    case SafetyFunction::elbow_speed: unit = "mm/s"; break;
    case SafetyFunction::joint_speed:
      if (v.linear) {
        unit = "mm/s";
      } else {
        scale = 180.0 / kPi;
        unit = "deg/s";
      }
      break;
  }
  char at[24] = "";
  if (v.s >= 0) std::snprintf(at, sizeof at, " at s=%.3f", v.s);
  std::snprintf(buf, size, "safety %s%s (x=%.1f, y=%.1f, z=%.1f mm): limit %.*f %s, value %.*f %s", name, at,
                v.where.x() * 1000.0, v.where.y() * 1000.0, v.where.z() * 1000.0, digits, v.limit * scale, unit,
                digits, v.value * scale, unit);
  return buf;
}

bool check_sample(const SafetyConfig& cfg, SafetyMode mode, const SafetySample& x, double position_margin,
                  double angle_margin, double speed_margin, SafetyViolation& out, double tolerance_scale) {
  if (!cfg.enabled) return false;
  SafetyViolation v;
  const bool has_elbow = cfg.elbow_frame >= 0;
  for (int e = 0; e < (has_elbow ? 2 : 1); ++e) {
    const bool elbow = e == 1;
    for (int i = 0; i < cfg.plane_count; ++i) {
      if (elbow && !cfg.planes[static_cast<std::size_t>(i)].elbow) continue;
      if (evaluate(cfg, mode, x, SafetyFunction::plane, i, elbow, v) > position_margin) { out = v; return true; }
    }
    for (int i = 0; i < cfg.box_count; ++i) {
      const SafetyBox& b = cfg.boxes[static_cast<std::size_t>(i)];
      if (elbow && !b.elbow) continue;
      const SafetyFunction fn = b.keep_in ? SafetyFunction::keep_in : SafetyFunction::keep_out;
      if (evaluate(cfg, mode, x, fn, i, elbow, v) > position_margin) { out = v; return true; }
    }
  }
  if (cfg.cone && evaluate(cfg, mode, x, SafetyFunction::orientation, -1, false, v) > angle_margin) {
    out = v;
    return true;
  }
  if (x.has_self && evaluate(cfg, mode, x, SafetyFunction::self_collision, -1, false, v) > position_margin) {
    out = v;
    return true;
  }
  if (x.has_velocity) {
    if (evaluate(cfg, mode, x, SafetyFunction::tcp_speed, -1, false, v) > speed_margin) { out = v; return true; }
    if (evaluate(cfg, mode, x, SafetyFunction::elbow_speed, -1, true, v) > speed_margin) { out = v; return true; }
    for (int j = 0; j < x.joint_count && j < kMaxJoints; ++j) {
      const double m = tolerance_scale > 0 ? tolerance_scale * cfg.joint_speed_tolerance[static_cast<std::size_t>(j)]
                                           : speed_margin;
      if (evaluate(cfg, mode, x, SafetyFunction::joint_speed, j, false, v) > m) { out = v; return true; }
    }
  }
  return check_stop(cfg, mode, x, position_margin, tolerance_scale, out);
}

bool check_stop(const SafetyConfig& cfg, SafetyMode mode, const SafetySample& x, double position_margin,
                double tolerance_scale, SafetyViolation& out) {
  if (!cfg.enabled) return false;
  SafetyViolation v;
  if (x.has_dynamics) {
    if (evaluate(cfg, mode, x, SafetyFunction::momentum, -1, false, v) > tolerance_scale * cfg.momentum_tolerance) {
      out = v;
      return true;
    }
    if (evaluate(cfg, mode, x, SafetyFunction::power, -1, false, v) > tolerance_scale * cfg.power_tolerance) {
      out = v;
      return true;
    }
  }
  if (!x.has_stop) return false;
  if (evaluate(cfg, mode, x, SafetyFunction::stop_time, -1, false, v) > tolerance_scale * cfg.stop_time_tolerance) {
    out = v;
    return true;
  }
  if (evaluate(cfg, mode, x, SafetyFunction::stop_distance, -1, false, v) > position_margin) {
    out = v;
    return true;
  }
  return false;
}

bool stop_prediction(const Chain& chain, const JointLimits& limits, const JointState& from, JointTrajectory& scratch,
                     SafetySample& x) {
  MovejOptions o;
  if (plan_stop(limits, from, o, scratch) != MotionStatus::ok) return false;
  Pose end;
  if (forward(chain, scratch.goal, end) != Status::ok) return false;
  x.has_stop = true;
  x.stop_time = scratch.duration;
  x.stop_distance = (end.translation() - x.tcp.translation()).norm();
  return true;
}

bool dynamics_prediction(const Chain& chain, const JointState& s, SafetySample& x) {
  if (!chain.has_inertial) return false;
  JointVector tau(s.pos.size());
  if (inverse_dynamics(chain, s.pos, s.vel, s.acc, tau) != Status::ok) return false;
  // the centres of mass a short step along the velocity: their speeds by the difference
  constexpr double h = 1e-4;  // s
  const JointVector q2 = s.pos + h * s.vel;
  FrameSet a, b;
  Pose pa, pb;
  if (forward_frames(chain, s.pos, a, pa) != Status::ok || forward_frames(chain, q2, b, pb) != Status::ok) return false;
  double p = 0;
  for (int i = 0; i < chain.n_rows && i + 1 < a.count; ++i) {
    const LinkInertial& in = chain.inertial[static_cast<std::size_t>(i)];
    if (!(in.mass > 0)) continue;
    const Eigen::Vector3d c(in.com[0], in.com[1], in.com[2]);
    p += in.mass * (b.frame[i + 1] * c - a.frame[i + 1] * c).norm() / h;
  }
  double w = 0;
  for (Eigen::Index j = 0; j < tau.size(); ++j) w += std::abs(tau[j] * s.vel[j]);
  x.has_dynamics = true;
  x.momentum = p;
  x.power = w;
  return true;
}

void set_velocity(SafetySample& x, const SafetySample& p, const JointVector& q_prev, const JointVector& q, double h) {
  if (!(h > 0)) return;
  x.has_velocity = true;
  x.tcp_velocity = (x.tcp.translation() - p.tcp.translation()) / h;
  x.elbow_velocity = (x.elbow - p.elbow) / h;
  const int n = static_cast<int>(std::min<Eigen::Index>(std::min(q.size(), q_prev.size()), kMaxJoints));
  x.joint_count = n;
  for (int j = 0; j < n; ++j) x.joint_velocity[static_cast<std::size_t>(j)] = (q[j] - q_prev[j]) / h;
}

double speed_ratio(const SafetyConfig& cfg, SafetyMode mode, const SafetySample& x, double stop_aim) {
  if (!cfg.enabled || (!x.has_velocity && !x.has_stop && !x.has_dynamics)) return 0;
  const SafetyLimits& lim = cfg.limits(mode);
  double r = 0;
  if (lim.tcp_speed > 0) r = std::max(r, x.tcp_velocity.norm() / lim.tcp_speed);
  if (lim.elbow_speed > 0 && cfg.elbow_frame >= 0) r = std::max(r, x.elbow_velocity.norm() / lim.elbow_speed);
  for (int j = 0; j < x.joint_count && j < kMaxJoints; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    if (lim.joint_speed[ju] > 0) r = std::max(r, std::abs(x.joint_velocity[ju]) / lim.joint_speed[ju]);
  }
  // A jerk-limited stop from a low speed v lasts about 2 sqrt(v / jerk) and travels about
  // v sqrt(v / jerk): speed goes with the square of the time and the 2/3 power of the
  // distance there (less steeply at higher speeds), so these ratios slow a path enough.
  if (x.has_stop) {
    if (lim.stop_time > 0) r = std::max(r, std::pow(x.stop_time / (stop_aim * lim.stop_time), 2.0));
    if (lim.stop_distance > 0) r = std::max(r, std::cbrt(std::pow(x.stop_distance / (stop_aim * lim.stop_distance), 2.0)));
  }
  if (x.has_dynamics) {
    if (lim.momentum > 0) r = std::max(r, x.momentum / lim.momentum);
    // power: from proportional to speed (gravity, friction) to its cube (inertia); the square
    // root between them, the caller plans again until it holds
    if (lim.power > 0) r = std::max(r, std::sqrt(x.power / lim.power));
  }
  return r;
}

bool is_speed(SafetyFunction f) {
  switch (f) {
    case SafetyFunction::tcp_speed:
    case SafetyFunction::elbow_speed:
    case SafetyFunction::joint_speed:
    case SafetyFunction::stop_time:
    case SafetyFunction::stop_distance:
    case SafetyFunction::momentum:
    case SafetyFunction::power: return true;
    case SafetyFunction::none:
    case SafetyFunction::plane:
    case SafetyFunction::keep_in:
    case SafetyFunction::keep_out:
    case SafetyFunction::orientation:
    case SafetyFunction::self_collision: return false;
  }
  return false;
}

int trigger_plane(const SafetyConfig& cfg, const SafetySample& x) {
  if (!cfg.enabled) return -1;
  const Eigen::Vector3d c = x.tcp.translation();
  for (int i = 0; i < cfg.trigger_count && i < kMaxSafetyPlanes; ++i) {
    const SafetyPlane& p = cfg.trigger_planes[static_cast<std::size_t>(i)];
    if (p.normal.dot(c) - cfg.tool_radius < p.offset) return i;
  }
  return -1;
}

double safety_excess(const SafetyConfig& cfg, SafetyMode mode, const SafetySample& x, const SafetyViolation& which) {
  SafetyViolation v;
  return evaluate(cfg, mode, x, which.function, which.index, which.elbow, v);
}

bool check_path(const SafetyConfig& cfg, SafetyMode mode, std::span<const SafetySample> path, SafetyViolation& out) {
  for (const SafetySample& x : path)
    if (check_sample(cfg, mode, x, 0.0, 0.0, 0.0, out)) return true;
  return false;
}

bool safety_sample(const Chain& chain, const SafetyConfig& cfg, const JointVector& q, double s, SafetySample& out) {
  FrameSet frames;
  Pose tcp;
  if (forward_frames(chain, q, frames, tcp) != Status::ok) return false;
  out.s = s;
  out.tcp = tcp;
  out.has_velocity = false;
  out.joint_count = 0;
  out.has_stop = false;
  out.has_dynamics = false;
  if (cfg.elbow_frame >= 0 && cfg.elbow_frame < frames.count)
    out.elbow = frames.frame[cfg.elbow_frame].translation();
  else
    out.elbow = tcp.translation();
  out.has_self = false;
  if (cfg.self_collision) self_capsules(chain, frames, tcp, true, cfg.tool_radius, out);
  return true;
}

double segment_distance(const Eigen::Vector3d& p1, const Eigen::Vector3d& q1, const Eigen::Vector3d& p2,
                        const Eigen::Vector3d& q2, Eigen::Vector3d& c1, Eigen::Vector3d& c2) {
  // Ericson, Real-Time Collision Detection (2005), 5.1.9: the closest points are
  // p1 + s d1 and p2 + t d2 with (s, t) minimising |r + s d1 - t d2|^2 over [0, 1]^2. Unclamped,
  // s = (b f - c e) / (a e - b^2); s is clamped, t taken for it, and where t leaves [0, 1] it is
  // clamped and s taken again for it, which reaches the constrained minimum.
  constexpr double kPoint = 1e-24;  // m^2: a segment shorter than 1e-12 m is a point
  const Eigen::Vector3d d1 = q1 - p1, d2 = q2 - p2, r = p1 - p2;
  const double a = d1.squaredNorm(), e = d2.squaredNorm(), f = d2.dot(r);
  double s = 0, t = 0;
  if (a <= kPoint && e <= kPoint) {
    // both points
  } else if (a <= kPoint) {
    t = std::clamp(f / e, 0.0, 1.0);
  } else {
    const double c = d1.dot(r);
    if (e <= kPoint) {
      s = std::clamp(-c / a, 0.0, 1.0);
    } else {
      const double b = d1.dot(d2);
      const double denom = a * e - b * b;  // >= 0; 0 (to rounding) when the segments are parallel
      // parallel (to within 1e-7 rad: below that denom is rounding): s = 0, the first end, then t
      // and s as below; exact for parallel segments, within 1e-7 of their length short of it
      s = denom > 1e-14 * a * e ? std::clamp((b * f - c * e) / denom, 0.0, 1.0) : 0.0;
      t = (b * s + f) / e;
      if (t < 0.0) {
        t = 0.0;
        s = std::clamp(-c / a, 0.0, 1.0);
      } else if (t > 1.0) {
        t = 1.0;
        s = std::clamp((b - c) / a, 0.0, 1.0);
      }
    }
  }
  c1 = p1 + s * d1;
  c2 = p2 + t * d2;
  return (c1 - c2).norm();
}

void self_capsules(const Chain& chain, const FrameSet& frames, const Pose& tcp, bool with_tool, double tool_radius,
                   SafetySample& x) {
  x.has_self = false;
  // every capsule in the base frame (slots as kMaxCapsules)
  std::array<Eigen::Vector3d, kMaxCapsules> a, b;
  std::array<double, kMaxCapsules> r{};
  std::uint32_t present = chain.capsule_mask & ((1u << kToolCapsule) - 1u);
  for (std::uint32_t m = present; m != 0; m &= m - 1) {
    const int k = std::countr_zero(m);
    if (k >= frames.count) {  // (a chain changed after its capsules were set)
      present &= ~(1u << k);
      continue;
    }
    const Capsule& c = chain.capsule[static_cast<std::size_t>(k)];
    const Pose& f = frames.frame[k];
    a[static_cast<std::size_t>(k)] = f * c.a;
    b[static_cast<std::size_t>(k)] = f * c.b;
    r[static_cast<std::size_t>(k)] = c.radius;
  }
  if (with_tool && chain.n_rows < frames.count) {
    a[kToolCapsule] = frames.frame[chain.n_rows].translation();
    b[kToolCapsule] = tcp.translation();
    r[kToolCapsule] = tool_radius;
    present |= 1u << kToolCapsule;
  }
  double best = INFINITY;
  Eigen::Vector3d c1, c2;
  for (std::uint32_t mi = present; mi != 0; mi &= mi - 1) {
    const int i = std::countr_zero(mi);
    const auto iu = static_cast<std::size_t>(i);
    for (std::uint32_t mj = chain.capsule_pairs[iu] & present; mj != 0; mj &= mj - 1) {
      const int j = std::countr_zero(mj);
      const auto ju = static_cast<std::size_t>(j);
      const double d = segment_distance(a[iu], b[iu], a[ju], b[ju], c1, c2) - r[iu] - r[ju];
      if (d < best) {
        best = d;
        x.self_a = static_cast<std::int8_t>(i);
        x.self_b = static_cast<std::int8_t>(j);
        x.self_where = 0.5 * (c1 + c2);
      }
    }
  }
  if (best < INFINITY) {
    x.has_self = true;
    x.self_distance = best;
  }
}

void set_capsule_pairs(Chain& chain, std::span<const std::array<int, 2>> ignore) {
  // the body each slot moves with: 0 the base, then one more after each joint row
  std::array<int, kMaxCapsules> body{};
  int joints = 0;
  for (int k = 1; k <= chain.n_rows && k < kMaxCapsules; ++k) {
    if (chain.rows[static_cast<std::size_t>(k - 1)].type != JointType::fixed) ++joints;
    body[static_cast<std::size_t>(k)] = joints;
  }
  body[kToolCapsule] = joints;
  const std::uint32_t present = (chain.capsule_mask & ((1u << kToolCapsule) - 1u)) | (1u << kToolCapsule);
  for (int i = 0; i < kMaxCapsules; ++i) {
    std::uint32_t m = 0;
    for (int j = i + 1; j < kMaxCapsules; ++j) {
      const bool both = ((present >> i) & 1u) != 0 && ((present >> j) & 1u) != 0;
      if (both && std::abs(body[static_cast<std::size_t>(i)] - body[static_cast<std::size_t>(j)]) > 1) m |= 1u << j;
    }
    chain.capsule_pairs[static_cast<std::size_t>(i)] = m;
  }
  for (const auto& p : ignore) {
    const int i = std::min(p[0], p[1]), j = std::max(p[0], p[1]);
    if (i >= 0 && j < kMaxCapsules) chain.capsule_pairs[static_cast<std::size_t>(i)] &= ~(1u << j);
  }
}

int capsule_pair_count(const Chain& chain) {
  if (chain.capsule_mask == 0) return 0;
  const std::uint32_t present = (chain.capsule_mask & ((1u << kToolCapsule) - 1u)) | (1u << kToolCapsule);
  int n = 0;
  for (std::uint32_t m = present; m != 0; m &= m - 1)
    n += std::popcount(chain.capsule_pairs[static_cast<std::size_t>(std::countr_zero(m))] & present);
  return n;
}

const char* capsule_name(int slot, char* buf, std::size_t size) {
  if (size == 0) return buf;
  if (slot == 0)
    std::snprintf(buf, size, "base");
  else if (slot == kToolCapsule)
    std::snprintf(buf, size, "tool");
  else
    std::snprintf(buf, size, "link %d", slot);
  return buf;
}

const char* safety_config_problem(const SafetyConfig& cfg, char* buf, std::size_t size) {
  if (size == 0) return buf;
  buf[0] = '\0';
  auto bad = [&](const char* what, int i) {
    std::snprintf(buf, size, what, i);
    return buf;
  };
  if (!std::isfinite(cfg.tool_radius) || cfg.tool_radius < 0) return bad("tool radius must be finite and >= 0", 0);
  if (!std::isfinite(cfg.elbow_radius) || cfg.elbow_radius < 0) return bad("elbow radius must be finite and >= 0", 0);
  if (cfg.plane_count < 0 || cfg.plane_count > kMaxSafetyPlanes) return bad("at most %d planes", kMaxSafetyPlanes);
  if (cfg.box_count < 0 || cfg.box_count > kMaxSafetyBoxes) return bad("at most %d boxes", kMaxSafetyBoxes);
  for (int i = 0; i < cfg.plane_count; ++i) {
    const SafetyPlane& p = cfg.planes[static_cast<std::size_t>(i)];
    if (!finite3(p.normal) || !std::isfinite(p.offset)) return bad("plane %d: not a finite number", i);
    if (std::abs(p.normal.norm() - 1.0) > 1e-9) return bad("plane %d: the normal must be a unit vector (zero or unnormalised)", i);
  }
  if (cfg.trigger_count < 0 || cfg.trigger_count > kMaxSafetyPlanes) return bad("at most %d trigger planes", kMaxSafetyPlanes);
  for (int i = 0; i < cfg.trigger_count; ++i) {
    const SafetyPlane& p = cfg.trigger_planes[static_cast<std::size_t>(i)];
    if (!finite3(p.normal) || !std::isfinite(p.offset)) return bad("trigger plane %d: not a finite number", i);
    if (std::abs(p.normal.norm() - 1.0) > 1e-9) return bad("trigger plane %d: the normal must be a unit vector", i);
  }
  for (int i = 0; i < cfg.box_count; ++i) {
    const SafetyBox& b = cfg.boxes[static_cast<std::size_t>(i)];
    if (!finite3(b.min) || !finite3(b.max)) return bad("box %d: not a finite number", i);
    if (!b.frame.matrix().allFinite() ||
        !(b.frame.linear().transpose() * b.frame.linear()).isApprox(Eigen::Matrix3d::Identity(), 1e-9))
      return bad("box %d: its frame is not a finite rotation and translation", i);
    if ((b.min.array() > b.max.array()).any()) return bad("box %d: inverted (a min above its max)", i);
    if (b.keep_in && ((b.max - b.min).minCoeff() < 2.0 * cfg.tool_radius))
      return bad("box %d: keep-in box narrower than the tool sphere's diameter", i);
    if (b.keep_in && b.elbow && cfg.elbow_frame >= 0 && (b.max - b.min).minCoeff() < 2.0 * cfg.elbow_radius)
      return bad("box %d: keep-in box narrower than the elbow sphere's diameter", i);
  }
  if (cfg.cone) {
    if (!finite3(cfg.cone_axis) || std::abs(cfg.cone_axis.norm() - 1.0) > 1e-9)
      return bad("cone axis must be a finite unit vector", 0);
  }
  for (const SafetyLimits* l : {&cfg.normal, &cfg.reduced}) {
    if (!std::isfinite(l->tcp_speed) || l->tcp_speed < 0 || !std::isfinite(l->elbow_speed) || l->elbow_speed < 0)
      return bad("speed limits must be finite and >= 0", 0);
    if (!std::isfinite(l->stop_time) || l->stop_time < 0 || !std::isfinite(l->stop_distance) || l->stop_distance < 0)
      return bad("stop time and distance limits must be finite and >= 0", 0);
    if (!std::isfinite(l->momentum) || l->momentum < 0 || !std::isfinite(l->power) || l->power < 0)
      return bad("momentum and power limits must be finite and >= 0", 0);
    for (const double js : l->joint_speed)
      if (!std::isfinite(js) || js < 0) return bad("joint speed limits must be finite and >= 0", 0);
    if (cfg.cone && (!std::isfinite(l->cone_half_angle) || l->cone_half_angle <= 0 || l->cone_half_angle > kPi))
      return bad("cone half angle must be in (0, 180] deg", 0);
  }
  if (!std::isfinite(cfg.position_tolerance) || cfg.position_tolerance < 0 || !std::isfinite(cfg.angle_tolerance) ||
      cfg.angle_tolerance < 0 || !std::isfinite(cfg.speed_tolerance) || cfg.speed_tolerance < 0)
    return bad("tolerances must be finite and >= 0", 0);
  if (!std::isfinite(cfg.stop_time_tolerance) || cfg.stop_time_tolerance < 0 || !std::isfinite(cfg.momentum_tolerance) ||
      cfg.momentum_tolerance < 0 || !std::isfinite(cfg.power_tolerance) || cfg.power_tolerance < 0)
    return bad("tolerances must be finite and >= 0", 0);
  for (const double t : cfg.joint_speed_tolerance)
    if (!std::isfinite(t) || t < 0) return bad("tolerances must be finite and >= 0", 0);
  if (!std::isfinite(cfg.self_collision_margin) || cfg.self_collision_margin < 0)
    return bad("the self-collision margin must be finite and >= 0", 0);
  return buf;
}

}  // namespace servoarm::kin
