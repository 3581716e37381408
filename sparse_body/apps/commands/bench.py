"""`sparse-body bench`: its arguments (add_parser) and what it runs (run)."""

from __future__ import annotations


def run(args) -> int:
    from ...methods import METHODS, load
    from ..bench import run, run_goals

    if args.runtime:
        bench = METHODS[args.runtime].runtime_bench
        if bench is None:
            raise ValueError(f"{args.runtime} has no runtime bench")
        load(bench)()
        return 0
    if args.robot:
        from ..bench import bench_latency

        estimator = (args.estimator or ["ik"])[0]
        return 0 if bench_latency(estimator, args.sensors, robot=(args.robot, args.robot_urdf or "")) else 1
    if args.estimator:
        run(args.estimator, args.sensors, latency=not args.no_latency)
    else:
        run_goals(latency=not args.no_latency)
    return 0


def add_parser(sub) -> None:
    from ...methods import METHODS

    p = sub.add_parser("bench", help="step times and end-to-end latency over DDS, beside their goals")
    p.add_argument(
        "--estimator",
        action="append",
        help="estimator(s) to measure on --sensors (default: the goal table: ik, lobstr, dragposer, dtp, avatarjlm "
        "step times and ik's TF -> JointState latency)",
    )
    p.add_argument("--sensors", default="six_point", help="the trackers benched: a configuration name or YAML path")
    p.add_argument("--no-latency", action="store_true", help="only the offline speed (no ROS needed)")
    p.add_argument(
        "--robot",
        help="only TF in -> a humanoid robot's JointState out, through the estimator and the retarget node: "
        "its mapping (a shipped name such as unitree_g1_29dof, or a YAML path)",
    )
    p.add_argument("--robot-urdf", help="the robot's URDF (with --robot; default: the file its mapping names)")
    benched = {name: m for name, m in METHODS.items() if m.runtime_bench}
    p.add_argument(
        "--runtime",
        choices=sorted(benched),
        metavar="METHOD",
        help="only that method's runtime against its torch reference, on one core",
    )
    p.set_defaults(func=run)
