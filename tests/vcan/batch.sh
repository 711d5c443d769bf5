# SPDX-License-Identifier: Apache-2.0
# Several vcan scenarios one after another in one VM boot (tests/vcan/vcan-batch runs this
# through host_sim/vm/run-scenario; docs/vcan-tests.md "Several scenarios per VM boot").
#   batch.sh NAME:SECONDS...
# Each NAME.sh (next to this script) runs as it would alone: its own $OUT_DIR
# ($OUT_DIR/NAME here), a fresh vcan0 (deleted and created again, as /init makes it),
# a time limit (SECONDS), its own starvation probe (the same 50 ms probe as /init's,
# counted from its start), and it runs in a session of its own, so whatever it leaves
# running is killed before the next one starts. Its console lines stand between
#   servoarm-batch: begin NAME ...
#   servoarm-batch: end NAME: exit status RC
# with the probe's summary line, in /init's words ("servoarm-vm: stalls: longest ..."),
# just before the end line: tests/vcan/vcan-test judges a scenario's part of the batch
# exactly as a run of its own. The batch itself always exits 0: the scenarios' tests
# give the verdicts.
base_out=$OUT_DIR

# a vcan0 as a fresh boot has it (a scenario may have changed its MTU or left it down);
# busybox's ip first, then iproute2's, as /init does
fresh_can() {
  for _ip in ip /usr/sbin/ip.full; do
    $_ip link del dev "$CAN_IF" 2>/dev/null
    $_ip link add dev "$CAN_IF" type vcan 2>/dev/null && $_ip link set up dev "$CAN_IF" && return 0
  done
  return 1
}

# the 50 ms starvation probe of /init, its figures in $1 as "N200 MAX N30"
probe() {
  _n=0; _max=0; _n30=0
  read -r _prev _ </proc/uptime
  while :; do
    sleep 0.05
    read -r _now _ </proc/uptime
    _late=$(( (${_now%.*}${_now#*.} - ${_prev%.*}${_prev#*.}) * 10 - 50 ))
    if [ "$_late" -ge 30 ]; then
      _n30=$((_n30 + 1)); [ "$_late" -gt "$_max" ] && _max=$_late
      [ "$_late" -ge 200 ] && _n=$((_n + 1))
      echo "$_n $_max $_n30" >"$1"
    fi
    _prev=$_now
  done
}

# kill every process of session $1 (the scenario's leftovers)
kill_session() {
  kill -KILL -- "-$1" 2>/dev/null
  for _st in /proc/[0-9]*/stat; do
    { read -r _line <"$_st"; } 2>/dev/null || continue   # gone meanwhile
    # after "pid (comm) ": state ppid pgrp session ...
    set -- "$1" ${_line##*) }
    [ "$5" = "$1" ] && kill -KILL "${_line%% *}" 2>/dev/null
  done
  return 0
}

for arg in "$@"; do
  name=${arg%:*}; secs=${arg##*:}
  echo "servoarm-batch: begin $name (timeout ${secs}s, uptime $(cut -d' ' -f1 /proc/uptime) s)"
  if ! fresh_can; then
    echo "servoarm-batch: cannot create $CAN_IF again"
    echo "servoarm-batch: end $name: exit status 125"
    continue
  fi
  mkdir -p "$base_out/$name"
  echo "0 0 0" >/tmp/batch_stalls
  probe /tmp/batch_stalls &
  probe_pid=$!
  OUT_DIR=$base_out/$name setsid timeout "$secs" sh "$SCENARIO_DIR/$name.sh" &
  pid=$!
  wait "$pid"
  rc=$?
  kill_session "$pid"
  kill "$probe_pid" 2>/dev/null
  wait "$probe_pid" 2>/dev/null
  read -r n200 max n30 </tmp/batch_stalls
  echo "servoarm-vm: stalls: longest $max ms late; $n30 wake-ups 30 ms or more late, $n200 200 ms or more (50 ms probe)"
  # busybox timeout: the scenario killed by SIGTERM gives 143 (run-scenario's 124)
  if [ "$rc" -eq 143 ]; then echo "servoarm-batch: $name timed out after ${secs}s"; rc=124; fi
  echo "servoarm-batch: end $name: exit status $rc (uptime $(cut -d' ' -f1 /proc/uptime) s)"
done
exit 0
