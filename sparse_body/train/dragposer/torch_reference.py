"""The paper's pose optimiser in torch, kept as the reference for the ONNX Runtime one.

Same variables (latent, root position, heading), same constraint residuals (the Constraint
classes run on torch tensors), same priors; the difference is the search: plain autograd
gradients through the decoder and an optimiser step (the paper uses a fixed-size gradient
step), instead of a damped Gauss-Newton step with a finite-difference Jacobian. Run long
enough, both must land on the same pose: test_dragposer checks it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnx
import torch
from onnx import numpy_helper

from ...methods.dragposer.constraints import ConstraintSet
from ...train.torch_body import forward_kinematics, sixd_to_matrix
from .vae_model import PoseVae, VaeConfig


def load_vae(model_dir: Path) -> PoseVae:
    """The decoder's weights back from its ONNX file (no pickle anywhere)."""
    import json

    model = onnx.load(str(Path(model_dir) / "dragposer_decoder.onnx"))
    meta = {p.key: json.loads(p.value) for p in model.metadata_props}
    vae = PoseVae(VaeConfig(**meta["config"])).double()
    weights = {i.name: numpy_helper.to_array(i) for i in model.graph.initializer}
    state = vae.state_dict()
    for name in [n for n in state if n.startswith("decoder.")]:
        if f"vae.{name}" not in weights:
            raise ValueError(f"{model_dir}: the decoder has no weight {name}")
        state[name] = torch.from_numpy(np.array(weights[f"vae.{name}"], dtype=np.float64))
    vae.load_state_dict(state)
    return vae.eval()


def optimise(
    vae: PoseVae,
    constraints: ConstraintSet,
    offsets: np.ndarray,
    z,
    root,
    yaw,
    z_prior,
    prior_weight: float = 0.001,
    latent_weight: float = 0.0002,
    iterations: int = 2000,
    lr: float = 0.01,
    tolerance: float = 0.0,
    rotation_tolerance: float = 0.087,
    stats: dict | None = None,
    skip_orientation: frozenset = frozenset(),
):
    """Minimise the same objective as methods.dragposer.estimator.LatentOptimizer with Adam; stop early
    once the trackers are met as in ConstraintSet.converged (stats["iterations"] says when)."""
    offsets_t = torch.as_tensor(offsets, dtype=torch.float64)
    z = torch.tensor(z, dtype=torch.float64, requires_grad=True)
    root = torch.tensor(root, dtype=torch.float64, requires_grad=True)
    yaw = torch.tensor(float(yaw), dtype=torch.float64, requires_grad=True)
    z_prior = torch.as_tensor(z_prior, dtype=torch.float64)
    opt = torch.optim.Adam([z, root, yaw], lr=lr)
    # annealed so the last steps settle instead of circling the minimum
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(opt, iterations)
    used = 0
    for used in range(1, iterations + 1):  # noqa: B007 - the count after the loop is the point
        free = sixd_to_matrix(vae.decode(z[None]).unflatten(-1, (22, 6)))[0]
        c, s = torch.cos(yaw), torch.sin(yaw)
        zero, one = torch.zeros_like(c), torch.ones_like(c)
        rz = torch.stack([torch.stack([c, -s, zero]), torch.stack([s, c, zero]), torch.stack([zero, zero, one])])
        local = torch.cat([(rz @ free[0])[None], free[1:]])
        glob, pos = forward_kinematics(local, root, offsets_t)
        r = constraints.residual(glob, pos, local, xp=torch)
        if tolerance and constraints.converged(r.detach().numpy(), tolerance, rotation_tolerance, skip_orientation):
            break
        loss = (r**2).sum() + prior_weight * ((z - z_prior) ** 2).sum() + latent_weight * (z**2).sum()
        opt.zero_grad()
        loss.backward()
        opt.step()
        schedule.step()
    if stats is not None:
        stats["iterations"] = used
    return z.detach().numpy(), root.detach().numpy(), float(yaw)
