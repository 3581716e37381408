"""Damped-least-squares IK: the "Final IK" baseline of the papers' tables, no training.

The root comes from the pelvis tracker (four- and six-point) or hangs below the headset
(three-point). Each tracked end joint pulls its chain: head <- spine1..neck, wrist <-
shoulder + elbow hinge, ankle <- hip + knee hinge; then the end joint takes the tracker's
orientation. Untracked legs keep a standing pose. Each frame starts from the last solution.
"""
from __future__ import annotations

import numpy as np

from ..core.contacts import FOOT_JOINTS, toe_contacts
from ..core.kinematics import forward_kinematics
from ..core.rotations import axis_angle_to_matrix, heading, matrix_to_quat, yaw_matrix
from ..core.skeleton import JOINT_INDEX as J
from ..core.types import BodyPose, TrackerFrame
from .base import Estimator
from .reference import standing_pose

X, Y, Z = np.eye(3)


def _about(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation about a unit axis (Rodrigues); scipy's per-call overhead dominates here."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def _hinge_angle(m: np.ndarray, axis: np.ndarray) -> float:
    """The angle of m about a coordinate axis (exact when m is a rotation about it)."""
    i = int(np.argmax(axis))
    j, k = (i + 1) % 3, (i + 2) % 3
    return float(np.arctan2(m[k, j], m[j, j]))
# (end joint, its tracker site, degrees of freedom: (joint, local axis, (min, max) or None))
_BALL = lambda j: [(J[j], X, None), (J[j], Y, None), (J[j], Z, None)]  # noqa: E731
CHAINS = {
    "head": ("head", _BALL("spine1") + _BALL("spine2") + _BALL("spine3") + _BALL("neck"), 3.0),
    "left_hand": ("left_wrist", _BALL("left_shoulder") + [(J["left_elbow"], Z, (-2.7, 0.0))], 1.0),
    "right_hand": ("right_wrist", _BALL("right_shoulder") + [(J["right_elbow"], Z, (0.0, 2.7))], 1.0),
    "left_foot": ("left_ankle", _BALL("left_hip") + [(J["left_knee"], Y, (0.0, 2.6))], 1.0),
    "right_foot": ("right_ankle", _BALL("right_hip") + [(J["right_knee"], Y, (0.0, 2.6))], 1.0),
}


def solve(local: np.ndarray, root: np.ndarray, offsets: np.ndarray, goals, iterations: int = 10,
          damping: float = 0.05, tolerance: float = 1e-4) -> np.ndarray:
    """Damped least squares: local rotations (22, 3, 3) moved so that each goal's end joint
    reaches its target. goals: [(target position, end joint, dofs, damping weight)], dofs as
    in CHAINS. Stops when every goal is within tolerance (m). Returns a new array; hinges stay
    within their limits."""
    local = local.copy()
    for _ in range(iterations):
        glob, pos = forward_kinematics(local, root, offsets)
        moved = False
        for target, end, dofs, weight in goals:
            err = target - pos[end]
            if np.linalg.norm(err) < tolerance:
                continue
            moved = True
            axes = np.stack([glob[j] @ a for j, a, _ in dofs])
            jac = np.cross(axes, pos[end] - np.stack([pos[j] for j, _, _ in dofs])).T   # (3, n)
            lam = damping * weight
            step = jac.T @ np.linalg.solve(jac @ jac.T + lam ** 2 * np.eye(3), err)
            for (j, a, limits), d in zip(dofs, step):
                local[j] = local[j] @ _about(a, d)
                if limits is not None:   # hinges: stay a rotation about their axis, in range
                    local[j] = _about(a, np.clip(_hinge_angle(local[j], a), *limits))
        if not moved:
            break
    return local


class IKEstimator(Estimator):
    name = "ik"

    def __init__(self, sensors, skeleton, fps: float = 60.0, iterations: int = 10, damping: float = 0.05,
                 floor_height: float = 0.0) -> None:
        super().__init__(sensors, skeleton, fps)
        if not {"head", "pelvis"} & set(sensors.site_names):
            raise ValueError("the IK estimator needs a head or a pelvis tracker")
        self.iterations, self.damping, self.floor = iterations, damping, floor_height
        self._head_above_pelvis = skeleton.rest_positions()[J["head"]]
        self.reset()

    def reset(self) -> None:
        self._local = standing_pose()
        self._local[J["left_knee"]] = self._local[J["right_knee"]] = axis_angle_to_matrix(Y * 0.1)
        self._last: BodyPose | None = None
        self._last_toes: np.ndarray | None = None

    def step(self, frame: TrackerFrame) -> BodyPose:
        targets = {s: self.joint_target(frame, s) for s in CHAINS if s in self.sensors.site_names}
        pelvis = self.joint_target(frame, "pelvis")
        head = targets.get("head")
        local = self._local.copy()
        pelvis_pose = pelvis is not None and pelvis[0] is not None and pelvis[1] is not None
        if pelvis_pose:
            local[0], root = pelvis[1], pelvis[0]
        elif head is not None and head[0] is not None and head[1] is not None:
            facing = yaw_matrix(heading(head[1]))
            root = head[0] - facing @ self._head_above_pelvis
            # a pelvis IMU (orientation only) still gives the pelvis its rotation
            local[0] = pelvis[1] if pelvis is not None and pelvis[1] is not None else facing
        else:
            return self.held_pose(frame.stamp)
        # orientation-only trackers (IMUs) only turn their end joint, below
        active = [(site, *CHAINS[site]) for site, tgt in targets.items() if tgt is not None and tgt[0] is not None]
        if not pelvis_pose:   # the root already hangs from the head: leave the spine alone
            active = [a for a in active if a[0] != "head"]
        local = solve(local, root, self.skeleton.offsets,
                      [(targets[site][0], J[end], dofs, weight) for site, end, dofs, weight in active],
                      self.iterations, self.damping)
        glob, _ = forward_kinematics(local, root, self.skeleton.offsets)
        for site, target in targets.items():
            if target is not None and target[1] is not None:   # the end joint takes the tracker's orientation
                end = J[CHAINS[site][0]]
                local[end] = glob[self.skeleton.parents[end]].T @ target[1]
        if not (np.all(np.isfinite(local)) and np.all(np.isfinite(root))):
            self.reset()
            return self.held_pose(frame.stamp)
        self._local = local
        return self._finish(frame.stamp, local, root)

    def _finish(self, stamp, local, root) -> BodyPose:
        _, pos = forward_kinematics(local, root, self.skeleton.offsets)
        toes = pos[list(FOOT_JOINTS)]
        contact = toe_contacts(toes, self._last_toes, self.fps, self.floor)
        self._last_toes = toes
        pose = BodyPose(stamp, matrix_to_quat(local), np.asarray(root, float), contact.astype(float), contact)
        self._last = pose
        return pose
