// SPDX-License-Identifier: Apache-2.0
// libFuzzer target: the CANopen master's receive path (CanopenServoBus::dispatch: TPDO1/2
// feedback, EMCY, heartbeats, SDO answers outside a transfer) for six joints, with read()
// and write() cycles in between. Beyond "no crash": the feedback stays finite.
#include <array>
#include <cmath>
#include <cstdint>

#include "fuzz_input.hpp"
#include "servoarm/hal/canopen_master.hpp"
#include "servoarm/hal/clock.hpp"

using namespace servoarm;
using namespace servoarm::hal;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  fuzz::FrameSource src(data, size, 0);
  fuzz::FuzzBus bus;
  ManualClock clock;
  CanopenServoBus master(bus, clock, CanopenMasterConfig::consecutive(1, 6));
  if (master.config_status() != Status::ok) __builtin_trap();
  std::array<double, 6> set{};
  CanFrame f;
  while (src.next(f)) {
    if (!f.extended && (f.id & 0x7F) > 6) f.id = (f.id & 0x780) | (1 + (f.id & 0x7F) % 6);  // mostly our nodes
    master.dispatch(f, clock.now());
    if (f.data[0] & 1) {
      clock.advance(kMillisecond);
      (void)master.read(clock.now());
      (void)master.write(set, clock.now());
    }
  }
  for (std::size_t j = 0; j < master.joint_count(); ++j) {
    const JointFeedback& fb = master.feedback(j);
    if (!std::isfinite(fb.position) || !std::isfinite(fb.velocity)) __builtin_trap();
    char buf[160];
    master.describe_fault(j, buf, sizeof buf);
  }
  return 0;
}
