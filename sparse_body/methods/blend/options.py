"""blend's options (estimator.py says how the share is handed over)."""

from __future__ import annotations

from dataclasses import dataclass

from ...estimators.options import EstimatorOptions, option


@dataclass(frozen=True)
class BlendOptions(EstimatorOptions):
    first: str = option("avatarjlm", "the estimator whose pose the blend starts from (and whose contacts it gives)")
    second: str = option("dragposer", "the estimator blended in")
    weight: float = option(0.7, "the second estimator's share while the two agree", 0.0, 1.0)
    agree_within: float = option(
        0.15, "leg disagreement (mean joint distance) with the full share", 0.0, 10.0, "metres"
    )
    disagree_from: float = option(0.25, "leg disagreement with no share", 0.0, 10.0, "metres")
    settle: float = option(0.1, "the share's time constant", 0.0, 10.0, "seconds")
    parallel: bool = option(True, "the first estimator steps in a worker thread beside the second")

    def check_together(self) -> None:
        from ..factory import check_estimator_name

        check_estimator_name(self.first, "blend's first")  # before either is made
        check_estimator_name(self.second, "blend's second")
        if "blend" in (self.first, self.second):
            raise ValueError("a blend's estimators cannot be 'blend'")
        if self.disagree_from <= self.agree_within:
            raise ValueError(f"disagree_from ({self.disagree_from}) must be above agree_within ({self.agree_within})")
