#pragma once
// A small "IK nearest to a seed" for the motion layer: damped Newton
// iterations on the full 6-D pose error, starting at the seed. It follows the
// seed's branch when the seed is close (how movel calls IK: every knot is
// seeded with the previous one), works for any serial chain, and is heap-free.
// It is the fallback movel uses until / unless a dedicated solver from
// kinematics/ik is passed instead (IkSolver in trajectory_cartesian.hpp).
#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/status.hpp"

namespace servoarm::kin {

/// Matches IkNearestFn. ctx is unused (pass nullptr).
/// @retval ok           |position error| + |rotation error| < 1e-10 (m + rad)
/// @retval unreachable  no convergence from this seed (q_out untouched)
/// @retval wrong_size   q_near.size() != chain.n_joints
/// @retval bad_input    NaN/Inf in the seed or the target
Status ik_nearest_newton(const Chain& chain, const Pose& target, const JointVector& q_near, JointVector& q_out,
                         void* ctx);

}  // namespace servoarm::kin
