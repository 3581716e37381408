"""DragPoser's pose representation (numpy; training and runtime share it).

The pose VAE sees a pose without where it stands or which way it faces: the root rotation
has its heading (yaw) removed, and the root translation is only its height above the floor.
Heading and root position are optimised beside the latent at runtime, so the latent space
spends its 24 dimensions on the body's shape of motion.

- Encoder input: each joint's dual quaternion in the root's heading frame (rotation, and
  translation = the joint's position relative to the root on the ground), 22 x 8, as in the
  paper ("rotations and translations in root space", Andreou et al. 2022).
- Decoder output: 22 local rotations in 6D (the root's without heading): 132 numbers.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ...core.kinematics import forward_kinematics
from ...core.rotations import heading, yaw_matrix
from ...core.skeleton import NUM_JOINTS

LATENT = 24
ENCODER_INPUT = NUM_JOINTS * 8
DECODER_OUTPUT = NUM_JOINTS * 6


def split_heading(local_rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(local rotations with a heading-free root, yaw) from local rotations (..., 22, 3, 3)."""
    yaw = heading(local_rot[..., 0, :, :])
    out = local_rot.copy()
    out[..., 0, :, :] = np.swapaxes(yaw_matrix(yaw), -1, -2) @ local_rot[..., 0, :, :]
    return out, yaw


def dual_quaternions(local_rot: np.ndarray, root_height: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Encoder input (..., 176) from heading-free local rotations (..., 22, 3, 3) and the
    root's height above the floor (...,)."""
    root = np.zeros(local_rot.shape[:-3] + (3,))
    root[..., 2] = root_height
    glob, pos = forward_kinematics(local_rot, root, offsets)
    pos = pos.copy()
    pos[..., 1:, :] -= root[..., None, :]  # joints relative to the root; the root keeps its height
    lead = glob.shape[:-2]
    real = Rotation.from_matrix(glob.reshape(-1, 3, 3)).as_quat().reshape(lead + (4,))  # x y z w
    real = real * np.where(real[..., 3:4] < 0, -1.0, 1.0)  # one hemisphere
    # dual part: 0.5 * (t, 0) * q, quaternion product in x y z w
    t, (qx, qy, qz, qw) = pos, np.moveaxis(real, -1, 0)
    tx, ty, tz = np.moveaxis(t, -1, 0)
    dual = 0.5 * np.stack(
        [
            tx * qw + ty * qz - tz * qy,
            -tx * qz + ty * qw + tz * qx,
            tx * qy - ty * qx + tz * qw,
            -tx * qx - ty * qy - tz * qz,
        ],
        axis=-1,
    )
    return np.concatenate([real, dual], axis=-1).reshape(lead[:-1] + (ENCODER_INPUT,))


# --- temporal predictor context -------------------------------------------------------------
# The paper gives the predictor's encoder "root displacements and the height to the ground
# for the root, head, hands, and feet" beside each past latent: the latent alone does not say
# whether the person walks or stands, nor how high they are.
HEIGHT_JOINTS = ("pelvis", "head", "left_wrist", "right_wrist", "left_foot", "right_foot")
LIMBS = {  # the paper's noise unit: one limb at a time
    "left_arm": ("left_collar", "left_shoulder", "left_elbow", "left_wrist"),
    "right_arm": ("right_collar", "right_shoulder", "right_elbow", "right_wrist"),
    "left_leg": ("left_hip", "left_knee", "left_ankle", "left_foot"),
    "right_leg": ("right_hip", "right_knee", "right_ankle", "right_foot"),
}
TEMPORAL_CONTEXT = 3 + len(HEIGHT_JOINTS)


def temporal_context(root: np.ndarray, yaw: np.ndarray, heights: np.ndarray) -> np.ndarray:
    """(T, 9) for T successive predictor steps: the root's ground displacement since the
    previous step in that step's heading frame (x, y), the heading change (rad), and the
    heights above the floor of HEIGHT_JOINTS. Lengths in canonical-body units (callers scale
    by body_scale). The first step has no displacement.

    root (T, 3), yaw (T,), heights (T, 6)."""
    out = np.zeros((len(root), TEMPORAL_CONTEXT))
    if len(root) > 1:
        step = root[1:, :2] - root[:-1, :2]
        c, s = np.cos(yaw[:-1]), np.sin(yaw[:-1])
        out[1:, 0] = c * step[:, 0] + s * step[:, 1]
        out[1:, 1] = -s * step[:, 0] + c * step[:, 1]
        out[1:, 2] = np.angle(np.exp(1j * (yaw[1:] - yaw[:-1])))
    out[:, 3:] = heights
    return out
