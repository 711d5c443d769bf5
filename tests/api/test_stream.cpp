// SPDX-License-Identifier: Apache-2.0
// Streaming targets (StreamService, service/stream.hpp, over the control thread's jog with
// JogSpec::stream) on the controller stepped cycle by cycle (a ManualClock, the virtual drives
// stepped with it): a 30 Hz stream with ±5 ms jitter stays within the joints' velocity,
// acceleration and jerk limits; without targets the deadman brakes the arm to rest with an
// event; a stop ends the stream and later targets do not move the arm; bad targets are refused.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "servoarm/service/stream.hpp"
#include "sim_app.hpp"

#include "CppUTest/TestHarness.h"

using namespace servoarm;
using namespace servoarm::fw;

namespace {

struct Rig {
  hal::ManualClock clock;
  test::SimApp app;
  hal::Duration period = hal::kMillisecond;
  std::vector<kin::JointVector> trace;  ///< q_cmd after every cycle
  bool record = false;

  explicit Rig(const FwConfig& base = {}) {
    FwConfig cfg = base;
    cfg.can = "sim";
    const std::string e = app.build(cfg, &clock);
    if (!e.empty()) FAIL(e.c_str());
    clock.set_idle_hook([this](hal::TimePoint t) { app.plant->step(t); });
    const std::string b = app.boot();
    if (!b.empty()) FAIL(b.c_str());
    app.console->set_idle([this] { cycle(); });
  }
  ~Rig() { clock.set_idle_hook(nullptr); }
  ArmService& svc() { return app.console->service(); }
  void cycle() {
    app.ctl->cycle(clock.now());
    clock.advance(period);
    if (record) trace.push_back(q_cmd());
  }
  void run(double s) {
    for (int i = 0; i < static_cast<int>(s * 1000); ++i) cycle();
  }
  Telemetry tel() const { return app.ctl->telemetry(); }
  kin::JointVector q_cmd() const {
    const Telemetry t = tel();
    kin::JointVector q(t.n);
    for (int j = 0; j < t.n; ++j) q[j] = t.q_cmd[static_cast<std::size_t>(j)];
    return q;
  }
  void enable() {
    CHECK(svc().enable().ok());
    for (int i = 0; i < 2000 && tel().state != ArmState::idle; ++i) cycle();
    CHECK_EQUAL(static_cast<int>(ArmState::idle), static_cast<int>(tel().state));
  }
  StreamSettings settings() const {
    StreamSettings s;
    s.max_step.assign(6, 0.5);
    return s;
  }
};

/// The sine the stream follows: every joint, 0.4 rad at 0.4 Hz around its start.
kin::JointVector sine(const kin::JointVector& q0, double t) {
  kin::JointVector q = q0;
  for (int j = 0; j < q.size(); ++j) q[j] += 0.4 * std::sin(2 * M_PI * 0.4 * t + 0.5 * j);
  return q;
}

/// Peak velocity, acceleration and jerk of a q_cmd trace (finite differences, 1 ms cycles) as
/// fractions of the joints' limits.
struct Peaks {
  double v = 0, a = 0, j = 0;
};
Peaks peak_ratios(const std::vector<kin::JointVector>& tr, const kin::JointLimits& L) {
  const double dt = 1e-3;
  Peaks p;
  for (std::size_t k = 3; k < tr.size(); ++k)
    for (int j = 0; j < tr[k].size(); ++j) {
      const auto u = static_cast<std::size_t>(j);
      const double v = (tr[k][j] - tr[k - 1][j]) / dt;
      const double a = (tr[k][j] - 2 * tr[k - 1][j] + tr[k - 2][j]) / (dt * dt);
      const double jk = (tr[k][j] - 3 * tr[k - 1][j] + 3 * tr[k - 2][j] - tr[k - 3][j]) / (dt * dt * dt);
      p.v = std::max(p.v, std::fabs(v) / L.dyn[u].max_velocity);
      p.a = std::max(p.a, std::fabs(a) / L.dyn[u].max_acceleration);
      p.j = std::max(p.j, std::fabs(jk) / L.dyn[u].max_jerk);
    }
  return p;
}

/// A 30 Hz stream (±5 ms jitter) of a 0.5 Hz, 0.4 rad sine on every joint for 4 s, each target
/// with its velocity (`with_qd`) or without (the service estimates it). Returns, over the last
/// 3 s: the smallest |commanded velocity| / the sine's velocity where the sine moves at more than
/// half its peak speed (mid-swing), the largest and the RMS tracking error (q_cmd against the
/// sine at the same time), and the peaks as fractions of the limits.
struct SineRun {
  double min_mid_ratio = 1e9, worst = 0, rms = 0;
  Peaks peaks;
  std::string figure() const {
    return "mid-swing min |qd_cmd|/|qd_sine| " + std::to_string(min_mid_ratio) + ", tracking error max " +
           std::to_string(worst) + " rms " + std::to_string(rms) + " rad, peak/limit v " + std::to_string(peaks.v) +
           " a " + std::to_string(peaks.a) + " j " + std::to_string(peaks.j);
  }
};
SineRun run_sine(Rig& rig, bool with_qd) {
  StreamService st(rig.svc(), *rig.app.ctl, rig.settings());
  const kin::JointVector q0 = rig.q_cmd();
  const double f = 0.5, amp = 0.4, w = 2 * M_PI * f;
  auto at = [&](double t) {
    kin::JointVector q = q0;
    for (int j = 0; j < q.size(); ++j) q[j] += amp * std::sin(w * t + 0.5 * j);
    return q;
  };
  auto vel = [&](double t) {
    kin::JointVector v = kin::JointVector::Zero(q0.size());
    for (int j = 0; j < v.size(); ++j) v[j] = amp * w * std::cos(w * t + 0.5 * j);
    return v;
  };
  std::mt19937 rng(38);
  std::uniform_real_distribution<double> jitter(-0.005, 0.005);
  SineRun out;
  rig.record = true;
  rig.trace.clear();
  double t = 0, sum2 = 0;
  long samples = 0;
  bool first = true;
  while (t < 4.0) {
    const StreamResult r = with_qd ? st.target(at(t), first, vel(t)) : st.target(at(t), first);
    CHECK_TEXT(r.ok(), r.reason.c_str());
    first = false;
    const double gap = 1.0 / 30 + jitter(rng);
    for (double g = 0; g < gap; g += 1e-3) {
      rig.cycle();
      t += 1e-3;
      if (t < 1.0) continue;
      const Telemetry tel = rig.tel();
      const kin::JointVector e = rig.q_cmd() - at(t), v = vel(t);
      out.worst = std::max(out.worst, e.cwiseAbs().maxCoeff());
      sum2 += e.squaredNorm() / static_cast<double>(e.size());
      ++samples;
      for (int j = 0; j < v.size(); ++j)
        if (std::fabs(v[j]) > 0.5 * amp * w)
          out.min_mid_ratio = std::min(out.min_mid_ratio, tel.qd_cmd[static_cast<std::size_t>(j)] / v[j]);
    }
    CHECK(rig.tel().streaming);
  }
  out.rms = std::sqrt(sum2 / static_cast<double>(std::max(1L, samples)));
  out.peaks = peak_ratios(rig.trace, rig.svc().limits());
  rig.record = false;
  if (std::getenv("SERVOARM_STREAM_FIGURES") != nullptr)
    std::printf("\n30 Hz stream of a 0.5 Hz sine, %s: %s\n", with_qd ? "qd sent" : "qd estimated", out.figure().c_str());
  return out;
}

}  // namespace

TEST_GROUP(FwStream){};

// A 30 Hz stream of a 0.5 Hz sine is followed without coming to rest at each target: mid-swing
// the commanded velocity stays near the sine's (never zero between targets), the tracking error
// is small, and the setpoints stay within the velocity, acceleration and jerk limits; the same
// with the service estimating the velocity from the targets' times and with the client sending it.
TEST(FwStream, A30HzSineIsFollowedWithoutStoppingBetweenTargets) {
  for (const bool with_qd : {false, true}) {
    Rig rig;
    rig.enable();
    const SineRun r = run_sine(rig, with_qd);
    const std::string fig = std::string(with_qd ? "qd sent: " : "qd estimated: ") + r.figure();
    CHECK_TEXT(r.min_mid_ratio > 0.5, fig.c_str());
    CHECK_TEXT(r.worst < 0.05, fig.c_str());
    CHECK_TEXT(r.peaks.v <= 1.0 + 1e-6 && r.peaks.a <= 1.0 + 1e-3 && r.peaks.j <= 1.0 + 1e-2, fig.c_str());
  }
}

// Mid-swing the client stops sending: the target moves on at its velocity for at most its
// horizon, then the arm comes to rest near the last target and the deadman ends the stream, still
// within the limits.
TEST(FwStream, TheDeadmanStopsAMovingStream) {
  Rig rig;
  rig.enable();
  StreamService st(rig.svc(), *rig.app.ctl, rig.settings());
  kin::JointVector q = rig.q_cmd();
  rig.record = true;
  for (int i = 0; i < 30; ++i) {  // joint 0 at 1 rad/s, 30 Hz, with its velocity
    q[0] += 1.0 / 30;
    kin::JointVector qd = kin::JointVector::Zero(q.size());
    qd[0] = 1.0;
    CHECK(st.target(q, i == 0, qd).ok());
    for (int k = 0; k < 33; ++k) rig.cycle();
  }
  CHECK(std::fabs(rig.tel().qd_cmd[0]) > 0.5);
  for (int k = 0; k < 1000; ++k) rig.cycle();
  const Telemetry t = rig.tel();
  CHECK_EQUAL(static_cast<int>(ArmState::idle), static_cast<int>(t.state));
  CHECK(!t.streaming);
  DOUBLES_EQUAL(0.0, t.qd_cmd[0], 1e-9);
  // beyond the last target: at most its velocity for the deadman's 100 ms and a stop on the limits
  const kin::JointDynamics& d0 = rig.svc().limits().dyn[0];
  const Peaks p = peak_ratios(rig.trace, rig.svc().limits());
  const double vmax = p.v * d0.max_velocity;  // the fastest it went (catching up with the target)
  CHECK(t.q_cmd[0] < q[0] + 0.1 * 1.0 + vmax * vmax / (2 * d0.max_acceleration) + vmax * d0.max_acceleration / d0.max_jerk);
  CHECK(p.v <= 1.0 + 1e-6 && p.a <= 1.0 + 1e-3 && p.j <= 1.0 + 1e-2);
}

// 30 Hz with ±5 ms jitter for 4 s: the setpoints' velocity, acceleration and jerk (finite
// differences of q_cmd, cycle by cycle) never exceed the joints' limits, and the arm tracks.
TEST(FwStream, A30HzStreamWithJitterStaysWithinTheLimits) {
  Rig rig;
  rig.enable();
  StreamService st(rig.svc(), *rig.app.ctl, rig.settings());
  const kin::JointVector q0 = rig.q_cmd();
  std::mt19937 rng(38);
  std::uniform_real_distribution<double> jitter(-0.005, 0.005);
  rig.record = true;
  double t = 0;
  bool first = true;
  double worst_track = 0;
  while (t < 4.0) {
    const StreamResult r = st.target(sine(q0, t), first);
    CHECK_TEXT(r.ok(), r.reason.c_str());
    first = false;
    const double gap = 1.0 / 30 + jitter(rng);
    const auto before = rig.trace.size();
    while (static_cast<double>(rig.trace.size() - before) * 1e-3 < gap) rig.cycle();
    t += static_cast<double>(rig.trace.size() - before) * 1e-3;
    CHECK(rig.tel().streaming);
    if (t > 1.0) worst_track = std::max(worst_track, (rig.q_cmd() - sine(q0, t)).cwiseAbs().maxCoeff());
  }
  const kin::JointLimits& L = rig.svc().limits();
  const double dt = 1e-3;
  double rv = 0, ra = 0, rj = 0;  // peak / limit
  const auto& tr = rig.trace;
  for (std::size_t k = 3; k < tr.size(); ++k)
    for (int j = 0; j < 6; ++j) {
      const auto u = static_cast<std::size_t>(j);
      const double v = (tr[k][j] - tr[k - 1][j]) / dt;
      const double a = (tr[k][j] - 2 * tr[k - 1][j] + tr[k - 2][j]) / (dt * dt);
      const double jk = (tr[k][j] - 3 * tr[k - 1][j] + 3 * tr[k - 2][j] - tr[k - 3][j]) / (dt * dt * dt);
      rv = std::max(rv, std::fabs(v) / L.dyn[u].max_velocity);
      ra = std::max(ra, std::fabs(a) / L.dyn[u].max_acceleration);
      rj = std::max(rj, std::fabs(jk) / L.dyn[u].max_jerk);
    }
  const std::string fig = "peak/limit v " + std::to_string(rv) + " a " + std::to_string(ra) + " j " + std::to_string(rj) +
                          ", tracking error " + std::to_string(worst_track) + " rad";
  CHECK_TEXT(rv <= 1.0 + 1e-6 && ra <= 1.0 + 1e-3 && rj <= 1.0 + 1e-2, fig.c_str());
  CHECK_TEXT(rv > 0.05, fig.c_str());  // it did move
  CHECK_TEXT(worst_track < 0.2, fig.c_str());
  CHECK_EQUAL(static_cast<int>(ArmState::jogging), static_cast<int>(rig.tel().state));
}

// No target for the deadman time (100 ms): the arm brakes to rest on its limits, the stream
// ends with an event, and a target without `start` is refused and does not move it.
TEST(FwStream, TheDeadmanBrakesToRestWithAnEvent) {
  Rig rig;
  rig.enable();
  StreamService st(rig.svc(), *rig.app.ctl, rig.settings());
  kin::JointVector q = rig.q_cmd();
  const std::uint64_t seq0 = rig.svc().next_event_seq();
  for (int i = 0; i < 30; ++i) {  // joint 0 at a steady pace, 100 Hz
    q[0] += 0.02;
    CHECK(st.target(q, i == 0).ok());
    rig.run(0.01);
  }
  CHECK(std::fabs(rig.tel().qd_cmd[0]) > 0.5);
  rig.run(0.09);
  CHECK(rig.tel().streaming);  // within the deadman time still tracking
  rig.run(1.0);
  const Telemetry t = rig.tel();
  CHECK_EQUAL(static_cast<int>(ArmState::idle), static_cast<int>(t.state));
  CHECK(!t.streaming);
  DOUBLES_EQUAL(0.0, t.qd_cmd[0], 1e-9);
  rig.svc().poll_events();
  const EventBatch b = rig.svc().events_since(seq0 - 1);
  bool said = false;
  for (const ArmEvent& e : b.events)
    said = said || (e.kind == ArmEventKind::jog_stopped && rig.svc().event_detail(e).find("stream stopped: no target within its deadman time (100 ms)") != std::string_view::npos);
  CHECK(said);
  const kin::JointVector rest = rig.q_cmd();
  q[0] += 0.02;
  const StreamResult r = st.target(q, false);
  CHECK_EQUAL(static_cast<int>(CmdError::bad_state), static_cast<int>(r.error));
  CHECK_TEXT(r.reason.find("the stream ended") != std::string::npos, r.reason.c_str());
  rig.run(0.2);
  CHECK((rig.q_cmd() - rest).cwiseAbs().maxCoeff() < 1e-12);
  CHECK(st.target(q, true).ok());  // a new stream starts when asked
}

// A stop ends the stream at once: the arm ramps to rest and targets that keep coming do not
// move it again.
TEST(FwStream, AStopWins) {
  Rig rig;
  rig.enable();
  StreamService st(rig.svc(), *rig.app.ctl, rig.settings());
  kin::JointVector q = rig.q_cmd();
  for (int i = 0; i < 20; ++i) {
    q[0] += 0.01;
    CHECK(st.target(q, i == 0).ok());
    rig.run(0.01);
  }
  // Where a stop from here can get to: its braking distance on joint 0's limits.
  const kin::JointDynamics& d0 = rig.svc().limits().dyn[0];
  const double v0 = std::fabs(rig.tel().qd_cmd[0]);
  const double reach = rig.tel().q_cmd[0] + v0 * v0 / (2 * d0.max_acceleration) + v0 * d0.max_acceleration / d0.max_jerk;
  CHECK(rig.svc().control(RequestOp::stop).ok());
  for (int i = 0; i < 40; ++i) {  // the client keeps streaming
    q[0] += 0.01;
    const StreamResult r = st.target(q, false);
    CHECK_EQUAL(static_cast<int>(CmdError::bad_state), static_cast<int>(r.error));
    rig.run(0.01);
  }
  const Telemetry t = rig.tel();
  CHECK_EQUAL(static_cast<int>(ArmState::idle), static_cast<int>(t.state));
  CHECK(t.q_cmd[0] <= reach + 1e-9);  // stopped on its limits: the targets sent after the stop did not move it
  CHECK(t.q_cmd[0] < q[0] - 0.2);  // long before the targets sent after the stop
}

// Targets outside the joint limits are refused; a step beyond max_step is clamped, or refused
// when so configured; a wrong joint count or NaN is refused; nothing moves on a refusal.
TEST(FwStream, BadTargetsAreRefused) {
  Rig rig;
  rig.enable();
  StreamSettings s = rig.settings();
  StreamService st(rig.svc(), *rig.app.ctl, s);
  kin::JointVector q = rig.q_cmd();
  kin::JointVector far = q;
  far[0] = 100;
  CHECK_EQUAL(static_cast<int>(CmdError::limits), static_cast<int>(st.target(far, true).error));
  CHECK_EQUAL(static_cast<int>(CmdError::arg_count), static_cast<int>(st.target(kin::JointVector::Zero(5), true).error));
  kin::JointVector nan = q;
  nan[2] = std::nan("");
  CHECK_EQUAL(static_cast<int>(CmdError::not_finite), static_cast<int>(st.target(nan, true).error));
  rig.run(0.1);
  CHECK_EQUAL(static_cast<int>(ArmState::idle), static_cast<int>(rig.tel().state));
  kin::JointVector jump = q;
  jump[0] += 1.5;
  const StreamResult c = st.target(jump, true);
  CHECK(c.ok() && c.clamped);
  kin::JointVector held = q;
  held[0] += 0.5;
  for (int i = 0; i < 100; ++i) {  // the clamped target, kept: the arm gets there and holds
    CHECK(st.target(held, false).ok());
    rig.run(0.02);
  }
  DOUBLES_EQUAL(q[0] + 0.5, rig.q_cmd()[0], 1e-6);
  CHECK(rig.tel().streaming);
  s.clamp_step = false;
  StreamService strict(rig.svc(), *rig.app.ctl, s);
  const StreamResult r = strict.target(jump + kin::JointVector::Constant(6, 0.0), true);
  CHECK_EQUAL(static_cast<int>(CmdError::out_of_range), static_cast<int>(r.error));
}

// The safety envelope (docs/safety.md) checks each streamed target before the control thread
// gets it: a target whose tool sphere is beyond a plane is refused with the plane's line, the
// stream keeps its last target, and the arm stays on the allowed side.
TEST(FwStream, ATargetBeyondASafetyPlaneIsRefused) {
  double z0 = 0;
  kin::JointVector q0;
  {
    Rig plain;
    plain.enable();
    q0 = plain.q_cmd();
    kin::Pose p;
    CHECK(kin::forward(plain.svc().tool_chain(plain.svc().active_tool()), q0, p) == kin::Status::ok);
    z0 = p.translation().z();
  }
  FwConfig c;
  c.safety_planes = {0, 0, -1, -(z0 * 1000.0 + 30.0)};  // a ceiling 30 mm above the tool: z <= z0 + 30 mm
  c.safety_tool_radius_mm = 10;
  Rig rig(c);
  rig.enable();
  const kin::Chain& ch = rig.svc().tool_chain(rig.svc().active_tool());
  auto z_of = [&](const kin::JointVector& q) {
    kin::Pose p;
    CHECK(kin::forward(ch, q, p) == kin::Status::ok);
    return p.translation().z();
  };
  // a target that lifts the tool 40 mm or more (the shoulder or the elbow, within 0.3 rad)
  kin::JointVector up = q0;
  bool found = false;
  for (int j = 1; j <= 2 && !found; ++j)
    for (const double d : {0.3, -0.3}) {
      kin::JointVector q = q0;
      q[j] += d;
      if (z_of(q) > z0 + 0.040) {
        up = q;
        found = true;
        break;
      }
    }
  CHECK_TEXT(found, "no 0.3 rad shoulder or elbow step lifts the tool 40 mm");
  StreamService st(rig.svc(), *rig.app.ctl, rig.settings());
  CHECK(st.target(q0, true).ok());
  rig.run(0.05);
  const StreamResult r = st.target(up, false);
  CHECK_FALSE(r.ok());
  CHECK_EQUAL(static_cast<int>(CmdError::limits), static_cast<int>(r.error));
  STRCMP_CONTAINS("safety plane 0", r.reason.c_str());
  rig.run(0.5);
  CHECK(z_of(rig.q_cmd()) < z0 + 0.030);
}

// Targets that reach the service in pairs (as when they are delayed on the way: two together,
// then a gap of two periods) at a steady 1 rad/s: the estimated velocity is the pace's, not the
// pair's (a small step over a very short time), so the commanded velocity stays near 1 rad/s.
TEST(FwStream, TargetsArrivingInPairsAreNotABurstOfSpeed) {
  Rig rig;
  rig.enable();
  StreamService st(rig.svc(), *rig.app.ctl, rig.settings());
  kin::JointVector q = rig.q_cmd();
  double peak = 0;
  for (int i = 0; i < 40; ++i) {  // 30 Hz pace: 1/30 rad each, sent two at a time
    for (int k = 0; k < 2; ++k) {
      q[0] += 1.0 / 30;
      CHECK(st.target(q, i == 0 && k == 0).ok());
      rig.cycle();
    }
    for (int k = 0; k < 65; ++k) {
      rig.cycle();
      if (i > 10) peak = std::max(peak, std::fabs(rig.tel().qd_cmd[0]));
    }
  }
  CHECK_TEXT(peak < 1.4, ("peak commanded velocity " + std::to_string(peak) + " rad/s at a 1 rad/s pace").c_str());
}

// Cartesian targets: a 30 Hz stream of tool poses (a 30 mm circle in the base frame's x-y plane,
// the orientation kept) is solved by the service's IK with the active tool and followed: the tool
// point by forward kinematics of q_cmd stays within a few mm of the circle. A pose out of reach,
// NaN, and a pose whose solution is a large joint step are refused with one line and do not move
// the arm (it keeps tracking its last target).
TEST(FwStream, CartesianTargetsAreSolvedAndFollowed) {
  Rig rig;
  rig.enable();
  StreamService st(rig.svc(), *rig.app.ctl, rig.settings());
  const kin::Chain& ch = rig.svc().tool_chain(rig.svc().active_tool());
  kin::Pose p0;
  CHECK(kin::forward(ch, rig.q_cmd(), p0) == kin::Status::ok);
  auto circle = [&](double t) {
    kin::Pose p = p0;
    p.translation() += Eigen::Vector3d(0.03 * (std::cos(2 * M_PI * 0.5 * t) - 1), 0.03 * std::sin(2 * M_PI * 0.5 * t), 0);
    return p;
  };
  double t = 0, worst = 0;
  bool first = true;
  while (t < 3.0) {
    const StreamResult r = st.target_pose(circle(t), false, first);
    CHECK_TEXT(r.ok(), r.reason.c_str());
    first = false;
    for (int k = 0; k < 33; ++k) {
      rig.cycle();
      t += 1e-3;
      kin::Pose p;
      CHECK(kin::forward(ch, rig.q_cmd(), p) == kin::Status::ok);
      if (t > 0.5) worst = std::max(worst, (p.translation() - circle(t).translation()).norm());
    }
  }
  const std::string fig = "tool point off the circle by up to " + std::to_string(worst * 1e3) + " mm";
  CHECK_TEXT(worst < 0.005, fig.c_str());
  CHECK_TEXT(worst > 0, fig.c_str());
  // bad poses: refused, the stream holds its last target
  const kin::JointVector before = rig.q_cmd();
  kin::Pose far = circle(t);
  far.translation() += Eigen::Vector3d(5, 0, 0);
  const StreamResult u = st.target_pose(far, false, false);
  CHECK_EQUAL(static_cast<int>(CmdError::unreachable), static_cast<int>(u.error));
  CHECK(u.reason.find('\n') == std::string::npos && !u.reason.empty());
  kin::Pose nan = circle(t);
  nan.translation().x() = std::nan("");
  CHECK_EQUAL(static_cast<int>(CmdError::not_finite), static_cast<int>(st.target_pose(nan, false, false).error));
  kin::Pose flipped = circle(t);  // the tool turned half round about z: far in joint space
  flipped.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitZ()).toRotationMatrix() * flipped.linear();
  const StreamResult f = st.target_pose(flipped, false, false);
  CHECK_FALSE(f.ok());
  for (int k = 0; k < 60; ++k) rig.cycle();
  kin::Pose p;
  CHECK(kin::forward(ch, rig.q_cmd(), p) == kin::Status::ok);
  CHECK((p.translation() - circle(t).translation()).norm() < 0.01);  // near the last good target
  CHECK((rig.q_cmd() - before).cwiseAbs().maxCoeff() < 0.05);
}

// A pose in the active user frame: the frame's pose applied, the same joints as the base pose.
TEST(FwStream, ACartesianTargetInTheActiveFrame) {
  Rig rig;
  rig.enable();
  kin::Pose F = kin::Pose::Identity();
  F.translation() = Eigen::Vector3d(0.1, -0.05, 0.02);
  F.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  NamedPose def;
  def.name = "table";
  def.pose = F;
  CHECK(rig.svc().define_frame(def).ok());
  CHECK(rig.svc().select_frame("table").ok());
  StreamService st(rig.svc(), *rig.app.ctl, rig.settings());
  const kin::Chain& ch = rig.svc().tool_chain(rig.svc().active_tool());
  kin::Pose p0;
  CHECK(kin::forward(ch, rig.q_cmd(), p0) == kin::Status::ok);
  kin::Pose goal = p0;
  goal.translation() += Eigen::Vector3d(0, 0, 0.02);
  for (int i = 0; i < 30; ++i) {
    CHECK(st.target_pose(F.inverse() * goal, true, i == 0).ok());
    rig.run(0.02);
  }
  kin::Pose p;
  CHECK(kin::forward(ch, rig.q_cmd(), p) == kin::Status::ok);
  CHECK((p.translation() - goal.translation()).norm() < 1e-4);
}

namespace {

/// A client sampling a 0.5 Hz, 0.4 rad sine (every joint, phases 0.5 rad apart) at a steady 30 Hz
/// whose targets reach the service 0 to 12 ms after they were sampled (a loaded machine's
/// scheduling, a network), in order, for 4 s; the targets carry their sampling time
/// (`timed`, on a clock 100 s from the sine's origin) or not. Over the last 3 s: the commanded
/// velocity's ripple (RMS of qd_cmd against the sine's velocity at the same instant), the largest
/// change of the commanded acceleration within a cycle (jerk), and the tracking error.
struct JitterRun {
  double v_ripple = 0, a_ripple = 0, worst = 0, rms = 0;
  Peaks peaks;
  StreamStats stats;
  std::string figure() const {
    char b[320];
    std::snprintf(b, sizeof b,
                  "velocity ripple rms %.4f rad/s, acceleration ripple rms %.3f rad/s^2, tracking error max %.4f rms %.4f "
                  "rad, peak/limit v %.3f a %.3f j %.3f, late max %.1f ms jitter %.2f ms, stale %llu",
                  v_ripple, a_ripple, worst, rms, peaks.v, peaks.a, peaks.j, stats.late_max_s * 1e3, stats.jitter_s * 1e3,
                  static_cast<unsigned long long>(stats.stale));
    return b;
  }
};
JitterRun run_jittered_arrival(Rig& rig, bool timed) {
  StreamService st(rig.svc(), *rig.app.ctl, rig.settings());
  const kin::JointVector q0 = rig.q_cmd();
  const double amp = 0.4, w = 2 * M_PI * 0.5, T = 1.0 / 30;
  auto at = [&](double t) {
    kin::JointVector q = q0;
    for (int j = 0; j < q.size(); ++j) q[j] += amp * std::sin(w * t + 0.5 * j);
    return q;
  };
  auto vel = [&](double t) {
    kin::JointVector v = kin::JointVector::Zero(q0.size());
    for (int j = 0; j < v.size(); ++j) v[j] = amp * w * std::cos(w * t + 0.5 * j);
    return v;
  };
  auto acc = [&](double t) {
    kin::JointVector a = kin::JointVector::Zero(q0.size());
    for (int j = 0; j < a.size(); ++j) a[j] = -amp * w * w * std::sin(w * t + 0.5 * j);
    return a;
  };
  std::mt19937 rng(38);
  std::uniform_real_distribution<double> delay(0.0, 0.012);
  JitterRun out;
  rig.record = true;
  rig.trace.clear();
  double sv = 0, sa = 0, se = 0;
  long samples = 0;
  int k = 0;
  double arrive = delay(rng);
  kin::JointVector qd_prev = kin::JointVector::Zero(q0.size());
  // the control thread's clock is the time base (a request to it runs cycles of its own here)
  const std::uint64_t c0 = rig.tel().cycles;
  auto clock_s = [&] { return static_cast<double>(rig.tel().cycles - c0) * 1e-3; };
  double t_prev = 0;
  while (clock_s() < 4.0) {
    const double now = clock_s();
    while (now >= arrive) {  // every target due by now, oldest first
      const double ts = k * T;
      const StreamResult r = st.target(at(ts), k == 0, kin::JointVector(), timed ? std::optional<double>(100.0 + ts) : std::nullopt);
      CHECK_TEXT(r.ok() && !r.stale, r.reason.c_str());
      out.stats = r.stats;
      ++k;
      arrive = k * T + delay(rng);
    }
    rig.cycle();
    const Telemetry tel = rig.tel();
    kin::JointVector qd(tel.n);
    for (int j = 0; j < tel.n; ++j) qd[j] = tel.qd_cmd[static_cast<std::size_t>(j)];
    const double t = clock_s();
    const double dt = t - t_prev;  // one cycle, or more when a target's request ran cycles
    if (t >= 1.0) {
      const kin::JointVector e = rig.q_cmd() - at(t), ev = qd - vel(t), ea = (qd - qd_prev) / dt - acc(t - 0.5 * dt);
      out.worst = std::max(out.worst, e.cwiseAbs().maxCoeff());
      se += e.squaredNorm() / static_cast<double>(e.size());
      sv += ev.squaredNorm() / static_cast<double>(ev.size());
      sa += ea.squaredNorm() / static_cast<double>(ea.size());
      ++samples;
    }
    qd_prev = qd;
    t_prev = t;
    CHECK(k == 0 || tel.streaming);
  }
  const double n = static_cast<double>(std::max(1L, samples));
  out.v_ripple = std::sqrt(sv / n);
  out.a_ripple = std::sqrt(sa / n);
  out.rms = std::sqrt(se / n);
  out.peaks = peak_ratios(rig.trace, rig.svc().limits());
  rig.record = false;
  if (std::getenv("SERVOARM_STREAM_FIGURES") != nullptr)
    std::printf("\n30 Hz sine sampled on time, delivered 0-12 ms late, %s: %s\n", timed ? "with t" : "without t",
                out.figure().c_str());
  return out;
}

}  // namespace

// Targets sampled at a steady 30 Hz but delivered 0 to 12 ms late: spaced by their arrival, the
// velocity estimate swings with the delivery (a 33 ms interval read as 21 to 45 ms) and a late
// target pulls the moving target back; spaced by the client's times and moved on by their
// velocity over their delay, the commanded path is smoother: its velocity and acceleration
// ripple against the sine are well below the arrival-spaced run's, within the same limits.
TEST(FwStream, ClientTimesSmoothAJitteredArrival) {
  JitterRun without, with;
  {
    Rig rig;
    rig.enable();
    without = run_jittered_arrival(rig, false);
  }
  {
    Rig rig;
    rig.enable();
    with = run_jittered_arrival(rig, true);
  }
  const std::string fig = "without t: " + without.figure() + "; with t: " + with.figure();
  CHECK_TEXT(with.v_ripple < 0.5 * without.v_ripple, fig.c_str());
  CHECK_TEXT(with.a_ripple < 0.7 * without.a_ripple, fig.c_str());
  CHECK_TEXT(with.rms < without.rms, fig.c_str());
  CHECK_TEXT(with.peaks.v <= 1.0 + 1e-6 && with.peaks.a <= 1.0 + 1e-3 && with.peaks.j <= 1.0 + 1e-2, fig.c_str());
  // the service saw the delivery: delays up to the 12 ms given, none stale
  CHECK_TEXT(with.stats.late_max_s > 0.008 && with.stats.late_max_s < 0.0125, fig.c_str());
  CHECK_TEXT(with.stats.jitter_s > 0.002 && with.stats.jitter_s < 0.005, fig.c_str());
  CHECK_EQUAL(0u, with.stats.stale);
  CHECK_EQUAL(with.stats.targets, with.stats.timed);
}

// A timed target older than, or as old as, the stream's newest is dropped: answered ok with
// `stale`, counted, never sent (the arm keeps tracking the newest); `start` begins a new clock.
TEST(FwStream, AnOutOfOrderTargetIsDroppedAndCounted) {
  Rig rig;
  rig.enable();
  StreamService st(rig.svc(), *rig.app.ctl, rig.settings());
  const kin::JointVector q0 = rig.q_cmd(), rest = kin::JointVector::Zero(q0.size());
  kin::JointVector q1 = q0, far = q0;
  q1[0] += 0.05;
  far[0] += 0.3;
  rig.record = true;
  CHECK(st.target(q0, true, rest, 5.0).ok());
  rig.run(0.02);
  CHECK(st.target(q1, false, rest, 5.02).ok());
  rig.run(0.01);
  const StreamResult older = st.target(far, false, rest, 5.01);
  CHECK_TEXT(older.ok(), older.reason.c_str());
  CHECK(older.stale);
  CHECK_EQUAL(1u, older.stats.stale);
  const StreamResult same = st.target(far, false, rest, 5.02);
  CHECK(same.ok() && same.stale);
  CHECK_EQUAL(2u, same.stats.stale);
  CHECK_EQUAL(2u, same.stats.targets);
  for (int i = 1; i <= 30; ++i) {  // the newest target, kept alive
    const StreamResult r = st.target(q1, false, rest, 5.02 + 0.01 * i);
    CHECK(r.ok() && !r.stale);
    rig.run(0.01);
  }
  double top = -1e9;
  for (const kin::JointVector& q : rig.trace) top = std::max(top, q[0]);
  DOUBLES_EQUAL(q1[0], rig.q_cmd()[0], 1e-6);
  CHECK_TEXT(top <= q1[0] + 1e-9, ("joint 0 went to " + std::to_string(top) + " beyond the newest target").c_str());
  CHECK_EQUAL(2u, st.stats().stale);
  // a new stream, a new clock: an earlier time is its first target, counts start again
  const StreamResult again = st.target(q1, true, rest, 1.0);
  CHECK(again.ok() && !again.stale);
  CHECK_EQUAL(0u, again.stats.stale);
  CHECK_EQUAL(1u, again.stats.targets);
}

// A bad time is refused with one line and moves nothing: NaN (not_finite), negative and a jump
// of the client's clock far beyond the control thread's (out_of_range); the stream keeps its last
// target and goes on with the next good one.
TEST(FwStream, ABadClientTimeIsRefused) {
  Rig rig;
  rig.enable();
  StreamService st(rig.svc(), *rig.app.ctl, rig.settings());
  const kin::JointVector q0 = rig.q_cmd(), rest = kin::JointVector::Zero(q0.size());
  kin::JointVector q1 = q0;
  q1[0] += 0.2;
  CHECK(st.target(q0, true, rest, 50.0).ok());
  rig.run(0.02);
  struct Case {
    double t;
    CmdError error;
    const char* says;
  };
  const Case cases[] = {{std::nan(""), CmdError::not_finite, "t: not finite"},
                        {std::numeric_limits<double>::infinity(), CmdError::not_finite, "t: not finite"},
                        {-0.5, CmdError::out_of_range, "t: -0.5 s is negative"},
                        {50.0 + 3600, CmdError::out_of_range, "s ahead of the control thread's clock"},
                        {50.0 + 1.5, CmdError::out_of_range, "s ahead of the control thread's clock"}};
  for (const Case& c : cases) {
    const StreamResult r = st.target(q1, false, rest, c.t);
    const std::string what = std::to_string(c.t) + ": " + r.reason;
    CHECK_EQUAL_TEXT(static_cast<int>(c.error), static_cast<int>(r.error), what.c_str());
    CHECK_TEXT(r.reason.find(c.says) != std::string::npos && r.reason.find('\n') == std::string::npos, what.c_str());
    rig.run(0.01);
  }
  CHECK((rig.q_cmd() - q0).cwiseAbs().maxCoeff() < 1e-9);  // nothing moved
  CHECK(rig.tel().streaming);
  // within the allowance (the client's clock 0.5 s ahead after 70 ms): taken
  const StreamResult ok = st.target(q1, false, rest, 50.0 + 0.57);
  CHECK_TEXT(ok.ok() && !ok.stale, ok.reason.c_str());
  rig.run(0.05);
  CHECK(rig.q_cmd()[0] > q0[0]);
}
