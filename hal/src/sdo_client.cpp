// SPDX-License-Identifier: Apache-2.0
#include "servoarm/hal/sdo_client.hpp"

#include <cstring>

#include "servoarm/hal/canopen.hpp"

namespace servoarm::hal {

using namespace canopen;

Status SdoClient::wait(std::uint8_t node, CanFrame& out, TimePoint deadline) {
  for (;;) {
    const Status st = bus_.receive(out, deadline);
    if (st != Status::ok) return st;
    if (!out.error && !out.extended && !out.rtr && out.id == kSdoTx + node && out.len == 8) return Status::ok;
    other_(out);
  }
}

// The initiate answers and the abort carry the object; a segment answer does not.
static bool names_another_object(const CanFrame& r, std::uint16_t index, std::uint8_t sub) {
  const std::uint8_t cs = sdo::cs_of(r.data[0]);
  const bool initiate = cs == sdo::kAbort || cs == sdo::kScsInitiateDownload || cs == sdo::kScsInitiateUpload;
  return initiate && (sdo::index_of(r) != index || sdo::sub_of(r) != sub);
}

Status SdoClient::wait_initiate(std::uint8_t node, std::uint16_t index, std::uint8_t sub, CanFrame& out,
                                TimePoint deadline) {
  for (;;) {
    const Status st = wait(node, out, deadline);
    if (st != Status::ok || !names_another_object(out, index, sub)) return st;
  }
}

SdoResult SdoClient::fail_abort(std::uint8_t node, std::uint16_t index, std::uint8_t sub, Status st,
                                std::uint32_t code) {
  bus_.send(sdo::abort(node, false, index, sub, code));
  return SdoResult{st == Status::timeout ? Status::timeout : st, code, 0};
}

SdoResult SdoClient::download(std::uint8_t node, std::uint16_t index, std::uint8_t sub, const std::uint8_t* data,
                              std::size_t len) {
  if (!valid_node(node) || (len > 0 && data == nullptr) || len > 0xFFFFFFFFu) return {Status::invalid_argument, 0, 0};
  const Status s0 = bus_.send(sdo::initiate_download(node, index, sub, data, std::uint32_t(len)));
  if (!is_ok(s0)) return {s0, 0, 0};
  CanFrame r;
  Status st = wait_initiate(node, index, sub, r, clock_.now() + timeout_);
  if (st == Status::timeout) return fail_abort(node, index, sub, st, sdo::kAbortTimeout);
  if (st != Status::ok) return {st, 0, 0};
  if (sdo::cs_of(r.data[0]) == sdo::kAbort) return {Status::sdo_abort, get_u32(&r.data[4]), 0};
  if (sdo::cs_of(r.data[0]) != sdo::kScsInitiateDownload || sdo::index_of(r) != index || sdo::sub_of(r) != sub)
    return fail_abort(node, index, sub, Status::protocol_error, sdo::kAbortCommand);
  if (len >= 1 && len <= 4) return {Status::ok, 0, len};

  bool toggle = false;
  std::size_t off = 0;
  while (off < len) {
    const std::uint8_t n = std::uint8_t(len - off > 7 ? 7 : len - off);
    const bool last = off + n == len;
    const Status s1 = bus_.send(sdo::download_segment(node, toggle, data + off, n, last));
    if (!is_ok(s1)) return {s1, 0, off};
    st = wait(node, r, clock_.now() + timeout_);
    if (st == Status::timeout) return fail_abort(node, index, sub, st, sdo::kAbortTimeout);
    if (st != Status::ok) return {st, 0, off};
    if (sdo::cs_of(r.data[0]) == sdo::kAbort) return {Status::sdo_abort, get_u32(&r.data[4]), off};
    if (sdo::cs_of(r.data[0]) != sdo::kScsDownloadSegment)
      return fail_abort(node, index, sub, Status::protocol_error, sdo::kAbortCommand);
    if (((r.data[0] & 0x10) != 0) != toggle) return fail_abort(node, index, sub, Status::protocol_error, sdo::kAbortToggle);
    toggle = !toggle;
    off += n;
  }
  return {Status::ok, 0, len};
}

SdoResult SdoClient::upload(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::uint8_t* buf,
                            std::size_t cap) {
  if (!valid_node(node) || (cap > 0 && buf == nullptr)) return {Status::invalid_argument, 0, 0};
  const Status s0 = bus_.send(sdo::initiate_upload(node, index, sub));
  if (!is_ok(s0)) return {s0, 0, 0};
  CanFrame r;
  Status st = wait_initiate(node, index, sub, r, clock_.now() + timeout_);
  if (st == Status::timeout) return fail_abort(node, index, sub, st, sdo::kAbortTimeout);
  if (st != Status::ok) return {st, 0, 0};
  const std::uint8_t c = r.data[0];
  if (sdo::cs_of(c) == sdo::kAbort) return {Status::sdo_abort, get_u32(&r.data[4]), 0};
  if (sdo::cs_of(c) != sdo::kScsInitiateUpload || sdo::index_of(r) != index || sdo::sub_of(r) != sub)
    return fail_abort(node, index, sub, Status::protocol_error, sdo::kAbortCommand);
  if (c & 0x02) {  // expedited
    const std::size_t n = (c & 0x01) ? std::size_t(4 - ((c >> 2) & 3)) : 4;
    if (n > cap) return fail_abort(node, index, sub, Status::sdo_abort, sdo::kAbortOutOfMemory);
    std::memcpy(buf, &r.data[4], n);
    return {Status::ok, 0, n};
  }
  const bool sized = (c & 0x01) != 0;
  const std::size_t total = sized ? get_u32(&r.data[4]) : 0;
  if (sized && total > cap) return fail_abort(node, index, sub, Status::sdo_abort, sdo::kAbortOutOfMemory);

  bool toggle = false;
  std::size_t off = 0;
  for (;;) {
    const Status s1 = bus_.send(sdo::upload_segment_request(node, toggle));
    if (!is_ok(s1)) return {s1, 0, off};
    st = wait(node, r, clock_.now() + timeout_);
    if (st == Status::timeout) return fail_abort(node, index, sub, st, sdo::kAbortTimeout);
    if (st != Status::ok) return {st, 0, off};
    const std::uint8_t sc = r.data[0];
    if (sdo::cs_of(sc) == sdo::kAbort) return {Status::sdo_abort, get_u32(&r.data[4]), off};
    if (sdo::cs_of(sc) != sdo::kScsUploadSegment)
      return fail_abort(node, index, sub, Status::protocol_error, sdo::kAbortCommand);
    if (((sc & 0x10) != 0) != toggle) return fail_abort(node, index, sub, Status::protocol_error, sdo::kAbortToggle);
    const std::size_t n = 7 - ((sc >> 1) & 7);
    if (off + n > cap) return fail_abort(node, index, sub, Status::sdo_abort, sdo::kAbortOutOfMemory);
    std::memcpy(buf + off, &r.data[1], n);
    off += n;
    toggle = !toggle;
    if (sc & 0x01) break;
  }
  if (sized && off != total) return {Status::protocol_error, 0, off};
  return {Status::ok, 0, off};
}

SdoResult SdoClient::write_u8(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::uint8_t v) {
  return download(node, index, sub, &v, 1);
}
SdoResult SdoClient::write_u16(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::uint16_t v) {
  std::uint8_t b[2];
  put_u16(b, v);
  return download(node, index, sub, b, 2);
}
SdoResult SdoClient::write_u32(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::uint32_t v) {
  std::uint8_t b[4];
  put_u32(b, v);
  return download(node, index, sub, b, 4);
}
SdoResult SdoClient::read_u32(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::uint32_t& v) {
  std::uint8_t b[4] = {};
  SdoResult r = upload(node, index, sub, b, 4);
  if (r.status == Status::ok) v = get_u32(b);
  return r;
}

Status SdoTransfer::begin_write(CanBus& bus, std::uint8_t node, std::uint16_t index, std::uint8_t sub,
                                std::uint8_t size, std::uint32_t value, TimePoint now, Duration timeout) {
  if (state_ == State::pending) return Status::bad_state;
  if (!valid_node(node) || size < 1 || size > 4) return Status::invalid_argument;
  std::uint8_t b[4];
  put_u32(b, value);
  const Status s = bus.send(sdo::initiate_download(node, index, sub, b, size));
  if (!is_ok(s)) return s;
  state_ = State::pending;
  write_ = true;
  node_ = node;
  index_ = index;
  sub_ = sub;
  deadline_ = now + timeout;
  result_ = Status::ok;
  abort_code_ = 0;
  value_ = value;
  return Status::ok;
}

Status SdoTransfer::begin_read(CanBus& bus, std::uint8_t node, std::uint16_t index, std::uint8_t sub, TimePoint now,
                               Duration timeout) {
  if (state_ == State::pending) return Status::bad_state;
  if (!valid_node(node)) return Status::invalid_argument;
  const Status s = bus.send(sdo::initiate_upload(node, index, sub));
  if (!is_ok(s)) return s;
  state_ = State::pending;
  write_ = false;
  node_ = node;
  index_ = index;
  sub_ = sub;
  deadline_ = now + timeout;
  result_ = Status::ok;
  abort_code_ = 0;
  value_ = 0;
  return Status::ok;
}

bool SdoTransfer::on_frame(const CanFrame& f) {
  if (state_ != State::pending || f.error || f.extended || f.rtr || f.id != kSdoTx + node_ || f.len != 8) return false;
  if (names_another_object(f, index_, sub_)) return true;  // a late answer to an earlier request: still pending
  const std::uint8_t c = f.data[0];
  const std::uint8_t cs = sdo::cs_of(c);
  state_ = State::done;
  if (cs == sdo::kAbort) {
    result_ = Status::sdo_abort;
    abort_code_ = get_u32(&f.data[4]);
    return true;
  }
  if (write_) {
    result_ = cs == sdo::kScsInitiateDownload ? Status::ok : Status::protocol_error;
    return true;
  }
  if (cs != sdo::kScsInitiateUpload || !(c & 0x02)) {  // only expedited uploads here
    result_ = Status::protocol_error;
    return true;
  }
  const std::size_t n = (c & 0x01) ? std::size_t(4 - ((c >> 2) & 3)) : 4;
  std::uint32_t v = 0;
  for (std::size_t i = 0; i < n; ++i) v |= std::uint32_t(f.data[4 + i]) << (8 * i);
  value_ = v;
  result_ = Status::ok;
  return true;
}

void SdoTransfer::poll(CanBus& bus, TimePoint now) {
  if (state_ != State::pending || now <= deadline_) return;
  bus.send(sdo::abort(node_, false, index_, sub_, sdo::kAbortTimeout));
  state_ = State::done;
  result_ = Status::timeout;
  abort_code_ = sdo::kAbortTimeout;
}

}  // namespace servoarm::hal
