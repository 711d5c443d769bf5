// SPDX-License-Identifier: Apache-2.0
// The drive doctor's scan (drive_scan.hpp).
#include "servoarm/hal/drive_scan.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "servoarm/hal/sdo_client.hpp"

namespace servoarm::hal {

namespace {

/// Sends `f`, waiting a little when the transmit queue is full (a burst on a real interface).
void send_paced(CanBus& bus, Clock& clock, CanFrame f, bool fd) {
  if (fd) f.fd = f.brs = true;
  for (int i = 0; i < 20; ++i) {
    if (bus.send(f) != Status::would_block) return;
    clock.sleep_until(clock.now() + kMillisecond);
  }
}

/// Hands every frame that arrives until `until` to `take`.
template <class Take>
void collect(CanBus& bus, Clock& clock, TimePoint until, Take&& take) {
  for (;;) {
    CanFrame f;
    while (bus.receive(f, 0) == Status::ok) take(f);
    const TimePoint now = clock.now();
    if (now >= until) return;
    clock.sleep_until(std::min(now + 200 * kMicrosecond, until));
  }
}

bool reg_ask(CanBus& bus, Clock& clock, const ScanOptions& opt, std::uint16_t id, mit::Reg rid, std::uint32_t& raw) {
  const auto r = static_cast<std::uint8_t>(rid);
  send_paced(bus, clock, mit::reg_read(id, r), opt.fd);
  bool got = false;
  const TimePoint until = clock.now() + opt.timeout;
  for (;;) {
    CanFrame f;
    while (!got && bus.receive(f, 0) == Status::ok) {
      mit::RegMessage m;
      if (f.id != mit::kRegisterId && f.len == 8 && mit::decode_register(f, m) && m.motor_id == id &&
          m.cmd == mit::RegCmd::read && m.rid == r) {
        raw = m.raw;
        got = true;
      }
    }
    const TimePoint now = clock.now();
    if (got || now >= until) return got;
    clock.sleep_until(std::min(now + 200 * kMicrosecond, until));
  }
}

float as_float(std::uint32_t raw) {
  float v;
  std::memcpy(&v, &raw, sizeof v);
  return v;
}

}  // namespace

std::size_t scan_drives(CanBus& bus, Clock& clock, const ScanOptions& opt, std::span<ScannedDrive> out) {
  std::size_t n = 0;
  const std::uint16_t lo = std::max<std::uint16_t>(1, opt.first_id);
  CanFrame drop;
  while (bus.receive(drop, 0) == Status::ok) {
  }
  if (opt.canopen) {
    const std::uint16_t hi = std::min<std::uint16_t>(127, opt.last_id);
    bool seen[128] = {};
    std::uint32_t type[128] = {};
    for (std::uint16_t id = lo; id <= hi; ++id)
      send_paced(bus, clock, CanFrame::make(0x600u + id, {0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0}), false);
    collect(bus, clock, clock.now() + opt.window, [&](const CanFrame& f) {
      if (f.error || f.extended || f.len != 8 || f.id <= 0x580 || f.id > 0x5FF) return;
      const unsigned id = f.id - 0x580;
      if ((f.data[0] & 0xE3) == 0x43 && f.data[1] == 0x00 && f.data[2] == 0x10 && f.data[3] == 0) {
        seen[id] = true;
        type[id] = get_u32(&f.data[4]);
      }
    });
    SdoClient sdo(bus, clock, opt.timeout);
    for (unsigned id = lo; id <= hi && n < out.size(); ++id) {
      if (!seen[id]) continue;
      ScannedDrive d;
      d.kind = ScannedDrive::Kind::canopen;
      d.id = static_cast<std::uint16_t>(id);
      d.device_type = type[id];
      sdo.read_u32(static_cast<std::uint8_t>(id), 0x1018, 1, d.vendor);
      sdo.read_u32(static_cast<std::uint8_t>(id), 0x1018, 2, d.product);
      sdo.read_u32(static_cast<std::uint8_t>(id), 0x1018, 3, d.revision);
      out[n++] = d;
    }
  }
  if (opt.damiao) {
    const std::uint16_t hi = std::min<std::uint16_t>(0x7FE, opt.last_id);
    constexpr std::size_t kMax = 0x7FF;
    static_assert(kMax <= 2048);
    std::uint16_t master[kMax] = {};
    std::uint32_t mode[kMax] = {};
    bool seen[kMax] = {};
    const auto ctrl = static_cast<std::uint8_t>(mit::Reg::ctrl_mode);
    for (std::uint16_t id = lo; id <= hi; ++id) send_paced(bus, clock, mit::reg_read(id, ctrl), opt.fd);
    collect(bus, clock, clock.now() + opt.window, [&](const CanFrame& f) {
      mit::RegMessage m;
      if (f.error || f.extended || f.id == mit::kRegisterId || f.len != 8 || !mit::decode_register(f, m)) return;
      if (m.cmd != mit::RegCmd::read || m.rid != ctrl || m.motor_id < lo || m.motor_id > hi) return;
      seen[m.motor_id] = true;
      master[m.motor_id] = static_cast<std::uint16_t>(f.id);
      mode[m.motor_id] = m.raw;
    });
    for (std::uint16_t id = lo; id <= hi && n < out.size(); ++id) {
      if (!seen[id]) continue;
      ScannedDrive d;
      d.kind = ScannedDrive::Kind::damiao;
      d.id = id;
      d.master_id = master[id];
      d.ctrl_mode = mode[id];
      std::uint32_t raw = 0;
      if (reg_ask(bus, clock, opt, id, mit::Reg::pmax, raw)) d.pmax = as_float(raw);
      if (reg_ask(bus, clock, opt, id, mit::Reg::vmax, raw)) d.vmax = as_float(raw);
      if (reg_ask(bus, clock, opt, id, mit::Reg::tmax, raw)) d.tmax = as_float(raw);
      if (reg_ask(bus, clock, opt, id, mit::Reg::gr, raw)) d.gear = as_float(raw);
      if (reg_ask(bus, clock, opt, id, mit::Reg::timeout, raw)) d.timeout = raw;
      if (reg_ask(bus, clock, opt, id, mit::Reg::sw_ver, raw)) d.sw_ver = raw;
      for (const mit::MotorProfile& p : mit::motor_profiles())
        if (p.vendor == mit::Vendor::damiao && std::fabs(p.gear_ratio - d.gear) < 0.01 && std::fabs(p.t_max - d.tmax) < 0.01)
          d.model = &p;
      out[n++] = d;
    }
  }
  return n;
}

void describe_drive(const ScannedDrive& d, char* buf, std::size_t size) {
  if (size == 0) return;
  switch (d.kind) {
    case ScannedDrive::Kind::canopen:
      std::snprintf(buf, size, "id %u: CANopen node, device type 0x%08X%s, vendor 0x%08X, product 0x%08X, revision 0x%08X",
                    unsigned(d.id), unsigned(d.device_type), (d.device_type & 0xFFFF) == 402 ? " (CiA 402 drive)" : "",
                    unsigned(d.vendor), unsigned(d.product), unsigned(d.revision));
      return;
    case ScannedDrive::Kind::damiao: {
      char model[64];
      if (d.model != nullptr) std::snprintf(model, sizeof model, "%s (Gr %g, TMAX %g)", d.model->name, double(d.gear), double(d.tmax));
      else std::snprintf(model, sizeof model, "model unknown (Gr %g, TMAX %g)", double(d.gear), double(d.tmax));
      char mode[96];
      if (d.ctrl_mode == mit::kModeMit) std::snprintf(mode, sizeof mode, "mode MIT");
      else
        std::snprintf(mode, sizeof mode, "mode %u %s (not MIT: armfw sets CTRL_MODE = 1 at bring-up)", unsigned(d.ctrl_mode),
                      mit::ctrl_mode_name(d.ctrl_mode));
      char wd[64];
      if (d.timeout == 0) std::snprintf(wd, sizeof wd, "CAN timeout off (armfw sets it)");
      else std::snprintf(wd, sizeof wd, "CAN timeout %g ms", d.timeout * (mit::kTimeoutUnitNs * 1e-6));
      std::snprintf(buf, size, "id 0x%02X: damiao %s, %s, master 0x%03X, %s, PMAX %g, VMAX %g, sw 0x%X", unsigned(d.id), model,
                    mode, unsigned(d.master_id), wd, double(d.pmax), double(d.vmax), unsigned(d.sw_ver));
      return;
    }
  }
}

bool read_drive_status(CanBus& bus, Clock& clock, const ScanOptions& opt, const ScannedDrive& d, DriveStatus& out) {
  out = DriveStatus{};
  switch (d.kind) {
    case ScannedDrive::Kind::canopen: {
      SdoClient sdo(bus, clock, opt.timeout);
      std::uint32_t reg = 0, code = 0;
      if (sdo.read_u32(static_cast<std::uint8_t>(d.id), 0x1001, 0, reg).status != Status::ok) return false;
      out.answered = true;
      out.error = static_cast<std::uint8_t>(reg);
      if (sdo.read_u32(static_cast<std::uint8_t>(d.id), 0x603F, 0, code).status == Status::ok)
        out.error_code = static_cast<std::uint16_t>(code);
      return true;
    }
    case ScannedDrive::Kind::damiao: {
      mit::Ranges r;
      if (d.model != nullptr) r = mit::ranges_of(*d.model);
      if (d.pmax > 0) r.p_max = d.pmax;
      if (d.vmax > 0) r.v_max = d.vmax;
      if (d.tmax > 0) r.t_max = d.tmax;
      CanFrame drop;
      while (bus.receive(drop, 0) == Status::ok) {
      }
      send_paced(bus, clock, mit::refresh_frame(d.id), opt.fd);
      collect(bus, clock, clock.now() + opt.timeout, [&](const CanFrame& f) {
        mit::Feedback fb;
        if (out.answered || f.error || f.extended || f.id != d.master_id || f.len != 8) return;
        if (!mit::decode_feedback(mit::Vendor::damiao, r, f, fb) || fb.id != (d.id & 0x0F)) return;
        out.answered = true;
        out.fd = f.fd;
        out.error = fb.error;
        out.has_temperature = true;
        out.t_mos = static_cast<float>(fb.t_mos);
        out.t_rotor = static_cast<float>(fb.t_rotor);
        out.position = fb.p;
      });
      return out.answered;
    }
  }
  return false;
}

void describe_status(const ScannedDrive& d, const DriveStatus& s, char* buf, std::size_t size) {
  if (size == 0) return;
  if (!s.answered) {
    std::snprintf(buf, size, "status: no answer");
    return;
  }
  switch (d.kind) {
    case ScannedDrive::Kind::canopen:
      if (s.error == 0) std::snprintf(buf, size, "no error");
      else std::snprintf(buf, size, "error register 0x%02X, error code 0x%04X", unsigned(s.error), unsigned(s.error_code));
      return;
    case ScannedDrive::Kind::damiao: {
      char err[64];
      if (mit::damiao_is_fault(s.error)) std::snprintf(err, sizeof err, "error %s (%u)", mit::damiao_error_name(s.error), unsigned(s.error));
      else std::snprintf(err, sizeof err, "no error, %s", s.error == 1 ? "enabled" : "disabled");
      std::snprintf(buf, size, "%s, %s, MOS %.0f C, rotor %.0f C", s.fd ? "CAN FD" : "classic CAN", err, double(s.t_mos),
                    double(s.t_rotor));
      return;
    }
  }
}

}  // namespace servoarm::hal
