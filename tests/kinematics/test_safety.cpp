// SPDX-License-Identifier: Apache-2.0
// The safety envelope's geometry (kinematics/include/servoarm/kinematics/safety.hpp):
//  - case tables for each function (plane, keep-in, keep-out, cone, speeds; tool and elbow
//    spheres), printing the failing case;
//  - seeded random sweeps against an independent reference: points spread over the sphere's
//    surface (a Fibonacci lattice) tested one by one against the half-space / the box;
//  - a straight path through a plane: the first violation is the first sample past the
//    analytic crossing;
//  - the configuration problems (NaN, zero normal, inverted box, keep-in smaller than the sphere);
//  - no heap in check_sample / check_path / safety_sample (and the checked build's EIGEN_NO_MALLOC).
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "../support/alloc_counter.hpp"
#include "../support/sweep.hpp"
#include "kin_test_util.hpp"
#include "servoarm/kinematics/safety.hpp"

using namespace servoarm;
using namespace servoarm::test;

namespace {

kin::SafetySample at(double x, double y, double z) {
  kin::SafetySample s;
  s.tcp.translation() = Eigen::Vector3d(x, y, z);
  s.elbow = Eigen::Vector3d(x, y, z);
  return s;
}

kin::SafetyConfig table_plane(double radius) {
  kin::SafetyConfig c;
  c.enabled = true;
  c.tool_radius = radius;
  c.plane_count = 1;
  c.planes[0].normal = Eigen::Vector3d(0, 0, 1);
  c.planes[0].offset = 0.1;  // the table top at z = 100 mm
  return c;
}

// Points on the unit sphere, spread evenly.
std::vector<Eigen::Vector3d> fibonacci(int n) {
  std::vector<Eigen::Vector3d> p;
  const double g = M_PI * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double z = 1.0 - 2.0 * (i + 0.5) / n, r = std::sqrt(1.0 - z * z);
    p.emplace_back(r * std::cos(g * i), r * std::sin(g * i), z);
  }
  // the six axis points, where a sphere first touches a face or an axis-aligned plane
  for (int a = 0; a < 3; ++a)
    for (double sgn : {-1.0, 1.0}) {
      Eigen::Vector3d e = Eigen::Vector3d::Zero();
      e[a] = sgn;
      p.push_back(e);
    }
  return p;
}

}  // namespace

TEST_GROUP(Safety){};

TEST(Safety, PlaneCaseTable) {
  struct Case { double z, radius; bool violated; double value; };
  const Case cases[] = {
      {0.20, 0.02, false, 0.18}, {0.1201, 0.02, false, 0.1001}, {0.1199, 0.02, true, 0.0999},
      {0.05, 0.00, true, 0.05},  {0.10, 0.00, false, 0.10}, {-1.0, 0.05, true, -1.05},
  };
  for (const Case& k : cases) {
    const kin::SafetyConfig c = table_plane(k.radius);
    kin::SafetyViolation v;
    const bool got = kin::check_sample(c, kin::SafetyMode::normal, at(0.3, -0.2, k.z), 0, 0, 0, v);
    char line[256];
    std::snprintf(line, sizeof line, "z=%g r=%g: expected %s", k.z, k.radius, k.violated ? "violation" : "none");
    CHECK_TEXT(got == k.violated, line);
    if (got) {
      CHECK_TEXT(v.function == kin::SafetyFunction::plane, line);
      CHECK_EQUAL(0, v.index);
      DOUBLES_EQUAL(0.1, v.limit, 1e-12);
      DOUBLES_EQUAL(k.value, v.value, 1e-12);
      DOUBLES_EQUAL(k.z, v.where.z(), 1e-12);
      CHECK(v.excess() > 0);
    }
  }
}

TEST(Safety, BoxCaseTable) {
  struct Case { bool keep_in; double x, y, z, radius; bool violated; double value; };
  // box [0, 1] x [0, 1] x [0, 1] m
  const Case cases[] = {
      {true, 0.5, 0.5, 0.5, 0.1, false, 0.5},  {true, 0.1, 0.5, 0.5, 0.1, false, 0.1},
      {true, 0.09, 0.5, 0.5, 0.1, true, 0.09}, {true, 0.5, 0.5, 0.95, 0.1, true, 0.05},
      {true, 1.5, 0.5, 0.5, 0.0, true, -0.5},  {false, 1.2, 0.5, 0.5, 0.1, false, 0.2},
      {false, 1.05, 0.5, 0.5, 0.1, true, 0.05}, {false, 0.5, 0.5, 0.6, 0.0, true, -0.4},
      {false, 1.1, 1.1, 0.5, 0.1, false, std::sqrt(0.02)}, {false, 1.06, 1.06, 0.5, 0.1, true, std::sqrt(0.0072)},
  };
  for (const Case& k : cases) {
    kin::SafetyConfig c;
    c.enabled = true;
    c.tool_radius = k.radius;
    c.box_count = 1;
    c.boxes[0] = {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1, 1, 1), k.keep_in, true};
    kin::SafetyViolation v;
    const bool got = kin::check_sample(c, kin::SafetyMode::normal, at(k.x, k.y, k.z), 0, 0, 0, v);
    char line[256];
    std::snprintf(line, sizeof line, "%s (%g, %g, %g) r=%g: expected %s", k.keep_in ? "keep-in" : "keep-out", k.x,
                  k.y, k.z, k.radius, k.violated ? "violation" : "none");
    CHECK_TEXT(got == k.violated, line);
    if (got) {
      CHECK_TEXT(v.function == (k.keep_in ? kin::SafetyFunction::keep_in : kin::SafetyFunction::keep_out), line);
      DOUBLES_EQUAL(k.radius, v.limit, 1e-12);
      DOUBLES_EQUAL(k.value, v.value, 1e-9);
    }
  }
}

// A box in a user frame is axis-aligned in that frame: a 100 x 20 x 20 mm keep-out box turned
// 45 deg about z and moved to (200, 100, 50) mm holds the points along its turned long axis and
// not those of the base-aligned box of the same size; values against the reference computed
// here in the box's frame.
TEST(Safety, BoxInAUserFrame) {
  kin::Pose f = kin::Pose::Identity();
  f.linear() = Eigen::AngleAxisd(M_PI / 4, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  f.translation() = Eigen::Vector3d(0.2, 0.1, 0.05);
  kin::SafetyConfig c;
  c.enabled = true;
  c.box_count = 1;
  c.boxes[0].min = Eigen::Vector3d(-0.05, -0.01, -0.01);
  c.boxes[0].max = Eigen::Vector3d(0.05, 0.01, 0.01);
  c.boxes[0].keep_in = false;
  c.boxes[0].frame = f;
  struct Case { double along, across; bool violated; };
  // (along, across): metres along the box's x and y axes from its centre
  const Case cases[] = {{0.04, 0.0, true}, {0.0, 0.009, true}, {0.06, 0.0, false}, {0.0, 0.02, false}, {-0.049, 0.0, true}};
  for (const Case& k : cases) {
    const Eigen::Vector3d p = f * Eigen::Vector3d(k.along, k.across, 0.0);
    kin::SafetyViolation v;
    const bool got = kin::check_sample(c, kin::SafetyMode::normal, at(p.x(), p.y(), p.z()), 0, 0, 0, v);
    char line[160];
    std::snprintf(line, sizeof line, "along %g across %g: expected %s", k.along, k.across, k.violated ? "violation" : "none");
    CHECK_TEXT(got == k.violated, line);
    if (got) {
      // inside: minus the clearance to the nearest face, in the box's frame
      const double clear = std::fmin(0.05 - std::fabs(k.along), 0.01 - std::fabs(k.across));
      DOUBLES_EQUAL_TEXT(-clear, v.value, 1e-9, line);
      CHECK_TEXT((v.where - p).norm() < 1e-12, line);  // where: the base frame
    }
  }
  // (0.24, 0.1, 0.05) is inside the base-aligned box of the same size there, outside the turned one
  kin::SafetyViolation v;
  CHECK(!kin::check_sample(c, kin::SafetyMode::normal, at(0.24, 0.1, 0.05), 0, 0, 0, v));
  c.boxes[0].frame.linear().setIdentity();
  CHECK(kin::check_sample(c, kin::SafetyMode::normal, at(0.24, 0.1, 0.05), 0, 0, 0, v));
  // a frame that is not a rotation is a configuration problem
  c.boxes[0].frame.linear() *= 2.0;
  char buf[160];
  STRCMP_CONTAINS("box 0: its frame is not a finite rotation", kin::safety_config_problem(c, buf, sizeof buf));
}

// A trigger plane switches the functions to Reduced mode while the tool sphere reaches beyond
// it (any part of it: n.c - r < offset) and restricts nothing: the mode at each height.
TEST(Safety, TriggerPlaneReducesWhileTheSphereReachesBeyond) {
  kin::SafetyConfig c;
  c.enabled = true;
  c.tool_radius = 0.02;
  c.trigger_count = 1;
  c.trigger_planes[0].normal = Eigen::Vector3d(0, 0, 1);
  c.trigger_planes[0].offset = 0.3;  // Reduced below z = 300 mm (the sphere's lowest point)
  c.normal.tcp_speed = 0.25;
  c.reduced.tcp_speed = 0.1;
  struct Case { double z; int plane; };
  const Case cases[] = {{0.5, -1}, {0.3201, -1}, {0.3199, 0}, {0.1, 0}};
  for (const Case& k : cases) {
    kin::SafetySample x = at(0.2, 0, k.z);
    char line[64];
    std::snprintf(line, sizeof line, "z=%g", k.z);
    LONGS_EQUAL_TEXT(k.plane, kin::trigger_plane(c, x), line);
    const kin::SafetyMode m = kin::effective_mode(c, kin::SafetyMode::normal, x);
    CHECK_TEXT(m == (k.plane >= 0 ? kin::SafetyMode::reduced : kin::SafetyMode::normal), line);
    CHECK_TEXT(kin::effective_mode(c, kin::SafetyMode::reduced, x) == kin::SafetyMode::reduced, line);
    // no position function: nothing is violated at rest, whatever the side
    kin::SafetyViolation v;
    CHECK_TEXT(!kin::check_sample(c, m, x, 0, 0, 0, v), line);
    // 200 mm/s: within Normal's 250, beyond Reduced's 100
    x.has_velocity = true;
    x.tcp_velocity = Eigen::Vector3d(0.2, 0, 0);
    CHECK_TEXT(kin::check_sample(c, m, x, 0, 0, 0, v) == (k.plane >= 0), line);
  }
}

TEST(Safety, ConeAndSpeedCaseTable) {
  kin::SafetyConfig c;
  c.enabled = true;
  c.cone = true;
  c.cone_axis = Eigen::Vector3d(0, 0, -1);  // tool pointing down
  c.normal = {0.25, 0.5, deg(30)};
  c.reduced = {0.1, 0.2, deg(10)};
  struct Case { double tilt_deg; double v_tcp; kin::SafetyMode mode; kin::SafetyFunction expected; };
  const Case cases[] = {
      {180, 0.0, kin::SafetyMode::normal, kin::SafetyFunction::none},
      {0, 0.0, kin::SafetyMode::normal, kin::SafetyFunction::orientation},  // pointing up
      {180 - 25, 0.0, kin::SafetyMode::normal, kin::SafetyFunction::none},  // z axis 25 deg from down
      {180 - 35, 0.0, kin::SafetyMode::normal, kin::SafetyFunction::orientation},
      {180 - 25, 0.0, kin::SafetyMode::reduced, kin::SafetyFunction::orientation},
      {180, 0.24, kin::SafetyMode::normal, kin::SafetyFunction::none},
      {180, 0.26, kin::SafetyMode::normal, kin::SafetyFunction::tcp_speed},
      {180, 0.11, kin::SafetyMode::reduced, kin::SafetyFunction::tcp_speed},
  };
  for (const Case& k : cases) {
    kin::SafetySample s = at(0.4, 0, 0.3);
    // rotate the tool about x: its z axis tilts tilt_deg from +z
    s.tcp.linear() = Eigen::AngleAxisd(deg(k.tilt_deg), Eigen::Vector3d::UnitX()).toRotationMatrix();
    s.has_velocity = true;
    s.tcp_velocity = Eigen::Vector3d(k.v_tcp, 0, 0);
    kin::SafetyViolation v;
    const bool got = kin::check_sample(c, k.mode, s, 0, 0, 0, v);
    char line[256];
    std::snprintf(line, sizeof line, "tilt %g v %g mode %s: expected %s", k.tilt_deg, k.v_tcp, kin::to_string(k.mode),
                  kin::to_string(k.expected));
    CHECK_TEXT(got == (k.expected != kin::SafetyFunction::none), line);
    if (got) CHECK_TEXT(v.function == k.expected, line);
    if (got && k.expected == kin::SafetyFunction::orientation)
      DOUBLES_EQUAL(deg(180 - k.tilt_deg), v.value, 1e-9);
  }
  // the margin: 0.26 m/s against 0.25 passes with a 0.02 m/s tolerance
  kin::SafetySample s = at(0.4, 0, 0.3);
  s.tcp.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
  s.has_velocity = true;
  s.tcp_velocity = Eigen::Vector3d(0, 0.26, 0);
  kin::SafetyViolation v;
  CHECK_FALSE(kin::check_sample(c, kin::SafetyMode::normal, s, 0, 0, 0.02, v));
}

TEST(Safety, ElbowSphereOnlyWhereAsked) {
  kin::SafetyConfig c = table_plane(0.01);
  c.elbow_frame = 3;
  c.elbow_radius = 0.05;
  kin::SafetySample s = at(0.3, 0, 0.5);
  s.elbow = Eigen::Vector3d(0.1, 0, 0.12);  // elbow sphere dips 30 mm into the table
  kin::SafetyViolation v;
  CHECK(kin::check_sample(c, kin::SafetyMode::normal, s, 0, 0, 0, v));
  CHECK(v.elbow);
  DOUBLES_EQUAL(0.07, v.value, 1e-12);
  DOUBLES_EQUAL(0.12, v.where.z(), 1e-12);
  c.planes[0].elbow = false;
  CHECK_FALSE(kin::check_sample(c, kin::SafetyMode::normal, s, 0, 0, 0, v));
}

// Random planes and boxes, random sphere centres: check_sample's verdict matches a test of
// points spread over the sphere's surface (skipping the cases within 0.5 mm of the boundary,
// where the lattice's spacing decides).
TEST(Safety, RandomSweepAgainstSurfacePoints) {
  std::mt19937_64 rng(41);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const std::vector<Eigen::Vector3d> unit = fibonacci(4000);
  int checked = 0, violated = 0;
  for (int n = 0; n < sweep(3000); ++n) {
    kin::SafetyConfig c;
    c.enabled = true;
    c.tool_radius = 0.01 + 0.2 * (u(rng) + 1.0) / 2.0;
    const int kind = n % 3;
    if (kind == 0) {
      c.plane_count = 1;
      c.planes[0].normal = Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();
      c.planes[0].offset = 0.3 * u(rng);
    } else {
      c.box_count = 1;
      const Eigen::Vector3d a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng));
      c.boxes[0] = {a.cwiseMin(b), a.cwiseMax(b), kind == 1, true};
      if (kind == 1 && (c.boxes[0].max - c.boxes[0].min).minCoeff() < 2.0 * c.tool_radius) continue;
    }
    const Eigen::Vector3d centre(u(rng), u(rng), u(rng));
    // reference: the smallest clearance of the surface points (negative: some point outside)
    double worst = INFINITY;
    for (const Eigen::Vector3d& d : unit) {
      const Eigen::Vector3d p = centre + c.tool_radius * d;
      double clear = 0;
      if (kind == 0) {
        clear = c.planes[0].normal.dot(p) - c.planes[0].offset;
      } else {
        const auto& bx = c.boxes[0];
        double in = INFINITY;
        for (int i = 0; i < 3; ++i) in = std::min({in, p[i] - bx.min[i], bx.max[i] - p[i]});
        clear = kind == 1 ? in : -in;  // keep-out: a surface point inside the box is a violation
      }
      worst = std::min(worst, clear);
    }
    // keep-out: the sphere also violates when it swallows the box whole (no surface point inside)
    if (kind == 2 && (centre - centre.cwiseMax(c.boxes[0].min).cwiseMin(c.boxes[0].max)).norm() < c.tool_radius)
      worst = std::min(worst, -1e-3);
    if (std::abs(worst) < 5e-4) continue;
    kin::SafetyViolation v;
    const bool got = kin::check_sample(c, kin::SafetyMode::normal, at(centre.x(), centre.y(), centre.z()), 0, 0, 0, v);
    char line[200];
    std::snprintf(line, sizeof line, "case %d kind %d: reference clearance %g m, check_sample %s", n, kind, worst,
                  got ? "violation" : "inside");
    CHECK_TEXT(got == (worst < 0), line);
    ++checked;
    violated += got;
  }
  CHECK(checked > sweep(3000) / 2);
  CHECK(violated > checked / 10 && violated < checked * 9 / 10);  // both verdicts well represented
}

// A straight path from above the table to below it, sampled at 1000 points: the first
// violation is the first sample past the analytic crossing z = offset + r.
TEST(Safety, PathFirstViolationAtCrossing) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int n = 0; n < 200; ++n) {
    const double r = 0.05 * u(rng), z0 = 0.3 + 0.3 * u(rng), z1 = -0.2 * u(rng);
    const kin::SafetyConfig c = table_plane(r);
    std::vector<kin::SafetySample> path;
    const int N = 1000;
    for (int i = 0; i <= N; ++i) {
      const double s = static_cast<double>(i) / N;
      kin::SafetySample x = at(0.1 * s, 0.2, z0 + (z1 - z0) * s);
      x.s = s;
      path.push_back(x);
    }
    kin::SafetyViolation v;
    CHECK(kin::check_path(c, kin::SafetyMode::normal, path, v));
    const double s_cross = (0.1 + r - z0) / (z1 - z0);
    CHECK(v.s >= s_cross);
    CHECK(v.s < s_cross + 1.0 / N + 1e-12);
    DOUBLES_EQUAL(z0 + (z1 - z0) * v.s, v.where.z(), 1e-12);
  }
  // the same path stopping above the plane passes
  const kin::SafetyConfig c = table_plane(0.02);
  std::vector<kin::SafetySample> path = {at(0, 0, 0.5), at(0, 0, 0.3), at(0, 0, 0.121)};
  kin::SafetyViolation v;
  CHECK_FALSE(kin::check_path(c, kin::SafetyMode::normal, path, v));
}

TEST(Safety, ExcessShrinksMovingBackInside) {
  const kin::SafetyConfig c = table_plane(0.0);
  kin::SafetyViolation v;
  CHECK(kin::check_sample(c, kin::SafetyMode::normal, at(0, 0, 0.09), 0, 0, 0, v));
  DOUBLES_EQUAL(0.01, kin::safety_excess(c, kin::SafetyMode::normal, at(0, 0, 0.09), v), 1e-12);
  CHECK(kin::safety_excess(c, kin::SafetyMode::normal, at(0, 0, 0.095), v) < v.excess());
  CHECK(kin::safety_excess(c, kin::SafetyMode::normal, at(0, 0, 0.2), v) < 0);
}

TEST(Safety, DescribeNamesFunctionWhereLimitValue) {
  const kin::SafetyConfig c = table_plane(0.02);
  kin::SafetySample x = at(0.25, -0.1, 0.11);
  x.s = 0.5;
  kin::SafetyViolation v;
  CHECK(kin::check_sample(c, kin::SafetyMode::normal, x, 0, 0, 0, v));
  char buf[256];
  const std::string line = kin::describe(v, buf, sizeof buf);
  STRCMP_CONTAINS("safety plane 0 (tool sphere)", line.c_str());
  STRCMP_CONTAINS("s=0.500", line.c_str());
  STRCMP_CONTAINS("x=250.0, y=-100.0, z=110.0 mm", line.c_str());
  STRCMP_CONTAINS("limit 100.0 mm", line.c_str());
  STRCMP_CONTAINS("value 90.0 mm", line.c_str());
  CHECK(line.size() < 110);  // fits an event's line with its prefix
  CHECK(line.find('\n') == std::string::npos);
}

TEST(Safety, ConfigProblems) {
  struct Case { const char* what; void (*edit)(kin::SafetyConfig&); const char* expect; };
  const Case cases[] = {
      {"fine", [](kin::SafetyConfig&) {}, ""},
      {"NaN offset", [](kin::SafetyConfig& c) { c.planes[0].offset = NAN; }, "plane 0: not a finite number"},
      {"zero normal", [](kin::SafetyConfig& c) { c.planes[0].normal = Eigen::Vector3d::Zero(); }, "plane 0: the normal must be a unit vector"},
      {"inverted box", [](kin::SafetyConfig& c) { std::swap(c.boxes[0].min, c.boxes[0].max); }, "box 0: inverted"},
      {"tool larger than keep-in", [](kin::SafetyConfig& c) { c.tool_radius = 0.6; }, "box 0: keep-in box narrower than the tool sphere"},
      {"negative speed", [](kin::SafetyConfig& c) { c.reduced.tcp_speed = -1; }, "speed limits"},
      {"NaN radius", [](kin::SafetyConfig& c) { c.tool_radius = NAN; }, "tool radius"},
  };
  for (const Case& k : cases) {
    kin::SafetyConfig c = table_plane(0.05);
    c.box_count = 1;
    c.boxes[0] = {Eigen::Vector3d(-1, -1, 0), Eigen::Vector3d(1, 1, 1), true, true};
    k.edit(c);
    char buf[200];
    const std::string got = kin::safety_config_problem(c, buf, sizeof buf);
    if (*k.expect == '\0')
      STRCMP_EQUAL_TEXT("", got.c_str(), k.what);
    else
      STRCMP_CONTAINS_TEXT(k.expect, got.c_str(), k.what);
  }
}

TEST(Safety, NoHeapInChecks) {
  const kin::Chain chain = model("puma560");
  kin::SafetyConfig c = table_plane(0.05);
  c.box_count = 1;
  c.boxes[0] = {Eigen::Vector3d(-1, -1, -1), Eigen::Vector3d(1, 1, 1), true, true};
  c.elbow_frame = 3;
  c.elbow_radius = 0.08;
  c.cone = true;
  c.normal.cone_half_angle = 1.0;
  c.normal.tcp_speed = 0.25;
  std::vector<kin::SafetySample> path(100);
  kin::JointVector q = kin::JointVector::Zero(chain.n_joints);
  AllocScope scope;
  int bad = 0;
  for (int i = 0; i < 100; ++i) {
    q[1] = -0.01 * i;
    if (!kin::safety_sample(chain, c, q, i / 100.0, path[static_cast<std::size_t>(i)])) ++bad;
  }
  kin::SafetyViolation v;
  (void)kin::check_path(c, kin::SafetyMode::normal, path, v);
  (void)kin::check_sample(c, kin::SafetyMode::reduced, path[5], 0.002, 0.03, 0.02, v);
  char buf[256];
  (void)kin::describe(v, buf, sizeof buf);
  CHECK_EQUAL(0u, scope.end());
  CHECK_EQUAL(0, bad);
  // the sample's elbow is frame 3's origin
  kin::FrameSet F;
  kin::Pose T;
  CHECK(kin::forward_frames(chain, q, F, T) == kin::Status::ok);
  CHECK((path[99].elbow - F.frame[3].translation()).norm() < 1e-12);
  CHECK((path[99].tcp.translation() - T.translation()).norm() < 1e-12);
}
