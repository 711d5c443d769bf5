// SPDX-License-Identifier: Apache-2.0
#pragma once
// Starting the project's own binaries (armctl, armfw, armsim, canmaster) from a
// test, in a cross build too.
//
// A cross build runs every suite under CMAKE_CROSSCOMPILING_EMULATOR (qemu-user);
// servoarm_add_test (top CMakeLists.txt) hands it to the suite as
// SERVOARM_TEST_EMULATOR, e.g. "/usr/bin/qemu-aarch64 -L /usr/aarch64-linux-gnu",
// and defines SERVOARM_TEST_EMULATED=1. The emulated test process cannot exec
// another ARM binary by itself: without a binfmt_misc entry for the target (which
// a CI container may not be allowed to register) the kernel refuses it. So the
// helpers below put the emulator in front. In a host build they change nothing.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#ifndef SERVOARM_TEST_EMULATOR
#define SERVOARM_TEST_EMULATOR ""
#endif
#ifndef SERVOARM_TEST_EMULATED
#define SERVOARM_TEST_EMULATED 0
#endif

namespace servoarm::test {

/// The emulator command line ("" on the host).
inline constexpr const char* kEmulator = SERVOARM_TEST_EMULATOR;

/// Shell words to put in front of a target program: "" on the host, else the
/// emulator and a space. Use as `emulator_prefix() + ARMFW_PATH + " --sim"`.
inline std::string emulator_prefix() {
  const std::string e = kEmulator;
  return e.empty() ? e : e + " ";
}

/// argv for execv() of a target program: the emulator's words (split at
/// spaces), then `args` (args[0] is the program's path).
inline std::vector<std::string> target_argv(const std::vector<std::string>& args) {
  std::vector<std::string> out;
  const std::string e = kEmulator;
  std::size_t i = 0;
  while (i < e.size()) {
    const std::size_t j = e.find(' ', i);
    const std::size_t end = j == std::string::npos ? e.size() : j;
    if (end > i) out.push_back(e.substr(i, end - i));
    i = end + 1;
  }
  out.insert(out.end(), args.begin(), args.end());
  return out;
}

/// ELF machine (e_machine) of a file, or -1 when it is not an ELF file.
inline int elf_machine(const std::string& path) {
  unsigned char h[20] = {};
  FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return -1;
  const std::size_t n = std::fread(h, 1, sizeof h, f);
  std::fclose(f);
  if (n < sizeof h || h[0] != 0x7f || h[1] != 'E' || h[2] != 'L' || h[3] != 'F') return -1;
  // e_machine at offset 18, in the file's byte order (EI_DATA: 1 little, 2 big endian).
  return h[5] == 2 ? (h[18] << 8 | h[19]) : (h[19] << 8 | h[18]);
}

/// A shell command line with the emulator in front when its first word is a
/// program for the same machine as this test (under qemu-user /proc/self/exe is
/// the emulated binary). Host programs (/bin/sh, python3) and scripts stay as
/// they are; on the host the line is returned unchanged.
inline std::string with_emulator(const std::string& cmdline) {
  if (kEmulator[0] == '\0') return cmdline;
  const std::size_t start = cmdline.find_first_not_of(' ');
  if (start == std::string::npos) return cmdline;
  const std::string first = cmdline.substr(start, cmdline.find(' ', start) - start);
  const int self = elf_machine("/proc/self/exe");
  if (self < 0 || elf_machine(first) != self) return cmdline;
  return emulator_prefix() + cmdline.substr(start);
}

/// Run `cmd` with the shell (popen), return what it printed on stdout; `status` gets
/// pclose's wait status (WIFEXITED / WEXITSTATUS).
inline std::string run_capture(const std::string& cmd, int& status) {
  std::string out;
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return out;
  char buf[4096];
  std::size_t n;
  while ((n = fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
  status = pclose(p);
  return out;
}

}  // namespace servoarm::test
