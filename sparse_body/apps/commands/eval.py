"""`sparse-body eval`: its arguments (add_parser) and what it runs (run)."""

from __future__ import annotations

import argparse
import re
import sys
from collections import Counter
from dataclasses import replace
from pathlib import Path

from .common import (
    RESULTS_DIR,
    between,
    degrees_per_minute,
    fps,
    jumps_per_minute,
    mocap_root,
    percent,
    positive_int,
)
from .exits import EXIT_INPUT


def run(args) -> int:
    from ...core.forecast import MAX_AHEAD
    from ...core.results import format_groups, format_table
    from ...core.sensors import load_sensor_config
    from ...data.field_protocol import Protocol
    from ...evaluation import (
        OUT_OF_DEPTH,
        check_results_path,
        file_items,
        run_evaluation,
        split_items,
        untrained_categories,
    )
    from ...methods import METHODS, paper_figures
    from ...methods.recommended import AUTO, resolve_estimator

    sensors = load_sensor_config(args.sensors)
    given = args.estimator or [AUTO]
    args.estimator = [resolve_estimator(spec, sensors.name) for spec in given]
    for spec, resolved in zip(given, args.estimator, strict=True):
        if spec != resolved:
            print(f"estimator: {resolved}, recommended for {sensors.name} (--estimator to choose)")
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
        from ...data.motion_inputs import balanced, find_inputs

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
        items, split = split_items(mocap_root(args), args.split, args.fps, args.limit), args.split
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
        notes = untrained_categories(mocap_root(args), results[0].categories)
        said = [OUT_OF_DEPTH] if any(OUT_OF_DEPTH in r.summary for r in results) else []
        for metric in ("MPJPE [cm]", "Lower PE [cm]", "Skate [cm/s]", "Ground [cm]", "Contact acc [%]", *said):
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


def add_parser(sub) -> None:
    p = sub.add_parser("eval", help="run estimators over a split of the CMU clips and print the metrics")
    p.add_argument(
        "--estimator",
        action="append",
        help="estimator name, optionally with options: lobstr:contact_ik=false (repeat to compare several); "
        "default: auto, the one recommended for the sensors",
    )
    p.add_argument("--sensors", default="three_point", help="sensor configuration name or YAML path")
    p.add_argument(
        "--split",
        default="test",
        choices=("train", "validation", "test", "selection", "floor"),  # data/catalog.PARTS, not imported for --help
        help="part of the split (default test); selection: the validation clips of the kinds of motion "
        "no train clip has, the set every accuracy choice is made on; floor: the selection's clips with the "
        "body lying on the floor (on its back, side and front in turn)",
    )
    p.add_argument("--fps", type=fps, default=60.0, help="frame rate the clips are resampled to")
    p.add_argument(
        "--protocol",
        default="field",
        choices=["field", "field-exact", "lab"],
        help="what the estimators are given (each value below overrides the protocol's own): field, a "
        "user's session (calibrated body, VR noise, trackers worn 1.5 cm off and found by the mounting "
        "calibration, hands lost 3 %%, a Lighthouse jump a minute, IMU heading drift up to 2 deg/min); "
        "field-exact, the same with exact mounting and no failures (what the lab notes that "
        "name it used); lab, the true skeleton without noise (the papers')",
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
        type=between(0.0, 0.5, "metres"),
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
        type=percent,
        metavar="PERCENT",
        help="DragPoser's faulty sensors: each frame, with this probability (%%), one tracker "
        "disconnects for 100 frames",
    )
    p.add_argument(
        "--occlusion",
        type=percent,
        metavar="PERCENT",
        help="DTP's foot occlusion: in about this share (%%) of the frames one or both foot trackers "
        "lose sight for half a second and report the origin with the identity rotation or noise "
        "within a leg's length",
    )
    p.add_argument(
        "--hand-loss",
        type=percent,
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
        type=jumps_per_minute,
        metavar="PER_MINUTE",
        help="Lighthouse reflections: about this many times a minute each tracked position jumps "
        "2-8 cm in a random direction for 2-8 frames (field: 1)",
    )
    p.add_argument(
        "--yaw-drift",
        type=degrees_per_minute,
        metavar="DEG_PER_MINUTE",
        help="IMUs without a magnetometer: each orientation-only sensor's heading drifts at a steady "
        "rate drawn per clip up to this (degrees a minute; field: 2)",
    )
    p.add_argument(
        "--limit",
        type=positive_int,
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
        type=fps,
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
    p.set_defaults(func=run)
