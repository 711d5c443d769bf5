// SPDX-License-Identifier: Apache-2.0
#include "text_regex.hpp"

#include <regex>

namespace servoarm::test {

struct Regex::Impl {
  std::regex re;
};

namespace {
Groups groups(const std::smatch& m) {
  Groups g;
  g.reserve(m.size());
  for (const auto& sub : m) g.push_back(sub.matched ? sub.str() : std::string());
  return g;
}
}  // namespace

Regex::Regex(const std::string& pattern) : impl_(new Impl{std::regex(pattern)}) {}
Regex::~Regex() = default;
Regex::Regex(Regex&&) noexcept = default;
Regex& Regex::operator=(Regex&&) noexcept = default;

Groups Regex::search(const std::string& text) const {
  std::smatch m;
  return std::regex_search(text, m, impl_->re) ? groups(m) : Groups();
}

Groups Regex::match(const std::string& text) const {
  std::smatch m;
  return std::regex_match(text, m, impl_->re) ? groups(m) : Groups();
}

std::vector<Groups> Regex::search_all(const std::string& text) const {
  std::vector<Groups> all;
  for (auto it = std::sregex_iterator(text.begin(), text.end(), impl_->re); it != std::sregex_iterator(); ++it)
    all.push_back(groups(*it));
  return all;
}

}  // namespace servoarm::test
