"""`sparse-body view`: its arguments (add_parser) and what it runs (run)."""

from __future__ import annotations

from pathlib import Path

from .common import fps, motion_of


def run(args) -> int:
    from ...evaluation import is_results_file
    from ..batch import is_bag
    from ..viewer import bag_bodies, write_body_page

    source = Path(args.source) if args.source else None
    live = bool(args.source and args.source.startswith(("ws://", "wss://")))
    if source is not None and not live and not source.exists():
        raise ValueError(f"{args.source}: no such file or folder")
    # the page's place checked before any work, where its name is known without it: a page
    # that may not be replaced was once refused only after 6 s of reading
    early = args.output or (f"{source.name}.html" if source is not None and not live and is_bag(source) else None)
    if early is not None:
        from ...core.file_output import check_target, marker_in_head
        from ..viewer import PAGE_MARKER

        check_target(Path(early), marker_in_head(PAGE_MARKER.encode()), args.overwrite, "page")
    if (args.robot or args.robot_urdf) and not (source is not None and is_bag(source)):
        raise ValueError("--robot draws the robot of an estimate bag written with process --robot: give the bag")
    title = None
    parts: dict  # what the page draws, by name: arrays (None: not shown)
    if live:
        from ..live_record import record_tf
        from ..viewer import tf_bodies

        messages, malformed = record_tf(args.source, args.seconds)
        positions, trackers, fps = tf_bodies(messages, args.source)
        parts, name = {"estimate": positions, "trackers": trackers}, "live"
        print(
            f"{len(positions)} estimates in {args.seconds:g} s"
            + (f"; {malformed} /tf messages that were not TFMessages left out" if malformed else "")
        )
    elif source is not None and is_bag(source):
        # the frames the page draws kept while reading: a 5-minute bag's every frame once took 330 MB
        positions, trackers, fps, stands_for = bag_bodies(source, drawn=True)
        parts = {"estimate": positions, "trackers": trackers, "stands_for": stands_for}
        name = source.name
        if args.robot:  # the robot the bag was written with, beside the body, from its mapping
            from ...core.skeleton import Skeleton
            from ...robot.retarget import load_retarget
            from ..viewer import bag_robot

            retarget = load_retarget(args.robot, args.robot_urdf, Skeleton.canonical())
            parts["robot"], parts["robot_bones"] = bag_robot(source, retarget, positions[:, 0], stands_for)
        else:  # the robot's links on the bag's /tf (process --robot writes them), where there are any
            from ..viewer import bag_robot_links

            drawn = bag_robot_links(source, positions[:, 0], stands_for)
            if drawn is not None:
                parts["robot"], parts["robot_bones"] = drawn
    elif source is not None and is_results_file(source):
        from ...data.catalog import find_mocap_root
        from ..result_view import view_clip

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
        motion = motion_of(args)
        parts, fps, name = {"truth": motion.positions}, motion.fps, motion.name
    page = write_body_page(Path(args.output or f"{name}.html"), fps, args.overwrite, title=title or name, **parts)
    print(f"written {page}: open it in a browser (no network needed)")
    return 0


def add_parser(sub) -> None:
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
    p.add_argument("--fps", type=fps, default=60.0, help="a motion file's frame rate where it has none")
    p.add_argument("--seconds", type=float, default=10.0, help="how long to record a live view (at most 600)")
    p.add_argument(
        "--robot",
        help="the mapping of the robot of an estimate bag written with process --robot, drawn beside the body "
        "(without it: the robot's links on the bag's /tf, where it has them)",
    )
    p.add_argument("--robot-urdf", help="the robot's URDF, where the mapping names none or another")
    p.set_defaults(func=run, motion=None)
