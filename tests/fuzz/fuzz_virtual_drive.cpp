// SPDX-License-Identifier: Apache-2.0
// libFuzzer target: host_sim's virtual CiA 402 drive as a CANopen server: its SDO server
// (expedited and segmented), NMT, SYNC, RPDOs, with the motor model ticking between
// frames. What a master written elsewhere may send it, including garbage.
#include <cstdint>

#include "fuzz_input.hpp"
#include "servoarm/sim/virtual_drive.hpp"

using namespace servoarm;
using namespace servoarm::hal;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  constexpr std::uint8_t kNode = 3;
  fuzz::FrameSource src(data, size, kNode);
  fuzz::FuzzBus bus;
  sim::VirtualDrive drive(kNode);
  TimePoint now = kSecond;
  drive.power_on(now, bus);
  CanFrame f;
  while (src.next(f)) {
    drive.handle(f, now, bus);
    now += (f.data[0] & 3) * kMillisecond;  // sometimes time passes between frames
    drive.tick(now, bus);
  }
  return 0;
}
