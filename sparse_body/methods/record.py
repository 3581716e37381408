"""The record a method registers: everything the commands need to know about it, by name
and import path only, so reading the registry imports no method's code (and no torch)."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


def load(target: str) -> Any:
    """The object a "module:name" path names, imported now."""
    module, name = target.split(":")
    return getattr(importlib.import_module(module), name)


@dataclass(frozen=True)
class TrainPart:
    """One trained network: its configuration class (with presets), its train function, and
    where its training report goes given the method's output path."""

    name: str
    config: str  # "module:Class", a train.presets.Presets dataclass
    train: str  # "module:function": train(config, train.harness.TrainRun) -> report
    report: Callable[[Path], Path]


@dataclass(frozen=True)
class Training:
    parts: tuple[TrainPart, ...]  # in training order (later parts may use earlier ones' output)
    # the default output under the package's models/, given a function making the (first
    # trained part's) configuration: a .onnx file, or "" (the folder) for several files
    output: Callable[[Callable[[], Any]], str]
    # "module:function", card(out, mocap, limit, evaluate) -> the card's path: evaluate on the
    # test split into <model>.eval.json (unless evaluate=False and it is there), then render
    # the card from it (train/NAME/card.md filled in)
    card: str
    config_help: str  # the presets, for `train --config`
    out_help: str  # what --out names


@dataclass(frozen=True)
class Method:
    name: str
    estimator: str  # "module:Class" of its estimators.base.Estimator
    options: str  # "module:Class" of its options (an estimators.options.EstimatorOptions)
    # what `sparse-body eval` runs beside it unless told not to (ablations, baselines)
    compare_with: tuple[str, ...] = ()
    # published figures printed beside its results, by sensors or (sensors, faulty %): the
    # papers' own data and protocols, a guide rather than a like-for-like comparison
    paper_figures: dict[Any, dict[str, dict[str, float]]] = field(default_factory=dict)
    training: Training | None = None
    # "module:function" timing its runtime against its reference implementation (no arguments;
    # it prints), run by `sparse-body bench --runtime NAME`
    runtime_bench: str | None = None
    # `sparse-body bench`'s goals for its step on one thread of an idle machine of the kind CI
    # runs on: (what a step does, its p99 in ms), and its p50 as a multiple of the reference
    # estimator's step in the same run (which holds on any machine); None: no goal
    step_goal: tuple[str, float] | None = None
    ratio_goal: float | None = None
    # the sensor configuration `make eval` evaluates it on (None: not in `make eval`)
    eval_sensors: str | None = None
