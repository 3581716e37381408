"""Retargeting a source skeleton's motion onto the 22-joint body.

Each body joint takes its position from one source joint and its rotation from another
(usually the same). The maps are chosen so that every body bone is rigid in the source
too: a child's position is its parent's position plus the parent's rotation times a fixed
offset. Forward kinematics of the body then reproduces the source positions of the mapped
joints (test_retarget checks < 1 cm on CMU clips), with the subject's own bone lengths.
Where the CMU skeleton has no joint for an SMPL one, the body joint sits on a neighbour:
spine1 on the pelvis (CMU's lower back starts at the root), the collars where the clavicles
start, and the head joint at the middle of the neck (its rotation is the skull's).

After mapping, each joint's rotation is re-based so that identity is the canonical T-pose
(legs straight down, arms along +-y, facing +x), whatever rest pose the source used.
"""

from __future__ import annotations

import numpy as np

from ..core.kinematics import forward_kinematics
from ..core.rotations import matrix_to_quat, rotation_between, yaw_matrix
from ..core.skeleton import JOINT_INDEX, JOINT_NAMES, NUM_JOINTS, PARENTS, Skeleton
from .motion import Motion
from .source import SourceMotion

# body joint -> (source joint for the position, source joint for the rotation)
JOINT_MAPS: dict[str, dict[str, tuple[str, str]]] = {
    "cmu_asf": {
        "pelvis": ("root", "root"),
        "left_hip": ("lfemur", "lfemur"),
        "right_hip": ("rfemur", "rfemur"),
        "spine1": ("lowerback", "lowerback"),
        "left_knee": ("ltibia", "ltibia"),
        "right_knee": ("rtibia", "rtibia"),
        "spine2": ("upperback", "upperback"),
        "left_ankle": ("lfoot", "lfoot"),
        "right_ankle": ("rfoot", "rfoot"),
        "spine3": ("thorax", "thorax"),
        "left_foot": ("ltoes", "ltoes"),
        "right_foot": ("rtoes", "rtoes"),
        "neck": ("lowerneck", "lowerneck"),
        "left_collar": ("lclavicle", "lclavicle"),
        "right_collar": ("rclavicle", "rclavicle"),
        "head": ("upperneck", "head"),
        "left_shoulder": ("lhumerus", "lhumerus"),
        "right_shoulder": ("rhumerus", "rhumerus"),
        "left_elbow": ("lradius", "lradius"),
        "right_elbow": ("rradius", "rradius"),
        "left_wrist": ("lwrist", "lhand"),
        "right_wrist": ("rwrist", "rhand"),
    },
    "cmu_bvh_mb2": {
        "pelvis": ("Hips", "Hips"),
        "left_hip": ("LeftUpLeg", "LeftUpLeg"),
        "right_hip": ("RightUpLeg", "RightUpLeg"),
        "spine1": ("LowerBack", "LowerBack"),
        "left_knee": ("LeftLeg", "LeftLeg"),
        "right_knee": ("RightLeg", "RightLeg"),
        "spine2": ("Spine", "Spine"),
        "left_ankle": ("LeftFoot", "LeftFoot"),
        "right_ankle": ("RightFoot", "RightFoot"),
        "spine3": ("Spine1", "Spine1"),
        "left_foot": ("LeftToeBase", "LeftToeBase"),
        "right_foot": ("RightToeBase", "RightToeBase"),
        "neck": ("Neck", "Neck"),
        "left_collar": ("LeftShoulder", "LeftShoulder"),
        "right_collar": ("RightShoulder", "RightShoulder"),
        "head": ("Neck1", "Head"),
        "left_shoulder": ("LeftArm", "LeftArm"),
        "right_shoulder": ("RightArm", "RightArm"),
        "left_elbow": ("LeftForeArm", "LeftForeArm"),
        "right_elbow": ("RightForeArm", "RightForeArm"),
        "left_wrist": ("LeftHand", "LeftHand"),
        "right_wrist": ("RightHand", "RightHand"),
    },
    "cmu_bvh_max": {
        "pelvis": ("Hips", "Hips"),
        "left_hip": ("LeftHip", "LeftHip"),
        "right_hip": ("RightHip", "RightHip"),
        "spine1": ("lowerback", "lowerback"),
        "left_knee": ("LeftKnee", "LeftKnee"),
        "right_knee": ("RightKnee", "RightKnee"),
        "spine2": ("Chest", "Chest"),
        "left_ankle": ("LeftAnkle", "LeftAnkle"),
        "right_ankle": ("RightAnkle", "RightAnkle"),
        "spine3": ("Chest2", "Chest2"),
        "left_foot": ("LeftToe", "LeftToe"),
        "right_foot": ("RightToe", "RightToe"),
        "neck": ("lowerneck", "lowerneck"),
        "left_collar": ("LeftCollar", "LeftCollar"),
        "right_collar": ("RightCollar", "RightCollar"),
        "head": ("Neck", "Head"),
        "left_shoulder": ("LeftShoulder", "LeftShoulder"),
        "right_shoulder": ("RightShoulder", "RightShoulder"),
        "left_elbow": ("LeftElbow", "LeftElbow"),
        "right_elbow": ("RightElbow", "RightElbow"),
        "left_wrist": ("LeftWrist", "lhand"),
        "right_wrist": ("RightWrist", "rhand"),
    },
    # Daz figures have one joint fewer in the spine: spine2 sits where the chest starts and
    # turns with the abdomen. Their feet end in an End Site, used as the ball of the foot.
    "cmu_bvh_daz": {
        "pelvis": ("hip", "hip"),
        "left_hip": ("lThigh", "lThigh"),
        "right_hip": ("rThigh", "rThigh"),
        "spine1": ("abdomen", "abdomen"),
        "left_knee": ("lShin", "lShin"),
        "right_knee": ("rShin", "rShin"),
        "spine2": ("chest", "abdomen"),
        "left_ankle": ("lFoot", "lFoot"),
        "right_ankle": ("rFoot", "rFoot"),
        "spine3": ("chest", "chest"),
        "left_foot": ("lFoot_End", "lFoot"),
        "right_foot": ("rFoot_End", "rFoot"),
        "neck": ("neck", "neck"),
        "left_collar": ("lCollar", "lCollar"),
        "right_collar": ("rCollar", "rCollar"),
        "head": ("head", "head"),
        "left_shoulder": ("lShldr", "lShldr"),
        "right_shoulder": ("rShldr", "rShldr"),
        "left_elbow": ("lForeArm", "lForeArm"),
        "right_elbow": ("rForeArm", "rForeArm"),
        "left_wrist": ("lHand", "lHand"),
        "right_wrist": ("rHand", "rHand"),
    },
}

_CHILDREN = {j: [k for k in range(NUM_JOINTS) if PARENTS[k] == j] for j in range(NUM_JOINTS)}


def _to_rep103(source: SourceMotion, pos_idx: list[int]) -> np.ndarray:
    """Rotation taking the source axes to REP-103 with the rest pose facing +x."""
    up = source.up_axis
    perm = np.zeros((3, 3))
    # new z <- source up; new x, y <- the two other source axes in cyclic order.
    perm[2, up], perm[0, (up + 1) % 3], perm[1, (up + 2) % 3] = 1.0, 1.0, 1.0
    rest = source.rest_positions @ perm.T
    left = rest[pos_idx[JOINT_INDEX["left_hip"]]] - rest[pos_idx[JOINT_INDEX["right_hip"]]]
    yaw = np.arctan2(left[1], left[0]) - np.pi / 2
    return yaw_matrix(-yaw) @ perm


def _rest_alignment(rest: np.ndarray, canonical: np.ndarray) -> np.ndarray:
    """Per joint, the rotation A with source_rest_bone = A @ canonical_bone for its one child."""
    align = np.tile(np.eye(3), (NUM_JOINTS, 1, 1))
    for j in range(NUM_JOINTS):
        kids = _CHILDREN[j]
        inherit = align[PARENTS[j]] if j else np.eye(3)
        if len(kids) != 1:
            # Leaves keep their parent's frame; branching joints (pelvis, spine3) keep the
            # source's rest frame, which _to_rep103 already faces forward.
            align[j] = inherit if not kids else np.eye(3)
            continue
        src, can = rest[kids[0]] - rest[j], canonical[kids[0]]
        align[j] = rotation_between(can, src) if np.linalg.norm(src) > 1e-6 else inherit
    return align


def retarget(source: SourceMotion, fps: float | None = None) -> Motion:
    """The source motion on the 22-joint body, optionally resampled to fps."""
    try:
        joint_map = JOINT_MAPS[source.layout]
    except KeyError:
        raise ValueError(
            f"{source.name}: no joint map for skeleton layout {source.layout!r}; known layouts: {', '.join(JOINT_MAPS)}"
        ) from None
    missing = sorted({s for pair in joint_map.values() for s in pair} - set(source.joint_names))
    if missing:
        raise ValueError(f"{source.name}: the {source.layout} skeleton lacks joints {', '.join(missing)}")
    pos_idx = [source.index(joint_map[n][0]) for n in JOINT_NAMES]
    rot_idx = [source.index(joint_map[n][1]) for n in JOINT_NAMES]

    base = _to_rep103(source, pos_idx)
    rest = source.rest_positions[pos_idx] @ base.T
    positions = source.positions[:, pos_idx] @ base.T
    rotations = base @ source.rotations[:, rot_idx] @ base.T

    align = _rest_alignment(rest, Skeleton.canonical().offsets)
    offsets = np.zeros((NUM_JOINTS, 3))
    for j in range(1, NUM_JOINTS):
        offsets[j] = align[PARENTS[j]].T @ (rest[j] - rest[PARENTS[j]])
    glob = rotations @ align
    local = np.empty_like(glob)
    local[:, 0] = glob[:, 0]
    for j in range(1, NUM_JOINTS):
        local[:, j] = np.swapaxes(glob[:, PARENTS[j]], -1, -2) @ glob[:, j]
    motion = Motion(source.name, source.fps, Skeleton(offsets), matrix_to_quat(local), positions[:, 0].copy())
    return motion if fps is None else motion.resampled(fps)


def retarget_error(source: SourceMotion, motion: Motion) -> np.ndarray:
    """Per-frame, per-joint distance (m) between the body's FK and the mapped source joints.

    The motion must be at the source frame rate (retarget without fps)."""
    joint_map = JOINT_MAPS[source.layout]
    pos_idx = [source.index(joint_map[n][0]) for n in JOINT_NAMES]
    base = _to_rep103(source, pos_idx)
    target = source.positions[:, pos_idx] @ base.T
    _, fk = forward_kinematics(motion.local_rotations, motion.root_positions, motion.skeleton.offsets)
    return np.linalg.norm(fk - target, axis=-1)
