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

from .types import BodyPose, breaks_take

MAX_AHEAD = 0.2  # s: past this a forecast is a guess (the option's range)
FADE = 0.1  # s: the velocity's time constant (chosen on the held-out kind dance: docs/methods.md)
MAX_TURN = 30.0  # rad/s a joint may turn (a fast punch's wrist: about 20)
MAX_SPEED = 12.0  # m/s the root may move (a sprinter's: about 10)
MAX_GAP = 0.1  # s between two poses over which a velocity is still read


def _quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton products of (N, 4) x y z w quaternions."""
    ax, ay, az, aw = a.T
    bx, by, bz, bw = b.T
    return np.stack(
        (
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ),
        axis=-1,
    )


def _rotation_vectors(q: np.ndarray) -> np.ndarray:
    """(N, 3) rotation vectors of (N, 4) unit quaternions, the shorter way round."""
    q = np.where(q[:, 3:] < 0.0, -q, q)
    sine = np.linalg.norm(q[:, :3], axis=1)
    angle = 2.0 * np.arctan2(sine, np.clip(q[:, 3], 0.0, 1.0))
    scale = np.where(sine > 1e-12, angle / np.maximum(sine, 1e-12), 2.0)
    return q[:, :3] * scale[:, None]


def _quaternions(v: np.ndarray) -> np.ndarray:
    """(N, 4) unit quaternions of (N, 3) rotation vectors."""
    angle = np.linalg.norm(v, axis=1)
    half = 0.5 * angle
    scale = np.where(angle > 1e-12, np.sin(half) / np.maximum(angle, 1e-12), 0.5)
    return np.concatenate((v * scale[:, None], np.cos(half)[:, None]), axis=1)


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
        last, self._last = self._last, (pose if pose.valid else None)
        if self.ahead == 0.0:
            return pose
        if not pose.valid or last is None or breaks_take(last.stamp, pose.stamp, MAX_GAP):
            return pose.restamped(pose.stamp + self.ahead)
        dt = pose.stamp - last.stamp
        turn = _rotation_vectors(_quat_multiply(_inverse(last.local_quats), pose.local_quats)) / dt
        speed = np.linalg.norm(turn, axis=1, keepdims=True)
        turn *= np.minimum(1.0, MAX_TURN / np.maximum(speed, 1e-12))
        velocity = (pose.root_position - last.root_position) / dt
        velocity *= min(1.0, MAX_SPEED / max(float(np.linalg.norm(velocity)), 1e-12))
        quats = _quat_multiply(pose.local_quats, _quaternions(turn * self.carry))
        return BodyPose(
            pose.stamp + self.ahead,
            quats / np.linalg.norm(quats, axis=1, keepdims=True),
            pose.root_position + velocity * self.carry,
            pose.contact_probability.copy(),
            pose.contact.copy(),
            valid=True,
        )


def _inverse(q: np.ndarray) -> np.ndarray:
    return q * np.array([-1.0, -1.0, -1.0, 1.0])
