// SPDX-License-Identifier: Apache-2.0
// armctl drives scan / check: the drive doctor (cli_drives.hpp, drives_doctor.hpp). The scan
// itself is hal's (drive_scan.hpp: CANopen SDO 1000h/1018h, Damiao register reads); this file
// adds each drive's status (errors, temperatures), compares with armfw's configuration and
// prints what to change.
#include "servoarm/armctl/cli_drives.hpp"

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "servoarm/armctl/cli_common.hpp"

#ifdef SERVOARM_CLI_CAN
#include <algorithm>
#include <map>
#include <memory>
#include <vector>

#include "servoarm/armctl/drives_doctor.hpp"
#include "servoarm/hal/mit.hpp"
#include "servoarm/hal/socketcan_bus.hpp"
#endif

namespace servoarm::fw {

namespace {

const char* kDrivesUsage =
    "usage: armctl drives scan --iface IFACE [--fd] [--first N] [--last N] [--timeout MS]\n"
    "       armctl drives check --config FILE [--timeout MS]\n"
    "       armctl drives zero --iface IFACE --id N [--fd] [--timeout MS]\n"
    "\n"
    "  scan   what answers on a CAN interface, one line per drive: id, family, identity or\n"
    "         motor model, mode, frame format, errors, temperature. CANopen nodes: an SDO read\n"
    "         of 1000h to ids 1-127, then 1018h (identity), 1001h and 603Fh (errors); Damiao\n"
    "         motors: a register read of CTRL_MODE to each id, then their ranges, gear ratio,\n"
    "         CAN timeout and a status query (error, temperatures). --fd probes with CAN FD\n"
    "         frames (motors set to CAN FD do not see classic ones, and the reverse).\n"
    "         --timeout: how long answers are awaited (ms, default 50; longer on a busy host).\n"
    "  check  armfw's configuration (FILE) against the buses its [[drive]] tables name: one\n"
    "         line per joint, \"ok\" or what to change; drives that no joint names.\n"
    "         --timeout: as for scan.\n"
    "  zero   saves the present position as Damiao motor N's own zero (its save-zero frame),\n"
    "         the motor disabled; the position before and after.\n"
    "scan and check only read from the drives. Exit status: 0 found / as configured / saved,\n"
    "1 nothing found / something to change / not saved, 2 bad usage or an interface that\n"
    "cannot be opened.\n";

}  // namespace

#ifdef SERVOARM_CLI_CAN

namespace {

std::string fmt(const char* f, auto... a) {
  char buf[512];
  std::snprintf(buf, sizeof buf, f, a...);
  return buf;
}

std::string drive_line(hal::CanBus& bus, hal::Clock& clock, const hal::ScanOptions& opt, const hal::ScannedDrive& d) {
  char line[512], st[160];
  hal::describe_drive(d, line, sizeof line);
  hal::DriveStatus s;
  hal::read_drive_status(bus, clock, opt, d, s);
  hal::describe_status(d, s, st, sizeof st);
  return std::string(line) + ", " + st;
}

const char* format_name(bool fd) { return fd ? "CAN FD" : "classic CAN"; }

}  // namespace

int drives_scan(hal::CanBus& bus, hal::Clock& clock, const std::string& iface, const hal::ScanOptions& opt,
                std::string& out) {
  std::vector<hal::ScannedDrive> found(256);
  const std::size_t n = hal::scan_drives(bus, clock, opt, found);
  for (std::size_t i = 0; i < n; ++i) out += drive_line(bus, clock, opt, found[i]) + "\n";
  if (n == 0)
    out += fmt("no drive answered on %s (%s, ids %u-%u): check the bitrate, the frame format (--fd), the ids, "
               "wiring, termination and power\n",
               iface.c_str(), format_name(opt.fd), unsigned(opt.first_id), unsigned(opt.last_id));
  else
    out += fmt("%zu drive%s on %s (%s, ids %u-%u); a drive at another bitrate or frame format is not seen\n", n,
               n == 1 ? "" : "s", iface.c_str(), format_name(opt.fd), unsigned(opt.first_id), unsigned(opt.last_id));
  return static_cast<int>(n);
}

int drives_zero(hal::CanBus& bus, hal::Clock& clock, const std::string& iface, std::uint16_t id,
                const hal::ScanOptions& opt, std::string& out) {
  hal::ScanOptions o = opt;
  o.first_id = o.last_id = id;
  o.canopen = false;
  o.damiao = true;
  hal::ScannedDrive found[1];
  hal::DriveStatus before, after;
  if (hal::scan_drives(bus, clock, o, found) != 1 || !hal::read_drive_status(bus, clock, o, found[0], before)) {
    out += fmt("id 0x%02X: no Damiao motor answered on %s (%s): nothing saved; check the id, the frame format "
               "(--fd), the bitrate, wiring and power\n",
               unsigned(id), iface.c_str(), format_name(o.fd));
    return 1;
  }
  if (before.error == 1) {  // the feedback's state nibble: 1 = enabled
    out += fmt("id 0x%02X: the motor is enabled (is armfw driving it?): disable it first; nothing saved\n", unsigned(id));
    return 1;
  }
  hal::CanFrame f = hal::mit::special_frame(id, hal::mit::Special::save_zero);
  f.fd = f.brs = o.fd;
  if (bus.send(f) != hal::Status::ok || !hal::read_drive_status(bus, clock, o, found[0], after)) {
    out += fmt("id 0x%02X: no answer after the save-zero frame: read it again with armctl drives scan\n", unsigned(id));
    return 1;
  }
  out += fmt("id 0x%02X: damiao %s: zero saved in the motor: position %.3f rad -> %.3f rad (armfw: drive.zero_offset "
             "= 0 for its joint)\n",
             unsigned(id), found[0].model != nullptr ? found[0].model->name : "model unknown", before.position,
             after.position);
  return 0;
}

int drives_check(const FwConfig& cfg, int joints, const BusOpener& open, hal::Clock& clock, std::string& out,
                 hal::Duration window, hal::Duration timeout) {
  struct Joint {
    int index;
    DriveConfig d;
    std::string iface;
    int node;
  };
  std::vector<Joint> js;
  if (cfg.drives.empty())
    for (int j = 0; j < joints; ++j) js.push_back({j, DriveConfig{}, cfg.can, cfg.first_node + j});
  else
    for (std::size_t j = 0; j < cfg.drives.size(); ++j) {
      const DriveConfig& d = cfg.drives[j];
      js.push_back({int(j), d, d.can.empty() ? cfg.can : d.can, d.node != 0 ? d.node : cfg.first_node + int(j)});
    }
  int problems = 0;
  std::vector<std::string> ifaces;
  for (const Joint& j : js)
    if (std::find(ifaces.begin(), ifaces.end(), j.iface) == ifaces.end()) ifaces.push_back(j.iface);
  for (const std::string& iface : ifaces) {
    if (iface == "sim") {
      out += "bus.can = \"sim\": the simulated drives, nothing to check on a bus\n";
      continue;
    }
    hal::ScanOptions opt;
    opt.window = window;
    opt.timeout = timeout;
    bool any_mit = false;
    for (const Joint& j : js)
      if (j.iface == iface) {
        if (j.d.can_fd) opt.fd = true;
        if (j.d.family != "cia402") any_mit = true;
        opt.last_id = static_cast<std::uint16_t>(std::max<int>(opt.last_id, std::min(j.node, 0x7FE)));
      }
    std::string error;
    hal::CanBus* bus = open(iface, opt.fd, error);
    if (bus == nullptr) {
      out += iface + ": " + error + "\n";
      ++problems;
      continue;
    }
    opt.damiao = any_mit;
    // the rates this interface's drives are set up for (drive.bitrate / drive.data_bitrate, else bus.*)
    bool own_rate = false;
    for (const Joint& j : js) own_rate = own_rate || (j.iface == iface && j.d.bitrate != 0);
    const double data_rate = interface_data_bitrate(cfg, iface);
    const std::string rates = num(interface_bitrate(cfg, iface)) + " bit/s in " + (own_rate ? "drive.bitrate" : "bus.bitrate") +
                              (data_rate > 0 ? ", data phase " + num(data_rate) + " bit/s" : std::string());
    std::vector<hal::ScannedDrive> found(256);
    const std::size_t n = hal::scan_drives(*bus, clock, opt, found);
    std::vector<bool> claimed(n, false);
    auto find = [&](hal::ScannedDrive::Kind k, int id) -> int {
      for (std::size_t i = 0; i < n; ++i)
        if (found[i].kind == k && found[i].id == id) return static_cast<int>(i);
      return -1;
    };
    for (const Joint& j : js) {
      if (j.iface != iface) continue;
      const DriveConfig& d = j.d;
      const std::string who = fmt("joint %d (%s %s %d on %s)", j.index + 1, d.family.c_str(),
                                  d.family == "cia402" ? "node" : "id", j.node, iface.c_str());
      if (d.family == "cia402") {
        const int i = find(hal::ScannedDrive::Kind::canopen, j.node);
        if (i < 0) {
          out += who + ": not seen (no answer to an SDO read of 1000h): check drive.node, the bitrate (" + rates +
                 "), wiring, termination and power\n";
          ++problems;
          continue;
        }
        claimed[std::size_t(i)] = true;
        const hal::ScannedDrive& s = found[std::size_t(i)];
        hal::DriveStatus st;
        hal::read_drive_status(*bus, clock, opt, s, st);
        if ((s.device_type & 0xFFFF) != 402) {
          out += who + fmt(": node %d answers but is not a CiA 402 drive (device type 0x%08X): check drive.node\n",
                           j.node, unsigned(s.device_type));
          ++problems;
        } else if (st.answered && st.error != 0) {
          out += who + fmt(": CiA 402 drive in fault (error register 0x%02X, error code 0x%04X): clear the cause\n",
                           unsigned(st.error), unsigned(st.error_code));
          ++problems;
        } else {
          out += who + fmt(": ok, CiA 402 drive, vendor 0x%08X, product 0x%08X\n", unsigned(s.vendor), unsigned(s.product));
        }
        continue;
      }
      if (d.family != "damiao") {
        out += who + ": not checked: the scan speaks CANopen and Damiao only\n";
        continue;
      }
      const int i = find(hal::ScannedDrive::Kind::damiao, j.node);
      if (i < 0) {
        out += who + fmt(": not seen (no answer to a register read in %s): a motor set to %s needs drive.can_fd = %s; "
                         "else check drive.node, the bitrate (%s), wiring, termination and power\n",
                         format_name(opt.fd), format_name(!opt.fd), opt.fd ? "false" : "true", rates.c_str());
        ++problems;
        continue;
      }
      claimed[std::size_t(i)] = true;
      const hal::ScannedDrive& s = found[std::size_t(i)];
      hal::DriveStatus st;
      hal::read_drive_status(*bus, clock, opt, s, st);
      std::vector<std::string> change, note;
      const hal::mit::MotorProfile* want = hal::mit::find_profile(d.motor);
      if (s.model == nullptr)
        change.push_back(fmt("the motor reads Gr %g, TMAX %g: no profile matches (drive.motor = \"%s\")", double(s.gear),
                             double(s.tmax), d.motor.c_str()));
      else if (s.model != want)
        change.push_back(fmt("set drive.motor = \"%s\" (the motor reads Gr %g, TMAX %g; the file says \"%s\")",
                             s.model->name, double(s.gear), double(s.tmax), d.motor.c_str()));
      const int master = mit_master_id(d, j.node);
      if (s.master_id != master)
        change.push_back(fmt("set drive.master_id = 0x%03X (the motor answers on 0x%03X, the file expects 0x%03X)",
                             unsigned(s.master_id), unsigned(s.master_id), unsigned(master)));
      if (st.answered && hal::mit::damiao_is_fault(st.error))
        change.push_back(fmt("the motor reports %s (%u): clear the cause (armfw clears the error at bring-up)",
                             hal::mit::damiao_error_name(st.error), unsigned(st.error)));
      if (s.ctrl_mode != hal::mit::kModeMit)
        note.push_back(fmt("mode %u %s: armfw sets MIT at bring-up and stops with a message if the motor refuses",
                           unsigned(s.ctrl_mode), hal::mit::ctrl_mode_name(s.ctrl_mode)));
      if (s.timeout == 0) note.push_back("CAN timeout off: armfw sets it at bring-up");
      std::string line = who + (change.empty() ? ": ok" : ": change");
      for (const std::string& c : change) line += "; " + c;
      line += fmt(", %s", s.model != nullptr ? s.model->name : "model unknown");
      if (st.answered) line += fmt(", %s, MOS %.0f C, rotor %.0f C", format_name(st.fd), double(st.t_mos), double(st.t_rotor));
      for (const std::string& c : note) line += "; note: " + c;
      out += line + "\n";
      if (!change.empty()) ++problems;
    }
    for (std::size_t i = 0; i < n; ++i) {
      if (claimed[i]) continue;
      char line[512];
      hal::describe_drive(found[i], line, sizeof line);
      out += iface + ": " + line + ": no joint names it (drive.node)\n";
    }
  }
  out += problems == 0 ? "the configuration matches the buses\n"
                       : fmt("%d thing%s to change before armfw runs on this arm\n", problems, problems == 1 ? "" : "s");
  return problems;
}

namespace {

bool parse_id(const char* option, const char* s, int hi, std::uint16_t& out, int& rc) {
  char* end = nullptr;
  const long l = std::strtol(s, &end, 0);
  if (end == s || *end != '\0' || l < 1 || l > hi) {
    rc = usage_error(fmt("%s: '%s' is not an id 1..%d", option, s, hi));
    return false;
  }
  out = static_cast<std::uint16_t>(l);
  return true;
}

/// --timeout MS (scan and check): how long answers are awaited. False with `rc` set when bad.
bool parse_timeout(const char* s, hal::Duration& out, int& rc) {
  double ms = 0;
  if (!parse_number(s, ms) || ms < 1 || ms > 10000) {
    rc = usage_error(fmt("--timeout: '%s' is not a time in ms (1..10000)", s));
    return false;
  }
  out = static_cast<hal::Duration>(ms * double(hal::kMillisecond));
  return true;
}

/// The options scan and zero share: --iface IFACE, --fd, --timeout MS. Returns 1 when argv[i]
/// is one of them (i moved past its value), 0 when it is not, -1 with `rc` set when its value
/// is bad.
int shared_option(int argc, char** argv, int& i, std::string& iface, hal::ScanOptions& opt, int& rc) {
  const std::string a = argv[i];
  const bool more = i + 1 < argc;
  if (a == "--iface" && more) iface = argv[++i];
  else if (a == "--fd") opt.fd = true;
  else if (a == "--timeout" && more) {
    if (!parse_timeout(argv[++i], opt.timeout, rc)) return -1;
    opt.window = opt.timeout;
  } else return 0;
  return 1;
}

/// Opens `iface` for `command` (classic or CAN FD, no reopening); 0, or the usage error's code.
int open_bus(const char* command, const std::string& iface, bool fd, hal::SocketCanBus& bus) {
  hal::SocketCanOptions so;
  so.enable_fd = fd;
  so.auto_reopen = false;
  if (const hal::Status s = bus.open(iface.c_str(), so); s != hal::Status::ok)
    return usage_error(fmt("drives %s: cannot open %s%s: %s", command, iface.c_str(), fd ? " for CAN FD" : "",
                           hal::describe(s)));
  return 0;
}

int scan_main(int argc, char** argv) {
  std::string iface;
  hal::ScanOptions opt;
  int rc = 0;
  for (int i = 0; i < argc; ++i) {
    const std::string a = argv[i];
    const bool more = i + 1 < argc;
    if (a == "--help" || a == "-h") {
      std::fputs(kDrivesUsage, stdout);
      return kExitOk;
    }
    if (const int k = shared_option(argc, argv, i, iface, opt, rc); k != 0) {
      if (k < 0) return rc;
    } else if (a == "--first" && more) {
      if (!parse_id("--first", argv[++i], 0x7FE, opt.first_id, rc)) return rc;
    } else if (a == "--last" && more) {
      if (!parse_id("--last", argv[++i], 0x7FE, opt.last_id, rc)) return rc;
    } else return usage_error("drives scan: unknown or incomplete option '" + a + "' (see armctl drives --help)");
  }
  if (iface.empty()) return usage_error("drives scan: --iface IFACE is required (e.g. can0)");
  if (opt.first_id > opt.last_id) return usage_error("drives scan: --first is above --last");
  hal::SocketCanBus bus;
  if (const int e = open_bus("scan", iface, opt.fd, bus); e != 0) return e;
  hal::MonotonicClock clock;
  std::string out;
  const int n = drives_scan(bus, clock, iface, opt, out);
  std::fputs(out.c_str(), stdout);
  return n > 0 ? kExitOk : kExitFailed;
}

int check_main(int argc, char** argv) {
  std::string file;
  hal::Duration timeout = 50 * hal::kMillisecond;
  int rc = 0;
  for (int i = 0; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help" || a == "-h") {
      std::fputs(kDrivesUsage, stdout);
      return kExitOk;
    }
    if (a == "--config" && i + 1 < argc) file = argv[++i];
    else if (a == "--timeout" && i + 1 < argc) {
      if (!parse_timeout(argv[++i], timeout, rc)) return rc;
    } else return usage_error("drives check: unknown or incomplete option '" + a + "' (see armctl drives --help)");
  }
  if (file.empty()) return usage_error("drives check: --config FILE is required");
  FwConfig cfg;
  if (const std::string e = load_config_file(file, cfg); !e.empty()) return usage_error(e);
  int joints = static_cast<int>(cfg.drives.size());
  if (joints == 0) {
    const kin::LoadResult r = load_robot_checked(cfg.robot);
    if (!r.ok) return usage_error(r.error);
    joints = r.chain.n_joints;
  }
  std::map<std::string, std::unique_ptr<hal::SocketCanBus>> buses;
  const BusOpener open = [&](const std::string& iface, bool fd, std::string& error) -> hal::CanBus* {
    auto bus = std::make_unique<hal::SocketCanBus>();
    hal::SocketCanOptions so;
    so.enable_fd = fd;
    so.auto_reopen = false;
    if (const hal::Status s = bus->open(iface.c_str(), so); s != hal::Status::ok) {
      error = fmt("cannot open%s: %s", fd ? " for CAN FD" : "", hal::describe(s));
      return nullptr;
    }
    return (buses[iface] = std::move(bus)).get();
  };
  hal::MonotonicClock clock;
  std::string out;
  const int problems = drives_check(cfg, joints, open, clock, out, timeout, timeout);
  std::fputs(out.c_str(), stdout);
  return problems == 0 ? kExitOk : kExitFailed;
}

int zero_main(int argc, char** argv) {
  std::string iface;
  hal::ScanOptions opt;
  std::uint16_t id = 0;
  int rc = 0;
  for (int i = 0; i < argc; ++i) {
    const std::string a = argv[i];
    const bool more = i + 1 < argc;
    if (a == "--help" || a == "-h") {
      std::fputs(kDrivesUsage, stdout);
      return kExitOk;
    }
    if (const int k = shared_option(argc, argv, i, iface, opt, rc); k != 0) {
      if (k < 0) return rc;
    } else if (a == "--id" && more) {
      if (!parse_id("--id", argv[++i], 0x7FE, id, rc)) return rc;
    } else return usage_error("drives zero: unknown or incomplete option '" + a + "' (see armctl drives --help)");
  }
  if (iface.empty()) return usage_error("drives zero: --iface IFACE is required (e.g. can0)");
  if (id == 0) return usage_error("drives zero: --id N is required (the motor's id)");
  hal::SocketCanBus bus;
  if (const int e = open_bus("zero", iface, opt.fd, bus); e != 0) return e;
  hal::MonotonicClock clock;
  std::string out;
  const int r = drives_zero(bus, clock, iface, id, opt, out);
  std::fputs(out.c_str(), stdout);
  return r == 0 ? kExitOk : kExitFailed;
}

}  // namespace

int cli_drives(int argc, char** argv) {
  // argv[0] = "drives"
  if (argc < 2 || !std::strcmp(argv[1], "--help") || !std::strcmp(argv[1], "-h")) {
    std::fputs(kDrivesUsage, argc < 2 ? stderr : stdout);
    return argc < 2 ? kExitUsage : kExitOk;
  }
  const std::string sub = argv[1];
  if (sub == "scan") return scan_main(argc - 2, argv + 2);
  if (sub == "check") return check_main(argc - 2, argv + 2);
  if (sub == "zero") return zero_main(argc - 2, argv + 2);
  return usage_error("unknown drives command '" + sub + "' (see armctl drives --help)");
}

#else

int cli_drives(int argc, char** argv) {
  (void)argc;
  (void)argv;
  return usage_error(std::string("drives: this armctl is built without the CAN layer (hal)\n") + kDrivesUsage);
}

#endif

}  // namespace servoarm::fw
