"""Where two estimators disagree about the legs, which one is wrong? The measurement behind
`blend`'s hand-over (docs/methods.md, "Motions the models never saw").

For each named validation clip: both estimators on its field-protocol trackers (the view
`sparse-body eval` gives them, same seed), then, frame by frame, the mean distance between
their leg joints and each one's lower-body error against the motion, grouped by that
distance. The hand-over's thresholds (agree_within, disagree_from) were read off this.

Usage: .venv/bin/python scripts/blend_disagreement.py 05_05 49_12 49_08 49_21
       [--first avatarjlm] [--second dragposer] [--sensors four_point] [--split validation]
"""

import argparse

import numpy as np

from sparse_body.core.metrics import LOWER
from sparse_body.core.sensors import load_sensor_config
from sparse_body.data.catalog import find_mocap_root
from sparse_body.evaluation import estimate_motion, split_items

BANDS = (0.0, 0.10, 0.15, 0.20, 0.30, np.inf)  # metres of leg disagreement


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("clips", nargs="+")
    parser.add_argument("--first", default="avatarjlm")
    parser.add_argument("--second", default="dragposer")
    parser.add_argument("--sensors", default="four_point")
    parser.add_argument("--split", default="validation")
    args = parser.parse_args()
    root = find_mocap_root()
    if root is None:
        raise SystemExit(
            "no motion capture indexed: sparse-body import-mocap FOLDER --out DIR, then SPARSE_BODY_MOCAP=DIR"
        )
    sensors = load_sensor_config(args.sensors)
    items = {item.name: item for item in split_items(root, args.split)}
    print(f"lower-body PE [cm] by leg disagreement between {args.first} and {args.second} [cm]")
    for name in args.clips:
        item = items.get(name)
        if item is None:
            raise SystemExit(f"{name}: not a clip of the {args.split} split")
        motion = item.load()
        a, b = (estimate_motion(motion, e, sensors, seed=item.seed) for e in (args.first, args.second))
        truth = a.motion.positions[:, LOWER]
        err_a = np.linalg.norm(a.positions[:, LOWER] - truth, axis=-1).mean(1) * 100
        err_b = np.linalg.norm(b.positions[:, LOWER] - truth, axis=-1).mean(1) * 100
        apart = np.linalg.norm(a.positions[:, LOWER] - b.positions[:, LOWER], axis=-1).mean(1)
        head = f"{name} ({item.category}, {len(apart)} frames)"
        print(f"{head}: {args.first} {err_a.mean():.2f}, {args.second} {err_b.mean():.2f}")
        for low, high in zip(BANDS, BANDS[1:], strict=False):
            band = (apart >= low) & (apart < high)
            if band.any():
                print(
                    f"  {low * 100:3.0f}-{high * 100:<4.0f} cm: {band.sum():5d} frames, "
                    f"{args.first} {err_a[band].mean():6.2f}, {args.second} {err_b[band].mean():6.2f}"
                )


if __name__ == "__main__":
    main()
