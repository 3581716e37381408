"""What predict_ahead trades (core/forecast.py; issue 74): MPJPE against the true body at the
forecast time, and the jitter and skate a robot driven by the forecast would show, for the
forecast as shipped and with its velocities averaged (SMOOTH) and its planted feet held, beside
the present pose given as the later one, on the validation people (field protocol), by kind.

Each clip is estimated once; the forecasts are applied to its poses afterwards (a forecast is a
function of the poses alone, as in PoseForecast.forecast). Skate is read against the true
body's contacts at the forecast time, as `sparse-body eval --horizon` does.

Usage: .venv/bin/python scripts/forecast_trade.py ESTIMATOR SENSORS [--ahead 0.1] [--smooth 0 0.4:0.1 ...] [--limit N]
           [--output docs/forecast_trade_ESTIMATOR_SENSORS.json]
Writes the table (Markdown) to stdout and every clip's figures to --output.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

SMOOTHS = ("0", "0.2", "0.4:0.1")  # s, joints[:root]; 0: the last two poses' velocity (as shipped before)
METRICS = ("MPJPE [cm]", "Jitter [100m/s3]", "Skate [cm/s]")


def main() -> int:
    from sparse_body.core.contact_hold import ContactHold
    from sparse_body.core.contacts import contact_labels
    from sparse_body.core.forecast import PoseForecast
    from sparse_body.core.kinematics import forward_kinematics
    from sparse_body.core.metrics import foot_skate, jitter, mpjpe
    from sparse_body.core.rotations import quat_to_matrix
    from sparse_body.data.catalog import find_mocap_root, split_clips
    from sparse_body.estimators.base import learned_root_available
    from sparse_body.estimators.forecast_model import RootForecastModel
    from sparse_body.evaluation import estimated_clips

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("estimator")
    parser.add_argument("sensors")
    parser.add_argument("--ahead", type=float, default=0.1)
    parser.add_argument(
        "--smooth", nargs="+", default=SMOOTHS, help="time constants to try, s: JOINTS or JOINTS:ROOT (ROOT: as JOINTS)"
    )
    parser.add_argument("--no-hold", action="store_true", help="skip the variants with planted feet held")
    parser.add_argument("--limit", type=int)
    parser.add_argument("--output", type=Path)
    args = parser.parse_args()
    root = find_mocap_root()
    if root is None:
        print("no motion capture folder found (sparse-body import-mocap)", file=sys.stderr)
        return 2
    kinds = {c.clip_id: c.category for c in split_clips(root, "validation")}
    model = RootForecastModel() if learned_root_available() else None
    lags = model.lags if model is not None else 0
    clips = []
    for item, motion, view, poses in estimated_clips(root, "validation", args.estimator, args.sensors, args.limit):
        h = round(args.ahead * motion.fps)
        count = len(motion) - h
        if count <= 3:
            continue
        truth = motion.positions[h:]
        contacts = contact_labels(motion.positions, motion.fps)[h:]

        def joints(local, roots, view=view):
            return forward_kinematics(local, roots, view.skeleton.offsets)[1]

        def figures(pos, count=count, truth=truth, contacts=contacts, fps=motion.fps):
            pos = pos[:count]
            return [mpjpe(pos, truth), jitter(pos, fps), foot_skate(pos, contacts, fps)]

        local = quat_to_matrix(np.stack([p.local_quats for p in poses]))
        roots = np.stack([p.root_position for p in poses])
        row = {"clip": item.key, "kind": kinds[item.key], "frames": count, "figures": {}}
        row["figures"]["present"] = figures(joints(local, roots))
        for smooth in args.smooth:
            turns, _, root = str(smooth).partition(":")
            forecast = PoseForecast(
                args.ahead, root_model=model, lags=lags, smooth=float(turns), smooth_root=float(root or turns)
            )
            ahead = [forecast.forecast(p) for p in poses]
            f_local = quat_to_matrix(np.stack([p.local_quats for p in ahead]))
            f_roots = np.stack([p.root_position for p in ahead])
            row["figures"][f"smooth {smooth}"] = figures(joints(f_local, f_roots))
            if args.no_hold:
                continue
            hold = ContactHold(view.skeleton)
            held = np.stack([hold.apply(f_local[t], f_roots[t], p.contact) for t, p in enumerate(ahead)])
            row["figures"][f"smooth {smooth}, feet held"] = figures(joints(held, f_roots))
        clips.append(row)
        print(item.key, file=sys.stderr)
    if args.output:
        args.output.write_text(json.dumps({"estimator": args.estimator, "sensors": args.sensors,
                                           "ahead": args.ahead, "clips": clips}))  # fmt: skip
    names = list(clips[0]["figures"])
    for k, metric in enumerate(METRICS):
        print(f"\n{args.estimator}/{args.sensors}, {metric} at {args.ahead * 1000:.0f} ms ahead\n")
        print("| kind | " + " | ".join(names) + " |")
        print("| --- |" + " ---: |" * len(names))
        for group in sorted({c["kind"] for c in clips}) + ["all"]:
            members = [c for c in clips if group in ("all", c["kind"])]
            cells = []
            for n in names:
                values = [
                    (c["figures"][n][k], c["frames"]) for c in members if c["figures"][n][k] == c["figures"][n][k]
                ]
                total = sum(w for _, w in values)
                cells.append(f"{sum(v * w for v, w in values) / total:.2f}" if total else "-")
            print(f"| {group} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
