# SPDX-License-Identifier: Apache-2.0
# Scenario 5c: a real G-code sender over a pty, the arm over real SocketCAN.
# armfw (bus.can = vcan0, console on a pty) and armsim (6 virtual CiA 402
# drives on vcan0) as separate processes; Printrun's pronsole (the host's own
# python3 and pronsole, run in the VM with `hostrun` over the host's file
# system shared read-only: run-scenario --hostfs) connects to the pty, enables
# the arm (M17), sends a joint move, a relative G1 Z+20, M400 and M114, and an
# unreachable G1. Checks:
#   - pronsole reports the printer online and every line is answered: ok for
#     the good ones, one `error:` (unreachable / limits) for the bad one;
#   - M114 (computed by armfw from the drives' position feedback received
#     over vcan0) equals `armctl kin fk` of the joint move plus 20 mm in z;
#   - the drives were driven over the bus: RPDOs to every node carried
#     "enable operation" controlwords (0x000F) while the move ran.
. "$SCENARIO_DIR/lib.sh"
. "$SCENARIO_DIR/s5_lib.sh"
need candump armsim armfw armctl hostrun mkfifo
hostrun /usr/bin/test -x /usr/bin/pronsole 2>"$OUT_DIR/hostrun.err" ||
  { cat "$OUT_DIR/hostrun.err"; skip "pronsole not runnable on the host file system (Debian package pronsole; run-scenario --hostfs)"; }

write_armfw_config "$OUT_DIR/armfw.toml"
# console on a pty instead of ISO-TP
sed -i '/^\[console\]/,$ s/^can = .*/pty = true/' "$OUT_DIR/armfw.toml"

start_candump all -r 4194304 "$CAN_IF,200:C00007F8"
start_armsim armsim --nodes 1-6
log "armfw: puma560 on 6 drives over $CAN_IF, ${rate_hz} Hz, console on a pty"
armfw --config "$OUT_DIR/armfw.toml" >"$OUT_DIR/armfw.log" 2>&1 &
ARMFW_PID=$!
wait_until 60 "armfw to boot the drives and print its pty" grep -qs 'console pty: ' "$OUT_DIR/armfw.log"
pty=$(sed -n 's/^.*console pty: \(\/dev\/[^ ]*\).*$/\1/p' "$OUT_DIR/armfw.log" | head -n 1)
[ -c "$pty" ] || fail "armfw's pty '$pty' is not a character device: $(cat "$OUT_DIR/armfw.log")"
log "armfw console on $pty"

# pronsole reads its console commands from a FIFO held open here (fd 3).
rm -f /tmp/pronsole_in; mkfifo /tmp/pronsole_in
hostrun /usr/bin/pronsole </tmp/pronsole_in >"$OUT_DIR/pronsole.log" 2>&1 &
PRONSOLE_PID=$!
exec 3>/tmp/pronsole_in
t_start=$(cut -d' ' -f1 /proc/uptime)
say_p() { log "pronsole> $1"; echo "$1" >&3; }
_online() { grep -q 'Printer is now online' "$OUT_DIR/pronsole.log"; }
# _seen N PATTERN: pronsole printed at least N lines matching PATTERN. (It does
# not print a bare "ok", so each step waits for the answer that carries data.)
_seen() { [ "$(grep -c -E "$2" "$OUT_DIR/pronsole.log")" -ge "$1" ]; }

say_p "connect $pty 115200"
wait_until 180 "pronsole to report the printer online (python under emulation starts slowly)" _online
log "pronsole online after $(awk -v t="$t_start" '{ printf "%.1f", $1 - t }' /proc/uptime) s"
say_p M17
wait_until 120 "'ok enabled' for M17" _seen 1 'ok enabled'
say_p 'movej 20 -40 160 10 -50 30 speed=100'
wait_until 60 "'ok queued' for movej" _seen 1 'ok queued'
say_p G91
say_p 'G1 Z20 F3000'
wait_until 60 "'ok queued' for G1 Z20" _seen 2 'ok queued'
say_p G90
say_p M400
wait_until 120 "'ok idle' for M400" _seen 1 'ok idle'
say_p M114
wait_until 60 "the X: Y: Z: report for M114" _seen 1 'X:[-0-9.]+ Y:'
say_p 'G1 X99999'
wait_until 60 "an error: for G1 X99999" _seen 1 'error: '
say_p disconnect
say_p exit
exec 3>&-
_p_gone() { ! kill -0 "$PRONSOLE_PID" 2>/dev/null; }
wait_until 60 "pronsole to exit" _p_gone
wait "$PRONSOLE_PID" 2>/dev/null || true
kill -TERM "$ARMFW_PID" 2>/dev/null || true
_f_rc=0; wait "$ARMFW_PID" || _f_rc=$?
[ "$_f_rc" -eq 0 ] && pass "armfw exited with status 0" || check_fail "armfw exited with status $_f_rc"
stop_armsim
stop_candump all
rm -f /tmp/pronsole_in

out=$OUT_DIR/pronsole.log
echo "--- pronsole output"; cat "$out"; echo "---"
grep -q 'Printer is now online' "$out" && pass "pronsole: printer online" || check_fail "pronsole never reported the printer online"
grep -q 'ok enabled' "$out" && pass "M17 answered 'ok enabled'" || check_fail "no 'ok enabled' for M17"
nq=$(grep -c 'ok queued' "$out")
[ "$nq" -eq 2 ] && pass "movej and G1 Z20 queued (2 x 'ok queued')" || check_fail "want 2 'ok queued', got $nq"
ne=$(grep -c 'error: ' "$out")
[ "$ne" -eq 1 ] && pass "exactly one error: $(grep -o "error: .*" "$out")" || check_fail "want exactly 1 'error:' line (G1 X99999), got $ne"
grep -q -E 'error: (unreachable|limits)' "$out" && pass "G1 X99999 refused as unreachable / out of limits" ||
  check_fail "G1 X99999 not refused with unreachable / limits"

# M114 vs armctl kin fk of the joint move, z + 20 mm
fk=$(armctl kin fk --robot puma560 20 -40 160 10 -50 30 | awk '$1 == "position" && $2 == "[mm]:" { print $4, $6, $8 }')
m114=$(sed -n 's/^.*X:\([^ ]*\) Y:\([^ ]*\) Z:\([^ ]*\).*$/\1 \2 \3/p' "$out" | tail -n 1)
log "M114: $m114   armctl kin fk: $fk (+20 mm in z expected)"
if [ -n "$fk" ] && [ -n "$m114" ] &&
   echo "$fk $m114" | awk '{ d = 0; for (i = 1; i <= 3; i++) { e = $(i + 3) - $i - (i == 3 ? 20 : 0); if (e < 0) e = -e; if (e > d) d = e }
                              printf "largest difference %.3f mm\n", d; exit !(d <= 0.05) }' >"$OUT_DIR/m114.txt"; then
  pass "M114 from the drives' feedback over $CAN_IF = FK(joint move) + 20 mm z: $(cat "$OUT_DIR/m114.txt")"
else
  check_fail "M114 '$m114' is not FK '$fk' + 20 mm z: $(cat "$OUT_DIR/m114.txt" 2>/dev/null)"
fi

# every node got "enable operation" RPDOs (controlword 0x000F = bytes 0F 00)
for node in 1 2 3 4 5 6; do
  c=$(frames "$OUT_DIR/all.log" | grep -c -i "^20$node#0F00")
  [ "$c" -gt 0 ] && pass "node $node: $c RPDOs with controlword 0x000F on $CAN_IF" ||
    check_fail "node $node: no RPDO with controlword 0x000F on $CAN_IF"
done
finish
