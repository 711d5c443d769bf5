// SPDX-License-Identifier: Apache-2.0
// armsim: virtual CiA 402 servo drives and MIT-mode motors on a SocketCAN interface (e.g. vcan0).
#include <algorithm>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "servoarm/hal/clock.hpp"
#include "servoarm/hal/socketcan_bus.hpp"
#include "servoarm/sim/cli.hpp"
#include "servoarm/kinematics/description.hpp"
#include "servoarm/sim/arm_plant.hpp"
#include "servoarm/sim/mit_motor.hpp"
#include "servoarm/sim/virtual_drive.hpp"

using namespace servoarm;
using namespace servoarm::hal;
namespace cli = servoarm::sim::cli;

namespace {

volatile std::sig_atomic_t g_stop = 0;
void on_signal(int) { g_stop = 1; }

const char* kUsage =
    "usage: armsim (--iface NAME | --fd N) [--nodes LIST] [options]\n"
    "\n"
    "Virtual CiA 402 servo drives (CANopen nodes) on a SocketCAN interface. Each node\n"
    "boots into pre-operational (boot-up heartbeat), answers SDO, follows NMT, produces\n"
    "heartbeats (0x1017) and EMCY, sends SYNC-triggered TPDOs as mapped by the master and\n"
    "runs a motor model in cyclic synchronous position mode.\n"
    "\n"
    "  --iface NAME            SocketCAN interface, e.g. vcan0 (this or --fd is required)\n"
    "  --fd N                  testing: use inherited fd N (a CAN_RAW socket or a SOCK_SEQPACKET\n"
    "                          socketpair end carrying struct can_frame records) instead of --iface\n"
    "  --nodes LIST            node ids: 1-6, 1,3,5 or 2-4,7 (default 1-6); none: no CiA 402 drive\n"
    "  --duration SEC          exit after SEC seconds (default: until SIGINT/SIGTERM)\n"
    "  --heartbeat-ms N        heartbeat producer time before the master sets 0x1017 (default 0 = off)\n"
    "  --lag-ms X              position-loop time constant (default 2)\n"
    "  --counts-per-rev N      encoder counts per motor revolution, for --vmax/--amax (default 131072)\n"
    "  --vmax REV_PER_S        velocity limit in motor revolutions/s (default 10)\n"
    "  --amax REV_PER_S2       acceleration limit (default 400)\n"
    "  --window COUNTS         following error window 0x6065 (default 13107)\n"
    "  --seed N                random seed for noise and drops (default 1)\n"
    "\n"
    "Plant (default first-order: each drive its own massless first-order motor, --lag-ms):\n"
    "  --plant dynamic         the drives move one rigid-body arm (--robot): each drive's position and\n"
    "                          velocity loop commands a joint torque, the arm's forward dynamics (gravity,\n"
    "                          friction, brakes) are integrated with RK4 at --step-us; nodes = joints in order\n"
    "  --robot NAME|FILE       built-in model or description file with inertial data (default puma560)\n"
    "  --gear-ratio G          motor revolutions per joint revolution, all joints (default 1)\n"
    "  --step-us N             integration step = the drives' loop period (default 100)\n"
    "  --bandwidth HZ          velocity-loop bandwidth for the automatic gains (default 40)\n"
    "  --kp X                  position-loop gain, 1/s, every joint (default bandwidth x 2 pi / 4)\n"
    "  --ki X                  velocity-loop integral gain, 1/s, every joint (default 0 = off)\n"
    "  --gains J:KP,KV,KI,TMAX joint J's loop: KP 1/s, KV N m s/rad, KI 1/s, torque limit N m (0 = automatic)\n"
    "  --friction J:VISC,COUL  extra friction on joint J (N m s/rad, N m) on top of the description's\n"
    "  --no-brakes             unpowered joints swing freely (default: holding brakes lock them)\n"
    "  --no-gravity            ignore the description's gravity\n"
    "  --stop J:DEG[:-]        rigid stop: joint J cannot pass DEG (mm for prismatic) upwards (':-': downwards)\n"
    "  --tool-force FX,FY,FZ   constant force at the tool point, world frame, N\n"
    "  --joint-torque J:NM     constant external torque on joint J\n"
    "  --without LIST          objects the drives lack, e.g. 0x606C,0x603F (a drive with less: SDO\n"
    "                          access aborts 06020000h, mapping it 06040041h)\n"
    "  --check-map-entries     refuse a PDO mapping entry for an object it lacks when the entry is\n"
    "                          written (default: when the count, sub 0, is written)\n"
    "  --status-every SEC      print one status line per node every SEC seconds\n"
    "  --verbose               print NMT/CiA 402 state changes\n"
    "\n"
    "MIT-mode motors (docs/servo-bus.md#virtual-mit-motors), beside or instead of the CiA 402 drives:\n"
    "  --mit MODEL:ID[:MASTER]  a virtual motor (DM-J4310-2EC, DM-J4340, DM-J8006, AK80-9, RS00) with command id\n"
    "                          ID, answering on MASTER (default: Damiao ID + 0x10, Robstride 0xFD, CubeMars 0)\n"
    "  --mit-mode ID:MODE      Damiao CTRL_MODE at power-up (1 MIT, 2 position-velocity, ...; default 1)\n"
    "  --mit-locked ID         its CTRL_MODE cannot be written (answered, not taken)\n"
    "  --mit-fd                the MIT motors are set to CAN FD (they take and send FD frames only)\n"
    "\n"
    "Switches and homing (positions in encoder counts of the drive before homing, 'inf' /\n"
    "'-inf' for none; NODE is a node id or 'all'). 60FDh reports them; Homing Mode (6060h = 6)\n"
    "with methods 1-7, 11, 17-23, 27, 33, 34, 35, 37 (docs/servo-bus.md#homing):\n"
    "  --home-switch NODE:LO[,HI]   home switch active on [LO, HI] (default HI = inf: a positive home switch)\n"
    "  --limits NODE:NEG,POS        negative / positive limit switches, active at or beyond\n"
    "  --end-stops NODE:NEG,POS     mechanical end stops: the shaft stops there, the following error grows\n"
    "  --index NODE:PERIOD[,PHASE]  index pulse every PERIOD counts at PHASE (default one per --counts-per-rev, 0)\n"
    "  --max-travel NODE:COUNTS     homing error after this much travel without the mark (default none)\n"
    "  --no-homing NODE             the drive has no homing mode (6502h bit 5 clear; 6060h = 6 refused)\n"
    "  --modes NODE:MASK            6502h supported drive modes as reported (e.g. 0x252)\n"
    "Conformance behaviours of real drives:\n"
    "  --sdo-delay-ms NODE:N        every SDO reply N ms late\n"
    "  --boot-delay-ms NODE:N       the boot-up (heartbeat, first SDO answers) N ms after start\n"
    "  --never-attained NODE        homing reaches home but never sets statusword bit 12\n"
    "  --halt-blocks-mode NODE      a mode change written while controlword bit 8 (halt) is set acts only\n"
    "                               once halt clears\n"
    "  --refuse-same-mode NODE      writing 6060h with the mode already active aborts 08000022h\n"
    "  --reset-on-level NODE        a fault reset on bit 7 set, without the rising edge CiA 402 requires\n"
    "\n"
    "Fault injection (NODE is a node id or 'all'; @SEC = seconds after start, default 0):\n"
    "  --silent NODE[@SEC]          node stops sending and ignores the bus (unplugged)\n"
    "  --stop-heartbeat NODE[@SEC]  only the heartbeat producer stops\n"
    "  --emcy NODE:CODE[@SEC]       EMCY with CODE (e.g. 0x2310) and the drive faults\n"
    "  --refuse-enable NODE         the drive stays in switched_on when told to enable\n"
    "  --noise NODE:COUNTS          uniform +-COUNTS noise on the reported position\n"
    "  --drop-rate NODE:P           each frame the node sends is lost with probability P\n"
    "\n"
    "Output: 'armsim ready iface=... nodes=...' once the socket is open, then event lines, e.g.\n"
    "'armsim homed t=SEC node=N method=M mark=COUNTS physical=COUNTS position=COUNTS' when a homing\n"
    "attains (mark: where the drive found its home mark, physical: where the shaft stands, both in the\n"
    "counts before homing; position: 6064h).\n"
    "Exit status: 0 normal end (duration, signal, or --fd peer closed), 2 usage error,\n"
    "3 cannot open the interface.\n";

struct Scheduled {
  enum Kind { silent, stop_hb, emcy } kind;
  cli::FaultArg arg;
  std::uint16_t code = 0;
  bool done = false;
};

int usage_error(const std::string& msg) {
  std::fprintf(stderr, "armsim: %s\n(see armsim --help)\n", msg.c_str());
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  std::string iface;
  std::uint32_t fd = 0;
  bool have_fd = false;
  std::vector<std::uint8_t> nodes = {1, 2, 3, 4, 5, 6};
  double duration = 0, status_every = 0, lag_ms = 2, vmax = 10, amax = 400;
  std::uint32_t hb_ms = 0, window = 13107, seed = 1, cpr = 131072;
  bool verbose = false, check_entries = false, dynamic = false;
  sim::ArmPlantParams pp;
  std::string robot = "puma560";
  double gear = 1.0, stop_user = 0;
  std::vector<std::uint16_t> without;
  std::vector<Scheduled> schedule;
  std::vector<cli::FaultArg> refuse, noise, drops;
  struct HomingArg {
    std::string opt;
    cli::FaultArg arg;
    std::vector<double> xs;
  };
  std::vector<HomingArg> homing_args;
  std::vector<sim::MitMotorSpec> mit_specs;
  std::vector<std::uint16_t> mit_locked;
  bool mit_fd = false;

  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&](std::string& out) {
      if (i + 1 >= argc) return false;
      out = argv[++i];
      return true;
    };
    std::string v;
    if (a == "--help" || a == "-h") {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (a == "--verbose") {
      verbose = true;
    } else if (a == "--check-map-entries") {
      check_entries = true;
    } else if (a == "--mit-fd") {
      mit_fd = true;
    } else if (a == "--no-brakes") {
      pp.brakes = false;
    } else if (a == "--no-gravity") {
      pp.gravity = false;
    } else if (a == "--plant") {
      if (i + 1 >= argc) return usage_error("--plant needs first-order or dynamic");
      const std::string k = argv[++i];
      if (k != "first-order" && k != "dynamic") return usage_error("bad --plant '" + k + "' (first-order or dynamic)");
      dynamic = k == "dynamic";
    } else if (!value(v)) {
      return usage_error("unknown option or missing value: " + a);
    } else if (a == "--iface") {
      iface = v;
    } else if (a == "--fd") {
      if (!cli::parse_uint(v, 1 << 20, fd)) return usage_error("bad --fd");
      have_fd = true;
    } else if (a == "--nodes" && v == "none") {
      nodes.clear();
    } else if (a == "--mit") {
      const std::size_t c1 = v.find(':');
      const hal::mit::MotorProfile* p = c1 == std::string::npos ? nullptr : hal::mit::find_profile(v.substr(0, c1));
      if (p == nullptr) return usage_error("bad --mit '" + v + "' (MODEL:ID[:MASTER], MODEL one of DM-J4310-2EC, DM-J4340, DM-J8006, AK80-9, RS00)");
      const std::string rest = v.substr(c1 + 1);
      const std::size_t c2 = rest.find(':');
      std::uint32_t id = 0, master = 0;
      if (!cli::parse_uint(rest.substr(0, c2), 0x7FE, id) || id == 0) return usage_error("bad --mit '" + v + "': id 1..0x7FE");
      if (c2 != std::string::npos) {
        if (!cli::parse_uint(rest.substr(c2 + 1), 0x7FF, master)) return usage_error("bad --mit '" + v + "': master 0..0x7FF");
      } else {
        master = p->vendor == hal::mit::Vendor::damiao ? id + 0x10 : p->vendor == hal::mit::Vendor::robstride ? 0xFD : 0;
      }
      sim::MitMotorSpec spec;
      spec.profile = p;
      spec.id = static_cast<std::uint16_t>(id);
      spec.master = static_cast<std::uint16_t>(master);
      mit_specs.push_back(spec);
    } else if (a == "--mit-mode" || a == "--mit-locked") {
      std::uint32_t id = 0, mode = 0;
      const std::size_t c1 = v.find(':');
      const bool mode_opt = a == "--mit-mode";
      if (!cli::parse_uint(v.substr(0, mode_opt ? c1 : std::string::npos), 0x7FE, id) ||
          (mode_opt && (c1 == std::string::npos || !cli::parse_uint(v.substr(c1 + 1), 7, mode))))
        return usage_error("bad " + a + " '" + v + "' (" + (mode_opt ? "ID:MODE" : "ID") + ")");
      bool found = false;
      for (auto& m : mit_specs)
        if (m.id == id) {
          found = true;
          if (mode_opt) m.ctrl_mode = mode;
        }
      if (!found) return usage_error(a + ": no --mit motor with id " + std::to_string(id) + " (give --mit first)");
      if (!mode_opt) mit_locked.push_back(static_cast<std::uint16_t>(id));
    } else if (a == "--nodes") {
      if (!cli::parse_nodes(v, nodes)) return usage_error("bad --nodes '" + v + "' (use e.g. 1-6 or 1,3,5; ids 1..127)");
    } else if (a == "--duration") {
      if (!cli::parse_double(v, duration) || duration < 0) return usage_error("bad --duration");
    } else if (a == "--status-every") {
      if (!cli::parse_double(v, status_every) || status_every < 0) return usage_error("bad --status-every");
    } else if (a == "--heartbeat-ms") {
      if (!cli::parse_uint(v, 65535, hb_ms)) return usage_error("bad --heartbeat-ms (0..65535)");
    } else if (a == "--lag-ms") {
      if (!cli::parse_double(v, lag_ms) || lag_ms <= 0) return usage_error("bad --lag-ms");
    } else if (a == "--counts-per-rev") {
      if (!cli::parse_uint(v, 0x7FFFFFFF, cpr) || cpr == 0) return usage_error("bad --counts-per-rev");
    } else if (a == "--vmax") {
      if (!cli::parse_double(v, vmax) || vmax <= 0) return usage_error("bad --vmax");
    } else if (a == "--amax") {
      if (!cli::parse_double(v, amax) || amax <= 0) return usage_error("bad --amax");
    } else if (a == "--window") {
      if (!cli::parse_uint(v, 0xFFFFFFFFu, window)) return usage_error("bad --window");
    } else if (a == "--without") {
      std::size_t p = 0;
      while (p <= v.size()) {
        const std::size_t q = std::min(v.find(',', p), v.size());
        std::uint32_t idx = 0;
        if (!cli::parse_uint(v.substr(p, q - p), 0xFFFF, idx) || idx < 0x1000)
          return usage_error("bad --without '" + v + "' (object indices 0x1000..0xFFFF, e.g. 0x606C,0x603F)");
        without.push_back(std::uint16_t(idx));
        p = q + 1;
      }
    } else if (a == "--robot") {
      robot = v;
    } else if (a == "--gear-ratio") {
      if (!cli::parse_double(v, gear) || gear < 1e-3 || gear > 1e5) return usage_error("bad --gear-ratio (1e-3..1e5)");
    } else if (a == "--step-us") {
      std::uint32_t us = 0;
      if (!cli::parse_uint(v, 2000, us) || us < 10) return usage_error("bad --step-us (10..2000)");
      pp.step = Duration(us) * kMicrosecond;
    } else if (a == "--bandwidth") {
      if (!cli::parse_double(v, pp.velocity_bandwidth_hz) || pp.velocity_bandwidth_hz <= 0 ||
          pp.velocity_bandwidth_hz > 2000)
        return usage_error("bad --bandwidth HZ (0..2000)");
    } else if (a == "--kp" || a == "--ki") {
      double x = 0;
      if (!cli::parse_double(v, x) || x < 0 || x > 1e5) return usage_error("bad " + a + " (0..1e5 1/s)");
      for (auto& g : pp.gains) (a == "--kp" ? g.kp : g.ki) = x;
    } else if (a == "--gains" || a == "--friction" || a == "--joint-torque" || a == "--stop") {
      // J:LIST of numbers
      const std::size_t colon = v.find(':');
      std::uint32_t jn = 0;
      if (colon == std::string::npos || !cli::parse_uint(v.substr(0, colon), 8, jn) || jn == 0)
        return usage_error("bad " + a + " '" + v + "' (joint number 1..8 first, then ':')");
      std::vector<double> xs;
      std::string rest = v.substr(colon + 1), tail;
      if (a == "--stop" && rest.size() > 2 && rest.compare(rest.size() - 2, 2, ":-") == 0) {
        tail = "-";
        rest.resize(rest.size() - 2);
      }
      std::size_t p = 0;
      while (p <= rest.size()) {
        const std::size_t q = std::min(rest.find(',', p), rest.size());
        double x = 0;
        if (!cli::parse_double(rest.substr(p, q - p), x)) return usage_error("bad " + a + " '" + v + "': not a number");
        xs.push_back(x);
        p = q + 1;
      }
      const std::size_t k = jn - 1;
      if (a == "--gains") {
        if (xs.size() != 4 || xs[0] < 0 || xs[1] < 0 || xs[2] < 0 || xs[3] < 0)
          return usage_error("bad --gains '" + v + "' (J:KP,KV,KI,TMAX, each >= 0; 0 = automatic)");
        pp.gains[k] = sim::ServoGains{xs[0], xs[1], xs[2], xs[3]};
      } else if (a == "--friction") {
        if (xs.size() != 2 || xs[0] < 0 || xs[1] < 0) return usage_error("bad --friction '" + v + "' (J:VISCOUS,COULOMB >= 0)");
        pp.extra_viscous[k] = xs[0];
        pp.extra_coulomb[k] = xs[1];
      } else if (a == "--joint-torque") {
        if (xs.size() != 1) return usage_error("bad --joint-torque '" + v + "' (J:NM)");
        pp.external_torque[k] = xs[0];
      } else {
        if (xs.size() != 1) return usage_error("bad --stop '" + v + "' (J:DEG or J:DEG:-)");
        pp.stop.joint = int(k);
        stop_user = xs[0];
        pp.stop.side = tail == "-" ? -1 : 1;
      }
    } else if (a == "--tool-force") {
      double f[3];
      std::size_t p = 0;
      for (int c = 0; c < 3; ++c) {
        const std::size_t q = std::min(v.find(',', p), v.size());
        if (p > v.size() || !cli::parse_double(v.substr(p, q - p), f[c])) return usage_error("bad --tool-force (FX,FY,FZ in N)");
        p = q + 1;
      }
      if (p <= v.size()) return usage_error("bad --tool-force (FX,FY,FZ in N)");
      pp.tool_force = Eigen::Vector3d(f[0], f[1], f[2]);
    } else if (a == "--seed") {
      if (!cli::parse_uint(v, 0xFFFFFFFFu, seed)) return usage_error("bad --seed");
    } else if (a == "--silent" || a == "--stop-heartbeat") {
      Scheduled s{a == "--silent" ? Scheduled::silent : Scheduled::stop_hb, {}, 0, false};
      if (!cli::parse_fault(v, false, s.arg)) return usage_error("bad " + a + " '" + v + "' (NODE[@SEC])");
      schedule.push_back(s);
    } else if (a == "--emcy") {
      Scheduled s{Scheduled::emcy, {}, 0, false};
      std::uint32_t code = 0;
      if (!cli::parse_fault(v, true, s.arg) || !cli::parse_uint(s.arg.value, 0xFFFF, code) || code == 0)
        return usage_error("bad --emcy '" + v + "' (NODE:CODE[@SEC], CODE e.g. 0x2310)");
      s.code = std::uint16_t(code);
      schedule.push_back(s);
    } else if (a == "--no-homing" || a == "--never-attained" || a == "--halt-blocks-mode" ||
               a == "--refuse-same-mode" || a == "--reset-on-level") {
      HomingArg h{a, {}, {}};
      if (!cli::parse_fault(v, false, h.arg) || !h.arg.value.empty() || h.arg.at != 0)
        return usage_error("bad " + a + " '" + v + "' (NODE or all)");
      homing_args.push_back(h);
    } else if (a == "--home-switch" || a == "--limits" || a == "--end-stops" || a == "--index" || a == "--max-travel" ||
               a == "--modes" || a == "--sdo-delay-ms" || a == "--boot-delay-ms") {
      HomingArg h{a, {}, {}};
      if (!cli::parse_fault(v, true, h.arg) || h.arg.at != 0) return usage_error("bad " + a + " '" + v + "' (NODE:VALUES)");
      std::size_t p = 0;
      const std::string& t = h.arg.value;
      while (p <= t.size()) {
        const std::size_t q = std::min(t.find(',', p), t.size());
        const std::string x = t.substr(p, q - p);
        double d = 0;
        if (x == "inf" || x == "+inf") d = sim::DriveSwitches::kNone;
        else if (x == "-inf") d = -sim::DriveSwitches::kNone;
        else if (std::uint32_t u = 0; x.rfind("0x", 0) == 0 && cli::parse_uint(x, 0xFFFFFFFFu, u)) d = double(u);
        else if (!cli::parse_double(x, d)) return usage_error("bad " + a + " '" + v + "': '" + x + "' is not a number");
        h.xs.push_back(d);
        p = q + 1;
      }
      const std::size_t n = h.xs.size();
      const bool two = a == "--limits" || a == "--end-stops";
      const bool ok = two ? n == 2 && h.xs[0] < h.xs[1]
                      : a == "--home-switch" ? (n == 1 || n == 2) && (n == 1 || h.xs[0] <= h.xs[1])
                      : a == "--index" ? (n == 1 || n == 2) && h.xs[0] > 0 && std::isfinite(h.xs[0])
                      : n == 1 && h.xs[0] >= 0 && std::isfinite(h.xs[0]);
      if (!ok) {
        const char* form = two ? "NODE:NEG,POS with NEG < POS"
                           : a == "--home-switch" ? "NODE:LO[,HI] with LO <= HI"
                           : a == "--index" ? "NODE:PERIOD[,PHASE], PERIOD > 0"
                           : "NODE:VALUE, VALUE >= 0";
        return usage_error("bad " + a + " '" + v + "' (" + form + ")");
      }
      homing_args.push_back(h);
    } else if (a == "--refuse-enable") {
      cli::FaultArg f;
      if (!cli::parse_fault(v, false, f)) return usage_error("bad --refuse-enable");
      refuse.push_back(f);
    } else if (a == "--noise" || a == "--drop-rate") {
      cli::FaultArg f;
      double x = 0;
      if (!cli::parse_fault(v, true, f) || !cli::parse_double(f.value, x) || x < 0 ||
          (a == "--drop-rate" && x > 1))
        return usage_error("bad " + a + " '" + v + "' (NODE:VALUE)");
      (a == "--noise" ? noise : drops).push_back(f);
    } else {
      return usage_error("unknown option " + a);
    }
  }
  if (iface.empty() == !have_fd) return usage_error("give exactly one of --iface NAME or --fd N");
  auto known = [&](std::uint8_t n) {
    return n == 0 || std::find(nodes.begin(), nodes.end(), n) != nodes.end();
  };
  for (auto& s : schedule)
    if (!known(s.arg.node)) return usage_error("fault for node " + std::to_string(s.arg.node) + " not in --nodes");

  std::unique_ptr<SocketCanBus> bus_ptr;
  if (have_fd) {
    bus_ptr = std::make_unique<SocketCanBus>(int(fd));
    iface = "fd:" + std::to_string(fd);
  } else {
    bus_ptr = std::make_unique<SocketCanBus>();
    SocketCanOptions opt;
    opt.enable_fd = mit_fd;  // the MIT motors set to CAN FD (the MTU check refuses a classic interface)
    if (const Status st = bus_ptr->open(iface.c_str(), opt); st != Status::ok) {
      std::fprintf(stderr, "armsim: cannot open %s: %s (%s)\n", iface.c_str(), bus_ptr->message(), to_string(st));
      return 3;
    }
  }
  SocketCanBus& bus = *bus_ptr;
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);

  sim::MotorParams motor;
  motor.lag = lag_ms * 1e-3;
  motor.max_velocity = vmax * cpr;
  motor.max_accel = amax * cpr;
  motor.following_window = window;
  motor.check_map_entries = check_entries;
  sim::ArmSim arm(bus, nodes, motor, seed);
  std::vector<std::unique_ptr<sim::VirtualMitMotor>> mit;
  for (sim::MitMotorSpec m : mit_specs) {
    m.fd = mit_fd;
    mit.push_back(std::make_unique<sim::VirtualMitMotor>(m));
    if (std::find(mit_locked.begin(), mit_locked.end(), m.id) != mit_locked.end()) mit.back()->quirks().mode_locked = true;
  }
  for (std::size_t i = 0; i < arm.size(); ++i)
    for (std::uint16_t idx : without) arm.at(i).od_remove(idx);
  for (auto& h : homing_args) {
    if (h.arg.node != 0 && !arm.node(h.arg.node))
      return usage_error(h.opt + ": node " + std::to_string(h.arg.node) + " not in --nodes");
  }
  for (std::size_t i = 0; i < arm.size(); ++i) {
    sim::VirtualDrive& d = arm.at(i);
    d.switches().index_period = double(cpr);
    sim::DriveQuirks q = d.quirks();
    for (auto& h : homing_args) {
      if (h.arg.node != 0 && h.arg.node != d.node()) continue;
      sim::DriveSwitches& s = d.switches();
      const auto& x = h.xs;
      if (h.opt == "--home-switch") s.home_lo = x[0], s.home_hi = x.size() > 1 ? x[1] : sim::DriveSwitches::kNone;
      else if (h.opt == "--limits") s.neg_limit = x[0], s.pos_limit = x[1];
      else if (h.opt == "--end-stops") s.end_neg = x[0], s.end_pos = x[1];
      else if (h.opt == "--index") s.index_period = x[0], s.index_phase = x.size() > 1 ? x[1] : 0.0;
      else if (h.opt == "--max-travel") s.max_travel = x[0];
      else if (h.opt == "--modes") q.supported_modes = std::uint32_t(x[0]);
      else if (h.opt == "--sdo-delay-ms") q.sdo_delay = Duration(x[0] * 1e6);
      else if (h.opt == "--boot-delay-ms") q.boot_delay = Duration(x[0] * 1e6);
      else if (h.opt == "--no-homing") q.no_homing = true;
      else if (h.opt == "--never-attained") q.never_attained = true;
      else if (h.opt == "--halt-blocks-mode") q.halt_blocks_mode_change = true;
      else if (h.opt == "--refuse-same-mode") q.refuse_same_mode = true;
      else if (h.opt == "--reset-on-level") q.fault_reset_on_level = true;
    }
    d.set_quirks(q);
  }
  MonotonicClock clock;
  const TimePoint t0 = clock.now();
  arm.power_on(t0);
  if (dynamic) {
    kin::LoadResult lr = kin::load_robot(robot);
    if (!lr.ok) return usage_error("--robot: " + lr.error);
    if (pp.stop.joint >= lr.chain.n_joints) return usage_error("--stop: the robot has no joint " + std::to_string(pp.stop.joint + 1));
    if (pp.stop.joint >= 0)
      pp.stop.position = stop_user * (lr.chain.joint(pp.stop.joint).type == kin::JointType::prismatic ? 1e-3
                                                                                                         : M_PI / 180.0);
    std::vector<JointScaling> sc(arm.size());
    for (std::size_t i = 0; i < sc.size(); ++i) {
      sc[i].counts_per_unit = cpr;
      sc[i].gear_ratio = gear;
      if (int(i) < lr.chain.n_joints && lr.chain.joint(int(i)).type == kin::JointType::prismatic)
        sc[i].kind = JointScaling::Kind::prismatic;
    }
    const std::string e = arm.use_dynamic_plant(lr.chain, sc, pp);
    if (!e.empty()) {
      std::fprintf(stderr, "armsim: --plant dynamic: %s\n", e.c_str());
      return 2;
    }
    sim::ArmPlant& pl = *arm.plant();
    std::printf("armsim plant=dynamic robot=%s step_us=%lld integrator=rk4 brakes=%s\n", robot.c_str(),
                static_cast<long long>(pp.step / kMicrosecond), pp.brakes ? "on" : "off");
    for (int j = 0; j < pl.joints(); ++j) {
      const auto& in = pl.info(j);
      std::printf("armsim joint=%d node=%u kp=%.4g kv=%.4g ki=%.4g torque_limit=%.4g rated_torque_mnm=%.0f "
                  "max_inertia=%.4g max_gravity=%.4g\n",
                  j + 1, unsigned(arm.at(std::size_t(j)).node()), in.gains.kp, in.gains.kv, in.gains.ki,
                  in.gains.torque_limit, in.rated_torque_mnm, in.max_inertia, in.max_gravity);
    }
  }
  auto each = [&](std::uint8_t node, auto fn) {
    for (std::size_t i = 0; i < arm.size(); ++i)
      if (node == 0 || arm.at(i).node() == node) fn(arm.at(i));
  };
  for (auto& f : refuse) each(f.node, [](sim::VirtualDrive& d) { d.faults().refuse_enable = true; });
  for (auto& f : noise) {
    double x = 0;
    cli::parse_double(f.value, x);
    each(f.node, [x](sim::VirtualDrive& d) { d.faults().position_noise = x; });
  }
  for (auto& f : drops) {
    double x = 0;
    cli::parse_double(f.value, x);
    each(f.node, [x](sim::VirtualDrive& d) { d.faults().tx_drop_rate = x; });
  }

  if (hb_ms > 0) {
    for (std::size_t i = 0; i < arm.size(); ++i) arm.at(i).od_write(0x1017, 0, hb_ms);
  }
  std::printf("armsim ready iface=%s nodes=", iface.c_str());
  for (std::size_t i = 0; i < nodes.size(); ++i) std::printf("%s%u", i ? "," : "", unsigned(nodes[i]));
  if (nodes.empty()) std::printf("none");
  if (!mit.empty()) {
    std::printf(" mit=");
    for (std::size_t i = 0; i < mit_specs.size(); ++i)
      std::printf("%s%s:0x%02X:0x%03X", i ? "," : "", mit_specs[i].profile->name, unsigned(mit_specs[i].id),
                  unsigned(mit_specs[i].master));
    if (mit_fd) std::printf(" mit_fd=1");
  }
  std::printf("\n");
  std::fflush(stdout);

  std::vector<double> last_mark(arm.size(), std::nan(""));
  std::vector<cia402::State> last_state(arm.size());
  std::vector<canopen::NmtState> last_nmt(arm.size());
  for (std::size_t i = 0; i < arm.size(); ++i) {
    last_state[i] = arm.at(i).state();
    last_nmt[i] = arm.at(i).nmt();
  }
  TimePoint next_tick = t0 + kMillisecond;
  TimePoint next_status = status_every > 0 ? t0 + TimePoint(status_every * 1e9) : 0;
  Status last_err = Status::ok;
  while (!g_stop) {
    TimePoint now = clock.now();
    const double t = double(now - t0) * 1e-9;
    if (duration > 0 && t >= duration) break;
    for (auto& s : schedule) {
      if (s.done || t < s.arg.at) continue;
      s.done = true;
      each(s.arg.node, [&](sim::VirtualDrive& d) {
        switch (s.kind) {
          case Scheduled::silent:
            d.faults().silent = true;
            std::printf("armsim fault t=%.3f node=%u kind=silent\n", t, unsigned(d.node()));
            break;
          case Scheduled::stop_hb:
            d.faults().heartbeat_stopped = true;
            std::printf("armsim fault t=%.3f node=%u kind=stop_heartbeat\n", t, unsigned(d.node()));
            break;
          case Scheduled::emcy:
            d.inject_emcy(s.code, now, bus);
            std::printf("armsim fault t=%.3f node=%u kind=emcy code=0x%04X\n", t, unsigned(d.node()), unsigned(s.code));
            break;
        }
      });
      std::fflush(stdout);
    }
    if (now >= next_tick) {
      arm.tick(now);
      for (auto& m : mit) m->tick(now, bus);
      next_tick += kMillisecond;
      if (next_tick <= now) next_tick = now + kMillisecond;
    }
    CanFrame f;
    const Status st = bus.receive(f, next_tick);
    if (st == Status::ok) {
      arm.handle(f, clock.now());
      for (auto& m : mit) m->handle(f, clock.now(), bus);
      last_err = Status::ok;
    } else if (st != Status::timeout) {
      if (have_fd && st == Status::interface_down) {
        std::printf("armsim peer closed fd\n");  // --fd: the other end is gone for good
        break;
      }
      if (st != last_err) std::fprintf(stderr, "armsim: receive: %s (%s); retrying\n", to_string(st), bus.message());
      last_err = st;
      clock.sleep_until(next_tick);  // no busy loop while the interface is down
    }
    for (std::size_t i = 0; i < arm.size(); ++i) {
      const auto& d = arm.at(i);
      const double m = d.home_mark();
      // Once the homing attained (statusword bit 12 in homing mode), once per new mark.
      std::uint32_t sw = 0;
      d.od_read(cia402::kStatusword, 0, sw);
      if (!std::isnan(m) && (sw & cia402::kSwHomingAttained) && d.mode_display() == cia402::kModeHoming &&
          !(m == last_mark[i])) {
        last_mark[i] = m;
        std::uint32_t method = 0, pos = 0;
        d.od_read(cia402::kHomingMethod, 0, method);
        d.od_read(cia402::kPositionActual, 0, pos);
        std::printf("armsim homed t=%.3f node=%u method=%d mark=%.0f physical=%.1f position=%d\n",
                    double(clock.now() - t0) * 1e-9, unsigned(d.node()), int(std::int8_t(method)), m,
                    d.physical_position(), int(std::int32_t(pos)));
        std::fflush(stdout);
      }
    }
    if (verbose) {
      for (std::size_t i = 0; i < arm.size(); ++i) {
        const auto& d = arm.at(i);
        if (d.state() != last_state[i] || d.nmt() != last_nmt[i]) {
          std::printf("armsim state t=%.3f node=%u nmt=%s cia402=%s\n", double(clock.now() - t0) * 1e-9,
                      unsigned(d.node()), canopen::to_string(d.nmt()), cia402::to_string(d.state()));
          last_state[i] = d.state();
          last_nmt[i] = d.nmt();
        }
      }
    }
    if (next_status && clock.now() >= next_status) {
      next_status += TimePoint(status_every * 1e9);
      for (std::size_t i = 0; i < arm.size(); ++i) {
        const auto& d = arm.at(i);
        std::printf("armsim status t=%.3f node=%u nmt=%s cia402=%s position=%.0f target=%d syncs=%llu",
                    double(clock.now() - t0) * 1e-9, unsigned(d.node()), canopen::to_string(d.nmt()),
                    cia402::to_string(d.state()), d.position(), int(d.target()),
                    static_cast<unsigned long long>(d.syncs_seen()));
        if (d.on_plant()) std::printf(" torque=%.3f", d.torque());
        std::printf("\n");
      }
      for (const auto& m : mit)
        std::printf("armsim mit t=%.3f id=0x%02X enabled=%d error=0x%X mode=%u timeout=%u position=%.4f torque=%.3f "
                    "frames=%llu\n",
                    double(clock.now() - t0) * 1e-9, unsigned(m->reg(hal::mit::Reg::esc_id)), int(m->enabled()),
                    unsigned(m->error()), unsigned(m->reg(hal::mit::Reg::ctrl_mode)),
                    unsigned(m->reg(hal::mit::Reg::timeout)), m->position(), m->torque(),
                    static_cast<unsigned long long>(m->mit_frames()));
      std::fflush(stdout);
    }
  }
  const BusStats s = bus.stats();
  std::printf("armsim exit tx=%llu rx=%llu tx_errors=%llu error_frames=%llu overruns=%llu\n",
              static_cast<unsigned long long>(s.tx_frames), static_cast<unsigned long long>(s.rx_frames),
              static_cast<unsigned long long>(s.tx_errors), static_cast<unsigned long long>(s.error_frames),
              static_cast<unsigned long long>(s.rx_overruns));
  return 0;
}
