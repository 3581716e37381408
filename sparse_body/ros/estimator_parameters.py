"""The estimator node's parameters (and the constraint node's, which takes them too): its own
(ros/node_options.EstimatorNodeOptions), the checks of its texts, and every method's and the
tracker filter's options as parameters of their own (ros/parameters.py declares and checks
them)."""

from __future__ import annotations

from ..core.options import Option
from ..core.tracker_filter import PREFIX as FILTER
from ..core.tracker_filter import FilterConfig
from ..estimators.base import parse_estimator_spec
from ..estimators.options import SharedOptions
from ..methods import METHODS, NAMES, load
from ..methods.recommended import AUTO
from .node_options import EstimatorNodeOptions
from .parameters import Ranges, table
from .parameters import check_parameter as _check
from .parameters import option_text as _text

# The tracker filter's options (core/tracker_filter.FilterConfig), each a parameter filter_<field>.
FILTER_PARAMETERS = {FILTER + name: (o.default, _text(o)) for name, o in FilterConfig.fields().items()}


def method_option_parameters() -> dict[str, Option]:
    """Every registered method's options (methods/NAME/options.py), each a parameter
    NAME.<field>: the options the estimator (or budget_fallback) of that method is made with,
    over those its spec string gives."""
    return {
        f"{method}.{name}": o for method, record in METHODS.items() for name, o in load(record.options).fields().items()
    }


METHOD_OPTIONS = method_option_parameters()

# The options every method takes (estimators/options.SharedOptions) that the node sets as its
# own parameters (smooth is offline only; forecast rides in the estimator spec).
SHARED = SharedOptions.fields()
SHARED_PARAMETERS = {name: (SHARED[name].default, _text(SHARED[name])) for name in ("foot_lock", "predict_ahead")}

# The node's own (ros/node_options.EstimatorNodeOptions), the estimator's help naming every
# estimator the registry has; then the tracker filter's, the shared options it sets and every
# method's, each checked by its own declaration.
OWN, OWN_RANGES = table(EstimatorNodeOptions)
OWN["estimator"] = (
    "auto",
    f"estimation method: auto (the one recommended for the sensors), {', '.join(NAMES)} "
    "(refined:base=NAME: DragPoser's refinement after another; options as NAME:key=value,...)",
)
PARAMETERS = {
    **OWN,
    **FILTER_PARAMETERS,
    **SHARED_PARAMETERS,
    **{name: (o.default, _text(o)) for name, o in METHOD_OPTIONS.items()},
}
# Numbers outside these bounds are refused with the reason (at configure and on a live set).
RANGES = {
    **OWN_RANGES,
    **{FILTER + name: (o.range.low, o.range.high) for name, o in FilterConfig.fields().items() if o.range},
    **{name: (r.low, r.high) for name in SHARED_PARAMETERS if (r := SHARED[name].range)},
    **{name: (o.range.low, o.range.high) for name, o in METHOD_OPTIONS.items() if o.range},
}
# What a configured node applies at once; the rest is refused until it is cleaned up.
LIVE = {"stale_timeout", "tracker_timeout", "publish_link_tf", "autostart"}


def _check_estimator_spec(value: str) -> str | None:
    from ..methods.factory import estimator_names

    try:
        method, _ = parse_estimator_spec(value)
    except ValueError as err:
        return str(err)
    names = estimator_names()
    if method not in names and method != AUTO:
        return f"unknown estimator {method!r}; available: {AUTO}, {', '.join(names)}"
    return None


# Text parameters with a form to check (the rest are checked where they are used, at configure).
TEXT_CHECKS = {
    "estimator": _check_estimator_spec,
    "budget_fallback": lambda value: _check_estimator_spec(value) if value else None,
}


# how ros/parameters.py checks this node's table (problems, check_parameter)
CHECKS = {"options": METHOD_OPTIONS, "text_checks": TEXT_CHECKS}


def check_parameter(name: str, value, default, ranges: Ranges = RANGES) -> str | None:
    """Why value is not acceptable for the estimator's parameter name, or None."""
    return _check(name, value, default, ranges, METHOD_OPTIONS, TEXT_CHECKS)


def method_options(p: dict, method: str) -> dict:
    """The NAME.<field> parameters of a method that a user set (not at their defaults): given
    over the spec's NAME:key=value options, as the filter_* parameters are."""
    return {
        key.partition(".")[2]: p[key]
        for key, option in METHOD_OPTIONS.items()
        if key.partition(".")[0] == method and p[key] != option.default
    }


def shared_options(p: dict) -> dict:
    """What the estimator and its budget fallback are both given, so that their poses are
    alike: the filter_* parameters a user set, foot_lock and predict_ahead."""
    shared = {k: p[k] for k, (default, _) in PARAMETERS.items() if k.startswith(FILTER) and p[k] != default}
    if p.get("predict_ahead"):
        shared["predict_ahead"] = p["predict_ahead"]
    shared["foot_lock"] = bool(p["foot_lock"])
    return shared


def estimator_options(p: dict) -> tuple[str, dict, dict]:
    """(method, the options it is made with, the spec's options a parameter overrode). One
    merge order for the filter and the method's options: their defaults, then the spec
    string's options, then the filter_* and NAME.<field> parameters a user set (those not at
    their defaults); the estimator applies them (create_estimator), so nothing sets its filter
    a second time."""
    name, spec = parse_estimator_spec(p["estimator"])
    options = dict(spec)
    options.update(method_options(p, name))
    if p["model_path"]:
        options["model_path"] = p["model_path"]
    options.update(shared_options(p))
    overridden = {key: value for key, value in spec.items() if key in options and options[key] != value}
    return name, options, overridden


def fallback_options(p: dict) -> tuple[str, dict] | None:
    """(method, options) of the estimator for frames the estimator's step misses its budget
    on (None: none), with the same filter parameters, so both see the trackers alike."""
    name, options = parse_estimator_spec(p["budget_fallback"]) if p["budget_fallback"] else ("", {})
    if not name or name == parse_estimator_spec(p["estimator"])[0]:
        return None
    return name, {**options, **method_options(p, name), **shared_options(p)}
