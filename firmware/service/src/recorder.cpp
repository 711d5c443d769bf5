// SPDX-License-Identifier: Apache-2.0
// The arm service's recorder (arm_service.hpp): samples the measured joints at a rate and
// hands the path, thinned within a tolerance, to the front end that keeps it. Console thread.
#include <algorithm>
#include <cmath>

#include "servoarm/service/arm_service.hpp"
#include "servoarm/service/mcap_recorder.hpp"

namespace servoarm::fw {

const char* to_string(RecordRefusal r) {
  switch (r) {
    case RecordRefusal::none: return "none";
    case RecordRefusal::recording: return "recording";
    case RecordRefusal::not_recording: return "not_recording";
    case RecordRefusal::not_homed: return "not_homed";
    case RecordRefusal::bad_value: return "bad_value";
  }
  return "?";
}

std::vector<std::size_t> decimate(const std::vector<kin::JointVector>& q, double tol) {
  const std::size_t n = q.size();
  std::vector<char> keep(n, 0);
  if (n == 0) return {};
  keep[0] = keep[n - 1] = 1;
  std::vector<std::pair<std::size_t, std::size_t>> stack{{0, n - 1}};
  while (!stack.empty()) {
    const auto [a, b] = stack.back();
    stack.pop_back();
    if (b <= a + 1) continue;
    // Plain loops over the joints, not Eigen temporaries: gcc 12 for armhf at -O2
    // takes those for maybe-uninitialized (-Werror in the cross build).
    const Eigen::Index m = q[a].size();
    double dd = 0;
    for (Eigen::Index j = 0; j < m; ++j) dd += (q[b][j] - q[a][j]) * (q[b][j] - q[a][j]);
    double worst = -1;
    std::size_t at = a;
    for (std::size_t i = a + 1; i < b; ++i) {
      double vd = 0;
      for (Eigen::Index j = 0; j < m; ++j) vd += (q[i][j] - q[a][j]) * (q[b][j] - q[a][j]);
      const double s = dd > 0 ? std::clamp(vd / dd, 0.0, 1.0) : 0.0;
      double dist2 = 0;
      for (Eigen::Index j = 0; j < m; ++j) {
        const double e = (q[i][j] - q[a][j]) - s * (q[b][j] - q[a][j]);
        dist2 += e * e;
      }
      const double dist = std::sqrt(dist2);
      if (dist > worst) worst = dist, at = i;
    }
    if (worst > tol) {
      keep[at] = 1;
      stack.push_back({a, at});
      stack.push_back({at, b});
    }
  }
  std::vector<std::size_t> out;
  for (std::size_t i = 0; i < n; ++i)
    if (keep[i]) out.push_back(i);
  return out;
}

void ArmService::tick() {
  record_sample();
  mcap_events();
  program_tick();
}

// One sample every rate interval of control cycles.
void ArmService::record_sample() {
  if (!rec_.active || ctl_ == nullptr || rec_.samples.size() >= kMaxRecordSamples) return;
  const Telemetry t = ctl_->telemetry();
  const double every = std::max(1.0, std::round(ctl_->config().rate_hz / rec_.rate_hz));
  if (static_cast<double>(t.cycles - rec_.last_cycle) < every) return;
  kin::JointVector q(n_);
  for (int j = 0; j < n_; ++j) q[j] = t.q_act[static_cast<std::size_t>(j)];
  rec_.samples.push_back(q);
  rec_.last_cycle = t.cycles;
}

RecordResult ArmService::record_start(double rate_hz) {
  RecordResult r;
  r.samples = rec_.samples.size();
  if (rec_.active) {
    r.error = CmdError::bad_state;
    r.refusal = RecordRefusal::recording;
    r.rate_hz = rec_.rate_hz;
    return r;
  }
  if (!(rate_hz > 0) || !std::isfinite(rate_hz) || ctl_ == nullptr) {
    r.error = CmdError::out_of_range;
    r.refusal = RecordRefusal::bad_value;
    return r;
  }
  if (std::string why = unhomed_reason(); !why.empty()) {  // a path in coordinates not established means nothing
    r.error = CmdError::not_homed;
    r.refusal = RecordRefusal::not_homed;
    r.reason = std::move(why);
    return r;
  }
  rec_.active = true;
  rec_.rate_hz = rate_hz;
  rec_.samples.clear();
  rec_.samples.reserve(kMaxRecordSamples);
  rec_.last_cycle = ctl_->telemetry().cycles - static_cast<std::uint64_t>(std::max(1.0, ctl_->config().rate_hz / rate_hz)) - 1;
  record_sample();  // the first sample: where the arm is now
  r.rate_hz = rate_hz;
  r.samples = rec_.samples.size();
  return r;
}

RecordResult ArmService::record_path(double tolerance) {
  RecordResult r;
  if (!rec_.active) {
    r.error = CmdError::bad_state;
    r.refusal = RecordRefusal::not_recording;
    return r;
  }
  if (!(tolerance > 0) || !std::isfinite(tolerance)) {
    r.error = CmdError::out_of_range;
    r.refusal = RecordRefusal::bad_value;
    return r;
  }
  {  // the last sample: where the arm is now
    const Telemetry t = ctl_->telemetry();
    kin::JointVector q = kin::JointVector::Zero(n_);
    bool moved = rec_.samples.empty();
    for (int j = 0; j < n_; ++j) {
      q[j] = t.q_act[static_cast<std::size_t>(j)];
      if (!moved && rec_.samples.back()[j] != q[j]) moved = true;
    }
    if (moved) rec_.samples.push_back(q);
  }
  // The moves follow the thinned polyline (within tol/2 of the samples) and each blend
  // stays within blend = tol/2 of its corner, a sample: within tol of the recorded path.
  r.rate_hz = rec_.rate_hz;
  r.samples = rec_.samples.size();
  r.tolerance = tolerance;
  r.blend = 0.5 * tolerance;
  for (const std::size_t k : decimate(rec_.samples, 0.5 * tolerance)) r.waypoints.push_back(rec_.samples[k]);
  return r;
}

RecordResult ArmService::record_stop() {
  RecordResult r;
  if (!rec_.active) {
    r.error = CmdError::bad_state;
    r.refusal = RecordRefusal::not_recording;
    return r;
  }
  r.rate_hz = rec_.rate_hz;
  r.samples = rec_.samples.size();
  rec_.active = false;
  rec_.samples.clear();
  return r;
}

std::string ArmService::record_mcap_start(double rate_hz, bool threaded) {
  if (ctl_ == nullptr) return "no control thread (a dry run records nothing)";
  if (!mcap_) mcap_ = std::make_unique<McapRecorder>(*ctl_, ctl_->chain());
  mcap_seq_ = next_seq_ - 1;
  return mcap_->start(mcap_cfg_, rate_hz, threaded && mcap_cfg_.threaded);
}

McapStatus ArmService::record_mcap_stop() {
  if (!mcap_) return {};
  mcap_events();
  return mcap_->stop();
}

McapStatus ArmService::mcap_status() const { return mcap_ ? mcap_->status() : McapStatus{}; }

void ArmService::mcap_poll() {
  mcap_events();
  if (mcap_ && !mcap_->threaded()) mcap_->poll();  // a recorder thread polls on its own
}

// The service's new events to the recorder (the service thread: the event ring's reader).
void ArmService::mcap_events() {
  if (!mcap_ || !mcap_->active()) return;
  const EventBatch b = events_since(mcap_seq_);
  for (const ArmEvent& e : b.events) {
    mcap_->event(e, event_detail(e));
    mcap_seq_ = e.seq;
  }
}

}  // namespace servoarm::fw
