// SPDX-License-Identifier: Apache-2.0
// ISO-TP (ISO 15765-2) endpoint over the in-process SimBus with a ManualClock.
//
// 1. Byte layouts written out by hand from ISO 15765-2 (single / first /
//    consecutive / flow-control frames, sequence-number wrap, padding, the
//    flow control we send, STmin pacing and block size).
// 2. Malformed input (bad PCI, short frames, wrong sequence number, overflow,
//    reserved flow status, WAIT overrun, timeouts N_Bs / N_Cr) -> an error
//    result, no crash, and the endpoint works again afterwards.
// 3. A seeded random sweep of message lengths 1..4095 between two endpoints,
//    both directions at once, random block sizes / STmin / padding.
// The independent reference for interoperability is the kernel's can-isotp
// (can-utils isotpsend / isotprecv), in tests/vcan/s5_can_console.sh.
#include <cstdio>
#include <cstring>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "servoarm/hal/isotp.hpp"
#include "servoarm/hal/sim_bus.hpp"

// CppUTest last: its leak detector redefines `new`.
#include <CppUTest/TestHarness.h>

using namespace servoarm::hal;

namespace {

std::string hex(const CanFrame& f) {
  std::string s;
  char b[4];
  std::snprintf(b, sizeof b, "%03X", unsigned(f.id));
  s = b;
  s += "#";
  for (int i = 0; i < f.len; ++i) {
    std::snprintf(b, sizeof b, "%02X", f.data[std::size_t(i)]);
    s += b;
  }
  return s;
}

CanFrame raw(std::uint32_t id, std::initializer_list<std::uint8_t> bytes) { return CanFrame::make(id, bytes); }

std::vector<std::uint8_t> counting(std::size_t n, std::uint8_t start = 0) {
  std::vector<std::uint8_t> v(n);
  for (std::size_t i = 0; i < n; ++i) v[i] = std::uint8_t(start + i);
  return v;
}

// A device endpoint `dev` (tx 0x7E8, rx 0x7E0) and a spy endpoint on the same
// bus that records everything and can inject raw frames as the peer.
struct Rig {
  ManualClock clock;
  std::unique_ptr<SimBus> bus;
  std::unique_ptr<SimBusEndpoint> dev_ep, spy;
  std::unique_ptr<IsoTpEndpoint> dev;
  IsoTpEvent last;  // last non-empty event of dev

  explicit Rig(const IsoTpConfig& cfg = {}) {
    bus = std::make_unique<SimBus>(clock);
    dev_ep = bus->open(8192);
    spy = bus->open(8192);
    dev = std::make_unique<IsoTpEndpoint>(*dev_ep, clock, cfg);
  }
  ~Rig() {
    dev.reset();
    dev_ep.reset();
    spy.reset();
  }
  // Frames the device sent since the last call.
  std::vector<std::string> sent() {
    std::vector<std::string> out;
    CanFrame f;
    while (spy->receive(f, 0) == Status::ok) out.push_back(hex(f));
    return out;
  }
  // Peer sends a raw frame; the device handles everything pending.
  IsoTpEvent inject(const CanFrame& f) {
    CHECK(spy->send(f) == Status::ok);
    return drain();
  }
  IsoTpEvent drain() {
    IsoTpEvent acc;
    CanFrame f;
    while (dev_ep->receive(f, 0) == Status::ok) {
      const IsoTpEvent e = dev->on_frame(f);
      if (e.rx != IsoTpResult::none) acc.rx = e.rx;
      if (e.tx != IsoTpResult::none) acc.tx = e.tx;
    }
    const IsoTpEvent e = dev->poll();
    if (e.rx != IsoTpResult::none) acc.rx = e.rx;
    if (e.tx != IsoTpResult::none) acc.tx = e.tx;
    if (acc.any()) last = acc;
    return acc;
  }
};

void check_frames(const std::vector<std::string>& want, const std::vector<std::string>& got, const char* what) {
  std::string w, g;
  for (const auto& s : want) w += s + " ";
  for (const auto& s : got) g += s + " ";
  STRCMP_EQUAL_TEXT(w.c_str(), g.c_str(), what);
}

}  // namespace

TEST_GROUP(IsoTpLayout){};

// Transmit side: the frames for messages of several lengths, hand-written from
// ISO 15765-2 (normal addressing, classic CAN, TX_DL = 8), with and without padding.
TEST(IsoTpLayout, TransmitTable) {
  struct Case {
    const char* what;
    std::size_t len;
    bool padding;
    const char* fc;  // peer's flow control after the FF ("" = none needed)
    std::vector<std::string> frames;
  } cases[] = {
      {"1 byte SF", 1, false, "", {"7E8#0100"}},
      {"7 byte SF", 7, false, "", {"7E8#0700010203040506"}},
      {"1 byte SF padded", 1, true, "", {"7E8#0100CCCCCCCCCCCC"}},
      {"8 bytes: FF + short last CF", 8, false, "300000", {"7E8#1008000102030405", "7E8#210607"}},
      {"8 bytes padded", 8, true, "300000", {"7E8#1008000102030405", "7E8#210607CCCCCCCCCC"}},
      {"13 bytes: FF + one full CF", 13, false, "300000", {"7E8#100D000102030405", "7E8#21060708090A0B0C"}},
      {"20 bytes: SN 1, 2", 20, false, "300000",
       {"7E8#1014000102030405", "7E8#21060708090A0B0C", "7E8#220D0E0F10111213"}},
  };
  for (const Case& c : cases) {
    IsoTpConfig cfg;
    cfg.padding = c.padding;
    Rig r(cfg);
    const auto msg = counting(c.len);
    CHECK_TEXT(r.dev->send(msg) == IsoTpResult::ok, c.what);
    std::vector<std::string> got = r.sent();
    if (c.fc[0] != '\0') {
      CHECK_TEXT(r.dev->sending(), c.what);
      CanFrame fc = raw(0x7E0, {0x30, 0x00, 0x00});
      const IsoTpEvent e = r.inject(fc);
      CHECK_TEXT(e.tx == IsoTpResult::ok, c.what);
      for (auto& s : r.sent()) got.push_back(s);
    }
    CHECK_FALSE_TEXT(r.dev->sending(), c.what);
    check_frames(c.frames, got, c.what);
  }
}

TEST(IsoTpLayout, FirstFrameOf4095AndSequenceWrap) {
  Rig r;
  const auto msg = counting(4095);
  CHECK(r.dev->send(msg) == IsoTpResult::ok);
  std::vector<std::string> got = r.sent();
  STRCMP_EQUAL("7E8#1FFF000102030405", got.at(0).c_str());
  r.inject(raw(0x7E0, {0x30, 0x00, 0x00}));
  for (auto& s : r.sent()) got.push_back(s);
  // 1 FF + ceil((4095 - 6) / 7) = 585 CFs; CF k has SN k mod 16: the 15th is 0x2F, the 16th 0x20.
  LONGS_EQUAL(1 + 585, got.size());
  STRCMP_EQUAL("7E8#2F", got[15].substr(0, 6).c_str());
  STRCMP_EQUAL("7E8#20", got[16].substr(0, 6).c_str());
  STRCMP_EQUAL("7E8#21", got[17].substr(0, 6).c_str());
  // last CF: (4095 - 6) mod 7 = 1 data byte, no padding -> 2 bytes; 4094 & 0xFF = 0xFE
  STRCMP_EQUAL("7E8#29FE", got.back().c_str());
  CHECK(r.last.tx == IsoTpResult::ok);
}

// Receive side: the flow control we answer a first frame with (BS, STmin from
// the config), and again after every block.
TEST(IsoTpLayout, ReceiveWithBlockSize) {
  IsoTpConfig cfg;
  cfg.block_size = 2;
  cfg.st_min = 0x0A;
  Rig r(cfg);
  // 30-byte message: FF (6) + CF 7,7,7,3
  IsoTpEvent e = r.inject(raw(0x7E0, {0x10, 30, 'a', 'b', 'c', 'd', 'e', 'f'}));
  CHECK(e.rx == IsoTpResult::none);
  check_frames({"7E8#30020A"}, r.sent(), "FC after FF");
  r.inject(raw(0x7E0, {0x21, 'g', 'h', 'i', 'j', 'k', 'l', 'm'}));
  check_frames({}, r.sent(), "no FC inside a block");
  r.inject(raw(0x7E0, {0x22, 'n', 'o', 'p', 'q', 'r', 's', 't'}));
  check_frames({"7E8#30020A"}, r.sent(), "FC after a block of 2");
  r.inject(raw(0x7E0, {0x23, 'u', 'v', 'w', 'x', 'y', 'z', '0'}));
  e = r.inject(raw(0x7E0, {0x24, '1', '2', '3'}));
  CHECK(e.rx == IsoTpResult::ok);
  const auto m = r.dev->rx_message();
  STRCMP_EQUAL("abcdefghijklmnopqrstuvwxyz0123", std::string(m.begin(), m.end()).c_str());
  check_frames({}, r.sent(), "no FC after the last CF");
}

TEST(IsoTpLayout, PaddedFlowControlAndSingleFramePadding) {
  IsoTpConfig cfg;
  cfg.padding = true;
  cfg.pad_byte = 0xAA;
  Rig r(cfg);
  r.inject(raw(0x7E0, {0x10, 0x09, 1, 2, 3, 4, 5, 6}));
  check_frames({"7E8#300000AAAAAAAAAA"}, r.sent(), "padded FC");
  // a padded last CF from the peer: only 3 bytes are data
  const IsoTpEvent e = r.inject(raw(0x7E0, {0x21, 7, 8, 9, 0x55, 0x55, 0x55, 0x55}));
  CHECK(e.rx == IsoTpResult::ok);
  LONGS_EQUAL(9, r.dev->rx_message().size());
  BYTES_EQUAL(9, r.dev->rx_message()[8]);
  // a padded SF from the peer
  const IsoTpEvent e2 = r.inject(raw(0x7E0, {0x02, 'o', 'k', 0x55, 0x55, 0x55, 0x55, 0x55}));
  CHECK(e2.rx == IsoTpResult::ok);
  LONGS_EQUAL(2, r.dev->rx_message().size());
}

TEST(IsoTpLayout, StMinTable) {
  struct {
    std::uint8_t st;
    Duration ns;
  } cases[] = {{0x00, 0}, {0x01, kMillisecond}, {0x7F, 127 * kMillisecond}, {0x80, 127 * kMillisecond},
               {0xF0, 127 * kMillisecond}, {0xF1, 100 * kMicrosecond}, {0xF9, 900 * kMicrosecond},
               {0xFA, 127 * kMillisecond}, {0xFF, 127 * kMillisecond}};
  for (const auto& c : cases) {
    char msg[32];
    std::snprintf(msg, sizeof msg, "STmin 0x%02X", c.st);
    CHECK_EQUAL_TEXT(c.ns, IsoTpEndpoint::st_min_ns(c.st), msg);
  }
}

// The peer asks for STmin 5 ms and BS 3: CFs are 5 ms apart, 3 per block.
TEST(IsoTpLayout, TransmitPacingStMinAndBlockSize) {
  Rig r;
  const auto msg = counting(6 + 7 * 5);  // FF + 5 CFs
  CHECK(r.dev->send(msg) == IsoTpResult::ok);
  r.sent();
  r.inject(raw(0x7E0, {0x30, 3, 5}));
  std::vector<TimePoint> times;
  CanFrame f;
  const TimePoint t0 = r.clock.now();
  for (int i = 0; i < 100 && times.size() < 3; ++i) {
    r.drain();
    while (r.spy->receive(f, 0) == Status::ok) times.push_back(r.clock.now());
    r.clock.advance(kMillisecond);
  }
  LONGS_EQUAL(3, times.size());
  CHECK(times[0] == t0);
  CHECK(times[1] - times[0] >= 5 * kMillisecond);
  CHECK(times[2] - times[1] >= 5 * kMillisecond);
  // block of 3 done: nothing more until the next FC
  for (int i = 0; i < 20; ++i) {
    r.clock.advance(kMillisecond);
    r.drain();
  }
  check_frames({}, r.sent(), "waits for FC after a block");
  CHECK(r.dev->sending());
  r.inject(raw(0x7E0, {0x30, 0, 0}));
  LONGS_EQUAL(2, r.sent().size());
  CHECK(r.last.tx == IsoTpResult::ok);
}

TEST_GROUP(IsoTpErrors){};

TEST(IsoTpErrors, MalformedFramesAreIgnoredAndReported) {
  Rig r;
  struct {
    const char* what;
    CanFrame f;
  } cases[] = {
      {"PCI type 4", raw(0x7E0, {0x40, 1, 2})},
      {"PCI type 0xF", raw(0x7E0, {0xF1, 1})},
      {"empty frame", raw(0x7E0, {})},
      {"SF_DL 0", raw(0x7E0, {0x00, 1, 2})},
      {"SF_DL 8 (classic)", raw(0x7E0, {0x08, 1, 2, 3, 4, 5, 6, 7})},
      {"SF_DL longer than the frame", raw(0x7E0, {0x05, 1, 2})},
      {"FF shorter than 8 bytes", raw(0x7E0, {0x10, 0x20, 1, 2})},
      {"FF_DL 7 (fits a SF)", raw(0x7E0, {0x10, 0x07, 1, 2, 3, 4, 5, 6})},
      {"FF escape with a small length", raw(0x7E0, {0x10, 0x00, 0, 0, 0x01, 0x00, 1, 2})},
  };
  std::uint64_t ignored = 0;
  for (const auto& c : cases) {
    const IsoTpEvent e = r.inject(c.f);
    CHECK_TEXT(e.rx == IsoTpResult::malformed, c.what);
    ++ignored;
    CHECK_EQUAL_TEXT(ignored, r.dev->stats().ignored, c.what);
    CHECK_FALSE_TEXT(r.dev->receiving(), c.what);
    check_frames({}, r.sent(), c.what);
  }
  // other ids, RTR, error frames: not ours, silently ignored
  CHECK_FALSE(r.inject(raw(0x7E1, {0x01, 'x'})).any());
  CanFrame ext = raw(0x7E0, {0x01, 'x'});
  ext.extended = true;
  CHECK_FALSE(r.inject(ext).any());
  // still works
  CHECK(r.inject(raw(0x7E0, {0x03, 'a', 'b', 'c'})).rx == IsoTpResult::ok);
  LONGS_EQUAL(3, r.dev->rx_message().size());
}

TEST(IsoTpErrors, WrongSequenceNumberAbortsTheReception) {
  Rig r;
  r.inject(raw(0x7E0, {0x10, 20, 1, 2, 3, 4, 5, 6}));
  r.sent();
  CHECK(r.dev->receiving());
  const IsoTpEvent e = r.inject(raw(0x7E0, {0x22, 7, 8, 9, 10, 11, 12, 13}));  // want SN 1
  CHECK(e.rx == IsoTpResult::wrong_sn);
  CHECK_FALSE(r.dev->receiving());
  LONGS_EQUAL(1, r.dev->stats().rx_errors);
  // a CF now (no reception) is ignored without an event, as ISO says
  CHECK_FALSE(r.inject(raw(0x7E0, {0x21, 7, 8, 9, 10, 11, 12, 13})).any());
  // the next message is received
  r.inject(raw(0x7E0, {0x10, 8, 1, 2, 3, 4, 5, 6}));
  CHECK(r.inject(raw(0x7E0, {0x21, 7, 8})).rx == IsoTpResult::ok);
  LONGS_EQUAL(8, r.dev->rx_message().size());
}

TEST(IsoTpErrors, OverflowAnswersFlowStatusOverflow) {
  IsoTpConfig cfg;
  cfg.rx_limit = 100;
  Rig r(cfg);
  IsoTpEvent e = r.inject(raw(0x7E0, {0x10, 101, 1, 2, 3, 4, 5, 6}));
  CHECK(e.rx == IsoTpResult::buffer_overflow);
  check_frames({"7E8#320000"}, r.sent(), "FC overflow for 101 > rx_limit");
  // escape sequence: 32-bit FF_DL 5000 > 4095
  e = r.inject(raw(0x7E0, {0x10, 0x00, 0x00, 0x00, 0x13, 0x88, 1, 2}));
  CHECK(e.rx == IsoTpResult::buffer_overflow);
  check_frames({"7E8#320000"}, r.sent(), "FC overflow for an escaped 5000");
  CHECK_FALSE(r.dev->receiving());
  // 100 fits
  e = r.inject(raw(0x7E0, {0x10, 100, 1, 2, 3, 4, 5, 6}));
  check_frames({"7E8#300000"}, r.sent(), "CTS for 100");
}

TEST(IsoTpErrors, NewMessageInterruptsAReception) {
  Rig r;
  r.inject(raw(0x7E0, {0x10, 20, 1, 2, 3, 4, 5, 6}));
  const IsoTpEvent e = r.inject(raw(0x7E0, {0x02, 'h', 'i'}));
  CHECK(e.rx == IsoTpResult::ok);  // the new SF is delivered; the old one counted as an error
  LONGS_EQUAL(2, r.dev->rx_message().size());
  LONGS_EQUAL(1, r.dev->stats().rx_errors);
}

TEST(IsoTpErrors, FlowControlErrorsEndTheTransmission) {
  struct {
    const char* what;
    CanFrame fc;
    IsoTpResult want;
  } cases[] = {
      {"FS overflow", raw(0x7E0, {0x32, 0, 0}), IsoTpResult::buffer_overflow},
      {"FS reserved 3", raw(0x7E0, {0x33, 0, 0}), IsoTpResult::invalid_fs},
      {"FS reserved 0xF", raw(0x7E0, {0x3F, 0, 0}), IsoTpResult::invalid_fs},
  };
  for (const auto& c : cases) {
    Rig r;
    CHECK_TEXT(r.dev->send(counting(30)) == IsoTpResult::ok, c.what);
    const IsoTpEvent e = r.inject(c.fc);
    CHECK_TEXT(e.tx == c.want, c.what);
    CHECK_FALSE_TEXT(r.dev->sending(), c.what);
    LONGS_EQUAL_TEXT(1, r.dev->stats().tx_errors, c.what);
    LONGS_EQUAL_TEXT(1, r.sent().size(), c.what);  // the FF only
  }
  // a short FC is malformed and ignored: still waiting
  Rig r;
  r.dev->send(counting(30));
  CHECK(r.inject(raw(0x7E0, {0x30, 0})).tx == IsoTpResult::malformed);
  CHECK(r.dev->sending());
}

TEST(IsoTpErrors, WaitFramesUpToMaxWft) {
  IsoTpConfig cfg;
  cfg.max_wft = 3;
  Rig r(cfg);
  r.dev->send(counting(30));
  for (int i = 0; i < 3; ++i) {
    r.clock.advance(900 * kMillisecond);  // each WAIT restarts N_Bs (1 s)
    CHECK(r.inject(raw(0x7E0, {0x31, 0, 0})).tx == IsoTpResult::none);
  }
  CHECK(r.inject(raw(0x7E0, {0x31, 0, 0})).tx == IsoTpResult::wft_ovrn);
  CHECK_FALSE(r.dev->sending());
}

TEST(IsoTpErrors, Timeouts) {
  Rig r;
  // N_Bs: FF sent, no FC
  r.dev->send(counting(30));
  r.clock.advance(999 * kMillisecond);
  CHECK(r.drain().tx == IsoTpResult::none);
  r.clock.advance(2 * kMillisecond);
  CHECK(r.drain().tx == IsoTpResult::timeout_bs);
  CHECK_FALSE(r.dev->sending());
  // N_Cr: FF received, CF never comes
  r.inject(raw(0x7E0, {0x10, 20, 1, 2, 3, 4, 5, 6}));
  r.clock.advance(500 * kMillisecond);
  r.inject(raw(0x7E0, {0x21, 7, 8, 9, 10, 11, 12, 13}));  // restarts N_Cr
  r.clock.advance(999 * kMillisecond);
  CHECK(r.drain().rx == IsoTpResult::none);
  r.clock.advance(2 * kMillisecond);
  CHECK(r.drain().rx == IsoTpResult::timeout_cr);
  CHECK_FALSE(r.dev->receiving());
  CHECK(r.dev->next_deadline() == IsoTpEndpoint::kNever);
}

TEST(IsoTpErrors, SendArgumentsAndBusErrors) {
  Rig r;
  CHECK(r.dev->send({}) == IsoTpResult::invalid_length);
  const auto big = counting(4096);
  CHECK(r.dev->send(big) == IsoTpResult::invalid_length);
  CHECK(r.dev->send(counting(100)) == IsoTpResult::ok);
  CHECK(r.dev->send(counting(3)) == IsoTpResult::busy);
  Rig r2;
  r2.bus->set_error_state(ErrorState::bus_off);
  CHECK(r2.dev->send(counting(3)) == IsoTpResult::bus_error);
  CHECK(r2.dev->send(counting(30)) == IsoTpResult::bus_error);
  CHECK(r2.dev->last_bus_status() == Status::bus_off);
  CHECK_FALSE(r2.dev->sending());
}

// Seeded random frames on the rx id: never a crash, never a message that was not
// sent as one; afterwards a clean message goes through.
TEST(IsoTpErrors, RandomGarbageSweep) {
  Rig r;
  std::mt19937 rng(20240607);
  for (int i = 0; i < 20000; ++i) {
    CanFrame f;
    f.id = 0x7E0;
    f.len = std::uint8_t(rng() % 9);
    for (int k = 0; k < f.len; ++k) f.data[std::size_t(k)] = std::uint8_t(rng());
    if (rng() % 4 == 0 && f.len > 0) f.data[0] = std::uint8_t((rng() % 4) << 4 | (f.data[0] & 0x0F));
    r.inject(f);
    if (rng() % 50 == 0) r.clock.advance(Duration(rng() % 1500) * kMillisecond);
    CHECK(r.dev->rx_message().size() <= IsoTpEndpoint::kMaxMessage);
  }
  r.sent();
  r.clock.advance(2 * kSecond);
  r.drain();
  CHECK_FALSE(r.dev->receiving());
  CHECK(r.inject(raw(0x7E0, {0x04, 'd', 'o', 'n', 'e'})).rx == IsoTpResult::ok);
  STRCMP_EQUAL("done", std::string(r.dev->rx_message().begin(), r.dev->rx_message().end()).c_str());
}

TEST_GROUP(IsoTpSweep){};

// Two endpoints (A: tx 0x7E0 rx 0x7E8, B the mirror) on one SimBus, messages
// in both directions at once, lengths 1..4095 (the edges and seeded random ones),
// random BS / STmin / padding per round. What arrives equals what was sent.
TEST(IsoTpSweep, RandomLengthsBothDirections) {
  std::mt19937 rng(15765);
  std::vector<std::size_t> lengths = {1, 2, 6, 7, 8, 13, 14, 15, 20, 111, 118, 119, 4088, 4094, 4095};
  for (int i = 0; i < 150; ++i) lengths.push_back(1 + rng() % 4095);
  ManualClock clock;
  SimBus bus(clock);
  auto ea = bus.open(8192), eb = bus.open(8192);
  int round = 0;
  std::uint64_t frames_a = 0, messages = 0;
  for (std::size_t len : lengths) {
    IsoTpConfig ca, cb;
    ca.tx_id = 0x7E0;
    ca.rx_id = 0x7E8;
    cb.tx_id = 0x7E8;
    cb.rx_id = 0x7E0;
    const std::uint8_t stmins[] = {0, 0, 1, 0xF3, 2};
    ca.block_size = std::uint8_t(rng() % 9);
    cb.block_size = std::uint8_t(rng() % 9);
    ca.st_min = stmins[rng() % 5];
    cb.st_min = stmins[rng() % 5];
    ca.padding = rng() % 2;
    cb.padding = rng() % 2;
    IsoTpEndpoint a(*ea, clock, ca), b(*eb, clock, cb);
    std::vector<std::uint8_t> ma(len), mb(1 + rng() % 4095);
    for (auto& x : ma) x = std::uint8_t(rng());
    for (auto& x : mb) x = std::uint8_t(rng());
    const std::uint64_t tx0 = ea->stats().tx_frames;
    CHECK(a.send(ma) == IsoTpResult::ok);
    CHECK(b.send(mb) == IsoTpResult::ok);
    bool got_a = false, got_b = false;  // got_a: A received B's message
    for (int step = 0; step < 100000 && !(got_a && got_b && !a.sending() && !b.sending()); ++step) {
      CanFrame f;
      while (ea->receive(f, 0) == Status::ok) {
        const IsoTpEvent e = a.on_frame(f);
        CHECK(e.rx != IsoTpResult::malformed && static_cast<int>(e.rx) >= 0 && static_cast<int>(e.tx) >= 0);
        if (e.rx == IsoTpResult::ok) {
          got_a = true;
          CHECK(a.rx_message().size() == mb.size() && std::memcmp(a.rx_message().data(), mb.data(), mb.size()) == 0);
        }
      }
      while (eb->receive(f, 0) == Status::ok) {
        const IsoTpEvent e = b.on_frame(f);
        CHECK(static_cast<int>(e.rx) >= 0 && static_cast<int>(e.tx) >= 0);
        if (e.rx == IsoTpResult::ok) {
          got_b = true;
          char msg[96];
          std::snprintf(msg, sizeof msg, "round %d: %zu bytes A->B (bs %u st 0x%02X pad %d)", round, len,
                        unsigned(cb.block_size), unsigned(cb.st_min), int(ca.padding));
          CHECK_TEXT(b.rx_message().size() == ma.size() && std::memcmp(b.rx_message().data(), ma.data(), len) == 0, msg);
        }
      }
      const IsoTpEvent pa = a.poll(), pb = b.poll();
      CHECK(static_cast<int>(pa.rx) >= 0 && static_cast<int>(pa.tx) >= 0);
      CHECK(static_cast<int>(pb.rx) >= 0 && static_cast<int>(pb.tx) >= 0);
      if (ea->pending() == 0 && eb->pending() == 0) {
        const TimePoint next = std::min(a.next_deadline(), b.next_deadline());
        if (next != IsoTpEndpoint::kNever && next > clock.now()) clock.sleep_until(next);
      }
    }
    char msg[64];
    std::snprintf(msg, sizeof msg, "round %d, %zu / %zu bytes", round, len, mb.size());
    CHECK_TEXT(got_a && got_b, msg);
    // frames A sent: its message (SF, or FF + CFs) and B's flow controls
    const std::uint64_t own = len <= 7 ? 1 : 1 + (len - 6 + 6) / 7;
    const std::uint64_t fcs = mb.size() <= 7 ? 0 : 1 + (ca.block_size ? ((mb.size() - 6 + 6) / 7 - 1) / ca.block_size : 0);
    CHECK_EQUAL_TEXT(own + fcs, ea->stats().tx_frames - tx0, msg);
    frames_a += ea->stats().tx_frames - tx0;
    messages += 2;
    ++round;
  }
  CHECK(messages == 2 * lengths.size());
  CHECK(frames_a > 0);
}
