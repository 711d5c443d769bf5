# SPDX-License-Identifier: Apache-2.0
# Scenario 3: a node goes silent. Node 3 runs in its own armsim process; once
# canmaster has enabled all 6 drives, that process is frozen (SIGSTOP: no
# heartbeat, no TPDO, no answer - an unplugged drive). canmaster must report
# node 3's heartbeat loss within heartbeat timeout + one SYNC period of its
# last heartbeat, and no fault on the other five.
# Judged by canmaster's report (since_last_hb_ms <= limit_ms + cycle_late_ms: a
# cycle the busy host started late is the host's load, not the timeout logic;
# the same rule as canmaster's own --expect-hb-loss verdict), and on the bus:
# from node 3's last heartbeat to the first RPDO 0x203 whose controlword stops
# saying "enable operation" (the master's fault reaction), see below.
. "$SCENARIO_DIR/lib.sh"
need candump armsim canmaster
# Time constants: the issue's 10 ms SYNC, 50 ms heartbeat, 150 ms consumer
# timeout on a real kernel; in the TCG-emulated VM (5-10x slower, and its
# vCPUs are host threads that a busy machine starves for tens of ms) twice as
# long, so that what is measured is the master's timeout logic, not the host's
# load. The property checked is the same: reported within timeout + one period.
if [ "${SERVOARM_VM:-0}" = 1 ]; then period_ms=20 hb_ms=100 hb_timeout_ms=300
else period_ms=10 hb_ms=50 hb_timeout_ms=150; fi

start_candump all -r 4194304 "$CAN_IF,000:C00007FF,080:C00007FF,180:C00007F8,280:C00007F8,200:C00007F8,700:C00007F8,080:C00007F8"
start_armsim armsim_others --nodes 1,2,4,5,6
others=$ARMSIM_PID
start_armsim armsim_node3 --nodes 3
node3=$ARMSIM_PID
log "canmaster: 6 nodes, ${period_ms} ms SYNC, heartbeat ${hb_ms} ms, consumer timeout ${hb_timeout_ms} ms"
canmaster --iface "$CAN_IF" --nodes 1-6 --bringup --hold 6 --period-ms "$period_ms" --hb-ms "$hb_ms" \
  --hb-timeout-ms "$hb_timeout_ms" --expect-hb-loss 3 >"$OUT_DIR/canmaster.log" 2>&1 &
master=$!
wait_until 30 "canmaster to enable node 6" grep -qs '^node id=6 .*state=enabled' "$OUT_DIR/canmaster.log"
sleep 1
log "node 3 goes silent (SIGSTOP to its armsim)"
kill -STOP "$node3"
mrc=0; wait "$master" || mrc=$?
log "canmaster exited with status $mrc"
kill -KILL "$node3" 2>/dev/null; wait "$node3" 2>/dev/null
ARMSIM_PID=$others; stop_armsim
stop_candump all
cat "$OUT_DIR/canmaster.log"

[ "$mrc" -eq 0 ] && pass "canmaster exit status 0 (its own judgement: loss reported in time, no other fault)" ||
  check_fail "canmaster exit status $mrc"
grep '^fault' "$OUT_DIR/canmaster.log" >"$OUT_DIR/faults.txt" || true
if [ "$(wc -l <"$OUT_DIR/faults.txt")" -eq 1 ] && grep -q 'node=3 reason=heartbeat_lost' "$OUT_DIR/faults.txt"; then
  pass "exactly one fault reported: node 3 heartbeat_lost"
else
  check_fail "want exactly one fault, node 3 heartbeat_lost; got: $(cat "$OUT_DIR/faults.txt")"
fi
awk '/node=3 reason=heartbeat_lost/ { for (i = 1; i <= NF; i++) { split($i, kv, "="); v[kv[1]] = kv[2] } }
     END { printf "canmaster: since_last_hb_ms=%s limit_ms=%s cycle_late_ms=%s\n", v["since_last_hb_ms"], v["limit_ms"], v["cycle_late_ms"]
           exit !(v["limit_ms"] != "" && v["since_last_hb_ms"] + 0 <= v["limit_ms"] + v["cycle_late_ms"] + 0.000001 && v["since_last_hb_ms"] + 0 > 0) }' \
  "$OUT_DIR/faults.txt" >"$OUT_DIR/selfreport.txt" &&
  pass "$(cat "$OUT_DIR/selfreport.txt") (reported within timeout + one period + the detecting cycle's own lateness)" ||
  check_fail "$(cat "$OUT_DIR/selfreport.txt"): not within timeout + one period + the detecting cycle's lateness"

tframes "$OUT_DIR/all.log" >"$OUT_DIR/all.tframes"
cut -d' ' -f2 "$OUT_DIR/all.tframes" >"$OUT_DIR/all.frames"
# On the bus: last heartbeat of node 3, then the first RPDO 0x203 that no
# longer enables operation (the fault reaction, sent in the cycle that
# detected the loss). Kernel timestamps give the latency, but under emulation
# a cycle's frames leave some ms after the cycle started, so "within timeout +
# one SYNC period" is judged in SYNC periods: the loss must be acted on in the
# first cycle that starts after the timeout expired, i.e. at most one SYNC
# between (last heartbeat + timeout) and the reaction; and not before the
# timeout expired.
awk -v timeout="$hb_timeout_ms" -v period="$period_ms" '
    { split($2, p, "#") }
    p[1] == "703" { last_hb = $1 }
    p[1] == "080" && p[2] == "" { sync[++ns] = $1 }
    p[1] == "203" && last_hb != "" && substr(p[2], 1, 4) != "0F00" && react == "" && seen_enabled { react = $1; cw = substr(p[2], 3, 2) substr(p[2], 1, 2) }
    p[1] == "203" && substr(p[2], 1, 4) == "0F00" { seen_enabled = 1; if (react != "") back = 1 }
    END { if (react == "") { print "no fault reaction (RPDO 0x203 without enable operation) after node 3 fell silent"; exit 1 }
          dt = (react - last_hb) * 1000
          for (i = 1; i <= ns; i++) if (sync[i] > last_hb + timeout / 1000 && sync[i] < react) between++
          printf "bus: node 3 last heartbeat at %.6f, RPDO 0x203 controlword 0x%s at %.6f: %.1f ms later, %d SYNC(s) between timeout expiry and reaction (want 0-1; timeout %d ms, period %d ms)%s\n", last_hb, cw, react, dt, between, timeout, period, back ? "; node 3 re-enabled afterwards!" : ""
          exit !(dt > timeout && between <= 1 && !back) }' "$OUT_DIR/all.tframes" >"$OUT_DIR/bus_latency.txt" &&
  pass "$(cat "$OUT_DIR/bus_latency.txt")" || check_fail "$(cat "$OUT_DIR/bus_latency.txt")"
# no false fault: the other drives keep "enable operation" until canmaster powers down
for n in 1 2 4 5 6; do check_controlwords "no false fault" "$OUT_DIR/all.frames" "$n"; done
finish
