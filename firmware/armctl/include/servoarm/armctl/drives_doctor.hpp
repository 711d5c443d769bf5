// SPDX-License-Identifier: Apache-2.0
#pragma once
// The drive doctor's core behind `armctl drives scan / check` (cli_drives.hpp), on any
// hal::CanBus: the command opens SocketCAN interfaces, the tests hand in-process buses with
// virtual drives. Set-up code: blocks for the scan's windows and timeouts, allocates.
#include <functional>
#include <string>

#include "servoarm/config/config.hpp"
#include "servoarm/hal/can_bus.hpp"
#include "servoarm/hal/clock.hpp"
#include "servoarm/hal/drive_scan.hpp"

namespace servoarm::fw {

/// Scans `bus` (called `iface` in the text) and appends to `out` one line per drive found (id,
/// family, identity / model, mode, frame format, errors, temperature) and a summary line.
/// Returns the number of drives found.
int drives_scan(hal::CanBus& bus, hal::Clock& clock, const std::string& iface, const hal::ScanOptions& opt,
                std::string& out);

/// Saves the present position as the zero of Damiao motor `id` on `bus` (its save-zero frame,
/// FF..FE), which must be disabled: finds it with a register read (opt.fd: CAN FD), reads its
/// position, sends the frame, reads it again. One line to `out`: the position before and after,
/// or why nothing was saved (no answer, enabled). Returns 0 when saved, else 1.
int drives_zero(hal::CanBus& bus, hal::Clock& clock, const std::string& iface, std::uint16_t id,
                const hal::ScanOptions& opt, std::string& out);

/// The bus an interface name stands for, opened for CAN FD when `fd`; nullptr with `error` set
/// (one line) when it cannot be opened.
using BusOpener = std::function<hal::CanBus*(const std::string& iface, bool fd, std::string& error)>;

/// Compares `cfg`'s [[drive]] tables (joint count `joints` when there are none: CiA 402 nodes
/// bus.first_node..) with what answers on each interface they name: one line per joint ("ok" or
/// what to change), one per drive on a bus that no joint names. `window` / `timeout`: the scan's.
/// Returns the number of problems (0: the configuration matches the buses); `out` gets the text.
/// A bus that cannot be opened is a problem named in `out`.
int drives_check(const FwConfig& cfg, int joints, const BusOpener& open, hal::Clock& clock, std::string& out,
                 hal::Duration window = 50 * hal::kMillisecond, hal::Duration timeout = 50 * hal::kMillisecond);

}  // namespace servoarm::fw
