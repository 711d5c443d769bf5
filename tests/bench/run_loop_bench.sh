#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# Control-loop wake-up latency against cyclictest, as interleaved pairs in one run,
# at the same period, priority and memory locking:
#   A. armfw --sim --robot puma560 --bench-loop SEC --rate HZ --priority PRIO   (moves in progress)
#   B. cyclictest -t1 -p PRIO -i PERIOD_US -D SEC -m -q -h 100000
# PAIRS pairs (default 5), the order alternating (AB, BA, AB, ...) so a drift of the
# machine's load does not favour one side. Per pair: both p99 and max wake-up
# latencies and the ratios armfw / cyclictest; then the median over the pairs of
# every figure and of the ratios (goal: p99 ratio <= 1.2).
#
#   tests/bench/run_loop_bench.sh [SEC=10] [HZ=1000] [PRIO=80]
#   PAIRS=N   number of pairs (default 5)
#   LOAD=1    one `stress-ng --cpu 2` beside the whole series (started before the first
#             run, stopped after the last)
#   ARMFW=... the armfw binary (default <repo>/build/bin/armfw)
#
# Wake-up latency = wake time - absolute deadline of clock_nanosleep(TIMER_ABSTIME,
# CLOCK_MONOTONIC), in us, for both. Percentiles on the same convention: armfw's
# 1-us histogram reports the upper edge of the bin holding the percentile (capped at
# the max), so cyclictest's (integer-us buckets) is read the same way (bucket + 1).
# SCHED_FIFO at PRIO when this user may (`chrt -f PRIO true` succeeds); otherwise both
# run with normal scheduling (armfw --priority 0, cyclictest -p 0) and the script says so.
# Exit status: 0 after printing the figures; 2 when armfw or cyclictest is missing.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
sec=${1:-10}; hz=${2:-1000}; prio=${3:-80}
pairs=${PAIRS:-5}
armfw=${ARMFW:-$root/build/bin/armfw}
[ -x "$armfw" ] || { echo "no $armfw (build first: bash .ci/build, or ARMFW=path)" >&2; exit 2; }
command -v cyclictest >/dev/null || { echo "cyclictest missing (apt-get install rt-tests)" >&2; exit 2; }
period_us=$(( 1000000 / hz ))
tmp=$(mktemp -d)
stress_pid=""
cleanup() {
  if [ -n "$stress_pid" ]; then kill "$stress_pid" 2>/dev/null || true; wait "$stress_pid" 2>/dev/null || true; fi
  [ -n "${KEEP_TMP:-}" ] && echo "kept $tmp" || rm -rf "$tmp"
}
trap cleanup EXIT

policy="SCHED_FIFO $prio"
if [ "$prio" -gt 0 ] && ! chrt -f "$prio" true 2>/dev/null; then
  policy="SCHED_OTHER (SCHED_FIFO $prio not permitted for $(id -un): both run with normal scheduling)"
  prio=0
fi
[ "$prio" -gt 0 ] || [[ $policy == SCHED_OTHER* ]] || policy="SCHED_OTHER (priority 0 asked)"

load_txt="idle (no stress-ng)"
if [ "${LOAD:-0}" = 1 ]; then
  command -v stress-ng >/dev/null || { echo "LOAD=1 but stress-ng is missing (apt-get install stress-ng)" >&2; exit 2; }
  stress-ng --cpu 2 --timeout "$(( pairs * 2 * (sec + 15) + 60 ))s" >/dev/null 2>&1 &
  stress_pid=$!
  load_txt="stress-ng --cpu 2 beside the whole series"
  sleep 2
fi

echo "machine:   $(uname -r), $(nproc) CPUs, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//')"
echo "run:       $(date -u '+%Y-%m-%d %H:%M UTC'), $pairs pairs of ${sec} s at $hz Hz (period $period_us us), $policy, $load_txt"
echo "load avg:  before $(cut -d' ' -f1-3 /proc/loadavg)"

# The control thread's page faults, context switches and timer slack while it runs
# (from /proc: armfw-rt's stat fields 10/12, status, timerslack_ns), read 1 s after the
# control thread appeared and SEC - 3 s after that (before the run ends): faults or
# involuntary switches between the two reads happened in the loop's steady state.
rt_probe() {  # rt_probe <pid>: one line "minflt majflt voluntary nonvoluntary slack_ns"
  local t
  for t in /proc/"$1"/task/*; do
    [ "$(cat "$t/comm" 2>/dev/null)" = armfw-rt ] || continue
    echo "$(awk '{print $10, $12}' "$t/stat") $(awk '/^voluntary_ctxt/{v=$2} /^nonvoluntary_ctxt/{n=$2} END{print v, n}' "$t/status") $(cat "/proc/${t##*/}/timerslack_ns" 2>/dev/null || echo -)"
    return 0
  done
  return 1
}
run_armfw() {  # run_armfw <i>
  "$armfw" --sim --robot puma560 --bench-loop "$sec" --rate "$hz" --priority "$prio" \
    >"$tmp/armfw.$1.json" 2>"$tmp/armfw.$1.err" &
  local pid=$! p0="" p1="" t
  for t in $(seq 1 100); do  # until the loop runs (its thread exists), at most 10 s
    p0=$(rt_probe "$pid" || true); [ -z "$p0" ] || break; sleep 0.1
  done
  sleep 1; p0=$(rt_probe "$pid" || true)
  sleep "$(awk -v s="$sec" 'BEGIN { x = s - 3; print (x < 0.5 ? 0.5 : x) }')"; p1=$(rt_probe "$pid" || true)
  wait "$pid" || { echo "armfw failed (pair $1):" >&2; cat "$tmp/armfw.$1.err" >&2; exit 1; }
  echo "${p0:-- - - - -} ${p1:-- - - - -}" >"$tmp/probe.$1"
  if grep -q "not permitted\|mlockall failed" "$tmp/armfw.$1.err"; then
    echo "pair $1: armfw: $(grep -m1 'warning' "$tmp/armfw.$1.err")"
  fi
}
run_cyclictest() {  # run_cyclictest <i>
  cyclictest -t1 -p "$prio" -i "$period_us" -D "${sec}s" -m -q -h 100000 >"$tmp/cyc.$1.txt" 2>&1 || {
    echo "cyclictest failed (pair $1):" >&2; tail -n 5 "$tmp/cyc.$1.txt" >&2; exit 1; }
}
for i in $(seq 1 "$pairs"); do
  if [ $(( i % 2 )) -eq 1 ]; then run_armfw "$i"; run_cyclictest "$i"; order=AB; else run_cyclictest "$i"; run_armfw "$i"; order=BA; fi
  echo "$order" >"$tmp/order.$i"
done
echo "load avg:  after $(cut -d' ' -f1-3 /proc/loadavg)"

python3 - "$tmp" "$pairs" <<'PY'
import json, statistics, sys
tmp, pairs = sys.argv[1], int(sys.argv[2])

def cyclic(path):
    # cyclictest -h: "usec count" histogram lines, then "# Max Latencies: 00123" etc.
    hist, mx, avg = [], None, None
    for line in open(path).read().splitlines():
        if line.startswith('# Max Latencies'):
            mx = int(line.split(':')[1].split()[0])
        elif line.startswith('# Avg Latencies'):
            avg = float(line.split(':')[1].split()[0])
        elif line and line[0].isdigit():
            us, n = line.split()[:2]
            if int(n):
                hist.append((int(us), int(n)))
    total = sum(n for _, n in hist)
    if total == 0 or mx is None:
        sys.exit(f"cyclictest: no samples in {path}")
    def pct(p):  # upper edge of the bucket holding the p-th percentile, capped at the max
        acc = 0
        for us, n in hist:
            acc += n
            if acc >= p / 100.0 * total:
                return min(us + 1, mx)
        return mx
    return dict(cycles=total, mean=avg, p50=pct(50), p99=pct(99), max=mx)

rows = []
print()
print("| pair | order | armfw cycles | armfw overruns | armfw mean | armfw p99 | armfw max | cyclictest mean | cyclictest p50 | cyclictest p99 | cyclictest max | p99 ratio | max ratio |")
print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
for i in range(1, pairs + 1):
    a = json.loads(open(f"{tmp}/armfw.{i}.json").read().strip().splitlines()[-1])
    c = cyclic(f"{tmp}/cyc.{i}.txt")
    order = open(f"{tmp}/order.{i}").read().strip()
    la = a["latency_us"]
    r = dict(ap99=la["p99"], amax=la["max"], amean=la["mean"], cp99=c["p99"], cmax=c["max"], cmean=c["mean"],
             cp50=c["p50"], overruns=a["overruns"], cycles=a["cycles"])
    r["rp99"] = r["ap99"] / r["cp99"] if r["cp99"] else float("inf")
    r["rmax"] = r["amax"] / r["cmax"] if r["cmax"] else float("inf")
    pr = open(f"{tmp}/probe.{i}").read().split()
    try:
        r["dflt"] = int(pr[5]) - int(pr[0]) + int(pr[6]) - int(pr[1])
        r["dinv"] = int(pr[8]) - int(pr[3])
        r["slack"] = pr[4]
    except (ValueError, IndexError):
        r["dflt"], r["dinv"], r["slack"] = -1, -1, "-"
    rows.append(r)
    print(f"| {i} | {order} | {r['cycles']} | {r['overruns']} | {r['amean']:.1f} | {r['ap99']:.0f} | {r['amax']:.0f} | "
          f"{r['cmean']:.1f} | {r['cp50']} | {r['cp99']} | {r['cmax']} | {r['rp99']:.2f} | {r['rmax']:.2f} |")
med = lambda k: statistics.median(r[k] for r in rows)
print(f"| median | | {med('cycles'):.0f} | {med('overruns'):.0f} | {med('amean'):.1f} | {med('ap99'):.0f} | {med('amax'):.0f} | "
      f"{med('cmean'):.1f} | {med('cp50'):.0f} | {med('cp99'):.0f} | {med('cmax'):.0f} | {med('rp99'):.2f} | {med('rmax'):.2f} |")
print()
ok = med('rp99') <= 1.2
print(f"median ratio armfw/cyclictest over {pairs} pairs: p99 {med('rp99'):.2f}, max {med('rmax'):.2f} "
      f"(goal p99 <= 1.2: {'met' if ok else 'NOT met'})")
print()
print("armfw-rt thread in the loop's steady state (from 1 s to SEC - 2 s after the control thread started), per pair: "
      + "; ".join(f"{i + 1}: {r['dflt']} page faults, {r['dinv']} involuntary switches, timer slack {r['slack']} ns"
                  for i, r in enumerate(rows)))
PY
