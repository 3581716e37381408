"""predict_ahead's fading velocity (core/forecast.py): what a forecast 33 to 150 ms ahead buys
against the present pose given as the later one, for each time constant of the fade, on the
validation people (field protocol), by kind of motion. The kind absent from training (dance)
chooses the constant (core/forecast.FADE). "learned root": the shipped forecast, the joints
faded at FADE and the root moved by the learned model (train/forecast.py), where it is there.

Each clip is estimated once; the forecasts are applied to its poses afterwards (a forecast is
a function of the poses alone, as in PoseForecast.forecast). The error is MPJPE [cm] of each
pose against the true body at its forecast time.

Usage: .venv/bin/python scripts/forecast_fade.py ESTIMATOR SENSORS [--limit N]
           [--output docs/forecast_fade_ESTIMATOR_SENSORS.json]
Writes the table (Markdown) to stdout and every clip's error sums to --output.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

HORIZON_FRAMES = (2, 4, 6, 9)  # at 60 fps: 33, 67, 100, 150 ms
FADES = (0.03, 0.05, 0.1, 0.2, math.inf)  # s; inf: a constant velocity


def main() -> int:
    from sparse_body.core.forecast import PoseForecast, faded_seconds
    from sparse_body.core.kinematics import forward_kinematics
    from sparse_body.core.rotations import quat_to_matrix
    from sparse_body.data.catalog import find_mocap_root, split_clips
    from sparse_body.estimators.base import learned_root_available
    from sparse_body.estimators.forecast_model import RootForecastModel
    from sparse_body.evaluation import estimated_clips

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("estimator")
    parser.add_argument("sensors")
    parser.add_argument("--limit", type=int)
    parser.add_argument("--output", type=Path)
    args = parser.parse_args()
    root = find_mocap_root()
    if root is None:
        print("no motion capture folder found (sparse-body import-mocap)", file=sys.stderr)
        return 2
    kinds = {c.clip_id: c.category for c in split_clips(root, "validation")}
    model = RootForecastModel() if learned_root_available() else None
    clips = []
    for item, motion, view, poses in estimated_clips(root, "validation", args.estimator, args.sensors, args.limit):

        def joints(poses, view=view):
            local = quat_to_matrix(np.stack([p.local_quats for p in poses]))
            return forward_kinematics(local, np.stack([p.root_position for p in poses]), view.skeleton.offsets)[1]

        made = joints(poses)
        row = {"clip": item.key, "kind": kinds[item.key], "errors": {}}
        for h in HORIZON_FRAMES:
            count = len(motion) - h
            if count <= 0:
                continue
            variants = {"present": made}
            for fade in FADES:
                forecast = PoseForecast(0.0, smooth=0.0, smooth_root=0.0)  # the fade alone, as measured
                forecast.ahead, forecast.carry = h / motion.fps, faded_seconds(h / motion.fps, fade)
                variants[f"fade {fade:g}"] = joints([forecast.forecast(p) for p in poses])
            if model is not None:  # the shipped forecast: joints faded (FADE), the root learned
                learned = PoseForecast(h / motion.fps, root_model=model, lags=model.lags, smooth=0.0, smooth_root=0.0)
                variants["learned root"] = joints([learned.forecast(p) for p in poses])
            row["errors"][str(h)] = {
                name: [float(np.linalg.norm(pred[:count] - motion.positions[h:], axis=-1).mean(axis=1).sum()), count]
                for name, pred in variants.items()
            }
        clips.append(row)
    if args.output:
        args.output.write_text(json.dumps({"estimator": args.estimator, "sensors": args.sensors, "clips": clips}))
    names = ["present"] + [f"fade {fade:g}" for fade in FADES] + (["learned root"] if model is not None else [])
    print(f"| {args.estimator}/{args.sensors} | ms | " + " | ".join(names) + " |")
    print("| --- | ---: |" + " ---: |" * len(names))
    for group in ("dance", "other", "all"):
        members = [c for c in clips if group == "all" or (c["kind"] == "dance") == (group == "dance")]
        for h in HORIZON_FRAMES:
            sums = {n: sum(c["errors"].get(str(h), {}).get(n, [0, 0])[0] for c in members) for n in names}
            counts = {n: sum(c["errors"].get(str(h), {}).get(n, [0, 0])[1] for c in members) for n in names}
            if not counts["present"]:
                continue
            cells = " | ".join(f"{100 * sums[n] / counts[n]:.2f}" for n in names)
            print(f"| {group} | {round(h * 1000 / 60)} | {cells} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
