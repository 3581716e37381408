"""DragPoser's temporal predictor (Ponton et al. 2024, Section 4.3): a transformer that predicts
the next latents from the past ones, so the pose optimiser is pulled along a plausible motion.

It runs every `every` frames (the paper's n = 4). The encoder reads the last `past` latents
(W_p = 16), each beside its context (root displacement, heading change, heights above the
floor: dragposer_pose.temporal_context); the decoder starts from the newest latent and
predicts the following ones one at a time, feeding its predictions back (W_f = 16 at most).
Training is teacher-forced, so one causal pass trains all W_f positions.

Deviations: the feed-forward width is 256 in the `small` configuration (the paper's 2048 is
`paper`); the decoder adds its output to its input latent (a residual), since the next latent
is mostly the current one.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import ClassVar

import torch
from torch import nn

from ...methods.dragposer.pose import LATENT, TEMPORAL_CONTEXT
from ...train.presets import Presets


@dataclass
class TemporalConfig(Presets):
    latent: int = LATENT
    context: int = TEMPORAL_CONTEXT
    width: int = 48  # the paper's feature dimension
    heads: int = 4
    layers: int = 3  # each for encoder and decoder
    feedforward: int = 256  # paper: 2048
    dropout: float = 0.1
    past: int = 16  # W_p
    future: int = 16  # W_f (training; the runtime may use fewer)
    every: int = 4  # n: frames between predictor steps
    limb_noise: float = 0.1  # probability per limb and step
    limb_noise_deg: float = 10.0  # per joint and axis
    noisy_copies: int = 4
    augment: str = "mirror,speed"  # train/augment.py (proportions: the canonical body hides them)
    variants: int = 2
    batch: int = 512
    lr: float = 1e-3
    weight_decay: float = 1e-4
    minutes: float = 0.0
    steps: int = 20_000
    steps_per_check: int = 250

    KIND = "temporal predictor"
    PRESETS: ClassVar[dict[str, dict]] = {
        "paper": {"feedforward": 2048, "minutes": 30.0, "steps": 1_000_000},
        # without limb noise: on 245 clips it made validation worse (model card)
        "small": {"limb_noise": 0.0, "noisy_copies": 1, "minutes": 30.0, "steps": 1_000_000},
        "tiny": {
            "width": 8,
            "heads": 2,
            "layers": 1,
            "feedforward": 16,
            "past": 4,
            "future": 3,
            "noisy_copies": 1,
            "batch": 8,
            "steps": 3,
            "steps_per_check": 1,
        },
    }

    def to_dict(self) -> dict:
        return asdict(self)


class TemporalPredictor(nn.Module):
    causal: torch.Tensor  # buffers (register_buffer), named for the type checker
    context_mean: torch.Tensor
    context_std: torch.Tensor

    def __init__(self, config: TemporalConfig) -> None:
        super().__init__()
        self.config = c = config
        self.past_in = nn.Linear(c.latent + c.context, c.width)
        self.future_in = nn.Linear(c.latent, c.width)
        self.past_position = nn.Parameter(torch.zeros(c.past, c.width))
        self.future_position = nn.Parameter(torch.zeros(c.future, c.width))
        nn.init.normal_(self.past_position, std=0.02)
        nn.init.normal_(self.future_position, std=0.02)
        self.transformer = nn.Transformer(
            c.width, c.heads, c.layers, c.layers, c.feedforward, c.dropout, batch_first=True
        )
        self.out = nn.Linear(c.width, c.latent)
        nn.init.zeros_(self.out.weight)  # starts as "the next latent is this one"
        nn.init.zeros_(self.out.bias)
        self.register_buffer("causal", nn.Transformer.generate_square_subsequent_mask(c.future), persistent=False)
        # context normalisation, set from the training data
        self.register_buffer("context_mean", torch.zeros(c.context))
        self.register_buffer("context_std", torch.ones(c.context))

    def forward(self, past: torch.Tensor, context: torch.Tensor, future: torch.Tensor) -> torch.Tensor:
        """past (B, W_p, 24), context (B, W_p, 9), future (B, W_f, 24): decoder inputs, the first
        being the newest latent -> (B, W_f, 24): output k predicts the latent after input k."""
        ctx = (context - self.context_mean) / self.context_std
        src = self.past_in(torch.cat([past, ctx], -1)) + self.past_position
        tgt = self.future_in(future) + self.future_position[: future.shape[1]]
        mask = self.causal[: future.shape[1], : future.shape[1]]
        h = self.transformer(src, tgt, tgt_mask=mask, tgt_is_causal=True)
        return future + self.out(h)


def loss(model: TemporalPredictor, batch: dict[str, torch.Tensor]) -> torch.Tensor:
    """The paper's plain MSE against the clean next latents."""
    return nn.functional.mse_loss(model(batch["past"], batch["context"], batch["future"]), batch["target"])
