// SPDX-License-Identifier: Apache-2.0
#pragma once
// Run a command line, capture stdout and stderr separately and the exit status.
// In a cross build a line that starts with a target binary (kArmctl) runs it
// under the emulator (target_exec.hpp): no binfmt_misc needed.
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <sys/wait.h>
#include <unistd.h>

#include "../program/tmp_dir.hpp"
#include "target_exec.hpp"

namespace servoarm::test {

struct CommandResult {
  int status = -1;
  std::string out, err;
};

inline std::string slurp(const std::string& path) {
  std::ifstream f(path);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

inline CommandResult run_command(const std::string& cmdline) {
  static int counter = 0;
  const std::string base = "/tmp/servoarm_cmd_" + std::to_string(getpid()) + "_" + std::to_string(counter++);
  const std::string full = with_emulator(cmdline) + " >" + base + ".out 2>" + base + ".err";
  CommandResult r;
  const int raw = std::system(full.c_str());
  r.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
  r.out = slurp(base + ".out");
  r.err = slurp(base + ".err");
  std::remove((base + ".out").c_str());
  std::remove((base + ".err").c_str());
  return r;
}

/// `armctl program check FILE EXTRA` (armctl: the binary, ARMCTL_PATH), with `text`
/// written to FILE first: the program-file tests' one way to run a program through armctl.
inline CommandResult program_check(const std::string& armctl, const std::string& file, const std::string& text,
                                   const std::string& extra) {
  write_file(file, text);
  return run_command(armctl + " program check " + file + " " + extra);
}

/// The seconds `armctl program check` answers as "planned cycle time T s", or -1 without it.
inline double cycle_time(const std::string& out) {
  const std::size_t k = out.find("planned cycle time ");
  if (k == std::string::npos) return -1;
  return std::atof(out.c_str() + k + 19);
}

/// Numbers of a JSON array that follows `"key": ` (flat arrays only, or the
/// flattened content of nested ones).
inline std::vector<double> json_numbers(const std::string& json, const std::string& key) {
  std::vector<double> v;
  const std::size_t k = json.find("\"" + key + "\":");
  if (k == std::string::npos) return v;
  std::size_t i = json.find('[', k);
  int depth = 0;
  std::string tok;
  for (; i < json.size(); ++i) {
    const char c = json[i];
    if (c == '[') {
      ++depth;
    } else if (c == ']' || c == ',') {
      if (!tok.empty()) v.push_back(std::strtod(tok.c_str(), nullptr)), tok.clear();
      if (c == ']' && --depth == 0) break;
    } else if (c != ' ') {
      tok += c;
    }
  }
  return v;
}

}  // namespace servoarm::test
