# SPDX-License-Identifier: Apache-2.0
# Install rules and CPack (Debian package) for the robot controller.
# Included at the end of the top-level CMakeLists.txt.
#
#   cmake --preset aarch64 && cmake --build --preset aarch64
#   cd build-aarch64 && cpack -G DEB          -> servoarm_<version>_arm64.deb
# (bash .ci/cross does both and runs the tests under qemu-aarch64.) A host build
# packages for the host's architecture the same way.
#
# What goes where (CPACK_PACKAGING_INSTALL_PREFIX /usr):
#   /usr/bin/armfw, /usr/bin/armctl          install() rules of firmware/app/ and firmware/armctl/CMakeLists.txt
#   /usr/share/servoarm/models/*.toml        built-in robot descriptions
#   /usr/share/servoarm/web/                 the browser pendant armfw serves (firmware/web/dist, docs/pendant.md)
#   /etc/servoarm/armfw.toml                 default firmware config (conffile)
#   /etc/default/servoarm                    CAN bitrate, extra armfw arguments (conffile)
#   /lib/systemd/system/servoarm.service     the firmware, real-time limits, service user
#   /lib/systemd/system/servoarm-can.service CAN interface bring-up (root oneshot)
#   /usr/lib/servoarm/servoarm-can-up        its script
#   /usr/share/doc/servoarm/README.md, docs/*.md   the manual (the units' Documentation=)
#   /usr/share/doc/servoarm/copyright        the licence (Apache-2.0), Debian's machine-readable format
set(_pkg ${CMAKE_CURRENT_LIST_DIR}/packaging)

set(SERVOARM_SYSCONFDIR "/etc" CACHE PATH "Where the package's configuration files go (absolute)")
set(SERVOARM_SYSTEMD_UNITDIR "/lib/systemd/system" CACHE PATH "Where the systemd units go (absolute)")

install(DIRECTORY ${PROJECT_SOURCE_DIR}/kinematics/models/ DESTINATION share/servoarm/models
        COMPONENT servoarm FILES_MATCHING PATTERN "*.toml")
install(DIRECTORY ${PROJECT_SOURCE_DIR}/firmware/web/dist/ DESTINATION share/servoarm/web COMPONENT servoarm)
install(FILES ${_pkg}/armfw.toml DESTINATION ${SERVOARM_SYSCONFDIR}/servoarm COMPONENT servoarm
        PERMISSIONS OWNER_READ OWNER_WRITE GROUP_READ)
install(FILES ${_pkg}/servoarm.default DESTINATION ${SERVOARM_SYSCONFDIR}/default RENAME servoarm COMPONENT servoarm)
install(FILES ${_pkg}/servoarm.service ${_pkg}/servoarm-can.service DESTINATION ${SERVOARM_SYSTEMD_UNITDIR}
        COMPONENT servoarm)
install(PROGRAMS ${_pkg}/servoarm-can-up DESTINATION lib/servoarm COMPONENT servoarm)
install(FILES ${PROJECT_SOURCE_DIR}/README.md ${_pkg}/copyright DESTINATION share/doc/servoarm COMPONENT servoarm)
install(DIRECTORY ${PROJECT_SOURCE_DIR}/docs/ DESTINATION share/doc/servoarm/docs COMPONENT servoarm
        FILES_MATCHING PATTERN "*.md")

# ---------------------------------------------------------------------------
# CPack: one Debian package, "servoarm".
# ---------------------------------------------------------------------------
set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME servoarm)
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_VENDOR "servoarm")
set(CPACK_PACKAGE_CONTACT "servoarm developers <servoarm@localhost>")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "servoarm robot arm firmware (armfw), armctl and robot descriptions")
string(CONCAT CPACK_PACKAGE_DESCRIPTION
       "Firmware for a serial-chain servo arm: a fixed-rate real-time control loop sending joint\n"
       "setpoints to CiA 402 servo drives over SocketCAN, started at boot by servoarm.service.")
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_SECTION misc)
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)
# The toolchain files name the target's Debian architecture (arm64, armhf);
# a host build packages for the host's (dpkg --print-architecture).
if(SERVOARM_DEB_ARCH)
  set(CPACK_DEBIAN_PACKAGE_ARCHITECTURE ${SERVOARM_DEB_ARCH})
endif()
# Written by hand: dpkg-shlibdeps cannot see a cross build's target libraries.
# The binaries need glibc >= 2.34 (bookworm's toolchain) and libstdc++ from g++ 12.
set(CPACK_DEBIAN_PACKAGE_DEPENDS "libc6 (>= 2.34), libstdc++6 (>= 12), libgcc-s1 (>= 3.0), adduser, iproute2")
# armctl's line editing (firmware/armctl/CMakeLists.txt: only when libedit was found for the target)
get_property(_servoarm_libedit GLOBAL PROPERTY SERVOARM_NEEDS_LIBEDIT)
if(_servoarm_libedit)
  string(APPEND CPACK_DEBIAN_PACKAGE_DEPENDS ", libedit2 (>= 3.1)")
endif()
# URDF import (kinematics/CMakeLists.txt: only when urdfdom was found for the target)
get_property(_servoarm_urdfdom GLOBAL PROPERTY SERVOARM_NEEDS_URDFDOM)
if(_servoarm_urdfdom)
  string(APPEND CPACK_DEBIAN_PACKAGE_DEPENDS ", liburdfdom-model3.0, libconsole-bridge1.0")
endif()
# The network API (firmware/api/CMakeLists.txt: only when libwebsockets was found for the target)
get_property(_servoarm_lws GLOBAL PROPERTY SERVOARM_NEEDS_LIBWEBSOCKETS)
if(_servoarm_lws)
  string(APPEND CPACK_DEBIAN_PACKAGE_DEPENDS ", libwebsockets17")
endif()
# The MQTT bridge (firmware/api/CMakeLists.txt: only when libmosquitto was found for the target)
get_property(_servoarm_mosq GLOBAL PROPERTY SERVOARM_NEEDS_LIBMOSQUITTO)
if(_servoarm_mosq)
  string(APPEND CPACK_DEBIAN_PACKAGE_DEPENDS ", libmosquitto1")
endif()
# GPIO safety inputs (hal/CMakeLists.txt: only when libgpiod was found for the target)
get_property(_servoarm_gpiod GLOBAL PROPERTY SERVOARM_NEEDS_LIBGPIOD)
if(_servoarm_gpiod)
  string(APPEND CPACK_DEBIAN_PACKAGE_DEPENDS ", libgpiod2")
endif()
set(CPACK_DEBIAN_PACKAGE_RECOMMENDS "can-utils")
set(CPACK_DEBIAN_PACKAGE_CONTROL_EXTRA ${_pkg}/postinst ${_pkg}/prerm ${_pkg}/postrm ${_pkg}/conffiles)
set(CPACK_DEBIAN_PACKAGE_CONTROL_STRICT_PERMISSION ON)
# Stripped binaries on the controller (CMAKE_STRIP: the cross strip in a cross build);
# the build tree keeps the unstripped ones for gdb.
set(CPACK_STRIP_FILES ON)
include(CPack)
unset(_pkg)
