// SPDX-License-Identifier: Apache-2.0
// CANopen frame codecs against byte layouts written out by hand from CiA 301 / CiA 402.
#include <cstdio>
#include <cstring>
#include <initializer_list>

#include "servoarm/hal/canopen.hpp"
#include "servoarm/hal/canopen_master.hpp"
#include "servoarm/hal/status.hpp"

// CppUTest last: its leak detector redefines `new`.
#include <CppUTest/TestHarness.h>

using namespace servoarm::hal;
using namespace servoarm::hal::canopen;

namespace {
void expect_frame(const CanFrame& f, std::uint32_t id, std::initializer_list<std::uint8_t> bytes, const char* what) {
  char msg[160];
  std::snprintf(msg, sizeof msg, "%s: id 0x%03X len %u", what, unsigned(f.id), unsigned(f.len));
  UNSIGNED_LONGS_EQUAL_TEXT(id, f.id, msg);
  CHECK_FALSE_TEXT(f.extended || f.rtr || f.fd || f.error, msg);
  UNSIGNED_LONGS_EQUAL_TEXT(bytes.size(), f.len, msg);
  std::size_t i = 0;
  for (std::uint8_t b : bytes) {
    char m2[200];
    std::snprintf(m2, sizeof m2, "%s byte %zu", msg, i);
    BYTES_EQUAL_TEXT(b, f.data[i], m2);
    ++i;
  }
}
}  // namespace

TEST_GROUP(CanopenCodec){};

TEST(CanopenCodec, NmtCommands) {
  // CiA 301 7.2.8.3.1: COB-id 0x000, byte 0 command specifier, byte 1 node id (0 = all).
  expect_frame(encode_nmt(NmtCommand::start, 5), 0x000, {0x01, 0x05}, "start 5");
  expect_frame(encode_nmt(NmtCommand::stop, 127), 0x000, {0x02, 0x7F}, "stop 127");
  expect_frame(encode_nmt(NmtCommand::enter_pre_operational, 0), 0x000, {0x80, 0x00}, "preop all");
  expect_frame(encode_nmt(NmtCommand::reset_node, 1), 0x000, {0x81, 0x01}, "reset node");
  expect_frame(encode_nmt(NmtCommand::reset_communication, 2), 0x000, {0x82, 0x02}, "reset comm");
  NmtCommand c;
  std::uint8_t n;
  CHECK(decode_nmt(CanFrame::make(0x000, {0x81, 0x09}), c, n));
  LONGS_EQUAL(int(NmtCommand::reset_node), int(c));
  LONGS_EQUAL(9, n);
  CHECK_FALSE(decode_nmt(CanFrame::make(0x000, {0x03, 0x01}), c, n));        // unknown command
  CHECK_FALSE(decode_nmt(CanFrame::make(0x000, {0x01, 0x80}), c, n));        // node 128
  CHECK_FALSE(decode_nmt(CanFrame::make(0x000, {0x01}), c, n));              // short
  CHECK_FALSE(decode_nmt(CanFrame::make(0x001, {0x01, 0x01}), c, n));        // wrong id
}

TEST(CanopenCodec, SyncAndHeartbeat) {
  expect_frame(encode_sync(), 0x080, {}, "sync");
  expect_frame(encode_sync(17), 0x080, {17}, "sync counter");
  CHECK(is_sync(CanFrame::make(0x080, {})));
  CHECK_FALSE(is_sync(CanFrame::make(0x081, {})));
  CHECK_FALSE(is_sync(CanFrame::make(0x080, {1, 2})));

  expect_frame(encode_heartbeat(3, NmtState::operational), 0x703, {0x05}, "hb op");
  expect_frame(encode_heartbeat(127, NmtState::pre_operational), 0x77F, {0x7F}, "hb preop");
  expect_frame(encode_heartbeat(1, NmtState::boot_up), 0x701, {0x00}, "boot-up");
  expect_frame(encode_heartbeat(1, NmtState::stopped), 0x701, {0x04}, "stopped");
  std::uint8_t n;
  NmtState s;
  CHECK(decode_heartbeat(CanFrame::make(0x70A, {0x05}), n, s));
  LONGS_EQUAL(10, n);
  LONGS_EQUAL(int(NmtState::operational), int(s));
  CHECK(decode_heartbeat(CanFrame::make(0x70A, {0x84}), n, s));  // toggle bit ignored
  LONGS_EQUAL(int(NmtState::stopped), int(s));
  CHECK_FALSE(decode_heartbeat(CanFrame::make(0x700, {0x05}), n, s));      // node 0
  CHECK_FALSE(decode_heartbeat(CanFrame::make(0x70A, {0x06}), n, s));      // no such state
  CHECK_FALSE(decode_heartbeat(CanFrame::make(0x70A, {0x05, 0}), n, s));   // length
  CHECK_FALSE(decode_heartbeat(CanFrame::make(0x68A, {0x05}), n, s));      // other function
}

TEST(CanopenCodec, Emcy) {
  Emcy e;
  e.error_code = 0x8611;
  e.error_register = 0x21;
  e.vendor[0] = 0xDE;
  e.vendor[4] = 0xAD;
  // CiA 301 7.2.7.3.1: bytes 0-1 error code (LE), byte 2 error register, 3-7 vendor.
  expect_frame(encode_emcy(4, e), 0x084, {0x11, 0x86, 0x21, 0xDE, 0x00, 0x00, 0x00, 0xAD}, "emcy");
  std::uint8_t n;
  Emcy d;
  CHECK(decode_emcy(CanFrame::make(0x0A0, {0x10, 0x23, 0x03, 1, 2, 3, 4, 5}), n, d));
  LONGS_EQUAL(0x20, n);
  UNSIGNED_LONGS_EQUAL(0x2310, d.error_code);
  BYTES_EQUAL(0x03, d.error_register);
  BYTES_EQUAL(5, d.vendor[4]);
  CHECK_FALSE(decode_emcy(CanFrame::make(0x080, {0, 0, 0, 0, 0, 0, 0, 0}), n, d));  // that is SYNC
  CHECK_FALSE(decode_emcy(CanFrame::make(0x085, {0, 0, 0}), n, d));               // short
  STRCMP_EQUAL("position following error", emcy_text(0x8611));
  STRCMP_EQUAL("temperature error", emcy_text(0x4201));
  STRCMP_EQUAL("device specific error", emcy_text(0xFF42));
  STRCMP_EQUAL("error reset or no error", emcy_text(0x0000));
}

TEST(CanopenCodec, SdoExpeditedDownload) {
  // CiA 301 7.2.4.3.3: ccs=1, n = 4 - len in bits 3..2, e=1, s=1.
  const std::uint8_t d4[] = {0x78, 0x56, 0x34, 0x12};
  expect_frame(sdo::initiate_download(2, 0x1017, 0, d4, 4), 0x602, {0x23, 0x17, 0x10, 0x00, 0x78, 0x56, 0x34, 0x12}, "dl4");
  const std::uint8_t d2[] = {0xE8, 0x03};
  expect_frame(sdo::initiate_download(2, 0x1017, 0, d2, 2), 0x602, {0x2B, 0x17, 0x10, 0x00, 0xE8, 0x03, 0x00, 0x00}, "dl2");
  const std::uint8_t d1[] = {0x08};
  expect_frame(sdo::initiate_download(1, 0x6060, 0, d1, 1), 0x601, {0x2F, 0x60, 0x60, 0x00, 0x08, 0, 0, 0}, "dl1");
  const std::uint8_t d3[] = {1, 2, 3};
  expect_frame(sdo::initiate_download(1, 0x2000, 5, d3, 3), 0x601, {0x27, 0x00, 0x20, 0x05, 1, 2, 3, 0}, "dl3");
  expect_frame(sdo::download_response(2, 0x1017, 0), 0x582, {0x60, 0x17, 0x10, 0x00, 0, 0, 0, 0}, "dl resp");
}

TEST(CanopenCodec, SdoSegmented) {
  const std::uint8_t d[] = {'a', 'b', 'c', 'd', 'e', 'f', 'g', 'h', 'i', 'j'};
  // Initiate segmented download: 0x21 (ccs=1, s=1), size 10 in bytes 4..7.
  expect_frame(sdo::initiate_download(3, 0x1008, 0, d, 10), 0x603, {0x21, 0x08, 0x10, 0x00, 10, 0, 0, 0}, "seg init");
  // First segment: t=0, n=0 (7 bytes), c=0 -> 0x00.
  expect_frame(sdo::download_segment(3, false, d, 7, false), 0x603, {0x00, 'a', 'b', 'c', 'd', 'e', 'f', 'g'}, "seg1");
  // Second: t=1, n=4 (3 bytes), c=1 -> 0x10 | 4<<1 | 1 = 0x19.
  expect_frame(sdo::download_segment(3, true, d + 7, 3, true), 0x603, {0x19, 'h', 'i', 'j', 0, 0, 0, 0}, "seg2");
  expect_frame(sdo::download_segment_response(3, true), 0x583, {0x30, 0, 0, 0, 0, 0, 0, 0}, "seg resp t1");
  expect_frame(sdo::download_segment_response(3, false), 0x583, {0x20, 0, 0, 0, 0, 0, 0, 0}, "seg resp t0");
  // Upload: request 0x40, segmented response 0x41 + size, segment requests 0x60/0x70.
  expect_frame(sdo::initiate_upload(3, 0x1008, 0), 0x603, {0x40, 0x08, 0x10, 0x00, 0, 0, 0, 0}, "ul init");
  expect_frame(sdo::upload_response(3, 0x1008, 0, d, 10), 0x583, {0x41, 0x08, 0x10, 0x00, 10, 0, 0, 0}, "ul resp seg");
  expect_frame(sdo::upload_response(3, 0x6041, 0, d, 2), 0x583, {0x4B, 0x41, 0x60, 0x00, 'a', 'b', 0, 0}, "ul resp exp2");
  expect_frame(sdo::upload_response(3, 0x1000, 0, d, 4), 0x583, {0x43, 0x00, 0x10, 0x00, 'a', 'b', 'c', 'd'}, "ul resp exp4");
  expect_frame(sdo::upload_segment_request(3, false), 0x603, {0x60, 0, 0, 0, 0, 0, 0, 0}, "ul seg req t0");
  expect_frame(sdo::upload_segment_request(3, true), 0x603, {0x70, 0, 0, 0, 0, 0, 0, 0}, "ul seg req t1");
  // Last upload segment with 1 byte: t=1, n=6, c=1 -> 0x10 | 0x0C | 1 = 0x1D.
  expect_frame(sdo::upload_segment(3, true, d, 1, true), 0x583, {0x1D, 'a', 0, 0, 0, 0, 0, 0}, "ul seg last");
}

TEST(CanopenCodec, SdoAbort) {
  expect_frame(sdo::abort(6, true, 0x6041, 0, 0x06010002), 0x586, {0x80, 0x41, 0x60, 0x00, 0x02, 0x00, 0x01, 0x06}, "abort server");
  expect_frame(sdo::abort(6, false, 0x1A00, 3, sdo::kAbortTimeout), 0x606, {0x80, 0x00, 0x1A, 0x03, 0x00, 0x00, 0x04, 0x05}, "abort client");
  struct {
    std::uint32_t code;
    const char* text;
  } table[] = {
      {0x05030000, "toggle bit not alternated"},
      {0x05040000, "SDO protocol timed out"},
      {0x06010002, "attempt to write a read only object"},
      {0x06020000, "object does not exist in the object dictionary"},
      {0x06040041, "object cannot be mapped to the PDO"},
      {0x06040042, "the number and length of the objects to be mapped would exceed PDO length"},
      {0x06090011, "sub-index does not exist"},
      {0x08000022, "data cannot be transferred or stored to the application because of the present device state"},
      {0x12345678, "unknown SDO abort code"},
  };
  for (auto& t : table) STRCMP_EQUAL(t.text, sdo::abort_text(t.code));
}

TEST(CanopenCodec, ProcessData) {
  // RPDO1 0x200+n: controlword (u16 LE) + target position (i32 LE).
  expect_frame(pdo::encode_rpdo1(1, 0x000F, 0x00012345), 0x201, {0x0F, 0x00, 0x45, 0x23, 0x01, 0x00}, "rpdo1");
  expect_frame(pdo::encode_rpdo1(6, 0x0006, -2), 0x206, {0x06, 0x00, 0xFE, 0xFF, 0xFF, 0xFF}, "rpdo1 neg");
  // TPDO1 0x180+n: statusword + position actual; TPDO2 0x280+n: velocity actual + error code.
  std::uint16_t sw;
  std::int32_t pos;
  CHECK(pdo::decode_tpdo1(CanFrame::make(0x183, {0x37, 0x02, 0x00, 0x00, 0x01, 0x80}), sw, pos));
  UNSIGNED_LONGS_EQUAL(0x0237, sw);
  LONGS_EQUAL(std::int32_t(0x80010000u), pos);
  CHECK_FALSE(pdo::decode_tpdo1(CanFrame::make(0x183, {0x37, 0x02, 0x00}), sw, pos));
  CHECK_FALSE(pdo::decode_tpdo1(CanFrame::make(0x203, {0x37, 0x02, 0, 0, 0, 0}), sw, pos));
  std::int32_t vel;
  std::uint16_t code;
  CHECK(pdo::decode_tpdo2(CanFrame::make(0x285, {0x18, 0xFC, 0xFF, 0xFF, 0x11, 0x86}), vel, code));
  LONGS_EQUAL(-1000, vel);
  UNSIGNED_LONGS_EQUAL(0x8611, code);
  expect_frame(pdo::encode_tpdo1(2, 0x0627, 1000), 0x182, {0x27, 0x06, 0xE8, 0x03, 0x00, 0x00}, "tpdo1");
  expect_frame(pdo::encode_tpdo2(2, 256, 0), 0x282, {0x00, 0x01, 0x00, 0x00, 0x00, 0x00}, "tpdo2");
}

TEST(CanopenCodec, FunctionAndNode) {
  UNSIGNED_LONGS_EQUAL(0x580, function_of(0x5A3));
  LONGS_EQUAL(0x23, node_of(0x5A3));
  CHECK(valid_node(1));
  CHECK(valid_node(127));
  CHECK_FALSE(valid_node(0));
  CHECK_FALSE(valid_node(128));
}

TEST_GROUP(HalStatus){};

TEST(HalStatus, EveryCodeHasANameAndADescriptionAndASign) {
  struct {
    Status s;
    const char* name;
    bool ok;
  } table[] = {
      {Status::ok, "ok", true},
      {Status::timeout, "timeout", true},
      {Status::would_block, "would_block", true},
      {Status::error_passive, "error_passive", true},
      {Status::invalid_argument, "invalid_argument", false},
      {Status::io_error, "io_error", false},
      {Status::bus_off, "bus_off", false},
      {Status::interface_down, "interface_down", false},
      {Status::not_open, "not_open", false},
      {Status::sdo_abort, "sdo_abort", false},
      {Status::protocol_error, "protocol_error", false},
      {Status::drive_fault, "drive_fault", false},
      {Status::drive_refused, "drive_refused", false},
      {Status::heartbeat_lost, "heartbeat_lost", false},
      {Status::not_configured, "not_configured", false},
      {Status::capacity, "capacity", false},
  };
  for (auto& t : table) {
    STRCMP_EQUAL(t.name, to_string(t.s));
    CHECK_EQUAL_TEXT(t.ok, is_ok(t.s), t.name);
    CHECK_TEXT(std::strlen(describe(t.s)) >= 7, t.name);
    CHECK_TEXT(std::strstr(describe(t.s), "unknown") == nullptr, t.name);
  }
  STRCMP_EQUAL("unknown_status", to_string(Status(99)));
}
