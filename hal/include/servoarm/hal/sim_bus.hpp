// SPDX-License-Identifier: Apache-2.0
#pragma once
// In-process CAN bus with vcan semantics, for host builds and tests.
//
// - Every frame sent on one endpoint reaches every *other* open endpoint, in
//   send order; the sender sees its own frame only if it opened with loopback.
// - Each endpoint has a bounded receive queue sized at open(); a frame that
//   does not fit is dropped for that endpoint and counted in rx_overruns.
// - Optional fault injection (seeded, reproducible): drop rate, fixed delivery
//   delay, payload corruption (one bit flipped), forced error state.
//
// Thread safety: one mutex per bus, so endpoints may live on different threads
// (that lock is a property of this test backend; SocketCanBus takes none).
// With a simulated Clock, receive() waits by calling clock.sleep_until() in
// steps of `poll_step`, so single-threaded tests can step devices in the idle hook.
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>

#include "servoarm/hal/can_bus.hpp"
#include "servoarm/hal/clock.hpp"

namespace servoarm::hal {

struct SimFaults {
  double drop_rate = 0.0;      ///< probability a frame is lost for a receiver (0..1)
  double corrupt_rate = 0.0;   ///< probability one payload bit is flipped for a receiver (0..1)
  Duration delay = 0;          ///< delivery delay added to every frame
  std::uint64_t seed = 1;      ///< PRNG seed (xorshift64*)
};

class SimBusEndpoint;

class SimBus {
 public:
  /// Set-up. `poll_step`: receive() wait granularity with a simulated clock.
  explicit SimBus(Clock& clock, Duration poll_step = 50 * kMicrosecond);
  ~SimBus();
  SimBus(const SimBus&) = delete;
  SimBus& operator=(const SimBus&) = delete;

  /// Set-up: open an endpoint (allocates its queue). The endpoint must be
  /// destroyed before the bus.
  std::unique_ptr<SimBusEndpoint> open(std::size_t queue_capacity = 1024, bool loopback = false);

  /// Set-up or test: replace the fault configuration (reseeds the PRNG).
  void set_faults(const SimFaults& faults);
  /// Test: force the error state every endpoint reports; bus_off makes send() fail.
  void set_error_state(ErrorState s);

  Clock& clock() { return clock_; }

 private:
  friend class SimBusEndpoint;
  Status send_from(SimBusEndpoint* from, const CanFrame& f);
  double next_uniform();  // caller holds mu_

  Clock& clock_;
  Duration poll_step_;
  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::vector<SimBusEndpoint*> endpoints_;
  SimFaults faults_;
  std::uint64_t rng_ = 1;
  ErrorState state_ = ErrorState::active;
};

/// One open "socket" on a SimBus. send/receive/stats never allocate and are bounded,
/// but take the bus mutex (fine for tests and host simulation; SocketCanBus takes none).
class SimBusEndpoint final : public CanBus {
 public:
  ~SimBusEndpoint() override;
  Status send(const CanFrame& frame) override;
  Status receive(CanFrame& out, TimePoint deadline) override;
  Status set_filters(std::span<const CanFilter> filters) override;
  BusStats stats() const override;
  /// Frames waiting in this endpoint's queue (including delayed ones).
  std::size_t pending() const;

 private:
  friend class SimBus;
  struct Entry {
    CanFrame frame;
    TimePoint deliver_at;
  };
  SimBusEndpoint(SimBus& bus, std::size_t capacity, bool loopback);
  bool passes(const CanFrame& f) const;  // caller holds bus mutex

  SimBus& bus_;
  std::vector<Entry> ring_;
  std::size_t head_ = 0, count_ = 0;
  bool loopback_;
  CanFilter filters_[kMaxFilters];
  std::size_t n_filters_ = 0;
  BusStats stats_;
};

}  // namespace servoarm::hal
