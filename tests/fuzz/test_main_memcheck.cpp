// SPDX-License-Identifier: Apache-2.0
// CppUTest main for the memcheck build (the `memcheck` preset, bash .ci/memcheck), in
// place of tests/support/test_main.cpp: the same IEEE 754 plugin, but CppUTest's
// new/delete leak detector switched off. That detector replaces operator new in the
// executable and not the sized operator delete, which valgrind then serves: every
// `delete` is reported as a mismatched or invalid free (240 errors in
// kin_fk_closed_forms alone). valgrind finds the leaks itself.
#include <CppUTest/CommandLineTestRunner.h>
#include <CppUTest/MemoryLeakWarningPlugin.h>
#include <CppUTest/TestRegistry.h>
#include <CppUTestExt/IEEE754ExceptionsPlugin.h>

int main(int argc, char** argv) {
  MemoryLeakWarningPlugin::turnOffNewDeleteOverloads();
  IEEE754ExceptionsPlugin ieee754("IEEE754");
  TestRegistry::getCurrentRegistry()->installPlugin(&ieee754);
  return CommandLineTestRunner::RunAllTests(argc, argv);
}
