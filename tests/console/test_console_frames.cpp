// SPDX-License-Identifier: Apache-2.0
// Named tools and user frames: `tool`, `frame`, G54..G59, G10 L2, the frames
// file. Every expected pose is computed here from the chain's own FK and the offsets
// typed (TCP = FK(q) * tool, pose in a frame = frame^-1 * pose in the base), never read
// back from the console's code.
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "console_rig.hpp"
#include "servoarm/lang/frames.hpp"
#include "servoarm/kinematics/orientation.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;
using test::answer_ok;

namespace {
constexpr double kDeg = M_PI / 180.0;
bool has(const std::string& s, const std::string& p) { return s.find(p) != std::string::npos; }

kin::Pose pose_of(double x_mm, double y_mm, double z_mm, double rx, double ry, double rz) {
  kin::Pose p = kin::Pose::Identity();
  p.translation() = Eigen::Vector3d(x_mm, y_mm, z_mm) * 1e-3;
  p.linear() = kin::rotation_from_rpy(rx * kDeg, ry * kDeg, rz * kDeg);
  return p;
}

/// The value of `key=` in an answer (x=, y=, ...), NAN when absent.
double field(const std::string& a, const std::string& key) {
  std::size_t p = a.find(" " + key + "=");
  if (p == std::string::npos) p = a.find("[" + key + "=");  // status: pose=[x=...
  if (p == std::string::npos) return NAN;
  return std::strtod(a.c_str() + p + key.size() + 2, nullptr);
}
Eigen::Vector3d xyz_m(const std::string& a) { return Eigen::Vector3d(field(a, "x"), field(a, "y"), field(a, "z")) * 1e-3; }

std::string temp_path(const char* what) {
  return "/tmp/servoarm_frames_" + std::to_string(getpid()) + "_" + what + ".toml";
}
std::string read_all(const std::string& path) {
  std::ifstream f(path);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

struct FramesRig : test::ConsoleRig {
  explicit FramesRig(fw::FwConfig cfg = {}) : test::ConsoleRig(cfg) {}
  kin::JointVector q() const {
    const Telemetry t = app.ctl->telemetry();
    kin::JointVector v(6);
    for (int j = 0; j < 6; ++j) v[j] = t.q_cmd[static_cast<std::size_t>(j)];
    return v;
  }
  kin::Pose flange() const {
    kin::Pose p;
    kin::forward(app.chain, q(), p);
    return p;
  }
  /// The flange at the measured joints (what fk / status / M114 report without joints).
  kin::Pose flange_measured() const {
    const Telemetry t = app.ctl->telemetry();
    kin::JointVector v(6);
    for (int j = 0; j < 6; ++j) v[j] = t.q_act[static_cast<std::size_t>(j)];
    kin::Pose p;
    kin::forward(app.chain, v, p);
    return p;
  }
  ArmState state() const { return app.ctl->telemetry().state; }
  void working_pose() {
    enable();
    CHECK(answer_ok(cmd("movej 20 -40 160 10 -50 30")));
    CHECK(answer_ok(cmd("wait")));
  }
  std::vector<kin::JointVector> run_to_idle(int max_cycles) {
    std::vector<kin::JointVector> tr;
    for (int i = 0; i < max_cycles; ++i) {  // a queued move starts at the next cycle
      cycle();
      tr.push_back(q());
      if (i >= 2 && state() == ArmState::idle && app.ctl->telemetry().queued == 0) break;
    }
    return tr;
  }
};

fw::FwConfig with_frames_file(const std::string& path) {
  fw::FwConfig c;
  c.console_frames_file = path;
  return c;
}
}  // namespace

TEST_GROUP(ConsoleFrames){};

TEST(ConsoleFrames, ATcpOffsetMovesTheReportedPointAndTheLinearMovesPoint) {
  FramesRig r;
  r.working_pose();
  const std::string f0 = r.cmd("fk");
  CHECK_TEXT(has(f0, "tool=tool0 frame=base"), f0.c_str());
  CHECK_TEXT(answer_ok(r.cmd("tool grip 10 -20 150 0 90 0 mass=1.5 com=0,0,60")), r.s.out.c_str());
  std::string a = r.cmd("fk");
  CHECK_TEXT(has(a, "tool=tool0"), a.c_str());  // defined, not selected
  a = r.cmd("tool grip");
  CHECK_TEXT(answer_ok(a) && has(a, "tool=grip"), a.c_str());
  const kin::Pose T = pose_of(10, -20, 150, 0, 90, 0);
  const kin::Pose want = r.flange_measured() * T;
  a = r.cmd("fk");
  CHECK_TEXT(has(a, "tool=grip frame=base"), a.c_str());
  CHECK_TEXT((xyz_m(a) - want.translation()).norm() < 2e-6, a.c_str());  // printed to 1e-3 mm
  const Eigen::Vector3d rpy = kin::rpy_from_rotation(want.linear()) / kDeg;
  CHECK_TEXT(std::fabs(field(a, "rx") - rpy.x()) < 2e-3 && std::fabs(field(a, "rz") - rpy.z()) < 2e-3, a.c_str());
  a = r.cmd("status");
  CHECK_TEXT(has(a, "tool=grip frame=base") && (xyz_m(a) - (r.flange_measured() * T).translation()).norm() < 2e-6, a.c_str());
  a = r.cmd("M114");
  CHECK_TEXT(std::fabs(std::strtod(a.c_str() + a.find("X:") + 2, nullptr) * 1e-3 - want.translation().x()) < 2e-6, a.c_str());

  // A pure rotation about the tool point: the TCP stays put (checked on every sample with
  // the chain's FK and the offset), while the flange swings around it.
  // (from the commanded joints, where the move starts; the measured ones lag by ~1e-3 deg)
  const kin::Pose start = r.flange() * T;
  const Eigen::Vector3d p = start.translation() * 1e3;
  const Eigen::Vector3d rpy0 = kin::rpy_from_rotation(start.linear()) / kDeg;
  char line[160];
  std::snprintf(line, sizeof line, "movel %.6f %.6f %.6f %.6f %.6f %.6f speed=50", p.x(), p.y(), p.z(), rpy0.x() + 15,
                rpy0.y() - 10, rpy0.z() + 20);
  a = r.cmd(line);
  CHECK_TEXT(answer_ok(a), a.c_str());
  const auto tr = r.run_to_idle(40000);
  double tcp_off = 0, flange_moved = 0;
  for (const auto& qk : tr) {
    kin::Pose fk;
    kin::forward(r.app.chain, qk, fk);
    tcp_off = std::fmax(tcp_off, ((fk * T).translation() - start.translation()).norm());
    flange_moved = std::fmax(flange_moved, (fk.translation() - (start * T.inverse()).translation()).norm());
  }
  CHECK_TEXT(tcp_off < 2e-6, std::to_string(tcp_off).c_str());
  CHECK_TEXT(flange_moved > 0.02, std::to_string(flange_moved).c_str());
  // `ik` answers for the tool point: its joints put the TCP there.
  std::snprintf(line, sizeof line, "ik %.6f %.6f %.6f %.6f %.6f %.6f", p.x(), p.y(), p.z(), rpy0.x(), rpy0.y(), rpy0.z());
  a = r.cmd(line);
  CHECK_TEXT(answer_ok(a) && has(a, "tool=grip"), a.c_str());
  kin::JointVector qi(6);
  const char* at = a.c_str() + a.find("joints=[") + 8;
  for (int j = 0; j < 6; ++j) qi[j] = std::strtod(at, const_cast<char**>(&at)) * kDeg;
  kin::Pose fi;
  kin::forward(r.app.chain, qi, fi);
  CHECK_TEXT(((fi * T).translation() - start.translation()).norm() < 1e-4, a.c_str());  // joints printed to 1e-3 deg
  CHECK(r.app.ctl->telemetry().cause == FaultCause::none);
}

TEST(ConsoleFrames, TargetsAndReportsAreInTheActiveUserFrame) {
  FramesRig r;
  r.working_pose();
  CHECK_TEXT(answer_ok(r.cmd("frame table 300 -200 50 0 0 90")), r.s.out.c_str());
  CHECK_TEXT(answer_ok(r.cmd("frame table")), r.s.out.c_str());
  const kin::Pose F = pose_of(300, -200, 50, 0, 0, 90);
  std::string a = r.cmd("fk");
  const Eigen::Vector3d in_frame = (F.inverse() * r.flange_measured()).translation();
  CHECK_TEXT(has(a, "frame=table") && (xyz_m(a) - in_frame).norm() < 2e-6, a.c_str());
  // movel to a point given in the frame ends at F * point in the base
  const Eigen::Vector3d goal_f = in_frame + Eigen::Vector3d(0.02, 0.01, -0.015);
  char line[160];
  std::snprintf(line, sizeof line, "movel %.4f %.4f %.4f", goal_f.x() * 1e3, goal_f.y() * 1e3, goal_f.z() * 1e3);
  CHECK_TEXT(answer_ok(r.cmd(line)), r.s.out.c_str());
  r.run_to_idle(40000);
  CHECK(((r.flange().translation()) - F * goal_f).norm() < 1e-6);
  // a tool jog along the user frame's x: along the base's y (the frame is turned 90 deg about z)
  const Eigen::Vector3d before = r.flange().translation();
  CHECK_TEXT(answer_ok(r.cmd("jog x +10 frame=user")), r.s.out.c_str());
  r.run_to_idle(20000);
  const Eigen::Vector3d d = r.flange().translation() - before;
  CHECK_TEXT((d - F.linear().col(0) * 0.010).norm() < 1e-7, std::to_string(d.norm()).c_str());
  CHECK(std::fabs(d.y() - 0.010) < 1e-7);
  // back to the base frame: the base's coordinates again
  CHECK(answer_ok(r.cmd("frame base")));
  a = r.cmd("fk");
  CHECK_TEXT(has(a, "frame=base") && (xyz_m(a) - r.flange_measured().translation()).norm() < 2e-6, a.c_str());
}

TEST(ConsoleFrames, G10L2SetsAWorkOffsetAndG54ToG59SelectOne) {
  FramesRig r;
  r.working_pose();
  CHECK_TEXT(answer_ok(r.cmd("G10 L2 P2 X100 Y-50 Z20")), r.s.out.c_str());  // G55
  std::string a = r.cmd("$#");
  CHECK_TEXT(has(a, "[G54:0.000,0.000,0.000]") && has(a, "[G55:100.000,-50.000,20.000]"), a.c_str());
  CHECK_TEXT(answer_ok(r.cmd("G55")), r.s.out.c_str());
  a = r.cmd("$G");
  CHECK_TEXT(has(a, " G55 "), a.c_str());
  const Eigen::Vector3d p = r.flange().translation();
  // G0 to the current point in G55 coordinates plus 10 mm in x: the base target is offset by G55
  char line[120];
  std::snprintf(line, sizeof line, "G0 X%.4f Y%.4f Z%.4f", (p.x() - 0.1) * 1e3 + 10, (p.y() + 0.05) * 1e3, (p.z() - 0.02) * 1e3);
  CHECK_TEXT(answer_ok(r.cmd(line)), r.s.out.c_str());
  r.run_to_idle(40000);
  CHECK_TEXT(((r.flange().translation()) - (p + Eigen::Vector3d(0.010, 0, 0))).norm() < 1e-6,
             (std::to_string(((r.flange().translation()) - (p + Eigen::Vector3d(0.010, 0, 0))).norm()) + r.s.out).c_str());
  // G53 on a motion line: machine coordinates for that line only
  const Eigen::Vector3d q = r.flange().translation();
  std::snprintf(line, sizeof line, "G53 G0 X%.4f", q.x() * 1e3 - 5);
  CHECK_TEXT(answer_ok(r.cmd(line)), r.s.out.c_str());
  r.run_to_idle(40000);
  CHECK(std::fabs(r.flange().translation().x() - (q.x() - 0.005)) < 1e-6);
  // P0 sets the active one; axes not given are kept
  CHECK_TEXT(answer_ok(r.cmd("G10 L2 P0 Z30")), r.s.out.c_str());
  a = r.cmd("$#");
  CHECK_TEXT(has(a, "[G55:100.000,-50.000,30.000]"), a.c_str());
  // G10 L20: "zero here" - the tool point gets the given coordinates in frame g56
  CHECK_TEXT(answer_ok(r.cmd("G10 L20 P3 X0 Y0 Z10")), r.s.out.c_str());
  CHECK(answer_ok(r.cmd("G56")));
  {
    std::string l = "fk";  // at the commanded joints (L20 takes where the arm is commanded to be)
    char b[32];
    for (int j = 0; j < 6; ++j) std::snprintf(b, sizeof b, " %.9f", r.q()[j] / kDeg), l += b;
    a = r.cmd(l);
  }
  CHECK_TEXT(std::fabs(field(a, "x")) < 1e-6 && std::fabs(field(a, "y")) < 1e-6 && std::fabs(field(a, "z") - 10) < 1e-6 &&
                 has(a, "frame=g56"), a.c_str());
  CHECK(answer_ok(r.cmd("G55")));
  // the GRBL report gives the work position and the offset
  r.s.dialect = Dialect::grbl;
  a = r.app.console->grbl_report(r.s);
  CHECK_TEXT(has(a, "|WPos:") && has(a, "|WCO:100.000,-50.000,30.000|"), a.c_str());
  CHECK(answer_ok(r.cmd("G54")) || r.s.out == "ok\n");
  a = r.app.console->grbl_report(r.s);
  CHECK_TEXT(has(a, "|WPos:") && has(a, "|WCO:0.000,0.000,0.000|"), a.c_str());
}

TEST(ConsoleFrames, ChangingToolOrFrameWhileMovingIsRefusedAndTheMoveRunsOn) {
  FramesRig r;
  r.working_pose();
  CHECK(answer_ok(r.cmd("tool grip 0 0 100 0 0 0")));
  CHECK(answer_ok(r.cmd("movej 0 -30 150 0 -40 0 speed=20")));
  r.cycle();
  r.cycle();
  CHECK(r.state() == ArmState::moving);
  for (const char* l : {"tool grip", "tool grip 0 0 50 0 0 0", "frame f 1 2 3 0 0 0", "G10 L2 P1 X5", "G55", "tool delete grip"}) {
    const std::string a = r.cmd(l);
    CHECK_TEXT(has(a, "error: bad_state") && has(a, "refused while"), (std::string(l) + ": " + a).c_str());
  }
  r.run_to_idle(60000);
  const Telemetry t = r.app.ctl->telemetry();
  CHECK(std::fabs(t.q_cmd[1] + 30 * kDeg) < 1e-9);  // the move was not lost
  CHECK(has(r.cmd("fk"), "tool=tool0"));
}

TEST(ConsoleFrames, BadToolAndFrameInputIsAOneLineErrorAndChangesNothing) {
  FramesRig r;
  r.working_pose();
  CHECK(answer_ok(r.cmd("tool grip 0 0 100 0 0 0")));
  const std::string tools = r.cmd("tool"), frames = r.cmd("frame");
  struct Bad {
    const char* line;
    const char* code;
  };
  const Bad bad[] = {
      {"tool t1 0 0 nan 0 0 0", "error: not_finite"},
      {"tool t1 0 0 1e309 0 0 0", "error: not_finite"},
      {"tool t1 0 0 inf 0 0 0", "error: not_finite"},
      {"tool t1 1 2 3", "error: arg_count"},
      {"tool t1 1 2 3 4 5 6 7", "error: arg_count"},
      {"tool tool0 0 0 10 0 0 0", "error: bad_option"},
      {"tool 9x 0 0 10 0 0 0", "error: bad_option"},
      {"tool a.b 0 0 10 0 0 0", "error: bad_option"},
      {"tool t1 0 0 10 0 0 0 mass=-1", "error: out_of_range"},
      {"tool t1 0 0 10 0 0 0 com=1,2", "error: arg_count"},
      {"tool t1 0 0 10 0 0 0 com=1,2,3", "error: bad_option"},  // com without mass
      {"tool t1 0 0 10 0 0 0 mass=1e9", "error: out_of_range"},
      {"tool t1 0 0 20000000 0 0 0", "error: out_of_range"},   // 20 km
      {"tool t1 0 0 10 0 0 1000", "error: out_of_range"},       // 1000 deg
      {"tool t1 0 0 10 0 0 0 speed=5", "error: bad_option"},
      {"tool nosuch", "error: bad_option"},
      {"tool delete nosuch", "error: bad_option"},
      {"tool delete grip extra", "error: arg_count"},
      {"frame base 0 0 0 0 0 0", "error: bad_option"},
      {"frame f1 0 0 0 0 0 0 mass=1", "error: bad_option"},
      {"frame nosuch", "error: bad_option"},
      {"G10 L3 P1 X0", "error: unsupported"},
      {"G10 L20 P1 A5", "error: unsupported"},
      {"G10 L2 P7 X0", "error: out_of_range"},
      {"G10 L2 X0", "error: arg_count"},
      {"G10 P1 X0", "error: arg_count"},
      {"G10 L2 P1", "error: arg_count"},
      {"G10 L2 P0 X5", "error: bad_state"},  // the active frame is base
      {"G54 G0 X1", "error: unsupported"},
      {"G54 G55", "error: arg_count"},
      {"G1 X1 L2", "error: arg_count"},
  };
  for (const Bad& b : bad) {
    const std::string a = r.cmd(b.line);
    CHECK_TEXT(a.rfind(b.code, 0) == 0 && a.find('\n') == a.size() - 1, (std::string(b.line) + " -> " + a).c_str());
  }
  CHECK_EQUAL(tools, r.cmd("tool"));
  CHECK_EQUAL(frames, r.cmd("frame"));
  CHECK(r.state() == ArmState::idle);
}

TEST(ConsoleFrames, TheFramesFileKeepsToolsFramesAndTheSelectionAcrossARestart) {
  const std::string path = temp_path("keep");
  std::remove(path.c_str());
  kin::JointVector q0;
  std::string fk_before;
  {
    FramesRig r(with_frames_file(path));
    r.working_pose();
    CHECK(answer_ok(r.cmd("tool grip 1.5 -2.25 123.456 10 20 30 mass=0.75 com=0,0,40")));
    CHECK(answer_ok(r.cmd("frame table 400 -100 25 0 0 -45")));
    CHECK(answer_ok(r.cmd("tool grip")));
    CHECK(answer_ok(r.cmd("frame table")));
    q0 = r.q();
    std::string l = "fk";
    char b[32];
    for (int j = 0; j < 6; ++j) std::snprintf(b, sizeof b, " %.9f", q0[j] / kDeg), l += b;
    fk_before = r.cmd(l);
    struct stat st{};
    CHECK(::stat((path + ".tmp").c_str(), &st) != 0);  // the temporary was renamed
  }
  const std::string text = read_all(path);
  CHECK_TEXT(has(text, "format = \"servoarm-frames-1\"") && has(text, "[tool.grip]") && has(text, "mass = 0.75"), text.c_str());
  FramesData d;
  CHECK_EQUAL(std::string(""), load_frames_file(path, d));
  CHECK_EQUAL(std::string("grip"), d.active_tool);
  CHECK(d.tools.size() == 1 && (d.tools[0].pose.translation() - Eigen::Vector3d(1.5e-3, -2.25e-3, 0.123456)).norm() < 1e-15);
  CHECK((d.tools[0].pose.linear() - kin::rotation_from_rpy(10 * kDeg, 20 * kDeg, 30 * kDeg)).norm() < 1e-14);
  {
    FramesRig r(with_frames_file(path));
    CHECK_EQUAL(std::string("grip"), r.app.console->active_tool());
    CHECK_EQUAL(std::string("table"), r.app.console->active_frame());
    const std::string fk = r.cmd([&] {
      std::string l = "fk";
      char b[32];
      for (int j = 0; j < 6; ++j) std::snprintf(b, sizeof b, " %.9f", q0[j] / kDeg), l += b;
      return l;
    }());
    CHECK_TEXT(xyz_m(fk).isApprox(xyz_m(fk_before), 1e-9) && has(fk, "tool=grip frame=table"), (fk + fk_before).c_str());
    CHECK(answer_ok(r.cmd("tool tool0")));
    CHECK(answer_ok(r.cmd("tool delete grip")));
  }
  CHECK(!has(read_all(path), "[tool.grip]"));
  std::remove(path.c_str());
}

TEST(ConsoleFrames, ABadOrForeignFramesFileIsRefusedAtStartAndNeverOverwritten) {
  struct Case {
    const char* text;
    const char* names;  // in the error
  };
  const Case cases[] = {
      {"robot = \"puma560\"\n", "not a servoarm frames file"},
      {"format = \"servoarm-frames-1\"\n[tool.grip]\nxyz = [0, 0, 0.1]\n", "tool.grip: needs both xyz"},
      {"format = \"servoarm-frames-1\"\n[tool.grip]\nxyz = [0, 0]\nrpy = [0, 0, 0]\n", ":3:"},
      {"format = \"servoarm-frames-1\"\n[tool.grip]\nxyz = [0, 0, nan]\nrpy = [0, 0, 0]\n", "tool.grip.xyz[2]"},
      {"format = \"servoarm-frames-1\"\n[tool.grip]\nxyz = [0, 0, 0]\nrpy = [0, 0, 0]\nmass = -2\n", "mass"},
      {"format = \"servoarm-frames-1\"\n[frame.base]\nxyz = [0, 0, 0]\nrpy = [0, 0, 0]\n", "base is the base frame"},
      {"format = \"servoarm-frames-1\"\nactive_tool = \"nosuch\"\n", "active_tool"},
      {"format = \"servoarm-frames-1\"\n[tool.grip]\nxyz = [0, 0, 0]\nrpy = [0, 0, 0]\ncolour = 3\n", "unknown key"},
      {"format = \"servoarm-frames-1\"\n[tool\n", "not valid TOML"},
  };
  const std::string path = temp_path("bad");
  for (const Case& c : cases) {
    {
      std::ofstream f(path);
      f << c.text;
    }
    test::SimApp app;
    hal::ManualClock clock;
    fw::FwConfig cfg = with_frames_file(path);
    cfg.can = "sim";
    const std::string e = app.build(cfg, &clock);
    CHECK_TEXT(has(e, "frames file refused: " + path) && has(e, c.names) && e.find('\n') == std::string::npos,
               (std::string(c.text) + " -> " + e).c_str());
    CHECK_EQUAL(std::string(c.text), read_all(path));
  }
  std::remove(path.c_str());
  // a frames file that cannot be written: the definition is not made, the old file stays
  FramesRig r(with_frames_file("/nonexistent-dir-servoarm/frames.toml"));
  const std::string a = r.cmd("tool grip 0 0 100 0 0 0");
  CHECK_TEXT(a.rfind("error: storage tool not defined: /nonexistent-dir-servoarm/frames.toml", 0) == 0, a.c_str());
  CHECK(!has(r.cmd("tool"), "grip"));
}

TEST(ConsoleFrames, AFramesFileReplacedWhileRunningOrMadeReadOnlyIsNeverOverwritten) {
  const std::string path = temp_path("replaced");
  std::remove(path.c_str());
  FramesRig r(with_frames_file(path));
  CHECK(answer_ok(r.cmd("tool grip 0 0 100 0 0 0")));
  CHECK(has(read_all(path), "[tool.grip]"));
  // Another program puts its own file in place (a new file renamed over ours).
  const char* foreign = "# someone else's settings\nspeed = 3\n";
  {
    std::ofstream f(path + ".other");
    f << foreign;
  }
  CHECK(std::rename((path + ".other").c_str(), path.c_str()) == 0);
  std::string a = r.cmd("tool probe 0 0 50 0 0 0");
  CHECK_TEXT(a.rfind("error: storage tool not defined: " + path, 0) == 0 && has(a, "not a servoarm frames file") &&
                 a.find('\n') == a.size() - 1,
             a.c_str());
  CHECK_EQUAL(std::string(foreign), read_all(path));
  CHECK(!has(r.cmd("tool"), "probe"));
  a = r.cmd("frame table 400 0 0 0 0 0");
  CHECK_TEXT(a.rfind("error: storage frame not set: " + path, 0) == 0, a.c_str());
  CHECK_EQUAL(std::string(foreign), read_all(path));
  // Our own file, made read-only by its owner: refused, the file and its mode stay.
  {
    std::ofstream f(path);
    f << "format = \"servoarm-frames-1\"\n";
  }
  CHECK(::chmod(path.c_str(), 0444) == 0);
  a = r.cmd("tool probe 0 0 50 0 0 0");
  CHECK_TEXT(a.rfind("error: storage tool not defined: " + path, 0) == 0 && has(a, "read-only") &&
                 a.find('\n') == a.size() - 1,
             a.c_str());
  CHECK_EQUAL(std::string("format = \"servoarm-frames-1\"\n"), read_all(path));
  struct stat st{};
  CHECK(::stat(path.c_str(), &st) == 0 && (st.st_mode & 0777) == 0444);
  CHECK(!has(r.cmd("tool"), "probe"));
  // Writable again: the definition is made.
  CHECK(::chmod(path.c_str(), 0644) == 0);
  CHECK(answer_ok(r.cmd("tool probe 0 0 50 0 0 0")));
  CHECK(has(read_all(path), "[tool.probe]"));
  std::remove(path.c_str());
}
