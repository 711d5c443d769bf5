// SPDX-License-Identifier: Apache-2.0
// A DH chain as URDF. Each row is Pre Rz(theta + q) Tz(d + q) Post (standard: Pre = I,
// Post = Tx(a) Rx(alpha); modified: Pre = Rx(alpha) Tx(a), Post = I). URDF moves the child
// link after the joint's origin, so link_i sits at DH frame i times Post_i^-1 and the
// origin of joint i is Post_{i-1} Pre_i Rz(theta) Tz(d) (Post_0 = the base transform),
// the axis z times the direction. Numbers are written with 17 digits: an import of the
// export gives back the same FK to rounding.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "servoarm/kinematics/urdf.hpp"
#include "urdf_math.hpp"

namespace servoarm::kin {
namespace {

std::string g17(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.17g", v == 0 ? 0.0 : v);  // no "-0"
  return b;
}

std::string xml_name(const char* s) {
  std::string out;
  for (; *s; ++s) {
    const char c = *s;
    out += (c == '"' || c == '<' || c == '>' || c == '&' || c == '\'') ? '_' : c;
  }
  return out;
}

std::string origin(const Pose& T) {
  const Eigen::Vector3d p = T.translation(), r = urdf_detail::rpy_of(T.linear());
  return "<origin xyz=\"" + g17(p[0]) + " " + g17(p[1]) + " " + g17(p[2]) + "\" rpy=\"" + g17(r[0]) + " " + g17(r[1]) + " " +
         g17(r[2]) + "\"/>";
}

Pose pre(const Chain& c, const DhRow& r) {
  Pose T = Pose::Identity();
  if (c.convention == Convention::modified) T = Eigen::AngleAxisd(r.alpha, Eigen::Vector3d::UnitX()) * Eigen::Translation3d(r.a, 0, 0);
  return T * Eigen::AngleAxisd(r.theta, Eigen::Vector3d::UnitZ()) * Eigen::Translation3d(0, 0, r.d);
}

Pose post(const Chain& c, const DhRow& r) {
  if (c.convention == Convention::modified) return Pose::Identity();
  return Pose(Eigen::Translation3d(r.a, 0, 0) * Eigen::AngleAxisd(r.alpha, Eigen::Vector3d::UnitX()));
}

/// A cylinder from the link origin to `to` (link frame), radius scaled to its length.
std::string visual(const Eigen::Vector3d& to) {
  const double len = to.norm();
  if (len < 1e-6) return "";
  const double radius = std::clamp(0.08 * len, 0.005, 0.04);
  Pose T = Pose::Identity();
  // The rotation taking z to the cylinder's axis: about z x d by the angle between them (any
  // axis across z when d is -z: a cylinder looks the same turned about its own axis). Written
  // out instead of Quaternion::FromTwoVectors, whose antiparallel case instantiates a 2 x 3
  // Jacobi SVD with its QR preconditioners (g++ 12: 12.5 CPU-s for this file with it, 4.4 without).
  const Eigen::Vector3d d = to / len, axis = Eigen::Vector3d::UnitZ().cross(d);
  const double s = axis.norm();
  if (s > 1e-12) T.linear() = Eigen::AngleAxisd(std::atan2(s, d.z()), axis / s).toRotationMatrix();
  else if (d.z() < 0) T.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
  T.translation() = to / 2;
  return "    <visual>\n      " + origin(T) + "\n      <geometry><cylinder radius=\"" + g17(radius) + "\" length=\"" + g17(len) +
         "\"/></geometry>\n    </visual>\n";
}

std::string inertial(const LinkInertial& L, const Pose& post_i) {
  if (!(L.mass > 0) && std::all_of(L.inertia.begin(), L.inertia.end(), [](double x) { return x == 0; })) return "";
  const Eigen::Matrix3d R = post_i.linear();
  const Eigen::Vector3d c = post_i * Eigen::Vector3d(L.com[0], L.com[1], L.com[2]);
  const auto& v = L.inertia;
  Eigen::Matrix3d I;
  I << v[0], v[3], v[4], v[3], v[1], v[5], v[4], v[5], v[2];
  I = R * I * R.transpose();
  return "    <inertial>\n      <origin xyz=\"" + g17(c[0]) + " " + g17(c[1]) + " " + g17(c[2]) + "\" rpy=\"0 0 0\"/>\n      <mass value=\"" +
         g17(L.mass) + "\"/>\n      <inertia ixx=\"" + g17(I(0, 0)) + "\" ixy=\"" + g17(I(0, 1)) + "\" ixz=\"" + g17(I(0, 2)) +
         "\" iyy=\"" + g17(I(1, 1)) + "\" iyz=\"" + g17(I(1, 2)) + "\" izz=\"" + g17(I(2, 2)) + "\"/>\n    </inertial>\n";
}

std::string joint_text(const Chain& c, int row, int joint_no, const std::string& parent, const std::string& child,
                       const Pose& from) {
  const DhRow& r = c.rows[static_cast<std::size_t>(row)];
  std::string type = "fixed", name = "fixed_" + std::to_string(row + 1);
  if (r.type != JointType::fixed) {
    name = "joint_" + std::to_string(joint_no);
    const bool limited = std::isfinite(r.lower) && std::isfinite(r.upper);
    type = r.type == JointType::prismatic ? "prismatic" : limited ? "revolute" : "continuous";
  }
  std::string s = "  <joint name=\"" + name + "\" type=\"" + type + "\">\n    <parent link=\"" + parent + "\"/>\n    <child link=\"" +
                  child + "\"/>\n    " + origin(from) + "\n";
  if (r.type != JointType::fixed) {
    s += "    <axis xyz=\"0 0 " + g17(r.direction) + "\"/>\n    <limit";
    if (std::isfinite(r.lower) && std::isfinite(r.upper)) s += " lower=\"" + g17(r.lower) + "\" upper=\"" + g17(r.upper) + "\"";
    s += " effort=\"" + g17(r.max_effort) + "\" velocity=\"" + g17(r.dynamics.max_velocity) + "\"/>\n";
  }
  return s + "  </joint>\n";
}

}  // namespace

std::string urdf_export(const Chain& c) {
  const std::string robot = xml_name(c.name.data());
  std::string s = "<?xml version=\"1.0\"?>\n<!-- " + robot + ": exported from a servoarm description (" + to_string(c.convention) +
                  " DH).\n     link_i moves with row i of the description; tool0 is the tool frame. -->\n";
  s += "<robot name=\"" + robot + "\">\n  <link name=\"base_link\"/>\n";
  std::string parent = "base_link";
  Pose carry = c.base;  // what lies between the parent link's frame and the next row
  int joint_no = 0;
  for (int i = 0; i < c.n_rows; ++i) {
    const DhRow& r = c.rows[static_cast<std::size_t>(i)];
    if (r.type != JointType::fixed) ++joint_no;
    const std::string link = "link_" + std::to_string(i + 1);
    s += joint_text(c, i, joint_no, parent, link, carry * pre(c, r));
    const Pose p = post(c, r);
    const Pose next = i + 1 < c.n_rows ? p * pre(c, c.rows[static_cast<std::size_t>(i + 1)]) : p * c.tool;
    s += "  <link name=\"" + link + "\">\n" + inertial(c.inertial[static_cast<std::size_t>(i)], p) + visual(next.translation()) +
         "  </link>\n";
    parent = link;
    carry = p;
  }
  s += "  <joint name=\"tool_joint\" type=\"fixed\">\n    <parent link=\"" + parent + "\"/>\n    <child link=\"tool0\"/>\n    " +
       origin(carry * c.tool) + "\n  </joint>\n  <link name=\"tool0\"/>\n</robot>\n";
  return s;
}

}  // namespace servoarm::kin
