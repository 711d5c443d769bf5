// SPDX-License-Identifier: Apache-2.0
// Orientation conversions: ZYZ (both branches and the s_beta = 0 cases of
// Custódio et al. (IST 2019), §2), RPY, quaternion, axis-angle; round trips over random
// rotations and the edge cases.
#include "kin_test_util.hpp"

using namespace servoarm;
using namespace servoarm::test;

namespace {
Eigen::Matrix3d random_rotation(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0, 1);
  Eigen::Quaterniond q(n(rng), n(rng), n(rng), n(rng));
  q.normalize();
  return q.toRotationMatrix();
}
double diff(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) { return (a - b).cwiseAbs().maxCoeff(); }
}  // namespace

TEST_GROUP(Orientation){};

TEST(Orientation, ZyzMatrixIsSeed001Eq4) {
  // Rz(a) Ry(b) Rz(g) composed by Eigen, against our printed form of eq. (4).
  const kin::EulerZyz e{0.3, 1.1, -2.0};
  const Eigen::Matrix3d ref = (Eigen::AngleAxisd(e.alpha, Eigen::Vector3d::UnitZ()) *
                               Eigen::AngleAxisd(e.beta, Eigen::Vector3d::UnitY()) *
                               Eigen::AngleAxisd(e.gamma, Eigen::Vector3d::UnitZ())).toRotationMatrix();
  CHECK(diff(ref, kin::rotation_from_zyz(e)) < 1e-15);
}

TEST(Orientation, ZyzBothBranchesRoundTrip) {
  std::mt19937_64 rng(11);
  for (int n = 0; n < 20000; ++n) {
    const Eigen::Matrix3d R = random_rotation(rng);
    const kin::ZyzSolutions z = kin::zyz_from_rotation(R);
    LONGS_EQUAL(2, z.count);
    CHECK_FALSE(z.singular);
    CHECK(std::sin(z.branch[0].beta) > 0);
    CHECK(std::sin(z.branch[1].beta) < 0);
    CHECK(diff(R, kin::rotation_from_zyz(z.branch[0])) < 1e-12);
    CHECK(diff(R, kin::rotation_from_zyz(z.branch[1])) < 1e-12);
    // the second branch is (alpha + pi, -beta, gamma + pi)
    DOUBLES_EQUAL(0.0, kin::wrap_pi(z.branch[1].alpha - z.branch[0].alpha - M_PI), 1e-9);
    DOUBLES_EQUAL(-z.branch[0].beta, z.branch[1].beta, 1e-12);
  }
}

TEST(Orientation, ZyzSingularCasesKeepAlphaAndSolveGamma) {
  // c_beta = 1: alpha + gamma = atan2(r21, r11)
  for (double total : {-3.0, -1.0, 0.0, 0.5, 2.9}) {
    const Eigen::Matrix3d R = kin::rotation_from_zyz({total, 0.0, 0.0});
    for (double keep : {0.0, 0.7, -2.5}) {
      const kin::ZyzSolutions z = kin::zyz_from_rotation(R, keep);
      CHECK(z.singular);
      LONGS_EQUAL(1, z.count);
      DOUBLES_EQUAL(keep, z.branch[0].alpha, 0);
      DOUBLES_EQUAL(0.0, z.branch[0].beta, 0);
      DOUBLES_EQUAL(0.0, kin::wrap_pi(z.branch[0].alpha + z.branch[0].gamma - total), 1e-12);
      CHECK(diff(R, kin::rotation_from_zyz(z.branch[0])) < 1e-12);
    }
  }
  // c_beta = -1: alpha - gamma = atan2(-r21, -r11)
  for (double a : {-2.0, 0.0, 1.3}) {
    for (double g : {-1.0, 0.4}) {
      const Eigen::Matrix3d R = kin::rotation_from_zyz({a, M_PI, g});
      const kin::ZyzSolutions z = kin::zyz_from_rotation(R, 0.25);
      CHECK(z.singular);
      DOUBLES_EQUAL(M_PI, z.branch[0].beta, 0);
      DOUBLES_EQUAL(0.0, kin::wrap_pi((z.branch[0].alpha - z.branch[0].gamma) - (a - g)), 1e-12);
      CHECK(diff(R, kin::rotation_from_zyz(z.branch[0])) < 1e-12);
    }
  }
}

TEST(Orientation, RpyRoundTripAndGimbalLock) {
  std::mt19937_64 rng(12);
  for (int n = 0; n < 20000; ++n) {
    const Eigen::Matrix3d R = random_rotation(rng);
    const Eigen::Vector3d rpy = kin::rpy_from_rotation(R);
    CHECK(std::abs(rpy[1]) <= M_PI / 2 + 1e-15);
    CHECK(diff(R, kin::rotation_from_rpy(rpy[0], rpy[1], rpy[2])) < 1e-12);
  }
  // R = Rz(y) Ry(p) Rx(r), independently composed
  const Eigen::Matrix3d ref = (Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()) *
                               Eigen::AngleAxisd(-0.2, Eigen::Vector3d::UnitY()) *
                               Eigen::AngleAxisd(1.0, Eigen::Vector3d::UnitX())).toRotationMatrix();
  CHECK(diff(ref, kin::rotation_from_rpy(1.0, -0.2, 0.3)) < 1e-15);
  for (double pitch : {M_PI / 2, -M_PI / 2}) {
    const Eigen::Matrix3d R = kin::rotation_from_rpy(0.4, pitch, -1.2);
    const Eigen::Vector3d rpy = kin::rpy_from_rotation(R);
    DOUBLES_EQUAL(0.0, rpy[0], 0);
    DOUBLES_EQUAL(pitch, rpy[1], 1e-7);
    CHECK(diff(R, kin::rotation_from_rpy(rpy[0], rpy[1], rpy[2])) < 1e-9);
  }
}

TEST(Orientation, QuaternionAndAxisAngle) {
  std::mt19937_64 rng(13);
  for (int n = 0; n < 20000; ++n) {
    const Eigen::Matrix3d R = random_rotation(rng);
    const Eigen::Quaterniond q = kin::quaternion_from_rotation(R);
    CHECK(q.w() >= 0);
    DOUBLES_EQUAL(1.0, q.norm(), 1e-14);
    Eigen::Matrix3d R2;
    CHECK(kin::rotation_from_quaternion(q.w() * 3, q.x() * 3, q.y() * 3, q.z() * 3, R2) == kin::Status::ok);
    CHECK(diff(R, R2) < 1e-12);
    const kin::AxisAngle aa = kin::axis_angle_from_rotation(R);
    CHECK(aa.angle >= 0 && aa.angle <= M_PI);
    Eigen::Matrix3d R3;
    CHECK(kin::rotation_from_axis_angle(aa.axis, aa.angle, R3) == kin::Status::ok);
    CHECK(diff(R, R3) < 1e-12);
    // rotation_error(R, R3') recovers a known small rotation
    const Eigen::Vector3d w(1e-3 * (n % 7), -2e-3, 5e-4);
    Eigen::Matrix3d Rw;
    kin::rotation_from_axis_angle(w, w.norm(), Rw);
    CHECK((kin::rotation_error(R, Rw * R) - w).norm() < 1e-12);
  }
  // angle = pi and angle = 0
  Eigen::Matrix3d Rpi;
  kin::rotation_from_axis_angle(Eigen::Vector3d(1, 1, 0), M_PI, Rpi);
  const kin::AxisAngle aa = kin::axis_angle_from_rotation(Rpi);
  DOUBLES_EQUAL(M_PI, aa.angle, 1e-12);
  CHECK((kin::rotation_error(Eigen::Matrix3d::Identity(), Rpi).cwiseAbs() - Eigen::Vector3d(M_PI / std::sqrt(2), M_PI / std::sqrt(2), 0)).norm() < 1e-9);
  DOUBLES_EQUAL(0.0, kin::axis_angle_from_rotation(Eigen::Matrix3d::Identity()).angle, 0);
}

TEST(Orientation, BadInputIsRefusedAndLeavesOutputUntouched) {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  CHECK(kin::rotation_from_quaternion(0, 0, 0, 0, R) == kin::Status::bad_input);
  CHECK(kin::rotation_from_quaternion(std::numeric_limits<double>::quiet_NaN(), 0, 0, 1, R) == kin::Status::bad_input);
  CHECK(kin::rotation_from_axis_angle(Eigen::Vector3d::Zero(), 1.0, R) == kin::Status::bad_input);
  CHECK(kin::rotation_from_axis_angle(Eigen::Vector3d::UnitX(), std::numeric_limits<double>::infinity(), R) == kin::Status::bad_input);
  CHECK(R.isIdentity(0));
  CHECK(kin::is_rotation(Eigen::Matrix3d::Identity()));
  Eigen::Matrix3d M = Eigen::Matrix3d::Identity();
  M(0, 1) = 0.1;  // not orthonormal
  CHECK_FALSE(kin::is_rotation(M));
  CHECK_FALSE(kin::is_rotation(-Eigen::Matrix3d::Identity()));  // det = -1
  M = Eigen::Matrix3d::Identity();
  M(2, 2) = std::numeric_limits<double>::quiet_NaN();
  CHECK_FALSE(kin::is_rotation(M));
}
