"""`sparse-body train dragposer --part tracker_prior`: the GRU that guesses DragPoser's latent
from the trackers' recent motion (methods/dragposer/tracker_prior.py says why).

Targets are the latents the shipped pose VAE's encoder gives for each train frame on the
canonical body, so the prior lives in that VAE's space and is trained after it. Inputs are
the six sites' joints with tracker noise (noisy copies beside the clean one), and every
90-frame chunk sees one sensor set (three-, four- or six-point: the absent sites' blocks are
zeros). The loss is the latent's squared error; `w_positions` adds that of the joint positions
its decoding gives (the shipped decoder, frozen, in torch), meant to weigh latents by the poses
they make, but it made DragPoser worse on the validation people (model card), so it is off.
The checkpoint with the lowest validation latent error, averaged over the three sets, is
exported; the decoded guess's joint errors are reported beside it. Inputs are scaled, not
centred, so that an absent site stays zero.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import torch
from torch import nn

from ...core.contacts import estimate_floor
from ...core.kinematics import forward_kinematics
from ...core.sensors import SITE_JOINTS
from ...core.skeleton import JOINT_INDEX, LOWER_BODY, Skeleton, body_scale, joint_indices
from ...data.catalog import load_clip, split_clips
from ...data.virtual_trackers import _random_rotations
from ...methods.dragposer.estimator import PoseVaeRuntime
from ...methods.dragposer.pose import LATENT, split_heading
from ...methods.dragposer.tracker_prior import FEATURES, FILE, SITE_FEATURES, SITES, sequence_features
from ...train.augment import NO_AUGMENTATION, Augmentation, augmented
from ...train.harness import TrainRun, export_onnx, fit
from ...train.presets import Presets
from ...train.torch_body import forward_kinematics as torch_fk
from .vae_model import Decoder, PoseVae, VaeConfig

JOINTS = [JOINT_INDEX[SITE_JOINTS[s]] for s in SITES]
SENSOR_SETS = {"three_point": SITES[:3], "four_point": SITES[:4], "six_point": SITES}


@dataclass
class TrackerPriorConfig(Presets):
    hidden: int = 256
    layers: int = 1
    dropout: float = 0.1  # on the GRU's output, in training only
    fps: float = 60.0
    chunk: int = 90
    burn_in: int = 30  # leading frames of a chunk without loss (the GRU warms up)
    batch: int = 64
    lr: float = 1e-3
    weight_decay: float = 1e-4
    w_latent: float = 1.0
    w_positions: float = 0.0  # on squared metres (100: as the VAE's FK term); off, see above
    noise_copies: int = 2
    position_noise: float = 0.01  # metres per axis: LoBSTr's tracker noise
    rotation_noise_deg: float = 5.0  # up to: tracker noise and what the calibration leaves
    augment: str = "mirror,speed,proportions"  # train/augment.py (all: splice too)
    variants: int = 2
    minutes: float = 0.0
    steps: int = 1_000_000
    steps_per_check: int = 200

    KIND = "tracker prior"
    PRESETS: ClassVar[dict[str, dict]] = {
        "small": {"minutes": 25.0},
        "paper": {"minutes": 25.0},  # the paper has no such part: trained as small
        "tiny": {
            "hidden": 8,
            "chunk": 20,
            "burn_in": 5,
            "batch": 4,
            "steps": 3,
            "steps_per_check": 1,
            "noise_copies": 1,
            "augment": "mirror",
            "variants": 1,
        },
    }

    def to_dict(self) -> dict:
        return asdict(self)


class TrackerPriorNet(nn.Module):
    scale: torch.Tensor  # a buffer (register_buffer), named for the type checker

    def __init__(self, config: TrackerPriorConfig) -> None:
        super().__init__()
        self.config = c = config
        self.register_buffer("scale", torch.ones(FEATURES))  # set from the training data
        self.gru = nn.GRU(FEATURES, c.hidden, c.layers, batch_first=True)
        self.dropout = nn.Dropout(c.dropout)
        self.out = nn.Linear(c.hidden, LATENT)

    def forward(self, x: torch.Tensor, state: torch.Tensor | None = None):
        """x (B, T, 79) -> latents (B, T, 24), state (layers, B, hidden)."""
        h, state = self.gru(x / self.scale, state)
        return self.out(self.dropout(h)), state


class TrackerPriorStep(nn.Module):
    """The exported graph: (features (B, 79), state) -> (latent (B, 24), next state)."""

    def __init__(self, net: TrackerPriorNet) -> None:
        super().__init__()
        self.net = net

    def forward(self, x: torch.Tensor, state: torch.Tensor):
        z, state = self.net(x[:, None], state)
        return z[:, 0], state


def frozen_decoder(model_dir: Path) -> Decoder:
    """The shipped pose VAE's decoder in torch, from its ONNX file's weights, frozen."""
    import onnx
    from onnx import numpy_helper

    graph = onnx.load(str(Path(model_dir) / "dragposer_decoder.onnx")).graph
    weights = {
        i.name.removeprefix("vae."): torch.from_numpy(numpy_helper.to_array(i).copy())
        for i in graph.initializer
        if i.name.startswith("vae.decoder.")
    }
    vae = PoseVae(VaeConfig(hidden=weights["decoder.0.weight"].shape[0]))
    missing = [k for k in vae.state_dict() if k.startswith("decoder.") and k not in weights]
    if missing:
        raise ValueError(f"{model_dir}/dragposer_decoder.onnx: no weights for {', '.join(missing)}")
    vae.load_state_dict(weights, strict=False)
    decoder = Decoder(vae).eval()
    decoder.requires_grad_(False)
    return decoder


def decoded_positions(decoder: Decoder, z: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
    """(..., 24) -> the decoded pose's joint positions relative to the root (..., 22, 3)."""
    rot = decoder(z.reshape(-1, LATENT))
    _, pos = torch_fk(rot, torch.zeros(rot.shape[0], 3), offsets)
    return pos.reshape(z.shape[:-1] + pos.shape[-2:])


def clip_tensors(motion, vae: PoseVaeRuntime, config: TrackerPriorConfig, rng, copies: int):
    """(features (1 + copies, T, 79) with every site present, target latents (T, 24), the
    pose's joint positions relative to the root on the canonical body without heading (T, 22, 3))."""
    scale = body_scale(motion.skeleton)
    floor = estimate_floor(motion.positions)
    free, _ = split_heading(motion.local_rotations)
    offsets = Skeleton.canonical().offsets
    z = vae.encode_free(free, (motion.root_positions[:, 2] - floor) * scale, offsets)
    _, body = forward_kinematics(free, np.zeros((len(motion), 3)), offsets)
    pos = (motion.positions[:, JOINTS] - [0.0, 0.0, floor]) * scale
    rot = motion.global_rotations[:, JOINTS]
    T, present = len(motion), np.ones((len(motion), len(SITES)), bool)
    xs = [sequence_features(pos, rot, present, config.fps)]
    for _ in range(copies):
        noisy = pos + rng.normal(0.0, config.position_noise * scale, pos.shape)
        turn = _random_rotations(rng, T * len(SITES), config.rotation_noise_deg).as_matrix()
        xs.append(sequence_features(noisy, turn.reshape(T, len(SITES), 3, 3) @ rot, present, config.fps))
    return np.stack(xs).astype(np.float32), z.astype(np.float32), body.astype(np.float32)


def site_mask(sites) -> np.ndarray:
    """(79,) ones where a sensor set's sites' inputs are (and the heading rate), zeros elsewhere."""
    mask = np.zeros(FEATURES, np.float32)
    for site in sites:
        s = SITES.index(site)
        mask[s * SITE_FEATURES : (s + 1) * SITE_FEATURES] = 1.0
    mask[-1] = 1.0
    return mask


MASKS = np.stack([site_mask(s) for s in SENSOR_SETS.values()])


def load_clips(mocap_root: Path, split: str, config: TrackerPriorConfig, vae, rng, limit: int | None = None):
    train = split == "train"
    augmentation = Augmentation.parse(config.augment, config.variants) if train else NO_AUGMENTATION
    return [
        clip_tensors(m, vae, config, rng, config.noise_copies if train else 0)
        for m in augmented([load_clip(c, config.fps) for c in split_clips(mocap_root, split, limit)], augmentation, rng)
    ]


LOWER = joint_indices(LOWER_BODY)


@torch.no_grad()
def validate(net: TrackerPriorNet, clips, decoder: Decoder, offsets: torch.Tensor) -> dict[str, float]:
    """Per sensor set, on whole clean clips (state carried from frame 0): the latent MSE, and
    the joint and lower-body position errors (cm, relative to the root, without heading) of
    the decoded guess. zero_mse: the latents' mean square, for scale."""
    out = {}
    for name, mask in zip(SENSOR_SETS, MASKS, strict=True):
        err, pe, lower, n = 0.0, 0.0, 0.0, 0
        for x, z, body in clips:
            pred, _ = net(torch.from_numpy(x[:1] * mask))
            err += float(((pred[0].numpy() - z) ** 2).mean(-1).sum())
            d = np.linalg.norm(decoded_positions(decoder, pred[0], offsets).numpy() - body, axis=-1) * 100
            pe, lower, n = pe + float(d.mean(-1).sum()), lower + float(d[:, LOWER].mean(-1).sum()), n + len(z)
        out[f"mse_{name}"], out[f"pe_{name}"], out[f"lower_pe_{name}"] = err / n, pe / n, lower / n
    for key in ("mse", "pe", "lower_pe"):
        out[key] = float(np.mean([out[f"{key}_{n}"] for n in SENSOR_SETS]))
    out["zero_mse"] = float(np.mean(np.concatenate([(z**2).mean(-1) for _, z, _ in clips])))
    return out


def export(net: TrackerPriorNet, path: Path, metadata: dict) -> None:
    c = net.config
    state = torch.zeros(c.layers, 1, c.hidden)
    export_onnx(
        TrackerPriorStep(net),
        (torch.zeros(1, FEATURES), state),
        path,
        ["features", "state"],
        ["latent", "next_state"],
        {**metadata, "state_shape": list(state.shape)},
        {"features": {0: "batch"}, "state": {1: "batch"}, "latent": {0: "batch"}, "next_state": {1: "batch"}},
    )


def train_tracker_prior(config: TrackerPriorConfig, run: TrainRun) -> dict:
    """Needs the pose VAE in out_dir (dragposer_encoder.onnx): the prior guesses its latents."""
    rng = run.start()
    out_dir = run.out
    t0 = time.perf_counter()
    vae = PoseVaeRuntime(out_dir, threads=torch.get_num_threads())
    train_clips = load_clips(run.mocap_root, "train", config, vae, rng, run.limit)
    val_clips = load_clips(run.mocap_root, "validation", config, vae, rng, run.limit)
    x = np.concatenate([c[0] for c in train_clips], axis=1)
    z = np.concatenate([c[1] for c in train_clips])
    body = np.concatenate([c[2] for c in train_clips])
    decoder = frozen_decoder(out_dir)
    offsets = torch.tensor(Skeleton.canonical().offsets, dtype=torch.float32)
    firsts, offset = [], 0
    for _, target, _ in train_clips:
        if len(target) >= config.chunk:
            firsts.append(offset + np.arange(len(target) - config.chunk + 1))
        offset += len(target)
    starts = np.concatenate(firsts)
    run.log(
        f"data: {len(train_clips)} train clips ({len(z)} frames x {len(x)} copies), {len(val_clips)} validation "
        f"clips, {time.perf_counter() - t0:.0f} s"
    )
    net = TrackerPriorNet(config)
    net.scale.copy_(torch.from_numpy(np.sqrt((x[0] ** 2).mean(0)) + 1e-3))
    opt = torch.optim.AdamW(net.parameters(), lr=config.lr, weight_decay=config.weight_decay)

    def step():
        idx = rng.choice(starts, size=config.batch)[:, None] + np.arange(config.chunk)
        copy = rng.integers(0, len(x), size=config.batch)[:, None]
        mask = MASKS[rng.integers(0, len(MASKS), size=config.batch)][:, None]
        pred, _ = net(torch.from_numpy(x[copy, idx] * mask))
        pred, kept = pred[:, config.burn_in :], idx[:, config.burn_in :]
        latent = ((pred - torch.from_numpy(z[kept])) ** 2).mean()
        positions = (
            ((decoded_positions(decoder, pred, offsets) - torch.from_numpy(body[kept])) ** 2).mean()
            if config.w_positions
            else pred.new_zeros(())
        )
        loss = config.w_latent * latent + config.w_positions * positions
        return loss, {"loss": loss.item(), "latent": latent.item(), "positions": positions.item()}

    fitted = fit(
        net,
        opt,
        step,
        lambda: validate(net, val_clips, decoder, offsets),
        lambda v: v["mse"],
        steps=config.steps,
        minutes=config.minutes,
        check_every=config.steps_per_check,
        rng=rng,
        run=run,
    )
    export(
        net,
        Path(out_dir) / FILE,
        {"method": "dragposer", "part": "tracker_prior", "config": config.to_dict(), "validation": fitted.validation},
    )
    return fitted.report(
        config,
        run,
        train_sequences=len(train_clips),
        train_frames=int(len(z)),
        validation_clips=len(val_clips),
        parameters=sum(p.numel() for p in net.parameters()),
    )
