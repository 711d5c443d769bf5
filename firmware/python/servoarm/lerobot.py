# SPDX-License-Identifier: Apache-2.0
"""servoarm as a LeRobot robot, duck-typed: the methods and properties of LeRobot's `Robot`
interface (connect, disconnect, is_connected, calibrate, is_calibrated, configure,
observation_features, action_features, get_observation, send_action with
max_relative_target) without importing lerobot. docs/python.md shows how to register it as a
`lerobot_robot_*` plugin.

Actions are joint targets, `"<joint>.pos"` in rad (m for a prismatic joint), sent as streaming
targets: the firmware tracks them jerk-limited and brakes the arm to rest when they stop coming
(api.stream_deadman_ms).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, Optional

from .client import Arm, ArmError


@dataclass
class ServoarmRobotConfig:
    host: str = "127.0.0.1"
    port: int = 8766
    token: Optional[str] = None
    id: str = "servoarm"
    #: The largest change of a joint per action (rad / m), as LeRobot's max_relative_target:
    #: one number for every joint, a dict by feature name, or None (no limit here; the firmware's
    #: own api.stream_max_step_deg still applies).
    max_relative_target: Optional[Any] = None


class ServoarmRobot:
    name = "servoarm"

    def __init__(self, config: ServoarmRobotConfig):
        self.config = config
        self.id = config.id
        self._arm: Optional[Arm] = None
        self._stream = None
        self._names: list = []

    # -- LeRobot's Robot interface ------------------------------------------------------------
    @property
    def observation_features(self) -> Dict[str, type]:
        return {n: float for n in self._feature_names()}

    @property
    def action_features(self) -> Dict[str, type]:
        return {n: float for n in self._feature_names()}

    @property
    def is_connected(self) -> bool:
        return self._arm is not None

    def connect(self, calibrate: bool = True) -> None:
        if self._arm is not None:
            raise RuntimeError(f"{self} already connected")
        self._arm = Arm(self.config.host, token=self.config.token, port=self.config.port)
        self._names = [f"joint_{i + 1}.pos" for i in range(self._arm.joints)]
        if calibrate and not self.is_calibrated:
            self.calibrate()
        self.configure()

    @property
    def is_calibrated(self) -> bool:
        """Every joint homed (its zero established this power cycle, or absolute)."""
        s = self._require().state()
        return s["homed"] == (1 << self._arm.joints) - 1

    def calibrate(self) -> None:
        """The homing cycle (the firmware's drive.homing.* settings)."""
        arm = self._require()
        if arm.state()["state"] == "disabled":
            arm.enable()
        arm.home()

    def configure(self) -> None:
        """Powers the arm (enable) so that actions move it."""
        arm = self._require()
        if arm.state()["state"] == "disabled":
            arm.enable()

    def get_observation(self) -> Dict[str, Any]:
        s = self._require().state()
        return {n: float(s["q"][i]) for i, n in enumerate(self._names)}

    def send_action(self, action: Dict[str, Any]) -> Dict[str, Any]:
        """Move towards `action` (`"joint_i.pos"` values; joints left out keep their target);
        returns the action actually sent (after max_relative_target)."""
        arm = self._require()
        s = arm.state()
        present = [float(v) for v in s["q"]]
        goal = list(s["q_cmd"])
        for i, n in enumerate(self._names):
            if n in action:
                goal[i] = float(action[n])
        mrt = self.config.max_relative_target
        if mrt is not None:
            for i, n in enumerate(self._names):
                m = float(mrt[n]) if isinstance(mrt, dict) else float(mrt)
                goal[i] = min(max(goal[i], present[i] - m), present[i] + m)
        if self._stream is None:
            self._stream = arm.stream()
        try:
            self._stream.send(goal)
        except ArmError as e:
            if e.code != "bad_state":
                raise
            self._stream = arm.stream()  # the stream had ended (deadman, stop): a new one
            self._stream.send(goal)
        return {n: goal[i] for i, n in enumerate(self._names)}

    def disconnect(self) -> None:
        arm = self._require()
        try:
            arm.call("disable")
        except ArmError:
            pass
        arm.close()
        self._arm = None
        self._stream = None

    # -- helpers ------------------------------------------------------------------------------
    def _require(self) -> Arm:
        if self._arm is None:
            raise RuntimeError(f"{self} is not connected")
        return self._arm

    def _feature_names(self):
        if not self._names:
            raise RuntimeError("the joints are known once connected (connect() first)")
        return self._names

    def __str__(self) -> str:
        return f"ServoarmRobot({self.id})"
