#pragma once
// armctl plan movej | movel  (offline trajectory planning, non-real-time)
//
//   armctl plan movej --robot NAME|FILE --from q1..qn --to q1..qn
//                     [--vmax V] [--amax A] [--jmax J] [--override PCT]
//                     [--rate HZ] [--csv FILE] [--svg FILE]
//   armctl plan movel --robot NAME|FILE --from q1..qn
//                     (--to q1..qn | --xyz X Y Z [--rpy R P Y | --quat W X Y Z])
//                     [--speed V] [--accel A] [--angular W] [--override PCT] [--no-slowdown]
//                     [--vmax V] [--amax A] [--jmax J] [--rate HZ] [--csv FILE] [--svg FILE]
//
// Units are the robot description's (built-in models: mm and degrees).
namespace servoarm::fw {
/// argv[0] is "plan", argv[1] the move kind. Returns an exit code
/// (0 planned, 1 refused by the planner, 2 bad usage / bad input).
int cli_plan(int argc, char** argv);
}  // namespace servoarm::fw
