"""DTP (Deep Tracker Poser) at runtime: ONNX Runtime over a window of recent frames.

Each frame, the last `past` frames and this one (sampled at the model's rate from what has
arrived) go through the transformer, and the current frame's token gives the 21 local joint
rotations; the pelvis's rotation and position are the pelvis tracker's. A stream's first
frames run as a shorter window (the network is trained for that: its attention is causal).
Then (polish=true, ours) the closed-form IK brings the head, the hands and each foot whose
tracker agrees with the network's foot (near it, not jumping) onto their trackers, and those
joints take their trackers' orientation (end_orientations=true); polish=false is the paper's
network output as it is.

A foot tracker with no usable sample (dropped, invalid, non-finite) is fed as an occluded
Lighthouse tracker reads: the origin and the identity rotation, which the fine-tuned network
has learnt to discount; the body goes on. Without the pelvis, the head or a hand there is
no pose (held, invalid). A gap longer than max_gap, or time going back, starts the window
over.

Shipped models (model=NAME): online (models/dtp.onnx, the default), lookahead
(dtp_lookahead.onnx: trained with the paper's 5 future frames) and pretrained (dtp.pretrained.onnx:
online, before the occlusion fine-tuning; kept to measure what the fine-tuning does). With the
lookahead model, process() (offline: `sparse-body eval`, `sparse-body process`) gives each
frame the 5 frames after it (frames at the model's rate); step() cannot see the future, so a
live node runs it without (worse than the online model: use that one live).
"""

from __future__ import annotations

import bisect
from collections import deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import cast

import numpy as np

from ...core.body_ik import solve_body
from ...core.contacts import FOOT_JOINTS as TOE_JOINTS
from ...core.contacts import ToeContacts
from ...core.kinematics import forward_kinematics
from ...core.rotations import rotations_to_quat, sixd_to_matrix
from ...core.sensors import SITE_JOINTS
from ...core.skeleton import JOINT_INDEX, PARENTS, body_scale
from ...core.types import BodyPose, TrackerFrame, TrackerStream, breaks_take
from ...estimators.base import Estimator, full_target
from ...estimators.onnx_model import load_model, shipped_model_path
from .features import FEATURES, FOOT_LEAVES, INPUT_SITES, LEAF_SITES, leaf_features, window_features
from .options import DtpOptions

IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])
FOOT_JOINTS = frozenset(JOINT_INDEX[SITE_JOINTS[s]] for s in ("left_foot", "right_foot"))  # the ankles


# the shipped models: model:=NAME
MODELS = {"online": "dtp.onnx", "lookahead": "dtp_lookahead.onnx", "pretrained": "dtp.pretrained.onnx"}


class DtpModel:
    """The exported network and what it was trained with."""

    def __init__(self, path: str | Path, threads: int = 1) -> None:
        self.path = Path(path)
        self.session, meta = load_model(
            self.path, ("method", "dtp"), {"window": FEATURES}, "train one with `sparse-body train dtp`", threads
        )
        try:
            self.config = meta["config"]
            self.past, self.future = int(self.config["past"]), int(self.config["future"])
            self.fps = float(self.config["fps"])
        except (KeyError, ValueError, TypeError):
            raise ValueError(f"{self.path}: not a DTP model (its metadata lacks config)") from None

    def run(self, window: np.ndarray, frame: int = -1) -> np.ndarray:
        """(n, 72) -> (21, 3, 3): the local rotations of joints 1..21 at one frame of the window."""
        out = self.session.run(None, {"window": window[None].astype(np.float32)})[0][0, frame]
        return sixd_to_matrix(out.astype(np.float64).reshape(-1, 6))


@dataclass
class Sample:
    """One frame as the network and the polish see it."""

    stamp: float
    pelvis_pos: np.ndarray  # canonical scale, floor at z = 0
    pelvis_rot: np.ndarray
    leaves: np.ndarray  # (60,) leaf_features
    root: np.ndarray  # the pelvis joint as tracked (the person's scale)
    goals: dict[int, np.ndarray]  # joint -> tracked position: head, hands, and the feet with a sample
    turns: dict[int, np.ndarray]  # joint -> tracked rotation, for the same joints


class DtpEstimator(Estimator):
    name = "dtp"
    required_sites = frozenset(INPUT_SITES)
    Options = DtpOptions
    options: DtpOptions

    def __init__(self, sensors, skeleton, fps: float = 60.0, **options) -> None:
        super().__init__(sensors, skeleton, fps, **options)
        o = self.options
        self.model = DtpModel(o.model_path or shipped_model_path("DTP", MODELS, o.model), o.threads)
        self.scale = body_scale(skeleton)
        self.polish, self.foot_trust, self.foot_speed = o.polish, o.foot_trust, o.foot_speed
        self.end_orientations = o.end_orientations
        self.floor, self.max_gap = o.floor_height, o.max_gap
        self._joints = [sensors.site(s).joint_index for s in INPUT_SITES]
        self.reset()

    def _reset(self) -> None:
        self._history: deque[tuple[float, Sample]] = deque()
        self._previous: Sample | None = None  # the last frame the polish saw
        self._toes = ToeContacts(self.fps)  # contacts from the toes frame to frame

    def sample(self, frame: TrackerFrame) -> Sample | None:
        """One frame's input, or None without pelvis, head and hands."""
        targets = [self.joint_target(frame, s) for s in INPUT_SITES]
        if not all(full_target(t) for t in targets[:4]):
            return None
        usable = [(j, t) for j, t in zip(self._joints[1:], targets[1:], strict=True) if full_target(t)]
        goals = {j: np.asarray(t[0], float) for j, t in usable}
        turns = {j: np.asarray(t[1], float) for j, t in usable}
        for k in FOOT_LEAVES:  # a foot without a usable sample reads as an occluded tracker
            t = targets[1 + k]
            if not full_target(t):
                targets[1 + k] = self.sensors.site(LEAF_SITES[k]).joint_pose(np.zeros(3), IDENTITY)
        pos = (np.stack([t[0] for t in targets]) - [0.0, 0.0, self.floor]) * self.scale
        rot = np.stack([t[1] for t in targets])
        return Sample(
            frame.stamp,
            pos[0],
            rot[0],
            leaf_features(pos[0], rot[0], pos[1:], rot[1:]),
            np.asarray(targets[0][0], float),
            goals,
            turns,
        )

    def _estimate(self, frame: TrackerFrame) -> BodyPose | None:
        sample = self.sample(frame)
        if sample is None:
            return None
        history = self._history
        if history and breaks_take(history[-1][0], frame.stamp, self.max_gap):
            history.clear()
        history.append((frame.stamp, sample))
        # keep what the window can reach: `past` model frames back, and the gap allowed before that
        while frame.stamp - history[0][0] > self.model.past / self.model.fps + self.max_gap:
            history.popleft()
        window = self._window(frame.stamp)
        return self._pose(sample, self.model.run(self._features(window, len(window) - 1)))

    def _window(self, stamp: float) -> list[Sample]:
        """The history sampled at the model's rate back from stamp: for each of the `past`
        model frames that reach no further back than the oldest sample, the nearest sample."""
        stamps = [h[0] for h in self._history]
        picks = []
        for k in range(self.model.past, -1, -1):
            t = stamp - k / self.model.fps
            if t < stamps[0] - 0.5 / self.model.fps:
                continue
            i = bisect.bisect_left(stamps, t)
            if i == len(stamps) or (i > 0 and t - stamps[i - 1] < stamps[i] - t):
                i -= 1
            picks.append(self._history[i][1])
        return picks

    @staticmethod
    def _features(window: list[Sample], current: int) -> np.ndarray:
        return window_features(
            np.stack([w.pelvis_pos for w in window]),
            np.stack([w.pelvis_rot for w in window]),
            np.stack([w.leaves for w in window]),
            current,
        )

    def _pose(self, sample: Sample, local_1_21: np.ndarray) -> BodyPose:
        local = np.concatenate([sample.pelvis_rot[None], local_1_21])
        glob, pos = forward_kinematics(local, sample.root, self.skeleton.offsets)
        if self.polish:
            local, glob, pos = self._polished(local, glob, pos, sample)
        # no contact model: toes low and still, as the IK judges them (toes under the ankles' final turn)
        toes = np.stack([pos[PARENTS[t]] + glob[PARENTS[t]] @ self.skeleton.offsets[t] for t in TOE_JOINTS])
        contact = self._toes(toes, self.floor)
        return BodyPose(
            sample.stamp, rotations_to_quat(local), sample.root.copy(), self._toes.probability.copy(), contact
        )

    def _polished(self, local: np.ndarray, glob: np.ndarray, pos: np.ndarray, sample: Sample):
        """Ours, not the paper's: the network's pose with the head, the hands and the feet
        brought onto their trackers by the closed-form IK, keeping the network's spine curve,
        elbows and knees. A foot tracker is followed fully within foot_trust of where the
        network put that foot, less and less out to twice that, and not at all when it jumped
        faster than foot_speed (m/s) since the previous frame: an occluded tracker reads far
        off, or jumps about. Head, hands and fully followed feet then take their trackers'
        orientation (end_orientations). (Chosen on the validation people, clean and
        occluded: models/dtp.runtime*.json.)"""
        offsets = self.skeleton.offsets
        previous, self._previous = self._previous, sample
        goals, followed = {}, []
        for j, p in sample.goals.items():
            if j in FOOT_JOINTS:
                w = np.clip(2.0 - np.linalg.norm(p - pos[j]) / self.foot_trust, 0.0, 1.0)
                if (
                    self.foot_speed
                    and previous is not None
                    and j in previous.goals
                    and np.linalg.norm(p - previous.goals[j])
                    > self.foot_speed * max(sample.stamp - previous.stamp, 1e-3)
                ):
                    w = 0.0
                if w == 0.0:
                    continue
                p = pos[j] + w * (p - pos[j])
            goals[j] = p
            if j not in FOOT_JOINTS or w == 1.0:
                followed.append(j)
        local, glob, pos = solve_body(local, sample.root, offsets, goals, keep_shape=True)
        if self.end_orientations:  # the tracked joints take their trackers' orientation, as the IK's do
            for j in followed:
                local[j] = glob[PARENTS[j]].T @ sample.turns[j]
                glob[j] = sample.turns[j]  # (what hangs below, a toe, is placed from it by the caller)
        return local, glob, pos

    def stream(self, frames: TrackerStream | Iterable[TrackerFrame]) -> Iterator[BodyPose]:
        """One pose per frame; with a lookahead model each frame also sees the `future`
        frames after it (offline), else as step() does. Each frame's pose is made as soon as
        the frames after it are sampled, so that sampling sees the poses before it (a
        returning tracker is eased from where the last pose had its joint). Only the frames a
        window can still reach are kept: a recording of any length in bounded memory."""
        if not self.model.future:
            yield from super().stream(frames)
            return
        self.reset()
        seen: dict[int, TrackerFrame] = {}  # by frame index, from the oldest a window reaches
        samples: dict[int, Sample | None] = {}
        run_of: dict[
            int, int
        ] = {}  # runs of usable frames without a gap longer than max_gap: a window stays within one
        past, future = self.model.past, self.model.future

        def pose_of(i: int, count: int) -> BodyPose:
            s = samples[i]
            if s is None:
                return self._checked(seen[i].stamp, None)
            lo, hi = i, i
            while lo > i - past and lo > 0 and run_of[lo - 1] == run_of[i]:
                lo -= 1
            while hi < i + future and hi + 1 < count and run_of[hi + 1] == run_of[i]:
                hi += 1
            window = [samples[k] for k in range(lo, hi + 1)]
            x = self._features(cast(list[Sample], window), i - lo)  # one run: no gaps
            return self._checked(seen[i].stamp, self._pose(s, self.model.run(x, i - lo)))

        def forget_before(i: int) -> None:
            for table in (seen, samples, run_of):
                table.pop(i - past - 1, None)  # (lo - 1 >= i - past - 1 is the oldest read)

        run, count = 0, 0
        for j, frame in enumerate(self.filtered(frames)):
            seen[j] = frame
            s = self.sample(frame)
            if (
                s is not None
                and j
                and (samples[j - 1] is None or breaks_take(seen[j - 1].stamp, frame.stamp, self.max_gap))
            ):
                run += 1
            samples[j] = s
            run_of[j] = run if s is not None else -1
            count = j + 1
            if j >= future:
                yield pose_of(j - future, count)
                forget_before(j - future)
        for i in range(max(0, count - future), count):
            yield pose_of(i, count)
