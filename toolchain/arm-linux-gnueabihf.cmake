# SPDX-License-Identifier: Apache-2.0
# Cross toolchain: 32-bit ARM Linux, hard float (BeagleBone Black/AI, Raspberry
# Pi OS 32-bit), Debian's g++-arm-linux-gnueabihf.
#
#   cmake --preset armhf              (CMakePresets.json)
#   cmake -S . -B build-armhf -DCMAKE_TOOLCHAIN_FILE=toolchain/arm-linux-gnueabihf.cmake
#
# Target libraries from Debian multiarch (libcpputest-dev:armhf, after
# `dpkg --add-architecture armhf`); binaries run under qemu-arm.
set(SERVOARM_CROSS_TRIPLET arm-linux-gnueabihf)
set(SERVOARM_CROSS_PROCESSOR arm)
set(SERVOARM_CROSS_QEMU qemu-arm)
set(SERVOARM_DEB_ARCH armhf)
include(${CMAKE_CURRENT_LIST_DIR}/cross-common.cmake)

# 64-bit file offsets and inode numbers (getdents64, stat64): with the 32-bit
# calls, readdir()/stat() fail with EOVERFLOW on a 64-bit kernel whose file
# system hands out 64-bit directory offsets or inode numbers: under qemu-arm on
# an x86-64 build machine (tests/packaging could not list its .deb directory),
# and on a 64-bit kernel with a 32-bit userland (Raspberry Pi OS) with btrfs,
# overlayfs or NFS. time_t stays 32-bit, as in Debian 12's armhf ABI.
# -Wno-psabi: g++ notes on every std::vector/std::span argument that its passing
# changed in GCC 7.1 (everything here is built by one compiler; noise only).
set(CMAKE_C_FLAGS_INIT "-D_FILE_OFFSET_BITS=64")
set(CMAKE_CXX_FLAGS_INIT "-D_FILE_OFFSET_BITS=64 -Wno-psabi")
