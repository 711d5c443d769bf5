// SPDX-License-Identifier: Apache-2.0
// Reading the files the firmware reads: size cap, file-type checks, TOML (toml++).
// See file_input.hpp. Set-up code (allocates, does I/O), exception-free.
#include "servoarm/kinematics/io/file_input.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cfenv>
#include <charconv>
#include <cstdint>
#include <cstdio>
#include <cstring>

namespace servoarm::kin {

namespace {

/// Length of the valid UTF-8 sequence at t[i] (1 for ASCII), 0 when it is not one.
std::size_t utf8_len(std::string_view t, std::size_t i, std::uint32_t& cp) {
  const auto c = static_cast<unsigned char>(t[i]);
  std::size_t n = 0;
  if (c < 0x80) {
    cp = c;
    return 1;
  }
  if (c >= 0xC2 && c <= 0xDF) n = 2, cp = c & 0x1Fu;
  else if (c >= 0xE0 && c <= 0xEF) n = 3, cp = c & 0x0Fu;
  else if (c >= 0xF0 && c <= 0xF4) n = 4, cp = c & 0x07u;
  else return 0;
  if (i + n > t.size()) return 0;
  for (std::size_t k = 1; k < n; ++k) {
    const auto d = static_cast<unsigned char>(t[i + k]);
    if ((d & 0xC0u) != 0x80u) return 0;
    cp = (cp << 6) | (d & 0x3Fu);
  }
  if ((n == 3 && cp < 0x800) || (n == 4 && (cp < 0x10000 || cp > 0x10FFFF)) || (cp >= 0xD800 && cp <= 0xDFFF)) return 0;
  return n;
}

/// toml++ 3.3 asks is_non_ascii_horizontal_whitespace() about non-ASCII characters it
/// meets outside string values (bare text, quoted keys, table headers, after a
/// line-ending backslash), and that function reaches __builtin_unreachable for most of
/// U+00A1-U+0499, U+1492-U+188B, U+1C86-U+207F and U+2F6E-U+3367: undefined behaviour
/// on a file holding just "é" (found by tests/fuzz/fuzz_description). So toml++ is never
/// shown a non-ASCII character: in basic strings (keys and values) each becomes its
/// \uXXXX / \UXXXXXXXX escape (the same string), in comments a space (nobody reads
/// them), and anywhere else -- bare text, literal strings (which cannot hold escapes),
/// right after a backslash -- the text is refused here with its line and column.
/// Invalid UTF-8 is left for toml++ to report. Columns of later errors on a line with
/// escaped characters are counted in the escaped text.
std::string ascii_only(std::string_view t, std::string& where) {
  std::string out;
  out.reserve(t.size() + t.size() / 4);
  std::size_t line = 1, col = 1;
  enum class In { text, comment, basic, ml_basic, literal, ml_literal } in = In::text;
  bool escape = false;
  for (std::size_t i = 0; i < t.size();) {
    std::uint32_t cp = 0;
    const std::size_t n = utf8_len(t, i, cp);
    if (n == 0) {  // not UTF-8: toml++ reports it
      out.append(t.substr(i));
      return out;
    }
    const char c = t[i];
    auto starts = [&](const char* s) { return t.compare(i, std::strlen(s), s) == 0; };
    if (n > 1) {
      if (in == In::comment) {
        out += ' ';
      } else if ((in == In::basic || in == In::ml_basic) && !escape) {
        char b[12];
        std::snprintf(b, sizeof b, cp > 0xFFFF ? "\\U%08X" : "\\u%04X", static_cast<unsigned>(cp));
        out += b;
      } else {
        where = std::to_string(line) + ":" + std::to_string(col) +
                (in == In::text ? ": a non-ASCII character outside a string or comment"
                                : ": a non-ASCII character in a literal ('...') string or after a backslash "
                                  "(write it in a \"...\" string)");
        return out;
      }
      i += n;
      ++col;
      escape = false;
      continue;
    }
    std::size_t take = 1;
    switch (in) {
      case In::text:
        if (c == '#') in = In::comment;
        else if (c == '"' && starts("\"\"\"")) in = In::ml_basic, take = 3;
        else if (c == '"') in = In::basic;
        else if (c == '\'' && starts("'''")) in = In::ml_literal, take = 3;
        else if (c == '\'') in = In::literal;
        break;
      case In::comment:
        if (c == '\n') in = In::text;
        break;
      case In::basic:
      case In::ml_basic:
        if (escape) escape = false;
        else if (c == '\\') escape = true;
        else if (in == In::basic && (c == '"' || c == '\n')) in = In::text;
        else if (in == In::ml_basic && c == '"' && starts("\"\"\"")) in = In::text, take = 3;
        break;
      case In::literal:
        if (c == '\'' || c == '\n') in = In::text;
        break;
      case In::ml_literal:
        if (c == '\'' && starts("'''")) in = In::text, take = 3;
        break;
    }
    for (std::size_t k = 0; k < take && i < t.size(); ++k, ++i) {
      out += t[i];
      if (t[i] == '\n') ++line, col = 1;
      else ++col;
    }
  }
  return out;
}

}  // namespace

std::string read_text_file(const std::string& path, std::string& text, std::size_t max_bytes) {
  // O_NONBLOCK: opening a FIFO without a writer must not hang; fstat then refuses it.
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) return path + ": cannot open: " + std::strerror(errno);
  struct stat st{};
  std::string why;
  if (::fstat(fd, &st) != 0) why = std::string("cannot stat: ") + std::strerror(errno);
  else if (S_ISDIR(st.st_mode)) why = "is a directory, not a file";
  else if (!S_ISREG(st.st_mode)) why = "not a regular file";
  else if (st.st_size > static_cast<off_t>(max_bytes))  // off_t: no wrap on 32-bit size_t (armhf)
    why = "larger than " + std::to_string(max_bytes) + " bytes (" + std::to_string(st.st_size) + ")";
  std::string out;
  if (why.empty()) {
    char buf[8192];
    for (;;) {
      const ssize_t n = ::read(fd, buf, sizeof buf);
      if (n < 0 && errno == EINTR) continue;
      if (n < 0) {
        why = std::string("read error: ") + std::strerror(errno);
        break;
      }
      if (n == 0) break;
      out.append(buf, static_cast<std::size_t>(n));
      if (out.size() > max_bytes) {  // the file grew after fstat
        why = "larger than " + std::to_string(max_bytes) + " bytes";
        break;
      }
    }
  }
  ::close(fd);
  if (!why.empty()) return path + ": " + why;
  text = std::move(out);
  return "";
}

std::string write_text_file_atomic(const std::string& path, std::string_view text) {
  const std::string tmp = path + ".tmp";
  auto failed = [&](const char* step, int err) { return path + ": " + step + " failed: " + std::strerror(err); };
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC | O_NOFOLLOW, 0644);
  if (fd < 0) return failed("creating the temporary file", errno);
  std::size_t done = 0;
  int err = 0;
  const char* step = nullptr;
  while (done < text.size()) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      err = n < 0 ? errno : EIO;
      step = "writing";
      break;
    }
    done += static_cast<std::size_t>(n);
  }
  if (step == nullptr && ::fsync(fd) != 0) err = errno, step = "fsync";
  if (::close(fd) != 0 && step == nullptr) err = errno, step = "closing";
  if (step == nullptr && ::rename(tmp.c_str(), path.c_str()) != 0) err = errno, step = "renaming";
  if (step != nullptr) {
    ::unlink(tmp.c_str());
    return failed(step, err);
  }
  // The rename is durable once the directory is: fsync it (best effort: some file
  // systems refuse fsync on a directory; the file itself is complete either way).
  const std::size_t slash = path.rfind('/');
  const std::string dir = slash == std::string::npos ? "." : slash == 0 ? "/" : path.substr(0, slash);
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    (void)::fsync(dfd);
    ::close(dfd);
  }
  return "";
}

std::string source_text(const toml::source_region& where, const std::string& origin) {
  if (where.begin.line == 0) return origin;
  return origin + ":" + std::to_string(where.begin.line) + ":" + std::to_string(where.begin.column);
}

TomlDocument parse_toml(std::string_view text, const std::string& origin, std::size_t max_bytes) {
  TomlDocument doc;
  if (text.size() > max_bytes) {
    doc.error = one_line(origin) + ": larger than " + std::to_string(max_bytes) + " bytes (" + std::to_string(text.size()) + ")";
    return doc;
  }
  // toml++ reads 1e400 with the C library, which raises FE_OVERFLOW (the number is then
  // refused as out of range): the floating-point flags are left as they were before.
  // Plain ASCII text (most files) is what ascii_only() would return unchanged: it is parsed
  // as it is, without the copy and the per-character pass (a quarter of the loaders' time
  // under ASan; tests/bench/RESULTS.md, 2026-12-04 long runs).
  const bool plain_ascii =
      std::all_of(text.begin(), text.end(), [](char ch) { return static_cast<unsigned char>(ch) < 0x80; });
  std::string escaped;
  if (!plain_ascii) {
    std::string where;
    escaped = ascii_only(text, where);
    if (!where.empty()) {
      doc.error = one_line(origin + ":" + where);
      return doc;
    }
  }
  const std::string_view ascii = plain_ascii ? text : std::string_view(escaped);
  std::fenv_t fenv;
  std::feholdexcept(&fenv);
  toml::parse_result r = toml::parse(ascii, std::string_view(origin));
  std::fesetenv(&fenv);
  if (!r) {
    const toml::parse_error& e = r.error();
    doc.error = one_line(source_text(e.source(), origin) + ": not valid TOML: " + std::string(e.description()));
    return doc;
  }
  doc.table = std::move(r).table();
  return doc;
}

std::string one_line(std::string msg) {
  std::string out;
  out.reserve(msg.size());
  for (const char ch : msg) {
    const auto c = static_cast<unsigned char>(ch);
    if (c >= 0x20 && c != 0x7F) {
      out += ch;
    } else if (c == '\n') {
      out += "\\n";
    } else if (c == '\t') {
      out += "\\t";
    } else if (c == '\r') {
      out += "\\r";
    } else {
      char b[8];
      std::snprintf(b, sizeof b, "\\x%02X", c);
      out += b;
    }
  }
  return out;
}

const char* type_name(const toml::node& v) {
  switch (v.type()) {
    case toml::node_type::none: return "nothing";
    case toml::node_type::table: return "a table";
    case toml::node_type::array: return "an array";
    case toml::node_type::string: return "a string";
    case toml::node_type::integer: return "an integer";
    case toml::node_type::floating_point: return "a number";
    case toml::node_type::boolean: return "a boolean";
    case toml::node_type::date:
    case toml::node_type::time:
    case toml::node_type::date_time: return "a date/time";
  }
  return "an unknown value";
}

std::string value_text(const toml::node& v) {
  std::string s;
  if (const auto* p = v.as_string()) {
    s = "\"" + p->get() + "\"";
  } else if (const auto* i = v.as_integer()) {
    s = std::to_string(i->get());
  } else if (const auto* f = v.as_floating_point()) {
    char b[32];
    const auto r = std::to_chars(b, b + sizeof b, f->get());
    s.assign(b, r.ptr);
  } else if (const auto* t = v.as_boolean()) {
    s = t->get() ? "true" : "false";
  } else if (const auto* a = v.as_array()) {
    s = "[";
    for (std::size_t k = 0; k < a->size() && s.size() < 40; ++k) s += (k ? ", " : "") + value_text(*a->get(k));
    s += "]";
  } else {
    s = type_name(v);
  }
  for (char& c : s)
    if (static_cast<unsigned char>(c) < 0x20) c = ' ';
  if (s.size() > 40) {
    std::size_t cut = 37;  // not inside a UTF-8 sequence
    while (cut > 0 && (static_cast<unsigned char>(s[cut]) & 0xC0u) == 0x80u) --cut;
    s = s.substr(0, cut) + "...";
  }
  return s;
}

}  // namespace servoarm::kin
