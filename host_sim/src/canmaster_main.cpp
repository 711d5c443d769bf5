// SPDX-License-Identifier: Apache-2.0
// canmaster: CANopen CiA 402 master for shell scenarios (bring-up, streaming, fault checks).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include "servoarm/hal/canopen_master.hpp"
#include "servoarm/hal/clock.hpp"
#include "servoarm/hal/sim_bus.hpp"
#include "servoarm/hal/socketcan_bus.hpp"
#include "servoarm/sim/cli.hpp"
#include "servoarm/sim/virtual_drive.hpp"

using namespace servoarm;
using namespace servoarm::hal;

namespace {

const char* kUsage =
    "usage: canmaster (--iface NAME | --sim | --fd N) [--nodes LIST] --bringup [--roundtrip N] [--stream-sine SEC]\n"
    "                 [--hold SEC] [options]\n"
    "\n"
    "CANopen master for CiA 402 drives (the servoarm hal::CanopenServoBus) for shell scenarios.\n"
    "--bringup configures every node over SDO (heartbeat 0x1017, mode 0x6060 = 8 CSP, RPDO1\n"
    "0x6040+0x607A, TPDO1 0x6041+0x6064, TPDO2 0x606C+0x603F, SYNC-triggered), starts them\n"
    "(NMT) and enables them (CiA 402). Then it runs a fixed-period cycle: read feedback,\n"
    "write RPDOs + SYNC.\n"
    "\n"
    "  --iface NAME            SocketCAN interface, e.g. vcan0\n"
    "  --fd N                  testing: use inherited fd N (CAN_RAW socket or SOCK_SEQPACKET socketpair\n"
    "                          end carrying struct can_frame records) instead of --iface\n"
    "  --sim                   in-process virtual drives on the sim bus, simulated time (no kernel CAN)\n"
    "  --nodes LIST            node ids: 1-6, 1,3,5, 2-4,7 (default 1-6; at most 8)\n"
    "  --bringup               SDO configuration + NMT start + enable (required for the phases below)\n"
    "  --roundtrip N           first phase: N round trips, each RPDOs + SYNC sent -> every node's TPDO1 and\n"
    "                          TPDO2 back (positions held); one round per --period-ms; prints the latency\n"
    "                          (send to the last TPDO1 back) and fails when a round is lost or a frame is bad\n"
    "  --roundtrip-timeout-ms N  a round not complete after N ms is lost (default 500)\n"
    "  --stream-sine SEC       stream a sine around each joint's start position for SEC seconds\n"
    "  --amplitude RAD         sine amplitude (default 0.3)\n"
    "  --freq HZ               sine frequency (default 0.5)\n"
    "  --tolerance RAD         max tracking error allowed while streaming (default 0.02)\n"
    "  --hold SEC              hold position for SEC seconds (after the sine), watching for faults\n"
    "  --period-ms X           cycle = SYNC period (default 2)\n"
    "  --hb-ms N               heartbeat producer time written to each node (default 50)\n"
    "  --hb-timeout-ms N       heartbeat consumer timeout per node (default 150)\n"
    "  --sdo-timeout-ms N      SDO answer timeout (default 200)\n"
    "  --enable-timeout-ms N   max time a drive may stay in one CiA 402 state while enabling (default 1000)\n"
    "  --counts-per-rev N      encoder counts per revolution, gear 1 (default 131072)\n"
    "  --expect-hb-loss NODE   success means: NODE's heartbeat loss is reported within\n"
    "                          hb-timeout + one period of its last heartbeat, and no other joint faults\n"
    "  --sim-silent NODE@SEC   (--sim) the virtual node goes silent SEC seconds into the phases\n"
    "  --sim-emcy NODE:CODE@SEC (--sim) the virtual node raises EMCY CODE and faults\n"
    "  --recover               after a bus outage (interface down then reopened, or bus-off then restarted),\n"
    "                          once every node's heartbeat is back: enable() again (clears the outage's\n"
    "                          heartbeat_lost / bus_off faults) and blend the sine in again from where each\n"
    "                          joint stands (smoothstep over 1.5 s)\n"
    "  --expect-outage         success means: the interface went down at least once and was reopened, every\n"
    "                          fault came during an outage (heartbeat_lost / bus_off) and, with --recover,\n"
    "                          every joint was enabled again and followed the sine within --tolerance\n"
    "                          (without it, an outage fails the run)\n"
    "  --tpdo2 LIST            what TPDO2 carries: velocity, error_code, torque, each optional (left out\n"
    "                          when the drive lacks it) or NAME:required (bring-up fails naming it);\n"
    "                          'none' = no TPDO2 (default velocity,error_code)\n"
    "  --no-filters            receive every frame (default: kernel filters pass only frames whose\n"
    "                          node part, id & 0x7F, is one of --nodes)\n"
    "  --home NODE:METHOD      after bring-up, home NODE with its drive's CiA 402 homing METHOD (6098h), or\n"
    "                          NODE:hard_stop[:DIR] (push against the end stop, DIR + or -, default -); repeat\n"
    "                          for more nodes, all home together. Then the phases below, from the homed positions\n"
    "  --home-speeds SW,ZERO   homing speeds in motor rev/s: search for switch, for zero (default 1,0.1)\n"
    "  --home-accel REV_S2     homing acceleration (default 20)\n"
    "  --home-offset COUNTS    the position (counts) at the home mark, 607Ch (default 0)\n"
    "  --home-timeout SEC      per joint (default 30)\n"
    "  --quiet                 only the final result line\n"
    "\n"
    "Output (stdout, one record per line, key=value):\n"
    "  bringup status=ok|<status> elapsed_ms=.. [error=\"..\"]\n"
    "  node id=N name=\"..\" state=enabled\n"
    "  fault t=SEC node=N reason=heartbeat_lost|drive_fault|drive_refused|protocol_error|bus_off\n"
    "        since_last_hb_ms=.. limit_ms=.. cycle_late_ms=.. error_code=0x.... detail=\"..\"\n"
    "        (--expect-hb-loss passes when since_last_hb_ms <= limit_ms + cycle_late_ms: the\n"
    "        bound hb-timeout + one period assumes the detecting cycle started on time)\n"
    "  bus t=SEC event=interface_down|reopened downs=.. reopens=.. [outage_ms=..] detail=\"..\"   (--iface)\n"
    "  bus t=SEC event=bus_off|restarted error_frames=..   (controller error frames CAN_ERR_BUSOFF / _RESTARTED)\n"
    "  recover t=SEC joints=N                  (--recover: enable() called again after an outage)\n"
    "  roundtrip rounds=N complete=.. lost=.. bad_frames=.. min_us=.. median_us=.. p99_us=.. max_us=..\n"
    "            all_tpdo_median_us=.. all_tpdo_p99_us=.. timestamps=kernel_ns|kernel_us|receive detail=\"..\"\n"
    "  homed node=N kind=cia402|hard_stop method=M status=ok|<status> time_s=.. position_counts=.. detail=\"..\"\n"
    "  homing status=ok|fail elapsed_s=..        (--home)\n"
    "  joint node=N max_err_rad=.. state=.. age_ms=..\n"
    "  result status=ok|fail cycles=.. late_cycles=.. max_err_rad=.. ignored_frames=.. tx_errors=.. reopens=..\n"
    "         reason=\"..\"\n"
    "Exit status: 0 success, 1 scenario failed, 2 usage error, 3 cannot open the interface,\n"
    "4 bring-up failed.\n";

int usage_error(const std::string& msg) {
  std::fprintf(stderr, "canmaster: %s\n(see canmaster --help)\n", msg.c_str());
  return 2;
}

struct Options {
  std::string iface;
  int fd = -1;
  bool sim = false;
  std::vector<std::uint8_t> nodes = {1, 2, 3, 4, 5, 6};
  bool bringup = false;
  double stream = 0, hold = 0, amplitude = 0.3, freq = 0.5, tolerance = 0.02, period_ms = 2;
  std::uint32_t hb_ms = 50, hb_timeout_ms = 150, sdo_timeout_ms = 200, enable_timeout_ms = 1000, cpr = 131072;
  std::uint32_t expect_hb_loss = 0;
  std::vector<sim::cli::FaultArg> sim_silent, sim_emcy;
  bool quiet = false;
  bool filters = true;
  std::uint32_t roundtrip = 0, roundtrip_timeout_ms = 500;
  bool recover = false, expect_outage = false;
  FeedbackObjects tpdo2{};
  struct Home {
    std::uint8_t node = 0;
    HomingKind kind = HomingKind::cia402;
    int method = 0;
    int dir = -1;
  };
  std::vector<Home> home;
  double home_sw = 1.0, home_zero = 0.1, home_accel = 20, home_offset = 0, home_timeout = 30;
};

// "velocity,error_code", "velocity:required,torque", "none": what TPDO2 carries.
bool parse_tpdo2(const std::string& v, FeedbackObjects& out) {
  FeedbackObjects f;
  f.velocity = f.error_code = f.torque = PdoUse::off;
  if (v == "none") {
    out = f;
    return true;
  }
  std::size_t p = 0;
  while (p <= v.size()) {
    const std::size_t q = std::min(v.find(',', p), v.size());
    std::string item = v.substr(p, q - p);
    PdoUse use = PdoUse::optional;
    const std::size_t colon = item.find(':');
    if (colon != std::string::npos) {
      const std::string u = item.substr(colon + 1);
      if (u == "required") use = PdoUse::required;
      else if (u != "optional") return false;
      item.resize(colon);
    }
    if (item == "velocity") f.velocity = use;
    else if (item == "error_code") f.error_code = use;
    else if (item == "torque") f.torque = use;
    else return false;
    p = q + 1;
  }
  out = f;
  return true;
}

struct SimParts {
  std::unique_ptr<SimBus> bus;
  std::unique_ptr<SimBusEndpoint> master_ep, sim_ep;
  std::unique_ptr<sim::ArmSim> arm;
};

double percentile(const std::vector<double>& sorted, double q) {
  if (sorted.empty()) return 0;
  std::size_t k = std::size_t(std::ceil(q * double(sorted.size())));
  if (k > 0) --k;
  return sorted[std::min(k, sorted.size() - 1)];
}

// --roundtrip N: the measure of BM_HalRoundTrip6_SimBus_TwoThreads on a real bus. Each
// round: write() (RPDOs + SYNC), then receive until every node's TPDO1 and TPDO2 of that
// SYNC are back. Latency = from just before write() to the return of the receive that
// delivered the last TPDO1 (and, second figure, the last of all 2n TPDOs). A TPDO that
// does not decode, comes twice in a round, says "not operation enabled" or reports a
// position off the held target by more than --tolerance is a bad frame.
// Returns true when every round completed with no bad frame.
bool roundtrip_phase(CanopenServoBus& master, CanBus& bus, Clock& clock, const Options& o, const char* ts_source) {
  const std::size_t n = o.nodes.size();
  std::vector<double> hold(n);
  for (std::size_t j = 0; j < n; ++j) hold[j] = master.feedback(j).position;
  std::vector<double> rt1, rt_all;
  rt1.reserve(o.roundtrip);
  rt_all.reserve(o.roundtrip);
  std::array<int, 128> slot{};
  slot.fill(-1);
  for (std::size_t j = 0; j < n; ++j) slot[o.nodes[j]] = int(j);
  const Duration period = Duration(o.period_ms * 1e6);
  const Duration timeout = Duration(o.roundtrip_timeout_ms) * kMillisecond;
  const double tol_counts = o.tolerance * double(o.cpr) / (2 * std::numbers::pi) + 1;
  std::uint64_t lost = 0, bad = 0;
  std::string first_bad;
  auto note_bad = [&](const char* what, const CanFrame& f, std::uint32_t round) {
    ++bad;
    if (first_bad.empty()) {
      char b[160];
      std::snprintf(b, sizeof b, "round %u: %s (id 0x%03X len %u)", unsigned(round), what, unsigned(f.id), unsigned(f.len));
      first_bad = b;
    }
  };
  // TPDO2 expected from the nodes that have one; decoded when it is the default layout.
  std::size_t n2 = 0;
  std::array<bool, kMaxServoJoints> std_tpdo2{};
  for (std::size_t j = 0; j < n; ++j) {
    const bool v = master.maps(j, cia402::kVelocityActual), e = master.maps(j, cia402::kErrorCode),
               t = master.maps(j, cia402::kTorqueActual);
    if (v || e || t) ++n2;
    std_tpdo2[j] = v && e && !t;
  }
  TimePoint next = clock.now();
  for (std::uint32_t r = 0; r < o.roundtrip; ++r) {
    std::array<std::uint8_t, kMaxServoJoints> got1{}, got2{};
    std::size_t c1 = 0, c2 = 0;
    const TimePoint t_send = clock.now();
    master.write(hold, t_send);
    const TimePoint deadline = t_send + timeout;
    TimePoint t1 = 0;
    CanFrame f;
    while (c1 < n || c2 < n2) {
      const Status st = bus.receive(f, deadline);
      if (st != Status::ok) break;
      const TimePoint at = clock.now();
      master.dispatch(f, f.rx_time != 0 ? f.rx_time : at);
      if (f.error || f.extended) continue;
      const std::uint32_t fn = canopen::function_of(f.id);
      const int j = slot[canopen::node_of(f.id)];
      if (j < 0 || (fn != canopen::kTpdo1 && fn != canopen::kTpdo2)) continue;
      if (fn == canopen::kTpdo1) {
        std::uint16_t sw = 0;
        std::int32_t pos = 0;
        if (!pdo::decode_tpdo1(f, sw, pos)) note_bad("TPDO1 does not decode", f, r);
        else if (got1[std::size_t(j)]) note_bad("second TPDO1 in one round", f, r);
        else if (cia402::decode_statusword(sw) != cia402::State::operation_enabled)
          note_bad("TPDO1 statusword is not operation enabled", f, r);
        else if (std::fabs(double(pos - master.last_target_counts(std::size_t(j)))) > tol_counts)
          note_bad("TPDO1 position off the held target", f, r);
        if (!got1[std::size_t(j)]) {
          got1[std::size_t(j)] = 1;
          if (++c1 == n) t1 = at;
        }
      } else {
        std::int32_t vel = 0;
        std::uint16_t ec = 0;
        if (!std_tpdo2[std::size_t(j)]) {
          // another layout (--tpdo2): counted, not decoded here
        } else if (!pdo::decode_tpdo2(f, vel, ec)) note_bad("TPDO2 does not decode", f, r);
        else if (got2[std::size_t(j)]) note_bad("second TPDO2 in one round", f, r);
        else if (ec != 0) note_bad("TPDO2 carries an error code", f, r);
        if (!got2[std::size_t(j)]) {
          got2[std::size_t(j)] = 1;
          ++c2;
        }
      }
      if (c1 == n && c2 == n2) rt_all.push_back(double(at - t_send) * 1e-3);
    }
    if (c1 == n) rt1.push_back(double(t1 - t_send) * 1e-3);
    if (c1 < n || c2 < n2) {
      ++lost;
      if (first_bad.empty() && lost == 1) {
        char b[160];
        std::snprintf(b, sizeof b, "round %u lost: %zu of %zu TPDO1, %zu of %zu TPDO2 within %u ms", unsigned(r), c1, n,
                      c2, n2, unsigned(o.roundtrip_timeout_ms));
        first_bad = b;
      }
    }
    master.read(clock.now());  // heartbeats, faults
    next += period;
    const TimePoint now = clock.now();
    if (next < now) next = now;
    clock.sleep_until(next);
  }
  std::sort(rt1.begin(), rt1.end());
  std::sort(rt_all.begin(), rt_all.end());
  std::printf("roundtrip rounds=%u complete=%zu lost=%llu bad_frames=%llu min_us=%.1f median_us=%.1f p99_us=%.1f "
              "max_us=%.1f all_tpdo_median_us=%.1f all_tpdo_p99_us=%.1f timestamps=%s detail=\"%s\"\n",
              unsigned(o.roundtrip), rt_all.size(), static_cast<unsigned long long>(lost),
              static_cast<unsigned long long>(bad), rt1.empty() ? 0.0 : rt1.front(), percentile(rt1, 0.5),
              percentile(rt1, 0.99), rt1.empty() ? 0.0 : rt1.back(), percentile(rt_all, 0.5), percentile(rt_all, 0.99),
              ts_source, first_bad.c_str());
  std::fflush(stdout);
  return lost == 0 && bad == 0 && rt_all.size() == o.roundtrip;
}

int run(CanBus& bus, Clock& clock, const Options& o, sim::ArmSim* arm, SocketCanBus* scb = nullptr) {
  CanopenMasterConfig cfg;
  cfg.joint_count = o.nodes.size();
  JointScaling sc;
  sc.counts_per_unit = double(o.cpr);
  for (std::size_t j = 0; j < o.nodes.size(); ++j) {
    cfg.joints[j].node_id = o.nodes[j];
    cfg.joints[j].scaling = sc;
  }
  const Duration period = Duration(o.period_ms * 1e6);
  cfg.heartbeat_period = Duration(o.hb_ms) * kMillisecond;
  cfg.heartbeat_timeout = Duration(o.hb_timeout_ms) * kMillisecond;
  cfg.sdo_timeout = Duration(o.sdo_timeout_ms) * kMillisecond;
  cfg.state_timeout = Duration(o.enable_timeout_ms) * kMillisecond;
  cfg.set_bus_filters = o.filters;
  cfg.tpdo2 = o.tpdo2;
  const double rev = 2 * std::numbers::pi;  // rad per motor revolution (gear 1)
  for (const auto& h : o.home) {
    const std::size_t j = std::size_t(std::find(o.nodes.begin(), o.nodes.end(), h.node) - o.nodes.begin());
    HomingSpec& hs = cfg.joints[j].homing;
    hs.kind = h.kind;
    hs.method = std::int8_t(h.method);
    hs.speed_switch = o.home_sw * rev * (h.kind == HomingKind::hard_stop ? double(h.dir) : 1.0);
    hs.speed_zero = o.home_zero * rev;
    hs.acceleration = o.home_accel * rev;
    hs.offset = o.home_offset / sc.counts_per_si();
    hs.timeout = Duration(o.home_timeout * 1e9);
    hs.following_limit = 0.01;
    hs.backoff = 0.05;
  }
  CanopenServoBus master(bus, clock, cfg);
  if (master.config_status() != Status::ok) {
    std::fprintf(stderr, "canmaster: %s\n", master.last_error());
    return 2;
  }
  const std::size_t n = o.nodes.size();
  const TimePoint tb = clock.now();
  Status st = master.start(tb + 10 * kSecond);
  if (st == Status::ok) st = master.enable_blocking(clock.now() + 5 * kSecond, period);
  const double bring_ms = double(clock.now() - tb) * 1e-6;
  if (st != Status::ok) {
    std::printf("bringup status=%s elapsed_ms=%.1f error=\"%s\"\n", to_string(st), bring_ms, master.last_error());
    std::printf("result status=fail cycles=0 late_cycles=0 max_err_rad=0 reason=\"bring-up failed\"\n");
    return 4;
  }
  if (!o.quiet) {
    std::printf("bringup status=ok elapsed_ms=%.1f\n", bring_ms);
    for (std::size_t j = 0; j < n; ++j)
      std::printf("node id=%u name=\"%s\" state=%s tpdo2=%s%s%s%s\n", unsigned(o.nodes[j]), master.device_name(j),
                  to_string(master.feedback(j).state), master.maps(j, cia402::kVelocityActual) ? "+606C" : "",
                  master.maps(j, cia402::kErrorCode) ? "+603F" : "", master.maps(j, cia402::kTorqueActual) ? "+6077" : "",
                  master.maps(j, cia402::kVelocityActual) || master.maps(j, cia402::kErrorCode) ||
                          master.maps(j, cia402::kTorqueActual)
                      ? ""
                      : "none");
    std::fflush(stdout);
  }
  bool roundtrip_ok = true;
  if (o.roundtrip > 0)
    roundtrip_ok = roundtrip_phase(master, bus, clock, o, scb ? to_string(scb->rx_timestamps()) : arm ? "simulated" : "receive");

  // --home: every configured joint homes at once; the others hold.
  if (!o.home.empty()) {
    const TimePoint th = clock.now();
    std::vector<TimePoint> done_at(n, 0);
    std::vector<double> hold(n);
    for (std::size_t j = 0; j < n; ++j) {
      if (cfg.joints[j].homing.kind == HomingKind::none) continue;
      if (const Status hs = master.start_homing(j, th); hs != Status::ok) {
        std::printf("homed node=%u status=%s detail=\"start_homing refused\"\n", unsigned(o.nodes[j]), to_string(hs));
        std::printf("result status=fail cycles=0 late_cycles=0 max_err_rad=0 reason=\"homing refused\"\n");
        return 1;
      }
    }
    TimePoint nx = th;
    bool all = false;
    while (!all && clock.now() - th < Duration((o.home_timeout + 10) * 1e9)) {
      const TimePoint now = clock.now();
      master.read(now);
      all = true;
      for (std::size_t j = 0; j < n; ++j) {
        hold[j] = master.feedback(j).position;
        if (master.homing(j).phase == HomingPhase::running) all = false;
        else if (done_at[j] == 0) done_at[j] = now;
      }
      master.write(std::span<const double>(hold.data(), n), now);
      nx += period;
      if (nx < clock.now()) nx = clock.now();
      clock.sleep_until(nx);
    }
    // A few cycles more: the positions settle, the feedback is fresh.
    for (int k = 0; k < 20; ++k) {
      const TimePoint now = clock.now();
      master.read(now);
      for (std::size_t j = 0; j < n; ++j) hold[j] = master.feedback(j).position;
      master.write(std::span<const double>(hold.data(), n), now);
      nx += period;
      if (nx < clock.now()) nx = clock.now();
      clock.sleep_until(nx);
    }
    bool ok = true;
    for (std::size_t j = 0; j < n; ++j) {
      const HomingSpec& hs = cfg.joints[j].homing;
      if (hs.kind == HomingKind::none) continue;
      const HomingProgress p = master.homing(j);
      char detail[160];
      master.describe_homing(j, detail, sizeof detail);
      std::int32_t counts = 0;
      master.scaling(j).to_counts(master.feedback(j).position, counts);
      ok = ok && p.phase == HomingPhase::attained;
      std::printf("homed node=%u kind=%s method=%d status=%s time_s=%.3f position_counts=%d detail=\"%s\"\n",
                  unsigned(o.nodes[j]), to_string(hs.kind), int(hs.method),
                  p.phase == HomingPhase::attained ? "ok" : to_string(p.status),
                  double((done_at[j] ? done_at[j] : clock.now()) - th) * 1e-9, int(counts), detail);
    }
    std::printf("homing status=%s elapsed_s=%.3f\n", ok ? "ok" : "fail", double(clock.now() - th) * 1e-9);
    std::fflush(stdout);
    if (!ok) {
      std::printf("result status=fail cycles=0 late_cycles=0 max_err_rad=0 reason=\"homing failed\"\n");
      return 1;
    }
    if (o.stream == 0 && o.hold == 0 && o.roundtrip == 0) {
      std::printf("result status=ok cycles=0 late_cycles=0 max_err_rad=0 ignored_frames=%llu tx_errors=0 reopens=0 reason=\"\"\n",
                  static_cast<unsigned long long>(master.ignored_frames()));
      return 0;
    }
  }

  // Cyclic phases.
  std::vector<double> p0(n), sp(n), max_err(n, 0.0);
  for (std::size_t j = 0; j < n; ++j) p0[j] = sp[j] = master.feedback(j).position;  // --hold alone holds here
  constexpr int kHist = 16;
  std::vector<std::array<double, kHist>> hist(n);
  for (std::size_t j = 0; j < n; ++j) hist[j].fill(p0[j]);
  std::vector<bool> reported(n, false);
  bool hb_loss_ok = false, other_fault = false, expected_seen = false;
  std::string reason;
  const TimePoint t0 = clock.now();
  const Duration total = Duration((o.stream + o.hold) * 1e9);
  std::uint64_t cycles = 0, late = 0;
  TimePoint next = t0;
  std::vector<bool> silent_done(o.sim_silent.size(), false), emcy_done(o.sim_emcy.size(), false);
  const double limit_ms = double(o.hb_timeout_ms) + o.period_ms;
  // Interface outages (--iface): reported as they happen; with --recover the joints are
  // enabled again once every heartbeat is back, and the sine blended in from where each
  // joint stands. The tracking error is not measured from the interface-down until the
  // joint follows again (kHist + 1 cycles after its re-enable, or 0.5 s after a reopen
  // that needed none).
  bool was_down = false, was_bus_off = false, bus_was_bad = false;
  bool outage_seen = false, reopened = false, in_outage = false, recovering = false;
  TimePoint down_at = 0, up_at = 0;
  std::uint64_t recoveries = 0, outage_faults = 0;
  std::vector<double> blend_from(n, 0.0);
  std::vector<double> blend_t0(n, -1.0);                  // s; < 0: no blend
  std::vector<std::uint64_t> measure_from(n, 21);         // first cycle whose error counts
  std::vector<bool> await_enable(n, false);
  for (;;) {
    const TimePoint now = clock.now();
    const double t = double(now - t0) * 1e-9;
    if (now - t0 >= total) break;
    if (arm) {
      for (std::size_t i = 0; i < o.sim_silent.size(); ++i)
        if (!silent_done[i] && t >= o.sim_silent[i].at) {
          silent_done[i] = true;
          for (std::size_t k = 0; k < arm->size(); ++k)
            if (o.sim_silent[i].node == 0 || arm->at(k).node() == o.sim_silent[i].node) arm->at(k).faults().silent = true;
        }
      for (std::size_t i = 0; i < o.sim_emcy.size(); ++i)
        if (!emcy_done[i] && t >= o.sim_emcy[i].at) {
          emcy_done[i] = true;
          std::uint32_t code = 0;
          sim::cli::parse_uint(o.sim_emcy[i].value, 0xFFFF, code);
          if (auto* d = arm->node(o.sim_emcy[i].node)) d->inject_emcy(std::uint16_t(code), now, arm->bus());
        }
    }
    master.read(now);
    // Bus events (after read(): it is the receive that sees them), before the faults they cause.
    if (scb && scb->is_down() != was_down) {
      was_down = scb->is_down();
      const BusStats bs = scb->stats();
      std::printf("bus t=%.3f event=%s downs=%llu reopens=%llu", t, was_down ? "interface_down" : "reopened",
                  static_cast<unsigned long long>(scb->interface_downs()), static_cast<unsigned long long>(bs.reopens));
      if (!was_down) std::printf(" outage_ms=%.1f", double(now - down_at) * 1e-6);
      std::printf(" detail=\"%s\"\n", was_down ? scb->down_reason() : "");
      if (was_down) down_at = now;
      else reopened = true;
      std::fflush(stdout);
    }
    const bool bus_off = bus.stats().state == ErrorState::bus_off;
    if (bus_off != was_bus_off) {
      was_bus_off = bus_off;
      std::printf("bus t=%.3f event=%s error_frames=%llu\n", t, bus_off ? "bus_off" : "restarted",
                  static_cast<unsigned long long>(bus.stats().error_frames));
      if (bus_off) down_at = now;
      std::fflush(stdout);
    }
    const bool bus_bad = was_down || bus_off;
    if (bus_bad && !bus_was_bad) outage_seen = in_outage = true;
    if (!bus_bad && bus_was_bad) up_at = now;
    bus_was_bad = bus_bad;
    for (std::size_t j = 0; j < n; ++j) {
      const JointFeedback& fb = master.feedback(j);
      if (fb.state == JointState::fault && !reported[j]) {
        reported[j] = true;
        const double since_hb = double(fb.fault_since - fb.last_heartbeat) * 1e-6;
        char detail[160];
        master.describe_fault(j, detail, sizeof detail);
        // How late this cycle started against its schedule (OS scheduling, not the master):
        // the "timeout + one period" bound assumes cycles start on time.
        const double cycle_late_ms = std::max(0.0, double(now - next) * 1e-6);
        std::printf("fault t=%.3f node=%u reason=%s since_last_hb_ms=%.3f limit_ms=%.3f cycle_late_ms=%.3f "
                    "error_code=0x%04X detail=\"%s\"\n",
                    double(fb.fault_since - t0) * 1e-9, unsigned(o.nodes[j]), to_string(fb.fault), since_hb, limit_ms,
                    cycle_late_ms, unsigned(fb.error_code), detail);
        std::fflush(stdout);
        if (in_outage && (fb.fault == Status::heartbeat_lost || fb.fault == Status::bus_off)) {
          ++outage_faults;  // the outage's doing: judged by --expect-outage / --recover below
        } else if (o.expect_hb_loss == o.nodes[j] && fb.fault == Status::heartbeat_lost) {
          expected_seen = true;
          hb_loss_ok = since_hb <= limit_ms + cycle_late_ms + 1e-6;
          if (!hb_loss_ok) reason = "heartbeat loss reported too late";
        } else {
          other_fault = true;
          if (reason.empty()) reason = std::string("unexpected fault on node ") + std::to_string(o.nodes[j]);
        }
      }
      if (await_enable[j] && fb.state == JointState::enabled) {
        await_enable[j] = false;
        blend_from[j] = fb.position;
        blend_t0[j] = t;
        measure_from[j] = cycles + kHist + 1;
      }
      // Tracking error against the best-matching recent setpoint (transport delay 1..kHist cycles).
      if (fb.state == JointState::enabled && cycles >= measure_from[j] && !in_outage && t < o.stream) {
        double best = 1e9;
        for (int l = 1; l < kHist; ++l) best = std::min(best, std::fabs(fb.position - hist[j][(cycles - l) % kHist]));
        max_err[j] = std::max(max_err[j], best);
      }
    }
    // End of an outage: the bus is back and every node's heartbeat came after the reopen.
    if (in_outage && !bus_was_bad) {
      bool all_hb = true, any_fault = false;
      for (std::size_t j = 0; j < n; ++j) {
        all_hb = all_hb && master.feedback(j).last_heartbeat > up_at;
        any_fault = any_fault || master.feedback(j).state == JointState::fault;
      }
      if (all_hb && any_fault && o.recover && !recovering) {
        master.enable();  // clears the latched faults (fault reset where needed), enables again
        recovering = true;
        ++recoveries;
        for (std::size_t j = 0; j < n; ++j) {
          reported[j] = false;
          await_enable[j] = true;
        }
        std::printf("recover t=%.3f joints=%zu\n", t, n);
        std::fflush(stdout);
      }
      if (all_hb && !any_fault) {  // recovered (or never faulted): measure again after 0.5 s
        in_outage = recovering = false;
        for (std::size_t j = 0; j < n; ++j)
          if (!await_enable[j]) measure_from[j] = std::max(measure_from[j], cycles + std::uint64_t(0.5e3 / o.period_ms));
      }
    }
    const double ramp = std::min(1.0, t / 0.5);
    for (std::size_t j = 0; j < n; ++j) {
      if (t < o.stream) {
        sp[j] = p0[j] + ramp * o.amplitude * std::sin(2 * std::numbers::pi * o.freq * t + 0.5 * double(j));
        if (blend_t0[j] >= 0) {  // after a re-enable: from where the joint stood to the sine in 1.5 s
          const double r = std::min(1.0, (t - blend_t0[j]) / 1.5);
          const double w = r * r * (3 - 2 * r);  // smoothstep: no velocity step at either end
          sp[j] = (1 - w) * blend_from[j] + w * sp[j];
          if (r >= 1) blend_t0[j] = -1;
        }
      }
      hist[j][cycles % kHist] = sp[j];
    }
    master.write(sp, now);
    ++cycles;
    next += period;
    const TimePoint after = clock.now();
    if (after > next + period) {
      ++late;
      next = after;
    }
    clock.sleep_until(next);
  }
  // Power down.
  master.disable();
  for (int k = 0; k < 200; ++k) {
    const TimePoint now = clock.now();
    master.read(now);
    master.write(sp, now);
    bool all = true;
    for (std::size_t j = 0; j < n; ++j) all = all && master.feedback(j).state != JointState::enabling && master.feedback(j).state != JointState::stopping;
    if (all) break;
    clock.sleep_until(now + period);
  }
  double worst = 0;
  for (std::size_t j = 0; j < n; ++j) {
    const JointFeedback& fb = master.feedback(j);
    worst = std::max(worst, max_err[j]);
    if (!o.quiet)
      std::printf("joint node=%u max_err_rad=%.6f state=%s age_ms=%.1f\n", unsigned(o.nodes[j]), max_err[j],
                  to_string(fb.state), fb.age >= 0 ? double(fb.age) * 1e-6 : -1.0);
  }
  bool ok = roundtrip_ok;
  if (!roundtrip_ok) reason = "round trip lost or bad frame (see the roundtrip line)";
  if (o.expect_outage) {
    if (!outage_seen) {
      ok = false;
      if (reason.empty()) reason = "no interface outage seen";
    } else if (!reopened) {
      ok = false;
      if (reason.empty()) reason = "interface not reopened";
    } else if (in_outage) {
      ok = false;
      if (reason.empty()) reason = outage_faults && !o.recover ? "joints faulted in the outage (no --recover)"
                                                              : "not every joint followed again after the outage";
    }
  } else if (outage_seen && reason.empty()) {
    reason = "unexpected interface outage";
  }
  if (outage_seen && !o.expect_outage) ok = false;
  if (o.expect_hb_loss) {
    if (!expected_seen) {
      ok = false;
      reason = "heartbeat loss of node " + std::to_string(o.expect_hb_loss) + " not reported";
    }
    ok = ok && hb_loss_ok && !other_fault;
  } else {
    ok = ok && !other_fault;
  }
  if (o.stream > 0 && worst > o.tolerance) {
    ok = false;
    if (reason.empty()) reason = "tracking error above tolerance";
  }
  const BusStats bs = bus.stats();
  std::printf("result status=%s cycles=%llu late_cycles=%llu max_err_rad=%.6f ignored_frames=%llu tx_errors=%llu "
              "reopens=%llu reason=\"%s\"\n",
              ok ? "ok" : "fail", static_cast<unsigned long long>(cycles), static_cast<unsigned long long>(late), worst,
              static_cast<unsigned long long>(master.ignored_frames()), static_cast<unsigned long long>(bs.tx_errors),
              static_cast<unsigned long long>(bs.reopens), reason.c_str());
  return ok ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    std::string v;
    auto value = [&]() {
      if (i + 1 >= argc) return false;
      v = argv[++i];
      return true;
    };
    auto num = [&](double& out, double lo) { return value() && sim::cli::parse_double(v, out) && out >= lo; };
    auto uint = [&](std::uint32_t& out, std::uint32_t max) { return value() && sim::cli::parse_uint(v, max, out); };
    if (a == "--help" || a == "-h") {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (a == "--sim") {
      o.sim = true;
    } else if (a == "--bringup") {
      o.bringup = true;
    } else if (a == "--quiet") {
      o.quiet = true;
    } else if (a == "--no-filters") {
      o.filters = false;
    } else if (a == "--tpdo2") {
      if (!value() || !parse_tpdo2(v, o.tpdo2))
        return usage_error("bad --tpdo2 '" + v + "' (e.g. velocity,error_code or velocity:required,torque; "
                           "'none' for no TPDO2)");
    } else if (a == "--recover") {
      o.recover = true;
    } else if (a == "--expect-outage") {
      o.expect_outage = true;
    } else if (a == "--roundtrip") {
      if (!uint(o.roundtrip, 1000000) || o.roundtrip == 0) return usage_error("bad --roundtrip N (1..1000000)");
    } else if (a == "--roundtrip-timeout-ms") {
      if (!uint(o.roundtrip_timeout_ms, 60000) || o.roundtrip_timeout_ms == 0)
        return usage_error("bad --roundtrip-timeout-ms (1..60000)");
    } else if (a == "--iface") {
      if (!value()) return usage_error("--iface needs a name");
      o.iface = v;
    } else if (a == "--fd") {
      std::uint32_t fd = 0;
      if (!uint(fd, 1 << 20)) return usage_error("bad --fd");
      o.fd = int(fd);
    } else if (a == "--nodes") {
      if (!value() || !sim::cli::parse_nodes(v, o.nodes)) return usage_error("bad --nodes (e.g. 1-6 or 1,3,5)");
      if (o.nodes.size() > kMaxServoJoints) return usage_error("at most 8 nodes");
    } else if (a == "--stream-sine") {
      if (!num(o.stream, 0)) return usage_error("bad --stream-sine SEC");
    } else if (a == "--hold") {
      if (!num(o.hold, 0)) return usage_error("bad --hold SEC");
    } else if (a == "--amplitude") {
      if (!num(o.amplitude, 0)) return usage_error("bad --amplitude");
    } else if (a == "--freq") {
      if (!num(o.freq, 0)) return usage_error("bad --freq");
    } else if (a == "--tolerance") {
      if (!num(o.tolerance, 0)) return usage_error("bad --tolerance");
    } else if (a == "--period-ms") {
      if (!num(o.period_ms, 0.1)) return usage_error("bad --period-ms (>= 0.1)");
    } else if (a == "--hb-ms") {
      if (!uint(o.hb_ms, 65535) || o.hb_ms == 0) return usage_error("bad --hb-ms (1..65535)");
    } else if (a == "--hb-timeout-ms") {
      if (!uint(o.hb_timeout_ms, 600000) || o.hb_timeout_ms == 0) return usage_error("bad --hb-timeout-ms");
    } else if (a == "--sdo-timeout-ms") {
      if (!uint(o.sdo_timeout_ms, 60000) || o.sdo_timeout_ms == 0) return usage_error("bad --sdo-timeout-ms");
    } else if (a == "--enable-timeout-ms") {
      if (!uint(o.enable_timeout_ms, 600000) || o.enable_timeout_ms == 0) return usage_error("bad --enable-timeout-ms");
    } else if (a == "--counts-per-rev") {
      if (!uint(o.cpr, 0x7FFFFFFF) || o.cpr == 0) return usage_error("bad --counts-per-rev");
    } else if (a == "--expect-hb-loss") {
      if (!uint(o.expect_hb_loss, 127) || o.expect_hb_loss == 0) return usage_error("bad --expect-hb-loss NODE");
    } else if (a == "--sim-silent" || a == "--sim-emcy") {
      sim::cli::FaultArg f;
      const bool emcy = a == "--sim-emcy";
      std::uint32_t code = 0;
      if (!value() || !sim::cli::parse_fault(v, emcy, f) || f.node == 0 ||
          (emcy && (!sim::cli::parse_uint(f.value, 0xFFFF, code) || code == 0)))
        return usage_error("bad " + a + " (NODE@SEC or NODE:CODE@SEC)");
      (emcy ? o.sim_emcy : o.sim_silent).push_back(f);
    } else if (a == "--home") {
      if (!value()) return usage_error("--home needs NODE:METHOD or NODE:hard_stop[:+|-]");
      const std::size_t c = v.find(':');
      std::uint32_t node = 0, m = 0;
      Options::Home h;
      if (c == std::string::npos || !sim::cli::parse_uint(v.substr(0, c), 127, node) || node == 0)
        return usage_error("bad --home '" + v + "' (NODE:METHOD, e.g. 3:19, or NODE:hard_stop[:+|-])");
      const std::string rest = v.substr(c + 1);
      if (rest.rfind("hard_stop", 0) == 0) {
        h.kind = HomingKind::hard_stop;
        if (rest == "hard_stop:+") h.dir = 1;
        else if (rest != "hard_stop" && rest != "hard_stop:-") return usage_error("bad --home '" + v + "' (hard_stop[:+|-])");
      } else if (!sim::cli::parse_uint(rest, 127, m) || m == 0 || m == 36 || m > 37) {
        return usage_error("bad --home '" + v + "': METHOD must be a CiA 402 homing method 1..35 or 37");
      }
      h.node = std::uint8_t(node);
      h.method = int(m);
      o.home.push_back(h);
    } else if (a == "--home-speeds") {
      if (!value()) return usage_error("--home-speeds needs SW,ZERO");
      const std::size_t c = v.find(',');
      if (c == std::string::npos || !sim::cli::parse_double(v.substr(0, c), o.home_sw) ||
          !sim::cli::parse_double(v.substr(c + 1), o.home_zero) || o.home_sw <= 0 || o.home_zero <= 0)
        return usage_error("bad --home-speeds '" + v + "' (SW,ZERO in rev/s, both > 0)");
    } else if (a == "--home-accel") {
      if (!num(o.home_accel, 1e-6)) return usage_error("bad --home-accel (> 0 rev/s^2)");
    } else if (a == "--home-offset") {
      if (!value() || !sim::cli::parse_double(v, o.home_offset) || std::fabs(o.home_offset) > 1e9)
        return usage_error("bad --home-offset COUNTS");
    } else if (a == "--home-timeout") {
      if (!num(o.home_timeout, 0.001)) return usage_error("bad --home-timeout SEC (> 0)");
    } else {
      return usage_error("unknown option " + a);
    }
  }
  for (const auto& h : o.home)
    if (std::find(o.nodes.begin(), o.nodes.end(), h.node) == o.nodes.end())
      return usage_error("--home node " + std::to_string(h.node) + " is not in --nodes");
  if (int(o.sim) + int(!o.iface.empty()) + int(o.fd >= 0) != 1)
    return usage_error("give exactly one of --iface NAME, --fd N or --sim");
  if (!o.bringup) return usage_error("nothing to do: add --bringup (and --roundtrip / --stream-sine / --hold)");
  if ((o.recover || o.expect_outage) && o.iface.empty())
    return usage_error("--recover / --expect-outage need --iface (an interface that can go down)");
  if (!o.sim && (!o.sim_silent.empty() || !o.sim_emcy.empty())) return usage_error("--sim-* faults need --sim");
  if (o.expect_hb_loss && std::find(o.nodes.begin(), o.nodes.end(), std::uint8_t(o.expect_hb_loss)) == o.nodes.end())
    return usage_error("--expect-hb-loss node is not in --nodes");

  if (o.sim) {
    ManualClock clock;
    SimParts s;
    s.bus = std::make_unique<SimBus>(clock, 50 * kMicrosecond);
    s.master_ep = s.bus->open(4096);
    s.sim_ep = s.bus->open(4096);
    s.arm = std::make_unique<sim::ArmSim>(*s.sim_ep, o.nodes);
    s.arm->power_on(clock.now());
    clock.set_idle_hook([&](TimePoint t) { s.arm->step(t); });
    const int rc = run(*s.master_ep, clock, o, s.arm.get());
    clock.set_idle_hook(nullptr);
    return rc;
  }
  if (o.fd >= 0) {
    SocketCanBus bus(o.fd);
    MonotonicClock clock;
    return run(bus, clock, o, nullptr, &bus);
  }
  SocketCanBus bus;
  if (const Status st = bus.open(o.iface.c_str()); st != Status::ok) {
    std::fprintf(stderr, "canmaster: cannot open %s: %s (%s)\n", o.iface.c_str(), bus.message(), to_string(st));
    return 3;
  }
  MonotonicClock clock;
  return run(bus, clock, o, nullptr, &bus);
}
