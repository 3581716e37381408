"""Poses off the feet: a clip's body turned to lie on the floor (on its back, its side or its
front), its limbs moving as in the clip. CMU's 42 minutes hold two dive-rolls and nothing
else off the feet, and another lab's lying on the floor broke the regressors trained on them
(issue 73): this part lets every estimator be measured there, and chosen on it.

The body is turned in its own frame (the root's rotation followed by the turn, so a person who
turns while walking turns on the floor), held where the clip starts (lying, a person does not
travel at walking speed), and raised each frame so that its lowest joint lies FLOOR_CLEARANCE
above the floor (joints sit inside the body: a pelvis on its back is about 10 cm up). The
motion says where that floor is (z = 0), and the evaluation puts a user's floor there, as a
calibrated play space would: estimated from the toes, as a motion capture's floor is, it sat
where the lowest toe of a lying body happened to be (up to 21 cm above the floor
the body lay on, on the floor part's clips).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from .motion import Motion

FLOOR_CLEARANCE = 0.08  # m: the lowest joint's height over the floor, lying
# kind of motion -> the body's turn in its own frame (x forward, y left, z up at rest)
LYING = {
    "lying on the back": Rotation.from_euler("y", -90, degrees=True),  # forward turned up
    "lying on the side": Rotation.from_euler("x", 90, degrees=True),  # left turned up
    "lying on the front": Rotation.from_euler("y", 90, degrees=True),  # forward turned down
}


def lying(motion: Motion, how: str) -> Motion:
    """The motion with its body lying on the floor as LYING[how] says."""
    return laid(motion, LYING[how], f"{motion.name}_{how.split()[-1]}")


def laid(motion: Motion, turn: Rotation, name: str) -> Motion:
    """The motion with its body turned by `turn` in its own frame, held where the clip starts
    and raised each frame so that its lowest joint is FLOOR_CLEARANCE over the floor (z = 0)."""
    from ..core.kinematics import forward_kinematics

    quats = np.array(motion.local_quats, dtype=float)
    quats[:, 0] = (Rotation.from_quat(quats[:, 0]) * turn).as_quat()
    roots = np.zeros_like(motion.root_positions)
    roots[:, :2] = motion.root_positions[0, :2]
    _, positions = forward_kinematics(
        Rotation.from_quat(quats.reshape(-1, 4)).as_matrix().reshape(len(quats), -1, 3, 3),
        roots,
        motion.skeleton.offsets,
    )
    roots[:, 2] = FLOOR_CLEARANCE - positions[..., 2].min(axis=1)
    return Motion(name, motion.fps, motion.skeleton, quats, roots, floor=0.0)
