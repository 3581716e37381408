"""The robot's links as TF transforms, as robot_state_publisher with `frame_prefix` would put
them, for the retarget node and the estimate bag alike (one builder: the bag is what the node
sent). The fixed frame holds the mapping's base link (where the solver places the robot); every
other link hangs from its neighbour on the way to the base, so the tree also holds when the base
is not the URDF's root but fixed below it (a TF frame has one parent).

Without robot_state_publisher installed (or with it, under a name of its own) a viewer then
draws the robot from its URDF on `robot/robot_description` and these frames alone.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np

from ..core.rotations import matrix_to_quat, quat_to_matrix
from ..robot.retarget import HumanoidRetarget
from .output import TransformTable, published_precision
from .topics import ROBOT_PREFIX


class RobotLinks:
    """link_table(commands, bases) -> the TransformTable of a robot's every link."""

    def __init__(self, retarget: HumanoidRetarget, fixed_frame: str, prefix: str = ROBOT_PREFIX) -> None:
        self.retarget, self.fixed_frame, self.prefix = retarget, fixed_frame, prefix

    @cached_property
    def edges(self) -> tuple[tuple[int, int], ...]:
        """(parent, child) link pairs, from the base outwards (each link once, as a child)."""
        model = self.retarget.model
        neighbours: dict[int, list[int]] = {}
        for joint in model.joints:
            neighbours.setdefault(joint.parent, []).append(joint.child)
            neighbours.setdefault(joint.child, []).append(joint.parent)
        found, order, seen = [self.retarget.base], [], {self.retarget.base}
        while found:
            link = found.pop(0)
            for other in neighbours.get(link, []):
                if other not in seen:
                    seen.add(other)
                    order.append((link, other))
                    found.append(other)
        return tuple(order)

    def link_table(self, commands: np.ndarray, bases: np.ndarray, world: np.ndarray | None = None) -> TransformTable:
        """fixed frame -> <prefix><base link>, then every link under its neighbour towards the
        base, for joint commands (frames, moving joints) and base poses (frames, 7: position,
        then quaternion x y z w), as a RobotPose gives them; world: their link transforms
        (frames, links, 4, 4) where the caller has them already (the node checks collisions
        on them), so they are not computed twice."""
        links = self.retarget.model.links
        commands, bases = np.atleast_2d(commands), np.atleast_2d(bases)
        values = np.empty((len(commands), 1 + len(self.edges), 7))
        values[:, 0] = bases
        parents = np.array([p for p, _ in self.edges], int)
        children = np.array([c for _, c in self.edges], int)
        for i, (q, base) in enumerate(zip(commands, bases, strict=True)):
            placed = (
                world[i] if world is not None else self.retarget.link_transforms(q, base[:3], quat_to_matrix(base[3:]))
            )
            relative = np.linalg.inv(placed[parents]) @ placed[children]
            values[i, 1:, :3] = relative[:, :3, 3]
            values[i, 1:, 3:] = matrix_to_quat(relative[:, :3, :3])
        names = (self.fixed_frame,) + tuple(self.prefix + links[p] for p in parents)
        return TransformTable(
            names,
            (self.prefix + links[self.retarget.base],) + tuple(self.prefix + links[c] for c in children),
            published_precision(values),
        )
