"""An estimator used only while the body is upright, handed over to another as it lies down
(upright:base=lobstr,fallback=ik)."""

from ..record import Method

METHOD = Method(
    "upright",
    "sparse_body.methods.upright.estimator:UprightEstimator",
    "sparse_body.methods.upright.options:UprightOptions",
    step_goal=("lobstr and ik, slerped", 3.0),
    compare_with=("lobstr", "ik"),  # its base alone, and the baseline it hands over to
)
