// SPDX-License-Identifier: Apache-2.0
// armctl plan movel previews what armfw runs: the console (armfw's path: movel's plan and
// the IkSolver the control thread samples with) and armctl's plan code plan the same
// movel -- same robot, start, target, speed, limits -- and every sample at 1 kHz agrees
// to 1e-12 (rad). Both get their IK from fw::firmware_ik_solver (ik_options.hpp).
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "../console/console_rig.hpp"
#include "servoarm/armctl/cli_plan.hpp"
#include "servoarm/lang/ik_options.hpp"
#include "servoarm/kinematics/description.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;

namespace {
constexpr double kDeg = M_PI / 180.0;

int plan_cli(std::vector<std::string> args) {
  args.insert(args.begin(), "plan");
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  std::fflush(stdout);
  return cli_plan(static_cast<int>(argv.size()), argv.data());
}

/// Sample both at 1 kHz (as the control loop does): the largest difference in q, v, a.
double max_sample_diff(const kin::CartesianTrajectory& a, const kin::CartesianTrajectory& b, int& samples) {
  const int n = a.n;
  kin::JointVector qa(n), va(n), aa(n), qb(n), vb(n), ab(n);
  double worst = 0;
  samples = 0;
  for (long k = 0;; ++k) {
    const double t = std::fmin(a.duration, static_cast<double>(k) * 1e-3);
    a.sample_ik(t, qa, va, aa);
    b.sample_ik(t, qb, vb, ab);
    worst = std::fmax(worst, (qa - qb).cwiseAbs().maxCoeff());
    worst = std::fmax(worst, (va - vb).cwiseAbs().maxCoeff());
    worst = std::fmax(worst, (aa - ab).cwiseAbs().maxCoeff());
    ++samples;
    if (t >= a.duration) break;
  }
  return worst;
}
}  // namespace

TEST_GROUP(PlanPreview) {
  void setup() override { MemoryLeakWarningPlugin::saveAndDisableNewDeleteOverloads(); }
  void teardown() override { MemoryLeakWarningPlugin::restoreNewDeleteOverloads(); }
};

TEST(PlanPreview, ArmctlPlanMovelSamplesAreTheFirmwares) {
  struct Case {
    const char* start;     // movej, degrees
    double dx, dy, dz;     // mm from the start's tool point
    double speed_mm_s;
  };
  const Case cases[] = {
      {"20 -40 160 10 -50 30", 60, -30, 20, 200},
      {"20 -40 160 10 -50 30", -80, 40, -60, 100},
      {"0 -30 150 0 -60 0", 0, 150, 0, 250},
  };
  for (const Case& k : cases) {
    test::ConsoleRig r;
    r.enable();
    CHECK(test::answer_ok(r.cmd(std::string("movej ") + k.start)));
    CHECK(test::answer_ok(r.cmd("wait")));
    const Telemetry tel = r.app.ctl->telemetry();
    kin::JointVector q0(6);
    for (int j = 0; j < 6; ++j) q0[j] = tel.q_cmd[static_cast<std::size_t>(j)];
    kin::Pose x0;
    kin::forward(r.app.chain, q0, x0);
    const Eigen::Vector3d c = x0.translation() * 1e3 + Eigen::Vector3d(k.dx, k.dy, k.dz);
    char line[160];
    std::snprintf(line, sizeof line, "movel %.17g %.17g %.17g speed=%.17g", c.x(), c.y(), c.z(), k.speed_mm_s);
    const std::string a = r.cmd(line);
    if (!test::answer_ok(a)) FAIL((std::string(line) + ": " + a).c_str());
    const MotionItem* m = r.app.ctl->motions().front();
    CHECK(m != nullptr && m->kind() == MotionKind::cartesian);
    const kin::CartesianTrajectory& fw_ct = std::get_if<CartesianMove>(&m->payload)->path;

    // armctl's plan code on armctl's own load of the robot.
    const kin::LoadResult lr = kin::load_robot("puma560");
    CHECK(lr.ok);
    kin::Pose target = x0;
    target.translation() = Eigen::Vector3d(c.x(), c.y(), c.z()) * lr.chain.length_unit;
    kin::CartesianLimits cl;
    cl.linear_velocity = k.speed_mm_s * lr.chain.length_unit;
    auto model = std::make_unique<kin::IkModel>();
    auto preview = std::make_unique<kin::CartesianTrajectory>();
    const kin::MotionStatus st = plan_movel_preview(lr.chain, q0, target, cl, kin::MovelOptions{}, *model, *preview, nullptr);
    CHECK_TEXT(kin::is_ok(st), kin::to_string(st));
    CHECK(preview->duration == fw_ct.duration);
    int samples = 0;
    const double d = max_sample_diff(*preview, fw_ct, samples);
    CHECK(samples > 100);
    CHECK_TEXT(d <= 1e-12, (std::string(line) + ": samples differ by " + std::to_string(d)).c_str());

    // The CLI itself: its CSV (description units, 9 digits) holds the firmware's samples.
    const std::string csv = "/tmp/servoarm_test_plan_preview.csv";
    char from[128], xyz[3][32], spd[32];
    std::snprintf(from, sizeof from, "%s", k.start);
    std::vector<std::string> args = {"movel", "--robot", "puma560", "--from"};
    for (const char* p = std::strtok(from, " "); p; p = std::strtok(nullptr, " ")) args.push_back(p);
    for (int i = 0; i < 3; ++i) std::snprintf(xyz[i], sizeof xyz[i], "%.17g", c[i]), (void)0;
    std::snprintf(spd, sizeof spd, "%.17g", k.speed_mm_s);
    for (const std::string& s : {std::string("--xyz"), std::string(xyz[0]), std::string(xyz[1]), std::string(xyz[2]),
                                std::string("--speed"), std::string(spd), std::string("--csv"), csv})
      args.push_back(s);
    CHECK_EQUAL(0, plan_cli(args));
    std::ifstream f(csv);
    std::string row;
    std::getline(f, row);  // header
    kin::JointVector q(6), v(6), acc(6);
    double worst_csv = 0;
    int rows = 0;
    while (std::getline(f, row)) {
      std::vector<double> vals;
      std::stringstream ss(row);
      std::string cell;
      while (std::getline(ss, cell, ',')) vals.push_back(std::stod(cell));
      CHECK(vals.size() == 19);
      fw_ct.sample_ik(vals[0], q, v, acc);
      for (int j = 0; j < 6; ++j) worst_csv = std::fmax(worst_csv, std::fabs(vals[static_cast<std::size_t>(1 + j)] - q[j] / kDeg));
      ++rows;
    }
    CHECK_EQUAL(samples, rows);
    CHECK_TEXT(worst_csv < 1e-6, std::to_string(worst_csv).c_str());  // degrees, 9 significant digits
    std::remove(csv.c_str());
  }
}

// The options are armfw's: nothing outside the joint limits (closed form), Newton where
// there is no closed form or no model.
TEST(PlanPreview, FirmwareIkOptions) {
  const kin::LoadResult lr = kin::load_robot("puma560");
  CHECK(lr.ok);
  auto model = std::make_unique<kin::IkModel>();
  CHECK(kin::ik_prepare(lr.chain, *model) == kin::Status::ok);
  CHECK(model->method != kin::IkMethod::none);
  const kin::IkSolverOptions o = firmware_ik_options(model.get());
  CHECK(!o.allow_out_of_limits && o.closed_form && o.fallback == kin::IkFallback::numeric);
  const kin::IkSolverOptions none = firmware_ik_options(nullptr);
  CHECK(!none.closed_form && none.fallback == kin::IkFallback::newton);
  const kin::IkSolver s = firmware_ik_solver(model.get());
  CHECK(s.ctx == model.get() && s.fn == kin::make_ik_solver(*model, {}).fn);
  CHECK(firmware_ik_solver(nullptr).fn == &kin::ik_nearest_newton);
}
