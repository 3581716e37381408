"""Foot-contact labels from toe height and speed.

The toe is the ball-of-foot joint (left_foot / right_foot). A foot is in contact while its
toe is nearly still (3-D speed under 0.3 m/s) and low: within 5 cm of the floor under it,
the lower toe's lowest point within a second either side. The papers label the toe by height
on their own clean floor (LoBSTr: under 1 cm) and their losses hold still feet that touch
it (AvatarJLM's contact mask); CMU's floors are neither level nor at one height through a
take (the lowest toe drifts by 3-4.5 cm across a walk, subject 08's stance toes stand 4-6 cm
over a single floor), so the floor is taken locally and speed decides, with the height only
keeping a foot held still in the air (a balance on one leg) out of contact.

Version 1 (the first labels) took one floor for the whole take (estimate_floor), a 2 cm band
and horizontal speed: it called 9-21 % of walking frames contacts, where a toe stands on the
floor about 40 % of a gait cycle. Skate and contact accuracy figures say which they used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import minimum_filter1d

from .skeleton import JOINT_INDEX

FOOT_JOINTS = (JOINT_INDEX["left_foot"], JOINT_INDEX["right_foot"])
LABEL_VERSION = 2  # bump when contact_labels changes: the metrics' JSON records it


@dataclass(frozen=True)
class ContactThresholds:
    height: float = 0.05  # metres above the floor under the foot
    speed: float = 0.30  # metres per second, 3-D
    floor_window: float = 1.0  # seconds either side that the local floor is the lowest toe of


def estimate_floor(positions: np.ndarray) -> float:
    """Floor height (m) under a (T, 22, 3) motion: a low percentile of the lower toe."""
    toes = positions[:, FOOT_JOINTS, 2].min(axis=1)
    return float(np.percentile(toes, 2))


def local_floor(positions: np.ndarray, fps: float, window: float = 1.0) -> np.ndarray:
    """(T,) the floor under each frame: the lower toe's lowest point within `window` seconds
    either side (a take's floor drifts; a second holds a step or a landing)."""
    lowest = positions[:, FOOT_JOINTS, 2].min(axis=1)
    return minimum_filter1d(lowest, 2 * max(1, round(window * fps)) + 1, mode="nearest")


def toe_speeds(positions: np.ndarray, fps: float, horizontal: bool = True) -> np.ndarray:
    """(T, 2) toe speed in m/s, horizontal or 3-D; the first frame repeats the second."""
    toes = positions[:, FOOT_JOINTS, :2] if horizontal else positions[:, FOOT_JOINTS]
    if len(toes) < 2:
        return np.zeros(toes.shape[:2])
    speed = np.linalg.norm(np.diff(toes, axis=0), axis=-1) * fps
    return np.concatenate([speed[:1], speed], axis=0)


def contact_labels(
    positions: np.ndarray, fps: float, thresholds: ContactThresholds = ContactThresholds()
) -> np.ndarray:
    """(T, 2) booleans, left then right: the toe is nearly still and low over its local floor."""
    floor = local_floor(positions, fps, thresholds.floor_window)
    low = positions[:, FOOT_JOINTS, 2] - floor[:, None] < thresholds.height
    still = toe_speeds(positions, fps, horizontal=False) < thresholds.speed
    return low & still


# The live rule, chosen on the selection clips (kinds of motion no model trained on) against
# contact_labels, over the field-protocol estimates of avatarjlm, dragposer and lobstr
# (docs/methods.md, "Feet held where they touch down"): a toe's estimated height and speed are
# rougher than the mocap's, so the bands are wider than the labels' and a state must hold for
# 50 ms before it is taken. The rule before (5 cm, 0.3 m/s, no hold): 58-71 % right there.
LIVE_HEIGHT, LIVE_SPEED, LIVE_HOLD = 0.08, 0.5, 0.05  # metres, metres per second (3-D), seconds


class ToeContacts:
    """Live contact flags frame after frame: a toe low over the floor and slower than `speed`
    (m/s, 3-D) since the last frame, each foot's state changing only once that has held for
    `hold` (every estimator without a contact model of its own uses one). In plain
    floats, foot by foot: numpy's per-call cost was most of a step's 40 us (LoBSTr's bench)."""

    def __init__(
        self, fps: float, height: float = LIVE_HEIGHT, speed: float = LIVE_SPEED, hold: float = LIVE_HOLD
    ) -> None:
        self.fps, self.height, self.speed = fps, height, speed
        self.hold = max(1, round(hold * fps))  # frames the rule must agree (1: at once)
        self._last: list[tuple[float, float, float]] | None = None
        self._state = [False, False]
        self._against = [0, 0]  # frames in a row the rule has said otherwise
        self.heights, self.speeds = [0.0, 0.0], [0.0, 0.0]  # what the rule saw of each toe last
        self.probability = np.zeros(2)  # how likely each foot is on the floor (contact_probability)

    def __call__(self, toes: np.ndarray, floor: float = 0.0) -> np.ndarray:
        now = [tuple(toe) for toe in np.asarray(toes, float).tolist()]  # (a copy: a caller may reuse its array)
        for foot, (x, y, z) in enumerate(now):
            moved = 0.0 if self._last is None else math.dist((x, y, z), self._last[foot]) * self.fps
            said = z - floor < self.height and moved < self.speed
            self.heights[foot], self.speeds[foot] = z - floor, moved
            if self._last is None:
                self._state[foot] = said
            elif said != self._state[foot]:
                self._against[foot] += 1
                if self._against[foot] >= self.hold:
                    self._state[foot], self._against[foot] = said, 0
            else:
                self._against[foot] = 0
        self._last = now
        for foot in (0, 1):
            self.probability[foot] = contact_probability(self.heights[foot], self.speeds[foot], self._state[foot])
        return np.array(self._state)


# P(on the floor | what the live rule sees of the toe): a logistic model over contact_terms,
# fitted by scripts/contact_probability.py (docs/contact_probability.json)
CONTACT_LOGIT = (1.357, -17.66, -1.581, 0.708)


def contact_terms(height, speed, held):
    """The model's terms for a toe's height [m] over the floor, its speed [m/s] and the rule's
    held state (floats or arrays): a toe far below the floor is no surer on it than one as far
    above (a body hung below the head by three trackers: its toes 30 cm under the floor)."""
    return 1.0, np.minimum(np.abs(height), 0.5), np.clip(speed, 0.0, 5.0), held


def contact_probability(height: float, speed: float, held: bool) -> float:
    """How likely a foot is on the floor, from what the live rule sees of its toe: contact_terms
    in plain floats (numpy's per-call cost made it 4 us a foot, this 0.5)."""
    b0, b_height, b_speed, b_held = CONTACT_LOGIT
    z = b0 + b_height * min(abs(height), 0.5) + b_speed * min(max(speed, 0.0), 5.0) + b_held * held
    return 1.0 / (1.0 + math.exp(-z))
