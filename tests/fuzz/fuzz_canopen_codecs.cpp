// SPDX-License-Identifier: Apache-2.0
// libFuzzer target: the CANopen frame decoders of hal (NMT, SYNC, heartbeat, EMCY, the
// PDO codecs, SDO multiplexer and abort texts). Every frame a decoder accepts re-encodes
// to the same frame (the decoders accept exactly what the encoders produce).
#include <cstdint>
#include <cstring>

#include "fuzz_input.hpp"
#include "servoarm/hal/canopen.hpp"
#include "servoarm/hal/canopen_master.hpp"

using namespace servoarm;
using namespace servoarm::hal;

namespace {
bool same(const CanFrame& a, const CanFrame& b) {
  return a.id == b.id && a.extended == b.extended && a.rtr == b.rtr && a.len == b.len &&
         std::memcmp(a.data.data(), b.data.data(), a.len) == 0;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  fuzz::FrameSource src(data, size);
  CanFrame f;
  while (src.next(f)) {
    canopen::NmtCommand cmd{};
    std::uint8_t node = 0;
    if (canopen::decode_nmt(f, cmd, node)) {
      if (!same(f, canopen::encode_nmt(cmd, node)) || node > canopen::kMaxNodeId) __builtin_trap();
      (void)canopen::to_string(cmd);
    }
    (void)canopen::is_sync(f);
    canopen::NmtState st{};
    if (canopen::decode_heartbeat(f, node, st)) {
      if (!canopen::valid_node(node)) __builtin_trap();
      (void)canopen::to_string(st);
    }
    canopen::Emcy e;
    if (canopen::decode_emcy(f, node, e)) {
      if (!same(f, canopen::encode_emcy(node, e))) __builtin_trap();
      (void)canopen::emcy_text(e.error_code);
    }
    std::uint16_t cw = 0, ec = 0;
    std::int32_t pos = 0, vel = 0;
    if (pdo::decode_rpdo1(f, cw, pos) && !same(f, pdo::encode_rpdo1(canopen::node_of(f.id), cw, pos))) __builtin_trap();
    if (pdo::decode_tpdo1(f, cw, pos) && !same(f, pdo::encode_tpdo1(canopen::node_of(f.id), cw, pos))) __builtin_trap();
    if (pdo::decode_tpdo2(f, vel, ec) && !same(f, pdo::encode_tpdo2(canopen::node_of(f.id), vel, ec))) __builtin_trap();
    if (f.len >= 8) {
      (void)canopen::sdo::index_of(f);
      (void)canopen::sdo::sub_of(f);
      (void)canopen::sdo::abort_text(get_u32(&f.data[4]));
      (void)canopen::sdo::cs_of(f.data[0]);
    }
  }
  return 0;
}
