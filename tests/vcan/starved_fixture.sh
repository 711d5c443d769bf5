# SPDX-License-Identifier: Apache-2.0
# Fixture of the harness's own test (tests/vcan/starved-test, CTest vcan_starved): a
# scenario that fails on purpose after a faked stall.
#   starved_fixture.sh stall   stop the guest's starvation probe for 1 s (its next wake-up
#                              is then ~1 s late, as in a starved VM), then fail
. "$SCENARIO_DIR/lib.sh"
# The probe counts the stall lines it printed in /tmp/stalls ("N longest n30", host_sim/vm/init):
# after the faked stall the fixture waits for one more than before it, not a fixed time.
_stalls() { read -r _n _ </tmp/stalls; echo "${_n:-0}"; }
_stall_printed() { [ "$(_stalls)" -gt "$stalls_before" ]; }
case ${1:-} in
  stall)
    [ -n "${SERVOARM_STALL_PROBE_PID:-}" ] || fail "SERVOARM_STALL_PROBE_PID not set: /init started no probe"
    stalls_before=$(_stalls)
    kill -STOP "$SERVOARM_STALL_PROBE_PID"
    sleep 1
    kill -CONT "$SERVOARM_STALL_PROBE_PID"
    wait_until 10 "the probe to print its stall line" _stall_printed
    fail "a deliberate failure after a faked stall" ;;
  *) fail "usage: starved_fixture.sh stall" ;;
esac
