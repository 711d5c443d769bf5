// SPDX-License-Identifier: Apache-2.0
#include "servoarm/sim/cli.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>

namespace servoarm::sim::cli {

bool parse_uint(const std::string& text, std::uint32_t max, std::uint32_t& out) {
  if (text.empty() || text[0] == '-' || text[0] == '+') return false;
  errno = 0;
  char* end = nullptr;
  const unsigned long long v = std::strtoull(text.c_str(), &end, 0);
  if (errno != 0 || end == text.c_str() || *end != '\0' || v > max) return false;
  out = std::uint32_t(v);
  return true;
}

bool parse_double(const std::string& text, double& out) {
  if (text.empty()) return false;
  errno = 0;
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (errno != 0 || end == text.c_str() || *end != '\0' || !std::isfinite(v)) return false;
  out = v;
  return true;
}

bool parse_nodes(const std::string& text, std::vector<std::uint8_t>& out) {
  out.clear();
  std::size_t pos = 0;
  if (text.empty()) return false;
  while (pos <= text.size()) {
    const std::size_t comma = text.find(',', pos);
    const std::string item = text.substr(pos, comma == std::string::npos ? std::string::npos : comma - pos);
    const std::size_t dash = item.find('-');
    std::uint32_t a = 0, b = 0;
    if (dash == std::string::npos) {
      if (!parse_uint(item, 127, a)) return false;
      b = a;
    } else if (!parse_uint(item.substr(0, dash), 127, a) || !parse_uint(item.substr(dash + 1), 127, b)) {
      return false;
    }
    if (a < 1 || b < a) return false;
    for (std::uint32_t n = a; n <= b; ++n) out.push_back(std::uint8_t(n));
    if (comma == std::string::npos) break;
    pos = comma + 1;
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return !out.empty();
}

bool parse_fault(const std::string& text, bool needs_value, FaultArg& out) {
  std::string rest = text;
  out = FaultArg{};
  const std::size_t at = rest.find('@');
  if (at != std::string::npos) {
    if (!parse_double(rest.substr(at + 1), out.at) || out.at < 0) return false;
    rest = rest.substr(0, at);
  }
  const std::size_t colon = rest.find(':');
  std::string target = rest;
  if (colon != std::string::npos) {
    out.value = rest.substr(colon + 1);
    target = rest.substr(0, colon);
    if (out.value.empty()) return false;
  }
  if (needs_value != !out.value.empty()) return false;
  if (target == "all") {
    out.node = 0;
    return true;
  }
  std::uint32_t n = 0;
  if (!parse_uint(target, 127, n) || n == 0) return false;
  out.node = std::uint8_t(n);
  return true;
}

}  // namespace servoarm::sim::cli
