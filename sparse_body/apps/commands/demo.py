"""`sparse-body demo`: its arguments (add_parser) and what it runs (run)."""

from __future__ import annotations

from pathlib import Path

from .common import seconds


def run(args) -> int:
    from ...core.sensors import load_sensor_config
    from ...data.catalog import find_mocap_root
    from ...estimators.base import parse_estimator_spec
    from ...methods.factory import check_estimator_name
    from ...methods.recommended import resolve_estimator
    from ..demo import run_demo

    check_estimator_name(parse_estimator_spec(args.estimator)[0])  # before the folder is made
    if args.motion and not Path(args.motion).exists():
        raise ValueError(f"{args.motion}: no such file")
    sensors = load_sensor_config(args.sensors)
    run_demo(
        Path(args.out),
        sensors,
        resolve_estimator(args.estimator, sensors.name),
        find_mocap_root(args.mocap),
        args.motion,
        args.seconds,
        gif=not args.no_gif,
    )
    return 0


def add_parser(sub) -> None:
    p = sub.add_parser("demo", help="motion -> tracker bag -> estimator -> metrics and an animation")
    p.add_argument("--out", default="sparse_body_demo", help="folder for the bags and demo.gif")
    p.add_argument(
        "--sensors", default="six_point", help="the trackers the demo's bag holds: a configuration name or YAML path"
    )
    p.add_argument(
        "--estimator",
        default="auto",
        help="the estimator, with options as NAME:key=value,...; auto: the one recommended for the sensors",
    )
    p.add_argument("--motion", help="a motion file to use instead of the CMU demo clip")
    p.add_argument("--mocap", help="the CMU folder")
    p.add_argument("--seconds", type=seconds, default=6.0, help="the length of the synthetic walk")
    p.add_argument("--no-gif", action="store_true", help="skip the animation")
    p.set_defaults(func=run)
