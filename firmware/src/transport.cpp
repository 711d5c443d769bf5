#include "servoarm/firmware/transport.hpp"

#include <fcntl.h>
#include <poll.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>

namespace servoarm::fw {

FdTransport::~FdTransport() {
  if (owns) {
    if (rd >= 0) ::close(rd);
    if (wr >= 0 && wr != rd) ::close(wr);
  }
  if (keep >= 0) ::close(keep);
}

static void make_raw(int fd) {
  termios tio{};
  if (tcgetattr(fd, &tio) != 0) return;
  cfmakeraw(&tio);
  tio.c_cc[VMIN] = 1;
  tio.c_cc[VTIME] = 0;
  tcsetattr(fd, TCSANOW, &tio);
}

std::string open_pty(FdTransport& t) {
  const int m = posix_openpt(O_RDWR | O_NOCTTY);
  if (m < 0) return std::string("posix_openpt: ") + std::strerror(errno);
  if (grantpt(m) != 0 || unlockpt(m) != 0) {
    ::close(m);
    return std::string("grantpt/unlockpt: ") + std::strerror(errno);
  }
  char name[128];
  if (ptsname_r(m, name, sizeof name) != 0) {
    ::close(m);
    return "ptsname failed";
  }
  const int s = ::open(name, O_RDWR | O_NOCTTY);
  if (s >= 0) make_raw(s);
  make_raw(m);
  fcntl(m, F_SETFL, fcntl(m, F_GETFL) | O_NONBLOCK);
  t.name = "pty";
  t.rd = t.wr = m;
  t.keep = s;
  t.path = name;
  t.owns = true;
  return "";
}

std::string open_serial(FdTransport& t, const std::string& path, int baud) {
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
    default: return "unsupported baud rate " + std::to_string(baud);
  }
  const int fd = ::open(path.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK);
  if (fd < 0) return path + ": " + std::strerror(errno);
  termios tio{};
  if (tcgetattr(fd, &tio) != 0) {
    const std::string e = path + ": not a terminal (" + std::strerror(errno) + ")";
    ::close(fd);
    return e;
  }
  cfmakeraw(&tio);
  tio.c_cflag |= CLOCAL | CREAD;
  tio.c_cflag &= ~static_cast<tcflag_t>(CRTSCTS | CSTOPB);
  cfsetispeed(&tio, sp);
  cfsetospeed(&tio, sp);
  if (tcsetattr(fd, TCSANOW, &tio) != 0) {
    const std::string e = path + ": tcsetattr: " + std::strerror(errno);
    ::close(fd);
    return e;
  }
  t.name = "serial";
  t.rd = t.wr = fd;
  t.path = path;
  t.owns = true;
  return "";
}

bool write_all(int fd, const std::string& s) {
  std::size_t off = 0;
  int spins = 0;
  while (off < s.size()) {
    const ssize_t w = ::write(fd, s.data() + off, s.size() - off);
    if (w > 0) {
      off += static_cast<std::size_t>(w);
      continue;
    }
    if (w < 0 && (errno == EINTR)) continue;
    if (w < 0 && (errno == EAGAIN || errno == EWOULDBLOCK) && ++spins < 200) {
      pollfd p{fd, POLLOUT, 0};
      ::poll(&p, 1, 10);
      continue;
    }
    return false;
  }
  return true;
}

}  // namespace servoarm::fw
