"""A URDF of the 22-joint body for a person's skeleton, whose joints are the JointState
names: each body joint is three continuous joints (z, y, x) through two massless links, so
robot_state_publisher and RViz show exactly the published estimate."""

from __future__ import annotations

from xml.sax.saxutils import quoteattr

import numpy as np

from ..core.skeleton import JOINT_NAMES, NUM_JOINTS, PARENTS, Skeleton
from .output import AXES, axis_link_name

_AXIS_VECTORS = {"x": "1 0 0", "y": "0 1 0", "z": "0 0 1"}


def _link(name: str, length: float) -> str:
    radius = 0.03
    if length <= 1e-6:
        return f"  <link name={quoteattr(name)}/>\n"
    return (
        f"  <link name={quoteattr(name)}>\n"
        f'    <visual><geometry><sphere radius="{radius}"/></geometry></visual>\n'
        f"  </link>\n"
    )


def body_urdf(skeleton: Skeleton, name: str = "sparse_body") -> str:
    """Link and joint names are unprefixed; robot_state_publisher's frame_prefix adds one."""
    lengths = np.zeros(NUM_JOINTS)
    for j in range(1, NUM_JOINTS):
        lengths[PARENTS[j]] = max(lengths[PARENTS[j]], float(np.linalg.norm(skeleton.offsets[j])))
    parts = [f'<?xml version="1.0"?>\n<robot name={quoteattr(name)}>\n']
    parts.append(_link(JOINT_NAMES[0], 1.0))
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
            parts.append(_link(child, lengths[j] if k == len(AXES) - 1 else 0.0))
            parent = child
    parts.append("</robot>\n")
    return "".join(parts)
