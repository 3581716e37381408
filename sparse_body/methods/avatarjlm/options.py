"""AvatarJLM's options (estimator.py says what each part does)."""

from __future__ import annotations

from dataclasses import dataclass

from ...estimators.options import EstimatorOptions, floor_height, max_gap, model_path, option, threads


@dataclass(frozen=True)
class AvatarJlmOptions(EstimatorOptions):
    model: str = option(
        "auto",
        "the shipped model (auto: four_point with a pelvis tracker)",
        choices=("auto", "three_point", "four_point"),
    )
    model_path: str | None = model_path()
    polish: bool = option(
        True, "bring head and hands onto their trackers by IK, keeping the network's spine and elbows"
    )
    end_orientations: bool = option(True, "head and hands take their trackers' orientation")
    hinge_knees: bool = option(True, "the knees are hinges (no shin turned about its length)")
    legs_from_positions: bool | None = option(
        None, "rebuild hips and knees from the network's joint positions; null: where the model's legs come out turned"
    )
    floor_height: float = floor_height()
    max_gap: float = max_gap()
    threads: int = threads()
