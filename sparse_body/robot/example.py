"""A small humanoid robot made here: its URDF and its mapping YAML, written to a folder, for
the tests, the bench and trying retargeting without a robot's files. Human proportions at
`scale` (so the retargeting's scaling is exercised), joints as a typical humanoid has them
(hip yaw, roll, pitch; knee; ankle pitch, roll; a waist yaw; shoulder pitch, roll, yaw;
elbow), arms hanging at the zero pose, limits like a robot's."""

from __future__ import annotations

from pathlib import Path

_SIDE = {"left": 1.0, "right": -1.0}
# joint, parent link, child link, origin xyz (at scale 1), axis, (lower, upper) or None: fixed
JointRow = tuple[str, str, str, tuple, str, "tuple[float, float] | None"]


def _joints(scale: float) -> list[JointRow]:
    out: list[JointRow] = []
    for side, s in _SIDE.items():
        leg = [
            ("hip_yaw", (0.047, 0.102 * s, -0.112), "0 0 1", (-0.6, 0.6)),
            ("hip_roll", (0.0, 0.0, 0.0), "1 0 0", (-0.4, 0.8) if s > 0 else (-0.8, 0.4)),
            ("hip_pitch", (0.0, 0.0, 0.0), "0 1 0", (-2.5, 1.5)),
            ("knee", (0.0, 0.0, -0.451), "0 1 0", (0.0, 2.4)),
            ("ankle_pitch", (0.0, 0.0, -0.488), "0 1 0", (-0.9, 0.6)),
            ("ankle_roll", (0.0, 0.0, 0.0), "1 0 0", (-0.3, 0.3)),
        ]
        parent = "pelvis"
        for name, xyz, axis, limits in leg:
            out.append((f"{side}_{name}_joint", parent, f"{side}_{name}_link", xyz, axis, limits))
            parent = f"{side}_{name}_link"
        out.append((f"{side}_sole_joint", parent, f"{side}_sole", (0.0, 0.0, -0.033), "", None))
    out.append(("waist_yaw_joint", "pelvis", "torso_link", (0.0, 0.0, 0.0), "0 0 1", (-2.0, 2.0)))
    out.append(("head_joint", "torso_link", "head_link", (0.004, 0.0, 0.508), "", None))
    for side, s in _SIDE.items():
        arm = [
            ("shoulder_pitch", (0.004, 0.22 * s, 0.397), "0 1 0", (-3.0, 3.0)),
            ("shoulder_roll", (0.0, 0.0, 0.0), "1 0 0", (-0.3, 3.0) if s > 0 else (-3.0, 0.3)),
            ("shoulder_yaw", (0.0, 0.0, 0.0), "0 0 1", (-2.6, 2.6)),
            ("elbow", (0.0, 0.0, -0.333), "0 1 0", (-2.5, 0.2)),
        ]
        parent = "torso_link"
        for name, xyz, axis, limits in arm:
            out.append((f"{side}_{name}_joint", parent, f"{side}_{name}_link", xyz, axis, limits))
            parent = f"{side}_{name}_link"
        out.append((f"{side}_hand_joint", parent, f"{side}_hand", (0.0, 0.0, -0.21), "", None))
    return [(n, p, c, tuple(v * scale for v in xyz), a, lim) for n, p, c, xyz, a, lim in out]


# link -> (its collision cylinder's centre z and length at scale 1, radius; rpy): the body's
# parts as a robot's collision primitives, so robot/collision.py has shapes to check
_SHAPES = {
    "pelvis": (-0.05, 0.2, 0.09, "1.5708 0 0"),
    "torso_link": (0.25, 0.4, 0.13, "0 0 0"),
    "head_link": (0.1, 0.12, 0.09, "0 0 0"),
    **{f"{side}_hip_pitch_link": (-0.2255, 0.45, 0.06, "0 0 0") for side in _SIDE},
    **{f"{side}_knee_link": (-0.244, 0.45, 0.05, "0 0 0") for side in _SIDE},
    **{f"{side}_shoulder_yaw_link": (-0.1665, 0.3, 0.04, "0 0 0") for side in _SIDE},
    **{f"{side}_elbow_link": (-0.105, 0.2, 0.035, "0 0 0") for side in _SIDE},
}


def _link(link: str, scale: float) -> str:
    if link not in _SHAPES:
        return f'  <link name="{link}"/>'
    z, length, radius, rpy = _SHAPES[link]
    return (
        f'  <link name="{link}">\n    <collision>\n      <origin xyz="0 0 {z * scale:.4f}" rpy="{rpy}"/>\n'
        f'      <geometry><cylinder radius="{radius * scale:.4f}" length="{length * scale:.4f}"/></geometry>\n'
        "    </collision>\n  </link>"
    )


def urdf(scale: float = 0.8, name: str = "test_humanoid") -> str:
    joints = _joints(scale)
    links = ["pelvis"] + [c for _, _, c, _, _, _ in joints]
    text = [f'<?xml version="1.0"?>\n<robot name="{name}">']
    text += [_link(link, scale) for link in links]
    for joint, parent, child, xyz, axis, limits in joints:
        kind = "fixed" if limits is None else "revolute"
        body = [f'    <parent link="{parent}"/>', f'    <child link="{child}"/>']
        body.append(f'    <origin xyz="{xyz[0]:.4f} {xyz[1]:.4f} {xyz[2]:.4f}" rpy="0 0 0"/>')
        if limits is not None:
            body.append(f'    <axis xyz="{axis}"/>')
            body.append(f'    <limit lower="{limits[0]}" upper="{limits[1]}" effort="100" velocity="10"/>')
        text.append(f'  <joint name="{joint}" type="{kind}">\n' + "\n".join(body) + "\n  </joint>")
    text.append("</robot>\n")
    return "\n".join(text)


MAPPING = """\
# the example humanoid (sparse_body/robot/example.py): its links <- the human's joints
urdf: {urdf}
base: pelvis
targets:
  left_foot: {{link: left_ankle_roll_link, joint: left_ankle, orientation: 0.3, contact: left}}
  right_foot: {{link: right_ankle_roll_link, joint: right_ankle, orientation: 0.3, contact: right}}
  left_hand: {{link: left_hand, joint: left_wrist}}
  right_hand: {{link: right_hand, joint: right_wrist}}
  head: {{link: head_link, joint: head, position: 0.5}}
  left_thigh: {{link: left_hip_pitch_link, joint: left_hip, position: 0.0, direction: 1.0}}
  left_shin: {{link: left_knee_link, joint: left_knee, position: 0.0, direction: 1.0}}
  right_thigh: {{link: right_hip_pitch_link, joint: right_hip, position: 0.0, direction: 1.0}}
  right_shin: {{link: right_knee_link, joint: right_knee, position: 0.0, direction: 1.0}}
"""


def write_robot(folder: Path, scale: float = 0.8) -> Path:
    """The test robot's URDF and mapping in folder; the mapping's path."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "test_humanoid.urdf").write_text(urdf(scale))
    path = folder / "test_humanoid.yaml"
    path.write_text(MAPPING.format(urdf="test_humanoid.urdf"))
    return path
