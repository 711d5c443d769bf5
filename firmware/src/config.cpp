#include "servoarm/firmware/config.hpp"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <toml.hpp>

namespace servoarm::fw {

const ConfigKey kConfigKeys[] = {
    {"robot", "\"puma560\"", "built-in model name (armctl kin models) or path to a description .toml"},
    {"loop.rate_hz", "1000", "control rate in Hz, 250..4000"},
    {"loop.priority", "80", "SCHED_FIFO priority 1..99 for the control thread; 0 = normal scheduling"},
    {"loop.cpu", "-1", "pin the control thread to this CPU; -1 = no affinity"},
    {"loop.lock_memory", "true", "mlockall() all memory at start"},
    {"bus.can", "\"sim\"", "\"sim\" = virtual drives on the in-process bus, or a SocketCAN interface (can0, vcan0)"},
    {"bus.first_node", "1", "CANopen node id of joint 1; joint k is first_node + k - 1 (1..127)"},
    {"bus.counts_per_rev", "131072", "encoder counts per motor revolution"},
    {"bus.gear_ratio", "1.0", "motor revolutions per joint revolution"},
    {"bus.heartbeat_period_ms", "50", "heartbeat period written to every drive"},
    {"bus.heartbeat_timeout_ms", "150", "heartbeat consumer time: silence longer than this faults the arm"},
    {"bus.start_timeout_s", "5", "time allowed for drive bring-up at start"},
    {"drive", "[] (one per joint from the [bus] values)", "[[drive]] tables, one per joint in chain order (keys below); give all or none"},
    {"drive.node", "bus.first_node + k", "CANopen node id of this joint's drive (1..127, unique)"},
    {"drive.counts_per_rev", "bus.counts_per_rev", "encoder counts per motor revolution (per motor mm for prismatic joints)"},
    {"drive.gear_ratio", "bus.gear_ratio", "motor revolutions (mm) per joint revolution (mm); not 0"},
    {"drive.direction", "1", "1 or -1: sign between the joint and the drive"},
    {"drive.zero_offset", "0", "drive position in counts at joint zero (what `home zero` answers)"},
    {"drive.limits", "the robot description's", "[lower, upper] in deg / mm; must lie within the description's limits"},
    {"drive.max_velocity", "the robot description's", "deg/s or mm/s; at most the description's"},
    {"drive.heartbeat_timeout_ms", "bus.heartbeat_timeout_ms", "heartbeat consumer time for this drive"},
    {"drive.quick_stop_decel", "the drive's own", "deg/s^2 or mm/s^2 (joint side): written to the drive's 6085h quick stop deceleration at bring-up (safety.stop = \"drive\")"},
    {"safety.following_error_deg", "5", "largest |commanded - actual| per joint (deg, or mm for prismatic)"},
    {"safety.enable_timeout_s", "2", "time for every drive to reach operation enabled"},
    {"safety.feedback_timeout_ms", "50", "an enabled drive silent (no position feedback) this long faults the arm"},
    {"safety.stop", "\"ramp\"", "e-stop and fault reaction: \"ramp\" = the controller ramps every joint to rest with the full limits, then powers down; \"drive\" = CiA 402 Quick Stop (controlword 0x0002) to every drive in the next cycle, each stops on its own quick-stop ramp (605Ah/6085h), power-down once all are at rest"},
    {"safety.drive_stop_timeout_s", "2", "stop = \"drive\": power the drives down after this long even if one still reports motion"},
    {"motion.home_deg", "[] (zeros, clamped into the limits)", "home pose for `home` / G28, one value per joint (deg / mm)"},
    {"motion.joint_speed_pct", "50", "movej / home speed without speed=, percent of the joint limits (1..100)"},
    {"motion.linear_speed_mm_s", "100", "movel / G1 speed without speed= / F"},
    {"motion.max_linear_speed_mm_s", "250", "highest linear speed (speed=, F are clamped to it; G0 uses it)"},
    {"console.stdin", "true", "console on stdin/stdout"},
    {"console.pty", "false", "open a pseudo-terminal console and print its path"},
    {"console.serial", "\"\"", "serial device for a console (e.g. /dev/ttyS0); \"\" = none"},
    {"console.baud", "115200", "serial baud rate (9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600)"},
    {"console.can", "\"\"", "console over CAN (ISO-TP): a SocketCAN interface (can0, vcan0), \"sim\" (the in-process bus), \"\" = none"},
    {"console.can_rx_id", "0x7E0", "11-bit id armfw receives console requests on (ISO-TP); outside the CANopen ids of nodes 1..127"},
    {"console.can_tx_id", "0x7E8", "11-bit id armfw answers on (ISO-TP); outside the CANopen ids of nodes 1..127"},
};
const int kConfigKeyCount = static_cast<int>(sizeof kConfigKeys / sizeof kConfigKeys[0]);

namespace {

struct Reader {
  std::string origin;
  std::string err;
  bool fail(const std::string& key, const std::string& why) {
    if (err.empty()) err = origin + ": " + key + ": " + why;
    return false;
  }
  bool num(const toml::value& v, const std::string& key, double& out) {
    if (v.is_integer()) out = static_cast<double>(v.as_integer());
    else if (v.is_floating()) out = v.as_floating();
    else return fail(key, "expected a number");
    if (!std::isfinite(out)) return fail(key, "not a finite number");
    return true;
  }
  bool integer(const toml::value& v, const std::string& key, int& out) {
    if (!v.is_integer()) return fail(key, "expected an integer");
    const auto i = v.as_integer();
    if (i < -1000000 || i > 1000000) return fail(key, "integer out of range");
    out = static_cast<int>(i);
    return true;
  }
  bool boolean(const toml::value& v, const std::string& key, bool& out) {
    if (!v.is_boolean()) return fail(key, "expected true or false");
    out = v.as_boolean();
    return true;
  }
  bool str(const toml::value& v, const std::string& key, std::string& out) {
    if (!v.is_string()) return fail(key, "expected a string");
    out = v.as_string().str;
    return true;
  }
};

bool apply_drive(Reader& r, const std::string& where, const std::string& key, const toml::value& v, DriveConfig& d) {
  const std::string k = where + "." + key;
  if (key == "node") return r.integer(v, k, d.node);
  if (key == "counts_per_rev") return r.num(v, k, d.counts_per_rev);
  if (key == "gear_ratio") return r.num(v, k, d.gear_ratio);
  if (key == "direction") return r.integer(v, k, d.direction);
  if (key == "zero_offset") {
    if (!v.is_integer()) return r.fail(k, "expected an integer (drive counts)");
    d.zero_offset = v.as_integer();
    return true;
  }
  if (key == "limits") {
    if (!v.is_array() || v.as_array().size() != 2) return r.fail(k, "expected [lower, upper]");
    d.limits.assign(2, 0.0);
    return r.num(v.as_array()[0], k, d.limits[0]) && r.num(v.as_array()[1], k, d.limits[1]);
  }
  if (key == "max_velocity") return r.num(v, k, d.max_velocity);
  if (key == "heartbeat_timeout_ms") return r.num(v, k, d.heartbeat_timeout_ms);
  if (key == "quick_stop_decel") return r.num(v, k, d.quick_stop_decel);
  return r.fail(k, "unknown key (node, counts_per_rev, gear_ratio, direction, zero_offset, limits, max_velocity, heartbeat_timeout_ms, quick_stop_decel)");
}

bool apply(Reader& r, const std::string& key, const toml::value& v, FwConfig& c) {
  if (key == "drive") {
    if (!v.is_array()) return r.fail(key, "expected [[drive]] tables");
    c.drives.clear();
    for (const auto& t : v.as_array()) {
      const std::string where = "drive[" + std::to_string(c.drives.size() + 1) + "]";
      if (!t.is_table()) return r.fail(where, "expected a table");
      DriveConfig d;
      for (const auto& [k2, v2] : t.as_table())
        if (!apply_drive(r, where, k2, v2, d)) return false;
      c.drives.push_back(d);
    }
    return true;
  }
  if (key == "robot") return r.str(v, key, c.robot);
  if (key == "loop.rate_hz") return r.num(v, key, c.rate_hz);
  if (key == "loop.priority") return r.integer(v, key, c.priority);
  if (key == "loop.cpu") return r.integer(v, key, c.cpu);
  if (key == "loop.lock_memory") return r.boolean(v, key, c.lock_memory);
  if (key == "bus.can") return r.str(v, key, c.can);
  if (key == "bus.first_node") return r.integer(v, key, c.first_node);
  if (key == "bus.counts_per_rev") return r.num(v, key, c.counts_per_rev);
  if (key == "bus.gear_ratio") return r.num(v, key, c.gear_ratio);
  if (key == "bus.heartbeat_period_ms") return r.num(v, key, c.heartbeat_period_ms);
  if (key == "bus.heartbeat_timeout_ms") return r.num(v, key, c.heartbeat_timeout_ms);
  if (key == "bus.start_timeout_s") return r.num(v, key, c.start_timeout_s);
  if (key == "safety.following_error_deg") return r.num(v, key, c.following_error_deg);
  if (key == "safety.enable_timeout_s") return r.num(v, key, c.enable_timeout_s);
  if (key == "safety.feedback_timeout_ms") return r.num(v, key, c.feedback_timeout_ms);
  if (key == "safety.stop") return r.str(v, key, c.stop);
  if (key == "safety.drive_stop_timeout_s") return r.num(v, key, c.drive_stop_timeout_s);
  if (key == "motion.home_deg") {
    if (!v.is_array()) return r.fail(key, "expected an array of numbers");
    c.home_deg.clear();
    int k = 0;
    for (const auto& e : v.as_array()) {
      double d = 0;
      if (!r.num(e, key + "[" + std::to_string(k++) + "]", d)) return false;
      c.home_deg.push_back(d);
    }
    return true;
  }
  if (key == "motion.joint_speed_pct") return r.num(v, key, c.joint_speed_pct);
  if (key == "motion.linear_speed_mm_s") return r.num(v, key, c.linear_speed_mm_s);
  if (key == "motion.max_linear_speed_mm_s") return r.num(v, key, c.max_linear_speed_mm_s);
  if (key == "console.stdin") return r.boolean(v, key, c.console_stdin);
  if (key == "console.pty") return r.boolean(v, key, c.console_pty);
  if (key == "console.serial") return r.str(v, key, c.console_serial);
  if (key == "console.baud") return r.integer(v, key, c.console_baud);
  if (key == "console.can") return r.str(v, key, c.console_can);
  if (key == "console.can_rx_id") return r.integer(v, key, c.console_can_rx_id);
  if (key == "console.can_tx_id") return r.integer(v, key, c.console_can_tx_id);
  return r.fail(key, "unknown key (see armfw --config-keys)");
}

}  // namespace

const char* can_console_id_problem(int id) {
  // CANopen predefined connection set (CiA 301) of nodes 1..127: NMT 0x000, SYNC 0x080,
  // EMCY 0x081-0x0FF, TIME 0x100, PDOs 0x181-0x57F, SDO 0x581-0x67F, heartbeat 0x701-0x77F;
  // LSS (CiA 305) 0x7E4 / 0x7E5.
  if (id < 0 || id > 0x7FF) return "must be an 11-bit id (0x000..0x7FF)";
  if (id <= 0x100) return "collides with CANopen NMT / SYNC / EMCY / TIME (0x000-0x100)";
  if (id >= 0x181 && id <= 0x57F) return "collides with the CANopen PDOs of nodes 1..127 (0x181-0x57F)";
  if (id >= 0x581 && id <= 0x67F) return "collides with the CANopen SDOs of nodes 1..127 (0x581-0x67F)";
  if (id >= 0x701 && id <= 0x77F) return "collides with the CANopen heartbeats of nodes 1..127 (0x701-0x77F)";
  if (id == 0x7E4 || id == 0x7E5) return "collides with CANopen LSS (0x7E4 / 0x7E5)";
  return nullptr;
}

std::string validate(const FwConfig& c) {
  auto bad = [](const char* k, const char* why) { return std::string(k) + ": " + why; };
  if (c.robot.empty()) return bad("robot", "must not be empty");
  if (!(c.rate_hz >= 250 && c.rate_hz <= 4000)) return bad("loop.rate_hz", "must be within 250..4000");
  if (c.priority < 0 || c.priority > 99) return bad("loop.priority", "must be within 0..99");
  if (c.cpu < -1 || c.cpu > 1023) return bad("loop.cpu", "must be -1 or a CPU index");
  if (c.can.empty() || c.can.size() > 15) return bad("bus.can", "must be \"sim\" or an interface name (1..15 chars)");
  if (c.first_node < 1 || c.first_node > 127) return bad("bus.first_node", "must be within 1..127");
  if (!(c.counts_per_rev > 0)) return bad("bus.counts_per_rev", "must be > 0");
  if (!(c.gear_ratio != 0)) return bad("bus.gear_ratio", "must not be 0");
  if (!(c.heartbeat_period_ms >= 1 && c.heartbeat_period_ms <= 10000)) return bad("bus.heartbeat_period_ms", "must be within 1..10000");
  if (!(c.heartbeat_timeout_ms > c.heartbeat_period_ms && c.heartbeat_timeout_ms <= 60000))
    return bad("bus.heartbeat_timeout_ms", "must be above heartbeat_period_ms and <= 60000");
  if (!(c.start_timeout_s > 0 && c.start_timeout_s <= 120)) return bad("bus.start_timeout_s", "must be within (0, 120]");
  if (!(c.following_error_deg > 0 && c.following_error_deg <= 180)) return bad("safety.following_error_deg", "must be within (0, 180]");
  if (!(c.enable_timeout_s > 0 && c.enable_timeout_s <= 60)) return bad("safety.enable_timeout_s", "must be within (0, 60]");
  if (!(c.feedback_timeout_ms >= 1 && c.feedback_timeout_ms <= 10000)) return bad("safety.feedback_timeout_ms", "must be within 1..10000");
  if (c.stop != "ramp" && c.stop != "drive") return bad("safety.stop", "must be \"ramp\" or \"drive\"");
  if (!(c.drive_stop_timeout_s >= 0.05 && c.drive_stop_timeout_s <= 60)) return bad("safety.drive_stop_timeout_s", "must be within 0.05..60");
  if (!(c.joint_speed_pct >= 1 && c.joint_speed_pct <= 100)) return bad("motion.joint_speed_pct", "must be within 1..100");
  if (!(c.max_linear_speed_mm_s > 0 && c.max_linear_speed_mm_s <= 5000)) return bad("motion.max_linear_speed_mm_s", "must be within (0, 5000]");
  if (!(c.linear_speed_mm_s > 0 && c.linear_speed_mm_s <= c.max_linear_speed_mm_s))
    return bad("motion.linear_speed_mm_s", "must be within (0, max_linear_speed_mm_s]");
  for (std::size_t i = 0; i < c.drives.size(); ++i) {
    const DriveConfig& d = c.drives[i];
    const std::string w = "drive[" + std::to_string(i + 1) + "].";
    if (d.node != 0 && (d.node < 1 || d.node > 127)) return w + "node: must be within 1..127";
    if (!(d.counts_per_rev >= 0)) return w + "counts_per_rev: must be > 0";
    if (d.direction != 1 && d.direction != -1) return w + "direction: must be 1 or -1";
    if (d.zero_offset < INT32_MIN || d.zero_offset > INT32_MAX) return w + "zero_offset: outside the drive's 32-bit position range";
    if (!d.limits.empty() && !(d.limits[0] < d.limits[1])) return w + "limits: lower must be below upper";
    if (!(d.max_velocity >= 0)) return w + "max_velocity: must be > 0";
    if (!(d.heartbeat_timeout_ms == 0 || (d.heartbeat_timeout_ms > c.heartbeat_period_ms && d.heartbeat_timeout_ms <= 60000)))
      return w + "heartbeat_timeout_ms: must be above bus.heartbeat_period_ms and <= 60000";
    if (!(d.quick_stop_decel >= 0 && d.quick_stop_decel <= 1e7)) return w + "quick_stop_decel: must be within 0..1e7 deg/s^2 (mm/s^2; 0 = the drive's own)";
  }
  switch (c.console_baud) {
    case 9600: case 19200: case 38400: case 57600: case 115200: case 230400: case 460800: case 921600: break;
    default: return bad("console.baud", "unsupported baud rate");
  }
  if (c.console_can.size() > 15) return bad("console.can", "must be \"\", \"sim\" or an interface name (1..15 chars)");
  if (const char* why = can_console_id_problem(c.console_can_rx_id)) return std::string("console.can_rx_id: ") + why;
  if (const char* why = can_console_id_problem(c.console_can_tx_id)) return std::string("console.can_tx_id: ") + why;
  if (c.console_can_rx_id == c.console_can_tx_id) return bad("console.can_tx_id", "must differ from console.can_rx_id");
  return "";
}

std::string load_config_text(const std::string& text, const std::string& origin, FwConfig& cfg) {
  Reader r{origin, {}};
  toml::value root;
  try {
    std::istringstream is(text);
    root = toml::parse(is, origin);
  } catch (const std::exception& e) {
    std::string m = e.what();
    const auto nl = m.find('\n');
    if (nl != std::string::npos) m = m.substr(0, nl);
    return origin + ": syntax: " + m;
  }
  if (!root.is_table()) return origin + ": not a TOML table";
  FwConfig c = cfg;
  for (const auto& [k, v] : root.as_table()) {
    if (v.is_table()) {
      if (k != "loop" && k != "bus" && k != "safety" && k != "motion" && k != "console") {
        r.fail(k, "unknown section (loop, bus, safety, motion, console)");
        break;
      }
      for (const auto& [k2, v2] : v.as_table())
        if (!apply(r, k + "." + k2, v2, c)) break;
      if (!r.err.empty()) break;
    } else if (!apply(r, k, v, c)) {
      break;
    }
  }
  if (!r.err.empty()) return r.err;
  const std::string bad = validate(c);
  if (!bad.empty()) return origin + ": " + bad;
  cfg = c;
  return "";
}

std::string load_config_file(const std::string& path, FwConfig& cfg) {
  std::ifstream f(path);
  if (!f) return path + ": cannot open";
  std::stringstream ss;
  ss << f.rdbuf();
  return load_config_text(ss.str(), path, cfg);
}

std::string to_toml(const FwConfig& c) {
  char b[2048];
  std::string home = "[";
  for (std::size_t i = 0; i < c.home_deg.size(); ++i) home += (i ? ", " : "") + std::to_string(c.home_deg[i]);
  home += "]";
  std::snprintf(b, sizeof b,
                "robot = \"%s\"\n[loop]\nrate_hz = %g\npriority = %d\ncpu = %d\nlock_memory = %s\n"
                "[bus]\ncan = \"%s\"\nfirst_node = %d\ncounts_per_rev = %g\ngear_ratio = %g\nheartbeat_period_ms = %g\n"
                "heartbeat_timeout_ms = %g\nstart_timeout_s = %g\n[safety]\nfollowing_error_deg = %g\nenable_timeout_s = %g\nfeedback_timeout_ms = %g\nstop = \"%s\"\ndrive_stop_timeout_s = %g\n"
                "[motion]\nhome_deg = %s\njoint_speed_pct = %g\nlinear_speed_mm_s = %g\nmax_linear_speed_mm_s = %g\n"
                "[console]\nstdin = %s\npty = %s\nserial = \"%s\"\nbaud = %d\ncan = \"%s\"\ncan_rx_id = 0x%03X\ncan_tx_id = 0x%03X\n",
                c.robot.c_str(), c.rate_hz, c.priority, c.cpu, c.lock_memory ? "true" : "false", c.can.c_str(), c.first_node,
                c.counts_per_rev, c.gear_ratio, c.heartbeat_period_ms, c.heartbeat_timeout_ms, c.start_timeout_s,
                c.following_error_deg, c.enable_timeout_s, c.feedback_timeout_ms, c.stop.c_str(), c.drive_stop_timeout_s, home.c_str(), c.joint_speed_pct, c.linear_speed_mm_s,
                c.max_linear_speed_mm_s, c.console_stdin ? "true" : "false", c.console_pty ? "true" : "false",
                c.console_serial.c_str(), c.console_baud, c.console_can.c_str(), static_cast<unsigned>(c.console_can_rx_id),
                static_cast<unsigned>(c.console_can_tx_id));
  std::string out = b;
  for (const DriveConfig& d : c.drives) {
    char l[512];
    std::snprintf(l, sizeof l,
                  "[[drive]]\nnode = %d\ncounts_per_rev = %g\ngear_ratio = %g\ndirection = %d\nzero_offset = %lld\n",
                  d.node, d.counts_per_rev, d.gear_ratio, d.direction, static_cast<long long>(d.zero_offset));
    out += l;
    if (!d.limits.empty()) {
      std::snprintf(l, sizeof l, "limits = [%g, %g]\n", d.limits[0], d.limits[1]);
      out += l;
    }
    if (d.max_velocity > 0) {
      std::snprintf(l, sizeof l, "max_velocity = %g\n", d.max_velocity);
      out += l;
    }
    if (d.heartbeat_timeout_ms > 0) {
      std::snprintf(l, sizeof l, "heartbeat_timeout_ms = %g\n", d.heartbeat_timeout_ms);
      out += l;
    }
    if (d.quick_stop_decel > 0) {
      std::snprintf(l, sizeof l, "quick_stop_decel = %.17g\n", d.quick_stop_decel);
      out += l;
    }
  }
  return out;
}

}  // namespace servoarm::fw
