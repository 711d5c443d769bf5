# SPDX-License-Identifier: Apache-2.0
# Scenario 5b: a drive falls silent while the arm moves. armfw (bus.can = vcan0,
# console over ISO-TP on vcan0) drives armsim nodes 1,2,4,5,6 (one process) and
# node 3 (its own process). T s into a 10 s move node 3's armsim is stopped
# (SIGSTOP): from then on the node sends nothing and reads nothing, an unplugged
# drive. (armsim's own --silent NODE@T counts from its start, so the move would
# have to wait for the slowest start-up; hal_binaries checks that option.)
# armfw must stop the arm with a fault naming joint 3:
#   - on the console: an `alarm: fault joint 3 ...` line, and `status` in
#     state fault with fault="joint 3 heartbeat_lost ...";
#   - on the bus (candump kernel timestamps, checked on the host by
#     s5_silent_node.host-check): from node 3's last heartbeat to the first RPDO
#     0x203 that no longer says "enable operation" (the fault reaction) within
#     heartbeat timeout + 2 control cycles. Under emulation the
#     cycles themselves run late, so this is judged like scenario 3, in cycles
#     actually run: at most 2 SYNCs between (last heartbeat + timeout) and the
#     reaction, and not before the timeout expired; the time is printed.
#   - every other joint is powered down afterwards (the quick-stop ramp ends).
. "$SCENARIO_DIR/lib.sh"
. "$SCENARIO_DIR/s5_lib.sh"
need candump isotpsend isotprecv isotpsniffer armsim armfw od mkfifo
silent_into=${1:-4}   # s into the 10 s move when node 3 falls silent
write_armfw_config "$OUT_DIR/armfw.toml"

start_candump all -r 4194304 "$CAN_IF,200:C00007F8,080:C00007FF,700:C00007F8,7E0:C00007F7"
start_armsim armsim_node3 --nodes 3
node3=$ARMSIM_PID
start_armsim armsim_others --nodes 1,2,4,5,6
others=$ARMSIM_PID
start_isotprecv
log "armfw: ${rate_hz} Hz, heartbeat ${hb_ms} ms, consumer timeout ${hb_timeout_ms} ms; node 3 falls silent ${silent_into} s into the move"
start_armfw "$OUT_DIR/armfw.toml"
first_contact
expect_ok "enable" "$(isotp_ask enable 60)"
wait_state idle 60
expect_ok "movej (slow, 10 s)" "$(isotp_ask 'movej 60 -60 120 40 -40 60 speed=10')"
t_move=$(cut -d' ' -f1 /proc/uptime)
_before_silence() { awk -v t="$t_move" -v s="$silent_into" '{ exit !($1 < t + s) }' /proc/uptime; }
while _before_silence; do sleep 0.1; done   # (sleep loops run slow under emulation: the clock decides)
kill -STOP "$node3" || fail "cannot stop node 3's armsim"
log "node 3 unplugged (its armsim stopped) $(awk -v t="$t_move" '{ printf "%.1f", $1 - t }' /proc/uptime) s into the move"
wait_state fault 30
st=$(isotp_ask status)
echo "$st"
# stopped on the way: not at the goal of the move
echo "$st" | awk '{ if (match($0, /joints=\[[^]]*\]/)) { split(substr($0, RSTART + 8, RLENGTH - 9), q, " ") }
                    d = q[1] - 60; if (d < 0) d = -d; printf "joint 1 at %s deg when stopped (goal 60)\n", q[1]; exit !(q[1] != "" && d > 1) }' \
  >"$OUT_DIR/stopped.txt" && pass "the arm stopped during the move: $(cat "$OUT_DIR/stopped.txt")" ||
  check_fail "the arm was not stopped during the move: $(cat "$OUT_DIR/stopped.txt")"
case $st in
  *'fault="joint 3 heartbeat_lost'*) pass "status names the joint and the cause: ${st#*fault=}" ;;
  *) check_fail "status does not say fault=\"joint 3 heartbeat_lost...\": $st" ;;
esac
isotp_text | grep '^alarm: fault' >"$OUT_DIR/alarms.txt" || true
grep -q '^alarm: fault joint 3 ' "$OUT_DIR/alarms.txt" && pass "console alarm: $(head -n 1 "$OUT_DIR/alarms.txt")" ||
  check_fail "no 'alarm: fault joint 3 ...' on the console (got: $(cat "$OUT_DIR/alarms.txt"))"
expect_error "movej refused while faulted" "$(isotp_ask 'movej 0 0 0 0 0 0')"
sleep 1
stop_armfw
stop_isotprecv
kill -KILL "$node3" 2>/dev/null; wait "$node3" 2>/dev/null
ARMSIM_PID=$others; stop_armsim
stop_candump all
cat "$OUT_DIR/armsim_node3.log" | grep -E 'fault|ready'

# the frames on the bus are checked on the host (s5_silent_node.host-check)
to_host hb_timeout_ms rate_hz
finish
