// SPDX-License-Identifier: Apache-2.0
// The drive-family factory (drive_factory.hpp): the plan of groups from the configuration and
// one builder per family. CiA 402: the CANopen master's configuration from the bus.*, drive.*
// and [dynamics] keys. MIT families (damiao, cubemars_mit, robstride_mit): hal::MitGroup from
// drive.motor, drive.mit_kp / mit_kd, drive.master_id and the joint mapping keys.
#include "servoarm/app/drive_factory.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "servoarm/hal/canopen_master.hpp"
#include "servoarm/hal/mit_group.hpp"
#include "servoarm/hal/safety_input.hpp"
#include "servoarm/kinematics/collision.hpp"
#include "servoarm/kinematics/dynamics.hpp"

namespace servoarm::fw {

hal::HomingSpec homing_spec(const FwConfig& cfg, const kin::Chain& chain, int j) {
  hal::HomingSpec h;
  if (cfg.drives.empty()) return h;  // no [[drive]] tables: every joint absolute (kind none)
  const DriveConfig& d = cfg.drives[static_cast<std::size_t>(j)];
  const double unit = kConfigUnits.joint_in(chain, j, 1.0);  // SI per deg (revolute) or mm (prismatic)
  if (d.homing_method == "none") return h;
  h.kind = d.homing_method == "hard_stop" ? hal::HomingKind::hard_stop : hal::HomingKind::cia402;
  h.method = static_cast<std::int8_t>(homing_method_number(d.homing_method));
  h.speed_switch = d.homing_speed_switch * unit;
  if (h.kind == hal::HomingKind::hard_stop) h.speed_switch *= d.homing_direction;  // the sign is the direction
  h.speed_zero = d.homing_speed_zero * unit;
  h.acceleration = d.homing_acceleration * unit;
  h.offset = d.homing_offset * unit;
  h.timeout = static_cast<hal::Duration>(d.homing_timeout_s * 1e9);
  h.following_limit = d.homing_following_limit * unit;
  h.torque_limit = d.homing_torque_limit;
  h.backoff = d.homing_backoff * unit;
  // Travel supervision: a missing switch or stop ends the homing once the joint has
  // travelled its whole range plus homing.travel_margin_deg (mm) from where it began.
  const kin::DhRow& row = chain.joint(j);
  if (std::isfinite(row.lower) && std::isfinite(row.upper))
    h.max_travel = (row.upper - row.lower) + cfg.homing_travel_margin_deg * unit;
  return h;
}

std::string plan_drive_groups(const FwConfig& cfg, int n_joints, std::vector<DriveGroupPlan>& out) {
  out.clear();
  for (int j = 0; j < n_joints; ++j) {
    const DriveConfig* d = cfg.drives.empty() ? nullptr : &cfg.drives[static_cast<std::size_t>(j)];
    const std::string family = d != nullptr ? d->family : "cia402";
    const std::string can = d != nullptr && !d->can.empty() ? d->can : cfg.can;
    const int id = d == nullptr || d->node == 0 ? cfg.first_node + j : d->node;
    if (id > 127) return "config: bus.first_node: node id of joint " + std::to_string(j + 1) + " would exceed 127";
    for (const DriveGroupPlan& p : out) {
      if (p.can != can) continue;
      if (d != nullptr && cfg.drives[static_cast<std::size_t>(p.joints.front())].can_fd != d->can_fd)
        return "config: drive[" + std::to_string(j + 1) + "].can_fd: " + (d->can_fd ? "true" : "false") + ", but joint " +
               std::to_string(p.joints.front() + 1) + " on the same interface (" + can + ") says " +
               (d->can_fd ? "false" : "true");
      for (std::size_t k = 0; k < p.joints.size(); ++k)
        if (p.ids[k] == id)
          return "config: drive[" + std::to_string(j + 1) + "].node: node " + std::to_string(id) + " is joint " +
                 std::to_string(p.joints[k] + 1) + "'s too" + (can != cfg.can ? " (on " + can + ")" : "");
    }
    if (d != nullptr && family != "cia402") {
      // the id the motor answers on: unique on the interface, never a CANopen NMT / SYNC / EMCY id
      const int master = mit_master_id(*d, id);
      const std::string at = "config: drive[" + std::to_string(j + 1) + "].master_id: ";
      const std::string which = d->master_id != 0 ? "" : " (the " + family + " default)";
      char hex[8];
      std::snprintf(hex, sizeof hex, "0x%03X", unsigned(master));
      if (master == 0x7FF) return at + hex + which + " is the Damiao register id (0x7FF)";
      if (const char* why = mit_id_problem(master); why != nullptr && canopen_shares_interface(cfg, *d))
        return at + hex + which + " " + why + ", and a CiA 402 drive is on " + can;
      for (const DriveGroupPlan& p : out) {
        if (p.can != can) continue;
        for (std::size_t k = 0; k < p.joints.size(); ++k) {
          const DriveConfig& o = cfg.drives[static_cast<std::size_t>(p.joints[k])];
          const std::string other = "joint " + std::to_string(p.joints[k] + 1);
          if (p.ids[k] == master) return at + hex + which + " is " + other + "'s drive id";
          if (p.family == "damiao" && family == "damiao" && mit_master_id(o, p.ids[k]) == master)
            return at + hex + which + " is " + other + "'s master id too";
          if (p.family != "cia402" && mit_master_id(o, p.ids[k]) == id)
            return "config: drive[" + std::to_string(j + 1) + "].node: " + std::to_string(id) + " is " + other +
                   "'s master id";
        }
      }
    }
    auto g = std::find_if(out.begin(), out.end(), [&](const DriveGroupPlan& p) { return p.family == family && p.can == can; });
    if (g == out.end()) g = out.insert(out.end(), DriveGroupPlan{family, can, {}, {}});
    g->joints.push_back(j);
    g->ids.push_back(static_cast<std::uint8_t>(id));
  }
  return "";
}

namespace {

/// CiA 402 drives over CANopen: one CanopenServoBus for the group's joints.
std::string make_cia402(const DriveGroupInput& in, std::unique_ptr<hal::DriveGroup>& out) {
  const FwConfig& cfg = in.cfg;
  hal::CanopenMasterConfig mc;
  mc.joint_count = in.plan.joints.size();
  mc.heartbeat_period = static_cast<hal::Duration>(cfg.heartbeat_period_ms * 1e6);
  mc.heartbeat_timeout = static_cast<hal::Duration>(cfg.heartbeat_timeout_ms * 1e6);
  mc.sdo_timeout = static_cast<hal::Duration>(cfg.sdo_timeout_ms * 1e6);
  mc.boot_timeout = static_cast<hal::Duration>(cfg.boot_timeout_ms * 1e6);
  mc.boot_retry = static_cast<hal::Duration>(cfg.boot_retry_ms * 1e6);
  mc.state_timeout = static_cast<hal::Duration>(cfg.state_timeout_ms * 1e6);
  // [dynamics]: RPDO2 and TPDO2's torque only when a part asks for them (else the
  // frames of before). Optional: a drive that lacks an object is brought up without it, and the
  // part that needs it is refused at boot() naming the joint (ModelControl::configure).
  if (cfg.feed_forward != "off") mc.rpdo2.velocity_offset = hal::PdoUse::optional;
  if (cfg.feed_forward == "torque") mc.rpdo2.torque_offset = hal::PdoUse::optional;
  if (cfg.freedrive) mc.rpdo2.torque_mode = hal::PdoUse::optional;
  if (cfg.collision) mc.tpdo2.torque = hal::PdoUse::optional;
  mc.interpolation_period = static_cast<hal::Duration>(std::llround(1e9 / cfg.rate_hz));  // 60C2h
  for (std::size_t k = 0; k < mc.joint_count; ++k) {
    const int j = in.plan.joints[k];
    const auto ju = static_cast<std::size_t>(j);
    auto& jc = mc.joints[k];
    jc.node_id = in.plan.ids[k];
    if (!cfg.drives.empty()) jc.rated_torque = cfg.drives[ju].rated_torque;
    jc.scaling.counts_per_unit = cfg.counts_per_rev;
    jc.scaling.gear_ratio = cfg.gear_ratio;
    if (!cfg.drives.empty()) {
      const DriveConfig& d = cfg.drives[ju];
      if (d.counts_per_rev > 0) jc.scaling.counts_per_unit = d.counts_per_rev;
      if (d.gear_ratio != 0) jc.scaling.gear_ratio = d.gear_ratio;
      jc.scaling.direction = d.direction;
      jc.scaling.zero_offset = static_cast<std::int32_t>(d.zero_offset);
      if (d.heartbeat_timeout_ms > 0) jc.heartbeat_timeout = static_cast<hal::Duration>(d.heartbeat_timeout_ms * 1e6);
    }
    jc.scaling.kind = in.chain.joint(j).type == kin::JointType::prismatic ? hal::JointScaling::Kind::prismatic
                                                                          : hal::JointScaling::Kind::revolute;
    if (!cfg.drives.empty() && cfg.drives[ju].quick_stop_decel > 0) {
      // joint deg/s^2 (mm/s^2) -> motor counts/s^2
      jc.quick_stop_decel = kConfigUnits.joint_in(in.chain, j, cfg.drives[ju].quick_stop_decel) * jc.scaling.counts_per_si();
    }
    jc.homing = homing_spec(cfg, in.chain, j);
    // hard_stop with homing.torque_limit: the drives' torque actual (6077h) into TPDO2 where
    // they can map it (else the following error alone detects the stop, as documented)
    if (jc.homing.kind == hal::HomingKind::hard_stop && jc.homing.torque_limit > 0) mc.tpdo2.torque = hal::PdoUse::optional;
    for (int jo : in.output_joint) jc.digital_outputs = jc.digital_outputs || jo == j;
    // [safety] inputs on this joint's drive: its 60FDh into TPDO3 (docs/safety.md#safety-inputs)
    for (const std::string* text : {&cfg.safety_estop_input, &cfg.safety_reduced_input}) {
      hal::InputSource src;
      char err[160];
      if (hal::parse_input_source(*text, src, err, sizeof err) && src.kind == hal::InputKind::drive && src.joint == j)
        jc.digital_inputs = true;
    }
    if (!cfg.drives.empty()) {  // drive.sdo, validated by the key table
      const std::vector<SdoEntry>& sdo = cfg.drives[ju].sdo;
      jc.sdo_write_count = std::min(sdo.size(), hal::kMaxSdoWrites);
      for (std::size_t e = 0; e < jc.sdo_write_count; ++e) {
        hal::SdoWrite& w = jc.sdo_writes[e];
        w.index = static_cast<std::uint16_t>(sdo[e].index);
        w.sub = static_cast<std::uint8_t>(sdo[e].sub);
        w.size = static_cast<std::uint8_t>(sdo_type_size(sdo[e].type));
        w.is_signed = sdo_type_signed(sdo[e].type);
        w.value = static_cast<std::uint32_t>(sdo[e].value);  // two's complement for a negative value
      }
    }
  }
  // Velocity actual and error code: in TPDO2 when bus.tpdo2 asks for it, or when TPDO2 is sent
  // for the torque anyway (the collision observer needs the drive's velocity; the three fit in
  // 8 bytes). Else no TPDO2: one frame per drive and cycle less (docs/deployment.md#bus-load).
  const bool tpdo2_sent = cfg.tpdo2 || mc.tpdo2.torque != hal::PdoUse::off;
  mc.tpdo2.velocity = mc.tpdo2.error_code = tpdo2_sent ? hal::PdoUse::optional : hal::PdoUse::off;
  auto master = std::make_unique<hal::CanopenServoBus>(in.bus, in.clock, mc);
  if (master->config_status() != hal::Status::ok)
    return std::string("bus: ") + hal::to_string(master->config_status()) + (master->last_error()[0] ? ": " : "") +
           master->last_error();
  out = std::move(master);
  return "";
}

/// Each joint's largest inertia M_jj (kg m^2 or kg, joint side) over the zero pose and 64
/// pseudo-random poses within the limits; all 0 for a robot without inertial data.
kin::JointVector largest_inertia(const kin::Chain& chain) {
  kin::JointVector out = kin::JointVector::Zero(chain.n_joints);
  char why[8];
  if (chain.n_joints < 1 || kin::dynamics_refusal(chain, why, sizeof why)) return out;
  kin::MassMatrix M;
  kin::JointVector q = kin::JointVector::Zero(chain.n_joints);
  std::uint64_t seed = 39;
  for (int s = 0; s <= 64; ++s) {
    for (int j = 0; j < chain.n_joints && s > 0; ++j) {
      const kin::DhRow& row = chain.joint(j);
      const bool finite = std::isfinite(row.lower) && std::isfinite(row.upper);
      const double lo = finite ? row.lower : row.type == kin::JointType::prismatic ? 0.0 : -M_PI;
      const double hi = finite ? row.upper : row.type == kin::JointType::prismatic ? 0.5 : M_PI;
      seed = seed * 6364136223846793005ull + 1442695040888963407ull;
      q[j] = lo + (hi - lo) * static_cast<double>(seed >> 11) * (1.0 / 9007199254740992.0);
    }
    if (kin::mass_matrix(chain, q, M) != kin::Status::ok) continue;
    for (int j = 0; j < chain.n_joints; ++j) out[j] = std::fmax(out[j], M(j, j));
  }
  return out;
}

/// The hold after an e-stop or fault brakes each MIT joint with its largest inertia over this
/// time (MitJointConfig::stop_damping) when no model torque arrives: a velocity time constant of
/// at most 0.1 s (at most T_MAX), where KD_MAX alone gives a heavy joint about a second.
constexpr double kStopBrakeTime = 0.1;  // s

/// MIT-mode actuators of one vendor: one hal::MitGroup for the group's joints.
std::string make_mit(const DriveGroupInput& in, hal::mit::Vendor vendor, std::unique_ptr<hal::DriveGroup>& out) {
  const FwConfig& cfg = in.cfg;
  hal::MitGroupConfig mc;
  mc.vendor = vendor;
  mc.joint_count = in.plan.joints.size();
  mc.reply_timeout = static_cast<hal::Duration>(cfg.sdo_timeout_ms * 1e6);
  mc.feedback_timeout = static_cast<hal::Duration>(cfg.heartbeat_timeout_ms * 1e6);
  mc.motor_timeout = static_cast<hal::Duration>(cfg.heartbeat_timeout_ms * 1e6);  // the motor stops as late as armfw sees it
  mc.state_timeout = static_cast<hal::Duration>(cfg.state_timeout_ms * 1e6);
  mc.fd = cfg.drives[static_cast<std::size_t>(in.plan.joints.front())].can_fd;  // one value per interface (plan)
  const kin::JointVector inertia = largest_inertia(in.chain);
  for (std::size_t k = 0; k < mc.joint_count && k < hal::kMaxServoJoints; ++k) {
    const int j = in.plan.joints[k];
    const DriveConfig& d = cfg.drives[static_cast<std::size_t>(j)];
    hal::MitJointConfig& jc = mc.joints[k];
    jc.motor_id = in.plan.ids[k];
    jc.master_id = static_cast<std::uint16_t>(mit_master_id(d, in.plan.ids[k]));
    jc.profile = hal::mit::find_profile(d.motor);
    jc.kp = d.mit_kp;
    jc.kd = d.mit_kd;
    jc.scaling.gear_ratio = d.gear_ratio != 0 ? d.gear_ratio : 1.0;  // after the actuator (its own gearbox is inside)
    jc.scaling.direction = d.direction;
    jc.scaling.zero_offset = static_cast<std::int32_t>(d.zero_offset);
    jc.scaling.kind = in.chain.joint(j).type == kin::JointType::prismatic ? hal::JointScaling::Kind::prismatic
                                                                          : hal::JointScaling::Kind::revolute;
    if (d.heartbeat_timeout_ms > 0) mc.feedback_timeout = std::max(mc.feedback_timeout, static_cast<hal::Duration>(d.heartbeat_timeout_ms * 1e6));
    jc.stop_damping = j < inertia.size() ? inertia[j] / kStopBrakeTime : 0.0;
    jc.homing = homing_spec(cfg, in.chain, j);
    if (jc.homing.kind == hal::HomingKind::cia402)
      return "config: drive[" + std::to_string(j + 1) + "].homing.method: " + d.homing_method +
             " is a CiA 402 drive's own homing; a " + d.family + " motor homes \"absolute\" or \"hard_stop\"";
  }
  auto g = std::make_unique<hal::MitGroup>(in.bus, in.clock, mc);
  if (g->config_status() != hal::Status::ok)
    return std::string("bus: ") + hal::to_string(g->config_status()) + ": " + g->last_error();
  out = std::move(g);
  return "";
}
std::string make_damiao(const DriveGroupInput& in, std::unique_ptr<hal::DriveGroup>& out) {
  return make_mit(in, hal::mit::Vendor::damiao, out);
}
std::string make_cubemars(const DriveGroupInput& in, std::unique_ptr<hal::DriveGroup>& out) {
  return make_mit(in, hal::mit::Vendor::cubemars, out);
}
std::string make_robstride(const DriveGroupInput& in, std::unique_ptr<hal::DriveGroup>& out) {
  return make_mit(in, hal::mit::Vendor::robstride, out);
}

constexpr DriveFamily kFamilies[] = {
    {"cia402", &make_cia402},
    {"damiao", &make_damiao},
    {"cubemars_mit", &make_cubemars},
    {"robstride_mit", &make_robstride},
};

}  // namespace

std::span<const DriveFamily> drive_families() { return kFamilies; }

std::string make_drive_group(const DriveGroupInput& in, std::unique_ptr<hal::DriveGroup>& out) {
  for (const DriveFamily& f : drive_families())
    if (in.plan.family == f.name) return f.make(in, out);
  return "config: drive.family: \"" + in.plan.family + "\" is no drive family armfw knows";
}

}  // namespace servoarm::fw
