// SPDX-License-Identifier: Apache-2.0
// libFuzzer target: hal's SDO client (expedited and segmented upload/download) against a
// server whose answers are the fuzz input. Beyond "no crash": an upload never reports
// more bytes than the buffer holds, and a failed transfer carries a status.
#include <cstdint>

#include "fuzz_input.hpp"
#include "servoarm/hal/clock.hpp"
#include "servoarm/hal/sdo_client.hpp"

using namespace servoarm;
using namespace servoarm::hal;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  constexpr std::uint8_t kNode = 5;
  fuzz::FrameSource src(data, size, kNode);
  fuzz::FuzzBus bus;
  ManualClock clock;
  SdoClient sdo(bus, clock, 10 * kMillisecond);
  while (!src.empty()) {
    const std::uint8_t op = src.byte();
    const std::size_t answers = 1 + op % 8;  // frames the "server" sends for this transfer
    for (std::size_t i = 0; i < answers; ++i) {
      CanFrame f;
      if (!src.next(f)) break;
      if (!(op & 0x40)) f.id = (f.id & 0x7F) == kNode && !f.extended ? 0x580 + kNode : f.id;
      bus.rx.push_back(f);
    }
    std::uint8_t buf[64];
    const std::size_t cap = 1 + op % sizeof buf;
    const std::uint8_t payload[20] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20};
    SdoResult r;
    switch ((op >> 3) & 3) {
      case 0: r = sdo.upload(kNode, 0x1008, 0, buf, cap); break;
      case 1: r = sdo.download(kNode, 0x6040, 0, payload, 1 + op % sizeof payload); break;
      case 2: {
        std::uint32_t v = 0;
        r = sdo.read_u32(kNode, 0x6041, 0, v);
        break;
      }
      default: r = sdo.write_u16(kNode, 0x6040, 0, 0x000F); break;
    }
    if (r.size > sizeof buf) __builtin_trap();
    if (((op >> 3) & 3) == 0 && r.status == Status::ok && r.size > cap) __builtin_trap();
    bus.rx.clear();
    clock.advance(kMillisecond);
  }
  return 0;
}
