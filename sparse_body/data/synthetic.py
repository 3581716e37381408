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
    """Walk forward along +x: legs swing about y, knees bend in swing, arms counter-swing."""
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
    root = np.stack([speed * t, 0.02 * np.sin(phase), stand + 0.015 * np.cos(2 * phase)], axis=-1)
    return Motion("synthetic_walk", fps, skeleton, matrix_to_quat(rot), root)
