"""A body pose as the ROS outputs carry it, without ROS types: JointState names and values,
TF transforms and foot contacts. ros/ and bagio.py wrap these in rclpy or rosbags messages."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from ..core.contacts import FOOT_JOINTS
from ..core.kinematics import forward_kinematics
from ..core.rotations import JOINT_EULER_ORDER, matrix_to_euler, quat_to_matrix
from ..core.sensors import SensorConfig
from ..core.skeleton import JOINT_NAMES, NUM_JOINTS, PARENTS, Skeleton
from ..core.types import BodyPose

AXES = ("z", "y", "x")  # JOINT_EULER_ORDER, one revolute joint per axis, outermost first
assert JOINT_EULER_ORDER == "ZYX"


def joint_state_names() -> list[str]:
    """Three revolute joints per body joint below the pelvis: <joint>_rz, _ry, _rx."""
    return [f"{name}_r{axis}" for name in JOINT_NAMES[1:] for axis in AXES]


def joint_state_positions(pose: BodyPose) -> np.ndarray:
    """Angles (radians) in joint_state_names() order: local = Rz(a) @ Ry(b) @ Rx(c)."""
    local = quat_to_matrix(pose.local_quats[1:])
    with warnings.catch_warnings():  # gimbal lock still yields a valid decomposition
        warnings.simplefilter("ignore", UserWarning)
        return matrix_to_euler(local, JOINT_EULER_ORDER).reshape(-1)


def pose_from_joint_state(names, positions, root_position, root_quat, stamp: float) -> BodyPose:
    """The inverse of joint_state_positions: a pose from a JointState of our 63 joints (in
    any order) and the root's pose (from TF). Missing joints or non-finite values: ValueError."""
    from ..core.rotations import euler_to_matrix, matrix_to_quat

    index = {n: i for i, n in enumerate(names)}
    wanted = joint_state_names()
    missing = [n for n in wanted if n not in index]
    if missing:
        raise ValueError(f"JointState lacks {len(missing)} of the body's joints, e.g. {missing[0]!r}")
    angles = np.array([positions[index[n]] for n in wanted], dtype=float).reshape(NUM_JOINTS - 1, 3)
    if not (np.all(np.isfinite(angles)) and np.all(np.isfinite(root_position)) and np.all(np.isfinite(root_quat))):
        raise ValueError("JointState or root pose holds non-finite values")
    quats = np.empty((NUM_JOINTS, 4))
    quats[0] = np.asarray(root_quat, float) / np.linalg.norm(root_quat)
    quats[1:] = matrix_to_quat(euler_to_matrix(angles, JOINT_EULER_ORDER))
    return BodyPose(stamp, quats, np.asarray(root_position, float))


@dataclass(frozen=True)
class Transform:
    parent: str
    child: str
    translation: np.ndarray  # (3,)
    rotation: np.ndarray  # (4,) x y z w


def body_transforms(
    pose: BodyPose, skeleton: Skeleton, fixed_frame: str, prefix: str = "", links: bool = True
) -> list[Transform]:
    """fixed_frame -> pelvis, and (links=True) every parent link -> child link."""
    out = [Transform(fixed_frame, prefix + JOINT_NAMES[0], pose.root_position, pose.local_quats[0])]
    if links:
        for j in range(1, NUM_JOINTS):
            out.append(
                Transform(
                    prefix + JOINT_NAMES[PARENTS[j]], prefix + JOINT_NAMES[j], skeleton.offsets[j], pose.local_quats[j]
                )
            )
    return out


def axis_link_name(body: str, axis: str) -> str:
    """The URDF's massless link after a body joint's revolute joint about `axis` (z or y)."""
    return f"{body}_r{axis}_link"


def axis_link_transforms(pose: BodyPose, skeleton: Skeleton, prefix: str = "") -> list[Transform]:
    """The two massless links inside each body joint of the URDF (io/urdf.py), placed as
    robot_state_publisher places them from the JointState: <joint>_rz_link under the parent
    link at the joint's offset, turned by Rz; <joint>_ry_link under it, turned by Ry. With
    body_transforms' links, every link of the URDF has a transform, so a viewer that draws the
    URDF from TF (Foxglove's 3D panel, RViz) finds each one. The body link itself still hangs
    from its parent link directly, as the node publishes it live; both paths give it the same
    pose, since Rx about the ry link's origin is the rest of the joint's rotation."""
    half = joint_state_positions(pose).reshape(NUM_JOINTS - 1, len(AXES)) / 2.0  # z, y, x per joint
    out = []
    for j in range(1, NUM_JOINTS):
        body, parent = prefix + JOINT_NAMES[j], prefix + JOINT_NAMES[PARENTS[j]]
        z, y = half[j - 1, 0], half[j - 1, 1]
        rz, ry = axis_link_name(body, "z"), axis_link_name(body, "y")
        out.append(Transform(parent, rz, skeleton.offsets[j], np.array([0.0, 0.0, np.sin(z), np.cos(z)])))
        out.append(Transform(rz, ry, np.zeros(3), np.array([0.0, np.sin(y), 0.0, np.cos(y)])))
    return out


def tracker_transforms(
    sensors: SensorConfig, positions: np.ndarray, orientations: np.ndarray, valid: np.ndarray
) -> list[Transform]:
    """fixed frame -> each tracker frame with a usable sample in this frame, so a viewer shows
    the trackers beside the body. An orientation-only tracker (IMU) has no place of its own
    and is left out; a position-only one is drawn unturned."""
    out = []
    for s, site in enumerate(sensors.sites):
        if not valid[s] or not site.has_position or not np.all(np.isfinite(positions[s])):
            continue
        rotation = orientations[s] if site.has_orientation else np.array([0.0, 0.0, 0.0, 1.0])
        out.append(Transform(sensors.fixed_frame, site.frame_id, positions[s], rotation))
    return out


def contact_points(pose: BodyPose, skeleton: Skeleton) -> np.ndarray:
    """(2, 3) toe positions in the fixed frame, left then right."""
    _, pos = forward_kinematics(quat_to_matrix(pose.local_quats), pose.root_position, skeleton.offsets)
    return pos[list(FOOT_JOINTS)]


FOOT_NAMES = ("left_foot", "right_foot")


def stamp_parts(seconds: float) -> tuple[int, int]:
    """(sec, nanosec) of a time in seconds, for builtin_interfaces/Time on both the rclpy and
    the rosbags path. Nanoseconds that round up to a whole second carry into the seconds
    (a wrap would jump the stamp back by a second)."""
    sec = int(np.floor(seconds))
    nanosec = int(round((seconds - sec) * 1e9))
    if nanosec >= 1_000_000_000:
        sec, nanosec = sec + 1, nanosec - 1_000_000_000
    return sec, nanosec
