// armfw configuration: defaults valid, every key accepted, bad files refused naming the key.
#include <string>

#include "servoarm/firmware/config.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm::fw;

TEST_GROUP(Config){};

TEST(Config, DefaultsAreValidAndRoundTrip) {
  FwConfig c;
  STRCMP_EQUAL("", validate(c).c_str());
  FwConfig d;
  d.rate_hz = 500;
  STRCMP_EQUAL("", load_config_text(to_toml(c), "rt", d).c_str());
  DOUBLES_EQUAL(1000.0, d.rate_hz, 0);
}

TEST(Config, FullFileAccepted) {
  FwConfig c;
  const std::string text =
      "robot = \"stanford\"\n[loop]\nrate_hz = 2000\npriority = 0\ncpu = 1\nlock_memory = false\n"
      "[bus]\ncan = \"vcan0\"\nfirst_node = 10\ncounts_per_rev = 4096\ngear_ratio = 50\nheartbeat_period_ms = 20\n"
      "heartbeat_timeout_ms = 60\nstart_timeout_s = 3\n[safety]\nfollowing_error_deg = 2.5\nenable_timeout_s = 1\n"
      "stop = \"drive\"\ndrive_stop_timeout_s = 1.5\n"
      "[motion]\nhome_deg = [0, 10, 0, 0, 0, 0]\njoint_speed_pct = 30\nlinear_speed_mm_s = 50\nmax_linear_speed_mm_s = 200\n"
      "[console]\nstdin = false\npty = true\nserial = \"/dev/ttyS0\"\nbaud = 57600\n";
  STRCMP_EQUAL("", load_config_text(text, "f.toml", c).c_str());
  STRCMP_EQUAL("stanford", c.robot.c_str());
  DOUBLES_EQUAL(2000, c.rate_hz, 0);
  LONGS_EQUAL(10, c.first_node);
  LONGS_EQUAL(6, c.home_deg.size());
  CHECK(c.console_pty);
  LONGS_EQUAL(57600, c.console_baud);
  STRCMP_EQUAL("drive", c.stop.c_str());
  DOUBLES_EQUAL(1.5, c.drive_stop_timeout_s, 0);
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
      {"[loop\nrate_hz = 1000\n", "syntax"},
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
  };
  for (const Case& k : cases) {
    FwConfig c;
    const std::string e = load_config_text(k.text, "bad.toml", c);
    if (e.find(k.must_contain) == std::string::npos || e.find("bad.toml") == std::string::npos)
      FAIL((std::string("case '") + k.text + "' gave '" + e + "'").c_str());
    DOUBLES_EQUAL(1000.0, c.rate_hz, 0);  // untouched
  }
}

TEST(Config, EveryDocumentedKeyIsAccepted) {
  // Each documented key written with its documented default loads.
  CHECK(kConfigKeyCount >= 20);
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
  for (int i = 0; i < kConfigKeyCount; ++i) {
    std::string k = kConfigKeys[i].key;
    if (k == "drive") {
      CHECK(toml.find("[[drive]]") != std::string::npos);
      continue;
    }
    const auto dot = k.find('.');
    const std::string leaf = dot == std::string::npos ? k : k.substr(dot + 1);
    if (toml.find(leaf + " = ") == std::string::npos) FAIL(("key not in to_toml: " + k).c_str());
  }
}
