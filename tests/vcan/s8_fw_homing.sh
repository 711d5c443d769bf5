#!/bin/sh
# SPDX-License-Identifier: Apache-2.0
# Scenario 8, through the firmware: armfw homes six armsim drives over real
# SocketCAN, driven by its console over ISO-TP (the kernel's isotpsend / isotpsniffer), with
# mixed methods and homing.order = [[3], [2], [1], [4, 5, 6]]:
#   joint 1 method 19 (positive home switch at +5 deg), joint 2 method 21 (negative home
#   switch, edge at -5 deg), joint 3 method 17 (negative limit switch at -6 deg), joint 4
#   method 34 (index pulse 5 deg ahead), joint 5 method 35 (current position), joint 6
#   "hard_stop" (no switch: a mechanical end stop at -8 deg, armfw drives it in CSP).
# homing.offset per joint [10, -20, 30, 15, 0, -40] deg (607Ch in counts: 131072 counts/rev).
# Checked:
#   console: an unhomed arm refuses movej (not_homed), `home` answers "group 1 of 4
#     (joint 3)", the progress lines, `wait` ok, status homing=[homed x6] with each joint
#     at its offset (0.01 deg), then park;
#   candump, per CiA 402 node: the SDO writes 6098h, 6099h:01/:02, 609Ah, 607Ch, 6060h = 6,
#     an RPDO with controlword bit 4, a TPDO1 with statusword bit 12 (13 clear), 6060h = 8
#     after it, the last TPDO1 position = 607Ch within one count; joint 6 (hard_stop): no
#     6060h = 6 at all, the RPDO target steps never faster than homing.speed_switch allows
#     (the master caps its step at 50 ms of travel), its final position = its offset;
#   the groups' order on the bus: node 3's 6060h = 8 before node 2's 6060h = 6, node 2's
#     before node 1's, node 1's before 4's and 5's and node 6's first moving RPDO;
#   armsim's "armsim homed" lines: the marks against the simulated switches (one count).
# Nothing is judged in wall-clock time (the VM's TCG CPU on a busy host is slow and uneven):
# the durations per node (from the kernel timestamps) are printed as figures only.
. "$SCENARIO_DIR/lib.sh"
. "$SCENARIO_DIR/s5_lib.sh"
need candump isotpsend isotprecv isotpsniffer armsim armfw od mkfifo
# Heartbeat consumer time 1 s in the VM (s5_lib's 300 ms): homing is not about heartbeat
# loss, and the TCG guest on a busy host starves armsim longer than 300 ms now and then.
if [ "${SERVOARM_VM:-0}" = 1 ]; then hb_timeout_ms=1000; fi
write_armfw_config "$OUT_DIR/armfw.toml" --own-drives
cat >>"$OUT_DIR/armfw.toml" <<EOF
[homing]
order = [[3], [2], [1], [4, 5, 6]]
[[drive]]
homing.method = 19
homing.speed_switch = 10
homing.speed_zero = 2
homing.acceleration = 100
homing.offset = 10
homing.timeout_s = 120
[[drive]]
homing.method = 21
homing.speed_switch = 10
homing.speed_zero = 2
homing.acceleration = 100
homing.offset = -20
homing.timeout_s = 120
[[drive]]
homing.method = 17
homing.speed_switch = 10
homing.speed_zero = 2
homing.acceleration = 100
homing.offset = 30
homing.timeout_s = 120
[[drive]]
homing.method = 34
homing.speed_zero = 4
homing.acceleration = 100
homing.offset = 15
homing.timeout_s = 120
[[drive]]
homing.method = 35
homing.offset = 0
homing.timeout_s = 120
[[drive]]
homing.method = "hard_stop"
homing.direction = -1
homing.speed_switch = 5
homing.acceleration = 50
homing.following_limit = 2
homing.backoff = 3
homing.offset = -40
homing.timeout_s = 120
EOF
cpd=364.0888889  # counts per degree (131072 counts/rev, gear 1)

start_candump all -r 8388608 "$CAN_IF,000:C00007FF,080:C00007FF,180:C00007F8,200:C00007F8,600:C00007F8,580:C00007F8,7E0:C00007F7"
# switches in counts before homing: 5 deg = 1820, 6 deg = 2185, 8 deg = 2913
start_armsim armsim --nodes 1-6 --home-switch 1:1820 --home-switch 2:-inf,-1820 --limits 3:-2185,inf \
  --index 4:131072,1820 --end-stops 6:-2913,inf
start_isotprecv
log "armfw: puma560 on 6 drives over $CAN_IF, ${rate_hz} Hz; homing 19 21 17 34 35 hard_stop, order [[3], [2], [1], [4, 5, 6]]"
start_armfw "$OUT_DIR/armfw.toml"

# enable_arm: `enable`, reset and again (at most 3 attempts) when a drive did not come up in
# time: armfw's CiA 402 state timeout (500 ms) and the heartbeat consumer time are fixed, and
# the TCG guest on a busy host is now and then starved longer than that.
_enable_try() {
  _e_a=$(isotp_ask enable 60)
  case $_e_a in ok*) pass "enable (attempt $retry_n): $_e_a"; return 0 ;; esac
  log "enable attempt $retry_n: $_e_a"
  return 1
}
_enable_reset() { isotp_ask reset 30 >/dev/null; }
enable_arm() {
  retry 3 _enable_try _enable_reset && return 0
  _enable_reset  # (after the last failed attempt too)
  dump_console_state
  fail "enable: 3 attempts failed, the last: $_e_a"
}
first_contact
enable_arm
wait_state idle 60
st=$(isotp_ask status)
echo "$st" | grep -q 'homing=\[unhomed unhomed unhomed unhomed unhomed unhomed\]' &&
  pass "status before homing: $(echo "$st" | grep -o 'homing=\[[^]]*\]')" || check_fail "status before homing: $st"
a=$(isotp_ask 'movej 0 0 0 0 0 0')
case $a in "error: not_homed"*"joints 1, 2, 3, 4, 5, 6 not homed"*) pass "unhomed movej: $a" ;;
  *) check_fail "unhomed movej: want error: not_homed naming joints 1-6, got '$a'" ;; esac
# armfw's SDO timeout (100 ms, CanopenMasterConfig::sdo_timeout) and its CiA 402 state
# timeouts are fixed (no configuration key yet): in the TCG VM on a busy host armsim now and
# then answers far later than that (seen: an SDO answer after 109 ms, a 6060h = 8 answer after
# 2.7 s with armfw's cycle p99 at 292 ms), and the homing fails naming the drive. Such an
# attempt is reset and homing run again, at most 4 attempts (the count and each cause printed;
# a fault that is not starvation repeats every time and fails the scenario). Everything below
# is judged on the frames of the last attempt.
_home_try() {
  a=$(isotp_ask home)
  case $a in "ok homing: group 1 of 4 (joint 3)"*) pass "home (attempt $retry_n): $a" ;; *) check_fail "home: '$a'" ;; esac
  a=$(isotp_ask wait 300)
  case $a in
    ok*) return 0 ;;
    *"error: fault"*)
      log "homing attempt $retry_n failed (a late answer in the starved VM?): $a"
      case $a in *"timed out"* | *timeout*) ;; *) home_not_timeout=1 ;; esac
      return 1 ;;
    *) return 2 ;;
  esac
}
_home_recover() {
  expect_ok "reset" "$(isotp_ask reset 30)"
  enable_arm
  wait_state idle 60
}
home_not_timeout=0
home_rc=0
retry 4 _home_try _home_recover || home_rc=$?
attempt=$retry_n
# Four attempts lost to timeouts in a VM whose control loop missed more than 1 cycle in 10
# (armfw's own count, printed at its exit): the VM was starved, not the firmware wrong.
# Reported as a skip with the figures, not as a failure (seen with stress-ng --cpu 2 beside
# the test command: 19 688 overruns in 26 218 cycles, loop latency p99 107 ms). Any check
# failed before, or a homing fault that is not a timeout, still fails the scenario.
if [ "$home_rc" -eq 1 ] && [ "$home_not_timeout" = 0 ] && [ "$FAILS" -eq 0 ]; then
  stop_isotprecv
  kill -TERM "$ARMFW_PID" 2>/dev/null || true
  wait "$ARMFW_PID" 2>/dev/null || true
  ex=$(grep 'exit: cycles=' "$OUT_DIR/armfw.log" || true)
  starved=$(echo "$ex" | awk '{ c = 0; o = 0
      if (match($0, /cycles=[0-9]+/)) c = substr($0, RSTART + 7, RLENGTH - 7) + 0
      if (match($0, /overruns=[0-9]+/)) o = substr($0, RSTART + 9, RLENGTH - 9) + 0
      print (c > 0 && 10 * o > c) ? 1 : 0 }')
  if [ "$starved" = 1 ]; then
    skip "the VM was starved: 4 homing attempts ended in SDO/state timeouts and armfw missed more than 1 cycle in 10 ($ex)"
  fi
  check_fail "4 homing attempts ended in timeouts though the VM was not starved ($ex)"
  finish
fi
expect_ok "wait (the homing cycle, attempt $attempt of at most 4)" "$a"
isotp_text | awk '/^ok homing: group 1 of 4/ { n = 0 } /^homing:/ { l[++n] = $0 } END { for (i = 1; i <= n; i++) print l[i] }' \
  >"$OUT_DIR/progress.txt" || true
cat "$OUT_DIR/progress.txt"
# progress: joint 3 first, then 2, then 1, then 4, 5, 6; each homed; done
awk 'BEGIN { want["joint 3 homing (group 1 of 4, cia402)"] = 1; want["joint 2 homing (group 2 of 4, cia402)"] = 2
             want["joint 1 homing (group 3 of 4, cia402)"] = 3; want["joint 6 homing (group 4 of 4, hard_stop)"] = 4 }
     { sub(/^homing: /, "") }
     $0 in want { if (want[$0] != ++k) bad = 1; seen++ }
     /^joint [0-9] homed$/ { homed++ }
     /homing done: every joint homed/ { done = 1 }
     END { printf "progress: %d group starts in order%s, %d joints homed, %s\n", seen, bad ? " (OUT OF ORDER)" : "", homed, done ? "done" : "no done line"
           exit !(seen == 4 && !bad && homed == 6 && done) }' "$OUT_DIR/progress.txt" >"$OUT_DIR/progress.chk" &&
  pass "$(cat "$OUT_DIR/progress.chk")" || check_fail "$(cat "$OUT_DIR/progress.chk")"
st=$(isotp_ask status)
echo "$st"
echo "$st" | grep -q 'homing=\[homed homed homed homed homed homed\]' && pass "status: every joint homed" ||
  check_fail "status after homing: $st"
echo "$st" | awk '{ if (match($0, /joints=\[[^]]*\]/)) { s = substr($0, RSTART + 8, RLENGTH - 9); n = split(s, q, " ") }
                    split("10 -20 30 15 0 -40", g, " "); worst = 0
                    for (i = 1; i <= 6; i++) { e = q[i] - g[i]; if (e < 0) e = -e; if (e > worst) worst = e }
                    printf "joints after homing %s, worst %.4f deg from the offsets (limit 0.01)\n", s, worst; exit !(n == 6 && worst <= 0.01) }' \
  >"$OUT_DIR/homed.txt" && pass "$(cat "$OUT_DIR/homed.txt")" || check_fail "$(cat "$OUT_DIR/homed.txt")"
expect_ok "park" "$(isotp_ask park)"
expect_ok "wait (park)" "$(isotp_ask wait 120)"
st=$(isotp_ask status)
echo "$st" | grep -q 'state=idle' && pass "idle after park" || check_fail "after park: $st"

stop_isotprecv
stop_armfw
grep 'exit: cycles=' "$OUT_DIR/armfw.log" | sed 's/^/armfw (how starved the VM was): /' || true
stop_armsim
stop_candump all
grep '^armsim homed' "$OUT_DIR/armsim.log" || true

tframes "$OUT_DIR/all.log" >"$OUT_DIR/all.tframes"
# the frames up to the `park` request (ISO-TP single frame "park": 7E0#047061726B): the
# positions after homing are read before park moves the joints
# (from the last `home` request, 7E0#04686F6D65, when homing had to be repeated)
last_home=$(awk '{ split($2, p, "#") } p[1] == "7E0" && p[2] == "04686F6D65" { k = NR } END { print k + 0 }' "$OUT_DIR/all.tframes")
awk -v from="$last_home" '{ split($2, p, "#") } p[1] == "7E0" && p[2] == "047061726B" { exit } NR >= from { print }' \
  "$OUT_DIR/all.tframes" >"$OUT_DIR/homing.tframes"
[ "$last_home" -gt 0 ] && pass "the last home request found on the bus (frame $last_home)" || check_fail "no ISO-TP 'home' request on the bus"
cut -d' ' -f2 "$OUT_DIR/homing.tframes" >"$OUT_DIR/all.frames"
[ "$(wc -l <"$OUT_DIR/all.frames")" -lt "$(wc -l <"$OUT_DIR/all.tframes")" ] && pass "the park request found on the bus" ||
  check_fail "no ISO-TP 'park' request (7E0#047061726B) on the bus"
# SDO writes (expedited: 2F = 1 byte, 23 = 4 bytes), little-endian counts
for n in 1 2 3 4 5; do
  case $n in 1) m=13 o=10 ;; 2) m=15 o=-20 ;; 3) m=11 o=30 ;; 4) m=22 o=15 ;; 5) m=23 o=0 ;; esac  # hex of 19 21 17 34 35
  case $n in 4) sw_deg=10 sz_deg=4 ;; *) sw_deg=10 sz_deg=2 ;; esac
  [ "$n" -eq 5 ] && sz_deg=1  # the key's default
  sw=$(le32 "$(awk -v d="$sw_deg" -v c="$cpd" 'BEGIN { printf "%d", d * c + 0.5 }')")
  sz=$(le32 "$(awk -v d="$sz_deg" -v c="$cpd" 'BEGIN { printf "%d", d * c + 0.5 }')")
  oc=$(awk -v d="$o" -v c="$cpd" 'BEGIN { v = d * c; printf "%d", v < 0 ? v - 0.5 : v + 0.5 }')
  for f in "60$n#2F986000${m}000000" "60$n#2F60600006000000"; do
    grep -qx "$f" "$OUT_DIR/all.frames" && pass "node $n: SDO $f" || check_fail "node $n: SDO $f missing"
  done
  for spec in "6099 01 $sw" "6099 02 $sz" "607C 00 $(le32 "$oc")"; do
    set -- $spec
    f="60$n#23$(echo "$1" | cut -c3-4)$(echo "$1" | cut -c1-2)$2$3"
    grep -qx "$f" "$OUT_DIR/all.frames" && pass "node $n: SDO $1h:$2 $f" || check_fail "node $n: SDO $1h:$2 $f missing"
  done
  grep -q "^60$n#239A6000" "$OUT_DIR/all.frames" && pass "node $n: SDO 609Ah (acceleration) written" ||
    check_fail "node $n: no SDO write of 609Ah"
  awk -v n="$n" -v want="$oc" "$AWK_LE"'
      { split($0, p, "#") }
      p[1] == "60" n && p[2] == "2F60600006000000" && !hm { hm = NR }
      p[1] == "20" n && hm && !bit4 && int(le_u(substr(p[2], 1, 4)) / 16) % 2 == 1 { bit4 = NR }
      p[1] == "18" n && bit4 && !att { s = le_u(substr(p[2], 1, 4)); if (int(s / 4096) % 2 == 1 && int(s / 8192) % 2 == 0) att = NR }
      p[1] == "60" n && p[2] == "2F60600008000000" && att && !csp { csp = NR }
      p[1] == "18" n && csp { pos = s32(le_u(substr(p[2], 5, 8))) }
      END { d = pos - want
            printf "node %s: 6060h=6 at frame %d, bit 4 at %d, statusword bit 12 at %d, 6060h=8 at %d; position after %d (607Ch %d, %+d)\n", n, hm, bit4, att, csp, pos, want, d
            exit !(hm && bit4 > hm && att > bit4 && csp > att && d >= -1 && d <= 1) }' \
    "$OUT_DIR/all.frames" >"$OUT_DIR/order_$n.txt" && pass "$(cat "$OUT_DIR/order_$n.txt")" || check_fail "$(cat "$OUT_DIR/order_$n.txt")"
done
# joint 6, hard_stop: never in homing mode; the RPDO targets go down past the stop (pushing
# into it until the following error passes 2 deg), at contact the target steps back once to
# where the shaft stands (the push released: one step of at most the 2 deg limit, upwards),
# then up by the backoff; every other step no faster than 5 deg/s over the master's 50 ms cap;
# the shaft ends at the stop + 3 deg in the drive's own counts (the master, not the drive,
# takes the offset: the joint reads -40 deg, status above).
grep -q '^606#2F60600006' "$OUT_DIR/all.frames" && check_fail "node 6 (hard_stop) was switched to homing mode" ||
  pass "node 6 (hard_stop): no 6060h = 6 (cyclic position throughout)"
awk -v cpd="$cpd" "$AWK_LE"'
    BEGIN { lim = 5 * cpd * 0.05 * 1.1 + 2 }
    { split($2, p, "#") }
    p[1] == "206" && substr(p[2], 1, 4) == "0F00" { v = s32(le_u(substr(p[2], 5, 8)))
      if (c++ && v != pv) { st = v - pv; a = st < 0 ? -st : st
        if (a > lim) { big++; release = st } else if (a > maxstep) maxstep = a
        if (!t1) t1 = $1; t2 = $1 }
      if (c == 1 || v < lo) lo = v; pv = v }
    p[1] == "186" { pos = s32(le_u(substr(p[2], 5, 8))) }
    END { want = -2913 + 3 * cpd
          printf "node 6 (hard_stop): lowest target %d counts (stop -2913), largest RPDO step %d counts (cap %.0f), the release at contact %+d counts (%d such), moving %.2f s; shaft at %d (stop + backoff %.1f, %+.1f)\n", lo, maxstep, lim, release, big, t2 - t1, pos, want, pos - want
          exit !(c > 10 && lo < -2913 && maxstep > 0 && big <= 1 && release >= 0 && release <= 2 * cpd + lim && pos - want >= -2 && pos - want <= 2) }' \
  "$OUT_DIR/homing.tframes" >"$OUT_DIR/hard_stop.txt" && pass "$(cat "$OUT_DIR/hard_stop.txt")" || check_fail "$(cat "$OUT_DIR/hard_stop.txt")"
# the groups' order on the bus (frame numbers of the first 6060h = 6 and of the 6060h = 8 after it)
awk "$AWK_LE"'
    { split($0, p, "#") }
    p[2] == "2F60600006000000" && !h6[p[1]] { h6[p[1]] = NR }
    p[2] == "2F60600008000000" && h6[p[1]] && !h8[p[1]] { h8[p[1]] = NR }
    p[1] == "206" && substr(p[2], 1, 4) == "0F00" { v = le_u(substr(p[2], 5, 8)); if (n6++ && v != pv && !m6) m6 = NR; pv = v }
    END { ok = h8["603"] < h6["602"] && h8["602"] < h6["601"] && h8["601"] < h6["604"] && h8["601"] < h6["605"] && h8["601"] < m6
          printf "order on the bus: node 3 [%d..%d], node 2 [%d..%d], node 1 [%d..%d], nodes 4 %d, 5 %d, 6 first move %d\n", h6["603"], h8["603"], h6["602"], h8["602"], h6["601"], h8["601"], h6["604"], h6["605"], m6
          exit !(ok && h6["603"] && m6) }' "$OUT_DIR/all.frames" >"$OUT_DIR/groups.txt" &&
  pass "$(cat "$OUT_DIR/groups.txt")" || check_fail "$(cat "$OUT_DIR/groups.txt")"
# the marks against the simulated switches, in counts before homing
for spec in 1:1820 2:-1820 3:-2185 4:1820; do
  n=${spec%%:*}; want=${spec#*:}
  awk -v n="$n" -v want="$want" '
      $1 == "armsim" && $2 == "homed" { for (i = 3; i <= NF; i++) { split($i, kv, "="); v[kv[1]] = kv[2] }
                                        if (v["node"] == n) { mark = v["mark"]; seen = 1 } }
      END { d = mark - want; printf "node %s: mark %s, switch at %s (%+.1f counts)\n", n, mark, want, d
            exit !(seen && d >= -1 && d <= 1) }' "$OUT_DIR/armsim.log" >"$OUT_DIR/mark_$n.txt" &&
    pass "$(cat "$OUT_DIR/mark_$n.txt")" || check_fail "$(cat "$OUT_DIR/mark_$n.txt")"
done
# figures (not judged): homing time per node from the kernel timestamps
awk "$AWK_LE"'
    { split($2, p, "#") }
    p[2] == "2F60600006000000" && !a[p[1]] { a[p[1]] = $1 }
    p[2] == "2F60600008000000" && a[p[1]] && !b[p[1]] { b[p[1]] = $1 }
    p[1] == "206" && substr(p[2], 1, 4) == "0F00" { v = le_u(substr(p[2], 5, 8)); if (n6++ && v != pv) { if (!s6) s6 = $1; e6 = $1 }; pv = v }
    END { printf "figures (VM, not judged): 6060h=6 -> 6060h=8 per node:"
          for (n = 1; n <= 5; n++) printf " %d: %.2f s", n, b["60" n] - a["60" n]
          e = e6; if (b["604"] > e) e = b["604"]; if (b["605"] > e) e = b["605"]
          printf "; node 6 hard_stop moving %.2f s; whole cycle (node 3 6060h=6 to the last end) %.2f s\n", e6 - s6, e - a["603"] }' "$OUT_DIR/homing.tframes" | tee "$OUT_DIR/figures.txt"
finish
