"""Forward kinematics of the 22-joint body in numpy (the torch twin is train/torch_body.py)."""

from __future__ import annotations

import numpy as np

from . import mat3
from .skeleton import JOINT_INDEX, LOWER_BODY, NUM_JOINTS, PARENTS

_PARENTS = np.array(PARENTS, dtype=np.int64)


def forward_kinematics(local_rot: np.ndarray, root_pos: np.ndarray, offsets: np.ndarray, joints=None):
    """Global joint rotations and positions.

    local_rot: (..., 22, 3, 3) rotation of each joint relative to its parent (the root's is
    global); root_pos: (..., 3); offsets: (22, 3) or (..., 22, 3).
    Returns (global_rot (..., 22, 3, 3), positions (..., 22, 3)).
    joints (one pose only): compute just these (parents before children, e.g. LEG_JOINTS);
    the other joints' entries are left undefined.
    """
    local_rot = np.asarray(local_rot, dtype=np.float64)
    if local_rot.ndim in (3, 4):  # the compiled paths take contiguous arrays (one signature)
        local_rot = np.ascontiguousarray(local_rot)
    if local_rot.ndim == 3 and np.ndim(offsets) == 2:
        glob, pos = np.empty_like(local_rot), np.empty((NUM_JOINTS, 3))
        subset = _ALL_BUT_ROOT if joints is None else np.asarray(joints, dtype=np.int64)
        root_pos, offsets = np.ascontiguousarray(root_pos, np.float64), np.ascontiguousarray(offsets, np.float64)
        mat3.forward_kinematics_into(local_rot, root_pos, offsets, _PARENTS, subset, glob, pos)  # compiled
        return glob, pos
    if joints is not None:
        raise ValueError("a joint subset is for one pose with one skeleton")
    lead = local_rot.shape[:-3]
    offsets = np.asarray(offsets, dtype=np.float64)
    if local_rot.ndim == 4 and offsets.ndim == 2:  # a batch of poses of one body (an optimiser's): compiled
        root = np.ascontiguousarray(np.broadcast_to(np.asarray(root_pos, dtype=np.float64), lead + (3,)))
        return mat3.forward_kinematics_batch(local_rot, root, np.ascontiguousarray(offsets), _PARENTS)
    shared = offsets.ndim == 2  # one body for the whole batch: a matrix-vector product per joint
    if not shared:
        offsets = np.broadcast_to(offsets, lead + (NUM_JOINTS, 3))
    glob = np.empty_like(local_rot)
    pos = np.empty(lead + (NUM_JOINTS, 3))
    glob[..., 0, :, :] = local_rot[..., 0, :, :]
    pos[..., 0, :] = root_pos
    for j in range(1, NUM_JOINTS):
        p = PARENTS[j]
        glob[..., j, :, :] = glob[..., p, :, :] @ local_rot[..., j, :, :]
        if shared:
            pos[..., j, :] = pos[..., p, :] + glob[..., p, :, :] @ offsets[j]
        else:
            pos[..., j, :] = pos[..., p, :] + np.einsum("...ab,...b->...a", glob[..., p, :, :], offsets[..., j, :])
    return glob, pos


_ALL_BUT_ROOT = np.arange(1, NUM_JOINTS)
# the legs, parents before children: what a foot's IK needs, a third of the body's FK
LEG_JOINTS = tuple(JOINT_INDEX[n] for n in LOWER_BODY)


def global_to_local(global_rot: np.ndarray) -> np.ndarray:
    """Local rotations (..., 22, 3, 3) from global ones."""
    local = np.empty_like(global_rot)
    local[..., 0, :, :] = global_rot[..., 0, :, :]
    for j in range(1, NUM_JOINTS):
        local[..., j, :, :] = np.swapaxes(global_rot[..., PARENTS[j], :, :], -1, -2) @ global_rot[..., j, :, :]
    return local
