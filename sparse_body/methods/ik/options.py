"""The closed-form IK's options."""

from __future__ import annotations

from dataclasses import dataclass

from ...estimators.options import EstimatorOptions, floor_height


@dataclass(frozen=True)
class IkOptions(EstimatorOptions):
    floor_height: float = floor_height()
