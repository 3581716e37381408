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
    settle: float = option(
        0.0, "the search's turn from the base pose follows with this time constant (0: at once)", 0.0, 10.0, "seconds"
    )
    only_legs: bool = option(False, "the search gives the legs only; the rest of the body stays the base's")

    def check_together(self) -> None:
        from ..factory import check_estimator_name

        check_estimator_name(self.base, "refined's base")
        if self.base == "refined":
            raise ValueError("a refined estimator's base cannot be 'refined'")
