"""An estimator that only ever sees an upright body: `upright` (base blend by default).

The learned models were trained on CMU's 42 minutes, upright but for two dive-rolls. Where the
body leaves upright poses they are out of their depth, and nothing told them so: another lab's
lying on the floor gave LoBSTr 1.57x IK's leg error (issue 73), and on the floor part here
(`eval --split floor`) DragPoser put the legs of a body lying on its front 126 degrees off
(median): its decoder cannot turn a root past what it saw standing, and every regressor reads
its input in a frame that only takes out the heading.

The torso's tilt says when: the angle between the world's up and the line from the pelvis
target to the head's (the head's own up where there is no pelvis tracker). Up to
`upright_within` the base has the body as it is. From there to `lying_from` a growing share of
the tilt is taken out: every joint target is turned about the pelvis (the head without one) so
that the torso stands, and lifted to where a standing body carries it; the base estimates that
upright body and its pose is turned and put back. A body lying on the floor is, to the base, a
person standing (a person lying keeps the joints' angles of one standing; only gravity's
direction differs). The share follows its target with time constant `settle`, so the turn never
jumps, and it is the frame's out-of-depth score (`share` after each step).

With a `fallback` named (`upright:base=lobstr,fallback=ik`) the lying body is handed to that
estimator instead (both step every frame; their poses slerped by the share): the first form of
this estimator, kept to compare with.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ...core.contacts import FOOT_JOINTS, ToeContacts
from ...core.kinematics import forward_kinematics
from ...core.rotations import matrix_to_quat, quat_to_matrix, slerp
from ...core.skeleton import JOINT_INDEX as J
from ...core.types import BodyPose
from ...estimators.base import _POSE, _POSITION, _ROTATION, Estimator
from ..factory import inner_estimators
from .options import UprightOptions

UP = np.array([0.0, 0.0, 1.0])
POSITIONED, TURNED = (_POSE, _POSITION), (_POSE, _ROTATION)  # what a joint target gives


def _smoothstep(x: float) -> float:
    x = min(1.0, max(0.0, x))
    return x * x * (3.0 - 2.0 * x)


class UprightEstimator(Estimator):
    name = "upright"
    Options = UprightOptions
    options: UprightOptions

    def __init__(self, sensors, skeleton, fps: float = 60.0, **options) -> None:
        super().__init__(sensors, skeleton, fps, **options)
        o = self.options
        self.keep = float(np.exp(-1.0 / (o.settle * fps))) if o.settle > 0 else 0.0  # of the share, a frame
        # the base reads the turned targets (_frame_targets below); a fallback the same ones untouched
        self.parts = inner_estimators(self, (o.base, o.fallback) if o.fallback else (o.base,))
        self._sites: tuple[str, ...] = ()  # the frames' site order, and where head and pelvis are in it
        self._head: int | None = None
        self._pelvis: int | None = None
        rest = skeleton.rest_positions()
        feet = rest[list(FOOT_JOINTS), 2].min()
        # where a standing body carries its pelvis and head over the floor (z = 0)
        self._standing = {"pelvis": rest[J["pelvis"], 2] - feet, "head": rest[J["head"], 2] - feet}
        self.share = 0.0
        self.tilted = 0.0  # the last frame's torso tilt, degrees
        self._turn: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # (R, pivot, lifted pivot)
        self._toes = ToeContacts(fps)

    def _reset(self) -> None:
        for inner in self.parts:
            inner.reset()
        self.share = 0.0
        self.tilted = 0.0  # the last frame's torso tilt, degrees
        self._turn = None
        self._toes = ToeContacts(self.fps)

    def out_of_depth(self) -> tuple[float, str] | None:
        if self.share < 0.01:
            return 0.0, ""
        if self.options.fallback:
            return self.share, f"the torso {self.tilted:.0f} degrees from upright; handed to {self.options.fallback}"
        return self.share, f"the torso {self.tilted:.0f} degrees from upright; {self.options.base} shown it stood up"

    def _torso(self, positions, rotations, kinds):
        """(the torso's unit direction, the pivot's site index) from the joint targets, or None."""
        head, pelvis = self._head, self._pelvis
        if head is None or not kinds[head]:
            return None
        if pelvis is not None and kinds[pelvis] in POSITIONED and kinds[head] in POSITIONED:
            torso, pivot = positions[head] - positions[pelvis], pelvis
        elif kinds[head] in TURNED:
            torso, pivot = rotations[head] @ UP, head
        else:
            return None
        length = float(np.linalg.norm(torso))
        return (torso / length, pivot) if length > 1e-6 else None

    def _lying(self, positions, direction, pivot) -> float:
        """How far (0 to 1) this frame's body lies: its torso tilted past upright_within and its
        pivot (pelvis, else head) low. A tilted torso alone is no lying body: a person bending
        over to pick something up, or in a cartwheel, tilts it as far with the pelvis high."""
        o = self.options
        tilt = self.tilted = float(np.degrees(np.arccos(np.clip(direction[2], -1.0, 1.0))))
        tilted = _smoothstep((tilt - o.upright_within) / (o.lying_from - o.upright_within))
        site = "pelvis" if pivot == self._pelvis else "head"
        height = positions[pivot][2] / self._standing[site]
        return tilted * _smoothstep((o.high_from - height) / (o.high_from - o.low_below))

    def _frame_targets(self, frame):
        """The joint targets every part reads, once a frame: the share follows the torso's
        tilt, and (without a fallback) the targets are turned so that the torso stands by
        that share of its tilt."""
        targets = super()._frame_targets(frame)
        o = self.options
        if frame.sites != self._sites:
            known = set(self.sensors.site_names)
            self._sites = frame.sites
            self._head, self._pelvis = (
                frame.index(s) if s in frame.sites and s in known else None for s in ("head", "pelvis")
            )
        torso = self._torso(*targets)
        if torso is not None:
            self.share = self.keep * self.share + (1.0 - self.keep) * self._lying(targets[0], *torso)
        self._turn = None
        if o.fallback or torso is None or self.share < 1e-6:
            return targets
        positions, rotations, kinds = targets
        (direction, i), pivot = torso, positions[torso[1]].copy()
        axis = np.cross(direction, UP)
        sine = float(np.linalg.norm(axis))
        if sine < 1e-9:
            return targets
        turn = Rotation.from_rotvec(axis / sine * self.share * float(np.arctan2(sine, direction[2]))).as_matrix()
        standing = self._standing["pelvis" if i == self._pelvis else "head"]
        lifted = pivot + UP * self.share * (standing - pivot[2])
        self._turn = (turn, pivot, lifted)
        return (positions - pivot) @ turn.T + lifted, turn @ rotations, kinds

    def _estimate(self, frame):
        self._converted(frame)  # this frame's share and turn, before any part steps
        poses = [inner.step(frame) for inner in self.parts]
        if not all(p.valid for p in poses):
            return None
        if len(poses) == 2:
            return self._handed_over(frame, *poses)
        pose = poses[0]
        if self._turn is None:
            return pose
        turn, pivot, lifted = self._turn
        quats = pose.local_quats.copy()
        quats[0] = matrix_to_quat(turn.T @ quat_to_matrix(pose.local_quats[0]))
        root = turn.T @ (pose.root_position - lifted) + pivot
        if self.share < 0.5:  # its feet on its floor still
            return BodyPose(frame.stamp, quats, root, pose.contact_probability.copy(), pose.contact.copy())
        _, joints = forward_kinematics(quat_to_matrix(quats), root, self.skeleton.offsets)
        contact = self._toes(joints[list(FOOT_JOINTS)])  # the base's floor is not the room's
        return BodyPose(frame.stamp, quats, root, self._toes.probability.copy(), contact)

    def _handed_over(self, frame, base: BodyPose, fallback: BodyPose) -> BodyPose:
        t = self.share
        contacts = base if t < 0.5 else fallback
        return BodyPose(
            frame.stamp,
            slerp(base.local_quats, fallback.local_quats, t),
            (1.0 - t) * base.root_position + t * fallback.root_position,
            contacts.contact_probability.copy(),
            contacts.contact.copy(),
        )
