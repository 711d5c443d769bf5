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
