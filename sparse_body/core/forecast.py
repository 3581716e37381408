"""The body a short time ahead of the trackers (the option and node parameter `predict_ahead`,
issue 54): a teleoperation loop adds tens of milliseconds after us (network, controller,
actuators), and a pose forecast that far ahead lets it cancel its own delay.

The forecast carries each joint's rotation and the root's position on at the velocity of the
last two poses, the velocity fading with a time constant: real motion turns back, and a fading
velocity overshoots less at a reversal than a constant one (the constant is chosen on
validation people and the held-out kinds of motion: docs/methods.md, "Predicted ahead").
Velocities are held to a person's (MAX_TURN, MAX_SPEED), so a jump in the input cannot
throw the forecast away; a gap, an invalid pose or a reset forecasts nothing (the present
pose, restamped) until two valid poses in a row have come again. ROS-free, per step.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from .types import BodyPose, breaks_take

MAX_AHEAD = 0.2  # s: past this a forecast is a guess (the option's range)
FADE = 0.1  # s: the velocity's time constant (chosen on the held-out kind dance: docs/methods.md)
MAX_TURN = 30.0  # rad/s a joint may turn (a fast punch's wrist: about 20)
MAX_SPEED = 12.0  # m/s the root may move (a sprinter's: about 10)
MAX_GAP = 0.1  # s between two poses over which a velocity is still read


def faded_seconds(ahead: float, fade: float) -> float:
    """How far a velocity that fades with time constant `fade` carries in `ahead` seconds,
    in seconds at its first speed (ahead itself as fade grows without end)."""
    return ahead if fade <= 0.0 or math.isinf(fade) else fade * (1.0 - math.exp(-ahead / fade))


class PoseForecast:
    """forecast(pose) -> the body `ahead` seconds after pose.stamp, stamped then."""

    def __init__(self, ahead: float, fade: float = FADE) -> None:
        if not 0.0 <= ahead <= MAX_AHEAD:
            raise ValueError(f"predict_ahead must be from 0 to {MAX_AHEAD:g} s, got {ahead!r}")
        self.ahead = float(ahead)
        self.carry = faded_seconds(self.ahead, fade)
        self.reset()

    def reset(self) -> None:
        self._last: BodyPose | None = None

    def forecast(self, pose: BodyPose) -> BodyPose:
        if self.ahead == 0.0:
            return pose
        last, self._last = self._last, (pose if pose.valid else None)
        if not pose.valid or last is None or breaks_take(last.stamp, pose.stamp, MAX_GAP):
            return pose.restamped(pose.stamp + self.ahead)
        dt = pose.stamp - last.stamp
        now = Rotation.from_quat(pose.local_quats)
        turn = (Rotation.from_quat(last.local_quats).inv() * now).as_rotvec() / dt  # the shorter way round
        speed = np.linalg.norm(turn, axis=1, keepdims=True)
        turn *= np.minimum(1.0, MAX_TURN / np.maximum(speed, 1e-12))
        velocity = (pose.root_position - last.root_position) / dt
        velocity *= min(1.0, MAX_SPEED / max(float(np.linalg.norm(velocity)), 1e-12))
        return BodyPose(
            pose.stamp + self.ahead,
            (now * Rotation.from_rotvec(turn * self.carry)).as_quat(),
            pose.root_position + velocity * self.carry,
            pose.contact_probability.copy(),
            pose.contact.copy(),
            valid=True,
        )
