// SPDX-License-Identifier: Apache-2.0
#include "servoarm/hal/canopen_master.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>

namespace servoarm::hal {

using namespace canopen;

const char* to_string(JointState s) {
  switch (s) {
    case JointState::offline: return "offline";
    case JointState::disabled: return "disabled";
    case JointState::enabling: return "enabling";
    case JointState::enabled: return "enabled";
    case JointState::fault: return "fault";
    case JointState::stopping: return "stopping";
  }
  return "unknown";
}

const char* to_string(PdoUse u) {
  switch (u) {
    case PdoUse::off: return "off";
    case PdoUse::optional: return "optional";
    case PdoUse::required: return "required";
  }
  return "unknown";
}

CanopenMasterConfig CanopenMasterConfig::consecutive(std::uint8_t first, std::size_t count, const JointScaling& s) {
  CanopenMasterConfig c;
  c.joint_count = count;
  for (std::size_t i = 0; i < count && i < kMaxServoJoints; ++i) {
    c.joints[i].node_id = std::uint8_t(first + i);
    c.joints[i].scaling = s;
  }
  return c;
}

namespace pdo {
CanFrame encode_rpdo1(std::uint8_t node, std::uint16_t controlword, std::int32_t target) {
  CanFrame f;
  f.id = kRpdo1 + node;
  f.len = 6;
  put_u16(&f.data[0], controlword);
  put_u32(&f.data[2], std::uint32_t(target));
  return f;
}
bool decode_rpdo1(const CanFrame& f, std::uint16_t& controlword, std::int32_t& target) {
  if (f.extended || f.rtr || f.error || function_of(f.id) != kRpdo1 || f.len != 6) return false;
  controlword = get_u16(&f.data[0]);
  target = std::int32_t(get_u32(&f.data[2]));
  return true;
}
CanFrame encode_tpdo1(std::uint8_t node, std::uint16_t statusword, std::int32_t position) {
  CanFrame f;
  f.id = kTpdo1 + node;
  f.len = 6;
  put_u16(&f.data[0], statusword);
  put_u32(&f.data[2], std::uint32_t(position));
  return f;
}
bool decode_tpdo1(const CanFrame& f, std::uint16_t& statusword, std::int32_t& position) {
  if (f.extended || f.rtr || f.error || function_of(f.id) != kTpdo1 || f.len != 6) return false;
  statusword = get_u16(&f.data[0]);
  position = std::int32_t(get_u32(&f.data[2]));
  return true;
}
CanFrame encode_tpdo2(std::uint8_t node, std::int32_t velocity, std::uint16_t error_code) {
  CanFrame f;
  f.id = kTpdo2 + node;
  f.len = 6;
  put_u32(&f.data[0], std::uint32_t(velocity));
  put_u16(&f.data[4], error_code);
  return f;
}
bool decode_tpdo2(const CanFrame& f, std::int32_t& velocity, std::uint16_t& error_code) {
  if (f.extended || f.rtr || f.error || function_of(f.id) != kTpdo2 || f.len != 6) return false;
  velocity = std::int32_t(get_u32(&f.data[0]));
  error_code = get_u16(&f.data[4]);
  return true;
}
}  // namespace pdo

CanopenServoBus::CanopenServoBus(CanBus& bus, Clock& clock, const CanopenMasterConfig& cfg)
    : bus_(bus), clock_(clock), cfg_(cfg), sdo_(bus, clock, cfg.sdo_timeout, FrameSink{&CanopenServoBus::sink, this}) {
  joint_of_node_.fill(-1);
  if (cfg_.joint_count > kMaxServoJoints) {
    config_status_ = Status::capacity;
    cfg_.joint_count = 0;
    std::snprintf(error_, sizeof error_, "%s", "more joints than kMaxServoJoints");
    return;
  }
  for (std::size_t j = 0; j < cfg_.joint_count; ++j) {
    const auto& jc = cfg_.joints[j];
    if (!valid_node(jc.node_id) || joint_of_node_[jc.node_id] >= 0 || !jc.scaling.valid()) {
      config_status_ = Status::invalid_argument;
      std::snprintf(error_, sizeof error_, "joint %zu: invalid or duplicate node id %u, or invalid scaling", j,
                    unsigned(jc.node_id));
      cfg_.joint_count = 0;
      joint_of_node_.fill(-1);
      return;
    }
    if (jc.sdo_write_count > kMaxSdoWrites) {
      config_status_ = Status::capacity;
      std::snprintf(error_, sizeof error_, "joint %zu: more than %zu SDO writes", j, kMaxSdoWrites);
      cfg_.joint_count = 0;
      joint_of_node_.fill(-1);
      return;
    }
    for (std::size_t k = 0; k < jc.sdo_write_count; ++k) {
      const std::uint8_t sz = jc.sdo_writes[k].size;
      if (sz != 1 && sz != 2 && sz != 4) {
        config_status_ = Status::invalid_argument;
        std::snprintf(error_, sizeof error_, "joint %zu: SDO write %04Xh:%u: size %u is not 1, 2 or 4 bytes", j,
                      unsigned(jc.sdo_writes[k].index), unsigned(jc.sdo_writes[k].sub), unsigned(sz));
        cfg_.joint_count = 0;
        joint_of_node_.fill(-1);
        return;
      }
    }
    joint_of_node_[jc.node_id] = std::int8_t(j);
    joints_[j].node = jc.node_id;
    joints_[j].hb_timeout = jc.heartbeat_timeout > 0 ? jc.heartbeat_timeout : cfg_.heartbeat_timeout;
  }
  for (std::size_t j = 0; j < cfg_.joint_count; ++j) {
    if (const Status s = validate_homing(j); s != Status::ok) {
      config_status_ = s;
      cfg_.joint_count = 0;
      joint_of_node_.fill(-1);
      return;
    }
  }
}

namespace {
enum HStep : std::uint8_t {
  hs_idle = 0,
  hs_w_method,
  hs_w_speed1,
  hs_w_speed2,
  hs_w_accel,
  hs_w_offset,
  hs_r_mode,
  hs_w_mode,
  hs_r_mode_check,
  hs_start_low,
  hs_running,
  hs_halting,
  hs_unhalt,
  hs_w_csp,
  hs_r_csp,
  hs_done,
};
bool finite(double x) { return std::isfinite(x); }
}  // namespace

const char* CanopenServoBus::homing_step_name(std::uint8_t step) {
  switch (step) {
    case hs_idle: return "idle";
    case hs_w_method: return "writing the method 6098h";
    case hs_w_speed1: return "writing the switch search speed 6099h:01";
    case hs_w_speed2: return "writing the zero search speed 6099h:02";
    case hs_w_accel: return "writing the homing acceleration 609Ah";
    case hs_w_offset: return "writing the home offset 607Ch";
    case hs_r_mode: return "reading the mode 6061h";
    case hs_w_mode: return "writing homing mode 6060h = 6";
    case hs_r_mode_check: return "waiting for homing mode in 6061h";
    case hs_start_low: return "starting (controlword bit 4)";
    case hs_running: return "waiting for homing attained (statusword bits 10, 12)";
    case hs_halting: return "halting";
    case hs_unhalt: return "leaving homing";
    case hs_w_csp: return "writing cyclic synchronous position 6060h = 8";
    case hs_r_csp: return "waiting for cyclic synchronous position in 6061h";
    case hs_done: return "done";
    default: return "unknown";
  }
}

std::int32_t CanopenServoBus::home_offset_counts(std::size_t j) const {
  const JointScaling& sc = cfg_.joints[j].scaling;
  const double c = double(sc.zero_offset) + std::nearbyint(double(sc.direction) * cfg_.joints[j].homing.offset * sc.counts_per_si());
  return std::int32_t(std::clamp(c, -2147483648.0, 2147483647.0));
}

Status CanopenServoBus::validate_homing(std::size_t j) {
  const HomingSpec& h = cfg_.joints[j].homing;
  const JointScaling& sc = cfg_.joints[j].scaling;
  auto bad = [&](const char* what, double got) {
    std::snprintf(error_, sizeof error_, "joint %zu (node %u): homing %s (got %g)", j, unsigned(cfg_.joints[j].node_id),
                  what, got);
    return Status::invalid_argument;
  };
  switch (h.kind) {
    case HomingKind::none: return Status::ok;
    case HomingKind::cia402: {
      const int m = h.method;
      if (m == 0 || m == 36 || m > 37)
        return bad("method must be a CiA 402 method 1..35 or 37 (or a negative manufacturer method)", double(m));
      if (!finite(h.speed_switch) || h.speed_switch <= 0) return bad("speed_switch must be finite and > 0", h.speed_switch);
      if (!finite(h.speed_zero) || h.speed_zero <= 0) return bad("speed_zero must be finite and > 0", h.speed_zero);
      if (!finite(h.acceleration) || h.acceleration < 0) return bad("acceleration must be finite and >= 0", h.acceleration);
      const double off = double(sc.zero_offset) + double(sc.direction) * h.offset * sc.counts_per_si();
      if (!finite(h.offset) || !(off >= -2147483648.0 && off <= 2147483647.0))
        return bad("offset must be finite and within the drive's 32-bit position range", h.offset);
      const double v1 = h.speed_switch * sc.counts_per_si(), v2 = h.speed_zero * sc.counts_per_si();
      const double a = h.acceleration * sc.counts_per_si();
      if (v1 > 4294967295.0 || v2 > 4294967295.0 || a > 4294967295.0)
        return bad("speed or acceleration beyond the drive's 32-bit range", std::max(v1, std::max(v2, a)));
      break;
    }
    case HomingKind::hard_stop:
      if (!finite(h.speed_switch) || h.speed_switch == 0) return bad("speed_switch must be finite and not 0 (its sign is the direction)", h.speed_switch);
      if (!finite(h.acceleration) || h.acceleration <= 0) return bad("acceleration must be finite and > 0", h.acceleration);
      if (!finite(h.following_limit) || h.following_limit <= 0) return bad("following_limit must be finite and > 0", h.following_limit);
      if (!finite(h.torque_limit) || h.torque_limit < 0) return bad("torque_limit must be finite and >= 0", h.torque_limit);
      if (!finite(h.backoff) || h.backoff <= 0) return bad("backoff must be finite and > 0", h.backoff);
      if (!finite(h.offset)) return bad("offset must be finite", h.offset);
      break;
  }
  if (!finite(h.max_travel) || h.max_travel < 0) return bad("max_travel must be finite and >= 0", h.max_travel);
  if (h.timeout <= 0) return bad("timeout must be > 0 (ms)", double(h.timeout) / double(kMillisecond));
  return Status::ok;
}

void CanopenServoBus::sink(void* ctx, const CanFrame& f) {
  auto* self = static_cast<CanopenServoBus*>(ctx);
  self->dispatch(f, self->clock_.now());
}

void CanopenServoBus::set_fault(std::size_t j, Status why, TimePoint now) {
  JointFeedback& fb = fb_[j];
  if (fb.state == JointState::fault) return;  // keep the first reason
  fb.state = JointState::fault;
  fb.fault = why;
  fb.fault_since = now;
}

void CanopenServoBus::dispatch(const CanFrame& f, TimePoint now) {
  if (f.error || f.extended || f.rtr || f.fd) {
    ++ignored_;
    return;
  }
  const std::uint8_t node = node_of(f.id);
  const std::int8_t jj = joint_of_node_[node];
  if (jj < 0 || f.id == kSync || f.id == kNmt) {
    ++ignored_;
    return;
  }
  const std::size_t j = std::size_t(jj);
  Joint& jt = joints_[j];
  JointFeedback& fb = fb_[j];
  switch (function_of(f.id)) {
    case kTpdo1: {
      std::uint16_t sw;
      std::int32_t pos;
      if (jt.tpdo1_len == 7) {
        // Torque mode mapped: statusword, position actual, modes of operation display 6061h.
        if (f.len != 7) break;
        sw = get_u16(&f.data[0]);
        pos = std::int32_t(get_u32(&f.data[2]));
        jt.mode_shown = std::int8_t(f.data[6]);
      } else if (!pdo::decode_tpdo1(f, sw, pos)) {
        break;
      }
      const cia402::State st = cia402::decode_statusword(sw);
      if (!jt.have_status || st != jt.state) jt.state_since = now;
      jt.state = st;
      jt.have_status = true;
      if (st != cia402::State::operation_enabled) jt.leaving_op = false;
      jt.actual_counts = pos;
      if (jt.tpdos < 1000) ++jt.tpdos;
      if (jt.off_velocity < 0) {
        // No 606Ch mapped: the velocity from successive positions (receive times).
        if (jt.prev_pos_time != 0 && now > jt.prev_pos_time)
          fb.velocity = cfg_.joints[j].scaling.to_joint(pos) - cfg_.joints[j].scaling.to_joint(jt.prev_pos);
        if (jt.prev_pos_time != 0 && now > jt.prev_pos_time) fb.velocity /= double(now - jt.prev_pos_time) * 1e-9;
        jt.prev_pos_time = now;
        jt.prev_pos = pos;
      }
      fb.statusword = sw;
      fb.drive_state = std::uint8_t(st);
      fb.position = cfg_.joints[j].scaling.to_joint(pos);
      fb.valid = true;
      fb.last_feedback = now;
      // A synchronous TPDO holds what the drive sampled at the SYNC it answers: the last one sent
      // before it arrived (the drives' clock, as far as the master can know it).
      fb.sampled = cfg_.produce_sync && last_sync_ != 0 && last_sync_ <= now ? last_sync_ : now;
      if (st == cia402::State::fault || st == cia402::State::fault_reaction_active) {
        // While enable() is resetting this drive, fault is the expected starting point.
        if (target_ == cia402::Target::enabled && !jt.resetting) set_fault(j, Status::drive_fault, now);
      } else {
        jt.resetting = false;
      }
      return;
    }
    case kTpdo3: {
      // 60FDh digital inputs (UNSIGNED32), mapped by start() when asked for.
      if (!jt.tpdo3 || f.len != 4) break;
      fb.digital_inputs = get_u32(&f.data[0]);
      fb.inputs_time = now;
      return;
    }
    case kTpdo2: {
      // Decoded with the layout start() mapped (default: velocity + error code, 6 bytes).
      if (jt.tpdo2_len == 0 || f.len != jt.tpdo2_len) break;
      if (jt.off_velocity >= 0) {
        const std::int32_t vel = std::int32_t(get_u32(&f.data[jt.off_velocity]));
        fb.velocity = cfg_.joints[j].scaling.velocity_to_joint(vel);
      }
      if (jt.off_error >= 0) {
        const std::uint16_t code = get_u16(&f.data[jt.off_error]);
        if (code != 0) fb.error_code = code;
      }
      if (jt.off_torque >= 0) {
        const std::int16_t tq = std::int16_t(get_u16(&f.data[jt.off_torque]));
        fb.torque = double(tq) * jt.torque_per_mille;
        fb.has_torque = true;
      }
      return;
    }
    case kEmcy: {
      std::uint8_t n;
      Emcy e;
      if (!decode_emcy(f, n, e)) break;
      ++fb.emcy_count;
      if (e.error_code != 0) fb.error_code = e.error_code;
      return;
    }
    case kHeartbeat: {
      std::uint8_t n;
      NmtState s;
      if (!decode_heartbeat(f, n, s)) break;
      fb.last_heartbeat = now;
      if (started_ && s != NmtState::operational && jt.nmt == NmtState::operational) {
        // Node was seen operational and left on its own (reset, boot-up, stop): no process data any more.
        set_fault(j, Status::protocol_error, now);
      }
      jt.nmt = s;
      return;
    }
    case kSdoTx:
      if (jt.sdo.on_frame(f)) return;  // the homing's non-blocking transfer
      break;  // late SDO answer after a timeout: ignore
    default:
      break;
  }
  ++ignored_;
}

Status CanopenServoBus::sdo_write(std::uint8_t n, std::uint16_t index, std::uint8_t sub, std::uint8_t size,
                                  std::uint32_t value, const char* what) {
  std::uint8_t b[4];
  put_u32(b, value);
  const SdoResult r = sdo_.download(n, index, sub, b, size);
  if (r.status != Status::ok) {
    std::snprintf(error_, sizeof error_, "node %u: SDO write 0x%04X:%u = 0x%X (%s) failed: %s (abort 0x%08X: %s)",
                  unsigned(n), unsigned(index), unsigned(sub), unsigned(value), what, to_string(r.status),
                  unsigned(r.abort_code), r.abort_code ? sdo::abort_text(r.abort_code) : "-");
  }
  return r.status;
}

namespace {
/// Interpolation time period (60C2h) of `period` ns: value x 10^index s with value <= 255.
void interpolation_period_of(Duration period, std::uint8_t& value, std::int8_t& index) {
  long long v = period > 0 ? static_cast<long long>(period) : 1;
  int e = -9;
  while (v % 10 == 0 && e < 0) v /= 10, ++e;
  while (v > 255) v = (v + 5) / 10, ++e;  // not exact in three digits: rounded
  value = std::uint8_t(v);
  index = std::int8_t(e);
}

/// "20000" / "-4000": `raw` as the type of `w` shows it.
void value_text(const SdoWrite& w, std::uint32_t raw, char* buf, std::size_t size) {
  if (!w.is_signed) {
    std::snprintf(buf, size, "%lu", static_cast<unsigned long>(raw));
    return;
  }
  const int bits = 8 * w.size;
  long long v = static_cast<long long>(raw);
  if (bits < 32 && (raw & (1u << (bits - 1)))) v -= 1LL << bits;
  else if (bits == 32) v = static_cast<std::int32_t>(raw);
  std::snprintf(buf, size, "%lld", v);
}
}  // namespace

Status CanopenServoBus::write_drive_objects(std::size_t j) {
  const std::uint8_t n = joints_[j].node;
  if (cfg_.interpolation_period > 0) {
    std::uint8_t value = 0;
    std::int8_t index = 0;
    interpolation_period_of(cfg_.interpolation_period, value, index);
    std::uint8_t b = value;
    SdoResult r = sdo_.download(n, cia402::kInterpolationPeriod, 1, &b, 1);
    if (r.status == Status::ok) {
      b = std::uint8_t(index);
      r = sdo_.download(n, cia402::kInterpolationPeriod, 2, &b, 1);
    }
    const bool absent = r.status == Status::sdo_abort &&
                        (r.abort_code == sdo::kAbortNoObject || r.abort_code == sdo::kAbortNoSub);
    if (r.status != Status::ok && !absent) {
      std::snprintf(error_, sizeof error_,
                    "node %u: SDO write interpolation period 60C2h = %u x 10^%d s failed: %s (abort 0x%08X: %s)",
                    unsigned(n), unsigned(value), int(index), to_string(r.status), unsigned(r.abort_code),
                    r.abort_code ? sdo::abort_text(r.abort_code) : "-");
      return r.status;
    }
  }
  const CanopenJointConfig& jc = cfg_.joints[j];
  for (std::size_t k = 0; k < jc.sdo_write_count; ++k) {
    const SdoWrite& w = jc.sdo_writes[k];
    char shown[24];
    value_text(w, w.value, shown, sizeof shown);
    std::uint8_t b[4];
    put_u32(b, w.value);
    SdoResult r = sdo_.download(n, w.index, w.sub, b, w.size);
    if (r.status != Status::ok) {
      std::snprintf(error_, sizeof error_, "node %u: drive.sdo %04Xh:%u = %s refused: %s (abort 0x%08X: %s)", unsigned(n),
                    unsigned(w.index), unsigned(w.sub), shown, to_string(r.status), unsigned(r.abort_code),
                    r.abort_code ? sdo::abort_text(r.abort_code) : "-");
      return r.status;
    }
    std::uint8_t back[4] = {};
    r = sdo_.upload(n, w.index, w.sub, back, sizeof back);
    if (r.status != Status::ok) {
      std::snprintf(error_, sizeof error_, "node %u: drive.sdo %04Xh:%u: reading it back failed: %s (abort 0x%08X: %s)",
                    unsigned(n), unsigned(w.index), unsigned(w.sub), to_string(r.status), unsigned(r.abort_code),
                    r.abort_code ? sdo::abort_text(r.abort_code) : "-");
      return r.status;
    }
    const std::uint32_t mask = w.size == 4 ? 0xFFFFFFFFu : (1u << (8 * w.size)) - 1;
    const std::uint32_t got = get_u32(back) & mask;
    if (r.size != w.size || got != (w.value & mask)) {
      char read[24];
      value_text(w, got, read, sizeof read);
      std::snprintf(error_, sizeof error_, "node %u: drive.sdo %04Xh:%u reads back %s (%zu bytes) after writing %s",
                    unsigned(n), unsigned(w.index), unsigned(w.sub), read, r.size, shown);
      return Status::protocol_error;
    }
  }
  return Status::ok;
}

Status CanopenServoBus::map_pdo(std::size_t j, std::uint16_t comm, std::uint16_t map, std::uint32_t cob,
                                const MapEntry* entries, std::size_t count, bool* mapped, const char* pdo_name) {
  const std::uint8_t n = joints_[j].node;
  char what[64];
  std::snprintf(what, sizeof what, "%s off", pdo_name);
  if (const Status s = sdo_write(n, comm, 1, 4, 0x80000000u | cob, what); s != Status::ok) return s;
  bool dropped[8] = {};
  for (int attempt = 0; attempt < 2; ++attempt) {
    std::snprintf(what, sizeof what, "%s mapping cleared", pdo_name);
    if (const Status s = sdo_write(n, map, 0, 1, 0, what); s != Status::ok) return s;
    std::uint8_t sub = 0;
    for (std::size_t k = 0; k < count; ++k) {
      const MapEntry& e = entries[k];
      mapped[k] = false;
      if (e.use == PdoUse::off || dropped[k]) continue;
      // Many drives refuse an entry they lack or cannot map when it is written (CiA 301:
      // abort 06040041h; 06020000h on some); no extra frames when everything is there.
      std::uint8_t b[4];
      put_u32(b, (std::uint32_t(e.index) << 16) | (std::uint32_t(e.sub) << 8) | e.bits);
      const SdoResult r = sdo_.download(n, map, std::uint8_t(sub + 1), b, 4);
      if (r.status == Status::ok) {
        mapped[k] = true;
        ++sub;
        continue;
      }
      if (r.status != Status::sdo_abort || e.use == PdoUse::required) {
        std::snprintf(error_, sizeof error_, "node %u: %s needs 0x%04X (%s), which the drive %s: %s (abort 0x%08X: %s)",
                      unsigned(n), pdo_name, unsigned(e.index), e.what,
                      r.abort_code == sdo::kAbortNoObject ? "does not have" : "cannot map", to_string(r.status),
                      unsigned(r.abort_code), r.abort_code ? sdo::abort_text(r.abort_code) : "-");
        return r.status;
      }
      // optional and refused: left out of the frame
    }
    if (sub == 0) return Status::ok;  // nothing to send: the PDO stays off
    std::uint8_t b[4];
    put_u32(b, sub);
    const SdoResult r = sdo_.download(n, map, 0, b, 1);
    if (r.status == Status::ok) {
      std::snprintf(what, sizeof what, "%s synchronous", pdo_name);
      if (const Status s = sdo_write(n, comm, 2, 1, 1, what); s != Status::ok) return s;
      std::snprintf(what, sizeof what, "%s on", pdo_name);
      return sdo_write(n, comm, 1, 4, cob, what);
    }
    // Other drives check the entries only when the count is written: find the object the
    // drive lacks (its upload aborts) and drop it when it is optional.
    bool found = false;
    for (std::size_t k = 0; k < count && r.status == Status::sdo_abort; ++k) {
      if (!mapped[k]) continue;
      std::uint8_t probe[4];
      const SdoResult p = sdo_.upload(n, entries[k].index, 0, probe, sizeof probe);
      if (p.status == Status::ok) continue;
      if (entries[k].use == PdoUse::required || p.status != Status::sdo_abort) {
        std::snprintf(error_, sizeof error_, "node %u: %s needs 0x%04X (%s), which the drive does not have: %s (abort 0x%08X: %s)",
                      unsigned(n), pdo_name, unsigned(entries[k].index), entries[k].what, to_string(p.status),
                      unsigned(p.abort_code), p.abort_code ? sdo::abort_text(p.abort_code) : "-");
        return p.status != Status::ok ? p.status : Status::protocol_error;
      }
      dropped[k] = true;
      found = true;
    }
    if (!found || attempt == 1) {
      char list[48] = {};
      std::size_t used = 0;
      for (std::size_t k = 0; k < count && used + 8 < sizeof list; ++k)
        if (mapped[k]) used += std::size_t(std::snprintf(list + used, sizeof list - used, "%s0x%04X", used ? "+" : "",
                                                         unsigned(entries[k].index)));
      std::snprintf(error_, sizeof error_, "node %u: %s mapping %s refused (0x%04X:0 = %u): %s (abort 0x%08X: %s)",
                    unsigned(n), pdo_name, list, unsigned(map), unsigned(sub), to_string(r.status),
                    unsigned(r.abort_code), r.abort_code ? sdo::abort_text(r.abort_code) : "-");
      return r.status;
    }
  }
  return Status::protocol_error;  // not reached: the second attempt returns
}

Status CanopenServoBus::setup_node(std::size_t j, TimePoint deadline) {
  const std::uint8_t n = joints_[j].node;
  Joint& jt = joints_[j];
  const std::uint32_t hb_ms = std::uint32_t(cfg_.heartbeat_period / kMillisecond);
  std::uint32_t devtype = 0;
  // A node still booting does not answer: ask again until the boot timeout (counted from start()).
  int attempts = 0;
  SdoResult r;
  for (;;) {
    ++attempts;
    r = sdo_.read_u32(n, 0x1000, 0, devtype);
    if (r.status != Status::timeout) break;
    const TimePoint t = clock_.now();
    if (t + cfg_.boot_retry > boot_end_ || t > deadline) break;
    clock_.sleep_until(t + cfg_.boot_retry);
    bus_.send(encode_nmt(NmtCommand::enter_pre_operational, n));
  }
  if (r.status != Status::ok) {
    if (attempts > 1)
      std::snprintf(error_, sizeof error_,
                    "node %u: no answer to SDO 0x1000 (device type) within the boot timeout of %lld ms (%d attempts): %s",
                    unsigned(n), static_cast<long long>(cfg_.boot_timeout / kMillisecond), attempts, to_string(r.status));
    else
      std::snprintf(error_, sizeof error_, "node %u: reading device type 0x1000 failed: %s%s%s", unsigned(n),
                    to_string(r.status), r.abort_code ? ", " : "", r.abort_code ? sdo::abort_text(r.abort_code) : "");
    return r.status;
  }
  if ((devtype & 0xFFFF) != cia402::kDeviceTypeProfile) {
    std::snprintf(error_, sizeof error_, "node %u: not a CiA 402 drive (0x1000 = 0x%08X)", unsigned(n), unsigned(devtype));
    return Status::protocol_error;
  }
  std::uint8_t name[sizeof joints_[j].name - 1] = {};
  r = sdo_.upload(n, 0x1008, 0, name, sizeof name);
  if (r.status == Status::ok) std::memcpy(joints_[j].name, name, r.size);
  auto late = [&] {
    if (clock_.now() <= deadline) return false;
    std::snprintf(error_, sizeof error_, "node %u: bring-up deadline passed", unsigned(n));
    return true;
  };
  if (late()) return Status::timeout;
  if (const Status s = sdo_write(n, 0x1017, 0, 2, hb_ms, "heartbeat producer time"); s != Status::ok) return s;
  // Supported modes (6502h): CSP is required; homing mode for a joint that homes with the drive.
  // A drive without 6502h is taken at its word (the 6061h checks below and at homing catch it).
  jt.modes = 0;
  std::uint32_t modes = 0;
  const HomingSpec& hs = cfg_.joints[j].homing;
  const bool want_cst = cfg_.rpdo2.torque_mode != PdoUse::off;
  bool cst_ok = want_cst;  // no 6502h: taken at its word (6061h decides when switching)
  if (cfg_.check_supported_modes || hs.kind == HomingKind::cia402 || want_cst)
    r = sdo_.read_u32(n, cia402::kSupportedModes, 0, modes);
  else r.status = Status::sdo_abort;  // not asked: taken at its word
  if (r.status == Status::ok) {
    jt.modes = modes;
    if (!(modes & cia402::kSupportsCsp)) {
      std::snprintf(error_, sizeof error_,
                    "joint %zu (node %u): the drive does not support cyclic synchronous position mode (6502h = 0x%08X)", arm_joint(j),
                    unsigned(n), unsigned(modes));
      return Status::not_supported;
    }
    if (hs.kind == HomingKind::cia402 && !(modes & cia402::kSupportsHoming)) {
      std::snprintf(error_, sizeof error_,
                    "joint %zu (node %u): homing method %d configured but the drive does not support homing mode "
                    "(6502h = 0x%08X)",
                    arm_joint(j), unsigned(n), int(hs.method), unsigned(modes));
      return Status::not_supported;
    }
    if (want_cst && !(modes & cia402::kSupportsCst)) {
      cst_ok = false;
      if (cfg_.rpdo2.torque_mode == PdoUse::required) {
        std::snprintf(error_, sizeof error_,
                      "joint %zu (node %u): torque mode required but the drive does not support cyclic synchronous "
                      "torque mode (6502h = 0x%08X)",
                      arm_joint(j), unsigned(n), unsigned(modes));
        return Status::not_supported;
      }
    }
  } else if (r.status != Status::sdo_abort) {
    std::snprintf(error_, sizeof error_, "node %u: reading supported drive modes 0x6502 failed: %s", unsigned(n),
                  to_string(r.status));
    return r.status;
  }
  if (hs.kind == HomingKind::cia402) {
    // The method now, so a method the drive lacks is refused at bring-up rather than at `home`.
    std::uint8_t b = std::uint8_t(hs.method);
    r = sdo_.download(n, cia402::kHomingMethod, 0, &b, 1);
    if (r.status != Status::ok) {
      std::snprintf(error_, sizeof error_, "joint %zu (node %u): homing method %d refused by the drive (6098h): %s (abort 0x%08X: %s)",
                    arm_joint(j), unsigned(n), int(hs.method), to_string(r.status), unsigned(r.abort_code),
                    r.abort_code ? sdo::abort_text(r.abort_code) : "-");
      return r.status;
    }
  }
  // CSP. Some drives abort a request for the mode they are already in (ros2_canopen #445):
  // then 6061h decides (no extra frames for the drives that accept it).
  {
    std::uint8_t b = std::uint8_t(cia402::kModeCsp);
    r = sdo_.download(n, cia402::kModesOfOperation, 0, &b, 1);
    if (r.status == Status::sdo_abort) {
      std::uint32_t shown = 0;
      const SdoResult d = sdo_.read_u32(n, cia402::kModesDisplay, 0, shown);
      if (d.status == Status::ok && std::int8_t(shown) == cia402::kModeCsp) r.status = Status::ok;
    }
    if (r.status != Status::ok) {
      std::snprintf(error_, sizeof error_, "node %u: SDO write 0x6060:0 = 0x8 (mode of operation: cyclic synchronous position) failed: %s (abort 0x%08X: %s)",
                    unsigned(n), to_string(r.status), unsigned(r.abort_code),
                    r.abort_code ? sdo::abort_text(r.abort_code) : "-");
      return r.status;
    }
  }
  // RPDO1 and TPDO1: required objects; TPDO2: what the configuration asks for and the drive has.
  // Torque mode: 6060h/6061h ride in RPDO1/TPDO1 (a mode change within one cycle).
  const PdoUse tq_use = cst_ok ? cfg_.rpdo2.torque_mode : PdoUse::off;
  const MapEntry rpdo1[] = {{cia402::kControlword, 16, PdoUse::required, "controlword"},
                            {cia402::kTargetPosition, 32, PdoUse::required, "target position"},
                            {cia402::kModesOfOperation, 8, tq_use, "modes of operation"}};
  const MapEntry tpdo1[] = {{cia402::kStatusword, 16, PdoUse::required, "statusword"},
                            {cia402::kPositionActual, 32, PdoUse::required, "position actual"},
                            {cia402::kModesDisplay, 8, tq_use, "modes of operation display"}};
  const MapEntry rpdo2[] = {{cia402::kVelocityOffset, 32, cfg_.rpdo2.velocity_offset, "velocity offset"},
                            {cia402::kTorqueOffset, 16, cfg_.rpdo2.torque_offset, "torque offset"},
                            {cia402::kTargetTorque, 16, tq_use, "target torque"}};
  bool m4[3] = {};
  const MapEntry tpdo2[] = {{cia402::kVelocityActual, 32, cfg_.tpdo2.velocity, "velocity actual"},
                            {cia402::kErrorCode, 16, cfg_.tpdo2.error_code, "error code"},
                            {cia402::kTorqueActual, 16, cfg_.tpdo2.torque, "torque actual"}};
  bool m1[3], m2[3], m3[3];
  if (late()) return Status::timeout;
  if (const Status s = map_pdo(j, 0x1400, 0x1600, kRpdo1 + n, rpdo1, 3, m1, "RPDO1"); s != Status::ok) return s;
  if (late()) return Status::timeout;
  if (const Status s = map_pdo(j, 0x1800, 0x1A00, kTpdo1 + n, tpdo1, 3, m2, "TPDO1"); s != Status::ok) return s;
  if (late()) return Status::timeout;
  if (const Status s = map_pdo(j, 0x1801, 0x1A01, kTpdo2 + n, tpdo2, 3, m3, "TPDO2"); s != Status::ok) return s;
  const bool want_rpdo2 = cfg_.rpdo2.velocity_offset != PdoUse::off || cfg_.rpdo2.torque_offset != PdoUse::off ||
                          tq_use != PdoUse::off;
  if (want_rpdo2) {
    if (late()) return Status::timeout;
    if (const Status s = map_pdo(j, 0x1401, 0x1601, kRpdo2 + n, rpdo2, 3, m4, "RPDO2"); s != Status::ok) return s;
  }
  jt.rpdo3 = false;
  jt.outputs = 0;
  if (cfg_.joints[j].digital_outputs) {
    const MapEntry rpdo3[] = {{cia402::kDigitalOutputs, 32, PdoUse::required, "digital outputs", 1}};
    bool m5[1] = {};
    if (late()) return Status::timeout;
    if (const Status s = map_pdo(j, 0x1402, 0x1602, kRpdo3 + n, rpdo3, 1, m5, "RPDO3"); s != Status::ok) return s;
    jt.rpdo3 = m5[0];
  }
  jt.tpdo3 = false;
  if (cfg_.joints[j].digital_inputs) {
    const MapEntry tpdo3[] = {{cia402::kDigitalInputs, 32, PdoUse::required, "digital inputs"}};
    bool m6[1] = {};
    if (late()) return Status::timeout;
    if (const Status s = map_pdo(j, 0x1802, 0x1A02, kTpdo3 + n, tpdo3, 1, m6, "TPDO3"); s != Status::ok) return s;
    jt.tpdo3 = m6[0];
  }
  jt.rpdo1_len = m1[2] ? 7 : 6;
  jt.tpdo1_len = m2[2] ? 7 : 6;
  jt.mode_shown = 0;
  jt.cmode = CyclicMode::position;
  jt.cstatus = Status::ok;
  jt.have_tq_target = false;
  jt.ff_pending = false;
  jt.tq_target = 0;
  {
    std::uint8_t o = 0;
    jt.off_vel_off = jt.off_tq_off = jt.off_tq_target = -1;
    if (m4[0]) jt.off_vel_off = std::int8_t(o), o += 4;
    if (m4[1]) jt.off_tq_off = std::int8_t(o), o += 2;
    if (m4[2]) jt.off_tq_target = std::int8_t(o), o += 2;
    jt.rpdo2_len = o;
  }
  // Torque mode needs all three of its objects (an optional one the drive refused: none).
  jt.torque_mode = m1[2] && m2[2] && m4[2];
  // (An optional mode byte mapped without the rest is sent as CSP: the mode never changes.)
  std::uint8_t off = 0;
  jt.off_velocity = jt.off_error = jt.off_torque = -1;
  if (m3[0]) jt.off_velocity = std::int8_t(off), off += 4;
  if (m3[1]) jt.off_error = std::int8_t(off), off += 2;
  if (m3[2]) jt.off_torque = std::int8_t(off), off += 2;
  jt.tpdo2_len = off;
  jt.torque_per_mille = 0;
  if (m3[2] || m4[1] || m4[2]) {
    // 6077h, 60B2h and 6071h are per mille of the rated torque (6076h, mN m, motor side, or
    // CanopenJointConfig::rated_torque in N m): joint side x gear ratio x direction.
    const JointScaling& sc = cfg_.joints[j].scaling;
    const double given = cfg_.joints[j].rated_torque;
    std::uint32_t rated = 0;
    if (given > 0) {
      jt.torque_per_mille = given * 1e-3 * sc.gear_ratio * double(sc.direction);
    } else {
      r = sdo_.read_u32(n, cia402::kRatedTorque, 0, rated);
      if (r.status == Status::ok && rated != 0) {
        jt.torque_per_mille = double(rated) * 1e-6 * sc.gear_ratio * double(sc.direction);
      } else {
        const bool required = (m3[2] && cfg_.tpdo2.torque == PdoUse::required) ||
                              (m4[1] && cfg_.rpdo2.torque_offset == PdoUse::required) ||
                              (m4[2] && cfg_.rpdo2.torque_mode == PdoUse::required);
        if (required) {
          std::snprintf(error_, sizeof error_, "node %u: %s needs the rated torque 0x6076: %s", unsigned(n),
                        m3[2] && cfg_.tpdo2.torque == PdoUse::required ? "torque actual 0x6077"
                        : m4[1] && cfg_.rpdo2.torque_offset == PdoUse::required ? "torque offset 0x60B2"
                                                                                : "target torque 0x6071",
                        r.status != Status::ok ? to_string(r.status) : "it reads 0");
          return r.status != Status::ok ? r.status : Status::protocol_error;
        }
        // optional: without a scale the torque is not reported and not commanded
        jt.off_torque = -1;
        jt.torque_mode = false;  // 60B2h stays in the frame, sent as 0
      }
    }
  }
  const double qsd = cfg_.joints[j].quick_stop_decel;
  if (qsd > 0) {
    const std::uint32_t v = qsd >= 4294967295.0 ? 0xFFFFFFFFu : std::uint32_t(std::max(1.0, std::round(qsd)));
    std::uint8_t b[4];
    put_u32(b, v);
    r = sdo_.download(n, cia402::kQuickStopDecel, 0, b, 4);
    if (r.status != Status::ok) {
      std::snprintf(error_, sizeof error_, "node %u: SDO write quick stop deceleration 0x6085 = %u failed: %s (abort 0x%08X: %s)",
                    unsigned(n), unsigned(v), to_string(r.status), unsigned(r.abort_code),
                    r.abort_code ? sdo::abort_text(r.abort_code) : "-");
      return r.status;
    }
  }
  return write_drive_objects(j);
}

bool CanopenServoBus::maps(std::size_t j, std::uint16_t object) const {
  if (j >= cfg_.joint_count) return false;
  const Joint& jt = joints_[j];
  switch (object) {
    case cia402::kVelocityActual: return jt.off_velocity >= 0;
    case cia402::kErrorCode: return jt.off_error >= 0;
    case cia402::kTorqueActual: return jt.off_torque >= 0;
    default: return false;
  }
}

Status CanopenServoBus::family_start(TimePoint deadline) {
  if (config_status_ != Status::ok) return config_status_;
  if (cfg_.joint_count == 0) {
    std::snprintf(error_, sizeof error_, "%s", "no joints configured");
    return Status::not_configured;
  }
  started_ = false;
  error_[0] = '\0';
  boot_end_ = clock_.now() + cfg_.boot_timeout;
  for (std::size_t j = 0; j < cfg_.joint_count; ++j) {
    Joint& jt = joints_[j];
    jt.hphase = HomingPhase::idle;  // a zero this power cycle only: homed again after every start()
    jt.hstatus = Status::ok;
    jt.hstep = hs_idle;
    jt.cw_extra = 0;
    jt.habort = false;
    jt.hmsg[0] = '\0';
    jt.sdo = SdoTransfer{};
  }
  if (cfg_.set_bus_filters) {
    CanFilter filters[kMaxServoJoints];
    // joint_count <= kMaxServoJoints (checked in the constructor); the min() tells GCC's
    // -O3 -Wstringop-overflow so.
    const std::size_t nf = cfg_.joint_count < kMaxServoJoints ? cfg_.joint_count : kMaxServoJoints;
    for (std::size_t j = 0; j < nf; ++j) filters[j] = CanFilter{joints_[j].node, 0x7F, false};
    if (const Status s = bus_.set_filters(std::span<const CanFilter>(filters, nf)); s != Status::ok) {
      std::snprintf(error_, sizeof error_, "installing receive filters: %s", describe(s));
      return s;
    }
  }
  for (std::size_t j = 0; j < cfg_.joint_count; ++j) {
    if (const Status s = bus_.send(encode_nmt(NmtCommand::enter_pre_operational, joints_[j].node)); !is_ok(s)) {
      std::snprintf(error_, sizeof error_, "NMT pre-operational: %s", describe(s));
      return s;
    }
  }
  for (std::size_t j = 0; j < cfg_.joint_count; ++j) {
    if (const Status s = setup_node(j, deadline); s != Status::ok) return s;
  }
  const TimePoint now = clock_.now();
  for (std::size_t j = 0; j < cfg_.joint_count; ++j) {
    if (const Status s = bus_.send(encode_nmt(NmtCommand::start, joints_[j].node)); !is_ok(s)) {
      std::snprintf(error_, sizeof error_, "NMT start: %s", describe(s));
      return s;
    }
    // NMT state is learnt from heartbeats only: a heartbeat sent before the node
    // processed this start command may still say pre-operational.
    joints_[j].nmt = NmtState::boot_up;
    joints_[j].have_status = false;
    joints_[j].leaving_op = false;
    joints_[j].prev_pos_time = 0;
    fb_[j] = JointFeedback{};
    fb_[j].state = JointState::disabled;
    fb_[j].has_inputs = joints_[j].tpdo3;
    joints_[j].hb_watch_since = now;  // consumer starts counting now (last_heartbeat stays a real one)
  }
  target_ = cia402::Target::disabled;
  started_ = true;
  return Status::ok;
}

void CanopenServoBus::enable() {
  target_ = cia402::Target::enabled;
  const TimePoint now = clock_.now();
  for (std::size_t j = 0; j < cfg_.joint_count; ++j) {
    JointFeedback& fb = fb_[j];
    if (fb.state == JointState::fault) {
      if (fb.fault == Status::heartbeat_lost || fb.fault == Status::protocol_error) joints_[j].need_nmt_start = true;
      fb.fault = Status::ok;
      fb.state = JointState::enabling;
      joints_[j].resetting = true;
      joints_[j].hb_watch_since = now;  // the consumer restarts; enabled needs a real heartbeat (read())
    }
    // A drive that faulted while disabled gets its reset too, and so does one whose state is
    // not known yet (right after start(): a drive that powered up in FAULT is reset with a
    // rising edge of controlword bit 7 instead of being reported as faulted at once).
    if (!joints_[j].have_status || joints_[j].state == cia402::State::fault ||
        joints_[j].state == cia402::State::fault_reaction_active)
      joints_[j].resetting = true;
    joints_[j].state_since = now;
  }
}

Status CanopenServoBus::nmt(NmtCommand cmd, std::uint8_t node) {
  if (node != 0 && (node > kMaxNodeId || joint_of_node_[node] < 0)) return Status::invalid_argument;
  return bus_.send(encode_nmt(cmd, node));
}

void CanopenServoBus::disable() { target_ = cia402::Target::disabled; }

Status CanopenServoBus::set_position_zero(std::size_t j) {
  if (j >= cfg_.joint_count) return Status::invalid_argument;
  JointFeedback& fb = fb_[j];
  if (!joints_[j].have_status || !fb.valid) return Status::not_configured;
  if (fb.state == JointState::enabled || fb.state == JointState::enabling || fb.state == JointState::stopping)
    return Status::bad_state;
  JointScaling& s = cfg_.joints[j].scaling;
  s.zero_offset = joints_[j].actual_counts;
  fb.position = s.to_joint(joints_[j].actual_counts);  // 0 from now on
  joints_[j].target_counts = joints_[j].actual_counts;
  return Status::ok;
}

void CanopenServoBus::quick_stop() { target_ = cia402::Target::quick_stop; }

Status CanopenServoBus::family_read(TimePoint now) {
  if (!started_) return Status::not_configured;
  CanFrame f;
  Status bus_status = Status::ok;
  // Bounded drain: at most this many frames per cycle, so a flood cannot stall the loop.
  for (int i = 0; i < 256; ++i) {
    const Status rs = bus_.receive(f, 0);
    if (rs != Status::ok) {
      if (rs != Status::timeout) bus_status = rs;  // interface_down, io_error, ...
      break;
    }
    dispatch(f, f.rx_time != 0 ? f.rx_time : now);
  }
  // A bus-off controller reaches no drive: every joint faults with that reason.
  const bool bus_off = bus_.stats().state == ErrorState::bus_off;
  Status worst = Status::ok;
  for (std::size_t j = 0; j < cfg_.joint_count; ++j) {
    Joint& jt = joints_[j];
    JointFeedback& fb = fb_[j];
    // Frames stamped by the backend after `now` was sampled count as fresh (age 0).
    fb.age = fb.last_feedback ? (now > fb.last_feedback ? now - fb.last_feedback : 0) : -1;
    if (bus_off) set_fault(j, Status::bus_off, now);
    const TimePoint hb_ref = fb.last_heartbeat > jt.hb_watch_since ? fb.last_heartbeat : jt.hb_watch_since;
    if (now - hb_ref > jt.hb_timeout) set_fault(j, Status::heartbeat_lost, now);
    // Operation enabled counts only with a heartbeat within the consumer time: a drive that
    // went silent is not "enabled" on its last statusword (it faults at hb_watch_since + timeout).
    const bool hb_fresh = fb.last_heartbeat != 0 && now - fb.last_heartbeat <= jt.hb_timeout;
    if (fb.state != JointState::fault) {
      switch (target_) {
        case cia402::Target::enabled:
          if (jt.have_status && jt.state == cia402::State::operation_enabled && hb_fresh && !jt.leaving_op) {
            fb.state = JointState::enabled;
          } else {
            fb.state = JointState::enabling;
            if (now - jt.state_since > cfg_.state_timeout) {
              jt.refused_in = jt.state;
              // Still in fault after the resets: the drive's own error, with its code.
              const bool in_fault =
                  jt.state == cia402::State::fault || jt.state == cia402::State::fault_reaction_active;
              set_fault(j, in_fault ? Status::drive_fault : Status::drive_refused, now);
            }
          }
          break;
        case cia402::Target::disabled:
        case cia402::Target::quick_stop:
          // Still powered (or still ramping down in quick stop with speed): stopping, not yet disabled.
          fb.state = jt.have_status && (jt.state == cia402::State::operation_enabled ||
                                        (jt.state == cia402::State::quick_stop_active &&
                                         std::fabs(fb.velocity) > 1e-9))
                         ? JointState::stopping
                         : JointState::disabled;
          break;
      }
    }
    if (fb.state == JointState::fault && worst == Status::ok) worst = fb.fault;
  }
  for (std::size_t j = 0; j < cfg_.joint_count; ++j) advance_homing(j, now);
  for (std::size_t j = 0; j < cfg_.joint_count; ++j) advance_cyclic_mode(j, now);
  return worst != Status::ok ? worst : bus_status;
}

Status CanopenServoBus::family_write(std::span<const double> setpoints, TimePoint) {
  if (!started_) return Status::not_configured;
  Status result = setpoints.size() == cfg_.joint_count ? Status::ok : Status::invalid_argument;
  for (std::size_t j = 0; j < cfg_.joint_count; ++j) {
    Joint& jt = joints_[j];
    JointFeedback& fb = fb_[j];
    if (jt.need_nmt_start) {
      jt.need_nmt_start = false;
      jt.nmt = NmtState::boot_up;  // learn the new state from the next heartbeats
      bus_.send(encode_nmt(NmtCommand::start, jt.node));
    }
    const bool faulted = fb.state == JointState::fault;
    cia402::Target t = faulted ? cia402::Target::disabled : target_;
    std::uint16_t cw = cia402::next_controlword(jt.state, t, jt.reset_phase);
    jt.reset_phase = !jt.reset_phase;
    std::int32_t target = jt.actual_counts;
    const bool following = !faulted && target_ == cia402::Target::enabled && jt.have_status &&
                           jt.state == cia402::State::operation_enabled;
    if (jt.hold_once) {
      // Homing ended in this cycle's read(): a setpoint computed before it is in the old
      // coordinates, so this cycle holds.
      jt.hold_once = false;
      target = jt.target_counts;
      if (!faulted) cw = std::uint16_t(cw | jt.cw_extra);
    } else if (jt.hphase == HomingPhase::running) {
      // The master moves a homing joint: the caller's setpoint is ignored. Drive homing: the
      // target follows the actual position (unused in homing mode, right when CSP resumes).
      if (jt.writes < 1000) ++jt.writes;
      if (!faulted) cw = std::uint16_t(cw | jt.cw_extra);
    } else if (jt.cmode == CyclicMode::leaving_torque) {
      target = jt.target_counts;  // back to CSP where the joint stood when it left torque mode
    } else if (jt.cmode != CyclicMode::position) {
      // Torque mode (or on the way): the target follows the actual position, so CSP resumes there.
    } else if (following) {
      if (j < setpoints.size() && cfg_.joints[j].scaling.to_counts(setpoints[j], target)) {
      } else {
        target = jt.target_counts;  // bad setpoint: hold the last good one
        result = Status::invalid_argument;
      }
    }
    jt.target_counts = target;
    CanFrame f = pdo::encode_rpdo1(jt.node, cw, target);
    if (jt.rpdo1_len == 7) {
      f.len = 7;
      f.data[6] = std::uint8_t(mode_to_send(j));
    }
    Status s = bus_.send(f);
    if (!is_ok(s) && is_ok(result)) result = s;
    // Every target but enabled ends operation enabled (next_controlword: disable operation
    // or quick stop there): once that controlword is on the bus, an enable() before the
    // drive has answered it must wait for the answer (a frame not sent changes nothing).
    if (is_ok(s) && t != cia402::Target::enabled && jt.have_status && jt.state == cia402::State::operation_enabled)
      jt.leaving_op = true;
    if (jt.rpdo2_len > 0) {
      // Offsets only while following setpoints in CSP (one-shot: cleared below); the target
      // torque while in (or entering, leaving) torque mode.
      const bool csp_following = following && jt.cmode == CyclicMode::position &&
                                 jt.hphase != HomingPhase::running && jt.ff_pending;
      const bool torque = jt.cmode != CyclicMode::position && !faulted;
      jt.sent_vel_off = csp_following ? jt.ff_vel : 0;
      jt.sent_tq_off = csp_following ? jt.ff_tq : std::int16_t(0);
      jt.sent_tq_target = torque ? jt.tq_target : std::int16_t(0);
      CanFrame g;
      g.id = kRpdo2 + jt.node;
      g.len = jt.rpdo2_len;
      if (jt.off_vel_off >= 0) put_u32(&g.data[jt.off_vel_off], std::uint32_t(jt.sent_vel_off));
      if (jt.off_tq_off >= 0) put_u16(&g.data[jt.off_tq_off], std::uint16_t(jt.sent_tq_off));
      if (jt.off_tq_target >= 0) put_u16(&g.data[jt.off_tq_target], std::uint16_t(jt.sent_tq_target));
      s = bus_.send(g);
      if (!is_ok(s) && is_ok(result)) result = s;
    }
    jt.ff_pending = false;
    if (jt.rpdo3) {
      CanFrame g;
      g.id = kRpdo3 + jt.node;
      g.len = 4;
      put_u32(&g.data[0], jt.outputs);
      s = bus_.send(g);
      if (!is_ok(s) && is_ok(result)) result = s;
    }
  }
  if (cfg_.produce_sync) {
    const Status s = bus_.send(encode_sync());
    // After the send: a send that waits (a busy controller queue, a bus shared with another
    // thread) puts the SYNC, and so the drives' sampling, at its end.
    if (is_ok(s)) last_sync_ = clock_.now();
    if (!is_ok(s) && is_ok(result)) result = s;
  }
  return result;
}

Status CanopenServoBus::enable_blocking(TimePoint deadline, Duration period) {
  enable();
  double hold[kMaxServoJoints] = {};
  TimePoint next = clock_.now();
  for (;;) {
    const TimePoint now = clock_.now();
    const Status rs = read(now);
    if (rs != Status::ok) {
      std::size_t j = 0;
      while (j < cfg_.joint_count && fb_[j].state != JointState::fault) ++j;
      if (j < cfg_.joint_count) describe_fault(j, error_, sizeof error_);
      return rs;
    }
    bool all = true;
    for (std::size_t j = 0; j < cfg_.joint_count; ++j) {
      all = all && fb_[j].state == JointState::enabled;
      hold[j] = fb_[j].position;
    }
    if (all) return Status::ok;
    if (now > deadline) {
      std::snprintf(error_, sizeof error_, "%s", "enable: deadline passed before every drive was enabled");
      return Status::drive_refused;
    }
    write(std::span<const double>(hold, cfg_.joint_count), now);
    next += period;
    clock_.sleep_until(next);
  }
}

// --- homing (real time) ---------------------------------------------------------------

Status CanopenServoBus::family_start_homing(std::size_t j, TimePoint now) {
  if (j >= cfg_.joint_count) return Status::invalid_argument;
  if (!started_) return Status::not_configured;
  Joint& jt = joints_[j];
  const HomingSpec& hs = cfg_.joints[j].homing;
  if (jt.hphase == HomingPhase::running) return Status::bad_state;
  if (hs.kind == HomingKind::none) {
    jt.hphase = HomingPhase::attained;
    jt.hstatus = Status::ok;
    return Status::ok;
  }
  if (fb_[j].state != JointState::enabled) return Status::bad_state;
  jt.hphase = HomingPhase::running;
  jt.hstatus = Status::ok;
  jt.habort = false;
  jt.hmsg[0] = '\0';
  jt.cw_extra = 0;
  jt.hstarted = now;
  jt.sdo = SdoTransfer{};  // a transfer left over from an earlier homing is abandoned
  jt.htravel = 0;
  jt.hlast = jt.actual_counts;
  jt.hlast_t = now;
  jt.hrebased = false;
  homing_step(j, hs_w_method, now);
  return Status::ok;
}

void CanopenServoBus::family_abort_homing(std::size_t j) {
  if (j < cfg_.joint_count && joints_[j].hphase == HomingPhase::running) joints_[j].habort = true;
}

HomingProgress CanopenServoBus::family_homing(std::size_t j) const {
  if (j >= cfg_.joint_count) return {HomingPhase::idle, Status::invalid_argument, 0};
  if (cfg_.joints[j].homing.kind == HomingKind::none) return {HomingPhase::attained, Status::ok, 0};
  const Joint& jt = joints_[j];
  return {jt.hphase, jt.hstatus, jt.hstep};
}

void CanopenServoBus::family_describe_homing(std::size_t j, char* buf, std::size_t size) const {
  if (size == 0) return;
  buf[0] = '\0';
  if (j >= cfg_.joint_count) return;
  std::snprintf(buf, size, "%s", joints_[j].hmsg);
}

void CanopenServoBus::homing_step(std::size_t j, std::uint8_t step, TimePoint now) {
  Joint& jt = joints_[j];
  jt.hstep = step;
  jt.hstep_since = now;
  jt.tpdos = 0;
  jt.writes = 0;
  jt.retries = 0;
}

void CanopenServoBus::homing_fail(std::size_t j, Status why, TimePoint now) {
  Joint& jt = joints_[j];
  const HomingSpec& hs = cfg_.joints[j].homing;
  if (jt.hstatus == Status::ok) jt.hstatus = why;
  if (jt.hmsg[0] == '\0') {
    if (why == Status::timeout)
      std::snprintf(jt.hmsg, sizeof jt.hmsg, "joint %zu (node %u): homing timeout after %lld ms %s (statusword 0x%04X)", arm_joint(j),
                    unsigned(jt.node), static_cast<long long>(hs.timeout / kMillisecond), homing_step_name(jt.hstep),
                    unsigned(fb_[j].statusword));
    else
      std::snprintf(jt.hmsg, sizeof jt.hmsg, "joint %zu (node %u): homing %s while %s (statusword 0x%04X)", arm_joint(j),
                    unsigned(jt.node), to_string(why), homing_step_name(jt.hstep), unsigned(fb_[j].statusword));
  }
  std::snprintf(error_, sizeof error_, "%s", jt.hmsg);
  if (hs.kind == HomingKind::cia402 && jt.hstep >= hs_w_mode && jt.hstep <= hs_running) {
    // The drive may be in homing mode: halt it, then back to CSP at its actual position.
    jt.cw_extra = cia402::kCwHalt;
    homing_step(j, hs_halting, now);
    return;
  }
  if (jt.hstep >= hs_halting && jt.hstep <= hs_r_csp) return;  // already on the way back
  homing_finish(j, now);
}

void CanopenServoBus::homing_finish(std::size_t j, TimePoint now) {
  Joint& jt = joints_[j];
  jt.cw_extra = 0;
  jt.target_counts = jt.actual_counts;  // holds where it stands
  jt.hphase = jt.hstatus == Status::ok ? HomingPhase::attained : HomingPhase::failed;
  jt.hold_once = true;
  homing_step(j, hs_done, now);
}

bool CanopenServoBus::travel_exceeded(std::size_t j, TimePoint now) {
  Joint& jt = joints_[j];
  const HomingSpec& hs = cfg_.joints[j].homing;
  const JointScaling& sc = cfg_.joints[j].scaling;
  const double cps = sc.counts_per_si();
  const double d = double(jt.actual_counts) - double(jt.hlast);
  if (d != 0) {
    // A drive sets its position to 607Ch when it latches the home mark (some before they show
    // bit 12): one change beyond twice what the homing speed allows since the last change is
    // that coordinate change, not motion. Every other change is motion.
    const double vmax = std::max(std::fabs(hs.speed_switch), std::fabs(hs.speed_zero)) * cps;
    const double dt = double(std::max<Duration>(now - jt.hlast_t, kMillisecond)) * 1e-9;
    if (hs.kind == HomingKind::cia402 && !jt.hrebased && std::fabs(d) > 2.0 * vmax * dt + 16.0) jt.hrebased = true;
    else jt.htravel += d;
    jt.hlast = jt.actual_counts;
    jt.hlast_t = now;
  }
  if (!(hs.max_travel > 0) || std::fabs(jt.htravel) <= hs.max_travel * cps) return false;
  const bool mm = sc.kind == JointScaling::Kind::prismatic;
  const char* unit = mm ? "mm" : "deg";
  const double k = mm ? 1e3 : 180.0 / 3.14159265358979323846;  // deg or mm per SI unit
  const double got = std::fabs(jt.htravel) / cps * k, limit = hs.max_travel * k;
  int digits = 1;  // as many as show the excess
  while (digits < 6 && std::nearbyint(got * std::pow(10.0, digits)) <= std::nearbyint(limit * std::pow(10.0, digits))) ++digits;
  std::snprintf(jt.hmsg, sizeof jt.hmsg,
                "joint %zu (node %u): homing travel %.*f %s from where it began, beyond the limit %.*f %s (the "
                "joint's range + homing.travel_margin_deg)",
                arm_joint(j), unsigned(jt.node), digits, got, unit, digits, limit, unit);
  return true;
}

void CanopenServoBus::advance_homing(std::size_t j, TimePoint now) {
  Joint& jt = joints_[j];
  if (jt.hphase != HomingPhase::running) return;
  JointFeedback& fb = fb_[j];
  const HomingSpec& hs = cfg_.joints[j].homing;
  const JointScaling& sc = cfg_.joints[j].scaling;
  jt.sdo.poll(bus_, now);
  const bool returning = jt.hstep >= hs_halting && jt.hstep <= hs_r_csp;
  if (!returning) {
    Status why = Status::ok;
    if (fb.state == JointState::fault) why = fb.fault;
    else if (fb.state != JointState::enabled) why = Status::bad_state;
    else if (jt.habort) why = Status::aborted;
    else if (now - jt.hstarted > hs.timeout) why = Status::timeout;
    else if (travel_exceeded(j, now)) why = Status::homing_error;
    if (why != Status::ok) {
      homing_fail(j, why, now);
      if (jt.hphase != HomingPhase::running) return;
    }
  } else if (now - jt.hstep_since > 2 * kSecond + 4 * cfg_.sdo_timeout) {
    // The drive does not come back to CSP: it cannot follow setpoints, so it faults.
    std::snprintf(jt.hmsg, sizeof jt.hmsg, "joint %zu (node %u): homing: the drive did not return to cyclic "
                  "synchronous position (%s)", arm_joint(j), unsigned(jt.node), homing_step_name(jt.hstep));
    std::snprintf(error_, sizeof error_, "%s", jt.hmsg);
    if (jt.hstatus == Status::ok) jt.hstatus = Status::drive_refused;
    set_fault(j, Status::drive_refused, now);
    homing_finish(j, now);
    return;
  }
  // One expedited SDO transfer per step: true once it succeeded; a failure fails the homing.
  auto sdo_step = [&](bool write, std::uint16_t index, std::uint8_t sub, std::uint8_t size, std::uint32_t value) {
    if (jt.sdo.state() == SdoTransfer::State::idle) {
      if (write) jt.sdo.begin_write(bus_, jt.node, index, sub, size, value, now, cfg_.sdo_timeout);
      else jt.sdo.begin_read(bus_, jt.node, index, sub, now, cfg_.sdo_timeout);
      return false;  // a bus error: tried again next cycle
    }
    if (!jt.sdo.done()) return false;
    jt.sdo.clear();
    if (jt.sdo.result() == Status::ok) return true;
    // On the way back to CSP a timed-out transfer (a request or answer lost on a loaded bus) is
    // sent again, up to 3 times: giving up leaves the drive in homing mode, where it cannot be
    // enabled for cyclic setpoints again until it is restarted.
    if (returning && jt.sdo.result() == Status::timeout && jt.retries < 3) {
      ++jt.retries;
      return false;
    }
    if (returning && jt.hstatus != Status::ok && jt.hmsg[0] != '\0') {
      // Keep the cause; say that the way back failed too.
      const std::size_t used = std::strlen(jt.hmsg);
      std::snprintf(jt.hmsg + used, sizeof jt.hmsg - used, "; back to CSP: SDO %s 0x%04X %s",
                    write ? "write" : "read", unsigned(index), to_string(jt.sdo.result()));
    } else {
      std::snprintf(jt.hmsg, sizeof jt.hmsg, "joint %zu (node %u): homing: SDO %s 0x%04X:%u failed: %s (abort 0x%08X: %s)",
                    arm_joint(j), unsigned(jt.node), write ? "write" : "read", unsigned(index), unsigned(sub),
                    to_string(jt.sdo.result()), unsigned(jt.sdo.abort_code()),
                    jt.sdo.abort_code() ? sdo::abort_text(jt.sdo.abort_code()) : "-");
    }
    const Status why = jt.sdo.result() == Status::sdo_abort ? Status::drive_refused : jt.sdo.result();
    if (returning) {
      if (jt.hstatus == Status::ok) jt.hstatus = why;
      std::snprintf(error_, sizeof error_, "%s", jt.hmsg);
      set_fault(j, Status::drive_refused, now);
      homing_finish(j, now);
    } else {
      homing_fail(j, why, now);
    }
    return false;
  };
  const double cps = sc.counts_per_si();
  auto u32 = [](double x) { return std::uint32_t(std::clamp(std::round(x), 0.0, 4294967295.0)); };
  const std::uint16_t sw = fb.statusword;
  switch (jt.hstep) {
    case hs_w_method:
      if (sdo_step(true, cia402::kHomingMethod, 0, 1, std::uint8_t(hs.method))) homing_step(j, hs_w_speed1, now);
      break;
    case hs_w_speed1:
      if (sdo_step(true, cia402::kHomingSpeeds, 1, 4, u32(hs.speed_switch * cps))) homing_step(j, hs_w_speed2, now);
      break;
    case hs_w_speed2:
      if (sdo_step(true, cia402::kHomingSpeeds, 2, 4, u32(hs.speed_zero * cps)))
        homing_step(j, hs.acceleration > 0 ? hs_w_accel : hs_w_offset, now);
      break;
    case hs_w_accel:
      if (sdo_step(true, cia402::kHomingAccel, 0, 4, u32(hs.acceleration * cps))) homing_step(j, hs_w_offset, now);
      break;
    case hs_w_offset:
      if (sdo_step(true, cia402::kHomeOffset, 0, 4, std::uint32_t(home_offset_counts(j)))) homing_step(j, hs_r_mode, now);
      break;
    case hs_r_mode:
      // Not re-requesting the mode the drive is already in (some drives abort that).
      if (sdo_step(false, cia402::kModesDisplay, 0, 0, 0))
        homing_step(j, std::int8_t(jt.sdo.value()) == cia402::kModeHoming ? hs_start_low : hs_w_mode, now);
      break;
    case hs_w_mode:
      if (sdo_step(true, cia402::kModesOfOperation, 0, 1, std::uint8_t(cia402::kModeHoming))) homing_step(j, hs_r_mode_check, now);
      break;
    case hs_r_mode_check:
      if (sdo_step(false, cia402::kModesDisplay, 0, 0, 0)) {
        if (std::int8_t(jt.sdo.value()) == cia402::kModeHoming) {
          homing_step(j, hs_start_low, now);
        } else if (++jt.retries > 50) {
          std::snprintf(jt.hmsg, sizeof jt.hmsg, "joint %zu (node %u): homing: 6060h = 6 written but 6061h shows %d",
                        arm_joint(j), unsigned(jt.node), int(std::int8_t(jt.sdo.value())));
          homing_fail(j, Status::drive_refused, now);
        }
      }
      break;
    case hs_start_low:
      // Bit 4 low for two cycles, then high: the rising edge starts the drive's homing.
      jt.cw_extra = 0;
      if (jt.writes >= 2) {
        homing_step(j, hs_running, now);
        jt.cw_extra = cia402::kCwHomingStart;
      }
      break;
    case hs_running:
      if (jt.tpdos < 3) break;  // statuswords sampled after the drive saw bit 4
      if (sw & cia402::kSwHomingError) {
        homing_fail(j, Status::homing_error, now);
      } else if ((sw & cia402::kSwHomingAttained) && (sw & cia402::kSwTargetReached)) {
        jt.cw_extra = 0;
        homing_step(j, hs_unhalt, now);
      }
      break;
    case hs_halting:
      jt.cw_extra = cia402::kCwHalt;  // bit 4 low, halt: the drive stops
      if ((jt.tpdos >= 3 && (sw & cia402::kSwTargetReached)) || now - jt.hstep_since > 300 * kMillisecond ||
          fb.state == JointState::fault)
        homing_step(j, hs_unhalt, now);
      break;
    case hs_unhalt:
      // Halt cleared (and bit 4 low) before the mode change: some drives take no mode change
      // while halted. Two cycles so the RPDO reached the drive before the SDO.
      jt.cw_extra = 0;
      if (jt.writes >= 2) homing_step(j, hs_w_csp, now);
      break;
    case hs_w_csp:
      if (sdo_step(true, cia402::kModesOfOperation, 0, 1, std::uint8_t(cia402::kModeCsp))) homing_step(j, hs_r_csp, now);
      break;
    case hs_r_csp:
      if (sdo_step(false, cia402::kModesDisplay, 0, 0, 0)) {
        if (std::int8_t(jt.sdo.value()) == cia402::kModeCsp) {
          if (jt.hstatus == Status::ok) jt.hmsg[0] = '\0';
          homing_finish(j, now);
        } else if (++jt.retries > 50) {
          std::snprintf(jt.hmsg, sizeof jt.hmsg, "joint %zu (node %u): homing: 6060h = 8 written but 6061h shows %d",
                        arm_joint(j), unsigned(jt.node), int(std::int8_t(jt.sdo.value())));
          std::snprintf(error_, sizeof error_, "%s", jt.hmsg);
          if (jt.hstatus == Status::ok) jt.hstatus = Status::drive_refused;
          set_fault(j, Status::drive_refused, now);
          homing_finish(j, now);
        }
      }
      break;
    default:
      break;
  }
}

// --- what the group base asks of the family -------------------------------------------

void CanopenServoBus::joint_name(std::size_t j, char* buf, std::size_t size) const {
  if (size > 0) std::snprintf(buf, size, "joint %zu (node %u)", arm_joint(j), unsigned(j < cfg_.joint_count ? joints_[j].node : 0));
}

double CanopenServoBus::shift_zero(std::size_t j, double at, double reads) {
  JointScaling& s = cfg_.joints[j].scaling;
  const double cps = s.counts_per_si();
  const double goal = std::clamp(std::nearbyint(double(s.zero_offset) + double(s.direction) * at * cps), -2147483648.0,
                                 2147483647.0);  // the drive's counts at `at`
  s.zero_offset = std::int32_t(std::clamp(goal - std::nearbyint(double(s.direction) * reads * cps), -2147483648.0,
                                          2147483647.0));
  fb_[j].position = s.to_joint(joints_[j].actual_counts);
  return s.to_joint(std::int32_t(goal));
}

void CanopenServoBus::note_error(const char* text) { std::snprintf(error_, sizeof error_, "%s", text); }

// --- feed-forward and torque mode (real time) ----------------------------------------

JointCapabilities CanopenServoBus::capabilities(std::size_t j) const {
  JointCapabilities c;
  if (j >= cfg_.joint_count) return c;
  const Joint& jt = joints_[j];
  c.velocity_offset = jt.off_vel_off >= 0;
  c.torque_offset = jt.off_tq_off >= 0 && jt.torque_per_mille != 0;
  c.torque_mode = jt.torque_mode && jt.torque_per_mille != 0;
  c.measured_torque = jt.off_torque >= 0;
  c.digital_outputs = jt.rpdo3;
  return c;
}

Status CanopenServoBus::set_digital_outputs(std::size_t j, std::uint32_t value) {
  if (j >= cfg_.joint_count) return Status::invalid_argument;
  Joint& jt = joints_[j];
  if (!jt.rpdo3) return Status::not_supported;
  jt.outputs = value;
  return Status::ok;
}

std::uint32_t CanopenServoBus::digital_outputs(std::size_t j) const {
  return j < cfg_.joint_count && joints_[j].rpdo3 ? joints_[j].outputs : 0;
}

namespace {
// Joint torque -> per mille of the rated torque (INTEGER16); false when out of range.
bool torque_units(double torque, double unit, std::int16_t& out) {
  if (!std::isfinite(torque) || unit == 0) return false;
  const double v = std::nearbyint(torque / unit);
  if (!(v >= -32768.0 && v <= 32767.0)) return false;
  out = std::int16_t(v);
  return true;
}
}  // namespace

Status CanopenServoBus::family_set_feed_forward(std::size_t j, double velocity, double torque) {
  if (j >= cfg_.joint_count) return Status::invalid_argument;
  Joint& jt = joints_[j];
  const JointCapabilities c = capabilities(j);
  if (!c.velocity_offset && !c.torque_offset) return Status::not_supported;
  jt.ff_pending = false;
  jt.ff_vel = 0;
  jt.ff_tq = 0;
  if (!std::isfinite(velocity) || !std::isfinite(torque)) return Status::invalid_argument;
  std::int32_t vc = 0;
  std::int16_t tc = 0;
  if (c.velocity_offset) {
    const JointScaling& sc = cfg_.joints[j].scaling;
    const double v = std::nearbyint(double(sc.direction) * velocity * sc.counts_per_si());
    if (!(v >= -2147483648.0 && v <= 2147483647.0)) return Status::invalid_argument;
    vc = std::int32_t(v);
  }
  if (c.torque_offset && !torque_units(torque, jt.torque_per_mille, tc)) return Status::invalid_argument;
  jt.ff_vel = vc;
  jt.ff_tq = tc;
  jt.ff_pending = true;
  return Status::ok;
}

Status CanopenServoBus::set_target_torque(std::size_t j, double torque) {
  if (j >= cfg_.joint_count) return Status::invalid_argument;
  Joint& jt = joints_[j];
  if (!capabilities(j).torque_mode) return Status::not_supported;
  std::int16_t t = 0;
  if (!torque_units(torque, jt.torque_per_mille, t)) return Status::invalid_argument;
  jt.tq_target = t;
  jt.have_tq_target = true;
  return Status::ok;
}

Status CanopenServoBus::family_set_torque_mode(std::size_t j, bool on) {
  if (j >= cfg_.joint_count) return Status::invalid_argument;
  Joint& jt = joints_[j];
  if (!on) {
    if (jt.cmode == CyclicMode::entering_torque || jt.cmode == CyclicMode::torque) {
      jt.cmode = CyclicMode::leaving_torque;
      jt.cmode_since = clock_.now();
      jt.cstatus = Status::ok;
      jt.target_counts = jt.actual_counts;  // holds where it stands
    }
    return Status::ok;
  }
  if (!capabilities(j).torque_mode) return Status::not_supported;
  if (jt.cmode == CyclicMode::entering_torque || jt.cmode == CyclicMode::torque) return Status::ok;
  if (jt.cmode == CyclicMode::leaving_torque || fb_[j].state != JointState::enabled ||
      target_ != cia402::Target::enabled || jt.hphase == HomingPhase::running || !jt.have_tq_target)
    return Status::bad_state;
  jt.cmode = CyclicMode::entering_torque;
  jt.cmode_since = clock_.now();
  jt.cstatus = Status::ok;
  return Status::ok;
}

std::int8_t CanopenServoBus::mode_to_send(std::size_t j) const {
  const Joint& jt = joints_[j];
  // A drive homing (its own homing mode) is told homing mode here too, from the step that
  // writes 6060h = 6 until the one that writes 8 again (what the SDO writes say).
  if (jt.hphase == HomingPhase::running && cfg_.joints[j].homing.kind == HomingKind::cia402 && jt.hstep >= hs_w_mode &&
      jt.hstep <= hs_unhalt)
    return cia402::kModeHoming;
  const bool cst = jt.torque_mode && (jt.cmode == CyclicMode::entering_torque || jt.cmode == CyclicMode::torque);
  return cst ? cia402::kModeCst : cia402::kModeCsp;
}

void CanopenServoBus::advance_cyclic_mode(std::size_t j, TimePoint now) {
  Joint& jt = joints_[j];
  if (jt.cmode == CyclicMode::position) return;
  const JointFeedback& fb = fb_[j];
  if ((fb.state != JointState::enabled || target_ != cia402::Target::enabled) && jt.cmode != CyclicMode::leaving_torque) {
    // A fault, heartbeat loss, disable or quick stop: back to CSP at once (the next RPDO1 says 8).
    jt.cstatus = fb.state == JointState::fault ? fb.fault : Status::aborted;
    jt.cmode = CyclicMode::leaving_torque;
    jt.cmode_since = now;
    jt.target_counts = jt.actual_counts;
  }
  switch (jt.cmode) {
    case CyclicMode::entering_torque:
      if (jt.mode_shown == cia402::kModeCst) {
        jt.cmode = CyclicMode::torque;
      } else if (now - jt.cmode_since > cfg_.state_timeout) {
        std::snprintf(error_, sizeof error_,
                      "joint %zu (node %u): torque mode: 6060h = 10 sent but 6061h shows %d after %lld ms", arm_joint(j),
                      unsigned(jt.node), int(jt.mode_shown), static_cast<long long>(cfg_.state_timeout / kMillisecond));
        jt.cstatus = Status::drive_refused;
        jt.cmode = CyclicMode::leaving_torque;
        jt.cmode_since = now;
        jt.target_counts = jt.actual_counts;
      }
      break;
    case CyclicMode::leaving_torque:
      if (jt.mode_shown == cia402::kModeCsp) {
        jt.cmode = CyclicMode::position;
        jt.have_tq_target = false;
        jt.hold_once = true;  // this cycle's setpoint was computed before the caller knew
      } else if (now - jt.cmode_since > cfg_.state_timeout) {
        // The drive stays in torque mode: it cannot hold a position, so it faults.
        std::snprintf(error_, sizeof error_,
                      "joint %zu (node %u): torque mode: 6060h = 8 sent but 6061h shows %d after %lld ms", arm_joint(j),
                      unsigned(jt.node), int(jt.mode_shown), static_cast<long long>(cfg_.state_timeout / kMillisecond));
        if (jt.cstatus == Status::ok) jt.cstatus = Status::drive_refused;
        set_fault(j, Status::drive_refused, now);
        jt.cmode = CyclicMode::position;
        jt.have_tq_target = false;
      }
      break;
    case CyclicMode::position:
    case CyclicMode::torque:
      break;
  }
}

void CanopenServoBus::describe_fault(std::size_t j, char* buf, std::size_t size) const {
  if (size == 0) return;
  if (j >= cfg_.joint_count) {
    buf[0] = '\0';
    return;
  }
  const JointFeedback& fb = fb_[j];
  const Joint& jt = joints_[j];
  switch (fb.fault) {
    case Status::heartbeat_lost:
      std::snprintf(buf, size, "node %u: heartbeat_lost (no heartbeat for more than %lld ms)", unsigned(jt.node),
                    static_cast<long long>(jt.hb_timeout / kMillisecond));
      return;
    case Status::drive_refused:
      std::snprintf(buf, size, "node %u: drive_refused (stayed in %s for more than %lld ms while enabling)",
                    unsigned(jt.node), cia402::to_string(jt.refused_in),
                    static_cast<long long>(cfg_.state_timeout / kMillisecond));
      return;
    case Status::drive_fault:
      std::snprintf(buf, size, "node %u: drive_fault (error code 0x%04X: %s)", unsigned(jt.node),
                    unsigned(fb.error_code), emcy_text(fb.error_code));
      return;
    case Status::ok:
    case Status::timeout:
    case Status::would_block:
    case Status::error_passive:
    case Status::invalid_argument:
    case Status::io_error:
    case Status::bus_off:
    case Status::interface_down:
    case Status::not_open:
    case Status::sdo_abort:
    case Status::protocol_error:
    case Status::not_configured:
    case Status::aborted:
    case Status::homing_error:
    case Status::capacity:
    case Status::not_supported:
    case Status::bad_state:
      break;
  }
  std::snprintf(buf, size, "node %u: %s (%s)", unsigned(jt.node), to_string(fb.fault), describe(fb.fault));
}

}  // namespace servoarm::hal
