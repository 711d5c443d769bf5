# SPDX-License-Identifier: Apache-2.0
# Shared part of toolchain/aarch64-linux-gnu.cmake and arm-linux-gnueabihf.cmake
# (Debian cross compilers + multiarch). Expects SERVOARM_CROSS_TRIPLET,
# SERVOARM_CROSS_PROCESSOR, SERVOARM_CROSS_QEMU and SERVOARM_DEB_ARCH.
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR ${SERVOARM_CROSS_PROCESSOR})
set(_t ${SERVOARM_CROSS_TRIPLET})

set(CMAKE_C_COMPILER ${_t}-gcc)
set(CMAKE_CXX_COMPILER ${_t}-g++)

# Where target files live on a Debian build machine:
#   /usr/<triplet>            the cross libc, libstdc++ (package libc6-dev-<arch>-cross)
#   /usr/lib/<triplet>        multiarch -dev packages (libcpputest-dev:arm64 ...),
#                             found because CMAKE_LIBRARY_ARCHITECTURE is the triplet
#   /usr/include, /usr/share  arch-independent headers and CMake configs (Eigen, toml11)
# so the root path is the cross prefix plus "/", and target files are looked up in
# both; programs (pkg-config, qemu) always come from the build machine.
set(CMAKE_LIBRARY_ARCHITECTURE ${_t})
set(CMAKE_FIND_ROOT_PATH /usr/${_t} /)
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE ONLY)

# pkg-config (CppUTest's cpputest.pc): only the target's .pc files and the
# arch-independent ones, never the build machine's /usr/lib/x86_64-linux-gnu.
set(ENV{PKG_CONFIG_LIBDIR} /usr/lib/${_t}/pkgconfig:/usr/share/pkgconfig)
set(ENV{PKG_CONFIG_PATH} "")
# Target libraries unpacked rather than installed (.ci/cross: libwebsockets-dev for the target
# cannot be installed beside the build machine's): the environment's SERVOARM_CROSS_EXTRA_ROOT
# names that root (its .pc files already point into it); looked up before the multiarch ones.
if(DEFINED ENV{SERVOARM_CROSS_EXTRA_ROOT} AND IS_DIRECTORY "$ENV{SERVOARM_CROSS_EXTRA_ROOT}/usr/lib/${_t}/pkgconfig")
  list(PREPEND CMAKE_FIND_ROOT_PATH $ENV{SERVOARM_CROSS_EXTRA_ROOT})
  set(ENV{PKG_CONFIG_LIBDIR} $ENV{SERVOARM_CROSS_EXTRA_ROOT}/usr/lib/${_t}/pkgconfig:$ENV{PKG_CONFIG_LIBDIR})
endif()

# Run target binaries (tests, try_run) under qemu-user with the cross sysroot
# for the dynamic loader. A test that starts another target binary (fork/exec,
# system()) needs the kernel's binfmt_misc to hand it to qemu too, with
# QEMU_LD_PREFIX=/usr/<triplet> in the environment: .ci/cross sets up both.
find_program(SERVOARM_QEMU_USER ${SERVOARM_CROSS_QEMU})
if(SERVOARM_QEMU_USER)
  set(CMAKE_CROSSCOMPILING_EMULATOR ${SERVOARM_QEMU_USER} -L /usr/${_t})
endif()

unset(_t)
