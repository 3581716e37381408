"""The one interface every estimator implements, and the registry that names them."""

from __future__ import annotations

import inspect
import math
from abc import ABC, abstractmethod
from collections.abc import Iterable
from typing import ClassVar, TypeGuard

import numpy as np
import yaml

from ..core.rotations import matrix_to_quat
from ..core.sensors import SensorConfig
from ..core.skeleton import Skeleton, standing_pose
from ..core.tracker_filter import FilterConfig, TrackerFilter, filter_config
from ..core.tracker_smoother import smooth_frames
from ..core.types import BodyPose, TrackerFrame, TrackerStream
from .options import Option, Range, check_value, options_of


# name -> "module:Class"; modules are imported on first use so that an estimator's
# dependencies (onnxruntime, a model file) are needed only when it is chosen.
def estimator_names() -> list[str]:
    """The registered methods' names (sparse_body.methods)."""
    from ..methods import METHODS  # the registry holds import paths only: no cycle at import

    return sorted(METHODS)


def full_target(target) -> TypeGuard[tuple[np.ndarray, np.ndarray]]:
    """Whether a joint_target gives both a position and a rotation (a full pose)."""
    return target is not None and target[0] is not None and target[1] is not None


class Estimator(ABC):
    """Streaming whole-body estimation: reset(), then step() once per tracker frame.

    step() never raises on bad tracker values and never returns non-finite numbers: with too
    little usable input it returns its last pose with valid=False. Every method sees its
    input through the same tracker filter (core/tracker_filter.py; filter_* options).
    """

    name: ClassVar[str]
    # Sites the method cannot work without (checked against the sensor configuration).
    required_sites: ClassVar[frozenset[str]] = frozenset()
    # The closed interval each numeric option must lie in (options.py; every one has one).
    option_ranges: ClassVar[dict[str, Range]] = {}

    @classmethod
    def options(cls) -> dict[str, Option]:
        """The options a user can give (the constructor's keywords), by name."""
        return options_of(cls.__init__)

    def __init__(self, sensors: SensorConfig, skeleton: Skeleton, fps: float = 60.0) -> None:
        missing = self.required_sites - set(sensors.site_names)
        if missing:
            raise ValueError(
                f"estimator {self.name!r} needs trackers on {', '.join(sorted(missing))}; "
                f"sensor configuration {sensors.name!r} has {', '.join(sensors.site_names)}"
            )
        self.sensors = sensors
        self.skeleton = skeleton
        self.fps = fps
        self.use_filter(FilterConfig())

    def use_filter(self, config: FilterConfig, smooth: bool = False) -> None:
        """Filter the tracker input this way from now on (from the next reset: no history).
        smooth: process() smooths a whole recording forwards and backwards instead
        (core/tracker_smoother.py); live steps keep the causal filter."""
        self.input_filter = TrackerFilter(config, self.sensors.site_names)
        self.smooth = smooth

    def filtered(self, frames: Iterable[TrackerFrame]) -> Iterable[TrackerFrame]:
        """A recording's frames as the method sees them: through the live filter one by one,
        or, with smooth, the whole recording smoothed at once."""
        if self.smooth:
            return smooth_frames(list(frames), self.input_filter.config)
        return (self.input_filter(frame) for frame in frames)

    def reset(self) -> None:
        """Forget all history (a new take, a clock jump back)."""
        self._last: BodyPose | None = None
        self.input_filter.reset()
        self._reset()

    def _reset(self) -> None:  # noqa: B027 - optional: a method without history has nothing to forget
        """Forget the method's own history (recurrent state, contacts, the last latent)."""

    def step(self, frame: TrackerFrame) -> BodyPose:
        """The body at frame.stamp. What every method shares is here: too little input holds
        the last pose (invalid), a non-finite result starts the method over and holds too,
        and the last valid pose is kept for holding."""
        return self._step_filtered(self.input_filter(frame))

    def _step_filtered(self, frame: TrackerFrame) -> BodyPose:
        """step() on a frame the filter (or the offline smoother) has already seen."""
        return self._checked(frame.stamp, self._estimate(frame))

    @abstractmethod
    def _estimate(self, frame: TrackerFrame) -> BodyPose | None:
        """The method: a pose from this frame's usable samples (joint_target), or None when
        they are too few."""

    def _checked(self, stamp: float, pose: BodyPose | None) -> BodyPose:
        if pose is None:
            return self.held_pose(stamp)
        if not pose.is_finite():
            self.reset()
            return self.held_pose(stamp)
        if pose.valid:
            self._last = pose
        return pose

    def joint_target(self, frame: TrackerFrame, site: str):
        """The followed joint's (position or None, rotation matrix or None) from a site's
        sample, or None when the sample is missing, invalid or non-finite.

        A position-only tracker gives its own position (its mounting offset cannot be undone
        without an orientation); an orientation-only tracker (IMU) gives (None, rotation):
        a rotation constraint, never an invented position."""
        if site not in frame.sites:
            return None
        spec = self.sensors.site(site)
        i = frame.index(site)
        if not frame.valid[i]:
            return None
        pos, quat = np.asarray(frame.positions[i], float), np.asarray(frame.orientations[i], float)
        # a sum or a dot product is finite exactly when every element is (and is cheaper here)
        has_pos = spec.has_position and math.isfinite(pos.sum())
        norm = math.sqrt(q2) if math.isfinite(q2 := float(quat @ quat)) else 0.0
        has_rot = spec.has_orientation and 0.9 < norm < 1.1
        if spec.has_position and not has_pos:
            return None  # a position tracker without its position: unusable
        if has_pos and has_rot:
            return spec.joint_pose(pos, quat / norm)
        if has_rot:
            return None, spec.joint_rotation(quat / norm)
        return (pos, None) if has_pos else None

    def held_pose(self, stamp: float) -> BodyPose:
        """The last output (self._last) again, marked invalid; before any, the estimator's
        starting pose (self._local, else standing) at the origin, invalid too."""
        last = getattr(self, "_last", None)
        if last is None:
            local = getattr(self, "_local", None)
            return BodyPose(
                stamp, matrix_to_quat(standing_pose() if local is None else local), np.zeros(3), valid=False
            )
        return last.held(stamp)

    def process(self, stream: TrackerStream | Iterable[TrackerFrame]) -> list[BodyPose]:
        """One pose per frame of a recording (offline). A recording that jumps back in time by
        more than a second (a concatenated or looping take) starts over there."""
        self.reset()
        poses, last = [], None
        for frame in self.filtered(stream):
            if last is not None and frame.stamp < last - 1.0:  # the method starts over (the
                self._last = None  # filter did so by itself)
                self._reset()
            last = frame.stamp
            poses.append(self._step_filtered(frame))
        return poses


def parse_estimator_spec(spec: str) -> tuple[str, dict]:
    """ "name" or "name:key=value,key=value" (values read as YAML scalars) -> (name, options)."""
    name, _, rest = spec.partition(":")
    options = {}
    for item in filter(None, rest.split(",")):
        key, eq, value = item.partition("=")
        if not eq or not key:
            raise ValueError(f"estimator option {item!r} in {spec!r} is not key=value")
        try:
            options[key.strip()] = yaml.safe_load(value)
        except (yaml.YAMLError, RecursionError):
            raise ValueError(f"estimator option {item!r} in {spec!r}: the value is not a plain YAML scalar") from None
    return name.strip(), options


def create_estimator(name: str, sensors: SensorConfig, skeleton: Skeleton, fps: float = 60.0, **options) -> Estimator:
    """An estimator by name with its options; filter_<field> options (of FilterConfig) set
    the tracker filter every estimator has, filter=false turns it off; smooth=true smooths
    a whole recording in process() (offline) instead."""
    from ..methods import METHODS, load

    if name not in METHODS:
        raise ValueError(f"unknown estimator {name!r}; available: {', '.join(estimator_names())}")
    filtering = filter_config(options)
    smooth = options.pop("smooth", False)
    if not isinstance(smooth, bool):
        raise ValueError(f"smooth must be true or false, got {smooth!r}")
    cls = load(METHODS[name].estimator)
    known = cls.options()
    takes_more = any(
        p.kind is inspect.Parameter.VAR_KEYWORD  # refined: its base's options
        for p in inspect.signature(cls.__init__).parameters.values()
    )
    unknown = [k for k in options if k not in known]
    if unknown and not takes_more:
        raise ValueError(
            f"estimator {name!r} has no option {', '.join(map(repr, unknown))}; "
            f"its options are {', '.join(known) or 'none'} and the filter's (filter_...)"
        )
    for key, value in options.items():  # before any model is loaded
        if key in known:
            check_value(name, known[key], value, cls.option_ranges)
    try:
        estimator = cls(sensors, skeleton, fps=fps, **options)
    except TypeError as err:
        if "unexpected keyword argument" not in str(err):
            raise
        raise ValueError(f"estimator {name!r}: {err}; its options are {', '.join(known)}") from None
    estimator.use_filter(filtering, smooth)
    return estimator
