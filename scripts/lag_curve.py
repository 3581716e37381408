"""The live smoother's lag curve (filter_lag, core/fixed_lag.py): what each lag from 0 to
100 ms buys each estimator in velocity error (MPJVE) and jitter, under a VR system's noise
and LoBSTr's, on the validation people (field protocol), beside the floor the noise leaves
on the tracked points themselves at that lag and each estimator's figures on clean trackers.

The live bar (issue 33): at the chosen lag, MPJVE at most 1.5 times the tracked points' floor
and jitter at most twice the estimator's clean figure. Each row says whether it holds.

Usage: .venv/bin/python scripts/lag_curve.py [--split validation] [--limit N] [--workers 2]
           [--output docs/lag_curve.json]
Writes the table (Markdown) to stdout and every run's per-clip figures to --output.
"""

from __future__ import annotations

import argparse
import json
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

LAG_FRAMES = (0, 1, 2, 4, 6)  # at 60 fps: 0, 17, 33, 67, 100 ms
NOISES = ("vr", "lobstr")
RUNS = (
    ("ik", "six_point"),
    ("dtp", "six_point"),
    ("dragposer", "six_point"),
    ("lobstr", "four_point"),
    ("avatarjlm", "four_point"),
)
FPS = 60.0
KEPT = ("MPJPE [cm]", "MPJVE [cm/s]", "Jitter [100m/s3]")


def _evaluate(job: tuple) -> dict:
    from sparse_body.core.sensors import load_sensor_config
    from sparse_body.data.catalog import find_mocap_root
    from sparse_body.data.field_protocol import Protocol
    from sparse_body.evaluation import evaluate

    spec, sensors, noise, split, limit = job
    result = evaluate(
        spec,
        load_sensor_config(sensors),
        find_mocap_root(),
        split,
        protocol=Protocol.named(noise=noise),
        limit=limit,
        progress=False,
    ).to_json()
    return {
        "estimator": spec,
        "sensors": sensors,
        "noise": noise,
        "protocol": result["protocol"],
        "frames": result["frames"],
        "summary": {k: result["summary"][k] for k in KEPT},
        "interval_95": {k: result["interval_95"][k] for k in KEPT},
        "clips": [{"clip": c["clip"], "frames": c["frames"], **{k: c[k] for k in KEPT}} for c in result["clips"]],
    }


def _floor(job: tuple) -> dict:
    """The tracked points' own velocity error and jitter after the smoother at each lag:
    the sensors' virtual trackers with the noise, against the same trackers clean."""
    from sparse_body.core.fixed_lag import FixedLagSmoother
    from sparse_body.core.metrics import jitter, mpjve
    from sparse_body.core.sensors import load_sensor_config
    from sparse_body.core.tracker_filter import filter_config
    from sparse_body.data.catalog import find_mocap_root, load_clip, split_clips
    from sparse_body.data.field_protocol import NOISE_MODELS
    from sparse_body.data.virtual_trackers import NO_NOISE, synthesize_trackers
    from sparse_body.evaluation import filter_options

    sensors_name, noise, split, limit = job
    sensors, model = load_sensor_config(sensors_name), NOISE_MODELS[noise]
    config = filter_config(filter_options(model))
    rows = {lag: [] for lag in LAG_FRAMES}
    for clip in split_clips(find_mocap_root(), split)[:limit]:
        motion = load_clip(clip)
        truth = synthesize_trackers(motion, sensors, NO_NOISE).positions
        noisy = list(synthesize_trackers(motion, sensors, model, seed=1))
        for lag in LAG_FRAMES:
            est = np.array([f.positions for f in FixedLagSmoother(config, lag).stream(noisy)])
            rows[lag].append((len(truth), mpjve(est, truth, motion.fps), jitter(est, motion.fps)))
    out = {}
    for lag, r in rows.items():
        n, v, j = np.array(r).T
        out[lag] = {
            "MPJVE [cm/s]": float(np.average(v, weights=n)),
            "Jitter [100m/s3]": float(np.average(j, weights=n)),
        }
    return {"sensors": sensors_name, "noise": noise, "by_lag": out}


def _spec(name: str, lag: int) -> str:
    return name if lag == 0 else f"{name}:filter_lag={lag / FPS:.4f}"


def _cell(summary: dict, interval: dict, metric: str, digits: int) -> str:
    low_high = interval.get(metric)
    spread = f" [{low_high[0]:.{digits}f}, {low_high[1]:.{digits}f}]" if low_high else ""
    return f"{summary[metric]:.{digits}f}{spread}"


def table(results: list[dict], floor: dict, split: str) -> list[str]:
    """The Markdown table: each estimator's MPJVE / jitter at each lag with its 95 % interval
    (clips drawn), and the floor (the tracked points, over all frames: no interval)."""
    found = {(r["estimator"], r["sensors"], r["noise"]): r for r in results}
    lines = [
        f"Validation split ({split}, {results[0]['frames']} frames at {FPS:g} fps; {results[0]['protocol']} "
        "protocol); MPJVE [cm/s] / jitter [100 m/s^3], each with its 95 % interval, clips drawn; floor: the "
        "tracked points' own figures at that lag; bar: MPJVE <= 1.5 x floor and jitter <= 2 x clean.",
        "",
        "| estimator | noise | clean (no noise) | "
        + " | ".join(f"lag {1000 * k / FPS:.0f} ms" for k in LAG_FRAMES)
        + " |",
        "|---|---|---|" + "---|" * len(LAG_FRAMES),
    ]
    for name, sensors in RUNS:
        clean = found[(name, sensors, "none")]["summary"]
        for noise in NOISES:
            cells = []
            for lag in LAG_FRAMES:
                run = found[(_spec(name, lag), sensors, noise)]
                s, f = run["summary"], floor[(sensors, noise)][str(lag)]
                met = (
                    s["MPJVE [cm/s]"] <= 1.5 * f["MPJVE [cm/s]"]
                    and s["Jitter [100m/s3]"] <= 2 * clean["Jitter [100m/s3]"]
                )
                interval = run.get("interval_95", {})
                cells.append(
                    f"{_cell(s, interval, 'MPJVE [cm/s]', 1)} / {_cell(s, interval, 'Jitter [100m/s3]', 2)}"
                    + (" (bar met)" if met else "")
                )
            lines.append(
                f"| {name}/{sensors} | {noise} | {clean['MPJVE [cm/s]']:.1f} / {clean['Jitter [100m/s3]']:.2f} | "
                + " | ".join(cells)
                + " |"
            )
    for (sensors, noise), by_lag in floor.items():
        lines.append(
            f"| floor: {sensors} tracked points | {noise} | | "
            + " | ".join(
                f"{by_lag[str(k)]['MPJVE [cm/s]']:.1f} / {by_lag[str(k)]['Jitter [100m/s3]']:.2f}" for k in LAG_FRAMES
            )
            + " |"
        )
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--split", default="validation")
    parser.add_argument("--limit", type=int, default=None)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--output", type=Path, default=Path("docs/lag_curve.json"))
    parser.add_argument(
        "--render", action="store_true", help="print the table of --output as measured, measuring nothing"
    )
    args = parser.parse_args()
    if args.render:
        data = json.loads(args.output.read_text())
        floor = {(f["sensors"], f["noise"]): f["by_lag"] for f in data["floor"]}
        print("\n".join(table(data["runs"], floor, data["split"])))
        return
    started = time.time()
    jobs = [
        (_spec(name, lag), sensors, noise, args.split, args.limit)
        for name, sensors in RUNS
        for noise in NOISES
        for lag in LAG_FRAMES
    ]
    jobs += [(name, sensors, "none", args.split, args.limit) for name, sensors in RUNS]  # clean: no noise, no filter
    floors = [(s, noise, args.split, args.limit) for s in dict.fromkeys(s for _, s in RUNS) for noise in NOISES]
    with ProcessPoolExecutor(args.workers) as pool:
        floor_results = list(pool.map(_floor, floors))
        results = list(pool.map(_evaluate, jobs))
    # JSON keys are strings: the floor keyed so as it is read back
    for f in floor_results:
        f["by_lag"] = {str(k): v for k, v in f["by_lag"].items()}
    floor = {(f["sensors"], f["noise"]): f["by_lag"] for f in floor_results}
    lines = table(results, floor, args.split)
    print("\n".join(lines))
    args.output.write_text(
        json.dumps(
            {
                "command": "python scripts/lag_curve.py" + (f" --limit {args.limit}" if args.limit else ""),
                "split": args.split,
                "lag_frames": LAG_FRAMES,
                "fps": FPS,
                "minutes": (time.time() - started) / 60,
                "floor": [{"sensors": s, "noise": n, "by_lag": v} for (s, n), v in floor.items()],
                "runs": results,
                "table": lines,
            },
            separators=(",", ":"),
        )
    )
    print(f"written {args.output}")


if __name__ == "__main__":
    main()
