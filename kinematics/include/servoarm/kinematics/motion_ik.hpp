// SPDX-License-Identifier: Apache-2.0
#pragma once
// The motion IK adapter: the IkSolver (trajectory_cartesian.hpp) that
// plan_movel, its path check and the Cartesian sampling call at every knot.
//
//   IkSolver ik = make_ik_solver(model, options);
//
// One adapter for every caller -- armfw (movel, G1, the `ik` command, the RT
// thread's Cartesian samples) and `armctl plan` alike -- so that what armctl
// previews is what the firmware runs: the same model and the same options
// give the same joints, bit for bit. IkSolverOptions names everything callers
// may differ in; nothing else is chosen behind their back.
//
// Joint limits: the model's. ik_prepare() copies the chain, and its joint
// limits are the ones solutions are checked against and wrapped into (and the
// numerical fallback clamps to). To plan against other limits (armfw's
// configured ones, narrower than the description's), prepare the model from
// the chain that carries them; armctl previews armfw's motion only if it
// prepares its model from that same chain. (There is no separate limits
// option: IkSolver's ctx is the model, nothing else has to outlive it.)
//
// Heap-free, no exceptions; real-time where the model has a closed form (its
// worst case is bounded), bounded but slower through the numerical fallback.
//
// Kept for the firmware until it switches to make_ik_solver (firmware/src/
// console.cpp, cli_plan.cpp, cli_ik.cpp call them), same signatures and
// results, now thin wrappers of the adapter:
//   ik_nearest_fn          (ik.hpp) = make_ik_solver(model, {}).fn
//   ik_nearest_for_motion           = make_ik_solver(model, {.allow_out_of_limits = true}).fn
//   ik_nearest_newton               = make_ik_solver(model, {.closed_form = false,
//                                                           .fallback = IkFallback::newton}).fn
//                                     (ctx unused: callable without a model)
//   ik_solve_nearest       (ik.hpp): the closed-form / numeric core the adapter calls.
// tests/ik/test_ik_adapter.cpp checks the equalities on seeded sweeps.
#include <cstdint>

#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/status.hpp"
#include "servoarm/kinematics/trajectory_cartesian.hpp"

namespace servoarm::kin {

struct IkModel;

/// What the adapter does where it does not use a closed form (the model has
/// none, IkMethod::none, or IkSolverOptions::closed_form is false).
enum class IkFallback : std::uint8_t {
  /// ik_numeric() on the model's chain from q_near: damped least squares,
  /// no restarts (continuity first), 100 iterations, every iterate clamped
  /// into the joint limits (so never out of limits whatever
  /// allow_out_of_limits says). No convergence: unreachable.
  numeric,
  /// ik_nearest_newton() on the call's chain: damped Newton on the full 6-D
  /// pose error from q_near, steps capped at 0.3 rad; ignores the joint
  /// limits (movel's path check refuses what is outside).
  newton,
  /// No fallback: Status::unsupported.
  none,
};
const char* to_string(IkFallback f);

struct IkSolverOptions {
  /// false: the nearest solution *within the joint limits*; a pose whose
  /// every solution is outside them fails with out_of_limits (what the
  /// firmware's console wants: nothing outside the limits is ever commanded).
  /// true: the nearest solution whatever the limits, so that plan_movel's
  /// path check can refuse with path_out_of_limits and name the joint instead
  /// of a bare "no solution" (closed forms only; see IkFallback::numeric).
  bool allow_out_of_limits = false;
  /// true: the model's closed form where it has one (nearest to q_near,
  /// weights 1, any branch). false: always the fallback.
  bool closed_form = true;
  /// Where no closed form is used.
  IkFallback fallback = IkFallback::numeric;
};

/// The IkSolver for `model` with `options`: fn chosen by the options, ctx =
/// &model (the model must outlive the solver; the options are copied into
/// the choice of fn). fn's chain argument must be the model's chain (same
/// number of joints), except with IkFallback::newton where no closed form is
/// used (it solves the chain it is given).
/// fn returns:
/// @retval ok / singular  q_out set (singular: the target is at a singularity)
/// @retval out_of_limits  solutions exist, none within the limits (allow_out_of_limits false)
/// @retval unreachable    no solution (closed form), no convergence (numeric, newton)
/// @retval bad_input      ctx null, chain does not match the model, NaN/Inf target or seed
/// @retval wrong_size     q_near.size() != the chain's joints
/// @retval unsupported    no closed form and IkFallback::none
IkSolver make_ik_solver(const IkModel& model, const IkSolverOptions& options = {});

/// Matches IkNearestFn; ctx = const IkModel* (from ik_prepare on the same chain).
/// Kept for the firmware: make_ik_solver(model, {.allow_out_of_limits = true}).
Status ik_nearest_for_motion(const Chain& chain, const Pose& target, const JointVector& q_near, JointVector& q_out,
                             void* ctx);

/// Matches IkNearestFn. ctx is unused (pass nullptr). The Newton fallback of
/// the adapter (IkFallback::newton), callable without a model.
/// @retval ok           |position error| + |rotation error| < 1e-10 (m + rad)
/// @retval unreachable  no convergence from this seed (q_out untouched)
/// @retval wrong_size   q_near.size() != chain.n_joints
/// @retval bad_input    NaN/Inf in the seed or the target
Status ik_nearest_newton(const Chain& chain, const Pose& target, const JointVector& q_near, JointVector& q_out,
                         void* ctx);

}  // namespace servoarm::kin
