"""`make train-forecast` (python -m sparse_body.train.forecast): the learned root forecast of
predict_ahead (core/forecast.py), a small network over the root's recent velocities.

Data: six-point IK's estimate of every train clip under the field protocol (the estimate a
user's stack forecasts from, not the mocap), mirrored left-right beside itself. Each frame with
`lags` + 1 valid frames behind it gives, for each horizon of 1 to 12 frames (up to 200 ms),
the root's velocities over those frames in the heading frame (newest first) and the move of the
estimate's own root that far ahead, in the same frame. The network gives that move as the
constant velocity's plus a correction (so an untrained one is the constant velocity).

Selection: the validation people, the held-out kind dance among them; the checkpoint with the
lowest root error at 100 ms over all validation frames is exported. After training the whole
forecast (joints faded, root learned) is scored against the present pose, the faded and the
constant velocity on the validation people by kind (MPJPE at the forecast time) and written
with the report (models/forecast_root.train.json) and the card (models/forecast_root.md).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import torch
from torch import nn

from .harness import TrainRun, export_onnx, fit, machine
from .presets import Presets

HORIZONS = range(1, 13)  # frames at 60 fps: up to 200 ms, MAX_AHEAD
SCORED_MS = (33, 67, 100, 150)


@dataclass
class ForecastConfig(Presets):
    KIND: ClassVar[str] = "forecast"
    lags: int = 5  # root velocities read, newest first (83 ms at 60 fps)
    hidden: int = 64  # the correction's width
    batch: int = 4096
    lr: float = 2e-3
    weight_decay: float = 1e-4
    steps: int = 3000
    minutes: float = 20.0
    check_every: int = 250
    mirror: bool = True  # each clip's left-right mirror beside it
    estimator: str = "ik"  # whose estimate is forecast in training
    sensors: str = "six_point"
    PRESETS: ClassVar[dict] = {"small": {}, "tiny": {"steps": 200, "check_every": 100}}

    def to_dict(self) -> dict:
        return asdict(self)


class RootForecastNet(nn.Module):
    """(velocities (n, lags, 3) m/s newest first, ahead (n,) s) -> move (n, 3) m, heading frame."""

    def __init__(self, lags: int, hidden: int) -> None:
        super().__init__()
        last = nn.Linear(hidden, 3)
        nn.init.zeros_(last.weight)  # untrained, it is the constant velocity
        nn.init.zeros_(last.bias)
        self.correction = nn.Sequential(
            nn.Linear(3 * lags + 1, hidden), nn.GELU(), nn.Linear(hidden, hidden), nn.GELU(), last
        )

    def forward(self, velocities: torch.Tensor, ahead: torch.Tensor) -> torch.Tensor:
        # the inputs as moves over the horizon (metres): one scale at every horizon and speed
        moves = velocities * ahead[:, None, None]
        features = torch.cat([moves.reshape(len(moves), -1), 10.0 * ahead[:, None]], 1)
        return moves[:, 0] + self.correction(features)


@dataclass
class Samples:
    velocities: np.ndarray  # (n, lags, 3)
    ahead: np.ndarray  # (n,)
    move: np.ndarray  # (n, 3)


def estimate_split(mocap_root: Path, split: str, config: ForecastConfig, limit: int | None = None) -> list[dict]:
    """Each clip of a split: the estimator's poses under the field protocol (floor at z = 0),
    the true joints, the person's body and the kind of motion."""
    from ..evaluation import estimated_clips

    return [
        {
            "key": item.key,
            "kind": item.category,
            "fps": motion.fps,
            "quats": np.stack([p.local_quats for p in poses]),
            "root": np.stack([p.root_position for p in poses]),
            "valid": np.array([p.valid for p in poses]),
            "truth": motion.positions,
            "offsets": view.skeleton.offsets,
        }
        for item, motion, view, poses in estimated_clips(mocap_root, split, config.estimator, config.sensors, limit)
    ]


def _heading(quats: np.ndarray) -> np.ndarray:
    """(T, 2, 2) each frame's turn into its pelvis's heading frame (x, y)."""
    from scipy.spatial.transform import Rotation

    m = Rotation.from_quat(quats[:, 0]).as_matrix()
    yaw = np.arctan2(m[:, 1, 0], m[:, 0, 0])
    c, s = np.cos(yaw), np.sin(yaw)
    return np.stack([np.stack([c, s], -1), np.stack([-s, c], -1)], -2)


def samples(clip: dict, lags: int, horizons, mirror: bool = False) -> Samples:
    """Every frame's root velocities (heading frame, newest first) and the estimate's root
    move at each horizon; mirror: the clip mirrored left-right (y and the heading's turn)."""
    root, fps, valid = np.array(clip["root"], float), float(clip["fps"]), np.asarray(clip["valid"], bool)
    turn = _heading(np.asarray(clip["quats"], float))
    if mirror:
        root[:, 1] *= -1.0
        turn = turn * np.array([[1.0, -1.0], [-1.0, 1.0]])  # yaw -> -yaw
    steps = np.diff(root, axis=0) * fps  # steps[t - 1]: from t - 1 to t
    count = len(root)
    ok = np.array([t >= lags and valid[t - lags : t + 1].all() for t in range(count)])
    out = []
    for h in horizons:
        frames = np.flatnonzero(ok[: count - h] & valid[h:])
        if not len(frames):
            continue
        vel = np.stack([steps[frames - 1 - lag] for lag in range(lags)], 1)  # (n, lags, 3)
        move = root[frames + h] - root[frames]
        into = turn[frames]
        vel[..., :2] = np.einsum("nab,nlb->nla", into, vel[..., :2])
        move[:, :2] = np.einsum("nab,nb->na", into, move[:, :2])
        out.append(Samples(vel, np.full(len(frames), h / fps), move))
    if not out:
        return Samples(np.zeros((0, lags, 3)), np.zeros(0), np.zeros((0, 3)))
    return Samples(*(np.concatenate([getattr(s, f) for s in out]) for f in ("velocities", "ahead", "move")))


def _joined(parts: list[Samples]) -> dict[str, torch.Tensor]:
    return {
        f: torch.tensor(np.concatenate([getattr(s, f) for s in parts]), dtype=torch.float32)
        for f in ("velocities", "ahead", "move")
    }


def score_forecasts(clips: list[dict], model: RootForecastNet | None, lags: int) -> dict:
    """MPJPE [cm] at the forecast time of the present pose, the faded forecast (joints and
    root), the constant velocity and the shipped forecast (joints faded, root learned), each
    clip's sums by horizon, as PoseForecast gives them step by step."""
    from ..core.forecast import PoseForecast
    from ..core.kinematics import forward_kinematics
    from ..core.rotations import quat_to_matrix
    from ..core.types import BodyPose

    def learned(velocities: np.ndarray, ahead: float) -> np.ndarray:
        assert model is not None
        with torch.no_grad():
            v = torch.tensor(velocities[None], dtype=torch.float32)
            return model(v, torch.tensor([ahead], dtype=torch.float32))[0].numpy().astype(np.float64)

    rows = []
    for clip in clips:
        fps = float(clip["fps"])
        poses = [
            BodyPose(i / fps, q, r, valid=bool(v))
            for i, (q, r, v) in enumerate(zip(clip["quats"], clip["root"], clip["valid"], strict=True))
        ]
        row: dict = {"clip": clip["key"], "kind": clip["kind"], "errors": {}}
        for ms in SCORED_MS:
            h = round(ms * fps / 1000)
            count = len(poses) - h
            if count <= 0:
                continue
            # each velocity as read (smooth=0): the root model is what is compared
            variants = {
                "present": PoseForecast(0.0),
                "faded": PoseForecast(h / fps, smooth=0.0, smooth_root=0.0),
                "constant velocity": PoseForecast(h / fps, fade=math.inf, smooth=0.0, smooth_root=0.0),
            }
            if model is not None:
                variants["learned root"] = PoseForecast(
                    h / fps, root_model=learned, lags=lags, smooth=0.0, smooth_root=0.0
                )
            row["errors"][str(ms)] = {}
            for name, forecast in variants.items():
                out = [forecast.forecast(p) for p in poses] if name != "present" else poses
                local = quat_to_matrix(np.stack([p.local_quats for p in out]))
                _, joints = forward_kinematics(local, np.stack([p.root_position for p in out]), clip["offsets"])
                error = np.linalg.norm(joints[:count] - clip["truth"][h:], axis=-1).mean(axis=1)
                row["errors"][str(ms)][name] = [float(error.sum()), count]
        rows.append(row)
    return {"clips": rows, "table": forecast_table(rows)}


def forecast_table(rows: list[dict]) -> list[dict]:
    """Frame-weighted MPJPE [cm] by group (dance, the held-out kind; other; all) and horizon."""
    table = []
    for group in ("dance", "other", "all"):
        members = [r for r in rows if group == "all" or (r["kind"] == "dance") == (group == "dance")]
        for ms in SCORED_MS:
            sums: dict[str, list[float]] = {}
            for r in members:
                for name, (total, count) in r["errors"].get(str(ms), {}).items():
                    s = sums.setdefault(name, [0.0, 0.0])
                    s[0], s[1] = s[0] + total, s[1] + count
            if sums:
                table.append({"group": group, "ms": ms, **{n: 100 * t / c for n, (t, c) in sums.items() if c}})
    return table


def train(config: ForecastConfig, run: TrainRun) -> dict:
    rng = run.start()
    run.log(f"estimating the train and validation clips with {config.estimator} {config.sensors} (field protocol)")
    train_clips = estimate_split(run.mocap_root, "train", config, run.limit)
    val_clips = estimate_split(run.mocap_root, "validation", config, run.limit)
    parts = [samples(c, config.lags, HORIZONS) for c in train_clips]
    if config.mirror:
        parts += [samples(c, config.lags, HORIZONS, mirror=True) for c in train_clips]
    data = _joined(parts)
    hundred = [round(0.1 * float(c["fps"])) for c in val_clips]
    val = _joined([samples(c, config.lags, [h]) for c, h in zip(val_clips, hundred, strict=True)])
    run.log(f"{len(data['ahead'])} train samples, {len(val['ahead'])} validation samples at 100 ms")
    model = RootForecastNet(config.lags, config.hidden)
    optimizer = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    count = len(data["ahead"])

    def step():
        pick = torch.as_tensor(rng.integers(0, count, config.batch))
        error = model(data["velocities"][pick], data["ahead"][pick]) - data["move"][pick]
        loss = (error**2).sum(1).mean()
        return loss, {"loss_cm2": float(loss.detach()) * 1e4}

    def validate() -> dict[str, float]:
        with torch.no_grad():
            error = model(val["velocities"], val["ahead"]) - val["move"]
            base = val["velocities"][:, 0] * val["ahead"][:, None] - val["move"]
        return {
            "root_cm": float(error.norm(dim=1).mean()) * 100,
            "constant_velocity_root_cm": float(base.norm(dim=1).mean()) * 100,
        }

    fitted = fit(
        model,
        optimizer,
        step,
        validate,
        lambda v: v["root_cm"],
        steps=config.steps,
        minutes=config.minutes,
        check_every=config.check_every,
        rng=rng,
        run=run,
    )
    out = Path(run.out)
    example = (torch.zeros(1, config.lags, 3), torch.full((1,), 0.1))
    export_onnx(
        model,
        example,
        out,
        ["velocities", "ahead"],
        ["move"],
        {"model": "forecast_root", "lags": config.lags, "fps": 60.0, "config": config.to_dict()},
        dynamic_axes={"velocities": {0: "n"}, "ahead": {0: "n"}, "move": {0: "n"}},
    )
    run.log("scoring the forecasts on the validation people")
    scored = score_forecasts(val_clips, model, config.lags)
    return {
        "config": config.to_dict(),
        "steps": fitted.steps,
        "minutes": fitted.minutes,
        "validation": fitted.validation,
        "history": fitted.history,
        "train_clips": len(train_clips),
        "validation_clips": len(val_clips),
        "train_samples": count,
        "forecasts": scored,
        **machine(),
    }


def card(report: dict, command: str) -> str:
    """The model card, from the training report alone."""
    rows = report["forecasts"]["table"]
    names = ["present", "faded", "constant velocity", "learned root"]
    sensors = report["config"]["sensors"].replace("_", "-")
    lines = [
        "# Learned root forecast (predict_ahead)",
        "",
        "What it is: the root's move over the next 0-200 ms from its last "
        f"{report['config']['lags']} velocities (heading frame), as `predict_ahead` uses it with every "
        "estimator (the joints' turns are carried at their fading velocity; `forecast=faded` turns it off). "
        "A two-layer MLP correcting the constant velocity; ONNX, `forecast_root.onnx`.",
        "",
        f"Data: the CMU train split ({report['train_clips']} clips), {sensors} {report['config']['estimator']}'s "
        "estimate under the field protocol, mirrored beside itself; selection and the table below: the validation "
        f"people ({report['validation_clips']} clips; dance, absent from training, is the held-out kind). "
        "The test split is not read.",
        "",
        f"Command: `{command}`. Training: {report['steps']} steps, {report['minutes']:.1f} minutes on "
        f"{report['hardware']} (torch {report['torch']}), {report['train_samples']:,} samples.",
        "",
        f"Validation root error at 100 ms: {report['validation']['root_cm']:.2f} cm "
        f"(constant velocity: {report['validation']['constant_velocity_root_cm']:.2f} cm).",
        "",
        "MPJPE [cm] of each pose against the true body at its forecast time (joints placed with the person's body):",
        "",
        "| group | ms | " + " | ".join(names) + " |",
        "| --- | ---: |" + " ---: |" * len(names),
    ]
    for row in rows:
        lines.append(f"| {row['group']} | {row['ms']} | " + " | ".join(f"{row[n]:.2f}" for n in names) + " |")
    lines.append("")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    from ..core.resources import models_dir
    from ..data.catalog import find_mocap_root

    parser = argparse.ArgumentParser(description="train the learned root forecast of predict_ahead")
    parser.add_argument("--config", default="small", choices=sorted(ForecastConfig.PRESETS))
    parser.add_argument("--out", type=Path, default=models_dir() / "forecast_root.onnx")
    parser.add_argument("--mocap", help="the CMU folder")
    parser.add_argument("--limit", type=int, help="only the first clips of each split (a quick check)")
    args = parser.parse_args(argv)
    root = find_mocap_root(args.mocap)
    if root is None:
        print("train forecast: no motion capture folder found (sparse-body import-mocap)", file=sys.stderr)
        return 2
    started = time.time()
    run = TrainRun(mocap_root=root, out=args.out, limit=args.limit)
    report = train(ForecastConfig.named(args.config), run)
    command = "make train-forecast" if args.config == "small" and args.limit is None else " ".join(sys.argv)
    report["command"] = command
    report["wall_minutes"] = (time.time() - started) / 60
    args.out.with_name("forecast_root.train.json").write_text(json.dumps(report, indent=1) + "\n")
    args.out.with_name("forecast_root.md").write_text(card(report, command))
    print(f"written {args.out}, its report and card")
    return 0


if __name__ == "__main__":
    sys.exit(main())
