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

from ..core.options import Option, Options, Range, option

__all__ = ["EstimatorOptions", "Option", "Range", "floor_height", "max_gap", "model_path", "option", "threads"]


@dataclass(frozen=True)
class EstimatorOptions(Options):
    owner = "estimator"
    others = " and the filter's (filter_...)"


def floor_height(default: float | None = 0.0) -> Any:
    return option(default, "the floor's height in the fixed frame (feet are kept above it)", -10.0, 10.0, "metres")


def max_gap(default: float = 0.5) -> Any:
    return option(default, "seconds without input after which the method starts over", 0.0, 60.0, "seconds")


def threads(default: int = 1) -> Any:
    return option(default, "ONNX Runtime threads", 1, 256)


def model_path(default: str | None = None) -> Any:
    return option(default, "the model file; null: the shipped model")
