// SPDX-License-Identifier: Apache-2.0
// The arm service's teach points (arm_service.hpp): taught where the arm is, deleted, gone to
// by name, kept in the points file (program/points.hpp) before a change is answered. Console
// thread: allocates, does file I/O.
#include <utility>

#include <cmath>

#include "servoarm/kinematics/chain.hpp"
#include "servoarm/service/arm_service.hpp"

namespace servoarm::fw {

const char* to_string(PointRefusal r) {
  switch (r) {
    case PointRefusal::none: return "none";
    case PointRefusal::not_here: return "not_here";
    case PointRefusal::bad_point: return "bad_point";
    case PointRefusal::no_point: return "no_point";
    case PointRefusal::joint_count: return "joint_count";
    case PointRefusal::program: return "program";
    case PointRefusal::storage: return "storage";
  }
  return "?";
}

std::string ArmService::load_points(const std::string& path) {
  prog::PointsData d;
  if (!path.empty()) {
    if (std::string e = prog::load_points_file(path, n_, d); !e.empty()) return e;
  }
  points_ = std::move(d);
  points_file_ = path;
  return "";
}

// The points as `d`, written to the points file first (when there is one); `r` as answered.
PointResult ArmService::store_points(prog::PointsData d, PointResult r) {
  if (!points_file_.empty()) {
    if (std::string e = prog::save_points_file(points_file_, d); !e.empty()) {
      r.error = CmdError::storage;
      r.refusal = PointRefusal::storage;
      r.reason = std::move(e);
      r.count = points_.points.size();
      return r;
    }
  }
  points_ = std::move(d);
  r.kept = !points_file_.empty();
  r.count = points_.points.size();
  return r;
}

PointResult ArmService::teach(const TeachRequest& rq) {
  PointResult r;
  r.here = teach_here();
  r.count = points_.points.size();
  if (!r.here.ok() && !(rq.dry && r.here.refusal == TeachRefusal::not_homed)) {  // (a dry run moves and stores nothing)
    r.error = r.here.error;
    r.refusal = PointRefusal::not_here;
    r.reason = r.here.reason;
    return r;
  }
  const std::size_t ti = rq.tool < tools_.size() ? rq.tool : tool_;
  const std::size_t fi = rq.frame < frames_.size() ? rq.frame : frame_;
  prog::TeachPoint& p = r.point;
  p.name = rq.name;
  p.q = r.here.q;
  if (kin::forward(tools_[ti]->chain, p.q, p.pose) != kin::Status::ok) p.pose.translation().setConstant(std::nan(""));
  p.tool = tools_[ti]->def.name;
  p.frame = frames_[fi].name;
  r.replaced = prog::find_point(points_, rq.name) != nullptr;
  prog::PointsData d = points_;
  if (std::string e = prog::put_point(d, p); !e.empty()) {
    r.error = CmdError::bad_option;
    r.refusal = PointRefusal::bad_point;
    r.reason = std::move(e);
    return r;
  }
  if (rq.dry) return r;
  return store_points(std::move(d), std::move(r));
}

PointResult ArmService::delete_point(std::string_view name, bool dry) {
  PointResult r;
  r.here = teach_here();
  r.count = points_.points.size();
  if (r.here.refusal == TeachRefusal::program) {
    r.error = CmdError::bad_state;
    r.refusal = PointRefusal::program;
    return r;
  }
  const prog::TeachPoint* p = prog::find_point(points_, name);
  if (p == nullptr) {
    r.error = CmdError::bad_option;
    r.refusal = PointRefusal::no_point;
    return r;
  }
  r.point = *p;
  if (dry) return r;
  prog::PointsData d = points_;
  prog::delete_point(d, name);
  return store_points(std::move(d), std::move(r));
}

PointResult ArmService::move_to_point(const PointMove& rq, const MoveContext& cx) {
  PointResult r;
  r.count = points_.points.size();
  const prog::TeachPoint* p = prog::find_point(points_, rq.name);
  if (p == nullptr) {
    r.error = CmdError::bad_option;
    r.refusal = PointRefusal::no_point;
    return r;
  }
  r.point = *p;
  if (p->q.size() != n_) {
    r.error = CmdError::bad_option;
    r.refusal = PointRefusal::joint_count;
    r.joints = static_cast<int>(p->q.size());
    return r;
  }
  if (!rq.line) {
    MoveJoints m;
    m.goal = p->q;
    m.speed_pct = rq.speed > 0 ? rq.speed : cfg_.default_joint_speed_pct;
    m.blend = rq.blend;
    r.move = move(m, cx);
  } else {
    MoveLine m;  // where the point's joints put the context's tool, on a straight line
    const kin::Chain& ch = cx.chain != nullptr ? *cx.chain : tools_[tool_]->chain;
    if (kin::forward(ch, p->q, m.target) != kin::Status::ok) m.target.translation().setConstant(std::nan(""));
    m.speed = rq.speed > 0 ? rq.speed : 0.0;
    m.blend = rq.blend;
    r.move = move(m, cx);
  }
  r.error = r.move.error;
  return r;
}

}  // namespace servoarm::fw
