// SPDX-License-Identifier: Apache-2.0
#pragma once
// Regular expressions for the suites (ECMAScript, std::regex's default syntax), compiled once,
// in the test support library: <regex>'s templates cost every source that includes it some 3 s
// of g++ 12's time and 6 s under clang's ASan+UBSan flags (docs/building-and-testing.md).
// A match is its groups as strings, [0] the whole match, an unmatched group empty; no match is
// an empty vector.
#include <memory>
#include <string>
#include <vector>

namespace servoarm::test {

using Groups = std::vector<std::string>;

class Regex {
 public:
  explicit Regex(const std::string& pattern);
  ~Regex();
  Regex(Regex&&) noexcept;
  Regex& operator=(Regex&&) noexcept;

  /// The first match anywhere in `text`.
  Groups search(const std::string& text) const;
  /// `text` matched whole.
  Groups match(const std::string& text) const;
  /// Every match in `text`, in order.
  std::vector<Groups> search_all(const std::string& text) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Regex(pattern).search(text), for a pattern used once.
inline Groups regex_search(const std::string& text, const std::string& pattern) { return Regex(pattern).search(text); }

}  // namespace servoarm::test
