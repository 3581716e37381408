"""Closed-form IK for the 22-joint body: two-bone limbs and a one-parameter spine fit.

One solver for every estimator (the `ik` baseline, LoBSTr's upper body and contact hold,
DragPoser's polish). Each frame costs a fixed, small amount of arithmetic; nothing iterates
on the whole body:

- A limb (shoulder-elbow-wrist, hip-knee-ankle, or hip-knee-toe with the ankle held) is a
  ball joint and a hinge. The hinge angle that makes the limb as long as the distance to
  the target follows from the law of cosines (in a form that allows bones that are not
  collinear, as retargeted skeletons have); the ball joint then turns by the smallest
  rotation that points the limb at the target. That smallest rotation keeps the limb's
  swivel (where the elbow or knee points) from the previous pose.
- The spine (spine1 .. neck under a tracked pelvis) bends forward or back by the same angle
  at spine2, spine3 and neck until the pelvis-to-head distance is right (a 1-D monotone
  search in complex arithmetic, no matrices), then spine1 turns to point it at the head.

The arithmetic is compiled (numba, core/mat3.py): a frame is a few hundred 3-vector and
3x3 operations, and as numpy calls each cost a microsecond of dispatch, more than the
arithmetic (issue 28's profile: 1,300 calls a step). The functions below without a
leading underscore are the Python interface; the `_` kernels take arrays and joint indices.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import mat3
from .mat3 import njit
from .skeleton import JOINT_INDEX as J
from .skeleton import NUM_JOINTS, PARENTS

X, Y, Z = np.eye(3)
_PARENTS = np.array(PARENTS, dtype=np.int64)
_ALL_BUT_ROOT = np.arange(1, NUM_JOINTS)


@dataclass(frozen=True)
class Limb:
    upper: int  # ball joint (shoulder, hip)
    hinge: int  # elbow, knee
    axis: np.ndarray  # the hinge's local axis
    limits: tuple[float, float]
    end: int  # wrist, ankle

    @property
    def axis_index(self) -> int:
        return int(np.argmax(self.axis))


LIMBS = {
    J["left_wrist"]: Limb(J["left_shoulder"], J["left_elbow"], Z, (-2.7, 0.0), J["left_wrist"]),
    J["right_wrist"]: Limb(J["right_shoulder"], J["right_elbow"], Z, (0.0, 2.7), J["right_wrist"]),
    J["left_ankle"]: Limb(J["left_hip"], J["left_knee"], Y, (0.0, 2.6), J["left_ankle"]),
    J["right_ankle"]: Limb(J["right_hip"], J["right_knee"], Y, (0.0, 2.6), J["right_ankle"]),
}
_FOOT_OF = {J["left_ankle"]: J["left_foot"], J["right_ankle"]: J["right_foot"]}  # hangs below the limb's end
_ARMS = (J["left_wrist"], J["right_wrist"])


def _limb_row(limb: Limb) -> tuple[int, ...]:
    """A limb for the kernels: (ball joint, hinge, end, axis index, foot below the end or -1,
    1 for an arm)."""
    return (limb.upper, limb.hinge, limb.end, limb.axis_index, _FOOT_OF.get(limb.end, -1), int(limb.end in _ARMS))


_LIMB_JOINTS = np.array([_limb_row(limb) for limb in LIMBS.values()], dtype=np.int64)
_LIMB_LIMITS = np.array([limb.limits for limb in LIMBS.values()])
SPINE_BEND = (J["spine2"], J["spine3"], J["neck"])
_SPINE = np.array([J["spine1"], *SPINE_BEND, J["head"]], dtype=np.int64)
MAX_BEND = 0.6  # radians per spine joint: about 100 degrees over the three
# Near full extension the bend that gives a length changes like the square root of what is
# missing: a millimetre of tracker noise swings a nearly straight knee, elbow or spine by
# degrees. Within SOFT_REACH of the full length the solvers aim for a length that approaches
# it smoothly instead (soft IK): the end falls short by at most 0.63 * SOFT_REACH there.
SOFT_REACH = 0.01
# metres: how far short or long of the headset a kept spine curve may leave the head
KEEP_BEND_TOLERANCE = 0.005


@njit
def soft_distance(distance: float, full: float, soft: float = SOFT_REACH) -> float:
    """The length to solve for: distance itself up to full - soft, then easing towards full."""
    start = full - soft
    if soft <= 0 or distance <= start:
        return distance
    return start + soft * (1.0 - math.exp(-(distance - start) / soft))


@njit
def _hinge_angle(m, i: int) -> float:
    j, k = (i + 1) % 3, (i + 2) % 3
    return math.atan2(m[k, j], m[j, j])


def hinge_angle(m: np.ndarray, axis: np.ndarray) -> float:
    """The angle of m about a coordinate axis (exact when m is a rotation about it)."""
    return _hinge_angle(np.ascontiguousarray(m, float), int(np.argmax(axis)))


@njit
def _reach_angle(a, w, k, distance, current, limited, low, high) -> float:
    ax, ay, az = a[0], a[1], a[2]
    wx, wy, wz = w[0], w[1], w[2]
    kx, ky, kz = k[0], k[1], k[2]
    along = kx * wx + ky * wy + kz * wz
    px, py, pz = wx - kx * along, wy - ky * along, wz - kz * along  # w across the axis
    A = ax * px + ay * py + az * pz
    B = ax * (ky * pz - kz * py) + ay * (kz * px - kx * pz) + az * (kx * py - ky * px)  # a . (k x p)
    fixed = ax * ax + ay * ay + az * az + wx * wx + wy * wy + wz * wz + 2 * (ax * kx + ay * ky + az * kz) * along
    C = math.hypot(A, B)
    if C < 1e-12:
        return min(max(current, low), high) if limited else current
    phi = math.atan2(B, A)
    spread = math.acos(min(1.0, max(-1.0, 0.5 * (distance * distance - fixed) / C)))
    best, best_miss, best_turn = current, math.inf, math.inf
    for t in (phi + spread, phi - spread):
        t = t - 2 * math.pi * np.rint(t / (2 * math.pi))  # math.remainder(t, 2 pi)
        if limited:
            t = min(max(t, low), high)
        miss = round(abs(math.sqrt(max(0.0, fixed + 2 * (A * math.cos(t) + B * math.sin(t)))) - distance), 5)
        turn = abs(t - current)
        if miss < best_miss or (miss == best_miss and turn < best_turn):  # nearest length, then nearest angle
            best, best_miss, best_turn = t, miss, turn
    return best


def reach_angle(a, w, axis, distance: float, current: float, limits: tuple[float, float] | None) -> float:
    """The hinge angle t with |a + R(axis, t) w| = distance, or the nearest reachable.

    a: ball joint to hinge, w: hinge to end (in the hinge's frame at angle 0), both in the
    ball joint's frame. Of the two solutions the one within the limits, nearest the current
    angle, wins."""
    low, high = limits if limits is not None else (-math.inf, math.inf)
    f = np.ascontiguousarray  # the kernels are compiled for contiguous arrays: one signature
    return _reach_angle(f(a, float), f(w, float), f(axis, float), distance, current, limits is not None, low, high)


@njit
def _reach(local, parent_rot, upper_pos, offsets, limb, low, high, target, w, exact_hinge):
    """reach() on a row of _LIMB_JOINTS; returns the global rotations of ball joint and hinge."""
    u, h, axis_index = limb[0], limb[1], limb[3]
    axis = np.zeros(3)
    axis[axis_index] = 1.0
    a = offsets[h]
    distance = soft_distance(mat3.norm(target - upper_pos), mat3.norm(a) + mat3.norm(w), SOFT_REACH)
    if not exact_hinge:  # solve in the hinge's own frame: |L_h^T a + R(t) w|
        base = local[h].copy()
        t = _reach_angle(mat3.tvec(base, a), w, axis, distance, 0.0, False, 0.0, 0.0)
        turned = mat3.mul(base, mat3.about(axis, t))
        exact_hinge = abs(mat3.norm(a + mat3.vec(turned, w)) - distance) > 0.005
        local[h] = turned
    if exact_hinge:
        angle = _reach_angle(a, w, axis, distance, _hinge_angle(local[h], axis_index), True, low, high)
        local[h] = mat3.about(axis, angle)
    upper_rot = mat3.mul(parent_rot, local[u])
    pointing = mat3.vec(upper_rot, a + mat3.vec(local[h], w))
    upper_rot = mat3.mul(mat3.between(pointing, target - upper_pos), upper_rot)
    local[u] = mat3.tmul(parent_rot, upper_rot)
    return upper_rot, mat3.mul(upper_rot, local[h])


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
    """Turn the limb's ball joint and hinge (in place in local) so that its end reaches target.

    parent_rot: global rotation of the ball joint's parent; upper_pos: the ball joint's
    position. end_vector: the hinge-to-end vector in the hinge's frame (default the end
    joint's offset; the toe's for a foot held on its toe). exact_hinge: the hinge becomes a
    rotation about its axis within its limits (the IK's model of an elbow or knee); else the
    hinge keeps its other components and only turns about its axis (a decoded pose), unless
    so turned it cannot make the limb long or short enough (within 5 mm).
    Returns the new global rotations of the ball joint and of the hinge."""
    w = offsets[limb.end] if end_vector is None else end_vector
    f = np.ascontiguousarray  # the kernels are compiled for contiguous arrays: one signature
    return _reach(
        local,
        f(parent_rot, float),
        f(upper_pos, float),
        f(offsets, float),
        np.array(_limb_row(limb), dtype=np.int64),
        limb.limits[0],
        limb.limits[1],
        f(target, float),
        f(w, float),
        exact_hinge,
    )


@njit
def _spine_length(beta: float, xz, lateral: float) -> float:
    """|head - spine1| with spine2, spine3 and neck each bent by beta about y (xz: the chain's
    offsets in the bend plane as complex numbers)."""
    e, h = complex(math.cos(beta), math.sin(beta)), 0j
    for i in range(len(xz) - 1, 0, -1):
        h = e * (xz[i] + h)
    h += xz[0]
    return math.sqrt(abs(h) ** 2 + lateral * lateral)


@njit
def _head_vector(local, offsets):
    """spine1 to head in spine1's frame, through the spine's current curve."""
    v = offsets[_SPINE[4]].copy()
    for i in range(3, 0, -1):
        v = offsets[_SPINE[i]] + mat3.vec(local[_SPINE[i]], v)
    return v


@njit
def _fit_spine(local, root, offsets, head_target, keep_bend, tolerance) -> None:
    pelvis = local[0]
    s1 = _SPINE[0]
    to_target = head_target - (root + mat3.vec(pelvis, offsets[s1]))
    distance = mat3.norm(to_target)
    if keep_bend:
        head_vector = _head_vector(local, offsets)
        if abs(mat3.norm(head_vector) - distance) < tolerance:
            s1_rot = mat3.mul(pelvis, local[s1])
            turn = mat3.between(mat3.vec(s1_rot, head_vector), to_target)
            local[s1] = mat3.tmul(pelvis, mat3.mul(turn, s1_rot))
            return
    # the bend plane is spine1's x-z plane; in it a rotation about y is a complex product
    xz = np.empty(4, dtype=np.complex128)
    lateral = 0.0
    for i in range(4):
        o = offsets[_SPINE[i + 1]]
        xz[i] = complex(o[2], o[0])
        lateral += o[1]
    straight = _spine_length(0.0, xz, lateral)
    distance = soft_distance(distance, straight, SOFT_REACH)
    s1_rot = mat3.mul(pelvis, local[s1])
    lean = s1_rot[0, 0] * to_target[0] + s1_rot[1, 0] * to_target[1] + s1_rot[2, 0] * to_target[2]
    limit = MAX_BEND if lean >= 0.0 else -MAX_BEND  # lean direction in spine1's frame
    lo, hi = 0.0, limit
    if distance >= straight:
        beta = 0.0
    elif distance <= _spine_length(limit, xz, lateral):
        beta = limit
    else:
        for _ in range(18):  # |head - spine1| shrinks monotonically as the bend grows
            mid = 0.5 * (lo + hi)
            if _spine_length(mid, xz, lateral) > distance:
                lo = mid
            else:
                hi = mid
        beta = 0.5 * (lo + hi)
    bend = mat3.about(np.array([0.0, 1.0, 0.0]), beta)
    for i in range(1, 4):
        local[_SPINE[i]] = bend
    head_vector = _head_vector(local, offsets)
    turn = mat3.between(mat3.vec(s1_rot, head_vector), to_target)
    local[s1] = mat3.tmul(pelvis, mat3.mul(turn, s1_rot))


def fit_spine(
    local: np.ndarray,
    root: np.ndarray,
    offsets: np.ndarray,
    head_target: np.ndarray,
    keep_bend: bool = False,
    tolerance: float = KEEP_BEND_TOLERANCE,
) -> None:
    """Bend and turn the spine (in place in local) so that the head joint reaches head_target,
    the pelvis (local[0], root) staying where it is. keep_bend: only turn the spine as it is
    curved (a decoded pose), unless that curve leaves the head more than tolerance short or
    long; then it is bent anew, uniformly. A curve that changes every frame crosses that
    line often, and the spine flips between the two (jitter): a wider tolerance trades
    millimetres at the head for a calmer spine."""
    f = np.ascontiguousarray  # the kernels are compiled for contiguous arrays: one signature
    _fit_spine(local, f(root, float), f(offsets, float), f(head_target, float), keep_bend, float(tolerance))


@njit
def _turn_collar(local, glob, pos, offsets, upper, turn) -> None:
    """Turn the collar above a shoulder by turn (global) and carry the shoulder along."""
    collar = _PARENTS[upper]
    glob[collar] = mat3.mul(turn, glob[collar])
    local[collar] = mat3.tmul(glob[_PARENTS[collar]], glob[collar])
    pos[upper] = pos[collar] + mat3.vec(glob[collar], offsets[upper])
    glob[upper] = mat3.mul(glob[collar], local[upper])


@njit
def _collar_towards(local, glob, pos, offsets, limb, target) -> None:
    """A hand beyond the arm's reach: the collar turns the shoulder towards it (in place),
    as far as puts the stretched arm's end on the line from the collar to the target."""
    upper = limb[0]
    length = mat3.norm(offsets[limb[1]]) + mat3.norm(offsets[limb[2]])
    to_target = target - pos[upper]
    distance = mat3.norm(to_target)
    if distance <= length:
        return
    collar = _PARENTS[upper]
    stretched = pos[upper] + to_target * (length / distance)
    _turn_collar(local, glob, pos, offsets, upper, mat3.between(stretched - pos[collar], target - pos[collar]))


@njit
def _collar_within_reach(local, glob, pos, offsets, limb, target) -> None:
    """A hand beyond the arm's reach from a predicted torso: the collar turns the shoulder (in
    place) by the smallest rotation that brings it within reach, SOFT_REACH and a half inside
    the stretched arm's length where the soft reach still lands exactly (or as near as the
    collar can). A network's shoulder is often a few centimetres off; _collar_towards' single
    turn then leaves a hanging arm's hand short by 2-5 cm in a third of the frames (LoBSTr's
    learned upper body, validation people)."""
    upper = limb[0]
    length = mat3.norm(offsets[limb[1]]) + mat3.norm(offsets[limb[2]])
    if mat3.norm(target - pos[upper]) <= length - 1.5 * SOFT_REACH:
        return
    collar = _PARENTS[upper]
    arm, goal = pos[upper] - pos[collar], target - pos[collar]
    r, d = mat3.norm(arm), mat3.norm(goal)
    axis = mat3.cross(arm, goal)
    sin_now = mat3.norm(axis)
    if r < 1e-9 or d < 1e-9 or sin_now < 1e-12:
        return
    now = math.atan2(sin_now, arm[0] * goal[0] + arm[1] * goal[1] + arm[2] * goal[2])  # between arm and goal
    reach_length = length - 1.5 * SOFT_REACH
    cos_wanted = (r * r + d * d - reach_length * reach_length) / (2 * r * d)
    wanted = math.acos(min(1.0, max(-1.0, cos_wanted)))
    if wanted >= now:
        return
    _turn_collar(local, glob, pos, offsets, upper, mat3.about(axis / sin_now, now - wanted))


@njit
def _solve_body(local, root, offsets, goals, has_goal, keep_shape, spine_tolerance):
    local = local.copy()
    if has_goal[_SPINE[4]]:
        _fit_spine(local, root, offsets, goals[_SPINE[4]], keep_shape, spine_tolerance)
    glob = np.empty_like(local)
    pos = np.empty((NUM_JOINTS, 3))
    mat3.forward_kinematics_into(local, root, offsets, _PARENTS, _ALL_BUT_ROOT, glob, pos)
    for row in range(len(_LIMB_JOINTS)):
        limb = _LIMB_JOINTS[row]
        upper, hinge, end, foot = limb[0], limb[1], limb[2], limb[4]
        if not has_goal[end]:
            continue
        target = goals[end]
        if limb[5] == 1:  # the IK baseline keeps its single turn (its figures are every comparison's bar)
            if keep_shape:
                _collar_within_reach(local, glob, pos, offsets, limb, target)
            else:
                _collar_towards(local, glob, pos, offsets, limb, target)
        upper_rot, hinge_rot = _reach(
            local,
            glob[_PARENTS[upper]],
            pos[upper],
            offsets,
            limb,
            _LIMB_LIMITS[row, 0],
            _LIMB_LIMITS[row, 1],
            target,
            offsets[end],
            not keep_shape,
        )
        # the limbs are independent: update only what this one moved
        glob[upper], glob[hinge], glob[end] = upper_rot, hinge_rot, mat3.mul(hinge_rot, local[end])
        pos[hinge] = pos[upper] + mat3.vec(upper_rot, offsets[hinge])
        pos[end] = pos[hinge] + mat3.vec(hinge_rot, offsets[end])
        if foot >= 0:
            glob[foot] = mat3.mul(glob[end], local[foot])
            pos[foot] = pos[end] + mat3.vec(glob[end], offsets[foot])
    return local, glob, pos


def solve_body(
    local: np.ndarray,
    root: np.ndarray,
    offsets: np.ndarray,
    targets: dict[int, np.ndarray],
    keep_shape: bool = False,
    spine_tolerance: float = KEEP_BEND_TOLERANCE,
):
    """A copy of local (22, 3, 3) with the spine fitted to a head target and each limb with
    a target (wrist or ankle joint index -> position) reaching it. The root stays.
    keep_shape: the pose's own spine curve, elbows and knees are kept and only turned (a
    decoded pose; the curve while it leaves the head within spine_tolerance, fit_spine);
    else elbows and knees are exact hinges within their limits.
    Returns (local, global rotations, positions) of the solved pose."""
    goals = np.zeros((NUM_JOINTS, 3))
    has_goal = np.zeros(NUM_JOINTS, dtype=np.bool_)
    for joint, target in targets.items():
        goals[joint], has_goal[joint] = target, True
    f = np.ascontiguousarray  # the kernels are compiled for contiguous arrays: one signature
    return _solve_body(
        f(local, float), f(root, float), f(offsets, float), goals, has_goal, keep_shape, float(spine_tolerance)
    )
