// SPDX-License-Identifier: Apache-2.0
// Robot description files (TOML, read with toml++ through file_input.hpp). Set-up code:
// allocates; exception-free. Every error is one line that starts with the file and the
// line:column of the offending value ("arm.toml:14:5: joint 2: key 'a': ..."), names the
// joint (1-based, in chain order) and the key, and says what is allowed.
#include "servoarm/kinematics/description.hpp"

#include <Eigen/Eigenvalues>

#include "servoarm/kinematics/dynamics.hpp"
#include "servoarm/kinematics/io/file_input.hpp"
#include "servoarm/kinematics/safety.hpp"
#ifdef SERVOARM_WITH_URDF
#include "servoarm/kinematics/urdf.hpp"
#endif

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <set>
#include <vector>

#include <unistd.h>

namespace servoarm::kin {
namespace {

// Plausible ranges (SI): a value outside them is a wrong unit or a typo, never an arm.
constexpr double kMaxLength = 100.0;              // m: a, d, tool/base xyz, prismatic limits
constexpr double kMaxAngle = 2 * M_PI;            // rad: theta, alpha, tool/base rpy (one turn)
constexpr double kMaxRevoluteRange = 20 * M_PI;   // rad: revolute limits (10 turns)
constexpr double kMaxRevVel = 100.0, kMaxRevAcc = 1e4, kMaxRevJerk = 1e6;  // rad/s, /s^2, /s^3
constexpr double kMaxLinVel = 10.0, kMaxLinAcc = 1e3, kMaxLinJerk = 1e5;   // m/s, /s^2, /s^3
constexpr double kMaxMass = 1e4;                  // kg
constexpr double kMaxInertia = 1e4;               // kg m^2 (inertia elements, rotor inertia)
constexpr double kMaxGearRatio = 1e5;             // |motor turns per joint turn|
constexpr double kMaxFriction = 1e5;              // N m s/rad, N m (N s/m, N)
constexpr double kMaxEffort = 1e6;                // N m (N): a joint's torque (force) limit

std::string shown(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.10g", v);
  return b;
}

class Reader {
 public:
  explicit Reader(std::string origin) : origin_(std::move(origin)) {}

  /// Record the first error: "<origin>[:line:col]: [where: ]what". Returns false.
  bool fail(const toml::node* at, const std::string& where, const std::string& what) {
    if (error_.empty())
      error_ = one_line((at ? source_text(at->source(), origin_) : origin_) + ": " + (where.empty() ? "" : where + ": ") + what);
    return false;
  }
  bool failed() const { return !error_.empty(); }
  const std::string& error() const { return error_; }

  bool number(const toml::node& v, const std::string& where, const std::string& key, double& x) {
    if (const auto* i = v.as_integer()) x = static_cast<double>(i->get());
    else if (const auto* f = v.as_floating_point()) x = f->get();
    else return fail(&v, where, "key '" + key + "': expected a number, got " + type_name(v));
    if (!std::isfinite(x)) return fail(&v, where, "key '" + key + "': value is not finite");
    return true;
  }

  /// A number whose magnitude, times `unit` (to SI), is at most `max` (SI); `what` names
  /// the bound in the message ("100 m").
  bool bounded(const toml::node& v, const std::string& where, const std::string& key, double unit, double max,
               const std::string& what, double& x) {
    if (!number(v, where, key, x)) return false;
    if (std::fabs(x * unit) > max)
      return fail(&v, where, "key '" + key + "': " + shown(x) + " is outside the plausible range (magnitude at most " + what + ")");
    return true;
  }

  bool string(const toml::node& v, const std::string& where, const std::string& key, std::string& out) {
    const auto* s = v.as_string();
    if (!s) return fail(&v, where, "key '" + key + "': expected a string, got " + type_name(v));
    out = s->get();
    return true;
  }

  bool numbers(const toml::node& v, const std::string& where, const std::string& key, double* out, std::size_t n) {
    const auto* arr = v.as_array();
    if (!arr)
      return fail(&v, where, "key '" + key + "': expected an array of " + std::to_string(n) + " numbers, got " + type_name(v));
    if (arr->size() != n)
      return fail(&v, where, "key '" + key + "': expected " + std::to_string(n) + " numbers, got " + std::to_string(arr->size()));
    for (std::size_t i = 0; i < n; ++i)
      if (!number(*arr->get(i), where, key, out[i])) return false;
    return true;
  }

  bool only_keys(const toml::table& table, const std::set<std::string>& allowed, const std::string& where) {
    for (const auto& [k, v] : table) {
      if (!allowed.count(std::string(k.str()))) {
        std::string list;
        for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
        return fail(&v, where, "key '" + std::string(k.str()) + "' is not known (expected one of: " + list + ")");
      }
    }
    return true;
  }

 private:
  std::string origin_;
  std::string error_;
};

// Every reader below returns false once rd holds the error (the first one wins).
#define SERVOARM_TRY(expr) \
  do {                     \
    if (!(expr)) return false; \
  } while (0)

bool read_transform(Reader& rd, const toml::node& n, const std::string& key, double lu, double au, Pose& T) {
  const toml::table* t = n.as_table();
  if (!t) return rd.fail(&n, "", "key '" + key + "': expected a table with xyz and rpy");
  const std::string where = "[" + key + "]";
  SERVOARM_TRY(rd.only_keys(*t, {"xyz", "rpy"}, where));
  double xyz[3] = {0, 0, 0}, rpy[3] = {0, 0, 0};
  if (const toml::node* v = t->get("xyz")) {
    SERVOARM_TRY(rd.numbers(*v, where, "xyz", xyz, 3));
    for (double x : xyz)
      if (std::fabs(x * lu) > kMaxLength)
        return rd.fail(v, where, "key 'xyz': " + shown(x) + " is outside the plausible range (magnitude at most 100 m)");
  }
  if (const toml::node* v = t->get("rpy")) {
    SERVOARM_TRY(rd.numbers(*v, where, "rpy", rpy, 3));
    for (double x : rpy)
      if (std::fabs(x * au) > kMaxAngle)
        return rd.fail(v, where, "key 'rpy': " + shown(x) + " is outside the plausible range (magnitude at most one turn)");
  }
  T = Pose::Identity();
  T.translation() = Eigen::Vector3d(xyz[0], xyz[1], xyz[2]) * lu;
  T.linear() = (Eigen::AngleAxisd(rpy[2] * au, Eigen::Vector3d::UnitZ()) *
                Eigen::AngleAxisd(rpy[1] * au, Eigen::Vector3d::UnitY()) *
                Eigen::AngleAxisd(rpy[0] * au, Eigen::Vector3d::UnitX()))
                   .toRotationMatrix();
  return true;
}

// A capsule (self-collision, docs/safety.md): `{ from = [x, y, z], to = [x, y, z], radius = r }`,
// lengths in the description's unit, in the frame after the row (the base frame for
// base_capsule): every point within r of the segment from-to.
bool read_capsule(Reader& rd, const toml::node& n, const std::string& where, const std::string& key, double L,
                  Capsule& c) {
  const toml::table* t = n.as_table();
  if (!t) return rd.fail(&n, where, "key '" + key + "': expected a table { from = [x, y, z], to = [x, y, z], radius = r }");
  SERVOARM_TRY(rd.only_keys(*t, {"from", "to", "radius"}, where.empty() ? key : where + ": " + key));
  for (const char* k : {"from", "to", "radius"})
    if (!t->contains(k)) return rd.fail(&n, where, "key '" + key + "': '" + k + "' is missing (from, to, radius)");
  double a[3], b[3], r = 0;
  SERVOARM_TRY(rd.numbers(*t->get("from"), where, key + ".from", a, 3));
  SERVOARM_TRY(rd.numbers(*t->get("to"), where, key + ".to", b, 3));
  for (int i = 0; i < 3; ++i)
    if (std::fabs(a[i] * L) > kMaxLength || std::fabs(b[i] * L) > kMaxLength)
      return rd.fail(&n, where, "key '" + key + "': a point outside the plausible range (magnitude at most 100 m)");
  const toml::node* rv = t->get("radius");
  SERVOARM_TRY(rd.number(*rv, where, key + ".radius", r));
  if (r < 0) return rd.fail(rv, where, "key '" + key + ".radius': " + shown(r) + " must not be negative");
  if (r * L > 10.0) return rd.fail(rv, where, "key '" + key + ".radius': " + shown(r) + " is more than 10 m (wrong length unit?)");
  c.a = Eigen::Vector3d(a[0], a[1], a[2]) * L;
  c.b = Eigen::Vector3d(b[0], b[1], b[2]) * L;
  c.radius = r * L;
  return true;
}

// The capsules' pairs: self_collision_ignore = [[i, j], ...] (0 = base, k = the link of the
// k-th [[joint]] table, "tool"), then no checked pair may overlap at the zero pose (every
// joint at 0, clamped into its limits): a description whose arm collides with itself at rest
// is wrong, and naming the pair tells which capsule to shrink or which pair to ignore.
bool read_capsule_pairs(Reader& rd, const toml::table& root, Chain& chain, const std::vector<const toml::node*>& at) {
  std::vector<std::array<int, 2>> ignore;
  if (const toml::node* v = root.get("self_collision_ignore")) {
    const toml::array* arr = v->as_array();
    if (!arr) return rd.fail(v, "", "key 'self_collision_ignore': expected an array of pairs [[1, 3], [2, \"tool\"]]");
    for (std::size_t i = 0; i < arr->size(); ++i) {
      const toml::node& e = *arr->get(i);
      const toml::array* pair = e.as_array();
      if (!pair || pair->size() != 2) return rd.fail(&e, "", "key 'self_collision_ignore': each entry is a pair [i, j]");
      std::array<int, 2> p{};
      for (std::size_t k = 0; k < 2; ++k) {
        const toml::node& x = *pair->get(k);
        if (const auto* s = x.as_string(); s && s->get() == "tool") {
          p[k] = kToolCapsule;
        } else if (const auto* s2 = x.as_string(); s2 && s2->get() == "base") {
          p[k] = 0;
        } else if (const auto* n = x.as_integer(); n && n->get() >= 0 && n->get() <= chain.n_rows) {
          p[k] = static_cast<int>(n->get());
        } else {
          return rd.fail(&x, "", "key 'self_collision_ignore': expected 0 (the base), 1.." + std::to_string(chain.n_rows) +
                                     " (a [[joint]] table's link) or \"tool\"");
        }
        if (p[k] != kToolCapsule && ((chain.capsule_mask >> p[k]) & 1u) == 0) {
          char nm[16];
          return rd.fail(&x, "", std::string("key 'self_collision_ignore': ") + capsule_name(p[k], nm, sizeof nm) +
                                     " has no capsule");
        }
      }
      if (p[0] == p[1]) return rd.fail(&e, "", "key 'self_collision_ignore': a pair of one capsule with itself");
      ignore.push_back(p);
    }
  }
  set_capsule_pairs(chain, ignore);
  if (chain.capsule_mask == 0) return true;
  JointVector q = JointVector::Zero(chain.n_joints);
  for (int j = 0; j < chain.n_joints; ++j) q[j] = std::clamp(0.0, chain.joint(j).lower, chain.joint(j).upper);
  FrameSet frames;
  Pose tcp;
  if (forward_frames(chain, q, frames, tcp) != Status::ok) return rd.fail(nullptr, "", "the zero pose has no forward kinematics");
  SafetySample x;
  self_capsules(chain, frames, tcp, false, 0.0, x);
  if (x.has_self && x.self_distance < 0) {
    char a[16], b[16];
    return rd.fail(at[static_cast<std::size_t>(x.self_b)], "",
                   std::string("the capsules of ") + capsule_name(x.self_a, a, sizeof a) + " and " +
                       capsule_name(x.self_b, b, sizeof b) + " overlap by " + shown(-x.self_distance / chain.length_unit) +
                       (chain.length_unit == 1.0 ? " m" : " mm") +
                       " at the zero pose (joints at 0, clamped into their limits): make one smaller or list the pair "
                       "in self_collision_ignore");
  }
  return true;
}

// Inertial keys of one row (docs/dynamics.md): mass [kg], com [length unit, DH frame of
// the row], inertia [kg m^2, about the COM, DH frame: ixx iyy izz ixy ixz iyz],
// rotor_inertia [kg m^2, motor side], gear_ratio [motor turns per joint turn],
// friction = [viscous, coulomb] [N m s/rad, N m; N s/m, N for a prismatic joint].
// A fixed row may carry mass, com and inertia (a body rigidly attached to the one
// before it); rotor_inertia, gear_ratio and friction are refused there.
bool read_inertial(Reader& rd, const toml::table& j, const std::string& where, Chain& chain, double L) {
  const bool any = j.contains("mass") || j.contains("com") || j.contains("inertia") ||
                   j.contains("rotor_inertia") || j.contains("gear_ratio") || j.contains("friction");
  if (!any) return true;
  LinkInertial li;
  if (const toml::node* v = j.get("mass")) {
    SERVOARM_TRY(rd.number(*v, where, "mass", li.mass));
    if (li.mass < 0) return rd.fail(v, where, "key 'mass': must not be negative (kg)");
    if (li.mass > kMaxMass) return rd.fail(v, where, "key 'mass': more than 10000 kg");
  }
  if (const toml::node* v = j.get("com")) {
    if (!j.contains("mass")) return rd.fail(v, where, "key 'com': needs 'mass'");
    double c[3];
    SERVOARM_TRY(rd.numbers(*v, where, "com", c, 3));
    for (int k = 0; k < 3; ++k) li.com[static_cast<std::size_t>(k)] = c[k] * L;
    if (!(std::sqrt(li.com[0] * li.com[0] + li.com[1] * li.com[1] + li.com[2] * li.com[2]) <= 10.0))
      return rd.fail(v, where, "key 'com': more than 10 m from the frame origin (wrong length unit?)");
  }
  if (const toml::node* v = j.get("inertia")) {
    double I[6];
    SERVOARM_TRY(rd.numbers(*v, where, "inertia", I, 6));
    for (int k = 0; k < 6; ++k) {
      if (std::fabs(I[k]) > kMaxInertia) return rd.fail(v, where, "key 'inertia': an element beyond 10000 kg m^2");
      li.inertia[static_cast<std::size_t>(k)] = I[k];
    }
    Eigen::Matrix3d M;
    M << I[0], I[3], I[4], I[3], I[1], I[5], I[4], I[5], I[2];
    const Eigen::Vector3d e = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(M, Eigen::EigenvaluesOnly).eigenvalues();
    const double tol = 1e-9 * std::max(1e-12, e.cwiseAbs().maxCoeff());
    if (e.minCoeff() < -tol)
      return rd.fail(v, where, "key 'inertia': not positive semi-definite (kg m^2 about the COM: ixx iyy izz ixy ixz iyz)");
    if (e[0] + e[1] < e[2] - tol)
      return rd.fail(v, where, "key 'inertia': principal moments violate the triangle inequality (I1 + I2 >= I3)");
  }
  if (const toml::node* v = j.get("rotor_inertia")) {
    SERVOARM_TRY(rd.number(*v, where, "rotor_inertia", li.rotor_inertia));
    if (li.rotor_inertia < 0) return rd.fail(v, where, "key 'rotor_inertia': must not be negative (kg m^2)");
    if (li.rotor_inertia > kMaxInertia) return rd.fail(v, where, "key 'rotor_inertia': more than 10000 kg m^2");
  }
  if (const toml::node* v = j.get("gear_ratio")) {
    SERVOARM_TRY(rd.number(*v, where, "gear_ratio", li.gear_ratio));
    if (li.gear_ratio == 0) return rd.fail(v, where, "key 'gear_ratio': must not be 0");
    if (std::fabs(li.gear_ratio) > kMaxGearRatio || std::fabs(li.gear_ratio) < 1 / kMaxGearRatio)
      return rd.fail(v, where, "key 'gear_ratio': " + shown(li.gear_ratio) + " is outside the plausible range (magnitude 1e-5 to 1e5)");
  }
  if (const toml::node* v = j.get("friction")) {
    double f[2];
    SERVOARM_TRY(rd.numbers(*v, where, "friction", f, 2));
    if (f[0] < 0 || f[1] < 0) return rd.fail(v, where, "key 'friction': [viscous, coulomb] must not be negative");
    if (f[0] > kMaxFriction || f[1] > kMaxFriction) return rd.fail(v, where, "key 'friction': beyond 1e5");
    li.viscous = f[0];
    li.coulomb = f[1];
  }
  if (set_inertial(chain, chain.n_rows - 1, li) != Status::ok) return rd.fail(&j, where, "inertial data rejected");
  return true;
}

bool read_row(Reader& rd, const toml::node& node, std::size_t i, int& njoints, double L, double A, Chain& chain) {
  const std::string where = "joint " + std::to_string(i + 1);
  const toml::table* jt = node.as_table();
  if (!jt) return rd.fail(&node, where, "expected a table");
  const toml::table& j = *jt;
  SERVOARM_TRY(rd.only_keys(j, {"type", "theta", "d", "a", "alpha", "direction", "limits", "max_velocity", "max_acceleration",
                                "max_jerk", "max_effort", "name", "mass", "com", "inertia", "rotor_inertia", "gear_ratio", "friction",
                                "capsule"},
                            where));
  const toml::node* tv = j.get("type");
  if (!tv) return rd.fail(&j, where, "key 'type' is missing (revolute, prismatic or fixed)");
  std::string type;
  SERVOARM_TRY(rd.string(*tv, where, "type", type));
  DhRow row;
  if (type == "revolute")
    row.type = JointType::revolute;
  else if (type == "prismatic")
    row.type = JointType::prismatic;
  else if (type == "fixed")
    row.type = JointType::fixed;
  else
    return rd.fail(tv, where, "key 'type': expected \"revolute\", \"prismatic\" or \"fixed\", got \"" + type + "\"");
  const bool joint = row.type != JointType::fixed;
  const bool rev = row.type == JointType::revolute;
  if (joint && ++njoints > kMaxJoints)
    return rd.fail(&j, where, "more than " + std::to_string(kMaxJoints) + " joints (the compile-time capacity)");
  if (static_cast<int>(i) >= kMaxRows)
    return rd.fail(&j, where, "more than " + std::to_string(kMaxRows) + " rows (the compile-time capacity)");
  if (const toml::node* v = j.get("name")) {
    std::string ignored;
    SERVOARM_TRY(rd.string(*v, where, "name", ignored));
  }
  double x = 0;
  if (const toml::node* v = j.get("theta")) {
    SERVOARM_TRY(rd.bounded(*v, where, "theta", A, kMaxAngle, "one turn", x));
    row.theta = x * A;
  }
  if (const toml::node* v = j.get("d")) {
    SERVOARM_TRY(rd.bounded(*v, where, "d", L, kMaxLength, "100 m", x));
    row.d = x * L;
  }
  if (const toml::node* v = j.get("a")) {
    SERVOARM_TRY(rd.bounded(*v, where, "a", L, kMaxLength, "100 m", x));
    row.a = x * L;
  }
  if (const toml::node* v = j.get("alpha")) {
    SERVOARM_TRY(rd.bounded(*v, where, "alpha", A, kMaxAngle, "one turn", x));
    row.alpha = x * A;
  }
  const double ju = row.type == JointType::prismatic ? L : A;  // joint unit
  for (const char* k : {"direction", "limits", "max_velocity", "max_acceleration", "max_jerk", "max_effort", "rotor_inertia", "gear_ratio",
                        "friction"})
    if (!joint && j.contains(k)) return rd.fail(j.get(k), where, std::string("key '") + k + "' does not apply to a fixed row");
  if (const toml::node* v = j.get("direction")) {
    double dir = 0;
    SERVOARM_TRY(rd.number(*v, where, "direction", dir));
    if (dir != 1.0 && dir != -1.0) return rd.fail(v, where, "key 'direction': expected 1 or -1");
    row.direction = dir;
  }
  if (const toml::node* v = j.get("limits")) {
    double lim[2];
    SERVOARM_TRY(rd.numbers(*v, where, "limits", lim, 2));
    const double max = rev ? kMaxRevoluteRange : kMaxLength;
    for (double l : lim)
      if (std::fabs(l * ju) > max)
        return rd.fail(v, where, "key 'limits': " + shown(l) + " is outside the plausible range (magnitude at most " +
                                     (rev ? "10 turns" : "100 m") + ")");
    if (!(lim[0] < lim[1])) return rd.fail(v, where, "key 'limits': lower limit must be below upper limit");
    row.lower = lim[0] * ju;
    row.upper = lim[1] * ju;
  }
  if (joint) {
    // Defaults: a moderate industrial arm (documented in docs/kinematics.md).
    row.dynamics.max_velocity = rev ? M_PI : 0.5;
    row.dynamics.max_acceleration = rev ? 4 * M_PI : 2.0;
    row.dynamics.max_jerk = rev ? 40 * M_PI : 20.0;
    const char* keys[3] = {"max_velocity", "max_acceleration", "max_jerk"};
    const double maxes[3] = {rev ? kMaxRevVel : kMaxLinVel, rev ? kMaxRevAcc : kMaxLinAcc, rev ? kMaxRevJerk : kMaxLinJerk};
    const char* max_text[3] = {rev ? "100 rad/s" : "10 m/s", rev ? "1e4 rad/s^2" : "1000 m/s^2",
                               rev ? "1e6 rad/s^3" : "1e5 m/s^3"};
    double* dst[3] = {&row.dynamics.max_velocity, &row.dynamics.max_acceleration, &row.dynamics.max_jerk};
    for (int k = 0; k < 3; ++k) {
      const toml::node* v = j.get(keys[k]);
      if (!v) continue;
      SERVOARM_TRY(rd.bounded(*v, where, keys[k], ju, maxes[k], max_text[k], x));
      if (!(x > 0)) return rd.fail(v, where, std::string("key '") + keys[k] + "': must be positive");
      *dst[k] = x * ju;
    }
    if (const toml::node* v = j.get("max_effort")) {
      SERVOARM_TRY(rd.bounded(*v, where, "max_effort", 1.0, kMaxEffort, "1e6 N m or N", x));
      if (!(x > 0)) return rd.fail(v, where, "key 'max_effort': must be positive");
      row.max_effort = x;
    }
  }
  if (add_row(chain, row) != Status::ok) return rd.fail(&j, where, "row rejected (capacity or bad value)");
  if (const toml::node* v = j.get("capsule")) {
    SERVOARM_TRY(read_capsule(rd, *v, where, "capsule", L, chain.capsule[static_cast<std::size_t>(chain.n_rows)]));
    chain.capsule_mask |= 1u << chain.n_rows;
  }
  return read_inertial(rd, j, where, chain, L);
}

bool unit_key(Reader& rd, const toml::table& root, const char* key, const char* a, double va, const char* b, double vb,
              double& out) {
  const toml::node* v = root.get(key);
  if (!v) return rd.fail(nullptr, "", std::string("key '") + key + "' is missing");
  std::string s;
  SERVOARM_TRY(rd.string(*v, "", key, s));
  if (s == a) out = va;
  else if (s == b) out = vb;
  else return rd.fail(v, "", std::string("key '") + key + "': expected \"" + a + "\" or \"" + b + "\", got \"" + s + "\"");
  return true;
}

bool parse(Reader& rd, const toml::table& root, Chain& chain) {
  SERVOARM_TRY(rd.only_keys(root, {"name", "convention", "length_unit", "angle_unit", "joint", "tool", "base", "summary", "gravity",
                                    "base_capsule", "self_collision_ignore"},
                            ""));
  const toml::node* nv = root.get("name");
  if (!nv) return rd.fail(nullptr, "", "key 'name' is missing");
  std::string name;
  SERVOARM_TRY(rd.string(*nv, "", "name", name));
  if (name.empty()) return rd.fail(nv, "", "key 'name': must not be empty");
  if (name.size() >= chain.name.size())
    return rd.fail(nv, "", "key 'name': longer than " + std::to_string(chain.name.size() - 1) + " characters");
  if (name.find('\0') != std::string::npos) return rd.fail(nv, "", "key 'name': holds a NUL character");
  set_name(chain, name.c_str());

  double conv = 0;
  SERVOARM_TRY(unit_key(rd, root, "convention", "standard", 0, "modified", 1, conv));
  chain.convention = conv == 0 ? Convention::standard : Convention::modified;
  SERVOARM_TRY(unit_key(rd, root, "length_unit", "mm", 1e-3, "m", 1.0, chain.length_unit));
  SERVOARM_TRY(unit_key(rd, root, "angle_unit", "deg", M_PI / 180.0, "rad", 1.0, chain.angle_unit));
  const double L = chain.length_unit, A = chain.angle_unit;

  const toml::node* jn = root.get("joint");
  if (!jn) return rd.fail(nullptr, "", "key 'joint' is missing");
  const toml::array* arr = jn->as_array();
  if (!arr) return rd.fail(jn, "", "key 'joint': expected an array of [[joint]] tables");
  if (arr->empty()) return rd.fail(jn, "", "key 'joint': the chain has no rows");
  int njoints = 0;
  for (std::size_t i = 0; i < arr->size(); ++i) SERVOARM_TRY(read_row(rd, *arr->get(i), i, njoints, L, A, chain));
  if (chain.n_joints == 0) return rd.fail(nullptr, "", "the chain has no joints (only fixed rows)");
  Pose T;
  if (const toml::node* v = root.get("tool")) {
    SERVOARM_TRY(read_transform(rd, *v, "tool", L, A, T));
    set_tool(chain, T);
  }
  if (const toml::node* v = root.get("base")) {
    SERVOARM_TRY(read_transform(rd, *v, "base", L, A, T));
    chain.base = T;
  }
  if (const toml::node* v = root.get("summary")) {
    std::string ignored;
    SERVOARM_TRY(rd.string(*v, "", "summary", ignored));
  }
  if (const toml::node* v = root.get("gravity")) {
    double g[3];
    SERVOARM_TRY(rd.numbers(*v, "", "gravity", g, 3));
    if (!chain.has_inertial) return rd.fail(v, "", "key 'gravity': no joint has inertial data (mass, inertia)");
    if (!(std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]) <= 100)) return rd.fail(v, "", "key 'gravity': more than 100 m/s^2");
    chain.gravity = {g[0], g[1], g[2]};
  }
  if (const toml::node* v = root.get("base_capsule")) {
    SERVOARM_TRY(read_capsule(rd, *v, "", "base_capsule", L, chain.capsule[0]));
    chain.capsule_mask |= 1u;
  }
  // where each capsule was given (the zero-pose check's message points at one)
  std::vector<const toml::node*> at(kMaxCapsules, nullptr);
  at[0] = root.get("base_capsule");
  for (std::size_t i = 0; i < arr->size() && i < static_cast<std::size_t>(kMaxRows); ++i)
    if (const toml::table* t = arr->get(i)->as_table()) at[i + 1] = t->get("capsule");
  return read_capsule_pairs(rd, root, chain, at);
}

#undef SERVOARM_TRY

}  // namespace

LoadResult load_description(std::string_view text, std::string_view origin) {
  LoadResult res;
  const std::string org(origin);
  TomlDocument doc = parse_toml(text, org);
  if (!doc.error.empty()) {
    res.error = doc.error;
    return res;
  }
  Reader rd(org);
  Chain chain;
  if (!parse(rd, doc.table, chain)) {
    res.error = rd.error();
    return res;
  }
  res.chain = chain;
  res.ok = true;
  return res;
}

LoadResult load_description_file(const std::string& path) {
  std::string text;
  if (std::string e = read_text_file(path, text); !e.empty()) {
    LoadResult r;
    r.error = e;
    return r;
  }
  return load_description(text, path);
}

namespace {

bool ends_with(const std::string& s, std::string_view tail) {
  return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

/// A .urdf file: the chain from its root to its deepest leaf, converted (standard DH).
LoadResult load_urdf(const std::string& path) {
  LoadResult r;
#ifdef SERVOARM_WITH_URDF
  const UrdfParseResult p = urdf_parse_file(path);
  if (!p.ok) {
    r.error = p.error;
    return r;
  }
  UrdfConversion c = urdf_convert(p.chain);
  if (!c.ok) {
    r.error = path + ": " + c.error;
    return r;
  }
  r.ok = true;
  r.chain = c.chain;
#else
  r.error = path + ": this build has no URDF support (urdfdom was not found: Debian liburdfdom-dev)";
#endif
  return r;
}

}  // namespace

LoadResult load_robot(const std::string& name_or_path) {
  if (ends_with(name_or_path, ".urdf")) return load_urdf(name_or_path);
  for (const auto& m : builtin_models())
    if (name_or_path == m.name) return load_description(m.toml, std::string("built-in model ") + m.name);
  const bool looks_like_path = name_or_path.find('/') != std::string::npos ||
                               name_or_path.find(".toml") != std::string::npos;
  if (!looks_like_path && ::access(name_or_path.c_str(), F_OK) != 0) {
    std::string names;
    for (const auto& m : builtin_models()) names += (names.empty() ? "" : ", ") + std::string(m.name);
    LoadResult r;
    r.error = "unknown robot '" + name_or_path + "' (built-in models: " + names + "; or give a path to a .toml file)";
    return r;
  }
  return load_description_file(name_or_path);
}

}  // namespace servoarm::kin
