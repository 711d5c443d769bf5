#pragma once
// Console transports (console thread, non-real-time): byte streams on file
// descriptors. stdin/stdout, a pseudo-terminal whose slave path is printed
// (screen / minicom / pronsole connect to it), a serial TTY in raw mode.
#include <string>

namespace servoarm::fw {

struct FdTransport {
  std::string name;
  int rd = -1, wr = -1;
  int keep = -1;          ///< pty: our own slave fd (keeps the master readable with no client)
  std::string path;       ///< pty slave / serial device path
  bool eof = false;
  bool owns = false;
  ~FdTransport();
};

/// Open a pty (raw, no echo). "" or the error; t.path = slave path.
std::string open_pty(FdTransport& t);
/// Open a serial TTY in raw 8N1 at `baud`. "" or the error.
std::string open_serial(FdTransport& t, const std::string& path, int baud);
/// Write all of `s` (blocking, retries on EINTR/EAGAIN with a short poll). False on error.
bool write_all(int fd, const std::string& s);

}  // namespace servoarm::fw
