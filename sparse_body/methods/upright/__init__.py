"""An estimator that only ever sees an upright body: as the body lies down its trackers are
turned so that the torso stands, for the base (blend by default), and its pose turned back."""

from ..record import Method

METHOD = Method(
    "upright",
    "sparse_body.methods.upright.estimator:UprightEstimator",
    "sparse_body.methods.upright.options:UprightOptions",
    step_goal=("blend (avatarjlm and dragposer) on turned targets", 3.0),
    compare_with=("blend", "ik"),  # its base alone, and the baseline every kind is measured against
)
