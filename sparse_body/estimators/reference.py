"""The trivial reference estimator: a standing pose placed under the trackers.

It needs no training and sets the floor every learned estimator must beat: the body stands
with arms down, its pelvis taken from a pelvis tracker when there is one, otherwise hung
below the headset and turned to the headset's heading.
"""

from __future__ import annotations

import numpy as np

from ..core.rotations import euler_to_matrix, heading, matrix_to_quat, yaw_matrix
from ..core.skeleton import JOINT_INDEX, NUM_JOINTS
from ..core.types import BodyPose, TrackerFrame
from .base import Estimator

HEAD = JOINT_INDEX["head"]


def standing_pose() -> np.ndarray:
    """(22, 3, 3) local rotations: the rest pose with the arms lowered to the sides."""
    local = np.tile(np.eye(3), (NUM_JOINTS, 1, 1))
    # Rest arms point along +-y; a roll of -+80 degrees about x brings them down.
    local[JOINT_INDEX["left_shoulder"]] = euler_to_matrix(np.array([np.deg2rad(-80.0), 0, 0]), "xyz")
    local[JOINT_INDEX["right_shoulder"]] = euler_to_matrix(np.array([np.deg2rad(80.0), 0, 0]), "xyz")
    return local


class ReferenceEstimator(Estimator):
    name = "reference"

    def __init__(self, sensors, skeleton, fps: float = 60.0) -> None:
        super().__init__(sensors, skeleton, fps)
        if not {"head", "pelvis"} & set(sensors.site_names):
            raise ValueError("the reference estimator needs a head or a pelvis tracker")
        self._local = standing_pose()
        self._head_above_pelvis = skeleton.rest_positions()[HEAD]
        self.reset()

    def _estimate(self, frame: TrackerFrame) -> BodyPose | None:
        pelvis = self.joint_target(frame, "pelvis")
        head = self.joint_target(frame, "head")
        full = lambda t: t is not None and t[0] is not None and t[1] is not None  # noqa: E731
        pelvis = pelvis if full(pelvis) else None  # needs a full pose
        head = head if full(head) else None
        if pelvis is not None:
            root_pos, root_rot = pelvis[0], yaw_matrix(heading(pelvis[1]))
        elif head is not None:
            root_rot = yaw_matrix(heading(head[1]))
            root_pos = head[0] - root_rot @ self._head_above_pelvis
        else:
            return None
        local = self._local.copy()
        local[0] = root_rot
        return BodyPose(
            frame.stamp, matrix_to_quat(local), root_pos.astype(float), np.full(2, 0.5), np.ones(2, dtype=bool)
        )
