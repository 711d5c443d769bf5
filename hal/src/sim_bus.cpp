// SPDX-License-Identifier: Apache-2.0
#include "servoarm/hal/sim_bus.hpp"

#include <algorithm>
#include <chrono>

namespace servoarm::hal {

const char* to_string(ErrorState s) {
  switch (s) {
    case ErrorState::active: return "error_active";
    case ErrorState::warning: return "error_warning";
    case ErrorState::passive: return "error_passive";
    case ErrorState::bus_off: return "bus_off";
  }
  return "unknown";
}

SimBus::SimBus(Clock& clock, Duration poll_step) : clock_(clock), poll_step_(poll_step > 0 ? poll_step : kMicrosecond) {}

SimBus::~SimBus() = default;

std::unique_ptr<SimBusEndpoint> SimBus::open(std::size_t queue_capacity, bool loopback) {
  std::unique_ptr<SimBusEndpoint> ep(new SimBusEndpoint(*this, queue_capacity == 0 ? 1 : queue_capacity, loopback));
  std::lock_guard lk(mu_);
  endpoints_.push_back(ep.get());
  return ep;
}

void SimBus::set_faults(const SimFaults& faults) {
  std::lock_guard lk(mu_);
  faults_ = faults;
  rng_ = faults.seed ? faults.seed : 0x9E3779B97F4A7C15ull;
}

void SimBus::set_error_state(ErrorState s) {
  std::lock_guard lk(mu_);
  state_ = s;
}

double SimBus::next_uniform() {
  // xorshift64*: small, seeded, reproducible across platforms.
  rng_ ^= rng_ >> 12;
  rng_ ^= rng_ << 25;
  rng_ ^= rng_ >> 27;
  const std::uint64_t r = rng_ * 0x2545F4914F6CDD1Dull;
  return double(r >> 11) * (1.0 / 9007199254740992.0);
}

Status SimBus::send_from(SimBusEndpoint* from, const CanFrame& f) {
  if (!f.valid()) {
    std::lock_guard lk(mu_);
    ++from->stats_.tx_errors;
    return Status::invalid_argument;
  }
  const TimePoint now = clock_.now();
  ErrorState st;
  {
    std::lock_guard lk(mu_);
    st = state_;
    if (state_ == ErrorState::bus_off) {
      ++from->stats_.tx_errors;
      return Status::bus_off;
    }
    ++from->stats_.tx_frames;
    for (SimBusEndpoint* ep : endpoints_) {
      if (ep == from && !ep->loopback_) continue;
      if (!ep->passes(f)) continue;
      CanFrame g = f;
      if (ep != from) {
        if (faults_.drop_rate > 0 && next_uniform() < faults_.drop_rate) continue;
        if (faults_.corrupt_rate > 0 && g.len > 0 && next_uniform() < faults_.corrupt_rate) {
          const auto bit = std::uint32_t(next_uniform() * g.len * 8) % (g.len * 8u);
          g.data[bit / 8] ^= std::uint8_t(1u << (bit % 8));
        }
      }
      if (ep->count_ == ep->ring_.size()) {
        ++ep->stats_.rx_overruns;
        continue;
      }
      const std::size_t tail = (ep->head_ + ep->count_) % ep->ring_.size();
      ep->ring_[tail].frame = g;
      ep->ring_[tail].deliver_at = now + (ep == from ? 0 : faults_.delay);
      ++ep->count_;
    }
  }
  cv_.notify_all();
  return st == ErrorState::passive ? Status::error_passive : Status::ok;
}

SimBusEndpoint::SimBusEndpoint(SimBus& bus, std::size_t capacity, bool loopback)
    : bus_(bus), ring_(capacity), loopback_(loopback) {}

SimBusEndpoint::~SimBusEndpoint() {
  std::lock_guard lk(bus_.mu_);
  auto& v = bus_.endpoints_;
  v.erase(std::remove(v.begin(), v.end(), this), v.end());
}

bool SimBusEndpoint::passes(const CanFrame& f) const {
  if (n_filters_ == 0 || f.error) return true;
  for (std::size_t i = 0; i < n_filters_; ++i)
    if (filters_[i].matches(f)) return true;
  return false;
}

Status SimBusEndpoint::send(const CanFrame& frame) { return bus_.send_from(this, frame); }

Status SimBusEndpoint::receive(CanFrame& out, TimePoint deadline) {
  Clock& clock = bus_.clock_;
  std::unique_lock lk(bus_.mu_);
  for (;;) {
    const TimePoint now = clock.now();
    TimePoint next_delivery = deadline;
    if (count_ > 0) {
      Entry& e = ring_[head_];
      if (e.deliver_at <= now) {
        out = e.frame;
        out.rx_time = e.deliver_at;  // when it arrived (as a kernel timestamp), not when it was read
        head_ = (head_ + 1) % ring_.size();
        --count_;
        ++stats_.rx_frames;
        return Status::ok;
      }
      next_delivery = std::min(deadline, e.deliver_at);
    }
    if (now >= deadline) return Status::timeout;
    if (clock.simulated()) {
      const TimePoint wake = std::min(next_delivery, now + bus_.poll_step_);
      lk.unlock();
      clock.sleep_until(wake);
      lk.lock();
    } else {
      const auto wake = std::chrono::steady_clock::time_point(std::chrono::nanoseconds(next_delivery));
      bus_.cv_.wait_until(lk, wake);
    }
  }
}

Status SimBusEndpoint::set_filters(std::span<const CanFilter> filters) {
  if (filters.size() > kMaxFilters) return Status::capacity;
  std::lock_guard lk(bus_.mu_);
  n_filters_ = filters.size();
  std::copy(filters.begin(), filters.end(), filters_);
  return Status::ok;
}

BusStats SimBusEndpoint::stats() const {
  std::lock_guard lk(bus_.mu_);
  BusStats s = stats_;
  s.state = bus_.state_;
  return s;
}

std::size_t SimBusEndpoint::pending() const {
  std::lock_guard lk(bus_.mu_);
  return count_;
}

}  // namespace servoarm::hal
