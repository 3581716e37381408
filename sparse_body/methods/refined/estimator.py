"""Any estimator followed by DragPoser's latent-space refinement: `refined:base=ik`.

The base estimator gives the pose; the refinement encodes it, then moves it in the pose
VAE's latent space until the end effectors sit on their trackers. This is what the
constraint node does live, packaged as an estimator for `sparse-body eval` and `process`.
"""

from __future__ import annotations

from ...core.tracker_filter import NO_FILTER
from ...estimators.base import Estimator
from ..dragposer.estimator import DragPoserEstimator
from ..factory import create_estimator
from .options import RefinedOptions


class RefinedEstimator(Estimator):
    name = "refined"
    Options = RefinedOptions
    options: RefinedOptions

    def __init__(self, sensors, skeleton, fps: float = 60.0, **options) -> None:
        super().__init__(sensors, skeleton, fps, **options)
        o = self.options
        base = o.base
        if base == "refined":
            raise ValueError("a refined estimator's base cannot be 'refined'")
        # the base's legs unheld: the search moves them, and this estimator's foot_lock holds the result
        self.base = create_estimator(base, sensors, skeleton, fps, foot_lock=False, **RefinedOptions.rest(options))
        self.base.use_filter(NO_FILTER)  # this estimator's filter has done it
        self.refiner = DragPoserEstimator(
            sensors,
            skeleton,
            fps,
            model_path=o.model_path,
            iterations=o.iterations,
            temporal_weight=0.0,
            tracker_prior=0.0,
        )  # the base pose is the prior
        for inner in (self.base, self.refiner):  # this estimator's targets: the lost-tracker options hold
            inner.read_targets_from(self)

    def _reset(self) -> None:
        self.base.reset()
        self.refiner.reset()

    def _estimate(self, frame):
        pose = self.base.step(frame)
        if not pose.valid:
            return pose
        refined = self.refiner.refine(pose, frame)
        if not refined.valid:
            return pose.held(frame.stamp)  # the base's pose, marked invalid
        refined.contact, refined.contact_probability = pose.contact, pose.contact_probability
        return refined
