"""DragPoser's pose VAE (Ponton et al. 2024): dual quaternions -> 24-D Gaussian latent -> pose.

The paper builds encoder and decoder from skeleton-aware convolutions (SparsePoser) with
about 168k parameters; here they are MLPs of about the same size, which CPU training in an
hour can fit. Losses and weights are the paper's: reconstruction (MSE), forward kinematics
(MSE, x100), KL divergence (x0.001) and continuity (x1): one gradient step in the latent
from pose i must reach pose i+1.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import ClassVar

import torch
from torch import nn

from ...methods.dragposer.pose import DECODER_OUTPUT, ENCODER_INPUT, LATENT
from ...train.presets import Presets
from ...train.torch_body import forward_kinematics, sixd_to_matrix


@dataclass
class VaeConfig(Presets):
    latent: int = LATENT
    hidden: int = 256
    batch: int = 256  # paper: 64 (a day on a GPU); larger batches suit CPU training
    lr: float = 1e-3  # paper: 1e-4 with AdamW
    weight_decay: float = 1e-4
    w_reconstruction: float = 1.0
    w_fk: float = 100.0
    w_kld: float = 0.001
    w_continuity: float = 1.0
    augment: str = "mirror"  # train/augment.py; the pose VAE sees single heading-free poses
    variants: int = 1  # on the canonical body, so only mirroring changes what it sees
    minutes: float = 0.0
    steps: int = 20_000
    steps_per_check: int = 250

    KIND = "VAE"
    PRESETS: ClassVar[dict[str, dict]] = {
        "small": {"minutes": 30.0, "steps": 1_000_000},
        "tiny": {"hidden": 16, "batch": 8, "steps": 3, "steps_per_check": 1},
    }

    def to_dict(self) -> dict:
        return asdict(self)


class PoseVae(nn.Module):
    def __init__(self, config: VaeConfig) -> None:
        super().__init__()
        self.config = config
        h = config.hidden
        self.encoder = nn.Sequential(nn.Linear(ENCODER_INPUT, h), nn.ELU(), nn.Linear(h, h), nn.ELU())
        self.mu = nn.Linear(h, config.latent)
        self.log_var = nn.Linear(h, config.latent)
        self.decoder = nn.Sequential(
            nn.Linear(config.latent, h), nn.ELU(), nn.Linear(h, h), nn.ELU(), nn.Linear(h, DECODER_OUTPUT)
        )

    def encode(self, dq: torch.Tensor):
        e = self.encoder(dq)
        return self.mu(e), self.log_var(e)

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        """(..., 24) -> (..., 132): 22 local rotations in 6D, the root's without heading."""
        return self.decoder(z)


class Decoder(nn.Module):
    """The exported decoder graph: z (B, 24) -> rotation matrices (B, 22, 3, 3)."""

    def __init__(self, vae: PoseVae) -> None:
        super().__init__()
        self.vae = vae

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        return sixd_to_matrix(self.vae.decode(z).unflatten(-1, (22, 6)))


class Encoder(nn.Module):
    """The exported encoder graph: dual quaternions (B, 176) -> latent mean (B, 24)."""

    def __init__(self, vae: PoseVae) -> None:
        super().__init__()
        self.vae = vae

    def forward(self, dq: torch.Tensor) -> torch.Tensor:
        return self.vae.encode(dq)[0]


def _positions(sixd: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
    rot = sixd_to_matrix(sixd.unflatten(-1, (22, 6)))
    return forward_kinematics(rot, torch.zeros(rot.shape[:-3] + (3,), dtype=rot.dtype), offsets)[1]


def losses(vae: PoseVae, batch: dict[str, torch.Tensor], offsets: torch.Tensor) -> dict[str, torch.Tensor]:
    """batch: dq (B, 2, 176) and pose (B, 2, 132) for consecutive frames (i, i+1)."""
    cfg = vae.config
    dq, pose = batch["dq"], batch["pose"]
    mu, log_var = vae.encode(dq[:, 0])
    z = mu + torch.randn_like(mu) * torch.exp(0.5 * log_var)
    x_hat = vae.decode(z)
    l_rec = ((x_hat - pose[:, 0]) ** 2).mean()
    l_fk = ((_positions(x_hat, offsets) - _positions(pose[:, 0], offsets)) ** 2).mean()
    l_kld = (-0.5 * (1 + log_var - mu**2 - log_var.exp()).sum(-1)).mean()
    # continuity: one plain gradient step in the latent, from pose i towards pose i+1
    x0 = vae.decode(mu)
    step = torch.autograd.grad(((x0 - pose[:, 1]) ** 2).mean(dim=-1).sum(), mu, create_graph=True)[0]
    z0 = mu
    l_cont = ((vae.decode(z0 - step) - pose[:, 1]) ** 2).mean()
    total = cfg.w_reconstruction * l_rec + cfg.w_fk * l_fk + cfg.w_kld * l_kld + cfg.w_continuity * l_cont
    return {"total": total, "reconstruction": l_rec, "fk": l_fk, "kld": l_kld, "continuity": l_cont}
