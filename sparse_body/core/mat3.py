"""Compiled 3-vector and 3x3 arithmetic for the per-frame path (numba).

A frame of IK is a few hundred products of 3x3 matrices and 3-vectors. As numpy calls each
costs about a microsecond of dispatch, far more than its nine multiplications (issue 28's
profile: 1,300 calls a step); compiled, a whole solve is one call. numba is the usual tool
for this in the field: plain loops in Python syntax, compiled on first use and cached on
disk (cache=True: a later process loads the machine code in milliseconds).

error_model="numpy": a division by zero gives inf or nan as numpy would, never an
exception; the estimators check their output for non-finite numbers and start over.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit as _njit


def njit(fn):
    """numba.njit with the package's settings: cached on disk, numpy's error model."""
    return _njit(cache=True, error_model="numpy")(fn)


def njit_nogil(fn):
    """njit for a kernel long enough (a tenth of a millisecond or more) that another thread
    should run meanwhile: it releases the GIL."""
    return _njit(cache=True, error_model="numpy", nogil=True)(fn)


@njit
def mul(a, b):
    """a @ b for 3x3 matrices."""
    out = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            out[i, j] = a[i, 0] * b[0, j] + a[i, 1] * b[1, j] + a[i, 2] * b[2, j]
    return out


@njit
def tmul(a, b):
    """a.T @ b for 3x3 matrices."""
    out = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            out[i, j] = a[0, i] * b[0, j] + a[1, i] * b[1, j] + a[2, i] * b[2, j]
    return out


@njit
def vec(a, v):
    """a @ v for a 3x3 matrix and a 3-vector."""
    out = np.empty(3)
    for i in range(3):
        out[i] = a[i, 0] * v[0] + a[i, 1] * v[1] + a[i, 2] * v[2]
    return out


@njit
def tvec(a, v):
    """a.T @ v for a 3x3 matrix and a 3-vector."""
    out = np.empty(3)
    for i in range(3):
        out[i] = a[0, i] * v[0] + a[1, i] * v[1] + a[2, i] * v[2]
    return out


@njit
def norm(v) -> float:
    return math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


@njit
def cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@njit
def about(axis, angle: float):
    """The rotation about a unit axis by angle (Rodrigues)."""
    x, y, z = axis[0], axis[1], axis[2]
    c, s = math.cos(angle), math.sin(angle)
    t = 1.0 - c
    out = np.empty((3, 3))
    out[0, 0], out[0, 1], out[0, 2] = c + x * x * t, x * y * t - z * s, x * z * t + y * s
    out[1, 0], out[1, 1], out[1, 2] = y * x * t + z * s, c + y * y * t, y * z * t - x * s
    out[2, 0], out[2, 1], out[2, 2] = z * x * t - y * s, z * y * t + x * s, c + z * z * t
    return out


@njit
def between(a, b):
    """The smallest rotation taking direction a onto direction b (identity when either is
    zero)."""
    na, nb = norm(a), norm(b)
    if na < 1e-12 or nb < 1e-12:
        return np.eye(3)
    a, b = a / na, b / nb
    c = a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    if c < -1.0 + 1e-9:  # opposite directions: half a turn about any perpendicular axis
        other = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        perp = cross(a, other)
        return about(perp / norm(perp), math.pi)
    k = cross(a, b)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + kx + mul(kx, kx) / (1.0 + c)


@njit
def quat_matrix(q):
    """A unit quaternion (x y z w) as a rotation matrix."""
    x, y, z, w = q[0], q[1], q[2], q[3]
    out = np.empty((3, 3))
    out[0, 0], out[0, 1], out[0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)
    out[1, 0], out[1, 1], out[1, 2] = 2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)
    out[2, 0], out[2, 1], out[2, 2] = 2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)
    return out


@njit
def quat_matrices(q):
    """Unit quaternions (N, 4) as rotation matrices (N, 3, 3)."""
    out = np.empty((len(q), 3, 3))
    for n in range(len(q)):
        out[n] = quat_matrix(q[n])
    return out


@njit
def forward_kinematics_into(local, root, offsets, parents, joints, glob, pos) -> None:
    """One pose's global rotations and positions, written into glob (J, 3, 3) and pos (J, 3):
    the root and then joints (parents before children)."""
    glob[0] = local[0]
    pos[0] = root
    for j in joints:
        p = parents[j]
        glob[j] = mul(glob[p], local[j])
        pos[j] = pos[p] + vec(glob[p], offsets[j])


@njit
def forward_kinematics_batch(local, root, offsets, parents):
    """Global rotations (B, J, 3, 3) and positions (B, J, 3) of B poses on one body."""
    glob, pos = np.empty_like(local), np.empty((len(local), len(offsets), 3))
    for b in range(len(local)):
        glob[b, 0], pos[b, 0] = local[b, 0], root[b]
        for j in range(1, len(offsets)):
            p = parents[j]
            glob[b, j] = mul(glob[b, p], local[b, j])
            pos[b, j] = pos[b, p] + vec(glob[b, p], offsets[j])
    return glob, pos


@njit
def quats(m):
    """Quaternions (N, 4) of orthonormal matrices (N, 3, 3); rotations.rotations_to_quat."""
    out = np.empty((len(m), 4))
    for n in range(len(m)):
        r = m[n]
        d0, d1, d2 = r[0, 0], r[1, 1], r[2, 2]
        x = 0.5 * math.sqrt(max(0.0, 1 + d0 - d1 - d2))
        y = 0.5 * math.sqrt(max(0.0, 1 - d0 + d1 - d2))
        z = 0.5 * math.sqrt(max(0.0, 1 - d0 - d1 + d2))
        w = 0.5 * math.sqrt(max(0.0, 1 + d0 + d1 + d2))
        x, y, z = (
            math.copysign(x, r[2, 1] - r[1, 2]),
            math.copysign(y, r[0, 2] - r[2, 0]),
            math.copysign(z, r[1, 0] - r[0, 1]),
        )
        size = math.sqrt(x * x + y * y + z * z + w * w)
        out[n, 0], out[n, 1], out[n, 2], out[n, 3] = x / size, y / size, z / size, w / size
    return out


@njit
def sixd_matrices(d6):
    """Rotation matrices (N, 3, 3) from 6D (N, 6); rotations.sixd_to_matrix."""
    out = np.empty((len(d6), 3, 3))
    for n in range(len(d6)):
        a, b = d6[n, 0:3], d6[n, 3:6]
        a = a / norm(a)
        b = b - (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) * a
        b = b / norm(b)
        c = cross(a, b)
        for i in range(3):
            out[n, i, 0], out[n, i, 1], out[n, i, 2] = a[i], b[i], c[i]
    return out


@njit
def yaw_frame(m):
    """The rotation about +z to the heading of m's forward (+x) axis on the ground plane;
    rotations.yaw_matrix(rotations.heading(m))."""
    yaw = math.atan2(m[1, 0], m[0, 0])
    c, s = math.cos(yaw), math.sin(yaw)
    out = np.zeros((3, 3))
    out[0, 0], out[0, 1], out[1, 0], out[1, 1], out[2, 2] = c, -s, s, c, 1.0
    return out
