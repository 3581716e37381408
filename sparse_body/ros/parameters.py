"""ROS parameters declared, described and checked the same way for every node: each node's own
are an options dataclass (ros/node_options.py), read by `table` into name -> (default,
description) and name -> (low, high) for its numbers; a parameter that is a declared option
of an estimator (core/options.Option: a method's, the tracker filter's) is checked by its
declaration. `ros2 param describe` shows the description and the range."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

from ..core.options import Option, Options

Ranges = dict[str, tuple[float, float]]


def option_text(option: Option) -> str:
    """An option's description as a parameter's: its help, its unit and its choices."""
    unit = f" ({option.range.unit})" if option.range is not None and option.range.unit else ""
    choices = f" (one of {', '.join(option.choices)})" if option.choices else ""
    return option.help + unit + choices


def table(options: type[Options]) -> tuple[dict[str, tuple], Ranges]:
    """A node's options dataclass as its parameter table and the ranges of its numbers (a
    tuple default is a ROS string array, given as a list)."""
    fields = options.fields()
    parameters = {
        name: (list(o.default) if isinstance(o.default, tuple) else o.default, option_text(o))
        for name, o in fields.items()
    }
    return parameters, {name: (o.range.low, o.range.high) for name, o in fields.items() if o.range}


def parameter_descriptor(default, text: str, bounds: tuple[float, float] | None) -> ParameterDescriptor:
    """A parameter's description, typed dynamically, with its range where it has one."""
    descriptor = ParameterDescriptor(description=text, dynamic_typing=True)
    if bounds is not None and isinstance(default, float):
        descriptor.floating_point_range = [FloatingPointRange(from_value=bounds[0], to_value=bounds[1], step=0.0)]
    elif bounds is not None and isinstance(default, int) and not isinstance(default, bool):
        descriptor.integer_range = [IntegerRange(from_value=int(bounds[0]), to_value=int(bounds[1]), step=1)]
    return descriptor


def declare(node, parameters: dict[str, tuple], ranges: Ranges) -> dict[str, str]:
    """Every parameter of a node's table, with its description and range; what was given
    outside its range at start-up, by name, with the reason (the default is kept meanwhile).

    Typed by their defaults but declared dynamically: a wrong type given at start-up is refused
    by configure with the reason, instead of ending the process. Numbers carry their range
    natively (`ros2 param describe` shows it; a set outside it is refused by rclpy); one given
    outside it at start-up is kept out, and configure says so (rclpy would have ended the
    process with a traceback)."""
    from rclpy.exceptions import InvalidParameterValueException

    refused = {}
    for name, (default, text) in parameters.items():
        descriptor = parameter_descriptor(default, text, ranges.get(name))
        try:
            node.declare_parameter(name, default, descriptor)
        except InvalidParameterValueException as err:
            node.declare_parameter(name, default, descriptor, ignore_override=True)
            low, high = ranges[name]
            refused[name] = f"{name} must be between {low:g} and {high:g} ({err})"
    return refused


def check_parameter(
    name: str,
    value,
    default,
    ranges: Ranges,
    options: dict[str, Option] | None = None,
    text_checks: dict[str, Callable[[str], str | None]] | None = None,
) -> str | None:
    """Why value is not acceptable for parameter name (whose default shows its type), or None.
    options: parameters that are declared options (method.option), checked by their declaration;
    text_checks: a check of its form for a text parameter."""
    if options and name in options:  # a method's option: its declaration says (null where it takes null)
        try:
            options[name].check(f"parameter {name.partition('.')[0]}", value)
        except ValueError as err:
            return str(err).replace(": ", ".", 1)
        return None
    if isinstance(default, bool):
        return None if isinstance(value, bool) else f"{name} must be true or false, got {value!r}"
    if isinstance(default, (int, float)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
            return f"{name} must be a finite number, got {value!r}"
        if isinstance(default, int) and not float(value).is_integer():
            return f"{name} must be a whole number, got {value!r}"
        low, high = ranges.get(name, (-np.inf, np.inf))
        return None if low <= value <= high else f"{name} must be between {low:g} and {high:g}, got {value!r}"
    if isinstance(default, str):
        if not isinstance(value, str):
            return f"{name} must be a string, got {value!r}"
        if text_checks and name in text_checks:
            return text_checks[name](value)
    return None


def problems(parameters: dict[str, tuple], given: dict, ranges: Ranges, **checks) -> list[str]:
    """Why each given value of a node's table is not acceptable (empty: all are)."""
    return [
        reason
        for name, (default, _) in parameters.items()
        if (reason := check_parameter(name, given[name], default, ranges, **checks))
    ]
