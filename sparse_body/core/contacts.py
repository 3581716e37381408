"""Foot-contact labels from toe height and speed.

The toe is the ball-of-foot joint (left_foot / right_foot). A clip's floor is the 2nd
percentile of the lower toe's height, so the joint's height above the sole cancels out.
LoBSTr labels contact below 1 cm on its skeleton; on CMU data a 2 cm height band together
with a speed limit keeps swinging feet that brush the floor out of contact.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .skeleton import JOINT_INDEX

FOOT_JOINTS = (JOINT_INDEX["left_foot"], JOINT_INDEX["right_foot"])


@dataclass(frozen=True)
class ContactThresholds:
    height: float = 0.02  # metres above the floor
    speed: float = 0.30  # metres per second, horizontal


def estimate_floor(positions: np.ndarray) -> float:
    """Floor height (m) under a (T, 22, 3) motion: a low percentile of the lower toe."""
    toes = positions[:, FOOT_JOINTS, 2].min(axis=1)
    return float(np.percentile(toes, 2))


def toe_speeds(positions: np.ndarray, fps: float) -> np.ndarray:
    """(T, 2) horizontal toe speed in m/s; the first frame repeats the second."""
    toes = positions[:, FOOT_JOINTS, :2]
    if len(toes) < 2:
        return np.zeros(toes.shape[:2])
    speed = np.linalg.norm(np.diff(toes, axis=0), axis=-1) * fps
    return np.concatenate([speed[:1], speed], axis=0)


def contact_labels(
    positions: np.ndarray, fps: float, floor: float | None = None, thresholds: ContactThresholds = ContactThresholds()
) -> np.ndarray:
    """(T, 2) booleans, left then right: the toe is low and nearly still."""
    floor = estimate_floor(positions) if floor is None else floor
    low = positions[:, FOOT_JOINTS, 2] - floor < thresholds.height
    still = toe_speeds(positions, fps) < thresholds.speed
    return low & still


class ToeContacts:
    """toe_contacts frame after frame: keeps the last frame's toes (every estimator without
    a contact model of its own uses one)."""

    def __init__(self, fps: float) -> None:
        self.fps = fps
        self._last: np.ndarray | None = None

    def __call__(self, toes: np.ndarray, floor: float = 0.0) -> np.ndarray:
        contact = toe_contacts(toes, self._last, self.fps, floor)
        self._last = toes
        return contact


def toe_contacts(
    toes: np.ndarray,
    last_toes: np.ndarray | None,
    fps: float,
    floor: float = 0.0,
    height: float = 0.05,
    speed: float = 0.3,
) -> np.ndarray:
    """Live contact flags (2,) for estimators without a contact model: toe (2, 3) low and
    slower than speed (m/s) since the last frame's toes."""
    moved = np.zeros(2) if last_toes is None else np.linalg.norm((toes - last_toes)[:, :2], axis=1) * fps
    return (toes[:, 2] - floor < height) & (moved < speed)
