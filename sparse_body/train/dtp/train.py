"""`sparse-body train dtp`: CMU train split -> DTP ONNX model + model card, one command.

Two stages, as in the paper: pre-training on clean windows, then fine-tuning on windows in
which one or both feet are occluded for a stretch (the paper's AMASS-OCC). An occluded foot
reports what a Lighthouse tracker reports (data/virtual_trackers.py): the origin with the
identity rotation (turned by what the calibration makes of it), or a position anywhere
within a leg's length of the foot with a random rotation. Both stages export a model: the
pre-trained one is kept beside the shipped one so that the fine-tuning's effect can be
measured on the same streams (`sparse-body eval --occlusion`).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path

import numpy as np
import roma
import torch
from scipy.spatial.transform import Rotation

from ...core.contacts import estimate_floor
from ...core.rotations import matrix_to_6d
from ...core.skeleton import Skeleton, body_scale
from ...data.catalog import load_clip, split_clips
from ...data.virtual_trackers import LOBSTR_NOISE, _random_rotations
from ...methods.dtp.features import FOOT_LEAVES, INPUT_JOINTS, leaf_features, window_features
from ...train.augment import NO_AUGMENTATION, Augmentation, augmented
from ...train.harness import TrainRun, fit, held_out_split, load_best, machine
from ...train.harness import export_onnx as export
from ...train.torch_body import sixd_to_matrix
from .model import DtpConfig, DtpNet, body_positions, losses

MOUNTING_RESIDUAL_DEG = 25.0  # how far from identity an occluded tracker's calibrated rotation can be


@dataclass
class Frames:
    """The clips' frames end to end (canonical scale, floor at z = 0)."""

    pelvis_pos: np.ndarray  # (T, 3)
    pelvis_rot: np.ndarray  # (T, 3, 3)
    leaves: np.ndarray  # (copies, T, 60): clean, then with tracker noise
    feet_pos: np.ndarray  # (T, 2, 3) in the world, for occluded samples near the true foot
    pose: np.ndarray  # (T, 126) local rotations of joints 1..21 in 6D
    starts: np.ndarray  # first frames of the windows that stay within one clip


def clip_frames(motion, copies: int, rng: np.random.Generator):
    floor = estimate_floor(motion.positions)
    pos = (motion.positions[:, INPUT_JOINTS] - [0.0, 0.0, floor]) * body_scale(motion.skeleton)
    rot = motion.global_rotations[:, INPUT_JOINTS]
    leaves = [leaf_features(pos[:, 0], rot[:, 0], pos[:, 1:], rot[:, 1:])]
    T = len(motion)
    for _ in range(copies):
        noisy = pos + rng.normal(0.0, LOBSTR_NOISE.position_std, size=pos.shape)
        turned = _random_rotations(rng, T * 6, LOBSTR_NOISE.rotation_max_deg).as_matrix().reshape(T, 6, 3, 3) @ rot
        leaves.append(leaf_features(noisy[:, 0], turned[:, 0], noisy[:, 1:], turned[:, 1:]))
    local = motion.local_rotations[:, 1:]
    return (
        pos[:, 0],
        rot[:, 0],
        np.stack(leaves),
        pos[:, [1 + f for f in FOOT_LEAVES]],
        matrix_to_6d(local).reshape(T, -1),
    )


def load_frames(mocap_root: Path, split: str, config: DtpConfig, rng, limit: int | None = None) -> Frames:
    augmentation = Augmentation.parse(config.augment, config.variants) if split == "train" else NO_AUGMENTATION
    parts, starts, offset = [], [], 0
    motions = [load_clip(clip, config.fps) for clip in split_clips(mocap_root, split, limit)]
    for motion in augmented(motions, augmentation, rng):
        parts.append(clip_frames(motion, 1 if split == "train" else 0, rng))
        T = len(motion)
        if config.window <= T:
            starts.append(offset + np.arange(T - config.window + 1))
        offset += T
    pelvis_pos, pelvis_rot, leaves, feet_pos, pose = (
        np.concatenate([p[k] for p in parts], axis=1 if k == 2 else 0).astype(np.float32) for k in range(5)
    )
    return Frames(pelvis_pos, pelvis_rot, leaves, feet_pos, pose, np.concatenate(starts))


def occlude(
    leaves: np.ndarray,
    pelvis_pos: np.ndarray,
    pelvis_rot: np.ndarray,
    feet_pos: np.ndarray,
    share: float,
    leg: float,
    rng: np.random.Generator,
) -> np.ndarray:
    """Windows' leaf features (B, W, 60) with, in `share` of the windows, one or both feet
    occluded from a random frame on (to the window's end, or for a random stretch)."""
    leaves = leaves.copy()
    B, W = leaves.shape[:2]
    for b in np.flatnonzero(rng.random(B) < share):
        start = int(rng.integers(W))
        end = W if rng.random() < 0.7 else int(rng.integers(start + 1, W + 1))
        frames = np.arange(start, end)
        n = len(frames)
        for foot in [[0], [1], [0, 1]][rng.integers(3)]:
            if rng.random() < 0.5:  # fully occluded: the origin, the identity (after calibration)
                pos = np.tile(rng.normal(0.0, 0.05, 3), (n, 1))
                rot = np.tile(_random_rotations(rng, 1, MOUNTING_RESIDUAL_DEG).as_matrix(), (n, 1, 1))
            else:  # partly: anywhere within a leg's length, any rotation
                direction = rng.normal(size=(n, 3))
                direction /= np.linalg.norm(direction, axis=1, keepdims=True)
                pos = feet_pos[b, frames, foot] + direction * rng.uniform(0.0, leg, (n, 1))
                rot = Rotation.random(n, random_state=rng).as_matrix()
            rt = np.swapaxes(pelvis_rot[b, frames], -1, -2)
            k = FOOT_LEAVES[foot] * 12
            leaves[b, frames, k : k + 3] = np.einsum("tij,tj->ti", rt, pos - pelvis_pos[b, frames])
            leaves[b, frames, k + 3 : k + 12] = (rt @ rot).reshape(n, 9)
    return leaves


class WindowSampler:
    def __init__(self, frames: Frames, config: DtpConfig) -> None:
        self.f, self.config = frames, config
        self.leg = Skeleton.canonical().leg_length()

    def sample(
        self, batch: int, rng: np.random.Generator, occluded_share: float = 0.0, clean: bool = False
    ) -> dict[str, torch.Tensor]:
        f, W = self.f, self.config.window
        idx = rng.choice(f.starts, size=batch)[:, None] + np.arange(W)
        copy = np.zeros((batch, 1), int) if clean else rng.integers(0, f.leaves.shape[0], size=(batch, 1))
        leaves = f.leaves[copy, idx]
        if occluded_share:
            leaves = occlude(
                leaves, f.pelvis_pos[idx], f.pelvis_rot[idx], f.feet_pos[idx], occluded_share, self.leg, rng
            )
        x = window_features(f.pelvis_pos[idx], f.pelvis_rot[idx], leaves, W - 1 - self.config.future)
        return {
            "x": torch.from_numpy(x.astype(np.float32)),
            "pose": torch.from_numpy(f.pose[idx]),
            "pelvis_rot": torch.from_numpy(f.pelvis_rot[idx]),
        }


@torch.no_grad()
def validate(net: DtpNet, batches: list[dict[str, torch.Tensor]], offsets: torch.Tensor) -> dict[str, float]:
    """Joint position and rotation error of each window's current frame (the token a stream
    reads), on fixed validation windows: clean and with feet occluded."""
    out = {}
    q = net.config.past
    for name, windows in zip(("clean", "occluded"), batches, strict=True):
        pose, target = net(windows["x"])[:, q], windows["pose"][:, q]
        err = (body_positions(pose, offsets) - body_positions(target, offsets)).norm(dim=-1)
        angle = roma.rotmat_geodesic_distance(
            sixd_to_matrix(pose.unflatten(-1, (-1, 6))), sixd_to_matrix(target.unflatten(-1, (-1, 6)))
        )
        out[f"{name}_mpjpe_cm"] = float(err.mean() * 100)
        out[f"{name}_mpjre_deg"] = float(torch.rad2deg(angle).mean())
    return out


def export_onnx(net: DtpNet, path: Path, metadata: dict) -> None:
    x = torch.zeros(1, net.config.window, net.mean.numel())
    export(
        net,
        (x,),
        path,
        ["window"],
        ["pose_6d"],
        metadata,
        {"window": {0: "batch", 1: "frames"}, "pose_6d": {0: "batch", 1: "frames"}},
    )


def pretrained_path(out: Path) -> Path:
    """Where the model before occlusion fine-tuning is kept: dtp.onnx -> dtp.pretrained.onnx."""
    return out.with_name(out.stem + ".pretrained.onnx")


def _log_stage(log: Callable[[str], None], stage: str, message: str) -> None:
    log(f"{stage}: {message}")


def train(config: DtpConfig, run: TrainRun) -> dict:
    """Pre-train, export the pre-trained model, fine-tune on occluded feet, export out (an
    .onnx path) and return what the model card reports."""
    held_out = held_out_split(config.select_on)
    rng = run.start()
    out = run.out
    t0 = time.perf_counter()
    train_frames = load_frames(run.mocap_root, "train", config, rng, run.limit)
    val_frames = load_frames(run.mocap_root, held_out, config, rng, run.limit)
    sampler, val_sampler = WindowSampler(train_frames, config), WindowSampler(val_frames, config)
    n_val = min(2048, 64 * config.batch)  # fixed validation windows (tiny configurations: fewer)
    val_batches = [
        val_sampler.sample(n_val, np.random.default_rng(run.seed + 1), clean=True),
        val_sampler.sample(n_val, np.random.default_rng(run.seed + 1), occluded_share=1.0, clean=True),
    ]
    run.log(
        f"data: {len(train_frames.pose)} train frames x {train_frames.leaves.shape[0]} copies, "
        f"{len(val_frames.pose)} {held_out} frames, {time.perf_counter() - t0:.0f} s"
    )
    net = DtpNet(config)
    x = sampler.sample(min(4096, 64 * config.batch), rng, clean=True)["x"].flatten(0, 1)
    net.mean.copy_(x.mean(0))
    net.std.copy_(x.std(0) + 1e-3)  # some features are constant (a rotation's fixed entries)
    offsets = torch.tensor(Skeleton.canonical().offsets, dtype=torch.float32)
    stages = {}
    for stage, share, lr, steps, minutes, score in (
        ("pretrain", 0.0, config.lr, config.steps, config.minutes, lambda v: v["clean_mpjpe_cm"]),
        (
            "finetune",
            config.occluded_share,
            config.finetune_lr,
            config.finetune_steps,
            config.finetune_minutes,
            lambda v: (v["clean_mpjpe_cm"] + v["occluded_mpjpe_cm"]) / 2,
        ),
    ):
        opt = torch.optim.Adam(net.parameters(), lr=lr)
        sched = torch.optim.lr_scheduler.StepLR(opt, max(1, config.lr_half_every // config.steps_per_check), 0.5)

        def step(share=share, opt=opt):
            terms = losses(net, sampler.sample(config.batch, rng, share), offsets)
            return terms["total"], {k: v.item() for k, v in terms.items()}

        # each stage keeps its checkpoint, and a finished stage its report, until both are done:
        # --resume after the pre-training has finished goes straight on with the fine-tuning
        stage_checkpoint = run.checkpoint.with_name(f"{run.checkpoint.stem}.{stage}.npz") if run.checkpoint else None
        finished = stage_checkpoint.with_suffix(".json") if stage_checkpoint else None
        if run.resume and stage_checkpoint and finished and finished.is_file() and stage_checkpoint.is_file():
            stages[stage] = json.loads(finished.read_text())
            load_best(net, stage_checkpoint)
            run.log(f"{stage}: finished before, its best weights taken from {stage_checkpoint}")
            continue
        fitted = fit(
            net,
            opt,
            step,
            lambda: validate(net, val_batches, offsets),
            score,
            steps=steps,
            minutes=minutes,
            check_every=config.steps_per_check,
            schedule=sched,
            rng=rng,
            run=replace(run, checkpoint=stage_checkpoint, log=partial(_log_stage, run.log, stage)),
        )
        stages[stage] = {
            "steps": fitted.steps,
            "minutes": fitted.minutes,
            "validation": fitted.validation,
            "history": fitted.history,
        }
        metadata = {
            "method": "dtp",
            "config": config.to_dict(),
            "feature_version": 1,
            "stage": stage,
            "canonical_leg_length": Skeleton.canonical().leg_length(),
            "trained_steps": fitted.steps,
            "validation": fitted.validation,
        }
        export_onnx(net, pretrained_path(out) if stage == "pretrain" else out, metadata)
        if finished is not None:
            finished.write_text(json.dumps(stages[stage]))
    for path in (
        [
            run.checkpoint.with_name(f"{run.checkpoint.stem}.{stage}{suffix}")
            for stage in stages
            for suffix in (".npz", ".json")
        ]
        if run.checkpoint
        else []
    ):
        path.unlink(missing_ok=True)
    return {
        "config": config.to_dict(),
        "stages": stages,
        "validation": stages["finetune"]["validation"],
        "steps": sum(s["steps"] for s in stages.values()),
        "minutes": sum(s["minutes"] for s in stages.values()),
        "train_clips": len(split_clips(run.mocap_root, "train", run.limit)),
        "augment": config.augment,
        "train_frames": int(len(train_frames.pose)),
        "validation_frames": int(len(val_frames.pose)),
        **machine(),
    }
