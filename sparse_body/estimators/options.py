"""Estimator options as a user gives them (`NAME:key=value`, node parameters): their names,
types and ranges, checked before an estimator (and its model) is made.

An option is a keyword of the estimator's constructor; its annotation gives the type, and the
class's `option_ranges` the closed interval a number must lie in. A test holds every numeric
option of every registered estimator to having a range."""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable
from dataclasses import dataclass

# the constructor's leading arguments, which are not options
NOT_OPTIONS = ("self", "sensors", "skeleton", "fps")
TYPES = {"float": (int, float), "int": (int,), "bool": (bool,), "str": (str,), "Path": (str,), "None": (type(None),)}


@dataclass(frozen=True)
class Range:
    low: float
    high: float
    unit: str = ""

    def __str__(self) -> str:
        return f"from {self.low:g} to {self.high:g}" + (f" ({self.unit})" if self.unit else "")


@dataclass(frozen=True)
class Option:
    name: str
    annotation: str  # as written in the signature: "float", "str | None", ...
    default: object

    @property
    def types(self) -> tuple[type, ...]:
        return tuple(t for part in self.annotation.split("|") for t in TYPES.get(part.strip(), (object,)))

    @property
    def numeric(self) -> bool:
        return any(part.strip() in ("float", "int") for part in self.annotation.split("|"))


def options_of(*functions: Callable) -> dict[str, Option]:
    """The keyword options of constructors, by name (later functions add to earlier ones)."""
    found: dict[str, Option] = {}
    for function in functions:
        for p in inspect.signature(function).parameters.values():
            if (
                p.kind is inspect.Parameter.POSITIONAL_OR_KEYWORD
                and p.name not in NOT_OPTIONS
                and p.default is not inspect.Parameter.empty
            ):
                found[p.name] = Option(p.name, str(p.annotation), p.default)
    return found


def check_value(estimator: str, option: Option, value: object, ranges: dict[str, Range]) -> None:
    """Raise ValueError naming the option, what it takes and the value, unless value fits."""
    prefix = f"estimator {estimator!r}: {option.name}"
    is_bool = isinstance(value, bool)
    if not isinstance(value, option.types) or (is_bool and bool not in option.types):
        kinds = " or ".join(
            dict.fromkeys(
                {
                    "float": "a number",
                    "int": "an integer",
                    "bool": "true or false",
                    "str": "a text",
                    "Path": "a path",
                    "None": "null",
                }.get(p.strip(), p.strip())
                for p in option.annotation.split("|")
            )
        )
        raise ValueError(f"{prefix} takes {kinds}, got {value!r}")
    if option.numeric and not is_bool and isinstance(value, (int, float)):
        bounds = ranges.get(option.name)
        if not math.isfinite(value) or (bounds is not None and not bounds.low <= value <= bounds.high):
            raise ValueError(f"{prefix} must be {bounds or 'finite'}, got {value!r}")


# Ranges several estimators share.
FLOOR = Range(-10.0, 10.0, "metres: the floor's height in the fixed frame")
MAX_GAP = Range(0.0, 60.0, "seconds without input after which the method starts over")
THREADS = Range(1, 256, "ONNX Runtime threads")
