// SPDX-License-Identifier: Apache-2.0
// libFuzzer target: ISO-TP (ISO 15765-2) reassembly and flow control in hal's
// IsoTpEndpoint: single/first/consecutive/flow-control frames in any order, with time
// passing and a message of our own being sent meanwhile. Beyond "no crash": a completed
// reception is never longer than the receive limit.
#include <cstdint>

#include "fuzz_input.hpp"
#include "servoarm/hal/clock.hpp"
#include "servoarm/hal/isotp.hpp"

using namespace servoarm;
using namespace servoarm::hal;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 2) return 0;
  IsoTpConfig cfg;
  cfg.padding = data[0] & 1;
  cfg.extended = data[0] & 2;
  cfg.block_size = data[1] & 7;
  cfg.rx_limit = (data[0] & 4) ? 64 : 4095;
  cfg.n_cr = cfg.n_bs = 20 * kMillisecond;
  fuzz::FrameSource src(data + 2, size - 2);
  fuzz::FuzzBus bus;
  bus.refuse_sends = data[0] & 8;
  ManualClock clock;
  IsoTpEndpoint ep(bus, clock, cfg);
  std::uint8_t msg[300];
  for (std::size_t i = 0; i < sizeof msg; ++i) msg[i] = static_cast<std::uint8_t>(i);
  CanFrame f;
  while (src.next(f)) {
    // most frames on the endpoint's receive id (0x7E0), with its id kind
    if (!(f.data[7] & 0x80)) {
      f.id = cfg.rx_id;
      f.extended = cfg.extended;
    }
    const IsoTpEvent ev = ep.on_frame(f);
    if (ev.rx == IsoTpResult::ok && ep.rx_message().size() > cfg.rx_limit) __builtin_trap();
    const std::uint8_t b = f.data[6];
    if (b & 1) (void)ep.send({msg, static_cast<std::size_t>(1 + b % sizeof msg)});
    if (b & 2) {
      clock.advance((b >> 2) * kMillisecond);
      (void)ep.poll();
    }
  }
  return 0;
}
