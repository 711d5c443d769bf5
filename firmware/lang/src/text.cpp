// SPDX-License-Identifier: Apache-2.0
#include "servoarm/lang/text.hpp"

#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstring>

namespace servoarm::fw {

namespace {
bool word_char(char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.'; }
bool separator(char c) { return c == ' ' || c == ',' || c == ';' || c == ':' || c == '(' || c == '[' || c == '\'' || c == '"' || c == '='; }
}  // namespace

void ellipsize(char* buf, std::size_t cap) {
  if (cap < 4) {
    if (cap > 0) buf[0] = '\0';
    return;
  }
  // Room for "...": at most cap - 4 characters of the text stay. The character after the
  // kept part decides whether the cut falls inside a word.
  std::size_t len = ::strnlen(buf, cap - 1);
  std::size_t keep = len < cap - 4 ? len : cap - 4;
  if (keep < len && word_char(buf[keep]))
    while (keep > 0 && word_char(buf[keep - 1])) --keep;  // back to the word's start
  while (keep > 0 && separator(buf[keep - 1])) --keep;
  if (keep == 0) keep = cap - 4;  // one long word: as much of it as fits, marked as cut
  std::memcpy(buf + keep, "...", 4);
}

std::string bounded_text(const char* buf, std::size_t cap) {
  const std::size_t len = ::strnlen(buf, cap);
  if (cap == 0 || len + 1 < cap) return std::string(buf, len);
  // Full: the producer's snprintf cut it (the usual case) or it fits exactly; both end
  // after a whole word with "...". A copy one larger keeps the cut character in view.
  std::string s(buf, len);
  std::size_t keep = len;
  if (keep > 0 && word_char(s[keep - 1]))
    while (keep > 0 && word_char(s[keep - 1])) --keep;
  while (keep > 0 && separator(s[keep - 1])) --keep;
  if (keep == 0) keep = len;  // one long word: keep it, marked as cut
  s.resize(keep);
  return s + "...";
}

std::string count_text(long long n, std::string_view noun) {
  std::string s = std::to_string(n);
  s += ' ';
  s += noun;
  if (n != 1) s += 's';
  return s;
}

std::string fixed(double v, int decimals) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  if (decimals < 0) decimals = 0;
  if (decimals > 17) decimals = 17;
  char b[352];  // the largest double to 17 places
  std::snprintf(b, sizeof b, "%.*f", decimals, v);
  if (b[0] == '-') {  // "-0.000": the value rounds to zero
    bool zero = true;
    for (const char* c = b + 1; *c != '\0'; ++c) zero = zero && (*c == '0' || *c == '.');
    if (zero) return std::string(b + 1);
  }
  return b;
}

}  // namespace servoarm::fw
