// SPDX-License-Identifier: Apache-2.0
#include "servoarm/app/app.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

#include "servoarm/lang/units.hpp"
#include "servoarm/kinematics/description.hpp"

namespace servoarm::fw {

namespace {
/// armfw.toml's lengths and angles are in mm and degrees (the keys say so: _mm, _deg;
/// a joint's value in mm when it is prismatic, in degrees when revolute), whatever units
/// the robot description uses: they reach SI through the units table.
constexpr ConsoleUnits kConfigUnits{LengthUnit::mm, AngleUnit::deg};
}  // namespace

ControllerConfig App::controller_config() const {
  ControllerConfig c;
  c.rate_hz = cfg.rate_hz;
  c.following_error = kConfigUnits.angle_in(cfg.following_error_deg);
  c.enable_timeout = cfg.enable_timeout_s;
  c.feedback_timeout = cfg.feedback_timeout_ms * 1e-3;
  c.drive_quick_stop = cfg.stop == "drive";
  c.drive_stop_timeout = cfg.drive_stop_timeout_s;
  c.unhomed_jog_scale = cfg.homing_unhomed_jog_pct / 100.0;
  // homing.order (1-based joints) -> bit masks; [] = one group of every joint
  c.homing_groups = 0;
  if (cfg.homing_order.empty()) {
    c.homing_group_mask[0] = static_cast<std::uint16_t>((1u << chain.n_joints) - 1u);
    c.homing_groups = 1;
  } else {
    for (const auto& g : cfg.homing_order) {
      std::uint16_t m = 0;
      for (const int j : g) m = static_cast<std::uint16_t>(m | (1u << (j - 1)));
      c.homing_group_mask[static_cast<std::size_t>(c.homing_groups++)] = m;
    }
  }
  return c;
}

ModelControlConfig App::model_config() const {
  ModelControlConfig m;
  m.feed_forward = cfg.feed_forward == "torque"     ? FeedForwardKind::torque
                   : cfg.feed_forward == "velocity" ? FeedForwardKind::velocity
                                                    : FeedForwardKind::off;
  m.collision = cfg.collision;
  m.freedrive = cfg.freedrive;
  m.collision_gain = cfg.collision_gain;
  m.collision_sensitivity = cfg.collision_sensitivity;
  m.collision_threshold_pct = cfg.collision_threshold_pct;
  m.freedrive_damping = cfg.freedrive_damping;
  for (int j = 0; j < chain.n_joints; ++j) {
    const auto ju = static_cast<std::size_t>(j);
    if (!cfg.drives.empty()) m.collision_threshold[ju] = cfg.drives[ju].collision_threshold;
    // 6071h/6077h/60B2h are per mille of the rated torque: the master's unit x 1000, joint side
    if (servo) m.rated_torque[ju] = std::fabs(servo->torque_unit(ju)) * 1000.0;
  }
  return m;
}

hal::HomingSpec App::homing_spec(int j) const {
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

ConsoleConfig App::console_config() const {
  ConsoleConfig c;
  c.default_joint_speed_pct = cfg.joint_speed_pct;
  c.default_linear_speed = kConfigUnits.length_in(cfg.linear_speed_mm_s);
  c.max_linear_speed = kConfigUnits.length_in(cfg.max_linear_speed_mm_s);
  c.cartesian.linear_velocity = c.max_linear_speed;
  c.max_move_duration_s = cfg.max_move_duration_s;
  c.default_blend_rad = kConfigUnits.angle_in(cfg.default_blend_deg);  // motion.default_blend_deg: movej
  c.default_blend_m = kConfigUnits.length_in(cfg.default_blend_mm);    // motion.default_blend_mm: movel, G0/G1
  if (!cfg.home_deg.empty()) {
    c.home = kin::JointVector::Zero(chain.n_joints);
    for (int j = 0; j < chain.n_joints; ++j)
      c.home[j] = kConfigUnits.joint_in(chain, j, cfg.home_deg[static_cast<std::size_t>(j)]);
  }
  c.units = units_of(chain);  // the console speaks the description's units (mm or m, deg or rad)
  c.robot_name = cfg.robot;
  c.jog_deadman_s = cfg.console_jog_deadman_ms * 1e-3;
  c.jog_speed_pct = cfg.console_jog_speed_pct;
  c.dialect = cfg.console_dialect == "grbl" ? Dialect::grbl : Dialect::native;
  c.config_text = to_toml(cfg);
  // Only an absolute path (armfw resolves console.frames_file against the configuration
  // file's folder): a relative one would land in whatever the working directory is.
  if (!cfg.console_frames_file.empty() && cfg.console_frames_file[0] == '/') c.frames_file = cfg.console_frames_file;
  if (!cfg.programs_points_file.empty() && cfg.programs_points_file[0] == '/') c.points_file = cfg.programs_points_file;
  if (!cfg.programs_dir.empty() && cfg.programs_dir[0] == '/') c.programs_dir = cfg.programs_dir;
  for (std::size_t i = 0; i < cfg.outputs.size() && i < output_joint.size(); ++i)
    c.outputs.push_back({cfg.outputs[i].name, output_joint[i], cfg.outputs[i].bit});
  return c;
}

std::string App::build(const FwConfig& c, hal::Clock* clock_override, const SimFactory& sim) {
  cfg = c;
  const std::string bad = validate(cfg);
  if (!bad.empty()) return "config: " + bad;
  if (clock_override != nullptr) clock = clock_override;
  kin::LoadResult lr = kin::load_robot(cfg.robot);
  if (!lr.ok) return "robot: " + lr.error;
  chain = lr.chain;
  // The checks that need the robot (home pose within the limits, [[drive]] count and limits,
  // ranges that fit the drives' 32-bit counts): the key table's, in firmware/config.
  if (const std::string e = validate_for_chain(cfg, chain); !e.empty()) return "config: " + e;
  const int n = chain.n_joints;
  if (n < 1 || n > static_cast<int>(hal::kMaxServoJoints)) return "robot: joint count not supported by the servo bus";
  if (!cfg.home_deg.empty() && static_cast<int>(cfg.home_deg.size()) != n)
    return "config: motion.home_deg: needs " + std::to_string(n) + " values for " + cfg.robot;
  if (!cfg.drives.empty() && static_cast<int>(cfg.drives.size()) != n)
    return "config: drive: " + std::to_string(cfg.drives.size()) + " [[drive]] tables for the " + std::to_string(n) +
           " joints of " + cfg.robot + " (give one per joint, or none)";
  // Per-drive limits narrow the description's (so IK, planning and the supervisor all see them).
  for (int j = 0; j < static_cast<int>(cfg.drives.size()); ++j) {
    const DriveConfig& d = cfg.drives[static_cast<std::size_t>(j)];
    kin::DhRow& row = chain.joint(j);
    const double unit = kConfigUnits.joint_in(chain, j, 1.0);  // SI per deg (revolute) or mm (prismatic)
    const std::string w = "config: drive[" + std::to_string(j + 1) + "].";
    if (!d.limits.empty()) {
      const double lo = d.limits[0] * unit, hi = d.limits[1] * unit;
      if (lo < row.lower - 1e-12 || hi > row.upper + 1e-12)
        return w + "limits: [" + std::to_string(d.limits[0]) + ", " + std::to_string(d.limits[1]) +
               "] reaches outside the robot description's [" + std::to_string(row.lower / unit) + ", " +
               std::to_string(row.upper / unit) + "]";
      row.lower = lo;
      row.upper = hi;
    }
    if (d.max_velocity > 0) {
      const double v = d.max_velocity * unit;
      if (row.dynamics.max_velocity > 0 && v > row.dynamics.max_velocity * (1 + 1e-12))
        return w + "max_velocity: " + std::to_string(d.max_velocity) + " is above the robot description's " +
               std::to_string(row.dynamics.max_velocity / unit);
      row.dynamics.max_velocity = v;
    }
  }
  std::vector<std::uint8_t> nodes;
  for (int j = 0; j < n; ++j) {
    const int id = cfg.drives.empty() || cfg.drives[static_cast<std::size_t>(j)].node == 0
                       ? cfg.first_node + j
                       : cfg.drives[static_cast<std::size_t>(j)].node;
    if (id > 127) return "config: bus.first_node: node id of joint " + std::to_string(j + 1) + " would exceed 127";
    for (int k = 0; k < j; ++k)
      if (nodes[static_cast<std::size_t>(k)] == id)
        return "config: drive[" + std::to_string(j + 1) + "].node: node " + std::to_string(id) + " is joint " +
               std::to_string(k + 1) + "'s too";
    nodes.push_back(static_cast<std::uint8_t>(id));
  }
  // [[output]]: each on a drive of the arm (its 60FEh:01 mapped in RPDO3 at bring-up)
  output_joint.clear();
  for (std::size_t i = 0; i < cfg.outputs.size(); ++i) {
    int jo = -1;
    for (int j = 0; j < n; ++j)
      if (nodes[static_cast<std::size_t>(j)] == cfg.outputs[i].node) jo = j;
    if (jo < 0)
      return "config: output[" + std::to_string(i + 1) + "].node: node " + std::to_string(cfg.outputs[i].node) +
             " is no drive of the arm (nodes " + std::to_string(nodes.front()) + ".." + std::to_string(nodes.back()) + ")";
    output_joint.push_back(jo);
  }
  canbus = nullptr;
  if (cfg.can == "sim") {
    if (sim) canbus = sim(*clock, nodes);
    if (canbus == nullptr)
      return "bus.can: \"sim\" needs virtual drives (armfw --sim; this armfw was built without host_sim, or none were given)";
  } else {
    socketcan = std::make_unique<hal::SocketCanBus>();
    const hal::Status st = socketcan->open(cfg.can.c_str());
    if (st != hal::Status::ok) {
      const std::string m = socketcan->message();  // starts with the interface name
      return "bus.can: cannot open " + (m.rfind(cfg.can + ":", 0) == 0 ? m : cfg.can + ": " + m);
    }
    canbus = socketcan.get();
  }
  hal::CanopenMasterConfig mc;
  mc.joint_count = static_cast<std::size_t>(n);
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
  for (int j = 0; j < n; ++j) {
    auto& jc = mc.joints[static_cast<std::size_t>(j)];
    jc.node_id = nodes[static_cast<std::size_t>(j)];
    if (!cfg.drives.empty()) jc.rated_torque = cfg.drives[static_cast<std::size_t>(j)].rated_torque;
    jc.scaling.counts_per_unit = cfg.counts_per_rev;
    jc.scaling.gear_ratio = cfg.gear_ratio;
    if (!cfg.drives.empty()) {
      const DriveConfig& d = cfg.drives[static_cast<std::size_t>(j)];
      if (d.counts_per_rev > 0) jc.scaling.counts_per_unit = d.counts_per_rev;
      if (d.gear_ratio != 0) jc.scaling.gear_ratio = d.gear_ratio;
      jc.scaling.direction = d.direction;
      jc.scaling.zero_offset = static_cast<std::int32_t>(d.zero_offset);
      if (d.heartbeat_timeout_ms > 0) jc.heartbeat_timeout = static_cast<hal::Duration>(d.heartbeat_timeout_ms * 1e6);
    }
    jc.scaling.kind = chain.joint(j).type == kin::JointType::prismatic ? hal::JointScaling::Kind::prismatic
                                                                       : hal::JointScaling::Kind::revolute;
    if (!cfg.drives.empty() && cfg.drives[static_cast<std::size_t>(j)].quick_stop_decel > 0) {
      // joint deg/s^2 (mm/s^2) -> motor counts/s^2
      jc.quick_stop_decel =
          kConfigUnits.joint_in(chain, j, cfg.drives[static_cast<std::size_t>(j)].quick_stop_decel) * jc.scaling.counts_per_si();
    }
    if (!cfg.drives.empty()) jc.homing = homing_spec(j);
    // hard_stop with homing.torque_limit: the drives' torque actual (6077h) into TPDO2 where
    // they can map it (else the following error alone detects the stop, as documented)
    if (jc.homing.kind == hal::HomingKind::hard_stop && jc.homing.torque_limit > 0) mc.tpdo2.torque = hal::PdoUse::optional;
    for (int jo : output_joint) jc.digital_outputs = jc.digital_outputs || jo == j;
    if (!cfg.drives.empty()) {  // drive.sdo, validated by the key table
      const std::vector<SdoEntry>& sdo = cfg.drives[static_cast<std::size_t>(j)].sdo;
      jc.sdo_write_count = std::min(sdo.size(), hal::kMaxSdoWrites);
      for (std::size_t k = 0; k < jc.sdo_write_count; ++k) {
        hal::SdoWrite& w = jc.sdo_writes[k];
        w.index = static_cast<std::uint16_t>(sdo[k].index);
        w.sub = static_cast<std::uint8_t>(sdo[k].sub);
        w.size = static_cast<std::uint8_t>(sdo_type_size(sdo[k].type));
        w.is_signed = sdo_type_signed(sdo[k].type);
        w.value = static_cast<std::uint32_t>(sdo[k].value);  // two's complement for a negative value
      }
    }
  }
  // Velocity actual and error code: in TPDO2 when bus.tpdo2 asks for it, or when TPDO2 is sent
  // for the torque anyway (the collision observer needs the drive's velocity; the three fit in
  // 8 bytes). Else no TPDO2: one frame per drive and cycle less (docs/deployment.md#bus-load).
  const bool tpdo2_sent = cfg.tpdo2 || mc.tpdo2.torque != hal::PdoUse::off;
  mc.tpdo2.velocity = mc.tpdo2.error_code = tpdo2_sent ? hal::PdoUse::optional : hal::PdoUse::off;
  servo = std::make_unique<hal::CanopenServoBus>(*canbus, *clock, mc);
  if (servo->config_status() != hal::Status::ok)
    return std::string("bus: ") + hal::to_string(servo->config_status()) + (servo->last_error()[0] ? ": " : "") + servo->last_error();
  ik = std::make_unique<kin::IkModel>();
  ik_ready = kin::ik_prepare(chain, *ik) == kin::Status::ok && ik->method != kin::IkMethod::none;
  ctl = std::make_unique<Controller>(*servo, chain, controller_config());
  model = std::make_unique<ModelControl>();
  console = std::make_unique<Console>(*ctl, console_config(), ik_ready ? ik.get() : nullptr);
  if (const std::string e = console->load_frames(); !e.empty()) return "frames file refused: " + e;
  if (const std::string e = console->load_points(); !e.empty()) return "points file refused: " + e;
  return "";
}

std::string App::boot() {
  const hal::TimePoint now = clock->now();
  const hal::Status st = ctl->boot(now, now + static_cast<hal::Duration>(cfg.start_timeout_s * 1e9));
  if (st != hal::Status::ok) return std::string("drive bring-up failed: ") + hal::to_string(st) + ": " + servo->last_error();
  // The drives are up: what each can do and its rated torque are known. A part that cannot run
  // is off with its reason (dynamics_notes()); everything else runs.
  model->configure(chain, *servo, model_config());
  ctl->set_model(model.get());  // before the control thread starts
  return "";
}

}  // namespace servoarm::fw
