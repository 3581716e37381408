"""The methods, one record each (record.Method): estimator, options, training parts and
presets, model card, paper figures, bench goals and what `eval` compares it with; estimators
are made by name with factory.create_estimator. The commands, the nodes and the
evaluation look methods up here and hold no per-method branches. Each method is a folder,
methods/NAME/, whose __init__ holds its record and nothing that imports its code (so listing
the methods imports neither torch nor ONNX Runtime); a learning method's training side (torch)
is its folder train/NAME/. Adding a method is its folder(s) and one line in NAMES."""

from __future__ import annotations

import importlib

from .record import Method, Training, TrainPart, load

# The registry: one name a line, in the order `--help` and `eval` list them. Each names its
# folder, methods/NAME/, whose METHOD record is read here (import paths only, no code).
NAMES = (
    "reference",
    "ik",
    "lobstr",
    "dragposer",
    "refined",
    "blend",
    "upright",
    "dtp",
    "avatarjlm",
)
METHODS: dict[str, Method] = {name: importlib.import_module(f"{__name__}.{name}").METHOD for name in NAMES}
TRAINABLE = [name for name, m in METHODS.items() if m.training is not None]


def paper_figures(method: str, sensors: str, faulty_percent: float = 0.0, occluded_percent: float = 0.0) -> dict:
    """The published figures for a method on a sensor set (and share of faulty sensors)."""
    if occluded_percent or method not in METHODS:  # DTP's occluded test set states no share: nothing alike
        return {}
    key = (sensors, faulty_percent) if faulty_percent else sensors
    return METHODS[method].paper_figures.get(key, {})


__all__ = ["METHODS", "TRAINABLE", "Method", "TrainPart", "Training", "load", "paper_figures"]
