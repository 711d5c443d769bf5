#include "servoarm/firmware/cli_console.hpp"

#include <fcntl.h>
#include <poll.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "servoarm/firmware/cli_common.hpp"

namespace servoarm::fw {

namespace {

// armctl links only the CLI library, so the few lines of termios set-up live here
// (armfw's side is firmware/src/transport.cpp).
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

int open_tty(const std::string& path, int baud, std::string& err) {
  speed_t sp = B115200;
  switch (baud) {
    case 9600: sp = B9600; break;
    case 19200: sp = B19200; break;
    case 38400: sp = B38400; break;
    case 57600: sp = B57600; break;
    case 115200: sp = B115200; break;
    case 230400: sp = B230400; break;
    case 460800: sp = B460800; break;
    case 921600: sp = B921600; break;
    default: err = "unsupported baud rate " + std::to_string(baud); return -1;
  }
  const int fd = ::open(path.c_str(), O_RDWR | O_NOCTTY);
  if (fd < 0) {
    err = path + ": " + std::strerror(errno);
    return -1;
  }
  termios tio{};
  if (tcgetattr(fd, &tio) != 0) {
    err = path + ": not a terminal";
    ::close(fd);
    return -1;
  }
  cfmakeraw(&tio);
  tio.c_cflag |= CLOCAL | CREAD;
  cfsetispeed(&tio, sp);
  cfsetospeed(&tio, sp);
  tcsetattr(fd, TCSANOW, &tio);
  return fd;
}

const char* kConsoleUsage =
    "usage: armctl console --serial PATH [--baud N] [--timeout SEC] [-c LINE]...\n"
    "  --serial PATH   serial device or pty printed by armfw (--pty)\n"
    "  --baud N        baud rate (default 115200)\n"
    "  --timeout SEC   how long to wait for each answer (default 60; `wait` can take long)\n"
    "  -c LINE         send LINE, print the answer; repeatable; without -c: interactive\n"
    "                  (lines from stdin are sent; a line holding only ?, ! or ~ sends that\n"
    "                  realtime character; ^X sends Ctrl-X)\n"
    "Exit status: 0 every answer ok, 1 an answer was error: (or timed out), 2 usage / device error.\n";

// Read from fd until a final answer line ("ok..." or "error:...") arrives.
// Data lines and alarms are printed as they come. Returns 0 ok, 1 error/timeout.
int await_answer(int fd, std::string& buf, double timeout_s) {
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
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(left * 1000) + 1) <= 0) continue;
    char tmp[512];
    const ssize_t r = ::read(fd, tmp, sizeof tmp);
    if (r > 0) buf.append(tmp, static_cast<std::size_t>(r));
    else if (r == 0) {
      std::fprintf(stderr, "armctl: device closed\n");
      return 1;
    }
  }
}

}  // namespace

int console_main(int argc, char** argv) {
  std::string path;
  int baud = 115200;
  double timeout_s = 60;
  std::vector<std::string> lines;
  for (int i = 2; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> const char* { return i + 1 < argc ? argv[++i] : nullptr; };
    if (a == "--help" || a == "-h") {
      std::fputs(kConsoleUsage, stdout);
      return kExitOk;
    } else if (a == "--serial") {
      const char* v = value();
      if (!v) return usage_error("--serial needs a path");
      path = v;
    } else if (a == "--baud") {
      const char* v = value();
      double d = 0;
      if (!v || !parse_number(v, d) || d < 1) return usage_error("--baud needs a rate");
      baud = static_cast<int>(d);
    } else if (a == "--timeout") {
      const char* v = value();
      if (!v || !parse_number(v, timeout_s) || timeout_s <= 0) return usage_error("--timeout needs seconds > 0");
    } else if (a == "-c") {
      const char* v = value();
      if (!v) return usage_error("-c needs a command line");
      lines.push_back(v);
    } else {
      return usage_error("console: unknown option '" + a + "' (see armctl console --help)");
    }
  }
  if (path.empty()) return usage_error("console: give --serial PATH (the pty armfw printed, or a serial device)");
  std::string e;
  const int fd = open_tty(path, baud, e);
  if (fd < 0) return usage_error("console: " + e);
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  struct {
    int rd, wr;
  } t{fd, fd};
  std::string buf;
  int rc = kExitOk;
  if (!lines.empty()) {
    for (const std::string& l : lines) {
      if (l.find('\n') != std::string::npos) return usage_error("console: -c takes one line");
      if (!write_all(t.wr, l + "\n")) return usage_error("console: write failed");
      if (await_answer(t.rd, buf, timeout_s) != 0) rc = kExitFailed;
    }
    return rc;
  }
  // Interactive: stdin lines to the device, everything from the device to stdout.
  std::fprintf(stderr, "armctl: connected to %s (Ctrl-D quits; ?, !, ~ alone on a line are realtime)\n", path.c_str());
  std::string in;
  for (;;) {
    pollfd p[2] = {{0, POLLIN, 0}, {t.rd, POLLIN, 0}};
    if (::poll(p, 2, -1) < 0) continue;
    char tmp[512];
    if (p[1].revents & POLLIN) {
      const ssize_t r = ::read(t.rd, tmp, sizeof tmp);
      if (r > 0) {
        std::fwrite(tmp, 1, static_cast<std::size_t>(r), stdout);
        std::fflush(stdout);
      }
    }
    if (p[0].revents & (POLLIN | POLLHUP)) {
      const ssize_t r = ::read(0, tmp, sizeof tmp);
      if (r <= 0) break;
      in.append(tmp, static_cast<std::size_t>(r));
      std::size_t nl;
      while ((nl = in.find('\n')) != std::string::npos) {
        std::string line = in.substr(0, nl);
        in.erase(0, nl + 1);
        if (line == "?" || line == "!" || line == "~") write_all(t.wr, line);
        else if (line == "^X") write_all(t.wr, std::string(1, '\x18'));
        else write_all(t.wr, line + "\n");
      }
    }
  }
  return kExitOk;
}

}  // namespace servoarm::fw
