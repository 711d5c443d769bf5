// SPDX-License-Identifier: Apache-2.0
// armfw configuration: defaults valid, every key accepted, bad files refused naming the key,
// the value and the range; to_toml round trips (awkward strings too); the shipped
// armfw.toml and docs/configuration.md agree with the key tables.
#include <algorithm>
#include <chrono>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>
#include <toml.hpp>

#include "servoarm/config/config.hpp"
#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/kinematics/safety.hpp"
#include "text_regex.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm::fw;
namespace test = servoarm::test;

namespace {

bool has(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

std::string read_file(const std::string& path) {
  std::ifstream f(path);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

/// The repository's root, from the shipped config's path (".../toolchain/packaging/armfw.toml").
std::string source_root() {
  const std::string p = SERVOARM_SHIPPED_CONFIG;
  const std::string tail = "toolchain/packaging/armfw.toml";
  CHECK(p.size() > tail.size() && p.compare(p.size() - tail.size(), tail.size(), tail) == 0);
  return p.substr(0, p.size() - tail.size());
}

std::string write_temp(const std::string& text) {
  char path[] = "/tmp/fw_config_XXXXXX";
  const int fd = mkstemp(path);
  CHECK(fd >= 0);
  CHECK(write(fd, text.data(), text.size()) == static_cast<ssize_t>(text.size()));
  close(fd);
  return path;
}

/// "<origin>:<line>:<column>: " at the start of `e`.
bool starts_with_position(const std::string& e, const std::string& origin) {
  if (e.rfind(origin + ":", 0) != 0) return false;
  std::size_t i = origin.size() + 1;
  for (int field = 0; field < 2; ++field) {
    const std::size_t b = i;
    while (i < e.size() && e[i] >= '0' && e[i] <= '9') ++i;
    if (i == b || i >= e.size() || e[i] != ':') return false;
    ++i;
  }
  return e.compare(i, 1, " ") == 0;
}

/// A refused text: the error starts with the origin, the line and the column, names
/// every `parts`, and leaves the config as it was.
void expect_refused(const std::string& text, std::initializer_list<const char*> parts) {
  FwConfig c;
  c.rate_hz = 777;
  const std::string e = load_config_text(text, "bad.toml", c);
  bool ok = starts_with_position(e, "bad.toml") && e.find('\n') == std::string::npos;
  for (const char* p : parts) ok = ok && has(e, p);
  if (!ok) FAIL(("'" + text + "' gave '" + e + "'").c_str());
  DOUBLES_EQUAL(777, c.rate_hz, 0);  // untouched
}

void expect_accepted(const std::string& text) {
  FwConfig c;
  const std::string e = load_config_text(text, "good.toml", c);
  if (!e.empty()) FAIL(("'" + text + "' refused: '" + e + "'").c_str());
}

}  // namespace

TEST_GROUP(Config){};

TEST(Config, DefaultsAreValidAndRoundTrip) {
  FwConfig c;
  STRCMP_EQUAL("", validate(c).c_str());
  FwConfig d;
  d.rate_hz = 500;
  STRCMP_EQUAL("", load_config_text(to_toml(c), "rt", d).c_str());
  DOUBLES_EQUAL(1000.0, d.rate_hz, 0);
  CHECK(c == d);
  DOUBLES_EQUAL(600.0, c.max_move_duration_s, 0);  // the new key's default
  DOUBLES_EQUAL(100.0, c.sdo_timeout_ms, 0);  // the master's fixed 100 ms before the key
}

TEST(Config, FullFileAccepted) {
  FwConfig c;
  const std::string text =
      "robot = \"stanford\"\n[loop]\nrate_hz = 2000\npriority = 0\ncpu = 1\nlock_memory = false\n"
      "[bus]\ncan = \"vcan0\"\nfirst_node = 10\ncounts_per_rev = 4096\ngear_ratio = 50\nheartbeat_period_ms = 20\n"
      "heartbeat_timeout_ms = 60\nstart_timeout_s = 3\n[safety]\nfollowing_error_deg = 2.5\nenable_timeout_s = 1\n"
      "stop = \"drive\"\ndrive_stop_timeout_s = 1.5\n"
      "[motion]\nhome_deg = [0, 10, 0, 0, 0, 0]\njoint_speed_pct = 30\nlinear_speed_mm_s = 50\nmax_linear_speed_mm_s = 200\n"
      "max_move_duration_s = 120\n"
      "[console]\nstdin = false\npty = true\nserial = \"/dev/ttyS0\"\nbaud = 57600\n"
      "[[drive]]\nhoming.method = 19\n[[drive]]\nhoming.method = \"hard_stop\"\n[[drive]]\nhoming.method = 17\n"
      "[[drive]]\nhoming.method = \"absolute\"\n[[drive]]\nhoming.method = \"absolute\"\n"
      "[[drive]]\nhoming.method = \"absolute\"\n";  // a real bus: every joint's homing
  STRCMP_EQUAL("", load_config_text(text, "f.toml", c).c_str());
  STRCMP_EQUAL("stanford", c.robot.c_str());
  DOUBLES_EQUAL(2000, c.rate_hz, 0);
  LONGS_EQUAL(10, c.first_node);
  LONGS_EQUAL(6, c.home_deg.size());
  CHECK(c.console_pty);
  LONGS_EQUAL(57600, c.console_baud);
  STRCMP_EQUAL("drive", c.stop.c_str());
  DOUBLES_EQUAL(1.5, c.drive_stop_timeout_s, 0);
  DOUBLES_EQUAL(120, c.max_move_duration_s, 0);
}

// The file the package installs as /etc/servoarm/armfw.toml loads and validates
// (a typo there would keep the service from starting on the controller).
TEST(Config, ShippedConfigLoads) {
  FwConfig c;
  STRCMP_EQUAL("", load_config_file(SERVOARM_SHIPPED_CONFIG, c).c_str());
  STRCMP_EQUAL("", validate(c).c_str());
  STRCMP_EQUAL("sim", c.can.c_str());  // as shipped: virtual drives until bus.can is set
  STRCMP_EQUAL("ramp", c.stop.c_str());
}

// The shipped file against the key table: every key it sets or shows commented out is a
// key of the table (of its section, or of [[drive]]); every value it sets is the table's
// default except the choices made for a service (console on a pty, not stdin); every
// "lo..hi" range its comments give is the table's range.
TEST(Config, ShippedConfigAgreesWithTheKeyTable) {
  const std::string text = read_file(SERVOARM_SHIPPED_CONFIG);
  CHECK(text.size() > 500);
  // (and the files armfw writes in its state folder: /etc/servoarm is read-only to the service)
  const std::set<std::string> service_choices = {"console.stdin", "console.pty", "console.frames_file", "programs.dir",
                                                 "programs.points_file"};
  auto find_key = [](const std::string& full) -> const ConfigKey* {
    for (const ConfigKey& k : config_keys())
      if (full == k.name) return &k;
    return nullptr;
  };
  auto is_drive_key = [](const std::string& leaf) {
    for (const DriveKey& k : drive_keys())
      if (leaf == k.name) return true;
    return false;
  };
  const test::Regex section(R"(^\[([a-z_]+)\]\s*(#.*)?$)");
  const test::Regex assign(R"(^([a-z_]+)\s*=\s*([^#]*?)\s*(#(.*))?$)");
  const test::Regex commented(R"(^#\s*([a-z_]+)\s*=)");
  const test::Regex range(R"((-?[0-9.]+)\.\.(-?[0-9.]+))");
  std::istringstream is(text);
  std::string line, sec;
  int assignments = 0, ranges = 0, commented_keys = 0;
  FwConfig loaded;
  STRCMP_EQUAL("", load_config_file(SERVOARM_SHIPPED_CONFIG, loaded).c_str());
  const FwConfig defaults;
  while (std::getline(is, line)) {
    test::Groups m;
    if (!(m = section.match(line)).empty()) {
      sec = m[1];
      continue;
    }
    if (!(m = commented.search(line)).empty()) {
      const std::string leaf = m[1];
      const std::string full = sec.empty() ? leaf : sec + "." + leaf;
      if (!find_key(full) && !is_drive_key(leaf)) FAIL(("shipped file shows an unknown key: " + line).c_str());
      ++commented_keys;
      continue;
    }
    if ((m = assign.match(line)).empty()) continue;
    const std::string full = sec.empty() ? std::string(m[1]) : sec + "." + std::string(m[1]);
    const ConfigKey* k = find_key(full);
    if (!k) FAIL(("shipped file sets a key not in the table: " + full).c_str());
    ++assignments;
    const bool is_default = value_text(*k, loaded) == value_text(*k, defaults);
    if (!is_default && !service_choices.count(full))
      FAIL((full + " = " + value_text(*k, loaded) + " in the shipped file, but the table's default is " +
            default_text(*k) + " (change one of them, or list it as a service choice here)")
               .c_str());
    const std::string comment = m[4];
    test::Groups r;
    if (!(r = range.search(comment)).empty()) {
      ++ranges;
      const double lo = std::stod(r[1]), hi = std::stod(r[2]);
      if (lo != k->lo || hi != k->hi)
        FAIL((full + ": the shipped comment says " + std::string(r[0]) + ", the table " + range_text(*k)).c_str());
    }
  }
  CHECK(assignments >= 15);
  CHECK(ranges >= 2);
  CHECK(commented_keys >= 1);
  CHECK(!loaded.console_stdin && loaded.console_pty);  // the service choices themselves
  // servoarm.service's StateDirectory=servoarm (owned by the service user): the only writable place
  STRCMP_EQUAL("/var/lib/servoarm/programs", loaded.programs_dir.c_str());
  STRCMP_EQUAL("/var/lib/servoarm/points.toml", loaded.programs_points_file.c_str());
  STRCMP_EQUAL("/var/lib/servoarm/frames.toml", loaded.console_frames_file.c_str());
}

TEST(Config, BadFilesNameTheKeyAndLeaveConfigUntouched) {
  struct Case {
    const char* text;
    const char* must_contain;
  };
  const Case cases[] = {
      {"[loop]\nrate_hz = 100\n", "loop.rate_hz"},
      {"[loop]\nrate_hz = \"fast\"\n", "loop.rate_hz"},
      {"[loop]\nspeed = 1\n", "loop.speed"},
      {"[nosuch]\nx = 1\n", "nosuch"},
      {"[bus]\nfirst_node = 0\n", "bus.first_node"},
      {"[bus]\nheartbeat_timeout_ms = 10\n", "bus.heartbeat_timeout_ms"},
      {"[safety]\nfollowing_error_deg = -1\n", "safety.following_error_deg"},
      {"[safety]\nstop = \"coast\"\n", "safety.stop"},
      {"[safety]\nstop = 1\n", "safety.stop"},
      {"[safety]\ndrive_stop_timeout_s = 0\n", "safety.drive_stop_timeout_s"},
      {"[motion]\nhome_deg = [0, \"x\"]\n", "motion.home_deg[1]"},
      {"[motion]\nlinear_speed_mm_s = 900\n", "motion.linear_speed_mm_s"},
      {"[console]\nbaud = 12345\n", "console.baud"},
      {"[console]\npty = 1\n", "console.pty"},
      {"robot = 5\n", "robot"},
      {"[loop\nrate_hz = 1000\n", "not valid TOML"},
      {"[loop]\nrate_hz = nan\n", "loop.rate_hz"},
      {"drive = 5\n", "drive"},
      {"[[drive]]\nnode = 1\n[[drive]]\ndirection = 0\n", "drive[2].direction"},
      {"[[drive]]\nnosuch = 1\n", "drive[1].nosuch"},
      {"[[drive]]\nlimits = [1]\n", "drive[1].limits"},
      {"[[drive]]\nlimits = [10, -10]\n", "drive[1].limits"},
      {"[[drive]]\nzero_offset = 1.5\n", "drive[1].zero_offset"},
      {"[[drive]]\nzero_offset = 9000000000\n", "drive[1].zero_offset"},
      {"[[drive]]\nnode = 200\n", "drive[1].node"},
      {"[[drive]]\nheartbeat_timeout_ms = 5\n", "drive[1].heartbeat_timeout_ms"},
      {"[[drive]]\nquick_stop_decel = -1\n", "drive[1].quick_stop_decel"},
      {"[[drive]]\nquick_stop_decel = \"fast\"\n", "drive[1].quick_stop_decel"},
      // a key-shaped typo is refused, not ignored
      {"[motion]\nlinear_speed_mm = 5\n", "motion.linear_speed_mm: unknown key"},
      {"linear_speed_mm_s = 5\n", "linear_speed_mm_s: unknown key"},
      {"\"motion.linear_speed_mm_s\" = 5\n", "motion.linear_speed_mm_s: unknown key"},
      {"[[drive]]\ngear = 5\n", "drive[1].gear: unknown key"},
      {"motion = 5\n", "motion: expected a [motion] table"},
      {"[motion.extra]\nx = 1\n", "motion.extra: unknown key"},
      // a key or string holding a newline stays one line in the message (found by fuzzing)
      {"\"a\\nb\" = 1\n", "a\\nb: unknown key"},
      {"[safety]\nstop = \"co\\nast\"\n", "safety.stop"},
  };
  for (const Case& k : cases) expect_refused(k.text, {k.must_contain});
}

// Each range edge: the value just inside loads, the value just outside is refused naming the
// key, the value and the allowed range .
TEST(Config, RangeEdgesNameKeyValueAndRange) {
  // speeds: a move at 1e-300 mm/s never ends
  expect_accepted("[motion]\nlinear_speed_mm_s = 0.01\n");
  expect_refused("[motion]\nlinear_speed_mm_s = 1e-300\n", {"motion.linear_speed_mm_s", "1e-300", "[0.01, 5000]", "mm/s"});
  expect_refused("[motion]\nlinear_speed_mm_s = 0.0099\n", {"motion.linear_speed_mm_s", "0.0099"});
  expect_refused("[motion]\nlinear_speed_mm_s = 0\n", {"motion.linear_speed_mm_s"});
  expect_accepted("[motion]\nmax_linear_speed_mm_s = 0.01\nlinear_speed_mm_s = 0.01\n");
  expect_refused("[motion]\nmax_linear_speed_mm_s = 1e-300\n", {"motion.max_linear_speed_mm_s", "1e-300", "[0.01, 5000]"});
  expect_refused("[motion]\nmax_linear_speed_mm_s = 5000.5\n", {"motion.max_linear_speed_mm_s", "5000.5"});
  expect_refused("[motion]\nmax_linear_speed_mm_s = 50\n", {"motion.linear_speed_mm_s", "at most motion.max_linear_speed_mm_s (50)"});
  expect_accepted("[motion]\njoint_speed_pct = 1\n");
  expect_accepted("[motion]\njoint_speed_pct = 100\n");
  expect_refused("[motion]\njoint_speed_pct = 0.5\n", {"motion.joint_speed_pct", "0.5", "[1, 100]"});
  expect_refused("[motion]\njoint_speed_pct = 100.01\n", {"motion.joint_speed_pct", "100.01"});
  expect_accepted("[motion]\nmax_move_duration_s = 1\n");
  expect_accepted("[motion]\nmax_move_duration_s = 86400\n");
  expect_refused("[motion]\nmax_move_duration_s = 0.5\n", {"motion.max_move_duration_s", "0.5", "[1, 86400]", " s "});
  expect_refused("[motion]\nmax_move_duration_s = 86401\n", {"motion.max_move_duration_s", "86401"});
  // scaling: plausible and positive (direction carries the sign)
  expect_accepted("[bus]\ncounts_per_rev = 1\n");
  expect_accepted("[bus]\ncounts_per_rev = 2147483647\n");
  expect_refused("[bus]\ncounts_per_rev = 2147483648\n", {"bus.counts_per_rev", "2147483648", "[1, 2147483648)"});
  expect_refused("[bus]\ncounts_per_rev = 1e300\n", {"bus.counts_per_rev", "1e+300"});
  expect_refused("[bus]\ncounts_per_rev = 0.5\n", {"bus.counts_per_rev", "0.5"});
  expect_refused("[bus]\ncounts_per_rev = 0\n", {"bus.counts_per_rev"});
  expect_accepted("[bus]\ngear_ratio = 0.001\n");
  expect_accepted("[bus]\ngear_ratio = 100000\n");
  expect_refused("[bus]\ngear_ratio = 0\n", {"bus.gear_ratio", "(got 0)", "[0.001, 100000]"});
  expect_refused("[bus]\ngear_ratio = 1e-300\n", {"bus.gear_ratio", "1e-300"});
  expect_refused("[bus]\ngear_ratio = -50\n", {"bus.gear_ratio", "-50"});
  expect_refused("[bus]\ngear_ratio = 100001\n", {"bus.gear_ratio", "100001"});
  // per drive: the same ranges; 0 (= inherit the [bus] value) may not be written
  expect_accepted("[[drive]]\ngear_ratio = 0.001\ncounts_per_rev = 1\n");
  expect_refused("[[drive]]\ngear_ratio = 0\n", {"drive[1].gear_ratio", "not allowed", "bus.gear_ratio"});
  expect_refused("[[drive]]\ngear_ratio = -2\n", {"drive[1].gear_ratio", "-2"});
  expect_refused("[[drive]]\ngear_ratio = 1e-300\n", {"drive[1].gear_ratio", "1e-300"});
  expect_refused("[[drive]]\ncounts_per_rev = 0\n", {"drive[1].counts_per_rev", "not allowed"});
  expect_refused("[[drive]]\ncounts_per_rev = 1e300\n", {"drive[1].counts_per_rev", "1e+300"});
  expect_refused("[[drive]]\nnode = 0\n", {"drive[1].node", "not allowed"});
  expect_refused("[[drive]]\nnode = 128\n", {"drive[1].node", "1..127", "128"});
  // 0 = "the drive's own / the description's / the bus's" may be written where documented
  expect_accepted("[[drive]]\nmax_velocity = 0\nheartbeat_timeout_ms = 0\nquick_stop_decel = 0\n");
  expect_refused("[[drive]]\nmax_velocity = -1\n", {"drive[1].max_velocity", "-1"});
  expect_refused("[[drive]]\nzero_offset = 2147483648\n", {"drive[1].zero_offset", "2147483648"});
  expect_accepted("[[drive]]\nzero_offset = -2147483648\n");
  // CANopen master timeouts: positive and bounded, the boot wait within the bring-up's
  expect_accepted("[bus]\nsdo_timeout_ms = 1\nboot_timeout_ms = 0\nboot_retry_ms = 10\nstate_timeout_ms = 10\n");
  expect_accepted("[bus]\nsdo_timeout_ms = 10000\nstart_timeout_s = 120\nboot_timeout_ms = 120000\n");
  expect_refused("[bus]\nsdo_timeout_ms = 0\n", {"bus.sdo_timeout_ms", "(got 0)", "[1, 10000]", "ms"});
  expect_refused("[bus]\nsdo_timeout_ms = 10001\n", {"bus.sdo_timeout_ms", "10001"});
  expect_refused("[bus]\nsdo_timeout_ms = nan\n", {"bus.sdo_timeout_ms"});
  expect_refused("[bus]\nboot_timeout_ms = -1\n", {"bus.boot_timeout_ms", "-1"});
  expect_refused("[bus]\nboot_timeout_ms = 6000\n", {"bus.boot_timeout_ms", "at most bus.start_timeout_s (5 s)"});
  expect_refused("[bus]\nboot_retry_ms = 0\n", {"bus.boot_retry_ms", "(got 0)"});
  expect_refused("[bus]\nstate_timeout_ms = 5\n", {"bus.state_timeout_ms", "5", "[10, 60000]"});
  expect_refused("[bus]\nstate_timeout_ms = \"long\"\n", {"bus.state_timeout_ms"});
  // integers: out of the key's range, and out of int before narrowing
  expect_refused("[loop]\npriority = 100\n", {"loop.priority", "0..99", "100"});
  expect_refused("[loop]\npriority = 4294967377\n", {"loop.priority", "4294967377"});  // 2^32 + 81: 81 after narrowing
  expect_refused("[bus]\nfirst_node = -4294967295\n", {"bus.first_node"});
  expect_refused("[[drive]]\nnode = 4294967297\n", {"drive[1].node"});  // 2^32 + 1
  expect_refused("[loop]\ncpu = -2\n", {"loop.cpu", "-1..1023"});
  expect_refused("[loop]\npriority = 80.0\n", {"loop.priority", "expected an integer"});
  expect_refused("robot = \"\"\n", {"robot", "not empty"});
}

// Every numeric key, top level and per drive, refuses NaN and both infinities.
TEST(Config, EveryNumericKeyRefusesNonFinite) {
  int checked = 0;
  for (const char* bad : {"nan", "inf", "-inf", "+nan"}) {
    for (const ConfigKey& k : config_keys()) {
      const std::string name = k.name;
      const auto dot = name.find('.');
      const std::string sec = name.substr(0, dot), leaf = name.substr(dot + 1);
      std::string value = bad;
      if (std::holds_alternative<std::vector<double> FwConfig::*>(k.member)) value = std::string("[") + bad + "]";
      else if (!std::holds_alternative<double FwConfig::*>(k.member)) continue;
      expect_refused("[" + sec + "]\n" + leaf + " = " + value + "\n", {k.name});
      ++checked;
    }
    for (const DriveKey& k : drive_keys()) {
      std::string value = bad;
      if (std::holds_alternative<std::vector<double> DriveConfig::*>(k.member)) value = std::string("[0, ") + bad + "]";
      else if (!std::holds_alternative<double DriveConfig::*>(k.member)) continue;
      expect_refused(std::string("[[drive]]\n") + k.name + " = " + value + "\n", {(std::string("drive[1].") + k.name).c_str()});
      ++checked;
    }
  }
  CHECK(checked >= 4 * 20);
}

// validate() on a config built in code (App::build's path), not only through a file.
TEST(Config, ValidateNamesTheKeyOfAStructValue) {
  struct Case {
    void (*set)(FwConfig&);
    const char* want;
  };
  const Case cases[] = {
      {[](FwConfig& c) { c.linear_speed_mm_s = 1e-300; }, "motion.linear_speed_mm_s: must be within [0.01, 5000] mm/s (got 1e-300)"},
      {[](FwConfig& c) { c.max_move_duration_s = 1e9; }, "motion.max_move_duration_s"},
      {[](FwConfig& c) { c.gear_ratio = 0; }, "bus.gear_ratio"},
      {[](FwConfig& c) { c.gear_ratio = std::nan(""); }, "bus.gear_ratio: must be a finite number"},
      {[](FwConfig& c) { c.counts_per_rev = INFINITY; }, "bus.counts_per_rev: must be a finite number"},
      {[](FwConfig& c) { c.home_deg = {0, 1, NAN}; }, "motion.home_deg[2]: must be a finite number"},
      {[](FwConfig& c) { c.drives.resize(2); c.drives[1].gear_ratio = -3; }, "drive[2].gear_ratio: must be within"},
      {[](FwConfig& c) { c.drives.resize(1); c.drives[0].limits = {1, 2, 3}; }, "drive[1].limits: must hold 2 values"},
      {[](FwConfig& c) { c.console_can_rx_id = 0x581; }, "console.can_rx_id: collides with the CANopen SDOs"},
      {[](FwConfig& c) { c.stop = "coast"; }, "safety.stop: must be \"ramp\" or \"drive\" (got \"coast\")"},
  };
  for (const Case& k : cases) {
    FwConfig c;
    k.set(c);
    const std::string e = validate(c);
    CHECK_TEXT(has(e, k.want), (std::string(k.want) + " <- " + e).c_str());
  }
  FwConfig c;
  c.drives.resize(6);  // every drive field unset: inherits, valid
  STRCMP_EQUAL("", validate(c).c_str());
}

TEST(Config, EveryDocumentedKeyIsAccepted) {
  // Each documented key written with its documented default loads.
  CHECK(config_keys().size() >= 29);
  FwConfig c;
  STRCMP_EQUAL("", load_config_text(to_toml(c), "defaults", c).c_str());
  DriveConfig d;  // every optional [[drive]] field set, so to_toml writes them all
  d.node = 7;
  d.counts_per_rev = 4096;
  d.gear_ratio = 100;
  d.direction = -1;
  d.zero_offset = -12345;
  d.limits = {-90, 45};
  d.max_velocity = 30;
  d.heartbeat_timeout_ms = 200;
  d.quick_stop_decel = 720.5;
  d.homing_method = "19";  // a joint that homes: its homing.* keys are written too
  d.rated_torque = 0.64;
  d.collision_threshold = 12.5;
  d.sdo = {{0x6065, 0, "u32", 20000}, {0x607D, 1, "i32", -400000}};
  c.drives = {d, d};
  c.drives[1].node = 8;
  const std::string toml = to_toml(c);
  FwConfig back;
  STRCMP_EQUAL("", load_config_text(toml, "round-trip", back).c_str());
  LONGS_EQUAL(2, back.drives.size());
  LONGS_EQUAL(8, back.drives[1].node);
  LONGS_EQUAL(-1, back.drives[0].direction);
  LONGS_EQUAL(-12345, back.drives[0].zero_offset);
  DOUBLES_EQUAL(45, back.drives[0].limits[1], 0);
  DOUBLES_EQUAL(200, back.drives[1].heartbeat_timeout_ms, 0);
  DOUBLES_EQUAL(720.5, back.drives[1].quick_stop_decel, 0);
  CHECK(back == c);
  for (const ConfigKey& k : config_keys()) {
    const std::string name = k.name;
    const auto dot = name.find('.');
    const std::string leaf = dot == std::string::npos ? name : name.substr(dot + 1);
    if (!has(toml, "\n" + leaf + " = ") && toml.rfind(leaf + " = ", 0) != 0) FAIL(("key not in to_toml: " + name).c_str());
  }
  for (const DriveKey& k : drive_keys())
    if (!has(toml, std::string("\n") + k.name + " = ")) FAIL((std::string("drive key not in to_toml: ") + k.name).c_str());
  // an unset drive field is left out (writing `gear_ratio = 0` would not load back)
  FwConfig u;
  u.drives.resize(1);
  const std::string ut = to_toml(u);
  CHECK_TEXT(!has(ut, "\ngear_ratio = 0") && !has(ut, "\nnode = 0"), ut.c_str());
  FwConfig ub;
  STRCMP_EQUAL("", load_config_text(ut, "unset", ub).c_str());
  CHECK(ub == u);
}

// What `config` prints is valid TOML that reads back to the same configuration, whatever
// the strings hold: quotes, backslashes, newlines, tabs, control characters, UTF-8.
TEST(Config, ToTomlEscapesAwkwardStrings) {
  FwConfig c;
  c.robot = "/opt/arms/\"left\" arm\\v2\n\ttab\x01\x7f \xC3\xA9t\xC3\xA9 \xE2\x82\xAC.toml";
  c.can = "a\"b\\c";
  c.console_serial = "/dev/tty\"S0\"\r\n";
  c.console_can = "c'a\\n";
  c.drives.resize(6);  // a real bus: every joint's homing.method (here "absolute") written
  c.rate_hz = 400;     // six drives on a real bus at 1 Mbit/s: 1000 Hz would be refused (bus load)
  const std::string t = to_toml(c);
  // an independent reader of the text (toml11 directly, not our loader)
  std::istringstream is(t);
  const toml::value v = toml::parse(is, "to_toml");
  STRCMP_EQUAL(c.robot.c_str(), toml::find<std::string>(v, "robot").c_str());
  STRCMP_EQUAL(c.can.c_str(), toml::find<std::string>(v, "bus", "can").c_str());
  STRCMP_EQUAL(c.console_serial.c_str(), toml::find<std::string>(v, "console", "serial").c_str());
  STRCMP_EQUAL(c.console_can.c_str(), toml::find<std::string>(v, "console", "can").c_str());
  FwConfig back;
  STRCMP_EQUAL("", load_config_text(t, "awkward", back).c_str());
  CHECK(back == c);
  // bytes that are not UTF-8 cannot be TOML: written as U+FFFD, still valid TOML
  FwConfig b;
  b.robot = std::string("x\x80y\xC3", 4);
  FwConfig bb;
  STRCMP_EQUAL("", load_config_text(to_toml(b), "invalid-utf8", bb).c_str());
  STRCMP_EQUAL("x\xEF\xBF\xBDy\xEF\xBF\xBD", bb.robot.c_str());
}

// Seeded random configurations inside the ranges (chosen here, not read from the table)
// round trip exactly through to_toml and the loader.
TEST(Config, RandomConfigsRoundTrip) {
  std::mt19937_64 rng(20261201);
  auto u = [&](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); };
  auto i = [&](int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng); };
  for (int n = 0; n < 300; ++n) {
    FwConfig c;
    c.robot = "model_" + std::to_string(i(0, 1 << 30));
    c.rate_hz = u(250, 4000);
    c.priority = i(0, 99);
    c.cpu = i(-1, 1023);
    c.lock_memory = i(0, 1) == 1;
    c.can = i(0, 1) ? "sim" : "vcan" + std::to_string(i(0, 9));
    c.first_node = i(1, 127);
    c.counts_per_rev = u(1, 2147483647);
    c.gear_ratio = std::exp(u(std::log(1e-3), std::log(1e5)));
    c.heartbeat_period_ms = u(1, 1000);
    c.heartbeat_timeout_ms = c.heartbeat_period_ms * u(1.01, 10);
    c.start_timeout_s = u(0.001, 120);
    c.following_error_deg = u(0.001, 180);
    c.enable_timeout_s = u(0.001, 60);
    c.feedback_timeout_ms = u(1, 10000);
    c.stop = i(0, 1) ? "ramp" : "drive";
    c.drive_stop_timeout_s = u(0.05, 60);
    c.home_deg.clear();
    for (int j = i(0, 8); j > 0; --j) c.home_deg.push_back(u(-360, 360));
    c.max_linear_speed_mm_s = u(0.01, 5000);
    c.linear_speed_mm_s = u(0.01, c.max_linear_speed_mm_s);
    c.joint_speed_pct = u(1, 100);
    c.max_move_duration_s = u(1, 86400);
    c.console_stdin = i(0, 1) == 1;
    c.console_pty = i(0, 1) == 1;
    c.console_baud = 115200;
    for (int j = i(0, 6); j > 0; --j) {
      DriveConfig d;
      if (i(0, 1)) d.node = i(1, 127);
      if (i(0, 1)) d.counts_per_rev = u(1, 1e9);
      if (i(0, 1)) d.gear_ratio = u(1e-3, 1e5);
      d.direction = i(0, 1) ? 1 : -1;
      d.zero_offset = i(-2000000000, 2000000000);
      if (i(0, 1)) d.limits = {u(-300, -1), u(1, 300)};
      if (i(0, 1)) d.max_velocity = u(0.1, 1000);
      if (i(0, 1)) d.heartbeat_timeout_ms = c.heartbeat_period_ms * u(1.01, 5);
      if (i(0, 1)) d.quick_stop_decel = u(1, 1e6);
      c.drives.push_back(d);
    }
    if (c.drives.empty()) c.drives.resize(1);  // a real bus needs [[drive]] tables (their homing.method)
    STRCMP_EQUAL("", validate(c).c_str());
    FwConfig back;
    const std::string e = load_config_text(to_toml(c), "random", back);
    if (!e.empty() || !(back == c)) FAIL(("case " + std::to_string(n) + ": " + e + "\n" + to_toml(c)).c_str());
  }
}

// --config-keys lists every key with its default, range, unit and doc.
TEST(Config, ConfigKeysTextListsDefaultRangeUnitDoc) {
  const std::string t = config_keys_text();
  for (const ConfigKey& k : config_keys()) CHECK_TEXT(has(t, std::string(k.name) + " "), k.name);
  for (const DriveKey& k : drive_keys()) CHECK_TEXT(has(t, std::string("drive.") + k.name + " "), k.name);
  // written out here, independently of the table
  const test::Regex dur(R"(motion\.max_move_duration_s +default 600 +range \[1, 86400\]  unit s\n +longest move the console accepts)");
  CHECK_TEXT(!dur.search(t).empty(), t.c_str());
  const test::Regex gear(R"(drive\.gear_ratio +default bus\.gear_ratio +range \[0\.001, 100000\])");
  CHECK_TEXT(!gear.search(t).empty(), t.c_str());
  const test::Regex rx(R"(console\.can_rx_id +default 0x7E0 )");
  CHECK_TEXT(!rx.search(t).empty(), t.c_str());
  const test::Regex speed(R"(motion\.linear_speed_mm_s +default 100 +range \[0\.01, 5000\], at most motion\.max_linear_speed_mm_s  unit mm/s)");
  CHECK_TEXT(!speed.search(t).empty(), t.c_str());
}

// docs/configuration.md holds exactly what the key tables produce between its markers: a key
// added (or a range changed) without regenerating the page fails here, with the diff.
TEST(Config, ReferencePageIsGeneratedFromTheTable) {
  const std::string page = read_file(source_root() + "docs/configuration.md");
  CHECK(page.size() > 1000);
  const std::string why = config_reference_mismatch(page);
  if (!why.empty()) FAIL(why.c_str());
  // every key is on the page
  for (const ConfigKey& k : config_keys()) CHECK_TEXT(has(page, std::string("| `") + k.name + "` |"), k.name);
  for (const DriveKey& k : drive_keys()) CHECK_TEXT(has(page, std::string("| `drive.") + k.name + "` |"), k.name);
  // the check itself: a row the table does not have, a row missing, a changed range, no markers
  const std::string row = "| `motion.max_move_duration_s` |";
  const auto at = page.find(row);
  CHECK(at != std::string::npos);
  const auto eol = page.find('\n', at);
  std::string extra = page;
  extra.insert(eol + 1, "| `motion.new_key_s` | `1` | [0, 1] | s | a key added by hand |\n");
  const std::string e1 = config_reference_mismatch(extra);
  CHECK_TEXT(has(e1, "- line ") && has(e1, "motion.new_key_s") && has(e1, "regenerate"), e1.c_str());
  std::string missing = page;
  missing.erase(at, eol + 1 - at);  // as if the key had been added to the table only
  const std::string e2 = config_reference_mismatch(missing);
  CHECK_TEXT(has(e2, "+ " + row), e2.c_str());
  std::string changed = page;
  const auto r = changed.find("[1, 86400]", at);
  CHECK(r != std::string::npos && r < eol);
  changed.replace(r, 10, "[1, 86401]");
  CHECK(!config_reference_mismatch(changed).empty());
  CHECK(has(config_reference_mismatch("# no markers\n"), "markers"));
}

// Checks that need the robot (App::build has the chain): home pose within the joint limits,
// drive limits within the description's, scaling that fits the drives' 32-bit counts.
TEST(Config, ChecksAgainstTheRobot) {
  const servoarm::kin::LoadResult lr = servoarm::kin::load_robot("puma560");
  CHECK_TEXT(lr.ok, lr.error.c_str());
  const servoarm::kin::Chain& ch = lr.chain;  // joint 2: [-225, 45] deg, joint 5: [-100, 100]
  FwConfig c;
  STRCMP_EQUAL("", validate_for_chain(c, ch).c_str());
  c.home_deg = {0, -45, 180, 0, 45, 0};
  STRCMP_EQUAL("", validate_for_chain(c, ch).c_str());
  c.home_deg = {0, -45, 180, 0, 100, 0};  // at the limit: fine
  STRCMP_EQUAL("", validate_for_chain(c, ch).c_str());
  c.drives.resize(6);
  c.drives[1].homing_method = "hard_stop";
  c.drives[1].homing_offset = 45;  // an offset at the limit: fine
  c.drives[0].homing_offset = 1000;  // method "none": the offset is never used
  STRCMP_EQUAL("", validate_for_chain(c, ch).c_str());
  c.drives.clear();
  struct Case {
    void (*set)(FwConfig&);
    const char* want;
  };
  const Case cases[] = {
      {[](FwConfig& c) { c.home_deg = {0, 60, 0, 0, 0, 0}; }, "motion.home_deg[1]: 60 deg is outside joint 2's limits [-225, 45]"},
      {[](FwConfig& c) { c.home_deg = {0, 0, 0, 0, -100.5, 0}; }, "motion.home_deg[4]"},
      {[](FwConfig& c) { c.home_deg = {0, 0, 0}; }, "motion.home_deg: needs 6 values"},
      {[](FwConfig& c) { c.drives.resize(5); }, "drive: 5 [[drive]] tables"},
      {[](FwConfig& c) {  // narrowed by the drive's limits
         c.drives.resize(6);
         c.drives[1].limits = {-90, 0};
         c.home_deg = {0, 10, 0, 0, 0, 0};
       },
       "motion.home_deg[1]: 10 deg is outside joint 2's limits [-90, 0]"},
      {[](FwConfig& c) {
         c.drives.resize(6);
         c.drives[0].limits = {-170, 0};
       },
       "drive[1].limits: [-170, 0] reaches outside"},
      {[](FwConfig& c) {  // 2^31-1 counts/rev x 100 000: 266 deg is far beyond int32
         c.counts_per_rev = 2147483647;
         c.gear_ratio = 1e5;
       },
       "bus.counts_per_rev: joint 1's range [-160, 160] deg does not fit the drive's 32-bit position"},
      {[](FwConfig& c) {  // per drive, with its own zero offset
         c.drives.resize(6);
         c.drives[5].counts_per_rev = 1 << 24;  // 932 068 counts/deg: +-266 deg is +-2.48e8 counts, fits...
         c.drives[5].gear_ratio = 20;
         c.drives[5].zero_offset = 2000000000;   // ...but not from 2e9
       },
       "drive[6].counts_per_rev: joint 6's range"},
      {[](FwConfig& c) {  // 1 count per 1000 motor revolutions of gearing: 360 deg per count
         c.counts_per_rev = 1;
         c.gear_ratio = 1e-3;
       },
       "bus.counts_per_rev: one count is 360000 deg on joint 1, not finer than safety.following_error_deg (5)"},
      {[](FwConfig& c) { c.gear_ratio = std::nan(""); }, "bus.gear_ratio: must be a finite number"},
      {[](FwConfig& c) {  // a homed joint would stand at its offset: outside the description's limits
         c.drives.resize(6);
         c.drives[1].homing_method = "19";
         c.drives[1].homing_offset = 60;
       },
       "drive[2].homing.offset: 60 deg is outside joint 2's limits [-225, 45] deg"},
      {[](FwConfig& c) {  // hard_stop's backed-off point, outside the drive's narrowed limits
         c.drives.resize(6);
         c.drives[4].limits = {-90, 90};
         c.drives[4].homing_method = "hard_stop";
         c.drives[4].homing_offset = -95;
       },
       "drive[5].homing.offset: -95 deg is outside joint 5's limits [-90, 90] deg"},
      {[](FwConfig& c) {  // the default offset 0 outside [10, 40]: refused for a joint that homes
         c.drives.resize(6);
         c.drives[0].limits = {10, 40};
         c.drives[0].homing_method = "35";
       },
       "drive[1].homing.offset: 0 deg is outside joint 1's limits [10, 40] deg"},
  };
  for (const Case& k : cases) {
    FwConfig d;
    k.set(d);
    const std::string e = validate_for_chain(d, ch);
    CHECK_TEXT(has(e, k.want), (std::string(k.want) + " <- " + e).c_str());
  }
}

// --config FILE reads only a regular file of bounded size, naming the path and the reason;
// text that is not UTF-8 is refused before the TOML parser sees it.
TEST(Config, FileInputIsCheckedAndCapped) {
  FwConfig c;
  c.rate_hz = 777;
  std::string e = load_config_file("/tmp", c);
  CHECK_TEXT(has(e, "/tmp: is a directory"), e.c_str());
  e = load_config_file("/dev/zero", c);
  CHECK_TEXT(has(e, "/dev/zero: not a regular file"), e.c_str());
  e = load_config_file("/nonexistent/armfw.toml", c);
  CHECK_TEXT(has(e, "/nonexistent/armfw.toml: cannot open"), e.c_str());
  char fifo[] = "/tmp/fw_config_fifo_XXXXXX";
  CHECK(mkdtemp(fifo) != nullptr);
  const std::string fpath = std::string(fifo) + "/f";
  CHECK(mkfifo(fpath.c_str(), 0600) == 0);
  e = load_config_file(fpath, c);  // must not block waiting for a writer
  CHECK_TEXT(has(e, fpath + ": not a regular file"), e.c_str());
  unlink(fpath.c_str());
  rmdir(fifo);
  const std::string big = write_temp("# " + std::string(70000, 'x') + "\n");
  e = load_config_file(big, c);
  unlink(big.c_str());
  CHECK_TEXT(has(e, big + ": larger than 65536 bytes"), e.c_str());
  e = load_config_text("# " + std::string(70000, 'x') + "\n", "big.toml", c);
  CHECK_TEXT(has(e, "big.toml: larger than 65536 bytes"), e.c_str());
  const std::string ok = write_temp("[motion]\nmax_move_duration_s = 30\n");
  e = load_config_file(ok, c);
  unlink(ok.c_str());
  STRCMP_EQUAL("", e.c_str());
  DOUBLES_EQUAL(30, c.max_move_duration_s, 0);
  c.rate_hz = 777;
  // invalid UTF-8 inside a literal string (toml11 3.7.1 read past its buffer on it)
  e = load_config_text(std::string("robot = '\x80'\x00", 12), "u.toml", c);
  CHECK_TEXT(starts_with_position(e, "u.toml") && has(e, "utf-8"), e.c_str());
  e = load_config_text("a = 1\nrobot = \"\xC3\x28\"\n", "u.toml", c);
  CHECK_TEXT(has(e, "u.toml:2:") && has(e, "utf-8"), e.c_str());
  // nesting that overflowed toml11's recursive parser (SIGSEGV at 20 000 levels) is refused
  e = load_config_text("x = " + std::string(20000, '[') + "\n", "deep.toml", c);
  CHECK_TEXT(has(e, "deep.toml:1:") && has(e, "nested value depth of 32"), e.c_str());
  e = load_config_text("a = 1\n[motion]\nhome_deg = [[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[1]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]\n", "deep.toml", c);
  CHECK_TEXT(has(e, "deep.toml:3:") && has(e, "nested value depth"), e.c_str());
  // a value error names the line and the column of the value, and the key
  e = load_config_text("[loop]\n\nrate_hz = 100\n", "v.toml", c);
  CHECK_TEXT(e.rfind("v.toml:3:11: loop.rate_hz: ", 0) == 0, e.c_str());
  e = load_config_text("[[drive]]\n[[drive]]\n  gear_ratio = -2\n", "v.toml", c);
  CHECK_TEXT(e.rfind("v.toml:3:16: drive[2].gear_ratio: ", 0) == 0, e.c_str());
  e = load_config_text("[motion]\nhome_deg = [0, 1e300]\n", "v.toml", c);
  CHECK_TEXT(e.rfind("v.toml:2:", 0) == 0 && has(e, "motion.home_deg[1]"), e.c_str());
  DOUBLES_EQUAL(777, c.rate_hz, 0);
  // brackets inside strings and comments are not nesting
  const std::string brackets(40, '[');
  FwConfig s;
  STRCMP_EQUAL("", load_config_text("robot = \"" + brackets + "\" # " + brackets + "\n[console]\nserial = '" + brackets +
                                        "'\ncan = \"\"\"\\\"[\"\"\"\n",
                                    "strings.toml", s)
                       .c_str());
  STRCMP_EQUAL(brackets.c_str(), s.robot.c_str());
  STRCMP_EQUAL("\"[", s.console_can.c_str());
  // a syntax error names the line and the column
  e = load_config_text("[loop]\nrate_hz = 1000\n[loop\nx = 1\n", "syn.toml", c);
  CHECK_TEXT(e.rfind("syn.toml:3:", 0) == 0 && has(e, ": not valid TOML: "), e.c_str());
  e = load_config_text("[motion]\nhome_deg = [1, 2\n", "syn.toml", c);
  CHECK_TEXT(has(e, "syn.toml:2:") && has(e, ": not valid TOML: "), e.c_str());
  // a long array parses in linear time (toml11 3.7.1: quadratic; 600 kB took 55 s)
  auto parse_seconds = [&](int n) {
    std::string arr = "[motion]\nhome_deg = [";
    for (int i = 0; i < n; ++i) arr += i ? ",1" : "1";
    arr += "]\n";
    double best = 1e9;
    for (int rep = 0; rep < 3; ++rep) {
      const auto t0 = std::chrono::steady_clock::now();
      const std::string err = load_config_text(arr, "arr.toml", c);
      best = std::min(best, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
      CHECK_TEXT(has(err, "motion.home_deg"), err.c_str());
    }
    return best;
  };
  // A hang guard only (valgrind: 12-37 s): the time per element is not constant enough on a
  // shared machine to test linearity here (0.13 us to 16 000 elements, 0.77 us at 32 000
  // with -O2, memory effects); the figures and toml11's 2.2 s are in tests/bench/RESULTS.md.
  const double t30k = parse_seconds(30000);
  CHECK_TEXT(t30k < 120.0, (std::to_string(t30k) + " s for 30000 elements").c_str());
}

// Homing keys: per [[drive]] `homing.*` (a dotted key: the sub-table `homing`) and
// [homing]; bad input is refused at start naming the key. The expected texts are written here.
TEST(Config, HomingKeysAreReadAndBadOnesRefusedNamingTheKey) {
  const std::string six_drives_head = "[[drive]]\n";
  auto drives = [](const std::string& first) {
    std::string t = "[[drive]]\n" + first;
    for (int i = 0; i < 5; ++i) t += "[[drive]]\n";
    return t;
  };
  FwConfig c;
  STRCMP_EQUAL("", load_config_text(drives("homing.method = 19\nhoming.speed_switch = 12.5\nhoming.offset = -3\n"
                                           "homing.timeout_s = 4\n") +
                                        "[homing]\norder = [[3], [2], [1], [4, 5, 6]]\nunhomed_jog_pct = 20\n",
                                    "t.toml", c)
                       .c_str());
  LONGS_EQUAL(6, c.drives.size());
  STRCMP_EQUAL("19", c.drives[0].homing_method.c_str());
  DOUBLES_EQUAL(12.5, c.drives[0].homing_speed_switch, 0);
  DOUBLES_EQUAL(-3, c.drives[0].homing_offset, 0);
  DOUBLES_EQUAL(4, c.drives[0].homing_timeout_s, 0);
  STRCMP_EQUAL("none", c.drives[1].homing_method.c_str());  // the default: an absolute encoder
  CHECK((c.homing_order == std::vector<std::vector<int>>{{3}, {2}, {1}, {4, 5, 6}}));
  DOUBLES_EQUAL(20, c.homing_unhomed_jog_pct, 0);
  // the effective configuration writes the method as a number and loads back to the same
  const std::string t = to_toml(c);
  CHECK_TEXT(t.find("homing.method = 19\n") != std::string::npos, t.c_str());
  CHECK_TEXT(t.find("order = [[3], [2], [1], [4, 5, 6]]\n") != std::string::npos, t.c_str());
  FwConfig back;
  STRCMP_EQUAL("", load_config_text(t, "back.toml", back).c_str());
  CHECK(back == c);
  // "none" and "hard_stop" as strings, and the string form of a number
  FwConfig h;
  STRCMP_EQUAL("", load_config_text(drives("homing.method = \"hard_stop\"\nhoming.direction = 1\n"), "h.toml", h).c_str());
  STRCMP_EQUAL("hard_stop", h.drives[0].homing_method.c_str());
  STRCMP_EQUAL("", load_config_text(drives("homing.method = \"35\"\n"), "h.toml", h).c_str());
  // refusals, each naming its key
  const struct {
    std::string text;
    const char* want;
  } bad[] = {
      {drives("homing.method = 36\n"), "drive[1].homing.method: must be \"absolute\", \"hard_stop\" or a CiA 402 homing method"},
      {drives("homing.method = 0\n"), "drive[1].homing.method: must be"},
      {drives("homing.method = 40\n"), "(got 40)"},
      {drives("homing.method = -129\n"), "drive[1].homing.method"},
      {drives("homing.method = \"switch\"\n"), "(got switch)"},
      {drives("homing.method = 1.5\n"), "drive[1].homing.method: expected a string or an integer"},
      {drives("homing.speed_switch = 0\n"), "drive[1].homing.speed_switch: must be within (0, 1000000]"},
      {drives("homing.speed_switch = -5\n"), "drive[1].homing.speed_switch: must be within"},
      {drives("homing.speed_zero = nan\n"), "drive[1].homing.speed_zero: must be a finite number"},
      {drives("homing.speed_zero = 0\n"), "drive[1].homing.speed_zero"},
      {drives("homing.timeout_s = 0\n"), "drive[1].homing.timeout_s: must be within (0, 3600]"},
      {drives("homing.acceleration = 0\n"), "drive[1].homing.acceleration"},
      {drives("homing.backoff = 0\n"), "drive[1].homing.backoff"},
      {drives("homing.direction = 0\n"), "drive[1].homing.direction: must be one of 1, -1"},
      {drives("homing.bogus = 1\n"), "drive[1].homing.bogus: unknown key"},
      {"[homing]\norder = [[1, 2], [2, 3, 4, 5, 6]]\n", "homing.order: joint 2 is named twice"},
      {"[homing]\norder = [[1], []]\n", "homing.order[1]: an empty group"},
      {"[homing]\norder = [[0, 1]]\n", "homing.order[0]: must be within [1, 8]"},
      {"[homing]\norder = [1, 2]\n", "homing.order[0]: expected an array of joint numbers"},
      {"[homing]\nunhomed_jog_pct = 0\n", "homing.unhomed_jog_pct: must be within [1, 100]"},
  };
  for (const auto& b : bad) {
    FwConfig k;
    const std::string e = load_config_text(b.text, "bad.toml", k);
    CHECK_TEXT(e.find(b.want) != std::string::npos, ("wanted '" + std::string(b.want) + "' in: " + e).c_str());
    CHECK_TEXT(k == FwConfig{}, b.want);  // untouched
  }
  (void)six_drives_head;
  // the robot's checks: every joint named once when the order is given
  const servoarm::kin::LoadResult lr = servoarm::kin::load_robot("puma560");
  CHECK_TEXT(lr.ok, lr.error.c_str());
  FwConfig o;
  o.homing_order = {{3}, {2}, {1}, {4, 5, 6}};
  STRCMP_EQUAL("", validate_for_chain(o, lr.chain).c_str());
  o.homing_order = {{3}, {2}, {1}, {4, 5}};
  STRCMP_EQUAL("homing.order: joint 6 is missing (name every joint once, or leave the key out)",
               validate_for_chain(o, lr.chain).c_str());
  o.homing_order = {{3}, {2}, {1}, {4, 5, 6, 7}};
  STRCMP_EQUAL("homing.order[3]: joint 7 does not exist (puma560 has 6)", validate_for_chain(o, lr.chain).c_str());
}

// Issue 20: the [dynamics] keys, drive.rated_torque and drive.collision_threshold, and the
// default blend tolerances (motion.default_blend_mm / _deg): defaults keep every part off (the
// frames of before), values read, bad ones refused naming the key and the range.
TEST(Config, DynamicsAndBlendKeysAreReadAndBadOnesRefusedNamingTheKey) {
  const FwConfig def;
  STRCMP_EQUAL("off", def.feed_forward.c_str());
  CHECK(!def.collision && !def.freedrive);
  DOUBLES_EQUAL(100, def.collision_gain, 0);
  DOUBLES_EQUAL(1, def.collision_sensitivity, 0);
  DOUBLES_EQUAL(15, def.collision_threshold_pct, 0);
  DOUBLES_EQUAL(10, def.freedrive_damping, 0);
  DOUBLES_EQUAL(0, def.default_blend_mm, 0);
  DOUBLES_EQUAL(0, def.default_blend_deg, 0);
  DOUBLES_EQUAL(0, DriveConfig{}.rated_torque, 0);
  DOUBLES_EQUAL(0, DriveConfig{}.collision_threshold, 0);
  auto drives = [](const std::string& first) {
    std::string t = "[[drive]]\n" + first;
    for (int i = 0; i < 5; ++i) t += "[[drive]]\n";
    return t;
  };
  FwConfig c;
  STRCMP_EQUAL("", load_config_text("[dynamics]\nfeed_forward = \"torque\"\ncollision = true\ncollision_gain = 50\n"
                                    "collision_sensitivity = 2\ncollision_threshold_pct = 20\nfreedrive = true\n"
                                    "freedrive_damping = 5\n[motion]\ndefault_blend_mm = 2.5\ndefault_blend_deg = 3\n" +
                                        drives("rated_torque = 0.64\ncollision_threshold = 12.5\n"),
                                    "d.toml", c)
                   .c_str());
  STRCMP_EQUAL("torque", c.feed_forward.c_str());
  CHECK(c.collision && c.freedrive);
  DOUBLES_EQUAL(50, c.collision_gain, 0);
  DOUBLES_EQUAL(2, c.collision_sensitivity, 0);
  DOUBLES_EQUAL(20, c.collision_threshold_pct, 0);
  DOUBLES_EQUAL(5, c.freedrive_damping, 0);
  DOUBLES_EQUAL(2.5, c.default_blend_mm, 0);
  DOUBLES_EQUAL(3, c.default_blend_deg, 0);
  DOUBLES_EQUAL(0.64, c.drives[0].rated_torque, 0);
  DOUBLES_EQUAL(12.5, c.drives[0].collision_threshold, 0);
  DOUBLES_EQUAL(0, c.drives[1].rated_torque, 0);  // unset: the drive's 6076h
  FwConfig back;
  const std::string t = to_toml(c);
  CHECK_TEXT(has(t, "[dynamics]\nfeed_forward = \"torque\"\n"), t.c_str());
  STRCMP_EQUAL("", load_config_text(t, "back.toml", back).c_str());
  CHECK(back == c);
  STRCMP_EQUAL("", load_config_text("[dynamics]\nfeed_forward = \"velocity\"\nfreedrive_damping = 0\n", "v.toml", c).c_str());
  const struct {
    std::string text;
    const char* want;
  } bad[] = {
      {"[dynamics]\nfeed_forward = \"model\"\n", "dynamics.feed_forward: must be \"off\", \"velocity\" or \"torque\" (got \"model\")"},
      {"[dynamics]\nfeed_forward = true\n", "dynamics.feed_forward: expected a string"},
      {"[dynamics]\ncollision = 1\n", "dynamics.collision: expected true or false"},
      {"[dynamics]\ncollision_gain = 0\n", "dynamics.collision_gain: must be within [1, 1000] 1/s (got 0)"},
      {"[dynamics]\ncollision_gain = 5000\n", "dynamics.collision_gain: must be within [1, 1000]"},
      {"[dynamics]\ncollision_sensitivity = 0\n", "dynamics.collision_sensitivity: must be within [0.1, 10] (got 0)"},
      {"[dynamics]\ncollision_sensitivity = nan\n", "dynamics.collision_sensitivity: must be a finite number"},
      {"[dynamics]\ncollision_threshold_pct = 0\n", "dynamics.collision_threshold_pct: must be within [1, 300] %"},
      // a threshold every residual's noise passes: `enable` would fault at once
      {"[dynamics]\ncollision_threshold_pct = 1e-9\n", "dynamics.collision_threshold_pct: must be within [1, 300] % (got 1e-09)"},
      {"[dynamics]\ncollision_threshold_pct = 0.99\n", "dynamics.collision_threshold_pct: must be within [1, 300]"},
      {drives("collision_threshold = 1e-9\n"), "drive[1].collision_threshold: must be within [0.01, 1000000] N m (N)"},
      {"[dynamics]\nfreedrive_damping = -1\n", "dynamics.freedrive_damping: must be within [0, 100] 1/s (got -1)"},
      {"[dynamics]\nfreedrive = \"yes\"\n", "dynamics.freedrive: expected true or false"},
      {"[dynamics]\nbogus = 1\n", "dynamics.bogus: unknown key"},
      {"[motion]\ndefault_blend_mm = 51\n", "motion.default_blend_mm: must be within [0, 50] mm (got 51)"},
      {"[motion]\ndefault_blend_mm = -0.5\n", "motion.default_blend_mm: must be within [0, 50]"},
      {"[motion]\ndefault_blend_deg = 31\n", "motion.default_blend_deg: must be within [0, 30] deg (got 31)"},
      {drives("rated_torque = -1\n"), "drive[1].rated_torque: must be within (0, 100000] N m (N) (got -1)"},
      {drives("collision_threshold = -2\n"), "drive[1].collision_threshold: must be within [0.01, 1000000] N m (N)"},
      {drives("collision_threshold = inf\n"), "drive[1].collision_threshold: must be a finite number"},
  };
  for (const auto& b : bad) {
    FwConfig k;
    const std::string e = load_config_text(b.text, "bad.toml", k);
    CHECK_TEXT(starts_with_position(e, "bad.toml"), e.c_str());
    CHECK_TEXT(e.find(b.want) != std::string::npos, ("wanted '" + std::string(b.want) + "' in: " + e).c_str());
    CHECK_TEXT(k == FwConfig{}, b.want);  // untouched
  }
}

// [[output]]: name, node and bit are required (a missing one is refused naming it), and the
// bits CiA 402 reserves in 60FEh:01 (0 = set brake, 1..15 reserved by the profile) are refused:
// an output may only be one of the manufacturer-specific bits 16..31.
TEST(Config, OutputKeysAreRequiredAndProfileBitsRefused) {
  const std::string head = "[[output]]\nname = \"gripper\"\nnode = 6\n";
  FwConfig c;
  STRCMP_EQUAL("", load_config_text(head + "bit = 16\n", "o.toml", c).c_str());
  LONGS_EQUAL(16, c.outputs.at(0).bit);
  STRCMP_EQUAL("", load_config_text(head + "bit = 31\n", "o.toml", c).c_str());
  LONGS_EQUAL(31, c.outputs.at(0).bit);
  const struct {
    std::string text;
    const char* want;
  } bad[] = {
      {head, "output[1].bit: missing"},
      {"[[output]]\nnode = 6\nbit = 16\n", "output[1].name: missing"},
      {"[[output]]\nname = \"gripper\"\nbit = 16\n", "output[1].node: missing"},
      {head + "bit = 0\n", "output[1].bit: must be within 16..31"},
      {head + "bit = 1\n", "output[1].bit: must be within 16..31"},
      {head + "bit = 15\n", "output[1].bit: must be within 16..31"},
      {head + "bit = 32\n", "output[1].bit: must be within 16..31"},
      {head + "bit = 16\n[[output]]\nname = \"lamp\"\nnode = 6\n", "output[2].bit: missing"},
  };
  for (const auto& b : bad) {
    FwConfig k;
    const std::string e = load_config_text(b.text, "bad.toml", k);
    CHECK_TEXT(starts_with_position(e, "bad.toml") && e.find('\n') == std::string::npos, e.c_str());
    CHECK_TEXT(has(e, b.want), ("wanted '" + std::string(b.want) + "' in: " + e).c_str());
    CHECK_TEXT(k == FwConfig{}, b.want);  // untouched
  }
  // the brake bit set in code (App::build validates the same way)
  FwConfig s;
  s.outputs = {{"lamp", 6, 0}};
  STRCMP_EQUAL("output[1].bit: must be within 16..31 (got 0)", validate(s).c_str());
  // the reference says why the low bits are refused
  const std::string ref = config_reference_markdown();
  CHECK_TEXT(has(ref, "\"set brake\"") && has(ref, "bits 1..15"), ref.c_str());
}

// homing.travel_margin_deg: how far beyond its range a homing joint may travel before the homing
// fails (hal::HomingSpec::max_travel = range + margin). Found through the key table (the
// firmware builds the homing from it), default, range and unit documented, bad values refused.
TEST(Config, HomingTravelMarginKeyIsInTheTable) {
  const ConfigKey* k = nullptr;
  for (const ConfigKey& e : config_keys())
    if (std::string(e.name) == "homing.travel_margin_deg") k = &e;
  CHECK_TEXT(k != nullptr, "no homing.travel_margin_deg in the key table");
  STRCMP_EQUAL("deg (mm)", k->unit);
  STRCMP_EQUAL("10", default_text(*k).c_str());
  STRCMP_EQUAL("(0, 1000]", range_text(*k).c_str());
  FwConfig c;
  STRCMP_EQUAL("", load_config_text("[homing]\ntravel_margin_deg = 25\n", "m.toml", c).c_str());
  STRCMP_EQUAL("25", value_text(*k, c).c_str());
  for (const char* bad : {"0", "-1", "1001", "\"10\"", "nan"}) {
    FwConfig b;
    const std::string e = load_config_text(std::string("[homing]\ntravel_margin_deg = ") + bad + "\n", "bad.toml", b);
    CHECK_TEXT(starts_with_position(e, "bad.toml") && has(e, "homing.travel_margin_deg: "), e.c_str());
  }
}

// A number TOML cannot hold (1e400 overflows a double) is refused naming its file, line, column
// and key, like any other bad value: in a section, at the top level, in a [[drive]] table and
// in a list.
TEST(Config, AnUnrepresentableNumberIsRefusedNamingItsKey) {
  const struct {
    const char* text;
    const char* key;
  } cases[] = {
      {"[loop]\nrate_hz = 1e400\n", ": loop.rate_hz: "},
      {"[motion]\n# park pose\nhome_deg = [0, -1e400, 0, 0, 0, 0]\n", ": motion.home_deg: "},
      {"[[drive]]\n[[drive]]\ngear_ratio = 1e400\n", ": drive[2].gear_ratio: "},
      {"[[drive]]\nhoming.speed_switch = 1e400\n", ": drive[1].homing.speed_switch: "},
      {"[dynamics]\n  collision_gain=1e400 # big\n", ": dynamics.collision_gain: "},
  };
  for (const auto& k : cases) {
    FwConfig c;
    const std::string e = load_config_text(k.text, "bad.toml", c);
    CHECK_TEXT(starts_with_position(e, "bad.toml") && has(e, k.key) && e.find('\n') == std::string::npos,
               ("wanted '" + std::string(k.key) + "' in: " + e).c_str());
    CHECK_TEXT(k.key[2] == 'd' || has(e, "1e400"), e.c_str());
  }
}

// A real bus (bus.can not "sim"): every joint says how it finds its zero. Each [[drive]] needs
// homing.method ("absolute" for an absolute encoder), and [[drive]] tables are needed at all:
// without them an arm of incremental encoders would count as homed at power-up. "sim" keeps its
// absolute virtual encoders without any.
TEST(Config, ARealBusNeedsEveryDrivesHomingMethod) {
  auto drives = [](const std::string& each, int n = 6) {
    std::string t;
    for (int i = 0; i < n; ++i) t += "[[drive]]\n" + each;
    return t;
  };
  const std::string can0 = "[bus]\ncan = \"can0\"\n";
  FwConfig c;
  STRCMP_EQUAL("", load_config_text(can0 + drives("homing.method = \"absolute\"\n"), "a.toml", c).c_str());
  STRCMP_EQUAL("none", c.drives[0].homing_method.c_str());  // what the firmware reads as "no homing"
  const std::string t = to_toml(c);
  CHECK_TEXT(has(t, "homing.method = \"absolute\"\n"), t.c_str());
  FwConfig back;
  STRCMP_EQUAL("", load_config_text(t, "back.toml", back).c_str());
  CHECK(back == c);
  STRCMP_EQUAL("", load_config_text(can0 + drives("homing.method = 19\n"), "a.toml", c).c_str());
  // sim: no [[drive]] tables, or tables without a method, are absolute virtual encoders
  STRCMP_EQUAL("", load_config_text("[bus]\ncan = \"sim\"\n" + drives("gear_ratio = 2\n"), "s.toml", c).c_str());
  STRCMP_EQUAL("", load_config_text("[bus]\ncan = \"sim\"\n", "s.toml", c).c_str());
  const struct {
    std::string text;
    const char* want;
  } bad[] = {
      {can0 + drives("gear_ratio = 2\n"), "drive[1].homing.method: missing"},
      {can0 + drives("homing.method = 19\n", 2) + drives("gear_ratio = 2\n", 4), "drive[3].homing.method: missing"},
      {can0, "drive: bus.can = \"can0\" is a real bus"},
      {"[bus]\ncan = \"vcan0\"\n", "homing.method"},
  };
  for (const auto& b : bad) {
    FwConfig k;
    const std::string e = load_config_text(b.text, "bad.toml", k);
    CHECK_TEXT(starts_with_position(e, "bad.toml") && e.find('\n') == std::string::npos, e.c_str());
    CHECK_TEXT(has(e, b.want), ("wanted '" + std::string(b.want) + "' in: " + e).c_str());
  }
}

// Bus load (docs/deployment.md#bus-load). Hand count, worst-case stuffing (hal/bus_load.hpp):
// SYNC 55 bits, a 6-byte PDO 115, a heartbeat 65. Six drives at 1 Mbit/s: per cycle
// 55 + 12 x 115 = 1435 bits; heartbeats 6 x 20/s x 65 = 7800 bit/s.
namespace {
std::string real_bus(int drives, const std::string& extra_bus = "", const std::string& loop = "") {
  std::string t = (loop.empty() ? "" : "[loop]\n" + loop) + "[bus]\ncan = \"can0\"\n" + extra_bus;
  for (int i = 0; i < drives; ++i) t += "[[drive]]\nhoming.method = \"absolute\"\n";
  return t;
}
}  // namespace

TEST(Config, BusLoadAboveTheLimitIsRefusedNamingRateFramesAndLoad) {
  FwConfig c;
  // 1000 Hz: 1.435 + 0.0078 = 144.3 %; at most (0.85 - 0.0078) / 0.001435 = 586.9 Hz fits.
  const std::string e = load_config_text(real_bus(6, "", "rate_hz = 1000\n"), "b.toml", c);
  CHECK_TEXT(e.find('\n') == std::string::npos, e.c_str());
  for (const char* part : {"b.toml:", "loop.rate_hz", "144.3 %", "bus.bitrate 1000000 bit/s", "loop.rate_hz 1000",
                           "6 drives", "13 frames per cycle: SYNC, 6 RPDO1, 6 TPDO1", "above 85 %", "at most 586 Hz"})
    CHECK_TEXT(has(e, part), ("wanted '" + std::string(part) + "' in: " + e).c_str());
  // TPDO2 asked for at 400 Hz: (55 + 18 x 115) x 400 + 7800 = 857800 bit/s: 85.8 %.
  const std::string e2 = load_config_text(real_bus(6, "tpdo2 = true\n", "rate_hz = 400\n"), "b.toml", c);
  CHECK_TEXT(has(e2, "85.8 %") && has(e2, "19 frames per cycle: SYNC, 6 RPDO1, 6 TPDO1, 6 TPDO2"), e2.c_str());
  // 500 kbit/s halves the room: 400 Hz is 2 x (0.574 + 0.0078) = 116.4 %.
  const std::string e3 = load_config_text(real_bus(6, "bitrate = 500000\n", "rate_hz = 400\n"), "b.toml", c);
  CHECK_TEXT(has(e3, "116.4 %") && has(e3, "bus.bitrate 500000 bit/s"), e3.c_str());
  // not checked: the in-process bus and a vcan carry no bits on a wire
  FwConfig s;
  STRCMP_EQUAL("", load_config_text("[loop]\nrate_hz = 4000\n[bus]\ncan = \"sim\"\n[[drive]]\n[[drive]]\n[[drive]]\n"
                                    "[[drive]]\n[[drive]]\n[[drive]]\n", "s.toml", s).c_str());
  std::string vt = real_bus(6, "", "rate_hz = 1000\n");
  vt.replace(vt.find("\"can0\""), 6, "\"vcan0\"");
  FwConfig v;
  STRCMP_EQUAL("", load_config_text(vt, "v.toml", v).c_str());
  STRCMP_EQUAL("vcan0", v.can.c_str());
  CHECK_FALSE(bus_load_checked(v));
}

TEST(Config, BusLoadAboveSixtyPercentIsWarned) {
  FwConfig c;
  // 500 Hz: 0.7175 + 0.0078 = 72.5 %: accepted, with a warning; (0.6 - 0.0078) / 0.001435 = 412.7 Hz.
  STRCMP_EQUAL("", load_config_text(real_bus(6, "", "rate_hz = 500\n"), "w.toml", c).c_str());
  const std::string w = bus_load_warning(c, 6);
  CHECK_TEXT(has(w, "72.5 %") && has(w, "above 60 %") && has(w, "412 Hz") && w.find('\n') == std::string::npos,
             w.c_str());
  STRCMP_EQUAL("", bus_load_problem(c, 6).c_str());
  c.rate_hz = 400;  // 57.4 + 0.78 = 58.2 %
  STRCMP_EQUAL("", bus_load_warning(c, 6).c_str());
}

TEST(Config, ARealBusWithoutARateGetsOneTheBusCarries) {
  FwConfig c;
  // 6 drives: 1000 (144 %), 800 (115 %), 500 (72.5 %) are above 60 %; 400 Hz: 58.2 %.
  STRCMP_EQUAL("", load_config_text(real_bus(6), "r.toml", c).c_str());
  DOUBLES_EQUAL(400, c.rate_hz, 0);
  FwConfig back;
  STRCMP_EQUAL("", load_config_text(to_toml(c), "back.toml", back).c_str());
  CHECK(back == c);
  // 3 drives: 55 + 6 x 115 = 745 bits per cycle + 3900 bit/s: 800 Hz is 59.99 %.
  STRCMP_EQUAL("", load_config_text(real_bus(3), "r.toml", c).c_str());
  DOUBLES_EQUAL(800, c.rate_hz, 0);
  // the simulated bus keeps the 1 kHz of the key table
  FwConfig s;
  STRCMP_EQUAL("", load_config_text("[bus]\ncan = \"sim\"\n", "s.toml", s).c_str());
  DOUBLES_EQUAL(1000, s.rate_hz, 0);
  // the default frames: no TPDO2
  CHECK_FALSE(FwConfig{}.tpdo2);
  LONGS_EQUAL(0, bus_traffic(FwConfig{}, 6).tpdo2_len);
}

// docs/deployment.md's table of load by rate and joint count is the calculation's own output.
TEST(Config, DeploymentPageBusLoadTableIsTheCalculation) {
  const std::string page = read_file(source_root() + "docs/deployment.md");
  const std::string why = bus_load_reference_mismatch(page);
  STRCMP_EQUAL("", why.c_str());
  // and the table says what the hand count says: 6 drives at 1000 Hz on 1 Mbit/s, 144.3 %
  CHECK_TEXT(has(bus_load_reference_markdown(), "| 58.2 % | 72.5 % warned | 115.6 % refused | 144.3 % refused | 287.8 % refused |"),
             bus_load_reference_markdown().c_str());
}

// The shipped file switched to a real bus, as its comments tell a user to (bus.can = "can0"
// and one [[drive]] table per joint of the PUMA 560), loads at a rate the bus carries:
// 6 drives at 1 Mbit/s, (55 + 12 x 115) x 400 + 7800 bit/s = 58.2 % at 400 Hz.
TEST(Config, ShippedConfigOnARealBusFits) {
  std::string text = read_file(SERVOARM_SHIPPED_CONFIG);
  const std::string sim = "\ncan = \"sim\"";  // [bus]'s own line, not a comment naming it
  const std::size_t at = text.find(sim);
  CHECK(at != std::string::npos);
  text.replace(at, sim.size(), "\ncan = \"can0\"");
  for (int i = 0; i < 6; ++i) text += "[[drive]]\nhoming.method = \"absolute\"\n";
  FwConfig c;
  STRCMP_EQUAL("", load_config_text(text, "armfw.toml", c).c_str());
  STRCMP_EQUAL("can0", c.can.c_str());
  DOUBLES_EQUAL(400, c.rate_hz, 0);
  STRCMP_EQUAL("", bus_load_warning(c, 6).c_str());
}

// armfw --bus-load's table: one column layout for the frames and the sums (the longest
// label, "from drives", included), whatever the traffic.
TEST(Config, BusLoadTableColumnsLineUp) {
  FwConfig c;
  c.can = "can0";
  c.tpdo2 = true;
  c.collision = true;
  c.feed_forward = "torque";
  c.outputs.resize(1);
  c.outputs[0].node = 1;
  const std::string t = bus_load_table(c, 6);
  std::vector<std::string> lines;
  for (std::size_t a = 0; a < t.size();) {
    const std::size_t n = t.find('\n', a);
    lines.push_back(t.substr(a, n - a));
    a = n + 1;
  }
  // a title line, the column heads, the frames, three sums, the verdict
  CHECK_TEXT(lines.size() >= 10, t.c_str());
  const std::size_t width = lines[1].size();
  for (std::size_t i = 1; i + 1 < lines.size(); ++i)
    CHECK_TEXT(lines[i].size() == width, ("line " + std::to_string(i + 1) + " '" + lines[i] + "' in:\n" + t).c_str());
  CHECK_TEXT(has(t, "\nfrom drives "), t.c_str());
}

// The frames bus_traffic() counts are the ones App::build maps: TPDO2 only with bus.tpdo2
// (velocity 4 + error code 2 bytes) or with the torque (then all three: 8 bytes, 135 bits).
TEST(Config, BusTrafficCountsTpdo2AsTheMasterMapsIt) {
  FwConfig c;
  c.can = "can0";
  LONGS_EQUAL(0, bus_traffic(c, 6).tpdo2_len);
  c.tpdo2 = true;
  LONGS_EQUAL(6, bus_traffic(c, 6).tpdo2_len);
  c.tpdo2 = false;
  c.collision = true;
  LONGS_EQUAL(8, bus_traffic(c, 6).tpdo2_len);
  c.tpdo2 = true;
  LONGS_EQUAL(8, bus_traffic(c, 6).tpdo2_len);
  c.collision = false;
  c.drives.resize(6);
  c.drives[2].homing_method = "hard_stop";
  c.drives[2].homing_torque_limit = 50;
  c.tpdo2 = false;
  LONGS_EQUAL(8, bus_traffic(c, 6).tpdo2_len);
  c.rate_hz = 250;  // (55 + 12 x 115 + 6 x 135) x 250 + 7800 = 2245 x 250 + 7800 = 569050 bit/s
  DOUBLES_EQUAL(0.56905, servoarm::hal::bus_load(bus_traffic(c, 6), c.bitrate).total(), 1e-9);
}

// CAN FD with bit-rate switch: the MIT frames' data phase runs at bus.data_bitrate, so six
// Damiao motors at 1 kHz that classical frames would overload (162 %) fit on an FD bus.
TEST(Config, BusLoadOfCanFdFramesCountsTheDataBitrate) {
  std::string six = "[loop]\nrate_hz = 1000\n[bus]\ncan = \"can0\"\n";
  std::string drives;
  for (int i = 1; i <= 6; ++i)
    drives += "[[drive]]\nfamily = \"damiao\"\nmotor = \"DM-J4340\"\nnode = " + std::to_string(i) +
              "\ncan_fd = true\nhoming.method = \"absolute\"\n";
  FwConfig c;
  const std::string classic = load_config_text(six + drives, "fd.toml", c);
  CHECK_TEXT(has(classic, "162.0 %") && has(classic, "above 85 %"), classic.c_str());
  FwConfig f2, f5;
  STRCMP_EQUAL("", load_config_text(six + "data_bitrate = 5000000\n" + drives, "fd.toml", f5).c_str());
  DOUBLES_EQUAL(5e6, f5.data_bitrate, 0);
  const std::string w5 = bus_load_warning(f5, 6);
  const std::string e2 = load_config_text(six + "data_bitrate = 2000000\n" + drives, "fd.toml", f2);
  const std::string w2 = e2.empty() ? bus_load_warning(f2, 6) : e2;
  std::printf("\n  5 Mbit/s: %s\n  2 Mbit/s: %s\n", w5.empty() ? "(no warning: at most 60 %)" : w5.c_str(), w2.c_str());
  const auto pct = [](const std::string& s) {
    const std::size_t k = s.find("bus load ");
    return k == std::string::npos ? -1.0 : std::atof(s.c_str() + k + 9);
  };
  // 2 Mbit/s leaves more bits at the nominal rate than 5 Mbit/s: more load, still under 162 %
  CHECK_TEXT(pct(w2) > 0 && pct(w2) < 162.0, w2.c_str());
  CHECK_TEXT(has(w2, "CAN FD, data phase 2000000 bit/s"), w2.c_str());
  if (!w5.empty()) CHECK_TEXT(pct(w5) < pct(w2), w5.c_str());
  // classical interfaces ignore it; below the nominal bitrate it is refused
  FwConfig cl;
  const std::string slow = load_config_text(six + "data_bitrate = 500000\n" + drives, "fd.toml", cl);
  CHECK_TEXT(has(slow, "bus.data_bitrate"), slow.c_str());
}

// Several buses at their own rates: can0 carries four Damiao motors at CAN FD 1/5 Mbit/s,
// can1 two CiA 402 drives at 500 kbit/s (drive.bitrate). can1's traffic at 1 kHz is
// (55 + 4 x 115) bits a cycle + 2 x 20/s x 65 heartbeat bits = 517600 bit/s: 51.8 % of
// 1 Mbit/s, 103.5 % of its own 500 kbit/s, so it is refused naming can1 and drive.bitrate.
namespace {
std::string mixed_arm(const std::string& loop, const std::string& can1_extra) {
  std::string t = loop + "[bus]\ncan = \"can0\"\nbitrate = 1000000\ndata_bitrate = 5000000\n";
  for (int i = 1; i <= 4; ++i)
    t += "[[drive]]\nfamily = \"damiao\"\nmotor = \"DM-J4340\"\nnode = " + std::to_string(i) +
         "\ncan_fd = true\nhoming.method = \"absolute\"\n";
  for (int i = 5; i <= 6; ++i)
    t += "[[drive]]\ncan = \"can1\"\nnode = " + std::to_string(i) + "\nhoming.method = \"absolute\"\n" + can1_extra;
  return t;
}
}  // namespace

TEST(Config, EachInterfaceIsLoadCheckedAtItsOwnBitrate) {
  const std::string loop = "[loop]\nrate_hz = 1000\n";
  FwConfig at1m;
  STRCMP_EQUAL("", load_config_text(mixed_arm(loop, ""), "m.toml", at1m).c_str());
  FwConfig at500k;
  const std::string e = load_config_text(mixed_arm(loop, "bitrate = 500000\n"), "m.toml", at500k);
  std::printf("\n  can1 at 500 kbit/s: %s\n", e.c_str());
  CHECK_TEXT(has(e, "loop.rate_hz: drive.can \"can1\": bus load 103.5 % of drive.bitrate 500000 bit/s at loop.rate_hz "
                    "1000 with 2 drives") && has(e, "above 85 %"),
             e.c_str());
  CHECK_TEXT(e.find('\n') == std::string::npos, e.c_str());
  // the interface's rates, for armfw and armctl drives check
  DOUBLES_EQUAL(1e6, interface_bitrate(at1m, "can1"), 0);
  DOUBLES_EQUAL(5e6, interface_data_bitrate(at1m, "can0"), 0);
  DOUBLES_EQUAL(0, interface_data_bitrate(at1m, "can1"), 0);  // classical: no drive says can_fd
  FwConfig slow = at1m;
  slow.drives[4].bitrate = slow.drives[5].bitrate = 500000;
  DOUBLES_EQUAL(5e5, interface_bitrate(slow, "can1"), 0);
  DOUBLES_EQUAL(1e6, interface_bitrate(slow, "can0"), 0);
  // loop.rate_hz left out: the highest standard rate every interface leaves room at (500 Hz:
  // can1 at 52.0 % of 500 kbit/s)
  FwConfig picked;
  STRCMP_EQUAL("", load_config_text(mixed_arm("", "bitrate = 500000\n"), "m.toml", picked).c_str());
  DOUBLES_EQUAL(500, picked.rate_hz, 0);
}

// All drives on one interface run at one rate: a drive.bitrate (or drive.data_bitrate) that
// another drive on the interface does not share, given or inherited, is refused naming both.
TEST(Config, DrivesOnOneInterfaceAgreeOnItsBitrates) {
  const std::string loop = "[loop]\nrate_hz = 250\n";
  struct Case {
    std::string toml;
    const char* want;
  } bad[] = {
      {mixed_arm(loop, "") + "[[drive]]\ncan = \"can1\"\nnode = 7\nbitrate = 500000\nhoming.method = \"absolute\"\n",
       "drive[7].bitrate: 500000 on can1, but drive[5] on the same interface has 1000000 (bus.bitrate)"},
      {mixed_arm(loop, "bitrate = 500000\n") + "[[drive]]\ncan = \"can1\"\nnode = 7\nbitrate = 250000\n"
                                               "homing.method = \"absolute\"\n",
       "drive[5].bitrate: 500000 on can1, but drive[7] on the same interface has 250000"},
      {mixed_arm(loop, "can_fd = true\ndata_bitrate = 2000000\n") +
           "[[drive]]\ncan = \"can1\"\nnode = 7\ncan_fd = true\nhoming.method = \"absolute\"\n",
       "drive[5].data_bitrate: 2000000 on can1, but drive[7] on the same interface has 5000000 (bus.data_bitrate)"},
      {mixed_arm(loop, "bitrate = 500000\ncan_fd = true\ndata_bitrate = 250000\n"),
       "drive[5].data_bitrate: must be at least the interface's bit rate (500000), or 0 (got 250000)"},
      {mixed_arm(loop, "data_bitrate = 2000000\n"), "drive[5].data_bitrate: is for a drive.can_fd interface"},
  };
  for (const Case& b : bad) {
    FwConfig k;
    const std::string e = load_config_text(b.toml, "m.toml", k);
    CHECK_TEXT(has(e, b.want) && e.find('\n') == std::string::npos, ("wanted '" + std::string(b.want) + "' in: " + e).c_str());
  }
  FwConfig ok;
  STRCMP_EQUAL("", load_config_text(mixed_arm(loop, "bitrate = 500000\ncan_fd = true\ndata_bitrate = 2000000\n"), "m.toml", ok).c_str());
  DOUBLES_EQUAL(2e6, interface_data_bitrate(ok, "can1"), 0);
}

// armfw --bus-load prints one table per interface, from the traffic the check counts: six
// Damiao motors on can0 show MIT frames and the 162 % the check refuses; a mixed arm, two tables.
TEST(Config, BusLoadTableIsOnePerInterfaceWithItsOwnFramesAndRates) {
  std::string six = "[loop]\nrate_hz = 1000\n[bus]\ncan = \"can0\"\n";
  for (int i = 1; i <= 6; ++i)
    six += "[[drive]]\nfamily = \"damiao\"\nmotor = \"DM-J4340\"\nnode = " + std::to_string(i) +
           "\nhoming.method = \"absolute\"\n";
  FwConfig c;
  STRCMP_EQUAL("", load_config_text(six, "six.toml", c, false).c_str());
  const std::string t = bus_load_table(c, 6);
  std::printf("\n%s", t.c_str());
  CHECK_TEXT(has(t, "bus load on can0: 6 drives (damiao)"), t.c_str());
  CHECK_TEXT(has(t, "\nMIT command ") && has(t, "\nMIT feedback "), t.c_str());
  CHECK_TEXT(!has(t, "SYNC") && !has(t, "RPDO1"), t.c_str());
  CHECK_TEXT(has(t, "162.0 %\nrefused: above 85 %: at most 524 Hz fits"), t.c_str());
  FwConfig m;
  STRCMP_EQUAL("", load_config_text(mixed_arm("[loop]\nrate_hz = 1000\n", "bitrate = 500000\n"), "m.toml", m, false).c_str());
  const std::string two = bus_load_table(m, 6);
  std::printf("\n%s", two.c_str());
  const std::size_t a = two.find("bus load on can0: 4 drives (damiao), loop.rate_hz 1000, bus.bitrate 1000000 bit/s, "
                                 "CAN FD data phase 5000000 bit/s");
  const std::size_t b = two.find("bus load on can1: 2 drives (cia402), loop.rate_hz 1000, drive.bitrate 500000 bit/s, "
                                 "classical CAN");
  CHECK_TEXT(a != std::string::npos && b != std::string::npos && a < b, two.c_str());
  CHECK_TEXT(has(two.substr(b), "\nSYNC ") && !has(two.substr(b), "MIT") && !has(two.substr(a, b - a), "SYNC"), two.c_str());
  CHECK_TEXT(has(two.substr(b), "103.5 %\nrefused: above 85 %"), two.c_str());
  CHECK_TEXT(has(two.substr(a, b - a), "\nfits: at most 60 %") || has(two.substr(a, b - a), "\nwarning:"), two.c_str());
}

// [safety]: the envelope's keys are read into the kinematics core's SI struct; bad ones
// (NaN, zero normal, inverted box, partial groups, a keep-in box narrower than the tool sphere)
// are refused at load with one line naming the key; the park pose outside is refused against
// the robot; the checksum covers exactly the [safety] section's canonical form.
TEST(Config, SafetyKeysAreReadAndBadOnesRefusedNamingTheKey) {
  FwConfig c;
  STRCMP_EQUAL("", load_config_text("[safety]\nplanes = [0, 0, 2, 100]\nkeep_in = [-1000, -1000, -500, 1000, 1000, 1500]\n"
                                    "keep_out = [300, -50, 0, 400, 50, 200]\ntool_radius_mm = 40\ncone_axis = [0, 0, -1]\n"
                                    "cone_deg = 30\ntcp_speed_mm_s = 250\nreduced_tcp_speed_mm_s = 100\n",
                                    "s.toml", c)
                   .c_str());
  const servoarm::kin::LoadResult lr = servoarm::kin::load_robot("puma560");
  CHECK_TEXT(lr.ok, lr.error.c_str());
  servoarm::kin::SafetyConfig e;
  STRCMP_EQUAL("", safety_envelope(c, lr.chain, e).c_str());
  CHECK(e.enabled);
  CHECK_EQUAL(1, e.plane_count);
  DOUBLES_EQUAL(1.0, e.planes[0].normal.z(), 1e-12);  // normalised
  DOUBLES_EQUAL(0.1, e.planes[0].offset, 1e-12);      // mm -> m
  CHECK_EQUAL(2, e.box_count);
  CHECK(e.boxes[0].keep_in);
  CHECK_FALSE(e.boxes[1].keep_in);
  DOUBLES_EQUAL(0.3, e.boxes[1].min.x(), 1e-12);
  DOUBLES_EQUAL(0.04, e.tool_radius, 1e-12);
  CHECK(e.cone);
  DOUBLES_EQUAL(30.0 * M_PI / 180.0, e.normal.cone_half_angle, 1e-12);
  DOUBLES_EQUAL(0.25, e.normal.tcp_speed, 1e-12);
  DOUBLES_EQUAL(0.1, e.reduced.tcp_speed, 1e-12);
  // the defaults: no envelope
  FwConfig d;
  STRCMP_EQUAL("", safety_envelope(d, lr.chain, e).c_str());
  CHECK_FALSE(e.enabled);

  expect_refused("[safety]\nplanes = [0, 0, 1, nan]\n", {"safety.planes"});
  expect_refused("[safety]\nplanes = [0, 0, 0, 100]\n", {"safety.planes", "zero normal"});
  expect_refused("[safety]\nplanes = [0, 0, 1]\n", {"safety.planes", "groups of 4"});
  expect_refused("[safety]\nkeep_in = [0, 0, 0, 1000, -10, 1000]\n", {"safety.keep_in", "inverted", "ymin"});
  expect_refused("[safety]\nkeep_out = [0, 0, 500, 100, 100, 400]\n", {"safety.keep_out", "inverted", "zmin"});
  expect_refused("[safety]\ntool_radius_mm = 60\nkeep_in = [0, 0, 0, 1000, 100, 1000]\n",
                 {"safety.keep_in", "narrower along y", "tool sphere"});
  expect_refused("[safety]\ncone_axis = [0, 0, 0]\n", {"safety.cone_axis", "zero axis"});
  expect_refused("[safety]\ntool_radius_mm = inf\n", {"safety.tool_radius_mm"});
  expect_refused("[safety]\ncone_deg = 0\n", {"safety.cone_deg"});
}

// Joint speed limits: one per joint in deg/s (mm/s for a prismatic joint), per mode, read into
// rad/s; a negative or NaN one is refused at load, a list not one per joint against the robot,
// each in one line naming the key; they are part of the checksum.
TEST(Config, SafetyJointSpeedKeysAreReadAndCheckedAgainstTheRobot) {
  const servoarm::kin::LoadResult lr = servoarm::kin::load_robot("puma560");
  CHECK_TEXT(lr.ok, lr.error.c_str());
  FwConfig c;
  STRCMP_EQUAL("", load_config_text("[safety]\njoint_speed_deg_s = [90, 90, 90, 180, 180, 180]\n"
                                    "reduced_joint_speed_deg_s = [30, 30, 30, 0, 60, 60]\ntolerance_deg_s = 3\n",
                                    "s.toml", c)
                   .c_str());
  servoarm::kin::SafetyConfig e;
  STRCMP_EQUAL("", safety_envelope(c, lr.chain, e).c_str());
  CHECK(e.enabled);
  DOUBLES_EQUAL(M_PI / 2, e.normal.joint_speed[0], 1e-12);
  DOUBLES_EQUAL(M_PI, e.normal.joint_speed[5], 1e-12);
  DOUBLES_EQUAL(M_PI / 6, e.reduced.joint_speed[0], 1e-12);
  DOUBLES_EQUAL(0.0, e.reduced.joint_speed[3], 0);
  DOUBLES_EQUAL(3 * M_PI / 180, e.joint_speed_tolerance[2], 1e-12);
  STRCMP_EQUAL("", validate_for_chain(c, lr.chain).c_str());
  FwConfig other = c;
  other.safety_reduced_joint_speed_deg_s[0] = 31;
  CHECK(safety_checksum(other) != safety_checksum(c));

  expect_refused("[safety]\njoint_speed_deg_s = [90, -1, 90, 90, 90, 90]\n", {"safety.joint_speed_deg_s"});
  expect_refused("[safety]\nreduced_joint_speed_deg_s = [nan, 1, 1, 1, 1, 1]\n", {"safety.reduced_joint_speed_deg_s"});
  expect_refused("[safety]\ntolerance_deg_s = -2\n", {"safety.tolerance_deg_s"});
  FwConfig five = c;
  five.safety_reduced_joint_speed_deg_s = {30, 30, 30, 30, 30};
  const std::string bad = validate_for_chain(five, lr.chain);
  STRCMP_EQUAL("safety.reduced_joint_speed_deg_s: needs one value per joint of puma560 (6), got 5", bad.c_str());
}

// Stopping time and distance limits per mode, read into s and m; negative or NaN ones refused
// at load naming the key; part of the checksum.
TEST(Config, SafetyStopKeysAreReadAndBadOnesRefused) {
  const servoarm::kin::LoadResult lr = servoarm::kin::load_robot("puma560");
  CHECK_TEXT(lr.ok, lr.error.c_str());
  FwConfig c;
  STRCMP_EQUAL("", load_config_text("[safety]\nstop_time_s = 0.4\nstop_distance_mm = 150\nreduced_stop_time_s = 0.2\n"
                                    "reduced_stop_distance_mm = 50\ntolerance_s = 0.05\n",
                                    "s.toml", c)
                   .c_str());
  servoarm::kin::SafetyConfig e;
  STRCMP_EQUAL("", safety_envelope(c, lr.chain, e).c_str());
  CHECK(e.enabled);
  DOUBLES_EQUAL(0.4, e.normal.stop_time, 1e-12);
  DOUBLES_EQUAL(0.15, e.normal.stop_distance, 1e-12);
  DOUBLES_EQUAL(0.2, e.reduced.stop_time, 1e-12);
  DOUBLES_EQUAL(0.05, e.reduced.stop_distance, 1e-12);
  DOUBLES_EQUAL(0.05, e.stop_time_tolerance, 1e-12);
  FwConfig other = c;
  other.safety_reduced_stop_distance_mm = 51;
  CHECK(safety_checksum(other) != safety_checksum(c));
  expect_refused("[safety]\nstop_time_s = -1\n", {"safety.stop_time_s"});
  expect_refused("[safety]\nstop_distance_mm = nan\n", {"safety.stop_distance_mm"});
  expect_refused("[safety]\nreduced_stop_time_s = inf\n", {"safety.reduced_stop_time_s"});
  expect_refused("[safety]\nreduced_stop_distance_mm = -5\n", {"safety.reduced_stop_distance_mm"});
  expect_refused("[safety]\ntolerance_s = -0.1\n", {"safety.tolerance_s"});
}

// Momentum and power limits per mode; negative or NaN ones refused at load naming the key; against
// a robot without inertial data (the ABB IRB 2400's description has none) refused in one line.
TEST(Config, SafetyMomentumAndPowerKeysNeedTheRobotsMasses) {
  const servoarm::kin::LoadResult lr = servoarm::kin::load_robot("puma560");
  CHECK_TEXT(lr.ok, lr.error.c_str());
  FwConfig c;
  STRCMP_EQUAL("", load_config_text("[safety]\nmomentum_kg_m_s = 10\npower_w = 80\nreduced_momentum_kg_m_s = 4\n"
                                    "reduced_power_w = 30\ntolerance_kg_m_s = 0.3\ntolerance_w = 3\n",
                                    "s.toml", c)
                   .c_str());
  servoarm::kin::SafetyConfig e;
  STRCMP_EQUAL("", safety_envelope(c, lr.chain, e).c_str());
  CHECK(e.enabled);
  DOUBLES_EQUAL(10, e.normal.momentum, 0);
  DOUBLES_EQUAL(80, e.normal.power, 0);
  DOUBLES_EQUAL(4, e.reduced.momentum, 0);
  DOUBLES_EQUAL(30, e.reduced.power, 0);
  DOUBLES_EQUAL(0.3, e.momentum_tolerance, 0);
  DOUBLES_EQUAL(3, e.power_tolerance, 0);
  FwConfig other = c;
  other.safety_reduced_power_w = 31;
  CHECK(safety_checksum(other) != safety_checksum(c));
  expect_refused("[safety]\nmomentum_kg_m_s = -1\n", {"safety.momentum_kg_m_s"});
  expect_refused("[safety]\npower_w = nan\n", {"safety.power_w"});
  expect_refused("[safety]\nreduced_momentum_kg_m_s = inf\n", {"safety.reduced_momentum_kg_m_s"});
  expect_refused("[safety]\nreduced_power_w = -5\n", {"safety.reduced_power_w"});
  expect_refused("[safety]\ntolerance_w = -1\n", {"safety.tolerance_w"});
  const servoarm::kin::LoadResult abb = servoarm::kin::load_robot("abb_irb2400");
  CHECK_TEXT(abb.ok, abb.error.c_str());
  CHECK_FALSE(abb.chain.has_inertial);
  FwConfig a;
  a.robot = "abb_irb2400";
  a.safety_reduced_power_w = 30;
  STRCMP_EQUAL("safety.reduced_power_w: needs the robot's masses (abb_irb2400's description has no inertial data, "
               "docs/dynamics.md)",
               safety_for_chain(a, abb.chain).c_str());
}

TEST(Config, SafetyParkPoseOutsideTheEnvelopeIsRefused) {
  const servoarm::kin::LoadResult lr = servoarm::kin::load_robot("puma560");
  CHECK_TEXT(lr.ok, lr.error.c_str());
  servoarm::kin::Pose tcp;
  CHECK(servoarm::kin::forward(lr.chain, servoarm::kin::JointVector::Zero(6), tcp) == servoarm::kin::Status::ok);
  const double z_mm = tcp.translation().z() * 1000.0;
  FwConfig c;
  c.safety_planes = {0, 0, 1, z_mm - 50};  // the park pose (zeros) 50 mm above the plane
  c.safety_tool_radius_mm = 20;
  STRCMP_EQUAL("", validate_for_chain(c, lr.chain).c_str());
  c.safety_tool_radius_mm = 60;  // the sphere reaches 10 mm below it
  const std::string e = validate_for_chain(c, lr.chain);
  STRCMP_CONTAINS("safety: the park pose (motion.home_deg) lies outside the envelope: safety plane 0", e.c_str());
  CHECK(e.find('\n') == std::string::npos);
  c.safety_tool_radius_mm = 0;
  c.safety_planes.clear();
  c.safety_elbow_frame = 12;
  STRCMP_CONTAINS("safety.elbow_frame: 12 is not a frame of puma560", validate_for_chain(c, lr.chain).c_str());
}

TEST(Config, SafetyChecksumCoversTheSafetySectionOnly) {
  FwConfig a;
  const std::uint32_t base = safety_checksum(a);
  CHECK_EQUAL(base, safety_checksum(a));  // stable
  STRCMP_CONTAINS("safety.planes = []\n", safety_canonical(a).c_str());
  FwConfig b = a;
  b.linear_speed_mm_s = 50;  // not a safety key
  CHECK_EQUAL(base, safety_checksum(b));
  b.safety_tcp_speed_mm_s = 250;
  CHECK(safety_checksum(b) != base);
  FwConfig p = a;
  p.safety_planes = {0, 0, 1, 100};
  CHECK(safety_checksum(p) != base);
  p.safety_planes = {0, 0, 1, 100.001};
  CHECK(safety_checksum(p) != safety_checksum(b));
  // the checksum survives a round trip through the file
  FwConfig r;
  STRCMP_EQUAL("", load_config_text(to_toml(p), "rt", r).c_str());
  CHECK_EQUAL(safety_checksum(p), safety_checksum(r));
  // the canonical form holds every [safety] key, the older ones too
  const std::string canon = safety_canonical(a);
  CHECK(canon.find("safety.stop = \"ramp\"\n") != std::string::npos);
}
