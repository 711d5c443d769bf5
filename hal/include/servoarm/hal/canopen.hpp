// SPDX-License-Identifier: Apache-2.0
#pragma once
// CANopen (CiA 301) frame codecs: COB-ids, NMT, SYNC, heartbeat, EMCY, SDO
// command bytes and abort codes. Pure functions over CanFrame: no I/O, no
// allocation; all real-time safe.
#include <cstdint>

#include "servoarm/hal/can_frame.hpp"

namespace servoarm::hal::canopen {

// Predefined connection set (CiA 301 7.3.5): function code base + node id.
inline constexpr std::uint32_t kNmt = 0x000;
inline constexpr std::uint32_t kSync = 0x080;
inline constexpr std::uint32_t kEmcy = 0x080;     ///< + node
inline constexpr std::uint32_t kTpdo1 = 0x180;    ///< + node
inline constexpr std::uint32_t kRpdo1 = 0x200;    ///< + node
inline constexpr std::uint32_t kTpdo2 = 0x280;    ///< + node
inline constexpr std::uint32_t kRpdo2 = 0x300;    ///< + node
inline constexpr std::uint32_t kTpdo3 = 0x380;    ///< + node (digital inputs 60FDh)
inline constexpr std::uint32_t kRpdo3 = 0x400;    ///< + node (digital outputs 60FEh:01)
inline constexpr std::uint32_t kSdoTx = 0x580;    ///< server -> client, + node
inline constexpr std::uint32_t kSdoRx = 0x600;    ///< client -> server, + node
inline constexpr std::uint32_t kHeartbeat = 0x700;///< + node
inline constexpr std::uint8_t kMaxNodeId = 127;

inline constexpr bool valid_node(unsigned n) { return n >= 1 && n <= kMaxNodeId; }
/// Function code (id & 0x780) and node (id & 0x7F) of a standard-id frame.
inline constexpr std::uint32_t function_of(std::uint32_t id) { return id & 0x780; }
inline constexpr std::uint8_t node_of(std::uint32_t id) { return std::uint8_t(id & 0x7F); }

// --- NMT --------------------------------------------------------------------
enum class NmtCommand : std::uint8_t {
  start = 0x01,
  stop = 0x02,
  enter_pre_operational = 0x80,
  reset_node = 0x81,
  reset_communication = 0x82,
};
const char* to_string(NmtCommand c);

/// NMT state as carried in the heartbeat (CiA 301 7.2.8.3.2.1).
enum class NmtState : std::uint8_t {
  boot_up = 0x00,
  stopped = 0x04,
  operational = 0x05,
  pre_operational = 0x7F,
};
const char* to_string(NmtState s);

/// NMT command frame: id 0x000, 2 bytes [command, node] (node 0 = all nodes).
CanFrame encode_nmt(NmtCommand cmd, std::uint8_t node);
/// False unless id 0x000, len 2, a known command and node <= 127.
bool decode_nmt(const CanFrame& f, NmtCommand& cmd, std::uint8_t& node);

// --- SYNC -------------------------------------------------------------------
/// SYNC: id 0x080, len 0 (counter 0 = no counter) or len 1 with counter 1..240.
CanFrame encode_sync(std::uint8_t counter = 0);
bool is_sync(const CanFrame& f);

// --- Heartbeat --------------------------------------------------------------
/// Heartbeat: id 0x700 + node, 1 byte state.
CanFrame encode_heartbeat(std::uint8_t node, NmtState state);
bool decode_heartbeat(const CanFrame& f, std::uint8_t& node, NmtState& state);

// --- EMCY -------------------------------------------------------------------
struct Emcy {
  std::uint16_t error_code = 0;       ///< 0x0000 = error reset / no error
  std::uint8_t error_register = 0;    ///< object 0x1001
  std::uint8_t vendor[5] = {};        ///< manufacturer-specific bytes
};
/// EMCY: id 0x080 + node, 8 bytes [code lo, code hi, register, vendor x5].
CanFrame encode_emcy(std::uint8_t node, const Emcy& e);
/// False unless id 0x081..0x0FF, standard, len 8.
bool decode_emcy(const CanFrame& f, std::uint8_t& node, Emcy& e);
/// Error-code class text (CiA 301 table 21 plus the CiA 402 codes drives use).
const char* emcy_text(std::uint16_t code);

// --- SDO --------------------------------------------------------------------
// Command byte layouts (CiA 301 7.2.4.3). ccs/scs in bits 7..5.
namespace sdo {
inline constexpr std::uint8_t kCcsDownloadSegment = 0;
inline constexpr std::uint8_t kCcsInitiateDownload = 1;
inline constexpr std::uint8_t kCcsInitiateUpload = 2;
inline constexpr std::uint8_t kCcsUploadSegment = 3;
inline constexpr std::uint8_t kScsUploadSegment = 0;
inline constexpr std::uint8_t kScsDownloadSegment = 1;
inline constexpr std::uint8_t kScsInitiateUpload = 2;
inline constexpr std::uint8_t kScsInitiateDownload = 3;
inline constexpr std::uint8_t kAbort = 4;  ///< cs = 4 (0x80) in both directions

inline constexpr std::uint8_t cs_of(std::uint8_t cmd) { return std::uint8_t(cmd >> 5); }

/// Client: initiate download. len 1..4 -> expedited with size (0x2F/0x2B/0x27/0x23),
/// len > 4 -> segmented with size indicated (0x21, size in bytes 4..7).
CanFrame initiate_download(std::uint8_t node, std::uint16_t index, std::uint8_t sub,
                           const std::uint8_t* data, std::uint32_t len);
/// Client: download segment: byte0 = t<<4 | (7-n)<<1 | c, up to 7 data bytes.
CanFrame download_segment(std::uint8_t node, bool toggle, const std::uint8_t* data, std::uint8_t n, bool last);
/// Client: initiate upload (0x40).
CanFrame initiate_upload(std::uint8_t node, std::uint16_t index, std::uint8_t sub);
/// Client: upload segment request (0x60 | t<<4).
CanFrame upload_segment_request(std::uint8_t node, bool toggle);
/// Either side: abort (0x80, index, sub, code). `server` picks 0x580+n vs 0x600+n.
CanFrame abort(std::uint8_t node, bool server, std::uint16_t index, std::uint8_t sub, std::uint32_t code);

/// Server: initiate download response (0x60).
CanFrame download_response(std::uint8_t node, std::uint16_t index, std::uint8_t sub);
/// Server: download segment response (0x20 | t<<4).
CanFrame download_segment_response(std::uint8_t node, bool toggle);
/// Server: initiate upload response. len <= 4 -> expedited (0x4F/0x4B/0x47/0x43),
/// otherwise segmented with size (0x41, size in bytes 4..7; data not included).
CanFrame upload_response(std::uint8_t node, std::uint16_t index, std::uint8_t sub,
                         const std::uint8_t* data, std::uint32_t len);
/// Server: upload segment: byte0 = t<<4 | (7-n)<<1 | c.
CanFrame upload_segment(std::uint8_t node, bool toggle, const std::uint8_t* data, std::uint8_t n, bool last);

/// Multiplexer of an initiate/abort frame.
inline std::uint16_t index_of(const CanFrame& f) { return get_u16(&f.data[1]); }
inline std::uint8_t sub_of(const CanFrame& f) { return f.data[3]; }

// Abort codes (CiA 301 table 22).
inline constexpr std::uint32_t kAbortToggle = 0x05030000;
inline constexpr std::uint32_t kAbortTimeout = 0x05040000;
inline constexpr std::uint32_t kAbortCommand = 0x05040001;
inline constexpr std::uint32_t kAbortOutOfMemory = 0x05040005;
inline constexpr std::uint32_t kAbortUnsupported = 0x06010000;
inline constexpr std::uint32_t kAbortWriteOnly = 0x06010001;
inline constexpr std::uint32_t kAbortReadOnly = 0x06010002;
inline constexpr std::uint32_t kAbortNoObject = 0x06020000;
inline constexpr std::uint32_t kAbortNotMappable = 0x06040041;
inline constexpr std::uint32_t kAbortPdoLength = 0x06040042;
inline constexpr std::uint32_t kAbortParamIncompatible = 0x06040043;
inline constexpr std::uint32_t kAbortHardware = 0x06060000;
inline constexpr std::uint32_t kAbortLength = 0x06070010;
inline constexpr std::uint32_t kAbortTooLong = 0x06070012;
inline constexpr std::uint32_t kAbortTooShort = 0x06070013;
inline constexpr std::uint32_t kAbortNoSub = 0x06090011;
inline constexpr std::uint32_t kAbortValueRange = 0x06090030;
inline constexpr std::uint32_t kAbortGeneral = 0x08000000;
inline constexpr std::uint32_t kAbortDeviceState = 0x08000022;

/// Text of an abort code, e.g. "object does not exist in the object dictionary".
const char* abort_text(std::uint32_t code);
}  // namespace sdo

}  // namespace servoarm::hal::canopen
