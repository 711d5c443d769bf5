// SPDX-License-Identifier: Apache-2.0
// The MIT-mode drive family (mit_group.hpp): bring-up over the Damiao registers, one MIT frame
// per motor and cycle, feedback with the multi-turn unwrap, temperatures and the joint mapping.
#include "servoarm/hal/mit_group.hpp"

#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstring>

namespace servoarm::hal {

namespace {
constexpr double kMicro = 1e-6;
bool finite_positive(double x) { return std::isfinite(x) && x > 0; }
}  // namespace

MitGroup::MitGroup(CanBus& bus, Clock& clock, const MitGroupConfig& cfg) : bus_(bus), clock_(clock), cfg_(cfg) {
  if (cfg_.joint_count == 0 || cfg_.joint_count > kMaxServoJoints) {
    config_status_ = Status::capacity;
    std::snprintf(error_, sizeof error_, "%s: %zu joints (1..%zu per group)", family(), cfg_.joint_count, kMaxServoJoints);
    return;
  }
  Status& st = config_status_;
  const Status bad = Status::invalid_argument;
  for (std::size_t j = 0; j < cfg_.joint_count && st == Status::ok; ++j) {
    const MitJointConfig& c = cfg_.joints[j];
    if (c.profile == nullptr) st = refuse(j, bad, "no motor model (drive.motor)");
    else if (c.profile->vendor != cfg_.vendor)
      st = refuse(j, bad, "%s is a %s motor, not %s", c.profile->name, mit::to_string(c.profile->vendor), family());
    else if (!c.scaling.valid()) st = refuse(j, bad, "gear ratio and direction give no usable mapping");
    else if (!(c.kp >= 0 && c.kp <= c.profile->kp_max) || !(c.kd >= 0 && c.kd <= c.profile->kd_max))
      st = refuse(j, bad, "kp %g / kd %g outside the %s's 0..%g / 0..%g", c.kp, c.kd, c.profile->name, c.profile->kp_max,
                  c.profile->kd_max);
    else if (c.motor_id == 0 || c.motor_id >= mit::kRegisterId)
      st = refuse(j, bad, "motor id 0x%03X outside 0x001..0x7FE", unsigned(c.motor_id));
    for (std::size_t i = 0; i < j && st == Status::ok; ++i) {
      if (cfg_.joints[i].motor_id == c.motor_id)
        st = refuse(j, bad, "motor id 0x%02X is joint %zu's too", unsigned(c.motor_id), arm_joint(i));
      else if (cfg_.vendor == mit::Vendor::damiao && master(i) == master(j))  // the others tell by byte 0
        st = refuse(j, bad, "master id 0x%03X is joint %zu's too: their feedback could not be told apart",
                    unsigned(master(j)), arm_joint(i));
      else if (master(j) == cfg_.joints[i].motor_id || master(i) == c.motor_id)
        st = refuse(j, bad, "master id 0x%03X clashes with joint %zu's motor id",
                    unsigned(master(j) == cfg_.joints[i].motor_id ? master(j) : master(i)), arm_joint(i));
    }
  }
  for (std::size_t j = 0; j < cfg_.joint_count && st == Status::ok; ++j) {
    Joint& J = joints_[j];
    const MitJointConfig& c = cfg_.joints[j];
    J.r = mit::ranges_of(*c.profile);
    J.k = c.scaling.direction * c.scaling.counts_per_si() * kMicro;
    J.zero = c.scaling.zero_offset * kMicro;
    const double kd = std::isfinite(c.stop_damping) && c.stop_damping > 0 ? c.stop_damping / (J.k * J.k) : 0.0;
    J.stop_kd_rest = std::max(0.0, kd - J.r.kd_max);  // the hold frame carries KD_MAX itself
  }
}

std::uint16_t MitGroup::master(std::size_t j) const {
  const MitJointConfig& c = cfg_.joints[j];
  if (c.master_id != MitJointConfig::kDefaultMaster) return c.master_id;
  switch (cfg_.vendor) {
    case mit::Vendor::damiao: return static_cast<std::uint16_t>(c.motor_id + 0x10);
    case mit::Vendor::cubemars: return 0x000;
    case mit::Vendor::robstride: return 0x0FD;
  }
  return 0;
}

void MitGroup::joint_name(std::size_t j, char* buf, std::size_t size) const {
  if (size == 0) return;
  const unsigned id = j < cfg_.joint_count ? cfg_.joints[j].motor_id : 0;
  std::snprintf(buf, size, "joint %zu (%s id 0x%02X)", arm_joint(j), family(), id);
}

double MitGroup::rated_torque(std::size_t j) const {
  return j < cfg_.joint_count ? joints_[j].r.t_max * std::fabs(joints_[j].k) : 0.0;
}

double MitGroup::resolution(std::size_t j) const {
  const Joint& J = joints_[j < cfg_.joint_count ? j : 0];
  return 2.0 * J.r.p_max / 65535.0 / std::fabs(J.k);
}

void MitGroup::note_error(const char* text) { std::snprintf(error_, sizeof error_, "%s", text); }

Status MitGroup::refuse(std::size_t j, Status why, const char* fmt, ...) {
  char name[48];
  joint_name(j, name, sizeof name);
  char what[200];
  va_list ap;
  va_start(ap, fmt);
  std::vsnprintf(what, sizeof what, fmt, ap);
  va_end(ap);
  std::snprintf(error_, sizeof error_, "%s: %s", name, what);
  return why;
}

Status MitGroup::send(const CanFrame& f) {
  if (!cfg_.fd) return bus_.send(f);
  CanFrame x = f;
  x.fd = x.brs = true;
  return bus_.send(x);
}

bool MitGroup::is_feedback_of(std::size_t j, const CanFrame& f) const {
  if (f.error || f.rtr || f.extended || f.id != master(j) || f.len < 6) return false;
  const std::uint16_t id = cfg_.joints[j].motor_id;
  switch (cfg_.vendor) {
    case mit::Vendor::damiao: return f.len == 8 && (f.data[0] & 0x0Fu) == (id & 0x0Fu);
    case mit::Vendor::cubemars:
    case mit::Vendor::robstride: return f.data[0] == (id & 0xFFu);
  }
  return false;
}

// ---- Bring-up ----------------------------------------------------------------------------

template <class Match>
bool MitGroup::ask(const CanFrame& req, Match&& match, TimePoint deadline) {
  for (int a = 0; a < cfg_.attempts; ++a) {
    if (!is_ok(send(req))) return false;
    const TimePoint until = std::min(deadline, clock_.now() + cfg_.reply_timeout);
    for (;;) {
      CanFrame f;
      while (bus_.receive(f, 0) == Status::ok)
        if (match(f)) return true;
      const TimePoint now = clock_.now();
      if (now >= until) break;
      clock_.sleep_until(std::min(now + 200 * kMicrosecond, until));
    }
    if (clock_.now() >= deadline) return false;
  }
  return false;
}

bool MitGroup::reg_read(std::size_t j, mit::Reg rid, std::uint32_t& raw, std::uint32_t& answered_on, TimePoint deadline) {
  const std::uint16_t id = cfg_.joints[j].motor_id;
  const auto r = static_cast<std::uint8_t>(rid);
  return ask(mit::reg_read(id, r),
             [&](const CanFrame& f) {
               mit::RegMessage m;
               if (f.id == mit::kRegisterId || f.len != 8 || !mit::decode_register(f, m)) return false;
               if (m.motor_id != id || m.cmd != mit::RegCmd::read || m.rid != r) return false;
               raw = m.raw;
               answered_on = f.id;
               return true;
             },
             deadline);
}

bool MitGroup::reg_write(std::size_t j, mit::Reg rid, std::uint32_t raw, TimePoint deadline) {
  const std::uint16_t id = cfg_.joints[j].motor_id;
  const auto r = static_cast<std::uint8_t>(rid);
  return ask(mit::reg_write_u32(id, r, raw),
             [&](const CanFrame& f) {
               mit::RegMessage m;
               return f.id == master(j) && f.len == 8 && mit::decode_register(f, m) && m.motor_id == id &&
                      m.cmd == mit::RegCmd::write && m.rid == r;
             },
             deadline);
}

Status MitGroup::bring_up(std::size_t j, TimePoint deadline) {
  Joint& J = joints_[j];
  const MitJointConfig& c = cfg_.joints[j];
  const unsigned wait_ms = static_cast<unsigned>(cfg_.attempts * cfg_.reply_timeout / kMillisecond);
  double cutoff = c.profile->temp_cutoff;
  if (cfg_.vendor == mit::Vendor::damiao) {
    std::uint32_t mode = 0, on = 0;
    if (!reg_read(j, mit::Reg::ctrl_mode, mode, on, deadline))
      return refuse(j, Status::timeout,
                    "no answer to a register read (CTRL_MODE) on 0x7FF in %u ms: the motor is not on this bus at this "
                    "bitrate and frame format (classic CAN / CAN FD), not powered, or has another id",
                    wait_ms);
    if (on != master(j)) {
      for (std::size_t i = 0; i < cfg_.joint_count; ++i)
        if (i != j && master(i) == on)
          return refuse(j, Status::protocol_error,
                        "answers on 0x%03X, joint %zu's master id (configured 0x%03X): master id clash, their "
                        "feedback cannot be told apart; write its MST_ID to 0x%03X",
                        unsigned(on), arm_joint(i), unsigned(master(j)), unsigned(master(j)));
      return refuse(j, Status::protocol_error,
                    "answers on 0x%03X, configured master id 0x%03X: set drive.master_id = 0x%03X or write the motor's "
                    "MST_ID",
                    unsigned(on), unsigned(master(j)), unsigned(on));
    }
    std::uint32_t raw[3] = {};
    const mit::Reg lim[3] = {mit::Reg::pmax, mit::Reg::vmax, mit::Reg::tmax};
    double got[3] = {};
    for (int i = 0; i < 3; ++i) {
      if (!reg_read(j, lim[i], raw[i], on, deadline))
        return refuse(j, Status::timeout, "no answer to a register read (%s)", mit::reg_name(static_cast<std::uint8_t>(lim[i])));
      float v;
      std::memcpy(&v, &raw[i], sizeof v);
      got[i] = v;
      if (!finite_positive(got[i]))
        return refuse(j, Status::protocol_error, "%s reads %g: no usable range", mit::reg_name(static_cast<std::uint8_t>(lim[i])),
                      got[i]);
    }
    const double prof[3] = {c.profile->p_max, c.profile->v_max, c.profile->t_max};
    for (int i = 0; i < 3; ++i)
      if (std::fabs(got[i] - prof[i]) > 1e-3 * prof[i]) {
        const std::size_t n = std::strlen(notes_);
        char name[48];
        joint_name(j, name, sizeof name);
        std::snprintf(notes_ + n, sizeof notes_ - n, "%s: %s reads %g, the %s profile says %g: frames use the motor's\n",
                      name, mit::reg_name(static_cast<std::uint8_t>(lim[i])), got[i], c.profile->name, prof[i]);
      }
    J.r.p_max = got[0];
    J.r.v_max = got[1];
    J.r.t_max = got[2];
    std::uint32_t ot = 0;
    if (reg_read(j, mit::Reg::ot_value, ot, on, deadline)) {
      float v;
      std::memcpy(&v, &ot, sizeof v);
      if (finite_positive(v)) cutoff = v;
    }
    if (mode != mit::kModeMit) {
      if (!cfg_.set_mode)
        return refuse(j, Status::drive_refused, "control mode %u (%s), not MIT (1): it answers no MIT frame in that mode",
                      unsigned(mode), mit::ctrl_mode_name(mode));
      std::uint32_t again = 0;
      if (!reg_write(j, mit::Reg::ctrl_mode, mit::kModeMit, deadline) ||
          !reg_read(j, mit::Reg::ctrl_mode, again, on, deadline) || again != mit::kModeMit)
        return refuse(j, Status::drive_refused,
                      "control mode %u (%s), not MIT (1), and CTRL_MODE = 1 did not take: in that mode it answers no "
                      "MIT frame; set it to MIT with the Damiao tool",
                      unsigned(mode), mit::ctrl_mode_name(mode));
    }
    const auto counts = static_cast<std::uint32_t>(cfg_.motor_timeout / static_cast<Duration>(mit::kTimeoutUnitNs));
    std::uint32_t back = 0;
    if (!reg_write(j, mit::Reg::timeout, counts, deadline) || !reg_read(j, mit::Reg::timeout, back, on, deadline) ||
        back != counts)
      return refuse(j, Status::drive_refused,
                    "its CAN timeout (TIMEOUT = %u x 50 us) did not take (reads %u): it would not stop when armfw stops "
                    "talking",
                    unsigned(counts), unsigned(back));
  }
  if (cutoff <= 0) cutoff = 80;  // no published cut-off: stay well below what windings take
  J.temp_fault = c.temp_fault > 0 ? c.temp_fault : cutoff - 5;
  J.temp_warning = c.temp_warning > 0 ? c.temp_warning : cutoff - 15;
  J.temp_cutoff = cutoff;
  // the start position (and proof the motor takes frames on its id)
  mit::Feedback m;
  const bool got = ask(mit::special_frame(c.motor_id, mit::Special::disable),
                       [&](const CanFrame& f) { return is_feedback_of(j, f) && mit::decode_feedback(cfg_.vendor, J.r, f, m); },
                       deadline);
  if (!got) {
    if (cfg_.vendor == mit::Vendor::damiao)
      return refuse(j, Status::timeout, "its registers answer but no feedback came to a disable frame on 0x%03X in %u ms",
                    unsigned(c.motor_id), wait_ms);
    return refuse(j, Status::timeout,
                  "no answer to a disable frame on 0x%03X in %u ms (expected on 0x%03X): not on this bus at this bitrate "
                  "and frame format, not powered, another id, or another master id",
                  unsigned(c.motor_id), wait_ms, unsigned(master(j)));
  }
  J.unwrap.reset();
  take_feedback(j, m, clock_.now());
  return Status::ok;
}

Status MitGroup::family_start(TimePoint deadline) {
  if (config_status_ != Status::ok) return config_status_;
  started_ = false;
  notes_[0] = '\0';
  error_[0] = '\0';
  for (std::size_t j = 0; j < cfg_.joint_count; ++j) {
    Joint& J = joints_[j];
    const mit::Ranges keep = mit::ranges_of(*cfg_.joints[j].profile);
    const double k = J.k, zero = J.zero, stop_kd_rest = J.stop_kd_rest;
    J = Joint{};
    J.r = keep;
    J.k = k;
    J.zero = zero;
    J.stop_kd_rest = stop_kd_rest;
    fb_[j] = JointFeedback{};
    fb_[j].has_torque = true;
  }
  CanFrame drop;
  while (bus_.receive(drop, 0) == Status::ok) {
  }
  for (std::size_t j = 0; j < cfg_.joint_count; ++j)
    if (const Status s = bring_up(j, deadline); s != Status::ok) return s;
  started_ = true;
  return Status::ok;
}

// ---- The cycle ---------------------------------------------------------------------------

void MitGroup::fault(std::size_t j, Status why, std::uint16_t code, TimePoint now) {
  JointFeedback& fb = fb_[j];
  if (fb.state != JointState::fault) fb.fault_since = now;
  fb.state = JointState::fault;
  fb.fault = why;
  fb.error_code = code;
  Joint& J = joints_[j];
  if (J.mode != CyclicMode::position) {
    J.mode = CyclicMode::position;
    J.mode_status = why;
  }
  J.enabling_since = 0;
}

void MitGroup::take_feedback(std::size_t j, const mit::Feedback& m, TimePoint now) {
  Joint& J = joints_[j];
  JointFeedback& fb = fb_[j];
  J.p_act = J.unwrap.update(m.p, J.r.p_max);
  fb.position = (J.p_act - J.zero) / J.k;
  fb.velocity = m.v / J.k;
  fb.torque = m.t * J.k;
  fb.has_torque = true;
  fb.valid = true;
  fb.last_feedback = fb.sampled = now;
  fb.drive_state = m.error;
  fb.statusword = m.error;
  J.v_act = m.v;
  J.t_act = m.t;
  J.t_mos = m.t_mos;
  J.t_rotor = m.t_rotor;
  J.error = m.error;
  const double hottest = std::max(m.t_mos, m.t_rotor);
  J.hot = hottest >= J.temp_warning;
  fb.has_temperature = true;
  fb.temperature = hottest;
  fb.temperature_warning = J.temp_warning;
  fb.temperature_limit = J.temp_fault;
  fb.temperature_cutoff = J.temp_cutoff;
  // enable() after a fault: the answers sent before the clear-error frame still carry the old
  // error; the state follows the answer to the clear-error frame
  if (J.clear) return;
  if (hottest >= J.temp_fault) J.overheated = true;
  if (fb.state == JointState::fault) return;  // latched until enable()
  if (J.overheated) {
    fault(j, Status::drive_fault, 0xF000u | static_cast<std::uint16_t>(hottest), now);
    std::snprintf(error_, sizeof error_, "joint %zu (%s id 0x%02X): %.0f deg C, at or above its fault temperature %.0f deg C",
                  arm_joint(j), family(), unsigned(cfg_.joints[j].motor_id), hottest, J.temp_fault);
    return;
  }
  bool on = false;
  switch (cfg_.vendor) {
    case mit::Vendor::damiao:
      if (mit::damiao_is_fault(m.error)) {
        fault(j, Status::drive_fault, m.error, now);
        std::snprintf(error_, sizeof error_, "joint %zu (damiao id 0x%02X): motor error 0x%X: %s", arm_joint(j),
                      unsigned(cfg_.joints[j].motor_id), unsigned(m.error), mit::damiao_error_name(m.error));
        return;
      }
      on = m.error == 1;
      break;
    case mit::Vendor::cubemars:
    case mit::Vendor::robstride:
      if (m.error != 0) {
        fault(j, Status::drive_fault, m.error, now);
        std::snprintf(error_, sizeof error_, "joint %zu (%s id 0x%02X): motor error code %u", arm_joint(j), family(),
                      unsigned(cfg_.joints[j].motor_id), unsigned(m.error));
        return;
      }
      on = J.want && J.answered;  // no state in the frame: the enable frame was answered
      break;
  }
  if (J.qstop && !on) {  // the motor dropped out of its hold by itself (its own watchdog): powered down
    J.qstop = false;
    J.want = false;
  }
  if (on && J.want) {
    fb.state = J.qstop ? JointState::stopping : JointState::enabled;
    J.enabling_since = 0;
  } else if (on) {
    fb.state = JointState::stopping;
  } else {
    fb.state = J.want ? JointState::enabling : JointState::disabled;
  }
}

Status MitGroup::family_read(TimePoint now) {
  if (!started_) return Status::not_configured;
  CanFrame f;
  Status io = Status::ok;
  for (int i = 0; i < 512; ++i) {
    const Status s = bus_.receive(f, 0);
    if (s == Status::timeout) break;
    if (s != Status::ok) {
      io = s;
      break;
    }
    for (std::size_t j = 0; j < cfg_.joint_count; ++j) {
      mit::Feedback m;
      if (is_feedback_of(j, f) && mit::decode_feedback(cfg_.vendor, joints_[j].r, f, m)) {
        if (joints_[j].enable_sent) joints_[j].answered = joints_[j].want;  // the answer to an enable frame
        joints_[j].enable_sent = false;
        take_feedback(j, m, f.rx_time != 0 && f.rx_time <= now ? f.rx_time : now);
        break;
      }
    }
  }
  Status first = io;
  // A bus-off controller reaches no motor: every joint faults with that reason.
  const bool bus_off = bus_.stats().state == ErrorState::bus_off;
  for (std::size_t j = 0; j < cfg_.joint_count; ++j) {
    JointFeedback& fb = fb_[j];
    fb.age = fb.last_feedback != 0 ? now - fb.last_feedback : -1;
    if (bus_off && fb.state != JointState::fault) {
      fault(j, Status::bus_off, 0, now);
      std::snprintf(error_, sizeof error_, "joint %zu (%s id 0x%02X): the CAN controller is bus-off", arm_joint(j),
                    family(), unsigned(cfg_.joints[j].motor_id));
    }
    if (fb.state != JointState::fault && fb.last_feedback != 0 && now - fb.last_feedback > cfg_.feedback_timeout) {
      fault(j, Status::heartbeat_lost, 0, now);
      std::snprintf(error_, sizeof error_, "joint %zu (%s id 0x%02X): no feedback for %lld ms (lost communication)",
                    arm_joint(j), family(), unsigned(cfg_.joints[j].motor_id),
                    static_cast<long long>((now - fb.last_feedback) / kMillisecond));
    }
    if (fb.state == JointState::enabling && joints_[j].enabling_since != 0 &&
        now - joints_[j].enabling_since > cfg_.state_timeout) {
      fault(j, Status::drive_refused, 0, now);
      std::snprintf(error_, sizeof error_, "joint %zu (%s id 0x%02X): did not take the enable frame in %lld ms", arm_joint(j),
                    family(), unsigned(cfg_.joints[j].motor_id), static_cast<long long>(cfg_.state_timeout / kMillisecond));
    }
    if (first == Status::ok && fb.state == JointState::fault) first = fb.fault;
    if (joints_[j].mode == CyclicMode::leaving_torque && !joints_[j].hold) joints_[j].mode = CyclicMode::position;
  }
  return first;
}

Status MitGroup::family_write(std::span<const double> setpoints, TimePoint now) {
  if (!started_) return Status::not_configured;
  if (setpoints.size() != cfg_.joint_count) return Status::invalid_argument;
  Status result = Status::ok;
  for (std::size_t j = 0; j < cfg_.joint_count; ++j) {
    Joint& J = joints_[j];
    JointFeedback& fb = fb_[j];
    const MitJointConfig& c = cfg_.joints[j];
    CanFrame f;
    if (J.want && J.clear) {
      f = mit::special_frame(c.motor_id, mit::Special::clear_error);
      J.clear = false;
    } else if (!J.want || fb.state == JointState::fault) {
      f = mit::special_frame(c.motor_id, mit::Special::disable);
      J.sent = {};
      J.answered = false;
      J.qstop = false;
    } else if (J.qstop) {
      // Damping first: the set point follows the measured position (kp pulls at nothing), KD_MAX
      // brakes the joint without overshoot whatever its inertia; once it is at rest the set point
      // stays there and kp holds it.
      if (!J.qstop_rest) {
        J.qstop_at = J.p_act;
        J.qstop_rest = std::fabs(J.v_act) <= rest_band(J);
      }
      const double wrap = static_cast<double>(J.unwrap.turns()) * 2.0 * J.r.p_max;
      // the model's torque at the measured pose when the controller gives one (gravity and its
      // braking torque), else the torque the motor measured when the stop began; without the
      // model's torque (a velocity feed-forward comes with torque 0: model_torque_) the stop
      // damping beyond KD_MAX brakes it from the measured velocity until it is at rest
      // (MitJointConfig::stop_damping)
      const double brake = model_torque_ || J.qstop_rest ? 0.0 : J.stop_kd_rest * J.v_act;
      const double t = std::clamp((J.ff ? J.ff_t : J.qstop_t) - brake, -J.r.t_max, J.r.t_max);
      const mit::Command cmd{J.qstop_at - wrap, 0, c.kp, J.r.kd_max, t};
      mit::pack_command(J.r, c.motor_id, cmd, f);
      J.sent = cmd;
      J.ff = false;
    } else if (fb.state != JointState::enabled) {
      f = mit::special_frame(c.motor_id, mit::Special::enable);
      if (J.enabling_since == 0) J.enabling_since = now;
      J.enable_sent = true;
    } else {
      const double wrap = static_cast<double>(J.unwrap.turns()) * 2.0 * J.r.p_max;
      mit::Command cmd{J.p_act - wrap, 0, c.kp, c.kd, 0};
      if (J.hold) {
        cmd.p = J.hold_at - wrap;
        J.hold = false;
      } else if (J.mode == CyclicMode::torque || J.mode == CyclicMode::entering_torque) {
        J.mode = CyclicMode::torque;
        cmd.kp = 0;  // free-drive: the motor damps the hand's motion itself
        if (J.torque_kd >= 0) cmd.kd = J.torque_kd;
        cmd.t = J.target_t / J.k - J.torque_kd_rest * J.v_act;
      } else if (std::isfinite(setpoints[j])) {
        cmd.p = J.zero + J.k * setpoints[j] - wrap;
        if (J.ff) {
          cmd.v = J.ff_v;
          cmd.t = J.ff_t;
        }
        // Near the wrap (+-P_MAX) the motor may cross it before this frame arrives: its
        // kp (p - q) would then see an error of 2 P_MAX. There the same law goes out as
        // kp = 0, v = v_ff + kp / kd x (p - q) (computed on the unwrapped position), which
        // does not depend on where the motor wraps.
        const double edge = J.r.p_max - std::max(0.05, 4e-3 * std::fabs(fb.velocity * J.k));
        if (c.kd > 0 && (std::fabs(J.p_act - wrap) > edge || std::fabs(cmd.p) > edge)) {
          cmd.v += c.kp / c.kd * (J.zero + J.k * setpoints[j] - J.p_act);
          cmd.kp = 0;
        }
      } else {
        result = Status::invalid_argument;  // holds where it stands
      }
      J.ff = false;
      if (!mit::pack_command(J.r, c.motor_id, cmd, f)) {
        result = Status::invalid_argument;
        cmd = {J.p_act - wrap, 0, c.kp, c.kd, 0};
        mit::pack_command(J.r, c.motor_id, cmd, f);
      }
      J.sent = cmd;
    }
    const Status s = send(f);
    if (!is_ok(s) && result == Status::ok) result = s;
  }
  return result;
}

void MitGroup::enable() {
  const TimePoint now = clock_.now();
  for (std::size_t j = 0; j < cfg_.joint_count; ++j) {
    Joint& J = joints_[j];
    JointFeedback& fb = fb_[j];
    J.want = true;
    if (J.qstop) {  // holding after quick_stop(): back to the setpoints through the enable frame
      J.qstop = false;
      if (fb.state == JointState::stopping) fb.state = JointState::enabling;
    }
    if (fb.state == JointState::fault) {
      J.clear = true;
      J.overheated = false;
      J.enabling_since = 0;
      fb.state = JointState::enabling;
      fb.fault = Status::ok;
      fb.error_code = 0;
      fb.last_feedback = now;  // the watchdog counts from here
    } else if (fb.state == JointState::disabled || fb.state == JointState::offline) {
      fb.state = JointState::enabling;
    }
  }
}

void MitGroup::quick_stop() {
  for (std::size_t j = 0; j < cfg_.joint_count; ++j) {
    Joint& J = joints_[j];
    JointFeedback& fb = fb_[j];
    if (!J.want || J.qstop || (fb.state != JointState::enabled && fb.state != JointState::stopping)) {
      if (!J.qstop) J.want = false;  // not powered: powered down as disable() does
      if (fb.state == JointState::enabling) fb.state = JointState::stopping;
      continue;
    }
    J.qstop = true;
    J.qstop_rest = false;
    J.qstop_at = J.p_act;
    J.qstop_t = std::clamp(std::isfinite(J.t_act) ? J.t_act : 0.0, -J.r.t_max, J.r.t_max);
    J.hold = false;
    J.enabling_since = 0;
    if (J.mode != CyclicMode::position) {
      J.mode = CyclicMode::position;
      J.mode_status = Status::aborted;
    }
    fb.state = JointState::stopping;
  }
}

double MitGroup::rest_band(const Joint& J) {
  return std::max(0.05, 8.0 * J.r.v_max / 4095.0);  // rad/s, actuator: at least four codes of the velocity
}

bool MitGroup::holding(std::size_t j) const {
  if (j >= cfg_.joint_count) return false;
  const Joint& J = joints_[j];
  return J.qstop && J.qstop_rest && fb_[j].state == JointState::stopping && std::fabs(J.v_act) <= rest_band(J);
}

void MitGroup::disable() {
  for (std::size_t j = 0; j < cfg_.joint_count; ++j) disable_joint(j);
}

void MitGroup::disable_joint(std::size_t j) {
  if (j >= cfg_.joint_count) return;
  Joint& J = joints_[j];
  J.want = false;
  J.qstop = false;
  J.clear = false;
  J.enabling_since = 0;
  if (J.mode != CyclicMode::position) {
    J.mode = CyclicMode::position;
    J.mode_status = Status::aborted;
  }
  if (fb_[j].state == JointState::enabled || fb_[j].state == JointState::enabling) fb_[j].state = JointState::stopping;
}

Status MitGroup::set_position_zero(std::size_t j) {
  if (j >= cfg_.joint_count) return Status::invalid_argument;
  const JointFeedback& fb = fb_[j];
  if (!fb.valid) return Status::not_configured;
  if (fb.state == JointState::enabled || fb.state == JointState::enabling || fb.state == JointState::stopping)
    return Status::bad_state;
  Joint& J = joints_[j];
  J.zero = J.p_act;
  cfg_.joints[j].scaling.zero_offset = static_cast<std::int32_t>(std::llround(J.zero / kMicro));
  fb_[j].position = 0;
  return Status::ok;
}

double MitGroup::shift_zero(std::size_t j, double at, double reads) {
  Joint& J = joints_[j];
  J.zero += J.k * (at - reads);
  cfg_.joints[j].scaling.zero_offset = static_cast<std::int32_t>(std::llround(J.zero / kMicro));
  fb_[j].position -= at - reads;
  return reads;
}

Status MitGroup::family_start_homing(std::size_t j, TimePoint now) {
  (void)now;
  if (j >= cfg_.joint_count) return Status::invalid_argument;
  return cfg_.joints[j].homing.kind == HomingKind::none ? Status::ok : Status::not_supported;
}

JointCapabilities MitGroup::capabilities(std::size_t j) const {
  JointCapabilities c;
  if (j >= cfg_.joint_count) return c;
  c.velocity_offset = c.torque_offset = c.torque_mode = c.measured_torque = c.torque_mode_damping = true;
  return c;
}

Status MitGroup::family_set_feed_forward(std::size_t j, double velocity, double torque) {
  if (j >= cfg_.joint_count) return Status::invalid_argument;
  Joint& J = joints_[j];
  if (!std::isfinite(velocity) || !std::isfinite(torque)) {
    J.ff = false;
    return Status::invalid_argument;
  }
  double v = velocity * J.k, t = torque / J.k;  // actuator side
  if (J.qstop) {  // the hold's braking torque: the motor gives at most T_MAX whatever is asked
    v = std::clamp(v, -J.r.v_max, J.r.v_max);
    t = std::clamp(t, -J.r.t_max, J.r.t_max);
  }
  if (std::fabs(v) > J.r.v_max || std::fabs(t) > J.r.t_max) {
    J.ff = false;
    return Status::invalid_argument;
  }
  J.ff = true;
  J.ff_v = v;
  J.ff_t = t;
  if (t != 0.0) model_torque_ = true;
  return Status::ok;
}

Status MitGroup::set_target_torque(std::size_t j, double torque) {
  if (j >= cfg_.joint_count) return Status::invalid_argument;
  Joint& J = joints_[j];
  if (!std::isfinite(torque) || std::fabs(torque / J.k) > J.r.t_max) return Status::invalid_argument;
  J.target_t = torque;
  J.have_target = true;
  return Status::ok;
}

Status MitGroup::set_torque_damping(std::size_t j, double damping) {
  if (j >= cfg_.joint_count || !std::isfinite(damping) || damping < 0) return Status::invalid_argument;
  Joint& J = joints_[j];
  const double kd = damping / (J.k * J.k);  // actuator side: tau_a = d qd_joint / k = d / k^2 qd_actuator
  J.torque_kd = std::min(kd, J.r.kd_max);
  J.torque_kd_rest = kd - J.torque_kd;  // beyond KD_MAX: added to tau_ff from the measured velocity
  return Status::ok;
}

Status MitGroup::family_set_torque_mode(std::size_t j, bool on) {
  if (j >= cfg_.joint_count) return Status::invalid_argument;
  Joint& J = joints_[j];
  if (on) {
    if (J.mode == CyclicMode::torque || J.mode == CyclicMode::entering_torque) return Status::ok;
    if (fb_[j].state != JointState::enabled || !J.have_target || J.mode == CyclicMode::leaving_torque) return Status::bad_state;
    J.mode = CyclicMode::entering_torque;  // the next write() sends kp = kd = 0 and the torque
    J.mode_status = Status::ok;
    return Status::ok;
  }
  if (J.mode == CyclicMode::position || J.mode == CyclicMode::leaving_torque) return Status::ok;
  J.mode = CyclicMode::leaving_torque;
  J.hold = true;
  J.hold_at = J.p_act;
  J.have_target = false;
  return Status::ok;
}

}  // namespace servoarm::hal
