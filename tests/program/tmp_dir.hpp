// SPDX-License-Identifier: Apache-2.0
#pragma once
// A fresh temporary folder per test, and whole-file writes.
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>

namespace servoarm::test {

inline std::string make_tmp_dir() {
  char tmpl[] = "/tmp/servoarm_prog_XXXXXX";
  const char* d = ::mkdtemp(tmpl);
  return d ? std::string(d) : std::string("/tmp");
}
inline void write_file(const std::string& path, const std::string& text) {
  std::ofstream f(path, std::ios::binary);
  f << text;
}
inline std::string read_file(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}
inline void remove_tree(const std::string& dir) {
  if (dir.rfind("/tmp/servoarm_prog_", 0) == 0) std::system(("rm -rf '" + dir + "'").c_str());
}

}  // namespace servoarm::test
