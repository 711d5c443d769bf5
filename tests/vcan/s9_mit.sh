# SPDX-License-Identifier: Apache-2.0
# Scenario 9: MIT-mode motors on SocketCAN. armsim --mit serves six Damiao DM-J4340 (ids 1-6,
# master ids 0x11-0x16) and a seventh motor in position-velocity mode (id 7) on $CAN_IF, in CAN
# FD when the interface takes it (mtu 72), else classic; armfw (bus.can = $CAN_IF, console over
# ISO-TP) drives the six as the puma560's joints (without gravity: the virtual motors carry no
# load, and free-drive sends the model's gravity torque). Checked from candump, byte by byte:
#   - bring-up: each motor's CTRL_MODE read, written to 1 (MIT) on motor 3 (powered up in
#     position-velocity mode), its CAN timeout written to bus.heartbeat_timeout_ms (0x7FF
#     register frames), then the enable frame FF..FC on its id;
#   - the MIT frames of a movej: on ids 1-6 only, kp / kd as configured, every position decoded
#     within the joint's limits, the last one at the movej's goal;
#   - free-drive: the frames go out with kp = kd = 0 and the torque code nearest 0 (no gravity,
#     no damping): 2048 of 0..4095, +0.0068 N m on +-28 N m, half a code; the virtual motor has
#     viscous damping (0.05 N m s/rad) and no static friction, so that half code turns it at
#     0.137 rad/s (7.8 deg/s): the joints creep no faster than 9 deg/s (a real motor's friction
#     holds it), no runaway;
#   - armfw killed: the motors' own watchdog disables them (error 0xD, communication lost), seen
#     by the drive doctor, which finds the six motors and the one in the wrong mode;
#   - before armfw starts, `armctl drives check` of the same configuration: every joint ok, the
#     motor in position-velocity mode a note, motor 7 named as no joint's; on CAN FD also the
#     check and a scan in classic CAN, the motors' stand-in for another bitrate: not seen, said so.
. "$SCENARIO_DIR/lib.sh"
. "$SCENARIO_DIR/s5_lib.sh"
need candump isotpsend isotprecv isotpsniffer armsim armfw armctl od mkfifo

fd=0
if ip link set dev "$CAN_IF" down && ip link set dev "$CAN_IF" mtu 72 && ip link set dev "$CAN_IF" up; then fd=1
else ip link set dev "$CAN_IF" up; fi
if [ "$fd" = 1 ]; then log "CAN FD on $CAN_IF (mtu 72)"; mit_fd=--mit-fd fd_key=true scan_fd=--fd
else log "classic CAN on $CAN_IF (no CAN FD)"; mit_fd= fd_key=false scan_fd=; fi

# puma560 without gravity (same kinematics, limits and inertias)
{ echo 'gravity = [0, 0, 0]'; grep -v '^gravity' "$SCENARIO_DIR/puma560.toml"; } >"$OUT_DIR/puma560_nog.toml"
# The motors' CAN timeout is bus.heartbeat_timeout_ms: 1 s, longer than the VM's worst stalls
# (a busy host starves the emulated CPUs for up to ~0.6 s), so a stall does not trip it.
hb_timeout_ms=1000
write_armfw_config "$OUT_DIR/armfw.toml" --own-drives
sed -i "s|^robot = .*|robot = \"$OUT_DIR/puma560_nog.toml\"|" "$OUT_DIR/armfw.toml"
# following error limit 90 deg: a starved VM (armsim or armfw descheduled for a few hundred ms
# during the movej) lets a joint fall 20 deg behind; the scenario is about the frames, the limit
# has its own tests (fw_mit_arm)
sed -i "s|^following_error_deg = .*|following_error_deg = 90|" "$OUT_DIR/armfw.toml"
# free-drive without gravity and without virtual damping (the virtual motors' inertia is not the
# model's: a damping torque sized for the puma's links would not be stable on them): torque 0
printf '[dynamics]\nfreedrive = true\nfreedrive_damping = 0\n' >>"$OUT_DIR/armfw.toml"
for j in 1 2 3 4 5 6; do
  printf '[[drive]]\nfamily = "damiao"\nmotor = "DM-J4340"\nnode = %d\ncan_fd = %s\nmit_kp = 60\nmit_kd = 2\nhoming.method = "absolute"\n' \
    "$j" "$fd_key" >>"$OUT_DIR/armfw.toml"
done

start_candump all -r 4194304 "$CAN_IF,000:F00,7FF:7FF"   # ids 0x000-0x0FF (MIT commands and answers) and 0x7FF
# motor 3 powers up in position-velocity mode (armfw switches it to MIT); motor 7, in the same
# mode, is no joint's (the drive doctor reports it)
start_armsim armsim --nodes none --mit DM-J4340:1 --mit DM-J4340:2 --mit DM-J4340:3 --mit DM-J4340:4 \
  --mit DM-J4340:5 --mit DM-J4340:6 --mit DM-J8006:7 --mit-mode 3:2 --mit-mode 7:2 $mit_fd
# the drive doctor before armfw runs: the configuration against the bus (exit 0; motor 3's mode
# and the CAN timeouts are notes, armfw sets them; motor 7 is no joint's), and, on CAN FD, the
# configuration and a scan in the other frame format (what a motor at another bitrate looks like:
# not seen, said so)
csrc=0
armctl drives check --config "$OUT_DIR/armfw.toml" --timeout 300 >"$OUT_DIR/check.txt" 2>&1 || csrc=$?
if [ "$fd" = 1 ]; then
  sed 's/^can_fd = true/can_fd = false/' "$OUT_DIR/armfw.toml" >"$OUT_DIR/armfw_classic.toml"
  wcrc=0
  armctl drives check --config "$OUT_DIR/armfw_classic.toml" --timeout 300 >"$OUT_DIR/check_classic.txt" 2>&1 || wcrc=$?
  wsrc=0
  armctl drives scan --iface "$CAN_IF" --last 16 --timeout 300 >"$OUT_DIR/scan_classic.txt" 2>&1 || wsrc=$?
fi
start_isotprecv
log "armfw: ${rate_hz} Hz, CAN timeout ${hb_timeout_ms} ms"
t_armfw=$(date +%s.%N)
start_armfw "$OUT_DIR/armfw.toml"
first_contact
# each step's answer must be ok; else armfw's log says why and the scenario stops there
step() {
  _s_a=$(isotp_ask "$1" "${2:-30}")
  case $_s_a in
    ok*) pass "$1: $_s_a" ;;
    *) check_fail "$1: want ok, got '$_s_a'"; isotp_ask status 10; echo "--- armfw.log"; tail -n 30 "$OUT_DIR/armfw.log"
       kill -KILL "$ARMFW_PID" "$ARMSIM_PID" 2>/dev/null; stop_isotprecv; stop_candump all; finish ;;
  esac
}
step enable 60
step status
goal="20 -30 40 15 -20 30"
step "movej $goal speed=50"
step wait 60
step "freedrive on"
sleep 1
step status
log "kill -KILL armfw (the motors' watchdog must stop them)"
kill -KILL "$ARMFW_PID"; wait "$ARMFW_PID" 2>/dev/null
stop_isotprecv
sleep 1
src=0
armctl drives scan --iface "$CAN_IF" $scan_fd --last 16 --timeout 300 >"$OUT_DIR/scan.txt" 2>&1 || src=$?
stop_armsim
stop_candump all
cat "$OUT_DIR/scan.txt"
ip link set dev "$CAN_IF" down; ip link set dev "$CAN_IF" mtu 16; ip link set dev "$CAN_IF" up

# "ID#DATA" with the FD flags nibble dropped
tframes "$OUT_DIR/all.log" | sed 's/##[0-9A-F]/#/' >"$OUT_DIR/all.tframes"
cut -d' ' -f2 "$OUT_DIR/all.tframes" >"$OUT_DIR/all.frames"
if [ "$fd" = 1 ]; then
  if grep -E ' 0[0-9A-F]{2}#' "$OUT_DIR/all.log" | grep -qv '##'; then check_fail "classic frames among the MIT frames on an FD bus"
  else pass "every frame on ids 0x000-0x0FF is a CAN FD frame"; fi
fi

# bring-up, byte by byte: 7FF#<id lo><id hi> <33 read | 55 write> <rid> <value le32>: CTRL_MODE
# (0x0A) read, written to 1 where it is not (motor 3), TIMEOUT (0x09) written, then enable
timeout_units=$((hb_timeout_ms * 20))   # 50 us units
for n in 1 2 3 4 5 6; do
  mode_r="7FF#0${n}00330A00000000"
  mode_w="7FF#0${n}00550A01000000"
  tmo_w="7FF#0${n}005509$(le32 "$timeout_units")"
  en="00$n#FFFFFFFFFFFFFFFC"
  first() { grep -n -m1 "^$1\$" "$OUT_DIR/all.frames" | cut -d: -f1; }
  lr=$(first "$mode_r"); lm=$(first "$mode_w"); lt=$(first "$tmo_w"); le=$(first "$en")
  if [ "$n" = 3 ]; then want_w=1; else want_w=0; fi
  if [ -n "$lr" ] && [ -n "$lt" ] && [ -n "$le" ] && [ "$lr" -lt "$le" ] && [ "$lt" -lt "$le" ] &&
     { { [ "$want_w" = 1 ] && [ -n "$lm" ] && [ "$lm" -lt "$le" ]; } || { [ "$want_w" = 0 ] && [ -z "$lm" ]; }; }; then
    pass "motor $n: $mode_r (CTRL_MODE read)$([ "$want_w" = 1 ] && echo ", $mode_w (set to MIT)"), $tmo_w (CAN timeout $hb_timeout_ms ms), then $en (enable)"
  else
    check_fail "motor $n: want $mode_r$([ "$want_w" = 1 ] && echo " and $mode_w" || echo " (no CTRL_MODE write)") and $tmo_w before $en; lines ${lr:-none}, ${lm:-none}, ${lt:-none}, ${le:-none}"
  fi
done

# bring-up time (a figure, not checked): armfw's first register frame on 0x7FF to its last one
# before the first enable frame
awk -v t0="$t_armfw" '$1 >= t0 && $2 ~ /^7FF#/ && !e { if (!a) a = $1; l = $1; n++ }
  $2 ~ /^00[1-6]#FFFFFFFFFFFFFFFC$/ && !e { e = $1 }
  END { if (a && l) printf "bring-up of the six motors: %.1f ms, %d register frames (first to last 0x7FF frame of armfw)\n", (l - a) * 1000, n }' \
  "$OUT_DIR/all.tframes" | while read -r line; do log "$line"; done

# MIT frames: p 16 bits over [-12.5, 12.5] rad, v 12, kp 12 over [0, 500], kd 12 over [0, 5], t 12
awk -v goal="$goal" "$AWK_LE"'
  BEGIN { split("-160 -225 -45 -110 -100 -266", lo, " "); split("160 45 225 170 100 266", hi, " "); split(goal, g, " ")
          kp60 = 491; kd2 = 1638 }
  { split($2, f, "#"); id = f[1]; d = f[2] }
  id ~ /^00[1-6]$/ && length(d) == 16 && substr(d, 1, 14) != "FFFFFFFFFFFFFF" {
    j = id + 0
    p = hexval(substr(d, 1, 4)) * 25 / 65535 - 12.5; deg = p * 180 / 3.14159265358979
    kp = hexval(substr(d, 8, 3)); kd = hexval(substr(d, 11, 3))
    n[j]++
    if (deg < lo[j] - 0.05 || deg > hi[j] + 0.05) { out++; if (!bad) bad = sprintf("joint %d at %.2f deg (limits %d..%d)", j, deg, lo[j], hi[j]) }
    if (kp == kp60) { if (kd != kd2) wrongkd++; pos[j]++; last[j] = deg; if (free[j]) back++ }
    else if (kp == 0 && kd == 0) { free[j]++; if (!f0[j]) { f0[j] = 1; fstart[j] = deg; t0[j] = $1 }; fend[j] = deg; t1[j] = $1
                                   tq = hexval(substr(d, 14, 3)); if (tq < 2046 || tq > 2049) ftq++ }
    else { other++; if (!oth) oth = $2 } }
  id ~ /^0[0-9A-F][0-9A-F]$/ && id !~ /^00[1-7]$/ && id !~ /^01[1-7]$/ { stray++; if (!sid) sid = id }
  END {
    ok = !out && !other && !wrongkd && !back && !stray && !ftq
    for (j = 1; j <= 6; j++) {
      e = last[j] - g[j]; if (e < 0) e = -e; dd = fend[j] - fstart[j]; if (dd < 0) dd = -dd
      rate = t1[j] > t0[j] ? dd / (t1[j] - t0[j]) : 0
      printf "  joint %d: %d MIT frames, %d at kp 60 kd 2 ending at %.3f deg (goal %s), %d in free-drive (kp 0, kd 0) moving %.3f deg in %.2f s (%.2f deg/s)\n", j, n[j], pos[j], last[j], g[j], free[j], dd, t1[j] - t0[j], rate
      if (pos[j] < 50 || e > 0.05 || free[j] < 20 || rate > 9) ok = 0 }
    printf "  %d outside the limits%s, %d with another kp%s, %d at kp 60 with kd not 2, %d at kp 60 after free-drive, %d frames on other ids%s, %d free-drive torques not 0\n",
      out + 0, bad ? " (first: " bad ")" : "", other + 0, oth ? " (first " oth ")" : "", wrongkd + 0, back + 0, stray + 0, sid ? " (first " sid ")" : "", ftq + 0
    exit !ok }' "$OUT_DIR/all.tframes" >"$OUT_DIR/mit.txt" && pass "MIT frames:" || check_fail "MIT frames:"
cat "$OUT_DIR/mit.txt"

# the watchdog: after the kill each motor's feedback (on 0x011-0x016, first byte = error << 4 | id)
# says D (communication lost), as the scan's status query shows
for n in 1 2 3 4 5 6; do
  if grep -q "^id 0x0$n: damiao DM-J4340 .*, error communication lost.*(13)" "$OUT_DIR/scan.txt" &&
     grep -q "^01$n#D$n" "$OUT_DIR/all.frames"; then
    pass "motor $n stopped by its watchdog (feedback 01$n#D$n..., communication lost)"
  else
    check_fail "motor $n: no 'communication lost' after armfw was killed"
  fi
done
if [ "$src" -eq 0 ] && grep -q '^7 drives on ' "$OUT_DIR/scan.txt"; then pass "drive doctor: 7 motors found"
else check_fail "drive doctor: exit $src, want 7 drives"; fi
if grep -q '^id 0x07: damiao DM-J8006 .*mode 2 position-velocity (not MIT' "$OUT_DIR/scan.txt"; then
  pass "drive doctor: id 7 in position-velocity mode, said so"
else check_fail "drive doctor: id 7's wrong mode not reported"; fi
cat "$OUT_DIR/check.txt"
fmt_name=$([ "$fd" = 1 ] && echo "CAN FD" || echo "classic CAN")
ok_joints=0
for n in 1 2 3 4 5 6; do
  grep -q "^joint $n (damiao id $n on $CAN_IF): ok, DM-J4340, $fmt_name" "$OUT_DIR/check.txt" && ok_joints=$((ok_joints + 1))
done
if [ "$csrc" -eq 0 ] && [ "$ok_joints" = 6 ] && grep -q '^the configuration matches the buses' "$OUT_DIR/check.txt" &&
   grep -q "^joint 3 .*note: mode 2 position-velocity: armfw sets MIT" "$OUT_DIR/check.txt" &&
   grep -q "^$CAN_IF: id 0x07: damiao DM-J8006 .*no joint names it" "$OUT_DIR/check.txt"; then
  pass "drive doctor check: 6 joints ok ($fmt_name), joint 3's mode a note, id 7 named as no joint's, exit 0"
else check_fail "drive doctor check: exit $csrc, $ok_joints of 6 joints ok"; fi
if [ "$fd" = 1 ]; then
  cat "$OUT_DIR/check_classic.txt" "$OUT_DIR/scan_classic.txt"
  unseen=$(grep -c "^joint [1-6] (damiao id [1-6] on $CAN_IF): not seen (no answer to a register read in classic CAN): a motor set to CAN FD needs drive.can_fd = true" "$OUT_DIR/check_classic.txt")
  if [ "$wcrc" -eq 1 ] && [ "$unseen" = 6 ] && grep -q '^6 things to change before armfw runs on this arm' "$OUT_DIR/check_classic.txt"; then
    pass "drive doctor check with can_fd = false on the CAN FD motors: 6 joints not seen, each saying drive.can_fd = true, exit 1"
  else check_fail "drive doctor check in the wrong frame format: exit $wcrc, $unseen of 6 joints not seen"; fi
  if [ "$wsrc" -eq 1 ] && grep -q "^no drive answered on $CAN_IF (classic CAN, ids 1-16): check the bitrate, the frame format (--fd)" "$OUT_DIR/scan_classic.txt"; then
    pass "drive doctor scan in classic CAN on the CAN FD motors: nothing seen, said so, exit 1"
  else check_fail "drive doctor scan in the wrong frame format: exit $wsrc"; fi
fi
finish
