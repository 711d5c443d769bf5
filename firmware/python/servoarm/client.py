# SPDX-License-Identifier: Apache-2.0
"""The client: one TCP connection of newline-delimited JSON to armfw (api.tcp_port).

A reader thread takes every line the server sends: results go to the call waiting for
their id, state samples to the subscriptions, events to the event log (and to the calls
they end: a fault or an e-stop while a move is waited for raises ArmStopped). Units are
SI: m, rad, s.
"""
from __future__ import annotations

import itertools
import json
import queue
import socket
import ssl
import threading
import time
from typing import Any, Dict, List, Optional, Sequence

__all__ = ["Arm", "ArmError", "ArmStopped", "Stream", "Subscription"]


class ArmError(Exception):
    """A request the firmware refused: `code` is its error code (docs/api.md), `message` one line.

    A program the firmware's check refused also names its place: `file`, `line` (1-based) and
    `step` (None otherwise)."""

    def __init__(self, code: str, message: str, cmd: str = "", fields: Optional[Dict[str, Any]] = None):
        super().__init__(f"{cmd}: {code}: {message}" if cmd else f"{code}: {message}")
        self.code = code
        self.message = message
        self.cmd = cmd
        f = fields or {}
        self.file: Optional[str] = f.get("file")
        self.line: Optional[int] = f.get("line")
        self.step: Optional[int] = f.get("step")


class ArmStopped(ArmError):
    """The arm stopped while a call waited for it: a fault, an e-stop or a stop (`event` says which)."""

    def __init__(self, event: Dict[str, Any]):
        super().__init__(str(event.get("kind", "stopped")), str(event.get("detail", "")))
        self.event = event


class Subscription:
    """State samples at the rate asked for: iterate, or get(timeout). Only the newest
    `keep` samples are kept: a reader that falls behind loses the oldest (counted in `lost`)."""

    def __init__(self, arm: "Arm", rate_hz: float, keep: int = 1000):
        self._arm = arm
        self.rate_hz = rate_hz
        self._q: "queue.Queue[Dict[str, Any]]" = queue.Queue(maxsize=keep)
        self.lost = 0

    def _put(self, sample: Dict[str, Any]) -> None:
        while True:
            try:
                self._q.put_nowait(sample)
                return
            except queue.Full:
                try:
                    self._q.get_nowait()
                    self.lost += 1
                except queue.Empty:
                    pass

    def get(self, timeout: Optional[float] = 1.0) -> Dict[str, Any]:
        """The next sample; queue.Empty after `timeout` s."""
        return self._q.get(timeout=timeout)

    def __iter__(self):
        while True:
            yield self.get(timeout=None)

    def close(self) -> None:
        self._arm._unsubscribe(self)


class Stream:
    """Streaming targets (servo mode): `send(q)` as often as the application produces targets;
    the first one starts the stream. The firmware brakes the arm to rest when no target comes
    within its deadman time (api.stream_deadman_ms), and ends the stream; so does a stop.

    Each target carries the time it was sampled (`t`, s on the client's monotonic clock; by
    default `time.monotonic()` when sent; `stamp=False`: none), so the firmware spaces targets
    by when they were sampled rather than when they arrived. `stale` counts the targets the
    firmware dropped as older than its newest; `stats` is the stream's counts from the last
    answer (targets, timed, stale, late_ms, late_max_ms, jitter_ms: docs/api.md)."""

    def __init__(self, arm: "Arm", stamp: bool = True):
        self._arm = arm
        self._started = False
        self.stamp = stamp
        self.clamped = 0
        self.stale = 0
        self.stats: Dict[str, Any] = {}

    def _time(self, t: Optional[float]) -> Dict[str, Any]:
        if t is not None:
            return {"t": float(t)}
        return {"t": time.monotonic()} if self.stamp else {}

    def _answer(self, r: Dict[str, Any]) -> None:
        self._started = True
        if r.get("clamped"):
            self.clamped += 1
        if r.get("stale"):
            self.stale += 1
        self.stats = r.get("stream", self.stats)

    def send(self, q: Sequence[float], qd: Optional[Sequence[float]] = None, t: Optional[float] = None) -> bool:
        """The newest target `q`, with its joint velocities `qd` when the application knows them
        (otherwise the firmware estimates them from the targets' times) and the time `t` it was
        sampled (s, the application's monotonic clock; default: now): the arm follows a moving
        target at its velocity instead of stopping at each one. False when the firmware dropped
        the target as not newer than one it has (counted in `stale`)."""
        args: Dict[str, Any] = {"q": [float(v) for v in q], **self._time(t)}
        if qd is not None:
            args["qd"] = [float(v) for v in qd]
        if not self._started:
            args["start"] = True
        r = self._arm.call("stream", **args)
        self._answer(r)
        return not r.get("stale", False)

    def send_pose(self, position: Sequence[float], rpy: Sequence[float], frame: str = "base",
                  t: Optional[float] = None) -> bool:
        """The newest Cartesian target: the active tool's `position` (m) and `rpy` (rad) in the base
        frame or the active user frame (`frame="user"`), solved by the firmware's IK, sampled at `t`
        as for send(). A pose out of reach or too far from the last target raises ArmError; the arm
        keeps its last target."""
        args: Dict[str, Any] = {"position": [float(v) for v in position], "rpy": [float(v) for v in rpy],
                                "frame": frame, **self._time(t)}
        if not self._started:
            args["start"] = True
        r = self._arm.call("stream_pose", **args)
        self._answer(r)
        return not r.get("stale", False)

    def restart(self) -> None:
        """The next send() starts a new stream (after the deadman or a stop ended this one)."""
        self._started = False

    def __enter__(self) -> "Stream":
        return self

    def __exit__(self, *exc) -> None:
        # Nothing to send: the deadman brings the arm to rest and ends the stream.
        self._started = False


class Arm:
    """One connection to armfw's API.

    >>> with Arm("127.0.0.1", token=None) as arm:   # doctest: +SKIP
    ...     arm.enable()
    ...     arm.movej([0.2, 0, 0, 0, 0, 0])

    `take_control`: ask for control at connect (the commands that move the arm need it).
    As a context manager the arm is disabled when the block ends (and control released).
    """

    def __init__(self, host: str = "127.0.0.1", token: Optional[str] = None, port: int = 8766,
                 timeout: float = 10.0, take_control: bool = True, tls: Optional[ssl.SSLContext] = None):
        self.timeout = timeout
        self._sock = socket.create_connection((host, port), timeout=timeout)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        if tls is not None:  # armfw with api.tls_cert: the certificate checked by the context
            self._sock = tls.wrap_socket(self._sock, server_hostname=host)
        self._sock.settimeout(None)
        self._wlock = threading.Lock()
        self._ids = itertools.count(1)
        self._pending: Dict[int, "queue.Queue[Dict[str, Any]]"] = {}
        self._plock = threading.Lock()
        self._subs: List[Subscription] = []
        self._events: List[Dict[str, Any]] = []
        self._ecv = threading.Condition()
        self._closed = False
        self.controller = 0
        self._reader = threading.Thread(target=self._read, name="servoarm-reader", daemon=True)
        self._reader.start()
        self.info = self.call("hello", **({"token": token} if token else {}))
        self.client = self.info.get("client", 0)
        self.joints = len(self.info.get("joints", []))
        self.call("subscribe", topic="events")
        if take_control:
            self.take_control()

    # -- transport -------------------------------------------------------------------------
    def _read(self) -> None:
        buf = b""
        try:
            while True:
                data = self._sock.recv(65536)
                if not data:
                    break
                buf += data
                while b"\n" in buf:
                    line, buf = buf.split(b"\n", 1)
                    if line:
                        self._dispatch(json.loads(line))
        except (OSError, ValueError):
            pass
        self._closed = True
        with self._plock:
            for q in self._pending.values():
                q.put({"error": "closed", "message": "the connection to armfw closed"})
        with self._ecv:
            self._ecv.notify_all()

    def _dispatch(self, m: Dict[str, Any]) -> None:
        topic = m.get("topic")
        if topic == "state" and "id" not in m:
            for s in list(self._subs):
                s._put(m)
        elif topic == "event":
            with self._ecv:
                self._events.append(m)
                del self._events[:-1000]
                self._ecv.notify_all()
        elif topic == "control":
            self.controller = m.get("holder", 0)
        elif "id" in m:
            with self._plock:
                q = self._pending.pop(m["id"], None)
            if q is not None:
                q.put(m)

    def call(self, cmd: str, **args: Any) -> Dict[str, Any]:
        """Send one request and return its result (a dict); ArmError when refused."""
        if self._closed:
            raise ArmError("closed", "the connection to armfw closed", cmd)
        rid = next(self._ids)
        q: "queue.Queue[Dict[str, Any]]" = queue.Queue(maxsize=1)
        with self._plock:
            self._pending[rid] = q
        line = json.dumps({"id": rid, "cmd": cmd, **args}, allow_nan=False) + "\n"
        with self._wlock:
            self._sock.sendall(line.encode())
        try:
            r = q.get(timeout=self.timeout)
        except queue.Empty:
            with self._plock:
                self._pending.pop(rid, None)
            raise ArmError("timeout", f"no answer within {self.timeout} s", cmd) from None
        if "error" in r:
            raise ArmError(r["error"], r.get("message", ""), cmd, r)
        return r

    def close(self) -> None:
        try:
            self._sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self._sock.close()
        self._reader.join(timeout=2)

    def __enter__(self) -> "Arm":
        return self

    def __exit__(self, *exc) -> None:
        try:
            if not self._closed and self.controller == self.client:
                self.call("disable")
                self.call("release_control")
        except ArmError:
            pass
        self.close()

    # -- control and state -------------------------------------------------------------------
    def take_control(self) -> None:
        self.call("take_control")
        self.controller = self.client

    def release_control(self) -> None:
        self.call("release_control")

    def enable(self, wait: bool = True) -> None:
        """Power the drives; `wait`: until the arm is idle (ArmStopped on a fault)."""
        seq = self._last_seq()
        self.call("enable")
        if wait:
            self._wait(lambda s: s["state"] == "idle", seq)

    def disable(self) -> None:
        self.call("disable")

    def stop(self) -> None:
        self.call("stop")

    def hold(self) -> None:
        self.call("hold")

    def resume(self) -> None:
        self.call("resume")

    def estop(self) -> None:
        self.call("estop")

    def reset(self) -> None:
        self.call("reset")

    def freedrive(self, on: bool = True) -> None:
        """Hand guiding on or off (needs `dynamics.freedrive = true` in armfw's configuration)."""
        self.call("freedrive", on=bool(on))

    def state(self) -> Dict[str, Any]:
        """One state sample (docs/api.md, Streams)."""
        return self.call("state")

    def subscribe(self, rate_hz: float = 50.0, keep: int = 1000) -> Subscription:
        """State samples at `rate_hz` (at most the control rate)."""
        s = Subscription(self, rate_hz, keep)
        self._subs.append(s)
        self.call("subscribe", topic="state", rate_hz=float(rate_hz))
        return s

    def _unsubscribe(self, s: Subscription) -> None:
        if s in self._subs:
            self._subs.remove(s)
        if not self._subs and not self._closed:
            self.call("unsubscribe", topic="state")

    def events(self, since: int = 0) -> List[Dict[str, Any]]:
        """The events received so far with a sequence number above `since`."""
        with self._ecv:
            return [e for e in self._events if e["seq"] > since]

    def stream(self, stamp: bool = True) -> Stream:
        """Streaming targets: `with arm.stream() as s: s.send(q)`; `stamp`: each target carries
        the time it was sampled (Stream)."""
        return Stream(self, stamp)

    # -- motion ----------------------------------------------------------------------------
    def home(self, joint: Optional[int] = None, wait: bool = True, timeout: float = 60.0) -> None:
        seq = self._last_seq()
        self.call("home", **({} if joint is None else {"joint": int(joint)}))
        if wait:
            time.sleep(0.05)
            self._wait(lambda s: s["state"] == "idle" and s["homing"] == 0, seq, timeout)

    def movej(self, q: Sequence[float], speed_pct: Optional[float] = None, blend: Optional[float] = None,
              wait: bool = True, timeout: float = 120.0) -> Dict[str, Any]:
        """A joint move (rad / m); `wait`: until it is done (ArmStopped on a fault, e-stop or stop)."""
        args: Dict[str, Any] = {"q": [float(v) for v in q]}
        if speed_pct is not None:
            args["speed_pct"] = float(speed_pct)
        if blend is not None:
            args["blend"] = float(blend)
        return self._move("movej", args, wait, timeout)

    def movel(self, position: Sequence[float], rpy: Optional[Sequence[float]] = None, speed: Optional[float] = None,
              blend: Optional[float] = None, wait: bool = True, timeout: float = 120.0) -> Dict[str, Any]:
        """A straight tool line to `position` (m, base frame), orientation `rpy` (rad) or kept."""
        args: Dict[str, Any] = {"position": [float(v) for v in position]}
        if rpy is not None:
            args["rpy"] = [float(v) for v in rpy]
        if speed is not None:
            args["speed"] = float(speed)
        if blend is not None:
            args["blend"] = float(blend)
        return self._move("movel", args, wait, timeout)

    def jog(self, joint: int, increment: Optional[float] = None, direction: Optional[int] = None,
            speed_pct: Optional[float] = None) -> Dict[str, Any]:
        args: Dict[str, Any] = {"joint": int(joint)}
        if increment is not None:
            args["increment"] = float(increment)
        if direction is not None:
            args["direction"] = int(direction)
        if speed_pct is not None:
            args["speed_pct"] = float(speed_pct)
        return self.call("jog", **args)

    def jog_cartesian(self, axis: int, frame: str = "base", increment: Optional[float] = None,
                      direction: Optional[int] = None, speed_pct: Optional[float] = None) -> Dict[str, Any]:
        """Jog the active tool along (axis 0..2: x, y, z, m) or about (3..5, rad) an axis of the
        `base`, `tool` or `user` frame: by `increment`, or continuously towards `direction`
        (+1 / -1; repeat within the jog deadman to keep it going)."""
        args: Dict[str, Any] = {"axis": int(axis), "frame": frame}
        if increment is not None:
            args["increment"] = float(increment)
        if direction is not None:
            args["direction"] = int(direction)
        if speed_pct is not None:
            args["speed_pct"] = float(speed_pct)
        return self.call("jog_cartesian", **args)

    def set_feed_override(self, pct: int) -> int:
        """The arm's feed override (percent, 10..200): scales jogs and the moves queued from now on."""
        return self.call("feed_override", pct=int(pct))["feed_pct"]

    # -- programs --------------------------------------------------------------------------
    @staticmethod
    def _program_args(text: Optional[str], name: Optional[str], gcode: bool) -> Dict[str, Any]:
        if text is None and name is None:
            raise ValueError("give the program's text or its name")
        args: Dict[str, Any] = {}
        if text is not None:
            args["text"] = text
            args["gcode"] = bool(gcode)
        if name is not None:
            args["name"] = name
        return args

    def save_program(self, name: str, text: str, gcode: bool = False) -> Dict[str, Any]:
        """Save `text` (native, or G-code with `gcode`) as program `name` in the controller's
        programs folder (replacing one of that name) once it loads; ArmError with the refused
        line otherwise, nothing written. The result's `file` is the file name."""
        return self.call("program_save", name=name, text=text, **({"gcode": True} if gcode else {}))

    def check_program(self, text: Optional[str] = None, name: Optional[str] = None, gcode: bool = False) -> Dict[str, Any]:
        """Check a whole program without running it (the firmware's dry run): its step counts
        and planned `duration`, or ArmError with the first refused line (`.line`, `.file`).
        `text`: the program (native, or G-code with `gcode`); `name`: a program of the
        controller's programs folder, or with `text` the name it is shown by."""
        return self.call("program_check", **self._program_args(text, name, gcode))

    def run_program(self, text: Optional[str] = None, name: Optional[str] = None, gcode: bool = False,
                    wait: bool = True, timeout: float = 600.0) -> Dict[str, Any]:
        """Check the whole program, then run it (a refused line: ArmError with `.line`, nothing
        moved). `wait`: until it has ended (ArmStopped on a fault, e-stop or stop); returns the
        run's answer (step counts, `program`: its state when it started)."""
        seq = self._last_seq()
        r = self.call("program_run", **self._program_args(text, name, gcode))
        if wait:
            self._wait(lambda s: s["program"]["state"] == "idle" and s["queued"] == 0, seq, timeout)
        return r

    def pause_program(self) -> Dict[str, Any]:
        """The running program pauses once its running motion is done (`resume` runs it on)."""
        return self.call("program_pause")["program"]

    def step_program(self) -> Dict[str, Any]:
        """A paused program runs its next motion, then pauses."""
        return self.call("program_step")["program"]

    def abort_program(self) -> None:
        """End the running program now and stop the arm."""
        self.call("program_abort")

    def program(self) -> Dict[str, Any]:
        """The running program's place: state, name, file, line, step, steps."""
        return self.state()["program"]

    # -- teach points, tools and frames ------------------------------------------------------
    def points(self) -> List[Dict[str, Any]]:
        """The teach points: name, q (rad / m), pose, tool, frame."""
        return self.call("points")["points"]

    def teach(self, name: str) -> Dict[str, Any]:
        """Store where the arm is as point `name` (kept in the controller's points file)."""
        return self.call("teach", name=name)["point"]

    def delete_point(self, name: str) -> None:
        self.call("point_delete", name=name)

    def go_to_point(self, name: str, line: bool = False, speed: Optional[float] = None,
                    wait: bool = True, timeout: float = 120.0) -> Dict[str, Any]:
        """Move to point `name`: a joint move (`speed`: percent of the joint limits), or with
        `line` a straight tool line (`speed`: m/s)."""
        args: Dict[str, Any] = {"name": name, "line": bool(line)}
        if speed is not None:
            args["speed"] = float(speed)
        return self._move("point_go", args, wait, timeout)

    def tools(self) -> Dict[str, Any]:
        """The tools and user frames (`tools`, `frames`: name, position, rpy) and the active `tool` and `frame`."""
        return self.call("tools")

    def select_tool(self, name: str) -> None:
        self.call("tool_select", name=name)

    def select_frame(self, name: str) -> None:
        self.call("frame_select", name=name)

    def define_tool(self, name: str, position: Sequence[float], rpy: Sequence[float] = (0.0, 0.0, 0.0),
                    mass: Optional[float] = None, com: Optional[Sequence[float]] = None) -> None:
        """Defines (or replaces) tool `name`: its point `position` (m) and `rpy` (rad) in the flange
        frame, and optionally its payload `mass` (kg) with its centre of mass `com` (m, tool frame)."""
        args: Dict[str, Any] = {"name": name, "position": [float(v) for v in position], "rpy": [float(v) for v in rpy]}
        if mass is not None:
            args["mass"] = float(mass)
        if com is not None:
            args["com"] = [float(v) for v in com]
        self.call("tool_define", **args)

    def delete_tool(self, name: str) -> None:
        self.call("tool_delete", name=name)

    def define_frame(self, name: str, position: Sequence[float], rpy: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
        """Defines (or replaces) user frame `name`: its origin `position` (m) and `rpy` (rad) in the base frame."""
        self.call("frame_define", name=name, position=[float(v) for v in position], rpy=[float(v) for v in rpy])

    def delete_frame(self, name: str) -> None:
        self.call("frame_delete", name=name)

    def _move(self, cmd: str, args: Dict[str, Any], wait: bool, timeout: float) -> Dict[str, Any]:
        seq = self._last_seq()
        r = self.call(cmd, **args)
        if wait:
            mid = r["motion"]
            self._wait(lambda s: s["done"] >= mid and s["running"] == 0 or s["done"] >= mid and s["queued"] == 0, seq, timeout)
        return r

    def _last_seq(self) -> int:
        with self._ecv:
            return self._events[-1]["seq"] if self._events else 0

    def _wait(self, done, seq: int, timeout: float = 30.0) -> None:
        end = time.monotonic() + timeout
        while True:
            for e in self.events(seq):
                if e["kind"] in ("fault", "estop") or (e["kind"] == "state" and e["state"] in ("stopping", "fault", "estop")):
                    raise ArmStopped(e)
            s = self.state()
            if s["state"] in ("fault", "estop"):
                raise ArmStopped({"kind": s["state"], "detail": s["fault"]["text"]})
            if done(s):
                return
            if time.monotonic() > end:
                raise ArmError("timeout", f"not done within {timeout} s")
            with self._ecv:
                self._ecv.wait(0.02)
