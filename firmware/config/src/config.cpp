// SPDX-License-Identifier: Apache-2.0
#include "servoarm/config/config.hpp"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include "servoarm/hal/mit.hpp"
#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/orientation.hpp"
#include "servoarm/hal/safety_input.hpp"
#include "servoarm/kinematics/safety.hpp"
#include "servoarm/kinematics/io/file_input.hpp"
#include "servoarm/lang/markdown.hpp"
#include "servoarm/lang/units.hpp"

namespace servoarm::fw {

// ---------------------------------------------------------------------------
// The key tables. One entry per key; the default is the member's initialiser in
// config.hpp. Ranges are closed unless `above` (open low end) or `below` (open
// high end) says otherwise.
// ---------------------------------------------------------------------------
namespace {

constexpr double kBauds[] = {9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600};
constexpr double kDirections[] = {1, -1};
constexpr const char* kStops[] = {"ramp", "drive"};
constexpr const char* kInputLevels[] = {"low", "high"};
constexpr const char* kDriveFamilies[] = {"cia402", "damiao", "cubemars_mit", "robstride_mit"};
constexpr const char* kDialects[] = {"native", "grbl"};
constexpr const char* kTransportDialects[] = {"", "native", "grbl"};
constexpr const char* kFeedForward[] = {"off", "velocity", "torque"};
constexpr double kTwo31 = 2147483648.0;  // counts_per_rev below 2^31: a revolution fits the drive's int32 position
constexpr double kMaxLength = 1e5;       // deg or mm: |limits| and |home| (277 turns, 100 m)

std::string num_text(double v);
std::string toml_string(const std::string& s);

// Relations between keys. validate() runs them only once every key is within its own
// range, so the values here are finite (no ordered compare with NaN) and a bad value
// is named by its own key, not by the key it is compared with.
std::string bus_heartbeat_above_period(const FwConfig& c, const FwConfig&) {
  if (c.heartbeat_timeout_ms > c.heartbeat_period_ms) return "";
  return "must be above bus.heartbeat_period_ms (" + num_text(c.heartbeat_period_ms) + ")";
}
std::string data_bitrate_not_below_nominal(const FwConfig& c, const FwConfig&) {
  if (c.data_bitrate == 0 || c.data_bitrate >= c.bitrate) return "";
  return "must be at least bus.bitrate (" + num_text(c.bitrate) + "), or 0";
}
std::string boot_timeout_within_start(const FwConfig& c, const FwConfig&) {
  if (c.boot_timeout_ms <= c.start_timeout_s * 1000.0) return "";
  return "must be at most bus.start_timeout_s (" + num_text(c.start_timeout_s) + " s), which bounds the whole bring-up";
}
std::string linear_speed_at_most_max(const FwConfig& c, const FwConfig&) {
  if (c.linear_speed_mm_s <= c.max_linear_speed_mm_s) return "";
  return "must be at most motion.max_linear_speed_mm_s (" + num_text(c.max_linear_speed_mm_s) + ")";
}
// [safety] lists: whole groups, normals and axes not zero, boxes not inverted, keep-in boxes
// wider than the tool sphere.
std::string safety_groups(const std::vector<double>& v, std::size_t n) {
  if (v.size() % n == 0) return "";
  return "needs groups of " + std::to_string(n) + " numbers (got " + std::to_string(v.size()) + ")";
}
std::string safety_planes_ok(const FwConfig& c, const FwConfig&) {
  if (std::string bad = safety_groups(c.safety_planes, 4); !bad.empty()) return bad;
  for (std::size_t i = 0; i + 3 < c.safety_planes.size(); i += 4) {
    const double* p = &c.safety_planes[i];
    if (p[0] * p[0] + p[1] * p[1] + p[2] * p[2] < 1e-18) return "plane " + std::to_string(i / 4) + ": zero normal";
  }
  return "";
}
std::string safety_boxes_ok(const std::vector<double>& v, double radius_mm) {
  if (std::string bad = safety_groups(v, 6); !bad.empty()) return bad;
  for (std::size_t i = 0; i + 5 < v.size(); i += 6)
    for (std::size_t a = 0; a < 3; ++a) {
      const char axis = static_cast<char>('x' + a);
      if (v[i + a] > v[i + 3 + a])
        return "box " + std::to_string(i / 6) + ": inverted (" + axis + "min " + num_text(v[i + a]) + " above " +
               axis + "max " + num_text(v[i + 3 + a]) + ")";
      if (radius_mm >= 0 && v[i + 3 + a] - v[i + a] < 2.0 * radius_mm)
        return "box " + std::to_string(i / 6) + ": narrower along " + axis + " (" + num_text(v[i + 3 + a] - v[i + a]) +
               " mm) than the tool sphere (safety.tool_radius_mm " + num_text(radius_mm) + ")";
    }
  return "";
}
std::string safety_keep_in_ok(const FwConfig& c, const FwConfig&) {
  return safety_boxes_ok(c.safety_keep_in, c.safety_tool_radius_mm);
}
std::string safety_keep_out_ok(const FwConfig& c, const FwConfig&) { return safety_boxes_ok(c.safety_keep_out, -1); }
std::string safety_cone_axis_ok(const FwConfig& c, const FwConfig&) {
  const auto& a = c.safety_cone_axis;
  if (a.empty()) return "";
  if (a.size() != 3) return "needs 3 numbers or none (got " + std::to_string(a.size()) + ")";
  if (a[0] * a[0] + a[1] * a[1] + a[2] * a[2] < 1e-18) return "zero axis";
  return "";
}
// A zone list's frames: none, or one frame (6 numbers) per zone of `zones` (group size `per`).
std::string safety_frames_ok(const std::vector<double>& frames, const std::vector<double>& zones, std::size_t per,
                             const char* key) {
  if (frames.empty()) return "";
  const std::size_t n = zones.size() / per;
  if (frames.size() == 6 * n) return "";
  return "needs 6 numbers (x, y, z, rx, ry, rz) per zone of " + std::string(key) + " (" + std::to_string(n) +
         " zones: " + std::to_string(6 * n) + " numbers), got " + std::to_string(frames.size());
}
std::string safety_plane_frames_ok(const FwConfig& c, const FwConfig&) {
  return safety_frames_ok(c.safety_plane_frames, c.safety_planes, 4, "safety.planes");
}
std::string safety_reduced_planes_ok(const FwConfig& c, const FwConfig&) {
  if (std::string bad = safety_groups(c.safety_reduced_planes, 4); !bad.empty()) return bad;
  for (std::size_t i = 0; i + 3 < c.safety_reduced_planes.size(); i += 4) {
    const double* p = &c.safety_reduced_planes[i];
    if (p[0] * p[0] + p[1] * p[1] + p[2] * p[2] < 1e-18) return "plane " + std::to_string(i / 4) + ": zero normal";
  }
  return "";
}
std::string safety_reduced_plane_frames_ok(const FwConfig& c, const FwConfig&) {
  return safety_frames_ok(c.safety_reduced_plane_frames, c.safety_reduced_planes, 4, "safety.reduced_planes");
}
std::string safety_keep_in_frames_ok(const FwConfig& c, const FwConfig&) {
  return safety_frames_ok(c.safety_keep_in_frames, c.safety_keep_in, 6, "safety.keep_in");
}
// [safety] inputs: a source the parser takes (hal/safety_input.hpp)
std::string safety_input_ok(const std::string& text) {
  hal::InputSource src;
  char err[160];
  return hal::parse_input_source(text, src, err, sizeof err) ? std::string() : std::string(err);
}
std::string safety_estop_input_ok(const FwConfig& c, const FwConfig&) { return safety_input_ok(c.safety_estop_input); }
std::string safety_reduced_input_ok(const FwConfig& c, const FwConfig&) {
  return safety_input_ok(c.safety_reduced_input);
}
std::string safety_keep_out_frames_ok(const FwConfig& c, const FwConfig&) {
  return safety_frames_ok(c.safety_keep_out_frames, c.safety_keep_out, 6, "safety.keep_out");
}
std::string can_rx_id_free(const FwConfig& c, const FwConfig&) {
  const char* why = can_console_id_problem(c.console_can_rx_id);
  return why ? why : "";
}
std::string can_tx_id_free(const FwConfig& c, const FwConfig&) {
  if (const char* why = can_console_id_problem(c.console_can_tx_id)) return why;
  return c.console_can_tx_id == c.console_can_rx_id ? "must differ from console.can_rx_id" : "";
}
std::string drive_heartbeat_above_period(const DriveConfig& d, const FwConfig& c) {
  if (d.heartbeat_timeout_ms > c.heartbeat_period_ms) return "";
  return "must be above bus.heartbeat_period_ms (" + num_text(c.heartbeat_period_ms) + ")";
}
std::string drive_limits_ordered(const DriveConfig& d, const FwConfig&) {
  return d.limits.size() == 2 && !(d.limits[0] < d.limits[1]) ? "lower must be below upper" : "";
}

/// "6065h", "6065H", "0x6065" -> 0x6065; false when it is none of those.
bool sdo_index_of(const std::string& t, int& out) {
  std::string h = t;
  if (h.size() > 2 && h[0] == '0' && (h[1] == 'x' || h[1] == 'X')) h = h.substr(2);
  else if (!h.empty() && (h.back() == 'h' || h.back() == 'H')) h.pop_back();
  else return false;
  if (h.empty() || h.size() > 4) return false;
  unsigned v = 0;
  const auto r = std::from_chars(h.data(), h.data() + h.size(), v, 16);
  if (r.ec != std::errc() || r.ptr != h.data() + h.size()) return false;
  out = static_cast<int>(v);
  return true;
}

/// Why the object `index` may not be in drive.sdo, or null.
const char* sdo_index_problem(int index) {
  if (index < 0x2000 || index > 0x9FFF)
    return "is outside the manufacturer-specific and device profile areas 2000h..9FFFh (the master sets the "
           "communication objects itself)";
  switch (index) {
    case 0x6040: case 0x6060: case 0x607A: case 0x6071: case 0x60B1: case 0x60B2: case 0x60FE:
      return "is written by the master in every cycle or at bring-up (process data / mode)";
    case 0x60C2: return "is written by the master from loop.rate_hz (interpolation period)";
    case 0x6085: return "is drive.quick_stop_decel's";
    case 0x6098: case 0x6099: case 0x609A: case 0x607C: return "is written by the master from drive.homing.*";
    default: return nullptr;
  }
}

std::string sdo_entries_valid(const DriveConfig& d, const FwConfig&) {
  for (std::size_t i = 0; i < d.sdo.size(); ++i) {
    const SdoEntry& e = d.sdo[i];
    char ix[16];
    std::snprintf(ix, sizeof ix, "%04Xh:%d", unsigned(e.index), e.sub);
    const std::string at = "entry " + std::to_string(i + 1) + " (" + ix + "): ";
    if (const char* why = sdo_index_problem(e.index)) return at + "index " + why;
    if (e.sub < 0 || e.sub > 255) return at + "sub-index must be 0..255";
    const int size = sdo_type_size(e.type);
    if (size == 0) return at + "type must be u8, u16, u32, i8, i16 or i32 (got " + toml_string(e.type) + ")";
    const bool sign = sdo_type_signed(e.type);
    const std::int64_t lo = sign ? -(std::int64_t(1) << (8 * size - 1)) : 0;
    const std::int64_t hi = sign ? (std::int64_t(1) << (8 * size - 1)) - 1 : (std::int64_t(1) << (8 * size)) - 1;
    if (e.value < lo || e.value > hi)
      return at + "value " + std::to_string(e.value) + " is outside " + e.type + " (" + std::to_string(lo) + ".." +
             std::to_string(hi) + ")";
    for (std::size_t k = 0; k < i; ++k)
      if (d.sdo[k].index == e.index && d.sdo[k].sub == e.sub)
        return at + "the object is also entry " + std::to_string(k + 1);
  }
  return "";
}

bool mit_family(const std::string& family) { return family != "cia402"; }

/// "DM-J4310-2EC, DM-J4340, DM-J8006 (damiao), AK80-9 (cubemars_mit), RS00 (robstride_mit)"
std::string known_motors() {
  std::string o;
  for (const hal::mit::MotorProfile& p : hal::mit::motor_profiles())
    o += (o.empty() ? "" : ", ") + std::string(p.name) + " (" + hal::mit::to_string(p.vendor) + ")";
  return o;
}
std::string drive_motor_known(const DriveConfig& d, const FwConfig&) {
  if (!mit_family(d.family)) return d.motor.empty() ? "" : "is for the MIT families only (drive.family is \"cia402\")";
  if (d.motor.empty()) return "is required with drive.family = \"" + d.family + "\"; known: " + known_motors();
  const hal::mit::MotorProfile* p = hal::mit::find_profile(d.motor);
  if (p == nullptr) return "unknown motor model \"" + d.motor + "\"; known: " + known_motors();
  if (d.family != hal::mit::to_string(p->vendor))
    return std::string(p->name) + " is a " + hal::mit::to_string(p->vendor) + " motor, not " + d.family;
  return "";
}
std::string drive_mit_kp_in_range(const DriveConfig& d, const FwConfig&) {
  const hal::mit::MotorProfile* p = mit_family(d.family) ? hal::mit::find_profile(d.motor) : nullptr;
  if (p == nullptr || d.mit_kp <= p->kp_max) return "";
  return "must be at most " + num_text(p->kp_max) + ", the " + p->name + "'s KP range";
}
std::string drive_mit_kd_in_range(const DriveConfig& d, const FwConfig&) {
  const hal::mit::MotorProfile* p = mit_family(d.family) ? hal::mit::find_profile(d.motor) : nullptr;
  if (p == nullptr || d.mit_kd <= p->kd_max) return "";
  return "must be at most " + num_text(p->kd_max) + ", the " + p->name + "'s KD range";
}
}  // namespace

const char* mit_id_problem(int id) {
  if (id == 0x000) return "is CANopen's NMT id (0x000)";
  if (id == 0x080) return "is CANopen's SYNC id (0x080)";
  if (id > 0x080 && id <= 0x0FF) return "is a CANopen EMCY id (0x081..0x0FF)";
  if (id == 0x7FF) return "is the Damiao register id (0x7FF)";
  return nullptr;
}

bool canopen_shares_interface(const FwConfig& c, const DriveConfig& d) {
  const std::string& mine = d.can.empty() ? c.can : d.can;
  for (const DriveConfig& o : c.drives)
    if (o.family == "cia402" && (o.can.empty() ? c.can : o.can) == mine) return true;
  return false;
}

int mit_master_id(const DriveConfig& d, int node) {
  if (d.master_id != 0) return d.master_id;
  if (d.family == "damiao") return node + 0x10;
  if (d.family == "robstride_mit") return 0x0FD;
  return 0x000;  // cubemars_mit
}

namespace {
std::string drive_master_id_free(const DriveConfig& d, const FwConfig& c) {
  if (!mit_family(d.family)) return d.master_id == 0 ? "" : "is for the MIT families only (drive.family is \"cia402\")";
  if (d.master_id == 0) return "";
  if (d.master_id == 0x7FF) return "is the Damiao register id (0x7FF)";
  if (const char* why = mit_id_problem(d.master_id); why != nullptr && canopen_shares_interface(c, d))
    return std::string(why) + ", and a CiA 402 drive is on the same interface";
  if (d.node != 0 && d.master_id == d.node) return "must differ from drive.node (the motor's command id)";
  return "";
}

// drive.bitrate / drive.data_bitrate: one value per interface. Each drive's own or inherited
// value is compared with every other drive on its interface (data bit rates among the
// drive.can_fd ones), so the first drive that gives a value the others do not share is named.
const std::string& drive_iface(const FwConfig& c, const DriveConfig& d) { return d.can.empty() ? c.can : d.can; }
std::string drive_index_text(const FwConfig& c, const DriveConfig& d) {
  for (std::size_t i = 0; i < c.drives.size(); ++i)
    if (&c.drives[i] == &d) return "drive[" + std::to_string(i + 1) + "]";
  return "a drive";
}
template <double DriveConfig::*Own, double FwConfig::*Bus>
std::string drive_rate_agrees(const DriveConfig& d, const FwConfig& c, const char* bus_key, bool fd_only) {
  const double mine = d.*Own != 0 ? d.*Own : c.*Bus;
  for (const DriveConfig& o : c.drives) {
    if (&o == &d || drive_iface(c, o) != drive_iface(c, d) || (fd_only && !o.can_fd)) continue;
    const double theirs = o.*Own != 0 ? o.*Own : c.*Bus;
    if (theirs != mine)
      return num_text(d.*Own) + " on " + drive_iface(c, d) + ", but " + drive_index_text(c, o) +
             " on the same interface has " + num_text(theirs) + (o.*Own != 0 ? "" : std::string(" (") + bus_key + ")") +
             ": every drive on one interface gives the same";
  }
  return "";
}
std::string drive_bitrate_agrees(const DriveConfig& d, const FwConfig& c) {
  return drive_rate_agrees<&DriveConfig::bitrate, &FwConfig::bitrate>(d, c, "bus.bitrate", false);
}
std::string drive_data_bitrate_ok(const DriveConfig& d, const FwConfig& c) {
  if (!d.can_fd) return "is for a drive.can_fd interface (classical frames have no data phase)";
  const double nominal = d.bitrate != 0 ? d.bitrate : c.bitrate;
  if (d.data_bitrate < nominal)
    return "must be at least the interface's bit rate (" + num_text(nominal) + "), or 0 (got " + num_text(d.data_bitrate) + ")";
  return drive_rate_agrees<&DriveConfig::data_bitrate, &FwConfig::data_bitrate>(d, c, "bus.data_bitrate", true);
}

std::string homing_order_once(const FwConfig& c, const FwConfig&) {
  std::vector<int> seen;
  for (const auto& g : c.homing_order)
    for (const int j : g) {
      if (std::find(seen.begin(), seen.end(), j) != seen.end())
        return "joint " + std::to_string(j) + " is named twice (each joint in one group, once)";
      seen.push_back(j);
    }
  return "";
}
std::string homing_method_known(const DriveConfig& d, const FwConfig&) {
  if (d.homing_method == "none" || d.homing_method == "hard_stop" || homing_method_number(d.homing_method) != 0) return "";
  return "must be \"absolute\", \"hard_stop\" or a CiA 402 homing method 1..35, 37 or -128..-1 (got " +
         (d.homing_method.empty() ? std::string("\"\"") : d.homing_method) + ")";
}

constexpr const char* kStreamSteps[] = {"clamp", "refuse"};

using K = ConfigKey;
using F = FwConfig;
const ConfigKey kConfigTable[] = {
    K{"robot", &F::robot, "", "built-in model name (`armctl kin models`) or the path of a robot description `.toml`"}
        .length(1, 4095).rule_text("a model name or a path, not empty"),
    K{"loop.rate_hz", &F::rate_hz, "Hz",
      "control rate, and the SYNC rate of the drive bus (written to each drive's 60C2h interpolation period). Left "
      "out on a real bus with [[drive]] tables: the highest of 1000, 800, 500, 400 and 250 Hz whose bus load "
      "(each interface at its own bit rate) stays at most 60 % (400 Hz for 6 drives at 1 Mbit/s)"}
        .within(250, 4000),
    K{"loop.priority", &F::priority, "", "SCHED_FIFO priority of the control thread; 0 = normal scheduling"}.within(0, 99),
    K{"loop.cpu", &F::cpu, "", "pin the control thread to this CPU (e.g. an isolcpus= one); -1 = no affinity"}.within(-1, 1023),
    K{"loop.lock_memory", &F::lock_memory, "", "`mlockall()` all memory at start"},
    K{"bus.can", &F::can, "",
      "`\"sim\"` = virtual CiA 402 drives on the in-process bus, or the SocketCAN interface of the drives (`can0`, `vcan0`)"}
        .length(1, 15).rule_text("\"sim\" or an interface name (1..15 chars)"),
    K{"bus.first_node", &F::first_node, "", "CANopen node id of joint 1; joint k is first_node + k - 1"}.within(1, 127),
    K{"bus.counts_per_rev", &F::counts_per_rev, "counts/rev",
      "encoder counts per motor revolution (per motor mm for prismatic joints)"}.below(1, kTwo31),
    K{"bus.gear_ratio", &F::gear_ratio, "",
      "motor revolutions per joint revolution (motor mm per joint mm); positive: the sign between joint and drive is "
      "drive.direction"}.within(1e-3, 1e5),
    K{"bus.heartbeat_period_ms", &F::heartbeat_period_ms, "ms", "heartbeat period written to every drive (1017h)"}
        .within(1, 10000),
    K{"bus.heartbeat_timeout_ms", &F::heartbeat_timeout_ms, "ms",
      "heartbeat consumer time: a drive silent longer than this faults the arm"}
        .above(0, 60000).related(bus_heartbeat_above_period, "above bus.heartbeat_period_ms"),
    K{"bus.start_timeout_s", &F::start_timeout_s, "s", "time allowed for drive bring-up at start"}.above(0, 120),
    K{"bus.sdo_timeout_ms", &F::sdo_timeout_ms, "ms",
      "how long the master waits for a drive's SDO answer (bring-up, homing); a later answer fails the step naming "
      "the node and the object"}.within(1, 10000),
    K{"bus.boot_timeout_ms", &F::boot_timeout_ms, "ms",
      "a drive that does not answer its first SDO (1000h) is asked again (NMT pre-operational + SDO) every "
      "bus.boot_retry_ms until this long after start, for drives that take seconds to boot; 0 = one attempt"}
        .within(0, 120000).related(boot_timeout_within_start, "at most bus.start_timeout_s"),
    K{"bus.boot_retry_ms", &F::boot_retry_ms, "ms", "time between those boot-up attempts"}.within(10, 10000),
    K{"bus.state_timeout_ms", &F::state_timeout_ms, "ms",
      "longest a drive may sit in one CiA 402 state while being enabled, or show the old mode (6061h) after a mode "
      "change; longer fails it naming the node"}.within(10, 60000),
    K{"bus.bitrate", &F::bitrate, "bit/s",
      "bit rate of the drive bus (bus.can, and every drive.can whose drives give no drive.bitrate), as its "
      "interface is set up (`ip link set can0 type can bitrate 1000000`; "
      "SERVOARM_CAN_BITRATE of the .deb). The cyclic traffic's load at it (`armfw --config FILE --bus-load`, "
      "docs/deployment.md#bus-load) is checked on a real bus (not \"sim\" or a vcan): above 85 % the configuration "
      "is refused, above 60 % armfw warns at start"}
        .within(10000, 1000000),
    K{"bus.data_bitrate", &F::data_bitrate, "bit/s",
      "CAN FD's data bit rate (`ip link set can0 type can bitrate 1000000 dbitrate 5000000 fd on`): on an interface "
      "whose drives say drive.can_fd the bus-load check counts their frames as CAN FD with bit-rate switch, the "
      "arbitration at the interface's bit rate and the data phase at this rate (drive.data_bitrate: another one "
      "per interface); 0 = counted as classical frames (an upper bound)"}
        .within(0, 8000000)
        .related(data_bitrate_not_below_nominal, "0 or at least bus.bitrate"),
    K{"bus.tpdo2", &F::tpdo2, "",
      "map velocity actual 606Ch and error code 603Fh into TPDO2: one more 6-byte frame per drive and cycle. Off: "
      "the velocity is the change of the position between cycles, the error code comes with the drive's EMCY "
      "(dynamics.collision and hard_stop homing with homing.torque_limit send TPDO2 either way, with torque "
      "actual 6077h: velocity and error code then come in it too, 8 bytes)"},
    K{"safety.following_error_deg", &F::following_error_deg, "deg (mm)",
      "largest |commanded - actual| per joint (mm for prismatic joints)"}.above(0, 180),
    K{"safety.enable_timeout_s", &F::enable_timeout_s, "s", "time for every drive to reach operation enabled"}.above(0, 60),
    K{"safety.feedback_timeout_ms", &F::feedback_timeout_ms, "ms",
      "an enabled drive without position feedback this long faults the arm"}.within(1, 10000),
    K{"safety.stop", &F::stop, "",
      "e-stop and fault reaction: `\"ramp\"` = the controller ramps every joint to rest with the full limits, then "
      "powers down; `\"drive\"` = CiA 402 Quick Stop (controlword 0x0002) to every drive in the next cycle, each stops "
      "on its own quick-stop ramp (605Ah/6085h), power-down once all are at rest"}
        .among(std::span<const char* const>(kStops)),
    K{"safety.drive_stop_timeout_s", &F::drive_stop_timeout_s, "s",
      "with stop = \"drive\", and on MIT motors after either stop (they hold the arm, docs/mit-motors.md): power "
      "the drives down after this long if one still reports motion; on MIT motors only the joint that is not at "
      "rest or is pushed out of its hold, the others keep holding"}.within(0.05, 60),
    K{"safety.planes", &F::safety_planes, "mm",
      "safety planes (docs/safety.md), four numbers each: the normal nx, ny, nz (towards the allowed side, any "
      "length but not zero) and the offset along it (mm): the tool sphere (and the elbow sphere) stays where "
      "n.p >= offset, e.g. `[0, 0, 1, 100]` = above a table top at z = 100 mm; `[]` = none"}
        .within(-kMaxLength, kMaxLength).length(0, 4 * kin::kMaxSafetyPlanes)
        .related(safety_planes_ok, "groups of 4, normals not zero"),
    K{"safety.keep_in", &F::safety_keep_in, "mm",
      "keep-in boxes, six numbers each: xmin, ymin, zmin, xmax, ymax, zmax in the base frame (mm); the whole tool "
      "sphere (and the elbow sphere) stays inside every one; `[]` = none"}
        .within(-kMaxLength, kMaxLength).length(0, 6 * kin::kMaxSafetyBoxes)
        .related(safety_keep_in_ok, "groups of 6, min <= max, wider than the tool sphere"),
    K{"safety.keep_out", &F::safety_keep_out, "mm",
      "keep-out boxes (a fixture, a column), six numbers each as safety.keep_in; neither sphere may touch one; "
      "`[]` = none"}
        .within(-kMaxLength, kMaxLength).length(0, 6 * kin::kMaxSafetyBoxes)
        .related(safety_keep_out_ok, "groups of 6, min <= max"),
    K{"safety.tool_radius_mm", &F::safety_tool_radius_mm, "mm",
      "radius of the sphere around the TCP that the planes and boxes restrict"}.within(0, 2000),
    K{"safety.elbow_frame", &F::safety_elbow_frame, "",
      "frame whose origin is the centre of the elbow sphere (0 = base, k = the frame after DH row k); -1 = no elbow "
      "sphere"}.within(-1, kin::kMaxRows),
    K{"safety.elbow_radius_mm", &F::safety_elbow_radius_mm, "mm", "radius of the elbow sphere"}.within(0, 2000),
    K{"safety.cone_axis", &F::safety_cone_axis, "",
      "tool orientation limit: the tool's z axis stays within safety.cone_deg of this direction (x, y, z in the base "
      "frame, any length but not zero), e.g. `[0, 0, -1]` = pointing down; `[]` = no orientation limit"}
        .within(-1e6, 1e6).length(0, 3).related(safety_cone_axis_ok, "3 numbers, not zero"),
    K{"safety.cone_deg", &F::safety_cone_deg, "deg", "half-angle of the orientation cone in Normal mode"}
        .above(0, 180),
    K{"safety.tcp_speed_mm_s", &F::safety_tcp_speed_mm_s, "mm/s",
      "TCP speed limit in Normal mode: moves are planned within it (a line's speed capped, a joint move at a lower "
      "override); the run-time monitor makes a protective stop beyond it plus safety.tolerance_mm_s; 0 = none"}
        .within(0, 10000),
    K{"safety.elbow_speed_mm_s", &F::safety_elbow_speed_mm_s, "mm/s",
      "speed limit of the elbow frame's origin in Normal mode (needs safety.elbow_frame); 0 = none"}.within(0, 10000),
    K{"safety.reduced_tcp_speed_mm_s", &F::safety_reduced_tcp_speed_mm_s, "mm/s",
      "TCP speed limit in Reduced mode; 0 = none"}.within(0, 10000),
    K{"safety.reduced_elbow_speed_mm_s", &F::safety_reduced_elbow_speed_mm_s, "mm/s",
      "elbow speed limit in Reduced mode; 0 = none"}.within(0, 10000),
    K{"safety.reduced_cone_deg", &F::safety_reduced_cone_deg, "deg",
      "half-angle of the orientation cone in Reduced mode"}.above(0, 180),
    K{"safety.joint_speed_deg_s", &F::safety_joint_speed_deg_s, "deg/s (mm/s)",
      "joint speed limits in Normal mode, one per joint (0 = none for that joint), tighter than the joints' motion "
      "limits: moves are planned within them (a joint move at a lower override, a line at a lower speed); the "
      "run-time monitor makes a protective stop naming the joint beyond one plus safety.tolerance_deg_s; `[]` = none"}
        .within(0, 1e6).length(0, kin::kMaxJoints),
    K{"safety.reduced_joint_speed_deg_s", &F::safety_reduced_joint_speed_deg_s, "deg/s (mm/s)",
      "joint speed limits in Reduced mode, one per joint (0 = none for that joint); `[]` = none"}
        .within(0, 1e6).length(0, kin::kMaxJoints),
    K{"safety.stop_time_s", &F::safety_stop_time_s, "s",
      "stopping time limit in Normal mode: the stop predicted from the commanded state, braked on the joints' "
      "limits as a protective stop brakes, lasts at most this long; moves are planned slower to keep it, the "
      "run-time monitor makes a protective stop beyond it plus safety.tolerance_s; 0 = none"}
        .within(0, 60),
    K{"safety.stop_distance_mm", &F::safety_stop_distance_mm, "mm",
      "stopping distance limit in Normal mode: the TCP's straight-line travel during that predicted stop; moves "
      "are planned slower to keep it, the monitor makes a protective stop beyond it plus safety.tolerance_mm; "
      "0 = none"}
        .within(0, 10000),
    K{"safety.reduced_stop_time_s", &F::safety_reduced_stop_time_s, "s", "stopping time limit in Reduced mode; 0 = none"}
        .within(0, 60),
    K{"safety.reduced_stop_distance_mm", &F::safety_reduced_stop_distance_mm, "mm",
      "stopping distance limit in Reduced mode; 0 = none"}.within(0, 10000),
    K{"safety.momentum_kg_m_s", &F::safety_momentum_kg_m_s, "kg m/s",
      "momentum limit in Normal mode: the sum over the links of mass x the speed of its centre of mass (the "
      "description's inertial data); moves are planned slower to keep it, the run-time monitor makes a protective "
      "stop beyond it plus safety.tolerance_kg_m_s; 0 = none"}
        .within(0, 10000),
    K{"safety.power_w", &F::safety_power_w, "W",
      "mechanical power limit in Normal mode: the sum over the joints of |torque x velocity| (inverse dynamics: "
      "inertia, gravity, friction); moves are planned slower to keep it, the monitor makes a protective stop "
      "beyond it plus safety.tolerance_w; 0 = none"}
        .within(0, 1e6),
    K{"safety.reduced_momentum_kg_m_s", &F::safety_reduced_momentum_kg_m_s, "kg m/s",
      "momentum limit in Reduced mode; 0 = none"}.within(0, 10000),
    K{"safety.reduced_power_w", &F::safety_reduced_power_w, "W", "mechanical power limit in Reduced mode; 0 = none"}
        .within(0, 1e6),
    K{"safety.tolerance_mm", &F::safety_tolerance_mm, "mm",
      "how far beyond a plane or box the run-time monitor lets the tool go before a protective stop (plan time "
      "allows none)"}.within(0, 100),
    K{"safety.tolerance_deg", &F::safety_tolerance_deg, "deg",
      "how far beyond the orientation cone the run-time monitor lets the tool turn before a protective stop"}
        .within(0, 30),
    K{"safety.tolerance_mm_s", &F::safety_tolerance_mm_s, "mm/s",
      "how far above a speed limit the run-time monitor lets the TCP or elbow go before a protective stop"}
        .within(0, 1000),
    K{"safety.tolerance_deg_s", &F::safety_tolerance_deg_s, "deg/s (mm/s)",
      "how far above its speed limit the run-time monitor lets a joint go before a protective stop"}
        .within(0, 1000),
    K{"safety.tolerance_s", &F::safety_tolerance_s, "s",
      "how far above the stopping time limit the run-time monitor lets the predicted stop go before a protective "
      "stop"}.within(0, 10),
    K{"safety.tolerance_kg_m_s", &F::safety_tolerance_kg_m_s, "kg m/s",
      "how far above the momentum limit the run-time monitor lets the arm go before a protective stop"}
        .within(0, 10000),
    K{"safety.tolerance_w", &F::safety_tolerance_w, "W",
      "how far above the power limit the run-time monitor lets the arm go before a protective stop"}.within(0, 1e6),
    K{"safety.plane_frames", &F::safety_plane_frames, "mm, deg",
      "the frame each of safety.planes is given in, six numbers per plane: its origin x, y, z (mm) and its "
      "rotation rx, ry, rz (deg, R = Rz(rz) Ry(ry) Rx(rx), as the frames file) in the base frame; the plane's normal "
      "and offset are in that frame; `[]` = every plane in the base frame"}
        .within(-kMaxLength, kMaxLength).length(0, 6 * kin::kMaxSafetyPlanes)
        .related(safety_plane_frames_ok, "none or 6 per plane"),
    K{"safety.keep_in_frames", &F::safety_keep_in_frames, "mm, deg",
      "the frame each of safety.keep_in is given in, six numbers per box as safety.plane_frames: the box is "
      "axis-aligned in it; `[]` = every box in the base frame"}
        .within(-kMaxLength, kMaxLength).length(0, 6 * kin::kMaxSafetyBoxes)
        .related(safety_keep_in_frames_ok, "none or 6 per box"),
    K{"safety.keep_out_frames", &F::safety_keep_out_frames, "mm, deg",
      "the frame each of safety.keep_out is given in, six numbers per box as safety.plane_frames; `[]` = every box "
      "in the base frame"}
        .within(-kMaxLength, kMaxLength).length(0, 6 * kin::kMaxSafetyBoxes)
        .related(safety_keep_out_frames_ok, "none or 6 per box"),
    K{"safety.reduced_planes", &F::safety_reduced_planes, "mm",
      "trigger planes, four numbers each as safety.planes: they restrict nothing, the arm runs in Reduced mode "
      "while the tool sphere reaches beyond one (to the side opposite its normal) and in Normal mode again once it "
      "is wholly back; moves that enter one are planned with the Reduced limits there; `[]` = none"}
        .within(-kMaxLength, kMaxLength).length(0, 4 * kin::kMaxSafetyPlanes)
        .related(safety_reduced_planes_ok, "groups of 4, normals not zero"),
    K{"safety.reduced_plane_frames", &F::safety_reduced_plane_frames, "mm, deg",
      "the frame each of safety.reduced_planes is given in, six numbers per plane as safety.plane_frames; `[]` = "
      "every trigger plane in the base frame"}
        .within(-kMaxLength, kMaxLength).length(0, 6 * kin::kMaxSafetyPlanes)
        .related(safety_reduced_plane_frames_ok, "none or 6 per plane"),
    K{"safety.self_collision", &F::safety_self_collision, "",
      "self-collision check (docs/safety.md#self-collision): the capsules of the robot description (capsule per "
      "[[joint]], base_capsule) and the tool's (from the flange to the TCP, radius the tool sphere's) stay "
      "safety.self_collision_margin_mm apart for every pair of links not joined by one joint (less the "
      "description's self_collision_ignore); moves are refused at plan time naming the pair, the run-time monitor "
      "makes a protective stop when a pair comes closer than the margin less safety.tolerance_mm; needs a "
      "description with capsules"},
    K{"safety.self_collision_margin_mm", &F::safety_self_collision_margin_mm, "mm",
      "least distance between the surfaces of two capsules that safety.self_collision checks"}.within(0, 1000),
    K{"safety.estop_input", &F::safety_estop_input, "",
      "external e-stop input (docs/safety.md#safety-inputs), mapped to the emergency stop: `\"drive:J:bitN\"` = bit "
      "N of joint J's drive's digital inputs (60FDh, CiA 402 drives), `\"gpio:CHIP:LINE\"` = a GPIO line (libgpiod), "
      "`\"sim:NAME\"` = simulated (tests); asserted or unreadable: emergency stop in that cycle (a powered arm), "
      "`enable` and `reset` refused until it is released; not a safety-rated input (wire the contact to the drives' STO through a safety "
      "relay too); `\"\"` = none"}
        .related(safety_estop_input_ok, "drive:J:bitN, gpio:CHIP:LINE or sim:NAME"),
    K{"safety.estop_input_active", &F::safety_estop_input_active, "",
      "the level of safety.estop_input that means stop: `\"low\"` (a normally closed contact: a broken wire "
      "stops) or `\"high\"`"}
        .among(std::span<const char* const>(kInputLevels)),
    K{"safety.reduced_input", &F::safety_reduced_input, "",
      "Reduced-mode input (a light curtain's or area scanner's output, a key switch), sources as "
      "safety.estop_input: asserted or unreadable, the envelope runs with the Reduced limits (moves planned and "
      "monitored so, a running move slowed on its path); released, the mode `safety` set; `\"\"` = none"}
        .related(safety_reduced_input_ok, "drive:J:bitN, gpio:CHIP:LINE or sim:NAME"),
    K{"safety.reduced_input_active", &F::safety_reduced_input_active, "",
      "the level of safety.reduced_input that means Reduced: `\"low\"` or `\"high\"`"}
        .among(std::span<const char* const>(kInputLevels)),
    K{"safety.input_debounce_ms", &F::safety_input_debounce_ms, "ms",
      "a safety input counts as released once it has read released this long without a break (asserting acts in "
      "the cycle it is read)"}.within(0, 1000),
    K{"safety.input_timeout_ms", &F::safety_input_timeout_ms, "ms",
      "a safety input whose last reading is older than this (a drive's 60FDh, a GPIO line's reading thread) cannot "
      "be read: the e-stop input then stops, the Reduced input reduces"}.within(5, 10000),
    K{"motion.home_deg", &F::home_deg, "deg (mm)",
      "park pose for `park` / G28, one value per joint, each within that joint's limits; `[]` = zeros clamped into "
      "the limits"}.within(-kMaxLength, kMaxLength).length(0, kin::kMaxJoints),
    K{"motion.joint_speed_pct", &F::joint_speed_pct, "%",
      "movej / park speed without speed=, percent of each joint's velocity limit"}.within(1, 100),
    K{"motion.linear_speed_mm_s", &F::linear_speed_mm_s, "mm/s", "movel / G1 speed without speed= / F"}
        .within(0.01, 5000).related(linear_speed_at_most_max, "at most motion.max_linear_speed_mm_s"),
    K{"motion.max_linear_speed_mm_s", &F::max_linear_speed_mm_s, "mm/s",
      "highest linear speed: speed= and F are clamped to it; G0 moves at it"}.within(0.01, 5000),
    K{"motion.max_move_duration_s", &F::max_move_duration_s, "s",
      "longest move the console accepts; longer moves are refused with out_of_range"}.within(1, 86400),
    K{"motion.default_blend_mm", &F::default_blend_mm, "mm",
      "blend tolerance of movel / G1 without blend=: how far a corner may be cut to go on without stopping; 0 = "
      "exact stop at every point"}.within(0, 50),
    K{"motion.default_blend_deg", &F::default_blend_deg, "deg",
      "blend tolerance of movej without blend= (per joint); 0 = exact stop at every point"}.within(0, 30),
    K{"homing.order", &F::homing_order, "",
      "homing groups run one after the other, joints inside a group together (1-based joint numbers, e.g. "
      "`[[3], [2], [1], [4, 5, 6]]`: the wrist clear of the table first); `[]` = one group of every joint. Given, it "
      "names every joint exactly once. Joints with homing.method = \"absolute\" count as homed at power-up"}
        .within(1, kin::kMaxJoints).length(0, kin::kMaxJoints)
        .related(homing_order_once, "each joint once"),
    K{"homing.unhomed_jog_pct", &F::homing_unhomed_jog_pct, "%",
      "while a joint is not homed, joint jogs run at this percent of the speed asked (Cartesian moves, tool jogs, "
      "movej, park and G-code moves are refused until every joint is homed)"}.within(1, 100),
    K{"homing.travel_margin_deg", &F::homing_travel_margin_deg, "deg (mm)",
      "supervision of homing travel: a joint's homing fails (homing_error, naming the joint and the distance) once "
      "it stands farther from where its homing began than its range (drive.limits or the description's) plus this, "
      "so a missing switch or hard stop ends there, not at homing.timeout_s. Cover how far the stop or switch lies "
      "outside the limits and the back-off; the joint comes to rest beyond by its braking distance (the homing "
      "acceleration). A joint without finite limits is not supervised"}
        .above(0, 1000),
    K{"dynamics.feed_forward", &F::feed_forward, "",
      "feed-forward sent with every setpoint in CSP (docs/dynamics.md#using-the-model-in-the-firmware): `\"off\"`; "
      "`\"velocity\"` = the setpoint's velocity as velocity offset 60B1h (needs no model); `\"torque\"` = that and "
      "the model torque M(q) qdd + c + g + friction as torque offset 60B2h (needs the robot's inertial data). Maps "
      "RPDO2 at bring-up; when a drive cannot map what the kind needs, feed-forward stays off, said at start naming "
      "the joint"}
        .among(std::span<const char* const>(kFeedForward)),
    K{"dynamics.collision", &F::collision, "",
      "collision detection: a momentum observer on the drives' measured torque (6077h, mapped into TPDO2) against "
      "the model, every cycle while the arm is powered (not during homing or free-drive); a residual above a joint's "
      "threshold stops the arm with fault `collision` naming the joint. Needs inertial data and 6077h on every joint "
      "(else off, said at start)"},
    K{"dynamics.collision_gain", &F::collision_gain, "1/s",
      "the observer's gain K: the residual follows the external torque with time constant 1/K"}.within(1, 1000),
    K{"dynamics.collision_sensitivity", &F::collision_sensitivity, "",
      "every threshold is divided by it: 2 halves them (more sensitive), 0.5 doubles them"}.within(0.1, 10),
    K{"dynamics.collision_threshold_pct", &F::collision_threshold_pct, "%",
      "a joint's collision threshold without drive.collision_threshold: this percent of its rated torque (joint "
      "side: 6076h or drive.rated_torque x gear ratio); at least 1 %: below it the measured torque's own noise and "
      "quantisation (6077h counts per mille) pass the threshold, and the arm faults as soon as it is enabled"}
        .within(1, 300),
    K{"dynamics.freedrive", &F::freedrive, "",
      "hand guiding (`freedrive on|off`): map cyclic synchronous torque (6060h/6061h in the PDOs, target torque 6071h "
      "in RPDO2) on the drives that have it; `freedrive on` then commands gravity and friction compensation only. A "
      "joint without it refuses `freedrive on` naming the joint"},
    K{"dynamics.freedrive_damping", &F::freedrive_damping, "1/s",
      "virtual viscous damping in free-drive, per joint this times the joint's largest inertia (so the arm does not "
      "drift on the model's errors); 0 = none"}.within(0, 100),
    K{"console.stdin", &F::console_stdin, "", "console on stdin/stdout"},
    K{"console.pty", &F::console_pty, "", "open a pseudo-terminal console and print its path"},
    K{"console.serial", &F::console_serial, "", "serial device for a console (e.g. `/dev/ttyS0`); `\"\"` = none"}
        .length(0, 4095).rule_text("a device path or \"\""),
    K{"console.baud", &F::console_baud, "baud", "serial baud rate"}.among(std::span<const double>(kBauds)),
    K{"console.can", &F::console_can, "",
      "console over CAN (ISO-TP): a SocketCAN interface (`can0`, `vcan0`), `\"sim\"` (the in-process bus), `\"\"` = none"}
        .length(0, 15).rule_text("\"\", \"sim\" or an interface name (at most 15 chars)"),
    K{"console.can_rx_id", &F::console_can_rx_id, "", "11-bit CAN id armfw receives console requests on (ISO-TP)"}
        .in_hex().rule_text("an 11-bit id (0x000..0x7FF)")
        .related(can_rx_id_free, "outside the CANopen ids of nodes 1..127 and LSS"),
    K{"console.can_tx_id", &F::console_can_tx_id, "", "11-bit CAN id armfw answers on (ISO-TP)"}
        .in_hex().rule_text("an 11-bit id (0x000..0x7FF)")
        .related(can_tx_id_free, "outside the CANopen ids of nodes 1..127 and LSS, not console.can_rx_id"),
    K{"console.dialect", &F::console_dialect, "",
      "the consoles' language: `\"native\"` (servoarm's) or `\"grbl\"` (GRBL 1.1 for G-code senders such as cncjs: "
      "banner, `$` commands, `error:N`, `<Idle|MPos:...>` reports, the ok of a motion line delayed while the queue is "
      "full); docs/grbl-senders.md"}
        .among(std::span<const char* const>(kDialects)),
    K{"console.pty_dialect", &F::console_pty_dialect, "", "the pty console's language; `\"\"` = console.dialect"}
        .among(std::span<const char* const>(kTransportDialects)),
    K{"console.serial_dialect", &F::console_serial_dialect, "", "the serial console's language; `\"\"` = console.dialect"}
        .among(std::span<const char* const>(kTransportDialects)),
    K{"console.jog_deadman_ms", &F::console_jog_deadman_ms, "ms",
      "a continuous jog stops by itself unless a jog line (or `jog` alone) comes within this time"}.within(20, 5000),
    K{"console.frames_file", &F::console_frames_file, "",
      "where the named tools and user frames are kept (`tool`, `frame`, G10 L2; written atomically); a relative "
      "path is relative to the configuration file's folder; `\"\"` = not kept (also the default of `armfw --sim` "
      "without --config; `armfw --frames FILE` sets it)"}
        .length(0, 4095),
    K{"console.jog_speed_pct", &F::console_jog_speed_pct, "%",
      "jog speed without speed=: percent of the joint limits (joint jog) or of the maximum linear and angular speeds "
      "(tool jog)"}.within(1, 100),
    K{"programs.dir", &F::programs_dir, "",
      "the programs folder: native `.arm` and G-code files for `run NAME`, `programs`, `call` inside programs, and "
      "where `record stop NAME` writes; a relative path is relative to the configuration file's folder; `\"\"` = none "
      "(also the default of `armfw --sim` without --config; `armfw --programs DIR` sets it)"}
        .length(0, 4095),
    K{"programs.points_file", &F::programs_points_file, "",
      "where the teach points are kept (`teach NAME`, `point delete`, `movej @NAME`; format servoarm-points-1, "
      "written atomically, a corrupt or foreign file refused at start naming its line); relative to the "
      "configuration file's folder; `\"\"` = not kept (the default of `armfw --sim` without --config; "
      "`armfw --points FILE` sets it)"}
        .length(0, 4095),
    K{"api.enabled", &F::api_enabled, "",
      "serve the network API (docs/api.md): WebSocket and newline-delimited JSON over TCP; `armfw --api-ws PORT` / "
      "`--api-tcp PORT` turn it on too"},
    K{"api.bind", &F::api_bind, "",
      "the address the API listens on; anything but loopback (`127.0.0.1`, `::1`, `localhost`) needs api.tokens_file"}
        .length(1, 255),
    K{"api.ws_port", &F::api_ws_port, "", "WebSocket port of the API; 0 = off"}.within(0, 65535),
    K{"api.tcp_port", &F::api_tcp_port, "", "TCP port of the API's newline-delimited JSON; 0 = off"}.within(0, 65535),
    K{"api.tokens_file", &F::api_tokens_file, "",
      "the API's tokens: one `<role> <token>` line each (role `observer` or `operator`, a token of at least 16 "
      "characters), the file not readable by others; a client sends its token in `hello`; `\"\"` = none: loopback "
      "only, and every client is an operator; a relative path is relative to the configuration file's folder"}
        .length(0, 4095),
    K{"api.max_message_kb", &F::api_max_message_kb, "KiB", "longest API message; a longer one is refused (overlong)"}
        .within(1, 16384),
    K{"api.max_rate_hz", &F::api_max_rate_hz, "Hz",
      "API messages per second per client; more are refused (rate_limited); stop, hold and estop always run"}
        .within(1, 100000),
    K{"api.max_clients", &F::api_max_clients, "", "API connections at once; more are closed at once"}.within(1, 1000),
    K{"api.client_buffer_kb", &F::api_client_buffer_kb, "KiB",
      "unsent API output per client: beyond it the client's state and event messages are dropped (counted, `dropped`) "
      "and its requests wait until it reads"}
        .within(16, 65536),
    K{"api.stream_deadman_ms", &F::api_stream_deadman_ms, "ms",
      "streaming targets (`stream`): no target within this time and the arm brakes to rest on its limits, the stream "
      "ends with an event"}
        .within(10, 2000),
    K{"api.stream_max_step_deg", &F::api_stream_max_step_deg, "deg",
      "streaming targets: the largest change of a joint from one target to the next (mm for a prismatic joint); "
      "larger steps are clamped or refused (api.stream_step); 0 = no limit (the tracking stays within the joint "
      "limits either way)"}
        .within(0, 360),
    K{"api.stream_step", &F::api_stream_step, "",
      "streaming targets: a step larger than api.stream_max_step_deg is `\"clamp\"`ed to it or `\"refuse\"`d"}
        .among(std::span<const char* const>(kStreamSteps)),
    K{"api.partial_timeout_s", &F::api_partial_timeout_s, "s",
      "an API client that begins a message and does not end it within this time is disconnected (a slow-loris "
      "client holds no connection)"}
        .within(1, 600),
    K{"api.tls_cert", &F::api_tls_cert, "",
      "TLS on the API's ports (WebSocket: wss://, TCP: TLS around the JSON lines): the server's certificate (PEM, "
      "its chain after it); with api.tls_key; a file that cannot be read or loaded refuses the start; `\"\"` = "
      "plain; a relative path is relative to the configuration file's folder"}
        .length(0, 4095),
    K{"api.tls_key", &F::api_tls_key, "",
      "the private key (PEM) of api.tls_cert (keep the file unreadable by others); a relative path is relative to the "
      "configuration file's folder"}
        .length(0, 4095),
    K{"mqtt.enabled", &F::mqtt_enabled, "",
      "the MQTT bridge (docs/api.md#mqtt): state and events published on `servoarm/<mqtt.name>/...`, the API's "
      "messages taken on `servoarm/<mqtt.name>/cmd`, last will `offline`"},
    K{"mqtt.host", &F::mqtt_host, "", "the MQTT broker's host name or address"},
    K{"mqtt.port", &F::mqtt_port, "", "the broker's port (1883 plain, 8883 TLS by convention)"}.within(1, 65535),
    K{"mqtt.name", &F::mqtt_name, "", "this arm's name in the topics: `servoarm/<name>/state` ..."},
    K{"mqtt.username", &F::mqtt_username, "", "user name at the broker; \"\" = none"},
    K{"mqtt.password_file", &F::mqtt_password_file, "",
      "a file whose first line is the broker password (kept out of the configuration); \"\" = none"},
    K{"mqtt.cafile", &F::mqtt_cafile, "", "TLS to the broker, checked against this CA certificate (PEM); \"\" = plain TCP"},
    K{"mqtt.certfile", &F::mqtt_certfile, "", "TLS client certificate (PEM) for a broker that asks for one; \"\" = none"},
    K{"mqtt.keyfile", &F::mqtt_keyfile, "", "the client certificate's key (PEM)"},
    K{"mqtt.state_rate_hz", &F::mqtt_state_rate_hz, "Hz", "state samples published per second"}.within(0.1, 100),
    K{"mqtt.keepalive_s", &F::mqtt_keepalive_s, "s",
      "keep-alive interval: the broker publishes the last will (`offline`) after 1.5 times this without traffic "
      "(libmosquitto takes 5 s at least)"}
        .within(5, 600),
    K{"record.dir", &F::record_dir, "",
      "the folder `record mcap` writes its MCAP files to (`servoarm-<UTC time>-NNN.mcap`, never overwriting one); a "
      "relative path is relative to the configuration file's folder; `\"\"` = none (`armfw --record-dir DIR` sets it)"}
        .length(0, 4095),
    K{"record.rate_hz", &F::record_rate_hz, "Hz",
      "`record mcap` without rate=: state samples per second (the control rate divided by a whole number; at most the "
      "control rate)"}
        .within(1, 4000),
    K{"record.max_file_mb", &F::record_max_file_mb, "MB",
      "an MCAP file reaching this size is closed (summary written) and the next one begun"}
        .within(1, 1000000),
    K{"record.max_files", &F::record_max_files, "",
      "files of one `record mcap` recording at most: the recording ends at the limit; 0 = no limit"}
        .within(0, 100000),
    K{"record.chunk_kb", &F::record_chunk_kb, "KiB",
      "MCAP chunk size; a chunk is also written every second, so a power cut loses at most the last second"}
        .within(4, 65536),
    K{"foxglove.enabled", &F::foxglove_enabled, "",
      "the Foxglove WebSocket server (docs/foxglove-mcap.md): joint states, link transforms, the tool pose and the "
      "events for Foxglove or Lichtblick (`armfw --foxglove-port PORT` turns it on)"},
    K{"foxglove.bind", &F::foxglove_bind, "", "the address the Foxglove server listens on: a loopback address only (the Foxglove protocol carries no authentication; a viewer elsewhere uses an ssh tunnel)"},
    K{"foxglove.port", &F::foxglove_port, "", "the Foxglove server's port (0: any free port, printed)"}.within(0, 65535),
    K{"foxglove.state_rate_hz", &F::foxglove_state_rate_hz, "Hz",
      "joint states and tool pose messages per second (at most the control rate)"}
        .within(0.1, 1000),
    K{"foxglove.tf_rate_hz", &F::foxglove_tf_rate_hz, "Hz", "link transform messages per second"}.within(0.1, 1000),
};

using D = DriveConfig;
using DK = DriveKey;
const DriveKey kDriveTable[] = {
    DK{"family", &D::family, "",
       "the joint's drive family (docs/servo-bus.md#drive-families-groups-and-the-arm): `\"cia402\"` = a CiA 402 "
       "servo drive over CANopen; `\"damiao\"`, `\"cubemars_mit\"`, `\"robstride_mit\"` = an MIT-mode actuator "
       "(docs/mit-motors.md; drive.motor names the model); the joints of one family on one interface form one group"}
        .among(std::span<const char* const>(kDriveFamilies)),
    DK{"can", &D::can, "",
       "the CAN interface of this joint's drive (`can1`); `\"\"` = bus.can. With bus.can = `\"sim\"` every name "
       "is an in-process bus of its own with virtual drives"}
        .length(0, 15).rule_text("\"\" or an interface name (up to 15 chars)"),
    DK{"node", &D::node, "",
       "CANopen node id of this joint's drive, or the MIT motor's CAN id (Damiao ESC_ID); unique on the bus"}
        .within(1, 127).unset_means(0, "bus.first_node + k - 1", false),
    DK{"motor", &D::motor, "",
       "MIT families: the motor model, whose ranges (P_MAX, V_MAX, T_MAX, KP, KD) the frames are packed with "
       "(docs/mit-motors.md#motor-models): DM-J4310-2EC, DM-J4340, DM-J8006 (damiao), AK80-9 (cubemars_mit), RS00 "
       "(robstride_mit). Required there; an unknown model is refused listing the known ones"}
        .length(0, 31).related(drive_motor_known, "a model of drive.family").rule_text("a model name or \"\""),
    DK{"mit_kp", &D::mit_kp, "N m/rad",
       "MIT families: position gain kp sent in every frame (actuator side); the motor computes "
       "kp (p - q) + kd (v - qd) + torque"}
        .within(0, 5000).related(drive_mit_kp_in_range, "at most the motor's KP range"),
    DK{"mit_kd", &D::mit_kd, "N m s/rad", "MIT families: velocity gain kd sent in every frame (actuator side)"}
        .within(0, 100).related(drive_mit_kd_in_range, "at most the motor's KD range"),
    DK{"master_id", &D::master_id, "",
       "MIT families: the 11-bit id the motor answers on (Damiao MST_ID); 0 = the vendor's default (Damiao: "
       "drive.node + 0x10, Robstride 0x0FD, CubeMars 0x000). Unique on its interface (Damiao); 0x7FF is refused, "
       "and on an interface that also carries CiA 402 drives CANopen's NMT (0x000), SYNC (0x080) and EMCY "
       "(0x081..0x0FF) ids"}
        .in_hex().within(0, 0x7FF)
        .related(drive_master_id_free, "not 0x7FF, not drive.node; beside CiA 402 drives not an NMT, SYNC or EMCY id"),
    DK{"can_fd", &D::can_fd, "",
       "this drive's interface carries CAN FD: armfw opens it for CAN FD (refused, naming the interface, when its "
       "MTU says it cannot) and the MIT families send their frames as FD with bit-rate switch (Damiao motors set to "
       "CAN FD answer only those; set the bitrates with `ip link set can0 type can bitrate 1000000 dbitrate 5000000 "
       "fd on`). Every drive on one interface says the same"},
    DK{"bitrate", &D::bitrate, "bit/s",
       "bit rate of this drive's interface (drive.can) when it is not bus.bitrate, as that interface is set up (a "
       "CiA 402 wrist on can1 at 500 kbit/s beside motors on can0 at 1 Mbit/s): the bus-load check counts that "
       "interface at it and `armctl drives check` names it. Every drive on one interface has the same, given or "
       "inherited"}
        .within(10000, 1000000).related(drive_bitrate_agrees, "the same on every drive of the interface")
        .unset_means(0, "bus.bitrate", true),
    DK{"data_bitrate", &D::data_bitrate, "bit/s",
       "CAN FD data bit rate of this drive's interface when it is not bus.data_bitrate (drive.can_fd drives only): "
       "the bus-load check counts that interface's data phase at it. At least the interface's bit rate; every "
       "drive.can_fd drive on one interface has the same, given or inherited"}
        .within(10000, 8000000)
        .related(drive_data_bitrate_ok, "drive.can_fd only, at least the interface's bit rate, the same on the interface")
        .unset_means(0, "bus.data_bitrate", true),
    DK{"counts_per_rev", &D::counts_per_rev, "counts/rev",
       "encoder counts per motor revolution (per motor mm for prismatic joints)"}
        .below(1, kTwo31).unset_means(0, "bus.counts_per_rev", false),
    DK{"gear_ratio", &D::gear_ratio, "",
       "motor revolutions (mm) per joint revolution (mm); positive. MIT families: actuator output turns per joint "
       "turn (a transmission after the actuator, whose own gearbox the motor model covers); unset = 1"}
        .within(1e-3, 1e5).unset_means(0, "bus.gear_ratio", false),
    DK{"direction", &D::direction, "", "sign between the joint and the drive"}.among(std::span<const double>(kDirections)),
    DK{"zero_offset", &D::zero_offset, "counts",
       "drive position at joint zero (what `home zero` answers); MIT families: actuator microradians"}
        .within(-kTwo31, kTwo31 - 1),
    DK{"limits", &D::limits, "deg (mm)",
       "`[lower, upper]`; must lie within the robot description's limits, narrows them for planning, IK and the "
       "supervisor"}
        .within(-kMaxLength, kMaxLength).length(2, 2).related(drive_limits_ordered, "lower below upper")
        .unset_means(0, "the robot description's", false),
    DK{"max_velocity", &D::max_velocity, "deg/s (mm/s)", "at most the robot description's; 0 = the description's"}
        .above(0, 1e6).unset_means(0, "the robot description's", true),
    DK{"heartbeat_timeout_ms", &D::heartbeat_timeout_ms, "ms", "heartbeat consumer time for this drive; 0 = the bus's"}
        .above(0, 60000).related(drive_heartbeat_above_period, "above bus.heartbeat_period_ms")
        .unset_means(0, "bus.heartbeat_timeout_ms", true),
    DK{"quick_stop_decel", &D::quick_stop_decel, "deg/s^2 (mm/s^2)",
       "joint-side deceleration written to the drive's 6085h quick stop deceleration at bring-up (how fast it stops "
       "on its own with safety.stop = \"drive\"); 0 = leave the drive's own"}
        .above(0, 1e7).unset_means(0, "the drive's own", true),
    DK{"homing.method", &D::homing_method, "",
       "how the joint finds its zero at power-up: `\"absolute\"` = absolute encoder (homed at start; `\"none\"` is "
       "read as the same), a CiA 402 homing method number (6098h: 1..35, 37 or a negative manufacturer method; the "
       "drive's own Homing Mode), or `\"hard_stop\"` (no switch: the master drives the joint slowly against its "
       "mechanical stop, backs off). Required in every [[drive]] of a real bus (bus.can not \"sim\"), so that an "
       "incremental encoder is never taken as homed; with \"sim\" (absolute virtual encoders) it may be left out"}
        .integer_too().length(1, 16).rule_text("\"absolute\", \"hard_stop\" or a method 1..35, 37, -128..-1")
        .spelled_as("absolute", "none")
        .related(homing_method_known, "a known method"),
    DK{"homing.speed_switch", &D::homing_speed_switch, "deg/s (mm/s)",
       "search for the switch (6099h:01); hard_stop: the approach speed"}.above(0, 1e6),
    DK{"homing.speed_zero", &D::homing_speed_zero, "deg/s (mm/s)", "search for zero (6099h:02)"}.above(0, 1e6),
    DK{"homing.acceleration", &D::homing_acceleration, "deg/s^2 (mm/s^2)",
       "homing acceleration (609Ah); hard_stop: of the approach and the back-off"}.above(0, 1e7),
    DK{"homing.offset", &D::homing_offset, "deg (mm)",
       "joint position at the home mark (written as 607Ch home offset) or, hard_stop, at the backed-off point; "
       "within the joint's limits (drive.limits or the description's) unless the method is \"absolute\""}
        .within(-kMaxLength, kMaxLength),
    DK{"homing.timeout_s", &D::homing_timeout_s, "s", "longest homing of this joint; longer fails it (arm disabled)"}
        .above(0, 3600),
    DK{"homing.direction", &D::homing_direction, "", "hard_stop: direction of the approach"}
        .among(std::span<const double>(kDirections)),
    DK{"homing.following_limit", &D::homing_following_limit, "deg (mm)",
       "hard_stop: |demanded - actual| that means the stop is reached"}.above(0, 180),
    DK{"homing.torque_limit", &D::homing_torque_limit, "N m (N)",
       "hard_stop: |torque| (6077h, when the drive reports it) that means the stop is reached; 0 = unused"}
        .within(0, 1e6),
    DK{"homing.backoff", &D::homing_backoff, "deg (mm)", "hard_stop: distance moved back from the stop"}
        .above(0, kMaxLength),
    DK{"rated_torque", &D::rated_torque, "N m (N)",
       "the motor's rated torque (motor side), the unit of 6071h / 6077h / 60B2h (per mille of it); 0 = read the "
       "drive's 6076h at bring-up (used when a torque object is mapped: dynamics.* or homing.torque_limit)"}
        .above(0, 1e5).unset_means(0, "the drive's 6076h", true),
    DK{"collision_threshold", &D::collision_threshold, "N m (N)",
       "this joint's collision threshold (joint side, before dynamics.collision_sensitivity); 0 = "
       "dynamics.collision_threshold_pct of its rated torque; at least 0.01 N m (N): below it the measured torque's "
       "noise alone faults the arm"}
        .within(0.01, 1e6).unset_means(0, "dynamics.collision_threshold_pct of the rated torque", true),
    DK{"sdo", &D::sdo, "",
       "objects written to the drive at bring-up, in order, each read back: `[[\"6065h\", 0, \"u32\", 20000], ...]` "
       "= index (\"6065h\" or \"0x6065\", 2000h..9FFFh), sub-index 0..255, type (u8, u16, u32, i8, i16, i32) "
       "and a value within the type, in the drive's own units (docs/servo-bus.md#drive-profiles). A drive that "
       "refuses one, or reads back another value, fails the bring-up naming the node, the object and the abort "
       "code. Objects the master writes itself (6040h, 6060h, 607Ah, 6071h, 60B1h, 60B2h, 60C2h, 60FEh, 6085h, "
       "6098h, 6099h, 609Ah, 607Ch) are refused"}
        .length(0, 16).rule_text("0..16 entries [index, sub, type, value]").related(sdo_entries_valid, "")
        .unset_means(0, "none", true),
};

using OC = OutputConfig;
using OK = OutputKey;
const OutputKey kOutputTable[] = {
    OK{"name", &OC::name, "", "the output's name (`out NAME on|off`): letters, digits, _ and -, starting with a letter"}
        .length(1, 31).rule_text("1..31 characters").needed(),
    OK{"node", &OC::node, "", "CANopen node of the drive whose 60FEh:01 physical outputs carry it (a drive of the arm)"}
        .within(1, 127).needed(),
    OK{"bit", &OC::bit, "",
       "bit of 60FEh:01: one of the manufacturer-specific outputs 16..31. CiA 402 gives bit 0 to \"set brake\" (the "
       "drive's brake control: switching it by hand would release the brake of a powered-down axis) and reserves "
       "bits 1..15 for the profile, so those are refused"}
        .within(16, 31).needed(),
};


// ---------------------------------------------------------------------------
// Text helpers
// ---------------------------------------------------------------------------

/// Shortest text that reads back to the same double (std::to_chars): "1000", "100000",
/// "0.01"; scientific ("1e-300", "1e+300") only outside [1e-4, 1e15).
std::string num_text(double v) {
  char b[64];
  const double a = std::fabs(v);
  const bool sci = std::isfinite(v) && a != 0 && (a < 1e-4 || a >= 1e15);
  const auto r = std::to_chars(b, b + sizeof b, v, sci ? std::chars_format::scientific : std::chars_format::fixed);
  return std::string(b, r.ptr);
}

/// A value converted from SI for a message ("-225", not "-225.00000000000003").
std::string shown_text(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.10g", v);
  return b;
}

std::string int_text(long long v, bool hex) {
  char b[32];
  if (hex && v >= 0) std::snprintf(b, sizeof b, "0x%03llX", v);
  else std::snprintf(b, sizeof b, "%lld", v);
  return b;
}

/// Length of the valid UTF-8 sequence at s[i], or 0 when it is not one.
std::size_t utf8_len(const std::string& s, std::size_t i) {
  const auto c = static_cast<unsigned char>(s[i]);
  std::size_t n = 0;
  std::uint32_t cp = 0;
  if (c < 0x80) return 1;
  if (c >= 0xC2 && c <= 0xDF) n = 2, cp = c & 0x1Fu;
  else if (c >= 0xE0 && c <= 0xEF) n = 3, cp = c & 0x0Fu;
  else if (c >= 0xF0 && c <= 0xF4) n = 4, cp = c & 0x07u;
  else return 0;
  if (i + n > s.size()) return 0;
  for (std::size_t k = 1; k < n; ++k) {
    const auto d = static_cast<unsigned char>(s[i + k]);
    if ((d & 0xC0u) != 0x80u) return 0;
    cp = (cp << 6) | (d & 0x3Fu);
  }
  if ((n == 3 && cp < 0x800) || (n == 4 && (cp < 0x10000 || cp > 0x10FFFF)) || (cp >= 0xD800 && cp <= 0xDFFF)) return 0;
  return n;
}

/// A TOML basic string: quotes, backslashes and control characters escaped; bytes
/// that are not UTF-8 (TOML cannot hold them) become U+FFFD.
std::string toml_string(const std::string& s) {
  std::string o = "\"";
  for (std::size_t i = 0; i < s.size();) {
    const unsigned char c = static_cast<unsigned char>(s[i]);
    const std::size_t n = utf8_len(s, i);
    if (n == 0) {
      o += "\\uFFFD";
      ++i;
      continue;
    }
    if (n > 1) {
      o.append(s, i, n);
      i += n;
      continue;
    }
    switch (c) {
      case '"': o += "\\\""; break;
      case '\\': o += "\\\\"; break;
      case '\b': o += "\\b"; break;
      case '\t': o += "\\t"; break;
      case '\n': o += "\\n"; break;
      case '\r': o += "\\r"; break;
      case '\f': o += "\\f"; break;
      default:
        if (c < 0x20 || c == 0x7F) {
          char b[8];
          std::snprintf(b, sizeof b, "\\u%04X", c);
          o += b;
        } else {
          o += static_cast<char>(c);
        }
    }
    ++i;
  }
  return o + "\"";
}

template <class S>
std::string value_of(const Key<S>& k, const S& s) {
  return std::visit(
      [&](auto m) -> std::string {
        using T = std::decay_t<decltype(s.*m)>;
        const T& v = s.*m;
        if constexpr (std::is_same_v<T, bool>) return v ? "true" : "false";
        else if constexpr (std::is_same_v<T, int> || std::is_same_v<T, std::int64_t>) return int_text(v, k.hex);
        else if constexpr (std::is_same_v<T, double>) return num_text(v);
        else if constexpr (std::is_same_v<T, std::string>) {
          if (k.or_integer && homing_method_number(v) != 0) return v;
          return toml_string(k.stored && v == k.stored ? std::string(k.spelled) : v);
        }
        else if constexpr (std::is_same_v<T, std::vector<double>>) {
          std::string o = "[";
          for (std::size_t i = 0; i < v.size(); ++i) o += (i ? ", " : "") + num_text(v[i]);
          return o + "]";
        } else if constexpr (std::is_same_v<T, std::vector<SdoEntry>>) {
          std::string o = "[";
          for (std::size_t i = 0; i < v.size(); ++i) {
            char b[24];
            std::snprintf(b, sizeof b, "\"%04Xh\", ", unsigned(v[i].index));
            o += std::string(i ? ", [" : "[") + b + std::to_string(v[i].sub) + ", " + toml_string(v[i].type) + ", " +
                 std::to_string(v[i].value) + "]";
          }
          return o + "]";
        } else {
          std::string o = "[";
          for (std::size_t i = 0; i < v.size(); ++i) {
            o += i ? ", [" : "[";
            for (std::size_t e = 0; e < v[i].size(); ++e) o += (e ? ", " : "") + std::to_string(v[i][e]);
            o += "]";
          }
          return o + "]";
        }
      },
      k.member);
}

template <class S>
bool is_integer_key(const Key<S>& k) {
  return k.member.index() == 1 || k.member.index() == 2;  // int, std::int64_t
}

/// "[0.01, 5000]", "(0, 120]", "1..127", "9600, 19200, ...", "\"ramp\" or \"drive\"".
template <class S>
std::string numeric_range(const Key<S>& k) {
  if (!k.one_of.empty()) {
    std::string o;
    for (std::size_t i = 0; i < k.one_of.size(); ++i) o += (i ? ", " : "") + num_text(k.one_of[i]);
    return o;
  }
  if (std::isinf(k.lo) && std::isinf(k.hi)) return "";
  if (is_integer_key(k) && !k.lo_open && !k.hi_open)
    return int_text(static_cast<long long>(k.lo), k.hex) + ".." + int_text(static_cast<long long>(k.hi), k.hex);
  return std::string(k.lo_open ? "(" : "[") + num_text(k.lo) + ", " + num_text(k.hi) + (k.hi_open ? ")" : "]");
}

template <class S>
std::string range_of(const Key<S>& k) {
  std::string r;
  switch (k.member.index()) {
    case 0: r = "true or false"; break;
    case 4:
      if (k.rule) r = k.rule;
      else if (!k.one_of_text.empty())
        for (std::size_t i = 0; i < k.one_of_text.size(); ++i)
          r += std::string(i == 0 ? "" : i + 1 == k.one_of_text.size() ? " or " : ", ") + "\"" + k.one_of_text[i] + "\"";
      break;
    case 5:
      r = (k.min_len == k.max_len ? std::to_string(k.min_len) : std::to_string(k.min_len) + ".." + std::to_string(k.max_len)) +
          " values, each " + numeric_range(k);
      break;
    case 6:
      r = "0.." + std::to_string(k.max_len) + " groups (lists) of integers " + numeric_range(k);
      break;
    default: r = k.rule ? k.rule : numeric_range(k);
  }
  if (k.relation_text && *k.relation_text) r += (r.empty() ? "" : ", ") + std::string(k.relation_text);
  if (k.has_unset && k.unset_writable && k.member.index() != 5 && k.member.index() != 7)
    r += " or " + num_text(k.unset) + " (unset)";
  return r;
}

template <class S>
std::string default_of(const Key<S>& k) {
  if (k.required) return "required";
  if (k.has_unset) return k.unset_text;
  return value_of(k, S{});
}

bool in_range(double v, double lo, double hi, bool lo_open, bool hi_open) {
  return (lo_open ? v > lo : v >= lo) && (hi_open ? v < hi : v <= hi);
}

std::string with_unit(const char* unit) { return *unit ? std::string(" ") + unit : std::string(); }

/// Why the number `v` of key `k` is refused, or "".
template <class S>
std::string number_problem(const Key<S>& k, double v) {
  if (!std::isfinite(v)) return "must be a finite number (got " + num_text(v) + ")";
  if (!k.one_of.empty()) {
    if (std::find(k.one_of.begin(), k.one_of.end(), v) != k.one_of.end()) return "";
    return "must be one of " + numeric_range(k) + with_unit(k.unit) + " (got " + num_text(v) + ")";
  }
  if (in_range(v, k.lo, k.hi, k.lo_open, k.hi_open)) return "";
  return "must be within " + numeric_range(k) + with_unit(k.unit) + " (got " + num_text(v) + ")";
}

/// True when key `k` of `s` holds its "unset: inherit" value.
template <class S>
bool is_unset(const Key<S>& k, const S& s) {
  if (!k.has_unset) return false;
  return std::visit(
      [&](auto m) -> bool {
        using T = std::decay_t<decltype(s.*m)>;
        if constexpr (std::is_same_v<T, std::vector<double>> || std::is_same_v<T, std::vector<std::vector<int>>> ||
                      std::is_same_v<T, std::vector<SdoEntry>>)
          return (s.*m).empty();
        else if constexpr (std::is_same_v<T, std::string> || std::is_same_v<T, bool>) return false;
        else return static_cast<double>(s.*m) == k.unset;
      },
      k.member);
}

/// Why key `k` of `s` is refused ("" when fine). `label` is its name in messages.
/// `relations`: false = the key's own range, true = only its relation to other keys
/// (checked after every key's own range, so a bad value is named by its own key).
template <class S>
std::string key_problem(const Key<S>& k, const S& s, const FwConfig& whole, const std::string& label, bool relations) {
  if (is_unset(k, s)) return "";
  if (relations) {
    const std::string why = k.relation ? k.relation(s, whole) : "";
    return why.empty() ? "" : label + ": " + why;
  }
  std::string why;
  std::visit(
      [&](auto m) {
        using T = std::decay_t<decltype(s.*m)>;
        const T& v = s.*m;
        if constexpr (std::is_same_v<T, bool>) {
          return;
        } else if constexpr (std::is_same_v<T, std::string>) {
          const bool listed = k.one_of_text.empty() ||
                              std::find(k.one_of_text.begin(), k.one_of_text.end(), v) != k.one_of_text.end();
          if (!listed || v.size() < k.min_len || v.size() > k.max_len)
            why = "must be " + range_of(k) + " (got " + toml_string(v) + ")";
        } else if constexpr (std::is_same_v<T, std::vector<double>>) {
          if (v.size() < k.min_len || v.size() > k.max_len) {
            why = "must hold " + (k.min_len == k.max_len ? std::to_string(k.min_len) : std::to_string(k.min_len) + ".." + std::to_string(k.max_len)) +
                  " values (got " + std::to_string(v.size()) + ")";
            return;
          }
          for (std::size_t i = 0; i < v.size() && why.empty(); ++i) {
            const std::string p = number_problem(k, v[i]);
            if (!p.empty()) why = "\x01" + std::to_string(i) + "\x02" + p;  // element index, rewritten below
          }
        } else if constexpr (std::is_same_v<T, std::vector<SdoEntry>>) {
          if (v.size() > k.max_len)
            why = "must hold at most " + std::to_string(k.max_len) + " entries (got " + std::to_string(v.size()) + ")";
        } else if constexpr (std::is_same_v<T, std::vector<std::vector<int>>>) {
          if (v.size() > k.max_len) {
            why = "must hold at most " + std::to_string(k.max_len) + " groups (got " + std::to_string(v.size()) + ")";
            return;
          }
          for (std::size_t i = 0; i < v.size() && why.empty(); ++i) {
            if (v[i].empty()) why = "\x01" + std::to_string(i) + "\x02" + "an empty group";
            for (std::size_t e = 0; e < v[i].size() && why.empty(); ++e) {
              const std::string p = number_problem(k, static_cast<double>(v[i][e]));
              if (!p.empty()) why = "\x01" + std::to_string(i) + "\x02" + p;
            }
          }
        } else {
          why = number_problem(k, static_cast<double>(v));
        }
      },
      k.member);
  if (why.empty()) return "";
  if (why[0] == '\x01') {  // "label[i]: reason"
    const auto e = why.find('\x02');
    return label + "[" + why.substr(1, e - 1) + "]: " + why.substr(e + 1);
  }
  return label + ": " + why;
}

std::string drive_label(std::size_t i) { return "drive[" + std::to_string(i + 1) + "]"; }

// ---------------------------------------------------------------------------
// Loading
// ---------------------------------------------------------------------------

struct Reader {
  std::string origin;
  std::string err;
  /// Record the first error: "<origin>:<line>:<column>: <key>: <why>".
  bool fail(const toml::node& at, const std::string& key, const std::string& why) {
    if (err.empty()) err = kin::source_text(at.source(), origin) + ": " + key + ": " + why;
    return false;
  }
  static std::string shown(const toml::node& v) { return kin::value_text(v); }
  bool number(const toml::node& v, const std::string& key, double& out) {
    if (const auto* i = v.as_integer()) out = static_cast<double>(i->get());
    else if (const auto* f = v.as_floating_point()) out = f->get();
    else return fail(v, key, "expected a number (got " + shown(v) + ")");
    if (!std::isfinite(out)) return fail(v, key, "must be a finite number (got " + shown(v) + ")");
    return true;
  }

  /// Read `v` into key `k` of `s`. False (and err set) when the type is wrong or the
  /// file writes the "unset" value of a key that does not allow it.
  template <class S>
  bool read(const Key<S>& k, const toml::node& v, const std::string& label, S& s) {
    bool ok = std::visit(
        [&](auto m) -> bool {
          using T = std::decay_t<decltype(s.*m)>;
          T& out = s.*m;
          if constexpr (std::is_same_v<T, bool>) {
            const auto* b = v.as_boolean();
            if (!b) return fail(v, label, "expected true or false (got " + shown(v) + ")");
            out = b->get();
          } else if constexpr (std::is_same_v<T, int> || std::is_same_v<T, std::int64_t>) {
            const auto* n = v.as_integer();
            if (!n) return fail(v, label, "expected an integer (got " + shown(v) + ")");
            const std::int64_t i = n->get();
            if constexpr (std::is_same_v<T, int>) {
              // Refused here, before it is narrowed: validate() could not see it.
              if (i < std::numeric_limits<int>::min() || i > std::numeric_limits<int>::max())
                return fail(v, label, "integer out of range (got " + std::to_string(i) + ")");
            }
            out = static_cast<T>(i);
          } else if constexpr (std::is_same_v<T, double>) {
            if (!number(v, label, out)) return false;
          } else if constexpr (std::is_same_v<T, std::string>) {
            const auto* str = v.as_string();
            if (k.or_integer && v.as_integer()) {
              out = std::to_string(v.as_integer()->get());
              return true;
            }
            if (!str) return fail(v, label, std::string(k.or_integer ? "expected a string or an integer" : "expected a string") + " (got " + shown(v) + ")");
            out = str->get();
            if (k.spelled && out == k.spelled) out = k.stored;
          } else if constexpr (std::is_same_v<T, std::vector<SdoEntry>>) {
            const auto* a = v.as_array();
            if (!a) return fail(v, label, "expected an array of [index, sub, type, value] entries (got " + shown(v) + ")");
            if (a->size() > k.max_len)
              return fail(v, label, "at most " + std::to_string(k.max_len) + " entries (got " + std::to_string(a->size()) + ")");
            std::vector<SdoEntry> tmp;
            for (std::size_t i = 0; i < a->size(); ++i) {
              const std::string li = label + "[" + std::to_string(i + 1) + "]";
              const toml::node& en = *a->get(i);
              const auto* e = en.as_array();
              if (!e || e->size() != 4)
                return fail(en, li, "expected [index, sub, type, value], e.g. [\"6065h\", 0, \"u32\", 20000] (got " +
                                        shown(en) + ")");
              SdoEntry out_e;
              const toml::node& ix = *e->get(0);
              if (const auto* is = ix.as_string()) {
                if (!sdo_index_of(is->get(), out_e.index))
                  return fail(ix, li, "index: expected a hexadecimal object index as \"6065h\" or \"0x6065\" (got " +
                                          shown(ix) + ")");
              } else if (const auto* ii = ix.as_integer()) {
                if (ii->get() < 0 || ii->get() > 0xFFFF)
                  return fail(ix, li, "index: expected 0x0000..0xFFFF (got " + shown(ix) + ")");
                out_e.index = static_cast<int>(ii->get());
              } else {
                return fail(ix, li, "index: expected \"6065h\" or \"0x6065\" (got " + shown(ix) + ")");
              }
              const auto* sub = e->get(1)->as_integer();
              if (!sub || sub->get() < 0 || sub->get() > 255)
                return fail(*e->get(1), li, "sub-index: expected an integer 0..255 (got " + shown(*e->get(1)) + ")");
              out_e.sub = static_cast<int>(sub->get());
              const auto* ty = e->get(2)->as_string();
              if (!ty || sdo_type_size(ty->get()) == 0)
                return fail(*e->get(2), li, "type: expected \"u8\", \"u16\", \"u32\", \"i8\", \"i16\" or \"i32\" (got " +
                                                shown(*e->get(2)) + ")");
              out_e.type = ty->get();
              const auto* val = e->get(3)->as_integer();
              if (!val) return fail(*e->get(3), li, "value: expected an integer (got " + shown(*e->get(3)) + ")");
              out_e.value = val->get();
              tmp.push_back(out_e);
            }
            out = std::move(tmp);
          } else if constexpr (std::is_same_v<T, std::vector<std::vector<int>>>) {
            const auto* a = v.as_array();
            if (!a) return fail(v, label, "expected an array of arrays of integers (got " + shown(v) + ")");
            if (a->size() > k.max_len) return fail(v, label, "expected " + range_of(k) + " (got " + std::to_string(a->size()) + " groups)");
            std::vector<std::vector<int>> tmp;
            for (std::size_t i = 0; i < a->size(); ++i) {
              const std::string li = label + "[" + std::to_string(i) + "]";
              const auto* g = a->get(i)->as_array();
              if (!g) return fail(*a->get(i), li, "expected an array of joint numbers (got " + shown(*a->get(i)) + ")");
              if (g->size() > k.max_len) return fail(*g, li, "more than " + std::to_string(k.max_len) + " joints");
              tmp.emplace_back();
              for (std::size_t e = 0; e < g->size(); ++e) {
                const auto* n = g->get(e)->as_integer();
                if (!n) return fail(*g->get(e), li, "expected an integer joint number (got " + shown(*g->get(e)) + ")");
                if (n->get() < -1000000 || n->get() > 1000000) return fail(*g->get(e), li, "integer out of range (got " + std::to_string(n->get()) + ")");
                tmp.back().push_back(static_cast<int>(n->get()));
              }
            }
            out = std::move(tmp);
          } else {
            const auto* a = v.as_array();
            if (!a) return fail(v, label, "expected an array of numbers (got " + shown(v) + ")");
            if (a->size() > k.max_len || a->size() < k.min_len)
              return fail(v, label, "expected " + range_of(k) + " (got " + std::to_string(a->size()) + " values)");
            std::vector<double> tmp(a->size());
            for (std::size_t i = 0; i < a->size(); ++i)
              if (!number(*a->get(i), label + "[" + std::to_string(i) + "]", tmp[i])) return false;
            out = std::move(tmp);
          }
          return true;
        },
        k.member);
    if (!ok) return false;
    if (!k.unset_writable && is_unset(k, s))
      return fail(v, label, value_of(k, s) + " is not allowed: " + range_of(k) + " (leave the key out for " + k.unset_text + ")");
    return true;
  }
};

/// The section of a dotted name ("loop" of "loop.rate_hz"), "" for a top-level key.
std::string section_of(const char* name) {
  const char* dot = std::strchr(name, '.');
  return dot ? std::string(name, dot) : std::string();
}

std::vector<std::string> sections() {
  std::vector<std::string> out;
  for (const ConfigKey& k : kConfigTable) {
    const std::string s = section_of(k.name);
    if (!s.empty() && std::find(out.begin(), out.end(), s) == out.end()) out.push_back(s);
  }
  return out;
}

std::string joined(const std::vector<std::string>& v) {
  std::string o;
  for (std::size_t i = 0; i < v.size(); ++i) o += (i ? ", " : "") + v[i];
  return o;
}

template <class Map>
std::vector<std::string> sorted_keys(const Map& m) {
  std::vector<std::string> out;
  for (const auto& e : m) out.push_back(e.first);
  std::sort(out.begin(), out.end());
  return out;
}

bool read_drive(Reader& r, const toml::node& t, std::size_t index, const std::string& bus, DriveConfig& d) {
  const std::string where = drive_label(index);
  const toml::table* tab = t.as_table();
  if (!tab) return r.fail(t, where, "expected a table");
  // The keys, with `homing.x = ...` (a dotted key: the sub-table `homing`) flattened to "homing.x".
  std::vector<std::pair<std::string, const toml::node*>> entries;
  for (const auto& [name, value] : *tab) {  // toml::table is ordered by key
    const std::string n(name.str());
    if (n == "homing" && value.is_table()) {
      for (const auto& [sub, sv] : *value.as_table()) entries.emplace_back("homing." + std::string(sub.str()), &sv);
      continue;
    }
    entries.emplace_back(n, &value);
  }
  for (const auto& [name, value] : entries) {
    const DriveKey* k = nullptr;
    for (const DriveKey& e : kDriveTable)
      if (name == e.name) k = &e;
    if (!k) {
      std::vector<std::string> names;
      for (const DriveKey& e : kDriveTable) names.push_back(e.name);
      return r.fail(*value, where + "." + name, "unknown key (" + joined(names) + ")");
    }
    if (!r.read(*k, *value, where + "." + k->name, d)) return false;
  }
  // A real bus: every joint says how it finds its zero (an incremental encoder left without a
  // method would count as homed at power-up). "sim": absolute virtual encoders.
  if (bus != "sim" && std::none_of(entries.begin(), entries.end(), [](const auto& e) { return e.first == "homing.method"; }))
    return r.fail(t, where + ".homing.method",
                  "missing: every [[drive]] of a real bus (bus.can = " + toml_string(bus) +
                      ") says how its joint finds its zero: \"absolute\" (absolute encoder), \"hard_stop\" or a CiA 402 "
                      "method (6098h)");
  return true;
}

/// Configuration files are small (the shipped one is 3 KiB, six [[drive]] tables add
/// 1 KiB): the cap of every file the firmware reads (kinematics/file_input.hpp).
constexpr std::size_t kMaxFileBytes = kin::kMaxInputFileBytes;

/// The node a validate() message is about: its label ("loop.rate_hz", "drive[2].limits",
/// "motion.home_deg[0]"; drive numbers 1-based) looked up in the parsed file, or null.
const toml::node* node_of_label(const toml::table& top, const std::string& msg) {
  const std::size_t colon = msg.find(": ");
  if (colon == std::string::npos) return nullptr;
  std::string path = msg.substr(0, colon);
  for (const std::string pre : {"drive[", "output["}) {
    if (path.rfind(pre, 0) != 0) continue;  // 1-based in messages, 0-based in toml++ paths
    const std::size_t close = path.find(']');
    int n = 0;
    const auto r = std::from_chars(path.data() + pre.size(), path.data() + close, n);
    if (close == std::string::npos || r.ec != std::errc() || n < 1) return nullptr;
    path = pre + std::to_string(n - 1) + path.substr(close);
  }
  const toml::node* n = toml::at_path(top, path).node();
  if (!n && !path.empty() && path.back() == ']') n = toml::at_path(top, path.substr(0, path.rfind('['))).node();
  // A relation broken by a key the file does not write (its default): the other key the
  // message names, which the file does write.
  for (const ConfigKey& k : kConfigTable)
    if (!n && msg.find(k.name, colon) != std::string::npos) n = toml::at_path(top, k.name).node();
  return n;
}

}  // namespace

std::span<const ConfigKey> config_keys() { return kConfigTable; }
std::span<const DriveKey> drive_keys() { return kDriveTable; }
std::span<const OutputKey> output_keys() { return kOutputTable; }
std::string value_text(const ConfigKey& k, const FwConfig& s) { return value_of(k, s); }
std::string value_text(const DriveKey& k, const DriveConfig& s) { return value_of(k, s); }
std::string range_text(const ConfigKey& k) { return range_of(k); }
std::string range_text(const DriveKey& k) { return range_of(k); }
std::string default_text(const ConfigKey& k) { return default_of(k); }
std::string default_text(const DriveKey& k) { return default_of(k); }

int sdo_type_size(const std::string& t) {
  if (t == "u8" || t == "i8") return 1;
  if (t == "u16" || t == "i16") return 2;
  if (t == "u32" || t == "i32") return 4;
  return 0;
}
bool sdo_type_signed(const std::string& t) { return !t.empty() && t[0] == 'i'; }

int homing_method_number(const std::string& m) {
  if (m.empty() || m.size() > 4) return 0;
  int v = 0;
  const auto r = std::from_chars(m.data(), m.data() + m.size(), v);
  if (r.ec != std::errc() || r.ptr != m.data() + m.size()) return 0;
  if ((v >= 1 && v <= 35) || v == 37 || (v >= -128 && v <= -1)) return v;
  return 0;
}

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

std::string validate(const FwConfig& c, bool check_bus_load) {
  for (const bool relations : {false, true}) {
    for (const ConfigKey& k : kConfigTable) {
      const std::string why = key_problem(k, c, c, k.name, relations);
      if (!why.empty()) return why;
    }
    for (std::size_t i = 0; i < c.drives.size(); ++i)
      for (const DriveKey& k : kDriveTable) {
        const std::string why = key_problem(k, c.drives[i], c, drive_label(i) + "." + k.name, relations);
        if (!why.empty()) return why;
      }
    for (std::size_t i = 0; i < c.outputs.size(); ++i)
      for (const OutputKey& k : kOutputTable) {
        const std::string why = key_problem(k, c.outputs[i], c, "output[" + std::to_string(i + 1) + "]." + k.name, relations);
        if (!why.empty()) return why;
      }
  }
  // A real bus without [[drive]] tables would take every joint as an absolute encoder.
  if (c.can != "sim" && c.drives.empty())
    return "drive: bus.can = " + toml_string(c.can) +
           " is a real bus: give one [[drive]] table per joint, each with homing.method (\"absolute\" for an absolute "
           "encoder), so that no joint with an incremental encoder counts as homed";
  // [[output]]: names valid and unique, one output per (node, bit)
  for (std::size_t i = 0; i < c.outputs.size(); ++i) {
    const OutputConfig& o = c.outputs[i];
    const std::string at = "output[" + std::to_string(i + 1) + "]";
    for (std::size_t k = 0; k < o.name.size(); ++k) {
      const char ch = o.name[k];
      const bool letter = (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z');
      if (!(letter || (k > 0 && ((ch >= '0' && ch <= '9') || ch == '_' || ch == '-'))))
        return at + ".name: '" + o.name + "': letters, digits, _ and - only, starting with a letter";
    }
    for (std::size_t k = 0; k < i; ++k) {
      if (c.outputs[k].name == o.name) return at + ".name: '" + o.name + "' is also output[" + std::to_string(k + 1) + "]'s";
      if (c.outputs[k].node == o.node && c.outputs[k].bit == o.bit)
        return at + ".bit: node " + std::to_string(o.node) + " bit " + std::to_string(o.bit) + " is also output[" +
               std::to_string(k + 1) + "] (" + c.outputs[k].name + ")";
    }
  }
  // A real bus has one [[drive]] table per joint (above; validate_for_chain checks the count).
  if (check_bus_load && !c.drives.empty())
    if (std::string why = bus_load_problem(c, c.drives.size()); !why.empty()) return "loop.rate_hz: " + why;
  return "";
}

// ---------------------------------------------------------------------------
// Bus load
// ---------------------------------------------------------------------------

hal::BusTraffic bus_traffic(const FwConfig& c, std::size_t joints) {
  hal::BusTraffic t;
  t.rate_hz = c.rate_hz;
  t.joints = joints;
  t.rpdo1_len = t.tpdo1_len = c.freedrive ? 7 : 6;  // + 6060h / 6061h for torque mode
  t.rpdo2_len = static_cast<std::uint8_t>((c.feed_forward != "off" ? 4 : 0) + (c.feed_forward == "torque" ? 2 : 0) +
                                          (c.freedrive ? 2 : 0));
  std::vector<int> nodes;
  for (const OutputConfig& o : c.outputs)
    if (std::find(nodes.begin(), nodes.end(), o.node) == nodes.end()) nodes.push_back(o.node);
  t.rpdo3_len = nodes.empty() ? 0 : 4;
  t.rpdo3_joints = nodes.size();
  bool torque = c.collision;
  for (const DriveConfig& d : c.drives) torque = torque || (d.homing_method == "hard_stop" && d.homing_torque_limit > 0);
  // velocity 4 + error code 2 (+ torque 2): velocity and error code ride along when the
  // torque sends TPDO2 anyway (App::build)
  t.tpdo2_len = static_cast<std::uint8_t>(torque ? 8 : c.tpdo2 ? 6 : 0);
  t.heartbeat_period_s = c.heartbeat_period_ms * 1e-3;
  return t;
}

bool bus_load_checked(const FwConfig& c) { return c.can != "sim" && c.can.rfind("vcan", 0) != 0; }

namespace {
bool on_iface(const FwConfig& c, const DriveConfig& d, const std::string& iface) { return drive_iface(c, d) == iface; }
}  // namespace

double interface_bitrate(const FwConfig& c, const std::string& iface) {
  for (const DriveConfig& d : c.drives)
    if (on_iface(c, d, iface) && d.bitrate != 0) return d.bitrate;
  return c.bitrate;
}

double interface_data_bitrate(const FwConfig& c, const std::string& iface) {
  bool fd = false;
  for (const DriveConfig& d : c.drives)
    if (on_iface(c, d, iface) && d.can_fd) {
      if (d.data_bitrate != 0) return d.data_bitrate;
      fd = true;
    }
  return fd ? c.data_bitrate : 0;
}

namespace {
std::string pct_text(double share) {
  char b[32];
  std::snprintf(b, sizeof b, "%.1f %%", share * 100.0);
  return b;
}

/// "13 frames per cycle: SYNC, 6 RPDO1, 6 TPDO1"
std::string frames_text(const hal::BusLoad& l, double rate) {
  std::string o = num_text(l.frames_per_cycle) + " frames per cycle:";
  bool first = true;
  for (std::size_t k = 0; k < l.count; ++k) {
    if (std::strcmp(l.kinds[k].name, "heartbeat") == 0) continue;
    const double n = l.kinds[k].per_second / rate;
    o += std::string(first ? " " : ", ") + (n == 1 ? "" : num_text(n) + " ") + l.kinds[k].name;
    first = false;
  }
  return o;
}

/// One interface as the load check sees it: `c` is the configuration with bus.can, bus.bitrate
/// and bus.data_bitrate set to the interface's (data_bitrate 0: classical frames), `t` its traffic.
struct IfaceLoad {
  FwConfig c;
  hal::BusTraffic t;
  std::string families;     ///< "damiao", "damiao, cia402"
  const char* rate_key;     ///< where the bit rate comes from: "bus.bitrate" or "drive.bitrate"
  const char* can_key;      ///< "bus.can" or "drive.can"
  hal::BusLoad load() const { return hal::bus_load(t, c.bitrate, c.data_bitrate); }
};

/// Highest rate (Hz) at which the load of `c`'s traffic `t` stays at most `share`.
double rate_for(const FwConfig& c, hal::BusTraffic t, double share) {
  t.rate_hz = 1;
  const hal::BusLoad one = hal::bus_load(t, c.bitrate, c.data_bitrate);
  t.rate_hz = 2;
  const hal::BusLoad two = hal::bus_load(t, c.bitrate, c.data_bitrate);
  const double per_hz = two.total() - one.total();  // the cyclic part; heartbeats do not scale
  const double fixed = one.total() - per_hz;
  return per_hz > 0 ? std::max(0.0, (share - fixed) / per_hz) : 1e9;
}

std::string load_line(const IfaceLoad& i, const hal::BusLoad& l) {
  const FwConfig& c = i.c;
  return "bus load " + pct_text(l.total()) + " of " + i.rate_key + " " + num_text(c.bitrate) + " bit/s at loop.rate_hz " +
         num_text(c.rate_hz) + " with " + std::to_string(i.t.joints + i.t.mit_joints) + " drives (" +
         frames_text(l, c.rate_hz) +
         (c.data_bitrate > 0 ? ", CAN FD, data phase " + num_text(c.data_bitrate) + " bit/s" : std::string()) +
         ", worst-case bit stuffing)";
}

/// The interfaces the [[drive]] tables use (drive.can, or bus.can for ""), bus.can first.
std::vector<std::string> drive_interfaces(const FwConfig& c) {
  std::vector<std::string> out{c.can};
  for (const DriveConfig& d : c.drives) {
    const std::string& i = d.can.empty() ? c.can : d.can;
    if (std::find(out.begin(), out.end(), i) == out.end()) out.push_back(i);
  }
  return out;
}

/// The traffic on interface `iface`: its CiA 402 drives' PDOs, SYNC and heartbeats and its MIT
/// motors' frames.
hal::BusTraffic interface_traffic(const FwConfig& c, const std::string& iface) {
  std::size_t cia = 0, mit = 0;
  for (const DriveConfig& d : c.drives)
    if ((d.can.empty() ? c.can : d.can) == iface) ++(d.family == "cia402" ? cia : mit);
  hal::BusTraffic t = bus_traffic(c, cia);
  t.mit_joints = mit;
  return t;
}

/// The interfaces with drives, each at its own rates: with [[drive]] tables every interface
/// they use (bus.can first), else bus.can with `joints` CiA 402 drives and classical frames.
std::vector<IfaceLoad> interface_loads(const FwConfig& c, std::size_t joints) {
  std::vector<IfaceLoad> out;
  if (c.drives.empty()) {
    if (joints == 0) return out;
    out.push_back(IfaceLoad{c, bus_traffic(c, joints), "cia402", "bus.bitrate", "bus.can"});
    out.back().c.data_bitrate = 0;  // without [[drive]] tables no drive says drive.can_fd
    return out;
  }
  for (const std::string& iface : drive_interfaces(c)) {
    IfaceLoad i{c, interface_traffic(c, iface), "", "bus.bitrate", iface == c.can ? "bus.can" : "drive.can"};
    if (i.t.joints + i.t.mit_joints == 0) continue;
    for (const DriveConfig& d : c.drives) {
      if (!on_iface(c, d, iface)) continue;
      if (d.bitrate != 0) i.rate_key = "drive.bitrate";
      if (i.families.find(d.family) == std::string::npos) i.families += (i.families.empty() ? "" : ", ") + d.family;
    }
    i.c.can = iface;
    i.c.bitrate = interface_bitrate(c, iface);
    i.c.data_bitrate = interface_data_bitrate(c, iface);
    out.push_back(std::move(i));
  }
  return out;
}

/// The first problem or warning `check` finds on a checked interface, "" when none; an
/// interface other than bus.can is named first ("drive.can \"can1\": ...").
template <class Check>
std::string per_interface(const FwConfig& c, std::size_t joints, Check&& check) {
  for (const IfaceLoad& i : interface_loads(c, joints)) {
    if (!bus_load_checked(i.c)) continue;
    if (std::string why = check(i); !why.empty())
      return i.c.can == c.can ? why : "drive.can " + toml_string(i.c.can) + ": " + why;
  }
  return "";
}

/// The highest load of the checked interfaces (0 when none is checked).
double highest_load(const FwConfig& c) {
  double most = 0;
  for (const IfaceLoad& i : interface_loads(c, c.drives.size()))
    if (bus_load_checked(i.c)) most = std::max(most, i.load().total());
  return most;
}

std::string problem_for(const IfaceLoad& i) {
  const hal::BusLoad l = i.load();
  if (l.total() <= kBusLoadLimit) return "";
  char b[32];
  std::snprintf(b, sizeof b, "%.0f", std::floor(rate_for(i.c, i.t, kBusLoadLimit)));
  return load_line(i, l) + " is above 85 %: at most " + b + " Hz fits (armfw --config FILE --bus-load)";
}

std::string warning_for(const IfaceLoad& i) {
  const hal::BusLoad l = i.load();
  if (l.total() <= kBusLoadWarn || l.total() > kBusLoadLimit) return "";
  char b[32];
  std::snprintf(b, sizeof b, "%.0f", std::floor(rate_for(i.c, i.t, kBusLoadWarn)));
  return load_line(i, l) + " is above 60 %: little room for SDO, EMCY and retransmitted frames (" + b +
         " Hz or less stays under 60 %)";
}

/// One interface's table of `armfw --bus-load`.
std::string load_table(const IfaceLoad& i) {
  const FwConfig& c = i.c;
  const hal::BusLoad l = i.load();
  const bool fd = c.data_bitrate > 0;
  std::string o;
  char b[300];
  std::snprintf(b, sizeof b, "bus load on %s: %zu drives (%s), loop.rate_hz %s, %s %s bit/s, %s, worst-case bit stuffing\n",
                c.can.c_str(), i.t.joints + i.t.mit_joints, i.families.c_str(), num_text(c.rate_hz).c_str(), i.rate_key,
                num_text(c.bitrate).c_str(),
                fd ? ("CAN FD data phase " + num_text(c.data_bitrate) +
                      " bit/s (bits: nominal+data; bit/s: bus time at the nominal rate)").c_str()
                   : "classical CAN");
  o += b;
  std::snprintf(b, sizeof b, "%-12s %-12s %6s %10s %8s %10s %8s\n", "frame", "direction", "bytes", "per cycle", "bits",
                "bit/s", "load");
  o += b;
  for (std::size_t k = 0; k < l.count; ++k) {
    if (l.kinds[k].per_second == 0) continue;  // heartbeats of an interface with MIT motors only
    const double per_cycle = l.kinds[k].per_second / c.rate_hz;
    const bool hb = std::strcmp(l.kinds[k].name, "heartbeat") == 0;
    const std::string bits = fd ? std::to_string(l.bits[k].nominal) + "+" + std::to_string(l.bits[k].data)
                                : std::to_string(l.bits[k].total());
    std::snprintf(b, sizeof b, "%-12s %-12s %6u %10s %8s %10.0f %8s\n", l.kinds[k].name, hal::to_string(l.kinds[k].direction),
                  unsigned(l.kinds[k].data_len), hb ? "-" : num_text(per_cycle).c_str(), bits.c_str(),
                  l.seconds[k] * c.bitrate, pct_text(l.seconds[k]).c_str());
    o += b;
  }
  const auto line = [&](const char* what, double share) {
    std::snprintf(b, sizeof b, "%-12s %-12s %6s %10s %8s %10.0f %8s\n", what, "", "", "", "", share * c.bitrate,
                  pct_text(share).c_str());
    o += b;
  };
  line("to drives", l.to_drives);
  line("from drives", l.from_drives);
  line("total", l.total());
  if (!bus_load_checked(c))
    o += std::string("not checked: ") + i.can_key + " = " + toml_string(c.can) +
         " has no wire (the figures are what a real bus would carry)\n";
  else if (l.total() > kBusLoadLimit)
    o += "refused: above 85 %: at most " + num_text(std::floor(rate_for(c, i.t, kBusLoadLimit))) + " Hz fits\n";
  else if (l.total() > kBusLoadWarn)
    o += "warning: above 60 %: " + num_text(std::floor(rate_for(c, i.t, kBusLoadWarn))) + " Hz or less stays under 60 %\n";
  else
    o += "fits: at most 60 %\n";
  return o;
}
}  // namespace

// With [[drive]] tables the load is checked per interface (each drive on its drive.can, CiA 402
// and MIT frames counted as they are, at the interface's own bit rates); without, `joints`
// CiA 402 drives on bus.can.
std::string bus_load_problem(const FwConfig& c, std::size_t joints) { return per_interface(c, joints, problem_for); }

std::string bus_load_warning(const FwConfig& c, std::size_t joints) { return per_interface(c, joints, warning_for); }

std::string bus_load_table(const FwConfig& c, std::size_t joints) {
  std::string o;
  for (const IfaceLoad& i : interface_loads(c, joints)) o += (o.empty() ? "" : "\n") + load_table(i);
  return o;
}

namespace {
constexpr const char* kLoadBegin =
    "<!-- BEGIN bus-load: generated by `armfw --bus-load-reference` from the bus-load calculation in "
    "firmware/config and hal/bus_load. Do not edit by hand: regenerate. -->";
constexpr const char* kLoadEnd = "<!-- END bus-load -->";
}  // namespace

std::string bus_load_reference_markdown() {
  std::string o = std::string(kLoadBegin) + "\n";
  const double rates[] = {250, 400, 500, 800, 1000, 2000};
  const std::size_t joints[] = {1, 2, 3, 4, 5, 6, 7};
  for (const double bitrate : {1e6, 5e5}) {
    for (const bool tpdo2 : {false, true}) {
      FwConfig c;
      c.can = "can0";
      c.bitrate = bitrate;
      c.tpdo2 = tpdo2;
      o += "\n" + std::string(bitrate == 1e6 ? "1 Mbit/s" : "500 kbit/s") +
           (tpdo2 ? ", with bus.tpdo2 = true (one more 6-byte frame per drive)" : ", the default frames (SYNC, RPDO1 and TPDO1 per drive, heartbeats every 50 ms)") +
           ":\n\n| drives |";
      for (const double r : rates) o += " " + num_text(r) + " Hz |";
      o += "\n| --- |";
      for (std::size_t i = 0; i < std::size(rates); ++i) o += " --- |";
      o += "\n";
      for (const std::size_t n : joints) {
        o += "| " + std::to_string(n) + " |";
        for (const double r : rates) {
          c.rate_hz = r;
          const double share = hal::bus_load(bus_traffic(c, n), bitrate).total();
          o += " " + pct_text(share) + (share > kBusLoadLimit ? " refused" : share > kBusLoadWarn ? " warned" : "") + " |";
        }
        o += "\n";
      }
    }
  }
  return o + "\n" + kLoadEnd + "\n";
}

std::string bus_load_reference_mismatch(const std::string& page) {
  const std::size_t b = page.find("<!-- BEGIN bus-load");
  const std::size_t e = page.find(kLoadEnd);
  const char* how = "regenerate it: armfw --bus-load-reference, pasted between the markers in docs/deployment.md";
  if (b == std::string::npos || e == std::string::npos || e < b)
    return std::string("docs/deployment.md: no BEGIN/END bus-load markers; ") + how;
  const std::string have = page.substr(b, e + std::strlen(kLoadEnd) + 1 - b);
  const std::string want = bus_load_reference_markdown();
  if (have == want) return "";
  const auto split = [](const std::string& t) {
    std::vector<std::string> out;
    std::size_t a = 0;
    while (a < t.size()) {
      const std::size_t n = std::min(t.find('\n', a), t.size());
      out.push_back(t.substr(a, n - a));
      a = n + 1;
    }
    return out;
  };
  const std::vector<std::string> hl = split(have), wl = split(want);
  for (std::size_t i = 0; i < std::max(hl.size(), wl.size()); ++i) {
    const std::string h = i < hl.size() ? hl[i] : "(none)", w = i < wl.size() ? wl[i] : "(none)";
    if (h != w) return "docs/deployment.md's bus-load table differs at its line " + std::to_string(i + 1) + ": page '" + h +
                       "', calculated '" + w + "'; " + how;
  }
  return std::string("docs/deployment.md's bus-load table differs; ") + how;
}

std::string validate_for_chain(const FwConfig& c, const kin::Chain& chain) {
  if (std::string bad = validate(c); !bad.empty()) return bad;  // the arithmetic below needs the ranges
  const int n = chain.n_joints;
  const std::string robot = c.robot;
  if (!c.home_deg.empty() && static_cast<int>(c.home_deg.size()) != n)
    return "motion.home_deg: needs " + std::to_string(n) + " values for " + robot + " (got " +
           std::to_string(c.home_deg.size()) + ")";
  if (!c.drives.empty() && static_cast<int>(c.drives.size()) != n)
    return "drive: " + std::to_string(c.drives.size()) + " [[drive]] tables for the " + std::to_string(n) +
           " joints of " + robot + " (give one per joint, or none)";
  if (!c.homing_order.empty()) {
    std::vector<bool> named(static_cast<std::size_t>(n), false);
    for (std::size_t g = 0; g < c.homing_order.size(); ++g)
      for (const int j : c.homing_order[g]) {
        if (j > n)
          return "homing.order[" + std::to_string(g) + "]: joint " + std::to_string(j) + " does not exist (" + robot +
                 " has " + std::to_string(n) + ")";
        named[static_cast<std::size_t>(j - 1)] = true;
      }
    for (int j = 0; j < n; ++j)
      if (!named[static_cast<std::size_t>(j)])
        return "homing.order: joint " + std::to_string(j + 1) + " is missing (name every joint once, or leave the key out)";
  }
  for (int j = 0; j < n; ++j) {
    const kin::DhRow& row = chain.joint(j);
    const bool prismatic = row.type == kin::JointType::prismatic;
    const double unit = kConfigUnits.joint_in(chain, j, 1.0);  // SI per deg / mm
    const char* u = prismatic ? " mm" : " deg";
    const std::string w = drive_label(static_cast<std::size_t>(j)) + ".";
    const DriveConfig* d = c.drives.empty() ? nullptr : &c.drives[static_cast<std::size_t>(j)];
    double lo = row.lower / unit, hi = row.upper / unit;  // deg / mm; may be infinite
    if (d && !d->limits.empty()) {
      if (d->limits[0] * unit < row.lower - 1e-12 || d->limits[1] * unit > row.upper + 1e-12)
        return w + "limits: [" + shown_text(d->limits[0]) + ", " + shown_text(d->limits[1]) +
               "] reaches outside the robot description's [" + shown_text(lo) + ", " + shown_text(hi) + "]" + u;
      lo = d->limits[0];
      hi = d->limits[1];
    }
    if (!c.home_deg.empty()) {
      const double h = c.home_deg[static_cast<std::size_t>(j)];
      if (!(h >= lo - 1e-9 && h <= hi + 1e-9))
        return "motion.home_deg[" + std::to_string(j) + "]: " + shown_text(h) + u + " is outside joint " +
               std::to_string(j + 1) + "'s limits [" + shown_text(lo) + ", " + shown_text(hi) + "]" + u;
    }
    // After homing the joint stands at its offset (the home mark's position, hard_stop the
    // backed-off point): one outside the limits would leave a homed arm outside them.
    if (d && d->homing_method != "none" && !(d->homing_offset >= lo - 1e-9 && d->homing_offset <= hi + 1e-9))
      return w + "homing.offset: " + shown_text(d->homing_offset) + u + " is outside joint " + std::to_string(j + 1) +
             "'s limits [" + shown_text(lo) + ", " + shown_text(hi) + "]" + u;
    // Drive scaling, as hal::JointScaling computes it: counts per joint unit.
    const bool own_counts = d && d->counts_per_rev > 0, own_gear = d && d->gear_ratio != 0;
    const double cpr = own_counts ? d->counts_per_rev : c.counts_per_rev;
    const double gear = own_gear ? d->gear_ratio : c.gear_ratio;
    const double per_unit = prismatic ? cpr * gear : cpr * gear / 360.0;  // counts per deg / mm
    const std::string scale_key = std::string(own_counts ? w : "bus.") + "counts_per_rev";
    const std::string scaling = " (" + shown_text(cpr) + " counts/rev x gear " + shown_text(gear) + ")";
    const double zero = d ? static_cast<double>(d->zero_offset) : 0.0;
    const double dir = d ? static_cast<double>(d->direction) : 1.0;
    for (const double q : {lo, hi}) {
      if (!std::isfinite(q)) continue;
      const double counts = zero + dir * q * per_unit;
      if (!(counts >= -kTwo31 && counts <= kTwo31 - 1))
        return scale_key + ": joint " + std::to_string(j + 1) + "'s range [" + shown_text(lo) + ", " + shown_text(hi) + "]" +
               u + " does not fit the drive's 32-bit position: " + shown_text(q) + u + " is " + shown_text(counts) +
               " counts" + scaling;
    }
    const double per_count = 1.0 / per_unit;  // deg / mm per count
    if (!(per_count < c.following_error_deg))
      return scale_key + ": one count is " + shown_text(per_count) + u + " on joint " + std::to_string(j + 1) +
             ", not finer than safety.following_error_deg (" + shown_text(c.following_error_deg) + ")" + scaling;
    double vmax = row.dynamics.max_velocity / unit;  // deg/s or mm/s; 0 = none given
    if (d && d->max_velocity > 0) vmax = d->max_velocity;
    if (vmax > 0 && vmax * per_unit > kTwo31 - 1)
      return scale_key + ": joint " + std::to_string(j + 1) + "'s maximum velocity " + shown_text(vmax) + u +
             "/s is " + shown_text(vmax * per_unit) + " counts/s, beyond the drive's 32-bit velocity" + scaling;
  }
  return safety_for_chain(c, chain);
}

std::string safety_for_chain(const FwConfig& c, const kin::Chain& chain) {
  kin::SafetyConfig env;
  if (std::string bad = safety_envelope(c, chain, env); !bad.empty()) return bad;
  if (c.safety_elbow_frame > chain.n_rows)
    return "safety.elbow_frame: " + std::to_string(c.safety_elbow_frame) + " is not a frame of " + c.robot + " (0.." +
           std::to_string(chain.n_rows) + ")";
  if (!env.enabled) return "";
  // The park pose (motion.home_deg, else zeros clamped into the limits, drive.limits included)
  // must lie inside the envelope's planes and boxes: an arm that cannot park is refused here.
  const int n = chain.n_joints;
  kin::JointVector home = kin::JointVector::Zero(n);
  for (int j = 0; j < n; ++j) {
    const double unit = kConfigUnits.joint_in(chain, j, 1.0);
    if (!c.home_deg.empty()) {
      home[j] = c.home_deg[static_cast<std::size_t>(j)] * unit;
      continue;
    }
    double lo = chain.joint(j).lower, hi = chain.joint(j).upper;
    if (!c.drives.empty() && c.drives[static_cast<std::size_t>(j)].limits.size() == 2) {
      lo = c.drives[static_cast<std::size_t>(j)].limits[0] * unit;
      hi = c.drives[static_cast<std::size_t>(j)].limits[1] * unit;
    }
    home[j] = std::clamp(0.0, lo, hi);
  }
  kin::SafetySample x;
  if (!kin::safety_sample(chain, env, home, 0.0, x)) return "";  // the joint checks name a bad home
  kin::SafetyConfig positions = env;  // the park pose is checked for position only
  positions.cone = false;
  kin::SafetyViolation v;
  if (kin::check_sample(positions, kin::SafetyMode::normal, x, 0.0, 0.0, 0.0, v)) {
    char line[256];
    return std::string("safety: the park pose (motion.home_deg) lies outside the envelope: ") +
           kin::describe(v, line, sizeof line);
  }
  return "";
}

std::string safety_envelope(const FwConfig& c, const kin::Chain& chain, kin::SafetyConfig& out) {
  out = kin::SafetyConfig{};
  kin::SafetyConfig e;
  constexpr double mm = 1e-3, deg = 3.14159265358979323846 / 180.0;
  // per joint: deg/s for a revolute joint, mm/s for a prismatic one, one value per joint
  const int n = std::min(chain.n_joints, kin::kMaxJoints);
  for (const auto& [key, list] : {std::pair{"safety.joint_speed_deg_s", &c.safety_joint_speed_deg_s},
                                  std::pair{"safety.reduced_joint_speed_deg_s", &c.safety_reduced_joint_speed_deg_s}})
    if (!list->empty() && list->size() != static_cast<std::size_t>(n))
      return std::string(key) + ": needs one value per joint of " + c.robot + " (" + std::to_string(n) + "), got " +
             std::to_string(list->size());
  bool joint_limits = false;
  for (int j = 0; j < n; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    if (chain.joint(j).type == kin::JointType::prismatic) e.prismatic |= 1u << j;
    e.joint_speed_tolerance[ju] = kConfigUnits.joint_in(chain, j, c.safety_tolerance_deg_s);
    if (!c.safety_joint_speed_deg_s.empty())
      e.normal.joint_speed[ju] = kConfigUnits.joint_in(chain, j, c.safety_joint_speed_deg_s[ju]);
    if (!c.safety_reduced_joint_speed_deg_s.empty())
      e.reduced.joint_speed[ju] = kConfigUnits.joint_in(chain, j, c.safety_reduced_joint_speed_deg_s[ju]);
    joint_limits = joint_limits || e.normal.joint_speed[ju] > 0 || e.reduced.joint_speed[ju] > 0;
  }
  // zone k's frame in the base frame (identity when the list gives none)
  auto frame_of = [&](const std::vector<double>& f, std::size_t k) {
    kin::Pose p = kin::Pose::Identity();
    if (f.size() < 6 * (k + 1)) return p;
    const double* v = &f[6 * k];
    p.translation() = Eigen::Vector3d(v[0], v[1], v[2]) * mm;
    p.linear() = kin::rotation_from_rpy(v[3] * deg, v[4] * deg, v[5] * deg);
    return p;
  };
  for (std::size_t i = 0; i + 3 < c.safety_planes.size() && e.plane_count < kin::kMaxSafetyPlanes; i += 4) {
    const Eigen::Vector3d n(c.safety_planes[i], c.safety_planes[i + 1], c.safety_planes[i + 2]);
    if (!(n.norm() > 1e-9)) return "safety.planes: plane " + std::to_string(i / 4) + ": zero normal";
    // n_f.p_f >= o in the frame F is (R n_f).p >= o + (R n_f).t in the base frame
    const kin::Pose f = frame_of(c.safety_plane_frames, i / 4);
    const Eigen::Vector3d nb = f.linear() * n.normalized();
    e.planes[static_cast<std::size_t>(e.plane_count++)] = {nb, c.safety_planes[i + 3] * mm + nb.dot(f.translation()),
                                                           true};
  }
  for (std::size_t i = 0; i + 3 < c.safety_reduced_planes.size() && e.trigger_count < kin::kMaxSafetyPlanes; i += 4) {
    const std::vector<double>& v = c.safety_reduced_planes;
    const Eigen::Vector3d n(v[i], v[i + 1], v[i + 2]);
    if (!(n.norm() > 1e-9)) return "safety.reduced_planes: plane " + std::to_string(i / 4) + ": zero normal";
    const kin::Pose f = frame_of(c.safety_reduced_plane_frames, i / 4);
    const Eigen::Vector3d nb = f.linear() * n.normalized();
    e.trigger_planes[static_cast<std::size_t>(e.trigger_count++)] = {nb, v[i + 3] * mm + nb.dot(f.translation()), false};
  }
  for (int pass = 0; pass < 2; ++pass) {
    const std::vector<double>& v = pass == 0 ? c.safety_keep_in : c.safety_keep_out;
    const std::vector<double>& fr = pass == 0 ? c.safety_keep_in_frames : c.safety_keep_out_frames;
    for (std::size_t i = 0; i + 5 < v.size() && e.box_count < kin::kMaxSafetyBoxes; i += 6)
      e.boxes[static_cast<std::size_t>(e.box_count++)] = {Eigen::Vector3d(v[i], v[i + 1], v[i + 2]) * mm,
                                                          Eigen::Vector3d(v[i + 3], v[i + 4], v[i + 5]) * mm,
                                                          pass == 0, true, frame_of(fr, i / 6)};
  }
  e.tool_radius = c.safety_tool_radius_mm * mm;
  e.elbow_frame = c.safety_elbow_frame;
  e.elbow_radius = c.safety_elbow_radius_mm * mm;
  if (c.safety_cone_axis.size() == 3) {
    const Eigen::Vector3d a(c.safety_cone_axis[0], c.safety_cone_axis[1], c.safety_cone_axis[2]);
    if (!(a.norm() > 1e-9)) return "safety.cone_axis: zero axis";
    e.cone = true;
    e.cone_axis = a.normalized();
  }
  e.normal.tcp_speed = c.safety_tcp_speed_mm_s * mm;
  e.normal.elbow_speed = c.safety_elbow_speed_mm_s * mm;
  e.normal.cone_half_angle = c.safety_cone_deg * deg;
  e.reduced.tcp_speed = c.safety_reduced_tcp_speed_mm_s * mm;
  e.reduced.elbow_speed = c.safety_reduced_elbow_speed_mm_s * mm;
  e.reduced.cone_half_angle = c.safety_reduced_cone_deg * deg;
  e.normal.stop_time = c.safety_stop_time_s;
  e.normal.stop_distance = c.safety_stop_distance_mm * mm;
  e.reduced.stop_time = c.safety_reduced_stop_time_s;
  e.reduced.stop_distance = c.safety_reduced_stop_distance_mm * mm;
  e.stop_time_tolerance = c.safety_tolerance_s;
  e.normal.momentum = c.safety_momentum_kg_m_s;
  e.normal.power = c.safety_power_w;
  e.reduced.momentum = c.safety_reduced_momentum_kg_m_s;
  e.reduced.power = c.safety_reduced_power_w;
  e.momentum_tolerance = c.safety_tolerance_kg_m_s;
  e.power_tolerance = c.safety_tolerance_w;
  if ((e.normal.has_dynamics_limit() || e.reduced.has_dynamics_limit()) && !chain.has_inertial)
    return std::string(e.normal.momentum > 0   ? "safety.momentum_kg_m_s"
                       : e.normal.power > 0    ? "safety.power_w"
                       : e.reduced.momentum > 0 ? "safety.reduced_momentum_kg_m_s"
                                                : "safety.reduced_power_w") +
           ": needs the robot's masses (" + c.robot + "'s description has no inertial data, docs/dynamics.md)";
  e.self_collision = c.safety_self_collision;
  e.self_collision_margin = c.safety_self_collision_margin_mm * mm;
  if (e.self_collision && chain.capsule_mask == 0)
    return "safety.self_collision: " + c.robot +
           "'s description has no capsules (capsule = { from, to, radius } per [[joint]], docs/safety.md)";
  e.position_tolerance = c.safety_tolerance_mm * mm;
  e.angle_tolerance = c.safety_tolerance_deg * deg;
  e.speed_tolerance = c.safety_tolerance_mm_s * mm;
  e.enabled = e.plane_count > 0 || e.box_count > 0 || e.trigger_count > 0 || e.cone || e.normal.tcp_speed > 0 || e.normal.elbow_speed > 0 ||
              e.reduced.tcp_speed > 0 || e.reduced.elbow_speed > 0 || joint_limits || e.normal.has_stop_limit() ||
              e.reduced.has_stop_limit() || e.normal.has_dynamics_limit() || e.reduced.has_dynamics_limit() ||
              e.self_collision;
  char buf[160];
  if (const std::string bad = kin::safety_config_problem(e, buf, sizeof buf); !bad.empty()) return "safety: " + bad;
  out = e;
  return "";
}

std::string safety_canonical(const FwConfig& c) {
  std::string text;
  for (const ConfigKey& k : config_keys()) {
    const std::string name = k.name;
    if (name.rfind("safety.", 0) != 0) continue;
    text += name + " = " + value_text(k, c) + "\n";
  }
  return text;
}

namespace {
std::uint32_t crc32_of(const std::string& text) {
  std::uint32_t crc = 0xFFFFFFFFu;
  for (const char ch : text) {
    crc ^= static_cast<unsigned char>(ch);
    for (int b = 0; b < 8; ++b) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
  }
  return ~crc;
}
}  // namespace

std::uint32_t safety_checksum(const FwConfig& c) { return crc32_of(safety_canonical(c)); }

std::string safety_description_canonical(const kin::Chain& chain) {
  std::string text;
  char line[256];
  for (int k = 0; k <= kin::kMaxRows; ++k) {
    if (((chain.capsule_mask >> k) & 1u) == 0) continue;
    const kin::Capsule& cp = chain.capsule[static_cast<std::size_t>(k)];
    char name[16];
    std::snprintf(line, sizeof line, "capsule %s = from [%.6f, %.6f, %.6f] to [%.6f, %.6f, %.6f] radius %.6f mm\n",
                  kin::capsule_name(k, name, sizeof name), cp.a.x() * 1e3, cp.a.y() * 1e3, cp.a.z() * 1e3,
                  cp.b.x() * 1e3, cp.b.y() * 1e3, cp.b.z() * 1e3, cp.radius * 1e3);
    text += line;
  }
  if (chain.capsule_mask == 0) return text;
  for (int i = 0; i < kin::kMaxCapsules; ++i) {
    std::snprintf(line, sizeof line, "capsule pairs %d = %08X\n", i,
                  static_cast<unsigned>(chain.capsule_pairs[static_cast<std::size_t>(i)]));
    text += line;
  }
  return text;
}

std::uint32_t safety_checksum(const FwConfig& c, const kin::Chain& chain) {
  return crc32_of(safety_canonical(c) + safety_description_canonical(chain));
}

namespace {
/// The key a syntax error at (line, column) of `text` is in, as the loader names it
/// ("loop.rate_hz", "drive[2].gear_ratio", "robot"), or "" when the error is not in a
/// `key = value` line's value (a header, a key, a value continued from an earlier line).
std::string key_at(const std::string& text, std::size_t line, std::size_t column) {
  auto trim = [](std::string_view v) {
    while (!v.empty() && (v.front() == ' ' || v.front() == '\t')) v.remove_prefix(1);
    while (!v.empty() && (v.back() == ' ' || v.back() == '\t' || v.back() == '\r')) v.remove_suffix(1);
    return v;
  };
  std::string table;  // "loop", "drive[2]", "" = top level
  std::vector<std::pair<std::string, int>> arrays;  // [[name]] counts
  std::size_t at = 0;
  for (std::size_t l = 1; at <= text.size(); ++l) {
    std::size_t end = text.find('\n', at);
    if (end == std::string::npos) end = text.size();
    const std::string_view raw(text.data() + at, end - at);
    const std::string_view t = trim(raw);
    if (l == line) {
      const std::size_t eq = raw.find('=');
      if (eq == std::string_view::npos || column <= eq + 1) return "";
      const std::string_view key = trim(raw.substr(0, eq));
      if (key.empty() || key.find_first_of("[]#\"'") != std::string_view::npos) return "";
      return (table.empty() ? "" : table + ".") + std::string(key);
    }
    if (t.rfind("[[", 0) == 0 && t.find("]]") != std::string_view::npos) {
      const std::string name(trim(t.substr(2, t.find("]]") - 2)));
      int n = 1;
      for (auto& [a, count] : arrays)
        if (a == name) n = ++count;
      if (n == 1) arrays.emplace_back(name, 1);
      table = name + "[" + std::to_string(n) + "]";
    } else if (t.rfind("[", 0) == 0 && t.find(']') != std::string_view::npos) {
      table = std::string(trim(t.substr(1, t.find(']') - 1)));
    }
    at = end + 1;
  }
  return "";
}

/// A syntax error ("<origin>:<line>:<column>: not valid TOML: ...") with the key it is in
/// after the position: "<origin>:<line>:<column>: <key>: not valid TOML: ...".
std::string with_key(const std::string& error, const std::string& text, const std::string& origin) {
  const std::string head = origin + ":";
  if (error.rfind(head, 0) != 0) return error;
  std::size_t line = 0, column = 0;
  const char* p = error.data() + head.size();
  const char* e = error.data() + error.size();
  auto r = std::from_chars(p, e, line);
  if (r.ec != std::errc() || r.ptr == e || *r.ptr != ':') return error;
  r = std::from_chars(r.ptr + 1, e, column);
  if (r.ec != std::errc() || e - r.ptr < 2 || r.ptr[0] != ':' || r.ptr[1] != ' ') return error;
  const std::string key = key_at(text, line, column);
  if (key.empty()) return error;
  const std::size_t rest = static_cast<std::size_t>(r.ptr + 2 - error.data());
  return error.substr(0, rest) + key + ": " + error.substr(rest);
}

std::string load_text(const std::string& text, const std::string& origin, FwConfig& cfg, bool check_bus_load) {
  kin::TomlDocument doc = kin::parse_toml(text, origin, kMaxFileBytes);  // size, UTF-8, nesting, syntax
  if (!doc.error.empty()) return with_key(doc.error, text, origin);
  const toml::table& top = doc.table;
  Reader r{origin, {}};
  const std::vector<std::string> secs = sections();
  FwConfig c = cfg;
  auto at = [&](const toml::node& n) { return kin::source_text(n.source(), origin) + ": "; };
  // Unknown names first (toml::table is ordered by key: the message does not depend on the file's order).
  for (const auto& [key, v] : top) {
    const std::string name(key.str());
    if (name == "drive" || name == "output") continue;
    if (std::find(secs.begin(), secs.end(), name) != secs.end()) {
      const toml::table* t = v.as_table();
      if (!t) return at(v) + name + ": expected a [" + name + "] table";
      for (const auto& [leaf, lv] : *t) {
        const std::string full = name + "." + std::string(leaf.str());
        bool known = false;
        for (const ConfigKey& k : kConfigTable) known = known || full == k.name;
        if (!known) return at(lv) + full + ": unknown key (see armfw --config-keys)";
      }
      continue;
    }
    bool known = false;
    for (const ConfigKey& k : kConfigTable) known = known || (name == k.name && section_of(k.name).empty());
    if (!known)
      return at(v) + name + ": " +
             (v.is_table() ? "unknown section (" + joined(secs) + ", [[drive]], [[output]])" : "unknown key (see armfw --config-keys)");
  }
  // Then every key in table order.
  for (const ConfigKey& k : kConfigTable) {
    const std::string sec = section_of(k.name);
    const toml::node* v = nullptr;
    if (sec.empty()) v = top.get(k.name);
    else if (const toml::table* t = top.get_as<toml::table>(sec)) v = t->get(k.name + sec.size() + 1);
    if (v && !r.read(k, *v, k.name, c)) return r.err;
  }
  if (const toml::node* v = top.get("drive")) {
    const toml::array* a = v->as_array();
    if (!a) return at(*v) + "drive: expected [[drive]] tables";
    c.drives.clear();
    for (const toml::node& t : *a) {
      DriveConfig d;
      if (!read_drive(r, t, c.drives.size(), c.can, d)) return r.err;
      c.drives.push_back(d);
    }
  }
  if (const toml::node* v = top.get("output")) {
    const toml::array* a = v->as_array();
    if (!a) return at(*v) + "output: expected [[output]] tables";
    c.outputs.clear();
    for (const toml::node& t : *a) {
      const std::string where = "output[" + std::to_string(c.outputs.size() + 1) + "]";
      const toml::table* tab = t.as_table();
      if (!tab) return at(t) + where + ": expected a table";
      OutputConfig o;
      for (const auto& [name, value] : *tab) {
        const OutputKey* k = nullptr;
        for (const OutputKey& e : kOutputTable)
          if (std::string(name.str()) == e.name) k = &e;
        if (!k) return at(value) + where + "." + std::string(name.str()) + ": unknown key (name, node, bit)";
        if (!r.read(*k, value, where + "." + k->name, o)) return r.err;
      }
      for (const OutputKey& k : kOutputTable)
        if (k.required && !tab->get(k.name))
          return at(t) + where + "." + k.name + ": missing (every [[output]] has a name, node and bit)";
      c.outputs.push_back(o);
    }
  }
  // No loop.rate_hz on a wire: the highest standard rate the drives' traffic leaves room at.
  const toml::table* loop = top.get_as<toml::table>("loop");
  if (!(loop && loop->get("rate_hz")) && bus_load_checked(c) && !c.drives.empty() && validate(c, false).empty()) {
    const double rates[] = {1000, 800, 500, 400, 250};
    double pick = 0;
    for (const double limit : {kBusLoadWarn, kBusLoadLimit})
      for (const double r : rates) {
        if (pick > 0) break;
        c.rate_hz = r;
        if (highest_load(c) <= limit) pick = r;  // every interface at its own rates
      }
    c.rate_hz = pick > 0 ? pick : 250;
  }
  const std::string bad = validate(c, check_bus_load);
  if (!bad.empty()) {
    const toml::node* n = node_of_label(top, bad);
    return (n ? at(*n) : origin + ": ") + bad;
  }
  cfg = c;
  return "";
}
}  // namespace

std::string load_config_text(const std::string& text, const std::string& origin, FwConfig& cfg, bool check_bus_load) {
  return kin::one_line(load_text(text, origin, cfg, check_bus_load));  // a key or string from the file may hold a newline
}

std::string load_config_file(const std::string& path, FwConfig& cfg, bool check_bus_load) {
  std::string text;
  if (std::string e = kin::read_text_file(path, text, kMaxFileBytes); !e.empty()) return e;
  return load_config_text(text, path, cfg, check_bus_load);
}

std::string to_toml(const FwConfig& c) {
  std::string out;
  for (const ConfigKey& k : kConfigTable)
    if (section_of(k.name).empty()) out += std::string(k.name) + " = " + value_of(k, c) + "\n";
  for (const std::string& sec : sections()) {
    out += "[" + sec + "]\n";
    for (const ConfigKey& k : kConfigTable)
      if (section_of(k.name) == sec) out += std::string(k.name + sec.size() + 1) + " = " + value_of(k, c) + "\n";
  }
  for (const DriveConfig& d : c.drives) {
    out += "[[drive]]\n";
    for (const DriveKey& k : kDriveTable) {
      if (is_unset(k, d)) continue;
      // A joint that does not home: its other homing keys only when they differ from the defaults.
      const bool homing_detail = std::strncmp(k.name, "homing.", 7) == 0 && std::strcmp(k.name, "homing.method") != 0;
      if (homing_detail && d.homing_method == "none" && value_of(k, d) == value_of(k, DriveConfig{})) continue;
      out += std::string(k.name) + " = " + value_of(k, d) + "\n";
    }
  }
  for (const OutputConfig& o : c.outputs) {
    out += "[[output]]\n";
    for (const OutputKey& k : kOutputTable) out += std::string(k.name) + " = " + value_of(k, o) + "\n";
  }
  return out;
}

// ---------------------------------------------------------------------------
// --config-keys and the reference page
// ---------------------------------------------------------------------------

std::string config_keys_text() {
  std::string o;
  auto line = [&](const std::string& name, const std::string& def, const std::string& range, const char* unit,
                  const char* doc) {
    auto pad = [](std::string s, std::size_t w) { return s.size() < w ? s.append(w - s.size(), ' ') : s + " "; };
    o += pad(name, 30) + "default " + pad(def, 22) + "range " + range + (*unit ? std::string("  unit ") + unit : "") +
         "\n    " + doc + "\n";
  };
  for (const ConfigKey& k : kConfigTable) line(k.name, default_of(k), range_of(k), k.unit, k.doc);
  line("drive", "[]", "[[drive]] tables", "", "one table per joint in chain order, give all or none; their keys:");
  for (const DriveKey& k : kDriveTable) line(std::string("drive.") + k.name, default_of(k), range_of(k), k.unit, k.doc);
  line("output", "[]", "[[output]] tables", "", "named digital outputs (out NAME on|off, M62..M65 P<index>); their keys:");
  for (const OutputKey& k : kOutputTable) line(std::string("output.") + k.name, default_of(k), range_of(k), k.unit, k.doc);
  return o;
}

namespace {

constexpr const char* kBegin =
    "<!-- BEGIN config-reference: generated by `armfw --config-reference` from the key tables in "
    "firmware/config/src/config.cpp. Do not edit by hand: change the table, then regenerate (see above). -->";
constexpr const char* kEnd = "<!-- END config-reference -->";


template <class S>
std::string table_row(const Key<S>& k, const std::string& name) {
  const std::string def = k.required    ? std::string("required")
                          : k.has_unset ? std::string(k.unset_text)
                                        : "`" + value_of(k, S{}) + "`";
  return "| `" + name + "` | " + md_cell(def) + " | " + md_cell(range_of(k)) + " | " + md_cell(k.unit) + " | " + md_cell(k.doc) + " |\n";
}

constexpr const char* kHeader = "| key | default | allowed | unit | meaning |\n| --- | --- | --- | --- | --- |\n";

}  // namespace

std::string config_reference_markdown() {
  std::string o = std::string(kBegin) + "\n\n### Top-level keys\n\n" + kHeader;
  for (const ConfigKey& k : kConfigTable)
    if (section_of(k.name).empty()) o += table_row(k, k.name);
  for (const std::string& sec : sections()) {
    o += "\n### `[" + sec + "]`\n\n" + kHeader;
    for (const ConfigKey& k : kConfigTable)
      if (section_of(k.name) == sec) o += table_row(k, k.name);
  }
  o += "\n### `[[drive]]`\n\n"
       "One table per joint, in chain order: give one for every joint or none (then every joint takes the [bus] "
       "values). Every key is optional; a key left out inherits what the default column says.\n\n";
  o += kHeader;
  for (const DriveKey& k : kDriveTable) o += table_row(k, std::string("drive.") + k.name);
  o += "\n### `[[output]]`\n\n"
       "Named digital outputs, in file order: `out NAME on|off` sets one at once, M64 / M65 P<index> "
       "(0-based, the order here) too, M62 / M63 P<index> at the start of the next move. Every table has all three "
       "keys (a missing one is refused naming it); names and (node, bit) pairs are unique, the node one of the arm's "
       "drives.\n\n";
  o += kHeader;
  for (const OutputKey& k : kOutputTable) o += table_row(k, std::string("output.") + k.name);
  o += std::string("\n") + kEnd + "\n";
  return o;
}

std::string config_reference_mismatch(const std::string& page) {
  return generated_section_mismatch(page, config_reference_markdown(),
                                    {"<!-- BEGIN config-reference", kEnd,
                                     "docs/configuration.md differs from armfw --config-reference",
                                     "regenerate the section: see \"Regenerating the reference\" in "
                                     "docs/configuration.md (armfw --config-reference)"});
}

}  // namespace servoarm::fw
