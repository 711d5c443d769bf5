// SPDX-License-Identifier: Apache-2.0
// URDF text -> the serial chain base -> tip (urdfdom 3.0, Debian liburdfdom-dev).
// The edge of the converter: urdfdom parses; everything it accepts is checked again here
// (a link with two parents, values that are not finite, a zero axis, mimic / floating /
// planar joints on the chain) so every refusal is one line naming the joint or link.
// urdfdom reports through console_bridge: its messages are captured, not printed, and
// the last error is the reason given for a file urdfdom refuses.
#include <cmath>
#include <algorithm>
#include <map>
#include <set>
#include <tuple>

#include <console_bridge/console.h>
#include <urdf_parser/urdf_parser.h>

#include "servoarm/kinematics/io/file_input.hpp"
#include "servoarm/kinematics/urdf.hpp"

namespace servoarm::kin {
namespace {

class Capture : public console_bridge::OutputHandler {
 public:
  void log(const std::string& text, console_bridge::LogLevel level, const char*, int) override {
    // Every error, in order: urdfdom says what is wrong first, then what it gave up on.
    if (level >= console_bridge::CONSOLE_BRIDGE_LOG_ERROR && last.size() < 400) last += (last.empty() ? "" : "; ") + text;
  }
  std::string last;
};

Pose to_pose(const urdf::Pose& p) {
  Pose T = Pose::Identity();
  T.translation() = Eigen::Vector3d(p.position.x, p.position.y, p.position.z);
  const urdf::Rotation& r = p.rotation;
  T.linear() = Eigen::Quaterniond(r.w, r.x, r.y, r.z).normalized().toRotationMatrix();
  return T;
}

bool finite_pose(const urdf::Pose& p) {
  const auto& a = p.position;
  const auto& r = p.rotation;
  return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z) && std::isfinite(r.x) && std::isfinite(r.y) &&
         std::isfinite(r.z) && std::isfinite(r.w);
}

/// One URDF joint on the chain as a UrdfJoint; "" or the reason it is refused.
std::string take_joint(const urdf::Joint& j, const urdf::Link& child, UrdfJoint& out) {
  const std::string who = "joint '" + j.name + "'";
  switch (j.type) {
    case urdf::Joint::REVOLUTE: out.type = UrdfJointType::revolute; break;
    case urdf::Joint::CONTINUOUS: out.type = UrdfJointType::continuous; break;
    case urdf::Joint::PRISMATIC: out.type = UrdfJointType::prismatic; break;
    case urdf::Joint::FIXED: out.type = UrdfJointType::fixed; break;
    case urdf::Joint::FLOATING: return who + ": floating joints are not supported (a serial arm has 1-DOF joints)";
    case urdf::Joint::PLANAR: return who + ": planar joints are not supported (a serial arm has 1-DOF joints)";
    case urdf::Joint::UNKNOWN: return who + ": unknown joint type";
  }
  if (j.mimic) return who + ": mimics joint '" + j.mimic->joint_name + "': mimic joints are not supported on the chain";
  out.name = j.name;
  out.child = child.name;
  if (!finite_pose(j.parent_to_joint_origin_transform)) return who + ": <origin> holds a value that is not finite";
  out.origin = to_pose(j.parent_to_joint_origin_transform);
  out.axis = Eigen::Vector3d(j.axis.x, j.axis.y, j.axis.z);
  const bool moving = out.type != UrdfJointType::fixed;
  if (moving && !out.axis.allFinite()) return who + ": <axis> holds a value that is not finite";
  if (moving && out.axis.norm() < 1e-9) return who + ": <axis> is zero";
  if (moving && j.limits) {
    const auto& L = *j.limits;
    if (!std::isfinite(L.lower) || !std::isfinite(L.upper) || !std::isfinite(L.velocity) || !std::isfinite(L.effort))
      return who + ": <limit> holds a value that is not finite";
    // lower = upper = 0 is urdfdom's value when the attributes are absent: no position limits.
    if (out.type != UrdfJointType::continuous && !(L.lower == 0 && L.upper == 0)) {
      if (!(L.lower < L.upper)) return who + ": <limit> lower must be below upper";
      out.has_limits = true;
      out.lower = L.lower;
      out.upper = L.upper;
    }
    out.velocity = L.velocity > 0 ? L.velocity : 0;
    out.effort = L.effort > 0 ? L.effort : 0;
  }
  if (child.inertial) {
    const urdf::Inertial& in = *child.inertial;
    const double v[7] = {in.mass, in.ixx, in.iyy, in.izz, in.ixy, in.ixz, in.iyz};
    for (double x : v)
      if (!std::isfinite(x)) return "link '" + child.name + "': <inertial> holds a value that is not finite";
    if (!finite_pose(in.origin)) return "link '" + child.name + "': <inertial><origin> holds a value that is not finite";
    if (in.mass < 0) return "link '" + child.name + "': <mass> is negative";
    out.has_inertial = true;
    out.inertial.mass = in.mass;
    out.inertial.origin = to_pose(in.origin);
    out.inertial.inertia = {in.ixx, in.iyy, in.izz, in.ixy, in.ixz, in.iyz};
  }
  return "";
}

/// Moving joints on the path from `link` down to each leaf: the leaf with the most.
void deepest_leaves(const urdf::Link& link, int moving, int depth, std::set<const urdf::Link*>& seen,
                    std::vector<std::tuple<int, int, std::string>>& leaves) {
  if (!seen.insert(&link).second) return;
  if (link.child_joints.empty()) leaves.emplace_back(moving, depth, link.name);
  for (std::size_t k = 0; k < link.child_links.size() && k < link.child_joints.size(); ++k) {
    const bool mv = link.child_joints[k]->type != urdf::Joint::FIXED;
    deepest_leaves(*link.child_links[k], moving + (mv ? 1 : 0), depth + 1, seen, leaves);
  }
}

std::string check_tree(const urdf::ModelInterface& m) {
  std::map<std::string, std::string> parent_joint;
  for (const auto& [name, j] : m.joints_) {
    if (j->child_link_name == j->parent_link_name) return "joint '" + name + "': its parent and child are one link (a loop)";
    auto [it, fresh] = parent_joint.emplace(j->child_link_name, name);
    if (!fresh)
      return "link '" + j->child_link_name + "' is the child of joints '" + it->second + "' and '" + name +
             "' (a loop: URDF describes a tree)";
  }
  return "";
}

/// Two ends of the longest chain tie, as a gripper's two fingers do: the arm ends at the
/// link named `tool0` below the base when there is one (the ROS-Industrial name of the tool
/// frame), else at the link where the two branch off (the fingers are then branches off the
/// chain, skipped). `a`, `b`: the tied leaves.
std::string tied_tip(const urdf::Link& base, const std::string& a, const std::string& b, std::string& tip) {
  std::vector<const urdf::Link*> todo{&base};
  std::map<std::string, const urdf::Link*> below;
  while (!todo.empty() && below.size() < 100000) {
    const urdf::Link* l = todo.back();
    todo.pop_back();
    if (!below.emplace(l->name, l).second) continue;
    for (const auto& c : l->child_links) todo.push_back(c.get());
  }
  if (below.count("tool0") != 0) {
    tip = "tool0";
    return "";
  }
  std::set<std::string> up;  // a's ancestors, a included, up to the base
  for (const urdf::Link* l = below.at(a); l != nullptr; l = l == &base ? nullptr : l->getParent().get()) up.insert(l->name);
  for (const urdf::Link* l = below.at(b); l != nullptr; l = l == &base ? nullptr : l->getParent().get())
    if (up.count(l->name) != 0) {
      tip = l->name;
      return "";
    }
  return "links '" + a + "' and '" + b + "' are both ends of the longest chain: name the tip with --tip LINK";
}

std::string choose_tip(const urdf::Link& base, std::string& tip) {
  std::vector<std::tuple<int, int, std::string>> leaves;
  std::set<const urdf::Link*> seen;
  deepest_leaves(base, 0, 0, seen, leaves);
  std::sort(leaves.begin(), leaves.end(), [](const auto& a, const auto& b) {
    return std::get<0>(a) != std::get<0>(b) ? std::get<0>(a) > std::get<0>(b) : std::get<1>(a) > std::get<1>(b);
  });
  tip = std::get<2>(leaves[0]);
  if (leaves.size() > 1 && std::get<0>(leaves[0]) == std::get<0>(leaves[1]) && std::get<1>(leaves[0]) == std::get<1>(leaves[1]))
    return tied_tip(base, std::get<2>(leaves[0]), std::get<2>(leaves[1]), tip);
  return "";
}

std::string extract(const urdf::ModelInterface& m, const UrdfParseOptions& opt, UrdfChain& out) {
  if (std::string e = check_tree(m); !e.empty()) return e;
  urdf::LinkConstSharedPtr base = opt.base.empty() ? m.getRoot() : m.getLink(opt.base);
  if (!base) return "no link '" + opt.base + "'";
  out.robot = m.getName();
  out.base = base->name;
  out.tip = opt.tip;
  if (out.tip.empty())
    if (std::string e = choose_tip(*base, out.tip); !e.empty()) return e;
  urdf::LinkConstSharedPtr tip = m.getLink(out.tip);
  if (!tip) return "no link '" + out.tip + "'";
  // Walk up from the tip to the base (each link has one parent: check_tree).
  std::vector<urdf::LinkConstSharedPtr> path{tip};
  while (path.back() != base) {
    urdf::LinkConstSharedPtr parent = path.back()->getParent();
    if (!parent || path.size() > m.links_.size())
      return "no path from '" + out.base + "' to '" + out.tip + "' ('" + out.tip + "' is not below '" + out.base + "')";
    path.push_back(parent);
  }
  std::set<std::string> on_chain;
  for (std::size_t k = path.size() - 1; k-- > 0;) {
    const urdf::Link& child = *path[k];
    UrdfJoint j;
    if (std::string e = take_joint(*child.parent_joint, child, j); !e.empty()) return e;
    on_chain.insert(j.name);
    out.joints.push_back(std::move(j));
  }
  for (const auto& [name, j] : m.joints_)
    if (!on_chain.count(name)) out.skipped.push_back(name);
  return "";
}

}  // namespace

UrdfParseResult urdf_parse(std::string_view text, const std::string& origin, const UrdfParseOptions& opt) {
  UrdfParseResult res;
  if (text.size() > kMaxUrdfFileBytes) {
    res.error = origin + ": larger than " + std::to_string(kMaxUrdfFileBytes) + " bytes";
    return res;
  }
  if (text.find('\0') != std::string_view::npos) {
    res.error = origin + ": holds a NUL byte (not an XML text file)";
    return res;
  }
  Capture capture;
  console_bridge::useOutputHandler(&capture);
  urdf::ModelInterfaceSharedPtr model;
  try {
    model = urdf::parseURDF(std::string(text));
  } catch (const std::exception& e) {
    capture.last = e.what();
  }
  console_bridge::restorePreviousOutputHandler();
  if (!model) {
    res.error = one_line(origin + ": not a valid URDF" + (capture.last.empty() ? "" : ": " + capture.last));
    return res;
  }
  try {
    if (std::string e = extract(*model, opt, res.chain); !e.empty()) {
      res.error = one_line(origin + ": " + e);
      return res;
    }
  } catch (const std::exception& e) {
    res.error = one_line(origin + ": " + e.what());
    return res;
  }
  res.ok = true;
  return res;
}

UrdfParseResult urdf_parse_file(const std::string& path, const UrdfParseOptions& opt) {
  std::string text;
  if (std::string e = read_text_file(path, text, kMaxUrdfFileBytes); !e.empty()) {
    UrdfParseResult r;
    r.error = e;
    return r;
  }
  return urdf_parse(text, path, opt);
}

}  // namespace servoarm::kin
