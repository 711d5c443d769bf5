// Robot description files (TOML, read with toml11). Set-up code: allocates,
// and toml11 throws; every exception is caught here and becomes a one-line
// error that names the file, the joint (1-based, in chain order) and the key.
#include "servoarm/kinematics/description.hpp"

#include <Eigen/Eigenvalues>

#include "servoarm/kinematics/dynamics.hpp"

#include <cmath>
#include <fstream>
#include <set>
#include <sstream>

#include <toml.hpp>

namespace servoarm::kin {
namespace {

struct LoadError {
  std::string msg;
};

class Reader {
 public:
  explicit Reader(std::string origin) : origin_(std::move(origin)) {}

  [[noreturn]] void fail(const std::string& where, const std::string& what) const {
    throw LoadError{origin_ + ": " + (where.empty() ? "" : where + ": ") + what};
  }

  static const char* type_name(const toml::value& v) {
    switch (v.type()) {
      case toml::value_t::empty: return "nothing";
      case toml::value_t::boolean: return "a boolean";
      case toml::value_t::integer: return "an integer";
      case toml::value_t::floating: return "a number";
      case toml::value_t::string: return "a string";
      case toml::value_t::offset_datetime:
      case toml::value_t::local_datetime:
      case toml::value_t::local_date:
      case toml::value_t::local_time: return "a date/time";
      case toml::value_t::array: return "an array";
      case toml::value_t::table: return "a table";
    }
    return "an unknown value";
  }

  double number(const toml::value& v, const std::string& where, const std::string& key) const {
    double x = 0;
    if (v.is_integer())
      x = static_cast<double>(v.as_integer());
    else if (v.is_floating())
      x = v.as_floating();
    else
      fail(where, "key '" + key + "': expected a number, got " + type_name(v));
    if (!std::isfinite(x)) fail(where, "key '" + key + "': value is not finite");
    return x;
  }

  std::string string(const toml::value& v, const std::string& where, const std::string& key) const {
    if (!v.is_string()) fail(where, "key '" + key + "': expected a string, got " + type_name(v));
    return v.as_string().str;
  }

  void numbers(const toml::value& v, const std::string& where, const std::string& key, double* out,
               std::size_t n) const {
    if (!v.is_array()) fail(where, "key '" + key + "': expected an array of " + std::to_string(n) + " numbers, got " + type_name(v));
    const auto& arr = v.as_array();
    if (arr.size() != n)
      fail(where, "key '" + key + "': expected " + std::to_string(n) + " numbers, got " + std::to_string(arr.size()));
    for (std::size_t i = 0; i < n; ++i) out[i] = number(arr[i], where, key);
  }

  void only_keys(const toml::value& table, const std::set<std::string>& allowed, const std::string& where) const {
    for (const auto& [k, v] : table.as_table()) {
      (void)v;
      if (!allowed.count(k)) {
        std::string list;
        for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
        fail(where, "key '" + k + "' is not known (expected one of: " + list + ")");
      }
    }
  }

 private:
  std::string origin_;
};

Pose read_transform(const Reader& rd, const toml::value& t, const std::string& where, double lu, double au) {
  if (!t.is_table()) rd.fail("", "key '" + where + "': expected a table with xyz and rpy");
  rd.only_keys(t, {"xyz", "rpy"}, "[" + where + "]");
  double xyz[3] = {0, 0, 0}, rpy[3] = {0, 0, 0};
  if (t.contains("xyz")) rd.numbers(t.at("xyz"), "[" + where + "]", "xyz", xyz, 3);
  if (t.contains("rpy")) rd.numbers(t.at("rpy"), "[" + where + "]", "rpy", rpy, 3);
  Pose T = Pose::Identity();
  T.translation() = Eigen::Vector3d(xyz[0], xyz[1], xyz[2]) * lu;
  T.linear() = (Eigen::AngleAxisd(rpy[2] * au, Eigen::Vector3d::UnitZ()) *
                Eigen::AngleAxisd(rpy[1] * au, Eigen::Vector3d::UnitY()) *
                Eigen::AngleAxisd(rpy[0] * au, Eigen::Vector3d::UnitX()))
                   .toRotationMatrix();
  return T;
}

// Inertial keys of one row (docs/dynamics.md): mass [kg], com [length unit, DH frame of
// the row], inertia [kg m^2, about the COM, DH frame: ixx iyy izz ixy ixz iyz],
// rotor_inertia [kg m^2, motor side], gear_ratio [motor turns per joint turn],
// friction = [viscous, coulomb] [N m s/rad, N m; N s/m, N for a prismatic joint].
// A fixed row may carry mass, com and inertia (a body rigidly attached to the one
// before it); rotor_inertia, gear_ratio and friction are refused there.
void read_inertial(const Reader& rd, const toml::value& j, const std::string& where, Chain& chain, double L) {
  const bool any = j.contains("mass") || j.contains("com") || j.contains("inertia") ||
                   j.contains("rotor_inertia") || j.contains("gear_ratio") || j.contains("friction");
  if (!any) return;
  LinkInertial li;
  if (j.contains("mass")) {
    li.mass = rd.number(j.at("mass"), where, "mass");
    if (li.mass < 0) rd.fail(where, "key 'mass': must not be negative (kg)");
  }
  if (j.contains("com")) {
    if (!j.contains("mass")) rd.fail(where, "key 'com': needs 'mass'");
    double c[3];
    rd.numbers(j.at("com"), where, "com", c, 3);
    for (int k = 0; k < 3; ++k) li.com[static_cast<std::size_t>(k)] = c[k] * L;
    if (std::sqrt(li.com[0] * li.com[0] + li.com[1] * li.com[1] + li.com[2] * li.com[2]) > 10.0)
      rd.fail(where, "key 'com': more than 10 m from the frame origin (wrong length unit?)");
  }
  if (j.contains("inertia")) {
    double I[6];
    rd.numbers(j.at("inertia"), where, "inertia", I, 6);
    for (int k = 0; k < 6; ++k) li.inertia[static_cast<std::size_t>(k)] = I[k];
    Eigen::Matrix3d M;
    M << I[0], I[3], I[4], I[3], I[1], I[5], I[4], I[5], I[2];
    const Eigen::Vector3d e = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(M, Eigen::EigenvaluesOnly).eigenvalues();
    const double tol = 1e-9 * std::max(1e-12, e.cwiseAbs().maxCoeff());
    if (e.minCoeff() < -tol)
      rd.fail(where, "key 'inertia': not positive semi-definite (kg m^2 about the COM: ixx iyy izz ixy ixz iyz)");
    if (e[0] + e[1] < e[2] - tol)
      rd.fail(where, "key 'inertia': principal moments violate the triangle inequality (I1 + I2 >= I3)");
  }
  if (j.contains("rotor_inertia")) {
    li.rotor_inertia = rd.number(j.at("rotor_inertia"), where, "rotor_inertia");
    if (li.rotor_inertia < 0) rd.fail(where, "key 'rotor_inertia': must not be negative (kg m^2)");
  }
  if (j.contains("gear_ratio")) {
    li.gear_ratio = rd.number(j.at("gear_ratio"), where, "gear_ratio");
    if (li.gear_ratio == 0) rd.fail(where, "key 'gear_ratio': must not be 0");
  }
  if (j.contains("friction")) {
    double f[2];
    rd.numbers(j.at("friction"), where, "friction", f, 2);
    if (f[0] < 0 || f[1] < 0) rd.fail(where, "key 'friction': [viscous, coulomb] must not be negative");
    li.viscous = f[0];
    li.coulomb = f[1];
  }
  if (set_inertial(chain, chain.n_rows - 1, li) != Status::ok) rd.fail(where, "inertial data rejected");
}

Chain parse(const toml::value& root, const Reader& rd) {
  if (!root.is_table()) rd.fail("", "the file is not a TOML table");
  rd.only_keys(root, {"name", "convention", "length_unit", "angle_unit", "joint", "tool", "base", "summary", "gravity"}, "");
  auto need = [&](const char* key) -> const toml::value& {
    if (!root.contains(key)) rd.fail("", std::string("key '") + key + "' is missing");
    return root.at(key);
  };
  Chain chain;
  const std::string name = rd.string(need("name"), "", "name");
  if (name.empty()) rd.fail("", "key 'name': must not be empty");
  if (name.size() >= chain.name.size()) rd.fail("", "key 'name': longer than " + std::to_string(chain.name.size() - 1) + " characters");
  set_name(chain, name.c_str());

  const std::string conv = rd.string(need("convention"), "", "convention");
  if (conv == "standard")
    chain.convention = Convention::standard;
  else if (conv == "modified")
    chain.convention = Convention::modified;
  else
    rd.fail("", "key 'convention': expected \"standard\" or \"modified\", got \"" + conv + "\"");

  const std::string lu = rd.string(need("length_unit"), "", "length_unit");
  if (lu == "mm")
    chain.length_unit = 1e-3;
  else if (lu == "m")
    chain.length_unit = 1.0;
  else
    rd.fail("", "key 'length_unit': expected \"mm\" or \"m\", got \"" + lu + "\"");
  const std::string au = rd.string(need("angle_unit"), "", "angle_unit");
  if (au == "deg")
    chain.angle_unit = M_PI / 180.0;
  else if (au == "rad")
    chain.angle_unit = 1.0;
  else
    rd.fail("", "key 'angle_unit': expected \"deg\" or \"rad\", got \"" + au + "\"");
  const double L = chain.length_unit, A = chain.angle_unit;

  const toml::value& joints = need("joint");
  if (!joints.is_array()) rd.fail("", "key 'joint': expected an array of [[joint]] tables");
  const auto& arr = joints.as_array();
  if (arr.empty()) rd.fail("", "key 'joint': the chain has no rows");
  int njoints = 0;
  for (std::size_t i = 0; i < arr.size(); ++i) {
    const std::string where = "joint " + std::to_string(i + 1);
    const toml::value& j = arr[i];
    if (!j.is_table()) rd.fail(where, "expected a table");
    rd.only_keys(j, {"type", "theta", "d", "a", "alpha", "direction", "limits", "max_velocity", "max_acceleration", "max_jerk", "name",
                    "mass", "com", "inertia", "rotor_inertia", "gear_ratio", "friction"}, where);
    if (!j.contains("type")) rd.fail(where, "key 'type' is missing (revolute, prismatic or fixed)");
    const std::string type = rd.string(j.at("type"), where, "type");
    DhRow row;
    if (type == "revolute")
      row.type = JointType::revolute;
    else if (type == "prismatic")
      row.type = JointType::prismatic;
    else if (type == "fixed")
      row.type = JointType::fixed;
    else
      rd.fail(where, "key 'type': expected \"revolute\", \"prismatic\" or \"fixed\", got \"" + type + "\"");
    const bool joint = row.type != JointType::fixed;
    if (joint && ++njoints > kMaxJoints)
      rd.fail(where, "more than " + std::to_string(kMaxJoints) + " joints (the compile-time capacity)");
    if (static_cast<int>(i) >= kMaxRows)
      rd.fail(where, "more than " + std::to_string(kMaxRows) + " rows (the compile-time capacity)");
    if (j.contains("theta")) row.theta = rd.number(j.at("theta"), where, "theta") * A;
    if (j.contains("d")) row.d = rd.number(j.at("d"), where, "d") * L;
    if (j.contains("a")) row.a = rd.number(j.at("a"), where, "a") * L;
    if (j.contains("alpha")) row.alpha = rd.number(j.at("alpha"), where, "alpha") * A;
    const double ju = row.type == JointType::prismatic ? L : A;  // joint unit
    for (const char* k : {"direction", "limits", "max_velocity", "max_acceleration", "max_jerk", "rotor_inertia",
                          "gear_ratio", "friction"})
      if (!joint && j.contains(k)) rd.fail(where, std::string("key '") + k + "' does not apply to a fixed row");
    if (j.contains("direction")) {
      const double dir = rd.number(j.at("direction"), where, "direction");
      if (dir != 1.0 && dir != -1.0) rd.fail(where, "key 'direction': expected 1 or -1");
      row.direction = dir;
    }
    if (j.contains("limits")) {
      double lim[2];
      rd.numbers(j.at("limits"), where, "limits", lim, 2);
      if (!(lim[0] < lim[1]))
        rd.fail(where, "key 'limits': lower limit must be below upper limit");
      row.lower = lim[0] * ju;
      row.upper = lim[1] * ju;
    }
    if (joint) {
      // Defaults: a moderate industrial arm (documented in docs/kinematics.md).
      const bool rev = row.type == JointType::revolute;
      row.dynamics.max_velocity = rev ? M_PI : 0.5;
      row.dynamics.max_acceleration = rev ? 4 * M_PI : 2.0;
      row.dynamics.max_jerk = rev ? 40 * M_PI : 20.0;
      const char* keys[3] = {"max_velocity", "max_acceleration", "max_jerk"};
      double* dst[3] = {&row.dynamics.max_velocity, &row.dynamics.max_acceleration, &row.dynamics.max_jerk};
      for (int k = 0; k < 3; ++k) {
        if (!j.contains(keys[k])) continue;
        const double v = rd.number(j.at(keys[k]), where, keys[k]);
        if (!(v > 0)) rd.fail(where, std::string("key '") + keys[k] + "': must be positive");
        *dst[k] = v * ju;
      }
    }
    if (add_row(chain, row) != Status::ok) rd.fail(where, "row rejected (capacity or bad value)");
    read_inertial(rd, j, where, chain, L);
  }
  if (chain.n_joints == 0) rd.fail("", "the chain has no joints (only fixed rows)");
  if (root.contains("tool")) set_tool(chain, read_transform(rd, root.at("tool"), "tool", L, A));
  if (root.contains("base")) chain.base = read_transform(rd, root.at("base"), "base", L, A);
  if (root.contains("summary")) (void)rd.string(root.at("summary"), "", "summary");
  if (root.contains("gravity")) {
    double g[3];
    rd.numbers(root.at("gravity"), "", "gravity", g, 3);
    if (!chain.has_inertial) rd.fail("", "key 'gravity': no joint has inertial data (mass, inertia)");
    if (std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]) > 100)
      rd.fail("", "key 'gravity': more than 100 m/s^2");
    chain.gravity = {g[0], g[1], g[2]};
  }
  return chain;
}

std::string first_line(const std::string& s) {
  std::string out;
  for (char c : s) {
    if (c == '\n') {
      if (!out.empty() && out.back() != ' ') out += ' ';
      continue;
    }
    out += c;
  }
  // collapse runs of spaces
  std::string r;
  for (char c : out)
    if (!(c == ' ' && !r.empty() && r.back() == ' ')) r += c;
  return r;
}

}  // namespace

LoadResult load_description(std::string_view text, std::string_view origin) {
  LoadResult res;
  const std::string org(origin);
  Reader rd(org);
  try {
    std::istringstream in{std::string(text)};
    const toml::value root = toml::parse(in, org);
    res.chain = parse(root, rd);
    res.ok = true;
  } catch (const LoadError& e) {
    res.error = e.msg;
  } catch (const toml::syntax_error& e) {
    res.error = org + ": not valid TOML: " + first_line(e.what());
  } catch (const std::exception& e) {
    res.error = org + ": " + first_line(e.what());
  }
  return res;
}

LoadResult load_description_file(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) {
    LoadResult r;
    r.error = path + ": cannot open the file";
    return r;
  }
  std::ostringstream ss;
  ss << f.rdbuf();
  return load_description(ss.str(), path);
}

LoadResult load_robot(const std::string& name_or_path) {
  for (const auto& m : builtin_models())
    if (name_or_path == m.name) return load_description(m.toml, std::string("built-in model ") + m.name);
  const bool looks_like_path = name_or_path.find('/') != std::string::npos ||
                               name_or_path.find(".toml") != std::string::npos;
  if (!looks_like_path) {
    std::string names;
    for (const auto& m : builtin_models()) names += (names.empty() ? "" : ", ") + std::string(m.name);
    std::ifstream probe(name_or_path);
    if (!probe) {
      LoadResult r;
      r.error = "unknown robot '" + name_or_path + "' (built-in models: " + names + "; or give a path to a .toml file)";
      return r;
    }
  }
  return load_description_file(name_or_path);
}

}  // namespace servoarm::kin
