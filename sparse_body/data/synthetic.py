"""A short procedural walk on the canonical body: for tests and for the demo when no motion
capture is at hand. It is not real motion and is never used for training or metrics."""

from __future__ import annotations

import numpy as np

from ..core.kinematics import forward_kinematics
from ..core.rotations import euler_to_matrix, matrix_to_quat
from ..core.skeleton import JOINT_INDEX, NUM_JOINTS, Skeleton
from .motion import Motion

STRAIGHT = 40.0  # m walked straight before the walk turns round a circle
STANCE = 0.6  # share of a stride a foot stands on the floor (both stand for 0.1 of it, twice)
LIFT = 0.08  # m a swinging foot rises at mid-swing
SOLE = 0.03  # m from the ball-of-foot joint down to the sole: a standing foot's joint is this high
REACH = 0.97  # share of the straight leg's length the hip is above a foot below it (knees never lock)


def synthetic_walk(
    seconds: float = 4.0, fps: float = 60.0, skeleton: Skeleton | None = None, speed: float = 1.0, cadence: float = 0.9
) -> Motion:
    """Walk forward along +x at `speed` m/s and `cadence` strides a second. Each ankle follows
    a path under its hip (back along the floor while the foot stands, forward through the
    air while it swings), the legs reach it by two-link IK with the foot kept level, and the
    body is carried by the standing feet: a planted foot does not slide, so contacts and
    skate mean something. After STRAIGHT metres the walk turns onto a circle of that
    circumference and goes round it, so however long it is, it stays within 47 m of where
    it began (a 5-minute walk went 300 m away, beyond the default play space, and every
    estimate of it was refused)."""
    skeleton = skeleton or Skeleton.canonical()
    t = np.arange(int(round(seconds * fps))) / fps
    phase = 2 * np.pi * cadence * t
    rot = np.tile(np.eye(3), (len(t), NUM_JOINTS, 1, 1))

    def about(axis: str, angle):
        angles = np.zeros((len(t), 3))
        angles[:, "xyz".index(axis)] = angle
        return euler_to_matrix(angles, "xyz")

    offsets = skeleton.offsets
    thigh = float(np.linalg.norm(offsets[JOINT_INDEX["left_knee"]]))
    shank = float(np.linalg.norm(offsets[JOINT_INDEX["left_ankle"]]))
    step = speed / cadence * STANCE  # m an ankle travels back under its hip while it stands
    drop = np.sqrt((REACH * (thigh + shank)) ** 2 - (step / 2) ** 2)  # hip above the ankle
    standing = np.zeros((len(t), 2), bool)
    for leg, (side, sign) in enumerate((("left", 1.0), ("right", -1.0))):
        cycle = ((cadence * t) + (0.0 if leg == 0 else 0.5)) % 1.0  # 0: the foot comes down
        standing[:, leg] = cycle < STANCE
        stand_part, swing_part = cycle / STANCE, (cycle - STANCE) / (1 - STANCE)
        ahead = np.where(standing[:, leg], 0.5 - stand_part, -0.5 + _ease(swing_part)) * step
        up = np.where(standing[:, leg], 0.0, LIFT * np.sin(np.pi * np.clip(swing_part, 0, 1)))
        # two-link IK in the leg's plane: the knee bends forward, the shank back (+y turn)
        reach = np.hypot(ahead, drop - up)
        knee = np.pi - np.arccos(np.clip((thigh**2 + shank**2 - reach**2) / (2 * thigh * shank), -1, 1))
        inner = np.arccos(np.clip((thigh**2 + reach**2 - shank**2) / (2 * thigh * reach), -1, 1))
        hip = -(np.arctan2(ahead, drop - up) + inner)  # a -y turn swings the leg forward
        rot[:, JOINT_INDEX[f"{side}_hip"]] = about("y", hip)
        rot[:, JOINT_INDEX[f"{side}_knee"]] = about("y", knee)
        rot[:, JOINT_INDEX[f"{side}_ankle"]] = about("y", -(hip + knee))  # the foot level with the floor
        swing = sign * np.sin(phase)  # the arms swing against the legs
        lower = about("x", -sign * np.deg2rad(80))  # arms down from the T-pose
        rot[:, JOINT_INDEX[f"{side}_shoulder"]] = lower @ about("y", np.deg2rad(20) * swing)
        rot[:, JOINT_INDEX[f"{side}_elbow"]] = about("z", sign * np.deg2rad(15))
    rot[:, JOINT_INDEX["spine2"]] = about("z", np.deg2rad(4) * np.sin(phase))
    rot[:, JOINT_INDEX["head"]] = about("z", np.deg2rad(10) * np.sin(0.3 * phase))
    _, body = forward_kinematics(rot, np.zeros((len(t), 3)), offsets)  # root at the origin, facing +x
    balls = body[:, [JOINT_INDEX["left_foot"], JOINT_INDEX["right_foot"]]]
    root = np.zeros((len(t), 3))
    root[:, 2] = SOLE - balls[:, :, 2].min(axis=1)  # the standing feet on the floor
    radius = STRAIGHT / (2 * np.pi)
    heading, walked = np.zeros(len(t)), 0.0
    for k in range(1, len(t)):
        # a standing foot stays where it is: the root moves (and turns) around it
        heading[k] = max(walked - STRAIGHT, 0.0) / radius  # 0 on the straight, then round the circle
        leg = int(np.argmax(standing[k] & standing[k - 1])) if (standing[k] & standing[k - 1]).any() else 0
        before, now = _yaw(heading[k - 1]) @ balls[k - 1, leg], _yaw(heading[k]) @ balls[k, leg]
        root[k, :2] = root[k - 1, :2] + before[:2] - now[:2]
        walked += float(np.linalg.norm(root[k, :2] - root[k - 1, :2]))
    rot[:, 0] = about("z", heading) @ rot[:, 0]
    return Motion("synthetic_walk", fps, skeleton, matrix_to_quat(rot), root)


def _ease(x):
    """0 to 1 with zero speed at both ends: a swinging foot leaves and lands gently."""
    x = np.clip(x, 0.0, 1.0)
    return x - np.sin(2 * np.pi * x) / (2 * np.pi)


def _yaw(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
