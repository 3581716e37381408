"""`sparse-body make-bag`: its arguments (add_parser) and what it runs (run)."""

from __future__ import annotations

from pathlib import Path

from .common import fps, motion_of, seconds


def run(args) -> int:
    from ...core.sensors import load_sensor_config
    from ...data.virtual_trackers import LOBSTR_NOISE, NO_NOISE
    from ..offline import make_bag

    if not (args.clip or args.motion or args.seconds > 0):
        raise ValueError("make-bag needs a motion: --clip ID, --motion FILE, or --seconds S of the synthetic walk")
    motion = motion_of(args)
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


def add_parser(sub) -> None:
    p = sub.add_parser("make-bag", help="write a rosbag2 (MCAP) of tracker TF from a motion")
    p.add_argument("out", metavar="OUT", help="the bag directory to create")
    p.add_argument("--sensors", default="six_point", help="sensor configuration name or YAML path")
    p.add_argument("--clip", help="a CMU clip id (e.g. 02_01)")
    p.add_argument("--motion", help="a motion file (.bvh, .amc, .npz)")
    p.add_argument(
        "--seconds", type=seconds, default=0.0, help="length of the synthetic walk, or cut a clip to this length"
    )
    p.add_argument("--fps", type=fps, default=60.0, help="the trackers' rate in the bag (Hz)")
    p.add_argument("--noise", action="store_true", help="add LoBSTr's tracker noise")
    p.add_argument("--mocap", help="the CMU folder")
    p.add_argument("--overwrite", action="store_true", help="replace OUT if it exists")
    p.set_defaults(func=run)
