"""A person's body proportions from where their trackers sit in a T-pose.

In the rest pose (a T-pose) the joints a tracker follows show lengths directly: the wrists'
distance is the arm span, their height the shoulder height, the head above them the neck,
the pelvis above the ankles the legs. What no tracker shows (the clavicle's share of the
span, the hip joints' drop below the pelvis, the ankle's height without foot trackers) comes
from the canonical body scaled to the person's height, as everything does without trackers.

fit_skeleton works in the person's facing frame (x forward, y left, z up, the floor at
z = 0) on joint positions, the trackers' mounting offsets already undone.
"""

from __future__ import annotations

import numpy as np

from .skeleton import JOINT_INDEX, STATURE_RATIO, Skeleton

_J = JOINT_INDEX
ARM = ("shoulder", "elbow", "wrist")  # clavicle, upper arm, forearm (offsets of these joints)
LEG = ("knee", "ankle")  # thigh, shin
SPINE = ("spine2", "spine3")  # pelvis -> spine3 (spine1 sits at the pelvis)
NECK = ("neck", "left_collar", "right_collar")  # spine3 -> base of the neck / clavicles


def _length(offsets: np.ndarray, joints) -> float:
    return float(sum(np.linalg.norm(offsets[_J[j]]) for j in joints))


def _scale(offsets: np.ndarray, joints, factor: float) -> None:
    for j in joints:
        offsets[_J[j]] *= factor


def _sides(names) -> list[str]:
    return [f"{side}_{n}" for side in ("left", "right") for n in names]


def arm_span(skeleton: Skeleton) -> float:
    """Wrist to wrist in the rest pose."""
    rest = skeleton.rest_positions()
    return float(np.linalg.norm(rest[_J["left_wrist"]] - rest[_J["right_wrist"]]))


def arm_length(skeleton: Skeleton) -> float:
    """Shoulder joint to wrist (upper arm + forearm), the mean of both sides."""
    return _length(skeleton.offsets, _sides(ARM[1:])) / 2


def leg_length(skeleton: Skeleton) -> float:
    """Hip joint to ankle (thigh + shin), the mean of both sides."""
    return _length(skeleton.offsets, _sides(LEG)) / 2


def fit_skeleton(joints: dict[str, np.ndarray], height: float) -> Skeleton:
    """The body whose T-pose puts its joints where the trackers saw them.

    joints: body site -> its joint's position (facing frame, floor at z = 0): head and both
    hands are used when present, pelvis and feet refine the torso and legs. height: the
    person's standing height (from the head, see calibrate_tpose)."""
    offsets = Skeleton.canonical(height).offsets.copy()
    head = joints.get("head")
    left, right = joints.get("left_hand"), joints.get("right_hand")
    if head is None:
        return Skeleton(offsets)
    if left is not None and right is not None:
        hands = [left, right]
        # Half the span is clavicle + upper arm + forearm; the clavicle keeps its canonical
        # share (no tracker sees the shoulder joint) and the arm the rest.
        chain = float(np.linalg.norm(hands[0] - hands[1])) / 2
        _scale(offsets, _sides(ARM), chain / _length(offsets, _sides(ARM)) * 2)
        shoulders = (hands[0][2] + hands[1][2]) / 2
        # the head joint above the shoulders is the head offset (the neck and the clavicles
        # start at one height in the canonical body)
        neck = head[2] - shoulders
        if 0.5 < neck / offsets[_J["head"], 2] < 2.0:
            offsets[_J["head"]] *= neck / offsets[_J["head"], 2]
    else:
        shoulders = head[2] - offsets[_J["head"], 2]
    rest = Skeleton(offsets).rest_positions()
    ankles = [joints.get("left_foot"), joints.get("right_foot")]
    ankle = (
        np.mean([a[2] for a in ankles if a is not None])
        if any(a is not None for a in ankles)
        else rest[_J["left_ankle"], 2] - rest[:, 2].min()
    )  # the ankle's canonical height above the toes
    hip_drop = -offsets[_J["left_hip"], 2]
    torso_now = _length(offsets, SPINE) + offsets[_J["neck"], 2]
    legs_now = _length(offsets, _sides(LEG)) / 2
    if joints.get("pelvis") is not None:
        pelvis = joints["pelvis"][2]
        torso, legs = shoulders - pelvis, pelvis - hip_drop - ankle
    else:  # only the sum shows: share it as the canonical body does
        both = shoulders - hip_drop - ankle
        torso, legs = both * torso_now / (torso_now + legs_now), both * legs_now / (torso_now + legs_now)
    if 0.5 < torso / torso_now < 2.0:
        _scale(offsets, SPINE + NECK, torso / torso_now)
    if 0.5 < legs / legs_now < 2.0:
        _scale(offsets, _sides(LEG), legs / legs_now)
    return Skeleton(offsets)


def standing_height(head_height: float) -> float:
    """A person's height from their head joint's height above the floor."""
    return float(head_height * STATURE_RATIO)
