// SPDX-License-Identifier: Apache-2.0
#include "servoarm/lang/markdown.hpp"

#include <algorithm>
#include <vector>

namespace servoarm::fw {

namespace {

std::vector<std::string> lines_of(const std::string& s) {
  std::vector<std::string> out;
  std::size_t a = 0;
  while (a < s.size()) {
    std::size_t b = s.find('\n', a);
    if (b == std::string::npos) b = s.size();
    out.push_back(s.substr(a, b - a));
    a = b + 1;
  }
  return out;
}

}  // namespace

std::string md_cell(std::string_view s) {
  std::string o;
  for (std::size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '|' && (i == 0 || s[i - 1] != '\\')) o += '\\';
    o += s[i];
  }
  return o;
}

std::string generated_section_mismatch(const std::string& page, const std::string& generated, const GeneratedSection& s) {
  const std::vector<std::string> pl = lines_of(page);
  std::size_t b = pl.size(), e = pl.size();
  for (std::size_t i = 0; i < pl.size(); ++i) {
    if (b == pl.size() && pl[i].rfind(s.begin_prefix, 0) == 0) b = i;
    else if (b != pl.size() && pl[i] == s.end_line) {
      e = i;
      break;
    }
  }
  if (b == pl.size() || e == pl.size())
    return std::string("no BEGIN/END ") + std::string(s.begin_prefix).substr(std::string_view("<!-- BEGIN ").size()) +
           " markers; " + s.how;
  const std::vector<std::string> have(pl.begin() + static_cast<long>(b), pl.begin() + static_cast<long>(e) + 1);
  const std::vector<std::string> want = lines_of(generated);
  if (have == want) return "";
  // Line diff by longest common subsequence (the sections are tens of lines).
  const std::size_t n = have.size(), m = want.size();
  std::vector<std::vector<int>> L(n + 1, std::vector<int>(m + 1, 0));
  for (std::size_t i = n; i-- > 0;)
    for (std::size_t j = m; j-- > 0;)
      L[i][j] = have[i] == want[j] ? L[i + 1][j + 1] + 1 : std::max(L[i + 1][j], L[i][j + 1]);
  std::string o = std::string(s.title) + " (- page, + generated):\n";
  int shown = 0;
  std::size_t i = 0, j = 0;
  while ((i < n || j < m) && shown < 40) {
    if (i < n && j < m && have[i] == want[j]) {
      ++i, ++j;
    } else if (j < m && (i == n || L[i][j + 1] >= L[i + 1][j])) {
      o += "+ " + want[j++] + "\n";
      ++shown;
    } else {
      o += "- line " + std::to_string(b + i + 1) + ": " + have[i] + "\n";
      ++i;
      ++shown;
    }
  }
  return o + s.how;
}

}  // namespace servoarm::fw
