// SPDX-License-Identifier: Apache-2.0
// The safety envelope's geometry (kinematics/include/servoarm/kinematics/safety.hpp):
//  - case tables for each function (plane, keep-in, keep-out, cone, speeds; tool and elbow
//    spheres), printing the failing case;
//  - seeded random sweeps against an independent reference: points spread over the sphere's
//    surface (a Fibonacci lattice) tested one by one against the half-space / the box;
//  - a straight path through a plane: the first violation is the first sample past the
//    analytic crossing;
//  - the configuration problems (NaN, zero normal, inverted box, keep-in smaller than the sphere);
//  - no heap in check_sample / check_path / safety_sample (and the checked build's EIGEN_NO_MALLOC);
//  - self-collision: the segment distance against brute-force sampling of both segments
//    (seeded sweep, an independent reference) and a case table of parallel, crossing and
//    degenerate segments; a planar arm folded onto itself names the pair, straight it passes;
//    the pairs a chain checks (adjacency, ignore list); the description's bad capsules refused
//    in one line (negative or NaN radius, missing point, overlap at the zero pose).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <random>
#include <vector>

#include "../support/alloc_counter.hpp"
#include "../support/sweep.hpp"
#include "kin_test_util.hpp"
#include "servoarm/kinematics/description.hpp"
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

// ---- self-collision ----

namespace {

// The distance of two segments by sampling both on an n x n grid: an upper bound of the exact
// distance, above it by at most (|d1| + |d2|) / (2 (n - 1)).
double sampled_distance(const Eigen::Vector3d& p1, const Eigen::Vector3d& q1, const Eigen::Vector3d& p2,
                        const Eigen::Vector3d& q2, int n) {
  double best = INFINITY;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d a = p1 + (q1 - p1) * (static_cast<double>(i) / (n - 1));
    for (int j = 0; j < n; ++j) best = std::min(best, (a - (p2 + (q2 - p2) * (static_cast<double>(j) / (n - 1)))).norm());
  }
  return best;
}

// A planar 3R arm (standard DH, a = 300, 250, 200 mm, links in one plane) with a capsule of
// radius 20 mm along each link: from the previous joint's axis to this frame's origin.
std::string planar_arm(const std::string& extra_rows_keys = "", const std::string& top = "", double r3 = 20) {
  char caps[3][128];
  const double a[3] = {300, 250, 200}, r[3] = {20, 20, r3};
  for (int i = 0; i < 3; ++i)
    std::snprintf(caps[i], sizeof caps[i], "capsule = { from = [%g, 0, 0], to = [0, 0, 0], radius = %g }\n", -a[i], r[i]);
  return "name = \"fold3\"\nconvention = \"standard\"\nlength_unit = \"mm\"\nangle_unit = \"deg\"\n" + top +
         "[[joint]]\ntype = \"revolute\"\na = 300\n" + caps[0] + "[[joint]]\ntype = \"revolute\"\na = 250\n" + caps[1] +
         "[[joint]]\ntype = \"revolute\"\na = 200\n" + caps[2] + extra_rows_keys;
}

kin::Chain load_ok(const std::string& text) {
  const kin::LoadResult lr = kin::load_description(text, "fold3.toml");
  if (!lr.ok) FAIL(lr.error.c_str());
  return lr.chain;
}

}  // namespace

// Random segments in a 1 m cube (a quarter of them nearly parallel, a tenth of them nearly
// points): the closed form never exceeds the sampled distance (by more than 1 um: segments
// within 1e-7 rad of parallel are taken as parallel) and is within the grid's bound of it; the
// closest points lie on their segments, that far apart.
TEST(Safety, SegmentDistanceAgainstBruteForceSampling) {
  std::mt19937 rng(4141);
  std::uniform_real_distribution<double> u(-0.5, 0.5);
  auto point = [&] { return Eigen::Vector3d(u(rng), u(rng), u(rng)); };
  constexpr int kGrid = 241;
  const int cases = sweep(1000);
  double worst_gap = 0;
  for (int k = 0; k < cases; ++k) {
    const Eigen::Vector3d p1 = point(), q1 = point(), p2 = point();
    Eigen::Vector3d q2 = point();
    if (k % 4 == 1) q2 = p2 + (q1 - p1) * 0.7 + point() * 1e-7;  // nearly parallel
    Eigen::Vector3d q1k = q1;
    if (k % 10 == 3) q1k = p1 + point() * 1e-13;                 // nearly a point
    Eigen::Vector3d c1, c2;
    const double d = kin::segment_distance(p1, q1k, p2, q2, c1, c2);
    const double ref = sampled_distance(p1, q1k, p2, q2, kGrid);
    const double bound = ((q1k - p1).norm() + (q2 - p2).norm()) / (2.0 * (kGrid - 1)) + 1e-12;
    char line[160];
    std::snprintf(line, sizeof line, "case %d: closed form %.9f, sampled %.9f, bound %.9f", k, d, ref, bound);
    CHECK_TEXT(d <= ref + 1e-6, line);  // (1e-6: the nearly parallel ones are taken as parallel)
    CHECK_TEXT(ref - d <= bound, line);
    DOUBLES_EQUAL_TEXT(d, (c1 - c2).norm(), 1e-12, line);
    // on the segments: the distances to both ends add up to the length
    CHECK_TEXT(std::abs((c1 - p1).norm() + (q1k - c1).norm() - (q1k - p1).norm()) < 1e-9, line);
    CHECK_TEXT(std::abs((c2 - p2).norm() + (q2 - c2).norm() - (q2 - p2).norm()) < 1e-9, line);
    worst_gap = std::max(worst_gap, ref - d);
  }
  std::printf("\n  segment distance: %d random pairs, largest sampled - closed form %.3g m\n", cases, worst_gap);
}

TEST(Safety, SegmentDistanceCaseTable) {
  using V = Eigen::Vector3d;
  struct Case { const char* what; V p1, q1, p2, q2; double expect; };
  const Case cases[] = {
      {"crossing", V(-1, 0, 0), V(1, 0, 0), V(0, -1, 0), V(0, 1, 0), 0.0},
      {"skew, perpendicular", V(-1, 0, 0), V(1, 0, 0), V(0, -1, 0.3), V(0, 1, 0.3), 0.3},
      {"parallel, overlapping", V(0, 0, 0), V(1, 0, 0), V(0.5, 0.2, 0), V(1.5, 0.2, 0), 0.2},
      {"parallel, reversed", V(0, 0, 0), V(1, 0, 0), V(1.5, 0.2, 0), V(0.5, 0.2, 0), 0.2},
      {"parallel, apart along the line", V(0, 0, 0), V(1, 0, 0), V(2, 0, 0), V(3, 0, 0), 1.0},
      {"parallel, apart and offset", V(0, 0, 0), V(1, 0, 0), V(1.3, 0.4, 0), V(3, 0.4, 0), 0.5},
      {"collinear, touching", V(0, 0, 0), V(1, 0, 0), V(1, 0, 0), V(2, 0, 0), 0.0},
      {"identical", V(0, 0, 0), V(1, 1, 1), V(0, 0, 0), V(1, 1, 1), 0.0},
      {"T: an end on the other's middle", V(-1, 0, 0), V(1, 0, 0), V(0, 0.25, 0), V(0, 2, 0), 0.25},
      {"ends closest", V(0, 0, 0), V(1, 0, 0), V(2, 1, 0), V(2, 3, 0), std::sqrt(2.0)},
      {"point and point", V(1, 2, 3), V(1, 2, 3), V(1, 2, 4), V(1, 2, 4), 1.0},
      {"point and segment, inside", V(0, 1, 0), V(0, 1, 0), V(-1, 0, 0), V(1, 0, 0), 1.0},
      {"point and segment, beyond an end", V(3, 0, 0), V(3, 0, 0), V(-1, 0, 0), V(1, 0, 0), 2.0},
      {"segment and point", V(-1, 0, 0), V(1, 0, 0), V(0, 0, -0.5), V(0, 0, -0.5), 0.5},
      {"point on the segment", V(0.3, 0, 0), V(0.3, 0, 0), V(0, 0, 0), V(1, 0, 0), 0.0},
  };
  for (const Case& k : cases) {
    V c1, c2;
    const double d = kin::segment_distance(k.p1, k.q1, k.p2, k.q2, c1, c2);
    DOUBLES_EQUAL_TEXT(k.expect, d, 1e-12, k.what);
    DOUBLES_EQUAL_TEXT(d, (c1 - c2).norm(), 1e-12, k.what);
    // symmetric in the two segments
    DOUBLES_EQUAL_TEXT(k.expect, kin::segment_distance(k.p2, k.q2, k.p1, k.q1, c1, c2), 1e-12, k.what);
  }
}

// Link 1 and link 3 are checked (not joined by one joint), link 1 / link 2 and link 2 / link 3
// are not; the tool (on link 3) against link 1. The ignore list takes a pair out.
TEST(Safety, CapsulePairsAreTheNonAdjacentLinks) {
  const kin::Chain c = load_ok(planar_arm());
  CHECK_EQUAL(0b1110u, c.capsule_mask);
  CHECK_EQUAL((1u << 3) | (1u << kin::kToolCapsule), c.capsule_pairs[1]);
  CHECK_EQUAL(0u, c.capsule_pairs[2]);
  CHECK_EQUAL(2, kin::capsule_pair_count(c));
  const kin::Chain b = load_ok(planar_arm("", "base_capsule = { from = [0, 0, -500], to = [0, 0, -50], radius = 40 }\n"));
  CHECK_EQUAL(5, kin::capsule_pair_count(b));  // + base / link 2, base / link 3, base / tool
  const kin::Chain t = load_ok(planar_arm("", "self_collision_ignore = [[3, 1], [1, \"tool\"]]\n"));
  CHECK_EQUAL(0, kin::capsule_pair_count(t));
  // a fixed row's link is the body before it: adjacent to that body's neighbours only
  const kin::Chain f = load_ok(planar_arm("[[joint]]\ntype = \"fixed\"\nd = 50\n"
                                          "capsule = { from = [0, 0, -50], to = [0, 0, 0], radius = 10 }\n"));
  CHECK_EQUAL(0u, f.capsule_pairs[3] & (1u << 4));  // link 3 and the fixed link 4: one body
  CHECK((f.capsule_pairs[1] & (1u << 4)) != 0);      // link 1 and link 4: two joints apart
  CHECK_EQUAL(0u, f.capsule_pairs[2] & (1u << 4));
}

// Straight, the arm is 210 mm clear (link 1 to link 3); folded (170, 170 deg) link 3 crosses
// link 1: refused naming the pair, the distance (-40 mm: the radii overlap), the limit and
// where; the margin counts (a 250 mm margin refuses the straight arm too).
TEST(Safety, AFoldedArmNamesThePairAStraightOnePasses) {
  const kin::Chain chain = load_ok(planar_arm());
  kin::SafetyConfig c;
  c.enabled = true;
  c.self_collision = true;
  c.self_collision_margin = 0.010;
  kin::JointVector q = kin::JointVector::Zero(3);
  kin::SafetySample x;
  kin::SafetyViolation v;
  CHECK(kin::safety_sample(chain, c, q, 0.0, x));
  CHECK(x.has_self);
  DOUBLES_EQUAL(0.210, x.self_distance, 1e-12);
  CHECK(!kin::check_sample(c, kin::SafetyMode::normal, x, 0, 0, 0, v));
  q[1] = q[2] = 170 * M_PI / 180;
  CHECK(kin::safety_sample(chain, c, q, 0.25, x));
  CHECK(kin::check_sample(c, kin::SafetyMode::normal, x, 0, 0, 0, v));
  CHECK(v.function == kin::SafetyFunction::self_collision);
  CHECK_EQUAL(1, v.index);
  CHECK_EQUAL(3, v.other);
  DOUBLES_EQUAL(-0.040, v.value, 1e-9);
  char buf[256];
  const std::string line = kin::describe(v, buf, sizeof buf);
  STRCMP_CONTAINS("safety self_collision link 1 and link 3 at s=0.250", line.c_str());
  STRCMP_CONTAINS("limit 10.0 mm, value -40.0 mm", line.c_str());
  CHECK(line.size() < 120);
  // within the run-time margin of an overlap the monitor lets it go; beyond, not
  CHECK(!kin::check_sample(c, kin::SafetyMode::normal, x, 0.051, 0, 0, v));
  CHECK(kin::check_sample(c, kin::SafetyMode::normal, x, 0.049, 0, 0, v));
  // the excess of the closest pair: smaller unfolding
  kin::SafetySample y;
  q[2] = 0;  // link 3 straight on from link 2: its start 43.4 mm above link 1
  CHECK(kin::safety_sample(chain, c, q, 0.5, y));
  DOUBLES_EQUAL(0.25 * std::sin(10 * M_PI / 180) - 0.040, y.self_distance, 1e-9);
  CHECK(kin::safety_excess(c, kin::SafetyMode::normal, y, v) < v.excess());
  q.setZero();
  c.self_collision_margin = 0.25;
  CHECK(kin::safety_sample(chain, c, q, 0.0, x));
  CHECK(kin::check_sample(c, kin::SafetyMode::normal, x, 0, 0, 0, v));
  // off: nothing found
  c.self_collision = false;
  CHECK(kin::safety_sample(chain, c, q, 0.0, x));
  CHECK(!x.has_self);
  CHECK(!kin::check_sample(c, kin::SafetyMode::normal, x, 0, 0, 0, v));
}

// The tool's capsule runs from the flange to the TCP with the tool radius: a tool 400 mm long
// pointing back along link 3 (-x of its frame); link 2 turned 120 deg, link 3 straight on: the
// TCP 25 sqrt(3) mm above link 1, link 3 itself far from it.
TEST(Safety, TheToolsCapsuleFromTheFlangeToTheTcp) {
  kin::Chain chain = load_ok(planar_arm());
  kin::SafetyConfig c;
  c.enabled = true;
  c.self_collision = true;
  c.tool_radius = 0.015;
  kin::Pose tool = kin::Pose::Identity();
  tool.translation() = Eigen::Vector3d(-0.4, 0, 0);
  kin::set_tool(chain, tool);
  kin::JointVector q = kin::JointVector::Zero(3);
  kin::SafetySample x;
  q[1] = 120 * M_PI / 180;
  CHECK(kin::safety_sample(chain, c, q, 0.0, x));
  DOUBLES_EQUAL(0.025 * std::sqrt(3.0) - 0.035, x.self_distance, 1e-9);
  kin::FrameSet F;
  kin::Pose T;
  CHECK(kin::forward_frames(chain, q, F, T) == kin::Status::ok);
  Eigen::Vector3d c1, c2;
  const double link1_tool = kin::segment_distance(F.frame[1] * chain.capsule[1].a, F.frame[1] * chain.capsule[1].b,
                                                  F.frame[3].translation(), T.translation(), c1, c2) -
                            0.020 - 0.015;
  const double link1_link3 = kin::segment_distance(F.frame[1] * chain.capsule[1].a, F.frame[1] * chain.capsule[1].b,
                                                   F.frame[3] * chain.capsule[3].a, F.frame[3] * chain.capsule[3].b,
                                                   c1, c2) -
                             0.040;
  DOUBLES_EQUAL(std::min(link1_tool, link1_link3), x.self_distance, 1e-12);
  CHECK_EQUAL(kin::kToolCapsule, static_cast<int>(x.self_b));  // the tool is the closer one here
  CHECK(link1_tool < link1_link3);
}

// Bad capsules are refused at load, one line naming the file, the joint and the key.
TEST(Safety, BadCapsulesRefusedAtLoad) {
  struct Case { const char* what; std::string text; const char* expect; };
  const std::string arm = planar_arm();
  auto with = [&](const char* from, const char* to) {
    std::string t = arm;
    const std::size_t at = t.find(from);
    CHECK(at != std::string::npos);
    return t.replace(at, std::strlen(from), to);
  };
  const Case cases[] = {
      {"negative radius", with("radius = 20 }", "radius = -5 }"), "joint 1: key 'capsule.radius': -5 must not be negative"},
      {"NaN radius", with("radius = 20 }", "radius = nan }"), "joint 1: key 'capsule.radius': value is not finite"},
      {"inf point", with("from = [-300, 0, 0]", "from = [-300, inf, 0]"), "joint 1: key 'capsule.from': value is not finite"},
      {"missing to", with("to = [0, 0, 0], radius = 20 }", "radius = 20 }"), "joint 1: key 'capsule': 'to' is missing"},
      {"two numbers", with("from = [-300, 0, 0]", "from = [-300, 0]"), "joint 1: key 'capsule.from': expected 3 numbers"},
      {"unknown key", with("radius = 20 }", "radius = 20, r = 3 }"), "key 'r' is not known"},
      {"huge radius (metres in a mm file)", with("radius = 20 }", "radius = 20000 }"), "more than 10 m"},
      {"1 mm apart at the zero pose", planar_arm("", "", 229), ""},  // loads
      {"overlap at the zero pose", planar_arm("", "", 240),
       "the capsules of link 1 and link 3 overlap by 10 mm at the zero pose"},
      {"ignore: no capsule", planar_arm("", "base_capsule = { from = [0,0,-1], to = [0,0,-2], radius = 1 }\n"
                                            "self_collision_ignore = [[5, 1]]\n"),
       "key 'self_collision_ignore': expected 0 (the base), 1..3"},
      {"ignore: a link without capsule", "name = \"x\"\nconvention = \"standard\"\nlength_unit = \"mm\"\nangle_unit = \"deg\"\n"
                                         "self_collision_ignore = [[1, 3]]\n[[joint]]\ntype = \"revolute\"\na = 300\n"
                                         "[[joint]]\ntype = \"revolute\"\na = 300\n[[joint]]\ntype = \"revolute\"\na = 300\n",
       "key 'self_collision_ignore': link 1 has no capsule"},
      {"ignore: not a pair", planar_arm("", "self_collision_ignore = [[1, 3, 2]]\n"), "each entry is a pair [i, j]"},
      {"ignore: itself", planar_arm("", "self_collision_ignore = [[3, 3]]\n"), "a pair of one capsule with itself"},
  };
  for (const Case& k : cases) {
    const kin::LoadResult lr = kin::load_description(k.text, "fold3.toml");
    if (*k.expect == '\0') {
      CHECK_TEXT(lr.ok, (std::string(k.what) + ": " + lr.error).c_str());
      continue;
    }
    CHECK_TEXT(!lr.ok, k.what);
    STRCMP_CONTAINS_TEXT("fold3.toml:", lr.error.c_str(), k.what);
    STRCMP_CONTAINS_TEXT(k.expect, lr.error.c_str(), k.what);
    CHECK_TEXT(lr.error.find('\n') == std::string::npos, k.what);
  }
  // the overlapping pair listed in self_collision_ignore loads
  CHECK(kin::load_description(planar_arm("", "self_collision_ignore = [[1, 3]]\n", 240), "fold3.toml").ok);
  // the margin is a configuration problem when not a finite number >= 0
  kin::SafetyConfig c;
  c.self_collision_margin = -0.001;
  char buf[160];
  STRCMP_CONTAINS("self-collision margin", kin::safety_config_problem(c, buf, sizeof buf));
  c.self_collision_margin = NAN;
  STRCMP_CONTAINS("self-collision margin", kin::safety_config_problem(c, buf, sizeof buf));
}

TEST(Safety, NoHeapInTheSelfCollisionCheck) {
  const kin::Chain chain = load_ok(planar_arm("", "base_capsule = { from = [0, 0, -500], to = [0, 0, -50], radius = 40 }\n"));
  kin::SafetyConfig c;
  c.enabled = true;
  c.self_collision = true;
  kin::JointVector q = kin::JointVector::Zero(3);
  std::vector<kin::SafetySample> path(50);
  AllocScope scope;
  for (int i = 0; i < 50; ++i) {
    q[1] = q[2] = 3.4 * i / 50.0;
    (void)kin::safety_sample(chain, c, q, i / 50.0, path[static_cast<std::size_t>(i)]);
  }
  kin::SafetyViolation v;
  const bool hit = kin::check_path(c, kin::SafetyMode::normal, path, v);
  char buf[256];
  (void)kin::describe(v, buf, sizeof buf);
  CHECK_EQUAL(0u, scope.end());
  CHECK(hit);
}
