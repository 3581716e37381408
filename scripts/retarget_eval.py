"""Humanoid retargeting (sparse_body/robot) measured on the validation people (field
protocol): the estimator's pose of each clip, retargeted onto a robot frame by frame as the
retarget node does and its commands eased and limited as the node sends them (robot/limits.py),
scored by robot/quality.py: each target's distance from the scaled human joint, joint-limit
violations, self-collision, foot skate while planted, below-floor depth, the commands' speeds
and accelerations against their limits, the knees against the person's, and the solver's
step time.

Usage: .venv/bin/python scripts/retarget_eval.py ROBOT_YAML [--urdf PATH] [--estimator ik]
           [--sensors six_point] [--limit N] [--output docs/retarget_ROBOT.json]
Writes the table (Markdown) to stdout and every clip's figures to --output.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np


def main() -> int:
    from sparse_body.core.rotations import matrix_to_quat
    from sparse_body.core.sensors import load_sensor_config
    from sparse_body.core.types import BodyPose
    from sparse_body.data.catalog import MocapFolderError
    from sparse_body.data.field_protocol import FIELD
    from sparse_body.evaluation import estimate_motion, part_items
    from sparse_body.robot.limits import limiter_for
    from sparse_body.robot.mapping import load_mapping
    from sparse_body.robot.quality import command_quality, retarget_quality
    from sparse_body.robot.retarget import HumanoidRetarget
    from sparse_body.robot.urdf_model import load_urdf

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("robot", type=Path)
    parser.add_argument("--urdf", type=Path)
    parser.add_argument("--estimator", default="ik")
    parser.add_argument("--sensors", default="six_point")
    parser.add_argument("--limit", type=int)
    parser.add_argument("--output", type=Path)
    args = parser.parse_args()
    try:
        items = part_items("validation", limit=args.limit)
    except MocapFolderError as err:
        print(err, file=sys.stderr)
        return 2
    mapping = load_mapping(args.robot)
    model = load_urdf(args.urdf or mapping.urdf)
    sensors = load_sensor_config(args.sensors)
    rows, steps = [], []
    for item in items:
        est = estimate_motion(item.load(), args.estimator, sensors, FIELD, item.seed)
        retarget = HumanoidRetarget(model, mapping, est.view.skeleton)
        poses = []
        for i in range(len(est.positions)):
            body = BodyPose(
                i / est.motion.fps, matrix_to_quat(est.local_rotations[i]), est.positions[i, 0], contact=est.contacts[i]
            )
            start = time.perf_counter()
            poses.append(retarget.step(body))
            steps.append(time.perf_counter() - start)
        figures = retarget_quality(poses, retarget, est.contacts, est.motion.fps)
        limiter = limiter_for(retarget)
        stamps = np.arange(len(poses)) / est.motion.fps
        sent = [limiter(t, p.positions, p.fresh) for t, p in zip(stamps, poses, strict=True)]
        commands, velocities = (np.array([s[k] for s in sent]) for k in (0, 1))
        figures |= command_quality(commands, velocities, stamps, retarget, est.local_rotations)
        figures["solved afresh after a miss [%]"] = retarget.restarts / max(1, len(poses)) * 100
        rows.append({"clip": item.key, "kind": item.category, **figures})
        print(f"{item.key}: {figures}", file=sys.stderr)
    keys = [k for k in rows[0] if k not in ("clip", "kind", "frames")]
    frames = np.array([r["frames"] for r in rows])
    print(f"{model.name} ({len(model.moving)} joints), {args.estimator} {args.sensors}, validation, field protocol:")
    print(f"{len(rows)} clips, {int(frames.sum())} frames; scale {retarget.scale:.3f}\n")
    print("| figure | frame-weighted mean | worst clip |\n| --- | ---: | ---: |")
    summary = {}
    for key in keys:
        values = np.array([r.get(key, np.nan) for r in rows])
        ok = np.isfinite(values)
        mean = float(np.sum(values[ok] * frames[ok]) / frames[ok].sum()) if ok.any() else float("nan")
        lowest_worst = "correlation" in key  # (the others are errors and counts: the highest is the worst)
        worst = float((values[ok].min() if lowest_worst else values[ok].max()) if ok.any() else np.nan)
        summary[key] = mean
        print(f"| {key} | {mean:.2f} | {worst:.2f} |")
    steps_ms = np.array(steps) * 1e3
    print(f"| step p50 / p99 [ms] | {np.percentile(steps_ms, 50):.2f} / {np.percentile(steps_ms, 99):.2f} | |")
    knee = [r for r in rows if np.isfinite(r.get("left knee correlation", np.nan))]
    if knee:
        lowest = min(min(r["left knee correlation"], r["right knee correlation"]) for r in knee)
        print(f"\nknee correlation with the person's, lowest clip and side: {lowest:.3f} ({len(knee)} clips)")
    print("\nby motion kind (frame-weighted; each figure the mean of both sides):\n")
    print(
        "| kind | clips | frames | hands [cm] | feet, not planted [cm] | feet skate [cm/s] "
        "| the person's feet skate [cm/s] | knee correlation |"
    )
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for kind in sorted({r["kind"] for r in rows}):
        mine = [r for r in rows if r["kind"] == kind]
        ends = ("hand error [cm]", "foot error [cm]", "skate [cm/s]", "skate, the person's [cm/s]", "knee correlation")
        figures = [_kind_mean(mine, end) for end in ends]
        count = int(sum(r["frames"] for r in mine))
        print(f"| {kind} | {len(mine)} | {count} | " + " | ".join(f"{v:.2f}" for v in figures) + " |")
    if args.output:
        args.output.write_text(
            json.dumps(
                {
                    "robot": model.name,
                    "command": "python " + " ".join(sys.argv),
                    "machine": f"{platform.machine()}, {len(os.sched_getaffinity(0))} cores",
                    "step_ms": {"p50": float(np.percentile(steps_ms, 50)), "p99": float(np.percentile(steps_ms, 99))},
                    "summary": summary,
                    "clips": rows,
                },
                indent=1,
            )
            + "\n"
        )
    return 0


def _kind_mean(rows: list[dict], ending: str) -> float:
    """The frame-weighted mean over clips of the mean of a clip's figures whose name ends so."""
    values = np.array([_finite_mean([v for k, v in r.items() if k.endswith(ending)]) for r in rows])
    weight = np.array([r["frames"] for r in rows])
    ok = np.isfinite(values)
    return float(np.sum(values[ok] * weight[ok]) / weight[ok].sum()) if ok.any() else float("nan")


def _finite_mean(values: list[float]) -> float:
    """The mean of the finite values (NaN where none: a knee that did not move has no correlation)."""
    finite = [v for v in values if np.isfinite(v)]
    return float(np.mean(finite)) if finite else float("nan")


if __name__ == "__main__":
    sys.exit(main())
