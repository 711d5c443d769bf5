#pragma once
// armctl console: a client for armfw's console over a serial TTY or a pty.
//   armctl console --serial PATH [--baud N] [--timeout SEC] -c "movej 0 45 -45 0 0 0" [-c ...]
//   armctl console --serial PATH               interactive (stdin lines -> device; answers printed)
// Non-real-time; returns an armctl exit code (0 every answer ok, 1 an answer was
// `error:` or timed out, 2 bad usage / cannot open the device).
namespace servoarm::fw {

int console_main(int argc, char** argv);

}  // namespace servoarm::fw
