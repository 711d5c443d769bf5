// SPDX-License-Identifier: Apache-2.0
// Inverse kinematics, choosing one solution: the branch of a configuration,
// the solution nearest to the current joints (weighted, within the limits
// unless allowed, on the same branch if asked), and ik_solve_nearest (closed
// form where the model has one, else the numerical solver). Real-time,
// heap-free. (ik_nearest_fn, the IkSolver adapter: motion_ik.cpp.)
#include "servoarm/kinematics/ik.hpp"

#include <cmath>

#include "ik_detail.hpp"

namespace servoarm::kin {

namespace detail {

Status ik_nearest_numeric(const Chain& chain, const Pose& target, const JointVector& q_current, JointVector& q_out) {
  IkNumericOptions o;
  o.max_restarts = 0;  // continuity first: stay on the current branch
  o.stall_iterations = 0;  // and give the start from the current joints every iteration
  o.max_iterations = 100;
  IkNumericResult nr;
  ik_numeric(chain, target, q_current, o, nr);
  if (nr.status != Status::ok) return nr.status == Status::not_converged ? Status::unreachable : nr.status;
  q_out = nr.q;
  return Status::ok;
}

}  // namespace detail

Branch ik_branch_of(const IkModel& model, const JointVector& q) {
  Pose T;
  if (forward(model.chain, q, T) != Status::ok) return {};
  IkResult r;
  ik_solve_all(model, T, &q, r);
  int best = -1;
  double bd = 0;
  for (int i = 0; i < r.count; ++i) {
    double d = 0;
    for (int j = 0; j < q.size(); ++j) d += detail::joint_distance(model.chain, j, r.solutions[static_cast<std::size_t>(i)].q[j], q[j]);
    if (best < 0 || d < bd) {
      best = i;
      bd = d;
    }
  }
  return best >= 0 ? r.solutions[static_cast<std::size_t>(best)].branch : Branch{};
}

int ik_choose(const IkModel& model, const IkResult& result, const JointVector& q_current, const IkChoice& choice) {
  const Chain& c = model.chain;
  if (q_current.size() != c.n_joints) return -1;
  Branch want{};
  if (choice.keep_branch) want = ik_branch_of(model, q_current);
  int best = -1;
  double bd = 0;
  for (int i = 0; i < result.count; ++i) {
    const IkSolution& s = result.solutions[static_cast<std::size_t>(i)];
    if (!s.within_limits && !choice.allow_out_of_limits) continue;
    if (choice.keep_branch && !(s.branch == want)) continue;
    double d = 0;
    for (int j = 0; j < c.n_joints; ++j) {
      const double w = choice.weights.size() == c.n_joints ? choice.weights[j] : 1.0;
      const double dj = s.q[j] - q_current[j];  // wrapped solutions: the travel really needed
      d += w * dj * dj;
    }
    if (best < 0 || d < bd) {
      best = i;
      bd = d;
    }
  }
  return best;
}

Status ik_solve_nearest(const IkModel& model, const Pose& target, const JointVector& q_current, JointVector& q_out,
                        const IkChoice& choice) {
  if (q_current.size() != model.chain.n_joints) return Status::wrong_size;
  if (model.method != IkMethod::none) {
    IkResult r;
    ik_solve_all(model, target, &q_current, r);
    if (!is_ok(r.status) && r.count == 0) return r.status;
    const int i = ik_choose(model, r, q_current, choice);
    if (i < 0) return r.count ? Status::out_of_limits : Status::unreachable;
    q_out = r.solutions[static_cast<std::size_t>(i)].q;
    return r.solutions[static_cast<std::size_t>(i)].singular ? Status::singular : Status::ok;
  }
  return detail::ik_nearest_numeric(model.chain, target, q_current, q_out);
}

}  // namespace servoarm::kin
