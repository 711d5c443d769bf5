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
#   on the host (s8_fw_homing.host-check), the candump of the bus, per CiA 402 node: the SDO writes 6098h, 6099h:01/:02, 609Ah, 607Ch, 6060h = 6,
#     an RPDO with controlword bit 4, a TPDO1 with statusword bit 12 (13 clear), 6060h = 8
#     after it, the last TPDO1 position = 607Ch within one count; joint 6 (hard_stop): no
#     6060h = 6 at all, the RPDO target steps never faster than homing.speed_switch allows
#     (the master caps its step at 50 ms of travel), its final position = its offset;
#   the groups' order on the bus: node 3's 6060h = 8 before node 2's 6060h = 6, node 2's
#     before node 1's, node 1's before 4's and 5's and node 6's first moving RPDO;
#   (host) armsim's "armsim homed" lines: the marks against the simulated switches (one count).
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

# the frames on the bus are checked on the host (s8_fw_homing.host-check)
to_host cpd
finish
