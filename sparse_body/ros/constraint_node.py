"""The constraint node: any estimator's output, refined in DragPoser's latent space so the end
effectors sit on their trackers (and the user's constraints hold), as a lifecycle node.

Input: the estimate's JointState (`input/joint_states`, remap it to the estimator's
`joint_states`) and its root on TF (`<input_prefix>pelvis` in the fixed frame), plus the
trackers on TF. Output: `refined/joint_states`, `refined/foot_contacts`,
`refined/estimate_status`, TF under `refined/`. Constraints change at runtime through
`~/set_constraint` (sparse_body/srv/SetConstraint). The lifecycle, parameters, diagnostics
and output handling are the estimator node's.
"""

from __future__ import annotations

import numpy as np
from rclpy.service import Service
from rclpy.subscription import Subscription
from sensor_msgs.msg import JointState

from ..core.types import BodyPose
from ..estimators.base import Estimator
from ..io.output import JointStateError, pose_from_joint_state
from ..methods.dragposer.constraints import AboveFloor, AngleLimit, LookAt, Orientation, Position
from .dropped import DroppedInputs
from .estimator_node import PARAMETERS as ESTIMATOR_PARAMETERS
from .estimator_node import EstimatorNode
from .estimator_node import main as estimator_main
from .estimator_parameters import METHOD_OPTIONS, method_options
from .estimator_parameters import RANGES as ESTIMATOR_RANGES
from .messages import to_seconds
from .node_options import ConstraintNodeInputOptions
from .parameters import table

# the refiner's input is the estimate: no estimator to choose, nor one to fall back on; of the
# methods' options, DragPoser's (dragposer.<field>) set the refiner
PARAMETERS = {
    k: v
    for k, v in ESTIMATOR_PARAMETERS.items()
    if k not in ("estimator", "budget_fallback", "step_budget", "predict_ahead", "foot_lock")
    and (k not in METHOD_OPTIONS or k.startswith("dragposer."))
}
INPUT, INPUT_RANGES = table(ConstraintNodeInputOptions)
PARAMETERS.update(INPUT)
RANGES = {**ESTIMATOR_RANGES, **INPUT_RANGES}
FIXED = ("temporal_weight", "tracker_prior")  # the input pose is the refiner's prior


class InputRefiner(Estimator):
    """step(frame) refines the newest input estimate against the frame's trackers."""

    name = "refine"

    def __init__(self, sensors, skeleton, fps: float, options: dict, timeout: float) -> None:
        from ..methods.dragposer.estimator import DragPoserEstimator

        super().__init__(sensors, skeleton, fps)
        # the input pose is the prior: no temporal or tracker prior
        self.refiner = DragPoserEstimator(sensors, skeleton, fps, **options, **dict.fromkeys(FIXED, 0.0))
        self.timeout = timeout
        self.latest: BodyPose | None = None
        self.reset()

    def _reset(self) -> None:
        self.refiner.reset()

    def _estimate(self, frame) -> BodyPose | None:
        if self.latest is None or not self.latest.valid or frame.stamp - self.latest.stamp > self.timeout:
            return None
        pose = self.refiner.refine(self.latest, frame)
        pose.contact, pose.contact_probability = self.latest.contact, self.latest.contact_probability
        return pose


def constraint_from_request(request):
    """A Constraint from a SetConstraint request, or ValueError saying what is wrong."""
    v = list(request.values)
    common = dict(joint=request.joint, weight=request.weight if request.weight > 0 else 1.0, name=request.name)
    need = {"position": 3, "orientation": 4, "above_floor": 1, "look_at": 3, "angle_limit": 1}
    if request.type not in need:
        raise ValueError(f"unknown constraint type {request.type!r}; types are {', '.join(need)}")
    if len(v) < need[request.type] or not np.all(np.isfinite(v)):
        raise ValueError(f"a {request.type} constraint needs {need[request.type]} finite values, got {v}")
    if request.type == "position":
        return Position(**common, target=tuple(v[:3]))
    if request.type == "orientation":
        from scipy.spatial.transform import Rotation

        if not 0.9 < np.linalg.norm(v[:4]) < 1.1:
            raise ValueError("an orientation constraint needs a unit quaternion x y z w")
        return Orientation(**common, target=Rotation.from_quat(v[:4]).as_matrix())
    if request.type == "above_floor":
        return AboveFloor(**common, height=v[0])
    if request.type == "look_at":
        return LookAt(**common, target=tuple(v[:3]), axis=tuple(v[3:6]) if len(v) >= 6 else (1.0, 0.0, 0.0))
    return AngleLimit(**common, max_angle=v[0])


class ConstraintNode(EstimatorNode):
    NAME = "sparse_body_constraint"
    PARAMETERS = PARAMETERS
    RANGES = RANGES
    OUTPUTS = "refined/"

    estimator: InputRefiner | None = None  # type: ignore[assignment]  # the refiner is this node's estimator
    sub_input: Subscription | None = None
    srv_constraint: Service | None = None

    def _make_estimator(self, p: dict, sensors):
        options = {k: v for k, v in method_options(p, "dragposer").items() if k not in FIXED}
        if p["model_path"]:
            options["model_path"] = p["model_path"]
        return InputRefiner(sensors, self.skeleton, p["output_rate"], options, p["input_timeout"])

    def _make_budget_fallback(self, p: dict, sensors) -> None:
        return None  # every refinement is waited for

    def _step_budget(self) -> float:
        return 0.0

    def _configure_inputs(self) -> None:
        from sparse_body.srv import SetConstraint

        self.sub_input = self.create_subscription(JointState, "input/joint_states", self._on_input, 10)
        self.srv_constraint = self.create_service(SetConstraint, "~/set_constraint", self._on_set_constraint)

    def _looked_up_frames(self, p: dict) -> set[str]:
        return {p["input_prefix"] + "pelvis"}  # where the input estimate's body is

    def _method(self) -> str:
        return "dragposer refinement"

    def _on_tracker(self) -> None:
        """The input estimate drives this node, not the trackers (they come first)."""

    def _on_input(self, msg: JointState) -> None:
        """The input estimate (from the network: whatever it holds never stops the node; what
        is no body pose is dropped and counted on /diagnostics)."""
        try:
            if self.estimator is None or self.tf_in is None:
                return
            found = self.tf_in.lookup(self.sensors.fixed_frame, self.params["input_prefix"] + "pelvis")
            if found is None:
                return
            _, translation, rotation = found
            stamp = to_seconds(msg.header.stamp)
            self.estimator.latest = pose_from_joint_state(msg.name, msg.position, translation, rotation, stamp)
        except JointStateError as err:
            self._dropped_inputs.drop(str(err))
            return
        except Exception as err:  # noqa: BLE001 - counted on /diagnostics, said once in the log
            self._dropped_inputs.drop(f"{type(err).__name__}: {str(err)[:200]}")
            return
        if self.timer is not None:
            self._estimate(fallback=False)

    def _input_diagnostics(self) -> dict[str, str]:
        return self._dropped_inputs.values("dropped input: ")

    def _on_set_constraint(self, request, response):
        constraints = None if self.estimator is None else self.estimator.refiner.constraints
        if constraints is None:
            response.success, response.message = False, "not configured"
            return response
        try:
            if request.remove:
                response.success = constraints.remove(request.name)
                response.message = f"removed {request.name}" if response.success else f"no constraint {request.name!r}"
            else:
                constraint = constraint_from_request(request)
                constraints.add(constraint)
                response.success, response.message = True, f"set {constraint.name}"
        except ValueError as err:
            response.success, response.message = False, str(err)
        response.active = constraints.user_names()  # as the service says: the user's, not the floor's
        return response

    def _release(self) -> None:
        if self.sub_input is not None:
            self.destroy_subscription(self.sub_input)
        if self.srv_constraint is not None:
            self.destroy_service(self.srv_constraint)
        self.sub_input = self.srv_constraint = None
        self._dropped_inputs = DroppedInputs(self.get_logger().warning)
        super()._release()


def main(args=None) -> None:
    estimator_main(args, node_class=ConstraintNode)


if __name__ == "__main__":
    main()
