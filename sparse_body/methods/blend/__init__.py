"""Two estimators' poses averaged, joint by joint (blend:first=avatarjlm,second=dragposer)."""

from ..record import Method

METHOD = Method(
    "blend",
    "sparse_body.methods.blend.estimator:BlendEstimator",
    "sparse_body.methods.blend.options:BlendOptions",
    step_goal=("avatarjlm and dragposer, slerped", 3.0),  # issue 52
)
