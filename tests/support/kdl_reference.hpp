// SPDX-License-Identifier: Apache-2.0
#pragma once
// Build an Orocos KDL chain from a servoarm chain: the independent reference
// for FK, Jacobian and IK cross-checks (tests and armbench only).
//
// KDL segment pose = joint.pose(q) * f_tip, with the joint at the segment root.
//  standard row  Rz(theta + dir q) Tz(d) Tx(a) Rx(alpha):
//     Segment(Joint(RotZ, scale=dir), Frame::DH(a, alpha, d, theta))
//  modified row  Rx(alpha) Tx(a) Rz(theta + dir q) Tz(d):
//     Segment(Joint::None, Rx(alpha) Tx(a)) then Segment(Joint(RotZ, dir), Rz(theta) Tz(d))
//  prismatic rows use TransZ the same way; fixed rows Joint::None.
#include <kdl/chain.hpp>
#include <kdl/frames.hpp>
#include <kdl/jntarray.hpp>
#include <kdl/segment.hpp>

#include "servoarm/kinematics/chain.hpp"

namespace servoarm::test {

inline KDL::Frame to_kdl(const Eigen::Isometry3d& T) {
  const auto& R = T.linear();
  const auto& p = T.translation();
  return KDL::Frame(KDL::Rotation(R(0, 0), R(0, 1), R(0, 2), R(1, 0), R(1, 1), R(1, 2), R(2, 0), R(2, 1), R(2, 2)),
                    KDL::Vector(p.x(), p.y(), p.z()));
}

inline Eigen::Isometry3d from_kdl(const KDL::Frame& F) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) T.linear()(r, c) = F.M(r, c);
    T.translation()[r] = F.p[r];
  }
  return T;
}

inline KDL::Chain to_kdl(const kin::Chain& chain) {
  using kin::JointType;
  KDL::Chain out;
  if (!chain.base.matrix().isIdentity(0)) out.addSegment(KDL::Segment(KDL::Joint(KDL::Joint::None), to_kdl(chain.base)));
  for (int i = 0; i < chain.n_rows; ++i) {
    const kin::DhRow& r = chain.rows[static_cast<std::size_t>(i)];
    const KDL::Joint::JointType jt = r.type == JointType::revolute    ? KDL::Joint::RotZ
                                     : r.type == JointType::prismatic ? KDL::Joint::TransZ
                                                                      : KDL::Joint::None;
    const KDL::Joint joint = jt == KDL::Joint::None ? KDL::Joint(KDL::Joint::None)
                                                    : KDL::Joint(jt, r.direction, 0.0);
    if (chain.convention == kin::Convention::standard) {
      out.addSegment(KDL::Segment(joint, KDL::Frame::DH(r.a, r.alpha, r.d, r.theta)));
    } else {
      out.addSegment(KDL::Segment(KDL::Joint(KDL::Joint::None),
                                  KDL::Frame(KDL::Rotation::RotX(r.alpha), KDL::Vector(r.a, 0, 0))));
      out.addSegment(KDL::Segment(joint, KDL::Frame(KDL::Rotation::RotZ(r.theta), KDL::Vector(0, 0, r.d))));
    }
  }
  if (!chain.tool.matrix().isIdentity(0)) out.addSegment(KDL::Segment(KDL::Joint(KDL::Joint::None), to_kdl(chain.tool)));
  return out;
}

inline KDL::JntArray to_kdl(const kin::JointVector& q) {
  KDL::JntArray a(static_cast<unsigned>(q.size()));
  for (int i = 0; i < q.size(); ++i) a(static_cast<unsigned>(i)) = q[i];
  return a;
}

}  // namespace servoarm::test
