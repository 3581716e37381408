"""DragPoser's latent search compiled (numba): one call a frame instead of a few hundred.

The ONNX Runtime search (estimator.LatentOptimizer) spent a frame of 3 iterations in about
10 decoder calls and 4,000 small numpy calls (issue 52's profile: 3 ms p50). Here the same
Levenberg-Marquardt steps run in one compiled function:

- the decoder's Jacobian in closed form: it is an MLP (Linear, ELU, Linear, ELU, Linear), so
  d(6D)/dz = W3 diag(elu'(a2)) W2 diag(elu'(a1)) W1, one 256x256x24 product (forward mode);
- the rest of the chain (6D to rotation, forward kinematics, constraint residuals) by forward
  differences on the linearised decoder output, 29 small forward kinematics in compiled loops;
- the same priors, damping schedule, refused steps and stopping rule as LatentOptimizer.

The weights are read from the decoder's ONNX file (the model stays one artefact); a decoder
that is not that MLP falls back to the ONNX Runtime search. Parity with it: test_search.py.
Constraints travel as arrays (`pack`): a kind, joint, weight and up to 9 numbers each.
"""

from __future__ import annotations

import math
from functools import cache
from pathlib import Path

import numpy as np

from ...core.mat3 import njit, njit_nogil
from ...estimators.onnx_graph import read_graph
from .constraints import AboveFloor, AngleLimit, ConstraintSet, LookAt, Orientation, OverPoint, Position
from .pose import DECODER_OUTPUT

KINDS = {Position: 0, OverPoint: 1, Orientation: 2, AboveFloor: 3, LookAt: 4, AngleLimit: 5}
SIZES = np.array([3, 2, 3, 1, 3, 1])
DATA = 9  # numbers a constraint carries: an orientation's matrix is the largest


def pack(constraints: ConstraintSet) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """kinds, joints, weights and data (n, 9) of a constraint set, in its order."""
    items = list(constraints)
    kinds = np.array([KINDS[type(c)] for c in items], dtype=np.int64)
    joints = np.array([int(c.joint) for c in items], dtype=np.int64)
    weights = np.array([float(c.weight) for c in items])
    data = np.zeros((len(items), DATA))
    for i, c in enumerate(items):
        if isinstance(c, (Position, OverPoint)):
            target = np.asarray(c.target, float)
            data[i, : len(target)] = target
        elif isinstance(c, Orientation):
            data[i] = np.asarray(c.target, float).reshape(9)
        elif isinstance(c, AboveFloor):
            data[i, 0] = c.height
        elif isinstance(c, LookAt):
            data[i, :3], data[i, 3:6] = np.asarray(c.target, float), np.asarray(c.axis, float)
        else:  # AngleLimit: 3 - trace is 2 (1 - cos angle); the bound on it
            data[i, 0] = 2.0 * (1.0 - math.cos(c.max_angle))
    return kinds, joints, weights, data


def mlp_weights(decoder_file: Path) -> tuple[np.ndarray, ...] | None:
    """(W1, b1, W2, b2, W3, b3) of a decoder that is Linear-ELU-Linear-ELU-Linear (ELU's alpha 1)
    from its input `latent`, then the 6D-to-matrix tail, as float64; None for any other graph."""
    graph = read_graph(decoder_file)
    ops = [n for n in graph.nodes if n.op_type != "Constant"]
    chain = ops[:5]
    if graph.inputs != ("latent",) or [n.op_type for n in ops[:6]][:5] != ["Gemm", "Elu", "Gemm", "Elu", "Gemm"]:
        return None  # a graph of another shape: the ONNX Runtime search runs it
    if len(ops) > 5 and ops[5].op_type == "Gemm":
        return None
    if chain[0].inputs[0] != "latent" or any(chain[k + 1].inputs[0] != chain[k].outputs[0] for k in range(4)):
        return None
    if any(abs(n.attributes.get("alpha", 1.0) - 1.0) > 1e-6 for n in chain[1::2]):
        return None
    out = []
    for n in chain[::2]:
        a = n.attributes
        if a.get("transA", 0) or a.get("alpha", 1.0) != 1.0 or a.get("beta", 1.0) != 1.0:
            return None
        if len(n.inputs) != 3 or n.inputs[1] not in graph.weights or n.inputs[2] not in graph.weights:
            return None
        w = np.asarray(graph.weights[n.inputs[1]], np.float64)
        out += [
            np.ascontiguousarray(w if a.get("transB", 0) else w.T),
            np.asarray(graph.weights[n.inputs[2]], np.float64),
        ]
    if out[-2].shape[0] != DECODER_OUTPUT or any(out[2 * k + 1].shape != out[2 * k].shape[:1] for k in range(3)):
        return None
    return tuple(out)


@njit
def _elu(a, slope):
    """ELU of a, its derivative written into slope."""
    out = np.empty_like(a)
    for i in range(len(a)):
        if a[i] > 0:
            out[i], slope[i] = a[i], 1.0
        else:
            e = math.exp(a[i])
            out[i], slope[i] = e - 1.0, e
    return out


@njit
def decode_sixd(z, w1, b1, w2, b2, w3, b3):
    """The decoder's 6D output (132,) at z."""
    slope1, slope2 = np.empty_like(b1), np.empty_like(b2)
    return w3 @ _elu(w2 @ _elu(w1 @ z + b1, slope1) + b2, slope2) + b3


@njit
def decode_jacobian(z, w1, b1, w2, b2, w3, b3):
    """The decoder's Jacobian d(6D)/dz (132, 24) at z, forward mode. Called with float32
    weights: half the cost of the 256x256x24 product, and a Jacobian needs no more digits
    (the values themselves come from decode_sixd in float64)."""
    slope1, slope2 = np.empty_like(b1), np.empty_like(b2)
    h1 = _elu(w1 @ z + b1, slope1)
    _elu(w2 @ h1 + b2, slope2)
    t1 = w1 * slope1.reshape(-1, 1)
    t2 = (w2 @ t1) * slope2.reshape(-1, 1)
    return w3 @ t2


@njit
def _pose_into(sixd, root, yaw, offsets, parents, local, glob, pos) -> None:
    """Local and global rotations and positions (22, ...) of a decoder output (132,), the root
    turned by yaw and placed at root. 6D to rotation as core.rotations.sixd_to_matrix
    (Gram-Schmidt, columns a, b, a x b); forward kinematics as core.mat3's, without its
    allocations (this runs 30 times an iteration)."""
    for j in range(len(local)):
        ax, ay, az = sixd[6 * j], sixd[6 * j + 1], sixd[6 * j + 2]
        bx, by, bz = sixd[6 * j + 3], sixd[6 * j + 4], sixd[6 * j + 5]
        n = math.sqrt(ax * ax + ay * ay + az * az)
        ax, ay, az = ax / n, ay / n, az / n
        d = ax * bx + ay * by + az * bz
        bx, by, bz = bx - d * ax, by - d * ay, bz - d * az
        n = math.sqrt(bx * bx + by * by + bz * bz)
        bx, by, bz = bx / n, by / n, bz / n
        local[j, 0, 0], local[j, 0, 1], local[j, 0, 2] = ax, bx, ay * bz - az * by
        local[j, 1, 0], local[j, 1, 1], local[j, 1, 2] = ay, by, az * bx - ax * bz
        local[j, 2, 0], local[j, 2, 1], local[j, 2, 2] = az, bz, ax * by - ay * bx
    c, s = math.cos(yaw), math.sin(yaw)
    for k in range(3):  # the root: Rz(yaw) @ its heading-free rotation
        x, y = local[0, 0, k], local[0, 1, k]
        local[0, 0, k], local[0, 1, k] = c * x - s * y, s * x + c * y
    glob[0] = local[0]
    pos[0] = root
    for j in range(1, len(local)):  # parents come before their children
        p = parents[j]
        for r in range(3):
            pos[j, r] = (
                pos[p, r]
                + glob[p, r, 0] * offsets[j, 0]
                + glob[p, r, 1] * offsets[j, 1]
                + glob[p, r, 2] * offsets[j, 2]
            )
            for k in range(3):
                glob[j, r, k] = (
                    glob[p, r, 0] * local[j, 0, k] + glob[p, r, 1] * local[j, 1, k] + glob[p, r, 2] * local[j, 2, k]
                )


@njit
def _residual(kinds, joints, weights, data, local, glob, pos, out) -> None:
    """Each constraint's weighted residual into out, in order (constraints.py's definitions)."""
    i = 0
    for n in range(len(kinds)):
        k, j, w = kinds[n], joints[n], weights[n]
        if k == 0:  # Position
            for a in range(3):
                out[i + a] = w * (pos[j, a] - data[n, a])
        elif k == 1:  # OverPoint
            for a in range(2):
                out[i + a] = w * (pos[j, a] - data[n, a])
        elif k == 2:  # Orientation: vee(target^T glob); (target^T glob)[r, c] = t[:, r] . g[:, c]
            for a in range(3):
                r, c = (2, 0, 1)[a], (1, 2, 0)[a]
                upper = data[n, r] * glob[j, 0, c] + data[n, 3 + r] * glob[j, 1, c] + data[n, 6 + r] * glob[j, 2, c]
                lower = data[n, c] * glob[j, 0, r] + data[n, 3 + c] * glob[j, 1, r] + data[n, 6 + c] * glob[j, 2, r]
                out[i + a] = w * 0.5 * (upper - lower)
        elif k == 3:  # AboveFloor
            out[i] = w * max(data[n, 0] - pos[j, 2], 0.0)
        elif k == 4:  # LookAt
            dx, dy, dz = data[n, 0] - pos[j, 0], data[n, 1] - pos[j, 1], data[n, 2] - pos[j, 2]
            size = math.sqrt(dx * dx + dy * dy + dz * dz) + 1e-9
            for a in range(3):
                axis = glob[j, a, 0] * data[n, 3] + glob[j, a, 1] * data[n, 4] + glob[j, a, 2] * data[n, 5]
                out[i + a] = w * (axis - (dx, dy, dz)[a] / size)
        else:  # AngleLimit
            out[i] = w * max(3.0 - (local[j, 0, 0] + local[j, 1, 1] + local[j, 2, 2]) - data[n, 0], 0.0)
        i += SIZES[k]


@njit
def _residuals(sixd, root, yaw, z, z_prior, sw, sl, kinds, joints, weights, data, offsets, parents, buf, out):
    """The full residual (constraints, then the two latent priors) of one pose into out; buf:
    the pose's (local, glob, pos)."""
    local, glob, pos = buf
    _pose_into(sixd, root, yaw, offsets, parents, local, glob, pos)
    _residual(kinds, joints, weights, data, local, glob, pos, out)
    m, nz = len(out) - 2 * len(z), len(z)
    for a in range(nz):
        out[m + a] = sw * (z[a] - z_prior[a])
        out[m + nz + a] = sl * z[a]


@njit
def _converged(kinds, joints, weights, r, position_tol, rotation_sin_tol, skip) -> bool:
    """ConstraintSet.converged: trackers' positions and orientations within tolerance."""
    i = 0
    for n in range(len(kinds)):
        k, size, w = kinds[n], SIZES[kinds[n]], weights[n]
        if w != 0 and (k == 0 or (k == 2 and not skip[joints[n]])):
            err = 0.0
            for a in range(size):
                err += r[i + a] * r[i + a]
            err = math.sqrt(err) / w
            if (k == 0 and err > position_tol) or (k == 2 and err > rotation_sin_tol):
                return False
        i += size
    return True


@njit
def _damped(h, lam):
    """Levenberg-Marquardt's matrix: h with lam times its diagonal (and a floor) added."""
    a = h.copy()
    for d in range(len(h)):
        a[d, d] += lam * (h[d, d] + 1e-9)
    return a


@njit
def _predicted_gain(jac, h, r, lam) -> float:
    """How much the next damped Gauss-Newton step from residual r would lower the cost r.r,
    by the linear model of the last Jacobian: -(2 g.d + d.H.d) for g = J^T r."""
    g = jac.T @ r
    step = -np.linalg.solve(_damped(h, lam), g)
    return -(2.0 * (g @ step) + step @ (h @ step))


@njit_nogil
def search(
    z, root, yaw, z_prior, prior_weight, latent_weight, damping, iterations, eps, w, w32, offsets, parents,
    kinds, joints, weights, data, position_tol, rotation_sin_tol, skip, cost_tolerance,
):  # fmt: skip
    """Up to `iterations` Levenberg-Marquardt steps from (z, root, yaw), stopping once the
    trackers are met or the next step is predicted to lower the cost by less than
    cost_tolerance of it: (z, root, yaw, steps used). LatentOptimizer.step's algorithm;
    w: the decoder's weights in float64, w32 in float32."""
    nz = len(z)
    n = nz + 4
    m = 2 * nz
    for k in kinds:
        m += SIZES[k]
    nj = len(offsets)
    buf = (np.empty((nj, 3, 3)), np.empty((nj, 3, 3)), np.empty((nj, 3)))
    sw, sl = math.sqrt(prior_weight), math.sqrt(latent_weight)
    z, root = z.copy(), root.copy()
    zv, rv = z.copy(), root.copy()
    lam = damping
    r0, r1, rk = np.empty(m), np.empty(m), np.empty(m)
    jac = np.empty((m, n))
    sixd = decode_sixd(z, *w)
    _residuals(sixd, root, yaw, z, z_prior, sw, sl, kinds, joints, weights, data, offsets, parents, buf, r0)
    used = 0
    for used in range(1, iterations + 1):  # noqa: B007
        dsixd = decode_jacobian(z.astype(np.float32), *w32).astype(np.float64)
        for v in range(n):  # forward differences on the linearised decoder, root and heading
            zv[:], rv[:] = z, root
            if v < nz:
                zv[v] += eps
                sv = sixd + eps * dsixd[:, v]
                _residuals(sv, root, yaw, zv, z_prior, sw, sl, kinds, joints, weights, data, offsets, parents, buf, rk)
            else:
                if v < nz + 3:
                    rv[v - nz] += eps
                yv = yaw + eps if v == n - 1 else yaw
                _residuals(sixd, rv, yv, z, z_prior, sw, sl, kinds, joints, weights, data, offsets, parents, buf, rk)
            for i in range(m):
                jac[i, v] = (rk[i] - r0[i]) / eps
        h, g, cost = jac.T @ jac, jac.T @ r0, r0 @ r0
        moved = False
        for _ in range(6):  # a step that does not lower the cost is refused, with more damping
            delta = -np.linalg.solve(_damped(h, lam), g)
            zc, rc, yc = z + delta[:nz], root + delta[nz : nz + 3], yaw + delta[n - 1]
            sc = decode_sixd(zc, *w)
            _residuals(sc, rc, yc, zc, z_prior, sw, sl, kinds, joints, weights, data, offsets, parents, buf, r1)
            if np.all(np.isfinite(r1)) and r1 @ r1 < cost:
                lam = max(lam / 3, 1e-6)
                z, root, yaw, sixd, moved = zc, rc, yc, sc, True
                r0[:] = r1  # the next step starts where this one landed
                break
            lam = min(lam * 4, 1e6)
        if _converged(kinds, joints, weights, r0, position_tol, rotation_sin_tol, skip):
            break
        if moved and _predicted_gain(jac, h, r0, lam) < cost_tolerance * (r0 @ r0):
            break  # the next step would barely help: spare its Jacobian
    return z, root, yaw, used


@njit
def pose_of(z, root, yaw, w, offsets, parents):
    """Local and global rotations and joint positions of (z, root, yaw)."""
    nj = len(offsets)
    local, glob, pos = np.empty((nj, 3, 3)), np.empty((nj, 3, 3)), np.empty((nj, 3))
    _pose_into(decode_sixd(z, *w), root, yaw, offsets, parents, local, glob, pos)
    return local, glob, pos


@cache
def _blas():
    """The loaded BLAS libraries' thread pools (threadpoolctl): numba's products call
    scipy's OpenBLAS, whose helper threads, left at one per core, spin after each product and
    took a core from the ONNX Runtime worker and the node (issue 52: the tick frames' p99
    1.9 ms with them, 1.0 ms on one thread)."""
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


class CompiledSearch:
    """The search over one decoder and body; `run` is LatentOptimizer's loop of steps, on
    `threads` BLAS threads (the estimator's `threads`, as ONNX Runtime's)."""

    def __init__(
        self, weights: tuple[np.ndarray, ...], offsets: np.ndarray, parents: np.ndarray, threads: int = 1
    ) -> None:
        self.weights = weights
        self.weights32 = tuple(np.ascontiguousarray(a, np.float32) for a in weights)
        self.offsets = np.ascontiguousarray(offsets, np.float64)
        self.parents = np.ascontiguousarray(parents, np.int64)
        self.threads = threads

    @classmethod
    def of(cls, vae, offsets: np.ndarray, parents: np.ndarray, threads: int = 1) -> CompiledSearch | None:
        """The search over a PoseVaeRuntime's decoder, or None where its graph is not the MLP
        this knows or its poses differ from ONNX Runtime's (checked here on a few latents)."""
        weights = mlp_weights(vae.dir / "dragposer_decoder.onnx")
        if weights is None:
            return None
        out = cls(weights, offsets, parents, threads)
        zs = np.random.default_rng(0).normal(size=(4, weights[0].shape[1]))
        ours = np.array([out.pose(z, np.zeros(3), 0.0)[0] for z in zs])
        return out if np.abs(ours - vae.decode(zs)).max() < 1e-4 else None

    def run(
        self, constraints, z, root, yaw, z_prior, *, prior_weight, latent_weight, damping, eps,
        iterations, position_tol, rotation_tol, skip: frozenset, cost_tolerance,
    ):  # fmt: skip
        kinds, joints, weights, data = pack(constraints)
        skip_mask = np.zeros(len(self.offsets), dtype=np.bool_)
        for j in skip:
            skip_mask[j] = True
        with _blas().limit(limits=self.threads, user_api="blas"):
            z, root, yaw, used = search(
                np.asarray(z, np.float64), np.asarray(root, np.float64), float(yaw), np.asarray(z_prior, np.float64),
                float(prior_weight), float(latent_weight), float(damping), int(iterations), float(eps),
                self.weights, self.weights32, self.offsets, self.parents, kinds, joints, weights, data,
                float(position_tol), math.sin(rotation_tol), skip_mask, float(cost_tolerance),
            )  # fmt: skip
        return z, root, float(yaw), int(used)

    def pose(self, z, root, yaw):
        z, root = np.asarray(z, np.float64), np.asarray(root, np.float64)
        return pose_of(z, root, float(yaw), self.weights, self.offsets, self.parents)
