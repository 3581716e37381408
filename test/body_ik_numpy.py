"""The parity reference of core/body_ik.py: the closed-form body IK as it was in numpy
(sparse_body 9209f2c), before its arithmetic was compiled. test_body_ik requires the
compiled solver to give the same poses within 1e-9; the documentation of the method is in
core/body_ik.py.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sparse_body.core.skeleton import JOINT_INDEX as J
from sparse_body.core.skeleton import NUM_JOINTS, PARENTS

# the numpy helpers as they were (core/rotations.py and core/kinematics.py at 9209f2c), so
# that the reference computes with none of the compiled kernels


def cross(a, b) -> np.ndarray:
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def about(axis, angle: float) -> np.ndarray:
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


def swing(a, b) -> np.ndarray:
    a, b = np.asarray(a, float), np.asarray(b, float)
    na, nb = math.sqrt(a @ a), math.sqrt(b @ b)
    if na < 1e-12 or nb < 1e-12:
        return np.eye(3)
    a, b = a / na, b / nb
    c = float(a @ b)
    if c < -1.0 + 1e-9:
        perp = cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        return about(perp / math.sqrt(perp @ perp), math.pi)
    k = cross(a, b)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + kx + (kx @ kx) / (1.0 + c)


def forward_kinematics(local_rot, root_pos, offsets):
    glob, pos = np.empty_like(local_rot), np.empty((NUM_JOINTS, 3))
    glob[0], pos[0] = local_rot[0], root_pos
    for j in range(1, NUM_JOINTS):
        p = PARENTS[j]
        glob[j] = glob[p] @ local_rot[j]
        pos[j] = pos[p] + glob[p] @ offsets[j]
    return glob, pos


X, Y, Z = np.eye(3)


@dataclass(frozen=True)
class Limb:
    upper: int  # ball joint (shoulder, hip)
    hinge: int  # elbow, knee
    axis: np.ndarray  # the hinge's local axis
    limits: tuple[float, float]
    end: int  # wrist, ankle


LIMBS = {
    J["left_wrist"]: Limb(J["left_shoulder"], J["left_elbow"], Z, (-2.7, 0.0), J["left_wrist"]),
    J["right_wrist"]: Limb(J["right_shoulder"], J["right_elbow"], Z, (0.0, 2.7), J["right_wrist"]),
    J["left_ankle"]: Limb(J["left_hip"], J["left_knee"], Y, (0.0, 2.6), J["left_ankle"]),
    J["right_ankle"]: Limb(J["right_hip"], J["right_knee"], Y, (0.0, 2.6), J["right_ankle"]),
}
_FOOT_OF = {J["left_ankle"]: J["left_foot"], J["right_ankle"]: J["right_foot"]}  # hangs below the limb's end
_ARMS = (J["left_wrist"], J["right_wrist"])
SPINE_BEND = (J["spine2"], J["spine3"], J["neck"])
MAX_BEND = 0.6  # radians per spine joint: about 100 degrees over the three
# Near full extension the bend that gives a length changes like the square root of what is
# missing: a millimetre of tracker noise swings a nearly straight knee, elbow or spine by
# degrees. Within SOFT_REACH of the full length the solvers aim for a length that approaches
# it smoothly instead (soft IK): the end falls short by at most 0.63 * SOFT_REACH there.
SOFT_REACH = 0.01


def soft_distance(distance: float, full: float, soft: float = SOFT_REACH) -> float:
    """As in core/body_ik.py."""
    start = full - soft
    if soft <= 0 or distance <= start:
        return distance
    return start + soft * (1.0 - math.exp(-(distance - start) / soft))


def hinge_angle(m: np.ndarray, axis: np.ndarray) -> float:
    """As in core/body_ik.py."""
    i = int(np.argmax(axis))
    j, k = (i + 1) % 3, (i + 2) % 3
    return float(math.atan2(m[k, j], m[j, j]))


def reach_angle(a, w, axis, distance: float, current: float, limits: tuple[float, float] | None) -> float:
    """As in core/body_ik.py."""
    ax, ay, az = (float(v) for v in a)
    wx, wy, wz = (float(v) for v in w)
    kx, ky, kz = (float(v) for v in axis)
    along = kx * wx + ky * wy + kz * wz
    px, py, pz = wx - kx * along, wy - ky * along, wz - kz * along  # w across the axis
    A = ax * px + ay * py + az * pz
    B = ax * (ky * pz - kz * py) + ay * (kz * px - kx * pz) + az * (kx * py - ky * px)  # a . (k x p)
    fixed = ax * ax + ay * ay + az * az + wx * wx + wy * wy + wz * wz + 2 * (ax * kx + ay * ky + az * kz) * along
    C = math.hypot(A, B)
    if C < 1e-12:
        return current if limits is None else min(max(current, limits[0]), limits[1])
    phi, spread = math.atan2(B, A), math.acos(min(1.0, max(-1.0, 0.5 * (distance * distance - fixed) / C)))
    best, best_key = current, None
    for t in (phi + spread, phi - spread):
        t = math.remainder(t, 2 * math.pi)
        if limits is not None:
            t = min(max(t, limits[0]), limits[1])
        miss = abs(math.sqrt(max(0.0, fixed + 2 * (A * math.cos(t) + B * math.sin(t)))) - distance)
        key = (round(miss, 5), abs(t - current))
        if best_key is None or key < best_key:
            best, best_key = t, key
    return best


def reach(
    local: np.ndarray,
    parent_rot: np.ndarray,
    upper_pos: np.ndarray,
    offsets: np.ndarray,
    limb: Limb,
    target: np.ndarray,
    end_vector: np.ndarray | None = None,
    exact_hinge: bool = True,
):
    """As in core/body_ik.py."""
    u, h = limb.upper, limb.hinge
    w = offsets[limb.end] if end_vector is None else end_vector
    a = offsets[h]
    distance = soft_distance(float(np.linalg.norm(target - upper_pos)), float(np.linalg.norm(a) + np.linalg.norm(w)))
    if not exact_hinge:  # solve in the hinge's own frame: |L_h^T a + R(t) w|
        base = local[h]
        turned = base @ about(limb.axis, reach_angle(base.T @ a, w, limb.axis, distance, 0.0, None))
        exact_hinge = abs(float(np.linalg.norm(a + turned @ w)) - distance) > 0.005
        local[h] = turned
    if exact_hinge:
        angle = reach_angle(a, w, limb.axis, distance, hinge_angle(local[h], limb.axis), limb.limits)
        local[h] = about(limb.axis, angle)
    upper_rot = parent_rot @ local[u]
    upper_rot = swing(upper_rot @ (a + local[h] @ w), target - upper_pos) @ upper_rot
    local[u] = parent_rot.T @ upper_rot
    return upper_rot, upper_rot @ local[h]


# metres: how far short or long of the headset a kept spine curve may leave the head
KEEP_BEND_TOLERANCE = 0.005


def fit_spine(
    local: np.ndarray,
    root: np.ndarray,
    offsets: np.ndarray,
    head_target: np.ndarray,
    keep_bend: bool = False,
    tolerance: float = KEEP_BEND_TOLERANCE,
) -> None:
    """As in core/body_ik.py."""
    pelvis = local[0]
    s1 = J["spine1"]
    s1_pos = root + pelvis @ offsets[s1]
    to_target = head_target - s1_pos
    if keep_bend:
        b = [local[j] for j in SPINE_BEND]
        head_vector = offsets[SPINE_BEND[0]] + b[0] @ (
            offsets[SPINE_BEND[1]] + b[1] @ (offsets[SPINE_BEND[2]] + b[2] @ offsets[J["head"]])
        )
        if abs(math.sqrt(head_vector @ head_vector) - math.sqrt(to_target @ to_target)) < tolerance:
            s1_rot = pelvis @ local[s1]
            local[s1] = pelvis.T @ swing(s1_rot @ head_vector, to_target) @ s1_rot
            return
    distance = math.sqrt(to_target @ to_target)
    # the bend plane is spine1's x-z plane; in it a rotation about y is a complex product
    chain = [offsets[j] for j in SPINE_BEND] + [offsets[J["head"]]]
    xz = [complex(o[2], o[0]) for o in chain]
    lateral = sum(o[1] for o in chain)

    def length(beta: float) -> float:
        e, h = complex(math.cos(beta), math.sin(beta)), 0j
        for w in reversed(xz[1:]):
            h = e * (w + h)
        h += xz[0]
        return math.sqrt(abs(h) ** 2 + lateral * lateral)

    distance = soft_distance(distance, length(0.0))
    forward = float((pelvis @ local[s1]).T[0] @ to_target) >= 0.0  # lean direction in spine1's frame
    limit = MAX_BEND if forward else -MAX_BEND
    lo, hi = 0.0, limit
    if distance >= length(0.0):
        beta = 0.0
    elif distance <= length(limit):
        beta = limit
    else:
        for _ in range(18):  # |head - spine1| shrinks monotonically as the bend grows
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if length(mid) > distance else (lo, mid)
        beta = 0.5 * (lo + hi)
    bend = about(Y, beta)
    for j in SPINE_BEND:
        local[j] = bend
    head_vector = offsets[SPINE_BEND[0]] + bend @ (
        offsets[SPINE_BEND[1]] + bend @ (offsets[SPINE_BEND[2]] + bend @ offsets[J["head"]])
    )
    s1_rot = pelvis @ local[s1]
    local[s1] = pelvis.T @ swing(s1_rot @ head_vector, to_target) @ s1_rot


def _collar_towards(local, glob, pos, offsets, limb: Limb, target: np.ndarray) -> None:
    """As in core/body_ik.py."""
    length = math.sqrt(offsets[limb.hinge] @ offsets[limb.hinge]) + math.sqrt(offsets[limb.end] @ offsets[limb.end])
    to_target = target - pos[limb.upper]
    distance = math.sqrt(to_target @ to_target)
    if distance <= length:
        return
    collar = PARENTS[limb.upper]
    stretched = pos[limb.upper] + to_target * (length / distance)
    glob[collar] = swing(stretched - pos[collar], target - pos[collar]) @ glob[collar]
    local[collar] = glob[PARENTS[collar]].T @ glob[collar]
    pos[limb.upper] = pos[collar] + glob[collar] @ offsets[limb.upper]
    glob[limb.upper] = glob[collar] @ local[limb.upper]


def _collar_within_reach(local, glob, pos, offsets, limb: Limb, target: np.ndarray) -> None:
    """As in core/body_ik.py."""
    length = math.sqrt(offsets[limb.hinge] @ offsets[limb.hinge]) + math.sqrt(offsets[limb.end] @ offsets[limb.end])
    to_target = target - pos[limb.upper]
    if math.sqrt(to_target @ to_target) <= length - 1.5 * SOFT_REACH:
        return
    collar = PARENTS[limb.upper]
    arm, goal = pos[limb.upper] - pos[collar], target - pos[collar]
    r, d = math.sqrt(arm @ arm), math.sqrt(goal @ goal)
    axis = cross(arm, goal)
    sin_now = math.sqrt(axis @ axis)
    if r < 1e-9 or d < 1e-9 or sin_now < 1e-12:
        return
    now = math.atan2(sin_now, float(arm @ goal))  # the angle between arm and goal
    reach_length = length - 1.5 * SOFT_REACH
    cos_wanted = (r * r + d * d - reach_length * reach_length) / (2 * r * d)
    wanted = math.acos(min(1.0, max(-1.0, cos_wanted)))
    if wanted >= now:
        return
    glob[collar] = about(axis / math.sqrt(axis @ axis), now - wanted) @ glob[collar]
    local[collar] = glob[PARENTS[collar]].T @ glob[collar]
    pos[limb.upper] = pos[collar] + glob[collar] @ offsets[limb.upper]
    glob[limb.upper] = glob[collar] @ local[limb.upper]


def solve_body(
    local: np.ndarray,
    root: np.ndarray,
    offsets: np.ndarray,
    targets: dict[int, np.ndarray],
    keep_shape: bool = False,
    spine_tolerance: float = KEEP_BEND_TOLERANCE,
):
    """As in core/body_ik.py."""
    local = local.copy()
    head = targets.get(J["head"])
    if head is not None:
        fit_spine(local, root, offsets, head, keep_bend=keep_shape, tolerance=spine_tolerance)
    glob, pos = forward_kinematics(local, root, offsets)
    for end, target in targets.items():
        limb = LIMBS.get(end)
        if limb is None:
            continue
        if end in _ARMS:
            # the IK baseline keeps its single turn (its figures are every comparison's bar)
            (_collar_within_reach if keep_shape else _collar_towards)(local, glob, pos, offsets, limb, target)
        upper, hinge = reach(
            local, glob[PARENTS[limb.upper]], pos[limb.upper], offsets, limb, target, exact_hinge=not keep_shape
        )
        # the limbs are independent: update only what this one moved
        glob[limb.upper], glob[limb.hinge], glob[end] = upper, hinge, hinge @ local[end]
        pos[limb.hinge] = pos[limb.upper] + upper @ offsets[limb.hinge]
        pos[end] = pos[limb.hinge] + hinge @ offsets[end]
        foot = _FOOT_OF.get(end)
        if foot is not None:
            glob[foot] = glob[end] @ local[foot]
            pos[foot] = pos[end] + glob[end] @ offsets[foot]
    return local, glob, pos
