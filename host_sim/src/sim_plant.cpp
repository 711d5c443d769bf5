// SPDX-License-Identifier: Apache-2.0
#include "servoarm/sim/sim_plant.hpp"

#include <algorithm>

namespace servoarm::sim {

SimPlant::SimPlant(hal::Clock& clock, const std::vector<std::uint8_t>& nodes, const MotorParams& motor) : clock_(clock) {
  bus_ = std::make_unique<hal::SimBus>(clock, 50 * hal::kMicrosecond);
  master_ep_ = bus_->open(4096);
  sim_ep_ = bus_->open(4096);
  arm_ = std::make_unique<ArmSim>(*sim_ep_, nodes, motor, 7);
  arm_->power_on(clock.now());
}

SimPlant::~SimPlant() {
  stop_thread();
  arm_.reset();
  sim_ep_.reset();
  master_ep_.reset();
}

void SimPlant::apply_injections(hal::TimePoint now) {
  const int s = silent_.exchange(-1);
  if (s >= 0 && static_cast<std::size_t>(s) < arm_->size()) arm_->at(static_cast<std::size_t>(s)).faults().silent = true;
  const int h = hb_stop_.exchange(-1);
  if (h >= 0 && static_cast<std::size_t>(h) < arm_->size()) arm_->at(static_cast<std::size_t>(h)).faults().heartbeat_stopped = true;
  const int e = emcy_joint_.exchange(-1);
  if (e >= 0 && static_cast<std::size_t>(e) < arm_->size())
    arm_->at(static_cast<std::size_t>(e)).inject_emcy(emcy_code_.load(), now, *sim_ep_);
}

void SimPlant::step(hal::TimePoint now) {
  apply_injections(now);
  if (!at_arrival_) {
    arm_->step(now);
    return;
  }
  // Events in the order they happened (the frames at their arrival, then this step): a gap
  // of more than pause_after_ between two of them is a pause.
  auto reach = [this](hal::TimePoint at) {
    if (pause_after_ > 0 && last_step_ != 0 && at - last_step_ > pause_after_) {
      arm_->skip_to(at - pause_after_);
      paused_ += at - pause_after_ - last_step_;
    }
    last_step_ = std::max(last_step_, at);
  };
  hal::CanFrame f;
  for (int i = 0; i < 4096 && sim_ep_->receive(f, 0) == hal::Status::ok; ++i) {
    const hal::TimePoint at = f.rx_time != 0 && f.rx_time <= now ? f.rx_time : now;
    reach(at);
    arm_->handle(f, at);
  }
  reach(now);
  arm_->tick(now);
}

void SimPlant::inject_silent(int joint) { silent_ = joint; }
void SimPlant::inject_heartbeat_stop(int joint) { hb_stop_ = joint; }
void SimPlant::inject_emcy(int joint, std::uint16_t code) {
  emcy_code_ = code;
  emcy_joint_ = joint;
}

void SimPlant::start_thread() {
  if (th_.joinable()) return;
  stop_ = false;
  th_ = std::thread([this] {
    while (!stop_.load(std::memory_order_relaxed)) {
      hal::CanFrame f;
      const hal::TimePoint now = clock_.now();
      apply_injections(now);
      // Wait up to 100 us for a frame, then hand everything pending to the drives, each at the time
      // it arrived: a drive samples at the SYNC, not when this thread gets round to it (after a
      // stall of this thread, several SYNCs would otherwise be sampled at one instant).
      if (sim_ep_->receive(f, now + 100 * hal::kMicrosecond) == hal::Status::ok) {
        arm_->handle(f, f.rx_time != 0 ? f.rx_time : clock_.now());
        for (int i = 0; i < 4096 && sim_ep_->receive(f, 0) == hal::Status::ok; ++i)
          arm_->handle(f, f.rx_time != 0 ? f.rx_time : clock_.now());
      }
      arm_->tick(clock_.now());
    }
  });
}

void SimPlant::stop_thread() {
  stop_ = true;
  if (th_.joinable()) th_.join();
}

}  // namespace servoarm::sim
