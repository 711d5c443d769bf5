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

need() { # need CMD... : fail (not skip) when a tool is missing
  for c in "$@"; do command -v "$c" >/dev/null 2>&1 || fail "$c not found in PATH ($PATH)"; done
}

# wait_until SECONDS WHAT CMD...: poll CMD every 50 ms until it succeeds.
wait_until() {
  _w_limit=$1; _w_what=$2; shift 2
  _w_n=$((_w_limit * 20))
  while [ "$_w_n" -gt 0 ]; do
    "$@" && return 0
    sleep 0.05
    _w_n=$((_w_n - 1))
  done
  fail "timed out after ${_w_limit}s waiting for $_w_what"
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

# frames FILE: candump -L lines -> "ID#DATA" (timestamp and interface dropped).
# Linux >= 6.1 sets CANFD_FDF (0x04) in the flags of every CAN FD frame; older
# kernels do not: it is masked out so expectations hold on both.
frames() {
  sed -n 's/^([0-9.]*) [^ ]* //p' "$1" |
    sed 's/##4/##0/; s/##5/##1/; s/##6/##2/; s/##7/##3/'
}

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
