"""LoBSTr (Yang et al. 2021) at runtime: ONNX Runtime, one GRU step per frame.

The legs come from the network, driven by the velocities of pelvis, head and hands; contacts
are held by IK (core/contact_hold.py). The paper solves the upper body by IK from the same trackers
(Final IK); a model trained with the learned upper body (features.py) predicts it,
and the same IK then only turns its spine and arms onto the headset and hands, keeping the
predicted spine curve, elbow bends and swivels (learned_upper=false: the paper's IK).

The GRU state is carried from frame to frame: the network sees the whole past instead of
re-running a one-second window each frame (the model is trained on 1.5 s chunks and
test_lobstr shows streaming equals running the recurrent net over the window). A gap in the
input longer than max_gap, or time going back, starts the state over.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ...core.contact_hold import ContactHold
from ...core.contacts import FOOT_JOINTS, ToeContacts
from ...core.kinematics import LEG_JOINTS, forward_kinematics
from ...core.rotations import (
    axis_angle_to_matrix,
    matrix_to_6d,
    matrix_to_axis_angle,
    rotations_to_quat,
    sixd_to_matrix,
)
from ...core.sensors import SITE_JOINTS
from ...core.skeleton import JOINT_INDEX as J
from ...core.skeleton import body_scale, standing_pose
from ...core.types import BodyPose, TrackerFrame, breaks_take
from ...estimators.base import Estimator
from ...estimators.onnx_model import load_model
from ..ik.estimator import IKEstimator
from .features import INPUT_SITES, OUTPUTS, apply_legs, apply_upper, feature_count, features
from .options import REACHED, LobstrOptions

_ENDS = [J[SITE_JOINTS[site]] for site in INPUT_SITES[1:]]  # head and hands, in input order


def default_model_path() -> Path:
    from ...core.resources import models_dir

    return models_dir() / "lobstr.onnx"


class LobstrModel:
    """The exported step graph and what it was trained with."""

    def __init__(self, path: str | Path | None = None, threads: int = 1) -> None:
        self.path = Path(path) if path else default_model_path()
        self.session, meta = load_model(
            self.path,
            ("method", "lobstr"),
            {"features": None, "state": None},
            "train one with `sparse-body train lobstr`",
            threads,
        )
        try:
            self.config = meta["config"]
            self.hidden, self.fps = int(self.config["hidden"]), float(self.config["fps"])
            self.learned_upper = bool(self.config.get("learned_upper", False))
        except (KeyError, ValueError, TypeError, AttributeError):
            raise ValueError(f"{self.path}: not a LoBSTr model (its metadata lacks config)") from None
        self.features = feature_count(self.learned_upper)
        width = {i.name: i.shape for i in self.session.get_inputs()}["features"][-1]
        if isinstance(width, int) and width != self.features:
            raise ValueError(
                f"{self.path}: input 'features' has last dimension {width}, "
                f"this LoBSTr model's configuration needs {self.features}"
            )

    def initial_state(self) -> np.ndarray:
        return np.zeros((1, 1, self.hidden), dtype=np.float32)

    def step(self, x: np.ndarray, state: np.ndarray):
        pose, prob, state = self.session.run(
            None, {"features": x.reshape(1, self.features).astype(np.float32), "state": state}
        )
        return pose[0], prob[0], state


class LobstrEnsemble:
    """LoBSTr models trained alike (other seeds), stepped side by side on the same features,
    their outputs averaged (the 6D rotations before they are made orthonormal, the contact
    probabilities). Two seeds of the shipped training, on the kinds of motion no train clip has:
    the legs are the two runs' mean (their error there is shared, not a seed's chance), the
    feet slide and jitter less and the rotations are nearer (docs/methods.md). The estimator
    builds one only for ensemble_path: one network steps alone (LobstrModel, the same calls)."""

    def __init__(self, models: list[LobstrModel]) -> None:
        first = models[0]
        for other in models[1:]:
            if (other.learned_upper, other.fps, other.features) != (first.learned_upper, first.fps, first.features):
                raise ValueError(
                    f"{other.path}: not averaged with {first.path}: its inputs or outputs differ "
                    "(an ensemble needs models trained with the same configuration)"
                )
        self.models, self.path = models, first.path
        self.fps, self.learned_upper, self.config = first.fps, first.learned_upper, first.config

    def initial_state(self) -> list[np.ndarray]:
        return [m.initial_state() for m in self.models]

    def step(self, x: np.ndarray, states: list[np.ndarray]):
        outs = [m.step(x, state) for m, state in zip(self.models, states, strict=True)]
        pose = np.mean([o[0] for o in outs], axis=0)
        return pose, np.mean([o[1] for o in outs], axis=0), [o[2] for o in outs]


def _retime(x: np.ndarray, ratio: float) -> np.ndarray:
    """Velocities measured over dt, expressed per model frame (ratio = model dt / dt)."""
    x = x.copy()
    for b in range(4):
        x[b * 9 : b * 9 + 3] *= ratio
        rotvec = matrix_to_axis_angle(sixd_to_matrix(x[b * 9 + 3 : b * 9 + 9]))
        x[b * 9 + 3 : b * 9 + 9] = matrix_to_6d(axis_angle_to_matrix(rotvec * ratio))
    return x


class LobstrEstimator(Estimator):
    name = "lobstr"
    required_sites = frozenset(INPUT_SITES)
    Options = LobstrOptions
    options: LobstrOptions

    def __init__(
        self,
        sensors,
        skeleton,
        fps: float = 60.0,
        **options,
    ) -> None:
        super().__init__(sensors, skeleton, fps, **options)
        o = self.options
        self.model: LobstrModel | LobstrEnsemble = LobstrModel(o.model_path, o.threads)
        if o.ensemble_path:  # (one network steps alone: no averaging on the default's hot path)
            self.model = LobstrEnsemble([self.model, LobstrModel(o.ensemble_path, o.threads)])
        self.learned_upper = o.learned_upper and self.model.learned_upper
        # the predicted spine curve is kept while it leaves the head this close to the headset
        # (body_ik.fit_spine)
        self.spine_tolerance = o.spine_tolerance
        self._start = standing_pose()  # the network replaces all but the pelvis, and the legs after
        self.scale = body_scale(skeleton)
        self.floor, self.max_gap, self.threshold = o.floor_height, o.max_gap, o.contact_threshold
        self._floor = np.array([0.0, 0.0, o.floor_height])
        # Feet trackers, if configured, are not LoBSTr's input: the upper body sees only its four.
        self.upper = IKEstimator(sensors.subset(INPUT_SITES), skeleton, fps)
        self.upper.read_targets_from(self)  # one conversion a frame, the lost-tracker options included
        self.contacts = ContactHold(skeleton, o.release_frames) if o.contact_ik else None
        self._toes = ToeContacts(fps) if o.toe_contacts else None
        self.reset()

    def use_foot_lock(self, on: bool) -> None:
        """With its own contact IK (contact_ik, the paper's) the feet are held already: a second
        hold on the same contacts would only cost time."""
        super().use_foot_lock(on and getattr(self, "contacts", None) is None)  # (None while built)

    def _reset(self) -> None:
        self.upper.reset()
        if self._toes is not None:
            self._toes = ToeContacts(self.fps)
        if self.contacts:
            self.contacts.reset()
        self._state: Any = self.model.initial_state()  # (one network's array, or an ensemble's list)
        self._prev: tuple[float, np.ndarray, np.ndarray] | None = None

    @staticmethod
    def _reached(joints: np.ndarray, positions: np.ndarray) -> bool:
        """Whether the solved head and hands are within REACHED of their targets (joints: the
        INPUT_SITES targets' positions of this frame)."""
        return all(
            math.dist(positions[joint], target) <= REACHED for joint, target in zip(_ENDS, joints[1:], strict=True)
        )

    def _estimate(self, frame: TrackerFrame) -> BodyPose | None:
        targets = self.full_targets(frame, INPUT_SITES)  # the IK reads the same conversion next
        if targets is None:
            return None  # keep the previous sample: the next velocity spans the gap
        joints, rot = targets
        pos = (joints - self._floor) * self.scale
        if self._prev is None or breaks_take(self._prev[0], frame.stamp, self.max_gap):
            self._state = self.model.initial_state()
            if self.contacts:
                self.contacts.reset()
            self._prev = (frame.stamp - 1.0 / self.model.fps, pos, rot)
        dt = frame.stamp - self._prev[0]
        x = features(pos, rot, self._prev[1], self._prev[2], pose=self.model.learned_upper)
        ratio = 1.0 / (self.model.fps * dt)
        if abs(ratio - 1.0) > 0.02:
            x = _retime(x, ratio)
        out, prob, state = self.model.step(x, self._state)
        upper = None
        if self.learned_upper:
            upper = self.upper.solve(frame, apply_upper(self._start, out[OUTPUTS:]), self.spine_tolerance)
            if upper is not None and not self._reached(joints, upper[3]):
                upper = None  # a predicted torso that leaves a tracker out of reach: the IK's frame
        upper = upper or self.upper.solve(frame)
        if upper is None:
            return None
        upper_local, root = upper[0], np.asarray(upper[1], float)
        local = apply_legs(upper_local, out[:OUTPUTS])
        if not math.isfinite(prob.sum()):  # the network's output gone bad (NaN in, NaN out): start over
            self.reset()
            return None
        contact = prob > self.threshold
        if self._toes is not None:  # the network's legs judged as every other method's are
            toes = forward_kinematics(local, root, self.skeleton.offsets, joints=LEG_JOINTS)[1][list(FOOT_JOINTS)]
            contact = self._toes(toes, self.floor)
            prob = self._toes.probability.copy()  # what is published: the rule's, as the others publish it
        if self.contacts:
            local = self.contacts.apply(local, root, contact)
        self._state, self._prev = state, (frame.stamp, pos, rot)
        return BodyPose(frame.stamp, rotations_to_quat(local), root.copy(), prob.astype(float), contact)
