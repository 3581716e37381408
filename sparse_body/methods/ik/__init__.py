"""The closed-form body IK (no learning): the baseline every learned method is compared with."""

from ..record import Method

METHOD = Method(
    "ik",
    "sparse_body.methods.ik.estimator:IKEstimator",
    "sparse_body.methods.ik.options:IkOptions",
    step_goal=("closed-form IK", 0.1),
    ratio_goal=1.5,
    eval_sensors="six_point",
)
