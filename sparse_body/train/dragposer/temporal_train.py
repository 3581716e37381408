"""`sparse-body train dragposer --part temporal`: the temporal predictor, on latents that the
shipped pose VAE's encoder gives for the CMU train split.

Each train clip is put on the canonical body, encoded frame by frame, and read every n
frames from each of its n phases. Inputs may carry the paper's limb noise: with
`limb_noise` probability per limb and step, every joint of the limb is turned by Gaussian
noise (`limb_noise_deg` per axis) before encoding. The paper adds Gaussian noise to the
latent per limb; our MLP latent has no per-limb part, so the noise is put on the limb in pose
space. Targets are the clean latents. The `small` configuration trains without the noise
(it made validation worse on our 245 clips; see the model card). The best validation MSE is exported as
`dragposer_temporal.onnx`.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from ...core.contacts import estimate_floor
from ...core.skeleton import JOINT_INDEX, Skeleton, body_scale
from ...data.catalog import load_clip, split_clips
from ...methods.dragposer.estimator import PoseVaeRuntime
from ...methods.dragposer.pose import HEIGHT_JOINTS, LIMBS, split_heading, temporal_context
from ...train.augment import NO_AUGMENTATION, Augmentation, augmented
from ...train.harness import TrainRun, export_onnx, fit
from .temporal_model import TemporalConfig, TemporalPredictor, loss


def clip_arrays(motion) -> dict[str, np.ndarray]:
    """Heading-free rotations and the context's raw material, on the canonical body."""
    free, yaw = split_heading(motion.local_rotations)
    scale = body_scale(motion.skeleton)
    floor = estimate_floor(motion.positions)
    heights = (motion.positions[:, [JOINT_INDEX[j] for j in HEIGHT_JOINTS], 2] - floor) * scale
    return {"local": free.astype(np.float32), "yaw": yaw, "root": motion.root_positions * scale, "heights": heights}


def limb_noise(local: np.ndarray, probability: float, degrees: float, rng) -> np.ndarray:
    """A copy of local (T, 22, 3, 3) in which each limb, with `probability` per frame, has
    every joint turned by Gaussian noise (`degrees` standard deviation per axis)."""
    out = local.copy()
    for joints in LIMBS.values():
        idx = np.array([JOINT_INDEX[j] for j in joints])
        hit = np.flatnonzero(rng.random(len(local)) < probability)
        turn = Rotation.from_rotvec(rng.normal(0, np.radians(degrees), (len(hit) * len(idx), 3))).as_matrix()
        out[hit[:, None], idx] = out[hit[:, None], idx] @ turn.reshape(len(hit), len(idx), 3, 3).astype(out.dtype)
    return out


def sequences(clips, vae, config: TemporalConfig, rng, noisy=True, phases=None):
    """Subsampled sequences flattened into one array each, and the valid window starts."""
    offsets = Skeleton.canonical().offsets
    length = config.past + config.future + 1
    clean, copies, context, starts, offset = [], [], [], [], 0
    for c in clips:
        height = c["root"][:, 2]
        z = vae.encode_free(c["local"], height, offsets)
        zn = (
            [
                vae.encode_free(limb_noise(c["local"], config.limb_noise, config.limb_noise_deg, rng), height, offsets)
                for _ in range(config.noisy_copies)
            ]
            if noisy and config.limb_noise > 0
            else [z]
        )
        for phase in phases if phases is not None else range(config.every):
            idx = np.arange(phase, len(z), config.every)
            if len(idx) < length:
                continue
            clean.append(z[idx])
            copies.append(np.stack([n[idx] for n in zn]))
            context.append(temporal_context(c["root"][idx], c["yaw"][idx], c["heights"][idx]))
            starts.append(offset + np.arange(len(idx) - length + 1))
            offset += len(idx)
    return {
        "clean": np.concatenate(clean).astype(np.float32),
        "noisy": np.concatenate(copies, axis=1).astype(np.float32),
        "context": np.concatenate(context).astype(np.float32),
        "starts": np.concatenate(starts),
    }


def batch(data, starts: np.ndarray, config: TemporalConfig, rng=None) -> dict[str, torch.Tensor]:
    p, f = config.past, config.future
    idx = starts[:, None] + np.arange(p + f + 1)
    # without rng the clean frames; with it, each step from a random noisy copy
    inputs = data["clean"][idx] if rng is None else data["noisy"][rng.integers(len(data["noisy"]), size=idx.shape), idx]
    return {
        "past": torch.from_numpy(inputs[:, :p]),
        "context": torch.from_numpy(data["context"][idx[:, :p]]),
        "future": torch.from_numpy(inputs[:, p : p + f]),
        "target": torch.from_numpy(data["clean"][idx[:, p + 1 :]]),
    }


@torch.no_grad()
def validate(model: TemporalPredictor, data, config: TemporalConfig) -> dict[str, float]:
    """Teacher-forced MSE on clean inputs, its first position (what W_f = 1 uses), and two
    baselines a predictor has to beat: holding the newest latent (the optimiser's prior
    without the predictor) and, for the next step, carrying on half the last step's change."""
    model.eval()
    starts = data["starts"][:: max(1, config.future // 2)]
    errors, hold, extrapolate = [], [], []
    for i in range(0, len(starts), 1024):
        b = batch(data, starts[i : i + 1024], config)
        errors.append(((model(b["past"], b["context"], b["future"]) - b["target"]) ** 2).mean(-1))
        hold.append(((b["future"] - b["target"]) ** 2).mean(-1))
        newest = b["future"][:, 0]
        extrapolate.append(((newest + 0.5 * (newest - b["past"][:, -1]) - b["target"][:, 0]) ** 2).mean(-1))
    error, held = torch.cat(errors), torch.cat(hold)
    return {
        "mse": error.mean().item(),
        "mse_next": error[:, 0].mean().item(),
        "hold_mse": held.mean().item(),
        "hold_mse_next": held[:, 0].mean().item(),
        "extrapolate_mse_next": torch.cat(extrapolate).mean().item(),
    }


def export(model: TemporalPredictor, path: Path, metadata: dict) -> None:
    c = model.config
    example = (torch.zeros(1, c.past, c.latent), torch.zeros(1, c.past, c.context), torch.zeros(1, c.future, c.latent))
    export_onnx(
        model, example, path, ["past_latents", "past_context", "future_latents"], ["predicted_latents"], metadata
    )


def load_clips(
    mocap_root: Path,
    split: str,
    limit: int | None,
    fps: float = 60.0,
    augmentation: Augmentation = NO_AUGMENTATION,
    rng=None,
):
    return [
        clip_arrays(m)
        for m in augmented([load_clip(c, fps) for c in split_clips(mocap_root, split, limit)], augmentation, rng)
    ]


def train_temporal(config: TemporalConfig, run: TrainRun) -> dict:
    """Needs the pose VAE in out_dir (dragposer_encoder.onnx): the predictor lives in its space."""
    rng = run.start()
    out_dir = run.out
    t0 = time.perf_counter()
    vae = PoseVaeRuntime(out_dir, threads=torch.get_num_threads())
    augmentation = Augmentation.parse(config.augment, config.variants)
    train_clips = load_clips(run.mocap_root, "train", run.limit, augmentation=augmentation, rng=rng)
    val_clips = load_clips(run.mocap_root, "validation", run.limit)
    train = sequences(train_clips, vae, config, rng)
    val = sequences(val_clips, vae, config, rng, noisy=False, phases=[0])
    run.log(
        f"data: {len(train_clips)} train clips, {len(train['starts'])} windows; {len(val['starts'])} validation "
        f"windows; {time.perf_counter() - t0:.0f} s"
    )
    model = TemporalPredictor(config)
    model.context_mean.copy_(torch.from_numpy(train["context"].mean(0)))
    model.context_std.copy_(torch.from_numpy(train["context"].std(0)).clamp_min(1e-3))
    opt = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)

    def step():
        terms = loss(model, batch(train, rng.choice(train["starts"], size=config.batch), config, rng))
        return terms, {"loss": terms.item()}

    fitted = fit(
        model,
        opt,
        step,
        lambda: validate(model, val, config),
        lambda v: v["mse"],
        steps=config.steps,
        minutes=config.minutes,
        check_every=config.steps_per_check,
        rng=rng,
        run=run,
    )
    export(
        model,
        Path(out_dir) / "dragposer_temporal.onnx",
        {
            "method": "dragposer",
            "part": "temporal_predictor",
            "config": config.to_dict(),
            "validation": fitted.validation,
        },
    )
    return fitted.report(
        config,
        run,
        train_sequences=len(train_clips),
        train_windows=int(len(train["starts"])),
        validation_clips=len(val_clips),
        parameters=sum(p.numel() for p in model.parameters()),
    )
