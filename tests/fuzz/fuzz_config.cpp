// SPDX-License-Identifier: Apache-2.0
// libFuzzer target: the armfw configuration loader (firmware/config, load_config_text).
// Beyond "no crash": a refused file leaves the configuration untouched and the error is
// one line starting with the origin; an accepted one validates and round-trips through
// to_toml().
#include <cstdint>
#include <string>

#include "servoarm/config/config.hpp"

using namespace servoarm::fw;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  FwConfig c;
  const FwConfig before = c;
  const std::string e = load_config_text(text, "fuzz.toml", c);
  if (!e.empty()) {
    if (!(c == before) || e.rfind("fuzz.toml", 0) != 0 || e.find('\n') != std::string::npos) __builtin_trap();
    return 0;
  }
  if (!validate(c).empty()) __builtin_trap();
  FwConfig back;
  if (!load_config_text(to_toml(c), "round-trip", back).empty() || !(back == c)) __builtin_trap();
  return 0;
}
