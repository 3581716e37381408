"""LoBSTr's network (Yang et al. 2021): GRU encoder -> 128-D latent -> pose and contact heads.

Torch is for training and export only; the runtime (methods/lobstr/estimator.py) runs the ONNX
export of LobstrStep with ONNX Runtime.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import ClassVar

import torch
from torch import nn

from ...core.skeleton import JOINT_INDEX, PARENTS
from ...methods.lobstr.features import LEG_JOINTS, OUTPUTS, feature_count, output_count
from ...train.presets import Presets
from ...train.torch_body import sixd_to_matrix


@dataclass
class LobstrConfig(Presets):
    hidden: int = 1024  # GRU width (paper)
    latent: int = 128  # paper
    fps: float = 60.0  # the paper trains at 45 fps; our clips and nodes run at 60
    chunk: int = 90  # frames per training sequence
    burn_in: int = 30  # leading frames of a chunk without loss (the GRU warms up)
    batch: int = 256  # paper
    lr: float = 1e-3  # paper: Adam, 1e-3, x0.999 per epoch
    lr_decay: float = 0.999
    weight_decay: float = 0.0  # AdamW's decoupled decay (the paper: none)
    dropout: float = 0.0  # on the GRU's output, in training only (the paper: none)
    learned_upper: bool = False  # predict the upper body too (features.py; the paper: IK)
    steps_per_epoch: int = 50
    w_pose: float = 1.0  # paper's loss weights
    w_fk: float = 0.1
    w_velocity: float = 0.1
    w_contact: float = 1e-6
    noise_copies: int = 3  # tracker-noise realisations per clip, besides the clean one
    # each noisy copy's trackers also sit off their sites, the same way through the clip: what
    # the field's calibration leaves (its T-pose is off by up to 2 degrees a segment; the
    # movement calibration finds the translations within millimetres)
    mounting_deg: float = 0.0  # each site's rotation turned by up to this (degrees)
    mounting_std: float = 0.0  # each site's translation off by this per axis (metres)
    select_on: str = "validation"  # the split whose figures keep the best weights: validation,
    #                                 or selection (its clips of kinds no train clip has)
    augment: str = "mirror,speed,proportions"  # train/augment.py: any of its KINDS; all; none
    variants: int = 3  # augmented copies per train clip, besides the clip
    minutes: float = 0.0  # stop after this long (0: only steps counts)
    steps: int = 75_000  # paper: 1,500 epochs

    KIND = "LoBSTr"
    PRESETS: ClassVar[dict[str, dict]] = {
        "paper": {},
        "small": {  # 50 minutes on one core of the 2-core developer machine (beside another run)
            "hidden": 256,
            "batch": 64,
            "steps_per_epoch": 100,
            # on the validation people's dance (no training clip has it) lower-body PE
            # 17.56 -> 17.00 cm, and 7.95 -> 7.78 MPJPE on all of them (docs/methods.md)
            "dropout": 0.1,
            "minutes": 0.0,  # a step budget, so that the model does not depend on the machine's speed
            "steps": 11_848,  # as many as the model before dropout made in its 30 minutes
            "learned_upper": True,
            # chosen on the selection (docs/methods.md, "Training augmentation"): with these
            # three, lower-body PE 18.81 -> 18.10 cm and skate 20.7 -> 18.4 cm/s there
            "augment": "mirror,speed,proportions,splice",
            "mounting_deg": 2.0,  # the T-pose calibration's residual: up to 2 degrees a segment
            "mounting_std": 0.01,  # the movement calibration leaves under 4 mm; a margin above it
            "select_on": "selection",
        },
        "tiny": {  # tests
            "hidden": 16,
            "latent": 8,
            "chunk": 20,
            "burn_in": 5,
            "batch": 4,
            "steps": 3,
            "noise_copies": 1,
            "augment": "mirror",
            "variants": 1,
            "learned_upper": True,
        },
    }

    def to_dict(self) -> dict:
        return asdict(self)


class LobstrNet(nn.Module):
    mean: torch.Tensor  # buffers (register_buffer), named for the type checker
    std: torch.Tensor

    def __init__(self, config: LobstrConfig) -> None:
        super().__init__()
        self.config = config
        # Input standardisation, fitted on the training set and exported with the weights.
        features = feature_count(config.learned_upper)
        self.register_buffer("mean", torch.zeros(features))
        self.register_buffer("std", torch.ones(features))
        self.gru = nn.GRU(features, config.hidden, batch_first=True)
        self.dropout = nn.Dropout(config.dropout)
        self.to_latent = nn.Sequential(nn.Linear(config.hidden, config.latent), nn.ReLU())
        self.pose_head = nn.Linear(config.latent, output_count(config.learned_upper))
        self.contact_head = nn.Linear(config.latent, 2 * 2)  # per foot: (no contact, contact) logits

    def forward(self, x: torch.Tensor, h: torch.Tensor | None = None):
        """x (B, T, 37 or 70) -> pose (B, T, 48 or 126) in 6D (legs, then the upper body),
        contact logits (B, T, 2, 2), state (1, B, H)."""
        out, h = self.gru((x - self.mean) / self.std, h)
        z = self.to_latent(self.dropout(out))
        return self.pose_head(z), self.contact_head(z).unflatten(-1, (2, 2)), h


class LobstrStep(nn.Module):
    """One streaming step, the graph that is exported: (x (B, 37 or 70), state (1, B, H)) ->
    (pose (B, 48 or 126), contact probability (B, 2), state)."""

    def __init__(self, net: LobstrNet) -> None:
        super().__init__()
        self.net = net

    def forward(self, x: torch.Tensor, state: torch.Tensor):
        pose, logits, state = self.net(x[:, None, :], state)
        return pose[:, 0], torch.softmax(logits[:, 0], dim=-1)[..., 1], state


# Leg chains for the FK losses: joint -> its parent among the legs (hips hang off the pelvis).
_LEG_PARENT = {j: (PARENTS[j] if PARENTS[j] in LEG_JOINTS else None) for j in LEG_JOINTS}
_TOES = [LEG_JOINTS.index(JOINT_INDEX["left_foot"]), LEG_JOINTS.index(JOINT_INDEX["right_foot"])]


def leg_positions(legs6d: torch.Tensor, pelvis_in_ref: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
    """Leg joint positions (..., 8, 3) relative to the pelvis, in the reference frame.

    legs6d (..., 48) as in features.py (hips in the reference frame, others local);
    pelvis_in_ref (..., 3, 3); offsets (22, 3) of the canonical body.
    """
    rot = sixd_to_matrix(legs6d.unflatten(-1, (len(LEG_JOINTS), 6)))
    offsets = offsets.to(legs6d)
    glob, pos = {}, {}
    for k, j in enumerate(LEG_JOINTS):
        parent = _LEG_PARENT[j]
        if parent is None:
            glob[j] = rot[..., k, :, :]
            pos[j] = (pelvis_in_ref @ offsets[j, :, None])[..., 0]
        else:
            glob[j] = glob[parent] @ rot[..., k, :, :]
            pos[j] = pos[parent] + (glob[parent] @ offsets[j, :, None])[..., 0]
    return torch.stack([pos[j] for j in LEG_JOINTS], dim=-2)


def losses(net: LobstrNet, batch: dict[str, torch.Tensor], offsets: torch.Tensor) -> dict[str, torch.Tensor]:
    """The paper's four terms on the frames after the burn-in, and their weighted sum; with
    the learned upper body, its pose term too (weighted as the legs')."""
    cfg = net.config
    out, logits, _ = net(batch["x"])
    s = slice(cfg.burn_in, None)
    out, logits = out[:, s], logits[:, s]
    pose = out[..., :OUTPUTS]
    target, pelvis, yaw = batch["legs"][:, s], batch["pelvis_in_ref"][:, s], batch["yaw"][:, s]
    contact = batch["contact"][:, s]
    l_pose = ((pose - target) ** 2).mean()
    l_upper = ((out[..., OUTPUTS:] - batch["upper"][:, s]) ** 2).mean() if cfg.learned_upper else out.new_zeros(())
    p_hat, p = leg_positions(pose, pelvis, offsets), leg_positions(target, pelvis, offsets)
    l_fk = (p_hat - p).norm(dim=-1).mean()
    # Toe velocity in the world (yaw only: the pelvis translation cancels between prediction
    # and truth). The printed equation compares each prediction with the previous true
    # pose, which reduces to a toe position error; we match frame-to-frame velocities,
    # which is what the text says the term is for.
    c, sn = torch.cos(yaw), torch.sin(yaw)

    def world(v):  # rotate (B, T, 2, 3) about z by yaw (B, T)
        x, y = v[..., 0], v[..., 1]
        return torch.stack([c[..., None] * x - sn[..., None] * y, sn[..., None] * x + c[..., None] * y, v[..., 2]], -1)

    toes_hat, toes = world(p_hat[..., _TOES, :]), world(p[..., _TOES, :])
    l_vel = ((toes_hat[:, 1:] - toes_hat[:, :-1]) - (toes[:, 1:] - toes[:, :-1])).norm(dim=-1).mean()
    ce = nn.functional.cross_entropy(logits.reshape(-1, 2), contact.reshape(-1).long(), reduction="none")
    ce = ce.view(*contact.shape).mean(dim=(0, 1))  # (2,) left, right
    l_contact = ce.sum() / 2
    total = cfg.w_pose * (l_pose + l_upper) + cfg.w_fk * l_fk + cfg.w_velocity * l_vel + cfg.w_contact * l_contact
    accuracy = (logits.argmax(-1) == contact.long()).float().mean()
    return {
        "total": total,
        "pose": l_pose,
        "upper": l_upper,
        "fk": l_fk,
        "velocity": l_vel,
        "contact": l_contact,
        "contact_accuracy": accuracy,
    }
