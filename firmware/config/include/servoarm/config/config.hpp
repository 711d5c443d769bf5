// SPDX-License-Identifier: Apache-2.0
#pragma once
// armfw configuration: defaults, TOML loading (toml11), validation, writing and
// documentation, all produced from ONE key table per TOML shape:
// config_keys() (the top-level keys and the [loop] [bus] [safety] [motion]
// [console] sections) and drive_keys() (the keys of each [[drive]] table).
//
// A key is declared once, in config.cpp: its name, the member it fills, its unit,
// its range and its doc. Its default is the member's initialiser below (read
// through the member pointer, so it is written nowhere else). From the tables
// come: load_config_text() (unknown keys, wrong types and values outside the
// range refuse the file naming the file, the key, the value and the range),
// validate(), to_toml() (what the console's `config` prints), `armfw
// --config-keys`, and the reference section of docs/configuration.md
// (`armfw --config-reference`; a test fails when the committed page differs).
// Set-up code only: nothing here runs on the control thread.
#include <cstdint>
#include <limits>
#include <span>
#include <string>
#include <variant>
#include <vector>

#include "servoarm/hal/bus_load.hpp"

namespace servoarm::kin {
struct Chain;
struct SafetyConfig;
}

namespace servoarm::fw {

/// One entry of drive.sdo: an object the master writes at bring-up and reads back
/// (`["6065h", 0, "u32", 20000]` in the file).
struct SdoEntry {
  int index = 0;        ///< 0x2000..0x9FFF (manufacturer-specific and device profile areas)
  int sub = 0;          ///< 0..255
  std::string type;     ///< "u8", "u16", "u32", "i8", "i16", "i32"
  std::int64_t value = 0;
  bool operator==(const SdoEntry&) const = default;
};
/// Bytes of an SdoEntry type (1, 2, 4), 0 when the type is not one of them.
int sdo_type_size(const std::string& type);
/// True for the signed types (i8, i16, i32).
bool sdo_type_signed(const std::string& type);

/// One `[[drive]]` table: the drive of one joint (chain order). Unset fields
/// (0 / empty) take the [bus] defaults and the robot description's limits.
struct DriveConfig {
  std::string family = "cia402";         ///< the drive family (docs/servo-bus.md): "cia402", "damiao",
                                         ///< "cubemars_mit", "robstride_mit"
  std::string can;                       ///< the CAN interface of this joint's drive; "" = bus.can
  int node = 0;                          ///< CANopen node id / MIT motor id; 0 = bus.first_node + joint index
  // MIT-mode families (docs/mit-motors.md)
  std::string motor;                     ///< motor model ("DM-J4340"); required by the MIT families
  double mit_kp = 30;                    ///< N m/rad, actuator side, sent in every MIT frame
  double mit_kd = 1;                     ///< N m s/rad
  int master_id = 0;                     ///< the id the motor answers on; 0 = the vendor's default
  bool can_fd = false;                   ///< this drive's interface carries CAN FD (all its drives agree)
  double bitrate = 0;                    ///< bit/s of this drive's interface; 0 = bus.bitrate (all its drives agree)
  double data_bitrate = 0;               ///< CAN FD data bit/s of this drive's interface; 0 = bus.data_bitrate
  double counts_per_rev = 0;             ///< 0 = bus.counts_per_rev (counts per mm for prismatic joints)
  double gear_ratio = 0;                 ///< 0 = bus.gear_ratio
  int direction = 1;                     ///< +1 / -1 between joint and drive
  std::int64_t zero_offset = 0;          ///< drive counts at joint zero
  std::vector<double> limits;            ///< {lower, upper} deg / mm; empty = the description's
  double max_velocity = 0;               ///< deg/s or mm/s; 0 = the description's
  double heartbeat_timeout_ms = 0;       ///< 0 = bus.heartbeat_timeout_ms
  double quick_stop_decel = 0;           ///< deg/s^2 or mm/s^2 written to 6085h; 0 = leave the drive's
  // homing (docs/configuration.md#homing; hal::HomingSpec): joint units deg (mm)
  /// "none" = absolute encoder (written "absolute" in the file), "hard_stop", or a CiA 402 6098h
  /// method ("19"). Required in every [[drive]] of a real bus (bus.can not "sim").
  std::string homing_method = "none";
  double homing_speed_switch = 10.0;     ///< deg/s: 6099h:01 search for switch; hard_stop: approach speed
  double homing_speed_zero = 1.0;        ///< deg/s: 6099h:02 search for zero
  double homing_acceleration = 100.0;    ///< deg/s^2: 609Ah; hard_stop: approach / back-off acceleration
  double homing_offset = 0.0;            ///< deg: joint position at the home mark (607Ch) / the backed-off point
  double homing_timeout_s = 30.0;        ///< the whole homing of this joint
  int homing_direction = -1;             ///< hard_stop: direction of the approach (+1 / -1)
  double homing_following_limit = 2.0;   ///< deg: hard_stop: |demanded - actual| that means contact
  double homing_torque_limit = 0.0;      ///< N m (N): hard_stop: |torque| that means contact; 0 = unused
  double homing_backoff = 2.0;           ///< deg: hard_stop: distance moved back from the contact
  // dynamics (docs/dynamics.md#using-the-model-in-the-firmware)
  double rated_torque = 0;               ///< N m (N), motor side: the unit of 6071h/6077h/60B2h; 0 = the drive's 6076h
  double collision_threshold = 0;        ///< N m (N), joint side; 0 = dynamics.collision_threshold_pct of the rated torque
  std::vector<SdoEntry> sdo;             ///< objects written at bring-up and read back, in order

  bool operator==(const DriveConfig&) const = default;
};

/// Why an 11-bit id may not be an MIT motor's answer id (drive.master_id) on an interface that
/// also carries CiA 402 drives, or null: CANopen's NMT (0x000), SYNC (0x080) or an EMCY id
/// (0x081..0x0FF), which the CANopen drives read, or the Damiao register id 0x7FF.
const char* mit_id_problem(int id);
struct FwConfig;
/// A CiA 402 drive is on `d`'s interface (drive.can, or bus.can for "").
bool canopen_shares_interface(const FwConfig& c, const DriveConfig& d);
/// The id an MIT motor with drive id `node` answers on: drive.master_id, else the family's
/// default (damiao node + 0x10, robstride_mit 0x0FD, cubemars_mit 0x000).
int mit_master_id(const DriveConfig& d, int node);

/// One [[output]] table: a named digital output, bit `bit` of the 60FEh:01 physical
/// outputs of the drive at CANopen node `node` (`out NAME on|off`, M62..M65 P<index>).
/// Every key is required; the zero values below are "not given" and fail validate().
struct OutputConfig {
  std::string name;   ///< letters, digits, _ and -, starting with a letter
  int node = 0;       ///< a drive of the arm
  int bit = 0;        ///< 16..31: CiA 402 gives bit 0 to "set brake" and reserves 1..15 for the profile
  bool operator==(const OutputConfig&) const = default;
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
  double sdo_timeout_ms = 100.0;       ///< SDO answer timeout (bring-up, homing): hal sdo_timeout
  double boot_timeout_ms = 0.0;        ///< a node still booting is asked again until then; 0 = one attempt
  double boot_retry_ms = 200.0;        ///< time between the boot-up attempts
  double state_timeout_ms = 500.0;     ///< longest a drive may sit in one CiA 402 state while enabling / changing mode
  double bitrate = 1000000.0;          ///< bit/s of the drive bus: the bus-load check (bus_load_problem)
  double data_bitrate = 0.0;           ///< bit/s of CAN FD's data phase (bit-rate switch) on the interfaces
                                       ///< whose drives say drive.can_fd; 0 = their frames counted as classical
  bool tpdo2 = false;                  ///< velocity actual 606Ch + error code 603Fh in TPDO2
  std::vector<DriveConfig> drives;     ///< [[drive]] tables; empty = defaults for every joint
  // [safety]
  double following_error_deg = 5.0;
  double enable_timeout_s = 2.0;
  double feedback_timeout_ms = 50.0;
  std::string stop = "ramp";           ///< e-stop / fault reaction: "ramp" (controller) or "drive" (CiA 402 quick stop)
  double drive_stop_timeout_s = 2.0;   ///< stop = "drive": power down after this long even if a drive still moves
  // [safety] envelope (docs/safety.md): base frame, mm / deg / mm/s
  std::vector<double> safety_planes;     ///< nx, ny, nz, offset_mm per plane; [] = none
  std::vector<double> safety_keep_in;    ///< xmin, ymin, zmin, xmax, ymax, zmax (mm) per box
  std::vector<double> safety_keep_out;   ///< same
  double safety_tool_radius_mm = 0.0;    ///< the sphere around the TCP
  int safety_elbow_frame = -1;           ///< frame (0 = base, k = after DH row k) of the elbow sphere; -1 = none
  double safety_elbow_radius_mm = 0.0;
  std::vector<double> safety_cone_axis;  ///< x, y, z; [] = no orientation limit
  double safety_cone_deg = 180.0;        ///< half-angle of the orientation cone (Normal mode)
  double safety_tcp_speed_mm_s = 0.0;    ///< 0 = none
  double safety_elbow_speed_mm_s = 0.0;  ///< 0 = none
  double safety_reduced_tcp_speed_mm_s = 0.0;
  double safety_reduced_elbow_speed_mm_s = 0.0;
  double safety_reduced_cone_deg = 180.0;
  std::vector<double> safety_joint_speed_deg_s;          ///< per joint, deg/s (mm/s prismatic), 0 = none; [] = none
  std::vector<double> safety_reduced_joint_speed_deg_s;  ///< same, Reduced mode
  double safety_stop_time_s = 0.0;               ///< the predicted stop's duration, Normal mode; 0 = none
  double safety_stop_distance_mm = 0.0;          ///< the TCP's travel during the predicted stop, Normal; 0 = none
  double safety_reduced_stop_time_s = 0.0;
  double safety_reduced_stop_distance_mm = 0.0;
  double safety_momentum_kg_m_s = 0.0;           ///< the links' mass x COM speed, summed, Normal; 0 = none
  double safety_power_w = 0.0;                   ///< the joints' |torque x velocity|, summed, Normal; 0 = none
  double safety_reduced_momentum_kg_m_s = 0.0;
  double safety_reduced_power_w = 0.0;
  double safety_tolerance_mm = 2.0;      ///< run-time monitor margin of planes and boxes
  double safety_tolerance_deg = 2.0;     ///< run-time monitor margin of the cone
  double safety_tolerance_mm_s = 20.0;   ///< run-time monitor margin of the speed limits
  double safety_tolerance_deg_s = 2.0;   ///< run-time monitor margin of the joint speed limits (mm/s prismatic)
  double safety_tolerance_s = 0.02;      ///< run-time monitor margin of the stop time limit
  double safety_tolerance_kg_m_s = 0.5;  ///< run-time monitor margin of the momentum limit
  double safety_tolerance_w = 5.0;       ///< run-time monitor margin of the power limit
  // zones in user frames: x, y, z (mm), rx, ry, rz (deg, R = Rz Ry Rx) per zone; [] = base frame
  std::vector<double> safety_plane_frames;     ///< one frame per safety.planes plane
  std::vector<double> safety_keep_in_frames;   ///< one frame per safety.keep_in box
  std::vector<double> safety_keep_out_frames;  ///< one frame per safety.keep_out box
  std::vector<double> safety_reduced_planes;   ///< trigger planes: nx, ny, nz, offset_mm; Reduced beyond one
  std::vector<double> safety_reduced_plane_frames;  ///< one frame per safety.reduced_planes plane
  bool safety_self_collision = false;            ///< the description's capsules kept apart pairwise
  double safety_self_collision_margin_mm = 0.0;  ///< least distance between two capsules' surfaces
  std::string safety_estop_input;                ///< "drive:J:bitN", "gpio:CHIP:LINE", "sim:NAME"; "" = none
  std::string safety_estop_input_active = "low"; ///< the level that means stop: "low" or "high"
  std::string safety_reduced_input;              ///< as safety_estop_input: Reduced mode while asserted
  std::string safety_reduced_input_active = "low";
  double safety_input_debounce_ms = 10.0;        ///< released this long before a release counts
  double safety_input_timeout_ms = 100.0;        ///< a reading older than this: the input is lost
  // [motion]
  std::vector<double> home_deg;        ///< empty = zeros clamped into the limits
  double joint_speed_pct = 50.0;
  double linear_speed_mm_s = 100.0;
  double max_linear_speed_mm_s = 250.0;
  double max_move_duration_s = 600.0;  ///< longest move the console accepts (longer: out_of_range)
  double default_blend_mm = 0.0;       ///< movel / G1 blend tolerance without blend=; 0 = exact stop
  double default_blend_deg = 0.0;      ///< movej blend tolerance without blend=; 0 = exact stop
  // [homing]
  std::vector<std::vector<int>> homing_order;  ///< groups of 1-based joints, run one after the other; [] = one group of all
  double homing_unhomed_jog_pct = 25.0;  ///< joint jogs of an unhomed arm run at this percent of the speed asked
  double homing_travel_margin_deg = 10.0;  ///< deg (mm): homing fails beyond the joint's range + this from its start
  // [dynamics]: the model in the control loop; every part off by default (the frames of before)
  std::string feed_forward = "off";    ///< "off", "velocity" (60B1h), "torque" (60B1h + model torque 60B2h)
  bool collision = false;              ///< momentum observer on the measured torque (6077h)
  double collision_gain = 100.0;       ///< 1/s: the observer's bandwidth
  double collision_sensitivity = 1.0;  ///< thresholds / sensitivity
  double collision_threshold_pct = 15.0;  ///< % of a joint's rated torque (joint side) without drive.collision_threshold
  bool freedrive = false;              ///< map cyclic synchronous torque (CST) for `freedrive on`
  double freedrive_damping = 10.0;     ///< 1/s x the joint's largest inertia: virtual damping in free-drive
  // [console]
  bool console_stdin = true;
  bool console_pty = false;
  std::string console_serial;          ///< "" = none
  int console_baud = 115200;
  std::string console_can;             ///< "" = none, "sim", or a SocketCAN interface
  int console_can_rx_id = 0x7E0;       ///< ISO-TP: requests to armfw
  int console_can_tx_id = 0x7E8;       ///< ISO-TP: armfw's answers
  std::string console_dialect = "native";  ///< "native" or "grbl" (GRBL 1.1 for G-code senders): every transport
  std::string console_pty_dialect;     ///< "" = console.dialect
  std::string console_serial_dialect;  ///< "" = console.dialect
  double console_jog_deadman_ms = 250.0;  ///< a continuous jog not refreshed this long stops
  double console_jog_speed_pct = 10.0;    ///< jog speed without speed=
  std::string console_frames_file = "frames.toml";  ///< tools and user frames; relative: to the config file's folder; "" = not kept
  std::vector<OutputConfig> outputs;  ///< [[output]] tables, in file order (M62..M65 P = index)
  // [programs]
  std::string programs_dir = "programs";              ///< program files (`run`, `programs`, `record stop`); relative: to the config file's folder; "" = none
  std::string programs_points_file = "points.toml";   ///< teach points; relative: to the config file's folder; "" = not kept
  // [api] (the network API, docs/api.md)
  bool api_enabled = false;              ///< serve the API (armfw --api-ws / --api-tcp turn it on too)
  std::string api_bind = "127.0.0.1";    ///< listen address; beyond loopback only with api_tokens_file
  int api_ws_port = 8765;                ///< WebSocket port; 0 = off
  int api_tcp_port = 8766;               ///< newline-delimited JSON port; 0 = off
  std::string api_tokens_file;           ///< "<role> <token>" lines; "" = none (loopback only, every client an operator)
  int api_max_message_kb = 64;           ///< longest message
  double api_max_rate_hz = 2000.0;       ///< messages per second per client
  int api_max_clients = 64;              ///< connections at once
  int api_client_buffer_kb = 1024;       ///< unsent output per client before its streams drop
  double api_stream_deadman_ms = 100.0;  ///< streaming targets: none this long, the arm brakes to rest
  double api_stream_max_step_deg = 30.0; ///< largest change of a joint between two targets (deg / mm); 0 = none
  std::string api_stream_step = "clamp"; ///< a larger step: "clamp" or "refuse"
  int api_partial_timeout_s = 10;        ///< a message begun and not ended this long: the connection is closed
  std::string api_tls_cert;              ///< TLS on the API's ports: the certificate (PEM); "" = plain
  std::string api_tls_key;               ///< its private key (PEM)

  // [mqtt]: the MQTT bridge (docs/api.md#mqtt)
  bool mqtt_enabled = false;             ///< connect to the broker, publish state / events, take commands
  std::string mqtt_host = "127.0.0.1";   ///< the broker
  int mqtt_port = 1883;
  std::string mqtt_name = "arm";         ///< topics under servoarm/<name>/
  std::string mqtt_username;             ///< "" none
  std::string mqtt_password_file;        ///< the password's file (first line); "" none
  std::string mqtt_cafile;               ///< TLS to the broker with this CA (PEM); "" plain TCP
  std::string mqtt_certfile;             ///< TLS client certificate (PEM); "" none
  std::string mqtt_keyfile;              ///< its key (PEM)
  double mqtt_state_rate_hz = 10.0;      ///< state samples published per second
  int mqtt_keepalive_s = 10;             ///< keep-alive: the broker publishes the last will after 1.5 x this

  // [record]: MCAP recordings (`record mcap`, docs/foxglove-mcap.md)
  std::string record_dir;                ///< the recordings folder; relative: to the config file's folder; "" = none
  double record_rate_hz = 100.0;         ///< state samples per second without rate=
  double record_max_file_mb = 256.0;     ///< a file reaching this size is closed and the next begun
  int record_max_files = 0;              ///< files of one recording at most; 0 = no limit
  int record_chunk_kb = 256;             ///< MCAP chunk size

  // [foxglove]: the Foxglove WebSocket server (docs/foxglove-mcap.md)
  bool foxglove_enabled = false;         ///< serve live data to Foxglove / Lichtblick
  std::string foxglove_bind = "127.0.0.1";
  int foxglove_port = 8767;               ///< not 8765 (Foxglove's usual port): api.ws_port has it
  double foxglove_state_rate_hz = 50.0;  ///< joint states and the tool pose per second
  double foxglove_tf_rate_hz = 30.0;     ///< link transforms per second

  bool operator==(const FwConfig&) const = default;
};

/// One key of a table over struct S (FwConfig or DriveConfig). Built with the
/// chained setters below, e.g.
///   Key<FwConfig>{"loop.rate_hz", &FwConfig::rate_hz, "Hz", "control rate"}.within(250, 4000)
/// Numbers are refused when not finite, outside [lo, hi] (either end may be open),
/// or not one of `one_of` when that is given; strings by length or `one_of_text`;
/// lists by element count and each element's range. `relation` checks what
/// depends on other keys; `rule` replaces the generated range text (docs and errors).
template <class S>
struct Key {
  using Member =
      std::variant<bool S::*, int S::*, std::int64_t S::*, double S::*, std::string S::*, std::vector<double> S::*,
                   std::vector<std::vector<int>> S::*, std::vector<SdoEntry> S::*>;
  /// Returns "" or why the value is refused ("must be above bus.heartbeat_period_ms (50)").
  using Relation = std::string (*)(const S& s, const FwConfig& whole);

  const char* name;   ///< "motion.linear_speed_mm_s" (FwConfig) or "gear_ratio" (DriveConfig)
  Member member;
  const char* unit;   ///< "mm/s", "" when the value has no unit
  const char* doc;
  double lo = -std::numeric_limits<double>::infinity();
  double hi = std::numeric_limits<double>::infinity();
  bool lo_open = false, hi_open = false;
  std::span<const double> one_of{};            ///< numbers: the only values allowed
  std::span<const char* const> one_of_text{};  ///< strings: the only values allowed
  std::size_t min_len = 0, max_len = 4096;     ///< strings: bytes; lists: elements
  const char* rule = nullptr;                  ///< hand-written allowed-values text
  Relation relation = nullptr;
  const char* relation_text = nullptr;         ///< shown after the range ("above bus.heartbeat_period_ms")
  bool hex = false;                            ///< integers written as 0x...
  bool or_integer = false;                     ///< strings: an integer is accepted too (kept as its decimal text,
                                               ///< written back unquoted): homing.method = 19 or "none"
  bool required = false;                       ///< the table must write it (no default)
  const char* spelled = nullptr;               ///< strings: the file's word for the member value `stored`
  const char* stored = nullptr;                ///< ("absolute" in the file is "none" in DriveConfig)
  bool has_unset = false;                      ///< a value meaning "not set: inherit" (lists: empty)
  double unset = 0;
  bool unset_writable = false;                 ///< may the file write the unset value itself?
  const char* unset_text = nullptr;            ///< what an unset key means ("bus.gear_ratio")

  constexpr Key(const char* n, Member m, const char* u, const char* d) : name(n), member(m), unit(u), doc(d) {}
  constexpr Key within(double l, double h) const { Key k = *this; k.lo = l; k.hi = h; return k; }
  constexpr Key above(double l, double h) const { Key k = within(l, h); k.lo_open = true; return k; }   ///< (l, h]
  constexpr Key below(double l, double h) const { Key k = within(l, h); k.hi_open = true; return k; }   ///< [l, h)
  constexpr Key among(std::span<const double> v) const { Key k = *this; k.one_of = v; return k; }
  constexpr Key among(std::span<const char* const> v) const { Key k = *this; k.one_of_text = v; return k; }
  constexpr Key length(std::size_t a, std::size_t b) const { Key k = *this; k.min_len = a; k.max_len = b; return k; }
  constexpr Key rule_text(const char* r) const { Key k = *this; k.rule = r; return k; }
  constexpr Key related(Relation f, const char* text) const { Key k = *this; k.relation = f; k.relation_text = text; return k; }
  constexpr Key in_hex() const { Key k = *this; k.hex = true; return k; }
  constexpr Key integer_too() const { Key k = *this; k.or_integer = true; return k; }
  /// The key has no default: a table that leaves it out is refused naming it.
  constexpr Key needed() const { Key k = *this; k.required = true; return k; }
  /// Strings: the file writes `file` for the member value `member` (both are read).
  constexpr Key spelled_as(const char* file, const char* member) const {
    Key k = *this; k.spelled = file; k.stored = member; return k;
  }
  /// `value` (lists: empty) means "inherit `text`"; `writable`: a file may write it.
  constexpr Key unset_means(double value, const char* text, bool writable) const {
    Key k = *this; k.has_unset = true; k.unset = value; k.unset_text = text; k.unset_writable = writable; return k;
  }
};
using ConfigKey = Key<FwConfig>;
using DriveKey = Key<DriveConfig>;
using OutputKey = Key<OutputConfig>;

/// Every top-level and [section] key, in file order.
std::span<const ConfigKey> config_keys();
/// Every key of a [[drive]] table, in file order.
std::span<const DriveKey> drive_keys();
/// Every key of an [[output]] table.
std::span<const OutputKey> output_keys();

/// A key's value in `s` as TOML ("1000", "0x7E0", "\"sim\"", "[-90, 45]").
std::string value_text(const ConfigKey& k, const FwConfig& s);
std::string value_text(const DriveKey& k, const DriveConfig& s);
/// The allowed values as text ("[0.01, 5000]", "1..127", "\"ramp\" or \"drive\"").
std::string range_text(const ConfigKey& k);
std::string range_text(const DriveKey& k);
/// The default as text: the value in FwConfig{} / DriveConfig{}, or what "unset" inherits.
std::string default_text(const ConfigKey& k);
std::string default_text(const DriveKey& k);

/// Load a TOML file over the defaults in `cfg`. Returns "" on success, else one
/// line naming the file and the key (unknown key, wrong type, out of range, syntax).
/// A read error, a directory, a FIFO, a device or a file over 64 KiB is refused naming the path;
/// text that is not UTF-8 or nests brackets deeper than 32 levels is refused before toml11 parses it.
/// A file that does not write loop.rate_hz on a checked bus (bus_load_checked()) with [[drive]]
/// tables gets the highest of 1000, 800, 500, 400, 250 Hz whose bus load is at most
/// kBusLoadWarn (else at most kBusLoadLimit; else 250 Hz, refused by the load check).
std::string load_config_file(const std::string& path, FwConfig& cfg, bool check_bus_load = true);
/// Same from text (tests). `cfg` is untouched when the text is refused.
std::string load_config_text(const std::string& text, const std::string& origin, FwConfig& cfg,
                             bool check_bus_load = true);
/// Range checks of every key (table order, first problem), then the bus load (below) with the
/// [[drive]] tables' count as the joint count. "" when valid, else "key: reason (got value)".
/// `check_bus_load` false: the load is left out (armfw --bus-load shows a refused one).
std::string validate(const FwConfig& cfg, bool check_bus_load = true);

// --- Bus load (docs/deployment.md#bus-load) ----------------------------------------
/// Refused above this share of bus.bitrate, warned above kBusLoadWarn.
inline constexpr double kBusLoadLimit = 0.85;
inline constexpr double kBusLoadWarn = 0.60;
/// The cyclic traffic `cfg` sets up with `joints` drives (what CanopenServoBus maps for it:
/// RPDO1/TPDO1, RPDO2 for dynamics.feed_forward / freedrive, RPDO3 for [[output]]s, TPDO2
/// for bus.tpdo2 / dynamics.collision / hard_stop torque, SYNC, heartbeats).
hal::BusTraffic bus_traffic(const FwConfig& cfg, std::size_t joints);
/// True when the load is checked: bus.can is a wire (not "sim", not a virtual "vcan*").
bool bus_load_checked(const FwConfig& cfg);
/// "" or why `cfg` with `joints` drives is refused: the load above kBusLoadLimit, naming
/// bus.bitrate (or drive.bitrate), loop.rate_hz, the frames per cycle, the load and the highest
/// rate that fits. With [[drive]] tables each interface they use is checked with its own traffic
/// and rates (interface_bitrate, interface_data_bitrate); a drive.can other than bus.can is named.
std::string bus_load_problem(const FwConfig& cfg, std::size_t joints);
/// The nominal bit rate of interface `iface` (bus.can or a drive.can): the drive.bitrate its
/// drives give (validate() makes them agree), else bus.bitrate.
double interface_bitrate(const FwConfig& cfg, const std::string& iface);
/// The CAN FD data bit rate the load of `iface` is counted with: 0 (classical frames) when its
/// drives do not say drive.can_fd, else their drive.data_bitrate, else bus.data_bitrate.
double interface_data_bitrate(const FwConfig& cfg, const std::string& iface);
/// "" or the warning for a load above kBusLoadWarn (and at most kBusLoadLimit).
std::string bus_load_warning(const FwConfig& cfg, std::size_t joints);
/// What `armfw --config FILE --bus-load` prints: one table per interface with drives (the
/// traffic and rates the check counts; its family, bit rates, drive count in the title), each
/// with one line per frame kind (direction, frames per cycle, bits per frame with worst-case
/// stuffing, load), the two directions, the total and the verdict; tables apart by a blank line.
std::string bus_load_table(const FwConfig& cfg, std::size_t joints);
/// The table of docs/deployment.md (`armfw --bus-load-reference`): the load of the default
/// traffic by loop rate and joint count at 1 Mbit/s and 500 kbit/s, between its markers.
std::string bus_load_reference_markdown();
/// "" when `page` holds exactly bus_load_reference_markdown() between its markers, else why not.
std::string bus_load_reference_mismatch(const std::string& page);
/// Checks that need the robot: homing.order names every joint exactly once (when given),
/// motion.home_deg has one value per joint within the
/// joint's limits (the description's, narrowed by drive.limits), drive.limits lie
/// within the description's, [[drive]] count, every joint's range fits the drive's
/// 32-bit position at its scaling, one count is finer than the following-error limit,
/// and the joint's maximum velocity fits 32-bit counts/s. "" when fine, else "key: reason".
std::string validate_for_chain(const FwConfig& cfg, const kin::Chain& chain);
/// The [safety] checks that need the robot (part of validate_for_chain): the envelope builds
/// (safety_envelope), safety.elbow_frame is a frame of the chain, and the park pose
/// (motion.home_deg, else zeros clamped into the limits) lies inside the planes and boxes.
std::string safety_for_chain(const FwConfig& cfg, const kin::Chain& chain);
/// Why `id` cannot be a console ISO-TP id (not 11-bit, or a CANopen id of nodes 1..127), or null.
const char* can_console_id_problem(int id);
/// drive.homing.method as a number: 1..35, 37 or -128..-1 (CiA 402 6098h); 0 for "none" / "hard_stop" / not a method.
int homing_method_number(const std::string& method);
/// The [safety] envelope of `cfg` in SI for the kinematics core (normals normalised; the
/// per-joint values in rad or m by `chain`'s joint types). Returns "" or why it cannot be
/// built (one line naming the key); `out` is then disabled.
std::string safety_envelope(const FwConfig& cfg, const kin::Chain& chain, kin::SafetyConfig& out);
/// The canonical form of the [safety] section: one `key = value` line per key of the
/// table's safety.* rows, in table order, values as to_toml writes them.
std::string safety_canonical(const FwConfig& cfg);
/// CRC-32 (IEEE 802.3) of safety_canonical().
std::uint32_t safety_checksum(const FwConfig& cfg);
/// The description's part of the safety configuration: its self-collision capsules (mm) and
/// the pairs checked, one line each; "" for a description without capsules.
std::string safety_description_canonical(const kin::Chain& chain);
/// CRC-32 of safety_canonical() followed by safety_description_canonical(): what `status`
/// shows as the safety checksum (equal to safety_checksum(cfg) for a robot without capsules).
std::uint32_t safety_checksum(const FwConfig& cfg, const kin::Chain& chain);

/// The effective configuration as TOML (what `config` prints); loads back to `cfg`.
/// Unset [[drive]] keys are left out.
std::string to_toml(const FwConfig& cfg);

/// What `armfw --config-keys` prints: one line per key (name, default, range, unit, doc).
std::string config_keys_text();
/// What `armfw --config-reference` prints: the generated section of
/// docs/configuration.md, from its BEGIN marker line to its END marker line.
std::string config_reference_markdown();
/// "" when `page` holds exactly config_reference_markdown() between its markers,
/// else what differs (first differing line of each, with line numbers) and how to regenerate.
std::string config_reference_mismatch(const std::string& page);

}  // namespace servoarm::fw
