// SPDX-License-Identifier: Apache-2.0
#pragma once
// URDF import and export (set-up code, not real-time: allocates).
//
// Import, in two steps:
//   urdf_parse()    URDF text -> UrdfChain: the serial chain from a base link to a tip link
//                   (urdfdom's parser, at the edge; branches off the chain are skipped,
//                   mimic / floating / planar joints on it refused, every value checked)
//   urdf_convert()  UrdfChain -> Chain plus a readable description file (TOML): a pure
//                   function over plain structs, no files
// Every serial chain of revolute and prismatic joints has a DH description: the frame of
// each row is put on the common normal of consecutive joint axes (parallel axes: the
// normal through the previous origin; intersecting axes: x along the cross product), the
// first frame's offset into the base transform, whatever follows the last joint into the
// tool transform. z of every frame points along the URDF axis, so every direction is +1,
// and the offsets make the URDF's zero the description's zero.
//
// Export: urdf_export() writes a chain as URDF (links with inertials and cylinder
// visuals along the links, joints with limits); importing it gives back the same FK.
#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include "servoarm/kinematics/chain.hpp"

namespace servoarm::kin {

/// URDF files hold meshes' names, comments and per-link visuals: far larger than a
/// description, so they have their own cap (refused by size before parsing).
inline constexpr std::size_t kMaxUrdfFileBytes = 4 * 1024 * 1024;

enum class UrdfJointType { revolute, continuous, prismatic, fixed };

/// Mass properties of one URDF link: `origin` places the inertial frame in the link
/// frame; the inertia (ixx iyy izz ixy ixz iyz, kg m^2) is about the COM in that frame.
struct UrdfInertial {
  double mass = 0;
  Pose origin = Pose::Identity();
  std::array<double, 6> inertia{};
};

/// One joint of the chain, base to tip, with the link it carries.
struct UrdfJoint {
  std::string name;
  UrdfJointType type = UrdfJointType::fixed;
  Pose origin = Pose::Identity();              ///< parent link frame -> joint (child link) frame
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();  ///< in the joint frame; not zero
  bool has_limits = false;                     ///< position limits (not for continuous)
  double lower = 0, upper = 0;                 ///< rad or m
  double velocity = 0;                         ///< rad/s or m/s; 0: not given
  double effort = 0;                           ///< N m or N; 0: not given
  std::string child;                           ///< the child link's name
  bool has_inertial = false;
  UrdfInertial inertial;                       ///< of the child link
};

struct UrdfChain {
  std::string robot;  ///< the <robot name>
  std::string base, tip;
  std::vector<UrdfJoint> joints;  ///< base to tip, fixed joints included
  std::vector<std::string> skipped;  ///< joints off the chain (branches), for the report
};

struct UrdfParseOptions {
  std::string base;  ///< "" = the root link
  std::string tip;   ///< "" = the leaf with the most moving joints below base
};

struct UrdfParseResult {
  bool ok = false;
  std::string error;  ///< one line: "<origin>: joint 'name': what is wrong"
  UrdfChain chain;
};

/// Parse URDF text (at most kMaxUrdfFileBytes) and extract the chain base -> tip.
UrdfParseResult urdf_parse(std::string_view text, const std::string& origin, const UrdfParseOptions& options = {});
/// Read (size-capped, regular files only) and parse a file.
UrdfParseResult urdf_parse_file(const std::string& path, const UrdfParseOptions& options = {});

struct UrdfConvertOptions {
  Convention convention = Convention::standard;
  std::string name;  ///< description name; "" = the URDF robot's name
};

struct UrdfConversion {
  bool ok = false;
  std::string error;              ///< one line naming the joint when !ok
  Chain chain;                    ///< SI, as the description file loads
  std::vector<std::string> row_joint;  ///< per DH row: the URDF joint it comes from
  std::string toml;               ///< the description file (mm, deg), comments per row
};

/// URDF chain -> DH description. Pure: no files, no parsing.
UrdfConversion urdf_convert(const UrdfChain& urdf, const UrdfConvertOptions& options = {});

/// Forward kinematics of the URDF chain itself (joint values in chain order, moving
/// joints only): the pose of the tip link in the base link frame.
Pose urdf_forward(const UrdfChain& urdf, const JointVector& q);

/// A chain as URDF text: links base_link, link_1..link_n, tool0; joints joint_1..
/// (revolute with limits, continuous without, prismatic), fixed joints for fixed rows and
/// the tool; inertials in each link; cylinders along the links as visuals.
std::string urdf_export(const Chain& chain);

}  // namespace servoarm::kin
