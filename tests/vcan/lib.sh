# SPDX-License-Identifier: Apache-2.0
# Helpers for vcan scenarios. POSIX sh: runs under busybox ash in the VM and
# under busybox sh / dash on a host with vcan. Source it: . "$SCENARIO_DIR/lib.sh"
#
# Environment (set by host_sim/vm/run-scenario): CAN_IF, OUT_DIR, SCENARIO_DIR.

: "${CAN_IF:?CAN_IF not set: run scenarios through host_sim/vm/run-scenario}"
: "${OUT_DIR:?OUT_DIR not set: run scenarios through host_sim/vm/run-scenario}"

FAILS=0
t0_uptime=$(cut -d' ' -f1 /proc/uptime)

log()  { echo "[$(awk -v t0="$t0_uptime" '{ printf "%7.3f", $1 - t0 }' /proc/uptime)] $*"; }
fail() { echo "FAIL: $*"; exit 1; }
skip() { echo "SKIP: $*"; exit 77; }
check_fail() { echo "FAIL: $*"; FAILS=$((FAILS + 1)); }   # record, keep going
pass() { echo "ok: $*"; }
finish() {
  if [ "$FAILS" -ne 0 ]; then echo "FAILED: $FAILS check(s)"; exit 1; fi
  echo "PASSED"; exit 0
}

# to_host VAR...: hands variables to the scenario's host check. SCRIPT.host-check runs on the
# host once the scenario passed (tests/vcan/vcan-test), with the files the scenario left in
# $OUT_DIR; long analyses of the captured frames belong there: awk over some 10 000 frames
# takes the emulated guest seconds per pass, the host milliseconds. A host check starts with
#   OUT_DIR=$1 CAN_IF=host SCENARIO_DIR=$(cd "$(dirname "$0")" && pwd)
#   . "$SCENARIO_DIR/lib.sh"; from_guest
# and ends with finish, as a scenario does.
to_host() {
  for _v in "$@"; do eval "printf \"%s='%s'\\n\" \"\$_v\" \"\$$_v\""; done >>"$OUT_DIR/host-check.env"
}
# from_guest: in a host check, the variables the scenario handed over (to_host).
from_guest() {
  [ -f "$OUT_DIR/host-check.env" ] || fail "$OUT_DIR/host-check.env missing: the scenario handed nothing over (to_host)"
  . "$OUT_DIR/host-check.env"
}

need() { # need CMD... : fail (not skip) when a tool is missing
  for c in "$@"; do command -v "$c" >/dev/null 2>&1 || fail "$c not found in PATH ($PATH)"; done
}

# nap SECONDS: a sleep that starts no process where the shell's `read` has a timeout
# (busybox ash, bash): a read on a FIFO that nothing writes, held open read-write on
# descriptor 8, so it never ends before its timeout. The wait loops poll every 50 ms, and
# under the VM's emulated CPUs each sleep(1) would be a fork and an exec the guest pays for.
# A shell without `read -t` (dash: exit status 2) sleeps with sleep(1).
_nap_fifo=${TMPDIR:-/tmp}/servoarm-nap.$$
if mkfifo "$_nap_fifo" 2>/dev/null; then
  exec 8<>"$_nap_fifo"
  rm -f "$_nap_fifo"
  if (read -t 0.01 _ <&8) 2>/dev/null; then _nap_rc=0; else _nap_rc=$?; fi
  if [ "$_nap_rc" -ne 2 ]; then nap() { read -t "$1" _ <&8; return 0; }; else nap() { sleep "$1"; }; fi
else
  nap() { sleep "$1"; }
fi

# wait_until SECONDS WHAT CMD...: poll CMD every 50 ms until it succeeds.
wait_until() {
  _w_limit=$1; _w_what=$2; shift 2
  _w_n=$((_w_limit * 20))
  while [ "$_w_n" -gt 0 ]; do
    "$@" && return 0
    nap 0.05
    _w_n=$((_w_n - 1))
  done
  fail "timed out after ${_w_limit}s waiting for $_w_what"
}

# retry MAX TRY RECOVER: run the function TRY (retry_n = its attempt, from 1) until it returns
# 0 (done) or 2 (give up at once), at most MAX times; after a 1 (try again) with attempts
# left, the function RECOVER runs first. Returns TRY's last status. The attempt count lives in
# the positional parameters, so RECOVER may itself use retry.
retry() {
  retry_n=${4:-1}
  "$2"; _r_rc=$?
  if [ "$_r_rc" -ne 1 ] || [ "$retry_n" -ge "$1" ]; then return "$_r_rc"; fi
  "$3"
  retry "$1" "$2" "$3" $((${4:-1} + 1))
}

# Number of receive filters (raw, isotp, bcm... sockets) registered on $CAN_IF,
# from /proc/net/can/rcvlist_*: a socket is listening once its count went up.
can_receivers() {
  cat /proc/net/can/rcvlist_* 2>/dev/null | awk -v i="$CAN_IF" '$1 == i' | wc -l
}
_more_receivers() { [ "$(can_receivers)" -gt "$1" ]; }
# wait_listening BEFORE [SECONDS]: wait until a new receiver registered on $CAN_IF
# since BEFORE=$(can_receivers) was taken.
wait_listening() { wait_until "${2:-5}" "a new CAN socket bound to $CAN_IF" _more_receivers "$1"; }

# start_candump NAME [CANDUMP-ARGS...]: candump -L (default args: $CAN_IF) into
# $OUT_DIR/NAME.log in the background; returns once its socket is bound.
start_candump() {
  _c_name=$1; shift
  [ $# -gt 0 ] || set -- "$CAN_IF"
  _c_before=$(can_receivers)
  candump -L "$@" >"$OUT_DIR/$_c_name.log" 2>"$OUT_DIR/$_c_name.err" &
  eval "CANDUMP_PID_$_c_name=$!"
  wait_until 5 "candump $_c_name to bind to $CAN_IF" _more_receivers "$_c_before"
}

# stop_candump NAME: SIGINT, wait; candump flushes every frame as it goes.
stop_candump() {
  eval "_c_pid=\$CANDUMP_PID_$1"
  kill -INT "$_c_pid" 2>/dev/null || true
  wait "$_c_pid" 2>/dev/null || true
}

# tframes FILE: candump -L lines -> "SECONDS ID#DATA", in kernel timestamp
# order. On an SMP kernel a frame is handed to each socket in turn, so a fast
# answer (armsim replying on the other CPU) can reach candump's socket before
# the request that caused it; the timestamps (taken when the frame entered the
# stack) keep the causal order. Linux >= 6.1 sets CANFD_FDF (0x04) in the flags
# of every CAN FD frame; older kernels do not: it is masked out.
tframes() {
  sed -n 's/^(\([0-9.]*\)) [^ ]* /\1 /p' "$1" | sort -s -k1,1 |
    sed 's/##4/##0/; s/##5/##1/; s/##6/##2/; s/##7/##3/'
}
# frames FILE: the same without timestamps: "ID#DATA" lines.
frames() { tframes "$1" | cut -d' ' -f2; }

# expected FILE: the file without blank lines and "# comment" lines.
expected() { grep -v -e '^[[:space:]]*$' -e '^#' "$1"; }

# same_frames WHAT EXPECTED-FILE ACTUAL-FRAMES-FILE: exact, in order.
same_frames() {
  if expected "$2" | diff -u - "$3" >"$OUT_DIR/diff.tmp"; then
    pass "$1 ($(wc -l <"$3") frames as expected)"
  else
    check_fail "$1: captured frames differ from $2 (- expected, + captured):"
    head -n 60 "$OUT_DIR/diff.tmp"
    [ "$(wc -l <"$OUT_DIR/diff.tmp")" -le 60 ] || echo "... (diff cut at 60 lines; files in \$OUT_DIR)"
  fi
  rm -f "$OUT_DIR/diff.tmp"
}

# Little-endian hex of an unsigned/signed 32-bit or 16-bit integer: le32 100000 -> A0860100
le32() { printf '%08X' $(( $1 & 0xFFFFFFFF )) | sed 's/\(..\)\(..\)\(..\)\(..\)/\4\3\2\1/'; }
le16() { printf '%04X' $(( $1 & 0xFFFF )) | sed 's/\(..\)\(..\)/\2\1/'; }

# awk functions for candump payloads: le_u(hex) little-endian unsigned value of
# a hex byte string, s32(v) / s16(v) two's complement.
AWK_LE='
function hexval(s,   i, v) { v = 0; for (i = 1; i <= length(s); i++) v = v * 16 + index("0123456789ABCDEF", substr(s, i, 1)) - 1; return v }
function le_u(s,   i, r) { r = ""; for (i = length(s) - 1; i >= 1; i -= 2) r = r substr(s, i, 2); return hexval(r) }
function s32(v) { return v >= 2147483648 ? v - 4294967296 : v }
function s16(v) { return v >= 32768 ? v - 65536 : v }
# CiA 402 "operation enabled": statusword bits 0-2 and 5 set, 3 and 6 clear (sw & 0x6F == 0x27)
function and_op(s) { return s % 8 == 7 && int(s / 8) % 2 == 0 && int(s / 32) % 2 == 1 && int(s / 64) % 2 == 0 }
'

# play_exchange FILE NAME: send the "> FRAME" lines of FILE with cansend and
# wait for each "< FRAME" line to be answered, with candump -L recording into
# $OUT_DIR/NAME.log (started by the caller with start_candump NAME ...). Each
# line waits until the log holds as many frames as lines played so far, so the
# order of requests and answers is fixed. In "<" lines, x matches any hex digit.
# "~ SECONDS" lines pause (a drive's move that must have ended before the next
# frame: its time is wall time, and the answers alone can come faster than it).
play_exchange() {
  _p_n=0
  while read -r _p_dir _p_frame _p_rest; do
    case $_p_dir in
      '>') _p_n=$((_p_n + 1)); cansend "$CAN_IF" "$_p_frame" || check_fail "cansend $_p_frame failed" ;;
      '<') _p_n=$((_p_n + 1)) ;;
      '~') nap "$_p_frame"; continue ;;
      *) continue ;;
    esac
    _p_t=60   # x 50 ms
    while [ "$(wc -l <"$OUT_DIR/$2.log")" -lt "$_p_n" ] && [ "$_p_t" -gt 0 ]; do nap 0.05; _p_t=$((_p_t - 1)); done
    [ "$_p_t" -gt 0 ] || { check_fail "no answer within 3 s after line $_p_n ($_p_dir $_p_frame)"; return 1; }
  done <"$1"
}

# match_exchange FILE ACTUAL-FRAMES WHAT: ACTUAL-FRAMES must be exactly the
# frames of FILE's "<" and ">" lines, in order ("x" = any hex digit).
match_exchange() {
  awk '$1 == "<" || $1 == ">" { print $2 }' "$1" >"$OUT_DIR/exchange.want"
  if awk 'NR == FNR { want[++n] = $0; next }
          { ++m; re = want[m]; gsub(/x/, "[0-9A-F]", re)
            if (m > n || $0 !~ ("^" re "$")) { printf "  frame %d: got %s, want %s\n", m, $0, (m > n ? "(nothing)" : want[m]); bad = 1 } }
          END { if (m < n) { printf "  only %d of %d frames; first missing: %s\n", m, n, want[m + 1]; bad = 1 }
                exit bad }' "$OUT_DIR/exchange.want" "$2" >"$OUT_DIR/exchange.diff"; then
    pass "$3 ($(wc -l <"$2") frames as expected)"
  else
    check_fail "$3: captured frames differ from $1:"
    head -n 20 "$OUT_DIR/exchange.diff"
  fi
}

# node_template FILE NODE: expected lines of FILE with the hex digit N -> NODE (1..9).
node_template() { expected "$1" | sed "s/N/$2/g"; }

# start_armsim NAME ARGS...: armsim --iface $CAN_IF ARGS > $OUT_DIR/NAME.log,
# returns once it printed "armsim ready". ARMSIM_PID is its pid.
start_armsim() {
  _a_name=$1; shift
  armsim --iface "$CAN_IF" "$@" >"$OUT_DIR/$_a_name.log" 2>&1 &
  ARMSIM_PID=$!
  wait_until 10 "armsim to print 'armsim ready'" grep -qs '^armsim ready' "$OUT_DIR/$_a_name.log"
}
stop_armsim() { # stop_armsim: SIGTERM, wait; fails the check if it did not exit 0
  kill -TERM "$ARMSIM_PID" 2>/dev/null || true
  _a_rc=0; wait "$ARMSIM_PID" || _a_rc=$?
  [ "$_a_rc" -eq 0 ] || check_fail "armsim exited with status $_a_rc (crash?)"
}

# check_sine_targets WHAT TFRAMES ID AMP_COUNTS FREQ PERIOD_S: the RPDO1 targets
# (bytes 2..5, cw 0x000F only) on ID in TFRAMES ("seconds ID#DATA") must be a
# streamed sine of amplitude AMP_COUNTS: its negative peak within 2 % of -AMP
# around the start position, never beyond +AMP, and no step faster than the
# sine (with its 0.5 s amplitude ramp) can move between two frames:
# |d target| <= 1.2 A (2 + 2 pi f) (dt + 10 PERIOD) + 20 counts, dt from the
# kernel timestamps (10 periods allow for the time between computing a
# setpoint and sending it, which the timestamps do not see: under emulation
# on a loaded machine the master is sometimes descheduled that long). A
# corrupted target is also caught by the range check (all within +-1.02 A).
check_sine_targets() {
  if awk -v id="$3" -v A="$4" -v f="$5" -v T="$6" "$AWK_LE"'
      { split($2, p, "#") }
      p[1] == id && substr(p[2], 1, 4) == "0F00" {
        v = s32(le_u(substr(p[2], 5, 8))); t = $1
        if (c == 0) { p0 = v; lo = hi = 0 }
        d = v - p0; if (d < lo) lo = d; if (d > hi) hi = d
        if (c > 0) { step = v - pv; if (step < 0) step = -step
                     lim = 1.2 * A * (2 + 6.2832 * f) * (t - pt + 10 * T) + 20
                     if (step > lim) { jumps++; if (!bad) bad = sprintf("jump of %d counts in %.4f s at target %d", step, t - pt, c + 1) } }
        pv = v; pt = t; c++ }
      END { printf "%d targets from %d: min %+d, max %+d counts around the start (A = %d)%s\n", c, p0, lo, hi, A, bad ? ", " jumps " bad steps, first: " bad : ""
            exit !(c >= 50 && lo <= -0.98 * A && lo >= -1.02 * A && hi <= 1.02 * A && !jumps) }' "$2" >"$OUT_DIR/sine.tmp"; then
    pass "$1: $(cat "$OUT_DIR/sine.tmp")"
  else
    check_fail "$1: not the streamed sine: $(cat "$OUT_DIR/sine.tmp")"
  fi
  rm -f "$OUT_DIR/sine.tmp"
}

# check_tracking WHAT TFRAMES NODE TOL_COUNTS [WINDOW]: from the bus alone, the drive
# NODE followed its setpoints. A drive acts on the RPDO received before a SYNC
# at that SYNC, and its TPDO1 at a SYNC reports the position reached so far.
# Under emulation a starved armsim handles a backlog of SYNCs with one clock
# reading, so its positions lag by a few cycles now and then: each TPDO1
# position (bytes 2..5) must be within TOL_COUNTS of one of the RPDO1 targets
# (bytes 2..5) applied at the WINDOW (default 16) SYNCs before it (16 is the
# transport delay canmaster itself allows), over the cycles where those RPDOs said "enable operation"
# (cw 0x000F) and the statusword says operation enabled. Then, at the end of
# the hold phase, the last such position must equal the last target within
# 10 counts (settled).
check_tracking() {
  if awk -v n="$3" -v tol="$4" -v W="${5:-16}" "$AWK_LE"'
      { split($2, p, "#"); id = p[1]; d = p[2] }
      id == "20" n && length(d) == 12 { last = s32(le_u(substr(d, 5, 8))); lastok = (substr(d, 1, 4) == "0F00"); next }
      id == "080" { k++; tg[k % W] = last; nok = lastok ? nok + 1 : 0; next }
      id == "18" n && length(d) == 12 {
        sw = le_u(substr(d, 1, 4)); pos = s32(le_u(substr(d, 5, 8)))
        if (nok >= W && and_op(sw)) {
          best = -1
          for (i = 0; i < W; i++) { e = pos - tg[i]; if (e < 0) e = -e; if (best < 0 || e < best) best = e }
          c++; if (best > worst) { worst = best; at = sprintf(" (position %d at SYNC %d, last target %d)", pos, k, tg[k % W]) }
          fin_pos = pos; fin_tg = tg[k % W]
        } }
      END { settle = fin_pos - fin_tg; if (settle < 0) settle = -settle
            printf "node %d: %d cycles compared, worst distance to the last %d targets %d counts (limit %d)%s; final position %d, target %d", n, c, W, worst, tol, (worst > tol ? at : ""), fin_pos, fin_tg
            exit !(c >= 50 && worst <= tol && settle <= 10) }' "$2" >"$OUT_DIR/track.tmp"; then
    pass "$1: $(cat "$OUT_DIR/track.tmp")"
  else
    check_fail "$1: $(cat "$OUT_DIR/track.tmp")"
  fi
  rm -f "$OUT_DIR/track.tmp"
}

# check_controlwords WHAT FRAMES NODE: the controlwords node NODE got, collapsed,
# are [0x0000] 0x0006 0x0007 0x000F (CiA 402 shutdown, switch on, enable
# operation) and at the end 0x0007 0x0006 (power-down); and the node's last
# "enable operation" is in the last cycle in which any node got one, i.e. it
# was not disabled before the master powered everything down (no fault reaction).
check_controlwords() {
  _cws=$(awk -F'#' -v id="20$3" '$1 == id { print substr($2, 3, 2) substr($2, 1, 2) }' "$2" | uniq | tr '\n' ' ')
  _cyc=$(awk -F'#' -v id="20$3" '$1 == "080" { k++ } $1 ~ /^20[0-9A-F]$/ && substr($2, 1, 4) == "0F00" { any = k; if ($1 == id) mine = k }
                                 END { print mine + 0, any + 0 }' "$2")
  case "$_cws" in
    "0006 0007 000F 0007 0006 "|"0000 0006 0007 000F 0007 0006 "|"0006 0007 000F "|"0000 0006 0007 000F ")
      if [ "${_cyc% *}" = "${_cyc#* }" ]; then
        pass "$1: node $3 controlwords $_cws(enabled until cycle ${_cyc% *}, the last enabled cycle)"
      else
        check_fail "$1: node $3 stopped being enabled at cycle ${_cyc% *}, the others at ${_cyc#* }: a fault reaction"
      fi ;;
    *) check_fail "$1: node $3 controlwords '$_cws', want [0000] 0006 0007 000F [0007 0006]" ;;
  esac
}
