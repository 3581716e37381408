"""IK from the trackers alone: the "Final IK" baseline of the papers' tables, no training.

The root comes from the pelvis tracker (four- and six-point) or hangs below the headset
(three-point). With a tracked pelvis the spine bends and turns to put the head on the
headset; each tracked hand or foot is reached by its two-bone limb (core/body_ik.py,
closed form, the swivel carried from the previous frame); then the end joint takes the
tracker's orientation. Untracked legs keep a standing pose. Orientation-only trackers
(IMUs) only turn their end joint.
"""

from __future__ import annotations

import math

import numpy as np

from ...core.body_ik import KEEP_BEND_TOLERANCE, solve_body
from ...core.contacts import FOOT_JOINTS, ToeContacts
from ...core.rotations import axis_angle_to_matrix, rotations_to_quat, yaw_matrix_of
from ...core.sensors import SITE_JOINTS
from ...core.skeleton import JOINT_INDEX as J
from ...core.skeleton import PARENTS, standing_pose
from ...core.types import BodyPose, TrackerFrame
from ...estimators.base import Estimator
from .options import IkOptions

END_SITES = ("head", "left_hand", "right_hand", "left_foot", "right_foot")
_ANKLES = (J["left_ankle"], J["right_ankle"])


class IKEstimator(Estimator):
    name = "ik"
    Options = IkOptions
    options: IkOptions

    def __init__(self, sensors, skeleton, fps: float = 60.0, **options) -> None:
        super().__init__(sensors, skeleton, fps, **options)
        if not {"head", "pelvis"} & set(sensors.site_names):
            raise ValueError("the IK estimator needs a head or a pelvis tracker")
        self.floor = self.options.floor_height
        self._sites = [s for s in END_SITES if s in sensors.site_names]
        self._head_above_pelvis = skeleton.rest_positions()[J["head"]]
        self.reset()

    def _reset(self) -> None:
        self._local = standing_pose()
        self._local[J["left_knee"]] = self._local[J["right_knee"]] = axis_angle_to_matrix(np.array([0.0, 0.1, 0.0]))
        self._toes = ToeContacts(self.fps)  # contacts from the toes frame to frame

    def _estimate(self, frame: TrackerFrame) -> BodyPose | None:
        solved = self.solve(frame)
        if solved is None:
            return None
        local, root, glob, pos = solved
        # the toes under the ankles' final rotations (what contacts are judged on)
        toes = np.stack(
            [pos[a] + glob[a] @ self.skeleton.offsets[f] for a, f in zip(_ANKLES, FOOT_JOINTS, strict=True)]
        )
        contact = self._toes(toes, self.floor)
        return BodyPose(
            frame.stamp, rotations_to_quat(local), np.asarray(root, float), self._toes.probability.copy(), contact
        )

    def solve(self, frame: TrackerFrame, start: np.ndarray | None = None, spine_tolerance: float = KEEP_BEND_TOLERANCE):
        """(local rotations, root, global rotations, positions) from this frame's trackers, or
        None without a usable head or pelvis; the pose is kept as the next frame's start.
        Global rotations and positions hold for every joint but the feet.
        start: a pose (22, 3, 3) to begin from instead of the previous frame's, e.g. a
        network's; its spine curve, elbows and knees are kept and only turned (the curve
        while it leaves the head within spine_tolerance metres: body_ik.fit_spine), and the
        result is not kept (the IK's own pose stays its next start)."""
        targets = {s: self.joint_target(frame, s) for s in self._sites}
        pelvis = self.joint_target(frame, "pelvis")
        head = targets.get("head")
        local = (self._local if start is None else start).copy()
        pelvis_pose = pelvis is not None and pelvis[0] is not None and pelvis[1] is not None
        if pelvis_pose:
            local[0], root = pelvis[1], pelvis[0]
        elif head is not None and head[0] is not None and head[1] is not None:
            facing = yaw_matrix_of(head[1])
            root = head[0] - facing @ self._head_above_pelvis
            # a pelvis IMU (orientation only) still gives the pelvis its rotation
            local[0] = pelvis[1] if pelvis is not None and pelvis[1] is not None else facing
        else:
            return None
        goals = {J[SITE_JOINTS[site]]: t[0] for site, t in targets.items() if t is not None and t[0] is not None}
        if not pelvis_pose:  # the root already hangs from the head: leave the spine alone
            goals.pop(J["head"], None)
        local, glob, pos = solve_body(
            local, root, self.skeleton.offsets, goals, keep_shape=start is not None, spine_tolerance=spine_tolerance
        )
        for site, target in targets.items():
            if target is not None and target[1] is not None:  # the end joint takes the tracker's orientation
                end = J[SITE_JOINTS[site]]
                local[end] = glob[PARENTS[end]].T @ target[1]
                glob[end] = target[1]
        if not math.isfinite(local.sum() + np.sum(root)):  # a sum is finite only when every element is
            self._reset()
            return None
        if start is None:
            self._local = local
        return local, root, glob, pos
