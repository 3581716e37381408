"""The options table (docs/options.md, `sparse-body options`), read from the options
dataclasses alone: every method's (methods/NAME/options.py) and the tracker filter's."""

from __future__ import annotations

from ..core.options import Option, Options
from ..core.tracker_filter import PREFIX, FilterConfig
from ..estimators.options import SharedOptions
from ..methods import METHODS, load

HEADER = """# Options

Generated from the options dataclasses by `sparse-body options --markdown` (a test keeps this file
equal to it). A method's options are given as `NAME:key=value,...` to `--estimator` (eval, process,
bench) and to the nodes' `estimator` parameter, or one by one as the nodes' parameters
`NAME.<option>` (a parameter set wins over the spec string). The tracker filter's are every
estimator's, as `filter_<option>` in both places.
"""


def _value(value: object) -> str:
    if value is None or isinstance(value, bool):
        return {None: "null", True: "true", False: "false"}[value]
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, tuple):  # a ROS string array
        return "[" + ", ".join(map(_value, value)) + "]"
    return repr(value) if isinstance(value, str) else str(value)


def _rows(options: type[Options], prefix: str = "", head: str = "option") -> list[str]:
    return _table({prefix + name: o for name, o in options.fields().items() if not o.experiment}, head)


def _table(options: dict[str, Option], head: str = "option") -> list[str]:
    return [f"| {head} | takes | default | what it does |", "| --- | --- | --- | --- |"] + [
        f"| `{name}` | {o.takes()} | `{_value(o.default)}` | {o.help} |" for name, o in options.items()
    ]


LAB_NOTES = """## Kept to measure a lab note again

Not for use: options a lab note (docs/experiments/) was measured with and that did not win, kept
so that its figures can be measured again. Each is given as any other (`NAME:key=value`).
"""


def _experiments() -> list[str]:
    kept = {
        f"{name}:{key}": o
        for name, record in METHODS.items()
        for key, o in load(record.options).fields().items()
        if o.experiment
    }
    return [LAB_NOTES, "\n".join(_table(kept)) + "\n"]


def markdown() -> str:
    parts = [HEADER]
    for name, record in METHODS.items():
        options = load(record.options)
        parts.append(f"## {name}\n")
        own = [o for o in options.fields().values() if not o.experiment]
        parts.append("\n".join(_rows(options)) + "\n" if own else "No options of its own.\n")
        if options.passes_on:
            parts.append("Any other option is its base estimator's.\n")
    parts.append("## Every estimator\n")
    parts.append("\n".join(_rows(SharedOptions)) + "\n")
    parts.append("## The tracker filter (every estimator)\n")
    parts.append("\n".join(_rows(FilterConfig, PREFIX)) + "\n")
    parts.extend(_experiments())
    parts.append(NODES)
    for title, options in _node_options():
        parts.append(f"### {title}\n")
        parts.append("\n".join(_rows(options, head="parameter")) + "\n")
    return "\n".join(parts)


NODES = """## The nodes' own parameters

Beside the options above (a method's as `NAME.<option>`, the filter's as `filter_<option>`,
`foot_lock` and `predict_ahead`), each node declares these (ros/node_options.py); numbers
outside their range are refused with the reason, and `ros2 param describe` shows it.
"""


def _node_options() -> list[tuple[str, type[Options]]]:
    from ..ros.node_options import (
        ConstraintNodeInputOptions,
        EstimatorNodeOptions,
        RetargetOptions,
        TrackerBridgeOptions,
    )

    return [
        ("sparse_body_estimator", EstimatorNodeOptions),
        (
            "sparse_body_constraint: the estimator's but those that choose or time one, and these",
            ConstraintNodeInputOptions,
        ),
        ("sparse_body_tracker_bridge", TrackerBridgeOptions),
        ("sparse_body_retarget", RetargetOptions),
    ]


def text(method: str) -> str:
    """One method's options, a line each, for a terminal."""
    options = load(METHODS[method].options).fields()
    if not options:
        return f"{method}: no options of its own (the filter's: filter_...)"
    width = max(map(len, options))
    note = " [a lab note's]"
    lines = [
        f"  {name:<{width}}  {_value(o.default):<10} {o.takes()}: {o.help}" + (note if o.experiment else "")
        for name, o in options.items()
    ]
    return f"{method} (NAME:key=value; besides these, the filter's filter_...):\n" + "\n".join(lines)
