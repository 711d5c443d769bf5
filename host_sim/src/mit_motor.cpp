// SPDX-License-Identifier: Apache-2.0
// Virtual MIT-mode actuators and their plant (mit_motor.hpp).
#include "servoarm/sim/mit_motor.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace servoarm::sim {

namespace mit = hal::mit;

VirtualMitMotor::VirtualMitMotor(const MitMotorSpec& s)
    : profile_(s.profile), vendor_(s.profile->vendor), fd_(s.fd), p_(s.params) {
  temp_ = p_.ambient;
  set_reg_f(mit::Reg::uv_value, 15.0f);
  set_reg_f(mit::Reg::kt_value, static_cast<float>(profile_->torque_constant));
  set_reg_f(mit::Reg::ot_value, static_cast<float>(profile_->temp_cutoff > 0 ? profile_->temp_cutoff : 100));
  set_reg(mit::Reg::mst_id, s.master);
  set_reg(mit::Reg::esc_id, s.id);
  set_reg(mit::Reg::timeout, 0);
  set_reg(mit::Reg::ctrl_mode, s.ctrl_mode);
  set_reg_f(mit::Reg::gr, static_cast<float>(profile_->gear_ratio));
  set_reg_f(mit::Reg::pmax, static_cast<float>(profile_->p_max));
  set_reg_f(mit::Reg::vmax, static_cast<float>(profile_->v_max));
  set_reg_f(mit::Reg::tmax, static_cast<float>(profile_->t_max));
}

float VirtualMitMotor::reg_f(mit::Reg r) const {
  float v;
  const std::uint32_t raw = reg(r);
  std::memcpy(&v, &raw, sizeof v);
  return v;
}

void VirtualMitMotor::set_reg_f(mit::Reg r, float v) {
  std::uint32_t raw;
  std::memcpy(&raw, &v, sizeof raw);
  set_reg(r, raw);
}

mit::Ranges VirtualMitMotor::ranges() const {
  return {reg_f(mit::Reg::pmax), reg_f(mit::Reg::vmax), reg_f(mit::Reg::tmax), profile_->kp_max, profile_->kd_max};
}

double VirtualMitMotor::wrapped() const {
  const double pm = ranges().p_max;
  return q_ - 2 * pm * std::floor((q_ + pm) / (2 * pm));
}

void VirtualMitMotor::inject_error(std::uint8_t code) {
  error_ = code;
  enabled_ = false;
}

void VirtualMitMotor::integrate_to(hal::TimePoint now) {
  if (t_ == 0 || now <= t_) {
    if (t_ == 0) t_ = now;
    return;
  }
  const mit::Ranges r = ranges();
  const double step = 1e-4;  // s
  double left = static_cast<double>(now - t_) * 1e-9;
  if (left > 1.0) left = 1.0;  // a long pause: the arm stood
  while (left > 0) {
    const double dt = std::min(step, left);
    left -= dt;
    double tau = 0;
    const std::uint32_t mode = vendor_ == mit::Vendor::damiao ? reg(mit::Reg::ctrl_mode) : mit::kModeMit;
    if (enabled_ && (mode == kModePosVel || mode == kModeVel)) {
      // the drive's own loops: position (mode 2, at most the frame's speed), then velocity
      const double vd = mode == kModeVel ? vel_v_ : std::clamp(kPosGain * (pv_p_ - wrapped()), -pv_v_, pv_v_);
      tau = std::clamp(p_.inertia / kVelTime * (vd - qd_) + p_.damping * vd, -r.t_max, r.t_max);
    } else if (enabled_) {
      tau = cmd_.kp * (cmd_.p - wrapped()) + cmd_.kd * (cmd_.v - qd_) + cmd_.t;
      tau = std::clamp(tau, -r.t_max, r.t_max);
    }
    tau_ = tau;
    qd_ += (tau + load_torque - p_.damping * qd_) / p_.inertia * dt;
    q_ += qd_ * dt;
    if (q_ < stop_lo) {
      q_ = stop_lo;
      qd_ = std::max(0.0, qd_);
    } else if (q_ > stop_hi) {
      q_ = stop_hi;
      qd_ = std::min(0.0, qd_);
    }
    temp_ += (p_.heating * tau * tau - (temp_ - p_.ambient) / p_.cooling_tau) * dt;
  }
  t_ = now;
}

void VirtualMitMotor::send_feedback(hal::TimePoint now, hal::CanBus& out) {
  mit::Feedback fb;
  fb.id = static_cast<std::uint8_t>(reg(mit::Reg::esc_id));
  fb.p = wrapped();
  fb.v = qd_;
  fb.t = tau_;
  fb.t_mos = temp_ - 5;
  fb.t_rotor = temp_;
  switch (vendor_) {
    case mit::Vendor::damiao: fb.error = error_ != 0 ? error_ : enabled_ ? 1 : 0; break;
    case mit::Vendor::cubemars:
    case mit::Vendor::robstride: fb.error = error_; break;
  }
  answer(mit::encode_feedback(vendor_, ranges(), reg(mit::Reg::mst_id), fb), now, out);
}

void VirtualMitMotor::answer(const hal::CanFrame& reply, hal::TimePoint now, hal::CanBus& out) {
  hal::CanFrame f = reply;
  f.fd = f.brs = fd_;
  if (quirks_.late > 0 && late_n_ < late_.size()) late_[late_n_++] = {f, now + quirks_.late};
  else if (quirks_.late <= 0) out.send(f);
}

void VirtualMitMotor::handle(const hal::CanFrame& f, hal::TimePoint now, hal::CanBus& out) {
  integrate_to(now);
  if (quirks_.silent || f.error || f.rtr || f.extended || f.fd != fd_) return;
  const auto id = static_cast<std::uint16_t>(reg(mit::Reg::esc_id));
  const std::uint32_t pv_id = 0x100u + id, vel_id = 0x200u + id;
  if (vendor_ == mit::Vendor::damiao && (f.id == pv_id || f.id == vel_id)) {
    // position-velocity / velocity frames: taken in their own control mode only
    std::uint16_t to = 0;
    double p = 0, v = 0;
    const std::uint32_t mode = reg(mit::Reg::ctrl_mode);
    if (f.id == pv_id ? mode != kModePosVel || !mit::unpack_pos_vel(f, to, p, v)
                           : mode != kModeVel || !mit::unpack_vel(f, to, v))
      return;
    last_rx_ = now;
    if (enabled_ && f.id == pv_id) {
      pv_p_ = p;
      pv_v_ = std::min(std::fabs(v), ranges().v_max);
    } else if (enabled_) {
      vel_v_ = std::clamp(v, -ranges().v_max, ranges().v_max);
    }
    send_feedback(now, out);
    return;
  }
  if (f.len != 8) return;
  if (f.id == mit::kRegisterId) {
    mit::RegMessage m;
    if (vendor_ != mit::Vendor::damiao || !mit::decode_register(f, m) || m.motor_id != id) return;
    last_rx_ = now;
    switch (m.cmd) {
      case mit::RegCmd::read:
        if (m.rid > mit::kLastReg) return;
        m.raw = regs_[m.rid];
        answer(mit::reg_reply(reg(mit::Reg::mst_id), m), now, out);
        return;
      case mit::RegCmd::write:
        if (m.rid > mit::kLastReg) return;
        if (!(m.rid == static_cast<std::uint8_t>(mit::Reg::ctrl_mode) && quirks_.mode_locked) && !enabled_) regs_[m.rid] = m.raw;
        answer(mit::reg_reply(reg(mit::Reg::mst_id), m), now, out);
        return;
      case mit::RegCmd::save: answer(mit::reg_reply(reg(mit::Reg::mst_id), m), now, out); return;
      case mit::RegCmd::refresh: send_feedback(now, out); return;
    }
    return;
  }
  if (f.id != id) return;
  last_rx_ = now;
  mit::Special s;
  if (mit::is_special(f, s)) {
    switch (s) {
      case mit::Special::enable:
        if (error_ == 0 && !enabled_) {
          enabled_ = true;
          pv_p_ = wrapped();  // the other modes hold where they are until their first frame
          pv_v_ = vel_v_ = 0;
        }
        break;
      case mit::Special::disable: enabled_ = false; break;
      case mit::Special::save_zero: q_ = 0; break;
      case mit::Special::clear_error: error_ = 0; break;
    }
    send_feedback(now, out);
    return;
  }
  if (vendor_ == mit::Vendor::damiao && reg(mit::Reg::ctrl_mode) != mit::kModeMit) return;  // not its frame: no answer
  mit::Command c;
  if (!mit::unpack_command(ranges(), f, c)) return;
  ++mit_frames_;
  if (enabled_) cmd_ = c;
  send_feedback(now, out);
}

void VirtualMitMotor::tick(hal::TimePoint now, hal::CanBus& out) {
  integrate_to(now);
  const auto timeout = static_cast<hal::Duration>(reg(mit::Reg::timeout)) * static_cast<hal::Duration>(mit::kTimeoutUnitNs);
  if (enabled_ && timeout > 0 && last_rx_ != 0 && now - last_rx_ > timeout) inject_error(0xD);
  if (error_ == 0 && temp_ >= reg_f(mit::Reg::ot_value)) inject_error(0xC);
  std::size_t keep = 0;
  for (std::size_t i = 0; i < late_n_; ++i) {
    if (late_[i].due <= now) out.send(late_[i].f);
    else late_[keep++] = late_[i];
  }
  late_n_ = keep;
}

MitPlant::MitPlant(hal::Clock& clock, const std::vector<MitMotorSpec>& motors) : clock_(clock) {
  bus_ = std::make_unique<hal::SimBus>(clock, 50 * hal::kMicrosecond);
  master_ep_ = bus_->open(4096);
  sim_ep_ = bus_->open(4096);
  for (const MitMotorSpec& s : motors) motors_.push_back(std::make_unique<VirtualMitMotor>(s));
}

MitPlant::~MitPlant() { stop_thread(); }

void MitPlant::step(hal::TimePoint now) {
  hal::CanFrame f;
  for (int i = 0; i < 4096 && sim_ep_->receive(f, 0) == hal::Status::ok; ++i) {
    const hal::TimePoint at = f.rx_time != 0 && f.rx_time <= now ? f.rx_time : now;
    for (auto& m : motors_) m->tick(at, *sim_ep_);
    for (auto& m : motors_) m->handle(f, at, *sim_ep_);
  }
  for (auto& m : motors_) m->tick(now, *sim_ep_);
}

void MitPlant::start_thread() {
  if (th_.joinable()) return;
  stop_ = false;
  th_ = std::thread([this] {
    while (!stop_.load(std::memory_order_relaxed)) {
      hal::CanFrame f;
      if (sim_ep_->receive(f, clock_.now() + 100 * hal::kMicrosecond) == hal::Status::ok) {
        const hal::TimePoint at = f.rx_time != 0 ? f.rx_time : clock_.now();
        for (auto& m : motors_) m->handle(f, at, *sim_ep_);
      }
      for (auto& m : motors_) m->tick(clock_.now(), *sim_ep_);
    }
  });
}

void MitPlant::stop_thread() {
  stop_ = true;
  if (th_.joinable()) th_.join();
}

}  // namespace servoarm::sim
