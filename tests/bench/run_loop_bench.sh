#!/usr/bin/env bash
# Control-loop latency against cyclictest, in the same run, at the same rate
# and priority:
#   1. armfw --sim --bench-loop SEC --rate HZ --priority PRIO  (moves in progress)
#   2. cyclictest -t1 -p PRIO -i PERIOD_US -D SEC -m -q -h HIST
# and prints both p99/max wake-up latencies and their ratios (goal: <= 1.5).
# Optional load beside both: LOAD=1 runs `stress-ng --cpu 2` during each run.
# usage: tests/bench/run_loop_bench.sh [SEC=10] [HZ=1000] [PRIO=80]   (ARMFW=path overrides)
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
sec=${1:-10}; hz=${2:-1000}; prio=${3:-80}
armfw=${ARMFW:-$root/build/bin/armfw}
[ -x "$armfw" ] || { echo "no $armfw (build first: bash .ci/build)" >&2; exit 2; }
command -v cyclictest >/dev/null || { echo "cyclictest missing (apt-get install rt-tests)" >&2; exit 2; }
period_us=$(( 1000000 / hz ))
tmp=$(mktemp -d); trap 'rm -rf "$tmp"; [ -n "${stress_pid:-}" ] && kill "$stress_pid" 2>/dev/null || true' EXIT
load() {
  if [ "${LOAD:-0}" = 1 ] && command -v stress-ng >/dev/null; then
    stress-ng --cpu 2 --timeout "$((sec + 5))s" >/dev/null 2>&1 & stress_pid=$!
  fi
}
unload() { if [ -n "${stress_pid:-}" ]; then kill "$stress_pid" 2>/dev/null || true; wait "$stress_pid" 2>/dev/null || true; stress_pid=; fi; }

load
"$armfw" --sim --robot puma560 --bench-loop "$sec" --rate "$hz" --priority "$prio" >"$tmp/armfw.json" 2>"$tmp/armfw.err"
unload
load
cyclictest -t1 -p "$prio" -i "$period_us" -D "${sec}s" -m -q -h 100000 >"$tmp/cyc.txt" 2>&1 || true
unload

json=$(tail -n1 "$tmp/armfw.json")
echo "armfw:      $json"
grep -q "not permitted" "$tmp/armfw.err" && echo "armfw:      $(grep -m1 warning "$tmp/armfw.err")"
python3 - "$tmp/cyc.txt" "$json" <<'PY'
import json, sys
cyc = open(sys.argv[1]).read().splitlines()
a = json.loads(sys.argv[2])
# cyclictest -h: histogram lines "usec count", then "# Max Latencies: 000123".
hist = []
mx = None
for line in cyc:
    if line.startswith('# Max Latencies'):
        mx = int(line.split(':')[1].split()[0])
    elif line and line[0].isdigit():
        us, n = line.split()[:2]
        hist.append((int(us), int(n)))
total = sum(n for _, n in hist)
if total == 0:
    print("cyclictest: no samples (output follows)"); print("\n".join(cyc[-5:])); sys.exit(1)
acc = 0; p99 = None
for us, n in hist:
    acc += n
    if acc >= 0.99 * total:
        p99 = us; break
print(f"cyclictest: samples={total} p99={p99} us max={mx} us")
ap99, amax = a["latency_us"]["p99"], a["latency_us"]["max"]
r = lambda x, y: (x / y) if y else float('inf')
print(f"ratio armfw/cyclictest: p99 {r(ap99, p99):.2f}  max {r(amax, mx):.2f}  (goal <= 1.5); armfw overruns={a['overruns']} over {a['cycles']} cycles")
PY
