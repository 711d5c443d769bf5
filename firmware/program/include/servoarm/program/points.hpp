// SPDX-License-Identifier: Apache-2.0
#pragma once
// Teach points and the points file that keeps them.
//
// A teach point is a named joint vector, with the tool pose it gave when it was taught
// and the names of the tool and user frame that were active then (`teach NAME` stores
// them; `movej @NAME` / `movel @NAME` go back to it). The joints are what counts: the
// pose is kept so that a changed robot description or tool can be noticed
// (point_pose_mismatch).
//
// The points file (next to the configuration, like the frames file) is TOML:
//
//   format = "servoarm-points-1"
//   [point.pick]
//   joints = [0.0, -0.5235987755982988, 1.0471975511965976, 0.0, 0.5, 0.0]  # rad (m: prismatic)
//   xyz = [0.41, 0.0, 0.23]      # m, the tool point in the base frame
//   rpy = [180.0, 0.0, 0.0]      # deg, roll-pitch-yaw R = Rz(rz) Ry(ry) Rx(rx)
//   tool = "gripper"             # the active tool when taught (tool0: the flange)
//   frame = "base"               # the active user frame when taught
//
// SI joints (rad, m) whatever the console's units: the numbers round-trip exactly.
// Written atomically (kin::write_text_file_atomic). A file that is not valid TOML, lacks
// the format line (a foreign file) or has a bad entry is refused with file:line:column;
// save_points_file never replaces a file that does not load (the old file is kept).
//
// Set-up / console-thread code (allocates, does I/O), never on the control path.
#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/types.hpp"

namespace servoarm::prog {

inline constexpr const char* kPointsFormat = "servoarm-points-1";
inline constexpr std::size_t kMaxPoints = 1000;     ///< points in one file
inline constexpr std::size_t kMaxPointName = 32;    ///< name length + 1
inline constexpr std::size_t kMaxPointsFileBytes = 1024 * 1024;  ///< 1 MiB (1000 points take about 250 kB)

struct TeachPoint {
  std::string name;
  kin::JointVector q;                        ///< SI (rad, m)
  kin::Pose pose = kin::Pose::Identity();    ///< tool point in the base frame when taught (m)
  std::string tool = "tool0";
  std::string frame = "base";
};

struct PointsData {
  std::vector<TeachPoint> points;  ///< in the file's order
};

/// "" when `name` may name a point: 1..31 letters, digits, '_' and '-', starting with a
/// letter, not `delete`; otherwise the reason naming it.
std::string check_point_name(std::string_view name);

/// The point called `name` (case-sensitive), or nullptr.
const TeachPoint* find_point(const PointsData& d, std::string_view name);

/// Add or replace (same name) a point. "" or the reason (bad name, bad values, full).
std::string put_point(PointsData& d, TeachPoint p);
/// Remove a point; false if there is none of that name.
bool delete_point(PointsData& d, std::string_view name);

/// Read and check `path` for an arm of `n_joints` joints. A missing file is not an error
/// (no points, `missing` true). Returns "" or one line "<path>:<line>:<col>: ..."; `out`
/// is set only on success.
std::string load_points_file(const std::string& path, int n_joints, PointsData& out, bool* missing = nullptr);

/// The file's text for `d` (numbers round-trip exactly).
std::string points_to_toml(const PointsData& d);

/// Write `d` to `path` atomically. If a file is there already it must load as a points
/// file (of the same joint count): a corrupt or foreign file is never overwritten (the
/// error names it and its line). "" or the error (the old file kept).
std::string save_points_file(const std::string& path, const PointsData& d);

/// Largest distance (m) between a point's stored tool position and FK(chain, q) * tool,
/// i.e. whether the description or the tool changed since the point was taught.
double point_pose_mismatch(const kin::Chain& chain, const kin::Pose& tool, const TeachPoint& p);

}  // namespace servoarm::prog
