// SPDX-License-Identifier: Apache-2.0
#include "servoarm/hal/canopen.hpp"

#include <cstring>

namespace servoarm::hal::canopen {

const char* to_string(NmtCommand c) {
  switch (c) {
    case NmtCommand::start: return "start";
    case NmtCommand::stop: return "stop";
    case NmtCommand::enter_pre_operational: return "enter_pre_operational";
    case NmtCommand::reset_node: return "reset_node";
    case NmtCommand::reset_communication: return "reset_communication";
  }
  return "unknown";
}

const char* to_string(NmtState s) {
  switch (s) {
    case NmtState::boot_up: return "boot_up";
    case NmtState::stopped: return "stopped";
    case NmtState::operational: return "operational";
    case NmtState::pre_operational: return "pre_operational";
  }
  return "unknown";
}

CanFrame encode_nmt(NmtCommand cmd, std::uint8_t node) {
  CanFrame f;
  f.id = kNmt;
  f.len = 2;
  f.data[0] = std::uint8_t(cmd);
  f.data[1] = node;
  return f;
}

bool decode_nmt(const CanFrame& f, NmtCommand& cmd, std::uint8_t& node) {
  if (f.extended || f.rtr || f.error || f.id != kNmt || f.len != 2 || f.data[1] > kMaxNodeId) return false;
  switch (f.data[0]) {
    case 0x01: case 0x02: case 0x80: case 0x81: case 0x82:
      cmd = NmtCommand(f.data[0]);
      node = f.data[1];
      return true;
    default:
      return false;
  }
}

CanFrame encode_sync(std::uint8_t counter) {
  CanFrame f;
  f.id = kSync;
  if (counter != 0) {
    f.len = 1;
    f.data[0] = counter;
  }
  return f;
}

bool is_sync(const CanFrame& f) { return !f.extended && !f.rtr && !f.error && f.id == kSync && f.len <= 1; }

CanFrame encode_heartbeat(std::uint8_t node, NmtState state) {
  CanFrame f;
  f.id = kHeartbeat + node;
  f.len = 1;
  f.data[0] = std::uint8_t(state);
  return f;
}

bool decode_heartbeat(const CanFrame& f, std::uint8_t& node, NmtState& state) {
  if (f.extended || f.rtr || f.error || function_of(f.id) != kHeartbeat || f.len != 1) return false;
  node = node_of(f.id);
  if (!valid_node(node)) return false;
  switch (f.data[0] & 0x7F) {  // bit 7 is the node-guarding toggle, unused with heartbeat
    case 0x00: case 0x04: case 0x05: case 0x7F:
      state = NmtState(f.data[0] & 0x7F);
      return true;
    default:
      return false;
  }
}

CanFrame encode_emcy(std::uint8_t node, const Emcy& e) {
  CanFrame f;
  f.id = kEmcy + node;
  f.len = 8;
  put_u16(&f.data[0], e.error_code);
  f.data[2] = e.error_register;
  std::memcpy(&f.data[3], e.vendor, 5);
  return f;
}

bool decode_emcy(const CanFrame& f, std::uint8_t& node, Emcy& e) {
  if (f.extended || f.rtr || f.error || function_of(f.id) != kEmcy || f.len != 8) return false;
  node = node_of(f.id);
  if (!valid_node(node)) return false;  // 0x080 itself is SYNC
  e.error_code = get_u16(&f.data[0]);
  e.error_register = f.data[2];
  std::memcpy(e.vendor, &f.data[3], 5);
  return true;
}

const char* emcy_text(std::uint16_t code) {
  // Specific codes first (CiA 301 table 21, CiA 402 annex), then classes.
  switch (code) {
    case 0x0000: return "error reset or no error";
    case 0x8110: return "CAN overrun (objects lost)";
    case 0x8120: return "CAN in error passive mode";
    case 0x8130: return "life guard error or heartbeat error";
    case 0x8140: return "recovered from bus off";
    case 0x8210: return "PDO not processed due to length error";
    case 0x8220: return "PDO length exceeded";
    case 0x8611: return "position following error";
    case 0x7121: return "motor blocked";
    case 0x2310: return "continuous over-current";
    case 0x3210: return "DC link over-voltage";
    case 0x3220: return "DC link under-voltage";
    case 0x4310: return "drive temperature too high";
    case 0x5441: return "safe torque off / enable input inactive";
    case 0x7305: return "incremental sensor 1 fault (encoder)";
    default: break;
  }
  switch (code & 0xF000) {
    case 0x1000: return "generic error";
    case 0x2000: return "current error";
    case 0x3000: return "voltage error";
    case 0x4000: return "temperature error";
    case 0x5000: return "device hardware error";
    case 0x6000: return "device software error";
    case 0x7000: return "additional modules error";
    case 0x8000: return "monitoring error";
    case 0x9000: return "external error";
    case 0xF000: return (code & 0xFF00) == 0xFF00 ? "device specific error" : "additional functions error";
    default: return "unknown error code";
  }
}

namespace sdo {

namespace {
CanFrame sdo_frame(std::uint32_t base, std::uint8_t node, std::uint8_t cmd) {
  CanFrame f;
  f.id = base + node;
  f.len = 8;  // SDO frames are always 8 bytes
  f.data[0] = cmd;
  return f;
}
void put_mux(CanFrame& f, std::uint16_t index, std::uint8_t sub) {
  put_u16(&f.data[1], index);
  f.data[3] = sub;
}
}  // namespace

CanFrame initiate_download(std::uint8_t node, std::uint16_t index, std::uint8_t sub, const std::uint8_t* data,
                           std::uint32_t len) {
  CanFrame f = sdo_frame(kSdoRx, node, 0);
  put_mux(f, index, sub);
  if (len >= 1 && len <= 4) {
    f.data[0] = std::uint8_t((kCcsInitiateDownload << 5) | ((4 - len) << 2) | 0x03);
    std::memcpy(&f.data[4], data, len);
  } else {
    f.data[0] = std::uint8_t((kCcsInitiateDownload << 5) | 0x01);
    put_u32(&f.data[4], len);
  }
  return f;
}

CanFrame download_segment(std::uint8_t node, bool toggle, const std::uint8_t* data, std::uint8_t n, bool last) {
  if (n > 7) n = 7;
  CanFrame f = sdo_frame(kSdoRx, node,
                         std::uint8_t((kCcsDownloadSegment << 5) | (toggle ? 0x10 : 0) | ((7 - n) << 1) | (last ? 1 : 0)));
  std::memcpy(&f.data[1], data, n);
  return f;
}

CanFrame initiate_upload(std::uint8_t node, std::uint16_t index, std::uint8_t sub) {
  CanFrame f = sdo_frame(kSdoRx, node, kCcsInitiateUpload << 5);
  put_mux(f, index, sub);
  return f;
}

CanFrame upload_segment_request(std::uint8_t node, bool toggle) {
  return sdo_frame(kSdoRx, node, std::uint8_t((kCcsUploadSegment << 5) | (toggle ? 0x10 : 0)));
}

CanFrame abort(std::uint8_t node, bool server, std::uint16_t index, std::uint8_t sub, std::uint32_t code) {
  CanFrame f = sdo_frame(server ? kSdoTx : kSdoRx, node, kAbort << 5);
  put_mux(f, index, sub);
  put_u32(&f.data[4], code);
  return f;
}

CanFrame download_response(std::uint8_t node, std::uint16_t index, std::uint8_t sub) {
  CanFrame f = sdo_frame(kSdoTx, node, kScsInitiateDownload << 5);
  put_mux(f, index, sub);
  return f;
}

CanFrame download_segment_response(std::uint8_t node, bool toggle) {
  return sdo_frame(kSdoTx, node, std::uint8_t((kScsDownloadSegment << 5) | (toggle ? 0x10 : 0)));
}

CanFrame upload_response(std::uint8_t node, std::uint16_t index, std::uint8_t sub, const std::uint8_t* data,
                         std::uint32_t len) {
  CanFrame f = sdo_frame(kSdoTx, node, 0);
  put_mux(f, index, sub);
  if (len >= 1 && len <= 4) {
    f.data[0] = std::uint8_t((kScsInitiateUpload << 5) | ((4 - len) << 2) | 0x03);
    std::memcpy(&f.data[4], data, len);
  } else {
    f.data[0] = std::uint8_t((kScsInitiateUpload << 5) | 0x01);
    put_u32(&f.data[4], len);
  }
  return f;
}

CanFrame upload_segment(std::uint8_t node, bool toggle, const std::uint8_t* data, std::uint8_t n, bool last) {
  if (n > 7) n = 7;
  CanFrame f = sdo_frame(kSdoTx, node,
                         std::uint8_t((kScsUploadSegment << 5) | (toggle ? 0x10 : 0) | ((7 - n) << 1) | (last ? 1 : 0)));
  std::memcpy(&f.data[1], data, n);
  return f;
}

const char* abort_text(std::uint32_t code) {
  switch (code) {
    case 0x05030000: return "toggle bit not alternated";
    case 0x05040000: return "SDO protocol timed out";
    case 0x05040001: return "client/server command specifier not valid or unknown";
    case 0x05040002: return "invalid block size";
    case 0x05040003: return "invalid sequence number";
    case 0x05040004: return "CRC error";
    case 0x05040005: return "out of memory";
    case 0x06010000: return "unsupported access to an object";
    case 0x06010001: return "attempt to read a write only object";
    case 0x06010002: return "attempt to write a read only object";
    case 0x06020000: return "object does not exist in the object dictionary";
    case 0x06040041: return "object cannot be mapped to the PDO";
    case 0x06040042: return "the number and length of the objects to be mapped would exceed PDO length";
    case 0x06040043: return "general parameter incompatibility reason";
    case 0x06040047: return "general internal incompatibility in the device";
    case 0x06060000: return "access failed due to a hardware error";
    case 0x06070010: return "data type does not match, length of service parameter does not match";
    case 0x06070012: return "data type does not match, length of service parameter too high";
    case 0x06070013: return "data type does not match, length of service parameter too low";
    case 0x06090011: return "sub-index does not exist";
    case 0x06090030: return "invalid value for parameter (download only)";
    case 0x06090031: return "value of parameter written too high (download only)";
    case 0x06090032: return "value of parameter written too low (download only)";
    case 0x06090036: return "maximum value is less than minimum value";
    case 0x060A0023: return "resource not available: SDO connection";
    case 0x08000000: return "general error";
    case 0x08000020: return "data cannot be transferred or stored to the application";
    case 0x08000021: return "data cannot be transferred or stored to the application because of local control";
    case 0x08000022: return "data cannot be transferred or stored to the application because of the present device state";
    case 0x08000023: return "object dictionary dynamic generation fails or no object dictionary is present";
    case 0x08000024: return "no data available";
    default: return "unknown SDO abort code";
  }
}

}  // namespace sdo
}  // namespace servoarm::hal::canopen
