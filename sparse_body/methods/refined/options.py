"""The refinement's own options; any other is its base estimator's."""

from __future__ import annotations

from dataclasses import dataclass

from ...estimators.options import EstimatorOptions, option
from ..dragposer.options import iterations


@dataclass(frozen=True)
class RefinedOptions(EstimatorOptions):
    passes_on = True  # options it has not are the base's (checked there)
    base: str = option("ik", "the estimator whose pose is refined")
    model_path: str | None = option(None, "the DragPoser models' folder, or one of its files; null: the shipped ones")
    iterations: int = iterations()
