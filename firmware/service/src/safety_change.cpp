// SPDX-License-Identifier: Apache-2.0
// Run-time changes of the [safety] section (docs/safety.md#confirming-a-change): staged with the
// checksum the configuration will have, applied only when that checksum is confirmed.
#include <chrono>
#include <cstdio>
#include <cstring>

#include "servoarm/service/arm_service.hpp"

namespace servoarm::fw {

namespace {
double steady_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
std::string hex8(std::uint32_t v) {
  char b[9];
  std::snprintf(b, sizeof b, "%08X", static_cast<unsigned>(v));
  return b;
}
}  // namespace

SafetyChangeResult ArmService::stage_safety(const std::string& changes) {
  SafetyChangeResult r;
  r.previous = cfg_.safety_checksum;
  if (!stager_) {
    r.error = CmdError::unsupported;
    r.reason = "run-time changes of [safety] are not available here (no configuration to change)";
    return r;
  }
  auto p = std::make_unique<SafetyProposal>();
  if (std::string e = stager_(changes, *p); !e.empty()) {
    r.error = CmdError::bad_option;
    r.reason = std::move(e);
    return r;
  }
  if (p->checksum == cfg_.safety_checksum) {
    r.error = CmdError::bad_option;
    r.reason = "the change leaves the safety configuration as it is (checksum " + hex8(p->checksum) + "): nothing staged";
    staged_.reset();
    return r;
  }
  r.checksum = p->checksum;
  r.changes = p->changes;
  r.expires_s = safety_window_s_;
  staged_ = std::move(p);
  staged_until_ = steady_s() + safety_window_s_;
  return r;
}

SafetyChangeResult ArmService::confirm_safety(std::uint32_t checksum) {
  SafetyChangeResult r;
  r.previous = cfg_.safety_checksum;
  if (!staged_) {
    r.error = CmdError::bad_state;
    r.reason = "no safety change is staged: stage one first";
    return r;
  }
  const std::string want = hex8(staged_->checksum);
  if (checksum != staged_->checksum) {
    r.error = CmdError::bad_option;
    r.reason = "checksum " + hex8(checksum) + " is not the staged change's (" + want + "): the change is dropped, stage it again";
    staged_.reset();
    return r;
  }
  if (const double late = steady_s() - staged_until_; late > 0) {
    char b[160];
    std::snprintf(b, sizeof b, "the staged change %s expired %.1f s ago (confirm within %.0f s): stage it again",
                  want.c_str(), late, safety_window_s_);
    r.error = CmdError::bad_state;
    r.reason = b;
    staged_.reset();
    return r;
  }
  if (ctl_ != nullptr) {
    switch (ctl_->telemetry().state) {
      case ArmState::boot:
      case ArmState::disabled:
      case ArmState::idle:
      case ArmState::fault:
      case ArmState::estop: break;
      case ArmState::enabling:
      case ArmState::moving:
      case ArmState::stopping:
      case ArmState::jogging:
      case ArmState::homing:
      case ArmState::freedrive:
        r.error = CmdError::bad_state;
        r.reason = "the arm is not at rest: confirm " + want + " once it is (the change stays staged)";
        return r;
    }
    if (!ctl_->set_safety_config(staged_->safety)) {
      r.error = CmdError::busy;
      r.reason = "the control thread has not taken the last change yet: confirm again";
      return r;
    }
  }
  cfg_.safety = staged_->safety;
  cfg_.safety_checksum = staged_->checksum;
  push_safety_tool();  // the monitor's new envelope has the chain's tool: the active one again
  if (staged_->commit) staged_->commit();
  r.checksum = staged_->checksum;
  r.changes = staged_->changes;
  staged_.reset();
  // Every client sees it in the event stream (the control thread's events before it first).
  poll_events();
  EventSlot& ev = push_event();
  ev.ev.kind = ArmEventKind::warning;
  std::snprintf(ev.detail, sizeof ev.detail, "safety configuration changed: checksum %s -> %s", hex8(r.previous).c_str(),
                hex8(r.checksum).c_str());
  return r;
}

}  // namespace servoarm::fw
