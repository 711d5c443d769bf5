#!/bin/sh
# SPDX-License-Identifier: Apache-2.0
# Scenario 8: canmaster homes six armsim drives with mixed CiA 402 homing
# methods over vcan0, all at once:
#   node 1 method 19 (positive home switch at 30000 counts)
#   node 2 method 21 (negative home switch, edge at -25000)
#   node 3 method 17 (negative limit switch at -40000)
#   node 4 method 34 (index pulse, positive: the pulse at 20000)
#   node 5 method 35 (current position)
#   node 6 method 23 (home cam [15000, 45000], limit switches at +-300000)
# Home offset 607Ch = 1000 counts: each drive reads 1000 at its mark.
# Checked from candump: per node the SDO writes 6098h (method), 6099h:01/:02 (speeds),
# 609Ah (acceleration), 607Ch (offset), 6060h = 6, an RPDO with controlword bit 4 set, a
# TPDO1 with statusword bit 12 (homing attained, bit 13 clear), then 6060h = 8 (back to
# CSP) after the 6060h = 6, and RPDOs "enable operation" without bit 4 afterwards; the
# positions in the last TPDO1s = 607Ch within one count. From armsim's "armsim homed"
# lines: the mark each drive found and where its shaft stands, in the counts before
# homing, against the simulated switches (within one count). Nothing here is judged in
# wall-clock time: homing takes as many cycles as it takes, the timeouts are generous.
. "$SCENARIO_DIR/lib.sh"
need candump armsim canmaster
if [ "${SERVOARM_VM:-0}" = 1 ]; then period_ms=10 hb_ms=100 hb_timeout_ms=500
else period_ms=4 hb_ms=50 hb_timeout_ms=300; fi

start_candump all -r 8388608 "$CAN_IF,000:C00007FF,080:C00007FF,180:C00007F8,200:C00007F8,600:C00007F8,580:C00007F8"
start_armsim armsim --nodes 1-6 --home-switch 1:30000 --home-switch 2:-inf,-25000 --limits 3:-40000,inf \
  --index 4:131072,20000 --home-switch 6:15000,45000 --limits 6:-300000,300000
log "canmaster: 6 nodes, ${period_ms} ms cycle, homing methods 19 21 17 34 35 23, 607Ch = 1000"
mrc=0
canmaster --iface "$CAN_IF" --nodes 1-6 --bringup --period-ms "$period_ms" --hb-ms "$hb_ms" \
  --hb-timeout-ms "$hb_timeout_ms" --sdo-timeout-ms 500 --enable-timeout-ms 3000 \
  --home 1:19 --home 2:21 --home 3:17 --home 4:34 --home 5:35 --home 6:23 \
  --home-speeds 1,0.1 --home-accel 20 --home-offset 1000 --home-timeout 60 --hold 0.5 \
  >"$OUT_DIR/canmaster.log" 2>&1 || mrc=$?
log "canmaster exited with status $mrc"
stop_armsim
stop_candump all
cat "$OUT_DIR/canmaster.log"
grep '^armsim homed' "$OUT_DIR/armsim.log" || true

[ "$mrc" -eq 0 ] && pass "canmaster exit status 0 (every joint homed, then held)" || check_fail "canmaster exit status $mrc"
[ "$(grep -c '^homed node=.* status=ok ' "$OUT_DIR/canmaster.log")" -eq 6 ] &&
  pass "canmaster: 6 homed lines with status=ok" || check_fail "canmaster: not 6 homed status=ok lines"

tframes "$OUT_DIR/all.log" >"$OUT_DIR/all.tframes"
cut -d' ' -f2 "$OUT_DIR/all.tframes" >"$OUT_DIR/all.frames"
# Expected SDO writes (expedited: 2F = 1 byte, 23 = 4 bytes), little-endian values.
sw=$(le32 131072)    # 6099h:01: 1 rev/s
zero=$(le32 13107)   # 6099h:02: 0.1 rev/s
acc=$(le32 2621440)  # 609Ah: 20 rev/s^2
off=$(le32 1000)     # 607Ch
for n in 1 2 3 4 5 6; do
  case $n in 1) m=13 ;; 2) m=15 ;; 3) m=11 ;; 4) m=22 ;; 5) m=23 ;; 6) m=17 ;; esac   # hex of 19 21 17 34 35 23
  for f in "60$n#2F986000${m}000000" "60$n#23996001$sw" "60$n#23996002$zero" "60$n#239A6000$acc" \
           "60$n#237C6000$off" "60$n#2F60600006000000"; do
    grep -qx "$f" "$OUT_DIR/all.frames" && pass "node $n: SDO $f" || check_fail "node $n: SDO $f missing"
  done
  # Order on the bus: 6060h = 6, then an RPDO with bit 4, a TPDO1 with bit 12 (not 13), then
  # 6060h = 8, then RPDOs enabling operation without bit 4; the last TPDO1 position.
  awk -v n="$n" "$AWK_LE"'
      { split($0, p, "#") }
      p[1] == "60" n && p[2] == "2F60600006000000" && !hm { hm = NR }
      p[1] == "20" n && hm && !bit4 && int(le_u(substr(p[2], 1, 4)) / 16) % 2 == 1 { bit4 = NR }
      p[1] == "18" n && bit4 && !att { s = le_u(substr(p[2], 1, 4)); if (int(s / 4096) % 2 == 1 && int(s / 8192) % 2 == 0) att = NR }
      p[1] == "60" n && p[2] == "2F60600008000000" && att && !csp { csp = NR }
      p[1] == "20" n && csp && le_u(substr(p[2], 1, 4)) == 15 { after++ }
      p[1] == "18" n && csp { pos = s32(le_u(substr(p[2], 5, 8))); last = p[2] }
      END { printf "node %s: 6060h=6 at frame %d, controlword bit 4 at %d, statusword bit 12 at %d, 6060h=8 at %d, %d RPDOs enable operation after, last TPDO1 %s position %d (607Ch 1000)\n", n, hm, bit4, att, csp, after, last, pos
            exit !(hm && bit4 > hm && att > bit4 && csp > att && after >= 10 && pos >= 999 && pos <= 1001) }' \
    "$OUT_DIR/all.frames" >"$OUT_DIR/order_$n.txt" && pass "$(cat "$OUT_DIR/order_$n.txt")" ||
    check_fail "$(cat "$OUT_DIR/order_$n.txt")"
done
# The marks against the simulated switches (counts before homing), and where the shafts stand.
for spec in 1:30000 2:-25000 3:-40000 4:20000 6:15000; do
  n=${spec%%:*}; want=${spec#*:}
  awk -v n="$n" -v want="$want" '
      $1 == "armsim" && $2 == "homed" { for (i = 3; i <= NF; i++) { split($i, kv, "="); v[kv[1]] = kv[2] }
                                        if (v["node"] == n) { mark = v["mark"]; phys = v["physical"]; seen = 1 } }
      END { d = mark - want; e = phys - want
            printf "node %s: mark %s, shaft at %s, switch at %s (%+.1f / %+.1f counts)\n", n, mark, phys, want, d, e
            exit !(seen && d >= -1 && d <= 1 && e >= -1 && e <= 1) }' "$OUT_DIR/armsim.log" >"$OUT_DIR/mark_$n.txt" &&
    pass "$(cat "$OUT_DIR/mark_$n.txt")" || check_fail "$(cat "$OUT_DIR/mark_$n.txt")"
done
grep -q '^armsim homed .*node=5 method=35' "$OUT_DIR/armsim.log" && pass "node 5: homed on its current position" ||
  check_fail "node 5: no 'armsim homed' line"
finish
