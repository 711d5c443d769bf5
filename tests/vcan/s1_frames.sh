# SPDX-License-Identifier: Apache-2.0
# Scenario 1: exact frames on a real vcan.
#  A. frames typed by hand with cansend to armsim node 2 (SDO, PDO mapping,
#     NMT, CiA 402 enable, setpoints, bad lengths) are decoded as CiA 301/402
#     say: the answers match s1_hand.txt byte for byte; NMT by hand moves node
#     1's heartbeat through the NMT states.
#  B. canmaster brings up armsim nodes 1-2 and streams a sine: candump holds
#     exactly the NMT / SDO frames of s1_bringup_master.txt and the answers of
#     s1_bringup_drive.txt, then cycles of RPDO 0x201, 0x202 + SYNC whose
#     controlwords walk the CiA 402 enable sequence and whose little-endian
#     targets are the commanded sine.
. "$SCENARIO_DIR/lib.sh"
need candump cansend armsim canmaster

# ---------------------------------------------------------------- part A
log "A: armsim nodes 1-2, frames by hand"
start_candump hb "$CAN_IF,700:780"
start_candump handA "$CAN_IF,700~780"
start_armsim armsimA --nodes 1-2 --verbose
play_exchange "$SCENARIO_DIR/s1_hand.txt" handA
sleep 0.2
stop_candump handA
frames "$OUT_DIR/handA.log" >"$OUT_DIR/handA.frames"
match_exchange "$SCENARIO_DIR/s1_hand.txt" "$OUT_DIR/handA.frames" "A: SDO/NMT/PDO frames typed by hand answered as CiA 301/402 say"

# Positions in the TPDO1 frames the file expects as exactly 0x3706 (settled,
# target reached): enabled at 0, +4000 reached, -4000 reached, still -4000
# after the 5-byte RPDO, still -4000 in the first frame after "disable
# operation". Bytes 2..5 signed little-endian; encoder quantisation +-1 count.
awk '$1 == "<" || $1 == ">" { print $2 }' "$SCENARIO_DIR/s1_hand.txt" |
  paste - "$OUT_DIR/handA.frames" | awk "$AWK_LE"'$1 == "182#3706xxxxxxxx" { print s32(le_u(substr($2, 9, 8))) }' \
  >"$OUT_DIR/handA.positions"
set -- $(cat "$OUT_DIR/handA.positions")
if [ $# -eq 5 ] && awk -v a="$1" -v b="$2" -v c="$3" -v d="$4" -v e="$5" 'function ab(x) { return x < 0 ? -x : x }
     BEGIN { exit !(ab(a) <= 1 && ab(b - 4000) <= 1 && ab(c + 4000) <= 1 && ab(d + 4000) <= 1 && ab(e + 4000) <= 1) }'; then
  pass "A: TPDO1 positions follow the hand-written RPDO targets 0, +4000, -4000 (ignoring a 5-byte RPDO): $*"
else
  check_fail "A: TPDO1 positions after the moves are '$*', want about 0 4000 -4000 -4000 -4000"
fi

log "A: NMT by hand on node 1 (heartbeat 100 ms)"
cansend "$CAN_IF" 601#2B17100064000000; sleep 0.35
cansend "$CAN_IF" 000#0101; sleep 0.35      # start
cansend "$CAN_IF" 000#0201; sleep 0.35      # stop
cansend "$CAN_IF" 000#8001; sleep 0.35      # pre-operational
cansend "$CAN_IF" 000#8101; sleep 0.35      # reset node: boot-up, 0x1017 back to 0
stop_candump hb
stop_armsim
frames "$OUT_DIR/hb.log" >"$OUT_DIR/hb.frames"
grep '^701#' "$OUT_DIR/hb.frames" | uniq >"$OUT_DIR/hb1.states"
grep '^702#' "$OUT_DIR/hb.frames" | uniq >"$OUT_DIR/hb2.states"
printf '%s\n' '# node 1: boot-up, pre-op, operational, stopped, pre-op, boot-up after reset' \
  701#00 701#7F 701#05 701#04 701#7F 701#00 >"$OUT_DIR/hb1.expected"
printf '%s\n' '# node 2: boot-up only (no heartbeat time set), operational by hand' 702#00 >"$OUT_DIR/hb2.expected"
same_frames "A: node 1 heartbeat states after NMT by hand" "$OUT_DIR/hb1.expected" "$OUT_DIR/hb1.states"
same_frames "A: node 2 heartbeat (boot-up only)" "$OUT_DIR/hb2.expected" "$OUT_DIR/hb2.states"
# heartbeat period: mean interval between node 1's heartbeats (boot-up
# messages excluded) from the kernel timestamps, 100 ms +-15 %
tframes "$OUT_DIR/hb.log" | awk '$2 ~ /^701#/ && $2 != "701#00" { if (n++) sum += $1 - prev; prev = $1 }
    END { m = n > 1 ? sum / (n - 1) * 1000 : 0; printf "%d heartbeats of node 1, mean interval %.1f ms", n, m
          exit !(n >= 8 && m >= 85 && m <= 115) }' >"$OUT_DIR/hb1.period" &&
  pass "A: $(cat "$OUT_DIR/hb1.period") (0x1017 = 100 ms)" || check_fail "A: $(cat "$OUT_DIR/hb1.period"), want 100 ms +-15 %"

# ---------------------------------------------------------------- part B
log "B: canmaster brings up nodes 1-2 and streams a 0.5 Hz sine for 2 s"
start_candump all
start_armsim armsimB --nodes 1-2
mrc=0
canmaster --iface "$CAN_IF" --nodes 1-2 --bringup --stream-sine 2 --amplitude 0.3 --freq 0.5 \
  --period-ms 10 --hb-ms 50 --hb-timeout-ms 400 --counts-per-rev 131072 >"$OUT_DIR/canmaster.log" 2>&1 || mrc=$?
sleep 0.2
stop_armsim
stop_candump all
cat "$OUT_DIR/canmaster.log"
[ "$mrc" -eq 0 ] && pass "B: canmaster exit status 0" || check_fail "B: canmaster exit status $mrc"
grep -q '^bringup status=ok' "$OUT_DIR/canmaster.log" || check_fail "B: canmaster did not report 'bringup status=ok'"
grep -q '^result status=ok' "$OUT_DIR/canmaster.log" || check_fail "B: canmaster did not report 'result status=ok'"

tframes "$OUT_DIR/all.log" >"$OUT_DIR/all.tframes"
cut -d' ' -f2 "$OUT_DIR/all.tframes" >"$OUT_DIR/all.frames"
# Master -> drives: NMT, SYNC, RPDO1, SDO requests. Bring-up = everything before the first RPDO.
grep -E '^(000|080|20[12]|60[12])#' "$OUT_DIR/all.frames" >"$OUT_DIR/master.frames"
awk '/^20[12]#/ { exit } { print }' "$OUT_DIR/master.frames" >"$OUT_DIR/bringup.frames"
{ echo 000#8001; echo 000#8002
  node_template "$SCENARIO_DIR/s1_bringup_master.txt" 1
  node_template "$SCENARIO_DIR/s1_bringup_master.txt" 2
  echo 000#0101; echo 000#0102; } >"$OUT_DIR/bringup.expected"
same_frames "B: master bring-up frames (NMT, SDO) for nodes 1, 2" "$OUT_DIR/bringup.expected" "$OUT_DIR/bringup.frames"
grep -E '^58[12]#' "$OUT_DIR/all.frames" >"$OUT_DIR/sdo_answers.frames"
{ node_template "$SCENARIO_DIR/s1_bringup_drive.txt" 1
  node_template "$SCENARIO_DIR/s1_bringup_drive.txt" 2; } >"$OUT_DIR/sdo_answers.expected"
same_frames "B: drive SDO answers for nodes 1, 2" "$OUT_DIR/sdo_answers.expected" "$OUT_DIR/sdo_answers.frames"

# Cycles: after bring-up, the master sends exactly RPDO 0x201, RPDO 0x202, SYNC, repeated.
sed -n '/^20[12]#/,$p' "$OUT_DIR/master.frames" >"$OUT_DIR/cycles.frames"
awk -F'#' '{ want = (NR % 3 == 1) ? "201" : (NR % 3 == 2) ? "202" : "080"
             if ($1 != want) { printf "cycle frame %d is %s, want id %s\n", NR, $0, want; bad = 1; exit }
             if (want != "080" && length($2) != 12) { printf "RPDO %s is not 6 bytes\n", $0; bad = 1; exit }
             if (want == "080" && $2 != "") { printf "SYNC %s has data\n", $0; bad = 1; exit } }
           END { exit bad }' "$OUT_DIR/cycles.frames" >"$OUT_DIR/cycles.err" &&
  pass "B: $(grep -c '^080#' "$OUT_DIR/master.frames") cycles of RPDO 0x201, 0x202 (6 bytes) + SYNC" ||
  check_fail "B: cycle structure broken: $(cat "$OUT_DIR/cycles.err")"
for n in 1 2; do
  # controlwords (bytes 0..1, LE), collapsed: optional 0x0000 before the first
  # statusword, then shutdown 0x0006, switch on 0x0007, enable operation 0x000F;
  # at the end optionally disable operation 0x0007 then shutdown 0x0006.
  cws=$(awk -F'#' -v id="20$n" '$1 == id { print substr($2, 3, 2) substr($2, 1, 2) }' "$OUT_DIR/master.frames" | uniq | tr '\n' ' ')
  case "$cws" in
    "0006 0007 000F "*|"0000 0006 0007 000F "*) pass "B: node $n controlwords $cws" ;;
    *) check_fail "B: node $n controlwords '$cws', want [0000] 0006 0007 000F ..." ;;
  esac
  # streamed targets while enabled (cw 0x000F): the sine of amplitude 0.3 rad =
  # 0.3 * 131072 / 2pi = 6258 counts (canmaster shifts joint j's phase by 0.5 j
  # rad, so only the negative peak is inside the 2 s window for both joints)
  check_sine_targets "B: node $n RPDO targets" "$OUT_DIR/all.tframes" "20$n" 6258 0.5 0.010
  # heartbeats: boot-up, pre-operational (once 0x1017 is written), operational (after NMT start)
  hbs=$(grep "^70$n#" "$OUT_DIR/all.frames" | uniq | tr '\n' ' ')
  [ "$hbs" = "70$n#00 70$n#7F 70$n#05 " ] && pass "B: node $n heartbeats $hbs" ||
    check_fail "B: node $n heartbeats '$hbs', want 70$n#00 70$n#7F 70$n#05"
done
finish
