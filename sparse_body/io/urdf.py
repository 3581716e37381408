"""A URDF of the 22-joint body for a person's skeleton, whose joints are the JointState
names: each body joint is three continuous joints (z, y, x) through two massless links, so
robot_state_publisher and RViz show exactly the published estimate. Each body link draws a
capsule (cylinder and spheres) to each child joint, and the ends (head, hands, feet) one along
their own bone, so a viewer shows a body, not 22 dots."""

from __future__ import annotations

from xml.sax.saxutils import quoteattr

import numpy as np

from ..core.skeleton import JOINT_NAMES, NUM_JOINTS, PARENTS, Skeleton
from .output import AXES, axis_link_name

HEIGHTS = (0.5, 2.5)  # m: the body sizes a node accepts, as the estimator's height parameter
MAX_BONE = 1.0  # m
_AXIS_VECTORS = {"x": "1 0 0", "y": "0 1 0", "z": "0 0 1"}


# Radius (m, for a 1.75 m body) of the limb a link draws towards its children: RViz and
# Foxglove draw the URDF's visuals, so the body shows as capsules from joint to joint.
_RADII = {
    "pelvis": 0.07,
    "hip": 0.06,
    "knee": 0.045,
    "ankle": 0.035,
    "foot": 0.03,
    "spine": 0.07,
    "neck": 0.045,
    "collar": 0.045,
    "shoulder": 0.04,
    "elbow": 0.035,
    "wrist": 0.03,
    "head": 0.045,
}
# The ends of the body, which no child link reaches: what each draws beyond its joint, along
# the direction of its own bone (the head upwards): (length, radius) for 1.75 m.
_ENDS = {"head": (0.2, 0.09), "wrist": (0.09, 0.035), "foot": (0.05, 0.03)}


def _radius(name: str) -> float:
    return next(r for key, r in _RADII.items() if key in name)


def _cylinder(start: np.ndarray, end: np.ndarray, radius: float) -> str:
    """A visual cylinder from start to end and a sphere at end: a capsule with the joint's sphere."""
    from scipy.spatial.transform import Rotation

    axis = end - start
    length = float(np.linalg.norm(axis))
    turn, _ = Rotation.align_vectors([axis / length], [[0.0, 0.0, 1.0]])  # the cylinder's z along the bone
    roll, pitch, yaw = turn.as_euler("xyz")  # URDF rpy: fixed axes x, y, z
    x, y, z = (start + end) / 2
    ex, ey, ez = end
    return (
        f'    <visual><origin xyz="{x:.5f} {y:.5f} {z:.5f}" rpy="{roll:.6f} {pitch:.6f} {yaw:.6f}"/>'
        f'<geometry><cylinder radius="{radius:.4f}" length="{length:.5f}"/></geometry></visual>\n'
        f'    <visual><origin xyz="{ex:.5f} {ey:.5f} {ez:.5f}"/>'
        f'<geometry><sphere radius="{radius:.4f}"/></geometry></visual>\n'
    )


def _link(name: str, skeleton: Skeleton | None = None, j: int = 0) -> str:
    """A massless link inside a joint (skeleton None: no visual, it lies on its body link), or
    body link j: a sphere at its joint and a capsule to each child joint, or for an end of the
    body (head, hands, feet) a capsule along its own bone."""
    if skeleton is None:
        return f"  <link name={quoteattr(name)}/>\n"
    scale = skeleton.height() / 1.75
    radius = _radius(name) * scale
    visuals = [f'    <visual><geometry><sphere radius="{radius:.4f}"/></geometry></visual>\n']
    children = [c for c in range(1, NUM_JOINTS) if PARENTS[c] == j]
    for c in children:
        offset = np.asarray(skeleton.offsets[c], float)
        if np.linalg.norm(offset) > 1e-6:
            visuals.append(_cylinder(np.zeros(3), offset, min(radius, _radius(JOINT_NAMES[c]) * scale * 1.2)))
    if not children:
        end = next(key for key in _ENDS if key in name)
        length, end_radius = _ENDS[end]
        bone = np.asarray(skeleton.offsets[j], float)
        direction = np.array([0.0, 0.0, 1.0]) if end == "head" else bone / np.linalg.norm(bone)
        tip = direction * (length - end_radius) * scale
        visuals.append(_cylinder(np.zeros(3), tip, end_radius * scale))
    return f"  <link name={quoteattr(name)}>\n" + "".join(visuals) + "  </link>\n"


def body_urdf(skeleton: Skeleton, name: str = "sparse_body") -> str:
    """Link and joint names are unprefixed; robot_state_publisher's frame_prefix adds one."""
    parts = [f'<?xml version="1.0"?>\n<robot name={quoteattr(name)}>\n']
    parts.append(_link(JOINT_NAMES[0], skeleton, 0))
    for j in range(1, NUM_JOINTS):
        body = JOINT_NAMES[j]
        parent = JOINT_NAMES[PARENTS[j]]
        x, y, z = skeleton.offsets[j]
        for k, axis in enumerate(AXES):
            child = body if k == len(AXES) - 1 else axis_link_name(body, axis)
            origin = f"{x:.6f} {y:.6f} {z:.6f}" if k == 0 else "0 0 0"
            parts.append(
                f'  <joint name={quoteattr(f"{body}_r{axis}")} type="continuous">\n'
                f"    <parent link={quoteattr(parent)}/><child link={quoteattr(child)}/>\n"
                f'    <origin xyz="{origin}" rpy="0 0 0"/><axis xyz="{_AXIS_VECTORS[axis]}"/>\n'
                f"  </joint>\n"
            )
            parts.append(_link(child, skeleton, j) if k == len(AXES) - 1 else _link(child))
            parent = child
    parts.append("</robot>\n")
    return "".join(parts)


def body_skeleton(text: str) -> Skeleton:
    """The skeleton a body URDF (body_urdf's) was made for, each joint's offset read from its
    z joint's origin: how a node that gets the body's robot_description knows the body the
    estimator publishes. RobotFileError (a ValueError) when the text is no such URDF."""
    from ..robot.urdf_model import RobotFileError, parse_urdf

    origins = {j.name: j.origin[:3, 3] for j in parse_urdf(text, "the body's robot_description").joints}
    missing = [name for name in JOINT_NAMES[1:] if f"{name}_rz" not in origins]
    if missing:
        raise RobotFileError(f"the body's robot_description has no joint {missing[0]}_rz: not a sparse_body body")
    offsets = np.array([np.zeros(3)] + [origins[f"{name}_rz"] for name in JOINT_NAMES[1:]])
    # a person as the estimator's own parameters allow one (0.5 to 2.5 m), whose longest bone,
    # a thigh, is under half a metre at 2.5 m: a peer's 1,750 m body is no person to retarget
    longest = float(np.linalg.norm(offsets, axis=1).max())
    if longest > MAX_BONE:
        raise RobotFileError(
            f"the body's robot_description has a {longest:.3g} m bone; a person's are under {MAX_BONE:g} m"
        )
    skeleton = Skeleton(offsets)
    height, (low, high) = skeleton.height(), HEIGHTS
    if not low <= height <= high:
        raise RobotFileError(
            f"the body's robot_description is a {height:.3g} m body; a person is {low:g} to {high:g} m"
        )
    return skeleton
