// SPDX-License-Identifier: Apache-2.0
#pragma once
// The one decimal-number reader of every text front end that is not a TOML file: the
// console's commands, G-code, armctl's options and armfw's flags. (TOML files — robot
// descriptions and the configuration — are read by the TOML library, which has its own
// grammar for numbers.) Strict: [+-]digits[.digits][(e|E)[+-]digits], at least one digit
// in the mantissa, nothing before or after; hex, "0x", "1e", ".", "nan", "inf" are refused.
// No heap, no exceptions, no locale: callable from any thread.

#include <cstdint>
#include <string_view>

namespace servoarm::fw {

enum class Num {
  ok,          ///< `out` holds the finite value
  bad,         ///< not a decimal number (empty, stray characters, longer than 40 characters)
  not_finite,  ///< nan/inf spelled out, or a decimal that overflows a double (1e400)
};

/// Parse `s` as a strict decimal; `out` is written only on Num::ok.
Num parse_decimal(std::string_view s, double& out);

/// Exactly 8 hex digits (either case) into `out`, as a CRC-32 checksum is shown
/// (`%08X`); false: anything else (`out` untouched).
bool parse_checksum(std::string_view s, std::uint32_t& out);

/// ASCII case-insensitive equality: how every word of the text front ends is matched
/// (command words, options, `$` words, reserved names).
bool ieq(std::string_view a, std::string_view b);

}  // namespace servoarm::fw
