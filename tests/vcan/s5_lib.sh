# SPDX-License-Identifier: Apache-2.0
# Helpers for the armfw scenarios (s5_*): armfw with bus.can = $CAN_IF and its
# console over ISO-TP on the same interface (requests 0x7E0, answers 0x7E8),
# armsim as the drives. Source after lib.sh.

# Time constants: on a real kernel the defaults (1 kHz, heartbeat 50 ms / consumer
# timeout 150 ms); in the TCG-emulated VM (5-10x slower, vCPUs starved now and
# then by a busy host) 250 Hz and 100 / 300 ms, as scenarios 2-4 do.
if [ "${SERVOARM_VM:-0}" = 1 ]; then rate_hz=250 hb_ms=100 hb_timeout_ms=300
else rate_hz=1000 hb_ms=50 hb_timeout_ms=150; fi

# write_armfw_config FILE [--own-drives]: a real bus needs every joint's homing.method;
# without --own-drives the six drives are absolute ([[drive]] homing.method = "absolute"),
# with it the caller appends its own [[drive]] tables.
write_armfw_config() {
  cat >"$1" <<EOF
robot = "puma560"
[loop]
rate_hz = $rate_hz
priority = 50
lock_memory = true
[bus]
can = "$CAN_IF"
heartbeat_period_ms = $hb_ms
heartbeat_timeout_ms = $hb_timeout_ms
start_timeout_s = 30
[safety]
following_error_deg = 20
enable_timeout_s = 20
feedback_timeout_ms = $((hb_timeout_ms * 3))
[console]
stdin = false
can = "$CAN_IF"
EOF
  if [ "${2:-}" != --own-drives ]; then
    for _j in 1 2 3 4 5 6; do printf '[[drive]]\nhoming.method = "absolute"\n' >>"$1"; done
  fi
}

# start_armfw CONFIG: armfw in the background (ARMFW_PID), returns once its
# console is up ("ready" on stderr), i.e. the drives are booted.
start_armfw() {
  armfw --config "$1" >"$OUT_DIR/armfw.log" 2>&1 &
  ARMFW_PID=$!
  wait_until 60 "armfw to boot the drives and open its CAN console" grep -qs 'ready (' "$OUT_DIR/armfw.log"
  grep -q 'can console: ISO-TP on' "$OUT_DIR/armfw.log" || fail "armfw did not open its CAN console: $(cat "$OUT_DIR/armfw.log")"
}
stop_armfw() { # SIGTERM; fails the check unless it exits 0
  kill -TERM "$ARMFW_PID" 2>/dev/null || true
  _f_rc=0; wait "$ARMFW_PID" || _f_rc=$?
  [ "$_f_rc" -eq 0 ] && pass "armfw exited with status 0" || check_fail "armfw exited with status $_f_rc"
}

# The kernel's ISO-TP (can-utils) as the console client. isotprecv -l is the
# receiver of armfw's answers (its socket sends the flow control frames); it
# does not flush its output, so what armfw sent is read from isotpsniffer (the
# kernel's ISO-TP in listen mode, flushes every message): its lines
# " vcan0  7E8  [N]  XX XX ..." are armfw's messages, "7E0" the requests.
# isotpsniffer quits on input: its stdin is a FIFO held open, never written.
start_isotprecv() {
  _i_before=$(can_receivers)
  isotprecv -s 7E0 -d 7E8 -l "$CAN_IF" >/dev/null 2>"$OUT_DIR/isotprecv.err" &
  ISOTPRECV_PID=$!
  wait_listening "$_i_before"
  rm -f /tmp/s5_sniff_in; mkfifo /tmp/s5_sniff_in
  _i_before=$(can_receivers)
  isotpsniffer -s 7E0 -d 7E8 -f 1 "$CAN_IF" <>/tmp/s5_sniff_in >"$OUT_DIR/isotp.log" 2>"$OUT_DIR/isotpsniffer.err" &
  SNIFFER_PID=$!
  wait_listening "$_i_before"
}
stop_isotprecv() {
  kill -TERM "$ISOTPRECV_PID" "$SNIFFER_PID" 2>/dev/null || true
  wait "$ISOTPRECV_PID" 2>/dev/null || true
  wait "$SNIFFER_PID" 2>/dev/null || true
  rm -f /tmp/s5_sniff_in
}
# isotp_text: everything armfw sent so far over ISO-TP, as text
isotp_text() { awk "$AWK_LE"'$2 == "7E8" { for (i = 4; i <= NF; i++) printf "%c", hexval(toupper($i)) }' "$OUT_DIR/isotp.log"; }
isotp_finals() { isotp_text | grep -c -E '^(ok|error:)'; }
_more_finals() { [ "$(isotp_finals)" -gt "$1" ]; }
# diagnostics for a console that does not answer
dump_console_state() {
  echo "--- armfw.log"; cat "$OUT_DIR/armfw.log"
  echo "--- isotp.log (last 10)"; tail -n 10 "$OUT_DIR/isotp.log"
  echo "--- console frames on the bus (last 20)"; grep -E ' 7E[08]#' "$OUT_DIR/all.log" | tail -n 20
}
# hex_of TEXT: space separated hex bytes
hex_of() { printf '%s' "$1" | od -An -tx1 | tr -s ' \n' '  '; }
# isotp_send_hex HEX: one ISO-TP message from the kernel's stack
isotp_send_hex() { echo "$1" | isotpsend -s 7E0 -d 7E8 "$CAN_IF"; }
# isotp_ask LINE [SECONDS]: send LINE with isotpsend, wait for one more final
# line (ok / error:) from armfw, print it.
# (No answer in time: prints "(no answer within N s)".)
isotp_ask() {
  _q_n=$(isotp_finals)
  isotp_send_hex "$(hex_of "$1")" || echo "(isotpsend failed)"
  _q_t=$(( ${2:-30} * 10 ))
  while [ "$_q_t" -gt 0 ] && ! _more_finals "$_q_n"; do nap 0.1; _q_t=$((_q_t - 1)); done
  if [ "$_q_t" -gt 0 ]; then isotp_text | grep -E '^(ok|error:)' | tail -n 1; else echo "(no answer within ${2:-30} s)"; fi
}
# first_contact: `status` must be answered, else dump what is known and stop.
first_contact() {
  _c_a=$(isotp_ask status 30)
  case $_c_a in ok*) pass "first contact over ISO-TP: $_c_a" ;;
    *) dump_console_state; fail "armfw's console does not answer over ISO-TP: $_c_a" ;; esac
}
# expect_ok WHAT ANSWER / expect_error WHAT ANSWER
expect_ok() { case $2 in ok*) pass "$1: $2" ;; *) check_fail "$1: want ok, got '$2'" ;; esac; }
expect_error() { case $2 in error:*) pass "$1: $2" ;; *) check_fail "$1: want error:, got '$2'" ;; esac; }

# wait_state STATE [SECONDS]: poll `status` over ISO-TP until state=STATE
_state_is() { isotp_ask status 30 | grep -q "state=$1"; }
wait_state() { wait_until "${2:-30}" "state=$1 in armfw's status" _state_is "$1"; }
