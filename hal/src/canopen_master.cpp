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
    joint_of_node_[jc.node_id] = std::int8_t(j);
    joints_[j].node = jc.node_id;
    joints_[j].hb_timeout = jc.heartbeat_timeout > 0 ? jc.heartbeat_timeout : cfg_.heartbeat_timeout;
  }
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
      if (!pdo::decode_tpdo1(f, sw, pos)) break;
      const cia402::State st = cia402::decode_statusword(sw);
      if (!jt.have_status || st != jt.state) jt.state_since = now;
      jt.state = st;
      jt.have_status = true;
      jt.actual_counts = pos;
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
      if (st == cia402::State::fault || st == cia402::State::fault_reaction_active) {
        // While enable() is resetting this drive, fault is the expected starting point.
        if (target_ == cia402::Target::enabled && !jt.resetting) set_fault(j, Status::drive_fault, now);
      } else {
        jt.resetting = false;
      }
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
      put_u32(b, (std::uint32_t(e.index) << 16) | e.bits);
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
  SdoResult r = sdo_.read_u32(n, 0x1000, 0, devtype);
  if (r.status != Status::ok) {
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
  if (const Status s = sdo_write(n, cia402::kModesOfOperation, 0, 1, std::uint32_t(cia402::kModeCsp),
                                 "mode of operation: cyclic synchronous position");
      s != Status::ok)
    return s;
  // RPDO1 and TPDO1: required objects; TPDO2: what the configuration asks for and the drive has.
  const MapEntry rpdo1[] = {{cia402::kControlword, 16, PdoUse::required, "controlword"},
                            {cia402::kTargetPosition, 32, PdoUse::required, "target position"}};
  const MapEntry tpdo1[] = {{cia402::kStatusword, 16, PdoUse::required, "statusword"},
                            {cia402::kPositionActual, 32, PdoUse::required, "position actual"}};
  const MapEntry tpdo2[] = {{cia402::kVelocityActual, 32, cfg_.tpdo2.velocity, "velocity actual"},
                            {cia402::kErrorCode, 16, cfg_.tpdo2.error_code, "error code"},
                            {cia402::kTorqueActual, 16, cfg_.tpdo2.torque, "torque actual"}};
  bool m1[2], m2[2], m3[3];
  if (late()) return Status::timeout;
  if (const Status s = map_pdo(j, 0x1400, 0x1600, kRpdo1 + n, rpdo1, 2, m1, "RPDO1"); s != Status::ok) return s;
  if (late()) return Status::timeout;
  if (const Status s = map_pdo(j, 0x1800, 0x1A00, kTpdo1 + n, tpdo1, 2, m2, "TPDO1"); s != Status::ok) return s;
  if (late()) return Status::timeout;
  if (const Status s = map_pdo(j, 0x1801, 0x1A01, kTpdo2 + n, tpdo2, 3, m3, "TPDO2"); s != Status::ok) return s;
  std::uint8_t off = 0;
  jt.off_velocity = jt.off_error = jt.off_torque = -1;
  if (m3[0]) jt.off_velocity = std::int8_t(off), off += 4;
  if (m3[1]) jt.off_error = std::int8_t(off), off += 2;
  if (m3[2]) jt.off_torque = std::int8_t(off), off += 2;
  jt.tpdo2_len = off;
  jt.torque_per_mille = 0;
  if (m3[2]) {
    // 6077h is per mille of the rated torque 6076h (mN m, motor side): joint side x gear ratio.
    std::uint32_t rated = 0;
    r = sdo_.read_u32(n, cia402::kRatedTorque, 0, rated);
    if (r.status != Status::ok || rated == 0) {
      if (cfg_.tpdo2.torque == PdoUse::required) {
        std::snprintf(error_, sizeof error_, "node %u: torque actual 0x6077 needs the rated torque 0x6076: %s",
                      unsigned(n), r.status != Status::ok ? to_string(r.status) : "it reads 0");
        return r.status != Status::ok ? r.status : Status::protocol_error;
      }
      jt.off_torque = -1;  // optional: without a scale the torque is not reported
    } else {
      const JointScaling& sc = cfg_.joints[j].scaling;
      jt.torque_per_mille = double(rated) * 1e-6 * sc.gear_ratio * double(sc.direction);
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
  return Status::ok;
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

Status CanopenServoBus::start(TimePoint deadline) {
  if (config_status_ != Status::ok) return config_status_;
  if (cfg_.joint_count == 0) {
    std::snprintf(error_, sizeof error_, "%s", "no joints configured");
    return Status::not_configured;
  }
  started_ = false;
  error_[0] = '\0';
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
    joints_[j].prev_pos_time = 0;
    fb_[j] = JointFeedback{};
    fb_[j].state = JointState::disabled;
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

Status CanopenServoBus::read(TimePoint now) {
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
          if (jt.have_status && jt.state == cia402::State::operation_enabled && hb_fresh) {
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
  return worst != Status::ok ? worst : bus_status;
}

Status CanopenServoBus::write(std::span<const double> setpoints, TimePoint now) {
  (void)now;
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
    const std::uint16_t cw = cia402::next_controlword(jt.state, t, jt.reset_phase);
    jt.reset_phase = !jt.reset_phase;
    std::int32_t target = jt.actual_counts;
    const bool following = !faulted && target_ == cia402::Target::enabled && jt.have_status &&
                           jt.state == cia402::State::operation_enabled;
    if (following) {
      if (j < setpoints.size() && cfg_.joints[j].scaling.to_counts(setpoints[j], target)) {
      } else {
        target = jt.target_counts;  // bad setpoint: hold the last good one
        result = Status::invalid_argument;
      }
    }
    jt.target_counts = target;
    const Status s = bus_.send(pdo::encode_rpdo1(jt.node, cw, target));
    if (!is_ok(s) && is_ok(result)) result = s;
  }
  if (cfg_.produce_sync) {
    const Status s = bus_.send(encode_sync());
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
