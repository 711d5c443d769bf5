// SPDX-License-Identifier: Apache-2.0
// Program files: load, check structure, expand repeats and calls, parse every line with
// the console's parser (program.hpp).
#include "servoarm/program/program.hpp"

#include <dirent.h>
#include <sys/stat.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <memory>

#include "servoarm/lang/number.hpp"
#include "servoarm/lang/text.hpp"
#include "servoarm/kinematics/io/file_input.hpp"

namespace servoarm::prog {

namespace {

constexpr const char* kGcodeExt[] = {".gcode", ".nc", ".ngc", ".gc"};

std::string shown(std::string_view s, std::size_t max = 40) {
  std::string o;
  for (char c : s.substr(0, max)) o += (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) >= 0x7f) ? '?' : c;
  return o + (s.size() > max ? "..." : "");
}

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

std::vector<std::string_view> words(std::string_view s) {
  std::vector<std::string_view> w;
  std::size_t i = 0;
  while (i < s.size()) {
    while (i < s.size() && (s[i] == ' ' || s[i] == '\t')) ++i;
    std::size_t j = i;
    while (j < s.size() && s[j] != ' ' && s[j] != '\t') ++j;
    if (j > i) w.push_back(s.substr(i, j - i));
    i = j;
  }
  return w;
}

std::string fmt17(double v) {
  char b[40];
  std::snprintf(b, sizeof b, "%.17g", v);
  return b;
}

bool file_exists(const std::string& p) {
  struct stat st{};
  return ::stat(p.c_str(), &st) == 0;
}

std::string dir_of(const std::string& path) {
  const std::size_t k = path.rfind('/');
  return k == std::string::npos ? "." : (k == 0 ? "/" : path.substr(0, k));
}

// A G-code line's M2 / M30 (program end), comments skipped.
bool gcode_program_end(std::string_view s) {
  int paren = 0;
  for (std::size_t i = 0; i < s.size(); ++i) {
    const char c = s[i];
    if (c == ';') break;
    if (c == '(') ++paren;
    else if (c == ')') --paren;
    else if (paren == 0 && (c == 'M' || c == 'm') && (i == 0 || s[i - 1] == ' ' || s[i - 1] == '\t' || std::isdigit(static_cast<unsigned char>(s[i - 1])))) {
      std::size_t j = i + 1;
      while (j < s.size() && s[j] == '0') ++j;
      std::size_t k = j;
      while (k < s.size() && std::isdigit(static_cast<unsigned char>(s[k]))) ++k;
      const std::string_view d = s.substr(j, k - j);
      const bool end_word = k >= s.size() || !(s[k] == '.' || std::isdigit(static_cast<unsigned char>(s[k])));
      if (end_word && (d == "2" || d == "30")) return true;
    }
  }
  return false;
}

// Console commands a program may not run: they answer a person at the console (help,
// jogging, the GRBL $ commands) or stop / reset the arm (a program ends, it does not
// reset). A list, not a switch over every command: the console's table grows.
bool interactive_only(fw::Cmd c) {
  using fw::Cmd;
  for (Cmd x : {Cmd::help, Cmd::jog, Cmd::grbl_jog, Cmd::grbl_settings, Cmd::grbl_params, Cmd::grbl_state, Cmd::grbl_info,
                Cmd::grbl_unlock, Cmd::grbl_home, Cmd::grbl_check, Cmd::grbl_help, Cmd::home_zero, Cmd::reset, Cmd::estop,
                Cmd::stop, Cmd::hold, Cmd::resume, Cmd::run, Cmd::pause, Cmd::step, Cmd::abort, Cmd::record, Cmd::teach,
                Cmd::point_delete, Cmd::quit})
    if (c == x) return true;
  return false;
}

enum class ItemKind { line, repeat, end, call, blend_mode };

struct Item {
  ItemKind kind = ItemKind::line;
  int line = 0;
  std::string text;    // line: what goes to the parser (native: comment stripped)
  int count = 0;       // repeat
  int match = -1;      // repeat: index of its end
  std::size_t body = 0;  // repeat: steps of one pass of its body (saturating)
  int callee = -1;     // call: file index
  double value = 0;    // blend_mode: G64 P (G-code length units), 0 = G61
};

struct ParsedFile {
  std::string path;
  bool gcode = false;
  std::vector<Item> items;
  std::size_t size = 0;  // steps once expanded (saturated at max_steps + 1)
  bool sized = false;
};

struct Loader {
  const ProgramContext& ctx;
  Program& prog;
  std::vector<std::unique_ptr<ParsedFile>> files;  // index = Program::files index
  std::vector<int> stack;
  std::string err;
  // phase 2 state (execution order)
  fw::GcodeModal modal;
  double gcode_blend = -1;  // mm, from G64 P / G61 (0); < 0: neither seen (the configured default)

  std::string at(int file, int line) const { return files[static_cast<std::size_t>(file)]->path + ":" + std::to_string(line); }
  bool fail(int file, int line, const std::string& why) {
    if (err.empty()) err = kin::one_line(at(file, line) + ": " + why);
    return false;
  }
  int failx(int file, int line, const std::string& why) {
    fail(file, line, why);
    return -1;
  }
  std::size_t cap() const { return ctx.limits.max_steps + 1; }
  static std::size_t sat_add(std::size_t a, std::size_t b, std::size_t c) { return std::min(c, a + b); }
  static std::size_t sat_mul(std::size_t a, std::size_t b, std::size_t c) {
    if (a == 0 || b == 0) return 0;
    return a > c / b ? c : std::min(c, a * b);
  }

  // Phase 1: read, check bytes, split, structure; recursively the callees. Returns the file index or -1.
  int open(const std::string& path, int from_file, int from_line) {
    char real[4096];
    const std::string key = ::realpath(path.c_str(), real) != nullptr ? std::string(real) : path;
    for (int s : stack)
      if (files[static_cast<std::size_t>(s)]->path == key || prog.files[static_cast<std::size_t>(s)] == key) {
        std::string chain;
        for (int t : stack) chain += prog.files[static_cast<std::size_t>(t)] + " -> ";
        fail(from_file, from_line, "call recursion: " + chain + path + " (a program may not call itself)");
        return -1;
      }
    if (static_cast<int>(stack.size()) > ctx.limits.max_call_depth) {
      fail(from_file, from_line, "calls nested deeper than " + std::to_string(ctx.limits.max_call_depth));
      return -1;
    }
    for (std::size_t i = 0; i < files.size(); ++i)
      if (files[i]->path == key) return static_cast<int>(i);  // read before (not on the stack): reuse
    std::string text;
    std::string e = kin::read_text_file(path, text, ctx.limits.max_file_bytes);
    if (!e.empty()) {
      if (from_file < 0) err = kin::one_line(e);
      else fail(from_file, from_line, e);
      return -1;
    }
    const int idx = static_cast<int>(files.size());
    auto pf = std::make_unique<ParsedFile>();
    pf->path = key;
    pf->gcode = is_gcode_file(path);
    files.push_back(std::move(pf));
    prog.files.push_back(path);
    ParsedFile& f = *files.back();
    // Binary data: any control byte but tab, and CR only before LF (or at the end).
    int line = 1;
    for (std::size_t i = 0; i < text.size(); ++i) {
      const auto u = static_cast<unsigned char>(text[i]);
      if (u == '\n') {
        ++line;
        continue;
      }
      if (u == '\r' && (i + 1 == text.size() || text[i + 1] == '\n')) continue;
      if ((u < 0x20 && u != '\t') || u == 0x7f) {
        char b[120];
        std::snprintf(b, sizeof b, "binary data (byte 0x%02X at offset %zu): not a program file", unsigned(u), i);
        fail(idx, line, b);
        return -1;
      }
    }
    stack.push_back(idx);
    std::vector<int> open_repeats;
    std::size_t pos = 0;
    line = 0;
    bool ended = false;
    while (pos < text.size() && !ended) {
      std::size_t nl = text.find('\n', pos);
      if (nl == std::string::npos) nl = text.size();
      std::string_view raw(text.data() + pos, nl - pos);
      pos = nl + 1;
      ++line;
      std::string_view s = trim(raw);
      if (f.gcode) {
        if (s.empty() || s == "%") continue;
        std::string up;
        for (char c : s) up += static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
        const auto w = words(up);
        if (!w.empty() && (w[0] == "G61" || w[0] == "G64" || w[0] == "G61.1")) {
          Item it;
          it.kind = ItemKind::blend_mode;
          it.line = line;
          if (w[0] != "G64") {
            if (w.size() != 1) return failx(idx, line, std::string(w[0]) + " goes on a line of its own");
            it.value = 0;
          } else {
            double p = 0;
            if (w.size() != 2 || w[1].size() < 2 || w[1][0] != 'P' ||
                fw::parse_decimal(w[1].substr(1), p) != fw::Num::ok || !(p >= 0) || p > 1000)
              return failx(idx, line, "G64 needs P<tolerance> (0..1000, length units) and nothing else on its line");
            it.value = p;
          }
          f.items.push_back(it);
          continue;
        }
        Item it;
        it.line = line;
        it.text = std::string(s);
        f.items.push_back(it);
        if (gcode_program_end(s)) ended = true;
        continue;
      }
      // native: a comment from '#' or ';' on ('$' lines are GRBL commands: kept whole)
      if (!s.empty() && s[0] != '$') {
        const std::size_t c = s.find_first_of("#;");
        if (c != std::string_view::npos) s = trim(s.substr(0, c));
      }
      if (s.empty()) continue;
      const auto w = words(s);
      Item it;
      it.line = line;
      if (fw::ieq(w[0], "repeat")) {
        double n = 0;
        if (w.size() != 2 || fw::parse_decimal(w[1], n) != fw::Num::ok || n != static_cast<double>(static_cast<long>(n)) ||
            n < 1 || n > kMaxRepeat)
          return failx(idx, line, "repeat needs a count 1.." + std::to_string(kMaxRepeat) + " (repeat N ... end)");
        it.kind = ItemKind::repeat;
        it.count = static_cast<int>(n);
        open_repeats.push_back(static_cast<int>(f.items.size()));
      } else if (fw::ieq(w[0], "end")) {
        if (w.size() != 1) return failx(idx, line, "end takes nothing after it");
        if (open_repeats.empty()) return failx(idx, line, "end without repeat");
        it.kind = ItemKind::end;
        it.count = f.items[static_cast<std::size_t>(open_repeats.back())].count;
        f.items[static_cast<std::size_t>(open_repeats.back())].match = static_cast<int>(f.items.size());
        open_repeats.pop_back();
      } else if (fw::ieq(w[0], "call")) {
        if (w.size() != 2) return failx(idx, line, "call needs one program name (call NAME)");
        const std::string name(w[1]);
        if (std::string why = check_program_name(name); !why.empty()) return failx(idx, line, "call: " + why);
        const std::string dir = ctx.dir.empty() ? dir_of(path) : ctx.dir;
        const std::string p = find_program(dir, name);
        if (p.empty()) return failx(idx, line, "call: no program '" + name + "' in " + dir);
        it.kind = ItemKind::call;
        it.text = name;
        it.callee = open(p, idx, line);
        if (it.callee < 0) return -1;
      } else {
        it.text = std::string(s);
      }
      f.items.push_back(it);
    }
    if (!open_repeats.empty())
      return failx(idx, f.items[static_cast<std::size_t>(open_repeats.back())].line, "repeat without end");
    stack.pop_back();
    // Steps once expanded (saturating).
    std::vector<std::size_t> acc(1, 0);
    std::vector<std::size_t> repeats;  // indices of the open repeats
    for (std::size_t k = 0; k < f.items.size(); ++k) {
      const Item& it = f.items[k];
      switch (it.kind) {
        case ItemKind::line: acc.back() = sat_add(acc.back(), 1, cap()); break;
        case ItemKind::blend_mode: break;
        case ItemKind::call: acc.back() = sat_add(acc.back(), files[static_cast<std::size_t>(it.callee)]->size, cap()); break;
        case ItemKind::repeat: acc.push_back(0); repeats.push_back(k); break;
        case ItemKind::end: {
          const std::size_t body = acc.back();
          acc.pop_back();
          f.items[repeats.back()].body = body;
          repeats.pop_back();
          // it.count: the count of the repeat this end closes
          acc.back() = sat_add(acc.back(), sat_mul(body, static_cast<std::size_t>(it.count), cap()), cap());
          break;
        }
      }
    }
    f.size = acc.back();
    f.sized = true;
    return idx;
  }

  // Phase 2: one step, parsed in execution order.
  bool step(int file, const Item& it) {
    const bool gcode = files[static_cast<std::size_t>(file)]->gcode;
    ProgramStep st;
    st.file = file;
    st.line = it.line;
    const kin::Chain& chain = *ctx.chain;
    std::string text = it.text;
    if (!gcode) {
      auto w = words(text);
      const bool move = fw::ieq(w[0], "movej") || fw::ieq(w[0], "movel");
      std::string rebuilt(w[0]);
      bool blend_given = false;
      for (std::size_t k = 1; k < w.size(); ++k) {
        const std::string_view x = w[k];
        if (x.size() > 6 && fw::ieq(x.substr(0, 6), "blend=")) {
          if (!move) return fail(file, it.line, "blend= is for movej and movel");
          if (blend_given) return fail(file, it.line, "blend given twice");
          double b = 0;
          if (fw::parse_decimal(x.substr(6), b) != fw::Num::ok || !(b >= 0) || b > 1e6)
            return fail(file, it.line, "blend=" + shown(x.substr(6), 20) + ": expected a tolerance >= 0");
          st.blend = b;
          blend_given = true;
          continue;
        }
        if (!x.empty() && x[0] == '@') {
          if (!move || k != 1) return fail(file, it.line, "@" + shown(x.substr(1), 32) + ": a point goes right after movej or movel");
          const std::string name(x.substr(1));
          const PointsData* pts = ctx.points;
          const TeachPoint* p = pts ? find_point(*pts, name) : nullptr;
          if (p == nullptr)
            return fail(file, it.line, "unknown point @" + shown(name, 32) +
                                           (pts ? " (" + std::to_string(pts->points.size()) + " points known)" : " (no points file)"));
          if (p->q.size() != chain.n_joints) return fail(file, it.line, "point @" + name + " has the wrong joint count");
          st.point = static_cast<int>(p - pts->points.data());
          if (fw::ieq(w[0], "movej")) {
            for (int j = 0; j < chain.n_joints; ++j) rebuilt += " " + fmt17(ctx.units.joint_out(chain, j, p->q[j]));
          } else {
            rebuilt += " 0 0 0 0 0 0";  // placeholder: the target is the point's (ProgramStep::point)
          }
          continue;
        }
        rebuilt += " ";
        rebuilt += x;
      }
      if (fw::ieq(w[0], "dwell")) {
        double s = 0;
        if (w.size() != 2 || fw::parse_decimal(w[1], s) != fw::Num::ok || !(s >= 0) || s > 3600)
          return fail(file, it.line, "dwell needs seconds 0..3600 (dwell S)");
        rebuilt = "G4 S" + fmt17(s);  // the console's dwell
      }
      text = rebuilt;
    } else {
      st.blend = gcode_blend;
    }
    const fw::ParseResult r = fw::parse_line(text, chain.n_joints, modal, st.cmd, gcode ? fw::kGcodeUnits : ctx.units);
    if (!r.ok()) return fail(file, it.line, std::string(r.message.data()) + " (" + fw::to_string(r.error) + ")");
    if (interactive_only(st.cmd.cmd))
      return fail(file, it.line, std::string(fw::to_string(st.cmd.cmd)) + " is not allowed in a program (interactive only)");
    if (st.cmd.cmd == fw::Cmd::none && text.empty()) return true;
    if (st.point >= 0 && st.cmd.cmd == fw::Cmd::movel) st.cmd.count = 0;  // the point's target, not numbers
    st.modal = modal;
    st.text = std::move(text);
    if (prog.steps.size() >= ctx.limits.max_steps)
      return fail(file, it.line, "the program expands to more than " + std::to_string(ctx.limits.max_steps) + " steps");
    prog.steps.push_back(std::move(st));
    return true;
  }

  bool expand(int file, int lo, int hi) {
    const ParsedFile& f = *files[static_cast<std::size_t>(file)];
    for (int i = lo; i < hi; ++i) {
      const Item& it = f.items[static_cast<std::size_t>(i)];
      switch (it.kind) {
        case ItemKind::line:
          if (!step(file, it)) return false;
          break;
        case ItemKind::blend_mode:
          gcode_blend = it.value * modal.unit_mm;
          break;
        case ItemKind::call:
          if (files[static_cast<std::size_t>(it.callee)]->size > 0 &&
              !expand(it.callee, 0, static_cast<int>(files[static_cast<std::size_t>(it.callee)]->items.size())))
            return false;
          break;
        case ItemKind::repeat: {
          // A body without steps has the same effect once as N times (nothing, or a modal G61/G64):
          // `repeat 100000` twice around nothing took 10^10 passes (9 s here) before.
          const int passes = it.body == 0 ? std::min(it.count, 1) : it.count;
          for (int k = 0; k < passes; ++k)
            if (!expand(file, i + 1, it.match)) return false;
          i = it.match;
          break;
        }
        case ItemKind::end: break;
      }
    }
    return true;
  }
};

}  // namespace

std::string Program::where(const ProgramStep& s) const {
  return (s.file >= 0 && static_cast<std::size_t>(s.file) < files.size() ? files[static_cast<std::size_t>(s.file)] : "?") + ":" +
         std::to_string(s.line);
}

bool is_gcode_file(std::string_view path) {
  for (const char* e : kGcodeExt) {
    const std::string_view x(e);
    if (path.size() > x.size() && fw::ieq(path.substr(path.size() - x.size()), x)) return true;
  }
  return false;
}

std::string check_program_name(std::string_view name) {
  if (name.empty()) return "empty program name";
  if (name.size() > 63) return "program name '" + shown(name) + "' is longer than 63 characters";
  for (std::size_t i = 0; i < name.size(); ++i) {
    const char c = name[i];
    const bool alnum = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9');
    if (!(alnum || (i > 0 && (c == '_' || c == '-' || c == '.'))))
      return "program name '" + shown(name) + "': letters, digits, '_', '-' and '.' only (no path)";
  }
  return "";
}

std::string find_program(const std::string& dir, const std::string& name) {
  if (!check_program_name(name).empty()) return "";
  const std::string base = dir + "/" + name;
  if (file_exists(base)) return base;
  if (file_exists(base + kNativeExtension)) return base + kNativeExtension;
  for (const char* e : kGcodeExt)
    if (file_exists(base + e)) return base + e;
  return "";
}

std::string load_program(const std::string& path, const ProgramContext& ctx, Program& out) {
  if (ctx.chain == nullptr || ctx.chain->n_joints < 1) return path + ": no robot description to check the program against";
  Program prog;
  Loader L{ctx, prog, {}, {}, {}, {}, 0};
  const int root = L.open(path, -1, 0);
  if (root < 0) return L.err.empty() ? path + ": cannot load" : L.err;
  if (L.files[static_cast<std::size_t>(root)]->size > ctx.limits.max_steps)
    return kin::one_line(path + ": the program expands to more than " + std::to_string(ctx.limits.max_steps) +
                         " steps (repeat counts and calls multiply)");
  if (!L.expand(root, 0, static_cast<int>(L.files[static_cast<std::size_t>(root)]->items.size()))) return L.err;
  out = std::move(prog);
  return "";
}

std::string list_programs(const std::string& dir, std::vector<std::string>& names) {
  names.clear();
  DIR* d = ::opendir(dir.c_str());
  if (d == nullptr) return dir + ": cannot open the programs folder";
  while (const dirent* e = ::readdir(d)) {
    const std::string n = e->d_name;
    if (n.empty() || n[0] == '.') continue;
    const bool native = n.size() > 4 && n.compare(n.size() - 4, 4, kNativeExtension) == 0;
    if (native || is_gcode_file(n)) names.push_back(n);
    if (names.size() >= 10000) break;
  }
  ::closedir(d);
  std::sort(names.begin(), names.end());
  return "";
}

// ---------------------------------------------------------------------------
// What a step is to the program runner (console_program.cpp) and the offline check (armctl)
// ---------------------------------------------------------------------------

StepKind kind_of(const fw::Command& c) {
  if (c.cmd == fw::Cmd::out && c.out_sync) return StepKind::other;
  return kind_of(c.cmd);
}

StepKind kind_of(fw::Cmd c) {
  switch (c) {
    case fw::Cmd::movej:
    case fw::Cmd::movel:
    case fw::Cmd::gmove:
    case fw::Cmd::park:
    case fw::Cmd::dwell: return StepKind::motion;
    case fw::Cmd::tool:
    case fw::Cmd::frame: return StepKind::needs_idle;
    case fw::Cmd::out: return StepKind::needs_idle;  // refined by the caller: M62 / M63 ride with the next move
    case fw::Cmd::wait: return StepKind::wait;
    case fw::Cmd::enable:
    case fw::Cmd::disable:
    case fw::Cmd::home:
    case fw::Cmd::home_zero:
    case fw::Cmd::stop:
    case fw::Cmd::estop:
    case fw::Cmd::reset:
    case fw::Cmd::hold:
    case fw::Cmd::resume:
    case fw::Cmd::jog:
    case fw::Cmd::grbl_jog:
    case fw::Cmd::grbl_unlock:
    case fw::Cmd::grbl_home:
    case fw::Cmd::grbl_check:
    case fw::Cmd::teach:
    case fw::Cmd::point_delete:
    case fw::Cmd::run:
    case fw::Cmd::pause:
    case fw::Cmd::step:
    case fw::Cmd::abort:
    case fw::Cmd::record:
    case fw::Cmd::freedrive_on:
    case fw::Cmd::freedrive_off:
    case fw::Cmd::collision_on:
    case fw::Cmd::collision_off:
    case fw::Cmd::safety_normal:
    case fw::Cmd::safety_reduced:
    case fw::Cmd::safety_stage:
    case fw::Cmd::safety_confirm:
    case fw::Cmd::quit: return StepKind::refused;
    case fw::Cmd::none:
    case fw::Cmd::help:
    case fw::Cmd::safety:
    case fw::Cmd::status:
    case fw::Cmd::fk:
    case fw::Cmd::ik:
    case fw::Cmd::limits:
    case fw::Cmd::stats:
    case fw::Cmd::config:
    case fw::Cmd::position:
    case fw::Cmd::temperature:
    case fw::Cmd::grbl_settings:
    case fw::Cmd::grbl_params:
    case fw::Cmd::grbl_state:
    case fw::Cmd::grbl_info:
    case fw::Cmd::grbl_help:
    case fw::Cmd::points:
    case fw::Cmd::programs:
    case fw::Cmd::freedrive: return StepKind::other;
  }
  return StepKind::refused;
}

bool next_motion_is_line(const Program& p, std::size_t i) {
  for (std::size_t k = i + 1; k < p.steps.size(); ++k) {
    const fw::Cmd c = p.steps[k].cmd.cmd;
    if (c == fw::Cmd::movel || c == fw::Cmd::gmove) return true;
    const StepKind kind = kind_of(p.steps[k].cmd);
    if (kind == StepKind::motion || kind == StepKind::needs_idle) return false;
  }
  return false;
}

}  // namespace servoarm::prog

namespace servoarm::prog {

StepCounts count_steps(const Program& p) {
  StepCounts c;
  c.steps = p.steps.size();
  for (const ProgramStep& st : p.steps) {
    const fw::Cmd k = st.cmd.cmd;
    if (k == fw::Cmd::movej || k == fw::Cmd::park) ++c.joint_moves;
    else if (k == fw::Cmd::movel || k == fw::Cmd::gmove) ++c.line_moves;
    else if (k == fw::Cmd::dwell) ++c.dwells;
  }
  c.moves = c.joint_moves + c.line_moves;
  return c;
}

std::string counts_text(const StepCounts& c) {
  return fw::count_text(static_cast<long long>(c.steps), "step") + ": " + fw::count_text(c.moves, "move") + " (" +
         std::to_string(c.joint_moves) + " joint, " + std::to_string(c.line_moves) + " linear), " +
         fw::count_text(c.dwells, "dwell");
}

}  // namespace servoarm::prog
