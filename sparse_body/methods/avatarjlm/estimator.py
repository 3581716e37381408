"""AvatarJLM at runtime: ONNX Runtime, one streaming step per frame over the kept past.

The network (model.py) attends causally, each temporal block to the last
window - 1 frames, and a frame's keys and values never change once computed; so each frame
runs once, against the kept keys and values of the frames before it (by their age in model
frames), and gives what the network gives on the whole stream. A stream's first frames see
fewer frames, as in training.

The pose: the network's local rotations on the person's (calibrated) skeleton, its root
rotation turned from the head's heading frame into the world; the body placed by head
alignment (the paper's), or on the pelvis tracker with the four-point model. The knees are
hinges (hinge_knees, ours): a three-point network trained from random rotations turned a shin
about its own length by up to 175 degrees, the ankle partly turning back, which leaves
positions near right and the joint angles a user drives a robot or an avatar with broken.
One trained so with the leg term turned whole legs instead, a hip half a turn about its thigh
with the knee turning back: for such networks (by default those whose config does not start
from the identity; the shipped ones do) the hips and knees are rebuilt from the joint
positions the network gives (legs_from_positions, ours; it makes the knees hinges too), which
keeps its positions and gives the legs' rotations a body would have. Then
(polish=true, ours: the paper relies on its hand-alignment loss alone) the closed-form IK
brings the head and hands onto their trackers, keeping the network's spine curve and
elbows, and they take their trackers' orientation.

Without a usable head or hand sample (or the pelvis, four-point) there is no pose (held,
invalid); a gap longer than max_gap, or time going back, starts the network's past over.
The network runs at its training rate: a stream at another rate has its velocities scaled
to it and its past looked up by age in model frames.

Shipped models (model=NAME): three_point (models/avatarjlm.onnx) and four_point
(avatarjlm_four_point.onnx, with the pelvis tracker: the paper's four-input row); auto (the
default) takes four_point when the sensor configuration has a pelvis tracker.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...core.body_ik import LIMBS, solve_body
from ...core.contacts import FOOT_JOINTS as TOE_JOINTS
from ...core.contacts import ToeContacts
from ...core.kinematics import forward_kinematics
from ...core.rotations import rotation_between, rotations_to_quat, sixd_to_matrix
from ...core.skeleton import JOINT_INDEX, PARENTS, body_scale
from ...core.types import BodyPose, TrackerFrame, breaks_take
from ...estimators.base import Estimator, full_target
from ...estimators.onnx_model import load_model, shipped_model_path
from .features import SITES, features, reference
from .options import AvatarJlmOptions

HEAD = JOINT_INDEX["head"]
LEGS = (LIMBS[JOINT_INDEX["left_ankle"]], LIMBS[JOINT_INDEX["right_ankle"]])  # hip, knee (a hinge), ankle


def legs_from_positions(local: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(22, 3, 3) local rotations with each hip and knee rebuilt from the joint positions they
    give: the thigh and shin point where they did, the knee is a hinge whose axis is normal to
    the hip-knee-ankle plane (the hip's own across a nearly straight leg, where that plane is
    not defined), the ankle keeps its local rotation. Hips, knees and ankles stay in place."""
    out = local.copy()
    for leg in LEGS:  # in the pelvis's frame: no forward kinematics of the body
        hip, knee, ankle = leg.upper, leg.hinge, leg.end
        thigh = local[hip] @ offsets[knee]
        shin = local[hip] @ local[knee] @ offsets[ankle]
        axis = np.cross(thigh, shin)
        if np.linalg.norm(axis) < 0.1 * np.linalg.norm(thigh) * np.linalg.norm(shin):  # bent under 6 degrees
            axis = local[hip] @ leg.axis
        # each a frame of (thigh, knee axis): the rest thigh's turned onto the given one
        out[hip] = (
            sixd_to_matrix(np.concatenate([thigh, axis])) @ sixd_to_matrix(np.concatenate([offsets[knee], leg.axis])).T
        )
        out[knee] = rotation_between(offsets[ankle], out[hip].T @ shin)
    return out


MODELS = {"three_point": "avatarjlm.onnx", "four_point": "avatarjlm_four_point.onnx"}


class AvatarJlmModel:
    """The exported streaming step, what it was trained with, and its kept past."""

    def __init__(self, path: str | Path, threads: int = 1) -> None:
        self.path = Path(path)
        self.session, meta = load_model(
            self.path,
            ("method", "avatarjlm"),
            {"x": None, "past_k": None},
            "train one with `sparse-body train avatarjlm`",
            threads,
        )
        try:
            c = meta["config"]
            self.sites = SITES[c["sensors"]]
            self.past, self.fps = int(c["window"]) - 1, float(c["fps"])
            self.cache_shape = (int(c["loops"]), 44, int(c["heads"]), self.past, int(c["d_model"]) // int(c["heads"]))
            # trained from random rotations, three-point networks settled with turned legs (the
            # four-point model started from the identity before its config recorded it)
            self.turned_legs = c["sensors"] == "three_point" and not c.get("identity_start", False)
        except (KeyError, ValueError, TypeError):
            raise ValueError(f"{self.path}: not an AvatarJLM model (its metadata lacks a usable config)") from None
        self.start()

    def start(self) -> None:
        """Forget the past (a new stream, a gap)."""
        self.keys = np.zeros(self.cache_shape, np.float32)
        self.values = np.zeros(self.cache_shape, np.float32)
        self.stamps = np.full(self.past, np.nan)  # of the frame in each slot (a ring)
        self.slot = 0

    def step(self, x: np.ndarray, stamp: float) -> np.ndarray:
        """One frame's features (F,) -> (22, 3, 3): the root's rotation in the heading frame,
        the other joints' local rotations. The frame joins the past."""
        age = np.rint((stamp - self.stamps) * self.fps)
        kept = np.isfinite(age) & (age >= 1) & (age <= self.past)
        pose, key, value = self.session.run(
            None,
            {
                "x": x[None].astype(np.float32),
                "past_k": self.keys,
                "past_v": self.values,
                "past_age": np.where(kept, age, 1).astype(np.int64),
                "past_mask": np.where(kept, 0.0, -np.inf).astype(np.float32),
            },
        )
        self.keys[:, :, :, self.slot] = key[:, :, :, 0]
        self.values[:, :, :, self.slot] = value[:, :, :, 0]
        self.stamps[self.slot] = stamp
        self.slot = (self.slot + 1) % self.past
        return sixd_to_matrix(pose[0].astype(np.float64))


class AvatarJlmEstimator(Estimator):
    name = "avatarjlm"
    required_sites = frozenset(SITES["three_point"])
    Options = AvatarJlmOptions
    options: AvatarJlmOptions

    def __init__(self, sensors, skeleton, fps: float = 60.0, **options) -> None:
        super().__init__(sensors, skeleton, fps, **options)
        o = self.options
        model = o.model
        if model == "auto":
            model = "four_point" if "pelvis" in sensors.site_names else "three_point"
        self.model = AvatarJlmModel(o.model_path or shipped_model_path("AvatarJLM", MODELS, model, "auto"), o.threads)
        missing = set(self.model.sites) - set(sensors.site_names)
        if missing:
            raise ValueError(
                f"{self.model.path} needs trackers on {', '.join(sorted(missing))}; sensor configuration "
                f"{sensors.name!r} has {', '.join(sensors.site_names)} (use model:=three_point)"
            )
        self.scale = body_scale(skeleton)
        self.polish, self.end_orientations, self.hinge_knees = o.polish, o.end_orientations, o.hinge_knees
        # None: rebuilt where the network's legs come out turned (AvatarJlmModel.turned_legs)
        self.four = "pelvis" in self.model.sites
        turned = o.legs_from_positions
        self.legs_from_positions = self.model.turned_legs if turned is None else bool(turned)
        self.floor, self.max_gap = o.floor_height, o.max_gap
        self._joints = [sensors.site(s).joint_index for s in self.model.sites]
        self.reset()

    def _reset(self) -> None:
        self.model.start()
        self._previous: tuple[float, np.ndarray, np.ndarray] | None = None  # stamp, scaled positions, rotations
        self._toes = ToeContacts(self.fps)  # contacts from the toes frame to frame

    def _estimate(self, frame: TrackerFrame) -> BodyPose | None:
        targets = [self.joint_target(frame, s) for s in self.model.sites]
        if not all(full_target(t) for t in targets):
            return None
        world = np.stack([np.asarray(t[0], float) for t in targets])
        rot = np.stack([np.asarray(t[1], float) for t in targets])
        pos = (world - [0.0, 0.0, self.floor]) * self.scale
        previous = self._previous
        if previous is not None and breaks_take(previous[0], frame.stamp, self.max_gap):
            self.model.start()
            previous = None
        step = 1.0 if previous is None else (frame.stamp - previous[0]) * self.model.fps
        x = features(
            pos,
            rot,
            pos if previous is None else previous[1],
            rot if previous is None else previous[2],
            step if abs(step - 1.0) > 0.05 else 1.0,
        )
        self._previous = (frame.stamp, pos, rot)
        out = self.model.step(x, frame.stamp)
        return self._pose(frame.stamp, out, world, rot)

    def _pose(self, stamp: float, out: np.ndarray, world: np.ndarray, rot: np.ndarray) -> BodyPose:
        local = out.copy()
        offsets = self.skeleton.offsets
        if self.legs_from_positions:
            local = legs_from_positions(local, offsets)
        elif self.hinge_knees:  # a knee is a hinge: no turn of the shin about its own length
            for leg in LEGS:
                local[leg.hinge] = rotation_between(offsets[leg.end], local[leg.hinge] @ offsets[leg.end])
        local[0] = rot[self.model.sites.index("pelvis")] if self.four else reference(world[0], rot[0])[1] @ out[0]
        glob, pos = forward_kinematics(local, np.zeros(3), offsets)
        # the root on its tracker, or where the head lands on the tracked head (head alignment)
        root = world[self.model.sites.index("pelvis")] if self.four else world[0] - pos[HEAD]
        pos = pos + root
        if self.polish:
            goals = dict(zip(self._joints, world, strict=True))
            local, glob, pos = solve_body(local, root, offsets, goals, keep_shape=True)
            if self.end_orientations:
                for j, r in zip(self._joints, rot, strict=True):
                    if j:  # the pelvis is the root already
                        local[j] = glob[PARENTS[j]].T @ r
                        glob[j] = r
        toes = np.stack([pos[PARENTS[t]] + glob[PARENTS[t]] @ offsets[t] for t in TOE_JOINTS])
        contact = self._toes(toes, self.floor)
        return BodyPose(
            stamp, rotations_to_quat(local), np.asarray(root, float).copy(), self._toes.probability.copy(), contact
        )
