// SPDX-License-Identifier: Apache-2.0
#pragma once
// An MCAP file writer (https://mcap.dev/spec, format version 0): schemas and channels right
// after the header (so a reader that streams the file knows them before any message), the
// messages in uncompressed chunks, each chunk followed by its message indexes, and at close a
// summary (schemas, channels, statistics, chunk indexes), the summary offsets and the footer.
// A file cut by power loss (no summary) still reads in a streaming reader up to its last
// complete chunk: every chunk is written in one piece and synced (fdatasync) when closed.
//
// Written here rather than taken from a library: Debian packages no MCAP library
// (`apt-cache search mcap` finds none in Debian 12), the reference C++ writer (foxglove/mcap's
// header-only cpp) is not packaged, and an uncompressed writer is a few hundred lines.
// Non-real-time: allocates and writes; one thread uses a writer at a time.
#include <cstdint>
#include <cstdio>
#include <map>
#include <string>
#include <string_view>
#include <vector>

namespace servoarm::fw {

class McapWriter {
 public:
  McapWriter() = default;
  ~McapWriter();
  McapWriter(const McapWriter&) = delete;
  McapWriter& operator=(const McapWriter&) = delete;

  /// Create `path` (never an existing file: O_EXCL) and write the header. "" or the error.
  std::string open(const std::string& path, std::size_t chunk_bytes);
  /// A JSON schema (encoding "jsonschema"); returns its id (1, 2, ...). Before the first message.
  std::uint16_t add_schema(std::string_view name, std::string_view json_schema);
  /// A channel of JSON messages; returns its id (0, 1, ...). Before the first message.
  std::uint16_t add_channel(std::uint16_t schema, std::string_view topic);
  /// One message (log and publish time `t_ns`); the chunk is written when it reaches its size.
  /// "" or the write error (the writer is then closed).
  std::string write(std::uint16_t channel, std::uint64_t t_ns, std::string_view json);
  /// Write the chunk being filled now (a partial one: bounds the loss on power failure).
  std::string flush();
  /// Write the last chunk, the summary and the footer; close. "" or the error. Idempotent.
  std::string close();
  bool is_open() const { return f_ != nullptr; }
  /// Bytes in the file so far, the chunk being filled included.
  std::uint64_t size() const { return file_off_ + chunk_.size(); }
  std::uint64_t messages() const { return msg_count_; }

 private:
  struct ChunkIndex {
    std::uint64_t start = 0, end = 0, offset = 0, length = 0, index_length = 0, uncompressed = 0;
    std::map<std::uint16_t, std::uint64_t> index_offsets;
  };
  std::string put(const std::string& rec);
  std::string fail(const std::string& why);
  std::FILE* f_ = nullptr;
  std::string path_;
  std::size_t chunk_bytes_ = 0;
  std::uint64_t file_off_ = 0;
  std::string schemas_, channels_;  ///< their records (repeated in the summary)
  std::uint16_t n_schemas_ = 0, n_channels_ = 0;
  std::vector<std::uint32_t> seq_;  ///< per channel
  std::vector<std::uint64_t> per_channel_;
  std::string chunk_;  ///< records of the chunk being filled
  std::uint64_t chunk_start_ = 0, chunk_end_ = 0;
  std::map<std::uint16_t, std::vector<std::pair<std::uint64_t, std::uint64_t>>> chunk_index_;
  std::vector<ChunkIndex> chunks_;
  std::uint64_t msg_count_ = 0, first_t_ = 0, last_t_ = 0;
};

}  // namespace servoarm::fw
