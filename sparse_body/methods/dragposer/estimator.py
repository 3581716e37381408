"""DragPoser (Ponton et al. 2024) at runtime: a pose is a point in the VAE's latent space, moved
each frame until the constraints hold. No torch: the decoder runs in ONNX Runtime.

Variables: the latent z (24), the root position (3) and the heading (1). Each iteration is
one Levenberg-Marquardt (damped Gauss-Newton) step on the weighted constraint residuals,
plus priors that keep z plausible: stay near the previous frame's z, the temporal
predictor's latent for this frame (temporal.py; from a second of history on) and
the tracker prior's guess from the trackers' recent motion (tracker_prior.py;
ours), and near the Gaussian's centre. The Jacobian comes from
ONE batched decoder pass over z and its 24 perturbations (forward differences), and batched
numpy FK; the paper backpropagates through the decoder instead, one gradient step per
iteration (train/dragposer/torch_reference.py keeps that as the reference).

Any sensor subset works without retraining: each tracker that has a usable sample this
frame becomes a Position and/or Orientation constraint on its joint, a missing one simply
is not there; user constraints (feet above the floor, look-at, angle limits) are added and
removed through `constraints`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...core.body_ik import solve_body
from ...core.contacts import FOOT_JOINTS, ToeContacts
from ...core.kinematics import forward_kinematics
from ...core.rotations import heading, rotations_to_quat, yaw_matrix
from ...core.sensors import SITE_JOINTS
from ...core.skeleton import JOINT_INDEX as J
from ...core.skeleton import Skeleton, body_scale
from ...core.types import BodyPose, TrackerFrame
from ...estimators.base import Estimator
from ...estimators.onnx_model import load_model
from .constraints import AboveFloor, ConstraintSet, Orientation, OverPoint, Position
from .options import DragPoserOptions
from .pose import HEIGHT_JOINTS, LATENT, dual_quaternions, split_heading
from .search import CompiledSearch
from .temporal import TemporalPrior
from .tracker_prior import FILE as TRACKER_PRIOR_FILE
from .tracker_prior import TrackerPrior

HEIGHT_INDEX = [J[j] for j in HEIGHT_JOINTS]
MODEL_FILES = ("dragposer_encoder.onnx", "dragposer_decoder.onnx", "dragposer_temporal.onnx", TRACKER_PRIOR_FILE)
# the root's children and the tracked end that the IK reaches through each
ROOT_CHAINS = {J["left_hip"]: J["left_ankle"], J["right_hip"]: J["right_ankle"], J["spine1"]: J["head"]}
END_JOINTS = frozenset(J[j] for j in ("head", "left_wrist", "right_wrist", "left_ankle", "right_ankle"))


def default_model_dir() -> Path:
    from ...core.resources import models_dir

    return models_dir()


class PoseVaeRuntime:
    """The exported decoder (and encoder, to start from a given pose)."""

    def __init__(self, model_dir: str | Path | None = None, threads: int = 1) -> None:
        self.dir = Path(model_dir) if model_dir else default_model_dir()
        hint = "train one with `sparse-body train dragposer`"
        self.decoder, _ = load_model(
            self.dir / "dragposer_decoder.onnx", ("method", "dragposer"), {"latent": LATENT}, hint, threads
        )
        self.encoder, _ = load_model(
            self.dir / "dragposer_encoder.onnx", ("method", "dragposer"), {"dual_quaternions": None}, hint, threads
        )

    def decode(self, z: np.ndarray) -> np.ndarray:
        """(B, 24) -> heading-free local rotations (B, 22, 3, 3)."""
        out = self.decoder.run(None, {"latent": np.asarray(z, np.float32).reshape(-1, LATENT)})[0]
        return out.astype(np.float64)

    def encode(self, local_rot: np.ndarray, root_height: float, offsets: np.ndarray) -> np.ndarray:
        """One pose's local rotations (22, 3, 3) -> its latent (24)."""
        free, _ = split_heading(local_rot[None])
        return self.encode_free(free, np.array([root_height]), offsets)[0].astype(np.float64)

    def encode_free(
        self, free: np.ndarray, root_height: np.ndarray, offsets: np.ndarray, chunk: int = 4096
    ) -> np.ndarray:
        """Heading-free local rotations (T, 22, 3, 3) and root heights (T,) -> latents (T, 24),
        float32, `chunk` poses an encoder pass."""
        out = []
        for i in range(0, len(free), chunk):
            dq = dual_quaternions(free[i : i + chunk].astype(np.float64), root_height[i : i + chunk], offsets)
            out.append(self.encoder.run(None, {"dual_quaternions": dq.astype(np.float32)})[0])
        return np.concatenate(out)


class LatentOptimizer:
    """Levenberg-Marquardt over (z, root position, heading) for a constraint set."""

    # Priors: weak. They only break ties the constraints leave open; stronger ones pulled the
    # end effectors off their trackers (02_05, six-point: 5 cm at 0.05 / 0.01, 0.9 cm here).
    def __init__(
        self,
        vae: PoseVaeRuntime,
        offsets: np.ndarray,
        damping: float = 1e-2,
        prior_weight: float = 0.001,
        latent_weight: float = 0.0002,
        eps: float = 1e-3,
    ) -> None:
        self.vae, self.offsets = vae, offsets
        self.damping, self.prior_weight, self.latent_weight, self.eps = damping, prior_weight, latent_weight, eps
        self.lam = damping
        self.last_jacobian: np.ndarray | None = None  # the last step's

    def predicted_gain(self, r: np.ndarray) -> float:
        """How much the next step from residual r would lower the cost r.r, by the linear
        model of the last step's Jacobian (search._predicted_gain)."""
        jac = self.last_jacobian
        if jac is None:
            return np.inf
        h, g = jac.T @ jac, jac.T @ r
        step = -np.linalg.solve(h + self.lam * np.diag(np.diag(h) + 1e-9), g)
        return float(-(2.0 * g @ step + step @ h @ step))

    def pose(self, z, root, yaw, decoded=None):
        """local, global rotations and positions of one pose (or a batch: z (B, 24) ...)."""
        if decoded is None:
            decoded = self.vae.decode(z)[0] if np.ndim(z) == 1 else self.vae.decode(z)
        free = decoded
        local = free.copy()
        local[..., 0, :, :] = yaw_matrix(np.asarray(yaw))[..., :, :] @ free[..., 0, :, :]
        glob, pos = forward_kinematics(local, root, self.offsets)
        return local, glob, pos

    def residuals(self, constraints: ConstraintSet, z, root, yaw, z_prior, decoded=None, prior_weight=None):
        local, glob, pos = self.pose(z, root, yaw, decoded)
        r = constraints.residual(glob, pos, local)
        w = self.prior_weight if prior_weight is None else prior_weight
        priors = np.concatenate([np.sqrt(w) * (z - z_prior), np.sqrt(self.latent_weight) * z], -1)
        return np.concatenate([r, priors], -1)

    def step(self, constraints, z, root, yaw, z_prior, prior_weight=None):
        """One Levenberg-Marquardt step; returns the new (z, root, yaw) and their residual."""
        n = LATENT + 4
        e = self.eps
        zs = np.repeat(z[None], LATENT + 1, axis=0)
        zs[1:] += e * np.eye(LATENT)
        decoded = self.vae.decode(zs)  # the one batched decoder pass
        # poses: base, z perturbations, root x/y/z perturbations, heading perturbation
        Z = np.concatenate([zs, np.repeat(z[None], 4, 0)])
        R = np.repeat(root[None], n + 1, 0)
        R[LATENT + 1 : LATENT + 4] += e * np.eye(3)
        Y = np.full(n + 1, yaw)
        Y[-1] += e
        D = np.concatenate([decoded, np.repeat(decoded[:1], 4, 0)])
        res = self.residuals(constraints, Z, R, Y, z_prior[None], decoded=D, prior_weight=prior_weight)
        r0 = res[0]
        jac = (res[1:] - r0).T / e  # (m, 28)
        h, g = jac.T @ jac, jac.T @ r0
        self.last_jacobian = jac
        cost = r0 @ r0
        # Levenberg-Marquardt: a step that does not lower the cost is refused, with more damping
        for _ in range(6):
            delta = -np.linalg.solve(h + self.lam * np.diag(np.diag(h) + 1e-9), g)
            cand = (z + delta[:LATENT], root + delta[LATENT : LATENT + 3], yaw + delta[-1])
            r1 = self.residuals(constraints, *cand, z_prior, prior_weight=prior_weight)
            if np.all(np.isfinite(r1)) and r1 @ r1 < cost:
                self.lam = max(self.lam / 3, 1e-6)
                return (*cand, r1)
            self.lam = min(self.lam * 4, 1e6)
        return z, root, yaw, r0


class DragPoserEstimator(Estimator):
    name = "dragposer"
    Options = DragPoserOptions
    options: DragPoserOptions

    def __init__(self, sensors, skeleton, fps: float = 60.0, **options) -> None:
        super().__init__(sensors, skeleton, fps, **options)
        o = self.options
        model_dir: str | None = None
        model_path, threads = o.model_path, o.threads
        if model_path:  # the folder, or one of its files
            if not Path(model_path).is_dir() and Path(model_path).name not in MODEL_FILES:
                raise ValueError(
                    f"{model_path}: not a DragPoser model; name the folder holding "
                    f"{', '.join(MODEL_FILES)} (or one of them)"
                )
            model_dir = model_path if Path(model_path).is_dir() else str(Path(model_path).parent)
        self.vae = PoseVaeRuntime(model_dir, threads)
        # the temporal predictor's pull on the latent (the paper's lambda_T); 0: without it
        self.temporal_weight = o.temporal_weight
        self.temporal = (
            TemporalPrior(self.vae.dir, o.ahead, threads, o.temporal_ramp) if o.temporal_weight > 0 else None
        )
        # the tracker prior's pull on the latent (ours; tracker_prior.py); 0: without it
        self.tracker_weight = o.tracker_prior
        self.guesser = TrackerPrior(self.vae.dir, fps, threads) if o.tracker_prior > 0 else None
        self.optimizer = LatentOptimizer(self.vae, skeleton.offsets, o.damping, o.prior_weight, o.latent_weight, o.eps)
        # the same steps compiled (search.py); None: the decoder is not the MLP it knows, or
        # compiled=False asks for the ONNX Runtime search it is tested against
        self.search = CompiledSearch.of(self.vae, skeleton.offsets, skeleton.parents, threads) if o.compiled else None
        # the paper's stopping rule: positional and rotational thresholds on the trackers
        self.iterations, self.tolerance, self.rotation_tolerance = o.iterations, o.tolerance, o.rotation_tolerance
        # The trackers are seldom met within `tolerance` (a VAE with 1.6 cm reconstruction
        # error cannot always close it; the polish does): from the previous frame's state the
        # first step does the work and the next lower the cost by 0.03 % and 0.0003 % (six-
        # and four-point walk). Where the step's own Jacobian predicts the next one to lower
        # the cost by less than this share, the search ends without computing another.
        self.cost_tolerance = o.cost_tolerance
        self.weights = (o.position_weight, o.orientation_weight)
        self.polish = o.polish
        self.pelvis_orientation = o.pelvis_orientation
        self.root_prior = o.root_prior
        self.floor = floor_height = o.floor_height
        self.constraints = ConstraintSet()  # the user's, kept across frames
        if floor_height is not None:
            for foot in FOOT_JOINTS:
                self.constraints.add(AboveFloor(foot, 1.0, name=f"floor:{foot}", height=floor_height), builtin=True)
        self._head_above_pelvis = skeleton.rest_positions()[J["head"]]
        self._scale = body_scale(skeleton)
        self._canonical_offsets = Skeleton.canonical().offsets
        self.iterations_used: list[int] = []
        self.reset()

    def _reset(self) -> None:
        self._state: tuple[np.ndarray, np.ndarray, float] | None = None  # (z, root, yaw)
        self._toes = ToeContacts(self.fps)  # contacts from the toes frame to frame
        if self.temporal is not None:
            self.temporal.reset()
        if self.guesser is not None:
            self.guesser.reset()

    def tracker_targets(self, frame: TrackerFrame) -> dict:
        """site -> its joint's (position, rotation) this frame, or None (Estimator.joint_target)."""
        return {site: self.joint_target(frame, site) for site in self.sensors.site_names}

    def tracker_constraints(self, frame: TrackerFrame, targets: dict | None = None) -> ConstraintSet:
        out = ConstraintSet()
        targets = self.tracker_targets(frame) if targets is None else targets
        for site, target in targets.items():
            if target is None:
                continue
            joint = J[SITE_JOINTS[site]]
            if target[0] is not None:
                out.add(Position(joint, self.weights[0], name=f"{site}:position", target=tuple(target[0])))
            if target[1] is not None:
                out.add(Orientation(joint, self.weights[1], name=f"{site}:orientation", target=target[1]))
        pelvis, head = targets.get("pelvis"), targets.get("head")
        if (
            self.root_prior > 0
            and (pelvis is None or pelvis[0] is None)
            and head is not None
            and head[0] is not None
            and head[1] is not None
        ):
            out.add(self._under_head(*head))
        return out

    def _under_head(self, head_position: np.ndarray, head_rotation: np.ndarray) -> OverPoint:
        """Without a pelvis tracker the search is free to slide the root under a leaning
        spine: the root_prior pulls it over the point where a standing body's pelvis hangs
        below the headset, as the IK places it (ours, not the paper's). On the validation
        people, three-point, it took MPJPE from 16.0 to 12.9 cm and the root from 17.1 to 9.8
        (`models/dragposer.root_prior.json`); most of the gain is on clips whose root the
        search had put 30-40 cm off."""
        hang = np.asarray(head_position, float) - yaw_matrix(float(heading(head_rotation))) @ self._head_above_pelvis
        return OverPoint(J["pelvis"], self.root_prior, name="pelvis:under_head", target=tuple(hang[:2]))

    def _initial_state(self, trackers: ConstraintSet, latent: np.ndarray | None = None):
        by_name = {c.name: c for c in trackers}
        yaw = 0.0
        for site in ("pelvis", "head"):
            if f"{site}:orientation" in by_name:
                yaw = float(heading(by_name[f"{site}:orientation"].target))
                break
        if "pelvis:position" in by_name:
            root = np.array(by_name["pelvis:position"].target)
        elif "head:position" in by_name:
            root = np.array(by_name["head:position"].target) - yaw_matrix(yaw) @ self._head_above_pelvis
        else:
            points = [np.array(c.target) for c in trackers if isinstance(c, Position)]
            if not points:
                return None
            root = np.mean(points, axis=0)
        return (np.zeros(LATENT) if latent is None else latent), root, yaw

    def refine(self, pose: BodyPose, frame: TrackerFrame) -> BodyPose:
        """Another estimator's pose, moved in the latent space until the trackers' (and the
        user's) constraints hold: the pose is encoded to start the search and stays the prior,
        so what the constraints do not decide keeps the other estimator's answer."""
        if not pose.is_finite():
            return self.held_pose(frame.stamp)
        from ...core.rotations import quat_to_matrix

        local = quat_to_matrix(pose.local_quats)
        yaw = float(heading(local[0]))
        height = (pose.root_position[2] - (self.floor or 0.0)) * self._scale
        z = self.vae.encode(local, height, self._canonical_offsets)
        return self._checked(
            frame.stamp, self._solve(frame, (z, np.asarray(pose.root_position, float), yaw), z_prior=z)
        )

    def _estimate(self, frame: TrackerFrame) -> BodyPose | None:
        targets = self.tracker_targets(frame)
        trackers = self.tracker_constraints(frame, targets)
        guess = self._guess(targets)  # every frame: the GRU keeps its state
        if self._state is None:
            return self._solve(frame, None, trackers=trackers, observe=True, start=guess)
        # Every pull at once: sum_k w_k |z - z_k|^2 is one quadratic with the weights' sum,
        # centred at their weighted mean. The paper's single gradient step a frame keeps z
        # near z_prev by itself; a Gauss-Newton step needs the term said.
        pulls = [(self.optimizer.prior_weight, self._state[0])]
        prediction = None if self.temporal is None else self.temporal.target()
        if prediction is not None:
            pulls.append((self.temporal_weight, prediction))
        if guess is not None:
            pulls.append((self.tracker_weight, guess))
        total = sum(w for w, _ in pulls)
        centre = sum(w * z for w, z in pulls) / total
        return self._solve(frame, self._state, centre, total, trackers=trackers, observe=True)

    def _guess(self, targets: dict) -> np.ndarray | None:
        """The tracker prior's latent for this frame, from the targets on the canonical body."""
        if self.guesser is None:
            return None
        lift = np.array([0.0, 0.0, self.floor or 0.0])
        return self.guesser.predict(
            {
                site: None if t is None or t[0] is None else ((t[0] - lift) * self._scale, t[1])
                for site, t in targets.items()
            }
        )

    def _polish(self, local, root, trackers: ConstraintSet):
        """Put the tracked pelvis and end effectors exactly on their trackers (ours, not the
        paper's): the latent search stops within its tolerance and a VAE with 1.6 cm
        reconstruction error cannot always close the last centimetre. The root moves onto the
        pelvis tracker and (pelvis_orientation) takes its orientation: the search weighs
        orientations at a tenth of positions, and a pelvis a few degrees off moves the hips by
        centimetres (chosen on the validation people: models/dragposer.pelvis_*.json).
        A leg or spine whose end is not tracked keeps its decoded direction; the shared
        closed-form IK then turns the spine towards the head and reaches each tracked hand and
        foot, keeping the decoded elbows, knees and spine curve (a decoded elbow is seldom an
        exact hinge) and only turning them. The latent state stays as the search left it, so
        this does not steer later frames."""
        root = np.array(root, float)
        positions = [c for c in trackers if isinstance(c, Position)]
        for c in positions:
            if c.joint == J["pelvis"]:
                root = np.array(c.target, float)
        goals = {c.joint: np.asarray(c.target, float) for c in positions if c.joint in END_JOINTS}
        pelvis = next((c.target for c in trackers if isinstance(c, Orientation) and c.joint == J["pelvis"]), None)
        if self.pelvis_orientation and pelvis is not None:  # and turns with it: the hips hang from it
            local = local.copy()
            for child, end in ROOT_CHAINS.items():
                if end not in goals:  # an untracked leg or spine keeps its decoded direction
                    local[child] = pelvis.T @ local[0] @ local[child]
            local[0] = pelvis  # a tracked one turns with the pelvis, then reaches
        if goals:
            local, glob, _ = solve_body(local, root, self.skeleton.offsets, goals, keep_shape=True)
        else:
            glob, _ = forward_kinematics(local, root, self.skeleton.offsets)
        return local, glob, root

    def _search(self, constraints, z, root, yaw, z_prior, prior_weight, iterations):
        """Levenberg-Marquardt steps until the trackers are met or `iterations` are spent:
        (z, root, yaw, steps used)."""
        opt = self.optimizer
        weight = opt.prior_weight if prior_weight is None else prior_weight
        if self.search is not None:
            return self.search.run(
                constraints, z, root, yaw, z_prior, prior_weight=weight, latent_weight=opt.latent_weight,
                damping=opt.damping, eps=opt.eps, iterations=iterations, position_tol=self.tolerance,
                rotation_tol=self.rotation_tolerance, skip=END_JOINTS, cost_tolerance=self.cost_tolerance,
            )  # fmt: skip
        opt.lam = opt.damping
        used = 0
        for used in range(1, iterations + 1):  # noqa: B007 - the count after the loop is the point
            before = z
            z, root, yaw, r0 = opt.step(constraints, z, root, yaw, z_prior, weight)
            if constraints.converged(r0, self.tolerance, self.rotation_tolerance, END_JOINTS):
                break
            if z is not before and opt.predicted_gain(r0) < self.cost_tolerance * (r0 @ r0):
                break
        return z, root, yaw, used

    def _solve(
        self,
        frame: TrackerFrame,
        state,
        z_prior=None,
        prior_weight=None,
        observe=False,
        trackers: ConstraintSet | None = None,
        start: np.ndarray | None = None,
    ) -> BodyPose | None:
        """One frame's search from state (z, root, yaw), or from a standing start (latent
        `start`, else the Gaussian's centre) when state is None."""
        trackers = self.tracker_constraints(frame) if trackers is None else trackers
        if not len(trackers):
            return None
        first = state is None
        state = state or self._initial_state(trackers, start)
        if state is None:
            return None
        constraints = ConstraintSet()
        for c in list(trackers) + list(self.constraints):
            constraints.add(c)
        z, root, yaw = state
        z_prior = z.copy() if z_prior is None else z_prior
        iterations = 10 * self.iterations if first else self.iterations
        z, root, yaw, used = self._search(constraints, z, root, yaw, z_prior, prior_weight, iterations)
        self.iterations_used.append(used)
        if not (np.all(np.isfinite(z)) and np.all(np.isfinite(root)) and np.isfinite(yaw)):
            self.reset()
            return None
        self._state = (z, root, float(yaw))
        local, glob, pos = (self.search or self.optimizer).pose(z, root, yaw)
        if observe and self.temporal is not None:  # the search's pose: its heights belong to z
            heights = pos[HEIGHT_INDEX, 2] - (self.floor or 0.0)
            self.temporal.observe(z, np.asarray(root) * self._scale, yaw, heights * self._scale)
        if self.polish:
            local, glob, root = self._polish(local, root, trackers)
        # End joints take their trackers' orientation exactly, as the IK does: it moves only
        # what hangs below them (hands, toes), and the VAE alone leaves 5-10 degrees there.
        for c in trackers:
            if isinstance(c, Orientation) and c.joint in END_JOINTS:
                local[c.joint] = glob[self.skeleton.parents[c.joint]].T @ c.target
        _, pos = forward_kinematics(local, root, self.skeleton.offsets)
        toes = pos[list(FOOT_JOINTS)]
        contact = self._toes(toes, self.floor or 0.0)
        return BodyPose(
            frame.stamp, rotations_to_quat(local), np.asarray(root, float), self._toes.probability.copy(), contact
        )
