// SPDX-License-Identifier: Apache-2.0
// libFuzzer target: the console's line parser (command language, G-code, GRBL $ lines).
// Input: one byte for the joint count (1..8), then the line. Checks beyond "no crash":
// a refused line leaves the G-code modal state untouched and has a message; an accepted
// command holds only finite values.
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string_view>

#include "servoarm/lang/commands.hpp"

using namespace servoarm::fw;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const int n_joints = 1 + data[0] % 8;
  const std::string_view line(reinterpret_cast<const char*>(data + 1), size - 1);
  GcodeModal modal;
  modal.relative = data[0] & 0x80;
  const GcodeModal before = modal;
  Command cmd;
  const ParseResult r = parse_line(line, n_joints, modal, cmd);
  if (!r.ok()) {
    if (modal.relative != before.relative || modal.unit_mm != before.unit_mm || modal.feed_mm_s != before.feed_mm_s)
      __builtin_trap();  // modal state changed by a refused line
    if (r.message[r.message.size() - 1] != '\0') __builtin_trap();
    return 0;
  }
  if (cmd.count < 0 || cmd.count > static_cast<int>(cmd.vals.size())) __builtin_trap();
  for (int i = 0; i < cmd.count; ++i)
    if (!std::isfinite(cmd.vals[static_cast<std::size_t>(i)])) __builtin_trap();
  if (cmd.has_speed && !std::isfinite(cmd.speed)) __builtin_trap();
  if (!std::isfinite(modal.feed_mm_s) || !(modal.unit_mm == 1.0 || modal.unit_mm == 25.4)) __builtin_trap();
  return 0;
}
