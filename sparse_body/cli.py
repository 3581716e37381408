"""The `sparse-body` command: argument parsing and dispatch to apps/.

Kept at the package's top level as the entry point that users and tests name
(`sparse-body`, `python -m sparse_body.cli`); the work it dispatches lives in apps/."""

from __future__ import annotations

import argparse
import os
import re
import sys
from collections import Counter
from dataclasses import replace
from pathlib import Path

from .io.tf_guards import TfGuards
from .io.topics import COMPRESSIONS, ESTIMATE_TOPICS


def _mocap(args) -> Path:
    from .data.catalog import find_mocap_root

    root = find_mocap_root(args.mocap)
    if root is None:  # main() makes it one line with the input error's exit code
        raise ValueError(
            "no motion capture found; index one with `sparse-body import-mocap FOLDER --out DIR`, "
            "then pass --mocap DIR or set SPARSE_BODY_MOCAP"
        )
    return root


RESULTS_DIR = "sparse_body_results"  # where eval writes when --output is not given


def cmd_eval(args) -> int:
    from .apps.evaluation import (
        check_results_path,
        file_items,
        format_groups,
        format_table,
        run_evaluation,
        split_items,
        untrained_categories,
    )
    from .core.forecast import MAX_AHEAD
    from .core.sensors import load_sensor_config
    from .data.field_protocol import Protocol
    from .methods import METHODS, paper_figures

    sensors = load_sensor_config(args.sensors)
    if args.horizon is not None and not 0.0 <= args.horizon <= MAX_AHEAD:
        raise ValueError(f"--horizon must be from 0 to {MAX_AHEAD:g} seconds, got {args.horizon:g}")
    specs, reference = list(args.estimator), {}
    if not args.no_compare:
        for name in args.estimator:
            compare = METHODS[name].compare_with if name in METHODS else ()
            specs += [s for s in compare if s not in specs]
            reference.update(paper_figures(name, sensors.name, args.faulty or 0.0, args.occlusion or 0.0))
    protocol = Protocol.preset(
        args.protocol,
        skeleton=args.skeleton,
        noise=args.noise,
        faulty_percent=args.faulty,
        mounting_error=args.mounting_error,
        occluded_percent=args.occlusion,
        lost_percent=args.hand_loss,
        loss_mode=args.hand_loss_mode,
        jumps_per_minute=args.jumps,
        yaw_drift=args.yaw_drift,
        calibrate_mounting=args.calibrate_mounting,
    )
    if args.motion:  # the files are found and every AMC paired with its ASF before any work
        from .data.motion_inputs import balanced, find_inputs

        group_by = args.group_by or "folder"
        inputs = balanced(find_inputs(args.motion, args.skeleton_file, group_by), args.limit)
        items, split = file_items(inputs, args.fps, args.amc_fps), "files"
        hows = Counter(i.how for i in inputs if i.is_amc)
        if hows:
            print(
                f"AMC files taken as captured at {args.amc_fps:g} Hz (--amc-fps); skeletons: "
                + ", ".join(f"{n} {how}" for how, n in hows.items()),
                file=sys.stderr,
            )
    else:
        if args.skeleton_file or args.group_by == "folder":
            raise ValueError("--skeleton-file and --group-by folder are for --motion files")
        items, split = split_items(_mocap(args), args.split, args.fps, args.limit), args.split
        if args.group_by != "prefix":  # the split's clips: by subject with --group-by prefix
            items = [replace(i, group="") for i in items]
    stem = re.sub(r"[^\w.+-]", "_", "+".join(args.estimator))
    if args.output:
        out = Path(args.output)
    else:
        folder = Path(RESULTS_DIR)
        if not (folder.exists() or folder.is_symlink()):  # ours to make; anything else there is checked below
            folder.mkdir()
        out = folder / f"eval_{stem}_{sensors.name}.json"
    out = check_results_path(out)  # before the work
    print(f"results: {out} (written after each clip; the same command resumes)", file=sys.stderr)
    results = run_evaluation(
        specs,
        sensors,
        items,
        split,
        args.fps,
        protocol,
        args.per_joint,
        out=out,
        progress=not args.quiet,
        warn=lambda text: print(f"warning: {text}", file=sys.stderr),
        **({} if args.horizon is None else {"horizon": args.horizon}),
    )
    if not results[0].clips:
        raise ValueError(
            f"no clip could be evaluated: {results[0].skipped[0]['clip']}: {results[0].skipped[0]['reason']}"
            if results[0].skipped
            else "no clips to evaluate"
        )
    print(format_table(results, reference, intervals=args.intervals))
    groups = format_groups(results, label=args.group_by or ("folder" if args.motion else "group"))
    if groups:
        print(groups)
    if results[0].subject_units() is not None:  # each person's own figure: the spread behind the mean
        print(format_groups(results, label="person", by="subject"))
    if not args.motion and len(set(results[0].categories)) > 1:  # each kind of motion, unseen ones marked
        notes = untrained_categories(_mocap(args), results[0].categories)
        for metric in ("MPJPE [cm]", "Lower PE [cm]"):
            print(format_groups(results, metric, label="motion", by="category", notes=notes))
    print(f"written {out}")
    skipped = {s["clip"]: s["reason"] for r in results for s in r.skipped}
    if skipped:
        first, why = next(iter(skipped.items()))
        print(
            f"sparse-body: {len(skipped)} of {len(items)} clips skipped (each in {out} under 'skipped'); "
            f"{first}: {why}",
            file=sys.stderr,
        )
        return EXIT_INPUT
    return 0


def _training(method: str):
    """The method's training record (train's choices name only trainable methods)."""
    from .methods import METHODS

    training = METHODS[method].training
    if training is None:
        raise ValueError(f"{method} is not trained (no learned model)")
    return training


def _trainers(args) -> list[tuple]:
    """(config class, train function, output, report file) for each part the command trains."""
    from .core.resources import models_dir
    from .methods import load

    training = _training(args.method)
    names = [part.name for part in training.parts]
    if args.part != "all" and args.part not in names:
        raise ValueError(f"{args.method} has no part {args.part!r}; its parts: all, {', '.join(names)}")
    parts = [part for part in training.parts if args.part in ("all", part.name)]
    config_classes = [load(part.config) for part in parts]
    out = Path(args.out or models_dir() / training.output(lambda: _config(config_classes[0], args)))
    return [
        (config_class, load(part.train), out, part.report(out))
        for part, config_class in zip(parts, config_classes, strict=True)
    ]


def cmd_train(args) -> int:
    import json

    import torch

    from .train.harness import TrainRun, beside, with_earlier_runs

    parts = _trainers(args)
    if args.ablate_augment:
        torch.set_num_threads(args.threads)
        _ablate_augmentation(args, parts)
        return 0
    if not (args.card_only or args.render_only):
        torch.set_num_threads(args.threads)
        configs = [_config(config_class, args) for config_class, *_ in parts]  # errors before training
        for config, (_, train, out, report_path) in zip(configs, parts, strict=True):
            checkpoint = beside(report_path, ".checkpoint.npz")
            earlier = json.loads(report_path.read_text()) if args.resume and report_path.is_file() else None
            report = train(
                config, TrainRun(_mocap(args), out, args.seed, args.limit, checkpoint=checkpoint, resume=args.resume)
            )
            if not args.keep_checkpoint:
                checkpoint.unlink(missing_ok=True)  # the model is exported: nothing left to resume
            report["command"] = "sparse-body " + " ".join(sys.argv[1:])
            report = with_earlier_runs(report, earlier)
            report_path.parent.mkdir(parents=True, exist_ok=True)
            report_path.write_text(json.dumps(report, indent=1))
            print(f"written {out} and {report_path}")
    if not args.no_card:
        mocap = None if args.render_only else _mocap(args)  # rendering reads only the measured JSON
        card = _training(args.method).card(parts[0][2], mocap, args.limit, not args.render_only)
        print(f"written {card}")
    return 0


def _config(config_class, args):
    """The named training configuration with the command line's overrides: --minutes,
    --steps, --augment, and --set FIELD=VALUE (the value read as the field's type)."""
    from dataclasses import fields

    from .train.augment import Augmentation

    config = config_class.named(args.config)
    if args.minutes is not None:
        config.minutes = args.minutes
    if args.steps is not None:
        config.steps = args.steps
    if args.augment is not None:
        config.augment = Augmentation.parse(args.augment).spec  # refused here, before any training
    types = {f.name: type(getattr(config, f.name)) for f in fields(config)}
    for item in args.set:
        name, _, value = item.partition("=")
        if name not in types or not value:
            raise ValueError(f"--set {item!r}: expected FIELD=VALUE with FIELD one of {', '.join(types)}")
        kind = types[name]
        try:
            setattr(config, name, value.lower() in ("1", "true", "yes") if kind is bool else kind(value))
        except ValueError:
            raise ValueError(f"--set {item!r}: {name} takes a {kind.__name__}") from None
    return config


def _ablate_augmentation(args, parts) -> None:
    """Each part trained anew (same seed and budget) without augmentation, with its
    configuration's, and with each of those augmentations left out; the validation figures go
    to <model>.augment.json beside the training report, for the model card."""
    import json
    import shutil
    import tempfile

    from .train.augment import Augmentation
    from .train.harness import TrainRun, beside

    for config_class, train, out, report_path in parts:
        kinds = Augmentation.parse(args.augment or config_class.named(args.config).augment).kinds
        specs = ["none", ",".join(kinds) or "none"]
        if len(kinds) > 1:
            specs += [",".join(k for k in kinds if k != left) for left in kinds]
        runs = []
        for spec in dict.fromkeys(specs):
            config = _config(config_class, args)
            config.augment = spec
            with tempfile.TemporaryDirectory() as tmp:
                if out.is_dir():  # what an earlier part left there (the predictor trains in the VAE's space)
                    shutil.copytree(out, tmp, dirs_exist_ok=True)
                target = Path(tmp) / out.name if out.suffix == ".onnx" else Path(tmp)
                report = train(config, TrainRun(_mocap(args), target, args.seed, args.limit))
            runs.append(
                {
                    "augment": spec,
                    "steps": report["steps"],
                    "minutes": report["minutes"],
                    "validation": report["validation"],
                }
            )
            print(f"augment {spec}: {report['validation']}")
        path = beside(report_path, ".augment.json")
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(
            json.dumps({"command": "sparse-body " + " ".join(sys.argv[1:]), "seed": args.seed, "runs": runs}, indent=1)
        )
        print(f"written {path}")


def cmd_options(args) -> int:
    from .apps import option_docs
    from .methods import METHODS

    if args.markdown:
        print(option_docs.markdown(), end="")
    else:
        print("\n\n".join(option_docs.text(m) for m in ([args.method] if args.method else METHODS)))
    return 0


def cmd_split(args) -> int:
    from .data.catalog import compute_split, read_index, split_path, split_yaml

    clips = read_index(_mocap(args))
    parts = compute_split(clips)
    subjects = {part: sorted({cid.split("_")[0] for cid in ids}, key=int) for part, ids in parts.items()}
    text = split_yaml(
        parts,
        "Train / validation / test split of the CMU motion capture clips, by subject: no\n"
        "test or validation subject has a take in training, so the test figures are those of\n"
        "people the models never saw. Written by `sparse-body split --write` (the rule is in\n"
        "sparse_body/data/catalog.py: compute_split). Every estimator trains and evaluates on it.\n"
        + "".join(f"{part} subjects: {', '.join(s)}\n" for part, s in subjects.items()),
    )
    if args.write:
        split_path().write_text(text)
        print(f"written {split_path()}")
    else:
        print(text)
    for part, ids in parts.items():
        print(f"{part}: {len(ids)} clips", file=sys.stderr)
    return 0


def cmd_import_mocap(args) -> int:
    from .data.user_mocap import import_motion

    progress = None
    if not args.quiet:
        from tqdm import tqdm

        progress = lambda files: tqdm(files, desc="reading motion files", unit="file")  # noqa: E731
    clips, skipped = import_motion(args.sources, Path(args.out), progress)
    for path, why in skipped:
        print(f"left out {path}: {why}", file=sys.stderr)
    subjects = len({c.subject for c in clips})
    minutes = sum(c.seconds for c in clips) / 60
    print(
        f"written {args.out}/clips.tsv and split.yaml: {len(clips)} clips of {subjects} subjects, "
        f"{minutes:.1f} minutes ({len(skipped)} files left out)\n"
        f"use it with --mocap {args.out} (or SPARSE_BODY_MOCAP={args.out}): "
        f"sparse-body eval --mocap {args.out} --estimator ik --sensors six_point"
    )
    return 0


def _motion(args):
    """The motion named by --clip, --motion or --synthetic (in that order of preference)."""
    from .data.catalog import load_clip, load_motion_file, read_index
    from .data.synthetic import synthetic_walk

    if args.motion:
        return load_motion_file(Path(args.motion), args.fps)
    if args.clip:
        index = {c.clip_id: c for c in read_index(_mocap(args))}
        if args.clip not in index:
            raise ValueError(f"no clip {args.clip!r} in {_mocap(args)}/clips.tsv")
        return load_clip(index[args.clip], args.fps)
    return synthetic_walk(args.seconds, args.fps)


def cmd_make_bag(args) -> int:
    from .apps.offline import make_bag
    from .core.sensors import load_sensor_config
    from .data.virtual_trackers import LOBSTR_NOISE, NO_NOISE

    if not (args.clip or args.motion or args.seconds > 0):
        raise ValueError("make-bag needs a motion: --clip ID, --motion FILE, or --seconds S of the synthetic walk")
    motion = _motion(args)
    if args.seconds and (args.clip or args.motion):
        motion = motion.slice(0, int(args.seconds * motion.fps))
    n = make_bag(
        motion,
        load_sensor_config(args.sensors),
        Path(args.out),
        LOBSTR_NOISE if args.noise else NO_NOISE,
        overwrite=args.overwrite,
        inputs=tuple(Path(p) for p in [args.motion, args.sensors] if p),
    )
    print(f"written {args.out}: {n} frames of {motion.name} at {motion.fps:g} Hz")
    return 0


def cmd_process(args) -> int:
    from .apps.batch import SUMMARY, Settings, is_bag, process_many
    from .apps.offline import process_bag
    from .core.calibration import person_body
    from .core.sensors import load_sensor_config
    from .estimators.base import parse_estimator_spec
    from .io.bagio import BagError

    name, options = parse_estimator_spec(args.estimator)
    if args.smooth:
        options["smooth"] = True
    body = person_body(args.calibration, args.height)
    robot = None
    if args.robot:
        from .robot.retarget import load_retarget

        load_retarget(args.robot, args.robot_urdf, body)  # one line on a bad robot file, before any work
        robot = (str(Path(args.robot).resolve()), str(Path(args.robot_urdf).resolve()) if args.robot_urdf else "")
    elif args.robot_urdf:
        raise ValueError("--robot-urdf goes with --robot (the mapping of the robot's links to the body)")
    guards = TfGuards(clock_window=args.clock_window, future_window=args.future_window, play_radius=args.play_radius)
    inputs = [Path(p) for p in args.bag_in]
    many = len(inputs) > 1 or (inputs[0].is_dir() and not is_bag(inputs[0]))
    if many or args.cluster:  # OUT is a folder
        args.left_when_stopped = (  # what main() says on a stop
            f"the bags finished are kept (see {Path(args.bag_out) / SUMMARY}), the ones being written were "
            "removed; the same command resumes"
        )
        settings = Settings(
            name,
            options,
            load_sensor_config(args.sensors),
            body,
            args.fps,
            guards,
            args.overwrite,
            args.topics,
            args.compression,
            args.axis_links,
            robot,
        )
        results = process_many(
            inputs, Path(args.bag_out), settings, args.jobs, progress=not args.quiet, cluster=args.cluster
        )
        count = Counter(r.status for r in results)
        failed = [r for r in results if r.status == "failed"]
        print(
            f"{args.bag_out}: {len(results)} bags, {count['done']} done, {count['skipped']} skipped "
            f"(finished before), {len(failed)} failed; each bag in {Path(args.bag_out) / SUMMARY}"
        )
        if failed:
            raise BagError(f"{len(failed)} of {len(results)} bags failed, the first: {failed[0].error}")
        return 0
    refused: dict[str, int] = {}
    timings: dict[str, float] = {}
    result = process_bag(
        inputs[0],
        Path(args.bag_out),
        name,
        load_sensor_config(args.sensors),
        body,
        args.fps,
        progress=not args.quiet,
        overwrite=args.overwrite,
        refused=refused,
        guards=guards,
        topics=args.topics,
        compression=args.compression,
        axis_links=args.axis_links,
        timings=timings,
        robot=robot,
        **options,
    )
    rejected = ", ".join(f"{n} {reason}" for reason, n in sorted(refused.items())) or "none"
    print(
        f"written {args.bag_out}: {result.frames} estimates ({result.invalid} marked invalid); "
        f"tracker samples refused: {rejected}"
    )
    print(_rates(result.frames, timings))
    return 0


def _rates(frames: int, timings: dict[str, float]) -> str:
    """Frames a second of each part of a run, and the whole run's time, so that a user sees
    what bounds it (reading and writing beside the estimation, or taking turns with it)."""
    parts = [("reading", "read"), ("estimation", "estimate"), ("writing", "write")]
    said = [f"{name} {frames / max(timings[key], 1e-9):,.0f} frames/s ({timings[key]:.1f} s)" for name, key in parts]
    how = "side by side" if timings["parallel"] else "in turn"
    return (
        f"{', '.join(said)}, {how}; the estimator's start {timings['start']:.1f} s; "
        f"the whole run {timings['wall']:.1f} s"
    )


def cmd_demo(args) -> int:
    from .apps.demo import run_demo
    from .core.sensors import load_sensor_config
    from .data.catalog import find_mocap_root

    run_demo(
        Path(args.out),
        load_sensor_config(args.sensors),
        args.estimator,
        find_mocap_root(args.mocap),
        args.motion,
        args.seconds,
        gif=not args.no_gif,
    )
    return 0


def cmd_view(args) -> int:
    from .apps.batch import is_bag
    from .apps.evaluation import is_results_file
    from .apps.viewer import bag_bodies, write_body_page

    source = Path(args.source) if args.source else None
    if (args.robot or args.robot_urdf) and not (source is not None and is_bag(source)):
        raise ValueError("--robot draws the robot of an estimate bag written with process --robot: give the bag")
    title = None
    parts: dict  # what the page draws, by name: arrays (None: not shown)
    if args.source and args.source.startswith(("ws://", "wss://")):
        from .apps.live_record import record_tf
        from .apps.viewer import tf_bodies

        messages, malformed = record_tf(args.source, args.seconds)
        positions, trackers, fps = tf_bodies(messages, args.source)
        parts, name = {"estimate": positions, "trackers": trackers}, "live"
        print(
            f"{len(positions)} estimates in {args.seconds:g} s"
            + (f"; {malformed} /tf messages that were not TFMessages left out" if malformed else "")
        )
    elif source is not None and is_bag(source):
        positions, trackers, fps = bag_bodies(source)
        parts = {"estimate": positions, "trackers": trackers}
        name = source.name
        if args.robot:  # the robot the bag was written with, beside the body
            from .apps.viewer import bag_robot
            from .core.skeleton import Skeleton
            from .robot.retarget import load_retarget

            retarget = load_retarget(args.robot, args.robot_urdf, Skeleton.canonical())
            parts["robot"], parts["robot_bones"] = bag_robot(source, retarget, positions[:, 0])
    elif source is not None and is_results_file(source):
        from .apps.result_view import view_clip
        from .data.catalog import find_mocap_root

        if not args.clip:
            raise ValueError("a results file holds many clips: name one with --clip")
        shown = view_clip(source, args.clip, args.estimator, find_mocap_root(args.mocap))
        parts, fps, title = shown.parts(), shown.run.motion.fps, shown.title
        name = f"{shown.run.motion.name}_{shown.result.estimator}"
        print(title)
    else:
        if args.estimator:
            raise ValueError("--estimator picks a result of a results file (what eval --output wrote)")
        if source is not None:
            args.motion = str(source)
        elif not args.clip:
            raise ValueError("view needs something to show: an estimate bag, a motion file or --clip ID")
        motion = _motion(args)
        parts, fps, name = {"truth": motion.positions}, motion.fps, motion.name
    page = write_body_page(Path(args.output or f"{name}.html"), fps, args.overwrite, title=title or name, **parts)
    print(f"written {page}: open it in a browser (no network needed)")
    return 0


def cmd_bench(args) -> int:
    from .apps.bench import run, run_goals
    from .methods import METHODS, load

    if args.runtime:
        bench = METHODS[args.runtime].runtime_bench
        if bench is None:
            raise ValueError(f"{args.runtime} has no runtime bench")
        load(bench)()
        return 0
    if args.estimator:
        run(args.estimator, args.sensors, latency=not args.no_latency)
    else:
        run_goals(latency=not args.no_latency)
    return 0


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def _between(low: float, high: float, unit: str = ""):
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


def _topics(text: str) -> tuple[str, ...]:
    """--topics: a comma-separated choice of the estimate bag's topics, in the bag's order."""
    given = {t.strip() if t.strip().startswith("/") else "/" + t.strip() for t in text.split(",") if t.strip()}
    unknown = sorted(given - set(ESTIMATE_TOPICS))
    if unknown or not given:
        raise argparse.ArgumentTypeError(f"{', '.join(unknown) or 'no topic'}: choose from {','.join(ESTIMATE_TOPICS)}")
    return tuple(t for t in ESTIMATE_TOPICS if t in given)


def _between_int(low: int, high: int):
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


_percent = _between(0.0, 100.0, "%")
_jumps_per_minute = _between(0.0, 600.0, "jumps a minute")
_degrees_per_minute = _between(0.0, 360.0, "degrees a minute")
_fps = _between(1.0, 1000.0, "Hz")
_height = _between(0.5, 2.5, "metres")
# an hour of synthetic motion is 216,000 frames at 60 Hz; longer runs belong in a recording
_seconds = _between(0.0, 3600.0, "seconds")


def _choices_text() -> str:
    from .core.resources import config_dir
    from .methods import METHODS

    sensors = sorted(p.stem for p in (config_dir() / "sensors").glob("*.yaml"))
    return (
        f"estimators: {', '.join(sorted(METHODS))} (options as NAME:key=value,...); "
        f"sensor configurations: {', '.join(sensors)} (or a YAML path)"
    )


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (the usage is one --help away)."""

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"{self.prog}: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    from .methods import METHODS, TRAINABLE

    parser = _Parser(prog="sparse-body", description=USER_DESCRIPTION, epilog=_choices_text())
    sub = parser.add_subparsers(dest="command", required=True)
    _add = sub.add_parser
    # every subcommand's --help shows the defaults and what can be chosen
    sub.add_parser = lambda *a, **k: _add(  # type: ignore[method-assign]
        *a, formatter_class=argparse.ArgumentDefaultsHelpFormatter, epilog=_choices_text(), **k
    )

    p = sub.add_parser("demo", help="motion -> tracker bag -> estimator -> metrics and an animation")
    p.add_argument("--out", default="sparse_body_demo", help="folder for the bags and demo.gif")
    p.add_argument("--sensors", default="six_point")
    p.add_argument("--estimator", default="ik")
    p.add_argument("--motion", help="a motion file to use instead of the CMU demo clip")
    p.add_argument("--mocap", help="the CMU folder")
    p.add_argument("--seconds", type=_seconds, default=6.0, help="the length of the synthetic walk")
    p.add_argument("--no-gif", action="store_true", help="skip the animation")
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser("eval", help="run estimators over a split of the CMU clips and print the metrics")
    p.add_argument(
        "--estimator",
        action="append",
        required=True,
        help="estimator name, optionally with options: lobstr:contact_ik=false (repeat to compare several)",
    )
    p.add_argument("--sensors", default="three_point", help="sensor configuration name or YAML path")
    p.add_argument("--split", default="test", choices=["train", "validation", "test"])
    p.add_argument("--fps", type=_fps, default=60.0, help="frame rate the clips are resampled to")
    p.add_argument(
        "--protocol",
        default="field",
        choices=["field", "field-exact", "lab"],
        help="what the estimators are given (each value below overrides the protocol's own): field, a "
        "user's session (calibrated body, VR noise, trackers worn 1.5 cm off and found by the mounting "
        "calibration, hands lost 3 %%, a Lighthouse jump a minute, IMU heading drift up to 2 deg/min); "
        "field-exact, the same with exact mounting and no failures (docs tables measured before "
        "2026-12); lab, the true skeleton without noise (the papers')",
    )
    p.add_argument(
        "--skeleton",
        choices=["calibrated", "height", "oracle"],
        help="the body the estimator gets: fitted by a T-pose calibration (trackers mounted as a user "
        "wears them), the canonical body at the calibrated height, or the subject's true skeleton "
        "with exact mounting (the lab protocol, with --noise none)",
    )
    p.add_argument(
        "--noise",
        choices=["vr", "lobstr", "none"],
        help="tracker noise: a VR system's (1 mm, 0.5 deg on average), LoBSTr's (1 cm, 1.5 deg) or none",
    )
    p.add_argument(
        "--mounting-error",
        type=_between(0.0, 0.5, "metres"),
        metavar="METRES",
        help="an error in each tracker's mounting translation, unknown to the user (std per axis, per "
        "clip; not with --skeleton oracle; field: 0.015); the T-pose does not find it, "
        "--calibrate-mounting does",
    )
    p.add_argument(
        "--calibrate-mounting",
        action=argparse.BooleanOptionalAction,
        help="after the T-pose, the person turns the head, circles the wrists and ankles and rolls the "
        "hips for 15 s, and the calibration finds each tracker's mounting translation from it, as the "
        "tracker bridge's ~/calibrate_mounting does (not with --skeleton oracle; field: on)",
    )
    p.add_argument(
        "--faulty",
        type=_percent,
        metavar="PERCENT",
        help="DragPoser's faulty sensors: each frame, with this probability (%%), one tracker "
        "disconnects for 100 frames",
    )
    p.add_argument(
        "--occlusion",
        type=_percent,
        metavar="PERCENT",
        help="DTP's foot occlusion: in about this share (%%) of the frames one or both foot trackers "
        "lose sight for half a second and report the origin with the identity rotation or noise "
        "within a leg's length",
    )
    p.add_argument(
        "--hand-loss",
        type=_percent,
        metavar="PERCENT",
        help="a headset losing its controllers: each hand out of view in about this share (%%) of the "
        "frames, 0.2-2 s at a time (field: 3); adds the hands' error while lost and their recovery jump",
    )
    p.add_argument(
        "--hand-loss-mode",
        choices=("lost", "frozen"),
        help="how a lost hand is reported: no sample (lost, the default) or its last sample repeated (frozen)",
    )
    p.add_argument(
        "--jumps",
        type=_jumps_per_minute,
        metavar="PER_MINUTE",
        help="Lighthouse reflections: about this many times a minute each tracked position jumps "
        "2-8 cm in a random direction for 2-8 frames (field: 1)",
    )
    p.add_argument(
        "--yaw-drift",
        type=_degrees_per_minute,
        metavar="DEG_PER_MINUTE",
        help="IMUs without a magnetometer: each orientation-only sensor's heading drifts at a steady "
        "rate drawn per clip up to this (degrees a minute; field: 2)",
    )
    p.add_argument(
        "--limit",
        type=_positive_int,
        help="only N clips: the first of the split, or of the --motion files taken in turn from each group",
    )
    p.add_argument(
        "--intervals",
        action="store_true",
        help="each mean in the table with its 95 %% bootstrap intervals, clips drawn and people drawn",
    )
    p.add_argument(
        "--horizon",
        type=float,
        metavar="SECONDS",
        help="score each pose against the body this long after its frame (default: the estimator's "
        "predict_ahead; a horizon without predict_ahead: the present pose given as the later one, what a "
        "forecast must beat)",
    )
    p.add_argument(
        "--per-joint",
        action="store_true",
        help="also each joint's position and rotation error (rows 'PE <joint> [cm]', 'RE <joint> [deg]'): "
        "where an estimator's error sits",
    )
    p.add_argument(
        "--motion",
        action="append",
        metavar="PATH",
        help="evaluate on these motion files instead of the CMU split (repeat): a file, a folder (searched "
        "recursively for .bvh / .amc / .npz) or AMC=ASF; an AMC file gets the ASF beside it whose "
        "name starts its own, else the only ASF in its folder",
    )
    p.add_argument("--skeleton-file", metavar="ASF", help="the ASF skeleton of every AMC file given")
    p.add_argument(
        "--amc-fps",
        type=_fps,
        default=120.0,
        metavar="HZ",
        help="the rate AMC files were captured at (the files do not say)",
    )
    p.add_argument(
        "--group-by",
        choices=["folder", "prefix", "none"],
        help="figures by group as well: the file's folder under the --motion folder, or its name up to "
        "the first _ or - (an actor; CMU's subject); default: folder for --motion",
    )
    p.add_argument("--mocap", help="an indexed motion capture folder (`import-mocap`; default: $SPARSE_BODY_MOCAP)")
    p.add_argument(
        "--output",
        help=f"where to write the JSON results (default: {RESULTS_DIR}/eval_ESTIMATOR_SENSORS.json); "
        "written after each clip, and an earlier run's file under the same settings is resumed",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument(
        "--no-compare",
        action="store_true",
        help="only the named estimators: no baseline, ablation or paper figures beside them",
    )
    p.set_defaults(func=cmd_eval)

    p = sub.add_parser("make-bag", help="write a rosbag2 (MCAP) of tracker TF from a motion")
    p.add_argument("out", help="the bag directory to create")
    p.add_argument("--sensors", default="six_point", help="sensor configuration name or YAML path")
    p.add_argument("--clip", help="a CMU clip id (e.g. 02_01)")
    p.add_argument("--motion", help="a motion file (.bvh, .amc, .npz)")
    p.add_argument(
        "--seconds", type=_seconds, default=0.0, help="length of the synthetic walk, or cut a clip to this length"
    )
    p.add_argument("--fps", type=_fps, default=60.0)
    p.add_argument("--noise", action="store_true", help="add LoBSTr's tracker noise")
    p.add_argument("--mocap", help="the CMU folder")
    p.add_argument("--overwrite", action="store_true", help="replace OUT if it exists")
    p.set_defaults(func=cmd_make_bag)

    p = sub.add_parser(
        "process",
        help="run an estimator over a tracker bag and write an estimate bag; or over many bags into a folder",
    )
    p.add_argument(
        "bag_in",
        nargs="+",
        metavar="IN",
        help="a tracker bag; several, or a folder of them: each is processed into the folder OUT",
    )
    p.add_argument("bag_out", metavar="OUT", help="the estimate bag; with several inputs, the folder for them")
    p.add_argument(
        "--jobs",
        type=_between_int(1, 1024),
        default=len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1),
        help="worker processes for several bags (default: the cores this process may use)",
    )
    p.add_argument(
        "--cluster",
        metavar="ADDRESS",
        help="run the bags as tasks on a Ray cluster (HOST:PORT of `ray start --head`, or auto) whose nodes "
        "see the same files, instead of --jobs processes here; OUT is a folder",
    )
    p.add_argument(
        "--estimator",
        default="ik",
        help="estimator, with options: lobstr, refined:base=lobstr (DragPoser refinement after it)",
    )
    p.add_argument("--sensors", default="six_point")
    p.add_argument(
        "--topics",
        type=_topics,
        default=ESTIMATE_TOPICS,
        help="the topics each output bag holds, comma-separated (default: all of " + ",".join(ESTIMATE_TOPICS) + ")",
    )
    p.add_argument(
        "--compression",
        choices=COMPRESSIONS,
        default="zstd",
        help="the output's MCAP chunk compression, which every MCAP reader reads (default zstd; lz4 is "
        "faster and larger)",
    )
    p.add_argument(
        "--axis-links",
        action="store_true",
        help="put the URDF's massless links inside each joint on /tf too, for a viewer without "
        "robot_state_publisher (about 40 %% more output)",
    )
    p.add_argument(
        "--robot",
        help="a humanoid robot's mapping YAML (e.g. config/robots/unitree_h1.yaml): its joints on "
        "/robot/joint_states beside the body's, its base on /tf as robot/<base link>",
    )
    p.add_argument("--robot-urdf", help="the robot's URDF, where the mapping names none or another")
    p.add_argument("--height", type=_height, default=1.75, help="the tracked person's height in metres")
    p.add_argument(
        "--calibration",
        help="a T-pose calibration file (the bridge's ~/calibrate): its fitted body "
        "instead of the canonical one at --height",
    )
    p.add_argument("--fps", type=_fps, default=60.0, help="the trackers' nominal rate")
    p.add_argument(
        "--smooth",
        action="store_true",
        help="smooth the tracker input over the whole recording, forwards and backwards (the "
        "estimator option smooth=true): far less shaking under noise than the live filter",
    )
    p.add_argument(
        "--clock-window",
        type=_between(0.0, 1e9, "s"),
        default=TfGuards.clock_window,
        help="refuse /tf stamps further than this from the bag's receive times (a frame stamped 0); "
        "0: no check, for a bag recorded with simulated time",
    )
    p.add_argument(
        "--future-window",
        type=_between(0.001, 60.0, "s"),
        default=TfGuards.future_window,
        help="refuse /tf stamps further than this ahead of the bag's receive times",
    )
    p.add_argument(
        "--play-radius",
        type=_between(0.1, 1e6, "m"),
        default=TfGuards.play_radius,
        help="refuse trackers further than this from the fixed frame's origin",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--overwrite", action="store_true", help="replace BAG_OUT if it exists")
    p.set_defaults(func=cmd_process)

    p = sub.add_parser(
        "view", help="an HTML page that plays a body in 3D: an estimate bag, a motion file, a clip or an eval result"
    )
    p.add_argument(
        "source",
        nargs="?",
        help="an estimate bag (what process wrote), a motion file, a results file (what eval wrote) with --clip,"
        " or ws://HOST:PORT, the estimator's live view (foxglove_port), recorded for --seconds",
    )
    p.add_argument(
        "--clip",
        help="a CMU clip ID instead (the motion capture folder: --mocap), or the clip of a results file to estimate"
        " again",
    )
    p.add_argument("--estimator", help="which estimator's result, where a results file holds several for the clip")
    p.add_argument("--mocap", help="the CMU folder")
    p.add_argument("--output", "-o", help="the page (default: NAME.html here)")
    p.add_argument("--overwrite", action="store_true", help="replace the page if it is one `view` wrote")
    p.add_argument("--fps", type=_fps, default=60.0, help="a motion file's frame rate where it has none")
    p.add_argument("--seconds", type=float, default=10.0, help="how long to record a live view (at most 600)")
    p.add_argument(
        "--robot", help="draw the robot of an estimate bag written with process --robot beside the body (its mapping)"
    )
    p.add_argument("--robot-urdf", help="the robot's URDF, where the mapping names none or another")
    p.set_defaults(func=cmd_view, motion=None)

    p = sub.add_parser("bench", help="step times and end-to-end latency over DDS, beside their goals")
    p.add_argument(
        "--estimator",
        action="append",
        help="estimator(s) to measure on --sensors (default: the goal table: ik, lobstr, dragposer, dtp, avatarjlm "
        "step times and ik's TF -> JointState latency)",
    )
    p.add_argument("--sensors", default="six_point")
    p.add_argument("--no-latency", action="store_true", help="only the offline speed (no ROS needed)")
    benched = {name: m for name, m in METHODS.items() if m.runtime_bench}
    p.add_argument(
        "--runtime",
        choices=sorted(benched),
        metavar="METHOD",
        help="only that method's runtime against its torch reference, on one core",
    )
    p.set_defaults(func=cmd_bench)

    p = sub.add_parser("train", help="train a learned estimator on the CMU train split (ONNX + model card)")
    trainable = {name: t for name in TRAINABLE if (t := METHODS[name].training) is not None}
    p.add_argument("method", choices=list(trainable))
    p.add_argument(
        "--config", default="small", help="; ".join(f"{name}: {t.config_help}" for name, t in trainable.items())
    )
    several = {name: [part.name for part in t.parts] for name, t in trainable.items() if len(t.parts) > 1}
    p.add_argument(
        "--part",
        default="all",
        help="of a method with several networks, train all (in order: later ones learn from earlier ones) "
        "or one: " + "; ".join(f"{name}: {', '.join(parts)}" for name, parts in several.items()),
    )
    p.add_argument(
        "--out",
        help="; ".join(f"{name}: {t.out_help}" for name, t in trainable.items()) + " (default: the package's models/)",
    )
    p.add_argument("--minutes", type=_between(0.0, 7 * 24 * 60, "minutes"), help="stop training after this long")
    p.add_argument("--steps", type=_positive_int, help="stop training after this many steps")
    p.add_argument("--threads", type=_between_int(1, 256), default=2, help="torch CPU threads")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--limit", type=_positive_int, help="only the first N clips of each split (smoke runs)")
    p.add_argument("--mocap", help="the CMU folder")
    p.add_argument("--no-card", action="store_true", help="skip the test-split evaluation and model card")
    p.add_argument(
        "--card-only",
        action="store_true",
        help="only rewrite the model card of an existing model: its test-split evaluations again "
        "(<model>.eval.json), then the card from them",
    )
    p.add_argument(
        "--render-only",
        action="store_true",
        help="only rewrite the model card from the measured <model>.eval.json as it is, evaluating nothing",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue an interrupted training from its checkpoint (<model>.checkpoint.npz, written "
        "at every validation; weights only, the optimiser and its schedule start afresh); "
        "--steps counts from the first run",
    )
    p.add_argument(
        "--keep-checkpoint",
        action="store_true",
        help="keep <model>.checkpoint.npz after the export, so that --resume can train a finished "
        "model further (a warm restart: the learning rate starts over)",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="override a field of the configuration (repeatable), e.g. --set dropout=0.2",
    )
    p.add_argument(
        "--augment",
        metavar="KINDS",
        help="augmentations of the train clips: mirror,speed,proportions (any of them), all or none "
        "(default: the configuration's)",
    )
    p.add_argument(
        "--ablate-augment",
        action="store_true",
        help="instead of training the model: train without augmentation, with the configuration's "
        "(or --augment's) and with each of its kinds left out (same seed, --minutes each), and "
        "write the validation figures to <model>.augment.json for the model card",
    )
    p.set_defaults(func=cmd_train)

    p = sub.add_parser(
        "import-mocap",
        help="index a CMU download or any folder of BVH / ASF+AMC files for eval, "
        "train and make-bag --clip (nothing is copied or changed)",
    )
    p.add_argument("sources", nargs="+", help="folders (searched recursively) or motion files")
    p.add_argument("--out", required=True, help="a new folder for clips.tsv and split.yaml")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_import_mocap)

    p = sub.add_parser("options", help="every option of a method: type, default, range and what it does")
    p.add_argument("method", nargs="?", choices=list(METHODS), help="the method (default: all)")
    p.add_argument("--markdown", action="store_true", help="the table of docs/options.md, for every method")
    p.set_defaults(func=cmd_options)

    p = sub.add_parser("split", help="compute the CMU train/validation/test split (by subject)")
    p.add_argument("--write", action="store_true", help="write config/splits/cmu.yaml")
    p.add_argument("--mocap", help="the CMU folder")
    p.set_defaults(func=cmd_split)
    return parser


USER_DESCRIPTION = (
    "A person's whole body from a few trackers (a headset, hand controllers, optionally pelvis "
    "and feet), without ROS: make tracker bags from motion, process recordings into body "
    "estimates, evaluate the estimators, view the results in a browser. "
    "`sparse-body COMMAND --help` says more of each."
)


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the command is, so that partial output is removed on the way out
    as for Ctrl-C."""


# Exit codes: one per kind of error a user can cause (docs/outputs.md, the table).
EXIT_INPUT, EXIT_USAGE, EXIT_OUTPUT, EXIT_OS, EXIT_TOO_LARGE = 1, 2, 3, 4, 5
TRAINING_MODULES = ("torch", "roma", "onnx")  # requirements-train.txt: what `make setup` leaves out


def needs_training_tools(module: str) -> str:
    return (
        f"this needs the training tools ({module}), which the runtime install leaves out: "
        "make setup-train (or pip install -r requirements-train.txt)"
    )


EXIT_INTERRUPTED, EXIT_TERMINATED = 130, 143


def _exit_code(err: BaseException) -> int:
    """The exit code of an error the command ends with (see the constants above)."""
    from .core.file_output import OutputError
    from .core.textfile import InputTooLarge

    if isinstance(err, OutputError):
        return EXIT_OUTPUT
    if isinstance(err, (InputTooLarge, MemoryError, RecursionError)):
        return EXIT_TOO_LARGE
    if isinstance(err, OSError):
        return EXIT_OS
    return EXIT_INPUT


MAX_MESSAGE = 2000  # characters of an error's one line


def _one_line(err: BaseException) -> str:
    if isinstance(err, MemoryError):
        return "out of memory (a smaller input, or a shorter --seconds / --limit)"
    if isinstance(err, RecursionError):
        return "input nested too deeply"
    if isinstance(err, OSError) and err.strerror:
        where = f"{err.filename}: " if err.filename else ""
        return f"{where}{err.strerror}"
    text = " ".join(str(err).split()) or type(err).__name__
    # an error quoting what it refused stays readable whatever that was (a value of megabytes)
    return text if len(text) <= MAX_MESSAGE else text[: MAX_MESSAGE - 20] + " ... (cut short)"


_sigterm_seen = False  # set by _terminate; main() clears it at its start
_sigint_seen = False  # set by _interrupt; likewise


def _interrupt(signum, frame):
    # remembered as well as raised: landing in a weakref callback or a __del__ while a module
    # is imported, the KeyboardInterrupt is printed as "ignored" and the command went on (exit
    # 0); main() looks at the flag before the command starts
    global _sigint_seen
    _sigint_seen = True
    raise KeyboardInterrupt


def _terminate(signum, frame):
    # remembered as well as raised: a library that catches the exception in its own wait can
    # raise a plain KeyboardInterrupt in its place (Ray's ray.wait does), and it is still SIGTERM
    global _sigterm_seen
    _sigterm_seen = True
    raise Terminated


def _stop_behind(err: BaseException) -> KeyboardInterrupt | None:
    """The Ctrl-C or SIGTERM an error stands for, if any: an interrupt inside compiled code
    comes back wrapped (numba's dispatcher turns it into a SystemError whose cause is the
    KeyboardInterrupt), and it is still the user's stop, not a failure."""
    from .core.causes import cause_of_kind

    stop = cause_of_kind(err, KeyboardInterrupt)
    return stop if isinstance(stop, KeyboardInterrupt) else None


def main(argv: list[str] | None = None) -> None:
    """Run a subcommand; every error a user can cause ends in one line on stderr and its own
    exit code, never a traceback."""
    import signal

    global _sigterm_seen, _sigint_seen
    _sigterm_seen = _sigint_seen = False
    command = "sparse-body"
    yaml_error: type[Exception] = ValueError  # (yaml's own until it is imported)
    args = None
    try:  # from the first statement: Ctrl-C while starting is one line too
        signal.signal(signal.SIGTERM, _terminate)
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # (not where it is ignored)
            signal.signal(signal.SIGINT, _interrupt)
        from yaml import YAMLError

        yaml_error = YAMLError

        args = build_parser().parse_args(argv)
        command = f"sparse-body {args.command}"
        if _sigterm_seen or _sigint_seen:  # a stop that an import swallowed: nothing has started
            raise Terminated if _sigterm_seen else KeyboardInterrupt
        sys.exit(args.func(args))
    except (KeyboardInterrupt, Exception) as err:  # (SystemExit passes: argparse's, ours)
        stop = _stop_behind(err)
        # what a stop leaves: a command that keeps finished parts says so on its own args
        left = getattr(args, "left_when_stopped", "nothing written")
        if isinstance(stop, Terminated) or (stop is not None and _sigterm_seen):
            print(f"{command}: terminated; {left}", file=sys.stderr)
            sys.exit(EXIT_TERMINATED)
        if stop is not None:  # partial output was removed on the way out
            print(f"{command}: interrupted; {left}", file=sys.stderr)
            sys.exit(EXIT_INTERRUPTED)
        if isinstance(err, ModuleNotFoundError) and err.name in TRAINING_MODULES:
            print(f"{command}: {needs_training_tools(err.name)}", file=sys.stderr)
            sys.exit(EXIT_INPUT)
        # ValueError includes MotionFileError, BagError, OutputError, SensorConfigError, CalibrationError
        if not isinstance(err, (ValueError, OSError, EOFError, yaml_error, MemoryError, RecursionError)):
            raise  # a bug, not something the user caused: its traceback is what we need
        print(f"{command}: {_one_line(err)}", file=sys.stderr)
        sys.exit(_exit_code(err))


if __name__ == "__main__":
    main()
