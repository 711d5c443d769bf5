#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Leader / follower teleoperation: the leader's measured joints, streamed to the follower.

  teleop.py --leader HOST:PORT --follower HOST:PORT [--rate 100] [--seconds 10]
  teleop.py --from-file FILE --follower HOST:PORT [--rate 100]

The leader is another armfw (in free-drive, a person moves it; or any motion), read through its
state stream; with --from-file each line of FILE (or of a pipe or socket: `-` is stdin) is one set
of joint values (rad / m, whitespace-separated), a leader device of your own. The follower
tracks every target jerk-limited; when the targets stop, its deadman brakes it to rest. At the
end the follower's lag and error are printed (one line).
"""
import argparse
import sys
import time

sys.path.insert(0, __import__("os").path.join(__import__("os").path.dirname(__file__), ".."))
from servoarm import Arm  # noqa: E402


def host_port(s):
    h, _, p = s.rpartition(":")
    return h or "127.0.0.1", int(p)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--leader")
    ap.add_argument("--from-file")
    ap.add_argument("--follower", required=True)
    ap.add_argument("--token")
    ap.add_argument("--rate", type=float, default=100.0)
    ap.add_argument("--seconds", type=float, default=10.0)
    a = ap.parse_args(argv)
    if (a.leader is None) == (a.from_file is None):
        ap.error("give one of --leader and --from-file")
    fh, fp = host_port(a.follower)
    follower = Arm(fh, token=a.token, port=fp)
    if follower.state()["state"] == "disabled":
        follower.enable()
    errors = []
    period = 1.0 / a.rate
    with follower.stream() as st:
        if a.leader:
            lh, lp = host_port(a.leader)
            leader = Arm(lh, token=a.token, port=lp, take_control=False)
            sub = leader.subscribe(a.rate)
            end = time.monotonic() + a.seconds
            while time.monotonic() < end:
                s = sub.get(timeout=2)
                st.send(s["q"])
                errors.append(max(abs(x - y) for x, y in zip(follower.state()["q"], s["q"])))
            leader.close()
        else:
            f = sys.stdin if a.from_file == "-" else open(a.from_file)
            for line in f:
                if not line.strip() or line.lstrip().startswith("#"):
                    continue
                q = [float(v) for v in line.split()]
                t0 = time.monotonic()
                st.send(q)
                errors.append(max(abs(x - y) for x, y in zip(follower.state()["q"], q)))
                time.sleep(max(0.0, period - (time.monotonic() - t0)))
    errors.sort()
    if errors:
        print(f"teleop: {len(errors)} targets, follower error median {errors[len(errors) // 2]:.4f} "
              f"max {errors[-1]:.4f} (rad / m), clamped {st.clamped}")
    follower.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
