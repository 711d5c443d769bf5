// SPDX-License-Identifier: Apache-2.0
#include "servoarm/hal/bus_load.hpp"

namespace servoarm::hal {

namespace {
/// Worst case: after the first bit, one stuff bit every four (length.h can_bitstuffing_len()).
int stuffed(int bits, bool worst) { return worst && bits > 0 ? bits + (bits - 1) / 4 : bits; }

/// The data field of an FD frame: the next length the DLC can say.
int fd_length(unsigned n) {
  constexpr unsigned kLengths[] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64};
  for (const unsigned l : kLengths)
    if (n <= l) return int(l);
  return 64;
}

constexpr int kFooter = 2 + 7;    // ACK slot + delimiter, end of frame
constexpr int kIntermission = 3;
}  // namespace

const char* to_string(BusDirection d) {
  switch (d) {
    case BusDirection::to_drives: return "to drives";
    case BusDirection::from_drives: return "from drives";
  }
  return "?";
}

FrameBits can_frame_bits(bool fd, bool brs, bool extended, unsigned data_len, bool worst) {
  FrameBits b;
  if (!fd) {
    // SOF, id (11 or 11 + SRR + IDE + 18), RTR, IDE / r1, r0, DLC; data; CRC 15 + delimiter
    const int header = extended ? 39 : 19;
    const int n = int(data_len > 8 ? 8 : data_len);
    b.nominal = stuffed(header + 8 * n + 16, worst) + kFooter + kIntermission;
    return b;
  }
  const int n = fd_length(data_len);
  const int header = extended ? 41 : 22;    // SOF .. DLC, ESI included
  const int crc_field = n <= 16 ? 28 : 33;  // stuff count, CRC, delimiter, fixed stuff bits
  const int all = stuffed(header + 8 * n, worst) + crc_field + kFooter + kIntermission;
  if (!brs) {
    b.nominal = all;
    return b;
  }
  // Nominal: SOF .. BRS (the header without ESI and DLC) with its stuff bits, the CRC
  // delimiter, ACK, EOF, intermission. The rest is the data phase.
  b.nominal = stuffed(header - 5, worst) + 1 + kFooter + kIntermission;
  b.data = all - b.nominal;
  return b;
}

BusLoad bus_load(const BusTraffic& t, double bitrate, double data_bitrate) {
  BusLoad l;
  const bool fd = data_bitrate > 0;
  const double j = double(t.joints), r = t.rate_hz;
  const auto add = [&](const char* name, BusDirection d, std::uint8_t len, double per_cycle) {
    if (per_cycle <= 0 || l.count == kMaxBusFrameKinds) return;
    const std::size_t k = l.count++;
    l.kinds[k] = BusFrameKind{name, d, len, per_cycle * r};
    l.bits[k] = can_frame_bits(fd, fd, false, len);
    l.seconds[k] = l.kinds[k].per_second * (l.bits[k].nominal / bitrate + (fd ? l.bits[k].data / data_bitrate : 0.0));
    l.frames_per_cycle += per_cycle;
  };
  add("SYNC", BusDirection::to_drives, 0, t.joints > 0 || t.mit_joints == 0 ? 1 : 0);
  add("RPDO1", BusDirection::to_drives, t.rpdo1_len, t.rpdo1_len ? j : 0);
  add("RPDO2", BusDirection::to_drives, t.rpdo2_len, t.rpdo2_len ? j : 0);
  add("RPDO3", BusDirection::to_drives, t.rpdo3_len, t.rpdo3_len ? double(t.rpdo3_joints) : 0);
  add("TPDO1", BusDirection::from_drives, t.tpdo1_len, t.tpdo1_len ? j : 0);
  add("TPDO2", BusDirection::from_drives, t.tpdo2_len, t.tpdo2_len ? j : 0);
  add("MIT command", BusDirection::to_drives, 8, double(t.mit_joints));
  add("MIT feedback", BusDirection::from_drives, 8, double(t.mit_joints));
  if (t.heartbeat_period_s > 0 && r > 0 && l.count < kMaxBusFrameKinds) {
    // Not cyclic: every drive's heartbeat, as frames per second.
    const std::size_t k = l.count++;
    l.kinds[k] = BusFrameKind{"heartbeat", BusDirection::from_drives, 1, j / t.heartbeat_period_s};
    l.bits[k] = can_frame_bits(fd, fd, false, 1);
    l.seconds[k] = l.kinds[k].per_second * (l.bits[k].nominal / bitrate + (fd ? l.bits[k].data / data_bitrate : 0.0));
  }
  for (std::size_t k = 0; k < l.count; ++k)
    (l.kinds[k].direction == BusDirection::to_drives ? l.to_drives : l.from_drives) += l.seconds[k];
  return l;
}

}  // namespace servoarm::hal
