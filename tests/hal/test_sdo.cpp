// SPDX-License-Identifier: Apache-2.0
// SDO client against the virtual drive's SDO server (and a hand-rolled bad server).
#include <cstring>
#include <string>

#include "servoarm/hal/canopen.hpp"
#include "servoarm/hal/sdo_client.hpp"
#include "sim_fixture.hpp"

// CppUTest last: its leak detector redefines `new`.
#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::hal;
using namespace servoarm::hal::canopen;

TEST_GROUP(Sdo) {
  test::SimRig* rig = nullptr;
  SdoClient* sdo = nullptr;
  void setup() override {
    rig = new test::SimRig({3});
    sdo = new SdoClient(*rig->master_ep, rig->clock, 50 * kMillisecond);
  }
  void teardown() override {
    delete sdo;
    delete rig;
  }
};

TEST(Sdo, ExpeditedUploadDeviceType) {
  std::uint32_t v = 0;
  SdoResult r = sdo->read_u32(3, 0x1000, 0, v);
  LONGS_EQUAL(int(Status::ok), int(r.status));
  UNSIGNED_LONGS_EQUAL(0x00020192, v);
  LONGS_EQUAL(4, r.size);
}

TEST(Sdo, ExpeditedDownloadSizes) {
  LONGS_EQUAL(int(Status::ok), int(sdo->write_u16(3, 0x1017, 0, 250).status));
  LONGS_EQUAL(int(Status::ok), int(sdo->write_u8(3, 0x6060, 0, 8).status));
  LONGS_EQUAL(int(Status::ok), int(sdo->write_u32(3, 0x607A, 0, 0xFFFFFFF6u).status));
  std::uint32_t v = 0;
  sdo->read_u32(3, 0x1017, 0, v);
  UNSIGNED_LONGS_EQUAL(250, v);
  sdo->read_u32(3, 0x6061, 0, v);  // modes display follows 0x6060
  UNSIGNED_LONGS_EQUAL(8, v);
  CHECK(rig->sim->node(3)->od_read(0x607A, 0, v));
  UNSIGNED_LONGS_EQUAL(0xFFFFFFF6u, v);
}

TEST(Sdo, SegmentedUploadOfDeviceName) {
  std::uint8_t buf[64] = {};
  SdoResult r = sdo->upload(3, 0x1008, 0, buf, sizeof buf);
  LONGS_EQUAL(int(Status::ok), int(r.status));
  STRCMP_EQUAL("servoarm virtual drive 3", std::string(reinterpret_cast<char*>(buf), r.size).c_str());
  // Frames on the wire: initiate 0x40, response 0x41 + size 24, then 4 segments (7+7+7+3).
  auto frames = rig->capture();
  int requests = 0, segments = 0;
  for (auto& f : frames) {
    if (f.id == 0x603 && (f.data[0] & 0xEF) == 0x60) ++requests;
    if (f.id == 0x583 && sdo::cs_of(f.data[0]) == 0) ++segments;
  }
  LONGS_EQUAL(4, requests);
  LONGS_EQUAL(4, segments);
}

TEST(Sdo, SegmentedDownloadRoundTripAtBoundaries) {
  for (std::size_t len : {5u, 7u, 8u, 14u, 15u, 32u}) {
    std::uint8_t data[32];
    for (std::size_t i = 0; i < len; ++i) data[i] = std::uint8_t(0xA0 + i);
    SdoResult w = sdo->download(3, 0x2000, 0, data, len);
    LONGS_EQUAL_TEXT(int(Status::ok), int(w.status), std::to_string(len).c_str());
    std::uint8_t back[64] = {};
    SdoResult r = sdo->upload(3, 0x2000, 0, back, sizeof back);
    LONGS_EQUAL(int(Status::ok), int(r.status));
    LONGS_EQUAL(len, r.size);
    MEMCMP_EQUAL(data, back, len);
  }
}

TEST(Sdo, ServerAbortsDecoded) {
  struct Case {
    std::uint16_t index;
    std::uint8_t sub;
    bool write;
    std::uint32_t code;
  } cases[] = {
      {0x5555, 0, false, 0x06020000},  // no object
      {0x1018, 7, false, 0x06090011},  // no sub-index
      {0x6041, 0, true, 0x06010002},   // read-only
      {0x6060, 0, true, 0x06090030},   // only CSP (8) supported
  };
  for (auto& c : cases) {
    SdoResult r;
    std::uint32_t v = 0;
    if (c.write) r = sdo->write_u8(3, c.index, c.sub, 3);
    else r = sdo->read_u32(3, c.index, c.sub, v);
    LONGS_EQUAL(int(Status::sdo_abort), int(r.status));
    UNSIGNED_LONGS_EQUAL(c.code, r.abort_code);
  }
  std::uint8_t big[40] = {};
  SdoResult r = sdo->download(3, 0x2000, 0, big, sizeof big);  // domain holds 32
  LONGS_EQUAL(int(Status::sdo_abort), int(r.status));
  UNSIGNED_LONGS_EQUAL(sdo::kAbortTooLong, r.abort_code);
  STRCMP_EQUAL("data type does not match, length of service parameter too high", sdo::abort_text(r.abort_code));
}

TEST(Sdo, PdoMappingValidatedLikeADrive) {
  // Mapping while the PDO is valid: refused.
  SdoResult r = sdo->write_u32(3, 0x1600, 1, 0x60400010);
  UNSIGNED_LONGS_EQUAL(0, r.abort_code);  // sub 0 is 0, PDO invalid by default: accepted
  LONGS_EQUAL(int(Status::ok), int(sdo->write_u32(3, 0x1600, 2, 0x607A0020).status));
  LONGS_EQUAL(int(Status::ok), int(sdo->write_u32(3, 0x1600, 3, 0x60FF0020).status));  // entry itself not checked yet
  r = sdo->write_u8(3, 0x1600, 0, 3);  // 0x60FF does not exist
  UNSIGNED_LONGS_EQUAL(sdo::kAbortNotMappable, r.abort_code);
  LONGS_EQUAL(int(Status::ok), int(sdo->write_u32(3, 0x1600, 3, 0x607A0020).status));
  LONGS_EQUAL(int(Status::ok), int(sdo->write_u32(3, 0x1600, 4, 0x607A0020).status));
  r = sdo->write_u8(3, 0x1600, 0, 4);  // 16 + 32 * 3 = 112 bits > 64
  UNSIGNED_LONGS_EQUAL(sdo::kAbortPdoLength, r.abort_code);
  LONGS_EQUAL(int(Status::ok), int(sdo->write_u8(3, 0x1600, 0, 2).status));
  r = sdo->write_u32(3, 0x1600, 1, 0x60400010);  // count != 0: entries locked
  UNSIGNED_LONGS_EQUAL(sdo::kAbortDeviceState, r.abort_code);
  LONGS_EQUAL(int(Status::ok), int(sdo->write_u32(3, 0x1400, 1, 0x203).status));  // enable RPDO1
  r = sdo->write_u8(3, 0x1600, 0, 0);  // PDO valid: mapping locked
  UNSIGNED_LONGS_EQUAL(sdo::kAbortDeviceState, r.abort_code);
  r = sdo->write_u32(3, 0x1A00, 1, 0x10170010);  // heartbeat time is not mappable
  UNSIGNED_LONGS_EQUAL(0, r.abort_code);
  r = sdo->write_u8(3, 0x1A00, 0, 1);
  UNSIGNED_LONGS_EQUAL(sdo::kAbortNotMappable, r.abort_code);
}

TEST(Sdo, TimeoutSendsAbortAndReturnsAfterTimeout) {
  rig->sim->node(3)->faults().silent = true;
  const TimePoint t0 = rig->clock.now();
  std::uint32_t v;
  SdoResult r = sdo->read_u32(3, 0x1000, 0, v);
  LONGS_EQUAL(int(Status::timeout), int(r.status));
  UNSIGNED_LONGS_EQUAL(sdo::kAbortTimeout, r.abort_code);
  const Duration waited = rig->clock.now() - t0;
  CHECK(waited >= 50 * kMillisecond && waited <= 51 * kMillisecond);
  auto frames = rig->capture();
  bool abort_seen = false;
  for (auto& f : frames)
    if (f.id == 0x603 && f.data[0] == 0x80 && get_u16(&f.data[1]) == 0x1000 && get_u32(&f.data[4]) == 0x05040000)
      abort_seen = true;
  CHECK(abort_seen);
}

TEST(Sdo, BadNodeAndUploadTooLarge) {
  std::uint8_t small[8];
  SdoResult r = sdo->upload(3, 0x1008, 0, small, sizeof small);  // 24 bytes into 8
  LONGS_EQUAL(int(Status::sdo_abort), int(r.status));
  UNSIGNED_LONGS_EQUAL(sdo::kAbortOutOfMemory, r.abort_code);
  LONGS_EQUAL(int(Status::invalid_argument), int(sdo->write_u8(0, 0x1000, 0, 1).status));
  LONGS_EQUAL(int(Status::invalid_argument), int(sdo->write_u8(128, 0x1000, 0, 1).status));
}

// A hand-rolled server that answers a segmented upload with a wrong toggle bit.
TEST_GROUP(SdoBadServer){};

TEST(SdoBadServer, ToggleErrorAborts) {
  ManualClock clock;
  SimBus bus(clock);
  auto client_ep = bus.open(64);
  auto server_ep = bus.open(64);
  clock.set_idle_hook([&](TimePoint) {
    CanFrame f;
    while (server_ep->receive(f, 0) == Status::ok) {
      if (f.id != 0x605) continue;
      if (f.data[0] == 0x40) {
        const std::uint8_t d[10] = {};
        server_ep->send(sdo::upload_response(5, 0x1008, 0, d, 10));
      } else if ((f.data[0] & 0xE0) == 0x60) {
        const std::uint8_t d[7] = {1, 2, 3, 4, 5, 6, 7};
        server_ep->send(sdo::upload_segment(5, true /* should be false */, d, 7, false));
      }
    }
  });
  SdoClient c(*client_ep, clock, 20 * kMillisecond);
  std::uint8_t buf[16];
  SdoResult r = c.upload(5, 0x1008, 0, buf, sizeof buf);
  LONGS_EQUAL(int(Status::protocol_error), int(r.status));
  UNSIGNED_LONGS_EQUAL(sdo::kAbortToggle, r.abort_code);
  clock.set_idle_hook(nullptr);
}

// A slow drive answers an earlier, timed-out request late: before each answer the
// server sends an initiate response and an abort naming another object. Both are
// skipped (the blocking client and the non-blocking transfer), not taken as the
// answer; an answer of the wrong kind for the right object still fails.
TEST(SdoBadServer, LateAnswersToEarlierRequestsAreSkipped) {
  ManualClock clock;
  SimBus bus(clock);
  auto client_ep = bus.open(64);
  auto server_ep = bus.open(64);
  bool wrong_kind = false;
  auto serve = [&] {
    CanFrame f;
    while (server_ep->receive(f, 0) == Status::ok) {
      if (f.id != 0x605 || f.data[0] == 0x80) continue;  // the client's aborts need no answer
      const std::uint8_t d[4] = {0x2A, 0, 0, 0};
      server_ep->send(sdo::upload_response(5, 0x1017, 0, d, 2));      // late: another object
      server_ep->send(sdo::abort(5, true, 0x1A01, 1, 0x06040041));    // late: another object
      const std::uint16_t index = std::uint16_t(f.data[1] | (f.data[2] << 8));
      if (f.data[0] == 0x40) {
        server_ep->send(sdo::upload_response(5, index, f.data[3], d, 4));
      } else if (wrong_kind) {
        server_ep->send(sdo::upload_response(5, index, f.data[3], d, 4));  // an upload answer to a download
      } else {
        server_ep->send(sdo::download_response(5, index, f.data[3]));
      }
    }
  };
  clock.set_idle_hook([&](TimePoint) { serve(); });
  SdoClient c(*client_ep, clock, 20 * kMillisecond);
  std::uint32_t v = 0;
  LONGS_EQUAL(int(Status::ok), int(c.read_u32(5, 0x6041, 0, v).status));
  UNSIGNED_LONGS_EQUAL(0x2A, v);
  LONGS_EQUAL(int(Status::ok), int(c.write_u8(5, 0x6060, 0, 6).status));
  wrong_kind = true;
  LONGS_EQUAL(int(Status::protocol_error), int(c.write_u8(5, 0x6060, 0, 8).status));
  wrong_kind = false;
  clock.set_idle_hook(nullptr);

  CanFrame f;
  serve();
  while (client_ep->receive(f, 0) == Status::ok) {
  }  // what the failed write left
  SdoTransfer t;
  LONGS_EQUAL(int(Status::ok), int(t.begin_write(*client_ep, 5, 0x6098, 0, 1, 19, clock.now(), 20 * kMillisecond)));
  serve();
  int answers = 0;
  while (client_ep->receive(f, 0) == Status::ok) answers += t.on_frame(f) ? 1 : 0;
  LONGS_EQUAL(3, answers);  // the two late ones consumed, then the answer
  CHECK(t.done());
  LONGS_EQUAL(int(Status::ok), int(t.result()));
}

// Quick stop objects of the virtual drive (CiA 402): 605Ah option code (the
// codes the model implements) and 6085h deceleration (non-zero), readable back.
TEST(Sdo, QuickStopObjectsValidatedLikeADrive) {
  std::uint32_t v = 0;
  LONGS_EQUAL(int(Status::ok), int(sdo->read_u32(3, 0x6085, 0, v).status));
  UNSIGNED_LONGS_EQUAL(400u * 131072u, v);  // default: the motor's acceleration limit
  LONGS_EQUAL(int(Status::ok), int(sdo->write_u32(3, 0x6085, 0, 65536).status));
  LONGS_EQUAL(int(Status::ok), int(sdo->read_u32(3, 0x6085, 0, v).status));
  UNSIGNED_LONGS_EQUAL(65536u, v);
  SdoResult r = sdo->write_u32(3, 0x6085, 0, 0);
  UNSIGNED_LONGS_EQUAL(sdo::kAbortValueRange, r.abort_code);
  for (int code : {0, 1, 2, 5, 6}) {
    r = sdo->write_u16(3, 0x605A, 0, std::uint16_t(code));
    LONGS_EQUAL_TEXT(int(Status::ok), int(r.status), std::to_string(code).c_str());
  }
  for (int code : {3, 4, 7, -1}) {
    r = sdo->write_u16(3, 0x605A, 0, std::uint16_t(std::int16_t(code)));
    UNSIGNED_LONGS_EQUAL_TEXT(sdo::kAbortValueRange, r.abort_code, std::to_string(code).c_str());
  }
  LONGS_EQUAL(int(Status::ok), int(sdo->read_u32(3, 0x605A, 0, v).status));
  UNSIGNED_LONGS_EQUAL(6u, v);  // the last accepted value
}
