"""A robot's kinematic tree read from its URDF, and its forward kinematics.

Only what retargeting needs is read: links, and each joint's type, parent, child, origin,
axis and limits. A URDF is user input: every way it can be unusable (not XML, too big, a
joint naming a link that is not there, a link with two parents, a loop, a moving joint
without limits) is a RobotFileError of one line naming the file and the element.
"""

from __future__ import annotations

import math
import os
import stat
import xml.etree.ElementTree as ElementTree
from collections import Counter
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path

import numpy as np

MAX_BYTES = 20_000_000  # the largest URDF read (a humanoid's is 20-60 kB; meshes are separate files)
MAX_JOINTS = 1000
# The joints the retargeting moves (those between the base and a target link): a humanoid has
# 20-60 (Unitree's G1 with hands 43). The solver's normal equations grow with their cube: 1,000
# on one chain cost 0.16 s a frame, 200 under 2 ms.
MAX_SOLVED_JOINTS = 200
# The largest joint origin (m, each coordinate) and axis component read: a humanoid's are under
# 1 m and near 1; a value near the float limit overflows the kinematics to inf or a zero axis.
MAX_OFFSET = 100.0
MAX_AXIS = 1e6
MOVING = ("revolute", "continuous", "prismatic")
MIN_RADIUS = 0.01  # m: a collision shape thinner than this is a contact point, not a body part (G1's feet)
MIN_MASS = 0.05  # kg: a link lighter than this is a frame, not a body part
# A floating or planar joint from a frame the URDF does not define ("world") only says that
# the root moves freely, as the retargeting base does anyway: it is skipped.
FREE = ("floating", "planar")


class RobotFileError(ValueError):
    """A robot file (URDF or mapping YAML) that cannot be used; the message is one line."""


@dataclass(frozen=True)
class Joint:
    name: str
    kind: str  # revolute, continuous, prismatic or fixed
    parent: int  # link index
    child: int  # link index
    origin: np.ndarray  # (4, 4) child joint frame in the parent link's frame at q = 0
    axis: np.ndarray  # (3,) unit, in the joint frame
    lower: float  # limits (rad or m); -inf/inf for continuous
    upper: float
    index: int = -1  # its place among the moving joints (the URDF's order), -1 when fixed
    velocity: float = math.inf  # the URDF's velocity limit (rad/s or m/s); inf where it gives none


@dataclass(frozen=True)
class Capsule:
    """A link's collision shape as a capsule: the points within `radius` of the segment a-b
    (in the link's frame). robot/collision.py checks them against each other."""

    link: int
    a: np.ndarray  # (3,)
    b: np.ndarray  # (3,)
    radius: float


@dataclass(frozen=True)
class RobotModel:
    """A tree of links from one root; joints in an order where each parent comes first."""

    name: str
    links: tuple[str, ...]
    joints: tuple[Joint, ...]
    root: int  # link index
    capsules: tuple[Capsule, ...] = ()  # from each link's <collision> (or, for a mesh, its <inertial>)

    @cached_property
    def moving(self) -> tuple[Joint, ...]:
        """The joints a JointState carries, in the URDF's order."""
        return tuple(sorted((j for j in self.joints if j.index >= 0), key=lambda j: j.index))

    @cached_property
    def _link_index(self) -> dict[str, int]:
        return {name: i for i, name in enumerate(self.links)}

    def link(self, name: str) -> int:
        found = self._link_index.get(name)
        if found is None:
            raise RobotFileError(f"robot {self.name!r} has no link {name!r}")
        return found

    @cached_property
    def _by_child(self) -> dict[int, Joint]:
        return {j.child: j for j in self.joints}

    def chain(self, link: int) -> list[int]:
        """Indices into `moving` of the joints between the root and a link, root first."""
        found = []
        while link != self.root:
            joint = self._by_child[link]
            if joint.index >= 0:
                found.append(joint.index)
            link = joint.parent
        return found[::-1]

    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        moving = self.moving
        return np.array([j.lower for j in moving]), np.array([j.upper for j in moving])

    def velocity_limits(self) -> np.ndarray:
        """Each moving joint's velocity limit (inf where the URDF gives none)."""
        return np.array([j.velocity for j in self.moving])

    def forward(self, q: np.ndarray, base: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(link transforms (links, 4, 4) in the world, joint frames (moving, 4, 4) after
        each moving joint's origin and before its motion) for joint values q (moving,) and
        the root link's world transform `base` (4, 4)."""
        motions = self._motions(np.asarray(q, float))
        links = np.empty((len(self.links), 4, 4))
        frames = np.empty((len(self.moving), 4, 4))
        links[self.root] = base
        for joint in self.joints:
            frame = links[joint.parent] @ joint.origin
            if joint.index >= 0:
                frames[joint.index] = frame
                frame = frame @ motions[joint.index]
            links[joint.child] = frame
        return links, frames

    @cached_property
    def _axes(self) -> tuple[np.ndarray, np.ndarray]:
        moving = self.moving
        return np.array([j.axis for j in moving]).reshape(-1, 3), np.array(
            [j.kind == "prismatic" for j in moving], bool
        )

    def _motions(self, q: np.ndarray) -> np.ndarray:
        """Each moving joint's motion (moving, 4, 4) at q: a turn about its axis (Rodrigues,
        all at once) or a slide along it."""
        axes, prismatic = self._axes
        c, s = np.cos(q)[:, None, None], np.sin(q)[:, None, None]
        skew = np.zeros((len(q), 3, 3))
        skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -axes[:, 2], axes[:, 1], -axes[:, 0]
        skew[:, 1, 0], skew[:, 2, 0], skew[:, 2, 1] = axes[:, 2], -axes[:, 1], axes[:, 0]
        out = np.zeros((len(q), 4, 4))
        out[:, :3, :3] = c * np.eye(3) + s * skew + (1 - c) * axes[:, :, None] * axes[:, None, :]
        out[:, 3, 3] = 1.0
        out[prismatic, :3, :3] = np.eye(3)
        out[prismatic, :3, 3] = axes[prismatic] * q[prismatic, None]
        return out


def axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    """The rotation matrix of angle (rad) about a unit axis (Rodrigues)."""
    x, y, z = axis
    c, s = math.cos(angle), math.sin(angle)
    t = 1.0 - c
    return np.array(
        [
            [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
            [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
            [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
        ]
    )


def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """URDF's rpy: about fixed x, then y, then z (R = Rz Ry Rx)."""
    x, y, z = np.eye(3)
    return axis_angle(z, yaw) @ axis_angle(y, pitch) @ axis_angle(x, roll)


def load_urdf(path: str | Path) -> RobotModel:
    """A URDF file as a RobotModel; RobotFileError (one line) when it cannot be one."""
    return parse_urdf(read_urdf_text(path), str(path))


def read_urdf_text(path: str | Path) -> str:
    """A URDF file's text: a regular file of at most MAX_BYTES of UTF-8, else RobotFileError.
    Opened without waiting (a FIFO would wait for a writer) and read with a cap: a device's
    size says 0, so the size on disk alone bounds nothing."""
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
        with os.fdopen(fd, "rb") as f:
            if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
                raise RobotFileError(f"{path}: not a regular file; a URDF is read from a file")
            data = f.read(MAX_BYTES + 1)
        if len(data) > MAX_BYTES:
            raise RobotFileError(f"{path}: too big for a URDF (at most {MAX_BYTES / 1e6:.0f} MB)")
        return data.decode("utf-8")
    except OSError as err:
        raise RobotFileError(f"{path}: cannot read the URDF ({err.strerror or err})") from None
    except UnicodeDecodeError:
        raise RobotFileError(f"{path}: a URDF is UTF-8 text; this file is not") from None


def _numbers(text: str | None, count: int, default: float, where: str, bound: float = math.inf) -> np.ndarray:
    """count numbers from an attribute, each finite and at most `bound` in size."""
    if text is None:
        return np.full(count, default)
    shown = text if len(text) <= 80 else text[:77] + "..."
    try:
        values = np.array([float(v) for v in text.split()[: count + 1]])
    except ValueError:
        raise RobotFileError(f"{where}: {shown!r} is not {count} numbers") from None
    if values.shape != (count,) or not np.all(np.isfinite(values)):
        raise RobotFileError(f"{where}: {shown!r} is not {count} finite numbers")
    if np.abs(values).max() > bound:
        raise RobotFileError(f"{where}: {shown!r} has a value over {bound:g} in size")
    return values


def parse_urdf(text: str, source: str = "URDF") -> RobotModel:
    """A URDF's text as a RobotModel (see load_urdf)."""
    if len(text) > MAX_BYTES:
        raise RobotFileError(f"{source}: too big for a URDF (at most {MAX_BYTES / 1e6:.0f} MB)")
    if "<!ENTITY" in text or "<!DOCTYPE" in text:  # entity expansion could blow up: a URDF needs neither
        raise RobotFileError(f"{source}: a URDF with a DOCTYPE or entities is not read")
    try:
        root = ElementTree.fromstring(text)
    except ElementTree.ParseError as err:
        raise RobotFileError(f"{source}: not valid XML ({err})") from None
    if root.tag != "robot":
        raise RobotFileError(f"{source}: the top element is <{root.tag}>, not <robot>")
    name = root.get("name") or Path(source).stem
    links = [link.get("name", "") for link in root.findall("link")]
    if not links or "" in links:
        raise RobotFileError(f"{source}: every <link> needs a name, and a robot at least one link")
    twice = _twice(links)
    if twice is not None:
        raise RobotFileError(f"{source}: link {twice!r} is defined twice")
    index = {n: i for i, n in enumerate(links)}
    elements = root.findall("joint")
    if len(elements) > MAX_JOINTS:
        raise RobotFileError(f"{source}: {len(elements)} joints; at most {MAX_JOINTS} are read")
    joints: list[Joint] = []
    for element in elements:
        joint = _joint(element, index, source)
        if joint is not None:
            moving = sum(j.index >= 0 for j in joints)
            joints.append(replace(joint, index=moving) if joint.kind in MOVING else joint)
    twice = _twice([j.name for j in joints])
    if twice is not None:
        raise RobotFileError(f"{source}: joint {twice!r} is defined twice")
    capsules = _fixed_fallback(root.findall("link"), joints, source)
    return RobotModel(name, tuple(links), _tree_order(joints, links, source), _root(joints, links, source), capsules)


def _fixed_fallback(elements, joints: list[Joint], source: str) -> tuple[Capsule, ...]:
    """Every link's capsules; a mesh link too light for its own fit (a shape hung on a fixed
    joint, as G1's pelvis_contour_link on its pelvis) takes its fixed parent's fit, where the
    parent has no shape of its own and no other such child took it."""
    found, wanting = [], []
    fits = [_inertial_capsule(el, i, f"{source}: link {el.get('name')!r}") for i, el in enumerate(elements)]
    for i, element in enumerate(elements):
        own, needs_fit = _capsules(element, i, source)
        found += own
        if needs_fit and fits[i]:
            found += fits[i]
        elif needs_fit:
            wanting.append(i)
    fixed_parent = {j.child: j for j in joints if j.kind == "fixed"}
    shaped = {c.link for c in found}  # a parent with shapes of its own keeps them (G1's torso and its logo)
    for link in wanting:
        joint = fixed_parent.get(link)
        if joint is not None and fits[joint.parent] and joint.parent not in shaped:
            shaped.add(joint.parent)
            back = np.linalg.inv(joint.origin)  # the parent's frame into the link's
            for c in fits[joint.parent]:
                a, b = (back[:3, :3] @ p + back[:3, 3] for p in (c.a, c.b))
                found.append(Capsule(link, a, b, c.radius))
    return tuple(found)


def _origin(element, where: str) -> np.ndarray:
    """An <origin>'s transform (4, 4) (identity where there is none)."""
    origin_el = element.find("origin") if element is not None else None
    xyz = _numbers(origin_el.get("xyz") if origin_el is not None else None, 3, 0.0, f"{where} origin xyz", MAX_OFFSET)
    rpy = _numbers(origin_el.get("rpy") if origin_el is not None else None, 3, 0.0, f"{where} origin rpy", MAX_OFFSET)
    origin = np.eye(4)
    origin[:3, :3], origin[:3, 3] = rpy_matrix(*rpy), xyz
    return origin


def _capsules(link_el, link: int, source: str) -> tuple[list[Capsule], bool]:
    """A link's collision shapes as capsules: a cylinder's axis, a sphere's centre, a box's
    longest side (its radius half the middle side); for a mesh, whose file is not read, the
    solid cylinder with the link's mass and inertia (its smallest principal moment about the
    long axis). Shapes under MIN_RADIUS (contact points) and massless links are left out.
    (primitive capsules, whether a mesh asks for the inertial fit)"""
    where = f"{source}: link {link_el.get('name')!r} collision"
    found: list[Capsule] = []
    fitted = False
    for collision in link_el.findall("collision"):
        geometry = collision.find("geometry")
        if geometry is None or not len(geometry):
            continue
        shape, frame = geometry[0], _origin(collision, where)
        half, radius = 0.0, 0.0
        if shape.tag == "cylinder":
            radius = float(_numbers(shape.get("radius"), 1, 0.0, f"{where} radius", MAX_OFFSET)[0])
            length = float(_numbers(shape.get("length"), 1, 0.0, f"{where} length", MAX_OFFSET)[0])
            axis, half = frame[:3, 2], max(length / 2 - radius, 0.0)
        elif shape.tag == "sphere":
            radius = float(_numbers(shape.get("radius"), 1, 0.0, f"{where} radius", MAX_OFFSET)[0])
            axis = frame[:3, 2]
        elif shape.tag == "box":
            size = np.abs(_numbers(shape.get("size"), 3, 0.0, f"{where} size", MAX_OFFSET))
            order = np.argsort(size)
            radius = float(size[order[1]]) / 2
            axis, half = frame[:3, order[2]], max(float(size[order[2]]) / 2 - radius, 0.0)
        elif shape.tag == "mesh":
            fitted = True
            continue
        else:
            continue
        if radius >= MIN_RADIUS:
            centre = frame[:3, 3]
            found.append(Capsule(link, centre - half * axis, centre + half * axis, radius))
    return found, fitted


def _inertial_capsule(link_el, link: int, where: str) -> list[Capsule]:
    """The solid cylinder of the link's mass and inertia, as a capsule (none for a link under
    MIN_MASS or without an inertia): radius^2 = 2 I_long / m, length^2 = 12 I_cross / m - 3 r^2."""
    inertial = link_el.find("inertial")
    mass_el = inertial.find("mass") if inertial is not None else None
    tensor_el = inertial.find("inertia") if inertial is not None else None
    if mass_el is None or tensor_el is None:
        return []
    mass = float(_numbers(mass_el.get("value"), 1, 0.0, f"{where} mass", 1e6)[0])
    keys = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
    xx, xy, xz, yy, yz, zz = (float(_numbers(tensor_el.get(k), 1, 0.0, f"{where} {k}", 1e6)[0]) for k in keys)
    if mass < MIN_MASS:
        return []
    frame = _origin(inertial, where)
    tensor = frame[:3, :3] @ np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]) @ frame[:3, :3].T
    moments, axes = np.linalg.eigh(tensor)
    if not np.all(np.isfinite(moments)) or moments[0] <= 0.0:
        return []
    radius = math.sqrt(2.0 * moments[0] / mass)
    length = math.sqrt(max(12.0 * (moments[1] + moments[2]) / 2 / mass - 3.0 * radius**2, 0.0))
    half, centre = max(length / 2 - radius, 0.0), frame[:3, 3]
    if radius < MIN_RADIUS:
        return []
    return [Capsule(link, centre - half * axes[:, 0], centre + half * axes[:, 0], radius)]


def _twice(names: list[str]) -> str | None:
    """The first name that appears twice (in linear time: a URDF may hold many thousands)."""
    counts = Counter(names)
    return next((n for n in names if counts[n] > 1), None)


def _joint(element, index: dict[str, int], source: str) -> Joint | None:
    name, kind = element.get("name", ""), element.get("type", "")
    where = f"{source}: joint {name!r}"
    if not name:
        raise RobotFileError(f"{source}: a <joint> without a name")
    parent_el, child_el = element.find("parent"), element.find("child")
    parent = parent_el.get("link", "") if parent_el is not None else ""
    child = child_el.get("link", "") if child_el is not None else ""
    if kind in FREE and parent not in index:
        return None
    if kind not in MOVING + ("fixed",):
        raise RobotFileError(f"{where}: type {kind!r} is not one of {', '.join(MOVING + ('fixed',) + FREE)}")
    for role, link in (("parent", parent), ("child", child)):
        if link not in index:
            raise RobotFileError(f"{where}: its {role} link {link!r} is not defined")
    origin_el = element.find("origin")
    xyz = _numbers(origin_el.get("xyz") if origin_el is not None else None, 3, 0.0, f"{where} origin xyz", MAX_OFFSET)
    rpy = _numbers(origin_el.get("rpy") if origin_el is not None else None, 3, 0.0, f"{where} origin rpy", MAX_OFFSET)
    origin = np.eye(4)
    origin[:3, :3], origin[:3, 3] = rpy_matrix(*rpy), xyz
    axis_el = element.find("axis")
    axis = _numbers(axis_el.get("xyz") if axis_el is not None else None, 3, 0.0, f"{where} axis", MAX_AXIS)
    if axis_el is None:
        axis = np.array([1.0, 0.0, 0.0])  # URDF's default
    if kind != "fixed" and np.linalg.norm(axis) < 1e-9:
        raise RobotFileError(f"{where}: its axis is zero")
    axis = axis / max(np.linalg.norm(axis), 1e-12)
    lower, upper = -math.inf, math.inf
    if kind in ("revolute", "prismatic"):
        limit = element.find("limit")
        if limit is None or limit.get("lower") is None or limit.get("upper") is None:
            raise RobotFileError(f"{where}: a {kind} joint needs <limit lower=... upper=...>")
        bound = MAX_OFFSET if kind == "prismatic" else math.inf  # a slide of 1e308 m overflows the kinematics
        lower, upper = (
            float(_numbers(limit.get(k), 1, 0.0, f"{where} limit {k}", bound)[0]) for k in ("lower", "upper")
        )
        if lower > upper:
            raise RobotFileError(f"{where}: its lower limit {lower:g} is above its upper limit {upper:g}")
    velocity = math.inf
    limit = element.find("limit")
    if kind in MOVING and limit is not None and limit.get("velocity") is not None:
        velocity = float(_numbers(limit.get("velocity"), 1, 0.0, f"{where} limit velocity", 1e6)[0])
        velocity = velocity if velocity > 0 else math.inf  # 0: none given (as some exporters write)
    return Joint(name, kind, index[parent], index[child], origin, axis, lower, upper, velocity=velocity)


def _root(joints: list[Joint], links: list[str], source: str) -> int:
    children = {j.child for j in joints}
    roots = [i for i in range(len(links)) if i not in children]
    if len(roots) != 1:
        what = "no link without a parent (a loop)" if not roots else f"{len(roots)} links without a parent"
        raise RobotFileError(f"{source}: a robot is one tree; found {what}")
    return roots[0]


def _tree_order(joints: list[Joint], links: list[str], source: str) -> tuple[Joint, ...]:
    """Joints with each parent link placed before its children: a link with two parents, a
    loop or a link no joint reaches is an error."""
    parents: dict[int, Joint] = {}
    for joint in joints:
        if joint.child in parents:
            raise RobotFileError(f"{source}: link {links[joint.child]!r} has two parent joints (a loop)")
        parents[joint.child] = joint
    root = _root(joints, links, source)
    by_parent: dict[int, list[Joint]] = {}
    for joint in joints:
        by_parent.setdefault(joint.parent, []).append(joint)
    ordered: list[Joint] = []
    todo = [root]
    while todo:
        link = todo.pop()
        for joint in by_parent.get(link, []):
            ordered.append(joint)
            todo.append(joint.child)
    if len(ordered) != len(joints):
        lost = sorted({links[j.child] for j in joints} - {links[j.child] for j in ordered})
        raise RobotFileError(f"{source}: links {', '.join(map(repr, lost[:3]))} are not connected to the root (a loop)")
    return tuple(ordered)
