"""DTP's input and output representations (numpy; training and runtime share them).

Input per frame (paper, eq. 1-2): the pelvis position and rotation (3 + 9) and the five other
sensors (head, hands, feet) relative to the pelvis: positions and flattened rotation
matrices in the pelvis frame, 5 x 12. That is 72 values.

One deviation: the paper feeds the pelvis in world coordinates, so the same motion played
elsewhere in the room, or facing another way, is a different input. Here the pelvis of
every frame in the window is expressed in the frame of the window's current pelvis,
heading only: x, y relative to the current pelvis on the floor, z its height above the floor,
and its rotation with the current heading taken out. The leaves are pelvis-relative as in
the paper.

Positions are scaled to the canonical body (leg length) first, as LoBSTr's are.

Output: the local rotations of joints 1..21 (6D, 126 values); the pelvis's rotation and
position are the pelvis tracker's (paper, eq. 3).
"""

from __future__ import annotations

import numpy as np

from ...core.rotations import yaw_matrix_of
from ...core.sensors import SITE_JOINTS
from ...core.skeleton import JOINT_INDEX, NUM_JOINTS

PELVIS_SITE = "pelvis"
LEAF_SITES = ("head", "left_hand", "right_hand", "left_foot", "right_foot")
INPUT_SITES = (PELVIS_SITE,) + LEAF_SITES
INPUT_JOINTS = tuple(JOINT_INDEX[SITE_JOINTS[s]] for s in INPUT_SITES)  # the feet trackers follow the ankles
FOOT_LEAVES = (3, 4)  # left and right foot among LEAF_SITES
FEATURES = 3 + 9 + len(LEAF_SITES) * 12
OUTPUTS = (NUM_JOINTS - 1) * 6
LEAF_FEATURES = len(LEAF_SITES) * 12


def leaf_features(
    pelvis_pos: np.ndarray, pelvis_rot: np.ndarray, positions: np.ndarray, rotations: np.ndarray
) -> np.ndarray:
    """(..., 60): the leaves (..., 5, 3) / (..., 5, 3, 3) in the pelvis frame (..., 3) / (..., 3, 3)."""
    rt = np.swapaxes(pelvis_rot, -1, -2)
    pos = np.einsum("...ij,...kj->...ki", rt, positions - pelvis_pos[..., None, :])
    rot = rt[..., None, :, :] @ rotations
    parts = np.concatenate([pos, rot.reshape(rot.shape[:-2] + (9,))], axis=-1)  # (..., 5, 12)
    return parts.reshape(parts.shape[:-2] + (LEAF_FEATURES,))


def window_features(
    pelvis_pos: np.ndarray, pelvis_rot: np.ndarray, leaves: np.ndarray, current: int | np.ndarray = -1
) -> np.ndarray:
    """(..., W, 72) network input for a window of frames: pelvis (..., W, 3) / (..., W, 3, 3)
    in world coordinates (floor at z = 0, canonical scale), leaves (..., W, 60) from
    leaf_features; current: the window index (or one per window) whose heading and floor
    position are the reference."""
    ref_pos, ref_rot = _at(pelvis_pos, current, 1), _at(pelvis_rot, current, 2)
    yaw_t = np.swapaxes(yaw_matrix_of(ref_rot), -1, -2)[..., None, :, :]  # (..., 1, 3, 3)
    rel = np.einsum("...ij,...j->...i", yaw_t, pelvis_pos - ref_pos[..., None, :])
    rel[..., 2] = pelvis_pos[..., 2]
    rot = (yaw_t @ pelvis_rot).reshape(pelvis_rot.shape[:-2] + (9,))
    return np.concatenate([rel, rot, leaves], axis=-1)


def _at(a: np.ndarray, index: int | np.ndarray, tail: int) -> np.ndarray:
    """a[..., index, <tail dims>] with one index, or one index per window."""
    index = np.asarray(index)
    if not index.ndim:
        return a[(Ellipsis, int(index)) + (slice(None),) * tail]
    return np.take_along_axis(a, index.reshape(index.shape + (1,) * (tail + 1)), axis=-1 - tail).squeeze(-1 - tail)
