// SPDX-License-Identifier: Apache-2.0
// Named tools and user frames, and the frames file (frames.hpp).
#include "servoarm/lang/frames.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "servoarm/lang/number.hpp"
#include "servoarm/kinematics/io/file_input.hpp"
#include "servoarm/kinematics/orientation.hpp"

namespace servoarm::fw {

namespace {

constexpr double kDegRad = 3.14159265358979323846 / 180.0;

bool name_char(char c, bool first) {
  if ((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z')) return true;
  return !first && ((c >= '0' && c <= '9') || c == '_' || c == '-');
}

std::string shown(std::string_view name) {
  std::string s;
  for (char c : name.substr(0, 24)) {
    if (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) >= 0x7f) s += '?';
    else s += c;
  }
  return s + (name.size() > 24 ? "..." : "");
}

std::string num(double v) {
  char b[40];
  std::snprintf(b, sizeof b, "%.17g", v);
  std::string s(b);
  if (s.find_first_of(".eEn") == std::string::npos) s += ".0";  // a TOML float, not an integer
  return s;
}

struct Reader {
  std::string origin;
  std::string err;
  bool fail(const toml::node& at, const std::string& key, const std::string& why) {
    if (err.empty()) err = kin::source_text(at.source(), origin) + ": " + key + ": " + why;
    return false;
  }
  bool number(const toml::node& v, const std::string& key, double& out) {
    if (const auto* i = v.as_integer()) out = static_cast<double>(i->get());
    else if (const auto* f = v.as_floating_point()) out = f->get();
    else return fail(v, key, std::string("expected a number (got ") + kin::type_name(v) + ")");
    if (!std::isfinite(out)) return fail(v, key, "must be a finite number (got " + kin::value_text(v) + ")");
    return true;
  }
  bool vec3(const toml::node& v, const std::string& key, double out[3]) {
    const toml::array* a = v.as_array();
    if (a == nullptr || a->size() != 3) return fail(v, key, "expected an array of 3 numbers (got " + kin::value_text(v) + ")");
    for (std::size_t i = 0; i < 3; ++i)
      if (!number(*a->get(i), key + "[" + std::to_string(i) + "]", out[i])) return false;
    return true;
  }
  /// One [tool.NAME] / [frame.NAME] table.
  bool entry(const toml::node& node, const std::string& label, bool is_tool, NamedPose& out) {
    const toml::table* t = node.as_table();
    if (t == nullptr) return fail(node, label, std::string("expected a table (got ") + kin::type_name(node) + ")");
    double xyz[3] = {0, 0, 0}, rpy[3] = {0, 0, 0}, com[3] = {0, 0, 0}, mass = 0, radius = -1;
    bool has_xyz = false, has_rpy = false, has_mass = false, has_com = false;
    for (const auto& [k, v] : *t) {
      const std::string key = label + "." + std::string(k.str());
      if (k.str() == "xyz") {
        if (!vec3(v, key, xyz)) return false;
        has_xyz = true;
      } else if (k.str() == "rpy") {
        if (!vec3(v, key, rpy)) return false;
        has_rpy = true;
      } else if (is_tool && k.str() == "mass") {
        if (!number(v, key, mass)) return false;
        has_mass = true;
      } else if (is_tool && k.str() == "com") {
        if (!vec3(v, key, com)) return false;
        has_com = true;
      } else if (is_tool && k.str() == "radius") {
        if (!number(v, key, radius)) return false;
        if (const std::string why = check_tool_radius(radius); !why.empty()) return fail(v, key, why);
      } else {
        return fail(v, key, is_tool ? "unknown key (xyz, rpy, mass, com, radius)" : "unknown key (xyz, rpy)");
      }
    }
    if (!has_xyz || !has_rpy) return fail(node, label, "needs both xyz (m) and rpy (deg)");
    if (has_com && !has_mass) return fail(node, label, "com without mass");
    const double rpy_rad[3] = {rpy[0] * kDegRad, rpy[1] * kDegRad, rpy[2] * kDegRad};
    const std::string why = check_frame_values(xyz, rpy_rad, has_mass, mass, com);
    if (!why.empty()) return fail(node, label, why);
    out.pose = kin::Pose::Identity();
    out.pose.translation() = Eigen::Vector3d(xyz[0], xyz[1], xyz[2]);
    out.pose.linear() = kin::rotation_from_rpy(rpy_rad[0], rpy_rad[1], rpy_rad[2]);
    out.has_payload = has_mass;
    out.mass = mass;
    out.com = Eigen::Vector3d(com[0], com[1], com[2]);
    out.radius = radius;
    return true;
  }
};

void write_entry(std::string& o, const char* kind, const NamedPose& e) {
  const Eigen::Vector3d rpy = kin::rpy_from_rotation(e.pose.linear()) / kDegRad;
  const Eigen::Vector3d& p = e.pose.translation();
  o += std::string("\n[") + kind + "." + e.name + "]\n";
  o += "xyz = [" + num(p.x()) + ", " + num(p.y()) + ", " + num(p.z()) + "]\n";
  o += "rpy = [" + num(rpy.x()) + ", " + num(rpy.y()) + ", " + num(rpy.z()) + "]\n";
  if (e.has_payload) {
    o += "mass = " + num(e.mass) + "\n";
    o += "com = [" + num(e.com.x()) + ", " + num(e.com.y()) + ", " + num(e.com.z()) + "]\n";
  }
  if (e.radius >= 0) o += "radius = " + num(e.radius) + "\n";
}

}  // namespace

std::string check_frame_name(std::string_view name, bool is_tool) {
  const char* what = is_tool ? "tool" : "frame";
  if (name.empty()) return std::string(what) + ": empty name";
  if (name.size() >= kMaxFrameName)
    return std::string(what) + " name '" + shown(name) + "' is longer than " + std::to_string(kMaxFrameName - 1) + " characters";
  for (std::size_t i = 0; i < name.size(); ++i)
    if (!name_char(name[i], i == 0))
      return std::string(what) + " name '" + shown(name) +
             "': letters, digits, '_' and '-' only, starting with a letter";
  if (ieq(name, "delete")) return std::string(what) + " name 'delete' is reserved (tool delete NAME)";
  if (is_tool && ieq(name, "tool0")) return "tool0 is the flange: it cannot be redefined";
  if (!is_tool && ieq(name, "base")) return "base is the base frame: it cannot be redefined";
  return "";
}

std::string check_tool_radius(double radius_m) {
  if (!std::isfinite(radius_m) || radius_m < 0 || radius_m > kMaxToolRadiusM)
    return "radius = " + num(radius_m * 1000.0) + " mm must be within [0, " + num(kMaxToolRadiusM * 1000.0) + "] mm";
  return "";
}

std::string check_frame_values(const double xyz[3], const double rpy_rad[3], bool has_payload, double mass,
                               const double com[3]) {
  static const char* const kAx[] = {"x", "y", "z", "rx", "ry", "rz"};
  for (int k = 0; k < 3; ++k) {
    if (!std::isfinite(xyz[k])) return std::string(kAx[k]) + " is not finite";
    if (std::fabs(xyz[k]) > kMaxOffsetM)
      return std::string(kAx[k]) + " = " + num(xyz[k]) + " m is beyond +-" + num(kMaxOffsetM) + " m";
    if (!std::isfinite(rpy_rad[k])) return std::string(kAx[k + 3]) + " is not finite";
    if (std::fabs(rpy_rad[k]) > 360.0 * kDegRad + 1e-9)
      return std::string(kAx[k + 3]) + " = " + num(rpy_rad[k] / kDegRad) + " deg is beyond +-360 deg";
  }
  if (has_payload) {
    if (!std::isfinite(mass) || mass < 0 || mass > kMaxPayloadKg)
      return "mass = " + num(mass) + " kg outside [0, " + num(kMaxPayloadKg) + "] kg";
    for (int k = 0; k < 3; ++k)
      if (!std::isfinite(com[k]) || std::fabs(com[k]) > kMaxOffsetM)
        return std::string("com ") + kAx[k] + " = " + num(com[k]) + " m is not finite or beyond +-" + num(kMaxOffsetM) + " m";
  }
  return "";
}

std::string load_frames_file(const std::string& path, FramesData& out, bool* missing) {
  if (missing != nullptr) *missing = false;
  std::string text;
  std::string err = kin::read_text_file(path, text);
  if (!err.empty()) {
    if (::access(path.c_str(), F_OK) != 0 && errno == ENOENT) {
      if (missing != nullptr) *missing = true;
      out = FramesData{};
      return "";
    }
    return err;
  }
  kin::TomlDocument doc = kin::parse_toml(text, path);
  if (!doc.error.empty()) return doc.error;
  const toml::table& top = doc.table;
  Reader r{path, ""};
  FramesData d;
  const toml::node* fmt = top.get("format");
  if (fmt == nullptr || fmt->value<std::string_view>() != std::string_view(kFramesFormat))
    return path + ": not a servoarm frames file (needs format = \"" + kFramesFormat + "\" first); refusing to read or overwrite it";
  for (const auto& [k, v] : top) {
    const std::string key(k.str());
    if (key == "format") continue;
    if (key == "active_tool" || key == "active_frame") {
      const auto s = v.value<std::string>();
      if (!s) {
        r.fail(v, key, std::string("expected a string (got ") + kin::type_name(v) + ")");
        break;
      }
      (key == "active_tool" ? d.active_tool : d.active_frame) = *s;
      continue;
    }
    if (key != "tool" && key != "frame") {
      r.fail(v, key, "unknown key (format, active_tool, active_frame, [tool.NAME], [frame.NAME])");
      break;
    }
    const bool is_tool = key == "tool";
    const toml::table* t = v.as_table();
    if (t == nullptr) {
      r.fail(v, key, "expected tables [" + key + ".NAME]");
      break;
    }
    for (const auto& [name, e] : *t) {
      const std::string label = key + "." + std::string(name.str());
      const std::string why = check_frame_name(name.str(), is_tool);
      if (!why.empty()) {
        r.fail(e, label, why);
        break;
      }
      std::vector<NamedPose>& list = is_tool ? d.tools : d.frames;
      if (list.size() + 1 >= (is_tool ? kMaxTools : kMaxFrames)) {
        r.fail(e, label, "more than " + std::to_string((is_tool ? kMaxTools : kMaxFrames) - 1) + " " + key + "s");
        break;
      }
      NamedPose np;
      np.name = std::string(name.str());
      if (!r.entry(e, label, is_tool, np)) break;
      list.push_back(np);
    }
    if (!r.err.empty()) break;
  }
  if (!r.err.empty()) return kin::one_line(r.err);
  auto known = [](const std::vector<NamedPose>& l, const std::string& n) {
    for (const NamedPose& e : l)
      if (e.name == n) return true;
    return false;
  };
  if (d.active_tool != "tool0" && !known(d.tools, d.active_tool))
    return kin::one_line(path + ": active_tool = \"" + shown(d.active_tool) + "\" is not a [tool.NAME] of the file");
  if (d.active_frame != "base" && !known(d.frames, d.active_frame))
    return kin::one_line(path + ": active_frame = \"" + shown(d.active_frame) + "\" is not a [frame.NAME] of the file");
  out = std::move(d);
  return "";
}

std::string frames_to_toml(const FramesData& d) {
  std::string o;
  o += "# servoarm tools and user frames, written by armfw (the tool and frame commands, G10 L2).\n";
  o += "# Lengths in m, angles in degrees: roll-pitch-yaw R = Rz(rz) Ry(ry) Rx(rx). Do not edit while armfw runs.\n";
  o += std::string("format = \"") + kFramesFormat + "\"\n";
  o += "active_tool = \"" + d.active_tool + "\"\n";
  o += "active_frame = \"" + d.active_frame + "\"\n";
  for (const NamedPose& t : d.tools) write_entry(o, "tool", t);
  for (const NamedPose& f : d.frames) write_entry(o, "frame", f);
  return o;
}

std::string check_writable_file(const std::string& path) {
  struct stat st{};
  if (::stat(path.c_str(), &st) != 0) {
    if (errno == ENOENT) return "";
    return path + ": " + std::strerror(errno) + "; not overwritten";
  }
  if (!S_ISREG(st.st_mode)) return path + ": not a regular file; not overwritten";
  // No write bit at all is read-only even for root (who passes access(W_OK) regardless).
  if ((st.st_mode & (S_IWUSR | S_IWGRP | S_IWOTH)) == 0 || ::access(path.c_str(), W_OK) != 0)
    return path + ": the file is read-only (no write permission); not overwritten";
  return "";
}

std::string save_frames_file(const std::string& path, const FramesData& d) {
  // What is there must be ours: a file that does not load as a frames file (another
  // program's, put in its place while armfw runs) is kept, and so is a read-only one.
  if (std::string why = check_writable_file(path); !why.empty()) return why;
  if (::access(path.c_str(), F_OK) == 0) {
    FramesData old;
    if (const std::string err = load_frames_file(path, old); !err.empty())
      return kin::one_line(err.find("overwrite") == std::string::npos ? err + " (not overwritten)" : err);
  }
  return kin::write_text_file_atomic(path, frames_to_toml(d));
}

}  // namespace servoarm::fw
