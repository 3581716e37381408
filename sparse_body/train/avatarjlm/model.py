"""AvatarJLM's network (Zheng et al., joint-level modelling): an MLP gives an initial pose,
its joints become rotation and position tokens, spatial and temporal transformer blocks
alternate over them, and a regressor gives the 22 local rotations (6D).

Torch is for training and export only; the runtime (methods/avatarjlm/estimator.py) runs the ONNX
export of one streaming step with ONNX Runtime.

Stage 1 (per frame): F_embed embeds the input (54 or 72 values), F_reg regresses an initial
pose (root rotation in the frame's heading frame, local rotations); its forward kinematics
on the canonical body, placed by head alignment, gives each joint's global rotation and
position, and the tracked joints take their trackers' instead: 22 + 22 tokens.

Stage 2: n loops of a spatial block (the 44 tokens of a frame and the embedded input as a
45th, with learned spatial position encodings) and a temporal block (each token over the
frames). Two deviations from the paper, written here because the runtime rests on them:
- the temporal attention is causal and slides: a frame sees itself and the window - 1
  frames before it, in every block. Every frame of a training sequence is a target, and a
  stream's first frames run without padding, as DTP's;
- where the paper adds a learned temporal position encoding to the tokens, each head here
  learns a bias by the age of the frame attended to (0: this frame). A frame's keys and
  values then never change once computed, and a live stream runs one frame at a time over
  the kept keys and values of the last window - 1 frames (step()), which gives what the
  network gives on the whole stream (test_avatarjlm checks it) at a 40th of the cost of
  running a window each frame.
Because of the stacked blocks a frame's output reaches further back than one window (loops x
(window - 1) frames); training sequences are longer than a window (`sequence`) so that
training sees what a stream sees.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import ClassVar, cast

import torch
from torch import nn

from ...core.skeleton import JOINT_INDEX, LOWER_BODY, NUM_JOINTS, Skeleton, joint_indices
from ...methods.avatarjlm.features import PER_SITE, SITES, input_joints
from ...train.presets import Presets
from ...train.torch_body import forward_kinematics, matrix_to_6d, sixd_to_matrix

TOKENS = 2 * NUM_JOINTS  # rotation tokens, then position tokens
ROTATION_LOSSES = ("6d", "matrix")  # AvatarJlmConfig.rotation_loss
HEAD = JOINT_INDEX["head"]
HANDS = (JOINT_INDEX["left_wrist"], JOINT_INDEX["right_wrist"])
FEET = tuple(JOINT_INDEX[j] for j in ("left_ankle", "right_ankle", "left_foot", "right_foot"))
LEGS = list(joint_indices(LOWER_BODY))


@dataclass
class AvatarJlmConfig(Presets):
    sensors: str = "three_point"  # three_point (head, hands) or four_point (and the pelvis)
    d_embed: int = 1024  # paper: d1
    d_model: int = 512  # paper: d2
    heads: int = 8
    loops: int = 6  # paper: n
    feedforward: int = 1024
    dropout: float = 0.1
    window: int = 41  # paper: 41 frames, the current one predicted (here: what a block attends to)
    sequence: int = 61  # frames per training sequence (>= window: the blocks reach further back together)
    fps: float = 60.0
    batch: int = 64  # paper
    lr: float = 1e-4  # paper: 1e-4, 1e-5 after 60 % of the steps
    lr_drop_at: float = 0.6
    masked_tokens: int = 2  # paper: 2 tokens other than the trackers' masked in training
    # both pose heads start near the identity (the root facing the head's heading). From random
    # rotations and at the paper's beta, training settled with the root half a turn about its own
    # axis and its children turned back: right positions from wrong local rotations, which a
    # tracked pelvis (four_point: the root is the tracker's) cannot live with
    identity_start: bool = False
    # the paper's loss weights:
    # L_first + beta L_ori + gamma L_rot + delta L_pos + eps L_h + zeta L_mot + L_p + alpha L_fh
    alpha: float = 0.5
    beta: float = 0.02
    gamma: float = 2.0
    delta: float = 5.0
    epsilon: float = 5.0
    zeta: float = 50.0
    # ours: the lower body's positions relative to the root (its rotation and place taken out),
    # L1. Head-aligned positions (L_pos) charge a leg for every error of the spine and root
    # above it; this term judges the legs' own swing (the three-point model)
    leg_weight: float = 0.0
    # what the rotation terms (L_first, L_ori, L_rot) measure: 6d, L1 on the network's raw
    # output, as the paper; or matrix, the angle between the rotations (rotation_error).
    # L1 falls again past 135 degrees of a joint's turn (2 (1 - cos a) + 2 |sin a|), so a joint
    # turned that far settles half a turn about its bone, its child turned back; the raw
    # vectors' only way out is through zero, where one column flips before the other and the
    # child swings through the joint, and the position terms hold it there
    rotation_loss: str = "6d"
    # tracker noise on the noisy copy of each clip: lobstr (1 cm, 1.5 degrees, LoBSTr's
    # training noise) or vr (the field protocol's: 1 mm, 1 degree)
    train_noise: str = "lobstr"
    augment: str = "mirror,speed,proportions"  # train/augment.py: any of its KINDS; all; none
    variants: int = 2
    steps_per_check: int = 200
    select_on: str = "validation"  # the split whose figures keep the best weights: validation,
    #                                 or selection (its clips of kinds no train clip has)
    minutes: float = 0.0  # time budget (0: only steps counts)
    steps: int = 100_000  # paper

    @property
    def sites(self) -> tuple[str, ...]:
        return SITES[self.sensors]

    @property
    def features(self) -> int:
        return PER_SITE * len(self.sites)

    KIND = "AvatarJLM"
    PRESETS: ClassVar[dict[str, dict]] = {
        "paper": {},
        # 88 minutes on one CPU core (beside four_point on the other); from the identity with
        # the root's own rotation weighed in, as four_point: its legs do not turn
        "small": {
            "d_embed": 256,
            "d_model": 64,
            "heads": 4,
            "loops": 3,
            "feedforward": 128,
            "dropout": 0.0,
            "batch": 6,
            "lr": 5e-4,
            "identity_start": True,
            "beta": 1.0,
            "leg_weight": 5.0,
            "minutes": 88.0,
            "steps": 1_000_000,
        },
        "four_point": {  # the same size with the pelvis
            "base": "small",
            "sensors": "four_point",
            # the leg term: on the validation people's dance (no training clip has it) lower-body
            # PE 21.38 -> 18.38 cm, and 8.84 -> 8.01 MPJPE on all of them (docs/methods.md)
            "leg_weight": 5.0,
            # these three together, against the model before them, on the selection: MPJPE -0.14
            # cm [-0.34, +0.06], lower-body PE -0.21 [-0.70, +0.34], MPJRE -1.52 degrees [-2.27,
            # -0.87], and no joint turned half round (docs/methods.md)
            "augment": "mirror,speed,proportions,splice,tilt",  # the splice alone turned seed 0's neck on 6d
            # tilt (a quarter of the random variants off the feet): the floor part's lower-body PE
            # 1.56x IK's -> 0.93x (worst kind 1.66x -> 1.14x), the selection 0.76x -> 0.78x,
            # cmu-extra 0.68x -> 0.66x; `upright` over it better on all three (the model's card)
            "rotation_loss": "matrix",  # the angle: a joint turned past 135 degrees is pulled back
            "select_on": "selection",  # the weights kept on kinds of motion no train clip has
            # the drop to a tenth at step 3,000, not 2,200: on the selection, against the same
            # recipe dropping at 0.6, MPJPE -0.12 cm [-0.24, +0.00], MPJRE -0.92 degrees [-1.17,
            # -0.66], skate -0.64 cm/s; on the kinds trained on every figure better too
            "lr_drop_at": 0.8,
            "minutes": 0.0,  # a step budget, so that the model does not depend on the machine's speed
            "steps": 3_965,  # 76 minutes on one core of the 2-core developer machine, 34 on two
        },
        "tiny": {  # tests
            "d_embed": 16,
            "d_model": 8,
            "heads": 2,
            "loops": 1,
            "feedforward": 16,
            "window": 6,
            "sequence": 8,
            "batch": 3,
            "steps": 3,
            "steps_per_check": 2,
            "augment": "mirror",
            "variants": 1,
        },
    }

    def to_dict(self) -> dict:
        return asdict(self)


class TemporalAttention(nn.Module):
    """Causal multi-head self-attention over one token's frames with a learned bias by age."""

    def __init__(self, d: int, heads: int, window: int) -> None:
        super().__init__()
        self.heads = heads
        self.qkv = nn.Linear(d, 3 * d)
        self.out = nn.Linear(d, d)
        self.age_bias = nn.Parameter(torch.zeros(heads, window))

    def _split(self, x: torch.Tensor):
        return (t.unflatten(-1, (self.heads, -1)).transpose(-2, -3) for t in self.qkv(x).chunk(3, dim=-1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """x (N, n, d): n frames, each attending to itself and the window - 1 frames before it."""
        q, k, v = self._split(x)
        i = torch.arange(x.shape[1])
        age = i[:, None] - i[None, :]
        window = self.age_bias.shape[1]
        seen = (age >= 0) & (age < window)
        bias = self.age_bias[:, age.clamp(0, window - 1)] + torch.where(seen, 0.0, float("-inf"))
        att = torch.softmax(q @ k.transpose(-1, -2) / q.shape[-1] ** 0.5 + bias, dim=-1)
        return self.out((att @ v).transpose(-2, -3).flatten(-2))

    def step(self, x: torch.Tensor, past_k: torch.Tensor, past_v: torch.Tensor, past_bias: torch.Tensor):
        """x (N, 1, d), one new frame; past_k / past_v (N, heads, P, d/heads) the kept frames'
        keys and values, past_bias (heads, 1, P) their age bias (-inf where a slot is empty).
        -> (output (N, 1, d), this frame's key and value (N, heads, 1, d/heads))."""
        q, k, v = self._split(x)
        keys, values = torch.cat([past_k, k], dim=2), torch.cat([past_v, v], dim=2)
        bias = torch.cat([past_bias, self.age_bias[:, None, :1]], dim=-1)
        att = torch.softmax(q @ keys.transpose(-1, -2) / q.shape[-1] ** 0.5 + bias, dim=-1)
        return self.out((att @ values).transpose(-2, -3).flatten(-2)), k, v


class SpatialAttention(nn.Module):
    def __init__(self, d: int, heads: int) -> None:
        super().__init__()
        self.heads = heads
        self.qkv = nn.Linear(d, 3 * d)
        self.out = nn.Linear(d, d)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        q, k, v = (t.unflatten(-1, (self.heads, -1)).transpose(-2, -3) for t in self.qkv(x).chunk(3, dim=-1))
        att = torch.softmax(q @ k.transpose(-1, -2) / q.shape[-1] ** 0.5, dim=-1)
        return self.out((att @ v).transpose(-2, -3).flatten(-2))


class Block(nn.Module):
    """Pre-norm transformer block: attention, then a GELU feed-forward, each residual."""

    def __init__(self, attention: nn.Module, d: int, feedforward: int, dropout: float) -> None:
        super().__init__()
        self.attention = attention
        self.norm1, self.norm2 = nn.LayerNorm(d), nn.LayerNorm(d)
        self.feedforward = nn.Sequential(
            nn.Linear(d, feedforward), nn.GELU(), nn.Dropout(dropout), nn.Linear(feedforward, d)
        )
        self.dropout = nn.Dropout(dropout)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = x + self.dropout(self.attention(self.norm1(x)))
        return x + self.dropout(self.feedforward(self.norm2(x)))

    def step(self, x, past_k, past_v, past_bias):
        out, k, v = self.attention.step(self.norm1(x), past_k, past_v, past_bias)
        x = x + out
        return x + self.feedforward(self.norm2(x)), k, v


class AvatarJlmNet(nn.Module):
    mean: torch.Tensor  # buffers (register_buffer), named for the type checker
    std: torch.Tensor
    offsets: torch.Tensor

    def __init__(self, config: AvatarJlmConfig) -> None:
        super().__init__()
        self.config = config
        F, d1, d2 = config.features, config.d_embed, config.d_model
        # input standardisation, fitted on the training set and exported with the weights
        self.register_buffer("mean", torch.zeros(F))
        self.register_buffer("std", torch.ones(F))
        self.register_buffer("offsets", torch.tensor(Skeleton.canonical().offsets, dtype=torch.float32))
        self.tracked = input_joints(config.sites)
        self.embed = nn.Sequential(nn.Linear(F, d1), nn.GELU(), nn.Linear(d1, d1))  # F_embed
        self.initial = nn.Sequential(nn.GELU(), nn.Linear(d1, d1), nn.GELU(), nn.Linear(d1, NUM_JOINTS * 6))  # F_reg
        self.embed_rotation, self.embed_position = nn.Linear(6, d2), nn.Linear(3, d2)
        self.embed_input = nn.Linear(d1, d2)
        self.spatial_position = nn.Parameter(torch.zeros(TOKENS + 1, d2))
        nn.init.normal_(self.spatial_position, std=0.02)
        self.spatial = nn.ModuleList(
            Block(SpatialAttention(d2, config.heads), d2, config.feedforward, config.dropout)
            for _ in range(config.loops)
        )
        self.temporal = nn.ModuleList(
            Block(TemporalAttention(d2, config.heads, config.window), d2, config.feedforward, config.dropout)
            for _ in range(config.loops)
        )
        self.norm = nn.LayerNorm(d2)
        self.regress = nn.Linear(TOKENS * d2, NUM_JOINTS * 6)
        heads: tuple[nn.Linear, ...] = (cast(nn.Linear, self.initial[-1]), self.regress)
        for head in heads if config.identity_start else ():
            with torch.no_grad():
                head.weight.mul_(0.1)
                head.bias.copy_(torch.tensor([1.0, 0.0, 0.0, 0.0, 1.0, 0.0]).repeat(NUM_JOINTS))

    def stage1(self, x: torch.Tensor):
        """x (..., F) -> (initial pose (..., 22, 6), tokens (..., 44, d2), input token (..., 1, d2))."""
        h = self.embed((x - self.mean) / self.std)
        init = self.initial(h).unflatten(-1, (NUM_JOINTS, 6))
        glob, pos = forward_kinematics(sixd_to_matrix(init), torch.zeros(init.shape[:-2] + (3,)), self.offsets)
        sites = x.unflatten(-1, (-1, PER_SITE))
        pos = pos - pos[..., HEAD : HEAD + 1, :] + sites[..., 0:1, 6:9]  # head alignment
        rot6 = matrix_to_6d(glob)
        tracked = list(self.tracked)
        rot6 = rot6.index_copy(-2, torch.tensor(tracked), sites[..., 0:6])  # the trackers' own, for their joints
        pos = pos.index_copy(-2, torch.tensor(tracked), sites[..., 6:9])
        tokens = torch.cat([self.embed_rotation(rot6), self.embed_position(pos)], dim=-2)
        return init, tokens, self.embed_input(h)[..., None, :]

    def _spatial(self, k: int, tokens: torch.Tensor, given: torch.Tensor) -> torch.Tensor:
        s = torch.cat([tokens, given], dim=-2) + self.spatial_position
        return self.spatial[k](s)[..., :TOKENS, :]

    def forward(self, x: torch.Tensor, token_mask: torch.Tensor | None = None):
        """x (B, n, F), n frames of a stream from its start -> (pose (B, n, 22, 6), initial pose (B, n, 22, 6)): the
        root's rotation in each frame's heading frame, the other joints' local rotations.
        token_mask (B, 44): tokens to blank (masked training)."""
        init, tokens, given = self.stage1(x)
        if token_mask is not None:
            tokens = tokens * (~token_mask)[:, None, :, None]
        B, n = x.shape[:2]
        for k in range(self.config.loops):
            tokens = self._spatial(k, tokens, given)
            t = tokens.transpose(1, 2).flatten(0, 1)  # (B * 44, n, d2)
            tokens = self.temporal[k](t).unflatten(0, (B, TOKENS)).transpose(1, 2)
        pose = self.regress(self.norm(tokens).flatten(-2)).unflatten(-1, (NUM_JOINTS, 6))
        return pose, init

    def step(
        self,
        x: torch.Tensor,
        past_k: torch.Tensor,
        past_v: torch.Tensor,
        past_age: torch.Tensor,
        past_mask: torch.Tensor,
    ):
        """One live frame: x (1, F); past_k / past_v (loops, 44, heads, P, d2/heads) the last
        P = window - 1 frames' keys and values in each temporal block, past_age (P,) their
        ages in frames (int64, 1..P), past_mask (P,) 0 where a slot holds a frame, -inf where
        empty. -> (pose (1, 22, 6), new keys, new values (loops, 44, heads, 1, d2/heads))."""
        _, tokens, given = self.stage1(x)  # (1, 44, d2), (1, 1, d2)
        new_k, new_v = [], []
        for k in range(self.config.loops):
            tokens = self._spatial(k, tokens, given)
            block = cast(Block, self.temporal[k])
            attention = cast(TemporalAttention, block.attention)
            bias = (attention.age_bias[:, past_age] + past_mask)[:, None, :]
            out, key, value = block.step(tokens.transpose(0, 1), past_k[k], past_v[k], bias)
            tokens = out.transpose(0, 1)
            new_k.append(key)
            new_v.append(value)
        pose = self.regress(self.norm(tokens).flatten(-2)).unflatten(-1, (NUM_JOINTS, 6))
        return pose, torch.stack(new_k), torch.stack(new_v)


class StreamingStep(nn.Module):
    """AvatarJlmNet.step as a module's forward, for the ONNX export the runtime runs."""

    def __init__(self, net: AvatarJlmNet) -> None:
        super().__init__()
        self.net = net

    def forward(self, x, past_k, past_v, past_age, past_mask):
        return self.net.step(x, past_k, past_v, past_age, past_mask)


def world_positions(pose6: torch.Tensor, yaw: torch.Tensor, head: torch.Tensor, offsets: torch.Tensor):
    """(..., 22, 3) joint positions on the canonical body, rotated out of the heading frame
    (yaw (..., 3, 3)) and placed by head alignment (head (..., 3), world)."""
    local = sixd_to_matrix(pose6)
    local = torch.cat([yaw[..., None, :, :] @ local[..., :1, :, :], local[..., 1:, :, :]], dim=-3)
    _, pos = forward_kinematics(local, torch.zeros(local.shape[:-3] + (3,)), offsets)
    return pos - pos[..., HEAD : HEAD + 1, :] + head[..., None, :]


def rotation_error(pose6: torch.Tensor, target6: torch.Tensor, space: str) -> torch.Tensor:
    """(..., n) per joint, the network's 6D against the target's: L1 on the raw vectors (6d), or
    the angle of the turn between the rotations they stand for, over 3 so that a small turn
    weighs as on 6d (matrix). The angle pulls as hard at 170 degrees as at 10; L1 pulls a turn
    past 135 degrees on toward the half turn (on unit vectors, 2 (1 - cos a) + 2 |sin a|)."""
    if space == "matrix":
        # atan2 of the turn's sine and cosine, not roma.rotmat_geodesic_distance (validate's):
        # its asin has no finite slope at the half turn, and its norm none at zero
        m = sixd_to_matrix(target6).transpose(-1, -2) @ sixd_to_matrix(pose6)  # the turn between them
        skew = torch.stack([m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]], -1)
        sin = skew.square().sum(-1).clamp_min(1e-12).sqrt() / 2
        cos = (m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2] - 1) / 2
        return torch.atan2(sin, cos) / 3
    return (pose6 - target6).abs().mean(-1)


def losses(net: AvatarJlmNet, batch: dict[str, torch.Tensor], token_mask: torch.Tensor | None = None):
    """The paper's terms (Section 3.3) on every frame of the windows, and their weighted sum.
    One deviation: the foot-height term pulls the feet to the true feet's height in contact
    (our toe joints sit a few centimetres above the floor), not to the floor itself; and one
    option, rotation_loss (the rotation terms on the matrices)."""
    c = net.config
    pose, init = net(batch["x"], token_mask)
    target = batch["pose"]  # (B, W, 22, 6), root in the heading frame
    l_first = rotation_error(init, target, c.rotation_loss).mean()
    l_ori = rotation_error(pose[..., :1, :], target[..., :1, :], c.rotation_loss).mean()
    l_rot = rotation_error(pose[..., 1:, :], target[..., 1:, :], c.rotation_loss).mean()
    p = world_positions(pose, batch["yaw"], batch["head"], net.offsets)
    g = world_positions(target, batch["yaw"], batch["head"], net.offsets)  # the same head: noise is not the network's
    l_pos = (p - g).abs().mean()
    l_hand = (p[..., HANDS, :] - g[..., HANDS, :]).abs().mean()
    l_vel = sum(((p[:, s:] - p[:, :-s]) - (g[:, s:] - g[:, :-s])).abs().mean() for s in (1, 3, 5))
    contact = batch["contact"][:, 1:]  # (B, W - 1, 4): each foot joint still and low
    l_contact = ((p[:, 1:, FEET] - p[:, :-1, FEET]).abs() * contact[..., None]).mean()
    l_ground = torch.relu(-p[..., 2]).mean()
    l_height = ((p[..., FEET, 2] - g[..., FEET, 2]).abs() * batch["contact"]).mean()
    total = (
        l_first
        + c.beta * l_ori
        + c.gamma * l_rot
        + c.delta * l_pos
        + c.epsilon * l_hand
        + c.zeta * (l_vel + l_contact)
        + l_ground
        + c.alpha * l_height
    )
    terms = {}
    if c.leg_weight:
        terms["leg"] = (leg_positions(pose, net.offsets) - leg_positions(target, net.offsets)).abs().mean()
        total = total + c.leg_weight * terms["leg"]
    return {
        "total": total,
        "first": l_first,
        "orientation": l_ori,
        "rotation": l_rot,
        "position": l_pos,
        "hand": l_hand,
        "velocity": l_vel,
        "contact": l_contact,
        "ground": l_ground,
        "foot_height": l_height,
        **terms,
    }


def leg_positions(pose6: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
    """(..., 8, 3): the lower body's joints in the root's own frame, the root at the origin."""
    local = sixd_to_matrix(pose6)
    local = torch.cat([torch.eye(3).expand_as(local[..., :1, :, :]), local[..., 1:, :, :]], dim=-3)
    _, pos = forward_kinematics(local, torch.zeros(local.shape[:-3] + (3,)), offsets)
    return pos[..., LEGS, :]
