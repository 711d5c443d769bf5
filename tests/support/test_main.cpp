// SPDX-License-Identifier: Apache-2.0
// CppUTest main for every servoarm suite.
// The IEEE754 exceptions plugin fails any test that raises an invalid,
// overflow or divide-by-zero floating-point exception, so a NaN produced
// anywhere in the code under test is caught even if no assertion looks at it.
#include <CppUTest/CommandLineTestRunner.h>
#include <CppUTest/TestRegistry.h>
#include <CppUTestExt/IEEE754ExceptionsPlugin.h>

int main(int argc, char** argv) {
  IEEE754ExceptionsPlugin ieee754("IEEE754");
  TestRegistry::getCurrentRegistry()->installPlugin(&ieee754);
  return CommandLineTestRunner::RunAllTests(argc, argv);
}
