#pragma once
// armfw configuration: defaults, TOML loading (toml11) and validation.
// Set-up code only. Every key, its default and its range are listed in
// kConfigKeys (and in the README); a bad file is refused naming the key.
#include <cstdint>
#include <string>
#include <vector>

namespace servoarm::fw {

/// One `[[drive]]` table: the drive of one joint (chain order). Unset fields
/// (NaN / 0 / empty) take the [bus] defaults and the robot description's limits.
struct DriveConfig {
  int node = 0;                          ///< CANopen node id; 0 = bus.first_node + joint index
  double counts_per_rev = 0;             ///< 0 = bus.counts_per_rev (counts per mm for prismatic joints)
  double gear_ratio = 0;                 ///< 0 = bus.gear_ratio
  int direction = 1;                     ///< +1 / -1 between joint and drive
  std::int64_t zero_offset = 0;          ///< drive counts at joint zero
  std::vector<double> limits;            ///< {lower, upper} deg / mm; empty = the description's
  double max_velocity = 0;               ///< deg/s or mm/s; 0 = the description's
  double heartbeat_timeout_ms = 0;       ///< 0 = bus.heartbeat_timeout_ms
  double quick_stop_decel = 0;           ///< deg/s^2 or mm/s^2 written to 6085h; 0 = leave the drive's
};

struct FwConfig {
  std::string robot = "puma560";       ///< built-in model name or a description file path
  // [loop]
  double rate_hz = 1000.0;
  int priority = 80;
  int cpu = -1;
  bool lock_memory = true;
  // [bus]
  std::string can = "sim";             ///< "sim" or a SocketCAN interface ("can0", "vcan0")
  int first_node = 1;
  double counts_per_rev = 131072.0;
  double gear_ratio = 1.0;
  double heartbeat_period_ms = 50.0;
  double heartbeat_timeout_ms = 150.0;
  double start_timeout_s = 5.0;
  std::vector<DriveConfig> drives;     ///< [[drive]] tables; empty = defaults for every joint
  // [safety]
  double following_error_deg = 5.0;
  double enable_timeout_s = 2.0;
  double feedback_timeout_ms = 50.0;
  std::string stop = "ramp";           ///< e-stop / fault reaction: "ramp" (controller) or "drive" (CiA 402 quick stop)
  double drive_stop_timeout_s = 2.0;   ///< stop = "drive": power down after this long even if a drive still moves
  // [motion]
  std::vector<double> home_deg;        ///< empty = zeros clamped into the limits
  double joint_speed_pct = 50.0;
  double linear_speed_mm_s = 100.0;
  double max_linear_speed_mm_s = 250.0;
  // [console]
  bool console_stdin = true;
  bool console_pty = false;
  std::string console_serial;          ///< "" = none
  int console_baud = 115200;
  std::string console_can;             ///< "" = none, "sim", or a SocketCAN interface
  int console_can_rx_id = 0x7E0;       ///< ISO-TP: requests to armfw
  int console_can_tx_id = 0x7E8;       ///< ISO-TP: armfw's answers
};

struct ConfigKey {
  const char* key;          ///< "section.name"
  const char* default_text;
  const char* doc;
};
/// Every key armfw reads, in file order.
extern const ConfigKey kConfigKeys[];
extern const int kConfigKeyCount;

/// Load a TOML file over the defaults in `cfg`. Returns "" on success, else one
/// line naming the file and the key (unknown key, wrong type, out of range, syntax).
std::string load_config_file(const std::string& path, FwConfig& cfg);
/// Same from text (tests).
std::string load_config_text(const std::string& text, const std::string& origin, FwConfig& cfg);
/// Range checks of every field. "" when valid, else "key: reason".
std::string validate(const FwConfig& cfg);
/// Why `id` cannot be a console ISO-TP id (not 11-bit, or a CANopen id of nodes 1..127), or null.
const char* can_console_id_problem(int id);
/// The effective configuration as TOML (what `config` prints).
std::string to_toml(const FwConfig& cfg);

}  // namespace servoarm::fw
