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

from ...core.skeleton import LOWER_BODY, joint_indices
from ...core.tracker_filter import NO_FILTER
from ...core.types import BodyPose
from ...estimators.base import Estimator
from ..blend.estimator import slerp
from ..dragposer.estimator import DragPoserEstimator
from ..factory import create_estimator
from .options import RefinedOptions


def quat_product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row by row, the rotation a b (x y z w): b, then a."""
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        axis=-1,
    )


def conjugate(q: np.ndarray) -> np.ndarray:
    return q * np.array([-1.0, -1.0, -1.0, 1.0])


class RefinedEstimator(Estimator):
    name = "refined"
    Options = RefinedOptions
    options: RefinedOptions

    def __init__(self, sensors, skeleton, fps: float = 60.0, **options) -> None:
        super().__init__(sensors, skeleton, fps, **options)
        o = self.options
        base = o.base
        if base == "refined":
            raise ValueError("a refined estimator's base cannot be 'refined'")
        # the base's legs unheld: the search moves them, and this estimator's foot_lock holds the result
        self.base = create_estimator(base, sensors, skeleton, fps, foot_lock=False, **RefinedOptions.rest(options))
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
        self.correction: np.ndarray | None = None  # per joint, the search's turn from the base (22, 4)
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
        # per joint, the search's turn from the base's rotation, followed with time constant settle
        turn = quat_product(refined.local_quats, conjugate(pose.local_quats))
        if self.correction is not None and self.keep > 0.0:
            turn = slerp(turn, self.correction, self.keep)
        self.correction = turn
        if self.from_search is None:
            quats, root = quat_product(turn, pose.local_quats), refined.root_position
        else:
            quats, root = pose.local_quats.copy(), pose.root_position.copy()
            quats[self.from_search] = quat_product(turn[self.from_search], pose.local_quats[self.from_search])
        return BodyPose(frame.stamp, quats, root, pose.contact_probability.copy(), pose.contact.copy())
