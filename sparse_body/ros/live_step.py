"""One live estimate from a tracker frame, and what estimate_status says of it: the
estimator's pose within the step's budget (or budget_fallback's, estimators/budget.py), the
last good pose held where the step fails or gives something non-finite, and why. ROS-free:
the estimator node publishes what this gives.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..core.rotations import matrix_to_quat
from ..core.skeleton import standing_pose
from ..core.types import BodyPose, TrackerFrame
from ..estimators.budget import BudgetedStep
from .estimate_stats import EstimateStats

# how estimate_status begins for a valid pose made by budget_fallback (the step over its budget)
OVER_BUDGET = "over budget:"
# how it begins for a valid pose of a frame the estimator says lay outside the motion it knows
# (Estimator.out_of_depth: upright's torso tilted past upright_within), the share following
OUT_OF_DEPTH = "out of depth"


class LiveStep:
    """step(frame, deadline) -> (pose, what estimate_status says of it: empty for a valid pose
    of the estimator's own within its depth)."""

    def __init__(self, budgeted: BudgetedStep, stats: Callable[[], EstimateStats], method: str, budget: float) -> None:
        self.budgeted, self._stats, self.method, self.budget = budgeted, stats, method, budget
        self.last_good: BodyPose | None = None

    def step(self, frame: TrackerFrame, deadline: float) -> tuple[BodyPose, str]:
        """The estimator's pose for frame, or budget_fallback's where the step is not done by
        the deadline (finite: a failure holds the last good pose), and why it is held, or that
        the fallback made it, or how far out of its depth the estimator was."""
        stats = self._stats()
        try:
            pose, over_budget = self.budgeted.step(frame, deadline)
            if not pose.is_finite():
                raise FloatingPointError("estimator returned non-finite values")
        except Exception as err:  # noqa: BLE001 - a failing step must not take the node down
            stats.error(f"{type(err).__name__}: {err}")
            self.budgeted.reset()
            return self.held(frame.stamp), "estimator error; held"
        if over_budget:
            stats.over_budget += 1
        if pose.valid:
            self.last_good = pose
        if over_budget and pose.valid:  # a held one says why it is held
            assert self.budgeted.fallback is not None
            return pose, (
                f"{OVER_BUDGET} {self.budgeted.fallback.name}'s pose: {self.method} took over "
                f"{self.budget * 1000:.1f} ms"
            )
        depth = self.budgeted.estimator.out_of_depth() if pose.valid else None
        if depth is not None and depth[0] > 0.0:
            return pose, f"{OUT_OF_DEPTH} {depth[0]:.2f}: {depth[1]}"
        return pose, ""

    def held(self, stamp: float) -> BodyPose:
        """The last good pose at `stamp`, marked invalid (a standing body before any)."""
        if self.last_good is None:
            return BodyPose(stamp, matrix_to_quat(standing_pose()), np.zeros(3), valid=False)
        return self.last_good.held(stamp)

    def reset(self) -> None:
        self.budgeted.reset()
