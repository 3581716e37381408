"""The one interface every estimator implements, and the registry that names them."""
from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from typing import ClassVar

from ..core.sensors import SensorConfig
from ..core.skeleton import Skeleton
from ..core.types import BodyPose, TrackerFrame, TrackerStream

# name -> "module:Class"; modules are imported on first use so that an estimator's
# dependencies (onnxruntime, a model file) are needed only when it is chosen.
ESTIMATORS: dict[str, str] = {
    "reference": "sparse_body.estimators.reference:ReferenceEstimator",
    "ik": "sparse_body.estimators.ik:IKEstimator",
}


class Estimator(ABC):
    """Streaming whole-body estimation: reset(), then step() once per tracker frame.

    step() never raises on bad tracker values and never returns non-finite numbers: with too
    little usable input it returns its last pose with valid=False.
    """

    name: ClassVar[str]
    # Sites the method cannot work without (checked against the sensor configuration).
    required_sites: ClassVar[frozenset[str]] = frozenset()

    def __init__(self, sensors: SensorConfig, skeleton: Skeleton, fps: float = 60.0) -> None:
        missing = self.required_sites - set(sensors.site_names)
        if missing:
            raise ValueError(f"estimator {self.name!r} needs trackers on {', '.join(sorted(missing))}; "
                             f"sensor configuration {sensors.name!r} has {', '.join(sensors.site_names)}")
        self.sensors = sensors
        self.skeleton = skeleton
        self.fps = fps

    @abstractmethod
    def reset(self) -> None:
        """Forget all history (a new take, a clock jump back)."""

    @abstractmethod
    def step(self, frame: TrackerFrame) -> BodyPose:
        """The body at frame.stamp."""

    def process(self, stream: TrackerStream) -> list[BodyPose]:
        self.reset()
        return [self.step(frame) for frame in stream]


def create_estimator(name: str, sensors: SensorConfig, skeleton: Skeleton, fps: float = 60.0,
                     **options) -> Estimator:
    try:
        target = ESTIMATORS[name]
    except KeyError:
        raise ValueError(f"unknown estimator {name!r}; available: {', '.join(sorted(ESTIMATORS))}") from None
    module, cls = target.split(":")
    return getattr(importlib.import_module(module), cls)(sensors, skeleton, fps=fps, **options)
