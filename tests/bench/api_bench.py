#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Figures of the network API against `armfw --sim --api-tcp 0` (tests/bench/RESULTS.md,
"Network API"): request round trip on loopback (a session message answered by the API
thread, and a service message run on the console thread), the state stream's delivered rate
and interval jitter at 1 kHz with 8 subscribers, and a console `state`-free baseline: the
round trip of a stop (service thread, control thread's reply).

With --stream: streaming targets (a sine and a hand-like motion at 30 / 100 / 500 Hz with
+-5 ms jitter) tracked by the arm, against a naive client-side linear interpolation of the same
targets computed in the same run; the deadman's stop distance; the pty console's round trip next
to the API's; the e-stop's time to the arm's stop while another client floods requests.

Each streaming row runs three ways: the velocity estimated by the firmware from the targets'
arrival, estimated from the client's sampling times (`t`), and sent with the target (`qd`, and `t`).
A row prints this script's longest gap between two targets: one past the deadman
(api.stream_deadman_ms, 100 ms) ends the stream, and the targets after it are refused, so
such a row measures the machine's load, not the stream.

  python3 tests/bench/api_bench.py build/bin/armfw [--stream [--rates=30,100,500] [--plant=dynamic]]

--plant: armfw --sim's plant (first-order by default; dynamic: the rigid-body plant). On a
shared machine, `chrt -f 50` in front keeps other processes' builds from stalling this script
(armfw's control thread still runs above it at SCHED_FIFO 80).
"""
import math
import os
import random
import termios
import json
import re
import socket
import statistics
import subprocess
import sys
import threading
import time


def start(exe, extra=()):
    p = subprocess.Popen([exe, "--sim", "--no-stdin", "--api-tcp", "0", *extra], stderr=subprocess.PIPE,
                         stdout=subprocess.DEVNULL, text=True)
    pty, port = None, 0
    for line in p.stderr:
        m = re.search(r"console pty: (\S+)", line)
        if m:
            pty = m.group(1)
        m = re.search(r"TCP port (\d+)", line)
        if m:
            port = int(m.group(1))
        if port and (pty or "--pty" not in extra):
            threading.Thread(target=lambda: [None for _ in p.stderr], daemon=True).start()
            return (p, port, pty) if extra else (p, port)
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


class Api:
    """One connection: requests answered by id; state samples and events kept by a reader thread."""

    def __init__(self, port):
        self.s, self.f = conn(port)
        self.lock = threading.Lock()
        self.answers = {}
        self.states = []  # (wall time received, sample)
        self.cv = threading.Condition(self.lock)
        self.n = 0
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        try:
            self._read_lines()
        except OSError:  # the connection closed by close()
            pass
        except ValueError:  # reading the file close() closed; a bad JSON line is raised
            if not self.f.closed:
                raise

    def _read_lines(self):
        for line in self.f:
            t = time.perf_counter()
            m = json.loads(line)
            with self.cv:
                if m.get("topic") == "state" and "id" not in m:  # a sample (a `state` answer has the id)
                    self.states.append((t, m))
                elif "id" in m:
                    self.answers[m["id"]] = (t, m)
                    self.cv.notify_all()

    def close(self):
        # shutdown, not only close: the reader's file object keeps the socket open otherwise, and
        # the firmware would go on streaming 1 kHz samples into a reader thread nobody uses
        try:
            self.s.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self.s.close()
        self.f.close()

    def send(self, cmd, **kw):
        with self.lock:
            self.n += 1
            i = self.n
        self.s.sendall((json.dumps({"id": i, "cmd": cmd, **kw}) + "\n").encode())
        return i

    def ask(self, cmd, timeout=10, **kw):
        i = self.send(cmd, **kw)
        with self.cv:
            self.cv.wait_for(lambda: i in self.answers, timeout)
            return self.answers.get(i, (0, {}))[1]


def wait_idle(a, timeout=20):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if a.ask("state").get("state") == "idle":
            return
        time.sleep(0.02)


def wait_motion(a, r, timeout=20):
    # a move's answer comes before the control thread takes it up: wait for its motion id to be
    # done (as the Python client does), not for "idle", which the state may still show
    mid = r["motion"]
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        s = a.ask("state")
        if s.get("done", 0) >= mid and (s.get("running") == 0 or s.get("queued") == 0):
            return
        time.sleep(0.02)


def sine(t):
    return 0.4 * math.sin(2 * math.pi * 0.5 * t)


def hand(t):
    # a recorded-looking hand motion: slow reach, tremor-free corrections, a quick flick
    return (0.3 * math.sin(2 * math.pi * 0.25 * t) + 0.08 * math.sin(2 * math.pi * 1.3 * t + 1.0)
            + 0.03 * math.sin(2 * math.pi * 3.1 * t + 2.0) + 0.1 * math.tanh(4 * (t - 2.0)))


def peaks(ts, xs, lim):
    """Peak |v|, |a|, |j| of x(t) on a 1 ms grid (linear interpolation of the samples), as fractions of lim."""
    if len(ts) < 4:
        return (0, 0, 0)
    t0, t1 = ts[0], ts[-1]
    n = int((t1 - t0) * 1000)
    g, k = [], 0
    for i in range(n):
        t = t0 + i * 1e-3
        while k + 1 < len(ts) - 1 and ts[k + 1] < t:
            k += 1
        u = (t - ts[k]) / (ts[k + 1] - ts[k]) if ts[k + 1] > ts[k] else 0
        g.append(xs[k] + u * (xs[k + 1] - xs[k]))
    v = [(b - a) / 1e-3 for a, b in zip(g, g[1:])]
    acc = [(b - a) / 1e-3 for a, b in zip(v, v[1:])]
    j = [(b - a) / 1e-3 for a, b in zip(acc, acc[1:])]
    return tuple(max(map(abs, x or [0])) / l for x, l in ((v, lim[0]), (acc, lim[1]), (j, lim[2])))


def setpoint_peaks(ts, v, lim):
    """Peak |a| (5 ms steps) and |j| (10 ms steps) of the velocity samples v(t), as fractions of lim."""
    def grid(ts, xs, h):
        out, k, t = [], 0, ts[0]
        while t < ts[-1]:
            while k + 1 < len(ts) - 1 and ts[k + 1] < t:
                k += 1
            u = (t - ts[k]) / (ts[k + 1] - ts[k]) if ts[k + 1] > ts[k] else 0
            out.append(xs[k] + u * (xs[k + 1] - xs[k]))
            t += h
        return out
    a = [(b - c) / 5e-3 for c, b in zip(grid(ts, v, 5e-3), grid(ts, v, 5e-3)[1:])]
    ta = [ts[0] + (i + 0.5) * 5e-3 for i in range(len(a))]
    a10 = grid(ta, a, 10e-3)
    j = [(b - c) / 10e-3 for c, b in zip(a10, a10[1:])]
    return max(map(abs, a or [0])) / lim[1], max(map(abs, j or [0])) / lim[2]


def stream_run(port, lim, fn, rate, seconds=4.0, jitter=0.005, send_qd=False, send_t=False):
    a = Api(port)
    a.ask("take_control")
    a.ask("enable")
    wait_idle(a)
    wait_motion(a, a.ask("movej", q=[fn(0), 0, 0, 0, 0, 0], speed_pct=50))
    # the arm's samples on a connection of their own (an observer): a backlog of 1 kHz samples
    # this script reads too slowly holds back that connection only, not the targets' answers
    mon = Api(port)
    mon.ask("subscribe", topic="state", rate_hz=1000)
    sent = []
    # send times on an absolute timeline: k / rate, each moved by up to +-jitter (kept in order)
    plan, prev = [], 0.0
    for k in range(int(seconds * rate)):
        prev = max(prev, k / rate + random.uniform(-jitter, jitter))
        plan.append(prev)
    t0 = time.perf_counter() + 0.01
    for k, ts in enumerate(plan):
        d = t0 + ts - time.perf_counter()
        if d > 0:
            time.sleep(d)
        t = time.perf_counter() - t0
        x = fn(t)
        extra = {"start": True} if k == 0 else {}
        if send_qd:  # the target's velocity, as a client that knows its signal sends it
            extra["qd"] = [(fn(t + 1e-4) - fn(t - 1e-4)) / 2e-4, 0, 0, 0, 0, 0]
        if send_t:  # when it was sampled, on this process's monotonic clock
            extra["t"] = t0 + t
        a.send("stream", q=[x, 0, 0, 0, 0, 0], **extra)
        sent.append((t0 + t, x))
    time.sleep(0.5)
    with mon.lock:
        st = [(t, m) for t, m in mon.states if t >= t0]
    mon.close()
    with a.lock:
        refused = sum(1 for _, m in a.answers.values() if "error" in m)
    counts = a.ask("state").get("stream", {})
    a.ask("stop")
    wait_idle(a)
    a.ask("release_control")
    a.close()
    # the arm's samples on the RT clock, placed on the wall clock by the earliest arrival
    off = min(t - m["cycle"] / 1000.0 for t, m in st)
    at = [m["cycle"] / 1000.0 + off for _, m in st]
    q = [m["q"][0] for _, m in st]
    qc = [m["q_cmd"][0] for _, m in st]
    # lag: the shift of the ideal signal that best matches the measured joint (0..400 ms)
    win = [(t, x) for t, x in zip(at, q) if t0 + 0.5 < t < t0 + seconds]
    best = min(range(0, 401, 2), key=lambda d: sum((x - fn(t - t0 - d * 1e-3)) ** 2 for t, x in win))
    err = max(abs(x - fn(t - t0 - best * 1e-3)) for t, x in win)
    # and against the signal itself (no shift): what a follower's lag costs
    err0 = max(abs(x - fn(t - t0)) for t, x in win)
    rms0 = (sum((x - fn(t - t0)) ** 2 for t, x in win) / max(1, len(win))) ** 0.5
    # the naive client: linear interpolation from the target before to the newest, over one period
    nt = [t for t, _ in sent]
    nx = [x for _, x in sent]
    ngrid = [(t0 + 0.5 + i * 1e-3) for i in range(int((seconds - 0.5) * 1000))]
    nq, k = [], 0
    for t in ngrid:
        while k + 1 < len(nt) and nt[k + 1] <= t:
            k += 1
        if k == 0:
            nq.append(nx[0])
            continue
        per = nt[k] - nt[k - 1]
        u = min(1.0, (t - nt[k]) / per) if per > 0 else 1.0
        nq.append(nx[k - 1] + u * (nx[k] - nx[k - 1]))
    nbest = min(range(0, 401, 2), key=lambda d: sum((x - fn(t - t0 - d * 1e-3)) ** 2 for t, x in zip(ngrid, nq)))
    nerr = max(abs(x - fn(t - t0 - nbest * 1e-3)) for t, x in zip(ngrid, nq))
    # the arm's setpoints: velocity as commanded (qd_cmd), acceleration and jerk from it on 5 / 10 ms
    # steps (the samples are not every cycle: finer differences would show the gaps, not the arm)
    qdc = [m["qd_cmd"][0] for _, m in st]
    pk = (max(map(abs, qdc)) / lim[0],) + setpoint_peaks(at, qdc, lim)
    return dict(lag=best, err=err, err0=err0, rms0=rms0, pk=pk, nlag=nbest, nerr=nerr, npk=peaks(ngrid, nq, lim),
                samples=len(st), targets=len(sent), refused=refused, counts=counts,
                gap=max((sent[i][0] - sent[i - 1][0] for i in range(1, len(sent))), default=0.0))


def deadman(port, lim):
    a = Api(port)
    a.ask("take_control")
    wait_idle(a)
    a.ask("subscribe", topic="state", rate_hz=1000)
    t0 = time.perf_counter()
    first, last = True, 0.0
    while time.perf_counter() - t0 < 1.0:  # 0.5 rad/s ramp at 100 Hz, then silence
        last = 0.5 * (time.perf_counter() - t0)
        a.send("stream", q=[last, 0, 0, 0, 0, 0], **({"start": True} if first else {}))
        first = False
        time.sleep(0.01)
    t_last = time.perf_counter()
    time.sleep(1.0)
    with a.lock:
        st = [(t, m) for t, m in a.states if t >= t_last]
    rest = next((t, m) for t, m in st if not m["streaming"] and all(abs(v) < 1e-9 for v in m["qd_cmd"]))
    a.ask("release_control")
    a.close()
    return rest[1]["q_cmd"][0] - last, (rest[0] - t_last) * 1e3


def pty_roundtrips(path, n):
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
    at = termios.tcgetattr(fd)
    at[3] &= ~(termios.ECHO | termios.ICANON)
    termios.tcsetattr(fd, termios.TCSANOW, at)
    buf, out = b"", []
    for _ in range(n):
        t0 = time.perf_counter()
        os.write(fd, b"status\n")
        while b"\n" not in buf:
            buf += os.read(fd, 4096)
        line, buf = buf.split(b"\n", 1)
        out.append((time.perf_counter() - t0) * 1e3)
    os.close(fd)
    out.sort()
    return statistics.median(out), out[int(0.99 * len(out)) - 1]


def estop_under_flood(port):
    flood_n = [0]
    stop = threading.Event()

    def flood():
        s, f = conn(port)
        threading.Thread(target=lambda: [None for _ in f], daemon=True).start()
        batch = b"".join(b'{"id":%d,"cmd":"state"}\n' % i for i in range(100))
        t0 = time.perf_counter()
        while not stop.is_set():
            s.sendall(batch)
            flood_n[0] += 100
            d = t0 + flood_n[0] / 10000.0 - time.perf_counter()
            if d > 0:
                time.sleep(d)
        s.close()

    a = Api(port)
    a.ask("take_control")
    a.ask("reset")
    a.ask("enable")
    wait_idle(a)
    a.ask("subscribe", topic="state", rate_hz=1000)
    th = threading.Thread(target=flood, daemon=True)
    tf = time.perf_counter()
    th.start()
    a.ask("movej", q=[1.0, 0, 0, 0, 0, 0], speed_pct=30)
    time.sleep(0.5)
    t0 = time.perf_counter()
    i = a.send("estop")
    time.sleep(0.5)
    stop.set()
    th.join()
    rate = flood_n[0] / (time.perf_counter() - tf)
    with a.lock:
        ans = a.answers.get(i, (0, {}))[0]
        st = [(t, m) for t, m in a.states if t >= t0]
    seen = next(((t, m) for t, m in st if m["state"] != "moving"), None)
    cyc0 = next((m["cycle"] for t, m in st), 0)
    a.close()
    return (ans - t0) * 1e3, ((seen[0] - t0) * 1e3 if seen else -1), (seen[1]["state"] if seen else "?"), rate


def stream_main(exe, rates=(30, 100, 500), plant="first-order"):
    p, port, pty = start(exe, ("--pty", "--plant", plant))
    try:
        time.sleep(1)
        h = Api(port)
        j0 = h.ask("hello")["joints"][0]
        h.close()
        lim = (j0["max_velocity"], j0["max_acceleration"], j0["max_jerk"])
        print(f"joint 1 limits: v {lim[0]:.3f} rad/s, a {lim[1]:.3f} rad/s^2, j {lim[2]:.1f} rad/s^3")
        # each target as sent: its velocity estimated by the firmware from arrivals, estimated from
        # the client's times (t), or sent with it (qd) and its time
        modes = (("estimated", False, False), ("estimated, t", False, True), ("qd, t", True, True))
        for name, fn in (("sine", sine), ("hand", hand)):
            for rate in rates:
                for mode, qd, ts in modes:
                    r = stream_run(port, lim, fn, rate, send_qd=qd, send_t=ts)
                    c = r["counts"]
                    print(f"{name} {rate:3d} Hz {mode:12s}: targets {r['targets']} (refused {r['refused']}, stale "
                          f"{c.get('stale', 0)}, late max {c.get('late_max_ms', 0):.1f} ms, jitter {c.get('jitter_ms', 0):.2f} ms, "
                          f"this script's longest gap between targets {r['gap'] * 1e3:.0f} ms), "
                          f"samples {r['samples']}; stream: lag {r['lag']} ms, max error {r['err']:.4f} rad, unshifted max "
                          f"{r['err0']:.4f} rms {r['rms0']:.4f} rad, peak v/a/j {r['pk'][0]:.2f}/{r['pk'][1]:.2f}/{r['pk'][2]:.2f}; "
                          f"naive interpolation: lag {r['nlag']} ms, max error {r['nerr']:.4f} rad, peak v/a/j "
                          f"{r['npk'][0]:.2f}/{r['npk'][1]:.2f}/{r['npk'][2]:.2f}", flush=True)
        d, ms = deadman(port, lim)
        print(f"deadman: 0.5 rad/s stream stopped: rest {d * 1000:.1f} mrad beyond the last target, {ms:.0f} ms after it")
        med, p99 = roundtrips(port, "events", 1000)
        print(f"round trip API events: median {med:.3f} ms, p99 {p99:.3f} ms (1000)")
        med, p99 = pty_roundtrips(pty, 1000)
        print(f"round trip pty status: median {med:.3f} ms, p99 {p99:.3f} ms (1000)")
        ans, seen, state, rate = estop_under_flood(port)
        print(f"estop with a {rate:.0f} req/s flood: answered after {ans:.2f} ms, state stream shows {state} after {seen:.2f} ms")
    finally:
        p.terminate()
        p.wait()


def main():
    if "--stream" in sys.argv:
        rates = next((x.split("=", 1)[1] for x in sys.argv if x.startswith("--rates=")), "30,100,500")
        plant = next((x.split("=", 1)[1] for x in sys.argv if x.startswith("--plant=")), "first-order")
        return stream_main(next((x for x in sys.argv[1:] if not x.startswith("--")), "build/bin/armfw"),
                           tuple(int(r) for r in rates.split(",")), plant)
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
