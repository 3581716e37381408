"""A body pose as the ROS outputs carry it, without ROS types: JointState names and values,
TF transforms and foot contacts. io/cdr.py encodes them as messages, for bags and the live node."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from ..core.contacts import FOOT_JOINTS
from ..core.kinematics import forward_kinematics
from ..core.rotations import JOINT_EULER_ORDER, matrix_to_euler, quat_to_matrix
from ..core.sensors import SensorConfig
from ..core.skeleton import JOINT_NAMES, NUM_JOINTS, PARENTS, Skeleton
from ..core.types import BodyPose, TrackerStream

AXES = ("z", "y", "x")  # JOINT_EULER_ORDER, one revolute joint per axis, outermost first
assert JOINT_EULER_ORDER == "ZYX"


def joint_state_names() -> list[str]:
    """Three revolute joints per body joint below the pelvis: <joint>_rz, _ry, _rx."""
    return [f"{name}_r{axis}" for name in JOINT_NAMES[1:] for axis in AXES]


def joint_angles(local_quats: np.ndarray) -> np.ndarray:
    """JointState positions (radians, joint_state_names() order) of poses' local rotations
    (..., 22, 4): local = Rz(a) @ Ry(b) @ Rx(c) for every joint below the pelvis."""
    local_quats = np.asarray(local_quats, dtype=np.float64)
    local = quat_to_matrix(local_quats[..., 1:, :])
    with warnings.catch_warnings():  # gimbal lock still yields a valid decomposition
        warnings.simplefilter("ignore", UserWarning)
        angles = matrix_to_euler(local, JOINT_EULER_ORDER)
    return angles.reshape(local_quats.shape[:-2] + (len(AXES) * (NUM_JOINTS - 1),))


# The farthest a body's root may be from the fixed frame's origin (m). The trackers are refused
# beyond 100 m by default (io/tf_guards.py), so an estimate lies well inside; a root at 1e200 m
# would scale to an infinite robot base.
MAX_ROOT_DISTANCE = 1000.0


class JointStateError(ValueError):
    """A JointState (with its root) that is no body pose: the reason, in one line."""


def pose_from_joint_state(names, positions, root_position, root_quat, stamp: float) -> BodyPose:
    """The inverse of joint_angles: a pose from a JointState of our 63 joints (in any order)
    and the root's pose (from TF): the one conversion every node that reads a body's JointState
    uses. JointStateError (one line) for anything that is no body pose: names and positions of
    different lengths, a joint missing or named twice, non-finite values, a root farther than
    MAX_ROOT_DISTANCE or a root turn that is no unit quaternion."""
    from ..core.rotations import euler_to_matrix, matrix_to_quat

    names, wanted = list(names), joint_state_names()
    if len(positions) != len(names):
        raise JointStateError(f"JointState has {len(names)} names and {len(positions)} positions")
    index = {n: i for i, n in enumerate(names)}
    if len(index) != len(names):
        raise JointStateError("JointState names a joint twice")
    missing = [n for n in wanted if n not in index]
    if missing:
        raise JointStateError(f"JointState lacks {len(missing)} of the body's joints, e.g. {missing[0]!r}")
    try:
        angles = np.array([positions[index[n]] for n in wanted], dtype=float).reshape(NUM_JOINTS - 1, 3)
        root_position = np.asarray(root_position, dtype=float).reshape(3)
        root_quat = np.asarray(root_quat, dtype=float).reshape(4)
    except (TypeError, ValueError):
        raise JointStateError("JointState or root pose holds values that are not numbers") from None
    if not (np.all(np.isfinite(angles)) and np.all(np.isfinite(root_position)) and np.all(np.isfinite(root_quat))):
        raise JointStateError("JointState or root pose holds non-finite values")
    if np.linalg.norm(root_position) > MAX_ROOT_DISTANCE:
        raise JointStateError(f"the body's root is more than {MAX_ROOT_DISTANCE:g} m from the fixed frame's origin")
    norm = np.linalg.norm(root_quat)
    if not 0.5 < norm < 2.0:
        raise JointStateError("the body's root turn is not a unit quaternion")
    quats = np.empty((NUM_JOINTS, 4))
    quats[0] = root_quat / norm
    quats[1:] = matrix_to_quat(euler_to_matrix(angles, JOINT_EULER_ORDER))
    return BodyPose(stamp, quats, root_position)


@dataclass(frozen=True)
class Transform:
    parent: str
    child: str
    translation: np.ndarray  # (3,)
    rotation: np.ndarray  # (4,) x y z w


@dataclass(frozen=True)
class TransformTable:
    """The same transforms over many frames (one /tf message each): parents[k] -> children[k],
    values (frames, k, 7): translation, then rotation x y z w, as a TFMessage holds them."""

    parents: tuple[str, ...]
    children: tuple[str, ...]
    values: np.ndarray

    def __add__(self, other: TransformTable) -> TransformTable:
        return TransformTable(
            self.parents + other.parents, self.children + other.children, np.concatenate([self.values, other.values], 1)
        )

    def frame(self, i: int) -> list[Transform]:
        v = self.values[i]
        return [
            Transform(p, c, v[k, :3], v[k, 3:])
            for k, (p, c) in enumerate(zip(self.parents, self.children, strict=True))
        ]


def published_precision(values) -> np.ndarray:
    """Estimated numbers as they are published, live and in bags: rounded to float32 precision
    and sent as float64 (the message types' own). The rounding, 6e-8 of a value (0.06 um a
    metre, 1e-7 rad), lies five orders of magnitude below any tracker's noise, and the zero
    bits it leaves make a compressed estimate bag 37 % smaller (issue 55). Tracker samples
    copied beside the body keep every bit."""
    return np.asarray(values, np.float32).astype(np.float64)


def body_table(
    local_quats: np.ndarray,
    roots: np.ndarray,
    skeleton: Skeleton,
    fixed_frame: str,
    prefix: str = "",
    links: bool = True,
) -> TransformTable:
    """fixed_frame -> pelvis, and (links=True) every parent link -> child link, for poses'
    local rotations (frames, 22, 4) and roots (frames, 3)."""
    local_quats, roots = np.asarray(local_quats, np.float64), np.asarray(roots, np.float64)
    joints = range(NUM_JOINTS if links else 1)
    values = np.empty((len(local_quats), len(joints), 7))
    values[:, 0, :3] = roots
    values[:, 1:, :3] = skeleton.offsets[1 : len(joints)]
    values[:, :, 3:] = local_quats[:, : len(joints)]
    values = published_precision(values)
    parents = (fixed_frame,) + tuple(prefix + JOINT_NAMES[PARENTS[j]] for j in joints[1:])
    return TransformTable(parents, tuple(prefix + JOINT_NAMES[j] for j in joints), values)


def axis_link_name(body: str, axis: str) -> str:
    """The URDF's massless link after a body joint's revolute joint about `axis` (z or y)."""
    return f"{body}_r{axis}_link"


def axis_link_table(angles: np.ndarray, skeleton: Skeleton, prefix: str = "") -> TransformTable:
    """The two massless links inside each body joint of the URDF (io/urdf.py), placed as
    robot_state_publisher places them from the JointState angles (frames, 63): <joint>_rz_link
    under the parent link at the joint's offset, turned by Rz; <joint>_ry_link under it,
    turned by Ry. With body_table's links, every link of the URDF has a transform, so a viewer
    that draws the URDF from TF (Foxglove's 3D panel, RViz) finds each one. The body link
    itself still hangs from its parent link directly, as the node publishes it live; both
    paths give it the same pose, Rx about the ry link's origin being the rest of the joint."""
    half = np.asarray(angles, np.float64).reshape(len(angles), NUM_JOINTS - 1, len(AXES)) / 2.0  # z, y, x
    values = np.zeros((len(angles), NUM_JOINTS - 1, 2, 7))
    values[:, :, 0, :3] = skeleton.offsets[1:]
    values[:, :, 0, 5], values[:, :, 0, 6] = np.sin(half[..., 0]), np.cos(half[..., 0])  # about z
    values[:, :, 1, 4], values[:, :, 1, 6] = np.sin(half[..., 1]), np.cos(half[..., 1])  # about y
    parents, children = [], []
    for j in range(1, NUM_JOINTS):
        body = prefix + JOINT_NAMES[j]
        rz = axis_link_name(body, "z")
        parents += [prefix + JOINT_NAMES[PARENTS[j]], rz]
        children += [rz, axis_link_name(body, "y")]
    return TransformTable(tuple(parents), tuple(children), values.reshape(len(angles), -1, 7))


def tracker_table(sensors: SensorConfig, stream: TrackerStream, which: np.ndarray, shown: tuple[int, ...]):
    """fixed frame -> the trackers `shown` (site indices) in the frames `which` of a tracker
    stream, so a viewer shows the trackers beside the body; a position-only tracker drawn
    unturned. tracker_sites says which to show."""
    values = np.zeros((len(which), len(shown), 7))
    values[..., 6] = 1.0
    for k, s in enumerate(shown):
        values[:, k, :3] = stream.positions[which, s]
        if sensors.sites[s].has_orientation:
            values[:, k, 3:] = stream.orientations[which, s]
    return TransformTable((sensors.fixed_frame,) * len(shown), tuple(sensors.sites[s].frame_id for s in shown), values)


def tracker_sites(sensors: SensorConfig, stream: TrackerStream) -> np.ndarray:
    """(frames, sites) bool: the trackers to show in each frame: a usable sample with a
    position (an orientation-only IMU has no place of its own and is left out)."""
    placed = np.array([site.has_position for site in sensors.sites], bool)
    return stream.valid & placed & np.all(np.isfinite(stream.positions), axis=-1)


def foot_points(local_quats: np.ndarray, roots: np.ndarray, skeleton: Skeleton) -> np.ndarray:
    """(..., 2, 3) toe positions in the fixed frame, left then right, of poses' local
    rotations (..., 22, 4) and roots (..., 3)."""
    _, pos = forward_kinematics(quat_to_matrix(local_quats), roots, skeleton.offsets)
    return pos[..., list(FOOT_JOINTS), :]


FOOT_NAMES = ("left_foot", "right_foot")
HELD = "held: too little tracker input"  # EstimateStatus.message of a held pose, offline and by default live


def stamp_parts(seconds: float) -> tuple[int, int]:
    """(sec, nanosec) of a time in seconds, for builtin_interfaces/Time on both the rclpy and
    the rosbags path. Nanoseconds that round up to a whole second carry into the seconds
    (a wrap would jump the stamp back by a second)."""
    sec = int(np.floor(seconds))
    nanosec = int(round((seconds - sec) * 1e9))
    if nanosec >= 1_000_000_000:
        sec, nanosec = sec + 1, nanosec - 1_000_000_000
    return sec, nanosec
