#!/bin/bash
# SPDX-License-Identifier: Apache-2.0
# Instructions per Controller::cycle (callgrind, exact and load-independent) on armbench's
# fixed-count firmware benchmarks (BM_FwCycleFixed_*: the same command sequence every run).
# Usage: tests/bench/callgrind_cycle.sh BUILD_DIR [FILTER]   (FILTER: a benchmark name regex)
# Prints one line per benchmark: name, calls of Controller::cycle, instructions per call.
set -euo pipefail
build=${1:?usage: callgrind_cycle.sh BUILD_DIR [FILTER]}
filter=${2:-FwCycleFixed}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
names=$("$build/tests/bench/armbench" --benchmark_list_tests=true --benchmark_filter="$filter")
for name in $names; do
  f="$out/cg.$(echo "$name" | tr '/:' '__')"
  valgrind --tool=callgrind --callgrind-out-file="$f" --toggle-collect='servoarm::fw::Controller::cycle(*' \
    "$build/tests/bench/armbench" --benchmark_filter="^${name}\$" >/dev/null 2>&1
  python3 - "$f" "$name" <<'PY'
import re, sys
path, name = sys.argv[1], sys.argv[2]
names, calls, total, cur_cfn = {}, 0, 0, None
def fn_name(tok):
    m = re.match(r'\((\d+)\)(?: (.*))?', tok)
    if not m: return tok
    if m.group(2): names[m.group(1)] = m.group(2)
    return names.get(m.group(1), '')
target = None
for line in open(path):
    line = line.rstrip('\n')
    if line.startswith('summary:') or line.startswith('totals:'):
        total = int(line.split()[1])
    elif line.startswith('cfn='):
        cur_cfn = fn_name(line[4:])
    elif line.startswith('fn='):
        fn_name(line[3:]); cur_cfn = None
    elif line.startswith('calls=') and cur_cfn and 'Controller::cycle(' in cur_cfn:
        calls += int(line[6:].split()[0])
print(f"{name}: {calls} calls, {total / max(calls, 1):.0f} instructions per call")
PY
done
