"""`sparse-body train lobstr`: CMU train split -> LoBSTr ONNX model + model card, one command.

Every clip is put on the canonical body (positions scaled by leg length, floor at z = 0),
its four tracked joints become input vectors (clean, plus noisy copies with the paper's
tracker noise), and 90-frame chunks are drawn with probability proportional to clip length
(the paper's sampling). The checkpoint with the best validation leg rotation and toe
position is exported (`select_on`: on all validation clips, or on the selection's, the kinds of
motion no train clip has).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ...core.contacts import contact_labels, estimate_floor
from ...core.rotations import angle_between, heading
from ...core.skeleton import Skeleton, body_scale
from ...data.catalog import load_clip, split_clips
from ...data.virtual_trackers import LOBSTR_NOISE, _random_rotations
from ...methods.lobstr.features import (
    INPUT_JOINTS,
    LEG_JOINTS,
    OUTPUTS,
    UPPER_JOINTS,
    leg_targets,
    reference_frames,
    sequence_features,
    upper_targets,
)
from ...train.augment import NO_AUGMENTATION, Augmentation, augmented
from ...train.harness import TrainRun, fit, held_out_split
from ...train.harness import export_onnx as export
from ...train.torch_body import sixd_to_matrix
from .model import LobstrConfig, LobstrNet, LobstrStep, leg_positions, losses


@dataclass
class ClipTensors:
    x: np.ndarray  # (copies, T, 37 or 70) float32
    legs: np.ndarray  # (T, 48)
    upper: np.ndarray  # (T, 78), or (T, 0) without the learned upper body
    pelvis_in_ref: np.ndarray  # (T, 3, 3)
    yaw: np.ndarray  # (T,)
    contact: np.ndarray  # (T, 2)


def clip_tensors(
    motion, copies: int, rng: np.random.Generator, learned_upper: bool = False, mounting: tuple[float, float] = (0, 0)
) -> ClipTensors:
    """A clip's inputs (clean, then `copies` noisy ones) and targets; mounting: (degrees,
    metres) of each noisy copy's constant mounting error per site (LobstrConfig)."""
    floor = estimate_floor(motion.positions)
    scale = body_scale(motion.skeleton)
    glob, local = motion.global_rotations, motion.local_rotations
    pos = (motion.positions[:, INPUT_JOINTS] - [0.0, 0.0, floor]) * scale
    rot = glob[:, INPUT_JOINTS]
    xs = [sequence_features(pos, rot, pose=learned_upper)]
    T = len(motion)
    for _ in range(copies):
        noisy_pos = pos + rng.normal(0.0, LOBSTR_NOISE.position_std, size=pos.shape)
        r = _random_rotations(rng, T * 4, LOBSTR_NOISE.rotation_max_deg).as_matrix().reshape(T, 4, 3, 3)
        worn = rot
        if mounting[0] or mounting[1]:  # a tracker at m in its site's frame turned by M: R M at p + R m
            turn = _random_rotations(rng, 4, mounting[0]).as_matrix()
            off = rng.normal(0.0, mounting[1], size=(4, 3)) * scale
            noisy_pos = noisy_pos + np.einsum("tsij,sj->tsi", rot, off)
            worn = rot @ turn
        xs.append(sequence_features(noisy_pos, r @ worn, pose=learned_upper))
    ref = reference_frames(glob[:, 0])
    upper = upper_targets(local) if learned_upper else np.zeros((T, 0))
    return ClipTensors(
        np.stack(xs).astype(np.float32),
        leg_targets(glob, local).astype(np.float32),
        upper.astype(np.float32),
        (np.swapaxes(ref, -1, -2) @ glob[:, 0]).astype(np.float32),
        heading(glob[:, 0]).astype(np.float32),
        contact_labels(motion.positions, motion.fps).astype(np.float32),
    )


class ChunkSampler:
    """Random chunks of the concatenated clips, never crossing a clip boundary."""

    def __init__(self, clips: list[ClipTensors], chunk: int) -> None:
        self.x = np.concatenate([c.x for c in clips], axis=1)
        self.legs = np.concatenate([c.legs for c in clips])
        self.upper = np.concatenate([c.upper for c in clips])
        self.pelvis = np.concatenate([c.pelvis_in_ref for c in clips])
        self.yaw = np.concatenate([c.yaw for c in clips])
        self.contact = np.concatenate([c.contact for c in clips])
        starts, offset = [], 0
        for c in clips:
            T = len(c.legs)
            if chunk <= T:
                starts.append(offset + np.arange(T - chunk + 1))
            offset += T
        self.starts = np.concatenate(starts)
        self.chunk = chunk

    def sample(self, batch: int, rng: np.random.Generator) -> dict[str, torch.Tensor]:
        idx = rng.choice(self.starts, size=batch)[:, None] + np.arange(self.chunk)
        copy = rng.integers(0, self.x.shape[0], size=batch)[:, None]
        return {
            "x": torch.from_numpy(self.x[copy, idx]),
            "legs": torch.from_numpy(self.legs[idx]),
            "upper": torch.from_numpy(self.upper[idx]),
            "pelvis_in_ref": torch.from_numpy(self.pelvis[idx]),
            "yaw": torch.from_numpy(self.yaw[idx]),
            "contact": torch.from_numpy(self.contact[idx]),
        }


@torch.no_grad()
def validate(net: LobstrNet, clips: list[ClipTensors], offsets: torch.Tensor) -> dict[str, float]:
    """The paper's three measures on whole clips (clean input, state carried from frame 0);
    with the learned upper body, its joints' local rotation error too."""
    acc, rot_err, toe_err, upper_err, n = 0.0, 0.0, 0.0, 0.0, 0
    for c in clips:
        out, logits, _ = net(torch.from_numpy(c.x[:1]))
        pose, target = out[0, :, :OUTPUTS], torch.from_numpy(c.legs)
        if net.config.learned_upper:
            pu = sixd_to_matrix(out[0, :, OUTPUTS:].unflatten(-1, (len(UPPER_JOINTS), 6))).numpy()
            gu = sixd_to_matrix(torch.from_numpy(c.upper).unflatten(-1, (len(UPPER_JOINTS), 6))).numpy()
            upper_err += np.degrees(angle_between(pu, gu)).mean(-1).sum()
        acc += (logits[0].argmax(-1) == torch.from_numpy(c.contact).long()).float().mean(-1).sum().item()
        pr = sixd_to_matrix(pose.unflatten(-1, (len(LEG_JOINTS), 6))).numpy()
        gt = sixd_to_matrix(target.unflatten(-1, (len(LEG_JOINTS), 6))).numpy()
        rot_err += np.degrees(angle_between(pr, gt)).mean(-1).sum()
        pelvis = torch.from_numpy(c.pelvis_in_ref)
        toes = [LEG_JOINTS.index(j) for j in LEG_JOINTS[-2:]]
        d = leg_positions(pose, pelvis, offsets)[:, toes] - leg_positions(target, pelvis, offsets)[:, toes]
        toe_err += d.norm(dim=-1).mean(-1).sum().item() * 100
        n += len(c.legs)
    scores = {
        "contact_accuracy_pct": float(100 * acc / n),
        "lower_rot_error_deg": float(rot_err / n),
        "toe_error_cm": float(toe_err / n),
    }
    if net.config.learned_upper:
        scores["upper_rot_error_deg"] = float(upper_err / n)
    return scores


def export_onnx(net: LobstrNet, path: Path, metadata: dict) -> None:
    x, h = torch.zeros(1, net.mean.numel()), torch.zeros(1, 1, net.config.hidden)
    export(
        LobstrStep(net),
        (x, h),
        path,
        ["features", "state"],
        ["pose_6d", "contact_probability", "next_state"],
        metadata,
        {
            "features": {0: "batch"},
            "state": {1: "batch"},
            "pose_6d": {0: "batch"},
            "contact_probability": {0: "batch"},
            "next_state": {1: "batch"},
        },
    )


def load_clips(mocap_root: Path, split: str, config: LobstrConfig, rng, limit: int | None = None):
    """The split's clips as tensors; train clips with their augmented variants and noisy copies."""
    augmentation = Augmentation.parse(config.augment, config.variants) if split == "train" else NO_AUGMENTATION
    return [
        clip_tensors(
            m,
            config.noise_copies if split == "train" else 0,
            rng,
            config.learned_upper,
            (config.mounting_deg, config.mounting_std),
        )
        for m in augmented([load_clip(c, config.fps) for c in split_clips(mocap_root, split, limit)], augmentation, rng)
    ]


def train(config: LobstrConfig, run: TrainRun) -> dict:
    """Train, export out (an .onnx path) and return what the model card reports."""
    held_out = held_out_split(config.select_on)
    rng = run.start()
    out = run.out
    t0 = time.perf_counter()
    train_clips = load_clips(run.mocap_root, "train", config, rng, run.limit)
    val_clips = load_clips(run.mocap_root, held_out, config, rng, run.limit)
    if not val_clips:
        raise ValueError(f"no {config.select_on} clips to keep the best weights by (--set select_on=validation)")
    sampler = ChunkSampler(train_clips, config.chunk)
    run.log(
        f"data: {len(train_clips)} train clips ({len(sampler.legs)} frames x {sampler.x.shape[0]} copies), "
        f"{len(val_clips)} {config.select_on} clips, {time.perf_counter() - t0:.0f} s"
    )
    net = LobstrNet(config)
    clean = sampler.x[0]
    net.mean.copy_(torch.from_numpy(clean.mean(0)))
    net.std.copy_(torch.from_numpy(clean.std(0) + 1e-6))
    offsets = torch.tensor(Skeleton.canonical().offsets, dtype=torch.float32)
    # eps far below the default: the paper's contact weight (1e-6) makes the contact head's
    # gradients ~1e-8, where Adam's default eps would stall it.
    opt = torch.optim.AdamW(net.parameters(), lr=config.lr, eps=1e-12, weight_decay=config.weight_decay)
    sched = torch.optim.lr_scheduler.ExponentialLR(opt, config.lr_decay)

    def step():
        terms = losses(net, sampler.sample(config.batch, rng), offsets)
        return terms["total"], {
            "train_loss": terms["total"].item(),
            "pose": terms["pose"].item(),
            "upper": terms["upper"].item(),
            "fk": terms["fk"].item(),
            "velocity": terms["velocity"].item(),
            "contact": terms["contact"].item(),
        }

    # the legs pick the checkpoint: with the paper's contact weight the contact head learns
    # last, and its early majority-class accuracy chose a 100-step model once
    fitted = fit(
        net,
        opt,
        step,
        lambda: validate(net, val_clips, offsets),
        lambda val: (val["lower_rot_error_deg"] + val["toe_error_cm"] + val.get("upper_rot_error_deg", 0.0)) / 10,
        steps=config.steps,
        minutes=config.minutes,
        check_every=config.steps_per_epoch,
        schedule=sched,
        rng=rng,
        run=run,
    )
    metadata = {
        "method": "lobstr",
        "config": config.to_dict(),
        "feature_version": 2 if config.learned_upper else 1,
        "canonical_leg_length": Skeleton.canonical().leg_length(),
        "trained_steps": fitted.steps,
        "validation": fitted.validation,
    }
    export_onnx(net, out, metadata)
    return fitted.report(
        config,
        run,
        train_sequences=len(train_clips),
        train_frames=int(len(sampler.legs)),
        validation_clips=len(val_clips),
    )
