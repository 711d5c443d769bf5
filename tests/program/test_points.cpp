// SPDX-License-Identifier: Apache-2.0
// Teach points and the points file (firmware/program/points.hpp): round trip, atomic
// replace, corrupt / foreign / wrong files refused with the line named and never overwritten.
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <string>

#include "servoarm/kinematics/description.hpp"
#include "servoarm/kinematics/orientation.hpp"
#include "servoarm/program/points.hpp"
#include "tmp_dir.hpp"

// CppUTest last: its leak detector redefines new.
#include <CppUTest/TestHarness.h>

using namespace servoarm;
using servoarm::test::make_tmp_dir;
using servoarm::test::read_file;
using servoarm::test::remove_tree;
using servoarm::test::write_file;

namespace {

prog::TeachPoint point(const std::string& name, double base) {
  prog::TeachPoint p;
  p.name = name;
  p.q = kin::JointVector::Zero(6);
  for (int j = 0; j < 6; ++j) p.q[j] = base + 0.1 * j + 1.0 / 3.0;  // not short decimals: exact round trip is tested
  p.pose = kin::Pose::Identity();
  p.pose.translation() = Eigen::Vector3d(0.4 + base, -0.1, 0.3);
  p.pose.linear() = kin::rotation_from_rpy(0.3, -0.2, 1.1);
  p.tool = "gripper";
  p.frame = "g54";
  return p;
}

const char* kGood =
    "format = \"servoarm-points-1\"\n"
    "[point.pick]\n"
    "joints = [0.0, 0.5, 1.0, 0.0, 0.5, 0.0]\n"
    "xyz = [0.4, 0.0, 0.2]\n"
    "rpy = [180.0, 0.0, 0.0]\n"
    "tool = \"tool0\"\n"
    "frame = \"base\"\n";

}  // namespace

TEST_GROUP(Points) {
  std::string dir;
  void setup() override {
    MemoryLeakWarningPlugin::saveAndDisableNewDeleteOverloads();
    dir = make_tmp_dir();
  }
  void teardown() override {
    remove_tree(dir);
    std::string().swap(dir);  // allocated with the leak detector off: freed with it off
    MemoryLeakWarningPlugin::restoreNewDeleteOverloads();
  }
};

TEST(Points, RoundTripIsExact) {
  prog::PointsData d;
  STRCMP_EQUAL("", prog::put_point(d, point("pick", 0.0)).c_str());
  STRCMP_EQUAL("", prog::put_point(d, point("place_2", 0.5)).c_str());
  const std::string path = dir + "/points.toml";
  STRCMP_EQUAL("", prog::save_points_file(path, d).c_str());
  CHECK(read_file(path).find("format = \"servoarm-points-1\"") != std::string::npos);
  prog::PointsData back;
  bool missing = true;
  STRCMP_EQUAL("", prog::load_points_file(path, 6, back, &missing).c_str());
  CHECK_FALSE(missing);
  LONGS_EQUAL(2, back.points.size());
  for (std::size_t i = 0; i < 2; ++i) {
    const prog::TeachPoint& a = d.points[i];
    const prog::TeachPoint& b = back.points[i];
    STRCMP_EQUAL(a.name.c_str(), b.name.c_str());
    for (int j = 0; j < 6; ++j) DOUBLES_EQUAL(a.q[j], b.q[j], 0.0);  // %.17g: bit-exact
    CHECK((a.pose.translation() - b.pose.translation()).norm() == 0.0);
    CHECK((a.pose.linear() - b.pose.linear()).norm() < 1e-14);  // via rpy in degrees
    STRCMP_EQUAL("gripper", b.tool.c_str());
    STRCMP_EQUAL("g54", b.frame.c_str());
  }
}

TEST(Points, PutReplacesDeleteRemovesFindFinds) {
  prog::PointsData d;
  prog::put_point(d, point("a", 0.0));
  prog::put_point(d, point("b", 0.1));
  prog::put_point(d, point("a", 0.7));  // same name: replaced in place
  LONGS_EQUAL(2, d.points.size());
  DOUBLES_EQUAL(0.7 + 1.0 / 3.0, prog::find_point(d, "a")->q[0], 1e-15);
  CHECK(prog::find_point(d, "A") == nullptr);  // names are case-sensitive
  CHECK(prog::delete_point(d, "a"));
  CHECK_FALSE(prog::delete_point(d, "a"));
  LONGS_EQUAL(1, d.points.size());
}

TEST(Points, BadNamesAndValuesRefused) {
  prog::PointsData d;
  for (const char* bad : {"", "1abc", "a b", "a/b", "delete", "x234567890123456789012345678901234"}) {
    prog::TeachPoint p = point(bad, 0.0);
    CHECK_TEXT(!prog::put_point(d, p).empty(), bad);
  }
  prog::TeachPoint p = point("nan", 0.0);
  p.q[2] = std::nan("");
  CHECK(prog::put_point(d, p).find("joint 3") != std::string::npos);
  LONGS_EQUAL(0, d.points.size());
}

TEST(Points, MissingFileIsEmpty) {
  prog::PointsData d;
  bool missing = false;
  STRCMP_EQUAL("", prog::load_points_file(dir + "/none.toml", 6, d, &missing).c_str());
  CHECK(missing);
  LONGS_EQUAL(0, d.points.size());
}

TEST(Points, CorruptForeignAndBadEntriesRefusedWithTheLine) {
  struct Case {
    const char* text;
    const char* expect;  // in the message
  } cases[] = {
      {"format = \"servoarm-points-1\"\n[point.pick\n", ":2:"},                       // not TOML: line 2
      {"title = \"my notes\"\n", "not a servoarm points file"},                       // foreign
      {"format = \"servoarm-frames-1\"\n", "not a servoarm points file"},             // the frames file
      {"format = \"servoarm-points-1\"\n[point.p]\njoints = [0, 0, 0]\nxyz = [0, 0, 0]\nrpy = [0, 0, 0]\n", ":3:"},  // 3 of 6 joints
      {"format = \"servoarm-points-1\"\n[point.p]\njoints = [0, 0, 0, 0, 0, \"x\"]\nxyz = [0,0,0]\nrpy = [0,0,0]\n", ":3:"},
      {"format = \"servoarm-points-1\"\n[point.p]\njoints = [0, 0, 0, 0, 0, 0]\nxyz = [0,0,0]\n", "needs xyz"},
      {"format = \"servoarm-points-1\"\n[point.p]\njoints = [0, 0, 0, 0, 0, 0]\nxyz = [0,0,0]\nrpy = [0,0,0]\ncolour = 1\n", ":6:"},
      {"format = \"servoarm-points-1\"\n[point.9p]\njoints = [0, 0, 0, 0, 0, 0]\nxyz = [0,0,0]\nrpy = [0,0,0]\n", "letters"},
      {"format = \"servoarm-points-1\"\n[point.p]\njoints = [0, 0, 0, 0, 0, 1e9]\nxyz = [0,0,0]\nrpy = [0,0,0]\n", "joint 6"},
      {"format = \"servoarm-points-1\"\n[point.p]\njoints = [0, 0, 0, 0, 0, 0]\nxyz = [0,0,99]\nrpy = [0,0,0]\n", "beyond"},
      {"\x7f\x45LF\x01\x01\x00\x00garbage", ""},
  };
  for (const Case& c : cases) {
    const std::string path = dir + "/points.toml";
    write_file(path, c.text);
    prog::PointsData d;
    d.points.push_back(point("keep", 0.0));
    const std::string e = prog::load_points_file(path, 6, d);
    CHECK_TEXT(!e.empty(), c.text);
    CHECK_TEXT(e.find(c.expect) != std::string::npos, (e + " / expected " + c.expect).c_str());
    CHECK_TEXT(e.find('\n') == std::string::npos, e.c_str());  // one line
    LONGS_EQUAL(1, d.points.size());                            // untouched on failure
    // ... and never overwritten: saving over it is refused, the file stays as it was
    prog::PointsData fresh;
    prog::put_point(fresh, point("new", 0.2));
    const std::string se = prog::save_points_file(path, fresh);
    CHECK_TEXT(!se.empty(), c.text);
    CHECK_TEXT(se.find("not overwritten") != std::string::npos, se.c_str());
    STRCMP_EQUAL(c.text, read_file(path).c_str());
  }
}

TEST(Points, GoodFileLoadsAndAnUnwritableFolderKeepsTheOldFile) {
  const std::string path = dir + "/points.toml";
  write_file(path, kGood);
  prog::PointsData d;
  STRCMP_EQUAL("", prog::load_points_file(path, 6, d).c_str());
  LONGS_EQUAL(1, d.points.size());
  DOUBLES_EQUAL(0.5, d.points[0].q[1], 0.0);
  // The folder read-only: the write fails, the error names the file, the old file is kept.
  if (::geteuid() != 0) {  // root ignores the mode bits
    std::system(("chmod a-w '" + dir + "'").c_str());
    prog::put_point(d, point("more", 0.1));
    const std::string e = prog::save_points_file(path, d);
    std::system(("chmod u+w '" + dir + "'").c_str());
    CHECK(e.find(path) != std::string::npos);
    STRCMP_EQUAL(kGood, read_file(path).c_str());
  }
  // A path inside a missing folder: the same (nothing written, the error names it).
  const std::string e2 = prog::save_points_file(dir + "/no/such/points.toml", d);
  CHECK(e2.find("/no/such/points.toml") != std::string::npos);
}

TEST(Points, AReadOnlyPointsFileIsNeverReplaced) {
  // The atomic write (temporary file, rename) would replace a 0444 file with a writable
  // one, and root passes any access check: the file's mode bits are what decide.
  const std::string path = dir + "/points.toml";
  write_file(path, kGood);
  ::chmod(path.c_str(), 0444);
  prog::PointsData d;
  STRCMP_EQUAL("", prog::load_points_file(path, 6, d).c_str());
  prog::put_point(d, point("more", 0.1));
  const std::string e = prog::save_points_file(path, d);
  CHECK_TEXT(e.find(path) != std::string::npos && e.find("read-only") != std::string::npos, e.c_str());
  STRCMP_EQUAL(kGood, read_file(path).c_str());
  struct stat st {};
  CHECK(::stat(path.c_str(), &st) == 0);
  LONGS_EQUAL(0444, st.st_mode & 0777);
  ::chmod(path.c_str(), 0644);
}

TEST(Points, PoseMismatchAgainstTheDescription) {
  const kin::LoadResult r = kin::load_robot("puma560");
  CHECK(r.ok);
  prog::TeachPoint p = point("x", 0.0);
  kin::JointVector q = kin::JointVector::Zero(6);
  q << 0.1, -0.4, 0.9, 0.2, 0.5, -0.3;
  p.q = q;
  kin::forward(r.chain, q, p.pose);
  DOUBLES_EQUAL(0.0, prog::point_pose_mismatch(r.chain, kin::Pose::Identity(), p), 1e-12);
  p.pose.translation().x() += 0.01;  // a description changed by 10 mm
  DOUBLES_EQUAL(0.01, prog::point_pose_mismatch(r.chain, kin::Pose::Identity(), p), 1e-12);
}
