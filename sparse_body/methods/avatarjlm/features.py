"""AvatarJLM's input representation (numpy; training and runtime share it).

Input per frame and tracker (paper, Section 3.1): rotation (6D), position, linear velocity
and angular velocity (6D): 18 values; head and hands (three_point) give 54, with the pelvis
(four_point, the paper's four-input row) 72.

The paper feeds them in world coordinates. Here each frame is expressed in its own frame of
reference: z up, x along the head's heading, origin on the floor under the head (positions
keep their height). So the same motion gives the same input wherever the person stands or
faces, and a frame's features never change once computed, which lets the runtime keep the
network's past instead of running the whole window again each frame. The linear velocity
is the world displacement since the previous frame in that frame of reference; the angular
velocity is the frame-to-frame rotation in the tracker's own frame (both per model frame).

Positions are scaled to the canonical body (leg length) first, as LoBSTr's and DTP's are.
"""

from __future__ import annotations

import numpy as np

from ...core.rotations import matrix_to_6d, yaw_matrix_of
from ...core.sensors import SITE_JOINTS
from ...core.skeleton import JOINT_INDEX

SITES = {
    "three_point": ("head", "left_hand", "right_hand"),
    "four_point": ("head", "left_hand", "right_hand", "pelvis"),
}
PER_SITE = 18


def input_joints(sites: tuple[str, ...]) -> tuple[int, ...]:
    """The joints the trackers follow, in input order (the head first)."""
    return tuple(JOINT_INDEX[SITE_JOINTS[s]] for s in sites)


def reference(head_pos: np.ndarray, head_rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each frame's frame of reference: (origin (..., 3) on the floor under the head, yaw
    rotation (..., 3, 3) of the head's heading)."""
    origin = np.array(head_pos, dtype=np.float64, copy=True)
    origin[..., 2] = 0.0
    return origin, yaw_matrix_of(head_rot)


def features(
    positions: np.ndarray,
    rotations: np.ndarray,
    previous_positions: np.ndarray,
    previous_rotations: np.ndarray,
    step: float = 1.0,
) -> np.ndarray:
    """(..., 18 n): n trackers (..., n, 3) / (..., n, 3, 3) now and at the previous sample
    (canonical scale, floor at z = 0; the head first). step: the time since the previous
    sample in model frames (velocities are per model frame)."""
    origin, yaw = reference(positions[..., 0, :], rotations[..., 0, :, :])
    yaw_t = np.swapaxes(yaw, -1, -2)[..., None, :, :]
    rot = yaw_t @ rotations
    pos = (yaw_t @ (positions - origin[..., None, :])[..., None])[..., 0]
    vel = (yaw_t @ (positions - previous_positions)[..., None])[..., 0] / step
    turn = np.swapaxes(previous_rotations, -1, -2) @ rotations
    if step != 1.0:  # the same turn per model frame: scale its angle (rare: a stream at another rate)
        from ...core.rotations import axis_angle_to_matrix, matrix_to_axis_angle

        turn = axis_angle_to_matrix(matrix_to_axis_angle(turn) / step)
    parts = np.concatenate([matrix_to_6d(rot), pos, vel, matrix_to_6d(turn)], axis=-1)  # (..., n, 18)
    return parts.reshape(parts.shape[:-2] + (-1,))


def sequence_features(positions: np.ndarray, rotations: np.ndarray) -> np.ndarray:
    """(T, 18 n) for a sequence (T, n, 3) / (T, n, 3, 3) at the model's rate; the first frame
    has zero velocity."""
    prev_p = np.concatenate([positions[:1], positions[:-1]])
    prev_r = np.concatenate([rotations[:1], rotations[:-1]])
    return features(positions, rotations, prev_p, prev_r)
