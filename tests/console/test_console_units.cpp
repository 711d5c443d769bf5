// SPDX-License-Identifier: Apache-2.0
// The console's units (units.hpp): the command language follows ConsoleConfig::units
// (the robot description's: mm or m, deg or rad); G-code keeps G20/G21 and degrees.
// Here the puma560 console runs in metres and radians.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>

#include "console_rig.hpp"
#include "servoarm/kinematics/orientation.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;
using test::answer_ok;

namespace {
constexpr double kDeg = M_PI / 180.0;
bool has(const std::string& s, const std::string& p) { return s.find(p) != std::string::npos; }

/// A rig whose console speaks metres and radians.
struct SiRig : test::ConsoleRig {
  SiRig() {
    ConsoleConfig cfg = app.console->config();
    cfg.units = {LengthUnit::m, AngleUnit::rad};
    app.console = std::make_unique<Console>(*app.ctl, cfg, app.ik_ready ? app.ik.get() : nullptr);
    app.console->set_idle([this] { cycle(); });
  }
  kin::JointVector q_cmd() const {
    const Telemetry t = app.ctl->telemetry();
    kin::JointVector q(6);
    for (int j = 0; j < 6; ++j) q[j] = t.q_cmd[static_cast<std::size_t>(j)];
    return q;
  }
};
}  // namespace

TEST_GROUP(ConsoleUnits){};

TEST(ConsoleUnits, ConversionTable) {
  const ConsoleUnits mm_deg{}, m_rad{LengthUnit::m, AngleUnit::rad};
  DOUBLES_EQUAL(0.25, mm_deg.length_in(250), 1e-15);
  DOUBLES_EQUAL(250, mm_deg.length_out(0.25), 1e-12);
  DOUBLES_EQUAL(90 * kDeg, mm_deg.angle_in(90), 0);
  DOUBLES_EQUAL(0.25, m_rad.length_in(0.25), 0);
  DOUBLES_EQUAL(1.5, m_rad.angle_out(1.5), 0);
  STRCMP_EQUAL("mm", mm_deg.length_name());
  STRCMP_EQUAL("rad", m_rad.angle_name());
  kin::Chain c;
  c.length_unit = 1e-3, c.angle_unit = kDeg;
  CHECK(units_of(c).length == LengthUnit::mm && units_of(c).angle == AngleUnit::deg);
  c.length_unit = 1.0, c.angle_unit = 1.0;
  CHECK(units_of(c).length == LengthUnit::m && units_of(c).angle == AngleUnit::rad);
}

TEST(ConsoleUnits, MetresAndRadiansEverywhereInTheCommandLanguage) {
  SiRig r;
  r.enable();
  // help and status say which units are in use
  const std::string help = r.cmd("help");
  CHECK_TEXT(has(help, "units: lengths m, angles rad") && answer_ok(help), help.c_str());
  // movej in radians
  const std::string mj = r.cmd("movej 0.349066 -0.698132 2.792527 0.174533 -0.872665 0.523599");
  CHECK_TEXT(answer_ok(mj), mj.c_str());
  CHECK(answer_ok(r.cmd("wait")));
  const kin::JointVector q = r.q_cmd();
  DOUBLES_EQUAL(0.349066, q[0], 1e-12);
  DOUBLES_EQUAL(2.792527, q[2], 1e-12);
  const std::string st = r.cmd("status");
  CHECK_TEXT(has(st, "joints=[0.349") && has(st, "] rad pose=[x="), st.c_str());  // measured: lags a little
  CHECK_TEXT(has(st, "] m,rad"), st.c_str());
  // fk / ik in metres and radians, round trip
  kin::Pose p;
  kin::forward(r.app.chain, q, p);
  const std::string fk = r.cmd("fk 0.349066 -0.698132 2.792527 0.174533 -0.872665 0.523599");
  char want[96];
  std::snprintf(want, sizeof want, "x=%.6f y=%.6f z=%.6f", p.translation().x(), p.translation().y(), p.translation().z());
  CHECK_TEXT(has(fk, want), fk.c_str());
  char ik[160];
  const Eigen::Vector3d rpy = kin::rpy_from_rotation(p.linear());
  std::snprintf(ik, sizeof ik, "ik %.9f %.9f %.9f %.9f %.9f %.9f", p.translation().x(), p.translation().y(), p.translation().z(),
                rpy[0], rpy[1], rpy[2]);
  const std::string ika = r.cmd(ik);
  CHECK_TEXT(has(ika, "joints=[0.349066 -0.698132 2.792527 0.174533 -0.872665 0.523599] rad"), ika.c_str());
  // limits: radians, metres per second
  const std::string lim = r.cmd("limits");
  CHECK_TEXT(has(lim, "joint 1: revolute [") && has(lim, "] rad  vmax=") && has(lim, " m/s, max "), lim.c_str());
  // movel in metres, speed in m/s: 0.009 m/s is a fine speed here (below 0.01 mm/s is not)
  const Eigen::Vector3d t = p.translation() + Eigen::Vector3d(0.02, -0.01, 0.01);
  char ml[160];
  std::snprintf(ml, sizeof ml, "movel %.9f %.9f %.9f speed=0.05", t.x(), t.y(), t.z());
  const std::string a = r.cmd(ml);
  CHECK_TEXT(answer_ok(a), a.c_str());
  CHECK(answer_ok(r.cmd("wait")));
  kin::Pose x;
  kin::forward(r.app.chain, r.q_cmd(), x);
  CHECK_TEXT((x.translation() - t).norm() < 1e-9, std::to_string((x.translation() - t).norm()).c_str());
  CHECK(kin::rotation_error(x.linear(), p.linear()).norm() < 1e-9);
  std::snprintf(ml, sizeof ml, "movel %.9f %.9f %.9f speed=0.009", p.translation().x(), p.translation().y(), p.translation().z());
  CHECK_TEXT(answer_ok(r.cmd(ml)), ml);
  CHECK(answer_ok(r.cmd("stop")));
  for (int i = 0; i < 3000 && r.app.ctl->telemetry().state != ArmState::idle; ++i) r.cycle();
  const std::string slow = r.cmd("movel 0.5 0.1 0.3 speed=0.000001");
  CHECK_TEXT(slow.rfind("error: out_of_range movel: speed=1e-06 m/s is below the minimum 1e-05 m/s", 0) == 0, slow.c_str());
  const std::string fast = r.cmd("movel 0.5 0.1 0.3 speed=2");
  CHECK_TEXT(fast.rfind("error: out_of_range linear speed 2 m/s outside [1e-05, 0.25]", 0) == 0, fast.c_str());
  // a joint outside its limits is named in radians
  const std::string out = r.cmd("movej 3.2 0 0 0 0 0");
  CHECK_TEXT(out.rfind("error: limits joint 1 = 3.200", 0) == 0, out.c_str());
  // G-code keeps G21 millimetres and degrees: G91 G1 Z-10 moves 10 mm down
  kin::forward(r.app.chain, r.q_cmd(), p);
  CHECK(answer_ok(r.cmd("G91")));
  CHECK(answer_ok(r.cmd("G1 Z-10 F600")));
  CHECK(answer_ok(r.cmd("G90")));
  CHECK(answer_ok(r.cmd("M400")));
  kin::forward(r.app.chain, r.q_cmd(), x);
  CHECK_TEXT(std::fabs(x.translation().z() - (p.translation().z() - 0.010)) < 1e-9, std::to_string(x.translation().z()).c_str());
  const std::string m114 = r.cmd("M114");
  const auto zp = m114.find(" Z:");
  CHECK_TEXT(zp != std::string::npos, m114.c_str());
  const double z_mm = std::atof(m114.c_str() + zp + 3);  // measured (q_act): within a following error
  CHECK_TEXT(std::fabs(z_mm - x.translation().z() * 1e3) < 0.5, m114.c_str());
}

TEST(ConsoleUnits, TheDefaultIsMillimetresAndDegrees) {
  test::ConsoleRig r;
  const std::string help = r.cmd("help");
  CHECK_TEXT(has(help, "units: lengths mm, angles deg"), help.c_str());
  const std::string st = r.cmd("status");
  CHECK_TEXT(has(st, "] deg pose=[x=") && has(st, "] mm,deg"), st.c_str());
}

// On an arm with a prismatic joint (the Stanford arm's joint 3) `status` names each joint's
// unit: the joints are not all angles.
TEST(ConsoleUnits, StatusNamesEachJointsUnitWhenOneIsPrismatic) {
  FwConfig c;
  c.robot = "stanford";
  test::ConsoleRig r(c);
  const std::string a = r.cmd("status");
  CHECK_TEXT(!has(a, "] deg pose=") && !has(a, "] rad pose="), a.c_str());
  CHECK_TEXT(has(a, "] deg,deg,m") || has(a, "] rad,rad,m"), a.c_str());
}
