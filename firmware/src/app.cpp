#include "servoarm/firmware/app.hpp"

#include <cmath>
#include <vector>

#include "servoarm/kinematics/description.hpp"

namespace servoarm::fw {

SimPlant::SimPlant(hal::Clock& clock, int joints, int first_node, const sim::MotorParams& motor) : clock_(clock) {
  bus_ = std::make_unique<hal::SimBus>(clock, 50 * hal::kMicrosecond);
  master_ep_ = bus_->open(4096);
  sim_ep_ = bus_->open(4096);
  std::vector<std::uint8_t> nodes;
  for (int j = 0; j < joints; ++j) nodes.push_back(static_cast<std::uint8_t>(first_node + j));
  arm_ = std::make_unique<sim::ArmSim>(*sim_ep_, nodes, motor, 7);
  arm_->power_on(clock.now());
}

SimPlant::~SimPlant() {
  stop_thread();
  arm_.reset();
  sim_ep_.reset();
  master_ep_.reset();
}

void SimPlant::apply_injections(hal::TimePoint now) {
  const int s = silent_.exchange(-1);
  if (s >= 0 && static_cast<std::size_t>(s) < arm_->size()) arm_->at(static_cast<std::size_t>(s)).faults().silent = true;
  const int h = hb_stop_.exchange(-1);
  if (h >= 0 && static_cast<std::size_t>(h) < arm_->size()) arm_->at(static_cast<std::size_t>(h)).faults().heartbeat_stopped = true;
  const int e = emcy_joint_.exchange(-1);
  if (e >= 0 && static_cast<std::size_t>(e) < arm_->size())
    arm_->at(static_cast<std::size_t>(e)).inject_emcy(emcy_code_.load(), now, *sim_ep_);
}

void SimPlant::step(hal::TimePoint now) {
  apply_injections(now);
  arm_->step(now);
}

void SimPlant::inject_silent(int joint) { silent_ = joint; }
void SimPlant::inject_heartbeat_stop(int joint) { hb_stop_ = joint; }
void SimPlant::inject_emcy(int joint, std::uint16_t code) {
  emcy_code_ = code;
  emcy_joint_ = joint;
}

void SimPlant::start_thread() {
  if (th_.joinable()) return;
  stop_ = false;
  th_ = std::thread([this] {
    while (!stop_.load(std::memory_order_relaxed)) {
      hal::CanFrame f;
      const hal::TimePoint now = clock_.now();
      apply_injections(now);
      // Wait up to 100 us for a frame, then hand everything pending to the drives.
      if (sim_ep_->receive(f, now + 100 * hal::kMicrosecond) == hal::Status::ok) {
        arm_->handle(f, clock_.now());
        for (int i = 0; i < 4096 && sim_ep_->receive(f, 0) == hal::Status::ok; ++i) arm_->handle(f, clock_.now());
      }
      arm_->tick(clock_.now());
    }
  });
}

void SimPlant::stop_thread() {
  stop_ = true;
  if (th_.joinable()) th_.join();
}

ControllerConfig App::controller_config() const {
  ControllerConfig c;
  c.rate_hz = cfg.rate_hz;
  c.following_error = cfg.following_error_deg * M_PI / 180.0;
  c.enable_timeout = cfg.enable_timeout_s;
  c.feedback_timeout = cfg.feedback_timeout_ms * 1e-3;
  return c;
}

ConsoleConfig App::console_config() const {
  ConsoleConfig c;
  c.default_joint_speed_pct = cfg.joint_speed_pct;
  c.default_linear_speed = cfg.linear_speed_mm_s * 1e-3;
  c.max_linear_speed = cfg.max_linear_speed_mm_s * 1e-3;
  c.cartesian.linear_velocity = c.max_linear_speed;
  if (!cfg.home_deg.empty()) {
    c.home = kin::JointVector::Zero(chain.n_joints);
    for (int j = 0; j < chain.n_joints; ++j) {
      const double v = cfg.home_deg[static_cast<std::size_t>(j)];
      c.home[j] = chain.joint(j).type == kin::JointType::prismatic ? v * 1e-3 : v * M_PI / 180.0;
    }
  }
  c.config_text = to_toml(cfg);
  return c;
}

std::string App::build(const FwConfig& c, hal::Clock* clock_override) {
  cfg = c;
  const std::string bad = validate(cfg);
  if (!bad.empty()) return "config: " + bad;
  if (clock_override != nullptr) clock = clock_override;
  kin::LoadResult lr = kin::load_robot(cfg.robot);
  if (!lr.ok) return "robot: " + lr.error;
  chain = lr.chain;
  const int n = chain.n_joints;
  if (n < 1 || n > static_cast<int>(hal::kMaxServoJoints)) return "robot: joint count not supported by the servo bus";
  if (!cfg.home_deg.empty() && static_cast<int>(cfg.home_deg.size()) != n)
    return "config: motion.home_deg: needs " + std::to_string(n) + " values for " + cfg.robot;
  if (cfg.first_node + n - 1 > 127) return "config: bus.first_node: node ids would exceed 127";
  hal::CanBus* canbus = nullptr;
  if (cfg.can == "sim") {
    plant = std::make_unique<SimPlant>(*clock, n, cfg.first_node, sim_motor);
    canbus = &plant->master_bus();
  } else {
    socketcan = std::make_unique<hal::SocketCanBus>();
    const hal::Status st = socketcan->open(cfg.can.c_str());
    if (st != hal::Status::ok) return "bus.can: cannot open " + cfg.can + ": " + socketcan->message();
    canbus = socketcan.get();
  }
  hal::CanopenMasterConfig mc;
  mc.joint_count = static_cast<std::size_t>(n);
  mc.heartbeat_period = static_cast<hal::Duration>(cfg.heartbeat_period_ms * 1e6);
  mc.heartbeat_timeout = static_cast<hal::Duration>(cfg.heartbeat_timeout_ms * 1e6);
  for (int j = 0; j < n; ++j) {
    auto& jc = mc.joints[static_cast<std::size_t>(j)];
    jc.node_id = static_cast<std::uint8_t>(cfg.first_node + j);
    jc.scaling.counts_per_unit = cfg.counts_per_rev;
    jc.scaling.gear_ratio = cfg.gear_ratio;
    jc.scaling.kind = chain.joint(j).type == kin::JointType::prismatic ? hal::JointScaling::Kind::prismatic
                                                                       : hal::JointScaling::Kind::revolute;
  }
  servo = std::make_unique<hal::CanopenServoBus>(*canbus, *clock, mc);
  if (servo->config_status() != hal::Status::ok) return std::string("bus: ") + hal::to_string(servo->config_status());
  ctl = std::make_unique<Controller>(*servo, chain, controller_config());
  console = std::make_unique<Console>(*ctl, console_config());
  return "";
}

std::string App::boot() {
  if (plant && !clock->simulated()) plant->start_thread();
  const hal::TimePoint now = clock->now();
  const hal::Status st = ctl->boot(now, now + static_cast<hal::Duration>(cfg.start_timeout_s * 1e9));
  if (st != hal::Status::ok) return std::string("drive bring-up failed: ") + hal::to_string(st) + ": " + servo->last_error();
  return "";
}

}  // namespace servoarm::fw
