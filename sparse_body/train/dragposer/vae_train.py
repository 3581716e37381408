"""`sparse-body train dragposer`: CMU train split -> pose VAE (encoder and decoder ONNX) + model card.

Every frame of every train clip is one example, put on the canonical body (rotations only
matter to the VAE; the root keeps its height above the floor, scaled by leg length) and
paired with its successor for the continuity loss. The best validation reconstruction is
exported.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch

from ...core.contacts import estimate_floor
from ...core.kinematics import forward_kinematics
from ...core.rotations import angle_between, matrix_to_6d
from ...core.skeleton import Skeleton, body_scale
from ...data.catalog import load_clip, split_clips
from ...methods.dragposer.pose import dual_quaternions, split_heading
from ...train.augment import NO_AUGMENTATION, Augmentation, augmented
from ...train.harness import TrainRun, export_onnx, fit
from ...train.torch_body import sixd_to_matrix
from .vae_model import Decoder, Encoder, PoseVae, VaeConfig, losses


def clip_arrays(motion, offsets: np.ndarray):
    """(dual quaternions (T, 176), heading-free 6D pose (T, 132)) on the canonical body."""
    local, _ = split_heading(motion.local_rotations)
    height = (motion.root_positions[:, 2] - estimate_floor(motion.positions)) * body_scale(motion.skeleton)
    dq = dual_quaternions(local, height, offsets)
    return dq.astype(np.float32), matrix_to_6d(local).reshape(len(motion), -1).astype(np.float32)


def load_frames(
    mocap_root: Path,
    split: str,
    fps: float = 60.0,
    limit: int | None = None,
    augmentation: Augmentation = NO_AUGMENTATION,
    rng=None,
):
    offsets = Skeleton.canonical().offsets
    return [
        clip_arrays(m, offsets)
        for m in augmented([load_clip(c, fps) for c in split_clips(mocap_root, split, limit)], augmentation, rng)
    ]


@torch.no_grad()
def validate(vae: PoseVae, clips, offsets: torch.Tensor) -> dict[str, float]:
    """Encode-decode every validation frame: joint position (cm) and rotation (deg) errors."""
    dq = torch.from_numpy(np.concatenate([c[0] for c in clips]))
    pose = torch.from_numpy(np.concatenate([c[1] for c in clips]))
    rec = vae.decode(vae.encode(dq)[0])
    r_hat, r = sixd_to_matrix(rec.unflatten(-1, (22, 6))), sixd_to_matrix(pose.unflatten(-1, (22, 6)))
    _, p_hat = forward_kinematics(r_hat.numpy(), np.zeros((len(dq), 3)), offsets.numpy())
    _, p = forward_kinematics(r.numpy(), np.zeros((len(dq), 3)), offsets.numpy())
    return {
        "position_error_cm": float(np.linalg.norm(p_hat - p, axis=-1).mean() * 100),
        "rotation_error_deg": float(np.degrees(angle_between(r_hat.numpy(), r.numpy())).mean()),
    }


def export(vae: PoseVae, out_dir: Path, metadata: dict) -> None:
    for name, module, example, inp, outp in [
        ("dragposer_decoder.onnx", Decoder(vae), torch.zeros(1, vae.config.latent), "latent", "local_rotations"),
        ("dragposer_encoder.onnx", Encoder(vae), torch.zeros(1, 176), "dual_quaternions", "latent"),
    ]:
        export_onnx(
            module, (example,), out_dir / name, [inp], [outp], metadata, {inp: {0: "batch"}, outp: {0: "batch"}}
        )


def train_vae(config: VaeConfig, run: TrainRun) -> dict:
    rng = run.start()
    out_dir = run.out
    t0 = time.perf_counter()
    train_clips = load_frames(
        run.mocap_root,
        "train",
        limit=run.limit,
        augmentation=Augmentation.parse(config.augment, config.variants),
        rng=rng,
    )
    val_clips = load_frames(run.mocap_root, "validation", limit=run.limit)
    dq = np.concatenate([c[0] for c in train_clips])
    pose = np.concatenate([c[1] for c in train_clips])
    # an example is frame i with i+1 in the same clip
    firsts, offset = [], 0
    for c in train_clips:
        firsts.append(offset + np.arange(len(c[0]) - 1))
        offset += len(c[0])
    starts = np.concatenate(firsts)
    run.log(
        f"data: {len(train_clips)} train clips ({len(dq)} frames), {len(val_clips)} validation clips, "
        f"{time.perf_counter() - t0:.0f} s"
    )
    offsets = torch.tensor(Skeleton.canonical().offsets, dtype=torch.float32)
    vae = PoseVae(config)
    opt = torch.optim.AdamW(vae.parameters(), lr=config.lr, weight_decay=config.weight_decay)

    def step():
        idx = rng.choice(starts, size=config.batch)[:, None] + np.arange(2)
        terms = losses(vae, {"dq": torch.from_numpy(dq[idx]), "pose": torch.from_numpy(pose[idx])}, offsets)
        return terms["total"], {k: v.item() for k, v in terms.items()}

    fitted = fit(
        vae,
        opt,
        step,
        lambda: validate(vae, val_clips, offsets),
        lambda val: val["position_error_cm"],
        steps=config.steps,
        minutes=config.minutes,
        check_every=config.steps_per_check,
        rng=rng,
        run=run,
    )
    export(
        vae,
        out_dir,
        {"method": "dragposer", "part": "pose_vae", "config": config.to_dict(), "validation": fitted.validation},
    )
    return fitted.report(
        config,
        run,
        train_sequences=len(train_clips),
        train_frames=int(len(dq)),
        validation_clips=len(val_clips),
    )
