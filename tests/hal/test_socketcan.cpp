// SPDX-License-Identifier: Apache-2.0
// SocketCAN backend without kernel CAN: the fd-taking constructor on one end of
// a socketpair(AF_UNIX, SOCK_SEQPACKET) carrying struct can_frame bytes.
#include <linux/can.h>
#include <linux/can/error.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstring>

#include "alloc_counter.hpp"
#include "servoarm/hal/socketcan_bus.hpp"

// CppUTest last: its leak detector redefines `new`.
#include <CppUTest/TestHarness.h>

using namespace servoarm::hal;

TEST_GROUP(SocketCan) {
  int sv[2] = {-1, -1};
  SocketCanBus* bus = nullptr;
  MonotonicClock clock;
  void setup() override {
    CHECK(socketpair(AF_UNIX, SOCK_SEQPACKET, 0, sv) == 0);
    bus = new SocketCanBus(sv[0]);
  }
  void teardown() override {
    delete bus;
    if (sv[1] >= 0) close(sv[1]);
  }
  void peer_send(canid_t id, std::initializer_list<std::uint8_t> bytes) {
    can_frame k;
    std::memset(&k, 0, sizeof k);
    k.can_id = id;
    k.can_dlc = std::uint8_t(bytes.size());
    std::size_t i = 0;
    for (auto b : bytes) k.data[i++] = b;
    CHECK(write(sv[1], &k, sizeof k) == ssize_t(sizeof k));
  }
};

TEST(SocketCan, SendWritesKernelLayout) {
  LONGS_EQUAL(int(Status::ok), int(bus->send(CanFrame::make(0x601, {0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0}))));
  CanFrame ext = CanFrame::make(0x1ABCDE0, {0xAA});
  ext.extended = true;
  LONGS_EQUAL(int(Status::ok), int(bus->send(ext)));
  CanFrame rtr;
  rtr.id = 0x701;
  rtr.rtr = true;
  LONGS_EQUAL(int(Status::ok), int(bus->send(rtr)));

  can_frame k;
  LONGS_EQUAL(sizeof(can_frame), read(sv[1], &k, sizeof k));  // one 16-byte record per frame
  UNSIGNED_LONGS_EQUAL(0x601, k.can_id);
  LONGS_EQUAL(8, k.can_dlc);
  BYTES_EQUAL(0x40, k.data[0]);
  BYTES_EQUAL(0x10, k.data[2]);
  LONGS_EQUAL(sizeof(can_frame), read(sv[1], &k, sizeof k));
  UNSIGNED_LONGS_EQUAL(0x1ABCDE0u | CAN_EFF_FLAG, k.can_id);
  LONGS_EQUAL(1, k.can_dlc);
  LONGS_EQUAL(sizeof(can_frame), read(sv[1], &k, sizeof k));
  UNSIGNED_LONGS_EQUAL(0x701u | CAN_RTR_FLAG, k.can_id);
  UNSIGNED_LONGS_EQUAL(3, bus->stats().tx_frames);
}

TEST(SocketCan, SendRejectsInvalidFrame) {
  CanFrame bad = CanFrame::make(0x900, {1});
  LONGS_EQUAL(int(Status::invalid_argument), int(bus->send(bad)));
  UNSIGNED_LONGS_EQUAL(1, bus->stats().tx_errors);
}

TEST(SocketCan, ReceiveDecodesIdsAndFlags) {
  peer_send(0x185, {0x27, 0x06, 1, 2, 3, 4});
  peer_send(0x12345u | CAN_EFF_FLAG, {9});
  CanFrame f;
  const TimePoint dl = clock.now() + 100 * kMillisecond;
  LONGS_EQUAL(int(Status::ok), int(bus->receive(f, dl)));
  UNSIGNED_LONGS_EQUAL(0x185, f.id);
  CHECK_FALSE(f.extended);
  LONGS_EQUAL(6, f.len);
  BYTES_EQUAL(4, f.data[5]);
  CHECK(f.rx_time > 0);
  LONGS_EQUAL(int(Status::ok), int(bus->receive(f, dl)));
  UNSIGNED_LONGS_EQUAL(0x12345, f.id);
  CHECK(f.extended);
  UNSIGNED_LONGS_EQUAL(2, bus->stats().rx_frames);
}

// rx_time must say when the frame arrived. Which kernel stamp is available decides the
// resolution: SO_TIMESTAMPNS on a Linux kernel; under qemu-user (7.2 answers
// SO_TIMESTAMPNS with ENOPROTOOPT) the microsecond SO_TIMESTAMP, which it translates.
// Either way the stamp is taken when the frame was queued, 30 ms before it is read.
TEST(SocketCan, RxTimeIsWhenTheFrameArrivedNotWhenItWasRead) {
  CHECK_TEXT(bus->rx_timestamps() != RxTimestamps::receive,
             "neither SO_TIMESTAMPNS nor SO_TIMESTAMP accepted on an AF_UNIX socket");
  const TimePoint before = clock.now();
  peer_send(0x701, {0x05});
  const TimePoint after_send = clock.now();
  clock.sleep_until(after_send + 30 * kMillisecond);
  CanFrame f;
  LONGS_EQUAL(int(Status::ok), int(bus->receive(f, 0)));
  const TimePoint read_at = clock.now();
  // Kernel timestamp (moved to CLOCK_MONOTONIC): within the send window, well before the read.
  const Duration res = bus->rx_timestamps() == RxTimestamps::kernel_us ? kMicrosecond : 1;
  CHECK(f.rx_time >= before - kMillisecond - res);
  CHECK(f.rx_time <= after_send + kMillisecond);
  CHECK(read_at - f.rx_time >= 29 * kMillisecond);
}

// Without kernel stamps (options.kernel_timestamps = false, or a kernel/emulator that takes
// neither option) rx_time is the CLOCK_MONOTONIC time receive() read the frame: never 0,
// never before the frame was sent, and the queueing time is not hidden.
TEST(SocketCan, RxTimeFallsBackToReceiveTime) {
  int p[2];
  CHECK(socketpair(AF_UNIX, SOCK_SEQPACKET, 0, p) == 0);
  SocketCanOptions opt;
  opt.kernel_timestamps = false;
  SocketCanBus b(p[0], opt);
  LONGS_EQUAL(int(RxTimestamps::receive), int(b.rx_timestamps()));
  STRCMP_EQUAL("receive", to_string(b.rx_timestamps()));
  can_frame k;
  std::memset(&k, 0, sizeof k);
  k.can_id = 0x701;
  k.can_dlc = 1;
  for (int round = 0; round < 3; ++round) {
    CHECK(write(p[1], &k, sizeof k) == ssize_t(sizeof k));
    const TimePoint sent = clock.now();
    clock.sleep_until(sent + 20 * kMillisecond);
    const TimePoint read_from = clock.now();
    CanFrame f;
    LONGS_EQUAL(int(Status::ok), int(b.receive(f, 0)));
    const TimePoint read_to = clock.now();
    CHECK(f.rx_time >= read_from);  // the read time, not the (earlier) arrival
    CHECK(f.rx_time <= read_to);
    CHECK(f.rx_time - sent >= 19 * kMillisecond);
  }
  close(p[1]);
}

TEST(SocketCan, ReceiveHonoursAbsoluteDeadline) {
  CanFrame f;
  const TimePoint t0 = clock.now();
  LONGS_EQUAL(int(Status::timeout), int(bus->receive(f, t0 + 20 * kMillisecond)));
  const Duration waited = clock.now() - t0;
  CHECK(waited >= 20 * kMillisecond);
  CHECK(waited < 200 * kMillisecond);  // generous upper bound for a shared VM
  // A deadline in the past polls.
  const TimePoint t1 = clock.now();
  LONGS_EQUAL(int(Status::timeout), int(bus->receive(f, 0)));
  CHECK(clock.now() - t1 < 10 * kMillisecond);
}

TEST(SocketCan, ErrorFramesUpdateState) {
  CanFrame f;
  // Controller problem: error passive (data[1] = CAN_ERR_CRTL_TX_PASSIVE).
  peer_send(CAN_ERR_FLAG | CAN_ERR_CRTL, {0, CAN_ERR_CRTL_TX_PASSIVE, 0, 0, 0, 0, 0, 0});
  LONGS_EQUAL(int(Status::ok), int(bus->receive(f, 0)));
  CHECK(f.error);
  LONGS_EQUAL(int(ErrorState::passive), int(bus->stats().state));
  // Sending while passive still works but says so.
  LONGS_EQUAL(int(Status::error_passive), int(bus->send(CanFrame::make(0x1, {}))));
  can_frame k;
  CHECK(read(sv[1], &k, sizeof k) == ssize_t(sizeof k));  // that frame went out
  // Bus-off (the kernel's error frame: class CAN_ERR_BUSOFF, as can_bus_off() sends it).
  peer_send(CAN_ERR_FLAG | CAN_ERR_BUSOFF, {0, 0, 0, 0, 0, 0, 0, 0});
  LONGS_EQUAL(int(Status::ok), int(bus->receive(f, 0)));
  LONGS_EQUAL(int(ErrorState::bus_off), int(bus->stats().state));
  // While bus-off nothing is queued: a setpoint would otherwise go out stale after the restart.
  const std::uint64_t tx_before = bus->stats().tx_frames;
  LONGS_EQUAL(int(Status::bus_off), int(bus->send(CanFrame::make(0x201, {0x0F, 0, 1, 2, 3, 4}))));
  UNSIGNED_LONGS_EQUAL(tx_before, bus->stats().tx_frames);
  CHECK(bus->stats().tx_errors >= 1);
  CHECK(recv(sv[1], &k, sizeof k, MSG_DONTWAIT) < 0);  // nothing reached the peer (EAGAIN)
  // Restarted (restart-ms, or ip link set can0 type can restart) -> active again, sends go out.
  peer_send(CAN_ERR_FLAG | CAN_ERR_RESTARTED, {0, 0, 0, 0, 0, 0, 0, 0});
  LONGS_EQUAL(int(Status::ok), int(bus->receive(f, 0)));
  LONGS_EQUAL(int(ErrorState::active), int(bus->stats().state));
  LONGS_EQUAL(int(Status::ok), int(bus->send(CanFrame::make(0x201, {0x0F, 0, 1, 2, 3, 4}))));
  CHECK(read(sv[1], &k, sizeof k) == ssize_t(sizeof k));
  UNSIGNED_LONGS_EQUAL(0x201, k.can_id);
  UNSIGNED_LONGS_EQUAL(3, bus->stats().error_frames);
  UNSIGNED_LONGS_EQUAL(0, bus->stats().rx_frames);  // error frames are not data frames
}

TEST(SocketCan, DecodeErrorFrameTable) {
  struct Case {
    std::uint32_t cls;
    std::uint8_t d1;
    ErrorState prev, expect;
    int overruns;
  } cases[] = {
      {CAN_ERR_CRTL, CAN_ERR_CRTL_RX_WARNING, ErrorState::active, ErrorState::warning, 0},
      {CAN_ERR_CRTL, CAN_ERR_CRTL_RX_PASSIVE, ErrorState::warning, ErrorState::passive, 0},
      {CAN_ERR_CRTL, CAN_ERR_CRTL_RX_OVERFLOW, ErrorState::active, ErrorState::active, 1},
      {CAN_ERR_CRTL, 0x40 /* CAN_ERR_CRTL_ACTIVE */, ErrorState::passive, ErrorState::active, 0},
      {CAN_ERR_BUSOFF, 0, ErrorState::passive, ErrorState::bus_off, 0},
      {CAN_ERR_RESTARTED, 0, ErrorState::bus_off, ErrorState::active, 0},
      {CAN_ERR_PROT, 0, ErrorState::warning, ErrorState::warning, 0},
  };
  for (const auto& c : cases) {
    CanFrame f;
    f.error = true;
    f.id = c.cls;
    f.len = 8;
    f.data[1] = c.d1;
    std::uint64_t ov = 0;
    LONGS_EQUAL(int(c.expect), int(SocketCanBus::decode_error_frame(f, c.prev, &ov)));
    LONGS_EQUAL(c.overruns, int(ov));
  }
}

TEST(SocketCan, UserSpaceFiltersOnAdoptedFd) {
  const CanFilter only_hb[] = {{0x700, 0x780, false}};
  LONGS_EQUAL(int(Status::ok), int(bus->set_filters(only_hb)));
  peer_send(0x181, {1, 2});
  peer_send(0x705, {0x05});
  CanFrame f;
  LONGS_EQUAL(int(Status::ok), int(bus->receive(f, clock.now() + 50 * kMillisecond)));
  UNSIGNED_LONGS_EQUAL(0x705, f.id);
}

TEST(SocketCan, PeerGoneIsInterfaceDown) {
  close(sv[1]);
  sv[1] = -1;
  CanFrame f;
  LONGS_EQUAL(int(Status::interface_down), int(bus->receive(f, clock.now() + 50 * kMillisecond)));
  CHECK(std::strlen(bus->message()) > 0);
  CHECK(bus->is_down());
  LONGS_EQUAL(int(Status::interface_down), int(bus->receive(f, 0)));
  UNSIGNED_LONGS_EQUAL(1, bus->interface_downs());  // one episode, counted once
  STRCMP_CONTAINS("peer closed", bus->down_reason());
  // An adopted fd has no interface name to reopen: reported, never "reopened".
  CHECK_FALSE(bus->reopen_pending());
  UNSIGNED_LONGS_EQUAL(0, bus->stats().reopens);
}

TEST(SocketCan, OddSizedRecordIgnored) {
  const char junk[5] = {1, 2, 3, 4, 5};
  CHECK(write(sv[1], junk, sizeof junk) == 5);
  peer_send(0x123, {7});
  CanFrame f;
  LONGS_EQUAL(int(Status::ok), int(bus->receive(f, clock.now() + 50 * kMillisecond)));
  UNSIGNED_LONGS_EQUAL(0x123, f.id);
}

TEST(SocketCan, NoAllocationInSendReceive) {
  CanFrame f;
  std::size_t allocs = 0;
  for (int i = 0; i < 100; ++i) {
    servoarm::test::AllocScope scope;
    bus->send(CanFrame::make(0x201, {0x0F, 0, 1, 2, 3, 4}));
    peer_send(0x181, {0x27, 0x06, 1, 2, 3, 4});
    bus->receive(f, 0);
    bus->receive(f, 0);  // nothing left: timeout path
    allocs += scope.end();
    can_frame k;
    CHECK(read(sv[1], &k, sizeof k) == ssize_t(sizeof k));
  }
  LONGS_EQUAL(0, allocs);
}

TEST(SocketCan, CanFdRecordsBothWays) {
  CanFrame fd;
  fd.id = 0x123;
  fd.fd = true;
  fd.brs = true;
  fd.len = 64;
  for (int i = 0; i < 64; ++i) fd.data[std::size_t(i)] = std::uint8_t(i);
  LONGS_EQUAL(int(Status::ok), int(bus->send(fd)));
  canfd_frame k;
  LONGS_EQUAL(sizeof(canfd_frame), read(sv[1], &k, sizeof k));  // 72-byte record
  UNSIGNED_LONGS_EQUAL(0x123, k.can_id);
  LONGS_EQUAL(64, k.len);
  CHECK(k.flags & CANFD_BRS);
  BYTES_EQUAL(63, k.data[63]);
  // Incoming FD record.
  std::memset(&k, 0, sizeof k);
  k.can_id = 0x456;
  k.len = 12;
  k.data[11] = 0xEE;
  CHECK(write(sv[1], &k, sizeof k) == ssize_t(sizeof k));
  CanFrame f;
  LONGS_EQUAL(int(Status::ok), int(bus->receive(f, 0)));
  CHECK(f.fd);
  LONGS_EQUAL(12, f.len);
  BYTES_EQUAL(0xEE, f.data[11]);
}

TEST_GROUP(SocketCanOpen){};

TEST(SocketCanOpen, BadNamesAndMissingKernelSupport) {
  SocketCanBus b;
  LONGS_EQUAL(int(Status::invalid_argument), int(b.open("")));
  LONGS_EQUAL(int(Status::invalid_argument), int(b.open("a_very_long_interface_name0")));  // > IFNAMSIZ-1
  STRCMP_CONTAINS("too long", b.message());
  // On a kernel without CAN, socket() fails: io_error with the errno text; on a
  // kernel with CAN, an unknown interface is interface_down. Never ok, never a crash.
  const Status s = b.open("nosuchcan7");
  CHECK(s == Status::io_error || s == Status::interface_down);
  CHECK(std::strlen(b.message()) > 0);
  CHECK_FALSE(b.is_open());
  LONGS_EQUAL(int(Status::not_open), int(b.send(CanFrame::make(1, {}))));
}
