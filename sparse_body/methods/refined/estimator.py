"""Any estimator followed by DragPoser's latent-space refinement: `refined:base=ik`.

The base estimator gives the pose; the refinement encodes it, then moves it in the pose
VAE's latent space until the end effectors sit on their trackers. This is what the
constraint node does live, packaged as an estimator for `sparse-body eval` and `process`.

The pose VAE's decoder is not smooth from frame to frame, so the refined pose jitters more
than its base (docs/methods.md). Two options keep the base's smoothness:
- `settle`: the output is the base pose turned, joint by joint, by the search's turn from it,
  that turn followed by an exponential with this time constant: the correction's slow part.
  The polish's last centimetre on the tracked joints lags with it.
- `only_legs`: the search gives the legs only (their turns from the base's, settled as above);
  the root, spine, head and arms stay the base's, on their trackers where it put them.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ...core.rotations import slerp
from ...core.skeleton import LOWER_BODY, joint_indices
from ...core.tracker_filter import NO_FILTER
from ...core.types import BodyPose
from ...estimators.base import Estimator
from ..dragposer.estimator import DragPoserEstimator
from ..factory import create_estimator
from .options import RefinedOptions


class RefinedEstimator(Estimator):
    name = "refined"
    Options = RefinedOptions
    options: RefinedOptions

    def __init__(self, sensors, skeleton, fps: float = 60.0, **options) -> None:
        super().__init__(sensors, skeleton, fps, **options)
        o = self.options
        base = o.base
        # the base's legs unheld: the search moves them, and this estimator's foot_lock holds the result
        self.base = create_estimator(base, sensors, skeleton, fps, foot_lock=False, **self.passed_on)
        self.base.use_filter(NO_FILTER)  # this estimator's filter has done it
        self.refiner = DragPoserEstimator(
            sensors,
            skeleton,
            fps,
            model_path=o.model_path,
            iterations=o.iterations,
            temporal_weight=0.0,
            tracker_prior=0.0,
        )  # the base pose is the prior
        for inner in (self.base, self.refiner):  # this estimator's targets: the lost-tracker options hold
            inner.read_targets_from(self)
        self.keep = float(np.exp(-1.0 / (o.settle * fps))) if o.settle > 0 else 0.0  # of the correction, a frame
        self.correction: np.ndarray | None = None  # per joint taken from the search, its turn from the base (n, 4)
        self.from_search = joint_indices(LOWER_BODY) if o.only_legs else None  # None: every joint

    def _reset(self) -> None:
        self.base.reset()
        self.refiner.reset()
        self.correction = None

    def _estimate(self, frame):
        pose = self.base.step(frame)
        if not pose.valid:
            return pose
        refined = self.refiner.refine(pose, frame)
        if not refined.valid:
            return pose.held(frame.stamp)  # the base's pose, marked invalid
        if self.keep == 0.0 and self.from_search is None:
            refined.contact, refined.contact_probability = pose.contact, pose.contact_probability
            return refined
        # per joint taken from the search, its turn from the base's rotation, followed with
        # time constant settle (only those joints: the rest would be thrown away)
        rows = slice(None) if self.from_search is None else self.from_search
        base = Rotation.from_quat(pose.local_quats[rows])
        turn = (Rotation.from_quat(refined.local_quats[rows]) * base.inv()).as_quat()
        if self.correction is not None and self.keep > 0.0:
            turn = slerp(turn, self.correction, self.keep)
        self.correction = turn
        turned = (Rotation.from_quat(turn) * base).as_quat()
        if self.from_search is None:
            quats, root = turned, refined.root_position
        else:
            quats, root = pose.local_quats.copy(), pose.root_position.copy()
            quats[rows] = turned
        return BodyPose(frame.stamp, quats, root, pose.contact_probability.copy(), pose.contact.copy())
