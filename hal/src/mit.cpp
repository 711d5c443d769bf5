// SPDX-License-Identifier: Apache-2.0
// The MIT-mode frame codecs and motor profiles (mit.hpp; sources listed there).
#include "servoarm/hal/mit.hpp"

#include <cmath>
#include <cstring>

namespace servoarm::hal::mit {

namespace {

constexpr MotorProfile kProfiles[] = {
    {"DM-J4310-2EC", Vendor::damiao, 12.5, 30, 10, 500, 5, 10, 0.945, 100,
     "Damiao DM-J4310-2EC V1.1 manual; Seeed wiki Damiao table (ratio 10, Kt 0.945 N m/A)"},
    {"DM-J4340", Vendor::damiao, 12.5, 8, 28, 500, 5, 40, 4.074, 100,
     "Seeed wiki Damiao table, DM-J4340-2EC (ratio 40, Kt 4.074 N m/A, VMAX 8; openarm_can: 10)"},
    {"DM-J8006", Vendor::damiao, 12.5, 45, 40, 500, 5, 6, 1.0206, 100,
     "Seeed wiki Damiao table, DM-J8006-2EC V1.1 (ratio 6, Kt 1.0206 N m/A)"},
    {"AK80-9", Vendor::cubemars, 12.5, 50, 18, 500, 5, 9, 0.091, 0,
     "CubeMars AK Series Actuator Driver Manual V1.0.8, MIT power mode (Kt motor side)"},
    {"RS00", Vendor::robstride, 12.57, 33, 14, 500, 5, 10, 0, 145,
     "Robstride RS00 manual, MIT protocol (over-temperature 145 deg C)"},
};

char lower(char c) { return c >= 'A' && c <= 'Z' ? static_cast<char>(c - 'A' + 'a') : c; }

void put_be16(std::uint8_t* p, std::uint32_t v) {
  p[0] = static_cast<std::uint8_t>(v >> 8);
  p[1] = static_cast<std::uint8_t>(v);
}

bool is_mit_len(const CanFrame& f) { return !f.error && !f.rtr && !f.extended && f.len == 8; }

}  // namespace

const char* to_string(Vendor v) {
  switch (v) {
    case Vendor::damiao: return "damiao";
    case Vendor::cubemars: return "cubemars_mit";
    case Vendor::robstride: return "robstride_mit";
  }
  return "?";
}

std::span<const MotorProfile> motor_profiles() { return kProfiles; }

const MotorProfile* find_profile(std::string_view name) {
  for (const MotorProfile& p : kProfiles) {
    const std::string_view n(p.name);
    if (n.size() != name.size()) continue;
    bool same = true;
    for (std::size_t i = 0; i < n.size() && same; ++i) same = lower(n[i]) == lower(name[i]);
    if (same) return &p;
  }
  return nullptr;
}

std::uint32_t to_code(double x, double min, double max, int bits) {
  const std::uint32_t top = (1u << bits) - 1u;
  if (std::isnan(x) || x <= min) return 0;
  if (x >= max) return top;
  const double u = std::nearbyint((x - min) * static_cast<double>(top) / (max - min));
  return u >= static_cast<double>(top) ? top : static_cast<std::uint32_t>(u);
}

double from_code(std::uint32_t u, double min, double max, int bits) {
  const std::uint32_t top = (1u << bits) - 1u;
  if (u > top) u = top;
  return min + static_cast<double>(u) * (max - min) / static_cast<double>(top);
}

Ranges ranges_of(const MotorProfile& p) { return {p.p_max, p.v_max, p.t_max, p.kp_max, p.kd_max}; }

bool pack_command(const Ranges& r, std::uint32_t can_id, const Command& c, CanFrame& out) {
  if (!std::isfinite(c.p) || !std::isfinite(c.v) || !std::isfinite(c.kp) || !std::isfinite(c.kd) || !std::isfinite(c.t))
    return false;
  const std::uint32_t p = to_code(c.p, -r.p_max, r.p_max, 16);
  const std::uint32_t v = to_code(c.v, -r.v_max, r.v_max, 12);
  const std::uint32_t kp = to_code(c.kp, 0, r.kp_max, 12);
  const std::uint32_t kd = to_code(c.kd, 0, r.kd_max, 12);
  const std::uint32_t t = to_code(c.t, -r.t_max, r.t_max, 12);
  CanFrame f;
  f.id = can_id;
  f.len = 8;
  put_be16(&f.data[0], p);
  f.data[2] = static_cast<std::uint8_t>(v >> 4);
  f.data[3] = static_cast<std::uint8_t>(((v & 0xFu) << 4) | (kp >> 8));
  f.data[4] = static_cast<std::uint8_t>(kp);
  f.data[5] = static_cast<std::uint8_t>(kd >> 4);
  f.data[6] = static_cast<std::uint8_t>(((kd & 0xFu) << 4) | (t >> 8));
  f.data[7] = static_cast<std::uint8_t>(t);
  out = f;
  return true;
}

bool unpack_command(const Ranges& r, const CanFrame& f, Command& out) {
  Special s;
  if (!is_mit_len(f) || is_special(f, s)) return false;
  const std::uint8_t* d = f.data.data();
  const std::uint32_t p = (std::uint32_t(d[0]) << 8) | d[1];
  const std::uint32_t v = (std::uint32_t(d[2]) << 4) | (d[3] >> 4);
  const std::uint32_t kp = ((std::uint32_t(d[3]) & 0xFu) << 8) | d[4];
  const std::uint32_t kd = (std::uint32_t(d[5]) << 4) | (d[6] >> 4);
  const std::uint32_t t = ((std::uint32_t(d[6]) & 0xFu) << 8) | d[7];
  out.p = from_code(p, -r.p_max, r.p_max, 16);
  out.v = from_code(v, -r.v_max, r.v_max, 12);
  out.kp = from_code(kp, 0, r.kp_max, 12);
  out.kd = from_code(kd, 0, r.kd_max, 12);
  out.t = from_code(t, -r.t_max, r.t_max, 12);
  return true;
}

namespace {
void put_f32(std::uint8_t* p, double v) {
  const float f = static_cast<float>(v);
  std::uint32_t raw;
  std::memcpy(&raw, &f, sizeof raw);
  put_u32(p, raw);
}
double get_f32(const std::uint8_t* p) {
  const std::uint32_t raw = get_u32(p);
  float f;
  std::memcpy(&f, &raw, sizeof f);
  return f;
}
bool plain(const CanFrame& f) { return !f.error && !f.rtr && !f.extended; }
}  // namespace

bool pack_pos_vel(std::uint16_t motor_id, double p, double v, CanFrame& out) {
  if (!std::isfinite(p) || !std::isfinite(v) || motor_id > 0xFF) return false;
  CanFrame f;
  f.id = 0x100u + motor_id;
  f.len = 8;
  put_f32(&f.data[0], p);
  put_f32(&f.data[4], v);
  out = f;
  return true;
}

bool pack_vel(std::uint16_t motor_id, double v, CanFrame& out) {
  if (!std::isfinite(v) || motor_id > 0xFF) return false;
  CanFrame f;
  f.id = 0x200u + motor_id;
  f.len = 4;
  put_f32(&f.data[0], v);
  out = f;
  return true;
}

bool unpack_pos_vel(const CanFrame& f, std::uint16_t& motor_id, double& p, double& v) {
  if (!plain(f) || f.len != 8 || f.id < 0x100 || f.id > 0x1FF) return false;
  motor_id = static_cast<std::uint16_t>(f.id - 0x100);
  p = get_f32(&f.data[0]);
  v = get_f32(&f.data[4]);
  return true;
}

bool unpack_vel(const CanFrame& f, std::uint16_t& motor_id, double& v) {
  if (!plain(f) || f.len != 4 || f.id < 0x200 || f.id > 0x2FF) return false;
  motor_id = static_cast<std::uint16_t>(f.id - 0x200);
  v = get_f32(&f.data[0]);
  return true;
}

const char* to_string(Special s) {
  switch (s) {
    case Special::enable: return "enable";
    case Special::disable: return "disable";
    case Special::save_zero: return "save zero";
    case Special::clear_error: return "clear error";
  }
  return "?";
}

CanFrame special_frame(std::uint32_t can_id, Special s) {
  CanFrame f;
  f.id = can_id;
  f.len = 8;
  for (int i = 0; i < 7; ++i) f.data[static_cast<std::size_t>(i)] = 0xFF;
  f.data[7] = static_cast<std::uint8_t>(s);
  return f;
}

bool is_special(const CanFrame& f, Special& s) {
  if (!is_mit_len(f)) return false;
  for (int i = 0; i < 7; ++i)
    if (f.data[static_cast<std::size_t>(i)] != 0xFF) return false;
  switch (f.data[7]) {
    case 0xFC: s = Special::enable; return true;
    case 0xFD: s = Special::disable; return true;
    case 0xFE: s = Special::save_zero; return true;
    case 0xFB: s = Special::clear_error; return true;
    default: return false;
  }
}

bool decode_feedback(Vendor vendor, const Ranges& r, const CanFrame& f, Feedback& out) {
  if (f.error || f.rtr || f.extended || f.len < 6) return false;
  if (vendor != Vendor::cubemars && f.len < 8) return false;
  const std::uint8_t* d = f.data.data();
  const std::uint32_t p = (std::uint32_t(d[1]) << 8) | d[2];
  const std::uint32_t v = (std::uint32_t(d[3]) << 4) | (d[4] >> 4);
  const std::uint32_t t = ((std::uint32_t(d[4]) & 0xFu) << 8) | d[5];
  Feedback fb;
  fb.p = from_code(p, -r.p_max, r.p_max, 16);
  fb.v = from_code(v, -r.v_max, r.v_max, 12);
  fb.t = from_code(t, -r.t_max, r.t_max, 12);
  switch (vendor) {
    case Vendor::damiao:
      fb.id = d[0] & 0x0Fu;
      fb.error = static_cast<std::uint8_t>(d[0] >> 4);
      fb.t_mos = d[6];
      fb.t_rotor = d[7];
      break;
    case Vendor::cubemars:
      fb.id = d[0];
      fb.t_mos = fb.t_rotor = f.len > 6 ? static_cast<double>(static_cast<std::int8_t>(d[6])) : 0.0;
      fb.error = f.len > 7 ? d[7] : 0;
      break;
    case Vendor::robstride:
      fb.id = d[0];
      fb.t_mos = fb.t_rotor = ((std::uint32_t(d[6]) << 8) | d[7]) / 10.0;
      break;
  }
  out = fb;
  return true;
}

CanFrame encode_feedback(Vendor vendor, const Ranges& r, std::uint32_t feedback_id, const Feedback& fb) {
  CanFrame f;
  f.id = feedback_id;
  f.len = 8;
  std::uint8_t* d = f.data.data();
  const std::uint32_t p = to_code(fb.p, -r.p_max, r.p_max, 16);
  const std::uint32_t v = to_code(fb.v, -r.v_max, r.v_max, 12);
  const std::uint32_t t = to_code(fb.t, -r.t_max, r.t_max, 12);
  put_be16(&d[1], p);
  d[3] = static_cast<std::uint8_t>(v >> 4);
  d[4] = static_cast<std::uint8_t>(((v & 0xFu) << 4) | (t >> 8));
  d[5] = static_cast<std::uint8_t>(t);
  auto byte_of = [](double c) {
    const double x = std::nearbyint(c);
    return static_cast<std::uint8_t>(x < 0 ? 0 : x > 255 ? 255 : x);
  };
  switch (vendor) {
    case Vendor::damiao:
      d[0] = static_cast<std::uint8_t>((fb.error << 4) | (fb.id & 0x0Fu));
      d[6] = byte_of(fb.t_mos);
      d[7] = byte_of(fb.t_rotor);
      break;
    case Vendor::cubemars:
      d[0] = fb.id;
      d[6] = static_cast<std::uint8_t>(static_cast<std::int8_t>(std::fmax(-128.0, std::fmin(127.0, std::nearbyint(fb.t_mos)))));
      d[7] = fb.error;
      break;
    case Vendor::robstride: {
      d[0] = fb.id;
      const double x = std::nearbyint(fb.t_mos * 10.0);
      put_be16(&d[6], static_cast<std::uint32_t>(x < 0 ? 0 : x > 65535 ? 65535 : x));
      break;
    }
  }
  return f;
}

const char* damiao_error_name(std::uint8_t code) {
  switch (code) {
    case 0x0: return "disabled";
    case 0x1: return "enabled";
    case 0x8: return "over-voltage";
    case 0x9: return "under-voltage";
    case 0xA: return "over-current";
    case 0xB: return "MOSFET over-temperature";
    case 0xC: return "rotor over-temperature";
    case 0xD: return "communication lost (its CAN timeout)";
    case 0xE: return "overload";
    default: return "unknown error";
  }
}

bool reg_is_uint(std::uint8_t rid) { return (rid >= 7 && rid <= 10) || (rid >= 13 && rid <= 16) || rid == 35 || rid == 36; }

const char* reg_name(std::uint8_t rid) {
  static constexpr const char* kNames[] = {
      "UV_Value", "KT_Value", "OT_Value", "OC_Value", "ACC",    "DEC",    "MAX_SPD", "MST_ID", "ESC_ID", "TIMEOUT",
      "CTRL_MODE", "Damp",    "Inertia",  "hw_ver",   "sw_ver", "SN",     "NPP",     "Rs",     "LS",     "Flux",
      "Gr",       "PMAX",     "VMAX",     "TMAX",     "I_BW",   "KP_ASR", "KI_ASR",  "KP_APR", "KI_APR", "OV_Value",
      "GREF",     "Deta",     "V_BW",     "IQ_c1",    "VL_c1",  "can_br", "sub_ver"};
  return rid <= kLastReg ? kNames[rid] : "?";
}

const char* ctrl_mode_name(std::uint32_t mode) {
  switch (mode) {
    case 1: return "MIT";
    case 2: return "position-velocity";
    case 3: return "velocity";
    case 4: return "torque-position";
    default: return "unknown";
  }
}

namespace {
CanFrame reg_frame(std::uint16_t motor_id, RegCmd cmd, std::uint8_t rid, std::uint32_t raw) {
  CanFrame f;
  f.id = kRegisterId;
  f.len = 8;
  put_u16(&f.data[0], motor_id);
  f.data[2] = static_cast<std::uint8_t>(cmd);
  f.data[3] = rid;
  put_u32(&f.data[4], raw);
  return f;
}
}  // namespace

CanFrame reg_read(std::uint16_t motor_id, std::uint8_t rid) { return reg_frame(motor_id, RegCmd::read, rid, 0); }
CanFrame reg_write_u32(std::uint16_t motor_id, std::uint8_t rid, std::uint32_t value) {
  return reg_frame(motor_id, RegCmd::write, rid, value);
}
CanFrame reg_write_f32(std::uint16_t motor_id, std::uint8_t rid, float value) {
  std::uint32_t raw;
  std::memcpy(&raw, &value, sizeof raw);
  return reg_frame(motor_id, RegCmd::write, rid, raw);
}
CanFrame reg_save(std::uint16_t motor_id) { return reg_frame(motor_id, RegCmd::save, 0, 0); }
CanFrame refresh_frame(std::uint16_t motor_id) { return reg_frame(motor_id, RegCmd::refresh, 0, 0); }

float RegMessage::as_float() const {
  float v;
  std::memcpy(&v, &raw, sizeof v);
  return v;
}

bool decode_register(const CanFrame& f, RegMessage& out) {
  if (f.error || f.rtr || f.extended || f.len < 4) return false;
  RegMessage m;
  m.motor_id = get_u16(&f.data[0]);
  switch (f.data[2]) {
    case 0x33: m.cmd = RegCmd::read; break;
    case 0x55: m.cmd = RegCmd::write; break;
    case 0xAA: m.cmd = RegCmd::save; break;
    case 0xCC: m.cmd = RegCmd::refresh; break;
    default: return false;
  }
  m.rid = f.data[3];
  if (m.cmd == RegCmd::write && f.len < 8) return false;
  m.raw = f.len >= 8 ? get_u32(&f.data[4]) : 0;
  out = m;
  return true;
}

CanFrame reg_reply(std::uint32_t master_id, const RegMessage& m) {
  CanFrame f = reg_frame(m.motor_id, m.cmd, m.rid, m.raw);
  f.id = master_id;
  return f;
}

double Unwrap::update(double wrapped, double p_max) {
  if (!primed_) {
    primed_ = true;
    last_ = wrapped;
    return wrapped;
  }
  const double d = wrapped - last_;
  if (d > p_max) --turns_;
  else if (d < -p_max) ++turns_;
  last_ = wrapped;
  return wrapped + static_cast<double>(turns_) * 2.0 * p_max;
}

}  // namespace servoarm::hal::mit
