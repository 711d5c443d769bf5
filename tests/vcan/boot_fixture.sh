# SPDX-License-Identifier: Apache-2.0
# Fixture of the harness's own test (tests/vcan/boot-retry-test, CTest vcan_boot_retry): the
# scenario of the second boot, after a first that hung or panicked. It passes when the guest
# /init started is the whole one: the CAN modules loaded and vcan0 up.
. "$SCENARIO_DIR/lib.sh"
grep -q '^vcan ' /proc/modules || fail "the vcan module is not loaded"
ip link show "$CAN_IF" | grep -q 'UP' || fail "$CAN_IF is not up"
echo PASSED
