"""`sparse-body process`: its arguments (add_parser) and what it runs (run)."""

from __future__ import annotations

import os
from collections import Counter
from pathlib import Path

from ...io.tf_guards import TfGuards
from ...io.topics import COMPRESSIONS, ESTIMATE_TOPICS
from .common import between, between_int, fps, height, rates, topics


def run(args) -> int:
    from ...core.calibration import person_body
    from ...estimators.base import parse_estimator_spec
    from ...io.bagio import BagError
    from ...methods.factory import check_estimator_name
    from ...methods.recommended import resolve_estimator
    from ..batch import SUMMARY, Settings, expand_inputs, is_bag, process_many
    from ..offline import process_bag

    check_estimator_name(parse_estimator_spec(args.estimator)[0])
    body = person_body(args.calibration, args.height)
    robot = None
    if args.robot:
        from ...robot.mapping import load_mapping
        from ...robot.retarget import load_retarget

        load_retarget(args.robot, args.robot_urdf, body)  # one line on a bad robot file, before any work
        # the mapping's file, resolved (a shipped one by its name: `--robot unitree_h1`, which a
        # path resolved against the working directory lost) and the URDF's
        mapping = str(Path(load_mapping(args.robot).source).resolve())
        robot = (mapping, str(Path(args.robot_urdf).resolve()) if args.robot_urdf else "")
    elif args.robot_urdf:
        raise ValueError("--robot-urdf goes with --robot (the mapping of the robot's links to the body)")
    guards = TfGuards(clock_window=args.clock_window, future_window=args.future_window, play_radius=args.play_radius)
    inputs = [Path(p) for p in args.bag_in]
    for given in inputs:  # before anything is read or made
        if not given.exists():
            raise BagError(f"{given}: no such file or folder")
    many = len(inputs) > 1 or (inputs[0].is_dir() and not is_bag(inputs[0]))
    bags = expand_inputs(inputs) if many or args.cluster else inputs
    if not bags:
        raise BagError(f"{', '.join(map(str, inputs))}: no bags there")
    # the trackers the (first readable) bag holds choose the configuration, unless --sensors
    # names one; of many, a bag that cannot be read fails alone, as in the run
    sensors, chosen = _sensors_of(bags, args.sensors, many or bool(args.cluster))
    if args.sensors is None:
        print(chosen)
    spec = resolve_estimator(args.estimator, sensors.name)
    if spec != args.estimator:
        print(f"estimator: {spec}, recommended for {sensors.name} (--estimator to choose)")
    name, options = parse_estimator_spec(spec)
    if args.smooth:
        options["smooth"] = True
    if many or args.cluster:  # OUT is a folder
        args.left_when_stopped = (  # what main() says on a stop
            f"the bags finished are kept (see {Path(args.bag_out) / SUMMARY}), the ones being written were "
            "removed; the same command resumes"
        )
        settings = Settings(
            name,
            options,
            sensors,
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
        sensors,
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
    print(rates(result.frames, timings))
    if result.never_usable:
        print(f"note: {', '.join(result.never_usable)} never had a usable pose in {args.bag_in[0]}: held where unknown")
    return 0


def _sensors_of(bags: list[Path], given: str | None, many: bool):
    """sensors_for_bag of the first bag that can be read (of one bag: its error)."""
    from ...core.sensors import load_sensor_config
    from ...io.bagio import BagError
    from ..offline import sensors_for_bag

    if many and given is not None:  # each bag's trackers are checked as it is processed
        sensors = load_sensor_config(given)
        return sensors, f"trackers: {sensors.name} (as given)"
    first_error = None
    for bag in bags if many else bags[:1]:
        try:
            return sensors_for_bag(bag, given)
        except BagError as err:
            first_error = first_error or err
    assert first_error is not None
    raise first_error


def add_parser(sub) -> None:
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
        type=between_int(1, 1024),
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
        default="auto",
        help="estimator, with options: lobstr, refined:base=lobstr (DragPoser refinement after it); auto: the "
        "one recommended for the sensors (said in one line)",
    )
    p.add_argument(
        "--sensors",
        help="the sensor configuration (a name or a YAML path); default: the shipped one whose trackers the bag "
        "holds (said in one line); a configuration whose tracker never appears in the bag is refused",
    )
    p.add_argument(
        "--topics",
        type=topics,
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
    p.add_argument("--height", type=height, default=1.75, help="the tracked person's height in metres")
    p.add_argument(
        "--calibration",
        help="a T-pose calibration file (the bridge's ~/calibrate): its fitted body "
        "instead of the canonical one at --height",
    )
    p.add_argument("--fps", type=fps, default=60.0, help="the trackers' nominal rate")
    p.add_argument(
        "--smooth",
        action="store_true",
        help="smooth the tracker input over the whole recording, forwards and backwards (the "
        "estimator option smooth=true): far less shaking under noise than the live filter",
    )
    p.add_argument(
        "--clock-window",
        type=between(0.0, 1e9, "s"),
        default=TfGuards.clock_window,
        help="refuse /tf stamps further than this from the bag's receive times (a frame stamped 0); "
        "0: no check, for a bag recorded with simulated time",
    )
    p.add_argument(
        "--future-window",
        type=between(0.001, 60.0, "s"),
        default=TfGuards.future_window,
        help="refuse /tf stamps further than this ahead of the bag's receive times",
    )
    p.add_argument(
        "--play-radius",
        type=between(0.1, 1e6, "m"),
        default=TfGuards.play_radius,
        help="refuse trackers further than this from the fixed frame's origin",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument(
        "--overwrite", action="store_true", help="replace OUT if it exists and is an estimate bag this command wrote"
    )
    p.set_defaults(func=run)
