// SPDX-License-Identifier: Apache-2.0
// armctl: the servoarm command-line tool (host side, non-real-time).
//   armctl kin ...    offline kinematics on a built-in model or a description file
//   armctl plan ...   offline trajectory planning (when built with the motion module)
//   armctl program check ...  whole-program validation offline
//   armctl drives scan / check  the drive doctor: what answers on a CAN bus, the configuration vs the buses
#include <cstdio>
#include <cstring>
#include <string>

#include "servoarm/armctl/cli_common.hpp"
#include "servoarm/armctl/cli_drives.hpp"
#include "servoarm/armctl/cli_kin.hpp"
#if __has_include("servoarm/armctl/cli_ik.hpp")
#include "servoarm/armctl/cli_ik.hpp"
#define SERVOARM_HAVE_CLI_IK 1
#endif
#include "servoarm/armctl/cli_urdf.hpp"
#include "servoarm/armctl/cli_workspace.hpp"
#if __has_include("servoarm/armctl/cli_console.hpp")
#include "servoarm/armctl/cli_console.hpp"
#define SERVOARM_HAVE_CLI_CONSOLE 1
#endif
#if __has_include("servoarm/armctl/cli_program.hpp")
#include "servoarm/armctl/cli_program.hpp"
#define SERVOARM_HAVE_CLI_PROGRAM 1
#endif
#if __has_include("servoarm/armctl/cli_plan.hpp")
#include "servoarm/armctl/cli_plan.hpp"
#define SERVOARM_HAVE_CLI_PLAN 1
#endif

namespace {

const char* kUsage =
    "usage: armctl <command> [options]\n"
    "\n"
    "Offline kinematics (units of the robot description: built-in models use mm and degrees):\n"
    "  armctl kin models                                   list the built-in robot models\n"
    "  armctl kin fk --robot NAME|FILE [--json] [--strict] q1 ... qn\n"
    "                                                      tool pose (position, rotation, ZYZ, RPY, quaternion)\n"
    "  armctl kin jacobian --robot NAME|FILE [--json] [--strict] q1 ... qn\n"
    "                                                      geometric Jacobian, manipulability, condition number\n"
    "  armctl kin workspace --robot NAME|FILE [--plane xz|xy|yz] [--grid N] [--pose q1..qn]\n"
    "                       [--svg FILE] [--csv FILE]\n"
    "                                                      reachable region of the tool point in a\n"
    "                                                      plane through the base, its area, a plot\n"
#ifdef SERVOARM_HAVE_CLI_IK
    "  armctl kin ik --robot NAME|FILE --xyz X Y Z (--zyz A B G | --rpy R P Y | --quat W X Y Z)\n"
    "                [--all] [--near q1..qn] [--keep-branch] [--json]\n"
    "                                                      inverse kinematics\n"
    "  armctl kin precision --robot NAME|FILE --resolution d1..dn q1..qn\n"
    "                                                      worst-case tool position error\n"
#endif
    "URDF (plain URDF; expand xacro first):\n"
    "  armctl urdf import FILE.urdf [--base LINK] [--tip LINK] [--convention standard|modified]\n"
    "                    [--name NAME] [-o FILE.toml] [--time N]\n"
    "                                                      the chain base -> tip as a description file\n"
    "  armctl urdf export --robot NAME|FILE [-o FILE.urdf]  a description as URDF\n"
#ifdef SERVOARM_HAVE_CLI_PLAN
    "Offline trajectory planning (prints duration and peaks; --csv and --svg write the samples):\n"
    "  armctl plan movej --robot NAME|FILE --from q1..qn --to q1..qn [--vmax V] [--amax A] [--jmax J]\n"
    "                    [--override PCT] [--max-duration S] [--rate HZ] [--csv FILE] [--svg FILE]\n"
    "  armctl plan movel --robot NAME|FILE --from q1..qn (--to q1..qn | --xyz X Y Z [--rpy R P Y | --quat W X Y Z])\n"
    "                    [--speed V] [--accel A] [--angular W] [--override PCT] [--no-slowdown]\n"
    "                    [--vmax V] [--amax A] [--jmax J] [--max-duration S] [--rate HZ] [--csv FILE] [--svg FILE]\n"
#endif
#ifdef SERVOARM_HAVE_CLI_PROGRAM
    "Programs (the native command language or G-code; docs/programs.md):\n"
    "  armctl program check FILE --robot NAME|FILE [--points FILE] [--programs DIR] [--from q1..qn]\n"
    "                                                      every line parsed, every target solved and\n"
    "                                                      every path checked before anything moves\n"
#endif
#ifdef SERVOARM_HAVE_CLI_CONSOLE
    "Console client of the firmware (armfw), interactive (line editing, history) or one-shot -c:\n"
    "  armctl console --serial PATH [--baud N] [--timeout SEC] [-c LINE]...\n"
    "                                                      over armfw's pty (--pty) or a serial port\n"
    "  armctl console --can IFACE [--tx-id 0x7E0] [--rx-id 0x7E8] [--timeout SEC] [-c LINE]...\n"
    "                                                      over CAN, ISO-TP (armfw console.can)\n"
#endif
    "Drive doctor (only reads from the drives; docs/armctl.md#drives):\n"
    "  armctl drives scan --iface IFACE [--fd] [--first N] [--last N] [--timeout MS]\n"
    "                                                      what answers on a CAN bus: CANopen nodes and\n"
    "                                                      Damiao motors, one line each (model, mode,\n"
    "                                                      frame format, errors, temperature)\n"
    "  armctl drives check --config FILE                   armfw's [[drive]] tables against the buses:\n"
    "                                                      per joint \"ok\" or what to change\n"
    "\n"
    "Each command takes --help. Exit status: 0 ok, 1 valid request that failed\n"
    "(e.g. unreachable), 2 bad usage or bad input (one line on stderr naming the option or\n"
    "value; a result that is not finite is such an error: --json output never holds nan or inf).\n";

}  // namespace

int main(int argc, char** argv) {
  using namespace servoarm::fw;
  if (argc < 2 || !std::strcmp(argv[1], "--help") || !std::strcmp(argv[1], "-h") || !std::strcmp(argv[1], "help")) {
    std::fputs(kUsage, argc < 2 ? stderr : stdout);
    return argc < 2 ? kExitUsage : kExitOk;
  }
  const std::string cmd = argv[1];
  if (cmd == "kin") {
    if (argc < 3) {
      std::fputs(kUsage, stderr);
      return kExitUsage;
    }
    const std::string sub = argv[2];
    char** sub_argv = argv + 2;
    const int sub_argc = argc - 2;
    if (sub == "fk") return cli_kin_fk(sub_argc, sub_argv);
    if (sub == "jacobian") return cli_kin_jacobian(sub_argc, sub_argv);
    if (sub == "models") return cli_kin_models(sub_argc, sub_argv);
    if (sub == "workspace") return cli_kin_workspace(sub_argc, sub_argv);
#ifdef SERVOARM_HAVE_CLI_IK
    if (sub == "ik") return cli_kin_ik(sub_argc, sub_argv);
    if (sub == "precision") return cli_kin_precision(sub_argc, sub_argv);
#endif
    return usage_error("unknown kin command '" + sub + "' (see armctl --help)");
  }
  if (cmd == "urdf") return cli_urdf(argc - 1, argv + 1);
  if (cmd == "drives") return cli_drives(argc - 1, argv + 1);
#ifdef SERVOARM_HAVE_CLI_PLAN
  if (cmd == "plan") return cli_plan(argc - 1, argv + 1);
#endif
#ifdef SERVOARM_HAVE_CLI_PROGRAM
  if (cmd == "program") return cli_program(argc - 1, argv + 1);
#endif
#ifdef SERVOARM_HAVE_CLI_CONSOLE
  if (cmd == "console") return console_main(argc, argv);  // armfw console client (serial / pty / CAN)
#endif
  return usage_error("unknown command '" + cmd + "' (see armctl --help)");
}
