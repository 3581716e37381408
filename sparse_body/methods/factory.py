"""Estimators by name (the lazy factory): the registry (methods/__init__.py) holds import
paths, and a method's code is imported only when one of its estimators is made. Above the
methods and the Estimator base, so neither imports the registry."""

from __future__ import annotations

from ..core.options import shown
from ..core.sensors import SensorConfig
from ..core.skeleton import JOINT_INDEX, Skeleton
from ..core.tracker_filter import filter_config
from ..estimators.base import Estimator
from ..estimators.options import SharedOptions
from . import METHODS, load
from .recommended import AUTO, recommended


def estimator_names() -> list[str]:
    """The registered methods' names."""
    return sorted(METHODS)


def check_estimator_name(name: str, where: str = "") -> None:
    """ValueError (one line, listing the estimators, after `where`: the option that names it)
    unless `name` is one, or auto: checked by the commands before they make anything."""
    if name not in METHODS and name != AUTO:
        said = f"{where}: " if where else ""
        raise ValueError(f"{said}unknown estimator {shown(name)}; available: {AUTO}, {', '.join(estimator_names())}")


def feet_tracked(sensors: SensorConfig) -> bool:
    """Whether both feet wear trackers (six-point, or IMUs: a hold would turn the shin and so
    the ankle away from the orientation an IMU measures)."""
    ankles = {JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"]}
    return ankles <= {site.joint_index for site in sensors.sites}


def create_estimator(name: str, sensors: SensorConfig, skeleton: Skeleton, fps: float = 60.0, **options) -> Estimator:
    """An estimator by name with its options; filter_<field> options (of FilterConfig) set
    the tracker filter every estimator has, filter=false turns it off; smooth=true smooths
    a whole recording in process() (offline) instead; predict_ahead=SECONDS gives each pose
    that far past its frame, forecast (core/forecast.py; forecast=faded: the root carried at
    its fading velocity instead of the learned model's move); foot_lock holds a foot where it
    touched down while in contact (core/contact_hold.py; default true; feet that wear trackers
    are never held), foot_lock=false leaves the method's legs as they are."""
    check_estimator_name(name)
    if name == AUTO:  # the recommended estimator for these sensors (methods/recommended.py)
        from ..estimators.base import parse_estimator_spec

        name, chosen = parse_estimator_spec(recommended(sensors.name))
        options = {**chosen, **options}
    filtering = filter_config(options)
    shared = SharedOptions.parse(options, f"estimator {name!r}")
    options = SharedOptions.rest(options)
    kind = load(METHODS[name].options)
    parsed = kind.parse(options, f"estimator {name!r}")  # once, before any model is loaded
    passed_on = kind.rest(options) if kind.passes_on else {}
    estimator = load(METHODS[name].estimator)(sensors, skeleton, fps=fps, parsed=parsed, **passed_on)
    estimator.use_filter(filtering, shared.smooth)
    estimator.use_forecast(float(shared.predict_ahead), shared.forecast)
    estimator.use_foot_lock(shared.foot_lock and not feet_tracked(sensors))
    return estimator


def inner_estimators(outer: Estimator, names: tuple[str, ...]) -> list[Estimator]:
    """The estimators a combining one (blend, upright) steps inside itself, by name: each with
    its own defaults and shipped model, its legs as its method gives them (the outer one's
    foot_lock holds the result), reading the outer one's filtered targets (its filter has
    done the filtering)."""
    from ..core.tracker_filter import NO_FILTER

    inner = [create_estimator(name, outer.sensors, outer.skeleton, outer.fps, foot_lock=False) for name in names]
    for estimator in inner:
        estimator.use_filter(NO_FILTER)
        estimator.read_targets_from(outer)
    return inner
