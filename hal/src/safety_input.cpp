// SPDX-License-Identifier: Apache-2.0
// Safety inputs: the source parser, the simulated and the drive-bit backends, InputWatch
// (safety_input.hpp). The GPIO backend is gpiod_input.cpp.
#include "servoarm/hal/safety_input.hpp"

#include <cstdio>
#include <cstring>

namespace servoarm::hal {

const char* to_string(InputLevel l) {
  switch (l) {
    case InputLevel::low: return "low";
    case InputLevel::high: return "high";
    case InputLevel::lost: return "lost";
    case InputLevel::pending: return "pending";
  }
  return "?";
}

namespace {

/// A whole decimal number in [lo, hi], nothing else.
bool whole(std::string_view s, int lo, int hi, int& out) {
  if (s.empty() || s.size() > 6) return false;
  int v = 0;
  for (const char c : s) {
    if (c < '0' || c > '9') return false;
    v = v * 10 + (c - '0');
  }
  if (v < lo || v > hi) return false;
  out = v;
  return true;
}

bool name_ok(std::string_view s, std::size_t cap) {
  if (s.empty() || s.size() >= cap) return false;
  for (const char c : s)
    if (!((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' || c == '-' ||
          c == '.' || c == '/'))
      return false;
  return true;
}

void say(char* err, std::size_t cap, std::string_view text, const char* what) {
  std::snprintf(err, cap, "\"%.*s\": %s", static_cast<int>(text.size() > 60 ? 60 : text.size()), text.data(), what);
}

}  // namespace

bool parse_input_source(std::string_view text, InputSource& out, char* err, std::size_t cap) {
  out = InputSource{};
  if (text.empty()) return true;
  const std::size_t c1 = text.find(':');
  const std::string_view kind = text.substr(0, c1);
  const std::string_view rest = c1 == std::string_view::npos ? std::string_view{} : text.substr(c1 + 1);
  if (kind == "drive") {
    const std::size_t c2 = rest.find(':');
    int joint = 0, bit = 0;
    if (c2 == std::string_view::npos || rest.substr(c2 + 1).substr(0, 3) != "bit") {
      say(err, cap, text, "a drive input is drive:JOINT:bitN (e.g. drive:2:bit16)");
      return false;
    }
    if (!whole(rest.substr(0, c2), 1, static_cast<int>(kMaxServoJoints), joint)) {
      std::snprintf(err, cap, "\"%.*s\": the joint is 1-based, 1..%zu", static_cast<int>(text.size() > 60 ? 60 : text.size()),
                    text.data(), kMaxServoJoints);
      return false;
    }
    if (!whole(rest.substr(c2 + 4), 0, 31, bit)) {
      say(err, cap, text, "the bit of 60FDh is 0..31");
      return false;
    }
    out.kind = InputKind::drive;
    out.joint = joint - 1;
    out.bit = bit;
    return true;
  }
  if (kind == "gpio") {
    const std::size_t c2 = rest.rfind(':');
    int line = 0;
    if (c2 == std::string_view::npos || !name_ok(rest.substr(0, c2), sizeof out.chip)) {
      say(err, cap, text, "a GPIO input is gpio:CHIP:LINE (e.g. gpio:gpiochip0:17)");
      return false;
    }
    if (!whole(rest.substr(c2 + 1), 0, 1023, line)) {
      say(err, cap, text, "the line is its offset on the chip, 0..1023");
      return false;
    }
    out.kind = InputKind::gpio;
    const std::string_view chip = rest.substr(0, c2);
    std::memcpy(out.chip, chip.data(), chip.size());
    out.chip[chip.size()] = '\0';
    out.line = line;
    return true;
  }
  if (kind == "sim") {
    if (!name_ok(rest, sizeof out.name) || rest.find('/') != std::string_view::npos) {
      say(err, cap, text, "a simulated input is sim:NAME (letters, digits, _ and -)");
      return false;
    }
    out.kind = InputKind::sim;
    std::memcpy(out.name, rest.data(), rest.size());
    out.name[rest.size()] = '\0';
    return true;
  }
  say(err, cap, text, "the source is drive:JOINT:bitN, gpio:CHIP:LINE, sim:NAME or \"\" (none)");
  return false;
}

SimInput::SimInput(const char* name) { std::snprintf(source_, sizeof source_, "sim:%s", name); }

InputLevel SimInput::read(TimePoint) {
  const auto l = static_cast<InputLevel>(level_.load(std::memory_order_relaxed));
  if (l == InputLevel::lost && !lost_) std::snprintf(why_, sizeof why_, "%s cannot be read (simulated)", source_);
  lost_ = l == InputLevel::lost;
  return l;
}

DriveBitInput::DriveBitInput(const ServoBus& bus, int joint, int bit, Duration stale)
    : bus_(bus), joint_(joint), bit_(bit), stale_(stale) {
  std::snprintf(source_, sizeof source_, "drive:%d:bit%d", joint + 1, bit);
}

InputLevel DriveBitInput::read(TimePoint now) {
  const JointFeedback& fb = bus_.feedback(static_cast<std::size_t>(joint_));
  if (first_read_ < 0) first_read_ = now;
  Reason r = Reason::none;
  if (!fb.has_inputs) r = Reason::not_mapped;
  else if (fb.inputs_time == 0 && now - first_read_ <= stale_) return InputLevel::pending;
  else if (fb.inputs_time == 0) r = Reason::never;
  else if (now - fb.inputs_time > stale_) r = Reason::stale;
  // The line is written when the reason changes (or, stale, to say for how long at first).
  if (r != reason_) {
    switch (r) {
      case Reason::none: why_[0] = '\0'; break;
      case Reason::not_mapped:
        std::snprintf(why_, sizeof why_, "%s: joint %d's drive does not report its digital inputs (60FDh not mapped)",
                      source_, joint_ + 1);
        break;
      case Reason::never:
        std::snprintf(why_, sizeof why_, "%s: no digital inputs (60FDh) received from joint %d's drive in %.1f ms",
                      source_, joint_ + 1, static_cast<double>(now - first_read_) * 1e-6);
        break;
      case Reason::stale:
        std::snprintf(why_, sizeof why_, "%s: joint %d's digital inputs (60FDh) not received for %.1f ms", source_,
                      joint_ + 1, static_cast<double>(now - fb.inputs_time) * 1e-6);
        break;
    }
    reason_ = r;
  }
  if (r != Reason::none) return InputLevel::lost;
  return (fb.digital_inputs >> bit_) & 1u ? InputLevel::high : InputLevel::low;
}

bool InputWatch::update(TimePoint now) {
  if (in_ == nullptr) return false;
  const InputLevel l = in_->read(now);
  if (l == InputLevel::pending) return asserted_;  // no reading yet: as it was (bounded by the input's timeout)
  lost_ = l == InputLevel::lost;
  const bool active = lost_ || (l == (active_low_ ? InputLevel::low : InputLevel::high));
  if (active) {
    asserted_ = true;
    released_since_ = -1;
  } else if (asserted_) {
    if (released_since_ < 0) released_since_ = now;
    if (now - released_since_ >= debounce_) asserted_ = false, released_since_ = -1;
  }
  return asserted_;
}

}  // namespace servoarm::hal
