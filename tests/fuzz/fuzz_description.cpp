// SPDX-License-Identifier: Apache-2.0
// libFuzzer target: the robot description loader (kinematics/src/description.cpp, toml++
// through kinematics/io/file_input.hpp). Beyond "no crash": a refusal is one line starting
// with the origin; an accepted chain has finite rows within the plausible ranges.
#include <cmath>
#include <cstdint>
#include <string_view>

#include "servoarm/kinematics/description.hpp"

using namespace servoarm::kin;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  const LoadResult r = load_description(text, "fuzz.toml");
  if (!r.ok) {
    if (r.error.rfind("fuzz.toml", 0) != 0 || r.error.find('\n') != std::string::npos) __builtin_trap();
    return 0;
  }
  const Chain& c = r.chain;
  if (c.n_joints < 1 || c.n_joints > kMaxJoints || c.n_rows > kMaxRows) __builtin_trap();
  for (int i = 0; i < c.n_joints; ++i) {
    const DhRow& j = c.joint(i);
    if (!std::isfinite(j.a) || !std::isfinite(j.d) || !std::isfinite(j.alpha) || !std::isfinite(j.theta)) __builtin_trap();
    if (std::fabs(j.a) > 100 || std::fabs(j.d) > 100) __builtin_trap();
    if (!(j.lower < j.upper)) __builtin_trap();
    if (!(j.dynamics.max_velocity > 0) || !std::isfinite(j.dynamics.max_jerk)) __builtin_trap();
  }
  return 0;
}
