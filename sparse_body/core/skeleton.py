"""The 22-joint body: SMPL topology and joint names, rest offsets, height scaling.

Convention (REP-103): x forward, y left, z up, metres. All-identity local rotations give the
rest pose: a T-pose facing +x with legs straight down and arms along +y (left) / -y (right).
Offsets are per person (a retargeted clip carries its subject's); the canonical body below
is the mean of the 22 CMU ASF subjects (mocap.cs.cmu.edu), made left-right symmetric and
scaled from their mean stature (1.55 m) to CANONICAL_HEIGHT.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .rotations import euler_to_matrix

JOINT_NAMES: tuple[str, ...] = (
    "pelvis",
    "left_hip",
    "right_hip",
    "spine1",
    "left_knee",
    "right_knee",
    "spine2",
    "left_ankle",
    "right_ankle",
    "spine3",
    "left_foot",
    "right_foot",
    "neck",
    "left_collar",
    "right_collar",
    "head",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
)
PARENTS: tuple[int, ...] = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19)
NUM_JOINTS = len(JOINT_NAMES)
JOINT_INDEX = {name: i for i, name in enumerate(JOINT_NAMES)}

LOWER_BODY = (
    "left_hip",
    "right_hip",
    "left_knee",
    "right_knee",
    "left_ankle",
    "right_ankle",
    "left_foot",
    "right_foot",
)
UPPER_BODY = tuple(n for n in JOINT_NAMES if n not in LOWER_BODY and n != "pelvis")
FEET = ("left_foot", "right_foot")
HANDS = ("left_wrist", "right_wrist")

# Standing height of the canonical body, and stature / (head joint height above the lowest
# joint), which turns a person's height into a scale. The ratio is the mean over the 22 CMU
# ASF subjects (top of the head bone to the lowest bone end), 1.086 to 1.119.
CANONICAL_HEIGHT = 1.75
STATURE_RATIO = 1.10

# Rest offsets (metres) of each joint from its parent, in the parent's rest frame.
_CANONICAL_OFFSETS = np.array(
    [
        [0.000, 0.000, 0.000],  # pelvis (root; its position comes from the motion)
        [0.047, 0.102, -0.112],  # left_hip (in front of the pelvis joint, as in every CMU subject)
        [0.047, -0.102, -0.112],  # right_hip
        [0.000, 0.000, 0.000],  # spine1 (at the pelvis: CMU's lower back starts at the root)
        [0.000, 0.000, -0.450],  # left_knee
        [0.000, 0.000, -0.450],  # right_knee
        [0.000, 0.000, 0.132],  # spine2
        [0.000, 0.000, -0.487],  # left_ankle
        [0.000, 0.000, -0.487],  # right_ankle
        [0.000, 0.000, 0.132],  # spine3
        [0.132, 0.000, -0.033],  # left_foot (ball of the foot)
        [0.132, 0.000, -0.033],  # right_foot
        [0.004, 0.000, 0.133],  # neck (base of the neck)
        [0.004, 0.000, 0.133],  # left_collar (where the clavicle starts)
        [0.004, 0.000, 0.133],  # right_collar
        [0.000, 0.000, 0.110],  # head (middle of the neck; rotation of the skull)
        [0.000, 0.220, 0.000],  # left_shoulder
        [0.000, -0.220, 0.000],  # right_shoulder
        [0.000, 0.333, 0.000],  # left_elbow
        [0.000, -0.333, 0.000],  # right_elbow
        [0.000, 0.210, 0.000],  # left_wrist
        [0.000, -0.210, 0.000],  # right_wrist
    ]
)


@dataclass(frozen=True)
class Skeleton:
    """Rest offsets of the 22-joint body; names and parents are fixed."""

    offsets: np.ndarray  # (22, 3)

    def __post_init__(self) -> None:
        offsets = np.asarray(self.offsets, dtype=np.float64)
        if offsets.shape != (NUM_JOINTS, 3) or not np.all(np.isfinite(offsets)):
            raise ValueError(f"skeleton offsets must be a finite ({NUM_JOINTS}, 3) array, got {offsets.shape}")
        object.__setattr__(self, "offsets", offsets)

    names = JOINT_NAMES
    parents = PARENTS

    @classmethod
    def canonical(cls, height: float | None = None) -> Skeleton:
        skeleton = cls(_CANONICAL_OFFSETS.copy())
        return skeleton if height is None else skeleton.with_height(height)

    def rest_positions(self) -> np.ndarray:
        """Joint positions of the rest pose with the pelvis at the origin."""
        pos = np.zeros((NUM_JOINTS, 3))
        for j in range(1, NUM_JOINTS):
            pos[j] = pos[PARENTS[j]] + self.offsets[j]
        return pos

    def height(self) -> float:
        """Estimated standing height (metres) of a person with these proportions."""
        rest = self.rest_positions()
        return float((rest[JOINT_INDEX["head"], 2] - rest[:, 2].min()) * STATURE_RATIO)

    def scaled(self, factor: float) -> Skeleton:
        if not np.isfinite(factor) or factor <= 0:
            raise ValueError(f"scale factor must be positive and finite, got {factor}")
        return Skeleton(self.offsets * factor)

    def with_height(self, height: float) -> Skeleton:
        if not np.isfinite(height) or not 0.5 <= height <= 2.5:
            raise ValueError(f"height must be between 0.5 m and 2.5 m, got {height}")
        return self.scaled(height / self.height())

    def leg_length(self) -> float:
        """Hip to ball-of-foot distance at rest: the bound DTP uses for occlusion noise."""
        rest = self.rest_positions()
        return float(np.linalg.norm(rest[JOINT_INDEX["left_hip"]] - rest[JOINT_INDEX["left_foot"]]))


def joint_indices(names) -> list[int]:
    """Indices of joint names, with an error that lists the valid names."""
    try:
        return [JOINT_INDEX[n] for n in names]
    except KeyError as err:
        raise ValueError(f"unknown joint {err.args[0]!r}; joints are {', '.join(JOINT_NAMES)}") from None


def standing_pose() -> np.ndarray:
    """(22, 3, 3) local rotations: the rest pose with the arms lowered to the sides."""
    local = np.tile(np.eye(3), (NUM_JOINTS, 1, 1))
    # Rest arms point along +-y; a roll of -+80 degrees about x brings them down.
    local[JOINT_INDEX["left_shoulder"]] = euler_to_matrix(np.array([np.deg2rad(-80.0), 0, 0]), "xyz")
    local[JOINT_INDEX["right_shoulder"]] = euler_to_matrix(np.array([np.deg2rad(80.0), 0, 0]), "xyz")
    return local


def body_scale(skeleton: Skeleton) -> float:
    """Factor that maps this person's positions onto the canonical body (the learned methods
    see every person at the canonical size)."""
    return Skeleton.canonical().leg_length() / skeleton.leg_length()
