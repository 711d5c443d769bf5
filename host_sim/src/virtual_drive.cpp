// SPDX-License-Identifier: Apache-2.0
#include "servoarm/sim/virtual_drive.hpp"

#include "servoarm/sim/arm_plant.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <utility>

namespace servoarm::sim {

using namespace hal::canopen;
namespace c402 = hal::cia402;
using hal::get_u16;
using hal::get_u32;
using hal::put_u32;

namespace {
constexpr int kRpdos = 3;  // RPDO3: 60FEh:01 digital outputs
constexpr std::uint16_t kRpdoComm[kRpdos] = {0x1400, 0x1401, 0x1402};
constexpr std::uint16_t kRpdoMap[kRpdos] = {0x1600, 0x1601, 0x1602};
constexpr int kTpdos = 3;  // TPDO3: 60FDh digital inputs
constexpr std::uint16_t kTpdoComm[kTpdos] = {0x1800, 0x1801, 0x1802};
constexpr std::uint16_t kTpdoMap[kTpdos] = {0x1A00, 0x1A01, 0x1A02};
constexpr std::uint32_t kRpdoBase[kRpdos] = {kRpdo1, kRpdo2, hal::canopen::kRpdo3};
constexpr std::uint32_t kTpdoBase[kTpdos] = {kTpdo1, kTpdo2, hal::canopen::kTpdo3};
constexpr std::uint32_t kCobInvalid = 0x80000000u;
constexpr std::uint16_t kMaxCurrent = 0x6073;              // UNSIGNED16, per mille of the rated current
constexpr std::uint32_t kPeakCurrentPerMille = 3000;       // the model's power stage: 3x rated
}  // namespace

VirtualDrive::VirtualDrive(std::uint8_t node, const MotorParams& motor, std::uint64_t seed)
    : node_(node), motor_(motor), rng_(seed * 0x9E3779B97F4A7C15ull + node) {
  if (rng_ == 0) rng_ = 1;
  // Communication profile (CiA 301).
  add(0x1000, 0, 4, false, false, 0x00020192);  // device type: servo drive, CiA 402
  add(0x1001, 0, 1, false, true, 0);            // error register
  add(0x1008, 0, 0, false, false, 0);           // manufacturer device name (segmented upload)
  add(0x1017, 0, 2, true, false, 0);            // producer heartbeat time, ms
  add(0x1018, 0, 1, false, false, 1);
  add(0x1018, 1, 4, false, false, 0x00000DEA);  // vendor id
  for (int p = 0; p < kRpdos; ++p) {
    add(kRpdoComm[p], 0, 1, false, false, 2);
    add(kRpdoComm[p], 1, 4, true, false, kCobInvalid | (kRpdoBase[p] + node));
    add(kRpdoComm[p], 2, 1, true, false, 0xFF);
    add(kRpdoMap[p], 0, 1, true, false, 0);
    for (std::uint8_t s = 1; s <= 8; ++s) add(kRpdoMap[p], s, 4, true, false, 0);
  }
  for (int p = 0; p < kTpdos; ++p) {
    add(kTpdoComm[p], 0, 1, false, false, 2);
    add(kTpdoComm[p], 1, 4, true, false, kCobInvalid | (kTpdoBase[p] + node));
    add(kTpdoComm[p], 2, 1, true, false, 0xFF);
    add(kTpdoMap[p], 0, 1, true, false, 0);
    for (std::uint8_t s = 1; s <= 8; ++s) add(kTpdoMap[p], s, 4, true, false, 0);
  }
  add(0x2000, 0, 0, true, false, 0);  // user data (domain, segmented download/upload)
  // Device profile (CiA 402).
  add(c402::kErrorCode, 0, 2, false, true, 0);
  add(c402::kControlword, 0, 2, true, true, 0);
  add(c402::kStatusword, 0, 2, false, true, 0);
  add(c402::kModesOfOperation, 0, 1, true, true, 0);
  add(c402::kModesDisplay, 0, 1, false, true, 0);
  add(c402::kPositionActual, 0, 4, false, true, 0);
  add(c402::kFollowingErrorWindow, 0, 4, true, false, motor_.following_window);
  add(c402::kVelocityActual, 0, 4, false, true, 0);
  add(c402::kTargetPosition, 0, 4, true, true, 0);
  add(c402::kDigitalOutputs, 0, 1, false, false, 1);  // 60FEh: physical outputs (:01)
  add(c402::kDigitalOutputs, 1, 4, true, true, 0);
  add(c402::kFollowingErrorActual, 0, 4, false, true, 0);
  // Torque: rated torque (mN m, motor side), torque actual (per mille of it; the
  // first-order plant has no mass and reports 0, the dynamic plant its loop's torque),
  // and the CSP feed-forward offsets the dynamic plant's loop adds.
  add(c402::kRatedTorque, 0, 4, false, false, motor_.rated_torque_mnm);
  add(c402::kTorqueActual, 0, 2, false, true, 0);
  add(c402::kVelocityOffset, 0, 4, true, true, 0);
  add(c402::kTorqueOffset, 0, 2, true, true, 0);
  // Cyclic synchronous torque: target torque, per mille of 6076h. Only a drive on
  // the dynamic plant offers CST (6502h bit 9): the first-order motor has no torque.
  add(c402::kTargetTorque, 0, 2, true, true, 0);
  // Quick stop: option code (6: ramp down with 6085h, stay in quick stop
  // active; 2: the same, then switch on disabled; 1/5: as 2/6 -- this model
  // has no separate slow-down ramp; 0: power off at once, the unpowered motor
  // stops with its acceleration limit) and deceleration (counts/s^2; default
  // and ceiling: the motor's acceleration limit).
  add(c402::kQuickStopOption, 0, 2, true, false, 6);
  add(c402::kQuickStopDecel, 0, 4, true, false,
      std::uint32_t(std::clamp(std::round(motor_.max_accel), 1.0, 4294967295.0)));
  // Homing: switches, method, speeds (counts/s), acceleration (counts/s^2, 0 = the
  // motor's limit), home offset, supported modes.
  add(c402::kDigitalInputs, 0, 4, false, true, 0);
  add(c402::kHomingMethod, 0, 1, true, false, 35);
  add(c402::kHomingSpeeds, 0, 1, false, false, 2);
  add(c402::kHomingSpeeds, 1, 4, true, false, 131072);
  add(c402::kHomingSpeeds, 2, 4, true, false, 13107);
  add(c402::kHomingAccel, 0, 4, true, false, 0);
  add(c402::kHomeOffset, 0, 4, true, false, 0);
  add(c402::kSupportedModes, 0, 4, false, false, c402::kSupportsCsp | c402::kSupportsHoming);
  // Set-up objects a master writes at bring-up (drive.sdo): kept and read back, not acted on
  // (the motor model's limits are MotorParams'): interpolation time period (1 x 10^-3 s),
  // position window, following error time out, software position limits, max torque and
  // max current (per mille of the rated values).
  add(c402::kInterpolationPeriod, 0, 1, false, false, 2);
  add(c402::kInterpolationPeriod, 1, 1, true, false, 1);
  add(c402::kInterpolationPeriod, 2, 1, true, false, 0xFD);
  add(0x6067, 0, 4, true, false, 1000);
  add(0x607D, 0, 1, false, false, 2);
  add(0x607D, 1, 4, true, false, 0x80000000u);
  add(0x607D, 2, 4, true, false, 0x7FFFFFFFu);
  add(0x6066, 0, 2, true, false, 10);
  add(0x6072, 0, 2, true, true, 1000);
  add(kMaxCurrent, 0, 2, true, false, 1000);
  Entry* name = find(0x1008, 0);
  char buf[48];
  const int n = std::snprintf(buf, sizeof buf, "servoarm virtual drive %u", unsigned(node));
  name->domain.assign(buf, buf + n);
  name->domain_cap = name->domain.size();
  find(0x2000, 0)->domain_cap = 32;
}

void VirtualDrive::add(std::uint16_t index, std::uint8_t sub, std::uint8_t size, bool writable, bool mappable,
                       std::uint32_t value) {
  // Kept sorted by (index, sub); find() looks entries up through od_slots_.
  const auto key = od_key(index, sub);
  const auto at = std::upper_bound(od_.begin(), od_.end(), key,
                                   [](std::uint32_t k, const Entry& e) { return k < od_key(e.index, e.sub); });
  od_.insert(at, Entry{index, sub, size, writable, mappable, value, value, {}, 0});
  index_dictionary();
}

// find() runs tens of times per plant sub-step and per frame (every get() and set() of the
// drive's loops, statusword and PDOs): a binary search over the sorted dictionary takes
// 41 % of a simulated suite's CPU time on the host, more under the sanitizers. A hash
// table of the entries' positions answers in one probe; the dictionary changes shape only
// at set-up (add, od_remove), so it is rebuilt there and find() stays a read.
void VirtualDrive::index_dictionary() {
  unsigned bits = 4;
  while ((std::size_t(1) << bits) < 4 * od_.size()) ++bits;
  od_shift_ = 32 - bits;
  od_slots_.assign(std::size_t(1) << bits, std::int16_t(-1));
  const std::size_t mask = od_slots_.size() - 1;
  for (std::size_t k = 0; k < od_.size(); ++k) {
    std::size_t i = (od_key(od_[k].index, od_[k].sub) * 0x9E3779B1u) >> od_shift_;
    while (od_slots_[i] >= 0) i = (i + 1) & mask;
    od_slots_[i] = std::int16_t(k);
  }
  const auto at = [this](std::uint16_t index, std::uint8_t sub) {
    const Entry* e = find(index, sub);
    return e ? std::int16_t(e - od_.data()) : std::int16_t(-1);
  };
  mode_at_ = at(c402::kModesDisplay, 0);
  static_assert(kRpdos == std::size(decltype(rpdo_cob_at_){}));
  for (int p = 0; p < kRpdos; ++p) {
    rpdo_cob_at_[p] = at(kRpdoComm[p], 1);
    rpdo_type_at_[p] = at(kRpdoComm[p], 2);
  }
}

VirtualDrive::Entry* VirtualDrive::find(std::uint16_t index, std::uint8_t sub) {
  return const_cast<Entry*>(std::as_const(*this).find(index, sub));
}
const VirtualDrive::Entry* VirtualDrive::find(std::uint16_t index, std::uint8_t sub) const {
  if (od_slots_.empty()) return nullptr;
  const std::size_t mask = od_slots_.size() - 1;
  for (std::size_t i = (od_key(index, sub) * 0x9E3779B1u) >> od_shift_;; i = (i + 1) & mask) {
    const int k = od_slots_[i];
    if (k < 0) return nullptr;
    const Entry& e = od_[std::size_t(k)];
    if (e.index == index && e.sub == sub) return &e;
  }
}

bool VirtualDrive::od_read(std::uint16_t index, std::uint8_t sub, std::uint32_t& value) const {
  const Entry* e = find(index, sub);
  if (!e || e->size == 0) return false;
  value = e->value;
  return true;
}

bool VirtualDrive::od_write(std::uint16_t index, std::uint8_t sub, std::uint32_t value) {
  Entry* e = find(index, sub);
  if (!e || e->size == 0) return false;
  e->value = value;
  if (index == 0x1017) next_hb_ = t_;
  return true;
}

bool VirtualDrive::od_remove(std::uint16_t index) {
  const std::size_t before = od_.size();
  std::erase_if(od_, [index](const Entry& e) { return e.index == index; });
  index_dictionary();
  return od_.size() != before;
}

void VirtualDrive::set(std::uint16_t index, std::uint32_t v) {
  if (Entry* e = find(index, 0)) e->value = v;
}
std::uint32_t VirtualDrive::get(std::uint16_t index, std::uint8_t sub) const {
  const Entry* e = find(index, sub);
  return e ? e->value : 0;
}

void VirtualDrive::reset_dictionary(bool communication_only) {
  for (Entry& e : od_) {
    const bool comm = e.index < 0x2000;
    if (communication_only && !comm) continue;
    if (e.index == c402::kPositionActual) continue;  // the shaft does not move on reset
    e.value = e.initial;
    if (e.index == 0x2000) e.domain.clear();
  }
}

double VirtualDrive::uniform() {
  rng_ ^= rng_ >> 12;
  rng_ ^= rng_ << 25;
  rng_ ^= rng_ >> 27;
  return double((rng_ * 0x2545F4914F6CDD1Dull) >> 11) * (1.0 / 9007199254740992.0);
}

void VirtualDrive::tx(CanBus& bus, const CanFrame& f) {
  if (faults_.silent) return;
  if (faults_.tx_drop_rate > 0 && uniform() < faults_.tx_drop_rate) return;
  if (quirks_.sdo_delay > 0 && f.id == kSdoTx + node_) {
    delayed_.emplace_back(now_ + quirks_.sdo_delay, f);  // sent by tick() when due
    return;
  }
  bus.send(f);
}

void VirtualDrive::set_quirks(const DriveQuirks& q) {
  quirks_ = q;
  update_supported_modes();
}

void VirtualDrive::update_supported_modes() {
  std::uint32_t modes = c402::kSupportsCsp | (quirks_.no_homing ? 0u : c402::kSupportsHoming);
  if (plant_ && !quirks_.no_cst) modes |= c402::kSupportsCst;
  if (quirks_.supported_modes != 0) modes = quirks_.supported_modes;
  if (Entry* e = find(c402::kSupportedModes, 0)) e->value = e->initial = modes;
}

bool VirtualDrive::mode_allowed(std::int8_t m) const {
  const std::uint32_t modes = get(c402::kSupportedModes);
  return m == 0 || (m == c402::kModeCsp && (modes & c402::kSupportsCsp)) ||
         (m == c402::kModeHoming && (modes & c402::kSupportsHoming)) ||
         (m == c402::kModeCst && (modes & c402::kSupportsCst) && plant_ != nullptr);
}

void VirtualDrive::power_on(TimePoint now, CanBus& bus) {
  if (quirks_.boot_delay > 0) {  // a slow boot: silent until then (tick() finishes it)
    booted_ = false;
    boot_at_ = now + quirks_.boot_delay;
    t_ = now;
    return;
  }
  boot(now, bus);
}

void VirtualDrive::boot(TimePoint now, CanBus& bus) {
  boot_at_ = 0;
  t_ = now;
  booted_ = true;
  nmt_ = NmtState::pre_operational;
  state_ = c402::State::switch_on_disabled;  // transitions 0 + 1 are automatic
  update_statusword();
  tx(bus, encode_heartbeat(node_, NmtState::boot_up));
  next_hb_ = now;
}

void VirtualDrive::handle(const CanFrame& f, TimePoint now, CanBus& bus) {
  if (faults_.silent || !booted_ || f.error || f.extended || f.rtr || f.fd) return;
  now_ = now;
  if (f.id == kNmt) {
    NmtCommand cmd;
    std::uint8_t target;
    if (decode_nmt(f, cmd, target) && (target == 0 || target == node_)) handle_nmt(cmd, now, bus);
    return;
  }
  if (nmt_ == NmtState::stopped) return;
  if (f.id == kSdoRx + node_) {
    if (f.len == 8) handle_sdo(f, now, bus);
    return;
  }
  if (nmt_ != NmtState::operational) return;
  if (is_sync(f)) {
    on_sync(now, bus);
    return;
  }
  for (int p = 0; p < kRpdos; ++p) {
    const std::uint32_t cob = value_at(rpdo_cob_at_[p]);
    if ((cob & kCobInvalid) || f.id != (cob & 0x7FF)) continue;
    const std::uint32_t type = value_at(rpdo_type_at_[p]);
    if (type <= 240) {
      rpdo_latch_[p] = f;  // synchronous: acted on at the next SYNC
      rpdo_pending_[p] = true;
    } else {
      apply_rpdo(p, f);
      apply_controlword(now, bus);
    }
  }
}

void VirtualDrive::handle_nmt(NmtCommand cmd, TimePoint now, CanBus& bus) {
  switch (cmd) {
    case NmtCommand::start:
      nmt_ = NmtState::operational;
      break;
    case NmtCommand::stop:
      nmt_ = NmtState::stopped;
      break;
    case NmtCommand::enter_pre_operational:
      nmt_ = NmtState::pre_operational;
      break;
    case NmtCommand::reset_node:
    case NmtCommand::reset_communication:
      reset_dictionary(cmd == NmtCommand::reset_communication);
      sdo_mode_ = SdoMode::idle;
      rpdo_pending_ = {};
      if (cmd == NmtCommand::reset_node) {
        state_ = c402::State::switch_on_disabled;
        prev_cw_ = 0;
        target_ = std::int32_t(std::lround(pos_));
        h_ = Homing{};
        has_pending_mode_ = false;
      }
      power_on(now, bus);
      break;
  }
}

std::uint32_t VirtualDrive::check_mapping(std::uint16_t map_index, std::uint32_t count) const {
  if (count > 8) return sdo::kAbortPdoLength;
  const bool rx = map_index < 0x1800;
  std::uint32_t bits = 0;
  for (std::uint8_t s = 1; s <= count; ++s) {
    const std::uint32_t m = get(map_index, s);
    const Entry* e = find(std::uint16_t(m >> 16), std::uint8_t(m >> 8));
    if (!e || !e->mappable || (rx && !e->writable)) return sdo::kAbortNotMappable;
    if ((m & 0xFF) != std::uint32_t(e->size) * 8) return sdo::kAbortParamIncompatible;
    bits += m & 0xFF;
  }
  return bits > 64 ? sdo::kAbortPdoLength : 0;
}

std::uint32_t VirtualDrive::sdo_write(Entry& e, const std::uint8_t* data, std::size_t len) {
  if (!e.writable) return sdo::kAbortReadOnly;
  if (e.size == 0) {
    if (len > e.domain_cap) return sdo::kAbortTooLong;
    e.domain.assign(data, data + len);
    return 0;
  }
  if (len > e.size) return sdo::kAbortTooLong;
  if (len < e.size) return sdo::kAbortTooShort;
  std::uint32_t v = 0;
  for (std::size_t i = 0; i < len; ++i) v |= std::uint32_t(data[i]) << (8 * i);
  const bool is_map = (e.index >= 0x1600 && e.index <= 0x1602) || (e.index >= 0x1A00 && e.index <= 0x1A02);
  const bool is_comm = (e.index >= 0x1400 && e.index <= 0x1402) || (e.index >= 0x1800 && e.index <= 0x1802);
  if (is_map) {
    const std::uint16_t comm = std::uint16_t(e.index - 0x200);
    if (!(get(comm, 1) & kCobInvalid)) return sdo::kAbortDeviceState;  // PDO must be disabled first
    if (e.sub == 0) {
      if (const std::uint32_t a = check_mapping(e.index, v)) return a;
    } else if (get(e.index, 0) != 0) {
      return sdo::kAbortDeviceState;  // CiA 301: set sub 0 to 0 before changing entries
    } else if (v != 0 && motor_.check_map_entries) {
      // Like many drives, check each entry as it is written: an object this drive lacks
      // or cannot map is refused here (by default only at sub 0, like others).
      const Entry* m = find(std::uint16_t(v >> 16), std::uint8_t(v >> 8));
      if (!m || !m->mappable || (e.index < 0x1800 && !m->writable)) return sdo::kAbortNotMappable;
      if ((v & 0xFF) != std::uint32_t(m->size) * 8) return sdo::kAbortParamIncompatible;
    }
  }
  if (is_comm && e.sub == 1) {
    if ((v & 0x3FFFF800u) != 0) return sdo::kAbortValueRange;  // 11-bit ids only
  }
  if (is_comm && e.sub == 2 && v > 240 && v < 254) return sdo::kAbortValueRange;
  if (e.index == c402::kModesOfOperation) {
    const std::int8_t m = std::int8_t(v);
    if (!mode_allowed(m)) return sdo::kAbortValueRange;
    if (quirks_.refuse_same_mode && m == std::int8_t(get(c402::kModesDisplay))) return sdo::kAbortDeviceState;
  }
  if (e.index == c402::kHomingMethod) {
    const std::int8_t m = std::int8_t(v);
    const bool ok = (m >= 1 && m <= 7) || m == 11 || (m >= 17 && m <= 23) || m == 27 || (m >= 33 && m <= 35) ||
                    m == 37;
    if (!ok) return sdo::kAbortValueRange;
  }
  if (e.index == c402::kQuickStopOption) {
    const std::int16_t o = std::int16_t(v);
    if (!(o == 0 || o == 1 || o == 2 || o == 5 || o == 6)) return sdo::kAbortValueRange;
  }
  if (e.index == c402::kQuickStopDecel && v == 0) return sdo::kAbortValueRange;
  // Max current 6073h: the power stage's peak is 3x the rated current. A higher value is
  // accepted and kept at that ceiling, as drives that saturate a limit without an abort
  // do: only reading it back shows it.
  if (e.index == kMaxCurrent && v > kPeakCurrentPerMille) v = kPeakCurrentPerMille;
  e.value = v;
  if (e.index == c402::kModesOfOperation) {
    if (quirks_.halt_blocks_mode_change && (get(c402::kControlword) & c402::kCwHalt)) {
      pending_mode_ = std::int8_t(v);  // shows (and acts) once the halt bit is clear
      has_pending_mode_ = true;
    } else {
      set_mode(std::int8_t(v));
    }
  }
  if (e.index == 0x1017) next_hb_ = t_;
  // A controlword (or target) written by SDO acts when it is written, in any NMT state
  // where SDO works (pre-operational too), as on a real drive: not at the next SYNC.
  if (e.index == c402::kControlword || e.index == c402::kTargetPosition) sdo_actuate_ = true;
  return 0;
}

void VirtualDrive::handle_sdo(const CanFrame& f, TimePoint now, CanBus& bus) {
  sdo_actuate_ = false;
  serve_sdo(f, bus);
  if (sdo_actuate_) {
    sdo_actuate_ = false;
    advance(now, bus);  // the motor runs up to the write, then the new command acts
    apply_controlword(now, bus);
  }
}

void VirtualDrive::serve_sdo(const CanFrame& f, CanBus& bus) {
  const std::uint8_t c = f.data[0];
  const std::uint8_t cs = sdo::cs_of(c);
  if (cs == sdo::kAbort) {
    sdo_mode_ = SdoMode::idle;
    return;
  }
  auto abort = [&](std::uint16_t index, std::uint8_t sub, std::uint32_t code) {
    sdo_mode_ = SdoMode::idle;
    tx(bus, sdo::abort(node_, true, index, sub, code));
  };
  switch (cs) {
    case sdo::kCcsInitiateDownload: {
      const std::uint16_t index = sdo::index_of(f);
      const std::uint8_t sub = sdo::sub_of(f);
      Entry* e = find(index, sub);
      if (!e) return abort(index, sub, find(index, 0) ? sdo::kAbortNoSub : sdo::kAbortNoObject);
      if (!e->writable) return abort(index, sub, sdo::kAbortReadOnly);
      if (c & 0x02) {  // expedited
        if (quirks_.lose_csp_writes > 0 && index == c402::kModesOfOperation && sub == 0 && f.data[4] == c402::kModeCsp) {
          --quirks_.lose_csp_writes;  // quirk: this request never arrived
          return;
        }
        const std::size_t n = (c & 0x01) ? std::size_t(4 - ((c >> 2) & 3)) : std::size_t(e->size ? e->size : 4);
        if (const std::uint32_t a = sdo_write(*e, &f.data[4], n)) return abort(index, sub, a);
        sdo_mode_ = SdoMode::idle;
        tx(bus, sdo::download_response(node_, index, sub));
        return;
      }
      const std::size_t size = (c & 0x01) ? get_u32(&f.data[4]) : 0;
      if (size > sdo_buf_.size()) return abort(index, sub, sdo::kAbortTooLong);
      sdo_mode_ = SdoMode::download;
      sdo_index_ = index;
      sdo_sub_ = sub;
      sdo_toggle_ = false;
      sdo_off_ = 0;
      sdo_size_ = size;
      tx(bus, sdo::download_response(node_, index, sub));
      return;
    }
    case sdo::kCcsDownloadSegment: {
      if (sdo_mode_ != SdoMode::download) return abort(0, 0, sdo::kAbortCommand);
      if (((c & 0x10) != 0) != sdo_toggle_) return abort(sdo_index_, sdo_sub_, sdo::kAbortToggle);
      const std::size_t n = 7 - ((c >> 1) & 7);
      if (sdo_off_ + n > sdo_buf_.size()) return abort(sdo_index_, sdo_sub_, sdo::kAbortTooLong);
      std::memcpy(&sdo_buf_[sdo_off_], &f.data[1], n);
      sdo_off_ += n;
      const bool toggle = sdo_toggle_;
      sdo_toggle_ = !sdo_toggle_;
      if (c & 0x01) {
        if (sdo_size_ != 0 && sdo_off_ != sdo_size_) return abort(sdo_index_, sdo_sub_, sdo::kAbortLength);
        Entry* e = find(sdo_index_, sdo_sub_);
        if (const std::uint32_t a = sdo_write(*e, sdo_buf_.data(), sdo_off_)) return abort(sdo_index_, sdo_sub_, a);
        sdo_mode_ = SdoMode::idle;
      }
      tx(bus, sdo::download_segment_response(node_, toggle));
      return;
    }
    case sdo::kCcsInitiateUpload: {
      const std::uint16_t index = sdo::index_of(f);
      const std::uint8_t sub = sdo::sub_of(f);
      const Entry* e = find(index, sub);
      if (!e) return abort(index, sub, find(index, 0) ? sdo::kAbortNoSub : sdo::kAbortNoObject);
      if (e->size != 0) {
        std::uint8_t b[4];
        put_u32(b, e->value);
        sdo_mode_ = SdoMode::idle;
        tx(bus, sdo::upload_response(node_, index, sub, b, e->size));
        return;
      }
      const std::size_t n = std::min(e->domain.size(), sdo_buf_.size());
      if (n > 0) std::memcpy(sdo_buf_.data(), e->domain.data(), n);  // an empty domain has no data pointer
      if (n >= 1 && n <= 4) {
        sdo_mode_ = SdoMode::idle;
        tx(bus, sdo::upload_response(node_, index, sub, sdo_buf_.data(), std::uint32_t(n)));
        return;
      }
      sdo_mode_ = SdoMode::upload;
      sdo_index_ = index;
      sdo_sub_ = sub;
      sdo_toggle_ = false;
      sdo_off_ = 0;
      sdo_size_ = n;
      tx(bus, sdo::upload_response(node_, index, sub, sdo_buf_.data(), std::uint32_t(n)));
      return;
    }
    case sdo::kCcsUploadSegment: {
      if (sdo_mode_ != SdoMode::upload) return abort(0, 0, sdo::kAbortCommand);
      if (((c & 0x10) != 0) != sdo_toggle_) return abort(sdo_index_, sdo_sub_, sdo::kAbortToggle);
      const std::size_t n = std::min<std::size_t>(7, sdo_size_ - sdo_off_);
      const bool last = sdo_off_ + n == sdo_size_;
      tx(bus, sdo::upload_segment(node_, sdo_toggle_, &sdo_buf_[sdo_off_], std::uint8_t(n), last));
      sdo_off_ += n;
      sdo_toggle_ = !sdo_toggle_;
      if (last) sdo_mode_ = SdoMode::idle;
      return;
    }
    default:
      return abort(sdo::index_of(f), sdo::sub_of(f), sdo::kAbortCommand);
  }
}

void VirtualDrive::apply_rpdo(int p, const CanFrame& f) {
  const std::uint32_t count = get(kRpdoMap[p], 0);
  std::size_t off = 0;
  for (std::uint8_t s = 1; s <= count; ++s) {
    const std::uint32_t m = get(kRpdoMap[p], s);
    const std::size_t bytes = (m & 0xFF) / 8;
    if (off + bytes > f.len) return;  // too short: CiA 301 says ignore (EMCY 0x8210 on real drives)
    Entry* e = find(std::uint16_t(m >> 16), std::uint8_t(m >> 8));
    if (!e) return;
    std::uint32_t v = 0;
    for (std::size_t i = 0; i < bytes; ++i) v |= std::uint32_t(f.data[off + i]) << (8 * i);
    off += bytes;
    if (e->index == c402::kModesOfOperation) {
      // 6060h by PDO (the master switches CSP <-> CST within a cycle): a mode the
      // drive lacks is ignored (6061h tells the master); a change acts as when written by SDO.
      const std::int8_t m = std::int8_t(v);
      if (!mode_allowed(m) || m == mode_display()) continue;
      e->value = v;
      if (quirks_.halt_blocks_mode_change && (get(c402::kControlword) & c402::kCwHalt)) {
        pending_mode_ = m;
        has_pending_mode_ = true;
      } else {
        set_mode(m);
      }
      continue;
    }
    e->value = v;
  }
}

void VirtualDrive::send_tpdo(int p, CanBus& bus) {
  const std::uint32_t cob = get(kTpdoComm[p], 1);
  if (cob & kCobInvalid) return;
  CanFrame f;
  f.id = cob & 0x7FF;
  const std::uint32_t count = get(kTpdoMap[p], 0);
  std::size_t off = 0;
  for (std::uint8_t s = 1; s <= count; ++s) {
    const std::uint32_t m = get(kTpdoMap[p], s);
    const std::size_t bytes = (m & 0xFF) / 8;
    std::uint32_t v = get(std::uint16_t(m >> 16), std::uint8_t(m >> 8));
    if ((m >> 16) == c402::kPositionActual && faults_.position_noise > 0) {
      v = std::uint32_t(std::int32_t(v) +
                        std::int32_t(std::lround((2 * uniform() - 1) * faults_.position_noise)));
    }
    for (std::size_t i = 0; i < bytes && off + i < 8; ++i) f.data[off + i] = std::uint8_t(v >> (8 * i));
    off += bytes;
  }
  f.len = std::uint8_t(off);
  tx(bus, f);
}

void VirtualDrive::on_sync(TimePoint now, CanBus& bus) {
  ++syncs_;
  advance(now, bus);
  if (plant_ && tq_n_ > 0 && torque_unit_ != 0) {
    // On the plant 6077h at a SYNC is the mean of the loop's torque since the previous SYNC
    // (a drive's filtered current): the torque steps with every new target and decays within
    // the cycle, and a sample at the SYNC alone would miss most of that impulse.
    const double t = std::clamp(std::round(tq_sum_ / double(tq_n_) / torque_unit_), -32768.0, 32767.0);
    set(c402::kTorqueActual, std::uint32_t(std::uint16_t(std::int16_t(t))));
  }
  tq_sum_ = 0;
  tq_n_ = 0;
  // Inputs are sampled at the SYNC...
  for (int p = 0; p < kTpdos; ++p) {
    const std::uint32_t type = get(kTpdoComm[p], 2);
    if (type >= 1 && type <= 240 && syncs_ % type == 0) send_tpdo(p, bus);
  }
  // ...and outputs received before it are actuated at it.
  for (int p = 0; p < kRpdos; ++p) {
    if (rpdo_pending_[p]) {
      apply_rpdo(p, rpdo_latch_[p]);
      rpdo_pending_[p] = false;
    }
  }
  apply_controlword(now, bus);
}

void VirtualDrive::apply_controlword(TimePoint now, CanBus& bus) {
  (void)now;
  const std::uint16_t cw = std::uint16_t(get(c402::kControlword));
  int t = 0;
  const std::uint16_t before = prev_cw_;
  std::uint16_t prev = prev_cw_;
  if (quirks_.fault_reset_on_level) prev = std::uint16_t(prev & ~c402::cw::kFaultReset);  // any bit 7 resets
  c402::State next = c402::apply_controlword(state_, cw, prev, &t);
  prev_cw_ = cw;
  if (t == 4 && (faults_.refuse_enable || (mode_display() != c402::kModeCsp && mode_display() != c402::kModeCst))) {
    next = state_;  // refuses: stays switched on
  }
  if (t == 11 && plant_) {  // quick stop on the plant: ramp the velocity demand down from here
    qs_ramping_ = true;
    qs_vref_ = vel_ / (double(scaling_.direction) * scaling_.counts_per_si());
  }
  if (t == 4 || t == 16) {
    integ_ = 0;
    // No jump on enable: the demand starts where the shaft stands (607Ah too, so a master
    // that enables by SDO before it ever wrote a target does not send the motor to 0).
    target_ = std::int32_t(std::lround(pos_));
    set(c402::kTargetPosition, std::uint32_t(target_));
  }
  if (t == 11 && std::int16_t(get(c402::kQuickStopOption)) == 0) next = c402::State::switch_on_disabled;
  if (t == 15 && faults_.fault_persists) next = state_;  // the cause is still there: stays in fault
  if (t == 15 && !faults_.fault_persists) {  // fault reset: clear the error and say so
    set(c402::kErrorCode, 0);
    set(0x1001, 0);
    tx(bus, encode_emcy(node_, Emcy{}));
  }
  state_ = next;
  if (has_pending_mode_ && !(cw & c402::kCwHalt)) {  // halt_blocks_mode_change: acts now
    has_pending_mode_ = false;
    set_mode(pending_mode_);
  }
  const bool homing_active = h_.phase == HPhase::search || h_.phase == HPhase::final_edge ||
                             h_.phase == HPhase::index || h_.phase == HPhase::to_home;
  if (state_ == c402::State::operation_enabled && mode_display() == c402::kModeHoming) {
    // Homing mode: the homing generator owns the demand; 607Ah is not used.
    const bool rise = (cw & c402::kCwHomingStart) && !(before & c402::kCwHomingStart);
    const bool fall = !(cw & c402::kCwHomingStart) && (before & c402::kCwHomingStart);
    if (t == 4 || t == 16) h_.demand = double(target_), h_.v = 0;
    if (rise) {
      homing_start();
    } else if (fall && homing_active) {
      h_.phase = HPhase::interrupted;  // bit 4 back to 0: homing interrupted, the drive stops
    }
  } else if (state_ == c402::State::operation_enabled) {
    target_ = std::int32_t(get(c402::kTargetPosition));
  } else if (homing_active) {
    h_.phase = HPhase::interrupted;  // powered down (or fault) mid-homing
    h_.v = 0;
  }
  update_statusword();
}

void VirtualDrive::set_mode(std::int8_t m) {
  const std::int8_t old = mode_display();
  set(c402::kModesDisplay, std::uint32_t(std::uint8_t(m)));
  if (old == m) return;
  // No jump at a mode change: the demand starts where the shaft stands.
  target_ = std::int32_t(std::lround(pos_));
  set(c402::kTargetPosition, std::uint32_t(target_));
  if (old == c402::kModeHoming) h_.phase = HPhase::idle;  // statusword 10/12/13 belong to homing mode
  h_.v = 0;
  h_.demand = double(target_);
}

std::uint32_t VirtualDrive::digital_inputs() const {
  const double p = pos_ - shift_;
  std::uint32_t v = 0;
  if (p <= switches_.neg_limit) v |= c402::kDiNegLimit;
  if (p >= switches_.pos_limit) v |= c402::kDiPosLimit;
  if (home_active(p)) v |= c402::kDiHome;
  return v | std::atomic_ref<std::uint32_t>(input_bits_).load(std::memory_order_relaxed);
}

bool VirtualDrive::signal_at(double p) const {
  switch (h_.signal) {
    case 1: return p <= switches_.neg_limit;
    case 2: return p >= switches_.pos_limit;
    default: return home_active(p);
  }
}

namespace {
/// The first index pulse strictly beyond `p` moving in `dir`.
double next_index(double p, int dir, double period, double phase) {
  if (!(period > 0)) return dir > 0 ? DriveSwitches::kNone : -DriveSwitches::kNone;
  const double k = (p - phase) / period;
  const double n = dir > 0 ? std::floor(k) + 1 : std::ceil(k) - 1;
  return phase + n * period;
}
}  // namespace

void VirtualDrive::homing_start() {
  const std::int8_t method = std::int8_t(get(c402::kHomingMethod));
  Homing h;
  h.demand = double(target_);
  h.v = 0;
  const double p = pos_ - shift_;
  const double sw = double(get(c402::kHomingSpeeds, 1)), sz = double(get(c402::kHomingSpeeds, 2));
  const bool home_now = home_active(p);
  // signal, edge, direction crossing it, signal state before the edge, index, initial direction, reversal
  auto table = [&](int signal, double edge, int d_final, bool want, bool index, int d_init, bool rev) {
    h.signal = signal;
    h.edge = edge;
    h.d_final = d_final;
    h.want_before = want;
    h.use_index = index;
    h.may_reverse = rev;
    h.dir = d_init;
    h.speed = sw;
    h.phase = HPhase::search;
  };
  const struct {
    double neg, pos, lo, hi;
  } g{switches_.neg_limit, switches_.pos_limit, switches_.home_lo, switches_.home_hi};
  switch (method) {
    case 1: case 17: table(1, g.neg, +1, true, method == 1, -1, false); break;
    case 2: case 18: table(2, g.pos, -1, true, method == 2, +1, false); break;
    case 3: case 19: table(0, g.lo, -1, true, method == 3, home_now ? -1 : +1, false); break;
    case 4: case 20: table(0, g.lo, +1, false, method == 4, home_now ? -1 : +1, false); break;
    case 5: case 21: table(0, g.hi, +1, true, method == 5, home_now ? +1 : -1, false); break;
    case 6: case 22: table(0, g.hi, -1, false, method == 6, home_now ? +1 : -1, false); break;
    case 7: case 23: table(0, g.lo, -1, true, method == 7, +1, true); break;
    case 11: case 27: table(0, g.hi, +1, true, method == 11, -1, true); break;
    case 33: case 34:
      h.dir = h.d_final = method == 33 ? -1 : +1;
      h.speed = sz;
      h.phase = HPhase::index;
      h.index_at = next_index(p, h.dir, switches_.index_period, switches_.index_phase);
      break;
    case 35: case 37:
      h_ = h;
      homing_capture(p);  // the current position is the home mark
      return;
    default:
      h.phase = HPhase::error;
      break;
  }
  h_ = h;
  if (h_.phase == HPhase::search && signal_at(p) == h_.want_before) {
    h_.phase = HPhase::final_edge;  // already on the near side of the edge: approach it slowly
    h_.dir = h_.d_final;
    h_.speed = sz;
  }
}

void VirtualDrive::homing_capture(double mark) {
  const double shift = double(std::int32_t(get(c402::kHomeOffset))) - mark;
  const double d = shift - shift_;
  pos_ += d;
  h_.demand += d;
  target_ = std::int32_t(std::lround(std::clamp(h_.demand, -2147483648.0, 2147483647.0)));
  shift_ = shift;
  home_mark_ = mark;
  h_.goal = double(std::int32_t(get(c402::kHomeOffset)));
  h_.speed = double(get(c402::kHomingSpeeds, 2));
  h_.phase = HPhase::to_home;
}

void VirtualDrive::homing_fail() {
  h_.phase = HPhase::error;  // the generator ramps the demand down to a stop
}

void VirtualDrive::homing_substep(double dt, bool halt) {
  double a = double(get(c402::kHomingAccel));
  if (!(a > 0)) a = motor_.max_accel;
  double vt = 0;
  switch (h_.phase) {
    case HPhase::search:
    case HPhase::final_edge:
    case HPhase::index:
      vt = halt ? 0.0 : double(h_.dir) * h_.speed;
      break;
    case HPhase::to_home: {
      const double d = h_.goal - h_.demand;
      const double vmax = std::min(h_.speed, std::sqrt(2.0 * a * std::fabs(d)));
      vt = halt ? 0.0 : (d > 0 ? vmax : -vmax);
      break;
    }
    case HPhase::idle:
    case HPhase::attained:
    case HPhase::error:
    case HPhase::interrupted:
      break;
  }
  h_.v += std::clamp(vt - h_.v, -a * dt, a * dt);
  const double step = h_.v * dt;
  if (h_.phase == HPhase::to_home && !halt &&
      (std::fabs(h_.goal - h_.demand) <= std::fabs(step) || std::fabs(h_.goal - h_.demand) < 0.5)) {
    h_.demand = h_.goal;  // on the mark: no overshoot of the demand
    h_.v = 0;
  } else {
    h_.demand += step;
  }
  h_.travel += std::fabs(step);
  target_ = std::int32_t(std::lround(std::clamp(h_.demand, -2147483648.0, 2147483647.0)));
}

void VirtualDrive::homing_after(double p0, double p1) {
  const bool running = h_.phase == HPhase::search || h_.phase == HPhase::final_edge || h_.phase == HPhase::index;
  if (running) {
    // The switch was never found: the end stop, the second limit switch, or the travel limit.
    if (at_stop_ || (switches_.max_travel > 0 && h_.travel > switches_.max_travel)) return homing_fail();
    // Running onto a limit switch (its edge, moving towards it) that is not the one sought.
    const bool nl = p1 <= switches_.neg_limit && p0 > switches_.neg_limit && h_.signal != 1;
    const bool pl = p1 >= switches_.pos_limit && p0 < switches_.pos_limit && h_.signal != 2;
    if (nl || pl) {
      if (h_.phase == HPhase::search && h_.may_reverse && !h_.reversed) {
        h_.reversed = true;
        h_.dir = -h_.dir;
      } else {
        return homing_fail();
      }
    }
  }
  switch (h_.phase) {
    case HPhase::search:
      if (signal_at(p1) == h_.want_before) {  // on the near side of the edge: reverse if needed, slow down
        h_.phase = HPhase::final_edge;
        h_.dir = h_.d_final;
        h_.speed = double(get(c402::kHomingSpeeds, 2));
      }
      break;
    case HPhase::final_edge:
      if (signal_at(p0) == h_.want_before && signal_at(p1) != h_.want_before && (p1 - p0) * h_.d_final > 0) {
        if (h_.use_index) {
          h_.phase = HPhase::index;
          h_.index_at = next_index(h_.edge, h_.d_final, switches_.index_period, switches_.index_phase);
        } else {
          homing_capture(h_.edge);  // the edge is latched where the switch is (a hardware capture)
        }
      }
      break;
    case HPhase::index:
      if ((p1 - h_.index_at) * h_.dir >= 0 && (p0 - h_.index_at) * h_.dir < 0) homing_capture(h_.index_at);
      break;
    case HPhase::to_home:
      if (h_.demand == h_.goal && std::fabs(pos_ - h_.goal) < 0.5 && std::fabs(vel_) < 100) h_.phase = HPhase::attained;
      break;
    case HPhase::idle:
    case HPhase::attained:
    case HPhase::error:
    case HPhase::interrupted:
      break;
  }
}

void VirtualDrive::inject_emcy(std::uint16_t code, TimePoint now, CanBus& bus) {
  if (code == 0) return;
  advance(now, bus);
  set(c402::kErrorCode, code);
  set(0x1001, 0x01 | ((code & 0xF000) == 0x2000 ? 0x02 : 0) | ((code & 0xF000) == 0x3000 ? 0x04 : 0) |
                  ((code & 0xF000) == 0x4000 ? 0x08 : 0));
  Emcy e;
  e.error_code = code;
  e.error_register = std::uint8_t(get(0x1001));
  tx(bus, encode_emcy(node_, e));
  state_ = c402::State::fault;  // fault reaction (stop) is immediate in the model
  update_statusword();
}

void VirtualDrive::advance(TimePoint now, CanBus& bus) {
  if (plant_) {
    plant_->advance(now, bus);  // every drive of the arm and the dynamics, in lockstep
    return;
  }
  if (now <= t_) return;
  const double dt = double(motor_.substep) * 1e-9;
  const bool homing_mode = mode_display() == c402::kModeHoming;
  const bool halt = (get(c402::kControlword) & c402::kCwHalt) != 0;
  while (t_ + motor_.substep <= now) {
    t_ += motor_.substep;
    const bool homing = homing_mode && state_ == c402::State::operation_enabled;
    if (homing) homing_substep(dt, halt);
    const double p0 = pos_ - shift_;
    double v_des = 0.0;
    const bool powered = state_ == c402::State::operation_enabled;
    if (powered) v_des = (double(target_) - pos_) / motor_.lag;
    v_des = std::clamp(v_des, -motor_.max_velocity, motor_.max_velocity);
    double amax = motor_.max_accel;
    if (state_ == c402::State::quick_stop_active) amax = std::min(amax, double(get(c402::kQuickStopDecel)));
    const double dv = std::clamp(v_des - vel_, -amax * dt, amax * dt);
    vel_ += dv;
    pos_ += vel_ * dt;
    // Settled on a target at (or near) count 0 -- a homing offset of 0, a move to 0 -- the lag's
    // exponential approach would go on into subnormal numbers (FE_UNDERFLOW): snap to it.
    if (powered && std::fabs(double(target_) - pos_) < 1e-9 && std::fabs(vel_) < 1e-6) pos_ = double(target_), vel_ = 0.0;
    // Mechanical end stops: the shaft stops there, whatever the demand.
    const double p = pos_ - shift_;
    at_stop_ = false;
    if (p < switches_.end_neg) {
      pos_ = switches_.end_neg + shift_;
      vel_ = std::max(vel_, 0.0);
      at_stop_ = true;
    } else if (p > switches_.end_pos) {
      pos_ = switches_.end_pos + shift_;
      vel_ = std::min(vel_, 0.0);
      at_stop_ = true;
    }
    if (homing) homing_after(p0, pos_ - shift_);
    after_substep(bus, vel_ == 0.0);
  }
  publish_feedback();
}

void VirtualDrive::after_substep(CanBus& bus, bool at_rest) {
  if (state_ == c402::State::quick_stop_active && at_rest) {
    const std::int16_t o = std::int16_t(get(c402::kQuickStopOption));
    if (o == 1 || o == 2) state_ = c402::State::switch_on_disabled;  // at rest: transition 12
  }
  if (state_ == c402::State::operation_enabled && mode_display() == c402::kModeCst) {
    // CST: no position demand, no following error; the demand follows the shaft so that
    // CSP resumes where the joint stands.
    target_ = std::int32_t(std::lround(pos_));
    set(c402::kFollowingErrorActual, 0);
  } else if (state_ == c402::State::operation_enabled) {
    const double fe = double(target_) - pos_;
    set(c402::kFollowingErrorActual, std::uint32_t(std::int32_t(std::lround(fe))));
    const std::uint32_t window = get(c402::kFollowingErrorWindow);
    if (window != 0xFFFFFFFFu && std::fabs(fe) > double(window)) {
      inject_emcy(0x8611, t_, bus);
    }
  }
}

void VirtualDrive::publish_feedback() {
  // Encoder quantisation: the drive reports whole counts.
  set(c402::kPositionActual, std::uint32_t(std::int32_t(std::floor(pos_))));
  set(c402::kVelocityActual, std::uint32_t(std::int32_t(std::lround(vel_))));
  if (torque_unit_ != 0) {
    const double t = std::clamp(std::round(torque_ / torque_unit_), -32768.0, 32767.0);
    set(c402::kTorqueActual, std::uint32_t(std::uint16_t(std::int16_t(t))));
  } else {
    // First-order motor: massless, no torque while free; pushing on an end stop it reports
    // the push, proportional to the following error (the following error window = 1000 per mille).
    double t = 0;
    if (at_stop_) {
      const double w = std::max(1.0, double(get(c402::kFollowingErrorWindow)));
      t = std::clamp(std::round(1000.0 * (double(target_) - pos_) / w), -32768.0, 32767.0);
    }
    set(c402::kTorqueActual, std::uint32_t(std::uint16_t(std::int16_t(t))));
  }
  set(c402::kDigitalInputs, digital_inputs());
  update_statusword();
}

void VirtualDrive::attach_plant(ArmPlant* plant, const hal::JointScaling& s, double kp, double kv, double ki,
                                double torque_limit, std::uint32_t rated_torque_mnm) {
  plant_ = plant;
  scaling_ = s;
  kp_ = kp;
  kv_ = kv;
  ki_ = ki;
  tmax_ = torque_limit;
  if (Entry* e = find(c402::kRatedTorque, 0)) e->value = e->initial = rated_torque_mnm;
  update_supported_modes();  // CST offered on the plant
  torque_unit_ = double(rated_torque_mnm) * 1e-6 * s.gear_ratio * double(s.direction);
  integ_ = 0;
  qs_ramping_ = false;
}

// The drive's loops on the plant, once per step (joint units): position P, velocity PI,
// the CSP offsets 60B1h/60B2h, the torque limit; quick stop ramps the velocity demand down
// with 6085h, then holds. Unpowered: no torque.
double VirtualDrive::servo_torque(double q, double qd, double h) {
  const double cps = scaling_.counts_per_si();
  const double vmax = motor_.max_velocity / cps;
  auto limit = [this](double t) { return std::clamp(t, -tmax_, tmax_); };
  switch (state_) {
    case c402::State::operation_enabled: {
      qs_ramping_ = false;
      if (mode_display() == c402::kModeCst) {
        // Cyclic synchronous torque: target torque 6071h + torque offset 60B2h, saturated at
        // the drive's torque limit.
        integ_ = 0;
        const double t = (double(std::int16_t(get(c402::kTargetTorque))) +
                          double(std::int16_t(get(c402::kTorqueOffset)))) * torque_unit_;
        return limit(t);
      }
      if (mode_display() == c402::kModeHoming) homing_substep(h, (get(c402::kControlword) & c402::kCwHalt) != 0);
      const double qt = scaling_.to_joint(std::int32_t(std::lround(double(target_) - shift_)));
      const double v_off = scaling_.velocity_to_joint(std::int32_t(get(c402::kVelocityOffset)));
      const double v = std::clamp(kp_ * (qt - q) + v_off, -vmax, vmax);
      const double e = v - qd;
      if (ki_ > 0 && kv_ > 0) {
        integ_ += ki_ * e * h;
        const double imax = tmax_ / kv_;  // anti-windup: the integral alone never exceeds the limit
        integ_ = std::clamp(integ_, -imax, imax);
      }
      const double t_off = double(std::int16_t(get(c402::kTorqueOffset))) * torque_unit_;
      return limit(kv_ * (e + integ_) + t_off);
    }
    case c402::State::quick_stop_active: {
      if (qs_ramping_) {
        const double dec = std::max(double(get(c402::kQuickStopDecel)), 1.0) / cps * h;
        qs_vref_ = qs_vref_ > 0 ? std::max(0.0, qs_vref_ - dec) : std::min(0.0, qs_vref_ + dec);
        if (qs_vref_ == 0.0) {
          qs_ramping_ = false;
          hold_q_ = q;
        }
        return limit(kv_ * (qs_vref_ - qd));
      }
      return limit(kv_ * (kp_ * (hold_q_ - q) - qd));
    }
    case c402::State::not_ready_to_switch_on:
    case c402::State::switch_on_disabled:
    case c402::State::ready_to_switch_on:
    case c402::State::switched_on:
    case c402::State::fault_reaction_active:
    case c402::State::fault:
      break;
  }
  integ_ = 0;
  return 0.0;
}

void VirtualDrive::plant_update(TimePoint t, double q, double qd, double torque, CanBus& bus) {
  t_ = t;
  const double k = double(scaling_.direction) * scaling_.counts_per_si();
  const double p0 = pos_ - shift_;
  pos_ = double(scaling_.zero_offset) + k * q + shift_;
  if (state_ == c402::State::operation_enabled && mode_display() == c402::kModeHoming) homing_after(p0, pos_ - shift_);
  vel_ = k * qd;
  torque_ = torque;
  tq_sum_ += torque;
  ++tq_n_;
  after_substep(bus, !qs_ramping_ && std::fabs(qd) < 5e-3);
}

void VirtualDrive::update_statusword() {
  std::uint16_t sw = c402::encode_state_bits(state_);
  if (state_ == c402::State::switched_on || state_ == c402::State::operation_enabled ||
      state_ == c402::State::quick_stop_active || state_ == c402::State::ready_to_switch_on)
    sw |= c402::kSwVoltageEnabled;
  sw |= c402::kSwRemote;
  if (mode_display() == c402::kModeHoming) {
    // Homing mode (CiA 402): bit 10 target reached (stopped: not started, interrupted, halted,
    // done or failed), bit 12 homing attained, bit 13 homing error.
    const bool stopped = h_.v == 0.0 && std::fabs(vel_) < 100.0;
    switch (h_.phase) {
      case HPhase::idle:
      case HPhase::interrupted:
        if (stopped) sw |= c402::kSwTargetReached;
        break;
      case HPhase::search:
      case HPhase::final_edge:
      case HPhase::index:
      case HPhase::to_home:
        if (stopped && (get(c402::kControlword) & c402::kCwHalt)) sw |= c402::kSwTargetReached;
        break;
      case HPhase::attained:
        sw |= c402::kSwTargetReached;
        if (!quirks_.never_attained) sw |= c402::kSwHomingAttained;
        break;
      case HPhase::error:
        sw |= c402::kSwHomingError;
        if (stopped) sw |= c402::kSwTargetReached;
        break;
    }
  } else if (state_ == c402::State::operation_enabled && std::fabs(double(target_) - pos_) < 10.0) {
    sw |= c402::kSwTargetReached;
  }
  set(c402::kStatusword, sw);
}

void VirtualDrive::tick(TimePoint now, CanBus& bus) {
  now_ = now;
  if (!booted_ && boot_at_ != 0 && now >= boot_at_) boot(now, bus);
  if (!delayed_.empty()) {  // quirks().sdo_delay: replies that are due now, in order
    std::size_t k = 0;
    while (k < delayed_.size() && delayed_[k].first <= now) {
      if (!faults_.silent) bus.send(delayed_[k].second);
      ++k;
    }
    delayed_.erase(delayed_.begin(), delayed_.begin() + std::ptrdiff_t(k));
  }
  if (!booted_) return;
  advance(now, bus);
  const std::uint32_t hb_ms = get(0x1017);
  if (hb_ms == 0 || faults_.heartbeat_stopped) {
    next_hb_ = now;
    return;
  }
  if (now >= next_hb_) {
    tx(bus, encode_heartbeat(node_, nmt_));
    const Duration period = Duration(hb_ms) * hal::kMillisecond;
    next_hb_ += period;
    if (next_hb_ <= now) next_hb_ = now + period;
  }
}

ArmSim::ArmSim(CanBus& bus, std::span<const std::uint8_t> nodes, const MotorParams& motor, std::uint64_t seed)
    : bus_(bus) {
  drives_.reserve(nodes.size());
  for (std::uint8_t n : nodes) drives_.emplace_back(n, motor, seed);
}

ArmSim::~ArmSim() = default;

std::string ArmSim::use_dynamic_plant(const kin::Chain& chain, std::span<const hal::JointScaling> scaling,
                                      const ArmPlantParams& params) {
  if (drives_.size() != static_cast<std::size_t>(chain.n_joints))
    return "dynamic plant: " + std::to_string(drives_.size()) + " drives for the " + std::to_string(chain.n_joints) +
           " joints of '" + std::string(chain.name.data()) + "'";
  auto p = std::make_unique<ArmPlant>();
  if (std::string e = p->configure(chain, scaling, params); !e.empty()) return e;
  plant_ = std::move(p);
  for (std::size_t i = 0; i < drives_.size(); ++i) plant_->attach(int(i), &drives_[i]);
  return "";
}

void VirtualDrive::place_at(double counts) {
  pos_ = counts;
  vel_ = 0.0;
  shift_ = 0.0;
  target_ = std::int32_t(std::lround(std::clamp(counts, -2147483648.0, 2147483647.0)));
  set(c402::kPositionActual, std::uint32_t(std::int32_t(std::floor(pos_))));
}

void VirtualDrive::fit_motion(double velocity, double acceleration) {
  if (std::isfinite(velocity)) motor_.max_velocity = std::max(motor_.max_velocity, 1.5 * std::fabs(velocity));
  if (std::isfinite(acceleration)) motor_.max_accel = std::max(motor_.max_accel, 1.5 * std::fabs(acceleration));
  const double window = std::min(4.0 * motor_.max_velocity * motor_.lag, 4294967294.0);
  if (window > double(get(c402::kFollowingErrorWindow))) set(c402::kFollowingErrorWindow, std::uint32_t(window));
  if (double(get(c402::kQuickStopDecel)) < motor_.max_accel)
    set(c402::kQuickStopDecel, std::uint32_t(std::clamp(std::round(motor_.max_accel), 1.0, 4294967295.0)));
}

void VirtualDrive::skip_to(TimePoint now) {
  if (!plant_ && now > t_) t_ = now;
}

void ArmSim::skip_to(TimePoint now) {
  for (auto& d : drives_) d.skip_to(now);
  if (plant_) plant_->skip_to(now);
}

void ArmSim::place_within_limits(const kin::Chain& chain, std::span<const hal::JointScaling> scaling) {
  const std::size_t n = std::min({drives_.size(), scaling.size(), static_cast<std::size_t>(chain.n_joints)});
  for (std::size_t i = 0; i < n; ++i) {
    const kin::DhRow& row = chain.joint(static_cast<int>(i));
    const double q = std::clamp(0.0, row.lower, row.upper);  // the in-limit value closest to 0
    const hal::JointScaling& s = scaling[i];
    drives_[i].place_at(double(s.zero_offset) + double(s.direction) * q * s.counts_per_si());
    // and follows the joint's own limits (a prismatic joint's counts per metre are many)
    drives_[i].fit_motion(row.dynamics.max_velocity * s.counts_per_si(), row.dynamics.max_acceleration * s.counts_per_si());
    if (plant_) plant_->attach(static_cast<int>(i), &drives_[i]);  // the plant starts there too
  }
}

void ArmSim::power_on(TimePoint now) {
  for (auto& d : drives_) d.power_on(now, bus_);
}

void ArmSim::handle(const CanFrame& f, TimePoint now) {
  for (auto& d : drives_) d.handle(f, now, bus_);
}

void ArmSim::tick(TimePoint now) {
  for (auto& d : drives_) d.tick(now, bus_);
}

void ArmSim::step(TimePoint now) {
  CanFrame f;
  for (int i = 0; i < 4096 && bus_.receive(f, 0) == hal::Status::ok; ++i) handle(f, now);
  tick(now);
}

VirtualDrive* ArmSim::node(std::uint8_t n) {
  for (auto& d : drives_)
    if (d.node() == n) return &d;
  return nullptr;
}

}  // namespace servoarm::sim
