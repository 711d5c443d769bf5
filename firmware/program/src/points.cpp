// SPDX-License-Identifier: Apache-2.0
// Teach points and the points file (points.hpp).
#include "servoarm/program/points.hpp"

#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>

#include "servoarm/lang/frames.hpp"
#include "servoarm/lang/number.hpp"
#include "servoarm/kinematics/io/file_input.hpp"
#include "servoarm/kinematics/orientation.hpp"

namespace servoarm::prog {

namespace {

constexpr double kDegRad = 3.14159265358979323846 / 180.0;
constexpr double kMaxJointValue = 1000.0;  // rad or m: beyond any joint (a corrupt number)

std::string shown(std::string_view name) {
  std::string s;
  for (char c : name.substr(0, 32)) s += (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) >= 0x7f) ? '?' : c;
  return s + (name.size() > 32 ? "..." : "");
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
  bool numbers(const toml::node& v, const std::string& key, std::size_t n, double* out) {
    const toml::array* a = v.as_array();
    if (a == nullptr || a->size() != n)
      return fail(v, key, "expected an array of " + std::to_string(n) + " numbers (got " + kin::value_text(v) + ")");
    for (std::size_t i = 0; i < n; ++i)
      if (!number(*a->get(i), key + "[" + std::to_string(i) + "]", out[i])) return false;
    return true;
  }
  bool text(const toml::node& v, const std::string& key, std::string& out) {
    const auto s = v.value<std::string>();
    if (!s) return fail(v, key, std::string("expected a string (got ") + kin::type_name(v) + ")");
    out = *s;
    return true;
  }
  bool entry(const toml::node& node, const std::string& label, int n, TeachPoint& p) {
    const toml::table* t = node.as_table();
    if (t == nullptr) return fail(node, label, std::string("expected a table (got ") + kin::type_name(node) + ")");
    double q[kin::kMaxJoints] = {}, xyz[3] = {}, rpy[3] = {};
    bool has_q = false, has_xyz = false, has_rpy = false;
    for (const auto& [k, v] : *t) {
      const std::string key = label + "." + std::string(k.str());
      if (k.str() == "joints") {
        if (!numbers(v, key, static_cast<std::size_t>(n), q)) return false;
        for (int j = 0; j < n; ++j)
          if (std::fabs(q[j]) > kMaxJointValue) return fail(v, key, "joint " + std::to_string(j + 1) + " = " + num(q[j]) + " is not a joint value");
        has_q = true;
      } else if (k.str() == "xyz") {
        if (!numbers(v, key, 3, xyz)) return false;
        has_xyz = true;
      } else if (k.str() == "rpy") {
        if (!numbers(v, key, 3, rpy)) return false;
        has_rpy = true;
      } else if (k.str() == "tool") {
        if (!text(v, key, p.tool)) return false;
        if (p.tool != "tool0") {
          const std::string why = fw::check_frame_name(p.tool, true);
          if (!why.empty()) return fail(v, key, why);
        }
      } else if (k.str() == "frame") {
        if (!text(v, key, p.frame)) return false;
        if (p.frame != "base") {
          const std::string why = fw::check_frame_name(p.frame, false);
          if (!why.empty()) return fail(v, key, why);
        }
      } else {
        return fail(v, key, "unknown key (joints, xyz, rpy, tool, frame)");
      }
    }
    if (!has_q) return fail(node, label, "needs joints (" + std::to_string(n) + " values, rad / m)");
    if (!has_xyz || !has_rpy) return fail(node, label, "needs xyz (m) and rpy (deg)");
    const double rpy_rad[3] = {rpy[0] * kDegRad, rpy[1] * kDegRad, rpy[2] * kDegRad};
    const std::string why = fw::check_frame_values(xyz, rpy_rad, false, 0.0, xyz);
    if (!why.empty()) return fail(node, label, why);
    p.q = kin::JointVector::Zero(n);
    for (int j = 0; j < n; ++j) p.q[j] = q[j];
    p.pose = kin::Pose::Identity();
    p.pose.translation() = Eigen::Vector3d(xyz[0], xyz[1], xyz[2]);
    p.pose.linear() = kin::rotation_from_rpy(rpy_rad[0], rpy_rad[1], rpy_rad[2]);
    return true;
  }
};

std::string check_values(const TeachPoint& p) {
  if (p.q.size() < 1 || p.q.size() > kin::kMaxJoints) return "point " + shown(p.name) + ": wrong joint count";
  for (int j = 0; j < p.q.size(); ++j)
    if (!std::isfinite(p.q[j]) || std::fabs(p.q[j]) > kMaxJointValue)
      return "point " + shown(p.name) + ": joint " + std::to_string(j + 1) + " is not a finite joint value";
  if (!p.pose.matrix().allFinite()) return "point " + shown(p.name) + ": the tool pose is not finite";
  return "";
}

}  // namespace

std::string check_point_name(std::string_view name) {
  if (name.empty()) return "point: empty name";
  if (name.size() >= kMaxPointName)
    return "point name '" + shown(name) + "' is longer than " + std::to_string(kMaxPointName - 1) + " characters";
  for (std::size_t i = 0; i < name.size(); ++i) {
    const char c = name[i];
    const bool letter = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z');
    if (!(letter || (i > 0 && ((c >= '0' && c <= '9') || c == '_' || c == '-'))))
      return "point name '" + shown(name) + "': letters, digits, '_' and '-' only, starting with a letter";
  }
  if (fw::ieq(name, "delete")) return "point name 'delete' is reserved (point delete NAME)";
  return "";
}

const TeachPoint* find_point(const PointsData& d, std::string_view name) {
  for (const TeachPoint& p : d.points)
    if (p.name == name) return &p;
  return nullptr;
}

std::string put_point(PointsData& d, TeachPoint p) {
  if (std::string why = check_point_name(p.name); !why.empty()) return why;
  if (std::string why = check_values(p); !why.empty()) return why;
  if (!d.points.empty() && d.points.front().q.size() != p.q.size()) return "point " + p.name + ": joint count differs from the file's";
  for (TeachPoint& e : d.points)
    if (e.name == p.name) {
      e = std::move(p);
      return "";
    }
  if (d.points.size() >= kMaxPoints) return "more than " + std::to_string(kMaxPoints) + " points: delete some first";
  d.points.push_back(std::move(p));
  return "";
}

bool delete_point(PointsData& d, std::string_view name) {
  for (auto it = d.points.begin(); it != d.points.end(); ++it)
    if (it->name == name) {
      d.points.erase(it);
      return true;
    }
  return false;
}

std::string load_points_file(const std::string& path, int n_joints, PointsData& out, bool* missing) {
  if (missing != nullptr) *missing = false;
  if (n_joints < 1 || n_joints > kin::kMaxJoints) return path + ": bad joint count " + std::to_string(n_joints);
  std::string text;
  std::string err = kin::read_text_file(path, text, kMaxPointsFileBytes);
  if (!err.empty()) {
    if (::access(path.c_str(), F_OK) != 0 && errno == ENOENT) {
      if (missing != nullptr) *missing = true;
      out = PointsData{};
      return "";
    }
    return kin::one_line(err);
  }
  kin::TomlDocument doc = kin::parse_toml(text, path, kMaxPointsFileBytes);
  if (!doc.error.empty()) return doc.error;
  const toml::table& top = doc.table;
  const toml::node* fmt = top.get("format");
  if (fmt == nullptr || fmt->value<std::string_view>() != std::string_view(kPointsFormat))
    return path + ": not a servoarm points file (needs format = \"" + kPointsFormat + "\"); refusing to read or overwrite it";
  Reader r{path, ""};
  PointsData d;
  for (const auto& [k, v] : top) {
    const std::string key(k.str());
    if (key == "format") continue;
    if (key != "point") {
      r.fail(v, key, "unknown key (format, [point.NAME])");
      break;
    }
    const toml::table* t = v.as_table();
    if (t == nullptr) {
      r.fail(v, key, "expected tables [point.NAME]");
      break;
    }
    for (const auto& [name, e] : *t) {
      const std::string label = "point." + std::string(name.str());
      if (const std::string why = check_point_name(name.str()); !why.empty()) {
        r.fail(e, label, why);
        break;
      }
      if (d.points.size() >= kMaxPoints) {
        r.fail(e, label, "more than " + std::to_string(kMaxPoints) + " points");
        break;
      }
      TeachPoint p;
      p.name = std::string(name.str());
      if (!r.entry(e, label, n_joints, p)) break;
      d.points.push_back(std::move(p));
    }
    if (!r.err.empty()) break;
  }
  if (!r.err.empty()) return kin::one_line(r.err);
  out = std::move(d);
  return "";
}

std::string points_to_toml(const PointsData& d) {
  std::string o;
  o += "# servoarm teach points, written by armfw (teach NAME, point delete NAME). Do not edit while armfw runs.\n";
  o += "# joints in rad (prismatic: m); xyz in m and rpy in deg (R = Rz(rz) Ry(ry) Rx(rx)): the tool point in the base.\n";
  o += std::string("format = \"") + kPointsFormat + "\"\n";
  for (const TeachPoint& p : d.points) {
    o += "\n[point." + p.name + "]\njoints = [";
    for (int j = 0; j < p.q.size(); ++j) o += (j ? ", " : "") + num(p.q[j]);
    const Eigen::Vector3d rpy = kin::rpy_from_rotation(p.pose.linear()) / kDegRad;
    const Eigen::Vector3d& x = p.pose.translation();
    o += "]\nxyz = [" + num(x.x()) + ", " + num(x.y()) + ", " + num(x.z()) + "]\n";
    o += "rpy = [" + num(rpy.x()) + ", " + num(rpy.y()) + ", " + num(rpy.z()) + "]\n";
    o += "tool = \"" + p.tool + "\"\nframe = \"" + p.frame + "\"\n";
  }
  return o;
}

std::string save_points_file(const std::string& path, const PointsData& d) {
  int n = d.points.empty() ? 0 : static_cast<int>(d.points.front().q.size());
  for (const TeachPoint& p : d.points) {
    if (std::string why = check_point_name(p.name); !why.empty()) return path + ": " + why + "; nothing written";
    if (std::string why = check_values(p); !why.empty()) return path + ": " + why + "; nothing written";
    if (p.q.size() != n) return path + ": points with different joint counts; nothing written";
  }
  if (::access(path.c_str(), F_OK) == 0) {  // what is there must be ours, and writable
    if (std::string why = fw::check_writable_file(path); !why.empty()) return kin::one_line(why);
    PointsData old;
    const std::string err = load_points_file(path, n > 0 ? n : 1, old);
    // An empty new set: any joint count of the old file is fine, only its format matters.
    if (!err.empty() && !(n == 0 && err.find("joints") != std::string::npos))
      return kin::one_line(err + " (not overwritten)");
  }
  return kin::write_text_file_atomic(path, points_to_toml(d));
}

double point_pose_mismatch(const kin::Chain& chain, const kin::Pose& tool, const TeachPoint& p) {
  if (p.q.size() != chain.n_joints) return INFINITY;
  kin::Pose f;
  if (kin::forward(chain, p.q, f) != kin::Status::ok) return INFINITY;
  return ((f * tool).translation() - p.pose.translation()).norm();
}

}  // namespace servoarm::prog
