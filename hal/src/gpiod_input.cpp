// SPDX-License-Identifier: Apache-2.0
// The GPIO safety input through libgpiod's v1 C API (Debian 12's libgpiod-dev 1.6): a thread
// waits for the line's edges (or polls a line that gives none) and publishes each reading in
// one atomic word (safety_input.hpp). Built
// without libgpiod (SERVOARM_HAVE_GPIOD unset), start() refuses and the input reads lost.
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <ctime>

#include "servoarm/hal/safety_input.hpp"

#if SERVOARM_HAVE_GPIOD
#include <gpiod.h>
#endif

namespace servoarm::hal {

namespace {
/// What the reading thread found (bits 2..4 of the word).
enum GpioError : std::uint32_t { kOk = 0, kNotStarted = 1, kNoChip = 2, kNoLine = 3, kRequest = 4, kRead = 5, kNotBuilt = 6 };
constexpr std::uint32_t pack(InputLevel l, std::uint32_t error, int err_no, std::uint32_t count) {
  const std::uint32_t e = err_no < 0 ? 0u : (err_no > 255 ? 255u : static_cast<std::uint32_t>(err_no));
  return static_cast<std::uint32_t>(l) | (error << 2) | (e << 5) | (count << 13);
}
constexpr InputLevel level_of(std::uint32_t w) { return static_cast<InputLevel>(w & 3u); }
constexpr std::uint32_t error_of(std::uint32_t w) { return (w >> 2) & 7u; }
constexpr int errno_of(std::uint32_t w) { return static_cast<int>((w >> 5) & 0xFFu); }
constexpr std::uint32_t count_of(std::uint32_t w) { return w >> 13; }
}  // namespace

bool gpiod_available() { return SERVOARM_HAVE_GPIOD != 0; }

GpiodInput::GpiodInput(const char* chip, int line, Duration period, Duration stale)
    : line_(line), period_(period > 0 ? period : kMillisecond), stale_(stale) {
  // The refresh: a quarter of the staleness limit, so that three refreshes may be late before
  // the control thread takes the line for lost; at most 50 ms, at least the poll period.
  refresh_ = stale_ / 4;
  if (refresh_ > 50 * kMillisecond) refresh_ = 50 * kMillisecond;
  if (refresh_ < period_) refresh_ = period_;
  std::snprintf(chip_, sizeof chip_, "%s", chip);
  std::snprintf(source_, sizeof source_, "gpio:%s:%d", chip_, line_);
  word_.store(pack(InputLevel::lost, SERVOARM_HAVE_GPIOD ? kNotStarted : kNotBuilt, 0, 0), std::memory_order_relaxed);
}

GpiodInput::~GpiodInput() { stop(); }

bool GpiodInput::start() {
  if (!gpiod_available() || thread_.joinable()) return gpiod_available();
  stop_.store(false, std::memory_order_relaxed);
  thread_ = std::thread([this] { run(); });
  return true;
}

void GpiodInput::stop() {
  stop_.store(true, std::memory_order_relaxed);
  if (thread_.joinable()) thread_.join();
}

void GpiodInput::run() {
#if SERVOARM_HAVE_GPIOD
  gpiod_chip* chip = nullptr;
  gpiod_line* line = nullptr;
  bool events = false;  // the line is requested for both edges' events (false: polled)
  bool fresh = false;   // just requested: its level is read without waiting
  std::uint32_t count = 0;
  timespec next{};
  clock_gettime(CLOCK_MONOTONIC, &next);
  TimePoint retry_at = 0;
  bool fallback_said = false;  // the polling fallback is said once on stderr
  auto now_ns = [] {
    timespec t{};
    clock_gettime(CLOCK_MONOTONIC, &t);
    return static_cast<TimePoint>(t.tv_sec) * kSecond + t.tv_nsec;
  };
  auto publish = [&](InputLevel l, std::uint32_t error, int err_no) {
    ++count;
    word_.store(pack(l, error, err_no, count), std::memory_order_release);
  };
  auto close_all = [&] {
    if (line != nullptr) gpiod_line_release(line);
    if (chip != nullptr) gpiod_chip_close(chip);
    line = nullptr;
    chip = nullptr;
  };
  while (!stop_.load(std::memory_order_relaxed)) {
    if (line == nullptr && now_ns() >= retry_at) {
      // Open (again) at most once a second: a chip that appears later (a module loaded, a
      // hat plugged) is taken up without a restart.
      retry_at = now_ns() + kSecond;
      if (chip == nullptr) chip = gpiod_chip_open_lookup(chip_);
      if (chip == nullptr) {
        publish(InputLevel::lost, kNoChip, errno);
      } else if (gpiod_line* l = gpiod_chip_get_line(chip, static_cast<unsigned>(line_)); l == nullptr) {
        publish(InputLevel::lost, kNoLine, errno);
        close_all();
      } else if (gpiod_line_request_both_edges_events(l, "armfw-safety") == 0) {
        line = l;
        events = fresh = true;
        polling_.store(false, std::memory_order_relaxed);
      } else {
        // No edge events from this line (a GPIO driver without interrupts answers ENODEV,
        // ENXIO, EINVAL or EOPNOTSUPP): read it as a plain input every period instead. A line
        // in use fails here too, with its own errno.
        const int event_errno = errno;
        if (gpiod_line_request_input(l, "armfw-safety") != 0) {
          publish(InputLevel::lost, kRequest, errno);
          close_all();
        } else {
          line = l;
          events = false;
          polling_.store(true, std::memory_order_relaxed);
          if (!fallback_said) {
            fallback_said = true;
            std::fprintf(stderr, "%s: the line gives no edge events (errno %d): it is polled every %.1f ms instead\n",
                         source_, event_errno, static_cast<double>(period_) * 1e-6);
          }
        }
      }
    }
    if (line != nullptr && events) {
      // Wait for an edge, at most the refresh period; then read the level (after an edge as
      // after a timeout: the level, not the edge, is what counts, and the timeout's read
      // tells the control thread that the thread and the line are alive).
      const Duration wait = fresh ? 0 : refresh_;
      fresh = false;
      const timespec timeout{static_cast<time_t>(wait / kSecond), static_cast<long>(wait % kSecond)};
      int r = gpiod_line_event_wait(line, &timeout);
      // Drain the queued edges (a bouncing contact queues several); at most 16 a wake-up.
      for (int n = 0; r == 1 && n < 16; ++n) {
        gpiod_line_event ev{};
        if (gpiod_line_event_read(line, &ev) != 0) {
          r = -1;
          break;
        }
        const timespec zero{0, 0};
        r = gpiod_line_event_wait(line, &zero);
      }
      const int v = r < 0 ? -1 : gpiod_line_get_value(line);
      if (v < 0) {
        publish(InputLevel::lost, kRead, errno);
        close_all();
      } else {
        publish(v ? InputLevel::high : InputLevel::low, kOk, 0);
      }
      continue;
    }
    Duration sleep = refresh_;
    if (line != nullptr) {
      const int v = gpiod_line_get_value(line);
      if (v < 0) {
        publish(InputLevel::lost, kRead, errno);
        close_all();
      } else {
        publish(v ? InputLevel::high : InputLevel::low, kOk, 0);
        sleep = period_;
      }
    } else {
      // Nothing to read: keep the count moving (at the refresh period) so the control thread
      // sees a live thread with a lost line, not a stalled one.
      const std::uint32_t w = word_.load(std::memory_order_relaxed);
      publish(InputLevel::lost, error_of(w), errno_of(w));
    }
    // A steady poll on an absolute schedule; from now when it fell behind (a wait for an
    // edge, a lost line's refresh, a starved thread) rather than catching up in a burst.
    const TimePoint now = now_ns();
    TimePoint at = static_cast<TimePoint>(next.tv_sec) * kSecond + next.tv_nsec + sleep;
    if (sleep != period_ || at < now) at = now + sleep;
    next.tv_sec = static_cast<time_t>(at / kSecond);
    next.tv_nsec = static_cast<long>(at % kSecond);
    clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr);
  }
  close_all();
#endif
}

InputLevel GpiodInput::read(TimePoint now) {
  const std::uint32_t w = word_.load(std::memory_order_acquire);
  const std::uint32_t count = count_of(w);
  if (count != seen_count_ || seen_at_ < 0) seen_count_ = count, seen_at_ = now;
  std::uint32_t error = error_of(w);
  const bool stalled = error == kOk && now - seen_at_ > stale_;
  if (stalled) error = 7;  // (not a thread's code: the control thread's own finding)
  const bool lost = error != kOk;
  if (lost && (!lost_ || error != last_error_)) {
    const int e = errno_of(w);
    const char* what = "";
    switch (error) {
      case kNotStarted: what = "not read yet"; break;
      case kNoChip: what = "the chip cannot be opened"; break;
      case kNoLine: what = "the chip has no such line"; break;
      case kRequest: what = "the line cannot be requested as an input (in use?)"; break;
      case kRead: what = "the line cannot be read"; break;
      case kNotBuilt: what = "this armfw was built without libgpiod (libgpiod-dev)"; break;
      default: what = "its reading thread has not read the line in time"; break;
    }
    // strerror is not called here (it may format into a static buffer): the number is enough.
    // (source_ is at most 63 characters, `what` at most 60: the line fits)
    if (e != 0) std::snprintf(why_, sizeof why_, "%.63s: %.60s (errno %d)", source_, what, e);
    else std::snprintf(why_, sizeof why_, "%.63s: %.60s", source_, what);
  }
  lost_ = lost;
  last_error_ = error;
  return lost ? InputLevel::lost : level_of(w);
}

}  // namespace servoarm::hal
