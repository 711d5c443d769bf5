// SPDX-License-Identifier: Apache-2.0
// The drive doctor's scan (hal/drive_scan.hpp) against virtual drives: Damiao motors (one in
// position-velocity mode, one at another bitrate: not seen) and CiA 402 nodes, each found
// with what it says about itself, in one line.
#include <cstdio>
#include <string>
#include <vector>

#include "servoarm/hal/clock.hpp"
#include "servoarm/hal/drive_scan.hpp"
#include "servoarm/sim/mit_motor.hpp"
#include "servoarm/sim/sim_plant.hpp"

// CppUTest last: its leak detector redefines `new`.
#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::hal;

TEST_GROUP(DriveScan){};

TEST(DriveScan, FindsDamiaoMotorsWithTheirModelModeAndMasterId) {
  ManualClock clock;
  std::vector<sim::MitMotorSpec> specs(3);
  const char* models[3] = {"DM-J4340", "DM-J8006", "DM-J4310-2EC"};
  for (std::size_t i = 0; i < 3; ++i) {
    specs[i].profile = mit::find_profile(models[i]);
    specs[i].id = static_cast<std::uint16_t>(i + 1);
    specs[i].master = static_cast<std::uint16_t>(i + 1 + 0x10);
  }
  specs[1].ctrl_mode = 2;
  sim::MitPlant plant(clock, specs);
  plant.at(2).quirks().silent = true;  // another bitrate: not seen
  clock.set_idle_hook([&](TimePoint t) { plant.step(t); });
  ScanOptions opt;
  opt.last_id = 16;
  std::vector<ScannedDrive> found(8);
  const std::size_t n = scan_drives(plant.master_bus(), clock, opt, found);
  clock.set_idle_hook(nullptr);
  LONGS_EQUAL(2, long(n));
  char line[256];
  describe_drive(found[0], line, sizeof line);
  std::printf("\n  %s\n", line);
  STRCMP_EQUAL("id 0x01: damiao DM-J4340 (Gr 40, TMAX 28), mode MIT, master 0x011, CAN timeout off (armfw sets it), "
               "PMAX 12.5, VMAX 8, sw 0x0",
               line);
  describe_drive(found[1], line, sizeof line);
  std::printf("  %s\n", line);
  STRCMP_CONTAINS("id 0x02: damiao DM-J8006 (Gr 6, TMAX 40), mode 2 position-velocity (not MIT: armfw sets CTRL_MODE = 1 "
                  "at bring-up), master 0x012",
                  line);
}

TEST(DriveScan, FindsCanopenNodesWithTheirIdentity) {
  ManualClock clock;
  sim::SimPlant plant(clock, {2, 4});
  clock.set_idle_hook([&](TimePoint t) { plant.step(t); });
  ScanOptions opt;
  opt.damiao = false;
  std::vector<ScannedDrive> found(8);
  const std::size_t n = scan_drives(plant.master_bus(), clock, opt, found);
  clock.set_idle_hook(nullptr);
  LONGS_EQUAL(2, long(n));
  LONGS_EQUAL(2, found[0].id);
  LONGS_EQUAL(4, found[1].id);
  char line[256];
  describe_drive(found[0], line, sizeof line);
  std::printf("\n  %s\n", line);
  STRCMP_CONTAINS("id 2: CANopen node, device type 0x00020192 (CiA 402 drive), vendor 0x00000DEA", line);
}
