"""Which robot links follow which human joints: a small YAML per robot.

    urdf: h1.urdf          # the robot's URDF, relative to this file (a robot_urdf given overrides it)
    base: pelvis           # the robot link that follows the human pelvis (its place and turn)
    targets:               # what the solver reaches for, one entry a robot link
      left_foot: {link: left_ankle_link, joint: left_ankle, orientation: 0.3, contact: left}
      left_hand: {link: left_elbow_link, joint: left_wrist, point: [0.28, 0.0, -0.02]}
      ...

A target's `point` is where on the link (metres, in the link's frame) the human joint is
matched; `position` and `orientation` weigh how hard it is reached (an orientation turns the
link as the human joint turns, from the robot's zero pose matched to the human T-pose; use
it only where those two agree, as for feet, not arms); `direction` weighs the turn of the
human bone that leaves the joint (to its one child joint: thigh, shin) with its twist about
the bone left free, for links the robot cannot twist as a person does; `contact` (left or
right) keeps it on the floor, where it touched down, while that foot is planted.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..core.skeleton import JOINT_INDEX, JOINT_NAMES, PARENTS
from .urdf_model import RobotFileError

KEYS = {
    "urdf",
    "base",
    "targets",
    "scale",
    "ankle_height",
    "smoothing",
    "iterations",
    "ramp",
    "max_acceleration",
    "description",
}
TARGET_KEYS = {"link", "joint", "point", "position", "orientation", "direction", "contact"}
SIDES = ("left", "right")


@dataclass(frozen=True)
class Target:
    name: str
    link: str
    joint: str  # the human joint (core/skeleton.JOINT_NAMES)
    point: tuple[float, float, float] = (0.0, 0.0, 0.0)
    position: float = 1.0  # weight of the position error (per metre)
    orientation: float = 0.0  # weight of the turn error (per radian); 0: the position only
    direction: float = 0.0  # weight of the turn of the bone leaving the joint, its twist free (per radian)
    contact: str = ""  # left / right: held on the floor while that foot is planted


@dataclass(frozen=True)
class RobotMapping:
    source: Path
    urdf: Path | None
    base: str
    targets: tuple[Target, ...]
    scale: float | None = None  # metres of robot per metre of human; None: robot leg / human leg
    ankle_height: float | None = None  # m above the floor of a planted foot target; None: scaled human's
    smoothing: float = 0.02  # weight of staying at the last frame's angles (smooth in time)
    iterations: int = 4  # Gauss-Newton steps a frame, from the last frame's solution
    ramp: float = 0.5  # s: after a start or a hold, the robot eases from where it is to the solution
    max_acceleration: float | None = None  # rad/s^2 (m/s^2) every joint keeps to; None: the velocity limits only
    description: str = ""


def bone_children(joint: str) -> list[int]:
    """The joints whose parent is this one (the bones that leave it)."""
    return [k for k, parent in enumerate(PARENTS) if parent == JOINT_INDEX[joint]]


def load_mapping(name_or_path: str | Path) -> RobotMapping:
    """A robot mapping by name (config/robots/NAME.yaml: unitree_h1, unitree_h1_2,
    unitree_g1_29dof, unitree_g1_23dof) or by path; RobotFileError (one line) where it cannot
    be one."""
    from ..core.resources import shipped_or_path
    from ..core.sensors import read_yaml

    path = shipped_or_path(name_or_path, "robots", RobotFileError, "robot mapping")
    return mapping_from(read_yaml(path, RobotFileError), path)


def _number(value, where: str, low: float, high: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not low <= float(value) <= high:
        raise RobotFileError(f"{where} must be a number from {low:g} to {high:g}, got {value!r}")
    return float(value)


def mapping_from(data, path: Path) -> RobotMapping:
    if not isinstance(data, dict):
        raise RobotFileError(f"{path}: a robot mapping is a YAML mapping with keys {', '.join(sorted(KEYS))}")
    unknown = sorted(set(map(str, data)) - KEYS)
    if unknown:
        raise RobotFileError(f"{path}: unknown key {unknown[0]!r}; the keys are {', '.join(sorted(KEYS))}")
    for key in ("base", "targets"):
        if key not in data:
            raise RobotFileError(f"{path}: {key!r} is missing")
    if not isinstance(data["base"], str) or not data["base"]:
        raise RobotFileError(f"{path}: base must be a link name")
    if not isinstance(data["targets"], dict) or not data["targets"]:
        raise RobotFileError(f"{path}: targets must map names to {{link, joint}} entries")
    targets = tuple(_target(str(name), entry, path) for name, entry in data["targets"].items())
    urdf = data.get("urdf")
    if urdf is not None and not isinstance(urdf, str):
        raise RobotFileError(f"{path}: urdf must be a file path")
    scale = data.get("scale", "auto")
    return RobotMapping(
        path,
        (path.parent / urdf) if urdf else None,
        data["base"],
        targets,
        None if scale == "auto" else _number(scale, f"{path}: scale", 0.05, 20.0),
        None if data.get("ankle_height") is None else _number(data["ankle_height"], f"{path}: ankle_height", 0.0, 2.0),
        _number(data.get("smoothing", 0.02), f"{path}: smoothing", 0.0, 100.0),
        int(_number(data.get("iterations", 4), f"{path}: iterations", 1, 100)),
        _number(data.get("ramp", 0.5), f"{path}: ramp", 0.0, 10.0),
        None
        if data.get("max_acceleration") is None
        else _number(data["max_acceleration"], f"{path}: max_acceleration", 0.1, 10_000.0),
        str(data.get("description", "")),
    )


def _target(name: str, entry, path: Path) -> Target:
    where = f"{path}: target {name!r}"
    if not isinstance(entry, dict):
        raise RobotFileError(f"{where} must be a mapping with link and joint")
    unknown = sorted(set(map(str, entry)) - TARGET_KEYS)
    if unknown:
        raise RobotFileError(f"{where}: unknown key {unknown[0]!r}; the keys are {', '.join(sorted(TARGET_KEYS))}")
    link, joint = entry.get("link"), entry.get("joint")
    if not isinstance(link, str) or not link:
        raise RobotFileError(f"{where}: link must be a link name")
    if joint not in JOINT_NAMES:
        raise RobotFileError(f"{where}: joint {joint!r} is not a body joint ({', '.join(JOINT_NAMES)})")
    point = entry.get("point", [0.0, 0.0, 0.0])
    if not isinstance(point, list) or len(point) != 3:
        raise RobotFileError(f"{where}: point must be [x, y, z] in metres")
    direction = _number(entry.get("direction", 0.0), f"{where} direction", 0.0, 100.0)
    if direction > 0 and len(bone_children(joint)) != 1:
        raise RobotFileError(f"{where}: direction needs a joint with one child bone (a hip, knee, shoulder, elbow)")
    contact = entry.get("contact", "")
    if contact not in ("", *SIDES):
        raise RobotFileError(f"{where}: contact must be left or right, got {contact!r}")
    return Target(
        name,
        link,
        joint,
        tuple(_number(v, f"{where} point", -10.0, 10.0) for v in point),  # type: ignore[arg-type]
        _number(entry.get("position", 1.0), f"{where} position", 0.0, 100.0),
        _number(entry.get("orientation", 0.0), f"{where} orientation", 0.0, 100.0),
        direction,
        contact,
    )
