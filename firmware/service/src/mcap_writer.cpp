// SPDX-License-Identifier: Apache-2.0
// The MCAP writer (mcap_writer.hpp). Records: opcode (1 byte), content length (8 bytes, little
// endian), content; strings and byte arrays carry a 4-byte length, a chunk's records an 8-byte one.
#include "servoarm/service/mcap_writer.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstring>
#include <tuple>
#include <algorithm>

namespace servoarm::fw {

namespace {

enum Op : std::uint8_t {
  header = 0x01, footer = 0x02, schema = 0x03, channel = 0x04, message = 0x05, chunk = 0x06,
  message_index = 0x07, chunk_index = 0x08, statistics = 0x0B, summary_offset = 0x0E, data_end = 0x0F,
};
constexpr char kMagic[8] = {'\x89', 'M', 'C', 'A', 'P', '0', '\r', '\n'};

void u8(std::string& s, std::uint8_t v) { s.push_back(static_cast<char>(v)); }
template <typename T>
void le(std::string& s, T v) {
  for (std::size_t i = 0; i < sizeof(T); ++i) s.push_back(static_cast<char>((static_cast<std::uint64_t>(v) >> (8 * i)) & 0xFF));
}
void str(std::string& s, std::string_view v) {
  le<std::uint32_t>(s, static_cast<std::uint32_t>(v.size()));
  s.append(v);
}
std::string record(Op op, const std::string& content) {
  std::string r;
  r.reserve(content.size() + 9);
  u8(r, op);
  le<std::uint64_t>(r, content.size());
  r += content;
  return r;
}

std::uint32_t crc32(std::string_view d) {
  static const auto table = [] {
    std::array<std::uint32_t, 256> t{};
    for (std::uint32_t i = 0; i < 256; ++i) {
      std::uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = (c & 1u) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[i] = c;
    }
    return t;
  }();
  std::uint32_t c = 0xFFFFFFFFu;
  for (const char ch : d) c = table[(c ^ static_cast<std::uint8_t>(ch)) & 0xFFu] ^ (c >> 8);
  return c ^ 0xFFFFFFFFu;
}

}  // namespace

McapWriter::~McapWriter() { close(); }

std::string McapWriter::fail(const std::string& why) {
  if (f_ != nullptr) std::fclose(f_);
  f_ = nullptr;
  return path_ + ": " + why;
}

std::string McapWriter::put(const std::string& rec) {
  if (f_ == nullptr) return path_ + ": not open";
  if (std::fwrite(rec.data(), 1, rec.size(), f_) != rec.size()) return fail(std::strerror(errno));
  file_off_ += rec.size();
  return "";
}

std::string McapWriter::open(const std::string& path, std::size_t chunk_bytes) {
  close();
  path_ = path;
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0) return path + ": " + std::strerror(errno);
  f_ = ::fdopen(fd, "wb");
  if (f_ == nullptr) {
    ::close(fd);
    return path + ": " + std::strerror(errno);
  }
  chunk_bytes_ = chunk_bytes;
  file_off_ = 0;
  schemas_.clear(), channels_.clear(), chunk_.clear(), chunks_.clear(), chunk_index_.clear();
  seq_.clear(), per_channel_.clear();
  n_schemas_ = n_channels_ = 0;
  msg_count_ = first_t_ = last_t_ = 0;
  std::string h;
  str(h, "");  // profile: none (JSON messages, no ROS)
  str(h, "servoarm");
  std::string m(kMagic, sizeof kMagic);
  m += record(Op::header, h);
  return put(m);
}

std::uint16_t McapWriter::add_schema(std::string_view name, std::string_view json_schema) {
  const auto id = static_cast<std::uint16_t>(++n_schemas_);
  std::string c;
  le<std::uint16_t>(c, id);
  str(c, name);
  str(c, "jsonschema");
  str(c, json_schema);
  const std::string r = record(Op::schema, c);
  schemas_ += r;
  put(r);
  return id;
}

std::uint16_t McapWriter::add_channel(std::uint16_t schema_id, std::string_view topic) {
  const auto id = n_channels_++;
  std::string c;
  le<std::uint16_t>(c, id);
  le<std::uint16_t>(c, schema_id);
  str(c, topic);
  str(c, "json");
  le<std::uint32_t>(c, 0);  // metadata: an empty map
  const std::string r = record(Op::channel, c);
  channels_ += r;
  put(r);
  seq_.push_back(0);
  per_channel_.push_back(0);
  return id;
}

std::string McapWriter::write(std::uint16_t ch, std::uint64_t t_ns, std::string_view json) {
  if (f_ == nullptr) return path_ + ": not open";
  if (ch >= n_channels_) return path_ + ": no channel " + std::to_string(ch);
  if (chunk_.empty()) chunk_start_ = t_ns, chunk_end_ = t_ns;
  chunk_start_ = std::min(chunk_start_, t_ns);
  chunk_end_ = std::max(chunk_end_, t_ns);
  chunk_index_[ch].push_back({t_ns, chunk_.size()});
  std::string c;
  c.reserve(json.size() + 22);
  le<std::uint16_t>(c, ch);
  le<std::uint32_t>(c, ++seq_[ch]);
  le<std::uint64_t>(c, t_ns);
  le<std::uint64_t>(c, t_ns);
  c.append(json);
  u8(chunk_, Op::message);
  le<std::uint64_t>(chunk_, c.size());
  chunk_ += c;
  if (msg_count_ == 0) first_t_ = t_ns;
  first_t_ = std::min(first_t_, t_ns);
  last_t_ = std::max(last_t_, t_ns);
  ++msg_count_;
  ++per_channel_[ch];
  if (chunk_.size() >= chunk_bytes_) return flush();
  return "";
}

std::string McapWriter::flush() {
  if (f_ == nullptr) return path_ + ": not open";
  if (chunk_.empty()) return "";
  ChunkIndex ci;
  ci.start = chunk_start_;
  ci.end = chunk_end_;
  ci.offset = file_off_;
  ci.uncompressed = chunk_.size();
  std::string c;
  c.reserve(chunk_.size() + 48);
  le<std::uint64_t>(c, chunk_start_);
  le<std::uint64_t>(c, chunk_end_);
  le<std::uint64_t>(c, chunk_.size());
  le<std::uint32_t>(c, crc32(chunk_));
  str(c, "");  // compression: none
  le<std::uint64_t>(c, chunk_.size());
  c += chunk_;
  std::string out = record(Op::chunk, c);
  ci.length = out.size();
  const std::uint64_t index_start = file_off_ + out.size();
  for (const auto& [ch, entries] : chunk_index_) {
    std::string m;
    le<std::uint16_t>(m, ch);
    le<std::uint32_t>(m, static_cast<std::uint32_t>(entries.size() * 16));
    for (const auto& [t, off] : entries) le<std::uint64_t>(m, t), le<std::uint64_t>(m, off);
    ci.index_offsets[ch] = file_off_ + out.size();
    out += record(Op::message_index, m);
  }
  ci.index_length = file_off_ + out.size() - index_start;
  chunk_.clear();
  chunk_index_.clear();
  if (std::string e = put(out); !e.empty()) return e;
  if (std::fflush(f_) != 0) return fail(std::strerror(errno));
  ::fdatasync(::fileno(f_));  // the chunk survives a power cut (best effort: an error shows at close)
  chunks_.push_back(std::move(ci));
  return "";
}

std::string McapWriter::close() {
  if (f_ == nullptr) return "";
  if (std::string e = flush(); !e.empty()) return e;
  std::string de;
  le<std::uint32_t>(de, 0);  // data section CRC: not computed
  if (std::string e = put(record(Op::data_end, de)); !e.empty()) return e;
  // Summary: schemas, channels, statistics, chunk indexes; each group's place in the offsets.
  const std::uint64_t summary_start = file_off_;
  std::string s;
  std::vector<std::tuple<Op, std::uint64_t, std::uint64_t>> groups;
  auto group = [&](Op op, const std::string& recs) {
    if (recs.empty()) return;
    groups.emplace_back(op, summary_start + s.size(), recs.size());
    s += recs;
  };
  group(Op::schema, schemas_);
  group(Op::channel, channels_);
  {
    std::string st;
    le<std::uint64_t>(st, msg_count_);
    le<std::uint16_t>(st, n_schemas_);
    le<std::uint32_t>(st, n_channels_);
    le<std::uint32_t>(st, 0);  // attachments
    le<std::uint32_t>(st, 0);  // metadata
    le<std::uint32_t>(st, static_cast<std::uint32_t>(chunks_.size()));
    le<std::uint64_t>(st, first_t_);
    le<std::uint64_t>(st, last_t_);
    le<std::uint32_t>(st, static_cast<std::uint32_t>(per_channel_.size() * 10));
    for (std::size_t i = 0; i < per_channel_.size(); ++i) le<std::uint16_t>(st, static_cast<std::uint16_t>(i)), le<std::uint64_t>(st, per_channel_[i]);
    group(Op::statistics, record(Op::statistics, st));
  }
  {
    std::string cis;
    for (const ChunkIndex& ci : chunks_) {
      std::string c;
      le<std::uint64_t>(c, ci.start);
      le<std::uint64_t>(c, ci.end);
      le<std::uint64_t>(c, ci.offset);
      le<std::uint64_t>(c, ci.length);
      le<std::uint32_t>(c, static_cast<std::uint32_t>(ci.index_offsets.size() * 10));
      for (const auto& [ch, off] : ci.index_offsets) le<std::uint16_t>(c, ch), le<std::uint64_t>(c, off);
      le<std::uint64_t>(c, ci.index_length);
      str(c, "");
      le<std::uint64_t>(c, ci.uncompressed);  // compressed size: the same (none)
      le<std::uint64_t>(c, ci.uncompressed);
      cis += record(Op::chunk_index, c);
    }
    group(Op::chunk_index, cis);
  }
  const std::uint64_t offsets_start = summary_start + s.size();
  for (const auto& [op, start, len] : groups) {
    std::string c;
    u8(c, op);
    le<std::uint64_t>(c, start);
    le<std::uint64_t>(c, len);
    s += record(Op::summary_offset, c);
  }
  std::string ft;
  le<std::uint64_t>(ft, summary_start);
  le<std::uint64_t>(ft, offsets_start);
  le<std::uint32_t>(ft, 0);  // summary CRC: not computed
  s += record(Op::footer, ft);
  s.append(kMagic, sizeof kMagic);
  if (std::string e = put(s); !e.empty()) return e;
  ::fdatasync(::fileno(f_));
  const int rc = std::fclose(f_);
  f_ = nullptr;
  return rc == 0 ? "" : path_ + ": " + std::strerror(errno);
}

}  // namespace servoarm::fw
