"""Would a learned contact model beat the live rule? The measurement behind docs/methods.md,
"Feet held where they touch down" (its last paragraph): a classifier that sees more than the
toe, trained on the train people's estimates, against ToeContacts on the same estimates.

Each estimator runs once over every train and validation clip under the field protocol (the
view `sparse-body eval` gives it, same seeds; foot_lock=false: the toes the rule reads). Per
foot and frame, the classifier sees the estimated toe's, ankle's and knee's heights, the toe's
and ankle's speeds, the other toe's, the pelvis's and the head's height and speed, where the
toe stands from the pelvis and the other toe, over the last third of a second (frames 0, 2, 4,
6, 8, 10, 14, 20 back: live, it would add no latency), one model for both feet. Two models:
logistic ("linear") and a 64-64 MLP ("mlp"), Adam, 12 passes, seeded. Labels: contact_labels
of the motion. Scored like contact_rules.py: the share of (frame, foot) states right, on the
kinds of motion no train clip has (the selection) and on the validation people's others; then
the share the rule says planted.

Usage: .venv/bin/python scripts/contact_model.py [--estimator lobstr --estimator avatarjlm]
       [--threshold 0.5]   (about 5 minutes an estimator on 2 cores; needs torch, make setup-train)
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.ndimage import minimum_filter1d

LAGS = (0, 2, 4, 6, 8, 10, 14, 20)  # frames back the classifier sees
FLOOR_WINDOW = 120  # frames back the floor is the lowest toe of (causal, as live)
PASSES, BATCH, SEED = 12, 512, 0


def foot_features(est: np.ndarray, fps: float) -> np.ndarray:
    """(T, 2, F): per frame and foot (left, right), what the classifier sees, from (T, 22, 3)
    estimated joints; mirror-free (heights, speeds, distances), so one model serves both feet."""
    from sparse_body.core.skeleton import JOINT_INDEX

    def joint(name: str) -> np.ndarray:
        return est[:, JOINT_INDEX[name]]

    def velocity(x: np.ndarray) -> np.ndarray:
        return np.diff(x, axis=0, prepend=x[:1]) * fps

    toes = [joint("left_foot"), joint("right_foot")]
    ankles, knees = [joint("left_ankle"), joint("right_ankle")], [joint("left_knee"), joint("right_knee")]
    pelvis, head = joint("pelvis"), joint("head")
    lowest = np.minimum(toes[0][:, 2], toes[1][:, 2])
    floor = minimum_filter1d(lowest, FLOOR_WINDOW + 1, origin=FLOOR_WINDOW // 2, mode="nearest")  # [t-120, t]
    pelvis_v, head_v = velocity(pelvis), velocity(head)
    feet = []
    for own, other in ((0, 1), (1, 0)):
        toe_v, ankle_v, other_v = velocity(toes[own]), velocity(ankles[own]), velocity(toes[other])
        now = np.stack(
            [
                toes[own][:, 2],
                toes[own][:, 2] - floor,
                ankles[own][:, 2],
                knees[own][:, 2],
                np.linalg.norm(toe_v, axis=1),
                np.linalg.norm(toe_v[:, :2], axis=1),
                toe_v[:, 2],
                np.linalg.norm(ankle_v, axis=1),
                ankle_v[:, 2],
                toes[other][:, 2] - floor,
                np.linalg.norm(other_v, axis=1),
                pelvis[:, 2],
                pelvis_v[:, 2],
                np.linalg.norm(pelvis_v[:, :2], axis=1),
                head[:, 2],
                head_v[:, 2],
                np.linalg.norm(toes[own][:, :2] - pelvis[:, :2], axis=1),
                np.linalg.norm(toes[own][:, :2] - toes[other][:, :2], axis=1),
                toes[own][:, 2] - toes[other][:, 2],
            ],
            axis=1,
        )
        back = [np.concatenate([now[:1].repeat(lag, 0), now[: len(now) - lag]]) if lag else now for lag in LAGS]
        feet.append(np.concatenate(back, axis=1))
    return np.stack(feet, axis=1).astype(np.float32)


def estimates(name: str, split: str):
    """(features, labels, the rule's contacts, kinds) over every clip of a split, frames stacked."""
    from sparse_body.core.contacts import FOOT_JOINTS, ToeContacts, contact_labels
    from sparse_body.core.sensors import load_sensor_config
    from sparse_body.data.catalog import find_mocap_root
    from sparse_body.evaluation import estimate_motion, split_items

    sensors, parts = load_sensor_config("four_point"), []
    for item in split_items(find_mocap_root(), split):
        motion = item.load()
        run = estimate_motion(motion, name, sensors, seed=item.seed, foot_lock=False)
        live = ToeContacts(motion.fps)
        rule = np.stack([live(toes) for toes in run.positions[:, FOOT_JOINTS]])
        truth = contact_labels(run.motion.positions, motion.fps)
        parts.append((foot_features(run.positions, motion.fps), truth, rule, [item.category] * len(truth)))
    return [np.concatenate([p[k] for p in parts]) for k in range(4)]


def fit(features: np.ndarray, labels: np.ndarray, hidden: int):
    """A seeded classifier of one foot's state (hidden 0: logistic); returns P(contact) of (N, F)."""
    import torch

    torch.manual_seed(SEED)
    x, y = features.reshape(-1, features.shape[-1]), labels.reshape(-1).astype(np.float32)
    mean, scale = x.mean(0), x.std(0) + 1e-6
    layers = [torch.nn.Linear(x.shape[1], 1)]
    if hidden:
        layers = [torch.nn.Linear(x.shape[1], hidden), torch.nn.ReLU(), torch.nn.Linear(hidden, hidden)]
        layers += [torch.nn.ReLU(), torch.nn.Linear(hidden, 1)]
    net = torch.nn.Sequential(*layers)
    opt = torch.optim.Adam(net.parameters(), 1e-3, weight_decay=1e-4)
    xs, ys = torch.from_numpy((x - mean) / scale), torch.from_numpy(y)
    draws = np.random.default_rng(SEED)
    for _ in range(PASSES):
        order = torch.from_numpy(draws.permutation(len(xs)))
        for start in range(0, len(xs), BATCH):
            batch = order[start : start + BATCH]
            loss = torch.nn.functional.binary_cross_entropy_with_logits(net(xs[batch])[:, 0], ys[batch])
            opt.zero_grad()
            loss.backward()
            opt.step()

    def predict(f: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            z = torch.from_numpy((f.reshape(-1, f.shape[-1]) - mean) / scale)
            return torch.sigmoid(net(z)[:, 0]).numpy().reshape(f.shape[:-1])

    return predict


def main() -> None:
    from sparse_body.data.catalog import find_mocap_root, split_clips

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--estimator", action="append")
    parser.add_argument("--threshold", type=float, default=0.5, help="P(contact) over which a foot is planted")
    args = parser.parse_args()
    trained = {c.kind for c in split_clips(find_mocap_root(), "train")}
    for name in args.estimator or ["lobstr", "avatarjlm"]:
        train_x, train_y, _, _ = estimates(name, "train")
        x, truth, rule, kinds = estimates(name, "validation")
        said = {"rule (shipped)": rule}
        for label, hidden in (("linear", 0), ("mlp", 64)):
            said[label] = fit(train_x, train_y, hidden)(x) > args.threshold
        unseen = ~np.isin(kinds, sorted(trained))
        print(
            f"{name}/four_point, validation: contacts right [%] (labels' share of contacts, then each contact model's)"
        )
        groups = [("selection", unseen), ("other kinds", ~unseen)]
        groups += [(f"  {kind}", kinds == kind) for kind in sorted(set(kinds))]
        print(f"  {'':20s} {'states':>7s} {'labels':>7s} " + " ".join(f"{k:>15s}" for k in said))
        for group, mask in groups:
            right = " ".join(f"{100 * (s == truth)[mask].mean():15.1f}" for s in said.values())
            print(f"  {group:20s} {2 * int(mask.sum()):7d} {100 * truth[mask].mean():7.1f} {right}")
        print(
            "  the rule says planted [% of states]: "
            + ", ".join(f"{g.strip()} {100 * rule[m].mean():.1f}" for g, m in groups)
        )


if __name__ == "__main__":
    main()
