"""The reference estimator's options: none (a standing pose turned to the headset)."""

from __future__ import annotations

from dataclasses import dataclass

from ...estimators.options import EstimatorOptions


@dataclass(frozen=True)
class ReferenceOptions(EstimatorOptions):
    pass
