// SPDX-License-Identifier: Apache-2.0
#pragma once
// armctl kin fk | jacobian | models  (offline kinematics, non-real-time)
namespace servoarm::fw {
/// argv[0] is the subcommand ("fk", "jacobian", "models"). Returns an exit code.
int cli_kin_fk(int argc, char** argv);
int cli_kin_jacobian(int argc, char** argv);
int cli_kin_models(int argc, char** argv);
}  // namespace servoarm::fw
