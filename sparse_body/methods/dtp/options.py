"""DTP's options (estimator.py says what each part does)."""

from __future__ import annotations

from dataclasses import dataclass

from ...estimators.options import EstimatorOptions, floor_height, max_gap, model_path, option, threads


@dataclass(frozen=True)
class DtpOptions(EstimatorOptions):
    model: str = option("online", "the shipped model", choices=("online", "lookahead", "pretrained"))
    model_path: str | None = model_path()
    polish: bool = option(True, "bring head, hands and tracked feet onto their trackers by IK")
    foot_trust: float = option(
        0.4, "metres between a foot tracker and the network's foot fully trusted", 0.0, 5.0, "metres"
    )
    foot_speed: float = option(8.0, "a foot tracker jumping faster than this is not followed", 0.0, 100.0, "m/s")
    end_orientations: bool = option(True, "head and hands take their trackers' orientation")
    floor_height: float = floor_height()
    max_gap: float = max_gap()
    threads: int = threads()
