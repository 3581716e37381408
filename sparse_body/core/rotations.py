"""Rotation conversions used across the package.

Quaternions are (x, y, z, w) as in geometry_msgs and scipy. numpy conversions wrap
scipy.spatial.transform.Rotation; torch conversions wrap roma. Only what neither library
offers in the needed shape is written here (6D, batched reshaping).
"""

from __future__ import annotations

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
    trackers' hot path converts a handful per frame; compiled: mat3.quat_matrix)."""
    return mat3.quat_matrix(np.ascontiguousarray(q, dtype=np.float64))


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


def rotation_about(axis, angle: float) -> np.ndarray:
    """The rotation matrix about a unit axis (Rodrigues), for one rotation in a hot path
    (compiled: mat3.about)."""
    return mat3.about(np.ascontiguousarray(axis, dtype=np.float64), float(angle))


def rotation_between(a, b) -> np.ndarray:
    """The smallest rotation matrix taking direction a onto direction b (identity when
    either is zero; compiled: mat3.between)."""
    c = np.ascontiguousarray
    return mat3.between(c(a, dtype=np.float64), c(b, dtype=np.float64))


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


def slerp(a: np.ndarray, b: np.ndarray, t: float) -> np.ndarray:
    """Row by row, unit quaternions (x y z w) a -> b at t: the shorter arc. (scipy's Slerp
    interpolates along one sequence of key rotations, not between two arrays row by row.)"""
    dot = np.sum(a * b, axis=-1, keepdims=True)
    b = np.where(dot < 0.0, -b, b)
    dot = np.clip(np.abs(dot), 0.0, 1.0)
    angle = np.arccos(dot)
    sin = np.sin(angle)
    near = sin < 1e-6  # the same rotation: the line is the arc
    wa = np.where(near, 1.0 - t, np.sin((1.0 - t) * angle) / np.where(near, 1.0, sin))
    wb = np.where(near, t, np.sin(t * angle) / np.where(near, 1.0, sin))
    q = wa * a + wb * b
    return q / np.linalg.norm(q, axis=-1, keepdims=True)
