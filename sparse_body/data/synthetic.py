"""A short procedural walk on the canonical body: for tests and for the demo when no motion
capture is at hand. It is not real motion and is never used for training or metrics."""

from __future__ import annotations

import numpy as np

from ..core.rotations import euler_to_matrix, matrix_to_quat
from ..core.skeleton import JOINT_INDEX, NUM_JOINTS, Skeleton
from .motion import Motion


def synthetic_walk(
    seconds: float = 4.0, fps: float = 60.0, skeleton: Skeleton | None = None, speed: float = 1.0, cadence: float = 0.9
) -> Motion:
    """Walk forward along +x: legs swing about y, knees bend in swing, arms counter-swing.
    After STRAIGHT metres the walk turns onto a circle of that circumference and goes round
    it, so however long it is, it stays within 47 m of where it began (a
    5-minute walk went 300 m away, beyond the default play space, and every estimate of it was
    refused)."""
    skeleton = skeleton or Skeleton.canonical()
    t = np.arange(int(round(seconds * fps))) / fps
    phase = 2 * np.pi * cadence * t
    rot = np.tile(np.eye(3), (len(t), NUM_JOINTS, 1, 1))

    def about(axis: str, angle):
        angles = np.zeros((len(t), 3))
        angles[:, "xyz".index(axis)] = angle
        return euler_to_matrix(angles, "xyz")

    for side, sign in (("left", 1.0), ("right", -1.0)):
        swing = sign * np.sin(phase)  # +1: leg forward
        rot[:, JOINT_INDEX[f"{side}_hip"]] = about("y", -np.deg2rad(25) * swing)
        rot[:, JOINT_INDEX[f"{side}_knee"]] = about("y", np.deg2rad(30) * np.clip(np.cos(phase * sign), 0, None) + 0.05)
        rot[:, JOINT_INDEX[f"{side}_ankle"]] = about("y", np.deg2rad(8) * swing)
        lower = about("x", -sign * np.deg2rad(80))  # arms down from the T-pose
        rot[:, JOINT_INDEX[f"{side}_shoulder"]] = lower @ about("y", np.deg2rad(20) * swing)
        rot[:, JOINT_INDEX[f"{side}_elbow"]] = about("z", sign * np.deg2rad(15))
    rot[:, JOINT_INDEX["spine2"]] = about("z", np.deg2rad(4) * np.sin(phase))
    rot[:, JOINT_INDEX["head"]] = about("z", np.deg2rad(10) * np.sin(0.3 * phase))
    rest = skeleton.rest_positions()
    stand = -rest[:, 2].min() + 0.03 - 0.02  # toes (3 cm above the sole) on the floor, knees bent a little
    walked = speed * t
    radius = STRAIGHT / (2 * np.pi)
    heading = np.clip(walked - STRAIGHT, 0.0, None) / radius  # 0 on the straight, then round the circle
    along = np.stack([np.minimum(walked, STRAIGHT) + radius * np.sin(heading), radius * (1 - np.cos(heading))], axis=-1)
    sway = 0.02 * np.sin(phase)  # sideways, in the walker's own frame
    root = np.stack(
        [along[:, 0] - sway * np.sin(heading), along[:, 1] + sway * np.cos(heading), stand + 0.015 * np.cos(2 * phase)],
        axis=-1,
    )
    rot[:, 0] = about("z", heading) @ rot[:, 0]
    return Motion("synthetic_walk", fps, skeleton, matrix_to_quat(rot), root)


STRAIGHT = 40.0  # m walked straight before the walk turns round a circle
