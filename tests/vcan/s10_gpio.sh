# SPDX-License-Identifier: Apache-2.0
# Scenario 10: armfw's GPIO safety inputs on real kernel GPIO lines. The kernel's GPIO simulator
# (gpio-sim, built out of tree by host_sim/vm/build-gpio-sim and loaded with run-scenario
# --kmod gpio-sim) gives a chip, labelled servoarm-safety, of 4 lines made through configfs; a
# line's input level is set through its sysfs `pull` attribute (pull-up: 1, pull-down: 0). armfw
# reads them through libgpiod (hal/src/gpiod_input.cpp), its console over ISO-TP, six armsim
# drives on $CAN_IF (as s5):
#   safety.estop_input   = gpio:servoarm-safety:0 (the chip by its label), active "low" (the
#                          default: a normally closed contact, 1 = released)
#   safety.reduced_input = gpio:gpiochipN:1 (the chip by its name), active "high"
#   safety.stop = "drive": the e-stop is the drives' Quick Stop (controlword 0x0002)
# Checked:
#   1. both lines released: enable, movej, wait answered ok, the joints at the goal, mode normal;
#   2. the Reduced line pulled up: `warning: safety mode reduced: Reduced input gpio:... asserted`,
#      `safety` shows mode=reduced with the Reduced TCP speed limit; pulled down: the operator's
#      mode (normal) again, without any confirmation, `warning: safety mode normal: ... released`;
#   3. the e-stop line pulled down while a movej runs: `alarm: estop: e-stop input ... asserted`,
#      the drives' Quick Stop on the bus (the time from the `pull` write, marked by a frame 7F0#01 sent just before it, to
#      the first RPDO with controlword 0x0002, from candump's kernel timestamps, measured on the
#      host by s10_gpio.host-check: a figure in $OUT_DIR/estop.txt, bound only loosely at
#      500 ms: the VM is emulated), the
#      joints at rest, `enable` refused naming the input while it is asserted; pulled up: the
#      release event naming it, then reset and enable; armfw read both lines on their edge
#      events (no "no edge events" fallback line); the CPU of armfw's threads, a figure;
#   4. lines that are not there (offset 7 of the 4-line chip; a chip label no chip has): armfw
#      starts (fail safe: an unreadable input counts as asserted), says why in one line per input
#      (`gpio:servoarm-safety:7: the chip has no such line`, `... the chip cannot be opened`),
#      and refuses `enable` naming the e-stop input.
. "$SCENARIO_DIR/lib.sh"
. "$SCENARIO_DIR/s5_lib.sh"
need candump cansend isotpsend isotprecv isotpsniffer armsim armfw od mkfifo

# --- the simulated chip
cfs=/sys/kernel/config
if [ ! -d "$cfs/gpio-sim" ]; then
  mount -t configfs none "$cfs" 2>/dev/null || true
  [ -d "$cfs/gpio-sim" ] || skip "no gpio-sim in this kernel's configfs (run-scenario --kmod gpio-sim loads it in the VM)"
fi
chipd=$cfs/gpio-sim/servoarm
mkdir "$chipd" "$chipd/bank0" || fail "cannot create a gpio-sim chip in $chipd"
echo 4 >"$chipd/bank0/num_lines"
echo servoarm-safety >"$chipd/bank0/label"
echo 1 >"$chipd/live" || fail "gpio-sim: the chip does not go live"
chip=$(cat "$chipd/bank0/chip_name")
lines=/sys/devices/platform/$(cat "$chipd/dev_name")/$chip
[ -f "$lines/sim_gpio0/pull" ] || fail "gpio-sim: no $lines/sim_gpio0/pull"
log "gpio-sim: $chip (label servoarm-safety, 4 lines) at $lines"
# set_line N up|down: the line's input level through its pull; waits until the line reads it
set_line() {
  echo "pull-$2" >"$lines/sim_gpio$1/pull"
  _l_want=1; [ "$2" = down ] && _l_want=0
  [ "$(cat "$lines/sim_gpio$1/value")" = "$_l_want" ] || check_fail "gpio-sim line $1: pull-$2 reads $(cat "$lines/sim_gpio$1/value")"
}
estop_src=gpio:servoarm-safety:0
reduced_src=gpio:$chip:1
set_line 0 up      # e-stop released (active low)
set_line 1 down    # Reduced released (active high)

# add_safety FILE LINES...: lines appended to the [safety] section of an armfw configuration
add_safety() {
  _f=$1; shift
  printf '%s\n' "$@" >/tmp/s10_add
  awk 'FNR == NR { add = add $0 "\n"; next } { print } /^\[safety\]$/ { printf "%s", add }' /tmp/s10_add "$_f" >"$_f.new"
  mv "$_f.new" "$_f"
}
# Heartbeats: a 1 s consumer timeout (s8_fw_homing's in the VM; s5_lib's 300 ms, and its 900 ms
# feedback timeout, failed here once at load 6: joint 1's feedback 909 ms late in the guest
# while the stall probe saw 160 ms), and the inputs' staleness limit (safety.input_timeout_ms)
# 1 s: a reading thread waits for its line's edges and wakes every 50 ms without one (a quarter
# of the limit, at most 50 ms); a guest stalled longer than the limit would read as lost. None
# of that is a drive's or a GPIO line's fault; the timeouts have their own tests
# (fw_safety_inputs, hal_gpiod, s3).
hb_timeout_ms=1000
write_armfw_config "$OUT_DIR/armfw.toml"
# following error limit 90 deg (as s9): a starved VM lets a joint fall 20 deg behind during a
# movej; the scenario is about the inputs, the limit has its own tests
sed -i "s|^following_error_deg = .*|following_error_deg = 90|" "$OUT_DIR/armfw.toml"
add_safety "$OUT_DIR/armfw.toml" 'stop = "drive"' "estop_input = \"$estop_src\"" \
  "reduced_input = \"$reduced_src\"" 'reduced_input_active = "high"' \
  'tcp_speed_mm_s = 2000' 'reduced_tcp_speed_mm_s = 250' 'input_timeout_ms = 1000'

# RPDOs 0x200-0x207, SYNC, heartbeats 0x700-0x707, the console ids 0x7E0 / 0x7E8, and 0x7F0: the
# scenario's marker, sent just before it writes the e-stop line's pull (busybox date has no
# %N: the marker's kernel timestamp is the write's time on candump's clock, a few ms early).
start_candump all -r 4194304 "$CAN_IF,200:C00007F8,080:C00007FF,700:C00007F8,7E0:C00007F7,7F0:C00007FF"
start_armsim armsim --nodes 1-6
start_isotprecv
log "armfw: e-stop input $estop_src (active low), Reduced input $reduced_src (active high), ${rate_hz} Hz"
start_armfw "$OUT_DIR/armfw.toml"
first_contact
# has_line TEXT: armfw sent a console line starting with TEXT
has_line() { isotp_text | grep -qF -- "$1"; }
# until SECONDS WHAT CMD...: CMD until it succeeds, for at most SECONDS of the guest's uptime
# (wait_until counts 50 ms sleeps, which a CMD that asks armfw over ISO-TP stretches)
until_s() {
  _u_end=$(awk -v s="$1" '{ printf "%d", $1 + s }' /proc/uptime); _u_what=$2; shift 2
  while ! "$@"; do
    read -r _u_now _ </proc/uptime
    [ "${_u_now%.*}" -lt "$_u_end" ] || fail "timed out waiting for $_u_what"
    nap 0.05
  done
}
# joints: the joints= list of a status line
joints_of() { echo "$1" | sed -n 's/.*joints=\[\([^]]*\)\].*/\1/p'; }

# --- 1. released lines: the arm enables and moves
expect_ok "enable (both inputs released)" "$(isotp_ask enable 60)"
until_s 60 "state=idle" _state_is idle
goal="10 -20 40 5 -20 10"
expect_ok "movej" "$(isotp_ask "movej $goal speed=30")"
expect_ok "wait (movej)" "$(isotp_ask wait 120)"
st=$(isotp_ask status)
echo "$st"
joints_of "$st" | awk -v goal="$goal" '{ n = split($0, q, " "); split(goal, g, " "); worst = 0
    for (i = 1; i <= 6; i++) { e = q[i] - g[i]; if (e < 0) e = -e; if (e > worst) worst = e }
    printf "movej with the GPIO lines released: joints %s, worst error %.3f deg (limit 0.1)\n", $0, worst
    exit !(n == 6 && worst <= 0.1) }' >"$OUT_DIR/movej.txt" && pass "$(cat "$OUT_DIR/movej.txt")" || check_fail "$(cat "$OUT_DIR/movej.txt")"
sf=$(isotp_ask safety)
case $sf in *mode=normal*tcp_speed_mm_s=2000*) pass "safety: $sf" ;; *) check_fail "safety with the Reduced line released: want mode=normal tcp_speed_mm_s=2000, got '$sf'" ;; esac
if isotp_text | grep -q -e '^warning: .*input' -e '^alarm: estop'; then
  check_fail "an input event with both lines released: $(isotp_text | grep -e '^warning: .*input' -e '^alarm: estop' | head -n 1)"
else pass "no input event while both lines read released"; fi

# --- 2. the Reduced line
log "Reduced line ($reduced_src) pulled up: asserted"
set_line 1 up
want="warning: safety mode reduced: Reduced input $reduced_src asserted"
_red_on() { has_line "$want"; }
wait_until 10 "'$want'" _red_on
pass "$want"
sf=$(isotp_ask safety)
case $sf in *mode=reduced*tcp_speed_mm_s=250*) pass "safety with the Reduced line asserted: $sf" ;;
  *) check_fail "safety with the Reduced line asserted: want mode=reduced tcp_speed_mm_s=250, got '$sf'" ;; esac
log "Reduced line pulled down: released"
set_line 1 down
want="warning: safety mode normal: Reduced input $reduced_src released"
_red_off() { has_line "$want"; }
wait_until 10 "'$want'" _red_off
pass "$want (no confirmation asked)"
sf=$(isotp_ask safety)
case $sf in *mode=normal*tcp_speed_mm_s=2000*) pass "safety after the release: $sf" ;;
  *) check_fail "safety after the Reduced line's release: want mode=normal tcp_speed_mm_s=2000, got '$sf'" ;; esac

# --- 3. the e-stop line while a move runs
a=$(isotp_ask 'movej -10 -30 60 -5 -10 -10 speed=10')
case $a in ok*) pass "movej (to be stopped): $a" ;; *) tail -n 20 "$OUT_DIR/armfw.log"; fail "movej (to be stopped): want ok, got '$a'" ;; esac
_moving() { isotp_ask status 10 | grep -q 'state=moving'; }
until_s 30 "state=moving" _moving
sleep 0.5
log "e-stop line ($estop_src) pulled down: asserted"
cansend "$CAN_IF" 7F0#01 || check_fail "cansend of the marker frame 7F0#01 failed"
echo pull-down >"$lines/sim_gpio0/pull"
[ "$(cat "$lines/sim_gpio0/value")" = 0 ] || check_fail "gpio-sim line 0 does not read 0 after pull-down"
until_s 30 "state=estop" _state_is estop
want="alarm: estop: e-stop input $estop_src asserted (send reset, then enable)"
_alarm() { has_line "$want"; }
wait_until 10 "'$want' on the console" _alarm
pass "$want"
s1=$(isotp_ask status); sleep 0.5; s2=$(isotp_ask status)
if [ -n "$(joints_of "$s1")" ] && [ "$(joints_of "$s1")" = "$(joints_of "$s2")" ]; then
  pass "the arm at rest after the stop: joints [$(joints_of "$s2")] unchanged over 0.5 s"
else check_fail "the arm not at rest after the e-stop: [$(joints_of "$s1")] then [$(joints_of "$s2")]"; fi
a=$(isotp_ask enable 30)
case $a in "error: fault the e-stop input $estop_src is asserted: release it first"*) pass "enable while asserted: $a" ;;
  *) check_fail "enable while the e-stop line is asserted: want 'error: fault the e-stop input $estop_src is asserted: release it first', got '$a'" ;; esac
log "e-stop line pulled up: released"
set_line 0 up
want="warning: e-stop input $estop_src released: \`reset\` clears the emergency stop"
_es_off() { has_line "$want"; }
wait_until 10 "'$want'" _es_off
pass "$want"
expect_ok "reset (e-stop line released)" "$(isotp_ask reset)"
expect_ok "enable (e-stop line released)" "$(isotp_ask enable 60)"
until_s 60 "state=idle" _state_is idle
sleep 0.3
# CPU time of armfw's threads so far (utime + stime, clock ticks), for the figures: the control
# thread, the two GPIO reading threads, the console's
_hz=$(getconf CLK_TCK 2>/dev/null || echo 100)
_up=$(cut -d' ' -f1 /proc/uptime)
for _t in /proc/"$ARMFW_PID"/task/*; do
  sed 's/^[0-9]* (\([^)]*\)) /\1 /' "$_t/stat" | awk -v tid="${_t##*/}" -v hz="$_hz" -v up="$_up" '
    { printf "armfw thread %s (%s): %.2f s of CPU in %.1f s since it started\n", tid, $1, ($13 + $14) / hz, up - $21 / hz }'
done | tee "$OUT_DIR/threads.txt"
stop_armfw
stop_isotprecv
stop_armsim
stop_candump all
# (the second armfw below writes these names again)
mv "$OUT_DIR/armfw.log" "$OUT_DIR/armfw_lines.log"; isotp_text >"$OUT_DIR/console_lines.txt"
# gpio-sim's lines give edge events: armfw waits for them, it does not fall back to polling
if grep -q 'no edge events' "$OUT_DIR/armfw_lines.log"; then
  check_fail "armfw polls a gpio-sim line: $(grep 'no edge events' "$OUT_DIR/armfw_lines.log" | head -n 1)"
else pass "both lines read on their edge events (no 'no edge events' line from armfw)"; fi
# the e-stop's reaction on the bus is measured on the host (s10_gpio.host-check) from all.log
capture_on=$([ "${SERVOARM_VM:-0}" = 1 ] && echo "emulated TCG VM" || echo host)
to_host rate_hz capture_on
isotp_text | grep -q '^alarm: fault' && check_fail "armfw raised a fault: $(isotp_text | grep '^alarm: fault' | head -n 1)"

# --- 4. lines that are not there
write_armfw_config "$OUT_DIR/armfw_missing.toml"
add_safety "$OUT_DIR/armfw_missing.toml" 'input_timeout_ms = 1000' 'estop_input = "gpio:servoarm-safety:7"' 'reduced_input = "gpio:no-such-chip:0"'
start_armsim armsim2 --nodes 1-6
start_isotprecv
log "armfw: e-stop input gpio:servoarm-safety:7 (the chip has 4 lines), Reduced input gpio:no-such-chip:0"
start_armfw "$OUT_DIR/armfw_missing.toml"
first_contact
want_e="warning: e-stop input cannot be read: gpio:servoarm-safety:7: the chip has no such line"
want_r="warning: safety mode reduced: Reduced input cannot be read: gpio:no-such-chip:0: the chip cannot be opened"
_lost() { has_line "$want_e" && has_line "$want_r"; }
wait_until 10 "the two inputs' 'cannot be read' lines" _lost
pass "$(isotp_text | grep -F -- "$want_e" | head -n 1)"
pass "$(isotp_text | grep -F -- "$want_r" | head -n 1)"
a=$(isotp_ask enable 30)
case $a in "error: fault the e-stop input gpio:servoarm-safety:7 is asserted (cannot be read): release it first"*) pass "enable with the line missing: $a" ;;
  *) check_fail "enable with the e-stop line missing: want 'error: fault the e-stop input gpio:servoarm-safety:7 is asserted (cannot be read): ...', got '$a'" ;; esac
stop_armfw
stop_isotprecv
stop_armsim
mv "$OUT_DIR/armfw.log" "$OUT_DIR/armfw_missing.log"; isotp_text >"$OUT_DIR/console_missing.txt"
echo 0 >"$chipd/live"; rmdir "$chipd/bank0" "$chipd"
finish
