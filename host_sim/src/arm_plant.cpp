// SPDX-License-Identifier: Apache-2.0
#include "servoarm/sim/arm_plant.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>

#include <Eigen/Cholesky>

#include "servoarm/sim/virtual_drive.hpp"

namespace servoarm::sim {

namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

// Sampling range of joint j for sizing: its limits, or +-pi (+-0.5 m) where they are
// unlimited or wider than one turn.
void sample_range(const kin::DhRow& row, double& lo, double& hi) {
  const bool prism = row.type == kin::JointType::prismatic;
  const double wide = prism ? 0.5 : std::numbers::pi;
  lo = std::isfinite(row.lower) ? row.lower : -wide;
  hi = std::isfinite(row.upper) ? row.upper : wide;
  if (!prism && hi - lo > kTwoPi) lo = -wide, hi = wide;
  if (prism && hi - lo > 2.0) lo = std::max(lo, -1.0), hi = std::min(hi, 1.0);
  if (hi < lo) std::swap(lo, hi);
}

}  // namespace

void auto_size(const kin::Chain& chain, const ArmPlantParams& p, std::array<ArmPlantJointInfo, kin::kMaxJoints>& out) {
  const int n = chain.n_joints;
  out = {};
  // 65 poses: zero, then 64 seeded uniform ones within the sampling ranges.
  std::uint64_t rng = 0x5eed5eedULL;
  auto uniform = [&rng] {
    rng ^= rng >> 12;
    rng ^= rng << 25;
    rng ^= rng >> 27;
    return double((rng * 0x2545F4914F6CDD1DULL) >> 11) * (1.0 / 9007199254740992.0);
  };
  kin::JointVector q = kin::JointVector::Zero(n), g(n);
  kin::MassMatrix M(n, n);
  for (int s = 0; s <= 64; ++s) {
    if (s > 0)
      for (int j = 0; j < n; ++j) {
        double lo, hi;
        sample_range(chain.joint(j), lo, hi);
        q[j] = lo + (hi - lo) * uniform();
      }
    if (kin::mass_matrix(chain, q, M) != kin::Status::ok) continue;
    const bool have_g = kin::gravity_torques(chain, q, g) == kin::Status::ok;
    for (int j = 0; j < n; ++j) {
      auto& o = out[static_cast<std::size_t>(j)];
      o.max_inertia = std::max(o.max_inertia, M(j, j));
      if (have_g) o.max_gravity = std::max(o.max_gravity, std::fabs(g[j]));
    }
  }
  const double wv = kTwoPi * p.velocity_bandwidth_hz;
  for (int j = 0; j < n; ++j) {
    auto& o = out[static_cast<std::size_t>(j)];
    const ServoGains& given = p.gains[static_cast<std::size_t>(j)];
    const double acc = std::max(p.sizing_acceleration, chain.joint(j).dynamics.max_acceleration);
    o.gains.kv = given.kv > 0 ? given.kv : wv * o.max_inertia;
    o.gains.kp = given.kp > 0 ? given.kp : wv / 4.0;
    o.gains.ki = given.ki;
    o.gains.torque_limit = given.torque_limit > 0 ? given.torque_limit : 2.0 * (o.max_gravity + o.max_inertia * acc);
    const double w = kTwoPi * 200.0;
    o.stop_stiffness = w * w * o.max_inertia;
    o.stop_damping = std::sqrt(o.stop_stiffness * o.max_inertia);  // damping ratio 0.5
  }
}

std::string ArmPlant::configure(const kin::Chain& chain, std::span<const hal::JointScaling> scaling,
                                const ArmPlantParams& params) {
  configured_ = false;
  const std::string model = chain.name.data();
  if (!chain.has_inertial)
    return "robot '" + model +
           "' has no inertial data (mass, com, inertia per joint in its description; docs/dynamics.md): the dynamic "
           "plant needs them (the first-order plant does not)";
  n_ = chain.n_joints;
  if (n_ < 1 || n_ > kin::kMaxJoints) return "robot '" + model + "': joint count not supported";
  if (scaling.size() != static_cast<std::size_t>(n_))
    return "dynamic plant: " + std::to_string(scaling.size()) + " drive scalings for the " + std::to_string(n_) +
           " joints of '" + model + "'";
  if (!(params.step > 0) || params.step > 2 * hal::kMillisecond)
    return "dynamic plant: step must be within (0, 2 ms]";
  if (!(params.velocity_bandwidth_hz > 0) || !(params.coulomb_velocity > 0) || !(params.sizing_acceleration > 0))
    return "dynamic plant: velocity bandwidth, Coulomb smoothing velocity and sizing acceleration must be positive";
  params_ = params;
  chain_ = chain;
  if (!params_.gravity) chain_.gravity = {0.0, 0.0, 0.0};
  for (int j = 0; j < n_; ++j) {
    if (!scaling[static_cast<std::size_t>(j)].valid()) return "dynamic plant: joint " + std::to_string(j + 1) + ": invalid drive scaling";
    scaling_[static_cast<std::size_t>(j)] = scaling[static_cast<std::size_t>(j)];
    kin::LinkInertial& li = chain_.inertial[static_cast<std::size_t>(chain_.joint_row[static_cast<std::size_t>(j)])];
    viscous_[static_cast<std::size_t>(j)] = li.viscous + params.extra_viscous[static_cast<std::size_t>(j)];
    coulomb_[static_cast<std::size_t>(j)] = li.coulomb + params.extra_coulomb[static_cast<std::size_t>(j)];
    li.viscous = li.coulomb = 0;  // applied by the plant (smoothed Coulomb)
    if (viscous_[static_cast<std::size_t>(j)] < 0 || coulomb_[static_cast<std::size_t>(j)] < 0)
      return "dynamic plant: joint " + std::to_string(j + 1) + ": negative friction";
  }
  auto_size(chain_, params_, info_);
  for (int j = 0; j < n_; ++j) {
    auto& o = info_[static_cast<std::size_t>(j)];
    if (!(o.max_inertia > 0))
      return "robot '" + model + "': joint " + std::to_string(j + 1) +
             " moves no inertia (no mass beyond it and no rotor inertia): the dynamic plant cannot integrate it";
    const double g = std::fabs(scaling_[static_cast<std::size_t>(j)].gear_ratio);
    o.rated_torque_mnm = std::max(1.0, std::round(o.gains.torque_limit / 3.0 / g * 1000.0));
  }
  if (params_.stop.joint >= n_) return "dynamic plant: stop on joint " + std::to_string(params_.stop.joint + 1) + ", which does not exist";
  if (params_.stop.joint >= 0) {
    auto& o = info_[static_cast<std::size_t>(params_.stop.joint)];
    if (params_.stop.stiffness > 0) o.stop_stiffness = params_.stop.stiffness;
    if (params_.stop.damping > 0) o.stop_damping = params_.stop.damping;
    if (params_.stop.side != 1 && params_.stop.side != -1) return "dynamic plant: stop side must be +1 or -1";
  }
  q_ = kin::JointVector::Zero(n_);
  qd_ = kin::JointVector::Zero(n_);
  tau_motor_ = kin::JointVector::Zero(n_);
  tau_ext_ = kin::JointVector::Zero(n_);
  tau_contact_ = kin::JointVector::Zero(n_);
  drives_ = {};
  locked_ = {};
  steps_ = 0;
  started_ = false;
  configured_ = true;
  return "";
}

void ArmPlant::attach(int j, VirtualDrive* d) {
  if (!configured_ || j < 0 || j >= n_ || d == nullptr) return;
  const auto& o = info_[static_cast<std::size_t>(j)];
  const hal::JointScaling& s = scaling_[static_cast<std::size_t>(j)];
  drives_[static_cast<std::size_t>(j)] = d;
  d->attach_plant(this, s, o.gains.kp, o.gains.kv, o.gains.ki, o.gains.torque_limit,
                  static_cast<std::uint32_t>(o.rated_torque_mnm));
  // The plant starts where the drive's shaft is, at the drive's time.
  q_[j] = double(s.direction) * (d->pos_ - double(s.zero_offset)) / s.counts_per_si();
  qd_[j] = 0;
  if (!started_ || d->t_ > t_) t_ = d->t_;
  started_ = true;
}

void ArmPlant::set_state(const kin::JointVector& q, const kin::JointVector& qd) {
  if (q.size() != n_ || qd.size() != n_) return;
  q_ = q;
  qd_ = qd;
}

double ArmPlant::kinetic_energy() const {
  kin::MassMatrix M(n_, n_);
  if (kin::mass_matrix(chain_, q_, M) != kin::Status::ok) return 0;
  return 0.5 * qd_.dot(M * qd_);
}

void ArmPlant::acceleration(const kin::JointVector& q, const kin::JointVector& qd, kin::JointVector& qdd) {
  // The torques on the joints besides the arm's own (c + g): the motors', the external ones,
  // the plant's friction (smoothed Coulomb; the chain's own friction is zero here) and a stop's
  // contact.
  kin::JointVector tau = tau_motor_ + tau_ext_;
  for (int j = 0; j < n_; ++j) {
    const std::size_t k = static_cast<std::size_t>(j);
    tau[j] -= viscous_[k] * qd[j] + coulomb_[k] * std::tanh(qd[j] / params_.coulomb_velocity);
  }
  const JointStop& st = params_.stop;
  if (st.joint >= 0) {
    const auto& o = info_[static_cast<std::size_t>(st.joint)];
    const double pen = double(st.side) * (q[st.joint] - st.position);
    if (pen > 0) {
      const double f = std::max(0.0, o.stop_stiffness * pen + o.stop_damping * double(st.side) * qd[st.joint]);
      tau[st.joint] -= double(st.side) * f;
    }
  }
  bool any_locked = false;
  for (int j = 0; j < n_; ++j) any_locked = any_locked || locked(j);
  // No joint braked: M qdd = tau - c - g in one pass of the row transforms, M factored in place
  // (kin::forward_dynamics). It also refuses a mass matrix its pivot test finds singular; the
  // general path below then decides.
  if (!any_locked && kin::forward_dynamics(chain_, q, qd, tau, qdd) == kin::Status::ok) return;
  kin::JointVector zero = kin::JointVector::Zero(n_), h(n_);
  kin::MassMatrix M(n_, n_);
  qdd = kin::JointVector::Zero(n_);
  if (kin::inverse_dynamics(chain_, q, qd, zero, h) != kin::Status::ok) return;  // c + g
  if (kin::mass_matrix(chain_, q, M) != kin::Status::ok) return;
  kin::JointVector rhs = tau - h;
  // Braked joints are held: their row and column become the identity, their acceleration 0.
  for (int j = 0; j < n_; ++j) {
    if (!locked(j)) continue;
    M.row(j).setZero();
    M.col(j).setZero();
    M(j, j) = 1;
    rhs[j] = 0;
  }
  Eigen::LLT<kin::MassMatrix> llt(M);
  if (llt.info() != Eigen::Success) return;
  qdd = llt.solve(rhs);
}

void ArmPlant::advance(hal::TimePoint now, hal::CanBus& bus) {
  if (!configured_ || busy_ || !started_) return;
  busy_ = true;
  const hal::Duration step = params_.step;
  const double h = double(step) * 1e-9;
  kin::Jacobian J(6, n_);
  kin::JointVector a1(n_), a2(n_), a3(n_), a4(n_), q2(n_), v2(n_);
  bool any = false;
  if (t0_ < 0) t0_ = t_;
  while (t_ + step <= now) {
    t_ += step;
    any = true;
    // The drives' loops sample the state at the start of the step; their torques hold over it.
    for (int j = 0; j < n_; ++j) {
      VirtualDrive* d = drives_[static_cast<std::size_t>(j)];
      tau_motor_[j] = d ? d->servo_torque(q_[j], qd_[j], h) : 0.0;
      locked_[static_cast<std::size_t>(j)] = params_.brakes && (d == nullptr || !d->powered());
      if (locked(j)) qd_[j] = 0;
    }
    tau_ext_.setZero();
    for (int j = 0; j < n_; ++j) tau_ext_[j] = params_.external_torque[static_cast<std::size_t>(j)];
    const double ts = double(t_ - step - t0_) * 1e-9;  // the step's start: the torques hold over it
    for (const ArmPlantParams::Push& p : params_.pushes)
      if (p.joint >= 0 && p.joint < n_)
        tau_ext_[p.joint] += p.amplitude * (p.frequency > 0 ? std::sin(2.0 * M_PI * p.frequency * ts + p.phase) : 1.0);
    if (params_.tool_force.squaredNorm() > 0 && kin::jacobian(chain_, q_, J) == kin::Status::ok)
      tau_ext_ += J.topRows<3>().transpose() * params_.tool_force;
    // Classical Runge-Kutta 4 on (q, qd).
    acceleration(q_, qd_, a1);
    q2 = q_ + 0.5 * h * qd_;
    v2 = qd_ + 0.5 * h * a1;
    acceleration(q2, v2, a2);
    const kin::JointVector v3 = qd_ + 0.5 * h * a2;
    q2 = q_ + 0.5 * h * v2;
    acceleration(q2, v3, a3);
    const kin::JointVector v4 = qd_ + h * a3;
    q2 = q_ + h * v3;
    acceleration(q2, v4, a4);
    q_ += (h / 6.0) * (qd_ + 2.0 * v2 + 2.0 * v3 + v4);
    qd_ += (h / 6.0) * (a1 + 2.0 * a2 + 2.0 * a3 + a4);
    for (int j = 0; j < n_; ++j)
      if (locked(j)) qd_[j] = 0;
    tau_contact_.setZero();
    if (params_.stop.joint >= 0) {
      const JointStop& st = params_.stop;
      const auto& o = info_[static_cast<std::size_t>(st.joint)];
      const double pen = double(st.side) * (q_[st.joint] - st.position);
      if (pen > 0)
        tau_contact_[st.joint] =
            -double(st.side) * std::max(0.0, o.stop_stiffness * pen + o.stop_damping * double(st.side) * qd_[st.joint]);
    }
    ++steps_;
    for (int j = 0; j < n_; ++j)
      if (VirtualDrive* d = drives_[static_cast<std::size_t>(j)]) d->plant_update(t_, q_[j], qd_[j], tau_motor_[j], bus);
  }
  if (any)
    for (int j = 0; j < n_; ++j)
      if (VirtualDrive* d = drives_[static_cast<std::size_t>(j)]) d->publish_feedback();
  busy_ = false;
}

}  // namespace servoarm::sim
