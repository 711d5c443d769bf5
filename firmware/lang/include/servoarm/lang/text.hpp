// SPDX-License-Identifier: Apache-2.0
#pragma once
// Text from fixed buffers (snprintf into char arrays: the parser's refusals, the control
// thread's replies, events and fault texts): a message that did not fit is cut after its
// last whole word and ends with "...", never inside a word. No heap in ellipsize (any thread).

#include <cstddef>
#include <string>
#include <string_view>

namespace servoarm::fw {

/// `buf` (capacity `cap`, NUL-terminated) was cut by snprintf: cut it back to the end of its
/// last whole word (trailing spaces and separators dropped) and append "...".
void ellipsize(char* buf, std::size_t cap);

/// The text of a buffer of capacity `cap` another layer filled with snprintf: as it is when
/// it is shorter than the buffer; when it fills it (it was cut, or is exactly that long),
/// cut after its last whole word with "..." appended.
std::string bounded_text(const char* buf, std::size_t cap);
template <std::size_t N>
std::string bounded_text(const char (&buf)[N]) {
  return bounded_text(buf, N);
}

/// "1 dwell", "0 dwells", "6 dwells": a count and its noun, plural unless the count is 1.
/// The one plural rule of the console's and armctl's answers (nouns taking -s).
std::string count_text(long long n, std::string_view noun);

/// `v` to `decimals` places: how every answer of the console, the GRBL dialect and armctl
/// prints a rounded number. A value that rounds to zero prints without a sign ("0.000" for
/// -0.0 and -0.0000001, never "-0.000"); not finite: "nan", "inf", "-inf".
std::string fixed(double v, int decimals);

}  // namespace servoarm::fw
