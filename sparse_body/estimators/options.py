"""The options every estimator's dataclass may take, declared once (core/options.py says how an
options dataclass works).

A method's options are `methods/NAME/options.py`: a frozen dataclass of EstimatorOptions whose
fields are option(...) lines; a field several methods share is one of the functions below, so
its default, range and help are written once. Besides its own, every estimator takes the
tracker filter's (filter_<field>, core/tracker_filter.FilterConfig) and the ones
create_estimator reads (foot_lock, predict_ahead, forecast, smooth, filter)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..core.forecast import FORECASTS, MAX_AHEAD
from ..core.options import Option, Options, Range, option

__all__ = [
    "EstimatorOptions",
    "Option",
    "Range",
    "SharedOptions",
    "floor_height",
    "max_gap",
    "model_path",
    "option",
    "threads",
]


@dataclass(frozen=True)
class EstimatorOptions(Options):
    owner = "estimator"
    others = " and the filter's (filter_...)"


@dataclass(frozen=True)
class SharedOptions(Options):
    """What every method takes (methods/factory.create_estimator applies it around the method)."""

    owner = "estimator"
    passes_on = True  # the rest are the method's own and the filter's

    # a whole recording smoothed in process() (offline) instead of filtered frame by frame
    smooth: bool = option(False, "smooth a whole recording (offline) instead of filtering frame by frame")
    # on by default: on the kinds of motion no model trained on it halves the four-point skate
    # of the estimators without a contact IK of their own and moves their lower-body error by
    # under 1 % either way (docs/experiments/feet-held-where-they-touch-down.md); feet that wear
    # trackers are as the trackers say, and never held
    foot_lock: bool = option(
        True,
        "hold each foot where it touched down while the estimator says it is in contact (hip and knee "
        "move): less sliding; feet that wear trackers are never held; false: the estimator's legs as they are",
    )
    predict_ahead: float = option(
        0.0,
        "seconds past the trackers' stamp the body is forecast and stamped (a teleoperation loop cancels "
        "its own delay with it): each joint carried on at its fading velocity, the root moved as forecast "
        "says; 0: the body at the trackers' stamp",
        0.0,
        MAX_AHEAD,
        "seconds",
    )
    forecast: str = option(
        "learned", "how predict_ahead moves the root: the learned model, or its fading velocity", choices=FORECASTS
    )


def floor_height(default: float | None = 0.0) -> Any:
    return option(default, "the floor's height in the fixed frame (feet are kept above it)", -10.0, 10.0, "metres")


def max_gap(default: float = 0.5) -> Any:
    return option(default, "seconds without input after which the method starts over", 0.0, 60.0, "seconds")


def threads(default: int = 1) -> Any:
    return option(default, "ONNX Runtime threads", 1, 256)


def model_path(default: str | None = None) -> Any:
    return option(default, "the model file; null: the shipped model")
