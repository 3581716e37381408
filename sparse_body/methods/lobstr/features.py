"""LoBSTr's input and output representations (numpy; training and runtime share them).

Input per frame (paper, Appendix 1): the velocities of the reference joint and of the head
and hands, all in the current reference frame, plus the reference height: 4 x 9 + 1 = 37.
The reference frame sits at the pelvis, z up, x along the pelvis's forward direction
projected on the floor. Each velocity is a linear part (3) and a frame-to-frame rotation
in 6D (6).

Output: the 8 leg joints (hips, knees, ankles, feet) in 6D. The hips are expressed in the
reference frame rather than relative to the pelvis: the input carries no pelvis tilt, so
a pelvis-relative hip would have to guess it; the other joints are local as in the paper.

Positions are scaled to the canonical body (leg length) before anything else, which plays
the part of the paper's height scale from the T-pose calibration.

The learned upper body (ours, `LobstrConfig.learned_upper`): the paper solves the upper body
by IK, which leaves the shoulders, elbows and wrists 60 degrees off in rotation on people
the model never saw (`sparse-body eval --per-joint`). With it the network also predicts the
13 upper-body joints' local rotations, and since velocities alone cannot say where an arm
is, it also sees the current pose: head and hands relative to the reference (position and
6D rotation) and the pelvis's tilt in the reference frame, 3 x 9 + 6 = 33 more inputs.
"""

from __future__ import annotations

import numpy as np

from ...core import mat3
from ...core.mat3 import njit
from ...core.rotations import matrix_to_6d, yaw_matrix_of
from ...core.skeleton import JOINT_INDEX, LOWER_BODY, UPPER_BODY

# The tracked joints, in input order: the reference comes from the pelvis.
INPUT_SITES = ("pelvis", "head", "left_hand", "right_hand")
INPUT_JOINTS = tuple(JOINT_INDEX[j] for j in ("pelvis", "head", "left_wrist", "right_wrist"))
LEG_JOINT_NAMES = LOWER_BODY  # hips, knees, ankles, toes; left before right
LEG_JOINTS = tuple(JOINT_INDEX[j] for j in LEG_JOINT_NAMES)
HIPS = LEG_JOINTS[:2]
UPPER_JOINTS = tuple(JOINT_INDEX[j] for j in UPPER_BODY)
FEATURES = 4 * 9 + 1
POSE_FEATURES = 3 * 9 + 6
OUTPUTS = len(LEG_JOINTS) * 6
UPPER_OUTPUTS = len(UPPER_JOINTS) * 6


def feature_count(learned_upper: bool) -> int:
    return FEATURES + POSE_FEATURES * learned_upper


def output_count(learned_upper: bool) -> int:
    return OUTPUTS + UPPER_OUTPUTS * learned_upper


def reference_frames(pelvis_rot: np.ndarray) -> np.ndarray:
    """(..., 3, 3) yaw-only frames from pelvis rotations."""
    return yaw_matrix_of(pelvis_rot)


def features(
    positions: np.ndarray,
    rotations: np.ndarray,
    previous_positions: np.ndarray,
    previous_rotations: np.ndarray,
    floor: float = 0.0,
    pose: bool = False,
) -> np.ndarray:
    """Input vectors (..., 37) from the 4 tracked joints now and one frame earlier; with
    pose, (..., 70): the current pose's 33 after them.

    positions (..., 4, 3) already scaled to the canonical body (the floor too), rotations
    (..., 4, 3, 3); joint order INPUT_SITES. One frame's (4, 3) is compiled (a streaming
    step's); a sequence's runs in numpy, the same numbers within 1e-12 (test_lobstr).
    """
    if np.ndim(positions) == 2:
        c = np.ascontiguousarray
        args = (positions, rotations, previous_positions, previous_rotations)
        return _frame_features(*(c(a, dtype=np.float64) for a in args), float(floor), pose)
    ref = reference_frames(rotations[..., 0, :, :])
    ref_prev = reference_frames(previous_rotations[..., 0, :, :])
    refT, ref_prevT = np.swapaxes(ref, -1, -2), np.swapaxes(ref_prev, -1, -2)
    root, root_prev = positions[..., 0, :], previous_positions[..., 0, :]
    v_ref = np.einsum("...ij,...j->...i", refT, root - root_prev)
    w_ref = ref_prevT @ ref
    # The three joints relative to the reference, each frame in its own reference frame.
    rel = np.einsum("...ij,...kj->...ki", refT, positions[..., 1:, :] - root[..., None, :])
    rel_prev = np.einsum("...ij,...kj->...ki", ref_prevT, previous_positions[..., 1:, :] - root_prev[..., None, :])
    q = refT[..., None, :, :] @ rotations[..., 1:, :, :]
    q_prev = ref_prevT[..., None, :, :] @ previous_rotations[..., 1:, :, :]
    w = np.swapaxes(q_prev, -1, -2) @ q
    parts = [v_ref, matrix_to_6d(w_ref)]
    for k in range(3):
        parts += [rel[..., k, :] - rel_prev[..., k, :], matrix_to_6d(w[..., k, :, :])]
    parts.append(root[..., 2:3] - floor)
    if pose:
        for k in range(3):
            parts += [rel[..., k, :], matrix_to_6d(q[..., k, :, :])]
        parts.append(matrix_to_6d(refT @ rotations[..., 0, :, :]))
    return np.concatenate(parts, axis=-1)


@njit
def _put_6d(out, at, m) -> int:
    """matrix_to_6d(m) written into out at `at`; the index after it."""
    for c in range(2):
        for r in range(3):
            out[at + 3 * c + r] = m[r, c]
    return at + 6


@njit
def _frame_features(positions, rotations, previous_positions, previous_rotations, floor, pose):
    """features() of one frame, in the same order."""
    out = np.empty(FEATURES + POSE_FEATURES * pose)
    ref, ref_prev = mat3.yaw_frame(rotations[0]), mat3.yaw_frame(previous_rotations[0])
    root, root_prev = positions[0], previous_positions[0]
    out[0:3] = mat3.tvec(ref, root - root_prev)
    at = _put_6d(out, 3, mat3.tmul(ref_prev, ref))
    rel, q = np.empty((3, 3)), np.empty((3, 3, 3))
    for k in range(3):
        rel[k] = mat3.tvec(ref, positions[k + 1] - root)
        q[k] = mat3.tmul(ref, rotations[k + 1])
        q_prev = mat3.tmul(ref_prev, previous_rotations[k + 1])
        out[at : at + 3] = rel[k] - mat3.tvec(ref_prev, previous_positions[k + 1] - root_prev)
        at = _put_6d(out, at + 3, mat3.tmul(q_prev, q[k]))
    out[at] = root[2] - floor
    at += 1
    if pose:
        for k in range(3):
            out[at : at + 3] = rel[k]
            at = _put_6d(out, at + 3, q[k])
        _put_6d(out, at, mat3.tmul(ref, rotations[0]))
    return out


def sequence_features(
    positions: np.ndarray, rotations: np.ndarray, floor: float = 0.0, pose: bool = False
) -> np.ndarray:
    """(T, 37) or with pose (T, 70) for a sequence of tracked joints (T, 4, 3) / (T, 4, 3, 3);
    the first frame has zero velocity."""
    prev_p = np.concatenate([positions[:1], positions[:-1]])
    prev_r = np.concatenate([rotations[:1], rotations[:-1]])
    return features(positions, rotations, prev_p, prev_r, floor, pose)


def leg_targets(global_rot: np.ndarray, local_rot: np.ndarray) -> np.ndarray:
    """Training targets (..., 48) from a body's global and local rotations (..., 22, 3, 3)."""
    ref = reference_frames(global_rot[..., 0, :, :])
    out = local_rot[..., LEG_JOINTS, :, :].copy()
    out[..., :2, :, :] = np.swapaxes(ref, -1, -2)[..., None, :, :] @ global_rot[..., HIPS, :, :]
    return matrix_to_6d(out).reshape(out.shape[:-3] + (OUTPUTS,))


def upper_targets(local_rot: np.ndarray) -> np.ndarray:
    """Training targets (..., 78) of the learned upper body: its joints' local rotations."""
    out = local_rot[..., UPPER_JOINTS, :, :]
    return matrix_to_6d(out).reshape(out.shape[:-3] + (UPPER_OUTPUTS,))


@njit
def _replaced(local_rot, joints, output, hips_in_reference):
    """A copy of local_rot with joints' rotations from a 6D output; with hips_in_reference the
    first two (the hips) are in the reference frame (leg_targets) and turned into the pelvis's."""
    local = local_rot.copy()
    turned = mat3.sixd_matrices(output.reshape(len(joints), 6))
    for i in range(len(joints)):
        local[joints[i]] = turned[i]
    if hips_in_reference:
        pelvis_from_reference = mat3.tmul(local[0], mat3.yaw_frame(local[0]))
        for i in range(2):
            local[joints[i]] = mat3.mul(pelvis_from_reference, turned[i])
    return local


_UPPER_INDEX, _LEG_INDEX = np.array(UPPER_JOINTS, dtype=np.int64), np.array(LEG_JOINTS, dtype=np.int64)


def apply_upper(local_rot: np.ndarray, output: np.ndarray) -> np.ndarray:
    """A body's local rotations (22, 3, 3) with the upper body replaced by a network output (78,)."""
    c = np.ascontiguousarray
    return _replaced(c(local_rot, dtype=np.float64), _UPPER_INDEX, c(output, dtype=np.float64), False)


def apply_legs(local_rot: np.ndarray, output: np.ndarray) -> np.ndarray:
    """A body's local rotations (22, 3, 3) with the legs replaced by a network output (48,)."""
    c = np.ascontiguousarray
    return _replaced(c(local_rot, dtype=np.float64), _LEG_INDEX, c(output, dtype=np.float64), True)
