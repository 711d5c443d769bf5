// SPDX-License-Identifier: Apache-2.0
#pragma once
// A strict JSON reader for the tests (RFC 8259 grammar: objects, arrays, strings,
// numbers, true/false/null), so a test can assert that armctl's --json output is one
// valid JSON value: bare nan, inf, -nan or a trailing comma fail here.
#include <cctype>
#include <string>

namespace servoarm::test {

class JsonCheck {
 public:
  /// True when `s` is exactly one JSON value (surrounding whitespace allowed);
  /// otherwise `error` says where it broke.
  bool valid(const std::string& s) {
    s_ = &s;
    i_ = 0;
    error.clear();
    ws();
    if (!value(0)) return false;
    ws();
    if (i_ != s.size()) return fail("text after the value");
    return true;
  }
  std::string error;

 private:
  bool fail(const char* what) {
    error = std::string(what) + " at offset " + std::to_string(i_) + ": '" + s_->substr(i_, 20) + "'";
    return false;
  }
  char peek() const { return i_ < s_->size() ? (*s_)[i_] : '\0'; }
  void ws() {
    while (i_ < s_->size() && ((*s_)[i_] == ' ' || (*s_)[i_] == '\n' || (*s_)[i_] == '\t' || (*s_)[i_] == '\r')) ++i_;
  }
  bool lit(const char* w) {
    const std::string t(w);
    if (s_->compare(i_, t.size(), t) != 0) return fail("bad literal");
    i_ += t.size();
    return true;
  }
  bool digits() {
    const std::size_t b = i_;
    while (std::isdigit(static_cast<unsigned char>(peek()))) ++i_;
    return i_ > b;
  }
  bool number() {
    if (peek() == '-') ++i_;
    if (peek() == '0') ++i_;
    else if (!digits()) return fail("bad number");
    if (peek() == '.') {
      ++i_;
      if (!digits()) return fail("bad fraction");
    }
    if (peek() == 'e' || peek() == 'E') {
      ++i_;
      if (peek() == '+' || peek() == '-') ++i_;
      if (!digits()) return fail("bad exponent");
    }
    return true;
  }
  bool string() {
    ++i_;  // "
    while (i_ < s_->size()) {
      const char c = (*s_)[i_++];
      if (c == '"') return true;
      if (static_cast<unsigned char>(c) < 0x20) return fail("control character in a string");
      if (c == '\\') {
        if (i_ >= s_->size()) break;
        const char e = (*s_)[i_++];
        if (e == 'u') {
          for (int k = 0; k < 4; ++k)
            if (!std::isxdigit(static_cast<unsigned char>(peek()))) return fail("bad \\u escape");
            else ++i_;
        } else if (std::string("\"\\/bfnrt").find(e) == std::string::npos) {
          return fail("bad escape");
        }
      }
    }
    return fail("unterminated string");
  }
  bool value(int depth) {
    if (depth > 64) return fail("nested too deep");
    const char c = peek();
    if (c == '{') {
      ++i_;
      ws();
      if (peek() == '}') return ++i_, true;
      for (;;) {
        ws();
        if (peek() != '"') return fail("object key expected");
        if (!string()) return false;
        ws();
        if (peek() != ':') return fail("':' expected");
        ++i_;
        ws();
        if (!value(depth + 1)) return false;
        ws();
        if (peek() == ',') { ++i_; continue; }
        if (peek() == '}') return ++i_, true;
        return fail("',' or '}' expected");
      }
    }
    if (c == '[') {
      ++i_;
      ws();
      if (peek() == ']') return ++i_, true;
      for (;;) {
        ws();
        if (!value(depth + 1)) return false;
        ws();
        if (peek() == ',') { ++i_; continue; }
        if (peek() == ']') return ++i_, true;
        return fail("',' or ']' expected");
      }
    }
    if (c == '"') return string();
    if (c == 't') return lit("true");
    if (c == 'f') return lit("false");
    if (c == 'n') return lit("null");
    if (c == '-' || std::isdigit(static_cast<unsigned char>(c))) return number();
    return fail("value expected");
  }
  const std::string* s_ = nullptr;
  std::size_t i_ = 0;
};

}  // namespace servoarm::test
