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
# Checked from candump, on the host (s8_homing.host-check): per node the SDO writes 6098h (method), 6099h:01/:02 (speeds),
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

# the frames on the bus are checked on the host (s8_homing.host-check)
to_host  # (nothing: the host check only needs the files)
finish
