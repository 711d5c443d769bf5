// SPDX-License-Identifier: Apache-2.0
// armctl urdf import | export: a URDF's serial chain as a description file (DH rows with
// comments naming the URDF joints), and a description as URDF. Converted by
// kinematics/urdf.hpp; the result goes through the IK analyser like any description.
#include "servoarm/armctl/cli_urdf.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include "servoarm/armctl/cli_common.hpp"
#include "servoarm/kinematics/io/file_input.hpp"
#include "servoarm/kinematics/ik.hpp"
#ifdef SERVOARM_WITH_URDF
#include "servoarm/kinematics/urdf.hpp"
#endif

namespace servoarm::fw {
namespace {

const char* kImportUsage =
    "usage: armctl urdf import FILE.urdf [--base LINK] [--tip LINK] [--convention standard|modified]\n"
    "                          [--name NAME] [-o FILE.toml] [--time N]\n"
    "  The serial chain from --base (default: the root link) to --tip (default: the leaf with\n"
    "  the most moving joints) as a description file: DH rows, each commented with the URDF\n"
    "  joint it comes from, limits, inertial data, base and tool transforms. Plain URDF only\n"
    "  (expand xacro first: xacro robot.urdf.xacro > robot.urdf). Without -o the file goes to\n"
    "  stdout; with -o it is written atomically and a summary (joints, IK class) is printed.\n"
    "  --time N: convert N times and print the median time of one conversion.\n"
    "  Bad input (malformed XML, a loop, no path, a zero axis, NaN, mimic, floating or planar\n"
    "  joints on the chain, a file over 4 MiB): one line, exit 2, nothing written.\n";
const char* kExportUsage =
    "usage: armctl urdf export --robot NAME|FILE [-o FILE.urdf]\n"
    "  The description as URDF: links base_link, link_1.., tool0 with inertials and cylinders\n"
    "  along the links as visuals; joints joint_1.. with their limits. Without -o: stdout.\n";

#ifdef SERVOARM_WITH_URDF
struct ImportArgs {
  std::string file, out, name;
  kin::UrdfParseOptions parse;
  kin::Convention convention = kin::Convention::standard;
  int time_runs = 0;
};

// -1 to continue, otherwise an exit code.
int parse_import(int argc, char** argv, ImportArgs& a) {
  for (int i = 2; i < argc; ++i) {
    const std::string s = argv[i];
    auto value = [&](const char*) -> const char* { return ++i < argc ? argv[i] : nullptr; };
    if (s == "--help" || s == "-h") {
      std::fputs(kImportUsage, stdout);
      return kExitOk;
    } else if (s == "--base" || s == "--tip" || s == "--name" || s == "-o") {
      const char* v = value(s.c_str());
      if (!v) return usage_error(s + " needs a value");
      (s == "--base" ? a.parse.base : s == "--tip" ? a.parse.tip : s == "--name" ? a.name : a.out) = v;
    } else if (s == "--convention") {
      const char* v = value("--convention");
      const std::string c = v ? v : "";
      if (c != "standard" && c != "modified") return usage_error("--convention: expected standard or modified");
      a.convention = c == "standard" ? kin::Convention::standard : kin::Convention::modified;
    } else if (s == "--time") {
      const char* v = value("--time");
      double n = 0;
      if (!v || !parse_number(v, n) || n < 1 || n > 100000 || n != static_cast<int>(n))
        return usage_error("--time: expected a whole number of runs from 1 to 100000");
      a.time_runs = static_cast<int>(n);
    } else if (!s.empty() && s[0] == '-') {
      return usage_error("unknown option '" + s + "' (see armctl urdf import --help)");
    } else if (a.file.empty()) {
      a.file = s;
    } else {
      return usage_error("one URDF file at a time ('" + s + "' is a second)");
    }
  }
  if (a.file.empty()) return usage_error("urdf import needs a URDF file (see armctl urdf import --help)");
  return -1;
}

int urdf_import(int argc, char** argv) {
  ImportArgs a;
  if (int rc = parse_import(argc, argv, a); rc >= 0) return rc;
  const kin::UrdfConvertOptions copt{a.convention, a.name};
  std::vector<double> us;
  kin::UrdfConversion c;
  for (int run = 0; run < std::max(1, a.time_runs); ++run) {
    const auto t0 = std::chrono::steady_clock::now();
    const kin::UrdfParseResult p = kin::urdf_parse_file(a.file, a.parse);
    if (!p.ok) return usage_error(p.error);
    c = kin::urdf_convert(p.chain, copt);
    if (!c.ok) return usage_error(a.file + ": " + c.error);
    us.push_back(std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count());
  }
  kin::IkModel ik;
  kin::ik_prepare(c.chain, ik);
  if (a.out.empty()) {
    std::fputs(c.toml.c_str(), stdout);
  } else if (std::string e = kin::write_text_file_atomic(a.out, c.toml); !e.empty()) {
    return usage_error(e);
  } else {
    std::printf("wrote %s: %d joints, %s DH, IK: %s\n", a.out.c_str(), c.chain.n_joints, kin::to_string(a.convention),
                kin::to_string(ik.method));
  }
  if (a.time_runs > 0) {
    std::sort(us.begin(), us.end());
    std::fprintf(a.out.empty() ? stderr : stdout, "conversion (read, parse, convert, check): median %.1f us of %d runs\n",
                 us[us.size() / 2], a.time_runs);
  }
  return kExitOk;
}

int urdf_export_cmd(int argc, char** argv) {
  std::string robot, out;
  for (int i = 2; i < argc; ++i) {
    const std::string s = argv[i];
    if (s == "--help" || s == "-h") {
      std::fputs(kExportUsage, stdout);
      return kExitOk;
    } else if (s == "--robot" || s == "-o") {
      if (++i >= argc) return usage_error(s + " needs a value");
      (s == "--robot" ? robot : out) = argv[i];
    } else {
      return usage_error("unknown argument '" + s + "' (see armctl urdf export --help)");
    }
  }
  if (robot.empty()) return usage_error("--robot is required (see armctl kin models)");
  const kin::LoadResult r = load_robot_checked(robot);
  if (!r.ok) return usage_error(r.error);
  const std::string text = kin::urdf_export(r.chain);
  if (out.empty()) {
    std::fputs(text.c_str(), stdout);
    return kExitOk;
  }
  if (std::string e = kin::write_text_file_atomic(out, text); !e.empty()) return usage_error(e);
  std::printf("wrote %s: %d joints\n", out.c_str(), r.chain.n_joints);
  return kExitOk;
}
#endif

}  // namespace

int cli_urdf(int argc, char** argv) {
  const std::string sub = argc > 1 ? argv[1] : "";
  if (sub == "--help" || sub == "-h") {
    std::fputs(kImportUsage, stdout);
    std::fputs(kExportUsage, stdout);
    return kExitOk;
  }
#ifdef SERVOARM_WITH_URDF
  if (sub == "import") return urdf_import(argc, argv);
  if (sub == "export") return urdf_export_cmd(argc, argv);
  return usage_error("urdf: expected import or export (see armctl urdf --help)");
#else
  return usage_error("urdf: this armctl was built without URDF support (urdfdom not found: Debian liburdfdom-dev)");
#endif
}

}  // namespace servoarm::fw
