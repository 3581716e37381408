"""The reference: the rest pose carried by the head (a floor for every comparison)."""

from ..record import Method

METHOD = Method(
    "reference",
    "sparse_body.methods.reference.estimator:ReferenceEstimator",
    "sparse_body.methods.reference.options:ReferenceOptions",
    eval_sensors="six_point",
)
