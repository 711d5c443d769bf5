// SPDX-License-Identifier: Apache-2.0
// The differential test of the dry run: seeded random programs (joint moves, lines, blends,
// dwells, outputs, tool changes, and lines that must be refused: beyond a joint limit, too
// slow, out of reach) are checked by `armctl program check` (fw::check_program, --stream: the
// lines as sent one by one) and run line by line through the firmware's App/Console on the
// sim bus. Both must take the same accept/refuse decision on every line, and every accepted
// move must end at the same joints with the same planned duration. The expected decisions
// are never written down: each side is the other's reference.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>
#include <vector>

#include "../console/console_rig.hpp"
#include "../program/tmp_dir.hpp"
#include "servoarm/armctl/cli_program.hpp"
#include "servoarm/program/program.hpp"
#include "sweep.hpp"  // kSlowBuild: the first 8 programs of 40 under qemu and the sanitizers

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;
using test::answer_ok;

namespace {

struct TmpDir {
  std::string dir = test::make_tmp_dir();
  ~TmpDir() { test::remove_tree(dir); }
};

constexpr double kDeg = M_PI / 180.0;

FwConfig rig_config() {
  FwConfig c;
  c.outputs = {{"gripper", 3, 16}};
  return c;
}

std::string num(double v, int digits = 10) {
  char b[64];
  std::snprintf(b, sizeof b, "%.*g", digits, v);
  return b;
}

// One random program of `n` lines on `chain` (mm, degrees), starting at `q0`. `pose` tracks
// where the generator believes the tool is, for small relative lines.
std::vector<std::string> random_program(std::mt19937_64& rng, const kin::Chain& chain, const kin::JointVector& q0, int n) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const kin::JointVector nominal = q0;
  kin::Pose pose;
  kin::forward(chain, q0, pose);
  std::vector<std::string> lines;
  auto joint_line = [&](kin::JointVector& q) {
    for (int j = 0; j < chain.n_joints; ++j) {
      const double lo = chain.joint(j).lower, hi = chain.joint(j).upper;
      q[j] = std::clamp(nominal[j] + (u(rng) - 0.5) * 60 * kDeg, lo + 2 * kDeg, hi - 2 * kDeg);
    }
  };
  for (int i = 0; i < n; ++i) {
    const double r = u(rng);
    std::string l;
    if (r < 0.32) {  // movej: inside the limits, or just or far beyond one
      kin::JointVector q(chain.n_joints);
      joint_line(q);
      const double edge = u(rng);
      const int k = static_cast<int>(u(rng) * chain.n_joints);
      if (edge < 0.12) q[k] = chain.joint(k).lower - 1e-10;       // a hair beyond the limit
      else if (edge < 0.18) q[k] = chain.joint(k).upper + 0.2;    // far beyond
      l = "movej";
      for (int j = 0; j < chain.n_joints; ++j) l += " " + num(q[j] / kDeg, 17);
      if (u(rng) < 0.4) l += " speed=" + num(std::round(20 + 80 * u(rng)));
      const double b = u(rng);
      if (b < 0.3) l += " blend=" + num(std::round(1 + 9 * u(rng)));
      else if (b < 0.4) l += " blend=0";
      if (edge >= 0.18) kin::forward(chain, q, pose);
    } else if (r < 0.64) {  // movel: reachable, too slow, or out of reach
      const double kind = u(rng);
      Eigen::Vector3d p;
      std::string speed;
      if (kind < 0.12) {  // a short line at a speed below the console's minimum
        p = pose.translation() + Eigen::Vector3d(0.0005, 0, 0);
        speed = " speed=0.005";
      } else if (kind < 0.2) {
        p = Eigen::Vector3d(3.0, 0.5, 0.2);  // out of reach
      } else {
        kin::JointVector q(chain.n_joints);
        joint_line(q);
        kin::Pose x;
        kin::forward(chain, q, x);
        p = pose.translation() + 0.25 * (x.translation() - pose.translation());
        if (u(rng) < 0.5) speed = " speed=" + num(std::round(20 + 200 * u(rng)));
      }
      l = "movel " + num(p.x() * 1e3) + " " + num(p.y() * 1e3) + " " + num(p.z() * 1e3) + speed;
      const double b = u(rng);
      if (b < 0.35) l += " blend=" + num(std::round(1 + 20 * u(rng)));
      if (kind >= 0.2) pose.translation() = p;
    } else if (r < 0.74) {
      l = "G4 P" + num(std::round(50 + 400 * u(rng)));  // dwell, ms
    } else if (r < 0.84) {
      l = u(rng) < 0.5 ? "M62 P0" : "M63 P0";  // output at the start of the next move
    } else {
      l = "tool tool0";  // select the flange (a tool change)
    }
    lines.push_back(l);
  }
  return lines;
}

// `armctl program check --stream` of `lines` (those marked skipped replaced by comments, so
// line numbers stay), from `q0`.
ProgramCheck offline(const kin::Chain& chain, const FwConfig& cfg, const std::string& dir, const std::vector<std::string>& lines,
                     const std::vector<bool>& skip, std::size_t upto, const kin::JointVector& q0) {
  std::string text;
  for (std::size_t i = 0; i < lines.size(); ++i) text += (skip[i] || i >= upto ? "# skipped" : lines[i]) + "\n";
  test::write_file(dir + "/p.txt", text);
  kin::Chain c = chain;
  ProgramCheckOptions opt;
  const std::string ce = apply_config(cfg, c, opt);
  CHECK_TEXT(ce.empty(), ce.c_str());
  opt.stream = true;
  prog::ProgramContext ctx;
  ctx.chain = &c;
  ctx.units = units_of(c);
  ctx.dir = dir;
  prog::Program program;
  const std::string e = prog::load_program(dir + "/p.txt", ctx, program);
  if (!e.empty()) {  // a line the loader refuses (armctl's usage error naming it)
    ProgramCheck bad;
    bad.error = e;
    return bad;
  }
  return check_program(c, program, nullptr, q0, opt);
}

// The line number (1-based) of a check error "DIR/p.txt:N: ...", 0 when none.
std::size_t error_line(const ProgramCheck& ck) {
  if (ck.ok) return 0;
  const std::size_t a = ck.error.find("p.txt:");
  return a == std::string::npos ? 0 : std::stoul(ck.error.substr(a + 6));
}

struct Differences {
  int programs = 0, lines = 0, moves = 0, refusals = 0, decisions = 0, knots = 0, ends = 0;
  std::string first;
  void note(const std::string& what) {
    if (first.size() < 2000) first += what + "\n";
  }
};

// One seeded program: real run line by line, then the offline check line by line.
void compare(std::uint64_t seed, Differences& d) {
  test::ConsoleRig r(rig_config());
  r.enable();
  const kin::JointVector q0 = r.app.console->tail();
  std::mt19937_64 rng(seed);
  const std::vector<std::string> lines = random_program(rng, r.app.chain, q0, 12);
  // the real run: every line through the console, the arm not moving meanwhile (no cycles)
  std::vector<bool> refused(lines.size());
  std::vector<std::string> answers(lines.size());
  std::vector<MoveResult> real(lines.size());  // the service's result of each move it queued
  for (std::size_t i = 0; i < lines.size(); ++i) {
    r.s.out.clear();
    const std::uint32_t before = r.app.console->last_motion_id();
    r.app.console->execute(r.s, lines[i]);
    answers[i] = r.s.out;
    refused[i] = !answer_ok(r.s.out);
    if (r.app.console->last_motion_id() != before) real[i] = r.app.console->service().last();
  }
  const kin::JointVector real_end = r.app.console->tail();
  // the offline check: drop each refused line and check again, so every line is decided
  TmpDir tmp;
  std::vector<bool> skip(lines.size(), false);
  ProgramCheck ck;
  for (;;) {
    ck = offline(r.app.chain, r.app.cfg, tmp.dir, lines, skip, lines.size(), q0);
    const std::size_t k = error_line(ck);
    if (k == 0) break;
    skip[k - 1] = true;
    if (!refused[k - 1]) d.note("seed " + std::to_string(seed) + " line " + lines[k - 1] + ": real ok, check " + ck.error);
  }
  ++d.programs;
  if (std::getenv("DIFF_DUMP") != nullptr)  // every program and its answers, for a failure's seed
    for (std::size_t i = 0; i < lines.size(); ++i) std::printf("%zu %s -> %s", i + 1, lines[i].c_str(), answers[i].c_str());
  const std::string tag = "seed " + std::to_string(seed) + " line ";
  for (std::size_t i = 0; i < lines.size(); ++i) {
    ++d.lines;
    if (refused[i]) ++d.refusals;
    if (refused[i] != skip[i]) {
      ++d.decisions;
      if (refused[i]) d.note(tag + lines[i] + ": check ok, real " + answers[i]);
    }
    if (real[i].id == 0) continue;
    ++d.moves;
    const ProgramKnot* k = nullptr;
    for (const ProgramKnot& x : ck.knots)
      if (x.line == static_cast<int>(i + 1)) k = &x;
    if (k == nullptr) continue;  // refused offline: counted above
    const MoveResult& m = real[i];
    const double dq = (k->goal - m.goal).norm();
    if (!(dq <= 1e-12 && std::fabs(k->duration - m.duration) <= 1e-12 && k->blended == m.blended &&
          std::fabs(k->blend - m.blend) <= 1e-12 && std::fabs(k->segment_end - m.segment_end) <= 1e-12)) {
      ++d.knots;
      d.note(tag + lines[i] + ": knots differ: goal by " + num(dq) + ", duration real " + num(m.duration, 17) + " check " +
             num(k->duration, 17) + ", blended " + std::to_string(m.blended) + "/" + std::to_string(k->blended) + " blend " +
             num(m.blend, 17) + "/" + num(k->blend, 17) + " end " + num(m.segment_end, 17) + "/" + num(k->segment_end, 17));
    }
  }
  if (ck.q_end.size() == real_end.size() && (ck.q_end - real_end).norm() > 1e-12) {
    ++d.ends;
    d.note("seed " + std::to_string(seed) + ": end joints differ by " + num((ck.q_end - real_end).norm()));
  }
}

}  // namespace

TEST_GROUP(ServiceDifferential){};

// Seeds 1-40 on the host; under qemu and the sanitizers (sweep.hpp) seeds 1-8, which hold
// every kind of line the generator writes, refused ones included (some 0.8 s a program there).
TEST(ServiceDifferential, CheckAndRealRunDecideEveryLineAlike) {
  Differences d;
  const int programs = servoarm::test::kSlowBuild ? 8 : 40;
  for (std::uint64_t seed = 1; seed <= std::uint64_t(programs); ++seed) compare(seed, d);
  std::printf("\n%d programs, %d lines, %d moves queued, %d lines refused: %d decisions differ, %d moves' knots differ, "
              "%d end poses differ\n%s",
              d.programs, d.lines, d.moves, d.refusals, d.decisions, d.knots, d.ends, d.first.c_str());
  CHECK(d.moves > 100 * programs / 40);  // the programs do move (most lines are accepted: 235 of 480 on the host)
  CHECK(d.refusals > 0);                 // and some lines are refused, by both sides
  LONGS_EQUAL(0, d.decisions);
  LONGS_EQUAL(0, d.knots);
  LONGS_EQUAL(0, d.ends);
}
