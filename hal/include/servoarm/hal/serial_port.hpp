// SPDX-License-Identifier: Apache-2.0
#pragma once
// Serial TTYs and ptys, opened for a console: raw 8N1, no flow control, no echo,
// non-blocking (callers wait with poll). Set-up code (opens, formats the error
// message), not for the real-time path. Used by armfw's console transports
// (firmware/console/transport.cpp) and armctl's console client alike.
#include <string>

#include "servoarm/hal/status.hpp"

namespace servoarm::hal {

/// A file descriptor of a TTY, closed by the destructor (move-only).
class SerialPort {
 public:
  SerialPort() = default;
  ~SerialPort() { close(); }
  SerialPort(const SerialPort&) = delete;
  SerialPort& operator=(const SerialPort&) = delete;
  SerialPort(SerialPort&& o) noexcept { *this = static_cast<SerialPort&&>(o); }
  SerialPort& operator=(SerialPort&& o) noexcept;

  /// Open the TTY at `path`: raw 8N1 at `baud` (9600, 19200, 38400, 57600, 115200,
  /// 230400, 460800, 921600), receiver on, modem lines ignored, no RTS/CTS, non-blocking.
  /// A port already open is closed first. message() names the path (and the baud).
  /// @retval ok                port open, fd() valid
  /// @retval invalid_argument  unsupported baud rate (nothing opened), or empty path
  /// @retval io_error          open() failed (no such device, permission), not a
  ///                           terminal, or the settings were refused (tcsetattr)
  Status open(const std::string& path, int baud);
  /// Adopt an open descriptor (e.g. a pty side); the port closes it.
  void adopt(int fd, const std::string& path);
  /// Give the descriptor away (the caller closes it); the port is closed after.
  int release();
  void close();

  bool is_open() const { return fd_ >= 0; }
  int fd() const { return fd_; }
  const std::string& path() const { return path_; }
  /// Why the last open failed ("" after a success).
  const std::string& message() const { return message_; }

  /// True for the baud rates open() accepts.
  static bool supported_baud(int baud);

 private:
  int fd_ = -1;
  std::string path_, message_;
};

/// Make an open TTY raw (cfmakeraw, VMIN 1, VTIME 0). False when it is not a terminal.
bool make_raw(int fd);

/// A pseudo-terminal pair. `master`: what the program reads and writes (raw,
/// non-blocking). `slave`: the side a client opens by `slave.path()` (raw; kept
/// open here too so that the master stays readable while no client is attached).
struct PtyPair {
  SerialPort master, slave;
};

/// Open a pty pair.
/// @retval ok        both sides open
/// @retval io_error  posix_openpt / grantpt / unlockpt / ptsname / opening the slave failed (message says which)
Status open_pty(PtyPair& out, std::string& message);

}  // namespace servoarm::hal
