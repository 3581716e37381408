"""upright's options (estimator.py says what the tilt is and how the pose is handed over)."""

from __future__ import annotations

from dataclasses import dataclass

from ...estimators.options import EstimatorOptions, option


@dataclass(frozen=True)
class UprightOptions(EstimatorOptions):
    base: str = option("lobstr", "the estimator used while the body is upright (a regressor trained on upright motion)")
    fallback: str = option("ik", "the estimator handed the pose as the body lies down")
    upright_within: float = option(45.0, "torso tilt up to which the base has the whole pose", 0.0, 180.0, "degrees")
    lying_from: float = option(70.0, "torso tilt from which the fallback has the whole pose", 0.0, 180.0, "degrees")
    settle: float = option(0.2, "the hand-over's time constant", 0.0, 10.0, "seconds")
