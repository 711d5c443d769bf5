#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# The cost of `record mcap`: armfw --sim runs SEC seconds idle-enabled three times (no
# recording, recording at 100 Hz, at 1 kHz); prints per run the recorder thread's CPU time
# (/proc/PID/task/TID, the thread named mcap-recorder), the whole process's CPU, the control
# loop's overruns (late cycles) and the recorder's frames and missed cycles.
# Usage: bash tests/bench/mcap_cost.sh build/bin/armfw [SEC]
set -euo pipefail
armfw=$1
sec=${2:-20}
dir=$(mktemp -d /tmp/servoarm_mcap_cost_XXXXXX)
tck=$(getconf CLK_TCK)
run() {  # run RATE (0: no recording)
  local rate=$1 fifo="$dir/in" log="$dir/log" pid rec_cpu=0 proc_cpu tid
  rm -f "$fifo"; mkfifo "$fifo"
  "$armfw" --sim --record-dir "$dir" < "$fifo" > "$log" 2>&1 &
  pid=$!
  exec 7> "$fifo"
  echo enable >&7; sleep 1
  if [ "$rate" != 0 ]; then echo "record mcap rate=$rate" >&7; fi
  sleep "$sec"
  for t in /proc/$pid/task/*; do
    if [ "$(cat "$t/comm" 2>/dev/null)" = mcap-recorder ]; then  # a thread may end meanwhile
      tid=$(awk '{print $14+$15}' "$t/stat"); rec_cpu=$tid
    fi
  done
  proc_cpu=$(awk '{print $14+$15}' /proc/$pid/stat)
  if [ "$rate" != 0 ]; then echo "record mcap stop" >&7; fi
  sleep 0.5
  echo quit >&7; exec 7>&-
  wait "$pid" || true
  local over frames
  over=$(grep -o 'overruns=[0-9]*' "$log" | tail -1)
  frames=$(grep -o 'recorded MCAP .*' "$log" | sed 's/.*: //' | head -1 || true)
  printf 'rate %-5s recorder %.2f s CPU (%.1f %% of one core), armfw %.2f s CPU, %s, %s\n' "$rate" \
    "$(echo "$rec_cpu / $tck" | bc -l)" "$(echo "100 * $rec_cpu / $tck / $sec" | bc -l)" "$(echo "$proc_cpu / $tck" | bc -l)" "$over" "${frames:-no recording}"
}
echo "$(date -u +%F) $(uname -n) $(nproc) CPUs, $(uname -r), $sec s per run, loadavg $(cut -d' ' -f1-3 /proc/loadavg)"
run 0; run 100; run 1000
rm -rf "$dir"
