"""How well `upright`'s out-of-depth score flags the frames its base breaks on: per kind of
motion, the frames where `blend` four-point (upright's base) puts the legs over 1.5 times as
far off as IK does, against the frames the score calls out of depth (over 0.5) before
upright stands the body up. Field protocol, on the selection, the floor part or a folder.

Usage: .venv/bin/python scripts/out_of_depth_flags.py [--split selection|floor] [--motion FOLDER]
           [--output FILE]
Prints one row a kind (recall, precision, the area under the score's ROC curve) and writes
every clip's figures to --output.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

BAD = 1.5  # a frame is bad where the base's lower-body error is over this many times IK's
FLAGGED = 0.5  # the score from which a frame counts as flagged


def frame_errors(est) -> np.ndarray:
    """(T,) the lower body's mean joint error [cm] of each frame."""
    from sparse_body.core.metrics import LOWER

    return np.linalg.norm(est.positions[:, LOWER] - est.motion.positions[:, LOWER], axis=-1).mean(axis=-1) * 100


def area_under_roc(score: np.ndarray, bad: np.ndarray) -> float:
    """The chance that a bad frame scores higher than a good one (ties count half)."""
    from scipy.stats import rankdata

    if bad.all() or not bad.any():
        return float("nan")
    ranks = rankdata(score)
    n_bad = int(bad.sum())
    return float((ranks[bad].sum() - n_bad * (n_bad + 1) / 2) / (n_bad * (len(bad) - n_bad)))


def main() -> int:
    from sparse_body.core.sensors import load_sensor_config
    from sparse_body.data.catalog import MocapFolderError
    from sparse_body.data.field_protocol import FIELD
    from sparse_body.evaluation import estimate_motion, part_items

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--split", default="selection", choices=("selection", "floor"))
    parser.add_argument("--motion", help="a folder of motion files instead of a split")
    parser.add_argument("--output", type=Path)
    args = parser.parse_args()
    try:
        items = part_items(args.split, args.motion)
    except MocapFolderError as err:
        print(err, file=sys.stderr)
        return 2
    sensors = load_sensor_config("four_point")
    clips, pooled = [], {}
    for item in items:
        motion = item.load()
        score = estimate_motion(motion, "upright", sensors, FIELD, item.seed).out_of_depth
        base = frame_errors(estimate_motion(motion, "blend", sensors, FIELD, item.seed))
        ik = frame_errors(estimate_motion(motion, "ik", sensors, FIELD, item.seed))
        assert score is not None  # upright says it
        bad, flagged = base > BAD * ik, score > FLAGGED
        kind = item.category or item.group or "files"
        pooled.setdefault(kind, []).append((score, bad))
        clips.append(
            {
                "clip": item.key,
                "kind": kind,
                "frames": len(bad),
                "bad [%]": float(bad.mean() * 100),
                "flagged [%]": float(flagged.mean() * 100),
                "bad flagged [%]": float(flagged[bad].mean() * 100) if bad.any() else float("nan"),
                "flagged bad [%]": float(bad[flagged].mean() * 100) if flagged.any() else float("nan"),
            }
        )
        print(f"{item.key}: {clips[-1]}", file=sys.stderr)
    rows = {}
    print("| kind | frames | bad [%] | flagged [%] | bad ones flagged [%] | flagged ones bad [%] | ROC area |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    for kind, parts in sorted(pooled.items()):
        score = np.concatenate([s for s, _ in parts])
        bad = np.concatenate([b for _, b in parts])
        flagged = score > FLAGGED
        row = {
            "frames": len(bad),
            "bad [%]": float(bad.mean() * 100),
            "flagged [%]": float(flagged.mean() * 100),
            "bad flagged [%]": float(flagged[bad].mean() * 100) if bad.any() else float("nan"),
            "flagged bad [%]": float(bad[flagged].mean() * 100) if flagged.any() else float("nan"),
            "roc area": area_under_roc(score, bad),
        }
        rows[kind] = row
        print(f"| {kind} | " + " | ".join(f"{v:.0f}" if k == "frames" else f"{v:.2f}" for k, v in row.items()) + " |")
    if args.output:
        command = "python " + " ".join(sys.argv)
        args.output.write_text(json.dumps({"command": command, "kinds": rows, "clips": clips}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
