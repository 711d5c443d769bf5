// SPDX-License-Identifier: Apache-2.0
#include "servoarm/app/app.hpp"

#include <chrono>
#include <thread>

#include <algorithm>
#include <cmath>
#include <vector>

#include "servoarm/app/drive_factory.hpp"
#include "servoarm/lang/units.hpp"
#include "servoarm/kinematics/description.hpp"

namespace servoarm::fw {

ControllerConfig App::controller_config() const {
  ControllerConfig c;
  c.rate_hz = cfg.rate_hz;
  c.following_error = kConfigUnits.angle_in(cfg.following_error_deg);
  c.enable_timeout = cfg.enable_timeout_s;
  c.feedback_timeout = cfg.feedback_timeout_ms * 1e-3;
  c.drive_quick_stop = cfg.stop == "drive";
  c.drive_stop_timeout = cfg.drive_stop_timeout_s;
  c.unhomed_jog_scale = cfg.homing_unhomed_jog_pct / 100.0;
  (void)safety_envelope(cfg, chain, c.safety);  // validated in build(): [safety] -> SI (disabled when none)
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
    if (servo) m.rated_torque[ju] = servo->rated_torque(ju);  // joint side, as the drives came up
  }
  return m;
}

hal::HomingSpec App::homing_spec(int j) const { return fw::homing_spec(cfg, chain, j); }

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
  (void)safety_envelope(cfg, chain, c.safety);  // the service checks every planned move against it
  c.safety_checksum = safety_checksum(cfg, chain);  // [safety] and the description's capsules
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
  std::vector<DriveGroupPlan> plans;  // joints by (drive.family, interface)
  if (const std::string e = plan_drive_groups(cfg, n, plans); !e.empty()) return e;
  // [[output]]: each on a drive of the arm (its 60FEh:01 mapped in RPDO3 at bring-up)
  output_joint.clear();
  for (std::size_t i = 0; i < cfg.outputs.size(); ++i) {
    int jo = -1;
    for (const DriveGroupPlan& p : plans)
      for (std::size_t k = 0; k < p.joints.size(); ++k)
        if (p.ids[k] == cfg.outputs[i].node && (jo < 0 || p.can == cfg.can)) jo = p.joints[k];
    if (jo < 0)
      return "config: output[" + std::to_string(i + 1) + "].node: node " + std::to_string(cfg.outputs[i].node) +
             " is no drive of the arm (nodes " + std::to_string(plans.front().ids.front()) + ".." +
             std::to_string(plans.back().ids.back()) + ")";
    output_joint.push_back(jo);
  }
  // [safety] inputs: a drive input on a CiA 402 drive of the arm, a GPIO input only with libgpiod
  if (const std::string e = check_safety_input("safety.estop_input", cfg.safety_estop_input, plans); !e.empty()) return e;
  if (const std::string e = check_safety_input("safety.reduced_input", cfg.safety_reduced_input, plans); !e.empty())
    return e;
  // One bus per interface named; one group per (family, interface); the arm's ServoBus over them.
  servo = std::make_unique<hal::ArmServoBus>();
  buses.clear();
  for (const DriveGroupPlan& p : plans) {
    hal::CanBus* bus = nullptr;
    for (const auto& [name, b] : buses)
      if (name == p.can) bus = b;
    if (bus == nullptr) {
      if (const std::string e = open_bus(p, sim, bus); !e.empty()) return e;
      buses.emplace_back(p.can, bus);
    }
    std::unique_ptr<hal::DriveGroup> group;
    if (const std::string e = make_drive_group({cfg, chain, p, output_joint, *bus, *clock}, group); !e.empty()) return e;
    const std::vector<std::size_t> joints(p.joints.begin(), p.joints.end());
    if (servo->add_group(std::move(group), joints) != hal::Status::ok) return std::string("bus: ") + servo->last_error();
  }
  if (servo->config_status() != hal::Status::ok) return std::string("bus: ") + servo->last_error();
  ik = std::make_unique<kin::IkModel>();
  ik_ready = kin::ik_prepare(chain, *ik) == kin::Status::ok && ik->method != kin::IkMethod::none;
  ctl = std::make_unique<Controller>(*servo, chain, controller_config());
  estop_input = make_safety_input(cfg.safety_estop_input);
  reduced_input = make_safety_input(cfg.safety_reduced_input);
  // A simulated input rests released (a test asserts it: SimInput::set).
  if (auto* e = sim_input_of(estop_input.get()))
    e->set(cfg.safety_estop_input_active == "low" ? hal::InputLevel::high : hal::InputLevel::low);
  if (auto* r = sim_input_of(reduced_input.get()))
    r->set(cfg.safety_reduced_input_active == "low" ? hal::InputLevel::high : hal::InputLevel::low);
  SafetyInputs si;
  si.estop = estop_input.get();
  si.estop_active_low = cfg.safety_estop_input_active == "low";
  si.reduced = reduced_input.get();
  si.reduced_active_low = cfg.safety_reduced_input_active == "low";
  si.debounce = static_cast<hal::Duration>(cfg.safety_input_debounce_ms * 1e6);
  ctl->set_safety_inputs(si);
  model = std::make_unique<ModelControl>();
  console = std::make_unique<Console>(*ctl, console_config(), ik_ready ? ik.get() : nullptr);
  console->service().set_safety_stager(
      [this](const std::string& changes, SafetyProposal& out) { return stage_safety_change(changes, out); });
  if (const std::string e = console->load_frames(); !e.empty()) return "frames file refused: " + e;
  if (const std::string e = console->load_points(); !e.empty()) return "points file refused: " + e;
  McapSettings ms;  // `record mcap`: an absolute folder only (armfw resolves a relative record.dir)
  if (!cfg.record_dir.empty() && cfg.record_dir[0] == '/') ms.dir = cfg.record_dir;
  ms.rate_hz = std::min(cfg.record_rate_hz, cfg.rate_hz);
  ms.max_file_mb = cfg.record_max_file_mb;
  ms.max_files = cfg.record_max_files;
  ms.chunk_kb = static_cast<std::size_t>(cfg.record_chunk_kb);
  ms.priority = cfg.priority > 1 ? cfg.priority - 1 : 0;  // just below the control thread: sees every cycle
  console->service().set_mcap_settings(ms);
  return "";
}

std::string App::open_bus(const DriveGroupPlan& p, const SimFactory& sim, hal::CanBus*& bus) {
  bus = nullptr;
  if (cfg.can == "sim" && p.family != "cia402") {  // virtual drives of that family
    if (sim_group) bus = sim_group(*clock, p);
    if (bus == nullptr)
      return "drive.family: \"" + p.family + "\" with bus.can = \"sim\": no virtual " + p.family +
             " motors here (the virtual drives of armfw --sim are CiA 402)";
    return "";
  }
  if (cfg.can == "sim") {  // every interface named is an in-process bus of virtual drives
    if (sim) bus = sim(*clock, p.ids);
    if (bus == nullptr && p.can != cfg.can)
      return "drive.can: \"" + p.can + "\": no virtual drives for a second in-process bus (armfw --sim runs one)";
    if (bus == nullptr)
      return "bus.can: \"sim\" needs virtual drives (armfw --sim; this armfw was built without host_sim, or none were given)";
    return "";
  }
  auto sc = std::make_unique<hal::SocketCanBus>();
  hal::SocketCanOptions opt;
  opt.enable_fd = !cfg.drives.empty() && cfg.drives[static_cast<std::size_t>(p.joints.front())].can_fd;
  const hal::Status st = sc->open(p.can.c_str(), opt);
  if (st != hal::Status::ok) {
    const std::string m = sc->message();  // starts with the interface name
    return "bus.can: cannot open " + (m.rfind(p.can + ":", 0) == 0 ? m : p.can + ": " + m);
  }
  bus = sc.get();
  socketcan.push_back(std::move(sc));
  return "";
}

std::string App::check_safety_input(const char* key, const std::string& text,
                                    const std::vector<DriveGroupPlan>& plans) const {
  hal::InputSource src;
  char err[160];
  if (!hal::parse_input_source(text, src, err, sizeof err)) return std::string("config: ") + key + ": " + err;
  const std::string what = std::string("config: ") + key + ": \"" + text + "\": ";
  switch (src.kind) {
    case hal::InputKind::none:
    case hal::InputKind::sim: return "";
    case hal::InputKind::gpio:
      if (!hal::gpiod_available())
        return what + "this armfw was built without libgpiod (install libgpiod-dev and configure the build again)";
      return "";
    case hal::InputKind::drive:
      if (src.joint >= chain.n_joints)
        return what + "the robot has " + std::to_string(chain.n_joints) + " joints";
      for (const DriveGroupPlan& p : plans)
        for (int jo : p.joints)
          if (jo == src.joint && p.family != "cia402")
            return what + "joint " + std::to_string(src.joint + 1) + "'s drive is of the family " + p.family +
                   ", which reports no digital inputs (60FDh is CiA 402's): use a CiA 402 drive's input or a GPIO line";
      return "";
  }
  return "";
}

std::unique_ptr<hal::SafetyInput> App::make_safety_input(const std::string& text) const {
  hal::InputSource src;
  char err[160];
  if (!hal::parse_input_source(text, src, err, sizeof err)) return nullptr;  // (refused by build())
  const auto stale = static_cast<hal::Duration>(cfg.safety_input_timeout_ms * 1e6);
  switch (src.kind) {
    case hal::InputKind::none: return nullptr;
    case hal::InputKind::sim: return std::make_unique<hal::SimInput>(src.name);
    case hal::InputKind::drive: return std::make_unique<hal::DriveBitInput>(*servo, src.joint, src.bit, stale);
    case hal::InputKind::gpio: return std::make_unique<hal::GpiodInput>(src.chip, src.line, hal::kMillisecond, stale);
  }
  return nullptr;
}

std::string App::stage_safety_change(const std::string& changes, SafetyProposal& out) const {
  // Keys set at start only: the controller's reactions and the inputs' wiring are not part of
  // the monitor's envelope, which is all a run-time change replaces.
  static constexpr const char* kStartOnly[] = {
      "following_error_deg", "enable_timeout_s", "feedback_timeout_ms", "stop", "drive_stop_timeout_s",
      "estop_input", "estop_input_active", "reduced_input", "reduced_input_active", "input_debounce_ms",
      "input_timeout_ms"};
  std::string text = to_toml(cfg);
  const std::size_t sec = text.find("\n[safety]\n");
  if (sec == std::string::npos) return "no [safety] section to change";
  std::vector<std::string> keys;
  std::size_t a = 0;
  while (a <= changes.size()) {
    std::size_t b = changes.find_first_of(";\n", a);
    if (b == std::string::npos) b = changes.size();
    std::string item = changes.substr(a, b - a);
    a = b + 1;
    const auto trim = [](std::string s) {
      const std::size_t f = s.find_first_not_of(" \t\r");
      if (f == std::string::npos) return std::string();
      return s.substr(f, s.find_last_not_of(" \t\r") - f + 1);
    };
    item = trim(item);
    if (item.empty()) continue;
    const std::size_t eq = item.find('=');
    if (eq == std::string::npos) return "\"" + item + "\": a change is `key = value`";
    std::string key = trim(item.substr(0, eq));
    const std::string value = trim(item.substr(eq + 1));
    if (key.rfind("safety.", 0) == 0) key = key.substr(7);
    if (value.empty()) return "safety." + key + ": no value";
    for (const char* k : kStartOnly)
      if (key == k) return "safety." + key + " is set at start only: change it in the configuration file and restart";
    for (const std::string& k : keys)
      if (k == key) return "safety." + key + ": given twice";
    // its line in the [safety] section of the effective configuration
    const std::size_t at = text.find("\n" + key + " = ", sec + 1);
    const std::size_t next_sec = text.find("\n[", sec + 1);
    if (at == std::string::npos || (next_sec != std::string::npos && at > next_sec))
      return "safety." + key + ": no such key in [safety] (armfw --config-keys lists them)";
    const std::size_t end = text.find('\n', at + 1);
    text.replace(at + 1, end - at - 1, key + " = " + value);
    keys.push_back(key);
  }
  if (keys.empty()) return "no change given (`key = value`, `;` between)";
  FwConfig next;
  if (std::string e = load_config_text(text, "safety change", next, false); !e.empty()) return e;
  if (std::string e = validate_for_chain(next, chain); !e.empty()) return e;
  if (std::string e = safety_envelope(next, chain, out.safety); !e.empty()) return e;
  out.checksum = safety_checksum(next, chain);
  out.changes.clear();
  for (const ConfigKey& k : config_keys()) {
    const std::string name = k.name;
    if (name.rfind("safety.", 0) != 0) continue;
    const std::string was = value_text(k, cfg), now = value_text(k, next);
    if (was != now) out.changes += (out.changes.empty() ? "" : "; ") + name + " = " + was + " -> " + now;
  }
  // The App's configuration takes the safety.* values when the change is applied, so that the
  // next change starts from it (the other keys stay as they are).
  FwConfig* mine = const_cast<FwConfig*>(&cfg);
  out.commit = [mine, next] {
    for (const ConfigKey& k : config_keys())
      if (std::string(k.name).rfind("safety.", 0) == 0)
        std::visit([&](auto m) { (*mine).*m = next.*m; }, k.member);
  };
  return "";
}

hal::SimInput* App::sim_input_of(hal::SafetyInput* in) {
  return in != nullptr && std::string(in->source()).rfind("sim:", 0) == 0 ? static_cast<hal::SimInput*>(in) : nullptr;
}

hal::SimInput* App::sim_input(const std::string& name) const {
  for (hal::SafetyInput* in : {estop_input.get(), reduced_input.get()})
    if (in != nullptr && std::string(in->source()) == "sim:" + name) return static_cast<hal::SimInput*>(in);
  return nullptr;
}

std::string App::boot() {
  // A GPIO safety input's reading thread (its line is read from now on; lost until it is).
  // Its first reading is waited for (at most 100 ms), so that the first cycle does not take a
  // line not read yet for a lost one.
  for (hal::SafetyInput* in : {estop_input.get(), reduced_input.get()}) {
    if (in == nullptr || std::string(in->source()).rfind("gpio:", 0) != 0) continue;
    auto* g = static_cast<hal::GpiodInput*>(in);
    if (!g->start()) continue;
    for (int i = 0; i < 100 && g->polls() == 0; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
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
