# SPDX-License-Identifier: Apache-2.0
# cmake -DCPACK=... -DBUILD_DIR=... -DOUT=... -P build_package.cmake
# Fresh Debian package of BUILD_DIR in OUT (the CTest fixture packaging_build).
file(REMOVE_RECURSE ${OUT})
file(MAKE_DIRECTORY ${OUT})
execute_process(COMMAND ${CPACK} -G DEB -B ${OUT} --config ${BUILD_DIR}/CPackConfig.cmake
                WORKING_DIRECTORY ${BUILD_DIR} RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "cpack failed (${rc})")
endif()
file(GLOB debs ${OUT}/*.deb)
list(LENGTH debs n)
if(NOT n EQUAL 1)
  message(FATAL_ERROR "expected one .deb in ${OUT}, found ${n}: ${debs}")
endif()
message(STATUS "package: ${debs}")
