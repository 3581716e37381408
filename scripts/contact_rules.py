"""Which live contact rule? The measurement behind core/contacts.py's LIVE_HEIGHT, LIVE_SPEED
and LIVE_HOLD (docs/methods.md, "Feet held where they touch down").

Each estimator runs once over every clip of a part of the split under the field protocol (the
view `sparse-body eval` gives it, same seed); then each candidate rule (ToeContacts with that
height band, 3-D speed limit and hold) reads the estimated toes frame by frame, and its
contacts are scored against contact_labels of the motion: the share of (frame, foot) states
right, on the kinds of motion no train clip has and on the others. The toes are the method's
own (foot_lock=false), as the rule reads them live. "own" is the estimator's published
contacts (LoBSTr's network's; the shipped rule's for the others).

With --label-rates, only the labels: each kind of motion's share of (frame, foot) contacts
under contact_labels and under its first version (one floor for the take, 2 cm, horizontal
speed), over the train and validation clips.

Usage: .venv/bin/python scripts/contact_rules.py [--estimator avatarjlm --estimator dragposer
       --estimator lobstr] [--sensors four_point] [--split validation] [--label-rates]
"""

import argparse
import itertools

import numpy as np

from sparse_body.core.contacts import FOOT_JOINTS, ToeContacts, contact_labels, estimate_floor, toe_speeds
from sparse_body.core.sensors import load_sensor_config
from sparse_body.data.catalog import find_mocap_root, load_clip, split_clips
from sparse_body.evaluation import estimate_motion, split_items, untrained_categories

HEIGHTS, SPEEDS, HOLDS = (0.05, 0.08, 0.12), (0.3, 0.5, 0.8), (0.0, 0.05)  # m, m/s, s


def first_version(positions: np.ndarray, fps: float) -> np.ndarray:
    """contact_labels before 2026-12-05: one floor for the take, a 2 cm band, horizontal speed."""
    low = positions[:, FOOT_JOINTS, 2] - estimate_floor(positions) < 0.02
    return low & (toe_speeds(positions, fps) < 0.3)


def label_rates(root) -> None:
    print(
        "contacts [% of (frame, foot)]: kind of motion, part, frames, labels now, first version; "
        "then the shipped live rule on the motion's own toes, right against the labels now [%]"
    )
    for part in ("train", "validation"):
        shares: dict[str, np.ndarray] = {}
        for clip in split_clips(root, part):
            motion = load_clip(clip)
            now, first = contact_labels(motion.positions, motion.fps), first_version(motion.positions, motion.fps)
            floor = estimate_floor(motion.positions)  # (as the estimators have it: the take's floor)
            live = ToeContacts(motion.fps)
            said = np.stack([live(toes, floor) for toes in motion.positions[:, FOOT_JOINTS]])
            n = len(motion)
            shares.setdefault(clip.kind, np.zeros(4))[:] += [
                n,
                now.mean() * n,
                first.mean() * n,
                (said == now).mean() * n,
            ]
        for kind, (frames, now, first, right) in sorted(shares.items()):
            print(
                f"  {kind:18s} {part:10s} {int(frames):7d} {100 * now / frames:6.1f} {100 * first / frames:6.1f}"
                f" {100 * right / frames:6.1f}"
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--estimator", action="append")
    parser.add_argument("--sensors", default="four_point")
    parser.add_argument("--split", default="validation")
    parser.add_argument("--label-rates", action="store_true")
    args = parser.parse_args()
    root, sensors = find_mocap_root(), load_sensor_config(args.sensors)
    if args.label_rates:
        return label_rates(root)
    items = split_items(root, args.split)
    unseen = untrained_categories(root, [i.category for i in items])
    rules = list(itertools.product(HEIGHTS, SPEEDS, HOLDS))
    for name in args.estimator or ["avatarjlm", "dragposer", "lobstr"]:
        right = {rule: np.zeros((2, 2)) for rule in [None, *rules]}  # [unseen, seen] x [right, all]
        for item in items:
            motion = item.load()
            run = estimate_motion(motion, name, sensors, seed=item.seed, foot_lock=False)  # the toes the rule reads
            truth = contact_labels(run.motion.positions, motion.fps)
            toes = run.positions[:, FOOT_JOINTS]
            row = 0 if item.category in unseen else 1
            for rule in right:
                if rule is None:
                    said = run.contacts
                else:
                    live = ToeContacts(motion.fps, *rule)  # (a hold of 0: a frame, each state taken at once)
                    said = np.stack([live(t) for t in toes])
                right[rule][row] += [(said == truth).sum(), truth.size]
        print(
            f"{name}/{args.sensors}, {args.split}: contacts right [%], "
            f"unseen kinds ({', '.join(sorted(unseen))}) / seen"
        )
        for rule, (u, s) in right.items():
            label = "own" if rule is None else f"height {rule[0]:.2f} m, speed {rule[1]:.1f} m/s, hold {rule[2]:.2f} s"
            print(f"  {label:44s} {100 * u[0] / u[1]:6.1f} {100 * s[0] / s[1]:6.1f}")


if __name__ == "__main__":
    main()
