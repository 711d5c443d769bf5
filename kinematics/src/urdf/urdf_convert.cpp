// SPDX-License-Identifier: Apache-2.0
// URDF chain -> DH description: pure geometry over plain structs (no files, no parser).
//
// The joint axes are lines in the base link frame at q = 0. Standard DH frame i (Spong)
// has z along the axis of joint i+1 and its origin where the common normal of axes i and
// i+1 meets axis i+1, x along that normal:
//   skew axes          the unique common normal, x from axis i towards axis i+1 (a >= 0)
//   intersecting axes  origin at the intersection, x = z_{i-1} x z_i
//   parallel axes      the normal through the previous origin (d = 0), x towards axis i+1;
//                      coincident axes keep the previous x (a = 0, alpha = 0 or 180 deg)
// A prismatic joint's axis is only a direction: its line is put through the next axis
// when they are parallel, through the previous frame's origin otherwise (a = 0).
// Frame 0: on axis 1 at the foot of the base link's origin, x the base link's x projected
// (the rest is the base transform); frame n: on axis n at the foot of the tip's origin, x the
// tip's x projected (the rest is the tool transform). z always along the URDF axis, so
// directions are +1; theta/d at q = 0 are the offsets that keep the URDF's zero.
// Modified DH (Craig) frames follow from the standard ones: C_i = S_{i-1} Rz(theta_i) Tz(d_i).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>

#include "servoarm/kinematics/description.hpp"
#include "servoarm/kinematics/urdf.hpp"
#include "urdf_math.hpp"

namespace servoarm::kin {
namespace {

using urdf_detail::rpy_of;

// Axes whose directions differ by less than this (rad) are parallel: the exact common
// normal of nearly parallel lines lies ~offset/angle away (1e15 m for rounding noise).
constexpr double kParallelTol = 1e-9;
constexpr double kCoincidentTol = 1e-12;  // m: parallel axes this close are one line
// The converted chain must reproduce the URDF's FK to this (m) on seeded joint vectors.
constexpr double kFkAgreement = 1e-9;

struct Line {
  Eigen::Vector3d p, z;  // a point and the unit direction (URDF axis), base link frame
};

Pose make_frame(const Eigen::Vector3d& o, const Eigen::Vector3d& x, const Eigen::Vector3d& z) {
  Pose F = Pose::Identity();
  F.linear().col(0) = x;
  F.linear().col(1) = z.cross(x);
  F.linear().col(2) = z;
  F.translation() = o;
  return F;
}

/// The unit component of `v` normal to `z`, or of `alt` when `v` is (nearly) along z.
Eigen::Vector3d normal_part(const Eigen::Vector3d& v, const Eigen::Vector3d& alt, const Eigen::Vector3d& z) {
  Eigen::Vector3d n = v - v.dot(z) * z;
  if (n.norm() < 1e-6) n = alt - alt.dot(z) * z;
  return n.normalized();
}

bool is_moving(UrdfJointType t) { return t != UrdfJointType::fixed; }

/// Standard DH frame i from frame i-1 (on axis i) and axis i+1.
Pose next_frame(const Pose& prev, const Line& next) {
  const Eigen::Vector3d o0 = prev.translation(), x0 = prev.linear().col(0), z0 = prev.linear().col(2);
  const Eigen::Vector3d c = z0.cross(next.z);
  if (c.norm() < kParallelTol) {
    const Eigen::Vector3d z = next.z.dot(z0) >= 0 ? z0 : Eigen::Vector3d(-z0);
    const Eigen::Vector3d w = next.p - o0;
    const Eigen::Vector3d foot = next.p - w.dot(next.z) * next.z;  // on axis i+1, nearest o0
    const Eigen::Vector3d perp = (foot - o0) - (foot - o0).dot(z0) * z0;
    if (perp.norm() < kCoincidentTol) return make_frame(o0, x0, z);
    return make_frame(foot, perp.normalized(), z);
  }
  // Closest points of the lines o0 + s z0 and next.p + t next.z.
  const Eigen::Vector3d w = o0 - next.p;
  const double b = z0.dot(next.z), dd = z0.dot(w), e = next.z.dot(w), den = 1 - b * b;
  const double s = (b * e - dd) / den, t = (e - b * dd) / den;
  const Eigen::Vector3d f1 = o0 + s * z0, f2 = next.p + t * next.z;
  Eigen::Vector3d x = c.normalized();
  if ((f2 - f1).dot(x) < -kCoincidentTol) x = -x;
  return make_frame(f2, x, next.z);
}

struct Dh {
  double theta, d, a, alpha;
};

Dh dh_between(const Pose& A, const Pose& B) {
  const Eigen::Vector3d xa = A.linear().col(0), za = A.linear().col(2);
  const Eigen::Vector3d xb = B.linear().col(0), zb = B.linear().col(2);
  const Eigen::Vector3d dp = B.translation() - A.translation();
  return {std::atan2(xa.cross(xb).dot(za), xa.dot(xb)), dp.dot(za), dp.dot(xb), std::atan2(za.cross(zb).dot(xb), za.dot(zb))};
}

// ---- the description file --------------------------------------------------------------

/// Shortest decimal text of v that reads back within tol (values within tol of 0: "0"):
/// plain decimals ("90", "162.5") where the magnitude allows, otherwise exponent form.
std::string num(double v, double tol) {
  if (std::fabs(v) <= tol) return "0";
  char b[48];
  const bool plain = std::fabs(v) >= 1e-4 && std::fabs(v) < 1e15;
  for (int p = plain ? 0 : 1; p <= 17; ++p) {
    std::snprintf(b, sizeof b, plain ? "%.*f" : "%.*e", p, v);
    if (std::fabs(std::strtod(b, nullptr) - v) <= tol) return b;
  }
  std::snprintf(b, sizeof b, "%.17g", v);
  return b;
}
std::string mm(double m) { return num(m * 1e3, 1e-12); }
std::string deg(double rad) { return num(rad * 180.0 / M_PI, 1e-12); }
std::string exact(double v) { return num(v, 1e-15 * std::fabs(v)); }

std::string vec3(const Eigen::Vector3d& v, std::string (*f)(double)) { return "[" + f(v[0]) + ", " + f(v[1]) + ", " + f(v[2]) + "]"; }

std::string transform_table(const char* key, const Pose& T) {
  const std::string xyz = vec3(T.translation(), mm), rpy = vec3(rpy_of(T.linear()), deg);
  if (xyz == "[0, 0, 0]" && rpy == "[0, 0, 0]") return "";
  return std::string("\n[") + key + "]\nxyz = " + xyz + "\nrpy = " + rpy + "\n";
}

const char* type_word(UrdfJointType t) {
  switch (t) {
    case UrdfJointType::revolute: return "revolute";
    case UrdfJointType::continuous: return "continuous";
    case UrdfJointType::prismatic: return "prismatic";
    case UrdfJointType::fixed: return "fixed";
  }
  return "?";
}

}  // namespace

Pose urdf_forward(const UrdfChain& urdf, const JointVector& q) {
  Pose W = Pose::Identity();
  int k = 0;
  for (const UrdfJoint& j : urdf.joints) {
    W = W * j.origin;
    if (!is_moving(j.type)) continue;
    const Eigen::Vector3d ax = j.axis.normalized();
    const double v = q[k++];
    if (j.type == UrdfJointType::prismatic) W.translate(ax * v);
    else W.rotate(Eigen::AngleAxisd(v, ax));
  }
  return W;
}

namespace {

/// One body per DH row: the child link of its joint and the links fixed to it.
struct Body {
  double m = 0;
  Eigen::Vector3d mc = Eigen::Vector3d::Zero();  // sum m_k c_k (row frame)
  Eigen::Matrix3d I = Eigen::Matrix3d::Zero();   // about the row frame's origin
};

void add_link(Body& b, const Pose& row_frame, const Pose& link, const UrdfInertial& in) {
  const Pose F = row_frame.inverse() * link * in.origin;  // inertial frame in the row frame
  const auto& v = in.inertia;
  Eigen::Matrix3d Ic;
  Ic << v[0], v[3], v[4], v[3], v[1], v[5], v[4], v[5], v[2];
  const Eigen::Matrix3d R = F.linear();
  const Eigen::Vector3d c = F.translation();
  b.m += in.mass;
  b.mc += in.mass * c;
  b.I += R * Ic * R.transpose() + in.mass * (c.squaredNorm() * Eigen::Matrix3d::Identity() - c * c.transpose());
}

struct Geometry {
  std::vector<int> moving;            // index into urdf.joints of each moving joint
  std::vector<Pose> link;             // child link pose at q = 0 of each URDF joint
  std::vector<Line> axis;             // per moving joint
  std::vector<Pose> S;                // standard DH frames 0..n
  Pose tip = Pose::Identity();
};

std::string check_input(const UrdfChain& u, Geometry& g) {
  Pose W = Pose::Identity();
  for (std::size_t k = 0; k < u.joints.size(); ++k) {
    const UrdfJoint& j = u.joints[k];
    if (!W.matrix().allFinite() || !j.origin.matrix().allFinite() || !j.axis.allFinite())
      return "joint '" + j.name + "': a value is not finite";
    W = W * j.origin;
    g.link.push_back(W);
    if (!is_moving(j.type)) continue;
    if (j.axis.norm() < 1e-9) return "joint '" + j.name + "': the axis is zero";
    g.moving.push_back(static_cast<int>(k));
    g.axis.push_back({W.translation(), W.linear() * j.axis.normalized()});
  }
  if (g.moving.empty()) return "no moving joint between '" + u.base + "' and '" + u.tip + "'";
  if (g.moving.size() > static_cast<std::size_t>(kMaxJoints))
    return std::to_string(g.moving.size()) + " moving joints between '" + u.base + "' and '" + u.tip + "' (at most " +
           std::to_string(kMaxJoints) + ")";
  g.tip = W;
  return "";
}

/// Standard DH frames S_0..S_n along the axes.
void build_frames(const UrdfChain& u, Geometry& g) {
  const std::size_t n = g.axis.size();
  auto place_prismatic = [&](std::size_t i, const Eigen::Vector3d& fallback) {
    // Axis i of a prismatic joint: only its direction counts; choose the line.
    if (u.joints[static_cast<std::size_t>(g.moving[i])].type != UrdfJointType::prismatic) return;
    if (i + 1 < n && g.axis[i].z.cross(g.axis[i + 1].z).norm() < kParallelTol) g.axis[i].p = g.axis[i + 1].p;
    else g.axis[i].p = fallback;
  };
  place_prismatic(0, Eigen::Vector3d::Zero());
  const Line& l1 = g.axis[0];
  const Eigen::Vector3d o0 = l1.p - l1.p.dot(l1.z) * l1.z;  // foot of the base origin on axis 1
  g.S.push_back(make_frame(o0, normal_part(Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(), l1.z), l1.z));
  for (std::size_t i = 1; i < n; ++i) {
    place_prismatic(i, g.S.back().translation());
    g.S.push_back(next_frame(g.S.back(), g.axis[i]));
  }
  const Pose& last = g.S.back();
  const Eigen::Vector3d z = last.linear().col(2), o = last.translation();
  const Eigen::Vector3d on = o + (g.tip.translation() - o).dot(z) * z;
  g.S.push_back(make_frame(on, normal_part(g.tip.linear().col(0), g.tip.linear().col(1), z), z));
}

std::string row_text(const UrdfJoint& j, const Dh& p, bool modified_first, const Dh& prev, const Body& b, bool has_mass) {
  std::string s = "\n[[joint]]  # URDF joint '" + j.name + "' (" + type_word(j.type) + "), moves link '" + j.child + "'\n";
  s += "name = \"" + j.name + "\"\n";
  s += std::string("type = \"") + (j.type == UrdfJointType::prismatic ? "prismatic" : "revolute") + "\"\n";
  const double alpha = modified_first ? prev.alpha : p.alpha, a = modified_first ? prev.a : p.a;
  s += "theta = " + deg(p.theta) + "\nd = " + mm(p.d) + "\na = " + mm(a) + "\nalpha = " + deg(alpha) + "\n";
  const bool pris = j.type == UrdfJointType::prismatic;
  auto ju = [&](double v) { return pris ? mm(v) : deg(v); };
  if (j.has_limits) s += "limits = [" + ju(j.lower) + ", " + ju(j.upper) + "]\n";
  if (j.velocity > 0) s += "max_velocity = " + ju(j.velocity) + "\n";
  if (j.effort > 0) s += "max_effort = " + exact(j.effort) + "\n";
  if (has_mass && (b.m > 0 || !b.I.isZero(0))) {  // a massless body may still carry a rotor's inertia
    const Eigen::Vector3d c = b.m > 0 ? Eigen::Vector3d(b.mc / b.m) : Eigen::Vector3d::Zero();
    const Eigen::Matrix3d Ic = b.I - b.m * (c.squaredNorm() * Eigen::Matrix3d::Identity() - c * c.transpose());
    s += "mass = " + exact(b.m) + "\n";
    if (b.m > 0) s += "com = " + vec3(c, mm) + "\n";
    s += "inertia = [" + exact(Ic(0, 0)) + ", " + exact(Ic(1, 1)) + ", " + exact(Ic(2, 2)) + ", " + exact(Ic(0, 1)) + ", " +
         exact(Ic(0, 2)) + ", " + exact(Ic(1, 2)) + "]\n";
  }
  return s;
}

std::string header(const UrdfChain& u, const std::string& name, std::size_t n, Convention conv) {
  std::string s = "# summary: " + u.robot + " from URDF (" + u.base + " -> " + u.tip + "), " + std::to_string(n) + " joints, " +
                  to_string(conv) + " DH\n";
  s += "# Converted from URDF: robot '" + u.robot + "', chain '" + u.base + "' -> '" + u.tip + "'.\n";
  s += "# Each [[joint]] names the URDF joint it comes from. z of every DH frame points along\n"
       "# that joint's URDF axis (direction +1) and theta/d hold the offsets that keep the\n"
       "# URDF's zero pose: joint values mean the same here as in the URDF.\n"
       "# base: the first DH frame in the URDF base link; tool: the tip link in the last DH frame.\n"
       "# mass/com/inertia: each moving link with the links fixed to it, in the row's DH frame.\n";
  if (!u.skipped.empty()) {
    s += "# Skipped (off the chain):";
    for (const auto& k : u.skipped) s += " " + k;
    s += "\n";
  }
  s += "name = \"" + name + "\"\nconvention = \"" + to_string(conv) + "\"\nlength_unit = \"mm\"\nangle_unit = \"deg\"\n";
  return s;
}

/// Largest FK difference (m, position; rad-weighted 1 m for rotation) on seeded joint vectors.
double fk_disagreement(const UrdfChain& u, const Chain& c) {
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> U(-M_PI, M_PI), L(-0.5, 0.5);
  double worst = 0;
  for (int s = 0; s < 64; ++s) {
    JointVector q(c.n_joints);
    for (int j = 0; j < c.n_joints; ++j) q[j] = s == 0 ? 0.0 : c.joint(j).type == JointType::prismatic ? L(rng) : U(rng);
    Pose a;
    if (forward(c, q, a) != Status::ok) return INFINITY;
    const Pose b = urdf_forward(u, q);
    worst = std::max({worst, (a.translation() - b.translation()).norm(), (a.linear() - b.linear()).norm()});
  }
  return worst;
}

}  // namespace

UrdfConversion urdf_convert(const UrdfChain& u, const UrdfConvertOptions& opt) {
  UrdfConversion out;
  Geometry g;
  if (std::string e = check_input(u, g); !e.empty()) {
    out.error = e;
    return out;
  }
  build_frames(u, g);
  const std::size_t n = g.moving.size();
  const bool modified = opt.convention == Convention::modified;
  std::vector<Dh> dh(n);
  std::vector<Pose> body_frame(n);
  for (std::size_t i = 0; i < n; ++i) {
    dh[i] = dh_between(g.S[i], g.S[i + 1]);
    body_frame[i] = modified ? g.S[i] * Eigen::AngleAxisd(dh[i].theta, Eigen::Vector3d::UnitZ()) *
                                   Eigen::Translation3d(0, 0, dh[i].d)
                             : g.S[i + 1];
  }
  // Bodies: each link after a moving joint, and the links fixed to it, ride on that row.
  std::vector<Body> bodies(n);
  bool any_mass = false;
  for (std::size_t k = 0, row = 0; k < u.joints.size(); ++k) {
    if (row < n && static_cast<int>(k) == g.moving[row]) ++row;
    if (row == 0 || !u.joints[k].has_inertial) continue;
    add_link(bodies[row - 1], body_frame[row - 1], g.link[k], u.joints[k].inertial);
    any_mass = true;
  }
  std::string name = opt.name.empty() ? u.robot : opt.name;
  if (name.empty()) name = "urdf_robot";
  if (name.size() > 47) name.resize(47);
  for (char& ch : name)
    if (ch == '"' || ch == '\\' || static_cast<unsigned char>(ch) < 0x20) ch = '_';
  std::string text = header(u, name, n, opt.convention);
  for (std::size_t i = 0; i < n; ++i) {
    const UrdfJoint& j = u.joints[static_cast<std::size_t>(g.moving[i])];
    text += row_text(j, dh[i], modified, i == 0 ? Dh{0, 0, 0, 0} : dh[i - 1], bodies[i], any_mass);
    out.row_joint.push_back(j.name);
  }
  // Modified: the last standard row's (a, alpha) are zero by construction, so the last
  // frame is the same in both conventions and so is the tool.
  text += transform_table("base", g.S.front());
  text += transform_table("tool", g.S.back().inverse() * g.tip);
  LoadResult lr = load_description(text, "URDF chain '" + u.base + "' -> '" + u.tip + "' (converted)");
  if (!lr.ok) {
    out.error = lr.error;
    return out;
  }
  const double worst = fk_disagreement(u, lr.chain);
  if (!(worst <= kFkAgreement)) {
    char b[160];
    std::snprintf(b, sizeof b, "the DH description misses the URDF's FK by %.3g m (axes within %.0e rad of parallel?)", worst,
                  kParallelTol);
    out.error = b;
    return out;
  }
  char b[120];
  std::snprintf(b, sizeof b, "# FK agrees with the URDF to %.1e m on 64 seeded joint vectors.\n", worst);
  text.insert(text.find("name = \""), b);
  out.chain = lr.chain;
  out.toml = std::move(text);
  out.ok = true;
  return out;
}

}  // namespace servoarm::kin
