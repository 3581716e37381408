"""What the commands share: argument types, the motion capture folder, the parser that
keeps a usage error to one line."""

from __future__ import annotations

import argparse
from pathlib import Path

from ...io.topics import ESTIMATE_TOPICS
from .exits import EXIT_USAGE


def mocap_root(args) -> Path:
    from ...data.catalog import find_mocap_root

    root = find_mocap_root(args.mocap)
    if root is None:  # main() makes it one line with the input error's exit code
        raise ValueError(
            "no motion capture found; index one with `sparse-body import-mocap FOLDER --out DIR`, "
            "then pass --mocap DIR or set SPARSE_BODY_MOCAP"
        )
    return root


RESULTS_DIR = "sparse_body_results"  # where eval writes when --output is not given


def motion_of(args):
    """The motion named by --clip, --motion or --synthetic (in that order of preference)."""
    from ...data.catalog import load_clip, load_motion_file, read_index
    from ...data.synthetic import synthetic_walk

    if args.motion:
        return load_motion_file(Path(args.motion), args.fps)
    if args.clip:
        index = {c.clip_id: c for c in read_index(mocap_root(args))}
        if args.clip not in index:
            raise ValueError(f"no clip {args.clip!r} in {mocap_root(args)}/clips.tsv")
        return load_clip(index[args.clip], args.fps)
    return synthetic_walk(args.seconds, args.fps)


def rates(frames: int, timings: dict[str, float]) -> str:
    """Frames a second of each part of a run, and the whole run's time, so that a user sees
    what bounds it (reading and writing beside the estimation, or taking turns with it)."""
    parts = [("reading", "read"), ("estimation", "estimate"), ("writing", "write")]
    said = [f"{name} {frames / max(timings[key], 1e-9):,.0f} frames/s ({timings[key]:.1f} s)" for name, key in parts]
    how = "side by side" if timings["parallel"] else "in turn"
    return (
        f"{', '.join(said)}, {how}; the estimator's start {timings['start']:.1f} s; "
        f"the whole run {timings['wall']:.1f} s"
    )


def positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def between(low: float, high: float, unit: str = ""):
    """An argparse type: a finite number from low to high (both included)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not low <= value <= high:  # NaN fails too
            raise argparse.ArgumentTypeError(
                f"must be from {low:g} to {high:g}{' ' + unit if unit else ''}, got {text}"
            )
        return value

    parse.__name__ = "number"
    return parse


def topics(text: str) -> tuple[str, ...]:
    """--topics: a comma-separated choice of the estimate bag's topics, in the bag's order."""
    given = {t.strip() if t.strip().startswith("/") else "/" + t.strip() for t in text.split(",") if t.strip()}
    unknown = sorted(given - set(ESTIMATE_TOPICS))
    if unknown or not given:
        raise argparse.ArgumentTypeError(f"{', '.join(unknown) or 'no topic'}: choose from {','.join(ESTIMATE_TOPICS)}")
    return tuple(t for t in ESTIMATE_TOPICS if t in given)


def between_int(low: int, high: int):
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"must be from {low} to {high}, got {value}")
        return value

    parse.__name__ = "integer"
    return parse


percent = between(0.0, 100.0, "%")


jumps_per_minute = between(0.0, 600.0, "jumps a minute")


degrees_per_minute = between(0.0, 360.0, "degrees a minute")


fps = between(1.0, 1000.0, "Hz")


height = between(0.5, 2.5, "metres")
# an hour of synthetic motion is 216,000 frames at 60 Hz; longer runs belong in a recording


seconds = between(0.0, 3600.0, "seconds")


def choices_text() -> str:
    from ...core.resources import config_dir
    from ...methods import METHODS

    sensors = sorted(p.stem for p in (config_dir() / "sensors").glob("*.yaml"))
    return (
        f"estimators: {', '.join(sorted(METHODS))} (options as NAME:key=value,...); "
        f"sensor configurations: {', '.join(sensors)} (or a YAML path)"
    )


class DefaultOnceFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """--help with each option's default said once: not where its help says it already (it
    was printed twice, "(default: the cores ...) (default: 2)"), nor where there is none to
    say (None, off)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if "default" in text or action.default in (None, False, argparse.SUPPRESS) or not action.option_strings:
            return text
        return text + " (default: %(default)s)"


class OneLineParser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (the usage is one --help away)."""

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"{self.prog}: {message} (see {self.prog} --help)\n")


USER_DESCRIPTION = (
    "A person's whole body from a few trackers (a headset, hand controllers, optionally pelvis "
    "and feet), without ROS: make tracker bags from motion, process recordings into body "
    "estimates, evaluate the estimators, view the results in a browser. "
    "`sparse-body COMMAND --help` says more of each."
)
