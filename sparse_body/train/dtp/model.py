"""DTP's network (Deep Tracker Poser): a two-layer embedding, a transformer encoder over a
window of frames, a linear decoder to the 21 local joint rotations in 6D.

Torch is for training and export only; the runtime (methods/dtp/estimator.py) runs the ONNX export
of DtpNet with ONNX Runtime.

Every frame of the window is a token. Attention is masked so that a token sees only the
frames before it and at most `future` frames after it (the first layer may look that far
ahead, the later ones only back, or the layers would add up their lookahead): then every token's output is a valid
estimate for its frame, training learns from all of them at once, and a stream's first
frames (fewer than a window) are run as a shorter window instead of being padded.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import ClassVar

import torch
from torch import nn

from ...core.skeleton import JOINT_INDEX
from ...methods.dtp.features import FEATURES, OUTPUTS
from ...train.presets import Presets
from ...train.torch_body import forward_kinematics, sixd_to_matrix


@dataclass
class DtpConfig(Presets):
    d_model: int = 256  # paper: 256-D embedding
    heads: int = 8  # paper
    layers: int = 3  # paper
    feedforward: int = 1024  # the encoder layer's inner width (Vaswani et al.'s 4x)
    dropout: float = 0.1
    past: int = 20  # paper: 20 past frames, the current one
    future: int = 0  # and 5 future frames (0: the online variant a live node runs)
    fps: float = 60.0  # paper: resampled to 60 fps
    batch: int = 64
    lr: float = 1e-4  # paper: Adam 1e-4, halved every 10,000 steps
    lr_half_every: int = 10_000
    w_rotation: float = 1.0  # paper's loss weights
    w_end_effector: float = 0.5
    w_foot_velocity: float = 0.01
    augment: str = "mirror,speed,proportions"  # train/augment.py: any of its KINDS; all; none
    variants: int = 2
    steps_per_check: int = 200
    select_on: str = "validation"  # the split whose figures keep the best weights: validation,
    #                                 or selection (its clips of kinds no train clip has)
    minutes: float = 0.0  # pre-training budget (0: only steps counts)
    steps: int = 200_000
    # occlusion fine-tuning (the paper's AMASS-OCC): in this share of windows one or both feet
    # are occluded for a stretch, reported as origin + identity or as bounded noise
    occluded_share: float = 0.5
    finetune_lr: float = 5e-5
    finetune_minutes: float = 0.0
    finetune_steps: int = 50_000

    @property
    def window(self) -> int:
        return self.past + 1 + self.future

    KIND = "DTP"
    PRESETS: ClassVar[dict[str, dict]] = {
        "paper": {},
        "small": {  # pre-training and fine-tuning in under an hour on 2 CPU cores
            "d_model": 128,
            "feedforward": 512,
            "lr": 5e-4,
            "lr_half_every": 4_000,
            "minutes": 30.0,
            "finetune_minutes": 14.0,
            "finetune_lr": 2e-4,
            "steps": 1_000_000,
            "finetune_steps": 1_000_000,
        },
        "lookahead": {"base": "small", "future": 5},  # the paper's 5 future frames (offline processing)
        "tiny": {  # tests
            "d_model": 16,
            "heads": 2,
            "layers": 1,
            "feedforward": 32,
            "past": 4,
            "batch": 4,
            "steps": 3,
            "finetune_steps": 2,
            "steps_per_check": 2,
            "augment": "mirror",
            "variants": 1,
        },
    }

    def to_dict(self) -> dict:
        return {**asdict(self), "window": self.window}


class SelfAttention(nn.Module):
    """Multi-head scaled dot-product self-attention (paper, Fig. 3b-c). Written out rather than
    nn.MultiheadAttention, whose ONNX export fixes the window length it was traced with."""

    def __init__(self, d: int, heads: int) -> None:
        super().__init__()
        self.heads = heads
        self.qkv = nn.Linear(d, 3 * d)
        self.out = nn.Linear(d, d)

    def forward(self, x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        q, k, v = (t.unflatten(-1, (self.heads, -1)).transpose(1, 2) for t in self.qkv(x).chunk(3, dim=-1))
        att = torch.softmax(q @ k.transpose(-1, -2) / q.shape[-1] ** 0.5 + mask, dim=-1)
        return self.out((att @ v).transpose(1, 2).flatten(-2))


class EncoderLayer(nn.Module):
    """Attention and a two-layer ReLU feed-forward, each with a residual connection followed by
    layer normalisation (paper, Section 3.3; Vaswani et al.)."""

    def __init__(self, d: int, heads: int, feedforward: int, dropout: float) -> None:
        super().__init__()
        self.attention = SelfAttention(d, heads)
        self.feedforward = nn.Sequential(
            nn.Linear(d, feedforward), nn.ReLU(), nn.Dropout(dropout), nn.Linear(feedforward, d)
        )
        self.norm1, self.norm2 = nn.LayerNorm(d), nn.LayerNorm(d)
        self.dropout = nn.Dropout(dropout)

    def forward(self, x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        x = self.norm1(x + self.dropout(self.attention(x, mask)))
        return self.norm2(x + self.dropout(self.feedforward(x)))


class DtpNet(nn.Module):
    mean: torch.Tensor  # buffers (register_buffer), named for the type checker
    std: torch.Tensor
    first_mask: torch.Tensor
    mask: torch.Tensor

    def __init__(self, config: DtpConfig) -> None:
        super().__init__()
        self.config = config
        # Input standardisation, fitted on the training set and exported with the weights.
        self.register_buffer("mean", torch.zeros(FEATURES))
        self.register_buffer("std", torch.ones(FEATURES))
        d = config.d_model
        self.embed = nn.Sequential(nn.Linear(FEATURES, d), nn.ReLU(), nn.Linear(d, d))  # paper: two layers
        self.position = nn.Parameter(torch.zeros(config.window, d))
        self.layers = nn.ModuleList(
            EncoderLayer(d, config.heads, config.feedforward, config.dropout) for _ in range(config.layers)
        )
        self.decode = nn.Linear(d, OUTPUTS)
        # token i may attend to token j when j <= i + future in the first layer and j <= i after it,
        # so that no token sees more than `future` frames ahead however many layers there are
        # (float masks: ONNX exports them as they are)
        i = torch.arange(config.window)
        self.register_buffer("first_mask", torch.where(i[None, :] <= i[:, None] + config.future, 0.0, float("-inf")))
        self.register_buffer("mask", torch.where(i[None, :] <= i[:, None], 0.0, float("-inf")))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """x (B, n, 72) with n <= window -> (B, n, 126): each frame's 21 local rotations in 6D."""
        n = x.shape[1]
        h = self.embed((x - self.mean) / self.std) + self.position[:n]
        for k, layer in enumerate(self.layers):
            h = layer(h, (self.mask if k else self.first_mask)[:n, :n])
        return self.decode(h)


END_EFFECTORS = tuple(JOINT_INDEX[j] for j in ("head", "left_wrist", "right_wrist", "left_foot", "right_foot"))
FEET = (3, 4)  # among END_EFFECTORS


def body_positions(pose6d: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
    """(..., 22, 3) joint positions in the pelvis frame from (..., 126) local rotations."""
    local = sixd_to_matrix(pose6d.unflatten(-1, (-1, 6)))
    eye = torch.eye(3, dtype=local.dtype).expand(local.shape[:-3] + (1, 3, 3))
    _, pos = forward_kinematics(torch.cat([eye, local], dim=-3), torch.zeros(local.shape[:-3] + (3,)), offsets)
    return pos


def losses(net: DtpNet, batch: dict[str, torch.Tensor], offsets: torch.Tensor) -> dict[str, torch.Tensor]:
    """The paper's three L2 terms on every frame of the windows, and their weighted sum."""
    cfg = net.config
    pose = net(batch["x"])
    target = batch["pose"]
    l_rot = ((pose - target) ** 2).mean()
    ends_hat = body_positions(pose, offsets)[..., END_EFFECTORS, :]
    ends = body_positions(target, offsets)[..., END_EFFECTORS, :]
    l_end = (ends_hat - ends).norm(dim=-1).mean()
    # foot velocity in the world: the pelvis (a tracker) moves both alike, so only its turn matters
    rot = batch["pelvis_rot"]  # (B, W, 3, 3)
    feet_hat = (rot[:, :, None] @ ends_hat[..., FEET, :, None])[..., 0]
    feet = (rot[:, :, None] @ ends[..., FEET, :, None])[..., 0]
    l_feet = ((feet_hat[:, 1:] - feet_hat[:, :-1]) - (feet[:, 1:] - feet[:, :-1])).norm(dim=-1).mean()
    total = cfg.w_rotation * l_rot + cfg.w_end_effector * l_end + cfg.w_foot_velocity * l_feet
    return {"total": total, "rotation": l_rot, "end_effector": l_end, "foot_velocity": l_feet}
