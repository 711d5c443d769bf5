// SPDX-License-Identifier: Apache-2.0
#pragma once
// Rigid-body dynamics of a DH chain: inverse dynamics (recursive Newton-Euler),
// gravity and Coriolis/centrifugal torques, the joint-space mass matrix (composite
// rigid body) and forward dynamics (M qdd = tau - c - g - friction, fixed-size LDL^T).
//
//   tau = M(q) qdd + c(q, qd) + g(q) + friction(qd)
//
// M includes the reflected rotor inertia G^2 Jm of each joint (on the diagonal);
// friction(qd) = viscous qd + coulomb sign(qd) per joint (0 at qd = 0).
// Both DH conventions, fixed rows (their bodies ride on the body before them),
// prismatic joints, negative directions and the base transform are handled; the
// tool transform carries no mass. Gravity is chain.gravity, in the world frame.
// The inertial data come from the description file (docs/dynamics.md).
//
// Real-time: every function here except set_inertial() is heap-free, lock-free and
// throws nothing (fixed-size arrays, bounded loops).
//
// Return codes of every function below:
// @retval ok
// @retval wrong_size   a joint vector's length != chain.n_joints
// @retval bad_input    a value is NaN or Inf (outputs untouched)
// @retval unsupported  the chain carries no inertial data (chain.has_inertial false);
//                      forward_dynamics also when M is not positive definite (a joint
//                      that moves no mass and has no rotor inertia)
#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/status.hpp"
#include "servoarm/kinematics/types.hpp"

namespace servoarm::kin {

/// Joint-space mass matrix, n x n, storage inline.
using MassMatrix =
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor, kMaxJoints, kMaxJoints>;

/// Store the inertial data of row `row` (mass, com, inertia, rotor, friction as given;
/// the derived fields are computed here) and mark the chain as having inertial data.
/// Set-up code; call after the row was added. Returns bad_input for a row index out
/// of range or a non-finite value.
Status set_inertial(Chain& chain, int row, const LinkInertial& link);

/// tau = M qdd + c + g + friction: the joint torques (forces) that produce qdd.
Status inverse_dynamics(const Chain& chain, const JointVector& q, const JointVector& qd,
                        const JointVector& qdd, JointVector& tau);

/// g(q): the torques that hold the arm still against gravity.
Status gravity_torques(const Chain& chain, const JointVector& q, JointVector& tau);

/// c(q, qd): Coriolis and centrifugal torques (no gravity, no friction).
Status coriolis(const Chain& chain, const JointVector& q, const JointVector& qd, JointVector& c);

/// friction(qd) = viscous qd + coulomb sign(qd).
Status friction_torques(const Chain& chain, const JointVector& qd, JointVector& tau);

/// M(q), symmetric positive definite when every joint moves some inertia.
Status mass_matrix(const Chain& chain, const JointVector& q, MassMatrix& M);

/// qdd = M^-1 (tau - c - g - friction).
Status forward_dynamics(const Chain& chain, const JointVector& q, const JointVector& qd,
                        const JointVector& tau, JointVector& qdd);

}  // namespace servoarm::kin
