"""Constraints on a body pose, as residuals a least-squares optimiser drives to zero.

DragPoser's pose optimiser (and the constraint node) hold a list of these and can add or
remove them at any time. Each one maps a batch of poses — global rotations (..., 22, 3, 3),
joint positions (..., 22, 3) and local rotations — to a residual vector (..., k), already
weighted. The code works on numpy arrays and on torch tensors alike (`xp` is the module),
so the Gauss-Newton runtime and the autograd reference share one definition.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...core.skeleton import JOINT_INDEX


def _as(xp, like, value):
    value = np.asarray(value, dtype=np.float64)
    return value if xp is np else xp.as_tensor(value, dtype=like.dtype)


def _relu(x):
    return x * (x > 0)


def _vee(m):
    """The axis-angle-like vector of a nearly-identity rotation's antisymmetric part."""
    return 0.5 * (m[..., [2, 0, 1], [1, 2, 0]] - m[..., [1, 2, 0], [2, 0, 1]])


def _joint(name_or_index) -> int:
    if isinstance(name_or_index, str):
        if name_or_index not in JOINT_INDEX:
            raise ValueError(f"unknown joint {name_or_index!r}")
        return JOINT_INDEX[name_or_index]
    return int(name_or_index)


@dataclass
class Constraint:
    size = 3  # residual entries
    joint: int | str
    weight: float = 1.0
    name: str = ""  # to remove it again; defaults to a description

    def __post_init__(self) -> None:
        self.joint = _joint(self.joint)
        if not np.isfinite(self.weight) or self.weight < 0:
            raise ValueError(f"constraint weight must be finite and non-negative, got {self.weight}")
        self.name = self.name or f"{type(self).__name__.lower()}:{self.joint}"

    def residual(self, glob, pos, local, xp=np):
        raise NotImplementedError


@dataclass
class Position(Constraint):
    """The joint at a point (metres): a 6-DoF or a position-only tracker."""

    target: tuple = (0.0, 0.0, 0.0)

    def residual(self, glob, pos, local, xp=np):
        return self.weight * (pos[..., self.joint, :] - _as(xp, pos, self.target))


@dataclass
class OverPoint(Constraint):
    """The joint over a point on the floor plane (x, y in metres), at any height: a soft
    prior where no tracker says where the joint is (DragPoser's root_prior)."""

    size = 2
    target: tuple = (0.0, 0.0)

    def residual(self, glob, pos, local, xp=np):
        return self.weight * (pos[..., self.joint, :2] - _as(xp, pos, self.target))


@dataclass
class Orientation(Constraint):
    """The joint's global rotation (3x3): a 6-DoF or an orientation-only (IMU) tracker.
    Residual: sin(angle) x axis of the difference, so 1 rad weighs like 0.84 m at weight 1."""

    target: np.ndarray = field(default_factory=lambda: np.eye(3))

    def residual(self, glob, pos, local, xp=np):
        target = _as(xp, glob, self.target)
        return self.weight * _vee(target.swapaxes(-1, -2) @ glob[..., self.joint, :, :])


@dataclass
class AboveFloor(Constraint):
    """The joint no lower than the floor height plus a clearance (feet on or above the floor)."""

    size = 1
    height: float = 0.0

    def residual(self, glob, pos, local, xp=np):
        return self.weight * _relu(self.height - pos[..., self.joint, 2:3])


@dataclass
class LookAt(Constraint):
    """The joint's local axis (default +x, forward) pointing at a point."""

    target: tuple = (0.0, 0.0, 0.0)
    axis: tuple = (1.0, 0.0, 0.0)

    def residual(self, glob, pos, local, xp=np):
        d = _as(xp, pos, self.target) - pos[..., self.joint, :]
        d = d / (((d**2).sum(-1, keepdims=True)) ** 0.5 + 1e-9)
        a = glob[..., self.joint, :, :] @ _as(xp, pos, self.axis)
        return self.weight * (a - d)


@dataclass
class AngleLimit(Constraint):
    """The joint's local rotation no further than max_angle (radians) from its rest."""

    size = 1
    max_angle: float = 2.0

    def residual(self, glob, pos, local, xp=np):
        # 3 - trace = 2 (1 - cos angle): monotonic in the angle, smooth, no arccos
        excess = (3.0 - local[..., self.joint, [0, 1, 2], [0, 1, 2]].sum(-1, keepdims=True)) - 2.0 * (
            1.0 - np.cos(self.max_angle)
        )
        return self.weight * _relu(excess)


class ConstraintSet:
    """Named constraints, added and removed while the optimiser runs. Built-in ones (the
    estimator's own, e.g. the feet above the floor) are told apart from the user's."""

    def __init__(self) -> None:
        self._items: dict[str, Constraint] = {}
        self._builtin: set[str] = set()

    def add(self, constraint: Constraint, builtin: bool = False) -> None:
        self._items[constraint.name] = constraint
        (self._builtin.add if builtin else self._builtin.discard)(constraint.name)

    def remove(self, name: str) -> bool:
        self._builtin.discard(name)
        return self._items.pop(name, None) is not None

    def user_names(self) -> list[str]:
        """The constraints a user added (set_constraint), not the built-in ones."""
        return [n for n in self._items if n not in self._builtin]

    def clear(self) -> None:
        self._items.clear()
        self._builtin.clear()

    def __iter__(self):
        return iter(list(self._items.values()))

    def __len__(self) -> int:
        return len(self._items)

    def names(self) -> list[str]:
        return list(self._items)

    def converged(
        self, residual: np.ndarray, position_tol: float, rotation_tol: float, skip_orientation: frozenset = frozenset()
    ) -> bool:
        """Whether the tracker constraints in a residual vector (this set's order) are met:
        positions within position_tol metres, orientations within rotation_tol radians
        (except on the joints in skip_orientation)."""
        i = 0
        for c in self:
            part = residual[i : i + c.size]
            i += c.size
            if c.weight == 0:
                continue
            err = np.linalg.norm(part) / c.weight
            if isinstance(c, Position) and err > position_tol:
                return False
            if isinstance(c, Orientation) and c.joint not in skip_orientation and err > np.sin(rotation_tol):
                return False
        return True

    def residual(self, glob, pos, local, xp=np):
        parts = [c.residual(glob, pos, local, xp) for c in self]
        if not parts:
            return glob[..., 0, 0, :0]
        return np.concatenate(parts, axis=-1) if xp is np else xp.cat(parts, dim=-1)
