#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Figures of the network API against `armfw --sim --api-tcp 0` (tests/bench/RESULTS.md,
"Network API"): request round trip on loopback (a session message answered by the API
thread, and a service message run on the console thread), the state stream's delivered rate
and interval jitter at 1 kHz with 8 subscribers, and a console `state`-free baseline: the
round trip of a stop (service thread, control thread's reply).

  python3 tests/bench/api_bench.py build/bin/armfw
"""
import json
import re
import socket
import statistics
import subprocess
import sys
import threading
import time


def start(exe):
    p = subprocess.Popen([exe, "--sim", "--no-stdin", "--api-tcp", "0"], stderr=subprocess.PIPE,
                         stdout=subprocess.DEVNULL, text=True)
    for line in p.stderr:
        m = re.search(r"TCP port (\d+)", line)
        if m:
            threading.Thread(target=lambda: [None for _ in p.stderr], daemon=True).start()
            return p, int(m.group(1))
    raise RuntimeError("armfw did not start")


def conn(port):
    s = socket.create_connection(("127.0.0.1", port))
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return s, s.makefile("rb")


def roundtrips(port, cmd, n):
    s, f = conn(port)
    out = []
    for i in range(n):
        t0 = time.perf_counter()
        s.sendall((json.dumps({"id": i, "cmd": cmd}) + "\n").encode())
        while True:
            m = json.loads(f.readline())
            if m.get("id") == i:
                break
        out.append((time.perf_counter() - t0) * 1e3)
    s.close()
    out.sort()
    return statistics.median(out), out[int(0.99 * len(out)) - 1]


def stream_rate(port, subs, seconds):
    res = []

    def one():
        s, f = conn(port)
        s.sendall(b'{"id":1,"cmd":"subscribe","topic":"state","rate_hz":1000}\n')
        f.readline()
        t_end = time.monotonic() + seconds
        cycles = []
        while time.monotonic() < t_end:
            m = json.loads(f.readline())
            if m.get("topic") == "state":
                cycles.append(m["cycle"])
        s.close()
        d = [b - a for a, b in zip(cycles, cycles[1:])]
        res.append((len(cycles) / seconds, statistics.pstdev(d) if d else 0, max(d) if d else 0))

    ts = [threading.Thread(target=one) for _ in range(subs)]
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    return res


def main():
    p, port = start(sys.argv[1] if len(sys.argv) > 1 else "build/bin/armfw")
    try:
        time.sleep(1)
        for cmd in ("state", "events", "stop"):
            med, p99 = roundtrips(port, cmd, 1000)
            print(f"round trip {cmd:6s}: median {med:.3f} ms, p99 {p99:.3f} ms (1000)")
        r = stream_rate(port, 8, 3.0)
        rates = [x[0] for x in r]
        print(f"state stream 1 kHz x 8 subscribers: delivered {min(rates):.0f}..{max(rates):.0f} /s per client, "
              f"cycle-interval stdev {max(x[1] for x in r):.2f} cycles, largest gap {max(x[2] for x in r)} cycles")
    finally:
        p.terminate()
        p.wait()


if __name__ == "__main__":
    main()
