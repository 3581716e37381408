"""Rotation conversions used across the package.

Quaternions are (x, y, z, w) as in geometry_msgs and scipy. numpy conversions wrap
scipy.spatial.transform.Rotation; torch conversions wrap roma. Only what neither library
offers in the needed shape is written here (6D, batched reshaping).
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

# JointState carries a 3-DoF joint as three revolute joints applied in this order about the
# parent-aligned axes: R = Rz(yaw) @ Ry(pitch) @ Rx(roll), i.e. intrinsic Z-Y-X.
JOINT_EULER_ORDER = "ZYX"


def _flat(x: np.ndarray, tail: tuple[int, ...]) -> tuple[np.ndarray, tuple[int, ...]]:
    x = np.asarray(x, dtype=np.float64)
    lead = x.shape[: x.ndim - len(tail)]
    return x.reshape((-1,) + tail), lead


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    flat, lead = _flat(q, (4,))
    return Rotation.from_quat(flat).as_matrix().reshape(lead + (3, 3))


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    flat, lead = _flat(m, (3, 3))
    return Rotation.from_matrix(flat).as_quat().reshape(lead + (4,))


def axis_angle_to_matrix(v: np.ndarray) -> np.ndarray:
    flat, lead = _flat(v, (3,))
    return Rotation.from_rotvec(flat).as_matrix().reshape(lead + (3, 3))


def matrix_to_axis_angle(m: np.ndarray) -> np.ndarray:
    flat, lead = _flat(m, (3, 3))
    return Rotation.from_matrix(flat).as_rotvec().reshape(lead + (3,))


def euler_to_matrix(angles: np.ndarray, order: str = JOINT_EULER_ORDER) -> np.ndarray:
    """Angles in radians; upper-case order is intrinsic, lower-case extrinsic (scipy's rule)."""
    flat, lead = _flat(angles, (3,))
    return Rotation.from_euler(order, flat).as_matrix().reshape(lead + (3, 3))


def matrix_to_euler(m: np.ndarray, order: str = JOINT_EULER_ORDER) -> np.ndarray:
    flat, lead = _flat(m, (3, 3))
    return Rotation.from_matrix(flat).as_euler(order).reshape(lead + (3,))


def matrix_to_6d(m: np.ndarray) -> np.ndarray:
    """The first two columns of the matrix (Zhou et al. 2019), flattened column by column."""
    m = np.asarray(m)
    return np.concatenate([m[..., :, 0], m[..., :, 1]], axis=-1)


def sixd_to_matrix(d6: np.ndarray) -> np.ndarray:
    """Gram-Schmidt of the two 3-vectors back to a rotation matrix (columns a, b, a x b)."""
    d6 = np.asarray(d6, dtype=np.float64)
    a = d6[..., 0:3] / np.linalg.norm(d6[..., 0:3], axis=-1, keepdims=True)
    b = d6[..., 3:6] - np.sum(a * d6[..., 3:6], axis=-1, keepdims=True) * a
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.stack([a, b, np.cross(a, b)], axis=-1)


def rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation matrix taking direction a onto direction b."""
    a = np.asarray(a, float) / np.linalg.norm(a)
    b = np.asarray(b, float) / np.linalg.norm(b)
    axis = np.cross(a, b)
    s, c = np.linalg.norm(axis), float(np.dot(a, b))
    if s < 1e-9:
        if c > 0:
            return np.eye(3)
        # Opposite directions: half a turn about any axis perpendicular to a.
        perp = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        return Rotation.from_rotvec(np.pi * perp / np.linalg.norm(perp)).as_matrix()
    return Rotation.from_rotvec(axis / s * np.arctan2(s, c)).as_matrix()


def angle_between(m1: np.ndarray, m2: np.ndarray) -> np.ndarray:
    """Geodesic angle in radians between rotation matrices (broadcasting)."""
    rel = np.swapaxes(m1, -1, -2) @ m2
    cos = (np.trace(rel, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.arccos(np.clip(cos, -1.0, 1.0))


def slerp_resample(quats: np.ndarray, src_times: np.ndarray, dst_times: np.ndarray) -> np.ndarray:
    """Resample (T, ..., 4) quaternions from src_times to dst_times (inside the source span)."""
    quats = np.asarray(quats, dtype=np.float64)
    tail = quats.shape[1:-1]
    flat = quats.reshape(len(quats), -1, 4)
    out = np.empty((len(dst_times), flat.shape[1], 4))
    for k in range(flat.shape[1]):
        out[:, k] = Slerp(src_times, Rotation.from_quat(flat[:, k]))(dst_times).as_quat()
    return out.reshape((len(dst_times),) + tail + (4,))


def yaw_matrix(yaw: np.ndarray) -> np.ndarray:
    """Rotation about +z (REP-103 up) by yaw radians."""
    yaw = np.asarray(yaw, dtype=np.float64)
    c, s = np.cos(yaw), np.sin(yaw)
    z, o = np.zeros_like(yaw), np.ones_like(yaw)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def heading(m: np.ndarray) -> np.ndarray:
    """Yaw of a rotation's forward (+x) axis projected on the ground plane."""
    fwd = np.asarray(m)[..., :, 0]
    return np.arctan2(fwd[..., 1], fwd[..., 0])
