"""Rotation conversions used across the package.

Quaternions are (x, y, z, w) as in geometry_msgs and scipy. numpy conversions wrap
scipy.spatial.transform.Rotation; torch conversions wrap roma. Only what neither library
offers in the needed shape is written here (6D, batched reshaping).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from . import mat3

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


def unit_quat_matrix(q) -> np.ndarray:
    """One unit quaternion (x y z w) as a matrix, without scipy's per-call overhead (the
    trackers' hot path converts a handful per frame)."""
    x, y, z, w = (float(v) for v in q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    flat, lead = _flat(m, (3, 3))
    return Rotation.from_matrix(flat).as_quat().reshape(lead + (4,))


def rotations_to_quat(m: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) of rotation matrices that are orthonormal already (an estimator's
    output), without scipy's orthogonalisation: several times faster at 22 joints. Each
    component's size comes from the diagonal, its sign from the skew part (w >= 0); accurate
    to about 1e-8 where a component is near zero. One pose's (J, 3, 3) is compiled
    (mat3.quats): an estimator's output, every frame."""
    m = np.asarray(m, dtype=np.float64)
    if m.ndim == 3:
        return mat3.quats(np.ascontiguousarray(m))
    d0, d1, d2 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    q = 0.5 * np.sqrt(
        np.maximum(0.0, np.stack([1 + d0 - d1 - d2, 1 - d0 + d1 - d2, 1 - d0 - d1 + d2, 1 + d0 + d1 + d2], -1))
    )
    q[..., 0] = np.copysign(q[..., 0], m[..., 2, 1] - m[..., 1, 2])
    q[..., 1] = np.copysign(q[..., 1], m[..., 0, 2] - m[..., 2, 0])
    q[..., 2] = np.copysign(q[..., 2], m[..., 1, 0] - m[..., 0, 1])
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


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
    """Gram-Schmidt of the two 3-vectors back to a rotation matrix (columns a, b, a x b).
    One frame's (N, 6) is compiled (mat3.sixd_matrices): a network's output, every frame."""
    d6 = np.asarray(d6, dtype=np.float64)
    if d6.ndim == 2:
        return mat3.sixd_matrices(np.ascontiguousarray(d6))
    a = d6[..., 0:3] / np.linalg.norm(d6[..., 0:3], axis=-1, keepdims=True)
    b = d6[..., 3:6] - np.sum(a * d6[..., 3:6], axis=-1, keepdims=True) * a
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.stack([a, b, np.cross(a, b)], axis=-1)


def cross3(a, b) -> np.ndarray:
    """a x b for two 3-vectors (np.cross costs ten times more at this size)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def rotation_about(axis, angle: float) -> np.ndarray:
    """The rotation matrix about a unit axis (Rodrigues), for one rotation in a hot path."""
    x, y, z = (float(v) for v in axis)
    c, s = math.cos(angle), math.sin(angle)
    t = 1.0 - c
    return np.array(
        [
            [c + x * x * t, x * y * t - z * s, x * z * t + y * s],
            [y * x * t + z * s, c + y * y * t, y * z * t - x * s],
            [z * x * t - y * s, z * y * t + x * s, c + z * z * t],
        ]
    )


def rotation_between(a, b) -> np.ndarray:
    """The smallest rotation matrix taking direction a onto direction b (identity when
    either is zero)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    na, nb = math.sqrt(a @ a), math.sqrt(b @ b)
    if na < 1e-12 or nb < 1e-12:
        return np.eye(3)
    a, b = a / na, b / nb
    c = float(a @ b)
    if c < -1.0 + 1e-9:  # opposite directions: half a turn about any perpendicular axis
        perp = cross3(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        return rotation_about(perp / math.sqrt(perp @ perp), math.pi)
    k = cross3(a, b)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + kx + (kx @ kx) / (1.0 + c)


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


def yaw_matrix(yaw: np.ndarray | float) -> np.ndarray:
    """Rotation about +z (REP-103 up) by yaw radians."""
    yaw = np.asarray(yaw, dtype=np.float64)
    c, s = np.cos(yaw), np.sin(yaw)
    out = np.zeros(yaw.shape + (3, 3))  # filled in place: nested stacks cost ten times more
    out[..., 0, 0], out[..., 0, 1], out[..., 1, 0], out[..., 1, 1], out[..., 2, 2] = c, -s, s, c, 1.0
    return out


def yaw_matrix_of(m: np.ndarray) -> np.ndarray:
    """yaw_matrix(heading(m)): the turn about +z to each rotation's heading (compiled for one
    rotation, mat3.yaw_frame)."""
    m = np.asarray(m, dtype=np.float64)
    return mat3.yaw_frame(np.ascontiguousarray(m)) if m.ndim == 2 else yaw_matrix(heading(m))


def heading(m: np.ndarray) -> np.ndarray:
    """Yaw of a rotation's forward (+x) axis projected on the ground plane."""
    fwd = np.asarray(m)[..., :, 0]
    return np.arctan2(fwd[..., 1], fwd[..., 0])
