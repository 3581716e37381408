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

from .skeleton import NUM_JOINTS, PARENTS


def njit(fn):
    """numba.njit with the package's settings: cached on disk, numpy's error model."""
    return _njit(cache=True, error_model="numpy")(fn)


_PARENTS = np.array(PARENTS, dtype=np.int64)


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
    """The rotation about a unit axis by angle (Rodrigues); rotations.rotation_about."""
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
    zero); rotations.rotation_between."""
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
def forward_kinematics_into(local, root, offsets, glob, pos) -> None:
    """One pose's global rotations and positions, written into glob (22, 3, 3) and pos (22, 3)."""
    glob[0] = local[0]
    pos[0] = root
    for j in range(1, NUM_JOINTS):
        p = _PARENTS[j]
        glob[j] = mul(glob[p], local[j])
        pos[j] = pos[p] + vec(glob[p], offsets[j])


def compile_kernels() -> None:
    """Compile (or load from the disk cache) every kernel of the per-frame path by running
    each once; setup runs it, so that the first estimator started after an install does not
    spend seconds compiling (numba compiles on first call)."""
    from .body_ik import LIMBS, reach, solve_body
    from .skeleton import Skeleton, standing_pose

    offsets = Skeleton.canonical().offsets
    local, root = standing_pose(), np.array([0.0, 0.0, 0.9])
    glob, pos = np.empty((NUM_JOINTS, 3, 3)), np.empty((NUM_JOINTS, 3))
    forward_kinematics_into(local, root, offsets, glob, pos)
    targets = {end: pos[end] + 0.05 for end in (15, *LIMBS)}
    for keep in (False, True):
        solve_body(local, root, offsets, targets, keep_shape=keep)
    limb = next(iter(LIMBS.values()))
    reach(local.copy(), glob[0], pos[limb.upper], offsets, limb, pos[limb.end], offsets[limb.end], exact_hinge=False)
