// SPDX-License-Identifier: Apache-2.0
// CanFrame validity and the in-process SimBus (vcan semantics, fault injection).
#include <cstdio>
#include <thread>
#include <vector>

#include "servoarm/hal/can_frame.hpp"
#include "servoarm/hal/sim_bus.hpp"

// CppUTest last: its leak detector redefines `new`.
#include <CppUTest/TestHarness.h>

using namespace servoarm::hal;

TEST_GROUP(CanFrame){};

TEST(CanFrame, ValidityTable) {
  struct Case {
    std::uint32_t id;
    bool ext, rtr, fd, err;
    std::uint8_t len;
    bool valid;
  } cases[] = {
      {0x000, false, false, false, false, 0, true},
      {0x7FF, false, false, false, false, 8, true},
      {0x800, false, false, false, false, 1, false},        // 12-bit id in standard format
      {0x800, true, false, false, false, 1, true},         // fine as extended
      {0x1FFFFFFF, true, false, false, false, 8, true},
      {0x20000000, true, false, false, false, 8, false},   // 30 bits
      {0x123, false, false, false, false, 9, false},       // classic len > 8
      {0x123, false, true, false, false, 0, true},         // RTR
      {0x123, false, false, true, false, 12, true},        // FD lengths
      {0x123, false, false, true, false, 64, true},
      {0x123, false, false, true, false, 13, false},       // not an FD length
      {0x123, false, true, true, false, 8, false},         // no RTR in FD
      {0x004, false, false, false, true, 8, false},        // error frames are not sendable
  };
  for (const Case& c : cases) {
    CanFrame f;
    f.id = c.id;
    f.extended = c.ext;
    f.rtr = c.rtr;
    f.fd = c.fd;
    f.error = c.err;
    f.len = c.len;
    char msg[96];
    std::snprintf(msg, sizeof msg, "id=0x%X ext=%d rtr=%d fd=%d err=%d len=%u", unsigned(c.id), c.ext, c.rtr, c.fd,
                  c.err, unsigned(c.len));
    CHECK_EQUAL_TEXT(c.valid, f.valid(), msg);
  }
}

TEST(CanFrame, LittleEndianHelpers) {
  std::uint8_t b[4];
  put_u32(b, 0x12345678);
  BYTES_EQUAL(0x78, b[0]);
  BYTES_EQUAL(0x56, b[1]);
  BYTES_EQUAL(0x34, b[2]);
  BYTES_EQUAL(0x12, b[3]);
  UNSIGNED_LONGS_EQUAL(0x12345678, get_u32(b));
  put_u16(b, 0xBEEF);
  BYTES_EQUAL(0xEF, b[0]);
  BYTES_EQUAL(0xBE, b[1]);
  UNSIGNED_LONGS_EQUAL(0xBEEF, get_u16(b));
}

TEST_GROUP(SimBus) {
  ManualClock clock;
};

TEST(SimBus, EveryOtherEndpointInOrderNoEchoByDefault) {
  SimBus bus(clock);
  auto a = bus.open(16);
  auto b = bus.open(16);
  auto c = bus.open(16);
  for (std::uint8_t i = 0; i < 5; ++i) LONGS_EQUAL(int(Status::ok), int(a->send(CanFrame::make(0x100 + i, {i, 0xAA}))));
  LONGS_EQUAL(0, a->pending());
  for (auto* ep : {b.get(), c.get()}) {
    for (std::uint8_t i = 0; i < 5; ++i) {
      CanFrame f;
      LONGS_EQUAL(int(Status::ok), int(ep->receive(f, 0)));
      UNSIGNED_LONGS_EQUAL(0x100 + i, f.id);
      BYTES_EQUAL(i, f.data[0]);
      LONGS_EQUAL(2, f.len);
    }
    CanFrame f;
    LONGS_EQUAL(int(Status::timeout), int(ep->receive(f, 0)));
  }
  UNSIGNED_LONGS_EQUAL(5, a->stats().tx_frames);
  UNSIGNED_LONGS_EQUAL(5, b->stats().rx_frames);
}

TEST(SimBus, LoopbackDeliversOwnFrames) {
  SimBus bus(clock);
  auto a = bus.open(4, /*loopback=*/true);
  a->send(CanFrame::make(0x55, {1}));
  CanFrame f;
  LONGS_EQUAL(int(Status::ok), int(a->receive(f, 0)));
  UNSIGNED_LONGS_EQUAL(0x55, f.id);
}

TEST(SimBus, BoundedQueueCountsOverflow) {
  SimBus bus(clock);
  auto a = bus.open(4);
  auto b = bus.open(3);
  for (int i = 0; i < 10; ++i) a->send(CanFrame::make(0x10, {std::uint8_t(i)}));
  UNSIGNED_LONGS_EQUAL(3, b->pending());
  UNSIGNED_LONGS_EQUAL(7, b->stats().rx_overruns);
  CanFrame f;
  b->receive(f, 0);
  BYTES_EQUAL(0, f.data[0]);  // the oldest frames are kept, newer ones dropped
}

TEST(SimBus, InvalidFrameRejected) {
  SimBus bus(clock);
  auto a = bus.open(4);
  auto b = bus.open(4);
  CanFrame bad;
  bad.id = 0x800;
  LONGS_EQUAL(int(Status::invalid_argument), int(a->send(bad)));
  LONGS_EQUAL(0, b->pending());
  UNSIGNED_LONGS_EQUAL(1, a->stats().tx_errors);
}

TEST(SimBus, FiltersLikeSocketCan) {
  SimBus bus(clock);
  auto a = bus.open(32);
  auto b = bus.open(32);
  const CanFilter filters[] = {{0x180, 0x780, false}, {0x700, 0x7FF, false}};
  LONGS_EQUAL(int(Status::ok), int(b->set_filters(filters)));
  const std::uint32_t ids[] = {0x181, 0x1FF, 0x201, 0x700, 0x701, 0x080};
  for (auto id : ids) a->send(CanFrame::make(id, {}));
  CanFrame ext = CanFrame::make(0x181, {});
  ext.extended = true;  // same number, other format: must not pass
  a->send(ext);
  std::vector<std::uint32_t> got;
  CanFrame f;
  while (b->receive(f, 0) == Status::ok) got.push_back(f.id);
  LONGS_EQUAL(3, got.size());
  UNSIGNED_LONGS_EQUAL(0x181, got[0]);
  UNSIGNED_LONGS_EQUAL(0x1FF, got[1]);
  UNSIGNED_LONGS_EQUAL(0x700, got[2]);
  CanFilter too_many[CanBus::kMaxFilters + 1];
  LONGS_EQUAL(int(Status::capacity), int(b->set_filters(too_many)));
}

TEST(SimBus, ReceiveWaitsUntilDeadlineWithSimulatedClock) {
  SimBus bus(clock, 100 * kMicrosecond);
  auto a = bus.open(4);
  auto b = bus.open(4);
  int hook_calls = 0;
  TimePoint send_at = clock.now() + 750 * kMicrosecond;
  clock.set_idle_hook([&](TimePoint t) {
    ++hook_calls;
    if (t >= send_at && send_at != 0) {
      a->send(CanFrame::make(0x42, {7}));
      send_at = 0;
    }
  });
  const TimePoint t0 = clock.now();
  CanFrame f;
  LONGS_EQUAL(int(Status::ok), int(b->receive(f, t0 + 5 * kMillisecond)));
  UNSIGNED_LONGS_EQUAL(0x42, f.id);
  CHECK(clock.now() - t0 >= 750 * kMicrosecond);
  CHECK(clock.now() - t0 <= 850 * kMicrosecond);  // noticed within one poll step
  CHECK(hook_calls >= 7);
  // Nothing more: times out exactly at the deadline.
  const TimePoint t1 = clock.now();
  LONGS_EQUAL(int(Status::timeout), int(b->receive(f, t1 + 2 * kMillisecond)));
  LONGS_EQUAL(t1 + 2 * kMillisecond, clock.now());
  clock.set_idle_hook(nullptr);
}

namespace {
std::vector<int> survivors(ManualClock& clock, std::uint64_t seed, double rate, int n) {
  SimBus bus(clock);
  auto a = bus.open(4);
  auto b = bus.open(std::size_t(n));
  SimFaults faults;
  faults.drop_rate = rate;
  faults.seed = seed;
  bus.set_faults(faults);
  for (int i = 0; i < n; ++i) a->send(CanFrame::make(0x1, {std::uint8_t(i), std::uint8_t(i >> 8)}));
  std::vector<int> got;
  CanFrame f;
  while (b->receive(f, 0) == Status::ok) got.push_back(f.data[0] | (f.data[1] << 8));
  return got;
}
}  // namespace

TEST(SimBus, DropRateIsSeededAndNearTheRate) {
  const auto a = survivors(clock, 1234, 0.25, 10000);
  CHECK(a.size() > 7300 && a.size() < 7700);
  for (std::size_t i = 1; i < a.size(); ++i) CHECK(a[i] > a[i - 1]);  // order kept
  CHECK(a == survivors(clock, 1234, 0.25, 10000));                   // reproducible
  CHECK(a != survivors(clock, 4321, 0.25, 10000));
  LONGS_EQUAL(10000, survivors(clock, 1, 0.0, 10000).size());
}

TEST(SimBus, DelayHoldsFramesBack) {
  SimBus bus(clock);
  auto a = bus.open(4);
  auto b = bus.open(4);
  SimFaults faults;
  faults.delay = 2 * kMillisecond;
  bus.set_faults(faults);
  a->send(CanFrame::make(0x9, {1}));
  CanFrame f;
  LONGS_EQUAL(int(Status::timeout), int(b->receive(f, 0)));
  clock.advance(1999 * kMicrosecond);
  LONGS_EQUAL(int(Status::timeout), int(b->receive(f, 0)));
  clock.advance(kMicrosecond);
  LONGS_EQUAL(int(Status::ok), int(b->receive(f, 0)));
}

TEST(SimBus, CorruptionFlipsExactlyOneBit) {
  SimBus bus(clock);
  auto a = bus.open(4);
  auto b = bus.open(4);
  SimFaults faults;
  faults.corrupt_rate = 1.0;
  faults.seed = 99;
  bus.set_faults(faults);
  for (int i = 0; i < 200; ++i) {
    const CanFrame sent = CanFrame::make(0x3, {0x00, 0xFF, 0x55, 0xAA, 0x12, 0x34, 0x56, 0x78});
    a->send(sent);
    CanFrame f;
    LONGS_EQUAL(int(Status::ok), int(b->receive(f, 0)));
    int flipped = 0;
    for (int k = 0; k < 8; ++k) flipped += __builtin_popcount(unsigned(f.data[k] ^ sent.data[k]));
    LONGS_EQUAL(1, flipped);
  }
}

TEST(SimBus, BusOffRefusesSends) {
  SimBus bus(clock);
  auto a = bus.open(4);
  auto b = bus.open(4);
  bus.set_error_state(ErrorState::bus_off);
  LONGS_EQUAL(int(Status::bus_off), int(a->send(CanFrame::make(1, {}))));
  LONGS_EQUAL(int(ErrorState::bus_off), int(b->stats().state));
  bus.set_error_state(ErrorState::passive);
  LONGS_EQUAL(int(Status::error_passive), int(a->send(CanFrame::make(1, {}))));
  LONGS_EQUAL(1, b->pending());
  STRCMP_EQUAL("bus_off", to_string(ErrorState::bus_off));
}

TEST(SimBus, RealClockReceiveWakesOnSendFromAnotherThread) {
  MonotonicClock real;
  SimBus bus(real);
  auto a = bus.open(4);
  auto b = bus.open(4);
  const TimePoint t0 = real.now();
  std::thread sender([&] {
    real.sleep_until(t0 + 20 * kMillisecond);
    a->send(CanFrame::make(0x77, {1}));
  });
  CanFrame f;
  const Status s = b->receive(f, t0 + 2 * kSecond);
  const Duration waited = real.now() - t0;
  sender.join();
  LONGS_EQUAL(int(Status::ok), int(s));
  UNSIGNED_LONGS_EQUAL(0x77, f.id);
  CHECK(waited >= 20 * kMillisecond);
  CHECK(waited < kSecond);  // woken by the send, not by the deadline
  // And the deadline holds when nothing comes.
  const TimePoint t1 = real.now();
  LONGS_EQUAL(int(Status::timeout), int(b->receive(f, t1 + 30 * kMillisecond)));
  CHECK(real.now() - t1 >= 30 * kMillisecond);
}
