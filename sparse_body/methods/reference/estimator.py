"""The trivial reference estimator: a standing pose placed under the trackers.

It needs no training and sets the floor every learned estimator must beat: the body stands
with arms down, its pelvis taken from a pelvis tracker when there is one, otherwise hung
below the headset and turned to the headset's heading.
"""

from __future__ import annotations

import numpy as np

from ...core.rotations import matrix_to_quat, yaw_matrix_of
from ...core.skeleton import JOINT_INDEX, standing_pose
from ...core.types import BodyPose, TrackerFrame
from ...estimators.base import Estimator, full_target
from .options import ReferenceOptions

HEAD = JOINT_INDEX["head"]


class ReferenceEstimator(Estimator):
    name = "reference"
    Options = ReferenceOptions

    def __init__(self, sensors, skeleton, fps: float = 60.0, **options) -> None:
        super().__init__(sensors, skeleton, fps, **options)
        if not {"head", "pelvis"} & set(sensors.site_names):
            raise ValueError("the reference estimator needs a head or a pelvis tracker")
        self._local = standing_pose()
        self._head_above_pelvis = skeleton.rest_positions()[HEAD]

    def use_foot_lock(self, on: bool) -> None:
        """Never: the floor to beat is the standing pose as it is (and the bench's yardstick of
        a step's cost stays one)."""
        super().use_foot_lock(False)
        self.reset()

    def _estimate(self, frame: TrackerFrame) -> BodyPose | None:
        pelvis = self.joint_target(frame, "pelvis")
        head = self.joint_target(frame, "head")
        pelvis = pelvis if full_target(pelvis) else None  # needs a full pose
        head = head if full_target(head) else None
        if pelvis is not None:
            root_pos, root_rot = pelvis[0], yaw_matrix_of(pelvis[1])
        elif head is not None:
            root_rot = yaw_matrix_of(head[1])
            root_pos = head[0] - root_rot @ self._head_above_pelvis
        else:
            return None
        local = self._local.copy()
        local[0] = root_rot
        return BodyPose(
            frame.stamp, matrix_to_quat(local), root_pos.astype(float), np.full(2, 0.5), np.ones(2, dtype=bool)
        )
