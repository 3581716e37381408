"""The one interface every estimator implements, and the registry that names them."""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Iterable, Iterator
from dataclasses import replace
from typing import ClassVar, TypeGuard

import numpy as np
import yaml

from ..core import mat3
from ..core.contact_hold import ContactHold
from ..core.fixed_lag import FixedLagSmoother
from ..core.forecast import PoseForecast
from ..core.kinematics import forward_kinematics
from ..core.mat3 import njit
from ..core.reacquire import FreezeGuard, Reacquisition
from ..core.rotations import matrix_to_quat, quat_to_matrix, rotations_to_quat
from ..core.sensors import SensorConfig
from ..core.skeleton import Skeleton, standing_pose
from ..core.textfile import load_yaml
from ..core.tracker_filter import FilterConfig, TrackerFilter
from ..core.tracker_smoother import smooth_frames
from ..core.types import BodyPose, TrackerFrame, TrackerStream, breaks_take
from .options import EstimatorOptions, Option


def full_target(target) -> TypeGuard[tuple[np.ndarray, np.ndarray]]:
    """Whether a joint_target gives both a position and a rotation (a full pose)."""
    return target is not None and target[0] is not None and target[1] is not None


# what joint_target makes of a site's sample
_NONE, _POSE, _ROTATION, _POSITION = 0, 1, 2, 3


def _mounting(sensors: SensorConfig, sites: tuple[str, ...]):
    """The kernel's view of the sensor configuration in a frame's site order: what each site
    measures and the inverse of its mounting (a site the configuration lacks measures nothing)."""
    known = set(sensors.site_names)
    specs = [sensors.site(s) if s in known else None for s in sites]
    has_position = np.array([s is not None and s.has_position for s in specs], np.bool_)
    has_orientation = np.array([s is not None and s.has_orientation for s in specs], np.bool_)
    unmount = np.array([s.joint_rotation(np.array([0.0, 0.0, 0.0, 1.0])) if s else np.eye(3) for s in specs]).reshape(
        -1, 3, 3
    )
    offset = np.array([s.offset_translation if s else (0.0, 0.0, 0.0) for s in specs], float).reshape(-1, 3)
    return has_position, has_orientation, unmount, offset


@njit
def _joint_targets(positions, orientations, valid, has_position, has_orientation, unmount, offset):
    """Every site's joint target at once: positions (S, 3), rotations (S, 3, 3) and what each
    site gives (_NONE, _POSE, _ROTATION, _POSITION). unmount: the mounting rotation's inverse
    (joint rotation = tracker rotation @ unmount); offset: the tracker in its joint's frame."""
    count = len(valid)
    out_p, out_r = np.zeros((count, 3)), np.zeros((count, 3, 3))
    kinds = np.zeros(count, np.int64)
    for i in range(count):
        if not valid[i]:
            continue
        p, q = positions[i], orientations[i]
        # a sum or a dot product is finite exactly when every element is
        has_pos = has_position[i] and math.isfinite(p[0] + p[1] + p[2])
        q2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]
        norm = math.sqrt(q2) if math.isfinite(q2) else 0.0
        has_rot = has_orientation[i] and 0.9 < norm < 1.1
        if has_position[i] and not has_pos:
            continue  # a position tracker without its position: unusable
        if has_rot:
            out_r[i] = mat3.mul(mat3.quat_matrix(q / norm), unmount[i])
        if has_pos and has_rot:
            out_p[i] = p - mat3.vec(out_r[i], offset[i])
            kinds[i] = _POSE
        elif has_rot:
            kinds[i] = _ROTATION
        elif has_pos:
            out_p[i] = p
            kinds[i] = _POSITION
    return out_p, out_r, kinds


class Estimator(ABC):
    """Streaming whole-body estimation: reset(), then step() once per tracker frame.

    step() never raises on bad tracker values and never returns non-finite numbers: with too
    little usable input it returns its last pose with valid=False. Every method sees its
    input through the same tracker filter (core/tracker_filter.py; filter_* options).
    """

    name: ClassVar[str]
    # Sites the method cannot work without (checked against the sensor configuration).
    required_sites: ClassVar[frozenset[str]] = frozenset()
    # Its options (methods/NAME/options.py): the keywords the constructor takes, read into
    # self.options, each checked against its declaration before anything is loaded.
    Options: ClassVar[type[EstimatorOptions]] = EstimatorOptions

    @classmethod
    def option_fields(cls) -> dict[str, Option]:
        """The options a user can give, by name."""
        return cls.Options.fields()

    def __init__(
        self,
        sensors: SensorConfig,
        skeleton: Skeleton,
        fps: float = 60.0,
        parsed: EstimatorOptions | None = None,
        **given,
    ) -> None:
        # parsed once where the options come in (methods/factory.py); read here when made directly
        self.options = self.Options.parse(given, f"estimator {self.name!r}") if parsed is None else parsed
        # the options this method's own pass on to another estimator (refined's base)
        self.passed_on = self.Options.rest(given) if self.Options.passes_on else {}
        missing = self.required_sites - set(sensors.site_names)
        if missing:
            raise ValueError(
                f"estimator {self.name!r} needs trackers on {', '.join(sorted(missing))}; "
                f"sensor configuration {sensors.name!r} has {', '.join(sensors.site_names)}"
            )
        self.sensors = sensors
        self.skeleton = skeleton
        self.fps = fps
        self._targets_of: TrackerFrame | None = None  # the frame whose joint targets are held
        self._targets_source: Estimator | None = None  # read_targets_from
        self._mounting_sites: tuple[str, ...] = ()
        self._rows: dict[tuple, np.ndarray] = {}  # full_targets: (frame sites, sites) -> rows
        self.use_filter(FilterConfig())
        self.use_forecast(0.0)
        self.use_foot_lock(False)

    def use_foot_lock(self, on: bool) -> None:
        """Hold each foot where its contact began while the method says it is in contact, by
        moving hip and knee (core/contact_hold.py: LoBSTr's contact IK, from the method's own
        contacts; the option foot_lock), from the next reset."""
        self.foot_lock = ContactHold(self.skeleton) if on else None
        self._locked_at: float | None = None  # the stamp of the last pose held
        self._lock_gap = float(getattr(self.options, "max_gap", 0.5))

    def use_forecast(self, ahead: float, root: str = "learned") -> None:
        """Give each pose `ahead` seconds past its frame, forecast (core/forecast.py; the
        option predict_ahead), from the next reset; the root's move by the shipped learned model
        (root "learned", where the package has it) or carried at its fading velocity ("faded",
        the option forecast=faded)."""
        if ahead > 0.0 and root == "learned" and learned_root_available():
            from .forecast_model import RootForecastModel

            model = RootForecastModel()
            self.forecast = PoseForecast(ahead, root_model=model, lags=model.lags)
        else:
            self.forecast = PoseForecast(ahead)

    @property
    def ahead(self) -> float:
        """Seconds by which a step's pose is forecast past its frame (predict_ahead)."""
        return self.forecast.ahead

    def use_filter(self, config: FilterConfig, smooth: bool = False) -> None:
        """Filter the tracker input this way from now on (from the next reset: no history).
        config.lag > 0: each step's pose is of the frame that many seconds (in frames at
        self.fps) before, smoothed by the frames since (core/fixed_lag.py). smooth: process()
        smooths a whole recording forwards and backwards instead (core/tracker_smoother.py);
        live steps keep the causal filter."""
        self.input_filter: TrackerFilter | FixedLagSmoother
        if config.lag > 0 and config.enabled:
            self.input_filter = FixedLagSmoother(config, round(config.lag * self.fps))
        else:
            self.input_filter = TrackerFilter(config, self.sensors.site_names)
        self.reacquisition = Reacquisition(config.reacquire_speed, config.carry_lost, config.leap_speed)
        self.freeze_guard = FreezeGuard(config.frozen_after) if config.frozen_after > 0 else None
        self.smooth = smooth

    @property
    def lag(self) -> float:
        """Seconds by which a step's pose is older than the frame given (the filter's lag)."""
        return self.input_filter.lag_frames / self.fps if isinstance(self.input_filter, FixedLagSmoother) else 0.0

    def filtered(self, frames: Iterable[TrackerFrame]) -> Iterable[TrackerFrame]:
        """A recording's frames as the method sees them, one for each frame given and in
        order: through the live filter (with its lag, if any), or, with smooth, the whole
        recording smoothed at once."""
        if self.freeze_guard is not None:
            frames = map(self.freeze_guard, frames)
        if self.smooth:
            return smooth_frames(list(frames), self.input_filter.config)
        return self.input_filter.stream(frames)

    def reset(self) -> None:
        """Forget all history (a new take, a clock jump back)."""
        self._last: BodyPose | None = None
        self._shown: BodyPose | None = None  # the last pose given, valid or held
        self.input_filter.reset()
        self._forget_given()
        self.reacquisition.reset()
        if self.freeze_guard is not None:
            self.freeze_guard.reset()
        self._reset()

    def out_of_depth(self) -> tuple[float, str] | None:
        """How far the last frame lay outside the motion the method knows (0: within it, 1:
        wholly outside) and what it did about it, said on estimate_status; None: the method
        does not say (only upright does today)."""
        return None

    def _reset(self) -> None:  # noqa: B027 - optional: a method without history has nothing to forget
        """Forget the method's own history (recurrent state, contacts, the last latent)."""

    def step(self, frame: TrackerFrame) -> BodyPose:
        """The body at frame.stamp. What every method shares is here: too little input holds
        the last pose (invalid), a non-finite result starts the method over and holds too,
        and the last valid pose is kept for holding. With a lag, the pose is of the frame that
        long before, and held (invalid) until as many frames have come since a reset."""
        filtered = self.input_filter(frame if self.freeze_guard is None else self.freeze_guard(frame))
        if filtered is None:
            return self._given(self.held_pose(frame.stamp - self.lag))
        return self._given(self._step_filtered(filtered))

    def _given(self, pose: BodyPose) -> BodyPose:
        """A pose on its way out, live and offline alike: its feet held where they touched down
        (foot_lock; a held pose as it is), then forecast (predict_ahead)."""
        if self.foot_lock is not None and pose.valid:
            # a gap the method starts over after lets go of the points held before it too
            if self._locked_at is not None and breaks_take(self._locked_at, pose.stamp, self._lock_gap):
                self.foot_lock.reset()
            self._locked_at = pose.stamp
            before = mat3.quat_matrices(pose.local_quats)
            after = self.foot_lock.apply(before, pose.root_position, pose.contact)
            moved = np.any(after != before, axis=(1, 2))  # hips and knees at most: the rest as they were, to the bit
            if moved.any():
                quats = pose.local_quats.copy()
                quats[moved] = rotations_to_quat(after[moved])
                pose = replace(pose, local_quats=quats)
        return self.forecast.forecast(pose)

    def _forget_given(self) -> None:
        """_given's history: the contact points held and the last pose forecast from."""
        self.forecast.reset()
        if self.foot_lock is not None:
            self.foot_lock.reset()
            self._locked_at = None

    def _step_filtered(self, frame: TrackerFrame) -> BodyPose:
        """step() on a frame the filter (or the offline smoother) has already seen."""
        return self._checked(frame.stamp, self._estimate(frame))

    @abstractmethod
    def _estimate(self, frame: TrackerFrame) -> BodyPose | None:
        """The method: a pose from this frame's usable samples (joint_target), or None when
        they are too few."""

    def _checked(self, stamp: float, pose: BodyPose | None) -> BodyPose:
        if pose is None:
            pose = self.held_pose(stamp)
        elif not pose.is_finite():
            self.reset()
            pose = self.held_pose(stamp)
        elif pose.valid:
            self._last = pose
        self._shown = pose
        return pose

    def joint_target(self, frame: TrackerFrame, site: str):
        """The followed joint's (position or None, rotation matrix or None) from a site's
        sample, or None when the sample is missing, invalid or non-finite.

        A position-only tracker gives its own position (its mounting offset cannot be undone
        without an orientation); an orientation-only tracker (IMU) gives (None, rotation):
        a rotation constraint, never an invented position. Every site of a frame is
        converted at once, in one compiled call, the first time the frame is asked."""
        if site not in frame.sites:
            return None
        positions, rotations, kinds = self._converted(frame)
        i = frame.index(site)
        kind = kinds[i]
        if kind == _POSE:
            return positions[i].copy(), rotations[i].copy()
        if kind == _ROTATION:
            return None, rotations[i].copy()
        return (positions[i].copy(), None) if kind == _POSITION else None

    def full_targets(self, frame: TrackerFrame, sites: tuple[str, ...]):
        """(positions (n, 3), rotations (n, 3, 3)) of the sites' joint targets when every one
        of them gives a full pose, else None: joint_target for a method that needs them all,
        as arrays."""
        key = (frame.sites, sites)
        rows = self._rows.get(key)
        if rows is None:
            if not set(sites) <= set(frame.sites):
                return None
            rows = self._rows[key] = np.array([frame.index(s) for s in sites], dtype=np.int64)
        positions, rotations, kinds = self._converted(frame)
        if not (kinds[rows] == _POSE).all():
            return None
        return positions[rows], rotations[rows]

    def read_targets_from(self, outer: Estimator) -> None:
        """Convert no frame here: take outer's joint targets. For an estimator used inside
        another (LoBSTr's IK, a refined estimator's base and refiner): what outer does to its
        targets (the lost-tracker options, with the poses outer gave) holds here too, once a
        frame."""
        self._targets_source = outer

    def _converted(self, frame: TrackerFrame):
        """The joint targets of every site of frame, converted once a frame."""
        if self._targets_source is not None:
            return self._targets_source._converted(frame)
        if frame is not self._targets_of:
            self._targets_of, self._targets = frame, self._frame_targets(frame)
        return self._targets

    def _frame_targets(self, frame: TrackerFrame):
        if frame.sites != self._mounting_sites:  # the frame's site order, once per site set
            self._mounting_sites, self._mounting = frame.sites, _mounting(self.sensors, frame.sites)
            known = set(self.sensors.site_names)
            self._site_joints = np.array([self.sensors.site(s).joint_index if s in known else 0 for s in frame.sites])
        targets = _joint_targets(
            np.ascontiguousarray(frame.positions, float),
            np.ascontiguousarray(frame.orientations, float),
            np.ascontiguousarray(frame.valid, np.bool_),
            *self._mounting,
        )
        if self.reacquisition.enabled:
            positions, rotations, kinds = targets
            self.reacquisition.apply(
                frame.stamp, positions, rotations, kinds, (_POSE, _POSITION), self._site_joints, self._shown_positions
            )
        return targets

    def _shown_positions(self) -> np.ndarray | None:
        """The joint positions (22, 3) of the last pose given, or None before any."""
        shown = getattr(self, "_shown", None)
        if shown is None:
            return None
        return forward_kinematics(quat_to_matrix(shown.local_quats), shown.root_position, self.skeleton.offsets)[1]

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
        return list(self.stream(stream))

    def stream(self, frames: TrackerStream | Iterable[TrackerFrame]) -> Iterator[BodyPose]:
        """process() a pose at a time, in the frames' order, taking frames only as it needs
        them: a recording of any length in bounded memory (but for the whole-recording
        smoother, use_filter(smooth=True), which needs every frame first)."""
        self.reset()
        last = None
        for frame in self.filtered(frames):
            if last is not None and frame.stamp < last - 1.0:  # the method starts over (the
                self._last = None  # filter did so by itself)
                self._forget_given()
                self._reset()
            last = frame.stamp
            yield self._given(self._step_filtered(frame))


def parse_estimator_spec(spec: str) -> tuple[str, dict]:
    """ "name" or "name:key=value,key=value" (values read as YAML scalars) -> (name, options)."""
    from ..core.options import shown

    name, _, rest = spec.partition(":")
    options = {}
    for item in filter(None, rest.split(",")):
        key, eq, value = item.partition("=")
        if not eq or not key:
            raise ValueError(f"estimator option {shown(item)} in {shown(spec)} is not key=value")
        if key.strip() in options:  # (the last silently won)
            raise ValueError(f"estimator option {key.strip()!r} is given twice in {shown(spec)}")
        try:
            options[key.strip()] = load_yaml(value)
        except (yaml.YAMLError, ValueError):  # (InputTooLarge: nested, or aliases expanded too far)
            raise ValueError(
                f"estimator option {shown(item)} in {shown(spec)}: the value is not a plain YAML scalar"
            ) from None
    return name.strip(), options


def learned_root_available() -> bool:
    """Whether the package has the learned root forecast's model (make train-forecast)."""
    from ..core.resources import models_dir
    from .forecast_model import FILE

    return (models_dir() / FILE).is_file()
