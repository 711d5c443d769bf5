# SPDX-License-Identifier: Apache-2.0
# Cross toolchain: 64-bit ARM Linux (Raspberry Pi 4/5 with a 64-bit OS, most
# current ARM SBCs), Debian's g++-aarch64-linux-gnu.
#
#   cmake --preset aarch64            (CMakePresets.json)
#   cmake -S . -B build-aarch64 -DCMAKE_TOOLCHAIN_FILE=toolchain/aarch64-linux-gnu.cmake
#
# Libraries for the target come from Debian multiarch (libcpputest-dev:arm64);
# Eigen and toml11 are header-only, arch-independent packages. The binaries run
# on the build machine under qemu-aarch64 (Debian qemu-user): CTest prefixes every
# test with CMAKE_CROSSCOMPILING_EMULATOR. See .ci/cross.
set(SERVOARM_CROSS_TRIPLET aarch64-linux-gnu)
set(SERVOARM_CROSS_PROCESSOR aarch64)
set(SERVOARM_CROSS_QEMU qemu-aarch64)
set(SERVOARM_DEB_ARCH arm64)
include(${CMAKE_CURRENT_LIST_DIR}/cross-common.cmake)
