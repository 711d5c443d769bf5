// SPDX-License-Identifier: Apache-2.0
#pragma once
// Fixed-capacity types of the kinematics core. Everything here lives on the
// stack or inside a struct: Eigen matrices with a compile-time maximum size
// never touch the heap (the library is compiled with EIGEN_NO_MALLOC).
#include <Eigen/Core>
#include <Eigen/Geometry>

namespace servoarm::kin {

/// Most joints a chain may have (revolute + prismatic).
inline constexpr int kMaxJoints = 8;
/// Most DH rows a chain may have: joints plus fixed (auxiliary) rows.
inline constexpr int kMaxRows = 16;

static_assert(kMaxJoints >= 6 && kMaxJoints <= kMaxRows, "a chain holds at least a 6-axis arm");

/// Joint values, one per joint (radians for revolute, metres for prismatic).
/// Runtime size 0..kMaxJoints, storage inline.
using JointVector = Eigen::Matrix<double, Eigen::Dynamic, 1, Eigen::ColMajor, kMaxJoints, 1>;

/// Geometric Jacobian: 6 rows (linear velocity first, then angular), one
/// column per joint.
using Jacobian = Eigen::Matrix<double, 6, Eigen::Dynamic, Eigen::ColMajor, 6, kMaxJoints>;

/// Position-only Jacobian (3 x n).
using PositionJacobian = Eigen::Matrix<double, 3, Eigen::Dynamic, Eigen::ColMajor, 3, kMaxJoints>;

/// A rigid transform (rotation + translation), metres.
using Pose = Eigen::Isometry3d;

/// Every frame along a chain: index 0 is the base frame (the base transform),
/// index k the frame after DH row k-1; the tool frame is not included.
struct FrameSet {
  Eigen::Isometry3d frame[kMaxRows + 1];
  int count = 0;
};

}  // namespace servoarm::kin
