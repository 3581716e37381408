"""How likely a foot is on the floor, from what the live contact rule sees (core/contacts.py,
ToeContacts): its toe's height over the floor, its speed and the rule's own held state, as a
logistic model fitted to the motion's contact labels (contact_labels) on the validation
people's kinds that training has, and judged on three sets no fit or model saw: the
selection (kinds absent from training), the floor part and a folder of other clips.

Usage: .venv/bin/python scripts/contact_probability.py fit [--output docs/contact_probability.json]
       .venv/bin/python scripts/contact_probability.py judge [--motion FOLDER] [--output FILE]
Each run estimates every clip with each sensor set's default estimator and ik six-point.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

RUNS = (("upright", "four_point"), ("blend", "three_point"), ("ik", "six_point"))


def features(positions: np.ndarray, fps: float) -> np.ndarray:
    """(frames * 2, 3) what ToeContacts sees of each foot each frame (height over the floor
    [m], speed [m/s], its held state), replayed over an estimate's (T, 22, 3) joints."""
    from sparse_body.core.contacts import FOOT_JOINTS, ToeContacts

    toes = ToeContacts(fps)
    seen = []
    for toe in positions[:, list(FOOT_JOINTS)]:
        state = toes(toe, 0.0)
        seen.append(np.column_stack([toes.heights, toes.speeds, state]))
    return np.concatenate(seen)


def collect(items, root_note: str) -> dict[str, np.ndarray]:
    from sparse_body.core.contacts import contact_labels
    from sparse_body.core.sensors import load_sensor_config
    from sparse_body.data.field_protocol import FIELD
    from sparse_body.evaluation import estimate_motion

    out: dict[str, list] = {"seen": [], "flags": [], "published": [], "label": [], "run": [], "kind": []}
    for item in items:
        motion = item.load()
        for estimator, sensors in RUNS:
            est = estimate_motion(motion, estimator, load_sensor_config(sensors), FIELD, item.seed)
            labels = contact_labels(est.motion.positions, est.motion.fps).reshape(-1)
            out["seen"].append(features(est.positions, est.motion.fps))
            out["flags"].append(est.contacts.reshape(-1))
            out["published"].append(est.contact_probability.reshape(-1))
            out["label"].append(labels)
            out["run"] += [f"{estimator} {sensors}"] * len(labels)
            out["kind"] += [item.category or "files"] * len(labels)
        print(f"{root_note} {item.key}", file=sys.stderr)
    return {k: np.array(v) if k in ("run", "kind") else np.concatenate(v) for k, v in out.items()}


def fit(seen: np.ndarray, label: np.ndarray) -> np.ndarray:
    """Logistic coefficients (intercept, height, speed, state) by maximum likelihood."""
    from scipy.optimize import minimize

    from sparse_body.core.contacts import contact_terms

    x = np.column_stack(np.broadcast_arrays(*contact_terms(seen[:, 0], seen[:, 1], seen[:, 2])))
    y = label.astype(float)

    def loss(b):
        z = x @ b
        return float(np.mean(np.logaddexp(0.0, z) - y * z)), x.T @ (1.0 / (1.0 + np.exp(-z)) - y) / len(y)

    return minimize(loss, np.zeros(4), jac=True, method="BFGS").x


def _logistic(seen: np.ndarray, coefficients: np.ndarray) -> np.ndarray:
    """The model's probability for each row of seen (height, speed, held) with these coefficients."""
    from sparse_body.core.contacts import contact_terms

    terms = np.column_stack(np.broadcast_arrays(*contact_terms(seen[:, 0], seen[:, 1], seen[:, 2])))
    return 1.0 / (1.0 + np.exp(-(terms @ coefficients)))


def judge(data: dict[str, np.ndarray]) -> dict:
    """Brier score and log loss of the published probability (what the estimator gave
    beside its flags) against the flags' own (0 or 1), and its calibration (the observed share
    of contacts per tenth of probability), per run."""
    rows = {}
    for run in sorted(set(data["run"])):
        mine = data["run"] == run
        p, y, flag = data["published"][mine], data["label"][mine].astype(float), data["flags"][mine].astype(float)
        eps = 1e-6
        bins = np.clip((p * 10).astype(int), 0, 9)
        rows[run] = {
            "frames": int(mine.sum() // 2),
            "brier": float(np.mean((p - y) ** 2)),
            "brier, flags": float(np.mean((flag - y) ** 2)),
            "log loss": float(-np.mean(y * np.log(p + eps) + (1 - y) * np.log(1 - p + eps))),
            "calibration": {
                f"{b / 10:.1f}-{(b + 1) / 10:.1f}": [int(np.sum(bins == b)), float(y[bins == b].mean())]
                for b in range(10)
                if np.any(bins == b)
            },
        }
    return rows


def main() -> int:
    from sparse_body.data.catalog import MocapFolderError
    from sparse_body.evaluation import part_items

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("what", choices=("fit", "judge"))
    parser.add_argument("--split", default="selection", help="judge: selection or floor")
    parser.add_argument("--motion", help="judge: a folder of motion files instead of a split")
    parser.add_argument("--output", type=Path)
    args = parser.parse_args()
    try:
        if args.what == "fit":  # the validation people's kinds that training has
            held_out = {i.key for i in part_items("selection")}
            items = [i for i in part_items("validation") if i.key not in held_out]
        else:
            items = part_items(args.split, args.motion)
    except MocapFolderError as err:
        print(err, file=sys.stderr)
        return 2
    data = collect(items, args.what)
    result: dict = {"command": "python " + " ".join(sys.argv), "clips": len(items)}
    if args.what == "fit":  # judged in-sample with the coefficients fitted, not the shipped ones
        coefficients = fit(data["seen"], data["label"])
        result["coefficients"] = coefficients.tolist()
        data["published"] = _logistic(data["seen"], coefficients)
    result["runs"] = judge(data)
    text = json.dumps(result, indent=1)
    print(text)
    if args.output:
        args.output.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
