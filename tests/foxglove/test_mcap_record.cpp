// SPDX-License-Identifier: Apache-2.0
// `record mcap` through the console and the service on a manual clock (every control cycle run
// by the test, the recorder polled after each: no scheduling in the way): every cycle at 1 kHz is
// a frame, every 10th at 100 Hz; files never overwrite one another; the size limit rotates
// and the file limit ends the recording; the file has MCAP's magic at both ends and its
// summary. The independent reader's checks (@mcap/core) are in foxglove_test.js.
#include <sys/stat.h>

#include <cstdint>
#include <string>
#include <vector>

#include <dirent.h>

#include "../console/console_rig.hpp"
#include "../program/tmp_dir.hpp"
#include "servoarm/service/arm_service.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;

namespace {

std::vector<std::string> files_in(const std::string& dir) {
  std::vector<std::string> out;
  if (DIR* d = ::opendir(dir.c_str())) {
    while (dirent* e = ::readdir(d))
      if (std::string(e->d_name).find(".mcap") != std::string::npos) out.push_back(dir + "/" + e->d_name);
    ::closedir(d);
  }
  return out;
}

const std::string kMagic("\x89MCAP0\r\n", 8);

struct Rig {
  std::string dir = test::make_tmp_dir();
  test::ConsoleRig r;
  ArmService& svc = r.app.console->service();
  Rig() {
    McapSettings s = svc.mcap_settings();
    s.dir = dir;
    s.threaded = false;  // the manual clock's cycles are polled by run(), the console's `record mcap` too
    svc.set_mcap_settings(s);
  }
  ~Rig() { test::remove_tree(dir); }
  void run(int cycles) {
    for (int i = 0; i < cycles; ++i) {
      r.cycle();
      svc.tick();
      svc.mcap_poll();
    }
  }
};

}  // namespace

TEST_GROUP(McapRecord){};

// At the control rate every cycle is a frame; at 100 Hz every 10th; nothing missed when the
// recorder sees every cycle.
TEST(McapRecord, EveryCycleIsAFrameAtTheControlRate) {
  for (const double rate : {1000.0, 100.0}) {
    Rig g;
    CHECK_EQUAL(std::string(""), g.svc.record_mcap_start(rate, false));
    g.run(5000);
    const McapStatus s = g.svc.record_mcap_stop();
    const std::uint64_t want = rate == 1000.0 ? 5000 : 500;
    CHECK_TEXT(s.frames >= want - 1 && s.frames <= want + 1, ("frames " + std::to_string(s.frames) + " at " + std::to_string(rate)).c_str());
    LONGS_EQUAL(0, s.missed);
    LONGS_EQUAL(1, s.files);
    const std::string f = test::read_file(s.file);
    CHECK(f.size() > 5000 * 100 / (rate == 1000.0 ? 1 : 10));
    CHECK(f.compare(0, 8, kMagic) == 0);
    CHECK(f.compare(f.size() - 8, 8, kMagic) == 0);  // closed: summary and footer written
  }
}

// A recorder that did not look for half a second (500 cycles at 1 kHz: its thread kept off the
// CPU) still writes every one of them: the control thread kept them in its sample ring.
TEST(McapRecord, CyclesARecorderDidNotLookAtAreStillWritten) {
  Rig g;
  CHECK_EQUAL(std::string(""), g.svc.record_mcap_start(1000, false));
  g.run(100);
  for (int i = 0; i < 500; ++i) g.r.cycle();
  g.run(100);
  const McapStatus s = g.svc.record_mcap_stop();
  LONGS_EQUAL(0, s.missed);
  CHECK_TEXT(s.frames >= 699 && s.frames <= 701, std::to_string(s.frames).c_str());
}

// Longer than the ring holds: the cycles it could not keep are counted as missed, never
// silently absent, and every cycle it kept is written.
TEST(McapRecord, CyclesBeyondTheRingAreCountedAsMissed) {
  Rig g;
  CHECK_EQUAL(std::string(""), g.svc.record_mcap_start(1000, false));
  g.run(100);
  const int unseen = static_cast<int>(Controller::kSampleRing) + 37;
  for (int i = 0; i < unseen; ++i) g.r.cycle();
  g.run(100);
  const McapStatus s = g.svc.record_mcap_stop();
  LONGS_EQUAL(37 + 1, s.missed);  // and run()'s first cycle, which comes before its first look
  const std::uint64_t want = 100 + Controller::kSampleRing + 99;
  CHECK_TEXT(s.frames + 1 >= want && s.frames <= want + 1, std::to_string(s.frames).c_str());
}

// At 100 Hz the ring carries only the cycles due: 20 s without a look (2 000 of them) lose none.
TEST(McapRecord, BelowTheControlRateTheRingHoldsOnlyTheCyclesDue) {
  Rig g;
  CHECK_EQUAL(std::string(""), g.svc.record_mcap_start(100, false));
  g.run(100);
  for (int i = 0; i < 20000; ++i) g.r.cycle();
  g.run(100);
  const McapStatus s = g.svc.record_mcap_stop();
  LONGS_EQUAL(0, s.missed);
  CHECK_TEXT(s.frames >= 2019 && s.frames <= 2021, std::to_string(s.frames).c_str());
}

// The console's command; a second recording is a new file; the old one is untouched.
TEST(McapRecord, TheConsoleRecordsAndNeverOverwrites) {
  Rig g;
  std::string a = g.r.cmd("record mcap rate=1000");
  CHECK_TEXT(a.rfind("ok recording MCAP at 1000 Hz to " + g.dir + "/servoarm-", 0) == 0, a.c_str());
  g.run(300);
  a = g.r.cmd("record mcap stop");
  CHECK_TEXT(a.rfind("ok recorded MCAP", 0) == 0 && a.find(" 0 missed") != std::string::npos, a.c_str());
  const std::vector<std::string> one = files_in(g.dir);
  LONGS_EQUAL(1, one.size());
  const std::string first = test::read_file(one[0]);
  a = g.r.cmd("record mcap");
  CHECK_TEXT(a.rfind("ok recording MCAP at 100 Hz", 0) == 0, a.c_str());  // record.rate_hz's default
  g.run(100);
  g.r.cmd("record mcap stop");
  LONGS_EQUAL(2, files_in(g.dir).size());
  CHECK(test::read_file(one[0]) == first);
  a = g.r.cmd("record mcap stop");
  CHECK_TEXT(a.rfind("error", 0) == 0 && a.find("no MCAP recording") != std::string::npos, a.c_str());
  a = g.r.cmd("record mcap rate=2000");
  CHECK_TEXT(a.find("outside (0, 1000]") != std::string::npos, a.c_str());
  a = g.r.cmd("record mcap rate=abc");
  CHECK_TEXT(a.rfind("error", 0) == 0, a.c_str());
}

// No folder configured: refused with the key's name; nothing starts.
TEST(McapRecord, WithoutAFolderItIsRefused) {
  test::ConsoleRig r;
  const std::string a = r.cmd("record mcap");
  CHECK_TEXT(a.find("record.dir") != std::string::npos, a.c_str());
  CHECK(!r.app.console->service().mcap_status().active);
}

// The size limit begins a new file; the file limit ends the recording, saying why.
TEST(McapRecord, RotationAndTheFileLimit) {
  Rig g;
  McapSettings s = g.svc.mcap_settings();
  s.max_file_mb = 0.2;
  s.max_files = 3;
  s.chunk_kb = 16;
  g.svc.set_mcap_settings(s);
  CHECK_EQUAL(std::string(""), g.svc.record_mcap_start(1000, false));
  g.run(10000);  // about 0.35 MB a second at 1 kHz: past three files of 0.2 MB
  const McapStatus st = g.svc.mcap_status();
  CHECK(!st.active);
  CHECK_TEXT(st.error.find("record.max_files") != std::string::npos, st.error.c_str());
  const std::vector<std::string> fs = files_in(g.dir);
  LONGS_EQUAL(3, fs.size());
  for (const std::string& f : fs) {
    const std::string b = test::read_file(f);
    CHECK_TEXT(b.size() >= 200000 && b.size() < 260000, (f + ": " + std::to_string(b.size())).c_str());
    CHECK(b.compare(b.size() - 8, 8, kMagic) == 0);
  }
}
