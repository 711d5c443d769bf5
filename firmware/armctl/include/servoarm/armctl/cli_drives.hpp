// SPDX-License-Identifier: Apache-2.0
#pragma once
// armctl drives: the drive doctor (docs/armctl.md#drives, docs/mit-motors.md#finding-the-motors).
//   armctl drives scan --iface can0 [--fd] [--first N] [--last N]   what answers on a bus
//   armctl drives check --config armfw.toml                          the configuration vs the buses
// Set-up tools: they query the drives (SDO uploads, Damiao register reads and status queries)
// and write nothing. Exit status: 0 all found / all as configured, 1 nothing found / something
// to change, 2 bad usage or an interface that cannot be opened.
namespace servoarm::fw {

int cli_drives(int argc, char** argv);

}  // namespace servoarm::fw
