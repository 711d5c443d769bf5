// SPDX-License-Identifier: Apache-2.0
#pragma once
// Digital inputs the safety functions read (docs/safety.md#safety-inputs): an external e-stop
// contact mapped to the emergency stop and a switch into Reduced mode. One small interface,
// the backends side by side:
//   DriveBitInput  bit N of a drive's digital inputs (CiA 402 60FDh in TPDO3, read with the
//                  drive's feedback: CanopenJointConfig::digital_inputs)      safety_input.cpp
//   GpiodInput     a GPIO line through libgpiod (v1 API), its edges waited for on a thread of
//                  its own, its level handed to the control thread in one atomic word
//                                                                             gpiod_input.cpp
//   SimInput       a level a test (or armfw --sim) sets                       safety_input.cpp
// InputWatch adds the active level, the debounce and the fail-safe rule on top of any of them.
//
// These are not safety-rated inputs: the safety chain of the arm is the drives' STO and an
// external safety relay; this reads the same contacts so that the firmware stops and slows
// with them and says why.
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string_view>
#include <thread>

#include "servoarm/hal/servo_bus.hpp"
#include "servoarm/hal/time.hpp"

namespace servoarm::hal {

/// One read of a safety input: its electrical level, lost (it cannot be read now), or pending
/// (no reading yet, within its timeout of the first read: a drive's first TPDO3 after start-up,
/// one or two cycles; InputWatch keeps the state it had, released at start, and the input turns
/// lost once the timeout has passed without one).
enum class InputLevel : std::uint8_t { low, high, lost, pending };
const char* to_string(InputLevel l);

/// Where a safety input comes from.
enum class InputKind : std::uint8_t { none, drive, gpio, sim };

/// A safety input's source as configured: "drive:J:bitN", "gpio:CHIP:LINE", "sim:NAME" or "".
struct InputSource {
  InputKind kind = InputKind::none;
  int joint = -1;      ///< drive: the arm's joint (0-based; 1-based in the text) whose drive reports it
  int bit = -1;        ///< drive: the bit of 60FDh, 0..31 (16..31 are the drive maker's inputs)
  char chip[48] = {};  ///< gpio: the chip as libgpiod's gpiod_chip_open_lookup takes it: name
                       ///< ("gpiochip0"), path ("/dev/gpiochip0"), label or number
  int line = -1;       ///< gpio: the line's offset on the chip, 0..1023
  char name[32] = {};  ///< sim: a name (letters, digits, _ and -)
};

/// Set-up: parse a source. True and `out` set, or false and one line in `err` (without the key's
/// name): "\"drive:0:bit16\": the joint is 1-based (1..8)".
bool parse_input_source(std::string_view text, InputSource& out, char* err, std::size_t cap);

/// Set-up: true when this build reads GPIO lines (built with libgpiod, SERVOARM_HAVE_GPIOD).
bool gpiod_available();

class SafetyInput {
 public:
  virtual ~SafetyInput() = default;
  /// Real-time: the level now, or lost when it cannot be read (why_lost() says why). Never
  /// blocks, allocates or makes a system call.
  virtual InputLevel read(TimePoint now) = 0;
  /// Real-time: why the last read() was lost, one line ("" when it was not).
  virtual const char* why_lost() const = 0;
  /// The source as configured ("drive:2:bit16").
  const char* source() const { return source_; }

 protected:
  char source_[64] = {};
};

/// A level set from another thread (tests, armfw --sim). Starts `low`.
class SimInput final : public SafetyInput {
 public:
  explicit SimInput(const char* name);
  /// Any thread: the level the next read() returns (lost: the input cannot be read).
  void set(InputLevel l) { level_.store(static_cast<std::uint8_t>(l), std::memory_order_relaxed); }
  InputLevel read(TimePoint now) override;
  const char* why_lost() const override { return lost_ ? why_ : ""; }

 private:
  std::atomic<std::uint8_t> level_{static_cast<std::uint8_t>(InputLevel::low)};
  bool lost_ = false;
  char why_[128] = {};
};

/// Bit `bit` of joint `joint`'s 60FDh, as the last TPDO3 of its drive carried it. Lost when the
/// drive does not report its inputs, none has arrived within `stale` of the first read (pending
/// until then), or the last is older than `stale`.
class DriveBitInput final : public SafetyInput {
 public:
  /// Set-up: `bus` outlives the input.
  DriveBitInput(const ServoBus& bus, int joint, int bit, Duration stale);
  InputLevel read(TimePoint now) override;
  const char* why_lost() const override { return reason_ != Reason::none ? why_ : ""; }

 private:
  enum class Reason : std::uint8_t { none, not_mapped, never, stale };
  const ServoBus& bus_;
  int joint_, bit_;
  Duration stale_;
  TimePoint first_read_ = -1;
  Reason reason_ = Reason::none;
  char why_[224] = {};
};

/// A GPIO line through libgpiod (Debian's libgpiod-dev, the v1 C API): a thread of its own opens
/// the chip and requests the line for both edges' events; it sleeps until an edge (then reads
/// the level at once) or until the refresh period has passed (then reads it again, to say that
/// the line and the thread are alive). A line that gives no events (a GPIO driver without
/// interrupts) is requested as a plain input and read every `period` instead, said once on
/// stderr and by polling(). Each reading goes to the control thread in one atomic word, with a
/// count of readings. read() loads that word: no system call and no lock on the control thread.
/// Lost when the chip or line cannot be opened or read (the thread tries again every second) or
/// when the thread has not read for `stale` (it stalled). Latency from the line's edge to read():
/// the thread's wake-up latency (polled: plus up to `period`).
class GpiodInput final : public SafetyInput {
 public:
  /// Set-up: nothing opened yet (start()).
  GpiodInput(const char* chip, int line, Duration period, Duration stale);
  ~GpiodInput() override;
  GpiodInput(const GpiodInput&) = delete;
  GpiodInput& operator=(const GpiodInput&) = delete;
  /// Set-up: start the reading thread. False when this build has no libgpiod (gpiod_available()).
  bool start();
  /// Set-up: stop and join the thread (the destructor does it too).
  void stop();
  InputLevel read(TimePoint now) override;
  const char* why_lost() const override { return lost_ ? why_ : ""; }
  /// Readings the thread has published since start() (tests).
  std::uint32_t polls() const { return word_.load(std::memory_order_acquire) >> 13; }
  /// The longest the thread waits for an edge before it reads the line again: a quarter of
  /// `stale`, within [period, 50 ms].
  Duration refresh() const { return refresh_; }
  /// The line gives no edge events: it is read every `period` instead.
  bool polling() const { return polling_.load(std::memory_order_relaxed); }

 private:
  void run();
  /// The thread's outcome: bits 0..1 the InputLevel, 2..4 what went wrong, 5..12 errno, 13..
  /// the count of reads (wraps).
  std::atomic<std::uint32_t> word_{static_cast<std::uint32_t>(InputLevel::lost)};
  std::atomic<bool> stop_{false};
  std::atomic<bool> polling_{false};
  std::thread thread_;
  char chip_[48] = {};
  int line_ = -1;
  Duration period_, stale_, refresh_ = 0;
  // control thread's view
  std::uint32_t seen_count_ = 0;
  TimePoint seen_at_ = -1;
  bool lost_ = false;
  std::uint32_t last_error_ = 0xFF;
  char why_[192] = {};
};

/// One safety input as the controller uses it: its active level, the debounce, and the rule
/// that an input that cannot be read counts as asserted (an e-stop stops, a Reduced switch
/// reduces). Asserting acts in the first cycle it is read; releasing only once the input has
/// read released for `debounce` without a break; a pending read changes nothing. Real-time
/// after configure().
class InputWatch {
 public:
  /// Set-up: `in` (nullptr: none, never asserted) outlives the watch.
  void configure(SafetyInput* in, bool active_low, Duration debounce) {
    in_ = in;
    active_low_ = active_low;
    debounce_ = debounce;
    asserted_ = lost_ = false;
    released_since_ = -1;
  }
  bool configured() const { return in_ != nullptr; }
  /// Real-time: read the input at `now`; returns asserted().
  bool update(TimePoint now);
  /// Asserted (or lost) after the last update().
  bool asserted() const { return asserted_; }
  /// The last read was lost (why: input()->why_lost()); a pending read is asserted, not lost.
  bool lost() const { return lost_; }
  SafetyInput* input() const { return in_; }

 private:
  SafetyInput* in_ = nullptr;
  bool active_low_ = true;
  Duration debounce_ = 0;
  bool asserted_ = false, lost_ = false;
  TimePoint released_since_ = -1;
};

}  // namespace servoarm::hal
