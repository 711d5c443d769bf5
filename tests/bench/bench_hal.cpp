// SPDX-License-Identifier: Apache-2.0
// HAL / servo bus benchmarks: the per-cycle codec path and master -> virtual
// drives -> master round trips on the in-process bus. Figures: tests/bench/RESULTS.md.
#include <benchmark/benchmark.h>

#include <sys/socket.h>

#include <atomic>
#include <cmath>
#include <memory>
#include <thread>
#include <vector>

#include "servoarm/hal/canopen.hpp"
#include "servoarm/hal/canopen_master.hpp"
#include "servoarm/hal/sim_bus.hpp"
#include "servoarm/hal/socketcan_bus.hpp"
#include "servoarm/sim/virtual_drive.hpp"

using namespace servoarm;
using namespace servoarm::hal;

namespace {

// Per-cycle codec work for 6 joints, no bus: scale + encode 6 RPDO1 + SYNC, then
// decode 6 TPDO1 (statusword + position) and 6 TPDO2 (velocity + error code) and scale back.
void BM_HalCycleCodec6(benchmark::State& state) {
  JointScaling sc;
  sc.counts_per_unit = 131072;
  sc.gear_ratio = 100;
  std::array<CanFrame, 12> feedback;
  for (std::uint8_t j = 0; j < 6; ++j) {
    feedback[j] = pdo::encode_tpdo1(std::uint8_t(j + 1), 0x0637, 1000 * j);
    feedback[6 + j] = pdo::encode_tpdo2(std::uint8_t(j + 1), -50 * j, 0);
  }
  double sp[6] = {0.1, -0.2, 0.3, -0.4, 0.5, -0.6};
  std::array<CanFrame, 7> out;
  double pos[6], vel[6];
  for (auto _ : state) {
    for (int j = 0; j < 6; ++j) {
      std::int32_t c = 0;
      sc.to_counts(sp[j], c);
      out[j] = pdo::encode_rpdo1(std::uint8_t(j + 1), cia402::cw::kEnableOperation, c);
    }
    out[6] = canopen::encode_sync();
    for (int j = 0; j < 6; ++j) {
      std::uint16_t sw;
      std::int32_t p, v;
      std::uint16_t code;
      pdo::decode_tpdo1(feedback[j], sw, p);
      pdo::decode_tpdo2(feedback[6 + j], v, code);
      pos[j] = sc.to_joint(p) + double(cia402::decode_statusword(sw));
      vel[j] = sc.velocity_to_joint(v) + code;
    }
    benchmark::DoNotOptimize(out);
    benchmark::DoNotOptimize(pos);
    benchmark::DoNotOptimize(vel);
    benchmark::ClobberMemory();
    sp[0] += 1e-9;
  }
}
BENCHMARK(BM_HalCycleCodec6);

// Master + 6 virtual drives on the in-process bus, one thread, simulated clock.
struct Rig {
  ManualClock clock;
  SimBus bus{clock, 50 * kMicrosecond};
  std::unique_ptr<SimBusEndpoint> master_ep = bus.open(4096);
  std::unique_ptr<SimBusEndpoint> sim_ep = bus.open(4096);
  std::vector<std::uint8_t> nodes{1, 2, 3, 4, 5, 6};
  sim::ArmSim arm{*sim_ep, nodes};
  CanopenServoBus master{*master_ep, clock, CanopenMasterConfig::consecutive(1, 6)};
  bool ok = false;
  Rig() {
    arm.power_on(clock.now());
    clock.set_idle_hook([this](TimePoint t) { arm.step(t); });
    ok = master.start(clock.now() + kSecond) == Status::ok &&
         master.enable_blocking(clock.now() + kSecond, kMillisecond) == Status::ok;
    clock.set_idle_hook(nullptr);
  }
};

// ServoBus::read + write for 6 joints on the sim bus: 12 TPDOs pushed through the bus
// (stand-in for the drives, counted in the figure), then the master drains and decodes
// them and sends 6 RPDOs + SYNC. The firmware's per-cycle bus cost with this backend,
// sim bus mutex included.
void BM_HalMasterReadWrite6_SimBus(benchmark::State& state) {
  Rig rig;
  if (!rig.ok) {
    state.SkipWithError("bring-up failed");
    return;
  }
  auto feeder = rig.bus.open(1);  // its own queue just overflows (counted, cheap)
  std::array<CanFrame, 12> fb;
  for (std::uint8_t j = 0; j < 6; ++j) {
    fb[j] = pdo::encode_tpdo1(std::uint8_t(j + 1), 0x0637, 0);
    fb[6 + j] = pdo::encode_tpdo2(std::uint8_t(j + 1), 0, 0);
  }
  // The drives are not stepped: their queue fills and then counts overflows (cheap).
  double sp[6] = {};
  for (auto _ : state) {
    for (auto& f : fb) feeder->send(f);
    const TimePoint now = rig.clock.now();
    rig.master.read(now);
    rig.master.write(std::span<const double>(sp, 6), now);
  }
}
BENCHMARK(BM_HalMasterReadWrite6_SimBus);

// Round trip master -> armsim -> master, one thread: write RPDOs + SYNC, the drives
// handle them (motor model step, TPDOs out), the master reads the 12 TPDOs.
void BM_HalRoundTrip6_SimBus_OneThread(benchmark::State& state) {
  Rig rig;
  if (!rig.ok) {
    state.SkipWithError("bring-up failed");
    return;
  }
  double sp[6] = {};
  int k = 0;
  for (auto _ : state) {
    const TimePoint now = rig.clock.now();
    for (int j = 0; j < 6; ++j) sp[j] = 0.01 * std::sin(1e-3 * k + j);
    rig.master.write(std::span<const double>(sp, 6), now);
    rig.clock.advance(kMillisecond);  // no hook: step the drives explicitly
    rig.arm.step(rig.clock.now());
    rig.master.read(rig.clock.now());
    ++k;
  }
  if (rig.master.feedback(0).state != JointState::enabled) state.SkipWithError("drive left operation enabled");
}
BENCHMARK(BM_HalRoundTrip6_SimBus_OneThread);

// Round trip with the drives on their own thread (real clock, condition-variable
// wake-ups): time from sending RPDOs + SYNC until all 6 TPDO1 are back.
void BM_HalRoundTrip6_SimBus_TwoThreads(benchmark::State& state) {
  MonotonicClock clock;
  SimBus bus(clock);
  auto master_ep = bus.open(4096);
  auto sim_ep = bus.open(4096);
  std::vector<std::uint8_t> nodes{1, 2, 3, 4, 5, 6};
  sim::ArmSim arm(*sim_ep, nodes);
  arm.power_on(clock.now());
  std::atomic<bool> stop{false};
  std::thread drives([&] {
    TimePoint next = clock.now();
    while (!stop.load(std::memory_order_relaxed)) {
      CanFrame f;
      if (sim_ep->receive(f, next) == Status::ok) arm.handle(f, clock.now());
      if (clock.now() >= next) {
        arm.tick(clock.now());
        next = clock.now() + kMillisecond;
      }
    }
  });
  CanopenServoBus master(*master_ep, clock, CanopenMasterConfig::consecutive(1, 6));
  bool ok = master.start(clock.now() + 2 * kSecond) == Status::ok &&
            master.enable_blocking(clock.now() + 2 * kSecond, kMillisecond) == Status::ok;
  if (!ok) state.SkipWithError("bring-up failed");
  double sp[6] = {};
  for (auto _ : state) {
    if (!ok) break;
    master.write(std::span<const double>(sp, 6), clock.now());
    int got = 0;
    CanFrame f;
    const TimePoint deadline = clock.now() + 100 * kMillisecond;
    while (got < 6 && master_ep->receive(f, deadline) == Status::ok) {
      if (canopen::function_of(f.id) == canopen::kTpdo1) ++got;
      master.dispatch(f, f.rx_time);
    }
  }
  stop = true;
  drives.join();
}
BENCHMARK(BM_HalRoundTrip6_SimBus_TwoThreads)->UseRealTime();

// SocketCanBus over a socketpair(AF_UNIX, SOCK_SEQPACKET): 7 frames (6 RPDO + SYNC)
// written and read back through the kernel, the syscall cost of one cycle's output
// (vcan costs about the same per frame; a real controller adds the wire time).
void BM_HalSocketCanPair7Frames(benchmark::State& state) {
  int sv[2];
  if (socketpair(AF_UNIX, SOCK_SEQPACKET, 0, sv) != 0) {
    state.SkipWithError("socketpair failed");
    return;
  }
  SocketCanBus a(sv[0]), b(sv[1]);
  std::array<CanFrame, 7> out;
  for (std::uint8_t j = 0; j < 6; ++j) out[j] = pdo::encode_rpdo1(std::uint8_t(j + 1), 0x000F, 1000 * j);
  out[6] = canopen::encode_sync();
  CanFrame in;
  for (auto _ : state) {
    for (auto& f : out) a.send(f);
    for (int i = 0; i < 7; ++i) b.receive(in, 0);
    benchmark::DoNotOptimize(in);
  }
}
BENCHMARK(BM_HalSocketCanPair7Frames);

// The round trip of BM_HalRoundTrip6_SimBus_TwoThreads through the kernel: master and
// drives each on a SocketCanBus, the two ends of a socketpair(AF_UNIX, SOCK_SEQPACKET)
// carrying struct can_frame records (what vcan does between two sockets, minus the CAN
// layer), the drives on their own thread waiting in ppoll. Time from sending RPDOs + SYNC
// until all 6 TPDO1 are back - the host reference for the vcan figure of vcan_s6_latency
// (canmaster --roundtrip), which runs emulated.
void BM_HalRoundTrip6_SocketPair_TwoThreads(benchmark::State& state) {
  int sv[2];
  if (socketpair(AF_UNIX, SOCK_SEQPACKET, 0, sv) != 0) {
    state.SkipWithError("socketpair failed");
    return;
  }
  MonotonicClock clock;
  SocketCanBus master_bus(sv[0]), drive_bus(sv[1]);
  std::vector<std::uint8_t> nodes{1, 2, 3, 4, 5, 6};
  sim::ArmSim arm(drive_bus, nodes);
  arm.power_on(clock.now());
  std::atomic<bool> stop{false};
  std::thread drives([&] {
    TimePoint next = clock.now();
    while (!stop.load(std::memory_order_relaxed)) {
      CanFrame f;
      if (drive_bus.receive(f, next) == Status::ok) arm.handle(f, clock.now());
      if (clock.now() >= next) {
        arm.tick(clock.now());
        next = clock.now() + kMillisecond;
      }
    }
  });
  CanopenServoBus master(master_bus, clock, CanopenMasterConfig::consecutive(1, 6));
  bool ok = master.start(clock.now() + 2 * kSecond) == Status::ok &&
            master.enable_blocking(clock.now() + 2 * kSecond, kMillisecond) == Status::ok;
  if (!ok) state.SkipWithError("bring-up failed");
  double sp[6] = {};
  for (int j = 0; j < 6; ++j) sp[j] = master.feedback(std::size_t(j)).position;
  std::int64_t lost = 0;
  for (auto _ : state) {
    if (!ok) break;
    master.write(std::span<const double>(sp, 6), clock.now());
    int got = 0;
    CanFrame f;
    const TimePoint deadline = clock.now() + 100 * kMillisecond;
    while (got < 6 && master_bus.receive(f, deadline) == Status::ok) {
      if (canopen::function_of(f.id) == canopen::kTpdo1) ++got;
      master.dispatch(f, f.rx_time);
    }
    if (got < 6) ++lost;
  }
  stop = true;
  drives.join();
  state.counters["lost"] = double(lost);
}
BENCHMARK(BM_HalRoundTrip6_SocketPair_TwoThreads)->UseRealTime();

}  // namespace
