// Reading the files the firmware reads: size cap, file-type checks, TOML (toml++).
// See file_input.hpp. Set-up code (allocates, does I/O), exception-free.
#include "servoarm/kinematics/file_input.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cfenv>
#include <charconv>
#include <cstring>

namespace servoarm::kin {

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

std::string source_text(const toml::source_region& where, const std::string& origin) {
  if (where.begin.line == 0) return origin;
  return origin + ":" + std::to_string(where.begin.line) + ":" + std::to_string(where.begin.column);
}

TomlDocument parse_toml(std::string_view text, const std::string& origin, std::size_t max_bytes) {
  TomlDocument doc;
  if (text.size() > max_bytes) {
    doc.error = origin + ": larger than " + std::to_string(max_bytes) + " bytes (" + std::to_string(text.size()) + ")";
    return doc;
  }
  // toml++ reads 1e400 with the C library, which raises FE_OVERFLOW (the number is then
  // refused as out of range): the floating-point flags are left as they were before.
  std::fenv_t fenv;
  std::feholdexcept(&fenv);
  toml::parse_result r = toml::parse(text, std::string_view(origin));
  std::fesetenv(&fenv);
  if (!r) {
    const toml::parse_error& e = r.error();
    std::string what(e.description());
    for (char& c : what)
      if (c == '\n' || c == '\r') c = ' ';
    doc.error = source_text(e.source(), origin) + ": not valid TOML: " + what;
    return doc;
  }
  doc.table = std::move(r).table();
  return doc;
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
