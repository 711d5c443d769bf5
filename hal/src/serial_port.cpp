// SPDX-License-Identifier: Apache-2.0
#include "servoarm/hal/serial_port.hpp"

#include <fcntl.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <utility>

namespace servoarm::hal {

namespace {

bool baud_constant(int baud, speed_t& sp) {
  switch (baud) {
    case 9600: sp = B9600; return true;
    case 19200: sp = B19200; return true;
    case 38400: sp = B38400; return true;
    case 57600: sp = B57600; return true;
    case 115200: sp = B115200; return true;
    case 230400: sp = B230400; return true;
    case 460800: sp = B460800; return true;
    case 921600: sp = B921600; return true;
    default: return false;
  }
}

std::string errno_text() { return std::strerror(errno); }

}  // namespace

SerialPort& SerialPort::operator=(SerialPort&& o) noexcept {
  if (this != &o) {
    close();
    fd_ = o.fd_;
    path_ = std::move(o.path_);
    message_ = std::move(o.message_);
    o.fd_ = -1;
  }
  return *this;
}

bool SerialPort::supported_baud(int baud) {
  speed_t sp;
  return baud_constant(baud, sp);
}

Status SerialPort::open(const std::string& path, int baud) {
  close();
  message_.clear();
  if (path.empty()) {
    message_ = "serial port: empty path";
    return Status::invalid_argument;
  }
  speed_t sp = B115200;
  if (!baud_constant(baud, sp)) {
    message_ = path + ": unsupported baud rate " + std::to_string(baud) +
               " (9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600)";
    return Status::invalid_argument;
  }
  const int fd = ::open(path.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) {
    message_ = path + ": " + errno_text();
    return Status::io_error;
  }
  termios tio{};
  if (tcgetattr(fd, &tio) != 0) {
    message_ = path + ": not a terminal (" + errno_text() + ")";
    ::close(fd);
    return Status::io_error;
  }
  cfmakeraw(&tio);  // 8 data bits, no parity, no echo, no line editing
  tio.c_cflag |= CLOCAL | CREAD;
  tio.c_cflag &= ~static_cast<tcflag_t>(CRTSCTS | CSTOPB);  // no hardware flow control, 1 stop bit
  tio.c_cc[VMIN] = 1;
  tio.c_cc[VTIME] = 0;
  cfsetispeed(&tio, sp);
  cfsetospeed(&tio, sp);
  if (tcsetattr(fd, TCSANOW, &tio) != 0) {
    message_ = path + ": tcsetattr at " + std::to_string(baud) + " baud: " + errno_text();
    ::close(fd);
    return Status::io_error;
  }
  fd_ = fd;
  path_ = path;
  return Status::ok;
}

void SerialPort::adopt(int fd, const std::string& path) {
  close();
  fd_ = fd;
  path_ = path;
  message_.clear();
}

int SerialPort::release() {
  const int fd = fd_;
  fd_ = -1;
  return fd;
}

void SerialPort::close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

bool make_raw(int fd) {
  termios tio{};
  if (tcgetattr(fd, &tio) != 0) return false;
  cfmakeraw(&tio);
  tio.c_cc[VMIN] = 1;
  tio.c_cc[VTIME] = 0;
  return tcsetattr(fd, TCSANOW, &tio) == 0;
}

Status open_pty(PtyPair& out, std::string& message) {
  out.master.close();
  out.slave.close();
  const int m = posix_openpt(O_RDWR | O_NOCTTY | O_CLOEXEC);
  if (m < 0) {
    message = "posix_openpt: " + errno_text();
    return Status::io_error;
  }
  if (grantpt(m) != 0 || unlockpt(m) != 0) {
    message = "grantpt/unlockpt: " + errno_text();
    ::close(m);
    return Status::io_error;
  }
  char name[128];
  if (ptsname_r(m, name, sizeof name) != 0) {
    message = "ptsname: " + errno_text();
    ::close(m);
    return Status::io_error;
  }
  const int s = ::open(name, O_RDWR | O_NOCTTY | O_CLOEXEC);
  if (s < 0) {
    message = std::string(name) + ": " + errno_text();
    ::close(m);
    return Status::io_error;
  }
  make_raw(s);
  make_raw(m);
  fcntl(m, F_SETFL, fcntl(m, F_GETFL) | O_NONBLOCK);
  out.master.adopt(m, name);
  out.slave.adopt(s, name);
  message.clear();
  return Status::ok;
}

}  // namespace servoarm::hal
