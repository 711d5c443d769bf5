// SPDX-License-Identifier: Apache-2.0
// libFuzzer target: the console's number reader (servoarm/lang/number.hpp), checked
// against strtod: every text parse_decimal accepts is a finite double strtod reads the
// same way (the whole text), and `not_finite` only for what strtod reads as inf/nan.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "servoarm/lang/number.hpp"

using namespace servoarm::fw;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > 64) return 0;
  const std::string s(reinterpret_cast<const char*>(data), size);
  double v = 0;
  const Num r = parse_decimal(s, v);
  if (r == Num::ok) {
    if (!std::isfinite(v)) __builtin_trap();
    if (s.find('\0') != std::string::npos) __builtin_trap();  // a NUL inside is not a number
    char* end = nullptr;
    const double ref = std::strtod(s.c_str(), &end);
    if (end != s.c_str() + s.size()) return 0;  // a form strtod reads differently (e.g. hex): no reference
    if (ref != v) __builtin_trap();             // the same double as the C library
  }
  return 0;
}
