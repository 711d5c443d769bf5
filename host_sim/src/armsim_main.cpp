// armsim: virtual CiA 402 servo drives on a SocketCAN interface (e.g. vcan0).
#include <algorithm>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "servoarm/hal/clock.hpp"
#include "servoarm/hal/socketcan_bus.hpp"
#include "servoarm/sim/cli.hpp"
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
    "  --nodes LIST            node ids: 1-6, 1,3,5 or 2-4,7 (default 1-6)\n"
    "  --duration SEC          exit after SEC seconds (default: until SIGINT/SIGTERM)\n"
    "  --heartbeat-ms N        heartbeat producer time before the master sets 0x1017 (default 0 = off)\n"
    "  --lag-ms X              position-loop time constant (default 2)\n"
    "  --counts-per-rev N      encoder counts per motor revolution, for --vmax/--amax (default 131072)\n"
    "  --vmax REV_PER_S        velocity limit in motor revolutions/s (default 10)\n"
    "  --amax REV_PER_S2       acceleration limit (default 400)\n"
    "  --window COUNTS         following error window 0x6065 (default 13107)\n"
    "  --seed N                random seed for noise and drops (default 1)\n"
    "  --status-every SEC      print one status line per node every SEC seconds\n"
    "  --verbose               print NMT/CiA 402 state changes\n"
    "\n"
    "Fault injection (NODE is a node id or 'all'; @SEC = seconds after start, default 0):\n"
    "  --silent NODE[@SEC]          node stops sending and ignores the bus (unplugged)\n"
    "  --stop-heartbeat NODE[@SEC]  only the heartbeat producer stops\n"
    "  --emcy NODE:CODE[@SEC]       EMCY with CODE (e.g. 0x2310) and the drive faults\n"
    "  --refuse-enable NODE         the drive stays in switched_on when told to enable\n"
    "  --noise NODE:COUNTS          uniform +-COUNTS noise on the reported position\n"
    "  --drop-rate NODE:P           each frame the node sends is lost with probability P\n"
    "\n"
    "Output: 'armsim ready iface=... nodes=...' once the socket is open, then event lines.\n"
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
  bool verbose = false;
  std::vector<Scheduled> schedule;
  std::vector<cli::FaultArg> refuse, noise, drops;

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
    } else if (!value(v)) {
      return usage_error("unknown option or missing value: " + a);
    } else if (a == "--iface") {
      iface = v;
    } else if (a == "--fd") {
      if (!cli::parse_uint(v, 1 << 20, fd)) return usage_error("bad --fd");
      have_fd = true;
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
    if (const Status st = bus_ptr->open(iface.c_str()); st != Status::ok) {
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
  sim::ArmSim arm(bus, nodes, motor, seed);
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

  MonotonicClock clock;
  const TimePoint t0 = clock.now();
  arm.power_on(t0);
  if (hb_ms > 0) {
    for (std::size_t i = 0; i < arm.size(); ++i) arm.at(i).od_write(0x1017, 0, hb_ms);
  }
  std::printf("armsim ready iface=%s nodes=", iface.c_str());
  for (std::size_t i = 0; i < nodes.size(); ++i) std::printf("%s%u", i ? "," : "", unsigned(nodes[i]));
  std::printf("\n");
  std::fflush(stdout);

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
      next_tick += kMillisecond;
      if (next_tick <= now) next_tick = now + kMillisecond;
    }
    CanFrame f;
    const Status st = bus.receive(f, next_tick);
    if (st == Status::ok) {
      arm.handle(f, clock.now());
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
        std::printf("armsim status t=%.3f node=%u nmt=%s cia402=%s position=%.0f target=%d syncs=%llu\n",
                    double(clock.now() - t0) * 1e-9, unsigned(d.node()), canopen::to_string(d.nmt()),
                    cia402::to_string(d.state()), d.position(), int(d.target()),
                    static_cast<unsigned long long>(d.syncs_seen()));
      }
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
