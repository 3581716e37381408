"""Foot contacts held by IK (LoBSTr, section 3.4.1): LoBSTr's own (contact_ik), and every
estimator's with the option foot_lock (estimators/base.py), from its own contacts.

When a foot's contact turns on, its toe's position becomes the contact point, and hip and
knee are solved (the shared two-bone IK, with the toe as the limb's end) so that the toe
stays there while contact lasts. When contact ends, the target moves from the contact point to
where the network puts the toe over release_frames frames with a slow-in / slow-out (shifted
sine) weight, so the foot does not snap. A contact point the leg can no longer reach is let go the same way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .body_ik import LIMBS, reach
from .contacts import FOOT_JOINTS
from .kinematics import LEG_JOINTS, forward_kinematics
from .skeleton import JOINT_INDEX as J
from .skeleton import Skeleton

# The toe is moved by the hip (ball) and knee (hinge) of its leg; ankle and toe keep the
# network's rotations.
_LEGS = (LIMBS[J["left_ankle"]], LIMBS[J["right_ankle"]])
_HIPS = (J["left_hip"], J["right_hip"])
_KNEES = (J["left_knee"], J["right_knee"])


@dataclass
class _Foot:
    anchor: np.ndarray | None = None  # the contact point while in contact
    release_from: np.ndarray | None = None  # the contact point being let go
    release_step: int = 0


def release_weight(step: int, frames: int) -> float:
    """0 -> 1 over frames steps, slow at both ends."""
    return 0.5 - 0.5 * np.cos(np.pi * min(step, frames) / frames)


class ContactHold:
    def __init__(self, skeleton: Skeleton, release_frames: int = 10) -> None:
        if release_frames < 1:
            raise ValueError(f"release_frames must be at least 1, got {release_frames}")
        self.skeleton = skeleton
        self.release_frames = release_frames
        self.reset()

    def reset(self) -> None:
        self._feet = [_Foot(), _Foot()]

    def apply(self, local: np.ndarray, root: np.ndarray, contact: np.ndarray) -> np.ndarray:
        """Local rotations (22, 3, 3) with the legs moved to honour the contacts (left, right)."""
        offsets = self.skeleton.offsets
        _, pos = forward_kinematics(local, root, offsets, joints=LEG_JOINTS)
        local = local.copy()
        for side, foot in enumerate(self._feet):
            toe, hip, knee = pos[FOOT_JOINTS[side]], pos[_HIPS[side]], pos[_KNEES[side]]
            # what hip and knee can reach with the ankle as the network has it
            span = 0.999 * (math.dist(knee, hip) + math.dist(toe, knee))  # math: numpy's per-call cost
            if foot.anchor is not None and math.dist(foot.anchor, hip) > span:
                contact = contact.copy()
                contact[side] = False  # out of reach: let it go rather than stretch
            if contact[side]:
                if foot.anchor is None:
                    foot.anchor = toe.copy()
                foot.release_from = None
                target = foot.anchor
            else:
                if foot.anchor is not None:
                    foot.release_from, foot.release_step, foot.anchor = foot.anchor, 0, None
                if foot.release_from is None:
                    continue
                foot.release_step += 1
                w = release_weight(foot.release_step, self.release_frames)
                target = (1 - w) * foot.release_from + w * toe
                if foot.release_step >= self.release_frames:
                    foot.release_from = None
            leg = _LEGS[side]
            toe_from_knee = offsets[leg.end] + local[leg.end] @ offsets[FOOT_JOINTS[side]]
            reach(local, local[0], pos[leg.upper], offsets, leg, target, end_vector=toe_from_knee)
        return local
