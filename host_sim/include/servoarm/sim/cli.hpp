// SPDX-License-Identifier: Apache-2.0
#pragma once
// Small argument parsers shared by the armsim and canmaster binaries (set-up code).
#include <cstdint>
#include <string>
#include <vector>

namespace servoarm::sim::cli {

/// "1-6", "1,3,5", "2-4,7" -> sorted unique node ids 1..127. False on bad syntax/range.
bool parse_nodes(const std::string& text, std::vector<std::uint8_t>& out);
/// Whole string is a finite number.
bool parse_double(const std::string& text, double& out);
/// Decimal or 0x-hex unsigned integer no larger than `max`.
bool parse_uint(const std::string& text, std::uint32_t max, std::uint32_t& out);

/// A fault-injection argument "TARGET[:VALUE][@SEC]" where TARGET is a node id or "all"
/// (node 0 = all nodes).
struct FaultArg {
  std::uint8_t node = 0;
  std::string value;   ///< empty when no ":VALUE"
  double at = 0.0;     ///< seconds after start
};
bool parse_fault(const std::string& text, bool needs_value, FaultArg& out);

}  // namespace servoarm::sim::cli
