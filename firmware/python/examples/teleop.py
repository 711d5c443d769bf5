#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Leader / follower teleoperation: the leader's measured joints, streamed to the follower.

  teleop.py --leader HOST:PORT --follower HOST:PORT [--rate 100] [--seconds 10]
  teleop.py --from-file FILE --follower HOST:PORT [--rate 100]

The leader is another armfw (in free-drive, a person moves it; or any motion), read through its
state stream; each target carries the leader's sample time (its control thread's clock, `t` of
the state sample), so the follower spaces the targets by when the leader measured them, not by
when they arrived through two network hops and this loop; with --from-file each line of FILE (or of a pipe or socket: `-` is stdin) is one set
of joint values (rad / m, whitespace-separated), a leader device of your own. The follower
tracks every target jerk-limited; when the targets stop, its deadman brakes it to rest. A file's
last line is held (sent on at the rate) until the follower rests within 0.001 of it or --settle
seconds pass, so a replay ends where the file does even when the follower lags. At the
end the follower's lag and error are printed (one line): the error is the largest joint
difference between the follower's measured joints and the leader's sample sent just before,
the lag the time shift of the leader's motion that best matches the follower's (least squares
over the run after its first second, 5 ms steps up to 1 s), the error left after that shift, and how far the leader
moved (its largest joint range over the run).
"""
import argparse
import queue
import sys
import time

sys.path.insert(0, __import__("os").path.join(__import__("os").path.dirname(__file__), ".."))
from servoarm import Arm, ArmError  # noqa: E402


def host_port(s):
    h, _, p = s.rpartition(":")
    return h or "127.0.0.1", int(p)


def lag_and_error(leader, follower, settle=1.0):
    """leader, follower: lists of (time, q). The shift of the leader's samples (s) that best
    matches the follower's, and the largest and median joint difference after it, from `settle`
    s after the first target on (before, the follower moves from where it was to the leader)."""
    if len(leader) < 2 or len(follower) < 2:
        return 0.0, 0.0, 0.0
    follower = [(t, q) for t, q in follower if t >= follower[0][0] + settle] or follower
    lt = [t for t, _ in leader]

    def leader_at(t):
        if t <= lt[0]:
            return leader[0][1]
        if t >= lt[-1]:
            return leader[-1][1]
        lo, hi = 0, len(lt) - 1
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if lt[mid] <= t:
                lo = mid
            else:
                hi = mid
        a = (t - lt[lo]) / (lt[hi] - lt[lo]) if lt[hi] > lt[lo] else 0.0
        return [x + a * (y - x) for x, y in zip(leader[lo][1], leader[hi][1])]

    def errors(shift):
        return [max(abs(x - y) for x, y in zip(q, leader_at(t - shift))) for t, q in follower if t - shift >= lt[0]]

    best = (float("inf"), 0.0)
    for k in range(0, 201):
        e = errors(0.005 * k)
        if e:
            rms = (sum(x * x for x in e) / len(e)) ** 0.5
            best = min(best, (rms, 0.005 * k))
    e = sorted(errors(best[1]))
    return best[1], (e[-1] if e else 0.0), (e[len(e) // 2] if e else 0.0)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--leader")
    ap.add_argument("--from-file")
    ap.add_argument("--follower", required=True)
    ap.add_argument("--token")
    ap.add_argument("--rate", type=float, default=100.0)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--settle", type=float, default=5.0)
    a = ap.parse_args(argv)
    if (a.leader is None) == (a.from_file is None):
        ap.error("give one of --leader and --from-file")
    fh, fp = host_port(a.follower)
    follower = Arm(fh, token=a.token, port=fp)
    if follower.state()["state"] == "disabled":
        follower.enable()
    errors = []
    lead_log, follow_log = [], []  # (time, q): the lag estimate
    period = 1.0 / a.rate
    restarts = 0

    def send(st, q, t=None):
        # A stall of this script longer than the follower's deadman (a loaded machine) ends the
        # stream: the follower brakes to rest; the next target starts a new one from there.
        # `t`: when the target was sampled (the leader's clock); None: now, on this machine's.
        nonlocal restarts
        try:
            st.send(q, t=t)
        except ArmError as e:
            if e.code != "bad_state" or "stream ended" not in e.message:
                raise
            restarts += 1
            st.restart()
            st.send(q, t=t)

    with follower.stream() as st:
        if a.leader:
            lh, lp = host_port(a.leader)
            leader = Arm(lh, token=a.token, port=lp, take_control=False)
            sub = leader.subscribe(a.rate)
            end = time.monotonic() + a.seconds
            while time.monotonic() < end:
                s = sub.get(timeout=2)
                while True:  # the newest sample: a slow loop streams where the leader is, not where it was
                    try:
                        s = sub.get(timeout=0)
                    except queue.Empty:
                        break
                send(st, s["q"], s["t"])
                lead_log.append((time.monotonic(), s["q"]))
                qf = follower.state()["q"]
                follow_log.append((time.monotonic(), qf))
                errors.append(max(abs(x - y) for x, y in zip(qf, s["q"])))
            leader.close()
        else:
            f = sys.stdin if a.from_file == "-" else open(a.from_file)
            for line in f:
                if not line.strip() or line.lstrip().startswith("#"):
                    continue
                q = [float(v) for v in line.split()]
                t0 = time.monotonic()
                send(st, q)
                lead_log.append((time.monotonic(), q))
                qf = follower.state()["q"]
                follow_log.append((time.monotonic(), qf))
                errors.append(max(abs(x - y) for x, y in zip(qf, q)))
                time.sleep(max(0.0, period - (time.monotonic() - t0)))
            if f is not sys.stdin:
                f.close()
            end = time.monotonic() + a.settle
            while lead_log and time.monotonic() < end:  # hold the last line until the follower rests there
                q = lead_log[-1][1]
                fs = follower.state()
                # at rest too: a follower passing the line on its way would otherwise be left to
                # carry on at the lines' speed to where the target was extrapolated
                if max(abs(x - y) for x, y in zip(fs["q"], q)) < 1e-3 and max(map(abs, fs["qd_cmd"])) < 1e-3:
                    break
                send(st, q)
                time.sleep(period)
    errors.sort()
    if errors:
        lag, lag_max, lag_med = lag_and_error(lead_log, follow_log)
        span = max(max(q[j] for _, q in lead_log) - min(q[j] for _, q in lead_log) for j in range(len(lead_log[0][1])))
        print(f"teleop: {len(errors)} targets, follower error median {errors[len(errors) // 2]:.4f} "
              f"max {errors[-1]:.4f} (rad / m), clamped {st.clamped}, stream restarts {restarts}; "
              f"lag {lag * 1e3:.0f} ms, error after it median {lag_med:.4f} max {lag_max:.4f}; "
              f"the leader's largest joint range {span:.3f}")
    follower.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
