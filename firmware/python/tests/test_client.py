# SPDX-License-Identifier: Apache-2.0
"""The Python client against `armfw --sim` (the real firmware with virtual drives), one armfw
per test class, on a free port. ARMFW names the armfw binary (CTest sets it); ARMFW_EMULATOR, when
set, the program (and its arguments) that runs it (a cross tree's qemu-user)."""
import math
import os
import re
import shutil
import ssl
import subprocess
import tempfile
import threading
import time
import unittest

from servoarm import Arm, ArmError, ArmStopped


class ArmfwSim:
    def __init__(self, extra=()):
        exe = os.environ.get("ARMFW", "build/bin/armfw")
        emu = os.environ.get("ARMFW_EMULATOR", "").split()
        self.p = subprocess.Popen([*emu, exe, "--sim", "--no-stdin", "--api-tcp", "0", *extra], stderr=subprocess.PIPE,
                                  stdout=subprocess.DEVNULL, text=True)
        self.port = None
        self.lines = []
        end = time.monotonic() + 30
        while self.port is None and time.monotonic() < end:
            line = self.p.stderr.readline()
            if not line:
                break
            self.lines.append(line)
            m = re.search(r"TCP port (\d+)", line)
            if m:
                self.port = int(m.group(1))
        if self.port is None:
            self.stop()
            raise RuntimeError("armfw did not start its API: " + "".join(self.lines))
        threading.Thread(target=self._drain, daemon=True).start()

    def _drain(self):
        for line in self.p.stderr:
            self.lines.append(line)

    def stop(self):
        self.p.terminate()
        try:
            self.p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.p.kill()


def recover(arm, timeout=10.0):
    """Reset an arm in e-stop or fault once its drives are at rest (reset is refused before)."""
    end = time.monotonic() + timeout
    while arm.state()["state"] in ("estop", "fault", "stopping") and time.monotonic() < end:
        try:
            arm.reset()
        except ArmError:
            time.sleep(0.05)


class TlsTest(unittest.TestCase):
    """armfw with --api-tls-cert / --api-tls-key: a client checking the certificate connects over
    TLS; a certificate path that cannot be read refuses the start in one line."""

    def setUp(self):
        self.dir = tempfile.mkdtemp(prefix="servoarm_tls_")
        self.cert, self.key = os.path.join(self.dir, "cert.pem"), os.path.join(self.dir, "key.pem")
        subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "2", "-subj",
                        "/CN=localhost", "-addext", "subjectAltName=IP:127.0.0.1", "-keyout", self.key, "-out",
                        self.cert], check=True, capture_output=True)

    def tearDown(self):
        shutil.rmtree(self.dir, ignore_errors=True)

    def test_tls_client(self):
        fw = ArmfwSim(["--api-tls-cert", self.cert, "--api-tls-key", self.key])
        try:
            ctx = ssl.create_default_context(cafile=self.cert)
            with Arm("127.0.0.1", port=fw.port, tls=ctx) as arm:
                self.assertEqual(arm.info["protocol"], 1)
                self.assertIn("state", arm.state())
            # every connection answers: 60 in a row (a handshake that stalls is closed after 5 s)
            answered = 0
            for _ in range(60):
                with Arm("127.0.0.1", port=fw.port, tls=ctx, take_control=False) as arm:
                    answered += arm.info["protocol"] == 1
            self.assertEqual(answered, 60)
            other = ssl.create_default_context()  # without the certificate as a CA: refused
            with self.assertRaises(ssl.SSLError):
                Arm("127.0.0.1", port=fw.port, tls=other)
        finally:
            fw.stop()

    def test_bad_certificate_path(self):
        exe = os.environ.get("ARMFW", "build/bin/armfw")
        p = subprocess.run([exe, "--sim", "--no-stdin", "--api-tcp", "0", "--api-tls-cert",
                            os.path.join(self.dir, "missing.pem"), "--api-tls-key", self.key],
                           capture_output=True, text=True, timeout=30)
        self.assertNotEqual(p.returncode, 0)
        self.assertIn("api.tls_cert = " + os.path.join(self.dir, "missing.pem") + ": No such file", p.stderr)


class ConfiguredArmTest(unittest.TestCase):
    """armfw --sim with a configuration file, its console on a pipe: what hello and the state
    samples say about the configured arm."""

    def start(self, toml):
        args = [os.environ.get("ARMFW", "build/bin/armfw"), "--sim", "--api-tcp", "0"]
        if toml is not None:
            path = os.path.join(self.dir, "armfw%d.toml" % len(os.listdir(self.dir)))
            with open(path, "w") as f:
                f.write(toml)
            args += ["--config", path]
        p = subprocess.Popen(args, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.procs.append(p)
        port = None
        end = time.monotonic() + 30
        while port is None and time.monotonic() < end:
            line = p.stderr.readline()
            if not line:
                break
            m = re.search(r"TCP port (\d+)", line)
            port = int(m.group(1)) if m else None
        self.assertIsNotNone(port, "armfw did not start its API")
        threading.Thread(target=lambda: [None for _ in p.stderr], daemon=True).start()
        return p, port

    def console_checksum(self, p):
        p.stdin.write("safety\n")
        p.stdin.flush()
        end = time.monotonic() + 10
        while time.monotonic() < end:
            line = p.stdout.readline()
            m = re.search(r"checksum=([0-9A-F]{8})", line)
            if m:
                return m.group(1)
        self.fail("no checksum in the console's `safety` answer")

    def setUp(self):
        self.dir = tempfile.mkdtemp(prefix="servoarm_safety_hello_")
        self.procs = []

    def tearDown(self):
        for p in self.procs:
            p.terminate()
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
        shutil.rmtree(self.dir, ignore_errors=True)

    def test_state_carries_the_motors_temperatures(self):
        """Four Damiao motors report their temperature, two CiA 402 drives on a second bus none
        (null, not a measured number); no joint is over its warning temperature."""
        toml = 'robot = "puma560"\n[bus]\ncan = "sim"\n'
        for j in range(6):
            toml += "[[drive]]\nnode = %d\n" % (j + 1)
            toml += 'can = "can1"\n' if j >= 4 else 'family = "damiao"\nmotor = "DM-J4340"\nmit_kp = 60\nmit_kd = 2\n'
        _, port = self.start(toml)
        with Arm("127.0.0.1", port=port) as arm:
            st = arm.state()
            temps = st["temperature"]
            self.assertEqual(len(temps), 6)
            self.assertTrue(all(isinstance(t, (int, float)) and 0 < t < 100 for t in temps[:4]), temps)
            self.assertEqual(temps[4:], [None, None])
            self.assertEqual(st["temperature_warning"], 0)

    def test_hello_carries_the_safety_checksum(self):
        """hello tells the safety envelope armfw runs with: enabled and the checksum that the
        console's `safety` shows for the same armfw; another envelope, another checksum; none: off."""
        table = "[safety]\nplanes = [0, 0, 1, -300]\ntool_radius_mm = 20\n"
        p, port = self.start(table)
        with Arm("127.0.0.1", port=port) as arm:
            s = arm.info["safety"]
            self.assertTrue(s["enabled"])
            self.assertEqual(s["checksum"], self.console_checksum(p))
            self.assertEqual(arm.state()["safety_mode"], "normal")
        _, port2 = self.start(table.replace("-300", "-250"))
        with Arm("127.0.0.1", port=port2) as arm:
            self.assertTrue(arm.info["safety"]["enabled"])
            self.assertNotEqual(arm.info["safety"]["checksum"], s["checksum"])
        _, port3 = self.start(None)
        with Arm("127.0.0.1", port=port3) as arm:
            self.assertFalse(arm.info["safety"]["enabled"])


class ProgramSaveTest(unittest.TestCase):
    """save_program writes a program that loads into the programs folder (--programs), where
    check_program finds it by name; a bad name, a text that does not load: refused, nothing written."""

    def test_save_program(self):
        d = tempfile.mkdtemp(prefix="servoarm_programs_")
        fw = ArmfwSim(["--programs", d])
        try:
            with Arm("127.0.0.1", port=fw.port) as arm:
                r = arm.save_program("square", "movej 0 0 0 0 0 0\nmovej 10 0 0 0 0 0\n")
                self.assertEqual(r["file"], "square.arm")
                with open(os.path.join(d, "square.arm")) as f:
                    self.assertEqual(f.read(), "movej 0 0 0 0 0 0\nmovej 10 0 0 0 0 0\n")
                self.assertEqual(arm.check_program(name="square")["steps"], 2)
                with self.assertRaises(ArmError) as e:
                    arm.save_program("../evil", "movej 0 0 0 0 0 0\n")
                self.assertEqual(e.exception.code, "bad_option")
                with self.assertRaises(ArmError) as e:
                    arm.save_program("broken", "movej 0 0 0 0 0 0\nfrobnicate 3\n")
                self.assertEqual(e.exception.code, "program")
                self.assertEqual(e.exception.line, 2)
                self.assertEqual(sorted(os.listdir(d)), ["square.arm"])
        finally:
            fw.stop()
            shutil.rmtree(d, ignore_errors=True)


class ClientTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        # The streams' deadman at 1 s instead of 100 ms: this Python loop stalls longer than
        # 100 ms on a loaded machine, which ends a stream the test is still sending.
        cls.cfg = tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False)
        cls.cfg.write("[api]\nstream_deadman_ms = 1000\n")
        cls.cfg.close()
        cls.fw = ArmfwSim(["--config", cls.cfg.name])

    @classmethod
    def tearDownClass(cls):
        cls.fw.stop()
        os.unlink(cls.cfg.name)

    def arm(self, **kw):
        return Arm("127.0.0.1", port=self.fw.port, **kw)

    def test_hello_enable_movej_movel(self):
        with self.arm() as arm:
            self.assertEqual(arm.info["protocol"], 1)
            self.assertEqual(arm.joints, 6)
            arm.enable()
            r = arm.movej([0.2, -0.3, 0.4, 0, 0.3, 0], speed_pct=80)
            self.assertGreater(r["motion"], 0)
            s = arm.state()
            self.assertAlmostEqual(s["q_cmd"][0], 0.2, places=6)
            p = s["tool"]["position"]
            arm.movel([p[0], p[1], p[2] - 0.02], speed=0.1)
            self.assertAlmostEqual(arm.state()["tool"]["position"][2], p[2] - 0.02, delta=2e-3)
            with self.assertRaises(ArmError) as e:
                arm.movej([0.1] * 5)
            self.assertEqual(e.exception.code, "arg_count")
            with self.assertRaises(ValueError):  # NaN never leaves the client (JSON has none)
                arm.movej([float("nan")] * 6)
            arm.movej([0] * 6)
        with self.arm(take_control=False) as obs:  # the context manager disabled the arm
            self.assertEqual(obs.state()["state"], "disabled")

    def test_subscribe(self):
        with self.arm(take_control=False) as arm:
            sub = arm.subscribe(100)
            first = sub.get(timeout=2)
            t0 = time.monotonic()
            n = 0
            while time.monotonic() - t0 < 1.0:
                s = sub.get(timeout=2)
                n += 1
            self.assertGreater(s["cycle"], first["cycle"])
            self.assertGreater(n, 50)
            self.assertLess(n, 150)
            sub.close()

    def test_stream_and_deadman(self):
        with self.arm() as arm:
            arm.enable()
            q0 = arm.state()["q_cmd"]
            # the events from here on: the stream's end may come before this script looks again
            # (a loaded machine stalls it past the deadman)
            seq = max([e["seq"] for e in arm.events()] or [0])
            with arm.stream() as st:
                t0 = time.monotonic()
                while time.monotonic() - t0 < 1.0:
                    t = time.monotonic() - t0
                    q = list(q0)
                    q[0] = q0[0] + 0.2 * math.sin(2 * math.pi * 0.5 * t)
                    st.send(q)
                    time.sleep(0.02)
                self.assertTrue(arm.state()["streaming"])
            end = time.monotonic() + 10  # no target: after the deadman (1 s) the arm brakes to rest
            s = arm.state()
            while (s["streaming"] or s["state"] != "idle") and time.monotonic() < end:
                time.sleep(0.05)
                s = arm.state()
            self.assertFalse(s["streaming"])
            self.assertEqual(s["state"], "idle")
            # events come on their own push, which may arrive after the state answer above
            stopped = lambda: any(e["kind"] == "jog_stopped" and "stream stopped" in e["detail"]
                                  for e in arm.events(seq))
            while not stopped() and time.monotonic() < end + 5:
                time.sleep(0.05)
            self.assertTrue(stopped(), arm.events(seq))

    def test_stream_with_velocities_moves_through_the_targets(self):
        # 30 Hz of a 0.5 Hz sine on joint 0, each target with its velocity: mid-swing the arm's
        # commanded velocity keeps the sine's sign and most of its size (it does not stop at
        # each target); a wrong number of velocities is refused.
        with self.arm() as arm:
            arm.enable()
            q0 = arm.state()["q_cmd"]
            amp, w = 0.2, 2 * math.pi * 0.5
            sub = arm.subscribe(200)
            ratios = []
            with arm.stream() as st:
                t0 = time.monotonic()
                while time.monotonic() - t0 < 2.0:
                    t = time.monotonic() - t0
                    q, qd = list(q0), [0.0] * len(q0)
                    q[0] = q0[0] + amp * math.sin(w * t)
                    qd[0] = amp * w * math.cos(w * t)
                    st.send(q, qd)
                    end = time.monotonic() + 1 / 30
                    while time.monotonic() < end:  # (never waiting past the next target's time)
                        try:
                            s = sub.get(timeout=max(0.001, end - time.monotonic()))
                        except Exception:
                            continue
                        ts = time.monotonic() - t0
                        v = amp * w * math.cos(w * ts)
                        if ts > 0.5 and abs(v) > 0.6 * amp * w:
                            ratios.append(s["qd_cmd"][0] / v)
                with self.assertRaises(ArmError) as e:
                    st.send(q0, [0.0] * 5)
                self.assertEqual(e.exception.code, "arg_count")
            sub.close()
            self.assertGreater(len(ratios), 20)
            self.assertGreater(min(ratios), 0.3, ratios)

    def test_stream_timestamps(self):
        # Each target carries time.monotonic() by default; one older than the newest is dropped
        # (send returns False, counted in stale and in the answer's counts); a negative time is
        # refused; stamp=False sends none.
        with self.arm() as arm:
            arm.enable()
            q0 = arm.state()["q_cmd"]
            with arm.stream() as st:
                self.assertTrue(st.send(q0))
                t1 = time.monotonic()
                self.assertTrue(st.send(q0, t=t1))
                self.assertEqual(st.stats["timed"], 2)
                q = list(q0)
                q[0] += 0.3
                self.assertFalse(st.send(q, t=t1 - 0.01))
                self.assertEqual(st.stale, 1)
                self.assertEqual(st.stats["stale"], 1)
                with self.assertRaises(ArmError) as e:
                    st.send(q0, t=-1.0)
                self.assertEqual(e.exception.code, "out_of_range")
                self.assertTrue(st.send(q0))
                self.assertLess(abs(arm.state()["q_cmd"][0] - q0[0]), 1e-6)
            time.sleep(0.3)
            with arm.stream(stamp=False) as st:
                st.send(q0)
                self.assertEqual(st.stats["timed"], 0)
                self.assertEqual(st.stats["targets"], 1)

    def test_stream_poses(self):
        # Cartesian targets at 30 Hz: 20 mm down along z, the orientation kept; then a pose out of
        # reach is refused (unreachable) and the arm stays where the last good target was.
        with self.arm() as arm:
            arm.enable()
            tool = arm.state()["tool"]
            p0, rpy = tool["position"], tool["rpy"]
            with arm.stream() as st:
                def send(p):
                    # a stall of this loop past the deadman (a loaded machine) ends the stream: the
                    # arm brakes to rest and the next target starts a new one from there
                    try:
                        st.send_pose(p, rpy)
                    except ArmError as e:
                        if e.code != "bad_state" or "stream ended" not in e.message:
                            raise
                        st.restart()
                        st.send_pose(p, rpy)
                for k in range(31):
                    send([p0[0], p0[1], p0[2] - 0.02 * k / 30])
                    time.sleep(1 / 30)
                for _ in range(10):
                    send([p0[0], p0[1], p0[2] - 0.02])
                    time.sleep(1 / 30)
                self.assertAlmostEqual(arm.state()["tool"]["position"][2], p0[2] - 0.02, delta=1e-3)
                with self.assertRaises(ArmError) as e:
                    st.send_pose([p0[0] + 5, p0[1], p0[2]], rpy)
                self.assertEqual(e.exception.code, "unreachable")
                time.sleep(0.05)
                self.assertAlmostEqual(arm.state()["tool"]["position"][2], p0[2] - 0.02, delta=1e-3)

    def test_define_tool_and_frame_movel_in_them(self):
        # A 100 mm tool and a frame shifted 50 mm along x: movel to the frame's coordinates of the
        # tool point moves that point there (the state's tool pose is the flange's: compared as a
        # difference); bad definitions are refused; the active tool is not deleted.
        with self.arm() as arm:
            arm.enable()
            arm.movej([0, 0.3, -0.6, 0, 0.6, 0], speed_pct=50)
            arm.define_tool("pen", [0, 0, 0.1])
            arm.define_frame("table", [0.05, 0, 0])
            with self.assertRaises(ArmError) as e:
                arm.define_tool("bad name", [0, 0, 0.1])
            self.assertEqual(e.exception.code, "bad_option")
            self.assertIn("pen", [t["name"] for t in arm.tools()["tools"]])
            arm.select_tool("pen")
            arm.select_frame("table")
            t = arm.state()["tool"]  # the flange: the pen point is 100 mm along its z
            a, (r, p, y) = t["position"], t["rpy"]
            z_axis = [math.cos(y) * math.sin(p) * math.cos(r) + math.sin(y) * math.sin(r),
                      math.sin(y) * math.sin(p) * math.cos(r) - math.cos(y) * math.sin(r),
                      math.cos(p) * math.cos(r)]
            pen = [a[i] + 0.1 * z_axis[i] for i in range(3)]
            # 10 mm along the table's x from the pen's point, in table coordinates; the orientation
            # kept, the flange moves as the pen point does
            arm.movel([pen[0] - 0.05 + 0.01, pen[1], pen[2]], speed=0.1)
            b = arm.state()["tool"]["position"]
            self.assertAlmostEqual(b[2] - a[2], 0.0, delta=1e-3)
            self.assertAlmostEqual(b[0] - a[0], 0.01, delta=1e-3)
            self.assertAlmostEqual(b[1] - a[1], 0.0, delta=1e-3)
            with self.assertRaises(ArmError):
                arm.delete_tool("pen")
            arm.select_tool("tool0")
            arm.select_frame("base")
            arm.delete_tool("pen")
            arm.delete_frame("table")
            self.assertNotIn("pen", [t["name"] for t in arm.tools()["tools"]])

    def test_estop_from_another_client_ends_the_wait(self):
        with self.arm() as arm:
            arm.enable()
            other = self.arm(take_control=False)
            threading.Timer(0.3, other.estop).start()
            with self.assertRaises(ArmStopped) as e:
                arm.movej([1.5, 0, 0, 0, 0, 0], speed_pct=10)
            self.assertEqual(e.exception.code, "estop")
            other.close()
            recover(arm)

    def test_programs(self):
        with self.arm() as arm:
            arm.enable()
            bad = "movej 0 0 0 0 0 0\nmovej 10 0 0 0 0 0\nmovel 5000 0 500 0 0 0\n"
            with self.assertRaises(ArmError) as e:
                arm.check_program(bad)
            self.assertEqual(e.exception.line, 3)
            self.assertEqual(e.exception.step, 2)
            done = arm.state()["done"]
            with self.assertRaises(ArmError) as e:
                arm.run_program(bad)
            self.assertEqual(e.exception.line, 3)
            time.sleep(0.3)
            self.assertEqual(arm.state()["done"], done)  # nothing moved
            good = "movej 10 0 0 0 0 0\ndwell 0.1\nmovej 0 0 0 0 0 0\n"
            c = arm.check_program(good)
            self.assertEqual((c["steps"], c["joint_moves"], c["dwells"]), (3, 2, 1))
            arm.run_program(good, name="swing")
            s = arm.state()
            self.assertEqual(s["program"]["state"], "idle")
            self.assertEqual(s["done"], done + 3)  # two moves and the dwell
            self.assertAlmostEqual(s["q_cmd"][0], 0.0, places=9)
            arm.run_program("movej 30 0 0 0 0 0\nmovej 0 0 0 0 0 0\n", wait=False)
            self.assertEqual(arm.program()["state"], "running")
            arm.abort_program()
            self.assertEqual(arm.program()["state"], "idle")

    def test_points_tools_cartesian_jog_override(self):
        with self.arm() as arm:
            arm.enable()
            arm.movej([0, 0.3, -0.6, 0, 0.6, 0])
            p = arm.teach("py1")
            self.assertIn("py1", [x["name"] for x in arm.points()])
            arm.movej([0.2, 0.3, -0.6, 0, 0.6, 0])
            arm.go_to_point("py1")
            for a, b in zip(arm.state()["q_cmd"], p["q"]):
                self.assertAlmostEqual(a, b, places=9)
            arm.delete_point("py1")
            self.assertNotIn("py1", [x["name"] for x in arm.points()])
            t = arm.tools()
            self.assertEqual((t["tool"], t["frame"]), ("tool0", "base"))
            with self.assertRaises(ArmError) as e:
                arm.select_tool("no_such_tool")
            self.assertEqual(e.exception.code, "bad_option")
            x0 = arm.state()["tool"]["position"][0]
            arm.jog_cartesian(0, "base", increment=0.01)
            end = time.monotonic() + 10
            while arm.state()["state"] != "idle" and time.monotonic() < end:
                time.sleep(0.02)
            time.sleep(0.1)
            self.assertAlmostEqual(arm.state()["tool"]["position"][0], x0 + 0.01, delta=1e-3)
            self.assertEqual(arm.set_feed_override(50), 50)
            self.assertEqual(arm.state()["feed_pct"], 50)
            arm.set_feed_override(100)


if __name__ == "__main__":
    unittest.main()
