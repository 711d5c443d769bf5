// SPDX-License-Identifier: Apache-2.0
#include "servoarm/lang/commands.hpp"

#include "servoarm/lang/command_table.hpp"
#include "servoarm/lang/number.hpp"
#include "servoarm/lang/text.hpp"

#include <cfenv>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace servoarm::fw {

const char* to_string(CmdError e) {
  switch (e) {
    case CmdError::ok: return "ok";
    case CmdError::overlong: return "overlong";
    case CmdError::binary: return "binary";
    case CmdError::unknown_command: return "unknown_command";
    case CmdError::arg_count: return "arg_count";
    case CmdError::bad_number: return "bad_number";
    case CmdError::not_finite: return "not_finite";
    case CmdError::bad_option: return "bad_option";
    case CmdError::out_of_range: return "out_of_range";
    case CmdError::unsupported: return "unsupported";
    case CmdError::checksum: return "checksum";
    case CmdError::busy: return "busy";
    case CmdError::bad_state: return "bad_state";
    case CmdError::fault: return "fault";
    case CmdError::unreachable: return "unreachable";
    case CmdError::limits: return "limits";
    case CmdError::singular: return "singular";
    case CmdError::branch: return "branch";
    case CmdError::plan_failed: return "plan_failed";
    case CmdError::timeout: return "timeout";
    case CmdError::estop: return "estop";
    case CmdError::storage: return "storage";
    case CmdError::not_homed: return "not_homed";
    case CmdError::program: return "program";
    case CmdError::internal: return "internal";
  }
  return "?";
}

const char* to_string(Cmd c) {
  switch (c) {
    case Cmd::none: return "none";
    case Cmd::help: return "help";
    case Cmd::status: return "status";
    case Cmd::enable: return "enable";
    case Cmd::disable: return "disable";
    case Cmd::home: return "home";
    case Cmd::home_zero: return "home zero";
    case Cmd::park: return "park";
    case Cmd::movej: return "movej";
    case Cmd::movel: return "movel";
    case Cmd::stop: return "stop";
    case Cmd::estop: return "estop";
    case Cmd::reset: return "reset";
    case Cmd::fk: return "fk";
    case Cmd::ik: return "ik";
    case Cmd::limits: return "limits";
    case Cmd::stats: return "stats";
    case Cmd::config: return "config";
    case Cmd::wait: return "wait";
    case Cmd::hold: return "hold";
    case Cmd::resume: return "resume";
    case Cmd::dwell: return "dwell";
    case Cmd::position: return "position";
    case Cmd::gmove: return "gmove";
    case Cmd::temperature: return "temperature";
    case Cmd::jog: return "jog";
    case Cmd::tool: return "tool";
    case Cmd::frame: return "frame";
    case Cmd::grbl_jog: return "$J";
    case Cmd::grbl_settings: return "$$";
    case Cmd::grbl_params: return "$#";
    case Cmd::grbl_state: return "$G";
    case Cmd::grbl_info: return "$I";
    case Cmd::grbl_unlock: return "$X";
    case Cmd::grbl_home: return "$H";
    case Cmd::grbl_check: return "$C";
    case Cmd::grbl_help: return "$";
    case Cmd::teach: return "teach";
    case Cmd::points: return "points";
    case Cmd::point_delete: return "point delete";
    case Cmd::programs: return "programs";
    case Cmd::run: return "run";
    case Cmd::pause: return "pause";
    case Cmd::step: return "step";
    case Cmd::abort: return "abort";
    case Cmd::record: return "record";
    case Cmd::out: return "out";
    case Cmd::freedrive: return "freedrive";
    case Cmd::freedrive_on: return "freedrive on";
    case Cmd::freedrive_off: return "freedrive off";
    case Cmd::collision_on: return "collision on";
    case Cmd::collision_off: return "collision off";
    case Cmd::safety: return "safety";
    case Cmd::safety_normal: return "safety normal";
    case Cmd::safety_reduced: return "safety reduced";
    case Cmd::safety_stage: return "safety stage";
    case Cmd::safety_confirm: return "safety confirm";
    case Cmd::quit: return "quit";
  }
  return "?";
}

namespace {

ParseResult fail(CmdError e, const char* fmt, ...) __attribute__((format(printf, 2, 3)));
ParseResult fail(CmdError e, const char* fmt, ...) {
  ParseResult r;
  r.error = e;
  va_list ap;
  va_start(ap, fmt);
  const int n = std::vsnprintf(r.message.data(), r.message.size(), fmt, ap);
  va_end(ap);
  if (n >= static_cast<int>(r.message.size())) ellipsize(r.message.data(), r.message.size());
  return r;
}


struct Words {
  std::array<std::string_view, 24> w{};
  int n = 0;
  bool too_many = false;
};

Words split(std::string_view line) {
  Words ws;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
    if (i >= line.size()) break;
    std::size_t j = i;
    while (j < line.size() && line[j] != ' ' && line[j] != '\t') ++j;
    if (ws.n == static_cast<int>(ws.w.size())) {
      ws.too_many = true;
      break;
    }
    ws.w[static_cast<std::size_t>(ws.n++)] = line.substr(i, j - i);
    i = j;
  }
  return ws;
}

ParseResult parse_numbers(const Words& ws, int first, Command& out, bool allow_speed, const char* name) {
  out.count = 0;
  for (int k = first; k < ws.n; ++k) {
    const std::string_view w = ws.w[static_cast<std::size_t>(k)];
    const std::size_t eq = w.find('=');
    if (eq != std::string_view::npos) {
      if (allow_speed && ieq(w.substr(0, eq), "blend")) {
        // blend=T: the tolerance the arm may pass this target by when the next move follows
        if (out.has_blend) return fail(CmdError::bad_option, "%s: blend given twice", name);
        double b = 0;
        switch (parse_decimal(w.substr(eq + 1), b)) {
          case Num::ok: break;
          case Num::bad: return fail(CmdError::bad_number, "%s: blend '%.*s' is not a number", name, int(w.size() - eq - 1), w.data() + eq + 1);
          case Num::not_finite: return fail(CmdError::not_finite, "%s: blend is not finite", name);
        }
        if (!(b >= 0) || b > 1e6) return fail(CmdError::out_of_range, "%s: blend must be >= 0 (0: exact stop)", name);
        out.has_blend = true;
        out.blend = b;
        continue;
      }
      if (!allow_speed || !ieq(w.substr(0, eq), "speed"))
        return fail(CmdError::bad_option, "%s: unknown option '%.*s' (only speed=%s)", name, int(eq), w.data(),
                    allow_speed ? " and blend=" : "");
      if (out.has_speed) return fail(CmdError::bad_option, "%s: speed given twice", name);
      double v = 0;
      switch (parse_decimal(w.substr(eq + 1), v)) {
        case Num::ok: break;
        case Num::bad: return fail(CmdError::bad_number, "%s: speed '%.*s' is not a number", name, int(w.size() - eq - 1), w.data() + eq + 1);
        case Num::not_finite: return fail(CmdError::not_finite, "%s: speed is not finite", name);
      }
      if (!(v > 0)) return fail(CmdError::out_of_range, "%s: speed must be > 0", name);
      out.has_speed = true;
      out.speed = v;
      continue;
    }
    if (out.has_speed || out.has_blend) return fail(CmdError::bad_option, "%s: options go after the values", name);
    if (out.count >= static_cast<int>(out.vals.size())) return fail(CmdError::arg_count, "%s: too many values", name);
    double v = 0;
    switch (parse_decimal(w, v)) {
      case Num::ok: break;
      case Num::bad: return fail(CmdError::bad_number, "%s: '%.*s' is not a number", name, int(w.size()), w.data());
      case Num::not_finite: return fail(CmdError::not_finite, "%s: value %d is not finite", name, out.count + 1);
    }
    out.vals[static_cast<std::size_t>(out.count++)] = v;
  }
  return {};
}

// ---------------------------------------------------------------------------
// G-code
// ---------------------------------------------------------------------------

/// `jog`: the words of a $J= line (GRBL): axis words without G0/G1, G90/G91 and G20/G21
/// for this line only (the modal state is not changed), G53 accepted, F required.
ParseResult parse_gcode(std::string_view line, GcodeModal& modal, Command& out, bool jog = false) {
  // Strip comments: ';' to end of line, '(...)' inline.
  char buf[kMaxLine + 1];
  std::size_t n = 0;
  int paren = 0;
  for (char c : line) {
    if (c == ';') break;
    if (c == '(') { ++paren; continue; }
    if (c == ')') { if (paren == 0) return fail(CmdError::bad_number, "G-code: ')' without '('"); --paren; continue; }
    if (paren == 0) buf[n++] = c;
  }
  if (paren != 0) return fail(CmdError::bad_number, "G-code: unclosed '('");
  std::string_view s(buf, n);
  // Checksum "*nn" (RepRap): the XOR of every byte of the line as sent before the '*',
  // comments included; the field is the last '*' of the line.
  const std::size_t star = s.find('*');
  if (star != std::string_view::npos) {
    const std::size_t raw_star = line.rfind('*');
    double cs = 0;
    std::string_view tail = line.substr(raw_star + 1);
    while (!tail.empty() && (tail.back() == ' ' || tail.back() == '\t')) tail.remove_suffix(1);
    if (parse_decimal(tail, cs) != Num::ok || cs < 0 || cs > 255 || cs != std::floor(cs))
      return fail(CmdError::checksum, "G-code: bad checksum field");
    unsigned x = 0;
    for (std::size_t i = 0; i < raw_star; ++i) x ^= static_cast<unsigned char>(line[i]);
    if (x != static_cast<unsigned>(cs)) return fail(CmdError::checksum, "G-code: checksum %u, line says %u", x, unsigned(cs));
    s = s.substr(0, star);
  }
  // Tokenise letter + number, spaces optional ("G1X10Y5" is valid).
  GcodeModal m = modal;
  Command c;
  c.gcode = true;
  int motion = -1;           // 0 / 1 for G0 / G1
  int other = -1;            // the one non-modal G/M code
  char other_letter = 0;
  std::array<bool, 6> given{};
  std::array<double, 6> axis{};
  double p = -1, sval = -1, f = -1, l = -1;
  bool g53 = false;
  int wcs = -1;              // G54..G59: 1..6
  std::size_t i = 0;
  while (i < s.size()) {
    char L = s[i];
    if (L == ' ' || L == '\t') { ++i; continue; }
    if (L >= 'a' && L <= 'z') L = static_cast<char>(L - 'a' + 'A');
    if (L < 'A' || L > 'Z') return fail(CmdError::bad_number, "G-code: expected a letter at '%c'", s[i]);
    ++i;
    // G-code numbers: optional sign, digits and one decimal point (no exponent).
    std::size_t j = i;
    if (j < s.size() && (s[j] == '-' || s[j] == '+')) ++j;
    while (j < s.size() && ((s[j] >= '0' && s[j] <= '9') || s[j] == '.')) ++j;
    double v = 0;
    if (j == i) return fail(CmdError::bad_number, "G-code: '%c' has no number", L);
    switch (parse_decimal(s.substr(i, j - i), v)) {
      case Num::ok: break;
      case Num::bad: return fail(CmdError::bad_number, "G-code: '%c%.*s' is not a number", L, int(j - i), s.data() + i);
      case Num::not_finite: return fail(CmdError::not_finite, "G-code: '%c' value is not finite", L);
    }
    i = j;
    switch (L) {
      case 'N': break;  // line number: accepted and ignored
      case 'G': {
        // Exact codes only: G1, G01, G1.0 are G1; G0.95 or G1.01 are no code of ours.
        const int g = static_cast<int>(std::lround(v * 10));
        if (std::fabs(v * 10 - g) > 1e-9 || g % 10 != 0)
          return fail(CmdError::unsupported, "G-code: G%g not supported (G0 G1 G4 G10 G20 G21 G28 G54-G59 G90 G91)", v);
        if (jog && !(g == 900 || g == 910 || g == 200 || g == 210 || g == 530))
          return fail(CmdError::unsupported, "$J: G%g not allowed in a jog line (G20 G21 G53 G90 G91 only)", v);
        if (g == 530) g53 = true;
        else if (g == 170 || g == 940) {
          // G17 (XY plane), G94 (feed per minute): the only modes there are here; CAM and
          // sender headers send them.
        } else if (g >= 540 && g <= 590) {
          if (wcs >= 0) return fail(CmdError::arg_count, "G-code: two of G54..G59 on one line");
          wcs = (g - 540) / 10 + 1;
        } else if (g == 900) m.relative = false;
        else if (g == 910) m.relative = true;
        else if (g == 200) m.unit_mm = 25.4;
        else if (g == 210) m.unit_mm = 1.0;
        else if (g == 0 || g == 10) {
          if (motion >= 0 || other >= 0) return fail(CmdError::arg_count, "G-code: two motion/action codes on one line");
          motion = g / 10;
        } else if (g == 40 || g == 280 || g == 100) {
          if (motion >= 0 || other >= 0) return fail(CmdError::arg_count, "G-code: two motion/action codes on one line");
          other = g / 10;
          other_letter = 'G';
        } else {
          return fail(CmdError::unsupported, "G-code: G%g not supported (G0 G1 G4 G10 G20 G21 G28 G54-G59 G90 G91)", v);
        }
        break;
      }
      case 'M': {
        const int mc = static_cast<int>(std::lround(v));
        if (v != mc || !(mc == 17 || mc == 18 || mc == 84 || mc == 112 || mc == 114 || mc == 400 || mc == 105 ||
                         mc == 110 || mc == 5 || mc == 9 || mc == 2 || mc == 30 || (mc >= 62 && mc <= 65)))
          return fail(CmdError::unsupported, "G-code: M%g not supported (M2 M5 M9 M17 M18 M30 M62-M65 M84 M105 M110 M112 M114 M400)", v);
        if (motion >= 0 || other >= 0) return fail(CmdError::arg_count, "G-code: two motion/action codes on one line");
        other = mc;
        other_letter = 'M';
        break;
      }
      case 'X': case 'Y': case 'Z': case 'A': case 'B': case 'C': {
        const int k = L <= 'C' ? 3 + (L - 'A') : L - 'X';
        if (given[static_cast<std::size_t>(k)]) return fail(CmdError::arg_count, "G-code: %c given twice", L);
        given[static_cast<std::size_t>(k)] = true;
        axis[static_cast<std::size_t>(k)] = v;
        break;
      }
      case 'F':
        if (!(v > 0)) return fail(CmdError::out_of_range, "G-code: F must be > 0");
        if (f >= 0) return fail(CmdError::arg_count, "G-code: F given twice");
        f = v;
        break;
      case 'L':
        if (jog) return fail(CmdError::unsupported, "$J: word 'L' not allowed in a jog line");
        if (l >= 0) return fail(CmdError::arg_count, "G-code: L given twice");
        if (v < 0) return fail(CmdError::out_of_range, "G-code: L must be >= 0 (got %g)", v);
        l = v;
        break;
      case 'P':
      case 'S':
        if (jog) return fail(CmdError::unsupported, "$J: word '%c' not allowed in a jog line", L);
        if (v < 0) return fail(CmdError::out_of_range, "G-code: %c must be >= 0 (got %g)", L, v);
        if ((L == 'P' ? p : sval) >= 0) return fail(CmdError::arg_count, "G-code: %c given twice", L);
        (L == 'P' ? p : sval) = v;
        break;
      default:
        return fail(CmdError::unsupported, "G-code: word '%c' not supported", L);
    }
  }
  const bool any_axis = given[0] || given[1] || given[2] || given[3] || given[4] || given[5];
  if (jog) {
    if (motion >= 0 || other >= 0) return fail(CmdError::unsupported, "$J: motion and M codes are not allowed in a jog line");
    if (f < 0) return fail(CmdError::out_of_range, "$J: a jog line needs F (feed, length units per minute)");
    if (!any_axis) return fail(CmdError::arg_count, "$J: no axis words");
    if (f * m.unit_mm / 60.0 < kMinLinearSpeedMmS)
      return fail(CmdError::out_of_range, "$J: F%g is below the minimum feed %g mm/min", f, kMinLinearSpeedMmS * 60.0 / m.unit_mm);
    c.cmd = Cmd::grbl_jog;
    c.relative = m.relative;
    c.g53 = g53;
    for (int k = 0; k < 6; ++k) {
      if (!given[static_cast<std::size_t>(k)]) continue;
      c.axis_mask = static_cast<std::uint8_t>(c.axis_mask | (1u << k));
      c.vals[static_cast<std::size_t>(k)] = k < 3 ? axis[static_cast<std::size_t>(k)] * m.unit_mm : axis[static_cast<std::size_t>(k)];
    }
    c.count = 6;
    c.has_speed = true;
    c.speed = f * m.unit_mm / 60.0;
    out = c;  // the modal state is the line's own: not kept
    return {};
  }
  if (f > 0 && f * m.unit_mm / 60.0 < kMinLinearSpeedMmS)
    return fail(CmdError::out_of_range, "G-code: F%g is below the minimum feed %g mm/min", f, kMinLinearSpeedMmS * 60.0 / m.unit_mm);
  if (f > 0) m.feed_mm_s = f * m.unit_mm / 60.0;
  if (l >= 0 && !(other_letter == 'G' && other == 10)) return fail(CmdError::arg_count, "G-code: L without G10");
  if (wcs >= 0 && (motion >= 0 || other >= 0))
    return fail(CmdError::unsupported, "G-code: G%d with a motion or action code: put G54..G59 on a line of its own", 53 + wcs);
  // G53 (machine coordinates for this line) means something only for a G0/G1 move on its line
  if (g53 && (motion < 0 || !any_axis))
    return fail(CmdError::arg_count, "G-code: G53 needs a G0/G1 move with axis words on its line (G53 G0 X.. Y.. Z..)");
  if (other_letter == 'G' && other == 10) {
    // G10 L2 Pn: set work offset n (frame g5(3+n)); P0 = the active one. Absolute values
    // (mm / deg), axes not given keep theirs.
    if (l < 0) return fail(CmdError::arg_count, "G-code: G10 needs L2 or L20 (G10 L2 Pn X.. Y.. Z.. A.. B.. C..)");
    if (l != 2 && l != 20) return fail(CmdError::unsupported, "G-code: G10 L%g not supported (G10 L2 or L20: set a work offset)", l);
    if (l == 20 && (given[3] || given[4] || given[5]))
      return fail(CmdError::unsupported, "G-code: G10 L20 takes X Y Z only (the frame's orientation is kept; G10 L2 sets A B C)");
    if (p < 0) return fail(CmdError::arg_count, "G-code: G10 L2 needs P0..P6 (P0: the active frame, P1..P6: G54..G59)");
    if (p > 6 || p != std::floor(p)) return fail(CmdError::out_of_range, "G-code: G10 L2 P%g: P must be 0..6", p);
    if (sval >= 0) return fail(CmdError::bad_option, "G-code: G10 takes no S");
    if (!any_axis) return fail(CmdError::arg_count, "G-code: G10 L2 P%g without axis words changes nothing", p);
    c.cmd = Cmd::frame;
    c.frame_op = FrameOp::set_axes;
    c.g10_p = static_cast<int>(p);
    c.g10_l20 = l == 20;
    for (int k = 0; k < 6; ++k) {
      if (!given[static_cast<std::size_t>(k)]) continue;
      c.axis_mask = static_cast<std::uint8_t>(c.axis_mask | (1u << k));
      c.vals[static_cast<std::size_t>(k)] = k < 3 ? axis[static_cast<std::size_t>(k)] * m.unit_mm : axis[static_cast<std::size_t>(k)];
    }
    c.count = 6;
    modal = m;
    out = c;
    return {};
  }
  if (motion >= 0) {
    if (p >= 0 || sval >= 0) return fail(CmdError::bad_option, "G-code: P/S not allowed with G%d", motion);
    c.cmd = any_axis ? Cmd::gmove : Cmd::none;
    c.rapid = motion == 0;
    c.g53 = g53;  // this line in machine coordinates (the base frame), whatever G54..G59 says
    c.relative = m.relative;
    for (int k = 0; k < 6; ++k) {
      if (!given[static_cast<std::size_t>(k)]) continue;
      c.axis_mask = static_cast<std::uint8_t>(c.axis_mask | (1u << k));
      c.vals[static_cast<std::size_t>(k)] = k < 3 ? axis[static_cast<std::size_t>(k)] * m.unit_mm : axis[static_cast<std::size_t>(k)];
    }
    c.count = any_axis ? 6 : 0;
    if (m.feed_mm_s > 0 && motion == 1) {
      c.has_speed = true;
      c.speed = m.feed_mm_s;
    }
  } else if (other >= 0) {
    if (any_axis && !(other_letter == 'G' && other == 28))
      return fail(CmdError::arg_count, "G-code: %c%d takes no axis words", other_letter, other);
    if (other_letter == 'G' && other == 4) {
      if (p >= 0 && sval >= 0) return fail(CmdError::arg_count, "G-code: G4 takes P (ms) or S (s), not both");
      if (p < 0 && sval < 0) return fail(CmdError::arg_count, "G-code: G4 needs P (milliseconds) or S (seconds)");
      const double secs = p >= 0 ? (m.dwell_p_seconds ? p : p / 1000.0) : sval;
      if (secs > 3600) return fail(CmdError::out_of_range, "G-code: G4 dwell longer than an hour");
      c.cmd = Cmd::dwell;
      c.count = 1;
      c.vals[0] = secs;
    } else if (other_letter == 'M' && other >= 62 && other <= 65) {
      // M62 / M63 P<n>: output n on / off at the start of the next move; M64 / M65: at once
      if (sval >= 0) return fail(CmdError::bad_option, "G-code: M%d takes P (the output number), no S", other);
      if (p < 0) return fail(CmdError::arg_count, "G-code: M%d needs P<n> (the output number, 0-based: [[output]] order)", other);
      if (p != std::floor(p) || p > 63) return fail(CmdError::out_of_range, "G-code: M%d P%g: P must be an output number 0..63", other, p);
      c.cmd = Cmd::out;
      c.out_index = static_cast<int>(p);
      c.out_on = other == 62 || other == 64;
      c.out_sync = other == 62 || other == 63;
    } else {
      if (p >= 0 || sval >= 0) return fail(CmdError::bad_option, "G-code: %c%d takes no P/S", other_letter, other);
      if (other_letter == 'G') c.cmd = Cmd::park;  // G28: the park pose (`home` is the homing cycle, $H)
      else if (other == 17) c.cmd = Cmd::enable;
      else if (other == 18 || other == 84) c.cmd = Cmd::disable;
      else if (other == 112) c.cmd = Cmd::estop;
      else if (other == 114) c.cmd = Cmd::position;
      else if (other == 400) c.cmd = Cmd::wait;
      else if (other == 105) c.cmd = Cmd::temperature;
      else c.cmd = Cmd::none;  // M110: line numbers are not tracked; M5 / M9: no spindle, no coolant; M2 / M30: program end
    }
  } else {
    if (any_axis) return fail(CmdError::arg_count, "G-code: axis words without G0/G1");
    if (p >= 0 || sval >= 0) return fail(CmdError::arg_count, "G-code: P/S without G4");
    c.cmd = Cmd::none;  // modal-only line (G90, G21 F600, N5, ...)
    if (wcs >= 0) {     // G54..G59 (with modal codes): select frame g54..g59
      c.cmd = Cmd::frame;
      c.frame_op = FrameOp::select;
      std::snprintf(c.name.data(), c.name.size(), "g5%d", 3 + wcs);
    }
  }
  modal = m;
  out = c;
  return {};
}

/// A GRBL '$' line (the '$' first): $J=<words>, or a word of kGrblCommands.
ParseResult parse_grbl(std::string_view line, GcodeModal& modal, Command& out) {
  std::string_view t = line.substr(1);
  while (!t.empty() && (t.back() == ' ' || t.back() == '\t')) t.remove_suffix(1);
  if (t.size() >= 2 && (t[0] == 'J' || t[0] == 'j') && t[1] == '=') return parse_gcode(t.substr(2), modal, out, true);
  if (!t.empty() && (t[0] == 'J' || t[0] == 'j')) return fail(CmdError::bad_option, "$J needs '=' and G-code words ($J=G91 X10 F600)");
  for (const GrblSpec& g : kGrblCommands) {
    if (!ieq(t, g.word)) continue;
    Command c;
    c.cmd = g.cmd;
    out = c;
    return {};
  }
  if (!t.empty() && t[0] >= '0' && t[0] <= '9' && t.find('=') != std::string_view::npos)
    return fail(CmdError::unsupported, "$%.*s: settings are read-only here (they come from the configuration file; $$ lists them)",
                int(t.size() > 20 ? 20 : t.size()), t.data());
  return fail(CmdError::unknown_command, "unknown $ command '$%.*s' ($ lists them)", int(t.size() > 20 ? 20 : t.size()), t.data());
}

/// `jog` arguments: nothing (keep-alive), `stop`, or an axis and a value, then options.
ParseResult parse_jog(const Words& ws, int first, int n_joints, const ConsoleUnits& units, Command& c) {
  (void)units;
  const int nargs = ws.n - first;
  if (nargs == 0) {
    c.jog_op = JogOp::keepalive;
    return {};
  }
  const std::string_view a = ws.w[first];
  if (ieq(a, "stop")) {
    if (nargs != 1) return fail(CmdError::arg_count, "jog stop takes no arguments");
    c.jog_op = JogOp::stop;
    return {};
  }
  static constexpr const char* kTool[] = {"x", "y", "z", "rx", "ry", "rz"};
  bool found = false;
  for (int k = 0; k < 6; ++k)
    if (ieq(a, kTool[k])) c.jog_tool = true, c.jog_axis = k, found = true;
  if (!found && a.size() >= 2 && (a[0] == 'j' || a[0] == 'J')) {
    double jn = 0;
    if (parse_decimal(a.substr(1), jn) == Num::ok && jn == std::floor(jn) && jn >= 1 && jn <= n_joints)
      c.jog_axis = static_cast<int>(jn) - 1, found = true;
    else
      return fail(CmdError::out_of_range, "jog: no joint '%.*s' (j1..j%d)", int(a.size() > 8 ? 8 : a.size()), a.data(), n_joints);
  }
  if (!found)
    return fail(CmdError::bad_option, "jog: unknown axis '%.*s' (j1..j%d, x y z rx ry rz, or stop)",
                int(a.size() > 8 ? 8 : a.size()), a.data(), n_joints);
  if (nargs < 2) return fail(CmdError::arg_count, "jog %.*s needs a value: +v, -v, + or -", int(a.size()), a.data());
  const std::string_view v = ws.w[first + 1];
  if (v == "+" || v == "-") {
    c.jog_op = JogOp::continuous;
    c.jog_dir = v == "+" ? 1 : -1;
  } else {
    double d = 0;
    switch (parse_decimal(v, d)) {
      case Num::ok: break;
      case Num::bad: return fail(CmdError::bad_number, "jog: '%.*s' is not a number (or + / -)", int(v.size() > 20 ? 20 : v.size()), v.data());
      case Num::not_finite: return fail(CmdError::not_finite, "jog: the value is not finite");
    }
    if (d == 0) return fail(CmdError::out_of_range, "jog: a jog of 0 moves nothing");
    c.jog_op = JogOp::increment;
    c.vals[0] = d;
    c.count = 1;
  }
  for (int i = first + 2; i < ws.n; ++i) {
    const std::string_view w = ws.w[i];
    const std::size_t eq = w.find('=');
    const std::string_view key = w.substr(0, eq), val = eq == std::string_view::npos ? std::string_view() : w.substr(eq + 1);
    if (eq == std::string_view::npos) return fail(CmdError::arg_count, "jog: unexpected '%.*s'", int(w.size() > 20 ? 20 : w.size()), w.data());
    if (ieq(key, "speed")) {
      double sp = 0;
      switch (parse_decimal(val, sp)) {
        case Num::ok: break;
        case Num::bad: return fail(CmdError::bad_number, "jog: speed '%.*s' is not a number", int(val.size() > 20 ? 20 : val.size()), val.data());
        case Num::not_finite: return fail(CmdError::not_finite, "jog: speed is not finite");
      }
      if (sp < kMinJointSpeedPct || sp > 100) return fail(CmdError::out_of_range, "jog: speed=%g is outside [%g, 100] (percent)", sp, kMinJointSpeedPct);
      c.has_speed = true;
      c.speed = sp;
    } else if (ieq(key, "frame")) {
      if (!c.jog_tool) return fail(CmdError::bad_option, "jog: frame= is for tool axes (x y z rx ry rz), not joints");
      if (ieq(val, "base")) c.jog_frame = JogFrame::base;
      else if (ieq(val, "tool")) c.jog_frame = JogFrame::tool;
      else if (ieq(val, "user")) c.jog_frame = JogFrame::user;
      else return fail(CmdError::bad_option, "jog: frame=%.*s unknown (base, tool or user)", int(val.size() > 20 ? 20 : val.size()), val.data());
    } else {
      return fail(CmdError::bad_option, "jog: unknown option '%.*s' (speed=, frame=)", int(key.size() > 20 ? 20 : key.size()), key.data());
    }
  }
  return {};
}

/// `tool ...` / `frame ...` arguments (frames.hpp has the rules the console checks again).
ParseResult parse_named(const Words& ws, int first, bool is_tool, const ConsoleUnits& units, Command& c) {
  (void)units;
  const char* what = is_tool ? "tool" : "frame";
  const int nargs = ws.n - first;
  auto put_name = [&](std::string_view n) -> ParseResult {
    if (n.empty() || n.size() >= c.name.size())
      return fail(CmdError::bad_option, "%s: name '%.*s' must be 1..%zu characters", what, int(n.size() > 30 ? 30 : n.size()),
                  n.data(), c.name.size() - 1);
    for (std::size_t i = 0; i < n.size(); ++i) {
      const char ch = n[i];
      const bool letter = (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z');
      const bool more = (ch >= '0' && ch <= '9') || ch == '_' || ch == '-';
      if (!(letter || (i > 0 && more)))
        return fail(CmdError::bad_option, "%s: name '%.*s': letters, digits, _ and - only, starting with a letter", what,
                    int(n.size()), n.data());
    }
    std::memcpy(c.name.data(), n.data(), n.size());
    return {};
  };
  if (nargs == 0) {
    c.frame_op = FrameOp::list;
    return {};
  }
  if (ieq(ws.w[first], "delete")) {
    if (nargs != 2) return fail(CmdError::arg_count, "%s delete takes one name", what);
    c.frame_op = FrameOp::remove;
    return put_name(ws.w[first + 1]);
  }
  ParseResult r = put_name(ws.w[first]);
  if (!r.ok()) return r;
  if (nargs == 1) {
    c.frame_op = FrameOp::select;
    return {};
  }
  c.frame_op = FrameOp::define;
  c.count = 0;
  for (int k = first + 1; k < ws.n; ++k) {
    const std::string_view w = ws.w[static_cast<std::size_t>(k)];
    const std::size_t eq = w.find('=');
    if (eq == std::string_view::npos) {
      if (c.has_mass || c.has_com || c.has_radius) return fail(CmdError::bad_option, "%s: options go after the values", what);
      if (c.count >= 6) return fail(CmdError::arg_count, "%s: too many values (x y z rx ry rz)", what);
      double v = 0;
      switch (parse_decimal(w, v)) {
        case Num::ok: break;
        case Num::bad: return fail(CmdError::bad_number, "%s: '%.*s' is not a number", what, int(w.size() > 20 ? 20 : w.size()), w.data());
        case Num::not_finite: return fail(CmdError::not_finite, "%s: value %d is not finite", what, c.count + 1);
      }
      c.vals[static_cast<std::size_t>(c.count++)] = v;
      continue;
    }
    const std::string_view key = w.substr(0, eq), val = w.substr(eq + 1);
    if (!is_tool) return fail(CmdError::bad_option, "frame: unknown option '%.*s' (a frame takes x y z rx ry rz only)", int(key.size() > 20 ? 20 : key.size()), key.data());
    if (ieq(key, "mass")) {
      if (c.has_mass) return fail(CmdError::bad_option, "tool: mass given twice");
      switch (parse_decimal(val, c.mass)) {
        case Num::ok: break;
        case Num::bad: return fail(CmdError::bad_number, "tool: mass '%.*s' is not a number", int(val.size() > 20 ? 20 : val.size()), val.data());
        case Num::not_finite: return fail(CmdError::not_finite, "tool: mass is not finite");
      }
      if (c.mass < 0) return fail(CmdError::out_of_range, "tool: mass must be >= 0 kg (got %g)", c.mass);
      c.has_mass = true;
    } else if (ieq(key, "com")) {
      if (c.has_com) return fail(CmdError::bad_option, "tool: com given twice");
      std::string_view rest = val;
      for (int i = 0; i < 3; ++i) {
        const std::size_t comma = rest.find(',');
        if ((i < 2) != (comma != std::string_view::npos))
          return fail(CmdError::arg_count, "tool: com needs three values x,y,z");
        const std::string_view part = rest.substr(0, comma);
        switch (parse_decimal(part, c.com[static_cast<std::size_t>(i)])) {
          case Num::ok: break;
          case Num::bad: return fail(CmdError::bad_number, "tool: com value '%.*s' is not a number", int(part.size() > 20 ? 20 : part.size()), part.data());
          case Num::not_finite: return fail(CmdError::not_finite, "tool: com value %d is not finite", i + 1);
        }
        rest = comma == std::string_view::npos ? std::string_view() : rest.substr(comma + 1);
      }
      c.has_com = true;
    } else if (ieq(key, "radius")) {
      if (c.has_radius) return fail(CmdError::bad_option, "tool: radius given twice");
      switch (parse_decimal(val, c.radius)) {
        case Num::ok: break;
        case Num::bad: return fail(CmdError::bad_number, "tool: radius '%.*s' is not a number", int(val.size() > 20 ? 20 : val.size()), val.data());
        case Num::not_finite: return fail(CmdError::not_finite, "tool: radius is not finite");
      }
      if (c.radius < 0) return fail(CmdError::out_of_range, "tool: radius must be >= 0 (got %g)", c.radius);
      c.has_radius = true;
    } else {
      return fail(CmdError::bad_option, "tool: unknown option '%.*s' (mass=, com=, radius=)", int(key.size() > 20 ? 20 : key.size()), key.data());
    }
  }
  if (c.count != 6) return fail(CmdError::arg_count, "%s %s needs x y z rx ry rz, got %d values", what, c.name.data(), c.count);
  if (c.has_com && !c.has_mass) return fail(CmdError::bad_option, "tool: com= needs mass=");
  return {};
}

/// A teach point name (letters, digits, _ and -, starting with a letter, 1..31) or, with
/// `program`, a program name (also '.', 1..63, starting with a letter or digit) into c.word.
ParseResult put_word(std::string_view n, bool program, const char* what, Command& c) {
  const std::size_t max = program ? 63 : 31;
  if (n.empty() || n.size() > max)
    return fail(CmdError::bad_option, "%s: name '%.*s' must be 1..%zu characters", what, int(n.size() > 40 ? 40 : n.size()),
                n.data(), max);
  for (std::size_t i = 0; i < n.size(); ++i) {
    const char ch = n[i];
    const bool letter = (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z');
    const bool digit = ch >= '0' && ch <= '9';
    const bool ok = i == 0 ? (letter || (program && digit)) : (letter || digit || ch == '_' || ch == '-' || (program && ch == '.'));
    if (!ok)
      return fail(CmdError::bad_option, program ? "%s: program name '%.*s': letters, digits, _ - and . only (no path)"
                                                : "%s: point name '%.*s': letters, digits, _ and - only, starting with a letter",
                  what, int(n.size()), n.data());
  }
  std::memcpy(c.word.data(), n.data(), n.size());
  return {};
}

bool looks_like_gcode(std::string_view w) {
  if (w.empty()) return false;
  const char L = w[0];
  if (!(L == 'G' || L == 'g' || L == 'M' || L == 'm' || L == 'N' || L == 'n')) return false;
  return w.size() >= 2 && ((w[1] >= '0' && w[1] <= '9') || w[1] == '-' || w[1] == '+' || w[1] == '.');
}

}  // namespace

ParseResult parse_line(std::string_view line, int n_joints, GcodeModal& modal, Command& out, const ConsoleUnits& units) {
  if (line.size() > kMaxLine) return fail(CmdError::overlong, "line longer than %zu characters", kMaxLine);
  while (!line.empty() && (line.back() == '\r' || line.back() == ' ' || line.back() == '\t')) line.remove_suffix(1);
  for (char ch : line) {
    const auto u = static_cast<unsigned char>(ch);
    if ((u < 0x20 && ch != '\t') || u >= 0x7f) return fail(CmdError::binary, "control or non-ASCII byte 0x%02X in line", unsigned(u));
  }
  const Words ws = split(line);
  // A command that takes the rest of the line (safety stage) may have more words than the table.
  bool rest_of_line = false;
  for (const CommandSpec& e : kCommands) {
    const std::string_view name(e.name);
    const std::size_t sp = name.find(' ');
    if (e.args == ArgShape::rest && sp != std::string_view::npos && ws.n >= 2 && ieq(ws.w[0], name.substr(0, sp)) &&
        ieq(ws.w[1], name.substr(sp + 1)))
      rest_of_line = true;
  }
  if (ws.too_many && !rest_of_line) return fail(CmdError::arg_count, "too many words");
  Command c;
  if (ws.n == 0 || ws.w[0][0] == '#' || ws.w[0][0] == ';') {
    out = c;
    return {};
  }
  const std::string_view head = ws.w[0];
  if (head[0] == '$') return parse_grbl(line.substr(line.find('$')), modal, out);
  if (looks_like_gcode(head)) return parse_gcode(line, modal, out);
  // The command table: a two-word entry ("home zero") before the one-word one.
  const CommandSpec* spec = nullptr;
  int used = 0;
  for (const CommandSpec& e : kCommands) {
    const std::string_view name(e.name);
    const std::size_t sp = name.find(' ');
    const int words = sp == std::string_view::npos ? 1 : 2;
    if (words == 2 ? ws.n >= 2 && ieq(head, name.substr(0, sp)) && ieq(ws.w[1], name.substr(sp + 1)) : ieq(head, name)) {
      if (words > used) spec = &e, used = words;
    }
  }
  for (const CommandAlias& a : kCommandAliases)
    if (spec == nullptr && ieq(head, a.alias))
      for (const CommandSpec& e : kCommands)
        if (std::string_view(e.name) == a.name) spec = &e, used = 1;
  if (spec == nullptr) return fail(CmdError::unknown_command, "unknown command '%.*s' (try help)", int(head.size() > 24 ? 24 : head.size()), head.data());
  c.cmd = spec->cmd;
  const int nargs = ws.n - used;
  const char* name = spec->name;
  switch (spec->args) {
    case ArgShape::none:
      if (nargs != 0) {
        // Name the longer forms of the same word ("home takes no arguments (or: home zero)").
        const CommandSpec* longer = nullptr;
        for (const CommandSpec& e : kCommands)
          if (&e != spec && std::string_view(e.name).rfind(std::string_view(name), 0) == 0 && e.name[std::strlen(name)] == ' ')
            longer = &e;
        if (longer != nullptr) return fail(CmdError::arg_count, "%s takes no arguments (or: %s)", name, longer->usage);
        return fail(CmdError::arg_count, "%s takes no arguments", name);
      }
      break;
    case ArgShape::topic:
      if (nargs > 1) return fail(CmdError::arg_count, "%s takes at most one topic", name);
      if (nargs == 1) {
        const std::string_view t = ws.w[1];
        const std::size_t k = t.size() < c.topic.size() - 1 ? t.size() : c.topic.size() - 1;
        std::memcpy(c.topic.data(), t.data(), k);
      }
      break;
    case ArgShape::joints_speed: {
      int first = used;
      if (nargs >= 1 && ws.w[used][0] == '@') {  // movej @NAME [speed=] [blend=]
        ParseResult r = put_word(ws.w[used].substr(1), false, name, c);
        if (!r.ok()) return r;
        c.at_point = true;
        ++first;
      }
      ParseResult r = parse_numbers(ws, first, c, true, name);
      if (!r.ok()) return r;
      if (c.at_point && c.count != 0) return fail(CmdError::arg_count, "%s @%s takes options only (speed=, blend=)", name, c.word.data());
      if (!c.at_point && c.count != n_joints)
        return fail(CmdError::arg_count, "%s needs %d joint values (or @point), got %d", name, n_joints, c.count);
      if (c.has_speed && (c.speed > 100 || c.speed < kMinJointSpeedPct))
        return fail(CmdError::out_of_range, "%s: speed=%g is outside [%g, 100] (percent)", name, c.speed, kMinJointSpeedPct);
      break;
    }
    case ArgShape::pose_speed:
    case ArgShape::pose: {
      int first = used;
      if (spec->args == ArgShape::pose_speed && nargs >= 1 && ws.w[used][0] == '@') {  // movel @NAME [speed=] [blend=]
        ParseResult r = put_word(ws.w[used].substr(1), false, name, c);
        if (!r.ok()) return r;
        c.at_point = true;
        ++first;
      }
      ParseResult r = parse_numbers(ws, first, c, spec->args == ArgShape::pose_speed, name);
      if (!r.ok()) return r;
      if (c.at_point && c.count != 0) return fail(CmdError::arg_count, "%s @%s takes options only (speed=, blend=)", name, c.word.data());
      if (!c.at_point && c.count != 3 && c.count != 6)
        return fail(CmdError::arg_count, "%s needs x y z [rx ry rz] (or @point), got %d values", name, c.count);
      // An orientation is an angle of at most a turn each way: 1e300 deg names no orientation
      for (int k = 3; k < c.count; ++k) {
        const double a = units.angle_in(c.vals[static_cast<std::size_t>(k)]);
        if (!(std::fabs(a) <= 2 * M_PI + 1e-9))
          return fail(CmdError::out_of_range, "%s: %s = %g %s outside [-%g, %g]", name, k == 3 ? "rx" : k == 4 ? "ry" : "rz",
                      c.vals[static_cast<std::size_t>(k)], units.angle_name(), units.angle_out(2 * M_PI), units.angle_out(2 * M_PI));
      }
      const double vmin = units.length == LengthUnit::mm ? kMinLinearSpeedMmS : kMinLinearSpeedMmS * 1e-3;
      if (c.has_speed && c.speed < vmin)
        return fail(CmdError::out_of_range, "%s: speed=%g %s/s is below the minimum %g %s/s", name, c.speed,
                    units.length_name(), vmin, units.length_name());
      break;
    }
    case ArgShape::joints_opt: {
      ParseResult r = parse_numbers(ws, used, c, false, name);
      if (!r.ok()) return r;
      if (c.count != 0 && c.count != n_joints) return fail(CmdError::arg_count, "%s takes no values or %d joint values, got %d", name, n_joints, c.count);
      break;
    }
    case ArgShape::jog: {
      ParseResult r = parse_jog(ws, used, n_joints, units, c);
      if (!r.ok()) return r;
      break;
    }
    case ArgShape::tool:
    case ArgShape::frame: {
      ParseResult r = parse_named(ws, used, spec->args == ArgShape::tool, units, c);
      if (!r.ok()) return r;
      break;
    }
    case ArgShape::point_name:
    case ArgShape::program_name: {
      if (nargs != 1) return fail(CmdError::arg_count, "%s takes one name", name);
      ParseResult r = put_word(ws.w[used], spec->args == ArgShape::program_name, name, c);
      if (!r.ok()) return r;
      break;
    }
    case ArgShape::output: {
      if (nargs == 0) break;  // list
      if (nargs != 2) return fail(CmdError::arg_count, "out NAME on|off (or out alone: list)");
      ParseResult r = put_word(ws.w[used], false, name, c);
      if (!r.ok()) return r;
      const std::string_view v = ws.w[used + 1];
      if (ieq(v, "on") || v == "1") c.out_on = true;
      else if (ieq(v, "off") || v == "0") c.out_on = false;
      else return fail(CmdError::bad_option, "out %s: '%.*s' is neither on nor off", c.word.data(), int(v.size() > 20 ? 20 : v.size()), v.data());
      c.out_index = -2;  // by name
      break;
    }
    case ArgShape::record: {
      if (nargs < 1) return fail(CmdError::arg_count, "record start [rate=Hz] | record stop NAME [tolerance=angle] | record mcap [rate=Hz] | record mcap stop");
      const std::string_view op = ws.w[used];
      int k = used + 1;
      if (ieq(op, "mcap")) {  // record mcap [rate=Hz] | record mcap stop: an MCAP file (the service checks the rate)
        c.record_mcap = true;
        if (k < ws.n && ieq(ws.w[k], "stop")) {
          c.record_stop = true;
          if (++k < ws.n) return fail(CmdError::arg_count, "record mcap stop takes no arguments");
        }
        for (; k < ws.n; ++k) {
          const std::string_view w = ws.w[k];
          const std::size_t eq = w.find('=');
          if (eq == std::string_view::npos || !ieq(w.substr(0, eq), "rate"))
            return fail(CmdError::bad_option, "record mcap: unexpected '%.*s' (only rate=)", int(w.size() > 20 ? 20 : w.size()), w.data());
          double v = 0;
          switch (parse_decimal(w.substr(eq + 1), v)) {
            case Num::ok: break;
            case Num::bad: return fail(CmdError::bad_number, "record mcap: rate '%.*s' is not a number", int(w.size() - eq - 1), w.data() + eq + 1);
            case Num::not_finite: return fail(CmdError::not_finite, "record mcap: rate is not finite");
          }
          if (!(v > 0)) return fail(CmdError::out_of_range, "record mcap: rate=%g must be > 0", v);
          c.rate = v;
        }
        break;
      }
      if (ieq(op, "stop")) {
        if (nargs < 2 || std::string_view(ws.w[k]).find('=') != std::string_view::npos)
          return fail(CmdError::arg_count, "record stop needs a program name (record stop NAME)");
        ParseResult r = put_word(ws.w[k], true, "record stop", c);
        if (!r.ok()) return r;
        c.record_stop = true;
        ++k;
      } else if (!ieq(op, "start")) {
        return fail(CmdError::bad_option, "record: '%.*s' is neither start nor stop", int(op.size() > 20 ? 20 : op.size()), op.data());
      }
      for (; k < ws.n; ++k) {
        const std::string_view w = ws.w[k];
        const std::size_t eq = w.find('=');
        const std::string_view key = w.substr(0, eq);
        const char* want = c.record_stop ? "tolerance" : "rate";
        if (eq == std::string_view::npos || !ieq(key, want))
          return fail(CmdError::bad_option, "record %s: unexpected '%.*s' (only %s=)", c.record_stop ? "stop" : "start",
                      int(w.size() > 20 ? 20 : w.size()), w.data(), want);
        double v = 0;
        switch (parse_decimal(w.substr(eq + 1), v)) {
          case Num::ok: break;
          case Num::bad: return fail(CmdError::bad_number, "record: %s '%.*s' is not a number", want, int(w.size() - eq - 1), w.data() + eq + 1);
          case Num::not_finite: return fail(CmdError::not_finite, "record: %s is not finite", want);
        }
        if (c.record_stop) {
          if (!(v > 0)) return fail(CmdError::out_of_range, "record stop: tolerance must be > 0");
          c.tolerance = v;
        } else {
          // sampled on the console thread, whose loop runs at least every 10 ms
          if (!(v >= 1 && v <= 100)) return fail(CmdError::out_of_range, "record start: rate=%g outside [1, 100] Hz", v);
          c.rate = v;
        }
      }
      break;
    }
    case ArgShape::confirm:
      if (nargs > 1) return fail(CmdError::arg_count, "%s takes at most the word confirm", name);
      if (nargs == 1) {
        const std::string_view w = ws.w[used];
        if (!ieq(w, "confirm"))
          return fail(CmdError::bad_option, "%s: '%.*s' is not `confirm`", name, int(w.size() > 20 ? 20 : w.size()), w.data());
        c.confirm = true;
      }
      break;
    case ArgShape::rest: {
      if (nargs < 1) return fail(CmdError::arg_count, "%s needs the change: KEY = VALUE[; KEY = VALUE ...]", name);
      // from the first argument to the end of the line (trailing blanks already cut)
      const std::size_t from = static_cast<std::size_t>(ws.w[used].data() - line.data());
      const std::string_view t = line.substr(from);
      std::memcpy(c.text.data(), t.data(), t.size());  // t.size() <= kMaxLine < c.text.size()
      break;
    }
    case ArgShape::checksum: {
      if (nargs != 1) return fail(CmdError::arg_count, "%s takes one checksum (8 hex digits, as `safety stage` answered it)", name);
      const std::string_view w = ws.w[used];
      if (!parse_checksum(w, c.checksum))
        return fail(CmdError::bad_number, "%s: '%.*s' is not 8 hex digits", name, int(w.size() > 20 ? 20 : w.size()), w.data());
      break;
    }
    case ArgShape::joint_word: {
      if (nargs > 1) return fail(CmdError::arg_count, "%s takes at most one joint (j1..j%d)", name, n_joints);
      if (nargs == 1) {
        const std::string_view w = ws.w[used];
        int j = 0;
        bool digits = w.size() >= 2 && w.size() <= 3 && (w[0] == 'j' || w[0] == 'J');
        for (std::size_t i = 1; digits && i < w.size(); ++i) {
          digits = w[i] >= '0' && w[i] <= '9';
          j = j * 10 + (w[i] - '0');
        }
        if (!digits) return fail(CmdError::arg_count, "%s: '%.*s' is not a joint (j1..j%d, or: home zero)", name, int(w.size() > 20 ? 20 : w.size()), w.data(), n_joints);
        if (j < 1 || j > n_joints) return fail(CmdError::out_of_range, "%s: joint %d does not exist (j1..j%d)", name, j, n_joints);
        c.home_joint = j - 1;
      }
      break;
    }
  }
  out = c;
  return {};
}

}  // namespace servoarm::fw
