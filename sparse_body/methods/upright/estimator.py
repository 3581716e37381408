"""One estimator while the body is upright, handed over to another as it lies down:
`upright:base=lobstr,fallback=ik`.

The learned regressors were trained on CMU's 42 minutes, upright but for two dive-rolls. Where
the body leaves upright poses they are out of their depth, and nothing told them so: another
lab's lying on the floor gave LoBSTr 1.57x IK's leg error (issue 73), and on the floor part
here (`eval --split floor`) every learned four-point estimator was 1.6-2.2x IK's. The torso's
tilt says when: the angle between the world's up and the line from the pelvis tracker to the
headset (the headset's own up where there is no pelvis tracker). Up to `upright_within` the
base has the whole pose; from `lying_from` the fallback; between, their local rotations are
slerped and their roots moved along the line between them, the share following its target with
time constant `settle`, so the hand-over never jumps. Both step every frame (the fallback's
history is warm when it is handed the pose). The share is the frame's out-of-depth score:
`share` after each step.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ...core.rotations import slerp
from ...core.types import BodyPose
from ...estimators.base import Estimator
from ..factory import inner_estimators
from .options import UprightOptions


class UprightEstimator(Estimator):
    name = "upright"
    Options = UprightOptions
    options: UprightOptions

    def __init__(self, sensors, skeleton, fps: float = 60.0, **options) -> None:
        super().__init__(sensors, skeleton, fps, **options)
        o = self.options
        if "upright" in (o.base, o.fallback):
            raise ValueError("upright's estimators cannot be 'upright'")
        if o.lying_from <= o.upright_within:
            raise ValueError(f"lying_from ({o.lying_from}) must be above upright_within ({o.upright_within})")
        self.keep = float(np.exp(-1.0 / (o.settle * fps))) if o.settle > 0 else 0.0  # of the share, a frame
        self.parts = inner_estimators(self, (o.base, o.fallback))
        names = list(sensors.site_names)
        self._head = names.index("head") if "head" in names else None
        self._pelvis = names.index("pelvis") if "pelvis" in names else None
        self.share = 0.0

    def _reset(self) -> None:
        for inner in self.parts:
            inner.reset()
        self.share = 0.0

    def tilt(self, frame) -> float | None:
        """Degrees between the world's up and the torso (pelvis tracker to headset), or the
        headset's own up; None when the frame says neither."""
        head, pelvis = self._head, self._pelvis
        if head is None or not frame.valid[head]:
            return None
        if pelvis is not None and frame.valid[pelvis] and np.all(np.isfinite(frame.positions[[head, pelvis]])):
            torso = frame.positions[head] - frame.positions[pelvis]
        elif np.all(np.isfinite(frame.orientations[head])):
            torso = Rotation.from_quat(frame.orientations[head]).apply([0.0, 0.0, 1.0])
        else:
            return None
        length = float(np.linalg.norm(torso))
        return float(np.degrees(np.arccos(np.clip(torso[2] / length, -1.0, 1.0)))) if length > 1e-6 else None

    def _estimate(self, frame):
        base, fallback = (inner.step(frame) for inner in self.parts)
        tilt = self.tilt(frame)
        if tilt is not None:
            o = self.options
            ramp = min(1.0, max(0.0, (tilt - o.upright_within) / (o.lying_from - o.upright_within)))
            self.share = self.keep * self.share + (1.0 - self.keep) * ramp * ramp * (3.0 - 2.0 * ramp)
        if not (base.valid and fallback.valid):
            return None
        t = self.share
        contacts = base if t < 0.5 else fallback
        return BodyPose(
            frame.stamp,
            slerp(base.local_quats, fallback.local_quats, t),
            (1.0 - t) * base.root_position + t * fallback.root_position,
            contacts.contact_probability.copy(),
            contacts.contact.copy(),
        )
