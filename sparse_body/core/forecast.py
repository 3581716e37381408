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

The root's move may come from a learned model instead (`root_model`: estimators/
forecast_model.py runs the shipped one, trained by train/forecast.py): given the root's
velocities over the last few frames in the heading frame, it says where the root will be. It
beat both the faded and the constant velocity on the validation people, dance included, where
a learned model of the joints' turns did not (docs/methods.md, "Predicted ahead"). Until it
has that many frames in a row, the root's velocity is carried as the joints' are.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from .types import BodyPose, breaks_take

MAX_AHEAD = 0.2  # s: past this a forecast is a guess (the option's range)
FORECASTS = ("learned", "faded")  # how predict_ahead moves the root (the option forecast)
FADE = 0.1  # s: the velocity's time constant (chosen on the held-out kind dance: docs/methods.md)
MAX_TURN = 30.0  # rad/s a joint may turn (a fast punch's wrist: about 20)
MAX_SPEED = 12.0  # m/s the root may move (a sprinter's: about 10)
MAX_GAP = 0.1  # s between two poses over which a velocity is still read
# s: the time constants the joints' and the root's velocities are averaged over (0: the last two
# poses'). Unaveraged, a forecast 0.1 s ahead had 7.7x the present pose's jitter and 5.1x its
# skate (ik six-point, validation people); these keep them to 1.32x and 1.39x with 61 % of the
# MPJPE gain. The root's is shorter because a jump's rise is the root's: averaged over 0.2 s as
# well, the jumps kept 10 % of their gain (docs/experiments/predicted-ahead.md).
SMOOTH = 0.4
SMOOTH_ROOT = 0.1
# A learned root forecast: (velocities (lags, 3) in m/s, newest first, in the heading frame;
# seconds ahead) -> the root's move (3,) in the heading frame. `lags` says how many it needs.
RootModel = Callable[[np.ndarray, float], np.ndarray]


def _averaged(before: np.ndarray | None, now: np.ndarray, dt: float, smooth: float) -> np.ndarray:
    """now averaged with what came before over about `smooth` s (0: now alone)."""
    if smooth <= 0.0 or before is None:
        return now
    keep = math.exp(-dt / smooth)
    return keep * before + (1.0 - keep) * now


def faded_seconds(ahead: float, fade: float) -> float:
    """How far a velocity that fades with time constant `fade` carries in `ahead` seconds,
    in seconds at its first speed (ahead itself as fade grows without end)."""
    return ahead if fade <= 0.0 or math.isinf(fade) else fade * (1.0 - math.exp(-ahead / fade))


class PoseForecast:
    """forecast(pose) -> the body `ahead` seconds after pose.stamp, stamped then."""

    def __init__(
        self,
        ahead: float,
        fade: float = FADE,
        root_model: RootModel | None = None,
        lags: int = 0,
        smooth: float = SMOOTH,
        smooth_root: float = SMOOTH_ROOT,
    ) -> None:
        if not 0.0 <= ahead <= MAX_AHEAD:
            raise ValueError(f"predict_ahead must be from 0 to {MAX_AHEAD:g} s, got {ahead!r}")
        self.ahead = float(ahead)
        self.carry = faded_seconds(self.ahead, fade)
        self.root_model, self.lags = root_model, lags
        self.smooth = smooth
        self.smooth_root = smooth_root
        self.reset()

    def reset(self) -> None:
        self._last: BodyPose | None = None
        self._roots: deque[tuple[float, np.ndarray]] = deque(maxlen=max(self.lags, 1) + 1)  # (stamp, root) in a row
        self._turn: np.ndarray | None = None  # the joints' velocities, averaged (smooth)
        self._move: np.ndarray | None = None  # the root's move, averaged

    def forecast(self, pose: BodyPose) -> BodyPose:
        if self.ahead == 0.0:
            return pose
        last, self._last = self._last, (pose if pose.valid else None)
        if not pose.valid or last is None or breaks_take(last.stamp, pose.stamp, MAX_GAP):
            self._roots.clear()
            self._turn = self._move = None
            if pose.valid:
                self._roots.append((pose.stamp, pose.root_position.copy()))
            return pose.restamped(pose.stamp + self.ahead)
        self._roots.append((pose.stamp, pose.root_position.copy()))
        dt = pose.stamp - last.stamp
        now = Rotation.from_quat(pose.local_quats)
        turn = (Rotation.from_quat(last.local_quats).inv() * now).as_rotvec() / dt  # the shorter way round
        speed = np.linalg.norm(turn, axis=1, keepdims=True)
        turn *= np.minimum(1.0, MAX_TURN / np.maximum(speed, 1e-12))
        move = self._root_move(now)
        turn = self._turn = _averaged(self._turn, turn, dt, self.smooth)  # noise is not motion
        move = self._move = _averaged(self._move, move, dt, self.smooth_root)
        return BodyPose(
            pose.stamp + self.ahead,
            (now * Rotation.from_rotvec(turn * self.carry)).as_quat(),
            pose.root_position + move,
            pose.contact_probability.copy(),
            pose.contact.copy(),
            valid=True,
        )

    def _root_move(self, now: Rotation) -> np.ndarray:
        """Where the root goes in `ahead` seconds: the learned model's move once it has its
        frames in a row, else the last velocity carried; never faster than a person."""
        stamps = np.array([t for t, _ in self._roots])
        roots = np.array([r for _, r in self._roots])
        velocities = np.diff(roots, axis=0)[::-1] / np.diff(stamps)[::-1, None]  # newest first
        speeds = np.linalg.norm(velocities, axis=1, keepdims=True)
        velocities *= np.minimum(1.0, MAX_SPEED / np.maximum(speeds, 1e-12))
        if self.root_model is None or len(velocities) < self.lags:
            return velocities[0] * self.carry
        heading = now[0].as_matrix()  # the pelvis's turn: its yaw is the heading frame's
        yaw = math.atan2(heading[1, 0], heading[0, 0])
        c, s = math.cos(yaw), math.sin(yaw)
        to_heading = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
        move = to_heading.T @ np.asarray(self.root_model(velocities @ to_heading.T, self.ahead), float)
        length = float(np.linalg.norm(move))
        if not math.isfinite(length):
            return velocities[0] * self.carry
        return move * min(1.0, MAX_SPEED * self.ahead / max(length, 1e-12))
