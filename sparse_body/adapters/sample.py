"""One tracker reading as the adapters deliver it (no ROS types)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class TrackerSample:
    """A device's pose in the tracking space, REP-103 (x forward, y left, z up, metres).

    position is None for orientation-only devices (IMUs): nothing downstream invents one.
    """

    device: str  # the device's own name or id, mapped to a body site later
    stamp: float  # host time, seconds
    orientation: np.ndarray  # (4,) x y z w, unit
    position: np.ndarray | None = None


def valid_pose(position, orientation) -> bool:
    """Finite values and a quaternion that is a rotation (norm within 10 % of 1)."""
    q = np.asarray(orientation, dtype=float)
    if q.shape != (4,) or not np.all(np.isfinite(q)) or not 0.9 < np.linalg.norm(q) < 1.1:
        return False
    if position is None:
        return True
    p = np.asarray(position, dtype=float)
    return p.shape == (3,) and bool(np.all(np.isfinite(p))) and bool(np.all(np.abs(p) < 1e4))
