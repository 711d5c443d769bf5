// SPDX-License-Identifier: Apache-2.0
#pragma once
// The drive-family factory (set-up code; docs/servo-bus.md#drive-families-groups-and-the-arm):
// the configuration's [[drive]] tables say each joint's family (drive.family) and interface
// (drive.can, "" = bus.can); the joints of one family on one interface form one group, built by
// that family's entry in drive_families() into a hal::DriveGroup. App puts the groups into one
// hal::ArmServoBus, the ServoBus the controller drives. A new family is a hal::DriveGroup class
// and one entry in the table; nothing above hal/ changes.
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "servoarm/config/config.hpp"
#include "servoarm/hal/can_bus.hpp"
#include "servoarm/hal/clock.hpp"
#include "servoarm/hal/drive_group.hpp"
#include "servoarm/kinematics/chain.hpp"
#include "servoarm/lang/units.hpp"

namespace servoarm::fw {

/// One group to build: the joints (arm indices, ascending) of one family on one interface.
struct DriveGroupPlan {
  std::string family;             ///< drive.family
  std::string can;                ///< the interface: drive.can, or bus.can when that is ""
  std::vector<int> joints;        ///< arm joints, ascending
  std::vector<std::uint8_t> ids;  ///< each joint's drive id on the bus (CANopen: the node id)
};

/// The groups of the arm: joints grouped by (drive.family, interface), in the order of their
/// first joint; drive ids unique per interface. "" or the error (one line naming the key).
std::string plan_drive_groups(const FwConfig& cfg, int n_joints, std::vector<DriveGroupPlan>& out);

/// What a family's builder gets: the whole configuration and chain (the joints' keys), the
/// plan, [[output]] i's arm joint output_joint[i], and the bus and clock the group runs on.
struct DriveGroupInput {
  const FwConfig& cfg;
  const kin::Chain& chain;
  const DriveGroupPlan& plan;
  const std::vector<int>& output_joint;
  hal::CanBus& bus;
  hal::Clock& clock;
};

/// A drive family: its drive.family name and its group builder ("" or the error).
struct DriveFamily {
  const char* name;
  std::string (*make)(const DriveGroupInput& in, std::unique_ptr<hal::DriveGroup>& out);
};
/// Every family armfw can build.
std::span<const DriveFamily> drive_families();
/// Builds `in.plan`'s group with its family's entry. "" or the error.
std::string make_drive_group(const DriveGroupInput& in, std::unique_ptr<hal::DriveGroup>& out);

/// Joint j's homing (drive.homing.*, deg / mm -> SI; kind none without [[drive]] tables).
hal::HomingSpec homing_spec(const FwConfig& cfg, const kin::Chain& chain, int j);

}  // namespace servoarm::fw
