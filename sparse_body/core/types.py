"""What flows between tracker sources, estimators and outputs (no ROS types here)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .skeleton import NUM_JOINTS


def breaks_take(earlier: float, later: float, max_gap: float) -> bool:
    """Whether a step at `later` cannot follow one at `earlier` in the same take: time stood
    still or went back, or more than max_gap seconds passed (a method with history starts
    over; what counts as too long is each method's max_gap option)."""
    return not 0.0 < later - earlier <= max_gap


@dataclass
class TrackerFrame:
    """The trackers' latest poses at one instant, in the fixed frame (REP-103, metres).

    valid[s] is False when site s has no usable sample (dropped, stale, non-finite); an
    orientation-only tracker has NaN position, a position-only tracker NaN orientation.
    """

    stamp: float  # seconds
    sites: tuple[str, ...]
    positions: np.ndarray  # (S, 3)
    orientations: np.ndarray  # (S, 4) x y z w
    valid: np.ndarray  # (S,) bool

    def index(self, site: str) -> int:
        return self.sites.index(site)


@dataclass
class TrackerStream:
    """A recorded sequence of tracker frames (virtual trackers, a bag)."""

    sites: tuple[str, ...]
    times: np.ndarray  # (T,) seconds
    positions: np.ndarray  # (T, S, 3)
    orientations: np.ndarray  # (T, S, 4)
    valid: np.ndarray  # (T, S)
    lost: np.ndarray | None = None  # (T, S) frames a simulated tracker was out of view (known only to a simulation)

    def __len__(self) -> int:
        return len(self.times)

    def frame(self, i: int) -> TrackerFrame:
        return TrackerFrame(float(self.times[i]), self.sites, self.positions[i], self.orientations[i], self.valid[i])

    def __iter__(self):
        return (self.frame(i) for i in range(len(self)))


@dataclass
class BodyPose:
    """One estimate of the 22-joint body."""

    stamp: float
    local_quats: np.ndarray  # (22, 4) x y z w; the root's is global
    root_position: np.ndarray  # (3,)
    contact_probability: np.ndarray = field(default_factory=lambda: np.full(2, np.nan))  # left, right
    contact: np.ndarray = field(default_factory=lambda: np.zeros(2, dtype=bool))
    valid: bool = True  # False: the estimator had too little input; values hold the last pose

    def __post_init__(self) -> None:
        if self.local_quats.shape != (NUM_JOINTS, 4) or self.root_position.shape != (3,):
            raise ValueError("a body pose needs (22, 4) quaternions and a (3,) root position")

    def held(self, stamp: float) -> BodyPose:
        """This pose again at a later stamp, marked invalid: what an estimator or node
        outputs when it has too little input."""
        return self.restamped(stamp, valid=False)

    def restamped(self, stamp: float, valid: bool | None = None) -> BodyPose:
        """A copy of this pose at another stamp (valid as this one unless given)."""
        return BodyPose(
            stamp,
            self.local_quats.copy(),
            self.root_position.copy(),
            self.contact_probability.copy(),
            self.contact.copy(),
            self.valid if valid is None else valid,
        )

    def is_finite(self) -> bool:
        # a sum is finite only when every element is (numpy's isfinite and all cost more, every step)
        return math.isfinite(self.local_quats.sum() + self.root_position.sum())


@dataclass
class BodyPoses:
    """Estimates as arrays, one row a pose (a recording or a chunk of it): what the message
    encoder takes, and what crosses between processes cheaply (arrays, not objects)."""

    stamps: np.ndarray  # (T,) seconds
    local_quats: np.ndarray  # (T, 22, 4)
    roots: np.ndarray  # (T, 3)
    contact_probability: np.ndarray  # (T, 2)
    contact: np.ndarray  # (T, 2) bool
    valid: np.ndarray  # (T,) bool

    @classmethod
    def of(cls, poses: list[BodyPose]) -> BodyPoses:
        count = len(poses)
        return cls(
            np.array([p.stamp for p in poses], np.float64),
            np.array([p.local_quats for p in poses], np.float64).reshape(count, NUM_JOINTS, 4),
            np.array([p.root_position for p in poses], np.float64).reshape(count, 3),
            np.array([p.contact_probability for p in poses], np.float64).reshape(count, 2),
            np.array([p.contact for p in poses], bool).reshape(count, 2),
            np.array([p.valid for p in poses], bool),
        )

    def __len__(self) -> int:
        return len(self.stamps)
