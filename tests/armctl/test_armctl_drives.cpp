// SPDX-License-Identifier: Apache-2.0
// armctl drives scan / check (the drive doctor, drives_doctor.hpp) against in-process buses with
// virtual drives: six Damiao DM-J4340 motors plus one in position-velocity mode and one that is
// silent (another bitrate: not seen, and said so), and a CiA 402 bus for a mixed arm. The core is
// the one `armctl drives` runs on SocketCAN; the command itself is run for its usage errors.
#include <cstdio>
#include <string>
#include <vector>

#include "servoarm/armctl/drives_doctor.hpp"
#include "servoarm/hal/clock.hpp"
#include "servoarm/sim/mit_motor.hpp"
#include "servoarm/sim/sim_plant.hpp"

#include "run_command.hpp"

// CppUTest last: its leak detector redefines `new`.
#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::hal;
using servoarm::fw::DriveConfig;
using servoarm::fw::FwConfig;
using servoarm::test::run_command;

namespace {

/// The line of `text` that contains `key` ("" if none).
std::string line_with(const std::string& text, const std::string& key) {
  const std::size_t k = text.find(key);
  if (k == std::string::npos) return "";
  const std::size_t b = text.rfind('\n', k);
  const std::size_t e = text.find('\n', k);
  return text.substr(b == std::string::npos ? 0 : b + 1, e == std::string::npos ? std::string::npos : e - (b == std::string::npos ? 0 : b + 1));
}

/// Ids 1..6: DM-J4340 in MIT mode, master 0x11..0x16. Id 7: DM-J8006 in position-velocity mode.
/// Id 8: a DM-J4340 that answers nothing (another bitrate).
std::vector<sim::MitMotorSpec> motors(bool fd) {
  std::vector<sim::MitMotorSpec> specs(8);
  for (std::size_t i = 0; i < specs.size(); ++i) {
    specs[i].profile = mit::find_profile(i == 6 ? "DM-J8006" : "DM-J4340");
    specs[i].id = static_cast<std::uint16_t>(i + 1);
    specs[i].master = static_cast<std::uint16_t>(i + 1 + 0x10);
    specs[i].fd = fd;
  }
  specs[6].ctrl_mode = 2;
  return specs;
}

FwConfig six_damiao(const char* iface, bool fd) {
  FwConfig c;
  c.can = iface;
  c.drives.resize(6);
  for (std::size_t j = 0; j < 6; ++j) {
    DriveConfig& d = c.drives[j];
    d.family = "damiao";
    d.motor = "DM-J4340";
    d.node = static_cast<int>(j + 1);
    d.can_fd = fd;
    d.homing_method = "none";
  }
  return c;
}

}  // namespace

TEST_GROUP(ArmctlDrives){};

TEST(ArmctlDrives, ScanFindsSevenMotorsWithModelModeFormatErrorsAndTemperature) {
  ManualClock clock;
  sim::MitPlant plant(clock, motors(true));
  plant.at(7).quirks().silent = true;
  plant.at(2).set_temperature(47);
  plant.at(4).inject_error(9);  // under-voltage
  clock.set_idle_hook([&](TimePoint t) { plant.step(t); });
  ScanOptions opt;
  opt.fd = true;
  std::string out;
  const int n = fw::drives_scan(plant.master_bus(), clock, "vcan0", opt, out);
  clock.set_idle_hook(nullptr);
  std::printf("\n%s", out.c_str());
  LONGS_EQUAL(7, n);
  const std::string l1 = line_with(out, "id 0x01:");
  STRCMP_CONTAINS("damiao DM-J4340", l1.c_str());
  STRCMP_CONTAINS("mode MIT", l1.c_str());
  STRCMP_CONTAINS("master 0x011", l1.c_str());
  STRCMP_CONTAINS("CAN FD, no error, disabled", l1.c_str());
  STRCMP_CONTAINS("rotor 47 C", line_with(out, "id 0x03:").c_str());
  STRCMP_CONTAINS("error under-voltage (9)", line_with(out, "id 0x05:").c_str());
  const std::string l7 = line_with(out, "id 0x07:");
  STRCMP_CONTAINS("damiao DM-J8006", l7.c_str());
  STRCMP_CONTAINS("mode 2 position-velocity (not MIT", l7.c_str());
  CHECK_TEXT(line_with(out, "id 0x08:").empty(), out.c_str());
  STRCMP_CONTAINS("7 drives on vcan0 (CAN FD, ids 1-127)", out.c_str());
}

TEST(ArmctlDrives, ScanOfClassicFramesSeesNoFdMotorAndSaysWhatToCheck) {
  ManualClock clock;
  sim::MitPlant plant(clock, motors(true));
  clock.set_idle_hook([&](TimePoint t) { plant.step(t); });
  std::string out;
  const int n = fw::drives_scan(plant.master_bus(), clock, "vcan0", ScanOptions{}, out);
  clock.set_idle_hook(nullptr);
  LONGS_EQUAL(0, n);
  STRCMP_CONTAINS("no drive answered on vcan0 (classic CAN, ids 1-127): check the bitrate, the frame format (--fd)",
                  out.c_str());
}

TEST(ArmctlDrives, ScanFindsCanopenNodesWithIdentityAndErrors) {
  ManualClock clock;
  sim::SimPlant plant(clock, {3, 5});
  clock.set_idle_hook([&](TimePoint t) { plant.step(t); });
  std::string out;
  const int n = fw::drives_scan(plant.master_bus(), clock, "can1", ScanOptions{}, out);
  clock.set_idle_hook(nullptr);
  std::printf("\n%s", out.c_str());
  LONGS_EQUAL(2, n);
  STRCMP_CONTAINS("id 3: CANopen node, device type 0x00020192 (CiA 402 drive)", out.c_str());
  STRCMP_CONTAINS("no error", line_with(out, "id 5:").c_str());
}

TEST(ArmctlDrives, CheckNamesTheSilentMotorTheWrongModelAndTheUnclaimedOne) {
  ManualClock clock;
  std::vector<sim::MitMotorSpec> specs = motors(false);
  specs[3].master = 0x30;  // id 4 answers on 0x030, the file expects 0x014
  sim::MitPlant plant(clock, specs);
  plant.at(5).quirks().silent = true;  // id 6: another bitrate
  clock.set_idle_hook([&](TimePoint t) { plant.step(t); });
  FwConfig cfg = six_damiao("can0", false);
  cfg.drives[1].motor = "DM-J8006";  // the motor on id 2 is a DM-J4340
  std::vector<std::string> opened;
  const fw::BusOpener open = [&](const std::string& iface, bool fd, std::string& error) -> CanBus* {
    opened.push_back(iface + (fd ? " fd" : ""));
    if (iface == "can0") return &plant.master_bus();
    error = "no such interface";
    return nullptr;
  };
  std::string out;
  const int problems = fw::drives_check(cfg, 6, open, clock, out);
  clock.set_idle_hook(nullptr);
  std::printf("\n%s", out.c_str());
  LONGS_EQUAL(1, long(opened.size()));
  STRCMP_EQUAL("can0", opened[0].c_str());
  LONGS_EQUAL(3, problems);
  STRCMP_CONTAINS("joint 1 (damiao id 1 on can0): ok, DM-J4340, classic CAN", out.c_str());
  STRCMP_CONTAINS("joint 2 (damiao id 2 on can0): change; set drive.motor = \"DM-J4340\"", out.c_str());
  STRCMP_CONTAINS("joint 4 (damiao id 4 on can0): change; set drive.master_id = 0x030", out.c_str());
  STRCMP_CONTAINS("joint 6 (damiao id 6 on can0): not seen (no answer to a register read in classic CAN): a motor set "
                  "to CAN FD needs drive.can_fd = true",
                  out.c_str());
  const std::string extra = line_with(out, "id 0x07:");
  STRCMP_CONTAINS("can0: id 0x07: damiao DM-J8006", extra.c_str());
  STRCMP_CONTAINS("no joint names it", extra.c_str());
  STRCMP_CONTAINS("3 things to change before armfw runs on this arm", out.c_str());
}

TEST(ArmctlDrives, CheckOfAMatchingMixedArmOnTwoBusesIsOk) {
  ManualClock clock;
  std::vector<sim::MitMotorSpec> specs = motors(true);
  specs.resize(4);
  specs[3].ctrl_mode = 3;  // velocity mode: a note, armfw sets MIT
  sim::MitPlant mit_plant(clock, specs);
  sim::SimPlant co_plant(clock, {5, 6});
  clock.set_idle_hook([&](TimePoint t) {
    mit_plant.step(t);
    co_plant.step(t);
  });
  FwConfig cfg = six_damiao("can0", true);
  for (std::size_t j = 4; j < 6; ++j) {
    cfg.drives[j].family = "cia402";
    cfg.drives[j].motor.clear();
    cfg.drives[j].can_fd = false;
    cfg.drives[j].can = "can1";
  }
  std::vector<std::string> opened;
  const fw::BusOpener open = [&](const std::string& iface, bool fd, std::string&) -> CanBus* {
    opened.push_back(iface + (fd ? " fd" : ""));
    return iface == "can0" ? &mit_plant.master_bus() : &co_plant.master_bus();
  };
  std::string out;
  const int problems = fw::drives_check(cfg, 6, open, clock, out);
  clock.set_idle_hook(nullptr);
  std::printf("\n%s", out.c_str());
  LONGS_EQUAL(0, problems);
  LONGS_EQUAL(2, long(opened.size()));
  STRCMP_EQUAL("can0 fd", opened[0].c_str());
  STRCMP_EQUAL("can1", opened[1].c_str());
  STRCMP_CONTAINS("joint 1 (damiao id 1 on can0): ok, DM-J4340, CAN FD", out.c_str());
  STRCMP_CONTAINS("joint 4 (damiao id 4 on can0): ok, DM-J4340, CAN FD", out.c_str());
  STRCMP_CONTAINS("note: mode 3 velocity: armfw sets MIT at bring-up", line_with(out, "joint 4").c_str());
  STRCMP_CONTAINS("joint 5 (cia402 node 5 on can1): ok, CiA 402 drive", out.c_str());
  STRCMP_CONTAINS("joint 6 (cia402 node 6 on can1): ok, CiA 402 drive", out.c_str());
  STRCMP_CONTAINS("the configuration matches the buses", out.c_str());
}

// A drive that is not seen is told to check the bit rate its own interface is set up for:
// can1's drive.bitrate (500 kbit/s) for the CiA 402 wrist, bus.bitrate and the FD data phase
// for the Damiao motors on can0.
TEST(ArmctlDrives, CheckNamesEachInterfacesOwnBitrate) {
  ManualClock clock;
  std::vector<sim::MitMotorSpec> specs = motors(true);
  specs.resize(4);
  sim::MitPlant mit_plant(clock, specs);
  mit_plant.at(3).quirks().silent = true;  // id 4: another bitrate
  sim::SimPlant co_plant(clock, {5});      // node 6 is not on can1
  clock.set_idle_hook([&](TimePoint t) {
    mit_plant.step(t);
    co_plant.step(t);
  });
  FwConfig cfg = six_damiao("can0", true);
  cfg.data_bitrate = 5000000;
  for (std::size_t j = 4; j < 6; ++j) {
    cfg.drives[j].family = "cia402";
    cfg.drives[j].motor.clear();
    cfg.drives[j].can_fd = false;
    cfg.drives[j].can = "can1";
    cfg.drives[j].bitrate = 500000;
  }
  const fw::BusOpener open = [&](const std::string& iface, bool, std::string&) -> CanBus* {
    return iface == "can0" ? &mit_plant.master_bus() : &co_plant.master_bus();
  };
  std::string out;
  const int problems = fw::drives_check(cfg, 6, open, clock, out);
  clock.set_idle_hook(nullptr);
  std::printf("\n%s", out.c_str());
  LONGS_EQUAL(2, problems);
  STRCMP_CONTAINS("check drive.node, the bitrate (500000 bit/s in drive.bitrate), wiring",
                  line_with(out, "joint 6 (cia402 node 6 on can1): not seen").c_str());
  STRCMP_CONTAINS("the bitrate (1000000 bit/s in bus.bitrate, data phase 5000000 bit/s), wiring",
                  line_with(out, "joint 4 (damiao id 4 on can0): not seen").c_str());
}

// The motor's own zero, when the user asks for it (`armctl drives zero --iface IFACE --id N`):
// the save-zero frame (FF..FE) to a disabled Damiao motor, whose position then reads 0; the
// position before and after said in one line. An enabled motor (armfw driving it) or one that
// does not answer is refused in one line, nothing sent.
TEST(ArmctlDrives, ZeroSavesTheMotorsOwnZeroAndRefusesAnEnabledOrSilentOne) {
  ManualClock clock;
  sim::MitPlant plant(clock, motors(true));
  plant.at(2).set_position(1.25);
  plant.at(7).quirks().silent = true;  // id 8: another bitrate
  clock.set_idle_hook([&](TimePoint t) { plant.step(t); });
  ScanOptions opt;
  opt.fd = true;
  std::string out;
  LONGS_EQUAL(0, fw::drives_zero(plant.master_bus(), clock, "can0", 3, opt, out));
  std::printf("\n%s", out.c_str());
  STRCMP_CONTAINS("id 0x03: damiao DM-J4340: zero saved in the motor: position 1.250 rad -> 0.000 rad", out.c_str());
  DOUBLES_EQUAL(0.0, plant.at(2).position(), 1e-9);
  // enabled: refused, the position kept
  plant.at(3).set_position(0.5);
  plant.master_bus().send([] {
    CanFrame f = mit::special_frame(4, mit::Special::enable);
    f.fd = f.brs = true;
    return f;
  }());
  clock.advance(kMillisecond);
  plant.step(clock.now());
  out.clear();
  LONGS_EQUAL(1, fw::drives_zero(plant.master_bus(), clock, "can0", 4, opt, out));
  STRCMP_CONTAINS("id 0x04: the motor is enabled (is armfw driving it?): disable it first; nothing saved", out.c_str());
  DOUBLES_EQUAL(0.5, plant.at(3).position(), 1e-3);
  out.clear();
  LONGS_EQUAL(1, fw::drives_zero(plant.master_bus(), clock, "can0", 8, opt, out));  // id 8 is silent
  clock.set_idle_hook(nullptr);
  STRCMP_CONTAINS("id 0x08: no Damiao motor answered on can0 (CAN FD): nothing saved", out.c_str());
}

TEST(ArmctlDrives, CommandLineErrorsAreOneLineAndExitTwo) {
  const std::string armctl = ARMCTL_PATH;
  auto r = run_command(armctl + " drives scan");
  LONGS_EQUAL(2, r.status);
  STRCMP_EQUAL("armctl: drives scan: --iface IFACE is required (e.g. can0)\n", r.err.c_str());
  r = run_command(armctl + " drives scan --iface vcan0 --first 0");
  LONGS_EQUAL(2, r.status);
  STRCMP_EQUAL("armctl: --first: '0' is not an id 1..2046\n", r.err.c_str());
  r = run_command(armctl + " drives scan --iface vcan0 --timeout 0");
  LONGS_EQUAL(2, r.status);
  STRCMP_EQUAL("armctl: --timeout: '0' is not a time in ms (1..10000)\n", r.err.c_str());
  r = run_command(armctl + " drives scan --iface nosuchcan9");
  LONGS_EQUAL(2, r.status);
  STRCMP_CONTAINS("armctl: drives scan: cannot open nosuchcan9", r.err.c_str());
  r = run_command(armctl + " drives check");
  LONGS_EQUAL(2, r.status);
  STRCMP_EQUAL("armctl: drives check: --config FILE is required\n", r.err.c_str());
  // check takes the scan's --timeout (a busy host answers late): checked like scan's, and taken
  r = run_command(armctl + " drives check --config nosuch.toml --timeout 0");
  LONGS_EQUAL(2, r.status);
  STRCMP_EQUAL("armctl: --timeout: '0' is not a time in ms (1..10000)\n", r.err.c_str());
  {
    const std::string file = "armctl_drives_check_sim.toml";
    FILE* f = std::fopen(file.c_str(), "w");
    CHECK(f != nullptr);
    std::fputs("robot = \"puma560\"\n[bus]\ncan = \"sim\"\n", f);
    std::fclose(f);
    r = run_command(armctl + " drives check --config " + file + " --timeout 300");
    std::remove(file.c_str());
    LONGS_EQUAL_TEXT(0, r.status, r.err.c_str());
    STRCMP_CONTAINS("bus.can = \"sim\": the simulated drives, nothing to check on a bus", r.out.c_str());
  }
  r = run_command(armctl + " drives zero --iface vcan0");
  LONGS_EQUAL(2, r.status);
  STRCMP_EQUAL("armctl: drives zero: --id N is required (the motor's id)\n", r.err.c_str());
  r = run_command(armctl + " drives frobnicate");
  LONGS_EQUAL(2, r.status);
  STRCMP_CONTAINS("unknown drives command 'frobnicate'", r.err.c_str());
  r = run_command(armctl + " --help");
  LONGS_EQUAL(0, r.status);
  STRCMP_CONTAINS("armctl drives scan --iface IFACE", r.out.c_str());
}
