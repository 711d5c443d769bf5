// SPDX-License-Identifier: Apache-2.0
#pragma once
// Robot description files (TOML) and the built-in models.
//
// Set-up code, not real-time: it allocates. Files are read through file_input.hpp
// (size cap, regular files only, toml++: UTF-8 validated, nesting bounded); every
// error is one line "<file>:<line>:<column>: joint N: key 'k': what is wrong".
// Values outside plausible ranges are refused (lengths and prismatic limits 100 m,
// theta/alpha/rpy one turn, revolute limits 10 turns, velocity/acceleration/jerk
// 100 rad/s, 1e4 rad/s^2, 1e6 rad/s^3 or 10 m/s, 1e3 m/s^2, 1e5 m/s^3, mass 1e4 kg).
//
//   name = "my_arm"
//   convention = "standard"      # or "modified"
//   length_unit = "mm"           # or "m"
//   angle_unit = "deg"           # or "rad"
//   [[joint]]                    # in chain order
//   type = "revolute"            # "revolute" | "prismatic" | "fixed"
//   theta = 0                    # fixed part of theta (offset for revolute)
//   d = 0
//   a = 0
//   alpha = 0
//   direction = 1                # optional, -1 reverses the joint
//   limits = [-170, 170]         # optional, joint units
//   max_velocity = 180           # optional, joint units per second (and /s^2, /s^3 below)
//   max_acceleration = 720
//   max_jerk = 7200
//   mass = 2.5                   # optional inertial data (docs/dynamics.md): kg
//   com = [0, 10, 50]            # length unit, in the row's DH frame
//   inertia = [ixx, iyy, izz, ixy, ixz, iyz]   # kg m^2 about the COM
//   rotor_inertia = 2e-4         # kg m^2 (motor side); gear_ratio = 100
//   friction = [0.5, 0.2]        # viscous N m s/rad, Coulomb N m (not on fixed rows)
//   [tool]                       # optional: xyz (length unit) + rpy (angle unit)
//   xyz = [0, 0, 100]
//   rpy = [0, 0, 0]
//   [base]                       # optional, same keys
//   gravity = [0, 0, -9.81]      # top level, m/s^2, world frame (default shown)
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "servoarm/kinematics/chain.hpp"

namespace servoarm::kin {

struct LoadResult {
  bool ok = false;
  std::string error;  ///< one line naming the file, the joint and the key when !ok
  Chain chain;
};

/// Parse a description from text; `origin` names it in error messages.
LoadResult load_description(std::string_view text, std::string_view origin);
/// Read and parse a file.
LoadResult load_description_file(const std::string& path);
/// A built-in model name (see builtin_model_names()) or a path to a .toml file.
LoadResult load_robot(const std::string& name_or_path);

struct BuiltinModel {
  const char* name;
  const char* summary;
  const char* toml;
};
/// The built-in models shipped in kinematics/models/*.toml.
std::span<const BuiltinModel> builtin_models();

}  // namespace servoarm::kin
