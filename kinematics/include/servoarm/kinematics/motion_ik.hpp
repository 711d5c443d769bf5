#pragma once
// IK adapters for movel (IkSolver in trajectory_cartesian.hpp).
//
// ik_nearest_for_motion: kinematics/ik's solver (closed form where the chain
// has one, numerical otherwise), nearest to the seed, *including* solutions
// outside the joint limits -- so that movel's path check can refuse with
// path_out_of_limits and the joint, instead of a bare "no solution".
// This is what armctl plan movel and the firmware use.
//
// ik_nearest_newton: a small "IK nearest to a seed": damped Newton
// iterations on the full 6-D pose error, starting at the seed. It follows the
// seed's branch when the seed is close (how movel calls IK: every knot is
// seeded with the previous one), works for any serial chain, and is heap-free.
// It is the fallback movel uses until / unless a dedicated solver from
// kinematics/ik is passed instead (IkSolver in trajectory_cartesian.hpp).
#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/status.hpp"

namespace servoarm::kin {

struct IkModel;

/// Matches IkNearestFn; ctx = const IkModel* (from ik_prepare on the same chain).
/// Returns ik_solve_nearest's status (ok / singular: q_out set).
Status ik_nearest_for_motion(const Chain& chain, const Pose& target, const JointVector& q_near, JointVector& q_out,
                             void* ctx);

/// Matches IkNearestFn. ctx is unused (pass nullptr).
/// @retval ok           |position error| + |rotation error| < 1e-10 (m + rad)
/// @retval unreachable  no convergence from this seed (q_out untouched)
/// @retval wrong_size   q_near.size() != chain.n_joints
/// @retval bad_input    NaN/Inf in the seed or the target
Status ik_nearest_newton(const Chain& chain, const Pose& target, const JointVector& q_near, JointVector& q_out,
                         void* ctx);

}  // namespace servoarm::kin
