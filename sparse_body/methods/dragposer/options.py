"""DragPoser's options: the search's and its optimiser's (estimator.py says what each does)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ...estimators.options import EstimatorOptions, floor_height, option, threads

TRACKER_PRIOR_WEIGHT = 0.001  # chosen on the validation people (models/dragposer.tracker_prior_*.json)


def iterations(default: int = 3) -> Any:
    """The search's step count, an option of DragPoser and of any estimator it refines."""
    return option(default, "search steps a frame at most", 1, 100, "steps")


@dataclass(frozen=True)
class DragPoserOptions(EstimatorOptions):
    # one option for the models: the nodes' model_path names a file, a user's folder names a folder
    model_path: str | None = option(
        None, "the folder of the DragPoser models, or one of its files; null: the shipped ones"
    )
    iterations: int = iterations()
    position_weight: float = option(1.0, "the trackers' position residual's weight", 0.0, 1e3)
    orientation_weight: float = option(0.1, "the trackers' orientation residual's weight", 0.0, 1e3)
    floor_height: float | None = floor_height()
    tolerance: float = option(0.01, "the search ends with every tracker this near", 0.0, 1.0, "metres")
    rotation_tolerance: float = option(
        0.087, "the search ends with every tracker turned this little", 0.0, 3.1416, "radians"
    )
    threads: int = threads()
    temporal_weight: float = option(
        0.002, "the temporal predictor's pull on the latent (the paper's lambda_T); 0: none", 0.0, 10.0
    )
    ahead: int = option(1, "frames the temporal predictor looks ahead", 1, 16, "frames")
    temporal_ramp: bool = option(True, "the temporal target ramps from the solved latent to the prediction")
    polish: bool = option(True, "bring the tracked ends onto their trackers by IK after the search")
    pelvis_orientation: bool = option(True, "a pelvis tracker's orientation turns the root")
    root_prior: float = option(0.3, "the pull of the root towards where the trackers put it", 0.0, 100.0)
    tracker_prior: float = option(TRACKER_PRIOR_WEIGHT, "the tracker prior's pull on the latent; 0: none", 0.0, 100.0)
    cost_tolerance: float = option(
        1e-3, "the search ends when the next step would lower the cost by less than this share", 0.0, 1.0
    )
    compiled: bool = option(
        True, "the compiled search (false: the ONNX Runtime search it is tested against)", experiment=True
    )
    # the optimiser's (LatentOptimizer)
    damping: float = option(1e-2, "the Levenberg-Marquardt damping it starts from", 1e-9, 1e6)
    prior_weight: float = option(0.001, "the pull towards the last frame's latent", 0.0, 10.0)
    latent_weight: float = option(0.0002, "the pull towards the latent's origin", 0.0, 10.0)
    eps: float = option(1e-3, "the finite-difference step", 1e-9, 1.0)
