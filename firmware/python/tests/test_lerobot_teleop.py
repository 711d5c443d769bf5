# SPDX-License-Identifier: Apache-2.0
"""The LeRobot-style adapter and the teleoperation example against `armfw --sim` instances."""
import os
import subprocess
import sys
import time
import unittest

from servoarm import Arm
from servoarm.lerobot import ServoarmRobot, ServoarmRobotConfig

sys.path.insert(0, os.path.dirname(__file__))
from test_client import ArmfwSim, recover  # noqa: E402

EXAMPLES = os.path.join(os.path.dirname(__file__), "..", "examples")


class LeRobotAdapterTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.fw = ArmfwSim()

    @classmethod
    def tearDownClass(cls):
        cls.fw.stop()

    def test_robot_interface(self):
        r = ServoarmRobot(ServoarmRobotConfig(port=self.fw.port, max_relative_target=0.05))
        self.assertFalse(r.is_connected)
        r.connect()
        try:
            self.assertTrue(r.is_connected)
            self.assertTrue(r.is_calibrated)
            names = [f"joint_{i}.pos" for i in range(1, 7)]
            self.assertEqual(list(r.observation_features), names)
            self.assertEqual(list(r.action_features), names)
            obs = r.get_observation()
            self.assertEqual(set(obs), set(names))
            goal = dict(obs)
            goal["joint_1.pos"] = obs["joint_1.pos"] + 0.3
            sent = r.send_action(goal)  # clamped to 0.05 from where the joint is
            self.assertAlmostEqual(sent["joint_1.pos"], obs["joint_1.pos"] + 0.05, places=6)
            for _ in range(40):  # repeated at 50 Hz, each step clamped: the joint gets there
                sent = r.send_action(goal)
                time.sleep(0.02)
            self.assertGreater(r.get_observation()["joint_1.pos"], obs["joint_1.pos"] + 0.2)
        finally:
            r.disconnect()
        self.assertFalse(r.is_connected)


class TeleopTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.leader = ArmfwSim()
        cls.follower = ArmfwSim()

    @classmethod
    def tearDownClass(cls):
        cls.leader.stop()
        cls.follower.stop()

    def test_follower_tracks_the_leader(self):
        with Arm(port=self.leader.port) as lead:
            lead.enable()
            lead.movej([0.3, -0.2, 0.3, 0.2, 0.2, 0.2], speed_pct=20, wait=False)
            p = subprocess.run([sys.executable, os.path.join(EXAMPLES, "teleop.py"), "--leader",
                                f"127.0.0.1:{self.leader.port}", "--follower", f"127.0.0.1:{self.follower.port}",
                                "--rate", "100", "--seconds", "3"], capture_output=True, text=True, timeout=60)
            self.assertEqual(p.returncode, 0, p.stderr)
            self.assertIn("teleop:", p.stdout)
            with Arm(port=self.follower.port, take_control=False) as f:
                qf = f.state()["q"]
            ql = lead.state()["q"]
            self.assertLess(max(abs(x - y) for x, y in zip(qf, ql)), 0.02, p.stdout)
            print(p.stdout.strip())

    def test_from_a_file(self):
        path = f"/tmp/servoarm_teleop_{os.getpid()}.txt"
        with open(path, "w") as f:
            for k in range(100):
                f.write(" ".join(str(v) for v in [0.002 * k, 0, 0, 0, 0, 0]) + "\n")
        p = subprocess.run([sys.executable, os.path.join(EXAMPLES, "teleop.py"), "--from-file", path, "--follower",
                            f"127.0.0.1:{self.follower.port}"], capture_output=True, text=True, timeout=60)
        os.unlink(path)
        self.assertEqual(p.returncode, 0, p.stderr)
        time.sleep(0.3)
        with Arm(port=self.follower.port, take_control=False) as f:
            self.assertAlmostEqual(f.state()["q"][0], 0.198, delta=0.01)


if __name__ == "__main__":
    unittest.main()
