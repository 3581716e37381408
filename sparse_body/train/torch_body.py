"""The body model in torch, for losses that need forward kinematics (the numpy twin is
core/kinematics.py; test_kinematics checks they agree to 1e-6)."""

from __future__ import annotations

import roma
import torch

from ..core.skeleton import NUM_JOINTS, PARENTS


def forward_kinematics(local_rot: torch.Tensor, root_pos: torch.Tensor, offsets: torch.Tensor):
    """local_rot (..., 22, 3, 3), root_pos (..., 3), offsets (22, 3) or (..., 22, 3)
    -> (global_rot (..., 22, 3, 3), positions (..., 22, 3))."""
    offsets = offsets.to(local_rot).expand(local_rot.shape[:-3] + (NUM_JOINTS, 3))
    glob = [local_rot[..., 0, :, :]]
    pos = [root_pos]
    for j in range(1, NUM_JOINTS):
        p = PARENTS[j]
        glob.append(glob[p] @ local_rot[..., j, :, :])
        pos.append(pos[p] + (glob[p] @ offsets[..., j, :, None])[..., 0])
    return torch.stack(glob, dim=-3), torch.stack(pos, dim=-2)


def sixd_to_matrix(d6: torch.Tensor) -> torch.Tensor:
    """6D (two columns, flattened column by column) to rotation matrices, as core.rotations.
    Written out rather than roma.special_gramschmidt: the ONNX export must keep the batch
    dimension dynamic, and roma's reshapes trace to fixed shapes."""
    a = d6[..., 0:3] / d6[..., 0:3].norm(dim=-1, keepdim=True)
    b = d6[..., 3:6] - (a * d6[..., 3:6]).sum(-1, keepdim=True) * a
    b = b / b.norm(dim=-1, keepdim=True)
    c = torch.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        dim=-1,
    )
    return torch.stack([a, b, c], dim=-1)


def matrix_to_6d(m: torch.Tensor) -> torch.Tensor:
    return torch.cat([m[..., :, 0], m[..., :, 1]], dim=-1)


def quat_to_matrix(q: torch.Tensor) -> torch.Tensor:
    """Quaternions x y z w (roma's order too)."""
    return roma.unitquat_to_rotmat(q)
