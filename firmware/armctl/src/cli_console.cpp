// SPDX-License-Identifier: Apache-2.0
#include "servoarm/armctl/cli_console.hpp"

#include <fcntl.h>
#include <poll.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <memory>
#include <string>
#include <vector>

#include "servoarm/armctl/cli_common.hpp"
#include "servoarm/lang/command_table.hpp"
#include "servoarm/lang/number.hpp"

#ifdef SERVOARM_CLI_CAN
#include "servoarm/hal/serial_port.hpp"
#include "servoarm/hal/isotp.hpp"
#include "servoarm/hal/socketcan_bus.hpp"
#endif
#ifdef SERVOARM_CLI_LIBEDIT
// Line editing and history: Debian's libedit (BSD licence, readline-compatible API,
// `libedit-dev`, pkg-config `libedit`) rather than GNU readline (GPL) or hand-written
// terminal code.
#include <histedit.h>
#include <clocale>
#include <cwchar>
#endif

namespace servoarm::fw {

namespace {

// Serial ports and ptys are opened by hal::SerialPort (serial_port.hpp), as in armfw.
bool write_all(int fd, const std::string& s) {
  std::size_t off = 0;
  while (off < s.size()) {
    const ssize_t w = ::write(fd, s.data() + off, s.size() - off);
    if (w > 0) off += static_cast<std::size_t>(w);
    else if (w < 0 && errno == EINTR) continue;
    else if (w < 0 && errno == EAGAIN) {
      pollfd p{fd, POLLOUT, 0};
      ::poll(&p, 1, 100);
    } else return false;
  }
  return true;
}


const char* kConsoleUsage =
    "usage: armctl console (--serial PATH [--baud N] | --can IFACE [--tx-id ID] [--rx-id ID])\n"
    "                      [--timeout SEC] [-c LINE]...\n"
    "       armctl console --reference   print the command reference of docs/console.md (from the\n"
    "                                    firmware's command table)\n"
    "  --serial PATH   serial device or pty printed by armfw (--pty)\n"
    "  --baud N        baud rate (default 115200)\n"
    "  --can IFACE     SocketCAN interface (can0, vcan0): armfw's console over ISO-TP (ISO 15765-2)\n"
    "  --tx-id ID      11-bit id armctl sends on = armfw's console.can_rx_id (default 0x7E0)\n"
    "  --rx-id ID      11-bit id armctl receives on = armfw's console.can_tx_id (default 0x7E8)\n"
    "                  (ids: 0x7E0 hex or 2016 decimal)\n"
    "  --timeout SEC   how long to wait for each answer (default 60, at most 86400; `wait` can take long)\n"
    "  -c LINE         send LINE, print the answer (up to its ok / error:); repeatable;\n"
    "                  without -c: interactive (line editing and history in ~/.armctl_history\n"
    "                  when built with libedit; answers that arrive while a line is half typed\n"
    "                  are printed above it and the line is redrawn; quit, exit or Ctrl-D ends it)\n"
    "  realtime characters, as a -c LINE or a typed line of their own: ?, !, ~, ^X (Ctrl-X,\n"
    "                  the e-stop), 0x85 (jog cancel; the bytes 0x18 and 0x85 themselves too).\n"
    "                  They have no ok: -c '?' prints the status report that comes back;\n"
    "                  -c '!' (and ~, ^X, 0x85) sends the character and then a ?, and prints\n"
    "                  what came back up to that report (the state after the character)\n"
    "Exit status: 0 every answer ok, 1 an answer was error: (or timed out), 2 usage / device error.\n";

// The device: a byte stream (serial / pty) or ISO-TP messages on a CAN interface.
class Link {
 public:
  virtual ~Link() = default;
  /// Send bytes: a command line with its newline, or one realtime character.
  virtual bool send(const std::string& bytes) = 0;
  /// fd to wait on for input (poll).
  virtual int fd() const = 0;
  /// Longest wait in ms before pump() must run again (timers), -1 = none.
  virtual int wait_ms() const { return -1; }
  /// Move whatever arrived into `in`; run timers. False when the device is gone.
  virtual bool pump(std::string& in) = 0;
  std::string error;
};

class TtyLink final : public Link {
 public:
  explicit TtyLink(int fd) : fd_(fd) { fcntl(fd_, F_SETFL, fcntl(fd_, F_GETFL) | O_NONBLOCK); }  // pump() never blocks
  ~TtyLink() override { ::close(fd_); }
  bool send(const std::string& bytes) override {
    if (write_all(fd_, bytes)) return true;
    error = std::string("write: ") + std::strerror(errno);
    return false;
  }
  int fd() const override { return fd_; }
  bool pump(std::string& in) override {
    char tmp[512];
    const ssize_t r = ::read(fd_, tmp, sizeof tmp);
    if (r > 0) in.append(tmp, static_cast<std::size_t>(r));
    if (r == 0) {
      error = "device closed";
      return false;
    }
    return true;
  }

 private:
  int fd_;
};

#ifdef SERVOARM_CLI_CAN
// One ISO-TP message per send(): armfw takes each message as one line (or as
// realtime characters). Messages wait in a queue while a long one is in flight.
class CanLink final : public Link {
 public:
  std::string open(const std::string& iface, std::uint32_t tx_id, std::uint32_t rx_id) {
    if (bus_.open(iface.c_str()) != hal::Status::ok) {
      const std::string m = bus_.message();
      return "cannot open " + (m.rfind(iface + ":", 0) == 0 ? m : iface + ": " + m);
    }
    hal::IsoTpConfig c;
    c.tx_id = tx_id;
    c.rx_id = rx_id;
    iso_ = std::make_unique<hal::IsoTpEndpoint>(bus_, clock_, c);
    const hal::CanFilter f = iso_->rx_filter();
    if (bus_.set_filters({&f, 1}) != hal::Status::ok) return iface + ": cannot set the receive filter";
    return "";
  }
  bool send(const std::string& bytes) override {
    for (std::size_t off = 0; off < bytes.size(); off += hal::IsoTpEndpoint::kMaxMessage)
      queue_.push_back(bytes.substr(off, hal::IsoTpEndpoint::kMaxMessage));
    std::string none;
    return pump(none);
  }
  int fd() const override { return bus_.fd(); }
  int wait_ms() const override {
    const hal::TimePoint t = iso_->next_deadline();
    if (t == hal::IsoTpEndpoint::kNever) return queue_.empty() ? -1 : 1;
    const hal::Duration d = t - clock_.now();
    return d <= 0 ? 0 : static_cast<int>(d / hal::kMillisecond) + 1;
  }
  bool pump(std::string& in) override {
    hal::CanFrame f;
    for (int i = 0; i < 4096; ++i) {
      const hal::Status s = bus_.receive(f, 0);
      if (s == hal::Status::timeout) break;
      if (s != hal::Status::ok) {
        error = std::string("can: ") + hal::describe(s) + " (" + bus_.message() + ")";
        return false;
      }
      if (!check(iso_->on_frame(f), in)) return false;
    }
    if (!check(iso_->poll(), in)) return false;
    while (!queue_.empty() && !iso_->sending()) {
      const std::string& m = queue_.front();
      const hal::IsoTpResult r = iso_->send({reinterpret_cast<const std::uint8_t*>(m.data()), m.size()});
      if (r != hal::IsoTpResult::ok) {
        error = std::string("can: send: ") + hal::to_string(r) + " (" + hal::describe(iso_->last_bus_status()) + ")";
        return false;
      }
      queue_.pop_front();
    }
    return true;
  }

 private:
  bool check(const hal::IsoTpEvent& ev, std::string& in) {
    if (ev.rx == hal::IsoTpResult::ok) {
      const auto m = iso_->rx_message();
      in.append(m.begin(), m.end());
    }
    if (static_cast<int>(ev.tx) < 0 && ev.tx != hal::IsoTpResult::malformed) {
      error = std::string("can: send: ISO-TP ") + hal::to_string(ev.tx) +
              (ev.tx == hal::IsoTpResult::timeout_bs ? " (no flow control: is armfw's console.can on this interface, with these ids?)" : "");
      return false;
    }
    if (static_cast<int>(ev.rx) < 0 && ev.rx != hal::IsoTpResult::malformed)
      std::fprintf(stderr, "armctl: can: an answer was lost: ISO-TP %s\n", hal::to_string(ev.rx));
    return true;
  }
  hal::SocketCanBus bus_;
  hal::MonotonicClock clock_;
  std::unique_ptr<hal::IsoTpEndpoint> iso_;
  std::deque<std::string> queue_;
};
#endif

// Wait for the device (or `extra_fd`) up to `ms`, then pump. False when the link failed.
bool wait_and_pump(Link& link, std::string& buf, int ms, int extra_fd = -1, bool* extra_ready = nullptr) {
  const int lw = link.wait_ms();
  if (lw >= 0 && (ms < 0 || lw < ms)) ms = lw;
  pollfd p[2] = {{link.fd(), POLLIN, 0}, {extra_fd, POLLIN, 0}};
  const int n = ::poll(p, extra_fd >= 0 ? 2 : 1, ms);
  if (extra_ready) *extra_ready = n > 0 && extra_fd >= 0 && (p[1].revents & (POLLIN | POLLHUP | POLLERR));
  return link.pump(buf);
}

// Read until a final answer line ("ok..." or "error:...") arrives. Data lines and
// alarms are printed as they come. Returns 0 ok, 1 error/timeout, 2 device failure.
int await_answer(Link& link, std::string& buf, double timeout_s) {
  const auto t0 = std::chrono::steady_clock::now();
  for (;;) {
    std::size_t nl;
    while ((nl = buf.find('\n')) != std::string::npos) {
      std::string line = buf.substr(0, nl);
      buf.erase(0, nl + 1);
      if (!line.empty() && line.back() == '\r') line.pop_back();
      if (line.rfind("alarm:", 0) == 0) {
        std::fprintf(stderr, "%s\n", line.c_str());
        continue;
      }
      std::printf("%s\n", line.c_str());
      std::fflush(stdout);
      if (line.rfind("ok", 0) == 0) return 0;
      if (line.rfind("error:", 0) == 0) return 1;
    }
    const double left = timeout_s - std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (left <= 0) {
      std::fprintf(stderr, "armctl: no answer within %.0f s\n", timeout_s);
      return 1;
    }
    if (!wait_and_pump(link, buf, static_cast<int>(left * 1000) + 1)) {
      std::fprintf(stderr, "armctl: %s\n", link.error.c_str());
      return 2;
    }
  }
}

// A typed line -> what goes to the device: a line alone holding ?, !, ~, ^X (or the
// byte 0x18), 0x85 (or the byte 0x85) is that realtime character, anything else a line.
std::string device_bytes(const std::string& line) {
  if (line == "?" || line == "!" || line == "~") return line;
  if (line == "^X" || line == "\x18") return std::string(1, '\x18');
  if (line == "0x85" || line == "\x85") return std::string(1, '\x85');
  return line + "\n";
}

bool is_realtime_bytes(const std::string& b) { return b.size() == 1 && b[0] != '\n'; }

// Read until the status report (a line "<...>") arrives; lines before it (alarms,
// the error of a realtime character) are printed as they come. Returns 0 the report
// came, 1 an error: line came or no report within the timeout, 2 device failure.
int await_report(Link& link, std::string& buf, double timeout_s) {
  const auto t0 = std::chrono::steady_clock::now();
  int rc = 0;
  for (;;) {
    std::size_t nl;
    while ((nl = buf.find('\n')) != std::string::npos) {
      std::string line = buf.substr(0, nl);
      buf.erase(0, nl + 1);
      if (!line.empty() && line.back() == '\r') line.pop_back();
      if (line.rfind("alarm:", 0) == 0) {
        std::fprintf(stderr, "%s\n", line.c_str());
        continue;
      }
      std::printf("%s\n", line.c_str());
      std::fflush(stdout);
      if (line.rfind("error:", 0) == 0) rc = 1;
      if (line.rfind("<", 0) == 0) return rc;
    }
    const double left = timeout_s - std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (left <= 0) {
      std::fprintf(stderr, "armctl: no status report within %.0f s\n", timeout_s);
      return 1;
    }
    if (!wait_and_pump(link, buf, static_cast<int>(left * 1000) + 1)) {
      std::fprintf(stderr, "armctl: %s\n", link.error.c_str());
      return 2;
    }
  }
}

// One -c item. A line waits for its ok / error:. A realtime character has no ok: `?`
// waits for its status report and prints it; `!`, `~`, Ctrl-X and 0x85 are followed
// by a `?`, whose report comes after the firmware has acted on the character (and
// after any error it answered), and that report is printed. 0 ok, 1 error/timeout, 2 device.
int run_one(Link& link, std::string& buf, const std::string& l, double timeout_s) {
  const std::string bytes = device_bytes(l);
  if (!link.send(bytes)) {
    std::fprintf(stderr, "armctl: %s\n", link.error.c_str());
    return 2;
  }
  if (!is_realtime_bytes(bytes)) return await_answer(link, buf, timeout_s);
  if (bytes != "?" && !link.send("?")) {
    std::fprintf(stderr, "armctl: %s\n", link.error.c_str());
    return 2;
  }
  return await_report(link, buf, timeout_s);
}

// A typed `quit` or `exit` (the command table's entry and its aliases): armctl sends it (armfw
// ends this client's session and answers), prints the answer and ends.
bool ends_session(const std::string& line) {
  const std::size_t a = line.find_first_not_of(" \t"), b = line.find_last_not_of(" \t\r");
  if (a == std::string::npos) return false;
  const std::string_view w = std::string_view(line).substr(a, b + 1 - a);
  if (ieq(w, "quit")) return true;
  for (const CommandAlias& x : kCommandAliases)
    if (ieq(w, x.alias) && std::string_view(x.name) == "quit") return true;
  return false;
}

// Interactive without line editing (stdin not a terminal, or no libedit): stdin
// lines to the device, everything from the device to stdout.
int interactive_plain(Link& link) {
  std::string in, buf;
  bool quit = false;
  while (!quit) {
    bool key = false;
    if (!wait_and_pump(link, buf, -1, 0, &key)) {
      std::fprintf(stderr, "armctl: %s\n", link.error.c_str());
      return kExitUsage;
    }
    if (!buf.empty()) {
      std::fwrite(buf.data(), 1, buf.size(), stdout);
      std::fflush(stdout);
      buf.clear();
    }
    if (!key) continue;
    char tmp[512];
    const ssize_t r = ::read(0, tmp, sizeof tmp);
    if (r <= 0) break;
    in.append(tmp, static_cast<std::size_t>(r));
    std::size_t nl;
    while (!quit && (nl = in.find('\n')) != std::string::npos) {
      const std::string line = in.substr(0, nl);
      in.erase(0, nl + 1);
      if (!link.send(device_bytes(line))) {
        std::fprintf(stderr, "armctl: %s\n", link.error.c_str());
        return kExitUsage;
      }
      quit = ends_session(line);
    }
  }
  // Let answers to the last lines arrive (a script piped in).
  const auto t0 = std::chrono::steady_clock::now();
  while (std::chrono::steady_clock::now() - t0 < std::chrono::milliseconds(300)) {
    if (!wait_and_pump(link, buf, 50)) break;
    std::fwrite(buf.data(), 1, buf.size(), stdout);
    buf.clear();
  }
  std::fflush(stdout);
  return kExitOk;
}

#ifdef SERVOARM_CLI_LIBEDIT
std::string history_path() {
  const char* home = std::getenv("HOME");
  return home && *home ? std::string(home) + "/.armctl_history" : std::string();
}

// Interactive with line editing (libedit's own API, histedit.h), in one thread: libedit
// reads keys through getc_fn, which waits on the keyboard and the device together.
// Complete lines from the device are printed above the line being typed, and libedit
// then redraws the prompt and the half-typed line (EL_REFRESH), cursor where it was.
struct EditCtx {
  Link* link = nullptr;
  std::string prompt, from_device, keys;
  std::size_t key_pos = 0;
  std::mbstate_t mb{};
  bool failed = false;
};

// Print the complete lines that came from the device on a fresh line, then redraw.
void print_device_lines(EditLine* el, EditCtx& c) {
  const std::size_t end = c.from_device.rfind('\n');
  if (end == std::string::npos) return;  // wait for the rest of the line
  std::fputs("\r\033[K", stdout);
  std::fwrite(c.from_device.data(), 1, end + 1, stdout);
  c.from_device.erase(0, end + 1);
  std::fflush(stdout);
  el_set(el, EL_REFRESH);
}

int getc_fn(EditLine* el, wchar_t* wc) {
  EditCtx* c = nullptr;
  el_get(el, EL_CLIENTDATA, &c);
  for (;;) {
    while (c->key_pos < c->keys.size()) {  // decode what the keyboard sent (UTF-8)
      const std::size_t n = std::mbrtowc(wc, c->keys.data() + c->key_pos, c->keys.size() - c->key_pos, &c->mb);
      if (n == static_cast<std::size_t>(-2)) break;  // incomplete: read more
      if (n == static_cast<std::size_t>(-1)) {      // not UTF-8: take the byte
        c->mb = std::mbstate_t{};
        *wc = static_cast<unsigned char>(c->keys[c->key_pos++]);
        return 1;
      }
      c->key_pos += n == 0 ? 1 : n;
      return 1;
    }
    c->keys.erase(0, c->key_pos);
    c->key_pos = 0;
    bool key = false;
    if (!wait_and_pump(*c->link, c->from_device, -1, 0, &key)) {
      std::fprintf(stderr, "\r\033[Karmctl: %s\n", c->link->error.c_str());
      c->failed = true;
      return -1;
    }
    print_device_lines(el, *c);
    if (key) {
      char tmp[256];
      const ssize_t r = ::read(0, tmp, sizeof tmp);
      if (r == 0) return 0;  // end of input
      if (r < 0) {
        if (errno == EINTR || errno == EAGAIN) continue;
        return -1;
      }
      c->keys.append(tmp, static_cast<std::size_t>(r));
    }
  }
}

char* prompt_fn(EditLine* el) {
  EditCtx* c = nullptr;
  el_get(el, EL_CLIENTDATA, &c);
  return c->prompt.data();
}

int interactive_edit(Link& link, const std::string& prompt) {
  std::setlocale(LC_CTYPE, "");
  EditCtx c;
  c.link = &link;
  c.prompt = prompt;
  EditLine* el = el_init("armctl", stdin, stdout, stderr);
  if (el == nullptr) return interactive_plain(link);
  History* h = history_init();
  HistEvent ev;
  history(h, &ev, H_SETSIZE, 1000);
  history(h, &ev, H_SETUNIQUE, 1);
  const std::string hist = history_path();
  if (!hist.empty()) history(h, &ev, H_LOAD, hist.c_str());
  el_set(el, EL_CLIENTDATA, &c);
  el_set(el, EL_EDITOR, "emacs");
  el_set(el, EL_SIGNAL, 1);
  el_set(el, EL_PROMPT, prompt_fn);
  el_set(el, EL_HIST, history, h);
  el_set(el, EL_GETCFN, getc_fn);
  el_source(el, nullptr);  // ~/.editrc, as other libedit programs
  for (;;) {
    int count = 0;
    const char* line = el_gets(el, &count);
    if (line == nullptr || count <= 0 || c.failed) break;  // Ctrl-D, end of input, device gone
    std::string l(line, static_cast<std::size_t>(count));
    while (!l.empty() && (l.back() == '\n' || l.back() == '\r')) l.pop_back();
    if (!l.empty()) history(h, &ev, H_ENTER, l.c_str());
    if (!link.send(device_bytes(l))) {
      std::fprintf(stderr, "armctl: %s\n", link.error.c_str());
      c.failed = true;
      break;
    }
    if (ends_session(l)) break;
  }
  el_end(el);  // the terminal back as it was
  std::fputc('\n', stdout);
  // Let the answer to the last line arrive before leaving.
  const auto t0 = std::chrono::steady_clock::now();
  while (!c.failed && std::chrono::steady_clock::now() - t0 < std::chrono::milliseconds(200)) {
    if (!wait_and_pump(link, c.from_device, 50)) break;
  }
  std::fwrite(c.from_device.data(), 1, c.from_device.size(), stdout);
  std::fflush(stdout);
  if (!hist.empty()) history(h, &ev, H_SAVE, hist.c_str());
  history_end(h);
  return c.failed ? kExitUsage : kExitOk;
}
#endif

bool parse_can_id(const char* v, std::uint32_t& out) {
  if (v == nullptr || *v == '\0') return false;
  char* end = nullptr;
  errno = 0;
  const long id = std::strtol(v, &end, 0);
  if (errno != 0 || *end != '\0' || id < 0 || id > 0x7FF) return false;
  out = static_cast<std::uint32_t>(id);
  return true;
}

}  // namespace

int console_main(int argc, char** argv) {
  std::string path, iface;
  int baud = 115200;
  double timeout_s = 60;
  std::uint32_t tx_id = 0x7E0, rx_id = 0x7E8;
  std::vector<std::string> lines;
  for (int i = 2; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> const char* { return i + 1 < argc ? argv[++i] : nullptr; };
    if (a == "--help" || a == "-h") {
      std::fputs(kConsoleUsage, stdout);
      return kExitOk;
    } else if (a == "--reference") {
      std::fputs(console_reference_markdown().c_str(), stdout);
      return kExitOk;
    } else if (a == "--serial") {
      const char* v = value();
      if (!v) return usage_error("--serial needs a path");
      path = v;
    } else if (a == "--can") {
      const char* v = value();
      if (!v || !*v) return usage_error("--can needs an interface (can0, vcan0)");
      iface = v;
    } else if (a == "--tx-id" || a == "--rx-id") {
      const char* v = value();
      if (!parse_can_id(v, a == "--tx-id" ? tx_id : rx_id))
        return usage_error(a + " needs an 11-bit CAN id (0x000..0x7FF, e.g. 0x7E0), got '" + (v ? v : "") + "'");
    } else if (a == "--baud") {
      const char* v = value();
      double d = 0;
      if (!v || !parse_number(v, d) || d < 50 || d > 4000000 || d != std::floor(d))
        return usage_error(std::string("--baud needs a whole rate in bits/s (50..4000000, e.g. 115200), got '") + (v ? v : "") + "'");
      baud = static_cast<int>(d);
    } else if (a == "--timeout") {
      const char* v = value();
      if (!v || !parse_number(v, timeout_s) || !(timeout_s > 0 && timeout_s <= 86400))
        return usage_error(std::string("--timeout needs seconds within 0..86400, got '") + (v ? v : "") + "'");
    } else if (a == "-c") {
      const char* v = value();
      if (!v) return usage_error("-c needs a command line");
      lines.push_back(v);
    } else {
      return usage_error("console: unknown option '" + a + "' (see armctl console --help)");
    }
  }
  if (path.empty() == iface.empty())
    return usage_error("console: give either --serial PATH (the pty armfw printed, or a serial device) or --can IFACE");
  if (tx_id == rx_id) return usage_error("console: --tx-id and --rx-id must differ");
  std::unique_ptr<Link> link;
  std::string where;
  if (!path.empty()) {
#ifdef SERVOARM_CLI_CAN
    hal::SerialPort port;
    if (port.open(path, baud) != hal::Status::ok) return usage_error("console: " + port.message());
    link = std::make_unique<TtyLink>(port.release());
    where = path;
#else
    return usage_error("console: --serial: this armctl was built without the hal library (no serial support)");
#endif
  } else {
#ifdef SERVOARM_CLI_CAN
    auto c = std::make_unique<CanLink>();
    const std::string e = c->open(iface, tx_id, rx_id);
    if (!e.empty()) return usage_error("console: --can: " + e);
    link = std::move(c);
    char b[96];
    std::snprintf(b, sizeof b, "%s (ISO-TP, sending on 0x%03X, receiving on 0x%03X)", iface.c_str(), unsigned(tx_id),
                  unsigned(rx_id));
    where = b;
#else
    return usage_error("console: --can: this armctl was built without the hal library (no CAN support)");
#endif
  }
  std::string buf;
  int rc = kExitOk;
  if (!lines.empty()) {
    for (const std::string& l : lines) {
      if (l.find('\n') != std::string::npos) return usage_error("console: -c takes one line");
      const int r = run_one(*link, buf, l, timeout_s);
      if (r == 2) return kExitUsage;
      if (r != 0) rc = kExitFailed;
    }
    return rc;
  }
  std::fprintf(stderr, "armctl: connected to %s (quit, exit or Ctrl-D ends; ?, !, ~ alone on a line are realtime; ^X e-stop)\n",
               where.c_str());
#ifdef SERVOARM_CLI_LIBEDIT
  if (isatty(0) && isatty(1)) return interactive_edit(*link, "arm> ");
#endif
  return interactive_plain(*link);
}

}  // namespace servoarm::fw
