// SPDX-License-Identifier: Apache-2.0
#pragma once
// armctl kin ik | precision  (offline inverse kinematics and Cartesian precision,
// non-real-time: allocates, prints).
namespace servoarm::fw {
/// armctl kin ik --robot NAME|FILE --xyz X Y Z (--zyz A B G | --rpy R P Y | --quat W X Y Z)
///               [--all] [--near q1..qn] [--keep-branch] [--json]
/// argv[0] is "ik". Exit: 0 solved (ok or singular), 1 unreachable / no
/// solution within the limits / numerical solver did not converge, 2 bad usage or input.
int cli_kin_ik(int argc, char** argv);
/// armctl kin precision --robot NAME|FILE --resolution d1..dn q1..qn [--json]
/// argv[0] is "precision". Prints the worst-case tool position error dx dy dz.
int cli_kin_precision(int argc, char** argv);
}  // namespace servoarm::fw
