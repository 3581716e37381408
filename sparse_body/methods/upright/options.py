"""upright's options (estimator.py says what the tilt is and how the pose is handed over)."""

from __future__ import annotations

from dataclasses import dataclass

from ...estimators.options import EstimatorOptions, option


@dataclass(frozen=True)
class UprightOptions(EstimatorOptions):
    base: str = option("blend", "the estimator that estimates the body, shown it stood up as it lies down")
    fallback: str = option(
        "",
        "an estimator handed the pose as the body lies down; empty: the base, shown the body stood up",
        experiment=True,  # the first form of upright (LoBSTr handed to IK), kept to compare with
    )
    upright_within: float = option(45.0, "torso tilt up to which the base has the body as it is", 0.0, 180.0, "degrees")
    lying_from: float = option(
        70.0, "torso tilt from which the whole tilt is taken out (or the fallback has the pose)", 0.0, 180.0, "degrees"
    )
    # the band chosen by the worst kind over the selection, the floor part and cmu-extra
    # (docs/methods.md, "The default estimator"), with the AvatarJLM trained off its feet too:
    # 0.55-0.75 0.90x IK's leg error on the floor part's worst kind, 0.5-0.7 0.94x, 0.4-0.6
    # 0.95x (0.97x, 1.01x, 1.14x before); the selection and cmu-extra alike for each
    low_below: float = option(
        0.55, "pelvis height (share of a standing one's) under which a tilted body counts as lying", 0.0, 2.0
    )
    high_from: float = option(0.75, "pelvis height (share of a standing one's) from which it never does", 0.0, 2.0)
    settle: float = option(0.2, "the time constant of the share of the tilt taken out", 0.0, 10.0, "seconds")

    def check_together(self) -> None:
        from ..factory import check_estimator_name

        check_estimator_name(self.base, "upright's base")  # before either is made
        if self.fallback:
            check_estimator_name(self.fallback, "upright's fallback")
        if "upright" in (self.base, self.fallback):
            raise ValueError("upright's estimators cannot be 'upright'")
        if self.lying_from <= self.upright_within:
            raise ValueError(f"lying_from ({self.lying_from}) must be above upright_within ({self.upright_within})")
        if self.high_from <= self.low_below:
            raise ValueError(f"high_from ({self.high_from}) must be above low_below ({self.low_below})")
