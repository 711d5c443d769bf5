// SPDX-License-Identifier: Apache-2.0
// Zero heap: FK, frames, Jacobian, manipulability, condition number,
// precision and every orientation conversion, counted by the malloc hook.
// This file is also compiled with EIGEN_NO_MALLOC.
#include "alloc_counter.hpp"
#include "kin_test_util.hpp"

using namespace servoarm;
using namespace servoarm::test;

TEST_GROUP(ZeroHeap){};

TEST(ZeroHeap, KinematicsHotPathsAllocateNothing) {
  // The counter itself must see an allocation, or a zero below proves nothing.
  if (alloc_counter_counts()) {
    AllocScope probe;
    probe_malloc_free();
    int* volatile q = new int(3);  // volatile: the compiler may not elide the pair
    delete q;
    LONGS_EQUAL(2, probe.end());
  } else {
    UT_PRINT("allocation counter off in this build (memcheck): the zero counts below prove nothing here");
  }
  for (const auto& m : kin::builtin_models()) {
    const kin::Chain c = model(m.name);  // loading allocates: outside the scope
    std::mt19937_64 rng(31);
    kin::JointVector qs[64];
    for (auto& q : qs) q = random_q(c, rng);
    AllocScope scope;
    double sink = 0;
    for (const auto& q : qs) {
      kin::Pose T;
      kin::FrameSet F;
      kin::Jacobian J;
      kin::forward(c, q, T);
      kin::forward_frames(c, q, F, T);
      kin::jacobian(c, q, J, &T);
      sink += kin::manipulability(J) + kin::condition_number(J);
      Eigen::Vector3d dw;
      kin::cartesian_precision(c, q, kin::JointVector::Constant(c.n_joints, 1e-4), dw);
      const kin::ZyzSolutions z = kin::zyz_from_rotation(T.linear());
      const Eigen::Matrix3d R1 = kin::rotation_from_zyz(z.branch[0]);
      const Eigen::Vector3d rpy = kin::rpy_from_rotation(R1);
      const Eigen::Matrix3d R2 = kin::rotation_from_rpy(rpy[0], rpy[1], rpy[2]);
      const Eigen::Quaterniond qq = kin::quaternion_from_rotation(R2);
      Eigen::Matrix3d R3;
      kin::rotation_from_quaternion(qq.w(), qq.x(), qq.y(), qq.z(), R3);
      const kin::AxisAngle aa = kin::axis_angle_from_rotation(R3);
      kin::rotation_from_axis_angle(aa.axis, aa.angle, R3);
      sink += kin::rotation_error(R1, R3).norm() + dw.sum() + (kin::is_rotation(R3) ? 1 : 0) +
              (kin::within_limits(c, q) ? 1 : 0);
    }
    const std::size_t allocations = scope.end();
    CHECK(std::isfinite(sink));
    if (allocations != 0) FAIL((std::string(m.name) + ": heap allocations on the hot path: " + std::to_string(allocations)).c_str());
  }
}
