// SPDX-License-Identifier: Apache-2.0
// The servoarm Debian package as CPack built it (fixture packaging_build):
// control fields, file list, maintainer scripts, the systemd units, and the
// package unpacked into a scratch root with dpkg-deb -x: files where the
// README says, binaries for the package's architecture, the default config
// accepted by armfw, the CAN bring-up script driving a stub `ip`. In a cross
// build the packaged armfw/armctl run under the emulator (target_exec.hpp).
#include <dirent.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "target_exec.hpp"

// CppUTest last: its leak detector redefines `new`.
#include <CppUTest/TestHarness.h>

namespace {

struct Cmd {
  int status = -1;
  std::string out;  // stdout and stderr together
};

// Runs `sh -c line` with stdout+stderr captured.
Cmd sh(const std::string& line) {
  Cmd c;
  const std::string full = "(" + line + ") 2>&1";
  FILE* p = ::popen(full.c_str(), "r");
  if (!p) return c;
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) c.out.append(buf, n);
  const int raw = ::pclose(p);
  c.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
  return c;
}

std::string slurp(const std::string& path) {
  std::ifstream f(path);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

bool has(const std::string& hay, const std::string& needle) { return hay.find(needle) != std::string::npos; }

// The text without its comment lines (shell scripts, unit files).
std::string code_only(const std::string& text) {
  std::istringstream is(text);
  std::string line, out;
  while (std::getline(is, line)) {
    const std::size_t i = line.find_first_not_of(" \t");
    if (i != std::string::npos && (line[i] == '#' || line[i] == ';')) continue;
    out += line + "\n";
  }
  return out;
}

// Lines of a unit file with the given key, e.g. "AmbientCapabilities".
std::vector<std::string> unit_values(const std::string& unit, const std::string& key) {
  std::vector<std::string> v;
  std::istringstream is(unit);
  std::string line;
  while (std::getline(is, line))
    if (line.rfind(key + "=", 0) == 0) v.push_back(line.substr(key.size() + 1));
  return v;
}

std::string the_deb() {
  std::string found;
  if (DIR* d = ::opendir(DEB_DIR)) {
    while (dirent* e = ::readdir(d)) {
      const std::string n = e->d_name;
      if (n.size() > 4 && n.compare(n.size() - 4, 4, ".deb") == 0) found = std::string(DEB_DIR) + "/" + n;
    }
    ::closedir(d);
  }
  return found;
}

mode_t mode_of(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 ? st.st_mode : 0;
}

// ELF e_machine of a file (0 if not ELF).
int elf_machine(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  unsigned char h[20] = {};
  f.read(reinterpret_cast<char*>(h), sizeof h);
  if (!f || std::memcmp(h, "\x7f" "ELF", 4) != 0) return 0;
  return h[18] | (h[19] << 8);  // little-endian targets only (all of ours)
}

int expected_machine() {
  const std::string a = DEB_ARCH;
  if (a == "arm64") return 183;   // EM_AARCH64
  if (a == "armhf") return 40;    // EM_ARM
  if (a == "amd64") return 62;    // EM_X86_64
  if (a == "i386") return 3;
  return -1;
}

}  // namespace

TEST_GROUP(Package) {
  std::string deb, tmp, root, ctl;
  void setup() override {
    deb = the_deb();
    CHECK_TEXT(!deb.empty(), "no .deb in " DEB_DIR " (did the packaging_build fixture run?)");
    char t[] = "/tmp/servoarm_pkg_XXXXXX";
    CHECK(::mkdtemp(t) != nullptr);
    tmp = t;
    root = tmp + "/root";
    ctl = tmp + "/DEBIAN";
  }
  void teardown() override {
    if (!tmp.empty()) sh("rm -rf '" + tmp + "'");
  }
  void extract() {
    const Cmd x = sh("dpkg-deb -x '" + deb + "' '" + root + "'");
    CHECK_EQUAL_TEXT(0, x.status, x.out.c_str());
  }
  void control() {
    const Cmd e = sh("dpkg-deb -e '" + deb + "' '" + ctl + "'");
    CHECK_EQUAL_TEXT(0, e.status, e.out.c_str());
  }
};

TEST(Package, ControlFields) {
  const Cmd f = sh("dpkg-deb -f '" + deb + "' Package Version Architecture Depends Maintainer");
  CHECK_EQUAL_TEXT(0, f.status, f.out.c_str());
  CHECK_TEXT(has(f.out, "Package: servoarm\n"), f.out.c_str());
  CHECK_TEXT(has(f.out, "Version: " DEB_VERSION "\n"), f.out.c_str());
  CHECK_TEXT(has(f.out, "Architecture: " DEB_ARCH "\n"), f.out.c_str());
  // postinst uses adduser, servoarm-can-up uses ip; the binaries need the C++ runtime.
  for (const char* dep : {"adduser", "iproute2", "libc6", "libstdc++6"}) CHECK_TEXT(has(f.out, dep), dep);
  STRCMP_CONTAINS("_" DEB_VERSION "_" DEB_ARCH ".deb", deb.c_str());
}

// Every shared library the packaged binaries load (ELF NEEDED, read with readelf,
// which reads any architecture) is provided by a package in Depends; statically linked
// binaries load none.
TEST(Package, DependsCoversEveryNeededLibrary) {
  extract();
  const Cmd f = sh("dpkg-deb -f '" + deb + "' Depends");
  CHECK_EQUAL_TEXT(0, f.status, f.out.c_str());
  struct Lib {
    const char* soname_prefix;
    const char* package;
  };
  const Lib known[] = {{"libc.so.", "libc6"},          {"libm.so.", "libc6"},       {"libpthread.so.", "libc6"},
                       {"libdl.so.", "libc6"},         {"librt.so.", "libc6"},      {"ld-linux", "libc6"},
                       {"libstdc++.so.", "libstdc++6"}, {"libgcc_s.so.", "libgcc-s1"}, {"libedit.so.", "libedit2"},
                       {"liburdfdom_model.so.", "liburdfdom-model3.0"}, {"libconsole_bridge.so.", "libconsole-bridge1.0"},
                       {"libwebsockets.so.", "libwebsockets17"}, {"libmosquitto.so.", "libmosquitto1"},
                       {"libgpiod.so.", "libgpiod2"}};
  int binaries = 0;
  for (const char* bin : {"/usr/bin/armfw", "/usr/bin/armctl"}) {
    const std::string path = root + bin;
    if (::access(path.c_str(), F_OK) != 0) continue;
    ++binaries;
    const Cmd d = sh("readelf -d '" + path + "'");
    CHECK_EQUAL_TEXT(0, d.status, d.out.c_str());
    std::istringstream is(d.out);
    std::string line;
    int needed = 0;
    while (std::getline(is, line)) {
      const auto p = line.find("Shared library: [");
      if (p == std::string::npos) continue;
      ++needed;
      const std::string so = line.substr(p + 17, line.find(']', p) - p - 17);
      const char* pkg = nullptr;
      for (const Lib& l : known)
        if (so.rfind(l.soname_prefix, 0) == 0) pkg = l.package;
      CHECK_TEXT(pkg != nullptr, (std::string(bin) + " needs " + so + ": which package? (add it to Depends and here)").c_str());
      if (pkg != nullptr) CHECK_TEXT(has(f.out, pkg), (std::string(bin) + " needs " + so + " but Depends lacks " + pkg + ": " + f.out).c_str());
    }
    // A static build (SERVOARM_STATIC) loads no library; a dynamic one at least libc.
    if (STATIC_LINK) LONGS_EQUAL_TEXT(0, needed, d.out.c_str());
    else CHECK_TEXT(needed > 0, d.out.c_str());
  }
  CHECK(binaries > 0 || (!HAVE_ARMFW && !HAVE_ARMCTL));
}

TEST(Package, FileList) {
  const Cmd c = sh("dpkg-deb -c '" + deb + "'");
  CHECK_EQUAL_TEXT(0, c.status, c.out.c_str());
  std::vector<std::string> want = {
      "./etc/servoarm/armfw.toml", "./etc/default/servoarm", "./lib/systemd/system/servoarm.service",
      "./lib/systemd/system/servoarm-can.service", "./usr/lib/servoarm/servoarm-can-up",
      "./usr/share/servoarm/models/puma560.toml", "./usr/share/doc/servoarm/README.md",
      "./usr/share/doc/servoarm/docs/deployment.md",  // the units' Documentation=
      "./usr/share/servoarm/web/index.html", "./usr/share/servoarm/web/pendant.js"};  // the pendant armfw serves
  if (HAVE_ARMCTL) want.push_back("./usr/bin/armctl");
  if (HAVE_ARMFW) want.push_back("./usr/bin/armfw");
  for (const auto& w : want) CHECK_TEXT(has(c.out, " " + w + "\n"), (w + " missing from:\n" + c.out).c_str());
  // Every built-in description, nothing from the build machine's prefix, no
  // development files, everything owned by root.
  int models = 0, lines = 0;
  std::istringstream is(c.out);
  std::string line;
  while (std::getline(is, line)) {
    ++lines;
    if (has(line, "./usr/share/servoarm/models/") && line.size() > 5 && line.compare(line.size() - 5, 5, ".toml") == 0) ++models;
    CHECK_TEXT(!has(line, "/usr/local"), line.c_str());
    CHECK_TEXT(!has(line, "/include/") && !(line.size() > 2 && line.compare(line.size() - 2, 2, ".a") == 0), line.c_str());
    CHECK_TEXT(has(line, " root/root "), line.c_str());
  }
  CHECK_EQUAL(N_MODELS, models);
  CHECK(lines > 10);
}

TEST(Package, CopyrightNamesTheLicence) {
  // Debian's place for a package's licence: /usr/share/doc/<package>/copyright, in the
  // machine-readable format, naming the licence the sources carry (LICENSE, SPDX lines).
  extract();
  const std::string c = slurp(root + "/usr/share/doc/servoarm/copyright");
  CHECK_TEXT(has(c, "Format: https://www.debian.org/doc/packaging-manuals/copyright-format/1.0/"), c.c_str());
  CHECK_TEXT(has(c, "License: Apache-2.0"), c.c_str());
  CHECK_TEXT(has(c, "/usr/share/common-licenses/Apache-2.0"), c.c_str());
}

TEST(Package, MaintainerScripts) {
  control();
  for (const char* s : {"postinst", "prerm", "postrm"}) {
    const std::string p = ctl + "/" + s;
    CHECK_EQUAL_TEXT(0755u, mode_of(p) & 07777u, s);
    const std::string text = slurp(p);
    CHECK_TEXT(text.rfind("#!/bin/sh\n", 0) == 0, s);
    CHECK_TEXT(has(text, "set -e"), s);
    const Cmd n = sh("sh -n '" + p + "'");
    CHECK_EQUAL_TEXT(0, n.status, (std::string(s) + ": " + n.out).c_str());
  }
  const std::string postinst = slurp(ctl + "/postinst");
  STRCMP_CONTAINS("adduser --system", postinst.c_str());
  STRCMP_CONTAINS("getent passwd servoarm", postinst.c_str());        // idempotent on upgrade
  STRCMP_CONTAINS("chown root:servoarm /etc/servoarm/armfw.toml", postinst.c_str());
  STRCMP_CONTAINS("systemctl daemon-reload", postinst.c_str());
  // Never enabled or started on a fresh install: only restarted after an upgrade.
  CHECK(!has(code_only(postinst), "systemctl enable"));
  STRCMP_CONTAINS("/run/servoarm.restart-after-upgrade", postinst.c_str());
  const std::string prerm = slurp(ctl + "/prerm");
  STRCMP_CONTAINS("systemctl stop servoarm.service", prerm.c_str());
  STRCMP_CONTAINS("touch /run/servoarm.restart-after-upgrade", prerm.c_str());
  // Conffiles: the admin's edits survive upgrades.
  const std::string conffiles = slurp(ctl + "/conffiles");
  STRCMP_CONTAINS("/etc/servoarm/armfw.toml\n", conffiles.c_str());
  STRCMP_CONTAINS("/etc/default/servoarm\n", conffiles.c_str());
}

TEST(Package, FirmwareUnit) {
  extract();
  const std::string unit = slurp(root + "/lib/systemd/system/servoarm.service");
  CHECK(!unit.empty());
  auto one = [&](const char* key) {
    const auto v = unit_values(unit, key);
    CHECK_EQUAL_TEXT(1u, v.size(), key);
    return v.empty() ? std::string() : v[0];
  };
  STRCMP_EQUAL("servoarm", one("User").c_str());
  STRCMP_EQUAL("on-failure", one("Restart").c_str());
  STRCMP_EQUAL("99", one("LimitRTPRIO").c_str());
  STRCMP_EQUAL("infinity", one("LimitMEMLOCK").c_str());
  STRCMP_EQUAL("CAP_SYS_NICE CAP_IPC_LOCK", one("AmbientCapabilities").c_str());
  STRCMP_EQUAL("CAP_SYS_NICE CAP_IPC_LOCK", one("CapabilityBoundingSet").c_str());
  STRCMP_EQUAL("yes", one("NoNewPrivileges").c_str());
  STRCMP_EQUAL("multi-user.target", one("WantedBy").c_str());
  STRCMP_EQUAL("servoarm-can.service", one("Requires").c_str());
  STRCMP_CONTAINS("servoarm-can.service", one("After").c_str());
  // The state folder the shipped armfw.toml writes programs, points and frames into:
  // created by systemd owned by User= (the rest of the file system is read-only to it).
  STRCMP_EQUAL("strict", one("ProtectSystem").c_str());
  STRCMP_EQUAL("servoarm servoarm/programs", one("StateDirectory").c_str());
  const std::string conf = slurp(root + "/etc/servoarm/armfw.toml");
  for (const char* k : {"dir = \"/var/lib/servoarm/programs\"", "points_file = \"/var/lib/servoarm/points.toml\"",
                        "frames_file = \"/var/lib/servoarm/frames.toml\""})
    STRCMP_CONTAINS(k, conf.c_str());
  const std::string exec = one("ExecStart");
  STRCMP_CONTAINS("/usr/bin/armfw --config /etc/servoarm/armfw.toml", exec.c_str());
  if (HAVE_ARMFW) CHECK_TEXT(mode_of(root + "/usr/bin/armfw") & S_IXUSR, "ExecStart binary not in the package");
  // The firmware itself never configures interfaces.
  const std::string code = code_only(unit);
  CHECK(!has(code, "CAP_NET_ADMIN") && !has(code, "CAP_SYS_ADMIN") && !has(code, "CAP_NET_RAW"));
}

TEST(Package, CanUnit) {
  extract();
  const std::string unit = slurp(root + "/lib/systemd/system/servoarm-can.service");
  CHECK(!unit.empty());
  const auto type = unit_values(unit, "Type");
  CHECK_EQUAL(1u, type.size());
  STRCMP_EQUAL("oneshot", type[0].c_str());
  const auto caps = unit_values(unit, "CapabilityBoundingSet");
  CHECK_EQUAL(1u, caps.size());
  STRCMP_EQUAL("CAP_NET_ADMIN", caps[0].c_str());
  const auto exec = unit_values(unit, "ExecStart");
  CHECK_EQUAL(1u, exec.size());
  STRCMP_CONTAINS("/usr/lib/servoarm/servoarm-can-up /etc/servoarm/armfw.toml", exec[0].c_str());
  CHECK(mode_of(root + "/usr/lib/servoarm/servoarm-can-up") & S_IXUSR);
}

TEST(Package, SystemdAnalyzeVerify) {
  if (sh("command -v systemd-analyze").status != 0) {
    UT_PRINT("systemd-analyze not installed: unit verification skipped");
    return;
  }
  extract();
  // Both units side by side in one directory (verify finds Requires= units
  // there), with the programs they start pointed into the scratch root, so
  // verify checks the packaged binaries exist and are executable.
  const std::string dir = tmp + "/units";
  CHECK_EQUAL(0, ::mkdir(dir.c_str(), 0755));
  for (const char* u : {"servoarm.service", "servoarm-can.service"}) {
    std::string text = slurp(root + "/lib/systemd/system/" + u);
    for (const char* key : {"ExecStart=", "ExecStartPre=", "ExecStop="}) {
      const std::string k = std::string(key) + "/usr/";
      for (std::size_t at = text.find(k); at != std::string::npos; at = text.find(k, at + 1))
        text.replace(at + std::strlen(key), 1, root + "/");
    }
    std::ofstream(dir + "/" + u) << text;
  }
  for (const char* u : {"servoarm.service", "servoarm-can.service"}) {
    const Cmd v = sh("systemd-analyze verify '" + dir + "/" + u + "'");
    CHECK_EQUAL_TEXT(0, v.status, (std::string(u) + ":\n" + v.out).c_str());
    // Warnings fail too (an unknown key is only a warning to systemd); a
    // container's "not booted with systemd" notice is tolerated.
    std::istringstream is(v.out);
    std::string line;
    while (std::getline(is, line))
      if (has(line, "servoarm")) FAIL((std::string(u) + ": " + line).c_str());
  }
}

TEST(Package, ScratchRootInstall) {
  extract();
  for (const char* f : {"/etc/servoarm/armfw.toml", "/etc/default/servoarm", "/usr/share/servoarm/models/puma560.toml",
                        "/usr/share/doc/servoarm/README.md"})
    CHECK_TEXT(S_ISREG(mode_of(root + f)), f);
  // Config not world-readable (postinst gives it to group servoarm).
  CHECK_EQUAL(0640u, mode_of(root + "/etc/servoarm/armfw.toml") & 07777u);
  // Every built-in description is installed, byte for byte.
  const Cmd d = sh("diff -r '" SOURCE_DIR "/kinematics/models' '" + root + "/usr/share/servoarm/models'");
  CHECK_EQUAL_TEXT(0, d.status, d.out.c_str());
  // Binaries are for the package's architecture.
  for (const char* b : {"armctl", "armfw"}) {
    if ((std::string(b) == "armfw" && !HAVE_ARMFW) || (std::string(b) == "armctl" && !HAVE_ARMCTL)) continue;
    CHECK_EQUAL_TEXT(expected_machine(), elf_machine(root + "/usr/bin/" + b), b);
  }
}

TEST(Package, InstalledArmctlReadsInstalledModels) {
  if (!HAVE_ARMCTL) return;
  extract();
  const Cmd c = sh(servoarm::test::emulator_prefix() + "'" + root + "/usr/bin/armctl' kin fk --robot '" + root +
                   "/usr/share/servoarm/models/puma560.toml' 0 0 0 0 0 0");
  CHECK_EQUAL_TEXT(0, c.status, c.out.c_str());
}

TEST(Package, DefaultConfigAcceptedByArmfw) {
  if (!HAVE_ARMFW) return;
  extract();
  // The shipped config as it is (bus.can = "sim": virtual drives), for a short
  // loop run at normal priority: armfw refuses a config it cannot load (exit 2).
  const Cmd c = sh(servoarm::test::emulator_prefix() + "'" + root + "/usr/bin/armfw' --config '" + root +
                   "/etc/servoarm/armfw.toml' --priority 0 --bench-loop 0.3 </dev/null");
  CHECK_EQUAL_TEXT(0, c.status, c.out.c_str());
  STRCMP_CONTAINS("\"cycles\"", c.out.c_str());
  // Consoles a service can use: no stdin (it is /dev/null under systemd), a pty.
  const std::string conf = slurp(root + "/etc/servoarm/armfw.toml");
  STRCMP_CONTAINS("stdin = false", conf.c_str());
  STRCMP_CONTAINS("pty = true", conf.c_str());
  STRCMP_CONTAINS("can = \"sim\"", conf.c_str());
}

// servoarm-can-up with `ip` replaced by a stub that logs its arguments.
TEST_GROUP(CanUp) {
  std::string tmp, script = SOURCE_DIR "/toolchain/packaging/servoarm-can-up";
  void setup() override {
    char t[] = "/tmp/servoarm_canup_XXXXXX";
    CHECK(::mkdtemp(t) != nullptr);
    tmp = t;
    std::ofstream(tmp + "/ip") << "#!/bin/sh\necho \"ip $*\" >> \"" << tmp << "/ip.log\"\n";
    ::chmod((tmp + "/ip").c_str(), 0755);
  }
  void teardown() override { sh("rm -rf '" + tmp + "'"); }
  Cmd can_up(const std::string& conf_text, const std::string& env) {
    std::ofstream(tmp + "/armfw.toml") << conf_text;
    return sh("env -i PATH=/usr/bin:/bin SERVOARM_IP='" + tmp + "/ip' SERVOARM_CAN_WAIT_S=0 " + env + " sh '" + script +
              "' '" + tmp + "/armfw.toml'");
  }
  std::string log() { return slurp(tmp + "/ip.log"); }
};

TEST(CanUp, SimNeedsNoInterface) {
  const Cmd c = can_up("robot = \"puma560\"\n[bus]\ncan = \"sim\"\n", "");
  CHECK_EQUAL_TEXT(0, c.status, c.out.c_str());
  STRCMP_CONTAINS("no CAN interface to bring up", c.out.c_str());
  STRCMP_EQUAL("", log().c_str());
}

TEST(CanUp, MissingKeyMeansSim) {
  const Cmd c = can_up("robot = \"puma560\"\n", "");
  CHECK_EQUAL_TEXT(0, c.status, c.out.c_str());
  STRCMP_EQUAL("", log().c_str());
}

// "lo" stands in for can0: an interface that exists on every machine.
TEST(CanUp, BitrateAndRestartFromEnvironment) {
  const Cmd c = can_up("[loop]\ncan = \"wrong-section\"\n[bus]\nfirst_node = 1\ncan = \"lo\"   # the drives\n",
                    "SERVOARM_CAN_BITRATE=500000 SERVOARM_CAN_RESTART_MS=200");
  CHECK_EQUAL_TEXT(0, c.status, c.out.c_str());
  STRCMP_EQUAL("ip link set dev lo down\n"
               "ip link set dev lo type can bitrate 500000 restart-ms 200\n"
               "ip link set dev lo txqueuelen 128\n"
               "ip link set dev lo up\n",
               log().c_str());
}

TEST(CanUp, DefaultsAndDottedKey) {
  const Cmd c = can_up("bus.can = 'lo'\n", "");
  CHECK_EQUAL_TEXT(0, c.status, c.out.c_str());
  STRCMP_CONTAINS("type can bitrate 1000000 restart-ms 100\n", log().c_str());
}

TEST(CanUp, CanFd) {
  const Cmd c = can_up("[bus]\ncan = \"lo\"\n", "SERVOARM_CAN_DBITRATE=5000000");
  CHECK_EQUAL_TEXT(0, c.status, c.out.c_str());
  STRCMP_CONTAINS("type can bitrate 1000000 dbitrate 5000000 fd on restart-ms 100\n", log().c_str());
}

TEST(CanUp, InterfaceOverride) {
  const Cmd c = can_up("[bus]\ncan = \"sim\"\n", "SERVOARM_CAN_INTERFACE=lo");
  CHECK_EQUAL_TEXT(0, c.status, c.out.c_str());
  STRCMP_CONTAINS("ip link set dev lo up\n", log().c_str());
}

TEST(CanUp, MissingInterfaceFailsClearly) {
  const Cmd c = can_up("[bus]\ncan = \"can7\"\n", "");
  CHECK_EQUAL_TEXT(1, c.status, c.out.c_str());
  STRCMP_CONTAINS("no interface can7", c.out.c_str());
  STRCMP_EQUAL("", log().c_str());
}

TEST(CanUp, BadInterfaceNameRefused) {
  const Cmd c = can_up("[bus]\ncan = \"can0;reboot\"\n", "");
  CHECK_EQUAL_TEXT(2, c.status, c.out.c_str());
  STRCMP_CONTAINS("bad interface name", c.out.c_str());
  STRCMP_EQUAL("", log().c_str());
}

TEST(CanUp, SetupNoLeavesInterfaceAlone) {
  const Cmd c = can_up("[bus]\ncan = \"lo\"\n", "SERVOARM_CAN_SETUP=no");
  CHECK_EQUAL_TEXT(0, c.status, c.out.c_str());
  STRCMP_CONTAINS("configured elsewhere", c.out.c_str());
  STRCMP_EQUAL("", log().c_str());
}
