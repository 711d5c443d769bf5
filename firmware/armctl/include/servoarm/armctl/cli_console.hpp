// SPDX-License-Identifier: Apache-2.0
#pragma once
// armctl console: a client for armfw's console over a serial TTY, a pty, or CAN (ISO-TP).
//   armctl console --serial PATH [--baud N] [--timeout SEC] -c "movej 0 45 -45 0 0 0" [-c ...]
//   armctl console --can vcan0 [--tx-id 0x7E0 --rx-id 0x7E8] -c status
//   armctl console --serial PATH | --can IFACE   interactive (line editing + history with libedit)
// Non-real-time; returns an armctl exit code (0 every answer ok, 1 an answer was
// `error:` or timed out, 2 bad usage / cannot open the device).
namespace servoarm::fw {

int console_main(int argc, char** argv);

}  // namespace servoarm::fw
