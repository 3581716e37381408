"""Two estimators run side by side, their poses averaged: `blend:first=E1,second=E2,weight=W`.

A network that meets motion it never saw guesses the legs; a search in a pose prior (DragPoser)
errs differently there. Where two methods' errors differ, their mean is nearer the truth than
either (issue 33: motions the models never saw). Each local rotation is slerped (weight: the
second's share), the root moved along the line between the two; the foot contacts are the
first's. Both see this estimator's filtered targets and run with their own defaults and
shipped models (options are not passed on to them).

The hand-over: where the two disagree about the legs by more than `agree_within` (mean leg
joint distance), the second's share falls, to nothing at `disagree_from`. On the validation
people a disagreement that large was the search failing (cartwheels, hanging on ropes:
DragPoser 2x AvatarJLM's error), while on dance, which no training clip has, the two stay
within 15 cm. The share follows its target with time constant `settle`, so the hand-over
never jumps.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ...core.kinematics import forward_kinematics
from ...core.mat3 import quat_matrices
from ...core.rotations import slerp
from ...core.skeleton import LOWER_BODY, joint_indices
from ...core.types import BodyPose
from ...estimators.base import Estimator
from ..factory import inner_estimators
from .options import BlendOptions


class BlendEstimator(Estimator):
    name = "blend"
    Options = BlendOptions
    options: BlendOptions

    def __init__(self, sensors, skeleton, fps: float = 60.0, **options) -> None:
        super().__init__(sensors, skeleton, fps, **options)
        o = self.options
        first, second, settle = o.first, o.second, o.settle
        self.weight, self.agree_within, self.disagree_from = (
            float(o.weight),
            float(o.agree_within),
            float(o.disagree_from),
        )
        self.keep = float(np.exp(-1.0 / (settle * fps))) if settle > 0 else 0.0  # of the share, a frame
        self.share = self.weight
        self.legs = joint_indices(LOWER_BODY)
        self.parts = inner_estimators(self, (first, second))
        # The two never share state but the frame's targets (converted before both start), so
        # the first (a network: ONNX Runtime, which lets go of the GIL) runs in a worker thread
        # while this thread runs the second: a step costs the longer of the two, not their sum
        # (issue 52), with the same poses as one after the other (test_blend).
        self._worker = ThreadPoolExecutor(1, thread_name_prefix="blend_first") if o.parallel else None

    def _reset(self) -> None:
        for inner in self.parts:
            inner.reset()
        self.share = self.weight

    def disagreement(self, a: BodyPose, b: BodyPose) -> float:
        """Metres: the mean distance between the two poses' leg joints."""
        offsets = self.skeleton.offsets  # the estimators' quaternions are unit: converted compiled
        _, pa = forward_kinematics(quat_matrices(np.ascontiguousarray(a.local_quats, float)), a.root_position, offsets)
        _, pb = forward_kinematics(quat_matrices(np.ascontiguousarray(b.local_quats, float)), b.root_position, offsets)
        return float(np.linalg.norm(pa[self.legs] - pb[self.legs], axis=-1).mean())

    def _estimate(self, frame):
        first, second = self.parts
        if self._worker is None:
            a, b = first.step(frame), second.step(frame)
        else:
            self._converted(frame)  # the targets both read, converted here and only read there
            running = self._worker.submit(first.step, frame)
            try:
                b = second.step(frame)
            finally:
                a = running.result()  # its error, if any, is raised here
        if not (a.valid and b.valid):  # one alone would jump on the way in and out
            return None
        trust = (self.disagree_from - self.disagreement(a, b)) / (self.disagree_from - self.agree_within)
        target = self.weight * min(1.0, max(0.0, trust))
        self.share = t = self.keep * self.share + (1.0 - self.keep) * target
        return BodyPose(
            frame.stamp,
            slerp(a.local_quats, b.local_quats, t),
            (1.0 - t) * a.root_position + t * b.root_position,
            a.contact_probability.copy(),
            a.contact.copy(),
        )
