// SPDX-License-Identifier: Apache-2.0
#pragma once
// Named tools and user frames (work objects), and the frames file that keeps them.
//
// A tool is the tool centre point (TCP) relative to the flange: TCP = FK(q) * tool
// (FK as the robot description gives it, its own `tool` transform included: that is
// the flange, `tool0`). A user frame is a pose in the base frame; a pose "in the frame"
// is frame^-1 * (pose in the base). `base` is the base frame itself; G54..G59 select the
// user frames `g54`..`g59` (GRBL/LinuxCNC work offsets 1..6; identity until set).
//
// The frames file (console.frames_file, next to the configuration) is TOML written by
// armfw, never by hand while it runs:
//
//   format = "servoarm-frames-1"
//   active_tool = "gripper"      # selected at start
//   active_frame = "base"
//   [tool.gripper]
//   xyz = [0.0, 0.0, 0.12]       # m (SI, whatever the console's units)
//   rpy = [0.0, 0.0, 90.0]       # deg, roll-pitch-yaw R = Rz(rz) Ry(ry) Rx(rx)
//   mass = 0.8                   # kg, optional (payload, for dynamics later)
//   com = [0.0, 0.0, 0.05]       # m, in the tool frame, optional (with mass)
//   radius = 0.04                # m: the safety envelope's tool sphere, optional
//   [frame.g54]
//   xyz = [0.4, 0.0, 0.0]
//   rpy = [0.0, 0.0, 0.0]
//
// Written atomically (write_text_file_atomic: a power cut leaves the old or the new
// file). A file that is not valid TOML, lacks the format line (a foreign file), or has
// a bad entry is refused with file:line:column and never overwritten: at start, and
// again before each write (a file replaced while armfw runs). A read-only file is
// never replaced either.
//
// Console-thread code (allocates, does I/O).
#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include "servoarm/kinematics/types.hpp"

namespace servoarm::fw {

inline constexpr std::size_t kMaxTools = 16;    ///< tool0 included
inline constexpr std::size_t kMaxFrames = 16;   ///< base included
inline constexpr std::size_t kMaxFrameName = 24;
inline constexpr double kMaxOffsetM = 10.0;      ///< |x|, |y|, |z| of a tool or frame, m
inline constexpr double kMaxPayloadKg = 1000.0;
inline constexpr double kMaxToolRadiusM = 2.0;   ///< a tool's safety sphere (safety.tool_radius_mm's range)
inline constexpr const char* kFramesFormat = "servoarm-frames-1";

/// A named tool or frame: pose (SI), and for tools an optional payload.
struct NamedPose {
  std::string name;
  kin::Pose pose = kin::Pose::Identity();
  bool has_payload = false;
  double mass = 0.0;                            ///< kg
  Eigen::Vector3d com = Eigen::Vector3d::Zero();  ///< m, in the tool frame
  /// Tools: the radius of the safety envelope's sphere around this TCP (m, docs/safety.md);
  /// < 0 = not given: safety.tool_radius_mm.
  double radius = -1.0;
};

/// What the frames file holds (tool0 and base are implicit: never stored).
struct FramesData {
  std::vector<NamedPose> tools;
  std::vector<NamedPose> frames;
  std::string active_tool = "tool0";
  std::string active_frame = "base";
};

/// "" when `name` may name a tool (`is_tool`) or a frame: 1..23 characters of letters,
/// digits, '_' and '-', starting with a letter; not a reserved word (`delete`, and
/// `tool0` for tools / `base` for frames, which cannot be redefined). Otherwise the
/// reason, naming `name`.
std::string check_frame_name(std::string_view name, bool is_tool);

/// "" when the pose values are acceptable (finite, |xyz| <= kMaxOffsetM, angles within
/// +-360 deg, payload 0..kMaxPayloadKg and |com| <= kMaxOffsetM); else the reason.
/// xyz in m, rpy in rad.
std::string check_frame_values(const double xyz[3], const double rpy_rad[3], bool has_payload, double mass,
                               const double com[3]);

/// "" when a tool's safety radius (m) is within [0, kMaxToolRadiusM]; else the reason.
std::string check_tool_radius(double radius_m);

/// Read and check `path`. A missing file is not an error (empty data, `missing` true).
/// Returns "" or the one-line error ("<path>:<line>:<col>: ..."); `out` is set only on success.
std::string load_frames_file(const std::string& path, FramesData& out, bool* missing = nullptr);

/// The file's text for `d` (numbers round-trip exactly).
std::string frames_to_toml(const FramesData& d);

/// "" when `path` is missing or a regular file that may be replaced; otherwise the one-line
/// reason naming `path`: a file without any write permission bit (read-only, whoever runs
/// armfw, root included) or one this process may not write is never replaced by a new,
/// writable file.
std::string check_writable_file(const std::string& path);

/// frames_to_toml + write_text_file_atomic. "" or the error (the old file is kept). The
/// file on disk is checked before each write: one that does not load as a frames file
/// (another program's file put in its place while armfw runs) or is read-only
/// (check_writable_file) is refused and kept as it is.
std::string save_frames_file(const std::string& path, const FramesData& d);

}  // namespace servoarm::fw
