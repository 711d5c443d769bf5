// SPDX-License-Identifier: Apache-2.0
// The controller's (mode x request) table, walked exhaustively: for every Mode and every
// RequestOp a fresh puma560 on the in-process bus (virtual CiA 402 drives, ManualClock)
// is driven into that mode through real cycles, the request is sent, and one cycle later
// the test checks the reply (result, text), the mode, the coarse ArmState / holding the
// console sees, and what went to the drives (ServoSpy: power commands, setpoints).
// The expectations below are written out by hand, from the behaviour before the table
// existed: they are not read from kRequestTable.
// Then the Cartesian IK-failure path: a sample whose IK fails keeps the precomputed
// (path-checked) joint value and is counted in Telemetry::ik_fallbacks.
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "servo_spy.hpp"
#include "controller_rig.hpp"
#include "servoarm/rt/controller.hpp"
#include "servoarm/rt/mode_table.hpp"
#include "servoarm/kinematics/ik.hpp"
#include "servoarm/kinematics/chain.hpp"

#include <CppUTest/TestHarness.h>

using namespace servoarm;
using namespace servoarm::fw;
using Call = test::ServoSpy::Call;

namespace {

using test::kDeg;

/// The App built, not booted; a Controller of the test's own over a ServoSpy on its bus,
/// stepped by the rig's cycle().
struct TableRig : test::ControllerRig {
  std::unique_ptr<test::ServoSpy> spy;
  std::unique_ptr<Controller> ctl;
  std::uint32_t seq = 100;

  /// `homing`: joint 1 homes with CiA 402 method 19 and no home switch on its drive (the search
  /// goes on until the 60 s timeout: the homing modes last), the others are absolute.
  bool freedrive = false;  ///< the dynamic plant, [dynamics] freedrive, the model attached
  explicit TableRig(bool drive_quick_stop, const sim::MotorParams& motor = {}, bool homing = false, bool fd = false)
      : ControllerRig(config(drive_quick_stop, homing, fd),
                      test::RigOptions{motor, fd ? dynamic_plant : nullptr, /*boot=*/false}),
        freedrive(fd) {
    spy = std::make_unique<test::ServoSpy>(*app.servo);
    ctl = std::make_unique<Controller>(*spy, app.chain, app.controller_config());
    drive(*ctl);
  }
  static FwConfig config(bool drive_quick_stop, bool homing, bool fd) {
    FwConfig cfg;
    cfg.freedrive = fd;
    cfg.stop = drive_quick_stop ? "drive" : "ramp";
    if (homing) {
      cfg.drives.resize(6);
      cfg.drives[0].homing_method = "19";
      cfg.drives[0].homing_speed_switch = 5;
      cfg.drives[0].homing_timeout_s = 60;
    }
    return cfg;
  }
  /// Torque mode needs the rigid-body plant.
  static void dynamic_plant(test::SimApp& app) {
    std::vector<hal::JointScaling> sc;
    for (std::size_t j = 0; j < app.servo->joint_count(); ++j) sc.push_back(app.servo->scaling(j));
    const std::string d = app.plant->use_dynamic_plant(app.chain, sc);
    if (!d.empty()) FAIL(d.c_str());
    kin::JointVector q(6);
    q << 0, -0.6, 1.2, 0, 0.9, 0;
    app.plant->arm().plant()->set_state(q, kin::JointVector::Zero(6));
  }
  ~TableRig() {
    clock.set_idle_hook(nullptr);
    ctl.reset();
  }
  void boot() {
    const hal::TimePoint now = clock.now();
    if (ctl->boot(now, now + 5 * hal::kSecond) != hal::Status::ok) FAIL(spy->last_error());
    if (freedrive) {  // what App::boot does: the model on this controller's bus
      app.model->configure(app.chain, *spy, app.model_config());
      if (!app.model->available(ModelPart::freedrive)) FAIL(app.model->refusal(ModelPart::freedrive));
      ctl->set_model(app.model.get());
    }
  }
  Mode mode() const { return ctl->mode(); }
  /// Send a request, run one cycle, return its reply (the cycle it ran in: spy->cycle).
  /// RequestOp::jog carries a joint jog of joint 1 by +10 deg at 50 %, or `jog` when given.
  Reply request(RequestOp op, const JogSpec* jog = nullptr) {
    Request r;
    r.op = op;
    r.seq = ++seq;
    r.joints = 0;  // home: every joint
    if (op == RequestOp::jog) {
      if (jog != nullptr) {
        r.jog = *jog;
      } else {
        r.jog.space = JogSpace::joint;
        r.jog.q_goal = q_cmd();
        r.jog.q_goal[0] += 10 * kDeg;
        r.jog.override = 0.5;
      }
    }
    if (!ctl->requests().push(r)) FAIL("request queue full");
    cycle();
    Reply rep;
    if (!ctl->replies().pop(rep)) FAIL("no reply");
    LONGS_EQUAL(r.seq, rep.seq);
    return rep;
  }
  void run_until(Mode m, int max_cycles, const char* what) {
    for (int i = 0; i < max_cycles && mode() != m; ++i) cycle();
    if (mode() != m) FAIL((std::string(what) + ": mode " + to_string(mode()) + ", wanted " + to_string(m)).c_str());
  }
  void expect(Mode m, const char* what) {
    if (mode() != m) FAIL((std::string(what) + ": mode " + to_string(mode()) + ", wanted " + to_string(m)).c_str());
  }
  /// Enable through the request queue (this controller has no service).
  void enable() {
    boot();
    request(RequestOp::enable);
    run_until(Mode::idle, 3000, "enable");
  }
  /// A joint move that runs long enough to be at speed when the request comes.
  void start_joint_move() {
    MotionItem* m = ctl->motions().back();
    JointMove& jm = m->payload.emplace<JointMove>();
    m->id = 1;
    jm.override = 1.0;
    jm.goal = q_cmd();
    for (int j = 0; j < 6; ++j) jm.goal[j] += (j % 2 ? -40.0 : 40.0) * kDeg;
    ctl->motions().commit();
    cycles(150);
    expect(Mode::moving, "joint move");
  }
  /// Plan a straight line of `dx` (m) along x from the commanded pose; not committed.
  MotionItem* plan_line(double dx) {
    MotionItem* m = ctl->motions().back();
    kin::Pose p;
    kin::forward(app.chain, q_cmd(), p);
    p.translation().x() += dx;
    const kin::IkSolver ik{&kin::ik_nearest_fn, app.ik.get()};
    kin::CartesianTrajectory& path = m->payload.emplace<CartesianMove>().path;
    const kin::MotionStatus st = kin::plan_movel(app.chain, q_cmd(), p, kin::CartesianLimits{}, kin::MovelOptions{}, ik, path);
    CHECK_TEXT(kin::is_ok(st), kin::to_string(st));
    m->id = 2;
    return m;
  }
  /// Move to the demo's working pose, then start a 60 mm line and run into it.
  void start_line() {
    MotionItem* m = ctl->motions().back();
    JointMove& jm = m->payload.emplace<JointMove>();
    m->id = 1;
    jm.override = 1.0;
    jm.goal = kin::JointVector(6);
    jm.goal << 20, -40, 160, 10, -50, 30;
    jm.goal *= kDeg;
    ctl->motions().commit();
    cycle();  // starts it
    run_until(Mode::idle, 10000, "move to the working pose");
    plan_line(0.06);
    ctl->motions().commit();
    cycles(100);
    expect(Mode::moving, "line");
  }
  void inject_bus_error() {
    spy->fail_next_write(hal::Status::io_error);
    cycle();
  }
};

/// Drive a fresh rig into `m` through real cycles.
void enter(TableRig& r, Mode m) {
  switch (m) {
    case Mode::boot: return;
    case Mode::disabled:
      r.boot();
      r.cycles(20);  // position feedback from every drive
      return;
    case Mode::enabling:
      r.boot();
      r.request(RequestOp::enable);
      r.expect(Mode::enabling, "enable");
      return;
    case Mode::idle: r.enable(); return;
    case Mode::moving:
      r.enable();
      r.start_joint_move();
      return;
    case Mode::hold_ramp:
      enter(r, Mode::moving);
      r.request(RequestOp::hold);
      r.expect(Mode::hold_ramp, "hold");
      return;
    case Mode::hold_ramp_resume:
      enter(r, Mode::hold_ramp);
      r.request(RequestOp::resume);
      r.expect(Mode::hold_ramp_resume, "resume during the hold's ramp");
      return;
    case Mode::hold_line:
      r.enable();
      r.start_line();
      r.request(RequestOp::hold);
      r.expect(Mode::hold_line, "hold on the line");
      return;
    case Mode::held:
      enter(r, Mode::hold_ramp);
      r.run_until(Mode::held, 3000, "hold ramp");
      return;
    case Mode::stopping_to_idle:
      enter(r, Mode::moving);
      r.request(RequestOp::stop);
      r.expect(Mode::stopping_to_idle, "stop");
      return;
    case Mode::stopping_to_disabled:
      enter(r, Mode::moving);
      r.request(RequestOp::disable);
      r.expect(Mode::stopping_to_disabled, "disable");
      return;
    case Mode::fault_ramp:
    case Mode::fault_quick_stop:  // (the rig's config decides which)
      enter(r, Mode::moving);
      r.inject_bus_error();
      r.expect(m, "bus error while moving");
      return;
    case Mode::fault:
      enter(r, Mode::fault_ramp);
      r.run_until(Mode::fault, 3000, "fault ramp");
      return;
    case Mode::estop_ramp:
    case Mode::estop_quick_stop:
      enter(r, Mode::moving);
      r.request(RequestOp::estop);
      r.expect(m, "estop while moving");
      return;
    case Mode::estop:
      enter(r, Mode::estop_ramp);
      r.run_until(Mode::estop, 3000, "estop ramp");
      return;
    case Mode::jogging: {
      r.enable();
      JogSpec js;  // joint 1 towards its upper limit, continuous, a deadman longer than the test
      js.space = JogSpace::joint;
      js.continuous = true;
      js.deadman_s = 60;
      js.q_goal = r.q_cmd();
      js.q_goal[0] = kin::limits_from(r.app.chain).upper[0];
      js.override = 0.3;
      r.request(RequestOp::jog, &js);
      r.cycles(150);
      r.expect(Mode::jogging, "continuous jog");
      return;
    }
    case Mode::homing:  // (a homing rig: joint 1 searches its switch)
      r.enable();
      r.request(RequestOp::home);
      r.cycles(50);
      r.expect(Mode::homing, "homing");
      return;
    case Mode::homing_abort:
      enter(r, Mode::homing);
      r.request(RequestOp::stop);
      r.expect(Mode::homing_abort, "homing aborted");
      return;
    case Mode::freedrive:  // (a freedrive rig: the dynamic plant, torque mode mapped, the model)
      r.enable();
      r.request(RequestOp::freedrive_on);
      r.cycles(5);
      r.expect(Mode::freedrive, "freedrive on");
      return;
    case Mode::freedrive_end:  // lasts one to three cycles (the drives back to CSP): not walked
      enter(r, Mode::freedrive);
      r.request(RequestOp::freedrive_off);
      r.expect(Mode::freedrive_end, "freedrive off");
      return;
  }
}

bool needs_drive_quick_stop(Mode m) { return m == Mode::fault_quick_stop || m == Mode::estop_quick_stop; }
bool needs_homing(Mode m) { return m == Mode::homing || m == Mode::homing_abort; }
bool needs_freedrive(Mode m) { return m == Mode::freedrive || m == Mode::freedrive_end; }

struct Expect {
  RtResult result;
  const char* reply;  ///< the reply text starts with this
  Mode after;         ///< mode after the request's cycle
  std::vector<Call> calls;  ///< power commands in that cycle
};

const std::vector<Call> kNone{};
const std::vector<Call> kDisable{Call::disable};
const std::vector<Call> kEnable{Call::enable};
const std::vector<Call> kQuick{Call::quick_stop};
const std::vector<Call> kZero6(6, Call::set_zero);
const std::vector<Call> kStart6(6, Call::start_homing);
const std::vector<Call> kAbort{Call::abort_homing};
const std::vector<Call> kAbortDisable{Call::abort_homing, Call::disable};

constexpr RtResult ok = RtResult::ok, bad = RtResult::bad_state, flt = RtResult::fault, busy = RtResult::busy;

// What every request does in every mode (ramp configuration; the quick-stop rows with
// the drives' quick stop). Columns: enable, disable, stop, estop, reset, hold, resume, set_zero,
// jog, jog_cancel, jog_keepalive, home. The homing rows with joint 1 searching its switch (TableRig
// `homing`); elsewhere every joint is absolute, so a homing cycle ends in the cycle it starts.
Expect expected(Mode m, RequestOp op) {
  // Requests that do nothing but answer, the same in many modes.
  const auto stays = [m](RtResult res, const char* text) { return Expect{res, text, m, kNone}; };
  const Expect nothing_to_reset = stays(ok, "nothing to reset");
  const Expect not_moving = stays(ok, "not moving");
  const Expect not_holding = stays(ok, "not holding");
  const Expect no_zero = stays(bad, "home zero needs the arm disabled (it is ");
  // The jog columns: outside the jogging mode a cancel / keep-alive only answers; a jog
  // starts from idle only.
  if (m != Mode::jogging && (op == RequestOp::jog_cancel || op == RequestOp::jog_keepalive)) return stays(ok, "not jogging");
  // The freedrive columns outside the freedrive mode. The table rigs other than the
  // freedrive one have no model attached: an idle arm refuses saying so.
  if (op == RequestOp::freedrive_off && m != Mode::freedrive)
    return stays(ok, m == Mode::freedrive_end ? "free-drive ending" : "free-drive off");
  if (op == RequestOp::freedrive_on && m != Mode::freedrive) {
    switch (m) {
      case Mode::boot: return stays(bad, "drives not started");
      case Mode::disabled:
      case Mode::enabling: return stays(bad, "freedrive needs the arm enabled (it is ");
      case Mode::idle: return stays(bad, "freedrive refused: no dynamic model");
      case Mode::moving:
      case Mode::hold_ramp:
      case Mode::hold_ramp_resume:
      case Mode::hold_line:
      case Mode::held:
      case Mode::jogging: return stays(busy, "a move, jog or homing is running (or held): freedrive refused");
      case Mode::stopping_to_idle:
      case Mode::stopping_to_disabled:
      case Mode::homing_abort:
      case Mode::freedrive_end: return stays(bad, "stopping; retry");
      case Mode::fault_ramp:
      case Mode::fault_quick_stop:
      case Mode::fault: return stays(flt, "in fault: send reset first");
      case Mode::estop_ramp:
      case Mode::estop_quick_stop:
      case Mode::estop: return stays(flt, "in estop: send reset first");
      case Mode::homing: return stays(busy, "homing runs: stop it first");
      case Mode::freedrive: break;
    }
  }
  if (m == Mode::freedrive) {  // every drive in CST, the arm held against gravity
    switch (op) {
      case RequestOp::enable: return stays(ok, "already enabled");
      case RequestOp::disable: return {ok, "disabled", Mode::disabled, kDisable};
      case RequestOp::stop:
      case RequestOp::hold:
      case RequestOp::freedrive_off: return {ok, "free-drive off: holding where it stands", Mode::freedrive_end, kNone};
      // the ramp from rest (the setpoint follows the measured pose) ends in the same cycle
      case RequestOp::estop: return {ok, "estop", Mode::estop, kDisable};
      case RequestOp::reset: return nothing_to_reset;
      case RequestOp::resume: return not_holding;
      case RequestOp::set_zero: return no_zero;
      case RequestOp::jog: return stays(busy, "a move is running (or held): jog refused");
      case RequestOp::home: return stays(busy, "a move or jog is running (or held): home refused");
      case RequestOp::freedrive_on: return stays(ok, "free-drive on");
      case RequestOp::jog_cancel:
      case RequestOp::jog_keepalive: break;  // (above)
    }
  }
  // The home column outside the homing modes.
  if (op == RequestOp::home && !needs_homing(m) && m != Mode::freedrive) {
    switch (m) {
      case Mode::boot: return stays(bad, "drives not started");
      case Mode::disabled:
      case Mode::enabling: return stays(bad, "home needs the arm enabled (it is ");
      // absolute joints: every one attained at once, the cycle over in the same control cycle
      case Mode::idle: return {ok, "homing: group 1 of 1 (joints 1, 2, 3, 4, 5, 6)", Mode::idle, kStart6};
      case Mode::moving:
      case Mode::hold_ramp:
      case Mode::hold_ramp_resume:
      case Mode::hold_line:
      case Mode::held:
      case Mode::jogging: return stays(busy, "a move or jog is running (or held): home refused");
      case Mode::stopping_to_idle:
      case Mode::stopping_to_disabled:
      case Mode::freedrive_end: return stays(bad, "stopping; retry");
      case Mode::fault_ramp:
      case Mode::fault_quick_stop:
      case Mode::fault: return stays(flt, "in fault: send reset first");
      case Mode::estop_ramp:
      case Mode::estop_quick_stop:
      case Mode::estop: return stays(flt, "in estop: send reset first");
      case Mode::homing:
      case Mode::homing_abort:
      case Mode::freedrive: break;
    }
  }
  if (m == Mode::homing) {  // joint 1 is being homed by its drive
    switch (op) {
      case RequestOp::enable: return stays(ok, "already enabled");
      case RequestOp::disable: return {ok, "homing aborted; disabled", Mode::disabled, kAbortDisable};
      case RequestOp::stop:
      case RequestOp::hold: return {ok, "homing aborted: joint 1 left unhomed", Mode::homing_abort, kAbort};
      case RequestOp::estop: return {ok, "estop", Mode::estop, kAbortDisable};
      case RequestOp::reset: return nothing_to_reset;
      case RequestOp::resume: return not_holding;
      case RequestOp::set_zero: return no_zero;
      case RequestOp::jog:
      case RequestOp::home: return stays(busy, "homing runs: stop it first");
      case RequestOp::jog_cancel:
      case RequestOp::jog_keepalive: return stays(ok, "not jogging");
      case RequestOp::freedrive_on:
      case RequestOp::freedrive_off: break;  // (above)
    }
  }
  if (m == Mode::homing_abort) {  // joint 1's drive halting and going back to CSP
    switch (op) {
      case RequestOp::enable: return stays(bad, "stopping; retry");
      case RequestOp::disable: return {ok, "homing aborted; disabled", Mode::disabled, kAbortDisable};
      case RequestOp::stop: return stays(ok, "stopping");
      case RequestOp::estop: return {ok, "estop", Mode::estop, kAbortDisable};
      case RequestOp::reset: return nothing_to_reset;
      case RequestOp::hold: return not_moving;
      case RequestOp::resume: return not_holding;
      case RequestOp::set_zero: return no_zero;
      case RequestOp::jog:
      case RequestOp::home: return stays(bad, "stopping; retry");
      case RequestOp::jog_cancel:
      case RequestOp::jog_keepalive: return stays(ok, "not jogging");
      case RequestOp::freedrive_on:
      case RequestOp::freedrive_off: break;  // (above)
    }
  }
  if (m != Mode::jogging && op == RequestOp::jog) {
    switch (m) {
      case Mode::boot:
      case Mode::disabled:
      case Mode::enabling: return stays(bad, "jog needs the arm enabled (it is ");
      case Mode::idle: return {ok, "jogging", Mode::jogging, kNone};
      case Mode::moving:
      case Mode::hold_ramp:
      case Mode::hold_ramp_resume:
      case Mode::hold_line:
      case Mode::held: return stays(busy, "a move is running (or held): jog refused");
      case Mode::stopping_to_idle:
      case Mode::stopping_to_disabled:
      case Mode::freedrive_end: return stays(bad, "stopping; retry");
      case Mode::fault_ramp:
      case Mode::fault_quick_stop:
      case Mode::fault: return stays(flt, "in fault: send reset first");
      case Mode::estop_ramp:
      case Mode::estop_quick_stop:
      case Mode::estop: return stays(flt, "in estop: send reset first");
      case Mode::jogging:
      case Mode::homing:
      case Mode::homing_abort:
      case Mode::freedrive: break;
    }
  }
  switch (m) {
    case Mode::boot:
      switch (op) {
        case RequestOp::enable: return stays(bad, "drives not started");
        case RequestOp::disable: return {ok, "drives disabled", Mode::boot, kDisable};
        case RequestOp::stop: return not_moving;
        case RequestOp::estop: return {ok, "estop", Mode::estop, kDisable};
        case RequestOp::reset: return nothing_to_reset;
        case RequestOp::hold: return not_moving;
        case RequestOp::resume: return not_holding;
        case RequestOp::set_zero: return no_zero;
        case RequestOp::jog:
        case RequestOp::jog_cancel:
        case RequestOp::jog_keepalive:
        case RequestOp::home:
        case RequestOp::freedrive_on:
        case RequestOp::freedrive_off: break;  // (above)
      }
      break;
    case Mode::disabled:
      switch (op) {
        case RequestOp::enable: return {ok, "enabling", Mode::enabling, kEnable};
        case RequestOp::disable: return {ok, "disabled", Mode::disabled, kDisable};
        case RequestOp::stop: return not_moving;
        case RequestOp::estop: return {ok, "estop", Mode::estop, kDisable};
        case RequestOp::reset: return nothing_to_reset;
        case RequestOp::hold: return not_moving;
        case RequestOp::resume: return not_holding;
        case RequestOp::set_zero: return {ok, "zero_offset = [", Mode::disabled, kZero6};
        case RequestOp::jog:
        case RequestOp::jog_cancel:
        case RequestOp::jog_keepalive:
        case RequestOp::home:
        case RequestOp::freedrive_on:
        case RequestOp::freedrive_off: break;  // (above)
      }
      break;
    case Mode::enabling:
      switch (op) {
        case RequestOp::enable: return stays(ok, "already enabled");
        case RequestOp::disable: return {ok, "disabled", Mode::disabled, kDisable};
        case RequestOp::stop: return not_moving;
        case RequestOp::estop: return {ok, "estop", Mode::estop, kDisable};
        case RequestOp::reset: return nothing_to_reset;
        case RequestOp::hold: return not_moving;
        case RequestOp::resume: return not_holding;
        case RequestOp::set_zero: return no_zero;
        case RequestOp::jog:
        case RequestOp::jog_cancel:
        case RequestOp::jog_keepalive:
        case RequestOp::home:
        case RequestOp::freedrive_on:
        case RequestOp::freedrive_off: break;  // (above)
      }
      break;
    case Mode::idle:
      switch (op) {
        case RequestOp::enable: return stays(ok, "already enabled");
        case RequestOp::disable: return {ok, "disabled", Mode::disabled, kDisable};
        case RequestOp::stop: return not_moving;
        // the ramp from rest ends in the same cycle: drives off at once
        case RequestOp::estop: return {ok, "estop", Mode::estop, kDisable};
        case RequestOp::reset: return nothing_to_reset;
        case RequestOp::hold: return not_moving;  // nothing queued
        case RequestOp::resume: return not_holding;
        case RequestOp::set_zero: return no_zero;
        case RequestOp::jog:
        case RequestOp::jog_cancel:
        case RequestOp::jog_keepalive:
        case RequestOp::home:
        case RequestOp::freedrive_on:
        case RequestOp::freedrive_off: break;  // (above)
      }
      break;
    case Mode::moving:
      switch (op) {
        case RequestOp::enable: return stays(ok, "already enabled");
        case RequestOp::disable: return {ok, "stopping, then disabling", Mode::stopping_to_disabled, kNone};
        case RequestOp::stop: return {ok, "stopping", Mode::stopping_to_idle, kNone};
        case RequestOp::estop: return {ok, "estop", Mode::estop_ramp, kNone};
        case RequestOp::reset: return nothing_to_reset;
        case RequestOp::hold: return {ok, "feed hold", Mode::hold_ramp, kNone};
        case RequestOp::resume: return not_holding;
        case RequestOp::set_zero: return no_zero;
        case RequestOp::jog:
        case RequestOp::jog_cancel:
        case RequestOp::jog_keepalive:
        case RequestOp::home:
        case RequestOp::freedrive_on:
        case RequestOp::freedrive_off: break;  // (above)
      }
      break;
    case Mode::hold_ramp:
      switch (op) {
        case RequestOp::enable: return stays(ok, "already enabled");
        case RequestOp::disable: return {ok, "stopping, then disabling", Mode::stopping_to_disabled, kNone};
        case RequestOp::stop: return {ok, "stopping", Mode::stopping_to_idle, kNone};
        case RequestOp::estop: return {ok, "estop", Mode::estop_ramp, kNone};
        case RequestOp::reset: return nothing_to_reset;
        case RequestOp::hold: return stays(ok, "already holding");
        case RequestOp::resume: return {ok, "resumes when the hold's ramp ends", Mode::hold_ramp_resume, kNone};
        case RequestOp::set_zero: return no_zero;
        case RequestOp::jog:
        case RequestOp::jog_cancel:
        case RequestOp::jog_keepalive:
        case RequestOp::home:
        case RequestOp::freedrive_on:
        case RequestOp::freedrive_off: break;  // (above)
      }
      break;
    case Mode::hold_ramp_resume:  // the hold released, the ramp still running
      switch (op) {
        case RequestOp::enable: return stays(ok, "already enabled");
        case RequestOp::disable: return {ok, "stopping, then disabling", Mode::stopping_to_disabled, kNone};
        case RequestOp::stop: return {ok, "stopping", Mode::stopping_to_idle, kNone};
        case RequestOp::estop: return {ok, "estop", Mode::estop_ramp, kNone};
        case RequestOp::reset: return nothing_to_reset;
        case RequestOp::hold: return {ok, "feed hold", Mode::hold_ramp, kNone};  // the later request wins
        case RequestOp::resume: return stays(ok, "resumes when the hold's ramp ends");
        case RequestOp::set_zero: return no_zero;
        case RequestOp::jog:
        case RequestOp::jog_cancel:
        case RequestOp::jog_keepalive:
        case RequestOp::home:
        case RequestOp::freedrive_on:
        case RequestOp::freedrive_off: break;  // (above)
      }
      break;
    case Mode::hold_line:
      switch (op) {
        case RequestOp::enable: return stays(ok, "already enabled");
        case RequestOp::disable: return {ok, "stopping, then disabling", Mode::stopping_to_disabled, kNone};
        case RequestOp::stop: return {ok, "stopping", Mode::stopping_to_idle, kNone};
        case RequestOp::estop: return {ok, "estop", Mode::estop_ramp, kNone};
        case RequestOp::reset: return nothing_to_reset;
        case RequestOp::hold: return stays(ok, "already holding");
        case RequestOp::resume: return {ok, "resumed", Mode::moving, kNone};
        case RequestOp::set_zero: return no_zero;
        case RequestOp::jog:
        case RequestOp::jog_cancel:
        case RequestOp::jog_keepalive:
        case RequestOp::home:
        case RequestOp::freedrive_on:
        case RequestOp::freedrive_off: break;  // (above)
      }
      break;
    case Mode::held:  // a joint move held at rest: a stop's ramp from rest ends in the same cycle
      switch (op) {
        case RequestOp::enable: return stays(ok, "already enabled");
        case RequestOp::disable: return {ok, "stopping, then disabling", Mode::disabled, kDisable};
        case RequestOp::stop: return {ok, "stopping", Mode::idle, kNone};
        case RequestOp::estop: return {ok, "estop", Mode::estop, kDisable};
        case RequestOp::reset: return nothing_to_reset;
        case RequestOp::hold: return stays(ok, "already holding");
        case RequestOp::resume: return {ok, "resumed", Mode::moving, kNone};
        case RequestOp::set_zero: return no_zero;
        case RequestOp::jog:
        case RequestOp::jog_cancel:
        case RequestOp::jog_keepalive:
        case RequestOp::home:
        case RequestOp::freedrive_on:
        case RequestOp::freedrive_off: break;  // (above)
      }
      break;
    case Mode::stopping_to_idle:
    case Mode::stopping_to_disabled:
      switch (op) {
        case RequestOp::enable: return stays(bad, "stopping; retry");
        case RequestOp::disable: return {ok, "stopping, then disabling", Mode::stopping_to_disabled, kNone};
        case RequestOp::stop: return stays(ok, "stopping");
        case RequestOp::estop: return {ok, "estop", Mode::estop_ramp, kNone};
        case RequestOp::reset: return nothing_to_reset;
        case RequestOp::hold: return not_moving;
        case RequestOp::resume: return not_holding;
        case RequestOp::set_zero: return no_zero;
        case RequestOp::jog:
        case RequestOp::jog_cancel:
        case RequestOp::jog_keepalive:
        case RequestOp::home:
        case RequestOp::freedrive_on:
        case RequestOp::freedrive_off: break;  // (above)
      }
      break;
    case Mode::fault_ramp:
    case Mode::fault_quick_stop:
      switch (op) {
        case RequestOp::enable: return stays(flt, "in fault: send reset first");
        case RequestOp::disable: return {ok, "drives disabled", m, kDisable};  // the reaction goes on
        case RequestOp::stop: return not_moving;
        case RequestOp::estop:
          return {ok, "estop", m == Mode::fault_ramp ? Mode::estop_ramp : Mode::estop_quick_stop, kNone};
        case RequestOp::reset: return stays(bad, "still stopping; retry when the arm is at rest");
        case RequestOp::hold: return not_moving;
        case RequestOp::resume: return not_holding;
        case RequestOp::set_zero: return no_zero;
        case RequestOp::jog:
        case RequestOp::jog_cancel:
        case RequestOp::jog_keepalive:
        case RequestOp::home:
        case RequestOp::freedrive_on:
        case RequestOp::freedrive_off: break;  // (above)
      }
      break;
    case Mode::fault:
      switch (op) {
        case RequestOp::enable: return stays(flt, "in fault: send reset first");
        case RequestOp::disable: return {ok, "drives disabled", Mode::fault, kDisable};
        case RequestOp::stop: return not_moving;
        case RequestOp::estop: return {ok, "estop", Mode::estop, kDisable};
        case RequestOp::reset: return {ok, "reset; drives disabled, send enable", Mode::disabled, kDisable};
        case RequestOp::hold: return not_moving;
        case RequestOp::resume: return not_holding;
        case RequestOp::set_zero: return no_zero;
        case RequestOp::jog:
        case RequestOp::jog_cancel:
        case RequestOp::jog_keepalive:
        case RequestOp::home:
        case RequestOp::freedrive_on:
        case RequestOp::freedrive_off: break;  // (above)
      }
      break;
    case Mode::estop_ramp:
    case Mode::estop_quick_stop:
      switch (op) {
        case RequestOp::enable: return stays(flt, "in estop: send reset first");
        case RequestOp::disable: return {ok, "drives disabled", m, kDisable};
        case RequestOp::stop: return not_moving;
        case RequestOp::estop: return stays(ok, "estop");
        case RequestOp::reset: return stays(bad, "still stopping; retry when the arm is at rest");
        case RequestOp::hold: return not_moving;
        case RequestOp::resume: return not_holding;
        case RequestOp::set_zero: return no_zero;
        case RequestOp::jog:
        case RequestOp::jog_cancel:
        case RequestOp::jog_keepalive:
        case RequestOp::home:
        case RequestOp::freedrive_on:
        case RequestOp::freedrive_off: break;  // (above)
      }
      break;
    case Mode::estop:
      switch (op) {
        case RequestOp::enable: return stays(flt, "in estop: send reset first");
        case RequestOp::disable: return {ok, "drives disabled", Mode::estop, kDisable};
        case RequestOp::stop: return not_moving;
        case RequestOp::estop: return stays(ok, "estop");
        case RequestOp::reset: return {ok, "reset; drives disabled, send enable", Mode::disabled, kDisable};
        case RequestOp::hold: return not_moving;
        case RequestOp::resume: return not_holding;
        case RequestOp::set_zero: return no_zero;
        case RequestOp::jog:
        case RequestOp::jog_cancel:
        case RequestOp::jog_keepalive:
        case RequestOp::home:
        case RequestOp::freedrive_on:
        case RequestOp::freedrive_off: break;  // (above)
      }
      break;
    case Mode::jogging:  // a continuous joint jog, at speed
      switch (op) {
        case RequestOp::enable: return stays(ok, "already enabled");
        case RequestOp::disable: return {ok, "stopping, then disabling", Mode::stopping_to_disabled, kNone};
        case RequestOp::stop: return {ok, "stopping", Mode::stopping_to_idle, kNone};
        case RequestOp::estop: return {ok, "estop", Mode::estop_ramp, kNone};
        case RequestOp::reset: return nothing_to_reset;
        case RequestOp::hold: return stays(ok, "jog cancelled");  // GRBL: a feed hold cancels a jog
        case RequestOp::resume: return not_holding;
        case RequestOp::set_zero: return no_zero;
        case RequestOp::jog: return stays(ok, "jog retargeted");
        case RequestOp::jog_cancel: return stays(ok, "jog cancelled");
        case RequestOp::jog_keepalive: return stays(ok, "jog refreshed");
        case RequestOp::home:
        case RequestOp::freedrive_on:
        case RequestOp::freedrive_off: break;  // (above)
      }
      break;
    case Mode::homing:
    case Mode::homing_abort:
    case Mode::freedrive:
    case Mode::freedrive_end: break;  // (above)
  }
  FAIL("unreachable");
  return stays(ok, "");
}

std::string calls_text(const std::vector<Call>& c) {
  std::string s = "[";
  for (std::size_t i = 0; i < c.size(); ++i) s += std::string(i ? " " : "") + test::ServoSpy::to_string(c[i]);
  return s + "]";
}

/// One (mode, request) case: enter the mode, send the request, check reply, mode and bus.
void check_pair(Mode m, RequestOp op, bool drive_quick_stop, const Expect& e) {
  TableRig r(drive_quick_stop || needs_drive_quick_stop(m), {}, needs_homing(m), needs_freedrive(m));
  enter(r, m);
  r.expect(m, "entering");
  // The setpoint written in the cycle before the request (to check continuity).
  const std::size_t writes_before = r.spy->writes.size();
  const test::ServoSpy::WriteRecord prev =
      writes_before > 0 ? r.spy->writes.back() : test::ServoSpy::WriteRecord{};
  const Reply rep = r.request(op);
  const std::uint64_t c = r.spy->cycle;
  char ctx[256];
  std::snprintf(ctx, sizeof ctx, "(%s x %s -> %s%s) reply %s \"%s\"", to_string(m), to_string(op),
                to_string(action_for(m, op)), drive_quick_stop ? ", drive quick stop" : "", to_string(rep.result),
                rep.message);
  // the reply
  CHECK_TEXT(rep.result == e.result, ctx);
  CHECK_TEXT(std::string(rep.message).rfind(e.reply, 0) == 0, (std::string(ctx) + " wanted \"" + e.reply + "\"").c_str());
  // the mode, and what the console sees of it
  CHECK_TEXT(r.mode() == e.after, (std::string(ctx) + " mode " + to_string(r.mode()) + ", wanted " + to_string(e.after)).c_str());
  const Telemetry t = r.ctl->telemetry();
  CHECK_TEXT(t.mode == e.after, ctx);
  CHECK_TEXT(t.state == arm_state(e.after), ctx);
  CHECK_TEXT(t.holding == holding(e.after), ctx);
  // the power commands of that cycle
  const std::vector<Call> calls = r.spy->calls_in(c);
  CHECK_TEXT(calls == e.calls, (std::string(ctx) + " calls " + calls_text(calls) + ", wanted " + calls_text(e.calls)).c_str());
  // one setpoint vector per cycle, finite; powered: continuous with the last one; not
  // powered: the drives' measured positions (enabling / re-enabling never jumps)
  const std::vector<test::ServoSpy::WriteRecord> w = r.spy->writes_in(c);
  LONGS_EQUAL_TEXT(1, w.size(), ctx);
  LONGS_EQUAL_TEXT(6, w[0].n, ctx);
  for (std::size_t j = 0; j < 6; ++j) {
    CHECK_TEXT(std::isfinite(w[0].setpoint[j]), ctx);
    if (powered(e.after) && writes_before > 0) {
      const double vmax = kin::limits_from(r.app.chain).dyn[j].max_velocity * 1.10;
      CHECK_TEXT(std::fabs(w[0].setpoint[j] - prev.setpoint[j]) <= vmax * 1e-3 + 1e-9, ctx);
    }
    const hal::JointFeedback& fb = r.spy->feedback(j);
    if (!powered(m) && !powered(e.after) && fb.valid) DOUBLES_EQUAL_TEXT(fb.position, w[0].setpoint[j], 0.0, ctx);
  }
}

constexpr RequestOp kOps[] = {RequestOp::enable, RequestOp::disable,  RequestOp::stop,       RequestOp::estop,
                              RequestOp::reset,  RequestOp::hold,     RequestOp::resume,     RequestOp::set_zero,
                              RequestOp::jog,    RequestOp::jog_cancel, RequestOp::jog_keepalive, RequestOp::home,
                              RequestOp::freedrive_on, RequestOp::freedrive_off};

void walk_mode(Mode m) {
  for (RequestOp op : kOps) check_pair(m, op, false, expected(m, op));
}

}  // namespace

TEST_GROUP(ModeTable){};

// The table itself: one row per mode, one column per request, and the console-facing
// derivations agree with the coarse states.
TEST(ModeTable, EveryModeHasARowAndNamesItsState) {
  LONGS_EQUAL(kModes, kRequestTable.size());
  for (std::size_t i = 0; i < kModes; ++i) {
    const Mode m = static_cast<Mode>(i);
    STRCMP_EQUAL_TEXT(to_string(m), to_string(m), "name");
    CHECK_TEXT(std::string(to_string(m)) != "?", "every mode is named");
    for (RequestOp op : kOps) CHECK_TEXT(std::string(to_string(action_for(m, op))) != "?", to_string(m));
    // the coarse name is the mode's own for the modes that are not split
    if (m == Mode::boot || m == Mode::disabled || m == Mode::enabling || m == Mode::idle || m == Mode::moving ||
        m == Mode::fault || m == Mode::estop)
      STRCMP_EQUAL(to_string(m), to_string(arm_state(m)));
    // powered modes are what validate_and_write checks; a ramp is always powered
    if (ramping(m)) CHECK_TEXT(powered(m), to_string(m));
  }
}

// Every (mode x request) pair, one test per mode (a fresh arm per pair).
TEST(ModeTable, Boot) { walk_mode(Mode::boot); }
TEST(ModeTable, Disabled) { walk_mode(Mode::disabled); }
TEST(ModeTable, Enabling) { walk_mode(Mode::enabling); }
TEST(ModeTable, Idle) { walk_mode(Mode::idle); }
TEST(ModeTable, Moving) { walk_mode(Mode::moving); }
TEST(ModeTable, HoldRamp) { walk_mode(Mode::hold_ramp); }
TEST(ModeTable, HoldRampResume) { walk_mode(Mode::hold_ramp_resume); }
TEST(ModeTable, HoldLine) { walk_mode(Mode::hold_line); }
TEST(ModeTable, Held) { walk_mode(Mode::held); }
TEST(ModeTable, StoppingToIdle) { walk_mode(Mode::stopping_to_idle); }
TEST(ModeTable, StoppingToDisabled) { walk_mode(Mode::stopping_to_disabled); }
TEST(ModeTable, FaultRamp) { walk_mode(Mode::fault_ramp); }
TEST(ModeTable, FaultQuickStop) { walk_mode(Mode::fault_quick_stop); }
TEST(ModeTable, Fault) { walk_mode(Mode::fault); }
TEST(ModeTable, EstopRamp) { walk_mode(Mode::estop_ramp); }
TEST(ModeTable, EstopQuickStop) { walk_mode(Mode::estop_quick_stop); }
TEST(ModeTable, Estop) { walk_mode(Mode::estop); }
TEST(ModeTable, Jogging) { walk_mode(Mode::jogging); }
TEST(ModeTable, Homing) { walk_mode(Mode::homing); }
TEST(ModeTable, HomingAbort) { walk_mode(Mode::homing_abort); }
TEST(ModeTable, Freedrive) { walk_mode(Mode::freedrive); }  // (freedrive_end lasts 1-3 cycles: fw_dynamics)

// With safety.stop = "drive", an e-stop of a powered arm is the drives' quick stop
// (controlword 0x0002 in the same cycle), also over a ramp already running.
TEST(ModeTable, DriveQuickStopTakesOverEveryPoweredMode) {
  const Expect to_quick{ok, "estop", Mode::estop_quick_stop, kQuick};
  for (Mode m : {Mode::moving, Mode::hold_ramp, Mode::hold_line, Mode::stopping_to_idle, Mode::stopping_to_disabled,
                 Mode::jogging})
    check_pair(m, RequestOp::estop, true, to_quick);
  // a fault while moving is a quick stop too, and the e-stop after it keeps it
  check_pair(Mode::fault_quick_stop, RequestOp::estop, true, {ok, "estop", Mode::estop_quick_stop, kNone});
}

// ---------------------------------------------------------------------------
// Cartesian IK failure: keep the precomputed value, count it
// ---------------------------------------------------------------------------

namespace {
struct FailingIk {
  int calls = 0;
  int fail_every = 1;  ///< fail every k-th call (1 = always)
  int failed = 0;
};
kin::Status failing_ik(const kin::Chain& chain, const kin::Pose& target, const kin::JointVector& q_near,
                       kin::JointVector& q_out, void* ctx) {
  (void)chain;
  (void)target;
  auto* f = static_cast<FailingIk*>(ctx);
  ++f->calls;
  if (f->calls % f->fail_every == 0) {
    ++f->failed;
    q_out = q_near;
    return kin::Status::unreachable;
  }
  // "succeed" with a value 10 urad off the path: distinguishable from the fallback
  q_out = q_near;
  q_out[0] += 1e-5;
  return kin::Status::ok;
}

void go_to_working_pose(TableRig& r) {
  r.enable();
  MotionItem* m = r.ctl->motions().back();
  JointMove& jm = m->payload.emplace<JointMove>();
  m->id = 1;
  jm.override = 1.0;
  jm.goal = kin::JointVector(6);
  jm.goal << 20, -40, 160, 10, -50, 30;
  jm.goal *= kDeg;
  r.ctl->motions().commit();
  r.cycle();  // starts it
  r.run_until(Mode::idle, 10000, "move to the working pose");
}
}  // namespace

TEST(ModeTable, IkFailureKeepsThePrecomputedPathAndCountsIt) {
  TableRig r(false);
  FailingIk f;
  go_to_working_pose(r);
  MotionItem* m = r.plan_line(0.03);
  const kin::CartesianTrajectory ct = std::get<CartesianMove>(m->payload).path;  // copy of the plan (the RT side uses the queued one)
  std::get<CartesianMove>(m->payload).path.ik = kin::IkSolver{&failing_ik, &f};
  r.ctl->motions().commit();
  const std::uint64_t first = r.spy->cycle + 1;
  r.cycle();  // starts it
  r.run_until(Mode::idle, 10000, "line with failing IK");
  const Telemetry t = r.ctl->telemetry();
  CHECK(t.state == ArmState::idle);
  CHECK(t.cause == FaultCause::none);
  LONGS_EQUAL(2, t.done_id);  // finished, not refused
  CHECK(f.failed > 100);
  LONGS_EQUAL(f.failed, t.ik_fallbacks);
  // every sample of the line is the precomputed joint value at its time
  double worst = 0;
  int samples = 0;
  for (const auto& w : r.spy->writes) {
    if (w.cycle < first) continue;
    const double tt = static_cast<double>(w.cycle - first + 1) * 1e-3;
    if (tt >= ct.duration) break;
    kin::JointVector q, qd, qdd;
    ct.sample_precomputed(tt, q, qd, qdd);
    for (int j = 0; j < 6; ++j) worst = std::fmax(worst, std::fabs(q[j] - w.setpoint[static_cast<std::size_t>(j)]));
    ++samples;
  }
  CHECK(samples > 100);
  CHECK_TEXT(worst < 1e-12, std::to_string(worst).c_str());
  LONGS_EQUAL(samples + 1, f.failed);  // + the last sample, at the end (then the goal is written)
}

TEST(ModeTable, IkFailureOfSomeSamplesCountsExactlyThose) {
  TableRig r(false);
  FailingIk f;
  f.fail_every = 3;
  go_to_working_pose(r);
  MotionItem* m = r.plan_line(0.03);
  const kin::CartesianTrajectory ct = std::get<CartesianMove>(m->payload).path;
  std::get<CartesianMove>(m->payload).path.ik = kin::IkSolver{&failing_ik, &f};
  r.ctl->motions().commit();
  const std::uint64_t first = r.spy->cycle + 1;
  r.cycle();  // starts it
  r.run_until(Mode::idle, 10000, "line with IK failing every third sample");
  LONGS_EQUAL(f.failed, r.ctl->telemetry().ik_fallbacks);
  CHECK(f.failed > 30 && f.calls > 3 * f.failed - 3);
  // failed samples are the precomputed value; solved ones are the IK's (10 urad off on joint 1)
  int k = 0;
  for (const auto& w : r.spy->writes) {
    if (w.cycle < first) continue;
    const double tt = static_cast<double>(w.cycle - first + 1) * 1e-3;
    if (tt >= ct.duration) break;
    ++k;
    kin::JointVector q, qd, qdd;
    ct.sample_precomputed(tt, q, qd, qdd);
    const double off = w.setpoint[0] - q[0];
    if (k % 3 == 0) DOUBLES_EQUAL(0.0, off, 1e-12);
    else DOUBLES_EQUAL(1e-5, off, 1e-12);
  }
  CHECK(k > 90);
}

// ---------------------------------------------------------------------------
// hal::JointState::stopping: powered on the way down, never reported as `enabling`
// ---------------------------------------------------------------------------

// An e-stop with the drives' quick stop: while they ramp on their own the joints say
// `stopping` (never `enabling`), the controller follows them, and it powers down in
// the first cycle after none is `stopping` or `enabled` any more.
TEST(ModeTable, DriveQuickStopReportsStoppingUntilRest) {
  sim::MotorParams motor;
  motor.max_accel = 4.0 * 131072;  // drives that take a while to stop (4 rev/s^2)
  TableRig r(true, motor);
  enter(r, Mode::moving);
  r.request(RequestOp::estop);
  r.expect(Mode::estop_quick_stop, "estop");
  int stopping_cycles = 0;
  bool powered_now = true;  // some joint stopping / enabled in the feedback the last cycle read
  for (int i = 0; i < 3000 && r.mode() == Mode::estop_quick_stop; ++i) {
    r.cycle();
    powered_now = false;
    for (std::size_t j = 0; j < 6; ++j) {
      const hal::JointState s = r.spy->feedback(j).state;
      CHECK_TEXT(s != hal::JointState::enabling, "a stopping drive reported as enabling");
      CHECK_TEXT(s != hal::JointState::fault, "fault during the quick stop");
      if (s == hal::JointState::stopping || s == hal::JointState::enabled) powered_now = true;
      // a powered joint cannot be re-zeroed
      if (s == hal::JointState::stopping) LONGS_EQUAL(int(hal::Status::bad_state), int(r.app.servo->set_position_zero(j)));
    }
    if (powered_now) ++stopping_cycles;
  }
  r.expect(Mode::estop, "quick stop finished");
  CHECK_TEXT(!powered_now, "powered down while a drive was still stopping");
  CHECK_TEXT(stopping_cycles > 20, std::to_string(stopping_cycles).c_str());  // the drives' ramp, not one cycle
  // power-down: one disable, in the cycle the mode became estop
  const std::vector<Call> last = r.spy->calls_in(r.spy->cycle);
  CHECK(last == kDisable);
  for (std::size_t j = 0; j < 6; ++j) CHECK(r.spy->feedback(j).state != hal::JointState::stopping);
}

// `disable` of an idle arm: the joints go stopping -> disabled, not enabling -> disabled.
// A resume sent while a feed hold still ramps down is kept, not refused (a '~' typed half a
// second after a '!' must not depend on how long the ramp takes): at rest the move resumes
// and reaches its goal.
TEST(ModeTable, AResumeDuringTheHoldsRampResumesTheMoveAtRest) {
  TableRig r(false);
  r.enable();
  const kin::JointVector start = r.q_cmd();
  r.start_joint_move();
  r.request(RequestOp::hold);
  r.expect(Mode::hold_ramp, "hold");
  const Reply rep = r.request(RequestOp::resume);
  LONGS_EQUAL_TEXT(int(RtResult::ok), int(rep.result), rep.message);
  r.expect(Mode::hold_ramp_resume, "resume during the ramp");
  r.run_until(Mode::moving, 5000, "the hold's ramp, then the resume");
  r.run_until(Mode::idle, 20000, "the resumed move");
  for (int j = 0; j < 6; ++j) DOUBLES_EQUAL(start[j] + (j % 2 ? -40.0 : 40.0) * kDeg, r.q_cmd()[j], 1e-6);
  LONGS_EQUAL(1, r.ctl->telemetry().done_id);
}

// A hold after a resume kept during the ramp wins: the arm comes to rest and stays held.
TEST(ModeTable, AHoldAfterAKeptResumeHoldsAtRest) {
  TableRig r(false);
  enter(r, Mode::hold_ramp_resume);
  r.request(RequestOp::hold);
  r.expect(Mode::hold_ramp, "hold after the kept resume");
  r.run_until(Mode::held, 5000, "the hold's ramp");
  const kin::JointVector at = r.q_cmd();
  r.cycles(500);
  r.expect(Mode::held, "held");
  for (int j = 0; j < 6; ++j) DOUBLES_EQUAL(at[j], r.q_cmd()[j], 0.0);
}

TEST(ModeTable, DisableReportsStoppingThenDisabled) {
  TableRig r(false);
  r.enable();
  r.request(RequestOp::disable);
  r.expect(Mode::disabled, "disable");
  bool saw_stopping = false;
  for (int i = 0; i < 500; ++i) {
    bool all_disabled = true;
    for (std::size_t j = 0; j < 6; ++j) {
      const hal::JointState s = r.spy->feedback(j).state;
      CHECK(s != hal::JointState::enabling);
      saw_stopping = saw_stopping || s == hal::JointState::stopping;
      all_disabled = all_disabled && s == hal::JointState::disabled;
    }
    if (all_disabled) break;
    r.cycle();
  }
  CHECK(saw_stopping);
  for (std::size_t j = 0; j < 6; ++j) LONGS_EQUAL(int(hal::JointState::disabled), int(r.spy->feedback(j).state));
  STRCMP_EQUAL("stopping", hal::to_string(hal::JointState::stopping));
}

// ---------------------------------------------------------------------------
// The motion executor's segment phases (SegPhase, mode_table.hpp): every phase reached
// through the console on the real controller, then hold, resume and stop in it. The
// expected phases and modes are written out by hand (not read from the table); every
// cycle's (mode, phase) pair is checked against the cells that may exist.
// ---------------------------------------------------------------------------

namespace {

struct QueueRig : test::ControllerRig {
  std::vector<std::pair<Mode, SegPhase>> bad_cells;  ///< (mode, phase) pairs no cell allows
  std::vector<bool> seen = std::vector<bool>(kSegPhases, false);

  QueueRig() : ControllerRig(FwConfig{}) {
    after_cycle = [this] {
      const Mode m = app.ctl->mode();
      const SegPhase p = app.ctl->segment_phase();
      seen[static_cast<std::size_t>(p)] = true;
      if (!allowed(m, p)) bad_cells.emplace_back(m, p);
    };
  }
  static bool allowed(Mode m, SegPhase p);
  void step() {
    cycle();
    app.console->poll(session);
  }
  /// A console line run to its end; anything but an ok fails the test.
  std::string cmd(const std::string& line) {
    const std::string out = console(line);
    if (out.rfind("ok", 0) != 0 && out.find("\nok") == std::string::npos) FAIL((line + ": " + out).c_str());
    return out;
  }
  Mode mode() const { return app.ctl->mode(); }
  SegPhase phase() const { return app.ctl->segment_phase(); }
  bool idle() const { return mode() == Mode::idle && app.ctl->motions().empty(); }
  void settle() {
    for (int i = 0; i < 60000 && !idle(); ++i) step();
    if (!idle()) FAIL((std::string("not idle: mode ") + to_string(mode())).c_str());
  }
  /// The running motion is a path move's joint segment.
  bool joint_path_segment() {
    const MotionItem* m = app.ctl->motions().front();
    const auto* p = m != nullptr ? std::get_if<PathMove>(&m->payload) : nullptr;
    return p != nullptr && p->seg.kind == kin::PathKind::joint;
  }
};

// The cells: which segment phase each mode may run (at the end of a cycle).
bool QueueRig::allowed(Mode m, SegPhase p) {
  if (m == Mode::moving) return p != SegPhase::none;
  if (m == Mode::hold_ramp) return p == SegPhase::plan || p == SegPhase::path_to_end || p == SegPhase::path_to_start;
  if (m == Mode::hold_line) return p == SegPhase::line || p == SegPhase::path_line;
  if (m == Mode::held)
    return p == SegPhase::none || p == SegPhase::plan || p == SegPhase::line || p == SegPhase::dwell ||
           p == SegPhase::path_line || p == SegPhase::path_to_end || p == SegPhase::path_to_start;
  return p == SegPhase::none;
}

std::string joints_cmd(const kin::JointVector& q, double blend_deg) {
  std::string t = "movej";
  char b[48];
  for (int j = 0; j < 6; ++j) {
    std::snprintf(b, sizeof b, " %.12g", q[j] / kDeg);
    t += b;
  }
  t += " speed=100";
  if (blend_deg >= 0) {
    std::snprintf(b, sizeof b, " blend=%g", blend_deg);
    t += b;
  }
  return t;
}

std::string line_cmd(const Eigen::Vector3d& p, double blend_mm) {
  char b[160];
  std::snprintf(b, sizeof b, "movel %.9g %.9g %.9g speed=100", p.x() * 1e3, p.y() * 1e3, p.z() * 1e3);
  std::string t = b;
  if (blend_mm >= 0) {
    std::snprintf(b, sizeof b, " blend=%g", blend_mm);
    t += b;
  }
  return t;
}

using test::deg;

const kin::JointVector kStart = deg({0, -30, 60, 0, 40, 0});

/// One phase's case: the moves queued from rest at kStart, the phase to run into (and, for
/// a path run, whether the running segment must be the joint one), what a hold leaves
/// (mode right after it, phase kept) and the phase a resume goes on in. `pre`: a hold
/// and a resume first (the phases only a resume enters).
struct PhaseCase {
  SegPhase phase;
  bool joint_segment;
  bool pre;
  Mode hold_mode;
  SegPhase hold_phase;
};

std::vector<std::string> moves_for(QueueRig& r, SegPhase p) {
  const Eigen::Vector3d p0 = r.flange(kStart).translation();
  const Eigen::Vector3d A = p0 + Eigen::Vector3d(-0.10, 0, 0), B = A + Eigen::Vector3d(0, 0.10, 0),
                        C = B + Eigen::Vector3d(0, 0, -0.08);
  const kin::JointVector kA = deg({30, -20, 40, 0, 20, 0}), kB = deg({70, -30, 60, 20, 30, 30});
  const kin::JointVector kJ = deg({25, -35, 70, 10, 35, 10});
  switch (p) {
    case SegPhase::none: return {};
    case SegPhase::plan: return {joints_cmd(kA, -1)};
    case SegPhase::blend_open: return {joints_cmd(kA, 20), joints_cmd(kB, 20)};
    case SegPhase::blend_closed: return {joints_cmd(kA, 20), joints_cmd(kB, 0), joints_cmd(kA, -1)};
    case SegPhase::line: return {line_cmd(A, -1)};
    case SegPhase::dwell: return {"G4 S1"};
    case SegPhase::path_open: return {line_cmd(A, 10)};
    case SegPhase::path_closed: return {line_cmd(A, 10), "G4 S1"};
    case SegPhase::path_overlap:
    case SegPhase::path_line:
    case SegPhase::path_to_start: return {line_cmd(A, 10), line_cmd(B, 10), line_cmd(C, -1)};
    case SegPhase::path_to_end: {
      const Eigen::Vector3d L0 = p0 + Eigen::Vector3d(0, 0, -0.08);
      const Eigen::Vector3d L = r.flange(kJ).translation() + Eigen::Vector3d(0, 0, -0.12);
      return {line_cmd(L0, 25), joints_cmd(kJ, 20), line_cmd(L, -1)};
    }
  }
  return {};
}

/// Queue the case's moves from rest at kStart and run into its phase (after a hold and
/// resume for the phases only a resume enters).
void enter_phase(QueueRig& r, const PhaseCase& c) {
  r.cmd("enable");
  for (int i = 0; i < 3000 && r.mode() != Mode::idle; ++i) r.step();
  r.cmd(joints_cmd(kStart, -1));
  r.settle();
  for (const std::string& m : moves_for(r, c.phase)) r.cmd(m);
  const SegPhase first = c.phase == SegPhase::path_line       ? SegPhase::path_open
                         : c.phase == SegPhase::path_to_start ? SegPhase::path_overlap
                         : c.phase == SegPhase::path_to_end   ? SegPhase::path_open
                                                              : c.phase;
  const auto there = [&] {
    if (r.phase() != first && !(c.joint_segment && r.phase() == SegPhase::path_closed)) return false;
    return !c.joint_segment || r.joint_path_segment();
  };
  for (int i = 0; i < 20000 && !there(); ++i) r.step();
  for (int i = 0; i < 50 && first != SegPhase::path_overlap; ++i) r.step();  // well into it (at speed)
  if (!there()) FAIL((std::string("never ran in phase ") + to_string(first) + ", now " + to_string(r.phase())).c_str());
  if (!c.pre) return;
  r.cmd("hold");
  for (int i = 0; i < 5000 && r.mode() != Mode::held; ++i) r.step();
  r.cmd("resume");
  for (int i = 0; i < 100; ++i) r.step();
  if (r.phase() != c.phase) FAIL((std::string("resumed in ") + to_string(r.phase()) + ", wanted " + to_string(c.phase)).c_str());
}

// What a hold does in each phase, written out by hand: a joint plan or blended joint run ramps
// down (resume plans again from where it stopped), a line stops on its line, a dwell's clock
// stops, a path segment alone stops as a line or ramps down (then a joint move to its end),
// in an overlap it ramps down and resume goes back to the next segment's start.
const std::vector<PhaseCase> kPhaseCases = {
    {SegPhase::plan, false, false, Mode::hold_ramp, SegPhase::plan},
    {SegPhase::blend_open, false, false, Mode::hold_ramp, SegPhase::plan},
    {SegPhase::blend_closed, false, false, Mode::hold_ramp, SegPhase::plan},
    {SegPhase::line, false, false, Mode::hold_line, SegPhase::line},
    {SegPhase::dwell, false, false, Mode::held, SegPhase::dwell},
    {SegPhase::path_open, false, false, Mode::hold_line, SegPhase::path_line},
    {SegPhase::path_closed, false, false, Mode::hold_line, SegPhase::path_line},
    {SegPhase::path_overlap, false, false, Mode::hold_ramp, SegPhase::path_to_start},
    {SegPhase::path_line, false, true, Mode::hold_line, SegPhase::path_line},
    {SegPhase::path_to_end, true, true, Mode::hold_ramp, SegPhase::path_to_end},
    {SegPhase::path_to_start, false, true, Mode::hold_ramp, SegPhase::path_to_start},
};

/// The final setpoint of the case's moves run without a hold.
kin::JointVector reference_end(SegPhase p) {
  QueueRig r;
  r.cmd("enable");
  for (int i = 0; i < 3000 && r.mode() != Mode::idle; ++i) r.step();
  r.cmd(joints_cmd(kStart, -1));
  r.settle();
  for (const std::string& m : moves_for(r, p)) r.cmd(m);
  r.settle();
  return r.q_cmd();
}

void walk_phase(const PhaseCase& c) {
  const kin::JointVector end = reference_end(c.phase);
  // hold, then resume: the rest of the queue runs to the same end
  {
    QueueRig r;
    enter_phase(r, c);
    LONGS_EQUAL(static_cast<int>(c.phase), static_cast<int>(r.phase()));
    const std::uint32_t done0 = r.app.ctl->telemetry().done_id;
    r.cmd("hold");
    if (r.mode() != c.hold_mode)
      FAIL((std::string(to_string(c.phase)) + ": hold entered " + to_string(r.mode()) + ", wanted " + to_string(c.hold_mode)).c_str());
    if (r.phase() != c.hold_phase)
      FAIL((std::string(to_string(c.phase)) + ": hold left " + to_string(r.phase()) + ", wanted " + to_string(c.hold_phase)).c_str());
    for (int i = 0; i < 5000 && r.mode() != Mode::held; ++i) r.step();
    if (r.mode() != Mode::held) FAIL((std::string(to_string(c.phase)) + ": never held").c_str());
    LONGS_EQUAL(static_cast<int>(c.hold_phase), static_cast<int>(r.phase()));
    r.cmd("resume");
    LONGS_EQUAL(static_cast<int>(Mode::moving), static_cast<int>(r.mode()));
    LONGS_EQUAL(static_cast<int>(c.hold_phase), static_cast<int>(r.phase()));  // resumed in the phase the hold kept
    r.settle();
    CHECK(r.app.ctl->telemetry().done_id > done0);
    CHECK_TEXT((r.q_cmd() - end).norm() < 1e-6, to_string(c.phase));
  }
  // stop: the run ends, nothing is left of it
  {
    QueueRig r;
    enter_phase(r, c);
    r.cmd("stop");
    LONGS_EQUAL(static_cast<int>(SegPhase::none), static_cast<int>(r.phase()));
    CHECK(r.app.ctl->motions().empty());
    for (int i = 0; i < 5000 && r.mode() != Mode::idle; ++i) r.step();
    LONGS_EQUAL(static_cast<int>(Mode::idle), static_cast<int>(r.mode()));
    for (int i = 0; i < 50; ++i) r.step();
    CHECK_TEXT(r.bad_cells.empty(), to_string(c.phase));
  }
}

}  // namespace

TEST_GROUP(SegmentPhases){};

TEST(SegmentPhases, EveryPhaseHasANameAndEveryCaseIsWalked) {
  std::vector<bool> walked(kSegPhases, false);
  walked[static_cast<std::size_t>(SegPhase::none)] = true;  // the modes without a segment: every walk above
  for (const PhaseCase& c : kPhaseCases) walked[static_cast<std::size_t>(c.phase)] = true;
  for (std::size_t p = 0; p < kSegPhases; ++p) {
    CHECK(std::string(to_string(static_cast<SegPhase>(p))) != "?");
    CHECK_TEXT(walked[p], to_string(static_cast<SegPhase>(p)));
  }
}
TEST(SegmentPhases, Plan) { walk_phase(kPhaseCases[0]); }
TEST(SegmentPhases, BlendOpen) { walk_phase(kPhaseCases[1]); }
TEST(SegmentPhases, BlendClosed) { walk_phase(kPhaseCases[2]); }
TEST(SegmentPhases, Line) { walk_phase(kPhaseCases[3]); }
TEST(SegmentPhases, Dwell) { walk_phase(kPhaseCases[4]); }
TEST(SegmentPhases, PathOpen) { walk_phase(kPhaseCases[5]); }
TEST(SegmentPhases, PathClosed) { walk_phase(kPhaseCases[6]); }
TEST(SegmentPhases, PathOverlap) { walk_phase(kPhaseCases[7]); }
TEST(SegmentPhases, PathLine) { walk_phase(kPhaseCases[8]); }
TEST(SegmentPhases, PathToEnd) { walk_phase(kPhaseCases[9]); }
TEST(SegmentPhases, PathToStart) { walk_phase(kPhaseCases[10]); }
