// SPDX-License-Identifier: Apache-2.0
#pragma once
// armctl urdf import | export (URDF <-> robot description, non-real-time)
namespace servoarm::fw {
/// argv[0] is "urdf", argv[1] the subcommand. Returns an exit code.
int cli_urdf(int argc, char** argv);
}  // namespace servoarm::fw
