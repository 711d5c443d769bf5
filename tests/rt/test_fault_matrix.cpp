// SPDX-License-Identifier: Apache-2.0
// Fault matrix: every arm state crossed with every fault the rig can inject, each cell
// asserted against a reaction written out by hand below (not read from the controller).
// Rig: puma560 on the in-process bus with virtual CiA 402 drives, ManualClock, the
// controller on a FaultBus (this file) between it and the CANopen master, which injects
// the faults the virtual drives cannot (frozen feedback, a jammed joint, bus-off) and
// records every setpoint vector written.
//
// States: disabled (then an enable is requested, so the latent faults show), enabling
// (one cycle after `enable`), idle, moving joint (a second move queued behind), moving
// linear (a joint move queued behind), jogging (continuous joint 1 jog), holding (held at
// rest, the move and a second one queued), stopping (the ramp of `stop`).
// Faults on joint k: drive fault (EMCY 0x2310, the drive goes to FAULT), heartbeat loss
// (the heartbeat producer stops, PDOs go on), node silent (unplugged: nothing sent,
// nothing heard), feedback stale (the joint's feedback frozen, heartbeat alive), bus-off
// (every write answers Status::bus_off), a drive refusing to enable, a jammed joint
// (its drive holds where it is: the following error grows while the arm moves), e-stop,
// a cycle overrun (the loop stalls 20 ms, the loop reports 20 missed deadlines), the safety
// envelope switched to Reduced mode (`safety reduced`) whose joint speed limits (1 deg/s) the
// running motion exceeds: a protective stop (docs/safety.md), not a fault.
//
// Checked in each cell, after a fixed number of cycles (the same in a baseline run of
// the state without a fault):
//  - the coarse state (ArmState) after;
//  - the drives powered or not, read from the virtual drives themselves (CiA 402 state),
//    not from the controller's view (an unplugged drive is left out: nothing reaches it);
//  - fault cells: Telemetry cause and joint, the fault text names the joint, one fault
//    event with that cause and joint, the motion queue empty and its moves dropped (none
//    of them finished), the generation bumped; e-stop: the estop event, queue dropped;
//  - protective-stop cells: at rest, powered and idle, no fault, the queue empty and its moves
//    dropped, one event (motion_refused, jog_stopped for a jog) naming the protective stop and
//    the joint speed, one safety stop counted;
//  - no-reaction cells: no fault, no fault event, the same state, finished moves and
//    commanded position as the baseline;
//  - every cycle: no setpoint step larger than the joint's velocity limit x one period
//    (checked on the setpoints the controller wrote, from the cycle before the fault on).
// Every control cycle runs inside the allocation counter.
#include <array>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "alloc_counter.hpp"
#include "sim_app.hpp"
#include "servoarm/rt/controller.hpp"
#include "servoarm/rt/mode_table.hpp"
#include "servoarm/kinematics/ik.hpp"
#include "servoarm/kinematics/chain.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;

namespace {

constexpr double kDeg = M_PI / 180.0;

// Between the controller and the CANopen master: fault injection the drives cannot do
// themselves, and a record of every setpoint vector written.
class FaultBus final : public hal::ServoBus {
 public:
  explicit FaultBus(hal::ServoBus& inner) : inner_(inner) { writes.reserve(1 << 14); }

  std::size_t joint_count() const override { return inner_.joint_count(); }
  hal::Status start(hal::TimePoint deadline) override { return inner_.start(deadline); }
  void enable() override { inner_.enable(); }
  void disable() override {
    ++disables;
    inner_.disable();
  }
  void quick_stop() override { inner_.quick_stop(); }
  hal::Status read(hal::TimePoint now) override {
    const hal::Status st = inner_.read(now);
    if (stale_ >= 0) frozen_.age = now - frozen_.last_feedback;  // the frame that never comes
    return st;
  }
  hal::Status write(std::span<const double> setpoints, hal::TimePoint now) override {
    std::array<double, hal::kMaxServoJoints> sp{};
    for (std::size_t j = 0; j < setpoints.size() && j < sp.size(); ++j) sp[j] = setpoints[j];
    if (writes.size() < writes.capacity()) writes.push_back(sp);
    if (jam_ >= 0) sp[static_cast<std::size_t>(jam_)] = jam_at_;  // the drive cannot follow
    const hal::Status st = inner_.write(std::span<const double>(sp.data(), setpoints.size()), now);
    return bus_off_ ? hal::Status::bus_off : st;  // (the frames still go out, as in ServoSpy)
  }
  hal::Status set_position_zero(std::size_t j) override { return inner_.set_position_zero(j); }
  std::int64_t zero_offset(std::size_t j) const override { return inner_.zero_offset(j); }
  const hal::JointFeedback& feedback(std::size_t j) const override {
    return static_cast<int>(j) == stale_ ? frozen_ : inner_.feedback(j);
  }
  const char* last_error() const override { return inner_.last_error(); }

  void freeze_feedback(int j) {
    frozen_ = inner_.feedback(static_cast<std::size_t>(j));
    stale_ = j;
  }
  void jam(int j) {
    jam_at_ = inner_.feedback(static_cast<std::size_t>(j)).position;
    jam_ = j;
  }
  void set_bus_off() { bus_off_ = true; }

  std::vector<std::array<double, hal::kMaxServoJoints>> writes;
  int disables = 0;

 private:
  hal::ServoBus& inner_;
  int stale_ = -1;
  hal::JointFeedback frozen_{};
  int jam_ = -1;
  double jam_at_ = 0;
  bool bus_off_ = false;
};

enum class St : std::uint8_t { disabled, enabling, idle, moving_joint, moving_linear, jogging, holding, stopping };
enum class Fx : std::uint8_t {
  none,  // the baseline
  drive_fault,
  heartbeat_loss,
  node_silent,
  feedback_stale,
  bus_off,
  refuse_enable,
  jammed_joint,
  estop,
  overrun,
  reduced_mode,
};
const char* name(St s) {
  switch (s) {
    case St::disabled: return "disabled";
    case St::enabling: return "enabling";
    case St::idle: return "idle";
    case St::moving_joint: return "moving joint";
    case St::moving_linear: return "moving linear";
    case St::jogging: return "jogging";
    case St::holding: return "holding";
    case St::stopping: return "stopping";
  }
  return "?";
}
const char* name(Fx f) {
  switch (f) {
    case Fx::none: return "none";
    case Fx::drive_fault: return "drive fault";
    case Fx::heartbeat_loss: return "heartbeat loss";
    case Fx::node_silent: return "node silent";
    case Fx::feedback_stale: return "feedback stale";
    case Fx::bus_off: return "bus-off";
    case Fx::refuse_enable: return "refuses enable";
    case Fx::jammed_joint: return "jammed joint";
    case Fx::estop: return "e-stop";
    case Fx::overrun: return "cycle overrun";
    case Fx::reduced_mode: return "reduced mode";
  }
  return "?";
}

constexpr std::uint32_t kQueuedId = 7;   // the move queued behind the running one
constexpr int kSettleCycles = 2600;       // after the fault: > enable_timeout (2 s) + a stop
constexpr int kEnableAfter = 300;         // disabled row: cycles before the enable request
constexpr hal::Duration kStall = 20 * hal::kMillisecond;

struct Rig {
  hal::ManualClock clock;
  test::SimApp app;
  std::unique_ptr<FaultBus> bus;
  std::unique_ptr<Controller> ctl;
  hal::Duration period = hal::kMillisecond;
  std::uint32_t seq = 100;
  std::size_t rt_allocs = 0;
  std::vector<Event> events;   // every event, in order
  struct CycleRec {
    Mode mode;
    unsigned powered;   // bit j: virtual drive j powered after the cycle's frames
    std::size_t write;  // index of the cycle's setpoint vector in bus->writes
  };
  std::vector<CycleRec> recs;  // one per cycle, parallel to bus->writes
  std::size_t events_at_fault = 0;

  Rig() {
    FwConfig cfg;
    cfg.can = "sim";
    cfg.following_error_deg = 2.0;  // the jammed joint trips within the stop ramps
    // a safety envelope with no Normal limits (the baseline moves as without one) and Reduced
    // joint speed limits every motion here exceeds
    cfg.safety_reduced_joint_speed_deg_s = {1, 1, 1, 1, 1, 1};
    const std::string e = app.build(cfg, &clock);
    if (!e.empty()) FAIL(e.c_str());
    clock.set_idle_hook([this](hal::TimePoint t) { app.plant->step(t); });
    recs.reserve(1 << 14);
    bus = std::make_unique<FaultBus>(*app.servo);
    ctl = std::make_unique<Controller>(*bus, app.chain, app.controller_config());
    const hal::TimePoint now = clock.now();
    if (ctl->boot(now, now + 5 * hal::kSecond) != hal::Status::ok) FAIL(bus->last_error());
  }
  ~Rig() {
    clock.set_idle_hook(nullptr);
    ctl.reset();
  }
  void cycle() {
    test::alloc_count_begin();
    ctl->cycle(clock.now());
    rt_allocs += test::alloc_count_end();
    clock.advance(period);
    if (recs.size() < recs.capacity()) recs.push_back(CycleRec{ctl->mode(), powered_mask(), bus->writes.size() - 1});
    Event ev;
    while (ctl->events().pop(ev)) events.push_back(ev);
    Reply rep;
    while (ctl->replies().pop(rep)) {
    }
  }
  void cycles(int n) {
    for (int i = 0; i < n; ++i) cycle();
  }
  void request(RequestOp op, const JogSpec* jog = nullptr) {
    Request r;
    r.op = op;
    r.seq = ++seq;
    if (jog != nullptr) r.jog = *jog;
    if (!ctl->requests().push(r)) FAIL("request queue full");
    cycle();
  }
  void run_until(Mode m, int max_cycles, const char* what) {
    for (int i = 0; i < max_cycles && ctl->mode() != m; ++i) cycle();
    if (ctl->mode() != m) FAIL((std::string(what) + ": mode " + to_string(ctl->mode()) + ", wanted " + to_string(m)).c_str());
  }
  kin::JointVector q_cmd() const {
    const Telemetry t = ctl->telemetry();
    kin::JointVector q(6);
    for (int j = 0; j < 6; ++j) q[j] = t.q_cmd[static_cast<std::size_t>(j)];
    return q;
  }
  void queue_joint_move(std::uint32_t id, const kin::JointVector& goal) {
    MotionItem* m = ctl->motions().back();
    if (m == nullptr) FAIL("motion queue full");
    JointMove& jm = m->payload.emplace<JointMove>();
    m->id = id;
    jm.override = 1.0;
    jm.goal = goal;
    ctl->motions().commit();
  }
  void enable() {
    request(RequestOp::enable);
    run_until(Mode::idle, 3000, "enable");
  }
  void start_joint_move() {
    kin::JointVector goal = q_cmd();
    for (int j = 0; j < 6; ++j) goal[j] += (j % 2 ? -40.0 : 40.0) * kDeg;
    queue_joint_move(1, goal);
    kin::JointVector back = goal;
    for (int j = 0; j < 6; ++j) back[j] -= 5.0 * kDeg;
    queue_joint_move(kQueuedId, back);
    cycles(150);
    if (ctl->mode() != Mode::moving) FAIL("joint move not running");
  }
  void start_line() {
    kin::JointVector work(6);
    work << 20, -40, 160, 10, -50, 30;
    work *= kDeg;
    queue_joint_move(1, work);
    cycle();
    run_until(Mode::idle, 10000, "move to the working pose");
    MotionItem* m = ctl->motions().back();
    kin::Pose p;
    kin::forward(app.chain, q_cmd(), p);
    p.translation().x() += 0.06;
    const kin::IkSolver ik{&kin::ik_nearest_fn, app.ik.get()};
    kin::CartesianTrajectory& path = m->payload.emplace<CartesianMove>().path;
    const kin::MotionStatus st = kin::plan_movel(app.chain, q_cmd(), p, kin::CartesianLimits{}, kin::MovelOptions{}, ik, path);
    if (!kin::is_ok(st)) FAIL(kin::to_string(st));
    m->id = 2;
    ctl->motions().commit();
    queue_joint_move(kQueuedId, work);
    cycles(100);
    if (ctl->mode() != Mode::moving) FAIL("line not running");
  }
  void start_jog() {
    JogSpec js;  // joint 1 towards its upper limit, continuous, a deadman longer than the test
    js.space = JogSpace::joint;
    js.continuous = true;
    js.deadman_s = 60;
    js.q_goal = q_cmd();
    js.q_goal[0] = kin::limits_from(app.chain).upper[0];
    js.override = 0.3;
    request(RequestOp::jog, &js);
    cycles(150);
    if (ctl->mode() != Mode::jogging) FAIL("jog not running");
  }
  void enter(St s) {
    cycles(20);  // position feedback from every drive
    switch (s) {
      case St::disabled: return;
      case St::enabling:
        request(RequestOp::enable);
        if (ctl->mode() != Mode::enabling) FAIL("not enabling");
        return;
      case St::idle: enable(); return;
      case St::moving_joint:
        enable();
        start_joint_move();
        return;
      case St::moving_linear:
        enable();
        start_line();
        return;
      case St::jogging:
        enable();
        start_jog();
        return;
      case St::holding:
        enable();
        start_joint_move();
        request(RequestOp::hold);
        run_until(Mode::held, 3000, "hold");
        return;
      case St::stopping:
        enable();
        start_joint_move();
        request(RequestOp::stop);
        if (ctl->mode() != Mode::stopping_to_idle) FAIL("not stopping");
        return;
    }
  }
  void inject(Fx f, int k) {
    switch (f) {
      case Fx::none: break;
      case Fx::drive_fault: app.plant->inject_emcy(k, 0x2310); break;
      case Fx::heartbeat_loss: app.plant->inject_heartbeat_stop(k); break;
      case Fx::node_silent: app.plant->inject_silent(k); break;
      case Fx::feedback_stale: bus->freeze_feedback(k); break;
      case Fx::bus_off: bus->set_bus_off(); break;
      case Fx::refuse_enable: app.plant->arm().at(static_cast<std::size_t>(k)).faults().refuse_enable = true; break;
      case Fx::jammed_joint: bus->jam(k); break;
      case Fx::reduced_mode: ctl->set_safety_mode(kin::SafetyMode::reduced); break;
      case Fx::estop: {
        Request r(RequestOp::estop, ++seq);
        if (!ctl->requests().push(r)) FAIL("request queue full");
        break;
      }
      case Fx::overrun:
        clock.advance(kStall);  // the loop stalls; the drives go on (the clock's hook steps them)
        ctl->record_timing(static_cast<std::int64_t>(kStall), 0, static_cast<std::uint32_t>(kStall / period));
        break;
    }
  }
  unsigned powered_mask() {
    unsigned m = 0;
    for (std::size_t j = 0; j < app.plant->arm().size(); ++j) {
      const hal::cia402::State s = app.plant->arm().at(j).state();
      if (s == hal::cia402::State::operation_enabled || s == hal::cia402::State::quick_stop_active) m |= 1u << j;
    }
    return m;
  }
  /// Some virtual drive powered (operation enabled, or quick stop active), `skip` left out.
  bool drives_powered(int skip) {
    for (std::size_t j = 0; j < app.plant->arm().size(); ++j) {
      if (static_cast<int>(j) == skip) continue;
      const hal::cia402::State s = app.plant->arm().at(j).state();
      if (s == hal::cia402::State::operation_enabled || s == hal::cia402::State::quick_stop_active) return true;
    }
    return false;
  }
};

struct Outcome {
  ArmState state = ArmState::boot;
  bool powered = false;
  FaultCause cause = FaultCause::none;
  int fault_joint = -1;
  std::string fault_text;
  std::uint32_t done_id = 0;
  std::uint32_t queued = 0;
  kin::JointVector q_cmd;
  std::vector<Event> events;  // after the fault
  bool queued_move_finished = false;
  std::uint64_t generation_before = 0, generation_after = 0;
  std::uint64_t overruns = 0;
  std::string worst_step;  // "" or the largest setpoint step over its bound
  std::size_t rt_allocs = 0;
  std::uint32_t safety_stops = 0;
};

Outcome run_cell(St s, Fx f, int k) {
  Rig r;
  r.enter(s);
  Outcome o;
  o.generation_before = r.ctl->telemetry().generation;
  const std::size_t r0 = r.recs.size();
  const std::size_t e0 = r.events.size();
  r.inject(f, k);
  int n = kSettleCycles;
  if (s == St::disabled) {
    r.cycles(kEnableAfter);
    r.request(RequestOp::enable);
    n -= kEnableAfter + 1;
  }
  r.cycles(n);
  const Telemetry t = r.ctl->telemetry();
  o.state = t.state;
  o.powered = r.drives_powered(f == Fx::node_silent ? k : -1);
  o.cause = t.cause;
  o.fault_joint = t.fault_joint;
  o.fault_text = t.fault_text;
  o.done_id = t.done_id;
  o.queued = t.queued;
  o.q_cmd = r.q_cmd();
  o.events.assign(r.events.begin() + static_cast<std::ptrdiff_t>(e0), r.events.end());
  for (const Event& e : r.events)
    if (e.kind == EventKind::motion_done && e.motion_id == kQueuedId) o.queued_move_finished = true;
  o.generation_after = t.generation;
  o.overruns = t.overruns;
  o.safety_stops = t.safety_stops;
  // Setpoint steps: at most one period at the joint's velocity limit (+ rounding).
  const kin::JointLimits& lim = r.ctl->limits();
  const double dt = r.ctl->period_s();
  double worst = 0;
  // Checked where it matters: a step into a setpoint that a powered drive received.
  for (std::size_t i = r0; i < r.recs.size(); ++i) {
    const Rig::CycleRec& c = r.recs[i];
    if (c.write == 0) continue;
    for (std::size_t j = 0; j < 6; ++j) {
      if ((c.powered & (1u << j)) == 0) continue;
      // An unplugged node hears nothing (it stays "powered" only in its own model); the
      // controller's setpoint for it in the fault state is its last known position.
      if (f == Fx::node_silent && static_cast<int>(j) == k) continue;
      const double step = std::fabs(r.bus->writes[c.write][j] - r.bus->writes[c.write - 1][j]);
      const double bound = lim.dyn[j].max_velocity * dt + 1e-9;
      if (step > bound && step / bound > worst) {
        worst = step / bound;
        char b[200];
        std::snprintf(b, sizeof b, "joint %zu stepped %.6f rad in one cycle (bound %.6f), %zu cycles after the fault, mode %s -> %s",
                      j + 1, step, bound, i - r0, to_string(i > 0 ? r.recs[i - 1].mode : c.mode), to_string(c.mode));
        o.worst_step = b;
      }
    }
  }
  o.rt_allocs = r.rt_allocs;
  return o;
}

// Expected reactions.
enum class Re : std::uint8_t {
  none,   // no reaction: as the baseline
  fault,  // fault: `cause` on `joint` (-1: the bus), drives down, queue dropped
  estop,  // e-stop: drives down, queue dropped
  protective_stop,  // the safety envelope: ramp to rest, idle and powered, queue dropped, no fault
};
struct Cell {
  St state;
  Fx fault;
  int k;           // the joint injected (0-based; unused for bus-off, e-stop, overrun)
  Re reaction;
  FaultCause cause;
  int joint;       // the joint the fault names (-1: none)
  // Also accepted: the feedback of a moving joint that stops updating passes the
  // following-error limit (2 deg here) before the 50 ms feedback timeout when the joint is fast.
  FaultCause alt = FaultCause::none;
};

constexpr FaultCause kNoCause = FaultCause::none;
constexpr FaultCause kEmcy = FaultCause::emcy;
constexpr FaultCause kDrive = FaultCause::drive_fault;
constexpr FaultCause kHb = FaultCause::heartbeat_lost;
constexpr FaultCause kFb = FaultCause::feedback_invalid;
constexpr FaultCause kBusOff = FaultCause::bus_off;
constexpr FaultCause kRefused = FaultCause::drive_refused;
constexpr FaultCause kFollow = FaultCause::following_error;

// The table. Disabled row: the state after the enable request that follows the fault
// (a drive fault while disabled latches nothing; the enable resets it).
const Cell kCells[] = {
    // disabled
    {St::disabled, Fx::drive_fault, 1, Re::none, kNoCause, -1},
    {St::disabled, Fx::heartbeat_loss, 2, Re::fault, kHb, 2},
    {St::disabled, Fx::node_silent, 3, Re::fault, kFb, 3},
    {St::disabled, Fx::feedback_stale, 4, Re::fault, kFb, 4},
    {St::disabled, Fx::bus_off, 0, Re::fault, kBusOff, -1},
    {St::disabled, Fx::refuse_enable, 5, Re::fault, kRefused, 5},
    {St::disabled, Fx::jammed_joint, 0, Re::none, kNoCause, -1},
    {St::disabled, Fx::estop, 0, Re::estop, kNoCause, -1},
    {St::disabled, Fx::overrun, 0, Re::none, kNoCause, -1},
    {St::disabled, Fx::reduced_mode, 0, Re::none, kNoCause, -1},
    // enabling (one cycle after the enable request)
    {St::enabling, Fx::drive_fault, 2, Re::fault, kDrive, 2},
    {St::enabling, Fx::heartbeat_loss, 3, Re::fault, kHb, 3},
    {St::enabling, Fx::node_silent, 4, Re::fault, kFb, 4},
    {St::enabling, Fx::feedback_stale, 5, Re::fault, kFb, 5},
    {St::enabling, Fx::bus_off, 0, Re::fault, kBusOff, -1},
    {St::enabling, Fx::refuse_enable, 0, Re::fault, kRefused, 0},
    {St::enabling, Fx::jammed_joint, 1, Re::none, kNoCause, -1},
    {St::enabling, Fx::estop, 0, Re::estop, kNoCause, -1},
    {St::enabling, Fx::overrun, 0, Re::none, kNoCause, -1},
    {St::enabling, Fx::reduced_mode, 0, Re::none, kNoCause, -1},
    // idle (enabled, at rest)
    {St::idle, Fx::drive_fault, 3, Re::fault, kEmcy, 3},
    {St::idle, Fx::heartbeat_loss, 4, Re::fault, kHb, 4},
    {St::idle, Fx::node_silent, 5, Re::fault, kFb, 5},
    {St::idle, Fx::feedback_stale, 0, Re::fault, kFb, 0},
    {St::idle, Fx::bus_off, 0, Re::fault, kBusOff, -1},
    {St::idle, Fx::refuse_enable, 1, Re::none, kNoCause, -1},
    {St::idle, Fx::jammed_joint, 2, Re::none, kNoCause, -1},
    {St::idle, Fx::estop, 0, Re::estop, kNoCause, -1},
    {St::idle, Fx::overrun, 0, Re::none, kNoCause, -1},
    {St::idle, Fx::reduced_mode, 0, Re::none, kNoCause, -1},
    // moving joint
    {St::moving_joint, Fx::drive_fault, 4, Re::fault, kEmcy, 4},
    {St::moving_joint, Fx::heartbeat_loss, 5, Re::fault, kHb, 5},
    {St::moving_joint, Fx::node_silent, 0, Re::fault, kFb, 0, kFollow},
    {St::moving_joint, Fx::feedback_stale, 1, Re::fault, kFb, 1, kFollow},
    {St::moving_joint, Fx::bus_off, 0, Re::fault, kBusOff, -1},
    {St::moving_joint, Fx::refuse_enable, 2, Re::none, kNoCause, -1},
    {St::moving_joint, Fx::jammed_joint, 3, Re::fault, kFollow, 3},
    {St::moving_joint, Fx::estop, 0, Re::estop, kNoCause, -1},
    {St::moving_joint, Fx::overrun, 0, Re::none, kNoCause, -1},
    {St::moving_joint, Fx::reduced_mode, 0, Re::protective_stop, kNoCause, -1},
    // moving linear
    {St::moving_linear, Fx::drive_fault, 5, Re::fault, kEmcy, 5},
    {St::moving_linear, Fx::heartbeat_loss, 0, Re::fault, kHb, 0},
    {St::moving_linear, Fx::node_silent, 1, Re::fault, kFb, 1, kFollow},
    {St::moving_linear, Fx::feedback_stale, 2, Re::fault, kFb, 2, kFollow},
    {St::moving_linear, Fx::bus_off, 0, Re::fault, kBusOff, -1},
    {St::moving_linear, Fx::refuse_enable, 3, Re::none, kNoCause, -1},
    {St::moving_linear, Fx::jammed_joint, 2, Re::fault, kFollow, 2},
    {St::moving_linear, Fx::estop, 0, Re::estop, kNoCause, -1},
    {St::moving_linear, Fx::overrun, 0, Re::none, kNoCause, -1},
    {St::moving_linear, Fx::reduced_mode, 0, Re::protective_stop, kNoCause, -1},
    // jogging (joint 1)
    {St::jogging, Fx::drive_fault, 0, Re::fault, kEmcy, 0},
    {St::jogging, Fx::heartbeat_loss, 1, Re::fault, kHb, 1},
    {St::jogging, Fx::node_silent, 2, Re::fault, kFb, 2, kFollow},
    {St::jogging, Fx::feedback_stale, 3, Re::fault, kFb, 3, kFollow},
    {St::jogging, Fx::bus_off, 0, Re::fault, kBusOff, -1},
    {St::jogging, Fx::refuse_enable, 4, Re::none, kNoCause, -1},
    {St::jogging, Fx::jammed_joint, 0, Re::fault, kFollow, 0},
    {St::jogging, Fx::estop, 0, Re::estop, kNoCause, -1},
    {St::jogging, Fx::overrun, 0, Re::none, kNoCause, -1},
    {St::jogging, Fx::reduced_mode, 0, Re::protective_stop, kNoCause, -1},
    // holding (feed hold, at rest, moves queued)
    {St::holding, Fx::drive_fault, 1, Re::fault, kEmcy, 1},
    {St::holding, Fx::heartbeat_loss, 2, Re::fault, kHb, 2},
    {St::holding, Fx::node_silent, 3, Re::fault, kFb, 3},
    {St::holding, Fx::feedback_stale, 4, Re::fault, kFb, 4},
    {St::holding, Fx::bus_off, 0, Re::fault, kBusOff, -1},
    {St::holding, Fx::refuse_enable, 5, Re::none, kNoCause, -1},
    {St::holding, Fx::jammed_joint, 0, Re::none, kNoCause, -1},
    {St::holding, Fx::estop, 0, Re::estop, kNoCause, -1},
    {St::holding, Fx::overrun, 0, Re::none, kNoCause, -1},
    {St::holding, Fx::reduced_mode, 0, Re::none, kNoCause, -1},  // (held at rest: no speed)
    // stopping (the ramp of `stop` from a joint move at speed)
    {St::stopping, Fx::drive_fault, 2, Re::fault, kEmcy, 2},
    {St::stopping, Fx::heartbeat_loss, 3, Re::fault, kHb, 3},
    {St::stopping, Fx::node_silent, 4, Re::fault, kFb, 4, kFollow},
    {St::stopping, Fx::feedback_stale, 5, Re::fault, kFb, 5, kFollow},
    {St::stopping, Fx::bus_off, 0, Re::fault, kBusOff, -1},
    {St::stopping, Fx::refuse_enable, 0, Re::none, kNoCause, -1},
    {St::stopping, Fx::jammed_joint, 1, Re::fault, kFollow, 1},
    {St::stopping, Fx::estop, 0, Re::estop, kNoCause, -1},
    {St::stopping, Fx::overrun, 0, Re::none, kNoCause, -1},
    {St::stopping, Fx::reduced_mode, 0, Re::none, kNoCause, -1},  // (the ramp of a stop is not watched)
};

bool has_moves(St s) { return s == St::moving_joint || s == St::moving_linear || s == St::holding; }

// One failure message per wrong aspect of the cell; "" when the cell holds.
std::string check_cell(const Cell& c, const Outcome& o, const Outcome& base) {
  std::string err;
  const auto bad = [&err](const std::string& m) { err += "\n    " + m; };
  if (!o.worst_step.empty()) bad("setpoint jump: " + o.worst_step);
  if (o.rt_allocs != 0) bad("the control cycle allocated " + std::to_string(o.rt_allocs) + " times");
  switch (c.reaction) {
    case Re::none: {
      if (o.cause != FaultCause::none) bad(std::string("faulted: ") + o.fault_text);
      for (const Event& e : o.events)
        if (e.kind == EventKind::fault || e.kind == EventKind::estop) bad(std::string("event ") + e.message);
      if (o.state != base.state) bad(std::string("state ") + to_string(o.state) + ", baseline " + to_string(base.state));
      if (o.powered != base.powered) bad(std::string("drives powered ") + (o.powered ? "yes" : "no") + ", baseline differs");
      if (o.done_id != base.done_id) bad("finished moves up to " + std::to_string(o.done_id) + ", baseline " + std::to_string(base.done_id));
      const double dq = (o.q_cmd - base.q_cmd).cwiseAbs().maxCoeff();
      if (!(dq < 1e-6)) bad("commanded position " + std::to_string(dq) + " rad from the baseline's");
      if (c.fault == Fx::overrun && o.overruns != base.overruns + static_cast<std::uint64_t>(kStall / hal::kMillisecond))
        bad("overruns " + std::to_string(o.overruns) + ", baseline " + std::to_string(base.overruns) + " + 20");
      break;
    }
    case Re::protective_stop: {
      if (o.state != ArmState::idle) bad(std::string("state ") + to_string(o.state) + ", wanted idle");
      if (!o.powered) bad("drives not powered");
      if (o.cause != FaultCause::none) bad(std::string("a fault: ") + o.fault_text);
      if (o.queued != 0) bad("motion queue not empty: " + std::to_string(o.queued));
      if (o.queued_move_finished) bad("the queued move ran");
      if (o.safety_stops != 1) bad(std::to_string(o.safety_stops) + " safety stops, wanted 1");
      const EventKind kind = c.state == St::jogging ? EventKind::jog_stopped : EventKind::motion_refused;
      int stops = 0;
      for (const Event& e : o.events)
        if (e.kind == kind && std::string(e.message).find("protective stop (commanded): joint ") != std::string::npos &&
            std::string(e.message).find(" speed") != std::string::npos)
          ++stops;
      if (stops != 1) bad(std::to_string(stops) + " protective stop events naming a joint speed, wanted 1");
      break;
    }
    case Re::fault:
    case Re::estop: {
      const ArmState want = c.reaction == Re::fault ? ArmState::fault : ArmState::estop;
      if (o.state != want) bad(std::string("state ") + to_string(o.state) + ", wanted " + to_string(want) + " (" + o.fault_text + ")");
      if (o.powered) bad("drives still powered");
      if (o.queued != 0) bad("motion queue not empty: " + std::to_string(o.queued));
      if (o.queued_move_finished) bad("the queued move ran");
      if (o.generation_after == o.generation_before) bad("generation not bumped (queue not flushed)");
      if (c.reaction == Re::estop) {
        bool seen = false;
        for (const Event& e : o.events) seen = seen || e.kind == EventKind::estop;
        if (!seen) bad("no estop event");
        if (o.cause != FaultCause::none) bad(std::string("a fault besides: ") + o.fault_text);
        break;
      }
      const bool cause_ok = o.cause == c.cause || (c.alt != FaultCause::none && o.cause == c.alt);
      const FaultCause seen = cause_ok ? o.cause : c.cause;
      if (!cause_ok) bad(std::string("cause ") + to_string(o.cause) + ", wanted " + to_string(c.cause) + " (" + o.fault_text + ")");
      if (o.fault_joint != c.joint) bad("fault joint " + std::to_string(o.fault_joint) + ", wanted " + std::to_string(c.joint));
      const std::string named = c.joint >= 0 ? "joint " + std::to_string(c.joint + 1) + " " : std::string(to_string(c.cause));
      if (o.fault_text.rfind(named, 0) != 0) bad("fault text '" + o.fault_text + "' does not start with '" + named + "'");
      int fault_events = 0;
      for (const Event& e : o.events)
        if (e.kind == EventKind::fault) {
          ++fault_events;
          if (e.cause != seen || e.joint != c.joint || std::string(e.message).rfind(named, 0) != 0)
            bad(std::string("fault event: ") + to_string(e.cause) + " joint " + std::to_string(e.joint) + " '" + e.message + "'");
        }
      if (fault_events != 1) bad(std::to_string(fault_events) + " fault events, wanted 1");
      if (has_moves(c.state)) {
        bool dropped = false;
        for (const Event& e : o.events) dropped = dropped || (e.kind == EventKind::motion_refused && std::string(e.message).find("dropped") != std::string::npos);
        if (!dropped) bad("no event saying the queued moves were dropped");
      }
      break;
    }
  }
  return err;
}

}  // namespace

TEST_GROUP(FaultMatrix){};

// The baseline of each state (no fault) must itself be what the table assumes: no fault,
// drives powered (disabled: after its enable), the moves finished or the jog running.
TEST(FaultMatrix, EveryCellReactsAsTabled) {
  Outcome base[8];
  for (int s = 0; s < 8; ++s) {
    base[s] = run_cell(static_cast<St>(s), Fx::none, 0);
    const Outcome& b = base[s];
    const std::string what = std::string("baseline ") + name(static_cast<St>(s));
    CHECK_TEXT(b.cause == FaultCause::none, (what + ": " + b.fault_text).c_str());
    CHECK_TEXT(b.powered, (what + ": drives not powered").c_str());
    CHECK_TEXT(b.worst_step.empty(), (what + ": " + b.worst_step).c_str());
    LONGS_EQUAL(0, b.rt_allocs);
    const bool runs_to_the_end = s == int(St::moving_joint) || s == int(St::moving_linear);  // (holding stays held)
    if (runs_to_the_end) CHECK_TEXT(b.queued_move_finished, (what + ": the queued move did not finish").c_str());
  }
  std::string failures;
  int cells = 0;
  for (const Cell& c : kCells) {
    const Outcome o = run_cell(c.state, c.fault, c.k);
    const std::string e = check_cell(c, o, base[static_cast<int>(c.state)]);
    ++cells;
    if (!e.empty()) failures += std::string("\n  ") + name(c.state) + " x " + name(c.fault) + " (joint " + std::to_string(c.k + 1) + "):" + e;
  }
  std::printf("\n[fault matrix] %d cells (8 states x 10 faults), %s\n", cells, failures.empty() ? "all as tabled" : "FAILED");
  CHECK_TEXT(failures.empty(), failures.c_str());
}
