// SPDX-License-Identifier: Apache-2.0
#pragma once
// Random-sweep sizes in slow builds. The host runs the full counts written at each
// sweep. A cross build runs the suites under qemu-user (SERVOARM_TEST_EMULATED=1) and
// the sanitizer and valgrind builds instrument every access
// (SERVOARM_TEST_INSTRUMENTED=1: the asan, tsan and memcheck presets), some 10-40x
// slower: the same sweeps, same seeds, with the first 1/20 of the cases, so they finish
// in their time (under ASan the 10 000-line sweep of motion_movel alone ran past 20
// minutes). Both are set by servoarm_add_test in the top CMakeLists.txt. The sanitizers
// look at each code path, which the first 1/20 of a seeded sweep still takes.
#include "target_exec.hpp"  // SERVOARM_TEST_EMULATED

#ifndef SERVOARM_TEST_INSTRUMENTED
#define SERVOARM_TEST_INSTRUMENTED 0
#endif

namespace servoarm::test {

inline constexpr int kSweepDivisor = (SERVOARM_TEST_EMULATED || SERVOARM_TEST_INSTRUMENTED) ? 20 : 1;
inline constexpr bool kSlowBuild = kSweepDivisor > 1;

/// The number of cases a sweep written for `host_count` runs in this build.
constexpr int sweep(int host_count) { return host_count / kSweepDivisor; }

}  // namespace servoarm::test
