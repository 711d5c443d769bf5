// SPDX-License-Identifier: Apache-2.0
// hal::SerialPort and hal::open_pty (serial_port.hpp), as armfw's console transports and
// armctl's console client open them: a pty pair carries bytes both ways (raw: no echo,
// no CR/LF translation, Ctrl-X passes); bad paths and bad baud rates are refused naming them.
#include <poll.h>
#include <unistd.h>

#include <string>

#include "servoarm/console/transport.hpp"
#include "servoarm/hal/serial_port.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;

namespace {
bool has(const std::string& s, const std::string& p) { return s.find(p) != std::string::npos; }

/// Read what arrives on fd within `ms` (until `want` bytes).
std::string read_some(int fd, std::size_t want, int ms = 1000) {
  std::string got;
  for (int i = 0; i < ms / 10 && got.size() < want; ++i) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 10) > 0) {
      char b[256];
      const ssize_t r = ::read(fd, b, sizeof b);
      if (r > 0) got.append(b, static_cast<std::size_t>(r));
    }
  }
  return got;
}
}  // namespace

TEST_GROUP(SerialPort){};

TEST(SerialPort, PtyPairCarriesBytesBothWaysRaw) {
  hal::PtyPair pty;
  std::string e;
  CHECK_TEXT(hal::open_pty(pty, e) == hal::Status::ok, e.c_str());
  CHECK(pty.master.is_open() && pty.slave.is_open());
  CHECK_TEXT(pty.slave.path().rfind("/dev/pts/", 0) == 0, pty.slave.path().c_str());
  // A client opens the slave by its path, as armctl does: SerialPort, raw 8N1 at a baud rate.
  hal::SerialPort client;
  CHECK_TEXT(client.open(pty.slave.path(), 115200) == hal::Status::ok, client.message().c_str());
  CHECK(client.message().empty());
  const std::string to_fw = std::string("status\r\n?\x18!~") + '\0' + "\xff";
  CHECK(::write(client.fd(), to_fw.data(), to_fw.size()) == static_cast<ssize_t>(to_fw.size()));
  const std::string got = read_some(pty.master.fd(), to_fw.size());
  CHECK_EQUAL(to_fw.size(), got.size());
  CHECK(got == to_fw);  // byte for byte: no echo, no CR -> LF, Ctrl-X not a signal
  const std::string to_client = "ok state=idle\nalarm: x\r\n";
  CHECK(::write(pty.master.fd(), to_client.data(), to_client.size()) == static_cast<ssize_t>(to_client.size()));
  CHECK(read_some(client.fd(), to_client.size()) == to_client);
  // nothing echoed back to the client
  CHECK(read_some(client.fd(), 1, 50).empty());
  // non-blocking: a read with nothing there returns at once
  char b[8];
  CHECK(::read(pty.master.fd(), b, sizeof b) < 0);
  // release hands the descriptor over
  const int fd = client.release();
  CHECK(fd >= 0 && !client.is_open());
  ::close(fd);
}

TEST(SerialPort, BadPathAndBadBaudAreRefusedNamingThem) {
  hal::SerialPort p;
  CHECK(p.open("/dev/servoarm-no-such-tty", 115200) == hal::Status::io_error);
  CHECK_TEXT(has(p.message(), "/dev/servoarm-no-such-tty: "), p.message().c_str());
  CHECK(!p.is_open());
  CHECK(p.open("/dev/null", 115200) == hal::Status::io_error);  // exists, not a terminal
  CHECK_TEXT(has(p.message(), "/dev/null: not a terminal"), p.message().c_str());
  CHECK(!p.is_open());
  hal::PtyPair pty;
  std::string e;
  CHECK(hal::open_pty(pty, e) == hal::Status::ok);
  CHECK(p.open(pty.slave.path(), 12345) == hal::Status::invalid_argument);
  CHECK_TEXT(has(p.message(), pty.slave.path()) && has(p.message(), "unsupported baud rate 12345"), p.message().c_str());
  CHECK(!p.is_open());
  CHECK(p.open("", 115200) == hal::Status::invalid_argument);
  CHECK(hal::SerialPort::supported_baud(921600) && !hal::SerialPort::supported_baud(0));
  // every supported rate opens
  for (int baud : {9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600})
    CHECK_TEXT(p.open(pty.slave.path(), baud) == hal::Status::ok, (std::to_string(baud) + ": " + p.message()).c_str());
}

// The console transports open through it (armfw's --pty and --serial).
TEST(SerialPort, ConsoleTransportsOpenThroughHal) {
  fw::FdTransport pt;
  STRCMP_EQUAL("", fw::open_pty(pt).c_str());
  // no slave fd of armfw's own: a client's hang-up is seen (the pty has no client yet)
  CHECK(pt.rd >= 0 && pt.keep < 0 && pt.no_peer && pt.owns);
  CHECK(pt.path.rfind("/dev/pts/", 0) == 0);
  fw::FdTransport se;
  const std::string e = fw::open_serial(se, "/dev/servoarm-no-such-tty", 115200);
  CHECK_TEXT(has(e, "/dev/servoarm-no-such-tty: "), e.c_str());
  CHECK(se.rd < 0);
  const std::string b = fw::open_serial(se, pt.path, 1234);
  CHECK_TEXT(has(b, "unsupported baud rate 1234"), b.c_str());
  STRCMP_EQUAL("", fw::open_serial(se, pt.path, 57600).c_str());
  CHECK(se.rd >= 0 && se.path == pt.path);
  const std::string msg = "M114\n";
  CHECK(::write(se.wr, msg.data(), msg.size()) == 5);
  CHECK(read_some(pt.rd, msg.size()) == msg);
}
